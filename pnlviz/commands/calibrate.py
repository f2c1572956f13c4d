"""``pnlviz calibrate``: a camera for every frame of a dataset, from its annotations or from
PnLCalib-format detections, written as a flat zip of SoccerNet camera JSON at 960x540 that the
official evaluator accepts."""

from __future__ import annotations

import json
import os
import sys
import time
from collections import Counter
from pathlib import Path

from pnlviz.conventions import DEFAULT_ALPHA, EVAL_SIZE

#: how the summary names each failure code
FAILURE_LABELS = {"too_few_keypoints": "too few keypoints", "degenerate": "degenerate geometry",
                  "no_inliers": "no keypoint agrees with the camera", "residual": "residual above the limit",
                  "no_input": "nothing to calibrate from", "internal": "internal error",
                  "bad_input": "unreadable input", "bad_output": "not written"}


def add_calibrate_parser(sub) -> None:
    from pnlviz.commands.common import parse_size

    p = sub.add_parser("calibrate", help="calibrate every frame (from annotations or PnLCalib detections)",
                       description="Calibrate every frame of a dataset and write camera_<stem>.json files "
                                   "(960x540, SoccerNet format) into a flat zip. Without --detections the "
                                   "cameras come from the frames' line annotations.")
    p.add_argument("--data", type=Path, help="dataset folder or zip (may be left out with --detections: every "
                                             "frame of the prediction zip is then calibrated at --size)")
    p.add_argument("--video", type=Path, help="the video the --detections were made on (pnlviz detect --video): "
                                              "its frame size, and its images to find cuts with --temporal")
    p.add_argument("--detections", type=Path, help="PnLCalib 2D prediction zip (default: use the annotations); "
                                                   "the calibration settings recorded beside it by pnlviz detect "
                                                   "(preds.json) apply")
    p.add_argument("--out", required=True, type=Path, help="output camera zip")
    p.add_argument("--no-pnl", action="store_true", help="skip the PnL refinement (and the focal/k1 refinement)")
    p.add_argument("--alpha", type=float, default=DEFAULT_ALPHA,
                   help=f"PnL weight of lines vs points (default {DEFAULT_ALPHA})")
    p.add_argument("--no-k1", action="store_true", help="do not refine radial distortion k1")
    p.add_argument("--size", type=parse_size, default=EVAL_SIZE,
                   help="image size for frames without an image, and for every frame without --data: the pixel "
                        "size the detections were made at (default 960x540; the cameras are written at 960x540)")
    p.add_argument("--temporal", action="store_true",
                   help="video: group the frames into clips by their stems (<clip>-IMG_<n>, <clip>_frame<n>, ...), "
                        "cut clips into shots and fit one broadcast camera per shot (fixed centre and k1, smooth "
                        "pan/tilt/roll/zoom); frames with too few keypoints get their camera from the shot")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run: frames already in --out (or in the progress a killed run "
                        "left beside it) are kept, only the missing ones are calibrated")
    p.add_argument("--workers", type=int, default=1, help="worker processes (0: all cores)")
    p.add_argument("--report", type=Path, help="also write one JSON line per frame with the evidence")
    from pnlviz.commands.cluster import add_cluster_args

    add_cluster_args(p)
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=run_calibrate)


def frame_settings(args, detection_settings: dict | None = None):
    """The engine's settings: the detector's (recorded beside its detections in ``preds.json``)
    for frames calibrated from detections, then the command-line flags."""
    from pnlviz.calib.frame import FrameSettings

    return FrameSettings(pnl=not args.no_pnl, alpha=args.alpha, source="annotation",
                         detection_settings=dict(detection_settings or {}),
                         overrides={"refine_k1": False} if args.no_k1 else {})


def calibrate_stem(ds, stem: str, prediction, size, settings) -> tuple[str, dict | None, dict]:
    """One frame: read its inputs, run the engine's one path (:func:`pnlviz.calib.frame.calibrate_frame`):
    (stem, camera dict at 960x540 or None, report). Never raises on bad input."""
    from pnlviz.calib.frame import calibrate_frame

    report: dict = {"stem": stem}
    inputs, problem = read_frame_inputs(ds, stem, prediction, size)
    if inputs is None:
        report.update(problem)
        return stem, None, report
    fc = calibrate_frame(inputs, settings)
    if fc.failure is not None:
        report.update(failure=fc.failure.message, failure_code=fc.failure.code)
    if fc.result is None:
        return stem, None, report
    res = fc.result
    report.update({
        "ms": round(fc.ms, 2), "keypoints": int(fc.observations.n_keypoints), "origin": fc.origin,
        "subset": res.subset, "threshold": res.threshold, "plane": res.plane,
        "inliers": [int(i) for i in res.inliers], "pnl_lines": res.pnl_lines,
        "point_residuals": {str(k): round(v, 3) for k, v in res.point_residuals.items()},
        "line_residuals_initial": {k: round(v, 3) for k, v in res.line_residuals_initial.items()},
        "line_residuals": {k: round(v, 3) for k, v in res.line_residuals.items()},
    })
    if not res.ok:
        return stem, None, report
    return stem, res.camera.scaled(*EVAL_SIZE).to_soccernet(), report


def read_frame_inputs(ds, stem: str, prediction, size) -> tuple[object | None, dict | None]:
    """The :class:`pnlviz.calib.frame.FrameInputs` of one frame (its image's size, else ``size``;
    its annotation unless it has detections), or None with the report's failure fields."""
    from pnlviz.calib.frame import FrameInputs
    from pnlviz.data import DataError

    try:
        size = ds.image_size(stem) or size if stem in ds else size
        ann = ds.annotation(stem) if prediction is None and stem in ds else None
    except DataError as exc:
        return None, {"failure": f"skipped: {exc}", "failure_code": "bad_input"}
    if prediction is None and ann is None:
        return None, {"failure": "no annotation", "failure_code": "no_input"}
    return FrameInputs(size, ann, prediction), None


def temporal_pass(ds, predictions, size, settings, stems: list[str], results: dict, progress: bool = True) -> dict:
    """``--temporal``: per clip (:func:`pnlviz.data.layout.clips`), the per-frame cameras in
    ``results`` (``{stem: (camera dict at 960x540 | None, report)}``) replaced by the broadcast
    model of their shot (:func:`pnlviz.calib.temporal.calibrate_clip`); reports gain the clip, the
    shot and the residuals. Image changes between consecutive frames mark cuts when the frames
    have images."""
    import numpy as np
    from tqdm import tqdm

    from pnlviz.calib.temporal import calibrate_clip_frames, image_changes
    from pnlviz.data import DataError
    from pnlviz.data.layout import clips
    from pnlviz.field import load_field_model
    from pnlviz.geometry.camera import Camera

    def image_or_none(stem):
        try:
            return ds.image(stem)
        except DataError:
            return None

    model = load_field_model()
    out = dict(results)
    groups = clips(stems)
    bar = tqdm(total=len(stems), desc="temporal", unit="frame", disable=not progress or None)
    for clip, members in groups.items():
        inputs = [read_frame_inputs(ds, s, None if predictions is None else predictions.get(s), size)[0]
                  for s in members]
        sizes = {tuple(i.size) for i in inputs if i is not None}
        if len(sizes) != 1:  # nothing to fit, or frames of different sizes: left per-frame
            bar.update(len(members))
            continue
        W, H = sizes.pop()
        cams = []
        for s in members:
            d = results.get(s, (None, {}))[0]
            cams.append(Camera.from_soccernet(d, *EVAL_SIZE).scaled(W, H) if d is not None else None)
        changes = None
        if all(s in ds and ds.frame(s).has_image for s in members):
            changes = image_changes(image_or_none(s) for s in members)  # two frames in memory at a time
        res = calibrate_clip_frames(inputs, settings, cameras=cams, changes=changes, model=model).result
        for t, s in enumerate(members):
            cam_dict, report = results.get(s, (None, {"stem": s}))
            report = dict(report)
            fit = res.fits[res.shot_of[t]]
            report["temporal"] = {"clip": clip, "shot": res.shot_of[t], "shots": len(res.shots),
                                  "per_frame": cam_dict is not None}
            if res.cameras[t] is not None and fit is not None:
                i = t - res.shots[res.shot_of[t]].start
                r = fit.residuals[i]
                report["temporal"].update(residual_median=round(float(np.median(r)), 3) if len(r) else None,
                                          dropped=fit.dropped[i])
                report.pop("failure", None)
                report.pop("failure_code", None)
                out[s] = (res.cameras[t].scaled(*EVAL_SIZE).to_soccernet(), report)
            else:
                out[s] = (cam_dict, report)
        bar.update(len(members))
    bar.close()
    return out


class _NoDataset:
    """What ``--detections`` alone calibrates against: no frame known (no image sizes, no
    annotations), so every frame of the prediction zip is calibrated at ``--size``."""

    stems: list[str] = []

    def __contains__(self, stem) -> bool:
        return False


class _Worker:
    """Picklable per-frame job for process pools (the dataset re-opens lazily in each worker)."""

    def __init__(self, ds, predictions, size, settings):
        self.ds, self.predictions, self.size, self.settings = ds, predictions, size, settings

    def __call__(self, stem):
        pred = None if self.predictions is None else self.predictions.get(stem)
        if self.predictions is not None and pred is None:
            return stem, None, {"stem": stem, "failure": "no detections for this frame", "failure_code": "no_input"}
        return calibrate_stem(self.ds, stem, pred, self.size, self.settings)


def _calibrate_chunk(job: "_Worker", stems: list[str]) -> list:
    """One cluster task: the frames ``stems`` (the worker opens the dataset where it is)."""
    return [job(stem) for stem in stems]


def _failed_on_cluster(stem: str, message: str) -> tuple:
    return stem, None, {"stem": stem, "failure": message, "failure_code": "internal"}


def _ignore_sigint() -> None:
    """Pool workers leave Ctrl+C to the main process, which keeps what was computed."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _check_outputs(args) -> None:
    """--out and --report: not over an input (nor over each other), not inside the dataset."""
    from pnlviz.data import check_output, predictions_info_path

    inputs = [args.detections, predictions_info_path(args.detections)] if args.detections else []
    inputs += [args.video] if getattr(args, "video", None) is not None else []
    datasets = [args.data] if args.data is not None else []
    check_output(args.out, inputs=inputs, datasets=datasets)
    if args.report:
        check_output(args.report, inputs=[*inputs, args.out], datasets=datasets, what="--report")


def _frames(ds, predictions) -> list[str]:
    """The frames to calibrate: annotated frames, or those with detections (unknown ones use --size)."""
    from pnlviz.data import sort_stems

    if predictions is None:
        return [s for s in ds.stems if ds.frame(s).has_annotation]
    known = set(ds.stems)
    return [s for s in ds.stems if s in predictions] + [s for s in sort_stems(predictions) if s not in known]


def _detection_settings(args):
    """(settings recorded beside the detections, the engine's settings); DataError/ValueError
    (an unknown setting) for a bad file."""
    from pnlviz.calib.calibrate import CalibParams
    from pnlviz.data import read_predictions_info

    recorded = (read_predictions_info(args.detections).get("calibration") or {}) if args.detections else {}
    CalibParams().updated(recorded)  # unknown names fail here, not on every frame
    return recorded, frame_settings(args, recorded)


def run_calibrate(args) -> int:
    import contextlib

    from tqdm import tqdm

    from pnlviz.commands.common import open_input_dataset, previous_run, print_skipped
    from pnlviz.data import DataError, LineStream, ZipStream, predictions_info_path, read_predictions
    from pnlviz.data.cameras import camera_member, camera_zip_order

    if args.data is None and args.detections is None:
        print("error: give --data (a dataset), --detections (a prediction zip), or both", file=sys.stderr)
        return 2
    if args.video is not None and (args.data is not None or args.detections is None):
        print("error: --video goes with --detections (made by pnlviz detect --video), instead of --data",
              file=sys.stderr)
        return 2
    _check_outputs(args)
    if args.video is not None:
        from pnlviz.data.video import VideoDataset

        ds = VideoDataset(args.video)
    else:
        ds = open_input_dataset(args.data) if args.data is not None else _NoDataset()
    predictions = read_predictions(args.detections, on_error=lambda e: print_skipped([e])) if args.detections else None
    stems = _frames(ds, predictions)
    if not stems:
        print(f"{args.data or args.detections}: no frame to calibrate", file=sys.stderr)
        return 1
    if args.video is not None:
        print(f"{len(stems)} frames of {args.detections.name}, video {args.video.name} at {ds.width}x{ds.height}")
    elif args.data is None:
        print(f"{len(stems)} frames of {args.detections.name}, calibrated at {args.size[0]}x{args.size[1]} (--size)")
    try:  # the detector's settings, recorded beside its prediction zip by pnlviz detect
        recorded, settings = _detection_settings(args)
    except (DataError, ValueError) as exc:
        print(f"error: {predictions_info_path(args.detections)}: {exc}", file=sys.stderr)
        return 2
    if recorded:
        print(f"calibration settings of the detector ({predictions_info_path(args.detections).name}): "
              + ", ".join(f"{k}={v}" for k, v in recorded.items()))
    if args.resume and args.temporal:
        print("error: --resume does not go with --temporal (a shot is fitted from all its frames at once)",
              file=sys.stderr)
        return 2
    done = previous_run(args.out, args.resume)
    kept = {f"camera_{s}.json": done[f"camera_{s}.json"] for s in stems if f"camera_{s}.json" in done}
    todo = [s for s in stems if f"camera_{s}.json" not in kept]
    if args.resume:
        print(f"resuming: {len(kept)} of {len(stems)} frames already in {args.out.name}, {len(todo)} to calibrate")
    job = _Worker(ds, predictions, args.size, settings)
    workers = (os.cpu_count() or 1) if args.workers == 0 else max(1, args.workers)
    order = {s: i for i, s in enumerate(stems)}
    failures: list[tuple[str, str]] = []  # (code, message) of the frames without a camera
    interrupted = False
    t0 = time.perf_counter()
    bar = tqdm(total=len(todo), desc="calibrate", unit="frame", disable=args.no_progress or None)
    with contextlib.ExitStack() as stack:
        cams = stack.enter_context(ZipStream(args.out, key=camera_zip_order, journal=True))
        for name, text in kept.items():  # what the interrupted run finished
            cams.add(name, text)
        reports = stack.enter_context(LineStream(args.report)) if args.report else None
        pool = None
        from pnlviz.commands.cluster import cluster_client, map_on_cluster

        client = stack.enter_context(cluster_client(args))
        if client is not None:
            workers = len(client.scheduler_info().get("workers", {}))
            results = map_on_cluster(client, _calibrate_chunk, job, todo, args.chunk, _failed_on_cluster)
        elif workers == 1:
            results = map(job, todo)
        else:
            import multiprocessing as mp

            pool = stack.enter_context(mp.get_context("spawn").Pool(workers, initializer=_ignore_sigint))
            results = pool.imap_unordered(job, todo, chunksize=8)
        try:
            if args.temporal:  # every frame first, then the clips' shots, then written
                per_frame = {}
                for stem, cam, report in results:
                    per_frame[stem] = (cam, report)
                    bar.update()
                bar.close()
                fitted = temporal_pass(ds, predictions, args.size, settings, stems, per_frame,
                                       progress=not args.no_progress)
                results = ((s, *fitted[s]) for s in stems)
                bar = tqdm(total=len(stems), desc="write", unit="frame", disable=args.no_progress or None)
            for stem, cam, report in results:
                if cam is not None:
                    try:  # written at once: an interrupted or failing batch keeps it
                        cams.add(*camera_member(stem, cam, args.out))
                    except DataError as exc:
                        cam = None
                        report.update(failure=f"skipped: not written: {exc}", failure_code="bad_output")
                if cam is None:
                    failures.append((report.get("failure_code") or "failed", report.get("failure") or ""))
                if reports is not None:
                    reports.add(json.dumps(report), key=order[stem])
                bar.update()
        except KeyboardInterrupt:
            interrupted = True
        bar.close()
    elapsed = time.perf_counter() - t0
    if interrupted:
        print(f"interrupted: kept {len(cams)} of {len(stems)} frames in {args.out}", file=sys.stderr)
        return 130
    print(f"calibrated {len(cams)}/{len(stems)} frames in {elapsed:.1f} s "
          f"({1e3 * elapsed / max(1, len(todo)):.1f} ms/frame with {workers} worker(s)"
          + (" on the dask cluster" if args.dask is not None or args.scheduler is not None else "") + f") -> {args.out}")
    for code, n in Counter(code for code, _ in failures).most_common():
        example = next(message for c, message in failures if c == code)
        print(f"  {n:5d} not calibrated: {FAILURE_LABELS.get(code, code)}" + (f" (e.g. {example})" if n > 1 else f" ({example})"))
    print_skipped([m for c, m in failures if c in ("bad_input", "bad_output")], prefix="  ")
    if not len(cams):
        print(f"error: no frame calibrated: {args.out} holds no camera", file=sys.stderr)
        return 1
    return 0
