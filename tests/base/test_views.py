"""Debug views: first-hit data and ray cost, with analytic expectations."""

from __future__ import annotations

import numpy as np

from conftest import make_scene
from viewer.gpu.renderer import Renderer

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
    from viewer.scene.load import builtin_scene_names, load_scene

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
    from viewer.scene.load import load_scene

    def img(name, fresnel):
        r = Renderer(gl, load_scene(name), fresnel=fresnel)
        try:
            return r.render(48, 27, 1)
        finally:
            r.release()

    assert np.max(np.abs(img("default", "exact") - img("default", "schlick"))) > 1e-3
    assert np.array_equal(img("mirror-ball", "exact"), img("mirror-ball", "schlick"))


# Four materials (a checker, glass, a mirror, a dull one) and three lights
# of different kinds and colours: every entry of pickLight's and
# pickMaterial's selects is taken somewhere in the image.
MANY_LIGHTS = {
    "camera": {"position": [0, 2.5, 6], "target": [0, 0.6, 0], "fov": 45},
    "lights": [{"position": [3, 5, 2], "color": [1.0, 0.6, 0.5]},
               {"position": [-4, 3, 1], "color": [0.3, 0.5, 1.0], "intensity": 0.7},
               {"type": "directional", "direction": [0.2, -1, -0.4], "color": [0.4, 1.0, 0.4], "intensity": 0.5}],
    "materials": {"floor": {"color": [0.8, 0.8, 0.8], "checker": {"color": [0.2, 0.2, 0.2], "size": 0.5}},
                  "glass": {"color": [1, 1, 1], "diffuse": 0, "ambient": 0, "specular": 0.6, "shininess": 100,
                            "transparency": 1, "ior": 1.5},
                  "mirror": {"color": [0.9, 0.9, 0.9], "reflectivity": 0.6, "specular": 0.4},
                  "dull": {"color": [0.8, 0.3, 0.2], "specular": 0.2}},
    "objects": [{"type": "plane", "material": "floor"},
                {"type": "sphere", "center": [-0.8, 0.6, 0], "radius": 0.6, "material": "glass"},
                {"type": "sphere", "center": [0.9, 0.5, -0.4], "radius": 0.5, "material": "mirror"},
                {"type": "box", "min": [-0.3, 0, 0.8], "max": [0.3, 0.9, 1.3], "material": "dull"}],
}


def test_lights_and_materials_read_by_literal_index_give_the_gathered_values(gl):
    # pickLight / pickMaterial (shaders/lib/shade.glsl) select among reads at literal
    # indices; without SCENE_*_INDICES the shader reads lights[j] and
    # materials[objects[k].info.y] directly.  The same values, so the same
    # image bit for bit, at 1 sample and with footprint samples.
    scene = make_scene(MANY_LIGHTS)
    gather = {"SCENE_LIGHT_INDICES(X)": None, "SCENE_MATERIAL_INDICES(X)": None}
    images = []
    for extra in (None, gather):
        r = Renderer(gl, scene, extra_defines=extra)
        try:
            picked = "SCENE_LIGHT_INDICES(X)" in r._defines and r._defines["SCENE_LIGHT_INDICES(X)"] is not None
            assert picked == (extra is None)
            images.append((r.render(64, 40, 1), r.render(32, 20, 4)))
        finally:
            r.release()
    (a1, a4), (b1, b4) = images
    assert np.array_equal(a1, b1) and np.array_equal(a4, b4)
    # and the image is not trivially dark: all three lights reach the floor
    assert a1.mean() > 0.05


def test_index_lists_stop_at_pick_max():
    from viewer.gpu.defines import index_list_macros
    from viewer.gpu.driver import PICK_MAX

    doc = dict(MANY_LIGHTS)
    macros = index_list_macros(make_scene(doc))
    assert macros == {"SCENE_LIGHT_INDICES(X)": "X(1) X(2)", "SCENE_MATERIAL_INDICES(X)": "X(1) X(2) X(3)"}
    one = index_list_macros(make_scene({**doc, "lights": doc["lights"][:1]}))
    assert one["SCENE_LIGHT_INDICES(X)"] == ""       # index 0 only: nothing to select
    many = {**doc, "lights": [{"position": [i, 5, 0]} for i in range(PICK_MAX + 1)]}
    assert "SCENE_LIGHT_INDICES(X)" not in index_list_macros(make_scene(many))
    assert "SCENE_LIGHT_INDICES(X)" not in index_list_macros(make_scene({**doc, "lights": []}))


def test_driver_defines_keep_the_gather_on_old_llvmpipe_only():
    from viewer.gpu.driver import driver_defines

    lp = "llvmpipe (LLVM 15.0.6, 256 bits)"
    assert driver_defines(lp, "4.5 (Core Profile) Mesa 22.3.6") == {"SCENE_MATERIAL_INDICES(X)": None}
    assert driver_defines(lp, "4.5 (Core Profile) Mesa 25.0.7-2~bpo12+1") == {}
    assert driver_defines("NVIDIA H200/PCIe/SSE2", "3.3.0 NVIDIA 580.159.04") == {}
    assert driver_defines("AMD Radeon (radeonsi)", "4.6 (Core Profile) Mesa 22.3.6") == {}
    assert driver_defines(lp, "") == {}
