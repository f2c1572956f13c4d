"""A dataset's frames through the engine: read once for every caller (:mod:`.reader`), calibrated
and scored (:mod:`.view`), exported (:mod:`.export`). ``pnlviz calibrate``, ``pnlviz export``, its
cluster workers and the app all go through here."""

from pnlviz.pipeline.reader import FrameRead, FrameReader, Settings
from pnlviz.pipeline.view import FrameView, frame_view

__all__ = ["FrameRead", "FrameReader", "FrameView", "Settings", "frame_view"]
