"""``python -m pnlviz.cli``: the command line (:mod:`pnlviz.commands`)."""

from pnlviz.commands import main, parse_size

__all__ = ["main", "parse_size"]

if __name__ == "__main__":
    raise SystemExit(main())
