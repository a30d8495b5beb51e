"""Audit of the debug views and of the quality cache's robustness: the views
against hand counts and analytic values, the legend's labels at any scale,
and cache files that are not what they should be (no GL needed there)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from conftest import make_scene
from viewer.measure import quality as q
from viewer.measure import quality_cache
from viewer.base import views

# ---------------------------------------------------------------- the legend's labels


def _labels(monkeypatch, view: str, raw: np.ndarray) -> list[str]:
    from PIL import ImageDraw

    drawn: list[str] = []
    original = ImageDraw.ImageDraw.text

    def text(self, xy, s, *args, **kwargs):
        drawn.append(s)
        return original(self, xy, s, *args, **kwargs)

    monkeypatch.setattr(ImageDraw.ImageDraw, "text", text)
    views.picture(view, raw)
    return drawn


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e30])
def test_depth_legend_names_its_range_at_any_scale(monkeypatch, scale):
    # distances stay in the scene's units (README): a scene in micrometres
    # must not be labelled "0 (log) ... 0.001 (log)"
    lo, hi = 3.5454e-6 / 1e-6 * scale, 7.6644e-4 / 1e-6 * scale
    v = np.geomspace(lo, hi, 320, dtype=np.float32)
    raw = np.repeat(np.tile(v, (20, 1))[..., None], 3, axis=2)
    raw[0, :10] = np.inf                                   # sky: not in the range
    labels = _labels(monkeypatch, "depth", raw)
    assert len(labels) == 2, labels
    got = [float(re.match(r"\s*([-+0-9.e]+)", s).group(1)) for s in labels]
    np.testing.assert_allclose(got, [lo, hi], rtol=1e-3)


def test_cost_legend_labels_are_whole_counts(monkeypatch):
    raw = np.repeat(np.array([[1, 2], [7, 12]], np.float32)[..., None], 3, axis=2)
    raw = np.kron(raw, np.ones((1, 200, 1), np.float32))    # wide enough for both labels
    assert _labels(monkeypatch, "cost", raw) == ["0 rays", "12 rays"]


# ---------------------------------------------------------------- the quality cache's files


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setattr(quality_cache, "_WARNED", set())
    key = quality_cache.Key("scene-digest", {"gl_renderer": "test", "cpu": "test", "cpus": 1}, q.layout(8, 4), {"version": 0})
    return q.Cache(key, tmp_path)


def test_a_cache_file_that_is_not_utf8_is_corrupt_not_a_crash(cache, capsys):
    cache.root.mkdir(parents=True, exist_ok=True)
    cache.path.write_bytes(b"\xff\xfe{garbage")
    assert cache.load() == {}
    err = capsys.readouterr().err
    assert "corrupt" in err and "measuring again" in err


def test_a_broken_reference_file_is_measured_again(cache):
    cache.root.mkdir(parents=True, exist_ok=True)
    good = np.full((4, 8, 3), 0.5, np.float32)
    np.save(cache.ref_path, good)
    assert cache.load_reference() is not None
    full = cache.ref_path.read_bytes()
    for data in (b"", full[:60], full[:-8]):               # empty, header cut, data cut
        cache.ref_path.write_bytes(data)
        assert cache.load_reference() is None, len(data)
    with open(cache.ref_path, "wb") as f:                  # an .npz archive, strings: no reference
        np.savez(f, ref=good)
    assert cache.load_reference() is None
    with open(cache.ref_path, "wb") as f:
        np.save(f, np.full((4, 8, 3), "x"))
    assert cache.load_reference() is None


# ---------------------------------------------------------------- views against hand counts


SLAB = {"camera": {"position": [0, 0, 5], "target": [0, 0, 0], "fov": 30},
        "sky": {"type": "color", "color": [0.5, 0.5, 0.5]},
        "materials": {"glass": {"color": [1, 1, 1], "ambient": 0, "diffuse": 0, "specular": 0,
                                "transparency": 1, "ior": 1.5}},
        "objects": [{"type": "box", "min": [-2, -2, -0.5], "max": [2, 2, 0.5], "material": "glass"}]}


@pytest.mark.parametrize("max_depth, min_weight, rays", [
    # head-on through a slab of ior 1.5: R = 0.04 at each face, weights
    # 1 -> 0.04 (reflected), 0.96 (in); in -> 0.0384 (back inside), 0.9216
    # (out); 0.0384 -> 0.001536, 0.0369; 0.001536 -> 6e-5 (cut at 1e-3), 0.00147
    (8, 0.001, 8), (8, 0.01, 6), (8, 0.05, 3), (1, 0.001, 1), (2, 0.001, 3), (3, 0.001, 5), (4, 0.0, 7)])
def test_cost_of_a_glass_slab_is_the_hand_count(gl, max_depth, min_weight, rays):
    from viewer.gpu.renderer import Renderer

    doc = {**SLAB, "render": {"max_depth": max_depth, "min_weight": min_weight}}
    r = Renderer(gl, make_scene(doc))
    try:
        c = r.ray_cost(9, 9)
    finally:
        r.release()
    assert c[4, 4] == rays and np.all(c == rays)


def test_objects_view_gives_every_object_its_own_colour():
    # a palette of 8 that repeats drew objects 8, 16, ... of bench-many in
    # the floor's colour (object 0): they vanished into it
    ids = np.arange(-1, 256, dtype=np.float32)
    raw = np.repeat(np.tile(ids, (2, 1))[..., None], 3, axis=2)
    pic = np.round(255 * views.picture("objects", raw)).astype(int)
    assert pic.shape == raw.shape
    assert np.all(pic[:, 0] == 0)                          # no hit: black
    colours = {tuple(c) for c in pic[0, 1:]}
    assert len(colours) == 256 and (0, 0, 0) not in colours
    first = pic[0, 1:9]                                    # the first 8 keep the documented palette
    np.testing.assert_array_equal(first, np.round(255 * views._PALETTE).astype(int))
