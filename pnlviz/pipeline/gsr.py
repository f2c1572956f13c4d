"""``pnlviz export --format gsr``: the export's cameras, and a tracker's boxes placed on the pitch,
as one JSON file in the layout of SoccerNet Game State Reconstruction's ``Labels-GameState.json``
(what sn-gamestate reads and writes):

* ``images``: one per exported frame, ``image_id`` a string (the tracker's COCO image id when its
  boxes came from a COCO file, else the frame's place in the dataset from 1, as MOT numbers
  frames and pnlviz's COCO export numbers images), ``file_name``, ``width``, ``height``, and
  pnlviz's ``stem``, ``reviewed`` and ``review``;
* ``annotations``: per frame with a camera, one ``supercategory: "camera"`` annotation whose
  ``parameters`` is the SoccerNet camera dict **at the frame's own image size** (SoccerNet's
  ``Camera.from_json_parameters`` reads it as is); per box, a ``supercategory: "object"``
  annotation with ``bbox_image`` ``{x, y, x_center, y_center, w, h}`` and ``bbox_pitch``
  ``{x_bottom_left, y_bottom_left, x_bottom_middle, y_bottom_middle, x_bottom_right,
  y_bottom_right}``: metres in SoccerNet's world frame (origin at the centre spot), the ground
  under the box's bottom corners and middle (:func:`pnlviz.geometry.footprint.boxes_on_pitch`);
  null without a camera or where a corner's ray misses the ground (above the horizon);
* ``categories``: sn-gamestate's (player 1, goalkeeper 2, referee 3, ball 4, pitch 5, camera 6,
  other 7); a box whose role the tracker did not give is ``other`` with ``role: null``.

The frames are the export's (accepted and corrected ones unless ``--all``) with the cameras the
label export writes for them; boxes on other frames are counted, not placed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pnlviz.data.atomic import atomic_write_bytes
from pnlviz.data.boxes import ROLES, Box, TrackerBoxes
from pnlviz.data.jsonio import dumps
from pnlviz.geometry.camera import Camera
from pnlviz.geometry.footprint import boxes_on_pitch
from pnlviz.pipeline.export import FrameExport
from pnlviz.pipeline.reader import FrameReader

__all__ = ["GSR_CATEGORIES", "GsrWriter", "bbox_pitch_dicts"]

GSR_CATEGORIES = [{"supercategory": "object", "id": ROLES["player"], "name": "player"},
                  {"supercategory": "object", "id": ROLES["goalkeeper"], "name": "goalkeeper"},
                  {"supercategory": "object", "id": ROLES["referee"], "name": "referee"},
                  {"supercategory": "object", "id": ROLES["ball"], "name": "ball"},
                  {"supercategory": "pitch", "id": 5, "name": "pitch"},
                  {"supercategory": "camera", "id": 6, "name": "camera"},
                  {"supercategory": "object", "id": ROLES["other"], "name": "other"}]
_SIDES = ("left", "middle", "right")


def bbox_pitch_dicts(camera: Camera | None, boxes: list[Box]) -> list[dict[str, float] | None]:
    """Each box's ``bbox_pitch`` (the six keys, metres) under ``camera`` at the image size the
    boxes are in; None for every box without a camera, and for a box one of whose bottom points
    has no ground point."""
    if camera is None or not boxes:
        return [None] * len(boxes)
    ground = boxes_on_pitch(camera, np.array([[b.x, b.y, b.w, b.h] for b in boxes], float))
    out: list[dict[str, float] | None] = []
    for g in ground:
        if not np.isfinite(g).all():
            out.append(None)
            continue
        d = {}
        for side, (x, y) in zip(_SIDES, g):
            d[f"x_bottom_{side}"], d[f"y_bottom_{side}"] = float(x), float(y)
        out.append(d)
    return out


def _bbox_image(b: Box) -> dict[str, float]:
    return {"x": b.x, "y": b.y, "x_center": b.x + b.w / 2, "y_center": b.y + b.h / 2, "w": b.w, "h": b.h}


@dataclass
class GsrWriter:
    """Collects the export's frames (:class:`FrameExport`, in any order) and writes the GSR file
    at :meth:`close` (atomically: a failed export leaves ``out`` as it was)."""

    reader: FrameReader
    out: Path
    boxes: TrackerBoxes | None = None
    include_all: bool = False
    _parts: dict[str, FrameExport] = field(default_factory=dict)
    _box_keys: dict[str, Any] = field(default_factory=dict)
    unmatched_boxes: int = 0

    def __post_init__(self) -> None:
        stems = list(self.reader.stems)
        if self.boxes is not None:
            for key in self.boxes.boxes:
                stem = self.boxes.frame_of(key, stems)
                if stem is None:
                    self.unmatched_boxes += len(self.boxes.boxes[key])
                else:
                    self._box_keys[stem] = key

    def add(self, part: FrameExport) -> None:
        self._parts[part.stem] = part

    def _image_id(self, stem: str) -> str:
        key = self._box_keys.get(stem)
        if key is not None and self.boxes is not None and self.boxes.kind == "coco":
            return self.boxes.images[key][0]
        return str(self.reader.index_of(stem) + 1)

    def document(self) -> tuple[dict, dict[str, int]]:
        """The GSR JSON object and its counts (frames, cameras, boxes placed, boxes on frames
        without a camera or not exported)."""
        images, annotations = [], []
        counts = {"frames": 0, "cameras": 0, "boxes": 0, "boxes_without_camera": 0, "boxes_not_exported": 0,
                  "boxes_unmatched": self.unmatched_boxes}
        ids = iter(range(1, 1 << 62))
        for stem in self.reader.stems:
            part = self._parts.get(stem)
            key = self._box_keys.get(stem)
            frame_boxes = self.boxes.boxes[key] if key is not None and self.boxes is not None else []
            if part is None or part.coco_image is None:  # not exported (unreviewed, unreadable)
                counts["boxes_not_exported"] += len(frame_boxes)
                continue
            image_id = self._image_id(stem)
            W, H = int(part.coco_image["width"]), int(part.coco_image["height"])
            camera = None if part.camera is None else Camera.from_soccernet(part.camera).scaled(W, H)
            counts["frames"] += 1
            images.append({"image_id": image_id, "file_name": part.coco_image["file_name"], "width": W, "height": H,
                           "stem": stem, "reviewed": bool(part.coco_image["reviewed"]),
                           "review": part.entry.get("review"), "has_labeled_camera": camera is not None})
            if camera is not None:
                counts["cameras"] += 1
                annotations.append({"id": str(next(ids)), "image_id": image_id, "supercategory": "camera",
                                    "category_id": 6, "parameters": camera.to_soccernet()})
            for box, pitch in zip(frame_boxes, bbox_pitch_dicts(camera, frame_boxes)):
                counts["boxes"] += 1
                counts["boxes_without_camera"] += pitch is None
                role = box.role
                attributes = {"role": role, "team": None, "jersey": None, **box.attributes}
                attributes["role"] = role
                ann: dict[str, Any] = {"id": str(next(ids)), "image_id": image_id, "track_id": box.track_id,
                                       "supercategory": "object", "category_id": ROLES[role or "other"],
                                       "bbox_image": _bbox_image(box), "bbox_pitch": pitch, "attributes": attributes}
                if box.score is not None:
                    ann["score"] = box.score
                annotations.append(ann)
        info = {"format": "Labels-GameState (sn-gamestate)", "source": self.reader.data.resolve().name,
                "exported": time.strftime("%Y-%m-%dT%H:%M:%S"), "include_all": self.include_all,
                "boxes": None if self.boxes is None else Path(self.boxes.path).name,
                "camera_size": "each frame's own image size"}
        return {"info": info, "images": images, "annotations": annotations, "categories": GSR_CATEGORIES}, counts

    def close(self) -> dict[str, int]:
        doc, counts = self.document()
        atomic_write_bytes(self.out, (dumps(doc, indent=1) + "\n").encode())
        return counts
