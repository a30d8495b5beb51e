"""The reference tracer's solids: where a ray crosses each object's surface,
and whether a point lies inside its solid.

Every object of the scene format (plane, sphere, box, cylinder, and the
open vessel, a cylinder with ``wall``) is a :class:`Primitive`, made by
:func:`primitive`.  Along rays (O, D), (N, 3) float64 each, a primitive
gives its surface crossings as ``ncols`` "columns" of (t, outward normal):
t = inf where a column has no crossing.  A solid's columns come in
(entry, exit) pairs, the interval(s) of t where the ray is inside it; the
plane (the half-space below its height) has one column.
The vessel is the difference of two convex solids: the outer capped
cylinder minus the inner one, whose axial range starts at ``wall`` and is
unbounded at the open end, so no coincident caps arise.  Containment
excludes the boundary.  Normals point out of the solid, whatever side the
ray comes from; nothing here knows materials, media or epsilons.
"""

from __future__ import annotations

import math

import numpy as np

from ..scene.model import SceneObject
from .vectors import dot, normalize

__all__ = ["Primitive", "primitive", "contains", "rotation_matrix"]

_INF = np.inf
_AXES = {"x": 0, "y": 1, "z": 2}


def rotation_matrix(rotate_deg) -> np.ndarray:
    """Rz @ Ry @ Rx for the spec's box ``rotate`` (degrees, right-handed)."""
    ax, ay, az = (math.radians(float(a)) for a in rotate_deg)
    cx, sx = math.cos(ax), math.sin(ax)
    cy, sy = math.cos(ay), math.sin(ay)
    cz, sz = math.cos(az), math.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]], dtype=np.float64)
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]], dtype=np.float64)
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]], dtype=np.float64)
    return rz @ ry @ rx


def _slab(o: np.ndarray, d: np.ndarray, lo: float, hi: float):
    """Ray parameter interval where lo < o + t d < hi (lo/hi may be infinite)."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inv = 1.0 / d
        ta = (lo - o) * inv
        tb = (hi - o) * inv
    t0 = np.minimum(ta, tb)
    t1 = np.maximum(ta, tb)
    zero = d == 0.0
    if zero.any():
        inside = (o > lo) & (o < hi)
        t0 = np.where(zero, np.where(inside, -_INF, _INF), t0)
        t1 = np.where(zero, np.where(inside, _INF, -_INF), t1)
    return t0, t1


# --------------------------------------------------------------------------- primitives


class Primitive:
    """One object's solid.  ``columns(O, D, normals)`` -> ``ncols`` pairs (t
    (N,), outward normal (N, 3) or None without ``normals``), t = inf where
    the column has no crossing; ``contains(P)`` -> (N,) bool, boundary
    excluded; ``extent()`` -> a bound on the distance of the solid's features
    from the origin (the scene size that scales the tracer's epsilon)."""

    ncols = 2

    def columns(self, O, D, normals=True):  # pragma: no cover - interface
        raise NotImplementedError

    def contains(self, P):  # pragma: no cover - interface
        raise NotImplementedError

    def extent(self) -> float:
        return 0.0


def _interval_columns(t0, t1, hit, n0, n1):
    t0 = np.where(hit, t0, _INF)
    t1 = np.where(hit, t1, _INF)
    return [(t0, n0), (t1, n1)]


class _Plane(Primitive):
    ncols = 1

    def __init__(self, obj: SceneObject):
        self.h = float(obj.height)

    def columns(self, O, D, normals=True):
        dy = D[:, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (self.h - O[:, 1]) / dy
        t = np.where(dy != 0.0, t, _INF)
        n = None
        if normals:
            n = np.zeros_like(O)
            n[:, 1] = 1.0
        return [(t, n)]

    def contains(self, P):
        return P[:, 1] < self.h

    def extent(self):
        return abs(self.h)


class _Sphere(Primitive):
    def __init__(self, obj: SceneObject):
        self.c = np.array(obj.center, dtype=np.float64)
        self.r = float(obj.radius)

    def columns(self, O, D, normals=True):
        oc = O - self.c
        b = dot(oc, D)
        perp = oc - b[:, None] * D
        disc = self.r * self.r - dot(perp, perp)
        hit = disc >= 0.0
        h = np.sqrt(np.maximum(disc, 0.0))
        t0, t1 = -b - h, -b + h
        n0 = n1 = None
        if normals:
            n0 = (oc + t0[:, None] * D) / self.r
            n1 = (oc + t1[:, None] * D) / self.r
            n0 = normalize(n0)
            n1 = normalize(n1)
        return _interval_columns(t0, t1, hit, n0, n1)

    def contains(self, P):
        q = P - self.c
        return dot(q, q) < self.r * self.r

    def extent(self):
        return float(np.linalg.norm(self.c)) + self.r


class _Box(Primitive):
    def __init__(self, obj: SceneObject):
        lo = np.array(obj.min, dtype=np.float64)
        hi = np.array(obj.max, dtype=np.float64)
        self.c = 0.5 * (lo + hi)
        self.h = 0.5 * (hi - lo)
        self.R = rotation_matrix(obj.rotate)  # world = c + R @ local

    def _local(self, P):
        return (P - self.c) @ self.R  # R^T (P - c) for row vectors

    def columns(self, O, D, normals=True):
        o = self._local(O)
        d = D @ self.R
        t0s = np.empty_like(o)
        t1s = np.empty_like(o)
        for k in range(3):
            t0s[:, k], t1s[:, k] = _slab(o[:, k], d[:, k], -self.h[k], self.h[k])
        a0 = np.argmax(t0s, axis=1)
        a1 = np.argmin(t1s, axis=1)
        idx = np.arange(len(O))
        t0 = t0s[idx, a0]
        t1 = t1s[idx, a1]
        hit = t0 <= t1
        n0 = n1 = None
        if normals:
            nl0 = np.zeros_like(o)
            nl1 = np.zeros_like(o)
            nl0[idx, a0] = -np.sign(d[idx, a0])
            nl1[idx, a1] = np.sign(d[idx, a1])
            n0 = nl0 @ self.R.T
            n1 = nl1 @ self.R.T
        return _interval_columns(t0, t1, hit, n0, n1)

    def contains(self, P):
        q = self._local(P)
        return np.all(np.abs(q) < self.h, axis=1)

    def extent(self):
        return float(np.linalg.norm(self.c) + np.linalg.norm(self.h))


def _cyl_interval(O, D, base, a, rr, lo, hi, normals):
    """Interval of a capped cylinder of radius rr about the axis through base along
    world axis a, axial coordinate in [lo, hi] (hi may be inf)."""
    i, j = [k for k in range(3) if k != a]
    o_s = O[:, a] - base[a]
    d_s = D[:, a]
    o_r = np.stack([O[:, i] - base[i], O[:, j] - base[j]], axis=1)
    d_r = np.stack([D[:, i], D[:, j]], axis=1)
    A = dot(d_r, d_r)
    par = A == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        tc = -dot(o_r, d_r) / A
        perp = o_r + tc[:, None] * d_r
        disc = rr * rr - dot(perp, perp)
        half = np.sqrt(np.maximum(disc, 0.0) / A)
    r0, r1 = tc - half, tc + half
    rhit = disc >= 0.0
    if par.any():
        inside = dot(o_r, o_r) < rr * rr
        r0 = np.where(par, np.where(inside, -_INF, _INF), r0)
        r1 = np.where(par, np.where(inside, _INF, -_INF), r1)
        rhit = np.where(par, inside, rhit)
    s0, s1 = _slab(o_s, d_s, lo, hi)
    t0 = np.maximum(r0, s0)
    t1 = np.minimum(r1, s1)
    hit = rhit & (t0 <= t1)
    n0 = n1 = None
    if normals:
        def radial(t):
            with np.errstate(invalid="ignore"):
                q = o_r + np.where(np.isfinite(t), t, 0.0)[:, None] * d_r
                q = q / np.linalg.norm(q, axis=1, keepdims=True)
            n = np.zeros_like(O)
            n[:, i] = q[:, 0]
            n[:, j] = q[:, 1]
            return n

        sgn = np.sign(d_s)
        cap0 = np.zeros_like(O)
        cap0[:, a] = -sgn
        cap1 = np.zeros_like(O)
        cap1[:, a] = sgn
        n0 = np.where((r0 >= s0)[:, None], radial(t0), cap0)
        n1 = np.where((r1 <= s1)[:, None], radial(t1), cap1)
        n0 = np.where(hit[:, None], n0, 0.0)
        n1 = np.where(hit[:, None], n1, 0.0)
    return t0, t1, hit, n0, n1


class _Cylinder(Primitive):
    def __init__(self, obj: SceneObject):
        self.a = _AXES[obj.axis]
        self.base = np.array(obj.base, dtype=np.float64)
        self.r = float(obj.radius)
        self.hgt = float(obj.height)

    def columns(self, O, D, normals=True):
        t0, t1, hit, n0, n1 = _cyl_interval(O, D, self.base, self.a, self.r, 0.0, self.hgt, normals)
        return _interval_columns(t0, t1, hit, n0, n1)

    def _radial2_axial(self, P):
        q = P - self.base
        s = q[:, self.a]
        q = q.copy()
        q[:, self.a] = 0.0
        return dot(q, q), s

    def contains(self, P):
        r2, s = self._radial2_axial(P)
        return (r2 < self.r * self.r) & (s > 0.0) & (s < self.hgt)

    def extent(self):
        return float(np.linalg.norm(self.base)) + self.r + self.hgt


class _Vessel(_Cylinder):
    """Outer capped cylinder [0, height] minus the hole: radius r - wall, axial
    [wall, inf) (the hole runs out through the open +axis end)."""

    ncols = 4

    def __init__(self, obj: SceneObject):
        super().__init__(obj)
        self.w = float(obj.wall)
        self.ri = self.r - self.w

    def columns(self, O, D, normals=True):
        a0, a1, ahit, na0, na1 = _cyl_interval(O, D, self.base, self.a, self.r, 0.0, self.hgt, normals)
        b0, b1, bhit, nb0, nb1 = _cyl_interval(O, D, self.base, self.a, self.ri, self.w, _INF, normals)
        b0 = np.where(bhit, b0, _INF)
        b1 = np.where(bhit, b1, _INF)
        # piece 1: [a0, min(a1, b0)], piece 2: [max(a0, b1), a1]
        p1 = ahit & (a0 < b0)
        p1_end_b = b0 < a1
        p2 = ahit & (b1 < a1)
        p2_start_b = b1 > a0
        t10 = np.where(p1, a0, _INF)
        t11 = np.where(p1, np.where(p1_end_b, b0, a1), _INF)
        t20 = np.where(p2, np.where(p2_start_b, b1, a0), _INF)
        t21 = np.where(p2, a1, _INF)
        n10 = n11 = n20 = n21 = None
        if normals:
            n10 = na0
            n11 = np.where(p1_end_b[:, None], -nb0, na1)
            n20 = np.where(p2_start_b[:, None], -nb1, na0)
            n21 = na1
        return [(t10, n10), (t11, n11), (t20, n20), (t21, n21)]

    def contains(self, P):
        r2, s = self._radial2_axial(P)
        outer = (r2 < self.r * self.r) & (s > 0.0) & (s < self.hgt)
        hole = (r2 < self.ri * self.ri) & (s > self.w)
        return outer & ~hole


def primitive(obj: SceneObject) -> Primitive:
    """The solid of a scene object."""
    if obj.type == "plane":
        return _Plane(obj)
    if obj.type == "sphere":
        return _Sphere(obj)
    if obj.type == "box":
        return _Box(obj)
    if obj.type == "cylinder":
        return _Vessel(obj) if obj.wall is not None else _Cylinder(obj)
    raise ValueError(f"unknown object type {obj.type!r}")


def contains(obj: SceneObject, points) -> np.ndarray:
    """Whether each point lies inside the solid of ``obj`` (boundary excluded)."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return primitive(obj).contains(P)
