"""One renderer for the window and for offscreen images.

It owns the shader programs (cached by their compile-time defines), the
scene's uniform block and the sky texture, and draws one pixel sample per
draw into whatever framebuffer it is given.  Offscreen, samples are summed
with additive blending in an RGBA32F framebuffer; a large image is drawn in
tiles (scissor rectangles) so that no single draw call runs long enough to
trip a GPU driver's watchdog.
"""

from __future__ import annotations

from typing import Callable

import moderngl
import numpy as np

from ..base import interrupt
from ..base.imageio import SkyImageError, read_sky_image
from ..base.sampling import sample_offsets
from ..scene.model import Scene
from . import culling, driver
from .footprint import FootprintSampler, drain, footprint_default
from .block import camera_uniforms, pack_scene
from .defines import shader_defines
from .driver import driver_defines
from .frame import F32_MAX, gpu_frame_scene, radiance_exponent
from .shaders import ShaderFiles, build_program
from .driver import CULL_MAX_OBJECTS, DEFAULT_TILE



def intersect_rect(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> tuple[int, int, int, int] | None:
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[0] + a[2], b[0] + b[2]), min(a[1] + a[3], b[1] + b[3])
    return (x0, y0, x1 - x0, y1 - y0) if x1 > x0 and y1 > y0 else None


def cut_marks(image: np.ndarray) -> np.ndarray:
    """Where a sum of samples holds one cut short by the driver's loop limit
    (shaders/render.frag, CUT_CHECK: -inf, or NaN where it met a +inf)."""
    return np.isnan(image) | np.isneginf(image)


def clamp_radiance(image: np.ndarray) -> np.ndarray:
    """The image with every value below 0 set to 0, in place.  Radiance is
    never negative, but a pixel's mean of few footprint samples can be: the
    checker's share is a control variate, c_bar L(x) + (c(x) - c_bar)(L(x) -
    L_ref), unbiased but not bounded below (the default scene at 320x180, 2
    samples: one pixel at -0.041 where the shadow's edge and a checker line
    cross it).  +inf (beyond float32) stays.  A read-only array (a
    read-back viewed in place) is copied first."""
    if not image.flags.writeable:
        image = image.copy()
    np.maximum(image, 0.0, out=image)
    return image


class Renderer:
    #: Draw the specialised shader per group of screen tiles, each with the
    #: objects its rays can meet (viewer/gpu/culling.py).  Off for renderers
    #: whose camera is not the scene's (viewer/measure/quality.py's window).
    cull = True
    COMPILES_PER_DRAW = 1
    SUBSET_PROGRAMS = 16

    def __init__(self, ctx: moderngl.Context, scene: Scene, tile: int = DEFAULT_TILE,
                 specialise: bool = True, fresnel: str = "exact", extra_defines: dict | None = None,
                 eager: bool = True):
        """specialise=False uses the generic all-features shader and
        fresnel="schlick" Schlick's approximation: both only for comparisons
        in the benchmark.  extra_defines are added to every program (the
        stress suite's NAIVE_INTERSECT), after the driver's own
        (gpu/driver.py driver_defines).

        eager: set_scene compiles the scene's full program at once, so that
        a shader the driver rejects fails there (the viewer keeps its last
        good scene and shaders).  eager=False compiles each program when a
        draw first needs it: render() of a glass scene, or of one with
        footprint samples, draws only variants of it (cut-checked, with
        footprints, culled), so the full one would be compiled for nothing
        (bench-many's: 3.5 s on llvmpipe, 15 s on an NVIDIA driver, with
        the driver's shader cache cold)."""
        self.ctx = ctx
        self.eager = eager
        self.tile = tile
        self.specialise = specialise
        self.fresnel = fresnel
        info = getattr(ctx, "info", None) or {}
        self.extra_defines = {**driver_defines(str(info.get("GL_RENDERER", "")), str(info.get("GL_VERSION", ""))),
                              **dict(extra_defines or {})}
        self._force_resume = False          # render(): the one-pass image was cut, drawn again
        self.last_render_resumed = False    # whether the last render() took resumable passes
        self._programs: dict[tuple, moderngl.Program] = {}
        self._subset_programs: dict[tuple, moderngl.Program] = {}
        self._subset_of: dict[tuple, tuple[frozenset, tuple]] = {}   # program key -> (objects, extra defines)
        self._plans: dict[tuple, list] = {}
        self._plan_key = None
        self._vao_for: dict[int, moderngl.VertexArray] = {}
        self._ubo: moderngl.Buffer | None = None
        self._sky: moderngl.Texture | None = None
        self._sky_path = None
        self._fbo: moderngl.Framebuffer | None = None
        self._camera_key = None
        self._camera: dict = {}
        self._fbo_tex: moderngl.Texture | None = None
        self._readback: bytearray | None = None     # _read_rgb's buffer, the target's size
        self._footprints = None           # footprint_sampler's FootprintSampler
        #: shader programs this renderer has built (a benchmark checks that
        #: its timed renders build none)
        self.programs_built = 0
        #: the shader sources as they were when this renderer was made: every
        #: program it builds later comes from them (F5 makes a new renderer)
        self.shader_files = ShaderFiles()
        self.scene: Scene | None = None
        #: what draw_sample draws with: None is the scene's full program
        #: (culled where culls()); _debug_pass swaps in a VIEW_MODE variant
        self.program: moderngl.Program | None = None
        self.set_scene(scene)

    # ------------------------------------------------------------ scene

    def set_scene(self, scene: Scene) -> None:
        """Upload a scene; recompiles only when its feature key changes.

        `self.scene` is the scene in the GPU's units: `scene` itself, or for
        a scene far outside float32's comfortable scale, a copy with its
        lengths times 2^length_exponent and its far lights and planes
        brought within reach of the eye (gpu/frame.py gpu_frame_scene); the
        image is the same."""
        scene, self.length_exponent = gpu_frame_scene(scene)
        packed = pack_scene(scene, self.specialise, self.fresnel)
        self._defines = {**packed.defines, **self.extra_defines}
        if self.eager:
            self._program(self._defines)
        self._plan_key, self._plans = None, {}
        if self._ubo is None or self._ubo.size != len(packed.block):
            if self._ubo is not None:
                self._ubo.release()
            self._ubo = self.ctx.buffer(packed.block)
        else:
            self._ubo.write(packed.block)
        self._update_sky(scene)
        self.scene = scene

    @property
    def _main(self) -> moderngl.Program:
        """The scene's full program (compiled now if it is not yet)."""
        return self._program(self._defines)

    @staticmethod
    def _program_key(defines: dict, vertex: str = "fullscreen.vert") -> tuple:
        return (vertex, *sorted(defines.items()))

    def _program(self, defines: dict, vertex: str = "fullscreen.vert") -> moderngl.Program:
        key = self._program_key(defines, vertex)
        prog = self._programs.get(key)
        if prog is None:
            prog = build_program(self.ctx, vertex=vertex, defines=defines, sources=self.shader_files)
            self.programs_built += 1
            self._programs[key] = prog
        return prog

    def variant(self, vertex: str = "fullscreen.vert", **defines) -> moderngl.Program:
        """The current scene's program with extra defines (cached like the
        main one): the adaptive sampler's ADAPTIVE variant, the debug views."""
        return self._program({**self._defines, **defines}, vertex)

    def _update_sky(self, scene: Scene) -> None:
        path = scene.sky.image_path if scene.sky.type == "image" else None
        # the picture is a source of light: times the sources' 2^r (gpu/frame.py radiance_exponent)
        key = None if path is None else (path, radiance_exponent(scene))
        if key == self._sky_path and self._sky is not None:
            return
        if path is not None:
            img = read_sky_image(path)
            h, w, _ = img.shape
            limit = int(self.ctx.info["GL_MAX_TEXTURE_SIZE"])
            if max(w, h) > limit:        # the driver would make an empty texture: a black sky
                raise SkyImageError(f"sky.image: {path} is {w}x{h}, larger than the {limit}x{limit} texture "
                                    "this OpenGL driver can hold; scale the picture down")
            if key[1]:
                with np.errstate(over="ignore"):
                    img = np.clip(np.ldexp(img.astype(np.float64), key[1]), 0.0, F32_MAX)
            tex = self.ctx.texture((w, h), 3, np.ascontiguousarray(img, dtype="f4").tobytes(), dtype="f4")
            tex.repeat_x, tex.repeat_y = True, False
        else:
            tex = self.ctx.texture((1, 1), 3, np.zeros(3, "f4").tobytes(), dtype="f4")
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        if self._sky is not None:        # only now: a picture refused above leaves the old sky working
            self._sky.release()
        self._sky, self._sky_path = tex, key

    # ------------------------------------------------------------ drawing

    def draw_sample(self, width: int, height: int, offset: tuple[float, float],
                    viewport: tuple[int, int, int, int] | None = None, compile: bool = True) -> None:
        """Trace one sample per pixel of the bound framebuffer (additively if
        blending is on).  viewport limits the work to a rectangle (x, y, w, h)
        in framebuffer pixels, bottom-left origin.  The specialised shader
        draws each group of screen tiles with a variant compiled for the
        objects its rays can meet (viewer/gpu/culling.py); the image is the same.
        compile=False compiles nothing new (the viewer's previews while the
        camera moves: a compile on llvmpipe takes up to a second): a group
        whose variant is not ready is drawn with a ready variant for more
        objects, or with the full shader."""
        if self.program is None and self.culls():
            self.draw_groups(self._culled(width, height, compile=compile), width, height, offset, viewport)
            return
        prog = self._main if self.program is None else self.program
        self.bind(prog, width, height, offset)
        self.ctx.scissor = viewport
        self.vao_of(prog).render(moderngl.TRIANGLES, vertices=3)
        self.ctx.scissor = None

    def draw_groups(self, groups, width: int, height: int, offset: tuple[float, float],
                    viewport: tuple[int, int, int, int] | None = None,
                    bind: Callable[[moderngl.Program], None] | None = None) -> None:
        """Draw one sample with `groups`, (program, rectangles) pairs that
        cover the image once (programs_for), within `viewport`; `bind` binds
        what a variant reads beyond bind()'s (footprint samples' mask)."""
        for prog, rects in groups:
            self.bind(prog, width, height, offset)
            if bind is not None:
                bind(prog)
            vao = self.vao_of(prog)
            for rect in rects:
                clipped = rect if viewport is None else intersect_rect(rect, viewport)
                if clipped is None:
                    continue
                self.ctx.scissor = clipped
                vao.render(moderngl.TRIANGLES, vertices=3)
        self.ctx.scissor = None

    def culls(self) -> bool:
        """Whether images are drawn per group of screen tiles (culling)."""
        return self.cull and self.specialise and 0 < len(self.scene.objects) <= CULL_MAX_OBJECTS

    def programs_for(self, width: int, height: int, compile_all: bool = False,
                     **defines) -> list[tuple[moderngl.Program, tuple]]:
        """(program, scissor rectangles) pairs that together cover a width x
        height image exactly once: the culling variants of the scene's
        program with `defines` added (the adaptive sampler's ADAPTIVE
        variants), or that one program over the whole image when the scene
        is not culled.  Every variant draws the same image as the full one
        (tests/test_culling.py), so which of them a pixel gets, or whether a
        variant is ready yet, never changes a result.  Variants compile
        COMPILES_PER_DRAW per call, or all of them now with compile_all."""
        if not self.culls():
            return [(self.variant(**defines) if defines else self._main, ((0, 0, width, height),))]
        return self._culled(width, height, defines, compile_all)

    def _culled(self, width: int, height: int, extra: dict | None = None,
                compile_all: bool = False, compile: bool = True) -> list[tuple[moderngl.Program, tuple]]:
        """The culling plan of this camera and size, its programs (with the
        `extra` defines) compiled."""
        extra = dict(extra or {})
        key = culling.plan_key(self.scene, width, height)
        if key != self._plan_key:
            self._plan_key = key
            self._plan_groups = culling.plan(self.scene, width, height).groups
            self._plans = {}
        extra_key = tuple(sorted(extra.items()))
        done = self._plans.get(extra_key)
        if done is not None:
            return done
        # Compile at most COMPILES_PER_DRAW new variants per call (a compile
        # costs up to seconds on llvmpipe), none with compile=False; until
        # its variant is ready a group is drawn with the ready variant of
        # the fewest objects that holds all of its own (exact there too: it
        # only tests more objects), or else the scene's full shader, which
        # is exact everywhere.
        def full() -> moderngl.Program:   # only when a group draws with it: none may
            return self.variant(**extra) if extra else self._main
        everything = tuple(range(len(self.scene.objects)))
        budget = len(self._plan_groups) if compile_all else (self.COMPILES_PER_DRAW if compile else 0)
        compiled, complete, progs = 0, True, []
        for subset, rects in self._plan_groups:
            if subset == everything:
                prog = full()
            else:
                defines = {**shader_defines(self.scene, True, self.fresnel, subset), **self.extra_defines, **extra}
                k = self._program_key(defines)
                if k in self._subset_programs or compiled < budget:
                    compiled += k not in self._subset_programs
                    prog = self._subset_program(k, defines, subset, extra_key, keep=[p for p, _ in progs])
                else:
                    complete = False
                    prog = self._ready_superset(subset, extra_key) or full()
            progs.append((prog, rects))
        if complete:
            self._plans[extra_key] = progs
        return progs

    def _ready_superset(self, subset: tuple[int, ...], extra_key: tuple) -> moderngl.Program | None:
        """The compiled variant (with the same extra defines) of the fewest
        objects that include `subset`, or None.  A variant compiled for an
        earlier scene counts only if it is still the one its objects would
        get (its defines list each object's shape by index)."""
        want = set(subset)
        for key, (objs, ek) in sorted(self._subset_of.items(), key=lambda kv: len(kv[1][0])):
            if ek == extra_key and want <= objs:
                defines = {**shader_defines(self.scene, True, self.fresnel, tuple(sorted(objs))),
                           **self.extra_defines, **dict(extra_key)}
                if self._program_key(defines) == key:
                    # most recently used now: a compile later in the same
                    # call evicts the least recent, never what it draws with
                    prog = self._subset_programs.pop(key)
                    self._subset_programs[key] = prog
                    return prog
        return None

    def _subset_program(self, key: tuple, defines: dict, subset: tuple[int, ...] = (),
                        extra_key: tuple = (), keep: list | None = None) -> moderngl.Program:
        """A culling variant, from a cache of the SUBSET_PROGRAMS most
        recently used (a viewer orbiting a scene meets new subsets all the
        time; the GL objects must not pile up).  Never evicted: the programs
        of complete plans and `keep` (what the caller draws with next); when
        everything is in use the cache holds more for a while."""
        prog = self._subset_programs.pop(key, None)
        if prog is None:
            prog = build_program(self.ctx, defines=defines, sources=self.shader_files)
            self.programs_built += 1
            self._subset_of[key] = (frozenset(subset), extra_key)
        self._subset_programs[key] = prog          # most recent last
        in_use = {id(p) for plan in self._plans.values() for p, _ in plan} | {id(p) for p in keep or ()}
        while len(self._subset_programs) > self.SUBSET_PROGRAMS:
            old_key = next((k for k, p in self._subset_programs.items() if id(p) not in in_use and k != key), None)
            if old_key is None:
                break
            old = self._subset_programs.pop(old_key)
            self._subset_of.pop(old_key, None)
            vao = self._vao_for.pop(id(old), None)
            if vao is not None:
                vao.release()
            old.release()
        return prog

    def vao_of(self, prog: moderngl.Program) -> moderngl.VertexArray:
        vao = self._vao_for.get(id(prog))
        if vao is None:
            vao = self.ctx.vertex_array(prog, [])
            self._vao_for[id(prog)] = vao
        return vao

    def bind(self, prog: moderngl.Program, width: int, height: int, offset: tuple[float, float]) -> None:
        """Bind the scene block, the sky (texture unit 0) and the per-draw
        uniforms of one sample to `prog` (a variant of the scene's program)."""
        prog["SceneBlock"].binding = 0
        self._ubo.bind_to_uniform_block(0)
        self._sky.use(location=0)
        c = self.scene.camera
        key = (tuple(c.position), tuple(c.target), c.fov, width, height)
        if self._camera_key != key:      # computed once per camera and size
            self._camera_key, self._camera = key, camera_uniforms(self.scene, width, height)
        values = {"skyImage": 0, "imageSize": (float(width), float(height)),
                  "sampleOffset": (float(offset[0]), float(offset[1])), **self._camera}
        for name, v in values.items():
            if name in prog:
                prog[name].value = v

    def tiles(self, width: int, height: int, side: int | None = None) -> list[tuple[int, int, int, int]]:
        t = min(self.tile, side) if side else self.tile
        return [(x, y, min(t, width - x), min(t, height - y))
                for y in range(0, height, t) for x in range(0, width, t)]

    def _target(self, width: int, height: int) -> moderngl.Framebuffer:
        """The RGBA32F framebuffer that offscreen renders sum their samples
        in, kept between renders of the same size (making one costs as much
        as tracing the sky of a 1280x720 frame on llvmpipe)."""
        if self._fbo is None or self._fbo.size != (width, height):
            self._release_target()
            self._fbo_tex = self.ctx.texture((width, height), 4, dtype="f4")
            self._fbo = self.ctx.framebuffer(color_attachments=[self._fbo_tex])
        return self._fbo

    def _release_target(self) -> None:
        self._release_resume()          # its framebuffers hold the texture
        for obj in (self._fbo, self._fbo_tex):
            if obj is not None:
                obj.release()
        self._fbo = self._fbo_tex = None
        self._readback = None

    def _read_rgb(self, fbo: moderngl.Framebuffer, samples: int = 1) -> np.ndarray:
        """(H, W, 3) float32 of the framebuffer divided by `samples`, first
        row = top, a new array.  Read as RGB: the driver drops alpha faster
        than numpy copies a strided view.  Read into a buffer kept with the
        target: a new 11 MB block for every 1280x720 read-back cost its page
        faults: 2-6 ms of a 112-119 ms frame (Mesa 25)."""
        width, height = fbo.size
        size = width * height * 12
        if self._readback is None or len(self._readback) != size:
            self._readback = bytearray(size)
        fbo.read_into(self._readback, components=3, dtype="f4")
        raw = np.frombuffer(self._readback, np.float32).reshape(height, width, 3)
        if samples == 1:
            return raw[::-1].copy()
        return np.divide(raw[::-1], np.float32(samples))

    def takes_footprint(self, samples: int) -> bool:
        """Whether render() of `samples` samples takes footprint samples
        unless told otherwise: with more than one sample (one is the spec's
        centred point sample) where the scene has a checkered plane."""
        return samples > 1 and footprint_default(self.scene)

    def footprint_sampler(self, width: int, height: int):
        """A FootprintSampler of this size whose footprint mask holds, for the
        current camera, every pixel whose four corner rays meet one
        checkered plane first, with its closed-form share: what the
        FOOTPRINT_SAMPLES variants read.  Kept for the next render of this
        size (its targets cost as much to make as a sample of the sky)."""
        s = self._footprints
        if s is None or (s.width, s.height) != (width, height):
            if s is not None:
                s.release()
            s = self._footprints = FootprintSampler(self, width, height)
            s.sync_draws = False
        drain(s.direct_footprints())
        return s

    def render(self, width: int, height: int, samples: int | None = None, seed: int = 0,
               progress: Callable[[int, int], None] | None = None,
               footprint: bool | None = None) -> np.ndarray:
        """(H, W, 3) float32 linear RGB, exposure applied, first row = top,
        never below 0 (clamp_radiance).

        footprint: footprint samples (shaders/lib/footprint.glsl): where a
        pixel's four corner rays all meet one checkered plane first, a
        camera ray that meets that plane takes the checker's two colours
        mixed by their exact shares of the pixel's square (the box filter
        every pixel converges to) instead of the colour at its point; its
        lighting stays its own.  The same limit, reached sooner: the checker
        costs no samples.  None: takes_footprint (more than one sample, a
        checkered plane)."""
        samples = samples or self.scene.render.samples
        offsets = sample_offsets(samples, seed)
        if footprint is None:
            footprint = self.takes_footprint(samples)
        fp = self.footprint_sampler(width, height) if footprint else None
        footprint_defines = FootprintSampler.FOOTPRINT_SAMPLES if fp is not None else {}
        resume = None
        self._resume_budget = self.RESUME_BUDGET    # halved where a pass meets the loop limit
        self.last_render_resumed = self._force_resume or self.resumes()
        # a scene with glass draws in one pass a pixel and checks that the
        # driver's loop limit cut no tree (-inf); if one was cut, the image
        # is drawn again in resumable passes
        check = self.cut_check and not self.last_render_resumed and bool(self._defines.get("HAS_DIELECTRIC"))
        if self.last_render_resumed:
            # one program over the whole image (no culling variants: a deep
            # tree costs far more than the objects it could skip)
            resume = self.variant(RESUME=1, **footprint_defines)
        elif check or fp is not None:
            groups = self.programs_for(width, height, compile_all=True,
                                       **({"CUT_CHECK": 1} if check else {}), **footprint_defines)

        def bind_check(p: moderngl.Program) -> None:
            if fp is not None:
                fp.bind_footprint(p)
            if "loopProbe" in p:
                p["loopProbe"].value = 2
        ctx = self.ctx
        fbo = self._target(width, height)
        fbo.use()
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        ctx.blend_equation = moderngl.FUNC_ADD
        tiles = self.tiles(width, height) if resume is None else self.tiles(width, height, self.RESUME_TILE)
        # progress in thousandths of a tile where a tile takes passes
        scale = 1 if resume is None else 1000
        total, done = samples * len(tiles) * scale, 0

        def tick(part: float) -> None:
            if progress is not None:
                progress(done + min(int(scale * part), scale - 1), total)
        try:
            for i, off in enumerate(offsets):
                # The first sample's tiles cover every pixel: written as they
                # are (no clear needed), the later ones added.
                if i == 0:
                    ctx.disable(moderngl.BLEND)
                elif i == 1:
                    ctx.enable(moderngl.BLEND)
                for rect in tiles:
                    if resume is not None:
                        self._draw_resumable(resume, width, height, off, rect, i > 0,
                                             None if fp is None else fp.bind_footprint, tick)
                    elif fp is None and not check:
                        self.draw_sample(width, height, off, rect)
                    else:
                        self.draw_groups(groups, width, height, off, rect, bind_check)
                    # Wait for each draw: the queue never holds more than one
                    # tile, so Ctrl-C (checked between draws) stops at once and
                    # the progress bar is truthful.
                    ctx.finish()
                    interrupt.check()
                    done += scale
                    if progress is not None:
                        progress(done, total)
        finally:
            ctx.disable(moderngl.BLEND)
        image = self._read_rgb(fbo, samples)
        # a sample cut short is -inf (shaders/render.frag, CUT_CHECK), and
        # stays -inf in the sum (or NaN where it met an inf); about 1 ms at
        # 1280x720.  (Not "anything below 0": a footprint sample is a control
        # variate, and a pixel's mean of few of them can be below 0, which
        # sent the default scene's 2-sample render to the passes, 5x slower.)
        if check and cut_marks(image[..., 0]).any():
            self._force_resume = True
            try:
                return self.render(width, height, samples, seed, progress, footprint)
            finally:
                self._force_resume = False
        return clamp_radiance(image)

    #: the driver's limits on one draw (gpu/driver.py says why each is what it is)
    RESUME_BUDGET = driver.RESUME_BUDGET
    RESUME_TILE = driver.RESUME_TILE
    RESUME_AT_ONCE = driver.RESUME_AT_ONCE
    #: Whether render() checks a one-pass image of a glass scene for trees
    #: cut short (False: trust it, as the viewer does; for measuring the check).
    cut_check = True

    def resumes(self) -> bool:
        """Whether render() goes straight to resumable passes: a scene with
        glass whose tree may be far beyond what one draw holds.  Depth d
        holds at most 2^(d-1) nodes, and at most 1 / min_weight: a node's
        children weigh at most what it weighs (R + (1 - R) T <= 1), so the
        weights at one depth add up to 1 at most.  The driver's limit counts
        loop iterations, and every light adds to a node's (measured on
        llvmpipe: two slabs at depth 9, 511 nodes, came out whole in one draw
        with 1 to 32 lights and were cut with 64), so every 8 lights count as
        one node more.  Below the bound, render() draws one pass a pixel and
        checks for a cut (CUT_CHECK), which the shipped scenes, with bounds
        up to 4,600, never meet: their real trees are a few dozen rays.
        (Without glass a tree is a chain of at most max_depth nodes.)"""
        if not self._defines.get("HAS_DIELECTRIC"):
            return False
        r = self.scene.render
        per_depth = 1.0 / r.min_weight if r.min_weight > 0 else float("inf")
        nodes = sum(min(2.0 ** (d - 1), per_depth) for d in range(1, r.max_depth + 1))
        return nodes * (1.0 + len(self.scene.lights) / 8.0) > self.RESUME_AT_ONCE

    def one_draw_warning(self, what: str) -> str | None:
        """A line for stderr where `what` (the viewer, an adaptive render,
        the cost view) traces each tree in one draw although the scene's
        trees may be far beyond one draw (resumes): there the driver's loop
        limit may cut them (render() alone traces them whole).  None where
        it cannot happen."""
        if not self.resumes():
            return None
        r = self.scene.render
        return (f"glassray: warning: with max depth {r.max_depth} and min weight {r.min_weight:g} this scene's "
                f"ray trees may hold more rays than one draw traces on this OpenGL driver; {what} traces each "
                "tree in one draw and may lose its lightest branches (a uniform 'glassray render' traces "
                "them whole)")

    def _resume_targets(self, width: int, height: int) -> list[moderngl.Framebuffer]:
        """Two framebuffers of the accumulation texture and a resume-state
        texture each (RGBA32UI): a pass reads one's state and writes the
        other's."""
        key = (width, height)
        if getattr(self, "_resume_key", None) != key:
            self._release_resume()
            self._resume_key = key
            self._resume_tex = [self.ctx.texture((width, height), 4, dtype="u4") for _ in range(2)]
            for t in self._resume_tex:
                t.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._resume_fbos = [self.ctx.framebuffer(color_attachments=[self._fbo_tex, t]) for t in self._resume_tex]
        return self._resume_fbos

    def _release_resume(self) -> None:
        for obj in (*getattr(self, "_resume_fbos", ()), *getattr(self, "_resume_tex", ())):
            obj.release()
        self._resume_fbos, self._resume_tex, self._resume_key = [], [], None

    def _draw_resumable(self, prog: moderngl.Program, width: int, height: int, offset, rect,
                        add: bool, bind: Callable[[moderngl.Program], None] | None,
                        tick: Callable[[float], None] | None = None) -> None:
        """One sample of the tile `rect` with the RESUME program: passes of
        at most RESUME_BUDGET nodes per pixel (half as many after each pass
        that met the loop limit) until every pixel's tree is done, each pass
        adding its light (additive blending; the sample's
        first pass writes where `add` is false), Ctrl-C taken between them."""
        fbos = self._resume_targets(width, height)
        unit = 7                 # the sky is on unit 0, the footprint mask on its own
        w, h = rect[2], rect[3]
        k, last = 0, None
        while True:
            src, dst = self._resume_tex[(k + 1) % 2], fbos[k % 2]
            dst.use()
            if k == 1 and not add:
                self.ctx.enable(moderngl.BLEND)

            def bind_all(p, k=k, src=src):
                if bind is not None:
                    bind(p)
                src.use(location=unit)
                for name, v in (("resumeIn", unit), ("resumeFirst", int(k == 0)),
                                ("resumeBudget", self._resume_budget), ("loopProbe", 2)):
                    if name in p:
                        p[name].value = v

            self.draw_groups([(prog, ((0, 0, width, height),))], width, height, offset, rect, bind_all)
            self.ctx.finish()
            interrupt.check()
            state = np.frombuffer(dst.read(viewport=rect, components=4, attachment=1, dtype="u4"), np.uint32)
            flags = state.reshape(h * w, 4)[:, 3]
            left = np.count_nonzero(flags)
            if not left:
                break
            if (flags == 2).any():
                # the pass reached the driver's loop limit (the shader hands
                # the cut nodes back): fewer nodes a pass from now on
                if self._resume_budget == 1 and last is not None and np.array_equal(state, last):
                    raise RuntimeError("a node of this scene's ray tree takes more loop iterations than "
                                       "this OpenGL driver runs in one shader invocation")
                self._resume_budget = max(1, self._resume_budget // 2)
            last = state
            if tick is not None:
                tick(1.0 - left / (h * w))      # the share of the tile's trees done
            k += 1
        if not add:
            self.ctx.disable(moderngl.BLEND)
        self._target(width, height).use()

    def first_hits(self, width: int, height: int, offset: tuple[float, float] = (0.5, 0.5)):
        """Per pixel, the first geometric surface along the camera ray through
        `offset`: (t (H, W) float32, inf where nothing is hit; object index
        (H, W) int, -1 where nothing is hit; unit outward normal (H, W, 3)).
        For comparing intersection code ray by ray with the reference."""
        hit, normal = (self._debug_pass(mode, width, height, offset) for mode in (1, 2))
        obj = hit[..., 1].round().astype(np.int32)
        # back to the scene's own units (an exact power of two; see set_scene),
        # finite wherever something is hit
        t = np.ldexp(hit[..., 0].astype(np.float64), -self.length_exponent)
        t = np.where(obj >= 0, np.minimum(t, F32_MAX), np.inf).astype(np.float32)
        return t, obj, np.ascontiguousarray(normal[..., :3])

    def ray_cost(self, width: int, height: int, offset: tuple[float, float] = (0.5, 0.5)) -> np.ndarray:
        """(H, W) rays traced per pixel (camera, reflected, refracted, shadow)."""
        return self._debug_pass(3, width, height, offset)[..., 0].round().astype(np.int32)

    def draw_view(self, mode: int, fbo: moderngl.Framebuffer, width: int, height: int,
                  offset: tuple[float, float] = (0.5, 0.5), rects=None) -> None:
        """Draw one sample of a VIEW_MODE variant (shaders/debug_view.frag)
        of a width x height image into `fbo`, without blending: over every
        pixel, or over `rects` (x, y, w, h, bottom-left origin).  Mode 1
        writes (t, object index, ...) per pixel: the viewer's pick and
        outline read it from an RG32F target of their own."""
        main = self.program
        self.program = self.variant(VIEW_MODE=mode)
        try:
            fbo.use()
            self.ctx.disable(moderngl.BLEND)
            for rect in self.tiles(width, height) if rects is None else rects:  # tiles cover every pixel
                self.draw_sample(width, height, offset, rect)
        finally:
            self.program = main

    def _debug_pass(self, mode: int, width: int, height: int, offset) -> np.ndarray:
        """One sample of a VIEW_MODE variant of the shader, (H, W, 4) top row first."""
        fbo = self._target(width, height)
        self.draw_view(mode, fbo, width, height, offset)
        raw = fbo.read(components=4, dtype="f4")
        return np.frombuffer(raw, np.float32).reshape(height, width, 4)[::-1]

    def release(self) -> None:
        self._release_target()
        if self._footprints is not None:
            self._footprints.release()
            self._footprints = None
        for vao in self._vao_for.values():
            vao.release()
        for prog in (*self._programs.values(), *self._subset_programs.values()):
            prog.release()
        self._subset_programs.clear()
        self._subset_of.clear()
        for res in (self._ubo, self._sky):
            if res is not None:
                res.release()
        self._vao_for.clear()
        self._programs.clear()
        self._ubo = self._sky = None
