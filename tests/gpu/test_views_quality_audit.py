"""Audit of the debug views' pictures and of --max-error's cache (no GL
needed): a depth view with nothing hit, the sky against the nearest hit, a
cached reference with cut pixels, fields of a cache file out of range, a
second pick from the same measurement, and a cache folder that is a file."""

from __future__ import annotations

import json
import math
import os
import re
import types

import numpy as np
import pytest

from conftest import make_scene
from test_views_audit import _labels  # the legend's labels as drawn
from viewer.measure import quality as q
from viewer.measure import quality_cache
from viewer.base import views
from viewer.measure import quality_grid




def _depth_raw(values: np.ndarray) -> np.ndarray:
    return np.repeat(np.asarray(values, np.float32)[..., None], 3, axis=2)


# ---------------------------------------------------------------- the depth view's picture


def test_depth_view_with_nothing_hit_claims_no_range(monkeypatch):
    # every ray leaves the scene: there is no distance to show, so the
    # legend must not read "0 (log) ... 1 (log)" (a made-up range, and a log
    # scale from 0)
    raw = _depth_raw(np.full((4, 320), np.inf))
    labels = _labels(monkeypatch, "depth", raw)
    numbers = [float(x) for s in labels for x in re.findall(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?", s)]
    assert numbers == [], labels
    assert any("nothing hit" in s for s in labels), labels


def test_depth_view_tells_the_sky_from_the_nearest_hit():
    # the nearest distance is the heat map's darkest colour: the sky (no
    # hit) must not be drawn (nearly) the same, or a near object against
    # the sky vanishes
    v = np.full((2, 64), np.inf)
    v[1] = np.geomspace(2.0, 50.0, 64)
    pic = views.picture("depth", _depth_raw(v))
    sky, nearest, farthest = pic[0, 0], pic[1, 0], pic[1, -1]
    assert np.max(np.abs(sky - nearest)) >= 0.25, (sky, nearest)
    assert np.max(np.abs(sky - farthest)) >= 0.25, (sky, farthest)
    # the hit pixels keep the heat map
    np.testing.assert_allclose(pic[1], views.heat(np.linspace(0, 1, 64)), atol=1e-6)


# ---------------------------------------------------------------- the quality cache


@pytest.fixture
def quiet(monkeypatch):
    monkeypatch.setattr(quality_cache, "_WARNED", set())


def _cache(tmp_path, w=8, h=4):
    key = quality_cache.Key("scene-digest", {"gl_renderer": "test", "cpu": "test", "cpus": 1}, q.layout(w, h), {"version": 0})
    return q.Cache(key, tmp_path / "quality")


def _grid_measured() -> dict[str, q.Measured]:
    out = {}
    for k, c in enumerate(q.candidate_grid()):
        out[c.key()] = q.Measured(c, 1.0 + k, 0.1 / (1 + k), 0.0)
    return out


def test_a_reference_with_cut_pixels_survives_the_cache(tmp_path, quiet):
    # the reference of a scene whose trees the driver cut holds NaN in
    # those pixels (Measurement._run); loading it back must keep it, or every
    # off-grid --samples drops all cached measurements and measures again
    c = _cache(tmp_path)
    ref = np.full((4, 8, 3), 0.25)
    ref[1, 2] = np.nan
    assert c.save(_grid_measured(), 0.003, ref, cut_pixels=1)
    back = c.load_reference()
    assert back is not None and back.shape == (4, 8, 3)
    assert np.isnan(back[1, 2]).all() and np.count_nonzero(np.isnan(back)) == 3
    np.testing.assert_array_equal(np.nan_to_num(back), np.nan_to_num(ref))
    # a reference with inf in it is still no reference
    np.save(c.ref_path, np.where(np.isnan(ref), np.inf, ref).astype(np.float32))
    assert c.load_reference() is None


def test_an_off_grid_value_keeps_the_cached_measurements_of_a_cut_scene(tmp_path, quiet, monkeypatch):
    scene = make_scene({"objects": [{"type": "sphere", "center": [0, 0.9, 0], "radius": 0.5, "material": "m"}],
                        "materials": {"m": {}}})
    ctx = types.SimpleNamespace(info={"GL_RENDERER": "fake"})
    monkeypatch.setattr(quality_cache, "cache_dir", lambda: tmp_path / "quality")
    lay = q.layout(8, 4)
    cache = q.Cache(q.make_key(ctx, scene, lay))
    ref = np.full((4, 8, 3), 0.25)
    ref[0, 0] = np.nan
    cache.save(_grid_measured(), 0.003, ref, cut_pixels=1)
    meas, _, cands = q.prepare(ctx, scene, 8, 4, samples=3)
    assert meas.reference is not None            # the cached reference, not a new one
    assert set(_grid_measured()) <= set(meas.measured)
    assert [c.samples for c in meas.todo] == [3] * len(quality_grid.TRACE)


@pytest.mark.parametrize("where, value", [
    ("cut_pixels", 1e300), ("cut_pixels", -1), ("cut_pixels", 33), ("cut_pixels", True), ("cut_pixels", "5"),
    ("cut_pixels", 2.5), ("noise_rmse", -1.0), ("noise_rmse", "x"), ("noise_rmse", math.inf),
    ("frac_off", math.nan), ("frac_off", 2.0), ("samples", 0), ("max_depth", 0), ("max_depth", 65),
    ("min_weight", -0.5), ("min_weight", 1.5), ("samples", 3.5), ("samples", True),
])
def test_cache_fields_out_of_range_are_a_corrupt_file(tmp_path, quiet, capsys, where, value):
    c = _cache(tmp_path)      # 8x4: 32 measured pixels
    assert c.save(_grid_measured(), 0.003, None, cut_pixels=0)
    assert c.load()          # as written: valid
    doc = json.loads(c.path.read_text())
    if where in ("cut_pixels", "noise_rmse"):
        doc["reference"][where] = value
    else:
        entry = dict(doc["measured"].pop("s1-d2-w0.01"), **{where: value})
        # named as the loader names it, so that only the value is wrong
        name = f"s{int(entry['samples'])}-d{int(entry['max_depth'])}-w{float(entry['min_weight']):g}"
        assert name not in doc["measured"]
        doc["measured"][name] = entry
    c.path.write_text(json.dumps(doc))
    assert c.load() == {}
    err = capsys.readouterr().err
    assert "corrupt" in err and "measuring again" in err


def test_valid_edge_values_of_a_cache_file_load(tmp_path, quiet):
    c = _cache(tmp_path)
    assert c.save(_grid_measured(), float("nan"), None, cut_pixels=32)   # noise unknown, every pixel cut
    assert len(c.load()) == len(q.candidate_grid())
    assert c.cut_pixels == 32 and math.isnan(c.noise)


def test_a_second_pick_from_the_same_measurement_does_not_write_again(tmp_path, quiet, monkeypatch):
    # the viewer picks again from the same measurement whenever its budget
    # slider moves (MaxError.finish -> quality.finish): one save is enough
    scene = make_scene({})
    lay = q.layout(8, 4)
    cands = q.candidate_grid()
    meas = q.Measurement(None, scene, lay, cands)
    assert meas.todo
    meas.measured = _grid_measured()                # as if run() had measured them all
    meas.reference, meas.noise, meas.done = np.zeros((4, 8, 3)), 0.001, True
    cache = _cache(tmp_path)
    saves = []
    monkeypatch.setattr(q.Cache, "save", lambda self, *a, **k: saves.append(a) or True)
    first = q.finish(meas, cache, cands, 0.05)
    for budget in (0.04, 0.03, 0.5):
        again = q.finish(meas, cache, cands, budget)
        assert again.cache_hit == first.cache_hit
    assert len(saves) == 1


def test_a_cache_folder_that_is_a_file_is_named_as_such(tmp_path, quiet, capsys):
    (tmp_path / "quality").write_text("not a folder")
    c = _cache(tmp_path)
    assert c.save(_grid_measured(), 0.003, None) is False
    err = capsys.readouterr().err
    assert "not saved" in err and "not a folder" in err, err


def test_ctrl_c_stops_a_measurement_between_passes(tmp_path):
    # Ctrl-C while --max-error measured (tens of seconds the first time) was
    # only taken by the render after it: the whole measurement ran on
    from viewer.base import interrupt

    passes = []

    def endless():
        for _ in range(200):          # finite: without the check, run() ends and the test fails
            passes.append(1)
            yield

    ctx = types.SimpleNamespace(disable=lambda *a: None, scissor=None)
    meas = q.Measurement(ctx, make_scene({}), q.layout(8, 4), q.candidate_grid())
    meas._gen = endless()
    try:
        with interrupt.deferred():
            import signal

            os.write(interrupt._pipe[1], bytes([signal.SIGINT]))      # as the C-level handler does
            with pytest.raises(KeyboardInterrupt):
                meas.run()
    except KeyboardInterrupt:        # (one escaping would stop pytest itself)
        pytest.fail("the Ctrl-C was not taken by the measurement")
    assert len(passes) == 1 and meas.done and meas._gen is None
