"""The export button's download: the labels export (:mod:`pnlviz.pipeline.export`) as the bytes of
a zip, read from the data and the edits folder as ``pnlviz export`` reads them (never from what the
server holds in memory), so the button and the command write the same label files."""

from __future__ import annotations

import io
import zipfile

from pnlviz.app.state import AppState
from pnlviz.data.zipwriter import member_info
from pnlviz.pipeline import FrameReader
from pnlviz.pipeline.export import export_files


def export_zip_bytes(state: AppState, include_all: bool = False) -> bytes:
    """The export of the state's dataset and edits folder as a zip (members in name order, as
    every zip pnlviz writes: the same labels give the same bytes), as ``pnlviz export`` with the
    server's ``--data``, ``--detections``, ``--detector-settings``, ``--edits`` and ``--size``
    writes it."""
    with FrameReader.open(state.data, detections=state.detections_path, edits=state.edits.root,
                          size=state.size, force_edits=state.force_edits,
                          settings_file=state.detector_settings_path) as reader:
        files = export_files(reader, include_all)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in sorted(files.items()):
            zf.writestr(member_info(name), data)
    return buf.getvalue()
