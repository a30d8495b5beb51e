"""What the window shows besides the image, without GLFW or ImGui: the help
text (stdout without the panel), the names of the debug views, and the
window's picture of a debug view.
"""

from __future__ import annotations

import numpy as np

from ..base.views import picture
from .controls import HELP_ALL

#: What the HUD says of each debug view.
VIEW_NAMES = {"cost": "cost (rays traced per pixel)", "normals": "normals (first hit)",
              "depth": "depth (first hit, log scale)", "objects": "objects (first hit)"}


def help_text() -> str:
    width = max(len(k) for k, _ in HELP_ALL)
    return "\n".join(f"  {k:<{width}}  {v.replace('`', '')}" for k, v in HELP_ALL)


def window_picture(view: str, raw: np.ndarray, width: int, height: int) -> np.ndarray:
    """The window's picture of a debug view: uint8 (height, width, 3).  ``raw``
    (viewer.views.raw_view, possibly smaller: scaled up to the window,
    nearest pixel) coloured as ``glassray render --view`` does
    (viewer.views.picture); a legend strip (depth, cost) replaces the
    picture's bottom rows, so that the view keeps the image's framing."""
    h, w = raw.shape[:2]
    if (w, h) != (width, height):
        ys = np.arange(height) * h // height
        xs = np.arange(width) * w // width
        raw = raw[ys][:, xs]
    pic = picture(view, raw)
    if pic.shape[0] > height:
        legend = pic[height:]
        pic = (np.concatenate([pic[:height - legend.shape[0]], legend]) if height >= 2 * legend.shape[0]
               else pic[:height])
    return np.round(255 * pic).astype(np.uint8)


# ------------------------------------------------------------ the HUD's lines

#: How readily a HUD line is left out of a window too small to show them all
#: whole (the higher, the sooner): the key hint first, then the depth, the
#: resolution, what the view is doing (frame time, samples), and last the
#: notes (a failed reload, the selection, "max error"); the message, there
#: to be read, is never left out.
ALWAYS, NOTE, STATUS, RESOLUTION, DEPTH, HINT = range(6)


def lines_that_fit(ranks: list[int], heights: list[float], room: float, gap: float) -> list[bool]:
    """Which of the HUD's lines to show, in their order: all of them when
    their heights (each line as wrapped) and a `gap` between two fit in
    `room`; else the lines of the highest rank are left out first (among
    equals the last first) until the rest fit.  ALWAYS lines are never
    left out: in a window too small even for those, they are shown and the
    window cuts them."""
    shown = [True] * len(ranks)

    def height() -> float:
        hs = [h for h, s in zip(heights, shown) if s]
        return sum(hs) + gap * max(0, len(hs) - 1)

    for i in sorted(range(len(ranks)), key=lambda i: (-ranks[i], -i)):
        if height() <= room or ranks[i] == ALWAYS:
            break
        shown[i] = False
    return shown
