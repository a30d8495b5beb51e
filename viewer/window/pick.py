"""Picking and moving objects, with no window code: which objects lie along
the camera ray through a pixel, which one a repeated click selects, where an
object is, and how a move changes it.  Plain Python and numpy; the viewer
(window/app.py) asks the GPU for the first hit and hands the rest here.

Invariants:
- an object index is its position in ``scene.objects`` (what the shader's
  first-hit view writes, and the panel's node "i: name");
- a move changes only the object's position keys (a sphere's ``center``, a
  box's ``min`` and ``max`` together, a cylinder's ``base``, a plane's
  ``height``), so a moved object keeps its size, rotation and material, and
  a valid scene stays valid.
"""

from __future__ import annotations

import math

import numpy as np

from ..reference.camera import pixel_rays
from ..reference.surfaces import Surfaces
from ..scene.model import Scene, SceneObject

#: A press and release closer than this (window pixels) is a click, not a drag.
CLICK_PX = 4.0

#: The unit vector of each cylinder axis.
_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def objects_along(scene: Scene, width: int, height: int, x: float, y: float) -> list[int]:
    """The objects the camera ray through the centre of pixel (x, y) of a
    width x height image (x to the right, y down from the top row) meets,
    nearest first, each once (by where the ray first meets it), in the
    float64 reference's geometry.  A rod in a glass of water, clicked
    through the glass: [glass, water, rod, floor]."""
    i = min(max(int(x), 0), width - 1)
    j = min(max(int(y), 0), height - 1)
    o, d = pixel_rays(scene, width, height, [j * width + i], [(0.5, 0.5)])
    surfaces = Surfaces(scene)
    if surfaces.K == 0:
        return []
    table, _ = surfaces.table(o, d, normals=False)
    first: dict[int, float] = {}
    for col, t in enumerate(table[0]):
        if t > 0 and math.isfinite(t):
            k = int(surfaces.col_obj[col])
            first[k] = min(first.get(k, math.inf), float(t))
    return sorted(first, key=lambda k: (first[k], k))


def next_pick(first_hit: int, along: list[int], current: int | None, again: bool) -> int | None:
    """The object a click selects: the one the GPU's first hit names
    (``first_hit``, -1 for the sky: nothing), or, for a click again on the
    same spot (``again``) while the selection lies along that ray, the
    object behind it (after the last, the nearest again): so clicking on a
    glass of water selects the glass, then the water, then the rod in it."""
    if first_hit < 0:
        return None
    if again and current is not None and current in along:
        return along[(along.index(current) + 1) % len(along)]
    return first_hit


def anchor(obj: SceneObject, near: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """A point that moves with the object (its centre; a plane's point
    below or above `near`): where a drag holds it under the cursor."""
    if obj.type == "sphere":
        return np.array(obj.center, float)
    if obj.type == "box":
        return 0.5 * (np.array(obj.min, float) + np.array(obj.max, float))
    if obj.type == "cylinder":
        return np.array(obj.base, float) + 0.5 * obj.height * np.array(_AXES[obj.axis])
    return np.array((near[0], obj.height, near[2]), float)


def translate(obj: SceneObject, delta) -> bool:
    """Move the object by `delta` (a plane only by its y); False, and the
    object unchanged, when the move changes nothing or would leave a
    position that is not finite."""
    d = tuple(float(v) for v in delta)

    def add(p):
        return tuple(a + b for a, b in zip(p, d))

    if obj.type == "plane":
        new = {"height": obj.height + d[1]}
    elif obj.type == "sphere":
        new = {"center": add(obj.center)}
    elif obj.type == "box":
        new = {"min": add(obj.min), "max": add(obj.max)}
    else:
        new = {"base": add(obj.base)}
    values = [v for value in new.values() for v in (value if isinstance(value, tuple) else (value,))]
    if not all(math.isfinite(v) for v in values):
        return False
    if all(getattr(obj, k) == v for k, v in new.items()):
        return False
    for k, v in new.items():
        setattr(obj, k, v)
    return True


def floor_axes(forward) -> tuple[np.ndarray, np.ndarray]:
    """The keys' directions in the floor (y = 0) plane: (right, ahead),
    unit vectors from the camera's forward direction; looking straight down,
    ahead is world -z."""
    f = np.array(forward, float)
    ahead = np.array((f[0], 0.0, f[2]))
    n = np.linalg.norm(ahead)
    ahead = ahead / n if n > 1e-9 else np.array((0.0, 0.0, -1.0))
    right = np.array((-ahead[2], 0.0, ahead[0]))
    return right, ahead
