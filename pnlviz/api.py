"""pnlviz's Python API: the few functions a program calls, checked at the door (an error names
the argument that is wrong), over the engine the app and the commands use.

World frame: SoccerNet's, metres, origin at the centre spot, x along the pitch (towards the
right goal), y across it (positive towards the main camera's side), z down (the crossbar is at
z = -2.44). Pixels: x to the right, y down, (0, 0) the centre of the top-left pixel.

>>> import pnlviz
>>> world = pnlviz.keypoints()
>>> world[45]  # the left penalty mark
(-41.5, 0.0, 0.0)
>>> cam = pnlviz.Camera.from_look_at((0.0, 45.0, -15.0), (0.0, 0.0, 0.0), hfov_deg=60, width=1280, height=720)
>>> pixels = {k: cam.project([xyz])[0] for k, xyz in world.items()}
>>> pixels = {k: uv for k, uv in pixels.items() if cam.in_image(uv[None])[0]}  # the keypoints in view
>>> len(pixels)
18
>>> result = pnlviz.calibrate(pixels, image_size=(1280, 720))
>>> result.ok, round(result.camera.hfov_deg, 2)
(True, 60.0)
>>> feet = result.camera.project([(10.0, 5.0, 0.0)])  # a player's feet in the image
>>> [round(float(v), 3) for v in result.camera.image_to_pitch(feet)[0]]
[10.0, 5.0]
>>> pnlviz.calibrate({99: (1.0, 2.0)}, image_size=(1280, 720))
Traceback (most recent call last):
...
pnlviz.ArgumentError: keypoints[99]: no such keypoint id (1-73: see pnlviz.keypoints())
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

import numpy as np
from numpy.typing import ArrayLike

from pnlviz.data.errors import ArgumentError
from pnlviz.geometry.camera import Camera

if TYPE_CHECKING:
    from pnlviz.data.dataset import Dataset
    from pnlviz.data.predictions import Predictions

__all__ = ["ArgumentError", "Calibration", "Camera", "ClipCalibration", "calibrate", "calibrate_clip", "detect",
           "keypoint_names", "keypoints", "open_dataset", "qa", "top_view"]


def keypoints() -> dict[int, tuple[float, float, float]]:
    """Every keypoint of PnLCalib's catalogue: ``{id: (x, y, z)}`` in the world frame (metres);
    ids 1-73 (their names: ``pnlviz.keypoint_names()``, their picture: ``docs/keypoint_map.png``).

    >>> import pnlviz
    >>> world = pnlviz.keypoints()
    >>> len(world), world[1], world[45]  # a corner, the left penalty mark
    (73, (-52.5, -34.0, 0.0), (-41.5, 0.0, 0.0))
    """
    from pnlviz.field.model import load_field_model

    model = load_field_model()
    out: dict[int, tuple[float, float, float]] = {}
    for k in model.keypoint_ids:
        x, y, z = (float(v) for v in model.keypoints[int(k)].xyz)
        out[int(k)] = (x, y, z)
    return out


def keypoint_names() -> dict[int, str]:
    """``{id: name}``: a distinct name in words for every keypoint id.

    >>> import pnlviz
    >>> names = pnlviz.keypoint_names()
    >>> len(names), names[45]
    (73, 'penalty mark left')
    """
    from pnlviz.field.model import load_field_model

    return dict(load_field_model().keypoint_names())


@dataclass(frozen=True)
class Calibration:
    """The camera of one frame and the evidence for it. ``camera``: None when the calibration
    failed, and then ``reason`` says why (``reason_code``: a short code); ``point_residuals``
    ``{id: px}`` and ``line_residuals`` ``{class: px}`` (its farthest point) under the camera;
    ``inliers``: the keypoint ids the voted camera agreed with; ``pnl_lines``: the lines and circles
    the PnL refinement used; ``lines_alone``: the keypoints derived from the lines (not given) that
    it left out, its lines and circles fixing the camera alone.

    >>> import pnlviz
    >>> lines = {"Side line top": [(0, 100), (960, 120)], "Middle line": [(470, 100), (440, 540)]}
    >>> result = pnlviz.calibrate(lines=lines, image_size=(960, 540))  # two lines: too little
    >>> result.ok, result.camera, result.reason_code
    (False, None, 'too_few_keypoints')
    """

    camera: Camera | None
    reason: str | None = None
    reason_code: str | None = None
    point_residuals: dict[int, float] = field(default_factory=dict)
    line_residuals: dict[str, float] = field(default_factory=dict)
    inliers: tuple[int, ...] = ()
    pnl_lines: tuple[str, ...] = ()
    lines_alone: tuple[int, ...] = ()

    @property
    def ok(self) -> bool:
        return self.camera is not None


def _image_size(image_size) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in image_size)
        ok = all(float(v) == int(v) for v in image_size)
    except (TypeError, ValueError, OverflowError):
        raise ArgumentError(f"image_size: expected (width, height) in pixels, got {image_size!r}") from None
    if not ok or not (16 <= w <= 16384 and 16 <= h <= 16384):
        raise ArgumentError(f"image_size: expected two whole numbers of pixels in 16..16384, got {image_size!r}")
    return w, h


def _pixel(value, where: str) -> tuple[float, float]:
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ArgumentError(f"{where}: expected a pixel (x, y), got {value!r}") from None
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ArgumentError(f"{where}: expected a finite pixel (x, y), got {value!r}")
    return float(arr[0]), float(arr[1])


#: detected keypoints scored under this are not used (the command line's threshold for detections)
KEYPOINT_SCORE_THRESHOLD = 0.1


def _keypoints_arg(keypoints, model) -> dict[int, tuple[float, float]]:
    if keypoints is None:
        return {}
    if not isinstance(keypoints, Mapping):
        raise ArgumentError(f"keypoints: expected a mapping {{id: (x, y)}}, got {type(keypoints).__name__}")
    out = {}
    for k, v in keypoints.items():
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
            raise ArgumentError(f"keypoints: ids are whole numbers 1-73, got {k!r}")
        if int(k) not in model.keypoints:
            raise ArgumentError(f"keypoints[{k}]: no such keypoint id (1-73: see pnlviz.keypoints())")
        try:
            arr = np.asarray(v, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            arr = np.zeros(0)
        if arr.shape == (3,):  # (x, y, score), as detect() gives them
            score = float(arr[2])
            if not 0.0 <= score <= 1.0:
                raise ArgumentError(f"keypoints[{k}]: a score is in [0, 1], got {score!r}")
            if score < KEYPOINT_SCORE_THRESHOLD:
                continue
            v = arr[:2]
        out[int(k)] = _pixel(v, f"keypoints[{k}]")
    return out


def _lines_arg(lines, model) -> dict[str, np.ndarray]:
    if lines is None:
        return {}
    if not isinstance(lines, Mapping):
        raise ArgumentError(f"lines: expected a mapping {{class name: (M, 2) pixels}}, got {type(lines).__name__}")
    from pnlviz.field.names import IGNORED_CLASSES

    known = set(model.lines) | set(model.circles)
    out = {}
    for name, pts in lines.items():
        if name in IGNORED_CLASSES:  # SoccerNet's own, which no calibration uses ("Line unknown"...)
            continue
        if name not in known:
            raise ArgumentError(f"lines[{name!r}]: not a SoccerNet class; one of {sorted(known)}")
        try:
            arr = np.asarray(pts, dtype=float)
        except (TypeError, ValueError):
            raise ArgumentError(f"lines[{name!r}]: expected (M, 2) pixels") from None
        if arr.ndim != 2 or arr.shape[1] != 2 or len(arr) < 2 or not np.all(np.isfinite(arr)):
            raise ArgumentError(f"lines[{name!r}]: expected (M, 2) finite pixels with M >= 2, got shape {arr.shape}")
        out[str(name)] = arr
    return out


def calibrate(keypoints: Mapping[int, Sequence[float]] | None = None,
              lines: Mapping[str, ArrayLike] | None = None, *, image_size: Sequence[int],
              pnl: bool = True, alpha: float | None = None) -> Calibration:
    """Calibrate one frame from what is seen in it.

    ``keypoints``: ``{id: (x, y)}`` pixels of catalogue keypoints (ids 1-73, see
    :func:`keypoints`), or ``{id: (x, y, score)}`` as :func:`detect` gives them (a keypoint
    scored under :data:`KEYPOINT_SCORE_THRESHOLD` is left out, as the command line's calibration
    from detections does; the fit weighs the others alike). ``lines``: ``{SoccerNet class name: (M, 2) pixels on it}`` (straight lines
    and circles, e.g. ``"Side line top"``, ``"Circle central"``); keypoints where annotated lines
    meet are derived from them, as PnLCalib does. A keypoint on a marking where no paint marks it
    (a circle's tangent point, where the long axis or a diagonal meets a circle or a box's main
    line: :meth:`FieldModel.unmarked_points`) is also a point of that marking, and where the lines
    and circles fix the camera it is held to the marking only, as from a detector. ``image_size``: (width, height) of the image
    the pixels are in. ``pnl``: the point-and-line refinement; ``alpha``: its weight of lines
    against points (default the paper's). Never raises on geometry: a frame that cannot be
    calibrated comes back with ``camera`` None and the reason.

    >>> import pnlviz
    >>> cam = pnlviz.Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
    >>> seen = {k: tuple(uv) for k, uv in zip(pnlviz.keypoints(), cam.project(list(pnlviz.keypoints().values())))}
    >>> seen = {k: uv for k, uv in seen.items() if cam.in_image([uv])[0]}
    >>> result = pnlviz.calibrate(seen, image_size=(960, 540))
    >>> assert result.camera is not None  # None when it failed (result.reason says why)
    >>> round(result.camera.hfov_deg, 3), sorted(seen) == sorted(result.inliers)
    (40.0, True)
    >>> pnlviz.calibrate({1: (10.0, 10.0)}, image_size=(960, 540)).reason_code  # one point: no camera
    'too_few_keypoints'
    """
    from pnlviz.calib.calibrate import calibrate as calibrate_frame
    from pnlviz.field.model import load_field_model

    model = load_field_model()
    w, h = _image_size(image_size)
    obs = _observations(keypoints, lines, w, h, model)
    res = calibrate_frame(obs, _params(pnl, alpha), model)
    return Calibration(res.camera, res.failure, res.failure_code, dict(res.point_residuals),
                       dict(res.line_residuals), tuple(int(k) for k in res.inliers), tuple(res.pnl_lines),
                       tuple(res.lines_alone))


def _params(pnl, alpha):
    from pnlviz.calib.calibrate import CalibParams

    if alpha is not None and (isinstance(alpha, bool) or not isinstance(alpha, (int, float))
                              or not math.isfinite(alpha) or not 0 <= alpha <= 1):
        raise ArgumentError(f"alpha: expected a number in [0, 1], got {alpha!r}")
    return CalibParams(pnl=bool(pnl)) if alpha is None else CalibParams(pnl=bool(pnl), alpha=float(alpha))


def _observations(keypoints, lines, w: int, h: int, model, where: str = ""):
    """The observations of a frame from the API's ``keypoints`` and ``lines`` (checked; ``where``
    prefixes the argument names in errors, e.g. ``frames[3].``)."""
    from pnlviz.calib.inputs import observations_from_annotation, on_their_markings
    from pnlviz.calib.observations import Observations

    try:
        kps = _keypoints_arg(keypoints, model)
        pixel_lines = _lines_arg(lines, model)
    except ArgumentError as exc:
        raise ArgumentError(f"{where}{exc}") from None
    scale = np.array([w - 1, h - 1], float)
    derived, _ = observations_from_annotation({k: v / scale for k, v in pixel_lines.items()}, w, h, model=model)
    points = {int(k): tuple(xy) for k, xy in zip(derived.kp_ids, derived.kp_xy)}
    sets = {int(k): str(s) for k, s in zip(derived.kp_ids, derived.kp_sets)}
    points.update(kps)  # a keypoint given wins over one derived from the lines
    for k in kps:
        sets.pop(k, None)
    # a given keypoint no paint marks is also a point of its marking (as from detections)
    lines, circles, unmarked = on_their_markings(kps, derived.lines, derived.circles, model)
    obs = Observations.from_keypoints(w, h, points, sets, lines=lines, circles=circles, model=model)
    from_lines = [int(k) for k in derived.kp_ids if int(k) not in kps]
    return replace(obs, kp_derived=np.isin(obs.kp_ids, from_lines + unmarked))  # the given ones are measurements


@dataclass(frozen=True)
class ClipCalibration:
    """A clip's cameras, one per frame (None: no camera), each from its shot's broadcast camera
    (one position and lens per shot, pan, tilt and zoom per frame), and the shots (lists of frame
    indices), as :func:`calibrate_clip` returns them.

    >>> import pnlviz
    >>> clip = pnlviz.calibrate_clip([{}, {}], image_size=(960, 540))  # nothing seen
    >>> clip.cameras
    (None, None)
    """

    cameras: tuple[Camera | None, ...]
    shots: tuple[tuple[int, ...], ...]


def calibrate_clip(frames: Sequence[Mapping], *, image_size: Sequence[int], pnl: bool = True) -> ClipCalibration:
    """Calibrate the frames of a video clip in time order, as ``pnlviz calibrate --temporal``
    does: each frame on its own, then the clip cut into shots and one broadcast camera fitted per
    shot. ``frames``: one mapping per frame with ``"keypoints"`` and/or ``"lines"`` as
    :func:`calibrate` takes them (an empty mapping: nothing seen).

    >>> import pnlviz
    >>> world = pnlviz.keypoints()
    >>> frames = []
    >>> for i in range(5):  # a camera panning 2 m a frame
    ...     cam = pnlviz.Camera.from_look_at((0, 50, -20), (2.0 * i, 0, 0), hfov_deg=40, width=960, height=540)
    ...     uv = dict(zip(world, cam.project(list(world.values()))))
    ...     frames.append({"keypoints": {k: tuple(p) for k, p in uv.items() if cam.in_image([p])[0]}})
    >>> frames.append({})  # a frame where nothing was seen: no camera is made up for it
    >>> clip = pnlviz.calibrate_clip(frames, image_size=(960, 540))
    >>> clip.shots, [c is not None for c in clip.cameras]
    (((0, 1, 2, 3, 4, 5),), [True, True, True, True, True, False])
    >>> middle = clip.cameras[2]
    >>> assert middle is not None
    >>> [round(float(v)) for v in middle.C]  # the shot's one position
    [0, 50, -20]
    """
    from pnlviz.calib.calibrate import calibrate as calibrate_frame
    from pnlviz.calib.temporal import calibrate_clip as solve_clip
    from pnlviz.field.model import load_field_model

    model = load_field_model()
    w, h = _image_size(image_size)
    if isinstance(frames, (str, bytes, Mapping)) or not isinstance(frames, Sequence):
        raise ArgumentError(f"frames: expected a sequence of mappings, one per frame, got {type(frames).__name__}")
    params = _params(pnl, None)
    observations, cameras = [], []
    for i, frame in enumerate(frames):
        if not isinstance(frame, Mapping) or set(frame) - {"keypoints", "lines"}:
            raise ArgumentError(f"frames[{i}]: expected a mapping with 'keypoints' and/or 'lines', got {frame!r:.60}")
        obs = _observations(frame.get("keypoints"), frame.get("lines"), w, h, model, where=f"frames[{i}].")
        observations.append(obs if obs.n_keypoints or obs.lines or obs.circles else None)
        cameras.append(calibrate_frame(obs, params, model).camera if observations[-1] is not None else None)
    result = solve_clip(observations, cameras, (w, h), model=model)
    return ClipCalibration(tuple(result.cameras), tuple(tuple(int(t) for t in shot) for shot in result.shots))


def open_dataset(path: str | Path) -> Dataset:
    """A dataset folder or zip (SoccerNet layout: ``<stem>.jpg`` with ``<stem>.json``), indexed
    lazily: ``len(ds)``, ``ds.stems``, ``ds.image(stem)`` (BGR), ``ds.annotation(stem)``. Split
    folders or split zips (``sn23/train/``, ``sn23/valid.zip``, ...) are one dataset whose stems
    are ``<split>/<stem>`` (``ds.splits`` names them).

    >>> import pnlviz
    >>> ds = pnlviz.open_dataset(pnlviz.SAMPLE_DIR)  # the bundled sample
    >>> image = ds.image("00000")  # None for a frame without an image
    >>> assert image is not None
    >>> len(ds), ds.stems[0], image.shape
    (33, 'sn22_00004', (540, 960, 3))
    """
    from pnlviz.data import open_dataset as open_data

    p = Path(path)
    if not p.exists():
        raise ArgumentError(f"path: {p} does not exist")
    return open_data(p)


@overload
def qa(data: str | Path, *, detections: str | Path | None = None,
       image_size: Sequence[int] | None = None) -> list[dict[str, Any]]: ...


@overload
def qa(data: Mapping[str, ArrayLike], *, detections: Predictions | None = None,
       image_size: Sequence[int] | None = None) -> dict[str, Any]: ...


def qa(data: str | Path | Mapping[str, ArrayLike], *, detections: str | Path | Predictions | None = None,
       image_size: Sequence[int] | None = None) -> list[dict[str, Any]] | dict[str, Any]:
    """Find the label errors, as ``pnlviz qa`` does. ``data``: a dataset folder or zip -> one
    ``{"stem", "score", "findings"}`` per annotated frame, most suspect first (higher score: more
    likely wrong; a frame scores 1 or more when something is found); or one frame's lines
    ``{SoccerNet class name: (M, 2) pixels}`` (as :func:`calibrate` takes them) with its
    ``image_size`` -> that frame's ``{"score", "findings"}``. Each finding: ``kind``
    (``wrong_class``, ``off_projection``, ``split_class``, ``missing_class``,
    ``detection_disagreement``, ``no_camera``), ``class`` or ``keypoint``, ``message``,
    ``severity``, ``evidence`` and a suggested ``fix`` (``{"op": "rename" | "drop_points" |
    "move_points" | "add_class", ...}``, points normalised as in SoccerNet files).
    ``detections``: a PnLCalib prediction zip for a dataset, or one frame's
    ``pnlviz.data.Predictions``, compared with the annotation.

    >>> import pnlviz
    >>> ds = pnlviz.open_dataset(pnlviz.SAMPLE_DIR)
    >>> annotation = ds.annotation("sn22_00004")  # normalised points; None for a frame without one
    >>> assert annotation is not None
    >>> lines = {name: points * (959, 539) for name, points in annotation.items()}  # normalised -> pixels
    >>> pnlviz.qa(lines, image_size=(960, 540))["findings"]  # nothing wrong
    []
    >>> lines["Side line left"] = lines.pop("Side line right")  # a class mixed up
    >>> [(f["kind"], f["class"], f["fix"]["op"]) for f in pnlviz.qa(lines, image_size=(960, 540))["findings"]]
    [('wrong_class', 'Side line left', 'rename')]
    """
    from pnlviz.calib.qa import check_frame
    from pnlviz.field.model import load_field_model

    model = load_field_model()
    if isinstance(data, Mapping):
        if image_size is None:
            raise ArgumentError("image_size: one frame's lines need the (width, height) of their image")
        w, h = _image_size(image_size)
        lines = _lines_arg(data, model)
        return check_frame({k: v / [w - 1, h - 1] for k, v in lines.items()}, (w, h), detections, model=model).to_json()
    if not isinstance(data, (str, Path)):
        raise ArgumentError(f"data: expected a dataset path or one frame's lines, got {type(data).__name__}")
    return _qa_dataset(open_dataset(data), detections, image_size, model)


def _qa_dataset(ds, detections, image_size, model) -> list[dict]:
    from pnlviz.calib.qa import check_frame
    from pnlviz.data import read_predictions

    size = (960, 540) if image_size is None else _image_size(image_size)
    if detections is not None and not Path(detections).exists():
        raise ArgumentError(f"detections: {detections} does not exist")
    preds = read_predictions(detections) if detections is not None else {}
    out = []
    for stem in ds.stems:
        ann = ds.annotation(stem) if ds.frame(stem).has_annotation else None
        if ann is None:
            continue
        frame_size = (ds.image_size(stem) if ds.frame(stem).has_image else None) or size
        out.append(check_frame(ann, frame_size, preds.get(stem), model=model).to_json(stem))
    return sorted(out, key=lambda r: (-r["score"], r["stem"]))


def detect(image: np.ndarray, weights: str | Path | None = None, *, threshold: float = 0.1) -> dict[str, Any]:
    """Keypoints and lines of one BGR image (H, W, 3) uint8: ``{"keypoints": {id: (x, y, score)},
    "lines": {class name: [(x1, y1), (x2, y2)]}}`` in its pixels (what :func:`calibrate` takes);
    the same as ``pnlviz.detect(image)`` (type checkers see ``pnlviz.detect`` as the package: typed
    code imports this one, ``from pnlviz.api import detect``). Needs ``pip install 'pnlviz[detect]'``
    (PyTorch). ``weights``: a light model (default: the shipped one); ``threshold``: the
    keypoint score below which a detection is left out. An image whose detections give no camera
    is read again at the model's lower ``second_look`` thresholds, kept when that gives one
    (``docs/detector.md``): its weak points keep their scores.

    >>> import pnlviz
    >>> from pnlviz.api import detect  # pnlviz.detect, as type checkers see it
    >>> image = pnlviz.open_dataset(pnlviz.SAMPLE_DIR).image("00000")
    >>> assert image is not None
    >>> found = detect(image)
    >>> len(found["keypoints"]) > 10, sorted(found) == ["keypoints", "lines"]
    (True, True)
    >>> pnlviz.calibrate(**found, image_size=(960, 540)).ok
    True
    """
    from pnlviz.calib.looks import take_look
    from pnlviz.detect.image import detect_image

    return detect_image(image, weights, threshold=threshold, look=take_look)


def top_view(camera: Camera | None = None, image: np.ndarray | None = None, points_pitch: ArrayLike | None = None,
             points_image: ArrayLike | None = None, *, keypoints: Mapping[int, Sequence[float]] | None = None,
             points: ArrayLike | None = None, px_per_m: float = 8.0) -> np.ndarray:
    """A bird's-eye view of the pitch (BGR uint8, (int(80 px_per_m), int(117 px_per_m), 3): the
    pitch and 6 m around it, the far touchline at the top): the camera's footprint and position;
    ``image``, the camera's picture (BGR, any size of its aspect), drawn on the ground it sees;
    ``points_pitch`` (N, 2) pitch positions in metres (a tracker's players) and ``points_image``
    (N, 2) pixels of the image put on the ground (players' feet, the bottom middle of their
    boxes) as red discs; ``keypoints`` ``{id: (x, y)}`` image keypoints put on the ground with
    their ids. ``points`` is the older name of ``points_image``. About 2 ms at 3 px/m, 12 ms at
    8 px/m, 35 ms with an image at 8 px/m (one core).

    >>> import pnlviz
    >>> cam = pnlviz.Camera.from_look_at((0, 50, -20), (0, 0, 0), hfov_deg=40, width=960, height=540)
    >>> view = pnlviz.top_view(cam, points_pitch=[[0.0, 0.0], [-41.5, 0.0]], px_per_m=3)
    >>> view.shape, view.dtype.name
    ((240, 351, 3), 'uint8')
    """
    from pnlviz.viz import top_view as draw

    if camera is not None and not isinstance(camera, Camera):
        raise ArgumentError(f"camera: expected a pnlviz.Camera, got {type(camera).__name__}")
    if not (isinstance(px_per_m, (int, float)) and 1 <= px_per_m <= 64):
        raise ArgumentError(f"px_per_m: expected a number in 1..64, got {px_per_m!r}")
    if points is not None and points_image is not None:
        raise ArgumentError("points: the older name of points_image; give one of them")
    points_image = points if points_image is None else points_image
    arrays = {}
    for name, value in (("points_pitch", points_pitch), ("points_image", points_image)):
        if value is None:
            continue
        try:
            arr = np.asarray(value, float)
        except (TypeError, ValueError):
            raise ArgumentError(f"{name}: expected numbers (N, 2), got {type(value).__name__}") from None
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ArgumentError(f"{name}: expected an array (N, 2), got shape {arr.shape}")
        arrays[name] = arr
    if points_image is not None and camera is None:
        raise ArgumentError("points_image: image points need the camera that puts them on the ground")
    if image is not None:
        if camera is None:
            raise ArgumentError("image: a picture needs the camera that took it")
        image = np.asarray(image)
        if image.ndim != 3 or image.shape[2] not in (3, 4) or image.dtype != np.uint8:
            raise ArgumentError(f"image: expected a BGR uint8 image (H, W, 3), got {image.dtype} {image.shape}")
        if abs(image.shape[1] / image.shape[0] - camera.width / camera.height) > 0.02:
            raise ArgumentError(f"image: {image.shape[1]}x{image.shape[0]} is not the camera's aspect "
                                f"({camera.width:g}x{camera.height:g}); a swapped or cropped picture?")
    return draw(camera, image=image, points=arrays.get("points_image"), keypoints=keypoints,
                points_pitch=arrays.get("points_pitch"), px_per_m=float(px_per_m))
