"""Where one adaptive render's time goes: each step of
``viewer.adaptive.AdaptiveRender`` (a GPU draw call, or the numpy
bookkeeping between passes) timed on its own, after a warm-up render with
every shader variant compiled (docs/adaptive.md).

With ``--passes``: the first pass and a list pass of 8 samples over the
pixels whose footprint lies on the checker, with footprint samples and with
point samples, medians of 10 interleaved runs (after 2 untimed).

With ``--glass``: what a sample costs in a list pass of 8 samples over the
pixels whose centre sample traced more than HEAVY_RAYS rays (the glass),
over the others, and in a uniform 8-sample render, per sample and per ray
(the rays each pixel's centre sample traced), point samples, medians of 6
runs (after 1 untimed).

Usage (repository root, the project's virtual environment)::

    python tools/adaptive_steps.py [SCENE [BUDGET [WxH]]]    # glass-sphere 4 320x180
    python tools/adaptive_steps.py --passes [SCENE]          # 320x180
    python tools/adaptive_steps.py --glass [SCENE]           # default, 320x180
"""
import sys
import time

import moderngl

from viewer.measure import bench
import numpy as np

from viewer.adaptive.render import AdaptiveRender
from viewer.adaptive.sampler import AdaptiveSampler
from viewer.gpu.footprint import drain, footprint_planes
from viewer.gpu.renderer import Renderer
from viewer.scene.load import load_scene


def passes(name: str, w: int = 320, h: int = 180) -> None:
    from viewer.base.sampling import progressive_offsets

    ctx = moderngl.create_standalone_context(backend="egl")
    r = Renderer(ctx, load_scene(name))
    r.SUBSET_PROGRAMS = 64                   # both kinds of variant stay compiled
    s = AdaptiveSampler(r, w, h, footprint=True)
    s.compile()
    AdaptiveSampler(r, w, h).compile()
    _, _, corner_obj = drain(s.corner_pass())
    planes = footprint_planes(r.scene, corner_obj)
    s.set_offsets(progressive_offsets(16, 0))
    pixels = np.flatnonzero(planes.ravel() >= 0)
    ones, eights = np.ones(len(pixels), np.int64), np.full(len(pixels), 8, np.int64)
    times = {k: [] for k in ("point first", "point list", "footprint first", "footprint list")}

    def timed(fn):
        t0 = time.perf_counter()
        fn()
        return (time.perf_counter() - t0) * 1e3
    for _ in range(12):
        for kind, mask in (("point", None), ("footprint", planes)):
            s.set_footprint(mask)
            times[f"{kind} first"].append(timed(lambda: drain(s.first_pass())))
            times[f"{kind} list"].append(timed(lambda: drain(s.add_samples(pixels, ones, eights))))
    print(f"{name} at {w}x{h}: list passes over {len(pixels)} pixels on the checker, 8 samples each")
    for k, v in times.items():
        print(f"  {k}: {np.median(v[2:]):.1f} ms")
    s.release()
    r.release()


def glass(name: str, w: int = 320, h: int = 180) -> None:
    from viewer.adaptive.pixel_lists import HEAVY_RAYS, image_coherent_order
    from viewer.adaptive.render import _offsets

    ctx = moderngl.create_standalone_context(backend="egl")
    r = Renderer(ctx, load_scene(name))
    r.SUBSET_PROGRAMS = 64
    s = AdaptiveSampler(r, w, h)
    s.compile()
    _, _, rays = drain(s.first_pass())
    s.set_offsets(_offsets(8, bench.RENDER_SEED))
    cost = rays.ravel().astype(np.int64)
    order = image_coherent_order(w, h)

    def timed(fn):
        out = []
        for _ in range(7):
            t0 = time.perf_counter()
            fn()
            out.append(time.perf_counter() - t0)
        return float(np.median(out[1:])) * 1e3

    print(f"{name} at {w}x{h}, 8 point samples a pixel")
    for label, sel in ((f"list pass, glass (> {HEAVY_RAYS} rays)", cost > HEAVY_RAYS),
                       (f"list pass, the rest (<= {HEAVY_RAYS} rays)", cost <= HEAVY_RAYS)):
        px = order[sel[order]]
        n = len(px)
        first, count = np.ones(n, np.int64), np.full(n, 8, np.int64)
        ms = timed(lambda: drain(s.add_samples(px, first, count, cost[px])))
        print(f"  {label}: {n} pixels, {ms:.1f} ms, {ms * 1e6 / (8 * n):.0f} ns a sample, "
              f"{ms * 1e6 / (8 * cost[px].sum()):.0f} ns a ray")
    ms = timed(lambda: r.render(w, h, 8, seed=bench.RENDER_SEED))
    print(f"  uniform render: {w * h} pixels, {ms:.1f} ms, {ms * 1e6 / (8 * w * h):.0f} ns a sample, "
          f"{ms * 1e6 / (8 * cost.sum()):.0f} ns a ray; the glass holds "
          f"{cost[cost > HEAVY_RAYS].sum() / cost.sum():.0%} of the rays")
    s.release()
    r.release()


def main(argv: list[str]) -> int:
    if argv and argv[0] == "--passes":
        passes(argv[1] if len(argv) > 1 else "glass-sphere")
        return 0
    if argv and argv[0] == "--glass":
        glass(argv[1] if len(argv) > 1 else "default")
        return 0
    name = argv[0] if argv else "glass-sphere"
    budget = int(argv[1]) if len(argv) > 1 else 4
    w, h = (int(v) for v in (argv[2] if len(argv) > 2 else "320x180").split("x"))
    ctx = moderngl.create_standalone_context(backend="egl")
    r = Renderer(ctx, load_scene(name))
    AdaptiveSampler(r, w, h, footprint=True).compile()
    log = []
    for _ in range(2):                      # the first is the warm-up
        job = AdaptiveRender(r, w, h, budget, seed=bench.RENDER_SEED)
        log, t_all = [], time.perf_counter()
        done = False
        while not done:
            draws, t0 = job.draws_done, time.perf_counter()
            done = job.step()
            log.append((job.draws_done > draws, time.perf_counter() - t0, len(job.rounds),
                        job.sampler.last_draw_fragments))
        t_all = time.perf_counter() - t_all
        job.release()
    draw_s = sum(dt for is_draw, dt, _, _ in log if is_draw)
    print(f"{name} at {w}x{h}, budget {budget}: {t_all * 1e3:.0f} ms; "
          f"{sum(1 for s in log if s[0])} draw calls {draw_s * 1e3:.0f} ms, "
          f"bookkeeping {(t_all - draw_s) * 1e3:.0f} ms")
    for is_draw, dt, rounds, fragments in log:
        if dt > 0.002:
            print(f"  {'draw' if is_draw else 'book'} (rounds so far {rounds}): {dt * 1e3:6.1f} ms"
                  + (f", {fragments} pixel-samples" if is_draw else ""))
    r.release()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
