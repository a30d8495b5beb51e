"""An independent float64 NumPy reference tracer, written from the scene-format
specification (``shared/spec/scene-format.md``) alone.

It is the ground truth the GPU shader is compared with, so it favours clarity
and exactness over speed, but it is vectorised over rays: the Whitted ray tree
is processed as a wavefront (batches of rays with their throughput, depth and
pixel index), never with per-pixel Python loops.

Conventions (all arrays float64):

* ``render_reference(scene, W, H, samples=None, seed=0)`` -> (H, W, 3) linear
  RGB, exposure applied, not clamped, row 0 at the top.
* ``render_reference_refined(scene, W, H, samples, max_samples, tolerance)``
  -> (image, samples per pixel): ``max_samples`` where the first ``samples``
  disagree by more than ``tolerance``.
* ``camera_rays(scene, W, H, offset=(0.5, 0.5))`` -> (origins, dirs), each
  (H, W, 3), dirs unit, exactly the spec's pinhole formula.
* ``trace(scene, origins, dirs)`` -> (N, 3) radiance (no exposure) of arbitrary
  rays; each ray starts in the medium that contains its origin.
* ``first_hit(scene, origins, dirs)`` -> (t, obj_index, outward normal) of the
  first geometric surface, media ignored (t = inf, index -1 when none).
* ``fresnel_dielectric(cos_i, n1, n2)`` exact unpolarised reflectance, 1 under
  total internal reflection; ``refract(d, n, n1, n2)`` -> (dirs, ok).
* ``medium_at(scene, points)`` -> index of the first transparent object whose
  solid contains each point (-1: air); ``contains(obj, points)``.

How surfaces are found.  Every solid is described, along a ray, by the
interval(s) of t where the ray is inside it (the vessel as the difference of
two convex solids: the outer capped cylinder minus the inner one, whose axial
range starts at ``wall`` and is unbounded at the open end, so no coincident
caps arise).  The endpoints of those intervals are the surface crossings.  At
the nearest crossings (grouped within a small epsilon, so coincident surfaces
are found together) an opaque surface, if any, is the interaction; otherwise
the medium on the far side is found by point containment at the middle of the
next stretch of the ray, and the crossing is an interaction only where it
differs from the medium the ray travels in (itself found by containment at the
middle of its first stretch).  A new ray starts exactly at its interaction
point and ignores crossings closer than the epsilon, which scales with the
scene size and the point's magnitude (about 1e-7 of them: far below the
thinnest feature, far above float64 error).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..base.imageio import read_picture_encoded  # 16-bit colour PNGs at full depth
from ..base.sampling import sample_offsets
from ..scene.model import Scene, SceneObject
from ..scene.load import unit_vector

__all__ = [
    "render_reference", "render_reference_refined", "camera_rays", "pixel_rays", "trace", "first_hit",
    "fresnel_dielectric", "refract", "medium_at", "contains", "rotation_matrix", "sky_radiance", "EPS_REL",
]

EPS_REL = 1e-7          # secondary-ray offset / coincidence tolerance, relative to the scene size
CHUNK = 1 << 15         # rays per wavefront batch (bounds memory of deep ray trees)
_INF = np.inf
_AXES = {"x": 0, "y": 1, "z": 2}


# --------------------------------------------------------------------------- small helpers


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def _normalize(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _transmittance(a: np.ndarray, s: np.ndarray) -> np.ndarray:
    """exp(-a s) per channel; a (N,3) >= 0, s (N,) >= 0 possibly inf (0 * inf -> 1)."""
    s = np.asarray(s, dtype=np.float64)[:, None]
    with np.errstate(invalid="ignore", over="ignore"):
        out = np.exp(-a * s)
    return np.where(a == 0.0, 1.0, out)


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
# Each primitive gives, for rays (O, D), "columns" of surface crossings: (t, outward
# normal), t = inf where the column has no crossing; and a point-containment test.


class _Prim:
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


class _Plane(_Prim):
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


class _Sphere(_Prim):
    def __init__(self, obj: SceneObject):
        self.c = np.array(obj.center, dtype=np.float64)
        self.r = float(obj.radius)

    def columns(self, O, D, normals=True):
        oc = O - self.c
        b = _dot(oc, D)
        perp = oc - b[:, None] * D
        disc = self.r * self.r - _dot(perp, perp)
        hit = disc >= 0.0
        h = np.sqrt(np.maximum(disc, 0.0))
        t0, t1 = -b - h, -b + h
        n0 = n1 = None
        if normals:
            n0 = (oc + t0[:, None] * D) / self.r
            n1 = (oc + t1[:, None] * D) / self.r
            n0 = _normalize(n0)
            n1 = _normalize(n1)
        return _interval_columns(t0, t1, hit, n0, n1)

    def contains(self, P):
        q = P - self.c
        return _dot(q, q) < self.r * self.r

    def extent(self):
        return float(np.linalg.norm(self.c)) + self.r


class _Box(_Prim):
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
    A = _dot(d_r, d_r)
    par = A == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        tc = -_dot(o_r, d_r) / A
        perp = o_r + tc[:, None] * d_r
        disc = rr * rr - _dot(perp, perp)
        half = np.sqrt(np.maximum(disc, 0.0) / A)
    r0, r1 = tc - half, tc + half
    rhit = disc >= 0.0
    if par.any():
        inside = _dot(o_r, o_r) < rr * rr
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


class _Cylinder(_Prim):
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
        return _dot(q, q), s

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


def _prim(obj: SceneObject) -> _Prim:
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
    return _prim(obj).contains(P)


# --------------------------------------------------------------------------- sky


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _read_pfm(path: Path) -> np.ndarray:
    data = path.read_bytes()
    pos = 0
    tokens = []
    while len(tokens) < 4:  # "PF"/"Pf", width, height, scale, separated by whitespace
        while data[pos:pos + 1].isspace():
            pos += 1
        start = pos
        while not data[pos:pos + 1].isspace():
            pos += 1
        tokens.append(data[start:pos].decode("ascii"))
    pos += 1  # the single whitespace character after the scale
    kind, w, h, scale = tokens[0], int(tokens[1]), int(tokens[2]), float(tokens[3])
    ch = 3 if kind == "PF" else 1
    dtype = "<f4" if scale < 0 else ">f4"
    img = np.frombuffer(data, dtype=dtype, count=w * h * ch, offset=pos).astype(np.float64)
    img = img.reshape(h, w, ch)[::-1]  # PFM rows run bottom to top
    if ch == 1:
        img = np.repeat(img, 3, axis=2)
    return np.ascontiguousarray(img)


_SKY_CACHE: dict = {}


def _load_sky_image(path: Path) -> np.ndarray:
    path = Path(path)
    key = (str(path.resolve()), path.stat().st_mtime_ns)
    if key not in _SKY_CACHE:
        if path.suffix.lower() == ".pfm":
            img = _read_pfm(path)
        else:
            img = _srgb_to_linear(read_picture_encoded(path))
        _SKY_CACHE[key] = img
    return _SKY_CACHE[key]


def _sample_equirect(img: np.ndarray, D: np.ndarray) -> np.ndarray:
    h, w = img.shape[:2]
    u = 0.5 + np.arctan2(D[:, 0], -D[:, 2]) / (2.0 * math.pi)
    v = np.arccos(np.clip(D[:, 1], -1.0, 1.0)) / math.pi
    x = u * w - 0.5
    y = v * h - 0.5
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    xa = np.mod(x0, w)
    xb = np.mod(x0 + 1, w)
    ya = np.clip(y0, 0, h - 1)
    yb = np.clip(y0 + 1, 0, h - 1)
    top = img[ya, xa] * (1 - fx) + img[ya, xb] * fx
    bot = img[yb, xa] * (1 - fx) + img[yb, xb] * fx
    return top * (1 - fy) + bot * fy


def sky_radiance(scene: Scene, dirs) -> np.ndarray:
    """What a ray with unit direction d that leaves the scene sees, (N, 3)."""
    D = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    sky = scene.sky
    if sky.type == "color":
        return np.broadcast_to(np.array(sky.color, dtype=np.float64), D.shape).copy()
    if sky.type == "gradient":
        t = np.maximum(D[:, 1], 0.0)[:, None]
        return np.array(sky.horizon) * (1.0 - t) + np.array(sky.zenith) * t
    if sky.type == "image":
        path = sky.image_path if sky.image_path is not None else Path(sky.image)
        return _sample_equirect(_load_sky_image(path), D)
    raise ValueError(f"unknown sky type {sky.type!r}")


# --------------------------------------------------------------------------- Fresnel


def fresnel_dielectric(cos_i, n1, n2) -> np.ndarray:
    """Exact unpolarised Fresnel reflectance for a ray in a medium of ior n1
    meeting one of ior n2 at incidence cosine cos_i (>= 0); 1 under total
    internal reflection, exactly 0 where n1 == n2."""
    cos_i = np.clip(np.asarray(cos_i, dtype=np.float64), 0.0, 1.0)
    n1 = np.asarray(n1, dtype=np.float64)
    n2 = np.asarray(n2, dtype=np.float64)
    eta = n1 / n2
    sin_t2 = eta * eta * (1.0 - cos_i * cos_i)
    tir = sin_t2 >= 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin_t2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
        rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)
        R = 0.5 * (rs * rs + rp * rp)
    R = np.where(tir, 1.0, R)
    R = np.where(n1 == n2, 0.0, R)
    return R


def refract(d, n, n1, n2):
    """Snell refraction of unit directions d at unit normals n (either
    orientation) from ior n1 into n2.  Returns (dirs, ok); ok is False under
    total internal reflection (dirs then 0).  Where n1 == n2 the direction is
    d itself."""
    d = np.asarray(d, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(n, dtype=np.float64).reshape(-1, 3)
    n1 = np.broadcast_to(np.asarray(n1, dtype=np.float64), (len(d),))
    n2 = np.broadcast_to(np.asarray(n2, dtype=np.float64), (len(d),))
    nf = np.where((_dot(n, d) > 0.0)[:, None], -n, n)  # facing the incoming ray
    cos_i = np.clip(-_dot(nf, d), 0.0, 1.0)
    eta = n1 / n2
    k = 1.0 - eta * eta * (1.0 - cos_i * cos_i)
    ok = k >= 0.0
    t = eta[:, None] * d + (eta * cos_i - np.sqrt(np.maximum(k, 0.0)))[:, None] * nf
    t = _normalize(np.where(ok[:, None], t, d))
    t = np.where((n1 == n2)[:, None], d, t)
    t = np.where(ok[:, None], t, 0.0)
    return t, ok


# --------------------------------------------------------------------------- scene context


class _Ctx:
    """Everything about a scene in array form."""

    def __init__(self, scene: Scene):
        self.scene = scene
        objs = scene.objects
        self.prims = [_prim(o) for o in objs]
        mats = [scene.materials[o.material] for o in objs]
        n = len(objs)
        self.n = n
        # per object arrays with one extra entry at the end for "air / none", so
        # that index -1 reads air
        def arr(fn, dim=None, air=0.0):
            shape = (n + 1,) if dim is None else (n + 1, dim)
            a = np.full(shape, air, dtype=np.float64)
            for k, m in enumerate(mats):
                a[k] = fn(m)
            return a

        self.color = arr(lambda m: m.color, 3)
        self.emission = arr(lambda m: m.emission, 3)
        self.ka = arr(lambda m: m.ambient)
        self.kd = arr(lambda m: m.diffuse)
        self.ks = arr(lambda m: m.specular)
        self.shin = arr(lambda m: m.shininess, air=1.0)
        self.refl = arr(lambda m: m.reflectivity)
        self.transp = arr(lambda m: m.transparency)
        self.ior = arr(lambda m: m.ior, air=1.0)
        self.absorb = arr(lambda m: m.absorption, 3)
        self.has_ck = np.array([m.checker is not None for m in mats] + [False])
        self.ck_size = arr(lambda m: m.checker.size if m.checker else 1.0, air=1.0)
        self.ck_color = arr(lambda m: m.checker.color if m.checker else (0, 0, 0), 3)
        self.ck_emis = arr(lambda m: (m.checker.emission if m.checker and m.checker.emission is not None
                                      else m.emission), 3)
        self.transparent = [k for k, m in enumerate(mats) if m.transparency > 0.0]
        # one column per surface crossing; columns in object order
        col_obj = []
        for k, p in enumerate(self.prims):
            col_obj += [k] * p.ncols
        self.col_obj = np.array(col_obj, dtype=np.int64)
        self.col_opq = np.array([self.transp[k] == 0.0 for k in col_obj], dtype=bool)
        self.K = len(col_obj)
        # scene size for the epsilon, and the step past a ray's last crossing
        # at which its medium is probed: no absolute floor or step, so that
        # the tracer is scale-free (tests/test_scale.py: 1e-30 to 1e30; a
        # floor of 1.0 made a 1e-5 scene acne, a step of 1.0 vanished
        # against t at 1e20).  position != target, so size > 0.
        size = max([1e-300, float(np.linalg.norm(scene.camera.position)),
                    float(np.linalg.norm(scene.camera.target))]
                   + [p.extent() for p in self.prims])
        # (not the point lights: a light 1e20 away, a sun, made every offset
        # 1e14 and the rays passed through the whole scene)
        self.size = size
        self.ambient = np.array(scene.ambient, dtype=np.float64)
        self.max_depth = scene.render.max_depth
        self.min_weight = scene.render.min_weight

    # -- geometry

    def eps(self, P):
        """Offset of a ray starting at P: crossings closer than this are the surface
        it leaves.  Crossings within eps + EPS_REL * t of the nearest one (at t)
        are taken as one coincident group."""
        return EPS_REL * (self.size + np.linalg.norm(P, axis=1))

    def table(self, O, D, normals=True):
        N = len(O)
        T = np.full((N, max(self.K, 1)), _INF)
        NR = np.zeros((N, max(self.K, 1), 3)) if normals else None
        c = 0
        for p in self.prims:
            for t, nrm in p.columns(O, D, normals):
                T[:, c] = t
                if normals:
                    NR[:, c] = nrm
                c += 1
        T[~np.isfinite(T)] = _INF  # nan or -inf: no crossing ahead
        return T, NR

    def medium(self, P):
        med = np.full(len(P), -1, dtype=np.int64)
        for k in reversed(self.transparent):
            med[self.prims[k].contains(P)] = k
        return med

    def _first_group(self, T, lo):
        return np.where(T > lo[:, None], T, _INF).min(axis=1)

    # -- the next interaction of each ray

    def next_interaction(self, O, D):
        """For each ray: kind (0 escape, 1 opaque, 2 dielectric), t, object S,
        outward normal of S, medium travelled in, medium beyond (dielectric)."""
        N = len(O)
        T, NR = self.table(O, D)
        eps = self.eps(O)
        kind = np.zeros(N, dtype=np.int64)
        t_hit = np.full(N, _INF)
        S = np.full(N, -1, dtype=np.int64)
        nrm = np.zeros((N, 3))
        med_after = np.full(N, -1, dtype=np.int64)
        lo = eps.copy()
        tg = self._first_group(T, lo)
        mid = np.where(np.isfinite(tg), 0.5 * (lo + tg), lo + self.size)
        med = self.medium(O + mid[:, None] * D) if self.transparent else np.full(N, -1, dtype=np.int64)
        act = np.arange(N)
        while act.size:
            Ta = T[act]
            lo_a = lo[act]
            tg = np.where(Ta > lo_a[:, None], Ta, _INF).min(axis=1)
            fin = np.isfinite(tg)
            act, Ta, lo_a, tg = act[fin], Ta[fin], lo_a[fin], tg[fin]
            if not act.size:
                break
            hi = tg + eps[act] + EPS_REL * tg
            grp = (Ta > lo_a[:, None]) & (Ta <= hi[:, None])
            opq = grp & self.col_opq[None, :]
            any_opq = opq.any(axis=1)
            if any_opq.any():
                sel = act[any_opq]
                Tm = np.where(opq[any_opq], Ta[any_opq], _INF)
                col = np.argmin(Tm, axis=1)
                kind[sel] = 1
                t_hit[sel] = Tm[np.arange(len(sel)), col]
                S[sel] = self.col_obj[col]
                nrm[sel] = NR[sel, col]
            rest = ~any_opq
            act, Ta, tg, hi, grp = act[rest], Ta[rest], tg[rest], hi[rest], grp[rest]
            if not act.size:
                break
            tn = np.where(Ta > hi[:, None], Ta, _INF).min(axis=1)
            mid = np.where(np.isfinite(tn), 0.5 * (tg + tn), tg + self.size)
            after = self.medium(O[act] + mid[:, None] * D[act])
            inter = after != med[act]
            if inter.any():
                sel = act[inter]
                g = grp[inter] & ~self.col_opq[None, :]
                col = np.argmax(g, axis=1)  # first transparent surface in object order
                kind[sel] = 2
                t_hit[sel] = tg[inter]
                S[sel] = self.col_obj[col]
                nrm[sel] = NR[sel, col]
                med_after[sel] = after[inter]
            keep = ~inter
            act = act[keep]
            lo[act] = hi[keep]
        return kind, t_hit, S, nrm, med, med_after

    # -- shadow rays

    def shadow(self, P, L, tmax):
        """Fraction (N, 3) of a light's radiance reaching P along unit L over
        distance tmax (inf for a directional light)."""
        N = len(P)
        V = np.ones((N, 3))
        if N == 0:
            return V
        T, _ = self.table(P, L, normals=False)
        eps = self.eps(P)
        lo = eps.copy()
        tg = self._first_group(T, lo)
        end = np.minimum(tg, tmax)
        mid = np.where(np.isfinite(end), 0.5 * (lo + end), lo + self.size)
        med = self.medium(P + mid[:, None] * L) if self.transparent else np.full(N, -1, dtype=np.int64)
        t_prev = np.zeros(N)
        act = np.arange(N)
        while act.size:
            Ta = T[act]
            tg = np.where(Ta > lo[act][:, None], Ta, _INF).min(axis=1)
            done = tg >= tmax[act]
            if done.any():
                d = act[done]
                V[d] *= _transmittance(self.absorb[med[d]], tmax[d] - t_prev[d])
            act, Ta, tg = act[~done], Ta[~done], tg[~done]
            if not act.size:
                break
            hi = tg + eps[act] + EPS_REL * tg
            grp = (Ta > lo[act][:, None]) & (Ta <= hi[:, None])
            blocked = (grp & self.col_opq[None, :]).any(axis=1)
            V[act[blocked]] = 0.0
            keep = ~blocked
            act, Ta, tg, hi, grp = act[keep], Ta[keep], tg[keep], hi[keep], grp[keep]
            if not act.size:
                break
            tn = np.where(Ta > hi[:, None], Ta, _INF).min(axis=1)
            mid = np.where(np.isfinite(tn), 0.5 * (tg + tn), tg + self.size)
            after = self.medium(P[act] + mid[:, None] * L[act])
            inter = after != med[act]
            if inter.any():
                sel = act[inter]
                col = np.argmax(grp[inter] & ~self.col_opq[None, :], axis=1)
                V[sel] *= self.transp[self.col_obj[col]][:, None]
            V[act] *= _transmittance(self.absorb[med[act]], tg - t_prev[act])
            t_prev[act] = tg
            med[act] = after
            lo[act] = hi
            act = act[V[act].max(axis=1) > 0.0]
        return V

    # -- local shading

    def shade(self, P, D, S, n_f):
        """E + C * (k_a A + sum_j L_j V_j [n.l > 0] (k_d n.l + k_s max(0, r.v)^p))."""
        C = self.color[S].copy()
        E = self.emission[S].copy()
        ck = self.has_ck[S]
        if ck.any():
            s = self.ck_size[S[ck]]
            # moved a little toward +x and +z (far more than the rounding of
            # P, far less than any feature): on a surface that lies on a
            # checker line (a box face at x = 0) floor(x / s) is then that of
            # the exact x all over, not of its rounding to either side
            e = 1e-9 * (self.size + np.linalg.norm(P[ck], axis=1))
            par = np.mod(np.floor((P[ck, 0] + e) / s) + np.floor((P[ck, 2] + e) / s), 2.0) == 1.0
            idx = np.nonzero(ck)[0][par]
            C[idx] = self.ck_color[S[idx]]
            E[idx] = self.ck_emis[S[idx]]
        local = E + C * (self.ka[S][:, None] * self.ambient)
        kd, ks, p = self.kd[S], self.ks[S], self.shin[S]
        lit = ((kd > 0) | (ks > 0)) & (C.max(axis=1) > 0)
        if not lit.any():
            return local
        v = -D
        for lt in self.scene.lights:
            with np.errstate(over="ignore"):        # beyond float64: inf (lit pixels are)
                Lc = np.array(lt.color, dtype=np.float64) * lt.intensity
            if not (Lc > 0).any():
                continue
            if lt.type == "point":
                # scaled by the largest component first, so that a light
                # 1e300 away neither overflows the length nor loses l
                half = np.array(lt.position, dtype=np.float64) / 2 - P / 2
                big = np.abs(half).max(axis=1, keepdims=True)
                with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                    u = half / big
                    n = np.linalg.norm(u, axis=1)
                    l = u / n[:, None]
                    dist = 2.0 * big[:, 0] * n
            else:
                l = np.broadcast_to(-np.array(unit_vector(lt.direction)), P.shape)
                dist = np.full(len(P), _INF)
            ndl = _dot(n_f, l)
            m = lit & (ndl > 0.0)
            if not m.any():
                continue
            reach = dist[m]
            if lt.type == "point":
                # short of the light by its own offset (as a ray leaving a
                # surface): a light on a surface is not shadowed by it
                reach = reach - (EPS_REL * self.size + EPS_REL * float(np.max(np.abs(lt.position))))
            Vj = self.shadow(P[m], np.ascontiguousarray(l[m]), reach)
            r = 2.0 * ndl[m][:, None] * n_f[m] - l[m]
            rv = np.maximum(_dot(r, v[m]), 0.0)
            term = kd[m] * ndl[m] + ks[m] * rv ** p[m]
            # a light whose colour * intensity overflows (1e200 * 1e200) is
            # inf: in shadow (V = 0) it adds 0, not inf * 0 = NaN
            with np.errstate(invalid="ignore", over="ignore"):
                add = C[m] * Lc * Vj * term[:, None]
            local[m] += np.where((Vj > 0) & (term[:, None] > 0) & (C[m] > 0), add, 0.0)
        return local

    # -- the ray tree

    def render_rays(self, O, D, pix, out, thr=None):
        """Trace rays and add their radiance (times throughput) into out[pix]."""
        N = len(O)
        thr = np.ones((N, 3)) if thr is None else thr
        depth = np.ones(N, dtype=np.int64)
        stack = [(O, D, thr, depth, pix)]
        npix = len(out)
        while stack:
            O, D, thr, depth, pix = stack.pop()
            if len(O) > CHUNK:
                stack.append((O[CHUNK:], D[CHUNK:], thr[CHUNK:], depth[CHUNK:], pix[CHUNK:]))
                O, D, thr, depth, pix = O[:CHUNK], D[:CHUNK], thr[:CHUNK], depth[:CHUNK], pix[:CHUNK]
            kind, t, S, nrm, med, med_after = self.next_interaction(O, D)
            thr = thr * _transmittance(self.absorb[med], t)
            contrib = np.zeros((len(O), 3))
            esc = kind == 0
            if esc.any():
                contrib[esc] = thr[esc] * sky_radiance(self.scene, D[esc])
            h = np.nonzero(~esc)[0]
            children = []
            if h.size:
                Oh, Dh, th, Sh = O[h], D[h], t[h], S[h]
                P = Oh + th[:, None] * Dh
                n = nrm[h]
                n_f = np.where((_dot(n, Dh) > 0.0)[:, None], -n, n)
                contrib[h] = thr[h] * self.shade(P, Dh, Sh, n_f)
                go = depth[h] < self.max_depth
                cos_i = np.clip(-_dot(n_f, Dh), 0.0, 1.0)
                mirror = Dh + 2.0 * cos_i[:, None] * n_f
                diel = kind[h] == 2
                R = np.zeros(len(h))
                if diel.any():
                    R[diel] = fresnel_dielectric(cos_i[diel], self.ior[med[h][diel]],
                                                 self.ior[med_after[h][diel]])
                f_refl = np.where(diel, R, self.refl[Sh])
                f_refr = np.where(diel, (1.0 - R) * self.transp[Sh], 0.0)
                # reflected branch
                tr = thr[h] * f_refl[:, None]
                w = tr.max(axis=1)
                ok = go & (w > 0.0) & (w >= self.min_weight)
                if ok.any():
                    children.append((P[ok], _normalize(mirror[ok]), tr[ok], depth[h][ok] + 1, pix[h][ok]))
                # refracted branch
                tt = thr[h] * f_refr[:, None]
                w = tt.max(axis=1)
                ok = go & diel & (w > 0.0) & (w >= self.min_weight)
                if ok.any():
                    sel = np.nonzero(ok)[0]
                    dirs, good = refract(Dh[sel], n_f[sel], self.ior[med[h][sel]],
                                         self.ior[med_after[h][sel]])
                    sel = sel[good]
                    children.append((P[sel], dirs[good], tt[sel], depth[h][sel] + 1, pix[h][sel]))
            for c in range(3):
                out[:, c] += np.bincount(pix, weights=contrib[:, c], minlength=npix)
            if children:
                stack.append(tuple(np.concatenate([ch[k] for ch in children]) for k in range(5)))
        return out


# --------------------------------------------------------------------------- public API


def _camera_basis(scene: Scene):
    cam = scene.camera
    pos = np.array(cam.position, dtype=np.float64)
    # scaled first: target - position may overflow (1e308 and -1e308) or its
    # square underflow (points 1e-300 apart)
    s = max(abs(c) for c in (*cam.target, *cam.position))
    f = np.array(unit_vector([t / s - p / s for t, p in zip(cam.target, cam.position)]))
    right = _normalize(np.cross(f, np.array([0.0, 1.0, 0.0])))
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
    d = _normalize(d)
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
    d = _normalize(f + a[:, None] * right + b[:, None] * up)
    return np.broadcast_to(pos, d.shape).copy(), d


def trace(scene: Scene, origins, dirs) -> np.ndarray:
    """Radiance (N, 3) along arbitrary rays (no exposure)."""
    O = np.ascontiguousarray(np.asarray(origins, dtype=np.float64).reshape(-1, 3))
    D = _normalize(np.asarray(dirs, dtype=np.float64).reshape(-1, 3))
    ctx = _Ctx(scene)
    out = np.zeros((len(O), 3))
    if len(O):
        ctx.render_rays(O, D, np.arange(len(O)), out)
    return out


def render_reference(scene: Scene, width: int, height: int, samples: int | None = None,
                     seed: int = 0) -> np.ndarray:
    """(H, W, 3) float64 linear image: box-filtered average of ``samples`` rays per
    pixel at the shared sub-pixel offsets, times the exposure; not clamped."""
    n = scene.render.samples if samples is None else int(samples)
    offs = sample_offsets(n, seed)
    ctx = _Ctx(scene)
    npix = width * height
    out = np.zeros((npix, 3))
    per = max(1, CHUNK // max(npix, 1))
    for k0 in range(0, n, per):
        Os, Ds = [], []
        for k in range(k0, min(n, k0 + per)):
            o, d = camera_rays(scene, width, height, offs[k])
            Os.append(o.reshape(-1, 3))
            Ds.append(d.reshape(-1, 3))
        O = np.concatenate(Os)
        D = np.concatenate(Ds)
        pix = np.tile(np.arange(npix), len(Os))
        ctx.render_rays(O, D, pix, out)
    img = out.reshape(height, width, 3) / n
    return img * scene.render.exposure


#: rays per call of the tracer in :func:`render_reference_refined`'s tasks
REFINE_TASK_RAYS = 1 << 19


def _sample_stats(scene: Scene, width: int, height: int, pixels, offsets):
    """Per pixel of ``pixels``: the sum, minimum and maximum (each (P, 3), no
    exposure) of the radiance at ``offsets``.  Module level, so that a worker
    process can run it."""
    pixels = np.asarray(pixels, dtype=np.int64)
    offsets = np.asarray(offsets, dtype=np.float64).reshape(-1, 2)
    P = len(pixels)
    total = np.zeros((P, 3))
    lo = np.full((P, 3), _INF)
    hi = np.full((P, 3), -_INF)
    per = max(1, min(len(offsets), REFINE_TASK_RAYS // max(P, 1)))
    for k0 in range(0, len(offsets), per):
        offs = offsets[k0:k0 + per]
        o, d = pixel_rays(scene, width, height, pixels, offs)
        L = trace(scene, o, d).reshape(P, len(offs), 3)
        total += L.sum(axis=1)
        lo = np.minimum(lo, L.min(axis=1))
        hi = np.maximum(hi, L.max(axis=1))
    return total, lo, hi


def _ignore_sigint() -> None:
    """A worker's start: Ctrl-C reaches the whole process group, and only the
    caller (its ``check``) should act on it; a worker's KeyboardInterrupt
    came back as the result of its task and stopped the caller a second
    time (two "interrupted" messages)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def render_reference_refined(scene: Scene, width: int, height: int, samples: int, max_samples: int,
                             tolerance: float, seed: int = 0, workers: int = 1,
                             log=None, check=None) -> tuple[np.ndarray, np.ndarray]:
    """A reference with many samples where a pixel needs them: (image (H, W,
    3) as :func:`render_reference`, samples per pixel (H, W)).

    Every pixel takes ``samples`` samples of the shared pattern.  A pixel
    whose samples all lie within ``tolerance`` of each other (after the
    exposure) keeps their mean: it is :func:`render_reference` there.  Every
    other pixel (an edge, a checker finer than the pixel) takes
    ``max_samples``: it is ``render_reference(..., max_samples)`` there.
    Why it matters: a 512-sample reference of ``whitted-exact`` at 320x180
    is itself off by RMSE 0.0027 (two seeds differ by 0.0038), about what
    the renderers it judges reach, and nearly all of that is in the third
    of its pixels that hold an edge.

    No pixel stops early on an error estimate from its own samples: samples
    0 .. n - 1 and n .. 2n - 1 are both nets of the Sobol' points and err
    alike (measured: pixels stopped when the two halves agreed to 5e-4 were
    off by RMS 0.0063).

    ``workers`` > 1 traces in that many processes.  ``log(message)`` hears
    of the progress, ``check()`` runs while waiting (Ctrl-C)."""
    import time

    samples, max_samples = int(samples), int(max_samples)
    if samples < 1 or max_samples < samples:
        raise ValueError("need 1 <= samples <= max_samples")
    offs = sample_offsets(max_samples, seed)
    npix = width * height
    exposure = scene.render.exposure
    pool = None
    if workers > 1:
        # processes: the tracer is many small NumPy calls, which threads
        # run one at a time (two threads were no faster than one); spawned,
        # not forked, as the caller may hold an OpenGL context and its threads
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        pool = ProcessPoolExecutor(max_workers=int(workers), mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_ignore_sigint)

    def run(pixels, block, what):
        """(sum, min, max) over ``block`` of the samples of every pixel."""
        per = max(1, REFINE_TASK_RAYS // len(block))
        parts = [pixels[p0:p0 + per] for p0 in range(0, len(pixels), per)]
        t0 = last = time.perf_counter()
        res = []

        def tell(k):
            nonlocal last
            now = time.perf_counter()
            if log is not None and now - last > 20.0 and k < len(parts):
                last = now
                log(f"  reference, {what}: {k}/{len(parts)} parts, {now - t0:.0f} s, "
                    f"about {(now - t0) / k * (len(parts) - k):.0f} s left")

        if pool is None:
            for part in parts:
                if check is not None:
                    check()
                res.append(_sample_stats(scene, width, height, part, block))
                tell(len(res))
        else:
            futs = [pool.submit(_sample_stats, scene, width, height, part, block) for part in parts]
            for f in futs:
                while True:
                    if check is not None:
                        check()
                    try:
                        res.append(f.result(timeout=0.25))
                        break
                    except TimeoutError:
                        continue
                tell(len(res))
        return tuple(np.concatenate([r[k] for r in res]) for k in range(3))

    try:
        everyone = np.arange(npix)
        acc, lo, hi = run(everyone, offs[:samples], f"{samples} samples a pixel")
        count = np.full(npix, samples, dtype=np.int64)
        edges = everyone[(hi - lo).max(axis=1) * exposure > tolerance]
        if edges.size and max_samples > samples:
            if log is not None:
                log(f"  reference: {edges.size} of {npix} pixels to {max_samples} samples")
            more, _, _ = run(edges, offs[samples:], f"{edges.size} pixels to {max_samples} samples")
            acc[edges] += more
            count[edges] = max_samples
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    img = (acc / count[:, None]).reshape(height, width, 3) * exposure
    return img, count.reshape(height, width)


def first_hit(scene: Scene, origins, dirs, tmin: float = 0.0):
    """First geometric surface along each ray (media ignored): t (N,), object
    index (N,) into scene.objects (-1 with t = inf when none), and the unit
    outward normal (N, 3) of that solid at the hit."""
    O = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    D = _normalize(np.asarray(dirs, dtype=np.float64).reshape(-1, 3))
    ctx = _Ctx(scene)
    N = len(O)
    if ctx.K == 0:
        return np.full(N, _INF), np.full(N, -1, dtype=np.int64), np.zeros((N, 3))
    T, NR = ctx.table(O, D)
    T = np.where(T > tmin, T, _INF)
    col = np.argmin(T, axis=1)
    idx = np.arange(N)
    t = T[idx, col]
    hit = np.isfinite(t)
    obj = np.where(hit, ctx.col_obj[col], -1)
    nrm = np.where(hit[:, None], NR[idx, col], 0.0)
    return t, obj, nrm


def medium_at(scene: Scene, points) -> np.ndarray:
    """Index of the first transparent object containing each point, -1 for air."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return _Ctx(scene).medium(P)
