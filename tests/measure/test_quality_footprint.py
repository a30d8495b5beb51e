"""Quality by error budget measures what ``glassray render`` draws: on a
checkered plane, candidates of two samples or more (and the reference) take
footprint samples with the full image's footprint mask, as Renderer.render
does; one sample stays the centred point sample.  Expectations come from
Renderer.render of the whole image (the route ``glassray render`` takes) and
numpy, never from the measurement itself."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from viewer.measure import quality as q
from viewer.measure import kit
from viewer.measure import quality_cache
from viewer.measure import quality_measure

from conftest import make_scene

SCENE = """
name = "quality footprint test"
[camera]
position = [0.0, 1.5, 4.0]
target = [0.0, 0.6, 0.0]
fov = 40
[render]
samples = 1
max_depth = 4
min_weight = 0.01
[[lights]]
position = [2.0, 4.0, 2.0]
[materials.floor]
color = [0.8, 0.8, 0.8]
checker = { color = [0.2, 0.2, 0.2], size = 0.25 }
[materials.ball]
color = [0.9, 0.3, 0.2]
reflectivity = 0.3
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
material = "MATERIAL"
"""

W, H = 192, 108


def scene_of(material: str):
    return make_scene(tomllib.loads(SCENE.replace("MATERIAL", material)), "footprint")


def mosaic_of(image: np.ndarray, lay: q.Layout) -> np.ndarray:
    """The mosaic's pixels cut out of a full W x H image."""
    out = np.zeros((lay.size[1], lay.size[0], 3))
    for (x, y, w, h), (px, py) in zip(lay.tiles, lay.packed):
        out[py:py + h, px:px + w] = image[y:y + h, x:x + w]
    return out


@pytest.fixture
def renderer(gl):
    from viewer.gpu.renderer import Renderer

    made = []

    def make(scene):
        r = Renderer(gl, scene, eager=False)
        made.append(r)
        return r
    yield make
    for r in made:
        r.release()


def rmse(a, b) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)))


def test_candidates_and_reference_are_what_render_draws(gl, renderer):
    """On a checker scene the measured error of a 4-sample candidate is the
    RMSE of Renderer.render's 4-sample image (footprint samples) against
    Renderer.render's reference (two footprint patterns of 32, depth 16)
    over the mosaic's pixels; a 1-sample candidate's is the centred point
    sample's.  Point samples (the measurement before) put the checker's
    aliasing into both the candidate and the reference."""
    from viewer.measure.bench import REFERENCE_MAX_DEPTH, REFERENCE_MIN_WEIGHT, REFERENCE_SEED
    from viewer.scene.load import with_overrides

    scene = scene_of("ball")
    lay = q.layout(W, H, pixels=1500, grid=4)
    assert len(lay.tiles) == 16
    ref_r = renderer(with_overrides(scene, max_depth=REFERENCE_MAX_DEPTH, min_weight=REFERENCE_MIN_WEIGHT))
    half = quality_measure.REFERENCE_SAMPLES // 2
    a = ref_r.render(W, H, half, REFERENCE_SEED)
    b = ref_r.render(W, H, half, REFERENCE_SEED + 1)
    want_ref = mosaic_of((a.astype(np.float64) + b) / 2, lay)
    cand_r = renderer(scene)
    img4, img1 = cand_r.render(W, H, 4, kit.RENDER_SEED), cand_r.render(W, H, 1, kit.RENDER_SEED)
    # the point-sampled image is far from the footprint one here: the test
    # can tell them apart
    assert rmse(mosaic_of(cand_r.render(W, H, 4, kit.RENDER_SEED, footprint=False), lay),
                mosaic_of(img4, lay)) > 0.005

    meas = q.Measurement(gl, scene, lay, [q.Candidate(1, 4, 0.01), q.Candidate(4, 4, 0.01)])
    meas.run()
    assert np.abs(meas.reference - want_ref).max() < 1e-5
    for n, img in ((4, img4), (1, img1)):
        want = rmse(mosaic_of(img, lay), want_ref)
        got = meas.measured[q.Candidate(n, 4, 0.01).key()].rmse
        assert got == pytest.approx(want, rel=1e-3, abs=1e-6), n


def test_mosaic_footprint_mask_is_the_full_images(gl, renderer):
    """The mosaic's mask holds, for each measured pixel, the full image's
    code (the checkered plane its corner rays meet, or none) exactly and its
    closed-form share to float32 rounding: what Renderer.render's
    direct_footprints gives for the W x H image.  And a mosaic pixel that
    takes footprint samples is Renderer.render's pixel (glass scene: the
    cut-checked footprint variant)."""
    from viewer.base.sampling import sample_offsets
    from viewer.scene.load import with_overrides

    scene = with_overrides(scene_of("glass"), max_depth=6, min_weight=0.001)
    lay = q.layout(W, H, pixels=1500, grid=4)
    r = renderer(scene)
    img = r.render(W, H, 4, 0)
    full_mask = r.footprint_sampler(W, H)._footprint_texels[::-1]      # top row first
    meas = q.Measurement(gl, scene, lay, [], reference=np.zeros((lay.size[1], lay.size[0], 3)))
    meas._fbo = gl.simple_framebuffer(lay.size, components=4, dtype="f4")
    try:
        meas._set_scene(scene)
        for _ in meas._footprint_mask():
            pass
        mw, mh = lay.size
        mask = np.frombuffer(meas._footprint_tex.read(), np.float32).reshape(mh, mw, 2)[::-1]
        meas._renderer.footprint_mask = meas._footprint_tex
        meas._clear()
        for _ in meas._accumulate(sample_offsets(4, 0)):
            pass
        mos = meas._read(4)
    finally:
        meas.close()
    on = 0
    for (x, y, w, h), (px, py) in zip(lay.tiles, lay.packed):
        got, want = mask[py:py + h, px:px + w], full_mask[y:y + h, x:x + w]
        assert np.array_equal(got[..., 0], want[..., 0])
        assert np.abs(got[..., 1] - want[..., 1]).max() < 1e-4
        fp = want[..., 0] > 0.5
        on += int(fp.sum())
        if fp.any():
            assert np.abs(mos[py:py + h, px:px + w][fp] - img[y:y + h, x:x + w][fp]).max() < 1e-4
    assert on > 0.3 * lay.pixels        # the floor fills much of the picture


def test_measurements_of_the_old_method_are_not_reused(gl, tmp_path):
    """A cache file written by the point-sampled method (method version 1)
    is not read as this method's."""
    scene = scene_of("ball")
    lay = q.layout(64, 36)
    key = q.make_key(gl, scene, lay)
    old = quality_cache.Key(key.scene, key.machine, lay, {**key.method, "version": 1}, key.name)
    m = q.Measured(q.Candidate(1, 4, 0.01), 1.0, 0.5)
    assert q.Cache(old, tmp_path).save({m.candidate.key(): m}, 0.001)
    assert q.Cache(key, tmp_path).load() == {}
