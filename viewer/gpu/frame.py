"""The scene in the GPU's frame: lengths and radiances by powers of two.

The shader computes in float32; a valid scene may be in any unit and any
brightness.  gpu_frame_scene scales every length by one power of two (exact
in binary floating point) so that the camera's distance to its target is
about 1, and brings far lights and planes within reach of the eye;
radiance_exponent does the same for the light sources.  Inside the ranges
below nothing changes, bit for bit, and the picture is that of the scene as
written.
"""

from __future__ import annotations

import copy
import math
import sys

import numpy as np

from ..scene.model import Scene
from ..scene.load import unit_vector
from .geometry import scene_extent


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
    ext = scene_extent(scene)
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
        return tuple(ldexp_saturating(float(c), k) for c in v)

    out = copy.deepcopy(scene)
    out.camera.position, out.camera.target = vec(out.camera.position), vec(out.camera.target)
    for lt in out.lights:
        if lt.position is not None:
            lt.position = vec(lt.position)
    for m in out.materials.values():
        m.absorption = tuple(ldexp_saturating(float(c), -k) for c in m.absorption)
        if m.checker is not None:
            m.checker.size = ldexp_saturating(m.checker.size, k)
    for o in out.objects:
        o.height, o.radius = ldexp_saturating(o.height, k), ldexp_saturating(o.radius, k)
        o.center, o.min, o.max, o.base = vec(o.center), vec(o.min), vec(o.max), vec(o.base)
        if o.wall is not None:
            o.wall = ldexp_saturating(o.wall, k)
    return out


def ldexp_saturating(x: float, k: int) -> float:
    """x * 2^k, at +-float64's largest where that overflows (a far light or
    plane the scaling takes past it: reached_scene brings it back)."""
    try:
        return math.ldexp(x, k)
    except OverflowError:
        return math.copysign(sys.float_info.max, x)


# Lengths squared must stay below float32's 3.4e38 in the shader, and the
# culling's float64 geometry (viewer/gpu/culling.py) loses a length's 1e-16 of
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


def scaled_radiance(values, r: int, factor: float = 1.0) -> tuple[float, ...]:
    """values * factor * 2^r in float64, without overflow in between (at
    +-float64's largest where the result itself is beyond it)."""
    out = []
    for v in values:
        if v == 0 or factor == 0:
            out.append(0.0)
            continue
        (mv, ev), (mf, ef) = math.frexp(v), math.frexp(factor)
        out.append(ldexp_saturating(mv * mf, ev + ef + r))
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
