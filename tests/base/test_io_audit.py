"""Image input and output, audited against shared/spec/scene-format.md
(`[sky]` type "image") and the PNG format's own definition: sky pictures
that the readers got wrong.  The test pictures are made here, byte by byte
where Pillow cannot write them (16-bit colour PNGs)."""

from __future__ import annotations

import struct
import warnings
import zlib

import numpy as np
import pytest
from PIL import Image

from viewer.base.imageio import SkyImageError, read_sky_image
from viewer.scene.model import SceneError
from viewer.scene.load import load_scene

SKY = '[sky]\ntype = "image"\nimage = "{name}"\n[camera]\nposition = [0, 0, 0]\ntarget = [0, 0, -1]\nfov = 90\n'

_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2))


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def _filter_rows(rows: np.ndarray, bpp: int) -> bytes:
    """PNG scanlines (h, n bytes) filtered by the PNG definition, row j
    with filter type j % 5 so that None, Sub, Up, Average and Paeth all occur."""
    x = rows.astype(np.int32)
    out = []
    for j, row in enumerate(x):
        prior = x[j - 1] if j else np.zeros_like(row)
        a = np.concatenate([np.zeros(bpp, np.int32), row[:-bpp]])
        c = np.concatenate([np.zeros(bpp, np.int32), prior[:-bpp]])
        b = prior
        kind = j % 5
        if kind == 4:
            p = a + b - c
            pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
            pred = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
        else:
            pred = (0, a, b, (a + b) // 2)[kind]
        out.append(bytes([kind]) + ((row - pred) % 256).astype(np.uint8).tobytes())
    return b"".join(out)


def png16(samples: np.ndarray, colour_type: int, interlace: bool = False) -> bytes:
    """(h, w, channels) uint16 -> a 16-bit PNG (colour type 0, 2, 4 or 6)."""
    h, w, ch = samples.shape
    passes = _ADAM7 if interlace else ((0, 0, 1, 1),)
    raw = b""
    for x0, y0, dx, dy in passes:
        sub = samples[y0::dy, x0::dx]
        if sub.size:
            raw += _filter_rows(sub.astype(">u2").view(np.uint8).reshape(sub.shape[0], -1), 2 * ch)
    ihdr = struct.pack(">IIBBBBB", w, h, 16, colour_type, 0, 0, int(interlace))
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", zlib.compress(raw))
            + _chunk(b"IEND", b""))


def srgb_decode(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


# ---------------------------------------------------------------- 16-bit colour PNGs


@pytest.mark.parametrize("interlace", [False, True], ids=["plain", "adam7"])
@pytest.mark.parametrize("colour_type, channels", [(2, 3), (6, 4), (4, 2)], ids=["rgb", "rgba", "grey-alpha"])
def test_a_16_bit_colour_png_sky_keeps_all_16_bits(tmp_path, colour_type, channels, interlace):
    """Pillow opens 16-bit RGB, RGBA and grey+alpha PNGs as 8-bit modes
    (the low byte dropped), so a 16-bit sky was quantised to 8 bits, unlike
    a 16-bit grey one.  Alpha is ignored (the sky has nothing behind it)."""
    rng = np.random.default_rng(7)
    samples = rng.integers(0, 65536, (11, 13, channels)).astype(np.uint16)
    samples[0, 0, 0] = 40000                     # 40000 = 156.25 * 256: its low byte is 64
    (tmp_path / "deep.png").write_bytes(png16(samples, colour_type, interlace))
    colour = samples[..., :3] if channels >= 3 else np.repeat(samples[..., :1], 3, axis=2)
    expected = srgb_decode(colour / 65535.0)

    img = read_sky_image(tmp_path / "deep.png")
    np.testing.assert_allclose(img, expected, rtol=2e-6, atol=1e-9)

    # the reference tracer reads it the same way: a direction at a texel's
    # centre (u = (i + 0.5) / W, v = (j + 0.5) / H) sees that texel
    from viewer.reference.sky import sky_radiance

    (tmp_path / "s.toml").write_text(SKY.format(name="deep.png"))
    scene = load_scene(tmp_path / "s.toml")
    h, w = expected.shape[:2]
    for j, i in ((0, 0), (5, 6), (h - 1, w - 1)):
        phi, theta = 2 * np.pi * ((i + 0.5) / w - 0.5), np.pi * (j + 0.5) / h
        d = [np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)]
        np.testing.assert_allclose(sky_radiance(scene, [d])[0], expected[j, i], atol=1e-7)


# ---------------------------------------------------------------- Pillow's limits and warnings


def test_a_picture_over_pillows_pixel_limit_is_a_bad_scene(tmp_path):
    """A PNG whose header claims 100000x100000: Pillow refuses it with
    DecompressionBombError, which is not an OSError, so it escaped the
    scene's validation and `glassray check` crashed (exit 1, 'glassray:
    DecompressionBombError: ...') instead of rejecting the scene (exit 2).
    Nothing is allocated for it."""
    ihdr = struct.pack(">IIBBBBB", 100_000, 100_000, 8, 2, 0, 0, 0)
    (tmp_path / "huge.png").write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr)
                                        + _chunk(b"IDAT", zlib.compress(b"\0" * 64)) + _chunk(b"IEND", b""))
    (tmp_path / "s.toml").write_text(SKY.format(name="huge.png"))
    with pytest.raises(SceneError) as e:
        load_scene(tmp_path / "s.toml")
    msg = str(e.value)
    assert "sky.image" in msg and "huge.png" in msg and "cannot decode it" in msg, msg


def test_pillows_warnings_stay_off_stderr(tmp_path):
    """A palette PNG with transparency made Pillow print a UserWarning on
    stderr for every check and render (and a picture over 89 M pixels a
    DecompressionBombWarning); the picture itself is fine."""
    pal = np.array([[0, 1, 2, 1]], np.uint8)
    im = Image.fromarray(pal, "P")
    im.putpalette([255, 0, 0, 0, 255, 0, 10, 20, 30] + [0] * (3 * 253))
    im.info["transparency"] = bytes([0, 255, 128])
    im.save(tmp_path / "pal.png", transparency=bytes([0, 255, 128]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        img = read_sky_image(tmp_path / "pal.png")
    expected = srgb_decode(np.array([[[255, 0, 0], [0, 255, 0], [10, 20, 30], [0, 255, 0]]]) / 255.0)
    np.testing.assert_allclose(img, expected, rtol=1e-6)


# ---------------------------------------------------------------- the driver's largest texture


def test_a_sky_larger_than_the_drivers_largest_texture_is_a_clear_failure(gl, tmp_path, capsys):
    """A PFM sky one texel wider than GL_MAX_TEXTURE_SIZE (16384 on
    llvmpipe): the texture came out empty and the render was silently black
    with exit 0.  Now: exit 1, one line naming the picture and the limit,
    and no output file."""
    from viewer.cli import commands as cli
    from viewer.gpu.renderer import Renderer

    limit = int(gl.info["GL_MAX_TEXTURE_SIZE"])
    w = limit + 1
    (tmp_path / "wide.pfm").write_bytes(f"PF\n{w} 1\n-1.0\n".encode() + np.ones(3 * w, "<f4").tobytes())
    (tmp_path / "s.toml").write_text(SKY.format(name="wide.pfm"))
    scene = load_scene(tmp_path / "s.toml")        # a valid scene: the limit is the machine's
    with pytest.raises(SkyImageError, match=f"{w}x1, larger than the {limit}x{limit} texture"):
        Renderer(gl, scene)
    # the viewer (F5, the panel) falls back to the last good scene on the
    # same renderer: its sky must still be there
    (tmp_path / "ok.pfm").write_bytes(b"PF\n1 1\n-1.0\n" + struct.pack("<3f", 0.25, 0.5, 2.0))
    (tmp_path / "ok.toml").write_text(SKY.format(name="ok.pfm"))
    good = load_scene(tmp_path / "ok.toml")
    r = Renderer(gl, good)
    try:
        with pytest.raises(SkyImageError):
            r.set_scene(scene)
        r.set_scene(good)
        np.testing.assert_allclose(r.render(4, 2, 1, 0), np.broadcast_to([0.25, 0.5, 2.0], (2, 4, 3)), rtol=1e-6)
    finally:
        r.release()
    out = tmp_path / "out.npy"
    assert cli.main(["render", str(tmp_path / "s.toml"), "-o", str(out), "--size", "8x4", "--samples", "1",
                     "--backend", "egl"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("glassray: sky.image: ") and "scale the picture down" in err[0], err
    assert not out.exists()
    gl.__enter__()                                  # cli.main made (and released) its own context


def test_pfm_with_windows_line_ends_reads_the_same_floats(tmp_path):
    from viewer.base.imageio import read_pfm

    # bytes chosen so that an off-by-one read would give other numbers
    values = np.array([[[0.25, 0.5, 2.0], [1.0, 3.0, 0.125]]], "<f4")
    for name, header in (("lf.pfm", b"PF\n2 1\n-1.0\n"), ("crlf.pfm", b"PF\r\n2 1\r\n-1.0\r\n")):
        (tmp_path / name).write_bytes(header + values.tobytes())
        assert np.array_equal(read_pfm(tmp_path / name), values), name
    # LF-ended data whose first byte is 0x0A after a CR as the header's last
    # byte: the length decides, so the data stay as written
    first = np.frombuffer(b"\n\x00\x80\x3f", "<f4")[0]           # 0x3f80000a: just above 1.0
    odd = np.array([[[first, 0.5, 2.0]]], "<f4")
    (tmp_path / "cr.pfm").write_bytes(b"PF\n1 1\n-1.0\r" + odd.tobytes())
    assert np.array_equal(read_pfm(tmp_path / "cr.pfm"), odd)
