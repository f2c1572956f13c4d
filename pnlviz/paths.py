"""Where pnlviz's own files are. The package's data (the pitch model, the light default
detector, a sample dataset) is installed with it and found through :mod:`importlib.resources`; in
a checkout, ``pnlviz/_assets`` and ``pnlviz/_sample`` are links to the repository's ``assets/``
and ``examples/sample/`` (one copy of each)."""

from importlib import resources
from pathlib import Path


def _package_dir(name: str) -> Path:
    """A folder installed with the package (resolved: in a checkout, the linked folder itself)."""
    return Path(str(resources.files("pnlviz").joinpath(name))).resolve()


#: The pitch model and the light default model.
ASSETS_DIR = _package_dir("_assets")
#: The bundled sample dataset (what ``pnlviz serve`` opens without ``--data``).
SAMPLE_DIR = _package_dir("_sample")
#: Repository root when pnlviz runs from a checkout (``pip install -e .``); nothing installed uses it.
REPO_ROOT = Path(__file__).resolve().parent.parent
#: The checkout's examples (the sample, pictures); not installed.
EXAMPLES_DIR = REPO_ROOT / "examples"

__all__ = ["ASSETS_DIR", "EXAMPLES_DIR", "REPO_ROOT", "SAMPLE_DIR"]
