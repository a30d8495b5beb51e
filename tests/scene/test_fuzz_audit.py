"""Bad input a mutation fuzzer found (glassray's standard: a bad scene, flag
or file gets one clear message naming what is wrong, exit 2, never a
traceback; shared/spec/cli.md and scene-format.md).  Each test is the
minimised input of one failure; the fuzzer itself is not part of the suite.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from viewer.cli import commands as cli
from viewer.base.imageio import ImageReadError, read_sky_image
from viewer.scene.model import SceneError
from viewer.scene.load import load_scene

SCENE = """name = "one ball"
[[lights]]
position = [2, 5, 3]
[materials.red]
color = [0.8, 0.2, 0.1]
[[objects]]
type = "sphere"
center = [0, 1, 0]
radius = 1
material = "red"
"""


def check(path, capsys) -> tuple[int, str, str]:
    rc = cli.main(["check", str(path)])
    out, err = capsys.readouterr()
    return rc, out, err


def one_line_error(path, capsys) -> str:
    """`glassray check path`: exit 2, one line on stderr (returned)."""
    rc, out, err = check(path, capsys)
    assert rc == 2, (rc, out, err)
    assert err.endswith("\n") and err.count("\n") == 1, err[:300]
    assert err.startswith("glassray: ")
    return err


# --------------------------------------------------------------------------- a byte order mark


def test_a_scene_saved_with_a_utf8_byte_order_mark_loads(tmp_path, capsys):
    # Windows Notepad's "UTF-8" writes EF BB BF first; tomllib called it
    # "Invalid statement (at line 1, column 1)": a character nobody can see
    plain, bom = tmp_path / "plain.toml", tmp_path / "bom.toml"
    plain.write_text(SCENE, encoding="utf-8")
    bom.write_bytes(b"\xef\xbb\xbf" + SCENE.encode("utf-8"))
    assert replace(load_scene(bom), path=None) == replace(load_scene(plain), path=None)
    rc, out, err = check(bom, capsys)
    assert (rc, err) == (0, "")
    assert out.startswith("one ball: 1 object, 1 material, 1 light")


def test_only_one_byte_order_mark_is_taken(tmp_path):
    # a second one is a character in the TOML, where it is not allowed
    p = tmp_path / "two.toml"
    p.write_bytes(b"\xef\xbb\xbf" * 2 + SCENE.encode("utf-8"))
    with pytest.raises(SceneError, match="not valid TOML"):
        load_scene(p)


# --------------------------------------------------------------------------- one line, however long or odd the input


def test_a_scene_path_with_a_newline_gives_a_one_line_message(tmp_path, capsys):
    err = one_line_error(tmp_path / "new\nline.toml", capsys)
    assert "new\\nline.toml: no such scene file" in err


def test_an_invalid_scene_with_a_newline_in_its_name_gives_a_one_line_message(tmp_path, capsys):
    p = tmp_path / "bad\nscene.toml"
    p.write_text('name = 1\n')
    err = one_line_error(p, capsys)
    assert "bad\\nscene.toml: name: expected a string, got an integer" in err


def test_a_sky_image_path_with_a_newline_gives_a_one_line_message(tmp_path, capsys):
    p = tmp_path / "s.toml"
    p.write_text('[sky]\ntype = "image"\nimage = "no\\nsuch.png"\n')
    err = one_line_error(p, capsys)
    assert "sky.image: no such file: " in err and "no\\nsuch.png" in err


LONG = 100_000


@pytest.mark.parametrize("text, names", [
    # an unknown key of a megabyte of junk (an editor's paste, a binary's bytes)
    ("x" * LONG + " = 1\n", "xxxxxxxxxx...(99920 more characters)...xxxxxxxxxx"),
    ("[render]\nsamples" + "x" * LONG + " = 1\n", "render.samplesxxxx"),
    ('[materials."' + "m" * LONG + '"]\nbogus = 1\n', 'materials.mmmm'),
    # a long string value
    ('[sky]\ntype = "' + "g" * LONG + '"\n', "sky.type: expected one of 'color', 'gradient', 'image', got 'ggg"),
    ('[sky]\ntype = "image"\nimage = "' + "i" * LONG + '.gif"\n', "sky.image: expected a .png"),
    ('[materials.m]\n[[objects]]\ntype = "plane"\nmaterial = "' + "q" * LONG + '"\n',
     "objects[0].material: unknown material 'qqq"),
    ('[materials.m]\n' + '[[objects]]\ntype = "plane"\nmaterial = "m"\nname = "' + "n" * LONG + '"\n' * 1 +
     '[[objects]]\ntype = "plane"\nmaterial = "m"\nname = "' + "n" * LONG + '"\n',
     "objects[1].name: duplicate object name 'nnn"),
    # a long number
    ("[render]\nsamples = " + "9" * 4000 + "\n", "render.samples: expected an integer in 1..65536, got 999"),
    ("[camera]\nfov = " + "9" * 300 + "\n", "camera.fov: expected a number in 1..179, got 999"),
])
def test_a_huge_key_or_value_is_shortened_in_the_message(tmp_path, capsys, text, names):
    p = tmp_path / "long.toml"
    p.write_text(text)
    err = one_line_error(p, capsys)
    assert names in err
    assert len(err) < 400, len(err)          # it was over 100 000 characters: the whole key or value
    assert "more characters)" in err


def test_many_long_material_names_are_shortened_in_the_message(tmp_path, capsys):
    mats = "".join(f'[materials.{c * 1000}]\n' for c in "abcdefgh")
    p = tmp_path / "many.toml"
    p.write_text(mats + '[[objects]]\ntype = "plane"\nmaterial = "nope"\n')
    err = one_line_error(p, capsys)
    assert "objects[0].material: unknown material 'nope' (known: aaaa" in err
    assert len(err) < 700, len(err)          # it was over 8000 characters


def test_a_list_of_ordinary_material_names_is_shown_in_full(tmp_path, capsys):
    names = [f"material{i}" for i in range(20)]          # 239 characters as a list
    p = tmp_path / "s.toml"
    p.write_text("".join(f"[materials.{n}]\n" for n in names) + '[[objects]]\ntype = "plane"\nmaterial = "x"\n')
    err = one_line_error(p, capsys)
    assert f"(known: {', '.join(sorted(names))})" in err


def test_a_short_key_or_value_is_still_quoted_in_full(tmp_path, capsys):
    k = "k" * 80                     # the longest shown whole
    p = tmp_path / "s.toml"
    p.write_text(f"[render]\n{k} = 1\n")
    assert f"render.{k}: unknown key" in one_line_error(p, capsys)


# --------------------------------------------------------------------------- sky pictures of another format


def _save(path, array, fmt):
    from PIL import Image

    Image.fromarray(array).save(path, format=fmt)


@pytest.mark.parametrize("fmt, array", [
    # a float TIFF of 0.5 named .png: Pillow's RGB conversion made it 0 (a black sky, no error)
    ("TIFF", np.full((4, 8), 0.5, np.float32)),
    ("TIFF", np.full((4, 8), 30000, np.uint16)),
    ("GIF", np.full((4, 8, 3), 128, np.uint8)),
    ("BMP", np.full((4, 8, 3), 128, np.uint8)),
])
@pytest.mark.parametrize("name", ["sky.png", "sky.jpg"])
def test_a_sky_picture_that_is_not_png_or_jpeg_is_a_bad_scene(tmp_path, capsys, fmt, array, name):
    _save(tmp_path / name, array, fmt)
    with pytest.raises(ImageReadError, match=f"it is a {fmt} picture, not a PNG or JPEG"):
        read_sky_image(tmp_path / name)
    scene = tmp_path / "s.toml"
    scene.write_text(f'[sky]\ntype = "image"\nimage = "{name}"\n')
    err = one_line_error(scene, capsys)
    assert f"sky.image: {tmp_path / name}: cannot decode it: it is a {fmt} picture" in err


@pytest.mark.parametrize("name, fmt", [("sky.png", "PNG"), ("sky.jpg", "JPEG"), ("sky.png", "JPEG"),
                                       ("sky.jpg", "PNG")])
def test_png_and_jpeg_skies_still_load_whatever_their_name(tmp_path, name, fmt):
    _save(tmp_path / name, np.full((4, 8, 3), 188, np.uint8), fmt)
    img = read_sky_image(tmp_path / name)
    # sRGB 188/255 = 0.737 -> linear ((0.737 + 0.055) / 1.055) ** 2.4 = 0.503 (JPEG: within its loss)
    expect = ((188 / 255 + 0.055) / 1.055) ** 2.4
    assert img.shape == (4, 8, 3)
    assert np.allclose(img, expect, atol=0.01 if fmt == "JPEG" else 1e-6)


# --------------------------------------------------------------------------- names too long for the file system


@pytest.mark.parametrize("name", ["a" * 5000, "a" * 300 + ".toml", "a/" * 3000 + "x.toml"])
def test_a_scene_path_too_long_for_the_file_system_is_a_bad_scene(tmp_path, monkeypatch, capsys, name):
    # pathlib's exists() raised ENAMETOOLONG out of the loader: exit 1, "OSError: [Errno 36] ..."
    monkeypatch.chdir(tmp_path)
    err = one_line_error(name, capsys)
    assert err.endswith(": cannot read: File name too long\n"), err[-200:]
    with pytest.raises(SceneError):
        load_scene(name)


@pytest.mark.parametrize("image", ["a" * 5000 + ".png", "a/" * 3000 + "x.png"])
def test_a_sky_image_path_too_long_for_the_file_system_is_a_bad_scene(tmp_path, capsys, image):
    p = tmp_path / "s.toml"
    p.write_text(f'[sky]\ntype = "image"\nimage = "{image}"\n')
    err = one_line_error(p, capsys)
    assert "sky.image: " in err and err.endswith(": cannot read: File name too long\n"), err[-200:]
    assert len(err) < 1500                  # the path shortened, not all 5000 characters of it


# --------------------------------------------------------------------------- render's output name


def test_an_output_name_too_long_for_the_file_system_is_one_message_before_rendering(tmp_path, capsys, gl):
    # out.is_dir() raised ENAMETOOLONG: exit 1 with a bare OSError and the
    # advice to run with --debug
    out = tmp_path / ("a" * 300 + ".png")
    rc = cli.main(["render", "-o", str(out), "--size", "8x8"])
    _, err = capsys.readouterr()
    assert rc == 1
    assert err.count("\n") == 1 and err.endswith(": cannot write: File name too long\n"), err
    assert "--debug" not in err and "OSError" not in err


def test_an_output_name_with_a_newline_gives_a_one_line_message(tmp_path, capsys, gl):
    rc = cli.main(["render", "-o", str(tmp_path / "no\nsuch" / "out.png"), "--size", "8x8"])
    _, err = capsys.readouterr()
    assert rc == 1
    assert err.count("\n") == 1 and "no\\nsuch" in err and "does not exist" in err, err


def test_a_name_the_terminal_cannot_encode_is_escaped_not_a_crash(tmp_path):
    # PYTHONIOENCODING=ascii: print() of "naïve ☃" raised UnicodeEncodeError (exit 1)
    import os
    import subprocess
    import sys

    scene = tmp_path / "uni.toml"
    scene.write_text('name = "na\u00efve \u2603"\n', encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "viewer", "check", str(scene)], capture_output=True,
                       env=dict(os.environ, PYTHONIOENCODING="ascii"), timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(b"na\\xefve \\u2603: 0 objects"), r.stdout
