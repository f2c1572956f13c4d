"""``pnlviz calibrate``: a camera for every frame of a dataset, from its annotations or from
PnLCalib-format detections (or both, ``--source``), with an edits folder's corrections
(``--edits``), written as a flat zip of SoccerNet camera JSON at 960x540 that the official
evaluator accepts. The frames are read as the app reads them (:class:`pnlviz.pipeline.FrameReader`)
and run through :mod:`pnlviz.commands.batch`."""

from __future__ import annotations

import contextlib
import json
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from pnlviz.commands.batch import BatchJob
from pnlviz.conventions import DEFAULT_ALPHA, EVAL_SIZE
from pnlviz.commands.common import add_output_options, float_in, workers_arg

if TYPE_CHECKING:
    from pnlviz.calib.frame import FrameInputs, FrameSettings

#: how the summary names the engine's failure codes, in the order of
#: :data:`pnlviz.calib.calibrate.FAILURE_CODES` (see :func:`failure_words`)
_ENGINE_WORDS = ("too few keypoints", "degenerate geometry", "no keypoint agrees with the camera",
                 "residual above the limit", "hand-placed points cannot calibrate")


def failure_words() -> dict[str, str]:
    """How the summary names each failure code: the engine's (:data:`pnlviz.calib.calibrate.FAILURE_CODES`,
    then :func:`pnlviz.calib.frame.calibrate_frame`'s "no_input" and "internal") and this
    command's own ("bad_input": unreadable files, "bad_output": a camera not written)."""
    from pnlviz.calib.calibrate import FAILURE_CODES

    return {**dict(zip(FAILURE_CODES, _ENGINE_WORDS)), "no_input": "nothing to calibrate from",
            "internal": "internal error", "bad_input": "unreadable input", "bad_output": "not written"}


def add_calibrate_parser(sub) -> None:
    from pnlviz.commands.common import add_detector_settings, add_force_edits, parse_size
    from pnlviz.conventions import SOURCES

    p = sub.add_parser("calibrate", help="calibrate every frame (from annotations or PnLCalib detections)",
                       description="Calibrate every frame of a dataset and write camera_<stem>.json files "
                                   "(960x540, SoccerNet format) into a flat zip. Without --detections the "
                                   "cameras come from the frames' line annotations.")
    p.add_argument("--data", type=Path, help="dataset folder or zip (may be left out with --detections: every "
                                             "frame of the prediction zip is then calibrated at --size)")
    p.add_argument("--video", type=Path, help="the video the --detections were made on (pnlviz detect --video): "
                                              "its frame size, and its images to find cuts with --temporal")
    p.add_argument("--detections", type=Path, help="PnLCalib 2D prediction zip (default: use the annotations); "
                                                   "the detector's settings file beside it (preds.json, from pnlviz "
                                                   "detect --settings) applies")
    add_detector_settings(p)
    p.add_argument("--source", choices=SOURCES, default=None,
                   help="what the frames are calibrated from: their annotations, their --detections, or both merged "
                        "(default: detections when --detections is given, else annotation); a frame without the "
                        "annotation uses its detections")
    p.add_argument("--edits", type=Path, help="an edits folder of the app (pnlviz serve): its keypoint and annotation "
                                              "corrections apply (read only; default: none)")
    add_force_edits(p)
    p.add_argument("--out", required=True, type=Path, help="output camera zip")
    p.add_argument("--no-pnl", action="store_true", help="skip the PnL refinement (and the focal/k1 refinement)")
    p.add_argument("--alpha", type=float_in(0.0, 1.0), default=DEFAULT_ALPHA,
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
    p.add_argument("--workers", type=workers_arg, default=1, help="worker processes (0: all cores)")
    p.add_argument("--report", type=Path, help="also write one JSON line per frame with the evidence")
    from pnlviz.commands.batch import add_cluster_args

    add_cluster_args(p)
    add_output_options(p)
    p.set_defaults(func=run_calibrate)


def source_of(args) -> str:
    """``--source``, else detections when there are ``--detections``, else the annotations."""
    return args.source or ("detections" if args.detections is not None else "annotation")


def frame_settings(args, detection_settings: dict | None = None):
    """The engine's settings: the source, the detector's settings (recorded beside its detections
    in ``preds.json``) for frames calibrated from detections, then the command-line flags."""
    from pnlviz.calib.frame import FrameSettings

    return FrameSettings(pnl=not args.no_pnl, alpha=args.alpha, source=source_of(args),
                         detection_settings=dict(detection_settings or {}),
                         overrides={"refine_k1": False} if args.no_k1 else {})


def calibrate_stem(reader, stem: str, settings) -> tuple[str, dict | None, dict]:
    """One frame: read its inputs (:func:`frame_inputs`), run the engine's one path
    (:func:`pnlviz.calib.frame.calibrate_frame`): (stem, camera dict at 960x540 or None, report).
    Never raises on bad input."""
    from pnlviz.calib.frame import calibrate_frame, detection_settings_apply
    from pnlviz.calib.looks import second_look_count

    report: dict = {"stem": stem}
    inputs, problem = frame_inputs(reader, stem)
    if inputs is None:
        report.update(problem or {})  # a frame without inputs has its problem
        return stem, None, report
    fc = calibrate_frame(inputs, settings)
    if fc.failure is not None:
        report.update(failure=fc.failure.message, failure_code=fc.failure.code)
    if fc.result is None:
        return stem, None, report
    res = fc.result
    assert fc.observations is not None  # a frame with a result has its observations
    report.update({
        "ms": round(fc.ms, 2), "keypoints": int(fc.observations.n_keypoints), "origin": fc.origin,
        "subset": res.subset, "threshold": res.threshold, "plane": res.plane,
        "inliers": [int(i) for i in res.inliers], "pnl_lines": res.pnl_lines, "lines_alone": res.lines_alone,
        "half": res.half,
        "point_residuals": {str(k): round(v, 3) for k, v in res.point_residuals.items()},
        "line_residuals_initial": {k: round(v, 3) for k, v in res.line_residuals_initial.items()},
        "line_residuals": {k: round(v, 3) for k, v in res.line_residuals.items()},
    })
    weak = second_look_count(inputs.detections, detection_settings_apply(fc.origin, settings))
    if weak:  # the camera rests on a second look at the detections (pnlviz.calib.looks)
        report["second_look"] = weak
    if res.camera is None:  # not res.ok
        return stem, None, report
    return stem, res.camera.scaled(*EVAL_SIZE).to_soccernet(), report


def frame_inputs(reader, stem: str) -> tuple[FrameInputs | None, dict | None]:
    """The :class:`pnlviz.calib.frame.FrameInputs` of one frame as :class:`pnlviz.pipeline.FrameReader`
    reads it, or None with the report's failure fields: a frame whose files (its image included)
    cannot be read is skipped, one with nothing to calibrate from fails."""
    read = reader.read(stem)
    problem = read.image_error or read.error
    if problem is not None:
        return None, {"failure": f"skipped: {problem}", "failure_code": "bad_input"}
    inputs = read.inputs
    if inputs.annotation is None and inputs.detections is None and not inputs.keypoint_edits:
        return None, {"failure": "no annotation" if reader.predictions is None else "no detections for this frame",
                      "failure_code": "no_input"}
    return inputs, None


def frame_reader(ds, predictions, size, source: str, edits):
    """How the command reads frames: the annotations only when the source uses them, no
    reference cameras, the corrections of ``edits`` (an edits folder opened read-only, or None)."""
    from pnlviz.pipeline import FrameReader

    return FrameReader(ds, predictions=predictions, edits=edits, size=size, annotations=source != "detections",
                       reference_cameras=False)


def temporal_pass(reader, settings, stems: list[str], results: dict, progress: bool = True) -> dict:
    """``--temporal``: per clip (:func:`pnlviz.data.layout.video_clips`), the per-frame cameras in
    ``results`` (``{stem: (camera dict at 960x540 | None, report)}``) replaced by the broadcast
    model of their shot where it is not worse than their own (:func:`pnlviz.calib.temporal.calibrate_clip`);
    reports gain the clip, the shot, which camera the frame uses and why, and the residuals. Image changes between consecutive frames mark cuts when the frames
    have images."""
    from tqdm import tqdm

    from pnlviz.calib.temporal import calibrate_clip_frames, image_changes
    from pnlviz.data.layout import video_clips
    from pnlviz.field import load_field_model
    from pnlviz.geometry.camera import Camera

    ds = reader.ds
    model = load_field_model()
    out = dict(results)
    groups = video_clips(stems)
    in_clip = {s for members in groups.values() for s in members}
    for s in stems:  # frames of no clip: each its own camera, and the report says why
        if s not in in_clip and s in out:
            cam_dict, report = out[s]
            out[s] = (cam_dict, {**report, "temporal": {"clip": None, "camera": "own" if cam_dict else "none",
                                                        "why": "not part of a clip (pnlviz.data.layout.video_clips)"}})
    bar = tqdm(total=len(in_clip), desc="temporal", unit="frame", disable=not progress or None)
    for clip, members in groups.items():
        inputs = [frame_inputs(reader, s)[0] for s in members]
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
            changes = image_changes(_image_or_none(ds, s) for s in members)  # two frames in memory at a time
        res = calibrate_clip_frames(inputs, settings, cameras=cams, changes=changes, model=model).result
        for t, s in enumerate(members):
            out[s] = _temporal_result(clip, t, res, *results.get(s, (None, {"stem": s})))
        bar.update(len(members))
    bar.close()
    return out


def _temporal_result(clip: str, t: int, res, cam_dict: dict | None, report: dict) -> tuple[dict | None, dict]:
    """Frame ``t`` of ``clip`` after its clip's calibration ``res``: the camera it uses (its
    shot's or its own, as SoccerNet JSON at 960x540) and its report with which one and why."""
    import numpy as np

    report = dict(report)
    k = res.shot_of[t]
    fit, choice = res.fits[k], res.choices[t]
    report["temporal"] = {"clip": clip, "shot": k, "shots": len(res.shots), "per_frame": cam_dict is not None,
                          "camera": choice.use, "why": choice.reason}
    cam = res.cameras[t]
    if choice.use != "shot" or cam is None or fit is None:
        return cam_dict, report
    i = t - res.shots[k].start
    r = fit.residuals[i]
    report["temporal"].update(residual_median=round(float(np.median(r)), 3) if len(r) else None,
                              dropped=fit.dropped[i])
    report.pop("failure", None)
    report.pop("failure_code", None)
    return cam.scaled(*EVAL_SIZE).to_soccernet(), report


def _image_or_none(ds, stem: str):
    """The frame's pixels, None when they cannot be read (no cut is found there)."""
    from pnlviz.data import DataError

    try:
        return ds.image(stem)
    except DataError:
        return None


class _NoDataset:
    """What ``--detections`` alone calibrates against: no frame known (no image sizes, no
    annotations), so every frame of the prediction zip is calibrated at ``--size``."""

    stems: list[str] = []
    splits: tuple[str, ...] = ()

    def __contains__(self, stem) -> bool:
        return False


def worker_reader(ds, predictions, size: tuple[int, int], source: str, edits: Path | None):
    """The :func:`frame_reader` a batch worker opens, with the edits folder ``edits`` read-only
    (None: no edits)."""
    from pnlviz.data.edits import EditsStore

    store = EditsStore(edits, writable=False) if edits is not None else None
    return frame_reader(ds, predictions, size, source, store)


@dataclass
class CalibrateJob(BatchJob):
    """The frames' calibration on any worker: ``ds`` (re-opened lazily where it runs), the
    detections, the fallback size, the engine's settings, the edits folder (None: none); each
    worker reads the frames with one :func:`frame_reader` built for the run."""

    ds: object
    predictions: object
    size: tuple[int, int]
    settings: FrameSettings
    edits: Path | None = None

    def open_state(self):
        return worker_reader(self.ds, self.predictions, self.size, self.settings.source, self.edits)

    def run_chunk(self, reader, stems: list[str]) -> list:
        return [calibrate_stem(reader, stem, self.settings) for stem in stems]


def _failed_on_cluster(stem: str, message: str) -> tuple:
    return stem, None, {"stem": stem, "failure": message, "failure_code": "internal"}


def _settings_path(args) -> Path:
    """The detector's settings file: ``--detector-settings``, else the one beside ``--detections``."""
    from pnlviz.data import predictions_info_path

    return args.detector_settings if args.detector_settings is not None else predictions_info_path(args.detections)


def _check_outputs(args) -> None:
    """--out and --report: not over an input (nor over each other), not inside the dataset."""
    from pnlviz.data import check_output

    inputs = [args.detections, _settings_path(args)] if args.detections else []
    inputs += [args.video] if getattr(args, "video", None) is not None else []
    datasets = [d for d in (args.data, args.edits) if d is not None]
    check_output(args.out, inputs=inputs, datasets=datasets)
    if args.report:
        check_output(args.report, inputs=[*inputs, args.out], datasets=datasets, what="--report")


def _frames(ds, predictions, source: str, edits) -> list[str]:
    """The frames to calibrate, in dataset order: those with what the source calibrates from
    (annotated frames unless the source is the detections; frames with detections, and those
    the dataset does not have, at --size), and with ``edits`` those with corrected keypoints (or
    a corrected annotation, when the source uses annotations)."""
    from pnlviz.data import sort_stems

    use_ann = source != "detections"
    edited = set()
    for s in edits.stems() if edits is not None else ():
        rec = edits.get(s)
        if rec.get("keypoints") or use_ann and rec.get("annotation") is not None:
            edited.add(s)
    stems = [s for s in ds.stems if use_ann and ds.frame(s).has_annotation
             or predictions is not None and s in predictions or s in edited]
    if predictions is None:
        return stems
    known = set(ds.stems)
    return stems + [s for s in sort_stems(predictions) if s not in known]


def _detection_settings(args):
    """(settings recorded beside the detections, the engine's settings); DataError/ValueError
    (an unknown setting) for a bad file."""
    from pnlviz.calib.calibrate import CalibParams
    from pnlviz.data import read_predictions_info
    from pnlviz.pipeline.settings import check_settings

    settings_file = args.detector_settings
    if settings_file is None and args.detections is None:
        recorded: dict = {}
    else:
        recorded = read_predictions_info(args.detections, settings_file).get("calibration") or {}
    if recorded:  # unknown names, wrong types and values out of range fail here, not on every frame
        recorded = check_settings(recorded, str(_settings_path(args)))
    CalibParams().updated(recorded)
    return recorded, frame_settings(args, recorded)


def _args_problem(args) -> str | None:
    """What is wrong with the options together, in one line (None: nothing)."""
    if args.data is None and args.detections is None:
        return "give --data (a dataset), --detections (a prediction zip), or both"
    if args.video is not None and (args.data is not None or args.detections is None):
        return "--video goes with --detections (made by pnlviz detect --video), instead of --data"
    if args.detector_settings is not None and args.detections is None:
        return "--detector-settings goes with --detections (the settings of the detector that made them)"
    if args.source == "detections" and args.detections is None:
        return "--source detections needs --detections"
    if args.edits is not None:
        from pnlviz.data import DataError
        from pnlviz.data.edits_folder import require_edits_folder

        try:
            require_edits_folder(args.edits)
        except DataError as exc:
            return str(exc)
    return None


def _open_inputs(args):
    """(the frames' dataset, the detections, the edits folder read-only or None), each problem
    with a file said in one line."""
    from pnlviz.commands.common import open_input_dataset, print_skipped, read_edits_folder
    from pnlviz.data import read_predictions

    ds: object
    if args.video is not None:
        from pnlviz.data.video import VideoDataset

        ds = VideoDataset(args.video)
    else:
        ds = open_input_dataset(args.data) if args.data is not None else _NoDataset()
    predictions = (read_predictions(args.detections, on_error=lambda e: print_skipped([e]), splits=ds.splits)
                   if args.detections else None)
    edits = read_edits_folder(args.edits, ds, args.force_edits) if args.edits is not None else None
    return ds, predictions, edits


def run_calibrate(args) -> int:
    from pnlviz.data import DataError
    from pnlviz.data.cameras import camera_member_name

    problem = _args_problem(args)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    _check_outputs(args)
    ds, predictions, edits = _open_inputs(args)
    source = source_of(args)
    stems = _frames(ds, predictions, source, edits)
    if not stems:
        print(f"{args.data or args.detections}: no frame to calibrate", file=sys.stderr)
        return 1
    if args.video is not None:
        print(f"{len(stems)} frames of {args.detections.name}, video {args.video.name} at {ds.width}x{ds.height}")
    elif args.data is None:
        print(f"{len(stems)} frames of {args.detections.name}, calibrated at {args.size[0]}x{args.size[1]} (--size)")
    try:  # the detector's settings (pnlviz detect --settings), given or beside its prediction zip
        recorded, settings = _detection_settings(args)
    except (DataError, ValueError) as exc:
        shown = exc if isinstance(exc, DataError) else f"{_settings_path(args)}: {exc}"
        print(f"error: {shown}", file=sys.stderr)
        return 2
    if recorded:
        print(f"calibration settings of the detector ({_settings_path(args).name}): "
              + ", ".join(f"{k}={v}" for k, v in recorded.items()))
    if args.resume and args.temporal:
        print("error: --resume does not go with --temporal (a shot is fitted from all its frames at once)",
              file=sys.stderr)
        return 2
    from pnlviz.commands.batch import resume_zip

    kept, todo = resume_zip(args.out, args.resume, stems, camera_member_name, "calibrate")
    edits_path = None if args.edits is None else args.edits.resolve()
    job = CalibrateJob(ds, predictions, tuple(args.size), settings, edits_path)
    reader = frame_reader(ds, predictions, args.size, source, edits)
    return _calibrate_all(args, job, reader, stems, kept, todo)


def _calibrate_all(args, job: CalibrateJob, reader, stems: list[str], kept: dict, todo: list[str]) -> int:
    """Calibrate the frames ``todo``, write their cameras (and reports) as they come, then the
    summary; ``kept``: the cameras an interrupted run finished."""
    from pnlviz.commands.batch import interrupted, journaled_zip, pool_size, run_batch
    from pnlviz.data import DataError, LineStream
    from pnlviz.data.cameras import camera_member, camera_zip_order

    order = {s: i for i, s in enumerate(stems)}
    failures: list[tuple[str, str]] = []  # (code, message) of the frames without a camera
    progress = not args.no_progress
    with contextlib.ExitStack() as stack:
        cams = journaled_zip(stack, args.out, camera_zip_order, kept)
        reports = stack.enter_context(LineStream(args.report)) if args.report else None

        def write(result) -> None:
            stem, cam, report = result
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

        per_frame: dict = {}
        collect = (lambda r: per_frame.__setitem__(r[0], r[1:])) if args.temporal else write
        run = run_batch(job, todo, collect, args, desc="calibrate", processes=pool_size(args.workers),
                        local_state=reader, failed=_failed_on_cluster, progress=progress)
        if args.temporal and not run.interrupted:  # every frame first, then the clips' shots, then written
            run.interrupted = _write_temporal(reader, job.settings, stems, per_frame, write, progress)
    if run.interrupted:
        return interrupted(len(cams), len(stems), args.out)
    _summary(args, run, len(cams), len(stems), len(todo), failures)
    return 0 if len(cams) else 1


def _write_temporal(reader, settings, stems: list[str], per_frame: dict, write, progress: bool) -> bool:
    """``--temporal``: the shots of the clips fitted (:func:`temporal_pass`), then every frame
    written in order; True when Ctrl+C stopped it."""
    from tqdm import tqdm

    try:
        fitted = temporal_pass(reader, settings, stems, per_frame, progress=progress)
        for s in tqdm(stems, desc="write", unit="frame", disable=not progress or None):
            write((s, *fitted[s]))
    except KeyboardInterrupt:
        return True
    return False


def _summary(args, run, n_cams: int, n_stems: int, n_todo: int, failures: list[tuple[str, str]]) -> None:
    """What the run did: cameras written, time per frame, the failures counted by code."""
    from pnlviz.commands.common import print_skipped

    print(f"calibrated {n_cams}/{n_stems} frames in {run.elapsed:.1f} s "
          f"({1e3 * run.elapsed / max(1, n_todo):.1f} ms/frame with {run.workers} worker(s)"
          + (" on the dask cluster" if run.cluster else "") + f") -> {args.out}")
    words = failure_words()
    for code, n in Counter(code for code, _ in failures).most_common():
        example, word = next(message for c, message in failures if c == code), words.get(code, code)
        if example.startswith(word):  # "residual above the limit (inlier RMS ...)": the detail only
            example = example[len(word):].strip(" ()") or example
        print(f"  {n:5d} not calibrated: {word}" + (f" (e.g. {example})" if n > 1 else f" ({example})"))
    print_skipped([m for c, m in failures if c in ("bad_input", "bad_output")], prefix="  ")
    if not n_cams:
        print(f"error: no frame calibrated: {args.out} holds no camera", file=sys.stderr)
