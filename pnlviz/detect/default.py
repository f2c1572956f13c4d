"""Where the light default model lives, and its provenance sidecar. torch-free on import (the
app runs detectors in a child process: :mod:`pnlviz.detect.worker`)."""

from __future__ import annotations

import json
from pathlib import Path

#: The light default model (``pnlviz train``), used when no weights are given.
DEFAULT_MODEL = Path(__file__).resolve().parents[2] / "assets" / "models" / "light.pt"


def sidecar_path(weights: str | Path) -> Path:
    """``light.pt`` -> ``light.json`` (the provenance written next to the weights)."""
    return Path(weights).with_suffix(".json")


def read_sidecar(weights: str | Path) -> dict:
    """The provenance JSON next to ``weights`` ({} when absent or unreadable)."""
    try:
        return json.loads(sidecar_path(weights).read_text())
    except (OSError, ValueError):
        return {}
