"""pnlviz: PnLCalib sports field registration with an interactive inspection and annotation app."""

from pathlib import Path

__version__ = "0.1.0"

#: Repository root when pnlviz runs from a checkout (``pip install -e .``).
REPO_ROOT = Path(__file__).resolve().parent.parent
ASSETS_DIR = REPO_ROOT / "assets"
EXAMPLES_DIR = REPO_ROOT / "examples"
