"""The event queue of one tab: everything the tab asks for runs here, one action at a time, in
the order the browser sent it; and the guard every user action runs in, which shows a refused
value or a failed save instead of losing it.

viser awaits ``async`` callbacks on its event loop in the order the messages came, but runs plain
ones in a thread pool in any order ("accepted" then "rejected" could end "accepted"). So every
callback of a tab is an ``async`` one that only puts the call on the tab's queue
(:meth:`TabQueue.ordered`). viser also calls a widget's update callback for a value set from the
server, later: :meth:`TabQueue.set_value` counts such sets so that their echoes are dropped.
"""

from __future__ import annotations

import asyncio
import threading
import traceback
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

from pnlviz.app.activity import UserActivity
from pnlviz.app.state import EditError


#: an action running longer than this (seconds) shows the busy cue
BUSY_AFTER_S = 0.15


class TabQueue:
    """One tab's actions, run one at a time on a thread of their own. ``notify(title, body)``
    shows an unexpected error to the tab; ``loop``: viser's event loop, which a value set from
    Python goes through before it reaches the queue (None: no server)."""

    def __init__(self, notify: Callable[..., None], loop: Callable[[], asyncio.AbstractEventLoop] | None = None,
                 activity: UserActivity | None = None):
        self.notify, self._loop = notify, loop
        self.activity = activity  # marked while an action runs (the background pass waits for a pause)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="pnlviz-tab")
        # id(widget) -> values set by this tab whose callbacks are to come (viser's event carries the
        # widget's handle itself as its target; the panel keeps its handles for the tab's life)
        self._own_sets: dict[int, int] = {}
        self._own_lock = threading.Lock()
        self.closed = False
        #: ``busy(True)`` when an action has run :data:`BUSY_AFTER_S` without ending, ``busy(False)``
        #: when it ends (the tab shows a cue where the user looks); None: no cue
        self.busy: Callable[[bool], None] | None = None

    def ordered(self, fn: Callable):
        """``fn(event)`` as a viser callback that keeps the browser's order: it only puts the call
        on the queue. The callbacks of values this tab set itself (:meth:`set_value`) are not
        taken for the user's."""

        async def queued(event) -> None:
            target = getattr(event, "target", None)
            if getattr(event, "client", True) is None and target is not None:
                with self._own_lock:
                    if self._own_sets.get(id(target)):
                        self._own_sets[id(target)] -= 1
                        return
            self.enqueue(lambda: fn(event))

        return queued

    def set_value(self, handle, value) -> None:
        """Set a widget's value from here. viser calls its update callback for such sets too,
        later, on its event loop: by then the tab may have moved on, so that call is dropped
        (the slider moved by ``goto`` would otherwise send the tab back)."""
        if handle.value == value:
            return  # viser does nothing either
        with self._own_lock:
            self._own_sets[id(handle)] = self._own_sets.get(id(handle), 0) + 1
        handle.value = value

    def enqueue(self, action: Callable[[], object]) -> None:
        if not self.closed:
            self._pool.submit(self._run, action)

    def flush(self, timeout: float = 30.0) -> None:
        """Wait until every action sent to this tab so far has run (for scripts and tests: a value
        set from Python reaches the queue through viser's event loop)."""
        if self._loop is not None:
            asyncio.run_coroutine_threadsafe(asyncio.sleep(0), self._loop()).result(timeout)
        self._pool.submit(lambda: None).result(timeout)

    def _run(self, action: Callable[[], object]) -> None:
        """One queued action; an unexpected error is printed and shown, and the tab goes on."""
        if self.activity is not None:
            self.activity.begin()
        shown = threading.Event()
        cue = None
        if self.busy is not None:
            busy = self.busy

            def say_busy() -> None:
                shown.set()
                busy(True)

            cue = threading.Timer(BUSY_AFTER_S, say_busy)
            cue.daemon = True
            cue.start()
        try:
            action()
        except Exception as exc:  # noqa: BLE001 - the queue would swallow it silently
            traceback.print_exc()
            self.notify("internal error", f"{type(exc).__name__}: {exc}")
        finally:
            if cue is not None:
                cue.cancel()
                cue.join()  # it either never ran or has said busy: then it is said done
                if shown.is_set() and self.busy is not None:
                    self.busy(False)
            if self.activity is not None:
                self.activity.end()

    def close(self, wait: bool = False) -> None:
        """No more actions; those queued still run (``wait``: until they have)."""
        self.closed = True
        self._pool.shutdown(wait=wait)


class ActionGuard:
    """Runs a user action so that a refused value or a failed save is shown, never lost silently.
    ``redraw()`` draws the tab again; ``drawn()`` counts the times it was drawn (an action that
    drew it need not draw it again). ``save_error``: why the last edit could not be written."""

    def __init__(self, notify: Callable[..., None], redraw: Callable[[], object], drawn: Callable[[], int]):
        self.notify, self.redraw, self.drawn = notify, redraw, drawn
        self.save_error: str | None = None

    def __call__(self, action: Callable[[], object]) -> object:
        """``action()``'s result (None when it was refused). The tab is redrawn after it, unless
        the change already redrew it (an edit announces itself to every tab on its frame) and
        there is no save error to show or clear."""
        result, shows, clean = None, self.drawn(), self.save_error is None
        try:
            result = action()
            self.save_error = None
        except EditError as exc:
            self.notify("not applied", str(exc))
        except OSError as exc:
            self.save_error = exc.strerror or str(exc)
            self.notify("not saved", f"the edits folder cannot be written: {self.save_error}")
        if self.drawn() == shows or not clean or self.save_error is not None:
            self.redraw()
        return result


__all__ = ["ActionGuard", "TabQueue"]
