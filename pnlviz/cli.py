"""The ``pnlviz`` command line. Subcommands import their heavy dependencies lazily so that the
command starts fast (no torch, no viser unless a subcommand needs them)."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path


def parse_size(text: str) -> tuple[int, int]:
    """``"960x540"`` -> (960, 540), with an argparse error on anything else (every command's --size)."""
    m = re.match(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$", text)
    if not m:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 960x540, got {text!r}")
    w, h = int(m.group(1)), int(m.group(2))
    if not (16 <= w <= 16384 and 16 <= h <= 16384):
        raise argparse.ArgumentTypeError(f"image size {w}x{h} out of range (16..16384 per side)")
    return w, h


def print_skipped(lines, prefix: str = "skipped: ") -> None:
    """Print problems to stderr, one line each (DataErrors or strings)."""
    for line in lines:
        print(f"{prefix}{line}", file=sys.stderr)


def open_input_dataset(path):
    """Open the dataset of a batch command: its rejected files (bad names, duplicates) are printed,
    one line each; a dataset without any frame is a DataError (nothing to do)."""
    from pnlviz.data import open_dataset

    ds = open_dataset(path)
    print_skipped(ds.rejected)
    ds.require_frames()
    return ds


# ------------------------------------------------------------------------------------ validate
def _add_validate(sub) -> None:
    p = sub.add_parser("validate", help="check every annotation (and optionally image) of a dataset",
                       description="Read every frame of a SoccerNet-Calibration folder or zip, report "
                                   "the problems file by file, and summarise what is there.")
    p.add_argument("--data", required=True, type=Path, help="dataset folder or zip")
    p.add_argument("--images", action="store_true", help="also decode every image")
    p.set_defaults(func=_run_validate)


def _run_validate(args) -> int:
    from collections import Counter

    from tqdm import tqdm

    from pnlviz.data import DataError, open_dataset

    ds = open_dataset(args.data)
    classes: Counter[str] = Counter()
    problems: list[str] = []
    n_ann = n_img = 0
    for stem in tqdm(ds.stems, desc="validate", unit="frame", disable=None):
        frame = ds.frame(stem)
        if frame.has_annotation:
            try:
                classes.update(ds.annotation(stem).keys())
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


# ------------------------------------------------------------------------------------- sheet
def _add_sheet(sub) -> None:
    p = sub.add_parser("sheet", help="contact sheet of frames with annotations and the camera's pitch",
                       description="Draw the first N frames of a dataset with their annotated lines and, "
                                   "when a camera is known, the pitch model reprojected through it.")
    p.add_argument("--data", required=True, type=Path, help="dataset folder or zip")
    p.add_argument("--out", required=True, type=Path, help="output image (.png or .jpg)")
    p.add_argument("--cameras", type=Path, help="camera zip (default: the dataset's cameras/ folder)")
    p.add_argument("-n", type=int, default=12, help="number of frames (default 12)")
    p.add_argument("--columns", type=int, default=4)
    p.add_argument("--tile-width", type=int, default=480)
    p.add_argument("--no-annotation", action="store_true", help="draw only the camera's pitch")
    p.set_defaults(func=_run_sheet)


SHEET_FORMATS = (".png", ".jpg", ".jpeg")


def _run_sheet(args) -> int:
    import cv2

    from pnlviz.data import DataError, OutputError, atomic_write_bytes, check_output, read_camera_zip
    from pnlviz.geometry import Camera
    from pnlviz.viz import blank_canvas, caption, contact_sheet, draw_annotation, draw_pitch

    ext = args.out.suffix.lower()
    if ext not in SHEET_FORMATS:
        raise OutputError(f"--out {args.out}", "the sheet must be a .png or .jpg file")
    check_output(args.out, inputs=[args.cameras], datasets=[args.data])
    ds = open_input_dataset(args.data)
    cams = read_camera_zip(args.cameras, on_error=lambda e: print_skipped([e])) if args.cameras else {}
    tiles = []
    for stem in ds.stems[: args.n]:
        frame = ds.frame(stem)
        try:
            img = ds.image(stem) if frame.has_image else blank_canvas()
            cam_dict = cams.get(stem) or ds.camera_dict(stem)
            if cam_dict is not None:
                draw_pitch(img, Camera.from_soccernet(cam_dict), thickness=2)
            if frame.has_annotation and not args.no_annotation:
                draw_annotation(img, ds.annotation(stem), radius=2)
            text = stem if cam_dict is None else f"{stem}  {cam_dict.get('synth', {}).get('kind', '')}".strip()
            tiles.append(caption(img, text))
        except DataError as exc:
            print_skipped([exc])
    if not tiles:
        print("nothing to draw", file=sys.stderr)
        return 1
    sheet = contact_sheet(tiles, columns=args.columns, tile_width=args.tile_width)
    ok, encoded = cv2.imencode(ext, sheet)  # encoded here, written by Python: any file name works
    if not ok:
        print(f"{args.out}: cannot encode the sheet as {ext}", file=sys.stderr)
        return 1
    atomic_write_bytes(args.out, encoded.tobytes())
    print(f"wrote {args.out} ({len(tiles)} frames)")
    return 0


# -------------------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    from pnlviz import __version__

    parser = argparse.ArgumentParser(prog="pnlviz", description="PnLCalib soccer field registration: "
                                     "synthetic data, labels, calibration and an inspection app.")
    parser.add_argument("--version", action="version", version=f"pnlviz {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    from pnlviz.app.cli import add_export_parser, add_serve_parser
    from pnlviz.calib.cli import add_calibrate_parser
    from pnlviz.detect.cli import add_detect_parser
    from pnlviz.detect.train_cli import add_train_parser
    from pnlviz.labels.cli import add_labels_parser
    from pnlviz.metrics.cli import add_eval_parser
    from pnlviz.synth.cli import add_synth_parser

    add_serve_parser(sub)
    add_synth_parser(sub)
    add_labels_parser(sub)
    add_detect_parser(sub)
    add_train_parser(sub)
    add_calibrate_parser(sub)
    add_eval_parser(sub)
    add_export_parser(sub)
    _add_validate(sub)
    _add_sheet(sub)
    return parser


def _printable_streams() -> None:
    """File names that are not valid UTF-8 (surrogate escapes) print as ``\\udcff`` instead of
    ending the command with UnicodeEncodeError after its work is done."""
    for stream in (sys.stdout, sys.stderr):
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")


def main(argv: list[str] | None = None) -> int:
    _printable_streams()
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    from pnlviz.data.errors import DataError
    from pnlviz.data.outputs import OutputError

    try:
        return int(args.func(args) or 0)
    except OutputError as exc:  # an output over an input or inside a dataset: a usage error
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except DataError as exc:  # a bad input file: one line, no traceback
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
