"""Audit of the viewer window as a user drives it (Xvfb, xdotool): the
controls of shared/spec/cli.md on scenes of any size and place.  The scene
format has no unit and no largest coordinate, and `render` draws a scene
scaled by a power of two exactly as at unit size (README, "Scale"); the
viewer's controls had absolute limits (a zoom stopped 1e-3 from the target,
1e6 at most; a pan and the light keys stopped at 1e7), so:

- in a scene in nanometres the first drag threw the eye a million times
  too far out, and one light key press moved the light 20000 scene sizes;
- in a scene in light years the first drag pulled the eye 50000 times
  closer, and pans and light keys did nothing at all;
- zooming into a target far from the origin (1e15) put the eye, rounded
  to float64, on the target: the viewer crashed (exit 1).

The expectations come from the unit-size scene (its controls are checked
against the spec's geometry in tests/test_controls.py) and from the scene
format's own camera validation, not from the scaled run itself."""

from __future__ import annotations

import shutil
import time

import numpy as np
import pytest

from conftest import make_scene
from test_viewer_e2e import Viewer, assert_same_picture
from viewer.window.controls import Controls
from viewer.scene.load import validate_camera

W, H = 160, 90

DOC = {
    "name": "window audit",
    "camera": {"position": [0.0, 2.0, 5.0], "target": [0.0, 0.5, 0.0], "fov": 40},
    "render": {"samples": 1, "max_depth": 3},
    "lights": [{"position": [0.0, 3.0, 1.0]}],
    "materials": {"floor": {"color": [0.8, 0.8, 0.8]}, "red": {"color": [0.9, 0.1, 0.1]},
                  "green": {"color": [0.1, 0.9, 0.1]}},
    "objects": [{"type": "plane", "material": "floor"},
                {"type": "sphere", "center": [0.0, 0.5, 0.0], "radius": 0.5, "material": "red"},
                {"type": "sphere", "center": [0.0, 0.2, 1.4], "radius": 0.2, "material": "green"}],
}


def transformed(k: float = 1.0, shift: float = 0.0) -> dict:
    """DOC with every length times k, then moved by `shift` along x, y and z."""
    import copy

    d = copy.deepcopy(DOC)
    move = lambda v: [x * k + shift for x in v]  # noqa: E731
    d["camera"]["position"] = move(d["camera"]["position"])
    d["camera"]["target"] = move(d["camera"]["target"])
    d["lights"][0]["position"] = move(d["lights"][0]["position"])
    for o in d["objects"]:
        if o["type"] == "plane":
            o["height"] = shift
        else:
            o["center"] = move(o["center"])
            o["radius"] *= k
    return d


def toml(doc: dict) -> str:
    def v(x):
        return "[" + ", ".join(repr(float(c)) for c in x) + "]"

    out = [f'name = "{doc["name"]}"', "[camera]", f"position = {v(doc['camera']['position'])}",
           f"target = {v(doc['camera']['target'])}", f"fov = {doc['camera']['fov']}",
           "[render]", f"samples = {doc['render']['samples']}", f"max_depth = {doc['render']['max_depth']}",
           "[[lights]]", f"position = {v(doc['lights'][0]['position'])}"]
    for name, m in doc["materials"].items():
        out += [f"[materials.{name}]", f"color = {v(m['color'])}"]
    for o in doc["objects"]:
        out += ["[[objects]]", f'type = "{o["type"]}"', f'material = "{o["material"]}"']
        if o["type"] == "plane":
            out.append(f"height = {float(o.get('height', 0.0))!r}")
        else:
            out += [f"center = {v(o['center'])}", f"radius = {float(o['radius'])!r}"]
    return "\n".join(out) + "\n"


def inputs(c: Controls) -> None:
    """What a user does: orbit, pan (right and shift+left), zoom in and out,
    move the light (plain and with shift)."""
    c.press("left", 40, 40)
    c.move(70, 50)
    c.release("left", 70, 50)
    c.press("right", 80, 45)
    c.move(95, 35)
    c.release("right", 95, 35)
    c.press("left", 60, 60, shift=True)
    c.move(50, 62)
    c.release("left", 50, 62)
    for _ in range(3):
        c.scroll(0.0, 1.0)
    c.scroll(0.0, -1.0)
    c.key("d", shift=True)
    c.key("q")


# ---------------------------------------------------------------- without a window


@pytest.mark.parametrize("k", [1e-200, 2.0 ** -30, 1e-9, 1e10, 2.0 ** 40, 1e200])
def test_a_scaled_scene_moves_as_the_unit_scene_does(k):
    unit = Controls(make_scene(DOC), (W, H))
    scaled = Controls(make_scene(transformed(k)), (W, H))
    inputs(unit)
    inputs(scaled)
    for a, b in ((unit.scene.camera.position, scaled.scene.camera.position),
                 (unit.scene.camera.target, scaled.scene.camera.target),
                 (unit.scene.lights[0].position, scaled.scene.lights[0].position)):
        assert np.allclose(np.multiply(a, k), b, rtol=1e-9, atol=1e-12 * k), (a, b)
    # the zoom's limits scale too: all the way in stays in front of the
    # target, at the same fraction of the distance
    for c in (unit, scaled):
        for _ in range(300):
            c.scroll(0.0, 100.0)
    ratio = scaled.camera.distance / (unit.camera.distance * k)
    assert 0.5 <= ratio <= 2.0
    assert scaled.camera.distance > 0 and scaled.camera.is_valid()


def test_a_camera_a_hair_from_its_target_starts_and_stays_valid():
    """README: "5e-324 is an ordinary view" for render; the viewer's
    controls took the distance as a sum of squares, which vanished, and the
    window closed at once ("camera position must differ from its target",
    hidden behind an AttributeError, see the last test)."""
    doc = dict(DOC, camera={"position": [0.0, 0.0, 5e-324], "target": [0.0, 0.0, 0.0]})
    c = Controls(make_scene(doc), (W, H))
    inputs(c)
    for _ in range(50):
        c.scroll(0.0, 1.0)
    c.orbit_pixels(0.0, 1000.0)
    validate_camera(c.scene.camera)
    assert c.camera.is_valid()


def test_light_and_pan_far_from_the_origin_still_move():
    """A scene placed at 2e7 (or a sun 1e9 away): pans and the light keys
    were refused past 1e7, so they did nothing at all."""
    c = Controls(make_scene(transformed(1.0, 2e7)), (W, H))
    unit = Controls(make_scene(DOC), (W, H))
    t0 = np.array(c.scene.camera.target)
    inputs(c)
    inputs(unit)
    assert np.allclose(np.subtract(c.scene.camera.target, t0), np.subtract(unit.scene.camera.target, (0, 0.5, 0)),
                       atol=1e-6)
    assert np.allclose(np.subtract(c.scene.lights[0].position, 2e7),
                       np.array(unit.scene.lights[0].position), atol=1e-6)
    doc = dict(DOC, lights=[{"position": [1e9, 1e9, 0.0]}])
    sun = Controls(make_scene(doc), (W, H))
    sun.take_changed()
    sun.key("a")
    assert sun.scene.lights[0].position[0] < 1e9 and sun.take_changed()


def test_a_light_too_far_out_for_a_step_is_no_change():
    doc = dict(DOC, lights=[{"position": [1e300, 1.0, 0.0]}])
    c = Controls(make_scene(doc), (W, H))
    c.take_changed()
    c.key("d")                                    # 1e300 + 0.1 is 1e300
    assert not c.take_changed(), "a light key that moved nothing restarted the accumulation"
    c.key("q")                                    # y does move
    assert c.take_changed() and c.scene.lights[0].position[1] < 1.0


@pytest.mark.parametrize("shift", [1e15, 3e16])
def test_zoom_and_orbit_at_a_target_far_from_the_origin_keep_a_valid_camera(shift):
    """Every camera the controls hand to the renderer passes the scene
    format's own check (position != target, not straight up or down)."""
    c = Controls(make_scene(transformed(1.0, shift)), (W, H))
    last = c.camera.distance
    for _ in range(200):
        c.scroll(0.0, 1.0)
        validate_camera(c.scene.camera)
        assert c.camera.distance <= last
        last = c.camera.distance
    for dy in (500, -2000, 4000):                # to both poles and back, at the closest distance
        c.orbit_pixels(37.0, dy)
        validate_camera(c.scene.camera)
    c.pan_pixels(1e4, -1e4)
    validate_camera(c.scene.camera)
    f = np.subtract(c.scene.camera.target, c.scene.camera.position)
    assert np.dot(f, c.camera.forward) > 0       # in front of the target, never past it


# ---------------------------------------------------------------- in a window

needs_x = pytest.mark.skipif(not (shutil.which("Xvfb") and shutil.which("xdotool")),
                             reason="needs Xvfb and xdotool")


def drive(v: Viewer) -> None:
    """inputs() with real events (window coordinates)."""
    v.drag((40, 40), (70, 50), steps=1)
    v.drag((80, 45), (95, 35), button=3, steps=1)
    v.drag((60, 60), (50, 62), steps=1, modifier="shift")
    v.xdo("mousemove", "--window", v.wid, "80", "45")
    v.xdo("click", "--repeat", "3", "--delay", "30", "4")
    v.xdo("click", "5")
    v.key("shift+d", "q")


@needs_x
def test_a_nanometre_scene_in_the_window_moves_as_at_unit_size(xdisplay, tmp_path, gl):  # noqa: F811
    """The same drags, scrolls and keys on the scene at 2^-30 scale give the
    picture of the unit scene after them (render draws a scene scaled by a
    power of two exactly as at unit size)."""
    from viewer.base.imageio import to_display8
    from viewer.gpu.renderer import Renderer

    scene_file = tmp_path / "nano.toml"
    scene_file.write_text(toml(transformed(2.0 ** -30)))
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    v = Viewer(xdisplay, run_dir, str(scene_file), "--size", f"{W}x{H}", "--no-vsync")
    try:
        v.shot()
        drive(v)
        shot = v.shot()
        unit = Controls(make_scene(DOC), (W, H))
        inputs(unit)
        r = Renderer(gl, unit.scene)
        try:
            expected = to_display8(r.render(W, H, 1, 0))
        finally:
            r.release()
        assert_same_picture(shot, expected)
        assert v.quit() == 0
        assert not any("Traceback" in e for e in v.stderr), "\n".join(v.stderr)
    finally:
        v.close()


@needs_x
def test_zooming_into_a_target_far_from_the_origin_does_not_crash(xdisplay, tmp_path):  # noqa: F811
    scene_file = tmp_path / "far.toml"
    scene_file.write_text(toml(transformed(1.0, 1e15)))
    v = Viewer(xdisplay, tmp_path, str(scene_file), "--size", f"{W}x{H}", "--no-vsync")
    try:
        v.shot()
        v.xdo("mousemove", "--window", v.wid, "80", "45")
        v.xdo("click", "--repeat", "120", "--delay", "5", "4")   # all the way in
        time.sleep(0.5)
        assert v.proc.poll() is None, "\n".join(v.stderr)       # it crashed here (exit 1)
        v.drag((80, 45), (80, 200), steps=2)                     # and over the pole
        time.sleep(0.5)
        assert v.proc.poll() is None, "\n".join(v.stderr)
        assert v.shot().shape == (H, W, 3)
        assert v.quit() == 0
        assert not any(e.startswith("glassray:") for e in v.stderr), "\n".join(v.stderr)
    finally:
        v.close()


# ---------------------------------------------------------------- a failed start


@needs_x
@pytest.mark.parametrize("case", ["shader", "sky"])
def test_a_failed_start_says_what_failed(xdisplay, tmp_path, gl, case):  # noqa: F811
    """A shader that does not compile, or a sky picture larger than the
    driver's largest texture (README: `render` fails with exit 1 and says
    so), made the viewer say "AttributeError: 'Viewer' object has no
    attribute 'quality_job'": the window was open when the renderer failed,
    and Viewer.close() met attributes that _open had not set yet."""
    import os
    import subprocess
    import sys

    from PIL import Image

    from viewer.gpu.shaders import shader_root

    env = dict(os.environ, DISPLAY=xdisplay)
    env.pop("WAYLAND_DISPLAY", None)
    scene_file = tmp_path / "s.toml"
    doc = toml(DOC)
    if case == "shader":
        shaders = tmp_path / "shaders"
        shutil.copytree(shader_root(), shaders)
        (shaders / "render.frag").write_text((shaders / "render.frag").read_text() + "\nthis is not GLSL;\n")
        env["GLASSRAY_SHADERS"] = str(shaders)
        expected = ["render.frag"]
    else:
        width = int(gl.info["GL_MAX_TEXTURE_SIZE"]) + 1
        Image.new("RGB", (width, 2), (90, 140, 200)).save(tmp_path / "wide.png")
        doc = doc.replace("[render]", '[sky]\ntype = "image"\nimage = "wide.png"\n[render]')
        expected = ["sky.image", "wide.png", "larger than"]
    scene_file.write_text(doc)
    r = subprocess.run([sys.executable, "-m", "viewer", "view", str(scene_file), "--size", "64x36", "--no-vsync"],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 1, r.stderr
    assert "AttributeError" not in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert all(e in r.stderr for e in expected), r.stderr
