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
Samples follow sampling.progressive_offsets, so every prefix is evenly
spread; everything is deterministic for a seed.  The target error is per
pixel, in linear radiance units (the .npy values), on the largest colour
channel.

This module is the policy (the flags, the rounds, the budget); the
estimates it ranks by are viewer/adaptive/estimators.py's, the chain
footprints viewer/adaptive/chains.py's, the GPU passes
viewer/adaptive/sampler.py's (the footprint mask viewer/gpu/footprint.py's).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable

import numpy as np

from ..base import interrupt
from ..base.sampling import progressive_offsets
from ..gpu.footprint import FOOTPRINT_EXACT, drain, fold, footprint_default, footprint_planes, pixel_corners
from ..gpu.renderer import clamp_radiance
from .chains import chain_footprints
from .estimators import (FIRST_ROUND, Sums, checker_cells_differ, choose_by_gain, choose_within_budget,
                         colour_contrast, corner_chains_differ, corner_contrast, corner_objects_differ,
                         next_count, own_error, sliver_error, with_neighbours)
from .pixel_lists import image_coherent_order
from .sampler import AdaptiveSampler

# The per-pixel target (linear, largest channel) when none is given.
# Measured on glass-sphere at 320x180, budgets 8-24: 0.005 stops short of
# the budget (RMSE 2.45e-3 at 24 where 0.002 gives 2.07e-3); 0.001 and
# 0.0005 give the same errors as 0.002.
DEFAULT_TARGET_ERROR = 0.002
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


@lru_cache(maxsize=16)
def _offsets(n: int, seed: int) -> np.ndarray:
    """progressive_offsets(n, seed), read-only and cached: scrambling takes
    about 8 ms (64 hashes of arrays), as much as a round's bookkeeping in a
    small render, and the viewer and the benchmark render again and again."""
    out = progressive_offsets(n, seed)
    out.setflags(write=False)
    return out


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
        # Footprint samples (FOOTPRINT_AA, shaders/lib/sample.glsl) where a pixel's
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
        through = fold(np.logical_or, [bends[o] for o in pixel_corners(corner_obj) + [obj]])
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
