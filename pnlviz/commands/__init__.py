"""The ``pnlviz`` command line: one module per command, the engine's functions behind them.
Commands import their heavy dependencies lazily so that the command line starts fast (no torch,
no viser unless a command needs them)."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys

from pnlviz.commands.calibrate import add_calibrate_parser
from pnlviz.commands.common import os_error_line, parse_size
from pnlviz.commands.detect import add_detect_parser
from pnlviz.commands.evaluate import add_eval_parser
from pnlviz.commands.labels import add_labels_parser
from pnlviz.commands.qa import add_qa_parser
from pnlviz.commands.render import add_render_parser
from pnlviz.commands.export import add_export_parser
from pnlviz.commands.serve import add_serve_parser
from pnlviz.commands.sheet import add_sheet_parser
from pnlviz.commands.synth import add_synth_parser
from pnlviz.commands.train import add_train_parser
from pnlviz.commands.validate import add_validate_parser

__all__ = ["build_parser", "main", "parse_size"]


def build_parser() -> argparse.ArgumentParser:
    from pnlviz import __version__

    parser = argparse.ArgumentParser(prog="pnlviz", description="PnLCalib soccer field registration: "
                                     "synthetic data, labels, calibration and an inspection app.")
    parser.add_argument("--version", action="version", version=f"pnlviz {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    add_serve_parser(sub)
    add_synth_parser(sub)
    add_labels_parser(sub)
    add_detect_parser(sub)
    add_train_parser(sub)
    add_calibrate_parser(sub)
    add_qa_parser(sub)
    add_eval_parser(sub)
    add_export_parser(sub)
    add_validate_parser(sub)
    add_sheet_parser(sub)
    add_render_parser(sub)
    return parser


def _printable_streams() -> None:
    """File names that are not valid UTF-8 (surrogate escapes) print as ``\\udcff`` instead of
    ending the command with UnicodeEncodeError after its work is done."""
    for stream in (sys.stdout, sys.stderr):
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")


class _Escaped:
    """A text stream whose writes show terminal control characters escaped (file names printed
    by any command cannot drive the terminal); everything else is the wrapped stream's."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        from pnlviz.data.errors import escape_controls

        return self._stream.write(escape_controls(text))

    def __getattr__(self, name):
        return getattr(self._stream, name)


def main(argv: list[str] | None = None) -> int:
    _printable_streams()
    saved = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = _Escaped(sys.stdout), _Escaped(sys.stderr)
    try:
        return _main(argv)
    finally:
        sys.stdout, sys.stderr = saved


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    from pnlviz.data.edits import EditsFolderError
    from pnlviz.data.errors import DataError
    from pnlviz.data.outputs import OutputError

    if args.quiet or not _is_terminal(sys.stderr):
        args.no_progress = True
    quiet = open(os.devnull, "w") if args.quiet else None
    try:
        with contextlib.redirect_stdout(quiet) if quiet is not None else contextlib.nullcontext():
            return int(args.func(args) or 0)
    except (OutputError, EditsFolderError) as exc:  # an output over an input, another dataset's edits: usage errors
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except DataError as exc:  # a bad input file: one line, no traceback
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except OSError as exc:  # a write failure (read-only, full disk, permission) or an unreadable path
        print(f"error: {os_error_line(exc)}", file=sys.stderr)
        return 1
    finally:
        if quiet is not None:
            quiet.close()


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False

