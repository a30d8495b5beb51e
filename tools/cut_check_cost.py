"""What render()'s check for trees cut by the driver's loop limit costs
(README, "Deep ray trees").

For each scene named (default: default, glass-sphere, whitted-glass,
coloured-liquid): the wall-clock and CPU time of a 1-sample render with the
check (Renderer.cut_check, the default) and without it, medians of 7
interleaved renders after a warm-up, and the largest difference between
the two images (0: the check changes no pixel of an uncut image).

Usage (repository root, the project's virtual environment)::

    python tools/cut_check_cost.py [--size WxH] [SCENE ...]
"""
import argparse
import time

import moderngl
import numpy as np

from viewer.gpu.renderer import Renderer
from viewer.scene.load import load_scene

ap = argparse.ArgumentParser()
ap.add_argument("--size", default="1280x720")
ap.add_argument("scenes", nargs="*", default=["default", "glass-sphere", "whitted-glass", "coloured-liquid"])
args = ap.parse_args()
W, H = (int(v) for v in args.size.split("x"))
ctx = moderngl.create_standalone_context(backend="egl")

for name in args.scenes:
    scene = load_scene(name)
    renderers = {"check": Renderer(ctx, scene), "no check": Renderer(ctx, scene)}
    renderers["no check"].cut_check = False
    images = {k: r.render(W, H, 1) for k, r in renderers.items()}     # warm-up: every variant compiled
    wall = {k: [] for k in renderers}
    cpu = {k: [] for k in renderers}
    for _ in range(7):
        for k, r in renderers.items():
            ctx.finish()
            t, c = time.perf_counter(), time.process_time()
            r.render(W, H, 1)
            wall[k].append(time.perf_counter() - t)
            cpu[k].append(time.process_time() - c)
    cells = ", ".join(f"{k} {1000 * np.median(wall[k]):.1f} ms (CPU {1000 * np.median(cpu[k]):.1f})" for k in renderers)
    diff = float(np.abs(images["check"] - images["no check"]).max())
    resumed = renderers["check"].last_render_resumed
    print(f"{name} {W}x{H}: {cells}; max difference {diff:g}; drawn again in passes: {resumed}", flush=True)
    for r in renderers.values():
        r.release()
