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
