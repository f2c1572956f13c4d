"""``pnlviz synth``: synthetic broadcast frames with exact ground-truth cameras and annotations."""

from __future__ import annotations

import argparse
import sys

from pnlviz.commands.common import add_output_options, int_at_least, parse_size  # one WxH parser for every command
from pnlviz.conventions import EVAL_SIZE

__all__ = ["add_synth_parser", "run_synth"]


_positive_int, _non_negative_int = int_at_least(1), int_at_least(0)


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
    add_output_options(p)
    p.set_defaults(func=run_synth)
    return p


#: Memory a rendering worker takes: a base plus bytes per pixel (measured: 115 MB at 960x540,
#: 267 MB at 1920x1080, 908 MB at 3840x2160), with a margin.
RENDER_BASE_BYTES = 120 * 2**20
RENDER_BYTES_PER_PIXEL = 130


def available_memory() -> int | None:
    """Bytes this process may still take: the smaller of the system's available memory and the
    address-space limit (None when neither is known)."""
    import resource

    found = []
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    found.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError):
        pass
    soft = resource.getrlimit(resource.RLIMIT_AS)[0]
    if soft != resource.RLIM_INFINITY:
        found.append(soft)
    return min(found) if found else None


def size_problem(size: tuple[int, int], workers: int) -> str | None:
    """Why frames of ``size`` cannot be rendered here: over the pixel cap every reader applies
    (the frames could not be read back), or more memory than there is for ``workers`` renderers."""
    from pnlviz.data.limits import MAX_IMAGE_PIXELS, format_bytes

    w, h = size
    if w * h > MAX_IMAGE_PIXELS:
        return (f"--size {w}x{h} is {w * h / 1e6:.0f} megapixels: over the {MAX_IMAGE_PIXELS / 1e6:.0f} megapixels "
                f"pnlviz reads back")
    need = (RENDER_BASE_BYTES + RENDER_BYTES_PER_PIXEL * w * h) * max(1, workers)
    have = available_memory()
    if have is not None and need > 0.8 * have:
        return (f"--size {w}x{h} with {max(1, workers)} worker(s) needs about {format_bytes(need)} of memory; "
                f"{format_bytes(have)} available")
    return None


def run_synth(args: argparse.Namespace) -> int:
    """Run ``pnlviz synth``; returns the process exit code."""
    from pnlviz.commands.batch import map_items
    from pnlviz.synth.writer import OutputFolderError, generate

    from pnlviz.data.outputs import check_writable

    check_writable(args.out, folder=True)  # OutputError: exit 2, one line
    problem = size_problem(tuple(args.size), args.workers)
    if problem:
        print(f"pnlviz synth: error: {problem}", file=sys.stderr)
        return 2
    try:
        summary = generate(args.out, args.n, args.seed, size=tuple(args.size), start_index=args.start_index,
                           progress=not args.no_progress, force=args.force, clip=args.clip,
                           run=lambda fn, jobs: map_items(fn, jobs, processes=min(args.workers, max(1, len(jobs))),
                                                          desc="synth", progress=not args.no_progress))
    except OutputFolderError as exc:
        print(f"pnlviz synth: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {summary.frames} frames to {summary.out_dir} in {summary.seconds:.1f} s "
          f"({summary.frames_per_second:.2f} frames/s)")
    return 0
