"""Quality by error budget: the fastest measured settings whose error stays
within a given RMSE (``glassray render --max-error E``, the viewer's "max
error" setting).

For a scene and an image size, a grid of candidate settings (samples per
pixel :data:`SAMPLES` x (max depth, min weight) pairs :data:`TRACE`, 20 in
all) is measured once on this machine, on about :data:`MEASURE_PIXELS`
pixels:

* **error**: RMSE over all measured pixels and channels in linear space
  against a reference: the metric of ``glassray bench``
  (:func:`viewer.bench.image_errors`).  The pixels are :data:`GRID` x
  :data:`GRID` small tiles of the real image, one at a seeded random place in
  each cell of a grid over it (the shader is given camera vectors that make
  a small framebuffer show exactly those pixels of the W x H image), so the
  error is the error at the real size: a scaled-down picture would count
  edges, where the sampling error lives, many times over.  The candidates
  take the samples ``glassray render`` takes (Renderer.render): one sample
  is the centred point sample; from two samples on, on a scene with a
  checkered plane, footprint samples (shaders/lib/footprint.glsl) with the
  full image's footprint mask for the measured pixels
  (:meth:`Measurement._footprint_mask`), so the checker's aliasing, which
  render's footprint samples remove, is not counted.  (Measured with point
  samples, glass-sphere at 160x90 gave 16 samples 0.0124 where the render's
  error was 0.0049.)  Where the tiles are a part of the image, a control
  variate takes out most of their sampling error: the error max depth and
  min weight leave (truncation: what a tree cut shallower misses) lives in
  a few pixels (on the default scene at 640x360, 1% of the pixels hold
  70% of the squared error), which a sample of tiles meets by chance (over
  300 layouts the 4-sample depth-6 RMSE measured 0.008 to 0.023, 10th to
  90th percentile, for a whole image's 0.0172).  So each (max depth, min weight) and the reference's
  are also drawn with one centred sample over the whole image, and a
  candidate's mean squared error is the mosaic's minus the mosaic's part
  of the centred samples' squared difference plus the whole image's
  (:meth:`Measurement._centre_full`): over the same layouts 0.0164 to
  0.0176 (10th to 90th percentile).  The pick holds the RMSE plus its standard error (the tiles'
  spread of what is left: :func:`tile_standard_error`) against the budget.
* **reference**: the scene's own shader with max depth 16 and min weight
  1e-4 (the bench's reference trace settings; going deeper changes the
  default scene by about 4e-4 RMSE) and :data:`REFERENCE_SAMPLES` samples,
  footprint samples as above where the scene has a checkered plane (the
  same limit as point samples, the box-filtered pixel, with far less noise
  on the checker): the mean of two independent stratified patterns of half
  as many (seeds 1 and 2; the candidates use seed 0, as ``glassray render``
  does), whose difference estimates the reference's own noise (``noise`` =
  RMSE(A - B) / 2, reported).  Not min weight 0: on the glass of water it
  is ten times slower (4.6 s against 0.44 s a sample at 160x90 on llvmpipe)
  for a change far below that noise.  Not the float64 NumPy tracer
  (``bench.reference_image``): the GPU already agrees with it
  (tests/test_gpu_vs_reference.py) and it is one to two orders of magnitude
  slower; what is measured here is convergence in samples, depth and weight.
  Measured errors include the reference's noise (they are not corrected
  for it: the estimate above is low where the two patterns' errors
  correlate, and at 64 samples the correction moved the errors by less than
  the mosaic's own sampling error), so a budget below it cannot be resolved.
* **time**: the whole picture, at its own size up to
  :data:`FULL_TIMING_PIXELS` (a warm-up pass then :data:`FULL_TIMED_PASSES`
  timed passes of one sample), larger ones scaled down to about that many
  pixels (its cost per pixel is the full image's: the mean rays per pixel
  agree), each finished on the GPU; a candidate's time is (the median pass
  x its samples + one read-back of the picture) x (full pixels / timed
  pixels): an estimate of one W x H frame as ``glassray render --timing``
  measures it.  (Scaled down further, a pass's fixed cost was scaled up
  with the pixels: the default scene at 640x360 timed at 160x90 was
  estimated 20-40% slow, at 1920x1080 1.6-2.6x.)  A candidate
  that takes footprint samples is timed with them, and with its picture's
  mask made once (:meth:`Measurement._timed_footprint`).

The measurements are cached as JSON (the reference as .npy beside it) in
``$XDG_CACHE_HOME/glassray/quality`` (default ``~/.cache/glassray/quality``),
one file per key: the scene's content less the three settings being chosen
(camera and lights included: what is seen decides the error), the machine
(GL renderer, CPU model, usable CPUs), the image size, the shader sources,
the Python modules that decide pixels and times (:data:`CODE_MODULES`) and
the measuring method.  Files are written atomically; an unreadable or
corrupt one is measured again, with one warning.

Explicit settings fix their value: ``--samples 4 --max-error E`` chooses among
the candidates with 4 samples (a value off the grid is measured and added to
the cache).  When no candidate meets E, the most accurate one is used and the
line says so (exit 0: a budget is a request, not a contract).
"""

from __future__ import annotations

import errno
import hashlib
import json
import math
import os
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

#: Candidate samples per pixel.
SAMPLES = (1, 2, 4, 8, 16)
#: Candidate (max depth, min weight) pairs, cheapest first.
TRACE = ((2, 0.01), (4, 0.003), (6, 0.001), (10, 0.0001))
#: Pixels measured: a GRID x GRID mosaic of tiles of the real image, about
#: this many pixels in all (a smaller image is measured whole).
MEASURE_PIXELS = 160 * 90
GRID = 8
#: Reference: samples (seed and trace settings are the bench's).  64, not 32:
#: at 32 (two patterns of 16) its own error on glass-sphere at 160x90 was
#: 0.0042, close to a 16-sample render's 0.0050, and 16 samples measured 0.0074.
REFERENCE_SAMPLES = 64
#: Pixels a band of a whole-image pass of the truncation control variate
#: traces at most (Measurement._centre_full).
FULL_BAND_PIXELS = 1280 * 48
#: Images of at most this many pixels are timed at their own size, larger
#: ones scaled down to about this many; FULL_TIMED_PASSES timed passes.
FULL_TIMING_PIXELS = 1280 * 720
FULL_TIMED_PASSES = 3
#: Bumped when the measuring method changes (old cache files are then ignored).
METHOD_VERSION = 5
#: Seed of the candidates' sample pattern (glassray render's default).
RENDER_SEED = 0

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


# ---------------------------------------------------------------- candidates and the pick


@dataclass(frozen=True)
class Candidate:
    samples: int
    max_depth: int
    min_weight: float

    def key(self) -> str:
        return f"s{self.samples}-d{self.max_depth}-w{self.min_weight:g}"

    def describe(self) -> str:
        return f"samples {self.samples}, max depth {self.max_depth}, min weight {self.min_weight:g}"


@dataclass(frozen=True)
class Measured:
    candidate: Candidate
    time_ms: float  # at the measuring size
    rmse: float
    frac_off: float = 0.0  # fraction of pixels more than 1/255 off (display space)
    #: the standard error of `rmse` as an estimate of the whole image's (0
    #: where the image is measured whole): see tile_standard_error
    rmse_se: float = 0.0

    @property
    def bound(self) -> float:
        """What the pick holds against the budget: rmse plus one standard error."""
        return self.rmse + self.rmse_se


def candidate_grid(samples: int | None = None, max_depth: int | None = None,
                   min_weight: float | None = None) -> list[Candidate]:
    """The candidates; a given value replaces that axis of the grid."""
    ss = (samples,) if samples is not None else SAMPLES
    out: list[Candidate] = []
    for d, w in TRACE:
        c_d = max_depth if max_depth is not None else d
        c_w = min_weight if min_weight is not None else w
        for s in ss:
            c = Candidate(int(s), int(c_d), float(c_w))
            if c not in out:
                out.append(c)
    return out


def pick(measured: list[Measured], max_error: float) -> tuple[Measured, bool]:
    """The fastest measurement with rmse + its standard error <= max_error
    (ties: the smaller error) and True; when none meets it, the most
    accurate one (ties: the faster) and False.  A larger budget never gives
    a slower pick.  (Against rmse alone, the default scene's pick for 0.02
    at 640x360, 2 samples measured at 0.0183 +- 0.0026, had 0.0225 over the
    whole image.)"""
    if not measured:
        raise ValueError("no measured candidates")
    if not any(math.isfinite(m.rmse) for m in measured):
        # no error could be measured (every measured pixel's tree was cut by
        # the driver's loop limit): the slowest setting traces the most
        return max(measured, key=lambda m: (m.time_ms, -m.rmse, m.candidate.key())), False
    ok = [m for m in measured if m.bound <= max_error]
    if ok:
        return min(ok, key=lambda m: (m.time_ms, m.rmse, m.candidate.key())), True
    return min(measured, key=lambda m: (m.rmse, m.time_ms, m.candidate.key())), False


@dataclass(frozen=True)
class Layout:
    """Which pixels are measured.  Error: ``tiles`` (x, y, w, h) of the full
    image (x right, y down from the top row), packed in a mosaic of ``size``
    (tile k at ``packed[k]``, x, y from the top).  Time: the whole picture
    at ``timing_size`` (the full size, or about FULL_TIMING_PIXELS)."""
    full: tuple[int, int]
    size: tuple[int, int]
    tiles: tuple[tuple[int, int, int, int], ...]
    packed: tuple[tuple[int, int], ...]
    timing_size: tuple[int, int]

    @property
    def pixels(self) -> int:
        return self.size[0] * self.size[1]


def layout(width: int, height: int, pixels: int = MEASURE_PIXELS, grid: int = GRID) -> Layout:
    """The measured pixels of a width x height image: all of them when there
    are at most about ``pixels``; else grid x grid tiles, one in each cell of
    a grid x grid partition of the image at a seeded random place in it
    (stratified, so that no part of the picture is favoured), about
    ``pixels`` in all.  The tiles are pixels of the real image (the same
    footprint and rays), so their error is the error at the real size."""
    width, height = int(width), int(height)
    if width * height <= pixels * 1.25:
        return Layout((width, height), (width, height), ((0, 0, width, height),), ((0, 0),), (width, height))
    f = math.sqrt(pixels / (width * height))
    # timed at the real size up to FULL_TIMING_PIXELS, else at about that
    # many pixels: scaled down to the mosaic's size, a pass's fixed cost
    # (draw calls, the GPU's finish) was scaled up with the pixels, and the
    # default scene's estimates ran 20-40% high at 640x360, 1.6-2.6x at 1920x1080
    ft = math.sqrt(FULL_TIMING_PIXELS / (width * height))
    timing = ((width, height) if width * height <= FULL_TIMING_PIXELS
              else (max(1, round(width * ft)), max(1, round(height * ft))))
    tw = max(1, min(width // grid, round(width * f / grid)))
    th = max(1, min(height // grid, round(height * f / grid)))
    rng = np.random.default_rng(width * 100003 + height)
    tiles, packed = [], []
    for j in range(grid):
        for i in range(grid):
            cx0, cx1 = (i * width) // grid, ((i + 1) * width) // grid
            cy0, cy1 = (j * height) // grid, ((j + 1) * height) // grid
            x0 = cx0 + int(rng.integers(0, max(1, cx1 - cx0 - tw + 1)))
            y0 = cy0 + int(rng.integers(0, max(1, cy1 - cy0 - th + 1)))
            tiles.append((min(x0, width - tw), min(y0, height - th), tw, th))
            packed.append((i * tw, j * th))
    return Layout((width, height), (grid * tw, grid * th), tuple(tiles), tuple(packed), timing)


# ---------------------------------------------------------------- keys and the cache


def error_scene(scene):
    """The scene with the settings being chosen (samples, max depth, min
    weight) set to fixed values: what the error depends on besides them."""
    from ..scene.load import with_overrides

    return with_overrides(scene, samples=1, max_depth=1, min_weight=0.0)


def scene_key(scene) -> str:
    from .bench import _scene_digest

    return _scene_digest(error_scene(scene))


#: The modules of this package whose code decides a candidate's pixels or
#: its time (how the scene becomes uniforms and defines, the culling, the
#: sample pattern and footprints, the draws, this measuring method): a new
#: version of any of them measures again, like a change of the shaders.
#: (Not the whole package: an edit of the viewer's window code changes no
#: measurement.)
CODE_MODULES = ("gpu_scene", "renderer", "culling", "sampling", "shaders", "adaptive", "quality")


def _shader_digest() -> str:
    from ..gpu.shaders import shader_root

    h = hashlib.sha256()
    root = shader_root()
    for p in sorted(root.rglob("*")):
        if p.is_file() and p.suffix in (".frag", ".glsl", ".vert"):
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:12]


def _code_digest(package: Path | None = None) -> str:
    """The digest of :data:`CODE_MODULES`' sources in ``package`` (default:
    this package's folder)."""
    h = hashlib.sha256()
    here = Path(__file__).resolve().parent if package is None else Path(package)
    for name in CODE_MODULES:
        h.update(name.encode())
        h.update((here / f"{name}.py").read_bytes())
    return h.hexdigest()[:12]


def machine(ctx) -> dict:
    """What identifies the machine for timings: GL renderer and version (the
    driver's release: llvmpipe names only its LLVM, and Mesa 25's draws the
    default scene 2-3x faster than 22.3's), CPU model, usable CPUs."""
    from .bench import machine_info

    info = machine_info()
    return {"gl_renderer": ctx.info.get("GL_RENDERER", ""), "gl_version": ctx.info.get("GL_VERSION", ""),
            "cpu": info.get("cpu", ""), "cpus": info.get("cpus_usable")}


def method() -> dict:
    from .bench import REFERENCE_MAX_DEPTH, REFERENCE_MIN_WEIGHT, REFERENCE_SEED

    return {"version": METHOD_VERSION, "reference_samples": REFERENCE_SAMPLES, "reference_seed": REFERENCE_SEED,
            "reference_max_depth": REFERENCE_MAX_DEPTH, "reference_min_weight": REFERENCE_MIN_WEIGHT,
            "render_seed": RENDER_SEED, "timed_passes": FULL_TIMED_PASSES, "shaders": _shader_digest(),
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
        import datetime as _dt
        import io

        from ..base.files import write_atomic

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


# ---------------------------------------------------------------- measuring


def _window_renderer_class():
    from ..gpu.packing import camera_uniforms
    from ..gpu.renderer import Renderer

    class WindowRenderer(Renderer):
        """A Renderer whose framebuffer shows a window of a larger image:
        framebuffer pixel (i, j) (from the top left) traces the ray of pixel
        (i + dx, j + dy) of a ``full`` = (W, H) image.  The camera vectors are
        changed so that the shader's own formula gives exactly that ray."""
        full: tuple[int, int] | None = None
        shift: tuple[int, int] = (0, 0)
        #: the mosaic's footprint mask (RG32F, the framebuffer's size; see
        #: Measurement._footprint_mask): while set, the window's samples are
        #: footprint samples, as Renderer.render takes them
        footprint_mask = None

        @property
        def cull(self):   # a window's tiles are not the scene camera's: cull only the whole picture
            return self.full is None

        def bind(self, prog, width, height, offset):
            super().bind(prog, width, height, offset)
            if "loopProbe" in prog:
                prog["loopProbe"].value = 2   # the CUT_CHECK probe loop's count (shaders/trace.frag)
            if self.full is None:
                return
            W, H = self.full
            dx, dy = self.shift
            cam = camera_uniforms(self.scene, W, H)
            F, R, U = (np.array(cam[k], dtype=np.float64) for k in ("camForward", "camRight", "camUp"))
            values = {"camForward": F + R * ((width + 2 * dx) / W - 1) + U * (1 - (height + 2 * dy) / H),
                      "camRight": R * (width / W), "camUp": U * (height / H)}
            for name, v in values.items():
                if name in prog:
                    prog[name].value = tuple(float(x) for x in v)

        def draw_sample(self, width, height, offset, viewport=None, compile=True):
            # The mosaic's passes of a scene with glass mark a pixel whose tree
            # the driver's loop limit cut short with -inf (CUT_CHECK, as
            # Renderer.render does): the measurement leaves those pixels out
            # instead of taking a tree cut short for the converged image.
            # With a footprint mask set, the variant and the mask Renderer.render
            # draws its samples of two or more with (FOOTPRINT_SAMPLES).
            glass = bool(self._defines.get("HAS_DIELECTRIC"))
            if self.full is None or not (glass or self.footprint_mask is not None):
                return super().draw_sample(width, height, offset, viewport, compile)
            from ..adaptive.sampler import AdaptiveSampler

            mask = self.footprint_mask
            defines = {**({"CUT_CHECK": 1} if glass else {}),
                       **(AdaptiveSampler.FOOTPRINT_SAMPLES if mask is not None else {})}

            def bind_mask(prog):
                if mask is not None and "footprintMask" in prog:
                    mask.use(location=AdaptiveSampler.FOOTPRINT_UNIT)
                    prog["footprintMask"].value = AdaptiveSampler.FOOTPRINT_UNIT
            self.draw_groups([(self.variant(**defines), [(0, 0, width, height)])], width, height, offset,
                             viewport, bind_mask)

    return WindowRenderer


def tile_standard_error(image: np.ndarray, reference: np.ndarray, keep: np.ndarray, lay: Layout,
                        rmse: float, control: np.ndarray | None = None) -> float:
    """The standard error of a mosaic's RMSE as an estimate of the whole
    image's: the measured tiles are a stratified sample of the picture (one
    at a random place in each cell of a grid), and the error lives in few
    places (edges, the glass), so another draw of places would measure
    otherwise.  From the spread of the tiles' mean squared errors (as if
    drawn at random: stratification only makes it smaller) over sqrt(tiles),
    taken to the RMSE by the delta method (se(mse) / (2 rmse)).  0 where the
    image is measured whole (one tile) or nothing finite is left.
    `control` (per pixel): a term the estimate subtracts per pixel and adds
    back as its whole image's mean (the truncation control variate, see
    Measurement._run); the spread is then that of the difference."""
    if len(lay.tiles) < 2 or not (math.isfinite(rmse) and rmse > 0):
        return 0.0
    with np.errstate(invalid="ignore"):
        err2 = np.mean((image - reference) ** 2, axis=-1)
        if control is not None:
            err2 = err2 - control
    tiles = []
    for (_x0, _y0, tw, th), (px, py) in zip(lay.tiles, lay.packed):
        k = keep[py:py + th, px:px + tw]
        if k.any():
            tiles.append(float(np.mean(err2[py:py + th, px:px + tw][k])))
    if len(tiles) < 2:
        return 0.0
    se_mse = float(np.std(tiles, ddof=1)) / math.sqrt(len(tiles))
    return se_mse / (2.0 * rmse)


def _bands(full: tuple[int, int]) -> int:
    """Bands of rows a whole-image pass is drawn in: about
    FULL_BAND_PIXELS each (a viewer frame's worth of tracing on llvmpipe)."""
    W, H = full
    return max(1, min(H, -(-W * H // FULL_BAND_PIXELS)))


def _squared_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per pixel, the mean over channels of (a - b)^2; NaN where either was
    cut (-inf) or is not finite."""
    with np.errstate(invalid="ignore"):
        out = np.mean((a - b) ** 2, axis=-1)
    return np.where(np.isfinite(a).all(axis=-1) & np.isfinite(b).all(axis=-1), out, np.nan)


def _uncut(image: np.ndarray) -> np.ndarray:
    """(H, W) mask of the pixels no cut tree marked: a cut sample is -inf (or
    NaN where it met an inf) and stays so in sums (renderer.cut_marks; not
    "below 0": a pixel's mean of few footprint samples can be)."""
    from ..gpu.renderer import cut_marks

    return ~cut_marks(image).any(axis=-1)


class Measurement:
    """Renders the reference (unless given) and the candidates not measured
    yet on the pixels of ``layout``, one GPU pass per step, so that a window
    can keep handling input between steps (:meth:`step`).  Needs the GL
    context current; leaves blending off and the scissor unset after every
    step."""

    def __init__(self, ctx, scene, lay: Layout, candidates: list[Candidate],
                 known: dict[str, Measured] | None = None, reference: np.ndarray | None = None,
                 noise: float = float("nan"), cut_pixels: int = 0):
        self.ctx = ctx
        self.scene = scene
        self.layout = lay
        self.candidates = list(candidates)
        self.measured: dict[str, Measured] = dict(known or {})
        self.reference = reference
        self.noise = noise
        self.todo = [c for c in self.candidates if c.key() not in self.measured]
        by_trace: dict[tuple, list[int]] = {}
        for c in self.todo:
            by_trace.setdefault((c.max_depth, c.min_weight), []).append(c.samples)
        self._by_trace = by_trace
        self.total = ((REFERENCE_SAMPLES + 1 if reference is None else 0)
                      + sum(2 + 2 * FULL_TIMED_PASSES
                            + sum(ss) + 2 for ss in by_trace.values())
                      + (len(lay.tiles) if reference is None or any(c.samples > 1 for c in self.todo) else 0)
                      # the control variate's centred passes: the mosaic (1), the image's bands and its read
                      + (0 if len(lay.tiles) < 2 else (1 + len(by_trace)) * (2 + _bands(lay.full))))
        self.steps_done = 0
        self.done = not self.todo
        self.saved = False  # finish() wrote what was measured to the cache
        self.rendered_reference = False
        #: measured pixels left out of the errors: a tree in them (the
        #: reference's or a candidate's) was cut by the driver's loop limit
        self.cut_pixels = cut_pixels
        self._renderer = None
        self._fbo = self._timing_fbo = None
        self._footprint_tex = None   # the mosaic's footprint mask (_footprint_mask)
        self._full_fbo = None        # the whole image's centred samples (_centre_full)
        self._gen: Iterator[None] | None = None if self.done else self._run()

    @property
    def fraction(self) -> float:
        return 1.0 if self.done else min(1.0, self.steps_done / max(1, self.total))

    def step(self, budget_s: float = 0.0) -> bool:
        """Run passes until ``budget_s`` is spent (at least one); True when done."""
        if self.done:
            return True
        import moderngl

        from ..base import interrupt

        t0 = time.perf_counter()
        try:
            while True:
                try:
                    next(self._gen)
                except StopIteration:
                    self.done = True
                    self._release()
                    return True
                self.steps_done += 1
                # Ctrl-C between passes (viewer/interrupt.py): a first
                # measurement takes tens of seconds, and one that ran to its
                # end before the render's first check ignored Ctrl-C that long
                interrupt.check()
                if time.perf_counter() - t0 >= budget_s:
                    return False
        except BaseException:
            self.close()
            raise
        finally:
            self.ctx.disable(moderngl.BLEND)
            self.ctx.scissor = None

    def run(self, progress: Callable[[int, int], None] | None = None) -> None:
        while not self.step(0.0):
            if progress is not None:
                # (total counts no compile steps: held short of the end until the end)
                progress(min(self.steps_done, self.total - 1), self.total)
        if progress is not None:
            progress(self.total, self.total)

    def close(self) -> None:
        """Stop early (the window no longer needs it) and free the GL objects."""
        if self._gen is not None:
            self._gen.close()
            self._gen = None
        self._release()
        self.done = True

    def _release(self) -> None:
        if self._full_fbo is not None:
            self._full_fbo.release()
            self._full_fbo = None
        if self._footprint_tex is not None:
            self._footprint_tex.release()
            self._footprint_tex = None
        if self._renderer is not None:
            self._renderer.release()
            self._renderer = None
        for fbo in (self._fbo, self._timing_fbo):
            if fbo is not None:
                for att in (*(fbo.color_attachments or ()), fbo.depth_attachment):
                    if att is not None:
                        att.release()  # Framebuffer.release leaves them
                fbo.release()
        self._fbo = self._timing_fbo = None

    # --------------------------------------------------------- the work

    def _pass(self, offset) -> None:
        """One sample of every tile, added into the mosaic."""
        lay, r = self.layout, self._renderer
        W, H = lay.size
        for (x0, y0, tw, th), (px, py) in zip(lay.tiles, lay.packed):
            r.full = lay.full
            r.shift = (x0 - px, y0 - py)
            r.draw_sample(W, H, offset, (px, H - py - th, tw, th))

    def _accumulate(self, offsets) -> Iterator[None]:
        import moderngl

        ctx = self.ctx
        for off in offsets:
            self._fbo.use()
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = moderngl.ONE, moderngl.ONE
            ctx.blend_equation = moderngl.FUNC_ADD
            self._pass((float(off[0]), float(off[1])))
            ctx.finish()
            ctx.disable(moderngl.BLEND)
            yield

    def _footprint_mask(self) -> Iterator[None]:
        """The footprint mask of the mosaic (self._footprint_tex, None where
        the scene takes no footprint samples): for each measured pixel what
        Renderer.render's (AdaptiveSampler.direct_footprints of the W x H
        image) holds for it, the checkered plane its four corner rays meet
        first and its closed-form share.  Both are functions of the rays
        through the pixel's corners, which the window's camera vectors give
        for the tile's pixels (WindowRenderer.bind), so each tile's mask is
        direct_footprints run on a tile-sized window (equal to the full
        image's up to float32 rounding of the shares: checked in
        tests/test_quality_footprint.py); the tiles' masks are then placed
        as the mosaic places the tiles.  A yield per tile."""
        from ..adaptive.sampler import AdaptiveSampler, drain, footprint_default, footprint_planes

        r, lay = self._renderer, self.layout
        if not footprint_default(r.scene):
            return
        W, H = lay.size
        texels = np.zeros((H, W, 2), np.float32)      # rows bottom first, as the texture's
        tw, th = lay.tiles[0][2:]
        sampler = AdaptiveSampler(r, tw, th, footprint=True)
        try:
            for (x0, y0, tw, th), (px, py) in zip(lay.tiles, lay.packed):
                r.full, r.shift = lay.full, (x0, y0)
                obj = drain(sampler.corner_objects())
                sampler.set_footprint(footprint_planes(r.scene, obj))
                drain(sampler.share_pass())
                texels[H - py - th:H - py, px:px + tw] = sampler._footprint_texels
                yield
        finally:
            sampler.release()
        tex = self.ctx.texture((W, H), 2, texels.tobytes(), dtype="f4")
        import moderngl

        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._footprint_tex = tex

    def _read(self, n: int) -> np.ndarray:
        """The mosaic's mean of n samples, clamped at 0 where render clamps
        (Renderer.render's clamp_radiance); cut pixels keep their -inf/NaN."""
        from ..gpu.renderer import clamp_radiance

        w, h = self.layout.size
        raw = self._fbo.read(components=4, dtype="f4")
        img = np.asarray(np.frombuffer(raw, dtype=np.float32).reshape(h, w, 4)[::-1, :, :3], dtype=np.float64) / n
        marks = np.isnan(img) | np.isneginf(img)
        clamp_radiance(img)
        img[marks] = -np.inf
        return img

    def _clear(self) -> None:
        self._fbo.use()
        self._fbo.clear(0.0, 0.0, 0.0, 0.0)

    def _set_scene(self, scene) -> None:
        if self._renderer is None:
            self._renderer = _window_renderer_class()(self.ctx, scene)
        else:
            self._renderer.set_scene(scene)  # compiles when the depth is new

    def _run(self) -> Iterator[None]:
        from .bench import REFERENCE_MAX_DEPTH, REFERENCE_MIN_WEIGHT, REFERENCE_SEED, image_errors
        from ..base.sampling import sample_offsets
        from ..scene.load import with_overrides

        self._fbo = self.ctx.simple_framebuffer(self.layout.size, components=4, dtype="f4")
        if self.reference is None:
            self._set_scene(with_overrides(self.scene, max_depth=REFERENCE_MAX_DEPTH,
                                           min_weight=REFERENCE_MIN_WEIGHT))
            yield
            # two independent stratified patterns of half the samples each (seeds
            # REFERENCE_SEED and REFERENCE_SEED + 1): their mean is the reference,
            # their difference estimates its own sampling noise
            half = REFERENCE_SAMPLES // 2
            if self._renderer.takes_footprint(half):
                yield from self._footprint_mask()
                self._renderer.footprint_mask = self._footprint_tex
            self._clear()
            yield from self._accumulate(sample_offsets(half, REFERENCE_SEED))
            a = self._read(half)
            self._clear()
            yield from self._accumulate(sample_offsets(half, REFERENCE_SEED + 1))
            b = self._read(half)
            self._renderer.footprint_mask = None
            keep = _uncut(a) & _uncut(b)
            with np.errstate(invalid="ignore"):          # -inf + -inf, -inf - -inf: left out
                self.reference = np.where(keep[..., None], (a + b) / 2, np.nan)
            self.cut_pixels = int(keep.size - np.count_nonzero(keep))
            self.noise = float(np.sqrt(np.mean((a[keep] - b[keep]) ** 2)) / 2) if keep.any() else float("nan")
            self.rendered_reference = True
        # time of a whole frame: the timing picture's (the image itself up to
        # FULL_TIMING_PIXELS, else about that many pixels) scaled to all pixels
        scale = self.layout.full[0] * self.layout.full[1] / (self.layout.timing_size[0] * self.layout.timing_size[1])
        tw, th = self.layout.timing_size
        self._timing_fbo = self.ctx.simple_framebuffer((tw, th), components=4, dtype="f4")
        # the truncation control variate (see the module's docstring): the
        # reference trace's centred sample, on the mosaic and on the image
        control = len(self.layout.tiles) > 1
        if control:
            self._set_scene(with_overrides(self.scene, max_depth=REFERENCE_MAX_DEPTH,
                                           min_weight=REFERENCE_MIN_WEIGHT))
            ref_mosaic = yield from self._centre_mosaic()
            ref_full = yield from self._centre_full()
        for (d, wgt), sample_counts in self._by_trace.items():
            self._set_scene(with_overrides(self.scene, max_depth=d, min_weight=wgt))
            yield
            if control:
                t_mosaic = _squared_difference(((yield from self._centre_mosaic())), ref_mosaic)
                t_full = _squared_difference(((yield from self._centre_full())), ref_full)
                t_full_mean = float(np.mean(t_full[np.isfinite(t_full)])) if np.isfinite(t_full).any() else 0.0
            timings: list[float] = []
            passes = FULL_TIMED_PASSES
            yield from self._timed_passes(1 + passes, timings)
            per_pass = statistics.median(timings[1:])  # the first is a warm-up
            # and what a render does once whatever its samples: read the image back
            readback = self._timed_readback()
            # a render of two samples or more on a checkered plane: its
            # footprint mask once, and footprint samples (Renderer.render)
            footprint_once = footprint_pass = None
            if any(self._renderer.takes_footprint(n) for n in sample_counts):
                timings = []
                footprint_once = yield from self._timed_footprint(1 + passes, timings)
                footprint_pass = statistics.median(timings[1:])
            for n in sample_counts:
                # footprint samples where Renderer.render takes them (two
                # samples or more on a checkered plane), with its mask
                footprint = self._renderer.takes_footprint(n)
                if footprint and self._footprint_tex is None:
                    yield from self._footprint_mask()
                self._renderer.footprint_mask = self._footprint_tex if footprint else None
                self._clear()
                yield from self._accumulate(sample_offsets(n, RENDER_SEED))
                self._renderer.footprint_mask = None
                image = self._read(n)
                keep = _uncut(image) & np.isfinite(self.reference).all(axis=-1)
                if control:
                    keep &= np.isfinite(t_mosaic)
                self.cut_pixels = max(self.cut_pixels, int(keep.size - np.count_nonzero(keep)))
                err = (image_errors(image[keep], self.reference[keep]) if keep.any() else
                       {"rmse": float("inf"), "frac_off": 1.0})
                if control and keep.any() and math.isfinite(err["rmse"]):
                    mse = err["rmse"] ** 2 - float(np.mean(t_mosaic[keep])) + t_full_mean
                    err["rmse"] = math.sqrt(max(mse, 0.0))
                se = tile_standard_error(image, self.reference, keep, self.layout, err["rmse"],
                                         t_mosaic if control else None)
                c = Candidate(n, d, wgt)
                t = (n * per_pass + readback if footprint_pass is None or not footprint
                     else footprint_once + n * footprint_pass + readback)
                self.measured[c.key()] = Measured(c, t * scale, err["rmse"], err["frac_off"], se)

    def _centre_mosaic(self):
        """One centred point sample of the mosaic with the scene as set
        (a generator: returns the (h, w, 3) image, -inf where a tree was cut)."""
        self._renderer.footprint_mask = None
        self._clear()
        yield from self._accumulate([(0.5, 0.5)])
        return self._read(1)

    def _centre_full(self):
        """One centred point sample of the whole W x H image with the scene
        as set, in bands of rows (a yield each: the viewer measures between
        frames); returns the (H, W, 3) image, top row first, -inf where a
        tree was cut (the window renderer's check, as on the mosaic)."""
        import moderngl

        ctx, r = self.ctx, self._renderer
        W, H = self.layout.full
        if self._full_fbo is None:
            self._full_fbo = ctx.simple_framebuffer((W, H), components=4, dtype="f4")
        fbo = self._full_fbo
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        r.full, r.shift, r.footprint_mask = (W, H), (0, 0), None   # the image's own camera
        rows = -(-H // _bands(self.layout.full))
        for top in range(0, H, rows):
            h = min(rows, H - top)
            fbo.use()
            ctx.disable(moderngl.BLEND)
            r.draw_sample(W, H, (0.5, 0.5), (0, H - top - h, W, h))
            ctx.finish()
            yield
        raw = fbo.read(components=4, dtype="f4")
        img = np.frombuffer(raw, dtype=np.float32).reshape(H, W, 4)[::-1, :, :3]
        yield
        return np.asarray(img, dtype=np.float64)

    def _timed_footprint(self, count: int, timings: list[float]):
        """As _timed_passes, with the footprint samples Renderer.render draws
        from two samples on: the mask of the timing picture made (timed, and
        returned: ms), then `count` passes of footprint samples."""
        from ..adaptive.sampler import AdaptiveSampler

        ctx, r = self.ctx, self._renderer
        tw, th = self.layout.timing_size
        r.full, r.footprint_mask = None, None
        r.footprint_sampler(tw, th)               # its targets and programs made, untimed
        yield
        ctx.finish()
        t0 = time.perf_counter()
        fp = r.footprint_sampler(tw, th)
        ctx.finish()
        mask_ms = (time.perf_counter() - t0) * 1000.0
        yield
        groups = r.programs_for(tw, th, compile_all=True, **AdaptiveSampler.FOOTPRINT_SAMPLES)
        for _ in range(count):
            ctx.finish()
            t0 = time.perf_counter()
            self._timing_fbo.use()
            r.draw_groups(groups, tw, th, (0.5, 0.5), None, fp.bind_footprint)
            ctx.finish()
            timings.append((time.perf_counter() - t0) * 1000.0)
            yield
        return mask_ms

    def _timed_readback(self) -> float:
        """ms of reading the timing picture back as Renderer.render does (RGB
        float32): a render's cost that does not grow with its samples."""
        self.ctx.finish()
        t0 = time.perf_counter()
        self._timing_fbo.read(components=3, dtype="f4")
        return (time.perf_counter() - t0) * 1000.0

    def _timed_passes(self, count: int, timings: list[float]) -> Iterator[None]:
        """Centred samples of the whole picture at the timing size, each
        finished on the GPU and timed."""
        ctx, r = self.ctx, self._renderer
        tw, th = self.layout.timing_size
        r.full = None
        # every culling variant of this size compiled first, untimed: a draw
        # compiles one (COMPILES_PER_DRAW), so the first trace's passes were
        # compiles (1 sample at depth 2: 1.69 s estimated for a 0.26 s frame).
        # One per step, as the draws would (the viewer's frames).
        while True:
            built = r.programs_built
            r.programs_for(tw, th)
            if r.programs_built == built:
                break
            yield
        for _ in range(count):
            ctx.finish()
            t0 = time.perf_counter()
            self._timing_fbo.use()
            r.draw_sample(tw, th, (0.5, 0.5))
            ctx.finish()
            timings.append((time.perf_counter() - t0) * 1000.0)
            yield


# ---------------------------------------------------------------- choosing


@dataclass
class Choice:
    measured: Measured
    met: bool
    max_error: float
    cache_hit: bool
    layout: Layout
    noise: float  # the reference's own sampling noise (RMSE, estimated)
    cache_path: Path | None = None
    candidates: int = 0
    cut_pixels: int = 0  # measured pixels left out: the driver's loop limit cut their trees

    def line(self) -> str:
        m = self.measured
        W, H = self.layout.full
        t = f"{m.time_ms / 1000:.2f} s" if m.time_ms >= 1000 else f"{m.time_ms:.1f} ms"
        what = (f"picked {m.candidate.describe()}" if self.met else
                f"no measured setting reaches it; using the most accurate: {m.candidate.describe()}"
                if math.isfinite(m.rmse) else
                f"no error could be measured; using the setting that traces the most: {m.candidate.describe()}")
        rmse = f"{m.rmse:.3g}" + (f" +- {m.rmse_se:.2g}" if m.rmse_se > 0 else "")
        return (f"max-error {self.max_error:g}: {what} (measured RMSE {rmse}, {t} per {W}x{H} frame; "
                f"{self.candidates} candidates measured on {self.layout.pixels} of its pixels, reference "
                f"noise {self.noise:.2g}; cache {'hit' if self.cache_hit else 'miss'})"
                + (f"; {self.cut_pixels} of the {self.layout.pixels} pixels left out: this OpenGL driver's loop "
                   "limit cut their ray trees, so the errors miss them" if self.cut_pixels else ""))


def prepare(ctx, scene, width: int, height: int, samples: int | None = None, max_depth: int | None = None,
            min_weight: float | None = None, root: Path | None = None,
            pixels: int = MEASURE_PIXELS) -> tuple[Measurement, Cache, list[Candidate]]:
    """The measurement still needed for this scene at this image size
    (done at once on a cache hit)."""
    lay = layout(width, height, pixels)
    cache = Cache(make_key(ctx, scene, lay), root)
    cands = candidate_grid(samples, max_depth, min_weight)
    known = cache.load()
    noise = getattr(cache, "noise", float("nan"))
    cut = getattr(cache, "cut_pixels", 0)
    ref = None
    if any(c.key() not in known for c in cands):
        ref = cache.load_reference() if known else None
        if ref is None:
            known = {}  # a new reference: the old errors were measured against another one
    return Measurement(ctx, scene, lay, cands, known, ref, noise, cut), cache, cands


def finish(meas: Measurement, cache: Cache, cands: list[Candidate], max_error: float) -> Choice:
    """Save what was measured and pick."""
    hit = not meas.todo
    if not hit and not meas.saved:
        # once: the viewer picks again from the same measurement whenever its
        # budget changes, and that is no new measurement to write
        cache.save(meas.measured, meas.noise, meas.reference, meas.cut_pixels)
        meas.saved = True
    pool = [meas.measured[c.key()] for c in cands]
    m, met = pick(pool, max_error)
    return Choice(m, met, max_error, hit, meas.layout, meas.noise, cache.path, len(pool), meas.cut_pixels)


def choose(ctx, scene, width: int, height: int, max_error: float, samples: int | None = None,
           max_depth: int | None = None, min_weight: float | None = None, root: Path | None = None,
           progress: Callable[[int, int], None] | None = None, pixels: int = MEASURE_PIXELS) -> Choice:
    """Measure (or read from the cache) and pick, blocking."""
    meas, cache, cands = prepare(ctx, scene, width, height, samples, max_depth, min_weight, root, pixels)
    meas.run(progress)
    return finish(meas, cache, cands, max_error)


def apply(scene, choice: Choice):
    """A copy of the scene with the picked settings."""
    from ..scene.load import with_overrides

    c = choice.measured.candidate
    return with_overrides(scene, samples=c.samples, max_depth=c.max_depth, min_weight=c.min_weight)


def parse_max_error(text: str) -> float:
    """argparse type of --max-error: a finite number > 0."""
    import argparse

    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a number > 0 (an RMSE in linear units, such as 0.01), "
                                         f"got {text!r}")
    return v


def scene_for_max_error(ctx, scene, args, width: int, height: int,
                        progress: Callable[[int, int], None] | None = None):
    """``glassray render --max-error E``: the scene with the picked settings;
    prints one line on stderr.  Explicit --samples / --max-depth /
    --min-weight fix those values."""
    choice = choose(ctx, scene, width, height, args.max_error, samples=getattr(args, "samples", None),
                    max_depth=getattr(args, "max_depth", None), min_weight=getattr(args, "min_weight", None),
                    progress=progress)
    print(f"glassray: {choice.line()}", file=sys.stderr, flush=True)
    return apply(scene, choice)
