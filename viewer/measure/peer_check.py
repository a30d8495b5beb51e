"""Which scenes the physically based peer draws as glassray does: on a scene
where exact Whitted tracing is physically exact -- opaque materials that
only emit (and, optionally, perfect mirrors), clear dielectrics, a constant
sky, no emitter and no eye inside a medium, no coincident faces with a
medium -- a converged path tracer and glassray's float64 reference draw
the same image.  :func:`reasons` says why a scene is not one.
"""

from __future__ import annotations

import math

import numpy as np

from ..reference.primitives import contains, rotation_matrix
from ..scene.model import Material, Scene, SceneObject

#: The peers ``glassray bench --peer`` knows
PEERS = ("mitsuba",)


class PeerError(ValueError):
    """A scene the physically based peer cannot draw identically (or no peer)."""


def is_black(c) -> bool:
    return c is None or max(c) == 0.0


def _phong_is_zero(scene: Scene, m: Material) -> bool:
    """Whether C * (k_a A + sum over lights (...)) is 0 for every point."""
    colours = [m.color] + ([m.checker.color] if m.checker is not None else [])
    if all(is_black(c) for c in colours):
        return True
    ambient_zero = m.ambient == 0.0 or is_black(scene.ambient)
    lit = any(lt.intensity > 0 and not is_black(lt.color) for lt in scene.lights)
    direct_zero = not lit or (m.diffuse == 0.0 and m.specular == 0.0)
    return ambient_zero and direct_zero


def _emissions(m: Material) -> list[tuple]:
    out = [tuple(m.emission)]
    if m.checker is not None and m.checker.emission is not None:
        out.append(tuple(m.checker.emission))
    return out


def bounding_box(obj: SceneObject) -> tuple[np.ndarray, np.ndarray] | None:
    """Axis-aligned bounds of a finite solid (None for the plane)."""
    if obj.type == "plane":
        return None
    if obj.type == "sphere":
        c = np.array(obj.center, float)
        return c - obj.radius, c + obj.radius
    if obj.type == "box":
        lo, hi = np.array(obj.min, float), np.array(obj.max, float)
        c, h = (lo + hi) / 2, (hi - lo) / 2
        ext = np.abs(rotation_matrix(obj.rotate)) @ h
        return c - ext, c + ext
    # cylinder
    a = "xyz".index(obj.axis)
    b = np.array(obj.base, float)
    lo, hi = b - obj.radius, b + obj.radius
    lo[a], hi[a] = b[a], b[a] + obj.height
    return lo, hi


def _overlap(a: SceneObject, b: SceneObject, tol: float) -> bool:
    """Whether the interiors of two solids may overlap (conservative: bounds;
    exact for two spheres and for a plane)."""
    if a.type == "plane" and b.type == "plane":
        return True
    if b.type == "plane":
        a, b = b, a
    if a.type == "plane":
        lo, _ = bounding_box(b)
        return lo[1] < a.height - tol
    if a.type == "sphere" and b.type == "sphere":
        d = math.dist(a.center, b.center)
        return d < a.radius + b.radius - tol
    (alo, ahi), (blo, bhi) = bounding_box(a), bounding_box(b)
    return bool(np.all(np.minimum(ahi, bhi) - np.maximum(alo, blo) > tol))


#: Flat faces closer than this (times the scene's scale) count as lying on
#: each other: Mitsuba intersects in float32, so a gap below about 1e-6 of the
#: scene's size cannot decide which of the two surfaces a ray meets first.
CONTACT_TOLERANCE = 1e-5


def _flat_faces(obj: SceneObject) -> list[tuple[np.ndarray, np.ndarray]]:
    """(outward unit normal, corners (k, 3) in order) of each flat face of a
    finite solid: a box's six rectangles, a cylinder's two caps (as inscribed
    64-gons); a sphere has none."""
    if obj.type == "box":
        lo, hi = np.array(obj.min, float), np.array(obj.max, float)
        c, h = (lo + hi) / 2, (hi - lo) / 2
        rot = rotation_matrix(obj.rotate)
        faces = []
        for a in range(3):
            b, e = (a + 1) % 3, (a + 2) % 3
            for s in (-1.0, 1.0):
                local = np.zeros((4, 3))
                local[:, a] = s * h[a]
                local[:, b] = np.array([-1, 1, 1, -1]) * h[b]
                local[:, e] = np.array([-1, -1, 1, 1]) * h[e]
                faces.append((s * rot[:, a], c + local @ rot.T))
        return faces
    if obj.type == "cylinder":
        a = "xyz".index(obj.axis)
        b, e = (a + 1) % 3, (a + 2) % 3
        t = np.linspace(0.0, 2.0 * math.pi, 64, endpoint=False)
        ring = np.zeros((64, 3))
        ring[:, b], ring[:, e] = obj.radius * np.cos(t), obj.radius * np.sin(t)
        base = np.array(obj.base, float)
        axis = np.zeros(3)
        axis[a] = 1.0
        return [(-axis, base + ring), (axis, base + obj.height * axis + ring)]
    return []


def _clip_area(p: np.ndarray, q: np.ndarray) -> float:
    """Area of the intersection of two convex polygons in 2D (Sutherland-Hodgman)."""
    def signed(poly):
        x, y = poly[:, 0], poly[:, 1]
        return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))

    if signed(p) < 0:
        p = p[::-1]
    if signed(q) < 0:
        q = q[::-1]
    out = list(p)
    for i in range(len(q)):
        a, b = q[i], q[(i + 1) % len(q)]
        edge = b - a
        inside = [edge[0] * (v[1] - a[1]) - edge[1] * (v[0] - a[0]) >= 0 for v in out]
        poly, n = [], len(out)
        for k in range(n):
            v, w = out[k], out[(k + 1) % n]
            if inside[k]:
                poly.append(v)
            if inside[k] != inside[(k + 1) % n]:
                dv, dw = (edge[0] * (v[1] - a[1]) - edge[1] * (v[0] - a[0]),
                          edge[0] * (w[1] - a[1]) - edge[1] * (w[0] - a[0]))
                poly.append(v + (w - v) * (dv / (dv - dw)))
        out = poly
        if len(out) < 3:
            return 0.0
    return abs(signed(np.array(out)))


def _faces_touch(a: SceneObject, b: SceneObject, tol: float) -> bool:
    """Whether a flat face of one solid lies on a flat face of the other (or
    on the plane) over an area: coincident surfaces, which a physically based
    renderer meets in an order left to float rounding."""
    if a.type == "plane" and b.type == "plane":
        return False
    if b.type == "plane":
        a, b = b, a
    fb = _flat_faces(b)
    if a.type == "plane":
        return any(abs(n[1]) > 1.0 - 1e-9 and np.all(np.abs(pts[:, 1] - a.height) <= tol) for n, pts in fb)
    for na, pa in _flat_faces(a):
        for nb, pb in fb:
            if abs(float(np.dot(na, nb))) < 1.0 - 1e-9 or abs(float(np.dot(na, pb[0] - pa[0]))) > tol:
                continue
            u = np.cross(na, [1.0, 0.0, 0.0] if abs(na[0]) < 0.9 else [0.0, 1.0, 0.0])
            u /= np.linalg.norm(u)
            v = np.cross(na, u)
            flat = lambda pts: np.stack([pts @ u, pts @ v], axis=1)  # noqa: E731
            if _clip_area(flat(pa), flat(pb)) > tol * tol:
                return True
    return False


def _name(scene: Scene, i: int) -> str:
    o = scene.objects[i]
    return f"objects[{i}]" + (f" ({o.name})" if o.name else "") + f" {o.type}"


def reasons(scene: Scene) -> list[str]:
    """Why a physically based renderer would not draw this scene as glassray
    does (empty: it qualifies)."""
    why: list[str] = []
    if scene.sky.type != "color":
        why.append(f"sky.type is {scene.sky.type!r}: only a constant sky (type \"color\") is supported")
    if not scene.objects:
        why.append("the scene has no objects")
    scale = max([1.0] + [abs(x) for x in scene.camera.position]
                + [float(np.max(np.abs(np.concatenate(bb)))) for o in scene.objects
                   if (bb := bounding_box(o)) is not None])
    tol = 1e-9 * scale
    for i, obj in enumerate(scene.objects):
        m = scene.materials[obj.material]
        where = f"{_name(scene, i)}, material {obj.material!r}"
        if not _phong_is_zero(scene, m):
            why.append(f"{where}: has Phong terms (ambient or lit diffuse/specular with a non-black colour); "
                       "only emission, mirrors and clear glass have a physically based equivalent")
        if obj.type == "cylinder" and obj.wall is not None:
            why.append(f"{where}: vessels (cylinder with wall) are not converted")
        if m.is_dielectric:
            if m.transparency != 1.0:
                why.append(f"{where}: transparency {m.transparency:g} < 1 (a clear dielectric needs 1)")
            if max(m.absorption) > 0:
                why.append(f"{where}: absorption is not supported (the peer would need a volumetric integrator)")
            if any(not is_black(e) for e in _emissions(m)):
                why.append(f"{where}: an emissive dielectric (emission inside a medium is scaled by ior^2 "
                           "in a physically based renderer)")
            if obj.type == "plane":
                why.append(f"{where}: a transparent plane (an infinite medium) is not supported")
        else:
            em = _emissions(m)
            if (obj.type != "plane" and m.checker is not None and m.checker.emission is not None
                    and tuple(m.checker.emission) != tuple(m.emission)):
                why.append(f"{where}: a checker on emission is supported on planes only")
            emissive = any(not is_black(e) for e in em)
            if emissive:
                for j, other in enumerate(scene.objects):
                    if scene.is_transparent(other) and _overlap(obj, other, tol):
                        why.append(f"{where}: emits inside the medium of {_name(scene, j)} "
                                   "(a physically based renderer scales that light by ior^2)")
    transparent = [i for i, o in enumerate(scene.objects) if scene.is_transparent(o)]
    for a in transparent:
        for b in transparent:
            if a < b and _overlap(scene.objects[a], scene.objects[b], tol):
                why.append(f"{_name(scene, a)} and {_name(scene, b)}: overlapping transparent objects "
                           "(nested media) are not supported")
    contact = CONTACT_TOLERANCE * scale
    for a in transparent:
        for b in range(len(scene.objects)):
            if b != a and not (b in transparent and b < a) and _faces_touch(scene.objects[a], scene.objects[b],
                                                                            contact):
                why.append(f"{_name(scene, a)} and {_name(scene, b)}: a flat face of the first lies on the "
                           "other (a physically based renderer meets coincident surfaces in an order left to "
                           "rounding; in glassray the media decide and an opaque surface wins): leave a gap, "
                           "or let them touch at a point or along a line")
    eye = np.array([scene.camera.position], float)
    for i, obj in enumerate(scene.objects):
        if bool(np.asarray(contains(obj, eye)).reshape(-1)[0]):
            why.append(f"the camera is inside {_name(scene, i)}"
                       + (" (below the plane)" if obj.type == "plane" else ""))
    return why


def check_scene(scene: Scene) -> None:
    """Raise PeerError with every reason when the scene does not qualify."""
    why = reasons(scene)
    if why:
        raise PeerError(f"scene {scene.name!r} cannot be compared with a physically based renderer: "
                        + "; ".join(why))
