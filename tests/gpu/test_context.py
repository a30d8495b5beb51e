"""Offscreen OpenGL contexts (viewer.context): every backend must really render.

Each test draws a full-screen triangle into an RGBA32F framebuffer and checks
the read-back exactly.  A test is skipped only when the backend's system
library is absent from the machine; any other failure is a failure.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import re

import moderngl
import numpy as np
import pytest

import viewer.gpu.context as vc
from viewer.gpu.context import ContextError, create_offscreen_context, describe

W, H = 7, 5  # not square, so a transposed read-back is caught

VERTEX = """#version 330 core
void main() {
    // Full-screen triangle from gl_VertexID: (-1,-1), (3,-1), (-1,3).
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

# Colour depends on the pixel, so orientation and pixel centres are checked;
# values outside [0, 1] check that the float target is not clamped.
FRAGMENT = """#version 330 core
uniform float k;
out vec4 colour;
void main() {
    colour = vec4(gl_FragCoord.x, gl_FragCoord.y, k * (gl_FragCoord.x + 10.0 * gl_FragCoord.y), -k);
}
"""


def _loadable(*names: str | None) -> bool:
    for name in names:
        if not name:
            continue
        try:
            ctypes.CDLL(name)
            return True
        except OSError:
            pass
    return False


def _library_missing(backend: str) -> str | None:
    """Why ``backend`` cannot work on this machine at all, or None."""
    egl = _loadable("libEGL.so.1", ctypes.util.find_library("EGL"))
    osmesa = _loadable(*vc._OSMESA_LIBRARIES) or _loadable(ctypes.util.find_library("OSMesa"))
    if backend == "egl" and not egl:
        return "libEGL is not installed (apt-get install libegl1 libegl-mesa0)"
    if backend == "osmesa" and not osmesa:
        return "libOSMesa is not installed (apt-get install libosmesa6)"
    if backend == "auto" and not (egl or osmesa):
        return "neither libEGL nor libOSMesa is installed"
    return None


def _create(backend: str):
    missing = _library_missing(backend)
    if missing:
        pytest.skip(missing)
    return create_offscreen_context(backend)


@pytest.fixture(params=["egl", "osmesa", "auto"])
def context(request):
    ctx, used = _create(request.param)
    yield request.param, ctx, used
    ctx.release()


class _Target:
    """Program, empty VAO and a W x H RGBA32F framebuffer in ``ctx``."""

    def __init__(self, ctx: moderngl.Context):
        self.prog = ctx.program(vertex_shader=VERTEX, fragment_shader=FRAGMENT)
        self.vao = ctx.vertex_array(self.prog, [])
        self.tex = ctx.texture((W, H), 4, dtype="f4")
        self.fbo = ctx.framebuffer(color_attachments=[self.tex])
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0)

    def draw(self, k: float) -> None:
        self.fbo.use()
        self.prog["k"].value = k
        self.vao.render(moderngl.TRIANGLES, vertices=3)

    def read(self) -> np.ndarray:
        """(H, W, 4) float32; row 0 is the bottom row (y = 0), as in GL."""
        data = self.fbo.read(components=4, dtype="f4")
        return np.frombuffer(data, dtype=np.float32).reshape(H, W, 4)

    def release(self) -> None:
        for obj in (self.fbo, self.tex, self.vao, self.prog):
            obj.release()


def _expected(k: float) -> np.ndarray:
    y, x = np.mgrid[0:H, 0:W].astype(np.float32) + np.float32(0.5)
    k = np.float32(k)
    return np.stack([x, y, k * (x + np.float32(10.0) * y), np.full_like(x, -k)], axis=-1)


def test_renders_exact_pattern(context):
    requested, ctx, used = context
    assert used in vc.BACKENDS
    if requested != "auto":
        assert used == requested
    assert ctx.version_code >= 330
    assert ctx.screen is None  # offscreen: no default framebuffer
    target = _Target(ctx)
    target.draw(4.0)
    got = target.read()
    np.testing.assert_array_equal(got, _expected(4.0))
    # Orientation spelled out: bottom-left pixel is (0.5, 0.5), top-right (W-0.5, H-0.5).
    assert tuple(got[0, 0, :2]) == (0.5, 0.5)
    assert tuple(got[H - 1, W - 1, :2]) == (W - 0.5, H - 0.5)
    target.release()


def test_additive_blending_accumulates_exactly(context):
    _, ctx, _ = context
    target = _Target(ctx)
    ctx.enable(moderngl.BLEND)
    ctx.blend_func = moderngl.ONE, moderngl.ONE
    try:
        target.draw(0.25)
        target.draw(1000.5)
    finally:
        ctx.disable(moderngl.BLEND)
        ctx.blend_func = moderngl.DEFAULT_BLENDING
    # Float32 sums are exact here: every term is a small dyadic rational.
    np.testing.assert_array_equal(target.read(), _expected(0.25) + _expected(1000.5))
    target.release()


def test_describe_is_one_line(context):
    _, ctx, _ = context
    text = describe(ctx)
    assert "\n" not in text
    renderer, version = text.split(" / ", 1)
    assert renderer == ctx.info["GL_RENDERER"]
    assert version == ctx.info["GL_VERSION"]
    assert re.match(r"\d+\.\d+", version)


@pytest.mark.parametrize("name", ["vulkan", "EGL", "", "osmesa "])
def test_unknown_backend_is_a_clear_error(name):
    with pytest.raises(ContextError) as info:
        create_offscreen_context(name)
    message = str(info.value)
    assert "unknown OpenGL backend" in message
    assert repr(name) in message
    for choice in ("auto", "egl", "osmesa"):
        assert choice in message


def test_context_error_is_a_runtime_error():
    assert issubclass(ContextError, RuntimeError)


@pytest.mark.parametrize("backend", ["egl", "osmesa", "auto"])
def test_create_and_release_twenty_times(backend):
    for _ in range(20):
        ctx, used = _create(backend)
        assert used in vc.BACKENDS
        ctx.release()
    ctx.release()  # releasing twice is harmless
    # Still works afterwards.
    ctx, _ = _create(backend)
    target = _Target(ctx)
    target.draw(1.0)
    np.testing.assert_array_equal(target.read(), _expected(1.0))
    target.release()
    ctx.release()


def test_osmesa_release_destroys_the_osmesa_context():
    before = set(vc._live_osmesa)
    ctx, _ = _create("osmesa")
    new = set(vc._live_osmesa) - before
    assert len(new) == 1
    (handle,) = new
    loader = vc._live_osmesa[handle]
    ctx.release()
    assert loader.released and loader.handle is None and loader.buffer is None
    assert handle not in vc._live_osmesa


def test_osmesa_leaves_gallium_driver_unset(monkeypatch):
    monkeypatch.delenv("GALLIUM_DRIVER", raising=False)
    ctx, _ = _create("osmesa")
    ctx.release()
    assert "GALLIUM_DRIVER" not in os.environ


@pytest.mark.parametrize("first,second", [("osmesa", "egl"), ("egl", "osmesa"), ("osmesa", "osmesa")])
def test_two_live_contexts_switch_with_with(first, second):
    a, _ = _create(first)
    b, _ = _create(second)
    try:
        with a:
            ta = _Target(a)
        with b:
            tb = _Target(b)
        with a:
            ta.draw(1.0)
        with b:
            tb.draw(2.0)
        with a:
            np.testing.assert_array_equal(ta.read(), _expected(1.0))
        with b:
            np.testing.assert_array_equal(tb.read(), _expected(2.0))
    finally:
        b.release()
        a.release()


def test_auto_names_both_failures(monkeypatch):
    # Make both backends fail for real: EGL loads a library that does not
    # exist (glcontext honours GLCONTEXT_LINUX_LIBEGL), OSMesa finds none.
    monkeypatch.setenv("GLCONTEXT_LINUX_LIBEGL", "/nonexistent/libEGL.so.1")
    monkeypatch.setattr(vc, "_osmesa_lib", None)
    monkeypatch.setattr(vc, "_OSMESA_LIBRARIES", ("libNoSuchOSMesa.so.1",))
    monkeypatch.setattr(vc.ctypes.util, "find_library", lambda name: None)
    with pytest.raises(ContextError) as info:
        create_offscreen_context("auto")
    message = str(info.value)
    assert "EGL backend" in message and "libegl1 libegl-mesa0" in message
    assert "OSMesa backend" in message and "libosmesa6" in message
    assert "/nonexistent/libEGL.so.1" in message
    assert "libNoSuchOSMesa.so.1" in message


def test_osmesa_version_too_high_is_a_context_error():
    if _library_missing("osmesa"):
        pytest.skip(_library_missing("osmesa"))
    with pytest.raises(ContextError, match="OSMesa backend"):
        create_offscreen_context("osmesa", require=990)


def test_driver_release_names_the_driver_not_the_gl_version():
    from viewer.gpu.context import driver_release

    assert driver_release("4.5 (Core Profile) Mesa 25.0.7-2~bpo12+1") == "Mesa 25.0.7"
    assert driver_release("4.5 (Core Profile) Mesa 22.3.6") == "Mesa 22.3.6"
    assert driver_release("3.3.0 NVIDIA 580.159.04") == "NVIDIA 580.159.04"
    assert driver_release("4.6") == ""
    assert driver_release("") == ""


def test_renderer_and_release_from_a_description():
    from viewer.gpu.context import renderer_and_release

    assert (renderer_and_release("llvmpipe (LLVM 15.0.6, 256 bits) / 4.5 (Core Profile) Mesa 25.0.7-2~bpo12+1")
            == "llvmpipe (LLVM 15.0.6, 256 bits) (Mesa 25.0.7)")
    assert renderer_and_release("Some GPU / 4.6") == "Some GPU"


def test_the_driver_release_of_this_context(context):
    """A context's GL_VERSION names its driver's release (Mesa's, here, on
    EGL and OSMesa; another driver's words after the GL version elsewhere)."""
    from viewer.gpu.context import driver_release

    _, ctx, _ = context
    version = ctx.info["GL_VERSION"]
    release = driver_release(version)
    assert release and release.split()[-1] in version
    if "Mesa" in version:
        assert release.startswith("Mesa ") and release.split()[1][0].isdigit()
