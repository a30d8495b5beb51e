"""``glassray stress --intersections``: the float32 error of the first hit's
distance, per primitive, with the robust intersection formulas against the
textbook ones (NAIVE_INTERSECT), over views chosen to be hard; and the
float32 emulation of world against camera-relative coordinates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..gpu.geometry import rotation_world_from_local
from ..gpu.renderer import Renderer
from ..reference import trace as reference
from .stress_cases import case_scene

# ---------------------------------------------------------------- intersection error distribution


PRIMITIVES: dict[str, dict] = {
    "plane": {"type": "plane", "height": 0.0},
    "sphere": {"type": "sphere", "center": [0.2, 0.6, -0.1], "radius": 0.6},
    "box": {"type": "box", "min": [-0.5, 0.0, -0.25], "max": [0.75, 1.0, 0.5]},
    "box-rotated": {"type": "box", "min": [-0.5, 0.1, -0.4], "max": [0.6, 1.0, 0.3], "rotate": [17, -33, 51]},
    "cylinder": {"type": "cylinder", "axis": "y", "base": [0.0, 0.0, 0.0], "radius": 0.5, "height": 1.25},
    "vessel": {"type": "cylinder", "base": [0.0, 0.0, 0.0], "radius": 0.75, "height": 1.25, "wall": 0.0625},
}


def _prim_bounds(obj: dict) -> tuple[np.ndarray, float]:
    """A centre and radius of the object (a point of the plane, radius 1)."""
    t = obj["type"]
    if t == "plane":
        return np.array([0.0, obj["height"], 0.0]), 1.0
    if t == "sphere":
        return np.array(obj["center"], float), obj["radius"]
    if t == "box":
        lo, hi = np.array(obj["min"], float), np.array(obj["max"], float)
        return (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2
    ax = {"x": 0, "y": 1, "z": 2}[obj.get("axis", "y")]
    c = np.array(obj["base"], float)
    c[ax] += obj["height"] / 2
    return c, math.hypot(obj["radius"], obj["height"] / 2)


def _inside_point(obj: dict, rng) -> np.ndarray:
    t = obj["type"]
    if t == "plane":
        return np.array([rng.uniform(-2, 2), obj["height"] - rng.uniform(0.05, 2.0), rng.uniform(-2, 2)])
    if t == "sphere":
        v = rng.normal(size=3)
        return np.array(obj["center"]) + obj["radius"] * rng.uniform(0, 0.9) * v / np.linalg.norm(v)
    if t == "box":
        lo, hi = np.array(obj["min"], float), np.array(obj["max"], float)
        c, half = (lo + hi) / 2, (hi - lo) / 2
        return c + rotation_world_from_local(obj.get("rotate", (0, 0, 0))) @ (half * rng.uniform(-0.9, 0.9, 3))
    r = obj["radius"] - obj.get("wall", 0.0) * 1.5 if "wall" in obj else obj["radius"]
    ang, rho = rng.uniform(0, 2 * np.pi), r * math.sqrt(rng.uniform(0, 0.8))
    y = rng.uniform(0.1, 0.9) * obj["height"]
    if "wall" in obj:      # inside the hollow (air), above the inner bottom
        y = obj["wall"] + rng.uniform(0.1, 0.9) * (obj["height"] - obj["wall"])
    return np.array(obj["base"], float) + np.array([rho * math.cos(ang), y, rho * math.sin(ang)])


def _cameras(obj: dict, n: int, rng) -> list[tuple[str, list[float], list[float], float, tuple[int, int]]]:
    """(kind, position, target, fov, size) of the measurement cameras."""
    c, rad = _prim_bounds(obj)
    cams = []

    def sph(yaw, pitch, dist, centre):
        yr, pr = math.radians(yaw), math.radians(pitch)
        return centre + dist * np.array([math.cos(pr) * math.sin(yr), math.sin(pr), math.cos(pr) * math.cos(yr)])

    plane = obj["type"] == "plane"
    for _ in range(n):           # near: random views at a few object sizes
        tgt = c + rng.uniform(-0.3, 0.3, 3) * rad
        pitch = rng.uniform(5, 70) if plane else rng.uniform(-60, 80)
        cams.append(("near", sph(rng.uniform(0, 360), pitch, rad * rng.uniform(2.5, 10), tgt), tgt,
                     rng.uniform(10, 90), (64, 48)))
    for _ in range(n):           # far: 30 to 1000 sizes away, narrow field of view
        tgt = c + rng.uniform(-0.5, 0.5, 3) * rad
        dist = rad * 10 ** rng.uniform(1.5, 3.0)
        pitch = rng.uniform(20, 80) if plane else rng.uniform(-60, 80)
        fov = max(1.0, min(10.0, math.degrees(2.4 * rad / dist)))
        cams.append(("far", sph(rng.uniform(0, 360), pitch, dist, tgt), tgt, fov, (64, 48)))
    for _ in range(n):           # grazing: the view centred on the silhouette (plane: near the horizon)
        if plane:
            pos = np.array([0.0, 10 ** rng.uniform(-3, -1), 0.0])
            dirn = sph(rng.uniform(0, 360), -rng.uniform(0.2, 3.0), 1.0, np.zeros(3))
            cams.append(("grazing", pos, pos + dirn, rng.uniform(1, 5), (64, 48)))
            continue
        dist = rad * 10 ** rng.uniform(0.5, 2.0)
        pos = sph(rng.uniform(0, 360), rng.uniform(-40, 70), dist, c)
        f = (c - pos) / np.linalg.norm(c - pos)
        u = np.cross(f, rng.normal(size=3))
        u /= np.linalg.norm(u)
        # aim at the edge of the silhouette of the bounding shape and a bit inside
        tgt = c + u * rad * rng.uniform(0.5, 1.0)
        cams.append(("grazing", pos, tgt, rng.uniform(1, 4), (64, 48)))
    for _ in range(max(2, n // 2)):   # inside the solid (the vessel: inside its hollow)
        pos = _inside_point(obj, rng)
        tgt = pos + rng.normal(size=3)
        cams.append(("inside", pos, tgt, rng.uniform(40, 100), (64, 48)))
    for i in range(max(2, n // 2)):   # exactly along x or z through the object's middle (odd size)
        ax = i % 2
        dirn = np.zeros(3)
        dirn[2 * ax] = 1.0 if i % 4 < 2 else -1.0
        pos = c - 4 * rad * dirn
        pos[1] = c[1] if not plane else 0.5
        if obj["type"] == "box" and i % 3 == 0 and "rotate" not in obj:
            # the eye on the plane of a face: centre rows/columns travel in it
            pos[1] = obj["max"][1]
        tgt = pos + dirn
        cams.append(("axis", pos, tgt, rng.uniform(20, 60), (65, 49)))
    return [(k, [float(x) for x in p], [float(x) for x in t], float(fv), s) for k, p, t, fv, s in cams]


@dataclass
class ErrorStats:
    primitive: str
    variant: str
    rays: int
    hits: int
    median: float
    p999: float
    max: float
    disagree: int      # rays where one side hits and the other misses


def intersection_errors(ctx, cameras_per_kind: int = 8, seed: int = 1,
                        primitives: list[str] | None = None) -> list[ErrorStats]:
    """Relative error |t_gpu - t_ref| / t_ref of the first hit, per primitive,
    with the robust formulations (default shader) and the textbook ones
    (NAIVE_INTERSECT), over the same rays: random near views, far views (30
    to 1000 sizes away), views centred on the silhouette (grazing rays),
    views from inside the solid, and views exactly along x and z."""
    out = []
    for name in primitives or list(PRIMITIVES):
        obj = dict(PRIMITIVES[name], material="m")
        rng = np.random.default_rng(seed)
        cams = _cameras(obj, cameras_per_kind, rng)
        # random sub-pixel offsets; the axis views use the centre (exact axis rays)
        offsets = [(0.5, 0.5) if cam[0] == "axis" else tuple(rng.random(2)) for cam in cams]
        rel = {False: [], True: []}
        disagree = {False: 0, True: 0}
        rays = 0
        renderer = None
        try:
            for (kind, pos, tgt, fov, (w, h)), off in zip(cams, offsets):
                doc = {"camera": {"position": pos, "target": tgt, "fov": fov},
                       "materials": {"m": {"color": [0.5, 0.5, 0.5]}}, "objects": [obj]}
                scene = case_scene(doc)
                if renderer is None:
                    renderer = Renderer(ctx, scene)
                else:
                    renderer.set_scene(scene)
                o, d = reference.camera_rays(scene, w, h, tuple(off))
                rt, robj, _ = reference.first_hit(scene, o.reshape(-1, 3), d.reshape(-1, 3))
                rt = rt.reshape(h, w)
                rhit = robj.reshape(h, w) >= 0
                rays += w * h
                base = {k: v for k, v in renderer.extra_defines.items() if k != "NAIVE_INTERSECT"}
                for naive in (False, True):
                    renderer.extra_defines = {**base, "NAIVE_INTERSECT": True} if naive else base
                    renderer.set_scene(scene)
                    t, gobj, _ = renderer.first_hits(w, h, tuple(off))
                    ghit = gobj >= 0
                    disagree[naive] += int(np.sum(ghit != rhit))
                    both = ghit & rhit & (rt > 0)
                    rel[naive].append(np.abs(t[both].astype(np.float64) - rt[both]) / rt[both])
        finally:
            if renderer is not None:
                renderer.release()
        for naive in (False, True):
            e = np.concatenate(rel[naive]) if rel[naive] else np.zeros(0)
            out.append(ErrorStats(name, "textbook" if naive else "robust", rays, len(e),
                                  float(np.median(e)) if len(e) else 0.0,
                                  float(np.quantile(e, 0.999)) if len(e) else 0.0,
                                  float(e.max()) if len(e) else 0.0, disagree[naive]))
    return out


def format_errors(stats: list[ErrorStats], markdown: bool = True) -> str:
    head = ("primitive", "formulation", "rays", "median", "99.9th pct", "max", "hit/miss disagree")
    rows = [head] + [(s.primitive, s.variant, str(s.rays), f"{s.median:.1e}", f"{s.p999:.1e}", f"{s.max:.1e}",
                      str(s.disagree)) for s in stats]
    if markdown:
        return "\n".join(["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(head)]
                         + ["| " + " | ".join(r) + " |" for r in rows[1:]])
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.rjust(wd) if i else c.ljust(wd) for i, (c, wd) in enumerate(zip(r, widths)))
                     for r in rows)


def camera_relative_errors(offsets=(0.0, 1e2, 1e4, 1e6), n: int = 20000, seed: int = 2) -> list[tuple]:
    """Float32 emulation in NumPy of the sphere routine (robust form) with
    world coordinates (eye and centre rounded to float32 where they are)
    against camera-relative ones (centre - eye in float64, then rounded), for
    the scene moved by each offset: (offset, world median, world max,
    relative median, relative max) of the relative error of t."""
    rng = np.random.default_rng(seed)
    f32 = np.float32
    centre = np.array([0.2, 0.6, -0.1])
    radius = 0.6
    eye = np.array([3.2, 2.2, 4.6])
    # directions toward random points of the sphere's disc seen from the eye
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    pts = centre + 0.98 * radius * u
    d = pts - eye
    d /= np.linalg.norm(d, axis=1, keepdims=True)

    def robust_t(oc, dd, r):
        b = np.einsum("ij,ij->i", oc, dd)
        qc = oc - b[:, None] * dd
        h = r * r - np.einsum("ij,ij->i", qc, qc)
        ok = h >= 0
        h = np.sqrt(np.maximum(h, 0).astype(oc.dtype))
        q = -b - np.where(b >= 0, h, -h)
        c = np.einsum("ij,ij->i", oc, oc) - r * r
        t0, t1 = q, c / q
        return np.where(ok, np.minimum(t0, t1), np.nan)

    exact = robust_t(np.broadcast_to(eye - centre, d.shape), d, radius)
    rows = []
    for off in offsets:
        e64, c64 = eye + off, centre + off
        world = robust_t(e64.astype(f32)[None] - c64.astype(f32)[None], d.astype(f32), f32(radius))
        rel = robust_t(np.broadcast_to(-(c64 - e64).astype(f32), d.shape), d.astype(f32), f32(radius))
        ew = np.abs(world.astype(np.float64) - exact) / exact
        er = np.abs(rel.astype(np.float64) - exact) / exact
        ew, er = np.nan_to_num(ew, nan=1.0), np.nan_to_num(er, nan=1.0)
        rows.append((off, float(np.median(ew)), float(ew.max()), float(np.median(er)), float(er.max())))
    return rows
