"""Screenshot files of the viewer: ``glassray-YYYYMMDD-HHMMSS.png`` in a
folder, with ``-2``, ``-3``, ... before ``.png`` when that name exists.
Writes are atomic (viewer.scene.write_atomic)."""

from __future__ import annotations

import io
import time
from pathlib import Path

import numpy as np

from .imageio import encode_png
from .scene import write_atomic


def screenshot_path(folder: str | Path = ".", when: float | None = None) -> Path:
    folder = Path(folder)
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(time.time() if when is None else when))
    path = folder / f"glassray-{stamp}.png"
    n = 2
    while path.exists():
        path = folder / f"glassray-{stamp}-{n}.png"
        n += 1
    return path


def save_linear(linear: np.ndarray, folder: str | Path = ".", when: float | None = None) -> Path:
    """(H, W, 3) linear radiance -> the spec's 8-bit sRGB PNG; returns the path."""
    path = screenshot_path(folder, when)
    write_atomic(path, encode_png(linear))
    return path


def save_rgb8(rgb: np.ndarray, folder: str | Path = ".", when: float | None = None) -> Path:
    """(H, W, 3) uint8, already display-encoded (a read-back of the window)."""
    from PIL import Image

    path = screenshot_path(folder, when)
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb, dtype=np.uint8), "RGB").save(buf, format="PNG")
    write_atomic(path, buf.getvalue())
    return path
