"""A clip under correction: hand edits drive the shot model, so a shot is corrected once, not
every frame.

:class:`ClipSolver` holds a clip in time order: each frame's own observations (detections or an
annotation), the keypoint edits made on its frames (``{"id": [x, y] | None}``, as the edits folder
stores them), each frame's own camera (its per-frame calibration, with its edits), the shots (found
as ``pnlviz calibrate --temporal`` finds them, :func:`pnlviz.calib.cuts.segment_shots`, then the
cuts a hand added or removed: :class:`CutEdits`) and one broadcast camera per shot
(:func:`pnlviz.calib.shot_fit.fit_shot`).

* **edits are constraints of the shot**: a point moved or placed on any frame is a pinned keypoint
  of its shot's solve (it weighs ``pin_weight`` times more and is never dropped, as a pin is on a
  single frame, :mod:`pnlviz.calib.pins`); a hidden point leaves the frame's observations. After
  an edit the shot is solved again from its previous solution (a warm start: a few iterations),
  and every frame of it gets its new camera;
* **labels of every frame** (:meth:`ClipSolver.labels`), each with its provenance: the frame's own
  observations (``annotation`` / ``detection``), the hand's (``hand``), and ``shot``: a keypoint
  placed by hand on one frame, carried to the neighbouring frames of its shot through their
  cameras for as long as it stays in view (until it leaves the image, is hidden, or is placed by
  hand again).

Pure (numpy / scipy, no I/O): the app, the export and the benchmark call the same.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera

from .calibrate import CalibParams, calibrate
from .cuts import segment_shots
from .observations import Observations
from .shot import ShotModel, TemporalParams, flatten
from .shot_fit import ShotFit, camera_vector, fit_shot
from .sources import apply_keypoint_edits

__all__ = ["PROVENANCE", "ClipLabel", "ClipSolver", "CutEdits", "apply_cuts", "carried_points"]

#: where a clip frame's label comes from
PROVENANCE = ("annotation", "detection", "hand", "shot")


@dataclass(frozen=True)
class CutEdits:
    """Cuts changed by hand: ``added`` frames start a shot, ``removed`` ones no longer do (a cut
    before frame t is named by t)."""

    added: frozenset[int] = frozenset()
    removed: frozenset[int] = frozenset()

    def with_cut(self, t: int, cut: bool) -> CutEdits:
        """These edits with a cut before frame ``t`` added (``cut``) or removed."""
        t = int(t)
        if cut:
            return CutEdits(self.added | {t}, self.removed - {t})
        return CutEdits(self.added - {t}, self.removed | {t})

    def to_json(self) -> dict:
        return {"added": sorted(self.added), "removed": sorted(self.removed)}

    @classmethod
    def from_json(cls, obj: Mapping | None) -> CutEdits:
        obj = obj or {}
        return cls(frozenset(int(t) for t in obj.get("added", ())), frozenset(int(t) for t in obj.get("removed", ())))


def apply_cuts(shots: Sequence[range], cuts: CutEdits, T: int) -> list[range]:
    """The shots of a clip of ``T`` frames after the hand's cuts: the found cuts without the
    removed ones, with the added ones."""
    starts = {s.start for s in shots if 0 < s.start < T}
    starts = (starts - set(cuts.removed)) | {t for t in cuts.added if 0 < t < T}
    bounds = [0, *sorted(starts), T]
    return [range(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


@dataclass(frozen=True)
class ClipLabel:
    """One keypoint label of a clip frame: pixels, its provenance (:data:`PROVENANCE`), its
    distance (px) to the frame's shot camera (None without one), its set."""

    x: float
    y: float
    provenance: str
    residual: float | None
    set: str = ""


def _in_view(cam: Camera, X: np.ndarray) -> tuple[np.ndarray, bool]:
    """``X`` (3,) projected by ``cam``, and whether it is in the image (in front, inside, and not
    folded back in by the lens far outside the view)."""
    uv, z = cam.project(X[None])
    flat, _ = cam.project(X[None], distort=False)
    ok = bool(z[0] > 0 and 0 <= uv[0, 0] < cam.width and 0 <= uv[0, 1] < cam.height
              and abs(flat[0, 0] - cam.cx) < cam.width and abs(flat[0, 1] - cam.cy) < cam.height)
    return uv[0], ok


def carried_points(shot: range, edits: Mapping[int, Mapping[str, Sequence[float] | None]],
                   cameras: Sequence[Camera | None],
                   model: FieldModel) -> dict[int, dict[int, np.ndarray]]:
    """``{frame: {id: (x, y)}}``: every keypoint placed by hand on a frame of ``shot`` carried to
    the frames before and after it through their cameras (``cameras[t]`` for frame t of the clip)
    while it stays in view; it stops where it leaves the image, where it is hidden or placed by
    hand again, at the shot's ends. The nearest placement wins where two reach a frame."""
    out: dict[int, dict[int, np.ndarray]] = {}
    dist: dict[tuple[int, int], int] = {}
    for u in shot:
        for key, value in (edits.get(u) or {}).items():
            if value is None:
                continue
            kid = int(key)
            X = model.keypoint_xyz(np.array([kid]))[0]
            for step in (-1, 1):
                t = u + step
                while t in shot and str(kid) not in (edits.get(t) or {}):
                    cam = cameras[t]
                    if cam is None:
                        break
                    uv, ok = _in_view(cam, X)
                    if not ok:
                        break
                    if dist.get((t, kid), 1 << 30) > abs(t - u):
                        out.setdefault(t, {})[kid] = uv
                        dist[(t, kid)] = abs(t - u)
                    t += step
    return out


@dataclass
class _Shot:
    frames: range
    fit: ShotFit | None = None
    seconds: float = 0.0


@dataclass
class ClipSolver:
    """A clip under correction (see the module docstring). ``observations[t]``: frame t's own
    observations without edits (None: nothing); ``size``: (W, H) of its frames; ``cameras``: the
    frames' own cameras when known (else calibrated here with ``calib_params``); ``changes``: the
    image change from each frame to the next (:func:`pnlviz.calib.temporal.image_changes`);
    ``origins[t]``: "annotation" or "detection", what frame t's own labels are called."""

    observations: Sequence[Observations | None]
    size: tuple[int, int]
    params: TemporalParams = field(default_factory=TemporalParams)
    calib_params: CalibParams = field(default_factory=CalibParams)
    cameras: Sequence[Camera | None] | None = None
    changes: Sequence[float | None] | None = None
    cuts: CutEdits = field(default_factory=CutEdits)
    origins: Sequence[str] | None = None
    model: FieldModel | None = None
    #: the keypoint edits made so far: ``{frame: {"id": [x, y] | None}}`` (``cameras``, when given,
    #: are the frames' own cameras with them)
    keypoint_edits: Mapping[int, Mapping[str, Sequence[float] | None]] | None = None

    def __post_init__(self):
        self.field_model: FieldModel = self.model or load_field_model()
        self.T = len(self.observations)
        self.base = list(self.observations)
        self.edits: dict[int, dict[str, list[float] | None]] = {}
        for t, e in (self.keypoint_edits or {}).items():
            if e:
                self.edits[int(t)] = {str(int(k)): (None if v is None else [float(v[0]), float(v[1])])
                                      for k, v in e.items()}
        self._stale: set[int] = set()  # frames whose own camera is to be recalibrated (their edits changed)
        if self.cameras is None:
            self.own = [self._own_camera(self.frame_observations(t)) for t in range(self.T)]
        else:
            self.own = list(self.cameras)
        #: the shots found (before the hand's cuts): where the images change when every change is
        #: known (a frame with few keypoints has an own camera that jumps, which is no cut), else
        #: as ``pnlviz calibrate --temporal`` finds them
        images = self.changes is not None and len(self.changes) == self.T - 1 and all(
            c is not None for c in self.changes)
        self.found = segment_shots([None] * self.T if images else self.own, self.changes, self.params)
        self._shots = [_Shot(r) for r in apply_cuts(self.found, self.cuts, self.T)]
        self._labels: list[dict[int, ClipLabel]] | None = None
        for k in range(len(self._shots)):
            self._solve(k, warm=False)

    # ------------------------------------------------------------------ what the clip is
    @property
    def shots(self) -> list[range]:
        return [s.frames for s in self._shots]

    def shot_of(self, t: int) -> int:
        """The index of frame ``t``'s shot."""
        for k, s in enumerate(self._shots):
            if t in s.frames:
                return k
        raise IndexError(f"frame {t} is not in the clip of {self.T} frames")

    def fit(self, k: int) -> ShotFit | None:
        return self._shots[k].fit

    def solve_seconds(self, k: int) -> float:
        """How long shot ``k``'s latest solve took."""
        return self._shots[k].seconds

    def camera(self, t: int) -> Camera | None:
        """Frame ``t``'s camera from its shot's model (None: the shot has no camera to start from,
        or the frame has nothing observed and no neighbour's hand point)."""
        s = self._shots[self.shot_of(t)]
        if s.fit is None or self.frame_observations(t) is None:
            return None
        return s.fit.cameras[t - s.frames.start]

    def own_camera(self, t: int) -> Camera | None:
        """Frame ``t``'s own camera: its per-frame calibration, with its edits."""
        if t in self._stale:
            self._stale.discard(t)
            self.own[t] = self._own_camera(self.frame_observations(t))
        return self.own[t]

    def cameras_of(self) -> list[Camera | None]:
        return [self.camera(t) for t in range(self.T)]

    @property
    def keyframes(self) -> list[int]:
        """The frames a hand corrected, in order."""
        return sorted(t for t, e in self.edits.items() if e)

    def frame_observations(self, t: int) -> Observations | None:
        """Frame ``t``'s observations with its edits applied (pins for the points placed by hand)."""
        obs, edits = self.base[t], self.edits.get(t)
        if not edits:
            return obs
        if obs is None:
            W, H = self.size
            obs = Observations(int(W), int(H))
        return apply_keypoint_edits(obs, edits, self.field_model)

    # ------------------------------------------------------------------ edits
    def set_edits(self, t: int, edits: Mapping[str, Sequence[float] | None] | None, solve: bool = True) -> int:
        """Frame ``t``'s keypoint edits (``{"id": [x, y] | None}``; None or empty: none): its own
        camera recalibrated, its shot solved again (warm) unless ``solve`` is off. Returns the shot."""
        if edits:
            self.edits[int(t)] = {str(int(k)): (None if v is None else [float(v[0]), float(v[1])])
                                  for k, v in edits.items()}
        else:
            self.edits.pop(int(t), None)
        self._stale.add(int(t))  # its own camera: recalibrated when asked for (it can take a second)
        k = self.shot_of(t)
        if solve:
            self._solve(k, warm=True)
        return k

    def set_keypoint(self, t: int, kid: int, xy: Sequence[float] | None, solve: bool = True) -> int:
        """Keypoint ``kid`` of frame ``t`` moved or placed at ``xy`` (pixels) or hidden (None)."""
        edits: dict[str, Sequence[float] | None] = dict(self.edits.get(t) or {})
        edits[str(int(kid))] = None if xy is None else [float(xy[0]), float(xy[1])]
        return self.set_edits(t, edits, solve)

    def set_cut(self, t: int, cut: bool) -> None:
        """A cut before frame ``t`` added (``cut``) or removed by hand; the shots it touches are
        solved again from the frames' own cameras, the others keep their solution."""
        self.cuts = self.cuts.with_cut(t, cut)
        old = {(s.frames.start, s.frames.stop): s for s in self._shots}
        self._shots = [old.get((r.start, r.stop)) or _Shot(r) for r in apply_cuts(self.found, self.cuts, self.T)]
        for k, s in enumerate(self._shots):
            if s.fit is None:
                self._solve(k, warm=False)
        self._labels = None

    def solve(self, k: int | None = None, warm: bool = True) -> None:
        """Solve shot ``k`` (every shot when None) again."""
        for j in range(len(self._shots)) if k is None else [k]:
            self._solve(j, warm)

    # ------------------------------------------------------------------ labels
    def labels(self, t: int) -> dict[int, ClipLabel]:
        """Frame ``t``'s labels with provenance (see the module docstring)."""
        if self._labels is None:
            self._labels = self._all_labels()
        return self._labels[t]

    def _all_labels(self) -> list[dict[int, ClipLabel]]:
        cams = self.cameras_of()
        carried: dict[int, dict[int, np.ndarray]] = {}
        for s in self._shots:
            carried.update(carried_points(s.frames, self.edits, cams, self.field_model))
        out = []
        for t in range(self.T):
            obs, cam = self.frame_observations(t), cams[t]
            labels: dict[int, ClipLabel] = {}
            own = (self.origins[t] if self.origins is not None else None) or "detection"
            if obs is not None and obs.n_keypoints:
                res = np.hypot(*(cam.project(obs.kp_xyz)[0] - obs.kp_xy).T) if cam is not None else None
                for i, kid in enumerate(obs.kp_ids.tolist()):
                    r = None if res is None or not np.isfinite(res[i]) else float(res[i])
                    labels[int(kid)] = ClipLabel(float(obs.kp_xy[i, 0]), float(obs.kp_xy[i, 1]),
                                                 "hand" if obs.pins[i] else own, r, str(obs.kp_sets[i]))
            for kid, uv in carried.get(t, {}).items():
                if kid not in labels:
                    labels[kid] = ClipLabel(float(uv[0]), float(uv[1]), "shot", 0.0,
                                            self.field_model.keypoints[kid].group)
            out.append(labels)
        return out

    # ------------------------------------------------------------------ internals
    def _own_camera(self, obs: Observations | None) -> Camera | None:
        if obs is None or obs.n_keypoints == 0:
            return None
        try:
            r = calibrate(obs, self.calib_params, self.field_model)
        except Exception:  # noqa: BLE001 - a frame without its own camera is placed by its shot
            return None
        return r.camera if r.ok else None

    def _start_cameras(self, frames: list[int]) -> list[Camera | None]:
        """The frames' own cameras to start a shot's solve from, without those whose centre is
        farther than ``cut_centre_m`` from the shot's median centre (a frame with few or wrong
        keypoints: its neighbours place it)."""
        own = [self.own_camera(t) for t in frames]
        known = [c.C for c in own if c is not None]
        if not known:
            return own
        centre = np.median(np.array(known), axis=0)
        return [c if c is not None and np.linalg.norm(c.C - centre) <= self.params.cut_centre_m else None for c in own]

    def frame_error(self, t: int) -> float:
        """What the app ranks frame ``t`` by: the median distance (px) of all its observations
        (keypoints and line points, the dropped ones too) to its shot camera; inf without one."""
        cam, obs = self.camera(t), self.frame_observations(t)
        if cam is None:
            return float("inf")
        if obs is None:
            return 0.0
        r_kp, r_ln = ShotModel(flatten([obs], self.field_model), 1, self.size, replace(self.params, fit_k1=True)
                               ).data_residuals(camera_vector(cam))
        r = np.concatenate([np.hypot(r_kp[:, 0], r_kp[:, 1]), np.abs(r_ln)])
        return float(np.median(r)) if len(r) else 0.0

    def _solve(self, k: int, warm: bool) -> None:
        s = self._shots[k]
        t0 = time.perf_counter()
        frames = list(s.frames)
        obs = [self.frame_observations(t) for t in frames]
        start = s.fit if warm and s.fit is not None else None
        # a warm start needs no per-frame camera (the stale ones are not recalibrated for it)
        own = self._start_cameras(frames) if start is None else [self.own[t] for t in frames]
        if start is None and all(c is None for c in own):
            s.fit = None
        else:
            s.fit = fit_shot(obs, own, self.size, self.params, self.field_model, start=start)
        s.seconds = time.perf_counter() - t0
        self._labels = None
