"""Overlays on images (OpenCV drawing): the pitch reprojected through a camera, annotated lines,
keypoints, and contact sheets. Images are BGR uint8, as OpenCV reads them."""

from __future__ import annotations

import math
import zlib

import cv2
import numpy as np

from pnlviz.field.model import FieldModel, load_field_model
from pnlviz.geometry.camera import Camera
from pnlviz.geometry.polylines import project_polylines

PITCH_BGR = (60, 220, 255)  # amber: the model reprojected through a camera

# A stable colour per class (BGR), for annotation overlays.
_CLASS_COLOURS: dict[str, tuple[int, int, int]] = {}


def cv_text(text: str) -> str:
    """``text`` as OpenCV can draw it: ASCII (its Hershey fonts have nothing else), ``?`` for the
    rest. OpenCV crashes (segfault) on a str it cannot encode, such as a file name with surrogate
    escapes; never hand it one."""
    return str(text).encode("ascii", "replace").decode("ascii")


def class_colour(name: str) -> tuple[int, int, int]:
    if name not in _CLASS_COLOURS:
        h = zlib.crc32(name.strip().encode("utf-8", "surrogatepass")) % 180
        hsv = np.uint8([[[h, 200, 255]]])
        _CLASS_COLOURS[name] = tuple(int(c) for c in cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0])
    return _CLASS_COLOURS[name]


def _to_int(pts: np.ndarray, shift: int = 4) -> np.ndarray:
    # sub-pixel drawing: OpenCV takes fixed-point coordinates with `shift` fractional bits
    return np.round(np.asarray(pts) * (1 << shift)).astype(np.int32).reshape(-1, 1, 2)


def draw_pitch(image: np.ndarray, camera: Camera, colour=PITCH_BGR, thickness: int = 1,
               model: FieldModel | None = None) -> np.ndarray:
    """Draw the pitch model projected through ``camera`` (rescaled to the image size). In place."""
    h, w = image.shape[:2]
    if (camera.width, camera.height) != (w, h):
        camera = camera.scaled(w, h)
    model = model or load_field_model()
    for pts in project_polylines(camera, model.sample_polylines(0.5, 0.25), w, h).values():
        if len(pts) >= 2:
            cv2.polylines(image, [_to_int(pts)], False, colour, thickness, cv2.LINE_AA, shift=4)
    return image


def draw_annotation(image: np.ndarray, annotation: dict[str, np.ndarray], *, normalised: bool = True,
                    thickness: int = 1, radius: int = 3, labels: bool = False) -> np.ndarray:
    """Draw annotated classes (points joined in order). ``normalised`` points use the SoccerNet
    convention x_px = x (W - 1). In place."""
    h, w = image.shape[:2]
    for name, pts in annotation.items():
        pts = np.asarray(pts, float).reshape(-1, 2)
        if normalised:
            pts = pts * [w - 1, h - 1]
        col = class_colour(name)
        if len(pts) >= 2:
            cv2.polylines(image, [_to_int(pts)], False, col, thickness, cv2.LINE_AA, shift=4)
        for p in pts:
            cv2.circle(image, tuple(_to_int(p)[0, 0]), radius << 4, col, 1, cv2.LINE_AA, shift=4)
        if labels and len(pts):
            x, y = pts[len(pts) // 2]
            cv2.putText(image, cv_text(name.strip()), (int(x) + 4, int(y) - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.35, col, 1, cv2.LINE_AA)
    return image


def caption(image: np.ndarray, text: str) -> np.ndarray:
    """Write ``text`` on a dark band at the top-left (non-ASCII characters as ``?``). In place."""
    text = cv_text(text)
    (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
    cv2.rectangle(image, (0, 0), (tw + 8, th + base + 6), (0, 0, 0), -1)
    cv2.putText(image, text, (4, th + 3), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return image


def contact_sheet(images: list[np.ndarray], columns: int = 4, tile_width: int = 480, gap: int = 4) -> np.ndarray:
    """Tile images (resized to ``tile_width``, aspect kept from the first) into one sheet."""
    if not images:
        raise ValueError("contact_sheet needs at least one image")
    h0, w0 = images[0].shape[:2]
    tile_h = int(round(tile_width * h0 / w0))
    rows = math.ceil(len(images) / columns)
    sheet = np.full((rows * tile_h + (rows + 1) * gap, columns * tile_width + (columns + 1) * gap, 3), 255, np.uint8)
    for i, img in enumerate(images):
        r, c = divmod(i, columns)
        y, x = gap + r * (tile_h + gap), gap + c * (tile_width + gap)
        sheet[y:y + tile_h, x:x + tile_width] = cv2.resize(img, (tile_width, tile_h), interpolation=cv2.INTER_AREA)
    return sheet


def blank_canvas(width: int = 960, height: int = 540) -> np.ndarray:
    """A neutral grey canvas for frames that come without an image (WC14/SN22 annotations)."""
    canvas = np.full((height, width, 3), 72, np.uint8)
    canvas[:, :, 1] = 84
    return canvas
