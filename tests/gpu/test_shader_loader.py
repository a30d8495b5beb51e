"""The shader loader: #include resolution, #define injection, and compile
errors reported as the file and line the user edits (not the driver's
index into the concatenated source)."""

from __future__ import annotations

import re
import shutil

import pytest

from viewer.gpu.block import pack_scene
from viewer.scene.load import load_scene
from viewer.gpu.shaders import (PASS_ENTRIES, RENDER_ENTRY, ShaderError, ShaderFiles, build_program, explain_compile_error,
                                fragment_for, load_source, shader_root)


@pytest.fixture
def shaders(tmp_path, monkeypatch):
    root = tmp_path / "shaders"
    shutil.copytree(shader_root(), root)
    monkeypatch.setenv("GLASSRAY_SHADERS", str(root))
    return root


def _defines() -> dict:
    return pack_scene(load_scene("default"), True, "exact").defines


def _insert_after(path, marker: str, line: str) -> int:
    """Insert `line` after the first line containing `marker`; its 1-based line number."""
    lines = path.read_text().splitlines()
    i = next(k for k, text in enumerate(lines) if marker in text)
    lines.insert(i + 1, line)
    path.write_text("\n".join(lines) + "\n")
    return i + 2


def _names_line(message: str, file: str, line: int) -> bool:
    """`file:line` as a whole number: Mesa writes `file:742:5: error`, NVIDIA
    `file:742 : error` (no column; seen on driver 580 on 2026-12-04)."""
    return re.search(rf"(^|\s){re.escape(file)}:{line}(?!\d)", message, re.M) is not None


def test_the_unedited_shaders_compile(gl, shaders):
    build_program(gl, defines=_defines(), sources=ShaderFiles(shaders))   # so an error below is the edit's


def test_an_error_in_an_included_file_names_that_file_and_line(gl, shaders):
    line = _insert_after(shaders / "lib" / "optics.glsl", "float fresnelDielectric(", "    undeclared_thing += 1.0;")
    with pytest.raises(ShaderError) as err:
        build_program(gl, defines=_defines(), sources=ShaderFiles(shaders))
    assert _names_line(str(err.value), "lib/optics.glsl", line), str(err.value)
    assert "undeclared_thing" in str(err.value)


def test_defines_come_right_after_version():
    src = load_source("render.frag", {"MAX_DEPTH": 3, "HAS_SHADOWS": True, "OFF": False})
    lines = src.text.splitlines()
    assert lines[0].startswith("#version")
    assert lines[1:3] == ["#define MAX_DEPTH 3", "#define HAS_SHADOWS"]
    assert "#define OFF" not in src.text
    assert not any(line.lstrip().startswith("#include") for line in lines)


def test_missing_include_and_cycle_are_named(shaders):
    (shaders / "lib" / "a.glsl").write_text('#include "b.glsl"\n')
    (shaders / "lib" / "b.glsl").write_text('#include "a.glsl"\n')
    (shaders / "c.frag").write_text('#version 330 core\n#include "lib/a.glsl"\nvoid main() {}\n')
    with pytest.raises(ShaderError, match=r"#include cycle: c\.frag -> lib/a\.glsl -> lib/b\.glsl -> lib/a\.glsl"):
        load_source("c.frag", root=shaders)
    (shaders / "d.frag").write_text('#version 330 core\n#include "lib/nope.glsl"\n')
    with pytest.raises(ShaderError, match=r"lib/nope\.glsl: cannot read shader \(included from d\.frag\)"):
        load_source("d.frag", root=shaders)


@pytest.mark.parametrize("log, want", [
    ("0:200012(3): error: `x' undeclared", "lib/optics.glsl:12:3: error"),            # Mesa (source 0 always)
    ("1(200012) : error C1008: undefined variable \"x\"", "lib/optics.glsl:12 : error"),  # NVIDIA
    ("ERROR: 1:200012: 'x' : undeclared identifier", "ERROR: lib/optics.glsl:12: 'x'"),  # glslang / ANGLE
    ("0:100741(5): error: x", "render.frag:741:5: error"),
    ("0:3(9): error: syntax error", "<#defines>:3:9: error"),      # the injected header
    ("0:900001(1): error: x", "0:900001(1): error: x"),            # no such file: left as it is
    ("0:100007(2): error: vec4(1:2) is no 3:4", "render.frag:7:2: error: vec4(1:2) is no 3:4"),
    ("note: see 1:100003 above", "note: see 1:100003 above"),      # not a leading location
])
def test_driver_logs_are_mapped_to_file_names(log, want):
    assert want in explain_compile_error(log, ["render.frag", "lib/optics.glsl"])


def test_an_error_keeps_its_line_past_a_skipped_include(gl, shaders):
    # every #include resets the numbering to the including file's next line;
    # lib/sample.glsl includes lib/footprint.glsl under #ifdef FOOTPRINT_AA:
    # when that is not defined, the include's #line directives are skipped too
    text = (shaders / "lib" / "sample.glsl").read_text()
    assert '#ifdef FOOTPRINT_AA' in text.split("void footprintPixel(")[0]
    assert '#include "footprint.glsl"' in text.split("void footprintPixel(")[0]
    assert "FOOTPRINT_AA" not in _defines()
    line = _insert_after(shaders / "lib" / "sample.glsl", "void footprintPixel(", "    yet_another_undeclared = 2.0;")
    with pytest.raises(ShaderError) as err:
        build_program(gl, defines=_defines(), sources=ShaderFiles(shaders))
    assert _names_line(str(err.value), "lib/sample.glsl", line), str(err.value)


@pytest.mark.parametrize("entry", ["render.frag", "adaptive_first.frag"])
def test_an_error_in_an_entry_file_names_that_file_and_line(gl, shaders, entry):
    line = _insert_after(shaders / entry, "void main()", "    yet_another_undeclared = 2.0;")
    defines = {**_defines(), **({"ADAPTIVE": 1, "ADAPTIVE_FIRST": 1} if entry != "render.frag" else {})}
    with pytest.raises(ShaderError) as err:
        build_program(gl, defines=defines, sources=ShaderFiles(shaders))
    assert _names_line(str(err.value), entry, line), str(err.value)


@pytest.mark.parametrize("defines, entry", [
    ({}, "render.frag"),
    ({"CUT_CHECK": 1, "FOOTPRINT_AA": 1}, "render.frag"),          # feature switches pick no pass
    ({"RESUME": 1}, "resume.frag"),
    ({"ADAPTIVE": 1, "ADAPTIVE_FIRST": 1}, "adaptive_first.frag"),
    ({"ADAPTIVE": 1, "ADAPTIVE_LIST": 1}, "adaptive_list.frag"),
    ({"FOOTPRINT_AA": 1, "FOOTPRINT_SHARE_PASS": 1}, "footprint_shares.frag"),
    ({"VIEW_MODE": 3}, "debug_view.frag"),
    ({"RESUME": False}, "render.frag"),                             # a define that is off asks for nothing
])
def test_each_pass_has_its_entry_file(defines, entry):
    assert fragment_for(defines) == entry
    assert (shader_root() / entry).is_file()


def test_every_entry_file_is_a_pass_and_two_passes_are_refused():
    entries = {p.name for p in shader_root().glob("*.frag")} - {"display.frag", "outline.frag"}  # the window's own
    assert entries == {RENDER_ENTRY, *PASS_ENTRIES.values()}
    with pytest.raises(ShaderError, match="one pass per program"):
        fragment_for({"RESUME": 1, "ADAPTIVE_FIRST": 1})


def test_pass_macros_are_the_entry_files_not_injected():
    # adaptive_first.frag defines ADAPTIVE_FIRST itself; a second, different
    # #define of it (the sampler's ADAPTIVE_FIRST 1) would not compile
    src = load_source("adaptive_first.frag", {"ADAPTIVE_FIRST": 1})
    assert "#define ADAPTIVE_FIRST 1" in src.text     # load_source injects what it is given ...
    seen = {}

    class Capture:
        def program(self, vertex_shader, fragment_shader):
            seen["fs"] = fragment_shader

    build_program(Capture(), defines={"ADAPTIVE": 1, "ADAPTIVE_FIRST": 1, "HAS_LIGHTS": 1})
    header = seen["fs"].split("#line")[0]                  # ... build_program the defines after the pass's
    assert "#define HAS_LIGHTS 1" in header and "ADAPTIVE" not in header, header
    assert "#define ADAPTIVE_FIRST\n" in seen["fs"]


def test_an_error_that_is_not_the_drivers_is_not_called_a_shader_error():
    class NotAContext:
        def program(self, **_):
            raise AttributeError("no GL here")

    with pytest.raises(AttributeError, match="no GL here"):
        build_program(NotAContext())
