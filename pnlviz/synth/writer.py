"""Write synthetic frames to a folder: images, SoccerNet annotations, ground-truth cameras.

Layout (nothing else is written)::

    DIR/NNNNN.jpg                   the rendered frame (JPEG, quality 60-95)
    DIR/NNNNN.json                  line annotation {class: [{"x": .., "y": ..}, ...]}
    DIR/cameras/camera_NNNNN.json   ground-truth camera (SoccerNet camera JSON)

Stems are 5-digit frame indices starting at ``start_index``. Every file is written atomically
(a temporary file in the same folder, then ``os.replace``), so an interrupted run leaves whole
files only; leftover temporaries of a killed run are removed by the next run.

Cameras are stored at the 960 x 540 evaluation scale (``camera.scaled(960, 540).to_soccernet()``)
whatever the image size, because the official evaluator takes the image size from the principal
point (width = 2 x principal_point[0]) and evaluates at 960 x 540; the rendered size is kept in
the extra key ``"synth": {"kind": ..., "image_size": [W, H]}``. Annotations are normalised at
that scale too (``x_px = x * (960 - 1)``).

Frame ``i`` of seed ``s`` is made from ``np.random.default_rng([s, i])`` alone (camera, scene,
noise, annotation clicks, JPEG quality, in that order), so the output does not depend on the
number of worker processes or on which frames are generated together.
"""

from __future__ import annotations

import json
import os
import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pnlviz.conventions import EVAL_SIZE
from pnlviz.data.atomic import atomic_write_bytes

from .annotate import EVAL_H, EVAL_W, annotate, annotation_to_json
from .cameras import sample_camera
from .render import render_frame

CAMERA_DIR = "cameras"
STEM_DIGITS = 5
_STEM = r"(?:\d{5,}|clip\d+-IMG_\d{4,})"  # a frame, or a frame of a clip (pnlviz.synth.clip)
_IMAGE_RE = re.compile(rf"^{_STEM}\.jpg$")
_ANNOTATION_RE = re.compile(rf"^{_STEM}\.json$")
_CAMERA_RE = re.compile(rf"^camera_{_STEM}\.json$")
_FRAME_CAMERA_RE = re.compile(rf"^camera_\d{{{STEM_DIGITS},}}\.json$")  # a plain frame's (not a clip's)
# Temporaries of pnlviz.data.atomic: ".<name>.<random>.tmp" next to the target.
_TEMP_RE = re.compile(rf"^\.({_STEM}\.(jpg|json)|camera_{_STEM}\.json)\..+\.tmp$")
OPTIONAL_FILES = ("match_info.json",)


class OutputFolderError(RuntimeError):
    """The output folder holds files that are not a previous synthetic output."""


@dataclass(frozen=True)
class SynthSummary:
    out_dir: Path
    frames: int
    seconds: float

    @property
    def frames_per_second(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else float("inf")


def frame_stem(index: int) -> str:
    return f"{index:0{STEM_DIGITS}d}"


def foreign_entries(out_dir: str | os.PathLike) -> list[str]:
    """Entries of ``out_dir`` that a synthetic output would not hold (relative paths)."""
    root = Path(out_dir)
    if not root.exists():
        return []
    foreign = []
    for entry in sorted(root.iterdir()):
        name = entry.name
        if entry.is_dir() and name == CAMERA_DIR:
            foreign += [f"{CAMERA_DIR}/{e.name}" for e in sorted(entry.iterdir())
                        if not (e.is_file() and (_CAMERA_RE.match(e.name) or _TEMP_RE.match(e.name)))]
        elif not (entry.is_file() and (_IMAGE_RE.match(name) or _ANNOTATION_RE.match(name)
                                       or _TEMP_RE.match(name) or name in OPTIONAL_FILES)):
            foreign.append(name + ("/" if entry.is_dir() else ""))
    return foreign


def check_output_folder(out_dir: str | os.PathLike, force: bool = False, *, seed: int | None = None,
                        size: tuple[int, int] | None = None) -> None:
    """Refuse (``OutputFolderError``) a non-empty folder that is not a previous synthetic output,
    and a previous output of frames of another ``seed`` or ``size`` (extending it would mix two
    sets under one numbering), unless ``force``. A file in the way of the folder itself is
    always refused."""
    root = Path(out_dir)
    if root.exists() and not root.is_dir():
        raise OutputFolderError(f"{root} exists and is not a folder")
    if force:
        return
    foreign = foreign_entries(root)
    if foreign:
        listed = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise OutputFolderError(f"{root} is not empty and is not a synthetic output (it holds {listed}); "
                                "choose an empty folder or pass --force")
    if seed is None or size is None:
        return
    for made in _frames_made(root):
        if made != (int(seed), (int(size[0]), int(size[1]))):
            what = "an unknown seed" if made[0] is None else f"seed {made[0]} at {made[1][0]}x{made[1][1]}"
            raise OutputFolderError(f"{root} holds synthetic frames of {what}; this run makes seed {seed} at "
                                    f"{size[0]}x{size[1]}: the folder would mix two sets under one numbering; "
                                    "choose another folder or pass --force")


def _frames_made(root: Path) -> set[tuple]:
    """(seed, (width, height)) of the plain frames already in ``root`` (their first and last
    camera files; seed None when a file does not record it), not of clip frames."""
    folder = root / CAMERA_DIR
    if not folder.is_dir():
        return set()
    names = sorted(e.name for e in folder.iterdir() if _FRAME_CAMERA_RE.match(e.name))
    made = set()
    for name in {names[0], names[-1]} if names else set():
        try:
            synth = json.loads((folder / name).read_text()).get("synth") or {}
            w, h = synth.get("image_size") or (None, None)
            made.add((synth.get("seed"), (w, h)))
        except (OSError, ValueError, TypeError, AttributeError):
            made.add((None, (None, None)))
    return made


def _remove_stale_temporaries(root: Path) -> None:
    for folder in (root, root / CAMERA_DIR):
        if folder.is_dir():
            for entry in folder.iterdir():
                if entry.is_file() and _TEMP_RE.match(entry.name):
                    entry.unlink(missing_ok=True)


def _dumps(obj) -> bytes:
    return (json.dumps(obj, indent=1, allow_nan=False) + "\n").encode()


def make_frame(index: int, seed: int, size: tuple[int, int] = EVAL_SIZE) -> dict:
    """Everything of frame ``index``: ``{"image": BGR uint8, "annotation": dict, "camera": dict,
    "kind": str, "jpeg_quality": int}`` (nothing written)."""
    rng = np.random.default_rng([int(seed), int(index)])
    width, height = size
    camera, kind = sample_camera(rng, width, height)
    image = render_frame(camera, rng)
    annotation = annotate(camera, rng)
    quality = int(rng.integers(60, 96))
    cam_json = camera.scaled(EVAL_W, EVAL_H).to_soccernet()
    cam_json["synth"] = {"kind": kind, "seed": int(seed), "image_size": [int(width), int(height)]}
    return {"image": image, "annotation": annotation_to_json(annotation), "camera": cam_json,
            "kind": kind, "jpeg_quality": quality}


def write_frame(out_dir: str | os.PathLike, index: int, seed: int, size: tuple[int, int] = EVAL_SIZE,
                clip_frames: int | None = None) -> str:
    """Make frame ``index`` (of the clip of ``clip_frames`` frames of ``seed``, when given) and
    write its three files; returns the stem."""
    root = Path(out_dir)
    if clip_frames is not None:
        from .clip import clip_frame

        frame = clip_frame(_clip_plan(seed, clip_frames, (size[0], size[1])), index)
    else:
        frame = make_frame(index, seed, size)
    stem = frame["stem"] if clip_frames is not None else frame_stem(index)
    ok, jpg = cv2.imencode(".jpg", frame["image"], [cv2.IMWRITE_JPEG_QUALITY, frame["jpeg_quality"]])
    if not ok:
        raise RuntimeError(f"JPEG encoding failed for frame {stem}")
    atomic_write_bytes(root / CAMERA_DIR / f"camera_{stem}.json", _dumps(frame["camera"]))
    atomic_write_bytes(root / f"{stem}.json", _dumps(frame["annotation"]))
    atomic_write_bytes(root / f"{stem}.jpg", jpg.tobytes())
    return stem


_PLANS: dict = {}


def _clip_plan(seed: int, frames: int, size: tuple[int, int]):
    """The clip's plan, drawn once per process."""
    from .clip import plan_clip

    key = (int(seed), int(frames), (size[0], size[1]))
    if key not in _PLANS:
        _PLANS.clear()
        _PLANS[key] = plan_clip(*key)
    return _PLANS[key]


def _worker_init() -> None:
    cv2.setNumThreads(1)


def _worker(job: tuple) -> str:
    _worker_init()  # whichever process renders it: one OpenCV thread (the runner's processes are the parallelism)
    return write_frame(*job)


def generate(out_dir: str | os.PathLike, n: int, seed: int, size: tuple[int, int] = EVAL_SIZE,
             start_index: int = 0, progress: bool = True, *, force: bool = False,
             clip: bool = False, run: Callable[[Callable, list], object] | None = None) -> SynthSummary:
    """Write frames ``start_index .. start_index + n - 1`` of ``seed`` into ``out_dir``; with
    ``clip``, the ``n`` frames of clip ``seed`` (:mod:`pnlviz.synth.clip`: pan-tilt-zoom shots and
    cuts, stems ``clip<seed>-IMG_<nnnn>``).

    ``run(fn, jobs)``: how the frames are rendered (``pnlviz synth`` gives the batch runner,
    :func:`pnlviz.commands.batch.map_items`, with its worker processes: the same output); by
    default one after the other here, under a progress bar. Refuses a non-empty folder
    that is not a previous synthetic output of the same seed and size unless ``force`` (see
    :func:`check_output_folder`).
    """
    if n < 0:
        raise ValueError("n must be >= 0")
    if start_index < 0:
        raise ValueError("start_index must be >= 0")
    width, height = (int(v) for v in size)
    if width < 2 or height < 2:
        raise ValueError(f"image size must be at least 2 x 2, got {width} x {height}")
    root = Path(out_dir)
    check_output_folder(root, force, seed=None if clip else int(seed), size=(width, height))
    (root / CAMERA_DIR).mkdir(parents=True, exist_ok=True)
    _remove_stale_temporaries(root)
    jobs: list[tuple]  # write_frame's arguments
    if clip:
        jobs = [(str(root), i, int(seed), (width, height), n) for i in range(n)]
    else:
        jobs = [(str(root), i, int(seed), (width, height)) for i in range(start_index, start_index + n)]
    from tqdm import tqdm

    start = time.perf_counter()
    if run is not None:
        run(_worker, jobs)
    else:
        with tqdm(total=n, desc="synth", unit="frame", disable=not progress) as bar:
            for job in jobs:
                _worker(job)
                bar.update(1)
    return SynthSummary(root, n, time.perf_counter() - start)


__all__ = ["generate", "make_frame", "write_frame", "frame_stem", "check_output_folder", "foreign_entries",
           "OutputFolderError", "SynthSummary", "CAMERA_DIR"]
