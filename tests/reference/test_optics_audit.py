"""Optics audit: small adversarial scenes checked against values computed
from shared/spec/scene-format.md by hand (NumPy), on the GPU and in the
float64 reference (viewer/reference/trace.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import make_scene
from viewer.reference import trace as reference
from viewer.gpu.renderer import Renderer

CLEAR = {"color": [1, 1, 1], "ambient": 0, "diffuse": 0, "specular": 0, "transparency": 1}


def _gpu(gl, scene, w, h, specialise=True):
    r = Renderer(gl, scene, specialise=specialise)
    try:
        return r.render(w, h, 1, 0).astype(np.float64)
    finally:
        r.release()


# --------------------------------------------------------------------------- many surfaces inside one medium

A = np.array([0.2, 0.1, 0.05])


def _box_holding_vessels(camera):
    """A clear absorbing box (ior 1) listed first, holding two transparent
    vessels: the box owns them, so their 8 surfaces along a line are no
    interaction (the spec's nested media) and the vessels are invisible."""
    mats = {"box": dict(CLEAR, ior=1.0, absorption=A.tolist()), "vessel": dict(CLEAR, ior=1.5)}
    objs = [{"type": "box", "min": [-3, -2, -2], "max": [3, 2, 2], "material": "box"}]
    for x in (-1, 1):
        objs.append({"type": "cylinder", "base": [x, -1, 0], "radius": 0.8, "height": 2, "wall": 0.1,
                     "material": "vessel"})
    return make_scene({"camera": camera, "ambient": [0, 0, 0], "materials": mats, "objects": objs,
                       "sky": {"type": "color", "color": [1, 1, 1]}, "render": {"max_depth": 8, "min_weight": 0}})


@pytest.mark.parametrize("specialise", [True, False])
def test_invisible_surfaces_inside_a_medium_do_not_end_the_ray(gl, specialise):
    # Looking along x through the box (6 long) and both vessels: the centre
    # pixel of an odd image keeps exp(-a 6) of the white sky.  The shader
    # walked at most 2 * objects + 2 groups of surfaces and took the ray for
    # escaped after 8 (only exp(-a 4.8) of the absorption).
    scene = _box_holding_vessels({"position": [-8, 0, 0], "target": [0, 0, 0], "fov": 30})
    want = np.exp(-A * 6.0)
    ref = reference.render_reference(scene, 31, 23, samples=1)
    assert np.allclose(ref[11, 15], want, atol=1e-9)
    img = _gpu(gl, scene, 31, 23, specialise)
    assert np.allclose(img[11, 15], want, atol=2e-5)
    # the vessels are invisible: the whole image is that of the box alone
    alone = make_scene({"camera": {"position": [-8, 0, 0], "target": [0, 0, 0], "fov": 30},
                        "ambient": [0, 0, 0], "sky": {"type": "color", "color": [1, 1, 1]},
                        "materials": {"box": dict(CLEAR, ior=1.0, absorption=A.tolist())},
                        "objects": [{"type": "box", "min": [-3, -2, -2], "max": [3, 2, 2], "material": "box"}],
                        "render": {"max_depth": 8, "min_weight": 0}})
    assert np.abs(img - _gpu(gl, alone, 31, 23, specialise)).max() < 1e-4


def test_invisible_surfaces_inside_a_medium_do_not_end_a_shadow_ray(gl):
    # A longer clear box holding three vessels and an opaque ball; a point
    # light beyond the box on the line through the vessels.  From the camera
    # (inside the box) the centre pixel sees the ball's point (-3.7, 0, 0)
    # face on, lit face on: its shadow ray runs 8.7 through the box and
    # crosses the vessels' 12 surfaces (no interaction) and the box's end
    # (transparency 1): L = exp(-a 0.7) (eye to ball) * exp(-a 8.7) * k_d.
    mats = {"box": dict(CLEAR, ior=1.0, absorption=A.tolist()), "vessel": dict(CLEAR, ior=1.5),
            "ball": {"color": [1, 1, 1], "ambient": 0, "diffuse": 1}}
    objs = [{"type": "box", "min": [-5, -2, -2], "max": [5, 2, 2], "material": "box"}]
    for x in (-2, 0, 2):
        objs.append({"type": "cylinder", "base": [x, -1, 0], "radius": 0.8, "height": 2, "wall": 0.1,
                     "material": "vessel"})
    objs.append({"type": "sphere", "center": [-4, 0, 0], "radius": 0.3, "material": "ball"})
    scene = make_scene({"camera": {"position": [-3, 0, 0], "target": [-4, 0, 0], "fov": 20},
                        "lights": [{"type": "point", "position": [6, 0, 0]}], "ambient": [0, 0, 0],
                        "materials": mats, "objects": objs, "sky": {"type": "color", "color": [0, 0, 0]},
                        "render": {"max_depth": 8, "min_weight": 0}})
    want = np.exp(-A * 9.4)
    ref = reference.render_reference(scene, 31, 23, samples=1)
    assert np.allclose(ref[11, 15], want, atol=1e-9)
    img = _gpu(gl, scene, 31, 23)
    assert np.allclose(img[11, 15], want, atol=2e-5)


# --------------------------------------------------------------------------- equal iors at grazing incidence


def test_equal_iors_never_reflect_even_at_grazing_incidence(gl):
    # An absorbing sea of ior 1 (the plane's half-space) seen from 0.001
    # above at 0.0086 degrees below the horizon (cos i = 1.5e-4).  Equal
    # iors: R = 0, the ray goes straight on into the sea and never comes
    # out (exp(-a inf) = 0).  In float32 1 - cos^2 rounds to 1 there and the
    # shader took it for total internal reflection: the sky.
    dy = 1.5e-4
    scene = make_scene({"camera": {"position": [0, 1e-3, 0], "target": [0, 1e-3 - dy, -1], "fov": 1},
                        "ambient": [0, 0, 0], "sky": {"type": "color", "color": [1, 1, 1]},
                        "materials": {"sea": dict(CLEAR, ior=1.0, absorption=[1, 1, 1])},
                        "objects": [{"type": "plane", "material": "sea"}],
                        "render": {"max_depth": 4, "min_weight": 0}})
    o, d = reference.camera_rays(scene, 31, 23)
    assert -d[11, 15, 1] == pytest.approx(dy / math.hypot(1, dy), rel=1e-9)   # the centre ray's cos i
    ref = reference.render_reference(scene, 31, 23, samples=1)
    img = _gpu(gl, scene, 31, 23)
    assert np.allclose(ref[11, 15], 0.0, atol=1e-12)
    assert np.allclose(img[11, 15], 0.0, atol=1e-6)
    # rows above the horizon see the sky, rows well below it the sea (the test sees both)
    assert np.allclose(img[0], 1.0) and np.allclose(img[-1], 0.0, atol=1e-6)


# --------------------------------------------------------------------------- checker on faces that lie on its lines


@pytest.mark.parametrize("where", ["x0-from-minus", "x0-from-plus", "z1"])
def test_checker_on_a_face_lying_on_a_checker_line(gl, where):
    # A checkered box whose visible face lies on a line of the checker (size
    # 0.5): x = 0, or z = 1.  There floor(x / s) (or floor(z / s)) is exact,
    # so the face shows stripes of the other coordinate only.  Both tracers
    # evaluated the rounding of the hit point, +-1e-16 (float64) or +-1e-7
    # (float32) off the line, and drew salt and pepper.
    box, cam, axis, value = {
        "x0-from-minus": ([[0, -1, -1], [1, 1, 1]], [-3, 0.3, 0.4], 0, 0.0),
        "x0-from-plus": ([[-2, -1, -1], [0, 1, 1]], [3.3, 0.3, 0.45], 0, 0.0),
        "z1": ([[-1, -1, -1], [1, 1, 1]], [0.4, 0.3, 4], 2, 1.0)}[where]
    scene = make_scene({"camera": {"position": cam, "target": [0, 0, 0], "fov": 40}, "ambient": [1, 1, 1],
                        "sky": {"type": "color", "color": [0.5, 0.5, 0.5]},
                        "materials": {"ck": {"color": [1, 1, 1], "ambient": 1, "diffuse": 0,
                                             "checker": {"color": [0, 0, 0], "size": 0.5}}},
                        "objects": [{"type": "box", "min": box[0], "max": box[1], "material": "ck"}],
                        "render": {"max_depth": 1}})
    W, H = 48, 36
    o, d = reference.camera_rays(scene, W, H)
    t, obj, n = reference.first_hit(scene, o.reshape(-1, 3), d.reshape(-1, 3))
    on_face = (obj == 0) & (np.abs(n[:, axis]) == 1.0)
    assert on_face.sum() > 300
    P = o.reshape(-1, 3)[on_face] + t[on_face, None] * d.reshape(-1, 3)[on_face]
    P[:, axis] = value                                   # the exact face
    odd = np.mod(np.floor(P[:, 0] / 0.5) + np.floor(P[:, 2] / 0.5), 2.0) == 1.0
    want = np.where(odd, 0.0, 1.0)
    assert 0.2 < odd.mean() < 0.8                        # both colours show
    ref = reference.render_reference(scene, W, H, samples=1).reshape(-1, 3)[on_face, 0]
    img = _gpu(gl, scene, W, H).reshape(-1, 3)[on_face, 0]
    # a pixel whose ray meets the face at a line of the other coordinate may go either way
    other = 2 - axis
    edge = np.abs(P[:, other] / 0.5 - np.round(P[:, other] / 0.5)) < 1e-4
    assert np.array_equal(ref[~edge], want[~edge])
    assert np.abs(img[~edge] - want[~edge]).max() < 1e-6
