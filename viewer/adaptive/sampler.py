"""The GPU side of adaptive anti-aliasing (viewer/adaptive/render.py) for
one image size: the first pass, the corner rays, and the list passes that
trace more samples of listed pixels only.

The GPU traces only listed pixels: a small framebuffer whose fragment
(x, y) traces the samples of the image pixel stored at (x, y) of a list
texture (its first sample index and count there too; the offsets come from
a texture), in coherent order (Z-order inside 8x8 image tiles, 4x4 blocks
of the list), one run of the list per culling group (viewer/gpu/culling.py:
each run is drawn by the shader compiled for the objects its tiles can
meet) and per sample count.  A short run is dealt over several bands of
64 rows (llvmpipe shades each 64x64 square of a framebuffer on one
thread), and where few pixels take a count, each one's samples are split
over several entries (the last rounds: a few glass pixels with 32 samples
each filled a few SIMD lanes of one thread).  Samples follow sampling.progressive_offsets,
so every prefix is evenly spread; everything is deterministic for a seed.

The footprint mask and the passes that make it are FootprintSampler's
(viewer/gpu/footprint.py), which AdaptiveSampler builds on; the list's
layout is viewer/adaptive/pixel_lists.py's.
"""

from __future__ import annotations

import moderngl
import numpy as np

from ..gpu.footprint import FootprintSampler
from .estimators import Sums
from .pixel_lists import LIST_BLOCK, entry_samples, list_layout, split_factor

#: Samples traced per fragment and draw call at most.
MAX_BATCH = 32


class AdaptiveSampler(FootprintSampler):
    """The GPU side for one image size: ``first_pass`` traces sample 0 of
    every pixel (with the first interaction of each camera ray),
    ``corner_pass`` the rays through the pixel corners, ``add_samples``
    more samples of a list of pixels only.  Results come back as arrays;
    the sums are kept by the caller.  Every pass draws each group of screen
    tiles with the renderer's culling variant for it."""

    FIRST = {"ADAPTIVE": 1, "ADAPTIVE_FIRST": 1}
    LIST = {"ADAPTIVE": 1, "ADAPTIVE_LIST": 1}
    #: the first and list passes' defines with footprint samples (shaders/lib/sample.glsl):
    #: in the list passes the shares the first pass computed (read from the
    #: footprint mask, not computed per entry)
    FOOTPRINT_FIRST = {**FIRST, **FootprintSampler.FOOTPRINT}
    FOOTPRINT_LIST = {**LIST, **FootprintSampler.FOOTPRINT, "FOOTPRINT_SHARES": 1}

    def __init__(self, renderer, width: int, height: int, footprint: bool = False):
        super().__init__(renderer, width, height)
        #: whether set_footprint may turn footprint samples on (their variants
        #: are the ones compile() makes)
        self.footprint = bool(footprint)
        self._list_tex = None
        self._list_fbo = None
        self._list_targets: list = []
        self._list_size = (0, 0)
        self._offsets_tex = None
        self._labels_key, self._labels = None, None      # group_labels' last answer
        #: deal the samples of short runs to several entries (add_samples);
        #: the viewer's display of a round in flight reads one texel per
        #: pixel (sums_target), so it turns this off
        self.split_entries = True
        self._in_flight = None           # (list framebuffer, texel of each entry) during add_samples
        #: what the checker's second colour adds to the colours the latest
        #: first pass ((H, W, 3)) and corner pass ((H + 1, W + 1, 3)) gave,
        #: where each camera ray's principal chain ends (0 off a checker;
        #: exposure applied)
        self.centre_checker = self.corner_checker = None
        #: (H, W) int8 from the latest first pass: how each pixel's footprint
        #: samples take the checker (FOOTPRINT_EXACT, FOOTPRINT_ROWS or 0: not)
        self.footprint_kind = None
        #: (H + 1, W + 1, 4) from the latest corner pass: each corner ray's
        #: chainLeaf (shaders/lib/sample.glsl; chain_footprints)
        self.corner_chain = None

    def _programs(self, defines: dict) -> list[tuple[moderngl.Program, tuple]]:
        """The renderer's (program, rectangles) pairs of these variant
        defines: its screen-tile culling variants (each exact everywhere; a
        variant not compiled yet is stood in for by the full shader)."""
        return self.renderer.programs_for(self.width, self.height, **defines)

    def compile(self) -> None:
        """Compile every shader variant the passes use at this size and
        camera now (the viewer's soak counts GL objects after it)."""
        for defines in ((self.FOOTPRINT_FIRST, self.FOOTPRINT_LIST) if self.footprint else (self.FIRST, self.LIST)):
            self.renderer.programs_for(self.width, self.height, compile_all=True, **defines)
        self.renderer.variant(**self.FIRST)              # the corner pass's (not culled)

    @property
    def first_defines(self) -> dict:
        return self.FOOTPRINT_FIRST if self._footprint_tex is not None else self.FIRST

    @property
    def list_defines(self) -> dict:
        return self.FOOTPRINT_LIST if self._footprint_tex is not None else self.LIST

    def set_footprint(self, planes: np.ndarray | None, chain=None) -> None:
        """FootprintSampler.set_footprint, where this sampler was made with
        footprint=True (point samples, planes None, in any)."""
        if planes is not None and not self.footprint:
            raise ValueError("footprint samples need an AdaptiveSampler made with footprint=True")
        super().set_footprint(planes, chain)

    def group_labels(self, programs) -> np.ndarray:
        """(H, W) int8, top row first: which of `programs`' groups of
        rectangles each pixel is drawn by."""
        key = tuple(rects for _, rects in programs)
        if key != self._labels_key:                # the plan changes with the camera only
            w, h = self.width, self.height
            labels = np.full((h, w), -1, np.int8)
            for g, rects in enumerate(key):
                for x, y, rw, rh in rects:
                    labels[h - y - rh:h - y, x:x + rw] = g
            labels.setflags(write=False)
            self._labels_key, self._labels = key, labels
        return self._labels

    def first_pass(self, offset=(0.5, 0.5)):
        """Sample 0 of every pixel.  A generator that yields after each draw
        call and returns (Sums of one sample, the object (H, W) int of the
        first interaction of each camera ray (-1 for the sky), and the rays
        (H, W) int that sample traced (camera,
        reflected, refracted and shadow rays: what Renderer.ray_cost
        counts)."""
        # the programs fetched per band pick up a variant compiled since
        # (no chain leaf: only the corner rays' is used)
        out = yield from self._mrt_pass((self.width, self.height), lambda: self._programs(self.first_defines),
                                        offset, 4)
        self.centre_checker = np.ascontiguousarray(out[3][..., :3], np.float64)
        self.footprint_kind = np.rint(out[3][..., 3]).astype(np.int8)
        if self._footprint_tex is not None:
            # each pixel's closed-form share, computed once here: the list
            # passes (FOOTPRINT_SHARES) read it instead of computing it per
            # entry (up to MAX_PIXEL_CORNERS clipped squares each)
            self._footprint_texels[..., 1] = out[2][::-1, :, 3]
            self._footprint_tex.write(self._footprint_texels.tobytes())
        sums = Sums(np.ascontiguousarray(out[0], np.float64), np.ascontiguousarray(out[1][..., 0], np.float64))
        _, obj = self._first_hits(out[2])
        rays = np.rint(out[2][..., 2]).astype(np.int32)
        return sums, obj, rays

    def corner_pass(self):
        """One camera ray through every corner of the pixel grid, (W + 1) x
        (H + 1) of them: fragment (x, y) of the corner grid traces pixel
        (x, H - 1 - y) at offset (0, 1), its bottom-left corner, which is
        corner (x, H - y) of the grid.  Not culled (the grid is not the
        image's tiles).  A generator (a yield per draw) that returns
        (colour (H+1, W+1, 3), t, object (H+1, W+1)), top-left corner
        first."""
        full = [(self.renderer.variant(**self.FIRST), ((0, 0, self.width + 1, self.height + 1),))]
        out = yield from self._mrt_pass((self.width + 1, self.height + 1), lambda: full, (0.0, 1.0), 5)
        self.corner_checker = np.ascontiguousarray(out[3][..., :3], np.float64)
        self.corner_chain = np.ascontiguousarray(out[4], np.float64)
        t, obj = self._first_hits(out[2])
        return np.ascontiguousarray(out[0][..., :3], np.float64), t, obj

    def set_offsets(self, offsets: np.ndarray) -> None:
        """The sample offsets (n, 2) the list passes read (texel k: sample k)."""
        if self._offsets_tex is not None:
            self._offsets_tex.release()
        data = np.ascontiguousarray(offsets, np.float32)
        self._offsets_tex = self.ctx.texture((len(data), 1), 2, data.tobytes(), dtype="f4")
        self._offsets_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)

    def _list_target(self, lw: int, lh: int):
        if self._list_size != (lw, lh):
            self._release_list()
            self._list_tex = self.ctx.texture((lw, lh), 4, dtype="i4")
            self._list_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._list_targets = [self.ctx.texture((lw, lh), 4, dtype="f4") for _ in range(2)]
            self._list_fbo = self.ctx.framebuffer(color_attachments=self._list_targets)
            self._list_size = (lw, lh)
        return self._list_tex, self._list_fbo

    def _layout(self, pixels: np.ndarray, count: np.ndarray):
        """The pixel list of these entries (pixels, each taking `count`
        samples), each drawn by its pixel's culling group: list_layout's
        (list width, rows, runs, texel index of each entry)."""
        groups = self.group_labels(self._programs(self.list_defines)).ravel()[pixels].astype(np.int64)
        return list_layout(groups, count)

    def add_samples(self, pixels: np.ndarray, first: np.ndarray, count: np.ndarray,
                    cost: np.ndarray | None = None):
        """Trace samples first[k] .. first[k] + count[k] - 1 (at the offsets
        set_offsets gave) of the pixels with flat indices `pixels` (j * W +
        i, j from the top row; listed in coherent_order).  A generator: it
        yields after each draw call (the viewer's frames, progress, Ctrl-C)
        and returns the sums (total (n, 4) = sum (L, 1), square (n,) = sum
        L.L) in the order of `pixels`.

        `cost` (rays per sample per pixel, None: all cheap) marks the
        pixels whose samples are costly (the glass): their samples are
        dealt to entries of at most entry_samples(cost) samples.  Where few
        pixels share a count, each one's samples are
        dealt to several consecutive entries of the list (split_factor; a
        4x4 block of them is one pixel's samples or a few pixels'), so that
        the last rounds, a few pixels with many samples each, use every
        SIMD lane and thread; their sums are added back per pixel."""
        w = self.width
        pixels, first, count = (np.asarray(a, np.int64) for a in (pixels, first, count))
        parts = self._split(pixels, count, cost)
        owner = np.repeat(np.arange(len(pixels)), parts)
        starts = np.concatenate([[0], np.cumsum(parts)[:-1]])
        each = count // parts
        e_pixels = pixels[owner]
        e_first = first[owner] + (np.arange(len(owner)) - starts[owner]) * each[owner]
        e_count = each[owner]
        lw, lh, runs, slot = self._layout(e_pixels, e_count)
        tex, fbo = self._list_target(lw, lh)
        entries = np.full((lh * lw, 4), -1, np.int32)
        entries[slot] = np.stack([e_pixels % w, e_pixels // w, e_first, e_count], axis=1)
        tex.write(entries.tobytes())               # row 0 of the texture = list row 0
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        self._in_flight = (fbo, slot, starts)
        try:
            # entries in list rows 0 .. r-1: filled[r] (a draw's exact pixel count)
            filled = np.concatenate([[0], np.cumsum(np.bincount(slot // lw, minlength=lh))])
            yield from self._list_draws(tex, fbo, runs, lw, filled)
        finally:
            self._in_flight = None
        return self._list_sums(fbo, slot, starts)

    def _split(self, pixels: np.ndarray, count: np.ndarray, cost: np.ndarray | None) -> np.ndarray:
        """Entries per pixel: split_factor of the pixels taking its count
        with its entry_samples limit (all groups together, so that the
        split, and with it every sum, is the same whichever culling variants
        draw them); all ones when the sampler's `split_entries` is off."""
        if not self.split_entries or len(pixels) == 0:
            return np.ones(len(pixels), np.int64)
        if cost is not None and np.asarray(cost).dtype.kind == "b":
            raise TypeError("add_samples takes each pixel's rays per sample, not a mask")
        most = np.zeros(len(pixels), np.int64) if cost is None else entry_samples(cost)
        span = int(most.max()) + 1
        key = count * span + most
        uniq, inverse, length = np.unique(key, return_inverse=True, return_counts=True)
        factor = np.array([split_factor(int(n), int(k // span), int(k % span) or None)
                           for k, n in zip(uniq, length)], np.int64)
        return factor[inverse.ravel()]

    def sums_so_far(self) -> np.ndarray | None:
        """Between the yields of add_samples: total (n, 4) = sum (L, 1) of
        the samples its draws have traced so far, in the order of its
        pixels (0 where none yet); None outside add_samples.  (Read back:
        AdaptiveRender.image mid-round, the viewer's screenshot; the window
        reads sums_target on the GPU instead.)"""
        if self._in_flight is None:
            return None
        fbo, slot, starts = self._in_flight
        return self._list_sums(fbo, slot, starts, square=False)[0]

    def sums_target(self):
        """Between the yields of add_samples: (the list target's sums
        texture, RGBA32F: sum (L, 1) of the samples traced so far at each
        texel; the texel index of each of its pixels); None outside it."""
        if self._in_flight is None:
            return None
        fbo, slot, starts = self._in_flight
        if len(starts) != len(slot):
            return None        # split entries: a pixel's sums lie in several texels (split_entries)
        return fbo.color_attachments[0], slot

    @staticmethod
    def _list_sums(fbo, slot, starts, square: bool = True):
        """The list targets' sums at the texels `slot`, added up per pixel
        (its entries begin at `starts`): (total (n, 4), square (n,) or
        None), float64."""
        size = fbo.size[0] * fbo.size[1]
        total = np.frombuffer(fbo.read(attachment=0, components=4, dtype="f4"), np.float32).reshape(size, 4)[slot]
        total = np.add.reduceat(total.astype(np.float64), starts, axis=0) if len(starts) else total.astype(np.float64)
        if not square:
            return total, None
        sq = np.frombuffer(fbo.read(attachment=1, components=1, dtype="f4"), np.float32)[slot].astype(np.float64)
        return total, (np.add.reduceat(sq, starts) if len(starts) else sq)

    def _list_draws(self, tex, fbo, runs, lw, filled):
        """add_samples' draw calls, a yield after each."""
        ctx, w = self.ctx, self.width
        for g, samples, row0, rows, length in runs:
            k0 = 0
            while k0 < samples:
                # about fragments_per_draw pixel-samples per draw: a batch of
                # samples for some rows of the run
                batch = max(1, min(MAX_BATCH, samples - k0, self.fragments_per_draw // max(1, length)))
                rows_per_draw = max(LIST_BLOCK, self.fragments_per_draw // (lw * batch)) // LIST_BLOCK * LIST_BLOCK
                y = row0
                while y < row0 + rows:
                    cut = min(rows_per_draw, row0 + rows - y)
                    # (re)bound before every draw: between yields the caller
                    # may have used the context for something else (the viewer)
                    prog = self._programs(self.list_defines)[g][0]
                    self.renderer.bind(prog, w, self.height, (0.5, 0.5))
                    prog["pixelList"].value = 1
                    prog["sampleOffsets"].value = 2
                    prog["chunkStart"].value = k0
                    prog["chunkSize"].value = batch
                    self.bind_footprint(prog)
                    fbo.use()
                    tex.use(location=1)
                    self._offsets_tex.use(location=2)
                    ctx.enable(moderngl.BLEND)
                    ctx.blend_func = moderngl.ONE, moderngl.ONE
                    ctx.blend_equation = moderngl.FUNC_ADD
                    ctx.scissor = (0, y, lw, cut)
                    try:
                        self.renderer.vao_of(prog).render(moderngl.TRIANGLES, vertices=3)
                        self.last_draw_fragments = int(filled[y + cut] - filled[y]) * batch
                        self._drawn(self.last_draw_fragments)
                    finally:
                        ctx.scissor = None
                        ctx.disable(moderngl.BLEND)
                    y += cut
                    yield
                k0 += batch

    def _release_list(self) -> None:
        for obj in (self._list_fbo, self._list_tex, *self._list_targets):
            if obj is not None:
                obj.release()
        self._list_fbo = self._list_tex = None
        self._list_targets = []
        self._list_size = (0, 0)

    def release(self) -> None:
        self._release_list()
        if self._offsets_tex is not None:
            self._offsets_tex.release()
            self._offsets_tex = None
        super().release()
