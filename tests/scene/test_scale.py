"""Scenes at any scale (the format sets no unit and no magnitude limit):
the GPU computes in float32, so the renderer uploads a scene whose camera
distance is far from 1 scaled by a power of two (gpu/frame.py gpu_frame_scene).
Checked by invariance: the same scene written at 10^k times the size gives
the same picture, with no NaN and no numpy warning; and against analytic
limits (a point light at 1e300 is a directional light)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from viewer.measure import stress_cases

from conftest import make_scene


def scaled_doc(L: float) -> dict:
    """One scene of every kind of object and of length, written at size L:
    lengths times L, absorption (per unit length) divided by it."""
    return {
        "camera": {"position": [0, 1 * L, 5 * L], "target": [0, 0, 0]},
        "lights": [{"position": [4 * L, 6 * L, 3 * L]}],
        "materials": {
            "m": {"color": [0.8, 0.2, 0.2], "specular": 0.5},
            "f": {"checker": {"color": [0.1, 0.1, 0.1], "size": 0.5 * L}},
            "g": {"transparency": 0.9, "ior": 1.5, "absorption": [0.2 / L, 0.1 / L, 0.0]},
        },
        "objects": [
            {"type": "plane", "material": "f", "height": -1 * L},
            {"type": "sphere", "material": "m", "center": [-1.2 * L, 0, 0], "radius": 0.8 * L},
            {"type": "cylinder", "material": "g", "base": [1.0 * L, -1 * L, 0], "radius": 0.6 * L,
             "height": 1.5 * L, "wall": 0.1 * L},
            {"type": "box", "material": "m", "min": [-0.3 * L, -1 * L, 1 * L], "max": [0.3 * L, -0.4 * L, 1.6 * L],
             "rotate": [0, 30, 0]},
        ],
    }


def render_strict(render, scene, w=96, h=54):
    """Render with every numpy warning an error (overflow, invalid)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(all="raise"):
            return render(scene, w, h)


def off_fraction(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean(np.abs(a - b).max(axis=2) > 1 / 255))


@pytest.mark.parametrize("k", [-300, -30, -19, 19, 30, 300])
def test_a_scene_renders_the_same_at_any_scale(render, k):
    # Before the scaling: from 10^+-17 up pixels went wrong, 10^-20 gave NaN
    # and 10^300 raised OverflowError.
    unit = render_strict(render, make_scene(scaled_doc(1.0)))
    img = render_strict(render, make_scene(scaled_doc(10.0 ** k)))
    assert not np.isnan(img).any()
    assert off_fraction(img, unit) == 0.0, f"10^{k}: {off_fraction(img, unit):.2%} of the pixels differ"
    assert float(np.abs(img - unit).max()) < 1e-3


def test_ordinary_scenes_are_uploaded_as_they_are():
    # bit-identical images for every ordinary scene: no copy, no scaling
    from viewer.gpu.frame import gpu_frame_scene
    from viewer.scene.load import builtin_scene_names, load_scene

    for name in builtin_scene_names():
        scene = load_scene(name)
        assert gpu_frame_scene(scene) == (scene, 0)
        assert gpu_frame_scene(scene)[0] is scene
    for L in (1e-5, 1e5):
        scene = make_scene(scaled_doc(L))
        assert gpu_frame_scene(scene)[0] is scene


def test_the_depth_view_is_in_the_scenes_own_units(gl):
    from viewer.gpu.renderer import Renderer

    hits = []
    for L in (1.0, 1e30):
        r = Renderer(gl, make_scene(scaled_doc(L)))
        t, obj, _ = r.first_hits(48, 27)
        r.release()
        hits.append((t / L, obj))
    (t1, o1), (t2, o2) = hits
    assert (o1 == o2).all() and (o1 >= 0).any()
    hit = o1 >= 0
    np.testing.assert_allclose(t2[hit], t1[hit], rtol=1e-5)
    assert np.isinf(t2[~hit]).all()


def test_a_camera_beyond_float64_squares_looks_the_right_way(render):
    # only sky: the picture depends on the view direction alone
    doc = {"camera": {"position": [1e200, 0, 0], "target": [0, 1e199, 0]}}
    unit = {"camera": {"position": [1, 0, 0], "target": [0, 0.1, 0]}}
    a = render_strict(render, make_scene(doc))
    b = render_strict(render, make_scene(unit))
    assert float(np.abs(a - b).max()) < 1e-5


def test_colours_beyond_float32_saturate_instead_of_turning_nan(render):
    # the sky's gradient mixes horizon and zenith: inf * 0 would be NaN
    from viewer.base.imageio import to_display8

    img = render_strict(render, make_scene({"sky": {"horizon": [1e39, 0, 0]},
                                            "camera": {"position": [0, 1, 5], "target": [0, 0.9, 0]}}))
    assert not np.isnan(img).any()
    assert (img[..., 0] > 1e37).all()          # float32's largest, times the horizon's share
    assert (to_display8(img)[..., 0] == 255).all()


def test_a_point_light_at_1e300_is_a_directional_light(render):
    # no fall-off: from infinitely far a point light only has a direction
    def doc(light):
        return {"camera": {"position": [0, 2, 5], "target": [0, 0, 0]},
                "lights": [light],
                "materials": {"m": {"color": [0.8, 0.8, 0.8], "specular": 0.3}},
                "objects": [{"type": "plane", "material": "m", "height": -1},
                            {"type": "sphere", "material": "m", "center": [0, 0, 0], "radius": 1}]}
    far = render_strict(render, make_scene(doc({"position": [1e300, 2e300, 1e300]})))
    sun = render_strict(render, make_scene(doc({"type": "directional", "direction": [-1, -2, -1]})))
    assert far.max() > 0.3                      # lit (before: black, the light's length overflowed)
    assert off_fraction(far, sun) < 0.002
    assert float(np.abs(far - sun).max()) < 0.05


def test_a_plane_1e300_below_is_still_the_ground(render):
    def doc(h):
        return {"camera": {"position": [0, 1, 5], "target": [0, 0, 0]},
                "lights": [{"type": "directional", "direction": [0, -1, -1]}],
                "materials": {"m": {"color": [0.2, 0.8, 0.2]}},
                "objects": [{"type": "plane", "material": "m", "height": h}]}
    far = render_strict(render, make_scene(doc(-1e300)))
    near = render_strict(render, make_scene(doc(-1e3)))
    # every ray below the horizon meets it: ambient + diffuse, n.l = 1/sqrt(2)
    ground = np.array([0.2, 0.8, 0.2]) * (0.05 * 0.1 + 0.8 / math.sqrt(2))
    np.testing.assert_allclose(near[-1, 0], ground, rtol=1e-4)
    assert float(np.abs(far - near).max()) < 1e-5


def test_objects_beyond_float32_do_not_crash_or_warn(render, gl):
    # not drawn faithfully (README, implementation limits), but a valid scene:
    # no exception, no numpy warning, no NaN
    from viewer.gpu.geometry import contains_point

    doc = {"camera": {"position": [0, 1, 5], "target": [0, 0, 0]},
           "lights": [{"position": [4, 6, 3]}],
           "materials": {"m": {"color": [0.2, 0.8, 0.2]}, "g": {"transparency": 1, "ior": 1.3}},
           "objects": [{"type": "box", "material": "m", "min": [-1e308, -1e308, -1e308], "max": [1e308, 0, 1e308]},
                       {"type": "sphere", "material": "g", "center": [0, 0, 0], "radius": 1e200},
                       {"type": "cylinder", "material": "g", "base": [0, -1e300, 0], "radius": 1e300,
                        "height": 1.5e300, "wall": 1e299}]}
    scene = make_scene(doc)
    assert contains_point(scene.objects[1], np.array([0.0, 1.0, 5.0]))    # was OverflowError
    img = render_strict(render, scene)
    assert np.isfinite(img).all()


@pytest.mark.parametrize("k", [-30, -5, 20, 30])
def test_the_float64_reference_is_scale_free_too(k):
    # an independent route for the same symmetry; it had an absolute offset
    # floor (1e-5: 0.4% of pixels off) and an absolute probe step (1e20: the
    # floor toward the horizon lost, 3.9%)
    from viewer.reference.trace import render_reference
    from viewer.scene.load import scene_from_dict

    unit = render_reference(scene_from_dict(stress_cases._base()), 48, 27)
    img = render_reference(scene_from_dict(stress_cases.scaled(stress_cases._base(), 10.0 ** k)), 48, 27)
    assert float(np.abs(img - unit).max()) < 1e-9
