"""A physically based peer for the benchmark: the same scene in Mitsuba 3.

On a scene where exact Whitted tracing is physically exact -- opaque
materials that only emit (and, optionally, perfect mirrors), clear
dielectrics, a constant sky, no emitter and no eye inside a medium -- a
converged path tracer and glassray's float64 reference draw the same image.
``glassray bench --peer mitsuba`` (viewer/measure/peer.py) times both, side
by side, against that reference (viewer/measure/peer_check.py says which
scenes qualify).  This module converts a glassray :class:`Scene` into a
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
import os
import re
import subprocess
import sys
import time

import numpy as np

from ..base import interrupt
from ..reference.primitives import rotation_matrix
from ..scene.model import Material, Scene, SceneObject
from .kit import usable_cpus
from .peer_check import PeerError, bounding_box, check_scene, is_black

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
    elif not is_black(em0):
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
    if not is_black(scene.sky.color):
        d["sky"] = {"type": "constant", "radiance": _rgb(scene.sky.color)}
    extent = max([1.0] + [abs(x) for x in scene.camera.position] + [abs(x) for x in scene.camera.target]
                 + [float(np.max(np.abs(np.concatenate(bb)))) for o in scene.objects
                    if (bb := bounding_box(o)) is not None])
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


class MitsubaPeer:
    """A Mitsuba 3 scene of a glassray scene at one size, ready to render."""

    def __init__(self, scene: Scene, width: int, height: int, *, max_depth: int | None = None,
                 sampler: str = DEFAULT_SAMPLER, variant: str | None = None, threads: int | None = None,
                 samples_per_pass: int | None = None):
        check_scene(scene)
        self.variant, self.variant_note = select_variant(variant)
        import drjit as dr
        import mitsuba as mi

        self.threads = int(threads or usable_cpus())
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

        interrupt.check()                             # Ctrl-C between renders (viewer/base/interrupt.py)
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
