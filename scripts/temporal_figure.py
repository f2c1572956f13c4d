"""The figure of temporal calibration in docs/video.md on a real TS-WorldCup clip (no images in the data:
the frames are drawn on a dark canvas at 960x540 with the published PnLCalib detections).

    python scripts/temporal_figure.py [--clip left-2014_Match_Highlights6_clip_00013-1] [--out docs/temporal_real.jpg]

Top: four frames across the clip: detected keypoints (dots), the pitch through the per-frame
camera (red) and through the clip's temporal camera (yellow). Bottom: the jitter of every frame
(:mod:`pnlviz.metrics.temporal`), per frame (red) and temporal (yellow).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from pnlviz.calib.frame import FrameInputs, FrameSettings
from pnlviz.calib.temporal import calibrate_clip_frames
from pnlviz.data import read_predictions
from pnlviz.data.layout import clips
from pnlviz.field import load_field_model
from pnlviz.metrics.temporal import jitter
from pnlviz.viz import caption, contact_sheet, draw_pitch

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    ap.add_argument("--clip", default="left-2014_Match_Highlights6_clip_00013-1")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "temporal_real.jpg")
    args = ap.parse_args()
    preds = read_predictions(args.shared / "data" / "tswc_clips" / "detections_pnlcalib.zip")
    members = clips(preds)[args.clip]
    model = load_field_model()
    size = (1280, 720)
    inputs = [FrameInputs(size, detections=preds[s]) for s in members]
    fit = calibrate_clip_frames(inputs, FrameSettings(), model=model)  # as pnlviz calibrate --temporal
    per, temporal = fit.per_frame, fit.result.cameras
    W, H = 960, 540
    tiles = []
    for t in np.linspace(0, len(members) - 1, 4).astype(int):
        img = np.full((H, W, 3), 38, np.uint8)
        if per[t] is not None:
            draw_pitch(img, per[t], colour=(60, 60, 230), thickness=2)
        if temporal[t] is not None:
            draw_pitch(img, temporal[t], colour=(80, 230, 255), thickness=1)
        for x, y, _ in preds[members[t]].keypoints_px(W, H).values():
            cv2.circle(img, (int(x), int(y)), 5, (255, 255, 255), -1, cv2.LINE_AA)
        tiles.append(caption(img, f"frame {t + 1}: detections (white), per-frame pitch (red), temporal (yellow)"))
    # the jitter of every frame (the acceleration of the projected pitch, px at 960x540)
    jp_t, jt_t = jitter(per), jitter(temporal)
    T = len(members)
    plot_w, plot_h = 2 * W + 4, 300
    plot = np.full((plot_h, plot_w, 3), 30, np.uint8)
    top = max(float(np.nanmax(jp_t)), 1.0)
    for px in range(0, int(top) + 1):  # a gridline per pixel of jitter
        y = int(plot_h - 20 - (plot_h - 40) * px / top)
        cv2.line(plot, (20, y), (plot_w - 20, y), (70, 70, 70), 1)
        cv2.putText(plot, f"{px} px", (plot_w - 70, y - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (150, 150, 150), 1, cv2.LINE_AA)
    for series, colour in ((jp_t, (60, 60, 230)), (jt_t, (80, 230, 255))):
        poly = [(int(20 + (plot_w - 40) * t / (T - 1)), int(plot_h - 20 - (plot_h - 40) * v / top))
                for t, v in enumerate(series) if np.isfinite(v)]
        cv2.polylines(plot, [np.array(poly, np.int32)], False, colour, 2, cv2.LINE_AA)
    jp, jt = np.nanmedian(jp_t), np.nanmedian(jt_t)
    label = (f"jitter of each of the {T} frames (px at 960x540): per frame (red, median {jp:.2f} px), "
             f"temporal (yellow, median {jt:.2f} px)")
    sheet = contact_sheet(tiles, columns=2, tile_width=W)
    plot = caption(plot, label)
    plot = cv2.resize(plot, (sheet.shape[1], int(plot.shape[0] * sheet.shape[1] / plot.shape[1])))
    out = np.vstack([sheet, plot])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out), cv2.resize(out, (out.shape[1] * 2 // 3, out.shape[0] * 2 // 3),
                                          interpolation=cv2.INTER_AREA), [cv2.IMWRITE_JPEG_QUALITY, 85])
    print(f"wrote {args.out} ({args.clip}: {T} frames, jitter per frame {jp:.2f} px, temporal {jt:.2f} px)")


if __name__ == "__main__":
    main()
