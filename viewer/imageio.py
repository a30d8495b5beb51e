"""Image files: the outputs of ``glassray render`` and the sky pictures.

All writes are atomic (temporary file beside the target, then rename), so an
interrupted or failed write never leaves a broken file behind.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from .scene import write_atomic

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
    from PIL import Image

    with Image.open(path) as im:
        im.load()
        if im.mode in ("I;16", "I;16B", "I;16L", "I"):      # 16-bit grey: PIL's RGB would clip it to 8 bits
            a = np.asarray(im, dtype=np.float64) / 65535.0
            a = np.repeat(a[:, :, None], 3, axis=2)
        else:
            a = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
    return srgb_to_linear(a).astype(np.float32)
