"""Conventions every room of pnlviz shares, defined once: sizes and defaults, and the words
(review statuses, sources, provenances, failure codes, finding kinds) as ``Literal`` types with
the tuple of their values."""

from typing import Literal, get_args

#: SoccerNet evaluates cameras at this image size (W, H); cameras are written at it, and frames
#: without an image are calibrated at it unless told otherwise
EVAL_SIZE: tuple[int, int] = (960, 540)
EVAL_WIDTH, EVAL_HEIGHT = EVAL_SIZE
#: the PnL weight of lines against points (the paper's 0.6)
DEFAULT_ALPHA = 0.6


# -- the vocabularies: every word a file, a report or the app uses for these, defined once ----------
#: a frame's review status in its edit record
ReviewStatus = Literal["accepted", "corrected", "rejected"]
REVIEW_STATES: tuple[str, ...] = get_args(ReviewStatus)
#: the review statuses whose frames export what their review recorded (their snapshot)
REVIEWED: tuple[str, ...] = ("accepted", "corrected")
#: what a frame is calibrated from (a setting)
Source = Literal["annotation", "detections", "both"]
SOURCES: tuple[str, ...] = get_args(Source)
#: where a frame's observations came from (a source, or only a hand's points)
Origin = Literal["annotation", "detections", "both", "edits"]
ORIGINS: tuple[str, ...] = get_args(Origin)
#: where a label's point came from
Provenance = Literal["annotation", "detection", "hand", "shot"]
PROVENANCES: tuple[str, ...] = get_args(Provenance)
#: why the engine gives a frame no camera ("pins": its hand-placed points alone cannot calibrate
#: it); the frame pipeline adds "no_input" (nothing to calibrate from) and "internal" (a bug), the
#: commands "bad_input" (unreadable files) and "bad_output" (a camera not written)
EngineFailure = Literal["too_few_keypoints", "degenerate", "no_inliers", "residual", "pins"]
FAILURE_CODES: tuple[str, ...] = get_args(EngineFailure)
FailureCode = Literal["too_few_keypoints", "degenerate", "no_inliers", "residual", "pins", "no_input", "internal",
                      "bad_input", "bad_output"]
#: what the label-error finder can say of a frame
FindingKind = Literal["wrong_class", "off_projection", "split_class", "missing_class", "detection_disagreement",
                      "no_camera"]
FINDING_KINDS: tuple[str, ...] = get_args(FindingKind)
