"""``pnlviz labels``: keypoint training labels (every set of the paper) from SoccerNet line
annotations, one ``<stem>.json`` per frame (schema: :mod:`pnlviz.labels.writer`).

Wire it with ``add_labels_parser(subparsers)``; it sets ``func=run_labels``.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from pnlviz.commands.batch import BatchJob
from pnlviz.commands.common import add_output_options, parse_size, workers_arg
from pnlviz.conventions import EVAL_SIZE

DEFAULT_SIZE = EVAL_SIZE


# --------------------------------------------------------------------------- per-frame work
def label_frame(ds, stem: str, out_dir: str, size: tuple[int, int], params) -> tuple[str, str, object]:
    """One frame's labels written to ``out_dir/<stem>.json``: ``(stem, status, payload)``:
    ``("ok", counts by set)``, ``("none", None)`` for a frame without annotation, ``("skipped",
    message)`` for a bad input file, ``("failed", message)`` otherwise."""
    from pnlviz.data.errors import DataError
    from pnlviz.labels.extremities import line_extremities
    from pnlviz.labels.keypoints import keypoints_from_annotation
    from pnlviz.labels.writer import write_labels

    try:
        ann = ds.annotation(stem)
        if ann is None:
            return stem, "none", None
        image_size = ds.image_size(stem) if ds.frame(stem).has_image else None
        width, height = image_size or size
        labels = keypoints_from_annotation(ann, width, height, params)
        ext = line_extremities(ann, width, height, mirror=labels.mirrored)
        path = Path(out_dir) / f"{stem}.json"  # <out>/<split>/<stem>.json for a dataset in splits
        path.parent.mkdir(exist_ok=True)
        write_labels(path, labels, ext)
        return stem, "ok", (labels.count_by_set(), labels.count_by_set(visible_only=True), len(labels.rejected))
    except DataError as exc:
        return stem, "skipped", str(exc)
    except OSError as exc:
        return stem, "failed", f"{stem}: cannot write labels: {exc}"
    except Exception as exc:  # noqa: BLE001 - one bad frame never stops the batch
        return stem, "failed", f"{stem}: labels failed: {type(exc).__name__}: {exc}"


@dataclass
class LabelsJob(BatchJob):
    """The frames' labels on any worker: the dataset (re-opened lazily where it runs), the output
    folder (which a cluster's workers write into themselves: a shared filesystem), the size of
    frames without an image, the label settings. Only each frame's status comes back."""

    ds: object
    out_dir: str
    size: tuple[int, int]
    params: object

    def run_chunk(self, state, stems: list[str]) -> list:
        return [label_frame(self.ds, stem, self.out_dir, self.size, self.params) for stem in stems]


class _Tally:
    """What the run did, frame by frame (:meth:`add`), and its summary (:meth:`print`)."""

    def __init__(self) -> None:
        self.totals: Counter[str] = Counter()
        self.visible: Counter[str] = Counter()
        self.n_ok = self.n_none = self.n_rejected = 0
        self.skipped: list[str] = []
        self.failed: list[str] = []

    def add(self, result) -> None:
        from tqdm import tqdm

        stem, status, payload = result
        if status == "ok":
            self.n_ok += 1
            self.totals.update(payload[0])
            self.visible.update(payload[1])
            self.n_rejected += payload[2]
        elif status == "none":
            self.n_none += 1
        elif status == "skipped":
            self.skipped.append(payload)
            tqdm.write(f"skipped: {payload}", file=sys.stderr)
        else:
            self.failed.append(payload)
            tqdm.write(f"failed: {payload}", file=sys.stderr)

    def print(self, data, n_stems: int, out_dir: Path) -> None:
        from pnlviz.labels.types import SETS

        print(f"{data}: {n_stems} frames, {self.n_ok} labelled -> {out_dir}"
              + (f", {self.n_none} without annotation" if self.n_none else "")
              + f", {len(self.skipped)} skipped" + (f", {len(self.failed)} failed" if self.failed else ""))
        if self.n_ok:
            n, totals, visible = self.n_ok, self.totals, self.visible
            per_set = "  ".join(f"{s} {totals[s] / n:.2f} ({visible[s] / n:.2f})" for s in SETS)
            print(f"keypoints per frame, all (visible): {per_set}  total {sum(totals.values()) / n:.2f} "
                  f"({sum(visible.values()) / n:.2f}); rejected candidates {self.n_rejected / n:.2f}")
        if self.skipped:
            print(f"{len(self.skipped)} bad frame(s) skipped:", file=sys.stderr)
            for line in self.skipped:
                print(f"  {line}", file=sys.stderr)


# ------------------------------------------------------------------------------- argparse
def add_labels_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "labels", help="keypoint training labels (all sets) from SoccerNet line annotations",
        description="Compute PnLCalib's keypoint labels (Kp line-line, Kpe extended lines, Kp1 "
                    "line-ellipse, Kp2 tangent points, Kp3 homography-completed) and the line "
                    "extremities of every annotated frame, and write one <stem>.json per frame "
                    "(pixels; schema in pnlviz/labels/writer.py).")
    p.add_argument("--data", required=True, type=Path, help="dataset folder or zip")
    p.add_argument("--out", required=True, type=Path, help="output folder for <stem>.json label files")
    p.add_argument("--size", type=parse_size, default=DEFAULT_SIZE, metavar="WxH",
                   help="image size for frames without an image (default 960x540)")
    p.add_argument("--kp3-all", action="store_true",
                   help="also complete every missing catalogue ground point through the homography")
    p.add_argument("--lr", action="store_true",
                   help="left-right disambiguation: mirror views along the long axis looking towards -x "
                        "(for training labels; off by default)")
    p.add_argument("--workers", type=workers_arg, default=1, help="worker processes (default 1; 0 = all cores)")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run: frames whose label file is already in --out are kept")
    from pnlviz.commands.batch import add_cluster_args

    add_cluster_args(p)
    add_output_options(p)
    p.set_defaults(func=run_labels)
    return p


def _check_out(out_dir: Path, data) -> None:
    from pnlviz.data import OutputError, check_output

    if out_dir.exists() and not out_dir.is_dir():
        raise OutputError(f"--out {out_dir}", "is a file: expected a folder for the label files")
    check_output(out_dir, datasets=[data], folder=True)


def run_labels(args) -> int:
    from pnlviz.commands.batch import interrupted, pool_size, run_batch
    from pnlviz.commands.common import open_input_dataset
    from pnlviz.data import DataError, OutputError
    from pnlviz.labels.types import LabelParams

    out_dir = Path(args.out)
    try:
        _check_out(out_dir, args.data)
    except OutputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    ds = open_input_dataset(args.data)
    if not any(ds.frame(s).has_annotation for s in ds.stems):
        raise DataError(str(args.data), "no annotated frame: no labels to compute")
    out_dir.mkdir(parents=True, exist_ok=True)
    params = LabelParams(kp3_all=bool(getattr(args, "kp3_all", False)),
                         lr_disambiguation=bool(getattr(args, "lr", False)))
    size = tuple(getattr(args, "size", None) or DEFAULT_SIZE)
    stems, kept = list(ds.stems), 0
    if getattr(args, "resume", False):  # label files are written whole (atomically): one there is done
        done = {p.relative_to(out_dir).with_suffix("").as_posix()
                for p in [*out_dir.glob("*.json"), *out_dir.glob("*/*.json")]}
        kept = sum(s in done for s in stems)
        stems = [s for s in stems if s not in done]
        print(f"resuming: {kept} frames already labelled in {out_dir}, {len(stems)} to go")
    tally = _Tally()
    job = LabelsJob(ds, os.fspath(out_dir.resolve()), size, params)
    run = run_batch(job, stems, tally.add, args, desc="labels", processes=pool_size(getattr(args, "workers", 1)),
                    failed=lambda s, m: (s, "failed", f"{s}: {m}"), progress=not args.no_progress)
    if run.interrupted:
        return interrupted(kept + tally.n_ok, kept + len(stems), out_dir)
    tally.print(args.data, len(stems), out_dir)
    return 1 if tally.failed or not (tally.n_ok or kept) else 0  # a resumed job already done is a success
