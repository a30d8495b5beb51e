"""The viewer's input handling without a window: viewer.controls drives
viewer.camera and the scene's light; drags, scrolls and keys are checked
against the numbers they must produce, with the clamps and the reset."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from viewer.window.camera import MAX_DISTANCE, MIN_DISTANCE, PITCH_LIMIT_DEG, OrbitCamera
from viewer.window.controls import EXTRA_HELP, HELP, HELP_ALL, VIEWS, LIGHT_FAST, LIGHT_STEP_FRACTION, ORBIT_RADIANS_PER_HEIGHT, ZOOM_PER_NOTCH, Controls, merge_reloaded
from viewer.scene.load import load_scene, validate_camera

from conftest import make_scene

ROOT = Path(__file__).resolve().parents[2]
W, H = 800, 400


def scene_doc(**camera):
    cam = {"position": [0.0, 1.0, 5.0], "target": [0.0, 1.0, 0.0], "fov": 40}
    cam.update(camera)
    return {
        "camera": cam,
        "render": {"max_depth": 8},
        "lights": [{"type": "directional", "direction": [0, -1, 0]},
                   {"type": "point", "position": [1.0, 4.0, 2.0]}],
        "materials": {"m": {}},
        "objects": [{"type": "plane", "material": "m"}, {"type": "sphere", "center": [0, 1, 0], "radius": 1,
                                                          "material": "m"}],
    }


@pytest.fixture
def ctl():
    return Controls(make_scene(scene_doc()), (W, H))


def drag(c: Controls, button: str, start, end, shift=False, steps=4):
    c.press(button, *start, shift=shift)
    for k in range(1, steps + 1):
        c.move(start[0] + (end[0] - start[0]) * k / steps, start[1] + (end[1] - start[1]) * k / steps)
    c.release(button, *end)


def assert_camera_ok(c: Controls):
    cam = c.scene.camera
    assert all(math.isfinite(v) for v in (*cam.position, *cam.target, cam.fov))
    validate_camera(cam)  # position != target and not straight up or down
    assert c.camera.is_valid()
    assert np.allclose(cam.position, c.camera.position) and np.allclose(cam.target, c.camera.target)


# ---------------------------------------------------------------- camera basics


def test_orbit_camera_reproduces_a_scene_camera():
    cam = OrbitCamera.look_at((3.2, 2.2, 4.6), (0.0, 0.9, 0.0), 40)
    assert np.allclose(cam.position, (3.2, 2.2, 4.6), atol=1e-12)
    f = np.subtract((0.0, 0.9, 0.0), (3.2, 2.2, 4.6))
    assert np.allclose(cam.forward, f / np.linalg.norm(f))
    assert np.allclose(np.cross(cam.forward, (0, 1, 0)) / np.linalg.norm(np.cross(cam.forward, (0, 1, 0))),
                       cam.right)


def test_pyrr_matrices_put_the_target_in_the_middle():
    cam = OrbitCamera.look_at((3.0, 2.0, 4.0), (0.5, 1.0, -0.5), 50)
    v = np.append(np.array(cam.target), 1.0) @ cam.view_matrix()
    assert np.allclose(v[:3], (0.0, 0.0, -cam.distance))
    clip = v @ cam.projection_matrix(16 / 9)
    assert np.allclose(clip[:2] / clip[3], (0.0, 0.0), atol=1e-12)
    # a point one unit along the right vector lands on the right of the picture
    p = np.append(np.array(cam.target) + cam.right, 1.0) @ cam.view_matrix() @ cam.projection_matrix(16 / 9)
    assert p[0] / p[3] > 0


# ---------------------------------------------------------------- mouse


def test_left_drag_right_orbits_the_eye_to_the_left(ctl):
    before = ctl.camera.copy()
    drag(ctl, "left", (100, 200), (180, 200))
    expected = -80 * ORBIT_RADIANS_PER_HEIGHT / H
    assert ctl.camera.yaw == pytest.approx(before.yaw + expected)
    assert ctl.camera.pitch == pytest.approx(before.pitch)
    assert ctl.camera.distance == pytest.approx(before.distance)
    assert ctl.camera.target == before.target
    # the eye went left: against the old right vector
    moved = np.subtract(ctl.scene.camera.position, before.position)
    assert np.dot(moved, before.right) < 0
    assert ctl.take_changed() and not ctl.take_changed()
    assert_camera_ok(ctl)


def test_left_drag_down_lifts_the_eye(ctl):
    y0 = ctl.scene.camera.position[1]
    drag(ctl, "left", (100, 100), (100, 140))
    assert ctl.camera.pitch == pytest.approx(40 * ORBIT_RADIANS_PER_HEIGHT / H)
    assert ctl.scene.camera.position[1] > y0
    assert_camera_ok(ctl)


def test_pitch_is_clamped_short_of_the_poles(ctl):
    drag(ctl, "left", (0, 0), (0, 100000))
    assert ctl.camera.pitch == pytest.approx(math.radians(PITCH_LIMIT_DEG))
    assert_camera_ok(ctl)
    drag(ctl, "left", (0, 100000), (0, -100000))
    assert ctl.camera.pitch == pytest.approx(-math.radians(PITCH_LIMIT_DEG))
    assert_camera_ok(ctl)


def test_a_steep_starting_camera_is_kept_and_only_moves_back():
    doc = scene_doc(position=[0.0, 10.0, 0.01], target=[0.0, 0.0, 0.0])
    c = Controls(make_scene(doc), (W, H))
    p0 = c.camera.pitch
    assert p0 > math.radians(PITCH_LIMIT_DEG)
    assert np.allclose(c.scene.camera.position, (0.0, 10.0, 0.01))
    c.orbit_pixels(0, 10)  # further up: refused, stays where it is
    assert c.camera.pitch == pytest.approx(p0)
    c.orbit_pixels(0, -10)
    assert c.camera.pitch < p0
    assert_camera_ok(c)


@pytest.mark.parametrize("button,shift", [("right", False), ("left", True), ("middle", False)])
def test_pan_moves_the_target_with_the_cursor(ctl, button, shift):
    before = ctl.camera.copy()
    drag(ctl, button, (400, 200), (440, 180), shift=shift)
    s = before.world_per_pixel(H)
    # mouse right and up: the scene follows it, so the target goes left and down
    expected = np.array(before.target) - 40 * s * before.right - 20 * s * before.up
    assert np.allclose(ctl.camera.target, expected)
    assert ctl.camera.distance == pytest.approx(before.distance)
    assert ctl.camera.yaw == pytest.approx(before.yaw) and ctl.camera.pitch == pytest.approx(before.pitch)
    # the eye moved by the same vector as the target
    assert np.allclose(np.subtract(ctl.scene.camera.position, before.position),
                       np.subtract(ctl.camera.target, before.target))
    assert_camera_ok(ctl)


def test_moves_without_a_button_and_other_buttons_do_nothing(ctl):
    ctl.take_changed()
    ctl.move(10, 10)
    ctl.press("button4", 10, 10)
    ctl.move(50, 50)
    ctl.release("button4", 50, 50)
    assert not ctl.take_changed()


def test_scroll_zooms_toward_the_target_and_never_passes_it(ctl):
    d0 = ctl.camera.distance
    ctl.scroll(0, 1)
    assert ctl.camera.distance == pytest.approx(d0 * ZOOM_PER_NOTCH)
    ctl.scroll(0, -2)
    assert ctl.camera.distance == pytest.approx(d0 / ZOOM_PER_NOTCH)
    for _ in range(200):
        ctl.scroll(0, 100)
    assert MIN_DISTANCE <= ctl.camera.distance < 1e-2
    assert_camera_ok(ctl)
    f = np.subtract(ctl.scene.camera.target, ctl.scene.camera.position)
    assert np.dot(f, ctl.camera.forward) > 0  # still in front of the target, not past it
    for _ in range(500):
        ctl.scroll(0, -100)
    assert ctl.camera.distance == MAX_DISTANCE
    assert_camera_ok(ctl)


def test_non_finite_input_is_ignored(ctl):
    before = ctl.camera.copy()
    ctl.scroll(0, float("nan"))
    ctl.scroll(0, float("inf"))
    ctl.press("left", 0, 0)
    ctl.move(float("nan"), 3)
    ctl.move(float("inf"), float("-inf"))
    ctl.release("left")
    ctl.camera.orbit(float("nan"), 0.0)
    ctl.camera.pan(float("inf"), 0.0)
    ctl.camera.dolly(0.0)
    ctl.camera.dolly(float("nan"))
    assert ctl.camera == before
    assert_camera_ok(ctl)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["orbit", "pan", "scroll", "key"]),
                          st.floats(-1e6, 1e6), st.floats(-1e6, 1e6),
                          st.sampled_from(list("wsadqe") + ["1", "9", "r"])), max_size=40))
def test_no_sequence_of_inputs_breaks_the_camera(ops):
    c = Controls(make_scene(scene_doc()), (W, H))
    for op, a, b, k in ops:
        if op == "orbit":
            c.orbit_pixels(a, b)
        elif op == "pan":
            c.pan_pixels(a, b)
        elif op == "scroll":
            c.scroll(0, a / 1e4)
        else:
            c.key(k, shift=a > 0)
        assert_camera_ok(c)
        assert all(math.isfinite(v) for v in c.scene.lights[1].position)


# ---------------------------------------------------------------- keys


@pytest.mark.parametrize("key,axis,sign", [("w", 2, -1), ("s", 2, 1), ("a", 0, -1), ("d", 0, 1),
                                           ("q", 1, -1), ("e", 1, 1)])
def test_light_keys_move_the_first_point_light(ctl, key, axis, sign):
    step = LIGHT_STEP_FRACTION * 5.0  # the starting camera is 5 units from its target
    assert ctl.light_step == pytest.approx(step)
    p0 = np.array(ctl.scene.lights[1].position)
    assert ctl.key(key) is None
    p1 = np.array(ctl.scene.lights[1].position)
    d = np.zeros(3)
    d[axis] = sign * step
    assert np.allclose(p1 - p0, d)
    ctl.key(key, shift=True)
    d[axis] = sign * step * (1 + LIGHT_FAST)
    assert np.allclose(np.array(ctl.scene.lights[1].position) - p0, d)
    ctl.key(key.upper(), repeat=True)  # held down: keeps moving
    assert not np.allclose(np.array(ctl.scene.lights[1].position) - p0, d)
    assert ctl.scene.lights[0].direction == (0, -1, 0)  # the directional light stays
    assert ctl.take_changed()


def test_light_keys_without_a_point_light_say_so():
    doc = scene_doc()
    doc["lights"] = [{"type": "directional", "direction": [0, -1, 0]}]
    c = Controls(make_scene(doc), (W, H))
    c.take_changed()
    c.key("w")
    assert not c.take_changed()
    assert "no point light" in c.message


def test_depth_keys(ctl):
    for n in range(1, 10):
        ctl.take_changed()
        assert ctl.key(str(n)) is None
        assert ctl.scene.render.max_depth == n
        assert ctl.take_changed()  # each differs from the one before (8 at the start)
    ctl.take_changed()
    ctl.key("9")
    assert not ctl.take_changed()
    ctl.key("3", repeat=True)  # auto-repeat of a depth key does nothing
    assert ctl.scene.render.max_depth == 9


def test_window_actions(ctl):
    expected = {"p": "screenshot", "f12": "screenshot_window", "tab": "toggle_panel", "f5": "reload",
                "h": "help", "f1": "help", "escape": "quit"}
    for key, action in expected.items():
        assert ctl.key(key) == action
        assert ctl.key(key, repeat=True) is None  # a held P takes one screenshot
    assert ctl.key("x") is None


def test_v_cycles_the_view_and_shift_v_goes_back(ctl):
    assert ctl.view == "image" and VIEWS == ("image", "cost", "normals", "depth", "objects")
    seen = []
    for _ in range(len(VIEWS)):
        assert ctl.key("v") == "view"
        seen.append(ctl.view)
    assert seen == ["cost", "normals", "depth", "objects", "image"]
    assert ctl.key("V", shift=True) == "view" and ctl.view == "objects"
    assert ctl.key("v", repeat=True) is None and ctl.view == "objects"  # a held V does not spin
    ctl.take_changed()
    ctl.key("v")  # the view is not a scene change ...
    assert not ctl.take_changed()  # ... so nothing is traced again for it
    ctl.set_view("cost")
    assert ctl.view == "cost"
    with pytest.raises(ValueError):
        ctl.set_view("colour")
    # V is none of the spec's keys
    spec_keys = " ".join(k for k, _ in HELP)
    assert not re.search(r"\bV\b", spec_keys)
    assert [k for k, _ in EXTRA_HELP][0] == "V (shift+V: back)"


def test_reset_returns_to_the_starting_camera_and_light(ctl):
    start_cam = (ctl.scene.camera.position, ctl.scene.camera.target, ctl.scene.camera.fov)
    start_light = ctl.scene.lights[1].position
    drag(ctl, "left", (0, 0), (123, 45))
    drag(ctl, "right", (0, 0), (-30, 70))
    ctl.scroll(0, 3)
    ctl.key("d")
    ctl.key("q", shift=True)
    assert ctl.scene.camera.position != start_cam[0] and ctl.scene.lights[1].position != start_light
    ctl.take_changed()
    assert ctl.key("r") is None
    assert (ctl.scene.camera.position, ctl.scene.camera.target, ctl.scene.camera.fov) == start_cam
    assert ctl.scene.lights[1].position == start_light
    assert ctl.take_changed()
    assert np.allclose(ctl.camera.position, start_cam[0])
    # after a reset, the controls work as before
    drag(ctl, "left", (0, 0), (10, 0))
    assert_camera_ok(ctl)


def test_reset_uses_the_command_line_overrides():
    from viewer.scene.load import with_overrides

    s = with_overrides(make_scene(scene_doc()), camera_position=(4.0, 3.0, 2.0), light_position=(0.0, 9.0, 0.0))
    c = Controls(s, (W, H))
    c.orbit_pixels(50, 20)
    c.key("e")
    c.reset()
    assert s.camera.position == (4.0, 3.0, 2.0) and s.lights[1].position == (0.0, 9.0, 0.0)


def test_panel_camera_edits_are_followed(ctl):
    ctl.scene.camera.position = (5.0, 1.0, 0.0)
    ctl.camera_edited()
    assert np.allclose(ctl.camera.position, (5.0, 1.0, 0.0))
    ctl.orbit_pixels(10, 0)
    assert_camera_ok(ctl)


# ---------------------------------------------------------------- reload, help, screenshots


def test_a_camera_edit_keeps_the_values_not_touched_exactly(ctl):
    # the panel sets scene.camera and calls camera_edited(); the orbit camera
    # rebuilt from it gave position 4.6000000000000005 back for 4.6
    ctl.scene.camera.position, ctl.scene.camera.target = (3.2, 2.2, 4.6), (0.0, 0.9, 0.0)
    ctl.camera_edited()
    ctl.scene.camera.fov = 30.0                # only fov edited
    ctl.camera_edited()
    assert ctl.scene.camera.position == (3.2, 2.2, 4.6)
    assert ctl.scene.camera.target == (0.0, 0.9, 0.0) and ctl.camera.fov == 30.0
    ctl.scene.camera.target = (0.0, 1.5, 0.0)  # only the target edited
    ctl.camera_edited()
    assert ctl.scene.camera.position == (3.2, 2.2, 4.6)
    assert np.allclose(ctl.camera.position, (3.2, 2.2, 4.6), rtol=1e-12)   # the orbit camera follows
    ctl.scene.camera.target = (3.2, 2.2, 4.6)  # position == target: not taken, put back
    ctl.camera_edited()
    assert ctl.scene.camera.target != ctl.scene.camera.position


def test_reload_takes_what_changed_on_disk_and_keeps_the_rest(ctl):
    import copy

    old_file = copy.deepcopy(ctl.scene)
    ctl.orbit_pixels(40, 0)  # the user moved the camera ...
    ctl.key("d")  # ... and the light
    ctl.scene.materials["m"].color = (0.1, 0.2, 0.3)  # and edited a colour in the panel
    new_file = copy.deepcopy(old_file)
    new_file.render.max_depth = 3  # the file changed its render settings only
    merged = merge_reloaded(old_file, new_file, ctl.scene)
    assert merged.render.max_depth == 3
    assert merged.camera == ctl.scene.camera and merged.lights == ctl.scene.lights
    assert merged.materials["m"].color == (0.1, 0.2, 0.3)
    new_file.camera.fov = 60  # now the file's camera changed too: it wins
    merged = merge_reloaded(old_file, new_file, ctl.scene)
    assert merged.camera == new_file.camera
    assert merged is not ctl.scene and merged.camera is not new_file.camera


def _table_rows(md: str, after: str) -> list[tuple[str, str]]:
    text = md[md.index(after):]
    rows = []
    for line in text.splitlines()[1:]:
        if not line.startswith("|"):
            if rows:
                break
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0] in ("input", "---") or set(cells[0]) <= {"-"}:
            continue
        rows.append((cells[0], cells[1]))
    return rows


def test_help_and_readme_show_the_controls_of_the_spec():
    def norm(rows):
        return [(re.sub(r"\s+", " ", k), re.sub(r"\s+", " ", v)) for k, v in rows]

    spec = norm(_table_rows((ROOT / "docs" / "cli.md").read_text(encoding="utf-8"), "Controls"))
    assert len(spec) == 12
    assert norm(HELP) == spec
    assert HELP_ALL == HELP + EXTRA_HELP  # the help overlay: the spec's table, then the viewer's own keys
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert norm(_table_rows(readme, "## Viewer")) in (spec, norm(HELP_ALL))


def test_screenshot_names_count_up(tmp_path):
    from viewer.window.screenshot import save_linear, screenshot_path

    when = 1_700_000_000.0
    img = np.full((2, 3, 3), 0.5, np.float32)
    p1 = save_linear(img, tmp_path, when)
    p2 = save_linear(img, tmp_path, when)
    p3 = save_linear(img, tmp_path, when)
    assert re.fullmatch(r"glassray-\d{8}-\d{6}\.png", p1.name)
    assert p2.name == p1.name[:-4] + "-2.png" and p3.name == p1.name[:-4] + "-3.png"
    assert screenshot_path(tmp_path, when).name == p1.name[:-4] + "-4.png"
    from PIL import Image

    with Image.open(p1) as im:
        assert im.size == (3, 2) and im.getpixel((0, 0)) == (188, 188, 188)  # sRGB of 0.5


def test_screenshot_into_a_missing_folder_raises_oserror(tmp_path):
    from viewer.window.screenshot import save_linear

    with pytest.raises(OSError):
        save_linear(np.zeros((2, 2, 3), np.float32), tmp_path / "gone")


def test_default_scene_loads_into_controls():
    s = load_scene(None)
    c = Controls(s, (1280, 720))
    assert np.allclose(c.camera.position, s.camera.position)
    assert_camera_ok(c)


def test_the_hud_says_idle_once_every_sample_is_in():
    # the viewer draws nothing more then: "303.7 ms  22 fps" stayed on screen,
    # stale, long after (the viewer audit)
    from types import SimpleNamespace

    pytest.importorskip("glfw")
    from viewer.window.app import Viewer

    v = object.__new__(Viewer)           # _hud_lines reads only these
    v.panel, v.frame_ms, v.fps, v.work_ms = None, 303.7, 3.0, 310.2
    v.max_error, v.live = SimpleNamespace(on=False, status=""), SimpleNamespace(error="")
    v.scene = SimpleNamespace(render=SimpleNamespace(max_depth=8))
    v.controls = SimpleNamespace(view="image", selected=None)
    v.prog = SimpleNamespace(active_resolution=(320, 180), size=(320, 180), samples=16, passes_done=7,
                             adaptive=False, done=False)
    # rate and time of the same window, labelled (not the last frame's
    # work next to a 0.5 s average: "35.4 ms 38 fps" read as a contradiction)
    assert v._hud_lines()[0] == "3 fps, 310.2 ms a frame"
    v.prog.passes_done, v.prog.done = 16, True
    lines = v._hud_lines()
    assert lines[0] == "idle (last frame 303.7 ms)" and lines[2] == "samples 16/16"
