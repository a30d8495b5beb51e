"""Picking and moving objects without a window (viewer/window/pick.py and
the click / move parts of Controls), against geometry worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from viewer.api import load_scene
from viewer.window.controls import Controls
from viewer.window.pick import anchor, floor_axes, next_pick, objects_along, translate
from viewer.scene.model import SceneObject

# A camera on +z looking down -z at a sphere of radius 1 at the origin, with a
# box behind it and a floor below: the centre pixel's ray meets the sphere at
# t = 9 (eye at z = 10), then the box (front face z = -3: t = 13).
SCENE = """
[camera]
position = [0, 0, 10]
target = [0, 0, 0]
fov = 30
[materials.glass]
color = [1, 1, 1]
transparency = 1
ior = 1.5
[materials.grey]
color = [0.5, 0.5, 0.5]
[[objects]]
type = "plane"
height = -2
material = "grey"
[[objects]]
type = "sphere"
center = [0, 0, 0]
radius = 1
material = "glass"
[[objects]]
type = "box"
min = [-2, -1, -5]
max = [2, 1, -3]
material = "grey"
"""


def test_objects_along_the_centre_ray_come_nearest_first():
    scene = load_scene(SCENE)
    assert objects_along(scene, 41, 41, 20, 20) == [1, 2]     # sphere at t = 9, box at t = 13
    # a ray down the top-left corner misses the sphere and the box, and
    # meets the floor below the horizon only in the bottom rows
    assert objects_along(scene, 41, 41, 0, 0) == []
    bottom = objects_along(scene, 41, 41, 20, 40)
    assert bottom[-1] == 0 and 1 not in bottom


def test_a_click_again_walks_along_the_ray_and_wraps():
    along = [1, 2, 0]
    assert next_pick(1, along, None, again=False) == 1
    assert next_pick(1, along, 1, again=True) == 2
    assert next_pick(1, along, 2, again=True) == 0
    assert next_pick(1, along, 0, again=True) == 1            # after the last, the nearest again
    assert next_pick(1, along, 2, again=False) == 1           # another spot: its first hit
    assert next_pick(-1, along, 2, again=True) is None        # the sky selects nothing


@pytest.mark.parametrize("obj, keys", [
    (SceneObject("sphere", "m", center=(1, 2, 3), radius=1), {"center": (1.5, 1.0, 3.25)}),
    (SceneObject("box", "m", min=(0, 0, 0), max=(1, 2, 3), rotate=(0, 30, 0)),
     {"min": (0.5, -1.0, 0.25), "max": (1.5, 1.0, 3.25), "rotate": (0, 30, 0)}),
    (SceneObject("cylinder", "m", base=(0, 0, 0), radius=0.5, height=2, wall=0.1),
     {"base": (0.5, -1.0, 0.25), "radius": 0.5, "height": 2, "wall": 0.1}),
    (SceneObject("plane", "m", height=0.5), {"height": -0.5}),
])
def test_a_move_changes_the_position_only(obj, keys):
    before = anchor(obj)
    assert translate(obj, (0.5, -1.0, 0.25))
    for k, v in keys.items():
        assert getattr(obj, k) == v
    moved = anchor(obj) - before
    assert np.allclose(moved, (0.0, -1.0, 0.0) if obj.type == "plane" else (0.5, -1.0, 0.25))
    assert not translate(obj, (0, 0, 0))                      # no change is no edit
    assert not translate(obj, (math.inf, 0, 0)) and getattr(obj, next(iter(keys))) == keys[next(iter(keys))]


def test_the_floor_axes_lie_flat_and_follow_the_view():
    right, ahead = floor_axes((0.0, -0.6, -0.8))               # looking down -z, tilted down
    assert np.allclose(ahead, (0, 0, -1)) and np.allclose(right, (1, 0, 0))
    right, ahead = floor_axes((0.0, -1.0, 0.0))                # straight down: -z ahead
    assert np.allclose(ahead, (0, 0, -1)) and np.allclose(right, (1, 0, 0))
    right, ahead = floor_axes((1.0, 0.0, 0.0))                 # looking down +x: right is +z
    assert np.allclose(right, (0, 0, 1))


def test_a_click_is_a_pick_and_a_drag_past_four_pixels_orbits():
    scene = load_scene(SCENE)
    c = Controls(scene, (200, 100))
    c.take_changed()
    c.press("left", 50, 50)
    c.move(52, 51)                                            # a hand's jitter: no orbit
    c.release("left", 52, 51)
    assert c.pick_request == (50.0, 50.0) and not c.take_changed()
    c.pick_request = None
    c.press("left", 50, 50)
    c.move(60, 50)
    c.release("left", 60, 50)
    assert c.pick_request is None and c.take_changed()


def test_keys_and_a_ctrl_drag_move_the_selected_object_only():
    scene = load_scene(SCENE)
    c = Controls(scene, (200, 100))
    assert c.key("right") is None and c.take_move() is None    # nothing selected: nothing moves
    assert "select" in c.message
    c.selected = 1
    c.key("right")
    assert np.allclose(c.take_move(), (c.light_step, 0, 0))  # the camera looks down -z: right is +x
    c.key("pageup", shift=True)
    assert np.allclose(c.take_move(), (0, 5 * c.light_step, 0))
    # ctrl+drag: the sphere's centre (at the target, 10 away) follows the
    # cursor: 10 pixels of a 100-pixel-high view of 30 degrees
    c.press("left", 100, 50, ctrl=True)
    c.move(110, 40)
    c.release("left", 110, 40)
    per_px = 2 * 10 * math.tan(math.radians(15)) / 100
    assert np.allclose(c.take_move(), (10 * per_px, 10 * per_px, 0))
    assert c.key("escape") == "deselect"
    c.selected = None
    assert c.key("escape") == "quit"


def test_a_click_on_the_open_panel_is_not_a_pick():
    """Moved onto the panel and clicked within one frame, ImGui had not yet
    claimed the mouse: the click went to the view behind the panel too
    (the fast-typing test in test_viewer_e2e.py printed "nothing selected")."""
    from types import SimpleNamespace

    pytest.importorskip("glfw")
    from viewer.window.app import Viewer
    from viewer.window.events import InputEvents

    v = SimpleNamespace(show_panel=True, panel=SimpleNamespace(rect=(256.0, 8.0, 472.0, 262.0)),
                        show_help=False, _help_rect=None)
    v._ui_rects = lambda: Viewer._ui_rects(v)
    on_ui = lambda at: InputEvents._on_ui(v, at)            # noqa: E731  (what _take_pick asks)
    assert on_ui((300, 62))
    assert not on_ui((115, 150))                            # the ball, left of the panel
    assert not on_ui((472, 62))                             # the panel's right edge is outside
    v.show_help, v._help_rect = True, (100.0, 100.0, 200.0, 200.0)
    assert on_ui((115, 150))                                # the help over the ball: its click
    v.show_panel, v.show_help = False, False                # hidden: their last rects mean nothing
    assert not on_ui((300, 62)) and not on_ui((115, 150))


def test_a_press_outside_imgui_s_windows_is_the_view_s_even_when_imgui_last_saw_the_panel():
    """ImGui's want_capture_mouse is from its last frame: moved off the panel
    and pressed before the next one, the press was taken as the panel's.
    Outside the panel and the help it is the view's, unless a widget is
    held or a popup is open."""
    from types import SimpleNamespace

    pytest.importorskip("glfw")
    from viewer.window.events import InputEvents

    state = {"active": False, "popup": False}
    imgui = SimpleNamespace(get_io=lambda: SimpleNamespace(want_capture_mouse=True),
                            is_any_item_active=lambda: state["active"],
                            is_popup_open=lambda name, flags: state["popup"],
                            PopupFlags_=SimpleNamespace(any_popup_id=1, any_popup_level=2))
    v = SimpleNamespace(_imgui_ready=True, imgui=imgui,
                        _ui_rects=lambda: [(256.0, 8.0, 472.0, 262.0)])
    v._on_ui = lambda at: InputEvents._on_ui(v, at)
    wants = lambda at: InputEvents._ui_wants_mouse(v, at)          # noqa: E731
    assert wants((300, 62)) and not wants((115, 150))
    state["active"] = True                 # a slider dragged out of the panel keeps the mouse
    assert wants((115, 150))
    state["active"], state["popup"] = False, True
    assert wants((115, 150))
    state["popup"] = False
    assert InputEvents._ui_wants_mouse(v) is True                   # no point given: ImGui's word
    v._imgui_ready = False
    assert not wants((300, 62))
