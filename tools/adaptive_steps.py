"""Where one adaptive render's time goes: each step of
``viewer.adaptive.AdaptiveRender`` (a GPU draw call, or the numpy
bookkeeping between passes) timed on its own, after a warm-up render with
every shader variant compiled (README, "Adaptive anti-aliasing").

Usage (repository root, the project's virtual environment)::

    python tools/adaptive_steps.py [SCENE [BUDGET [WxH]]]    # glass-sphere 4 320x180
"""
import sys
import time

import moderngl

from viewer import bench
from viewer.adaptive import AdaptiveRender, AdaptiveSampler
from viewer.renderer import Renderer
from viewer.scene import load_scene


def main(argv: list[str]) -> int:
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
