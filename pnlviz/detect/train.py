"""Training :class:`pnlviz.detect.light.LightNet` on synthetic frames (issue #5), mixed with real
ones (issue #13: :func:`build_sources`, :mod:`pnlviz.detect.train_data`; an epoch draws from each
source by its weight, :func:`epoch_plan`), optionally from given weights (``init``).

Synthetic data: frames ``0 .. frames - 1`` of ``pnlviz.synth.make_frame(i, data_seed, size)`` are rendered once
(JPEG round trip at the frame's own quality, like the written datasets) and kept in memory as
uint8 images plus their annotations; optionally also in a cache folder (``cache_dir``) so a second
run skips the rendering. Heatmap targets and their loss masks come from
``pnlviz.labels.training_targets`` (left-right disambiguation on), computed on the fly at the
network's input size.

Loss (:mod:`pnlviz.detect.train_loss`): CenterNet's penalty-reduced focal loss on the probability maps (the 57 keypoint channels of
the softmax; the 23 line-extremity channels and the line-body channel of the sigmoid), positives at
the pixel nearest each target Gaussian's centre, channels kept by the masks (keypoint mask per
frame; the line mask keeps all), keypoint loss + line loss. The paper's loss (Sec. III-B, mean
squared error between heatmaps and targets) is available as ``loss: "mse"``; with this small
network it collapsed to empty maps (peaks <= 0.035 after a full 58-minute run), because an empty
map is already within 1e-3 of its optimum.

Optimiser: Adam with a cosine learning-rate decay over the planned steps. Augmentations: colour
jitter (brightness, contrast, saturation, per-channel gain) and Gaussian noise; optionally a
horizontal flip (``augment.flip``: its probability), whose targets come from the flipped
annotation (:func:`pnlviz.labels.flip_annotation`: x -> 1 - x and left/right class names swapped,
so the keypoint and line ids follow).

The configuration: :mod:`pnlviz.detect.train_config`. Everything is seeded (``seed`` for the weights, the shuffling and the augmentations;
``data.seed`` for the frames). The checkpoint is a plain state dict written with
``save_checkpoint``; a JSON sidecar (``light.pt`` -> ``light.json``) records the provenance.
"""

from __future__ import annotations

import json
import math
import platform
import random
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from collections.abc import Sequence
from typing import Any, Callable, Protocol

import cv2
import numpy as np
import torch

from pnlviz.detect.checkpoint import save_checkpoint
from pnlviz.detect.light import LightNet, sidecar_path
from pnlviz.detect.train_data import (AnnotatedFrames, ExportedFrames, HomographyFrames, View, annotation_example,
                                     draw_view)

from pnlviz.detect.train_config import TrainConfig, resolve_path
from pnlviz.detect.train_loss import augment, loss_fn
from pnlviz.labels.resize import resize_annotation

__all__ = ["FrameCache", "Source", "TrainResult", "build_sources", "epoch_plan", "train", "write_sidecar"]


class TrainFrames(Protocol):
    """Frames to train on: :class:`FrameCache`, ``HomographyFrames``, ``AnnotatedFrames`` or
    ``ExportedFrames`` (:mod:`pnlviz.detect.train_data`)."""

    def __len__(self) -> int: ...

    def sample(self, i: int, input_size: tuple[int, int], sigma: float = ..., view: View = ...) -> Any: ...


def _pair(size: Sequence[int]) -> tuple[int, int]:
    """A ``(W, H)`` size as a tuple (a ValueError unless it has two items)."""
    w, h = size
    return w, h


@dataclass
class Source:
    """One source of training frames, its share of an epoch and its augmentation overrides."""

    name: str
    frames: TrainFrames
    weight: float
    augment: dict

    def __len__(self) -> int:
        return len(self.frames)


def build_sources(config: TrainConfig, *, cache: "FrameCache | None" = None, cache_dir: str | Path | None = None,
                  progress: bool = True) -> list[Source]:
    """The training sources of ``config``: the synthetic frames (``data``; ``cache`` when given) and
    every entry of ``real``:

    * ``{"kind": "homography", "path": image folder, "homographies": json (default
      path/homographies.json), "source_size": [1280, 720], "exclude": [stems], "paint_fit": false
      (each homography brought onto its image's paint first), "weight", "augment"}``;
    * ``{"kind": "soccernet", "path": dataset folder or zip, "exclude": [stems], "weight", "augment"}``;
    * ``{"kind": "labels", "path": a pnlviz export (folder or zip), "images": the dataset it was
      made on, "exclude", "weight", "augment"}``.
    """
    base = dict(config.augment or {})
    real: list[Source] = []  # read first: a bad path fails before minutes of rendering
    for k, entry in enumerate(config.real or []):
        entry = dict(entry)
        kind = entry.get("kind")
        if "path" not in entry:
            raise ValueError(f"real source {k}: no 'path'")
        path = resolve_path(entry["path"], config.base_dir)
        exclude = [str(s) for s in entry.get("exclude", [])]
        frames: TrainFrames
        if kind == "homography":
            hom = entry.get("homographies")
            frames = HomographyFrames(path, resolve_path(hom, config.base_dir) if hom else None,
                                      source_size=_pair(entry.get("source_size", (1280, 720))), exclude=exclude,
                                      paint_fit=bool(entry.get("paint_fit", False)))
        elif kind == "soccernet":
            frames = AnnotatedFrames(path, exclude=exclude)
        elif kind == "labels":
            if "images" not in entry:
                raise ValueError(f"real source {k}: exported labels need 'images' (the dataset they were made on)")
            frames = ExportedFrames(path, resolve_path(entry["images"], config.base_dir), exclude=exclude)
        else:
            raise ValueError(f"real source {k}: unknown kind {kind!r} (homography, soccernet or labels)")
        real.append(Source(f"{kind} {entry['path']}", frames, float(entry.get("weight", 1.0)),
                           {**base, **dict(entry.get("augment", {}))}))
    sources: list[Source] = []
    if cache is None and config.frames > 0:
        cache = FrameCache(config.frames, config.data_seed, _pair(config.size), cache_dir, progress)
    if cache is not None and len(cache):
        sources.append(Source(f"synthetic seed {config.data_seed}", cache, float(config.data_weight), base))
    sources += real
    if not sources:
        raise ValueError("no training frames")
    if any(s.weight <= 0 for s in sources):
        raise ValueError("source weights must be > 0")
    return sources


def epoch_plan(sources: list[Source], rng: np.random.Generator, epoch_frames: int | None = None
               ) -> list[tuple[int, int]]:
    """The ``(source, frame)`` order of one epoch: ``epoch_frames`` samples (default: every frame
    of every source once), each source's share by its weight (its frames cycled in fresh random
    orders when it has fewer), shuffled. One source: a permutation of its frames."""
    if len(sources) == 1 and epoch_frames is None:
        return [(0, int(i)) for i in rng.permutation(len(sources[0]))]
    total = int(epoch_frames or sum(len(s) for s in sources))
    weights = np.array([s.weight for s in sources], float)
    counts = np.floor(total * weights / weights.sum()).astype(int)
    counts[np.argmax(weights)] += total - counts.sum()
    plan: list[tuple[int, int]] = []
    for k, (src, n) in enumerate(zip(sources, counts)):
        idx: list[int] = []
        while len(idx) < n:
            idx.extend(int(i) for i in rng.permutation(len(src)))
        plan.extend((k, i) for i in idx[:n])
    return [plan[j] for j in rng.permutation(len(plan))]


@dataclass
class TrainResult:
    path: Path
    history: list[float]  # mean training loss per (possibly partial) epoch
    final_loss: float
    epochs_done: float  # fractional when stopped by the time budget
    steps: int
    seconds: float
    seconds_per_step: float
    stopped_early: bool


# -- data ----------------------------------------------------------------------------------------
def _annotation_arrays(annotation: dict) -> dict[str, np.ndarray]:
    return {k: np.array([[p["x"], p["y"]] for p in v], float).reshape(-1, 2) for k, v in annotation.items()}


class FrameCache:
    """Rendered synthetic frames (uint8 BGR at the rendering size) and their annotations."""

    def __init__(self, frames: int, seed: int, size: tuple[int, int], cache_dir: str | Path | None = None,
                 progress: bool = True) -> None:
        from tqdm import tqdm

        from pnlviz.synth import make_frame
        from pnlviz.synth.cameras import EVAL_SIZE

        self.images: list[np.ndarray] = []
        self.annotations: list[dict[str, np.ndarray]] = []
        folder = None
        if cache_dir is not None:
            folder = Path(cache_dir) / f"seed{seed}_{size[0]}x{size[1]}"
            folder.mkdir(parents=True, exist_ok=True)
        for i in tqdm(range(frames), desc="render", unit="frame", disable=not progress, leave=False):
            path = folder / f"{i:06d}.npz" if folder is not None else None
            if path is not None and path.is_file():
                with np.load(path) as z:
                    image = z["image"]
                    annotation = json.loads(str(z["annotation"]))
            else:
                f = make_frame(i, seed, _pair(size))
                ok, jpg = cv2.imencode(".jpg", f["image"], [cv2.IMWRITE_JPEG_QUALITY, int(f["jpeg_quality"])])
                image = f["image"]
                if ok:
                    decoded = cv2.imdecode(jpg, cv2.IMREAD_COLOR)
                    assert decoded is not None  # what cv2 has just encoded
                    image = decoded
                annotation = f["annotation"]
                if path is not None:
                    tmp = path.with_suffix(".tmp.npz")
                    np.savez(tmp, image=image, annotation=np.array(json.dumps(annotation)))
                    tmp.replace(path)
            self.images.append(image)
            # the annotation is made at 960x540 by the camera the frame was rendered through, scaled
            # (pnlviz.synth.annotate.evaluation_camera): read at the render's size the same way
            self.annotations.append(resize_annotation(_annotation_arrays(annotation), EVAL_SIZE, _pair(size), "index"))

    def __len__(self) -> int:
        return len(self.images)

    def sample(self, i: int, input_size: tuple[int, int], sigma: float = 2.0, view: View | None = None):
        """(RGB float32 (3, H, W) in [0, 1], keypoints (58, h, w), kp mask (58,), lines (24, h, w),
        line mask (24,)) at ``input_size``, drawn through ``view`` (flip, zoom, blur, JPEG)."""
        return annotation_example(self.images[i], self.annotations[i], input_size, sigma, view or View())


def _batch(items: list, input_size, sigma):
    """Stack ``(source, index, view)`` examples into tensors."""
    rows = [src.sample(int(i), input_size, sigma, view) for src, i, view in items]
    return [torch.from_numpy(np.stack(col)) for col in zip(*rows)]



# -- loop ----------------------------------------------------------------------------------------
def _seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % (2 ** 32))
    torch.manual_seed(seed)


def _sha256(path: str | Path) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def write_sidecar(weights: Path, info: dict) -> Path:
    path = sidecar_path(weights)
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(info, indent=2) + "\n")
    tmp.replace(path)
    return path


def train(config: TrainConfig, out: str | Path, *, minutes: float | None = None, progress: bool = True,
          cache_dir: str | Path | None = None, log: Callable[[str], None] | None = print,
          cache: FrameCache | None = None, init: str | Path | None = None) -> TrainResult:
    """Train a LightNet with ``config`` and save it to ``out`` (+ sidecar). ``minutes`` bounds the
    training time (rendering excluded): the loop stops after the step that crosses it and saves.
    ``init`` (or ``config.init``): a LightNet checkpoint to start from."""
    out = Path(out)
    log = log or (lambda s: None)
    threads = torch.get_num_threads()
    if config.threads:
        torch.set_num_threads(int(config.threads))
    torch.set_flush_denormal(True)  # tiny heatmap gradients otherwise hit slow denormal arithmetic
    try:
        return _train(config, out, minutes, progress, cache_dir, log, cache, init)
    finally:  # the process's own settings back, whatever happened
        torch.set_flush_denormal(False)
        torch.set_num_threads(threads)


def _train(config: TrainConfig, out: Path, minutes, progress, cache_dir, log, cache, init) -> TrainResult:
    _seed_everything(config.seed)
    t_render = time.perf_counter()
    sources = build_sources(config, cache=cache, cache_dir=cache_dir, progress=progress)
    render_s = time.perf_counter() - t_render
    for src in sources:
        log(f"source {src.name}: {len(src)} frames, weight {src.weight:g}")
    # recorded as given: on the command line, or as the config names it (relative to the config)
    init_label = str(init) if init is not None else config.init
    init = init if init is not None else (str(resolve_path(config.init, config.base_dir)) if config.init else None)
    net = LightNet()
    if init is not None:
        from pnlviz.detect.checkpoint import load_checkpoint

        load_checkpoint(net, init)
        log(f"starting from {init}")
    net.train()
    run = _train_loop(net, sources, config, None if minutes is None else float(minutes) * 60.0, progress, log)
    net.eval()
    out.parent.mkdir(parents=True, exist_ok=True)
    save_checkpoint(net, out)
    info = _provenance(config, sources, net, run, render_s, init, init_label)
    write_sidecar(out, info)
    per_step = run.seconds / max(1, run.steps)
    log(f"saved {out} (+ {sidecar_path(out).name}); final loss {info['final_loss']:.6f}, "
        f"{run.seconds:.0f} s, {per_step:.3f} s/step")
    return TrainResult(out, run.history, info["final_loss"], run.epochs_done, run.steps, run.seconds, per_step,
                       run.stopped)


@dataclass
class _Run:
    """What the training loop did."""

    history: list[float]  #: mean loss of each epoch
    steps: int
    stopped: bool  #: by the time budget
    epochs_done: float
    step_times: list[float]
    seconds: float
    batch_size: int


def _train_loop(net: LightNet, sources: list[Source], config: TrainConfig, budget: float | None, progress: bool,
                log: Callable[[str], None]) -> _Run:
    """Adam with a cosine learning rate over ``config.epochs`` epochs of shuffled batches, until
    ``budget`` seconds have passed (None: no limit)."""
    from tqdm import tqdm

    opt = torch.optim.Adam(net.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    epoch_len = int(config.epoch_frames or sum(len(s) for s in sources))
    bs = max(1, min(int(config.batch_size), epoch_len))
    steps_per_epoch = math.ceil(epoch_len / bs)
    total_steps = max(1, steps_per_epoch * int(config.epochs))
    rng = np.random.default_rng(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    size = _pair(config.input_size)
    run = _Run([], 0, False, 0.0, [], 0.0, bs)
    t0 = time.perf_counter()
    bar = tqdm(total=total_steps, desc="train", unit="step", disable=not progress)
    for epoch in range(int(config.epochs)):
        order = epoch_plan(sources, rng, config.epoch_frames)
        losses = []
        for b in range(steps_per_epoch):
            t_step = time.perf_counter()
            items = [(sources[k].frames, i, draw_view(sources[k].augment, rng, size))
                     for k, i in order[b * bs:(b + 1) * bs]]
            x, kp_t, kp_m, ln_t, ln_m = _batch(items, size, config.sigma)
            x = augment(x, config.augment or {}, gen)
            cosine = 0.5 * (1 + math.cos(math.pi * min(run.steps, total_steps) / total_steps))
            for g in opt.param_groups:
                g["lr"] = config.lr_final + (config.lr - config.lr_final) * cosine
            loss = loss_fn(net, x, kp_t, kp_m, ln_t, ln_m, config.loss)
            if not math.isfinite(float(loss.detach())):  # stop before the weights turn NaN: no checkpoint
                raise ValueError(f"training diverged: the loss is {float(loss.detach())} at step {run.steps + 1} "
                                 f"(epoch {epoch + 1}); no checkpoint written (check sigma, lr and the data)")
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            run.steps += 1
            run.step_times.append(time.perf_counter() - t_step)
            losses.append(float(loss.detach()))
            bar.update(1)
            bar.set_postfix(epoch=epoch + 1, loss=f"{losses[-1]:.5f}")
            if budget is not None and time.perf_counter() - t0 >= budget:
                run.stopped = True
                break
        run.history.append(float(np.mean(losses)))
        run.epochs_done = epoch + len(losses) / steps_per_epoch
        log(f"epoch {epoch + 1}/{config.epochs}: loss {run.history[-1]:.6f} "
            f"({time.perf_counter() - t0:.0f} s, {run.steps} steps)")
        if run.stopped:
            break
    bar.close()
    run.seconds = time.perf_counter() - t0
    return run


def _provenance(config: TrainConfig, sources: list[Source], net: LightNet, run: _Run, render_s: float,
                init: str | Path | None, init_label: str | None) -> dict:
    """The sidecar written next to the weights: what was trained, on what, how long."""
    return {
        "model": "LightNet",
        "module": "pnlviz.detect.light",
        "input_size": list(config.input_size),
        "kp_threshold": float(config.kp_threshold),
        "line_threshold": float(config.line_threshold),
        "peak_refine": str(config.peak_refine),
        "second_look": None if config.second_look is None else dict(config.second_look),
        "calibration": dict(config.calibration),
        "config": config.to_dict(),
        "seed": config.seed,
        "data": {"generator": "pnlviz.synth.make_frame", "seed": config.data_seed, "frames": config.frames,
                 "size": list(config.size)},
        "sources": [{"name": s.name, "frames": len(s), "weight": s.weight} for s in sources],
        "init": None if init is None else {"path": init_label, "sha256": _sha256(init)},
        "epochs_planned": int(config.epochs),
        "epochs": round(run.epochs_done, 3),
        "steps": run.steps,
        "frames": sum(len(s) for s in sources),
        "loss_history": [round(v, 7) for v in run.history],
        "final_loss": run.history[-1] if run.history else None,
        "stopped_by_time_budget": run.stopped,
        "train_seconds": round(run.seconds, 1),
        "render_seconds": round(render_s, 1),
        "seconds_per_step": round(run.seconds / max(1, run.steps), 4),
        "seconds_per_step_median": round(float(np.median(run.step_times)), 4) if run.step_times else None,
        "batch_size": run.batch_size,
        "parameters": sum(p.numel() for p in net.parameters()),
        "torch": torch.__version__,
        "python": platform.python_version(),
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
