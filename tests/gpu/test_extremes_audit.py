"""Extremes audit: valid scenes with numbers at the edges of float32 and
float64 (colours, intensities and exposures beyond 3.4e38 or below 1e-38,
checker squares of 1e300, a camera 5e-324 from its target, lights 1e20 to
1e300 away or pointing along [1e300, -1e300, 0]).  Each is checked against
values computed by hand from shared/spec/scene-format.md, on the GPU and
in the float64 reference (viewer/reference/trace.py).  Where the spec's value is
beyond float32, the float32 output holds inf (what float32 makes of it)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import make_scene
from viewer.reference import trace as reference
from viewer.gpu.renderer import Renderer

F32_MAX = float(np.finfo(np.float32).max)
W, H = 24, 14


def _gpu(gl, scene, w=W, h=H, samples=1):
    r = Renderer(gl, scene)
    try:
        return r.render(w, h, samples, 0).astype(np.float64)
    finally:
        r.release()


def _as_f32(x: np.ndarray) -> np.ndarray:
    """What float32 makes of float64 values: inf beyond 3.4e38."""
    with np.errstate(over="ignore"):
        return np.asarray(x, np.float64).astype(np.float32).astype(np.float64)


def _lit_floor(color=(0.5, 0.5, 0.5), diffuse=0.8, light=None, exposure=1.0, ambient=0.0) -> dict:
    """A camera looking down at a diffuse floor that fills the picture, one
    directional light along [0, -1, -1]: every pixel is
    exposure * C * (k_a A + k_d (n.l) L) with n.l = 1/sqrt(2)."""
    return {"camera": {"position": [0, 3, 0.5], "target": [0, 0, 0], "fov": 30},
            "render": {"exposure": exposure},
            "ambient": [0.05, 0.05, 0.05],
            "lights": [dict({"type": "directional", "direction": [0, -1, -1]}, **(light or {}))],
            "materials": {"floor": {"color": list(color), "ambient": ambient, "diffuse": diffuse}},
            "objects": [{"type": "plane", "material": "floor"}]}


def _floor_value(color, diffuse, radiance, exposure=1.0, ambient=0.0):
    c, L = np.array(color, np.float64), np.array(radiance, np.float64)
    return exposure * c * (ambient * 0.05 + diffuse * L / math.sqrt(2))


# --------------------------------------------------------------------------- radiance beyond float32


@pytest.mark.parametrize("case", [
    # intensity beyond float32: 0.5 * 0.8 * 1e39 / sqrt(2) = 2.8e38 fits in
    # float32 (it came out 9.6e37, a third of it: the intensity saturated)
    dict(light={"intensity": 1e39}),
    # one channel beyond float32 (inf), one in it, one zero (0, not NaN)
    dict(light={"intensity": 2e39, "color": [1, 0.1, 0]}),
    # exposure 1e-300 of a light of 1e300: 0.28 (it came out 0)
    dict(light={"intensity": 1e300}, exposure=1e-300),
    # exposure 1e39 of an ordinary light: 1.4e38 fits (it came out 9.6e37)
    dict(exposure=5e38, diffuse=0.1),
    # a colour of 1e39 and a diffuse of 0.2: 1.4e38 fits (it came out 4.8e37)
    dict(color=(1e39, 1e-3, 0.0), diffuse=0.2),
    # a diffuse of 1e39 and a small colour, ambient term kept beside it
    dict(color=(0.1, 1e-3, 0.5), diffuse=1e39, ambient=0.1),
])
def test_radiance_beyond_float32_follows_the_spec(gl, case):
    light = {"color": [1, 1, 1], "intensity": 1.0, **case.get("light", {})}
    want = _floor_value(case.get("color", (0.5, 0.5, 0.5)), case.get("diffuse", 0.8),
                        np.array(light["color"], np.float64) * light["intensity"],
                        case.get("exposure", 1.0), case.get("ambient", 0.0))
    scene = make_scene(_lit_floor(**case))
    img = _gpu(gl, scene)
    assert not np.isnan(img).any()
    want32 = _as_f32(want)
    assert (np.isinf(img) == np.isinf(want32)[None, None, :]).all()
    fin = np.isfinite(want32)
    np.testing.assert_allclose(img[..., fin], np.broadcast_to(want[fin], img[..., fin].shape), rtol=1e-5)
    # the float64 reference: the spec's value itself
    ref = reference.render_reference(scene, 8, 5, samples=1)
    np.testing.assert_allclose(ref, np.broadcast_to(want, ref.shape), rtol=1e-12)


def test_a_source_beyond_float32_leaves_the_ordinary_pixels_as_they_are(gl):
    # Sky 1e300 and an emitter of 1e39 beside a floor lit by a light of 1:
    # the sky and the emitter are inf in float32, the floor keeps its value.
    doc = {"camera": {"position": [0, 1, 4], "target": [0, 0.6, 0], "fov": 50},
           "sky": {"type": "color", "color": [1e300, 1e300, 1e300]},
           "ambient": [0, 0, 0],
           "lights": [{"type": "directional", "direction": [0, -1, -1]}],
           "materials": {"floor": {"color": [0.5, 0.5, 0.5], "ambient": 0, "diffuse": 0.8},
                         "lamp": {"color": [0, 0, 0], "emission": [1e39, 1e39, 1e39]}},
           "objects": [{"type": "plane", "material": "floor"},
                       {"type": "sphere", "center": [0, 0.6, 0], "radius": 0.4, "material": "lamp"}]}
    scene = make_scene(doc)
    img = _gpu(gl, scene)
    ref = _as_f32(reference.render_reference(scene, W, H, samples=1))
    assert not np.isnan(img).any()
    assert (np.isinf(img) == np.isinf(ref)).all()
    floor = np.isfinite(ref).all(axis=2) & (ref.max(axis=2) > 0)
    assert floor.sum() > W * H // 4
    # the floor away from the lamp's shadow: 0.5 * 0.8 / sqrt(2)
    np.testing.assert_allclose(img[floor], ref[floor], rtol=1e-4)
    assert np.isclose(img[-1, 0, 0], 0.4 / math.sqrt(2), rtol=1e-5)


# --------------------------------------------------------------------------- checker squares beyond float32


@pytest.mark.parametrize("size", [1e39, 1e300])
def test_checker_squares_beyond_float32_keep_the_negative_side(gl, size):
    # floor(x / size) is -1 for every x < 0, 0 for 0 <= x < size: four
    # quadrants around the origin, odd (checker colour) where exactly one
    # of x, z is negative.  The quotient flushed to -0 on the GPU, floor 0:
    # the negative side took the positive side's colour.
    doc = {"camera": {"position": [0.3, 4, 0.2], "target": [0.3, 0, 0.1], "fov": 40},
           "ambient": [1, 1, 1],
           "materials": {"floor": {"color": [0.8, 0.8, 0.8], "ambient": 1, "diffuse": 0,
                                   "checker": {"color": [0.2, 0.2, 0.2], "size": size}}},
           "objects": [{"type": "plane", "material": "floor"}]}
    scene = make_scene(doc)
    o, d = reference.camera_rays(scene, W, H)
    p = o + (-o[..., 1:2] / d[..., 1:2]) * d                   # on y = 0
    odd = (p[..., 0] < 0) != (p[..., 2] < 0)
    want = np.where(odd, 0.2, 0.8)
    assert odd.any() and (~odd).any()
    img = _gpu(gl, scene)
    np.testing.assert_allclose(img[..., 0], want, atol=1e-6)
    ref = reference.render_reference(scene, W, H, samples=1)
    np.testing.assert_allclose(ref[..., 0], want, atol=1e-12)
    # footprint samples (more than one sample on a checkered plane) take the
    # same cells: away from the lines x = 0 and z = 0 the pixels are pure
    far = (np.abs(p[..., 0]) > 0.2) & (np.abs(p[..., 2]) > 0.2)
    aa = _gpu(gl, scene, samples=4)
    np.testing.assert_allclose(aa[..., 0][far], want[far], atol=1e-5)


# --------------------------------------------------------------------------- the camera


def test_a_camera_a_hair_from_its_target_sees_what_its_direction_shows(gl):
    # The picture depends on the eye and the view direction only.  A target
    # 5e-324 from the eye scaled the scene by 2^1075 for the GPU:
    # OverflowError (glassray render: exit 1).
    def doc(target):
        return {"camera": {"position": [0.0, 0.5, 0.0], "target": target, "fov": 60},
                "lights": [{"position": [3, 5, 3]}],
                "materials": {"m": {"color": [0.8, 0.2, 0.2], "specular": 0.3}},
                "objects": [{"type": "plane", "material": "m", "height": -0.5},
                            {"type": "sphere", "center": [-1.2, 0.6, -1.2], "radius": 0.6, "material": "m"}]}
    near = make_scene(doc([-5e-324, 0.5, -5e-324]))
    unit = make_scene(doc([-1.0, 0.5, -1.0]))
    a, b = _gpu(gl, near), _gpu(gl, unit)
    assert np.isfinite(a).all()
    assert np.abs(a - b).max() < 1e-5
    # the reference normalised target - position as it was: 0 / 0
    ra = reference.render_reference(near, W, H, samples=1)
    rb = reference.render_reference(unit, W, H, samples=1)
    assert np.isfinite(ra).all()
    assert np.abs(ra - rb).max() < 1e-9


# --------------------------------------------------------------------------- the reference


@pytest.mark.parametrize("direction", [[0, -1e300, -1e300], [0, -1.5e308, -1.5e308], [0, -5e-324, -5e-324],
                                       [1e-320, -1e-300, -1e-300]])
def test_reference_normalises_any_light_direction(direction):
    # the spec only asks for a non-zero direction; |d| overflowed or
    # underflowed in the reference (unlit floor, or NaN)
    scene = make_scene(_lit_floor(light={"direction": direction}))
    ref = reference.render_reference(scene, 8, 5, samples=1)
    np.testing.assert_allclose(ref, np.broadcast_to(_floor_value((0.5,) * 3, 0.8, (1, 1, 1)), ref.shape),
                               rtol=1e-9)


@pytest.mark.parametrize("far", [1e20, 1e300, 1.7e308])
def test_reference_point_light_far_away_is_the_directional_light(far):
    # no fall-off: from 1e20 on, a point light only has a direction.  The
    # reference took the light's distance for the scene's size: offsets of
    # 1e14 and every ray passed through the floor (sky everywhere).
    doc = _lit_floor(light={"type": "point", "position": [0, far, far]})
    del doc["lights"][0]["direction"]
    ref = reference.render_reference(make_scene(doc), 8, 5, samples=1)
    np.testing.assert_allclose(ref, np.broadcast_to(_floor_value((0.5,) * 3, 0.8, (1, 1, 1)), ref.shape),
                               rtol=1e-9)


def test_reference_light_beyond_float64_gives_inf_where_lit_and_0_in_shadow():
    # colour 1e200 * intensity 1e200 is beyond float64: inf where the light
    # reaches, and in the ball's shadow 0 (C * L * V with V = 0), not NaN
    doc = _lit_floor(light={"intensity": 1e200, "color": [1e200, 0, 0]})
    doc["materials"]["ball"] = {"color": [0, 0, 0], "ambient": 0, "diffuse": 0}
    doc["objects"].append({"type": "sphere", "center": [0, 0.5, 0.5], "radius": 0.45, "material": "ball"})
    ref = reference.render_reference(make_scene(doc), W, H, samples=1)
    assert not np.isnan(ref).any()
    assert np.isinf(ref[..., 0]).any() and (ref[..., 0] == 0).any()


def test_a_surface_brighter_than_float32_seen_through_an_absorbing_slab(gl):
    # The floor sends back C k_a A = 1e39 (beyond float32), a clear slab of
    # ior 1 (no refraction, R = 0) and absorption 2 over it lets
    # exp(-2 / |d.y|) of it through: about 1e38, which float32 holds.  The
    # shader had the floor's radiance at inf before the slab's factor.
    doc = {"camera": {"position": [0, 3, 0.3], "target": [0, 0, 0], "fov": 30},
           "ambient": [1, 1, 1],
           "materials": {"floor": {"color": [1e39, 1e39, 1e39], "ambient": 1, "diffuse": 0},
                         "slab": {"color": [0, 0, 0], "ambient": 0, "diffuse": 0, "transparency": 1,
                                  "absorption": [2, 2, 2]}},
           "objects": [{"type": "plane", "material": "floor"},
                       {"type": "box", "min": [-50, 0.5, -50], "max": [50, 1.5, 50], "material": "slab"}]}
    scene = make_scene(doc)
    _, d = reference.camera_rays(scene, W, H)
    want = 1e39 * np.exp(-2.0 / np.abs(d[..., 1]))
    assert (want < F32_MAX).all()
    img = _gpu(gl, scene)
    np.testing.assert_allclose(img, np.repeat(want[..., None], 3, axis=2), rtol=1e-4)
    ref = reference.render_reference(scene, W, H, samples=1)
    np.testing.assert_allclose(ref, np.repeat(want[..., None], 3, axis=2), rtol=1e-9)


@pytest.mark.parametrize("exposure, want", [(1e39, 2.5e38), (1e300, math.inf), (1e-30, 2.5e-31)])
def test_a_sky_picture_takes_any_exposure(gl, tmp_path, exposure, want):
    # a uniform PFM sky of 0.25: every pixel 0.25 * exposure (inf beyond float32)
    from viewer.base.imageio import encode_pfm

    (tmp_path / "sky.pfm").write_bytes(encode_pfm(np.full((4, 8, 3), 0.25, np.float32)))
    scene = make_scene({"camera": {"position": [0, 0, 0], "target": [0, 1, -1]},
                        "render": {"exposure": exposure},
                        "sky": {"type": "image", "image": str(tmp_path / "sky.pfm")}})
    img = _gpu(gl, scene, 8, 5)
    np.testing.assert_allclose(img, want, rtol=1e-6)
    np.testing.assert_allclose(reference.render_reference(scene, 8, 5, samples=1), 0.25 * exposure, rtol=1e-9)


@pytest.mark.parametrize("height", [0.0, 1e-300, 1e-6])
def test_a_point_light_on_the_floor_is_not_shadowed_by_it(gl, height):
    # The segment from a point above the floor to a light on it (or 1e-300
    # above it) only touches the floor at the light: nothing in between, so
    # a ball beside the light is lit, n.l as the spec has it.  The shadow
    # ray ran into the floor at the light (salt and pepper on the ball),
    # and from its start offset along the normal it passed under the light
    # and met the floor before it (a dark band on the ball's lower half).
    doc = {"camera": {"position": [0, 1.5, 5], "target": [-1, 0.5, 0], "fov": 30},
           "ambient": [0, 0, 0],
           "lights": [{"position": [0, height, 0]}],
           "materials": {"floor": {"color": [0.2, 0.2, 0.2], "ambient": 0, "diffuse": 0},
                         "ball": {"color": [1, 1, 1], "ambient": 0, "diffuse": 1}},
           "objects": [{"type": "plane", "material": "floor"},
                       {"type": "sphere", "center": [-1.2, 0.6, 0], "radius": 0.6, "material": "ball"}]}
    scene = make_scene(doc)
    w, h = 32, 18
    o, d = reference.camera_rays(scene, w, h)
    t, obj, n = reference.first_hit(scene, o.reshape(-1, 3), d.reshape(-1, 3))
    ball = (obj == 1).reshape(h, w)
    p = (o + t.reshape(h, w, 1) * d)[ball]
    to = np.array([0, height, 0]) - p
    want = np.maximum(np.einsum("ij,ij->i", n[ball.reshape(-1)], to / np.linalg.norm(to, axis=1, keepdims=True)), 0)
    img = _gpu(gl, scene, w, h)
    np.testing.assert_allclose(img[ball][:, 0], want, atol=2e-4)
    ref = reference.render_reference(scene, w, h, samples=1)
    np.testing.assert_allclose(ref[ball][:, 0], want, atol=1e-9)


@pytest.mark.parametrize("specular", [1e40, 1e48])
def test_a_huge_specular_keeps_the_same_material_s_dim_diffuse_and_ambient(gl, specular):
    """The fuzz audit: a sphere of specular 1e48 (and diffuse 1, ambient
    0.1) came out black in 111 of 2304 pixels where the float64 reference
    has 0.001-0.3: the colour balance (k to 2^100 at most) and the sources'
    scale (the brightest output to 2^100) left its ambient and dim diffuse
    at 2^-121, under float32's normals.  Every pixel the reference has finite
    and at least 1e-3 is within 1e-3 (relative) of it, but for one at most
    (float32's pow() of a highlight's far tail underflows before the 1e48
    multiplies it)."""
    scene = make_scene({
        "camera": {"position": [0, 2, 6], "target": [0, 1, 0]},
        "lights": [{"position": [2, 5, 3]}],
        "materials": {"red": {"color": [0.8, 0.2, 0.1], "specular": specular},
                      "floor": {"color": [0.7, 0.7, 0.7]}},
        "objects": [{"type": "sphere", "center": [0, 1, 0], "radius": 1, "material": "red"},
                    {"type": "plane", "material": "floor"}]}, "huge specular")
    got = _gpu(gl, scene, 64, 36).astype(np.float64)
    want = reference.render_reference(scene, 64, 36, samples=1)
    seen = np.isfinite(want).all(-1) & (want.max(-1) >= 1e-3) & (want.max(-1) < 3e38)
    assert seen.sum() > 1500
    rel = (np.abs(got - want) / np.maximum(want, 1e-6)).max(-1)
    assert int((rel[seen] > 1e-3).sum()) <= 1, np.argwhere(seen & (rel > 1e-3))[:5]
    # beyond float32 where the reference is (well beyond: not the rounding's
    # edge): inf, never NaN
    assert not np.isnan(got).any()
    far = want > 1e39
    assert far.any() and np.isinf(got[far]).all()
