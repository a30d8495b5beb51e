"""What the viewer's inputs do, with no window code: the window module
(viewer/window/app.py) turns GLFW events into calls on :class:`Controls`, which move
the orbit camera and the scene's light and change the render settings.
Everything here is plain Python, so the tests drive it directly.

Keys are named by lower-case strings: ``"w"``, ``"1"``, ``"tab"``, ``"f5"``,
``"escape"``...; mouse buttons are ``"left"``, ``"right"``, ``"middle"``;
positions are window coordinates in pixels (x to the right, y downward), the
same units as the window size given to :meth:`Controls.set_window_size`.
"""

from __future__ import annotations

import copy
import math
from dataclasses import replace

import numpy as np

from .camera import OrbitCamera
from .pick import CLICK_PX, anchor, floor_axes
from ..scene.model import Scene

#: A drag across the full height of the window turns the camera by this many radians.
ORBIT_RADIANS_PER_HEIGHT = math.pi
#: One scroll notch (offset 1.0) scales the distance to the target by this factor.
ZOOM_PER_NOTCH = 0.9
#: A light key moves the light by this fraction of the starting camera distance ...
LIGHT_STEP_FRACTION = 0.02
#: ... times this with shift held.
LIGHT_FAST = 5.0

#: Light keys: key -> (axis, sign): W/S -z/+z, A/D -x/+x, Q/E -y/+y.
LIGHT_KEYS = {"w": (2, -1.0), "s": (2, 1.0), "a": (0, -1.0), "d": (0, 1.0), "q": (1, -1.0), "e": (1, 1.0)}

#: Keys that move the selected object: key -> (direction, sign); "floor-right"
#: and "floor-ahead" are the camera's right and forward laid flat on the
#: floor (window/pick.py, floor_axes), "up" is world +y.  A step is a light
#: step (LIGHT_STEP_FRACTION of the camera's distance), LIGHT_FAST with shift.
OBJECT_KEYS = {"left": ("floor-right", -1.0), "right": ("floor-right", 1.0),
               "up": ("floor-ahead", 1.0), "down": ("floor-ahead", -1.0),
               "pageup": ("up", 1.0), "pagedown": ("up", -1.0)}

#: With Ctrl held: (key, shift) -> the action (undo and redo of the panel's
#: edits, saving the scene as the panel's "Save scene" does).
CTRL_ACTIONS = {("z", False): "undo", ("z", True): "redo", ("y", False): "redo", ("s", False): "save_scene"}

#: Keys that the window handles (they return an action name from Controls.key).
ACTIONS = {"p": "screenshot", "f12": "screenshot_window", "tab": "toggle_panel", "f5": "reload",
           "h": "help", "f1": "help", "escape": "quit"}

#: The controls table of shared/spec/cli.md: shown by H / F1 and in the README.
HELP = [
    ("left-drag", "orbit the camera around its target"),
    ("right-drag or shift+left-drag", "pan (move the target)"),
    ("scroll", "zoom (dolly toward the target)"),
    ("W / S, A / D, Q / E", "move the light: -z / +z, -x / +x, -y / +y (hold shift: faster)"),
    ("R", "reset camera and light to the values the viewer started with "
          "(scene file plus command-line overrides)"),
    ("P", "save the current view (no HUD, no panel) rendered at full framebuffer resolution with the "
          "samples accumulated so far, as `glassray-YYYYMMDD-HHMMSS.png` in the current folder "
          "(`-2`, `-3`, … before `.png` if that name exists); the path is printed on stdout"),
    ("F12", "the same, of the window as shown (HUD and panel included)"),
    ("Tab", "show / hide the settings panel"),
    ("1..9", "max depth 1..9"),
    ("F5", "reload shaders and the scene file from disk (command-line overrides applied again)"),
    ("H or F1", "help overlay"),
    ("Esc", "quit"),
]


#: What the window shows: the image, or a debug view of viewer/base/views.py
#: (the rays traced per pixel, the first hit's normal, distance or object).
VIEWS = ("image", "cost", "normals", "depth", "objects")

#: Viewer keys beyond the spec's table (shown by H / F1 below it).
EXTRA_HELP = [
    ("V (shift+V: back)", "cycle the view: image, cost (rays traced per pixel, with a legend), normals, "
                          "depth, objects (the first hit's normal, distance, object); the HUD names it"),
    ("middle-drag", "pan, as right-drag"),
    ("click", "select the object under the cursor (outlined; the panel opens its node and material); "
              "click the same spot again: the object behind it (through a glass: the liquid, then the rod); "
              "click the sky or Esc: select nothing (Esc with nothing selected quits)"),
    ("arrows, PageUp / PageDown", "move the selected object: left / right and away / toward along the floor "
                                  "as the camera faces it, up / down (hold shift: faster)"),
    ("ctrl+left-drag", "move the selected object in the plane facing the camera, under the cursor"),
    ("Ctrl+Z / Ctrl+Shift+Z or Ctrl+Y", "undo / redo the settings panel's edits and object moves"),
    ("Ctrl+S", "save the scene as the panel's Save scene does (to the path in its box: the scene's own file, "
               "or NAME.toml in the current folder for a built-in scene)"),
    ("drop a .toml file", "open that scene (its camera if the file has one, else the view stays)"),
]

#: Everything the help overlay lists.
HELP_ALL = HELP + EXTRA_HELP


def first_point_light(scene: Scene) -> int | None:
    for i, lt in enumerate(scene.lights):
        if lt.type == "point" and lt.position is not None:
            return i
    return None


class Controls:
    """Input -> camera, light and settings of one scene (changed in place).

    After any change that alters the picture, :attr:`changed` is True until
    :meth:`take_changed` reads it; the scene's ``camera`` always holds the
    orbit camera's position, target and fov."""

    def __init__(self, scene: Scene, window_size: tuple[int, int] = (1280, 720)):
        self.window_size = (max(1, int(window_size[0])), max(1, int(window_size[1])))
        self._drag: str | None = None  # "orbit" or "pan" while a button is held
        self._drag_button: str | None = None
        self._last: tuple[float, float] | None = None
        self._press_at: tuple[float, float] | None = None   # where a left-button orbit started
        self._dragged = False             # ... and whether it has gone CLICK_PX from there
        self.selected: int | None = None  # the selected object (its index in scene.objects)
        # a move of the selected object asked for by keys or a drag, not
        # applied yet: the window applies it between two snapshots of the
        # undo history, so that it is an edit of its own (window/app.py)
        self.pending_move = np.zeros(3)
        self.pick_request: tuple[float, float] | None = None  # a click to pick at (window pixels)
        self.changed = True
        self.message = ""  # a short note for the HUD (for example "no point light to move")
        self.view = VIEWS[0]  # what the window shows (V cycles)
        self.rebase(scene)

    # ------------------------------------------------------------ state

    def rebase(self, scene: Scene, start: Scene | None = None) -> None:
        """Use this scene from now on; R returns to the camera and lights of
        ``start`` (the scene file plus overrides; default: ``scene`` as it is now)."""
        start = scene if start is None else start
        self.scene = scene
        self._start_camera = replace(start.camera)
        self._start_lights = copy.deepcopy(start.lights)
        # the camera's limits and the light's step scale with the scene (the
        # format has no unit: a scene in nanometres moves as the same scene
        # at unit size does), taken from the camera it starts with
        self._limits = OrbitCamera.limits_for(start.camera.position, start.camera.target)
        self.camera = OrbitCamera.look_at(scene.camera.position, scene.camera.target, scene.camera.fov,
                                          self._limits)
        start_distance = math.dist(start.camera.position, start.camera.target)
        self.light_step = LIGHT_STEP_FRACTION * start_distance
        self.changed = True

    def take_changed(self) -> bool:
        c, self.changed = self.changed, False
        return c

    def set_window_size(self, width: int, height: int) -> None:
        self.window_size = (max(1, int(width)), max(1, int(height)))

    def _sync_scene_camera(self) -> None:
        cam = self.scene.camera
        cam.position = self.camera.position
        cam.target = tuple(float(x) for x in self.camera.target)
        cam.fov = self.camera.fov
        self.changed = True

    def camera_edited(self) -> None:
        """The scene's camera was edited directly (settings panel): follow it."""
        c = self.scene.camera
        try:
            self.camera = OrbitCamera.look_at(c.position, c.target, c.fov, self._limits)
        except ValueError:  # position == target: keep the orbit camera, put it back
            self._sync_scene_camera()
            return
        # the scene keeps the values as edited: the orbit camera's position,
        # rebuilt from angles and a distance, can differ in the last bit
        # (editing only fov turned 4.6 into 4.6000000000000005 in a saved scene)
        self.changed = True

    # ------------------------------------------------------------ mouse

    def press(self, button: str, x: float, y: float, shift: bool = False, ctrl: bool = False) -> None:
        if self._drag is not None:
            return
        if button == "left" and ctrl and self.selected is not None:
            self._drag = "move"                  # the selected object follows the cursor
        elif button == "left":
            self._drag = "pan" if shift else "orbit"
            self._press_at, self._dragged = (float(x), float(y)), False
        elif button in ("right", "middle"):      # middle-drag pans, as in Blender and most 3D tools
            self._drag = "pan"
        else:
            return
        self._drag_button = button
        self._last = (float(x), float(y))

    def release(self, button: str, x: float | None = None, y: float | None = None) -> None:
        if button != self._drag_button:
            return
        if x is not None and y is not None:
            self.move(x, y)
        if self._drag == "orbit" and not self._dragged and self._press_at is not None:
            self.pick_request = self._press_at   # a click, not a drag: pick what is under it
        self._drag = self._drag_button = None
        self._last = self._press_at = None

    @property
    def dragging(self) -> str | None:
        return self._drag

    def move(self, x: float, y: float) -> None:
        if self._drag is None or self._last is None:
            return
        if not (math.isfinite(x) and math.isfinite(y)):
            return
        if self._drag == "orbit" and not self._dragged:
            # a click until the cursor has gone CLICK_PX: a hand's jitter
            # during a click neither turns the camera nor restarts the
            # samples; past it the drag turns by all of its way so far
            if math.dist(self._press_at, (x, y)) < CLICK_PX:
                return
            self._dragged = True
        dx, dy = x - self._last[0], y - self._last[1]
        self._last = (float(x), float(y))
        if dx == 0 and dy == 0:
            return
        if self._drag == "orbit":
            self.orbit_pixels(dx, dy)
        elif self._drag == "move":
            self.move_pixels(dx, dy)
        else:
            self.pan_pixels(dx, dy)

    def orbit_pixels(self, dx: float, dy: float) -> None:
        """Drag right turns the scene right (the eye moves left around the
        target); drag down lifts the eye (the scene tips toward the viewer)."""
        k = ORBIT_RADIANS_PER_HEIGHT / self.window_size[1]
        self.camera.orbit(-dx * k, dy * k)
        self._sync_scene_camera()

    def pan_pixels(self, dx: float, dy: float) -> None:
        """The point under the cursor at the target's depth follows the cursor."""
        s = self.camera.world_per_pixel(self.window_size[1])
        self.camera.pan(-dx * s, dy * s)
        self._sync_scene_camera()

    def move_pixels(self, dx: float, dy: float) -> None:
        """The selected object's centre follows the cursor in the plane that
        faces the camera through it (its depth stays)."""
        if self.selected is None or not 0 <= self.selected < len(self.scene.objects):
            return
        eye, f = np.array(self.camera.position), np.array(self.camera.forward)
        depth = float(np.dot(anchor(self.scene.objects[self.selected], self.camera.target) - eye, f))
        if not depth > 0:       # behind the eye: a drag has no plane to follow
            return
        s = self.camera.world_per_pixel(self.window_size[1]) * depth / self.camera.distance
        self.pending_move = self.pending_move + s * (dx * np.array(self.camera.right) - dy * np.array(self.camera.up))

    def move_selected(self, direction: str, steps: float) -> bool:
        """A key's move of the selected object (OBJECT_KEYS), queued on
        pending_move; False when nothing is selected."""
        if self.selected is None:
            self.message = "click an object to select it, then move it with the arrows"
            return False
        right, ahead = floor_axes(self.camera.forward)
        unit = {"floor-right": right, "floor-ahead": ahead, "up": np.array((0.0, 1.0, 0.0))}[direction]
        self.pending_move = self.pending_move + steps * self.light_step * unit
        return True

    def take_move(self) -> np.ndarray | None:
        """The queued move of the selected object, or None; cleared."""
        if not np.any(self.pending_move):
            return None
        move, self.pending_move = self.pending_move, np.zeros(3)
        return move

    def scroll(self, dx: float, dy: float) -> None:
        """Scroll up (dy > 0) moves the eye toward the target."""
        if not math.isfinite(dy) or dy == 0:
            return
        dy = max(-100.0, min(100.0, dy))
        self.camera.dolly(ZOOM_PER_NOTCH ** dy)
        self._sync_scene_camera()

    # ------------------------------------------------------------ keys

    def key(self, name: str, shift: bool = False, repeat: bool = False, ctrl: bool = False) -> str | None:
        """Handle a key press (``repeat``: the key is held).  Returns the
        name of an action the window must carry out (``"screenshot"``,
        ``"screenshot_window"``, ``"toggle_panel"``, ``"reload"``, ``"help"``,
        ``"quit"``, ``"view"`` after V changed :attr:`view`; with ``ctrl``
        ``"undo"`` or ``"redo"``, CTRL_ACTIONS; ``"deselect"`` for Esc while an
        object is selected) or None."""
        name = name.lower()
        if ctrl:
            return None if repeat else CTRL_ACTIONS.get((name, shift))
        if name in OBJECT_KEYS:
            direction, sign = OBJECT_KEYS[name]
            self.move_selected(direction, sign * (LIGHT_FAST if shift else 1.0))
            return None
        if name in LIGHT_KEYS:
            axis, sign = LIGHT_KEYS[name]
            self.move_light(axis, sign * (LIGHT_FAST if shift else 1.0))
            return None
        if repeat:
            return None
        if name == "r":
            self.reset()
            return None
        if len(name) == 1 and name in "123456789":
            self.set_max_depth(int(name))
            return None
        if name == "v":
            self.cycle_view(-1 if shift else 1)
            return "view"
        if name == "escape" and self.selected is not None:
            return "deselect"           # Esc clears a selection first, and quits after
        return ACTIONS.get(name)

    def cycle_view(self, step: int = 1) -> str:
        """V: the next view (shift+V: the previous one), wrapping around."""
        i = VIEWS.index(self.view) if self.view in VIEWS else 0
        self.view = VIEWS[(i + step) % len(VIEWS)]
        return self.view

    def set_view(self, name: str) -> None:
        if name not in VIEWS:
            raise ValueError(f"unknown view {name!r} (expected one of {', '.join(VIEWS)})")
        self.view = name

    def move_light(self, axis: int, steps: float) -> bool:
        i = first_point_light(self.scene)
        if i is None:
            self.message = "no point light to move"
            return False
        lt = self.scene.lights[i]
        p = list(lt.position)
        p[axis] += steps * self.light_step
        # any finite position is a valid one (the renderer takes a light
        # 1e300 away as well); a light so far out that a step is lost in
        # rounding does not move, and that is no change
        if not all(math.isfinite(v) for v in p) or tuple(p) == tuple(lt.position):
            return False
        lt.position = (p[0], p[1], p[2])
        self.changed = True
        return True

    def set_max_depth(self, n: int) -> None:
        n = max(1, min(64, int(n)))
        if self.scene.render.max_depth != n:
            self.scene.render.max_depth = n
            self.changed = True

    def reset(self) -> None:
        """Camera and lights back to the values the viewer started with
        (nothing to do, and no change, when they are there already: the
        samples accumulated for the view are kept)."""
        if self.scene.camera == self._start_camera and self.scene.lights == self._start_lights:
            return
        self.scene.camera = replace(self._start_camera)
        self.scene.lights = copy.deepcopy(self._start_lights)
        self.camera = OrbitCamera.look_at(self._start_camera.position, self._start_camera.target,
                                          self._start_camera.fov, self._limits)
        self.changed = True


def merge_reloaded(old_file: Scene, new_file: Scene, current: Scene) -> Scene:
    """The scene after F5: each top-level part (camera, render settings, sky,
    ambient, lights, materials, objects, name) that changed on disk since the
    last load is taken from the file; the others keep what the viewer has
    now (the orbit camera, a moved light, edits in the panel)."""
    from dataclasses import fields

    merged = copy.deepcopy(current)
    for f in fields(Scene):
        if getattr(new_file, f.name) != getattr(old_file, f.name):
            setattr(merged, f.name, copy.deepcopy(getattr(new_file, f.name)))
    return merged
