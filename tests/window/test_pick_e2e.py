"""Selecting and moving an object in a real window under Xvfb, with real
input from xdotool: a click on the ball of the default scene selects the
ball (the window prints it, the outline is drawn round it and only round
it, the panel opens its node), an arrow key moves it, Ctrl+Z gives the
picture back bit for bit, and Esc clears the selection before it quits."""

from __future__ import annotations

import shutil
import time

import numpy as np
import pytest

from test_viewer_e2e import Viewer, settled_shot, wait_for

pytestmark = pytest.mark.skipif(not (shutil.which("Xvfb") and shutil.which("xdotool")),
                                reason="needs Xvfb and xdotool (make test installs them)")

#: Where the ball of the default scene is in a 480x270 window: its centre,
#: from the scene's camera (the picture below checks it is the ball).
BALL = (115, 150)


def orange(img: np.ndarray) -> np.ndarray:
    """Pixels of the selection outline's colour (viewer.window.selection
    OUTLINE_COLOR, 255 x (1.0, 0.62, 0.16)), blended at 0.55 or whole."""
    p = img.astype(int)
    return (p[..., 0] > 200) & (np.abs(p[..., 1] - 158) < 40) & (p[..., 2] < 110)


def click(v: Viewer, xy) -> None:
    """Move there, then click, as a hand does: ImGui learns at its next
    frame that the pointer left the panel (or came onto it)."""
    v.xdo("mousemove", "--window", v.wid, str(xy[0]), str(xy[1]))
    time.sleep(0.2)
    v.xdo("click", "1")


def test_click_selects_the_ball_and_ctrl_z_takes_its_move_back(xdisplay, tmp_path):
    v = Viewer(xdisplay, tmp_path, "default", "--size", "480x270", "--no-vsync", "--samples", "1")
    try:
        scene = (slice(60, 270), slice(0, 480))     # below the HUD
        before = settled_shot(v, scene)
        assert not orange(before[scene]).any()
        plain = v.shot()
        click(v, BALL)
        assert wait_for(v, "selected 4: ball (sphere)") < 15
        selected = settled_shot(v, scene)
        ring = orange(selected)
        ys, xs = np.nonzero(ring[60:])
        ys = ys + 60
        assert len(xs) > 40, len(xs)
        # round the ball: a closed curve a few tens of pixels across round
        # the point clicked, and nothing orange anywhere else
        assert xs.min() < BALL[0] < xs.max() and ys.min() < BALL[1] < ys.max(), (xs.min(), xs.max(), ys.min(), ys.max())
        assert 30 < xs.max() - xs.min() < 120 and 30 < ys.max() - ys.min() < 120
        assert np.hypot(xs.mean() - BALL[0], ys.mean() - BALL[1]) < 20
        # the outline is the window's, never the picture's: P has none
        assert np.array_equal(v.shot(), plain)
        # an arrow moves the ball; Ctrl+Z gives the picture back bit for bit
        v.key("Right")
        moved = v.shot()
        assert np.abs(moved.astype(int) - plain.astype(int)).mean() > 0.05
        v.key("ctrl+z")
        assert np.array_equal(v.shot(), plain)
        v.key("ctrl+shift+z")
        assert np.array_equal(v.shot(), moved)
        # Esc clears the selection (and the outline) and does not quit
        v.key("Escape")
        assert wait_for(v, "nothing selected") < 15
        assert not orange(settled_shot(v, scene)[scene]).any()
        assert v.proc.poll() is None
        # with the panel open, the click opens the ball's node and scrolls
        # to it (the Objects section was closed: the panel's side changes,
        # by about 30 of 255; the click's taking focus from the panel
        # darkens its title bar alone, 4.4)
        v.key("Tab")
        side = (slice(0, 270), slice(270, 480))
        closed = settled_shot(v, side)
        click(v, BALL)
        assert wait_for(v, "selected 4: ball (sphere)") < 15
        opened = settled_shot(v, side)
        assert np.abs(opened[side].astype(int) - closed[side].astype(int)).mean() > 12
        v.key("Escape")
        assert wait_for(v, "nothing selected") < 15
        assert v.quit() == 0
    finally:
        v.close()


def test_save_from_the_window_keeps_the_file_and_writes_only_the_move(xdisplay, tmp_path):
    """The shipped default scene, copied to a file of the user's and viewed
    with `--samples 1`: "Save scene" in the panel, unedited, writes it back
    byte for byte (the command line's samples are how this run looks at the
    file, not an edit of it); after the ball is clicked and moved with an
    arrow key, Ctrl+S changes only the ball's `center` line, and the file
    loads back to the moved ball."""
    from importlib import resources

    from viewer.api import load_scene

    mine = tmp_path / "my.toml"
    original = resources.files("viewer.scene.builtin").joinpath("default.toml").read_bytes()
    mine.write_bytes(original)
    v = Viewer(xdisplay, tmp_path, str(mine), "--size", "480x270", "--no-vsync", "--samples", "1")
    try:
        v.key("Tab")
        settled_shot(v, (slice(0, 270), slice(256, 480)))
        save = (355, 62)                                   # "Save scene", right of the path box (my.toml)
        click(v, save)
        assert wait_for(v, f"saved scene {mine.resolve()}") < 15
        assert mine.read_bytes() == original
        click(v, BALL)
        assert wait_for(v, "selected 4: ball (sphere)") < 15
        v.key("Right")
        v.key("ctrl+s")                                    # the panel has scrolled to the ball's node
        assert wait_for(v, f"saved scene {mine.resolve()}") < 15
        old, new = original.decode().splitlines(), mine.read_text().splitlines()
        changed = [(a, b) for a, b in zip(old, new) if a != b]
        assert len(old) == len(new) and len(changed) == 1, changed
        assert changed[0][0].lstrip().startswith("center") and changed[0][1].lstrip().startswith("center")
        before, after = load_scene(original.decode()).objects[4], load_scene(mine).objects[4]
        assert after.center != before.center and after.center[1] == before.center[1]   # along the floor
        v.key("Escape")                                    # the selection first, then quit
        assert wait_for(v, "nothing selected") < 15
        assert v.quit() == 0
    finally:
        v.close()
