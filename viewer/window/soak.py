"""`glassray view --soak N` (hidden; `make run` and the tests use it): the
viewer driven by programmatic input for N frames, so that its memory and GL
objects can be counted before and after (Viewer.run prints them)."""

from __future__ import annotations

import math

from . import backend  # noqa: F401  (first: it imports imgui-bundle before glfw)

import glfw  # noqa: E402


def soak_step(viewer) -> None:
    """Programmatic input for ``--soak N``: the camera orbits and zooms,
    the light moves, the panel opens and closes, the window changes size,
    and every few frames the view stays still so that samples accumulate."""
    n = viewer.frames
    c = viewer.controls
    if n == 0:
        viewer.soak_depth = min(9, viewer.scene.render.max_depth)
    phase = n % 40
    if phase < 30:
        c.orbit_pixels(3.0, 2.0 * math.sin(n * 0.05))
        if n % 7 == 0:
            c.key("d" if (n // 70) % 2 == 0 else "a", shift=n % 14 == 0)
        if n % 11 == 0:
            c.scroll(0.0, 0.5 if (n // 110) % 2 == 0 else -0.5)
        if n % 97 == 0:  # two depths, both compiled during the warm-up
            c.key("3" if (n // 97) % 2 == 0 else str(viewer.soak_depth))
    if n % 150 == 0 and viewer.panel is not None:
        viewer.show_panel = not viewer.show_panel
        viewer.panel.open_all = True  # every widget of the panel drawn
    if n % 60 == 30:
        viewer.show_help = not viewer.show_help
    if n == 60 and viewer.panel is not None:  # "max error": measured in steps, then applied
        viewer.panel.max_error_on = True
        viewer.max_error.update()
    if n % 170 == 85:  # the debug views too (their textures must not pile up)
        c.key("v")
        viewer._view_changed()
    if n % 250 == 125:
        w, h = viewer.args.size
        k = (n // 250) % 3
        glfw.set_window_size(viewer.window, max(1, w + 16 * k), max(1, h + 8 * k))
    viewer.ui_frames = max(viewer.ui_frames, 1)
