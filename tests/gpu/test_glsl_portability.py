"""GLSL that another driver (NVIDIA, AMD, Intel) compiles or runs differently
from Mesa's llvmpipe, which the project is developed on.

1. Every program the built-in scenes compile (1 and 4 samples, adaptive,
   the debug views, resumable passes, the generic shader) must pass
   ``glslangValidator -S vert|frag``, a stricter front end than Mesa's
   (skipped where glslangValidator is not installed).
2. Every loop in shaders/ must have a bounded trip count: a GPU has no loop
   limit like llvmpipe's 65535 iterations, and a headless one may have no
   watchdog, so a runaway loop is a draw that never ends.  A ``for`` loop's
   bound may only be made of integer literals, compile-time macros
   (UPPER_CASE), uniforms and block members (set by the program), and
   locals whose every definition is clamped: ``clamp(...)`` or ``min(...)``
   with one of those (never a bare ``int()`` of a float, which GLSL leaves
   undefined for NaN and out-of-range values).  ``while`` loops are listed
   below with what bounds them.

The self-tests at the end show that each check rejects a broken input.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

SHADERS = Path(__file__).resolve().parents[2] / "shaders"
GLSLANG = shutil.which("glslangValidator")

# ----------------------------------------------------------------- glslang


def glslang_errors(source: str, stage: str, tmp_path: Path, name: str = "shader") -> str | None:
    """None where glslangValidator accepts `source` as a `stage` (vert or
    frag) shader, else its log."""
    path = tmp_path / f"{name}.{stage}"
    path.write_text(source)
    run = subprocess.run([GLSLANG, "-S", stage, str(path)], capture_output=True, text=True, timeout=120)
    return None if run.returncode == 0 else (run.stdout + run.stderr)


def scene_names() -> list[str]:
    from viewer.scene.load import builtin_scene_names

    return builtin_scene_names()


#: Scenes with more objects compile only some of their programs (captured_programs).
LARGE_SCENE_OBJECTS = 24


def captured_programs(ctx, name: str) -> dict[str, tuple[str, str]]:
    """{source: (stage, what compiled it)} of every program scene `name`
    compiles at a small size: renders of 1 and 4 samples, an adaptive
    render, the first-hit and cost views, the resumable passes (scenes with
    glass) and the generic shader's renders of 1 and 4 samples."""
    from viewer.adaptive.render import render_adaptive
    from viewer.gpu.renderer import Renderer
    from viewer.scene.load import load_scene

    seen: dict[str, tuple[str, str]] = {}
    cls = type(ctx)
    original = cls.program
    what = [""]

    def program(self, vertex_shader=None, fragment_shader=None, **kw):
        for stage, src in (("vert", vertex_shader), ("frag", fragment_shader)):
            if src is not None:
                seen.setdefault(src, (stage, what[0]))
        return original(self, vertex_shader=vertex_shader, fragment_shader=fragment_shader, **kw)

    w, h = 32, 18
    scene = load_scene(name)
    cls.program = program
    try:
        r = Renderer(ctx, scene)
        r.COMPILES_PER_DRAW = 99
        try:
            runs = (("1 sample", lambda: r.render(w, h, 1)),
                    ("4 samples", lambda: r.render(w, h, 4)),
                    ("adaptive", lambda: render_adaptive(r, w, h, 4)),
                    ("views", lambda: (r.first_hits(w, h), r.ray_cost(w, h))))
            if len(scene.objects) > LARGE_SCENE_OBJECTS:
                # bench-many: the same code as the other scenes' with a longer
                # object list, each program seconds to compile on llvmpipe
                # (45 s of the suite for nothing new): its 1-sample program
                # and the views, whose lists are as long
                runs = runs[:1] + runs[3:]
            for label, run in runs:
                what[0] = label
                run()
            if r._defines.get("HAS_DIELECTRIC") and len(scene.objects) <= LARGE_SCENE_OBJECTS:
                what[0] = "resumable passes"
                r._force_resume = True
                try:
                    r.render(w, h, 4)
                finally:
                    r._force_resume = False
        finally:
            r.release()
        g = Renderer(ctx, scene, specialise=False)
        try:
            for label, n in (("generic, 1 sample", 1), ("generic, 4 samples", 4)):
                what[0] = label
                g.render(w, h, n)
        finally:
            g.release()
    finally:
        cls.program = original
    return seen


@pytest.mark.skipif(GLSLANG is None, reason="glslangValidator is not installed")
@pytest.mark.parametrize("name", scene_names())
def test_every_program_passes_glslang(gl, name, tmp_path):
    programs = captured_programs(gl, name)
    stages = {stage for stage, _ in programs.values()}
    assert stages == {"vert", "frag"}, f"{name}: nothing captured ({stages})"
    bad = []
    for k, (src, (stage, what)) in enumerate(programs.items()):
        log = glslang_errors(src, stage, tmp_path, f"p{k}")
        if log is not None:
            bad.append(f"{name}, {what} ({stage}):\n{log}")
    assert not bad, "\n\n".join(bad)


@pytest.mark.skipif(GLSLANG is None, reason="glslangValidator is not installed")
@pytest.mark.parametrize("mode", range(5))
def test_display_shader_passes_glslang(mode, tmp_path):
    from viewer.gpu.shaders import load_source

    src = load_source("display.frag", {"DISPLAY_MODE": mode}, SHADERS).text
    log = glslang_errors(src, "frag", tmp_path)
    assert log is None, log


# ------------------------------------------------------------- loop bounds

#: while loops and what bounds them (the file, the condition)
BOUNDED_WHILE = {
    # the ray tree's walk: every step goes one level down (depth <= max_depth,
    # an integer, validated <= 64) or pops the stack (an integer); in RESUME
    # passes also resumeBudget nodes at most
    ("lib/tree.glsl", "walking"),
    ("lib/resume.glsl", "walking"),
}

_FOR = re.compile(r"\bfor\s*\(([^;]*);([^;]*);([^)]*)\)")
_WHILE = re.compile(r"\bwhile\s*\(([^)]*)\)")
_IDENT = re.compile(r"\b[A-Za-z_]\w*\b")
_SWIZZLE = re.compile(r"\.\s*[xyzwrgba]{1,4}\b")


def _strip_comments(text: str) -> str:
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    return re.sub(r"//[^\n]*", "", text)


def _uniforms(texts: dict[str, str]) -> set[str]:
    names = set()
    for text in texts.values():
        names.update(re.findall(r"\buniform\s+\w+\s+(\w+)\s*;", text))
        # members of the uniform block (and the structs it holds)
        block = re.search(r"uniform\s+SceneBlock\s*\{(.*?)\}", text, re.S)
        if block:
            names.update(re.findall(r"\b(\w+)\s*(?:\[[^\]]*\])?\s*;", block.group(1)))
    return names


def _definitions(text: str, name: str) -> list[str]:
    """Right-hand sides of every declaration or assignment of `name`."""
    return [m.group(1) for m in re.finditer(rf"\b{re.escape(name)}\s*=(?!=)\s*([^;]*);", text)]


def _strip_parens(expr: str) -> str:
    expr = expr.strip()
    while expr.startswith("(") and expr.endswith(")") and _closing(expr, 0) == len(expr) - 1:
        expr = expr[1:-1].strip()
    return expr


def _closing(expr: str, i: int) -> int:
    depth = 0
    for j in range(i, len(expr)):
        depth += expr[j] == "("
        depth -= expr[j] == ")"
        if depth == 0:
            return j
    return -1


def _top_level(expr: str, sep: str) -> list[str]:
    """expr split at `sep` outside parentheses."""
    out, depth, cur = [], 0, ""
    for ch in expr:
        if ch == sep and depth == 0:
            out.append(cur)
            cur = ""
            continue
        depth += ch == "("
        depth -= ch == ")"
        cur += ch
    return out + [cur]


def _is_float(expr: str) -> bool:
    return bool(re.search(r"\d\.\d*|\bfloat\s*\(|\bvec[234]\s*\(", expr))


def _bounded(expr: str, text: str, uniforms: set[str], seen: set[str] | None = None) -> list[str]:
    """The parts of a loop bound that the rule (module docstring) does not
    bound; [] where it is bounded."""
    seen = set() if seen is None else seen
    e = _strip_parens(_SWIZZLE.sub("", expr))
    if re.fullmatch(r"\d+u?", e) or re.fullmatch(r"[A-Z_][A-Z0-9_]*", e) or e in uniforms:
        return []
    if "?" in e:                                         # c ? x : y: both arms
        arms = _top_level(e.split("?", 1)[1], ":")
        return [p for a in arms for p in _bounded(a, text, uniforms, seen)]
    terms = _top_level(e, "+")
    if len(terms) > 1:
        return [p for t in terms for p in _bounded(t, text, uniforms, seen)]
    m = re.fullmatch(r"(\w+)\s*\((.*)\)", e, re.S)
    if m and _closing(e, e.index("(")) == len(e) - 1:
        fn, args = m.group(1), _top_level(m.group(2), ",")
        if fn in ("int", "uint", "ivec2", "uvec2"):
            inner = _strip_parens(args[0])
            # a conversion bounds nothing: int() of a NaN or of a float out
            # of range is undefined; only an integer min or clamp converted
            # (no float operand) stays bounded
            if re.fullmatch(r"\d+u?|[A-Z_][A-Z0-9_]*", inner):   # a compile-time integer
                return []
            if re.match(r"(min|clamp)\s*\(", inner) and not _is_float(inner):
                return _bounded(inner, text, uniforms, seen)
            return [f"{e} (a conversion, not clamped after it)"]
        if fn == "min":                                  # bounded where either side is
            if any(not _bounded(a, text, uniforms, set(seen)) for a in args):
                return []
            return [f"{e} (neither side bounded)"]
        if fn == "clamp" and len(args) == 3:
            return _bounded(args[2], text, uniforms, seen)
        return [f"{e} (call {fn}())"]
    if re.fullmatch(r"[A-Za-z_]\w*", e):
        if e in seen:
            return []
        seen.add(e)
        defs = _definitions(text, e)
        if not defs:
            return [f"{e} (no definition found)"]
        return [f"{e} = {d.strip()}: {p}" for d in defs for p in _bounded(d, text, uniforms, seen)]
    return [f"{e} (not a bounded expression)"]


def loop_problems(texts: dict[str, str]) -> list[str]:
    """Loops of the shader files `texts` ({name: text}) whose trip count the
    rule does not bound."""
    uniforms = _uniforms(texts)
    problems = []
    for fname, raw in texts.items():
        text = _strip_comments(raw)
        for m in _FOR.finditer(text):
            cond = m.group(2)
            line = text.count("\n", 0, m.start()) + 1
            # the condition: var < bound, var <= bound (several joined by &&)
            for part in cond.split("&&"):
                cm = re.fullmatch(r"\s*(\w+)\s*(<=|<)\s*(.+?)\s*", part)
                if cm is None:
                    problems.append(f"{fname}:{line}: condition {part.strip()!r} is not `i < bound`")
                    continue
                counter, bound = cm.group(1), cm.group(3)
                if not re.search(rf"\+\+\s*{counter}\b|\b{counter}\s*\+\+", m.group(3)):
                    problems.append(f"{fname}:{line}: {counter} is not incremented by the loop")
                for p in _bounded(bound, text, uniforms):
                    problems.append(f"{fname}:{line}: bound {bound.strip()!r}: {p}")
        for m in _WHILE.finditer(text):
            line = text.count("\n", 0, m.start()) + 1
            if (fname, m.group(1).strip()) not in BOUNDED_WHILE:
                problems.append(f"{fname}:{line}: while ({m.group(1).strip()}) is not in BOUNDED_WHILE")
    return problems


def shader_texts() -> dict[str, str]:
    return {p.relative_to(SHADERS).as_posix(): p.read_text()
            for p in sorted(SHADERS.rglob("*")) if p.suffix in (".frag", ".vert", ".glsl")}


def test_every_loop_is_bounded():
    problems = loop_problems(shader_texts())
    assert not problems, "\n".join(problems)


def test_loop_rule_finds_the_loops():
    """The rule sees the loops it must judge (a regex that matched none
    would pass anything)."""
    text = _strip_comments(shader_texts()["lib/footprint.glsl"])
    assert len(_FOR.findall(text)) == 4


# ------------------------------------------------- the checks on broken input

BROKEN_LOOPS = {
    # a trip count straight from a float: int(NaN) is undefined
    "float_trips.glsl": "float f(vec2 span) { ivec2 n = ivec2(span); float s = 0.0;\n"
                        "for (int b = 1; b <= n.y; ++b) s += 1.0; return s; }",
    # a float clamped, then converted: clamp(NaN) is undefined too
    "float_clamp.glsl": "float f(vec2 span) { ivec2 n = ivec2(clamp(span, 0.0, 10.0)); float s = 0.0;\n"
                        "for (int b = 1; b <= n.y; ++b) s += 1.0; return s; }",
    # a texel as the bound
    "texel.glsl": "uniform usampler2D t; float f() { uvec4 st = texelFetch(t, ivec2(0), 0); float s = 0.0;\n"
                  "for (int l = 0; l < int(st.z); ++l) s += 1.0; return s; }",
    # a loop that ends on float arithmetic
    "float_loop.glsl": "float f() { float s = 0.0; for (float x = 0.0; x < 1.0; x += 0.1) s += x; return s; }",
    # a while loop nobody vouched for
    "while.glsl": "float f(float x) { while (x < 1.0) x *= 2.0; return x; }",
}


@pytest.mark.parametrize("name", sorted(BROKEN_LOOPS))
def test_loop_rule_rejects_unbounded_loops(name):
    assert loop_problems({name: BROKEN_LOOPS[name]}), f"{name} was not flagged"


def test_loop_rule_accepts_clamped_loops():
    ok = ("uniform int chunkSize; float f(vec2 span, ivec4 w) { ivec2 n = clamp(ivec2(span), 0, 10);\n"
          "int end = min(w.w, chunkSize); float s = 0.0;\n"
          "for (int b = 1; b <= n.y; ++b) s += 1.0; for (int k = 0; k < end; ++k) s += 1.0;\n"
          "for (int j = 0; j < MAX_THINGS; ++j) s += 1.0; return s; }")
    assert loop_problems({"ok.glsl": ok}) == []


@pytest.mark.skipif(GLSLANG is None, reason="glslangValidator is not installed")
def test_glslang_rejects_broken_source(tmp_path):
    # what Mesa forgives and a stricter front end need not: an implicit
    # int -> uint conversion (GLSL 4.00, not 3.30) and a missing semicolon
    for src in ("#version 330 core\nout vec4 c;\nvoid main() { uint u = 1; c = vec4(float(u)); }\n",
                "#version 330 core\nout vec4 c;\nvoid main() { c = vec4(1.0) }\n"):
        assert glslang_errors(src, "frag", tmp_path) is not None, src
