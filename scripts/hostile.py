"""Hostile inputs, round two: files that are not files, outputs that are not files, full disks,
impossible cameras and settings, training that fails, and the smaller ones.

    python scripts/hostile.py            # run every case, print the table, update docs/reliability.md
    python scripts/hostile.py -k fifo    # only the cases whose name contains "fifo" (no docs update)

Every case is a real ``pnlviz`` process (or a short Python process for the app's state) in a
temporary folder, bounded in time (``--timeout``) and in memory (``RLIMIT_AS``). Each outcome is
classified as:

* ``clean``: the expected result: a one-line message (non-zero exit) for a refusal, or success
  for a case that must work;
* ``traceback``: a Python traceback in the output;
* ``hang``: still running at the time limit (killed), or killed by a signal (memory);
* ``silent wrong``: exit 0 where a refusal was due, a refusal where the run had to succeed,
  raw control characters printed, or a wrong result written;
* ``destructive``: a non-regular file at an output path (device node, FIFO, symlink) replaced or
  written through.

The full disk and the read-only folder are small tmpfs mounts (needs root; skipped otherwise).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import time
import zipfile
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CODE = Path(os.environ.get("PNLVIZ_CODE", REPO))  # the pnlviz under test (default: this checkout)
DOC = REPO / "docs" / "reliability.md"
SECTION = "## 6. Hostile inputs, round two"
KINDS = ("clean", "traceback", "hang", "silent wrong", "destructive")
MEMORY_LIMIT = 6 * 2**30


@dataclass
class Run:
    """One process to run: ``argv`` after ``python -m pnlviz.cli`` (or ``code`` for ``python -c``)."""
    argv: list[str] = field(default_factory=list)
    expect: str = "refuse"  # "refuse" (non-zero exit, one line) or "ok" (exit 0)
    check: Callable[[], str | None] | None = None  # after the run: "destructive: ..." / "wrong: ..." / None
    code: str | None = None
    user: int | None = None
    timeout: float | None = None
    custom: Callable[[], tuple[str, str]] | None = None  # runs itself: (kind, detail)
    mention: str | None = None  # the output must name this (the bad field or file)


# ------------------------------------------------------------------------------ running
def _limits(user: int | None):
    def pre():
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
        os.setsid()
        if user is not None:
            os.setgid(user)
            os.setuid(user)
    return pre


def execute(run: Run, cwd: Path, timeout: float) -> tuple[int | None, str]:
    """(exit code or None on a time-out, stdout + stderr)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "PYTHONPATH": str(CODE),
           "PYTHONDONTWRITEBYTECODE": "1"}
    cmd = [sys.executable, "-c", run.code] if run.code else [sys.executable, "-m", "pnlviz.cli", *run.argv]
    p = subprocess.Popen(cmd, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, preexec_fn=_limits(run.user))
    try:
        out, _ = p.communicate(timeout=run.timeout or timeout)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        out, _ = p.communicate()
        return None, out.decode("utf-8", "backslashreplace")
    return p.returncode, out.decode("utf-8", "backslashreplace")


def classify(run: Run, rc: int | None, out: str) -> tuple[str, str]:
    last = next((line for line in reversed(out.splitlines()) if line.strip()), "")
    if rc is None:
        return "hang", "killed at the time limit"
    if "Traceback (most recent call last)" in out:
        tb = [line for line in out.splitlines() if line and not line.startswith(" ")]
        return "traceback", tb[-1][:160] if tb else "traceback"
    if rc < 0:
        return "hang", f"killed by signal {-rc}"
    problem = run.check() if run.check else None
    if problem and problem.startswith("destructive"):
        return "destructive", problem
    if "\x1b" in out:
        return "silent wrong", "raw terminal escape printed"
    if problem:
        return "silent wrong", problem
    if run.mention and run.mention.lower() not in out.lower():
        return "silent wrong", f"no word of {run.mention!r} (exit {rc}): {last[:120]}"
    if run.expect == "refuse" and rc == 0:
        return "silent wrong", f"exit 0: {last[:150]}"
    if run.expect == "ok" and rc != 0:
        return "silent wrong", f"refused (exit {rc}): {last[:150]}"
    return "clean", f"exit {rc}: {last[:150]}"


# ------------------------------------------------------------------------------ material
def pn(*argv: str) -> list[str]:
    return [str(a) for a in argv]


def fifo(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists() or path.is_symlink():
        path.unlink()
    os.mkfifo(path)
    return path


def chardev(path: Path, minor: int = 3) -> Path | None:
    """A character device node at ``path`` (like /dev/null: major 1, ``minor``); None if not allowed."""
    try:
        os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, minor))
    except (PermissionError, OSError):
        return None
    return path


def still(path: Path, kind: str, target: str | None = None) -> Callable[[], str | None]:
    """A check that ``path`` is still a ``kind`` ("fifo", "chr", "link") (and the link's target unchanged)."""
    def check():
        try:
            st = os.lstat(path)
        except FileNotFoundError:
            return f"destructive: {path.name} removed"
        ok = {"fifo": stat.S_ISFIFO, "chr": stat.S_ISCHR, "link": stat.S_ISLNK}[kind](st.st_mode)
        if not ok:
            return f"destructive: the {kind} at {path.name} was replaced"
        if target is not None and Path(os.readlink(path)).exists() and Path(os.readlink(path)).read_text() != target:
            return f"destructive: written through the link {path.name}"
        return None
    return check


def camera_json(base: dict, **change) -> str:
    cam = dict(base)
    cam.update(change)
    return json.dumps(cam)


class Material:
    """The shared inputs: a 6-frame synthetic dataset, its detections, a tiny training config."""

    def __init__(self, root: Path):
        self.root = root
        self.data = root / "D"
        rc, out = execute(Run(pn("synth", "--out", self.data, "-n", 6, "--seed", 1, "--no-progress")), root, 300)
        assert rc == 0, out
        self.preds = root / "preds.zip"
        rc, out = execute(Run(pn("detect", "--data", self.data, "--out", self.preds, "--no-progress",
                                 "--threads", 1)), root, 300)
        assert rc == 0, out
        self.cams = root / "cams.zip"
        with zipfile.ZipFile(self.cams, "w") as zf:
            for p in sorted((self.data / "cameras").glob("camera_*.json")):
                zf.write(p, p.name)
        self.camera = json.loads((self.data / "cameras" / "camera_00001.json").read_text())
        self.config = root / "tiny.json"
        self.config.write_text(json.dumps(tiny_config()))
        self.n = 0

    def work(self) -> Path:
        self.n += 1
        w = self.root / f"case{self.n:03d}"
        w.mkdir()
        w.chmod(0o777)
        return w

    def copy(self, work: Path) -> Path:
        d = work / "D"
        shutil.copytree(self.data, d, symlinks=True)
        return d

    def preds_with(self, work: Path, member: str | None = None, text: str | None = None,
                   info: dict | None = None) -> Path:
        z = work / "p.zip"
        with zipfile.ZipFile(self.preds) as src, zipfile.ZipFile(z, "w") as dst:
            for name in src.namelist():
                dst.writestr(name, text if name == member else src.read(name))
        sidecar = json.loads(self.preds.with_suffix(".json").read_text())
        if info is not None:
            sidecar.update(info)
        (work / "p.json").write_text(json.dumps(sidecar))
        return z

    def cams_with(self, work: Path, text: str) -> Path:
        z = work / "c.zip"
        with zipfile.ZipFile(self.cams) as src, zipfile.ZipFile(z, "w") as dst:
            for name in src.namelist():
                dst.writestr(name, text if name == "camera_00001.json" else src.read(name))
        return z


def tiny_config() -> dict:
    return {"data": {"seed": 1, "frames": 4, "size": [128, 72], "weight": 1.0}, "real": [],
            "input_size": [128, 72], "epoch_frames": 4, "epochs": 1, "batch_size": 2, "lr": 0.001,
            "lr_final": 0.0001, "weight_decay": 0.0, "sigma": 2.0, "loss": "focal", "kp_threshold": 0.3,
            "line_threshold": 0.4, "peak_refine": "raw", "calibration": {}, "seed": 0, "threads": 1, "augment": {}}


# ------------------------------------------------------------------------------ the cases
DATASET_COMMANDS = ("validate", "calibrate", "labels", "export", "sheet", "eval", "detect")


def dataset_run(m: Material, cmd: str, d: Path | str, w: Path, expect: str = "refuse") -> Run:
    """``cmd`` on dataset ``d``, writing into ``w``."""
    argv = {
        "validate": pn("validate", "--data", d, "--images"),
        "calibrate": pn("calibrate", "--data", d, "--out", w / "cams.zip", "--no-progress"),
        "labels": pn("labels", "--data", d, "--out", w / "labels"),
        "export": pn("export", "--data", d, "--out", w / "export", "--all", "--edits", w / "edits", "--no-progress"),
        "sheet": pn("sheet", "--data", d, "--out", w / "sheet.png", "-n", 6),
        "eval": pn("eval", "--gt", d, "--pred", m.cams, "--no-progress"),
        "detect": pn("detect", "--data", d, "--out", w / "preds.zip", "--no-progress", "--threads", 1),
    }[cmd]
    return Run(argv, expect=expect)


def not_files(m: Material):
    """Inputs that are not regular files."""
    for cmd in DATASET_COMMANDS:
        w = m.work()
        d = m.copy(w)
        os.symlink("loop_b.json", d / "loop_a.json")
        os.symlink("loop_a.json", d / "loop_b.json")
        os.symlink(".", d / "sub")
        run = dataset_run(m, cmd, d, w, "any" if cmd == "validate" else "ok")
        run.mention = "loop" if cmd != "detect" else None
        yield "not a file", f"symlink loops in the data folder: {cmd}", run
    for cmd in DATASET_COMMANDS:
        w = m.work()
        d = m.copy(w)
        fifo(d / "00001.json")
        run = dataset_run(m, cmd, d, w, "ok" if cmd == "detect" else "any")
        yield "not a file", f"FIFO as an annotation: {cmd}", run
    for cmd in DATASET_COMMANDS:
        w = m.work()
        d = m.copy(w)
        fifo(d / "00001.jpg")
        yield "not a file", f"FIFO as an image: {cmd}", dataset_run(m, cmd, d, w, "any")
    for cmd in DATASET_COMMANDS:
        w = m.work()
        yield "not a file", f"--data is a FIFO: {cmd}", dataset_run(m, cmd, fifo(w / "data.zip"), w)
    for cmd in DATASET_COMMANDS:
        w = m.work()
        yield "not a file", f"--data /dev/zero: {cmd}", dataset_run(m, cmd, "/dev/zero", w)
    w = m.work()
    yield "not a file", "train --data a FIFO", Run(pn("train", "--config", m.config, "--out", w / "m.pt", "--data",
                                                      fifo(w / "real.zip"), "--no-progress"))
    w = m.work()
    d = m.copy(w)
    (d / "cameras" / "camera_00002.json").unlink()
    os.symlink("/dev/zero", d / "cameras" / "camera_00002.json")
    yield "not a file", "a camera that is a link to /dev/zero: sheet", Run(pn("sheet", "--data", d, "--out",
                                                                             w / "s.png"), "any")
    w = m.work()
    yield "not a file", "--cameras a FIFO: sheet", Run(pn("sheet", "--data", m.data, "--cameras", fifo(w / "c.zip"),
                                                          "--out", w / "s.png"))
    w = m.work()
    yield "not a file", "--pred a FIFO: eval", Run(pn("eval", "--gt", m.data, "--pred", fifo(w / "c.zip")))
    w = m.work()
    yield "not a file", "--pred /dev/zero: eval", Run(pn("eval", "--gt", m.data, "--pred", "/dev/zero"))
    w = m.work()
    yield "not a file", "--detections a FIFO: calibrate", Run(pn("calibrate", "--data", m.data, "--detections",
                                                                 fifo(w / "p.zip"), "--out", w / "c.zip",
                                                                 "--no-progress"))
    w = m.work()
    z = m.preds_with(w)
    fifo(w / "p.json")
    yield "not a file", "--detections sidecar a FIFO: calibrate", Run(
        pn("calibrate", "--data", m.data, "--detections", z, "--out", w / "c.zip", "--no-progress"))
    w = m.work()
    yield "not a file", "--config a FIFO: train", Run(pn("train", "--config", fifo(w / "c.json"), "--out", w / "m.pt"))
    w = m.work()
    yield "not a file", "--config /dev/zero: train", Run(pn("train", "--config", "/dev/zero", "--out", w / "m.pt"))
    w = m.work()
    yield "not a file", "--weights a FIFO: detect", Run(pn("detect", "--data", m.data, "--weights", fifo(w / "m.pt"),
                                                           "--out", w / "p.zip", "--no-progress"))
    w = m.work()
    yield "not a file", "--init /dev/zero: train", Run(pn("train", "--config", m.config, "--init", "/dev/zero",
                                                          "--out", w / "m.pt", "--no-progress"))
    for cmd in ("detect", "render", "calibrate"):
        w = m.work()
        v = fifo(w / "clip.mp4")
        argv = {"detect": pn("detect", "--video", v, "--out", w / "p.zip", "--no-progress"),
                "render": pn("render", "--video", v, "--cameras", m.cams, "--out", w / "r.mp4", "--no-progress"),
                "calibrate": pn("calibrate", "--video", v, "--detections", m.preds, "--out", w / "c.zip",
                                "--no-progress")}[cmd]
        yield "not a file", f"--video a FIFO: {cmd}", Run(argv)
    for what in ("a link to /dev/zero", "a FIFO"):
        w = m.work()
        edits = w / "edits"
        (edits / "frames").mkdir(parents=True)
        rec = edits / "frames" / "00001.json"
        if what == "a FIFO":
            fifo(rec)
        else:
            os.symlink("/dev/zero", rec)
        yield "not a file", f"edit record {what}: export", Run(pn("export", "--data", m.data, "--edits", edits,
                                                                  "--out", w / "x", "--all", "--no-progress"), "any")
        yield "not a file", f"edit record {what}: serve", Run(custom=serve_case(m, w, ["--edits", edits], connects=0))


def output_runs(m: Material, w: Path, target: Path) -> dict[str, list[str]]:
    """Each writing command with ``target`` as its output (the suffix each expects)."""
    return {
        "calibrate": pn("calibrate", "--data", m.data, "--out", target, "--no-progress"),
        "detect": pn("detect", "--data", m.data, "--out", target, "--no-progress", "--threads", 1),
        "export": pn("export", "--data", m.data, "--edits", w / "edits", "--out", target, "--all", "--no-progress"),
        "eval --csv": pn("eval", "--gt", m.data, "--pred", m.cams, "--csv", target, "--no-progress"),
        "sheet": pn("sheet", "--data", m.data, "--out", target, "-n", 2),
        "render": pn("render", "--data", m.data, "--cameras", m.cams, "--out", target, "--no-progress"),
        "synth": pn("synth", "--out", target, "-n", 1, "--no-progress"),
        "labels": pn("labels", "--data", m.data, "--out", target),
        "train": pn("train", "--config", m.config, "--out", target, "--no-progress"),
    }


SUFFIX = {"calibrate": ".zip", "detect": ".zip", "export": ".zip", "eval --csv": ".csv", "sheet": ".png",
          "render": ".mp4", "synth": "", "labels": "", "train": ".pt"}


def not_file_outputs(m: Material):
    """Outputs that exist and are not regular files: they must be left as they are."""
    for cmd in SUFFIX:
        w = m.work()
        target = chardev(w / f"out{SUFFIX[cmd]}")
        if target is not None:
            argv = output_runs(m, w, target)[cmd]
            yield "output not a file", f"a device node (like /dev/null) as output: {cmd}", Run(
                argv, check=still(target, "chr"))
    for cmd in SUFFIX:
        w = m.work()
        target = fifo(w / f"out{SUFFIX[cmd]}")
        yield "output not a file", f"a FIFO as output: {cmd}", Run(output_runs(m, w, target)[cmd],
                                                                  check=still(target, "fifo"))
    for cmd in SUFFIX:
        w = m.work()
        victim = w / "elsewhere.txt"
        victim.write_text("keep me")
        target = w / f"out{SUFFIX[cmd]}"
        os.symlink(victim, target)
        yield "output not a file", f"a symlink as output: {cmd}", Run(output_runs(m, w, target)[cmd],
                                                                     check=still(target, "link", "keep me"))
    for cmd in ("eval --csv", "sheet", "calibrate"):
        w = m.work()
        target = w / f"stdout{SUFFIX[cmd]}"
        os.symlink("/proc/self/fd/1", target)
        yield "output not a file", f"a link to /proc/self/fd/1 (as /dev/stdout is): {cmd}", Run(
            output_runs(m, w, target)[cmd], check=still(target, "link"))
    w = m.work()
    full = chardev(w / "full.png", minor=7)
    if full is not None:
        yield "output not a file", "a copy of /dev/full as --out: sheet", Run(output_runs(m, w, full)["sheet"],
                                                                             check=still(full, "chr"))


# ------------------------------------------------------------------------------ write failures
MOUNTS: list[Path] = []


def mount_tmpfs(path: Path, *, full: bool = False, readonly: bool = False) -> bool:
    path.mkdir(parents=True, exist_ok=True)
    opts = "size=64k,mode=0777" + (",ro" if readonly else "")
    if subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(path)], capture_output=True).returncode:
        return False
    MOUNTS.append(path)
    if full:
        try:
            with open(path / "filler", "wb") as f:
                while True:
                    f.write(b"\0" * 4096)
                    f.flush()
        except OSError:  # ENOSPC: the disk is full, as wanted
            pass
    return True


def unmount_all() -> None:
    while MOUNTS:
        subprocess.run(["umount", "-l", str(MOUNTS.pop())], capture_output=True)


def write_failures(m: Material):
    """A read-only folder and a full disk (tmpfs mounts; "permission denied" is covered by the
    tests: as root every folder is writable, and the interpreter is not reachable as another user)."""
    for how in ("read-only", "full disk"):
        for cmd in SUFFIX:
            w = m.work()
            place = w / "mnt"
            if not mount_tmpfs(place, full=how == "full disk", readonly=how == "read-only"):
                continue
            target = place / ("out" + SUFFIX[cmd])
            yield "write failure", f"{how}: {cmd}", Run(output_runs(m, w, target)[cmd])


# ------------------------------------------------------------------------------ impossible values
BAD_CAMERAS = {
    "focal 0": {"x_focal_length": 0.0, "y_focal_length": 0.0},
    "focal -900": {"x_focal_length": -900.0},
    "focal 1e308": {"x_focal_length": 1e308, "y_focal_length": 1e308},
    "position 1e308": {"position_meters": [1e308, 0.0, -10.0]},
    "k1 1e12": {"radial_distortion": [1e12, 0, 0, 0, 0, 0]},
    "pan 1e300": {"pan_degrees": 1e300},
    "principal point [0, 0]": {"principal_point": [0.0, 0.0]},
}


def camera_readers(m: Material, w: Path, text: str) -> dict[str, Run]:
    d = m.copy(w)
    (d / "cameras" / "camera_00001.json").write_text(text)
    cams = m.cams_with(w, text)
    return {
        "validate": Run(pn("validate", "--data", d)),
        "eval": Run(pn("eval", "--gt", m.data, "--pred", cams, "--no-progress")),
        "sheet": Run(pn("sheet", "--data", d, "--out", w / "s.png", "-n", 3)),
        "render": Run(pn("render", "--data", m.data, "--cameras", cams, "--out", w / "r.mp4", "--no-progress")),
        "export": Run(pn("export", "--data", d, "--edits", w / "edits", "--out", w / "x", "--all", "--no-progress")),
    }


def impossible(m: Material):
    """Cameras, detector settings, detections and images no camera can have made."""
    for what, change in BAD_CAMERAS.items():
        text = camera_json(m.camera, **change)
        for cmd, run in camera_readers(m, m.work(), text).items():
            run.expect = "any" if cmd in ("eval", "sheet", "render", "export") else "refuse"
            run.mention = next(iter(change))
            yield "impossible value", f"camera {what}: {cmd}", run
    settings = {
        "alpha 7.5, refine_k1 'maybe'": {"calibration": {"alpha": 7.5, "refine_k1": "maybe"}},
        "an unknown setting": {"calibration": {"no_such_setting": 1}},
        "kp_threshold 'high'": {"kp_threshold": "high"},
    }
    for what, info in settings.items():
        for cmd in ("calibrate", "export"):
            w = m.work()
            z = m.preds_with(w, info=info)
            argv = (pn("calibrate", "--data", m.data, "--detections", z, "--out", w / "c.zip", "--no-progress")
                    if cmd == "calibrate" else
                    pn("export", "--data", m.data, "--detections", z, "--edits", w / "e", "--out", w / "x", "--all",
                       "--no-progress"))
            yield "impossible value", f"detector sidecar {what}: {cmd}", Run(argv)
    for p in ("-5", "1e308", "NaN"):
        text = json.dumps({"kp": {"3": {"x": 0.1, "y": 0.5, "p": float(p)}}, "lines": {}})
        for cmd in ("calibrate", "export"):
            w = m.work()
            z = m.preds_with(w, member="00001.json", text=text)
            argv = {"calibrate": pn("calibrate", "--data", m.data, "--detections", z, "--out", w / "c.zip",
                                    "--no-progress"),
                    "export": pn("export", "--data", m.data, "--detections", z, "--edits", w / "e", "--out", w / "x",
                                 "--all", "--no-progress")}[cmd]
            yield "impossible value", f"detection probability {p}: {cmd}", Run(argv, expect="any", mention="probab")
    import cv2
    import numpy as np
    for cmd in ("validate", "calibrate", "export", "labels", "sheet"):
        w = m.work()
        d = m.copy(w)
        cv2.imwrite(str(d / "00001.jpg"), np.zeros((1, 1, 3), np.uint8))
        run = dataset_run(m, cmd, d, w, "refuse" if cmd == "validate" else "any")
        run.mention = "00001.jpg"
        yield "impossible value", f"a 1x1 image: {cmd}", run


# ------------------------------------------------------------------------------ training
def no_file(path: Path) -> Callable[[], str | None]:
    return lambda: f"wrong: {path.name} written" if path.exists() else None


def training(m: Material):
    """Training that must stop with an error (and write no checkpoint), and options out of range."""
    configs = {"sigma 0": {"sigma": 0.0}, "input_size [0, 0]": {"input_size": [0, 0]},
               "lr 'fast'": {"lr": "fast"}, "epochs -1": {"epochs": -1}, "batch_size 0": {"batch_size": 0}}
    for what, change in configs.items():
        w = m.work()
        cfg = w / "cfg.json"
        cfg.write_text(json.dumps({**tiny_config(), **change}))
        out = w / "m.pt"
        yield "training", f"config {what}", Run(pn("train", "--config", cfg, "--out", out, "--no-progress"),
                                                check=no_file(out), timeout=240)
    options = {"--minutes nan": ["--minutes", "nan"], "--minutes -1": ["--minutes", "-1"],
               "--data-weight nan": ["--data", m.data, "--data-weight", "nan"],
               "--data-weight inf": ["--data", m.data, "--data-weight", "inf"],
               "--epochs 0": ["--epochs", "0"], "--batch-size -2": ["--batch-size", "-2"],
               "--frames -3": ["--frames", "-3"], "--threads 0": ["--threads", "0"]}
    for what, extra in options.items():
        w = m.work()
        out = w / "m.pt"
        yield "training", f"train {what}", Run(pn("train", "--config", m.config, "--out", out, "--no-progress", *extra),
                                               check=no_file(out), timeout=240)
    w = m.work()
    garbage = w / "garbage.zip"
    garbage.write_bytes(os.urandom(3000))
    yield "training", "train --labels garbage.zip", Run(pn("train", "--config", m.config, "--data", m.data, "--labels",
                                                           garbage, "--out", w / "m.pt", "--no-progress"),
                                                        check=no_file(w / "m.pt"))
    w = m.work()
    rc, out = execute(Run(pn("export", "--data", m.data, "--edits", w / "e", "--out", w / "x", "--all",
                             "--no-progress")), w, 120)
    for manifest in (w / "x").glob("manifest*"):
        manifest.unlink()
    yield "training", "train --labels a partial export (no manifest)", Run(
        pn("train", "--config", m.config, "--data", m.data, "--labels", w / "x", "--out", w / "m.pt", "--no-progress"),
        check=no_file(w / "m.pt"), mention="manifest")
    w = m.work()
    yield "training", "synth --size 16384x16384", Run(pn("synth", "--out", w / "s", "-n", 2, "--size", "16384x16384",
                                                         "--no-progress"))


# ------------------------------------------------------------------------------ smaller
def smaller(m: Material):
    for cmd in ("validate", "calibrate", "labels"):
        w = m.work()
        d = m.copy(w)
        (d / "\x1b[2J\x1b]0;owned\x07.json").write_text("{broken")
        yield "smaller", f"a file name with terminal escapes: {cmd}", dataset_run(m, cmd, d, w, "any")
    w = m.work()
    yield "smaller", "an output name with terminal escapes: sheet", Run(
        pn("sheet", "--data", m.data, "--out", w / "\x1b[2Jsheet.png", "-n", 1), expect="ok")
    w = m.work()
    junk = w / "junk.mp4"
    junk.write_bytes(os.urandom(20000))
    jpeg = w / "photo.mp4"
    shutil.copy(m.data / "00000.jpg", jpeg)
    for what, video in (("random bytes", junk), ("a JPEG", jpeg)):
        yield "smaller", f"{what} named .mp4: detect --video", Run(pn("detect", "--video", video, "--out",
                                                                      w / f"p_{video.stem}.zip", "--no-progress"))
        yield "smaller", f"{what} named .mp4: render --video", Run(pn("render", "--video", video, "--cameras", m.cams,
                                                                      "--out", w / f"r_{video.stem}.mp4",
                                                                      "--no-progress"))
        yield "smaller", f"{what} named .mp4: calibrate --video", Run(pn("calibrate", "--video", video, "--detections",
                                                                         m.preds, "--out", w / f"c_{video.stem}.zip",
                                                                         "--no-progress"))
    for kid in ("5.5", "True", "'7'", "7.0", "None"):
        w = m.work()
        code = ("from pathlib import Path\nfrom pnlviz.app.state import AppState\n"
                f"st = AppState(Path({str(m.data)!r}), edits=Path({str(w / 'e')!r}))\n"
                f"try:\n    st.move_keypoint('00001', {kid}, 100.0, 100.0)\n"
                "except Exception as e:\n    print('refused:', e); raise SystemExit(1)\n"
                "finally:\n    st.close()\nprint('moved')\n")
        yield "smaller", f"keypoint id {kid} through AppState", Run(code=code)
    w = m.work()
    yield "smaller", "bare TCP connects to serve (a port scan)", Run(custom=serve_case(m, w, [], connects=5))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve_case(m: Material, w: Path, extra: list[str], connects: int) -> Callable[[], tuple[str, str]]:
    """Start ``serve``, wait for its URL (60 s), make ``connects`` bare TCP connections, stop it;
    clean when it started (or refused in one line) and printed no traceback."""
    def run() -> tuple[str, str]:
        port = free_port()
        env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(CODE)}
        log = w / "serve.log"
        with open(log, "wb") as f:
            p = subprocess.Popen([sys.executable, "-m", "pnlviz.cli", "serve", "--data", str(m.data), "--no-detect",
                                  "--port", str(port), *extra], cwd=w, env=env, stdout=f, stderr=subprocess.STDOUT,
                                 preexec_fn=_limits(None))
        try:
            up = False
            deadline = time.time() + 60
            while time.time() < deadline and p.poll() is None:
                try:
                    socket.create_connection(("127.0.0.1", port), timeout=1).close()
                    up = True
                    break
                except OSError:
                    time.sleep(0.5)
            for _ in range(connects):
                with socket.create_connection(("127.0.0.1", port), timeout=2) as s:
                    s.sendall(b"\x16\x03\x01garbage")
            time.sleep(2)
        finally:
            rc = p.poll()
            if rc is None:
                p.terminate()
                try:
                    p.wait(10)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
        out = log.read_text(errors="backslashreplace")
        last = next((line for line in reversed(out.splitlines()) if line.strip()), "")
        if "Traceback" in out or "Exception in callback" in out or "ERROR" in out:
            lines = [line for line in out.splitlines() if line and not line.startswith(" ")]
            return "traceback", lines[-1][:160] if lines else "traceback"
        if rc is None and not up:
            return "hang", "not listening after 60 s"
        return "clean", ("served" if rc is None else f"exit {rc}") + f": {last[:120]}"
    return run


# ------------------------------------------------------------------------------ main
GROUPS = (not_files, not_file_outputs, write_failures, impossible, training, smaller)


def run_all(root: Path, pattern: str | None, timeout: float, groups: list[int] | None = None) -> list[dict]:
    m = Material(root)
    results = []
    try:
        for i, group in enumerate(GROUPS):
            if groups is not None and i not in groups:
                continue
            for kind, name, run in group(m):
                if pattern and pattern.lower() not in f"{kind} {name}".lower():
                    continue
                t0 = time.time()
                if run.custom:
                    outcome, detail = run.custom()
                else:
                    rc, out = execute(run, root, timeout)
                    outcome, detail = classify(run, rc, out)
                results.append({"kind": kind, "case": name, "outcome": outcome, "detail": detail,
                                "seconds": round(time.time() - t0, 1)})
                print(f"{outcome:>12}  {name}  ({time.time() - t0:.1f} s)  {detail}", flush=True)
    finally:
        unmount_all()
    return results


def summary(results: list[dict], before: list[dict] | None = None) -> list[str]:
    kinds = list(dict.fromkeys(r["kind"] for r in results))
    head = "| kind | runs | " + " | ".join(KINDS) + " |"
    lines = [head, "|---" * (len(KINDS) + 2) + "|"]
    for kind in [*kinds, None]:
        rows = [r for r in results if kind is None or r["kind"] == kind]
        c = Counter(r["outcome"] for r in rows)
        label = "**all**" if kind is None else kind
        lines.append(f"| {label} | {len(rows)} | " + " | ".join(str(c[k]) for k in KINDS) + " |")
    if before:  # the same cases, run on the code before the fixes
        names = {r["case"] for r in results}
        same = [r for r in before if r["case"] in names]
        c = Counter(r["outcome"] for r in same)
        lines.append(f"| *before the fixes* | {len(same)} | " + " | ".join(str(c[k]) for k in KINDS) + " |")
    return lines


def escape(text: str) -> str:
    return text.encode("unicode_escape").decode("ascii").replace("|", "\\|")


BEFORE_NOTE = ("*Before the fixes*: the same cases run on commit b67a54e (`PNLVIZ_CODE=<a checkout of it> "
               "python scripts/hostile.py --json ...`), kept in `docs/reliability_before.json`.")


def section(results: list[dict], before: list[dict] | None, commit: str) -> list[str]:
    lines = [SECTION, "",
             f"`python scripts/hostile.py` on {time.strftime('%Y-%m-%d')} (commit {commit}): "
             f"{len(results)} runs, each a real process bounded in time and memory "
             f"({MEMORY_LIMIT // 2**30} GiB address space). Outcomes: clean (the refusal or result due, in "
             "one line), traceback, hang (or killed), silent wrong (exit 0 where a refusal was due, the bad "
             "field not named, raw terminal escapes printed, a checkpoint written after a failure), "
             "destructive (a device node, FIFO or symlink at an output path replaced or written through).", "",
             *summary(results, before), "",
             *([BEFORE_NOTE, ""] if before else []),
             "| kind | case | outcome | what was printed (last line) |", "|---|---|---|---|"]
    for r in results:
        lines.append(f"| {r['kind']} | {escape(r['case'])} | {r['outcome']} | {escape(r['detail'])} |")
    return lines + [""]


def update_doc(lines: list[str]) -> None:
    text = DOC.read_text() if DOC.exists() else "# Reliability\n"
    head, sep, _ = text.partition(SECTION)
    DOC.write_text(head.rstrip("\n") + "\n\n" + "\n".join(lines))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-k", help="only the cases whose kind or name contains this (no docs update)")
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds per run (default 60)")
    ap.add_argument("--json", type=Path, help="also write the results to this JSON file")
    ap.add_argument("--groups", type=lambda t: [int(v) for v in t.split(",")],
                    help="only these groups of cases (0-based, comma-separated; no docs update)")
    ap.add_argument("--no-doc", action="store_true", help="do not update docs/reliability.md")
    ap.add_argument("--before", type=Path, help="results JSON of an earlier run, summed in the table")
    args = ap.parse_args()
    root = Path(tempfile.mkdtemp(prefix="pnlviz-hostile-"))
    root.chmod(0o755)
    t0 = time.time()
    try:
        results = run_all(root, args.k, args.timeout, args.groups)
    finally:
        unmount_all()
        shutil.rmtree(root, ignore_errors=True)
    before = json.loads(args.before.read_text()) if args.before else None
    print("\n".join(summary(results, before)))
    print(f"{len(results)} runs in {time.time() - t0:.0f} s")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    if not args.k and not args.no_doc and args.groups is None:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True,
                                text=True).stdout.strip()
        update_doc(section(results, before, commit))
        print(f"wrote {DOC}")


if __name__ == "__main__":
    main()
