"""Adaptive anti-aliasing: samples go only to the pixels that still need them.

The error left in a correct Whitted image is almost all pixel footprint
(silhouettes, checker edges, the checker toward the horizon, the refracted
picture inside glass); a flat region is exact with one centred sample.  So:

1. The first pass traces sample 0 (the pixel centre) of every pixel and
   records the first interaction of each camera ray.  A pixel is flagged
   when its 3x3 neighbourhood says its footprint may not be flat: a colour
   differs by more than max(target, FLAG_CONTRAST), the first interaction
   changes across it (another object, a normal turned by more than
   NORMAL_ANGLE_DEG, a relative depth jump over DEPTH_JUMP; where the colour
   contrast is above the target), or the camera
   rays of neighbours land on a checker more than half a check apart (where
   centre samples alias into flat-looking patches; these two count as an
   error of EDGE_ERROR, so a larger target ignores them); the flags are
   dilated by one pixel (a thin feature between two centres).  Every other pixel ends
   with one sample.
2. Flagged pixels get FIRST_ROUND samples.  Then, round after round, a
   pixel's error is estimated from its own samples (the difference of its
   even- and odd-index halves, and its standard error), from what they may
   have missed (SLIVER x its contrast / n) and from its neighbours (errors
   lie along edges: at least NEIGHBOUR_SHARE of the worst neighbour's); the
   pixels above the target error whose error^2 / n is largest (the squared
   error a doubling removes per sample) double their samples, as many as
   ROUND_SHARE of the budget left pays for.
3. The budget is samples x W x H pixel-samples in all (the mean samples per
   pixel), one pixel taking at most MAX_SPP_FACTOR x samples; the render
   stops when it is spent or no pixel is above the target.

The GPU traces only listed pixels: a small framebuffer whose fragment
(x, y) traces the image pixel stored at (x, y) of a list texture, in
coherent order (8x8 image tiles), up to MAX_BATCH samples per fragment and
draw.  Samples follow sampling.progressive_offsets, so every prefix is
evenly spread; everything is deterministic for a seed.  The target error
is per pixel, in linear radiance units (the .npy values), on the largest
colour channel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import moderngl
import numpy as np

from .sampling import progressive_offsets

# The per-pixel target (linear, largest channel) when none is given: chosen
# from measurements (README, "Adaptive anti-aliasing"): below it the bench's
# scenes spend their whole budget for the same error.
DEFAULT_TARGET_ERROR = 0.005
NORMAL_ANGLE_DEG = 25.0
DEPTH_JUMP = 0.1
# Samples per pixel: 1, then FIRST_ROUND for every flagged pixel, then
# doublings (4, 8, 16, ...) for the pixels chosen round by round; powers of
# two are where the Sobol' points form nets.  Measured against rounds of 4x:
# lower RMSE at the same budget on glass-sphere and whitted-exact.
FIRST_ROUND = 4
ROUND_FACTOR = 2
# One pixel takes at most this many times the mean budget, and never more
# than MAX_SPP: an edge pixel may need far more than the average.
MAX_SPP_FACTOR = 8
MAX_SPP = 1024
SLIVER = 0.1
#: A pixel is flagged for more samples when its neighbourhood contrast is
#: above this (or above the target error, whichever is larger).
FLAG_CONTRAST = 0.02
FLAG_DILATE = True
#: The error assumed of a pixel flagged by a first-hit edge or checker
#: aliasing alone (its colour contrast may not show it).
EDGE_ERROR = 0.1
#: A pixel's error is at least this share of its worst neighbour's.
NEIGHBOUR_SHARE = 0.25
#: Share of the budget left that one round may spend (the rest waits for
#: the better estimates the round brings).
ROUND_SHARE = 0.5


@dataclass
class AdaptiveResult:
    image: np.ndarray                 # (H, W, 3) float32 linear, exposure applied
    spp: np.ndarray                   # (H, W) int32 samples per pixel
    rounds: list[tuple[int, int]] = field(default_factory=list)   # (samples after, pixels drawn)

    def __iter__(self):               # image, spp = render_adaptive(...)
        return iter((self.image, self.spp))

    @property
    def mean_spp(self) -> float:
        return float(self.spp.mean())


# ---------------------------------------------------------------- pure parts


def _neighbourhood(a: np.ndarray, reduce) -> np.ndarray:
    """reduce over the 3x3 neighbourhood of every pixel (edges replicated) of
    an (H, W, ...) array; reduce is np.maximum or np.minimum."""
    h, w = a.shape[:2]
    p = np.pad(a, [(1, 1), (1, 1)] + [(0, 0)] * (a.ndim - 2), mode="edge")
    out = a.copy()
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            out = reduce(out, p[dy:dy + h, dx:dx + w])
    return out


def colour_contrast(image: np.ndarray) -> np.ndarray:
    """(H, W): the largest difference, over the 3x3 neighbourhood and the
    colour channels, between a pixel's colour and its neighbours'."""
    hi = _neighbourhood(image, np.maximum)
    lo = _neighbourhood(image, np.minimum)
    return np.maximum(hi - image, image - lo).max(axis=2)


def first_hit_edges(t: np.ndarray, obj: np.ndarray, normal: np.ndarray,
                    normal_angle_deg: float = NORMAL_ANGLE_DEG, depth_jump: float = DEPTH_JUMP) -> np.ndarray:
    """(H, W) bool: the first hit changes inside the pixel's 3x3 neighbourhood
    (object, normal direction, or relative depth)."""
    edges = _neighbourhood(obj, np.maximum) != _neighbourhood(obj, np.minimum)
    cos_limit = math.cos(math.radians(normal_angle_deg))
    h, w = obj.shape
    pn = np.pad(normal, [(1, 1), (1, 1), (0, 0)], mode="edge")
    tt = np.where(np.isfinite(t), t, np.float32(3.0e38)).astype(np.float64)
    pt = np.pad(tt, 1, mode="edge")
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            if dy == dx == 1:
                continue
            q = pn[dy:dy + h, dx:dx + w]
            edges |= (np.sum(normal * q, axis=2) < cos_limit) & (obj >= 0)
            tq = pt[dy:dy + h, dx:dx + w]
            edges |= np.abs(tq - tt) > depth_jump * np.minimum(tq, tt)
    return edges


def checker_aliasing(scene, t: np.ndarray, obj: np.ndarray) -> np.ndarray:
    """(H, W) bool: the camera rays of neighbouring pixels hit a checkered
    surface more than half a check apart.  There the centre samples can
    alias into a flat-looking patch (toward the horizon), so colour contrast
    alone cannot tell that the footprint holds edges."""
    from .reference import camera_rays

    h, w = obj.shape
    size = np.full(len(scene.objects) + 1, np.inf)      # last entry: no hit
    for k, o in enumerate(scene.objects):
        c = scene.materials[o.material].checker
        if c is not None:
            size[k] = c.size
    if not np.isfinite(size).any():
        return np.zeros((h, w), bool)
    _, d = camera_rays(scene, w, h)
    hit = np.isfinite(t)
    p = d * np.where(hit, t, 0.0)[..., None]            # camera-relative hit points
    spacing = np.zeros((h, w))
    for axis in (0, 1):
        step = np.linalg.norm(np.diff(p, axis=axis), axis=2)
        both = np.logical_and(*(np.take(hit, r, axis=axis) for r in (np.arange(1, hit.shape[axis]),
                                                                       np.arange(hit.shape[axis] - 1))))
        step = np.where(both, step, 0.0)
        lo = [slice(None), slice(None)]
        hi = [slice(None), slice(None)]
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        spacing[tuple(lo)] = np.maximum(spacing[tuple(lo)], step)
        spacing[tuple(hi)] = np.maximum(spacing[tuple(hi)], step)
    return hit & (spacing > 0.5 * size[np.where(obj >= 0, obj, -1)])


class Sums(NamedTuple):
    """Per-pixel sums over a pixel's samples 0..n-1, (H, W, 4) float32 each,
    top row first: total = sum (L, 1); moments = sum (L [odd index], L.L)."""
    total: np.ndarray
    moments: np.ndarray

    @property
    def count(self) -> np.ndarray:
        return self.total[..., 3]

    @property
    def mean(self) -> np.ndarray:
        return self.total[..., :3] / np.maximum(self.total[..., 3:], 1)


def half_error(sums: Sums) -> np.ndarray:
    """(H, W): |A - B| / 2 for the means A, B of the even- and odd-index
    samples (n // 2 of them are odd), largest channel; 0 below two samples."""
    n = sums.count
    n_odd = np.floor(n / 2)
    n_even = n - n_odd
    odd = sums.moments[..., :3]
    mean_odd = odd / np.maximum(n_odd, 1)[..., None]
    mean_even = (sums.total[..., :3] - odd) / np.maximum(n_even, 1)[..., None]
    return np.where(n_odd > 0, 0.5 * np.abs(mean_even - mean_odd).max(axis=2), 0.0)


def standard_error(sums: Sums) -> np.ndarray:
    """(H, W): sqrt(s^2 / n) with s^2 the sample variance of L summed over
    the channels (an upper bound of every channel's); 0 below two samples."""
    n = sums.count
    mean = sums.mean
    var = np.maximum(sums.moments[..., 3] / np.maximum(n, 1) - np.sum(mean * mean, axis=2), 0.0)
    var = var * n / np.maximum(n - 1, 1)
    return np.where(n > 1, np.sqrt(var / np.maximum(n, 1)), 0.0)


def pixel_error(sums: Sums) -> np.ndarray:
    """A pixel's estimated error: the larger of the two estimates above.
    The halves follow evenly spread samples' faster-than-1/sqrt(n)
    convergence but miss a split that puts the same mix in both halves; the
    standard error sees any spread among the samples.  A pixel whose samples
    all agree has error 0: a sliver narrower than their spacing may be
    missed, which costs at most its contrast times its area."""
    return np.maximum(half_error(sums), standard_error(sums))


def sliver_error(contrast: np.ndarray, n) -> np.ndarray:
    """What n samples that all agree may still miss: an edge of contrast C
    (the neighbourhood's, from the first pass) whose sliver inside the pixel
    falls between them, about 1/n of the pixel at most, SLIVER x C / n.
    Without this a pixel next to an edge stops as soon as its samples
    agree."""
    return SLIVER * contrast / np.maximum(n, 1)


def own_error(sums: Sums, contrast: np.ndarray) -> np.ndarray:
    """A pixel's error estimate from its own samples (pixel_error) and from
    what they may have missed (sliver_error)."""
    return np.maximum(pixel_error(sums), sliver_error(contrast, sums.count))


def with_neighbours(own: np.ndarray) -> np.ndarray:
    """At least NEIGHBOUR_SHARE of the worst neighbour's error: errors lie
    along edges, so a pixel whose few samples happen to agree beside one
    that disagrees is not done."""
    return np.maximum(own, NEIGHBOUR_SHARE * _neighbourhood(own, np.maximum))


def estimated_error(sums: Sums, contrast: np.ndarray) -> np.ndarray:
    """(H, W): what a pixel's mean is estimated to be off by (what the
    render's rounds rank pixels by)."""
    return with_neighbours(own_error(sums, contrast))


def choose_by_gain(want: np.ndarray, error: np.ndarray, count: np.ndarray, left: int,
                   share: float = 0.5) -> np.ndarray:
    """The pixels of `want` to take from n to ROUND_FACTOR x n samples next:
    in order of error^2 / n (the squared error an upgrade removes per
    sample it costs), as many as `share` of the `left` budget pays for (at
    least one pixel's upgrade when affordable; ties by position)."""
    idx = np.flatnonzero(want.ravel())
    if len(idx) == 0:
        return np.zeros_like(want)
    n = count.ravel()[idx]
    cost = n * (ROUND_FACTOR - 1)
    order = np.lexsort((idx, -(error.ravel()[idx] ** 2) / n))
    spend = np.cumsum(cost[order])
    cap = max(share * left, float(cost[order[0]]))
    take = order[(spend <= cap) & (spend <= left)]
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


# ---------------------------------------------------------------- the GPU part

#: Width of the pixel-list framebuffer (a multiple of 4: a software
#: rasteriser shades 4x4 blocks, which then hold list entries that are close
#: in the image) and the most fragments one draw call traces (the renderer's
#: 512x512 tiles: no draw long enough to trip a GPU watchdog).
LIST_WIDTH = 64
#: Samples traced per fragment and draw call (the shader's MAX_BATCH).
MAX_BATCH = 32
MAX_LIST_HEIGHT = 16384
FRAGMENTS_PER_DRAW = 512 * 512


def coherent_order(pixels: np.ndarray, width: int, tile: int = 8) -> np.ndarray:
    """Flat pixel indices (j * width + i) sorted by tile x tile squares of
    the image, row by row inside a square: neighbours in the list are
    neighbours in the image, so their rays take similar paths (less SIMD
    divergence)."""
    i, j = pixels % width, pixels // width
    tiles_x = (width + tile - 1) // tile
    key = ((j // tile) * tiles_x + i // tile) * (tile * tile) + (j % tile) * tile + (i % tile)
    return pixels[np.argsort(key, kind="stable")]


class AdaptiveSampler:
    """The GPU side for one image size: ``first_pass`` traces sample 0 of
    every pixel (with the first interaction of each camera ray);
    ``add_samples`` traces more samples of a list of pixels only.  Results
    come back as arrays; the sums are kept by the caller."""

    def __init__(self, renderer, width: int, height: int):
        self.renderer = renderer
        self.ctx: moderngl.Context = renderer.ctx
        self.width, self.height = width, height
        self._vaos: dict[int, moderngl.VertexArray] = {}
        self._list_tex = None
        self._list_fbo = None
        self._list_targets: list = []
        self._list_size = (0, 0)
        #: pixel-samples one draw call may trace; read before every draw, so
        #: the viewer can fit draws into its frame budget as it goes
        self.fragments_per_draw = FRAGMENTS_PER_DRAW
        self.last_draw_fragments = 0     # pixel-samples the latest draw traced

    def compile(self) -> None:
        """Compile the two shader variants now (the viewer's soak counts GL
        objects after it)."""
        self._program(ADAPTIVE_FIRST=1)
        self._program(ADAPTIVE_LIST=1)

    def _program(self, **defines) -> tuple[moderngl.Program, moderngl.VertexArray]:
        prog = self.renderer.variant(ADAPTIVE=1, **defines)
        vao = self._vaos.get(id(prog))
        if vao is None:
            vao = self.ctx.vertex_array(prog, [])
            self._vaos[id(prog)] = vao
        return prog, vao

    def first_pass(self, offset=(0.5, 0.5)):
        """Sample 0 of every pixel.  A generator that yields after each draw
        call and returns (Sums of one sample, t (H, W), object (H, W) int,
        outward normal (H, W, 3)) of the first interaction of each camera
        ray (t = inf, object -1 for the sky)."""
        ctx, (w, h) = self.ctx, (self.width, self.height)
        prog, vao = self._program(ADAPTIVE_FIRST=1)
        texs = [ctx.texture((w, h), 4, dtype="f4") for _ in range(4)]
        fbo = ctx.framebuffer(color_attachments=texs)
        try:
            top = 0                                   # bands of rows from the top cover every pixel
            while top < h:
                rows = max(1, min(h - top, self.fragments_per_draw // w, 512))
                # (re)bound before every draw: between yields the caller may
                # have used the context for something else (the viewer)
                fbo.use()
                ctx.disable(moderngl.BLEND)
                self.renderer.bind(prog, w, h, offset)
                prog["sampleParity"].value = 0.0
                ctx.scissor = (0, h - top - rows, w, rows)
                vao.render(moderngl.TRIANGLES, vertices=3)
                ctx.finish()
                self.last_draw_fragments = rows * w
                ctx.scissor = None
                top += rows
                yield
            out = [np.frombuffer(fbo.read(attachment=k, components=4, dtype="f4"), np.float32)
                   .reshape(h, w, 4)[::-1] for k in range(4)]
        finally:
            ctx.scissor = None
            fbo.release()
            for t in texs:
                t.release()
        sums = Sums(np.ascontiguousarray(out[0], np.float64), np.ascontiguousarray(out[1], np.float64))
        obj = np.rint(out[2][..., 1]).astype(np.int32)
        t = np.where(obj >= 0, out[2][..., 0], np.inf).astype(np.float64)
        return sums, t, obj, np.ascontiguousarray(out[3][..., :3])

    def _list_target(self, lw: int, lh: int):
        if self._list_size != (lw, lh):
            self._release_list()
            self._list_tex = self.ctx.texture((lw, lh), 2, dtype="i4")
            self._list_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._list_targets = [self.ctx.texture((lw, lh), 4, dtype="f4") for _ in range(2)]
            self._list_fbo = self.ctx.framebuffer(color_attachments=self._list_targets)
            self._list_size = (lw, lh)
        return self._list_tex, self._list_fbo

    def add_samples(self, pixels: np.ndarray, offsets: np.ndarray, first_index: int):
        """Trace samples first_index, first_index + 1, ... (offsets[k] for
        sample first_index + k) of the pixels with flat indices `pixels`
        (j * W + i, j from the top row; listed in coherent_order).  A
        generator: it yields after each draw call (the viewer's frames,
        progress, Ctrl-C) and returns the sums (total (n, 4) = sum (L, 1),
        moments (n, 4) = sum (L [odd sample index], L.L)) in the order of
        `pixels`."""
        ctx, w = self.ctx, self.width
        n = len(pixels)
        lw = LIST_WIDTH * max(1, -(-n // (LIST_WIDTH * MAX_LIST_HEIGHT)))
        lh = max(1, -(-n // lw))
        tex, fbo = self._list_target(lw, lh)
        ij = np.full((lh * lw, 2), -1, np.int32)
        ij[:n, 0] = pixels % w
        ij[:n, 1] = pixels // w
        tex.write(ij.tobytes())                    # row 0 of the texture = list entries 0..lw-1
        prog, vao = self._program(ADAPTIVE_LIST=1)
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        k0 = 0
        while k0 < len(offsets):
            # about fragments_per_draw pixel-samples per draw: a batch of
            # samples for some rows of the list
            batch = max(1, min(MAX_BATCH, len(offsets) - k0, self.fragments_per_draw // max(1, n)))
            chunk = offsets[k0:k0 + batch]
            padded = np.zeros((MAX_BATCH, 2))
            padded[:len(chunk)] = chunk
            y = 0
            while y < lh:
                rows = max(1, self.fragments_per_draw // (lw * batch))
                # (re)bound before every draw: between yields the caller may
                # have used the context for something else (the viewer)
                self.renderer.bind(prog, w, self.height, (0.5, 0.5))
                prog["pixelList"].value = 1
                prog["batchSize"].value = len(chunk)
                prog["firstSample"].value = int(first_index + k0)
                prog["batchOffsets"].value = [tuple(map(float, o)) for o in padded]
                fbo.use()
                tex.use(location=1)
                ctx.enable(moderngl.BLEND)
                ctx.blend_func = moderngl.ONE, moderngl.ONE
                ctx.blend_equation = moderngl.FUNC_ADD
                ctx.scissor = (0, y, lw, min(rows, lh - y))
                try:
                    vao.render(moderngl.TRIANGLES, vertices=3)
                    ctx.finish()
                    self.last_draw_fragments = min(rows, lh - y) * lw * batch
                finally:
                    ctx.scissor = None
                    ctx.disable(moderngl.BLEND)
                y += rows
                yield
            k0 += batch
        total, moments = (np.frombuffer(fbo.read(attachment=a, components=4, dtype="f4"), np.float32)
                          .reshape(lh * lw, 4)[:n] for a in (0, 1))
        return total.astype(np.float64), moments.astype(np.float64)

    def _release_list(self) -> None:
        for obj in (self._list_fbo, self._list_tex, *self._list_targets):
            if obj is not None:
                obj.release()
        self._list_fbo = self._list_tex = None
        self._list_targets = []
        self._list_size = (0, 0)

    def release(self) -> None:
        self._release_list()
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()


class AdaptiveRender:
    """One adaptive render, advanced one GPU draw at a time by step() (the
    viewer spreads it over frames) or to the end by run().  The sums live
    here, in float64, per pixel: sum (L, 1) and sum (L [odd index], L.L)."""

    def __init__(self, renderer, width: int, height: int, samples: int | None = None,
                 target_error: float = DEFAULT_TARGET_ERROR, seed: int = 0, max_spp: int | None = None):
        samples = int(samples or renderer.scene.render.samples)
        self.width, self.height = width, height
        self.samples = samples
        self.target_error = float(target_error)
        self.max_spp = int(max_spp or min(MAX_SPP_FACTOR * samples, MAX_SPP))
        self.budget = samples * width * height
        self.offsets = progressive_offsets(self.max_spp, seed)
        self.sampler = AdaptiveSampler(renderer, width, height)
        self.total = np.zeros((height, width, 4))
        self.moments = np.zeros((height, width, 4))
        self.spent = 0                    # pixel-samples traced
        self.draws_done = 0
        self.rounds: list[tuple[int, int]] = []
        self.done = False
        self._gen = self._run()

    # ------------------------------------------------------------ driving

    def step(self) -> bool:
        """Run one draw call (and the bookkeeping after it); True when done."""
        if self.done:
            return True
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

    def image(self) -> np.ndarray:
        """(H, W, 3) float32: the mean of each pixel's samples so far."""
        return (self.total[..., :3] / np.maximum(self.total[..., 3:], 1)).astype(np.float32)

    def result(self) -> "AdaptiveResult":
        return AdaptiveResult(np.ascontiguousarray(self.image()), self.spp, list(self.rounds))

    def release(self) -> None:
        if self._gen is not None:
            self._gen.close()
            self._gen = None
        self.sampler.release()
        self.done = True

    # ------------------------------------------------------------ the work

    def _run(self):
        w, h = self.width, self.height
        renderer = self.sampler.renderer

        sums, t, obj, normal = yield from self._draws(self.sampler.first_pass((0.5, 0.5)))
        self.total[...] = sums.total
        self.moments[...] = sums.moments
        self.spent = w * h
        self.rounds.append((1, w * h))
        contrast = colour_contrast(sums.mean)
        self._contrast = contrast
        self._own = own_error(sums, contrast)   # one sample: the sliver term only
        flagged = contrast > max(self.target_error, FLAG_CONTRAST)
        # An edge of the first interaction or an aliasing checker counts as
        # an error of EDGE_ERROR until the pixel's samples say otherwise: a
        # target above it leaves such pixels alone.
        if self.target_error < EDGE_ERROR:
            # an edge whose sides look alike (within the target) is no error:
            # a box of one colour stays at one sample
            flagged |= first_hit_edges(t, obj, normal) & (contrast > self.target_error)
            flagged |= checker_aliasing(renderer.scene, t, obj)
        if FLAG_DILATE:
            flagged = _neighbourhood(flagged, np.maximum)
        # Every flagged pixel first goes to FIRST_ROUND samples (a spread
        # needs several), the most contrasted first if the budget is short.
        chosen = choose_within_budget(flagged, contrast, FIRST_ROUND - 1, self.budget - self.spent)
        yield from self._upgrade(chosen)
        # Then, round by round, the pixels whose estimated error is above the
        # target and largest for its cost double their samples, until the
        # budget is spent.  A pixel that is not flagged keeps one sample.
        while True:
            count = self.total[..., 3]
            error = with_neighbours(self._own)       # estimated_error, own part kept up to date
            want = flagged & (error > self.target_error) & (count * ROUND_FACTOR <= self.max_spp)
            left = self.budget - self.spent
            chosen = choose_by_gain(want, error, count, left, ROUND_SHARE)
            if not chosen.any():
                break
            yield from self._upgrade(chosen)

    def _refresh_own(self, flat: np.ndarray) -> None:
        """own_error of the pixels just sampled (the others are unchanged)."""
        sums = Sums(self.total.reshape(-1, 4)[flat][:, None], self.moments.reshape(-1, 4)[flat][:, None])
        self._own.ravel()[flat] = own_error(sums, self._contrast.ravel()[flat][:, None])[:, 0]

    def _upgrade(self, chosen: np.ndarray):
        """Take every chosen pixel from n to ROUND_FACTOR x n samples (from
        one sample: to FIRST_ROUND), one pixel list per current count."""
        count = np.rint(self.total[..., 3]).astype(np.int64).ravel()
        flat_all = np.flatnonzero(chosen.ravel())
        if len(flat_all) == 0:
            return
        for n in np.unique(count[flat_all]):
            flat = coherent_order(flat_all[count[flat_all] == n], self.width)
            n_next = FIRST_ROUND if n == 1 else int(n) * ROUND_FACTOR
            n_next = min(n_next, self.max_spp)
            yield from self._add(flat, int(n), n_next)
            self.rounds.append((n_next, len(flat)))

    def _draws(self, gen):
        """Run one of the sampler's generators, counting its draw calls (one
        per yield); returns what it returns."""
        while True:
            try:
                next(gen)
            except StopIteration as stop:
                return stop.value
            self.draws_done += 1
            yield

    def _add(self, flat: np.ndarray, n_prev: int, n: int):
        """Samples n_prev .. n - 1 of the pixels `flat` (all at n_prev)."""
        tot, mom = yield from self._draws(self.sampler.add_samples(flat, self.offsets[n_prev:n], n_prev))
        self.total.reshape(-1, 4)[flat] += tot
        self.moments.reshape(-1, 4)[flat] += mom
        self.spent += len(flat) * (n - n_prev)
        self._refresh_own(flat)


def render_adaptive(renderer, width: int, height: int, samples: int | None = None,
                    target_error: float = DEFAULT_TARGET_ERROR, seed: int = 0,
                    progress: Callable[[int, int], None] | None = None,
                    max_spp: int | None = None) -> AdaptiveResult:
    """Render spending at most `samples` (the scene's samples when None)
    samples per pixel on average -- samples x W x H in all -- where a pixel's
    estimated error is above target_error (linear, largest channel); one
    pixel takes at most max_spp (default MAX_SPP_FACTOR x samples).  When the
    budget runs short, the pixels with the largest estimated error go first.
    The image converges to the same box-filtered picture as Renderer.render."""
    job = AdaptiveRender(renderer, width, height, samples, target_error, seed, max_spp)
    try:
        return job.run(progress)
    finally:
        job.release()
