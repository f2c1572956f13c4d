"""A ground homography brought onto the paint of its own image: cleaner labels for real frames.

The WC14 ground-truth homographies are a few pixels off the painted lines (on the one
full-resolution training frame, the near box line 6 px at 1280x720: ``docs/detector.md``), and a
detector trained on them learns that. :func:`fit_to_paint` moves a homography (field metres ->
pixels of ``image``) so that the pitch's straight ground lines run along the middle of their
paint, measured in the image itself:

1. *Paint strength*: the grey image minus its median over a window a little wider than a line
   (white paint on grass stands out, wide bright areas do not).
2. *Offsets*: every half metre along each straight ground line in view, the strength is sampled
   across the line (+-4 px, quarter-pixel steps); where it peaks at ``min_contrast`` or more and
   falls below half the peak on both sides (a line, not the edge of a board or a shadow), the
   weighted centre of its top half is the paint's offset from the line.
3. *Update*: a small homography applied in image space, ``H' = C^-1 (I + E) C H`` (``C`` maps the
   image to [-1, 1]), fitted to the offsets by Gauss-Newton with a Huber loss (a player on a
   line, a shadow), and damped: a 5x5 grid over the image stays where it is unless the paint says
   otherwise (a direction no line in view measures keeps the homography's). Four rounds, the
   offsets measured again each round.

A homography is refused (returned unchanged, with the reason) when the paint measures too little
of it: fewer than ``min_samples`` offsets, fewer than three lines, or lines all of one direction;
and when the fitted one sits no closer to the paint than the given one.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from pnlviz.field import STRAIGHT_CLASSES, FieldModel, load_field_model

__all__ = ["PaintFit", "fit_to_paint", "paint_offsets", "paint_strength"]

PROFILE_HALF_PX = 4.0  #: how far across a line its paint is looked for (px)
HUBER_PX = 0.75  #: offsets beyond this count linearly (a player, a shadow)
DAMPING = 0.3  #: weight of the grid that keeps what no line measures (chosen on WC14 training frame 16)


@dataclass(frozen=True)
class PaintFit:
    """``H``: the homography (refined, or the given one when refused); ``before_px`` / ``after_px``:
    the median distance of the paint from the lines before and after; ``samples``, ``lines``: what
    the paint measured; ``refused``: why the given homography was kept (None when refined)."""

    H: np.ndarray
    before_px: float
    after_px: float
    samples: int
    lines: int
    refused: str | None = None

    @property
    def refined(self) -> bool:
        return self.refused is None


def paint_strength(image: np.ndarray) -> np.ndarray:
    """How much brighter than its surroundings each pixel is (float32, grey levels, >= 0)."""
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else np.asarray(image, np.uint8)
    k = max(5, int(round(min(grey.shape[:2]) / 40)) | 1)
    return np.clip(grey.astype(np.float32) - cv2.medianBlur(grey, k).astype(np.float32), 0, None)


def _ground_lines(model: FieldModel) -> list[str]:
    return [n for n in STRAIGHT_CLASSES if model.lines[n].plane == "ground"]


def paint_offsets(H: np.ndarray, strength: np.ndarray, model: FieldModel | None = None, min_contrast: float = 12.0,
                  half: float = PROFILE_HALF_PX) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Where the paint is across each straight ground line drawn by ``H`` (field metres ->
    pixels), looked for within ``half`` px: ``(points (N, 2), unit normals (N, 2), offsets (N,)
    along the normals, line index (N,))``."""
    model = model or load_field_model()
    h, w = strength.shape
    t = np.arange(-half, half + 1e-9, 0.25)
    pts, normals, offsets, which = [], [], [], []
    for i, name in enumerate(_ground_lines(model)):
        seg = model.lines[name]
        X = seg.start[:2] + np.linspace(0.0, 1.0, max(2, int(seg.length / 0.5)))[:, None] * (seg.end[:2] - seg.start[:2])
        q = np.c_[X, np.ones(len(X))] @ H.T
        if np.any(q[:, 2] <= 0):  # a line reaching behind the camera: its far part is no line in the image
            q = q[q[:, 2] > 0]
            if len(q) < 2:
                continue
        uv = q[:, :2] / q[:, 2:]
        d = np.gradient(uv, axis=0)
        n = np.stack([-d[:, 1], d[:, 0]], 1)
        n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
        inside = (uv[:, 0] > half + 1) & (uv[:, 0] < w - half - 2) & (uv[:, 1] > half + 1) & (uv[:, 1] < h - half - 2)
        if not inside.any():
            continue
        # every profile across the line sampled in one call: row k is the profile at point k
        s = uv[inside][:, None] + t[None, :, None] * n[inside][:, None]
        profiles = cv2.remap(strength, s[..., 0].astype(np.float32), s[..., 1].astype(np.float32), cv2.INTER_LINEAR)
        for p, nv, prof in zip(uv[inside], n[inside], profiles):
            peak = prof.max()
            if peak < min_contrast or prof[0] > 0.5 * peak or prof[-1] > 0.5 * peak:
                continue  # no paint, or the edge of something wide (a board, a shadow): not a line
            top = np.where(prof > 0.5 * peak, prof, 0.0)
            pts.append(p)
            normals.append(nv)
            offsets.append(float((top * t).sum() / top.sum()))
            which.append(i)
    return (np.array(pts).reshape(-1, 2), np.array(normals).reshape(-1, 2), np.array(offsets), np.array(which, int))


def _jacobian(q: np.ndarray, w: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """d(pixel)/dE at normalised points ``q`` (N, 2), E's 8 entries row by row (E[2, 2] = 0)."""
    x, y, one, zero = q[:, 0], q[:, 1], np.ones(len(q)), np.zeros(len(q))
    jx = np.stack([x, y, one, zero, zero, zero, -x * x, -x * y], 1) * (w / 2.0)
    jy = np.stack([zero, zero, zero, x, y, one, -x * y, -y * y], 1) * (h / 2.0)
    return jx, jy


def fit_to_paint(H: np.ndarray, image: np.ndarray, model: FieldModel | None = None, *, rounds: int = 4,
                 min_samples: int = 40) -> PaintFit:
    """``H`` (field metres -> pixels of ``image``, BGR or grey) fitted to the image's paint (see
    the module docstring)."""
    model = model or load_field_model()
    H = np.asarray(H, float)
    strength = paint_strength(image)
    h, w = strength.shape
    C = np.array([[2.0 / w, 0.0, -1.0], [0.0, 2.0 / h, -1.0], [0.0, 0.0, 1.0]])
    g = np.stack(np.meshgrid(np.linspace(-1, 1, 5), np.linspace(-1, 1, 5)), -1).reshape(-1, 2)
    gx, gy = _jacobian(g, w, h)
    damp = np.vstack([gx, gy]) * DAMPING
    P, N, D, L = paint_offsets(H, strength, model)
    first = len(D)
    before = float(np.median(np.abs(D))) if len(D) else float("nan")
    out = H.copy()
    for k in range(rounds):
        if k:  # measured again where the last round put the lines
            P, N, D, L = paint_offsets(out, strength, model)
        why = _too_little(N, L, min_samples)
        if why:
            return PaintFit(H, before, before, len(D), len(set(L.tolist())), why)
        jx, jy = _jacobian((np.c_[P, np.ones(len(P))] @ C.T)[:, :2], w, h)
        A = N[:, :1] * jx + N[:, 1:] * jy
        weights = np.ones(len(D))
        for _ in range(5):  # Huber by reweighting
            sw = np.sqrt(weights)
            e = np.linalg.lstsq(np.vstack([A * sw[:, None], damp]), np.r_[D * sw, np.zeros(len(damp))], rcond=None)[0]
            r = np.abs(A @ e - D)
            weights = np.where(r < HUBER_PX, 1.0, HUBER_PX / np.maximum(r, 1e-12))
        E = np.eye(3) + np.array([[e[0], e[1], e[2]], [e[3], e[4], e[5]], [e[6], e[7], 0.0]])
        out = np.linalg.inv(C) @ E @ C @ out
    _, _, last, L = paint_offsets(out, strength, model)
    after = float(np.median(np.abs(last))) if len(last) else float("nan")
    if not after < before:
        return PaintFit(H, before, before, first, len(set(L.tolist())), "no closer to the paint")
    return PaintFit(out / out[2, 2], before, after, len(last), len(set(L.tolist())))


def _too_little(N: np.ndarray, L: np.ndarray, min_samples: int) -> str | None:
    if len(N) < min_samples:
        return f"the paint measures {len(N)} points (< {min_samples})"
    if len(set(L.tolist())) < 3:
        return f"the paint measures {len(set(L.tolist()))} lines (< 3)"
    angles = np.degrees(np.arctan2(N[:, 1], N[:, 0])) % 180.0
    spread = min(np.ptp(angles), np.ptp((angles + 90.0) % 180.0))
    if spread < 20.0:
        return "the lines measured all run one way"
    return None
