"""WC14 homography metrics from the published PnLCalib detections: homography-only calibration
(:mod:`pnlviz.calib.homography`) with and without PnL, and the full camera pipeline
(:func:`pnlviz.calib.calibrate.calibrate`) converted to a homography, with and without PnL (both
the frame pipeline of :mod:`pnlviz.calib.pipeline`, the homography its ground-plane case).

    python benchmarks/wc14_homography.py [--data ../shared/data/wc14_test_half] [--one-thread]

Frames are 1280 x 720; detections are normalised (x_px = x * W). Every prediction is a WC14
homography (template yards -> pixels at 1280 x 720): the field -> image homography composed with
``template_to_field_matrix``; the camera pipeline's cameras through ``homography_from_camera``
(lens distortion, if the final refinement fitted k1, is ignored: a homography has none).
Metrics: :mod:`pnlviz.metrics.homography` (IoU part / whole, projection error in metres,
reprojection error / image height), mean and median over the frames where they are defined;
frames with no calibration and per-metric failures are counted separately. ms/frame is the
calibration alone (observations built beforehand), one process.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from pnlviz.calib.calibrate import CalibParams, calibrate
from pnlviz.calib.homography import HomographyParams, estimate_homography
from pnlviz.calib.inputs import observations_from_predictions
from pnlviz.data import read_homographies, read_predictions
from pnlviz.field import load_field_model
from pnlviz.metrics.homography import METRICS, evaluate_homographies, homography_from_camera

W, H = 1280, 720
DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "wc14_test_half"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--one-thread", action="store_true", help="cv2.setNumThreads(1)")
    args = ap.parse_args(argv)
    if args.one_thread:
        import cv2

        cv2.setNumThreads(1)
    if not (args.data / "detections_pnlcalib.zip").is_file():
        print(f"no WC14 data at {args.data}", file=sys.stderr)
        return 2
    model = load_field_model()
    T = model.template_to_field_matrix
    preds = read_predictions(args.data / "detections_pnlcalib.zip")
    gt = read_homographies(args.data / "homographies.json")
    stems = [s for s in gt if s in preds]
    obs = {s: observations_from_predictions(preds[s], W, H, model=model) for s in stems}

    def homography_only(pnl: bool):
        params = HomographyParams(pnl=pnl)

        def run(o):
            r = estimate_homography(o, params, model=model)
            return None if r.H is None else r.H @ T, r.failure

        return run

    def camera(params: CalibParams):
        def run(o):
            r = calibrate(o, params, model)
            return None if r.camera is None else homography_from_camera(r.camera, model), r.failure

        return run

    methods = {
        "homography only": homography_only(False),
        "homography only + PnL": homography_only(True),
        "camera pipeline": camera(CalibParams(pnl=False, refine_focal=False, refine_k1=False)),
        "camera pipeline + PnL (default)": camera(CalibParams()),
    }
    estimate_homography(obs[stems[0]], model=model)  # warm-up (imports, caches)
    calibrate(obs[stems[0]], CalibParams(), model)
    rows = []
    for name, run in methods.items():
        pred, fails, times = {}, {}, []
        for s in stems:
            t0 = time.perf_counter()
            Hp, why = run(obs[s])
            times.append(time.perf_counter() - t0)
            if Hp is None:
                fails[s] = why
            else:
                pred[s] = Hp
        summ = evaluate_homographies(gt, pred, stems=stems)
        rows.append((name, summ, 1000 * np.mean(times), 1000 * np.median(times), fails))

    print(f"WC14 test half: {len(stems)} frames {W}x{H}, published PnLCalib detections")
    head = (f"{'method':<33}{'IoU part':>17}{'IoU whole':>17}{'proj. (m)':>15}{'reproj. (/H)':>17}"
            f"{'no calib':>9}{'failed':>8}{'ms/frame':>15}")
    sub = f"{'':<33}" + f"{'mean':>9}{'median':>8}" * 2 + f"{'mean':>7}{'median':>8}{'mean':>9}{'median':>8}" \
          + f"{'':>9}{'':>8}{'mean':>7}{'median':>8}"
    print(head)
    print(sub)
    for name, s, t_mean, t_med, fails in rows:
        vals = "".join(f"{100 * s.mean(m):9.2f}{100 * s.median(m):8.2f}" for m in METRICS[:2])
        vals += f"{s.mean('proj_error_m'):7.3f}{s.median('proj_error_m'):8.3f}"
        vals += f"{s.mean('reproj_error'):9.4f}{s.median('reproj_error'):8.4f}"
        nfail = max(s.n_failed(m) for m in METRICS)
        print(f"{name:<33}{vals}{s.n_missing:9d}{nfail:8d}{t_mean:7.1f}{t_med:8.1f}")
    print("IoU in %; 'no calib' = frames the method could not calibrate; 'failed' = most frames on which "
          "a metric was undefined")
    for name, _, _, _, fails in rows:
        for s, why in fails.items():
            print(f"  {name}: frame {s}: {why}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
