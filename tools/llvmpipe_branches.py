"""What a branch skips on this OpenGL driver: the time of one full-screen
draw whose fragments run a costly block of code always, never (behind an
`if` that no fragment takes, per fragment or on a uniform), in a loop of
zero or one iterations (bare, behind an `if`, left by a `break` or after
a `return`), after a `discard`, or not at all because the early depth test
fails for them (docs/performance.md, "What a branch costs").

On a GPU a block that no thread of a warp takes is skipped.  Mesa's
llvmpipe runs a SIMD group (a 4x2 block of pixels) under a mask.  Mesa
22.3 (Debian 12's) runs a block behind an `if` that no lane takes, and a
loop's body at least once even when no lane enters it; only whole draws,
the iterations after a loop's first, and a group whose every fragment
fails the early depth test skip work.  Mesa 25.0 (bookworm-backports)
skips an `if`, a `break` or a `return` that leaves every lane out, but
still runs a bare loop's first iteration; a `discard` only masks the
lanes off on both.

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

# name: (the code before `color = ...`, the depth buffer's test: None for no
# depth test, else a GLSL condition on gl_FragCoord for the fragments that
# fail it: the depth buffer is filled with 0 there and 1 elsewhere by a
# draw before the timed one, which is drawn at depth 0.5 with GL_LESS)
CASES = {
    "nothing": ("", None),
    "always": (HEAVY, None),
    "if, no fragment takes it": ("if (gl_FragCoord.x < -5.0) { %s }" % HEAVY, None),
    "if on a uniform, false": ("if (k > 5.0) { %s }" % HEAVY, None),
    "loop of 0 iterations": ("for (int i = 0; i < int(gl_FragCoord.x) - 100000; ++i) { %s }" % HEAVY, None),
    "loop of 1 iteration": ("for (int i = 0; i < int(gl_FragCoord.x) - int(gl_FragCoord.x) + 1; ++i) { %s }" % HEAVY,
                            None),
    "loop of 0 iterations, behind an if": ("int n = int(gl_FragCoord.x) - 100000; if (n > 0) { for (int i = 0; "
                                           "i < n; ++i) { %s } }" % HEAVY, None),
    "loop whose first iteration breaks": ("for (int i = 0; i < 4; ++i) { if (gl_FragCoord.x > -5.0) break; %s }"
                                          % HEAVY, None),
    "loop after a return in a function": ("x = early(x);", None),
    "discard, every fragment": ("if (gl_FragCoord.x > -5.0) discard; " + HEAVY, None),
    "depth test fails, every fragment": (HEAVY, "true"),
    "depth test fails, left half": (HEAVY, "gl_FragCoord.x < %(half)d.0"),
    "depth test fails, alternate 4x2 blocks": (HEAVY, "((int(gl_FragCoord.x) / 4 + int(gl_FragCoord.y) / 2) & 1) == 1"),
    "depth test fails, alternate 2x2 blocks": (HEAVY, "((int(gl_FragCoord.x) / 2 + int(gl_FragCoord.y) / 2) & 1) == 1"),
    "depth test fails, odd columns": (HEAVY, "(int(gl_FragCoord.x) & 1) == 1"),
}

MASK = ("#version 330\n"
        "void main() {{ gl_FragDepth = ({fails}) ? 0.0 : 1.0; }}\n")


def fragment(body: str) -> str:
    sines = " ".join("x = sin(x * 1.0001 + k);" for _ in range(8))
    return ("#version 330\nuniform float k;\nout vec4 color;\n"
            f"float heavy(float x) {{ {sines} return x; }}\n"
            "float early(float x) { if (gl_FragCoord.x > -5.0) return x; "
            f"for (int i = 0; i < int(k) + 1; ++i) {{ {HEAVY} }} return x; }}\n"
            f"void main() {{ float x = gl_FragCoord.x * 0.001; {body} color = vec4(x); }}\n")


def main(size: int = 1024) -> None:
    ctx = moderngl.create_standalone_context(backend="egl")
    print(f"{ctx.info['GL_RENDERER']}, {ctx.info['GL_VERSION']}, {size}x{size}, median of 9 draws (each finished)")
    vbo = ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], "f4"))
    fbo = ctx.framebuffer([ctx.texture((size, size), 4, dtype="f4")], ctx.depth_texture((size, size)))
    fbo.use()
    for name, (body, fails) in CASES.items():
        prog = ctx.program(vertex_shader=VERTEX, fragment_shader=fragment(body))
        if "k" in prog:
            prog["k"] = 0.5
        vao = ctx.vertex_array(prog, [(vbo, "2f", "p")])
        if fails is not None:
            mask = ctx.program(vertex_shader=VERTEX, fragment_shader=MASK.format(fails=fails % {"half": size // 2}))
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.depth_func = "1"                       # GL_ALWAYS: the mask's depths go in as written
            mask_vao = ctx.vertex_array(mask, [(vbo, "2f", "p")])
            mask_vao.render()
            ctx.depth_func = "<"
            fbo.depth_mask = False                     # the timed draws leave the mask as it is
        vao.render()
        ctx.finish()
        times = []
        for _ in range(9):
            t = time.perf_counter()
            vao.render()
            ctx.finish()
            times.append(time.perf_counter() - t)
        print(f"  {name:40s} {statistics.median(times) * 1e3:7.1f} ms")
        if fails is not None:
            ctx.disable(moderngl.DEPTH_TEST)
            fbo.depth_mask = True
            mask_vao.release()
            mask.release()
        vao.release()
        prog.release()


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:2]))
