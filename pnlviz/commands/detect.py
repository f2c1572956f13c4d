"""``pnlviz detect``: keypoint and line-extremity detection over a dataset, written as a PnLCalib
2D prediction zip that ``pnlviz calibrate --detections`` (and PnLCalib's own code) reads."""

from __future__ import annotations

import contextlib
import sys
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from pnlviz.commands.batch import BatchJob, on_cluster
from pnlviz.commands.common import add_output_options, float_in, int_at_least


def add_detect_parser(sub) -> None:
    from pnlviz.commands.common import parse_size

    p = sub.add_parser("detect", help="keypoint + line-extremity detection (torch, CPU) -> prediction zip",
                       description="Run PnLCalib-compatible networks on every image of a dataset and write a "
                                   "PnLCalib 2D prediction zip. The published architecture takes 6-7 s per frame "
                                   "per network at 960x540 on a 2-core CPU; without weights, the light default model "
                                   "shipped with pnlviz takes about 50 ms.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--data", type=Path, help="dataset folder or zip with images")
    src.add_argument("--video", type=Path, help="a video file (mp4, ...): every frame, decoded one at a time; "
                                               "frames are named <video>-IMG_<n> (one clip for --temporal)")
    p.add_argument("--out", required=True, type=Path, help="output prediction zip")
    p.add_argument("--settings", type=Path, default=None, metavar="FILE",
                   help="also write the detector's settings to FILE (JSON: the networks, thresholds, input size and the "
                        "calibration settings its detections calibrate best with); calibrate, serve and export "
                        "apply them with --detector-settings FILE, or by themselves when FILE sits beside the zip "
                        "with its name (preds.zip -> preds.json). Default: nothing but --out is written")
    p.add_argument("--weights-kp", type=Path, help="keypoint network checkpoint (e.g. PnLCalib's SV_kp)")
    p.add_argument("--weights-lines", type=Path, help="line network checkpoint (e.g. PnLCalib's SV_lines)")
    p.add_argument("--weights", type=Path, default=None,
                   help="a light model (LightNet checkpoint from pnlviz train, with its .json sidecar) instead of "
                        "the shipped default")
    p.add_argument("--input-size", type=parse_size, default=None,
                   help="network input size (default: the network's own, 960x540 for PnLCalib's networks, "
                        "480x272 for the light default model, as its sidecar says)")
    p.add_argument("--kp-threshold", type=float_in(0.0, 1.0), default=None,
                   help="keypoint heatmap threshold (default 0.1; the light default model: its sidecar's)")
    p.add_argument("--line-threshold", type=float_in(0.0, 1.0), default=None,
                   help="line heatmap threshold (default 0.1; the light default model: its sidecar's)")
    p.add_argument("--batch", type=int_at_least(1, 256), default=1,
                   help="frames per forward pass (default 1, the fastest on a CPU: batches of 8 are 1.05-1.13x slower "
                        "there; on a GPU larger batches pay). Detections do not depend on it")
    p.add_argument("--device", default="cpu", help="where the networks run: cpu (default), cuda, cuda:N, or auto "
                                                   "(a GPU if torch sees one)")
    p.add_argument("--half", action="store_true",
                   help="run the networks in float16 (for GPUs: half the memory; 1.4-1.5x slower on a CPU). With the light "
                        "model on real frames, points move 0.11 px at p99)")
    p.add_argument("--threads", type=int, default=0,
                   help="torch CPU threads (default: the idle cores less one, at least 1; more threads than "
                        "free cores makes torch wait for itself: 5-9x slower)")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run: frames already in --out (or in the progress a killed run "
                        "left beside it) are kept, only the missing ones are detected")
    from pnlviz.commands.batch import add_cluster_args

    add_cluster_args(p)
    add_output_options(p)
    p.set_defaults(func=run_detect)


def _check_outputs(args) -> None:
    """--out must be a .zip; neither it nor the settings file (``--settings``) may overwrite an
    input or land inside the dataset."""
    import os

    from pnlviz.data import OutputError, check_output

    if args.out.suffix.lower() != ".zip":
        raise OutputError(f"--out {args.out}", "must end in .zip (PnLCalib's prediction zip)")
    inputs = [args.weights_kp, args.weights_lines, args.weights]
    datasets = [args.data] if args.data is not None else []
    inputs = inputs + ([args.video] if args.video is not None else [])
    check_output(args.out, inputs=inputs, datasets=datasets)
    if args.settings is not None:
        if Path(os.path.abspath(args.settings)) == Path(os.path.abspath(args.out)):
            raise OutputError(f"--settings {args.settings}", "is --out itself")
        check_output(args.settings, inputs=inputs, datasets=datasets, what="--settings")


def _detector_kwargs(args) -> dict:
    """What :meth:`pnlviz.detect.run.Detector.from_weights` is called with (here and on cluster
    workers); ``device`` as asked: each process resolves it where the networks run."""
    kw = {"weights_kp": args.weights_kp, "weights_lines": args.weights_lines, "light": args.weights,
          "input_size": args.input_size, "device": args.device, "half": args.half}
    kw.update({k: v for k, v in (("kp_threshold", args.kp_threshold), ("line_threshold", args.line_threshold))
               if v is not None})
    return kw


def _load_detector(args):
    """The detector of this run, in this process. On a cluster the workers run the networks on the
    device asked for; here only its settings are needed (for ``preds.json``): PnLCalib's networks
    (1.75 GB) are not loaded for that, the light model (6 MB, settings in its sidecar) is, on the CPU."""
    from pnlviz.detect.run import DEFAULT_INPUT_SIZE, Detector, resolve_device

    kw = _detector_kwargs(args)
    weights_kp, weights_lines = kw.pop("weights_kp"), kw.pop("weights_lines")
    if on_cluster(args) and (weights_kp is not None or weights_lines is not None):
        kw.pop("light")
        kw["device"] = "cpu"
        kw["input_size"] = kw["input_size"] or DEFAULT_INPUT_SIZE
        return Detector(None, None, **kw)
    kw["device"] = "cpu" if on_cluster(args) else resolve_device(kw["device"])
    return Detector.from_weights(weights_kp, weights_lines, **kw)


def _detect_here(ds, det, stems: list[str], step: int):
    """``(stem, Predictions | None, problem | None)`` of every frame, ``step`` frames per pass;
    each frame's second reading kept where its first gives no camera
    (:func:`pnlviz.calib.looks.kept_reading`)."""
    from pnlviz.calib.looks import kept_reading
    from pnlviz.data import DataError

    for i in range(0, len(stems), step):
        batch, images = [], []
        for stem in stems[i:i + step]:
            try:
                images.append(ds.image(stem))
                batch.append(stem)
            except DataError as exc:
                yield stem, None, str(exc)
        for stem, img, p in zip(batch, images, det.detect(images) if images else []):
            yield stem, kept_reading(p, img, det), None


def _detector_key(kw: dict) -> str:
    """What a worker's detector is built from: its settings and its weight files as they are now
    (a model retrained under the same name is loaded again on a long-lived cluster)."""
    import os

    from pnlviz.detect.default import DEFAULT_MODEL

    files = [kw.get(k) for k in ("weights_kp", "weights_lines", "light")]
    if not any(files):
        files = [DEFAULT_MODEL]
    stats = []
    for f in files:
        try:
            st = os.stat(f) if f is not None else None
        except OSError:  # loading it says what is wrong with it
            st = None
        stats.append(None if st is None else (st.st_size, st.st_mtime_ns))
    return repr((sorted((k, str(v)) for k, v in kw.items()), stats))


@dataclass
class DetectJob(BatchJob):
    """The frames' detection on any worker: the dataset (or video, re-opened lazily where it runs),
    how to build the detector (:func:`_detector_kwargs`), frames per forward pass. A worker
    builds the detector once and keeps it while its settings and weight files stay the same
    (:func:`_detector_key`), from one run to the next."""

    ds: object
    detector: dict
    batch: int

    def state_key(self) -> str:
        return _detector_key(self.detector)

    def open_state(self):
        import torch

        from pnlviz.detect.run import Detector, resolve_device

        torch.set_num_threads(1)  # one thread per worker process: the cluster's processes are its parallelism
        kw = dict(self.detector)
        kw["device"] = resolve_device(kw["device"])  # this worker's GPU, or a clear error from it
        return Detector.from_weights(kw.pop("weights_kp"), kw.pop("weights_lines"), **kw)

    def run_chunk(self, det, stems: list[str]) -> list:
        return list(_detect_here(self.ds, det, stems, self.batch))


def _sidecar(args, det, frames: int) -> dict:
    from pnlviz.detect.default import DEFAULT_MODEL

    weights = {"kp": args.weights_kp, "lines": args.weights_lines}
    named: str | dict[str, str]
    if args.weights is not None:
        kind, named = "light model", str(args.weights)
    elif any(weights.values()):
        kind, named = "PnLCalib networks", {k: str(v) for k, v in weights.items() if v}
    else:
        kind, named = "light default model", str(DEFAULT_MODEL)
    return {
        "detector": kind,
        "weights": named,
        "input_size": list(det.input_size), "device": args.device if on_cluster(args) else det.device,
        "precision": "float16" if args.half else "float32",
        "kp_threshold": det.kp_threshold,
        "line_threshold": det.line_threshold, "peak_refine": det.refine,
        "second_look": (None if det.second_look is None
                        else dict(zip(("kp_threshold", "line_threshold"), det.second_look))),
        "calibration": det.calibration, "frames": frames,
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }


def _threads(args) -> int:
    """Torch's CPU threads in this process: ``--threads``, else chosen from the idle cores (said)."""
    import os

    import torch

    from pnlviz.detect.default import default_threads, machine_load

    threads = args.threads or default_threads()
    torch.set_num_threads(threads)
    if not args.threads:
        load = machine_load()
        print(f"torch threads: {threads} (chosen from {os.cpu_count()} cores"
              + (f", load {load:.1f}" if load is not None else "") + "; --threads N to set)")
    return threads


def run_detect(args) -> int:
    from pnlviz.detect.default import torch_missing

    if (missing := torch_missing()) is not None:
        print(f"error: {missing}", file=sys.stderr)
        return 2

    from pnlviz.commands.batch import resume_zip
    from pnlviz.commands.common import open_input_dataset
    from pnlviz.detect.checkpoint import CheckpointError
    from pnlviz.detect.run import NoModelError

    if args.threads < 0:
        print(f"error: --threads must be 0 (the default: chosen from the idle cores) or more, got {args.threads}",
              file=sys.stderr)
        return 2
    _check_outputs(args)
    if args.video is not None:
        from pnlviz.data.video import VideoDataset

        ds = VideoDataset(args.video)
        print(f"{args.video.name}: {len(ds)} frames, {ds.width}x{ds.height}" + (f", {ds.fps:.2f} fps" if ds.fps else ""))
    else:
        ds = open_input_dataset(args.data)
    stems = [s for s in ds.stems if ds.frame(s).has_image]
    if not stems:
        print(f"{args.data or args.video}: no images to detect on", file=sys.stderr)
        return 1
    kept, todo = resume_zip(args.out, args.resume, stems, lambda s: f"{s}.json", "detect")
    _threads(args)
    try:
        det = _load_detector(args)
    except (NoModelError, CheckpointError, OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return _detect_all(args, DetectJob(ds, _detector_kwargs(args), max(1, args.batch)), det, stems, kept, todo)


def _detect_all(args, job: DetectJob, det, stems: list[str], kept: dict, todo: list[str]) -> int:
    """Detect the frames ``todo`` (here with ``det``, or on the cluster), write them as they come,
    the sidecar, then the summary; ``kept``: the frames an interrupted run finished."""
    from pnlviz.commands.batch import interrupted, journaled_zip, run_batch
    from pnlviz.commands.common import print_skipped
    from pnlviz.data import DataError, predictions_info_path, write_predictions_info
    from pnlviz.data.predictions import prediction_member, prediction_zip_order

    skipped: list[str] = []
    with contextlib.ExitStack() as stack:
        preds = journaled_zip(stack, args.out, prediction_zip_order, kept)

        def write(result) -> None:
            stem, p, problem = result
            if p is not None:
                try:  # written at once: an interrupted or failing batch keeps it
                    preds.add(*prediction_member(stem, p, args.out))
                except DataError as exc:
                    problem = str(exc)
            if problem is not None:
                skipped.append(problem)

        run = run_batch(job, todo, write, args, desc="detect", local_state=det, chunk=job.batch,
                        failed=lambda s, m: (s, None, m), progress=not args.no_progress)
    if args.settings is not None:
        write_predictions_info(args.out, _sidecar(args, det, len(preds)), to=args.settings)
    if run.interrupted:
        return interrupted(len(preds), len(stems), args.out)
    print(f"detected {len(preds)}/{len(stems)} frames in {run.elapsed:.1f} s "
          f"({1e3 * run.elapsed / max(1, len(todo)):.0f} ms/frame) -> {args.out}")
    if args.settings is not None:
        print(f"detector settings -> {args.settings}")
    elif det.calibration:
        shown = ", ".join(f"{k} {v}" for k, v in sorted(det.calibration.items()))
        print(f"note: this detector calibrates best with {shown}; --settings FILE keeps them for calibrate, serve "
              f"and export (FILE beside the zip, {predictions_info_path(args.out).name}, is applied by itself)")
    print_skipped(skipped, prefix="  skipped: ")
    if not len(preds):
        print(f"error: no frame detected: {args.out} holds no detection", file=sys.stderr)
        return 1
    return 0
