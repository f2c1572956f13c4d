"""A detector that runs in a child process, so that the process that uses it never imports torch.

Why a process and not a thread: importing torch in a thread while another thread runs scipy
crashes (scipy's array checks look up ``torch.Tensor`` on the half-imported module, issue #10),
and a detector thread competes with the app for the GIL and both cores. In the child, torch runs
on ``threads`` threads (1 by default) at a lower priority, so detection never starves the app.

torch-free on import. The child is started on first use (``spawn``: nothing of the parent's
threads is inherited) and builds :meth:`pnlviz.detect.run.Detector.from_weights` once.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from pnlviz.detect.default import DEFAULT_MODEL, read_sidecar

#: how much lower the child's scheduling priority is than the parent's (``os.nice``)
NICENESS = 10

_DETECTOR = None  # the child's Detector, built by its first job


class DetectorProcessError(RuntimeError):
    """The detector process died or could not start."""


class DetectorLoadError(ValueError):
    """The detector could not be built (no default model, a checkpoint that does not fit). Raised
    in the parent with the child's message, so the parent needs no torch to unpickle it."""


def _child_init(threads: int, parent: int) -> None:
    os.environ["OMP_NUM_THREADS"] = str(threads)
    try:
        os.nice(NICENESS)
    except OSError:  # not permitted here: run at the same priority
        pass
    threading.Thread(target=_exit_with_parent, args=(parent,), daemon=True).start()


def _exit_with_parent(parent: int) -> None:
    """End the child when its parent is gone (killed, or stopped without closing us)."""
    while os.getppid() == parent:
        time.sleep(0.5)
    os._exit(0)


def _child_detector(weights_kp, weights_lines, kw):
    global _DETECTOR
    if _DETECTOR is None:
        import torch

        from pnlviz.detect.run import Detector

        torch.set_num_threads(int(os.environ.get("OMP_NUM_THREADS", "1")))
        _DETECTOR = Detector.from_weights(weights_kp, weights_lines, **kw)
    return _DETECTOR


def _child_load(weights_kp, weights_lines, kw) -> dict:
    try:
        det = _child_detector(weights_kp, weights_lines, kw)
    except Exception as exc:  # noqa: BLE001 - its class may need torch to unpickle: send the message
        raise DetectorLoadError(str(exc)) from None
    return dict(det.calibration)


def _child_detect(weights_kp, weights_lines, kw, images):
    _child_load(weights_kp, weights_lines, kw)  # builds the detector on the first call
    try:
        return _DETECTOR.detect(images)
    except Exception as exc:  # noqa: BLE001 - sent as a message, as in _child_load
        raise DetectorProcessError(f"{type(exc).__name__}: {exc}") from None


class DetectorProcess:
    """``Detector.from_weights(weights_kp, weights_lines, **kw)`` in a child process.

    :meth:`detect` blocks the calling thread until the child answers (frames are sent as arrays,
    detections come back as :class:`pnlviz.data.Predictions`); calls are served one at a time.
    :meth:`load` builds the detector now and raises its error (a checkpoint that does not fit,
    no default model) in the caller. Thread-safe; :meth:`close` ends the child.
    """

    def __init__(self, weights_kp: Path | None = None, weights_lines: Path | None = None, *, threads: int = 1,
                 **kw) -> None:
        self._args = (weights_kp, weights_lines, kw)
        self.threads = max(1, int(threads))
        self.light = weights_kp is None and weights_lines is None
        self._pool: ProcessPoolExecutor | None = None
        self._lock = threading.Lock()
        self._calibration: dict | None = None

    @property
    def started(self) -> bool:
        return self._pool is not None

    @property
    def calibration(self) -> dict:
        """The calibration settings for these detections: the light model's sidecar (read here,
        without torch), else what the child reported on :meth:`load` ({} before)."""
        if self.light:
            return dict(read_sidecar(DEFAULT_MODEL).get("calibration") or {})
        return dict(self._calibration or {})

    def _submit(self, fn, *args):
        with self._lock:
            if self._pool is None:
                ctx = multiprocessing.get_context("spawn")
                self._pool = ProcessPoolExecutor(max_workers=1, mp_context=ctx, initializer=_child_init,
                                                 initargs=(self.threads, os.getpid()))
            pool = self._pool
        try:
            return pool.submit(fn, *self._args, *args).result()
        except BrokenProcessPool as exc:
            with self._lock:
                if self._pool is pool:  # the next call starts a fresh child
                    self._pool = None
            raise DetectorProcessError(f"the detector process stopped ({exc})") from None

    def load(self) -> None:
        """Start the child and build the detector in it; its errors are raised here."""
        self._calibration = self._submit(_child_load)

    def warm_up(self) -> None:
        """Start the child and build the detector in it, without waiting (an error shows on the
        first :meth:`detect`)."""
        threading.Thread(target=self._quiet_load, daemon=True, name="detector-warm-up").start()

    def _quiet_load(self) -> None:
        try:
            self.load()
        except (DetectorLoadError, DetectorProcessError):
            pass

    def detect(self, images_bgr) -> list:
        return self._submit(_child_detect, list(images_bgr))

    def close(self) -> None:
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
