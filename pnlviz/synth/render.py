"""Broadcast-like rendering of a synthetic frame by per-pixel ray casting (vectorised numpy).

Every pixel centre gets a world ray (:mod:`pnlviz.synth.raycast`). Layers, back to front:

1. background, the nearest of: the ground plane z = 0 (grass with mowing stripes, lighting, a
   world-space noise texture and the painted markings: :mod:`pnlviz.synth.ground`), the
   advertising boards, the stands or the sky (:mod:`pnlviz.synth.backdrop`);
2. sprites drawn in depth order, farthest first: goal nets, posts and crossbars, and players
   (:mod:`pnlviz.synth.sprites`);
3. camera effects (here): optical blur, optional motion blur, vignetting, colour gain, sensor
   noise. JPEG compression happens when the frame is written.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from pnlviz.geometry.camera import Camera

from .backdrop import BOARD, GROUND, SKY, STAND, paint_background, surfaces
from .ground import ground_colour, player_shadows
from .raycast import F32, ray_grid
from .scene import Scene, sample_scene
from .sprites import Canvas, draw_sprites


@dataclass
class RenderResult:
    image: np.ndarray  # (H, W, 3) uint8, BGR
    surface: np.ndarray  # (H, W) uint8: SKY, GROUND, BOARD or STAND (what the background shows)
    occluder: np.ndarray  # (H, W) float32: opacity of the goals and players drawn over it
    scene: Scene


def camera_effects(image: np.ndarray, scene: Scene, rng: np.random.Generator) -> np.ndarray:
    """What the broadcast camera does to the rendered light: blur (optical, and motion where the
    scene says so), vignetting, colour gain and sensor noise; BGR float (0..1) in, uint8 out."""
    look = scene.look
    H, W = image.shape[:2]
    img: np.ndarray = cv2.GaussianBlur(image, (0, 0), look.blur_sigma)  # float, as ``image``
    if look.motion_blur is not None:
        # A line kernel of odd size, point-symmetric about its centre pixel: blurs without
        # shifting the image (the markings stay centred on the ground truth).
        length, angle = look.motion_blur
        size = length | 1
        c = size // 2
        k = np.zeros((size, size), F32)
        for s in np.linspace(-c, c, 4 * size):
            k[c + int(math.floor(s * math.sin(angle) + 0.5)), c + int(math.floor(s * math.cos(angle) + 0.5))] = 1.0
        k += k[::-1, ::-1]
        img = cv2.filter2D(img, -1, k / k.sum(), borderType=cv2.BORDER_REFLECT)
    if look.vignette > 0:
        u = (np.arange(W, dtype=F32) - W / 2) / F32(W / 2)
        v = (np.arange(H, dtype=F32) - H / 2) / F32(W / 2)
        vig = F32(1.0) - F32(look.vignette) * (u[None, :] ** 2 + v[:, None] ** 2) / F32(1.3)
        img *= vig[:, :, None]
    img *= look.gain[None, None, :] * F32(255.0)
    noise = rng.standard_normal((H, W), dtype=F32) * F32(look.noise_sigma)
    img += noise[:, :, None]
    return np.clip(img + F32(0.5), 0, 255).astype(np.uint8)



def render(camera: Camera, rng: np.random.Generator, scene: Scene | None = None) -> RenderResult:
    """Render a broadcast-like frame of ``camera.width`` x ``camera.height`` seen by ``camera``.

    The random stadium and look are drawn from ``rng`` (or given as ``scene``); the result keeps
    the per-pixel surface ids and the opacity of occluders (players and goals) for tests.
    """
    if scene is None:
        scene = sample_scene(camera, rng)
    d = ray_grid(camera)
    surf, t_bg, t_ground, info, starts = surfaces(camera, scene, d)
    image, X, Y, _ = ground_colour(camera, scene, d, t_ground)
    player_shadows(camera, scene, X, Y, image)
    paint_background(image, camera, scene, d, surf, t_bg, info, starts)
    canvas = Canvas(camera, d, image, t_bg)
    draw_sprites(canvas, scene)
    out = camera_effects(image, scene, rng)
    return RenderResult(image=out, surface=surf, occluder=canvas.occ, scene=scene)


def render_frame(camera: Camera, rng: np.random.Generator) -> np.ndarray:
    """BGR uint8 image (camera.height, camera.width, 3) of a random broadcast-like scene."""
    return render(camera, rng).image


__all__ = ["render", "render_frame", "RenderResult", "ray_grid", "SKY", "GROUND", "BOARD", "STAND"]
