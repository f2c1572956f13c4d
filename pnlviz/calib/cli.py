"""``pnlviz calibrate``: a camera for every frame of a dataset, from its annotations or from
PnLCalib-format detections, written as a flat zip of SoccerNet camera JSON at 960x540 that the
official evaluator accepts."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

EVAL_SIZE = (960, 540)


def add_calibrate_parser(sub) -> None:
    from pnlviz.cli import parse_size

    p = sub.add_parser("calibrate", help="calibrate every frame (from annotations or PnLCalib detections)",
                       description="Calibrate every frame of a dataset and write camera_<stem>.json files "
                                   "(960x540, SoccerNet format) into a flat zip. Without --detections the "
                                   "cameras come from the frames' line annotations.")
    p.add_argument("--data", required=True, type=Path, help="dataset folder or zip")
    p.add_argument("--detections", type=Path, help="PnLCalib 2D prediction zip (default: use the annotations); "
                                                   "the calibration settings recorded beside it by pnlviz detect "
                                                   "(preds.json) apply")
    p.add_argument("--out", required=True, type=Path, help="output camera zip")
    p.add_argument("--no-pnl", action="store_true", help="skip the PnL refinement (and the focal/k1 refinement)")
    p.add_argument("--alpha", type=float, default=0.6, help="PnL weight of lines vs points (default 0.6)")
    p.add_argument("--no-k1", action="store_true", help="do not refine radial distortion k1")
    p.add_argument("--size", type=parse_size, default=EVAL_SIZE,
                   help="image size for frames without an image (default 960x540)")
    p.add_argument("--workers", type=int, default=1, help="worker processes (0: all cores)")
    p.add_argument("--report", type=Path, help="also write one JSON line per frame with the evidence")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=run_calibrate)


def frame_params(args, detection_settings: dict | None = None):
    """The calibration settings: the defaults, then the settings recorded with the detections
    (``detection_settings``, from ``preds.json``), then the command-line flags."""
    from pnlviz.calib.calibrate import CalibParams

    params = CalibParams(alpha=args.alpha).updated(detection_settings)
    if args.no_k1:
        params = replace(params, refine_k1=False)
    if args.no_pnl:
        params = replace(params, pnl=False, refine_focal=False, refine_k1=False)
    return params


def calibrate_frame(ds, stem: str, prediction, size, params) -> tuple[str, dict | None, dict]:
    """One frame: (stem, camera dict at 960x540 or None, report). Never raises on bad input."""
    from pnlviz.calib.calibrate import calibrate
    from pnlviz.calib.inputs import observations_from_annotation, observations_from_predictions
    from pnlviz.data import DataError

    t0 = time.perf_counter()
    report: dict = {"stem": stem}
    try:
        W, H = ds.image_size(stem) or size
        if prediction is not None:
            obs = observations_from_predictions(prediction, W, H)
        else:
            ann = ds.annotation(stem)
            if ann is None:
                report["failure"] = "no annotation"
                return stem, None, report
            obs, _ = observations_from_annotation(ann, W, H)
    except DataError as exc:
        report["failure"] = f"skipped: {exc}"
        return stem, None, report
    try:
        result = calibrate(obs, params)
    except Exception as exc:  # a bug must not end a 23k-frame batch: report the frame and go on
        report["failure"] = f"internal error: {type(exc).__name__}: {exc}"
        return stem, None, report
    report.update({
        "ms": round(1e3 * (time.perf_counter() - t0), 2), "keypoints": int(obs.n_keypoints),
        "subset": result.subset, "threshold": result.threshold, "plane": result.plane,
        "inliers": [int(i) for i in result.inliers], "pnl_lines": result.pnl_lines, "failure": result.failure,
        "point_residuals": {str(k): round(v, 3) for k, v in result.point_residuals.items()},
        "line_residuals_initial": {k: round(v, 3) for k, v in result.line_residuals_initial.items()},
        "line_residuals": {k: round(v, 3) for k, v in result.line_residuals.items()},
    })
    if not result.ok:
        return stem, None, report
    return stem, result.camera.scaled(*EVAL_SIZE).to_soccernet(), report


class _Worker:
    """Picklable per-frame job for process pools (the dataset re-opens lazily in each worker)."""

    def __init__(self, ds, predictions, size, params):
        self.ds, self.predictions, self.size, self.params = ds, predictions, size, params

    def __call__(self, stem):
        pred = None if self.predictions is None else self.predictions.get(stem)
        if self.predictions is not None and pred is None:
            return stem, None, {"stem": stem, "failure": "no detections for this frame"}
        return calibrate_frame(self.ds, stem, pred, self.size, self.params)


def run_calibrate(args) -> int:
    from tqdm import tqdm

    from pnlviz.data import (DataError, open_dataset, predictions_info_path, read_predictions, read_predictions_info,
                             sort_stems, write_camera_zip)

    ds = open_dataset(args.data)
    predictions = read_predictions(args.detections) if args.detections else None
    if predictions is None:
        stems = [s for s in ds.stems if ds.frame(s).has_annotation]
    else:  # the frames with detections; those unknown to the dataset use --size
        known = set(ds.stems)
        stems = [s for s in ds.stems if s in predictions] + [s for s in sort_stems(predictions) if s not in known]
    if not stems:
        print(f"{args.data}: no frame to calibrate", file=sys.stderr)
        return 1
    try:  # the detector's settings, recorded beside its prediction zip by pnlviz detect
        settings = (read_predictions_info(args.detections).get("calibration") or {}) if args.detections else {}
        params = frame_params(args, settings)
    except (DataError, ValueError) as exc:
        print(f"error: {predictions_info_path(args.detections)}: {exc}", file=sys.stderr)
        return 2
    if settings:
        print(f"calibration settings of the detector ({predictions_info_path(args.detections).name}): "
              + ", ".join(f"{k}={v}" for k, v in settings.items()))
    job = _Worker(ds, predictions, args.size, params)
    workers = (os.cpu_count() or 1) if args.workers == 0 else max(1, args.workers)
    cameras, reports = {}, []
    t0 = time.perf_counter()
    bar = tqdm(total=len(stems), desc="calibrate", unit="frame", disable=args.no_progress or None)
    if workers == 1:
        results = map(job, stems)
    else:
        import multiprocessing as mp

        pool = mp.get_context("spawn").Pool(workers)
        results = pool.imap_unordered(job, stems, chunksize=8)
    for stem, cam, report in results:
        if cam is not None:
            cameras[stem] = cam
        reports.append(report)
        bar.update()
    bar.close()
    if workers > 1:
        pool.close()
        pool.join()
    elapsed = time.perf_counter() - t0
    write_camera_zip(args.out, cameras)
    if args.report:
        from pnlviz.data import atomic_write_text

        order = {s: i for i, s in enumerate(stems)}
        reports.sort(key=lambda r: order[r["stem"]])
        atomic_write_text(args.report, "".join(json.dumps(r) + "\n" for r in reports))
    failures = Counter((r.get("failure") or "").split(" (")[0] for r in reports if r["stem"] not in cameras)
    print(f"calibrated {len(cameras)}/{len(stems)} frames in {elapsed:.1f} s "
          f"({1e3 * elapsed / len(stems):.1f} ms/frame with {workers} worker(s)) -> {args.out}")
    for reason, n in failures.most_common():
        print(f"  {n:5d} not calibrated: {reason}")
    skipped = [r for r in reports if str(r.get("failure", "")).startswith("skipped")]
    for r in skipped:
        print(f"  {r['failure']}", file=sys.stderr)
    return 0
