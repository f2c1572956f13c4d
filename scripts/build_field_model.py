"""Build ``assets/field_model/soccer_pitch.json`` from the rules of the game.

Run from the repository root::

    python scripts/build_field_model.py [--reference ../shared/reference/pnlcalib_keypoints.json]

Everything is derived from the IFAB dimensions used by the SoccerNet evaluator (its ``SoccerPitch``
constants). The keypoint catalogue takes its ids, groups and definitions from PnLCalib's published
table (``pnlcalib_keypoints.json``, facts only); coordinates are recomputed here from the geometry so
that every keypoint lies exactly on the lines or circles that define it. Where PnLCalib's own
table differs from the true geometry beyond rounding, its value is kept as ``pnlcalib_xyz`` (id 52:
PnLCalib's networks were trained on x = 9.0 instead of 9.15).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "assets" / "field_model" / "soccer_pitch.json"

# --- dimensions (metres), as in the SoccerNet evaluator -------------------------------------------
L, W = 105.0, 68.0
PEN_LEN, PEN_WID = 16.5, 40.32
GA_LEN, GA_WID = 5.5, 18.32
PEN_MARK = 11.0
R = 9.15
GOAL_W, GOAL_H = 7.32, 2.44
GOAL_DEPTH = 2.0  # depth of the net box behind the goal line (3D view only; not in SoccerNet)
LINE_WIDTH = 0.12
hl, hw = L / 2, W / 2


def p(x, y, z=0.0):
    return [round(float(x), 10), round(float(y), 10), round(float(z), 10)]


# Straight classes with start -> end in the SoccerNet evaluator's order (its polylines are sampled
# from start to end, so keep the same direction).
arc_dy = math.sqrt(R**2 - (PEN_LEN - PEN_MARK) ** 2)
LINES = {
    "Big rect. left bottom": (p(-hl, PEN_WID / 2), p(-hl + PEN_LEN, PEN_WID / 2), "ground"),
    "Big rect. left main": (p(-hl + PEN_LEN, -PEN_WID / 2), p(-hl + PEN_LEN, PEN_WID / 2), "ground"),
    "Big rect. left top": (p(-hl, -PEN_WID / 2), p(-hl + PEN_LEN, -PEN_WID / 2), "ground"),
    "Big rect. right bottom": (p(hl - PEN_LEN, PEN_WID / 2), p(hl, PEN_WID / 2), "ground"),
    "Big rect. right main": (p(hl - PEN_LEN, -PEN_WID / 2), p(hl - PEN_LEN, PEN_WID / 2), "ground"),
    "Big rect. right top": (p(hl - PEN_LEN, -PEN_WID / 2), p(hl, -PEN_WID / 2), "ground"),
    "Goal left crossbar": (p(-hl, -GOAL_W / 2, -GOAL_H), p(-hl, GOAL_W / 2, -GOAL_H), "goal_left"),
    "Goal left post left ": (p(-hl, GOAL_W / 2, -GOAL_H), p(-hl, GOAL_W / 2, 0), "goal_left"),
    "Goal left post right": (p(-hl, -GOAL_W / 2, -GOAL_H), p(-hl, -GOAL_W / 2, 0), "goal_left"),
    "Goal right crossbar": (p(hl, -GOAL_W / 2, -GOAL_H), p(hl, GOAL_W / 2, -GOAL_H), "goal_right"),
    "Goal right post left": (p(hl, -GOAL_W / 2, -GOAL_H), p(hl, -GOAL_W / 2, 0), "goal_right"),
    "Goal right post right": (p(hl, GOAL_W / 2, -GOAL_H), p(hl, GOAL_W / 2, 0), "goal_right"),
    "Middle line": (p(0, -hw), p(0, hw), "ground"),
    "Side line bottom": (p(-hl, hw), p(hl, hw), "ground"),
    "Side line left": (p(-hl, -hw), p(-hl, hw), "ground"),
    "Side line right": (p(hl, -hw), p(hl, hw), "ground"),
    "Side line top": (p(-hl, -hw), p(hl, -hw), "ground"),
    "Small rect. left bottom": (p(-hl, GA_WID / 2), p(-hl + GA_LEN, GA_WID / 2), "ground"),
    "Small rect. left main": (p(-hl + GA_LEN, -GA_WID / 2), p(-hl + GA_LEN, GA_WID / 2), "ground"),
    "Small rect. left top": (p(-hl, -GA_WID / 2), p(-hl + GA_LEN, -GA_WID / 2), "ground"),
    "Small rect. right bottom": (p(hl - GA_LEN, GA_WID / 2), p(hl, GA_WID / 2), "ground"),
    "Small rect. right main": (p(hl - GA_LEN, -GA_WID / 2), p(hl - GA_LEN, GA_WID / 2), "ground"),
    "Small rect. right top": (p(hl - GA_LEN, -GA_WID / 2), p(hl, -GA_WID / 2), "ground"),
}

# Circles: centre, radius and the arc as [start_deg, end_deg] (counter-clockwise in the x-y plane,
# angle measured from +x towards +y), matching the evaluator's sampling direction.
a_left = math.degrees(math.atan2(-arc_dy, PEN_LEN - PEN_MARK)) + 360.0  # ~306.97
a_right = math.degrees(math.atan2(arc_dy, -(PEN_LEN - PEN_MARK)))  # ~126.97
CIRCLES = {
    "Circle central": {"center": p(0, 0), "radius": R, "start_deg": 0.0, "end_deg": 360.0},
    "Circle left": {
        "center": p(-hl + PEN_MARK, 0), "radius": R,
        "start_deg": round(a_left, 10), "end_deg": round(a_left + 2 * (360.0 - a_left), 10),
    },
    "Circle right": {
        "center": p(hl - PEN_MARK, 0), "radius": R,
        "start_deg": round(a_right, 10), "end_deg": round(360.0 - a_right, 10),
    },
}


def line_line(a: str, b: str) -> np.ndarray:
    """Intersection of two (coplanar) model lines, as 3D point."""
    p1, q1, _ = LINES[a]
    p2, q2, _ = LINES[b]
    p1, q1, p2, q2 = map(np.asarray, (p1, q1, p2, q2))
    d1, d2 = q1 - p1, q2 - p2
    # least squares for p1 + s d1 = p2 + t d2
    A = np.stack([d1, -d2], axis=1)
    st, *_ = np.linalg.lstsq(A, p2 - p1, rcond=None)
    x1 = p1 + st[0] * d1
    x2 = p2 + st[1] * d2
    assert np.linalg.norm(x1 - x2) < 1e-9, (a, b)
    return x1


def line_circle(line: str, circle: str) -> list[np.ndarray]:
    p1, q1, _ = LINES[line]
    p1, q1 = np.asarray(p1)[:2], np.asarray(q1)[:2]
    c = np.asarray(CIRCLES[circle]["center"])[:2]
    d = q1 - p1
    f = p1 - c
    a, b, cc = d @ d, 2 * f @ d, f @ f - R**2
    disc = math.sqrt(b * b - 4 * a * cc)
    return [np.array([*(p1 + t * d), 0.0]) for t in ((-b - disc) / (2 * a), (-b + disc) / (2 * a))]


def tangent_points(circle: str, ext: np.ndarray) -> list[np.ndarray]:
    c = np.asarray(CIRCLES[circle]["center"])[:2]
    d = ext[:2] - c
    d2 = d @ d
    base = c + (R**2 / d2) * d
    off = R * math.sqrt(d2 - R**2) / d2 * np.array([-d[1], d[0]])
    return [np.array([*(base + off), 0.0]), np.array([*(base - off), 0.0])]


def additional_point(kid: int) -> tuple[np.ndarray, dict]:
    """Kp3: points on the long axis y = 0 and the centre circle at 45 degrees."""
    s = R / math.sqrt(2)
    table = {
        45: ((-hl + PEN_MARK, 0), ["penalty mark left"]),
        46: ((-hl + PEN_LEN, 0), ["Big rect. left main", "axis"]),
        47: ((-hl + PEN_MARK + R, 0), ["Circle left", "axis"]),
        48: ((-s, -s), ["Circle central", "diagonal"]),
        49: ((s, -s), ["Circle central", "diagonal"]),
        50: ((-R, 0), ["Circle central", "axis"]),
        51: ((0, 0), ["Middle line", "axis"]),
        52: ((R, 0), ["Circle central", "axis"]),
        53: ((-s, s), ["Circle central", "diagonal"]),
        54: ((s, s), ["Circle central", "diagonal"]),
        55: ((hl - PEN_MARK - R, 0), ["Circle right", "axis"]),
        56: ((hl - PEN_LEN, 0), ["Big rect. right main", "axis"]),
        57: ((hl - PEN_MARK, 0), ["penalty mark right"]),
    }
    (x, y), on = table[kid]
    return np.array([x, y, 0.0]), {"kind": "additional", "on": on}


# Where PnLCalib's own table (and so its published networks) put a keypoint somewhere else than the
# true geometry: id 52 sits at x = +9.0 there (61.5 in its corner frame), not at +9.15.
PNLCALIB_POSITIONS = {52: (9.0, 0.0, 0.0)}


def build(reference: Path) -> dict:
    ref = json.loads(reference.read_text())
    keypoints = []
    exact: dict[int, np.ndarray] = {}
    for k in sorted(ref["keypoints"], key=lambda k: k["id"]):
        kid, group, by = k["id"], k["group"], k["defined_by"]
        ref_xyz = np.array([k["x"], k["y"], k["z"]], dtype=float)
        if group in ("Kp", "Kpe"):
            xyz = line_line(*by["lines"])
            definition = {"kind": "line_line" if group == "Kp" else "extended_line_line",
                          "lines": list(by["lines"])}
        elif group == "Kp1":
            cands = line_circle(by["line"], by["circle"])
            xyz = min(cands, key=lambda c: np.linalg.norm(c - ref_xyz))
            definition = {"kind": "line_circle", "line": by["line"], "circle": by["circle"]}
        elif group == "Kp2":
            ext = exact[by["tangent_from_keypoint"]]
            cands = tangent_points(by["circle"], ext)
            xyz = min(cands, key=lambda c: np.linalg.norm(c - ref_xyz))
            definition = {"kind": "tangent", "circle": by["circle"],
                          "from_keypoint": by["tangent_from_keypoint"]}
        elif group == "Kp3":
            xyz, definition = additional_point(kid)
        else:
            raise ValueError(group)
        exact[kid] = xyz
        entry = {"id": kid, "group": group, "xyz": p(*xyz), "defined_by": definition}
        if kid in PNLCALIB_POSITIONS:
            entry["pnlcalib_xyz"] = p(*PNLCALIB_POSITIONS[kid])
        assert np.linalg.norm(xyz - ref_xyz) < 0.2, (kid, xyz, ref_xyz)
        keypoints.append(entry)

    return {
        "format": "pnlviz-field-model",
        "version": 1,
        "frame": ("SoccerNet world frame, metres: origin at the pitch centre, x along the length "
                  "(-52.5..52.5), y across (-34 at 'Side line top', +34 at 'Side line bottom'; the "
                  "main camera sits at y > 0), z pointing down (crossbar at z = -2.44)."),
        "dimensions": {
            "pitch_length": L, "pitch_width": W,
            "penalty_area_length": PEN_LEN, "penalty_area_width": PEN_WID,
            "goal_area_length": GA_LEN, "goal_area_width": GA_WID,
            "penalty_mark_distance": PEN_MARK, "circle_radius": R,
            "goal_width": GOAL_W, "goal_height": GOAL_H, "goal_depth": GOAL_DEPTH,
            "line_width": LINE_WIDTH,
        },
        "lines": {name: {"start": s, "end": e, "plane": plane} for name, (s, e, plane) in LINES.items()},
        "circles": CIRCLES,
        "ignored_classes": ["Goal unknown", "Line unknown"],
        "keypoints": keypoints,
        "wc14_template": {
            "length": 115.0, "width": 74.0, "unit": "yard",
            "metres_to_template": 1.09361,
            "origin_in_field": [-hl, -hw],
            "note": ("WC14 / TS-WorldCup homographies map template points to image pixels at "
                     "1280x720. A field point maps to the template by (X + 52.5, Y + 34) * 1.09361: "
                     "origin at the far-left corner, x along the length, y towards the main camera."),
            "image_size": [1280, 720],
        },
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", type=Path,
                    default=ROOT.parent / "shared" / "reference" / "pnlcalib_keypoints.json")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    model = build(args.reference)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(model, indent=1) + "\n")
    print(f"wrote {args.out} ({len(model['keypoints'])} keypoints)")


if __name__ == "__main__":
    main()
