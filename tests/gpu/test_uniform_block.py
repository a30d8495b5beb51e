"""The scene's uniform block is typed twice, once as numpy dtypes
(viewer/gpu/block.py, which writes the bytes) and once in GLSL
(shaders/lib/scene_block.glsl, which reads them).  These tests hold the two
to each other field by field: name, type and byte offset, the offsets
computed twice, by the std140 rules from the GLSL text and by the OpenGL
driver itself (glGetActiveUniformsiv on a linked program)."""

from __future__ import annotations

import ctypes
import re

import numpy as np
import pytest

from viewer.gpu import block as gpu_block
from viewer.gpu.renderer import Renderer
from viewer.gpu.shaders import shader_root
from viewer.scene import load_scene

BLOCK_FILE = shader_root() / "lib" / "scene_block.glsl"

#: GLSL type -> (numpy scalar type, count) of the types the block may hold:
#: only 16-byte ones, so that std140 inserts no padding (the packing's
#: invariant, which this test also checks)
GLSL_TYPES = {"vec4": ("<f4", 4), "ivec4": ("<i4", 4), "uvec4": ("<u4", 4)}

#: the block's array members and the dtype of one element
ARRAYS = {"objects": gpu_block.OBJECT_DTYPE, "materials": gpu_block.MATERIAL_DTYPE,
          "lights": gpu_block.LIGHT_DTYPE, "media": gpu_block.MEDIUM_DTYPE}
STRUCT_DTYPES = {"Object": gpu_block.OBJECT_DTYPE, "Material": gpu_block.MATERIAL_DTYPE,
                 "Light": gpu_block.LIGHT_DTYPE, "Medium": gpu_block.MEDIUM_DTYPE}


def _strip_comments(text: str) -> str:
    return re.sub(r"//[^\n]*", "", re.sub(r"/\*.*?\*/", " ", text, flags=re.S))


def _members(body: str) -> list[tuple[str, str, str | None]]:
    """(type, name, array length or None) of each declaration in a
    struct's or block's body."""
    return [(t, n, a or None) for t, n, a in
            re.findall(r"\b(\w+)\s+(\w+)\s*(?:\[\s*(\w+)\s*\])?\s*;", body)]


def glsl_layout(text: str) -> tuple[dict, list]:
    """The structs and the SceneBlock members declared in `text`."""
    text = _strip_comments(text)
    structs = {m.group(1): _members(m.group(2))
               for m in re.finditer(r"\bstruct\s+(\w+)\s*\{(.*?)\}\s*;", text, re.S)}
    block = re.search(r"uniform\s+SceneBlock\s*\{(.*?)\}\s*;", text, re.S)
    assert block, "no uniform SceneBlock in scene_block.glsl"
    return structs, _members(block.group(1))


def mismatches(text: str) -> list[str]:
    """Every way the GLSL declarations in `text` differ from the dtypes:
    a struct's members (names, types, order, hence offsets) against its
    dtype's fields, the block's arrays against ARRAYS, and its scalar tail
    against TAIL_DTYPE.  Empty when they agree."""
    structs, block = glsl_layout(text)
    out = []

    def compare(where: str, members: list, dtype: np.dtype) -> None:
        offset = 0
        names = []
        for typ, name, length in members:
            names.append(name)
            if typ not in GLSL_TYPES or length is not None:
                out.append(f"{where}.{name}: {typ}{'[]' if length else ''} is not a 16-byte vector")
                continue
            if name not in dtype.names:
                out.append(f"{where}.{name}: not a field of the dtype")
                continue
            base, off = dtype.fields[name][:2]
            want = np.dtype((GLSL_TYPES[typ][0], (GLSL_TYPES[typ][1],)))
            if base != want:
                out.append(f"{where}.{name}: GLSL {typ}, dtype {base}")
            if off != offset:   # std140: 16-byte members follow each other unpadded
                out.append(f"{where}.{name}: GLSL offset {offset}, dtype offset {off}")
            offset += 16
        missing = [n for n in dtype.names if n not in names]
        if missing:
            out.append(f"{where}: dtype fields {missing} not in GLSL")
        if offset != dtype.itemsize:
            out.append(f"{where}: GLSL size {offset}, dtype itemsize {dtype.itemsize}")

    for struct, dtype in STRUCT_DTYPES.items():
        if struct not in structs:
            out.append(f"struct {struct} not declared")
        else:
            compare(struct, structs[struct], dtype)
    arrays = [(t, n) for t, n, a in block if a is not None]
    want = [(dt_struct, name) for name, dt in ARRAYS.items()
            for dt_struct, d in STRUCT_DTYPES.items() if d is dt]
    if arrays != want:
        out.append(f"SceneBlock arrays {arrays}, packing writes {want}")
    compare("SceneBlock", [(t, n, None) for t, n, a in block if a is None], gpu_block.TAIL_DTYPE)
    return out


def test_the_glsl_block_matches_the_dtypes_field_by_field():
    assert mismatches(BLOCK_FILE.read_text(encoding="utf-8")) == []


@pytest.mark.parametrize("edit", [
    ("vec4 phong;", "vec4 phongs;"),                        # a renamed field
    ("ivec4 info;", "vec4 info;"),                          # a changed type
    ("vec4 vector;    //", "vec4 radiance2;  //"),          # a field the dtype lacks
    ("    vec4 skyHorizon;\n    vec4 skyZenith;",           # two fields swapped
     "    vec4 skyZenith;\n    vec4 skyHorizon;"),
])
def test_the_check_sees_an_edit_of_either_side(edit):
    text = BLOCK_FILE.read_text(encoding="utf-8")
    assert edit[0] in text, edit[0]
    assert mismatches(text.replace(edit[0], edit[1], 1)) != []


def _gl_function(ctx, name: str, argtypes):
    """An OpenGL entry point of the current context's library, through EGL
    (or GLX) proc lookup."""
    for lib, getter in (("libEGL.so.1", "eglGetProcAddress"), ("libGL.so.1", "glXGetProcAddress")):
        try:
            dll = ctypes.CDLL(lib)
        except OSError:
            continue
        get = getattr(dll, getter)
        get.restype, get.argtypes = ctypes.c_void_p, [ctypes.c_char_p]
        addr = get(name.encode())
        if addr:
            return ctypes.CFUNCTYPE(None, *argtypes)(addr)
    pytest.skip(f"no {name} to look up")


GL_UNIFORM_OFFSET = 0x8A3B
GL_INVALID_INDEX = 0xFFFFFFFF


@pytest.mark.parametrize("specialise", [True, False], ids=["specialised", "generic"])
def test_the_drivers_offsets_are_the_dtypes(gl, specialise):
    """Every member of the linked program's block (objects[0].a, …,
    counts) sits at the byte offset where pack_scene writes it."""
    scene = load_scene("default")
    r = Renderer(gl, scene, specialise=specialise)
    try:
        prog = r._main
        defines = r._defines
        lens = {k: int(defines[k]) for k in ("OBJECTS_LEN", "MATERIALS_LEN", "LIGHTS_LEN", "MEDIA_LEN")}
        expected = {}
        start = 0
        for (name, dtype), key in zip(ARRAYS.items(), ("OBJECTS_LEN", "MATERIALS_LEN", "LIGHTS_LEN", "MEDIA_LEN")):
            for i in (0, lens[key] - 1):
                for field in dtype.names:
                    expected[f"{name}[{i}].{field}"] = start + i * dtype.itemsize + dtype.fields[field][1]
            start += lens[key] * dtype.itemsize
        for field in gpu_block.TAIL_DTYPE.names:
            expected[field] = start + gpu_block.TAIL_DTYPE.fields[field][1]
        names = list(expected)
        count = len(names)
        c_names = (ctypes.c_char_p * count)(*[n.encode() for n in names])
        indices = (ctypes.c_uint * count)()
        get_indices = _gl_function(gl, "glGetUniformIndices",
                                   [ctypes.c_uint, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p])
        get_iv = _gl_function(gl, "glGetActiveUniformsiv",
                              [ctypes.c_uint, ctypes.c_int, ctypes.c_void_p, ctypes.c_uint, ctypes.c_void_p])
        get_indices(prog.glo, count, c_names, indices)
        known = [i for i in range(count) if indices[i] != GL_INVALID_INDEX]
        # std140: every member of the block is active, used by the shader or not
        assert len(known) == count, [names[i] for i in range(count) if i not in known]
        offsets = (ctypes.c_int * count)()
        get_iv(prog.glo, count, indices, GL_UNIFORM_OFFSET, offsets)
        got = {names[i]: offsets[i] for i in range(count)}
        assert got == expected
        assert prog["SceneBlock"].size == start + gpu_block.TAIL_DTYPE.itemsize
    finally:
        r.release()
