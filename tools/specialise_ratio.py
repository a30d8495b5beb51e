"""Specialised against generic shader, and where a frame's time goes
(docs/performance.md; README, "Measured speed").

For each scene named (default: bench-opaque, glass-sphere, default): the
wall-clock and CPU time of a 1280x720, 1-sample render with the specialised
shader (culling included) and with the generic all-features one, medians of
9 interleaved renders after a warm-up with every variant compiled; then the
culling plan's groups of tiles, their share of the pixels and the time of
one 1-sample pass over each (median of 5), and the time to compute the plan.

Usage (repository root, the project's virtual environment)::

    python tools/specialise_ratio.py [SCENE ...]
"""
import sys

import moderngl
import numpy as np

from _frame_groups import median_time, timed_groups
from viewer.gpu import culling
from viewer.gpu.renderer import Renderer
from viewer.scene.load import load_scene

W, H = 1280, 720
ctx = moderngl.create_standalone_context(backend="egl")


for name in sys.argv[1:] or ["bench-opaque", "glass-sphere", "default"]:
    scene = load_scene(name)
    spec, gen = Renderer(ctx, scene), Renderer(ctx, scene, specialise=False)
    for r in (spec, gen):
        r.COMPILES_PER_DRAW = 99
        r.render(W, H, 1)
    times = {"specialised": ([], []), "generic": ([], [])}
    for _ in range(9):                                   # interleaved
        for label, r in (("specialised", spec), ("generic", gen)):
            w, c = median_time(lambda: r.render(W, H, 1), 1)
            times[label][0].append(w)
            times[label][1].append(c)
    (sw, sc), (gw, gc) = ([float(np.median(v)) for v in times[k]] for k in ("specialised", "generic"))
    print(f"{name}: specialised {sw * 1e3:.0f} ms, generic {gw * 1e3:.0f} ms: "
          f"{gw / sw:.2f}x by wall clock, {gc / sc:.2f}x by CPU time")
    if spec.culls():
        plan_s, _ = median_time(lambda: culling.plan(scene, W, H), 5)
        print(f"  culling plan: {plan_s * 1e3:.1f} ms to compute")
        names = [o.name or f"#{k}" for k, o in enumerate(scene.objects)]
        for subset, rects, wall in timed_groups(spec, W, H):
            area = sum(w * h for _, _, w, h in rects)
            print(f"  {len(subset)} objects ({', '.join(names[k] for k in subset)}): "
                  f"{area / (W * H):.1%} of the pixels, {wall * 1e3:.1f} ms")
    spec.release()
    gen.release()
