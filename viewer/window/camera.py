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
import sys
from dataclasses import dataclass

import numpy as np
import pyrr

#: Pitch is kept within this many degrees of the horizon (the poles are at 90).
PITCH_LIMIT_DEG = 89.0
#: Closest and farthest the eye may be from the target (world units) ...
MIN_DISTANCE = 1e-3
MAX_DISTANCE = 1e6
#: ... and the largest target coordinate a pan may reach (keeps float32
#: uploads finite and precise enough), for a scene whose camera starts about
#: REFERENCE_DISTANCE from its target; a scene 2^k times as large has them
#: times 2^k (limits_for).
MAX_COORD = 1e7
REFERENCE_DISTANCE = 5.0
#: The eye, as float64 rounds it, must lie within this fraction of the
#: distance of where the camera means it to be (else the operation is refused).
#: Loose: beside coordinates of 1e15 float64 spaces points 0.125 apart, and
#: an eye 5 units from its target there is still a fine view.
REALISED_TOLERANCE = 0.25
#: The scene format's smallest angle between the view and +y or -y (degrees).
FORMAT_POLE_DEG = 0.01


def _finite(*vals: float) -> bool:
    return all(math.isfinite(float(v)) for v in vals)


@dataclass
class OrbitCamera:
    target: tuple[float, float, float] = (0.0, 0.9, 0.0)
    yaw: float = 0.0  # radians
    pitch: float = 0.0  # radians
    distance: float = 5.0
    fov: float = 40.0  # vertical, degrees
    min_distance: float = MIN_DISTANCE
    max_distance: float = MAX_DISTANCE
    max_coord: float = MAX_COORD

    # ------------------------------------------------------------ construction

    @staticmethod
    def limits_for(position, target) -> tuple[float, float, float]:
        """(min_distance, max_distance, max_coord) for a scene whose camera
        starts at ``position`` looking at ``target``: MIN_DISTANCE,
        MAX_DISTANCE and MAX_COORD times the power of two nearest to the
        starting distance over REFERENCE_DISTANCE (so 1 for a scene of
        ordinary size, whose limits stay as they were; a power of two, so a
        scene scaled by one has exactly the scaled limits), and max_coord at
        least twice the target's largest coordinate (a scene placed far from
        the origin can still be panned)."""
        p = np.asarray(position, dtype=np.float64)
        t = np.asarray(target, dtype=np.float64)
        d = math.hypot(*(p - t))
        if not (d > 0.0 and math.isfinite(d)):
            return MIN_DISTANCE, MAX_DISTANCE, MAX_COORD
        k = round(math.log2(d) - math.log2(REFERENCE_DISTANCE))   # (d / 5 underflows for d = 5e-324)
        k = max(-1100, min(k, 1000))                              # (ldexp overflows past 2^1024)
        # the starting distance is always within the limits, which stay
        # finite and above 0 (the smallest float at the bottom)
        lo = max(min(math.ldexp(MIN_DISTANCE, k), d), math.ulp(0.0))
        hi = max(math.ldexp(MAX_DISTANCE, k), d)
        t_max = float(np.max(np.abs(t))) if np.all(np.isfinite(t)) else 0.0
        max_coord = min(max(math.ldexp(MAX_COORD, k), 2.0 * t_max), sys.float_info.max)
        return lo, hi, max_coord

    @classmethod
    def look_at(cls, position, target, fov: float = 40.0, limits=None) -> "OrbitCamera":
        """The orbit camera whose eye is at ``position`` looking at ``target``.
        The pitch is kept as it is even beyond PITCH_LIMIT_DEG (a scene may
        look more steeply down than the viewer's orbit allows); orbiting then
        only moves it back toward the horizon.  ``limits``: (min_distance,
        max_distance, max_coord), default limits_for(position, target)."""
        p = np.asarray(position, dtype=np.float64)
        t = np.asarray(target, dtype=np.float64)
        off = p - t
        # hypot, not a sum of squares: those of a camera 1e-170 from its
        # target vanish (the format allows any distance above 0)
        d = math.hypot(*off)
        if not (d > 0.0 and math.isfinite(d)):
            raise ValueError("camera position must differ from its target")
        lo, hi, max_coord = cls.limits_for(p, t) if limits is None else limits
        pitch = math.asin(max(-1.0, min(1.0, off[1] / d)))
        yaw = math.atan2(off[0], off[2])
        return cls(tuple(float(x) for x in t), yaw, pitch, min(max(d, lo), hi), float(fov), lo, hi, max_coord)

    @property
    def limits(self) -> tuple[float, float, float]:
        return (self.min_distance, self.max_distance, self.max_coord)

    def copy(self) -> "OrbitCamera":
        return OrbitCamera(self.target, self.yaw, self.pitch, self.distance, self.fov, *self.limits)

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

    def realised(self) -> bool:
        """True when the eye, as float64 rounds ``target + distance * dir``,
        makes the camera meant: not on the target, not past it, not past a
        pole (the view turned upside down), not within FORMAT_POLE_DEG of
        straight up or down (a camera the format forbids), and within
        REALISED_TOLERANCE of the distance of where it should be.  Only an
        eye very near a target far from the origin can fail (at 1e-3 from a
        target at 1e15 it lands on the target)."""
        t = np.asarray(self.target, dtype=np.float64)
        off = np.asarray(self.position, dtype=np.float64) - t
        d = math.hypot(*off)
        if not (math.isfinite(d) and d > 0.0):
            return False
        meant = self.offset_dir
        if math.hypot(*(off - self.distance * meant)) > REALISED_TOLERANCE * self.distance:
            return False
        if abs(off[1]) / d > math.cos(math.radians(FORMAT_POLE_DEG)):
            return False
        # the same side of the pole: the horizontal part points the way yaw says
        return float(off[0] * meant[0] + off[2] * meant[2]) > 0.0

    def _apply(self, **state) -> bool:
        """Take the new state, or keep the old one where the eye would not be
        realised (see realised); True when taken."""
        old = {k: getattr(self, k) for k in state}
        for k, v in state.items():
            setattr(self, k, v)
        if self.realised():
            return True
        for k, v in old.items():
            setattr(self, k, v)
        return False

    def orbit(self, dyaw: float, dpitch: float) -> None:
        """Turn the eye about the target: yaw by dyaw, pitch by dpitch
        (radians), pitch clamped short of the poles."""
        if not _finite(dyaw, dpitch):
            return
        limit = math.radians(PITCH_LIMIT_DEG)
        lo, hi = min(-limit, self.pitch), max(limit, self.pitch)
        self._apply(pitch=min(max(self.pitch + dpitch, lo), hi),
                    yaw=math.remainder(self.yaw + dyaw, 2.0 * math.pi))

    def pan(self, dx: float, dy: float) -> None:
        """Move the target (and the eye with it) by dx along the view's right
        vector and dy along its up vector (world units)."""
        if not _finite(dx, dy):
            return
        t = np.asarray(self.target) + dx * self.right + dy * self.up
        if not (np.all(np.isfinite(t)) and np.max(np.abs(t)) <= self.max_coord):
            return
        self._apply(target=(float(t[0]), float(t[1]), float(t[2])))

    def dolly(self, factor: float) -> None:
        """Scale the distance to the target by ``factor`` (> 0), within
        [min_distance, max_distance]: a zoom never reaches the target."""
        if not (_finite(factor) and factor > 0.0):
            return
        self._apply(distance=min(max(self.distance * factor, self.min_distance), self.max_distance))

    def is_valid(self) -> bool:
        return _finite(*self.target, self.yaw, self.pitch, self.distance, self.fov, *self.position) and \
            self.min_distance <= self.distance <= self.max_distance
