"""JSON files of keypoint labels (what ``pnlviz labels`` writes, one ``<stem>.json`` per frame).

Schema (version 1), coordinates in **pixels** of the frame as stored (not normalised)::

    {
      "format": "pnlviz-keypoint-labels", "version": 1,
      "image_size": [W, H],
      "units": "pixels",
      "mirrored": false,                      # left-right disambiguation applied
      "homography": [[...], [...], [...]],    # world ground (X, Y, 1) metres -> pixels, or null
      "keypoints": {"<id>": {"x": float, "y": float, "visible": bool, "set": "Kp|Kpe|Kp1|Kp2|Kp3"}},
      "lines": {"<line id 1-23>": {"x_1": float, "y_1": float, "x_2": float, "y_2": float}},
      "rejected": [{"id": int|null, "set": str, "x": float|null, "y": float|null, "reason": str}]
    }

Keypoint ids are PnLCalib's (1-73, see ``assets/field_model``); ``visible`` means inside the
image (0 <= x <= W - 1, 0 <= y <= H - 1): Kp points may lie a little outside, Kpe points up to
half the image size outside. ``set = "Kp3"`` marks every point completed through the homography
(the 13 additional points, and with ``--kp3-all`` any other missing catalogue ground point).
Line extremities are ordered along the line's dominant image axis (``p1`` the left one for a
line closer to horizontal, the upper one otherwise).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping

import numpy as np

from pnlviz.data.atomic import atomic_write_text
from pnlviz.data.errors import DataError
from pnlviz.field.names import LINE_ID_TO_CLASS

from .types import SETS, KeypointLabel, KeypointLabels, LineExtremities, RejectedKeypoint

FORMAT = "pnlviz-keypoint-labels"
VERSION = 1

__all__ = ["FORMAT", "VERSION", "labels_from_dict", "labels_to_dict", "labels_to_json", "read_labels",
           "write_labels"]


def _num(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def labels_to_dict(labels: KeypointLabels, extremities: Mapping[int, LineExtremities] | None = None) -> dict:
    kps = {str(k): {"x": float(v.x), "y": float(v.y), "visible": bool(v.visible), "set": v.set}
           for k, v in sorted(labels.keypoints.items())}
    lines = {str(lid): {"x_1": float(e.p1[0]), "y_1": float(e.p1[1]), "x_2": float(e.p2[0]), "y_2": float(e.p2[1])}
             for lid, e in sorted((extremities or {}).items())}
    return {
        "format": FORMAT,
        "version": VERSION,
        "image_size": [int(labels.width), int(labels.height)],
        "units": "pixels",
        "mirrored": bool(labels.mirrored),
        "homography": None if labels.homography is None else [[float(v) for v in row] for row in labels.homography],
        "keypoints": kps,
        "lines": lines,
        "rejected": [{"id": r.id, "set": r.set, "x": _num(r.x), "y": _num(r.y), "reason": r.reason}
                     for r in labels.rejected],
    }


def labels_to_json(labels: KeypointLabels, extremities: Mapping[int, LineExtremities] | None = None) -> str:
    """The JSON text: one line per top-level scalar, keypoint, line and rejected candidate."""
    d = labels_to_dict(labels, extremities)
    dump = lambda v: json.dumps(v, allow_nan=False)  # noqa: E731
    parts = []
    for key, value in d.items():
        if key in ("keypoints", "lines") and value:
            inner = ",\n".join(f"  {dump(k)}: {dump(v)}" for k, v in value.items())
            parts.append(f" {dump(key)}: {{\n{inner}\n }}")
        elif key == "rejected" and value:
            inner = ",\n".join(f"  {dump(v)}" for v in value)
            parts.append(f" {dump(key)}: [\n{inner}\n ]")
        else:
            parts.append(f" {dump(key)}: {dump(value)}")
    return "{\n" + ",\n".join(parts) + "\n}\n"


def write_labels(path: str | os.PathLike, labels: KeypointLabels,
                 extremities: Mapping[int, LineExtremities] | None = None) -> None:
    """Write one label file atomically."""
    atomic_write_text(path, labels_to_json(labels, extremities))


def labels_from_dict(d: dict, source: str = "<labels>") -> tuple[KeypointLabels, dict[int, LineExtremities]]:
    """Parse a label dict back (DataError on anything malformed)."""
    try:
        if d.get("format") != FORMAT:
            raise ValueError(f"not a {FORMAT} file")
        w, h = (int(v) for v in d["image_size"])
        H = d.get("homography")
        labels = KeypointLabels(width=w, height=h, mirrored=bool(d.get("mirrored", False)),
                                homography=None if H is None else np.asarray(H, float).reshape(3, 3))
        for k, v in d.get("keypoints", {}).items():
            if v["set"] not in SETS:
                raise ValueError(f"keypoint {k}: unknown set {v['set']!r}")
            labels.keypoints[int(k)] = KeypointLabel(int(k), float(v["x"]), float(v["y"]), bool(v["visible"]), v["set"])
        for r in d.get("rejected", []):
            labels.rejected.append(RejectedKeypoint(r.get("id"), r.get("set", ""),
                                                    math.nan if r.get("x") is None else float(r["x"]),
                                                    math.nan if r.get("y") is None else float(r["y"]),
                                                    str(r.get("reason", ""))))
        ext = {}
        for k, v in d.get("lines", {}).items():
            lid = int(k)
            p1 = np.array([float(v["x_1"]), float(v["y_1"])])
            p2 = np.array([float(v["x_2"]), float(v["y_2"])])
            ext[lid] = LineExtremities(lid, LINE_ID_TO_CLASS[lid], p1, p2, np.vstack([p1, p2]))
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise DataError(source, f"bad keypoint label file: {exc}") from None
    return labels, ext


def read_labels(path: str | os.PathLike) -> tuple[KeypointLabels, dict[int, LineExtremities]]:
    try:
        with open(path, encoding="utf-8") as f:
            d = json.load(f)
    except (OSError, json.JSONDecodeError) as exc:
        raise DataError(os.fspath(path), f"cannot read keypoint labels: {exc}") from None
    return labels_from_dict(d, os.fspath(path))
