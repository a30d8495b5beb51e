"""``glassray bench --peer mitsuba``: glassray side by side with a physically
based path tracer (Mitsuba 3, viewer/measure/peer_mitsuba.py) on one
scene that both draw identically (viewer/measure/peer_check.py): each
one's error against its time, and the time each takes to reach an error.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from ..adaptive.render import DEFAULT_TARGET_ERROR, render_adaptive
from ..gpu.context import renderer_and_release
from ..gpu.renderer import Renderer
from .kit import (REFERENCE_MAX_DEPTH, REFERENCE_MIN_WEIGHT, REFERENCE_SEED, RENDER_SEED, SUBSET_PROGRAMS,
                  image_errors, machine_info, warm_up)
from .outputs import remove_stale, results_written_together, write_output
from .peer_mitsuba import MitsubaPeer, peer_info, slow_variant_warning
from .peer_report import Point, series_csv, series_table, time_to_error_csv, tte_rows, tte_table
from .plots import peer_plot
from .reference_cache import REFINE_TOLERANCE, effective_refine, reference_image, reference_text

def llvmpipe_threads() -> int | None:
    """How many llvmpipe rasteriser threads this process runs (Linux: the
    threads named llvmpipe-N), None where that cannot be seen."""
    try:
        names = [open(os.path.join("/proc/self/task", t, "comm")).read().strip()
                 for t in os.listdir("/proc/self/task")]
    except OSError:
        return None
    n = sum(1 for c in names if c.startswith("llvmpipe-"))
    return n or None


# ---------------------------------------------------------------- the side-by-side benchmark
#
# ``glassray bench --peer mitsuba [SCENE]`` (viewer/cli/bench.py parses the
# options and calls run_bench).  Each series is a list of points (a sample
# count, or an adaptive target); every point is rendered once untimed (its
# image is the one compared with the reference, and it compiles / warms up
# whatever it needs), then all points of all series are timed in ``repeat``
# interleaved rounds (order reversed every other round), medians reported.

PEER_DEFAULT_SCENE = "whitted-exact"
PEER_REFERENCE_SAMPLES = 512
#: ... and 8192 in the pixels where those disagree (about a third of
#: whitted-exact's at 320x180): 512 everywhere left the reference off by
#: RMSE 0.0027 itself, which is what the renderers reach at 256-512
#: samples, so lower errors could not be measured (see
#: viewer.reference.render_reference_refined)
PEER_REFERENCE_REFINE = 8192
PEER_QUICK_REFERENCE_SAMPLES = 16
GLASSRAY_SPP = (1, 2, 4, 8, 16, 32, 64, 128, 256)
#: Squares only: Mitsuba's multijitter sampler rounds other counts up to a
#: product of two near factors (32 -> 35, 2048 -> 2070, 8192 -> 8280), with
#: a warning each.  Measured per sample (whitted-glass, 320x180, peerwg4):
#: the powers of 4 took 8.7-9.5 ms of wall time, the counts 9 * 4^k
#: 11.0-11.8 ms (the rounded counts of the earlier series: 12.4-13.1 ms), so
#: docs/benchmark.md also gives the ratio at the 4096 point's rate.  Up to the time
#: limit (36864 = 192^2 only with --peer-time-limit over 16384's time: about
#: 47 s on a 2-core machine).
MITSUBA_SPP = (1, 4, 9, 16, 36, 64, 144, 256, 576, 1024, 2304, 4096, 9216, 16384, 36864)
#: The adaptive series: `render --adaptive --samples N` at the default
#: target error, N = each of these budgets (mean rays per pixel).
ADAPTIVE_BUDGETS = (2, 4, 8, 16, 32, 64, 128)     # ≤256 stops where ≤128 does (the target)
QUICK_GLASSRAY_SPP = (1, 2, 4)
QUICK_MITSUBA_SPP = (1, 2, 4, 8)
QUICK_ADAPTIVE_BUDGETS = (4, 8)
TARGET_ERRORS = (0.1, 0.07, 0.05, 0.04, 0.03, 0.025, 0.02, 0.015, 0.01, 0.007, 0.005, 0.004, 0.003,
                 0.002, 0.0015, 0.0012, 0.001, 0.0008, 0.0007)
#: A Mitsuba point whose warm-up render took longer than this (seconds) ends
#: its series: the next sample count (MITSUBA_SPP: 1.78-4 times as many)
#: would take that much longer.
PEER_TIME_LIMIT_S = 30.0


def run_bench(ctx, backend: str, name: str, scene, width: int, height: int, out, log, *, quick: bool = False,
              repeat: int = 5, reference_samples: int | None = None, reference_refine: int | None = None,
              time_limit_s: float | None = None) -> int:
    """The side-by-side comparison (``glassray bench --peer``: --quick,
    --repeat, --reference-samples, --reference-refine, --peer-time-limit);
    writes peer.md, peer.csv, peer-time-to-error.csv, peer-machine.json and
    peer.png to ``out``; returns the exit status."""
    out = Path(out)
    stem = Path(name).stem if str(name).endswith(".toml") else name
    ref_samples = reference_samples or (PEER_QUICK_REFERENCE_SAMPLES if quick else PEER_REFERENCE_SAMPLES)
    refine = reference_refine
    refine = (0 if quick else PEER_REFERENCE_REFINE) if refine is None else refine
    g_spp = QUICK_GLASSRAY_SPP if quick else GLASSRAY_SPP
    m_spp = QUICK_MITSUBA_SPP if quick else MITSUBA_SPP
    a_budgets = QUICK_ADAPTIVE_BUDGETS if quick else ADAPTIVE_BUDGETS
    limit_s = float(time_limit_s or PEER_TIME_LIMIT_S)

    info = machine_info(ctx, backend)
    log(f"peer comparison on {stem} ({scene.name}), {width}x{height}")
    log(f"machine: {info['cpu']} ({info['cpus_usable']} usable CPUs), load average "
        f"{info.get('load_average_start', ['?'])[0]}; GL: {info['gl']} via {backend}")
    peer = MitsubaPeer(scene, width, height)
    info["peer"] = peer_info(peer)
    log(f"peer: Mitsuba {info['peer']['mitsuba']} ({peer.variant_note}), {peer.threads} threads, "
        f"sampler {peer.sampler}, path tracer max depth {peer.max_depth}")
    slow = slow_variant_warning(peer.variant)
    if slow:
        info["peer"]["warning"] = slow
        log(f"warning: {slow}")

    refined = effective_refine(ref_samples, refine)
    ref_text = reference_text(ref_samples, refined)
    log(f"reference {width}x{height}, {ref_text} ...")
    t0 = time.perf_counter()
    ref, kind, cached = reference_image(scene, stem, width, height, ref_samples, out, ctx=ctx, log=log,
                                              refine=refined)
    log(f"reference {'from the cache' if cached else f'took {time.perf_counter() - t0:.1f} s'}")

    renderer = Renderer(ctx, scene, eager=False)
    renderer.SUBSET_PROGRAMS = SUBSET_PROGRAMS   # keep every culling variant compiled
    series: dict[str, list[Point]] = {"glassray": [], "mitsuba": []}

    def gl_run(n):
        return lambda: renderer.render(width, height, n, RENDER_SEED)

    def mi_run(n):
        return lambda: peer.render(n, seed=RENDER_SEED)

    def ad_run(n):
        return lambda: render_adaptive(renderer, width, height, n, seed=RENDER_SEED)

    try:
        for n in g_spp:
            series["glassray"].append(Point("glassray", f"{n}", n, gl_run(n)))
        series["glassray adaptive"] = [Point("glassray adaptive", f"<={n}", n, ad_run(n)) for n in a_budgets]
        # untimed first renders: the images compared, kernels compiled
        for sname, pts in list(series.items()):
            if sname == "mitsuba":
                continue
            for p in pts:
                # rendered again until nothing is left to compile: no timed render compiles
                res = warm_up(renderer, p.run)
                if sname == "glassray adaptive":
                    img = res.image
                    p.effective_spp = res.rays / res.spp.size     # rays per pixel, the corner rays included
                else:
                    img = res
                p.errors = image_errors(img, ref)
        for n in m_spp:
            p = Point("mitsuba", f"{n}", n, mi_run(n))
            t0 = time.perf_counter()
            img = p.run()
            took = time.perf_counter() - t0
            p.run()   # a second untimed render: the first of each size also traces and compiles the kernel
            p.errors = image_errors(img, ref)
            try:
                p.effective_spp = float(peer.mi_scene.sensors()[0].sampler().sample_count())
            except Exception:  # pragma: no cover - introspection only
                pass
            series["mitsuba"].append(p)
            if took > limit_s:
                log(f"mitsuba: {n} spp took {took:.1f} s: larger sample counts left out")
                break
        order = [p for pts in series.values() for p in pts]
        built = renderer.programs_built
        for k in range(repeat):
            for p in (order if k % 2 == 0 else order[::-1]):
                c0, t0 = time.process_time(), time.perf_counter()
                p.run()
                ctx.finish()
                p.times.append((time.perf_counter() - t0) * 1000.0)
                p.cpu_times.append((time.process_time() - c0) * 1000.0)
            log(f"round {k + 1}/{repeat} done")
        built_timed = renderer.programs_built - built
        gl_threads = llvmpipe_threads()
        if built_timed:
            log(f"warning: glassray's timed renders built {built_timed} shader programs")
    finally:
        renderer.release()

    if hasattr(os, "getloadavg"):
        info["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    adaptive = "glassray adaptive" in series
    tte = {clock: tte_rows(series, TARGET_ERRORS, clock) for clock in ("wall", "cpu")}
    info.update({
        "size": f"{width}x{height}", "scene": stem, "repeat": repeat, "quick": quick,
        "reference": {"kind": kind, "samples": ref_samples, "refined_samples": refined,
                      "refine_tolerance": REFINE_TOLERANCE if refined else None, "seed": REFERENCE_SEED,
                      "max_depth": REFERENCE_MAX_DEPTH, "min_weight": REFERENCE_MIN_WEIGHT},
        "glassray": {"max_depth": scene.render.max_depth, "min_weight": scene.render.min_weight,
                     "programs_built_in_timed_rounds": built_timed, "llvmpipe_threads": gl_threads,
                     "LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS"),
                     "sampling": "stratified sub-pixel offsets (viewer.sampling), uniform over the image"},
        "adaptive": ({"budgets_spp": list(a_budgets), "target": DEFAULT_TARGET_ERROR} if adaptive else None),
        "time_to_error": {clock: [{"target": e, "glassray_ms": tg[0], "mitsuba_ms": tm[0],
                                   "ratio": r[0], "ratio_flag": r[1],
                                   "adaptive_ms": ta[0] if ta else None,
                                   "ratio_adaptive": ra[0] if ra else None,
                                   "ratio_adaptive_flag": ra[1] if ra else None}
                                  for e, tg, tm, r, ta, ra in rows] for clock, rows in tte.items()},
    })

    header = [
        f"glassray bench --peer mitsuba, {info['date']}",
        f"scene {stem} ({scene.name}), {width}x{height}; machine: {info['cpu']}, {info['cpus_usable']} usable "
        f"CPUs, load average {info.get('load_average_start', ['?'])[0]} at start, "
        f"{info.get('load_average_end', ['?'])[0]} at end",
        f"glassray: GLSL shader on {info['gl']} via {backend}, max depth {scene.render.max_depth}, "
        f"min weight {scene.render.min_weight:g}, stratified samples",
        f"peer: Mitsuba {info['peer']['mitsuba']} (Dr.Jit {info['peer']['drjit']}), variant {peer.variant_note}, "
        f"{peer.threads} threads, path tracer max depth {peer.max_depth}, {peer.sampler} sampler, box filter, "
        "black delta BSDF on surfaces that only emit (no shadow rays)",
        f"threads: Mitsuba {peer.threads}, llvmpipe "
        + (f"{gl_threads}" if gl_threads is not None else "its default")
        + (f" (LP_NUM_THREADS={os.environ['LP_NUM_THREADS']})" if os.environ.get("LP_NUM_THREADS") else "")
        + f", on {info['cpus_usable']} usable CPUs",
        f"error: RMSE (linear) against the float64 reference, {ref_text} (seed {REFERENCE_SEED}), "
        f"max depth {REFERENCE_MAX_DEPTH}, min weight {REFERENCE_MIN_WEIGHT:g}; the same function "
        "and reference for both renderers",
        f"time: median of {repeat} interleaved timed renders after untimed warm-up renders (compiling is not "
        "timed for either: glassray's shader programs, Mitsuba's kernel for each sample count); each render "
        "finished (read back) before the clock stops; time to reach an error: log-log interpolation between "
        "measured points, no extrapolation",
    ]
    if slow:
        header.append(f"WARNING: {slow}")
    text = "\n".join(f"    {h}" for h in header) + "\n\n### Measured series\n\n" + series_table(series)
    for clock, title in (("wall", "wall clock"), ("cpu", "CPU time of the process")):
        text += (f"\n\n### Time to reach an RMSE ({title}); ratio = how many times sooner glassray gets there\n\n"
                 + tte_table(tte[clock], adaptive, clock))
    text += "\n"

    stale = []
    with results_written_together():      # all of them, or none
        write_output(out / "peer.csv", series_csv(series, width, height))
        write_output(out / "peer-time-to-error.csv", time_to_error_csv(tte))
        write_output(out / "peer.md", text.encode("utf-8"))
        write_output(out / "peer-machine.json", (json.dumps(info, indent=2) + "\n").encode("utf-8"))
        plotted = peer_plot(out / "peer.png", series, TARGET_ERRORS,
                        f"glassray on {renderer_and_release(info['gl'])} vs "
                        f"Mitsuba {info['peer']['mitsuba']} ({peer.variant}, {peer.threads} threads), "
                        f"{stem} {width}x{height}, {info['cpus_usable']} CPUs, reference {ref_samples}"
                        f"{f'/{refined}' if refined else ''} spp; "
                        f"{info['date'][:10]}")
        if not plotted:
            stale = remove_stale([out / "peer.png"])
    print(text, end="")
    print()
    print(f"wrote {out / 'peer.md'}, {out / 'peer.csv'}, {out / 'peer-time-to-error.csv'}, "
          f"{out / 'peer-machine.json'}" + (f", {out / 'peer.png'}" if plotted else ""))
    if not plotted:
        print("no plot: peer.png needs matplotlib (pip install 'glassray[bench]')")
        if stale:
            print(f"removed the plot of an earlier run: {out / 'peer.png'}")
    return 0
