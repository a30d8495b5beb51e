"""Progressive rendering for the viewer: previews while things move,
accumulation when they stop, and the display pass.  No window code here: it
draws with the shared :class:`~viewer.renderer.Renderer` into its own
framebuffers and shows the result in whatever framebuffer it is given.

* Accumulation: an RGBA32F texture at the full framebuffer resolution, with
  additive blending; every traced sample adds its radiance to rgb and 1 to
  alpha, so each pixel divides by its own count.  A full-resolution sample is
  traced in horizontal bands, top to bottom, as many per frame as fit in a
  time budget, so one slow sample never blocks the event loop; sample k uses
  offset k of ``sample_offsets(samples, seed)``, the same pattern as
  ``glassray render``, so a finished accumulation equals the offscreen image.
* Adaptive accumulation (``adaptive=True``; the viewer's --adaptive): instead
  of uniform passes, an :class:`~viewer.adaptive.AdaptiveRender` for the
  full framebuffer size, advanced one draw call (``step``) at a time within
  the same frame-time budget; its first step traces sample 0 of every pixel,
  later ones only the pixels that still need samples (``samples`` is then
  the mean per pixel).  Its sums (rgb, count) are uploaded into the same
  accumulation texture when a pass ends, so the display pass is the same;
  while a round of added samples runs (seconds at 1280x720), the display
  also adds the sums its draws have traced so far, straight from the
  round's pixel-list target (DISPLAY_MODE 4: nothing read back), so the
  picture improves frame by frame.  A finished adaptive view equals
  ``render_adaptive`` for the seed.
* Preview: one centred sample per pixel at a reduced resolution chosen from
  the measured cost per pixel so that a frame holds the target frame time;
  shown (upscaled) wherever the accumulation has no sample yet.
* Display: ``shaders/display.frag`` divides, clamps, applies the sRGB curve
  (the spec's display encoding) and scales to the output viewport.
"""

from __future__ import annotations

import math
import time

import moderngl
import numpy as np

from ..adaptive.render import AdaptiveRender
from ..adaptive.sampler import AdaptiveSampler
from ..gpu.footprint import FootprintSampler, footprint_default
from ..base.sampling import sample_offsets
from ..gpu.shaders import build_program

#: Smallest preview scale (fraction of the framebuffer's width and height).
MIN_PREVIEW_SCALE = 1.0 / 32.0
#: Most pixels one draw call may cover (as the offscreen renderer's tiles).
MAX_DRAW_PIXELS = 512 * 512


class Progressive:
    def __init__(self, ctx: moderngl.Context, renderer, target_ms: float = 33.0, seed: int = 0,
                 adaptive: bool = False):
        self.ctx = ctx
        self.renderer = renderer
        self.target_ms = float(target_ms)
        self.seed = seed
        self.programs, self.vaos = self._build_display()
        self.size = (0, 0)
        self.accum_tex = self.accum_fbo = None
        self.preview_tex = self.preview_fbo = None
        self.preview8_tex = self.preview8_fbo = None  # the preview, display-encoded
        self.preview_size: tuple[int, int] | None = None  # (pw, ph) of the latest preview
        self.passes_done = 0  # complete full-resolution samples
        self.next_row = 0  # first row (from the top) of the current pass not yet traced
        self.cost_per_px: float | None = None  # seconds per pixel-sample (moving average)
        self.last_trace_ms = 0.0
        self._offsets = None
        self._offsets_key = None
        # adaptive mode: the render in progress (or finished), what of it is in accum_tex
        self._adaptive = bool(adaptive)
        self.job: AdaptiveRender | None = None
        self._uploaded_spent = 0
        self._uploaded_first = False     # the upload holds the first pass (every pixel has a sample)
        self._uploaded_mean = 0.0
        self._uploaded_draws = 0    # the job's draws_done when accum_tex or the overlay was last updated
        self._overlay = None        # (a round's pixels, its sums texture): what the display adds to accum_tex
        self._slot_tex = None       # (W, H) R32I: each pixel's texel in that texture, -1 if not in the round
        self._step_s = 0.0  # duration of the latest adaptive step (predicts the next one)
        self.uploads = 0  # times accum_tex got new adaptive sums (the viewer shows them at once)
        # uniform mode's footprint samples (Renderer.render's, so that a
        # finished accumulation equals the offscreen image): an
        # FootprintSampler of the accumulation's size whose mask is made for
        # each still view by its direct_footprints steps, before the first band
        self._fp: FootprintSampler | None = None
        self._fp_steps = None     # those steps while they run
        self._fp_ready = False    # the mask is the current view's

    # ------------------------------------------------------------ state

    @property
    def samples(self) -> int:
        return int(self.renderer.scene.render.samples)

    @property
    def adaptive(self) -> bool:
        return self._adaptive

    @adaptive.setter
    def adaptive(self, on: bool) -> None:
        """Switch between adaptive and uniform accumulation (starts over)."""
        on = bool(on)
        if on != self._adaptive:
            self._adaptive = on
            self.restart()

    @property
    def done(self) -> bool:
        if self._adaptive:
            return self.job is not None and self.job.done
        return self.passes_done >= self.samples

    @property
    def started(self) -> bool:
        """Some full-resolution work for the current view has been traced."""
        if self._adaptive:
            return self.job is not None and (self.job.draws_done > 0 or self.job.spent > 0)
        return self.passes_done > 0 or self.next_row > 0

    @property
    def has_full_sample(self) -> bool:
        """Every pixel of accum_tex has at least one sample."""
        if self._adaptive:
            w, h = self.size
            return self.job is not None and w * h > 0 and self._uploaded_first
        return self.passes_done > 0

    @property
    def mean_spp(self) -> float:
        """Mean samples per pixel accumulated so far (the pixels' counts in
        accum_tex averaged over the framebuffer)."""
        w, h = self.size
        if w * h == 0:
            return 0.0
        if self._adaptive:
            if self.job is None:
                return 0.0
            # and the pixel-samples of a round in flight so far
            return self._uploaded_mean + (self.job.round_traced / (w * h) if self._showing_round else 0.0)
        return self.passes_done + self.next_row / h

    @property
    def active_resolution(self) -> tuple[int, int]:
        """What the latest trace work ran at: the preview's size until the
        first full-resolution band lands, then the full size."""
        if self.started or self.preview_size is None:
            return self.size
        return self.preview_size

    def offsets(self) -> np.ndarray:
        key = (self.samples, self.seed)
        if key != self._offsets_key:
            self._offsets = sample_offsets(self.samples, self.seed)
            self._offsets_key = key
        return self._offsets

    def set_renderer(self, renderer) -> None:
        self.renderer = renderer
        self.restart()

    def resize(self, width: int, height: int) -> None:
        """Reallocate for a framebuffer of this size (nothing for 0 x 0)."""
        if (width, height) == self.size:
            return
        self._release_targets()
        self.size = (width, height)
        self.preview_size = None
        if width > 0 and height > 0:
            ctx = self.ctx
            self.accum_tex = ctx.texture((width, height), 4, dtype="f4")
            self.accum_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self.accum_fbo = ctx.framebuffer(color_attachments=[self.accum_tex])
            self.preview_tex = ctx.texture((width, height), 4, dtype="f4")
            self.preview_tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self.preview_tex.repeat_x = self.preview_tex.repeat_y = False
            self.preview_fbo = ctx.framebuffer(color_attachments=[self.preview_tex])
            self.preview8_tex = ctx.texture((width, height), 4)
            self.preview8_tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self.preview8_tex.repeat_x = self.preview8_tex.repeat_y = False
            self.preview8_fbo = ctx.framebuffer(color_attachments=[self.preview8_tex])
        self.restart()

    def restart(self) -> None:
        """The scene changed: throw the accumulated samples away (and the
        adaptive render in progress, with its GL objects)."""
        self.passes_done = 0
        self.next_row = 0
        self._release_job()
        self._stop_footprints()
        if self.accum_fbo is not None:
            self.accum_fbo.clear(0.0, 0.0, 0.0, 0.0)

    def _stop_footprints(self) -> None:
        """The footprint mask is no longer the view's (a new one is made
        before the next first band)."""
        if self._fp_steps is not None:
            self._fp_steps.close()        # (its pass's finally: no scissor left behind)
        self._fp_steps, self._fp_ready = None, False

    def _release_job(self) -> None:
        if self.job is not None:
            self.job.release()
            self.job = None
        self._reset_upload()

    def _reset_upload(self) -> None:
        self._uploaded_spent = 0
        self._uploaded_first = False     # the upload holds the first pass (every pixel has a sample)
        self._uploaded_mean = 0.0
        self._uploaded_draws = 0
        self._overlay = None

    # ------------------------------------------------------------ tracing

    def _note_cost(self, seconds: float, pixels: int) -> None:
        if pixels <= 0:
            return
        c = max(seconds, 1e-6) / pixels
        self.cost_per_px = c if self.cost_per_px is None else 0.5 * self.cost_per_px + 0.5 * c

    def preview_scale(self, budget_ms: float | None = None) -> float:
        """The scale whose preview should take about ``budget_ms`` to trace."""
        w, h = self.size
        budget = (self.target_ms if budget_ms is None else budget_ms) / 1000.0
        if self.cost_per_px is None or w * h == 0:
            return 0.125  # unknown yet: start small (a software renderer is slow)
        s = math.sqrt(max(budget, 1e-4) / (self.cost_per_px * w * h))
        return min(1.0, max(MIN_PREVIEW_SCALE, s))

    def render_preview(self, budget_ms: float | None = None) -> float:
        """Trace one centred sample per pixel at the reduced resolution; return ms."""
        w, h = self.size
        if w == 0 or h == 0:
            return 0.0
        s = self.preview_scale(budget_ms)
        pw, ph = max(1, round(w * s)), max(1, round(h * s))
        ctx = self.ctx
        t0 = time.perf_counter()
        self.preview_fbo.viewport = (0, 0, pw, ph)
        self.preview_fbo.use()
        ctx.disable(moderngl.BLEND)
        # bands of at most MAX_DRAW_PIXELS keep each draw call short; no
        # culling variant is compiled while things move (a new one takes up
        # to a second on llvmpipe, and orbiting meets new ones all the time:
        # bench-opaque's previews stalled on most frames with Mesa's shader
        # cache cold): ready variants or the full shader draw the preview
        rows = max(1, MAX_DRAW_PIXELS // pw)
        for y in range(0, ph, rows):
            self.renderer.draw_sample(pw, ph, (0.5, 0.5), (0, y, pw, min(rows, ph - y)), compile=False)
        ctx.finish()
        dt = time.perf_counter() - t0
        self._note_cost(dt, pw * ph)
        self.preview_size = (pw, ph)
        # display-encode it once at its own size: scaling it up is then a plain texture read
        self._draw(1, self.preview8_fbo, (0, 0, pw, ph))
        self.last_trace_ms = dt * 1000.0
        return self.last_trace_ms

    def _footprints_pending(self, budget_s: float) -> bool:
        """Advance the making of this view's footprint mask (when the
        uniform accumulation takes footprint samples: Renderer.takes_footprint)
        by steps within `budget_s` (at least one); True while it is not done."""
        if self._fp_ready or self.passes_done or self.next_row or not self.renderer.takes_footprint(self.samples):
            return False
        w, h = self.size
        if self._fp_steps is None:
            fp = self._fp
            if fp is None or fp.renderer is not self.renderer or (fp.width, fp.height) != (w, h):
                if fp is not None:
                    fp.release()
                self._fp = FootprintSampler(self.renderer, w, h)
            self._fp_steps = self._fp.direct_footprints()
        t0 = time.perf_counter()
        while True:
            try:
                next(self._fp_steps)
            except StopIteration:
                self._fp_steps, self._fp_ready = None, True
                return False
            if time.perf_counter() - t0 >= budget_s:
                return True

    def _band(self, rows: int) -> None:
        """Trace `rows` rows of the current pass from next_row down."""
        w, h = self.size
        off = self.offsets()[self.passes_done]
        y0 = h - self.next_row - rows  # GL rows count from the bottom
        offset, viewport = (float(off[0]), float(off[1])), (0, y0, w, rows)
        if self._fp_ready:
            groups = self.renderer.programs_for(w, h, **FootprintSampler.FOOTPRINT_SAMPLES)
            self.renderer.draw_groups(groups, w, h, offset, viewport, self._fp.bind_footprint)
        else:
            self.renderer.draw_sample(w, h, offset, viewport)
        self.next_row += rows
        if self.next_row >= h:
            self.passes_done += 1
            self.next_row = 0

    def accumulate(self, budget_ms: float | None = None, stop_at_pass_end: bool = False) -> float:
        """Trace full-resolution bands until the budget is spent or all
        samples are done (at least one band per call; with
        ``stop_at_pass_end``, also when a sample is complete); return ms spent."""
        w, h = self.size
        if w == 0 or h == 0 or self.done:
            return 0.0
        if self._adaptive:
            return self._accumulate_adaptive(budget_ms, stop_at_pass_end)
        budget = (self.target_ms if budget_ms is None else budget_ms) / 1000.0
        t_start = time.perf_counter()
        if self._footprints_pending(budget):
            self.last_trace_ms = (time.perf_counter() - t_start) * 1000.0
            return self.last_trace_ms
        ctx = self.ctx
        self.accum_fbo.use()
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        ctx.blend_equation = moderngl.FUNC_ADD
        try:
            first = True
            while not self.done:
                left = budget - (time.perf_counter() - t_start)
                if left <= 0 and not first:
                    break
                first = False
                if self.cost_per_px is None:
                    rows = min(8, h)
                else:
                    rows = int(max(left, 0.0) / (self.cost_per_px * w))
                rows = max(1, min(rows, h - self.next_row, max(1, MAX_DRAW_PIXELS // w)))
                t0 = time.perf_counter()
                self._band(rows)
                ctx.finish()
                self._note_cost(time.perf_counter() - t0, rows * w)
                if stop_at_pass_end and self.next_row == 0:
                    break
        finally:
            ctx.disable(moderngl.BLEND)
        self.last_trace_ms = (time.perf_counter() - t_start) * 1000.0
        return self.last_trace_ms

    # ------------------------------------------------------------ adaptive

    def _accumulate_adaptive(self, budget_ms: float | None, stop_at_first_sample: bool = False) -> float:
        """Advance the adaptive render by as many draw calls (steps) as fit
        in the budget (at least one; with ``stop_at_first_sample``, also
        stop once every pixel has a sample), then upload its sums if they
        changed; return ms spent."""
        w, h = self.size
        if self.job is None:
            self.job = AdaptiveRender(self.renderer, w, h, self.samples, seed=self.seed)
            # the display adds a round in flight from one texel per pixel
            # (round_target): no pixel's samples dealt to several
            self.job.sampler.split_entries = False
            self._reset_upload()
        job = self.job
        budget = (self.target_ms if budget_ms is None else budget_ms) / 1000.0
        t_start = time.perf_counter()
        first = True
        had_sample = job.first_pass_done
        while not job.done:
            left = budget - (time.perf_counter() - t_start)
            # a step is one draw call, sized from the measured cost per
            # pixel-sample so that it fits what is left of the budget
            if not first and left < self._step_s:
                break
            first = False
            if self.cost_per_px is not None:
                job.sampler.fragments_per_draw = int(max(64, max(left, 0.25 * budget) / self.cost_per_px))
            else:
                job.sampler.fragments_per_draw = 8 * w
            t0 = time.perf_counter()
            job.sampler.last_draw_fragments = 0
            job.step()
            self._step_s = time.perf_counter() - t0
            self._note_cost(self._step_s, job.sampler.last_draw_fragments)
            if stop_at_first_sample and not had_sample and job.first_pass_done:
                break
        self._upload()
        if job.done:
            job.release()  # its GL objects (the sums stay): nothing more to trace
        self.last_trace_ms = (time.perf_counter() - t_start) * 1000.0
        return self.last_trace_ms

    def compile_adaptive(self) -> None:
        """Compile the shader variants an adaptive render of the current
        scene uses at the current size and camera (the renderer keeps them),
        which it otherwise compiles on first use, one per draw: the first
        pass's, and the pixel lists' (needed only once a pixel gets a second
        sample), each per group of screen tiles.  For the viewer's soak,
        which counts GL objects and wants every program compiled during its
        warm-up."""
        if 0 in self.size:
            return                 # no image yet: nothing to compile for
        sampler = AdaptiveSampler(self.renderer, *self.size, footprint=footprint_default(self.renderer.scene))
        try:
            sampler.compile()
        finally:
            sampler.release()

    def _upload(self) -> None:
        """The adaptive sums into accum_tex (rows bottom first: rgb sums,
        count in alpha) when a pass has ended; while a round runs, the
        display adds the sums of its draws so far from the sampler's list
        target on the GPU (a round at 1280x720 takes seconds: the picture
        improves frame by frame, not in jumps, and nothing is read back)."""
        job = self.job
        if job is None:
            return
        if job.spent != self._uploaded_spent:
            self.accum_tex.write(np.ascontiguousarray(job.total[::-1], dtype=np.float32).tobytes())
            self._uploaded_spent = job.spent
            self._uploaded_first = job.first_pass_done
            # the samples in the pixels' means (the corner rays the adaptive
            # render also traces are in `spent`, not in any pixel)
            self._uploaded_mean = float(job.total[..., 3].mean())
            self._overlay = None
            self.uploads += 1
        target = job.round_target()
        if target is None:
            self._overlay = None       # between passes, or the first or corner pass: shown when it ends
            return
        flat, sums_tex, slot = target
        if self._overlay is not None and self._overlay[0] is flat and job.draws_done == self._uploaded_draws:
            return
        if self._overlay is None or self._overlay[0] is not flat:
            # a new round: which texel of its list each pixel's sums are in
            w, h = self.size
            texel = np.full(w * h, -1, np.int32)
            texel[(h - 1 - flat // w) * w + flat % w] = slot
            if self._slot_tex is None:
                self._slot_tex = self.ctx.texture((w, h), 1, dtype="i4")
                self._slot_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._slot_tex.write(texel.tobytes())
        self._overlay = (flat, sums_tex)
        self._uploaded_draws = job.draws_done
        self.uploads += 1

    @property
    def _showing_round(self) -> bool:
        """The display adds a round in flight (its list target) to accum_tex."""
        job = self.job
        if self._overlay is None or job is None or job.done or job.spent != self._uploaded_spent:
            return False
        target = job.round_target()
        return target is not None and target[0] is self._overlay[0] and target[1] is self._overlay[1]

    def finish_pass(self) -> None:
        """Complete the current full-resolution sample if none is complete
        yet (a screenshot needs every pixel to have one)."""
        w, h = self.size
        if w == 0 or h == 0:
            return
        if self._adaptive:
            while not self.has_full_sample and not self.done:
                self._accumulate_adaptive(budget_ms=1e9, stop_at_first_sample=True)
            return
        if self.passes_done == 0:
            while self.passes_done == 0:
                self.accumulate(budget_ms=1e9, stop_at_pass_end=True)

    # ------------------------------------------------------------ output

    def image(self) -> np.ndarray:
        """(H, W, 3) float32 linear radiance, each pixel the mean of its
        accumulated samples (0 where it has none), first row = top."""
        w, h = self.size
        if self._adaptive and self.job is not None:
            self._upload()
            return np.ascontiguousarray(self.job.image(), dtype=np.float32)
        raw = self.accum_tex.read()
        acc = np.frombuffer(raw, dtype=np.float32).reshape(h, w, 4)[::-1]
        count = acc[:, :, 3:4]
        with np.errstate(invalid="ignore", divide="ignore"):
            img = np.where(count > 0, acc[:, :, :3] / np.maximum(count, 1e-30), 0.0)
        return np.ascontiguousarray(img, dtype=np.float32)

    def _build_display(self):
        """The display programs, one per DISPLAY_MODE (see display.frag)."""
        progs, vaos = [], []
        try:
            for mode in (0, 1, 2, 3, 4):
                progs.append(build_program(self.ctx, fragment="display.frag", vertex="fullscreen.vert",
                                           defines={"DISPLAY_MODE": mode}))
                vaos.append(self.ctx.vertex_array(progs[-1], []))
        except Exception:
            for obj in vaos + progs:
                obj.release()
            raise
        return progs, vaos

    @property
    def program(self) -> moderngl.Program:
        return self.programs[0]

    def display(self, fbo: moderngl.Framebuffer, viewport: tuple[int, int, int, int]) -> None:
        """Draw the current image into ``fbo`` over ``viewport`` (x, y, w, h)."""
        if self.accum_tex is None:
            fbo.use()
            self.ctx.clear(0.0, 0.0, 0.0, 1.0)
            return
        if self.has_full_sample:
            mode = 4 if self._showing_round else 2  # every pixel has a sample (and a round adds more)
        elif (self.started and not self._adaptive) or self.preview_size is None:
            mode = 0  # the first sample is on its way
        else:
            mode = 3  # nothing accumulated yet: the encoded preview
        self._draw(mode, fbo, viewport)

    def _draw(self, mode: int, fbo: moderngl.Framebuffer, viewport: tuple[int, int, int, int]) -> None:
        ctx = self.ctx
        fbo.viewport = viewport
        fbo.use()
        ctx.scissor = None
        ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        w, h = self.size
        pw, ph = self.preview_size or (1, 1)
        prog = self.programs[mode]
        self.accum_tex.use(location=0)
        (self.preview8_tex if mode == 3 else self.preview_tex).use(location=1)
        if mode == 4:
            self._overlay[1].use(location=2)
            self._slot_tex.use(location=3)
        for name, value in (("accumTex", 0), ("previewTex", 1), ("outSize", (float(viewport[2]), float(viewport[3]))),
                            ("accumSize", (float(w), float(h))), ("previewUsed", (pw / w, ph / h)),
                            ("previewTexel", (1.0 / w, 1.0 / h)), ("hasPreview", int(self.preview_size is not None)),
                            ("roundSums", 2), ("roundTexel", 3)):
            if name in prog:
                prog[name].value = value
        self.vaos[mode].render(moderngl.TRIANGLES, vertices=3)

    def reload_program(self) -> None:
        """Rebuild the display shaders from disk (raises ShaderError, keeping the old ones)."""
        progs, vaos = self._build_display()
        self._release_display()
        self.programs, self.vaos = progs, vaos

    def _release_display(self) -> None:
        for obj in self.vaos + self.programs:
            obj.release()
        self.vaos, self.programs = [], []

    # ------------------------------------------------------------ cleanup

    def _release_targets(self) -> None:
        for obj in (self.accum_fbo, self.accum_tex, self.preview_fbo, self.preview_tex, self.preview8_fbo,
                    self.preview8_tex, self._slot_tex):
            if obj is not None:
                obj.release()
        self._slot_tex = self._overlay = None
        self.accum_fbo = self.accum_tex = self.preview_fbo = self.preview_tex = None
        self.preview8_fbo = self.preview8_tex = None

    def release(self) -> None:
        self._release_job()
        self._stop_footprints()
        if self._fp is not None:
            self._fp.release()
            self._fp = None
        self._release_targets()
        self._release_display()
        self.size = (0, 0)
