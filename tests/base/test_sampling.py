"""The sub-pixel sample pattern (viewer/base/sampling.py): properties checked
directly, independent of any render."""

from __future__ import annotations

import numpy as np
import pytest

from viewer.base.sampling import progressive_offsets, sample_offsets


@pytest.mark.parametrize("seed", [0, 1, 7, 12345])
def test_sample_zero_is_the_centre_and_all_lie_in_the_pixel(seed):
    for n in (1, 2, 3, 16, 100):
        o = sample_offsets(n, seed)
        assert o.shape == (n, 2)
        assert tuple(o[0]) == (0.5, 0.5)
        assert np.all(o >= 0.0) and np.all(o < 1.0)


@pytest.mark.parametrize("seed", [0, 3, 99])
@pytest.mark.parametrize("m", [1, 2, 3, 4, 5, 6])
def test_power_of_two_prefixes_are_0_m_2_nets(seed, m):
    """Every elementary rectangle of area 2^-m (2^a x 2^(m-a) cells) holds
    exactly one of the first 2^m points."""
    n = 2 ** m
    o = sample_offsets(n, seed)
    for a in range(m + 1):
        cols, rows = 2 ** a, 2 ** (m - a)
        cell = np.floor(o[:, 0] * cols).astype(int) * rows + np.floor(o[:, 1] * rows).astype(int)
        assert np.array_equal(np.sort(cell), np.arange(n)), (a, m)


def test_prefixes_are_the_same_points():
    """A pixel that stops after k samples used exactly the first k of any
    longer pattern (the adaptive sampler relies on it)."""
    long = progressive_offsets(256, 4)
    for k in (1, 5, 64, 100):
        assert np.array_equal(progressive_offsets(k, 4), long[:k])


def test_seeds_change_the_pattern_deterministically():
    a, b = sample_offsets(16, 0), sample_offsets(16, 1)
    assert not np.array_equal(a[1:], b[1:])
    assert np.array_equal(a, sample_offsets(16, 0))


def test_the_mean_of_a_smooth_function_converges_fast():
    """Quasi-Monte Carlo: the integral of a smooth function over the pixel to
    well below what independent random points give (1/sqrt(n))."""
    f = lambda o: np.sin(3.0 * o[:, 0]) * np.exp(o[:, 1])   # noqa: E731
    exact = (1 - np.cos(3.0)) / 3.0 * (np.e - 1)
    for n in (64, 256, 1024):
        err = abs(f(sample_offsets(n, 2)).mean() - exact)
        assert err < 0.2 / n ** 0.75 + 0.5 / n, (n, err)


def test_rejects_no_samples():
    with pytest.raises(ValueError):
        sample_offsets(0)


def test_seeds_give_nearly_independent_estimates_of_an_edge():
    """Owen scrambling: the coverage of a straight edge estimated with two
    different seeds has errors that are nearly uncorrelated, and their mean
    square falls faster than 1/n (the centre sample is fixed, so a small
    common part remains at low counts).  The bench and --max-error estimate
    a reference's own noise from two seeds."""
    rng = np.random.default_rng(0)
    pats = {n: np.stack([sample_offsets(n, s) for s in range(400)]) for n in (16, 64)}
    grid = (np.stack(np.meshgrid(*(2 * [(np.arange(1024) + 0.5) / 1024])), -1).reshape(-1, 2))
    mse = {16: [], 64: []}
    corr = []
    for _ in range(12):
        a = rng.uniform(0, 2 * np.pi)
        normal, c = np.array([np.cos(a), np.sin(a)]), rng.uniform(0.3, 0.7, 2)
        exact = np.mean((grid - c) @ normal > 0)
        for n, p in pats.items():
            err = np.mean((p - c) @ normal > 0, axis=1) - exact      # one estimate per seed
            mse[n].append(np.mean(err ** 2))
            if n == 64 and err.std() > 0:
                corr.append(np.corrcoef(err[0::2], err[1::2])[0, 1])
    assert abs(np.mean(corr)) < 0.1
    assert np.mean(mse[64]) < np.mean(mse[16]) / 4 / 1.5      # better than Monte Carlo's 1/n


def test_offsets_are_a_fresh_copy_each_call():
    # the pattern is cached (a timed render asks for it every frame); a
    # caller that edits its copy must not change anyone else's
    from viewer.base.sampling import progressive_offsets, sample_offsets

    first = sample_offsets(4, 3)
    first[:] = -1.0
    assert np.array_equal(sample_offsets(4, 3), progressive_offsets(4, 3))
