"""What every command shares: the WxH option parser, the data options of the app and export, and
how batch commands open their dataset and report the files they skip (one line each)."""

from __future__ import annotations

import argparse
import math
import os
import re
import sys


def parse_size(text: str) -> tuple[int, int]:
    """``"960x540"`` -> (960, 540), with an argparse error on anything else (every command's --size)."""
    m = re.match(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$", text)
    if not m:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 960x540, got {text!r}")
    w, h = int(m.group(1)), int(m.group(2))
    if not (16 <= w <= 16384 and 16 <= h <= 16384):
        raise argparse.ArgumentTypeError(f"image size {w}x{h} out of range (16..16384 per side)")
    return w, h


def int_at_least(minimum: int, maximum: int | None = None):
    """An argparse type: a whole number >= ``minimum`` (and <= ``maximum``)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < minimum or (maximum is not None and value > maximum):
            span = f">= {minimum}" if maximum is None else f"in {minimum}..{maximum}"
            raise argparse.ArgumentTypeError(f"expected a whole number {span}, got {value}")
        return value

    return parse


def float_in(low: float, high: float | None = None, *, open_low: bool = False):
    """An argparse type: a finite number in [``low``, ``high``] (``open_low``: above ``low``)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        below = value <= low if open_low else value < low
        if not math.isfinite(value) or below or (high is not None and value > high):
            span = (f"> {low:g}" if open_low else f">= {low:g}") if high is None else \
                f"in {'(' if open_low else '['}{low:g}, {high:g}]"
            raise argparse.ArgumentTypeError(f"expected a number {span}, got {text}")
        return value

    return parse


#: --workers: 0 for every core, else that many processes
workers_arg = int_at_least(0)


def add_output_options(p: argparse.ArgumentParser) -> None:
    """What every command takes: ``--quiet`` and ``--no-progress`` (a progress bar shows only on
    a terminal anyway: a log redirected to a file gets none)."""
    g = p.add_argument_group("output")
    g.add_argument("-q", "--quiet", action="store_true",
                   help="print nothing but warnings and errors (on stderr); no progress bar")
    g.add_argument("--no-progress", action="store_true", help="no progress bar (the default when stderr is not a terminal)")


def add_app_data_args(p) -> None:
    """The options that say what the app shows (``serve``) and exports (``export``): the dataset,
    its detections, its edits folder, and the size of frames without an image."""
    from pathlib import Path

    from pnlviz.conventions import EVAL_SIZE

    p.add_argument("--data", type=Path, help="dataset folder or zip (default: the bundled sample)")
    p.add_argument("--detections", type=Path, help="PnLCalib 2D prediction zip")
    add_detector_settings(p)
    p.add_argument("--edits", type=Path, help="edits folder (default: <data>.edits beside the data)")
    add_force_edits(p)
    p.add_argument("--size", type=parse_size, default=EVAL_SIZE, help="image size for frames without an image")


def add_detector_settings(p) -> None:
    from pathlib import Path

    p.add_argument("--detector-settings", type=Path, default=None, metavar="FILE",
                   help="the detector's settings (pnlviz detect --settings FILE): the calibration settings its "
                        "detections calibrate best with apply (default: the .json beside --detections, when there is one)")


def add_force_edits(p) -> None:
    p.add_argument("--force-edits", action="store_true",
                   help="use the edits folder even where its records are of other pictures than this dataset's "
                        "(it was made for another dataset; the mismatches are listed)")


def read_edits_folder(path, ds, force: bool):
    """The edits folder ``--edits`` of a command that only reads it (``qa``, ``calibrate``): it
    must be one (:func:`pnlviz.data.edits_folder.require_edits_folder`) and of this dataset's
    pictures (:func:`~pnlviz.data.edits_folder.check_identity`), its warnings printed (a damaged
    record: one line). DataError or EditsFolderError otherwise (the command exits with 2)."""
    from pnlviz.data.edits import EditsStore
    from pnlviz.data.edits_folder import check_identity, require_edits_folder

    store = EditsStore(require_edits_folder(path), writable=False)
    check_identity(store, ds, force=force)
    print_skipped(store.warnings, prefix="warning: ")
    return store


def app_data(args):
    """``(data, edits)`` of ``serve`` and ``export``: ``--data`` and ``--edits``, or without
    ``--data`` the bundled sample, whose edits go beside it in a checkout and, installed (where
    the sample sits inside the package), in the user's state folder
    (``$XDG_STATE_HOME/pnlviz/sample.edits``, by default ``~/.local/state/pnlviz/sample.edits``)."""
    import os
    from pathlib import Path

    from pnlviz.paths import EXAMPLES_DIR, SAMPLE_DIR

    if args.data is not None:
        return args.data, args.edits
    edits = args.edits
    if edits is None and SAMPLE_DIR != (EXAMPLES_DIR / "sample").resolve():
        state = Path(os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state")
        edits = state / "pnlviz" / "sample.edits"
        edits.parent.mkdir(parents=True, exist_ok=True)
    return SAMPLE_DIR, edits


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


def os_error_line(exc: OSError) -> str:
    """``OSError`` as one line naming the path: ``"out/x.zip: No space left on device"``."""
    from pnlviz.data.errors import DataError
    from pnlviz.data.filekind import os_error_text

    name = exc.filename if exc.filename is not None else "<output>"
    text = os_error_text(exc) if exc.errno is not None else (str(exc) or type(exc).__name__)
    return str(DataError(os.fsdecode(name) if isinstance(name, bytes) else str(name), text))

