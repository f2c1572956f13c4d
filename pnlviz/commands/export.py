"""``pnlviz export``: the corrected training labels of a dataset and its edits, as the app's
export button downloads them (layout: :mod:`pnlviz.pipeline.export`). Read-only: the edits folder
is neither created, locked nor changed. With ``--dask`` / ``--scheduler`` the frames are
calibrated on a cluster whose workers read the data and the edits where they are."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from pnlviz.commands.batch import BatchJob
from pnlviz.commands.common import add_output_options, float_in

if TYPE_CHECKING:
    from pnlviz.pipeline.reader import Settings


def add_export_parser(sub) -> None:
    from pnlviz.commands.batch import add_cluster_args
    from pnlviz.commands.common import add_app_data_args

    p = sub.add_parser("export", help="export corrected training labels (as the app's export button)",
                       description="Write the corrected labels of a dataset and its edits: SoccerNet annotations, "
                                   "keypoint labels, cameras, COCO keypoints and a manifest of what changed. "
                                   "Only accepted and corrected frames unless --all. --format gsr writes the cameras "
                                   "(and a tracker's boxes placed on the pitch) as one sn-gamestate JSON file instead.")
    add_app_data_args(p)  # as pnlviz serve takes them
    p.add_argument("--out", required=True, type=Path, help="output folder, or a .zip (--format gsr: a .json file)")
    p.add_argument("--format", choices=("labels", "gsr"), default="labels",
                   help="labels: the training labels (default); gsr: SoccerNet Game State Reconstruction's "
                        "Labels-GameState.json layout, one camera per frame (SoccerNet camera dict at the frame's size) "
                        "and, with --boxes, each box's bbox_pitch")
    p.add_argument("--boxes", type=Path, default=None,
                   help="--format gsr: a tracker's boxes to place on the pitch, MOT text (frame, id, left, top, width, "
                        "height, ...; frame 1 is the dataset's first) or COCO JSON (images matched by file name)")
    p.add_argument("--all", action="store_true", help="export every frame, reviewed or not (unreviewed ones marked so)")
    p.add_argument("--gate-px", type=float_in(0.0, 1000.0, open_low=True), default=10.0,
                   help="outlier gate: a visible point farther than this from its frame's camera (pixels at "
                        "960x540, scaled to the frame) is exported flagged, not as ground truth, unless a hand "
                        "placed it (default 10)")
    add_cluster_args(p)
    add_output_options(p)
    p.set_defaults(func=run_export)


@dataclass
class ExportJob(BatchJob):
    """The frames' exports on any worker: where the data, the detections and the edits are, the
    fallback size and the calibration settings; each worker opens them read-only once per run
    (a new run reads the edits again)."""

    data: str
    detections: str | None
    edits: str
    size: tuple[int, int]
    settings: Settings
    gate_px: float = 10.0
    settings_file: str | None = None

    def open_state(self):
        from pnlviz.pipeline import FrameReader

        return FrameReader.open(Path(self.data), detections=None if self.detections is None else Path(self.detections),
                                edits=Path(self.edits), size=self.size,
                                settings_file=None if self.settings_file is None else Path(self.settings_file))

    def run_chunk(self, reader, stems: list[str]) -> list:
        from pnlviz.pipeline.export import export_frame

        return [export_frame(reader, stem, self.settings, gate_px=self.gate_px) for stem in stems]


def _interrupted(args, writer, done: int, total: int) -> int:
    """Ctrl+C: a zip is not written; a folder keeps the label files written so far, without the
    COCO file and the manifest (the export is not whole)."""
    writer.discard()
    if writer.out.suffix == ".zip":
        print(f"interrupted: {args.out} not written ({done} of {total} frames were done)", file=sys.stderr)
    else:
        print(f"interrupted: kept the label files of {done} of {total} frames in {args.out}, without "
              f"coco_keypoints.json and manifest.json", file=sys.stderr)
    return 130


def _say_done(args, frames: dict, total: int, cluster: bool) -> None:
    empty = [stem for stem, e in frames.items() if e.get("empty")]
    unreadable = {stem: e["error"] for stem, e in frames.items() if not e["exported"] and not e.get("empty")}
    for stem, e in frames.items():
        if e["error"]:
            print(f"{'skipped' if stem in unreadable else 'warning'}: {e['error']}", file=sys.stderr)
    if empty:
        print(f"warning: {len(empty)} unreviewed frame(s) with nothing to export (no annotation, no detections, no "
              f"keypoint placed by hand: {', '.join(empty[:3])}{' ...' if len(empty) > 3 else ''}): no label files "
              f"written for them, listed in the manifest; give --detections to export the detector's points",
              file=sys.stderr)
    which = "frames" if args.all else "accepted/corrected frames"
    flagged = sum(e.get("flagged", 0) for e in frames.values())
    print(f"exported {len(frames) - len(unreadable) - len(empty)} {which} of {total} to {args.out}; "
          f"{flagged} points beyond the outlier gate flagged ({args.gate_px:g} px at 960x540)"
          + (" on the dask cluster" if cluster else "")
          + (f" ({len(unreadable)} unreadable or failed, listed in the manifest)" if unreadable else ""))


def run_export(args) -> int:
    from pnlviz.commands.batch import run_batch
    from pnlviz.commands.common import app_data
    from pnlviz.data.edits_folder import check_identity, require_edits_folder
    from pnlviz.data.outputs import OutputError, check_output
    from pnlviz.pipeline import FrameReader
    from pnlviz.pipeline.export import ExportWriter, export_stems, failed_frame

    given_edits = args.edits is not None
    data, args.edits = app_data(args)
    if not (args.gate_px > 0 and args.gate_px < float("inf")):
        print(f"error: --gate-px must be a positive number of pixels, got {args.gate_px}", file=sys.stderr)
        return 2
    gsr = args.format == "gsr"
    try:
        if args.boxes is not None and not gsr:
            raise OutputError("--boxes", "places a tracker's boxes on the pitch in a GSR file: give --format gsr")
        if gsr and Path(args.out).suffix.lower() != ".json":
            raise OutputError(f"--out {args.out}", "must end in .json with --format gsr (one Labels-GameState file)")
        check_output(args.out, inputs=(args.detections, args.boxes, args.detector_settings), datasets=(data, args.edits),
                     folder=not gsr and Path(args.out).suffix.lower() != ".zip")
    except OutputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    boxes = None
    if args.boxes is not None:
        from pnlviz.data import DataError
        from pnlviz.data.boxes import read_boxes

        try:
            boxes = read_boxes(args.boxes)
        except DataError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    if given_edits:
        require_edits_folder(args.edits)  # a typo, a file or a FIFO is not "no edits"
    # read-only: export never creates, locks or changes the edits folder
    with FrameReader.open(data, detections=args.detections, edits=args.edits, size=args.size,
                          force_edits=args.force_edits, settings_file=args.detector_settings) as reader:
        stems = export_stems(reader, args.all)
        # every record exported is of this dataset's picture (the folder's were checked in part when opened)
        check_identity(reader.edits_folder, reader.ds, force=args.force_edits, stems=stems, limit=None)
        for warning in [str(e) for e in reader.ds.rejected] + reader.edits_folder.warnings:
            print(f"warning: {warning}", file=sys.stderr)
        job = ExportJob(str(Path(data).resolve()), None if args.detections is None else str(args.detections.resolve()),
                        str(reader.edits_folder.root.resolve()), tuple(args.size), reader.default_settings(),
                        args.gate_px,
                        None if args.detector_settings is None else str(args.detector_settings.resolve()))
        if gsr:
            return _export_gsr(args, reader, job, stems, boxes)
        with ExportWriter(reader, args.out, include_all=args.all, gate_px=args.gate_px) as writer:
            run = run_batch(job, stems, writer.add, args, desc="export", local_state=reader,
                            failed=lambda stem, message: failed_frame(reader, stem, message),
                            progress=not args.no_progress)
            if run.interrupted:
                return _interrupted(args, writer, run.done, len(stems))
            writer.close()
        _say_done(args, writer.manifest["frames"], len(reader.stems), run.cluster)
    return 0


def _export_gsr(args, reader, job: ExportJob, stems: list[str], boxes) -> int:
    """``--format gsr``: the same frames and cameras as the label export, one GSR file
    (:mod:`pnlviz.pipeline.gsr`); nothing is written when interrupted."""
    from pnlviz.commands.batch import run_batch
    from pnlviz.pipeline.export import failed_frame
    from pnlviz.pipeline.gsr import GsrWriter

    writer = GsrWriter(reader, Path(args.out), boxes, include_all=args.all)
    run = run_batch(job, stems, writer.add, args, desc="export", local_state=reader,
                    failed=lambda stem, message: failed_frame(reader, stem, message), progress=not args.no_progress)
    if run.interrupted:
        print(f"interrupted: {args.out} not written ({run.done} of {len(stems)} frames were done)", file=sys.stderr)
        return 130
    counts = writer.close()
    which = "frames" if args.all else "accepted/corrected frames"
    line = (f"exported {counts['frames']} {which} of {len(reader.stems)} to {args.out} (GSR): "
            f"{counts['cameras']} with a camera")
    if boxes is not None:
        line += f"; {counts['boxes'] - counts['boxes_without_camera']} of {counts['boxes']} boxes placed on the pitch"
    print(line)
    if boxes is not None:
        if counts["boxes_without_camera"]:
            print(f"warning: {counts['boxes_without_camera']} box(es) have no bbox_pitch (their frame has no camera, "
                  f"or a bottom corner is above the horizon)", file=sys.stderr)
        if counts["boxes_not_exported"]:
            print(f"warning: {counts['boxes_not_exported']} box(es) on frames not exported (not accepted or corrected: "
                  f"--all exports every frame)", file=sys.stderr)
        if counts["boxes_unmatched"]:
            print(f"warning: {counts['boxes_unmatched']} box(es) on images that are no frame of {reader.data.name} "
                  f"(MOT frame numbers count the dataset's frames from 1; COCO images match by file name)",
                  file=sys.stderr)
    return 0
