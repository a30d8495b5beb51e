"""Adaptive anti-aliasing: samples go only to the pixels that still need them.

The error left in a correct Whitted image is almost all pixel footprint
(silhouettes, checker edges, the checker toward the horizon, the refracted
picture inside glass); a flat region is exact with one centred sample.  So:

1. Round 0 traces sample 0 (the pixel centre) everywhere.  A pixel needs more
   when its 3x3 neighbourhood says its footprint may not be flat: a
   neighbour's colour differs by more than the target error, the first hit
   changes across it (another object, a normal turned by more than
   NORMAL_ANGLE_DEG, a relative depth jump over DEPTH_JUMP), or neighbouring
   rays land on a checker more than half a check apart (where centre
   samples alias into flat-looking patches).  Everything else ends with one
   sample.
2. Later rounds take the pixels still active to 4, 16, 64, ... samples.  A
   pixel's error is estimated from its own samples (the difference of its
   even- and odd-index halves, and its standard error) and, for a pixel
   whose samples agree, from the sliver of an edge they may all have missed
   (half its round-0 contrast over n).  It stops for good once that is at
   most the target error.
3. The budget is samples x W x H pixel-samples in all (the mean samples per
   pixel), one pixel taking at most MAX_SPP_FACTOR x samples.  When a round
   cannot pay for every active pixel, those with the largest estimated
   error go first.

Each sample is drawn over the bounding boxes of the active pixels (one per
renderer tile that holds any), and the shader discards inactive pixels
before tracing (llvmpipe skips a 4x4 block whose pixels all discard).
Samples follow sampling.progressive_offsets (Sobol'), so every prefix is
evenly spread.  Everything is deterministic for a seed.

The target error is per pixel, in linear radiance units (the .npy values),
on the largest colour channel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import moderngl
import numpy as np

from .sampling import progressive_offsets

# The per-pixel target (linear, largest channel) when none is given: chosen
# from measurements (README, "Adaptive anti-aliasing").
DEFAULT_TARGET_ERROR = 0.005
NORMAL_ANGLE_DEG = 25.0
DEPTH_JUMP = 0.1
# Rounds: 1 sample, then 4, 16, 64, ... per active pixel.  Powers of four
# are where the Sobol' points fill a square grid of strata (2x2, 4x4, 8x8),
# which suits edges of any direction; measured better than doubling.
FIRST_ROUND = 4
ROUND_FACTOR = 4
# One pixel takes at most this many times the mean budget, and never more
# than MAX_SPP: an edge pixel may need far more than the average.
MAX_SPP_FACTOR = 8
MAX_SPP = 1024
SLIVER = 0.5


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


def sliver_error(contrast: np.ndarray, n: int) -> np.ndarray:
    """What n samples that all agree may still miss: an edge of contrast C
    (the neighbourhood's, from round 0) whose sliver inside the pixel falls
    between them, about 1/n of the pixel at most, SLIVER x C / n on
    average.  Without this a pixel next to an edge stops as soon as its
    samples agree, and those pixels carried most of the error left."""
    return SLIVER * contrast / n


def round_schedule(max_spp: int, first: int = FIRST_ROUND) -> list[int]:
    """Samples per active pixel after each round: 1, first, first x
    ROUND_FACTOR, ... capped at max_spp (the last entry is max_spp)."""
    out = [1]
    n = first
    while out[-1] < max_spp:
        out.append(min(n, max_spp))
        n *= ROUND_FACTOR
    return out


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


def active_rects(active: np.ndarray, tile: int) -> list[tuple[int, int, int, int]]:
    """Scissor rectangles (x, y, w, h) in framebuffer pixels (y up): the
    image cut into tile x tile squares (the renderer's draw size), and in
    each the bounding box of its active pixels; squares without one are
    left out.  active is (H, W) with the first row at the top."""
    h, w = active.shape
    fb = active[::-1]                                # framebuffer rows: bottom first
    rects = []
    for y in range(0, h, tile):
        for x in range(0, w, tile):
            sub = fb[y:y + tile, x:x + tile]
            rows = np.flatnonzero(sub.any(axis=1))
            if len(rows) == 0:
                continue
            cols = np.flatnonzero(sub.any(axis=0))
            rects.append((x + int(cols[0]), y + int(rows[0]),
                          int(cols[-1] - cols[0]) + 1, int(rows[-1] - rows[0]) + 1))
    return rects


# ---------------------------------------------------------------- the GPU part


class AdaptiveSampler:
    """Owns the two accumulation targets and the mask texture for one image
    size; `add(offsets, first_index, active)` traces samples for the active
    pixels.  Used by render_adaptive and by the viewer."""

    def __init__(self, renderer, width: int, height: int):
        self.renderer = renderer
        self.ctx: moderngl.Context = renderer.ctx
        self.width, self.height = width, height
        ctx = self.ctx
        self._total = ctx.texture((width, height), 4, dtype="f4")
        self._moments = ctx.texture((width, height), 4, dtype="f4")
        self.fbo = ctx.framebuffer(color_attachments=[self._total, self._moments])
        self._mask = ctx.texture((width, height), 1, dtype="f1")
        self._vaos: dict[int, moderngl.VertexArray] = {}
        self.clear()

    def clear(self) -> None:
        self.fbo.clear(0.0, 0.0, 0.0, 0.0)

    def _vao(self) -> tuple[moderngl.Program, moderngl.VertexArray]:
        prog = self.renderer.variant(ADAPTIVE=1)
        vao = self._vaos.get(id(prog))
        if vao is None:
            vao = self.ctx.vertex_array(prog, [])
            self._vaos[id(prog)] = vao
        return prog, vao

    def add(self, offsets: np.ndarray, first_index: int, active: np.ndarray,
            between: Callable[[], None] | None = None) -> int:
        """Trace samples first_index, first_index + 1, ... (offsets[i] is the
        offset of sample first_index + i) for the pixels where `active`
        ((H, W) bool, top row first) is set.  between() is called after each
        draw call (progress, Ctrl-C).  Returns the number of draw calls."""
        ctx = self.ctx
        rects = active_rects(active, self.renderer.tile)
        if not rects:
            return 0
        mask = np.ascontiguousarray(active[::-1], dtype=np.uint8) * np.uint8(255)
        self._mask.write(mask.tobytes())
        prog, vao = self._vao()
        self.fbo.use()
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        ctx.blend_equation = moderngl.FUNC_ADD
        self._mask.use(location=1)
        try:
            for i, off in enumerate(offsets):
                self.renderer.bind(prog, self.width, self.height, off)
                prog["activeMask"].value = 1
                prog["sampleParity"].value = float((first_index + i) % 2)
                for rect in rects:
                    # One full-screen triangle per rectangle, the scissor
                    # keeping it to the rectangle.  (Small quads per tile cost
                    # 50% more on llvmpipe: the 4x4 blocks on each quad's
                    # diagonal are shaded once per triangle.)
                    ctx.scissor = rect
                    vao.render(moderngl.TRIANGLES, vertices=3)
                    ctx.finish()
                    if between is not None:
                        between()
        finally:
            ctx.scissor = None
            ctx.disable(moderngl.BLEND)
        return len(rects) * len(offsets)

    def read(self) -> "Sums":
        """The per-pixel sums so far, top row first."""
        shape = (self.height, self.width, 4)
        return Sums(*(np.frombuffer(t.read(), np.float32).reshape(shape)[::-1]
                      for t in (self._total, self._moments)))

    def release(self) -> None:
        for vao in self._vaos.values():
            vao.release()
        for obj in (self.fbo, self._total, self._moments, self._mask):
            obj.release()


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
    samples = samples or renderer.scene.render.samples
    max_spp = max_spp or min(MAX_SPP_FACTOR * samples, MAX_SPP)
    budget = samples * width * height
    offsets = progressive_offsets(max_spp, seed)
    sampler = AdaptiveSampler(renderer, width, height)
    rounds: list[tuple[int, int]] = []
    spent = 0

    def tick(per_draw: int, total: int):
        def step() -> None:
            nonlocal spent
            spent += per_draw
            if progress is not None:
                progress(min(spent, total), total)
        return step

    try:
        active = np.ones((height, width), bool)
        error = np.zeros((height, width))
        n_prev = 0
        for n in round_schedule(max_spp):
            active = choose_within_budget(active, error, n - n_prev, budget - spent)
            count = int(active.sum())
            if count == 0:
                break
            draws = len(active_rects(active, renderer.tile)) * (n - n_prev)
            before = spent
            sampler.add(offsets[n_prev:n], n_prev, active, tick(count * (n - n_prev) // draws, budget))
            spent = before + count * (n - n_prev)
            rounds.append((n, count))
            if n >= max_spp:
                break
            sums = sampler.read()
            if n == 1:
                t, obj, normal = renderer.first_hits(width, height)
                active = ((colour_contrast(sums.mean) > target_error) | first_hit_edges(t, obj, normal)
                          | checker_aliasing(renderer.scene, t, obj))
                # before any spread is known, the neighbourhood contrast ranks
                contrast = colour_contrast(sums.mean)
                error = contrast
            else:
                error = np.maximum(pixel_error(sums), sliver_error(contrast, n))
                active &= error > target_error
            n_prev = n
        if progress is not None:
            progress(budget, budget)
        total = sampler.read().total
    finally:
        sampler.release()
    spp = np.rint(total[..., 3]).astype(np.int32)
    image = total[..., :3] / np.maximum(total[..., 3:], 1)
    return AdaptiveResult(np.ascontiguousarray(image, np.float32), spp, rounds)
