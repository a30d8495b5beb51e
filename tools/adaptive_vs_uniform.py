"""Adaptive against uniform sampling at equal error: the numbers of the
README's "Adaptive anti-aliasing" section and docs/adaptive.md (issue 7).

For each scene at 320x180: uniform renders at 16, 32 and 64 samples (as
``uniform-point`` with point samples only, the baseline of the ratios, as
issue 7 measured them; as ``uniform`` with the footprint samples
``Renderer.render`` takes from 2 samples on since) and adaptive renders (``viewer.adaptive.render_adaptive``, default target) at
budgets of 4 to 32 rays per pixel, with footprint samples on the checker
(the default) and, as ``adaptive-point``, without, each rendered once untimed (the
image compared) and then timed in 5 interleaved rounds (order reversed
every other round; medians of wall-clock and process CPU time).  Errors are
RMSE (linear) against two float64 references (``viewer.reference``) of 512
samples (seed 1), cached in the output folder:

* ``bench``: the benchmark's reference, max depth 16 and min weight 1e-4
  (``viewer.bench.reference_image``); it includes what the scene's own
  depth and weight leave out (the default scene: 5.5e-3 RMSE at max depth
  8, which no sampling removes);
* ``own``: the scene's own max depth and min weight, so that the error is
  the anti-aliasing error alone.

Usage (from the repository root, the project's virtual environment)::

    python tools/adaptive_vs_uniform.py ref default glass-sphere    # references: 20 + 10 min on 2 cores
    python tools/adaptive_vs_uniform.py time default glass-sphere   # the table: about 4 min

The references are computed one scene at a time per process (run two
processes for two cores).  ``time`` writes ``adaptive-vs-uniform.json``.
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from viewer.measure import bench
from viewer.scene.load import load_scene

W, H = 320, 180
REFERENCE_SAMPLES = 512
OUT = Path("bench-results/adaptive")
# (kind, samples); "adaptive@E": adaptive with target error E instead of
# the default (a budget that is not a whole number of samples per pixel:
# the render stops where every pixel's estimate is below E)
SETTINGS = [("uniform-point", 16), ("uniform-point", 32), ("uniform-point", 64),
            ("uniform", 16), ("uniform", 32), ("uniform", 64),
            ("adaptive", 4), ("adaptive@0.004", 4), ("adaptive@0.006", 4),
            ("adaptive", 5), ("adaptive", 6), ("adaptive@0.003", 6), ("adaptive", 7), ("adaptive", 8),
            ("adaptive", 12), ("adaptive", 16), ("adaptive", 24), ("adaptive", 32),
            ("adaptive-point", 8), ("adaptive-point", 16), ("adaptive-point", 24), ("adaptive-point", 32)]
REPEAT = 5


def own_reference_path(name: str) -> Path:
    scene = load_scene(name)
    return OUT / (f"ref-own-{name}-{bench._scene_digest(scene)}-{W}x{H}-s{REFERENCE_SAMPLES}"
                  f"-seed{bench.REFERENCE_SEED}-float64-{bench._reference_source_digest()}.npy")


def references(names: list[str]) -> None:
    from viewer.reference.camera import camera_rays
    from viewer.reference.trace import trace
    from viewer.base.sampling import sample_offsets

    OUT.mkdir(parents=True, exist_ok=True)
    for name in names:
        scene = load_scene(name)
        t0 = time.time()
        bench.reference_image(scene, name, W, H, REFERENCE_SAMPLES, OUT, log=print)
        print(f"{name}: bench reference {time.time() - t0:.0f} s", flush=True)
        path = own_reference_path(name)
        if path.is_file():
            continue
        t0 = time.time()
        acc = np.zeros((H * W, 3))
        for off in sample_offsets(REFERENCE_SAMPLES, bench.REFERENCE_SEED):
            o, d = camera_rays(scene, W, H, off)
            acc += trace(scene, o.reshape(-1, 3), d.reshape(-1, 3))
        img = acc.reshape(H, W, 3) / REFERENCE_SAMPLES * scene.render.exposure
        tmp = path.with_suffix(".tmp.npy")
        np.save(tmp, img)
        tmp.replace(path)
        print(f"{name}: own-settings reference {time.time() - t0:.0f} s", flush=True)


def measure(names: list[str]) -> None:
    import moderngl

    from viewer.adaptive.render import DEFAULT_TARGET_ERROR, render_adaptive
    from viewer.adaptive.sampler import AdaptiveSampler
    from viewer.gpu.renderer import Renderer

    ctx = moderngl.create_standalone_context(backend="egl")
    rows = []
    for name in names:
        scene = load_scene(name)
        refs = {"bench": bench.reference_image(scene, name, W, H, REFERENCE_SAMPLES, OUT)[0],
                "own": np.load(own_reference_path(name))}
        r = Renderer(ctx, scene)
        # room for every variant the settings use (uniform, and adaptive with
        # and without footprint samples, per culling group): no recompiles
        # inside the timed runs
        r.SUBSET_PROGRAMS = 64
        for footprint in (False, True):
            AdaptiveSampler(r, W, H, footprint=footprint).compile()

        def run(kind, n):
            if kind.startswith("uniform"):
                img = r.render(W, H, n, seed=bench.RENDER_SEED, footprint=False if kind == "uniform-point" else None)
                return img, float(n), float(n)
            target = float(kind.split("@")[1]) if "@" in kind else DEFAULT_TARGET_ERROR
            res = render_adaptive(r, W, H, n, target_error=target, seed=bench.RENDER_SEED,
                                  footprint=False if kind == "adaptive-point" else None)
            return res.image, res.mean_spp, res.rays / (W * H)

        info = {}
        for kind, n in SETTINGS:
            img, spp, rays = run(kind, n)
            err = {k: float(np.sqrt(np.mean((img.astype(np.float64) - ref) ** 2))) for k, ref in refs.items()}
            info[(kind, n)] = dict(rmse=err, spp=spp, rays=rays, wall=[], cpu=[])
        for rep in range(REPEAT):
            for kind, n in (SETTINGS if rep % 2 == 0 else SETTINGS[::-1]):
                t0, c0 = time.perf_counter(), time.process_time()
                run(kind, n)
                info[(kind, n)]["wall"].append(time.perf_counter() - t0)
                info[(kind, n)]["cpu"].append(time.process_time() - c0)
        base = ("uniform-point", 64)         # the ratios' baseline ("u64")
        u64 = info[base]
        med = {k: {c: statistics.median(v[c]) * 1e3 for c in ("wall", "cpu")} for k, v in info.items()}
        for (kind, n), d in info.items():
            row = dict(scene=name, setting=f"{kind} {n}", mean_spp=d["spp"], rays_per_px=d["rays"],
                       wall_ms=med[(kind, n)]["wall"], cpu_ms=med[(kind, n)]["cpu"],
                       rmse_bench=d["rmse"]["bench"], rmse_own=d["rmse"]["own"],
                       rays_vs_u64=d["rays"] / 64, wall_vs_u64=med[(kind, n)]["wall"] / med[base]["wall"],
                       cpu_vs_u64=med[(kind, n)]["cpu"] / med[base]["cpu"],
                       rmse_bench_vs_u64=d["rmse"]["bench"] / u64["rmse"]["bench"],
                       rmse_own_vs_u64=d["rmse"]["own"] / u64["rmse"]["own"])
            rows.append(row)
            print(f"| {name} | {kind} {n} | {d['rays']:.0f} ({row['rays_vs_u64']:.2f}x) | "
                  f"{row['wall_ms']:.0f} / {row['cpu_ms']:.0f} ({row['wall_vs_u64']:.2f}x / {row['cpu_vs_u64']:.2f}x) | "
                  f"{row['rmse_own']:.2e} ({row['rmse_own_vs_u64']:.2f}x) | "
                  f"{row['rmse_bench']:.2e} ({row['rmse_bench_vs_u64']:.2f}x) |", flush=True)
        r.release()
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "adaptive-vs-uniform.json").write_text(json.dumps(rows, indent=1))


def main(argv: list[str]) -> int:
    if len(argv) < 2 or argv[0] not in ("ref", "time"):
        print(__doc__.split("Usage")[1].split("::")[1], file=sys.stderr)
        return 2
    (references if argv[0] == "ref" else measure)(argv[1:])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
