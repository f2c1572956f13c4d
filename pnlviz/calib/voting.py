"""The parts of the heuristic vote (paper Sec. "Camera Parameters Estimation") that the frame
pipeline (:mod:`pnlviz.calib.pipeline`) uses for the camera and the homography alike: the keypoint
subsets a candidate is fitted to, the truncated quadratic every candidate is scored with on *all*
observations, and the winner (the lowest score, ``full`` on ties).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, TypeVar

import numpy as np

from pnlviz.calib.observations import Observations

#: keypoint subsets, in the order that breaks ties: ``full`` (every keypoint), ``main`` (the
#: line-line intersections of the annotation or detector), ``ground`` (keypoints with z = 0)
SUBSETS = ("full", "main", "ground")


def subset_mask(obs: Observations, subset: str, ground_only: bool = False) -> np.ndarray:
    """Keypoints (N,) of a subset; with ``ground_only`` only those on the ground plane (for a
    homography ``full`` and ``ground`` are then the same points)."""
    if subset == "full":
        mask = np.ones(obs.n_keypoints, bool)
    elif subset == "main":
        mask = obs.kp_main.copy()
    elif subset == "ground":
        mask = obs.ground.copy()
    else:
        raise ValueError(f"unknown keypoint subset {subset!r}; one of {SUBSETS}")
    return mask & obs.ground if ground_only else mask


def truncated_score(distances: np.ndarray, tau: float | np.ndarray) -> float:
    """``sum(min(d^2, tau^2))``: every observation counts, none by more than ``tau`` (one bound,
    or one per observation)."""
    return float(np.sum(np.minimum(distances * distances, tau * tau)))


class Scored(Protocol):
    subset: str
    threshold: float
    score: float


ScoredT = TypeVar("ScoredT", bound=Scored)


def best(candidates: Sequence[ScoredT]) -> ScoredT | None:
    """The lowest score (to 1e-6), then the earlier subset, then the smaller threshold."""
    if not candidates:
        return None
    rank = {s: i for i, s in enumerate(SUBSETS)}
    return min(candidates, key=lambda c: (round(c.score, 6), rank.get(c.subset, 9), c.threshold))
