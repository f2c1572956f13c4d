"""What a calibration is fitted to: keypoints with known world positions, and points observed on
the pitch's straight lines and circles. Pixels of the frame as stored (or of the evaluation size).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pnlviz.field.model import FieldModel, load_field_model


@dataclass
class Observations:
    """Inputs of a calibration.

    * ``kp_ids`` (N,), ``kp_xy`` (N, 2) pixels, ``kp_xyz`` (N, 3) world metres, ``kp_sets`` (N,)
      the keypoint set each came from (``Kp``, ``Kpe``, ``Kp1``, ``Kp2``, ``Kp3``), ``kp_main``
      (N,) True for line-line intersections of the original annotation (the paper's
      'main-keypoints' subset).
    * ``lines``: straight class -> (M, 2) pixels on that line (annotated points or detected
      extremities); ``circles``: circle class -> (M, 2) pixels on it.
    * ``kp_pinned`` (N,) True for keypoints a hand placed or moved (pinned: the camera is fitted
      to them above the others and never drops them; see :mod:`pnlviz.calib.pins`). Empty means
      none.
    * ``kp_derived`` (N,) True for keypoints computed from this frame's own line and circle
      observations (the keypoint labels of an annotation, the intersections of detected lines):
      they repeat what those observations say, so the final refinement leaves them out where the
      lines and circles alone determine the camera (``CalibParams.lines_alone_classes``). Empty
      means none (detected and hand-placed keypoints are measurements of their own).

    Shapes are checked when made: a keypoint array of another length than ``kp_ids`` (a pin mask
    of the wrong length would silently mean "no pins") is a ValueError naming it.
    """

    width: int
    height: int
    kp_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    kp_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    kp_xyz: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    kp_sets: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype="<U3"))
    kp_main: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    lines: dict[str, np.ndarray] = field(default_factory=dict)
    circles: dict[str, np.ndarray] = field(default_factory=dict)
    kp_pinned: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    kp_derived: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    def __post_init__(self) -> None:
        n = len(np.asarray(self.kp_ids))
        shapes = {"kp_xy": (n, 2), "kp_xyz": (n, 3), "kp_sets": (n,), "kp_main": (n,)}
        for name, shape in shapes.items():
            got = np.shape(getattr(self, name))
            if got != shape and not (n == 0 and np.size(getattr(self, name)) == 0):
                raise ValueError(f"Observations.{name}: expected shape {shape} for {n} keypoints, got {got}")
        for name in ("kp_pinned", "kp_derived"):
            got = np.shape(getattr(self, name))
            if got not in ((n,), (0,)):
                raise ValueError(f"Observations.{name}: expected ({n},) or empty, got {got}")

    @classmethod
    def from_keypoints(cls, width: int, height: int, keypoints: dict[int, tuple[float, float]],
                       sets: dict[int, str] | None = None, *, lines=None, circles=None,
                       pnlcalib_positions: bool = False, model: FieldModel | None = None) -> "Observations":
        """From ``{id: (x_px, y_px)}``; world positions from the catalogue (``pnlcalib_positions``
        for detections of PnLCalib's published networks: id 52 at x = 9.0)."""
        model = model or load_field_model()
        ids = np.array(sorted(keypoints), dtype=int)
        xy = np.array([keypoints[i][:2] for i in ids], float).reshape(-1, 2)
        groups = np.array([(sets or {}).get(int(i), model.keypoints[int(i)].group) for i in ids], dtype="<U3")
        main = np.array([model.keypoints[int(i)].group == "Kp" and g == "Kp" for i, g in zip(ids, groups)], bool)
        return cls(width, height, ids, xy, model.keypoint_xyz(ids, pnlcalib=pnlcalib_positions), groups, main,
                   dict(lines or {}), dict(circles or {}))

    @property
    def n_keypoints(self) -> int:
        return len(self.kp_ids)

    @property
    def ground(self) -> np.ndarray:
        """Mask of keypoints on the ground plane (z = 0)."""
        return np.abs(self.kp_xyz[:, 2]) < 1e-9

    @property
    def pins(self) -> np.ndarray:
        """Mask (N,) of the pinned keypoints (placed or moved by hand)."""
        pinned = np.asarray(self.kp_pinned, bool)
        return pinned if pinned.shape == (self.n_keypoints,) else np.zeros(self.n_keypoints, bool)

    @property
    def derived(self) -> np.ndarray:
        """Mask (N,) of the keypoints computed from this frame's lines and circles (never a pinned one)."""
        derived = np.asarray(self.kp_derived, bool)
        return (derived & ~self.pins) if derived.shape == (self.n_keypoints,) else np.zeros(self.n_keypoints, bool)

    def subset(self, mask: np.ndarray) -> "Observations":
        """The same observations with only the keypoints in ``mask``."""
        return Observations(self.width, self.height, self.kp_ids[mask], self.kp_xy[mask], self.kp_xyz[mask],
                            self.kp_sets[mask], self.kp_main[mask], self.lines, self.circles, self.pins[mask],
                            self.derived[mask])
