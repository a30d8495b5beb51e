"""Opening another scene in a running viewer (a file dropped on the window,
or the panel's Open field): GLFW's drop callback with the paths it passes,
in a real window under Xvfb, in a process of its own.  The new scene's own
camera when its file has one, the view kept when it has none; a bad file,
or a dropped file that is not a scene, leaves the scene shown as it was;
F5 follows the opened file."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
pytest.importorskip("glfw")

A = """name = "A"
[camera]
position = [0, 1, 6]
target = [0, 0.5, 0]
[[lights]]
position = [1, 4, 2]
[materials.red]
color = [0.9, 0.1, 0.1]
[[objects]]
type = "sphere"
center = [0, 0.5, 0]
radius = 0.5
material = "red"
"""
NO_CAMERA = """name = "B without a camera"
[[lights]]
position = [1, 4, 2]
[materials.blue]
color = [0.1, 0.1, 0.9]
[[objects]]
type = "box"
min = [-0.5, 0, -0.5]
max = [0.5, 1, 0.5]
material = "blue"
"""
OWN_CAMERA = NO_CAMERA.replace('name = "B without a camera"', 'name = "C"\n[camera]\nposition = [4, 3, 4]\nfov = 30')

SCRIPT = """
import json, sys
from viewer.cli.commands import build_parser, _load
from viewer.window import app

a, b, c, bad, png = sys.argv[1:6]
args = build_parser().parse_args(["view", a, "--size", "48x27", "--no-vsync", "--no-watch"])
v = app.Viewer(args, _load(args), _load)
out = {}
try:
    v._frame()
    v.controls.orbit_pixels(30, 0)            # the user has moved the view
    v._frame()
    moved = list(v.scene.camera.position)
    v._on_drop(v.window, [b])
    v._frame()
    out["b"] = [v.scene.name, list(v.scene.camera.position) == moved, v.renderer.scene.objects[0].type]
    v._on_drop(v.window, [png, c])            # the first .toml of the drop
    v._frame()
    out["c"] = [v.scene.name, list(v.scene.camera.position), v.scene.camera.fov]
    v._on_drop(v.window, [bad])
    v._frame()
    out["bad"] = [v.scene.name, v.panel.error if v.panel else v.message]
    v._on_drop(v.window, [png])
    v._frame()
    out["png"] = [v.scene.name, v.message]
    out["builtin"] = [v.open_scene("glass-sphere"), v.scene.name]
    v.open_scene(c)
    v.args.samples = None
    text = open(c).read()
    open(c, "w").write(text.replace('name = "C"', 'name = "C edited"'))
    v.reload()
    out["f5"] = v.scene.name
finally:
    v.close()
print("RESULT " + json.dumps(out))
"""


def test_a_dropped_scene_opens_with_its_own_camera_or_the_view_kept(xdisplay, tmp_path):
    files = {}
    for name, text in (("a", A), ("b", NO_CAMERA), ("c", OWN_CAMERA), ("bad", A.replace("radius = 0.5", "radius = 0"))):
        files[name] = tmp_path / f"{name}.toml"
        files[name].write_text(text)
    png = tmp_path / "picture.png"
    png.write_bytes(b"not a scene")
    env = dict(os.environ, DISPLAY=xdisplay, GLASSRAY_NO_IMGUI="1")
    r = subprocess.run([sys.executable, "-c", SCRIPT, *(str(files[k]) for k in ("a", "b", "c", "bad")), str(png)],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(next(ln for ln in r.stdout.splitlines() if ln.startswith("RESULT "))[7:])
    assert out["b"] == ["B without a camera", True, "box"]
    assert out["c"] == ["C", [4.0, 3.0, 4.0], 30.0]
    assert out["bad"][0] == "C" and "radius" in out["bad"][1]
    assert out["png"][0] == "C" and "not a scene file" in out["png"][1]
    from viewer.scene.load import load_scene

    assert out["builtin"] == [True, load_scene("glass-sphere").name]
    assert out["f5"] == "C edited"
    assert f"opened {files['b']}" in r.stdout and "cannot open" in r.stderr
