"""The estimates an adaptive render (viewer/adaptive/render.py) is steered
by: the contrasts and edges that flag a pixel from its five first rays
(step 1 of render.py's docstring), each pixel's error from its own samples
(step 2), and the choice of the pixels that get more samples next.  Pure
numpy: no GL.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..gpu.footprint import checker_sizes, fold, pixel_corners
from ..gpu.block import camera_uniforms

# Samples per pixel: 1, then FIRST_ROUND for every flagged pixel, then
# doublings (4, 8, 16, ...) for the pixels chosen round by round; powers of
# two are where the Sobol' points form nets.  Measured against rounds of 4x:
# lower RMSE at the same budget on glass-sphere and whitted-exact.
FIRST_ROUND = 4
ROUND_FACTOR = 2
SLIVER = 0.1
#: The spread term: standard error x n^(1/2 - SPREAD_EXPONENT), i.e. the
#: sample spread over n^SPREAD_EXPONENT (a net's rate on an edge; measured
#: here: RMSE over the edge pixels of glass-sphere falls as n^-0.75 to
#: n^-0.89 from 4 to 256 samples), weighted SPREAD_WEIGHT against the
#: prefix difference.
SPREAD_EXPONENT = 0.75
SPREAD_WEIGHT = 0.5
#: A pixel's error is at least this share of its worst neighbour's.
NEIGHBOUR_SHARE = 0.25


# numpy reduces a short last axis (the colour channels) an order of magnitude
# slower than it applies a ufunc pairwise: these helpers do the latter (and
# gpu.footprint.fold for a list of arrays).
def _channel_max(a: np.ndarray) -> np.ndarray:
    """The largest of the (..., 3) channels."""
    return np.maximum(np.maximum(a[..., 0], a[..., 1]), a[..., 2])


def _channel_sum(a: np.ndarray) -> np.ndarray:
    """The sum of the (..., 3) channels."""
    return a[..., 0] + a[..., 1] + a[..., 2]


def _neighbourhood(a: np.ndarray, reduce) -> np.ndarray:
    """reduce over the 3x3 neighbourhood of every pixel (edges replicated) of
    an (H, W, ...) array; reduce is np.maximum or np.minimum."""
    # separable: along rows, then along columns (4 reductions, not 9)
    rows = a.copy()
    reduce(rows[:, 1:], a[:, :-1], out=rows[:, 1:])
    reduce(rows[:, :-1], a[:, 1:], out=rows[:, :-1])
    out = rows.copy()
    reduce(out[1:], rows[:-1], out=out[1:])
    reduce(out[:-1], rows[1:], out=out[:-1])
    return out


def colour_contrast(image: np.ndarray) -> np.ndarray:
    """(H, W): the largest difference, over the 3x3 neighbourhood and the
    colour channels, between a pixel's colour and its neighbours'."""
    hi = _neighbourhood(image, np.maximum)
    lo = _neighbourhood(image, np.minimum)
    return _channel_max(np.maximum(hi - image, image - lo))


def corner_contrast(corner_colour: np.ndarray, centre_colour: np.ndarray) -> np.ndarray:
    """(H, W): max - min over a pixel's four corner colours and its centre
    colour, largest channel (corner_colour (H + 1, W + 1, 3))."""
    five = pixel_corners(corner_colour) + [centre_colour]
    return _channel_max(fold(np.maximum, five) - fold(np.minimum, five))


def corner_objects_differ(corner_obj: np.ndarray, centre_obj: np.ndarray) -> np.ndarray:
    """(H, W) bool: a pixel's four corner rays and centre ray do not all
    meet the same object first (-1: the sky)."""
    five = pixel_corners(corner_obj) + [centre_obj]
    return fold(np.maximum, five) != fold(np.minimum, five)


def corner_chains_differ(corner_chain: np.ndarray) -> np.ndarray:
    """(H, W) bool: a pixel's four corner rays do not all follow the same
    principal chain (corner_chain (H + 1, W + 1, 4): the corner pass's
    chainLeaf, the chain id in [..., 2]; 0 for a ray that crosses nothing)."""
    four = pixel_corners(np.ascontiguousarray(corner_chain[..., 2]))
    return fold(np.maximum, four) != fold(np.minimum, four)


def corner_directions(scene, width: int, height: int) -> np.ndarray:
    """(H + 1, W + 1, 3) unit directions of the camera rays through the
    corners of the pixel grid (the spec's pinhole camera, from the vectors
    the shader gets: continuous pixel position (x, y) looks along camForward
    + (2x/W - 1) camRight + (1 - 2y/H) camUp), top-left corner first."""
    cam = {k: np.array(v) for k, v in camera_uniforms(scene, width, height).items()}
    a = 2.0 * np.arange(width + 1) / width - 1.0
    b = 1.0 - 2.0 * np.arange(height + 1) / height
    d = cam["camForward"] + a[None, :, None] * cam["camRight"] + b[:, None, None] * cam["camUp"]
    return d / np.sqrt(_channel_sum(d * d))[..., None]


def checker_cells_differ(scene, t: np.ndarray, obj: np.ndarray) -> np.ndarray:
    """(H, W) bool from the corner rays' first interactions (t, obj: (H + 1,
    W + 1); t = inf, obj = -1 for the sky): all four corners of the pixel
    land on one checkered surface (whose two colours differ), in different
    squares of its checker.  Then a checker edge crosses the pixel's
    footprint even where the five colours agree: two squares diagonal to
    each other have the same colour, and a square's corner can poke into
    the pixel between its corners."""
    h, w = t.shape[0] - 1, t.shape[1] - 1
    size = checker_sizes(scene)
    out = np.zeros((h, w), bool)
    if not np.isfinite(size).any():
        return out
    eye = np.array(scene.camera.position, dtype=np.float64)
    s = size[np.where(obj >= 0, obj, -1)]
    ok = np.isfinite(t) & np.isfinite(s)
    p = eye + corner_directions(scene, w, h) * np.where(ok, t, 0.0)[..., None]
    s = np.where(ok, s, 1.0)
    same = fold(np.logical_and, [c_ok & (c_obj == pixel_corners(obj)[0])
                                 for c_ok, c_obj in zip(pixel_corners(ok), pixel_corners(obj))])
    for axis in (0, 2):                                  # the squares are in world x and z
        cells = np.where(ok, np.floor(p[..., axis] / s), 0.0)
        q = pixel_corners(cells)
        out |= same & (fold(np.maximum, q) != fold(np.minimum, q))
    return out


class Sums(NamedTuple):
    """Per-pixel sums over a pixel's samples 0..n-1, top row first: total
    (H, W, 4) = sum (L, 1); square (H, W) = sum L.L."""
    total: np.ndarray
    square: np.ndarray

    @property
    def count(self) -> np.ndarray:
        return self.total[..., 3]

    @property
    def mean(self) -> np.ndarray:
        return self.total[..., :3] / np.maximum(self.total[..., 3:], 1)


def standard_error(sums: Sums) -> np.ndarray:
    """(H, W): sqrt(s^2 / n) with s^2 the sample variance of L summed over
    the channels (an upper bound of every channel's); 0 below two samples."""
    n = sums.count
    mean = sums.mean
    var = np.maximum(sums.square / np.maximum(n, 1) - _channel_sum(mean * mean), 0.0)
    var = var * n / np.maximum(n - 1, 1)
    return np.where(n > 1, np.sqrt(var / np.maximum(n, 1)), 0.0)


def prefix_error(total: np.ndarray, prev: np.ndarray) -> np.ndarray:
    """(...): a pixel's error at n samples from how far its mean moved since
    it had p of them (total, prev: (..., 4) sums (L, 1) at n and p, 0 < p <
    n), largest channel.  Were the samples independent, the difference would
    have rms sigma sqrt((n - p) / (n p)) against the error's sigma /
    sqrt(n): error = sqrt(p / (n - p)) |mean_n - mean_p| (the difference
    itself for a doubling).  A net's error falls faster than that, so this
    leans to over- rather than under-estimating.  0 where p = 0."""
    n, p = total[..., 3], prev[..., 3]
    ok = (p > 0) & (n > p)
    mean_n = total[..., :3] / np.maximum(n, 1)[..., None]
    mean_p = prev[..., :3] / np.maximum(p, 1)[..., None]
    k = np.sqrt(p / np.maximum(n - p, 1))
    return np.where(ok, k * _channel_max(np.abs(mean_n - mean_p)), 0.0)


def spread_error(sums: Sums) -> np.ndarray:
    """The spread term: the samples' spread (summed over channels) over
    n^SPREAD_EXPONENT; 0 below two samples."""
    n = np.maximum(sums.count, 1)
    return standard_error(sums) * n ** (0.5 - SPREAD_EXPONENT)


def sliver_error(contrast: np.ndarray, n) -> np.ndarray:
    """What n samples that all agree may still miss: an edge of contrast C
    (the pixel's, from its five first rays) whose sliver inside the pixel
    falls between them, about 1/n of the pixel at most, SLIVER x C / n.
    Without this a pixel next to an edge stops as soon as its samples
    agree."""
    return SLIVER * contrast / np.maximum(n, 1)


def own_error(sums: Sums, prev: np.ndarray, contrast: np.ndarray) -> np.ndarray:
    """A pixel's error estimate from its own samples (the prefix difference
    against `prev`, the sums at its previous count, and the spread term)
    and from what they may have missed (sliver_error)."""
    e = (1.0 - SPREAD_WEIGHT) * prefix_error(sums.total, prev) + SPREAD_WEIGHT * spread_error(sums)
    return np.maximum(e, sliver_error(contrast, sums.count))


def with_neighbours(own: np.ndarray) -> np.ndarray:
    """At least NEIGHBOUR_SHARE of the worst neighbour's error: errors lie
    along edges, so a pixel whose few samples happen to agree beside one
    that disagrees is not done."""
    return np.maximum(own, NEIGHBOUR_SHARE * _neighbourhood(own, np.maximum))


def estimated_error(sums: Sums, prev: np.ndarray, contrast: np.ndarray) -> np.ndarray:
    """(H, W): what a pixel's mean is estimated to be off by (what the
    render's rounds rank pixels by)."""
    return with_neighbours(own_error(sums, prev, contrast))


def next_count(n):
    """The samples a pixel at n has after its next upgrade: FIRST_ROUND
    from one, else ROUND_FACTOR x n."""
    n = np.asarray(n)
    return np.where(n <= 1, FIRST_ROUND, n * ROUND_FACTOR)


def choose_by_gain(want: np.ndarray, error: np.ndarray, count: np.ndarray, left: int,
                   share: float = 0.5, floor: float = 0.0, cost: np.ndarray | None = None) -> np.ndarray:
    """The pixels of `want` to upgrade next (from n to next_count(n)
    samples): in order of error^2 / (n cost) (the squared error an upgrade
    removes per unit of work: per sample, times what a sample of the pixel
    costs, `cost`, 1 when None), as many as max(share x left, floor) pays
    for in samples, never more than `left` (at least one pixel's upgrade
    when affordable; ties by position)."""
    idx = np.flatnonzero(want.ravel())
    if len(idx) == 0:
        return np.zeros_like(want)
    n = count.ravel()[idx]
    samples = next_count(n) - n
    work = n if cost is None else n * cost.ravel()[idx]
    key = -(error.ravel()[idx] ** 2) / work
    # The order is by key, ties by position (idx is ascending: a stable
    # sort); what is taken is the longest prefix of it that spends at most
    # cap.  Only the prefix needs sorting: it holds at most cap / (fewest
    # samples) pixels, all among those with the k0 smallest keys.
    cap = min(max(share * left, floor, float(samples[np.argmin(key)])), left)
    if samples.sum() <= cap:
        take = np.arange(len(idx))
    else:
        k0 = int(cap // samples.min()) + 1
        cand = np.arange(len(idx))
        if k0 < len(idx):
            cand = np.flatnonzero(key <= np.partition(key, k0 - 1)[k0 - 1])   # ties at the cut included
        order = cand[np.argsort(key[cand], kind="stable")]
        take = order[np.cumsum(samples[order]) <= cap]
    out = np.zeros(want.size, bool)
    out[idx[take]] = True
    return out.reshape(want.shape)


def choose_within_budget(active: np.ndarray, error: np.ndarray, per_pixel: int, left: int) -> np.ndarray:
    """The active pixels that the next round can afford: all of them when
    `left` pixel-samples pay for `per_pixel` more each, else the ones with
    the largest estimated error (ties broken by position: deterministic)."""
    count = int(active.sum())
    if count * per_pixel <= left:
        return active
    k = left // per_pixel
    out = np.zeros_like(active)
    if k <= 0:
        return out
    idx = np.flatnonzero(active)
    order = np.argsort(-error.ravel()[idx], kind="stable")[:k]
    out.ravel()[idx[order]] = True
    return out
