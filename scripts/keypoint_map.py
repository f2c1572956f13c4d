"""Draw the keypoint map (docs/keypoint_map.png): PnLCalib's 73 keypoint ids on a top view of the
pitch, coloured by set, from the pitch model (`pnlviz.viz.keypoint_map`); and print the id -> name
table docs/formats.md shows under it.

    python scripts/keypoint_map.py [--out docs/keypoint_map.png] [--table]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2

from pnlviz.field import load_field_model
from pnlviz.viz import keypoint_map

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "keypoint_map.png")
    ap.add_argument("--table", action="store_true", help="print docs/formats.md's id -> name table (markdown)")
    args = ap.parse_args()
    model = load_field_model()
    image = keypoint_map(model)
    if not cv2.imwrite(str(args.out), image, [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        raise SystemExit(f"cannot write {args.out}")
    print(f"wrote {args.out} ({image.shape[1]}x{image.shape[0]})")
    if args.table:
        print("| id | set | name |\n|---|---|---|")
        for kid, name in model.keypoint_names().items():
            print(f"| {kid} | {model.keypoints[kid].group} | {name} |")


if __name__ == "__main__":
    main()
