"""Quality by error budget (viewer/measure/quality.py, ``glassray render --max-error``):
the pick on synthetic measurements, the measuring layout, the cache (round
trip, corruption, keys) and the command end to end on a tiny image."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from viewer.measure import quality as q
from viewer.measure import quality_cache
from viewer.measure import quality_grid

from conftest import make_scene

SCENE = """
name = "quality test"
[camera]
position = [0.0, 1.5, 4.0]
target = [0.0, 0.6, 0.0]
fov = 40
[render]
samples = 1
max_depth = 8
[[lights]]
position = [2.0, 4.0, 2.0]
[materials.floor]
color = [0.8, 0.8, 0.8]
checker = { color = [0.2, 0.2, 0.2], size = 0.25 }
[materials.glass]
color = [1, 1, 1]
transparency = 0.9
ior = 1.5
[[objects]]
type = "plane"
material = "floor"
[[objects]]
type = "sphere"
center = [0.0, 0.6, 0.0]
radius = 0.6
material = "glass"
"""


def m(samples, depth, weight, t, e):
    return q.Measured(q.Candidate(samples, depth, weight), t, e)


# ---------------------------------------------------------------- the pick (pure)


def test_pick_is_the_fastest_within_the_budget():
    ms = [m(1, 2, 0.01, 10.0, 0.20), m(4, 2, 0.01, 40.0, 0.08), m(1, 8, 0.001, 30.0, 0.05),
          m(16, 8, 0.001, 480.0, 0.01), m(8, 8, 0.001, 240.0, 0.02)]
    assert q.pick(ms, 0.3) == (ms[0], True)
    assert q.pick(ms, 0.1) == (ms[2], True)  # 30 ms beats 40 ms, both within 0.1
    assert q.pick(ms, 0.05) == (ms[2], True)  # the bound is inclusive
    assert q.pick(ms, 0.03) == (ms[4], True)
    assert q.pick(ms, 0.01) == (ms[3], True)
    # nothing meets it: the most accurate, and the caller is told
    assert q.pick(ms, 0.001) == (ms[3], False)
    # equal times: the smaller error
    tie = [m(1, 2, 0.01, 10.0, 0.05), m(1, 4, 0.01, 10.0, 0.04)]
    assert q.pick(tie, 0.1)[0] is tie[1]
    with pytest.raises(ValueError):
        q.pick([], 0.1)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.floats(0.01, 1e4), st.floats(0.0, 1.0)), min_size=1, max_size=25),
       st.floats(1e-4, 1.0), st.floats(1e-4, 1.0))
def test_a_larger_budget_never_gives_a_slower_pick(points, e1, e2):
    ms = [m(1 + i, 2, 0.01, t, e) for i, (t, e) in enumerate(points)]
    lo, hi = sorted((e1, e2))
    p_lo, met_lo = q.pick(ms, lo)
    p_hi, met_hi = q.pick(ms, hi)
    assert p_hi.time_ms <= p_lo.time_ms
    assert met_hi or not met_lo
    if met_hi:
        assert p_hi.rmse <= hi and all(x.time_ms >= p_hi.time_ms for x in ms if x.rmse <= hi)


def test_explicit_settings_fix_their_axis_of_the_grid():
    full = q.candidate_grid()
    assert len(full) == len(quality_grid.SAMPLES) * len(quality_grid.TRACE) and 10 <= len(full) <= 20
    assert {c.samples for c in q.candidate_grid(samples=4)} == {4}
    g = q.candidate_grid(max_depth=3)
    assert {c.max_depth for c in g} == {3} and len(g) == len(full)
    g = q.candidate_grid(samples=7, max_depth=5, min_weight=0.02)
    assert g == [q.Candidate(7, 5, 0.02)]


def test_bad_budgets_are_rejected():
    import argparse

    for bad in ("0", "-0.01", "abc", "nan", "inf", ""):
        with pytest.raises(argparse.ArgumentTypeError):
            q.parse_max_error(bad)
    assert q.parse_max_error("0.02") == 0.02


# ---------------------------------------------------------------- the measured pixels


@pytest.mark.parametrize("size", [(1280, 720), (1920, 1080), (640, 640), (300, 2000)])
def test_layout_spreads_tiles_over_the_whole_image(size):
    W, H = size
    lay = q.layout(W, H)
    assert len(lay.tiles) == quality_grid.GRID ** 2
    assert 0.7 * q.MEASURE_PIXELS <= lay.pixels <= 1.3 * q.MEASURE_PIXELS
    seen = np.zeros((H, W), bool)
    for (x, y, w, h), (px, py) in zip(lay.tiles, lay.packed):
        assert 0 <= x and x + w <= W and 0 <= y and y + h <= H
        assert not seen[y:y + h, x:x + w].any()
        seen[y:y + h, x:x + w] = True
        assert px + w <= lay.size[0] and py + h <= lay.size[1]
    # one tile in each cell of the grid
    cells = {(int((x + w / 2) * quality_grid.GRID // W), int((y + h / 2) * quality_grid.GRID // H)) for x, y, w, h in lay.tiles}
    assert len(cells) == quality_grid.GRID ** 2
    tw, th = lay.timing_size
    if W * H <= quality_grid.FULL_TIMING_PIXELS:
        assert (tw, th) == (W, H)            # timed at its own size: no fixed cost scaled up
    else:
        # about FULL_TIMING_PIXELS of the image's shape: a pass's fixed cost
        # stays small against its pixels' (at the mosaic's size it was not)
        assert abs(tw / th - W / H) < 0.05 * W / H and abs(tw * th - quality_grid.FULL_TIMING_PIXELS) < 0.05 * quality_grid.FULL_TIMING_PIXELS
    assert q.layout(W, H) == lay  # deterministic
    small = q.layout(100, 60)
    assert small.tiles == ((0, 0, 100, 60),) and small.size == small.timing_size == (100, 60)


def test_the_mosaic_holds_the_pixels_of_the_real_image(gl):
    """The tiles are traced with the rays of the full-size image."""
    from viewer.gpu.renderer import Renderer
    from viewer.base.sampling import sample_offsets
    from viewer.scene.load import with_overrides

    scene = with_overrides(make_scene_from_toml(), max_depth=4, min_weight=0.01)
    W, H = 192, 108
    lay = q.layout(W, H, pixels=1500, grid=4)
    assert len(lay.tiles) == 16
    r = Renderer(gl, scene)
    try:
        full = r.render(W, H, 2, 0, footprint=False)     # the mosaic's samples are point samples
    finally:
        r.release()
    meas = q.Measurement(gl, scene, lay, [], reference=np.zeros((lay.size[1], lay.size[0], 3)))
    meas._fbo = gl.simple_framebuffer(lay.size, components=4, dtype="f4")
    try:
        meas._set_scene(scene)
        meas._clear()
        for _ in meas._accumulate(sample_offsets(2, 0)):
            pass
        img = meas._read(2)
    finally:
        meas.close()
    for (x, y, w, h), (px, py) in zip(lay.tiles, lay.packed):
        tile, want = img[py:py + h, px:px + w], full[y:y + h, x:x + w]
        assert np.mean(np.abs(tile - want) > 1e-3) < 0.01  # float32 rounding of a ray may cross an edge


def make_scene_from_toml():
    import tomllib

    return make_scene(tomllib.loads(SCENE), "quality")


# ---------------------------------------------------------------- measuring and the cache


@pytest.fixture
def cache_root(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setattr(quality_cache, "_WARNED", set())
    return tmp_path / "xdg" / "glassray" / "quality"


def test_measure_cache_round_trip_and_corruption(gl, cache_root, capsys):
    scene = make_scene_from_toml()
    assert quality_cache.cache_dir() == cache_root
    meas, cache, cands = q.prepare(gl, scene, 64, 36)
    assert meas.todo == cands and not meas.done
    steps = 0
    while not meas.step(0.0):
        steps += 1
        assert 0.0 <= meas.fraction <= 1.0
    assert meas.rendered_reference and 0 <= meas.noise < 0.05
    first = q.finish(meas, cache, cands, 0.05)
    assert not first.cache_hit and cache.path.is_file() and cache.ref_path.is_file()
    assert cache.path.parent == cache_root
    by_key = meas.measured
    assert set(by_key) == {c.key() for c in cands}
    assert all(x.time_ms > 0 and x.rmse >= 0 for x in by_key.values())
    # more samples and more depth never measure much worse here (a sanity check of the measurements)
    assert by_key["s16-d10-w0.0001"].rmse < by_key["s1-d2-w0.01"].rmse

    # round trip: a second prepare has nothing to do, the pick is the same
    meas2, cache2, _ = q.prepare(gl, scene, 64, 36)
    assert meas2.done and not meas2.todo
    assert meas2.measured == by_key
    second = q.finish(meas2, cache2, cands, 0.05)
    assert second.cache_hit and second.measured == first.measured

    # a value off the grid is measured against the cached reference and added
    meas3, cache3, cands3 = q.prepare(gl, scene, 64, 36, samples=3)
    assert [c.samples for c in meas3.todo] == [3] * len(quality_grid.TRACE) and meas3.reference is not None
    meas3.run()
    q.finish(meas3, cache3, cands3, 0.05)
    assert len(json.loads(cache3.path.read_text())["measured"]) == len(cands) + len(quality_grid.TRACE)

    # corrupt file: warned about once, measured again, rewritten
    for garbage in ("{not json", json.dumps({"format": 1, "key": {}, "measured": {}})):
        cache.path.write_text(garbage)
        meas4, cache4, _ = q.prepare(gl, scene, 64, 36)
        assert not meas4.done
        meas4.run()
        q.finish(meas4, cache4, cands, 0.05)
        assert json.loads(cache.path.read_text())["measured"]
    err = capsys.readouterr().err
    assert err.count("quality cache") == 1 and "measuring again" in err


def test_cache_key_follows_what_the_error_depends_on(gl, cache_root):
    from viewer.scene.load import with_overrides

    scene = make_scene_from_toml()
    lay = q.layout(64, 36)
    stem = q.make_key(gl, scene, lay).stem()
    # the settings being chosen are not part of the key
    same = with_overrides(scene, samples=9, max_depth=3, min_weight=0.05)
    assert q.make_key(gl, same, lay).stem() == stem
    # the scene's content, the camera, the size and the machine are
    other = make_scene_from_toml()
    other.materials["glass"].ior = 1.33
    moved = with_overrides(scene, camera_position=(1.0, 2.0, 4.0))
    stems = {q.make_key(gl, s, lay).stem() for s in (other, moved)}
    stems.add(q.make_key(gl, scene, q.layout(64, 48)).stem())
    key = q.make_key(gl, scene, lay)
    key.machine = dict(key.machine, cpu="another CPU")
    stems.add(key.stem())
    assert stem not in stems and len(stems) == 4


def test_cache_key_follows_the_code_digest(gl, cache_root, monkeypatch):
    """The key's stem follows the digest of the measured code (which
    modules that covers: tests/measure/test_cache_identity.py)."""
    scene = make_scene_from_toml()
    lay = q.layout(64, 36)
    stem = q.make_key(gl, scene, lay).stem()
    monkeypatch.setattr(quality_cache, "_code_digest", lambda package=None: "another")
    assert q.make_key(gl, scene, lay).stem() != stem


# ---------------------------------------------------------------- the command


def run_render(tmp_path, *args, cache=None):
    env = dict(os.environ, XDG_CACHE_HOME=str(cache or tmp_path / "xdg"))
    return subprocess.run([sys.executable, "-m", "viewer", "render", *args], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)


def test_render_max_error_end_to_end(tmp_path):
    scene_file = tmp_path / "q.toml"
    scene_file.write_text(SCENE)
    out = tmp_path / "out.npy"
    args = (str(scene_file), "-o", str(out), "--size", "64x36", "--max-error", "0.05")
    r = run_render(tmp_path, *args)
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if "max-error" in ln]
    assert len(lines) == 1 and "cache miss" in lines[0] and "picked samples" in lines[0], r.stderr
    img = np.load(out)
    assert img.shape == (36, 64, 3)
    files = list((tmp_path / "xdg" / "glassray" / "quality").glob("*.json"))
    assert len(files) == 1
    doc = json.loads(files[0].read_text())
    picked = q.pick([q.Measured(q.Candidate(v["samples"], v["max_depth"], v["min_weight"]), v["time_ms"],
                                v["rmse"]) for v in doc["measured"].values()], 0.05)[0].candidate
    assert f"picked {picked.describe()}" in lines[0]

    # the second run reads the cache and renders the same picture
    r2 = run_render(tmp_path, *args)
    assert r2.returncode == 0 and "cache hit" in r2.stderr and picked.describe() in r2.stderr, r2.stderr
    assert np.array_equal(np.load(out), img)

    # explicit settings fix their value; an unreachable budget takes the most accurate (exit 0)
    r3 = run_render(tmp_path, *args[:-1], "1e-9", "--samples", "2")
    assert r3.returncode == 0, r3.stderr
    assert "no measured setting reaches it" in r3.stderr and "samples 2," in r3.stderr

    # a bad budget: exit 2, one message, nothing written
    out.unlink()
    for bad in ("0", "-1", "abc"):
        r4 = run_render(tmp_path, *args[:-1], bad)
        assert r4.returncode == 2 and "--max-error" in r4.stderr and "Traceback" not in r4.stderr
    assert not out.exists()
