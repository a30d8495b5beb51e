"""The shader on another OpenGL driver: the same images, and its frame times.

Made for the GPU machine a session is sometimes lent (docs/performance.md, "On a GPU");
it runs anywhere an offscreen context does.

    python tools/gpu_check.py images DIR    # the built-in scenes, 320x180, 4 samples, to DIR/NAME.npy
    python tools/gpu_check.py compare DIR [SAVE]  # the same here, compared with DIR's (another
                                                  # driver's); SAVE: folder for this driver's images
    python tools/gpu_check.py timing [N]    # 1280x720, 1 sample: frame times, medians of N (21)
    python tools/gpu_check.py steps [SCENE ...]  # 320x180: 1 sample, 4 without and with footprint
                                                  # samples, each timed with its programs built

Every render that takes over WATCHDOG seconds prints where Python stands
(faulthandler), again every WATCHDOG seconds: a GPU has no loop limit and
may have no watchdog, so a shader that never ends, or a compile that takes
minutes, shows here as a stack instead of silence.

compare prints, per scene, the RMSE, the largest difference and the share of
pixels more than 1/255 apart in display space (sRGB, clamped), and exits 1
when a scene differs by more than the tolerance below (float32 rounding
that branches differently at an edge or a grazing angle moves a few pixels
a lot, so the share is judged, not the largest difference).

timing measures, per scene, after a warm-up with every variant compiled:
- "render": Renderer.render() by wall clock (what `glassray render --timing`
  times: tile-by-tile draws, each finished, the image read back);
- "frame (GPU)": the GPU's own time of one frame's draws as the viewer draws
  them (draw_sample over the whole image, no read-back), from a GL timer
  query, and by wall clock to ctx.finish(); with the tile culling (specialised), without it, and with the
  generic all-features shader.
"""
import faulthandler
import statistics
import sys
import time
from pathlib import Path

import moderngl
import numpy as np

from viewer.gpu.context import create_offscreen_context, describe
from viewer.base.imageio import linear_to_srgb
from viewer.gpu.renderer import Renderer
from viewer.scene.load import builtin_scene_names, load_scene

SIZE = (320, 180)
SAMPLES = 4
#: compare: the share of pixels more than 1/255 apart that a scene may have
MAX_SHARE = 0.002
WATCHDOG = 20
NAMES = ("default", "bench-opaque", "glass-sphere", "bench-many", "whitted-glass", "coloured-liquid")


def scenes() -> list[str]:
    return builtin_scene_names()


class watch:
    """Prints Python's stack every WATCHDOG seconds while the block runs."""
    def __enter__(self):
        faulthandler.dump_traceback_later(WATCHDOG, repeat=True)

    def __exit__(self, *exc):
        faulthandler.cancel_dump_traceback_later()


def render_all(ctx) -> dict[str, np.ndarray]:
    out = {}
    for name in scenes():
        r = Renderer(ctx, load_scene(name))
        r.COMPILES_PER_DRAW = 99
        t = time.perf_counter()
        with watch():
            out[name] = r.render(*SIZE, SAMPLES)
        print(f"  {name}: {time.perf_counter() - t:.1f} s, {r.programs_built} programs built", flush=True)
        r.release()
    return out


def steps(ctx, names: list[str]) -> None:
    for name in names:
        r = Renderer(ctx, load_scene(name))
        r.COMPILES_PER_DRAW = 99
        for label, kw in (("1 sample", dict(samples=1)), ("4 samples, point", dict(samples=4, footprint=False)),
                          ("4 samples, footprint", dict(samples=4, footprint=True)),
                          ("4 samples, footprint, again", dict(samples=4, footprint=True))):
            t, built = time.perf_counter(), r.programs_built
            with watch():
                img = r.render(*SIZE, **kw)
            print(f"{name}, {label}: {time.perf_counter() - t:.2f} s, {r.programs_built - built} programs built, "
                  f"mean {img.mean():.4f}", flush=True)
        r.release()


def frame_ms(ctx, fn, n: int) -> tuple[float, float]:
    """Medians of n: the GPU's time of fn's draws (timer query; llvmpipe's
    is meaningless, it defers the work) and the wall-clock time to finish."""
    q = ctx.query(time=True)
    gpu, wall = [], []
    for _ in range(n):
        t = time.perf_counter()
        with q:
            fn()
        ctx.finish()
        wall.append((time.perf_counter() - t) * 1e3)
        gpu.append(q.elapsed / 1e6)
    return statistics.median(gpu), statistics.median(wall)


def timing(ctx, n: int) -> None:
    W, H = 1280, 720
    for name in NAMES:
        scene = load_scene(name)
        culled, flat, generic = Renderer(ctx, scene), Renderer(ctx, scene), Renderer(ctx, scene, specialise=False)
        flat.cull = False
        for r in (culled, flat, generic):
            r.COMPILES_PER_DRAW = 99
            with watch():
                r.render(W, H, 1)
        walls = []
        for _ in range(n):
            t = time.perf_counter()
            culled.render(W, H, 1)
            walls.append((time.perf_counter() - t) * 1e3)
        line = [f"{name}: render {statistics.median(walls):.2f} ms (wall, median of {n})"]
        for label, r in (("culled", culled), ("unculled", flat), ("generic", generic)):
            fbo = r._target(W, H)

            def draw(r=r, fbo=fbo):
                fbo.use()
                ctx.disable(moderngl.BLEND)
                r.draw_sample(W, H, (0.5, 0.5))
            draw()
            g, w = frame_ms(ctx, draw, n)
            line.append(f"frame {label}: GPU {g:.3f} ms, wall {w:.3f} ms")
        print("; ".join(line), flush=True)
        for r in (culled, flat, generic):
            r.release()


def main(argv: list[str]) -> int:
    with watch():
        ctx, backend = create_offscreen_context("egl")
    print(f"{describe(ctx)} ({backend})", flush=True)
    cmd = argv[0] if argv else "timing"
    if cmd == "images":
        d = Path(argv[1])
        d.mkdir(parents=True, exist_ok=True)
        for name, img in render_all(ctx).items():
            np.save(d / f"{name}.npy", img)
        return 0
    if cmd == "compare":
        d = Path(argv[1])
        if len(argv) > 2:
            Path(argv[2]).mkdir(parents=True, exist_ok=True)
        bad = 0
        for name, img in render_all(ctx).items():
            other = np.load(d / f"{name}.npy")
            rmse = float(np.sqrt(np.mean((img.astype(np.float64) - other) ** 2)))
            diff = np.abs(linear_to_srgb(img) - linear_to_srgb(other)).max(axis=-1)
            share = float(np.mean(diff > 1 / 255))
            worst = np.unravel_index(np.argmax(diff), diff.shape)
            ok = share <= MAX_SHARE and np.isfinite(img).all()
            bad += not ok
            print(f"{name}: RMSE {rmse:.2e}, largest {diff.max():.4f} at (x={worst[1]}, y={worst[0]}), "
                  f"{share:.3%} of pixels > 1/255 {'ok' if ok else 'DIFFERS'}", flush=True)
            if len(argv) > 2:
                np.save(Path(argv[2]) / f"{name}.npy", img)
        return 1 if bad else 0
    if cmd == "steps":
        steps(ctx, argv[1:] or ["default", "bench-many"])
        return 0
    if cmd == "timing":
        timing(ctx, int(argv[1]) if len(argv) > 1 else 21)
        return 0
    print(__doc__)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
