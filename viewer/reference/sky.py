"""What a ray that leaves the scene sees: the reference tracer's sky.

:func:`sky_radiance` gives the radiance (N, 3), float64 linear RGB, along
unit directions for the three sky types of the scene format: a constant
colour, a gradient from horizon to zenith over the upper hemisphere, and
an equirectangular picture, sampled bilinearly (wrapping in longitude,
clamped in latitude; u = 0.5 looks down -z, v = 0 is the zenith).  A
picture is read once per (resolved path, modification time) and kept: a
``.pfm`` as its linear floats, any other picture (16-bit colour PNGs at
full depth) decoded from sRGB.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..base.imageio import read_picture_encoded  # 16-bit colour PNGs at full depth
from ..scene.model import Scene

__all__ = ["sky_radiance"]


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _read_pfm(path: Path) -> np.ndarray:
    data = path.read_bytes()
    pos = 0
    tokens = []
    while len(tokens) < 4:  # "PF"/"Pf", width, height, scale, separated by whitespace
        while data[pos:pos + 1].isspace():
            pos += 1
        start = pos
        while not data[pos:pos + 1].isspace():
            pos += 1
        tokens.append(data[start:pos].decode("ascii"))
    pos += 1  # the single whitespace character after the scale
    kind, w, h, scale = tokens[0], int(tokens[1]), int(tokens[2]), float(tokens[3])
    ch = 3 if kind == "PF" else 1
    dtype = "<f4" if scale < 0 else ">f4"
    img = np.frombuffer(data, dtype=dtype, count=w * h * ch, offset=pos).astype(np.float64)
    img = img.reshape(h, w, ch)[::-1]  # PFM rows run bottom to top
    if ch == 1:
        img = np.repeat(img, 3, axis=2)
    return np.ascontiguousarray(img)


_SKY_CACHE: dict = {}


def _load_sky_image(path: Path) -> np.ndarray:
    path = Path(path)
    key = (str(path.resolve()), path.stat().st_mtime_ns)
    if key not in _SKY_CACHE:
        if path.suffix.lower() == ".pfm":
            img = _read_pfm(path)
        else:
            img = _srgb_to_linear(read_picture_encoded(path))
        _SKY_CACHE[key] = img
    return _SKY_CACHE[key]


def _sample_equirect(img: np.ndarray, D: np.ndarray) -> np.ndarray:
    h, w = img.shape[:2]
    u = 0.5 + np.arctan2(D[:, 0], -D[:, 2]) / (2.0 * math.pi)
    v = np.arccos(np.clip(D[:, 1], -1.0, 1.0)) / math.pi
    x = u * w - 0.5
    y = v * h - 0.5
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    xa = np.mod(x0, w)
    xb = np.mod(x0 + 1, w)
    ya = np.clip(y0, 0, h - 1)
    yb = np.clip(y0 + 1, 0, h - 1)
    top = img[ya, xa] * (1 - fx) + img[ya, xb] * fx
    bot = img[yb, xa] * (1 - fx) + img[yb, xb] * fx
    return top * (1 - fy) + bot * fy


def sky_radiance(scene: Scene, dirs) -> np.ndarray:
    """What a ray with unit direction d that leaves the scene sees, (N, 3)."""
    D = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    sky = scene.sky
    if sky.type == "color":
        return np.broadcast_to(np.array(sky.color, dtype=np.float64), D.shape).copy()
    if sky.type == "gradient":
        t = np.maximum(D[:, 1], 0.0)[:, None]
        return np.array(sky.horizon) * (1.0 - t) + np.array(sky.zenith) * t
    if sky.type == "image":
        path = sky.image_path if sky.image_path is not None else Path(sky.image)
        return _sample_equirect(_load_sky_image(path), D)
    raise ValueError(f"unknown sky type {sky.type!r}")
