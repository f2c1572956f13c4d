"""The image view's overlays as the page draws them: the pitch lines, residuals, points, pin boxes
and selection rings, in image pixels with their sizes in screen pixels, written as one text the
page reads (``#pnlviz-view`` ``data-draw``: :mod:`pnlviz.app.pagesync`) and draws on a 2D canvas
over viser's (``pageframes.js``).

Why the page: a change to viser's scene reaches the screen in its second render frame, and in
software WebGL each frame of the canvas costs 40-80 ms; a panel element's change is drawn by the
page at once (p50 37 / p95 68 ms against 120 / 139 ms for a scene change, measured by
``benchmarks/bench_page_paths.py``). The scene keeps only what the pointer hits (invisible).

The text: marks in drawing order (later ones over earlier ones), separated by ``|``; each is
``kind;size;width;colour;alpha;x,y,x,y,...`` with

* ``kind`` ``s``: line segments (two points each), ``width`` CSS px wide;
* ``d``: filled discs of radius ``size`` CSS px at each point;
* ``c``: circles of radius ``size`` stroked ``width`` wide;
* ``q``: squares of half side ``size`` stroked ``width`` wide;

``colour`` ``rrggbb``, ``alpha`` 0-1, and the points in image pixels (one decimal; an image spans
-0.5 .. W - 0.5). Pure: no viser, no I/O.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: the kinds of mark the page draws (see the module docstring)
KINDS = ("s", "d", "c", "q")


@dataclass(frozen=True)
class Mark:
    """One kind of mark in one colour: ``xy`` (N, 2) image pixels (segments: their two ends one
    after the other), ``size`` and ``width`` in CSS px, ``rgb`` 0-255, ``alpha`` 0-1."""

    kind: str
    xy: np.ndarray
    rgb: tuple[int, int, int]
    size: float = 0.0
    width: float = 0.0
    alpha: float = 1.0


def segment_marks(points: np.ndarray, colors: np.ndarray, width: float, alpha: float = 1.0) -> list[Mark]:
    """Line segments ``points`` (N, 2, 2) coloured ``colors`` (N, 3): one mark per colour, in the
    order the colours first appear."""
    pts = np.asarray(points, float).reshape(-1, 2, 2)
    cols = np.asarray(colors, np.uint8).reshape(-1, 3)
    return [Mark("s", pts[np.all(cols == c, axis=1)].reshape(-1, 2), _rgb(c), width=width, alpha=alpha)
            for c in _first_seen(cols)]


def disc_marks(uv: np.ndarray, colors: np.ndarray, radius: float, rim: float = 0.0,
               rim_rgb: tuple[int, int, int] = (0, 0, 0)) -> list[Mark]:
    """Discs of radius ``radius`` at ``uv`` (N, 2) coloured ``colors`` (N, 3), each on a disc of
    ``rim_rgb`` of radius ``rim`` (0: none)."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    cols = np.asarray(colors, np.uint8).reshape(-1, 3)
    if not len(uv):
        return []
    out = [Mark("d", uv, rim_rgb, size=rim)] if rim > 0 else []
    return out + [Mark("d", uv[np.all(cols == c, axis=1)], _rgb(c), size=radius) for c in _first_seen(cols)]


def draw_text(marks: Sequence[Mark]) -> str:
    """The page's text for ``marks`` (see the module docstring); points that are not finite are
    left out, and so is a mark left with none."""
    out = []
    for m in marks:
        if m.kind not in KINDS:
            raise ValueError(f"unknown mark kind {m.kind!r} (one of {', '.join(KINDS)})")
        xy = np.asarray(m.xy, float).reshape(-1, 2)
        if m.kind == "s":  # a segment goes whole or not at all
            pairs = xy.reshape(-1, 2, 2)
            xy = pairs[np.all(np.isfinite(pairs), axis=(1, 2))].reshape(-1, 2)
        else:
            xy = xy[np.all(np.isfinite(xy), axis=1)]
        if not len(xy):
            continue
        coords = ",".join(map("{:.1f}".format, xy.ravel().tolist()))  # Python floats: twice as fast
        r, g, b = (int(np.clip(c, 0, 255)) for c in m.rgb)
        out.append(f"{m.kind};{m.size:g};{m.width:g};{r:02x}{g:02x}{b:02x};{float(np.clip(m.alpha, 0, 1)):g};{coords}")
    return "|".join(out)


def _first_seen(colors: np.ndarray) -> list[np.ndarray]:
    if not len(colors):
        return []
    _, first = np.unique(colors, axis=0, return_index=True)
    return [colors[i] for i in sorted(first)]


def _rgb(c) -> tuple[int, int, int]:
    return int(c[0]), int(c[1]), int(c[2])


__all__ = ["KINDS", "Mark", "disc_marks", "draw_text", "segment_marks"]
