"""The HUD in a real window under Xvfb: beside the open settings panel, not
under it.  What the window draws over the image is where its F12 screenshot
differs from the image (P); in the rows of the HUD, those columns are two
runs, the HUD's box and the panel, with the HUD's margin between them."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from test_viewer_e2e import Viewer, settled_shot

pytestmark = pytest.mark.skipif(not (shutil.which("Xvfb") and shutil.which("xdotool")),
                                reason="needs Xvfb and xdotool (make test installs them)")


def runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """The [start, end) runs of True in a 1-d array."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(int), [0]])))
    return list(zip(edges[::2], edges[1::2]))


def test_the_hud_lies_beside_the_panel(xdisplay, tmp_path):
    from viewer.window.overlays import HUD_MARGIN

    v = Viewer(xdisplay, tmp_path, "default", "--size", "480x270", "--no-vsync", "--samples", "1")
    try:
        v.key("Tab")
        window = settled_shot(v, (slice(0, 270), slice(0, 480)))   # with its "saved ..." message
        image = v.shot()
        over = np.abs(window.astype(int) - image.astype(int)).max(axis=2) > 3
        hud_rows = over[10:40, :]                                     # the HUD's first lines
        (h0, h1), (p0, p1) = runs(hud_rows.any(axis=0))               # exactly two: HUD, panel
        assert h0 == int(HUD_MARGIN) and h1 < p0 - HUD_MARGIN + 1, (h0, h1, p0, p1)
        assert p1 > 470 and 150 < p0 < 300, (p0, p1)
        # the HUD, message and all, is taller than its four lines: the
        # "saved ..." line wrapped inside the box instead of running under
        # the panel
        left = over[:, h0:h1].any(axis=1)
        top, bottom = runs(left)[0]
        assert bottom - top > 5 * 17, (top, bottom)
        assert v.quit() == 0
    finally:
        v.close()
