"""Sweep the settings that trade frame time for image error and mark the Pareto front.

``glassray bench [SCENE]`` renders each benchmark scene under a set of
settings (max depth, samples per pixel, min weight, resolution scale, the
scene-specialised against the generic all-features shader, exact Fresnel
against Schlick's approximation, adaptive sampling at a few target errors and
sample budgets), times every setting and measures its error against a
converged float64 reference image:

* adaptive settings (``Setting.adaptive`` = the per-pixel target error) render
  with ``viewer.adaptive.render_adaptive`` with the setting's samples as the
  mean budget per pixel, same seed as the uniform renders; the time is all
  of render_adaptive (its passes, its NumPy bookkeeping between them and the
  read-back), and the samples per pixel it actually used on average
  (``mean_spp``, at most the budget: pixels below the target stop early) is
  reported next to the budget.  The Pareto front is one front over uniform
  and adaptive settings together.

* time: untimed warm-up renders per setting until one compiles no shader
  program (``warm_up``; the last one's image is the one compared), then
  ``--repeat`` timed renders, each finished on the GPU before the clock
  stops (the read-back waits for it); machine.json counts the programs they
  built (``programs_built_in_timed_rounds``: 0 unless the warm-up gave up).
  The timed renders are interleaved in rounds (every setting once per
  round, the order reversed every other round), so a burst of load from
  other processes spreads over all settings instead of landing on one.
  Two clocks, medians of both: wall-clock frame time, and the process's
  CPU time (all threads: on a software renderer such as
  llvmpipe, the work done, which other load on the machine hardly changes;
  on a hardware GPU it is only the driver's share and means little).  A
  resolution-scaled setting is timed at its reduced size (the upscale,
  bilinear, is a blit on a real GPU and is not counted).
* error: against the float64 NumPy tracer (``viewer.reference``) at the full
  size with ``--reference-samples`` samples of the shared stratified pattern
  (seed 1, while the timed renders use seed 0, so no setting shares the
  reference's sample positions beyond the always-centred first one), max
  depth 16 and min weight 1e-4 (deeper than any setting swept; going to depth
  32 / 1e-6 changes the default scene's reference by 4e-4 RMSE, under
  the reference's own sampling noise: about 1.2e-3 at 128 samples and
  320x180 on the default scene, glass-sphere and bench-opaque, measured as
  the RMSE between references of seeds 1 and 2 over sqrt(2); a reported
  RMSE e is about sqrt(e_true^2 + 1.2e-3^2), so the smallest ones, about
  1.4e-3 on bench-opaque and glass-sphere, are mostly the reference's
  noise).  With
  ``--reference-refine N`` the pixels whose samples disagree (edges, a
  checker finer than the pixel) take N samples instead
  (``viewer.reference.render_reference_refined``; the peer comparison's
  default, as its renderers get below the plain reference's own error).
  Reference images are cached in the
  output folder, keyed by scene content, size, samples and the reference
  tracer's source.  Metrics: RMSE over all pixels and channels in linear
  space, the fraction of pixels with a channel more than 1/255 off in
  display space (the spec's encoding), the largest absolute linear difference.
* Pareto front of (time, RMSE), per clock: a setting is on it when no other
  setting is as fast and as good and better in one.  Time differences under
  ``--time-tolerance`` (5%) count as ties (measurement noise), and so do RMSE
  differences under ``--error-tolerance`` (1%: a change that small, such as
  depth 8 against 10 behind a glass sphere, is far below the images' sampling
  noise, which then sets its sign).

Writes to ``--out`` (default ./bench-results): results.csv, results.md (the
tables), machine.json (platform, CPU, load, GL renderer, versions, date,
command, the headline numbers) and pareto.png / pareto-cpu.png (time against
RMSE, log axes, Pareto front marked, default settings labelled, adaptive
settings in their own colour with the front of the uniform settings alone
drawn dotted for comparison; these need
matplotlib: ``pip install glassray[bench]``).  The same tables go to stdout.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import datetime as _dt
import hashlib
import io
import json
import math
import os
import platform
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..adaptive.sampler import DEFAULT_TARGET_ERROR, footprint_default  # (no GL at import: the module creates no context)
from ..base.files import AtomicSet

#: The benchmark's scenes when none is named: the default scene, opaque only,
#: one glass sphere, many objects.
DEFAULT_SCENES = ("default", "bench-opaque", "glass-sphere", "bench-many")
DEFAULT_SIZE = (320, 180)
DEFAULT_REPEAT = 5
DEFAULT_REFERENCE_SAMPLES = 128
QUICK_REFERENCE_SAMPLES = 4
RENDER_SEED = 0
REFERENCE_SEED = 1
REFERENCE_MAX_DEPTH = 16
REFERENCE_MIN_WEIGHT = 1e-4
#: --reference-refine: a pixel whose reference samples all lie within this
#: (linear, after the exposure) keeps them; any other takes the refined count
REFINE_TOLERANCE = 2.5e-4

DEFAULT_TIME_TOLERANCE = 0.05
#: RMSEs closer than this (relative) are one error.  Two settings that
#: differ only slightly (depth 8 against 10 behind a glass sphere) change
#: the image far less than its sampling noise, and the sign of such a small
#: RMSE difference is then set by that noise, not by quality.
DEFAULT_ERROR_TOLERANCE = 0.01
CLOCKS = ("wall", "cpu")

CSV_COLUMNS = ("scene", "setting", "is_default", "pareto_wall", "pareto_cpu", "max_depth", "samples",
               "adaptive_target", "mean_spp", "min_weight", "scale", "width", "height", "specialise", "fresnel",
               "footprint",
               "time_ms", "time_min_ms", "time_max_ms", "cpu_ms", "repeat", "rmse", "frac_off_1_255", "max_abs_err")


# ---------------------------------------------------------------- settings


@dataclass(frozen=True)
class Setting:
    """One point of the sweep.  ``label`` names what differs from the scene's
    own settings ("default" for none).  ``adaptive``: None for uniform
    sampling (``samples`` per pixel everywhere), else the per-pixel target
    error of adaptive sampling (viewer.adaptive), ``samples`` then being the
    mean budget per pixel.  ``footprint`` False: point samples only (no
    footprint samples on a checkered plane: Renderer.render's and
    render_adaptive's footprint=False)."""
    label: str
    max_depth: int
    samples: int
    min_weight: float
    scale: float = 1.0
    specialise: bool = True
    fresnel: str = "exact"
    adaptive: float | None = None
    footprint: bool = True

    def key(self) -> tuple:
        return (self.max_depth, self.samples, self.min_weight, self.scale, self.specialise, self.fresnel,
                self.adaptive, self.footprint)


#: Adaptive points of the full sweep: (target error, budget as a multiple of
#: the scene's samples).  0.05 and 0.01 stop before the budget on some
#: scenes; the default target (viewer.adaptive.DEFAULT_TARGET_ERROR) spends
#: it, at 1x, 2x and 4x the scene's samples: what adaptive sampling reaches
#: with more samples to spend.  The uniform sweep gets a setting at every
#: adaptive budget, so each has its uniform counterpart.
ADAPTIVE_SWEEP = ((0.05, 1), (0.01, 1), (DEFAULT_TARGET_ERROR, 1), (DEFAULT_TARGET_ERROR, 2),
                  (DEFAULT_TARGET_ERROR, 4))
#: --quick: one adaptive point, the default target at the scene's samples.
QUICK_ADAPTIVE_SWEEP = ((DEFAULT_TARGET_ERROR, 1),)


def adaptive_label(target: float, samples: int) -> str:
    return f"adaptive e={target:g} spp<={samples}"


def _fmt_w(w: float) -> str:
    return f"{w:g}"


def sweep(scene, quick: bool = False, reference_samples: int | None = None) -> list[Setting]:
    """The settings benchmarked for one scene: its own settings ("default"),
    each knob moved on its own, and a few combined presets.  Sample counts
    at or above the reference's are left out (they would measure the
    reference's own noise)."""
    r = scene.render
    base = Setting("default", r.max_depth, r.samples, r.min_weight)
    out: list[Setting] = [base]

    def add(s: Setting) -> None:
        if reference_samples is not None and s.samples != base.samples and s.samples >= reference_samples:
            return
        if all(s.key() != o.key() for o in out):
            out.append(s)

    def add_adaptive(points) -> None:
        for target, factor in points:
            n = r.samples * factor
            add(replace(base, label=adaptive_label(target, n), samples=n, adaptive=target))

    if quick:
        add(replace(base, label="max_depth=2", max_depth=2))
        add(replace(base, label=f"samples={1 if r.samples > 1 else 2}", samples=1 if r.samples > 1 else 2))
        add(replace(base, label="min_weight=0.01", min_weight=0.01))
        add(replace(base, label="scale=0.5", scale=0.5))
        add(replace(base, label="generic", specialise=False))
        add(replace(base, label="schlick", fresnel="schlick"))
        add_adaptive(QUICK_ADAPTIVE_SWEEP)
        return out
    for d in (1, 2, 4, 6, 8, 12):
        if d != r.max_depth:
            add(replace(base, label=f"max_depth={d}", max_depth=d))
    # every adaptive budget as a uniform setting too: a like-for-like comparison
    for s in sorted({1, 4, 8, 16, 32} | {r.samples * f for _, f in ADAPTIVE_SWEEP}):
        if s != r.samples:
            add(replace(base, label=f"samples={s}", samples=s))
    for w in (0.03, 0.01, 0.001, 0.0001):
        if w != r.min_weight:
            add(replace(base, label=f"min_weight={_fmt_w(w)}", min_weight=w))
    for sc in (0.25, 0.5, 0.75):
        add(replace(base, label=f"scale={sc:g}", scale=sc))
    add(replace(base, label="generic", specialise=False))
    add(replace(base, label="schlick", fresnel="schlick"))
    # What footprint samples bring (render's default from 2 samples on a
    # checkered plane): the same samples, point-sampled
    if r.samples > 1 and footprint_default(scene):
        add(replace(base, label="point samples", footprint=False))
    # Combined presets: where several cheap changes together land.
    add(Setting("preset:preview", 4, 1, 0.01, scale=0.5))
    add(Setting("preset:fast", 4, 4, 0.01))
    # Adaptive sampling: the scene's samples and larger budgets, a few targets.
    add_adaptive(ADAPTIVE_SWEEP)
    return out


# ---------------------------------------------------------------- metrics


def image_errors(image, reference) -> dict[str, float]:
    """Error of ``image`` against ``reference`` (both (H, W, 3) linear RGB):
    ``rmse`` over all pixels and channels in linear space, ``frac_off`` the
    fraction of pixels with any channel more than 1/255 off after the spec's
    display encoding, ``max_abs`` the largest absolute linear difference."""
    from ..base.imageio import to_display8

    a = np.asarray(image, dtype=np.float64)
    b = np.asarray(reference, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"image shape {a.shape} differs from the reference's {b.shape}")
    diff = a - b
    d8 = np.abs(to_display8(a).astype(np.int16) - to_display8(b).astype(np.int16)).max(axis=-1)
    return {"rmse": float(np.sqrt(np.mean(diff * diff))),
            "frac_off": float(np.mean(d8 > 1)),
            "max_abs": float(np.max(np.abs(diff))) if diff.size else 0.0}


def upscale(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """Bilinear resize of an (h, w, 3) image to (height, width, 3), pixel
    centres aligned (edge pixels clamped): how a reduced-resolution render is
    shown full size.  Aligned by screen position: the camera's vertical field
    of view is fixed and the horizontal one follows the aspect, so where
    rounding gave the small image another aspect (48x27 at scale 0.5:
    24x14) it spans a different width of the scene, not the whole frame."""
    img = np.asarray(image, dtype=np.float64)
    h, w = img.shape[:2]
    if (h, w) == (height, width):
        return img.copy()

    def coords(n_out: int, n_in: int, stretch: float = 1.0):
        x = ((np.arange(n_out) + 0.5) / n_out - 0.5) * stretch * n_in + 0.5 * n_in - 0.5
        x = np.clip(x, 0.0, n_in - 1)
        i0 = np.floor(x).astype(np.int64)
        i1 = np.minimum(i0 + 1, n_in - 1)
        return i0, i1, x - i0

    y0, y1, fy = coords(height, h)
    x0, x1, fx = coords(width, w, (width / height) / (w / h))
    fx = fx[None, :, None]
    top = img[y0][:, x0] * (1 - fx) + img[y0][:, x1] * fx
    bot = img[y1][:, x0] * (1 - fx) + img[y1][:, x1] * fx
    return top * (1 - fy[:, None, None]) + bot * fy[:, None, None]


def dominates(tj: float, ej: float, ti: float, ei: float, time_tol: float = 0.0, error_tol: float = 0.0) -> bool:
    """Whether point j = (time, error) dominates point i: no slower and no
    worse, and better in at least one.  With tolerances, differences within
    them (relative) are ties: j must be faster than i by more than time_tol
    or better by more than error_tol, and no slower or worse beyond them."""
    no_worse = tj <= ti * (1 + time_tol) and ej <= ei * (1 + error_tol)
    better = tj < ti * (1 - time_tol) or ej < ei * (1 - error_tol)
    return no_worse and better


def pareto_mask(times, errors, time_tol: float = 0.0, error_tol: float = 0.0) -> list[bool]:
    """True for the points that no other point dominates (see dominates)."""
    pts = list(zip((float(t) for t in times), (float(e) for e in errors)))
    return [not any(dominates(tj, ej, ti, ei, time_tol, error_tol) for j, (tj, ej) in enumerate(pts) if j != i)
            for i, (ti, ei) in enumerate(pts)]


def render_size(setting: Setting, width: int, height: int) -> tuple[int, int]:
    return max(1, round(width * setting.scale)), max(1, round(height * setting.scale))


# ---------------------------------------------------------------- reference


def _reference_source_digest() -> str:
    try:
        from ..reference import trace as reference
        from ..base import sampling

        # the tracer and its sample pattern
        return hashlib.sha256(Path(reference.__file__).read_bytes()
                              + Path(sampling.__file__).read_bytes()).hexdigest()[:12]
    except Exception:  # not importable: the GPU fallback is keyed by the shader sources instead
        from ..gpu.shaders import shader_root

        h = hashlib.sha256()
        for p in sorted(shader_root().rglob("*")):
            if p.is_file() and p.suffix in (".frag", ".glsl", ".vert"):
                h.update(p.read_bytes())
        return "gpu-" + h.hexdigest()[:12]


def _reference_scene(scene):
    from ..scene.load import with_overrides

    return with_overrides(scene, max_depth=REFERENCE_MAX_DEPTH, min_weight=REFERENCE_MIN_WEIGHT)


def _scene_digest(scene) -> str:
    from ..scene.save import scene_to_toml

    h = hashlib.sha256(scene_to_toml(scene).encode("utf-8"))
    if scene.sky.type == "image" and scene.sky.image_path is not None:
        try:
            h.update(Path(scene.sky.image_path).read_bytes())
        except OSError:
            pass
    return h.hexdigest()[:12]


def usable_cpus() -> int:
    """The CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def effective_refine(samples: int, refine: int | None) -> int:
    """The refined count a reference of `samples` samples really takes: 0
    (none) unless `refine` is above `samples` and the float64 tracer is
    there (the GPU fallback is never refined)."""
    refine = int(refine or 0)
    return refine if reference_kind() == "float64" and refine > samples else 0


def reference_text(samples: int, refine: int) -> str:
    """How a reference is sampled, for logs and reports."""
    return f"{samples} samples" + (f", {refine} where they disagree by more than {REFINE_TOLERANCE:g}"
                                   if refine else "")


def reference_kind() -> str:
    """"float64" when viewer.reference is importable, else "gpu" (fallback)."""
    try:
        from ..reference.trace import camera_rays, trace  # noqa: F401
    except Exception:
        return "gpu"
    return "float64"


def reference_image(scene, stem: str, width: int, height: int, samples: int, cache_dir: Path | None,
                    ctx=None, log=None, refine: int = 0) -> tuple[np.ndarray, str, bool]:
    """The converged reference image (H, W, 3) float64, its kind ("float64" or
    "gpu") and whether it came from the cache.  ``refine`` > ``samples``:
    pixels whose samples disagree by more than REFINE_TOLERANCE take
    ``refine`` samples (:func:`viewer.reference.render_reference_refined`;
    float64 only)."""
    kind = reference_kind()
    ref_scene = _reference_scene(scene)
    refine = effective_refine(samples, refine)
    spp = f"s{samples}" + (f"r{refine}t{REFINE_TOLERANCE:g}" if refine else "")
    name = (f"ref-{stem}-{_scene_digest(ref_scene)}-{width}x{height}-{spp}-seed{REFERENCE_SEED}"
            f"-d{REFERENCE_MAX_DEPTH}-w{REFERENCE_MIN_WEIGHT:g}-{kind}-{_reference_source_digest()}.npy")
    path = cache_dir / name if cache_dir is not None else None
    if path is not None and path.is_file():
        try:
            img = np.load(path)
            if img.shape == (height, width, 3):
                return img.astype(np.float64), kind, True
        except (OSError, ValueError):
            pass
    t0 = time.perf_counter()
    if kind == "float64" and refine:
        from ..base import interrupt
        from ..reference.trace import render_reference_refined

        img, _ = render_reference_refined(ref_scene, width, height, samples, refine, REFINE_TOLERANCE,
                                          seed=REFERENCE_SEED, workers=usable_cpus(), log=log,
                                          check=interrupt.check)
    elif kind == "float64":
        from ..base import interrupt
        from ..reference.trace import camera_rays, trace
        from ..base.sampling import sample_offsets

        acc = np.zeros((height * width, 3))
        offsets = sample_offsets(samples, REFERENCE_SEED)
        last = t0
        for k, off in enumerate(offsets):
            interrupt.check()                         # Ctrl-C between samples (viewer/interrupt.py)
            o, d = camera_rays(ref_scene, width, height, off)
            acc += trace(ref_scene, o.reshape(-1, 3), d.reshape(-1, 3))
            now = time.perf_counter()
            if log is not None and now - last > 20.0 and k + 1 < samples:
                el, last = now - t0, now
                log(f"  reference {k + 1}/{samples} samples, {el:.0f} s, about {el / (k + 1) * (samples - k - 1):.0f} s left")
        img = acc.reshape(height, width, 3) / samples * ref_scene.render.exposure
    else:
        from ..gpu.renderer import Renderer

        r = Renderer(ctx, ref_scene, eager=False)
        try:
            img = r.render(width, height, samples, REFERENCE_SEED).astype(np.float64)
        finally:
            r.release()
    if path is not None:
        buf = io.BytesIO()
        np.save(buf, img)
        write_output(path, buf.getvalue())
    return img, kind, False


# ---------------------------------------------------------------- measuring


class Timings:
    """Median wall-clock and CPU time of the repeated renders in ``times`` and
    ``cpu_times`` (ms); ``t(clock)`` picks one (the bench and its peer)."""

    times: list[float]
    cpu_times: list[float]

    @property
    def time_ms(self) -> float:
        return statistics.median(self.times)

    @property
    def cpu_ms(self) -> float:
        return statistics.median(self.cpu_times)

    def t(self, clock: str) -> float:
        return self.cpu_ms if clock == "cpu" else self.time_ms


@dataclass
class Result(Timings):
    scene: str
    setting: Setting
    width: int
    height: int
    times: list[float] = field(default_factory=list)       # wall clock, ms
    cpu_times: list[float] = field(default_factory=list)   # process CPU time, ms
    errors: dict[str, float] = field(default_factory=dict)
    front: dict[str, bool] = field(default_factory=dict)   # on the Pareto front, per clock
    #: on the front of the uniform settings alone (None for adaptive ones)
    front_uniform: dict[str, bool | None] = field(default_factory=dict)
    #: samples per pixel used on average (adaptive: measured; uniform: samples)
    mean_spp: float | None = None
    #: shader programs its timed renders built (0 unless warm_up gave up)
    built_in_timed: int = 0

    @property
    def spp_used(self) -> float:
        return float(self.setting.samples) if self.mean_spp is None else self.mean_spp



class _Renderers:
    """One Renderer per shader variant (specialised / generic, exact /
    Schlick) of a scene; a setting switches scene values with set_scene
    (programs are cached by their defines, so switching is cheap).

    Each keeps every culling variant it compiles (SUBSET_PROGRAMS): the
    sweep's settings need more than the viewer's cache of 16 holds (max
    depth is a compile-time constant, and uniform, footprint and adaptive
    passes are variants of their own), and with 16 the timed renders of
    the default scene recompiled 24 variants a round.  (Measured, it cost
    little: with Mesa's shader cache a round of all settings took the same
    17-20 s either way; but a timed render must not compile.)"""

    SUBSET_PROGRAMS = 1024

    def __init__(self, ctx):
        self.ctx = ctx
        self._by_variant: dict[tuple, object] = {}
        self._current: dict[tuple, object] = {}

    def get(self, scene, setting: Setting, size: tuple[int, int] | None = None):
        from ..gpu.renderer import Renderer
        from ..scene.load import with_overrides

        s = with_overrides(scene, samples=setting.samples, max_depth=setting.max_depth,
                           min_weight=setting.min_weight)
        # One Renderer per image size too: a Renderer keeps its offscreen
        # target and footprint mask for the size it drew last, so a shared
        # one re-made them inside the timed render of every setting drawn
        # after one of another size (the resolution scales, preset:preview,
        # "point samples"; preview at 320x180: 14.1 ms CPU against 11.9).
        variant = (setting.specialise, setting.fresnel, size)
        r = self._by_variant.get(variant)
        if r is None:
            r = Renderer(self.ctx, s, specialise=setting.specialise, fresnel=setting.fresnel, eager=False)
            r.SUBSET_PROGRAMS = self.SUBSET_PROGRAMS
            self._by_variant[variant] = r
        elif self._current.get(variant) != setting.key():
            r.set_scene(s)
        self._current[variant] = setting.key()
        return r

    def release(self) -> None:
        for r in self._by_variant.values():
            r.release()
        self._by_variant.clear()


def _render_setting(renderer, setting: Setting, w: int, h: int) -> tuple[np.ndarray, float | None]:
    """One render of a setting at (w, h): the image (H, W, 3) and, for an
    adaptive setting, the mean samples per pixel it used (None: uniform)."""
    footprint = None if setting.footprint else False     # None: the renderers' own default
    if setting.adaptive is None:
        return renderer.render(w, h, setting.samples, RENDER_SEED, footprint=footprint), None
    from ..adaptive.sampler import render_adaptive

    res = render_adaptive(renderer, w, h, setting.samples, setting.adaptive, seed=RENDER_SEED, footprint=footprint)
    return res.image, res.mean_spp


#: warm_up's most renders of one setting: an image is drawn with at most
#: culling.MAX_VARIANTS (4) variants per kind of pass (uniform, footprint,
#: adaptive first and list passes), and a render compiles at least one of
#: each kind it draws
WARM_UP_RENDERS = 8


def warm_up(renderer, run):
    """run() until a render builds no shader program; returns the last
    result (the finished image: the earlier ones drew groups whose variant
    was not compiled yet with a superset, the same image to float rounding).
    A render compiles at most Renderer.COMPILES_PER_DRAW culling variants
    per draw, so one untimed render is not enough to keep the timed ones
    from compiling (a compile on llvmpipe takes up to a second); stops
    after WARM_UP_RENDERS renders whatever they built."""
    built = renderer.programs_built
    result = run()
    for _ in range(WARM_UP_RENDERS - 1):
        if renderer.programs_built == built:
            break
        built = renderer.programs_built
        result = run()
    return result


def _timed_render(renderer, setting: Setting, w: int, h: int) -> tuple[float, float]:
    """(wall ms, process CPU ms) of one render, finished on the GPU: all of
    Renderer.render, or all of render_adaptive (every pass and the NumPy
    work between them)."""
    ctx = renderer.ctx
    ctx.finish()
    c0 = time.process_time()
    t0 = time.perf_counter()
    _render_setting(renderer, setting, w, h)   # the read-back waits for the GPU
    ctx.finish()
    return (time.perf_counter() - t0) * 1000.0, (time.process_time() - c0) * 1000.0


def bench_scene(ctx, scene, stem: str, settings: list[Setting], width: int, height: int, repeat: int,
                reference: np.ndarray, log=None, time_tol: float = DEFAULT_TIME_TOLERANCE,
                error_tol: float = DEFAULT_ERROR_TOLERANCE) -> list[Result]:
    """Warm-up renders (warm_up; the last one's image is the one compared
    with the reference; for adaptive settings also the mean samples per
    pixel used, which is deterministic for the seed) of every setting, then
    ``repeat`` interleaved rounds of timed renders."""
    pool = _Renderers(ctx)
    results: list[Result] = []
    try:
        for st in settings:
            w, h = render_size(st, width, height)
            r = pool.get(scene, st, (w, h))
            img, mean_spp = warm_up(r, lambda: _render_setting(r, st, w, h))
            if (w, h) != (width, height):
                img = upscale(img, width, height)
            res = Result(stem, st, w, h, errors=image_errors(img, reference), mean_spp=mean_spp)
            results.append(res)
        for k in range(repeat):
            # alternate the order between rounds so no setting always runs right after another
            order = results if k % 2 == 0 else results[::-1]
            for res in order:
                st = res.setting
                r = pool.get(scene, st, (res.width, res.height))
                built = r.programs_built
                wall, cpu = _timed_render(r, st, res.width, res.height)
                res.built_in_timed += r.programs_built - built
                res.times.append(wall)
                res.cpu_times.append(cpu)
            if log is not None:
                log(f"  round {k + 1}/{repeat} done")
    finally:
        pool.release()
    mark_fronts(results, time_tol, error_tol)
    return results


def mark_fronts(results: list[Result], time_tol: float = DEFAULT_TIME_TOLERANCE,
                error_tol: float = DEFAULT_ERROR_TOLERANCE) -> None:
    """Set each result's Pareto membership for both clocks (time against
    RMSE): over all settings (``front``: the front), and over the uniform
    settings alone (``front_uniform``: where the front would be without
    adaptive sampling; None for the adaptive settings)."""
    uniform = [r for r in results if r.setting.adaptive is None]
    for clock in CLOCKS:
        mask = pareto_mask([r.t(clock) for r in results], [r.errors["rmse"] for r in results],
                           time_tol, error_tol)
        for res, m in zip(results, mask):
            res.front[clock] = m
        mask = pareto_mask([r.t(clock) for r in uniform], [r.errors["rmse"] for r in uniform],
                           time_tol, error_tol)
        for res in results:
            res.front_uniform[clock] = None
        for res, m in zip(uniform, mask):
            res.front_uniform[clock] = m


# ---------------------------------------------------------------- machine


def machine_info(ctx=None, backend: str | None = None) -> dict:
    import moderngl

    from ..base.version import __version__

    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    cpus_usable = usable_cpus()
    info = {
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "cpus_usable": cpus_usable,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "moderngl": moderngl.__version__,
        "glassray": __version__,
        "command": " ".join(["glassray", *sys.argv[1:]]) if sys.argv else "glassray bench",
    }
    if hasattr(os, "getloadavg"):
        info["load_average_start"] = [round(x, 2) for x in os.getloadavg()]
    if ctx is not None:
        from ..gpu.context import describe

        info["gl"] = describe(ctx)
        info["gl_vendor"] = ctx.info.get("GL_VENDOR", "")
        info["gl_backend"] = backend
    return info


# ---------------------------------------------------------------- output


def _row(res: Result) -> dict:
    st = res.setting
    return {"scene": res.scene, "setting": st.label, "is_default": int(st.label == "default"),
            "pareto_wall": int(res.front["wall"]), "pareto_cpu": int(res.front["cpu"]),
            "max_depth": st.max_depth, "samples": st.samples,
            "adaptive_target": "" if st.adaptive is None else f"{st.adaptive:g}",
            "mean_spp": f"{res.spp_used:.4f}" if st.adaptive is not None else str(st.samples),
            "min_weight": _fmt_w(st.min_weight), "scale": f"{st.scale:g}", "width": res.width,
            "height": res.height, "specialise": int(st.specialise), "fresnel": st.fresnel,
            "footprint": int(st.footprint),
            "time_ms": f"{res.time_ms:.4f}", "time_min_ms": f"{min(res.times):.4f}",
            "time_max_ms": f"{max(res.times):.4f}", "cpu_ms": f"{res.cpu_ms:.4f}", "repeat": len(res.times),
            "rmse": f"{res.errors['rmse']:.10g}", "frac_off_1_255": f"{res.errors['frac_off']:.6g}",
            "max_abs_err": f"{res.errors['max_abs']:.6g}"}


def write_csv(path: Path, results: list[Result]) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_COLUMNS, lineterminator="\n")
    w.writeheader()
    for res in results:
        w.writerow(_row(res))
    write_output(path, buf.getvalue().encode("utf-8"))


def speedup(results: list[Result], a: str = "generic", b: str = "default", clock: str = "wall") -> float | None:
    """Median time of setting ``a`` over that of ``b`` (same scene)."""
    ta = [r.t(clock) for r in results if r.setting.label == a]
    tb = [r.t(clock) for r in results if r.setting.label == b]
    return ta[0] / tb[0] if ta and tb and tb[0] > 0 else None


def scene_table(results: list[Result], title: str, clock: str = "wall") -> str:
    """A Markdown table (also readable as plain text), fastest first on
    ``clock``.  "spp" is the samples per pixel (for an adaptive setting the
    mean budget), "mean spp" what was used on average."""
    head = ("setting", "size", "depth", "spp", "mean spp", "min_w", "shader", "fresnel", "ms (median)",
            "min..max", "CPU ms", "RMSE", ">1/255", "max err", "front")
    rows = []
    for res in sorted(results, key=lambda r: r.t(clock)):
        st = res.setting
        rows.append((st.label, f"{res.width}x{res.height}", str(st.max_depth), str(st.samples),
                     str(st.samples) if st.adaptive is None else f"{res.spp_used:.2f}",
                     _fmt_w(st.min_weight), "spec" if st.specialise else "generic", st.fresnel,
                     f"{res.time_ms:.1f}", f"{min(res.times):.1f}..{max(res.times):.1f}", f"{res.cpu_ms:.0f}",
                     f"{res.errors['rmse']:.2e}", f"{100 * res.errors['frac_off']:.2f}%",
                     f"{res.errors['max_abs']:.3f}",
                     "**" if res.front["wall"] and res.front["cpu"] else ("w" if res.front["wall"] else
                                                                            ("c" if res.front["cpu"] else ""))))
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    right = {2, 3, 4, 5, 8, 9, 10, 11, 12, 13}

    def line(cells):
        return "| " + " | ".join(c.rjust(wd) if i in right else c.ljust(wd)
                                 for i, (c, wd) in enumerate(zip(cells, widths))) + " |"

    sep = "|" + "|".join(("-" * (wd + 1) + ":") if i in right else ("-" * (wd + 2))
                         for i, wd in enumerate(widths)) + "|"
    return "\n".join([f"### {title}", "", line(head), sep, *(line(r) for r in rows)])


def scene_summary(results: list[Result], time_tol: float = DEFAULT_TIME_TOLERANCE,
                  error_tol: float = DEFAULT_ERROR_TOLERANCE) -> list[str]:
    out = []
    default = next((r for r in results if r.setting.label == "default"), None)
    generic = next((r for r in results if r.setting.label == "generic"), None)
    if default is not None and generic is not None:
        out.append(f"specialised vs generic shader: {speedup(results):.2f}x faster by wall clock "
                   f"({default.time_ms:.1f} ms against {generic.time_ms:.1f} ms), "
                   f"{speedup(results, clock='cpu'):.2f}x by CPU time "
                   f"({default.cpu_ms:.0f} ms against {generic.cpu_ms:.0f} ms)")
    if default is not None:
        for clock, name in (("wall", "wall clock"), ("cpu", "CPU time")):
            if default.front[clock]:
                out.append(f"default settings: on the Pareto front ({name})")
            else:
                doms = [r.setting.label for r in results if r is not default and
                        dominates(r.t(clock), r.errors["rmse"], default.t(clock), default.errors["rmse"],
                                  time_tol, error_tol)]
                out.append(f"default settings: NOT on the Pareto front ({name}; dominated by {', '.join(doms)})")
    out.extend(adaptive_summary(results))
    return out


def adaptive_on_front(results: list[Result]) -> dict[str, list[str]] | None:
    """Per clock, the adaptive settings on the Pareto front (of all settings
    together); None when the sweep had no adaptive setting."""
    if not any(r.setting.adaptive is not None for r in results):
        return None
    return {clock: [r.setting.label for r in results if r.setting.adaptive is not None and r.front[clock]]
            for clock in CLOCKS}


def adaptive_summary(results: list[Result]) -> list[str]:
    """Whether adaptive sampling moves the front, per clock: the adaptive
    settings on it, and the uniform settings that were on the front of the
    uniform settings alone and that adaptive ones push off it."""
    on = adaptive_on_front(results)
    if on is None:
        return []
    out = []
    for clock, name in (("wall", "wall clock"), ("cpu", "CPU time")):
        if not on[clock]:
            out.append(f"adaptive sampling ({name}): no adaptive setting on the Pareto front")
            continue
        pushed = [r.setting.label for r in results if r.front_uniform.get(clock) and not r.front[clock]]
        out.append(f"adaptive sampling ({name}): on the Pareto front: {', '.join(on[clock])}"
                   + (f"; pushes off the front of the uniform settings: {', '.join(pushed)}" if pushed else
                      "; every point of the uniform settings' front stays on it"))
    return out


def _group(setting: Setting) -> str:
    """The plot's group of a setting: "adaptive", or its label's knob."""
    if setting.adaptive is not None:
        return "adaptive"
    return setting.label.split("=")[0].split(":")[0]


def ms_axis(ax) -> None:
    """A logarithmic x axis of milliseconds, labelled in plain numbers at
    1, 2 and 5 of every decade (on a span under a decade with fewer than
    two of them, the locator falls back to evenly spaced ticks, labelled
    the same way).  (Matplotlib's default labels every minor tick in
    scientific notation where an axis shows one major tick, and on a span
    of 15 to 600 ms they ran into each other.)  Over more than three
    decades of data (the peer comparison: 10 ms to 40 s) only 1 and 3 are
    labelled: "5000 10000 20000" ran together.  Call it after plotting."""
    import math

    from matplotlib.ticker import FuncFormatter, LogLocator

    ax.set_xscale("log")
    lo, hi = ax.dataLim.intervalx
    wide = lo > 0 and math.isfinite(hi) and math.log10(hi / lo) > 3.0
    labelled = (1.0, 3.0) if wide else (1.0, 2.0, 5.0)
    ax.xaxis.set_major_locator(LogLocator(base=10, subs=labelled))
    ax.xaxis.set_minor_locator(LogLocator(base=10, subs=tuple(float(k) for k in range(2, 10)
                                                              if float(k) not in labelled)))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(FuncFormatter(lambda v, _: ""))


def plot(path: Path, by_scene: dict[str, list[Result]], titles: dict[str, str], subtitle: str,
         clock: str = "wall") -> bool:
    """pareto.png: per scene, median frame time against RMSE (log axes), the
    Pareto front (of all settings) as a staircase, the default settings
    labelled; adaptive settings in their own colour and marker, and, when
    there are any, the front of the uniform settings alone as a dotted
    staircase (where the front would be without adaptive sampling).  False
    when matplotlib is missing."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    n = len(by_scene)
    cols = 1 if n == 1 else 2
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.2 * cols if n > 1 else 8.0, 4.4 * rows), squeeze=False)
    groups = (("default", "default", "#d62728", "*", 180), ("max_depth", "max depth", "#1f77b4", "o", 36),
              ("samples", "samples", "#2ca02c", "s", 36), ("min_weight", "min weight", "#9467bd", "^", 40),
              ("scale", "resolution scale", "#8c564b", "D", 32), ("generic", "generic shader", "#ff7f0e", "X", 60),
              ("schlick", "Schlick Fresnel", "#e377c2", "P", 60), ("preset", "combined preset", "#7f7f7f", "v", 40),
              ("point samples", "point samples (no footprint samples)", "#bcbd22", "d", 50),
              ("adaptive", "adaptive (e target \u2264 mean budget)", "#17becf", "h", 70))
    for ax, (stem, results) in zip(axes.flat, by_scene.items()):
        floor = min((r.errors["rmse"] for r in results if r.errors["rmse"] > 0), default=1e-6) / 2
        err = lambda r: max(r.errors["rmse"], floor)  # noqa: E731 - log axes need > 0
        for prefix, name, colour, marker, size in groups:
            pts = [r for r in results if _group(r.setting) == prefix]
            if pts:
                ax.scatter([r.t(clock) for r in pts], [err(r) for r in pts], c=colour, marker=marker, s=size,
                           label=name, zorder=3, edgecolors="black" if prefix in ("default", "adaptive") else "none",
                           linewidths=0.6)

        def staircase(points):
            xs, ys = [], []
            for r in sorted(points, key=lambda r: (r.t(clock), err(r))):
                if xs:
                    xs.append(r.t(clock))
                    ys.append(ys[-1])
                xs.append(r.t(clock))
                ys.append(err(r))
            return xs, ys

        front = [r for r in results if r.front[clock]]
        if any(r.setting.adaptive is not None for r in results):
            uniform_front = [r for r in results if r.front_uniform.get(clock)]
            if uniform_front:
                ax.plot(*staircase(uniform_front), color="#7f7f7f", lw=1.0, ls=":", zorder=1,
                        label="front of uniform settings only")
        if front:
            ax.plot(*staircase(front), color="black", lw=1.0, ls="--", zorder=2, label="Pareto front")
            ax.scatter([r.t(clock) for r in front], [err(r) for r in front], s=110, facecolors="none",
                       edgecolors="black", linewidths=1.0, zorder=4)
        # Labels: the default settings always (with an arrow), then the front,
        # then the rest, each skipped when it would land on an earlier label.
        lt = [math.log10(max(r.t(clock), 1e-9)) for r in results]
        le = [math.log10(err(r)) for r in results]
        span_t = (max(lt) - min(lt)) or 1.0
        span_e = (max(le) - min(le)) or 1.0
        placed: list[tuple[float, float]] = []
        order = sorted(range(len(results)), key=lambda i: (results[i].setting.label != "default",
                                                            not results[i].front[clock], results[i].t(clock)))
        for i in order:
            r = results[i]
            lab = r.setting.label
            x, y = (lt[i] - min(lt)) / span_t, (le[i] - min(le)) / span_e
            if lab == "default":
                ax.annotate("default", (r.t(clock), err(r)), textcoords="offset points", xytext=(-30, 26),
                            fontsize=8, color="#d62728", fontweight="bold",
                            arrowprops=dict(arrowstyle="->", color="#d62728", lw=0.8))
                placed.append((x - 0.05, y + 0.12))
                continue
            if any(abs(x - px) < 0.07 and abs(y - py) < 0.045 for px, py in placed):
                continue
            placed.append((x, y))
            if r.setting.adaptive is not None:
                short = f"e{r.setting.adaptive:g} \u2264{r.setting.samples}"
            else:
                short = lab.replace("max_depth=", "d").replace("samples=", "spp ").replace("min_weight=", "w ") \
                           .replace("scale=", "x").replace("preset:", "")
            ax.annotate(short, (r.t(clock), err(r)), textcoords="offset points", xytext=(4, 3), fontsize=6.5,
                        color="#333333")
        ms_axis(ax)
        ax.set_yscale("log")
        ax.set_xlabel("frame time, ms (median, wall clock)" if clock == "wall" else
                      "CPU time per frame, ms (median, all threads)")
        ax.set_ylabel("RMSE against reference (linear)")
        ax.set_title(titles.get(stem, stem), fontsize=10)
        ax.grid(True, which="both", alpha=0.25)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    seen = dict(zip(labels, handles))
    for ax in list(axes.flat)[1:n]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(lab, h)
    fig.legend(list(seen.values()), list(seen.keys()), loc="lower center", ncol=min(4, len(seen)),
               fontsize=8, frameon=False)
    import textwrap

    fig.suptitle("\n".join(textwrap.wrap(subtitle, 95 * cols if n > 1 else 120)), fontsize=8)
    fig.tight_layout(rect=(0, 0.06 if rows > 1 else 0.1, 1, 0.96))
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    write_output(path, buf.getvalue())
    return True


# ---------------------------------------------------------------- command line


def _fraction(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0.0 <= v < 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1), got {text!r}")
    return v


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", nargs="?", metavar="SCENE",
                   help="benchmark only this scene (file or built-in name); default: "
                        + ", ".join(DEFAULT_SCENES))
    p.add_argument("--scenes", metavar="A,B,C", help="comma-separated scenes to benchmark (instead of SCENE)")
    from ..cli.commands import int_range, size_type

    p.add_argument("--size", type=size_type(), default=DEFAULT_SIZE, metavar="WxH",
                   help="full image size; error is measured at this size (%dx%d)" % DEFAULT_SIZE)
    p.add_argument("--repeat", type=int_range(1, 1000), default=DEFAULT_REPEAT, metavar="N",
                   help=f"timed renders per setting after the warm-up; the median is reported ({DEFAULT_REPEAT})")
    p.add_argument("--reference-samples", type=int_range(1, 65536), default=None, metavar="N",
                   help=f"samples per pixel of the reference ({DEFAULT_REFERENCE_SAMPLES}; "
                        f"{QUICK_REFERENCE_SAMPLES} with --quick)")
    p.add_argument("--reference-refine", type=int_range(0, 1 << 20), default=None, metavar="N",
                   help="samples per pixel of the reference where its samples disagree by more than "
                        f"{REFINE_TOLERANCE:g} (edges, a checker finer than the pixel); 0, or at most "
                        "--reference-samples: none (default: none for the sweep, "
                        "8192 with --peer, none with --peer --quick)")
    p.add_argument("--quick", action="store_true",
                   help="a tiny sweep (eight settings per scene, one of them adaptive), for tests")
    p.add_argument("--out", default="bench-results", metavar="DIR",
                   help="folder for results.csv, results.md, machine.json, pareto.png, pareto-cpu.png and the cached "
                        "reference images (./bench-results)")
    p.add_argument("--time-tolerance", type=_fraction, default=DEFAULT_TIME_TOLERANCE, metavar="F",
                   help="relative time difference treated as a tie (measurement noise) when finding the "
                        f"Pareto front ({DEFAULT_TIME_TOLERANCE:g}); 0 for the plain definition")
    p.add_argument("--error-tolerance", type=_fraction, default=DEFAULT_ERROR_TOLERANCE, metavar="F",
                   help="relative RMSE difference treated as a tie when finding the Pareto front "
                        f"({DEFAULT_ERROR_TOLERANCE:g}: smaller differences are within the sampling noise "
                        "of the images); 0 for the plain definition")
    p.add_argument("--backend", choices=("auto", "egl", "osmesa"), default="auto",
                   help="OpenGL context: EGL, OSMesa, or EGL falling back to OSMesa (auto)")
    p.add_argument("--peer", choices=("mitsuba",), default=None,
                   help="instead of the sweep: glassray side by side with a physically based path tracer "
                        "(Mitsuba 3: pip install 'glassray[peer]') on one scene that both draw identically "
                        "(default whitted-exact): error against time, time to reach an error "
                        "(peer.md, peer.csv, peer-time-to-error.csv, peer-machine.json, peer.png; see viewer/peer.py)")
    p.add_argument("--peer-time-limit", type=int_range(1, 86400), default=None, metavar="S",
                   help="with --peer: a Mitsuba sample count whose first render took longer than S seconds "
                        "ends its series (30; the next count is 1.78-4 times as many samples)")


def _log(msg: str) -> None:
    print(f"bench: {msg}", file=sys.stderr, flush=True)


class OutputError(Exception):
    """An output file could not be written (the message names it)."""


#: the set of files being written together (results_written_together), if any
_writing: "AtomicSet | None" = None


def write_output(path: Path, data: bytes) -> None:
    """write_atomic (or, inside results_written_together, a part of its
    set), with an OSError (a full disk, a read-only folder) turned into an
    OutputError that names the file: the OSError of a failed write names at
    most the temporary file, and often nothing."""
    from ..base.files import write_atomic

    try:
        if _writing is not None:
            _writing.write(path, data)
        else:
            write_atomic(path, data)
    except OSError as e:
        raise OutputError(f"{path}: cannot write: {e.strerror or e}") from e


@contextlib.contextmanager
def results_written_together():
    """A run's result files as one set: every write_output and remove_stale
    inside is done at the end, all of them, or none if anything inside
    fails (a second run into the same folder that cannot write one of its
    files leaves the first run's files, all of them, as they were)."""
    from ..base.files import AtomicSet

    global _writing
    outer, _writing = _writing, AtomicSet()
    files = _writing
    try:
        yield
    except BaseException:
        files.discard()
        raise
    finally:
        _writing = outer
    try:
        files.commit()
    except OSError as e:
        raise OutputError(f"{e.filename or 'a result file'}: cannot write: {e.strerror or e}") from e


def results_folder_problem(out: Path) -> str | None:
    """Why results cannot be written into the folder `out` (made if
    missing; its parent must exist), or None: checked before a run, not
    found after it."""
    if out.exists() and not out.is_dir():
        return f"{out}: cannot write results there: it is a file, not a folder"
    if not out.parent.is_dir():      # as render's output: a mistyped path is not made
        what = "is a file, not a folder" if out.parent.exists() else "does not exist"
        return f"{out}: cannot write results there: folder {out.parent} {what}"
    try:
        out.mkdir(exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".glassray-write-test-", dir=out)   # a name no file has
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        return f"{out}: cannot write results there: {e.strerror or e}"
    return None


def remove_stale(paths: list[Path]) -> list[Path]:
    """Remove the files of `paths` that exist (an earlier run's plots, which
    would pass for this run's); returns those removed."""
    stale = [p for p in paths if p.is_file()]
    for p in stale:
        if _writing is not None:        # with the set's other files, at its end
            _writing.remove(p)
            continue
        try:
            p.unlink()
        except OSError as e:
            raise OutputError(f"{p}: an earlier run's plot, cannot remove it: {e.strerror or e}") from e
    return stale


def _unique_stems(names: list[str]) -> list[str]:
    """A distinct stem (the scene column, the table and plot title, the
    reference's file name) per scene: a file's name without .toml, with
    "-2", "-3", ... after the second and later of the same stem (a.toml and
    other/a.toml).  run() has refused a file named twice (_named_twice)."""
    stems: list[str] = []
    for name in names:
        stem = base = _stem(name, None)
        k = 2
        while stem in stems:
            stem, k = f"{base}-{k}", k + 1
        stems.append(stem)
    return stems


def _named_twice(names: list[str]) -> list[str]:
    """The scenes of `names` that name one file twice, however spelt
    (glass-sphere and glass-sphere; a/s.toml and /abs/a/s.toml): each
    spelling after the first of its file."""
    from ..scene.load import resolve_scene_path

    seen, twice = {}, []
    for name in names:
        key = os.path.realpath(resolve_scene_path(name))
        if key in seen:
            twice.append(name if name == seen[key] else f"{name} (the same file as {seen[key]})")
        else:
            seen[key] = name
    return twice


def run(args) -> int:
    from ..scene.model import SceneError
    from ..scene.load import builtin_scene_names, load_scene

    debug = getattr(args, "debug", False)
    if args.scene and args.scenes:
        print("glassray bench: give either SCENE or --scenes, not both", file=sys.stderr)
        return 2
    peer = getattr(args, "peer", None)
    if peer and args.scenes:
        print("glassray bench: --peer compares on one SCENE, not --scenes", file=sys.stderr)
        return 2
    if not peer and getattr(args, "peer_time_limit", None) is not None:
        print("glassray bench: --peer-time-limit limits the peer's renders; it needs --peer", file=sys.stderr)
        return 2
    if args.scene is not None and not args.scene.strip():
        print("glassray bench: empty scene name (give a scene file or a built-in scene name)", file=sys.stderr)
        return 2
    names = [args.scene] if args.scene else (
        [s.strip() for s in args.scenes.split(",") if s.strip()] if args.scenes is not None else
        (["whitted-exact"] if peer else list(DEFAULT_SCENES)))
    if not names:
        print("glassray bench: --scenes names no scene", file=sys.stderr)
        return 2
    twice = _named_twice(names)
    if twice:
        print(f"glassray bench: --scenes names {', '.join(twice)} more than once", file=sys.stderr)
        return 2
    if not str(args.out):
        print("glassray bench: --out names no folder", file=sys.stderr)
        return 2
    scenes = []
    for name in names:
        try:
            scenes.append((name, load_scene(name)))
        except SceneError as e:
            if name in DEFAULT_SCENES and name not in builtin_scene_names():
                e = SceneError(f"{name}: benchmark scene missing from this installation")
            print(f"glassray: {e}", file=sys.stderr)
            return 2
    if peer:
        from .peer import PeerError, check_scene

        try:
            check_scene(scenes[0][1])
        except PeerError as e:
            print(f"glassray: {names[0]}: {e}", file=sys.stderr)
            return 2
    width, height = args.size
    ref_samples = args.reference_samples or (QUICK_REFERENCE_SAMPLES if args.quick else DEFAULT_REFERENCE_SAMPLES)
    out = Path(args.out)
    made = not out.exists()
    problem = results_folder_problem(out)
    if problem:
        print(f"glassray: {problem}", file=sys.stderr)
        return 1
    try:
        return _run_into(args, peer, scenes, width, height, ref_samples, out, debug)
    finally:
        if made:
            remove_if_empty(out)      # a run that wrote nothing leaves no folder of its own behind


def remove_if_empty(folder: Path) -> None:
    """Remove `folder` if it is empty (results_folder_problem made it, and
    the run failed before writing anything into it)."""
    try:
        folder.rmdir()                # fails on a folder with anything in it
    except OSError:
        pass


def _run_into(args, peer, scenes, width, height, ref_samples, out: Path, debug: bool) -> int:
    from ..gpu.context import ContextError, create_offscreen_context

    try:
        ctx, backend = create_offscreen_context(args.backend)
    except ContextError as e:
        print(f"glassray: {e}", file=sys.stderr)
        return 1
    try:
        if peer:
            from .peer import run_bench

            return run_bench(args, ctx, backend, scenes[0][0], scenes[0][1], width, height, out, _log)
        return _run(args, ctx, backend, scenes, width, height, ref_samples, out)
    except KeyboardInterrupt:
        print("glassray: interrupted", file=sys.stderr)
        return 130
    except OutputError as e:
        if debug:
            raise
        print(f"glassray: {e}", file=sys.stderr)
        return 1
    except Exception as e:
        if debug:
            raise
        from .peer import PeerError     # viewer.peer imports Mitsuba only when used
        if isinstance(e, PeerError):    # a message for the user (Mitsuba missing, its variant unusable)
            print(f"glassray: {e}", file=sys.stderr)
            return 1
        print(f"glassray: bench failed: {type(e).__name__}: {e} (run with --debug for the traceback)",
              file=sys.stderr)
        return 1
    finally:
        ctx.release()


def _stem(name: str, scene) -> str:
    p = Path(name)
    return p.stem if p.suffix == ".toml" else name


def _run(args, ctx, backend, scenes, width, height, ref_samples, out: Path) -> int:
    info = machine_info(ctx, backend)
    kind = reference_kind()
    refine = effective_refine(ref_samples, getattr(args, "reference_refine", None))
    ref_text = reference_text(ref_samples, refine)
    info.update({"size": f"{width}x{height}", "repeat": args.repeat, "quick": bool(args.quick),
                 "reference": {"kind": kind, "samples": ref_samples, "refined_samples": refine, "seed": REFERENCE_SEED,
                               "max_depth": REFERENCE_MAX_DEPTH, "min_weight": REFERENCE_MIN_WEIGHT},
                 "render_seed": RENDER_SEED})
    header = [f"glassray bench {info['date']}",
              f"machine: {info['cpu']} ({info['cpus_usable']} usable CPUs), {info['platform']}",
              f"GL: {info['gl']} via {backend}",
              f"size {width}x{height}, median of {args.repeat} interleaved timed renders after untimed "
              f"warm-up renders (until one compiles nothing); "
              f"Pareto front of time against RMSE with differences under {100 * args.time_tolerance:g}% in time "
              f"and {100 * args.error_tolerance:g}% in RMSE as ties; front column: ** on both clocks, "
              f"w wall clock only, c CPU time only",
              (f"reference: float64 NumPy tracer, {ref_text} (seed {REFERENCE_SEED}), "
               f"max depth {REFERENCE_MAX_DEPTH}, min weight {REFERENCE_MIN_WEIGHT:g}") if kind == "float64" else
              (f"reference: viewer.reference is not importable: FALLBACK to a GPU render with {ref_samples} "
               f"samples (seed {REFERENCE_SEED}), max depth {REFERENCE_MAX_DEPTH}, min weight "
               f"{REFERENCE_MIN_WEIGHT:g}: errors measure convergence of the shader, not its correctness")]
    if "load_average_start" in info:
        la = info["load_average_start"][0]
        header.append(f"load average at start: {la:.2f} on {info['cpus_usable']} CPUs"
                      + (" (the machine was busy: timings are medians of interleaved rounds)"
                         if la > 0.5 else ""))
    for line in header:
        _log(line)

    all_results: list[Result] = []
    by_scene: dict[str, list[Result]] = {}
    titles: dict[str, str] = {}
    started = time.perf_counter()
    for (name, scene), stem in zip(scenes, _unique_stems([n for n, _ in scenes])):
        if stem != _stem(name, scene):
            _log(f"{name}: called {stem} in the results (another scene has the same name)")
        settings = sweep(scene, quick=args.quick, reference_samples=ref_samples)
        dropped = [x.label for x in sweep(scene, quick=args.quick) if x not in settings]
        if dropped:
            _log(f"{stem}: left out, as they take as many samples as the {ref_samples}-sample reference or "
                 f"more (they would measure its noise): {', '.join(dropped)}")
        from ..gpu.packing import GENERIC_LENS

        if (len(scene.objects) > GENERIC_LENS["OBJECTS_LEN"] or len(scene.materials) > GENERIC_LENS["MATERIALS_LEN"]
                or len(scene.lights) > GENERIC_LENS["LIGHTS_LEN"]):
            settings = [s for s in settings if s.specialise]
            _log(f"{stem}: too large for the generic shader: its setting is left out")
        _log(f"{stem}: reference {width}x{height}, {ref_text} ...")
        t0 = time.perf_counter()
        ref, _, cached = reference_image(scene, stem, width, height, ref_samples, out, ctx=ctx, log=_log,
                                         refine=refine)
        _log(f"{stem}: reference {'from the cache' if cached else f'took {time.perf_counter() - t0:.1f} s'}")
        _log(f"{stem}: {len(settings)} settings, warm-up and {args.repeat} rounds ...")
        t0 = time.perf_counter()
        results = bench_scene(ctx, scene, stem, settings, width, height, args.repeat, ref,
                              log=_log if not args.quick else None, time_tol=args.time_tolerance,
                              error_tol=args.error_tolerance)
        _log(f"{stem}: done in {time.perf_counter() - t0:.1f} s")
        compiling = [r.setting.label for r in results if r.built_in_timed]
        if compiling:
            _log(f"{stem}: warning: timed renders built shader programs ({', '.join(compiling)}): "
                 f"their times include compiling")
        by_scene[stem] = results
        titles[stem] = f"{stem}: {scene.name}"
        all_results.extend(results)

    if hasattr(os, "getloadavg"):
        info["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    info["wall_s"] = round(time.perf_counter() - started, 1)
    info["time_tolerance"] = args.time_tolerance
    info["error_tolerance"] = args.error_tolerance
    info["summary"] = {stem: scene_summary(res, args.time_tolerance, args.error_tolerance)
                       for stem, res in by_scene.items()}
    info["speedup_specialised_vs_generic"] = {
        stem: {clock: round(speedup(res, clock=clock), 3) for clock in CLOCKS}
        for stem, res in by_scene.items() if speedup(res) is not None}
    info["default_on_pareto_front"] = {
        stem: next((dict(r.front) for r in res if r.setting.label == "default"), None)
        for stem, res in by_scene.items()}
    info["adaptive_on_pareto_front"] = {stem: adaptive_on_front(res) for stem, res in by_scene.items()}
    info["programs_built_in_timed_rounds"] = {stem: sum(r.built_in_timed for r in res)
                                              for stem, res in by_scene.items()}

    tables = []
    for stem, res in by_scene.items():
        tables.append(scene_table(res, titles[stem]) + "\n\n"
                      + "\n".join(f"- {s}" for s in scene_summary(res, args.time_tolerance, args.error_tolerance)))
    text = "\n\n".join(["\n".join(f"    {h}" for h in header), *tables]) + "\n"
    # the tables first: a run's results are not lost if its files cannot be written (a full disk)
    print(text, end="", flush=True)
    print()
    from ..gpu.context import renderer_and_release

    subtitle = (f"glassray bench, {width}x{height}, {renderer_and_release(info['gl'])}, {info['cpus_usable']} CPUs; "
                f"reference {ref_samples}{f'/{refine}' if refine else ''} spp ({kind}); {info['date'][:10]}")
    stale = []
    with results_written_together():
        write_csv(out / "results.csv", all_results)
        write_output(out / "results.md", text.encode("utf-8"))
        write_output(out / "machine.json", (json.dumps(info, indent=2) + "\n").encode("utf-8"))
        plotted = (plot(out / "pareto.png", by_scene, titles, subtitle + "; wall-clock frame time", "wall")
                   and plot(out / "pareto-cpu.png", by_scene, titles, subtitle + "; CPU time of all threads", "cpu"))
        if not plotted:
            stale = remove_stale([out / "pareto.png", out / "pareto-cpu.png"])

    print(f"wrote {out / 'results.csv'}, {out / 'results.md'}, {out / 'machine.json'}"
          + (f", {out / 'pareto.png'}, {out / 'pareto-cpu.png'}" if plotted else ""))
    if not plotted:
        print("no plot: pareto.png needs matplotlib (pip install 'glassray[bench]')")
        if stale:
            print(f"removed the plots of an earlier run: {', '.join(str(p) for p in stale)}")
    return 0
