"""Converged reference images, cached in the output folder: the float64
NumPy tracer (``viewer.reference``) at the references' trace settings and
seed, optionally refined where its samples disagree; a GPU render where
that tracer is not importable.  Cached by scene content, size, samples and
the content of the code that draws them (REFERENCE_CODE).
"""

from __future__ import annotations

import hashlib
import io
import time
from pathlib import Path

import numpy as np

from ..base import interrupt
from ..base.sampling import sample_offsets
from ..gpu.renderer import Renderer
from ..reference.camera import camera_rays
from ..reference.refine import render_reference_refined
from ..reference.trace import trace
from ..scene.load import with_overrides
from .digests import code_digest, scene_digest, shader_digest
from .kit import REFERENCE_MAX_DEPTH, REFERENCE_MIN_WEIGHT, REFERENCE_SEED, usable_cpus
from .outputs import write_output

#: --reference-refine: a pixel whose reference samples all lie within this
#: (linear, after the exposure) keeps them; any other takes the refined count
REFINE_TOLERANCE = 2.5e-4

#: What decides a reference image's pixels besides the scene and the
#: settings its file name carries: the float64 tracer and what it imports
#: (the sample pattern, the scene model), this module, which drives it, and
#: the kit's reference settings (seed, max depth, min weight); walked from
#: the installed files, so a module added to or moved between these parts
#: is in the key without a change here (tests/measure/test_cache_identity.py
#: checks that every module they import is in them)
REFERENCE_CODE = ("reference", "scene", "base", "measure/reference_cache.py", "measure/kit.py")
#: ... and of the GPU fallback (the renderer and its shaders)
FALLBACK_CODE = ("gpu", "adaptive", "scene", "base", "measure/reference_cache.py", "measure/kit.py")


def reference_source_digest(package: Path | None = None) -> str:
    """The code that decides a reference's pixels (REFERENCE_CODE; the
    GPU fallback's: FALLBACK_CODE and the shaders), from the package's files."""
    if reference_kind() == "float64":
        return code_digest(REFERENCE_CODE, package)
    both = f"{code_digest(FALLBACK_CODE, package)}-{shader_digest()}"
    return "gpu-" + hashlib.sha256(both.encode()).hexdigest()[:12]


def reference_scene(scene):
    """The scene with the references' trace settings."""
    return with_overrides(scene, max_depth=REFERENCE_MAX_DEPTH, min_weight=REFERENCE_MIN_WEIGHT)


def effective_refine(samples: int, refine: int | None) -> int:
    """The refined count a reference of `samples` samples really takes: 0
    (none) unless `refine` is above `samples` and the float64 tracer is
    there (the GPU fallback is never refined)."""
    refine = int(refine or 0)
    return refine if reference_kind() == "float64" and refine > samples else 0


def reference_text(samples: int, refine: int) -> str:
    """How a reference is sampled, for logs and reports."""
    return f"{samples} samples" + (f", {refine} where they disagree by more than {REFINE_TOLERANCE:g}"
                                   if refine else "")


def reference_kind() -> str:
    """What draws the references: "float64", the NumPy tracer of
    viewer.reference (imported above, so always here in this package); the
    GPU fallback ("gpu") is what a copy of the measuring code without that
    tracer would use, and the tests take it by replacing this function."""
    return "float64"


def reference_image(scene, stem: str, width: int, height: int, samples: int, cache_dir: Path | None,
                    ctx=None, log=None, refine: int = 0) -> tuple[np.ndarray, str, bool]:
    """The converged reference image (H, W, 3) float64, its kind ("float64" or
    "gpu") and whether it came from the cache.  ``refine`` > ``samples``:
    pixels whose samples disagree by more than REFINE_TOLERANCE take
    ``refine`` samples (:func:`viewer.reference.render_reference_refined`;
    float64 only)."""
    kind = reference_kind()
    ref_scene = reference_scene(scene)
    refine = effective_refine(samples, refine)
    spp = f"s{samples}" + (f"r{refine}t{REFINE_TOLERANCE:g}" if refine else "")
    name = (f"ref-{stem}-{scene_digest(ref_scene)}-{width}x{height}-{spp}-seed{REFERENCE_SEED}"
            f"-d{REFERENCE_MAX_DEPTH}-w{REFERENCE_MIN_WEIGHT:g}-{kind}-{reference_source_digest()}.npy")
    path = cache_dir / name if cache_dir is not None else None
    if path is not None and path.is_file():
        try:
            img = np.load(path)
            if img.shape == (height, width, 3):
                return img.astype(np.float64), kind, True
        except (OSError, ValueError):
            pass
    t0 = time.perf_counter()
    if kind == "float64" and refine:
        img, _ = render_reference_refined(ref_scene, width, height, samples, refine, REFINE_TOLERANCE,
                                          seed=REFERENCE_SEED, workers=usable_cpus(), log=log,
                                          check=interrupt.check)
    elif kind == "float64":
        acc = np.zeros((height * width, 3))
        offsets = sample_offsets(samples, REFERENCE_SEED)
        last = t0
        for k, off in enumerate(offsets):
            interrupt.check()                         # Ctrl-C between samples (viewer/base/interrupt.py)
            o, d = camera_rays(ref_scene, width, height, off)
            acc += trace(ref_scene, o.reshape(-1, 3), d.reshape(-1, 3))
            now = time.perf_counter()
            if log is not None and now - last > 20.0 and k + 1 < samples:
                el, last = now - t0, now
                log(f"  reference {k + 1}/{samples} samples, {el:.0f} s, about {el / (k + 1) * (samples - k - 1):.0f} s left")
        img = acc.reshape(height, width, 3) / samples * ref_scene.render.exposure
    else:
        r = Renderer(ctx, ref_scene, eager=False)
        try:
            img = r.render(width, height, samples, REFERENCE_SEED).astype(np.float64)
        finally:
            r.release()
    if path is not None:
        buf = io.BytesIO()
        np.save(buf, img)
        write_output(path, buf.getvalue())
    return img, kind, False
