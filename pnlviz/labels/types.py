"""Dataclasses of :mod:`pnlviz.labels`: parameters, keypoint labels and line extremities, and
the label a reviewed or exported frame carries (:class:`Label`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: The keypoint sets of the paper, in the order they are computed.
SETS: tuple[str, ...] = ("Kp", "Kpe", "Kp1", "Kp2", "Kp3")


@dataclass(frozen=True)
class Label:
    """One keypoint label of a reviewed or exported frame, whoever made it (a frame's own review,
    a clip's shot model, an export): pixels of the frame, its set, where it came from (one of
    :data:`pnlviz.conventions.PROVENANCES`), its distance (px) to the frame's camera (None
    without a camera). (:class:`KeypointLabel` is the other kind: a label *generated* from a line
    annotation to train the detector.)"""

    x: float
    y: float
    set: str
    provenance: str
    residual: float | None


@dataclass(frozen=True)
class LabelParams:
    """Tolerances of keypoint-label generation.

    Distances are fractions of the image (so the same parameters work at 960x540 and at
    1920x1080): ``*_diag`` ones of the image diagonal (1101 px at 960x540), ``kp_margin`` of the
    width / height. The defaults were tuned on synthetic frames and the SN22 test subset.
    """

    #: Kp (line-line) points are kept inside the image and up to this far beyond its border.
    kp_margin: float = 0.02
    #: A Kp point must lie near an end of at least one of its two annotated segments: within
    #: max(``kp_end_tol_diag`` x diagonal, ``kp_end_tol_length`` x segment length) of it.
    kp_end_tol_diag: float = 0.03
    kp_end_tol_length: float = 0.15
    #: Kpe (extended lines) points are kept up to this share of the image size beyond it (paper: 50 %).
    kpe_beyond: float = 0.5
    #: Straight classes whose points span less than this are not used (their direction is noise).
    min_line_length_diag: float = 0.01
    #: A Kp / Kpe intersection is kept only if 1 px of annotation noise moves it by at most this
    #: many pixels (first-order estimate, see ``intersection_noise_gain``): rejects nearly parallel
    #: lines and far extrapolations of short segments.
    max_noise_gain: float = 8.0
    #: The same for homography-completed points (Kp3), estimated on the homography fit
    #: (``homography_noise_gain``); its inputs are themselves noisy, so the bound is tighter.
    max_kp3_noise_gain: float = 3.0
    #: Ellipse fit: at least this many points, spanning at least ``min_conic_extent_diag`` (the
    #: diagonal of their bounding box), with an RMS geometric residual below
    #: ``max_conic_residual_diag``.
    min_conic_points: int = 5
    min_conic_extent_diag: float = 0.03
    max_conic_residual_diag: float = 0.004
    #: Kp1 / Kp2 candidates that 1 px of noise on the circle's points moves by more than this
    #: (finite differences on the ellipse fit, ``conic_candidates_gain``) are not used.
    max_conic_noise_gain: float = 4.0
    #: Kp1 / Kp2 candidates farther than this from every annotated point of their circle are
    #: extrapolations of the ellipse too far from the data and are dropped.
    max_conic_gap_diag: float = 0.08
    #: Validation (paper: "a reprojection error threshold"): ground keypoints farther than this
    #: from the projection of their world point by the final homography are rejected.
    max_reproj_error_diag: float = 0.01
    #: The cross-product orientation check (paper) on triples of ground keypoints.
    orientation_check: bool = True
    #: Fewest ground keypoints behind the homography used for Kp3 completion.
    min_points_kp3: int = 4
    #: Also complete, through the homography, every catalogue ground point (ids 1-73, not just the
    #: 13 Kp3 points) that the annotation did not give (paper: "other points initially missing").
    #: Those labels carry ``set = "Kp3"``.
    kp3_all: bool = False
    #: Left-right disambiguation (paper Sec. III-A): mirror the annotation when the view looks
    #: along the long axis towards -x, so that the goal area nearest to the camera is the left one.
    #: See :mod:`pnlviz.labels.leftright`. Off for exported labels; on for training targets.
    lr_disambiguation: bool = False
    #: Use PnLCalib's table positions (id 52 at x = +9.0) for homography-completed points, as its
    #: published networks learned them. Default: the true geometry.
    pnlcalib_positions: bool = False
    #: Cap on the set-wise grid search over Kp1/Kp2 candidate assignments.
    max_grid_combinations: int = 4096


@dataclass(frozen=True)
class KeypointLabel:
    id: int
    x: float  # pixels of the frame as stored
    y: float
    visible: bool  # inside the image: 0 <= x <= W - 1 and 0 <= y <= H - 1
    set: str  # "Kp", "Kpe", "Kp1", "Kp2" or "Kp3" (homography-completed)

    @property
    def xy(self) -> np.ndarray:
        return np.array([self.x, self.y])


@dataclass(frozen=True)
class RejectedKeypoint:
    id: int | None  # None for a candidate that matched no catalogue point
    set: str
    x: float
    y: float
    reason: str


@dataclass
class KeypointLabels:
    """Keypoint labels of one frame (pixels) with what it took to get them."""

    width: int
    height: int
    keypoints: dict[int, KeypointLabel] = field(default_factory=dict)
    #: world ground (X, Y, 1) in metres -> pixels, the last homography of the pipeline (H, H1 or
    #: H2 in the paper's terms), or None when there were not enough points.
    homography: np.ndarray | None = None
    #: True when the left-right disambiguation mirrored the annotation.
    mirrored: bool = False
    #: pixel distance of each ground keypoint to the projection of its world point by ``homography``.
    reprojection_errors: dict[int, float] = field(default_factory=dict)
    rejected: list[RejectedKeypoint] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: the (canonical, after mirroring) classes of the annotation the labels come from.
    annotated_classes: frozenset[str] = frozenset()
    #: how Kp1/Kp2 were disambiguated: "homography", "grid", or None (not computed).
    disambiguation: str | None = None

    def __len__(self) -> int:
        return len(self.keypoints)

    def ids(self, *, visible_only: bool = False) -> list[int]:
        return sorted(k for k, v in self.keypoints.items() if v.visible or not visible_only)

    def xy(self, ids=None) -> np.ndarray:
        """(N, 2) pixels of ``ids`` (default: all labels, sorted by id)."""
        ids = self.ids() if ids is None else ids
        return np.array([self.keypoints[int(i)].xy for i in ids], dtype=float).reshape(-1, 2)

    def count_by_set(self, *, visible_only: bool = False) -> dict[str, int]:
        out = dict.fromkeys(SETS, 0)
        for kp in self.keypoints.values():
            if kp.visible or not visible_only:
                out[kp.set] += 1
        return out


@dataclass(frozen=True)
class LineExtremities:
    """The two extreme annotated points of one straight class (PnLCalib line id 1..23), pixels.

    ``p1`` / ``p2`` are ordered along the dominant image axis of the line: ``p1`` has the smaller
    x when the line is closer to horizontal (|dx| >= |dy|), the smaller y otherwise. ``points``
    holds every annotated point sorted along the line (the polyline drawn in the boundary channel).
    """

    line_id: int
    name: str
    p1: np.ndarray  # (2,)
    p2: np.ndarray  # (2,)
    points: np.ndarray  # (N, 2)
