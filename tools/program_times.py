"""Which shader programs a glassray command compiles, and how long each
took (docs/performance.md, "On a GPU": compile on use).

Runs `glassray ARGS...` in this process with moderngl's Context.program
wrapped, then prints one line per program built: the seconds the driver
took, the source's length, and the defines that tell it apart from the
other programs built (footprint, share pass, cut check, ...). Turn the driver's disk cache off
to time real compiles: `MESA_SHADER_CACHE_DISABLE=true` (Mesa) or
`__GL_SHADER_DISK_CACHE=0` (NVIDIA).

Usage (repository root, the project's virtual environment)::

    python tools/program_times.py render default -o /tmp/x.png --size 320x180
"""
import sys
import time

import moderngl

_program = moderngl.Context.program
built = []


def timed_program(self, **kw):
    start = time.perf_counter()
    prog = _program(self, **kw)
    source = kw.get("fragment_shader") or ""
    defines = {line.split()[1] for line in source.splitlines() if line.startswith("#define ")}
    built.append((time.perf_counter() - start, len(source), defines))
    return prog


moderngl.Context.program = timed_program

from viewer.cli.commands import main  # noqa: E402  (after the wrap, so every program is seen)

try:
    rc = main(sys.argv[1:])
except SystemExit as stop:
    rc = stop.code
shared = set.intersection(*(b[2] for b in built)) if built else set()
for seconds, chars, defines in built:
    print(f"{seconds:6.2f} s  {chars:6d} chars  {','.join(sorted(defines - shared)) or '(plain)'}")
print(f"{len(built)} programs, {sum(b[0] for b in built):.2f} s compiling")
sys.exit(rc)
