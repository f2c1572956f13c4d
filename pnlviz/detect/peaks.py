"""Heatmap peaks -> keypoints and line extremities (PnLCalib's network outputs -> 2D detections).

PnLCalib's networks output, at half the input resolution,

* keypoint heatmaps ``(58, h, w)``: channel ``k - 1`` is keypoint id ``k`` = 1..57, channel 57 the
  background (softmax over channels) -- :func:`extract_keypoints`;
* line heatmaps ``(24, h, w)``: channel ``k - 1`` holds two peaks at the extremities of line id
  ``k`` = 1..23, channel 23 every line body (the "boundary" channel, sigmoid) --
  :func:`extract_lines`.

Both functions take numpy arrays ``(C, h, w)`` (a torch tensor is accepted too and converted) and
return positions in *heatmap pixels*: ``x`` is the column index, ``y`` the row index, continuous
(pixel ``(c, r)`` is at ``x = c, y = r``). :func:`heatmap_to_image` maps them to image pixels and
:func:`detections_to_predictions` to a normalised :class:`~pnlviz.data.predictions.Predictions`
(PnLCalib's ``x_px = x * W``), ready for :func:`~pnlviz.data.predictions.write_predictions`.

Peak finding
------------
Max-pool non-maximum suppression: a pixel is a peak when it equals the maximum over its
``nms_kernel`` x ``nms_kernel`` neighbourhood (borders padded with -inf) and reaches the channel's
threshold (``value >= threshold``). With the torch module already imported (never imported here)
the max-pool runs in ``torch.nn.functional.max_pool2d``, otherwise in
``scipy.ndimage.maximum_filter``; both give the same mask.

Keypoints keep one peak per channel, the strongest. The global maximum of a channel is always an
NMS peak whatever the kernel (it equals the maximum of any neighbourhood containing it), so this is
computed as the channel's argmax; ``nms_kernel`` is validated but cannot change the result.

Sub-pixel refinement (``refine="log"``, the default)
----------------------------------------------------
A Newton step on the *logarithm* of the 3x3 values around the peak: with ``f = log(value)``,
central differences give the gradient ``g`` and Hessian ``H`` (including the cross term ``f_xy``)
at the window centre, and the maximum sits at ``centre - H^-1 g``. Why log: the targets the
networks are trained on (:mod:`pnlviz.labels.heatmaps`) are Gaussians, and the log of any Gaussian
(isotropic, anisotropic or rotated) is an exact quadratic, whose finite differences are exact, so
the step lands on the Gaussian's centre whatever its sub-pixel offset and sigma: the only error
left is float32 rounding (about 1e-5 heatmap px for sigma 2, see the tests). Fitting a parabola to
the raw values instead (``refine="raw"``) is biased towards the pixel centre, by up to ~0.03 px
for sigma 2 and ~0.07 px for sigma 1 (and does not extrapolate: peaks on the border row/column
keep that axis integer); ``refine="none"`` keeps the integer peak.

When ``H`` is not negative definite (a plateau, a saddle-shaped blob) the step falls back to a
separate parabola per axis, and an axis without negative curvature keeps its integer position.
At the border of the heatmap the 3x3 window is shifted inwards (for a quadratic the Newton step
from any window centre is exact), so a Gaussian centred on the last half pixel of the grid --
an image label at ``x = W - 1`` is at heatmap ``x = (W - 1) / 2 = w - 0.5`` -- is still recovered.
The refined position is clamped to within 1 px of the integer peak (a sampled concave peak's
maximum cannot be farther), which also bounds what noisy network outputs can do. Values are
floored at 1e-30 before the log. ``p`` is the heatmap value at the integer peak.

Lines
-----
:func:`extract_lines` keeps, per line channel, the two strongest NMS peaks that are at least
``min_separation`` heatmap px apart (the default 4 px = 2 sigma of the training Gaussians: two
equal Gaussians closer than 2 sigma merge into one blob, so closer peaks are the same extremity).
A channel with fewer than two such peaks gives no line: one extremity fixes no line, and
:func:`pnlviz.calib.inputs.observations_from_predictions` needs both. The two extremities are
ordered as the label generator orders them (:class:`~pnlviz.labels.types.LineExtremities`): along
the dominant image axis of the segment, the first with the smaller x when ``|dx| >= |dy|``, the
smaller y otherwise.

Coordinate mapping
------------------
The label generator draws image pixel ``(x, y)`` at heatmap ``(x, y) / downsample`` (pixel
indices scale: index 0 maps to index 0), so the inverse, the default ``convention="index"``, is
``x_img = x * s`` with ``s = image size / heatmap size`` (2 for PnLCalib's 960x540 -> 480x270).
``convention="centre"`` is the pixel-centre (area) alignment, ``x_img = (x + 0.5) * s - 0.5``,
for networks trained on targets drawn that way; the two differ by ``(s - 1) / 2`` = 0.5 image px
at s = 2. ``scale=`` overrides ``s`` (e.g. ``scale=2`` reproduces the label generator exactly for
odd image sizes, where it floors the heatmap size).
"""

from __future__ import annotations

import sys
from collections.abc import Mapping

import numpy as np

__all__ = [
    "N_KEYPOINT_IDS",
    "N_LINE_IDS",
    "detections_to_predictions",
    "extract_keypoints",
    "extract_lines",
    "extract_predictions",
    "find_peaks",
    "heatmap_to_image",
    "image_to_heatmap",
    "nms_mask",
    "refine_peaks",
]

#: Keypoint channels 0..56 are ids 1..57 (channel 57 is the background).
N_KEYPOINT_IDS = 57
#: Line channels 0..22 are line ids 1..23 (channel 23 is the boundary channel).
N_LINE_IDS = 23
#: Line extremities closer than this (heatmap px) are the same blob (2 sigma of the targets).
DEFAULT_MIN_SEPARATION = 4.0

_LOG_FLOOR = 1e-30
_REFINE_MODES = ("log", "raw", "none")
_CONVENTIONS = ("index", "centre", "center")


# ----------------------------------------------------------------------------- helpers
def _to_numpy(heatmaps) -> np.ndarray:
    """(C, h, w) float32 numpy array from a numpy array or a torch tensor (a leading batch axis
    of size 1 is dropped)."""
    if hasattr(heatmaps, "detach") and hasattr(heatmaps, "cpu"):  # torch tensor, without importing torch
        heatmaps = heatmaps.detach().cpu().float().numpy()
    a = np.asarray(heatmaps, dtype=np.float32)
    if a.ndim == 4 and a.shape[0] == 1:
        a = a[0]
    if a.ndim != 3:
        raise ValueError(f"heatmaps must be (C, h, w), got shape {a.shape}")
    return a


def _check_kernel(nms_kernel: int) -> int:
    k = int(nms_kernel)
    if k < 1 or k % 2 == 0:
        raise ValueError(f"nms_kernel must be a positive odd integer, got {nms_kernel!r}")
    return k


def _thresholds(threshold, n: int, what: str) -> np.ndarray:
    t = np.asarray(threshold, dtype=np.float64)
    if t.ndim == 0:
        return np.full(n, float(t))
    t = t.reshape(-1)
    if t.size in (n, n + 1):  # one per id, or one per channel including the last (ignored) one
        return t[:n].copy()
    raise ValueError(f"{what} threshold must be a scalar or have {n} values (one per id), got {t.size}")


def nms_mask(heatmaps, nms_kernel: int = 3) -> np.ndarray:
    """Boolean ``(C, h, w)``: pixels equal to the maximum of their ``nms_kernel`` square
    neighbourhood in their own channel (the border is padded with -inf)."""
    k = _check_kernel(nms_kernel)
    a = _to_numpy(heatmaps)
    if k == 1:
        return np.ones(a.shape, bool)
    torch = sys.modules.get("torch")
    if torch is not None and hasattr(torch, "nn"):
        with torch.no_grad():
            buf = np.ascontiguousarray(a)
            t = torch.from_numpy(buf if buf.flags.writeable else buf.copy())[None]
            pooled = torch.nn.functional.max_pool2d(t, k, stride=1, padding=k // 2)[0].numpy()
    else:
        from scipy.ndimage import maximum_filter

        pooled = maximum_filter(a, size=(1, k, k), mode="constant", cval=-np.inf)
    return a == pooled


def refine_peaks(heatmaps, channels, rows, cols, refine: str = "log") -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel ``(x, y)`` (heatmap px, float64 arrays) of the integer peaks ``(channels, rows,
    cols)`` of ``heatmaps`` (see the module docstring for the method)."""
    if refine not in _REFINE_MODES:
        raise ValueError(f"refine must be one of {_REFINE_MODES}, got {refine!r}")
    a = _to_numpy(heatmaps)
    ch = np.asarray(channels, np.int64).reshape(-1)
    r = np.asarray(rows, np.int64).reshape(-1)
    c = np.asarray(cols, np.int64).reshape(-1)
    x, y = c.astype(np.float64), r.astype(np.float64)
    _, h, w = a.shape
    if refine == "none" or len(ch) == 0 or h < 3 or w < 3:
        return x, y
    # 3x3 windows, shifted inwards at the border
    rc = np.clip(r, 1, h - 2)
    cc = np.clip(c, 1, w - 2)
    off = np.arange(-1, 2)
    patch = a[ch[:, None, None], (rc[:, None] + off)[:, :, None], (cc[:, None] + off)[:, None, :]].astype(np.float64)
    f = np.log(np.maximum(patch, _LOG_FLOOR)) if refine == "log" else patch
    gx = 0.5 * (f[:, 1, 2] - f[:, 1, 0])
    gy = 0.5 * (f[:, 2, 1] - f[:, 0, 1])
    fxx = f[:, 1, 2] - 2.0 * f[:, 1, 1] + f[:, 1, 0]
    fyy = f[:, 2, 1] - 2.0 * f[:, 1, 1] + f[:, 0, 1]
    fxy = 0.25 * (f[:, 2, 2] - f[:, 2, 0] - f[:, 0, 2] + f[:, 0, 0])
    det = fxx * fyy - fxy * fxy
    with np.errstate(divide="ignore", invalid="ignore"):
        # Newton step -H^-1 g where H is negative definite
        newton = (fxx < 0) & (det > 0)
        dx_n = -(fyy * gx - fxy * gy) / det
        dy_n = -(fxx * gy - fxy * gx) / det
        # otherwise one parabola per axis (0 where that axis is not concave)
        dx_s = np.where(fxx < 0, -gx / fxx, 0.0)
        dy_s = np.where(fyy < 0, -gy / fyy, 0.0)
    dx = np.where(newton, dx_n, dx_s)
    dy = np.where(newton, dy_n, dy_s)
    xr = cc + np.nan_to_num(dx, nan=0.0, posinf=0.0, neginf=0.0)
    yr = rc + np.nan_to_num(dy, nan=0.0, posinf=0.0, neginf=0.0)
    if refine == "raw":  # a parabola through raw values does not extrapolate: keep border axes integer
        xr = np.where(cc != c, x, xr)
        yr = np.where(rc != r, y, yr)
    return np.clip(xr, x - 1.0, x + 1.0), np.clip(yr, y - 1.0, y + 1.0)


def find_peaks(heatmaps, threshold=0.1, nms_kernel: int = 3, max_peaks: int | None = None,
               min_separation: float = 0.0) -> list[list[tuple[int, int, float]]]:
    """Per channel, the NMS peaks ``(row, col, value)`` reaching ``threshold`` (scalar or one per
    channel), strongest first, greedily keeping only peaks at least ``min_separation`` px from
    every kept one, at most ``max_peaks`` of them."""
    a = _to_numpy(heatmaps)
    thr = _thresholds(threshold, a.shape[0], "peak")
    mask = nms_mask(a, nms_kernel) & (a >= thr[:, None, None].astype(np.float32))
    out: list[list[tuple[int, int, float]]] = []
    for k in range(a.shape[0]):
        rs, cs = np.nonzero(mask[k])
        vals = a[k, rs, cs]
        order = np.argsort(-vals, kind="stable")
        kept: list[tuple[int, int, float]] = []
        for i in order:
            if max_peaks is not None and len(kept) >= max_peaks:
                break
            r, c = int(rs[i]), int(cs[i])
            if min_separation > 0 and any((r - kr) ** 2 + (c - kc) ** 2 < min_separation ** 2 for kr, kc, _ in kept):
                continue
            kept.append((r, c, float(vals[i])))
        out.append(kept)
    return out


# ----------------------------------------------------------------------------- extraction
def extract_keypoints(heatmaps, threshold=0.1, nms_kernel: int = 3, *,
                      refine: str = "log") -> dict[int, tuple[float, float, float]]:
    """``{keypoint id: (x, y, p)}`` in heatmap pixels from keypoint heatmaps ``(58, h, w)``
    (channels 0..56 = ids 1..57; channel 57, the background, is ignored; a ``(57, h, w)`` array
    works too). One peak per channel, the strongest, kept when ``p >= threshold`` (a scalar, or 57
    per-id values); sub-pixel refined (module docstring). ``p`` is the value at the integer peak."""
    _check_kernel(nms_kernel)
    a = _to_numpy(heatmaps)
    if a.shape[0] < N_KEYPOINT_IDS:
        raise ValueError(f"keypoint heatmaps need {N_KEYPOINT_IDS} (+1 background) channels, got {a.shape[0]}")
    a = a[:N_KEYPOINT_IDS]
    thr = _thresholds(threshold, N_KEYPOINT_IDS, "keypoint")
    _, h, w = a.shape
    flat = a.reshape(N_KEYPOINT_IDS, -1)
    idx = flat.argmax(axis=1)  # the channel maximum is an NMS peak for every kernel size
    p = flat[np.arange(N_KEYPOINT_IDS), idx]
    keep = np.nonzero(p >= thr)[0]
    rows, cols = np.divmod(idx[keep], w)
    x, y = refine_peaks(a, keep, rows, cols, refine)
    return {int(k) + 1: (float(xi), float(yi), float(p[k])) for k, xi, yi in zip(keep, x, y, strict=True)}


def _order_pair(x1, y1, p1, x2, y2, p2):
    """Order two extremities as LineExtremities does: by x when the segment is closer to
    horizontal (|dx| >= |dy|), by y otherwise."""
    dx, dy = x2 - x1, y2 - y1
    swap = (dx < 0) if abs(dx) >= abs(dy) else (dy < 0)
    return (x2, y2, p2, x1, y1, p1) if swap else (x1, y1, p1, x2, y2, p2)


def extract_lines(heatmaps, threshold=0.1, nms_kernel: int = 3, min_separation: float = DEFAULT_MIN_SEPARATION,
                  *, refine: str = "log") -> dict[int, tuple[float, float, float, float, float, float]]:
    """``{line id: (x1, y1, p1, x2, y2, p2)}`` in heatmap pixels from line heatmaps ``(24, h, w)``
    (channels 0..22 = line ids 1..23; channel 23, the boundary channel, is ignored). Per channel
    the two strongest NMS peaks reaching ``threshold`` (scalar or 23 per-id values) that are at
    least ``min_separation`` heatmap px apart; a channel with fewer gives no line. Sub-pixel
    refined; ordered as :class:`~pnlviz.labels.types.LineExtremities` (module docstring)."""
    a = _to_numpy(heatmaps)
    if a.shape[0] < N_LINE_IDS:
        raise ValueError(f"line heatmaps need {N_LINE_IDS} (+1 boundary) channels, got {a.shape[0]}")
    a = a[:N_LINE_IDS]
    thr = _thresholds(threshold, N_LINE_IDS, "line")
    peaks = find_peaks(a, thr, nms_kernel, max_peaks=2, min_separation=float(min_separation))
    chans, rows, cols, vals = [], [], [], []
    for k, pk in enumerate(peaks):
        if len(pk) == 2:
            for r, c, v in pk:
                chans.append(k)
                rows.append(r)
                cols.append(c)
                vals.append(v)
    x, y = refine_peaks(a, chans, rows, cols, refine)
    out = {}
    for i in range(0, len(chans), 2):
        x1, y1, p1, x2, y2, p2 = _order_pair(x[i], y[i], vals[i], x[i + 1], y[i + 1], vals[i + 1])
        out[chans[i] + 1] = (float(x1), float(y1), float(p1), float(x2), float(y2), float(p2))
    return out


# ----------------------------------------------------------------------------- coordinates
def _scales(heatmap_size, image_size, scale) -> tuple[float, float]:
    if scale is not None:
        s = np.broadcast_to(np.asarray(scale, np.float64), (2,))
        return float(s[0]), float(s[1])
    hw, hh = heatmap_size
    iw, ih = image_size
    return float(iw) / float(hw), float(ih) / float(hh)


def _convention(convention: str) -> str:
    if convention not in _CONVENTIONS:
        raise ValueError(f"convention must be 'index' or 'centre', got {convention!r}")
    return "centre" if convention == "center" else convention


def heatmap_to_image(x, y, heatmap_size, image_size, *, convention: str = "index", scale=None):
    """Heatmap pixels -> image pixels. ``heatmap_size`` and ``image_size`` are ``(width,
    height)``; ``s = image / heatmap`` per axis unless ``scale`` (scalar or ``(sx, sy)``) is given.

    * ``"index"`` (default, the inverse of :func:`pnlviz.labels.heatmap_targets`, which draws image
      pixel ``x`` at ``x / downsample``): ``x_img = x * s``;
    * ``"centre"`` (pixel centres aligned): ``x_img = (x + 0.5) * s - 0.5``.

    Scalars in, floats out; arrays in, arrays out."""
    sx, sy = _scales(heatmap_size, image_size, scale)
    xa, ya = np.asarray(x, np.float64), np.asarray(y, np.float64)
    if _convention(convention) == "index":
        xo, yo = xa * sx, ya * sy
    else:
        xo, yo = (xa + 0.5) * sx - 0.5, (ya + 0.5) * sy - 0.5
    if xo.ndim == 0 and yo.ndim == 0:
        return float(xo), float(yo)
    return xo, yo


def image_to_heatmap(x, y, heatmap_size, image_size, *, convention: str = "index", scale=None):
    """The inverse of :func:`heatmap_to_image` (same arguments)."""
    sx, sy = _scales(heatmap_size, image_size, scale)
    xa, ya = np.asarray(x, np.float64), np.asarray(y, np.float64)
    if _convention(convention) == "index":
        xo, yo = xa / sx, ya / sy
    else:
        xo, yo = (xa + 0.5) / sx - 0.5, (ya + 0.5) / sy - 0.5
    if xo.ndim == 0 and yo.ndim == 0:
        return float(xo), float(yo)
    return xo, yo


def detections_to_predictions(kp: Mapping[int, tuple], lines: Mapping[int, tuple], heatmap_size, image_size, *,
                              convention: str = "index", scale=None):
    """:class:`~pnlviz.data.predictions.Predictions` from :func:`extract_keypoints` /
    :func:`extract_lines` output (heatmap pixels): mapped to image pixels by
    :func:`heatmap_to_image`, then normalised with PnLCalib's convention ``x / W``, ``y / H``
    (``image_size = (W, H)``)."""
    from pnlviz.data.predictions import Predictions

    iw, ih = float(image_size[0]), float(image_size[1])

    def norm(x, y):
        xi, yi = heatmap_to_image(x, y, heatmap_size, image_size, convention=convention, scale=scale)
        return xi / iw, yi / ih

    keypoints = {}
    for k, (x, y, p) in kp.items():
        xn, yn = norm(x, y)
        keypoints[int(k)] = (xn, yn, float(p))
    out_lines = {}
    for k, (x1, y1, p1, x2, y2, p2) in lines.items():
        x1n, y1n = norm(x1, y1)
        x2n, y2n = norm(x2, y2)
        out_lines[int(k)] = (x1n, y1n, float(p1), x2n, y2n, float(p2))
    return Predictions(keypoints=keypoints, lines=out_lines)


def extract_predictions(kp_heatmaps, line_heatmaps, image_size, *, kp_threshold=0.1, line_threshold=0.1,
                        nms_kernel: int = 3, min_separation: float = DEFAULT_MIN_SEPARATION, refine: str = "log",
                        convention: str = "index", scale=None):
    """Both networks' heatmaps of one frame -> normalised ``Predictions`` for an image of
    ``image_size = (W, H)``; either heatmap array may be None."""
    kp, lines, size = {}, {}, None
    if kp_heatmaps is not None:
        a = _to_numpy(kp_heatmaps)
        size = (a.shape[2], a.shape[1])
        kp = extract_keypoints(a, kp_threshold, nms_kernel, refine=refine)
    if line_heatmaps is not None:
        b = _to_numpy(line_heatmaps)
        if size is not None and size != (b.shape[2], b.shape[1]):
            raise ValueError(f"keypoint and line heatmaps differ in size: {size} vs {(b.shape[2], b.shape[1])}")
        size = (b.shape[2], b.shape[1])
        lines = extract_lines(b, line_threshold, nms_kernel, min_separation, refine=refine)
    if size is None:
        from pnlviz.data.predictions import Predictions

        return Predictions()
    return detections_to_predictions(kp, lines, size, image_size, convention=convention, scale=scale)
