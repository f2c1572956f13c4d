"""What the app draws on a frame: annotated lines, keypoints coloured by set, the pitch projected
through the initial (voted) and the refined camera, and residual vectors."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from pnlviz.app.state import FrameView
from pnlviz.viz import blank_canvas, caption, draw_annotation, draw_pitch

#: BGR colours of the keypoint sets, as in the paper's figure (Kp red, Kpe yellow, Kp1 blue,
#: Kp2 pink, Kp3 green).
SET_BGR = {"Kp": (40, 40, 230), "Kpe": (0, 220, 255), "Kp1": (255, 120, 30), "Kp2": (200, 90, 255), "Kp3": (60, 200, 60)}
INITIAL_BGR = (255, 200, 0)  # cyan-blue: pitch through the voted camera, before PnL
REFINED_BGR = (60, 220, 255)  # amber: pitch through the final camera
RESIDUAL_BGR = (0, 0, 255)
DETECTED_BGR = (255, 255, 255)  # white: detected line extremities
REFERENCE_BGR = (255, 80, 255)  # magenta: pitch through a known camera (synthetic ground truth)


@dataclass
class Layers:
    annotation: bool = True
    keypoints: bool = True
    ids: bool = False
    initial_pitch: bool = True
    refined_pitch: bool = True
    residuals: bool = True
    reference_pitch: bool = True
    detected_lines: bool = True


def render(view: FrameView, image: np.ndarray | None, layers: Layers = Layers(), max_width: int = 1280) -> np.ndarray:
    """The frame (``image``, BGR, or a neutral canvas when None) with overlays, RGB uint8 for the
    browser, at most ``max_width`` wide."""
    W, H = view.size
    img = image.copy() if image is not None else blank_canvas(W, H)
    res = view.result
    if layers.reference_pitch and view.reference_camera is not None:
        draw_pitch(img, view.reference_camera, colour=REFERENCE_BGR, thickness=1)
    if res is not None and res.ok:
        if layers.initial_pitch and res.initial_camera is not None:
            draw_pitch(img, res.initial_camera, colour=INITIAL_BGR, thickness=1)
        if layers.refined_pitch:
            draw_pitch(img, res.camera, colour=REFINED_BGR, thickness=2)
    if layers.annotation and view.annotation:
        draw_annotation(img, view.annotation, thickness=1, radius=2)
    obs = view.observations
    if view.detections is not None and layers.detected_lines:
        # the detector's line extremities (PnLCalib format: x_px = x W)
        for x1, y1, p1, x2, y2, p2 in view.detections.lines_px(W, H).values():
            a, b = (int(round(x1)), int(round(y1))), (int(round(x2)), int(round(y2)))
            cv2.line(img, a, b, DETECTED_BGR, 2, cv2.LINE_AA)
            for p in (a, b):
                cv2.drawMarker(img, p, DETECTED_BGR, cv2.MARKER_TILTED_CROSS, 10, 2, cv2.LINE_AA)
    if obs is not None and layers.keypoints and obs.n_keypoints:
        proj = None
        if res is not None and res.ok:
            proj, _ = res.camera.project(obs.kp_xyz)
        for i, (k, (x, y), s) in enumerate(zip(obs.kp_ids, obs.kp_xy, obs.kp_sets)):
            col = SET_BGR.get(str(s), (255, 255, 255))
            c = (int(round(x)), int(round(y)))
            if layers.residuals and proj is not None and np.all(np.isfinite(proj[i])):
                cv2.line(img, c, (int(round(proj[i, 0])), int(round(proj[i, 1]))), RESIDUAL_BGR, 1, cv2.LINE_AA)
            cv2.circle(img, c, 5, (0, 0, 0), 2, cv2.LINE_AA)
            cv2.circle(img, c, 4, col, -1, cv2.LINE_AA)
            if layers.ids:
                cv2.putText(img, str(k), (c[0] + 6, c[1] - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 3, cv2.LINE_AA)
                cv2.putText(img, str(k), (c[0] + 6, c[1] - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.45, col, 1, cv2.LINE_AA)
    if view.error or (res is not None and not res.ok):
        caption(img, f"{view.stem}: {view.error or res.failure}")
    if W > max_width:
        img = cv2.resize(img, (max_width, int(round(H * max_width / W))), interpolation=cv2.INTER_AREA)
    return img[:, :, ::-1].copy()
