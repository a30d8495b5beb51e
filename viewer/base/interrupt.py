"""Ctrl-C and OpenGL.

Python raises KeyboardInterrupt at whatever bytecode runs when SIGINT
arrives, and the signal itself may land in any thread.  Arriving while
llvmpipe compiled a shader (inside moderngl's ``ctx.program``) it crashed
the process with SIGSEGV (measured: a render interrupted 1 s after its
start).  So while OpenGL work runs (:func:`deferred`):

* SIGINT is blocked in the main thread, which is where the driver compiles
  and draws (its own threads block every signal), so the signal never
  interrupts that work;
* the kernel then hands it to another thread that accepts it (numpy's
  BLAS threads, started at import) or, if none does, leaves it pending;
  in the first case Python's C-level handler runs there and writes the
  signal's number to the wakeup pipe set here -- Python itself would not
  notice it in the main thread until much later (a render in the test
  suite took 47 s to stop), so the handler installed here only records it;
* :func:`check`, called by the render loops between draw calls, looks at
  both (the pipe, and the signals pending on the process) and raises
  KeyboardInterrupt there; the caller's ``except KeyboardInterrupt`` ends
  cleanly (exit 130).

Outside :func:`deferred`, or off the main thread, nothing changes.
"""

from __future__ import annotations

import os
import signal
import threading
from contextlib import contextmanager

_depth = 0
_pipe: tuple[int, int] | None = None


def _record(signum, frame) -> None:
    """The Python-level handler: nothing to do.  The C-level one already
    wrote the signal to the wakeup pipe, which check() reads; this one runs
    later, in the main thread, and a flag set here as well counted the same
    Ctrl-C twice when check() read the pipe before it ran ("interrupted"
    printed twice: once by the command, once when deferred() ended)."""


def _take() -> bool:
    """Whether a SIGINT came (consuming it)."""
    came = False
    if _pipe is not None:
        try:
            while data := os.read(_pipe[0], 64):
                came |= signal.SIGINT in data
        except BlockingIOError:
            pass
    if signal.SIGINT in signal.sigpending():
        signal.sigwait({signal.SIGINT})
        came = True
    return came


@contextmanager
def deferred():
    """Defer Ctrl-C to check() for the block (re-entrant); one that came
    and was not taken yet is raised when the block ends."""
    global _depth, _pipe
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    if _depth == 0:
        r, w = os.pipe()
        os.set_blocking(r, False)
        os.set_blocking(w, False)
        old_fd = signal.set_wakeup_fd(w, warn_on_full_buffer=False)
        old_handler = signal.signal(signal.SIGINT, _record)
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        _pipe = (r, w)
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        if _depth == 0:
            came = _take()
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
            signal.signal(signal.SIGINT, old_handler)
            signal.set_wakeup_fd(old_fd)
            for fd in _pipe:
                os.close(fd)
            _pipe = None
            if came:
                raise KeyboardInterrupt


def check() -> None:
    """Between draw calls: raise KeyboardInterrupt if Ctrl-C came while
    deferred."""
    if _depth and _take():
        raise KeyboardInterrupt
