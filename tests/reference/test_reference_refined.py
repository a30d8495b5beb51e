"""The refined reference (viewer.reference.render_reference_refined): more
samples exactly where a pixel's first samples disagree, checked against the
plain reference computed sample by sample."""

from __future__ import annotations

import numpy as np
import pytest

from viewer.measure import reference_cache
from viewer.reference.camera import camera_rays, pixel_rays
from viewer.reference.refine import render_reference_refined
from viewer.reference.trace import render_reference, trace
from viewer.base.sampling import sample_offsets
from viewer.scene.load import load_scene

W, H = 24, 14


@pytest.fixture(scope="module")
def scene():
    # the peer bench's scene: a clear sphere over an emissive checker, sky above
    return reference_cache.reference_scene(load_scene("whitted-exact"))


def test_pixel_rays_are_the_camera_rays(scene):
    offs = sample_offsets(4, 3)
    pixels = np.array([0, 5, W + 3, W * H - 1])
    o, d = pixel_rays(scene, W, H, pixels, offs)
    assert o.shape == d.shape == (len(pixels) * len(offs), 3)
    for k, off in enumerate(offs):
        O, D = camera_rays(scene, W, H, off)
        for p, pix in enumerate(pixels):
            j, i = divmod(int(pix), W)
            assert np.array_equal(d[p * len(offs) + k], D[j, i])
            assert np.array_equal(o[p * len(offs) + k], O[j, i])


def test_without_refinement_it_is_the_plain_reference(scene):
    img, count = render_reference_refined(scene, W, H, 8, 8, 1e-3, seed=1)
    assert np.all(count == 8)
    assert np.allclose(img, render_reference(scene, W, H, 8, seed=1), rtol=0, atol=1e-12)


def test_refines_exactly_the_pixels_whose_samples_disagree(scene):
    n, big, tol = 16, 64, 1e-3
    img, count = render_reference_refined(scene, W, H, n, big, tol, seed=1)
    # the spread of each pixel's first n samples, sample by sample
    per_sample = np.stack([trace(scene, *(a.reshape(-1, 3) for a in camera_rays(scene, W, H, off)))
                           for off in sample_offsets(n, 1)])
    spread = (per_sample.max(axis=0) - per_sample.min(axis=0)).max(axis=1) * scene.render.exposure
    edges = (spread > tol).reshape(H, W)
    assert 0 < edges.sum() < edges.size          # both kinds occur: sky and smooth floor, edges
    assert np.array_equal(count, np.where(edges, big, n))
    plain_n = render_reference(scene, W, H, n, seed=1)
    plain_big = render_reference(scene, W, H, big, seed=1)
    assert np.allclose(img[~edges], plain_n[~edges], rtol=0, atol=1e-12)
    assert np.allclose(img[edges], plain_big[edges], rtol=0, atol=1e-12)


def test_refinement_brings_it_nearer_an_independent_reference(scene):
    """Against 1024 samples of another seed, the refined reference (16, then
    256 where needed) is far nearer than its 16 samples alone and about as
    near as 256 everywhere, for a fraction of the rays."""
    far = render_reference(scene, W, H, 1024, seed=7)
    refined, count = render_reference_refined(scene, W, H, 16, 256, 2.5e-4, seed=1)

    def rmse(a):
        return float(np.sqrt(np.mean((a - far) ** 2)))

    plain16 = rmse(render_reference(scene, W, H, 16, seed=1))
    plain256 = rmse(render_reference(scene, W, H, 256, seed=1))
    assert rmse(refined) < 0.5 * plain16
    assert rmse(refined) < 1.25 * plain256
    assert count.mean() < 0.9 * 256


def test_workers_give_the_same_image(scene):
    one = render_reference_refined(scene, W, H, 8, 32, 1e-3, seed=2)
    two = render_reference_refined(scene, W, H, 8, 32, 1e-3, seed=2, workers=2)
    assert np.array_equal(one[0], two[0]) and np.array_equal(one[1], two[1])


def test_check_runs_and_can_stop_it(scene):
    calls = []

    def check():
        calls.append(1)
        if len(calls) > 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_reference_refined(scene, W, H, 8, 64, 1e-3, seed=1, check=check)
    assert len(calls) == 2


def test_bad_counts_are_refused(scene):
    with pytest.raises(ValueError):
        render_reference_refined(scene, W, H, 16, 8, 1e-3)


def test_bench_caches_the_refined_reference_apart(tmp_path):
    scene = load_scene("whitted-exact")
    plain, kind, cached = reference_cache.reference_image(scene, "whitted-exact", W, H, 8, tmp_path)
    refined, _, cached_r = reference_cache.reference_image(scene, "whitted-exact", W, H, 8, tmp_path, refine=32)
    assert kind == "float64" and not cached and not cached_r
    names = sorted(p.name for p in tmp_path.glob("ref-*.npy"))
    assert len(names) == 2 and any("-s8r32t" in n for n in names)
    assert not np.array_equal(plain, refined)
    again, _, cached = reference_cache.reference_image(scene, "whitted-exact", W, H, 8, tmp_path, refine=32)
    assert cached and np.array_equal(again, refined)
    # a refined count no larger than the base is no refinement: the plain file
    same, _, cached = reference_cache.reference_image(scene, "whitted-exact", W, H, 8, tmp_path, refine=8)
    assert cached and np.array_equal(same, plain)


def _interrupt_myself():
    import os
    import signal
    import time

    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.05)
    return "still here"


def test_workers_leave_ctrl_c_to_the_caller(scene, monkeypatch):
    """Ctrl-C reaches the whole process group; a worker that took it sent a
    KeyboardInterrupt back as its task's result and the bench said
    "interrupted" twice.  Workers ignore it: the caller's check() acts."""
    import concurrent.futures
    import multiprocessing

    from viewer.reference import refine

    with concurrent.futures.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                                initializer=refine._ignore_sigint) as pool:
        try:
            got = pool.submit(_interrupt_myself).result(timeout=60)
        except KeyboardInterrupt:     # the worker's, sent back: fail this test, not the session
            pytest.fail("a worker took Ctrl-C")
        assert got == "still here"

    made = []
    real = concurrent.futures.ProcessPoolExecutor

    def recording(*args, **kwargs):
        made.append(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(concurrent.futures, "ProcessPoolExecutor", recording)
    render_reference_refined(scene, 8, 4, 4, 8, 1e-3, seed=2, workers=2)
    assert made and made[0].get("initializer") is refine._ignore_sigint
