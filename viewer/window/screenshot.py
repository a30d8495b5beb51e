"""Screenshot files of the viewer: ``glassray-YYYYMMDD-HHMMSS.png`` in a
folder, with ``-2``, ``-3``, ... before ``.png`` when that name exists.
A screenshot never replaces a file, also not one another program saves
under the same name at the same moment, and is never seen half-written
(viewer.scene.write_new)."""

from __future__ import annotations

import io
import itertools
import time
from pathlib import Path

import numpy as np

from ..base.imageio import encode_png
from ..base.files import write_new


def screenshot_names(folder: str | Path = ".", when: float | None = None):
    """glassray-STAMP.png, then glassray-STAMP-2.png, -3, ... (endless)."""
    folder = Path(folder)
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(time.time() if when is None else when))
    yield folder / f"glassray-{stamp}.png"
    for n in itertools.count(2):
        yield folder / f"glassray-{stamp}-{n}.png"


def screenshot_path(folder: str | Path = ".", when: float | None = None) -> Path:
    """The name a screenshot saved now would take (the first free one)."""
    return next(p for p in screenshot_names(folder, when) if not p.exists())


def save_linear(linear: np.ndarray, folder: str | Path = ".", when: float | None = None) -> Path:
    """(H, W, 3) linear radiance -> the spec's 8-bit sRGB PNG; returns the path."""
    return write_new(screenshot_names(folder, when), encode_png(linear))


def save_rgb8(rgb: np.ndarray, folder: str | Path = ".", when: float | None = None) -> Path:
    """(H, W, 3) uint8, already display-encoded (a read-back of the window)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb, dtype=np.uint8), "RGB").save(buf, format="PNG")
    return write_new(screenshot_names(folder, when), buf.getvalue())
