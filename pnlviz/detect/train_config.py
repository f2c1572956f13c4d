"""The training configuration of the light model (:mod:`pnlviz.detect.train`): its fields, its
JSON form (``assets/models/light_config.json`` is the shipped one) and how relative paths in it
are read (from the config's own folder)."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

from pnlviz.paths import ASSETS_DIR

__all__ = ["DEFAULT_CONFIG_PATH", "TrainConfig", "load_config", "resolve_path"]

DEFAULT_CONFIG_PATH = ASSETS_DIR / "models" / "light_config.json"


@dataclass
class TrainConfig:
    data_seed: int = 5
    frames: int = 1400  # synthetic frames (0: none)
    data_weight: float = 1.0  # share of the synthetic frames in a mixed epoch
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
    #: lower peak thresholds of a second reading for frames the first leaves without a camera
    #: (``{"kp_threshold": k, "line_threshold": l}``, sidecar; None: none)
    second_look: dict | None = None
    calibration: dict = field(default_factory=dict)  # CalibParams overrides for its detections (sidecar)
    seed: int = 0
    threads: int = 2
    augment: dict = field(default_factory=lambda: {"brightness": 0.3, "contrast": 0.3, "saturation": 0.3,
                                                   "gain": 0.08, "noise": 0.03})
    #: real sources: ``{"kind": "homography" | "soccernet", "path": ..., "weight": w, ...}`` (see
    #: :func:`build_sources`); relative paths are taken from ``base_dir`` (the config's folder)
    real: list = field(default_factory=list)
    #: weights to start from (a LightNet checkpoint), instead of a random initialisation
    init: str | None = None
    #: samples per epoch (default: the frames of every source, once)
    epoch_frames: int | None = None
    base_dir: str | None = field(default=None, compare=False)

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
        if "weight" in data:
            kw["data_weight"] = float(data["weight"])
        known = {f for f in cls.__dataclass_fields__}
        for k, v in d.items():
            if k.startswith("_") or k in ("comment", "estimate", "base_dir"):
                continue
            if k not in known:
                raise ValueError(f"unknown training config key {k!r}")
            kw[k] = tuple(int(x) for x in v) if k in ("size", "input_size") else v
        cfg = cls(**kw)
        if "input_size" not in d and "size" in data:
            cfg.input_size = cfg.size
        check_config(cfg)
        return cfg

    def to_dict(self) -> dict:
        d = asdict(self)
        d.pop("base_dir")
        out = {"data": {"seed": d.pop("data_seed"), "frames": d.pop("frames"), "size": list(d.pop("size")),
                        "weight": d.pop("data_weight")}}
        d["input_size"] = list(d["input_size"])
        out.update(d)
        return out


#: numeric fields: (whole number, low, high); every value must lie in [low, high]
_RANGES: dict[str, tuple[bool, float, float]] = {
    "data_seed": (True, 0, 2**32 - 1), "frames": (True, 0, 10**7), "data_weight": (False, 0.0, 1e6),
    "epochs": (True, 1, 10**6), "lr": (False, 1e-12, 10.0), "lr_final": (False, 0.0, 10.0),
    "weight_decay": (False, 0.0, 10.0), "batch_size": (True, 1, 4096), "sigma": (False, 0.05, 100.0),
    "kp_threshold": (False, 0.0, 1.0), "line_threshold": (False, 0.0, 1.0), "seed": (True, 0, 2**32 - 1),
    "threads": (True, 1, 1024), "epoch_frames": (True, 1, 10**8),
}
_SIZES = ("size", "input_size")
_SIDE = (16, 4096)


def _range_problem(name: str, value, whole: bool, low: float, high: float) -> str | None:
    import math

    if isinstance(value, bool) or not isinstance(value, (int, float)) or (whole and not float(value).is_integer()):
        return f"{name} must be {'a whole number' if whole else 'a number'}, got {value!r}"[:100]
    if not math.isfinite(value) or not low <= value <= high:
        return f"{name} = {value!r} is out of range ({low:g} to {high:g})"
    return None


def check_config(cfg: TrainConfig) -> None:
    """ValueError naming the first field of ``cfg`` of the wrong type or out of range (a sigma of
    0 makes every target NaN; an input size of 0 cannot be resized to)."""
    for name, (whole, low, high) in _RANGES.items():
        value = getattr(cfg, name)
        if value is None and name == "epoch_frames":
            continue
        problem = _range_problem(name, value, whole, low, high)
        if problem:
            raise ValueError(problem)
    for name in _SIZES:
        size = getattr(cfg, name)
        if len(size) != 2 or not all(_SIDE[0] <= v <= _SIDE[1] for v in size):
            raise ValueError(f"{name} = {list(size)} is out of range (two sides of {_SIDE[0]} to {_SIDE[1]} pixels)")
    if cfg.loss not in ("focal", "mse"):
        raise ValueError(f"loss must be focal or mse, got {cfg.loss!r}"[:100])
    for name in ("calibration", "augment"):
        if not isinstance(getattr(cfg, name), dict):
            raise ValueError(f"{name} must be an object, got {getattr(cfg, name)!r}"[:100])
    look = cfg.second_look
    if look is not None and not (isinstance(look, dict) and set(look) == {"kp_threshold", "line_threshold"}
                                 and all(_range_problem(k, v, False, 0.0, 1.0) is None for k, v in look.items())):
        raise ValueError(f"second_look must be {{\"kp_threshold\": k, \"line_threshold\": l}} in [0, 1], "
                         f"got {look!r}"[:120])
    if not isinstance(cfg.real, list):
        raise ValueError(f"real must be a list of sources, got {cfg.real!r}"[:100])


def load_config(path: str | Path | None = None) -> TrainConfig:
    from pnlviz.data.reading import read_file

    path = Path(path) if path is not None else DEFAULT_CONFIG_PATH
    cfg = TrainConfig.from_dict(json.loads(read_file(path)))  # capped; a FIFO or device refused
    cfg.base_dir = str(Path(path).resolve().parent)
    return cfg


def resolve_path(path: str, base_dir: str | None) -> Path:
    """``path`` as a config names it: relative paths are taken from ``base_dir`` (the config's folder)."""
    p = Path(path).expanduser()
    return p if p.is_absolute() or base_dir is None else Path(base_dir) / p


