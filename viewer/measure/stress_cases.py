"""The stress suite's cases (``glassray stress --list``): the scene each one
renders, as a plain document (shipped scenes changed, or built here), and
what it checks beyond the default tolerance.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..scene.load import builtin_scene_names, load_scene, scene_from_dict
from ..scene.save import scene_to_dict

DEFAULT_TOL = 0.001          # fraction of unmasked pixels off by more than 1/255


def case_scene(doc: dict):
    """The Scene of a case's document (validated as a scene file is)."""
    return scene_from_dict(copy.deepcopy(doc), source=f"<stress: {doc.get('name', 'case')}>",
                           default_name="stress")


# ---------------------------------------------------------------- scene documents


def _base(name: str = "default", **render) -> dict:
    """A shipped scene as a plain document, one sample per pixel."""
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
        # rescaled by a power of two (gpu/frame.py gpu_frame_scene)
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
