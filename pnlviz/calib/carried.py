"""The hand's points of a clip carried through its shot (:class:`pnlviz.calib.clip.ClipSolver`'s
``shot`` labels): a keypoint placed by hand on one frame is drawn and labelled on the frames
before and after it through their cameras while it stays in view. Pure (numpy)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from pnlviz.field.model import FieldModel
from pnlviz.geometry.camera import MIN_DEPTH, Camera

__all__ = ["carried_points"]


def _in_view(cams: Sequence[Camera], X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points ``X`` (K, 3) projected by each camera of ``cams`` at once: their pixels (n, K, 2) and
    whether each is in each image (in front, inside, and not folded back in by the lens far
    outside the view)."""
    R, C = np.array([c.R for c in cams]), np.array([c.C for c in cams])
    f = np.array([(c.fx, c.fy) for c in cams])[:, None]
    centre = np.array([(c.cx, c.cy) for c in cams])[:, None]
    size = np.array([(c.width, c.height) for c in cams])[:, None]
    Xc = np.einsum("nij,nkj->nki", R, X[None] - C[:, None])
    z = Xc[..., 2]
    lenses: dict[tuple, list[int]] = {}
    for i, c in enumerate(cams):
        lenses.setdefault((*c.radial, *c.tangential, *c.thin_prism), []).append(i)
    with np.errstate(all="ignore"):  # the points behind are computed too, then left out
        flat = Xc[..., :2] / z[..., None]
        xd = np.empty_like(flat)
        for idx in lenses.values():  # one lens: one call
            xd[idx] = cams[idx[0]].distort(flat[idx].reshape(-1, 2)).reshape(len(idx), -1, 2)
        uv = xd * f + centre
        ok = ((z > MIN_DEPTH) & np.all((uv >= 0) & (uv < size), axis=-1)
              & np.all(np.abs(flat * f) < size, axis=-1))
    return uv, ok


def carried_points(shot: range, edits: Mapping[int, Mapping[str, Sequence[float] | None]],
                   cameras: Sequence[Camera | None],
                   model: FieldModel) -> dict[int, dict[int, np.ndarray]]:
    """``{frame: {id: (x, y)}}``: every keypoint placed by hand on a frame of ``shot`` carried to
    the frames before and after it through their cameras (``cameras[t]`` for frame t of the clip)
    while it stays in view; it stops where it leaves the image, where it is hidden or placed by
    hand again, at the shot's ends. The nearest placement wins where two reach a frame."""
    placed = [(u, int(key)) for u in shot for key, value in (edits.get(u) or {}).items() if value is not None]
    seen = [(t, cam) for t in shot if (cam := cameras[t]) is not None]
    if not placed or not seen:
        return {}
    frames = [t for t, _ in seen]
    kids = sorted({kid for _, kid in placed})
    uv, ok = _in_view([cam for _, cam in seen], model.keypoint_xyz(np.array(kids)))
    at = {t: i for i, t in enumerate(frames)}
    column = {kid: j for j, kid in enumerate(kids)}
    out: dict[int, dict[int, np.ndarray]] = {}
    dist: dict[tuple[int, int], int] = {}
    for u, kid in placed:
        j = column[kid]
        for step in (-1, 1):
            t = u + step
            while t in shot and str(kid) not in (edits.get(t) or {}):
                i = at.get(t)
                if i is None or not ok[i, j]:  # no camera, or out of its view
                    break
                if dist.get((t, kid), 1 << 30) > abs(t - u):
                    out.setdefault(t, {})[kid] = uv[i, j]
                    dist[(t, kid)] = abs(t - u)
                t += step
    return out
