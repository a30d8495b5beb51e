"""The scene packed for the GPU: numpy structured dtypes that mirror the GLSL
uniform block in shaders/lib/scene_block.glsl member for member (all vec4 /
ivec4 sized, so std140 adds no padding), the compile-time defines, and the
camera uniforms.

Everything is camera-relative: positions have the eye subtracted in float64
here, so a scene far from the world origin keeps float32 precision where it
matters (near the eye).  The checker's world anchoring is kept by passing the
eye's (x, z) modulo 2 * size (the period of the parity).
"""

from __future__ import annotations

import copy
import math
import re
import sys
from dataclasses import dataclass

import numpy as np

from ..scene.model import Scene, SceneObject
from ..scene.load import unit_vector

OBJ_TYPES = {"plane": 0, "sphere": 1, "box": 2, "cylinder": 3}
SKY_TYPES = {"color": 0, "gradient": 1, "image": 2}
AXES = {"x": 0, "y": 1, "z": 2}

OBJECT_DTYPE = np.dtype([("a", "<f4", 4), ("b", "<f4", 4), ("c", "<f4", 4), ("d", "<f4", 4),
                         ("e", "<f4", 4), ("info", "<i4", 4), ("bound", "<f4", 4)])
MATERIAL_DTYPE = np.dtype([("colorAmbient", "<f4", 4), ("phong", "<f4", 4), ("dielectric", "<f4", 4),
                           ("absorption", "<f4", 4), ("emission", "<f4", 4), ("checkerColor", "<f4", 4),
                           ("checkerEmission", "<f4", 4), ("checkerOffset", "<f4", 4)])
LIGHT_DTYPE = np.dtype([("vector", "<f4", 4), ("radiance", "<f4", 4)])
MEDIUM_DTYPE = np.dtype([("index", "<i4", 4), ("optics", "<f4", 4), ("absorption", "<f4", 4)])
TAIL_DTYPE = np.dtype([("ambient", "<f4", 4), ("skyColor", "<f4", 4), ("skyHorizon", "<f4", 4),
                       ("skyZenith", "<f4", 4), ("params", "<f4", 4), ("iparams", "<i4", 4),
                       ("counts", "<i4", 4)])

# Array sizes of the GENERIC shader (all features, counts read at run time);
# its uniform block stays under the 64 KiB that llvmpipe and most GPUs allow.
GENERIC_LENS = {"OBJECTS_LEN": 64, "MATERIALS_LEN": 64, "LIGHTS_LEN": 16, "MEDIA_LEN": 32}
GENERIC_STACK = 65
assert OBJECT_DTYPE.itemsize == 112 and MATERIAL_DTYPE.itemsize == 128 and LIGHT_DTYPE.itemsize == 32

# Offsets for leaving a surface (see surfaceEps in trace.frag).
EPS_REL = 2e-6        # of the hit point's magnitude (camera-relative); ~16 float32 ulps
EPS_SCENE = 1e-6      # of the scene's size


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


# ---------------------------------------------------------------- units for the GPU
#
# The shader computes in float32, whose squares of lengths overflow past about
# 1e19 and flush to zero below about 1e-19.  A scene at such a scale (valid: the
# format sets no unit) is therefore uploaded in units where the camera's
# distance to its target is about 1: every length is multiplied by the same
# power of two, which is exact in binary floating point, the shader's epsilons
# are relative to the scene's size, and absorption (per unit length) is
# divided by it, so the picture is that of the scene as written.  Inside
# GPU_DISTANCE_RANGE nothing changes (bit for bit).
GPU_DISTANCE_RANGE = (2.0 ** -20, 2.0 ** 20)
F32_MAX = float(np.finfo(np.float32).max)


def camera_distance_exponent(scene: Scene) -> int:
    """e with |target - position| in [2^(e-1), 2^e) (frexp's exponent),
    computed without overflow or underflow for any finite camera."""
    c = scene.camera
    s = max(abs(float(v)) for v in (*c.position, *c.target))
    # s > 0: validation keeps position != target
    hyp = math.hypot(*(t / s - p / s for t, p in zip(c.target, c.position)))
    return math.frexp(s)[1] + math.frexp(hyp)[1] - 1


def view_length_exponent(scene: Scene) -> int:
    """The exponent of the scene's unit length for the GPU: that of the
    camera's distance to its target (camera_distance_exponent), but never
    below 2^-20 of the bounded objects' extent.  The image depends on the
    view direction only, so a camera 5e-324 from its target in a scene of
    size 1 is an ordinary view; its distance alone would have scaled the
    scene by 2^1075, past float64 (OverflowError)."""
    e = camera_distance_exponent(scene)
    ext = _extent(scene)
    if 0 < ext < math.inf:
        e = max(e, math.frexp(ext)[1] - 20)
    return e


def gpu_length_exponent(scene: Scene) -> int:
    """k such that the GPU gets the scene's lengths times 2^k: 0 when the
    scene's unit length (view_length_exponent) lies in GPU_DISTANCE_RANGE,
    else the k that brings it to [1, 2)."""
    e = view_length_exponent(scene)
    lo, hi = (math.frexp(v)[1] for v in GPU_DISTANCE_RANGE)
    return 0 if lo <= e <= hi else 1 - e


def scaled_scene(scene: Scene, k: int) -> Scene:
    """A copy of `scene` with every length times 2^k (positions, sizes,
    checker squares) and absorption times 2^-k; the same scene when k == 0."""
    if k == 0:
        return scene

    def vec(v):
        return tuple(_ldexp(float(c), k) for c in v)

    out = copy.deepcopy(scene)
    out.camera.position, out.camera.target = vec(out.camera.position), vec(out.camera.target)
    for lt in out.lights:
        if lt.position is not None:
            lt.position = vec(lt.position)
    for m in out.materials.values():
        m.absorption = tuple(_ldexp(float(c), -k) for c in m.absorption)
        if m.checker is not None:
            m.checker.size = _ldexp(m.checker.size, k)
    for o in out.objects:
        o.height, o.radius = _ldexp(o.height, k), _ldexp(o.radius, k)
        o.center, o.min, o.max, o.base = vec(o.center), vec(o.min), vec(o.max), vec(o.base)
        if o.wall is not None:
            o.wall = _ldexp(o.wall, k)
    return out


def _ldexp(x: float, k: int) -> float:
    """x * 2^k, at +-float64's largest where that overflows (a far light or
    plane the scaling takes past it: reached_scene brings it back)."""
    try:
        return math.ldexp(x, k)
    except OverflowError:
        return math.copysign(sys.float_info.max, x)


# Lengths squared must stay below float32's 3.4e38 in the shader, and the
# culling's float64 geometry (viewer/culling.py) loses a length's 1e-16 of
# itself.  A point light or a plane further from the eye than GPU_REACH times
# the camera's distance to its target is brought to that distance: a light
# along the same direction (it has no fall-off, and seen from anything within
# 1000 camera distances its direction changes by less than 1e-9 rad), a plane
# to that height (a ray down toward a plane 1e300 below still meets it, as it
# should).  A sphere, box or cylinder that large cannot be held by float32
# near the eye and is not drawn faithfully (README, implementation limits).
# Measured: a light brought to 2^40 camera distances shadows as a directional
# one does; brought to 2^60, the culling left a piece of a shadow out (18
# pixels of 96x54 lit; tests/test_scale.py).
GPU_REACH = 2.0 ** 40


def reached_scene(scene: Scene, reach: float = GPU_REACH) -> Scene:
    """`scene` with its far point lights and planes brought within `reach`
    camera distances of the eye (see GPU_REACH); the same scene when nothing
    is that far, as in any ordinary scene."""
    reach = math.ldexp(reach, view_length_exponent(scene))
    eye = np.array(scene.camera.position, dtype=np.float64)
    out = None

    def copied() -> Scene:
        nonlocal out
        out = out or copy.deepcopy(scene)
        return out

    for j, lt in enumerate(scene.lights):
        if lt.position is None:
            continue
        v = np.array(lt.position) / 2 - eye / 2          # halves: no overflow
        m = float(np.max(np.abs(v)))
        if m > reach / 2:
            u = np.array(unit_vector(v))
            copied().lights[j].position = tuple(eye + u * reach)
    for k, o in enumerate(scene.objects):
        if o.type == "plane" and abs(o.height / 2 - eye[1] / 2) > reach / 2:
            copied().objects[k].height = float(eye[1] + math.copysign(reach, o.height / 2 - eye[1] / 2))
    return out or scene


def gpu_frame_scene(scene: Scene) -> tuple[Scene, int]:
    """The scene as the GPU gets it, and the k of its lengths' 2^k: scaled
    (scaled_scene) and then brought within reach (reached_scene).  For any
    ordinary scene, `scene` itself and 0."""
    k = gpu_length_exponent(scene)
    return reached_scene(scaled_scene(scene, k)), k


# ---------------------------------------------------------------- radiance for the GPU
#
# The image is linear in the scene's sources of light (emission, ambient,
# light colour * intensity, sky), and the exposure scales it once more.  In
# float32 a source beyond 3.4e38 (an intensity of 1e39) saturated, and every
# pixel it lit came out a third of its value; an exposure of 1e-300 on a
# light of intensity 1e300 gave 0 (and inf) for a pixel of 0.9.  So the
# sources are uploaded times 2^r (exact) and the exposure times 2^-r, with
# r = the exposure's exponent: the shader then computes in the units of
# the output, where an intermediate overflows or underflows only with the
# pixel itself.  Where the brightest source would come out above
# 2^RADIANCE_TOP, up to 2^EXPOSURE_TOP of the exposure stays in the final
# product, so that a source beyond float32 (saturated) still makes inf and
# the ordinary ones keep their values.  An ordinary scene has r = 0 (bit for
# bit the same).
RADIANCE_TOP = 120
EXPOSURE_TOP = 100


def _top_exponent(values) -> int | None:
    """frexp's exponent of the largest of `values` (>= 0); None if all are 0."""
    top = max(values, default=0.0)
    return math.frexp(top)[1] if top > 0 else None


def radiance_exponent(scene: Scene) -> int:
    """r of the sources' 2^r on the GPU (the exposure's 2^-r)."""
    sources = [c for m in scene.materials.values()
               for c in (*m.emission, *(m.checker.emission if m.checker and m.checker.emission else ()))]
    sources += [*scene.ambient, *scene.sky.color, *scene.sky.horizon, *scene.sky.zenith]
    e_max = max([_top_exponent(sources) or 0]
                + [_top_exponent(lt.color) + math.frexp(lt.intensity)[1] for lt in scene.lights
                   if lt.intensity > 0 and _top_exponent(lt.color) is not None])
    # a surface sends back up to C * k times the light it gets (a colour of
    # 1e39 lit by a light of 1: 8e38 leaves it, a tenth of it through glass)
    gains = [(_top_exponent((*m.color, *(m.checker.color if m.checker else ()))),
              _top_exponent((m.ambient, m.diffuse, m.specular))) for m in scene.materials.values()]
    e_max += max([0] + [c + k for c, k in gains if c is not None and k is not None])
    x = math.frexp(scene.render.exposure)[1]
    out = e_max + x                     # the brightest radiance's exponent in the output
    if -60 <= e_max <= 60 and -60 <= x <= 60 and out <= 60:
        return 0                        # ordinary: nothing near float32's limits
    return x - min(max(out - RADIANCE_TOP, 0), EXPOSURE_TOP)


def _radiance(values, r: int, factor: float = 1.0) -> tuple[float, ...]:
    """values * factor * 2^r in float64, without overflow in between (at
    +-float64's largest where the result itself is beyond it)."""
    out = []
    for v in values:
        if v == 0 or factor == 0:
            out.append(0.0)
            continue
        (mv, ev), (mf, ef) = math.frexp(v), math.frexp(factor)
        out.append(_ldexp(mv * mf, ev + ef + r))
    return tuple(out)


def colour_balance(m) -> int:
    """a of a material's colours uploaded times 2^-a and its ambient,
    diffuse and specular times 2^a: the shader only uses their products
    (C * k), so a colour of 1e39 (about 1 on the GPU, the k times 2^130)
    or a diffuse of 1e39 keeps its pixels of 8e37 instead of saturating
    to a third of them.  The colour to about 1 where the largest k stays
    within 2^120 and the smallest colour channel above 2^-100; 0 (bit for
    bit the same) for any ordinary material.  (The k's limit was 2^100, and
    the sources' top 2^100 too: a specular of 1e48 beside a diffuse of 1
    then left the diffuse and ambient terms at 2^-121, flushed to 0; with
    120 both, specular to about 1e50 keeps them.)"""
    colours = (*m.color, *(m.checker.color if m.checker else ()))
    ec = _top_exponent(colours)
    ek = _top_exponent((m.ambient, m.diffuse, m.specular))
    if ec is None or ek is None or (-60 <= ec <= 60 and -60 <= ek <= 60):
        return 0
    ec_min = math.frexp(min(c for c in colours if c > 0))[1]
    return min(ec, 120 - ek, ec_min + 100)


def _saturate(a: np.ndarray) -> np.ndarray:
    """Float fields that overflowed float32 (validation admits only finite
    numbers, so an inf here is a value beyond 3.4e38) at +-F32_MAX instead:
    inf would turn into NaN where it meets a 0 (inf * 0, inf - inf)."""
    for name in a.dtype.names:
        f = a[name]
        if f.dtype.kind == "f":
            np.clip(f, -F32_MAX, F32_MAX, out=f)
    return a


def scene_scale(scene: Scene) -> float:
    """A length for the scene: bounded objects' extent and the camera distance."""
    return max(_extent(scene), 1e-30)


def _extent(scene: Scene) -> float:
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


@dataclass
class PackedScene:
    block: bytes
    defines: dict[str, object]
    eye: np.ndarray  # world position of the eye (float64)


# The compile-time shape of an object (shaders/lib/intersect.glsl): its type,
# and SHAPE_VESSEL for a cylinder with a wall.
SHAPE_VESSEL = 4


def object_shape(obj: SceneObject) -> int:
    return SHAPE_VESSEL if obj.type == "cylinder" and obj.wall else OBJ_TYPES[obj.type]


def object_list_macros(scene: Scene, subset: tuple[int, ...] | None = None) -> dict[str, str]:
    """The scene's objects as X-macros for the specialised shader (see
    FOR_EACH_OBJECT in trace.frag): SCENE_OBJECTS(X) lists X(k, shape, slot)
    per object (slot: transparent slot, -1 opaque), SCENE_MEDIA(X) lists
    X(slot, k, shape) per transparent object.  Only the structure (shapes,
    order, which objects are transparent) goes in: every value stays in the
    uniform block, so editing one never recompiles.  `subset`: only these
    object indices are listed (viewer/culling.py); slots keep their numbers."""
    objects, media = [], []
    slot_of = 0
    for k, o in enumerate(scene.objects):
        shape = object_shape(o)
        slot = slot_of if scene.is_transparent(o) else -1
        slot_of += slot >= 0
        if subset is not None and k not in subset:
            continue
        if slot >= 0:
            media.append(f"X({slot},{k},{shape})")
        objects.append(f"X({k},{shape},{slot})")
    return {"SCENE_OBJECTS(X)": " ".join(objects), "SCENE_MEDIA(X)": " ".join(media)}


#: The most lights or materials the specialised shader reads by literal
#: index and select (trace.frag, pickLight / pickMaterial) rather than
#: through a per-lane index: a select per component and entry against a
#: gather of about 17 instructions a component.
PICK_MAX = 8


def index_list_macros(scene: Scene) -> dict[str, str]:
    """SCENE_LIGHT_INDICES(X) and SCENE_MATERIAL_INDICES(X): X(1) .. X(n - 1)
    for the scene's n lights and n materials where 1 <= n <= PICK_MAX (with
    one, an empty list: index 0 is read anyway).  None for 0 or for more
    than PICK_MAX (the shader gathers).  The counts are compile-time
    constants already (the block's array lengths), so these add no
    recompiles."""
    out = {}
    for name, n in (("SCENE_LIGHT_INDICES(X)", len(scene.lights)),
                    ("SCENE_MATERIAL_INDICES(X)", len(scene.materials))):
        if 1 <= n <= PICK_MAX:
            out[name] = " ".join(f"X({q})" for q in range(1, n))
    return out


def driver_defines(renderer: str, version: str) -> dict[str, object]:
    """What a driver changes in every program (GL_RENDERER, GL_VERSION).
    llvmpipe before Mesa 25 keeps the per-lane gather of a hit's material:
    there the literal-index selects made the default frame 25% slower
    (22.3.6: 330 -> 405 ms), where 25.0.7 is 3% faster with them.  (A
    value None drops the define: shaders.load_source skips it.)"""
    m = re.search(r"\bMesa (\d+)\.", version)
    if "llvmpipe" in renderer and m and int(m.group(1)) < 25:
        return {"SCENE_MATERIAL_INDICES(X)": None}
    return {}


def max_passes(scene: Scene) -> int:
    """MAX_PASSES of trace.frag: the most groups of transparent surfaces a
    ray or shadow ray can cross before its interaction (a line crosses at
    most 1 surface of a plane, 2 of a sphere, box or cylinder, 4 of a
    vessel), plus the pass that finds the interaction or the sky, plus one;
    never fewer than the 2 * objects + 2 the shader had before."""
    per = {"plane": 1, "sphere": 2, "box": 2, "cylinder": 2}
    crossings = sum(4 if o.type == "cylinder" and o.wall else per[o.type]
                    for o in scene.objects if scene.is_transparent(o))
    return max(crossings, 2 * len(scene.objects)) + 2


#: Sizes of the ray-tree stack a program is compiled with: the smallest that
#: holds max_depth + 1 entries.  Max depth itself is a uniform (iparams.x),
#: so a new depth within a size (1..8, 9..16, 17..32, 33..64) compiles
#: nothing: the panel's slider and --max-error's candidates reuse the
#: program.  The default depth 8 gets 9, exactly what it needs.
STACK_SIZES = (9, 17, 33, 65)


def stack_size(max_depth: int) -> int:
    """Entries of the ray-tree stack for trees of max_depth (trace.frag:
    max_depth + 1 suffice)."""
    need = max_depth + 1
    return next((n for n in STACK_SIZES if n >= need), need)


def shader_defines(scene: Scene, specialise: bool = True, fresnel: str = "exact",
                   subset: tuple[int, ...] | None = None) -> dict[str, object]:
    """Compile-time constants of the shader for this scene: counts, the
    features present and the object list (specialise=True), or the generic
    all-features shader.  `subset` (object indices): a shader for the part
    of the image that can meet only those objects (viewer/culling.py): the
    features are theirs, the counts and the block stay the scene's."""
    extra: dict[str, object] = {"FRESNEL_SCHLICK": True} if fresnel == "schlick" else {}
    if not specialise:
        return {"GENERIC": True, **GENERIC_LENS, "STACK_SIZE": GENERIC_STACK, "HAS_LIGHTS": True,
                "HAS_PLANE": True, "HAS_SPHERE": True, "HAS_BOX": True, "HAS_CYLINDER": True,
                "HAS_DIELECTRIC": True, "HAS_REFLECTION": True, "HAS_SKY_IMAGE": True, **extra}
    n_obj = len(scene.objects)
    n_tr = sum(scene.is_transparent(o) for o in scene.objects)
    present = [o for k, o in enumerate(scene.objects) if subset is None or k in subset]
    used = [scene.materials[o.material] for o in present]
    d: dict[str, object] = {
        "NUM_OBJECTS": n_obj, "OBJECTS_LEN": max(1, n_obj),
        "MATERIALS_LEN": max(1, len(scene.materials)),
        "NUM_LIGHTS": len(scene.lights), "LIGHTS_LEN": max(1, len(scene.lights)),
        "NUM_TRANSPARENT": n_tr, "MEDIA_LEN": max(1, n_tr),
        "MAX_PASSES": max_passes(scene),
        **object_list_macros(scene, subset),
        **index_list_macros(scene),
        **extra,
    }

    if scene.lights:
        d["HAS_LIGHTS"] = True
    for t in OBJ_TYPES:
        if any(o.type == t for o in present):
            d[f"HAS_{t.upper()}"] = True
    if any(scene.is_transparent(o) for o in present):
        d["HAS_DIELECTRIC"] = True
        # only the dielectric tree has a stack (trace.frag): without glass
        # the depth compiles nothing at all
        d["STACK_SIZE"] = stack_size(scene.render.max_depth)
    if any(m.reflectivity > 0 for m in used):
        d["HAS_REFLECTION"] = True
    if scene.sky.type == "image":
        d["HAS_SKY_IMAGE"] = True
    return d


def pack_scene(scene: Scene, specialise: bool = True, fresnel: str = "exact") -> PackedScene:
    """The uniform block's bytes and the shader defines.  The generic shader
    (specialise=False) takes the same data in arrays of fixed length."""
    with np.errstate(over="ignore"):        # values beyond float32 saturate (_saturate)
        return _pack_scene(scene, specialise, fresnel)


def _pack_scene(scene: Scene, specialise: bool, fresnel: str) -> PackedScene:
    if not specialise and (len(scene.objects) > GENERIC_LENS["OBJECTS_LEN"]
                           or len(scene.materials) > GENERIC_LENS["MATERIALS_LEN"]
                           or len(scene.lights) > GENERIC_LENS["LIGHTS_LEN"]):
        raise ValueError("scene too large for the generic shader")
    eye = np.array(scene.camera.position, dtype=np.float64)
    mat_index = {name: i for i, name in enumerate(scene.materials)}

    objs = np.zeros(max(1, len(scene.objects)), OBJECT_DTYPE)
    media = np.zeros(max(1, len(scene.objects)), MEDIUM_DTYPE)
    slot = 0
    initial_mask = 0
    for k, o in enumerate(scene.objects):
        rec = objs[k]
        tr = scene.is_transparent(o)
        rec["info"] = (OBJ_TYPES[o.type], mat_index[o.material], AXES.get(o.axis, 1), slot if tr else -1)
        rec["bound"] = bounding_sphere(o, eye)
        if o.type == "plane":
            rec["a"][0] = o.height - eye[1]
        elif o.type == "sphere":
            rec["a"] = (*(np.array(o.center) - eye), o.radius)
        elif o.type == "box":
            c = (np.array(o.min) + np.array(o.max)) / 2
            rec["a"][:3] = c - eye
            rec["b"][:3] = (np.array(o.max) - np.array(o.min)) / 2
            local_from_world = rotation_world_from_local(o.rotate).T
            rec["c"][:3], rec["d"][:3], rec["e"][:3] = local_from_world
        else:
            rec["a"] = (*(np.array(o.base) - eye), o.radius)
            rec["b"][:2] = (o.height, o.wall or 0.0)
        if tr:
            m = scene.materials[o.material]
            media[slot]["index"] = (k, mat_index[o.material], 0, 0)
            media[slot]["optics"] = (m.ior, m.transparency, 0.0, 0.0)      # as the material's, below
            media[slot]["absorption"][:3] = m.absorption
            if contains_point(o, eye):
                initial_mask |= 1 << slot
            slot += 1

    rad = radiance_exponent(scene)
    mats = np.zeros(max(1, len(scene.materials)), MATERIAL_DTYPE)
    for i, m in enumerate(scene.materials.values()):
        rec = mats[i]
        a = colour_balance(m)
        rec["colorAmbient"] = (*_radiance(m.color, -a), _ldexp(m.ambient, a))
        rec["phong"] = (_ldexp(m.diffuse, a), _ldexp(m.specular, a), m.shininess, m.reflectivity)
        rec["absorption"][:3] = m.absorption
        rec["emission"][:3] = _radiance(m.emission, rad)
        if m.checker is not None:
            s = m.checker.size
            rec["dielectric"] = (m.transparency, m.ior, 1.0, s)
            rec["checkerColor"][:3] = _radiance(m.checker.color, -a)
            rec["checkerEmission"][:3] = _radiance(m.checker.emission if m.checker.emission is not None
                                                   else m.emission, rad)
            rec["checkerOffset"][:2] = (math.fmod(eye[0], 2 * s), math.fmod(eye[2], 2 * s))
        else:
            rec["dielectric"] = (m.transparency, m.ior, 0.0, 1.0)

    lights = np.zeros(max(1, len(scene.lights)), LIGHT_DTYPE)
    for j, lt in enumerate(scene.lights):
        if lt.type == "point":
            lights[j]["vector"] = (*(np.array(lt.position) - eye), 0.0)
        else:
            lights[j]["vector"] = (*unit_vector(lt.direction), 1.0)
        lights[j]["radiance"][:3] = _radiance(lt.color, rad, lt.intensity)

    tail = np.zeros(1, TAIL_DTYPE)
    tail["ambient"][0, :3] = _radiance(scene.ambient, rad)
    tail["skyColor"][0, :3] = _radiance(scene.sky.color, rad)
    tail["skyHorizon"][0, :3] = _radiance(scene.sky.horizon, rad)
    tail["skyZenith"][0, :3] = _radiance(scene.sky.zenith, rad)
    r = scene.render
    tail["params"][0] = (EPS_SCENE * scene_scale(scene), EPS_REL, r.min_weight, _ldexp(r.exposure, -rad))
    # the mask travels as the bits of a signed int (uint(...) in GLSL restores them)
    tail["iparams"][0] = (r.max_depth, np.int32(np.uint32(initial_mask).view(np.int32)),
                          SKY_TYPES[scene.sky.type], 0)

    n_tr = slot
    tail["counts"][0] = (len(scene.objects), len(scene.lights), n_tr, 0)
    media = media[: max(1, n_tr)]
    if not specialise:
        def pad(a: np.ndarray, n: int) -> np.ndarray:
            out = np.zeros(n, a.dtype)
            out[: len(a)] = a
            return out
        objs, mats = pad(objs, GENERIC_LENS["OBJECTS_LEN"]), pad(mats, GENERIC_LENS["MATERIALS_LEN"])
        lights, media = pad(lights, GENERIC_LENS["LIGHTS_LEN"]), pad(media, GENERIC_LENS["MEDIA_LEN"])
    block = b"".join(_saturate(a).tobytes() for a in (objs, mats, lights, media, tail))
    return PackedScene(block=block, defines=shader_defines(scene, specialise, fresnel), eye=eye)


def camera_uniforms(scene: Scene, width: int, height: int) -> dict[str, tuple[float, ...]]:
    """f, right * t * W/H and up * t of the spec's pinhole model (float64 math)."""
    c = scene.camera
    f = np.array(c.target, dtype=np.float64) - np.array(c.position, dtype=np.float64)
    n = np.linalg.norm(f)
    if 0 < n < math.inf:
        f /= n
    else:                  # a camera beyond float64's squares (the renderer's scenes never are)
        s = max(abs(v) for v in (*c.target, *c.position))
        f = np.array(unit_vector([t / s - p / s for t, p in zip(c.target, c.position)]))
    right = np.cross(f, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, f)
    t = math.tan(math.radians(c.fov) / 2)
    return {"camForward": tuple(f), "camRight": tuple(right * t * width / height), "camUp": tuple(up * t)}
