"""The max-error measurement itself: the candidates and a reference drawn on
a mosaic of tiles of the real image (a Renderer whose framebuffer shows a
window of the larger image), the truncation control variate, the timed
passes; one GPU pass per step, so that the viewer measures between frames.
"""

from __future__ import annotations

import math
import statistics
import time
from typing import Callable, Iterator

import moderngl
import numpy as np

from ..adaptive.sampler import AdaptiveSampler
from ..base import interrupt
from ..base.sampling import sample_offsets
from ..gpu.footprint import drain, footprint_default, footprint_planes
from ..gpu.block import camera_uniforms
from ..gpu.renderer import Renderer, clamp_radiance, cut_marks
from ..scene.load import with_overrides
from .kit import REFERENCE_MAX_DEPTH, REFERENCE_MIN_WEIGHT, REFERENCE_SEED, image_errors
from .quality_grid import Candidate, Layout, Measured

#: Reference: samples (seed and trace settings are the bench's).  64, not 32:
#: at 32 (two patterns of 16) its own error on glass-sphere at 160x90 was
#: 0.0042, close to a 16-sample render's 0.0050, and 16 samples measured 0.0074.
REFERENCE_SAMPLES = 64
#: Pixels a band of a whole-image pass of the truncation control variate
#: traces at most (Measurement._centre_full).
FULL_BAND_PIXELS = 1280 * 48
FULL_TIMED_PASSES = 3
#: Seed of the candidates' sample pattern (glassray render's default).
RENDER_SEED = 0



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
            prog["loopProbe"].value = 2   # the CUT_CHECK probe loop's count (shaders/lib/loop_limit.glsl)
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
        mask = self.footprint_mask
        defines = {**({"CUT_CHECK": 1} if glass else {}),
                   **(AdaptiveSampler.FOOTPRINT_SAMPLES if mask is not None else {})}

        def bind_mask(prog):
            if mask is not None and "footprintMask" in prog:
                mask.use(location=AdaptiveSampler.FOOTPRINT_UNIT)
                prog["footprintMask"].value = AdaptiveSampler.FOOTPRINT_UNIT
        self.draw_groups([(self.variant(**defines), [(0, 0, width, height)])], width, height, offset,
                         viewport, bind_mask)


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
                # Ctrl-C between passes (viewer/base/interrupt.py): a first
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
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._footprint_tex = tex

    def _read(self, n: int) -> np.ndarray:
        """The mosaic's mean of n samples, clamped at 0 where render clamps
        (Renderer.render's clamp_radiance); cut pixels keep their -inf/NaN."""
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
            self._renderer = WindowRenderer(self.ctx, scene)
        else:
            self._renderer.set_scene(scene)  # compiles when the depth is new

    def _run(self) -> Iterator[None]:
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
