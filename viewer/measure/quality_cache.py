"""The max-error measurements' cache: one JSON file (and the reference as
.npy) per key in ``$XDG_CACHE_HOME/glassray/quality``; the key is the
scene's content less the settings being chosen, the machine, the measured
pixels, and the method (the shaders, the code that decides pixels and
times: MEASURED_CODE, the measuring constants).
"""

from __future__ import annotations

import datetime as _dt
import errno
import hashlib
import io
import json
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..base.files import write_atomic
from ..scene.load import with_overrides
from .digests import code_digest, scene_digest, shader_digest
from .kit import REFERENCE_MAX_DEPTH, REFERENCE_MIN_WEIGHT, REFERENCE_SEED, machine_info
from .quality_grid import Candidate, Layout, Measured
from .quality_measure import FULL_TIMED_PASSES, REFERENCE_SAMPLES, RENDER_SEED

#: Bumped when the measuring method changes (old cache files are then ignored).
METHOD_VERSION = 5

_WARNED: set[str] = set()


def _warn_once(key: str, text: str) -> None:
    if key not in _WARNED:
        _WARNED.add(key)
        print(f"glassray: {text}", file=sys.stderr, flush=True)


def _whole(v) -> int:
    """A cache file's integer: a JSON integer (not a boolean, a float or a string)."""
    if isinstance(v, bool) or not isinstance(v, int):
        raise TypeError(f"expected an integer, got {v!r}")
    return v


def _real(v) -> float:
    """A cache file's number: a JSON integer or float (NaN and inf as Python
    writes them), not a boolean or a string."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise TypeError(f"expected a number, got {v!r}")
    return float(v)


# ---------------------------------------------------------------- keys and the cache


def error_scene(scene):
    """The scene with the settings being chosen (samples, max depth, min
    weight) set to fixed values: what the error depends on besides them."""
    return with_overrides(scene, samples=1, max_depth=1, min_weight=0.0)


def scene_key(scene) -> str:
    return scene_digest(error_scene(scene))


#: The parts of this package whose code decides a candidate's pixels or its
#: time (how the scene becomes uniforms and defines, the culling, the
#: sample pattern and footprints, the draws, this measuring method), walked
#: from the installed files (viewer/measure/digests.py): a new version of
#: any file in them measures again, like a change of the shaders.  (Not the
#: whole package: an edit of the viewer's window code changes no
#: measurement.)  tests/measure/test_cache_identity.py checks that every
#: module the measurement imports is in them.
MEASURED_CODE = ("gpu", "adaptive", "scene", "base", "measure/quality*.py", "measure/kit.py")


def _code_digest(package: Path | None = None) -> str:
    """The digest of :data:`MEASURED_CODE` in ``package`` (default: the
    installed package's folder)."""
    return code_digest(MEASURED_CODE, package)


def machine(ctx) -> dict:
    """What identifies the machine for timings: GL renderer and version (the
    driver's release: llvmpipe names only its LLVM, and Mesa 25's draws the
    default scene 2-3x faster than 22.3's), CPU model, usable CPUs."""
    info = machine_info()
    return {"gl_renderer": ctx.info.get("GL_RENDERER", ""), "gl_version": ctx.info.get("GL_VERSION", ""),
            "cpu": info.get("cpu", ""), "cpus": info.get("cpus_usable")}


def method() -> dict:
    return {"version": METHOD_VERSION, "reference_samples": REFERENCE_SAMPLES, "reference_seed": REFERENCE_SEED,
            "reference_max_depth": REFERENCE_MAX_DEPTH, "reference_min_weight": REFERENCE_MIN_WEIGHT,
            "render_seed": RENDER_SEED, "timed_passes": FULL_TIMED_PASSES, "shaders": shader_digest(),
            "code": _code_digest()}


def cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or ""
    root = Path(base) if base and Path(base).is_absolute() else Path.home() / ".cache"
    return root / "glassray" / "quality"


@dataclass
class Key:
    scene: str
    machine: dict
    layout: Layout
    method: dict
    name: str = "scene"

    def as_dict(self) -> dict:
        lay = self.layout
        return {"scene": self.scene, "machine": self.machine, "size": list(lay.full),
                "tiles": [list(t) for t in lay.tiles], "timing_size": list(lay.timing_size), "method": self.method}

    def stem(self) -> str:
        h = hashlib.sha256(json.dumps(self.as_dict(), sort_keys=True).encode()).hexdigest()[:16]
        slug = "".join(c if c.isalnum() or c in "-_" else "-" for c in self.name.lower())[:32].strip("-")
        W, H = self.layout.full
        return f"{slug or 'scene'}-{W}x{H}-{h}"


def make_key(ctx, scene, lay: Layout) -> Key:
    return Key(scene_key(scene), machine(ctx), lay, method(), scene.name)


class Cache:
    """One JSON file (and the reference .npy) per key."""

    def __init__(self, key: Key, root: Path | None = None):
        self.key = key
        self.root = cache_dir() if root is None else Path(root)
        self.path = self.root / f"{key.stem()}.json"
        self.ref_path = self.root / f"{key.stem()}.ref.npy"

    def load(self) -> dict[str, Measured]:
        """The measurements stored for this key ({} when there are none, or
        when the file is unreadable: then warn once)."""
        try:
            text = self.path.read_bytes()   # decoded below: bytes that are not UTF-8 are a corrupt file
        except FileNotFoundError:
            return {}
        except OSError as e:
            _warn_once(str(self.path), f"quality cache {self.path} is unreadable ({e.strerror or e}); "
                                       "measuring again")
            return {}
        try:
            doc = json.loads(text.decode("utf-8"))
            if doc.get("key") != json.loads(json.dumps(self.key.as_dict())):
                raise ValueError("stored for another key")
            out = {}
            for k, m in doc["measured"].items():
                c = Candidate(_whole(m["samples"]), _whole(m["max_depth"]), _real(m["min_weight"]))
                meas = Measured(c, _real(m["time_ms"]), _real(m["rmse"]), _real(m.get("frac_off", 0.0)),
                                _real(m.get("rmse_se", 0.0)))
                # the ranges the program writes (rmse inf: every measured pixel cut)
                if (c.key() != k or c.samples < 1 or not 1 <= c.max_depth <= 64 or not 0 <= c.min_weight <= 1
                        or not (math.isfinite(meas.time_ms) and meas.time_ms >= 0 and meas.rmse >= 0)
                        or not 0 <= meas.frac_off <= 1 or not 0 <= meas.rmse_se < math.inf):
                    raise ValueError(f"bad entry {k!r}")
                out[k] = meas
            ref = doc.get("reference", {})
            noise = _real(ref.get("noise_rmse", float("nan")))
            cut = _whole(ref.get("cut_pixels", 0))
            if not (math.isnan(noise) or (math.isfinite(noise) and noise >= 0)):
                raise ValueError(f"bad reference noise {noise!r}")
            if not 0 <= cut <= self.key.layout.pixels:
                raise ValueError(f"bad cut pixel count {cut!r}")
            self.noise, self.cut_pixels = noise, cut
            return out
        except (ValueError, KeyError, TypeError, AttributeError) as e:
            _warn_once(str(self.path), f"quality cache {self.path} is corrupt ({type(e).__name__}: {e}); "
                                       "measuring again")
            return {}

    def load_reference(self) -> np.ndarray | None:
        try:
            ref = np.load(self.ref_path)
        except (OSError, ValueError, EOFError):   # EOFError: an empty (truncated) file
            return None
        w, h = self.key.layout.size
        # an .npz archive or an array of strings is no reference either; NaN
        # marks a pixel left out (the driver's loop limit cut its tree: see
        # Measurement._run), an infinite or negative radiance is corrupt
        if (not isinstance(ref, np.ndarray) or ref.dtype.kind not in "fiu" or ref.shape != (h, w, 3)
                or not np.all(np.isnan(ref) | (np.isfinite(ref) & (ref >= 0)))):
            return None
        return ref.astype(np.float64)

    def save(self, measured: dict[str, Measured], noise: float, reference: np.ndarray | None = None,
             cut_pixels: int = 0) -> bool:
        doc = {"format": 1, "scene_name": self.key.name, "key": self.key.as_dict(),
               "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
               "reference": {"noise_rmse": noise, "cut_pixels": cut_pixels},
               "measured": {k: {"samples": m.candidate.samples, "max_depth": m.candidate.max_depth,
                                "min_weight": m.candidate.min_weight, "time_ms": m.time_ms,
                                "rmse": m.rmse, "frac_off": m.frac_off, "rmse_se": m.rmse_se}
                            for k, m in sorted(measured.items())}}
        try:
            if self.root.exists() and not self.root.is_dir():
                raise NotADirectoryError(errno.ENOTDIR, "it is a file, not a folder")
            self.root.mkdir(parents=True, exist_ok=True)
            if reference is not None:
                buf = io.BytesIO()
                np.save(buf, reference.astype(np.float32))
                write_atomic(self.ref_path, buf.getvalue())
            write_atomic(self.path, (json.dumps(doc, indent=1) + "\n").encode("utf-8"))
        except OSError as e:
            _warn_once("save:" + str(self.root), f"quality cache not saved in {self.root}: {e.strerror or e}")
            return False
        return True
