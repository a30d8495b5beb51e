"""Quality by error budget: the fastest measured settings whose error stays
within a given RMSE (``glassray render --max-error E``, the viewer's "max
error" setting).

For a scene and an image size, a grid of candidate settings (samples per
pixel :data:`SAMPLES` x (max depth, min weight) pairs :data:`TRACE`, 20 in
all) is measured once on this machine, on about :data:`MEASURE_PIXELS`
pixels:

* **error**: RMSE over all measured pixels and channels in linear space
  against a reference: the metric of ``glassray bench``
  (:func:`viewer.measure.kit.image_errors`).  The pixels are :data:`GRID` x
  :data:`GRID` small tiles of the real image, one at a seeded random place in
  each cell of a grid over it (the shader is given camera vectors that make
  a small framebuffer show exactly those pixels of the W x H image), so the
  error is the error at the real size: a scaled-down picture would count
  edges, where the sampling error lives, many times over.  The candidates
  take the samples ``glassray render`` takes (Renderer.render): one sample
  is the centred point sample; from two samples on, on a scene with a
  checkered plane, footprint samples (shaders/lib/footprint.glsl) with the
  full image's footprint mask for the measured pixels
  (:meth:`Measurement._footprint_mask`), so the checker's aliasing, which
  render's footprint samples remove, is not counted.  (Measured with point
  samples, glass-sphere at 160x90 gave 16 samples 0.0124 where the render's
  error was 0.0049.)  Where the tiles are a part of the image, a control
  variate takes out most of their sampling error: the error max depth and
  min weight leave (truncation: what a tree cut shallower misses) lives in
  a few pixels (on the default scene at 640x360, 1% of the pixels hold
  70% of the squared error), which a sample of tiles meets by chance (over
  300 layouts the 4-sample depth-6 RMSE measured 0.008 to 0.023, 10th to
  90th percentile, for a whole image's 0.0172).  So each (max depth, min weight) and the reference's
  are also drawn with one centred sample over the whole image, and a
  candidate's mean squared error is the mosaic's minus the mosaic's part
  of the centred samples' squared difference plus the whole image's
  (:meth:`Measurement._centre_full`): over the same layouts 0.0164 to
  0.0176 (10th to 90th percentile).  The pick holds the RMSE plus its standard error (the tiles'
  spread of what is left: :func:`tile_standard_error`) against the budget.
* **reference**: the scene's own shader with max depth 16 and min weight
  1e-4 (the bench's reference trace settings; going deeper changes the
  default scene by about 4e-4 RMSE) and :data:`REFERENCE_SAMPLES` samples,
  footprint samples as above where the scene has a checkered plane (the
  same limit as point samples, the box-filtered pixel, with far less noise
  on the checker): the mean of two independent stratified patterns of half
  as many (seeds 1 and 2; the candidates use seed 0, as ``glassray render``
  does), whose difference estimates the reference's own noise (``noise`` =
  RMSE(A - B) / 2, reported).  Not min weight 0: on the glass of water it
  is ten times slower (4.6 s against 0.44 s a sample at 160x90 on llvmpipe)
  for a change far below that noise.  Not the float64 NumPy tracer
  (``reference_cache.reference_image``): the GPU already agrees with it
  (tests/test_gpu_vs_reference.py) and it is one to two orders of magnitude
  slower; what is measured here is convergence in samples, depth and weight.
  Measured errors include the reference's noise (they are not corrected
  for it: the estimate above is low where the two patterns' errors
  correlate, and at 64 samples the correction moved the errors by less than
  the mosaic's own sampling error), so a budget below it cannot be resolved.
* **time**: the whole picture, at its own size up to
  :data:`FULL_TIMING_PIXELS` (a warm-up pass then :data:`FULL_TIMED_PASSES`
  timed passes of one sample), larger ones scaled down to about that many
  pixels (its cost per pixel is the full image's: the mean rays per pixel
  agree), each finished on the GPU; a candidate's time is (the median pass
  x its samples + one read-back of the picture) x (full pixels / timed
  pixels): an estimate of one W x H frame as ``glassray render --timing``
  measures it.  (Scaled down further, a pass's fixed cost was scaled up
  with the pixels: the default scene at 640x360 timed at 160x90 was
  estimated 20-40% slow, at 1920x1080 1.6-2.6x.)  A candidate
  that takes footprint samples is timed with them, and with its picture's
  mask made once (:meth:`Measurement._timed_footprint`).

The measurements are cached as JSON (the reference as .npy beside it) in
``$XDG_CACHE_HOME/glassray/quality`` (default ``~/.cache/glassray/quality``),
one file per key: the scene's content less the three settings being chosen
(camera and lights included: what is seen decides the error), the machine
(GL renderer, CPU model, usable CPUs), the image size, the shader sources,
the Python modules that decide pixels and times (:data:`viewer.measure.quality_cache.MEASURED_CODE`) and
the measuring method.  Files are written atomically; an unreadable or
corrupt one is measured again, with one warning.

Explicit settings fix their value: ``--samples 4 --max-error E`` chooses among
the candidates with 4 samples (a value off the grid is measured and added to
the cache).  When no candidate meets E, the most accurate one is used and the
line says so (exit 0: a budget is a request, not a contract).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..scene.load import with_overrides
from .quality_cache import Cache, make_key
from .quality_grid import MEASURE_PIXELS, Candidate, Layout, Measured, candidate_grid, layout, pick
from .quality_measure import Measurement

@dataclass
class Choice:
    measured: Measured
    met: bool
    max_error: float
    cache_hit: bool
    layout: Layout
    noise: float  # the reference's own sampling noise (RMSE, estimated)
    cache_path: Path | None = None
    candidates: int = 0
    cut_pixels: int = 0  # measured pixels left out: the driver's loop limit cut their trees

    def line(self) -> str:
        m = self.measured
        W, H = self.layout.full
        t = f"{m.time_ms / 1000:.2f} s" if m.time_ms >= 1000 else f"{m.time_ms:.1f} ms"
        what = (f"picked {m.candidate.describe()}" if self.met else
                f"no measured setting reaches it; using the most accurate: {m.candidate.describe()}"
                if math.isfinite(m.rmse) else
                f"no error could be measured; using the setting that traces the most: {m.candidate.describe()}")
        rmse = f"{m.rmse:.3g}" + (f" +- {m.rmse_se:.2g}" if m.rmse_se > 0 else "")
        return (f"max-error {self.max_error:g}: {what} (measured RMSE {rmse}, {t} per {W}x{H} frame; "
                f"{self.candidates} candidates measured on {self.layout.pixels} of its pixels, reference "
                f"noise {self.noise:.2g}; cache {'hit' if self.cache_hit else 'miss'})"
                + (f"; {self.cut_pixels} of the {self.layout.pixels} pixels left out: this OpenGL driver's loop "
                   "limit cut their ray trees, so the errors miss them" if self.cut_pixels else ""))


def prepare(ctx, scene, width: int, height: int, samples: int | None = None, max_depth: int | None = None,
            min_weight: float | None = None, root: Path | None = None,
            pixels: int = MEASURE_PIXELS) -> tuple[Measurement, Cache, list[Candidate]]:
    """The measurement still needed for this scene at this image size
    (done at once on a cache hit)."""
    lay = layout(width, height, pixels)
    cache = Cache(make_key(ctx, scene, lay), root)
    cands = candidate_grid(samples, max_depth, min_weight)
    known = cache.load()
    noise = getattr(cache, "noise", float("nan"))
    cut = getattr(cache, "cut_pixels", 0)
    ref = None
    if any(c.key() not in known for c in cands):
        ref = cache.load_reference() if known else None
        if ref is None:
            known = {}  # a new reference: the old errors were measured against another one
    return Measurement(ctx, scene, lay, cands, known, ref, noise, cut), cache, cands


def finish(meas: Measurement, cache: Cache, cands: list[Candidate], max_error: float) -> Choice:
    """Save what was measured and pick."""
    hit = not meas.todo
    if not hit and not meas.saved:
        # once: the viewer picks again from the same measurement whenever its
        # budget changes, and that is no new measurement to write
        cache.save(meas.measured, meas.noise, meas.reference, meas.cut_pixels)
        meas.saved = True
    pool = [meas.measured[c.key()] for c in cands]
    m, met = pick(pool, max_error)
    return Choice(m, met, max_error, hit, meas.layout, meas.noise, cache.path, len(pool), meas.cut_pixels)


def choose(ctx, scene, width: int, height: int, max_error: float, samples: int | None = None,
           max_depth: int | None = None, min_weight: float | None = None, root: Path | None = None,
           progress: Callable[[int, int], None] | None = None, pixels: int = MEASURE_PIXELS) -> Choice:
    """Measure (or read from the cache) and pick, blocking."""
    meas, cache, cands = prepare(ctx, scene, width, height, samples, max_depth, min_weight, root, pixels)
    meas.run(progress)
    return finish(meas, cache, cands, max_error)


def apply(scene, choice: Choice):
    """A copy of the scene with the picked settings."""
    c = choice.measured.candidate
    return with_overrides(scene, samples=c.samples, max_depth=c.max_depth, min_weight=c.min_weight)


def parse_max_error(text: str) -> float:
    """argparse type of --max-error: a finite number > 0."""
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a number > 0 (an RMSE in linear units, such as 0.01), "
                                         f"got {text!r}")
    return v


def scene_for_max_error(ctx, scene, args, width: int, height: int,
                        progress: Callable[[int, int], None] | None = None):
    """``glassray render --max-error E``: the scene with the picked settings;
    prints one line on stderr.  Explicit --samples / --max-depth /
    --min-weight fix those values."""
    choice = choose(ctx, scene, width, height, args.max_error, samples=getattr(args, "samples", None),
                    max_depth=getattr(args, "max_depth", None), min_weight=getattr(args, "min_weight", None),
                    progress=progress)
    print(f"glassray: {choice.line()}", file=sys.stderr, flush=True)
    return apply(scene, choice)
