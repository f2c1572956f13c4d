"""A detector that runs in a child process, so that the process that uses it never imports torch.

Why a process and not a thread: importing torch in a thread while another thread runs scipy
crashes (scipy's array checks look up ``torch.Tensor`` on the half-imported module, issue #10),
and a detector thread competes with the app for the GIL and both cores. In the child, torch runs
on ``threads`` threads (1 by default) at a lower priority, so detection never starves the app.

torch-free on import. The child is started on first use (``spawn``: nothing of the parent's
threads is inherited), builds :meth:`pnlviz.detect.run.Detector.from_weights` once, and answers
one request at a time over a pipe. It ends when asked (:meth:`DetectorProcess.close`), when its
parent exits, or when its parent is killed.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from pathlib import Path

from pnlviz.detect.default import DEFAULT_MODEL, read_sidecar

#: how much lower the child's scheduling priority is than the parent's (``os.nice``)
NICENESS = 10


class DetectorProcessError(RuntimeError):
    """The detector process died, could not start, or failed on a frame."""


class DetectorLoadError(ValueError):
    """The detector could not be built (no default model, a checkpoint that does not fit). Raised
    in the parent with the child's message, so the parent needs no torch to unpickle it."""


# ------------------------------------------------------------------------------ the child
def _child_main(conn, args: tuple, threads: int, parent: int) -> None:
    """Build the detector on the first request, then answer requests until told to stop."""
    os.environ["OMP_NUM_THREADS"] = str(threads)
    try:
        os.nice(NICENESS)
    except OSError:  # not permitted here: run at the same priority
        pass
    threading.Thread(target=_exit_with_parent, args=(parent,), daemon=True).start()
    detector = None
    while True:
        try:
            kind, payload = conn.recv()
        except (EOFError, OSError):  # the parent is gone
            return
        if kind == "stop":
            return
        try:
            if detector is None:
                detector = _build(args, threads)
            result = dict(detector.calibration) if kind == "load" else detector.detect(payload)
            conn.send(("ok", result))
        except DetectorLoadError as exc:
            conn.send(("load-error", str(exc)))
        except Exception as exc:  # noqa: BLE001 - sent as text: its class may need torch to unpickle
            conn.send(("error", f"{type(exc).__name__}: {exc}"))


def _build(args: tuple, threads: int):
    weights_kp, weights_lines, kw = args
    try:
        import torch

        from pnlviz.detect.run import Detector

        torch.set_num_threads(threads)
        return Detector.from_weights(weights_kp, weights_lines, **kw)
    except Exception as exc:  # noqa: BLE001 - a checkpoint error, no model, a broken install
        raise DetectorLoadError(str(exc)) from None


def _exit_with_parent(parent: int) -> None:
    """End the child when its parent is gone (killed, or exited without closing it)."""
    while os.getppid() == parent:
        time.sleep(0.5)
    os._exit(0)


# ------------------------------------------------------------------------------ the parent
class DetectorProcess:
    """``Detector.from_weights(weights_kp, weights_lines, **kw)`` in a child process.

    :meth:`detect` blocks the calling thread until the child answers (frames are sent as arrays,
    detections come back as :class:`pnlviz.data.Predictions`); calls are served one at a time.
    :meth:`load` builds the detector now and raises its error (a checkpoint that does not fit,
    no default model) in the caller; :meth:`warm_up` does the same without waiting.
    Thread-safe; :meth:`close` ends the child.
    """

    def __init__(self, weights_kp: Path | None = None, weights_lines: Path | None = None, *, threads: int = 1,
                 **kw) -> None:
        self._args = (weights_kp, weights_lines, kw)
        self.threads = max(1, int(threads))
        #: the light model's checkpoint (its sidecar holds the calibration settings), else None
        self.light_weights = kw.get("light") or (DEFAULT_MODEL if weights_kp is None and weights_lines is None else None)
        self.light = self.light_weights is not None
        self._proc: BaseProcess | None = None
        self._conn: Connection | None = None
        self._lock = threading.Lock()
        self._calibration: dict | None = None

    @property
    def started(self) -> bool:
        return self._proc is not None and self._proc.is_alive()

    @property
    def calibration(self) -> dict:
        """The calibration settings for these detections: the light model's sidecar (read here,
        without torch), else what the child reported on :meth:`load` ({} before)."""
        if self.light_weights is not None:  # self.light
            return dict(read_sidecar(self.light_weights).get("calibration") or {})
        return dict(self._calibration or {})

    def _start(self) -> None:
        ctx = multiprocessing.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_child_main, args=(child, self._args, self.threads, os.getpid()),
                                 daemon=True, name="pnlviz-detector")
        self._proc.start()
        child.close()

    def _call(self, kind: str, payload=None):
        with self._lock:
            if not self.started:
                self._start()
            proc, conn = self._proc, self._conn
            assert proc is not None and conn is not None  # started above
            try:
                conn.send((kind, payload))
                while not conn.poll(0.5):
                    if not proc.is_alive():
                        raise EOFError
                status, value = conn.recv()
            except (EOFError, OSError):
                if self._proc is proc:  # the next call starts a fresh child
                    self._proc = self._conn = None
                raise DetectorProcessError(f"the detector process stopped (exit code {proc.exitcode})") from None
        if status == "load-error":
            raise DetectorLoadError(value)
        if status == "error":
            raise DetectorProcessError(value)
        return value

    def load(self) -> None:
        """Start the child and build the detector in it; its errors are raised here."""
        self._calibration = self._call("load")

    def warm_up(self) -> None:
        """:meth:`load` in a background thread (an error then shows on the first :meth:`detect`)."""
        def quiet_load():
            try:
                self.load()
            except (DetectorLoadError, DetectorProcessError):
                pass

        threading.Thread(target=quiet_load, daemon=True, name="detector-warm-up").start()

    def detect(self, images_bgr) -> list:
        return self._call("detect", list(images_bgr))

    def close(self) -> None:
        """End the child: it finishes the frame it is on, if any, for at most two seconds."""
        proc, conn = self._proc, self._conn
        self._proc = self._conn = None
        if proc is None or conn is None:  # never started (the two are set together)
            return
        if self._lock.acquire(timeout=0.5):  # not while a request is being sent on the pipe
            try:
                conn.send(("stop", None))
            except (OSError, ValueError):
                pass
            finally:
                self._lock.release()
        proc.join(timeout=2.0)
        if proc.is_alive():
            proc.terminate()
            proc.join(timeout=2.0)
        conn.close()
