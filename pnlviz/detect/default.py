"""Where the light default model lives, and a detector on it that is built on first use.

torch-free on import: ``pnlviz serve`` checks for the model and hands the app a
:class:`DeferredDetector`, so torch's import and the weights load (about 2.7 s) happen in the
app's background detection thread, not before the URL is printed.
"""

from __future__ import annotations

import json
import threading
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


class DeferredDetector:
    """``Detector.from_weights(None, None, **kw)`` (the light default model), built on the first
    :meth:`detect` call; thread-safe."""

    def __init__(self, **kw) -> None:
        self._kw = kw
        self._detector = None
        self._lock = threading.Lock()

    @property
    def loaded(self) -> bool:
        return self._detector is not None

    @property
    def calibration(self) -> dict:
        """The calibration settings for the model's detections, from its sidecar (no torch)."""
        return dict(read_sidecar(DEFAULT_MODEL).get("calibration") or {})

    def detect(self, images_bgr):
        with self._lock:
            if self._detector is None:
                from pnlviz.detect.run import Detector

                self._detector = Detector.from_weights(None, None, **self._kw)
        return self._detector.detect(images_bgr)
