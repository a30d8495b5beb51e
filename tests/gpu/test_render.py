"""Rendering checks with physically meaningful, independent expectations:
vanishing media, the inverted image in a glass sphere, a furnace test,
invariances and symmetries, and the box rotation convention."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import make_scene
from viewer.scene.load import load_scene

CLEAR = {"color": [1, 1, 1], "ambient": 0, "diffuse": 0, "specular": 0, "transparency": 1}


def glass_of_water(ior_glass=1.5, ior_water=1.33, absorption=(0.0, 0.0, 0.0), with_glass=True):
    """The default scene's content as a dict (no sphere; a plain rod)."""
    doc = {
        "camera": {"position": [3.2, 2.2, 4.6], "target": [0, 0.9, 0], "fov": 40},
        "render": {"max_depth": 12, "min_weight": 0.0},
        "lights": [{"type": "point", "position": [4, 6, 3]}],
        "materials": {
            "floor": {"color": [0.85, 0.85, 0.85], "checker": {"color": [0.25, 0.25, 0.25], "size": 0.5}},
            "glass": dict(CLEAR, ior=ior_glass),
            "water": dict(CLEAR, ior=ior_water, absorption=list(absorption)),
            "rod": {"color": [0.8, 0.25, 0.15], "specular": 0.3},
        },
        "objects": [{"type": "plane", "material": "floor"}],
    }
    if with_glass:
        doc["objects"] += [
            {"type": "cylinder", "base": [0, 0, 0], "radius": 1.0, "height": 2.4, "wall": 0.06, "material": "glass"},
            {"type": "cylinder", "base": [0, 0.06, 0], "radius": 0.945, "height": 1.3, "material": "water"},
        ]
    doc["objects"].append({"type": "box", "min": [-0.08, 0.1, -0.08], "max": [0.08, 3.1, 0.08],
                           "rotate": [0, 0, -22], "material": "rod"})
    return doc


def test_media_of_ior_one_vanish_exactly(render):
    # ior 1 everywhere, transparency 1, no Phong terms, no absorption: every
    # interaction has R = 0 and the ray goes straight on, so the image is that
    # of the scene without the glass and the liquid.
    with_media = render(make_scene(glass_of_water(1.0, 1.0)), 96, 54)
    without = render(make_scene(glass_of_water(with_glass=False)), 96, 54)
    assert np.max(np.abs(with_media - without)) < 2e-5


def test_equal_ior_interface_vanishes(render):
    # liquid ior == glass ior: the inner interface has R = 0 and no bend, so
    # the picture equals a glass filled with glass up to the liquid level.
    a = render(make_scene(glass_of_water(1.5, 1.5)), 96, 54)
    doc = glass_of_water(1.5, 1.5)
    doc["materials"]["water"] = dict(doc["materials"]["glass"])  # same material under another name
    b = render(make_scene(doc), 96, 54)
    assert np.max(np.abs(a - b)) < 1e-5
    # and it differs from the real glass of water (the test can see a change)
    c = render(make_scene(glass_of_water()), 96, 54)
    assert np.max(np.abs(a - c)) > 0.05


def _quadrant_floor_scene(with_sphere: bool):
    # Checker squares of size 10: around the origin the floor is split at x = 0
    # (bright for x >= 0, dark for x < 0 where 0 <= z < 10). Emission only.
    doc = {
        "ambient": [0, 0, 0],
        "camera": {"position": [0, 20, 3.0], "target": [0, 0, 1.0], "fov": 6},
        "render": {"max_depth": 10, "min_weight": 0.0},
        "sky": {"type": "color", "color": [0, 0, 0]},
        "materials": {
            "floor": {"color": [0, 0, 0], "ambient": 0, "diffuse": 0, "emission": [1, 1, 1],
                      "checker": {"color": [0, 0, 0], "emission": [0.05, 0.05, 0.05], "size": 10}},
            "glass": dict(CLEAR, ior=1.5),
        },
        "objects": [{"type": "plane", "material": "floor"}],
    }
    if with_sphere:
        # ball lens: focal length n r / (2 (n - 1)) = 0.75 from its centre,
        # the floor 1.0 below it, so the eye far above sees a real inverted image
        doc["objects"].append({"type": "sphere", "center": [0, 1.0, 1.0], "radius": 0.5, "material": "glass"})
    return make_scene(doc)


def test_glass_sphere_flips_what_is_behind_it(render):
    w, h = 120, 120
    plain = render(_quadrant_floor_scene(False), w, h)
    ball = render(_quadrant_floor_scene(True), w, h)
    mid = h // 2
    # Without the sphere: left half dark, right half bright (x to the right in the image).
    assert plain[mid, w // 2 - 20].mean() < 0.1 and plain[mid, w // 2 + 20].mean() > 0.9
    # Through the sphere near its centre the floor is seen inverted.
    assert ball[mid, w // 2 - 6].mean() > 0.5, "left of the centre should show the bright (x > 0) side"
    assert ball[mid, w // 2 + 6].mean() < 0.3, "right of the centre should show the dark (x < 0) side"


def test_furnace_clear_sphere_in_uniform_sky_shows_the_sky(render):
    # Energy: with nothing but a uniform sky, every branch of the tree ends in
    # the sky, and the weights R and 1 - R of each split add up to one, so
    # every pixel is the sky colour up to what max_depth/min_weight cut.
    sky = [0.3, 0.5, 0.7]
    doc = {"ambient": [0, 0, 0], "sky": {"type": "color", "color": sky},
           "camera": {"position": [0, 0, 3], "target": [0, 0, 0], "fov": 50},
           "render": {"max_depth": 24, "min_weight": 1e-5},
           "materials": {"glass": dict(CLEAR, ior=1.5)},
           "objects": [{"type": "sphere", "center": [0, 0, 0], "radius": 1.0, "material": "glass"}]}
    img = render(make_scene(doc), 64, 64)
    assert np.max(np.abs(img - np.array(sky, np.float32))) < 2e-3
    # with a shallow tree the cut energy shows: the test can fail
    doc["render"]["max_depth"] = 2
    shallow = render(make_scene(doc), 64, 64)
    assert np.max(np.abs(shallow - np.array(sky, np.float32))) > 0.05


def test_translation_by_checker_periods_changes_nothing(render):
    # The checker repeats every 2 * size (size 0.5); moving the whole scene and
    # the eye by whole periods must give the same picture (camera-relative
    # coordinates keep the precision).
    base = glass_of_water()
    base["render"]["max_depth"] = 6
    ref = render(make_scene(base), 96, 54)
    off = np.array([1000.0, 0.0, -3000.0])

    def shifted(doc):
        doc = {**doc}
        doc["camera"] = {**doc["camera"], "position": list(np.add(doc["camera"]["position"], off)),
                         "target": list(np.add(doc["camera"]["target"], off))}
        doc["lights"] = [{**lt, "position": list(np.add(lt["position"], off))} for lt in doc["lights"]]
        objs = []
        for o in doc["objects"]:
            o = dict(o)
            for key in ("base", "min", "max", "center"):
                if key in o:
                    o[key] = list(np.add(o[key], off))
            objs.append(o)
        doc["objects"] = objs
        return doc

    moved = render(make_scene(shifted(base)), 96, 54)
    diff = np.abs(moved - ref).max(axis=2)
    assert np.mean(diff > 1 / 255) < 0.003, f"{np.mean(diff > 1 / 255):.4f} of pixels changed"


def test_left_right_mirror_symmetry(render):
    # A scene symmetric about the plane x = 0 seen from a camera on that plane.
    doc = glass_of_water()
    doc["materials"]["floor"] = {"color": [0.7, 0.7, 0.7]}
    doc["camera"] = {"position": [0, 2.0, 5.0], "target": [0, 0.9, 0], "fov": 40}
    doc["lights"] = [{"type": "point", "position": [0, 6, 3]}]
    doc["objects"][-1]["rotate"] = [0, 0, 0]
    doc["objects"][-1]["min"] = [-0.08, 0.1, -0.08]
    img = render(make_scene(doc), 96, 54)
    diff = np.abs(img - img[:, ::-1]).max(axis=2)
    assert np.mean(diff > 1 / 255) < 0.005


def test_box_rotation_is_counter_clockwise_about_z(render):
    # A tall thin box turned +30 degrees about z (a positive angle turns +x
    # toward +y, so +y turns toward -x): seen from +z its top leans left.
    doc = {"camera": {"position": [0, 1, 6], "target": [0, 1, 0], "fov": 40},
           "sky": {"type": "color", "color": [0, 0, 0]}, "ambient": [1, 1, 1],
           "materials": {"m": {"color": [1, 1, 1], "ambient": 1, "diffuse": 0}},
           "objects": [{"type": "box", "min": [-0.1, 0, -0.1], "max": [0.1, 2, 0.1], "rotate": [0, 0, 30],
                        "material": "m"}]}
    img = render(make_scene(doc), 80, 80).mean(axis=2)
    rows = [r for r in range(80) if img[r].max() > 0.5]
    top, bottom = rows[0], rows[-1]
    centre = lambda r: np.mean(np.nonzero(img[r] > 0.5)[0])  # noqa: E731
    assert centre(top) < centre(bottom) - 10


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_cylinder_axis_extent(render, axis):
    # A cylinder of length 2 along `axis` and radius 0.25, seen from +z: the
    # image extent along the axis is about 4x the other one (x, y), or it is a
    # disc (z).
    doc = {"camera": {"position": [0, 0.001, 8], "target": [0, 0, 0], "fov": 30},
           "sky": {"type": "color", "color": [0, 0, 0]}, "ambient": [1, 1, 1],
           "materials": {"m": {"color": [1, 1, 1], "ambient": 1, "diffuse": 0}},
           "objects": [{"type": "cylinder", "axis": axis, "radius": 0.25, "height": 2.0,
                        "base": {"x": [-1, 0, 0], "y": [0, -1, 0], "z": [0, 0, -1]}[axis], "material": "m"}]}
    img = render(make_scene(doc), 100, 100).mean(axis=2) > 0.5
    ys, xs = np.nonzero(img)
    wx, wy = xs.max() - xs.min() + 1, ys.max() - ys.min() + 1
    if axis == "x":
        assert 3.5 * wy < wx < 4.5 * wy
    elif axis == "y":
        assert 3.5 * wx < wy < 4.5 * wx
    else:
        assert abs(wx - wy) <= 2


def test_absorption_follows_beer_lambert(render):
    # An absorbing slab (a box of clear liquid with ior 1, so nothing bends or
    # reflects) between the eye and a white emitter: each channel keeps
    # exp(-a * d) with d the slab's thickness along the ray.
    a = [0.5, 1.0, 2.0]
    doc = {"ambient": [0, 0, 0], "sky": {"type": "color", "color": [1, 1, 1]},
           "camera": {"position": [0, 0.0001, 5], "target": [0, 0, 0], "fov": 10},
           "render": {"max_depth": 4, "min_weight": 0},
           "materials": {"liquid": dict(CLEAR, ior=1.0, absorption=a)},
           "objects": [{"type": "box", "min": [-2, -2, -0.6], "max": [2, 2, 0.6], "material": "liquid"}]}
    img = render(make_scene(doc), 9, 9)
    centre = img[4, 4]
    # the central ray is (almost) along -z: thickness 1.2 (test vector: a = 0.5 keeps 0.548812)
    np.testing.assert_allclose(centre, np.exp(-np.array(a) * 1.2), rtol=1e-4)
    assert centre[0] == pytest.approx(0.548812, abs=1e-4)


def test_transparent_objects_attenuate_shadows(render):
    # A point light above a half-transparent slab over a white floor: the
    # floor under the slab receives transparency x (light), elsewhere full.
    def scene(transparency):
        return make_scene({
            "ambient": [0, 0, 0], "sky": {"type": "color", "color": [0, 0, 0]},
            "camera": {"position": [0, 4, 4], "target": [0, 0, 0], "fov": 50},
            "lights": [{"type": "point", "position": [0, 5, 0]}],
            "materials": {"floor": {"color": [1, 1, 1], "ambient": 0, "diffuse": 1},
                          "pane": dict(CLEAR, ior=1.0, transparency=transparency)},
            "objects": [{"type": "plane", "material": "floor"},
                        {"type": "box", "min": [-0.5, 2.0, -0.5], "max": [0.5, 2.1, 0.5], "material": "pane"}]})

    lit = render(scene(1.0), 64, 64)
    half = render(scene(0.5), 64, 64)
    # the floor point right under the light, seen at the image position where
    # the slab does not hide it: compare a floor pixel inside the shadow area
    # (ratio ~ 0.5 x 0.5: the shadow ray crosses two surfaces) and one outside (1).
    ratio = half / np.maximum(lit, 1e-6)
    floor_mask = lit.mean(axis=2) > 1e-3
    values = np.round(ratio[floor_mask].mean(axis=1), 2)
    assert np.any(np.isclose(values, 0.25, atol=0.02)), "no floor pixel in the 0.5 x 0.5 shadow"
    assert np.any(np.isclose(values, 1.0, atol=0.01)), "no floor pixel outside the shadow"


def test_same_seed_same_image_and_samples_converge(render):
    scene = load_scene("glass-sphere")
    a = render(scene, 48, 27, samples=4, seed=3)
    b = render(scene, 48, 27, samples=4, seed=3)
    assert np.array_equal(a, b)
    c = render(scene, 48, 27, samples=4, seed=4)
    assert not np.array_equal(a, c)
    # many samples converge: two seeds agree better at 64 than at 4 samples
    d = render(scene, 48, 27, samples=64, seed=1)
    e = render(scene, 48, 27, samples=64, seed=2)
    assert np.abs(d - e).mean() < np.abs(a - c).mean()


@pytest.mark.parametrize("name", ["default", "glass-sphere", "mirror-ball", "glass-rod-x",
                                  "coloured-liquid", "whitted-exact"])
def test_builtin_scenes_render_finite(render, name):
    img = render(load_scene(name), 64, 36)
    assert np.all(np.isfinite(img))
    assert img.min() >= 0.0
    assert img.std() > 0.01  # not a blank picture


def test_a_renderer_builds_its_later_variants_from_the_shaders_it_started_with(gl, tmp_path, monkeypatch):
    # The viewer compiles culling and debug variants long after it started; a
    # shader file broken on disk meanwhile (an edit in progress) crashed it
    # there (exit 1), although F5 had just kept the last good shaders.  Only a
    # new renderer (F5) reads the disk again.
    import shutil

    from viewer.gpu.renderer import Renderer
    from viewer.scene.load import load_scene
    from viewer.gpu.shaders import ShaderError, shader_root

    shaders = tmp_path / "shaders"
    shutil.copytree(shader_root(), shaders)
    monkeypatch.setenv("GLASSRAY_SHADERS", str(shaders))
    r = Renderer(gl, load_scene("default"))
    try:
        good = r.render(64, 36, 1)
        trace = shaders / "render.frag"
        trace.write_text(trace.read_text().replace("void main() {", "void main() { this_is_an_error;"))
        (shaders / "lib" / "optics.glsl").unlink()
        before = r.programs_built
        r.variant(VIEW_MODE=1)                       # a debug view: a new program
        assert r.programs_built == before + 1
        r.COMPILES_PER_DRAW = 99                     # every culling variant at a new size
        r.render(320, 180, 1)
        assert r.programs_built > before + 1
        assert np.array_equal(r.render(64, 36, 1), good)
        with pytest.raises(ShaderError, match="this_is_an_error|optics.glsl"):
            Renderer(gl, load_scene("default"))      # F5: the disk as it is now
    finally:
        r.release()


def test_a_medium_s_optics_edited_in_place_take_effect_without_a_compile(gl):
    # The block carries each transparent slot's ior, transparency and
    # absorption beside its material (gpu/block.py MEDIUM_DTYPE): an edit of
    # those values (the panel's set_scene) must reach every copy, with no
    # new program, and give the image a new renderer of the edited scene gives.
    import copy

    from viewer.gpu.renderer import Renderer

    scene = load_scene("coloured-liquid")
    r = Renderer(gl, scene)
    before = r.render(64, 36, 1)
    built = r.programs_built
    edited = copy.deepcopy(scene)
    transparent = [m for m in edited.materials.values() if m.transparency > 0]
    assert len(transparent) >= 2
    for m in transparent:
        m.ior = 1.9 if m.ior < 1.4 else 1.2
        m.absorption = [0.5, 0.1, 0.9]
        m.transparency = 0.7
    r.set_scene(edited)
    after = r.render(64, 36, 1)
    assert r.programs_built == built
    assert np.abs(after - before).max() > 0.05
    fresh = Renderer(gl, edited)
    assert np.array_equal(after, fresh.render(64, 36, 1))
    r.release()
    fresh.release()


def test_each_render_returns_its_own_image(gl):
    """render() reads back into a buffer it keeps: the image it returns must
    not be that buffer, or the next render of the same size would change
    an image the caller holds (and one of another size would leave it)."""
    from viewer.gpu.renderer import Renderer

    r = Renderer(gl, load_scene("default"), eager=False)
    lit = r.render(48, 27, 1)
    kept = lit.copy()
    r.scene.lights[0].color = (0.0, 0.0, 0.0)
    r.set_scene(r.scene)
    dark = r.render(48, 27, 1)
    assert not np.array_equal(dark, kept), "the light's change shows"
    assert np.array_equal(lit, kept), "the first image did not change"
    assert lit.flags.c_contiguous and lit.flags.writeable and lit.flags.owndata
    dark_kept = dark.copy()
    r.render(48, 27, 2)                                  # the divided read-back
    r.render(24, 12, 1)                                  # another size: a new buffer
    assert np.array_equal(dark, dark_kept)
    r.release()
