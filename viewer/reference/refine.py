"""The refined reference: many samples exactly where a pixel needs them, so
that the reference is cleaner than the renderers it judges, at a fraction of
the cost of that many samples everywhere; and its process-pool driver.

Invariants: every pixel first takes samples 0 .. ``samples`` - 1 of the
shared pattern (``base.sampling.sample_offsets(max_samples, seed)``); a
pixel whose samples all lie within ``tolerance`` of each other (after the
exposure) keeps their mean, :func:`.trace.render_reference` with
``samples`` there, and every other pixel takes all ``max_samples``, the
reference with ``max_samples`` there (both to rounding: the sums run in
another order).  The result does not depend on ``workers``: the work is
cut into the same parts, traced by the same code and gathered in the same
order, in this process or in spawned ones (whose Ctrl-C is the caller's).
"""

from __future__ import annotations

import concurrent.futures
import multiprocessing
import signal
import time

import numpy as np

from ..base.sampling import sample_offsets
from ..scene.model import Scene
from .camera import pixel_rays
from .trace import trace

__all__ = ["render_reference_refined", "REFINE_TASK_RAYS"]

_INF = np.inf


#: rays per call of the tracer in :func:`render_reference_refined`'s tasks
REFINE_TASK_RAYS = 1 << 19


def _sample_stats(scene: Scene, width: int, height: int, pixels, offsets):
    """Per pixel of ``pixels``: the sum, minimum and maximum (each (P, 3), no
    exposure) of the radiance at ``offsets``.  Module level, so that a worker
    process can run it."""
    pixels = np.asarray(pixels, dtype=np.int64)
    offsets = np.asarray(offsets, dtype=np.float64).reshape(-1, 2)
    P = len(pixels)
    total = np.zeros((P, 3))
    lo = np.full((P, 3), _INF)
    hi = np.full((P, 3), -_INF)
    per = max(1, min(len(offsets), REFINE_TASK_RAYS // max(P, 1)))
    for k0 in range(0, len(offsets), per):
        offs = offsets[k0:k0 + per]
        o, d = pixel_rays(scene, width, height, pixels, offs)
        L = trace(scene, o, d).reshape(P, len(offs), 3)
        total += L.sum(axis=1)
        lo = np.minimum(lo, L.min(axis=1))
        hi = np.maximum(hi, L.max(axis=1))
    return total, lo, hi


def _ignore_sigint() -> None:
    """A worker's start: Ctrl-C reaches the whole process group, and only the
    caller (its ``check``) should act on it; a worker's KeyboardInterrupt
    came back as the result of its task and stopped the caller a second
    time (two "interrupted" messages)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def render_reference_refined(scene: Scene, width: int, height: int, samples: int, max_samples: int,
                             tolerance: float, seed: int = 0, workers: int = 1,
                             log=None, check=None) -> tuple[np.ndarray, np.ndarray]:
    """A reference with many samples where a pixel needs them: (image (H, W,
    3) as :func:`render_reference`, samples per pixel (H, W)).

    Every pixel takes ``samples`` samples of the shared pattern.  A pixel
    whose samples all lie within ``tolerance`` of each other (after the
    exposure) keeps their mean: it is :func:`render_reference` there.  Every
    other pixel (an edge, a checker finer than the pixel) takes
    ``max_samples``: it is ``render_reference(..., max_samples)`` there.
    Why it matters: a 512-sample reference of ``whitted-exact`` at 320x180
    is itself off by RMSE 0.0027 (two seeds differ by 0.0038), about what
    the renderers it judges reach, and nearly all of that is in the third
    of its pixels that hold an edge.

    No pixel stops early on an error estimate from its own samples: samples
    0 .. n - 1 and n .. 2n - 1 are both nets of the Sobol' points and err
    alike (measured: pixels stopped when the two halves agreed to 5e-4 were
    off by RMS 0.0063).

    ``workers`` > 1 traces in that many processes.  ``log(message)`` hears
    of the progress, ``check()`` runs while waiting (Ctrl-C)."""
    samples, max_samples = int(samples), int(max_samples)
    if samples < 1 or max_samples < samples:
        raise ValueError("need 1 <= samples <= max_samples")
    offs = sample_offsets(max_samples, seed)
    npix = width * height
    exposure = scene.render.exposure
    pool = None
    if workers > 1:
        # processes: the tracer is many small NumPy calls, which threads
        # run one at a time (two threads were no faster than one); spawned,
        # not forked, as the caller may hold an OpenGL context and its threads;
        # looked up on its module when called, where a test may replace it
        pool = concurrent.futures.ProcessPoolExecutor(max_workers=int(workers),
                                                      mp_context=multiprocessing.get_context("spawn"),
                                                      initializer=_ignore_sigint)

    def run(pixels, block, what):
        """(sum, min, max) over ``block`` of the samples of every pixel."""
        per = max(1, REFINE_TASK_RAYS // len(block))
        parts = [pixels[p0:p0 + per] for p0 in range(0, len(pixels), per)]
        t0 = last = time.perf_counter()
        res = []

        def tell(k):
            nonlocal last
            now = time.perf_counter()
            if log is not None and now - last > 20.0 and k < len(parts):
                last = now
                log(f"  reference, {what}: {k}/{len(parts)} parts, {now - t0:.0f} s, "
                    f"about {(now - t0) / k * (len(parts) - k):.0f} s left")

        if pool is None:
            for part in parts:
                if check is not None:
                    check()
                res.append(_sample_stats(scene, width, height, part, block))
                tell(len(res))
        else:
            futs = [pool.submit(_sample_stats, scene, width, height, part, block) for part in parts]
            for f in futs:
                while True:
                    if check is not None:
                        check()
                    try:
                        res.append(f.result(timeout=0.25))
                        break
                    except TimeoutError:
                        continue
                tell(len(res))
        return tuple(np.concatenate([r[k] for r in res]) for k in range(3))

    try:
        everyone = np.arange(npix)
        acc, lo, hi = run(everyone, offs[:samples], f"{samples} samples a pixel")
        count = np.full(npix, samples, dtype=np.int64)
        edges = everyone[(hi - lo).max(axis=1) * exposure > tolerance]
        if edges.size and max_samples > samples:
            if log is not None:
                log(f"  reference: {edges.size} of {npix} pixels to {max_samples} samples")
            more, _, _ = run(edges, offs[samples:], f"{edges.size} pixels to {max_samples} samples")
            acc[edges] += more
            count[edges] = max_samples
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    img = (acc / count[:, None]).reshape(height, width, 3) * exposure
    return img, count.reshape(height, width)
