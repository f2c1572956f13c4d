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
  written through, or an input changed (every file the run did not write is checked: its kind,
  size and modification time before and after; the outputs a run may write are named by its
  ``--out``, ``--report``, ``--csv``);
* ``data loss``: frames the fault does not concern missing from the output (the others must be
  done), or a user's file not kept;
* ``memory``: a peak resident size above :data:`MEMORY_FLAG_MB` (the largest of any case is
  printed).

A serve case is clean when the server starts, a browser page shows a frame (headless Chromium,
when playwright and chromium are installed; else the port must answer), and no traceback is
printed.

``--mutate`` checks the screen itself: each fault of :data:`MUTATIONS` is planted in a copy of the
package (a FIFO read as if it were a file, a refusal turned into a crash, a server that never
shows a frame, an output over its dataset let through, ...) and the cases named for it run on the
copy; the screen must find each one (any outcome but clean), else it exits 1.

The full disk and the read-only folder are small tmpfs mounts (needs root; skipped otherwise).
"""

from __future__ import annotations

import argparse
import contextlib
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
SECTION = "## 7. Hostile inputs, round two"
KINDS = ("clean", "traceback", "hang", "silent wrong", "destructive", "data loss", "memory")
MEMORY_LIMIT = 6 * 2**30
#: a case whose peak resident size is above this (MB) is classified "memory"
MEMORY_FLAG_MB = 1024
#: the options whose value is a path a run may write (everything else it must leave as it was)
OUTPUT_OPTIONS = ("--out", "--report", "--csv", "--json")


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
    done: Callable[[], str | None] | None = None  # "data loss: ..." when frames not concerned are missing

    def outputs(self) -> list[Path]:
        """The paths this run may write (the values of :data:`OUTPUT_OPTIONS`, their sidecars)."""
        out = [Path(v) for k, v in zip(self.argv, self.argv[1:]) if k in OUTPUT_OPTIONS]
        return out + [p.with_suffix(".json") for p in out if p.suffix and p.suffix != ".json"]


# ------------------------------------------------------------------------------ running
def _limits(user: int | None):
    def pre():
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
        os.setsid()
        if user is not None:
            os.setgid(user)
            os.setuid(user)
    return pre


PEAK_MB: list[float] = []  # the peak resident size of the last run (MB), set by execute


def execute(run: Run, cwd: Path, timeout: float) -> tuple[int | None, str]:
    """(exit code or None on a time-out, stdout + stderr); the run's peak resident size goes to
    :data:`PEAK_MB` (from the kernel's accounting of the process, ``wait4``)."""
    import threading

    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "PYTHONPATH": str(CODE),
           "PYTHONDONTWRITEBYTECODE": "1"}
    cmd = [sys.executable, "-c", run.code] if run.code else [sys.executable, "-m", "pnlviz.cli", *run.argv]
    p = subprocess.Popen(cmd, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, preexec_fn=_limits(run.user))
    chunks: list[bytes] = []
    reader = threading.Thread(target=lambda: chunks.append(p.stdout.read()), daemon=True)  # type: ignore[union-attr]
    reader.start()
    timed_out = threading.Event()

    def kill() -> None:
        timed_out.set()
        with contextlib.suppress(ProcessLookupError):
            os.killpg(p.pid, signal.SIGKILL)

    timer = threading.Timer(run.timeout or timeout, kill)
    timer.start()
    _, status, usage = os.wait4(p.pid, 0)
    timer.cancel()
    p.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait for it again
    reader.join(10)
    PEAK_MB[:] = [usage.ru_maxrss / 1024]
    out = b"".join(chunks).decode("utf-8", "backslashreplace")
    return (None if timed_out.is_set() else p.returncode), out


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
    lost = run.done() if run.done else None
    if lost:
        return "data loss", lost
    if PEAK_MB and PEAK_MB[0] > MEMORY_FLAG_MB:
        return "memory", f"peak {PEAK_MB[0]:.0f} MB (exit {rc})"
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


def snapshot(root: Path) -> dict[str, tuple]:
    """Every entry under ``root``: (kind, size, modification time), links not followed."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
        for name in dirnames + filenames:
            path = os.path.join(dirpath, name)
            with contextlib.suppress(OSError):
                st = os.lstat(path)
                out[path] = (stat.S_IFMT(st.st_mode), st.st_size, st.st_mtime_ns)
    return out


def changed_inputs(before: dict[str, tuple], after: dict[str, tuple], outputs: list[Path]) -> str | None:
    """``destructive: ...`` when a run changed or removed an entry that is none of its outputs,
    or made one inside a dataset folder (``D``: the material's and every case's copy)."""
    allowed = [os.path.abspath(o) for o in outputs]

    def output(path: str) -> bool:
        return any(path == a or path.startswith(a.rstrip("/") + "/") for a in allowed)

    for path, was in before.items():
        if output(path) or stat.S_ISDIR(was[0]):
            continue
        now = after.get(path)
        if now is None:
            return f"destructive: the input {os.path.basename(path)} was removed"
        if now != was:
            return f"destructive: the input {os.path.basename(path)} was changed"
    for path in after.keys() - before.keys():
        if not output(path) and "/D/" in path:
            return f"destructive: {os.path.basename(path)} written into the dataset"
    return None


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
        self._baseline: dict[str, set[str]] = {}

    def other_dataset(self) -> dict:
        """Another synthetic dataset with the same stems, and its edits folder made by the app (a
        review and a moved point)."""
        if not hasattr(self, "_other"):
            b = self.root / "B"
            rc, out = execute(Run(pn("synth", "--out", b, "-n", 6, "--seed", 2, "--no-progress")), self.root, 300)
            assert rc == 0, out
            edits = self.root / "B.edits"
            code = ("from pnlviz.app.state import AppState\n"
                    f"st = AppState({str(b)!r}, edits={str(edits)!r})\n"
                    "st.set_review('00000', 'accepted'); st.move_keypoint('00001', 5, 100.0, 100.0); st.close()\n")
            rc, out = execute(Run(code=code), self.root, 120)
            assert rc == 0, out
            self._other = {"data": b, "edits": edits}
        return self._other

    def baseline(self, cmd: str) -> set[str]:
        """The frames ``cmd`` gives on the clean material (run once)."""
        if cmd not in self._baseline:
            w = self.root / f"baseline-{cmd}"
            w.mkdir()
            run = dataset_run(self, cmd, self.data, w, "ok")
            run.done = None
            execute(run, self.root, 300)
            out = {"calibrate": w / "cams.zip", "labels": w / "labels", "export": w / "export",
                   "detect": w / "preds.zip"}[cmd]
            self._baseline[cmd] = stems_in(cmd, out)
        return self._baseline[cmd]

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


def dataset_run(m: Material, cmd: str, d: Path | str, w: Path, expect: str = "refuse",
                concerned: tuple[str, ...] = ("00001",)) -> Run:
    """``cmd`` on dataset ``d``, writing into ``w``. When it succeeds, the frames the fault does
    not ``concern`` must all be in its output (those the same command gives on the clean
    material, :meth:`Material.baseline`)."""
    argv = {
        "validate": pn("validate", "--data", d, "--images"),
        "calibrate": pn("calibrate", "--data", d, "--out", w / "cams.zip", "--no-progress"),
        "labels": pn("labels", "--data", d, "--out", w / "labels"),
        "export": pn("export", "--data", d, "--out", w / "export", "--all", "--no-progress"),
        "sheet": pn("sheet", "--data", d, "--out", w / "sheet.png", "-n", 6),
        "eval": pn("eval", "--gt", d, "--pred", m.cams, "--no-progress"),
        "detect": pn("detect", "--data", d, "--out", w / "preds.zip", "--no-progress", "--threads", 1),
    }[cmd]
    run = Run(argv, expect=expect)
    out = {"calibrate": w / "cams.zip", "labels": w / "labels", "export": w / "export",
           "detect": w / "preds.zip"}.get(cmd)
    if out is not None and expect != "refuse":
        run.done = others_done(m, cmd, out, concerned)
    return run


def stems_in(cmd: str, out: Path) -> set[str]:
    """The frames an output holds (a camera zip, a prediction zip, a label folder, an export)."""
    if not out.exists():
        return set()
    if cmd in ("calibrate", "detect"):
        with zipfile.ZipFile(out) as zf:
            names = [n.rsplit("/", 1)[-1] for n in zf.namelist() if n.endswith(".json")]
        return {n[len("camera_"):-5] if n.startswith("camera_") else n[:-5] for n in names}
    if cmd == "labels":
        return {p.stem for p in out.glob("*.json")}
    manifest = json.loads((out / "manifest.json").read_text())
    return {stem for stem, e in manifest["frames"].items() if e.get("exported")}


def others_done(m: Material, cmd: str, out: Path, concerned: tuple[str, ...]) -> Callable[[], str | None]:
    def check() -> str | None:
        if not out.exists():
            return None  # refused as a whole: classified by its exit and message
        missing = sorted(m.baseline(cmd) - set(concerned) - stems_in(cmd, out))
        return f"data loss: frames {missing} not in the output (the fault concerns {list(concerned)})" if missing \
            else None
    return check


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
        "export": pn("export", "--data", m.data, "--out", target, "--all", "--no-progress"),
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
        "export": Run(pn("export", "--data", d, "--out", w / "x", "--all", "--no-progress")),
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
                    pn("export", "--data", m.data, "--detections", z, "--out", w / "x", "--all", "--no-progress"))
            yield "impossible value", f"detector sidecar {what}: {cmd}", Run(argv)
    for p in ("-5", "1e308", "NaN"):
        text = json.dumps({"kp": {"3": {"x": 0.1, "y": 0.5, "p": float(p)}}, "lines": {}})
        for cmd in ("calibrate", "export"):
            w = m.work()
            z = m.preds_with(w, member="00001.json", text=text)
            argv = {"calibrate": pn("calibrate", "--data", m.data, "--detections", z, "--out", w / "c.zip",
                                    "--no-progress"),
                    "export": pn("export", "--data", m.data, "--detections", z, "--out", w / "x", "--all",
                                 "--no-progress")}[cmd]
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
    rc, out = execute(Run(pn("export", "--data", m.data, "--out", w / "x", "--all", "--no-progress")), w, 120)
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


def lost(m: Material):
    """Issue #32: what cost a user data or time: outputs over inputs, another dataset's edits, an
    --edits that is not one, the app's own files damaged or not files, memory, nonsense cameras."""
    for inner in ("annotations", "keypoints"):
        w = m.work()
        x = w / "X"
        shutil.copytree(m.data, x / inner)
        yield "nothing lost", f"export --data X/{inner} --out X (over its own dataset)", Run(
            pn("export", "--data", x / inner, "--out", x, "--all", "--no-progress"), mention="holds the dataset")
    other = m.other_dataset()
    for cmd in ("export", "qa", "calibrate"):
        w = m.work()
        out = {"export": w / "x", "qa": w / "q.jsonl", "calibrate": w / "c.zip"}[cmd]
        argv = pn(cmd, "--data", m.data, "--edits", other["edits"], "--out", out, "--no-progress")
        yield "nothing lost", f"an edits folder of another dataset (same stems): {cmd}", Run(
            argv + (["--all"] if cmd == "export" else []), mention="another dataset", check=no_file(out))
    w = m.work()
    yield "nothing lost", "an edits folder of another dataset: serve", Run(
        custom=serve_case(m, w, ["--edits", str(other["edits"])], connects=0, refused="another dataset"))
    for what in ("a typo", "a file", "a FIFO", "/dev/zero", "an empty folder"):
        for cmd in ("export", "qa", "calibrate"):
            w = m.work()
            e = {"a typo": w / "edtis", "a file": w / "edits.txt", "a FIFO": w / "edits.fifo", "/dev/zero": "/dev/zero",
                 "an empty folder": w / "empty"}[what]
            if what == "a file":
                Path(e).write_text("{}")
            elif what == "a FIFO":
                fifo(Path(e))
            elif what == "an empty folder":
                Path(e).mkdir()
            out = {"export": w / "x", "qa": w / "q.jsonl", "calibrate": w / "c.zip"}[cmd]
            yield "nothing lost", f"--edits {what}: {cmd}", Run(
                pn(cmd, "--data", m.data, "--edits", e, "--out", out, "--no-progress"), mention="--edits",
                check=no_file(out))
    for what in ("a FIFO", "a link to /dev/zero", "damaged", "'123'"):
        w = m.work()
        yield "nothing lost", f"a clip's cuts file {what}", Run(code=cuts_case(m, w, what), expect="ok")
    for what in ("a FIFO", "a bad line", "a file for the folder"):
        w = m.work()
        edits = w / "edits"
        cache = edits / "cache"
        if what == "a file for the folder":
            edits.mkdir()
            cache.write_text("not a folder")
        else:
            cache.mkdir(parents=True)
            if what == "a FIFO":
                fifo(cache / "summaries.jsonl")
            else:
                (cache / "summaries.jsonl").write_text('{"stem": "00000", "ok": true}\n{broken\n[1, 2]\n')
        yield "nothing lost", f"the triage cache {what}: serve", Run(
            custom=serve_case(m, w, ["--edits", str(edits)], connects=0))
    w = m.work()
    d = m.copy(w)
    rng_points = [{"x": (i % 997) / 997, "y": (i % 991) / 991} for i in range(650_000)]
    (d / "00001.json").write_text(json.dumps({"Side line top": rng_points}))
    run = Run(pn("qa", "--data", d, "--out", w / "q.jsonl", "--no-progress"), expect="ok", mention="00001.json")
    yield "nothing lost", "a 31 MB annotation: qa", run
    yield "nothing lost", "a 31 MB annotation: serve", Run(custom=serve_case(m, w, ["--data", str(d)], connects=0))
    w = m.work()
    out = w / "q.jsonl"
    execute(Run(pn("qa", "--data", m.data, "--out", out, "--no-progress")), w, 300)
    lines = out.read_text().splitlines() if out.exists() else []
    if lines:
        first = json.loads(lines[0])
        out.write_text("\n".join([json.dumps({**first, "score": "high"}), *lines[1:], "{torn"]) + "\n")
    yield "nothing lost", "qa --resume over a damaged line of its own output", Run(
        pn("qa", "--data", m.data, "--out", out, "--resume", "--no-progress"), expect="ok", mention="damaged")
    w = m.work()
    edits = w / "edits"
    (edits / "frames").mkdir(parents=True)
    (edits / "frames" / "00002.json").write_text("{damaged")
    yield "nothing lost", "qa with a damaged edit record", Run(
        pn("qa", "--data", m.data, "--edits", edits, "--out", w / "q.jsonl", "--no-progress"), expect="ok",
        mention="damaged edit record")
    code = ("import pnlviz, numpy as np\n"
            "cam = pnlviz.Camera.from_look_at((0.0, 60.0, -18.0), (0.0, 0.0, 0.0), hfov_deg=40, width=1280, height=720)\n"
            "far = cam.project(np.array([[0.0, -1e7, 0.0]]))[0]\n"
            "p = cam.image_to_pitch(far + [0.0, 0.25])\n"
            "print('a pitch point', p) if np.all(np.isfinite(p)) else print('no pitch point: nan')\n"
            "raise SystemExit(0 if np.all(np.isnan(p)) else 3)\n")
    yield "nothing lost", "image_to_pitch 0.25 px below the horizon", Run(code=code, expect="ok")
    for key, value in (("x_focal_length", "0"), ("x_focal_length", "float('nan')"),
                       ("position_meters", "[1e308, 0.0, -10.0]"), ("pan_degrees", None)):
        change = (f"d.pop({key!r})" if value is None else f"d[{key!r}] = {value}")
        code = ("import pnlviz\n"
                "d = pnlviz.Camera.from_look_at((0.0, 60.0, -18.0), (0.0, 0.0, 0.0), hfov_deg=40, width=960, "
                "height=540).to_soccernet()\n"
                f"{change}\n"
                "try:\n    pnlviz.Camera.from_soccernet(d)\nexcept pnlviz.ArgumentError as e:\n"
                "    print('refused:', e); raise SystemExit(1)\nprint('accepted')\n")
        yield "nothing lost", f"from_soccernet with {key} {value or 'missing'}", Run(code=code, mention=key)
    w = m.work()
    yield "nothing lost", "SIGTERM to serve", Run(custom=serve_case(m, w, [], connects=0, sigterm=True))


def cuts_case(m: Material, w: Path, what: str) -> str:
    """Python that opens a clip with a bad cuts file and checks it is set aside, not read as cuts
    nor written over (exit 0: so; else a message and exit 3)."""
    return f"""
import os, json, shutil
from pathlib import Path
from pnlviz.pipeline.reader import FrameReader
from pnlviz.pipeline.clip import read_cuts
data = Path({str(w)!r}) / "clip"
data.mkdir()
for i, src in enumerate(sorted(Path({str(m.data)!r}).glob("*.json"))[:4]):
    shutil.copy(src, data / f"m-IMG_{{i + 1}}.json")
edits = Path({str(w)!r}) / "edits"
path = edits / "clips" / "m.json"
path.parent.mkdir(parents=True)
what = {what!r}
if what == "a FIFO":
    os.mkfifo(path)
elif what == "a link to /dev/zero":
    os.symlink("/dev/zero", path)
elif what == "damaged":
    path.write_text('{{"cuts": {{"added": [2], "removed": [')
else:
    path.write_text("123")
reader = FrameReader.open(data, edits=edits, writable=True)
cuts = read_cuts(reader, "m")
aside = list(path.parent.glob("m.json.damaged-*"))
print("; ".join(reader.edits_folder.warnings))
reader.close()
if cuts.added or cuts.removed or len(aside) != 1 or os.path.lexists(path):
    print("read as cuts, or not set aside:", cuts, aside); raise SystemExit(3)
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


BROWSER_FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def page_shows_frame(url: str) -> str | None:
    """Why a browser page on ``url`` shows no calibrated frame within 60 s (None: it does, or no
    browser is at hand to look: playwright and Debian's chromium)."""
    chromium = shutil.which("chromium")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        return None
    if chromium is None:
        return None
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, args=BROWSER_FLAGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(url)
            page.get_by_text("focal").first.wait_for(timeout=60_000)
        except Exception as exc:  # noqa: BLE001 - any failure to show a frame is the finding
            return f"no frame shown within 60 s ({type(exc).__name__})"
        finally:
            browser.close()
    return None


def serve_case(m: Material, w: Path, extra: list[str], connects: int, refused: str | None = None,
               sigterm: bool = False) -> Callable[[], tuple[str, str]]:
    """Start ``serve`` and wait for its URL (60 s); make ``connects`` bare TCP connections; look
    at a page (:func:`page_shows_frame`); stop it (with ``sigterm``: SIGTERM must end it within
    5 s). Clean when it started, showed a frame and printed no traceback; with ``refused``, when
    it refused in one line naming that."""
    def run() -> tuple[str, str]:
        port = free_port()
        env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(CODE)}
        log = w / f"serve{port}.log"
        with open(log, "wb") as f:
            p = subprocess.Popen([sys.executable, "-m", "pnlviz.cli", "serve", "--data", str(m.data), "--no-detect",
                                  "--port", str(port), *extra], cwd=w, env=env, stdout=f, stderr=subprocess.STDOUT,
                                 preexec_fn=_limits(None))
        shown = stopped = None
        try:
            url = None
            deadline = time.time() + 60
            while time.time() < deadline and p.poll() is None and url is None:
                url = next((line.split("open ", 1)[1].strip() for line in log.read_text(errors="replace").splitlines()
                            if line.startswith("pnlviz: open ")), None)
                time.sleep(0.3)
            for _ in range(connects if url else 0):
                with socket.create_connection(("127.0.0.1", port), timeout=2) as s:
                    s.sendall(b"\x16\x03\x01garbage")
            if url and refused is None:
                shown = page_shows_frame(url)
            time.sleep(1)
            if sigterm and p.poll() is None:
                t0 = time.time()
                p.send_signal(signal.SIGTERM)
                try:
                    p.wait(10)
                    stopped = None if time.time() - t0 <= 5.5 else f"ended {time.time() - t0:.1f} s after SIGTERM"
                except subprocess.TimeoutExpired:
                    stopped = "still running 10 s after SIGTERM"
        finally:
            rc = p.poll()
            if rc is None:
                with contextlib.suppress(OSError, ValueError):  # the server's peak resident size (kB)
                    status = Path(f"/proc/{p.pid}/status").read_text()
                    PEAK_MB[:] = [int(status.split("VmHWM:")[1].split()[0]) / 1024]
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
        if PEAK_MB and PEAK_MB[0] > MEMORY_FLAG_MB:
            return "memory", f"serve peaked at {PEAK_MB[0]:.0f} MB"
        if refused is not None:
            if rc is None or rc == 0:
                return "silent wrong", f"served where a refusal was due: {last[:120]}"
            if refused.lower() not in out.lower():
                return "silent wrong", f"no word of {refused!r}: {last[:120]}"
            return "clean", f"exit {rc}: {last[:150]}"
        if stopped:
            return "hang", stopped
        if url is None:
            return "hang", f"no URL after 60 s (exit {rc}): {last[:120]}"
        if shown:
            return "hang", shown
        return "clean", ("served, a frame shown" if rc is None or sigterm else f"exit {rc}") + f": {last[:100]}"
    return run


# ------------------------------------------------------------------------------ main
GROUPS = (not_files, not_file_outputs, write_failures, impossible, training, smaller, lost)


def run_all(root: Path, pattern: str | None, timeout: float, groups: list[int] | None = None,
            patterns: list[str] | None = None) -> list[dict]:
    """Every case (or those whose name contains ``pattern``, or one of ``patterns``)."""
    root.mkdir(parents=True, exist_ok=True)
    m = Material(root)
    results = []
    try:
        for i, group in enumerate(GROUPS):
            if groups is not None and i not in groups:
                continue
            for kind, name, run in group(m):
                if patterns is not None:
                    if not any(p.lower() in f"{kind} {name}".lower() for p in patterns):
                        continue
                elif pattern and pattern.lower() not in f"{kind} {name}".lower():
                    continue
                t0 = time.time()
                PEAK_MB.clear()
                if run.custom:
                    outcome, detail = run.custom()
                else:
                    before = snapshot(root)
                    rc, out = execute(run, root, timeout)
                    outcome, detail = classify(run, rc, out)
                    changed = changed_inputs(before, snapshot(root), run.outputs())
                    if changed and outcome != "destructive":
                        outcome, detail = "destructive", changed
                results.append({"kind": kind, "case": name, "outcome": outcome, "detail": detail,
                                "seconds": round(time.time() - t0, 1),
                                "peak_mb": round(PEAK_MB[0]) if PEAK_MB else None})
                print(f"{outcome:>12}  {name}  ({time.time() - t0:.1f} s)  {detail}", flush=True)
    finally:
        unmount_all()
    return results


#: faults planted by ``--mutate``: (what, file in the package, text, its replacement, the cases
#: that must find it: a part of their names)
MUTATIONS = [
    ("a FIFO or device in the app's files silently passed over (not set aside)",
     [("data/state_files.py", 'set_aside(path, f"is {kind_of(st.st_mode)}, not a regular file", warnings)\n'
                              "        return False", "return False")],
     ["cuts file a FIFO", "cuts file a link to /dev/zero"]),
    ("a refusal turned into a crash (--edits that is a file)",
     [("data/edits_folder.py", 'raise DataError(source, "is not a folder (an edits folder holds frames/ with one '
                               'record per frame)")', 'raise RuntimeError("not a folder")')],
     ["--edits a file:", "--edits a FIFO:"]),
    ("a server that never shows a frame",
     [("app/session.py", "            view = self.view()\n            self.painter.draw(view)",
       "            view = self.view()")],
     ["SIGTERM to serve", "bare TCP connects"]),
    ("an output folder over its dataset let through",
     [("data/outputs.py", "        if target in root.parents:\n", "        if False:\n")],
     ["over its own dataset"]),
    ("another dataset's edits adopted without a word",
     [("data/edits_folder.py", "    names = list(store.stems() if stems is None else stems)", "    return []")],
     ["edits folder of another dataset"]),
    ("memory unbounded (the annotation caps lifted)",
     [("data/reading.py", "else MAX_DATASET_JSON_BYTES", "else MAX_JSON_BYTES"),
      ("data/annotations.py", "MAX_POINTS = 500", "MAX_POINTS = 10**9")],
     ["a 31 MB annotation: qa"]),
]


def mutate(root: Path, timeout: float) -> list[dict]:
    """Plant each fault of :data:`MUTATIONS` in a copy of the package and run its cases on it:
    one result per fault (``caught``: some case found it)."""
    global CODE
    original = CODE
    out = []
    for i, (what, changes, patterns) in enumerate(MUTATIONS):
        copy = root / f"mutant{i}"
        shutil.copytree(original / "pnlviz", copy / "pnlviz", symlinks=False,
                        ignore=shutil.ignore_patterns("__pycache__"))
        for rel, old, new in changes:
            path = copy / "pnlviz" / rel
            text = path.read_text()
            assert text.count(old) == 1, f"mutation {what!r}: the text to replace is not found once in {rel}"
            path.write_text(text.replace(old, new))
        CODE = copy
        try:
            results = run_all(root / f"run{i}", " | ".join(patterns), timeout, patterns=patterns)
        finally:
            CODE = original
        found = [r for r in results if r["outcome"] != "clean"]
        out.append({"mutation": what, "cases": len(results), "caught": bool(found),
                    "by": "; ".join(f"{r['case']}: {r['outcome']}" for r in found[:3])})
        print(f"{'caught' if found else 'MISSED':>7}  {what}  ({len(found)} of {len(results)} cases)", flush=True)
    return out


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
             "destructive (a device node, FIFO or symlink at an output path replaced or written through), "
             "data loss (an input changed, or frames the fault does not concern left undone), "
             f"memory (a peak resident size over {MEMORY_FLAG_MB} MB).", "",
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
    ap.add_argument("--mutate", action="store_true",
                    help="check the screen: plant each fault of MUTATIONS in a copy and run its cases (exit 1 when "
                         "one is missed)")
    args = ap.parse_args()
    root = Path(tempfile.mkdtemp(prefix="pnlviz-hostile-"))
    root.chmod(0o755)
    t0 = time.time()
    if args.mutate:
        try:
            found = mutate(root, args.timeout)
        finally:
            unmount_all()
            shutil.rmtree(root, ignore_errors=True)
        missed = [f for f in found if not f["caught"]]
        print(f"{len(found) - len(missed)} of {len(found)} planted faults found in {time.time() - t0:.0f} s")
        raise SystemExit(1 if missed else 0)
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
