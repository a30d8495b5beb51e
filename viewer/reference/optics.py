"""What happens to light at and between the reference tracer's surfaces:
exact dielectric Fresnel reflectance, Snell refraction, and Beer–Lambert
absorption along a path through a medium.

Invariants: all float64 and row-wise ((N,) cosines and iors, (N, 3)
directions and absorption coefficients); directions are unit; where the
two iors are equal a surface reflects nothing and bends nothing (so an
interface between equal media is invisible); under total internal
reflection the reflectance is exactly 1 and there is no refracted ray.
"""

from __future__ import annotations

import numpy as np

from .vectors import dot, normalize

__all__ = ["fresnel_dielectric", "refract", "transmittance"]


def fresnel_dielectric(cos_i, n1, n2) -> np.ndarray:
    """Exact unpolarised Fresnel reflectance for a ray in a medium of ior n1
    meeting one of ior n2 at incidence cosine cos_i (>= 0); 1 under total
    internal reflection, exactly 0 where n1 == n2."""
    cos_i = np.clip(np.asarray(cos_i, dtype=np.float64), 0.0, 1.0)
    n1 = np.asarray(n1, dtype=np.float64)
    n2 = np.asarray(n2, dtype=np.float64)
    eta = n1 / n2
    sin_t2 = eta * eta * (1.0 - cos_i * cos_i)
    tir = sin_t2 >= 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin_t2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
        rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)
        R = 0.5 * (rs * rs + rp * rp)
    R = np.where(tir, 1.0, R)
    R = np.where(n1 == n2, 0.0, R)
    return R


def refract(d, n, n1, n2):
    """Snell refraction of unit directions d at unit normals n (either
    orientation) from ior n1 into n2.  Returns (dirs, ok); ok is False under
    total internal reflection (dirs then 0).  Where n1 == n2 the direction is
    d itself."""
    d = np.asarray(d, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(n, dtype=np.float64).reshape(-1, 3)
    n1 = np.broadcast_to(np.asarray(n1, dtype=np.float64), (len(d),))
    n2 = np.broadcast_to(np.asarray(n2, dtype=np.float64), (len(d),))
    nf = np.where((dot(n, d) > 0.0)[:, None], -n, n)  # facing the incoming ray
    cos_i = np.clip(-dot(nf, d), 0.0, 1.0)
    eta = n1 / n2
    k = 1.0 - eta * eta * (1.0 - cos_i * cos_i)
    ok = k >= 0.0
    t = eta[:, None] * d + (eta * cos_i - np.sqrt(np.maximum(k, 0.0)))[:, None] * nf
    t = normalize(np.where(ok[:, None], t, d))
    t = np.where((n1 == n2)[:, None], d, t)
    t = np.where(ok[:, None], t, 0.0)
    return t, ok


def transmittance(a: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Beer–Lambert: exp(-a s) per channel; a (N,3) >= 0, s (N,) >= 0 possibly inf (0 * inf -> 1)."""
    s = np.asarray(s, dtype=np.float64)[:, None]
    with np.errstate(invalid="ignore", over="ignore"):
        out = np.exp(-a * s)
    return np.where(a == 0.0, 1.0, out)
