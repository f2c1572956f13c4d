"""The viser app (``pnlviz serve``): state without GUI in :mod:`.state`, overlays in
:mod:`.overlay`, the server and panels in :mod:`.server`."""
