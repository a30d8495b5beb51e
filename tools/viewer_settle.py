"""How soon the viewer's accumulation settles, uniform against adaptive
(README, "Viewer"): a Progressive driven with 33 ms frame budgets at 320x180
and 16 samples on glass-sphere and the default scene, the RMSE of what the
window would show against a 256-sample uniform render (another seed) after
every frame; medians of 3 runs of the time to RMSE 0.01 and to 0.0065 (about
where 16 uniform samples end), the time to done,
and the RMSE when done.  The clock counts what a frame of the viewer does
(accumulate, then the display pass into a window-sized framebuffer), not
the read-back of the image for the RMSE.  Then the longest frame of an
adaptive accumulation of glass-sphere at 1280x720.

Usage (repository root, the project's virtual environment)::

    python tools/viewer_settle.py
"""
import time

import moderngl
import numpy as np

from viewer.scene.load import load_scene
from viewer.gpu.renderer import Renderer
from viewer.window.progressive import Progressive
ctx = moderngl.create_standalone_context(backend="egl")
W, H = 320, 180
window = ctx.simple_framebuffer((W, H), components=4)
for name in ("glass-sphere", "default"):
    sc = load_scene(name); sc.render.samples = 16
    r = Renderer(ctx, sc)
    ref = r.render(W, H, 256, seed=9).astype(np.float64)
    for adaptive in (False, True):
        res = []
        for rep in range(3):
            p = Progressive(ctx, r, adaptive=adaptive)
            p.resize(W, H)
            if adaptive: p.compile_adaptive()
            r.render(W, H, 1)
            clock = 0.0; hit = None; hit2 = None
            while not p.done:
                t0 = time.perf_counter()
                p.accumulate(budget_ms=33)
                p.display(window, (0, 0, W, H))
                ctx.finish()
                clock += time.perf_counter() - t0
                e = np.sqrt(np.mean((p.image().astype(np.float64) - ref) ** 2))
                if hit is None and e < 0.01: hit = clock
                if hit2 is None and e < 0.0065: hit2 = clock
            res.append((hit, clock, e, hit2)); p.release()
        med = lambda k: float(np.median([x[k] if x[k] is not None else np.inf for x in res]))
        print(f"{name} {'adaptive' if adaptive else 'uniform '}: RMSE 0.01 after {med(0):.2f} s, "
              f"0.0065 after {med(3):.2f} s, done after {med(1):.2f} s at RMSE {med(2):.4f}", flush=True)
    r.release()

# The longest frame (one accumulate() call with the viewer's 33 ms budget)
# of an adaptive accumulation at the window's default size: a step (one
# draw call or one piece of the bookkeeping between passes) is never cut,
# so the longest step is what a user sees as a hitch when the view settles.
sc = load_scene("glass-sphere")
r = Renderer(ctx, sc)
p = Progressive(ctx, r, adaptive=True)
p.resize(1280, 720)
p.compile_adaptive()
frames = []
while not p.done:
    t0 = time.perf_counter()
    p.accumulate(budget_ms=33)
    frames.append(time.perf_counter() - t0)
print(f"glass-sphere adaptive 1280x720: {len(frames)} frames, longest {max(frames) * 1e3:.0f} ms, "
      f"median {np.median(frames) * 1e3:.0f} ms", flush=True)
p.release()
r.release()
