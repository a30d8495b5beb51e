"""Adaptive anti-aliasing: samples go only to the pixels that still need them.

The error left in a correct Whitted image is almost all pixel footprint
(silhouettes, checker edges, the checker toward the horizon, the refracted
picture inside glass); a flat region is exact with one centred sample.  So:

1. Two passes find the pixels whose footprint is not flat.  The first traces
   sample 0 (the centre) of every pixel; the second one camera ray through
   every pixel corner ((W + 1) x (H + 1) rays, counted in the budget).  A
   straight edge that crosses a pixel's square leaves corners on both of its
   sides, so a pixel is flagged when its five rays (four corners, centre)
   differ in colour by more than max(target, FLAG_CONTRAST), or meet
   different objects where the colours differ by more than the target (or
   at all, where one of them is glass or a mirror), or follow different
   principal chains through glass (step 3), or land on one checkered
   surface in different squares of it (a square's
   corner can poke into a pixel without reaching any of its corners; this
   is exact for a footprint that is flat on the surface, so the checker
   toward the horizon, many squares per pixel, is flagged too).  Where one
   of the five rays meets something reflective or transparent (the picture
   in it bends: an edge need not be straight at the pixel's scale), the 3x3
   neighbourhood of centres counts as well, from THROUGH_CONTRAST up (half
   FLAG_CONTRAST: a refracted edge can pass between all five rays).  Every
   other pixel ends with one sample.
2. Flagged pixels get FIRST_ROUND samples.  Then, round by round, a pixel's
   error is estimated from its own samples: how far its mean moved since it
   had half as many (the prefix of a net is a coarser net, so this follows
   the faster-than-1/sqrt(n) convergence of evenly spread samples) averaged
   with a spread term (the standard error times n^(1/2 - SPREAD_EXPONENT):
   it sees every spread among the samples, even one that two halves share,
   at the convergence rate of a net), no less than what agreeing samples
   may still miss (SLIVER x the pixel's contrast / n; a pixel flagged by
   geometry alone, whose five rays agree in colour, takes UNSEEN_CONTRAST
   there: a rim seen edge-on is a line thinner than the gaps between its
   first samples), and no less than
   NEIGHBOUR_SHARE of the worst neighbour's (errors lie along edges).  The
   pixels above the target error whose error^2 / (n c) is largest double
   their samples, c being the rays the pixel's centre sample traced (so the
   order is by the squared error a doubling removes per unit of work: a
   sample through glass costs several of one on the floor), as many as
   ROUND_SHARE of the budget left pays for (at least MIN_ROUND of the
   whole).
3. Footprint samples: where a pixel's four corner rays meet one checkered
   plane first (and so, the set of directions that meet a plane being
   convex, does its whole square, unless another object pokes in), a
   camera ray that meets that plane takes the checker's colours mixed by
   their exact shares of the pixel's square (the box filter, in closed
   form: shaders/lib/footprint.glsl) instead of the colour at its point;
   its lighting stays its own.  So a checker edge costs no samples: such a
   pixel is flagged only by what else differs among its five rays (the
   checker's part of each ray's colour, which the first pass reports, taken
   out), and where no other edge crosses it, it ends with one sample.
   Where too many checker lines cross the pixel for the closed form, each
   sample takes the checker's exact average along its row of the pixel,
   and the pixel is flagged as a point-sampled one; nearer the horizon,
   point samples.  Chain footprints do the same for the checker seen through
   glass: where the four corner rays' principal chains (the refracted
   branch at every crossing) cross the same surfaces and end on one
   checkered plane, the homography through the four points they reach
   stands in for the map from the pixel's square to the plane, where it
   predicts the neighbouring corners within CHAIN_TOLERANCE
   (chain_footprints); such a pixel is flagged on its five rays' colours
   as they are (what else varies through glass can be far smaller than a
   pixel: a highlight).  On by default where the scene has a checkered plane
   (footprint=False: point samples only).  The corner rays are traced
   before the first pass, which then already takes footprint samples.
4. The budget is samples x W x H rays in all (the corner rays included),
   one pixel taking at most MAX_SPP_FACTOR x samples (its last upgrade
   goes to that cap where a doubling would pass it); the render stops when
   it is spent (or all but TAIL_SHARE of it: a last round of a few hundred
   samples costs more than it brings) or no pixel is above the target.
   Below 3 samples per pixel
   the corner rays would take most of the budget: there the 3x3
   neighbourhood of centres says where edges may be (and no footprint
   samples are taken).

Measured (README, "Adaptive anti-aliasing", and docs/adaptive.md; tools/adaptive_vs_uniform.py):
against a 512-sample float64 reference at 320x180 footprint samples reach
the error of 64 uniform samples with 4 rays per pixel on glass-sphere (5
before chain footprints; 0.74x of it at 4 since the closed form's wider
limits) and 6 on the default scene (7 before those limits, 11 before the
flags at glass boundaries whose sides look alike, and the cap's last
upgrade), in 0.29-0.33x of uniform 64's time.  With point samples only, this estimator
and the corner rays needed about 26 on glass-sphere, where the
3x3-neighbourhood flags and an
even/odd-halves estimate of the first version needed between 32 and 64.
(The even- and odd-index points of the scrambled Sobol' sequence lie in the
two halves of the pixel, so their difference measured a left/right
asymmetry, not the error.)  Ranked by each pixel's expected error instead
(tools/adaptive_bound.py: a perfect estimate), the same rounds would need
about 20: the limit is the share of pixels that hold edges, not the
estimate.

The GPU traces only listed pixels: a small framebuffer whose fragment
(x, y) traces the samples of the image pixel stored at (x, y) of a list
texture (its first sample index and count there too; the offsets come from
a texture), in coherent order (Z-order inside 8x8 image tiles, 4x4 blocks
of the list), one run of the list per culling group (viewer/culling.py:
each run is drawn by the shader compiled for the objects its tiles can
meet) and per sample count.  A short run is dealt over several bands of
64 rows (llvmpipe shades each 64x64 square of a framebuffer on one
thread), and where few pixels take a count, each one's samples are split
over several entries (the last rounds: a few glass pixels with 32 samples
each filled a few SIMD lanes of one thread).  Samples follow sampling.progressive_offsets,
so every prefix is evenly spread; everything is deterministic for a seed.
The target error is per pixel, in linear radiance units (the .npy values),
on the largest colour channel.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable, NamedTuple

import moderngl
import numpy as np

from ..base import interrupt
from ..gpu.packing import camera_uniforms
from ..gpu.renderer import intersect_rect
from ..base.sampling import progressive_offsets

# The per-pixel target (linear, largest channel) when none is given.
# Measured on glass-sphere at 320x180, budgets 8-24: 0.005 stops short of
# the budget (RMSE 2.45e-3 at 24 where 0.002 gives 2.07e-3); 0.001 and
# 0.0005 give the same errors as 0.002.
DEFAULT_TARGET_ERROR = 0.002
# Samples per pixel: 1, then FIRST_ROUND for every flagged pixel, then
# doublings (4, 8, 16, ...) for the pixels chosen round by round; powers of
# two are where the Sobol' points form nets.  Measured against rounds of 4x:
# lower RMSE at the same budget on glass-sphere and whitted-exact.
FIRST_ROUND = 4
ROUND_FACTOR = 2
# One pixel takes at most this many times the mean budget, and never more
# than MAX_SPP: an edge pixel may need far more than the average.  A pixel
# below the cap has room for one more upgrade, which stops at the cap: the
# default scene at 320x180, budget 7 (cap 56), held 6711 pixels at 32 with
# 76% of its squared error when only whole doublings were allowed (RMSE
# 2.43e-3; to the cap: 2.11e-3).  Measured against factor 16 (caps 96, 112
# for budgets 6, 7): no better on the default scene, and glass-sphere at
# budget 4 (cap 64) went from 2.08e-3 to 2.32e-3.
MAX_SPP_FACTOR = 8
MAX_SPP = 1024
SLIVER = 0.1
#: A pixel is flagged for more samples when the colours of its five rays
#: differ by more than this (or than the target error, whichever is larger).
FLAG_CONTRAST = 0.02
#: Where a pixel's five rays meet glass or a mirror, the 3x3 neighbourhood
#: of centres flags it above this contrast (or the target error) instead:
#: the picture there bends, and a refracted edge can pass between all five
#: rays with only its neighbours showing it.  The default scene at 320x180,
#: budget 8, with FLAG_CONTRAST here: 1814 pixels through the glass kept one
#: sample, 10 of them more than 0.01 off a 64-sample render (0.077 at worst:
#: the refracted rod's edge); with 0.01: 930, none 0.01 off, and RMSE
#: 1.78e-3 -> 1.71e-3 (0.005: the same; glass-sphere unchanged).
THROUGH_CONTRAST = 0.01
#: Flags that do not come from colour (other objects at the corners, other
#: checker squares) count only for a target below this: an edge of another
#: kind is taken to be about this large an error until samples say otherwise.
EDGE_ERROR = 0.1
#: The spread term: standard error x n^(1/2 - SPREAD_EXPONENT), i.e. the
#: sample spread over n^SPREAD_EXPONENT (a net's rate on an edge; measured
#: here: RMSE over the edge pixels of glass-sphere falls as n^-0.75 to
#: n^-0.89 from 4 to 256 samples), weighted SPREAD_WEIGHT against the
#: prefix difference.
SPREAD_EXPONENT = 0.75
SPREAD_WEIGHT = 0.5
#: The contrast the sliver term takes for a pixel flagged by geometry alone
#: (an object boundary with glass or a mirror on one side, or corner rays on
#: different principal chains) where its five rays' colours agree: what lies
#: between them is unseen, and the sky's and the floor's radiance are about
#: 1.  The default scene's glass rim seen edge-on is a dark line 1/25 of a
#: pixel thick (0.13 against 0.78): 4 to 16 samples that all missed it
#: agreed, and stopped, 0.04 off each, with 11.5% of the squared error left
#: at a budget of 8 (RMSE 1.87e-3; with this: 1.80e-3; 0.3: 1.81e-3; the
#: same for every geometry-flagged pixel: 1.81e-3).
UNSEEN_CONTRAST = 1.0
#: A pixel's error is at least this share of its worst neighbour's.
NEIGHBOUR_SHARE = 0.25
#: Scenes with this many objects or more take point samples only (the
#: footprint mask held k + 1 in an 8-bit texel when this was set; it is a
#: float texel now, which could name more, but no scene that large was
#: measured).
MAX_FOOTPRINT_OBJECTS = 255
#: How a pixel's footprint samples take the checker (the first pass reports
#: it): over the whole pixel, exactly, or along each sample's row.
FOOTPRINT_EXACT, FOOTPRINT_ROWS = 2, 1
#: The closed form of a pixel's checker share (footprint.glsl's
#: pixelCoverage) takes at most this many checker corners inside the pixel
#: and this many checker lines across it; beyond, each sample takes the
#: checker's exact average along its own row.  The first pass computes each
#: pixel's share once and the list passes read it, so the limits cost one
#: loop per pixel, not per entry.  Measured (default scene, 320x180, budget
#: 6; RMSE against uniform 64's): 16 and 32 left 3653 pixels near the
#: horizon on rows, which took 23 samples each and held 8% of the squared
#: error (1.15x); 400 and 100: 1459 pixels, 0.97x; 1600 and 200: 940,
#: 0.95x.  The first pass took 101, 105 and 113 ms of CPU.
MAX_PIXEL_CORNERS = 400
MAX_PIXEL_LINES = 100
#: Share of the budget left that one round may spend (the rest waits for
#: the better estimates the round brings), and the least share of the
#: whole budget a round may spend (no long tail of tiny rounds: each costs
#: a pass over the pixel list and its bookkeeping).
ROUND_SHARE = 0.5
MIN_ROUND = 0.05
#: No round starts once the budget left is below this share of the whole:
#: the last rounds of a render that spends its budget trace a few hundred
#: samples each (the default scene at 320x180, budget 7: 984, 176 and 24 of
#: 403,200) and cost a pass over a pixel list and its bookkeeping each
#: (measured, interleaved: 3-4% of the render's time; RMSE 2.011e-3 ->
#: 2.017e-3).
TAIL_SHARE = 0.01


@dataclass
class AdaptiveResult:
    image: np.ndarray                 # (H, W, 3) float32 linear, exposure applied
    spp: np.ndarray                   # (H, W) int32 samples per pixel
    rounds: list[tuple[int, int]] = field(default_factory=list)   # (pixel-samples traced, pixels drawn)
    rays: int = 0                     # camera rays traced in all (the corner rays included)

    def __iter__(self):               # image, spp = render_adaptive(...)
        return iter((self.image, self.spp))

    @property
    def mean_spp(self) -> float:
        return float(self.spp.mean())


# ---------------------------------------------------------------- pure parts


# numpy reduces a short last axis (the colour channels) or a list of arrays
# (stacked into one first) an order of magnitude slower than it applies a
# ufunc pairwise: these helpers do the latter.
def _channel_max(a: np.ndarray) -> np.ndarray:
    """The largest of the (..., 3) channels."""
    return np.maximum(np.maximum(a[..., 0], a[..., 1]), a[..., 2])


def _channel_sum(a: np.ndarray) -> np.ndarray:
    """The sum of the (..., 3) channels."""
    return a[..., 0] + a[..., 1] + a[..., 2]


def _fold(ufunc, arrays) -> np.ndarray:
    """ufunc applied pairwise over a list of arrays (ufunc.reduce of their stack)."""
    out = arrays[0]
    for a in arrays[1:]:
        out = ufunc(out, a)
    return out


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


def _corners(a: np.ndarray) -> list[np.ndarray]:
    """The four (H, W, ...) views of an (H + 1, W + 1, ...) corner grid:
    each pixel's top-left, top-right, bottom-left and bottom-right corner."""
    return [a[:-1, :-1], a[:-1, 1:], a[1:, :-1], a[1:, 1:]]


def corner_contrast(corner_colour: np.ndarray, centre_colour: np.ndarray) -> np.ndarray:
    """(H, W): max - min over a pixel's four corner colours and its centre
    colour, largest channel (corner_colour (H + 1, W + 1, 3))."""
    five = _corners(corner_colour) + [centre_colour]
    return _channel_max(_fold(np.maximum, five) - _fold(np.minimum, five))


def corner_objects_differ(corner_obj: np.ndarray, centre_obj: np.ndarray) -> np.ndarray:
    """(H, W) bool: a pixel's four corner rays and centre ray do not all
    meet the same object first (-1: the sky)."""
    five = _corners(corner_obj) + [centre_obj]
    return _fold(np.maximum, five) != _fold(np.minimum, five)


def corner_chains_differ(corner_chain: np.ndarray) -> np.ndarray:
    """(H, W) bool: a pixel's four corner rays do not all follow the same
    principal chain (corner_chain (H + 1, W + 1, 4): the corner pass's
    chainLeaf, the chain id in [..., 2]; 0 for a ray that crosses nothing)."""
    four = _corners(np.ascontiguousarray(corner_chain[..., 2]))
    return _fold(np.maximum, four) != _fold(np.minimum, four)


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


def checker_sizes(scene) -> np.ndarray:
    """(objects + 1,): the checker size of each object whose checker's two
    colours (or emissions) differ, inf for the others and for the last
    entry (the sky's -1)."""
    size = np.full(len(scene.objects) + 1, np.inf)
    for k, o in enumerate(scene.objects):
        m = scene.materials[o.material]
        c = m.checker
        if c is not None and (tuple(c.color) != tuple(m.color)
                              or (c.emission is not None and tuple(c.emission) != tuple(m.emission))):
            size[k] = c.size
    return size


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
    same = _fold(np.logical_and, [c_ok & (c_obj == _corners(obj)[0])
                                 for c_ok, c_obj in zip(_corners(ok), _corners(obj))])
    for axis in (0, 2):                                  # the squares are in world x and z
        cells = np.where(ok, np.floor(p[..., axis] / s), 0.0)
        q = _corners(cells)
        out |= same & (_fold(np.maximum, q) != _fold(np.minimum, q))
    return out


def checkered_planes(scene) -> np.ndarray:
    """(objects + 1,) bool: which objects are planes with a checker whose two
    colours differ (the last entry, for the sky's -1, is False)."""
    planes = np.array([o.type == "plane" for o in scene.objects] + [False])
    return planes & np.isfinite(checker_sizes(scene))


def footprint_default(scene) -> bool:
    """Whether adaptive renders of `scene` take footprint samples unless
    told otherwise: where it has a checkered plane and few enough objects
    for the footprint mask's texels."""
    return bool(checkered_planes(scene).any()) and len(scene.objects) < MAX_FOOTPRINT_OBJECTS


def footprint_planes(scene, corner_obj: np.ndarray) -> np.ndarray:
    """(H, W) int: for each pixel whose four corner rays all meet one
    checkered plane first (corner_obj (H + 1, W + 1)), that plane's object
    index, else -1.  There footprint samples replace point samples.  The
    directions that meet a plane are a convex set, so every ray of such a
    pixel meets that plane; only another object poking in between the
    corners could cover part of it (then a sample that meets the other
    object is a point sample, and the flags see the other object in the
    centre ray)."""
    four = _corners(corner_obj)
    hi, lo = _fold(np.maximum, four), _fold(np.minimum, four)
    return np.where((hi == lo) & checkered_planes(scene)[np.where(lo >= 0, lo, -1)], lo, -1)


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
#: Chain footprints per row of their texture (three texels each): a 1280x720
#: image's (46,000 on glass-sphere) in 45 rows, where one texel per pixel
#: would upload 44 MB.
CHAIN_ENTRIES_PER_ROW = 1024


def square_homography(p: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rows (X, Z, W) of the homography taking the unit square's
    corners (u, v) = (0, 0), (1, 0), (0, 1), (1, 1) to the points p (..., 4,
    2) in that order (_corners' order: top-left, top-right, bottom-left,
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
    for o, c in zip(_corners(obj)[1:], _corners(ident)[1:]):
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


@lru_cache(maxsize=16)
def _offsets(n: int, seed: int) -> np.ndarray:
    """progressive_offsets(n, seed), read-only and cached: scrambling takes
    about 8 ms (64 hashes of arrays), as much as a round's bookkeeping in a
    small render, and the viewer and the benchmark render again and again."""
    out = progressive_offsets(n, seed)
    out.setflags(write=False)
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


def drain(gen):
    """Run a generator of this module (a pass, the flags) to its end without
    pausing: what it returns."""
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value


# ---------------------------------------------------------------- the GPU part

#: Width of the pixel-list framebuffer (a multiple of LIST_BLOCK) and the
#: most fragments one draw call traces (the renderer's 512x512 tiles: no
#: draw long enough to trip a GPU watchdog).
LIST_WIDTH = 64
#: Samples traced per fragment and draw call at most.
MAX_BATCH = 32
MAX_LIST_HEIGHT = 16384
FRAGMENTS_PER_DRAW = 512 * 512
#: With AdaptiveSampler.sync_draws off (offscreen renders): pixel-samples
#: that may be queued before the driver is made to finish them (Ctrl-C,
#: taken between draws, then waits for at most this much).
MAX_QUEUED_FRAGMENTS = 4 * FRAGMENTS_PER_DRAW
#: Side of the blocks the pixel list is laid out in (llvmpipe shades 4x4
#: blocks; a GPU's warps are 2x2 quads, which the Z-order inside keeps).
LIST_BLOCK = 4
#: The least number of 64-row bands a pixel list spans (list_width).
LIST_MIN_BINS = 8


def _spread_bits(v: np.ndarray) -> np.ndarray:
    """Bits b0 b1 b2 ... of v (< 2^16) moved to b0 b2 b4 ... (Z-order keys)."""
    v = v.astype(np.int64)
    out = np.zeros_like(v)
    for bit in range(16):
        out |= ((v >> bit) & 1) << (2 * bit)
    return out


def z_index(i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """The Z-order (Morton) index of (i, j): i's bits in the even places."""
    return _spread_bits(i) | (_spread_bits(j) << 1)


def coherent_order(pixels: np.ndarray, width: int, tile: int = 8) -> np.ndarray:
    """Flat pixel indices (j * width + i) sorted by tile x tile squares of
    the image (row of squares by row of squares), in Z-order inside a square:
    neighbours in the list are neighbours in the image, so their rays take
    similar paths (less SIMD divergence), and 16 consecutive entries of a
    full square are one of its 4x4 blocks (what list_slots puts in one 4x4
    block of the list, the block a software rasteriser shades at once)."""
    i, j = pixels % width, pixels // width
    tiles_x = (width + tile - 1) // tile
    inside = np.arange(tile * tile)
    z = z_index(inside % tile, inside // tile)          # a table: the Z-order index inside a square
    key = ((j // tile) * tiles_x + i // tile) * (tile * tile) + z[(j % tile) * tile + i % tile]
    return pixels[np.argsort(key, kind="stable")]


@lru_cache(maxsize=4)
def image_coherent_order(width: int, height: int) -> np.ndarray:
    """coherent_order of every pixel of a width x height image (read-only,
    cached: the viewer restarts a render at every change of view)."""
    out = coherent_order(np.arange(width * height), width)
    out.setflags(write=False)
    return out


def list_width(count: int) -> int:
    """The width of the pixel list for `count` entries: LIST_WIDTH, or
    narrower (down to LIST_BLOCK) so that the list spans at least
    LIST_MIN_BINS rows of 64: llvmpipe shades each 64x64 square of a
    framebuffer on one thread, and a short list one square wide would run
    on one core.  Wider when MAX_LIST_HEIGHT rows would not hold it."""
    lw = LIST_WIDTH
    while lw > LIST_BLOCK and count < lw * 64 * LIST_MIN_BINS:
        lw //= 2
    if count > LIST_WIDTH * MAX_LIST_HEIGHT:
        lw = LIST_WIDTH * -(-count // (LIST_WIDTH * MAX_LIST_HEIGHT))
    return lw


def list_rows(count: int, list_width: int) -> int:
    """Rows of a list list_width wide that list_slots fills with `count`
    entries: whole blocks of LIST_BLOCK rows."""
    return LIST_BLOCK * max(1, -(-count // (LIST_BLOCK * list_width)))


def list_slots(count: int, list_width: int) -> np.ndarray:
    """Where list entries 0..count-1 go in a list list_width wide (a
    multiple of LIST_BLOCK = 4): texel indices y * list_width + x.  Runs of
    16 consecutive entries fill one 4x4 block of texels in Z-order, the
    blocks left to right, then the next row of blocks, so that a block the
    rasteriser shades together holds entries that are neighbours in the
    list (and, through coherent_order, in the image)."""
    k = np.arange(count, dtype=np.int64)
    per_block = LIST_BLOCK * LIST_BLOCK
    blocks_x = list_width // LIST_BLOCK
    b, r = k // per_block, k % per_block
    x = (r & 1) | ((r >> 1) & 2)              # the Z-order index r of a 4x4 block: x from the even bits,
    y = ((r >> 1) & 1) | ((r >> 2) & 2)       # y from the odd ones
    return ((b // blocks_x) * LIST_BLOCK + y) * list_width + (b % blocks_x) * LIST_BLOCK + x


#: Rows of the llvmpipe bins a framebuffer is cut into (64x64 squares, each
#: shaded by one thread).
BIN = 64


def run_bands(count: int, list_width: int) -> int:
    """How many bands of BIN rows a run of `count` entries is spread over:
    1 where it fills LIST_MIN_BINS bands or more (dense, list_slots), else
    as many as it has blocks of 16, at most LIST_MIN_BINS (run_slots)."""
    blocks = -(-count // (LIST_BLOCK * LIST_BLOCK))
    per_band = (list_width // LIST_BLOCK) * (BIN // LIST_BLOCK)
    if blocks >= LIST_MIN_BINS * per_band:
        return 1
    return max(1, min(LIST_MIN_BINS, blocks))


def run_rows(count: int, list_width: int, bands: int) -> int:
    """Rows a run of `count` entries takes in run_slots' layout."""
    if bands <= 1:
        return list_rows(count, list_width)
    blocks = -(-count // (LIST_BLOCK * LIST_BLOCK))
    in_first = -(-blocks // bands)                       # band 0 holds the most
    return BIN * (bands - 1) + LIST_BLOCK * -(-in_first // (list_width // LIST_BLOCK))


def run_slots(count: int, list_width: int, bands: int) -> np.ndarray:
    """Where a run's entries go (texel indices from the run's first row,
    which is a multiple of BIN when bands > 1): list_slots' blocks of 16,
    dealt round the `bands` bands of BIN rows (block b into band b % bands),
    so that a short run (a few pixels that take many samples: the last
    rounds' glass) is shaded by every thread instead of one."""
    if bands <= 1:
        return list_slots(count, list_width)
    k = np.arange(count, dtype=np.int64)
    b, r = k // (LIST_BLOCK * LIST_BLOCK), k % (LIST_BLOCK * LIST_BLOCK)
    x = (r & 1) | ((r >> 1) & 2)              # the Z-order inside a block, as in list_slots
    y = ((r >> 1) & 1) | ((r >> 2) & 2)
    s = b // bands                            # the block's place in its band
    blocks_x = list_width // LIST_BLOCK
    return (((b % bands) * BIN + (s // blocks_x) * LIST_BLOCK + y) * list_width
            + (s % blocks_x) * LIST_BLOCK + x)


#: A run of the pixel list (one group, one sample count) with fewer pixels
#: than this has each pixel's samples dealt to several entries (split_factor),
#: up to one sample each: a few pixels with many samples would otherwise fill
#: a few SIMD lanes of one thread.
MIN_RUN_ENTRIES = 512
#: The most samples one entry of a costly pixel traces (add_samples'
#: `cost`: where a sample traces more than HEAVY_RAYS rays, the glass): the
#: power of two nearest under ENTRY_RAYS / its rays per sample, at least 1.
#: The lanes of a SIMD block run each ray tree in step, as long as the
#: longest; more entries of one pixel in a block are more alike trees, and
#: a short list keeps every thread busy.  Measured, entries of at most 4
#: samples for every costly pixel (the rule before): a list pass over the
#: default scene's 10765 glass pixels, 16 samples each, took 436 ms as one
#: entry a pixel, 379 / 330 / 344 / 354 ms at 8 / 4 / 2 / 1 samples an
#: entry; but whole adaptive renders (320x180, 7 interleaved runs each,
#: CPU time) took 10-12% less at 2 or 1 on the default scene (26 rays a
#: glass sample), and 4-7% more on glass-sphere (6 rays a sphere sample),
#: hence a size by cost: 1 sample an entry on the default scene's glass, 4
#: on glass-sphere's sphere.  Not for the cheap pixels: every pixel at one
#: sample an entry took 731 ms against 518 (the entry's own work, a
#: footprint's closed form among it, is no longer small beside a sample of
#: the floor).
ENTRY_RAYS = 32
HEAVY_RAYS = 4


def entry_samples(cost: np.ndarray) -> np.ndarray:
    """The most samples one entry of each pixel traces (0: no limit), from
    its rays per sample `cost`: for a pixel above HEAVY_RAYS, the largest
    power of two at most ENTRY_RAYS / cost, and at least 1."""
    cost = np.asarray(cost, np.float64)
    most = np.exp2(np.floor(np.log2(np.maximum(ENTRY_RAYS / np.maximum(cost, 1.0), 1.0))))
    return np.where(cost > HEAVY_RAYS, most, 0).astype(np.int64)


def split_factor(length: int, samples: int, most: int | None = None) -> int:
    """Into how many entries each of a run's `length` pixels, taking
    `samples` more samples, is split: the least divisor d of samples with
    length x d >= MIN_RUN_ENTRIES and samples / d <= `most` (None: no
    limit), else samples (one sample an entry).  Equal parts: every entry
    of a run loops alike."""
    if samples <= 1:
        return 1
    most = samples if most is None else max(1, most)
    for d in range(1, samples):
        if samples % d == 0 and length * d >= MIN_RUN_ENTRIES and samples // d <= most:
            return d
    return samples


class AdaptiveSampler:
    """The GPU side for one image size: ``first_pass`` traces sample 0 of
    every pixel (with the first interaction of each camera ray),
    ``corner_pass`` the rays through the pixel corners, ``add_samples``
    more samples of a list of pixels only.  Results come back as arrays;
    the sums are kept by the caller.  Every pass draws each group of screen
    tiles with the renderer's culling variant for it."""

    FIRST = {"ADAPTIVE": 1, "ADAPTIVE_FIRST": 1}
    LIST = {"ADAPTIVE": 1, "ADAPTIVE_LIST": 1}
    #: the first and list passes' defines with footprint samples (trace.frag):
    #: the closed form's limits, and in the list passes the shares the first
    #: pass computed (read from the footprint mask, not computed per entry)
    FOOTPRINT = {"FOOTPRINT_AA": 1, "MAX_PIXEL_CORNERS": MAX_PIXEL_CORNERS, "MAX_PIXEL_LINES": MAX_PIXEL_LINES}
    FOOTPRINT_FIRST = {**FIRST, **FOOTPRINT}
    FOOTPRINT_LIST = {**LIST, **FOOTPRINT, "FOOTPRINT_SHARES": 1}
    #: a uniform render's samples with footprint samples (Renderer.render),
    #: and the pass that computes the shares they read (share_pass)
    FOOTPRINT_SAMPLES = {**FOOTPRINT, "FOOTPRINT_SHARES": 1, "FOOTPRINT_DIRECT_ONLY": 1}
    FOOTPRINT_SHARE_PASS = {**FOOTPRINT, "FOOTPRINT_SHARE_PASS": 1, "FOOTPRINT_DIRECT_ONLY": 1}
    #: the texture units of the footprint mask and of the chain footprints
    FOOTPRINT_UNIT = 3
    FOOTPRINT_CHAIN_UNIT = 4

    def __init__(self, renderer, width: int, height: int, footprint: bool = False):
        self.renderer = renderer
        #: whether set_footprint may turn footprint samples on (their variants
        #: are the ones compile() makes)
        self.footprint = bool(footprint)
        self._footprint_tex = None           # the mask set_footprint gave (None: point samples)
        self._footprint_texels = None        # its texels (H, W, 2): code, the first pass's share
        self._chain_tex = None               # its chain footprints (zeros: none)
        self.ctx: moderngl.Context = renderer.ctx
        self.width, self.height = width, height
        self._list_tex = None
        self._list_fbo = None
        self._list_targets: list = []
        self._list_size = (0, 0)
        self._offsets_tex = None
        self._mrt: dict[tuple[tuple[int, int], int], moderngl.Framebuffer] = {}
        self._labels_key, self._labels = None, None      # group_labels' last answer
        #: pixel-samples one draw call may trace; read before every draw, so
        #: the viewer can fit draws into its frame budget as it goes
        self.fragments_per_draw = FRAGMENTS_PER_DRAW
        self.last_draw_fragments = 0     # pixel-samples the latest draw traced
        #: finish every draw before its yield: the viewer times each draw to
        #: fit its frame.  An offscreen render (render_adaptive) turns it
        #: off: the driver then draws while Python prepares the next draw,
        #: and finishes at the read-back or after MAX_QUEUED_FRAGMENTS
        #: (measured, whole renders at 320x180, interleaved: 7-19% less
        #: wall time and 3-7% less CPU time, most at larger budgets; the
        #: images bit for bit the same)
        self.sync_draws = True
        self._queued = 0                 # pixel-samples drawn since the last finish
        #: deal the samples of short runs to several entries (add_samples);
        #: the viewer's display of a round in flight reads one texel per
        #: pixel (sums_target), so it turns this off
        self.split_entries = True
        self._in_flight = None           # (list framebuffer, texel of each entry) during add_samples
        #: what the checker's second colour adds to the colours the latest
        #: first pass ((H, W, 3)) and corner pass ((H + 1, W + 1, 3)) gave,
        #: where each camera ray's principal chain ends (0 off a checker;
        #: exposure applied)
        self.centre_checker = self.corner_checker = None
        #: (H, W) int8 from the latest first pass: how each pixel's footprint
        #: samples take the checker (FOOTPRINT_EXACT, FOOTPRINT_ROWS or 0: not)
        self.footprint_kind = None
        #: (H + 1, W + 1, 4) from the latest corner pass: each corner ray's
        #: chainLeaf (trace.frag; chain_footprints)
        self.corner_chain = None

    def _programs(self, defines: dict) -> list[tuple[moderngl.Program, tuple]]:
        """The renderer's (program, rectangles) pairs of these variant
        defines: its screen-tile culling variants (each exact everywhere; a
        variant not compiled yet is stood in for by the full shader)."""
        return self.renderer.programs_for(self.width, self.height, **defines)

    def compile(self) -> None:
        """Compile every shader variant the passes use at this size and
        camera now (the viewer's soak counts GL objects after it)."""
        for defines in ((self.FOOTPRINT_FIRST, self.FOOTPRINT_LIST) if self.footprint else (self.FIRST, self.LIST)):
            self.renderer.programs_for(self.width, self.height, compile_all=True, **defines)
        self.renderer.variant(**self.FIRST)              # the corner pass's (not culled)

    @property
    def first_defines(self) -> dict:
        return self.FOOTPRINT_FIRST if self._footprint_tex is not None else self.FIRST

    @property
    def list_defines(self) -> dict:
        return self.FOOTPRINT_LIST if self._footprint_tex is not None else self.LIST

    def set_footprint(self, planes: np.ndarray | None, chain: "ChainFootprints | None" = None) -> None:
        """Footprint samples (shaders/lib/footprint.glsl) from now on: on the
        plane `planes` gives for each pixel ((H, W) object index, -1: point
        samples; top row first; see footprint_planes) and, where it gives
        none, through the chain footprints `chain` (chain_footprints; None:
        none), or point samples everywhere (planes None)."""
        for tex in (self._footprint_tex, self._chain_tex):
            if tex is not None:
                tex.release()
        self._footprint_tex = self._chain_tex = None
        if planes is None:
            return
        if not self.footprint:
            raise ValueError("footprint samples need an AdaptiveSampler made with footprint=True")
        if planes.max() >= MAX_FOOTPRINT_OBJECTS:
            raise ValueError(f"footprint samples take object indices below {MAX_FOOTPRINT_OBJECTS}")
        # texel (RG32F, rows bottom first): in r k + 1 for a directly seen
        # plane k, -(e + 1) for chain footprint e, 0 for point samples (whole
        # numbers below 2^24: exact in a float); in g the pixel's share, -1
        # until the first pass has computed it (footprint.glsl)
        code = (planes + 1).astype(np.float32).ravel()
        n = 0 if chain is None else len(chain.pixels)
        if n:
            code[chain.pixels] = -1.0 - np.arange(n, dtype=np.float32)
        texels = np.full((self.height, self.width, 2), -1.0, np.float32)
        texels[..., 0] = code.reshape(self.height, self.width)[::-1]
        self._footprint_texels = texels
        self._footprint_tex = self.ctx.texture((self.width, self.height), 2, texels.tobytes(), dtype="f4")
        self._footprint_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        # the chain footprints, compact: entry e at texels (3 (e % C) + r, e // C)
        c = CHAIN_ENTRIES_PER_ROW
        rows = max(1, -(-n // c))
        texels = np.zeros((rows * c, 12), np.float32)
        if n:
            texels[:n] = chain.texels
        self._chain_tex = self.ctx.texture((3 * c, rows), 4, texels.tobytes(), dtype="f4")
        self._chain_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)

    def bind_footprint(self, prog) -> None:
        """Bind the footprint mask and chain footprints set_footprint gave to
        `prog` (a FOOTPRINT_AA variant), if it reads them."""
        if self._footprint_tex is not None and "footprintMask" in prog:
            self._footprint_tex.use(location=self.FOOTPRINT_UNIT)
            prog["footprintMask"].value = self.FOOTPRINT_UNIT
            if "footprintChain" in prog:
                self._chain_tex.use(location=self.FOOTPRINT_CHAIN_UNIT)
                prog["footprintChain"].value = self.FOOTPRINT_CHAIN_UNIT
                if "chainEntriesPerRow" in prog:
                    prog["chainEntriesPerRow"].value = CHAIN_ENTRIES_PER_ROW

    def group_labels(self, programs) -> np.ndarray:
        """(H, W) int8, top row first: which of `programs`' groups of
        rectangles each pixel is drawn by."""
        key = tuple(rects for _, rects in programs)
        if key != self._labels_key:                # the plan changes with the camera only
            w, h = self.width, self.height
            labels = np.full((h, w), -1, np.int8)
            for g, rects in enumerate(key):
                for x, y, rw, rh in rects:
                    labels[h - y - rh:h - y, x:x + rw] = g
            labels.setflags(write=False)
            self._labels_key, self._labels = key, labels
        return self._labels

    #: the channels of the ADAPTIVE_FIRST variants' outputs that are read
    #: back: (sum L, 1), L.L, (t, object, rays, the pixel's footprint
    #: share), (checker part, footprint kind), chain leaf
    MRT_CHANNELS = (4, 1, 4, 4, 4)

    def _mrt_target(self, size, count: int) -> moderngl.Framebuffer:
        """The first `count` of the ADAPTIVE_FIRST variants' five outputs
        (sums, square, first interaction, the checker's part, the chain
        leaf) as RGBA32F targets of `size`, kept for the sampler's life: at
        1280x720 making them costs as much as a sample of the sky.  (An
        output with no target is not written.)"""
        fbo = self._mrt.get((size, count))
        if fbo is None:
            texs = [self.ctx.texture(size, 4, dtype="f4") for _ in range(count)]
            fbo = self._mrt[(size, count)] = self.ctx.framebuffer(color_attachments=texs)
        return fbo

    def _drawn(self, fragments: int) -> None:
        """After a draw of `fragments` pixel-samples: finish it now, or (with
        sync_draws off) once MAX_QUEUED_FRAGMENTS are waiting."""
        self._queued += int(fragments)
        if self.sync_draws or self._queued >= MAX_QUEUED_FRAGMENTS:
            self.ctx.finish()
            self._queued = 0

    def _mrt_pass(self, size, band_programs, offset, count: int):
        """Draw one sample of the ADAPTIVE_FIRST variants into the first
        `count` targets of `size`, in bands of rows (one draw call each, a
        yield after each); band_programs() gives the (program, rects) to
        draw a band with.  Returns those attachments, top row first."""
        ctx, (w, h) = self.ctx, size
        fbo = self._mrt_target(size, count)
        try:
            top = 0                                   # bands of rows from the top cover every pixel
            while top < h:
                rows = max(1, min(h - top, self.fragments_per_draw // w, 512))
                band = (0, h - top - rows, w, rows)
                # (re)bound before every draw: between yields the caller may
                # have used the context for something else (the viewer)
                fbo.use()
                ctx.disable(moderngl.BLEND)
                for prog, rects in band_programs():
                    self.renderer.bind(prog, self.width, self.height, offset)
                    self.bind_footprint(prog)
                    vao = self.renderer.vao_of(prog)
                    for rect in rects:
                        clipped = intersect_rect(rect, band)
                        if clipped is not None:
                            ctx.scissor = clipped
                            vao.render(moderngl.TRIANGLES, vertices=3)
                self.last_draw_fragments = rows * w
                self._drawn(rows * w)
                ctx.scissor = None
                top += rows
                yield
            # only the channels the attachments use
            return [np.frombuffer(fbo.read(attachment=k, components=c, dtype="f4"), np.float32)
                    .reshape(h, w, c)[::-1] for k, c in enumerate(self.MRT_CHANNELS[:count])]
        finally:
            ctx.scissor = None

    @staticmethod
    def _first_hits(hit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        obj = np.rint(hit[..., 1]).astype(np.int32)
        t = np.where(obj >= 0, hit[..., 0], np.inf).astype(np.float64)
        return t, obj

    def first_pass(self, offset=(0.5, 0.5)):
        """Sample 0 of every pixel.  A generator that yields after each draw
        call and returns (Sums of one sample, the object (H, W) int of the
        first interaction of each camera ray (-1 for the sky), and the rays
        (H, W) int that sample traced (camera,
        reflected, refracted and shadow rays: what Renderer.ray_cost
        counts)."""
        # the programs fetched per band pick up a variant compiled since
        # (no chain leaf: only the corner rays' is used)
        out = yield from self._mrt_pass((self.width, self.height), lambda: self._programs(self.first_defines),
                                        offset, 4)
        self.centre_checker = np.ascontiguousarray(out[3][..., :3], np.float64)
        self.footprint_kind = np.rint(out[3][..., 3]).astype(np.int8)
        if self._footprint_tex is not None:
            # each pixel's closed-form share, computed once here: the list
            # passes (FOOTPRINT_SHARES) read it instead of computing it per
            # entry (up to MAX_PIXEL_CORNERS clipped squares each)
            self._footprint_texels[..., 1] = out[2][::-1, :, 3]
            self._footprint_tex.write(self._footprint_texels.tobytes())
        sums = Sums(np.ascontiguousarray(out[0], np.float64), np.ascontiguousarray(out[1][..., 0], np.float64))
        _, obj = self._first_hits(out[2])
        rays = np.rint(out[2][..., 2]).astype(np.int32)
        return sums, obj, rays

    def corner_pass(self):
        """One camera ray through every corner of the pixel grid, (W + 1) x
        (H + 1) of them: fragment (x, y) of the corner grid traces pixel
        (x, H - 1 - y) at offset (0, 1), its bottom-left corner, which is
        corner (x, H - y) of the grid.  Not culled (the grid is not the
        image's tiles).  A generator (a yield per draw) that returns
        (colour (H+1, W+1, 3), t, object (H+1, W+1)), top-left corner
        first."""
        full = [(self.renderer.variant(**self.FIRST), ((0, 0, self.width + 1, self.height + 1),))]
        out = yield from self._mrt_pass((self.width + 1, self.height + 1), lambda: full, (0.0, 1.0), 5)
        self.corner_checker = np.ascontiguousarray(out[3][..., :3], np.float64)
        self.corner_chain = np.ascontiguousarray(out[4], np.float64)
        t, obj = self._first_hits(out[2])
        return np.ascontiguousarray(out[0][..., :3], np.float64), t, obj

    def corner_objects(self):
        """The object the camera ray through every pixel corner meets first,
        (H + 1, W + 1) int, -1 for none, top-left corner first: the corner
        grid of corner_pass, but first geometric hits only (the VIEW_MODE 1
        variant: no shading, no further rays), which is all footprint_planes
        needs.  (Where a plane is the first surface it is also the first
        interaction.)  A generator, a yield per draw."""
        full = [(self.renderer.variant(VIEW_MODE=1), ((0, 0, self.width + 1, self.height + 1),))]
        out = yield from self._mrt_pass((self.width + 1, self.height + 1), lambda: full, (0.0, 1.0), 1)
        return self._first_hits(out[0])[1]

    def share_pass(self):
        """Each footprint pixel's closed-form share into the mask, as the
        first pass computes it, but with no tracing: for renders whose
        samples all read it (FOOTPRINT_SAMPLES).  A generator, a yield per
        draw."""
        if self._footprint_tex is None:
            return
        full = [(self.renderer.variant(**self.FOOTPRINT_SHARE_PASS), ((0, 0, self.width, self.height),))]
        out = yield from self._mrt_pass((self.width, self.height), lambda: full, (0.5, 0.5), 1)
        self._footprint_texels[..., 1] = out[0][::-1, :, 1]
        self._footprint_tex.write(self._footprint_texels.tobytes())

    def direct_footprints(self):
        """Footprint samples for a uniform render (Renderer.render, the
        viewer's accumulation): the mask holds every pixel whose four corner
        rays meet one checkered plane first, with its closed-form share,
        for the current camera.  Direct footprints only: their shares are
        exact, so the render still converges to the box-filtered pixel
        (chain footprints allow a small bias, CHAIN_TOLERANCE, which an
        adaptive render's own samples bound).  A generator, a yield per
        draw."""
        obj = yield from self.corner_objects()
        self.set_footprint(footprint_planes(self.renderer.scene, obj))
        yield from self.share_pass()

    def set_offsets(self, offsets: np.ndarray) -> None:
        """The sample offsets (n, 2) the list passes read (texel k: sample k)."""
        if self._offsets_tex is not None:
            self._offsets_tex.release()
        data = np.ascontiguousarray(offsets, np.float32)
        self._offsets_tex = self.ctx.texture((len(data), 1), 2, data.tobytes(), dtype="f4")
        self._offsets_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)

    def _list_target(self, lw: int, lh: int):
        if self._list_size != (lw, lh):
            self._release_list()
            self._list_tex = self.ctx.texture((lw, lh), 4, dtype="i4")
            self._list_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._list_targets = [self.ctx.texture((lw, lh), 4, dtype="f4") for _ in range(2)]
            self._list_fbo = self.ctx.framebuffer(color_attachments=self._list_targets)
            self._list_size = (lw, lh)
        return self._list_tex, self._list_fbo

    def _layout(self, pixels: np.ndarray, count: np.ndarray):
        """The pixel list: one run of rows per culling group and sample
        count (drawn with that group's program, all its fragments looping
        alike), entries placed by run_slots in the order given (a short run
        spread over several bands of BIN rows, each starting on a band).
        Returns (list width, rows, [(group, samples, first row, rows)],
        texel index of each entry)."""
        n = len(pixels)
        groups = self.group_labels(self._programs(self.list_defines)).ravel()[pixels].astype(np.int64)
        key = groups * (MAX_SPP + 1) + count
        runs_of = [np.flatnonzero(key == k) for k in np.unique(key)]
        lw = list_width(n)

        def plan(lw, spread):
            row, out = 0, []
            for m in runs_of:
                bands = run_bands(len(m), lw) if spread else 1
                if bands > 1:
                    row = -(-row // BIN) * BIN            # a spread run starts on a band
                out.append((row, bands))
                row += run_rows(len(m), lw, bands)
            return row, out

        height, placed = plan(lw, True)
        if height > MAX_LIST_HEIGHT:                      # too tall for a texture: dense runs, wider
            while plan(lw, False)[0] > MAX_LIST_HEIGHT and lw < n:
                lw += LIST_WIDTH
            height, placed = plan(lw, False)
        slot = np.empty(n, np.int64)
        runs = []
        for m, (row, bands) in zip(runs_of, placed):
            rows = run_rows(len(m), lw, bands)
            slot[m] = row * lw + run_slots(len(m), lw, bands)
            runs.append((int(groups[m[0]]), int(count[m[0]]), row, rows, len(m)))
        return lw, max(height, 1), runs, slot

    def add_samples(self, pixels: np.ndarray, first: np.ndarray, count: np.ndarray,
                    cost: np.ndarray | None = None):
        """Trace samples first[k] .. first[k] + count[k] - 1 (at the offsets
        set_offsets gave) of the pixels with flat indices `pixels` (j * W +
        i, j from the top row; listed in coherent_order).  A generator: it
        yields after each draw call (the viewer's frames, progress, Ctrl-C)
        and returns the sums (total (n, 4) = sum (L, 1), square (n,) = sum
        L.L) in the order of `pixels`.

        `cost` (rays per sample per pixel, None: all cheap) marks the
        pixels whose samples are costly (the glass): their samples are
        dealt to entries of at most entry_samples(cost) samples.  Where few
        pixels share a count, each one's samples are
        dealt to several consecutive entries of the list (split_factor; a
        4x4 block of them is one pixel's samples or a few pixels'), so that
        the last rounds, a few pixels with many samples each, use every
        SIMD lane and thread; their sums are added back per pixel."""
        w = self.width
        pixels, first, count = (np.asarray(a, np.int64) for a in (pixels, first, count))
        parts = self._split(pixels, count, cost)
        owner = np.repeat(np.arange(len(pixels)), parts)
        starts = np.concatenate([[0], np.cumsum(parts)[:-1]])
        each = count // parts
        e_pixels = pixels[owner]
        e_first = first[owner] + (np.arange(len(owner)) - starts[owner]) * each[owner]
        e_count = each[owner]
        lw, lh, runs, slot = self._layout(e_pixels, e_count)
        tex, fbo = self._list_target(lw, lh)
        entries = np.full((lh * lw, 4), -1, np.int32)
        entries[slot] = np.stack([e_pixels % w, e_pixels // w, e_first, e_count], axis=1)
        tex.write(entries.tobytes())               # row 0 of the texture = list row 0
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        self._in_flight = (fbo, slot, starts)
        try:
            # entries in list rows 0 .. r-1: filled[r] (a draw's exact pixel count)
            filled = np.concatenate([[0], np.cumsum(np.bincount(slot // lw, minlength=lh))])
            yield from self._list_draws(tex, fbo, runs, lw, filled)
        finally:
            self._in_flight = None
        return self._list_sums(fbo, slot, starts)

    def _split(self, pixels: np.ndarray, count: np.ndarray, cost: np.ndarray | None) -> np.ndarray:
        """Entries per pixel: split_factor of the pixels taking its count
        with its entry_samples limit (all groups together, so that the
        split, and with it every sum, is the same whichever culling variants
        draw them); all ones when the sampler's `split_entries` is off."""
        if not self.split_entries or len(pixels) == 0:
            return np.ones(len(pixels), np.int64)
        if cost is not None and np.asarray(cost).dtype.kind == "b":
            raise TypeError("add_samples takes each pixel's rays per sample, not a mask")
        most = np.zeros(len(pixels), np.int64) if cost is None else entry_samples(cost)
        span = int(most.max()) + 1
        key = count * span + most
        uniq, inverse, length = np.unique(key, return_inverse=True, return_counts=True)
        factor = np.array([split_factor(int(n), int(k // span), int(k % span) or None)
                           for k, n in zip(uniq, length)], np.int64)
        return factor[inverse.ravel()]

    def sums_so_far(self) -> np.ndarray | None:
        """Between the yields of add_samples: total (n, 4) = sum (L, 1) of
        the samples its draws have traced so far, in the order of its
        pixels (0 where none yet); None outside add_samples.  (Read back:
        AdaptiveRender.image mid-round, the viewer's screenshot; the window
        reads sums_target on the GPU instead.)"""
        if self._in_flight is None:
            return None
        fbo, slot, starts = self._in_flight
        return self._list_sums(fbo, slot, starts, square=False)[0]

    def sums_target(self):
        """Between the yields of add_samples: (the list target's sums
        texture, RGBA32F: sum (L, 1) of the samples traced so far at each
        texel; the texel index of each of its pixels); None outside it."""
        if self._in_flight is None:
            return None
        fbo, slot, starts = self._in_flight
        if len(starts) != len(slot):
            return None        # split entries: a pixel's sums lie in several texels (split_entries)
        return fbo.color_attachments[0], slot

    @staticmethod
    def _list_sums(fbo, slot, starts, square: bool = True):
        """The list targets' sums at the texels `slot`, added up per pixel
        (its entries begin at `starts`): (total (n, 4), square (n,) or
        None), float64."""
        size = fbo.size[0] * fbo.size[1]
        total = np.frombuffer(fbo.read(attachment=0, components=4, dtype="f4"), np.float32).reshape(size, 4)[slot]
        total = np.add.reduceat(total.astype(np.float64), starts, axis=0) if len(starts) else total.astype(np.float64)
        if not square:
            return total, None
        sq = np.frombuffer(fbo.read(attachment=1, components=1, dtype="f4"), np.float32)[slot].astype(np.float64)
        return total, (np.add.reduceat(sq, starts) if len(starts) else sq)

    def _list_draws(self, tex, fbo, runs, lw, filled):
        """add_samples' draw calls, a yield after each."""
        ctx, w = self.ctx, self.width
        for g, samples, row0, rows, length in runs:
            k0 = 0
            while k0 < samples:
                # about fragments_per_draw pixel-samples per draw: a batch of
                # samples for some rows of the run
                batch = max(1, min(MAX_BATCH, samples - k0, self.fragments_per_draw // max(1, length)))
                rows_per_draw = max(LIST_BLOCK, self.fragments_per_draw // (lw * batch)) // LIST_BLOCK * LIST_BLOCK
                y = row0
                while y < row0 + rows:
                    cut = min(rows_per_draw, row0 + rows - y)
                    # (re)bound before every draw: between yields the caller
                    # may have used the context for something else (the viewer)
                    prog = self._programs(self.list_defines)[g][0]
                    self.renderer.bind(prog, w, self.height, (0.5, 0.5))
                    prog["pixelList"].value = 1
                    prog["sampleOffsets"].value = 2
                    prog["chunkStart"].value = k0
                    prog["chunkSize"].value = batch
                    self.bind_footprint(prog)
                    fbo.use()
                    tex.use(location=1)
                    self._offsets_tex.use(location=2)
                    ctx.enable(moderngl.BLEND)
                    ctx.blend_func = moderngl.ONE, moderngl.ONE
                    ctx.blend_equation = moderngl.FUNC_ADD
                    ctx.scissor = (0, y, lw, cut)
                    try:
                        self.renderer.vao_of(prog).render(moderngl.TRIANGLES, vertices=3)
                        self.last_draw_fragments = int(filled[y + cut] - filled[y]) * batch
                        self._drawn(self.last_draw_fragments)
                    finally:
                        ctx.scissor = None
                        ctx.disable(moderngl.BLEND)
                    y += cut
                    yield
                k0 += batch

    def _release_list(self) -> None:
        for obj in (self._list_fbo, self._list_tex, *self._list_targets):
            if obj is not None:
                obj.release()
        self._list_fbo = self._list_tex = None
        self._list_targets = []
        self._list_size = (0, 0)

    def release(self) -> None:
        self._release_list()
        self.set_footprint(None)
        if self._offsets_tex is not None:
            self._offsets_tex.release()
            self._offsets_tex = None
        for fbo in self._mrt.values():
            for tex in fbo.color_attachments:
                tex.release()
            fbo.release()
        self._mrt.clear()


class AdaptiveRender:
    """One adaptive render, advanced one GPU draw at a time by step() (the
    viewer spreads it over frames) or to the end by run().  The sums live
    here, in float64, per pixel: sum (L, 1) and sum L.L, and sum (L, 1) at
    the pixel's previous sample count (for the prefix difference)."""

    def __init__(self, renderer, width: int, height: int, samples: int | None = None,
                 target_error: float = DEFAULT_TARGET_ERROR, seed: int = 0, max_spp: int | None = None,
                 sampler=None, footprint: bool | None = None):
        samples = int(samples or renderer.scene.render.samples)
        self.scene = renderer.scene
        self.width, self.height = width, height
        self.samples = samples
        self.target_error = float(target_error)
        self.max_spp = int(max_spp or min(MAX_SPP_FACTOR * samples, MAX_SPP))
        self.budget = samples * width * height
        self.offsets = _offsets(self.max_spp, seed)
        # `sampler`: anything with AdaptiveSampler's passes (first_pass,
        # corner_pass, set_offsets, add_samples, release) for this size;
        # tools/adaptive_bound.py replays recorded samples through one.
        # Footprint samples (trace.frag's FOOTPRINT_AA) where a pixel's
        # footprint lies on one checkered plane: on by default where the
        # scene has one; a sampler given here says whether it takes them.
        if footprint is None:
            footprint = getattr(sampler, "footprint", False) if sampler is not None else footprint_default(self.scene)
        self.footprint = bool(footprint)
        self.sampler = (sampler if sampler is not None
                        else AdaptiveSampler(renderer, width, height, footprint=self.footprint))
        #: (H, W) bool: the pixels with footprint samples (None: none yet, or off)
        self.footprint_mask: np.ndarray | None = None
        #: (H, W) bool: those of them with chain footprints (None: none yet, or off)
        self.chain_mask: np.ndarray | None = None
        #: every pixel has its first sample (the first pass is done)
        self.first_pass_done = False
        # every pixel in coherent_order, once: the chosen ones in that order
        # are a mask of it (no sort per round)
        self._coherent = image_coherent_order(width, height)
        self.total = np.zeros((height, width, 4))
        self.square = np.zeros((height, width))
        self.prev = np.zeros((height, width, 4))      # total at the previous count (0: none)
        self.spent = 0                    # rays traced (pixel samples and corner rays)
        self.draws_done = 0
        self.steps_done = 0               # step() calls: draw calls and the bookkeeping between passes
        self.rounds: list[tuple[int, int]] = []
        self._upgrading = None            # (pixels, their sums before it) while a round's draws run
        self.round_traced = 0             # pixel-samples the round in flight has traced so far
        self.done = False
        self._gen = self._run()

    # ------------------------------------------------------------ driving

    def step(self) -> bool:
        """Run one draw call (and the bookkeeping after it); True when done."""
        if self.done:
            return True
        interrupt.check()                 # a deferred Ctrl-C ends the render between draws
        self.steps_done += 1
        try:
            next(self._gen)
        except StopIteration:
            self.done = True
        return self.done

    def run(self, progress: Callable[[int, int], None] | None = None) -> "AdaptiveResult":
        while not self.step():
            if progress is not None:
                progress(min(self.spent, self.budget), self.budget)
        if progress is not None:
            progress(self.budget, self.budget)
        return self.result()

    # ------------------------------------------------------------ results

    @property
    def spp(self) -> np.ndarray:
        return np.rint(self.total[..., 3]).astype(np.int32)

    def _ask_round(self, method: str):
        """The sampler's answer about the round in flight (its `method`,
        None outside add_samples), with the round's (pixels, sums before
        it); None between rounds or when the sampler has no such method."""
        ask = getattr(self.sampler, method, None)
        if self._upgrading is None or ask is None:
            return None
        got = ask()
        return None if got is None else (got, *self._upgrading)

    def in_flight(self) -> tuple[np.ndarray, np.ndarray] | None:
        """While a round's draws run (between steps): (flat pixel indices,
        their sums (n, 4) = sum (L, 1) with what the round's draws so far
        traced); None between rounds.  `total` gets them when the round
        ends; a sampler without sums_so_far shows none before that."""
        got = self._ask_round("sums_so_far")
        if got is None:
            return None
        so_far, flat, old = got
        return flat, old + so_far

    def round_target(self):
        """While a round's draws run: (its flat pixel indices, the texture
        of their new sums so far, the texel of each pixel in it) -- see
        AdaptiveSampler.sums_target -- for a display that adds them to
        `total` on the GPU; None between rounds or with a sampler that has
        no such texture."""
        got = self._ask_round("sums_target")
        if got is None:
            return None
        (sums_tex, slot), flat, _ = got
        return flat, sums_tex, slot

    def image(self) -> np.ndarray:
        """(H, W, 3) float32: the mean of each pixel's samples so far (a
        round's draws included while it runs)."""
        total = self.total
        moving = self.in_flight()
        if moving is not None:
            total = total.copy()
            total.reshape(-1, 4)[moving[0]] = moving[1]
        from ..gpu.renderer import clamp_radiance

        # (footprint samples: a pixel's mean of few can be below 0, Renderer.render's clamp_radiance)
        return clamp_radiance((total[..., :3] / np.maximum(total[..., 3:], 1)).astype(np.float32))

    def result(self) -> "AdaptiveResult":
        return AdaptiveResult(np.ascontiguousarray(self.image()), self.spp, list(self.rounds), self.spent)

    def release(self) -> None:
        if self._gen is not None:
            self._gen.close()
            self._gen = None
        self.sampler.release()
        self.done = True

    # ------------------------------------------------------------ the work

    def flags(self, centre: np.ndarray, obj: np.ndarray, corner_colour: np.ndarray, corner_t: np.ndarray,
              corner_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(flagged (H, W) bool, contrast (H, W)) from the centre colours and
        first objects and the corner rays (module docstring, step 1)."""
        return drain(self._flag_steps(centre, obj, corner_colour, corner_t, corner_obj))

    def _flag_steps(self, centre, obj, corner_colour, corner_t, corner_obj):
        """flags() as a generator that yields between its parts (each 0.06-0.13
        s of numpy at 1280x720: the viewer draws a frame in between; as one
        step, the corner contrasts and the object and chain flags took 0.37
        s, the viewer's longest frame)."""
        scene = self.scene
        fp = None if self.footprint_mask is None else self.sampler.footprint_kind == FOOTPRINT_EXACT
        chain = None if fp is None or self.chain_mask is None else fp & self.chain_mask
        if fp is not None:
            # Pixels whose footprint samples take the checker exactly: their
            # five rays are compared with the checker's part taken out, so
            # that only what else varies (a shadow edge, another object)
            # counts.  (Those that take it along rows only, and those too far
            # for either, count as point-sampled ones.)  That is the contrast
            # returned, which the sliver term sees.  But chain footprints are
            # flagged on their colours as they are: what else varies there
            # can be far smaller than a pixel (the glass's own highlight, an
            # object in a minified refracted picture), and took 1 sample
            # where it had taken 256 with the checker's contrast flagging the
            # pixel (bench-many, a glass sphere's highlight: errors of
            # 0.05-0.11); with FIRST_ROUND footprint samples that agree such
            # a pixel then stops.
            direct = fp if chain is None else fp & ~chain
            removed = centre - self.sampler.centre_checker
            raw = corner_contrast(corner_colour, centre)
            yield
            contrast = np.where(fp, corner_contrast(corner_colour - self.sampler.corner_checker, removed), raw)
            flag_contrast = np.where(direct, contrast, raw)
            seen = np.where(direct[..., None], removed, centre)
        else:
            contrast = flag_contrast = corner_contrast(corner_colour, centre)
            direct, seen = None, centre
        level = max(self.target_error, FLAG_CONTRAST)
        flagged = flag_contrast > level
        yield
        bends = np.array([scene.scatters(o) for o in scene.objects] + [False])
        through = _fold(np.logical_or, [bends[o] for o in _corners(corner_obj) + [obj]])
        if self.target_error < EDGE_ERROR:
            # an edge between opaque surfaces whose sides look alike (within
            # the target) is no error: a box of one colour stays at one sample
            differ = corner_objects_differ(corner_obj, obj)
            flagged |= differ & (flag_contrast > self.target_error)
            # But where glass or a mirror is one side, or the corner rays'
            # principal chains cross different surfaces, something thinner
            # than the pixel can lie between sides that look alike: a glass's
            # rim seen edge-on between two views of the sky (the default
            # scene: 60 such pixels, left at one sample, held half the
            # squared error of a 12-sample budget, 0.07-0.08 each).
            unseen = differ & through
            chain = getattr(self.sampler, "corner_chain", None)
            if chain is not None:
                unseen |= corner_chains_differ(chain)
            unseen &= ~flagged
            flagged |= unseen
            contrast = np.where(unseen, np.maximum(contrast, UNSEEN_CONTRAST), contrast)
            yield
            cells = checker_cells_differ(scene, corner_t, corner_obj)
            flagged |= cells if direct is None else cells & ~direct
        if through.any():
            yield
            flagged |= through & (colour_contrast(seen) > max(self.target_error, THROUGH_CONTRAST))
        return flagged, contrast

    def _run(self):
        w, h = self.width, self.height
        corners = (w + 1) * (h + 1)
        # Room for the corner rays and more (a budget of 3 samples per pixel
        # or more): they are traced first, so that the first pass already
        # knows where footprint samples go.
        with_corners = self.max_spp >= 2 and self.budget - w * h >= 2 * corners
        if with_corners:
            colour, corner_t, corner_obj = yield from self._draws(self.sampler.corner_pass())
            self.spent += corners
            if self.footprint:
                planes = footprint_planes(self.scene, corner_obj)
                chain = getattr(self.sampler, "corner_chain", None)
                if chain is not None:
                    yield                 # (steps of their own: about 0.1 s each at 1280x720)
                    chain = chain_footprints(self.scene, chain, planes)
                    yield
                self.footprint_mask = planes >= 0
                if chain is not None:
                    self.chain_mask = chain.mask
                    self.footprint_mask |= self.chain_mask
                self.sampler.set_footprint(planes, chain)
            yield
        sums, obj, rays = yield from self._draws(self.sampler.first_pass((0.5, 0.5)))
        # what a sample of each pixel costs: the rays its centre sample traced
        self._cost = np.maximum(rays, 1).astype(np.float64)
        self.total[...] = sums.total
        self.square[...] = sums.square
        self.spent += w * h
        self.first_pass_done = True
        self.rounds.append((w * h, w * h))
        if self.max_spp < 2 or self.budget - self.spent < FIRST_ROUND - 1:
            return                                    # no room for anything but the centres
        # Bare yields (steps with no draw call) split the bookkeeping between
        # passes, which takes tenths of a second at 1280x720, into steps of
        # its own, so that the viewer's frames go on in between.
        yield
        if with_corners:
            flagged, contrast = yield from self._flag_steps(sums.mean, obj, colour, corner_t, corner_obj)
            yield
        else:
            # A budget under 3 samples per pixel: the corner rays would take
            # most of what is left, so the centres' 3x3 neighbourhoods say
            # where the edges may be.
            contrast = colour_contrast(sums.mean)
            flagged = contrast > max(self.target_error, FLAG_CONTRAST)
        # the contrast the sliver term sees (module docstring, step 2)
        self._contrast = contrast
        self._own = sliver_error(self._contrast, 1)
        self.sampler.set_offsets(self.offsets)
        # Kept per pixel by _upgrade (contiguous, so rounds do not copy
        # strided views of the image): the samples, and whether the pixel is
        # below max_spp, so that an upgrade (to the cap at most) is left
        # (only flagged pixels are upgraded).
        self._count = np.ones((h, w))
        self._room = flagged & (1 < self.max_spp)
        # Every flagged pixel first goes to FIRST_ROUND samples (a spread
        # needs several), the most contrasted first if the budget is short.
        chosen = choose_within_budget(flagged, contrast, min(FIRST_ROUND, self.max_spp) - 1, self.budget - self.spent)
        yield from self._upgrade(chosen)
        # Then, round by round, the pixels whose estimated error is above the
        # target and largest for its cost double their samples, until the
        # budget is spent.  A pixel that is not flagged keeps one sample.
        while True:
            error = with_neighbours(self._own)       # estimated_error, own part kept up to date
            want = self._room & (error > self.target_error)
            left = self.budget - self.spent
            if left < TAIL_SHARE * self.budget:
                break
            chosen = choose_by_gain(want, error, self._count, left, ROUND_SHARE, MIN_ROUND * self.budget, self._cost)
            if not chosen.any():
                break
            yield from self._upgrade(chosen)
            yield

    def _upgrade(self, chosen: np.ndarray):
        """Take every chosen pixel from n to next_count(n) samples (at most
        max_spp) in one pass over one pixel list."""
        flat = self._coherent[chosen.ravel()[self._coherent]]     # coherent_order of the chosen pixels
        if len(flat) == 0:
            return
        total, square = self.total.reshape(-1, 4), self.square.ravel()       # views
        old = total[flat]
        n = np.rint(old[:, 3]).astype(np.int64)
        more = np.minimum(next_count(n), self.max_spp) - n
        self._upgrading = (flat, old)
        self.round_traced = 0
        try:
            tot, sq = yield from self._draws(self.sampler.add_samples(flat, n, more, self._cost.ravel()[flat]))
        finally:
            self._upgrading = None
        sums = Sums(old + tot, square[flat] + sq)
        total[flat] = sums.total
        square[flat] = sums.square
        self.prev.reshape(-1, 4)[flat] = old
        self._count.ravel()[flat] = n + more
        self._room.ravel()[flat] = n + more < self.max_spp
        self.spent += int(more.sum())
        self.rounds.append((int(more.sum()), len(flat)))
        self._own.ravel()[flat] = self.estimate(flat, sums, old)

    def estimate(self, flat: np.ndarray, sums: Sums, prev: np.ndarray) -> np.ndarray:
        """The own error (own_error) of the pixels `flat` from their sums
        and their sums at the previous count; what the rounds rank by
        before the neighbour term (a measurement can put an oracle here)."""
        return own_error(sums, prev, self._contrast.ravel()[flat])

    def _draws(self, gen):
        """Run one of the sampler's generators, counting its draw calls (one
        per yield); returns what it returns."""
        while True:
            try:
                next(gen)
            except StopIteration as stop:
                return stop.value
            self.draws_done += 1
            if self._upgrading is not None:             # a round's draw (not the first or corner pass)
                self.round_traced += getattr(self.sampler, "last_draw_fragments", 0)
            yield


def render_adaptive(renderer, width: int, height: int, samples: int | None = None,
                    target_error: float = DEFAULT_TARGET_ERROR, seed: int = 0,
                    progress: Callable[[int, int], None] | None = None,
                    max_spp: int | None = None, footprint: bool | None = None) -> AdaptiveResult:
    """Render spending at most `samples` (the scene's samples when None)
    rays per pixel on average -- samples x W x H in all, the corner rays
    included -- where a pixel's estimated error is above target_error
    (linear, largest channel); one pixel takes at most max_spp (default
    MAX_SPP_FACTOR x samples).  When the budget runs short, the pixels with
    the largest estimated error go first.  The image converges to the same
    box-filtered picture as Renderer.render."""
    job = AdaptiveRender(renderer, width, height, samples, target_error, seed, max_spp, footprint=footprint)
    job.sampler.sync_draws = False       # no frame to fit: draws overlap the Python between them
    try:
        return job.run(progress)
    finally:
        job.release()
