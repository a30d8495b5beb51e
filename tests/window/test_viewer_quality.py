"""The viewer's "max error" setting (viewer/window/app.py over viewer/measure/quality.py):
when it measures, which measurements a new budget picks from, and what it
prints.  Each test drives a real Viewer (a GLFW window under Xvfb) in a
process of its own, calling the methods the panel and the keys call, with
its quality cache in a temporary folder."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest


ROOT = Path(__file__).resolve().parents[2]

pytest.importorskip("glfw")

# two facing mirrors and a light between them: a few rays a pixel, so that
# a measurement at 48x27 takes a second or two
SCENE = """\
[camera]
position = [0, 0, 5]
target = [0, 0, 0]
fov = 30
[render]
max_depth = 3
[[lights]]
type = "point"
position = [0.3, 0.4, 2]
[materials.mirror]
color = [0.8, 0.8, 0.8]
reflectivity = 0.5
[[objects]]
type = "box"
min = [-50, -50, -3]
max = [50, 50, -2]
material = "mirror"
[[objects]]
type = "box"
min = [-50, -50, 6]
max = [50, 50, 7]
material = "mirror"
"""

# the driver: a Viewer, "max error" switched on and measured to the end,
# then the steps of each test; it prints one JSON line of what it saw
PRELUDE = """
import json, sys
from viewer.cli.commands import build_parser, _load
from viewer.window import app

args = build_parser().parse_args(["view", sys.argv[1], "--size", "48x27", "--no-vsync"])
v = app.Viewer(args, _load(args), _load)
out = {}

def measure_to_the_end():
    frames = 0
    while v.max_error.job is not None:
        v._frame()
        frames += 1
    return frames

try:
    v._frame()
    v.panel.max_error_on = True
    v.panel.max_error = 0.05
    v.max_error.update()
    out["first_measured"] = v.max_error.job is not None
    measure_to_the_end()
"""
POSTLUDE = """
finally:
    v.close()
print("RESULT " + json.dumps(out))
"""


def drive(display: str, tmp_path: Path, steps: str) -> tuple[dict, str]:
    scene = tmp_path / "mirrors.toml"
    scene.write_text(SCENE)
    script = PRELUDE + textwrap.indent(textwrap.dedent(steps), "    ") + POSTLUDE
    env = dict(os.environ, DISPLAY=display, XDG_CACHE_HOME=str(tmp_path / "cache"))
    r = subprocess.run([sys.executable, "-c", script, str(scene)], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    line = next(ln for ln in r.stdout.splitlines() if ln.startswith("RESULT "))
    return json.loads(line[len("RESULT "):]), r.stderr


def test_f5_with_nothing_changed_takes_the_measurement_from_the_cache(xdisplay, tmp_path, gl):  # noqa: F811
    # F5 measured everything again (tens of seconds at a real window's
    # size) although the cache's key holds the scene and the shaders
    out, _ = drive(xdisplay, tmp_path, """
        v.reload()
        out["after_f5_measuring"] = v.max_error.job is not None
        out["after_f5_picked"] = v.max_error.choice is not None and v.max_error.choice.cache_hit
    """)
    assert out["first_measured"]
    assert out["after_f5_measuring"] is False
    assert out["after_f5_picked"] is True


def test_f5_after_the_scene_file_changed_measures_again(xdisplay, tmp_path, gl):  # noqa: F811
    out, _ = drive(xdisplay, tmp_path, """
        from pathlib import Path
        p = Path(sys.argv[1])
        p.write_text(p.read_text().replace("position = [0.3, 0.4, 2]", "position = [0.5, 0.4, 2]"))
        v.reload()
        out["after_edit_measuring"] = v.max_error.job is not None
    """)
    assert out["after_edit_measuring"] is True


def test_a_new_budget_after_the_camera_moved_is_picked_from_this_view(xdisplay, tmp_path, gl):  # noqa: F811
    # the pick came from the measurements of the view where "max error" was
    # switched on, however far the camera had moved since
    out, _ = drive(xdisplay, tmp_path, """
        first = v.max_error.parts
        v.panel.max_error = 0.06
        v.max_error.update()
        out["same_view_reused"] = v.max_error.parts is first and v.max_error.job is None
        v.scene.camera.position = (0.5, 0.3, 4.0)
        v.controls.camera_edited()
        v._frame()
        v.panel.max_error = 0.07
        v.max_error.update()
        out["moved_reused"] = v.max_error.parts is first
        out["moved_key_is_current"] = v.max_error.parts[1].key.stem() != first[1].key.stem()
        measure_to_the_end()
        # back to the first view: its measurement is in the cache
        v.scene.camera.position = (0.0, 0.0, 5.0)
        v.controls.camera_edited()
        v._frame()
        v.panel.max_error = 0.08
        v.max_error.update()
        out["back_measuring"] = v.max_error.job is not None
        out["back_key"] = v.max_error.parts[1].key.stem() == first[1].key.stem()
    """)
    assert out["same_view_reused"] is True
    assert out["moved_reused"] is False and out["moved_key_is_current"] is True
    assert out["back_measuring"] is False and out["back_key"] is True


def test_the_pick_is_printed_once_not_at_every_step_of_the_budget(xdisplay, tmp_path, gl):  # noqa: F811
    out, err = drive(xdisplay, tmp_path, """
        picks = set()
        for e in (0.05, 0.051, 0.052, 0.053, 0.054, 0.055):
            v.panel.max_error = e
            v.max_error.update()
            picks.add((v.max_error.choice.measured.candidate.key(), v.max_error.choice.met))
        out["picks"] = len(picks)
    """)
    lines = [ln for ln in err.splitlines() if ln.startswith("glassray: max-error ")]
    assert out["picks"] == 1                 # the same setting for every one of those budgets
    assert len(lines) == 1, lines
