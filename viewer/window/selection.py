"""The object selected by a click, on the GPU: the pick (the first hit under
the cursor, from the debug views' first-hit pass) and the outline drawn over
the window (shaders/outline.frag).  Which object a click selects and how a
move changes it are in window/pick.py.

The outline reads an id map: the first-hit pass over the whole image,
kept in an RG32F target of this module's.  It is made again after any change
of the camera, the scene or the window's size, once the view is still (one
pass of camera rays, no shading: a small part of a frame), and until then
the outline is not drawn, so that it never outlines where the object was.
"""

from __future__ import annotations

import moderngl
import numpy as np

from ..gpu.shaders import build_program

#: The outline's colour (display values): the orange of Blender's selection.
OUTLINE_COLOR = (1.0, 0.62, 0.16)
#: Its half width in window pixels.
OUTLINE_RADIUS = 1


class Selection:
    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.stale = True                # the id map is not of the picture shown
        self._tex = self._fbo = None
        self._prog = self._vao = None

    # ------------------------------------------------------------ the id map

    def _target(self, width: int, height: int) -> moderngl.Framebuffer:
        if self._fbo is None or self._tex.size != (width, height):
            self._release_target()
            self._tex = self.ctx.texture((width, height), 2, dtype="f4")
            self._fbo = self.ctx.framebuffer(color_attachments=[self._tex])
            self.stale = True
        return self._fbo

    def first_hit(self, renderer, width: int, height: int, x: int, y: int) -> int:
        """The object whose surface the camera ray through the centre of
        pixel (x, y) of a width x height image (x right, y down from the top
        row) meets first, -1 for the sky: one pixel of the first-hit pass."""
        x = min(max(int(x), 0), width - 1)
        y = min(max(int(y), 0), height - 1)
        fbo = self._target(width, height)
        rect = (x, height - 1 - y, 1, 1)       # framebuffer rows count from the bottom
        renderer.draw_view(1, fbo, width, height, rects=[rect])
        t, k = np.frombuffer(fbo.read(viewport=rect, components=2, dtype="f4"), np.float32)
        return int(round(float(k))) if np.isfinite(k) else -1

    def update(self, renderer, width: int, height: int) -> None:
        """The id map of the picture as it is now (when stale)."""
        fbo = self._target(width, height)
        if self.stale:
            renderer.draw_view(1, fbo, width, height)
            self.stale = False

    # ------------------------------------------------------------ the outline

    def draw(self, fbo: moderngl.Framebuffer, viewport: tuple[int, int, int, int], index: int) -> bool:
        """Outline object `index` over what `fbo` shows (True), unless the id
        map is stale (False: the caller updates it once the view is still)."""
        if self.stale or self._tex is None:
            return False
        if self._prog is None:
            self._prog = build_program(self.ctx, fragment="outline.frag", vertex="fullscreen.vert")
            self._vao = self.ctx.vertex_array(self._prog, [])
        fbo.viewport = viewport
        fbo.use()
        self.ctx.scissor = None
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        self._tex.use(location=0)
        prog = self._prog
        for name, value in (("idTex", 0), ("outSize", (float(viewport[2]), float(viewport[3]))),
                            ("selected", float(index)), ("outlineColor", OUTLINE_COLOR),
                            ("radius", OUTLINE_RADIUS)):
            if name in prog:
                prog[name].value = value
        try:
            self._vao.render(moderngl.TRIANGLES, vertices=3)
        finally:
            self.ctx.disable(moderngl.BLEND)
            self.ctx.blend_func = moderngl.ONE, moderngl.ONE   # the accumulation's additive blending
        return True

    def reload_program(self) -> None:
        """Build the outline shader again from disk (raises ShaderError and
        keeps the old one)."""
        prog = build_program(self.ctx, fragment="outline.frag", vertex="fullscreen.vert")
        self._release_program()
        self._prog, self._vao = prog, self.ctx.vertex_array(prog, [])

    # ------------------------------------------------------------ cleanup

    def _release_program(self) -> None:
        for obj in (self._vao, self._prog):
            if obj is not None:
                obj.release()
        self._prog = self._vao = None

    def _release_target(self) -> None:
        for obj in (self._fbo, self._tex):
            if obj is not None:
                obj.release()
        self._fbo = self._tex = None

    def release(self) -> None:
        self._release_target()
        self._release_program()
