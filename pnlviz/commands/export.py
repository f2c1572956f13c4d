"""``pnlviz export``: the corrected training labels of a dataset and its edits, as the app's
export button downloads them (layout: :mod:`pnlviz.app.export`). Read-only: the edits folder is
neither created, locked nor changed. With ``--dask`` / ``--scheduler`` the frames are calibrated
on a cluster whose workers read the data and the edits where they are."""

from __future__ import annotations

import contextlib
import sys
import uuid
from dataclasses import dataclass
from pathlib import Path


def add_export_parser(sub) -> None:
    from pnlviz.commands.cluster import add_cluster_args
    from pnlviz.commands.common import add_app_data_args

    p = sub.add_parser("export", help="export corrected training labels (as the app's export button)",
                       description="Write the corrected labels of a dataset and its edits: SoccerNet annotations, "
                                   "keypoint labels, cameras, COCO keypoints and a manifest of what changed. "
                                   "Only accepted and corrected frames unless --all.")
    add_app_data_args(p)  # as pnlviz serve takes them
    p.add_argument("--out", required=True, type=Path, help="output folder, or a .zip")
    p.add_argument("--all", action="store_true", help="export every frame, reviewed or not")
    p.add_argument("--no-progress", action="store_true")
    add_cluster_args(p)
    p.set_defaults(func=run_export)


@dataclass(frozen=True)
class _ExportJob:
    """What a cluster worker needs to export frames: where the data and the edits are. ``run`` is
    new for every command, so that a long-lived cluster does not export from edits it read before."""

    data: str
    detections: str | None
    edits: str | None
    size: tuple[int, int]
    run: str


_WORKER_STATE: dict = {}  # on a cluster worker: the read-only AppState of the current run


def _export_chunk(job: _ExportJob, stems: list[str]) -> list:
    """One cluster task: the exports of the frames ``stems``, computed on this worker."""
    from pnlviz.app.export import export_frame
    from pnlviz.app.state import AppState

    if _WORKER_STATE.get("run") != job.run:
        old = _WORKER_STATE.pop("state", None)
        if old is not None:
            old.close()
        _WORKER_STATE.update(run=job.run, state=AppState(
            Path(job.data), detections=None if job.detections is None else Path(job.detections),
            edits=None if job.edits is None else Path(job.edits), size=job.size, writable=False))
    state = _WORKER_STATE["state"]
    return [export_frame(state, stem) for stem in stems]


def _failed_on_cluster(state, stem: str, message: str):
    """The manifest entry of a frame whose cluster task failed: what the edits say of it, no labels."""
    from pnlviz.app.export import FrameExport, edits_entry

    return FrameExport(stem, {**edits_entry(state, stem), "calibrated": False, "error": f"{stem}: {message}",
                              "exported": False})


def run_export(args) -> int:
    from tqdm import tqdm

    from pnlviz import EXAMPLES_DIR
    from pnlviz.app.export import export_frame, export_stems, write_export
    from pnlviz.app.state import AppState
    from pnlviz.commands.cluster import cluster_client, map_on_cluster
    from pnlviz.data.outputs import OutputError, check_output

    data = args.data or EXAMPLES_DIR / "sample"
    try:
        check_output(args.out, inputs=(args.detections,), datasets=(data, args.edits))
    except OutputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    # read-only: export never creates, locks or changes the edits folder
    with AppState(data, detections=args.detections, edits=args.edits, size=args.size, writable=False) as state, \
            contextlib.ExitStack() as stack:
        for warning in state.problems + state.edits.warnings:
            print(f"warning: {warning}", file=sys.stderr)
        stems = export_stems(state, args.all)
        client = stack.enter_context(cluster_client(args))
        if client is not None:
            job = _ExportJob(str(Path(data).resolve()), None if args.detections is None else str(args.detections.resolve()),
                             str(state.edits.root.resolve()), tuple(args.size), uuid.uuid4().hex)
            parts = map_on_cluster(client, _export_chunk, job, stems, args.chunk,
                                   lambda stem, message: _failed_on_cluster(state, stem, message))
        else:
            parts = (export_frame(state, stem) for stem in stems)
        bar = tqdm(parts, total=len(stems), desc="export", unit="frame", disable=args.no_progress or None)
        frames = write_export(state, args.out, include_all=args.all, parts=bar)
        bar.close()
        unreadable = {stem: e["error"] for stem, e in frames.items() if not e["exported"]}
        for stem, e in frames.items():
            if e["error"]:
                print(f"{'skipped' if stem in unreadable else 'warning'}: {e['error']}", file=sys.stderr)
        which = "frames" if args.all else "accepted/corrected frames"
        print(f"exported {len(frames) - len(unreadable)} {which} of {len(state.stems)} to {args.out}"
              + (" on the dask cluster" if client is not None else "")
              + (f" ({len(unreadable)} unreadable or failed, listed in the manifest)" if unreadable else ""))
    return 0
