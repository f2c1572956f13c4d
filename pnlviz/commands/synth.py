"""``pnlviz synth``: synthetic broadcast frames with exact ground-truth cameras and annotations."""

from __future__ import annotations

import argparse
import sys

from pnlviz.commands.common import parse_size  # one WxH parser for every command
from pnlviz.conventions import EVAL_SIZE

__all__ = ["add_synth_parser", "run_synth"]


def _int_at_least(minimum: int):
    """An argparse type: a whole number >= ``minimum``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected a number >= {minimum}, got {value}")
        return value

    return parse


_positive_int, _non_negative_int = _int_at_least(1), _int_at_least(0)


def add_synth_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``synth`` sub-command to an ``argparse`` sub-parsers object."""
    p = subparsers.add_parser(
        "synth", help="synthetic broadcast frames with exact ground-truth cameras and annotations",
        description="Render synthetic broadcast-like frames with SoccerNet line annotations and "
                    "ground-truth cameras: DIR/NNNNN.jpg, DIR/NNNNN.json, DIR/cameras/camera_NNNNN.json. "
                    "Frame i depends only on (seed, i).")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    p.add_argument("-n", "--num", dest="n", type=_positive_int, required=True, metavar="N", help="number of frames")
    p.add_argument("--seed", type=_non_negative_int, default=0, help="random seed (default 0)")
    p.add_argument("--size", type=parse_size, default=EVAL_SIZE, metavar="WxH",
                   help="image size (default 960x540); cameras and annotations stay at the 960x540 evaluation scale")
    p.add_argument("--start-index", type=_non_negative_int, default=0, metavar="I",
                   help="index (file stem) of the first frame (default 0)")
    p.add_argument("--clip", action="store_true",
                   help="one video clip of N frames instead: pan-tilt-zoom shots following play, players running, "
                        "a cut every ~60 frames; stems clip<seed>-IMG_<nnnn>, the exact camera of every frame")
    p.add_argument("--workers", type=_positive_int, default=1, metavar="K", help="worker processes (default 1)")
    p.add_argument("--force", action="store_true",
                   help="write into a non-empty folder that is not a previous synthetic output")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_synth)
    return p


def run_synth(args: argparse.Namespace) -> int:
    """Run ``pnlviz synth``; returns the process exit code."""
    from pnlviz.synth.writer import OutputFolderError, generate

    try:
        summary = generate(args.out, args.n, args.seed, size=tuple(args.size), start_index=args.start_index,
                           workers=args.workers, progress=not args.no_progress, force=args.force, clip=args.clip)
    except OutputFolderError as exc:
        print(f"pnlviz synth: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {summary.frames} frames to {summary.out_dir} in {summary.seconds:.1f} s "
          f"({summary.frames_per_second:.2f} frames/s)")
    return 0
