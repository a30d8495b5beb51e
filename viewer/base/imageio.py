"""Image files: the outputs of ``glassray render`` and the sky pictures.

All writes are atomic (temporary file beside the target, then rename), so an
interrupted or failed write never leaves a broken file behind.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from .files import write_atomic

OUTPUT_EXTENSIONS = (".png", ".npy", ".pfm")


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))


def to_display8(linear: np.ndarray) -> np.ndarray:
    """The spec's display encoding: clamp, sRGB curve, round(255 v)."""
    return np.round(255.0 * linear_to_srgb(np.asarray(linear, dtype=np.float64))).astype(np.uint8)


def encode_png(linear: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(to_display8(linear), "RGB").save(buf, format="PNG")
    return buf.getvalue()


def encode_pfm(linear: np.ndarray) -> bytes:
    h, w, _ = linear.shape
    header = f"PF\n{w} {h}\n-1.0\n".encode("ascii")
    data = np.ascontiguousarray(np.asarray(linear, dtype="<f4")[::-1])  # PFM rows go bottom to top
    return header + data.tobytes()


def encode_npy(linear: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(linear, dtype=np.float32))
    return buf.getvalue()


def write_image(path: str | Path, linear: np.ndarray) -> None:
    """Write (H, W, 3) linear RGB by the file's extension (.png, .npy, .pfm)."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext == ".png":
        data = encode_png(linear)
    elif ext == ".npy":
        data = encode_npy(linear)
    elif ext == ".pfm":
        data = encode_pfm(linear)
    else:
        raise ValueError(f"{path}: unknown output extension {ext!r} (expected .png, .npy or .pfm)")
    write_atomic(path, data)


class ImageReadError(ValueError):
    """A picture that cannot be decoded, or whose texels are not finite
    radiances >= 0 (the message says which)."""


class SkyImageError(RuntimeError):
    """A valid sky picture the OpenGL driver cannot take (larger than its
    largest texture): a failure of this machine, exit 1, not a bad scene."""


def read_pfm(path: str | Path) -> np.ndarray:
    """(H, W, 3) float32, first row = top of the image.  The header is four
    whitespace-separated tokens (PF or Pf, width, height, scale), then one
    whitespace byte and the data; raises ImageReadError on anything else."""
    data = Path(path).read_bytes()
    tokens, pos = [], 0
    while len(tokens) < 4:
        while pos < len(data) and data[pos:pos + 1].isspace():
            pos += 1
        start = pos
        while pos < len(data) and not data[pos:pos + 1].isspace():
            pos += 1
        if start == pos:
            raise ImageReadError("not a PFM file (its header ends early)")
        tokens.append(data[start:pos])
    pos += 1                                    # the one whitespace byte after the scale
    if tokens[0] not in (b"PF", b"Pf"):
        raise ImageReadError("not a PFM file (it must start with PF or Pf)")
    try:
        w, h, scale = int(tokens[1]), int(tokens[2]), float(tokens[3])
    except ValueError:
        raise ImageReadError("not a PFM file (width, height and scale must be numbers)") from None
    if w < 1 or h < 1 or scale == 0.0 or not np.isfinite(scale):
        raise ImageReadError(f"not a PFM file (size {w}x{h}, scale {scale:g})")
    ch = 3 if tokens[0] == b"PF" else 1
    need = w * h * ch * 4
    if data[pos - 1:pos + 1] == b"\r\n" and len(data) - pos == need + 1:
        # A header written with Windows line ends: the byte after the scale
        # is CR and the data begin after its LF (read from the LF, every
        # float would be one byte off).  Only where the file's length says
        # so, so that LF-ended data whose first byte is 0x0A stay as they are.
        pos += 1
    if len(data) - pos < need:
        raise ImageReadError(f"truncated PFM: {w}x{h} needs {need} bytes of data, the file has {max(len(data) - pos, 0)}")
    img = np.frombuffer(data, dtype="<f4" if scale < 0 else ">f4", count=w * h * ch, offset=pos)
    img = img.reshape(h, w, ch)[::-1].astype(np.float32)     # PFM rows run bottom to top
    return np.repeat(img, 3, axis=2) if ch == 1 else img


_SKY_CACHE: dict = {}


def read_sky_image(path: str | Path) -> np.ndarray:
    """An equirectangular sky as (H, W, 3) float32 linear RGB, top row
    first: a PFM as it is, a PNG or JPEG decoded from sRGB (16-bit PNGs at
    their full depth).  Raises ImageReadError when the file cannot be
    decoded or holds a texel that is not finite or is negative (it would
    put NaN or negative radiance in the image); the scene's validation
    calls this, so a bad picture is a bad scene.  Decoded once per file
    version (the scene's check and the renderer share it)."""
    path = Path(path)
    try:
        st = path.stat()
        key = (str(path.resolve()), st.st_mtime_ns, st.st_size)
        if key in _SKY_CACHE:
            return _SKY_CACHE[key]
        img = read_pfm(path) if path.suffix.lower() == ".pfm" else _read_picture(path)
    except ImageReadError:
        raise
    except (OSError, ValueError, SyntaxError, MemoryError) as e:   # PIL's errors for a bad file
        from PIL import UnidentifiedImageError

        if isinstance(e, UnidentifiedImageError):    # its text names the file again, and its class
            raise ImageReadError(f"cannot decode it: not a {path.suffix.lstrip('.').upper()} picture "
                                 "(or a kind of one Pillow cannot read)") from None
        raise ImageReadError(f"cannot decode it ({type(e).__name__}: {e})") from None
    bad = ~np.isfinite(img) | (img < 0)
    if bad.any():
        j, i, _ = np.argwhere(bad)[0]
        raise ImageReadError(f"its texels must be finite and >= 0: {int(bad.any(axis=2).sum())} are not "
                             f"(the first at row {j}, column {i}: {img[j, i].tolist()})")
    img.setflags(write=False)
    _SKY_CACHE.clear()                            # one picture kept: the scene's
    _SKY_CACHE[key] = img
    return img


def _read_picture(path: Path) -> np.ndarray:
    return srgb_to_linear(read_picture_encoded(path)).astype(np.float32)


def read_picture_encoded(path: str | Path) -> np.ndarray:
    """A PNG or JPEG as (H, W, 3) float64 in [0, 1], still sRGB-encoded, at
    its full depth: 16-bit PNGs (grey, grey+alpha, RGB, RGBA) keep all 16
    bits.  An alpha channel (or a palette's transparency) is ignored: the
    sky is the background, with nothing behind it to show through.
    Pillow's warnings (a large picture, a palette with transparency) are
    kept off stderr; a picture over Pillow's decompression-bomb limit is an
    ImageReadError."""
    import warnings

    from PIL import Image

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            with Image.open(path) as im:
                # Pillow opens many formats, whatever the name; a sky is PNG
                # or JPEG (MPO: a camera's JPEG with extra pictures).  Another
                # (a float TIFF, a GIF) would be converted by rules of its own:
                # a float TIFF named .png came out black without a word
                if im.format not in ("PNG", "JPEG", "MPO"):
                    raise ImageReadError(f"cannot decode it: it is a {im.format} picture, not a PNG or JPEG "
                                         "(or a PFM, named .pfm)")
                deep = im.format == "PNG" and _png16_colour(path)
                im.load()
                if deep:           # 16-bit colour: Pillow's RGB/RGBA/LA keep only the high 8 bits
                    return _read_png16_colour(Path(path).read_bytes())
                if im.mode in ("I;16", "I;16B", "I;16L", "I"):      # 16-bit grey: PIL's RGB would clip it to 8 bits
                    a = np.asarray(im, dtype=np.float64) / 65535.0
                    return np.repeat(a[:, :, None], 3, axis=2)
                return np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
        except Image.DecompressionBombError as e:       # not an OSError: it would escape as a crash
            raise ImageReadError(f"cannot decode it: {e}") from None


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: Adam7 passes: first column, first row, column step, row step.
_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2))


def _png16_colour(path) -> bool:
    """Whether the PNG is 16-bit grey+alpha, RGB or RGBA (colour types 4, 2, 6)."""
    with open(path, "rb") as f:
        head = f.read(29)
    return (len(head) == 29 and head[:8] == _PNG_SIGNATURE and head[12:16] == b"IHDR"
            and head[24] == 16 and head[25] in (2, 4, 6))


def _read_png16_colour(data: bytes) -> np.ndarray:
    """A 16-bit grey+alpha, RGB or RGBA PNG as (H, W, 3) float64 in [0, 1]
    (alpha dropped).  The scanlines are inflated here and unfiltered by
    Pillow: PNG's filters work byte lane by byte lane (byte k of a pixel is
    predicted from byte k of its neighbours), so each of the pixel's bytes
    goes to Pillow as an 8-bit grey PNG with the same filter bytes."""
    import struct
    import zlib

    from PIL import Image

    w, h, _, ctype, _, _, interlace = struct.unpack(">IIBBBBB", data[16:29])
    channels = {2: 3, 4: 2, 6: 4}[ctype]
    bpp = 2 * channels
    passes = _ADAM7 if interlace else ((0, 0, 1, 1),)
    sizes = [(-(-(w - x0) // dx), -(-(h - y0) // dy)) if w > x0 and h > y0 else (0, 0)
             for x0, y0, dx, dy in passes]
    need = sum(ph * (1 + pw * bpp) for pw, ph in sizes if pw and ph)
    idat, pos = [], 8
    while pos + 8 <= len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        if kind == b"IDAT":
            idat.append(data[pos + 8:pos + 8 + n])
        elif kind == b"IEND":
            break
        pos += 12 + n
    try:
        raw = zlib.decompressobj().decompress(b"".join(idat), need)
    except zlib.error as e:
        raise ImageReadError(f"cannot decode it (broken PNG data: {e})") from None
    if len(raw) < need:
        raise ImageReadError(f"cannot decode it (truncated PNG: {len(raw)} of {need} bytes of pixel data)")

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    out = np.empty((h, w, bpp), np.uint8)
    start = 0
    for (x0, y0, dx, dy), (pw, ph) in zip(passes, sizes):
        if not (pw and ph):
            continue
        rows = np.frombuffer(raw, np.uint8, ph * (1 + pw * bpp), start).reshape(ph, 1 + pw * bpp)
        start += rows.size
        for k in range(bpp):
            lane = np.empty((ph, 1 + pw), np.uint8)
            lane[:, 0], lane[:, 1:] = rows[:, 0], rows[:, 1 + k::bpp]
            grey = (_PNG_SIGNATURE + chunk(b"IHDR", struct.pack(">IIBBBBB", pw, ph, 8, 0, 0, 0, 0))
                    + chunk(b"IDAT", zlib.compress(lane.tobytes(), 0)) + chunk(b"IEND", b""))
            with Image.open(io.BytesIO(grey)) as im:
                out[y0::dy, x0::dx, k] = np.asarray(im)
    a = out.view(">u2").astype(np.float64) / 65535.0        # (h, w, channels), big-endian samples
    return np.repeat(a[:, :, :1], 3, axis=2) if ctype == 4 else a[:, :, :3]
