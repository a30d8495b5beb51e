"""The scene's pinhole camera in the reference tracer: the primary rays
through each pixel, exactly the spec's formula.

Invariants: float64 throughout; origins are the camera position; directions
are unit; with f the unit direction to the target, right = f x (0, 1, 0)
normalised and up = right x f, pixel (i, j) at sub-pixel offset (u, v)
looks along f + a right + b up, a = (2 (i + u) / W - 1) tan(fov / 2) W / H,
b = (1 - 2 (j + v) / H) tan(fov / 2), row 0 at the top; :func:`camera_rays`
(a whole image at one offset) and :func:`pixel_rays` (chosen pixels at
several offsets) compute it by the same operations in the same order, so
they give bit-identical rays for the same pixel and offset.
"""

from __future__ import annotations

import math

import numpy as np

from ..scene.load import unit_vector
from ..scene.model import Scene
from .vectors import normalize

__all__ = ["camera_rays", "pixel_rays"]


def _camera_basis(scene: Scene):
    cam = scene.camera
    pos = np.array(cam.position, dtype=np.float64)
    # scaled first: target - position may overflow (1e308 and -1e308) or its
    # square underflow (points 1e-300 apart)
    s = max(abs(c) for c in (*cam.target, *cam.position))
    f = np.array(unit_vector([t / s - p / s for t, p in zip(cam.target, cam.position)]))
    right = normalize(np.cross(f, np.array([0.0, 1.0, 0.0])))
    up = np.cross(right, f)
    return pos, f, right, up, math.tan(math.radians(cam.fov) / 2.0)


def camera_rays(scene: Scene, width: int, height: int, offset=(0.5, 0.5)):
    """Primary rays of the spec's pinhole camera: (origins, dirs), each (H, W, 3)."""
    pos, f, right, up, t = _camera_basis(scene)
    u, v = float(offset[0]), float(offset[1])
    i = np.arange(width, dtype=np.float64)
    j = np.arange(height, dtype=np.float64)
    a = (2.0 * (i + u) / width - 1.0) * t * (width / height)
    b = (1.0 - 2.0 * (j + v) / height) * t
    d = f + a[None, :, None] * right + b[:, None, None] * up
    d = normalize(d)
    o = np.broadcast_to(pos, d.shape).copy()
    return o, d


def pixel_rays(scene: Scene, width: int, height: int, pixels, offsets):
    """Camera rays through ``offsets`` (K, 2) of each pixel of ``pixels`` (P,),
    row-major indices j * width + i: (origins, dirs), each (P * K, 3), pixel
    by pixel (the K rays of pixels[0] first); the same formula as
    :func:`camera_rays`."""
    pos, f, right, up, t = _camera_basis(scene)
    pixels = np.asarray(pixels, dtype=np.int64).reshape(-1)
    offs = np.asarray(offsets, dtype=np.float64).reshape(-1, 2)
    i = (pixels % width).astype(np.float64)[:, None] + offs[None, :, 0]
    j = (pixels // width).astype(np.float64)[:, None] + offs[None, :, 1]
    a = ((2.0 * i / width - 1.0) * t * (width / height)).reshape(-1)
    b = ((1.0 - 2.0 * j / height) * t).reshape(-1)
    d = normalize(f + a[:, None] * right + b[:, None] * up)
    return np.broadcast_to(pos, d.shape).copy(), d
