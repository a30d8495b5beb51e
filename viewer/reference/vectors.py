"""Row-wise float64 vector helpers shared by the reference tracer's modules.

Invariants: arrays are (N, 3) rows of float64 (the last axis is the
vector); nothing is clamped or guarded, so a zero vector normalises to NaN
and the callers decide what such a row means.
"""

from __future__ import annotations

import numpy as np

__all__ = ["dot", "normalize"]


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-by-row dot product of two (N, 3) arrays: (N,)."""
    return np.einsum("ij,ij->i", a, b)


def normalize(v: np.ndarray) -> np.ndarray:
    """Each row (along the last axis) divided by its length."""
    return v / np.linalg.norm(v, axis=-1, keepdims=True)
