"""The pitch model: lines, circles, keypoint catalogue and the WC14 template, loaded from
``assets/field_model/soccer_pitch.json`` (see ``assets/field_model/README.md`` for the format).

Everything is in the SoccerNet world frame (metres, origin at the centre spot, z down).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from pnlviz.paths import ASSETS_DIR
from pnlviz.field.names import CIRCLE_CLASSES, IGNORED_CLASSES, STRAIGHT_CLASSES

DEFAULT_MODEL_PATH = ASSETS_DIR / "field_model" / "soccer_pitch.json"

KEYPOINT_GROUPS = ("Kp", "Kp1", "Kp2", "Kp3", "Kpe")
DEFINITION_KINDS = ("line_line", "extended_line_line", "line_circle", "tangent", "additional")


class FieldModelError(ValueError):
    """The pitch model file is malformed."""


@dataclass(frozen=True)
class Segment:
    name: str
    start: np.ndarray  # (3,)
    end: np.ndarray  # (3,)
    plane: str  # "ground", "goal_left" or "goal_right"

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.end - self.start))


@dataclass(frozen=True)
class Arc:
    name: str
    center: np.ndarray  # (3,)
    radius: float
    start_deg: float
    end_deg: float  # > start_deg; counter-clockwise from +x towards +y

    def point_at(self, angle_rad: np.ndarray | float) -> np.ndarray:
        a = np.asarray(angle_rad, dtype=float)
        return np.stack(
            [self.center[0] + self.radius * np.cos(a), self.center[1] + self.radius * np.sin(a),
             np.full_like(a, self.center[2])], axis=-1)

    def contains_angle(self, angle_rad: np.ndarray) -> np.ndarray:
        """True where the direction ``angle_rad`` (from the centre) lies on the arc."""
        start = math.radians(self.start_deg)
        span = math.radians(self.end_deg - self.start_deg)
        rel = np.mod(np.asarray(angle_rad) - start, 2 * np.pi)
        return rel <= span + 1e-12


@dataclass(frozen=True)
class Keypoint:
    id: int
    group: str
    xyz: np.ndarray  # true geometry
    definition: dict
    pnlcalib_xyz: np.ndarray  # where PnLCalib's table puts it (equals xyz except id 52)


@dataclass(frozen=True, eq=False)  # compared and hashed by identity: per-model caches key on it
class FieldModel:
    dimensions: dict
    lines: dict[str, Segment]
    circles: dict[str, Arc]
    keypoints: dict[int, Keypoint]
    template: dict
    source: Path | None = None
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    # ------------------------------------------------------------------ keypoints
    @property
    def keypoint_ids(self) -> np.ndarray:
        return np.array(sorted(self.keypoints), dtype=int)

    def keypoint_xyz(self, ids=None, *, pnlcalib: bool = False) -> np.ndarray:
        """(N, 3) world coordinates of ``ids`` (default: all, sorted). ``pnlcalib=True`` uses
        PnLCalib's table positions (what its published networks detect)."""
        ids = self.keypoint_ids if ids is None else ids
        attr = "pnlcalib_xyz" if pnlcalib else "xyz"
        return np.array([getattr(self.keypoints[int(i)], attr) for i in ids], dtype=float).reshape(-1, 3)

    def keypoint_names(self) -> dict[int, str]:
        """A distinct name in words for every keypoint id (see :func:`keypoint_names`)."""
        return keypoint_names(self)

    def unmarked_points(self) -> dict[int, str]:
        """``{id: line or circle class}`` of the keypoints on a marking where nothing painted
        crosses it (see :func:`unmarked_points`)."""
        return unmarked_points(self)

    def keypoints_in_group(self, group: str) -> list[int]:
        return [k.id for k in self.keypoints.values() if k.group == group]

    # ------------------------------------------------------------------ polylines
    def sample_polylines(self, spacing: float = 0.1, circle_spacing: float = 0.2) -> dict[str, np.ndarray]:
        """Points along every class, ``{class: (N, 3)}``, sampled the way the SoccerNet evaluator
        does (``SoccerPitch.sample_field_points``): straight classes from start to end every
        ``spacing`` metres with the end appended; the centre circle every ``circle_spacing``
        metres without repeating its first point; the penalty arcs every ``circle_spacing``
        metres with both arc ends included."""
        key = ("polylines", float(spacing), float(circle_spacing))
        if key not in self._cache:
            out: dict[str, np.ndarray] = {}
            for name in CIRCLE_CLASSES:
                out[name] = _sample_arc(self.circles[name], circle_spacing)
            for name in STRAIGHT_CLASSES:
                seg = self.lines[name]
                n_inner = int(seg.length / spacing - 1)
                direction = (seg.end - seg.start) / seg.length
                steps = spacing * np.arange(1, max(n_inner, 0) + 1)[:, None]
                out[name] = np.vstack([seg.start, seg.start + steps * direction, seg.end])
            for arr in out.values():
                arr.setflags(write=False)
            self._cache[key] = out
        return self._cache[key]

    def sample_points(self, spacing: float = 0.1, circle_spacing: float = 0.2) -> np.ndarray:
        """Every class's :meth:`sample_polylines` as one array (N, 3), made once."""
        key = ("points", float(spacing), float(circle_spacing))
        if key not in self._cache:
            points = np.vstack(list(self.sample_polylines(spacing, circle_spacing).values()))
            points.setflags(write=False)
            self._cache[key] = points
        return self._cache[key]

    # ------------------------------------------------------------------ WC14 template
    def field_to_template(self, xy: np.ndarray) -> np.ndarray:
        """Field metres (X, Y) -> WC14 template yards: (X + 52.5, Y + 34) * 1.09361."""
        t = self.template
        return (np.asarray(xy, float)[..., :2] - np.asarray(t["origin_in_field"])) * t["metres_to_template"]

    def template_to_field(self, uv: np.ndarray) -> np.ndarray:
        t = self.template
        return np.asarray(uv, float)[..., :2] / t["metres_to_template"] + np.asarray(t["origin_in_field"])

    @property
    def template_to_field_matrix(self) -> np.ndarray:
        """3x3 homogeneous map from template yards to field metres (on the ground plane)."""
        t = self.template
        s = 1.0 / t["metres_to_template"]
        ox, oy = t["origin_in_field"]
        return np.array([[s, 0, ox], [0, s, oy], [0, 0, 1.0]])


def _sample_arc(arc: Arc, spacing: float) -> np.ndarray:
    start = math.radians(arc.start_deg)
    length = arc.radius * math.radians(arc.end_deg - arc.start_deg)
    n = int(length / spacing)
    dangle = spacing / arc.radius
    if arc.end_deg - arc.start_deg >= 360.0 - 1e-9:  # full circle: the evaluator stops before closing
        angles = start + dangle * np.arange(0, n)
        return arc.point_at(angles)
    angles = start + dangle * np.arange(0, n + 1)
    return np.vstack([arc.point_at(angles), arc.point_at(math.radians(arc.end_deg))])


# ---------------------------------------------------------------------- loading and validation
def _vec3(value, where: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise FieldModelError(f"{where}: expected 3 finite numbers, got {value!r}")
    arr.setflags(write=False)
    return arr


def parse_field_model(data: dict, source: Path | None = None) -> FieldModel:
    """Validate the JSON structure of a pitch model and build a :class:`FieldModel`."""
    where = str(source or "field model")
    if data.get("format") != "pnlviz-field-model":
        raise FieldModelError(f"{where}: not a pnlviz field model (format={data.get('format')!r})")
    lines_raw, circles_raw = data.get("lines", {}), data.get("circles", {})
    missing = [n for n in STRAIGHT_CLASSES if n not in lines_raw] + [n for n in CIRCLE_CLASSES if n not in circles_raw]
    if missing:
        raise FieldModelError(f"{where}: missing classes {missing}")
    extra = set(lines_raw) - set(STRAIGHT_CLASSES) | set(circles_raw) - set(CIRCLE_CLASSES)
    if extra:
        raise FieldModelError(f"{where}: unknown classes {sorted(extra)}")
    lines = {}
    for name in STRAIGHT_CLASSES:
        raw = lines_raw[name]
        seg = Segment(name, _vec3(raw["start"], f"{where}: {name}.start"),
                      _vec3(raw["end"], f"{where}: {name}.end"), raw["plane"])
        if seg.length <= 0:
            raise FieldModelError(f"{where}: {name} has zero length")
        lines[name] = seg
    circles = {}
    for name in CIRCLE_CLASSES:
        raw = circles_raw[name]
        arc = Arc(name, _vec3(raw["center"], f"{where}: {name}.center"), float(raw["radius"]),
                  float(raw["start_deg"]), float(raw["end_deg"]))
        if not (arc.radius > 0 and arc.end_deg > arc.start_deg):
            raise FieldModelError(f"{where}: {name} needs radius > 0 and end_deg > start_deg")
        circles[name] = arc
    keypoints = {}
    known = set(STRAIGHT_CLASSES) | set(CIRCLE_CLASSES)
    for raw in data.get("keypoints", []):
        kid = int(raw["id"])
        if kid in keypoints:
            raise FieldModelError(f"{where}: duplicate keypoint id {kid}")
        if raw["group"] not in KEYPOINT_GROUPS:
            raise FieldModelError(f"{where}: keypoint {kid} has unknown group {raw['group']!r}")
        definition = raw["defined_by"]
        if definition.get("kind") not in DEFINITION_KINDS:
            raise FieldModelError(f"{where}: keypoint {kid} has unknown definition {definition!r}")
        for ref in list(definition.get("lines", [])) + [definition[k] for k in ("line", "circle") if k in definition]:
            if ref not in known:
                raise FieldModelError(f"{where}: keypoint {kid} refers to unknown class {ref!r}")
        xyz = _vec3(raw["xyz"], f"{where}: keypoint {kid}")
        pxyz = _vec3(raw.get("pnlcalib_xyz", raw["xyz"]), f"{where}: keypoint {kid}.pnlcalib_xyz")
        keypoints[kid] = Keypoint(kid, raw["group"], xyz, definition, pxyz)
    if sorted(keypoints) != list(range(1, 74)):
        raise FieldModelError(f"{where}: keypoint ids must be exactly 1..73")
    return FieldModel(dict(data["dimensions"]), lines, circles, keypoints, dict(data["wc14_template"]), source)


def load_field_model(path: str | Path | None = None) -> FieldModel:
    """Load and validate a pitch model (default: the bundled SoccerNet pitch). Cached."""
    return _load(Path(path) if path else DEFAULT_MODEL_PATH)


@lru_cache(maxsize=4)
def _load(path: Path) -> FieldModel:
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise FieldModelError(f"{path}: cannot read pitch model: {exc}") from exc
    return parse_field_model(data, path)


__all__ = ["Arc", "FieldModel", "FieldModelError", "Keypoint", "Segment", "load_field_model",
           "parse_field_model", "pitch_grid", "DEFAULT_MODEL_PATH", "IGNORED_CLASSES"]


def _base_name(kp: Keypoint) -> str:
    """What defines a keypoint, in the catalogue's words (the lines and circles through it)."""
    d = kp.definition
    if d.get("kind") == "tangent":
        return f"tangent to {d['circle']} from keypoint {d['from_keypoint']}"
    parts = d.get("lines") or [p for p in (d.get("line"), d.get("circle")) if p] or d.get("on") or []
    return " x ".join(str(p).strip() for p in parts)


@lru_cache(maxsize=4)
def keypoint_names(model: FieldModel) -> dict[int, str]:
    """``{id: name}``, distinct: what defines each keypoint, and where two share a definition (the
    two intersections of a line with a circle, a circle's diagonal points...) the side that tells
    them apart, in SoccerNet's words: *top* / *bottom* for y < 0 / y > 0 (the far and the near
    touchline), *left* / *right* for x < 0 / x > 0.

    >>> names = load_field_model().keypoint_names()
    >>> names[33], names[36]
    ('Big rect. right main x Circle right (top)', 'Big rect. right main x Circle right (bottom)')
    >>> len(set(names.values())) == len(names)
    True
    """
    base = {int(k): _base_name(kp) for k, kp in model.keypoints.items()}
    groups: dict[str, list[int]] = {}
    for kid, name in base.items():
        groups.setdefault(name, []).append(kid)
    out = {}
    for name, ids in groups.items():
        xyz = np.array([model.keypoints[k].xyz for k in ids])
        for kid, (x, y, _) in zip(ids, xyz):
            side = []
            if len(ids) > 1 and np.ptp(xyz[:, 1]) > 1e-6:
                side.append("top" if y < 0 else "bottom")
            if len(ids) > 1 and np.ptp(xyz[:, 0]) > 1e-6:
                side.append("left" if x < 0 else "right")
            out[kid] = f"{name} ({' '.join(side)})" if side else name
    if len(set(out.values())) != len(out):
        raise FieldModelError("two keypoints of the catalogue have the same definition and position")
    return dict(sorted(out.items()))


#: The unpainted directions the catalogue places points with (``additional`` keypoints where a
#: marking meets the pitch's long axis or a diagonal).
UNPAINTED = frozenset({"axis", "diagonal"})


@lru_cache(maxsize=4)
def unmarked_points(model: FieldModel) -> dict[int, str]:
    """``{keypoint id: line or circle class}`` of the catalogue points that lie on a painted
    marking where nothing painted crosses it: the tangent points of the circles, and where the
    long axis or a diagonal meets a circle or a box's main line (not the centre of the pitch,
    where the centre mark is painted). A picture shows the marking there, not the point: a
    network places such a point along its marking from the context (the light model on a
    synthetic clip: 1-4 px off along the centre circle, the same way through a shot), while
    across the marking it sees the paint.

    >>> sorted(load_field_model().unmarked_points().items())[:2]
    [(37, 'Circle left'), (38, 'Circle central')]
    """
    out = {}
    for kp in model.keypoints.values():
        d = kp.definition
        if d["kind"] == "tangent":
            out[int(kp.id)] = str(d["circle"])
        elif (d["kind"] == "additional" and (d["on"][0] in model.circles or d["on"][0] in model.lines)
              and set(d["on"][1:]) <= UNPAINTED and np.linalg.norm(np.asarray(kp.xyz)[:2]) > 0.5):
            out[int(kp.id)] = str(d["on"][0])
    return dict(sorted(out.items()))


def pitch_grid(spacing: float = 5.0, length: float = 105.0, width: float = 68.0) -> np.ndarray:
    """(N, 3) ground points every ``spacing`` metres over the pitch, centred on the centre spot
    (a camera's view of the pitch is compared on them: clip jitter, cuts between shots)."""
    xs = np.arange(-length / 2, length / 2 + 1e-9, spacing)
    ys = np.arange(-width / 2, width / 2 + 1e-9, spacing)
    return np.array([[x, y, 0.0] for x in xs for y in ys])
