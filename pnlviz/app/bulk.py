"""Bulk work (no GUI here): one action on one keypoint id over many frames, counted before it runs.

An annotator who finds the same mistake on many frames (the wrong goal's ids 19 and 14 on the
left-goal frames of a match) fixes it once: keypoint ``kid`` made absent, occluded or visible
again, or renamed to another id, on the frames of a scope (this frame, its shot, the frames of the
tab's filter). :func:`plan` says which frames it would change (the count the panel shows before it
runs); :func:`apply` runs it through the session's edit door, one edit per frame, which the tab
takes back as one undo step.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from pnlviz.data.edit_changes import set_keypoint, set_occluded, set_visible
from pnlviz.data.edits import EditError

__all__ = ["ACTIONS", "MAX_FRAMES", "BulkPlan", "apply", "change_of", "plan"]

#: what a bulk action does to the keypoint on each frame
ACTIONS = {"absent": "make keypoint {kid} absent", "occluded": "mark keypoint {kid} occluded",
           "visible": "make keypoint {kid} visible again", "rename": "rename keypoint {kid} to {to}"}
#: the most frames one action is planned over (each frame's view is needed to know what it shows)
MAX_FRAMES = 2000


@dataclass(frozen=True)
class BulkPlan:
    """What a bulk action would change: ``action`` on keypoint ``kid`` (``to``: the id a rename
    gives it), ``stems`` the frames it changes (with, for a rename, where the point is on each),
    out of ``scope`` frames looked at."""

    action: str
    kid: int
    to: int | None
    stems: tuple[str, ...]
    scope: int
    positions: tuple[tuple[float, float] | None, ...] = ()

    def text(self) -> str:
        what = ACTIONS[self.action].format(kid=self.kid, to=self.to)
        return f"{what} on {len(self.stems)} of {self.scope} frame{'s' if self.scope != 1 else ''}"


def _shows(view, kid: int) -> tuple[bool, np.ndarray | None]:
    """Whether the frame's view shows keypoint ``kid`` (observed, from any source) and where."""
    obs = view.observations
    if obs is None:
        return False, None
    hit = np.flatnonzero(obs.kp_ids == kid)
    return (True, obs.kp_xy[hit[0]].copy()) if len(hit) else (False, None)


def plan(stems: Sequence[str], action: str, kid: int, *, to: int | None = None,
         view: Callable[[str], object], record: Callable[[str], dict]) -> BulkPlan:
    """The frames of ``stems`` that ``action`` on keypoint ``kid`` changes: ``view(stem)`` the
    frame's view (what it shows), ``record(stem)`` its edit record. EditError for an unknown
    action, a rename without another id, or more than :data:`MAX_FRAMES` frames."""
    if action not in ACTIONS:
        raise EditError(f"a bulk action is one of {', '.join(ACTIONS)}, got {str(action)[:20]!r}")
    if action == "rename" and (to is None or int(to) == int(kid)):
        raise EditError("a rename needs another id: choose it as the place id")
    if len(stems) > MAX_FRAMES:
        raise EditError(f"{len(stems)} frames are more than one action runs on ({MAX_FRAMES}): narrow the filter")
    changed, positions = [], []
    for stem in stems:
        rec, seen = record(stem), view(stem)
        shown, xy = _shows(seen, kid)
        occluded = kid in (rec.get("occluded") or [])
        absent = (rec.get("keypoints") or {}).get(str(kid), 0) is None
        if action == "absent":
            hit = shown
        elif action == "occluded":
            hit = shown and not occluded
        elif action == "visible":
            hit = occluded or absent
        else:
            hit = shown and not _shows(seen, int(to or 0))[0]  # never over the id's own point
        if hit:
            changed.append(stem)
            positions.append(None if xy is None else (float(xy[0]), float(xy[1])))
    return BulkPlan(action, int(kid), None if to is None else int(to), tuple(changed), len(stems), tuple(positions))


def change_of(bulk: BulkPlan, i: int) -> Callable[[dict], None]:
    """The edit of the ``i``-th frame of ``bulk``, as a change of its record."""
    kid, to, xy = bulk.kid, bulk.to, bulk.positions[i] if i < len(bulk.positions) else None

    def change(rec: dict) -> None:
        if bulk.action == "absent":
            set_occluded(rec, kid, False)
            set_keypoint(rec, kid, None)
        elif bulk.action == "occluded":
            set_occluded(rec, kid, True)
        elif bulk.action == "visible":
            set_visible(rec, kid)
        else:
            if xy is None or to is None:
                return
            set_keypoint(rec, to, xy)
            set_keypoint(rec, kid, None)
            if kid in (rec.get("occluded") or []):
                set_occluded(rec, kid, False)
                set_occluded(rec, to, True)

    return change


def apply(bulk: BulkPlan, write: Callable[..., bool], settings=None) -> list[str]:
    """Run ``bulk`` through the edit door ``write`` (:meth:`pnlviz.app.state.AppState.write`):
    one edit per frame; the frames changed."""
    return [stem for i, stem in enumerate(bulk.stems) if write(stem, change_of(bulk, i), settings=settings)]
