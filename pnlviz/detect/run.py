"""Inference: frames -> PnLCalib networks -> heatmaps -> detections (PnLCalib 2D prediction format).

The published networks take RGB in [0, 1] at 960x540 and answer at half resolution; frames of
another size are resized to ``input_size`` first (detections are normalised, so they do not
depend on it). torch is imported here only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import torch

from pnlviz.data.predictions import Predictions
from pnlviz.detect.checkpoint import load_checkpoint
from pnlviz.detect.default import DEFAULT_MODEL, read_sidecar
from pnlviz.detect.light import load_light
from pnlviz.detect.hrnet import PnLCalibNet, keypoint_net, line_net
from pnlviz.detect.peaks import extract_predictions

DEFAULT_INPUT_SIZE = (960, 540)


class NoModelError(ValueError):
    """No weights were given and no default model is installed."""


@dataclass
class Detector:
    """The keypoint and line networks (either may be absent) and the peak extraction settings."""

    kp_net: PnLCalibNet | None
    line_net: PnLCalibNet | None
    input_size: tuple[int, int] = DEFAULT_INPUT_SIZE
    kp_threshold: float = 0.1
    line_threshold: float = 0.1
    #: (keypoint, line) thresholds of a second reading of the heatmaps, at or below the first's,
    #: attached to a frame's detections when it finds more (``Predictions.second``): the light
    #: model's sidecar names them; the reading is kept only where the first gives no camera
    second_look: tuple[float, float] | None = None
    #: How input pixels map back to the frame when the frame was resized. False: ``X = x / s``
    #: (``s`` = input / frame size), PnLCalib's own scaling, kept for its published networks.
    #: True: ``X = (x + 0.5) / s - 0.5``, the exact inverse of ``cv2.resize`` (which aligns pixel
    #: centres), for a network that localises what it sees on its input grid: the light model,
    #: trained on frames rendered at its input size (issue #5: without it the resize moved its
    #: keypoints 0.5 px up-left at 960x540).
    centre_aligned_resize: bool = False
    #: sub-pixel refinement of the heatmap peaks (see :func:`pnlviz.detect.peaks.refine_peaks`):
    #: "log" suits Gaussian-shaped peaks (networks trained on the paper's MSE), "raw" the sharper
    #: peaks of a focal-loss network such as the light model.
    refine: str = "log"
    #: :class:`pnlviz.calib.calibrate.CalibParams` overrides for calibrating from these detections
    #: (``pnlviz detect`` writes them next to its prediction zip; the app applies them).
    calibration: dict = field(default_factory=dict)
    #: where the networks run: "cpu" or a CUDA device ("cuda", "cuda:1"); see :func:`resolve_device`
    device: str = "cpu"
    #: run the networks in float16 (autocast; the heatmaps come back as float32): half the memory
    #: and faster on a GPU, slower on a CPU. ``benchmarks/bench_precision.py`` measures how far
    #: the detections move: with the light model on 48 real frames, 0.11 px at p99; 2 of 1465
    #: points were ties of two peaks a few pixels apart (scores 0.0002 apart) that went the other way
    half: bool = False

    def __post_init__(self) -> None:
        if self.second_look is not None:  # never above the first reading's
            kp, line = (float(v) for v in self.second_look)
            if not (0.0 <= kp <= 1.0 and 0.0 <= line <= 1.0):
                raise ValueError(f"second_look: two thresholds in [0, 1] (keypoints, lines), got {self.second_look!r}")
            self.second_look = (min(kp, self.kp_threshold), min(line, self.line_threshold))
            # a shot fits the first reading alone (pnlviz.calib.looks.for_shot): its thresholds,
            # whatever the sidecar says, travel with the calibration settings as the detections do
            self.calibration = {**self.calibration, "shot_min_score": [self.kp_threshold, self.line_threshold]}
        if self.device != "cpu":
            for net in (self.kp_net, self.line_net):
                if net is not None:
                    net.to(self.device)

    @classmethod
    def from_weights(cls, weights_kp: Path | None, weights_lines: Path | None, *, light: Path | None = None,
                     **kw) -> "Detector":
        """The published networks from their checkpoints, a light model from ``light`` (a LightNet
        checkpoint with its sidecar, e.g. one ``pnlviz train`` wrote), or with no weights the light
        default model shipped in ``assets/models/light.pt`` (one file, both heads)."""
        if kw.get("input_size") is None:  # each network's own: 960x540, or the light model's sidecar
            kw.pop("input_size", None)
        if light is not None:
            if weights_kp is not None or weights_lines is not None:
                raise ValueError("give either a light model or PnLCalib's networks, not both")
            return light_detector(light, **kw)
        if weights_kp is None and weights_lines is None:
            if not DEFAULT_MODEL.exists():
                raise NoModelError(f"no detector weights: pass --weights-kp and/or --weights-lines (PnLCalib's "
                                   f"SV_kp / SV_lines load as they are), or train the default model with "
                                   f"`pnlviz train` ({DEFAULT_MODEL} is missing)")
            return light_detector(DEFAULT_MODEL, **kw)
        kp = line = None
        if weights_kp is not None:
            kp = load_checkpoint(keypoint_net(), weights_kp).eval()
        if weights_lines is not None:
            line = load_checkpoint(line_net(), weights_lines).eval()
        return cls(kp, line, **kw)

    @classmethod
    def for_light_net(cls, net, input_size: tuple[int, int] = DEFAULT_INPUT_SIZE, **kw) -> "Detector":
        """A detector running a :class:`pnlviz.detect.light.LightNet` (eval mode) for both heads."""
        net.eval()
        kw.setdefault("centre_aligned_resize", True)  # trained on frames rendered at its input size
        w, h = input_size
        return cls(net.kp_head_module(), net.line_head_module(), input_size=(w, h), **kw)

    def _tensor(self, images_bgr: list[np.ndarray]) -> torch.Tensor:
        W, H = self.input_size
        batch = [cv2.resize(img, (W, H), interpolation=cv2.INTER_AREA if img.shape[1] > W else cv2.INTER_LINEAR)
                 [:, :, ::-1].astype(np.float32) / 255.0 for img in images_bgr]
        return torch.from_numpy(np.stack(batch)).permute(0, 3, 1, 2).contiguous().to(self.device)

    @torch.inference_mode()
    def heatmaps(self, images_bgr: list[np.ndarray]) -> tuple[np.ndarray | None, np.ndarray | None]:
        """(B, 58, H/2, W/2) keypoint and (B, 24, H/2, W/2) line heatmaps of a batch."""
        x = self._tensor(images_bgr)
        with torch.autocast(x.device.type, dtype=torch.float16, enabled=self.half):
            kp = self.kp_net(x) if self.kp_net is not None else None
            lines = self.line_net(x) if self.line_net is not None else None
        return (None if kp is None else kp.float().cpu().numpy(),
                None if lines is None else lines.float().cpu().numpy())

    def detect(self, images_bgr: list[np.ndarray]) -> list[Predictions]:
        """Detections of a batch of BGR frames, normalised (x_px = x W) for each frame's own size."""
        kp, lines = self.heatmaps(images_bgr)
        out = []
        for b, img in enumerate(images_bgr):
            pred = self._read(None if kp is None else kp[b], None if lines is None else lines[b], img,
                              self.kp_threshold, self.line_threshold)
            if self.second_look is not None:
                second = self._read(None if kp is None else kp[b], None if lines is None else lines[b], img,
                                    *self.second_look)
                if len(second.keypoints) + len(second.lines) > len(pred.keypoints) + len(pred.lines):
                    pred.second = second
            out.append(pred)
        return out

    def _read(self, kp, lines, img: np.ndarray, kp_threshold: float, line_threshold: float) -> Predictions:
        """One frame's heatmaps read at the given peak thresholds, normalised for ``img``'s size."""
        pred = extract_predictions(kp, lines, self.input_size, kp_threshold=kp_threshold,
                                   line_threshold=line_threshold, refine=self.refine)
        if self.centre_aligned_resize:
            pred = undo_centre_aligned_resize(pred, self.input_size, (img.shape[1], img.shape[0]))
        return pred


class DeviceError(ValueError):
    """A device was asked for that this machine does not have."""


def resolve_device(name: str) -> str:
    """``"cpu"``, ``"cuda"`` / ``"cuda:N"`` (an error when torch sees no such GPU), or ``"auto"``
    (the first GPU if there is one, else the CPU)."""
    name = str(name).strip().lower()
    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cpu":
        return "cpu"
    if name == "cuda" or name.startswith("cuda:"):
        if not torch.cuda.is_available():
            raise DeviceError(f"--device {name}: torch sees no CUDA GPU here (torch {torch.__version__}, "
                              f"{'a CPU-only build' if torch.version.cuda is None else 'CUDA ' + torch.version.cuda}); "
                              f"use --device cpu or auto")
        index = int(name.split(":")[1]) if ":" in name else 0
        if index >= torch.cuda.device_count():
            raise DeviceError(f"--device {name}: only {torch.cuda.device_count()} CUDA device(s) here")
        return name
    raise DeviceError(f"--device {name}: expected cpu, cuda, cuda:N or auto")


def undo_centre_aligned_resize(pred: Predictions, input_size, frame_size) -> Predictions:
    """Detections normalised by the input size (``x_in / W_in``) -> normalised for the frame it
    was resized from with pixel centres aligned: ``X = (x_in + 0.5) W_f / W_in - 0.5`` (then
    ``X / W_f``), per axis. The identity when the sizes agree."""
    (wi, hi), (wf, hf) = input_size, frame_size
    if (wi, hi) == (wf, hf):
        return pred

    def f(x, y):
        return ((x * wi + 0.5) * wf / wi - 0.5) / wf, ((y * hi + 0.5) * hf / hi - 0.5) / hf

    keypoints = {k: (*f(x, y), p) for k, (x, y, p) in pred.keypoints.items()}
    lines = {k: (*f(x1, y1), p1, *f(x2, y2), p2) for k, (x1, y1, p1, x2, y2, p2) in pred.lines.items()}
    return Predictions(keypoints=keypoints, lines=lines)


def _second_look(look, weights) -> tuple[float, float] | None:
    """A sidecar's ``"second_look": {"kp_threshold": k, "line_threshold": l}`` -> (k, l)."""
    if look is None:
        return None
    try:
        return float(look["kp_threshold"]), float(look["line_threshold"])
    except (TypeError, KeyError, ValueError):
        raise ValueError(f"{weights}: the sidecar's second_look must be "
                         f"{{\"kp_threshold\": k, \"line_threshold\": l}}, got {look!r}"[:300]) from None


def light_detector(weights: str | Path, input_size: tuple[int, int] | None = None, **kw) -> Detector:
    """A ``Detector`` on a light checkpoint. ``input_size`` defaults to the size it was trained at,
    the peak thresholds (``kp_threshold``, ``line_threshold``), the sub-pixel refinement
    (``refine``) and the calibration settings for its detections (``calibration``) to the ones
    tuned for it, all from the sidecar (else 960x540 and the Detector's defaults)."""
    side = read_sidecar(weights)
    if input_size is None:
        size = side.get("input_size")
        if size:
            w, h = (int(v) for v in size)
            input_size = (w, h)
        else:
            input_size = DEFAULT_INPUT_SIZE
    tuned = {"kp_threshold": side.get("kp_threshold"), "line_threshold": side.get("line_threshold"),
             "refine": side.get("peak_refine"), "calibration": side.get("calibration"),
             "second_look": _second_look(side.get("second_look"), weights)}
    for name, value in tuned.items():  # what the caller leaves at None comes from the sidecar
        if kw.get(name) is None:
            kw.pop(name, None)
            if value is not None:
                kw[name] = value
    return Detector.for_light_net(load_light(weights), input_size, **kw)
