"""The GLFW backend: the one module that starts GLFW, opens windows and asks
the driver what exists.  Everything else of the window floor gets a window
from here (create_window) and its events as names (KEYS, BUTTONS).

imgui-bundle ships its own GLFW library and points the glfw package at it, so
it is imported here, before glfw: one GLFW for both.
"""

from __future__ import annotations

import ctypes
import os

#: Dear ImGui (imgui-bundle's module), or None; IMGUI_ERROR says why not.
imgui = None
IMGUI_ERROR: str | None = None
if os.environ.get("GLASSRAY_NO_IMGUI"):
    IMGUI_ERROR = "disabled by GLASSRAY_NO_IMGUI"
else:
    try:
        from imgui_bundle import imgui  # type: ignore[no-redef]
    except Exception as _e:  # ImportError, or a broken binary wheel
        imgui = None
        IMGUI_ERROR = f"{type(_e).__name__}: {_e}"

import glfw  # noqa: E402
import moderngl  # noqa: E402

#: GLFW's keys and mouse buttons by the names viewer/window/controls.py binds.
KEYS = {getattr(glfw, f"KEY_{c.upper()}"): c for c in "wsadqerphvzy"}
KEYS.update({getattr(glfw, f"KEY_{d}"): str(d) for d in range(1, 10)})
KEYS.update({getattr(glfw, f"KEY_KP_{d}"): str(d) for d in range(1, 10)})
KEYS.update({glfw.KEY_TAB: "tab", glfw.KEY_F1: "f1", glfw.KEY_F5: "f5", glfw.KEY_F12: "f12",
              glfw.KEY_ESCAPE: "escape", glfw.KEY_LEFT: "left", glfw.KEY_RIGHT: "right", glfw.KEY_UP: "up",
              glfw.KEY_DOWN: "down", glfw.KEY_PAGE_UP: "pageup", glfw.KEY_PAGE_DOWN: "pagedown"})
BUTTONS = {glfw.MOUSE_BUTTON_LEFT: "left", glfw.MOUSE_BUTTON_RIGHT: "right", glfw.MOUSE_BUTTON_MIDDLE: "middle"}


class WindowError(RuntimeError):
    """No window or no OpenGL 3.3 context (the CLI turns it into exit 1)."""


def no_window_message(detail: str) -> str:
    disp = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") or "(not set)"
    return (f"cannot open a window on display {disp}: {detail}. "
            "Render offscreen instead: glassray render -o out.png")


def init_glfw() -> list[str]:
    errors: list[str] = []

    def on_error(code, desc):
        errors.append(desc.decode("utf-8", "replace") if isinstance(desc, bytes) else str(desc))

    glfw.ERROR_REPORTING = "ignore"  # reported through on_error and the checks below
    glfw.set_error_callback(on_error)
    if not glfw.init():
        raise WindowError(no_window_message(errors[-1] if errors else "GLFW could not start"))
    return errors


def create_window(width: int, height: int, title: str, visible: bool, errors: list[str]):
    glfw.default_window_hints()
    glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
    glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
    glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
    glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
    glfw.window_hint(glfw.SCALE_TO_MONITOR, True)
    glfw.window_hint(glfw.VISIBLE, visible)
    win = glfw.create_window(width, height, title, None, None)
    if not win:
        raise WindowError(no_window_message(
            f"no OpenGL 3.3 core context ({errors[-1] if errors else 'window creation failed'})"))
    return win


def probe(args) -> int:
    """Exit 0 when a window with an OpenGL 3.3 core context can be opened (make run)."""
    errors = init_glfw()
    try:
        win = create_window(64, 64, "glassray probe", False, errors)
        glfw.make_context_current(win)
        ctx = moderngl.create_context(require=330)
        ctx.release()
        glfw.destroy_window(win)
    finally:
        glfw.terminate()
    return 0


def rss_kb() -> int:
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * (os.sysconf("SC_PAGE_SIZE") // 1024)
    except (OSError, ValueError, IndexError):
        import resource

        return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


_GL_IS = (("buffers", "glIsBuffer"), ("textures", "glIsTexture"), ("framebuffers", "glIsFramebuffer"),
          ("vertex_arrays", "glIsVertexArray"), ("programs", "glIsProgram"), ("shaders", "glIsShader"),
          ("renderbuffers", "glIsRenderbuffer"), ("samplers", "glIsSampler"), ("queries", "glIsQuery"))


def gl_object_counts(ctx: moderngl.Context, prog) -> dict[str, int]:
    """How many GL objects of each kind exist in the current context
    (glIs* over every name up to a little past the newest one).  For the
    soak test: the counts must stay flat."""
    proto = ctypes.CFUNCTYPE(ctypes.c_ubyte, ctypes.c_uint)
    probes = [ctx.buffer(reserve=4), ctx.texture((1, 1), 4)]
    probes.append(ctx.framebuffer(color_attachments=[probes[1]]))
    probes.append(ctx.vertex_array(prog.program, []))
    upper = max(p.glo for p in probes) + 256
    upper = max(upper, prog.program.glo + 256)
    counts = {}
    try:
        for kind, fname in _GL_IS:
            addr = glfw.get_proc_address(fname)
            if not addr:
                continue
            fn = proto(addr)
            counts[kind] = sum(1 for name in range(1, upper) if fn(name))
    finally:
        for p in reversed(probes):
            p.release()
    for kind in ("buffers", "textures", "framebuffers", "vertex_arrays"):  # less the probes
        if kind in counts:
            counts[kind] -= 1
    return counts
