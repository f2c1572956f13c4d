"""The changes an edit makes to a frame's edit record (:mod:`pnlviz.data.edits`), as pure
functions of the record: a keypoint placed or made absent, occluded or not, a line point moved, the
frame's note. Whoever edits (the app's tabs, its bulk actions, a script) changes records the same
way, through the app's one door (:meth:`pnlviz.app.state.AppState.write`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping

from pnlviz.data.annotations import annotation_to_json, parse_annotation
from pnlviz.data.edits import MAX_NOTE, EditError

__all__ = ["move_line_point", "set_keypoint", "set_note", "set_occluded", "set_visible"]


def set_keypoint(rec: dict, kid: int, xy: tuple[float, float] | None) -> None:
    """In a record: keypoint ``kid`` at pixel ``xy``, or not visible (None)."""
    rec["keypoints"] = {**(rec.get("keypoints") or {}), str(kid): None if xy is None else list(xy)}


def set_occluded(rec: dict, kid: int, occluded: bool) -> None:
    """In a record: keypoint ``kid`` occluded (labelled where it is, but hidden behind a player or
    an object: COCO's v=1) or not."""
    ids = set(rec.get("occluded") or []) - {int(kid)}
    if occluded:
        ids.add(int(kid))
    rec["occluded"] = sorted(ids) or None


def set_note(rec: dict, text: str) -> None:
    """In a record: the frame's note (free text for a colleague; empty: none)."""
    if not isinstance(text, str):
        raise EditError(f"a note is text, got {type(text).__name__}")
    if len(text) > MAX_NOTE:
        raise EditError(f"a note has at most {MAX_NOTE} characters, got {len(text)}")
    rec["note"] = text.strip() or None


def move_line_point(rec: dict, source: Callable[[], Mapping | None], stem: str, name: str, index: int,
                    xy: tuple[float, float], size: tuple[int, int]) -> None:
    """In a record: point ``index`` of annotated class ``name`` at pixel ``xy`` of a frame of
    ``size``, in the edited annotation (made from ``source()``, the frame's own annotation, at the
    first change); EditError when the annotation has no such point."""
    edited = rec.get("annotation")
    ann = parse_annotation(edited) if edited is not None else source()
    if not ann or name not in ann or not (0 <= int(index) < len(ann[name])):
        raise EditError(f"{stem} has no point {index} on {str(name)[:40]!r}")
    W, H = size
    ann[name][int(index)] = [xy[0] / (W - 1), xy[1] / (H - 1)]
    rec["annotation"] = annotation_to_json(ann)


def set_visible(rec: dict, kid: int) -> None:
    """In a record: keypoint ``kid`` neither absent nor occluded: the hand's "absent" taken back,
    so the position its source (or an earlier placement) gives shows again."""
    set_occluded(rec, kid, False)
    rec["keypoints"] = {k: v for k, v in (rec.get("keypoints") or {}).items() if k != str(kid)} or None
