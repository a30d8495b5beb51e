"""What tools/frame_budget.py and tools/specialise_ratio.py share: a
median timer, and one timed pass over each group of tiles of a renderer's
culling plan."""
import time

import moderngl
import numpy as np


def median_time(fn, n):
    """Median wall-clock and CPU seconds of n calls of fn."""
    wall, cpu = [], []
    for _ in range(n):
        t, c = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return float(np.median(wall)), float(np.median(cpu))


def timed_groups(r, W, H, n=5):
    """For each group of the culling plan of renderer r at WxH, 1 sample:
    (object indices, scissor rectangles, median wall-clock seconds of one
    pass over the group's rectangles, finished on the GPU). r must cull
    (r.culls()) and have every variant compiled already."""
    ctx = r.ctx
    r._target(W, H).use()
    ctx.disable(moderngl.BLEND)
    programs = r._culled(W, H)                    # also makes r._plan_groups this size's plan
    for (subset, rects), (prog, _) in zip(r._plan_groups, programs):
        def draw():
            r.bind(prog, W, H, (0.5, 0.5))
            vao = r.vao_of(prog)
            for rect in rects:
                ctx.scissor = rect
                vao.render(moderngl.TRIANGLES, vertices=3)
            ctx.scissor = None
            ctx.finish()
        yield subset, rects, median_time(draw, n)[0]
