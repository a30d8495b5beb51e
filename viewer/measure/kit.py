"""The measuring kit that the benchmark, its peer, the stress suite and the
max-error measurement share: the seeds and trace settings of renders and
references, the error metric, medians of timed renders, warm-up renders
that leave nothing to compile, and what identifies the machine.
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import statistics
import sys

import moderngl
import numpy as np

from ..base.imageio import to_display8
from ..base.version import __version__
from ..gpu.context import describe

#: The sample pattern of the renders measured (glassray render's default seed)
RENDER_SEED = 0
#: ... and of the references they are measured against: another pattern, so
#: that no render shares the reference's sample positions beyond the
#: always-centred first one
REFERENCE_SEED = 1
#: The references' trace settings: deeper than any setting measured (going to
#: depth 32 / 1e-6 changes the default scene's reference by 4e-4 RMSE, under
#: the reference's own sampling noise)
REFERENCE_MAX_DEPTH = 16
REFERENCE_MIN_WEIGHT = 1e-4


# ---------------------------------------------------------------- metrics


def image_errors(image, reference) -> dict[str, float]:
    """Error of ``image`` against ``reference`` (both (H, W, 3) linear RGB):
    ``rmse`` over all pixels and channels in linear space, ``frac_off`` the
    fraction of pixels with any channel more than 1/255 off after the spec's
    display encoding, ``max_abs`` the largest absolute linear difference."""
    a = np.asarray(image, dtype=np.float64)
    b = np.asarray(reference, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"image shape {a.shape} differs from the reference's {b.shape}")
    diff = a - b
    d8 = np.abs(to_display8(a).astype(np.int16) - to_display8(b).astype(np.int16)).max(axis=-1)
    return {"rmse": float(np.sqrt(np.mean(diff * diff))),
            "frac_off": float(np.mean(d8 > 1)),
            "max_abs": float(np.max(np.abs(diff))) if diff.size else 0.0}


def usable_cpus() -> int:
    """The CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


# ---------------------------------------------------------------- measuring


class Timings:
    """Median wall-clock and CPU time of the repeated renders in ``times`` and
    ``cpu_times`` (ms); ``t(clock)`` picks one (the bench and its peer)."""

    times: list[float]
    cpu_times: list[float]

    @property
    def time_ms(self) -> float:
        return statistics.median(self.times)

    @property
    def cpu_ms(self) -> float:
        return statistics.median(self.cpu_times)

    def t(self, clock: str) -> float:
        return self.cpu_ms if clock == "cpu" else self.time_ms


#: Culling variants a measuring Renderer keeps compiled (its
#: SUBSET_PROGRAMS): every one its settings draw, where the viewer keeps 16.
#: A timed render must not compile (see bench._Renderers).
SUBSET_PROGRAMS = 1024


#: warm_up's most renders of one setting: an image is drawn with at most
#: culling.MAX_VARIANTS (4) variants per kind of pass (uniform, footprint,
#: adaptive first and list passes), and a render compiles at least one of
#: each kind it draws
WARM_UP_RENDERS = 8


def warm_up(renderer, run):
    """run() until a render builds no shader program; returns the last
    result (the finished image: the earlier ones drew groups whose variant
    was not compiled yet with a superset, the same image to float rounding).
    A render compiles at most Renderer.COMPILES_PER_DRAW culling variants
    per draw, so one untimed render is not enough to keep the timed ones
    from compiling (a compile on llvmpipe takes up to a second); stops
    after WARM_UP_RENDERS renders whatever they built."""
    built = renderer.programs_built
    result = run()
    for _ in range(WARM_UP_RENDERS - 1):
        if renderer.programs_built == built:
            break
        built = renderer.programs_built
        result = run()
    return result


# ---------------------------------------------------------------- machine


def machine_info(ctx=None, backend: str | None = None) -> dict:
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    cpus_usable = usable_cpus()
    info = {
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "cpus_usable": cpus_usable,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "moderngl": moderngl.__version__,
        "glassray": __version__,
        "command": " ".join(["glassray", *sys.argv[1:]]) if sys.argv else "glassray bench",
    }
    if hasattr(os, "getloadavg"):
        info["load_average_start"] = [round(x, 2) for x in os.getloadavg()]
    if ctx is not None:
        info["gl"] = describe(ctx)
        info["gl_vendor"] = ctx.info.get("GL_VENDOR", "")
        info["gl_backend"] = backend
    return info
