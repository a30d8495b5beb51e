"""Footprint samples' mask (shaders/lib/footprint.glsl): for one image size,
which pixels take the checker of a plane by its exact share of the pixel's
square instead of at a point, with each one's closed-form share, and the
GPU passes that make it.

Where a pixel's four corner rays meet one checkered plane first (and so,
the set of directions that meet a plane being convex, does its whole
square, unless another object pokes in), a camera ray that meets that plane
takes the checker's colours mixed by their exact shares of the pixel's
square (the box filter, in closed form) instead of the colour at its point;
its lighting stays its own.  A uniform render (Renderer.render, the
viewer's accumulation) takes them through FootprintSampler.direct_footprints
and the FOOTPRINT_SAMPLES variants; the adaptive sampler
(viewer/adaptive/sampler.py) builds on FootprintSampler: its first and
corner passes, and the chain footprints it gives set_footprint.
"""

from __future__ import annotations

import moderngl
import numpy as np

#: Scenes with this many objects or more take point samples only (the
#: footprint mask held k + 1 in an 8-bit texel when this was set; it is a
#: float texel now, which could name more, but no scene that large was
#: measured).
MAX_FOOTPRINT_OBJECTS = 255
#: How a pixel's footprint samples take the checker (the first pass reports
#: it): over the whole pixel, exactly, or along each sample's row.
FOOTPRINT_EXACT, FOOTPRINT_ROWS = 2, 1
#: The closed form of a pixel's checker share (footprint.glsl's
#: pixelCoverage) takes at most this many checker corners inside the pixel
#: and this many checker lines across it; beyond, each sample takes the
#: checker's exact average along its own row.  The first pass computes each
#: pixel's share once and the list passes read it, so the limits cost one
#: loop per pixel, not per entry.  Measured (default scene, 320x180, budget
#: 6; RMSE against uniform 64's): 16 and 32 left 3653 pixels near the
#: horizon on rows, which took 23 samples each and held 8% of the squared
#: error (1.15x); 400 and 100: 1459 pixels, 0.97x; 1600 and 200: 940,
#: 0.95x.  The first pass took 101, 105 and 113 ms of CPU.
MAX_PIXEL_CORNERS = 400
MAX_PIXEL_LINES = 100
#: Chain footprints per row of their texture (three texels each): a 1280x720
#: image's (46,000 on glass-sphere) in 45 rows, where one texel per pixel
#: would upload 44 MB.
CHAIN_ENTRIES_PER_ROW = 1024
#: The most fragments one draw call traces (the renderer's 512x512 tiles: no
#: draw long enough to trip a GPU watchdog).
FRAGMENTS_PER_DRAW = 512 * 512
#: With FootprintSampler.sync_draws off (offscreen renders): pixel-samples
#: that may be queued before the driver is made to finish them (Ctrl-C,
#: taken between draws, then waits for at most this much).
MAX_QUEUED_FRAGMENTS = 4 * FRAGMENTS_PER_DRAW


# numpy reduces a list of arrays (stacked into one first) an order of
# magnitude slower than it applies a ufunc pairwise: fold does the latter.
def fold(ufunc, arrays) -> np.ndarray:
    """ufunc applied pairwise over a list of arrays (ufunc.reduce of their stack)."""
    out = arrays[0]
    for a in arrays[1:]:
        out = ufunc(out, a)
    return out


def pixel_corners(a: np.ndarray) -> list[np.ndarray]:
    """The four (H, W, ...) views of an (H + 1, W + 1, ...) corner grid:
    each pixel's top-left, top-right, bottom-left and bottom-right corner."""
    return [a[:-1, :-1], a[:-1, 1:], a[1:, :-1], a[1:, 1:]]


def checker_sizes(scene) -> np.ndarray:
    """(objects + 1,): the checker size of each object whose checker's two
    colours (or emissions) differ, inf for the others and for the last
    entry (the sky's -1)."""
    size = np.full(len(scene.objects) + 1, np.inf)
    for k, o in enumerate(scene.objects):
        m = scene.materials[o.material]
        c = m.checker
        if c is not None and (tuple(c.color) != tuple(m.color)
                              or (c.emission is not None and tuple(c.emission) != tuple(m.emission))):
            size[k] = c.size
    return size


def checkered_planes(scene) -> np.ndarray:
    """(objects + 1,) bool: which objects are planes with a checker whose two
    colours differ (the last entry, for the sky's -1, is False)."""
    planes = np.array([o.type == "plane" for o in scene.objects] + [False])
    return planes & np.isfinite(checker_sizes(scene))


def footprint_default(scene) -> bool:
    """Whether adaptive renders of `scene` take footprint samples unless
    told otherwise: where it has a checkered plane and few enough objects
    for the footprint mask's texels."""
    return bool(checkered_planes(scene).any()) and len(scene.objects) < MAX_FOOTPRINT_OBJECTS


def footprint_planes(scene, corner_obj: np.ndarray) -> np.ndarray:
    """(H, W) int: for each pixel whose four corner rays all meet one
    checkered plane first (corner_obj (H + 1, W + 1)), that plane's object
    index, else -1.  There footprint samples replace point samples.  The
    directions that meet a plane are a convex set, so every ray of such a
    pixel meets that plane; only another object poking in between the
    corners could cover part of it (then a sample that meets the other
    object is a point sample, and the flags see the other object in the
    centre ray)."""
    four = pixel_corners(corner_obj)
    hi, lo = fold(np.maximum, four), fold(np.minimum, four)
    return np.where((hi == lo) & checkered_planes(scene)[np.where(lo >= 0, lo, -1)], lo, -1)


def drain(gen):
    """Run a generator (a pass of FootprintSampler or AdaptiveSampler, an
    adaptive render's flags) to its end without pausing: what it returns."""
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value


class FootprintSampler:
    """The footprint mask of one image size and the passes that make it:
    ``corner_objects`` traces the first hit of the camera ray through every
    pixel corner, ``set_footprint`` uploads the mask (and any chain
    footprints) that a FOOTPRINT_AA variant reads through
    ``bind_footprint``, ``share_pass`` computes each footprint pixel's
    closed-form share into it; ``direct_footprints`` does all three for a
    uniform render.  Every pass is drawn in bands of rows into RGBA32F
    targets kept for the sampler's life (_mrt_pass), a yield per draw; the
    adaptive sampler (viewer/adaptive/sampler.py) draws its first and corner
    passes with them too."""

    #: the defines of every pass with footprint samples (shaders/lib/sample.glsl): the
    #: closed form's limits
    FOOTPRINT = {"FOOTPRINT_AA": 1, "MAX_PIXEL_CORNERS": MAX_PIXEL_CORNERS, "MAX_PIXEL_LINES": MAX_PIXEL_LINES}
    #: a uniform render's samples with footprint samples (Renderer.render),
    #: and the pass that computes the shares they read (share_pass)
    FOOTPRINT_SAMPLES = {**FOOTPRINT, "FOOTPRINT_SHARES": 1, "FOOTPRINT_DIRECT_ONLY": 1}
    FOOTPRINT_SHARE_PASS = {**FOOTPRINT, "FOOTPRINT_SHARE_PASS": 1, "FOOTPRINT_DIRECT_ONLY": 1}
    #: the texture units of the footprint mask and of the chain footprints
    FOOTPRINT_UNIT = 3
    FOOTPRINT_CHAIN_UNIT = 4

    def __init__(self, renderer, width: int, height: int):
        self.renderer = renderer
        self._footprint_tex = None           # the mask set_footprint gave (None: point samples)
        self._footprint_texels = None        # its texels (H, W, 2): code, the first pass's share
        self._chain_tex = None               # its chain footprints (zeros: none)
        self.ctx: moderngl.Context = renderer.ctx
        self.width, self.height = width, height
        self._mrt: dict[tuple[tuple[int, int], int], moderngl.Framebuffer] = {}
        #: pixel-samples one draw call may trace; read before every draw, so
        #: the viewer can fit draws into its frame budget as it goes
        self.fragments_per_draw = FRAGMENTS_PER_DRAW
        self.last_draw_fragments = 0     # pixel-samples the latest draw traced
        #: finish every draw before its yield: the viewer times each draw to
        #: fit its frame.  An offscreen render (render_adaptive) turns it
        #: off: the driver then draws while Python prepares the next draw,
        #: and finishes at the read-back or after MAX_QUEUED_FRAGMENTS
        #: (measured, whole renders at 320x180, interleaved: 7-19% less
        #: wall time and 3-7% less CPU time, most at larger budgets; the
        #: images bit for bit the same)
        self.sync_draws = True
        self._queued = 0                 # pixel-samples drawn since the last finish

    def set_footprint(self, planes: np.ndarray | None, chain=None) -> None:
        """Footprint samples (shaders/lib/footprint.glsl) from now on: on the
        plane `planes` gives for each pixel ((H, W) object index, -1: point
        samples; top row first; see footprint_planes) and, where it gives
        none, through the chain footprints `chain` (viewer/adaptive/chains.py's
        ChainFootprints: flat pixel indices `pixels` and their three texels
        each, `texels` (n, 12); None: none), or point samples everywhere
        (planes None)."""
        for tex in (self._footprint_tex, self._chain_tex):
            if tex is not None:
                tex.release()
        self._footprint_tex = self._chain_tex = None
        if planes is None:
            return
        if planes.max() >= MAX_FOOTPRINT_OBJECTS:
            raise ValueError(f"footprint samples take object indices below {MAX_FOOTPRINT_OBJECTS}")
        # texel (RG32F, rows bottom first): in r k + 1 for a directly seen
        # plane k, -(e + 1) for chain footprint e, 0 for point samples (whole
        # numbers below 2^24: exact in a float); in g the pixel's share, -1
        # until the first pass has computed it (footprint.glsl)
        code = (planes + 1).astype(np.float32).ravel()
        n = 0 if chain is None else len(chain.pixels)
        if n:
            code[chain.pixels] = -1.0 - np.arange(n, dtype=np.float32)
        texels = np.full((self.height, self.width, 2), -1.0, np.float32)
        texels[..., 0] = code.reshape(self.height, self.width)[::-1]
        self._footprint_texels = texels
        self._footprint_tex = self.ctx.texture((self.width, self.height), 2, texels.tobytes(), dtype="f4")
        self._footprint_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        # the chain footprints, compact: entry e at texels (3 (e % C) + r, e // C)
        c = CHAIN_ENTRIES_PER_ROW
        rows = max(1, -(-n // c))
        texels = np.zeros((rows * c, 12), np.float32)
        if n:
            texels[:n] = chain.texels
        self._chain_tex = self.ctx.texture((3 * c, rows), 4, texels.tobytes(), dtype="f4")
        self._chain_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)

    def bind_footprint(self, prog) -> None:
        """Bind the footprint mask and chain footprints set_footprint gave to
        `prog` (a FOOTPRINT_AA variant), if it reads them."""
        if self._footprint_tex is not None and "footprintMask" in prog:
            self._footprint_tex.use(location=self.FOOTPRINT_UNIT)
            prog["footprintMask"].value = self.FOOTPRINT_UNIT
            if "footprintChain" in prog:
                self._chain_tex.use(location=self.FOOTPRINT_CHAIN_UNIT)
                prog["footprintChain"].value = self.FOOTPRINT_CHAIN_UNIT
                if "chainEntriesPerRow" in prog:
                    prog["chainEntriesPerRow"].value = CHAIN_ENTRIES_PER_ROW

    #: the channels of the ADAPTIVE_FIRST variants' outputs that are read
    #: back: (sum L, 1), L.L, (t, object, rays, the pixel's footprint
    #: share), (checker part, footprint kind), chain leaf
    MRT_CHANNELS = (4, 1, 4, 4, 4)

    def _mrt_target(self, size, count: int) -> moderngl.Framebuffer:
        """The first `count` of the ADAPTIVE_FIRST variants' five outputs
        (sums, square, first interaction, the checker's part, the chain
        leaf) as RGBA32F targets of `size`, kept for the sampler's life: at
        1280x720 making them costs as much as a sample of the sky.  (An
        output with no target is not written.)"""
        fbo = self._mrt.get((size, count))
        if fbo is None:
            texs = [self.ctx.texture(size, 4, dtype="f4") for _ in range(count)]
            fbo = self._mrt[(size, count)] = self.ctx.framebuffer(color_attachments=texs)
        return fbo

    def _drawn(self, fragments: int) -> None:
        """After a draw of `fragments` pixel-samples: finish it now, or (with
        sync_draws off) once MAX_QUEUED_FRAGMENTS are waiting."""
        self._queued += int(fragments)
        if self.sync_draws or self._queued >= MAX_QUEUED_FRAGMENTS:
            self.ctx.finish()
            self._queued = 0

    def _mrt_pass(self, size, band_programs, offset, count: int):
        """Draw one sample of the given variants (outputs as the
        ADAPTIVE_FIRST ones': MRT_CHANNELS) into the first
        `count` targets of `size`, in bands of rows (one draw call each, a
        yield after each); band_programs() gives the (program, rects) to
        draw a band with.  Returns those attachments, top row first."""
        ctx, (w, h) = self.ctx, size
        fbo = self._mrt_target(size, count)
        try:
            top = 0                                   # bands of rows from the top cover every pixel
            while top < h:
                rows = max(1, min(h - top, self.fragments_per_draw // w, 512))
                band = (0, h - top - rows, w, rows)
                # (re)bound before every draw: between yields the caller may
                # have used the context for something else (the viewer)
                fbo.use()
                ctx.disable(moderngl.BLEND)
                # each program bound (renderer.bind), then its footprint
                # mask, and drawn over its rectangles within the band
                self.renderer.draw_groups(band_programs(), self.width, self.height, offset, band,
                                          self.bind_footprint)
                self.last_draw_fragments = rows * w
                self._drawn(rows * w)
                top += rows
                yield
            # only the channels the attachments use
            return [np.frombuffer(fbo.read(attachment=k, components=c, dtype="f4"), np.float32)
                    .reshape(h, w, c)[::-1] for k, c in enumerate(self.MRT_CHANNELS[:count])]
        finally:
            ctx.scissor = None

    @staticmethod
    def _first_hits(hit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        obj = np.rint(hit[..., 1]).astype(np.int32)
        t = np.where(obj >= 0, hit[..., 0], np.inf).astype(np.float64)
        return t, obj

    def corner_objects(self):
        """The object the camera ray through every pixel corner meets first,
        (H + 1, W + 1) int, -1 for none, top-left corner first: the corner
        grid of corner_pass, but first geometric hits only (the VIEW_MODE 1
        variant: no shading, no further rays), which is all footprint_planes
        needs.  (Where a plane is the first surface it is also the first
        interaction.)  A generator, a yield per draw."""
        full = [(self.renderer.variant(VIEW_MODE=1), ((0, 0, self.width + 1, self.height + 1),))]
        out = yield from self._mrt_pass((self.width + 1, self.height + 1), lambda: full, (0.0, 1.0), 1)
        return self._first_hits(out[0])[1]

    def share_pass(self):
        """Each footprint pixel's closed-form share into the mask, as the
        first pass computes it, but with no tracing: for renders whose
        samples all read it (FOOTPRINT_SAMPLES).  A generator, a yield per
        draw."""
        if self._footprint_tex is None:
            return
        full = [(self.renderer.variant(**self.FOOTPRINT_SHARE_PASS), ((0, 0, self.width, self.height),))]
        out = yield from self._mrt_pass((self.width, self.height), lambda: full, (0.5, 0.5), 1)
        self._footprint_texels[..., 1] = out[0][::-1, :, 1]
        self._footprint_tex.write(self._footprint_texels.tobytes())

    def direct_footprints(self):
        """Footprint samples for a uniform render (Renderer.render, the
        viewer's accumulation): the mask holds every pixel whose four corner
        rays meet one checkered plane first, with its closed-form share,
        for the current camera.  Direct footprints only: their shares are
        exact, so the render still converges to the box-filtered pixel
        (chain footprints allow a small bias, CHAIN_TOLERANCE, which an
        adaptive render's own samples bound).  A generator, a yield per
        draw."""
        obj = yield from self.corner_objects()
        self.set_footprint(footprint_planes(self.renderer.scene, obj))
        yield from self.share_pass()

    def release(self) -> None:
        self.set_footprint(None)
        for fbo in self._mrt.values():
            for tex in fbo.color_attachments:
                tex.release()
            fbo.release()
        self._mrt.clear()
