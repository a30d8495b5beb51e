"""Debug views: first-hit data and ray cost, with analytic expectations."""

from __future__ import annotations

import numpy as np

from conftest import make_scene
from viewer.renderer import Renderer

PLAIN = {"materials": {"m": {"color": [0.8, 0.8, 0.8]}},
         "camera": {"position": [0, 1, 5], "target": [0, 1, 0], "fov": 40}}


def test_first_hit_of_a_sphere_is_analytic(gl):
    doc = {**PLAIN, "objects": [{"type": "sphere", "center": [0, 1, 0], "radius": 1, "material": "m"}]}
    r = Renderer(gl, make_scene(doc))
    try:
        t, obj, n = r.first_hits(33, 33)
    finally:
        r.release()
    # the centre pixel looks straight at the sphere: t = 5 - 1, normal +z
    assert obj[16, 16] == 0 and abs(t[16, 16] - 4.0) < 1e-5
    np.testing.assert_allclose(n[16, 16], [0, 0, 1], atol=1e-5)
    assert obj[0, 0] == -1 and np.isinf(t[0, 0])
    hit = obj >= 0
    np.testing.assert_allclose(np.linalg.norm(n[hit], axis=-1), 1.0, atol=1e-5)


def test_ray_cost_counts_camera_and_shadow_rays(gl):
    # Sky: 1 ray. Opaque floor with one light: the camera ray and a shadow ray.
    # A mirror floor adds the reflected ray and that ray's own hit (sky).
    def cost(reflectivity, lights):
        doc = {"camera": {"position": [0, 1, 5], "target": [0, 0.5, 0], "fov": 60},
               "lights": lights,
               "materials": {"m": {"color": [0.8, 0.8, 0.8], "reflectivity": reflectivity}},
               "objects": [{"type": "plane", "material": "m"}]}
        r = Renderer(gl, make_scene(doc))
        try:
            return r.ray_cost(16, 16)
        finally:
            r.release()

    c = cost(0.0, [{"position": [0, 5, 0]}])
    assert c[0, 8] == 1 and c[-1, 8] == 2
    c = cost(0.5, [{"position": [0, 5, 0]}])
    assert c[-1, 8] == 3          # camera, shadow, reflected (which escapes to the sky)
    c = cost(0.0, [])
    assert c[-1, 8] == 1


def test_generic_shader_draws_the_same_image(gl):
    # Specialisation must be image-neutral: the all-features shader with
    # run-time counts gives the same picture on every built-in scene.
    from viewer.scene import builtin_scene_names, load_scene

    for name in builtin_scene_names():
        scene = load_scene(name)
        imgs = []
        for specialise in (True, False):
            r = Renderer(gl, scene, specialise=specialise)
            try:
                imgs.append(r.render(64, 36, 1))
            finally:
                r.release()
        assert np.max(np.abs(imgs[0] - imgs[1])) < 1e-4, name


def test_schlick_option_changes_dielectric_images_only(gl):
    from viewer.scene import load_scene

    def img(name, fresnel):
        r = Renderer(gl, load_scene(name), fresnel=fresnel)
        try:
            return r.render(48, 27, 1)
        finally:
            r.release()

    assert np.max(np.abs(img("default", "exact") - img("default", "schlick"))) > 1e-3
    assert np.array_equal(img("mirror-ball", "exact"), img("mirror-ball", "schlick"))
