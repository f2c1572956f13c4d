"""``pnlviz labels``: keypoint training labels (every set of the paper) from SoccerNet line
annotations, one ``<stem>.json`` per frame (schema: :mod:`pnlviz.labels.writer`).

Wire it with ``add_labels_parser(subparsers)``; it sets ``func=run_labels``.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from pnlviz.commands.common import parse_size
from pnlviz.conventions import EVAL_SIZE

DEFAULT_SIZE = EVAL_SIZE

# --------------------------------------------------------------------------- per-frame work
_STATE: dict = {}


def _init_worker(dataset, out_dir: str, size: tuple[int, int], params) -> None:
    _STATE.update(dataset=dataset, out_dir=out_dir, size=size, params=params)


def _label_one(stem: str) -> tuple[str, str, object]:
    """``(stem, status, payload)``: ``("ok", counts by set)``, ``("none", None)`` for a frame without
    annotation, ``("skipped", message)`` for a bad input file, ``("failed", message)`` otherwise."""
    from pnlviz.data.errors import DataError
    from pnlviz.labels.extremities import line_extremities
    from pnlviz.labels.keypoints import keypoints_from_annotation
    from pnlviz.labels.writer import write_labels

    ds, params = _STATE["dataset"], _STATE["params"]
    try:
        ann = ds.annotation(stem)
        if ann is None:
            return stem, "none", None
        size = ds.image_size(stem) if ds.frame(stem).has_image else None
        width, height = size or _STATE["size"]
        labels = keypoints_from_annotation(ann, width, height, params)
        ext = line_extremities(ann, width, height, mirror=labels.mirrored)
        write_labels(Path(_STATE["out_dir"]) / f"{stem}.json", labels, ext)
        return stem, "ok", (labels.count_by_set(), labels.count_by_set(visible_only=True), len(labels.rejected))
    except DataError as exc:
        return stem, "skipped", str(exc)
    except OSError as exc:
        return stem, "failed", f"{stem}: cannot write labels: {exc}"
    except Exception as exc:  # noqa: BLE001 - one bad frame never stops the batch
        return stem, "failed", f"{stem}: labels failed: {type(exc).__name__}: {exc}"


def _label_chunk(spec: tuple, stems: list[str]) -> list:
    """One cluster task: ``spec`` = (dataset, out folder, size, params); the worker writes the label
    files into the out folder itself (which it must reach: a shared filesystem) and returns only
    the status of each frame."""
    _init_worker(*spec)
    return [_label_one(stem) for stem in stems]


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
    p.add_argument("--workers", type=int, default=1, help="worker processes (default 1; 0 = all cores)")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run: frames whose label file is already in --out are kept")
    from pnlviz.commands.cluster import add_cluster_args

    add_cluster_args(p)
    p.set_defaults(func=run_labels)
    return p


def run_labels(args) -> int:
    from tqdm import tqdm

    from pnlviz.commands.common import open_input_dataset
    from pnlviz.data import DataError, OutputError, check_output
    from pnlviz.labels.types import SETS, LabelParams

    out_dir = Path(args.out)
    try:
        check_output(out_dir, datasets=[args.data])
        if out_dir.exists() and not out_dir.is_dir():
            raise OutputError(f"--out {out_dir}", "is a file: expected a folder for the label files")
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
    workers = int(getattr(args, "workers", 1) or 0) or (os.cpu_count() or 1)
    stems = list(ds.stems)
    if getattr(args, "resume", False):  # label files are written whole (atomically): one there is done
        done = {p.stem for p in out_dir.glob("*.json")}
        kept = [s for s in stems if s in done]
        stems = [s for s in stems if s not in done]
        print(f"resuming: {len(kept)} frames already labelled in {out_dir}, {len(stems)} to go")

    totals: Counter[str] = Counter()
    visible: Counter[str] = Counter()
    n_ok = n_none = n_rejected = 0
    skipped: list[str] = []
    failed: list[str] = []
    bar = tqdm(total=len(stems), desc="labels", unit="frame", disable=None)

    def handle(result) -> None:
        nonlocal n_ok, n_none, n_rejected
        stem, status, payload = result
        if status == "ok":
            n_ok += 1
            totals.update(payload[0])
            visible.update(payload[1])
            n_rejected += payload[2]
        elif status == "none":
            n_none += 1
        elif status == "skipped":
            skipped.append(payload)
            tqdm.write(f"skipped: {payload}", file=sys.stderr)
        else:
            failed.append(payload)
            tqdm.write(f"failed: {payload}", file=sys.stderr)
        bar.update(1)

    from pnlviz.commands.cluster import cluster_client, map_on_cluster

    try:
        if getattr(args, "dask", None) is not None or getattr(args, "scheduler", None) is not None:
            with cluster_client(args) as client:
                spec = (ds, os.fspath(out_dir.resolve()), size, params)
                for result in map_on_cluster(client, _label_chunk, spec, stems, args.chunk,
                                             lambda s, m: (s, "failed", f"{s}: {m}")):
                    handle(result)
        elif workers <= 1 or len(stems) < 2:
            _init_worker(ds, os.fspath(out_dir), size, params)
            for stem in stems:
                handle(_label_one(stem))
        else:
            ds.close()  # reopened in each worker
            with ProcessPoolExecutor(max_workers=workers, initializer=_init_worker,
                                     initargs=(ds, os.fspath(out_dir), size, params)) as pool:
                chunk = max(1, min(32, len(stems) // (4 * workers) or 1))
                for result in pool.map(_label_one, stems, chunksize=chunk):
                    handle(result)
    finally:
        bar.close()
        _STATE.clear()

    print(f"{args.data}: {len(stems)} frames, {n_ok} labelled -> {out_dir}"
          + (f", {n_none} without annotation" if n_none else "")
          + f", {len(skipped)} skipped" + (f", {len(failed)} failed" if failed else ""))
    if n_ok:
        per_set = "  ".join(f"{s} {totals[s] / n_ok:.2f} ({visible[s] / n_ok:.2f})" for s in SETS)
        print(f"keypoints per frame, all (visible): {per_set}  total {sum(totals.values()) / n_ok:.2f} "
              f"({sum(visible.values()) / n_ok:.2f}); rejected candidates {n_rejected / n_ok:.2f}")
    if skipped:
        print(f"{len(skipped)} bad frame(s) skipped:", file=sys.stderr)
        for line in skipped:
            print(f"  {line}", file=sys.stderr)
    return 1 if failed or not n_ok else 0
