"""trimesh meshes of the pitch for the 3D view: painted markings (12 cm wide ribbons on the
ground), goal posts and crossbars (cylinders) and the net boxes. World frame: SoccerNet (z down);
markings are lifted ``lift`` metres above the grass (towards -z) so they do not z-fight with it.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from pnlviz.field.model import FieldModel, load_field_model


def _concatenate(parts: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """One mesh of ``parts`` (trimesh types the result as any geometry; meshes give a mesh)."""
    mesh = trimesh.util.concatenate(parts)
    assert isinstance(mesh, trimesh.Trimesh)
    return mesh


def _ribbon(points: np.ndarray, width: float, z: float) -> trimesh.Trimesh:
    """Flat strip of ``width`` centred on a 2D polyline (N, 2) at height ``z``."""
    p = np.asarray(points, float)[:, :2]
    d = np.gradient(p, axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n = np.stack([-d[:, 1], d[:, 0]], axis=1) * (width / 2)
    left, right = p + n, p - n
    verts = np.vstack([np.column_stack([left, np.full(len(p), z)]), np.column_stack([right, np.full(len(p), z)])])
    k = len(p)
    i = np.arange(k - 1)
    faces = np.vstack([np.stack([i, i + k, i + 1], 1), np.stack([i + 1, i + k, i + k + 1], 1)])
    return trimesh.Trimesh(verts, faces, process=False)


def _cylinder_between(a: np.ndarray, b: np.ndarray, radius: float, sections: int = 12) -> trimesh.Trimesh:
    a, b = np.asarray(a, float), np.asarray(b, float)
    length = float(np.linalg.norm(b - a))
    cyl = trimesh.creation.cylinder(radius=radius, height=length, sections=sections)
    # trimesh's cylinder is centred at the origin along +z: rotate +z onto (b - a), move to the middle
    T = trimesh.geometry.align_vectors([0, 0, 1], (b - a) / length)
    T[:3, 3] = (a + b) / 2
    cyl.apply_transform(T)
    return cyl


def markings_mesh(model: FieldModel | None = None, lift: float = 0.005) -> trimesh.Trimesh:
    """All ground markings as one mesh: straight ground lines, the three circle classes, the centre
    spot and the penalty spots."""
    model = model or load_field_model()
    w = model.dimensions["line_width"]
    parts = []
    for seg in model.lines.values():
        if seg.plane != "ground":
            continue
        d = (seg.end - seg.start)[:2] / seg.length
        # extend by half a line width so corners close like painted corners do
        pts = np.stack([seg.start[:2] - d * w / 2, seg.end[:2] + d * w / 2])
        parts.append(_ribbon(pts, w, -lift))
    for arc in model.circles.values():
        n = max(8, int(math.radians(arc.end_deg - arc.start_deg) * arc.radius / 0.25))
        ang = np.linspace(math.radians(arc.start_deg), math.radians(arc.end_deg), n)
        parts.append(_ribbon(arc.point_at(ang), w, -lift))
    dims = model.dimensions
    spots = [(0.0, 0.0), (-dims["pitch_length"] / 2 + dims["penalty_mark_distance"], 0.0),
             (dims["pitch_length"] / 2 - dims["penalty_mark_distance"], 0.0)]
    for x, y in spots:
        disc = trimesh.creation.cylinder(radius=0.11, height=0.001, sections=16)
        disc.apply_translation([x, y, -lift])
        parts.append(disc)
    return _concatenate(parts)


def goals_mesh(model: FieldModel | None = None, post_radius: float = 0.06) -> trimesh.Trimesh:
    """Posts and crossbars of both goals as white cylinders (the model lines are their axes)."""
    model = model or load_field_model()
    parts = [_cylinder_between(seg.start, seg.end, post_radius)
             for seg in model.lines.values() if seg.plane.startswith("goal")]
    return _concatenate(parts)


def nets_mesh(model: FieldModel | None = None) -> trimesh.Trimesh:
    """The net boxes behind both goals: back, roof and side panels (open to the pitch)."""
    model = model or load_field_model()
    dims = model.dimensions
    hl, gw, gh, depth = dims["pitch_length"] / 2, dims["goal_width"] / 2, dims["goal_height"], dims["goal_depth"]
    parts = []
    for sign in (-1.0, 1.0):
        x0, x1 = sign * hl, sign * (hl + depth)
        quads = [
            [(x1, -gw, 0), (x1, gw, 0), (x1, gw, -gh), (x1, -gw, -gh)],  # back
            [(x0, -gw, -gh), (x0, gw, -gh), (x1, gw, -gh), (x1, -gw, -gh)],  # roof
            [(x0, -gw, 0), (x1, -gw, 0), (x1, -gw, -gh), (x0, -gw, -gh)],  # side
            [(x0, gw, 0), (x1, gw, 0), (x1, gw, -gh), (x0, gw, -gh)],  # side
        ]
        for q in quads:
            parts.append(trimesh.Trimesh(np.array(q, float), [[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]], process=False))
    return _concatenate(parts)


def grass_mesh(model: FieldModel | None = None, margin: float = 5.0) -> trimesh.Trimesh:
    """A flat rectangle under the pitch, ``margin`` metres beyond the lines."""
    model = model or load_field_model()
    hl = model.dimensions["pitch_length"] / 2 + margin
    hw = model.dimensions["pitch_width"] / 2 + margin
    v = np.array([(-hl, -hw, 0), (hl, -hw, 0), (hl, hw, 0), (-hl, hw, 0)], float)
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]], process=False)
