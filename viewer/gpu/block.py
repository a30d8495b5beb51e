"""The uniform block: numpy structured dtypes that mirror the GLSL structs of
shaders/lib/scene_block.glsl member for member (all vec4 / ivec4 sized, so
std140 adds no padding; tests/gpu/test_uniform_block.py checks every field's
name, type and offset against the GLSL and the driver), the packing of a
scene into them, and the camera uniforms.

Everything is camera-relative: positions have the eye subtracted in float64
here, so a scene far from the world origin keeps float32 precision where it
matters (near the eye).  The checker's world anchoring is kept by passing the
eye's (x, z) modulo 2 * size (the period of the parity).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..scene.model import Scene
from ..scene.load import unit_vector
from .defines import GENERIC_LENS, OBJ_TYPES, shader_defines
from .frame import F32_MAX, colour_balance, ldexp_saturating, radiance_exponent, scaled_radiance
from .geometry import AXES, bounding_sphere, contains_point, rotation_world_from_local, scene_scale


SKY_TYPES = {"color": 0, "gradient": 1, "image": 2}


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


assert OBJECT_DTYPE.itemsize == 112 and MATERIAL_DTYPE.itemsize == 128 and LIGHT_DTYPE.itemsize == 32


# Offsets for leaving a surface (see surfaceEps in shaders/lib/shade.glsl).
EPS_REL = 2e-6        # of the hit point's magnitude (camera-relative); ~16 float32 ulps


EPS_SCENE = 1e-6      # of the scene's size


def _saturate(a: np.ndarray) -> np.ndarray:
    """Float fields that overflowed float32 (validation admits only finite
    numbers, so an inf here is a value beyond 3.4e38) at +-F32_MAX instead:
    inf would turn into NaN where it meets a 0 (inf * 0, inf - inf)."""
    for name in a.dtype.names:
        f = a[name]
        if f.dtype.kind == "f":
            np.clip(f, -F32_MAX, F32_MAX, out=f)
    return a


@dataclass
class PackedScene:
    block: bytes
    defines: dict[str, object]
    eye: np.ndarray  # world position of the eye (float64)


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
        rec["colorAmbient"] = (*scaled_radiance(m.color, -a), ldexp_saturating(m.ambient, a))
        rec["phong"] = (ldexp_saturating(m.diffuse, a), ldexp_saturating(m.specular, a), m.shininess, m.reflectivity)
        rec["absorption"][:3] = m.absorption
        rec["emission"][:3] = scaled_radiance(m.emission, rad)
        if m.checker is not None:
            s = m.checker.size
            rec["dielectric"] = (m.transparency, m.ior, 1.0, s)
            rec["checkerColor"][:3] = scaled_radiance(m.checker.color, -a)
            rec["checkerEmission"][:3] = scaled_radiance(m.checker.emission if m.checker.emission is not None
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
        lights[j]["radiance"][:3] = scaled_radiance(lt.color, rad, lt.intensity)

    tail = np.zeros(1, TAIL_DTYPE)
    tail["ambient"][0, :3] = scaled_radiance(scene.ambient, rad)
    tail["skyColor"][0, :3] = scaled_radiance(scene.sky.color, rad)
    tail["skyHorizon"][0, :3] = scaled_radiance(scene.sky.horizon, rad)
    tail["skyZenith"][0, :3] = scaled_radiance(scene.sky.zenith, rad)
    r = scene.render
    tail["params"][0] = (EPS_SCENE * scene_scale(scene), EPS_REL, r.min_weight, ldexp_saturating(r.exposure, -rad))
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
