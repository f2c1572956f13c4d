"""Planar homographies: applying them, and the WC14 template <-> field <-> image chain."""

from __future__ import annotations

import numpy as np


def apply_homography(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Map 2D points (N, 2) through a 3x3 homography; points mapped to infinity become NaN."""
    pts = np.asarray(pts, float).reshape(-1, 2)
    h = np.hstack([pts, np.ones((len(pts), 1))]) @ np.asarray(H, float).T
    with np.errstate(divide="ignore", invalid="ignore"):
        out = h[:, :2] / h[:, 2:]
    out[np.abs(h[:, 2]) < 1e-15] = np.nan
    return out


def normalize_homography(H: np.ndarray) -> np.ndarray:
    """Scale so that the Frobenius norm is 1 and H[2, 2] >= 0 (a canonical representative)."""
    H = np.asarray(H, float)
    H = H / np.linalg.norm(H)
    return -H if H[2, 2] < 0 else H


def field_to_image_from_template(H_template: np.ndarray, template_to_field: np.ndarray) -> np.ndarray:
    """A WC14 homography (template yards -> image) as a field-metres -> image homography."""
    return np.asarray(H_template, float) @ np.linalg.inv(template_to_field)
