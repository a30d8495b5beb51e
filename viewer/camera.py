"""An orbit camera: a target point, and the eye on a sphere around it.

The eye sits at ``target + distance * (cos(pitch) sin(yaw), sin(pitch),
cos(pitch) cos(yaw))``: yaw turns about +y (0 puts the eye on +z of the
target), pitch lifts the eye above the target's horizontal plane.  Pitch is
clamped short of the poles (so the view is never straight up or down, which
the scene format forbids), the distance stays in a finite range above 0 (a
zoom never reaches or passes the target), and every operation ignores
non-finite input, so nothing can produce a NaN camera.

Matrices use pyrr's row-vector convention (``v @ M``).  The renderer itself
needs only position, target and fov (the scene's camera); the matrices are
for anything that wants to project points (and for the tests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pyrr

#: Pitch is kept within this many degrees of the horizon (the poles are at 90).
PITCH_LIMIT_DEG = 89.0
#: Closest and farthest the eye may be from the target (world units).
MIN_DISTANCE = 1e-3
MAX_DISTANCE = 1e6
#: Largest target coordinate a pan may reach (keeps float32 uploads finite and precise enough).
MAX_COORD = 1e7


def _finite(*vals: float) -> bool:
    return all(math.isfinite(float(v)) for v in vals)


@dataclass
class OrbitCamera:
    target: tuple[float, float, float] = (0.0, 0.9, 0.0)
    yaw: float = 0.0  # radians
    pitch: float = 0.0  # radians
    distance: float = 5.0
    fov: float = 40.0  # vertical, degrees

    # ------------------------------------------------------------ construction

    @classmethod
    def look_at(cls, position, target, fov: float = 40.0) -> "OrbitCamera":
        """The orbit camera whose eye is at ``position`` looking at ``target``.
        The pitch is kept as it is even beyond PITCH_LIMIT_DEG (a scene may
        look more steeply down than the viewer's orbit allows); orbiting then
        only moves it back toward the horizon."""
        p = np.asarray(position, dtype=np.float64)
        t = np.asarray(target, dtype=np.float64)
        off = p - t
        d = float(np.linalg.norm(off))
        if not (d > 0.0 and math.isfinite(d)):
            raise ValueError("camera position must differ from its target")
        pitch = math.asin(max(-1.0, min(1.0, off[1] / d)))
        yaw = math.atan2(off[0], off[2])
        return cls(tuple(float(x) for x in t), yaw, pitch, min(max(d, MIN_DISTANCE), MAX_DISTANCE), float(fov))

    def copy(self) -> "OrbitCamera":
        return OrbitCamera(self.target, self.yaw, self.pitch, self.distance, self.fov)

    # ------------------------------------------------------------ derived vectors

    @property
    def offset_dir(self) -> np.ndarray:
        """Unit vector from the target to the eye."""
        cp = math.cos(self.pitch)
        return np.array([cp * math.sin(self.yaw), math.sin(self.pitch), cp * math.cos(self.yaw)])

    @property
    def position(self) -> tuple[float, float, float]:
        p = np.asarray(self.target) + self.distance * self.offset_dir
        return (float(p[0]), float(p[1]), float(p[2]))

    @property
    def forward(self) -> np.ndarray:
        return -self.offset_dir

    @property
    def right(self) -> np.ndarray:
        """Unit right vector of the view (horizontal: forward x +y)."""
        return np.array([math.cos(self.yaw), 0.0, -math.sin(self.yaw)])

    @property
    def up(self) -> np.ndarray:
        return np.cross(self.right, self.forward)

    def view_matrix(self) -> np.ndarray:
        """World to view (row vectors, pyrr)."""
        return pyrr.matrix44.create_look_at(np.array(self.position), np.asarray(self.target, dtype=np.float64),
                                            np.array([0.0, 1.0, 0.0]))

    def projection_matrix(self, aspect: float, near: float | None = None, far: float | None = None) -> np.ndarray:
        near = near if near is not None else max(self.distance * 1e-3, 1e-6)
        far = far if far is not None else self.distance * 1e3 + 1.0
        return pyrr.matrix44.create_perspective_projection(self.fov, aspect, near, far)

    def world_per_pixel(self, viewport_height: float) -> float:
        """World units per pixel at the target's depth, for a view this tall."""
        return 2.0 * self.distance * math.tan(math.radians(self.fov) / 2.0) / max(viewport_height, 1.0)

    # ------------------------------------------------------------ operations

    def orbit(self, dyaw: float, dpitch: float) -> None:
        """Turn the eye about the target: yaw by dyaw, pitch by dpitch
        (radians), pitch clamped short of the poles."""
        if not _finite(dyaw, dpitch):
            return
        limit = math.radians(PITCH_LIMIT_DEG)
        lo, hi = min(-limit, self.pitch), max(limit, self.pitch)
        self.pitch = min(max(self.pitch + dpitch, lo), hi)
        self.yaw = math.remainder(self.yaw + dyaw, 2.0 * math.pi)

    def pan(self, dx: float, dy: float) -> None:
        """Move the target (and the eye with it) by dx along the view's right
        vector and dy along its up vector (world units)."""
        if not _finite(dx, dy):
            return
        t = np.asarray(self.target) + dx * self.right + dy * self.up
        if not (np.all(np.isfinite(t)) and np.max(np.abs(t)) <= MAX_COORD):
            return
        self.target = (float(t[0]), float(t[1]), float(t[2]))

    def dolly(self, factor: float) -> None:
        """Scale the distance to the target by ``factor`` (> 0), within
        [MIN_DISTANCE, MAX_DISTANCE]: a zoom never reaches the target."""
        if not (_finite(factor) and factor > 0.0):
            return
        self.distance = min(max(self.distance * factor, MIN_DISTANCE), MAX_DISTANCE)

    def is_valid(self) -> bool:
        return _finite(*self.target, self.yaw, self.pitch, self.distance, self.fov, *self.position) and \
            MIN_DISTANCE <= self.distance <= MAX_DISTANCE
