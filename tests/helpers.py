"""Small helpers the tests share (imported as ``from helpers import ...``: pytest puts this folder
on the path)."""

import contextlib
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


def sn22_first(shared: Path, dst: Path, n: int) -> Path:
    """A zip ``dst`` of the first ``n`` SN22 annotations of ``shared/data/sn22_test_subset`` (same
    member names and bytes): for the batch tests that need a run of some length, not all 400."""
    import zipfile

    with zipfile.ZipFile(shared / "data" / "sn22_test_subset" / "annotations.zip") as src, \
            zipfile.ZipFile(dst, "w") as out:
        for name in sorted(m for m in src.namelist() if m.endswith(".json"))[:n]:
            out.writestr(name, src.read(name))
    return dst


@contextlib.contextmanager
def running_app(data, host: str = "127.0.0.1", **state_options):
    """The app serving ``data`` on a free port (``state_options``: those of ``AppState``, e.g.
    ``edits=`` or ``detections=``); stopped, and its state closed, on leaving."""
    from pnlviz.app.server import PnlvizApp
    from pnlviz.app.state import AppState

    app = PnlvizApp(AppState(data, **state_options), host=host, port=free_port())
    try:
        yield app
    finally:
        app.stop()
        app.state.close()


def copy_sample_set(dst: Path, stems) -> Path:
    """Frames ``stems`` of the bundled sample with their annotations and known cameras, copied into
    a new dataset folder ``dst``."""
    from pnlviz import EXAMPLES_DIR

    src = EXAMPLES_DIR / "sample"
    (dst / "cameras").mkdir(parents=True)
    for stem in stems:
        for name in (f"{stem}.jpg", f"{stem}.json", f"cameras/camera_{stem}.json"):
            shutil.copy(src / name, dst / name)
    return dst
