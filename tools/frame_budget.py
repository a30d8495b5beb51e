"""Rays against time in one frame, per culling group, and what that implies
for issue 5's 100 ms target (README, "Measured speed"; docs/performance.md).

For a scene (default: the default scene) at WxH (default 1280x720), 1
sample: the whole frame's wall-clock and CPU time (median of 9 after a
warm-up that compiles every variant); the rays it traces (camera, reflected,
refracted and shadow rays, from the shader's own count: `--view cost`); and
for each group of tiles of the culling plan its share of the pixels, its
rays, the wall-clock time of one pass over it (median of 5) and so its
nanoseconds per ray. Then the bound: the frame's fixed cost (a frame with
no objects: clear, draw calls, read-back) plus every ray at the cheapest
group's price. No change to how the rays are scheduled can beat that
without tracing fewer rays, that is without changing the image.

Each group's line also gives its SIMD waste: llvmpipe shades a 4x2 block
of pixels as one group of 8 lanes (`tools/llvmpipe_branches.py`), whose
loops run until its slowest lane is done, so the block costs about 8 times
its pixel with the most rays (a pixel's rays stand for its lane's work);
the waste is the sum of that over the group's blocks against the rays it
traces.  A small waste means that the time goes into the code each ray
runs, not into lanes left idle, and that no regrouping of pixels (sorting
rays, compaction) has much to win.

Usage (repository root, the project's virtual environment)::

    python tools/frame_budget.py [SCENE] [WxH]
"""
import dataclasses
import sys

import moderngl

from _frame_groups import median_time, timed_groups
from viewer.gpu.renderer import Renderer
from viewer.scene.load import load_scene


def simd_waste(rays, rects, height: int) -> float:
    """8 x the most rays of each whole 4x2 block (llvmpipe's SIMD group) of
    the rectangles, summed, against the rays they trace, minus 1.  The
    rectangles are culling tiles, whole 4x2 blocks but at the image's
    right and top edges, whose partial blocks are left out."""
    busiest = traced = 0
    for x, y, w, h in rects:
        block = rays[height - y - h:height - y, x:x + w]
        # blocks are counted from OpenGL's bottom-left corner: a partial
        # row is the slice's first (top), a partial column its last
        block = block[block.shape[0] % 2:, :block.shape[1] // 4 * 4]
        g = block.reshape(block.shape[0] // 2, 2, block.shape[1] // 4, 4).max(axis=(1, 3))
        busiest += 8 * int(g.sum())
        traced += int(block.sum())
    return busiest / traced - 1 if traced else 0.0


def main(name="default", size="1280x720"):
    W, H = (int(v) for v in size.split("x"))
    ctx = moderngl.create_standalone_context(backend="egl")
    scene = load_scene(name)
    r = Renderer(ctx, scene)
    r.COMPILES_PER_DRAW = 99                       # every variant now, none in a timed render
    r.render(W, H, 1)
    wall, cpu = median_time(lambda: r.render(W, H, 1), 9)

    empty = Renderer(ctx, dataclasses.replace(scene, objects=[]))
    empty.render(W, H, 1)
    fixed, _ = median_time(lambda: empty.render(W, H, 1), 9)
    empty.release()

    rays = r.ray_cost(W, H)
    total = int(rays.sum())
    print(f"{name} {W}x{H}, 1 sample: {wall * 1e3:.0f} ms wall, {cpu * 1e3:.0f} ms CPU (medians of 9); "
          f"{total / 1e6:.2f} M rays ({total / (W * H):.2f} a pixel, at most {rays.max()}); "
          f"a frame without objects {fixed * 1e3:.0f} ms")

    groups = []
    if r.culls():
        names = [o.name or f"#{k}" for k, o in enumerate(scene.objects)]
        for subset, rects, t in timed_groups(r, W, H):
            area = sum(w * h for _, _, w, h in rects)
            # OpenGL's scissor rectangles count rows from the bottom; ray_cost's rows are top first.
            n = sum(int(rays[H - y - h:H - y, x:x + w].sum()) for x, y, w, h in rects)
            groups.append((t, n))
            label = ", ".join(names[k] for k in subset) or "none"
            print(f"  objects {label}: {area / (W * H):.1%} of the pixels, {n / 1e6:.2f} M rays "
                  f"({n / max(area, 1):.1f} a pixel), {t * 1e3:.1f} ms, "
                  f"{t / max(n, 1) * 1e9:.0f} ns a ray, SIMD waste {simd_waste(rays, rects, H):+.0%}")
    r.release()
    # the groups' rectangles tile the image exactly once
    assert not groups or sum(n for _, n in groups) == total, "groups do not cover the rays"
    if groups:
        cheapest = min(t / n for t, n in groups if n)
        bound = fixed + total * cheapest
        print(f"every ray at the cheapest group's {cheapest * 1e9:.0f} ns plus the fixed cost: "
              f"{bound * 1e3:.0f} ms (the frame takes {wall * 1e3:.0f} ms)")


if __name__ == "__main__":
    main(*sys.argv[1:])
