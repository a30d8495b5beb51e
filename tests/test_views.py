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


def test_no_shadow_ray_where_the_light_term_is_zero(gl):
    """A light's Phong term k_d n.l + k_s max(0, r.v)^p multiplies its
    visibility, so where it is zero no shadow ray is traced.  A floor seen
    from (0, 1, 5), 17x17, its lower half (rows 9-16) on the floor:
    - k_d = k_s = 0 (ambient only): the camera ray only, and still lit;
    - k_d = 0, k_s = 1, p = 200, the light behind and above the eye: every
      mirror direction r points away from the eye (r.v < 0): no shadow ray;
    - the same with the light in front, low over the floor: r.v is near 1
      on the floor's near part, so shadow rays are traced there."""
    def cost(material, light):
        doc = {"camera": {"position": [0, 1, 5], "target": [0, 0.5, 0], "fov": 60},
               "lights": [{"position": light}],
               "materials": {"m": {"color": [0.8, 0.8, 0.8], **material}},
               "objects": [{"type": "plane", "material": "m"}]}
        r = Renderer(gl, make_scene(doc))
        try:
            return r.ray_cost(17, 17)[9:], r.render(17, 17, 1)[9:]
        finally:
            r.release()

    floor, img = cost({"diffuse": 0.0, "ambient": 0.5}, [0, 5, 0])
    assert (floor == 1).all() and img.min() > 0
    sharp = {"diffuse": 0.0, "specular": 1.0, "shininess": 200}
    floor, _ = cost(sharp, [0, 6, 12])
    assert (floor == 1).all()
    floor, _ = cost(sharp, [0, 1, -5])
    assert floor.max() == 2 and (floor[-1] == 2).all()


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
