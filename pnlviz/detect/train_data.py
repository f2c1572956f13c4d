"""Training frames from three kinds of source, and the label-exact augmentations for real footage.

Sources (each: ``len()``, ``sample(i, input_size, sigma, view)`` -> one training example):

* :class:`FrameCache` (in :mod:`pnlviz.detect.train`): ``pnlviz synth`` frames rendered in memory;
  targets from their line annotations (the label generator);
* :class:`AnnotatedFrames`: a SoccerNet-Calibration folder or zip (images + line annotations, e.g.
  ``sn23/train`` or an ``pnlviz export`` of corrected labels); targets from the label generator,
  as PnLCalib trains on SN23; images read when sampled (nothing held in memory);
* :class:`ExportedFrames`: the labels ``pnlviz export`` (or the app's export button) wrote -
  keypoints as corrected in the app, line annotations - with the images of the dataset they were
  made on: the loop "correct labels in the app -> export -> fine-tune";
* :class:`HomographyFrames`: images + ground-truth homographies (WC14 / TS-WorldCup style,
  ``homographies.json``: template yards -> pixels of a ``source_size`` frame); targets from
  :func:`pnlviz.labels.from_homography.homography_training_targets`: ground keypoints and line
  extremities projected through H, the non-planar channels masked in the loss.

A :class:`View` says how one example is drawn, and every part of it keeps the labels exact:

* ``flip``: the horizontally mirrored image (labels: x -> W - 1 - x, and the pitch reflected in its
  halfway line so that the ids follow);
* ``crop`` ``(x0, y0, s)``: a zoom by ``s`` >= 1 into the window at ``(x0, y0)`` (input pixels),
  resized back to the input size (labels through the same affine map; annotations are clipped to
  the window);
* ``down`` ``(fx, fy)``: down-up scaling, the blur of a low-resolution source (the image is shrunk
  by fx, fy <= 1 and enlarged back; labels unchanged);
* ``jpeg``: a JPEG round trip at that quality (labels unchanged);
* ``wear``: worn or partly hidden paint, gaps of grass colour painted over stretches of the
  annotated lines (labels unchanged: the geometry is where it was; frames with a line annotation);
* ``graphics``: a broadcast score bug (a box with team names, score and clock) drawn near a top
  corner, as live broadcasts show (labels unchanged: the pitch is still where it was).

Photometric jitter and noise are applied to the batch afterwards (:func:`pnlviz.detect.train_loss.augment`).
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pnlviz.data.limits import MAX_IMAGE_BYTES
from pnlviz.data.reading import read_file
from pnlviz.field.names import FLIP_X, canonical_class_name
from pnlviz.labels.resize import clip_to_image, resize_annotation, resize_matrix

__all__ = ["AnnotatedFrames", "HomographyFrames", "View", "apply_view_image", "clip_annotation", "draw_view",
           "pad_targets"]


@dataclass(frozen=True)
class View:
    flip: bool = False
    crop: tuple[float, float, float] | None = None  # (x0, y0, zoom) in input pixels
    down: tuple[float, float] | None = None  # (fx, fy) down-up scaling factors
    jpeg: int | None = None  # JPEG quality
    graphics: int | None = None  # seed of a drawn score bug
    wear: int | None = None  # seed of the worn stretches of line paint

    def affine(self, width: int, height: int) -> np.ndarray:
        """3x3 map from input pixels before the view to pixels after it (flip, then crop)."""
        A = np.eye(3)
        if self.flip:
            A = np.array([[-1.0, 0.0, width - 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) @ A
        if self.crop is not None:
            x0, y0, s = self.crop
            # pixel centres: the window's pixel u maps to s * (u - x0) + (s - 1) / 2 (cv2's resize convention)
            A = np.array([[s, 0.0, -s * x0 + 0.5 * (s - 1)], [0.0, s, -s * y0 + 0.5 * (s - 1)], [0.0, 0.0, 1.0]]) @ A
        return A


def draw_view(params: dict, rng: np.random.Generator, size: tuple[int, int]) -> View:
    """A random :class:`View` from the augmentation ``params`` (keys ``flip``: probability; ``zoom``:
    maximum zoom, drawn log-uniformly with probability ``zoom_p`` (default 0.5); ``downscale``:
    smallest down-up factor per axis, with probability ``downscale_p`` (default 0.5); ``jpeg``:
    lowest quality, with probability ``jpeg_p`` (default 0.5); ``graphics``: probability of a score
    bug; ``wear``: probability of worn line paint). Keys not set draw nothing, so a configuration
    without them keeps its random stream."""
    W, H = size
    flip = bool(rng.random() < float(params["flip"])) if params.get("flip") else False
    crop = down = jpeg = graphics = None
    if params.get("zoom") and float(params["zoom"]) > 1.0 and rng.random() < float(params.get("zoom_p", 0.5)):
        s = float(np.exp(rng.uniform(0.0, np.log(float(params["zoom"])))))
        crop = (float(rng.uniform(0, W - W / s)), float(rng.uniform(0, H - H / s)), s)
    if params.get("downscale") and rng.random() < float(params.get("downscale_p", 0.5)):
        lo = float(params["downscale"])
        down = (float(rng.uniform(lo, 1.0)), float(rng.uniform(min(1.0, 2 * lo), 1.0)))
    if params.get("jpeg") and rng.random() < float(params.get("jpeg_p", 0.5)):
        jpeg = int(rng.integers(int(params["jpeg"]), 96))
    if params.get("graphics") and rng.random() < float(params["graphics"]):
        graphics = int(rng.integers(2 ** 31))
    wear = None
    if params.get("wear") and rng.random() < float(params["wear"]):
        wear = int(rng.integers(2 ** 31))
    return View(flip, crop, down, jpeg, graphics, wear)


def draw_wear(img: np.ndarray, lines: list[np.ndarray], seed: int) -> np.ndarray:
    """Worn paint on a copy of ``img``: on about half of the pixel polylines ``lines``, one to three
    stretches of 6-30 px painted over, partly or fully, with the grass colour found beside them."""
    rng = np.random.default_rng(seed)
    out = img.copy()
    H, W = out.shape[:2]
    for pts in lines:
        if len(pts) < 2 or rng.random() < 0.5:
            continue
        seg = np.diff(pts, axis=0)
        length = np.hypot(seg[:, 0], seg[:, 1])
        total = float(length.sum())
        if total < 12:
            continue
        cum = np.concatenate([[0.0], np.cumsum(length)])
        for _ in range(int(rng.integers(1, 4))):
            a = rng.uniform(0, total)
            b = min(total, a + rng.uniform(6, 30))
            pa = np.array([np.interp(a, cum, pts[:, 0]), np.interp(a, cum, pts[:, 1])])
            pb = np.array([np.interp(b, cum, pts[:, 0]), np.interp(b, cum, pts[:, 1])])
            d = pb - pa
            n = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), 1e-6)
            beside = [np.clip(np.round(p + k * 6 * n), [0, 0], [W - 1, H - 1]).astype(int)
                      for p in (pa, pb) for k in (-1, 1)]
            colour = np.median([out[y, x] for x, y in beside], axis=0)
            layer = out.copy()
            cv2.line(layer, tuple(int(v) for v in np.round(pa)), tuple(int(v) for v in np.round(pb)),
                     tuple(float(c) for c in colour), int(rng.integers(3, 6)), cv2.LINE_AA)
            alpha = float(rng.uniform(0.6, 1.0))
            out = cv2.addWeighted(layer, alpha, out, 1.0 - alpha, 0.0)
    return out


def draw_score_bug(img: np.ndarray, seed: int) -> np.ndarray:
    """A broadcast score bug on a copy of ``img``: a dark, partly transparent box near a top corner
    with two team codes, a score and a clock in light text."""
    rng = np.random.default_rng(seed)
    out = img.copy()
    H, W = out.shape[:2]
    w, h = int(W * rng.uniform(0.16, 0.32)), int(H * rng.uniform(0.045, 0.08))
    x0 = int(W * rng.uniform(0.02, 0.06)) if rng.random() < 0.7 else W - w - int(W * rng.uniform(0.02, 0.06))
    y0 = int(H * rng.uniform(0.02, 0.07))
    box = out[y0:y0 + h, x0:x0 + w].astype(np.float32)
    colour = rng.uniform(10, 90, 3).astype(np.float32)
    alpha = rng.uniform(0.6, 0.95)
    out[y0:y0 + h, x0:x0 + w] = (alpha * colour + (1 - alpha) * box).astype(np.uint8)
    stripe = tuple(int(v) for v in rng.uniform(60, 255, 3))
    cv2.rectangle(out, (x0, y0 + h - max(1, h // 6)), (x0 + w - 1, y0 + h - 1), stripe, -1)
    letters = "ABCDEFGHIJKLMNOPRSTUVWZ"
    code = lambda: "".join(letters[i] for i in rng.integers(len(letters), size=3))  # noqa: E731
    text = f"{code()} {rng.integers(4)}-{rng.integers(4)} {code()}  {rng.integers(90):02d}:{rng.integers(60):02d}"
    scale = h / 40.0
    cv2.putText(out, text, (x0 + max(2, w // 30), y0 + int(0.7 * h)), cv2.FONT_HERSHEY_SIMPLEX, scale,
                (235, 235, 235), max(1, int(round(scale * 1.5))), cv2.LINE_AA)
    return out


def apply_view_image(img: np.ndarray, view: View, lines: list[np.ndarray] | None = None) -> np.ndarray:
    """The uint8 BGR image (already at the input size) seen through ``view``; ``lines``: the
    annotated polylines in the viewed image's pixels, for ``wear``."""
    H, W = img.shape[:2]
    if view.flip:
        img = img[:, ::-1]
    if view.crop is not None:
        x0, y0, s = view.crop
        M = np.array([[s, 0.0, -s * x0 + 0.5 * (s - 1)], [0.0, s, -s * y0 + 0.5 * (s - 1)]])
        img = cv2.warpAffine(np.ascontiguousarray(img), M, (W, H), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_REFLECT)
    if view.wear is not None and lines:
        img = draw_wear(np.ascontiguousarray(img), lines, view.wear)
    if view.down is not None:
        w, h = max(8, round(W * view.down[0])), max(8, round(H * view.down[1]))
        img = cv2.resize(cv2.resize(np.ascontiguousarray(img), (w, h), interpolation=cv2.INTER_AREA), (W, H),
                         interpolation=cv2.INTER_LINEAR)
    if view.graphics is not None:
        img = draw_score_bug(img, view.graphics)
    if view.jpeg is not None:
        ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(img), [cv2.IMWRITE_JPEG_QUALITY, int(view.jpeg)])
        if ok:
            decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR)
            assert decoded is not None  # what cv2 has just encoded
            img = decoded
    return np.ascontiguousarray(img)


def clip_annotation(annotation: dict[str, np.ndarray], A: np.ndarray, width: int, height: int
                    ) -> dict[str, np.ndarray]:
    """A normalised annotation (``{class: (N, 2)}``, x (W - 1) scaling) mapped through the pixel
    affine ``A`` (a flip and/or crop of the same W x H image) and clipped to the image. A flip
    (negative x scale) also renames the classes by :data:`pnlviz.field.FLIP_X`."""
    scale = np.array([width - 1.0, height - 1.0])
    flip = A[0, 0] < 0
    out = {}
    for name, pts in annotation.items():
        px = np.asarray(pts, float).reshape(-1, 2) * scale
        px = px @ A[:2, :2].T + A[:2, 2]
        px = clip_to_image(px, width, height)
        canon = canonical_class_name(name) or name
        if len(px):
            out[FLIP_X.get(canon, canon) if flip else canon] = px / scale
    return out


def pad_targets(t, W: int, H: int):
    """Keypoint and line targets padded to the network's ceil(H/2) x ceil(W/2) output (the targets
    are floor(H/2) x floor(W/2)); padded keypoint pixels are background."""
    h, w = (H + 1) // 2, (W + 1) // 2
    kp, lines = t.keypoints, t.lines
    if kp.shape[1:] != (h, w):
        kp = np.pad(kp, ((0, 0), (0, h - kp.shape[1]), (0, w - kp.shape[2])))
        kp[-1, t.keypoints.shape[1]:, :] = 1.0
        kp[-1, :, t.keypoints.shape[2]:] = 1.0
        lines = np.pad(lines, ((0, 0), (0, h - lines.shape[1]), (0, w - lines.shape[2])))
    return kp, lines


def _to_input(img: np.ndarray, input_size: tuple[int, int]) -> np.ndarray:
    W, H = input_size
    if (img.shape[1], img.shape[0]) != (W, H):
        img = cv2.resize(img, (W, H), interpolation=cv2.INTER_AREA if img.shape[1] > W else cv2.INTER_LINEAR)
    return img


def _example(img: np.ndarray, t, input_size: tuple[int, int]):
    W, H = input_size
    x = np.ascontiguousarray(img[:, :, ::-1].transpose(2, 0, 1), dtype=np.float32) / 255.0
    kp, lines = pad_targets(t, W, H)
    return x, kp, t.keypoint_mask, lines, t.line_mask


def annotation_example(img: np.ndarray, annotation: dict[str, np.ndarray], input_size: tuple[int, int],
                       sigma: float, view: View):
    """One example from an image and its normalised line annotation (targets from the label
    generator with the left-right disambiguation, as for synthetic frames)."""
    from pnlviz.labels import training_targets

    W, H = input_size
    annotation = resize_annotation(annotation, (img.shape[1], img.shape[0]), (W, H))  # as _to_input resizes img
    if view.flip or view.crop is not None:
        annotation = clip_annotation(annotation, view.affine(W, H), W, H)
    lines = None
    if view.wear is not None:
        scale = np.array([W - 1.0, H - 1.0])
        lines = [np.asarray(p, float).reshape(-1, 2) * scale for p in annotation.values()]
    img = apply_view_image(_to_input(img, input_size), view, lines)
    _, _, t = training_targets(annotation, W, H, sigma=sigma)
    return _example(img, t, input_size)


class HomographyFrames:
    """Images with ground-truth homographies (see the module docstring). ``stems``: the frames to
    use (default: every image that has a homography); images are decoded once and kept (these
    sets are small: WC14 has 209 training frames). ``paint_fit``: each homography is first
    brought onto the paint of its own image (:func:`pnlviz.labels.paint_fit.fit_to_paint`; kept
    as given where the paint measures too little of it); :attr:`paint_fits` says what each got."""

    def __init__(self, images: str | os.PathLike, homographies: str | os.PathLike | None = None, *,
                 source_size: tuple[int, int] = (1280, 720), stems: list[str] | None = None,
                 exclude: list[str] | None = None, paint_fit: bool = False) -> None:
        from pnlviz.data import read_homographies
        from pnlviz.data.errors import DataError

        folder = Path(images)
        hpath = Path(homographies) if homographies is not None else folder / "homographies.json"
        if not hpath.is_file():
            raise DataError(str(hpath), "no homographies.json for this image folder")
        gt = read_homographies(hpath)
        skip = set(exclude or ())
        wanted = [s for s in (stems if stems is not None else gt) if s not in skip]
        self.source = str(folder)
        self.source_size = (int(source_size[0]), int(source_size[1]))
        self.stems: list[str] = []
        self.homographies: list[np.ndarray] = []
        self.images: list[np.ndarray] = []
        for stem in wanted:
            if stem not in gt:
                raise DataError(str(hpath), f"no homography for frame {stem!r}")
            path = next((folder / f"{stem}{ext}" for ext in (".jpg", ".png", ".jpeg") if (folder / f"{stem}{ext}").is_file()),
                        None)
            if path is None:
                raise DataError(str(folder), f"no image for frame {stem!r}")
            img = cv2.imdecode(np.frombuffer(read_file(path, MAX_IMAGE_BYTES), np.uint8), cv2.IMREAD_COLOR)
            if img is None:
                raise DataError(str(path), "cannot decode the image")
            self.stems.append(stem)
            self.homographies.append(np.asarray(gt[stem], float))
            self.images.append(img)
        self.paint_fits: list = []
        if paint_fit:
            self.paint_fits = [self._fit_to_paint(i) for i in range(len(self.stems))]

    def _fit_to_paint(self, i: int):
        """Frame ``i``'s homography fitted to its image's paint (kept in the source's convention)."""
        from pnlviz.labels.from_homography import template_homography
        from pnlviz.labels.paint_fit import fit_to_paint

        h, w = self.images[i].shape[:2]
        fit = fit_to_paint(self.field_homography(i, (w, h)), self.images[i])
        if fit.refined:
            self.homographies[i] = template_homography(fit.H, (w, h), source_size=self.source_size)
        return fit

    def __len__(self) -> int:
        return len(self.stems)

    def field_homography(self, i: int, input_size: tuple[int, int]) -> np.ndarray:
        """Field metres -> pixels of frame ``i`` resized to ``input_size``."""
        from pnlviz.labels.from_homography import homography_for_size

        return homography_for_size(self.homographies[i], input_size, source_size=self.source_size)

    def sample(self, i: int, input_size: tuple[int, int], sigma: float = 2.0, view: View = View()):
        from pnlviz.labels.from_homography import homography_training_targets

        W, H = input_size
        img = apply_view_image(_to_input(self.images[i], input_size), view)
        Hf = view.affine(W, H) @ self.field_homography(i, input_size)
        if view.flip:
            Hf = Hf @ np.diag([-1.0, 1.0, 1.0])  # the pitch reflected in its halfway line: ids follow
        _, _, t = homography_training_targets(Hf, W, H, sigma=sigma)
        return _example(img, t, input_size)


class AnnotatedFrames:
    """A SoccerNet-Calibration dataset (folder or zip): the frames that have both an image and a line
    annotation; images and annotations are read when sampled."""

    def __init__(self, path: str | os.PathLike, *, exclude: list[str] | None = None) -> None:
        from pnlviz.data import open_dataset
        from pnlviz.data.errors import DataError

        self.dataset = open_dataset(path)
        skip = set(exclude or ())
        self.stems = [s for s in self.dataset.stems
                      if s not in skip and self.dataset.frame(s).has_image and self.dataset.frame(s).has_annotation]
        self.source = str(path)
        if not self.stems:
            raise DataError(str(path), "no frame has both an image and a line annotation")

    def __len__(self) -> int:
        return len(self.stems)

    def sample(self, i: int, input_size: tuple[int, int], sigma: float = 2.0, view: View = View()):
        stem = self.stems[i]
        image = self.dataset.image(stem)
        assert image is not None  # the frames kept have an image
        return annotation_example(image, self.dataset.annotation(stem) or {}, input_size, sigma, view)


@functools.lru_cache(maxsize=4)
def _keypoint_id_map(sign_x: float, sign_y: float) -> dict[int, int]:
    """Network keypoint id -> the id at the reflected world position ``(sign_x X, sign_y Y, Z)``:
    the ids of a flipped image (-1, 1) or of the evaluator's mirror (-1, -1)."""
    from pnlviz.labels import NETWORK_KEYPOINT_IDS, get_catalogue

    cat = get_catalogue()
    xyz = cat.world_xyz(NETWORK_KEYPOINT_IDS)
    out = {}
    for kid, p in zip(NETWORK_KEYPOINT_IDS, xyz):
        q = p * np.array([sign_x, sign_y, 1.0])
        j = int(np.argmin(np.linalg.norm(xyz - q, axis=1)))
        if np.linalg.norm(xyz[j] - q) < 0.05:
            out[kid] = NETWORK_KEYPOINT_IDS[j]
    return out


class ExportedFrames:
    """Labels exported from the app (``keypoints/<stem>.json`` and ``annotations/<stem>.json`` of a
    ``pnlviz export`` folder or zip) with the images of ``images`` (the dataset the app served).
    The keypoints are taken as corrected (moved points where the annotator put them, hidden ones
    and those the outlier gate flagged absent), the annotation's lines give the line targets; the
    left-right disambiguation is
    decided on a homography fitted to the ground keypoints, as for every training target."""

    def __init__(self, export: str | os.PathLike, images: str | os.PathLike, *,
                 exclude: list[str] | None = None) -> None:
        import json

        from pnlviz.data import open_dataset
        from pnlviz.data.errors import DataError

        from pnlviz.data.reading import open_zip, read_file, read_zip_member

        export = Path(export)
        files: dict[str, bytes] = {}
        if export.is_file():
            with open_zip(export, not_zip="not a pnlviz export (not a valid .zip archive)") as z:
                files = {n: read_zip_member(z, n, f"{export}:{n}") for n in z.namelist() if n.endswith(".json")}
        elif export.is_dir():
            files = {str(p.relative_to(export).as_posix()): read_file(p) for p in export.glob("*/*.json")}
            files.update({p.name: read_file(p) for p in export.glob("*.json")})
        else:
            raise DataError(str(export), "no such export folder or zip")
        if not any(n.rsplit("/", 1)[-1].startswith("manifest") for n in files):
            raise DataError(str(export), "no manifest: not a complete pnlviz export (an interrupted export?); "
                                         "export again and train on the finished one")
        self.dataset = open_dataset(images)
        skip = set(exclude or ())
        self.stems: list[str] = []
        self.keypoints: list[dict] = []
        self.annotations: list[dict[str, np.ndarray]] = []
        for name in sorted(files):
            if not (name.startswith("keypoints/") and name.endswith(".json")):
                continue
            stem = name[len("keypoints/"):-len(".json")]
            if stem in skip or stem not in self.dataset or not self.dataset.frame(stem).has_image:
                continue
            try:
                kp = json.loads(files[name])
                size = tuple(int(v) for v in kp["image_size"])
                # points the export's outlier gate flagged are not ground truth: left out
                points = {int(k): (float(v["x"]), float(v["y"])) for k, v in kp["keypoints"].items()
                          if not v.get("flagged")}
            except (ValueError, KeyError, TypeError) as exc:
                raise DataError(f"{export}/{name}", f"not a pnlviz keypoint label file ({exc})") from None
            ann = files.get(f"annotations/{stem}.json")
            annotation = {}
            if ann is not None:
                from pnlviz.data.annotations import parse_annotation_bytes

                annotation = parse_annotation_bytes(ann, f"{export}/annotations/{stem}.json")
            self.stems.append(stem)
            self.keypoints.append({"size": size, "points": points})
            self.annotations.append(annotation)
        self.source = str(export)
        if not self.stems:
            raise DataError(str(export), f"no exported keypoint labels match an image of {images}")

    def __len__(self) -> int:
        return len(self.stems)

    def sample(self, i: int, input_size: tuple[int, int], sigma: float = 2.0, view: View = View()):
        from pnlviz.labels import NETWORK_KEYPOINT_IDS, get_catalogue, line_extremities
        from pnlviz.labels.heatmaps import heatmap_targets, keypoint_mask
        from pnlviz.labels.leftright import lr_decision
        from pnlviz.labels.types import KeypointLabel, KeypointLabels

        W, H = input_size
        image = self.dataset.image(self.stems[i])
        assert image is not None  # the frames kept have an image
        img = apply_view_image(_to_input(image, input_size), view)
        (w0, h0), points = self.keypoints[i]["size"], self.keypoints[i]["points"]
        # frame pixels -> input pixels (cv2.resize aligns pixel centres), then the view
        A = view.affine(W, H) @ resize_matrix((w0, h0), (W, H))
        flip = _keypoint_id_map(-1.0, 1.0) if view.flip else None
        px: dict[int, np.ndarray] = {}
        for kid, (x, y) in points.items():
            if kid not in NETWORK_KEYPOINT_IDS:
                continue
            q = A @ np.array([x, y, 1.0])
            kid = flip.get(kid) if flip is not None else kid
            if kid is not None:
                px[kid] = q[:2]
        annotation = resize_annotation(self.annotations[i], (w0, h0), (W, H))
        if view.flip or view.crop is not None:
            annotation = clip_annotation(annotation, view.affine(W, H), W, H)
        # left-right disambiguation on the ground keypoints' homography
        cat = get_catalogue()
        ground = [k for k in px if abs(float(cat.model.keypoints[k].xyz[2])) < 1e-9]
        Hg, mirror = None, False
        if len(ground) >= 4:
            Hg, _ = cv2.findHomography(cat.world_xyz(ground)[:, :2], np.array([px[k] for k in ground]), 0)
            if Hg is not None:
                mirror = lr_decision(Hg, np.mean([px[k] for k in ground], axis=0)).mirror
        if mirror:
            m = _keypoint_id_map(-1.0, -1.0)
            px = {m[k]: v for k, v in px.items() if k in m}
        labels = KeypointLabels(W, H, homography=Hg, mirrored=mirror, annotated_classes=frozenset(annotation))
        labels.keypoints = {k: KeypointLabel(k, float(v[0]), float(v[1]), bool(0 <= v[0] <= W - 1 and 0 <= v[1] <= H - 1),
                                             "Kp") for k, v in sorted(px.items())}
        ext = line_extremities(annotation, W, H, mirror=mirror)
        t = heatmap_targets(labels, ext, W, H, sigma=sigma)
        t.keypoint_mask = keypoint_mask(labels)
        return _example(img, t, input_size)
