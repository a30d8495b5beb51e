"""Chain footprints: footprint samples of the checker seen through glass.
Where a pixel's four corner rays follow one principal chain (the refracted
branch at every crossing) across the same surfaces and end on one checkered
plane, the homography through the four points they reach stands in for the
map from the pixel's square to the plane, where it predicts the
neighbouring corners within CHAIN_TOLERANCE (step 3 of
viewer/adaptive/render.py's docstring).  Pure numpy: the footprint mask
(viewer/gpu/footprint.py) uploads what chain_footprints finds.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..gpu.footprint import checkered_planes, pixel_corners

#: Chain footprints (chain_footprints): a pixel's homography through its
#: four corners' points must predict its eight neighbouring corners within
#: 8 x this share of its footprint's size (its square's side on the plane),
#: i.e. (a smooth map's error inside the square being about an eighth of
#: its error one pixel out: u (u - 1) is -1/4 at u = 1/2 and 2 at u = -1)
#: put every point of the square within this share of where the map puts
#: it: a bound on the error of the shares, as a share of the pixel.  A
#: sample of the pixel whose own point is further off takes a point
#: sample.  Measured at 320x180 (adaptive <=4 / <=12, RMSE): 0.01 gives
#: 2.55e-3 / 1.73e-3 on glass-sphere, 0.02 2.07e-3 / 1.18e-3, 0.04
#: 1.96e-3 / 1.15e-3; at <=32, 0.02 leaves 8.07e-4 where point samples
#: reach 7.85e-4 (the bias it allows).
CHAIN_TOLERANCE = 0.02
#: The extrapolation factor of that check (see above).
CHAIN_REACH = 8.0


def square_homography(p: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rows (X, Z, W) of the homography taking the unit square's
    corners (u, v) = (0, 0), (1, 0), (0, 1), (1, 1) to the points p (..., 4,
    2) in that order (pixel_corners' order: top-left, top-right, bottom-left,
    bottom-right): x = X . w / W . w, z = Z . w / W . w, w = (u, v, 1), W =
    (g, h, 1) (Heckbert's square-to-quad map).  NaN where the four points
    are degenerate."""
    p0, p1, p3, p2 = p[..., 0, :], p[..., 1, :], p[..., 2, :], p[..., 3, :]   # around the square
    sig = p0 - p1 + p2 - p3
    d1, d2 = p1 - p2, p3 - p2

    def det(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    with np.errstate(divide="ignore", invalid="ignore"):
        den = det(d1, d2)
        g = det(sig, d2) / den
        h = det(d1, sig) / den
    out = np.empty(p.shape[:-2] + (3, 3))
    for row, axis in ((0, 0), (1, 1)):
        out[..., row, 0] = p1[..., axis] - p0[..., axis] + g * p1[..., axis]
        out[..., row, 1] = p3[..., axis] - p0[..., axis] + h * p3[..., axis]
        out[..., row, 2] = p0[..., axis]
    out[..., 2, 0], out[..., 2, 1], out[..., 2, 2] = g, h, 1.0
    return out


def apply_homography(m: np.ndarray, u, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, z, W . w) of square point (u, v) under rows m (..., 3, 3)."""
    w = m[..., 2, 0] * u + m[..., 2, 1] * v + m[..., 2, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = (m[..., 0, 0] * u + m[..., 0, 1] * v + m[..., 0, 2]) / w
        z = (m[..., 1, 0] * u + m[..., 1, 1] * v + m[..., 1, 2]) / w
    return x, z, w


class ChainFootprints(NamedTuple):
    """The chain footprints of an image (chain_footprints): the pixels that
    have one, as flat indices j * W + i in increasing order, and each one's
    three texels (footprint.glsl), (n, 12) float32: (X, id, Z, k + 1, W,
    tolerance^2)."""
    pixels: np.ndarray
    texels: np.ndarray
    shape: tuple[int, int]            # (H, W)

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: the pixels with a chain footprint."""
        out = np.zeros(self.shape[0] * self.shape[1], bool)
        out[self.pixels] = True
        return out.reshape(self.shape)

    def dense(self) -> np.ndarray:
        """(H, W, 12): each pixel's texels, zero where it has none."""
        out = np.zeros((self.shape[0] * self.shape[1], 12), np.float32)
        out[self.pixels] = self.texels
        return out.reshape(self.shape + (12,))


def chain_footprints(scene, chain: np.ndarray, planes: np.ndarray | None = None) -> ChainFootprints:
    """The chain footprints (ChainFootprints) from the corner rays.

    chain (H + 1, W + 1, 4): each corner ray's chainLeaf (x, z camera-
    relative, chain id, object; object -1: none).  A pixel has a chain
    footprint where its four corners end their principal chain on one
    checkered plane k along one chain other than the camera ray itself (id
    0: footprint_planes' kind, and so are the pixels planes marks), the
    homography through their points keeps W > 0 over the square, and it
    predicts the eight neighbouring corners (on the same chain) within
    CHAIN_REACH x CHAIN_TOLERANCE of the square's side on the plane."""
    hh, ww = chain.shape[0] - 1, chain.shape[1] - 1
    none = ChainFootprints(np.zeros(0, np.int64), np.zeros((0, 12), np.float32), (hh, ww))
    if hh < 3 or ww < 3:
        return none
    # whole numbers, compared as floats; contiguous (a strided view of the
    # grid makes each comparison below several times slower)
    obj, ident = np.ascontiguousarray(chain[..., 3]), np.ascontiguousarray(chain[..., 2])
    # the pixels whose four corners share their top-left one's object and
    # chain id, that id not the camera ray's own (0) and the object not the sky
    o0, i0 = obj[:-1, :-1], ident[:-1, :-1]
    ok = (i0 != 0) & (o0 >= 0)
    for o, c in zip(pixel_corners(obj)[1:], pixel_corners(ident)[1:]):
        ok &= (o == o0) & (c == i0)
    if planes is not None:
        ok &= planes < 0
    # the image's border pixels have no neighbouring corners on every side
    ok[0], ok[-1], ok[:, 0], ok[:, -1] = False, False, False, False
    jj, ii = np.nonzero(ok)
    k = np.rint(o0[jj, ii]).astype(np.int64)
    on_checker = checkered_planes(scene)[k]
    jj, ii, k = jj[on_checker], ii[on_checker], k[on_checker]
    if len(jj) == 0:
        return none
    pts = chain[..., :2]                       # only the candidates' corners are read
    quad = np.stack([pts[jj, ii], pts[jj, ii + 1], pts[jj + 1, ii], pts[jj + 1, ii + 1]], axis=1).astype(np.float64)
    m = square_homography(quad)
    good = np.isfinite(m).all(axis=(1, 2))
    for u, v in ((0, 0), (1, 0), (0, 1), (1, 1)):
        good &= apply_homography(m, u, v)[2] > 0.0
    # the side of the square on the plane: sqrt of the quad's area
    d = quad[:, 3] - quad[:, 0], quad[:, 2] - quad[:, 1]
    side = np.sqrt(0.5 * np.abs(d[0][:, 0] * d[1][:, 1] - d[0][:, 1] * d[1][:, 0]))
    worst = np.zeros(len(jj))
    c = ident[jj, ii]
    for du, dv in ((-1, 0), (-1, 1), (2, 0), (2, 1), (0, -1), (1, -1), (0, 2), (1, 2)):
        r, q = jj + dv, ii + du
        good &= (obj[r, q] == k) & (ident[r, q] == c)
        x, z, w = apply_homography(m, float(du), float(dv))
        good &= w > 0.0
        with np.errstate(invalid="ignore"):
            worst = np.maximum(worst, np.hypot(x - pts[r, q, 0], z - pts[r, q, 1]))
    tol = CHAIN_TOLERANCE * side
    good &= np.isfinite(worst) & (worst <= CHAIN_REACH * tol) & (side > 0.0)
    jj, ii, m, k, c, tol = jj[good], ii[good], m[good], k[good], c[good], tol[good]
    texels = np.empty((len(jj), 12), np.float32)
    texels[:, 0:3], texels[:, 3] = m[:, 0], c
    texels[:, 4:7], texels[:, 7] = m[:, 1], k + 1
    texels[:, 8:11], texels[:, 11] = m[:, 2], tol * tol
    return ChainFootprints(jj * ww + ii, texels, (hh, ww))      # np.nonzero's order: increasing
