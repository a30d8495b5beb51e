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


def read_pfm(path: str | Path) -> np.ndarray:
    """(H, W, 3) float32, first row = top of the image."""
    with open(path, "rb") as f:
        kind = f.readline().strip()
        if kind not in (b"PF", b"Pf"):
            raise ValueError(f"{path}: not a PFM file")
        dims = f.readline().split()
        while not dims:
            dims = f.readline().split()
        w, h = int(dims[0]), int(dims[1])
        scale = float(f.readline().strip())
        dtype = "<f4" if scale < 0 else ">f4"
        ch = 3 if kind == b"PF" else 1
        data = np.frombuffer(f.read(w * h * ch * 4), dtype=dtype).reshape(h, w, ch)
    data = data[::-1].astype(np.float32)
    return np.repeat(data, 3, axis=2) if ch == 1 else data


def read_sky_image(path: str | Path) -> np.ndarray:
    """An equirectangular sky as (H, W, 3) float32 linear RGB, top row first."""
    path = Path(path)
    if path.suffix.lower() == ".pfm":
        return read_pfm(path)
    from PIL import Image

    with Image.open(path) as im:
        rgb = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
    return srgb_to_linear(rgb).astype(np.float32)
