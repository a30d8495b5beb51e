"""Audit of multi-sample images by routes independent of the renderer's own
output: the sample pattern is what the spec asks (inside the pixel as the
GPU sees it, stratified, the centre first).  The footprint samples' bias
floor at shadow edges on the checker (mirror-ball at 48x27, pixel (22, 19):
0.052 off the float64 box filter at 256 samples) is reported, not fixed
here: the fix tried (point samples where the corners' lighting differs)
costs 2-3x the RMSE at 8 samples; see the audit report."""

from __future__ import annotations

import numpy as np
import pytest

from viewer.base.sampling import sample_offsets


# ---------------------------------------------------------------- sample pattern


@pytest.mark.parametrize("seed", [0, 1, 7, 123456789])
def test_pattern_is_in_the_pixel_in_float32_too(seed):
    """The offsets reach the GPU as float32 (uniforms, the offsets texture):
    every one must stay inside [0, 1) there as well, and the first is the
    centre exactly."""
    off = sample_offsets(4096, seed)
    f = off.astype(np.float32)
    assert (f >= 0).all() and (f < 1).all()
    assert tuple(f[0]) == (0.5, 0.5)


def test_pattern_is_stratified_on_the_grid_of_every_power_of_four():
    """A 2^2m prefix has one point in each cell of the 2^m x 2^m grid (the
    stratified pattern the spec names), checked by counting in numpy."""
    for seed in (0, 3):
        off = sample_offsets(1024, seed)
        for m in range(1, 6):
            n = 4 ** m
            k = 2 ** m
            cells = np.floor(off[:n] * k).astype(int)
            counts = np.zeros((k, k), int)
            np.add.at(counts, (cells[:, 1], cells[:, 0]), 1)
            assert (counts == 1).all(), (seed, m)


# ---------------------------------------------------------------- footprint samples converge


def box_filter(scene, w, h, i, j, k=64):
    """Pixel (i, j)'s box filter by the float64 reference: a k x k midpoint
    grid over its square, exposure applied."""
    from viewer.reference import trace as REF

    g = (np.arange(k) + 0.5) / k
    offs = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    o, d = REF.pixel_rays(scene, w, h, [j * w + i], offs)
    return REF.trace(scene, o, d).mean(axis=0) * scene.render.exposure


def test_footprint_samples_converge_to_the_box_filter_at_a_shadow_edge(gl):
    # mirror-ball at 48x27, pixel (22, 19): the ball's contact shadow crosses
    # a checker line inside it.  A footprint sample took the mean colour
    # times its own point's lighting, so the pixel converged to mean colour
    # x mean lighting: 0.052 off the box filter at 256 samples, 0.053 at
    # 1024, for every seed.  As a control variate (lib/footprint.glsl) it
    # converges like point samples; the pixel's own sampling noise at 256
    # samples is a few thousandths.
    from viewer.gpu.renderer import Renderer
    from viewer.scene.load import load_scene

    scene = load_scene("mirror-ball")
    w, h, i, j = 48, 27, 22, 19
    expected = box_filter(scene, w, h, i, j)
    r = Renderer(gl, scene)
    try:
        assert r.takes_footprint(256)
        got = r.render(w, h, 256)[j, i]
        point = r.render(w, h, 256, footprint=False)[j, i]
    finally:
        r.release()
    assert np.abs(point - expected).max() < 0.01, (point, expected)   # the reference and pattern agree
    assert np.abs(got - expected).max() < 0.01, (got, expected)
