"""A tracker's boxes, read for ``pnlviz export --format gsr``: MOTChallenge text or COCO JSON.

* **MOT** (``.txt``, ``.csv``): one box per line, ``frame, id, left, top, width, height[, conf,
  ...]``; ``frame`` counts from 1 (frame 1 is the dataset's first frame, in its order); an ``id``
  below 0 (MOT's -1) is a box without a track.
* **COCO** (``.json``): ``images`` (``id``, ``file_name``) and ``annotations`` (``image_id``,
  ``bbox`` ``[x, y, w, h]`` or sn-gamestate's ``bbox_image`` ``{x, y, w, h}``, optional
  ``track_id``, ``category_id``, ``attributes``); ``categories`` name the roles. An image is the
  dataset frame whose stem is its file name without the extension (its base name when that is
  unique), or without a file name the frame at its id (1 is the first, as pnlviz's COCO export
  numbers them).

Boxes are in the pixels of the frame's own image. Every problem is a one-line :class:`DataError`
naming the file and the line or annotation; nothing is guessed.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import PurePosixPath
from typing import Any

from pnlviz.data.errors import DataError
from pnlviz.data.jsonio import as_number, describe, parse_json_bytes
from pnlviz.data.limits import MAX_JSON_BYTES
from pnlviz.data.reading import read_file

__all__ = ["Box", "TrackerBoxes", "read_boxes", "ROLES"]

#: sn-gamestate's object categories (Labels-GameState.json): name -> category id; any other
#: category is "other" (7).
ROLES = {"player": 1, "goalkeeper": 2, "referee": 3, "ball": 4, "other": 7}


@dataclass(frozen=True)
class Box:
    """One box in a frame's pixels: left, top, width, height; its track (None: untracked), its
    role (one of :data:`ROLES`; None where the file does not say, as in MOT), the detector's score and the attributes a COCO file gave it."""

    x: float
    y: float
    w: float
    h: float
    track_id: int | None = None
    role: str | None = None
    score: float | None = None
    attributes: dict[str, Any] = field(default_factory=dict)


@dataclass
class TrackerBoxes:
    """A tracker's boxes by image: ``images`` maps an image key to ``(image id, file name or
    None)``; ``boxes`` maps it to its boxes. The key is the MOT frame number, or the COCO image id
    as a string."""

    path: str
    kind: str  # "mot" or "coco"
    images: dict[Any, tuple[str, str | None]]
    boxes: dict[Any, list[Box]]

    def frame_of(self, key: Any, stems: list[str] | tuple[str, ...]) -> str | None:
        """The dataset stem an image key names (None: no such frame in ``stems``)."""
        image_id, file_name = self.images[key]
        if file_name is not None:
            name = PurePosixPath(file_name.replace("\\", "/"))
            full = str(name.with_suffix(""))
            if full in stems:
                return full
            base = name.stem
            hits = [s for s in stems if PurePosixPath(s).name == base]
            return hits[0] if len(hits) == 1 else None
        n = key if self.kind == "mot" else int(image_id) if image_id.isdigit() else None
        return stems[n - 1] if n is not None and 1 <= n <= len(stems) else None

    def __len__(self) -> int:
        return sum(len(b) for b in self.boxes.values())


def _positive_box(source: str, x: Any, y: Any, w: Any, h: Any) -> tuple[float, float, float, float]:
    vals = [as_number(v) for v in (x, y, w, h)]
    if any(v is None or not math.isfinite(v) for v in vals):
        raise DataError(source, f"a box needs four finite numbers (x, y, w, h), got {describe([x, y, w, h])}")
    bx, by, bw, bh = (float(v) for v in vals)  # type: ignore[arg-type]
    if bw <= 0 or bh <= 0:
        raise DataError(source, f"a box's width and height must be positive, got {bw:g} x {bh:g}")
    return bx, by, bw, bh


def _text_number(text: str) -> float | None:
    """A number written in a text file (None for anything else, NaN and infinities included)."""
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def _read_mot(path: str, text: str) -> TrackerBoxes:
    boxes: dict[Any, list[Box]] = {}
    for n, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        where = f"{path}:{n}"
        cols = [c.strip() for c in line.split(",")]
        if len(cols) < 6:
            raise DataError(where, f"a MOT line has at least 6 comma-separated columns (frame, id, left, top, width, "
                                   f"height), got {len(cols)}")
        frame, track = _text_number(cols[0]), _text_number(cols[1])
        if frame is None or frame != int(frame) or frame < 1:
            raise DataError(where, f"the frame number must be a whole number from 1, got {describe(cols[0])}")
        if track is None or track != int(track):
            raise DataError(where, f"the track id must be a whole number (-1: none), got {describe(cols[1])}")
        x, y, w, h = _positive_box(where, *(_text_number(c) for c in cols[2:6]))
        score = _text_number(cols[6]) if len(cols) > 6 else None
        boxes.setdefault(int(frame), []).append(Box(x, y, w, h, int(track) if track >= 0 else None, None, score))
    return TrackerBoxes(path, "mot", {k: (str(k), None) for k in boxes}, boxes)


def _read_coco(path: str, obj: Any) -> TrackerBoxes:
    if not isinstance(obj, dict) or not isinstance(obj.get("annotations"), list):
        raise DataError(path, "a COCO file is an object with an 'annotations' list")
    names: dict[str, str] = {}
    for c in obj.get("categories") or []:
        if isinstance(c, dict) and "id" in c:
            names[str(c["id"])] = str(c.get("name", "")).strip().lower()
    images: dict[Any, tuple[str, str | None]] = {}
    for i, im in enumerate(obj.get("images") or []):
        if not isinstance(im, dict) or "id" not in im and "image_id" not in im:
            raise DataError(path, f"images[{i}] has no 'id'")
        image_id = str(im.get("id", im.get("image_id")))
        file_name = im.get("file_name")
        images[image_id] = (image_id, str(file_name) if file_name else None)
    boxes: dict[Any, list[Box]] = {}
    for i, a in enumerate(obj["annotations"]):
        where = f"{path}: annotations[{i}]"
        if not isinstance(a, dict) or "image_id" not in a:
            raise DataError(where, "has no 'image_id'")
        if "bbox" not in a and "bbox_image" not in a:
            continue  # not a box (sn-gamestate's camera and pitch annotations)
        if a.get("bbox") is not None:
            bbox = a["bbox"]
            if not isinstance(bbox, list) or len(bbox) != 4:
                raise DataError(where, f"'bbox' must be [x, y, w, h], got {describe(bbox)}")
            x, y, w, h = _positive_box(where, *bbox)
        else:
            b = a["bbox_image"]
            if not isinstance(b, dict):
                raise DataError(where, f"'bbox_image' must be an object {{x, y, w, h}}, got {describe(b)}")
            x, y, w, h = _positive_box(where, b.get("x"), b.get("y"), b.get("w"), b.get("h"))
        given = a.get("attributes")
        attrs: dict[str, Any] = given if isinstance(given, dict) else {}
        role = str(attrs.get("role") or names.get(str(a.get("category_id"))) or "").lower() or None
        track = as_number(a.get("track_id")) if a.get("track_id") is not None else None
        image_id = str(a["image_id"])
        images.setdefault(image_id, (image_id, None))
        boxes.setdefault(image_id, []).append(Box(
            x, y, w, h, int(track) if track is not None and track >= 0 else None, role if role is None or role in ROLES else "other",
            as_number(a.get("score")), dict(attrs)))
    return TrackerBoxes(path, "coco", images, boxes)


def read_boxes(path: str | os.PathLike) -> TrackerBoxes:
    """A tracker's boxes from a MOT text file or a COCO JSON file (by its content: JSON starts
    with ``{``), at most :data:`~pnlviz.data.limits.MAX_JSON_BYTES`."""
    source = os.fspath(path)
    data = read_file(path, MAX_JSON_BYTES, source)
    head = data.lstrip()[:1]
    if head == b"{":
        return _read_coco(source, parse_json_bytes(data, source))
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise DataError(source, "neither a COCO JSON file nor MOT text (not UTF-8)") from None
    return _read_mot(source, text)
