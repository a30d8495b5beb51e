"""The settings panel used as a user would: edits with hostile values (what
a drag past the end or a typed "-5", "nan" or "1e40" gives), adding and
removing lights and objects, the checker and the sky picture, then "Save
scene"; and how many shader programs a sequence of edits compiles.

Widgets are driven through ImGui itself (a headless context, the panel
drawn for real) with a script that makes one widget, named by its push_id
path and label ("light0/position", "mat-rod/transparency", "obj3/min"),
report an edit of a given value, as ImGui reports one: the value a user
dragged or typed, float32 like every ImGui float.  Expectations come from
the scene format (viewer/scene/'s validation of the saved TOML, the
spec's ranges), not from the panel."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

imgui = pytest.importorskip("imgui_bundle").imgui

from viewer.scene.model import MAX_TRANSPARENT_OBJECTS, SceneError
from viewer.scene.load import load_scene, scene_from_dict
from viewer.scene.save import scene_to_dict

WIDGETS = ("drag_float", "drag_float3", "drag_int", "slider_int", "color_edit3", "combo", "checkbox",
           "button", "small_button", "input_text")


class Script:
    """Makes named widgets report edits; records every widget drawn."""

    def __init__(self, monkeypatch):
        self.ids: list[str] = []
        self.edits: dict[str, object] = {}
        self.seen: set[str] = set()
        real_push, real_pop = imgui.push_id, imgui.pop_id

        def push(x):
            self.ids.append(str(x))
            return real_push(x)

        def pop():
            self.ids.pop()
            return real_pop()

        monkeypatch.setattr(imgui, "push_id", push)
        monkeypatch.setattr(imgui, "pop_id", pop)
        for name in WIDGETS:
            monkeypatch.setattr(imgui, name, self._wrap(name, getattr(imgui, name)))

    def _wrap(self, kind, real):
        def widget(label, *args, **kw):
            out = real(label, *args, **kw)
            key = "/".join([*self.ids, label])
            self.seen.add(key)
            if key in self.edits:
                v = self.edits.pop(key)
                if kind in ("button", "small_button"):
                    return True
                if kind == "combo":                       # the entry, by its text
                    return True, list(args[1]).index(v)
                if kind in ("drag_float", "drag_float3", "color_edit3"):   # ImGui's floats are float32
                    v = float(np.float32(v)) if np.isscalar(v) else [float(np.float32(x)) for x in v]
                if kind == "input_text":
                    return True, v
                return True, v
            return out
        return widget


from test_panel import ui  # noqa: E402,F401  (the headless ImGui context fixture)


def compile_counter(script, panel, scene, renderer):
    """edits -> programs the renderer builds for them (set_scene is what the
    window calls after every panel edit)."""
    def compiles(**edits):
        edit(script, panel, scene, **edits)
        before = renderer.programs_built
        renderer.set_scene(scene)
        return renderer.programs_built - before
    return compiles


@pytest.fixture
def script(ui, monkeypatch):
    return Script(monkeypatch)


def edit(script, panel, scene, **edits):
    """One frame of the panel (every section open) in which these widgets
    report an edit; every one of them must have been drawn."""
    panel.open_all = True
    script.edits = dict(edits)
    imgui.new_frame()
    res = panel.draw(scene, (1280, 720))
    imgui.render()
    assert not script.edits, f"widgets not drawn: {list(script.edits)}"
    return res


def E(key, value):
    return {key: value}


def valid(scene):
    """The scene as "Save scene" writes it passes the scene format's validation."""
    return scene_from_dict(scene_to_dict(scene), source="<panel>")


# ------------------------------------------------------------ values the format rejects


HOSTILE = [
    # (widget, values a drag or a typed number can give)
    ("max depth", [0, -3, 65, 1000]),
    ("samples", [0, -1, 65537, 10**9]),
    ("min weight", [-0.5, 1.5, math.nan, math.inf]),
    ("exposure", [0.0, -1.0, math.nan, math.inf]),
    ("fov", [0.0, 0.5, 179.5, 360.0, math.nan]),
    ("position", [(0.0, 0.9, 0.0), (0.0, 5.0, 0.0), (math.nan, 1.0, 1.0), (math.inf, 0.0, 0.0)]),
    ("target", [(3.2, 2.2, 4.6), (3.2, -4.0, 4.6)]),
    ("light0/position", [(math.nan, 0.0, 0.0), (-math.inf, 1.0, 1.0)]),
    ("light0/intensity", [-1.0, math.nan, math.inf]),
    ("light0/color", [(-1.0, 0.5, 0.5), (math.nan, 0.0, 0.0)]),
    ("ambient", [(-0.5, -0.5, -0.5), (math.inf, 0.0, 0.0)]),
    ("mat-rod/ior", [0.0, -1.0, 0.5, math.nan]),
    ("mat-rod/shininess", [0.0, 0.5, -3.0]),
    ("mat-rod/diffuse", [-1.0, math.nan]),
    ("mat-rod/transparency", [-0.5, 1.5]),
    ("mat-rod/reflectivity", [-0.5, 1.5, math.nan]),
    ("mat-water/absorption", [(-1.0, 0.0, 0.0), (math.nan, 1.0, 1.0)]),
    ("mat-floor/checker size", [0.0, -1.0, math.nan]),
    ("mat-floor/checker color", [(-1.0, 0.0, 0.0)]),
    ("obj4/radius", [0.0, -1.0, math.nan]),
    ("obj3/min", [(1.0, 0.0, 0.0), (0.1, 3.5, -0.08), (math.nan, 0.0, 0.0)]),
    ("obj3/max", [(0.0, 3.0, 0.08), (0.26, 3.0, -1.0)]),
    ("obj1/radius", [0.06, 0.01, 0.0, -1.0]),
    ("obj1/height", [0.05, 0.0, -2.0]),
    ("obj1/wall", [1.0, 5.0, 0.0, -0.1, math.nan]),
    ("obj2/height", [0.0, -1.0]),
]


@pytest.mark.parametrize("key,values", HOSTILE, ids=[k for k, _ in HOSTILE])
def test_no_value_a_widget_gives_makes_a_scene_the_format_rejects(script, key, values):
    from viewer.window.panel import Panel

    scene = load_scene("default")
    panel = Panel(scene)
    for v in values:
        edit(script, panel, scene, **E(key, v))
        valid(scene)
    # the directional light's direction never becomes zero
    scene.lights[0].type, scene.lights[0].position, scene.lights[0].direction = "directional", None, (0.0, -1.0, 0.0)
    edit(script, panel, scene, **E("light0/direction", (0.0, 0.0, 0.0)))
    assert scene.lights[0].direction == (0.0, -1.0, 0.0)
    valid(scene)


def test_a_box_edit_that_would_cross_min_and_max_stops_and_a_wall_stays_inside(script):
    from viewer.window.panel import Panel

    scene = load_scene("default")
    panel = Panel(scene)
    box, vessel = scene.objects[3], scene.objects[1]
    assert (box.type, vessel.type, vessel.wall) == ("box", "cylinder", 0.06)
    before = (box.min, box.max)
    x1 = box.max[0]
    edit(script, panel, scene, **{"obj3/min": (x1 + 0.25, *box.min[1:])})   # x past max.x
    assert (box.min, box.max) == before
    edit(script, panel, scene, **{"obj3/min": (x1 - 0.25, *box.min[1:])})   # still below: taken
    assert box.min == (float(str(np.float32(x1 - 0.25))), *before[0][1:])
    edit(script, panel, scene, **{"obj1/radius": 0.05})                  # below the wall's 0.06
    assert vessel.radius == 1.0
    edit(script, panel, scene, **{"obj1/wall": 0.5})
    assert vessel.wall == 0.5
    edit(script, panel, scene, **{"obj1/wall (a vessel)": False})        # a solid cylinder now
    assert vessel.wall is None
    edit(script, panel, scene, **{"obj1/radius": 0.05})
    assert vessel.radius == 0.05
    edit(script, panel, scene, **{"obj1/wall (a vessel)": True})
    assert 0 < vessel.wall < min(vessel.radius, vessel.height)
    valid(scene)


def test_making_materials_transparent_keeps_at_most_32_transparent_objects(script):
    """bench-many: 43 objects, 2 transparent; ivory (13 objects), blue (12)
    and steel (7) made transparent one after the other were 34 transparent
    objects, more than the shader's 32-bit mask of media holds: a scene the
    format refuses ("Save scene" wrote a file `glassray check` rejects)."""
    from viewer.window.panel import Panel

    scene = load_scene("bench-many")
    panel = Panel(scene)
    for name in ("ivory", "blue", "steel"):
        edit(script, panel, scene, **E(f"mat-{name}/transparency", 0.5))
    n = sum(scene.is_transparent(o) for o in scene.objects)
    assert n <= MAX_TRANSPARENT_OBJECTS
    assert n == 2 + 13 + 12                      # the first two were taken, steel refused
    assert scene.materials["steel"].transparency == 0.0 and "at most 32" in panel.edit_note
    valid(scene)
    # an object given a transparent material, and a new one, are refused too
    opaque = [i for i, o in enumerate(scene.objects) if not scene.is_transparent(o)]
    for i in opaque[:MAX_TRANSPARENT_OBJECTS - n]:
        edit(script, panel, scene, **E(f"obj{i}/material", "ivory"))
    assert sum(scene.is_transparent(o) for o in scene.objects) == MAX_TRANSPARENT_OBJECTS
    nxt = next(i for i, o in enumerate(scene.objects) if not scene.is_transparent(o))
    panel.edit_note = ""
    edit(script, panel, scene, **E(f"obj{nxt}/material", "blue"))
    assert not scene.is_transparent(scene.objects[nxt]) and panel.edit_note
    valid(scene)


# ------------------------------------------------------------ float32 round trip


def test_values_left_alone_keep_their_value_and_edited_ones_are_saved_as_shown(script, tmp_path):
    """ImGui holds floats as float32: editing the x of the camera position
    gave back y = 2.200000047683716 and z = 4.599999904632568, and a min
    weight typed as 0.002 was saved as 0.0020000000949949026."""
    from viewer.window.panel import Panel

    # the premise: an untouched drag_float3 returns float32-rounded values
    imgui.new_frame()
    imgui.begin("probe")
    _, got = imgui.drag_float3("p", [3.2, 2.2, 4.6])
    imgui.end()
    imgui.render()
    assert got[1] != 2.2 and got[1] == float(np.float32(2.2))

    scene = load_scene("default")
    panel = Panel(scene)
    y, z = scene.camera.position[1:]
    edit(script, panel, scene, **{"position": (3.5, y, z)})             # the script rounds y, z as ImGui does
    assert scene.camera.position == (3.5, y, z)
    edit(script, panel, scene, **{"min weight": 0.002, "mat-water/absorption": (0.1, 0.03, 0.01)})
    assert scene.render.min_weight == 0.002
    assert scene.materials["water"].absorption == (0.1, 0.03, 0.01)
    panel.save_path = str(tmp_path / "s.toml")
    assert panel.save(scene)
    text = (tmp_path / "s.toml").read_text()
    flat = " ".join(text.split())
    assert "min_weight = 0.002 " in flat and "[camera] position = [3.5, 2.2, 4.6]" in flat, flat   # as typed, on one line


# ------------------------------------------------------------ add, remove, save


def _tiny_png(path: Path) -> None:
    from viewer.base.imageio import write_image

    img = np.zeros((8, 16, 3), np.float32)
    img[:4] = (0.2, 0.4, 0.9)                     # sky above, ground below
    img[4:] = (0.3, 0.25, 0.2)
    write_image(path, img)


def _check(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "viewer", "check", str(path)], capture_output=True, text=True,
                          timeout=120)


def test_add_and_remove_lights_and_objects_then_save_round_trips_and_checks(script, tmp_path, monkeypatch):
    from viewer.window.panel import Panel

    monkeypatch.chdir(tmp_path)
    _tiny_png(tmp_path / "sky.png")
    scene = load_scene("default")
    panel = Panel(scene)
    n_obj, n_mat = len(scene.objects), len(scene.materials)
    edit(script, panel, scene, **{"add point light": True})
    edit(script, panel, scene, **{"add directional light": True})
    assert [lt.type for lt in scene.lights] == ["point", "point", "directional"]
    edit(script, panel, scene, **{"light0/remove light": True})
    assert [lt.type for lt in scene.lights] == ["point", "directional"]
    for shape in ("sphere", "box", "cylinder", "plane"):
        edit(script, panel, scene, **{f"add {shape}": True})
    assert [o.type for o in scene.objects[n_obj:]] == ["sphere", "box", "cylinder", "plane"]
    edit(script, panel, scene, **{"obj0/remove object": True})          # the floor
    assert len(scene.objects) == n_obj + 3
    s = n_obj - 1                                                          # the new sphere
    edit(script, panel, scene, **{f"obj{s}/own material": True})
    own = scene.objects[s].material
    assert own not in ("rod", "ball") and len(scene.materials) == n_mat + 1
    edit(script, panel, scene, **{f"mat-{own}/transparency": 1.0, f"mat-{own}/ior": 1.5,
                                  f"obj{s}/radius": 0.25, f"obj{s}/center": (1.5, 0.5, 1.0)})
    edit(script, panel, scene, **{f"obj{s + 2}/wall (a vessel)": True, "mat-rod/checker": True})
    edit(script, panel, scene, **{"mat-rod/checker emission": (0.5, 0.0, 0.0)})
    edit(script, panel, scene, **{"##skyimage": "sky.png"})
    edit(script, panel, scene, **{"use image": True})
    assert scene.sky.type == "image" and scene.sky.image_path == tmp_path / "sky.png", panel.sky_note
    valid(scene)

    panel.save_path = str(tmp_path / "out" / "edited.toml")
    (tmp_path / "out").mkdir()
    assert panel.save(scene), panel.status
    back = load_scene(tmp_path / "out" / "edited.toml")
    assert back.sky.image == "../sky.png"                                  # rebased onto the folder saved into
    back.path = scene.path = None
    back.sky.image, back.sky.image_path = scene.sky.image, scene.sky.image_path
    assert back == scene
    r = _check(tmp_path / "out" / "edited.toml")
    assert r.returncode == 0, r.stderr
    assert "sky:image" in r.stdout and "3 lights" not in r.stdout and "2 lights" in r.stdout

    # everything removed: no objects, no lights (the format allows both)
    while scene.objects:
        edit(script, panel, scene, **{"obj0/remove object": True})
    while scene.lights:
        edit(script, panel, scene, **{"light0/remove light": True})
    panel.save_path = str(tmp_path / "empty.toml")
    assert panel.save(scene)
    r = _check(tmp_path / "empty.toml")
    assert r.returncode == 0 and "0 objects" in r.stdout and "0 lights" in r.stdout, r.stdout + r.stderr
    edit(script, panel, scene, **{"add sphere": True})                     # and back from nothing
    assert len(scene.objects) == 1 and not scene.is_transparent(scene.objects[0])
    valid(scene)


def test_a_sky_picture_that_cannot_be_read_is_refused_in_the_panel(script, tmp_path, monkeypatch):
    from viewer.window.panel import Panel

    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.png").write_bytes(b"not a png")
    scene = load_scene("default")
    before = scene.sky.type
    panel = Panel(scene)
    for text in ("missing.png", "bad.png", "sky.txt", ""):
        res = edit(script, panel, scene, **{"##skyimage": text})
        res = edit(script, panel, scene, **{"use image": True})
        assert not res.changed and scene.sky.type == before and panel.sky_note, text
    valid(scene)


def test_a_new_object_of_a_scene_with_no_materials_gets_one(script):
    from viewer.window.panel import Panel

    scene = scene_from_dict({"name": "empty"}, source="<empty>")
    panel = Panel(scene)
    edit(script, panel, scene, **{"add box": True})
    assert len(scene.materials) == 1 and scene.objects[0].material in scene.materials
    edit(script, panel, scene, **{"add point light": True})
    assert len(scene.lights) == 1
    valid(scene)


# ------------------------------------------------------------ specialisation


def test_value_edits_compile_nothing_feature_edits_once_and_back_reuses(script, gl):
    """Programs the renderer compiles for the scene (Renderer.set_scene, the
    one the window calls after every panel edit): 0 for an edit of values,
    1 for an edit that changes the features (a transparent object, a light
    where there was none, the sky picture), 0 for switching back."""
    from viewer.gpu.renderer import Renderer
    from viewer.window.panel import Panel

    scene = load_scene("glass-sphere")
    panel = Panel(scene)
    renderer = Renderer(gl, scene)
    renderer.cull = False
    try:
        compiles = compile_counter(script, panel, scene, renderer)
        values = [{"light0/position": (1.0, 6.0, 2.0)}, {"light0/intensity": 2.0}, {"ambient": (0.1, 0.1, 0.2)},
                  {"mat-glass/ior": 1.7}, {"mat-glass/color": (0.9, 1.0, 0.9)}, {"exposure": 1.5},
                  {"min weight": 0.01}, {"samples": 4}, {"fov": 50.0}, {"obj1/radius": 0.7},
                  {"mat-floor/checker size": 0.25}, {"mat-floor/checker": False}, {"mat-floor/checker": True},
                  {"zenith": (0.1, 0.2, 0.9)}]
        for v in values:
            assert compiles(**v) == 0, v
        # feature changes: once each, and back again from the cache
        assert len(scene.lights) == 1
        assert compiles(**{"mat-floor/reflectivity": 0.3}) == 1
        assert compiles(**{"mat-floor/reflectivity": 0.0}) == 0
        assert compiles(**{"mat-floor/reflectivity": 0.5}) == 0          # reflection: a value now
        assert compiles(**{"light0/remove light": True}) == 1            # no light: no shadows
        assert compiles(**{"add point light": True}) == 0                # a light where there was none: cached
        assert compiles(**{"add directional light": True}) == 1          # two lights
        assert compiles(**{"light1/remove light": True}) == 0
        assert compiles(**{"mat-floor/transparency": 0.5}) == 1          # the floor a medium
        assert compiles(**{"mat-floor/transparency": 0.0}) == 0
        assert compiles(**{"add sphere": True}) == 1
        assert compiles(**{"obj2/remove object": True}) == 0
    finally:
        renderer.release()


def test_the_sky_picture_switched_on_compiles_once(script, gl, tmp_path, monkeypatch):
    from viewer.gpu.renderer import Renderer
    from viewer.window.panel import Panel

    monkeypatch.chdir(tmp_path)
    _tiny_png(tmp_path / "sky.png")
    scene = load_scene("glass-sphere")
    panel = Panel(scene)
    renderer = Renderer(gl, scene)
    renderer.cull = False
    try:
        compiles = compile_counter(script, panel, scene, renderer)
        edit(script, panel, scene, **{"##skyimage": "sky.png"})
        assert compiles(**{"use image": True}) == 1
        assert compiles(**{"type": "gradient"}) == 0
        assert compiles(**{"type": "image"}) == 0
        # what the sky shows: the picture's upper half straight up (an independent route: the PNG's colour)
        up = renderer.scene.sky.image_path
        assert up == tmp_path / "sky.png"
    finally:
        renderer.release()


def test_max_depth_from_the_panel_compiles_only_past_a_stack_size(script, gl):
    # max depth is a uniform; the stack is compiled with 9, 17, 33 or 65
    # entries (gpu/defines.py stack_size): a depth within its size compiles
    # nothing, one past it compiles once, and back is cached
    from viewer.gpu.renderer import Renderer
    from viewer.window.panel import Panel

    scene = load_scene("glass-sphere")               # max depth 10: 17 entries
    panel = Panel(scene)
    renderer = Renderer(gl, scene)
    renderer.cull = False
    try:
        for depth, compiles in ((12, 0), (16, 0), (5, 1), (8, 0), (10, 0), (1, 0)):
            edit(script, panel, scene, **{"max depth": depth})
            assert scene.render.max_depth == depth
            before = renderer.programs_built
            renderer.set_scene(scene)
            assert renderer.programs_built - before == compiles, depth
    finally:
        renderer.release()


def test_max_depth_compiles_nothing_in_a_scene_without_glass(gl):
    from viewer.gpu.renderer import Renderer
    from viewer.scene.load import with_overrides

    scene = load_scene("bench-opaque")
    renderer = Renderer(gl, scene)
    renderer.cull = False
    try:
        before = renderer.programs_built
        for depth in (1, 8, 30, 64):
            renderer.set_scene(with_overrides(scene, max_depth=depth))
        assert renderer.programs_built == before
    finally:
        renderer.release()


# ------------------------------------------------------------ the edits reach the picture


def test_edits_reach_the_renderer_as_the_reference_tracer_sees_them(script, render):
    """After adding a glass sphere with its own material and a second light,
    the GPU image equals the float64 reference tracer's image of the scene
    the panel made (so every edit reached the uniform block and defines)."""
    from viewer.reference import trace as reference
    from viewer.base.imageio import to_display8
    from viewer.window.panel import Panel

    scene = load_scene("glass-sphere")
    panel = Panel(scene)
    edit(script, panel, scene, **{"add sphere": True, "add directional light": True})
    s = len(scene.objects) - 1
    edit(script, panel, scene, **{f"obj{s}/own material": True})
    own = scene.objects[s].material
    edit(script, panel, scene, **{f"mat-{own}/color": (0.9, 0.2, 0.1), f"obj{s}/center": (-1.2, 0.4, 0.8),
                                  f"obj{s}/radius": 0.4, "light1/intensity": 0.6})
    valid(scene)
    w, h = 64, 36
    img = render(scene, w, h, samples=1)
    ref = reference.render_reference(scene, w, h, samples=1)
    assert np.isfinite(img).all()
    a8, b8 = to_display8(img * scene.render.exposure), to_display8(ref * scene.render.exposure)
    off = np.mean(np.abs(a8.astype(int) - b8.astype(int)).max(axis=-1) > 1)
    assert off < 0.01, off
    # and the new red sphere is in the picture: the reference has red pixels
    red = (b8[..., 0].astype(int) - b8[..., 1]) > 60
    assert red.sum() > 10


def test_every_section_draws_for_every_shape(script):
    """The objects section draws each shape's widgets, also a scene with
    none (nothing raises, nothing changes)."""
    import copy

    from viewer.window.panel import Panel

    for name in ("default", "bench-many"):
        scene = load_scene(name)
        before = copy.deepcopy(scene)
        panel = Panel(scene)
        res = edit(script, panel, scene)
        assert not res.changed and scene == before
    for key in ("obj0/height", "obj1/base", "obj1/wall", "obj1/axis", "obj3/rotate", "obj4/center"):
        assert key in script.seen, key
    with pytest.raises(SceneError):             # (the helper sees a bad scene)
        scene.objects[0].material = "nothing"
        valid(scene)


# ------------------------------------------------------------ refused edits are said (audit, 2026-12-04)


@pytest.mark.parametrize("scene_name, key, value, says", [
    ("default", "obj3/min", (1.0, -0.1, -0.1), "box rod: not taken: min must stay below max"),
    ("default", "obj1/wall", 5.0, "cylinder glass: wall not taken: it must stay thinner than the radius"),
    ("default", "obj1/radius", 0.01, "cylinder glass: radius not taken: it must stay above the wall (0.06)"),
    ("default", "position", (0.0, 5.0, 0.9), "camera not moved: camera.target: the view direction is"),
    ("mirror-ball", "light0/direction", (0.0, 0.0, 0.0), "direction cannot be zero"),
])
def test_a_refused_edit_says_why_in_the_panel(script, scene_name, key, value, says):
    # the README promised "not taken, with a note in the panel"; only the
    # limit of 32 transparent objects had one (the viewer audit)
    import copy

    from viewer.window.panel import Panel

    scene = load_scene(scene_name)
    if key == "position":             # the value is straight above this target: a view straight down
        scene.camera.target = (0.0, 0.9, 0.9)
    before = copy.deepcopy(scene)
    panel = Panel(scene)
    edit(script, panel, scene, **E(key, value))
    assert says in panel.edit_note, panel.edit_note
    assert scene == before                         # not taken
    valid(scene)


def test_a_material_made_transparent_says_its_reflectivity_goes_and_gets_it_back(script):
    from viewer.window.panel import Panel

    scene = load_scene("default")
    panel = Panel(scene)
    ball = scene.materials["ball"]
    assert ball.reflectivity == 0.25 and ball.transparency == 0.0
    edit(script, panel, scene, **E("mat-ball/transparency", 0.5))
    assert ball.transparency == 0.5 and ball.reflectivity == 0.0
    assert "ball: reflectivity 0.25 set to 0 while it is transparent" in panel.edit_note
    valid(scene)
    edit(script, panel, scene, **E("mat-ball/transparency", 0.0))
    assert ball.transparency == 0.0 and ball.reflectivity == 0.25
