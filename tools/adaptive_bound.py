"""How far the adaptive sampler's error estimate is from the best any
estimate could do: the measurement behind docs/adaptive.md's "The bound of
point samples" (issue 7).

For each scene at 320x180 it records, for every pixel that the corner and
centre rays flag (viewer/adaptive/, step 1), each of the first 256
samples separately (one list pass per sample index), for the render seed
and for SEEDS other scrambles of the same points.  Then it replays the
adaptive render (``AdaptiveRender`` itself, its sampler replaced by one
that adds up recorded samples) with three rankings:

* ``estimate``: the render's own error estimate (the replay of the real
  render: its RMSE is printed next to the real one as a check);
* ``expected``: the same rounds ranked by each pixel's *expected* error at
  its sample count, the RMS over the other scrambles of its error against
  the reference: what a perfect estimate of the error (as opposed to the
  error of this one draw, which nothing can know) would give;
* ``greedy``: no rounds, targets or neighbours: samples doubled one pixel
  at a time in order of expected error^2 / n until the budget is spent
  (how far the round structure and the cost weighting are from a
  sample-count optimum).

Errors are RMSE (linear) against the float64 ``own`` reference of
tools/adaptive_vs_uniform.py (512 samples at the scene's own depth and
weight; ``python tools/adaptive_vs_uniform.py ref NAME`` makes it, 10-20
minutes).  For each ranking the table ends with the rays per pixel at which
it reaches the error of a uniform 64-sample render (interpolated in log-log
between budgets).

Usage (from the repository root, the project's virtual environment)::

    python tools/adaptive_bound.py glass-sphere default    # about 6 minutes on 2 cores

writes ``bench-results/adaptive/bound.json``.
"""

from __future__ import annotations

import heapq
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import adaptive_vs_uniform as avu  # noqa: E402

from viewer.adaptive.estimators import FIRST_ROUND, Sums  # noqa: E402
from viewer.measure import bench  # noqa: E402
from viewer.adaptive.render import AdaptiveRender, render_adaptive  # noqa: E402
from viewer.adaptive.sampler import AdaptiveSampler  # noqa: E402
from viewer.gpu.footprint import drain  # noqa: E402
from viewer.base.sampling import progressive_offsets  # noqa: E402
from viewer.scene.load import load_scene  # noqa: E402

W, H = avu.W, avu.H
RECORD = 256                       # samples recorded per flagged pixel (max_spp at a budget of 32)
SEEDS = tuple(range(101, 109))     # the other scrambles the expected error is taken over
BUDGETS = (8, 12, 16, 20, 24, 32)


class Recording:
    """The first pass, corner pass and flags of one width x height render,
    and the samples 0..record-1 (seed `seed`) of every flagged pixel."""

    def __init__(self, renderer, seed: int, width: int = W, height: int = H, record: int = RECORD):
        self.width, self.height, self.record = width, height, record
        job = AdaptiveRender(renderer, width, height, 16, seed=bench.RENDER_SEED)
        sampler = job.sampler
        self.first = drain(sampler.first_pass((0.5, 0.5)))
        self.corners = drain(sampler.corner_pass())
        sums = self.first[0]
        flagged, _ = job.flags(sums.mean, self.first[1], *self.corners)
        self.flat = job._coherent[flagged.ravel()[job._coherent]]
        self.offsets = progressive_offsets(record, seed)
        sampler.set_offsets(self.offsets)
        m = len(self.flat)
        L = np.empty((m, record, 3), np.float32)
        L[:, 0] = sums.mean.reshape(-1, 3)[self.flat]
        ones = np.ones(m, np.int64)
        for k in range(1, record):
            total, _ = drain(sampler.add_samples(self.flat, k * ones, ones))
            L[:, k] = total[:, :3]
        job.release()
        # cumulative sums: cum[:, n] = the sum of samples 0..n-1
        self.cum = np.concatenate([np.zeros((m, 1, 3)), np.cumsum(L, axis=1, dtype=np.float64)], axis=1)
        L = L.astype(np.float64)
        self.cumsq = np.concatenate([np.zeros((m, 1)), np.cumsum(np.sum(L * L, axis=2), axis=1)], axis=1)
        self.row = np.full(width * height, -1, np.int64)
        self.row[self.flat] = np.arange(m)

    def errors(self, ref: np.ndarray) -> np.ndarray:
        """(pixels, record + 1): each flagged pixel's error (largest channel)
        against `ref` after n samples, n = 0..record (column 0 unused)."""
        n = np.arange(1, self.record + 1)
        r = ref.reshape(-1, 3)[self.flat]
        out = np.zeros((len(self.flat), self.record + 1))
        out[:, 1:] = np.abs(self.cum[:, 1:] / n[None, :, None] - r[:, None, :]).max(axis=2)
        return out


class ReplaySampler:
    """AdaptiveSampler's passes answered from a Recording (sums of recorded
    samples in float64, where the GPU adds float32)."""

    def __init__(self, rec: Recording):
        self.rec = rec

    def first_pass(self, offset=(0.5, 0.5)):
        return self.rec.first
        yield

    def corner_pass(self):
        return self.rec.corners
        yield

    def set_offsets(self, offsets):
        if not np.array_equal(offsets, self.rec.offsets[:len(offsets)]):
            raise ValueError("the replay was recorded with other sample offsets")

    def add_samples(self, pixels, first, count, cost=None):
        rows = self.rec.row[pixels]
        if (rows < 0).any() or (first + count > self.rec.record).any():
            raise ValueError("a sample that was not recorded")
        total = self.rec.cum[rows, first + count] - self.rec.cum[rows, first]
        square = self.rec.cumsq[rows, first + count] - self.rec.cumsq[rows, first]
        return np.concatenate([total, count[:, None].astype(np.float64)], axis=1), square
        yield

    def release(self):
        pass


class ExpectedErrorRender(AdaptiveRender):
    """The adaptive render ranked by each pixel's expected error."""

    expected: np.ndarray        # (pixels, RECORD + 1), rows as in the recording
    row: np.ndarray

    def estimate(self, flat, sums: Sums, prev):
        n = np.rint(sums.total[:, 3]).astype(np.int64)
        return self.expected[self.row[flat], np.minimum(n, RECORD)]


def rmse(image, ref) -> float:
    return float(np.sqrt(np.mean((np.asarray(image, np.float64) - ref) ** 2)))


def image_of(rec: Recording, count: np.ndarray) -> np.ndarray:
    """The image with each flagged pixel at count[k] samples (others: 1)."""
    img = rec.first[0].mean.reshape(-1, 3).copy()
    m = np.arange(len(rec.flat))
    img[rec.flat] = rec.cum[m, count] / count[:, None]
    return img.reshape(rec.height, rec.width, 3)


def greedy(rec: Recording, expected: np.ndarray, budget: int) -> np.ndarray:
    """Counts from doubling, one pixel at a time, the one whose expected
    error^2 / n is largest, from FIRST_ROUND for every flagged pixel, until
    `budget` rays per pixel (centres and corners included) are spent."""
    m = len(rec.flat)
    n = np.full(m, FIRST_ROUND, np.int64)
    w, h = rec.width, rec.height
    left = budget * w * h - w * h - (w + 1) * (h + 1) - (FIRST_ROUND - 1) * m
    heap = [(-expected[k, n[k]] ** 2 / n[k], k) for k in range(m)]
    heapq.heapify(heap)
    while heap:
        _, k = heapq.heappop(heap)
        if n[k] > left:
            continue
        left -= n[k]
        n[k] *= 2
        if 2 * n[k] <= rec.record:
            heapq.heappush(heap, (-expected[k, n[k]] ** 2 / n[k], k))
    return n


def reach(budgets, errors, target) -> float | None:
    """Rays per pixel at which `errors` (falling with budget) reaches
    `target`, log-log interpolated; None outside the range."""
    for (b0, e0), (b1, e1) in zip(zip(budgets, errors), list(zip(budgets, errors))[1:]):
        if e0 >= target >= e1 and e0 > e1:
            return float(np.exp(np.log(b0) + (np.log(e0) - np.log(target)) / (np.log(e0) - np.log(e1))
                                * (np.log(b1) - np.log(b0))))
    return None


def measure(names: list[str]) -> list[dict]:
    import moderngl

    from viewer.gpu.renderer import Renderer

    ctx = moderngl.create_standalone_context(backend="egl")
    rows = []
    for name in names:
        scene = load_scene(name)
        path = avu.own_reference_path(name)
        if not path.exists():
            raise SystemExit(f"no reference {path}: run python tools/adaptive_vs_uniform.py ref {name}")
        ref = np.load(path)
        r = Renderer(ctx, scene)
        AdaptiveSampler(r, W, H).compile()
        u64 = rmse(r.render(W, H, 64, seed=bench.RENDER_SEED), ref)
        rec = Recording(r, bench.RENDER_SEED)
        sq = np.zeros((len(rec.flat), RECORD + 1))
        for s in SEEDS:
            other = Recording(r, s)
            if not np.array_equal(other.flat, rec.flat):
                raise RuntimeError("the flags depend on the seed")
            sq += other.errors(ref) ** 2
            del other
        expected = np.sqrt(sq / len(SEEDS))
        table = {"real": [], "estimate": [], "expected": [], "greedy": []}
        for b in BUDGETS:
            table["real"].append(rmse(render_adaptive(r, W, H, b, seed=bench.RENDER_SEED, footprint=False).image, ref))
            job = AdaptiveRender(r, W, H, b, seed=bench.RENDER_SEED, sampler=ReplaySampler(rec))
            table["estimate"].append(rmse(job.run().image, ref))
            job = ExpectedErrorRender(r, W, H, b, seed=bench.RENDER_SEED, sampler=ReplaySampler(rec))
            job.expected, job.row = expected, rec.row
            table["expected"].append(rmse(job.run().image, ref))
            table["greedy"].append(rmse(image_of(rec, greedy(rec, expected, b)), ref))
        r.release()
        print(f"\n{name}: {len(rec.flat)} of {W * H} pixels flagged ({len(rec.flat) / (W * H):.0%}); "
              f"uniform 64 samples: RMSE {u64:.3e}")
        print("| ranking | " + " | ".join(f"≤{b}" for b in BUDGETS) + " | rays/px for uniform 64's RMSE |")
        print("|---" * (len(BUDGETS) + 2) + "|")
        for kind, errs in table.items():
            at = reach(BUDGETS, errs, u64)
            print(f"| {kind} | " + " | ".join(f"{e:.2e}" for e in errs)
                  + f" | {'above ' + str(BUDGETS[-1]) if at is None else f'{at:.1f} ({at / 64:.2f}x)'} |")
            rows.append(dict(scene=name, ranking=kind, budgets=list(BUDGETS), rmse=errs, uniform64=u64,
                             flagged=len(rec.flat), rays_for_uniform64=at))
    return rows


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__.split("Usage")[1].split("::")[1], file=sys.stderr)
        return 2
    rows = measure(argv)
    avu.OUT.mkdir(parents=True, exist_ok=True)
    (avu.OUT / "bound.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
