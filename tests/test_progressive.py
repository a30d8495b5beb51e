"""The viewer's progressive renderer, offscreen (no window): accumulation in
bands equals `glassray render`, previews, the display encoding, resizing."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import make_scene
from viewer.imageio import to_display8
from viewer.progressive import Progressive
from viewer.renderer import Renderer

DOC = {
    "camera": {"position": [0.0, 1.5, 4.0], "target": [0.0, 0.6, 0.0]},
    "render": {"samples": 3},
    "lights": [{"position": [2.0, 4.0, 3.0]}],
    "materials": {"floor": {"checker": {"color": [0.2, 0.2, 0.2], "size": 0.5}},
                  "red": {"color": [0.9, 0.2, 0.1], "specular": 0.4},
                  "glass": {"ambient": 0, "diffuse": 0, "transparency": 1, "ior": 1.5}},
    "objects": [{"type": "plane", "material": "floor"},
                {"type": "sphere", "center": [-0.6, 0.5, 0], "radius": 0.5, "material": "red"},
                {"type": "sphere", "center": [0.6, 0.5, 0], "radius": 0.5, "material": "glass"}],
}


@pytest.fixture
def setup(gl):
    scene = make_scene(DOC, "progressive")
    r = Renderer(gl, scene)
    p = Progressive(gl, r)
    yield gl, scene, r, p
    p.release()
    r.release()


def test_accumulation_in_bands_equals_the_offscreen_render(setup):
    gl, scene, r, p = setup
    w, h = 61, 37  # odd sizes: bands do not divide them
    p.resize(w, h)
    p.cost_per_px = 1e-3  # pretend it is slow: bands of a row or two per call
    calls = 0
    while not p.done:
        p.accumulate(budget_ms=0.05)
        calls += 1
        if p.passes_done == 1 and p.next_row == 0 and calls < 1000:
            # after the first complete sample every pixel has exactly one
            one = p.image()
            assert np.array_equal(one, r.render(w, h, 1))
    assert calls > 3 * 2  # it really went band by band
    assert p.passes_done == 3
    expected = r.render(w, h, 3)
    assert np.array_equal(p.image(), expected)
    assert p.accumulate() == 0.0  # done: no more work


def test_partial_pass_divides_each_pixel_by_its_own_count(setup):
    gl, scene, r, p = setup
    w, h = 40, 30
    p.resize(w, h)
    p.finish_pass()
    assert p.passes_done == 1
    p.cost_per_px = 1.0  # one row per call
    p.accumulate(budget_ms=0.01)
    assert p.passes_done == 1 and 0 < p.next_row < h
    img = p.image()
    assert np.array_equal(img[p.next_row:], r.render(w, h, 1)[p.next_row:])  # rows with one sample


def test_preview_scale_follows_the_measured_cost(setup):
    gl, scene, r, p = setup
    p.resize(200, 100)
    p.cost_per_px = 1e-6  # 20000 px would take 20 ms
    assert p.preview_scale(20.0) == pytest.approx(1.0)
    assert p.preview_scale(5.0) == pytest.approx(0.5)
    p.cost_per_px = 1.0
    assert p.preview_scale(5.0) == pytest.approx(1 / 32)  # the floor
    p.render_preview(10.0)
    pw, ph = p.preview_size
    assert (pw, ph) == (round(200 * p.preview_scale(10.0)), round(100 * p.preview_scale(10.0))) or pw >= 1


def test_display_shows_the_encoded_image_and_the_preview_until_samples_land(setup):
    gl, scene, r, p = setup
    w, h = 48, 27
    p.resize(w, h)
    out = gl.simple_framebuffer((w, h), components=4)
    # nothing traced and no preview yet: black
    p.display(out, (0, 0, w, h))
    assert not np.frombuffer(out.read(components=3), np.uint8).any()
    # a full-resolution preview is shown where there is no sample yet
    p.cost_per_px = 1e-12
    p.render_preview(1000.0)
    assert p.preview_size == (w, h)
    p.display(out, (0, 0, w, h))
    shown = np.frombuffer(out.read(components=3), np.uint8).reshape(h, w, 3)[::-1]
    assert np.abs(shown.astype(int) - to_display8(r.render(w, h, 1)).astype(int)).max() <= 1
    # accumulated samples: the spec's display encoding of the mean
    while not p.done:
        p.accumulate(1000.0)
    p.display(out, (0, 0, w, h))
    shown = np.frombuffer(out.read(components=3), np.uint8).reshape(h, w, 3)[::-1]
    expected = to_display8(r.render(w, h, 3))
    assert np.abs(shown.astype(int) - expected.astype(int)).max() <= 1
    out.release()


def test_resize_and_zero_size(setup):
    gl, scene, r, p = setup
    p.resize(30, 20)
    p.finish_pass()
    p.resize(0, 0)  # minimised
    assert p.size == (0, 0) and p.accum_tex is None
    assert p.accumulate() == 0.0 and p.render_preview() == 0.0
    p.finish_pass()
    p.resize(25, 15)
    assert p.passes_done == 0 and p.accum_tex.size == (25, 15)
    p.finish_pass()
    assert p.image().shape == (15, 25, 3)


def test_scene_changes_restart_the_accumulation(setup):
    gl, scene, r, p = setup
    p.resize(20, 12)
    while not p.done:
        p.accumulate(1000.0)
    scene.lights[0].position = (-2.0, 4.0, 3.0)
    r.set_scene(scene)
    p.restart()
    assert p.passes_done == 0 and not p.image().any()
    p.finish_pass()
    assert np.array_equal(p.image(), r.render(20, 12, 1))
