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

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from ..adaptive.render import render_adaptive
from ..gpu.context import renderer_and_release
from ..gpu.defines import GENERIC_LENS
from ..gpu.renderer import Renderer
from ..scene.load import with_overrides
from .bench_report import adaptive_on_front, scene_summary, scene_table, speedup, write_csv
from .kit import (REFERENCE_MAX_DEPTH, REFERENCE_MIN_WEIGHT, REFERENCE_SEED, RENDER_SEED, SUBSET_PROGRAMS,
                  image_errors, machine_info, warm_up)
from .outputs import remove_stale, results_written_together, write_output
from .plots import pareto_plot
from .reference_cache import effective_refine, reference_image, reference_kind, reference_text
from .sweep import (CLOCKS, DEFAULT_ERROR_TOLERANCE, DEFAULT_TIME_TOLERANCE, Result, Setting, mark_fronts,
                    sweep)

#: The benchmark's scenes when none is named: the default scene, opaque only,
#: one glass sphere, many objects.
DEFAULT_SCENES = ("default", "bench-opaque", "glass-sphere", "bench-many")
DEFAULT_SIZE = (320, 180)
DEFAULT_REPEAT = 5
DEFAULT_REFERENCE_SAMPLES = 128
QUICK_REFERENCE_SAMPLES = 4


# ---------------------------------------------------------------- measuring


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


def render_size(setting: Setting, width: int, height: int) -> tuple[int, int]:
    return max(1, round(width * setting.scale)), max(1, round(height * setting.scale))


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

    SUBSET_PROGRAMS = SUBSET_PROGRAMS

    def __init__(self, ctx):
        self.ctx = ctx
        self._by_variant: dict[tuple, object] = {}
        self._current: dict[tuple, object] = {}

    def get(self, scene, setting: Setting, size: tuple[int, int] | None = None):
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
    res = render_adaptive(renderer, w, h, setting.samples, setting.adaptive, seed=RENDER_SEED, footprint=footprint)
    return res.image, res.mean_spp


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


def log_progress(msg: str) -> None:
    """A line of progress on stderr."""
    print(f"bench: {msg}", file=sys.stderr, flush=True)


def _unique_stems(names: list[str]) -> list[str]:
    """A distinct stem (the scene column, the table and plot title, the
    reference's file name) per scene: a file's name without .toml, with
    "-2", "-3", ... after the second and later of the same stem (a.toml and
    other/a.toml).  ``glassray bench`` has refused a file named twice (viewer/cli/bench.py)."""
    stems: list[str] = []
    for name in names:
        stem = base = _stem(name, None)
        k = 2
        while stem in stems:
            stem, k = f"{base}-{k}", k + 1
        stems.append(stem)
    return stems


def _stem(name: str, scene) -> str:
    p = Path(name)
    return p.stem if p.suffix == ".toml" else name


def run_sweep(ctx, backend: str, scenes, width: int, height: int, ref_samples: int, out: Path, *,
              repeat: int = DEFAULT_REPEAT, quick: bool = False, refine: int | None = None,
              time_tol: float = DEFAULT_TIME_TOLERANCE, error_tol: float = DEFAULT_ERROR_TOLERANCE) -> int:
    """``glassray bench`` (the sweep): every setting of every scene of
    ``scenes`` ((name, Scene) pairs) measured at width x height against a
    reference of ``ref_samples`` samples (``refine``: --reference-refine);
    the tables on stdout, the files into ``out``; returns the exit status."""
    info = machine_info(ctx, backend)
    kind = reference_kind()
    refine = effective_refine(ref_samples, refine)
    ref_text = reference_text(ref_samples, refine)
    info.update({"size": f"{width}x{height}", "repeat": repeat, "quick": bool(quick),
                 "reference": {"kind": kind, "samples": ref_samples, "refined_samples": refine, "seed": REFERENCE_SEED,
                               "max_depth": REFERENCE_MAX_DEPTH, "min_weight": REFERENCE_MIN_WEIGHT},
                 "render_seed": RENDER_SEED})
    header = [f"glassray bench {info['date']}",
              f"machine: {info['cpu']} ({info['cpus_usable']} usable CPUs), {info['platform']}",
              f"GL: {info['gl']} via {backend}",
              f"size {width}x{height}, median of {repeat} interleaved timed renders after untimed "
              f"warm-up renders (until one compiles nothing); "
              f"Pareto front of time against RMSE with differences under {100 * time_tol:g}% in time "
              f"and {100 * error_tol:g}% in RMSE as ties; front column: ** on both clocks, "
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
        log_progress(line)

    all_results: list[Result] = []
    by_scene: dict[str, list[Result]] = {}
    titles: dict[str, str] = {}
    started = time.perf_counter()
    for (name, scene), stem in zip(scenes, _unique_stems([n for n, _ in scenes])):
        if stem != _stem(name, scene):
            log_progress(f"{name}: called {stem} in the results (another scene has the same name)")
        settings = sweep(scene, quick=quick, reference_samples=ref_samples)
        dropped = [x.label for x in sweep(scene, quick=quick) if x not in settings]
        if dropped:
            log_progress(f"{stem}: left out, as they take as many samples as the {ref_samples}-sample reference or "
                 f"more (they would measure its noise): {', '.join(dropped)}")
        if (len(scene.objects) > GENERIC_LENS["OBJECTS_LEN"] or len(scene.materials) > GENERIC_LENS["MATERIALS_LEN"]
                or len(scene.lights) > GENERIC_LENS["LIGHTS_LEN"]):
            settings = [s for s in settings if s.specialise]
            log_progress(f"{stem}: too large for the generic shader: its setting is left out")
        log_progress(f"{stem}: reference {width}x{height}, {ref_text} ...")
        t0 = time.perf_counter()
        ref, _, cached = reference_image(scene, stem, width, height, ref_samples, out, ctx=ctx, log=log_progress,
                                         refine=refine)
        log_progress(f"{stem}: reference {'from the cache' if cached else f'took {time.perf_counter() - t0:.1f} s'}")
        log_progress(f"{stem}: {len(settings)} settings, warm-up and {repeat} rounds ...")
        t0 = time.perf_counter()
        results = bench_scene(ctx, scene, stem, settings, width, height, repeat, ref,
                              log=log_progress if not quick else None, time_tol=time_tol,
                              error_tol=error_tol)
        log_progress(f"{stem}: done in {time.perf_counter() - t0:.1f} s")
        compiling = [r.setting.label for r in results if r.built_in_timed]
        if compiling:
            log_progress(f"{stem}: warning: timed renders built shader programs ({', '.join(compiling)}): "
                 f"their times include compiling")
        by_scene[stem] = results
        titles[stem] = f"{stem}: {scene.name}"
        all_results.extend(results)

    if hasattr(os, "getloadavg"):
        info["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    info["wall_s"] = round(time.perf_counter() - started, 1)
    info["time_tolerance"] = time_tol
    info["error_tolerance"] = error_tol
    info["summary"] = {stem: scene_summary(res, time_tol, error_tol)
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
                      + "\n".join(f"- {s}" for s in scene_summary(res, time_tol, error_tol)))
    text = "\n\n".join(["\n".join(f"    {h}" for h in header), *tables]) + "\n"
    # the tables first: a run's results are not lost if its files cannot be written (a full disk)
    print(text, end="", flush=True)
    print()
    subtitle = (f"glassray bench, {width}x{height}, {renderer_and_release(info['gl'])}, {info['cpus_usable']} CPUs; "
                f"reference {ref_samples}{f'/{refine}' if refine else ''} spp ({kind}); {info['date'][:10]}")
    stale = []
    with results_written_together():
        write_csv(out / "results.csv", all_results)
        write_output(out / "results.md", text.encode("utf-8"))
        write_output(out / "machine.json", (json.dumps(info, indent=2) + "\n").encode("utf-8"))
        plotted = (pareto_plot(out / "pareto.png", by_scene, titles, subtitle + "; wall-clock frame time", "wall")
                   and pareto_plot(out / "pareto-cpu.png", by_scene, titles, subtitle + "; CPU time of all threads", "cpu"))
        if not plotted:
            stale = remove_stale([out / "pareto.png", out / "pareto-cpu.png"])

    print(f"wrote {out / 'results.csv'}, {out / 'results.md'}, {out / 'machine.json'}"
          + (f", {out / 'pareto.png'}, {out / 'pareto-cpu.png'}" if plotted else ""))
    if not plotted:
        print("no plot: pareto.png needs matplotlib (pip install 'glassray[bench]')")
        if stale:
            print(f"removed the plots of an earlier run: {', '.join(str(p) for p in stale)}")
    return 0
