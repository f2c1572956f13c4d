"""When the user is at work: the tabs' actions mark it, the background pass waits for a pause.

The pass (:func:`pnlviz.app.triage.run_pass`) calibrates frame after frame in a thread of the same
process; on two cores its numpy work and the tab's share the interpreter, so a key press that
arrives while it runs takes about twice as long. It waits instead: before each frame, until no
tab's action is running and none has ended for :data:`QUIET_S` seconds.
"""

from __future__ import annotations

import threading
import time

#: how long the tabs have been idle before the background pass takes its next frame (seconds)
QUIET_S = 0.4


class UserActivity:
    """Counts the tabs' actions running (:meth:`begin`, :meth:`end`) and when the last one ended."""

    def __init__(self, quiet: float = QUIET_S):
        self.quiet = quiet
        self._running = 0
        self._last = -float("inf")
        self._cond = threading.Condition()

    def begin(self) -> None:
        with self._cond:
            self._running += 1

    def end(self) -> None:
        with self._cond:
            self._running -= 1
            self._last = time.monotonic()
            self._cond.notify_all()

    def busy(self) -> bool:
        """An action is running, or one ended less than ``quiet`` seconds ago."""
        with self._cond:
            return self._running > 0 or time.monotonic() - self._last < self.quiet

    def wait_quiet(self, stop: threading.Event, longest: float = 30.0) -> float:
        """Wait until the tabs are quiet (or ``stop`` is set, or ``longest`` seconds passed: a tab
        that plays a clip for minutes does not stop the pass for good). The seconds waited."""
        start = time.monotonic()
        with self._cond:
            while not stop.is_set() and time.monotonic() - start < longest:
                if self._running > 0:
                    self._cond.wait(0.1)
                    continue
                left = self.quiet - (time.monotonic() - self._last)
                if left <= 0:
                    break
                self._cond.wait(min(left, 0.1))
        return time.monotonic() - start


__all__ = ["QUIET_S", "UserActivity"]
