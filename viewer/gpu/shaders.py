"""Shader sources: loading from the package, ``#include`` resolution and
``#define`` injection, and error messages that name the file and line.

The GLSL lives in the top-level ``shaders/`` folder, shipped inside the wheel
as the folder ``viewer/glsl/``.  ``#include "lib/x.glsl"`` is
resolved relative to the including file, and ``#line`` directives let a
compiler's ``0:12(3): error`` be mapped back to ``lib/x.glsl:12:3``.

The file is encoded in the line number itself (file k's line n is numbered
(k + 1) * LINE_BASE + n), not only in ``#line``'s source-string number:
Mesa honours the line of ``#line N S`` but prints source string 0 in every
message.  And since a ``#line`` inside a branch the preprocessor skips is
skipped too (lib/tree.glsl's ``#ifdef FOOTPRINT_AA`` around an include), the
numbering is set again after every ``#include``, ``#else``, ``#elif`` and
``#endif``: whichever branch was taken, the next line has its own number.
"""

from __future__ import annotations

import os
import posixpath
import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import moderngl

_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$')
_BRANCH = re.compile(r"^\s*#\s*(?:else|elif|endif)\b")
#: Line numbers of file k (load_source's Source.files[k]) start at
#: (k + 1) * LINE_BASE; smaller ones are the injected #version and #defines.
LINE_BASE = 100000
_VERSION = re.compile(r"^\s*#\s*version\b")


class ShaderError(RuntimeError):
    """A shader that failed to load, compile or link; message has file:line."""


def shader_root() -> Path:
    """The folder holding the shaders (render.frag, lib/, …) (inside the installed package, or the
    repository's shaders/ for an editable install); the environment
    variable GLASSRAY_SHADERS names another folder (shader work with F5 in
    the viewer, tests)."""
    override = os.environ.get("GLASSRAY_SHADERS")
    if override:
        return Path(override)
    try:
        # an installed wheel: the folder viewer/glsl/ (pyproject.toml)
        p = Path(str(resources.files("viewer").joinpath("glsl")))
        if (p / "fullscreen.vert").is_file():
            return p
    except (ModuleNotFoundError, TypeError):
        pass
    return Path(__file__).resolve().parents[2] / "shaders"      # the repository (editable install)


def shaders_editable() -> bool:
    """Whether shader_root() is a folder someone edits (GLASSRAY_SHADERS, or
    the repository's shaders/ of an editable install), not the copy inside
    an installed wheel: the viewer watches it for live reload then."""
    if os.environ.get("GLASSRAY_SHADERS"):
        return True
    return shader_root().name == "shaders"


class ShaderFiles:
    """The shader folder's sources, read once, when made.  A renderer
    compiles every later variant of its program (culling subsets, debug
    views, adaptive passes) from the same text as the first, whatever the
    files on disk say by then: an edit being typed must not reach a running
    viewer half-way, only through F5, which makes a new renderer and so reads
    them again."""

    SUFFIXES = (".frag", ".vert", ".glsl")

    def __init__(self, root: Path | None = None):
        self.root = Path(root or shader_root())
        self._texts: dict[str, str] = {}
        self._errors: dict[str, str] = {}
        for p in sorted(self.root.rglob("*")) if self.root.is_dir() else ():
            if p.suffix in self.SUFFIXES and p.is_file():
                rel = p.relative_to(self.root).as_posix()
                try:
                    self._texts[rel] = p.read_text(encoding="utf-8")
                except (OSError, UnicodeDecodeError) as e:   # reported if a shader includes it
                    self._errors[rel] = getattr(e, "strerror", None) or str(e)

    def read(self, rel: str) -> str:
        rel = posixpath.normpath(rel)
        if rel in self._texts:
            return self._texts[rel]
        raise OSError(self._errors.get(rel, "No such file or directory"))


@dataclass
class Source:
    text: str
    files: list[str] = field(default_factory=list)  # index -> file name for #line


def load_source(name: str, defines: dict[str, object] | None = None, root: Path | None = None,
                sources: ShaderFiles | None = None) -> Source:
    """Read ``name`` with its includes resolved and ``defines`` injected right
    after ``#version``: from `sources` (a snapshot) when given, else from disk."""
    root = root or shader_root()
    files: list[str] = []
    out: list[str] = []
    version_line: list[str] = []

    def emit(rel: str, stack: tuple[str, ...]) -> None:
        if rel in stack:
            raise ShaderError(f"{rel}: #include cycle: {' -> '.join(stack + (rel,))}")
        try:
            text = sources.read(rel) if sources is not None else (root / rel).read_text(encoding="utf-8")
        except OSError as e:
            where = f" (included from {stack[-1]})" if stack else ""
            raise ShaderError(f"{rel}: cannot read shader{where}: {e.strerror or e}") from None
        index = len(files)
        files.append(rel)

        def line_directive(n: int) -> str:       # the next line is this file's line n
            return f"#line {(index + 1) * LINE_BASE + n} {index}"
        out.append(line_directive(1))
        for lineno, line in enumerate(text.splitlines(), start=1):
            if _VERSION.match(line):
                if stack or version_line:
                    raise ShaderError(f"{rel}:{lineno}: #version only belongs at the top of the main shader")
                version_line.append(line)
                out.append("")  # keep line numbers
                continue
            m = _INCLUDE.match(line)
            if m:
                inc = str((Path(rel).parent / m.group(1)).as_posix())
                emit(inc, stack + (rel,))
                out.append(line_directive(lineno + 1))
                continue
            out.append(line)
            if _BRANCH.match(line):
                out.append(line_directive(lineno + 1))

    emit(name, ())
    header = version_line[0] if version_line else "#version 330 core"
    define_lines = [f"#define {k} {'' if v is True else v}".rstrip() for k, v in (defines or {}).items()
                    if v is not False and v is not None]
    text = "\n".join([header, *define_lines, *out]) + "\n"
    return Source(text, files)


# Mesa: "0:12(3): error: ..."; NVIDIA: "0(12) : error ..."; ANGLE/others: "ERROR: 0:12: ..."
# The location leads its line (after ERROR: / WARNING:), so that a pair of
# numbers inside a message is left alone.
_LOCATION = re.compile(r"^(?P<pre>\s*(?:(?:ERROR|WARNING):\s*)?)(?P<file>\d+)(?::|\()(?P<line>\d+)\)?"
                       r"(?:\((?P<col>\d+)\))?")


def explain_compile_error(message: str, files: list[str]) -> str:
    """Rewrite the locations in a driver's log as file:line[:column] of the
    shader files (load_source's Source.files), decoded from the line number
    (see LINE_BASE); a line of the injected header reads "<#defines>:N"."""
    lines = []
    for raw in str(message).splitlines():
        m = _LOCATION.match(raw)
        if m:
            k, n = divmod(int(m.group("line")), LINE_BASE)
            if k <= len(files):
                where = f"{files[k - 1] if k else '<#defines>'}:{n}"
                if m.group("col"):
                    where += f":{m.group('col')}"
                raw = m.group("pre") + where + raw[m.end():]
        lines.append(raw)
    return "\n".join(lines)


#: The entry file (shaders/*.frag) of each kind of pass, by the define that
#: asks for it; a program that asks for none is a render pass (render.frag).
#: The contract: a program's defines ask for at most one pass, and its file
#: follows from its defines alone, so a cache of programs keyed by their
#: defines (Renderer's) still holds one program per key.  An entry file
#: makes the pass macros its lib needs itself, so PASS_MACROS are not
#: passed on; every other define is (the scene's specialisation, feature
#: switches such as FOOTPRINT_AA or CUT_CHECK, VIEW_MODE's view).
PASS_ENTRIES = {"FOOTPRINT_SHARE_PASS": "footprint_shares.frag", "ADAPTIVE_FIRST": "adaptive_first.frag",
                "ADAPTIVE_LIST": "adaptive_list.frag", "RESUME": "resume.frag", "VIEW_MODE": "debug_view.frag"}
RENDER_ENTRY = "render.frag"
PASS_MACROS = ("FOOTPRINT_SHARE_PASS", "ADAPTIVE", "ADAPTIVE_FIRST", "ADAPTIVE_LIST", "RESUME")


def fragment_for(defines: dict[str, object] | None) -> str:
    """The entry file of the pass `defines` ask for (PASS_ENTRIES)."""
    asked = [k for k in PASS_ENTRIES if (defines or {}).get(k) not in (None, False)]
    if len(asked) > 1:
        raise ShaderError(f"one pass per program, not {' and '.join(asked)}")
    return PASS_ENTRIES[asked[0]] if asked else RENDER_ENTRY


def build_program(ctx, fragment: str | None = None, vertex: str = "fullscreen.vert",
                  defines: dict[str, object] | None = None, root: Path | None = None,
                  sources: ShaderFiles | None = None):
    """Compile and link; raise ShaderError with file:line locations.  The
    fragment shader is the entry file of the pass `defines` ask for unless
    named (fragment_for)."""
    vs = load_source(vertex, None, root, sources)
    fragment = fragment or fragment_for(defines)
    fs = load_source(fragment, {k: v for k, v in (defines or {}).items() if k not in PASS_MACROS}, root, sources)

    try:
        return ctx.program(vertex_shader=vs.text, fragment_shader=fs.text)
    except moderngl.Error as e:  # the driver's log; anything else is no shader's fault
        msg = str(e)
        files = fs.files if "fragment" in msg.lower() or "vertex" not in msg.lower() else vs.files
        raise ShaderError(f"shader compilation failed:\n{explain_compile_error(msg, files)}") from None
