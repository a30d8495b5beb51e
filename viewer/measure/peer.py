"""A physically based peer for the benchmark: the same scene in Mitsuba 3.

On a scene where exact Whitted tracing is physically exact -- opaque
materials that only emit (and, optionally, perfect mirrors), clear
dielectrics, a constant sky, no emitter and no eye inside a medium -- a
converged path tracer and glassray's float64 reference draw the same image.
``glassray bench --peer mitsuba`` (viewer/bench.py) times both, side by side,
against that reference.  This module converts a glassray :class:`Scene` into a
Mitsuba 3 scene and renders it.

Conventions, each checked by tests/test_peer.py:

* camera: ``perspective`` sensor, ``fov_axis = "y"`` (Mitsuba's default is
  x; glassray's ``fov`` is vertical), the frame built here exactly as the
  spec builds it (f, right = f x +y, up = right x f; Mitsuba's camera space
  has +x to the image's *left*, so its x column is -right);
* pixels: ``hdrfilm`` with a ``box`` reconstruction filter (Mitsuba's default
  is a Gaussian that blurs across pixels), linear float RGB, rows top first:
  a converged pixel is the average over its square, like glassray's;
* the plane y = h: a flat mesh of concentric square rings (each 4x wider than
  the last, out to 10^6 scene units, so the sliver of missing floor under
  the horizon is far below a pixel and float32 vertex positions stay
  precise near the eye) facing +y; its emission is an ``area`` emitter
  (one-sided, facing up: the solid is below) whose radiance is a
  ``checkerboard`` texture on texture coordinates (x, z) / (2 size):
  Mitsuba 3.9's checkerboard takes ``color1`` where frac(u) > 1/2 differs
  from frac(v) > 1/2 (checked by rendering: tests/test_peer.py), that is
  where floor(x/size) + floor(z/size) is odd -- the spec's ``checker``
  squares;
* emission-only opaque materials: a black *delta* BSDF (a ``conductor``
  with ``specular_reflectance`` 0; without a BSDF Mitsuba gives an emitter a
  grey diffuse one) plus an ``area`` emitter.  Not a black ``diffuse``: on a
  smooth BSDF the path tracer samples an emitter at every hit (a shadow ray
  whose contribution is 0 here), which took 1.5-1.6x the CPU time for the
  very same image (tests/test_peer_audit.py);
  ``reflectivity`` r > 0: a perfect mirror (``conductor``, material
  ``none``) scaled by r;
* clear dielectrics: ``dielectric`` with ``int_ior = ior`` and ``ext_ior =
  1`` (Mitsuba's default exterior is air at 1.000277);
* sky: a ``constant`` emitter; exposure scales the image;
* integrator: ``path`` with ``max_depth`` = the scene's (both count the
  segments of a path: the primary hit is depth 1), ``hide_emitters`` false.

Variant: the fastest CPU variant that works here, ``llvm_ad_rgb`` (Dr.Jit's
LLVM backend; it needs libLLVM >= 16: Dr.Jit 1.5 aborts the whole process
on LLVM 15, so each candidate library is tried in a child process first),
else ``scalar_rgb``.  ``GLASSRAY_PEER_VARIANT`` forces one.
"""

from __future__ import annotations

import copy
import glob
import math
import os
import re
import subprocess
import sys
import time

import numpy as np

from .bench import Timings, ms_axis
from ..scene.model import Material, Scene, SceneObject

__all__ = ["PeerError", "PEERS", "reasons", "check_scene", "select_variant", "scene_dict", "MitsubaPeer",
           "peer_info"]

PEERS = ("mitsuba",)
VARIANTS = ("llvm_ad_rgb", "scalar_rgb")
#: Mitsuba's correlated multi-jittered sampler: of independent, stratified and
#: multijitter it had the lowest error per sample on whitted-exact (0.030
#: against 0.048 and 0.036 RMSE at 16 spp, 320x180), so the peer runs at its best.
DEFAULT_SAMPLER = "multijitter"
#: The BSDF of an opaque material that only emits: black, and delta, so that
#: the path tracer spends no shadow ray on it (a black ``diffuse`` one gives
#: the same image bit for bit in 1.47-1.64x the CPU time: whitted-glass at
#: 320x180, 1024 to 9216 samples; whitted-exact 1.4x at 256).
BLACK_BSDF = {"type": "conductor", "material": "none", "specular_reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
#: Measured: scalar_rgb against llvm_ad_rgb (whitted-glass, 160x90, 256 samples).
SCALAR_SLOWDOWN = "scalar_rgb took 6.4x the CPU time of llvm_ad_rgb on whitted-glass at 160x90"
#: The floor's outermost ring, in scene units from the origin.
FLOOR_EXTENT = 1.0e6


class PeerError(ValueError):
    """A scene the physically based peer cannot draw identically (or no peer)."""


# ---------------------------------------------------------------- qualifying


def _black(c) -> bool:
    return c is None or max(c) == 0.0


def _phong_is_zero(scene: Scene, m: Material) -> bool:
    """Whether C * (k_a A + sum over lights (...)) is 0 for every point."""
    colours = [m.color] + ([m.checker.color] if m.checker is not None else [])
    if all(_black(c) for c in colours):
        return True
    ambient_zero = m.ambient == 0.0 or _black(scene.ambient)
    lit = any(lt.intensity > 0 and not _black(lt.color) for lt in scene.lights)
    direct_zero = not lit or (m.diffuse == 0.0 and m.specular == 0.0)
    return ambient_zero and direct_zero


def _emissions(m: Material) -> list[tuple]:
    out = [tuple(m.emission)]
    if m.checker is not None and m.checker.emission is not None:
        out.append(tuple(m.checker.emission))
    return out


def _bbox(obj: SceneObject) -> tuple[np.ndarray, np.ndarray] | None:
    """Axis-aligned bounds of a finite solid (None for the plane)."""
    if obj.type == "plane":
        return None
    if obj.type == "sphere":
        c = np.array(obj.center, float)
        return c - obj.radius, c + obj.radius
    if obj.type == "box":
        from ..reference.trace import rotation_matrix

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
        lo, _ = _bbox(b)
        return lo[1] < a.height - tol
    if a.type == "sphere" and b.type == "sphere":
        d = math.dist(a.center, b.center)
        return d < a.radius + b.radius - tol
    (alo, ahi), (blo, bhi) = _bbox(a), _bbox(b)
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
        from ..reference.trace import rotation_matrix

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
                   if (bb := _bbox(o)) is not None])
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
            if any(not _black(e) for e in _emissions(m)):
                why.append(f"{where}: an emissive dielectric (emission inside a medium is scaled by ior^2 "
                           "in a physically based renderer)")
            if obj.type == "plane":
                why.append(f"{where}: a transparent plane (an infinite medium) is not supported")
        else:
            em = _emissions(m)
            if (obj.type != "plane" and m.checker is not None and m.checker.emission is not None
                    and tuple(m.checker.emission) != tuple(m.emission)):
                why.append(f"{where}: a checker on emission is supported on planes only")
            emissive = any(not _black(e) for e in em)
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
    try:
        from ..reference.trace import contains

        eye = np.array([scene.camera.position], float)
        for i, obj in enumerate(scene.objects):
            if bool(np.asarray(contains(obj, eye)).reshape(-1)[0]):
                why.append(f"the camera is inside {_name(scene, i)}"
                           + (" (below the plane)" if obj.type == "plane" else ""))
    except ImportError:  # pragma: no cover - the reference ships with the package
        pass
    return why


def check_scene(scene: Scene) -> None:
    """Raise PeerError with every reason when the scene does not qualify."""
    why = reasons(scene)
    if why:
        raise PeerError(f"scene {scene.name!r} cannot be compared with a physically based renderer: "
                        + "; ".join(why))


# ---------------------------------------------------------------- variant


def _llvm_candidates() -> list[str]:
    """libLLVM shared libraries, newest first, version >= 16 (Dr.Jit 1.5
    emits llvm.minimum, which LLVM 15's x86 back end cannot select)."""
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return [os.environ["DRJIT_LIBLLVM_PATH"]]
    found: dict[str, int] = {}
    for d in ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib64", "/usr/lib",
              "/usr/local/lib", "/opt/homebrew/opt/llvm/lib", "/usr/local/opt/llvm/lib"):
        for p in glob.glob(os.path.join(d, "libLLVM*.so*")) + glob.glob(os.path.join(d, "libLLVM*.dylib")):
            m = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", os.path.basename(p))
            if m and int(m.group(1)) >= 16:
                real = os.path.realpath(p)
                found.setdefault(real, int(m.group(1)))
    return sorted(found, key=lambda p: -found[p])


_PROBE = r"""
import numpy as np, mitsuba as mi
mi.set_variant("llvm_ad_rgb")
s = mi.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 4},
    "sensor": {"type": "perspective", "fov": 40, "film": {"type": "hdrfilm", "width": 8, "height": 8,
               "rfilter": {"type": "box"}}},
    "sky": {"type": "constant"},
    "ball": {"type": "sphere", "center": [0, 0, 4], "radius": 1, "bsdf": {"type": "dielectric"}}})
a = np.array(mi.render(s, spp=2))
print("PROBE-OK" if np.isfinite(a).all() else "PROBE-NAN")
"""

_selected: tuple[str, str] | None = None


def select_variant(requested: str | None = None) -> tuple[str, str]:
    """(variant, note).  The first call decides for the whole process (Mitsuba's
    variant and Dr.Jit's LLVM library are process-wide)."""
    global _selected
    if _selected is not None:
        return _selected
    try:
        import mitsuba  # noqa: F401
    except ImportError:
        raise PeerError("the peer needs Mitsuba 3: pip install 'glassray[peer]' (or pip install mitsuba)") from None
    requested = requested or os.environ.get("GLASSRAY_PEER_VARIANT") or None
    notes = []
    if requested in (None, "llvm_ad_rgb"):
        for lib in _llvm_candidates():
            env = {**os.environ, "DRJIT_LIBLLVM_PATH": lib}
            try:
                p = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True,
                                   timeout=180)
                ok = "PROBE-OK" in p.stdout
            except (OSError, subprocess.TimeoutExpired):
                ok = False
            if ok:
                os.environ["DRJIT_LIBLLVM_PATH"] = lib
                _selected = ("llvm_ad_rgb", f"llvm_ad_rgb with {lib}")
                break
            notes.append(f"LLVM backend failed with {lib}")
        else:
            if requested == "llvm_ad_rgb":
                raise PeerError("the llvm_ad_rgb variant does not work here ("
                                + ("; ".join(notes) or "no libLLVM >= 16 found") + ")")
            notes.append("no working libLLVM >= 16" if not notes else "")
    if _selected is None:
        variant = requested or "scalar_rgb"
        _selected = (variant, variant + (f" (fallback: {'; '.join(n for n in notes if n)})" if notes else ""))
    import mitsuba as mi

    mi.set_variant(_selected[0])
    return _selected


# ---------------------------------------------------------------- conversion


def _rgb(c, scale: float = 1.0) -> dict:
    return {"type": "rgb", "value": [float(x) * scale for x in c]}


def _camera_matrix(scene: Scene) -> np.ndarray:
    """Mitsuba camera-to-world: columns (-right, up, f, position): Mitsuba's
    camera looks down +z with +x to the image's left."""
    cam = scene.camera
    pos = np.array(cam.position, float)
    f = np.array(cam.target, float) - pos
    f /= np.linalg.norm(f)
    right = np.cross(f, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, f)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = -right, up, f, pos
    return m


def _floor_rings(height: float, inner: float, extent: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) and triangles (M, 3) of the plane y = height out to
    +-extent: a square of half-side ``inner``, then square rings each 4x wider,
    every triangle wound so that its normal is +y."""
    verts: list[tuple[float, float, float]] = []
    tris: list[tuple[int, int, int]] = []

    def rect(x0, x1, z0, z1):
        k = len(verts)
        verts.extend([(x0, height, z0), (x0, height, z1), (x1, height, z1), (x1, height, z0)])
        # (p1 - p0) x (p2 - p0) with p1 along +z and p2 along +x points up
        tris.extend([(k, k + 1, k + 3), (k + 1, k + 2, k + 3)])

    r = inner
    rect(-r, r, -r, r)
    while r < extent:
        big = min(4.0 * r, extent)
        rect(-big, big, -big, -r)   # z < -r strip
        rect(-big, big, r, big)     # z > r strip
        rect(-big, -r, -r, r)       # x < -r
        rect(r, big, -r, r)         # x > r
        r = big
    return np.array(verts, float), np.array(tris, np.uint32)


def _material_parts(m: Material, checker_uv: bool) -> dict:
    """Mitsuba 'bsdf' (and 'emitter') entries for an opaque or dielectric material."""
    import mitsuba as mi  # noqa: F401

    if m.is_dielectric:
        return {"bsdf": {"type": "dielectric", "int_ior": float(m.ior), "ext_ior": 1.0}}
    if m.reflectivity > 0:
        bsdf = {"type": "conductor", "material": "none", "specular_reflectance": _rgb((m.reflectivity,) * 3)}
    else:
        # black and delta: no next-event estimation at a surface that reflects nothing
        bsdf = copy.deepcopy(BLACK_BSDF)
    out = {"bsdf": bsdf}
    em0 = tuple(m.emission)
    em1 = tuple(m.checker.emission) if m.checker is not None and m.checker.emission is not None else em0
    if checker_uv and em1 != em0:
        s = float(m.checker.size)
        radiance = {"type": "checkerboard", "color0": _rgb(em0), "color1": _rgb(em1),
                    "to_uv": mi.ScalarTransform4f.scale([1.0 / (2 * s), 1.0 / (2 * s), 1.0])}
        out["emitter"] = {"type": "area", "radiance": radiance}
    elif not _black(em0):
        out["emitter"] = {"type": "area", "radiance": _rgb(em0)}
    return out


def _plane_mesh(scene: Scene, obj: SceneObject, index: int, inner: float):
    import mitsuba as mi

    m = scene.materials[obj.material]
    parts = _material_parts(m, checker_uv=True)
    v, f = _floor_rings(obj.height, inner, max(FLOOR_EXTENT, 1e4 * inner))
    props = mi.Properties()
    for key in ("bsdf", "emitter"):
        if key in parts:
            props[key] = mi.load_dict(parts[key])
    mesh = mi.Mesh(f"plane{index}", vertex_count=len(v), face_count=len(f), props=props,
                   has_vertex_normals=False, has_vertex_texcoords=True)
    params = mi.traverse(mesh)
    # texture coordinates (x, z): the checkerboard's to_uv divides by 2 size
    # flat interleaved buffers, of the parameter's own array type (llvm or
    # scalar: Point3f(numpy columns) only works in a vectorised variant)
    for name, data in (("vertex_positions", v.astype(np.float32)),
                       ("vertex_texcoords", v[:, [0, 2]].astype(np.float32)),
                       ("faces", f.astype(np.uint32))):
        params[name] = type(params[name])(np.ascontiguousarray(data).ravel())
    params.update()
    return mesh


def _disk(centre, normal, radius) -> "object":
    import mitsuba as mi

    n = np.array(normal, float)
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t = np.cross(n, a)
    t /= np.linalg.norm(t)
    b = np.cross(n, t)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = t * radius, b * radius, n, centre
    return mi.ScalarTransform4f(m.tolist())


def scene_dict(scene: Scene, width: int, height: int, *, max_depth: int | None = None,
               sampler: str = DEFAULT_SAMPLER, spp: int = 16, samples_per_pass: int | None = None,
               threads: int | None = None) -> dict:
    """The Mitsuba scene dictionary (a Mitsuba variant must be set; see
    select_variant).  Raises PeerError for a scene that does not qualify."""
    check_scene(scene)
    import mitsuba as mi

    from ..reference.trace import rotation_matrix

    depth = int(max_depth or scene.render.max_depth)
    integrator = {"type": "path", "max_depth": depth, "hide_emitters": False}
    if samples_per_pass:
        integrator["samples_per_pass"] = int(samples_per_pass)
    d: dict = {
        "type": "scene",
        "integrator": integrator,
        "sensor": {
            "type": "perspective",
            "fov": float(scene.camera.fov),
            "fov_axis": "y",
            "near_clip": 1e-4,
            "far_clip": 10.0 * FLOOR_EXTENT,   # Mitsuba's default, 1e4, would cut the floor short of the horizon
            "to_world": mi.ScalarTransform4f(_camera_matrix(scene).tolist()),
            "sampler": {"type": sampler, "sample_count": int(spp)},
            "film": {"type": "hdrfilm", "width": int(width), "height": int(height), "rfilter": {"type": "box"},
                     "pixel_format": "rgb", "component_format": "float32", "sample_border": False},
        },
    }
    if not _black(scene.sky.color):
        d["sky"] = {"type": "constant", "radiance": _rgb(scene.sky.color)}
    extent = max([1.0] + [abs(x) for x in scene.camera.position] + [abs(x) for x in scene.camera.target]
                 + [float(np.max(np.abs(np.concatenate(bb)))) for o in scene.objects
                    if (bb := _bbox(o)) is not None])
    for i, obj in enumerate(scene.objects):
        m = scene.materials[obj.material]
        key = f"obj{i:03d}"
        if obj.type == "plane":
            d[key] = _plane_mesh(scene, obj, i, inner=4.0 * extent)
            continue
        parts = _material_parts(m, checker_uv=False)
        if obj.type == "sphere":
            d[key] = {"type": "sphere", "center": [float(x) for x in obj.center], "radius": float(obj.radius),
                      **parts}
        elif obj.type == "box":
            lo, hi = np.array(obj.min, float), np.array(obj.max, float)
            mat = np.eye(4)
            mat[:3, :3] = rotation_matrix(obj.rotate) @ np.diag((hi - lo) / 2)
            mat[:3, 3] = (lo + hi) / 2
            d[key] = {"type": "cube", "to_world": mi.ScalarTransform4f(mat.tolist()), **parts}
        elif obj.type == "cylinder":
            a = "xyz".index(obj.axis)
            axis = np.zeros(3)
            axis[a] = 1.0
            p0 = np.array(obj.base, float)
            p1 = p0 + obj.height * axis
            # an open tube plus two caps; each part its own emitter where emissive
            d[key] = {"type": "cylinder", "p0": p0.tolist(), "p1": p1.tolist(), "radius": float(obj.radius),
                      **parts}
            d[key + "b"] = {"type": "disk", "to_world": _disk(p0, -axis, obj.radius),
                            **_material_parts(m, checker_uv=False)}
            d[key + "t"] = {"type": "disk", "to_world": _disk(p1, axis, obj.radius),
                            **_material_parts(m, checker_uv=False)}
        else:  # pragma: no cover - the scene validator knows no other type
            raise PeerError(f"objects[{i}]: type {obj.type!r} is not converted")
    return d


# ---------------------------------------------------------------- rendering


def _cores() -> int:
    from .bench import usable_cpus

    return usable_cpus()


class MitsubaPeer:
    """A Mitsuba 3 scene of a glassray scene at one size, ready to render."""

    def __init__(self, scene: Scene, width: int, height: int, *, max_depth: int | None = None,
                 sampler: str = DEFAULT_SAMPLER, variant: str | None = None, threads: int | None = None,
                 samples_per_pass: int | None = None):
        check_scene(scene)
        self.variant, self.variant_note = select_variant(variant)
        import drjit as dr
        import mitsuba as mi

        self.threads = int(threads or _cores())
        dr.set_thread_count(self.threads)
        self.scene = scene
        self.width, self.height = int(width), int(height)
        self.max_depth = int(max_depth or scene.render.max_depth)
        self.sampler = sampler
        t0 = time.perf_counter()
        self.mi_scene = mi.load_dict(scene_dict(scene, width, height, max_depth=self.max_depth, sampler=sampler,
                                                samples_per_pass=samples_per_pass))
        self.load_s = time.perf_counter() - t0

    def render(self, spp: int, seed: int = 0) -> np.ndarray:
        """(H, W, 3) float64 linear RGB, exposure applied, top row first;
        returns when the render is finished (the array is evaluated)."""
        import mitsuba as mi

        from ..base import interrupt

        interrupt.check()                             # Ctrl-C between renders (viewer/interrupt.py)
        img = mi.render(self.mi_scene, spp=int(spp), seed=int(seed))
        a = np.array(img, dtype=np.float64)          # forces the JIT to run the kernel
        return a[..., :3] * self.scene.render.exposure


def slow_variant_warning(variant: str) -> str | None:
    """What a report must say when the peer is not Mitsuba's fastest CPU
    variant (None when it is)."""
    if variant == VARIANTS[0]:
        return None
    return (f"Mitsuba runs its {variant} variant, not {VARIANTS[0]} (its fastest on a CPU, which needs a "
            f"working libLLVM >= 16): several times slower per sample ({SCALAR_SLOWDOWN}), so these ratios "
            "overstate glassray's lead")


def llvmpipe_threads() -> int | None:
    """How many llvmpipe rasteriser threads this process runs (Linux: the
    threads named llvmpipe-N), None where that cannot be seen."""
    try:
        names = [open(os.path.join("/proc/self/task", t, "comm")).read().strip()
                 for t in os.listdir("/proc/self/task")]
    except OSError:
        return None
    n = sum(1 for c in names if c.startswith("llvmpipe-"))
    return n or None


def peer_info(peer: MitsubaPeer | None = None) -> dict:
    import drjit as dr
    import mitsuba as mi

    info = {"peer": "mitsuba", "mitsuba": mi.__version__, "drjit": dr.__version__}
    if peer is not None:
        info.update({"variant": peer.variant, "variant_note": peer.variant_note, "threads": peer.threads,
                     "sampler": peer.sampler, "integrator": f"path, max_depth {peer.max_depth}, rr_depth 5 "
                     "(Mitsuba's default), hide_emitters false", "rfilter": "box", "fov_axis": "y",
                     "emitter_bsdf": "black conductor (delta: no shadow rays)",
                     "scene_load_s": round(peer.load_s, 3)})
    return info


# ---------------------------------------------------------------- the side-by-side benchmark
#
# ``glassray bench --peer mitsuba [SCENE]`` (viewer/bench.py parses the
# options and calls run_bench).  Each series is a list of points (a sample
# count, or an adaptive target); every point is rendered once untimed (its
# image is the one compared with the reference, and it compiles / warms up
# whatever it needs), then all points of all series are timed in ``repeat``
# interleaved rounds (order reversed every other round), medians reported.

PEER_DEFAULT_SCENE = "whitted-exact"
PEER_REFERENCE_SAMPLES = 512
#: ... and 8192 in the pixels where those disagree (about a third of
#: whitted-exact's at 320x180): 512 everywhere left the reference off by
#: RMSE 0.0027 itself, which is what the renderers reach at 256-512
#: samples, so lower errors could not be measured (see
#: viewer.reference.render_reference_refined)
PEER_REFERENCE_REFINE = 8192
PEER_QUICK_REFERENCE_SAMPLES = 16
GLASSRAY_SPP = (1, 2, 4, 8, 16, 32, 64, 128, 256)
#: Squares only: Mitsuba's multijitter sampler rounds other counts up to a
#: product of two near factors (32 -> 35, 2048 -> 2070, 8192 -> 8280), with
#: a warning each.  Measured per sample (whitted-glass, 320x180, peerwg4):
#: the powers of 4 took 8.7-9.5 ms of wall time, the counts 9 * 4^k
#: 11.0-11.8 ms (the rounded counts of the earlier series: 12.4-13.1 ms), so
#: docs/benchmark.md also gives the ratio at the 4096 point's rate.  Up to the time
#: limit (36864 = 192^2 only with --peer-time-limit over 16384's time: about
#: 47 s on a 2-core machine).
MITSUBA_SPP = (1, 4, 9, 16, 36, 64, 144, 256, 576, 1024, 2304, 4096, 9216, 16384, 36864)
#: The adaptive series: `render --adaptive --samples N` at the default
#: target error, N = each of these budgets (mean rays per pixel).
ADAPTIVE_BUDGETS = (2, 4, 8, 16, 32, 64, 128)     # ≤256 stops where ≤128 does (the target)
QUICK_GLASSRAY_SPP = (1, 2, 4)
QUICK_MITSUBA_SPP = (1, 2, 4, 8)
QUICK_ADAPTIVE_BUDGETS = (4, 8)
TARGET_ERRORS = (0.1, 0.07, 0.05, 0.04, 0.03, 0.025, 0.02, 0.015, 0.01, 0.007, 0.005, 0.004, 0.003,
                 0.002, 0.0015, 0.0012, 0.001, 0.0008, 0.0007)
#: A Mitsuba point whose warm-up render took longer than this (seconds) ends
#: its series: the next sample count (MITSUBA_SPP: 1.78-4 times as many)
#: would take that much longer.
PEER_TIME_LIMIT_S = 30.0

PEER_CSV_COLUMNS = ("series", "renderer", "point", "samples", "effective_spp", "width", "height", "time_ms",
                    "time_min_ms", "time_max_ms", "cpu_ms", "repeat", "rmse", "frac_off_1_255", "max_abs_err")
TTE_CSV_COLUMNS = ("target_rmse", "clock", "glassray_ms", "mitsuba_ms", "ratio_mitsuba_over_glassray",
                   "glassray_adaptive_ms", "ratio_mitsuba_over_adaptive")


class Point(Timings):
    """One measured point of a series (its medians: bench.Timings)."""

    def __init__(self, series: str, label: str, samples: int, run):
        self.series, self.label, self.samples, self.run = series, label, samples, run
        self.effective_spp: float = float(samples)
        self.times: list[float] = []
        self.cpu_times: list[float] = []
        self.errors: dict[str, float] = {}


def time_to_error(points: list[Point], target: float, clock: str = "wall") -> tuple[float | None, str]:
    """Time at which a series first reaches ``target`` RMSE, interpolated
    log-log between the two measured points around the first crossing (in
    order of increasing samples); (None, "not reached") when no measured point
    is at or below it (no extrapolation), (t0, "<=") when the first point is
    already there (only a bound: the series cannot be cheaper than measured)."""
    pts = [(p.t(clock), p.errors["rmse"]) for p in points]
    if not pts:
        return None, "not reached"
    if pts[0][1] <= target:
        return pts[0][0], "<="
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e0 > target >= e1:
            if e1 <= 0 or t0 <= 0 or t1 <= 0:
                return t1, ""
            f = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0))), ""
    return None, "not reached"


def _fmt_ms(t: float | None, flag: str) -> str:
    if t is None:
        return "not reached"
    return (f"<={t:.0f}" if flag == "<=" else f"{t:.0f}") if t >= 10 else (
        f"<={t:.1f}" if flag == "<=" else f"{t:.1f}")


def _ratio(a: tuple[float | None, str], b: tuple[float | None, str]) -> tuple[float | None, str]:
    """a / b (how many times sooner b reaches the error than a) and how sure:
    "" exact, ">=" a lower bound (b's time is an upper bound), "n/a"."""
    (ta, fa), (tb, fb) = a, b
    if ta is None or tb is None:
        if tb is not None and ta is None:
            return None, "peer not reached"
        return None, "n/a"
    if fa == "<=" and fb == "<=":
        return ta / tb, "~"
    if fa == "<=":
        return ta / tb, "<="
    if fb == "<=":
        return ta / tb, ">="
    return ta / tb, ""


def _fmt_ratio(r: tuple[float | None, str]) -> str:
    v, flag = r
    if v is None:
        return flag
    pre = {"<=": "<=", ">=": ">=", "~": "~", ">": ">"}.get(flag, "")
    return f"{pre}{v:.2f}x" if v < 10 else f"{pre}{v:.0f}x"


def _series_table(series: dict[str, list[Point]]) -> str:
    head = ("series", "point", "spp (effective)", "ms (median)", "min..max", "CPU ms", "RMSE", ">1/255",
            "max err")
    rows = []
    for name, pts in series.items():
        for p in pts:
            rows.append((name, p.label, f"{p.effective_spp:.4g}", f"{p.time_ms:.1f}",
                         f"{min(p.times):.0f}..{max(p.times):.0f}", f"{p.cpu_ms:.0f}",
                         f"{p.errors['rmse']:.4f}", f"{100 * p.errors['frac_off']:.1f}%",
                         f"{p.errors['max_abs']:.3f}"))
    return _md_table(head, rows, right={2, 3, 4, 5, 6, 7, 8})


def _md_table(head, rows, right=frozenset()) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(head)]

    def line(cells):
        return "| " + " | ".join(c.rjust(w) if i in right else c.ljust(w)
                                 for i, (c, w) in enumerate(zip(cells, widths))) + " |"

    sep = "|" + "|".join(("-" * (w + 1) + ":") if i in right else ("-" * (w + 2)) for i, w in enumerate(widths)) + "|"
    return "\n".join([line(head), sep, *(line(r) for r in rows)])


def _tte_rows(series: dict[str, list[Point]], targets, clock: str):
    rows = []
    g = series.get("glassray", [])
    m = series.get("mitsuba", [])
    a = series.get("glassray adaptive")
    if a is not None:   # an adaptive series' curve runs in order of its cost, not of its target
        a = sorted(a, key=lambda p: p.t(clock))
    for e in targets:
        tg, tm = time_to_error(g, e, clock), time_to_error(m, e, clock)
        ta = time_to_error(a, e, clock) if a is not None else None
        r = _ratio(tm, tg)
        ra = _ratio(tm, ta) if ta is not None else None
        if m and tm[0] is None:
            # the peer never got there: its slowest measured point bounds the ratio from below
            last = max(p.t(clock) for p in m)
            if tg[0] is not None:
                r = (last / tg[0], ">")
            if ta is not None and ta[0] is not None:
                ra = (last / ta[0], ">")
        rows.append((e, tg, tm, r, ta, ra))
    return rows


def _tte_table(rows, adaptive: bool, clock: str) -> str:
    head = ["target RMSE", "glassray ms", "mitsuba ms", "mitsuba / glassray"]
    if adaptive:
        head += ["glassray adaptive ms", "mitsuba / adaptive"]
    out = []
    for e, tg, tm, r, ta, ra in rows:
        cells = [f"{e:g}", _fmt_ms(*tg), _fmt_ms(*tm), _fmt_ratio(r)]
        if adaptive:
            cells += [_fmt_ms(*ta), _fmt_ratio(ra)]
        out.append(tuple(cells))
    return _md_table(head, out, right=set(range(1, len(head))))


def _plot(path, series: dict[str, list[Point]], targets, subtitle: str) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    import io

    from .bench import write_output     # an OSError becomes a message naming the file

    styles = {"glassray": ("#d62728", "o"), "mitsuba": ("#1f77b4", "s"), "glassray adaptive": ("#2ca02c", "^")}
    fig, axes = plt.subplots(1, 2, figsize=(12.0, 4.8))
    for ax, clock in zip(axes, ("wall", "cpu")):
        for name, pts in series.items():
            if not pts:
                continue
            colour, marker = styles.get(name, ("#7f7f7f", "x"))
            xs = [p.t(clock) for p in pts]
            ys = [max(p.errors["rmse"], 1e-6) for p in pts]
            ax.plot(xs, ys, color=colour, marker=marker, ms=5, lw=1.2, label=name)
            for p, x, y in zip(pts, xs, ys):
                ax.annotate(p.label, (x, y), textcoords="offset points", xytext=(4, 3), fontsize=6.5,
                            color=colour)
        for e in targets:
            ax.axhline(e, color="#999999", lw=0.5, ls=":")
        ms_axis(ax)
        ax.set_yscale("log")
        ax.set_xlabel("time per image, ms (median, wall clock)" if clock == "wall" else
                      "CPU time per image, ms (median, all threads of the process)")
        ax.set_ylabel("RMSE against the float64 reference (linear)")
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=8)
    import textwrap

    fig.suptitle("\n".join(textwrap.wrap(subtitle, 150)), fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    write_output(path, buf.getvalue())
    return True


def run_bench(args, ctx, backend: str, name: str, scene, width: int, height: int, out, log) -> int:
    """The side-by-side comparison; writes peer.md, peer.csv,
    peer-time-to-error.csv, peer-machine.json and peer.png to ``out``."""
    import csv
    import io
    import json
    from pathlib import Path

    from . import bench
    from .bench import write_output     # an OSError becomes a message naming the file
    from ..gpu.renderer import Renderer

    out = Path(out)
    stem = Path(name).stem if str(name).endswith(".toml") else name
    quick = bool(getattr(args, "quick", False))
    repeat = int(args.repeat)
    ref_samples = args.reference_samples or (PEER_QUICK_REFERENCE_SAMPLES if quick else PEER_REFERENCE_SAMPLES)
    refine = getattr(args, "reference_refine", None)
    refine = (0 if quick else PEER_REFERENCE_REFINE) if refine is None else refine
    g_spp = QUICK_GLASSRAY_SPP if quick else GLASSRAY_SPP
    m_spp = QUICK_MITSUBA_SPP if quick else MITSUBA_SPP
    a_budgets = QUICK_ADAPTIVE_BUDGETS if quick else ADAPTIVE_BUDGETS
    limit_s = float(getattr(args, "peer_time_limit", None) or PEER_TIME_LIMIT_S)

    info = bench.machine_info(ctx, backend)
    log(f"peer comparison on {stem} ({scene.name}), {width}x{height}")
    log(f"machine: {info['cpu']} ({info['cpus_usable']} usable CPUs), load average "
        f"{info.get('load_average_start', ['?'])[0]}; GL: {info['gl']} via {backend}")
    peer = MitsubaPeer(scene, width, height)
    info["peer"] = peer_info(peer)
    log(f"peer: Mitsuba {info['peer']['mitsuba']} ({peer.variant_note}), {peer.threads} threads, "
        f"sampler {peer.sampler}, path tracer max depth {peer.max_depth}")
    slow = slow_variant_warning(peer.variant)
    if slow:
        info["peer"]["warning"] = slow
        log(f"warning: {slow}")

    refined = bench.effective_refine(ref_samples, refine)
    ref_text = bench.reference_text(ref_samples, refined)
    log(f"reference {width}x{height}, {ref_text} ...")
    t0 = time.perf_counter()
    ref, kind, cached = bench.reference_image(scene, stem, width, height, ref_samples, out, ctx=ctx, log=log,
                                              refine=refined)
    log(f"reference {'from the cache' if cached else f'took {time.perf_counter() - t0:.1f} s'}")

    from ..adaptive.sampler import DEFAULT_TARGET_ERROR, render_adaptive

    renderer = Renderer(ctx, scene, eager=False)
    renderer.SUBSET_PROGRAMS = bench._Renderers.SUBSET_PROGRAMS   # keep every culling variant compiled
    series: dict[str, list[Point]] = {"glassray": [], "mitsuba": []}

    def gl_run(n):
        return lambda: renderer.render(width, height, n, bench.RENDER_SEED)

    def mi_run(n):
        return lambda: peer.render(n, seed=bench.RENDER_SEED)

    def ad_run(n):
        return lambda: render_adaptive(renderer, width, height, n, seed=bench.RENDER_SEED)

    try:
        for n in g_spp:
            series["glassray"].append(Point("glassray", f"{n}", n, gl_run(n)))
        series["glassray adaptive"] = [Point("glassray adaptive", f"<={n}", n, ad_run(n)) for n in a_budgets]
        # untimed first renders: the images compared, kernels compiled
        for sname, pts in list(series.items()):
            if sname == "mitsuba":
                continue
            for p in pts:
                # rendered again until nothing is left to compile: no timed render compiles
                res = bench.warm_up(renderer, p.run)
                if sname == "glassray adaptive":
                    img = res.image
                    p.effective_spp = res.rays / res.spp.size     # rays per pixel, the corner rays included
                else:
                    img = res
                p.errors = bench.image_errors(img, ref)
        for n in m_spp:
            p = Point("mitsuba", f"{n}", n, mi_run(n))
            t0 = time.perf_counter()
            img = p.run()
            took = time.perf_counter() - t0
            p.run()   # a second untimed render: the first of each size also traces and compiles the kernel
            p.errors = bench.image_errors(img, ref)
            try:
                p.effective_spp = float(peer.mi_scene.sensors()[0].sampler().sample_count())
            except Exception:  # pragma: no cover - introspection only
                pass
            series["mitsuba"].append(p)
            if took > limit_s:
                log(f"mitsuba: {n} spp took {took:.1f} s: larger sample counts left out")
                break
        order = [p for pts in series.values() for p in pts]
        built = renderer.programs_built
        for k in range(repeat):
            for p in (order if k % 2 == 0 else order[::-1]):
                c0, t0 = time.process_time(), time.perf_counter()
                p.run()
                ctx.finish()
                p.times.append((time.perf_counter() - t0) * 1000.0)
                p.cpu_times.append((time.process_time() - c0) * 1000.0)
            log(f"round {k + 1}/{repeat} done")
        built_timed = renderer.programs_built - built
        gl_threads = llvmpipe_threads()
        if built_timed:
            log(f"warning: glassray's timed renders built {built_timed} shader programs")
    finally:
        renderer.release()

    if hasattr(os, "getloadavg"):
        info["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    adaptive = "glassray adaptive" in series
    tte = {clock: _tte_rows(series, TARGET_ERRORS, clock) for clock in ("wall", "cpu")}
    info.update({
        "size": f"{width}x{height}", "scene": stem, "repeat": repeat, "quick": quick,
        "reference": {"kind": kind, "samples": ref_samples, "refined_samples": refined,
                      "refine_tolerance": bench.REFINE_TOLERANCE if refined else None, "seed": bench.REFERENCE_SEED,
                      "max_depth": bench.REFERENCE_MAX_DEPTH, "min_weight": bench.REFERENCE_MIN_WEIGHT},
        "glassray": {"max_depth": scene.render.max_depth, "min_weight": scene.render.min_weight,
                     "programs_built_in_timed_rounds": built_timed, "llvmpipe_threads": gl_threads,
                     "LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS"),
                     "sampling": "stratified sub-pixel offsets (viewer.sampling), uniform over the image"},
        "adaptive": ({"budgets_spp": list(a_budgets), "target": DEFAULT_TARGET_ERROR} if adaptive else None),
        "time_to_error": {clock: [{"target": e, "glassray_ms": tg[0], "mitsuba_ms": tm[0],
                                   "ratio": r[0], "ratio_flag": r[1],
                                   "adaptive_ms": ta[0] if ta else None,
                                   "ratio_adaptive": ra[0] if ra else None,
                                   "ratio_adaptive_flag": ra[1] if ra else None}
                                  for e, tg, tm, r, ta, ra in rows] for clock, rows in tte.items()},
    })

    header = [
        f"glassray bench --peer mitsuba, {info['date']}",
        f"scene {stem} ({scene.name}), {width}x{height}; machine: {info['cpu']}, {info['cpus_usable']} usable "
        f"CPUs, load average {info.get('load_average_start', ['?'])[0]} at start, "
        f"{info.get('load_average_end', ['?'])[0]} at end",
        f"glassray: GLSL shader on {info['gl']} via {backend}, max depth {scene.render.max_depth}, "
        f"min weight {scene.render.min_weight:g}, stratified samples",
        f"peer: Mitsuba {info['peer']['mitsuba']} (Dr.Jit {info['peer']['drjit']}), variant {peer.variant_note}, "
        f"{peer.threads} threads, path tracer max depth {peer.max_depth}, {peer.sampler} sampler, box filter, "
        "black delta BSDF on surfaces that only emit (no shadow rays)",
        f"threads: Mitsuba {peer.threads}, llvmpipe "
        + (f"{gl_threads}" if gl_threads is not None else "its default")
        + (f" (LP_NUM_THREADS={os.environ['LP_NUM_THREADS']})" if os.environ.get("LP_NUM_THREADS") else "")
        + f", on {info['cpus_usable']} usable CPUs",
        f"error: RMSE (linear) against the float64 reference, {ref_text} (seed {bench.REFERENCE_SEED}), "
        f"max depth {bench.REFERENCE_MAX_DEPTH}, min weight {bench.REFERENCE_MIN_WEIGHT:g}; the same function "
        "and reference for both renderers",
        f"time: median of {repeat} interleaved timed renders after untimed warm-up renders (compiling is not "
        "timed for either: glassray's shader programs, Mitsuba's kernel for each sample count); each render "
        "finished (read back) before the clock stops; time to reach an error: log-log interpolation between "
        "measured points, no extrapolation",
    ]
    if slow:
        header.append(f"WARNING: {slow}")
    text = "\n".join(f"    {h}" for h in header) + "\n\n### Measured series\n\n" + _series_table(series)
    for clock, title in (("wall", "wall clock"), ("cpu", "CPU time of the process")):
        text += (f"\n\n### Time to reach an RMSE ({title}); ratio = how many times sooner glassray gets there\n\n"
                 + _tte_table(tte[clock], adaptive, clock))
    text += "\n"

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=PEER_CSV_COLUMNS, lineterminator="\n")
    w.writeheader()
    for sname, pts in series.items():
        for p in pts:
            w.writerow({"series": sname, "renderer": "mitsuba" if sname == "mitsuba" else "glassray",
                        "point": p.label, "samples": p.samples, "effective_spp": f"{p.effective_spp:.6g}",
                        "width": width, "height": height, "time_ms": f"{p.time_ms:.4f}",
                        "time_min_ms": f"{min(p.times):.4f}", "time_max_ms": f"{max(p.times):.4f}",
                        "cpu_ms": f"{p.cpu_ms:.4f}", "repeat": len(p.times), "rmse": f"{p.errors['rmse']:.10g}",
                        "frac_off_1_255": f"{p.errors['frac_off']:.6g}",
                        "max_abs_err": f"{p.errors['max_abs']:.6g}"})
    peer_csv = buf.getvalue().encode("utf-8")
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=TTE_CSV_COLUMNS, lineterminator="\n")
    w.writeheader()

    def num(x):
        return "" if x is None else f"{x:.6g}"

    for clock, rows in tte.items():
        for e, tg, tm, r, ta, ra in rows:
            w.writerow({"target_rmse": f"{e:g}", "clock": clock, "glassray_ms": num(tg[0]), "mitsuba_ms": num(tm[0]),
                        "ratio_mitsuba_over_glassray": num(r[0]),
                        "glassray_adaptive_ms": num(ta[0]) if ta else "",
                        "ratio_mitsuba_over_adaptive": num(ra[0]) if ra else ""})
    stale = []
    with bench.results_written_together():      # all of them, or none
        write_output(out / "peer.csv", peer_csv)
        write_output(out / "peer-time-to-error.csv", buf.getvalue().encode("utf-8"))
        write_output(out / "peer.md", text.encode("utf-8"))
        write_output(out / "peer-machine.json", (json.dumps(info, indent=2) + "\n").encode("utf-8"))
        from ..gpu.context import renderer_and_release

        plotted = _plot(out / "peer.png", series, TARGET_ERRORS,
                        f"glassray on {renderer_and_release(info['gl'])} vs "
                        f"Mitsuba {info['peer']['mitsuba']} ({peer.variant}, {peer.threads} threads), "
                        f"{stem} {width}x{height}, {info['cpus_usable']} CPUs, reference {ref_samples}"
                        f"{f'/{refined}' if refined else ''} spp; "
                        f"{info['date'][:10]}")
        if not plotted:
            stale = bench.remove_stale([out / "peer.png"])
    print(text, end="")
    print()
    print(f"wrote {out / 'peer.md'}, {out / 'peer.csv'}, {out / 'peer-time-to-error.csv'}, "
          f"{out / 'peer-machine.json'}" + (f", {out / 'peer.png'}" if plotted else ""))
    if not plotted:
        print("no plot: peer.png needs matplotlib (pip install 'glassray[bench]')")
        if stale:
            print(f"removed the plot of an earlier run: {out / 'peer.png'}")
    return 0
