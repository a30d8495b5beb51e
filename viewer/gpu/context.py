"""Offscreen OpenGL contexts for headless rendering: Mesa EGL or OSMesa.

``create_offscreen_context()`` returns a moderngl context with no window and no
default framebuffer (``ctx.screen`` is None): render into your own framebuffers
(``ctx.framebuffer(...)``), as the renderer does.  Two backends:

* ``"egl"``: moderngl/glcontext's EGL backend (EGL device platform, so no X
  server and no ``DISPLAY`` are needed; Mesa gives llvmpipe on a machine
  without a GPU).
* ``"osmesa"``: Mesa's off-screen library, driven with ctypes.  An OSMesa
  context is made current on a tiny owned RGBA buffer and moderngl loads its
  GL functions through ``OSMesaGetProcAddress``.  The OSMesa context and the
  buffer live as long as the moderngl context and are destroyed by
  ``ctx.release()`` (or when the context is garbage collected).

``"auto"`` tries EGL, then OSMesa.

Like every OpenGL context, one of these is current on the thread that created
it.  With several contexts alive in one thread, the last one created is the
current one; switch with ``with ctx: ...`` before using another.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import re
import threading
import weakref

import moderngl
from ..base.errors import Failure

__all__ = [
    "BACKENDS",
    "ContextError",
    "create_offscreen_context",
    "describe",
    "release_context",
]

#: The concrete backends, in the order ``"auto"`` tries them.
BACKENDS = ("egl", "osmesa")

_EGL_INSTALL = "apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri"
_OSMESA_INSTALL = "apt-get install libosmesa6"


class ContextError(RuntimeError):
    """No offscreen OpenGL context could be created (message says why and what to install)."""


def _version_text(require: int) -> str:
    return f"{require // 100}.{(require // 10) % 10}"


def create_offscreen_context(
    backend: str = "auto", require: int = 330
) -> tuple[moderngl.Context, str]:
    """Create a headless OpenGL (core, >= ``require``) moderngl context.

    ``backend`` is ``"egl"``, ``"osmesa"`` or ``"auto"`` (EGL, then OSMesa).
    Returns ``(ctx, backend_used)``; raises :class:`ContextError` on failure.
    Release the context with ``ctx.release()`` (or :func:`release_context`).
    """
    if not isinstance(backend, str) or backend not in ("auto", *BACKENDS):
        raise ContextError(
            f"unknown OpenGL backend {backend!r}: use 'auto', 'egl' or 'osmesa'"
        )
    if backend != "auto":
        return _CREATORS[backend](require), backend

    failures = []
    for name in BACKENDS:
        try:
            return _CREATORS[name](require), name
        except ContextError as exc:
            failures.append(str(exc))
    raise ContextError(
        f"no offscreen OpenGL {_version_text(require)} context could be created "
        "(tried EGL, then OSMesa):\n  " + "\n  ".join(failures)
    )


def describe(ctx: moderngl.Context) -> str:
    """``"GL_RENDERER / GL_VERSION"`` on one line, for logs and benchmarks."""
    info = ctx.info
    return f"{info['GL_RENDERER']} / {info['GL_VERSION']}"


def driver_release(gl_version: str) -> str:
    """The driver and its release from a GL_VERSION string, for a plot's
    title: "4.5 (Core Profile) Mesa 25.0.7-2~bpo12+1" -> "Mesa 25.0.7",
    "3.3.0 NVIDIA 580.159.04" -> "NVIDIA 580.159.04"; "" when the string
    names none.  (llvmpipe's GL_RENDERER names only its LLVM, and two Mesa
    releases differ 2-3x in speed on the same machine.)"""
    m = re.match(r"\s*\d+(?:\.\d+)*\s*(?:\([^)]*\))?\s*(.*)$", gl_version)
    rest = (m.group(1) if m else gl_version).strip()
    words = rest.split()
    if words and words[0] == "Mesa" and len(words) > 1:
        words[1] = words[1].split("-")[0]
    return " ".join(words)


def renderer_and_release(description: str) -> str:
    """describe()'s line as a plot's title gives it: the renderer, and the
    driver's release where GL_VERSION names one ("llvmpipe (LLVM 15.0.6,
    256 bits) (Mesa 25.0.7)")."""
    renderer, _, version = description.partition(" / ")
    release = driver_release(version)
    return f"{renderer} ({release})" if release else renderer


def release_context(ctx: moderngl.Context) -> None:
    """Release ``ctx`` and whatever backs it (OSMesa context and buffer); idempotent."""
    ctx.release()


# --------------------------------------------------------------------------- EGL


def _create_egl(require: int) -> moderngl.Context:
    try:
        return moderngl.create_standalone_context(backend="egl", require=require)
    except Exception as exc:  # glcontext raises plain Exception / ValueError
        detail = str(exc).strip() or type(exc).__name__
        raise ContextError(
            f"EGL backend: could not create an OpenGL {_version_text(require)} core "
            f"context ({detail}); install Mesa's EGL with '{_EGL_INSTALL}'"
        ) from exc


# ------------------------------------------------------------------------ OSMesa

# From Mesa's GL/osmesa.h.
_OSMESA_RGBA = 0x1908  # GL_RGBA
_OSMESA_FORMAT = 0x22
_OSMESA_DEPTH_BITS = 0x30
_OSMESA_STENCIL_BITS = 0x31
_OSMESA_PROFILE = 0x33
_OSMESA_CORE_PROFILE = 0x34
_OSMESA_CONTEXT_MAJOR_VERSION = 0x36
_OSMESA_CONTEXT_MINOR_VERSION = 0x37
_GL_UNSIGNED_BYTE = 0x1401

# The OSMesa context's own colour buffer: never rendered to (rendering goes to
# the caller's FBOs), it only has to exist for OSMesaMakeCurrent.
_BUFFER_SIZE = 16

# Sonames tried in order, then ctypes.util.find_library("OSMesa").
_OSMESA_LIBRARIES = ("libOSMesa.so.8", "libOSMesa.so.6")

_osmesa_lock = threading.Lock()
_osmesa_lib: ctypes.CDLL | None = None
# OSMesa context handle -> loader, for every live context (to restore the
# previously current one in __exit__).
_live_osmesa: weakref.WeakValueDictionary[int, _OSMesaLoader] = (
    weakref.WeakValueDictionary()
)


def _load_osmesa() -> ctypes.CDLL:
    """Load libOSMesa once and declare the prototypes we use."""
    global _osmesa_lib
    if _osmesa_lib is not None:
        return _osmesa_lib
    tried = []
    lib = None
    for name in (*_OSMESA_LIBRARIES, None):
        if name is None:
            name = ctypes.util.find_library("OSMesa")
            if name is None or name in tried:
                continue
        try:
            lib = ctypes.CDLL(name)
            break
        except OSError as exc:
            tried.append(f"{name}: {exc}")
    if lib is None:
        raise ContextError(
            "OSMesa backend: libOSMesa not found (" + "; ".join(tried) + "); "
            f"install it with '{_OSMESA_INSTALL}'"
        )
    vp, c_int = ctypes.c_void_p, ctypes.c_int
    try:
        lib.OSMesaCreateContextExt.restype = vp
        lib.OSMesaCreateContextExt.argtypes = [ctypes.c_uint, c_int, c_int, c_int, vp]
        lib.OSMesaMakeCurrent.restype = ctypes.c_ubyte
        lib.OSMesaMakeCurrent.argtypes = [vp, vp, ctypes.c_uint, c_int, c_int]
        lib.OSMesaGetCurrentContext.restype = vp
        lib.OSMesaGetCurrentContext.argtypes = []
        lib.OSMesaDestroyContext.restype = None
        lib.OSMesaDestroyContext.argtypes = [vp]
        lib.OSMesaGetProcAddress.restype = vp
        lib.OSMesaGetProcAddress.argtypes = [ctypes.c_char_p]
    except AttributeError as exc:
        raise ContextError(
            f"OSMesa backend: {lib._name} lacks a required function ({exc}); "
            f"install Mesa's OSMesa with '{_OSMESA_INSTALL}'"
        ) from exc
    if hasattr(lib, "OSMesaCreateContextAttribs"):  # Mesa >= 11.2
        lib.OSMesaCreateContextAttribs.restype = vp
        lib.OSMesaCreateContextAttribs.argtypes = [ctypes.POINTER(c_int), vp]
    _osmesa_lib = lib
    return lib


_egl_lib: ctypes.CDLL | None = None


def _release_egl_thread() -> None:
    """Make EGL forget its current context on this thread, if it has one.

    Mesa's EGL and OSMesa share one GL dispatch (libglapi), so making an
    OSMesa context current silently takes over from a current EGL context
    while EGL still believes its context is current; a later eglMakeCurrent
    of that same context is then skipped as a no-op and GL calls would go to
    the OSMesa context.  Releasing EGL's thread state first keeps both views
    consistent.  libEGL is never loaded here, only looked up if already loaded.
    """
    global _egl_lib
    if _egl_lib is None:
        noload = getattr(os, "RTLD_NOLOAD", None)
        if noload is None:
            return
        try:
            lib = ctypes.CDLL("libEGL.so.1", mode=noload | os.RTLD_LAZY)
        except (OSError, AttributeError):
            return  # EGL is not in this process: nothing to release
        lib.eglGetCurrentContext.restype = ctypes.c_void_p
        lib.eglGetCurrentContext.argtypes = []
        lib.eglReleaseThread.restype = ctypes.c_uint
        lib.eglReleaseThread.argtypes = []
        _egl_lib = lib
    if _egl_lib.eglGetCurrentContext():
        _egl_lib.eglReleaseThread()


def _osmesa_versions(require: int) -> list[tuple[int, int]]:
    """Core versions to ask for, newest first, none below ``require``."""
    wanted = {(4, 5), (3, 3), (require // 100, (require // 10) % 10)}
    return sorted(v for v in wanted if v[0] * 100 + v[1] * 10 >= require)[::-1]


class _OSMesaLoader:
    """An OSMesa context plus its buffer, shaped as a glcontext context.

    moderngl keeps this object for the lifetime of its context and calls
    ``load_opengl_function`` (at creation), ``__enter__``/``__exit__`` (``with
    ctx:``) and ``release`` (``ctx.release()``).
    """

    def __init__(self, lib: ctypes.CDLL, handle: int, how: str):
        self.lib = lib
        self.handle = handle
        self.how = how  # which creation call worked, for diagnostics
        self.buffer = (ctypes.c_ubyte * (_BUFFER_SIZE * _BUFFER_SIZE * 4))()
        self.loaded = 0
        self._previous: list[int | None] = []
        self.released = False

    def make_current(self) -> bool:
        _release_egl_thread()
        return bool(
            self.lib.OSMesaMakeCurrent(
                self.handle, self.buffer, _GL_UNSIGNED_BYTE, _BUFFER_SIZE, _BUFFER_SIZE
            )
        )

    def load_opengl_function(self, name: str) -> int:
        self.loaded += 1
        return self.lib.OSMesaGetProcAddress(name.encode("ascii")) or 0

    def __enter__(self):
        if self.released:
            return self
        self._previous.append(self.lib.OSMesaGetCurrentContext())
        self.make_current()
        return self

    def __exit__(self, *args):
        if not self._previous:
            return
        previous = self._previous.pop()
        if previous == self.handle or self.released:
            return
        other = _live_osmesa.get(previous) if previous else None
        if other is not None and not other.released:
            other.make_current()
        else:  # nothing (or a foreign OSMesa context) was current before
            self.lib.OSMesaMakeCurrent(None, None, 0, 0, 0)

    def release(self) -> None:
        if self.released:
            return
        self.released = True
        _live_osmesa.pop(self.handle, None)
        if self.lib.OSMesaGetCurrentContext() == self.handle:
            self.lib.OSMesaMakeCurrent(None, None, 0, 0, 0)
        self.lib.OSMesaDestroyContext(self.handle)
        self.handle = None
        self.buffer = None


def _create_osmesa_handle(lib: ctypes.CDLL, require: int) -> tuple[int, str]:
    """An OSMesa RGBA context: a core profile via attribs if possible, else Ext."""
    tried = []
    if hasattr(lib, "OSMesaCreateContextAttribs"):
        for major, minor in _osmesa_versions(require):
            attribs = [
                _OSMESA_FORMAT, _OSMESA_RGBA,
                _OSMESA_DEPTH_BITS, 0,
                _OSMESA_STENCIL_BITS, 0,
                _OSMESA_PROFILE, _OSMESA_CORE_PROFILE,
                _OSMESA_CONTEXT_MAJOR_VERSION, major,
                _OSMESA_CONTEXT_MINOR_VERSION, minor,
                0,
            ]  # fmt: skip
            handle = lib.OSMesaCreateContextAttribs(
                (ctypes.c_int * len(attribs))(*attribs), None
            )
            if handle:
                return handle, f"OSMesaCreateContextAttribs core {major}.{minor}"
            tried.append(f"core {major}.{minor}")
    else:
        tried.append("no OSMesaCreateContextAttribs")
    # Older Mesa: a compatibility context whose version moderngl checks below.
    handle = lib.OSMesaCreateContextExt(_OSMESA_RGBA, 0, 0, 0, None)
    if handle:
        return handle, "OSMesaCreateContextExt"
    tried.append("OSMesaCreateContextExt")
    raise ContextError(
        "OSMesa backend: could not create an OpenGL context (tried "
        + ", ".join(tried)
        + f"); install a newer Mesa OSMesa with '{_OSMESA_INSTALL}'"
    )


def _create_osmesa(require: int) -> moderngl.Context:
    with _osmesa_lock:
        lib = _load_osmesa()
        # OSMesa's gallium picks its driver when it first creates a context;
        # ask for llvmpipe unless the user chose, and only while we create.
        set_driver = "GALLIUM_DRIVER" not in os.environ
        if set_driver:
            os.environ["GALLIUM_DRIVER"] = "llvmpipe"
        try:
            handle, how = _create_osmesa_handle(lib, require)
            loader = _OSMesaLoader(lib, handle, how)
            current = loader.make_current()
        finally:
            if set_driver:
                os.environ.pop("GALLIUM_DRIVER", None)
    if not current:
        loader.release()
        raise ContextError(
            "OSMesa backend: OSMesaMakeCurrent failed; "
            f"reinstall Mesa's OSMesa with '{_OSMESA_INSTALL}'"
        )
    _live_osmesa[handle] = loader
    try:
        # moderngl uses a given glcontext-like ``context`` object instead of
        # one of glcontext's backends (this is what moderngl.init_context does).
        ctx = moderngl.create_context(require=require, standalone=True, context=loader)
    except Exception as exc:
        loader.release()
        detail = str(exc).strip() or type(exc).__name__
        raise ContextError(
            f"OSMesa backend: moderngl could not use the OSMesa context ({how}): "
            f"{detail}; OpenGL {_version_text(require)} core is needed (OSMesa from "
            f"'{_OSMESA_INSTALL}', Mesa >= 20 with llvmpipe, gives 4.5)"
        ) from exc
    if loader.loaded == 0:  # a moderngl that ignores ``context=`` made its own
        ctx.release()
        loader.release()
        raise ContextError(
            f"OSMesa backend: moderngl {moderngl.__version__} cannot load OpenGL "
            "through an external loader; upgrade it with 'pip install -U moderngl'"
        )
    # Destroy the OSMesa context if the moderngl context is dropped unreleased.
    weakref.finalize(ctx, loader.release).atexit = False
    return ctx


_CREATORS = {"egl": _create_egl, "osmesa": _create_osmesa}


#: How moderngl words a framebuffer (or texture) the driver could not
#: allocate: llvmpipe answers INCOMPLETE_ATTACHMENT for one too large for
#: its memory (16384x8192 RGBA32F and up); a driver may say GL_OUT_OF_MEMORY.
_ALLOCATION_ERRORS = ("framebuffer is not complete", "out of memory", "out_of_memory")


def size_failure(e: BaseException, w: int, h: int) -> Failure | None:
    """The Failure to report when e is the OpenGL driver (or the host)
    failing to allocate an image of w x h; None for any other error.  Shared
    by render and the viewer (whose window size is the framebuffer's)."""
    if isinstance(e, MemoryError):
        return Failure(f"cannot render {w}x{h}: not enough memory for an image of that size "
                       "(try a smaller --size)")
    if isinstance(e, moderngl.Error) and any(t in str(e).lower() for t in _ALLOCATION_ERRORS):
        return Failure(f"cannot render {w}x{h}: the OpenGL driver could not allocate a framebuffer of "
                       f"that size (try a smaller --size; the driver said: {e})")
    return None
