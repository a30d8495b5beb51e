"""The shapes' geometry in float64, as the GPU side needs it before a draw:
rotations, point-in-solid (the eye's starting medium), bounding spheres (the
block's per-object bounds, culling) and the scene's size (its epsilons).
"""

from __future__ import annotations

import math

import numpy as np

from ..scene.model import Scene, SceneObject


AXES = {"x": 0, "y": 1, "z": 2}


def rotation_world_from_local(deg: tuple[float, float, float]) -> np.ndarray:
    """Rz @ Ry @ Rx, right-handed, angles in degrees (x applied first)."""
    ax, ay, az = (math.radians(a) for a in deg)
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def contains_point(obj: SceneObject, p: np.ndarray) -> bool:
    """Strict point-in-solid in float64 (used for the eye's starting medium)."""
    p = np.asarray(p, dtype=np.float64)
    if obj.type == "plane":
        return bool(p[1] < obj.height)
    # distances by hypot, not squares: a valid radius may be 1e200
    if obj.type == "sphere":
        return bool(math.hypot(*(p / 2 - np.array(obj.center) / 2)) < obj.radius / 2)
    if obj.type == "box":
        c = (np.array(obj.min) + np.array(obj.max)) / 2
        half = (np.array(obj.max) - np.array(obj.min)) / 2
        q = rotation_world_from_local(obj.rotate).T @ (p - c)
        return bool(np.all(np.abs(q) < half))
    ax = AXES[obj.axis]
    q = p / 2 - np.array(obj.base) / 2                  # halves: no overflow
    along = q[ax]
    rho = math.hypot(*np.delete(q, ax))
    inside = rho < obj.radius / 2 and 0 < along < obj.height / 2
    if obj.wall is not None:
        ri = obj.radius - obj.wall
        inside = inside and not (rho < ri / 2 and along > obj.wall / 2)
    return inside


def scene_scale(scene: Scene) -> float:
    """A length for the scene: bounded objects' extent and the camera distance."""
    return max(scene_extent(scene), 1e-30)


def scene_extent(scene: Scene) -> float:
    """The largest extent along x, y or z of the eye, the target and the
    bounded objects (inf where it overflows)."""
    eye = np.array(scene.camera.position)
    pts = [eye, np.array(scene.camera.target)]
    for o in scene.objects:
        if o.type == "sphere":
            pts += [np.array(o.center) - o.radius, np.array(o.center) + o.radius]
        elif o.type == "box":
            pts += [np.array(o.min), np.array(o.max)]
        elif o.type == "cylinder":
            pts += [np.array(o.base) - o.radius, np.array(o.base) + o.radius + o.height]
    pts = np.array(pts)
    with np.errstate(over="ignore"):        # a box 1e308 across: inf (not drawn faithfully anyway)
        return float(np.max(pts.max(axis=0) - pts.min(axis=0)))


def bounding_sphere(obj: SceneObject, eye: np.ndarray) -> tuple[float, float, float, float]:
    """Camera-relative centre and radius (padded by 1e-4 relative, so float32
    rounding never rejects a true hit); radius -1 for the unbounded plane."""
    if obj.type == "plane":
        return (0.0, 0.0, 0.0, -1.0)
    if obj.type == "sphere":
        c, r = np.array(obj.center), obj.radius
    elif obj.type == "box":
        lo, hi = np.array(obj.min), np.array(obj.max)
        with np.errstate(over="ignore"):    # as in scene_scale
            c, r = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2   # rotation about c keeps it
    else:
        axis = np.zeros(3)
        axis[AXES[obj.axis]] = 1.0
        c = np.array(obj.base) + axis * obj.height / 2
        r = math.hypot(obj.radius, obj.height / 2)
    return (*(c - eye), r * (1 + 1e-4))
