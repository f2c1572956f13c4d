"""Training :class:`pnlviz.detect.light.LightNet` on synthetic frames (issue #5).

Data: frames ``0 .. frames - 1`` of ``pnlviz.synth.make_frame(i, data_seed, size)`` are rendered once
(JPEG round trip at the frame's own quality, like the written datasets) and kept in memory as
uint8 images plus their annotations; optionally also in a cache folder (``cache_dir``) so a second
run skips the rendering. Heatmap targets and their loss masks come from
``pnlviz.labels.training_targets`` (left-right disambiguation on), computed on the fly at the
network's input size.

Loss: CenterNet's penalty-reduced focal loss on the probability maps (the 57 keypoint channels of
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

Everything is seeded (``seed`` for the weights, the shuffling and the augmentations;
``data.seed`` for the frames). The checkpoint is a plain state dict written with
``save_checkpoint``; a JSON sidecar (``light.pt`` -> ``light.json``) records the provenance.
"""

from __future__ import annotations

import json
import math
import platform
import random
import time
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import cv2
import numpy as np
import torch

from pnlviz.detect.checkpoint import save_checkpoint
from pnlviz.detect.light import LightNet, sidecar_path

__all__ = ["TrainConfig", "TrainResult", "FrameCache", "load_config", "masked_mse", "train",
           "DEFAULT_CONFIG_PATH"]

DEFAULT_CONFIG_PATH = Path(__file__).resolve().parents[2] / "assets" / "models" / "light_config.json"


@dataclass
class TrainConfig:
    data_seed: int = 5
    frames: int = 1400
    size: tuple[int, int] = (480, 272)  # rendering size (W, H)
    input_size: tuple[int, int] = (480, 272)  # network input size in training, and at inference
    epochs: int = 20
    lr: float = 1e-3
    lr_final: float = 5e-5
    weight_decay: float = 0.0
    batch_size: int = 8
    sigma: float = 2.0
    loss: str = "focal"  # or "mse" (the paper's loss; collapses to empty maps for this network)
    kp_threshold: float = 0.1  # peak thresholds the detector uses with this model (kept in the sidecar)
    line_threshold: float = 0.1
    peak_refine: str = "log"  # sub-pixel peak refinement the detector uses with this model (sidecar)
    calibration: dict = field(default_factory=dict)  # CalibParams overrides for its detections (sidecar)
    seed: int = 0
    threads: int = 2
    augment: dict = field(default_factory=lambda: {"brightness": 0.3, "contrast": 0.3, "saturation": 0.3,
                                                   "gain": 0.08, "noise": 0.03})

    @classmethod
    def from_dict(cls, d: dict) -> "TrainConfig":
        d = dict(d)
        data = d.pop("data", {}) or {}
        kw: dict = {}
        if "seed" in data:
            kw["data_seed"] = int(data["seed"])
        if "frames" in data:
            kw["frames"] = int(data["frames"])
        if "size" in data:
            kw["size"] = tuple(int(v) for v in data["size"])
        known = {f for f in cls.__dataclass_fields__}
        for k, v in d.items():
            if k.startswith("_") or k in ("comment", "estimate"):
                continue
            if k not in known:
                raise ValueError(f"unknown training config key {k!r}")
            kw[k] = tuple(int(x) for x in v) if k in ("size", "input_size") else v
        cfg = cls(**kw)
        if "input_size" not in d and "size" in data:
            cfg.input_size = cfg.size
        return cfg

    def to_dict(self) -> dict:
        d = asdict(self)
        out = {"data": {"seed": d.pop("data_seed"), "frames": d.pop("frames"), "size": list(d.pop("size"))}}
        d["input_size"] = list(d["input_size"])
        out.update(d)
        return out


def load_config(path: str | Path | None = None) -> TrainConfig:
    path = Path(path) if path is not None else DEFAULT_CONFIG_PATH
    return TrainConfig.from_dict(json.loads(Path(path).read_text()))


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
                f = make_frame(i, seed, tuple(size))
                ok, jpg = cv2.imencode(".jpg", f["image"], [cv2.IMWRITE_JPEG_QUALITY, int(f["jpeg_quality"])])
                image = cv2.imdecode(jpg, cv2.IMREAD_COLOR) if ok else f["image"]
                annotation = f["annotation"]
                if path is not None:
                    tmp = path.with_suffix(".tmp.npz")
                    np.savez(tmp, image=image, annotation=np.array(json.dumps(annotation)))
                    tmp.replace(path)
            self.images.append(image)
            self.annotations.append(_annotation_arrays(annotation))

    def __len__(self) -> int:
        return len(self.images)

    def sample(self, i: int, input_size: tuple[int, int], sigma: float = 2.0, flip: bool = False):
        """(RGB float32 (3, H, W) in [0, 1], keypoints (58, h, w), kp mask (58,), lines (24, h, w),
        line mask (24,)) at ``input_size``; ``flip``: of the horizontally flipped frame."""
        from pnlviz.labels import flip_annotation, training_targets

        W, H = input_size
        img = self.images[i]
        annotation = self.annotations[i]
        if (img.shape[1], img.shape[0]) != (W, H):
            img = cv2.resize(img, (W, H), interpolation=cv2.INTER_AREA if img.shape[1] > W else cv2.INTER_LINEAR)
        if flip:
            img = img[:, ::-1]
            annotation = flip_annotation(annotation)
        x = np.ascontiguousarray(img[:, :, ::-1].transpose(2, 0, 1), dtype=np.float32) / 255.0
        _, _, t = training_targets(annotation, W, H, sigma=sigma)
        # The network answers at ceil(H/2) x ceil(W/2); the targets are floor: pad odd sizes.
        h, w = (H + 1) // 2, (W + 1) // 2
        kp, lines = t.keypoints, t.lines
        if kp.shape[1:] != (h, w):
            kp = np.pad(kp, ((0, 0), (0, h - kp.shape[1]), (0, w - kp.shape[2])))
            kp[-1, t.keypoints.shape[1]:, :] = 1.0
            kp[-1, :, t.keypoints.shape[2]:] = 1.0
            lines = np.pad(lines, ((0, 0), (0, h - lines.shape[1]), (0, w - lines.shape[2])))
        return x, kp, t.keypoint_mask, lines, t.line_mask


def _batch(cache: FrameCache, idx, input_size, sigma, flips=None):
    flips = np.zeros(len(idx), bool) if flips is None else flips
    items = [cache.sample(int(i), input_size, sigma, bool(f)) for i, f in zip(idx, flips)]
    return [torch.from_numpy(np.stack(col)) for col in zip(*items)]


def augment(x: torch.Tensor, params: dict, gen: torch.Generator) -> torch.Tensor:
    """Colour jitter + Gaussian noise on an RGB batch in [0, 1] (B, 3, H, W)."""
    B = x.shape[0]

    def factor(name):
        a = float(params.get(name, 0.0))
        return 1.0 + (torch.rand(B, 1, 1, 1, generator=gen) * 2 - 1) * a

    if params.get("brightness"):
        x = x * factor("brightness")
    if params.get("contrast"):
        mean = x.mean(dim=(1, 2, 3), keepdim=True)
        x = (x - mean) * factor("contrast") + mean
    if params.get("saturation"):
        gray = (0.299 * x[:, 0:1] + 0.587 * x[:, 1:2] + 0.114 * x[:, 2:3])
        x = (x - gray) * factor("saturation") + gray
    if params.get("gain"):
        g = float(params["gain"])
        x = x * (1.0 + (torch.rand(B, 3, 1, 1, generator=gen) * 2 - 1) * g)
    if params.get("noise"):
        std = torch.rand(B, 1, 1, 1, generator=gen) * float(params["noise"])
        x = x + torch.randn(x.shape, generator=gen) * std
    return x.clamp_(0.0, 1.0)


# -- loss ----------------------------------------------------------------------------------------
def masked_mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean over the kept (B, C) channels of the per-channel mean squared error."""
    per_channel = (pred - target).square().mean(dim=(2, 3))
    return (per_channel * mask).sum() / mask.sum().clamp_min(1.0)


def peak_pixels(target: torch.Tensor, floor: float = 0.5) -> torch.Tensor:
    """The positives of the focal loss: pixels that are the 3x3 maximum of a target Gaussian
    reaching ``floor`` (one pixel per Gaussian, the one nearest its sub-pixel centre)."""
    return (target >= torch.nn.functional.max_pool2d(target, 3, 1, 1)) & (target >= floor)


def focal_heatmap_loss(p: torch.Tensor, log_p: torch.Tensor, log_1mp: torch.Tensor, target: torch.Tensor,
                       mask: torch.Tensor, pos: torch.Tensor, alpha: float = 2.0, beta: float = 4.0
                       ) -> torch.Tensor:
    """CenterNet's penalty-reduced pixel-wise focal loss (Law & Deng 2018, Zhou et al. 2019) on
    probability maps ``p`` (B, C, h, w), with their logs given for numerical stability: positives
    ``pos`` pull p to 1, every other pixel pushes p to 0 with weight (1 - target)^beta (so the
    Gaussian's shoulders are barely penalised); summed over kept channels, divided by the number of
    positives. Unlike a plain MSE it cannot be minimised by an empty map (issue #5: the MSE run
    collapsed to the background)."""
    m = mask[:, :, None, None]
    pos_f = pos.to(p.dtype) * m
    pos_loss = -((1 - p) ** alpha * log_p * pos_f).sum()
    neg_w = (1 - target).clamp_min(0) ** beta * (1 - pos.to(p.dtype)) * m
    neg_loss = -((p ** alpha) * log_1mp * neg_w).sum()
    return (pos_loss + neg_loss) / pos_f.sum().clamp_min(1.0)


def loss_fn(net: LightNet, x, kp_t, kp_m, ln_t, ln_m, kind: str = "focal") -> torch.Tensor:
    kp_logits, ln_logits = net.logits(x)
    if kind == "mse":
        return (masked_mse(torch.softmax(kp_logits, dim=1), kp_t, kp_m)
                + masked_mse(torch.sigmoid(ln_logits), ln_t, ln_m))
    if kind != "focal":
        raise ValueError(f"unknown loss {kind!r} (focal or mse)")
    # keypoints: the 57 keypoint channels of the softmax (the background is their complement)
    log_sm = torch.log_softmax(kp_logits, dim=1)[:, :-1]
    p = log_sm.exp()
    log_1mp = torch.log1p(-p.clamp(max=1 - 1e-6))
    kp_t, kp_m = kp_t[:, :-1], kp_m[:, :-1]
    kp_loss = focal_heatmap_loss(p, log_sm, log_1mp, kp_t, kp_m, peak_pixels(kp_t))
    # lines: the 23 extremity channels (two peaks each), and the line-body ridge channel as its own
    # term. Normalised together, the body's hundreds of ridge pixels per frame outnumbered the ~2
    # positives per extremity channel and starved those channels (issue #5: line-end peaks reached
    # 0.29 on average, 4 % above the 0.6 threshold).
    sig = torch.nn.functional.logsigmoid
    z, t, m = ln_logits[:, :-1], ln_t[:, :-1], ln_m[:, :-1]
    ln_loss = focal_heatmap_loss(torch.sigmoid(z), sig(z), sig(-z), t, m, peak_pixels(t))
    z, t, m = ln_logits[:, -1:], ln_t[:, -1:], ln_m[:, -1:]
    ln_loss = ln_loss + focal_heatmap_loss(torch.sigmoid(z), sig(z), sig(-z), t, m, t >= 0.8)
    return kp_loss + ln_loss


# -- loop ----------------------------------------------------------------------------------------
def _seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % (2 ** 32))
    torch.manual_seed(seed)


def write_sidecar(weights: Path, info: dict) -> Path:
    path = sidecar_path(weights)
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(info, indent=2) + "\n")
    tmp.replace(path)
    return path


def train(config: TrainConfig, out: str | Path, *, minutes: float | None = None, progress: bool = True,
          cache_dir: str | Path | None = None, log: Callable[[str], None] | None = print,
          cache: FrameCache | None = None) -> TrainResult:
    """Train a LightNet with ``config`` and save it to ``out`` (+ sidecar). ``minutes`` bounds the
    training time (rendering excluded): the loop stops after the step that crosses it and saves."""
    out = Path(out)
    log = log or (lambda s: None)
    if config.threads:
        torch.set_num_threads(int(config.threads))
    torch.set_flush_denormal(True)  # tiny heatmap gradients otherwise hit slow denormal arithmetic
    _seed_everything(config.seed)
    t_render = time.perf_counter()
    if cache is None:
        cache = FrameCache(config.frames, config.data_seed, tuple(config.size), cache_dir, progress)
    render_s = time.perf_counter() - t_render
    if len(cache) == 0:
        raise ValueError("no training frames")
    net = LightNet()
    net.train()
    run = _train_loop(net, cache, config, None if minutes is None else float(minutes) * 60.0, progress, log)
    torch.set_flush_denormal(False)  # back to torch's default for the rest of the process
    net.eval()
    save_checkpoint(net, out)
    info = _provenance(config, cache, net, run, render_s)
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


def _train_loop(net: LightNet, cache: FrameCache, config: TrainConfig, budget: float | None, progress: bool,
                log: Callable[[str], None]) -> _Run:
    """Adam with a cosine learning rate over ``config.epochs`` epochs of shuffled batches, until
    ``budget`` seconds have passed (None: no limit)."""
    from tqdm import tqdm

    opt = torch.optim.Adam(net.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    bs = max(1, min(int(config.batch_size), len(cache)))
    steps_per_epoch = math.ceil(len(cache) / bs)
    total_steps = max(1, steps_per_epoch * int(config.epochs))
    rng = np.random.default_rng(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    flip_p = float((config.augment or {}).get("flip", 0.0))
    run = _Run([], 0, False, 0.0, [], 0.0, bs)
    t0 = time.perf_counter()
    bar = tqdm(total=total_steps, desc="train", unit="step", disable=not progress)
    for epoch in range(int(config.epochs)):
        order = rng.permutation(len(cache))
        losses = []
        for b in range(steps_per_epoch):
            t_step = time.perf_counter()
            idx = order[b * bs:(b + 1) * bs]
            # drawn only when flipping is on, so a run without it keeps its exact shuffling
            flips = rng.random(len(idx)) < flip_p if flip_p > 0 else None
            x, kp_t, kp_m, ln_t, ln_m = _batch(cache, idx, tuple(config.input_size), config.sigma, flips)
            x = augment(x, config.augment or {}, gen)
            cosine = 0.5 * (1 + math.cos(math.pi * min(run.steps, total_steps) / total_steps))
            for g in opt.param_groups:
                g["lr"] = config.lr_final + (config.lr - config.lr_final) * cosine
            loss = loss_fn(net, x, kp_t, kp_m, ln_t, ln_m, config.loss)
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


def _provenance(config: TrainConfig, cache: FrameCache, net: LightNet, run: _Run, render_s: float) -> dict:
    """The sidecar written next to the weights: what was trained, on what, how long."""
    return {
        "model": "LightNet",
        "module": "pnlviz.detect.light",
        "input_size": list(config.input_size),
        "kp_threshold": float(config.kp_threshold),
        "line_threshold": float(config.line_threshold),
        "peak_refine": str(config.peak_refine),
        "calibration": dict(config.calibration),
        "config": config.to_dict(),
        "seed": config.seed,
        "data": {"generator": "pnlviz.synth.make_frame", "seed": config.data_seed, "frames": len(cache),
                 "size": list(config.size)},
        "epochs_planned": int(config.epochs),
        "epochs": round(run.epochs_done, 3),
        "steps": run.steps,
        "frames": len(cache),
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
