"""Undo and redo of the panel's edits: the history alone (window/history.py,
pure), the keys (controls), and a real Viewer under Xvfb, where Ctrl+Z
through GLFW's key callback gives back the picture bit for bit."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path


from viewer.scene.load import load_scene
from viewer.window.controls import Controls
from viewer.window.history import EditHistory

ROOT = Path(__file__).resolve().parents[2]


def edit(h: EditHistory, scene, change, frames_held: int = 2):
    """One edit as the panel makes it: a widget held for some frames, each
    changing the scene, then released."""
    h.at_rest(scene)
    for _ in range(frames_held):
        change(scene)
        h.after_panel(scene, changed=True, active=True)
        h.at_rest(scene)
    return h.after_panel(scene, changed=False, active=False)


def test_an_edit_is_what_changed_between_two_moments_of_rest():
    scene = load_scene("default")
    h = EditHistory()
    original = copy.deepcopy(scene)
    e = edit(h, scene, lambda s: setattr(s.materials["rod"], "color", (0.1, 0.9, 0.1)))
    assert e is not None and e.parts == ["materials"]
    assert e.before["materials"] == original.materials and len(h.undo_stack) == 1
    # a camera move afterwards is no part of it: undo keeps it
    scene.camera.fov = 25.0
    assert h.undo(scene).parts == ["materials"]
    assert scene.materials == original.materials and scene.camera.fov == 25.0
    assert h.redo(scene) is not None and scene.materials["rod"].color == (0.1, 0.9, 0.1)
    assert h.redo(scene) is None                       # nothing more to redo


def test_a_new_edit_clears_redo_and_a_change_undone_by_hand_is_no_edit():
    scene = load_scene("default")
    h = EditHistory()
    edit(h, scene, lambda s: setattr(s.render, "samples", 4))
    h.undo(scene)
    assert h.redo_stack
    edit(h, scene, lambda s: setattr(s.render, "max_depth", 3))
    assert not h.redo_stack
    fov = scene.camera.fov
    assert edit(h, scene, lambda s: setattr(s.camera, "fov", fov), frames_held=1) is None


def test_undo_waits_while_a_widget_is_held_and_the_history_is_bounded():
    scene = load_scene("default")
    h = EditHistory(limit=3)
    for k in range(5):
        edit(h, scene, lambda s, k=k: setattr(s.render, "samples", k + 2))
    assert len(h.undo_stack) == 3
    h.at_rest(scene)
    scene.render.samples = 99
    h.after_panel(scene, changed=True, active=True)
    assert h.undo(scene) is None and scene.render.samples == 99    # mid-drag: not now
    h.clear()
    assert h.undo(scene) is None


def test_ctrl_z_and_ctrl_y_are_undo_and_redo_and_ctrl_keeps_the_light_keys_quiet():
    c = Controls(load_scene("default"), (320, 180))
    assert c.key("z", ctrl=True) == "undo"
    assert c.key("z", shift=True, ctrl=True) == "redo" and c.key("y", ctrl=True) == "redo"
    light = c.scene.lights[0].position
    assert c.key("w", ctrl=True) is None and c.scene.lights[0].position == light
    assert c.key("z") is None                                    # plain Z does nothing
    # Ctrl+S saves; S alone still moves the light (+z)
    assert c.key("s", ctrl=True) == "save_scene" and c.scene.lights[0].position == light
    assert c.key("s") is None and c.scene.lights[0].position[2] > light[2]


SCRIPT = """
import json, sys, time
import glfw
import numpy as np
from viewer.cli.commands import build_parser, _load
from viewer.window import app

args = build_parser().parse_args(["view", sys.argv[1], "--size", "64x36", "--no-vsync", "--no-watch"])
v = app.Viewer(args, _load(args), _load)

def picture():
    # every sample in (the loop starts accumulating once the view has been
    # still for SETTLE_S: frames before that are previews)
    deadline = time.monotonic() + 120
    v._frame()
    while not v.prog.done and time.monotonic() < deadline:
        time.sleep(0.01)
        v._frame()
    assert v.prog.done
    return v.prog.image().copy()

out = {}
try:
    before = picture()
    # a panel edit, as _ui_new_frame records it
    v.history.at_rest(v.scene)
    v.scene.materials["rod"].color = (0.1, 0.9, 0.1)
    v.history.after_panel(v.scene, changed=True, active=False)
    v.history.after_panel(v.scene, changed=False, active=False)
    v.controls.changed = True
    edited = picture()
    v._on_key(v.window, glfw.KEY_Z, 0, glfw.PRESS, glfw.MOD_CONTROL)      # GLFW's callback, its arguments
    v._on_key(v.window, glfw.KEY_Z, 0, glfw.RELEASE, glfw.MOD_CONTROL)
    undone = picture()
    v._on_key(v.window, glfw.KEY_Y, 0, glfw.PRESS, glfw.MOD_CONTROL)
    redone = picture()
    out = {"edit_changed": not np.array_equal(edited, before), "undo_same": bool(np.array_equal(undone, before)),
           "redo_same": bool(np.array_equal(redone, edited)), "message": v.message}
    v.reload()
    out["after_reload"] = len(v.history.undo_stack) + len(v.history.redo_stack)
finally:
    v.close()
print("RESULT " + json.dumps(out))
"""


def test_ctrl_z_in_the_window_gives_back_the_picture_bit_for_bit(xdisplay, tmp_path):
    env = dict(os.environ, DISPLAY=xdisplay, GLASSRAY_NO_IMGUI="1")
    r = subprocess.run([sys.executable, "-c", SCRIPT, "default"], cwd=ROOT, env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(next(ln for ln in r.stdout.splitlines() if ln.startswith("RESULT "))[7:])
    assert out["edit_changed"] and out["undo_same"] and out["redo_same"], out
    assert out["message"] == "redone: materials" and out["after_reload"] == 0
