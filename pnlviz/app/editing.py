"""A tab's edits: the selected point, placing a keypoint (shift+click), nudging (arrows), dragging a
point with the frame recalibrated as it moves, hiding, reviewing, and the tab's own undo trail.

Every edit names the frame it was made on (captured when the pointer went down), so a drag
released after the tab moved on still lands on its own frame. Edits go through
:class:`pnlviz.app.state.AppState`, which validates ids and positions; each one is an undo step
there, and the frames this tab changed are remembered here (:class:`EditTrail`) so that Ctrl+Z
goes back to them.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from pnlviz.app.asking import ask_before_accepting, say_flagged, say_slip
from pnlviz.app.cards import listed_id
from pnlviz.app.host import Part, TabPart
from pnlviz.app.modes import DragEvent, DragMode, DragPhase, PointKind, Selection, labels
from pnlviz.app.panels import choice_id
from pnlviz.app.state import REVIEW_STATES, EditError
from pnlviz.app.trail import EditTrail
from pnlviz.app.view2d import snap
from pnlviz.calib.solver import Cancelled, cancellable

if TYPE_CHECKING:
    from pnlviz.app.drawing import Painter
    from pnlviz.app.frameorder import FrameOrder
    from pnlviz.app.panels import Panels
    from pnlviz.app.state import AppState
    from pnlviz.app.tabqueue import ActionGuard, TabQueue
    from pnlviz.app.viewcontrol import ViewControl
    from pnlviz.app.workspace import Workspace

SNAP_PX = 8.0  # screen pixels
CLICK_REACH_PX = 12.0  # a click this close to a point (screen pixels) selects it


@dataclass
class Drag:
    """A point being dragged: the frame it was grabbed on, the point, where it was grabbed and
    where it is now (image pixels), and whether a preview of it is waiting on the queue."""

    stem: str
    point: Selection
    origin: np.ndarray
    uv: np.ndarray
    pending: bool = False

    @property
    def moved(self) -> bool:
        """A press without a move changes nothing."""
        return bool(np.hypot(*(self.uv - self.origin)) > 0.05)


@dataclass(frozen=True)
class EditorTab(TabPart):
    """What a tab's editor (:class:`pnlviz.app.editing.Editor`) uses of its tab, and nothing
    else: the session's ``state`` (the edit door and the frames' views), the tab's ``queue``,
    ``guard`` and frame ``order``, its frame and moves (``handle``), going on after a review
    (``advance_from(stem)``) and the parts it shows its edits with, made after it (``parts()``:
    the painter, the panel, the workspace and the view control)."""

    state: AppState
    queue: TabQueue
    guard: ActionGuard
    frames: FrameOrder
    advance_from: Callable[[str], Any]
    parts: Callable[[], tuple[Painter, Panels, Workspace, ViewControl]]

    def notify(self, title: str, body: str, error: bool = True) -> None:
        self.handle.notify(title, body, error)

    def goto(self, index: int) -> Any:
        return self.handle.goto(index)

    painter: ClassVar[Part[Painter]] = Part(0)
    panels: ClassVar[Part[Panels]] = Part(1)
    workspace: ClassVar[Part[Workspace]] = Part(2)
    view_control: ClassVar[Part[ViewControl]] = Part(3)


def _chosen(editor: Editor) -> list[Selection]:
    """The keypoints ``editor`` has selected, the first selected first."""
    return [s for s in [editor.selected, *editor.also] if s is not None and s.kind is PointKind.KEYPOINTS]


def _keep(editor: Editor, chosen: list[Selection]) -> None:
    """``chosen`` keypoints as ``editor``'s selection, ringed and said in the panel."""
    editor.selected, editor.also = (chosen[0], chosen[1:]) if chosen else (None, [])
    editor.tab.workspace.select(editor.selected, editor.also)
    editor.tab.painter.show_selected()  # the rings say what is selected (no notice over the image)


class Editor:
    """The edits of one tab: ``tab`` is what it uses of the tab (:class:`EditorTab`:
    the frame shown and its settings, the edit door, the queue, the parts it shows its edits with),
    not the tab itself."""

    def __init__(self, tab: EditorTab) -> None:
        self.tab = tab
        self.trail = EditTrail(tab.state, tab.guard)
        self.selected: Selection | None = None
        self.also: list[Selection] = []  # more keypoints selected (Ctrl+click)
        self.place_id = 1
        self.snap = False
        self.drag_mode = DragMode.KEYPOINTS
        self.dragging: Drag | None = None
        self.grabs = self.releases = 0  # drags started and released in this tab
        self.live_preview = True  # recalibrate while a point is dragged (off: only on release)
        self.flagged: tuple[str, list[int]] | None = None  # the last reviewed frame's flagged points, for H
        #: the frame (and its edits) an accept was asked about once: a second G accepts it as it is
        self.asked: tuple[str, str] | None = None
        #: the bulk action whose count was shown: applying the same again runs it
        self.bulk_asked: tuple | None = None
        self.last_recalibration_ms = 0.0
        self.previews_given_up = 0  # previews abandoned because their point was let go elsewhere

    # ------------------------------------------------------------------ choices
    def select(self, selected: Selection | None) -> None:
        """Select a point, or nothing (the other selected keypoints too). Selecting a keypoint or
        a ghost also chooses its id for placing."""
        self.selected, self.also = selected, []
        if selected is not None and selected.is_keypoint:
            self.choose_id(selected.kid)
        self.tab.workspace.select(selected)
        self.tab.painter.show_selected()

    def add_to_selection(self, point: Selection) -> None:
        """Ctrl+click on a keypoint: in the selection, or out of it when it was there (Delete and
        O then act on every selected keypoint at once, one undo step)."""
        if point.kind is not PointKind.KEYPOINTS:
            return
        chosen = _chosen(self)
        _keep(self, [s for s in chosen if s.key != point.key] if any(s.key == point.key for s in chosen)
              else [*chosen, point])

    def select_in_box(self, lo, hi) -> None:
        """A box drawn with ctrl+drag (corners ``lo``, ``hi`` in image pixels): the keypoints the
        frame shows inside it join the selection (Delete and O then act on all of them)."""
        overlay = self.tab.painter.overlay
        if overlay is None or not len(overlay.keypoints):
            return
        uv = np.asarray(overlay.keypoints.uv, float)
        inside = np.all((uv >= np.minimum(lo, hi)) & (uv <= np.maximum(lo, hi)), axis=1)
        chosen = _chosen(self)
        known = {s.key for s in chosen}
        _keep(self, chosen + [Selection(PointKind.KEYPOINTS, int(k)) for k, ok in zip(overlay.keypoints.keys, inside)
                              if ok and int(k) not in known])

    def selected_ids(self) -> list[int]:
        """The ids of the selected keypoints (the first selected first)."""
        return [s.kid for s in _chosen(self)]

    def choose_id(self, kid: int) -> None:
        """The id shift+click places."""
        self.place_id = kid
        self.tab.panels.show_place_id(kid)

    def select_listed(self, row) -> None:
        """A choice in the panel's keypoint list ("12 · visible · 0.8 px")."""
        kid, overlay = listed_id(row), self.tab.painter.overlay
        if kid is None:
            return
        if overlay is not None and kid in overlay.keypoints.keys:
            self.select(Selection(PointKind.KEYPOINTS, kid))
        elif overlay is not None and kid in overlay.ghosts.keys:
            self.select(Selection(PointKind.GHOSTS, kid))
        elif 1 <= kid <= 73:  # hidden: choose it, shift+click puts it back
            self.select(None)
            self.choose_id(kid)

    def set_place_id(self, value) -> None:
        """A choice in the picker ("45 · penalty mark left")."""
        panels = self.tab.panels
        kid = choice_id(panels.choice(panels.kp_id, panels.kp_choices, panels.choice_of(self.place_id)))
        assert kid is not None  # every option starts with its id
        self.place_id = kid
        panels.kp_map.image = panels.map_of(self.place_id)
        self.tab.painter.show_selected()

    def set_drag_mode(self, value) -> None:
        self.drag_mode = DragMode(self.tab.panels.choice(self.tab.panels.drag_mode, labels(DragMode),
                                                         DragMode.KEYPOINTS.value))
        self.selected = None
        self.tab.show()

    def set_snap(self, value) -> None:
        self.snap = bool(value)

    # ------------------------------------------------------------------ edits
    def review(self, status: str, advance: bool = True) -> None:
        """Record a review status for the frame; with ``advance``, go on to the next frame of the
        filter (the filter as it is after this review: "unreviewed" moves on to the next one)."""
        tab = self.tab
        if status not in REVIEW_STATES + ("clear",):
            tab.notify("refused", f"review status {str(status)[:20]!r} is not one of the options")
            return
        stem = tab.stem
        if status == "accepted" and ask_before_accepting(self, stem):
            return
        self.trail.act(stem, lambda: tab.state.set_review(stem, None if status == "clear" else status, tab.settings))
        say_flagged(self, stem)
        if advance and status != "clear" and tab.state.edits.review(stem) == status:
            tab.advance_from(stem)

    def hide_flagged(self) -> None:
        """H: hide the points the gate flagged on the frame reviewed last from its labels (one
        undo step); its review status and its reviewed camera stay
        (:meth:`pnlviz.app.state.AppState.hide_flagged`)."""
        if self.flagged is None:
            self.tab.notify("nothing flagged", "the last frame reviewed has no flagged point", error=False)
            return
        stem, ids = self.flagged
        self.trail.act(stem, lambda: self.tab.state.hide_flagged(stem, ids, self.tab.settings))
        say_flagged(self, stem)

    def hide_selected(self) -> None:
        """Delete: the selected keypoints (one, or several with Ctrl+click) absent, one undo step."""
        kids = self.selected_ids()
        if not kids:
            self.tab.notify("nothing to hide", "select a keypoint first (click it)", error=False)
            return
        stem = self.tab.stem
        self.selected, self.also = None, []
        self.trail.act(stem, lambda: self.tab.state.hide_keypoint(stem, kids, self.tab.settings))

    def cycle_visibility(self) -> None:
        """O: the selected keypoint visible -> occluded (labelled where it is, hidden behind
        something: COCO v=1) -> absent (not on the frame) -> visible again (where its source put
        it); one undo step each."""
        from pnlviz.data.edit_changes import set_keypoint, set_occluded, set_visible

        tab = self.tab
        kids = self.selected_ids()
        if not kids:
            tab.notify("nothing selected", "select a keypoint first (click it)", error=False)
            return
        stem, kid = tab.stem, kids[0]
        record = tab.state.edits.get(stem)
        occluded = kid in (record.get("occluded") or [])
        absent = str(kid) in (record.get("keypoints") or {}) and record["keypoints"][str(kid)] is None

        def change(rec: dict) -> None:  # every selected keypoint to the first one's next state
            for k in kids:
                if absent:  # visible again: the hand's "absent" taken back, the source's position shows
                    set_visible(rec, k)
                elif occluded:
                    set_occluded(rec, k, False)
                    set_keypoint(rec, k, None)
                else:
                    set_occluded(rec, k, True)

        self.trail.act(stem, lambda: tab.state.write(stem, change, settings=tab.settings))
        now = "visible" if absent else "absent" if occluded else "occluded"
        obs = tab.state.view(stem, tab.settings).observations
        if now == "visible" and (obs is None or kid not in obs.kp_ids):
            now = "absent (nothing else puts it on this frame: Shift+click places it)"
        named = f"point {kid}" if len(kids) == 1 else f"points {', '.join(map(str, kids))}"
        tab.notify(f"{named} {now}", f"{stem}: {named} {now} now (O cycles visible, occluded, absent)", error=False)
        if now == "absent":
            self.selected, self.also = None, []

    def set_note(self, text: str) -> None:
        """The frame's note for a colleague (saved at once, exported in the manifest; not a label
        change: the review status stays)."""
        from pnlviz.data.edit_changes import set_note

        tab, stem = self.tab, self.tab.stem
        self.trail.act(stem, lambda: tab.state.write(stem, lambda rec: set_note(rec, str(text)), corrected=False,
                                                     merge=("note", stem)))  # typing: one undo step

    def bulk(self, action: str, scope: str, to: int | None = None) -> None:
        """A bulk action (:mod:`pnlviz.app.bulk`) on the selected keypoint (else the place id) over
        ``scope``: "this frame", "this shot" or "filtered frames" (the tab's filter); ``to``: the
        id a rename gives it. The first time the panel says what it would change (the count);
        the same action again runs it, all of it one undo step (Ctrl+Z)."""
        from pnlviz.app import bulk as work

        tab, st = self.tab, self.tab.state
        sel = self.selected
        kid = sel.kid if sel is not None and sel.kind is not PointKind.LINE_POINTS else self.place_id
        if scope == "this shot":
            stems = st.shots.shot_stems(tab.stem, tab.settings)
            if stems is None:
                tab.notify("not a clip", f"{tab.stem} is not a frame of a clip: no shot", error=False)
                return
        elif scope == "filtered frames":
            stems = [st.stems[i] for i in tab.frames.order]
        else:
            stems = [tab.stem]
        try:
            bulk = work.plan(stems, action, int(kid), to=to, record=st.edits.get,
                             view=lambda s: st.view(s, tab.settings, keep=s == tab.stem))
        except EditError as exc:
            tab.notify("refused", str(exc))
            return
        key = (bulk.action, bulk.kid, bulk.to, bulk.stems)
        if not bulk.stems:
            self.bulk_asked = None
            tab.panels.bulk_text.content = f"nothing to do: {bulk.text()}"
            return
        if self.bulk_asked != key:
            self.bulk_asked = key
            tab.panels.bulk_text.content = f"**{bulk.text()}**: *apply* again runs it (one undo step)"
            return
        self.bulk_asked = None
        changed = self.trail.act_many(list(bulk.stems), lambda: work.apply(bulk, st.write, tab.settings))
        tab.panels.bulk_text.content = f"done: {bulk.text()}: {len(changed)} changed (Ctrl+Z takes it all back)"
        tab.notify("bulk action done", f"{bulk.text()}: {len(changed)} frames changed", error=False)
        tab.show()

    def apply_fix(self) -> None:
        """The suggested fix of the frame's worst finding (the label-error finder's: a class
        renamed, stray points dropped, points moved onto their marking, a marking added), applied
        as an edit of the annotation (Ctrl+Z takes it back)."""
        from pnlviz.app.triage import fix_frame

        stem, found = self.tab.stem, []
        self.trail.act(stem, lambda: found.append(fix_frame(self.tab.state, stem, self.tab.settings)))
        if found and found[0] is not None:
            self.tab.notify("fix applied", f"{found[0].message} -> {found[0].fix['op']} (Ctrl+Z takes it back)",
                            error=False)
        else:
            self.tab.notify("nothing to fix", "the label-error finder suggests no fix for this frame", error=False)

    def place(self, stem: str, uv, kid: int | None = None) -> None:
        """Put keypoint ``kid`` (default: the chosen id) at pixel ``uv`` of ``stem`` (shift+click;
        a ghost's own position is not snapped)."""
        if kid is None:
            kid, uv = self.place_id, self._snapped(uv)
        else:
            self.place_id = int(kid)
        x, y = float(uv[0]), float(uv[1])
        self.trail.act(stem, lambda: self.tab.state.move_keypoint(stem, kid, x, y, settings=self.tab.settings))
        self.tab.queue.enqueue(lambda: say_slip(self.tab, stem, kid))  # after the frame is drawn
        overlay = self.tab.painter.overlay
        if stem == self.tab.stem and overlay is not None and kid in overlay.keypoints.keys:
            self.select(Selection(PointKind.KEYPOINTS, kid))

    def nudge(self, dx: int, dy: int) -> None:
        """Move the selected point by (dx, dy) image pixels (arrow keys)."""
        sel, overlay = self.selected, self.tab.painter.overlay
        if sel is None or overlay is None or sel.kind is PointKind.GHOSTS:
            return
        markers = overlay.keypoints if sel.kind is PointKind.KEYPOINTS else overlay.line_points
        if sel.key not in markers.keys:
            return
        uv = markers.uv[markers.keys.index(sel.key)] + [dx, dy]
        self.release(self.tab.stem, sel, uv, snap_to_pitch=False, merge=("nudge", sel.kind, sel.key))

    def release(self, stem: str, point: Selection, uv, snap_to_pitch: bool = True, merge: object = None) -> None:
        """A point of ``stem`` was dropped at pixel ``uv``: the edit goes to ``stem``, the frame
        the drag began on, whatever this tab shows now (``merge``: nudges of one point in a row
        are one undo step)."""
        t0 = time.perf_counter()
        uv = self._snapped(uv) if snap_to_pitch else np.asarray(uv, float)
        state, settings = self.tab.state, self.tab.settings

        def edit() -> None:
            x, y = float(uv[0]), float(uv[1])
            if point.kind is PointKind.LINE_POINTS:
                state.move_line_point(stem, *point.line_point, x, y, settings=settings)
            else:
                state.move_keypoint(stem, point.kid, x, y, settings=settings, merge=merge)
            state.view(stem, settings)  # recalibrate now, to time it
            self.last_recalibration_ms = 1e3 * (time.perf_counter() - t0)

        self.trail.act(stem, edit)
        if point.kind is not PointKind.LINE_POINTS:
            self.tab.queue.enqueue(lambda: say_slip(self.tab, stem, point.kid))  # after the frame is drawn
        if point.kind is PointKind.GHOSTS and stem == self.tab.stem:
            self.select(Selection(PointKind.KEYPOINTS, point.kid))

    def undo(self) -> None:
        """Take back this tab's last change (going back to its frame), else the frame's last one."""
        self.trail.undo(self.tab.stem, self._goto_stem, self.tab.settings)

    def redo(self) -> None:
        self.trail.redo(self.tab.stem, self._goto_stem, self.tab.settings)

    def _goto_stem(self, stem: str) -> None:
        self.tab.goto(self.tab.state.index_of(stem))

    def _snapped(self, uv) -> np.ndarray:
        """``uv``, or with snapping on, the projected intersection or pitch line it was dropped by."""
        uv = np.asarray(uv, float)
        view, overlay, view2d = self.tab.painter.shown, self.tab.painter.overlay, self.tab.view_control.view2d
        if not self.snap or view is None or view.camera is None or view2d is None:
            return uv
        proj = view.camera.project(self.tab.state.model.keypoint_xyz())
        ok = np.all(np.isfinite(proj), axis=1)
        segments = overlay.segments.get("refined_pitch") if overlay is not None else None
        snapped, _ = snap(uv, proj[ok], segments.points if segments is not None else np.zeros((0, 2, 2)),
                          SNAP_PX / view2d.zoom)
        return snapped

    # ------------------------------------------------------------------ pointer events
    def click(self, uv) -> None:
        """A click beside the points: the nearest point within reach is selected, else nothing."""
        view2d = self.tab.view_control.view2d
        best, best_d = None, CLICK_REACH_PX / (view2d.zoom if view2d else 1.0)
        kinds: tuple[PointKind, ...] = (PointKind.KEYPOINTS, PointKind.GHOSTS)
        kinds += (PointKind.LINE_POINTS,) if self.drag_mode is DragMode.LINE_POINTS else ()
        for kind in kinds:
            nodes = self.tab.workspace.points[kind]
            for key, p in zip(nodes.keys, nodes.uv):
                d = float(np.hypot(*(p - uv)))
                if d < best_d:
                    best, best_d = Selection(kind, key), d
        self.select(best)

    def on_place(self, uv, kid: int | None = None) -> None:
        """Shift+click (on viser's event loop): placed on the frame shown when it came; ``kid``:
        that keypoint (a ghost shift+clicked: it is placed where the camera puts it), else the
        chosen id."""
        stem = self.tab.painter.shown_stem
        self.tab.queue.enqueue(lambda: self.place(stem, uv, kid))

    def on_click(self, uv) -> None:
        self.tab.queue.enqueue(lambda: self.click(uv))

    def on_pick(self, point: Selection) -> None:
        self.tab.queue.enqueue(lambda: self.select(point))

    def drag(self, event: DragEvent) -> None:
        """A point is dragged (called on viser's event loop, in order): the point follows the hand
        on screen at once; the frame is recalibrated as it moves (the latest position only,
        nothing saved) and for good when it is released."""
        enqueue, uv = self.tab.queue.enqueue, np.asarray(event.uv, float)
        if event.phase is DragPhase.START:
            self.grabs += 1
            self.dragging = Drag(self.tab.painter.shown_stem, event.point, uv, uv)
            enqueue(lambda: self.select(event.point))
            return
        drag = self.dragging
        if drag is None or drag.point.key != event.key:
            return
        drag.uv = uv
        if event.phase is DragPhase.UPDATE and not drag.pending and self.live_preview:
            drag.pending = True
            enqueue(self._preview)
        elif event.phase is DragPhase.END:
            self.dragging = None
            self.releases += 1
            if drag.moved:
                enqueue(lambda: self.release(drag.stem, event.point, drag.uv))
            else:
                enqueue(self.tab.show)

    def _preview(self) -> None:
        """The frame as it would be with the dragged keypoint where it is now (not kept). Given up
        as soon as the point is let go somewhere else: the release's own calibration, which the
        hand waits for, then starts at once instead of after this one."""
        drag = self.dragging
        if drag is None:
            return
        drag.pending = False
        if drag.point.kind is not PointKind.KEYPOINTS or drag.stem != self.tab.stem:
            return  # a ghost becomes a keypoint (and a line point changes no keypoint) on release
        uv = drag.uv.copy()
        try:
            with cancellable(lambda: self.dragging is not drag and not np.array_equal(drag.uv, uv)):
                view = self.tab.state.preview(drag.stem, self.tab.settings, drag.point.kid, *uv)
        except EditError:
            return
        except Cancelled:
            self.previews_given_up += 1
            return
        if self.dragging is drag:  # still dragging: show the frame as it would be
            self.tab.painter.show_overlay(view, preview=True)


__all__ = ["CLICK_REACH_PX", "SNAP_PX", "Drag", "EditTrail", "Editor"]
