"""The calibration's settings (:class:`CalibParams`): one setting for every benchmark, each with
the figures it was chosen on. :func:`pnlviz.calib.calibrate.calibrate` takes them."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from pnlviz.calib.voting import SUBSETS
from pnlviz.conventions import DEFAULT_ALPHA, EVAL_WIDTH


@dataclass(frozen=True)
class CalibParams:
    """Calibration settings. Pixel values are for a 960 px wide image and scale with the width."""

    subsets: tuple[str, ...] = SUBSETS
    ransac_thresholds: tuple[float, ...] = (5.0, 10.0, 20.0, 40.0)
    min_points: int = 4  #: keypoints needed on one plane for a homography
    vote_tau: float = 10.0  #: truncation of the voting score, pixels
    max_rms: float = 15.0  #: a calibration whose inlier RMS (px) is above this is a failure
    min_hfov_deg: float = 1.0
    max_hfov_deg: float = 130.0
    #: a camera a broadcast can have: at least this high above the pitch (m; a camera on the grass
    #: sees every line edge-on, and a few weak detections fit one there exactly: a pitch corner or
    #: the half-way line's end as the camera's centre) ...
    min_height_m: float = 2.0
    #: ... and no farther than this from the centre mark (m): a camera kilometres away is a
    #: degenerate fit (one came 3e7 m away), not a telephoto from the far stand (about 150 m away).
    #: The development halves' cameras: 3.4-27 m high, at most 107 m away; a pin dragged 60 px
    #: against ten detections zoomed out can give a camera 300 m away that fits what is seen
    max_distance_m: float = 1000.0
    #: a shot fits a frame's detections scoring at least these (keypoint, line end): a detector's
    #: second look (weaker peaks read again for a frame its first reading leaves without a camera)
    #: serves that frame's own camera, never its shot's (:func:`pnlviz.calib.looks.for_shot`)
    shot_min_score: tuple[float, float] = (0.0, 0.0)
    pnl: bool = True  #: run the PnL refinement
    alpha: float = DEFAULT_ALPHA  #: PnL weight of lines vs points (paper: 0.6)
    line_gate_px: float = 20.0  #: a line/circle joins PnL when all its points are this close to its projection
    point_gate_px: float = 20.0  #: a keypoint joins PnL when this close to its initial projection
    #: a PnL holding at least this many line and circle classes (each fixes two of the camera's
    #: eight parameters at least) leaves out the keypoints derived from them
    #: (``Observations.kp_derived``: they repeat the lines, computed from them as straight lines
    #: under a pinhole; :func:`pnlviz.calib.pipeline.lines_alone`); 0: never. FS@5 alone: SN22
    #: from annotations 0.918 -> 0.928, WC14 from published detections 0.922 -> 0.940 (3: SN22 CR
    #: 0.990; 5: WC14 0.938)
    lines_alone_classes: int = 4
    #: after PnL, the gates are applied again at the refined camera and, when they let more classes
    #: or keypoints through, PnL runs again from there with them, up to this many times
    #: (:func:`pnlviz.calib.pipeline.pnl_refine`). Alone: SN22 0.918 -> 0.923, WC14 0.922 -> 0.922;
    #: with the one above: SN22 0.933, WC14 0.939
    regate_rounds: int = 2
    refine_focal: bool = True  #: PnL refines the focal length with the pose (the paper keeps K fixed)
    refine_k1: bool = True  #: PnL refines radial distortion k1 too (+3 JaC@5 on SN22 and WC14)
    #: a fitted k1 whose model folds part of the pitch back into the image (a lens has no such
    #: fold: :func:`pnlviz.geometry.lens.folds_into_view`) is refused, and the frame fitted again with
    #: k1 = 0. SN22 from annotations FS@5 0.936 -> 0.946 (19 of 398 cameras folded), WC14 0.943 (none)
    refuse_folding_lens: bool = True
    #: a frame whose keypoints name both halves of the pitch and give no camera together is
    #: calibrated from each half's keypoints and classes alone (:func:`pnlviz.calib.calibrate._one_half`;
    #: ``result.half``). SN22 from annotations CR 0.995 -> 0.998 (FS@5 0.946 -> 0.948), WC14 unchanged;
    #: the light model's synthetic seeds 777 / 778 CR 0.967 -> 0.983 / 0.915 -> 0.940
    #: (FS@5 0.814 -> 0.815 / 0.807 -> 0.813), its real val and test frames unchanged; on seed 779,
    #: never looked at, CR 0.940 -> 0.960, FS@5 0.802 -> 0.806
    one_half_when_both_fail: bool = True
    final_loss: str = "linear"  #: loss of PnL with intrinsics; soft_l1 and a quartic loss scored lower on SN22
    final_f_scale: float = 2.0  #: px where a robust final loss bends
    #: after PnL with intrinsics, a class with a point farther than this (px) is pulled in
    #: (:meth:`CameraProblem.tighten`; 0: off). It gave SN22 from annotations FS@5 0.901 -> 0.913,
    #: most of it frames it kept from failing the RMS verdict; since the verdict judges a fit from
    #: the lines alone by its lines, 4 px gives SN22 0.9332 against 0.9337 off, WC14 0.943 either
    #: way, at 3 ms more per SN22 frame: off
    class_tolerance_px: float = 0.0
    #: observed line points on the image border are aimed this far (px) inside while fitting
    #: (:func:`pnlviz.calib.problem.aim_inside`; 0: off; residuals are reported against the points
    #: as observed): SN22 from annotations FS@5 0.913 -> 0.918, WC14 0.918 -> 0.922
    border_aim_px: float = 2.0
    prior_search: bool = True  #: with too few keypoints for a homography, start from broadcast priors
    #: with too few keypoints for a homography, start from the straight ground lines too where
    #: they fix the plane (:mod:`pnlviz.calib.line_start`)
    line_search: bool = True
    refine_top: int = 3  #: candidates refined (focal + pose) after the first vote
    tol: float = 1e-6  #: refinements stop when the cost drops by less than this fraction
    #: Levenberg-Marquardt steps of each PnL solve: most converge in 4-12 steps from the voted camera;
    #: one on the lines alone can creep for 40-50 along a flat valley of focal length, distance and
    #: k1 for no gain (50 -> 20: SN22 FS@5 -0.0002, WC14 unchanged, the p90 time about halved)
    pnl_max_iter: int = 20
    prior_good_rms: float = 3.0  #: stop the prior search at a camera fitting everything this well (px RMS)
    pin_weight: float = 3.0  #: weight of pinned (hand-placed) keypoints in every refinement
    pin_scale_px: float = 10.0  #: px where the pins' bounded (Cauchy) loss bends
    pin_vote_px: float = 50.0  #: a pinned keypoint counts as an inlier of the vote up to this far
    pin_flag_px: float = 10.0  #: a pinned keypoint farther than this from the camera is flagged (never dropped)

    def px(self, value: float, width: float) -> float:
        return value * width / EVAL_WIDTH

    def updated(self, overrides: Mapping[str, object] | None) -> "CalibParams":
        """These settings with ``overrides`` (field name -> value) applied; unknown names are a
        ValueError naming the known ones. A detector states the settings its detections calibrate
        best with this way (the light model: no k1, a soft-L1 final loss; see
        ``assets/models/light.json``), and they travel with its predictions."""
        if not overrides:
            return self
        known = set(self.__dataclass_fields__)
        unknown = sorted(set(overrides) - known)
        if unknown:
            raise ValueError(f"unknown calibration setting(s) {unknown}; known: {sorted(known)}")
        # JSON gives lists where the fields hold tuples
        changes: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in overrides.items()}
        return replace(self, **changes)
