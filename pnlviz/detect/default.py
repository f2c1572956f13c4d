"""Where the light default model lives, and a detector on it that is built on first use.

torch-free on import: ``pnlviz serve`` checks for the model and hands the app a
:class:`DeferredDetector`, so torch's import and the weights load (about 2.7 s) happen in the
app's background detection thread, not before the URL is printed.
"""

from __future__ import annotations

import threading
from pathlib import Path

#: The light default model (``pnlviz train``), used when no weights are given.
DEFAULT_MODEL = Path(__file__).resolve().parents[2] / "assets" / "models" / "light.pt"


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

    def detect(self, images_bgr):
        with self._lock:
            if self._detector is None:
                from pnlviz.detect.run import Detector

                self._detector = Detector.from_weights(None, None, **self._kw)
        return self._detector.detect(images_bgr)
