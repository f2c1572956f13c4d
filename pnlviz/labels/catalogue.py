"""The keypoint catalogue rearranged for label generation (paper Sec. III-A, "Keypoint
Generation"): which pairs of annotated classes define which keypoint, and the world geometry
needed to disambiguate the two candidates that a line/ellipse or tangent construction yields.

Everything is derived from :func:`pnlviz.field.load_field_model` (never hard-coded ids), and
cached per model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.field.names import CIRCLE_CLASSES

#: Keypoint ids the published networks predict (heatmap channels 0..56).
NETWORK_KEYPOINT_IDS: tuple[int, ...] = tuple(range(1, 58))


@dataclass(frozen=True)
class LinePair:
    """A keypoint defined by two straight classes (sets Kp and Kpe)."""

    id: int
    lines: tuple[str, str]
    ground: bool  # z == 0 (the goal-frame corners 12, 15, 16, 19 are not)


@dataclass(frozen=True)
class CandidatePair:
    """Two image candidates from one construction and the world points they may be.

    ``world`` holds the two world points (2, 2) of the construction in the ground plane, and
    ``ids`` the catalogue id of each (None when that point is not in the catalogue, e.g. the
    tangent point of a penalty arc's tangent that falls inside the box where no arc is painted).
    """

    kind: str  # "Kp1" or "Kp2"
    circle: str
    line: str | None  # Kp1: the straight class
    external: int | None  # Kp2: the external keypoint id
    world: np.ndarray  # (2, 2)
    ids: tuple[int | None, int | None]


@dataclass(frozen=True)
class Catalogue:
    model: FieldModel
    kp: tuple[LinePair, ...]
    kpe: tuple[LinePair, ...]
    kp1: tuple[CandidatePair, ...]
    kp2: tuple[CandidatePair, ...]
    kp3: tuple[int, ...]
    ground_ids: frozenset[int]
    #: classes each keypoint "belongs to" (paper's keypoint mask): the classes that would have
    #: to be annotated for the point to be labelled from the annotation.
    belongs_to: dict[int, tuple[str, ...]]

    def world_xyz(self, ids, *, pnlcalib: bool = False) -> np.ndarray:
        return self.model.keypoint_xyz(list(ids), pnlcalib=pnlcalib)


def _line_circle_world(model: FieldModel, line: str, circle: str) -> np.ndarray:
    seg = model.lines[line]
    arc = model.circles[circle]
    p0, d = seg.start[:2], seg.end[:2] - seg.start[:2]
    d = d / np.linalg.norm(d)
    c, r = arc.center[:2], arc.radius
    # |p0 + t d - c|^2 = r^2
    f = p0 - c
    b = float(f @ d)
    disc = b * b - (float(f @ f) - r * r)
    if disc <= 0:
        raise ValueError(f"{line} does not cross {circle}")
    s = math.sqrt(disc)
    return np.array([p0 + (-b - s) * d, p0 + (-b + s) * d])


def _tangent_world(center: np.ndarray, radius: float, external: np.ndarray) -> np.ndarray:
    v = external - center
    dist = float(np.linalg.norm(v))
    if dist <= radius:
        raise ValueError("external point inside the circle")
    phi = math.atan2(v[1], v[0])
    alpha = math.acos(radius / dist)
    return np.array([center + radius * np.array([math.cos(phi + s * alpha), math.sin(phi + s * alpha)])
                     for s in (-1.0, 1.0)])


def _match_ids(model: FieldModel, world: np.ndarray, candidates: list[int], tol: float = 0.05):
    ids: list[int | None] = []
    for w in world:
        hit = None
        for kid in candidates:
            if np.linalg.norm(model.keypoints[kid].xyz[:2] - w) < tol:
                hit = kid
        ids.append(hit)
    return tuple(ids)


def _matched(pair: CandidatePair, ids: list[int]) -> CandidatePair:
    """``pair`` when its world points are the keypoints ``ids`` of its construction, else a ValueError."""
    wanted = set(ids)
    if set(i for i in pair.ids if i is not None) != wanted:
        raise ValueError(f"catalogue: cannot match the {pair.kind} construction on {pair.circle} "
                         f"to keypoints {sorted(wanted)}")
    return pair


def build_catalogue(model: FieldModel) -> Catalogue:
    kp: list[LinePair] = []
    kpe: list[LinePair] = []
    kp3: list[int] = []
    kp1_groups: dict[tuple[str, str], list[int]] = {}
    kp2_groups: dict[tuple[str, int], list[int]] = {}
    belongs: dict[int, tuple[str, ...]] = {}
    ground = set()
    for kid in sorted(model.keypoints):
        k = model.keypoints[kid]
        d = k.definition
        if abs(k.xyz[2]) < 1e-9:
            ground.add(kid)
        kind = d["kind"]
        if kind in ("line_line", "extended_line_line"):
            pair = LinePair(kid, (d["lines"][0], d["lines"][1]), kid in ground)
            (kp if kind == "line_line" else kpe).append(pair)
            belongs[kid] = tuple(d["lines"])
        elif kind == "line_circle":
            kp1_groups.setdefault((d["line"], d["circle"]), []).append(kid)
            belongs[kid] = (d["line"], d["circle"])
        elif kind == "tangent":
            kp2_groups.setdefault((d["circle"], int(d["from_keypoint"])), []).append(kid)
            belongs[kid] = (d["circle"],)
        elif kind == "additional":
            kp3.append(kid)
            on = []
            for item in d.get("on", []):
                if item in model.lines or item in model.circles:
                    on.append(item)
                elif item.startswith("penalty mark"):  # the centre of that penalty arc
                    on.append("Circle left" if item.endswith("left") else "Circle right")
            belongs[kid] = tuple(on)
    kp1: list[CandidatePair] = []
    for (line, circle), ids in kp1_groups.items():
        world = _line_circle_world(model, line, circle)
        kp1.append(_matched(CandidatePair("Kp1", circle, line, None, world, _match_ids(model, world, ids)), ids))
    kp2: list[CandidatePair] = []
    for (circle, ext), ids in kp2_groups.items():
        arc = model.circles[circle]
        world = _tangent_world(arc.center[:2], arc.radius, model.keypoints[ext].xyz[:2])
        kp2.append(_matched(CandidatePair("Kp2", circle, None, ext, world, _match_ids(model, world, ids)), ids))
    if any(p.circle not in CIRCLE_CLASSES for p in kp1 + kp2):
        raise ValueError("catalogue: Kp1/Kp2 must refer to circle classes")
    return Catalogue(model, tuple(kp), tuple(kpe), tuple(kp1), tuple(kp2), tuple(kp3),
                     frozenset(ground), belongs)


def get_catalogue(model: FieldModel | None = None) -> Catalogue:
    """The catalogue of ``model`` (default: the bundled pitch), built once per model."""
    return _catalogue_of(model or load_field_model())


@lru_cache(maxsize=8)
def _catalogue_of(model: FieldModel) -> Catalogue:
    """Cached by the model itself (a pitch model hashes by identity; the cache holds it, so a
    model that was dropped cannot be mistaken for a new one)."""
    return build_catalogue(model)
