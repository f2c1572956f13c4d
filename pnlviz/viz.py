"""Overlays on images (OpenCV drawing): the pitch reprojected through a camera, annotated lines,
keypoints, and contact sheets. Images are BGR uint8, as OpenCV reads them."""

from __future__ import annotations

import functools
import math
import zlib
from collections.abc import Mapping

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
        hsv = np.array([[[h, 200, 255]]], np.uint8)
        b, g, r = (int(c) for c in cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0])
        _CLASS_COLOURS[name] = (b, g, r)
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
    for pts in project_polylines(camera, model.sample_polylines(0.5, 0.25), w, h, skip_folded=True).values():
        if len(pts) >= 2:
            cv2.polylines(image, [_to_int(pts)], False, colour, thickness, cv2.LINE_AA, shift=4)
    return image


def draw_annotation(image: np.ndarray, annotation: Mapping[str, np.ndarray], *, normalised: bool = True,
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


#: a label-error finding (pnlviz.calib.qa): the class where the annotation put it, where the
#: judging camera expects it, and the points its fix is about (RGB; the app uses the same)
FINDING_ANNOTATED_RGB = (255, 40, 120)
FINDING_EXPECTED_RGB = (150, 255, 0)


def ring(centre, radius: float, sides: int = 16) -> np.ndarray:
    """A closed polygon of ``sides`` around ``centre`` (a circle drawn as segments)."""
    t = np.linspace(0.0, 2.0 * np.pi, sides + 1)
    return np.asarray(centre, float) + radius * np.stack([np.cos(t), np.sin(t)], axis=1)


def draw_findings(image: np.ndarray, marks, thickness: int = 2) -> np.ndarray:
    """Draw label-error findings (:func:`pnlviz.calib.qa.finding_marks`, pixels of this image):
    the class as annotated (pink), where the camera expects it (green), the fix's points circled
    (green). In place."""
    pink, green = FINDING_ANNOTATED_RGB[::-1], FINDING_EXPECTED_RGB[::-1]
    for m in marks:  # the annotation under, thicker: where the camera agrees, green runs inside pink
        if len(m.annotated) >= 2:
            cv2.polylines(image, [_to_int(m.annotated)], False, pink, thickness + 2, cv2.LINE_AA, shift=4)
        for p in m.annotated:
            cv2.circle(image, tuple(_to_int(p)[0, 0]), 4 << 4, pink, -1, cv2.LINE_AA, shift=4)
        for part in m.expected:
            cv2.polylines(image, [_to_int(part)], False, green, thickness, cv2.LINE_AA, shift=4)
        for p in m.points:
            cv2.polylines(image, [_to_int(ring(p, 8.0))], True, green, thickness, cv2.LINE_AA, shift=4)
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


# ----------------------------------------------------------------------------- the keypoint map
#: the colour of each keypoint set (RGB), the same in the app, its overlays and the keypoint map
SET_RGB = {"Kp": (230, 40, 40), "Kpe": (255, 220, 0), "Kp1": (30, 120, 255), "Kp2": (255, 90, 200),
           "Kp3": (60, 200, 60)}
SET_WORDS = {"Kp": "line-line intersections", "Kpe": "extended-line intersections",
             "Kp1": "line-circle intersections", "Kp2": "circle tangent points", "Kp3": "additional points"}
#: how far the crossbar's corners (2.44 m up, above the posts) are drawn behind the goal line
_CROSSBAR_SHIFT_M = 3.2


def _map_position(xyz: np.ndarray) -> np.ndarray:
    """Where a keypoint is drawn on the top view (metres): itself, except a point above the ground
    (a crossbar corner), drawn behind its goal line so that it does not hide its post."""
    x, y, z = xyz
    return np.array([x + math.copysign(_CROSSBAR_SHIFT_M, x) if z < -0.5 else x, y])


def _free_spot(box_w: int, box_h: int, at: tuple[int, int], taken: list, bounds: tuple[int, int]) -> tuple[int, int]:
    """The top-left corner of a ``box_w`` x ``box_h`` label beside the point ``at`` that overlaps
    no rectangle in ``taken`` (the first of eight places around it that is free, else the first)."""
    x, y = at
    g = 5
    places = [(x + g, y - box_h - g), (x + g, y + g), (x - box_w - g, y - box_h - g), (x - box_w - g, y + g),
              (x - box_w // 2, y - box_h - 2 * g), (x - box_w // 2, y + 2 * g), (x + 2 * g, y - box_h // 2),
              (x - box_w - 2 * g, y - box_h // 2)]
    for px, py in places:
        r = (px, py, px + box_w, py + box_h)
        inside = 0 <= px and px + box_w < bounds[0] and 0 <= py and py + box_h < bounds[1]
        if inside and not any(r[0] < t[2] and t[0] < r[2] and r[1] < t[3] and t[1] < r[3] for t in taken):
            return px, py
    return places[0]


_TOP_GRASS = (40, 92, 46)  # the top view's background (BGR)


def _ground_picture(camera: Camera, picture: np.ndarray, size: tuple[int, int], px_per_m: float,
                    margin: float, step: int = 4) -> np.ndarray:
    """``picture`` (the camera's image) as seen from above on a top-view canvas of ``size``: each
    canvas pixel's ground point projected into it (lens included) on a grid every ``step``
    pixels, the map between grid nodes interpolated (a projection is smooth at that scale)."""
    W, H = size
    gw, gh = W // step + 3, H // step + 3
    # node j sits at canvas pixel (j - 1) * step + (step - 1) / 2: where a linear resize by
    # ``step`` puts it at pixel j * step + (step - 1) / 2, i.e. the canvas shifted by ``step``
    cx = (np.arange(gw) - 1) * step + (step - 1) / 2
    cy = (np.arange(gh) - 1) * step + (step - 1) / 2
    gx, gy = np.meshgrid((cx + 0.5) / px_per_m - 52.5 - margin, (cy + 0.5) / px_per_m - 34 - margin)
    uv = camera.project(np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1))
    ph, pw = picture.shape[:2]
    uv = np.nan_to_num(uv * [pw / camera.width, ph / camera.height], nan=-1e4).clip(-1e4, 1e4).astype(np.float32)
    full = cv2.resize(uv.reshape(gh, gw, 2), (gw * step, gh * step), interpolation=cv2.INTER_LINEAR)
    full = np.ascontiguousarray(full[step:step + H, step:step + W])
    return cv2.remap(np.ascontiguousarray(picture[:, :, :3]), full[..., 0], full[..., 1], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=_TOP_GRASS)


def _top_canvas(model: FieldModel, px_per_m: float, margin: float = 6.0):
    """The pitch seen from above (the far touchline at the top) with ``margin`` metres around it:
    ``(image BGR, px)``, ``px`` mapping pitch metres (N, 2) to image pixels."""
    W, H = int((105 + 2 * margin) * px_per_m), int((68 + 2 * margin) * px_per_m)
    image = np.full((H, W, 3), _TOP_GRASS, np.uint8)

    def px(xy) -> np.ndarray:
        return (np.asarray(xy, float) + [52.5 + margin, 34 + margin]) * px_per_m

    for pts in model.sample_polylines(0.25, 0.1).values():
        ground = np.abs(pts[:, 2]) < 1e-6
        colour = (235, 235, 235) if ground.all() else (170, 170, 170)
        cv2.polylines(image, [_to_int(px(pts[:, :2]))], False, colour, 2, cv2.LINE_AA, shift=4)
    return image, px


@functools.lru_cache(maxsize=8)
def _cached_top_canvas(px_per_m: float):
    """:func:`_top_canvas` of the default pitch model, drawn once per scale (read-only: copy it)."""
    image, px = _top_canvas(load_field_model(), px_per_m)
    image.setflags(write=False)
    return image, px


def top_view(camera: Camera | None = None, *, image: np.ndarray | None = None, points=None, keypoints=None,
             points_pitch=None, model: FieldModel | None = None, px_per_m: float = 8.0) -> np.ndarray:
    """A bird's-eye view of the pitch (BGR uint8, the far touchline at the top): where ``camera``
    sees the ground (its footprint, shaded: :func:`pnlviz.geometry.footprint.ground_footprint`, and
    its position), ``keypoints`` ``{id: (u, v)}`` pixels of its image put on the ground (yellow,
    with their ids), ``points`` (N, 2) pixels put on the ground (players' feet: red discs) and
    ``points_pitch`` (N, 2) pitch positions in metres (a tracker's: red discs too, drawn with or
    without a camera). ``image``: the camera's picture (BGR, any size of its aspect), drawn on the
    ground it sees instead of the shading, the pitch's lines over it at half strength."""
    from pnlviz.geometry.footprint import ground_footprint

    picture = image
    margin = 6.0
    if model is None:
        canvas, px = _cached_top_canvas(float(px_per_m))
        image = canvas.copy()
    else:
        image, px = _top_canvas(model, px_per_m, margin)
    H, W = image.shape[:2]
    if camera is not None:
        polygon = ground_footprint(camera)
        if len(polygon) >= 3:
            seen = np.zeros((H, W), np.uint8)
            # fixed point, pixel centres at +0.5 (as the canvas's own drawing); the reach keeps it in int32
            cv2.fillPoly(seen, [_to_int(px(polygon) - 0.5)], 1, cv2.LINE_8, shift=4)
            mask = seen.astype(bool)
            if picture is not None:
                lines = np.any(image != _TOP_GRASS, axis=2) & mask
                warped = _ground_picture(camera, picture, (W, H), px_per_m, margin)
                image[lines] = (0.5 * image[lines] + 0.5 * warped[lines]).astype(np.uint8)
                image[mask & ~lines] = warped[mask & ~lines]
            else:
                image[mask] = (0.55 * image[mask] + 0.45 * np.array([255, 200, 90])).astype(np.uint8)
            edges = cv2.findContours(seen, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)[0]
            cv2.drawContours(image, edges, -1, (255, 200, 90), 1, cv2.LINE_AA)
        c = px(camera.C[:2])
        inside = 0 <= c[0] < W and 0 <= c[1] < H
        at = tuple(int(v) for v in np.clip(c, 4, [W - 5, H - 5]))
        cv2.circle(image, at, 5, (255, 200, 90), -1 if inside else 2, cv2.LINE_AA)
    if keypoints and camera is not None:
        kids = list(keypoints)
        ground = camera.image_to_pitch(np.array([keypoints[k] for k in kids], float).reshape(-1, 2))
        for kid, xy in zip(kids, ground):
            if np.all(np.isfinite(xy)):
                q = tuple(int(v) for v in px(xy))
                cv2.circle(image, q, 3, (0, 220, 255), -1, cv2.LINE_AA)
                cv2.putText(image, cv_text(str(kid)), (q[0] + 4, q[1] - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.35,
                            (0, 220, 255), 1, cv2.LINE_AA)
    feet = []
    if points is not None and camera is not None:
        feet.append(camera.image_to_pitch(np.asarray(points, float).reshape(-1, 2)))
    if points_pitch is not None:
        feet.append(np.asarray(points_pitch, float).reshape(-1, 2))
    for xy in (np.vstack(feet) if feet else ()):
        if np.all(np.isfinite(xy)) and np.all(np.abs(px(xy)) < 1e6):
            cv2.circle(image, tuple(int(v) for v in px(xy)), 4, (40, 40, 230), -1, cv2.LINE_AA)
    return image


def inset_top_view(image: np.ndarray, camera: Camera, share: float = 0.28) -> np.ndarray:
    """Paste :func:`top_view` of ``camera`` into the bottom-right corner of ``image`` (in place;
    ``share`` of its width, framed), as ``pnlviz render`` does on every frame."""
    h, w = image.shape[:2]
    px_per_m = max(1.0, share * w / 117.0)  # the view is 105 m + 2 x 6 m wide
    inset = top_view(camera, px_per_m=px_per_m)
    ih, iw = inset.shape[:2]
    if ih + 8 > h or iw + 8 > w:
        return image
    y0, x0 = h - ih - 8, w - iw - 8
    cv2.rectangle(image, (x0 - 2, y0 - 2), (x0 + iw + 1, y0 + ih + 1), (20, 20, 20), 2)
    image[y0:y0 + ih, x0:x0 + iw] = inset
    return image


def keypoint_map(model: FieldModel | None = None, *, px_per_m: float = 16.0,
                 highlight: int | None = None, legend: bool = True, text_scale: float | None = None) -> np.ndarray:
    """A top view of the pitch with every keypoint id, coloured by set (:data:`SET_RGB`): the
    picture of PnLCalib's numbering. The far touchline (y < 0, "top" in SoccerNet's names) is at
    the top, the main camera's side at the bottom; the crossbar's corners (2.44 m above the posts)
    are drawn just behind their goal line. ``highlight``: an id drawn larger, ringed; ``legend``:
    the sets' colours and the orientation written along the bottom; ``text_scale``: the ids'
    font scale (default: grows with ``px_per_m``). BGR uint8."""
    model = model or load_field_model()
    legend_h = 56 if legend else 0
    pitch, px = _top_canvas(model, px_per_m)
    image = np.vstack([pitch, np.full((legend_h, pitch.shape[1], 3), (40, 92, 46), np.uint8)])
    H, W = image.shape[:2]
    ids = [int(k) for k in model.keypoint_ids]
    where = {k: px(_map_position(model.keypoints[k].xyz)) for k in ids}
    for k in ids:  # a crossbar corner is joined to the top of its post
        if model.keypoints[k].xyz[2] < -0.5:
            post = px(model.keypoints[k].xyz[:2])
            cv2.line(image, tuple(int(v) for v in post), tuple(int(v) for v in where[k]), (150, 150, 150), 1, cv2.LINE_AA)
    if highlight in where:  # guides across the map through the highlighted id, to find it at a glance
        hx, hy = (int(round(v)) for v in where[highlight])
        cv2.line(image, (0, hy), (W - 1, hy), (0, 215, 255), max(1, int(px_per_m / 8)), cv2.LINE_AA)
        cv2.line(image, (hx, 0), (hx, H - legend_h - 1), (0, 215, 255), max(1, int(px_per_m / 8)), cv2.LINE_AA)
    scale = max(0.4, px_per_m / 26) if text_scale is None else float(text_scale)
    order = sorted(ids, key=lambda k: k == highlight)  # the highlighted one drawn last, on top
    dot = max(3, int(px_per_m * 0.25)) + 2
    taken: list = [(int(p[0]) - dot, int(p[1]) - dot, int(p[0]) + dot, int(p[1]) + dot) for p in where.values()]
    for k in order:
        rgb = SET_RGB.get(model.keypoints[k].group, (255, 255, 255))
        bgr = tuple(int(c) for c in rgb[::-1])
        x, y = (int(round(v)) for v in where[k])
        big = k == highlight
        r = max(3, int(px_per_m * (0.45 if big else 0.25))) + (3 if big else 0)
        cv2.circle(image, (x, y), r, bgr, -1, cv2.LINE_AA)
        cv2.circle(image, (x, y), r, (0, 0, 0), 1, cv2.LINE_AA)
        if big:
            cv2.circle(image, (x, y), 2 * r + 2, (255, 255, 255), 2, cv2.LINE_AA)
        text = str(k)
        s = scale * (1.5 if big else 1.0)
        (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, s, 1 + big)
        tx, ty = _free_spot(tw + 4, th + base + 2, (x, y), taken, (W, H - legend_h))
        taken.append((tx, ty, tx + tw + 4, ty + th + base + 2))
        cv2.rectangle(image, (tx, ty), (tx + tw + 4, ty + th + base + 2), (20, 20, 20), -1)
        cv2.putText(image, text, (tx + 2, ty + th + 1), cv2.FONT_HERSHEY_SIMPLEX, s, bgr, 1 + big, cv2.LINE_AA)
    if not legend:
        return image
    x0 = 8
    for group, rgb in SET_RGB.items():  # the legend, along the bottom
        label = f"{group}: {SET_WORDS[group]}"
        cv2.circle(image, (x0 + 6, H - legend_h + 14), 6, tuple(int(c) for c in rgb[::-1]), -1, cv2.LINE_AA)
        cv2.putText(image, label, (x0 + 16, H - legend_h + 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (240, 240, 240), 1,
                    cv2.LINE_AA)
        x0 += 26 + cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)[0][0]
    note = ("top: the far touchline (y < 0); the main camera looks from the bottom. Crossbar corners (2.44 m up) "
            "are drawn behind their goal line.")
    cv2.putText(image, note, (8, H - 12), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (240, 240, 240), 1, cv2.LINE_AA)
    return image
