"""Where the light default model lives, and its provenance sidecar. torch-free on import (the
app runs detectors in a child process: :mod:`pnlviz.detect.worker`)."""

from __future__ import annotations

import json
from pathlib import Path

from pnlviz.paths import ASSETS_DIR

#: how to get the networks where PyTorch is missing (the base install calibrates without it)
DETECT_EXTRA = "pip install 'pnlviz[detect]'"


def torch_missing() -> str | None:
    """None when PyTorch can be imported; else the one line that says how to get the networks."""
    import importlib.util

    if importlib.util.find_spec("torch") is None:
        return f"the keypoint and line networks need PyTorch, which is not installed: {DETECT_EXTRA}"
    return None


#: The light default model (``pnlviz train``), used when no weights are given.
DEFAULT_MODEL = ASSETS_DIR / "models" / "light.pt"


def sidecar_path(weights: str | Path) -> Path:
    """``light.pt`` -> ``light.json`` (the provenance written next to the weights)."""
    return Path(weights).with_suffix(".json")


def read_sidecar(weights: str | Path) -> dict:
    """The provenance JSON next to ``weights`` ({} when absent or unreadable)."""
    try:
        return json.loads(sidecar_path(weights).read_text())
    except (OSError, ValueError):
        return {}


def default_threads(cores: int | None = None, load: float | None = None) -> int:
    """Torch threads for a detection run when none are asked for: the cores that are idle (the
    1-minute load average taken off), one core always left to the rest of the machine, and at
    least one. Torch's OpenMP threads spin while they wait for each other: one thread more than
    there are free cores makes every forward pass wait for a descheduled one. Measured with the
    light model on 2 cores (``benchmarks/bench_detect_threads.py``): 2 threads 62 ms per frame
    idle, 776 ms with one busy process beside, 343 ms with two; 1 thread 92, 90 and 99 ms."""
    import math
    import os

    cores = cores if cores is not None else os.cpu_count() or 1
    load = load if load is not None else machine_load() or 0.0
    return max(1, min(cores - 1, cores - math.ceil(load - 0.25)))


def machine_load() -> float | None:
    """The 1-minute load average (None where the platform has none)."""
    import os

    try:
        return os.getloadavg()[0]
    except (AttributeError, OSError):
        return None
