"""Run the numerical stability suite: hard cases on the float32 GPU tracer, each checked against the float64 reference.

``glassray stress`` renders a named suite of cases that stress float32
arithmetic (grazing views, rays exactly along the axes, the eye on a box's
planes, the scene moved by up to 1e6 or scaled by 1e-30 to 1e30, glass walls
down to 1e-4 of the radius, coincident surfaces, interfaces that must vanish,
views at the critical angles, a 64-deep ray tree, and every shipped scene)
with the shader and with the independent float64 tracer
(``viewer.reference``), one centred sample per pixel on both sides.  It
prints one row per case and writes a contact sheet (GPU | reference | error
heat map per case).  Exit status 1 when any case exceeds its tolerance.

Metrics (display space: the spec's 8-bit sRGB encoding of each image):

* ``max``, ``mean``: the largest and the mean absolute difference, in 8-bit
  levels (1 level = 1/255), over the unmasked pixels (max over channels).
* ``>1/255``, ``>0.05``: the fraction of unmasked pixels with a channel off
  by more than 1 level, and by more than 0.05 (12.75 levels).
* ``masked``: the fraction of pixels whose footprint straddles an edge
  (silhouettes, checker edges, seen directly, reflected or refracted): the
  reference traced at the four points a quarter pixel around the centre
  differs by more than 8 levels between them.  Only there may a float32
  rounding of the ray flip the pixel to the other side of the edge.
* ``NaN/Inf``: pixels of the GPU image with a non-finite channel.
* ``acne``: among unmasked pixels whose primary ray (reference) meets an
  opaque surface, the fraction that comes out darker than the reference by
  more than 0.05 in some channel: the signature of self-shadowing (a
  secondary ray that re-hits the surface it leaves).
* ``ms``: wall-clock time of one GPU render of the case (after a warm-up
  render that compiles the shader), finished on the GPU.

Default tolerance of a case: no NaN/Inf pixel and at most 0.1% of the
unmasked pixels off by more than 1/255; some cases add a check of their own
(printed with ``--list``).  ``--naive`` compiles the shader with
``NAIVE_INTERSECT`` (the textbook intersection formulas kept in
shaders/lib/intersect.glsl for this comparison); ``--intersections`` also
prints the float32 intersection error distribution per primitive, before
(textbook) and after (robust formulations).
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

DEFAULT_SIZE = (96, 54)
DEFAULT_OUT = "stress-results"
DEFAULT_TOL = 0.001          # fraction of unmasked pixels off by more than 1/255
STRADDLE_DELTA = 1 / 64      # pixels: how close to the sample point an edge must pass to mask it
STRADDLE_LEVELS = 2          # a change (8-bit levels) within STRADDLE_DELTA that marks an edge
ACNE_LEVEL = 0.05            # darker than the reference by this much (display 0..1)


# ---------------------------------------------------------------- scene documents


def _base(name: str = "default", **render) -> dict:
    """A shipped scene as a plain document, one sample per pixel."""
    from ..scene.load import load_scene
    from ..scene.save import scene_to_dict

    doc = scene_to_dict(load_scene(name))
    doc["render"]["samples"] = 1
    doc["render"].update(render)
    return doc


def _obj(doc: dict, name: str) -> dict:
    return next(o for o in doc["objects"] if o.get("name") == name)


def _transform(doc: dict, point: Callable[[np.ndarray], np.ndarray], scale: float = 1.0) -> dict:
    """The same scene with every position mapped by ``point`` and every length
    multiplied by ``scale`` (absorption coefficients divided by it)."""
    d = copy.deepcopy(doc)

    def p(v):
        return [float(x) for x in point(np.array(v, dtype=np.float64))]

    d["camera"]["position"] = p(d["camera"]["position"])
    d["camera"]["target"] = p(d["camera"]["target"])
    for lt in d.get("lights", []):
        if lt.get("type", "point") == "point":
            lt["position"] = p(lt["position"])
    for o in d.get("objects", []):
        t = o["type"]
        if t == "plane":
            o["height"] = p([0.0, o.get("height", 0.0), 0.0])[1]
        elif t == "sphere":
            o["center"], o["radius"] = p(o["center"]), o["radius"] * scale
        elif t == "box":
            o["min"], o["max"] = p(o["min"]), p(o["max"])
        else:
            o["base"] = p(o["base"])
            for k in ("radius", "height", "wall"):
                if k in o:
                    o[k] = o[k] * scale
    for m in d.get("materials", {}).values():
        if "checker" in m:
            m["checker"]["size"] = m["checker"]["size"] * scale
        if "absorption" in m:
            m["absorption"] = [a / scale for a in m["absorption"]]
    return d


def translated(doc: dict, offset) -> dict:
    """The scene moved by ``offset``.  A checker repeats every 2 * size, so an
    offset that is a multiple of it leaves the image unchanged."""
    off = np.array(offset, dtype=np.float64)
    for m in doc.get("materials", {}).values():
        if "checker" in m:
            period = 2 * m["checker"]["size"]
            assert np.all(np.mod(off[[0, 2]], period) == 0), "translate by multiples of the checker period"
    return _transform(doc, lambda v: v + off)


def scaled(doc: dict, s: float) -> dict:
    """The scene (geometry, camera, lights, checker) scaled by s about the
    origin; absorption per unit length scales by 1/s, so the image is the same."""
    return _transform(doc, lambda v: v * s, s)


def _axes_doc() -> dict:
    """Axis-aligned primitives at dyadic coordinates (so camera-relative
    coordinates are exact): a cup (vessel along y), solid cylinders along x and
    z, an axis-aligned box, a mirror ball, a checker floor."""
    return {
        "name": "axes",
        "camera": {"position": [3.0, 2.5, 4.5], "target": [0.0, 0.5, 0.0], "fov": 45},
        "render": {"max_depth": 6, "samples": 1},
        "lights": [{"type": "point", "position": [-3.0, 5.0, 4.0], "intensity": 0.7}],
        "materials": {
            "floor": {"color": [0.8, 0.8, 0.8], "checker": {"color": [0.3, 0.3, 0.3], "size": 0.5}},
            "cup": {"color": [0.9, 0.6, 0.2], "specular": 0.3},
            "rodx": {"color": [0.2, 0.55, 0.9], "specular": 0.3},
            "rodz": {"color": [0.3, 0.8, 0.3], "specular": 0.2},
            "box": {"color": [0.85, 0.3, 0.3], "specular": 0.2},
            "ball": {"color": [0.7, 0.7, 0.9], "specular": 0.5, "reflectivity": 0.3},
        },
        "objects": [
            {"type": "plane", "name": "floor", "material": "floor"},
            {"type": "cylinder", "name": "cup", "axis": "y", "base": [0.0, 0.0, 0.0], "radius": 0.5,
             "height": 1.0, "wall": 0.0625, "material": "cup"},
            {"type": "cylinder", "name": "rodx", "axis": "x", "base": [-1.5, 0.5, 1.0], "radius": 0.25,
             "height": 2.25, "material": "rodx"},
            {"type": "cylinder", "name": "rodz", "axis": "z", "base": [1.25, 0.375, -1.5], "radius": 0.25,
             "height": 2.25, "material": "rodz"},
            {"type": "box", "name": "box", "min": [-1.5, 0.0, -1.25], "max": [-0.75, 0.75, -0.5], "material": "box"},
            {"type": "sphere", "name": "ball", "center": [-1.125, 0.375, 0.0], "radius": 0.375, "material": "ball"},
        ],
    }


def _axes_view(position, target, lights: list[dict]) -> dict:
    d = _axes_doc()
    d["camera"].update(position=list(position), target=list(target))
    d["lights"] = d["lights"] + lights
    return d


def _grazing_floor() -> dict:
    d = _base()
    d["camera"] = {"position": [0.4, 0.02, 6.5], "target": [0.0, 0.45, 0.0], "fov": 40}
    return d


def _grazing_light(elevation: float = 1.0) -> dict:
    # a plain floor under a directional light `elevation` degrees above the horizon
    d = _base()
    del d["materials"]["floor"]["checker"]
    el = math.radians(elevation)
    d["lights"] = [{"type": "directional", "direction": [-0.8 * math.cos(el), -math.sin(el), -0.6 * math.cos(el)],
                    "intensity": 6.0}]
    return d


def _grazing_caps() -> dict:
    # the eye exactly in the plane of the glass's rim and of a pedestal's top cap
    d = _base()
    d["materials"]["pedestal"] = {"color": [0.6, 0.6, 0.55], "specular": 0.2}
    d["objects"].append({"type": "cylinder", "name": "pedestal", "base": [1.6, 0.0, -1.2], "radius": 0.35,
                         "height": 2.4, "material": "pedestal"})
    d["camera"] = {"position": [0.5, 2.4, 6.0], "target": [0.0, 2.4, 0.0], "fov": 40}
    return d


def _far_camera(k: float = 35.0) -> dict:
    # the default view from k times as far with a k times narrower field of view
    d = _base()
    c = d["camera"]
    pos, tgt = np.array(c["position"]), np.array(c["target"])
    c["position"] = [float(x) for x in tgt + k * (pos - tgt)]
    c["fov"] = c["fov"] / k
    return d


def _eye_on_floor() -> dict:
    d = _base()
    d["camera"] = {"position": [0.5, 0.0, 6.0], "target": [0.0, 0.6, 0.0], "fov": 40}
    return d


def _thin_wall(f: float) -> dict:
    d = _base()
    g, w = _obj(d, "glass"), _obj(d, "water")
    g["wall"] = f * g["radius"]
    w["base"] = [0.0, g["wall"], 0.0]
    w["radius"] = g["radius"] - g["wall"] / 2          # ends inside the wall, as the format asks
    w["height"] = 1.36 - g["wall"]
    return d


def _coincident() -> dict:
    # the glass on the floor, the liquid's bottom on the glass's inner bottom,
    # the (upright) rod standing on it, the ball touching the floor and the glass
    d = _base()
    rod = _obj(d, "rod")
    rod.update(min=[-0.08, 0.06, -0.08], max=[0.08, 3.1, 0.08], rotate=[0.0, 0.0, 0.0])
    _obj(d, "ball")["center"] = [-1.55, 0.55, 0.0]
    d["camera"] = {"position": [3.0, 0.35, 4.0], "target": [0.0, 0.3, 0.0], "fov": 40}
    return d


def _ior_equal(merged: bool) -> dict:
    """A vessel filled to the rim with a liquid of the glass's ior (and
    absorption), or (merged) the solid cylinder that is their union."""
    clear = {"color": [1, 1, 1], "ambient": 0, "diffuse": 0, "specular": 0, "transparency": 1, "ior": 1.5,
             "absorption": [0.6, 0.3, 0.15]}
    objs = [{"type": "plane", "material": "floor"}]
    if merged:
        objs.append({"type": "cylinder", "base": [0, 0, 0], "radius": 1.0, "height": 2.5, "material": "glass"})
    else:
        objs += [{"type": "cylinder", "base": [0, 0, 0], "radius": 1.0, "height": 2.5, "wall": 0.0625,
                  "material": "glass"},
                 {"type": "cylinder", "base": [0, 0.0625, 0], "radius": 0.96875, "height": 2.4375,
                  "material": "liquid"}]
    objs.append({"type": "box", "min": [-0.08, 0.3, -0.08], "max": [0.08, 3.0, 0.08], "rotate": [0, 0, -15],
                 "material": "rod"})
    return {
        "name": "ior equal" + (" (merged)" if merged else ""),
        "camera": {"position": [2.6, 1.9, 4.2], "target": [0.0, 1.0, 0.0], "fov": 40},
        "render": {"max_depth": 32, "min_weight": 0.001, "samples": 1},
        "lights": [{"position": [4.0, 6.0, 3.0]}],
        "materials": {"floor": {"color": [0.85, 0.85, 0.85], "checker": {"color": [0.25, 0.25, 0.25], "size": 0.5}},
                      "glass": dict(clear), "liquid": dict(clear),
                      "rod": {"color": [0.8, 0.25, 0.15], "specular": 0.3}},
        "objects": objs,
    }


def _all_ior_one(without: bool) -> dict:
    d = _base(max_depth=24)
    for m in ("glass", "water"):
        d["materials"][m].update(ior=1.0, ambient=0.0, diffuse=0.0, specular=0.0, transparency=1.0,
                                 absorption=[0.0, 0.0, 0.0])
    if without:
        d["objects"] = [o for o in d["objects"] if o.get("name") not in ("glass", "water")]
    return d


def _critical(n1: float, n2: float | None) -> dict:
    """The eye inside a slab of ior n1 (a box, top face y = 0), optionally
    under a layer of ior n2 (0 < y < 0.5), looking up so that the centre
    row meets the top face exactly at the critical angle asin(n_out / n1)
    (n_out = n2, or 1 for air); the rows span it by +-15 degrees."""
    theta = math.asin((n2 or 1.0) / n1)
    clear = {"color": [1, 1, 1], "ambient": 0, "diffuse": 0, "specular": 0, "transparency": 1}
    eye = [0.0, -1.0, 0.0]
    objs = [{"type": "box", "name": "dense", "min": [-100, -8, -100], "max": [100, 0, 100], "material": "dense"}]
    mats = {"dense": dict(clear, ior=n1),
            "floor": {"color": [0.8, 0.8, 0.8], "checker": {"color": [0.2, 0.2, 0.25], "size": 0.5}},
            "ball": {"color": [0.9, 0.4, 0.2], "specular": 0.4}}
    if n2 is not None:
        objs.append({"type": "box", "name": "cover", "min": [-100, -8, -100], "max": [100, 0.5, 100],
                     "material": "cover"})
        mats["cover"] = dict(clear, ior=n2)
    objs += [{"type": "plane", "name": "floor", "height": -3.0, "material": "floor"},
             {"type": "sphere", "name": "ball", "center": [0.0, 2.5, -4.5], "radius": 1.0, "material": "ball"}]
    return {
        "name": f"critical {n1} / {n2 or 1.0}",
        "camera": {"position": eye, "target": [0.0, -1.0 + math.cos(theta), -math.sin(theta)], "fov": 30},
        "render": {"max_depth": 10, "samples": 1},
        "lights": [{"position": [3.0, 8.0, 2.0]}],
        "materials": mats,
        "objects": objs,
    }


FURNACE_SKY = (0.5, 0.6, 0.8)


def _furnace() -> dict:
    """One clear sphere in a uniform sky, max depth 64, min weight 0.  Every
    ray splits only into one escaping and one continuing branch, so the tree
    is a chain (about 2 rays per level); on a glass of water it would grow
    about 1.5x per level and never finish."""
    return {
        "name": "furnace",
        "ambient": [0, 0, 0],
        "camera": {"position": [0.0, 0.0, 4.0], "target": [0.0, 0.0, 0.0], "fov": 40},
        "render": {"max_depth": 64, "min_weight": 0.0, "samples": 1},
        "sky": {"type": "color", "color": list(FURNACE_SKY)},
        "materials": {"glass": {"color": [0, 0, 0], "ambient": 0, "diffuse": 0, "transparency": 1, "ior": 1.5}},
        "objects": [{"type": "sphere", "center": [0, 0, 0], "radius": 1.0, "material": "glass"}],
    }


def _camera_in_liquid() -> dict:
    d = _base()
    d["camera"] = {"position": [0.4, 0.9, 0.5], "target": [-0.5, 1.5, -0.3], "fov": 60}
    return d


# ---------------------------------------------------------------- cases


@dataclass(frozen=True)
class Check:
    """A check of a case beyond the default tolerance."""
    label: str
    kind: str                        # "same-gpu": the GPU image of `other` ; "furnace": every pixel = colour
    other: Callable[[], dict] | None = None
    limit: float = DEFAULT_TOL
    colour: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def describe(self) -> str:
        if self.kind == "furnace":
            return f"{self.label}: every pixel within {self.limit:g} (linear) of the sky {self.colour}"
        return f"{self.label}: <= {100 * self.limit:g}% of unmasked pixels off by > 1/255"


@dataclass(frozen=True)
class Case:
    name: str
    what: str
    build: Callable[[], dict]
    reference: Callable[[], dict] | None = None   # the scene whose reference image is expected (default: build)
    centre: bool = False                          # odd size: the centre row/column/pixel lie on the view axis
    tol: float = DEFAULT_TOL
    checks: tuple[Check, ...] = ()

    def tolerance(self) -> str:
        parts = [f"no NaN/Inf, <= {100 * self.tol:g}% of unmasked pixels off by > 1/255 vs the reference"]
        if self.reference is not None:
            parts[0] += " (of the untransformed scene)"
        parts += [c.describe() for c in self.checks]
        return "; ".join(parts)


def _cases() -> list[Case]:
    from ..scene.load import builtin_scene_names

    cases = [
        Case("grazing-floor", "eye 0.02 above the checker floor: the floor at grazing angles out to the horizon",
             _grazing_floor),
        Case("grazing-light", "plain floor under a directional light 1 degree above the horizon (self-shadowing)",
             _grazing_light),
        Case("grazing-light-low", "the same with the light 0.1 degree above the horizon",
             lambda: _grazing_light(0.1)),
        Case("grazing-caps", "eye exactly in the plane of the glass's rim and a pedestal's top cap; the centre "
             "row travels in that plane", _grazing_caps, centre=True),
        Case("far-camera", "the default view from 35 times as far (about 200 units) through a 1.14 degree "
             "field of view", _far_camera),
        Case("eye-on-floor", "eye exactly on the floor plane: rays that start on a surface", _eye_on_floor,
             centre=True),
        Case("axis-x", "centre pixel exactly along +x down a cylinder's axis; shadow rays exactly along -x",
             lambda: _axes_view([-6.0, 0.5, 1.0], [0.0, 0.5, 1.0],
                                [{"type": "directional", "direction": [1, 0, 0], "intensity": 0.5}]), centre=True),
        Case("axis-y", "shadow rays exactly along +y (light straight down) through the cup, past the box; "
             "the eye 0.1 degree off straight down the cup's axis",
             lambda: _axes_view([0.0, 4.0, 0.0], [4.0 * math.tan(math.radians(0.1)), 0.0, 0.0],
                                [{"type": "directional", "direction": [0, -1, 0], "intensity": 0.6}])),
        Case("axis-z", "centre pixel exactly along -z down a cylinder's axis; shadow rays exactly along +z",
             lambda: _axes_view([1.25, 0.375, 6.0], [1.25, 0.375, 0.0],
                                [{"type": "directional", "direction": [0, 0, -1], "intensity": 0.5}]), centre=True),
        Case("box-symmetry-plane", "eye on both symmetry planes of a box (y and z), looking along its x axis",
             lambda: _axes_view([-4.0, 0.375, -0.875], [0.0, 0.375, -0.875], []), centre=True),
        Case("box-face-plane", "eye on the planes of a box's top face and side face: the centre row and column "
             "travel in them, the centre pixel along their common edge",
             lambda: _axes_view([-4.0, 0.75, -0.5], [0.0, 0.75, -0.5], []), centre=True),
    ]
    for e in (2, 4, 6):
        off = 10.0 ** e
        cases.append(Case(f"translate-1e{e}", f"the whole scene moved by ({off:g}, {off:g}, {off:g})",
                          lambda off=off: translated(_base(), (off, off, off)), reference=_base,
                          checks=(Check("equals the unmoved GPU image", "same-gpu", _base),)))
    for e in (-30, -3, 3, 30):
        s = 10.0 ** e
        # +-30: beyond float32's squares, so the renderer uploads the scene
        # rescaled by a power of two (gpu_scene.gpu_frame_scene)
        cases.append(Case(f"scale-1e{e}", f"the whole scene (geometry, camera, light, checker) scaled by {s:g}",
                          lambda s=s: scaled(_base(), s),
                          checks=(Check("equals the unscaled GPU image", "same-gpu", _base),)))
    for e in (2, 3, 4):
        cases.append(Case(f"thin-wall-1e-{e}", f"glass wall {10.0 ** -e:g} of the radius",
                          lambda e=e: _thin_wall(10.0 ** -e)))
    cases += [
        Case("coincident", "glass on the floor, liquid on the glass's inner bottom, the rod standing on it, the "
             "ball touching floor and glass", _coincident),
        Case("ior-equal", "liquid with the glass's ior and absorption filling the glass to the rim: the inner "
             "interface must vanish", lambda: _ior_equal(False),
             checks=(Check("equals the merged solid cylinder (GPU)", "same-gpu", lambda: _ior_equal(True)),)),
        Case("all-ior-1", "every transparent material ior 1, no Phong terms, no absorption: glass and liquid "
             "must vanish", lambda: _all_ior_one(False),
             checks=(Check("equals the scene without them (GPU)", "same-gpu", lambda: _all_ior_one(True)),)),
        Case("critical-glass-air", "eye in glass (1.5) under air: the centre row at the critical angle "
             "41.81 degrees, rows +-15 degrees around it", lambda: _critical(1.5, None), centre=True),
        Case("critical-water-air", "eye in water (1.33) under air: critical angle 48.75 degrees",
             lambda: _critical(1.33, None), centre=True),
        Case("critical-glass-water", "eye in glass under a water layer: glass-water critical angle 62.46 "
             "degrees (water-air TIR beyond 41.81)", lambda: _critical(1.5, 1.33), centre=True),
        Case("depth64-furnace", "max depth 64, min weight 0: one clear sphere in a uniform sky (a furnace: "
             "every pixel is the sky); a glass of water would grow ~1.5x per level and not finish", _furnace,
             checks=(Check("furnace", "furnace", limit=1e-3, colour=FURNACE_SKY),)),
        Case("camera-in-liquid", "the eye inside the liquid, looking up at its surface and the rod "
             "(rays that start inside solids)", _camera_in_liquid),
    ]
    for name in builtin_scene_names():
        cases.append(Case(f"scene-{name}", f"the shipped scene {name!r}, one sample per pixel",
                          lambda name=name: _base(name)))
    return cases


CASES: list[Case] = _cases()


def case_names() -> list[str]:
    return [c.name for c in CASES]


def get_case(name: str) -> Case:
    for c in CASES:
        if c.name == name:
            return c
    raise KeyError(name)


# ---------------------------------------------------------------- image metrics


def display8(linear: np.ndarray) -> np.ndarray:
    from ..base.imageio import to_display8

    return to_display8(np.nan_to_num(linear, nan=0.0, posinf=1.0, neginf=0.0))


def level_diff(a8: np.ndarray, b8: np.ndarray) -> np.ndarray:
    """(H, W) largest channel difference in 8-bit levels."""
    return np.abs(a8.astype(np.int32) - b8.astype(np.int32)).max(axis=-1)


def off_fraction(a8: np.ndarray, b8: np.ndarray, mask: np.ndarray | None = None, levels: float = 1) -> float:
    """Fraction of the unmasked pixels whose largest channel difference exceeds `levels`."""
    off = level_diff(a8, b8) > levels
    keep = np.ones(off.shape, bool) if mask is None else ~mask
    return float(np.sum(off & keep) / max(1, np.sum(keep)))


@dataclass
class CheckResult:
    label: str
    value: float
    limit: float
    ok: bool

    def text(self) -> str:
        if "furnace" in self.label:
            return f"{self.label} {self.value:.1e}<={self.limit:g}"
        return f"{self.label} {100 * self.value:.2f}%<={100 * self.limit:g}%"


@dataclass
class CaseResult:
    name: str
    size: tuple[int, int]
    max_err: float          # 8-bit levels, unmasked
    mean_err: float         # 8-bit levels, unmasked
    off1: float             # fraction of unmasked pixels > 1 level
    off05: float            # fraction of unmasked pixels > 0.05
    masked: float           # fraction of pixels masked
    nonfinite: int
    acne: float
    ms: float
    checks: list[CheckResult] = field(default_factory=list)
    tol: float = DEFAULT_TOL
    gpu8: np.ndarray | None = None
    ref8: np.ndarray | None = None
    mask: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return self.nonfinite == 0 and self.off1 <= self.tol and all(c.ok for c in self.checks)


class Suite:
    """Renders and caches what the cases need: GPU images, reference images,
    straddle masks and the reference's primary hits, keyed by scene content."""

    def __init__(self, ctx, naive: bool = False):
        self.ctx = ctx
        self.naive = naive
        self._cache: dict = {}

    @staticmethod
    def scene(doc: dict):
        from ..scene.load import scene_from_dict

        return scene_from_dict(copy.deepcopy(doc), source=f"<stress: {doc.get('name', 'case')}>",
                               default_name="stress")

    def _memo(self, kind: str, doc: dict, w: int, h: int, fn):
        key = (kind, json.dumps(doc, sort_keys=True), w, h, self.naive)
        if key not in self._cache:
            self._cache[key] = fn()
        return self._cache[key]

    def gpu(self, doc: dict, w: int, h: int) -> tuple[np.ndarray, float]:
        """(image, ms of one render after a warm-up)."""
        def go():
            from ..gpu.renderer import Renderer

            r = Renderer(self.ctx, self.scene(doc),
                         extra_defines={"NAIVE_INTERSECT": True} if self.naive else None)
            try:
                r.render(w, h, 1)
                t0 = time.perf_counter()
                img = r.render(w, h, 1)
                self.ctx.finish()
                return img, (time.perf_counter() - t0) * 1000.0
            finally:
                r.release()
        return self._memo("gpu", doc, w, h, go)

    def reference(self, doc: dict, w: int, h: int) -> np.ndarray:
        from ..reference import trace as reference

        return self._memo("ref", doc, w, h, lambda: reference.render_reference(self.scene(doc), w, h, samples=1))

    def straddle(self, doc: dict, w: int, h: int) -> np.ndarray:
        """Pixels whose footprint straddles an edge at the sample point: the
        reference traced STRADDLE_DELTA of a pixel left, right, above and below
        the centre differs from the centred ray by more than STRADDLE_LEVELS
        8-bit levels (some edge passes within STRADDLE_DELTA of the centre)."""
        def go():
            from ..reference import trace as reference

            scene = self.scene(doc)
            centre = display8(self.reference(doc, w, h)).astype(np.int32)
            spread = np.zeros((h, w), np.int32)
            for du, dv in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                off = (0.5 + du * STRADDLE_DELTA, 0.5 + dv * STRADDLE_DELTA)
                o, d = reference.camera_rays(scene, w, h, off)
                rad = reference.trace(scene, o.reshape(-1, 3), d.reshape(-1, 3)).reshape(h, w, 3)
                v = display8(rad * scene.render.exposure).astype(np.int32)
                spread = np.maximum(spread, np.abs(v - centre).max(axis=-1))
            return spread > STRADDLE_LEVELS
        return self._memo("mask", doc, w, h, go)

    def opaque_hits(self, doc: dict, w: int, h: int) -> np.ndarray:
        """Pixels whose centred primary ray meets an opaque surface first (reference)."""
        def go():
            from ..reference import trace as reference

            scene = self.scene(doc)
            o, d = reference.camera_rays(scene, w, h)
            _, obj, _ = reference.first_hit(scene, o.reshape(-1, 3), d.reshape(-1, 3))
            opaque = np.array([not scene.is_transparent(ob) for ob in scene.objects] + [False])
            return opaque[obj].reshape(h, w)      # index -1 (a miss) picks the trailing False
        return self._memo("opaque", doc, w, h, go)

    def run_case(self, case: Case, size: tuple[int, int]) -> CaseResult:
        w, h = size
        if case.centre:
            w, h = w | 1, h | 1
        doc = case.build()
        ref_doc = case.reference() if case.reference is not None else doc
        gpu, ms = self.gpu(doc, w, h)
        ref = self.reference(ref_doc, w, h)
        mask = self.straddle(ref_doc, w, h)
        nonfinite = int(np.sum(~np.all(np.isfinite(gpu), axis=-1)))
        g8, r8 = display8(gpu), display8(ref)
        diff = level_diff(g8, r8)
        keep = ~mask
        vals = diff[keep] if keep.any() else np.zeros(1)
        darker = (r8.astype(np.int32) - g8.astype(np.int32)).max(axis=-1) > ACNE_LEVEL * 255
        opq = self.opaque_hits(ref_doc, w, h) & keep
        res = CaseResult(
            name=case.name, size=(w, h), max_err=float(vals.max()), mean_err=float(vals.mean()),
            off1=off_fraction(g8, r8, mask), off05=off_fraction(g8, r8, mask, ACNE_LEVEL * 255),
            masked=float(mask.mean()), nonfinite=nonfinite,
            acne=float(np.sum(darker & opq) / max(1, np.sum(opq))), ms=ms, tol=case.tol,
            gpu8=g8, ref8=r8, mask=mask)
        for chk in case.checks:
            if chk.kind == "furnace":
                err = float(np.max(np.abs(np.nan_to_num(gpu, nan=np.inf) - np.array(chk.colour)))) if gpu.size else 0.0
                res.checks.append(CheckResult(chk.label, err, chk.limit, err <= chk.limit))
            else:
                other_doc = chk.other()
                other, _ = self.gpu(other_doc, w, h)
                m = mask | self.straddle(other_doc, w, h)
                frac = off_fraction(g8, display8(other), m)
                res.checks.append(CheckResult(chk.label, frac, chk.limit, frac <= chk.limit))
        return res


# ---------------------------------------------------------------- table and contact sheet


HEADER = ("case", "size", "max", "mean", ">1/255", ">0.05", "masked", "NaN/Inf", "acne", "ms", "result")


def table_rows(results: list[CaseResult]) -> list[tuple[str, ...]]:
    rows = []
    for r in results:
        verdict = "ok" if r.ok else "FAIL"
        extra = "; ".join(c.text() for c in r.checks)
        rows.append((r.name, f"{r.size[0]}x{r.size[1]}", f"{r.max_err:.0f}", f"{r.mean_err:.3f}",
                     f"{100 * r.off1:.2f}%", f"{100 * r.off05:.2f}%", f"{100 * r.masked:.1f}%", str(r.nonfinite),
                     f"{100 * r.acne:.2f}%", f"{r.ms:.0f}", verdict + (f" ({extra})" if extra else "")))
    return rows


def format_table(results: list[CaseResult], markdown: bool = False) -> str:
    rows = [HEADER] + table_rows(results)
    if markdown:
        lines = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(HEADER)]
        lines += ["| " + " | ".join(r) + " |" for r in rows[1:]]
        return "\n".join(lines)
    widths = [max(len(r[i]) for r in rows) for i in range(len(HEADER) - 1)]
    out = []
    for r in rows:
        cells = [r[i].ljust(widths[i]) if i == 0 else r[i].rjust(widths[i]) for i in range(len(HEADER) - 1)]
        out.append("  ".join(cells + [r[-1]]))
    return "\n".join(out)


def error_heat(g8: np.ndarray, r8: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8: log heat of the largest channel difference (0 levels
    black, 1 level dim, 255 levels yellow); masked pixels in grey."""
    from ..base.views import heat

    d = level_diff(g8, r8).astype(np.float64)
    x = np.log2(1.0 + d) / 8.0
    img = heat(x)
    grey = np.repeat(np.clip(0.15 + 0.6 * x, 0, 1)[..., None], 3, axis=2)
    img = np.where((mask & (d > 1))[..., None], grey, img)
    return np.round(255 * img).astype(np.uint8)


def contact_sheet(results: list[CaseResult], columns: int = 3, scale: int | None = None):
    """A PIL image: per case a cell with its name and verdict above
    GPU | reference | error heat map (log scale; grey = masked pixels)."""
    from PIL import Image, ImageDraw

    shown = [r for r in results if r.gpu8 is not None]
    if not shown:
        return Image.new("RGB", (1, 1))
    wmax = max(r.size[0] for r in shown)
    hmax = max(r.size[1] for r in shown)
    k = scale or max(1, math.ceil(128 / wmax))
    gap, label_h, pad = 3, 24, 10
    cell_w = 3 * wmax * k + 2 * gap
    cell_h = label_h + hmax * k
    columns = max(1, min(columns, len(shown)))
    rows = math.ceil(len(shown) / columns)
    title_h = 18
    sheet = Image.new("RGB", (columns * cell_w + (columns + 1) * pad, title_h + rows * (cell_h + pad) + pad),
                      (24, 24, 28))
    draw = ImageDraw.Draw(sheet)
    draw.text((pad, 4), "glassray stress: GPU (float32) | reference (float64) | |difference| "
                        "(log heat: dark blue = equal, yellow = 255 levels; grey = masked straddling pixels)", fill=(230, 230, 230))
    for i, r in enumerate(shown):
        x0 = pad + (i % columns) * (cell_w + pad)
        y0 = title_h + pad + (i // columns) * (cell_h + pad)
        colour = (150, 230, 150) if r.ok else (255, 110, 110)
        draw.text((x0, y0), f"{r.name}  {'ok' if r.ok else 'FAIL'}", fill=colour)
        draw.text((x0, y0 + 11), f">1/255 {100 * r.off1:.2f}%  masked {100 * r.masked:.0f}%  "
                                 f"NaN {r.nonfinite}", fill=(190, 190, 190))
        tiles = [r.gpu8, r.ref8, error_heat(r.gpu8, r.ref8, r.mask)]
        for j, t in enumerate(tiles):
            im = Image.fromarray(np.ascontiguousarray(t)).resize((t.shape[1] * k, t.shape[0] * k), Image.NEAREST)
            sheet.paste(im, (x0 + j * (wmax * k + gap), y0 + label_h))
    return sheet


# ---------------------------------------------------------------- intersection error distribution


PRIMITIVES: dict[str, dict] = {
    "plane": {"type": "plane", "height": 0.0},
    "sphere": {"type": "sphere", "center": [0.2, 0.6, -0.1], "radius": 0.6},
    "box": {"type": "box", "min": [-0.5, 0.0, -0.25], "max": [0.75, 1.0, 0.5]},
    "box-rotated": {"type": "box", "min": [-0.5, 0.1, -0.4], "max": [0.6, 1.0, 0.3], "rotate": [17, -33, 51]},
    "cylinder": {"type": "cylinder", "axis": "y", "base": [0.0, 0.0, 0.0], "radius": 0.5, "height": 1.25},
    "vessel": {"type": "cylinder", "base": [0.0, 0.0, 0.0], "radius": 0.75, "height": 1.25, "wall": 0.0625},
}


def _prim_bounds(obj: dict) -> tuple[np.ndarray, float]:
    """A centre and radius of the object (a point of the plane, radius 1)."""
    t = obj["type"]
    if t == "plane":
        return np.array([0.0, obj["height"], 0.0]), 1.0
    if t == "sphere":
        return np.array(obj["center"], float), obj["radius"]
    if t == "box":
        lo, hi = np.array(obj["min"], float), np.array(obj["max"], float)
        return (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2
    ax = {"x": 0, "y": 1, "z": 2}[obj.get("axis", "y")]
    c = np.array(obj["base"], float)
    c[ax] += obj["height"] / 2
    return c, math.hypot(obj["radius"], obj["height"] / 2)


def _inside_point(obj: dict, rng) -> np.ndarray:
    t = obj["type"]
    if t == "plane":
        return np.array([rng.uniform(-2, 2), obj["height"] - rng.uniform(0.05, 2.0), rng.uniform(-2, 2)])
    if t == "sphere":
        v = rng.normal(size=3)
        return np.array(obj["center"]) + obj["radius"] * rng.uniform(0, 0.9) * v / np.linalg.norm(v)
    if t == "box":
        from ..gpu.packing import rotation_world_from_local

        lo, hi = np.array(obj["min"], float), np.array(obj["max"], float)
        c, half = (lo + hi) / 2, (hi - lo) / 2
        return c + rotation_world_from_local(obj.get("rotate", (0, 0, 0))) @ (half * rng.uniform(-0.9, 0.9, 3))
    r = obj["radius"] - obj.get("wall", 0.0) * 1.5 if "wall" in obj else obj["radius"]
    ang, rho = rng.uniform(0, 2 * np.pi), r * math.sqrt(rng.uniform(0, 0.8))
    y = rng.uniform(0.1, 0.9) * obj["height"]
    if "wall" in obj:      # inside the hollow (air), above the inner bottom
        y = obj["wall"] + rng.uniform(0.1, 0.9) * (obj["height"] - obj["wall"])
    return np.array(obj["base"], float) + np.array([rho * math.cos(ang), y, rho * math.sin(ang)])


def _cameras(obj: dict, n: int, rng) -> list[tuple[str, list[float], list[float], float, tuple[int, int]]]:
    """(kind, position, target, fov, size) of the measurement cameras."""
    c, rad = _prim_bounds(obj)
    cams = []

    def sph(yaw, pitch, dist, centre):
        yr, pr = math.radians(yaw), math.radians(pitch)
        return centre + dist * np.array([math.cos(pr) * math.sin(yr), math.sin(pr), math.cos(pr) * math.cos(yr)])

    plane = obj["type"] == "plane"
    for _ in range(n):           # near: random views at a few object sizes
        tgt = c + rng.uniform(-0.3, 0.3, 3) * rad
        pitch = rng.uniform(5, 70) if plane else rng.uniform(-60, 80)
        cams.append(("near", sph(rng.uniform(0, 360), pitch, rad * rng.uniform(2.5, 10), tgt), tgt,
                     rng.uniform(10, 90), (64, 48)))
    for _ in range(n):           # far: 30 to 1000 sizes away, narrow field of view
        tgt = c + rng.uniform(-0.5, 0.5, 3) * rad
        dist = rad * 10 ** rng.uniform(1.5, 3.0)
        pitch = rng.uniform(20, 80) if plane else rng.uniform(-60, 80)
        fov = max(1.0, min(10.0, math.degrees(2.4 * rad / dist)))
        cams.append(("far", sph(rng.uniform(0, 360), pitch, dist, tgt), tgt, fov, (64, 48)))
    for _ in range(n):           # grazing: the view centred on the silhouette (plane: near the horizon)
        if plane:
            pos = np.array([0.0, 10 ** rng.uniform(-3, -1), 0.0])
            dirn = sph(rng.uniform(0, 360), -rng.uniform(0.2, 3.0), 1.0, np.zeros(3))
            cams.append(("grazing", pos, pos + dirn, rng.uniform(1, 5), (64, 48)))
            continue
        dist = rad * 10 ** rng.uniform(0.5, 2.0)
        pos = sph(rng.uniform(0, 360), rng.uniform(-40, 70), dist, c)
        f = (c - pos) / np.linalg.norm(c - pos)
        u = np.cross(f, rng.normal(size=3))
        u /= np.linalg.norm(u)
        # aim at the edge of the silhouette of the bounding shape and a bit inside
        tgt = c + u * rad * rng.uniform(0.5, 1.0)
        cams.append(("grazing", pos, tgt, rng.uniform(1, 4), (64, 48)))
    for _ in range(max(2, n // 2)):   # inside the solid (the vessel: inside its hollow)
        pos = _inside_point(obj, rng)
        tgt = pos + rng.normal(size=3)
        cams.append(("inside", pos, tgt, rng.uniform(40, 100), (64, 48)))
    for i in range(max(2, n // 2)):   # exactly along x or z through the object's middle (odd size)
        ax = i % 2
        dirn = np.zeros(3)
        dirn[2 * ax] = 1.0 if i % 4 < 2 else -1.0
        pos = c - 4 * rad * dirn
        pos[1] = c[1] if not plane else 0.5
        if obj["type"] == "box" and i % 3 == 0 and "rotate" not in obj:
            # the eye on the plane of a face: centre rows/columns travel in it
            pos[1] = obj["max"][1]
        tgt = pos + dirn
        cams.append(("axis", pos, tgt, rng.uniform(20, 60), (65, 49)))
    return [(k, [float(x) for x in p], [float(x) for x in t], float(fv), s) for k, p, t, fv, s in cams]


@dataclass
class ErrorStats:
    primitive: str
    variant: str
    rays: int
    hits: int
    median: float
    p999: float
    max: float
    disagree: int      # rays where one side hits and the other misses


def intersection_errors(ctx, cameras_per_kind: int = 8, seed: int = 1,
                        primitives: list[str] | None = None) -> list[ErrorStats]:
    """Relative error |t_gpu - t_ref| / t_ref of the first hit, per primitive,
    with the robust formulations (default shader) and the textbook ones
    (NAIVE_INTERSECT), over the same rays: random near views, far views (30
    to 1000 sizes away), views centred on the silhouette (grazing rays),
    views from inside the solid, and views exactly along x and z."""
    from ..reference import trace as reference
    from ..gpu.renderer import Renderer

    out = []
    for name in primitives or list(PRIMITIVES):
        obj = dict(PRIMITIVES[name], material="m")
        rng = np.random.default_rng(seed)
        cams = _cameras(obj, cameras_per_kind, rng)
        # random sub-pixel offsets; the axis views use the centre (exact axis rays)
        offsets = [(0.5, 0.5) if cam[0] == "axis" else tuple(rng.random(2)) for cam in cams]
        rel = {False: [], True: []}
        disagree = {False: 0, True: 0}
        rays = 0
        renderer = None
        try:
            for (kind, pos, tgt, fov, (w, h)), off in zip(cams, offsets):
                doc = {"camera": {"position": pos, "target": tgt, "fov": fov},
                       "materials": {"m": {"color": [0.5, 0.5, 0.5]}}, "objects": [obj]}
                scene = Suite.scene(doc)
                if renderer is None:
                    renderer = Renderer(ctx, scene)
                else:
                    renderer.set_scene(scene)
                o, d = reference.camera_rays(scene, w, h, tuple(off))
                rt, robj, _ = reference.first_hit(scene, o.reshape(-1, 3), d.reshape(-1, 3))
                rt = rt.reshape(h, w)
                rhit = robj.reshape(h, w) >= 0
                rays += w * h
                base = {k: v for k, v in renderer.extra_defines.items() if k != "NAIVE_INTERSECT"}
                for naive in (False, True):
                    renderer.extra_defines = {**base, "NAIVE_INTERSECT": True} if naive else base
                    renderer.set_scene(scene)
                    t, gobj, _ = renderer.first_hits(w, h, tuple(off))
                    ghit = gobj >= 0
                    disagree[naive] += int(np.sum(ghit != rhit))
                    both = ghit & rhit & (rt > 0)
                    rel[naive].append(np.abs(t[both].astype(np.float64) - rt[both]) / rt[both])
        finally:
            if renderer is not None:
                renderer.release()
        for naive in (False, True):
            e = np.concatenate(rel[naive]) if rel[naive] else np.zeros(0)
            out.append(ErrorStats(name, "textbook" if naive else "robust", rays, len(e),
                                  float(np.median(e)) if len(e) else 0.0,
                                  float(np.quantile(e, 0.999)) if len(e) else 0.0,
                                  float(e.max()) if len(e) else 0.0, disagree[naive]))
    return out


def format_errors(stats: list[ErrorStats], markdown: bool = True) -> str:
    head = ("primitive", "formulation", "rays", "median", "99.9th pct", "max", "hit/miss disagree")
    rows = [head] + [(s.primitive, s.variant, str(s.rays), f"{s.median:.1e}", f"{s.p999:.1e}", f"{s.max:.1e}",
                      str(s.disagree)) for s in stats]
    if markdown:
        return "\n".join(["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(head)]
                         + ["| " + " | ".join(r) + " |" for r in rows[1:]])
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.rjust(wd) if i else c.ljust(wd) for i, (c, wd) in enumerate(zip(r, widths)))
                     for r in rows)


def camera_relative_errors(offsets=(0.0, 1e2, 1e4, 1e6), n: int = 20000, seed: int = 2) -> list[tuple]:
    """Float32 emulation in NumPy of the sphere routine (robust form) with
    world coordinates (eye and centre rounded to float32 where they are)
    against camera-relative ones (centre - eye in float64, then rounded), for
    the scene moved by each offset: (offset, world median, world max,
    relative median, relative max) of the relative error of t."""
    rng = np.random.default_rng(seed)
    f32 = np.float32
    centre = np.array([0.2, 0.6, -0.1])
    radius = 0.6
    eye = np.array([3.2, 2.2, 4.6])
    # directions toward random points of the sphere's disc seen from the eye
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    pts = centre + 0.98 * radius * u
    d = pts - eye
    d /= np.linalg.norm(d, axis=1, keepdims=True)

    def robust_t(oc, dd, r):
        b = np.einsum("ij,ij->i", oc, dd)
        qc = oc - b[:, None] * dd
        h = r * r - np.einsum("ij,ij->i", qc, qc)
        ok = h >= 0
        h = np.sqrt(np.maximum(h, 0).astype(oc.dtype))
        q = -b - np.where(b >= 0, h, -h)
        c = np.einsum("ij,ij->i", oc, oc) - r * r
        t0, t1 = q, c / q
        return np.where(ok, np.minimum(t0, t1), np.nan)

    exact = robust_t(np.broadcast_to(eye - centre, d.shape), d, radius)
    rows = []
    for off in offsets:
        e64, c64 = eye + off, centre + off
        world = robust_t(e64.astype(f32)[None] - c64.astype(f32)[None], d.astype(f32), f32(radius))
        rel = robust_t(np.broadcast_to(-(c64 - e64).astype(f32), d.shape), d.astype(f32), f32(radius))
        ew = np.abs(world.astype(np.float64) - exact) / exact
        er = np.abs(rel.astype(np.float64) - exact) / exact
        ew, er = np.nan_to_num(ew, nan=1.0), np.nan_to_num(er, nan=1.0)
        rows.append((off, float(np.median(ew)), float(ew.max()), float(np.median(er)), float(er.max())))
    return rows


# ---------------------------------------------------------------- command line


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--list", action="store_true", help="list the cases with what they test and their tolerance")
    p.add_argument("--case", action="append", metavar="NAME", help="run only this case (repeatable)")
    from ..cli.commands import int_range, size_type

    p.add_argument("--size", type=size_type(4, 4096), default=DEFAULT_SIZE, metavar="WxH",
                   help="image size of every case (%dx%d); cases that need a pixel on the view axis use "
                        "the next odd width and height" % DEFAULT_SIZE)
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"folder for contact-sheet.png and results.md (./{DEFAULT_OUT})")
    p.add_argument("--columns", type=int_range(1, 1000), default=3, metavar="N",
                   help="cases per row of the contact sheet (3)")
    p.add_argument("--naive", action="store_true",
                   help="measure the textbook intersection formulas instead (NAIVE_INTERSECT)")
    p.add_argument("--intersections", action="store_true",
                   help="also print the float32 intersection error per primitive, textbook against robust")
    p.add_argument("--backend", choices=("auto", "egl", "osmesa"), default="auto",
                   help="OpenGL context: EGL, OSMesa, or EGL falling back to OSMesa (auto)")


def _print(msg: str = "") -> None:
    print(msg, flush=True)


def run(args) -> int:
    if args.list:
        for c in CASES:
            _print(f"{c.name}\n    {c.what}\n    tolerance: {c.tolerance()}")
        return 0
    names = args.case or case_names()
    unknown = [n for n in names if n not in case_names()]
    if unknown:
        print(f"glassray stress: unknown case {', '.join(map(repr, unknown))} (see --list)", file=sys.stderr)
        return 2
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:       # it ran and reported such a case twice
        print(f"glassray stress: --case names {', '.join(twice)} more than once", file=sys.stderr)
        return 2
    if not str(args.out):
        print("glassray stress: --out names no folder", file=sys.stderr)
        return 2
    out = Path(args.out)
    from .bench import remove_if_empty, results_folder_problem

    made = not out.exists()
    problem = results_folder_problem(out)     # before the cases run, not after them
    if problem:
        print(f"glassray: {problem}", file=sys.stderr)
        return 1
    try:
        return _run_cases(args, names, out)
    finally:
        if made:
            remove_if_empty(out)      # a run that wrote nothing leaves no folder of its own behind


def _run_cases(args, names: list[str], out: Path) -> int:
    from .bench import OutputError
    from ..gpu.context import ContextError, create_offscreen_context, describe

    try:
        ctx, _backend = create_offscreen_context(args.backend)
    except ContextError as e:
        print(f"glassray: {e}", file=sys.stderr)
        return 1
    try:
        suite = Suite(ctx, naive=args.naive)
        results = []
        from ..base import interrupt

        for name in names:
            interrupt.check()                         # Ctrl-C between cases (viewer/interrupt.py)
            results.append(suite.run_case(get_case(name), args.size))
            print(f"stress: {name}: {'ok' if results[-1].ok else 'FAIL'}", file=sys.stderr, flush=True)
        variant = "textbook intersections (NAIVE_INTERSECT)" if args.naive else "robust intersections"
        head = f"glassray stress: {len(results)} case{'' if len(results) == 1 else 's'}, {variant}, {describe(ctx)}"
        from .bench import machine_info

        mi = machine_info()
        machine = (f"{mi['date']}, {mi['cpu'] or mi['machine']} ({mi['cpus_usable']} usable CPUs), "
                   f"{mi['platform']}, glassray {mi['glassray']}")
        text = format_table(results)
        _print(head)
        _print(text)
        failed = [r.name for r in results if not r.ok]
        verdict = (f"{len(results) - len(failed)} of {len(results)} cases within tolerance"
                   + (f"; failed: {', '.join(failed)}" if failed else ""))
        _print(verdict)
        # the file says what stdout said: the verdict, and the command that reproduces it
        md = (f"{head}\n\nmachine: {machine}\n\ncommand: `{mi['command']}`\n\n"
              f"{format_table(results, markdown=True)}\n\n{verdict}\n")
        if args.intersections:
            stats = intersection_errors(ctx)
            _print("\nfloat32 relative error of t, first hit against the float64 reference:")
            _print(format_errors(stats, markdown=False))
            md += "\n" + format_errors(stats) + "\n"
        from .bench import results_written_together, write_output   # an OSError names the file
        import io

        buf = io.BytesIO()
        contact_sheet(results, columns=args.columns).save(buf, format="PNG", optimize=True)
        with results_written_together():      # both, or neither
            write_output(out / "contact-sheet.png", buf.getvalue())
            write_output(out / "results.md", md.encode("utf-8"))
        print(f"stress: wrote {out / 'contact-sheet.png'} and {out / 'results.md'}", file=sys.stderr)
        return 1 if failed else 0
    except KeyboardInterrupt:
        print("glassray: interrupted", file=sys.stderr)
        return 130
    except OutputError as e:
        if getattr(args, "debug", False):
            raise
        print(f"glassray: {e}", file=sys.stderr)
        return 1
    except Exception as e:
        if getattr(args, "debug", False):
            raise
        print(f"glassray: stress failed: {type(e).__name__}: {e} (run with --debug for the traceback)",
              file=sys.stderr)
        return 1
    finally:
        ctx.release()
