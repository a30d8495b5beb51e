"""The sub-pixel sample pattern shared by the GPU renderer and the reference.

Sample 0 is always the pixel centre (so ``samples = 1`` is the centred ray the
spec asks for); samples 1..n-1 are stratified: with m = ceil(sqrt(n)) the pixel
is cut into m x m cells, a seeded permutation picks distinct cells and a
seeded jitter places the sample uniformly inside its cell.  Every jittered
sample is uniform over the pixel, so the average converges to the box-filtered
pixel; the same seed gives the same pattern.
"""

from __future__ import annotations

import math

import numpy as np


def sample_offsets(n: int, seed: int = 0) -> np.ndarray:
    """(n, 2) float64 offsets (u, v) in [0, 1)^2; u to the right, v downward."""
    if n < 1:
        raise ValueError("need at least one sample")
    out = np.empty((n, 2), dtype=np.float64)
    out[0] = (0.5, 0.5)
    if n > 1:
        m = math.ceil(math.sqrt(n - 1))
        rng = np.random.default_rng(seed)
        cells = rng.permutation(m * m)[: n - 1]
        jitter = rng.random((n - 1, 2))
        out[1:, 0] = (cells % m + jitter[:, 0]) / m
        out[1:, 1] = (cells // m + jitter[:, 1]) / m
    return out


def _sobol2(n: int) -> np.ndarray:
    """(n, 2) uint64: the first n points of the 2-D Sobol' sequence as 32-bit
    fixed-point fractions (dimension 1 is van der Corput's radical inverse,
    dimension 2 uses the direction numbers of the polynomial x + 1).  Every
    prefix of 2^m points is a (0, m, 2)-net: each of the 2^m elementary
    intervals of any shape holds exactly one point."""
    k = np.arange(n, dtype=np.uint64)
    x = np.zeros(n, dtype=np.uint64)
    y = np.zeros(n, dtype=np.uint64)
    v = np.uint64(1 << 31)
    for j in range(32):
        bit = (k >> np.uint64(j)) & np.uint64(1)
        on = bit.astype(bool)
        x[on] ^= np.uint64(1 << (31 - j))
        y[on] ^= v
        v = v ^ (v >> np.uint64(1))
    return np.stack([x, y], axis=1)


def progressive_offsets(n: int, seed: int = 0) -> np.ndarray:
    """(n, 2) offsets for adaptive sampling, where pixels stop after different
    numbers of samples, so every prefix must be evenly spread: the 2-D
    Sobol' sequence, digitally shifted by 1/2 so that point 0 is the pixel
    centre (sample 0 is centred, as everywhere).  The seed picks one of the
    square's eight symmetries and a digital shift below 2^-6 of the later
    points (both keep the net property of the first 64 points); point 0
    stays exactly at the centre.  Each sample is uniform over the pixel in
    distribution, so the mean converges to the box-filtered pixel."""
    if n < 1:
        raise ValueError("need at least one sample")
    rng = np.random.default_rng(seed)
    jitter = rng.integers(0, 1 << 26, size=2, dtype=np.uint64)
    half = np.uint64(1 << 31)
    pts = ((_sobol2(n) ^ half ^ jitter).astype(np.float64) + 0.5) / float(1 << 32)
    sym = int(rng.integers(0, 8))
    if sym & 1:
        pts[:, 0] = 1.0 - pts[:, 0]
    if sym & 2:
        pts[:, 1] = 1.0 - pts[:, 1]
    if sym & 4:
        pts = pts[:, ::-1]
    out = np.ascontiguousarray(np.clip(pts, 0.0, np.nextafter(1.0, 0.0)))
    out[0] = (0.5, 0.5)
    return out
