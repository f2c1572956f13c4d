"""A tab's undo trail across frames (no GUI here): the frames it changed, most recent last, so
that Ctrl+Z in a tab goes back to the frame that tab changed last; a bulk action is one step."""

from __future__ import annotations

import functools
from collections.abc import Callable

__all__ = ["EditTrail"]


class EditTrail:
    """The frames a tab changed, most recent last (``done``), and those it took back
    (``undone``). ``guard(action)`` runs an edit, showing a refusal (see
    :class:`pnlviz.app.tabqueue.ActionGuard`)."""

    def __init__(self, state, guard: Callable[[Callable[[], object]], object]):
        self.state, self.guard = state, guard
        #: a frame, or the frames of one bulk action (one step of the tab's trail)
        self.done: list[str | tuple[str, ...]] = []
        self.undone: list[str | tuple[str, ...]] = []

    def act(self, stem: str, action: Callable[[], object]) -> None:
        """An edit of ``stem``: remembered when it changed the frame's history."""
        self.act_many([stem], action)

    def act_many(self, stems, action: Callable[[], object]) -> list[str]:
        """An edit of several frames at once (a bulk action): one step of the trail, for the
        frames whose history it changed (returned)."""
        before = {s: self.state.edits.history(s)[0] for s in stems}
        self.guard(action)
        changed = [s for s in stems if self.state.edits.history(s)[0] != before[s]]
        if changed:
            self.done.append(changed[0] if len(changed) == 1 else tuple(changed))
            self.undone.clear()
        return changed

    def undo(self, current: str, goto: Callable[[str], None], settings=None) -> None:
        """Take back this tab's last change (going to its frame with ``goto(stem)``), else the
        last change of the ``current`` frame (a reviewed frame records what it shows under the
        tab's ``settings``)."""
        self._step(self.done, self.undone, lambda stem: self.state.undo(stem, settings), current, goto)

    def redo(self, current: str, goto: Callable[[str], None], settings=None) -> None:
        self._step(self.undone, self.done, lambda stem: self.state.redo(stem, settings), current, goto)

    def _step(self, trail: list, other: list, step: Callable[[str], bool], current: str,
              goto: Callable[[str], None]) -> None:
        entry = trail.pop() if trail else current
        stems = list(entry) if isinstance(entry, tuple) else [entry]
        if current not in stems:
            goto(stems[0])
        done = [self.guard(functools.partial(step, stem)) for stem in stems]
        if all(done):
            other.append(entry)
