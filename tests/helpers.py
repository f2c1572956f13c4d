"""Small helpers the tests share (imported as ``from helpers import ...``: pytest puts this folder
on the path)."""

import shutil
import socket
from pathlib import Path

import pytest

#: for tests that read ../shared through module-level paths: they skip (one reason for all) without it
needs_shared = pytest.mark.usefixtures("shared_dir")


def free_port() -> int:
    """A TCP port nobody listens on right now, for a test server."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def copy_sample_frames(dst: Path, n: int) -> Path:
    """The first ``n`` images of the bundled sample (``00000.jpg`` ...) copied into a new folder
    ``dst``, as a dataset of bare frames."""
    from pnlviz import EXAMPLES_DIR

    dst.mkdir(parents=True)
    for p in sorted((EXAMPLES_DIR / "sample").glob("0*.jpg"))[:n]:
        shutil.copy(p, dst / p.name)
    return dst
