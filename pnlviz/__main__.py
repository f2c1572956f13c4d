"""``python -m pnlviz``: the command line (:mod:`pnlviz.commands`)."""

from pnlviz.commands import main

raise SystemExit(main())
