"""The export button's download: the app's labels export (:mod:`pnlviz.pipeline.export`) as the
bytes of a zip."""

from __future__ import annotations

import io
import zipfile

from pnlviz.app.state import AppState, Settings
from pnlviz.data.zipwriter import member_info
from pnlviz.pipeline.export import export_files


def export_zip_bytes(state: AppState, include_all: bool = False, settings: Settings | None = None) -> bytes:
    """The export of the state's frames as a zip (members in name order, as every zip pnlviz
    writes: the same labels give the same bytes); the frames' views the state has computed
    already are used as they are."""
    settings = settings or state.default_settings
    files = export_files(state.reader, include_all, settings, state.model,
                         view_of=lambda stem: state.view(stem, settings, keep=False))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in sorted(files.items()):
            zf.writestr(member_info(name), data)
    return buf.getvalue()
