"""``pnlviz validate``: read every frame and camera of a dataset, report each bad or unused file in
one line, and summarise the classes."""

from __future__ import annotations

import sys
from pathlib import Path

from pnlviz.commands.common import add_output_options, print_skipped


def add_validate_parser(sub) -> None:
    p = sub.add_parser("validate", help="check every annotation (and optionally image) of a dataset",
                       description="Read every frame of a SoccerNet-Calibration folder or zip, report "
                                   "the problems file by file, and summarise what is there.")
    p.add_argument("--data", required=True, type=Path, help="dataset folder or zip")
    p.add_argument("--images", action="store_true", help="also decode every image")
    add_output_options(p)
    p.set_defaults(func=_run_validate)


def _run_validate(args) -> int:
    from collections import Counter

    from tqdm import tqdm

    from pnlviz.data import DataError, SplitDataset, open_dataset

    ds = open_dataset(args.data)
    classes: Counter[str] = Counter()
    problems: list[str] = []
    n_ann = n_img = 0
    for stem in tqdm(ds.stems, desc="validate", unit="frame", disable=args.no_progress or None):
        frame = ds.frame(stem)
        if frame.has_annotation:
            try:
                classes.update((ds.annotation(stem) or {}).keys())  # has_annotation: never None
                n_ann += 1
            except DataError as exc:
                problems.append(str(exc))
        if frame.has_image:
            n_img += 1
            if args.images:
                try:
                    ds.image(stem)
                except DataError as exc:
                    problems.append(str(exc))
    n_cam, camera_problems = _validate_cameras(ds)
    problems = [str(e) for e in ds.rejected] + problems + camera_problems
    if not len(ds):
        print_skipped(problems, prefix="")
        ds.require_frames()
    print(f"{args.data}: {len(ds)} frames, {n_ann} valid annotations, {n_img} images, {n_cam} valid cameras")
    for split, part in (ds.parts.items() if isinstance(ds, SplitDataset) else ()):
        print(f"  split {split}: {len(part)} frames ({part.path.name}{'' if part.is_zip else '/'})")
    for name, count in sorted(classes.items(), key=lambda kv: -kv[1]):
        print(f"  {count:7d}  {name}")
    if problems:
        print(f"{len(problems)} problem(s), skipped:", file=sys.stderr)
        print_skipped(problems, prefix="  ")
        return 1
    return 0


def _validate_cameras(ds) -> tuple[int, list[str]]:
    """Parse every ``cameras/camera_<stem>.json``: (valid count, one line per problem)."""
    from pnlviz.data import DataError

    n_ok, problems = 0, []
    for stem in ds.camera_stems():
        try:
            ds.camera_dict(stem)
            n_ok += 1
        except DataError as exc:
            problems.append(str(exc))
        if stem not in ds:
            problems.append(str(DataError(ds.camera_source(stem), f"camera without a frame: no {stem}.jpg/.png/.json")))
    return n_ok, problems
