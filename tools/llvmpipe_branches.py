"""What a branch skips on this OpenGL driver: the time of one full-screen
draw whose fragments run a costly block of code always, never (behind an
`if` that no fragment takes, per fragment or on a uniform), or in a loop
of zero or one iterations (docs/performance.md, "What a branch costs").

On a GPU a block that no thread of a warp takes is skipped.  Mesa's
llvmpipe runs a SIMD group's lanes under a mask: a block behind an `if`
costs what it costs when taken, and a loop runs its body at least once
even when no lane enters it.  Only whole draws (the tile culling) and
the iterations after a loop's first skip work.

Usage (repository root, the project's virtual environment)::

    python tools/llvmpipe_branches.py [SIZE]       # SIZE x SIZE pixels, default 1024
"""
import statistics
import sys
import time

import moderngl
import numpy as np

VERTEX = "#version 330\nin vec2 p;\nvoid main() { gl_Position = vec4(p, 0.0, 1.0); }\n"

# a block of 32 dependent sines: about 30 ms at 1024x1024 on two cores
HEAVY = "x = heavy(x) + heavy(x + 1.0) + heavy(x + 2.0) + heavy(x + 3.0);"

CASES = {
    "nothing": "",
    "always": HEAVY,
    "if, no fragment takes it": "if (gl_FragCoord.x < -5.0) { %s }" % HEAVY,
    "if on a uniform, false": "if (k > 5.0) { %s }" % HEAVY,
    "loop of 0 iterations": "for (int i = 0; i < int(gl_FragCoord.x) - 100000; ++i) { %s }" % HEAVY,
    "loop of 1 iteration": "for (int i = 0; i < int(gl_FragCoord.x) - int(gl_FragCoord.x) + 1; ++i) { %s }" % HEAVY,
}


def fragment(body: str) -> str:
    sines = " ".join("x = sin(x * 1.0001 + k);" for _ in range(8))
    return ("#version 330\nuniform float k;\nout vec4 color;\n"
            f"float heavy(float x) {{ {sines} return x; }}\n"
            f"void main() {{ float x = gl_FragCoord.x * 0.001; {body} color = vec4(x); }}\n")


def main(size: int = 1024) -> None:
    ctx = moderngl.create_standalone_context(backend="egl")
    print(f"{ctx.info['GL_RENDERER']}, {size}x{size}, median of 9 draws (each finished)")
    vbo = ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], "f4"))
    fbo = ctx.simple_framebuffer((size, size), components=4, dtype="f4")
    fbo.use()
    for name, body in CASES.items():
        prog = ctx.program(vertex_shader=VERTEX, fragment_shader=fragment(body))
        if "k" in prog:
            prog["k"] = 0.5
        vao = ctx.vertex_array(prog, [(vbo, "2f", "p")])
        vao.render()
        ctx.finish()
        times = []
        for _ in range(9):
            t = time.perf_counter()
            vao.render()
            ctx.finish()
            times.append(time.perf_counter() - t)
        print(f"  {name:28s} {statistics.median(times) * 1e3:7.1f} ms")
        vao.release()
        prog.release()


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:2]))
