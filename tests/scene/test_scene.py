"""Scene-file validation, loading, saving and overrides, driven by the contract in
``shared/spec/scene-format.md`` (not by the current implementation).

Every rejected input must raise :class:`SceneError` whose message names the file
and the key path (``objects[1].radius``); every accepted edge case must load.
"""

from __future__ import annotations

import copy
import math
import os
import re
import struct
import tomllib
from dataclasses import replace
from pathlib import Path

import pytest

from viewer.scene import load as scene_load
from viewer.scene import save as scene_save
from viewer.scene.model import Scene, SceneError
from viewer.scene.load import builtin_scene_names, load_scene, scene_from_dict, with_overrides
from viewer.scene.save import save_scene, scene_to_toml

# --------------------------------------------------------------------------- helpers

MAT = '[materials.m]\ncolor = [0.5, 0.5, 0.5]\n'
SPHERE = 'type = "sphere"\ncenter = [0, 1, 0]\nradius = 1\nmaterial = "m"\n'
BOX = 'type = "box"\nmin = [0, 0, 0]\nmax = [1, 1, 1]\nmaterial = "m"\n'
CYL = 'type = "cylinder"\nbase = [0, 0, 0]\nradius = 1\nheight = 2\nmaterial = "m"\n'
PLANE = 'type = "plane"\nmaterial = "m"\n'
POINT = '[[lights]]\ntype = "point"\nposition = [0, 5, 0]\n'
DIRL = '[[lights]]\ntype = "directional"\ndirection = [0, -1, 0]\n'


def objs(*bodies: str) -> str:
    """A scene with material ``m`` and the given [[objects]] bodies."""
    return MAT + "".join("[[objects]]\n" + b for b in bodies)


def write(tmp_path: Path, text: str | bytes, name: str = "scene.toml") -> Path:
    p = tmp_path / name
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text, encoding="utf-8")
    return p


def load_text(tmp_path: Path, text: str, name: str = "scene.toml") -> Scene:
    return load_scene(write(tmp_path, text, name))


def _names_key(message: str, key: str) -> bool:
    """``key`` occurs in ``message`` as a whole key path (``objects[1].radius``
    matches ``objects[1].radius`` and ``objects[1].radius[0]`` but not
    ``objects[1].radius_x`` or ``xobjects[1].radius``)."""
    return re.search(r"(?<![\w.\[\]])" + re.escape(key) + r"(?!\w)", message) is not None


def assert_rejected(path: Path, keys: str | tuple[str, ...] | None) -> str:
    with pytest.raises(SceneError) as info:
        load_scene(path)
    msg = str(info.value)
    assert str(path) in msg, f"the message does not name the file: {msg!r}"
    if keys is not None:
        keys = (keys,) if isinstance(keys, str) else keys
        rest = msg.replace(str(path), "<FILE>")
        assert any(_names_key(rest, k) for k in keys), f"the message does not name {keys}: {msg!r}"
    return msg


def rotation(deg: tuple[float, float, float]):
    """Rz * Ry * Rx for right-handed rotations in degrees (spec: x first)."""
    ax, ay, az = (math.radians(a) for a in deg)
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    rx = [[1, 0, 0], [0, cx, -sx], [0, sx, cx]]
    ry = [[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]]
    rz = [[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]

    def mul(a, b):
        return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]

    return mul(rz, mul(ry, rx))


def box_corners(o) -> list[tuple[float, float, float]]:
    """World-space corners of a (rotated) box object, per the spec's formula
    p_world = c + Rz * Ry * Rx * (p - c)."""
    c = [(a + b) / 2 for a, b in zip(o.min, o.max)]
    m = rotation(o.rotate)
    out = []
    for x in (o.min[0], o.max[0]):
        for y in (o.min[1], o.max[1]):
            for z in (o.min[2], o.max[2]):
                d = (x - c[0], y - c[1], z - c[2])
                out.append(tuple(c[i] + sum(m[i][k] * d[k] for k in range(3)) for i in range(3)))
    return out


def test_rotation_helper_follows_the_spec_convention():
    # "a positive z angle turns +x toward +y"; likewise +y toward +z about x, +z toward +x about y
    def apply(m, v):
        return tuple(sum(m[i][k] * v[k] for k in range(3)) for i in range(3))

    assert apply(rotation((0, 0, 90)), (1, 0, 0)) == pytest.approx((0, 1, 0), abs=1e-12)
    assert apply(rotation((90, 0, 0)), (0, 1, 0)) == pytest.approx((0, 0, 1), abs=1e-12)
    assert apply(rotation((0, 90, 0)), (0, 0, 1)) == pytest.approx((1, 0, 0), abs=1e-12)
    # x first, then y: +y -> (about x by 90) +z -> (about y by 90) +x
    assert apply(rotation((90, 90, 0)), (0, 1, 0)) == pytest.approx((1, 0, 0), abs=1e-12)


# --------------------------------------------------------------------------- built-in scenes

BUILTINS = builtin_scene_names()


def test_builtin_scenes_exist():
    assert "default" in BUILTINS
    assert len(BUILTINS) >= 2


@pytest.mark.parametrize("name", BUILTINS)
def test_builtin_scene_validates(name):
    s = load_scene(name)
    assert isinstance(s, Scene)
    assert isinstance(s.name, str) and s.name
    for o in s.objects:
        assert o.material in s.materials
    named = [o.name for o in s.objects if o.name is not None]
    assert len(named) == len(set(named))
    # the file as shipped re-validates through the dict path too
    data = tomllib.loads(s.path.read_text(encoding="utf-8"))
    assert replace(scene_from_dict(data, source=name, base_dir=s.path.parent, default_name=s.path.stem),
                   path=s.path) == s


def _default_parts():
    s = load_scene(None)
    planes = [o for o in s.objects if o.type == "plane"]
    vessels = [o for o in s.objects if o.type == "cylinder" and o.wall is not None]
    liquids = [o for o in s.objects if o.type == "cylinder" and o.wall is None
               and s.materials[o.material].is_dielectric]
    boxes = [o for o in s.objects if o.type == "box"]
    spheres = [o for o in s.objects if o.type == "sphere"]
    assert len(planes) == 1 and len(vessels) == 1 and len(liquids) == 1
    assert len(boxes) == 1 and len(spheres) == 1
    return s, planes[0], vessels[0], liquids[0], boxes[0], spheres[0]


def test_default_scene_is_the_default_builtin():
    s = load_scene(None)
    d = load_scene("default")
    assert replace(s, path=None) == replace(d, path=None)


def test_default_scene_settings():
    s = load_scene(None)
    assert s.render.samples == 16
    assert s.sky.type == "gradient"
    assert len(s.lights) == 1 and s.lights[0].type == "point"
    assert s.lights[0].position is not None


def test_default_scene_floor_has_checker():
    s, plane, vessel, *_ = _default_parts()
    assert s.materials[plane.material].checker is not None
    assert s.materials[plane.material].checker.size > 0
    assert not s.materials[plane.material].is_dielectric
    assert vessel.base[1] >= plane.height  # the glass is not sunk into the floor


def test_default_scene_glass_vessel():
    s, _, vessel, *_ = _default_parts()
    m = s.materials[vessel.material]
    assert m.is_dielectric and m.transparency > 0
    assert m.ior == pytest.approx(1.5)
    assert m.reflectivity == 0
    assert vessel.axis == "y"
    assert 0 < vessel.wall < vessel.radius and vessel.wall < vessel.height


def test_default_scene_liquid_inside_the_glass():
    s, _, vessel, liquid, *_ = _default_parts()
    m = s.materials[liquid.material]
    assert m.ior == pytest.approx(1.33)
    assert m.is_dielectric
    assert max(m.absorption) > 0 and min(m.absorption) >= 0  # faintly tinted
    assert s.objects.index(liquid) > s.objects.index(vessel)  # listed after the glass
    assert liquid.axis == vessel.axis == "y"
    # same axis line
    assert liquid.base[0] == pytest.approx(vessel.base[0])
    assert liquid.base[2] == pytest.approx(vessel.base[2])
    inner = vessel.radius - vessel.wall
    # slightly wider than the inside of the glass, but not wider than the glass
    assert inner < liquid.radius <= vessel.radius
    # sits on the inner bottom and fills only part of the glass
    assert liquid.base[1] == pytest.approx(vessel.base[1] + vessel.wall)
    rim = vessel.base[1] + vessel.height
    assert liquid.base[1] + liquid.height < rim


def test_default_scene_rod_leans_from_the_liquid_past_the_rim():
    s, _, vessel, liquid, rod, _ = _default_parts()
    assert not s.materials[rod.material].is_dielectric  # opaque
    assert any(a != 0 for a in rod.rotate)  # it leans
    corners = box_corners(rod)
    axis_xz = (vessel.base[0], vessel.base[2])
    inner = vessel.radius - vessel.wall
    liquid_bottom, liquid_top = liquid.base[1], liquid.base[1] + liquid.height
    rim = vessel.base[1] + vessel.height

    def radial(p):
        return math.hypot(p[0] - axis_xz[0], p[2] - axis_xz[1])

    lowest = min(corners, key=lambda p: p[1])
    highest = max(corners, key=lambda p: p[1])
    # starts inside the liquid (and inside the glass's inner wall)
    assert liquid_bottom < lowest[1] < liquid_top
    assert radial(lowest) < inner
    # the four bottom-end corners are all in the liquid
    for p in sorted(corners, key=lambda p: p[1])[:4]:
        assert liquid_bottom < p[1] < liquid_top
        assert radial(p) < inner
    # reaches above the rim
    assert highest[1] > rim
    # and leaves through the opening: where each long edge crosses the rim height
    # it is still inside the inner radius (it does not pierce the glass wall)
    # the four long edges: corners that differ only along the box's longest local axis
    long_axis = max(range(3), key=lambda i: rod.max[i] - rod.min[i])
    crossings = 0
    for i in range(8):
        j = i ^ (1 << (2 - long_axis))  # corners are ordered x, y, z (outermost first)
        if i < j:
            b, t = sorted((corners[i], corners[j]), key=lambda p: p[1])
            assert b[1] < rim < t[1]  # every long edge crosses the rim height
            u = (rim - b[1]) / (t[1] - b[1])
            p = tuple(b[k] + u * (t[k] - b[k]) for k in range(3))
            assert radial(p) < inner
            crossings += 1
    assert crossings == 4


def test_default_scene_sphere_beside_the_glass():
    s, plane, vessel, _, _, sphere = _default_parts()
    assert sphere.radius > 0
    d = math.hypot(sphere.center[0] - vessel.base[0], sphere.center[2] - vessel.base[2])
    assert d > vessel.radius + sphere.radius  # beside it, not touching or inside
    assert sphere.center[1] - sphere.radius >= plane.height - 1e-9  # not sunk into the floor


# --------------------------------------------------------------------------- rejected inputs


def _cam_dir(angle_deg: float, down: bool, azimuth_deg: float = 30.0) -> str:
    """A camera whose view is ``angle_deg`` off +y (or -y)."""
    a, az = math.radians(angle_deg), math.radians(azimuth_deg)
    s, c = math.sin(a), math.cos(a)
    d = (s * math.cos(az), -c if down else c, s * math.sin(az))
    pos = (1.0, 2.0, 3.0)
    tgt = tuple(p + 2.0 * k for p, k in zip(pos, d))
    return f"[camera]\nposition = [{pos[0]!r}, {pos[1]!r}, {pos[2]!r}]\ntarget = [{tgt[0]!r}, {tgt[1]!r}, {tgt[2]!r}]\n"


CAMERA_KEYS = ("camera.target", "camera.position")

BAD = [
    # ---- unknown keys at every level
    ("unknown-top", "foo = 1\n", "foo"),
    ("unknown-top-typo", "object = []\n", "object"),
    ("unknown-camera", "[camera]\nzoom = 2\n", "camera.zoom"),
    ("unknown-camera-up", "[camera]\nup = [0, 1, 0]\n", "camera.up"),
    ("unknown-render", "[render]\nspp = 4\n", "render.spp"),
    ("unknown-sky", '[sky]\ntype = "gradient"\nsun = [1, 1, 1]\n', "sky.sun"),
    ("unknown-light", POINT + "radius = 1\n", "lights[0].radius"),
    ("direction-on-point", POINT + "direction = [0, -1, 0]\n", "lights[0].direction"),
    ("direction-on-default-type", "[[lights]]\nposition = [0, 5, 0]\ndirection = [0, -1, 0]\n",
     "lights[0].direction"),
    ("position-on-directional", DIRL + "position = [0, 5, 0]\n", "lights[0].position"),
    ("unknown-second-light", POINT + POINT + "falloff = 2\n", "lights[1].falloff"),
    ("unknown-material", "[materials.glass]\nrefraction = 1.5\n", "materials.glass.refraction"),
    ("unknown-checker", '[materials.floor]\nchecker = { color = [0, 0, 0], size = 1, scale = 2 }\n',
     "materials.floor.checker.scale"),
    ("unknown-object", objs(SPHERE + "colour = [1, 0, 0]\n"), "objects[0].colour"),
    ("radius-on-box", objs(BOX + "radius = 1\n"), "objects[0].radius"),
    ("radius-on-second-box", objs(PLANE, BOX + "radius = 1\n"), "objects[1].radius"),
    ("wall-on-sphere", objs(SPHERE + "wall = 0.1\n"), "objects[0].wall"),
    ("axis-on-sphere", objs(SPHERE + 'axis = "y"\n'), "objects[0].axis"),
    ("rotate-on-cylinder", objs(CYL + "rotate = [0, 0, 10]\n"), "objects[0].rotate"),
    ("rotate-on-sphere", objs(SPHERE + "rotate = [0, 0, 10]\n"), "objects[0].rotate"),
    ("center-on-plane", objs(PLANE + "center = [0, 0, 0]\n"), "objects[0].center"),
    ("radius-on-plane", objs(PLANE + "radius = 1\n"), "objects[0].radius"),
    ("height-on-sphere", objs(SPHERE + "height = 1\n"), "objects[0].height"),
    ("base-on-box", objs(BOX + "base = [0, 0, 0]\n"), "objects[0].base"),
    ("min-on-cylinder", objs(CYL + "min = [0, 0, 0]\n"), "objects[0].min"),
    ("position-on-object", objs(SPHERE + "position = [0, 0, 0]\n"), "objects[0].position"),
    # ---- wrong types
    ("name-number", "name = 5\n", "name"),
    ("fov-string", '[camera]\nfov = "40"\n', "camera.fov"),
    ("fov-bool", "[camera]\nfov = true\n", "camera.fov"),
    ("fov-array", "[camera]\nfov = [40]\n", "camera.fov"),
    ("camera-not-table", "camera = [1, 2, 3]\n", "camera"),
    ("position-short", "[camera]\nposition = [1, 2]\n", "camera.position"),
    ("position-long", "[camera]\nposition = [1, 2, 3, 4]\n", "camera.position"),
    ("position-empty", "[camera]\nposition = []\n", "camera.position"),
    ("position-scalar", "[camera]\nposition = 1\n", "camera.position"),
    ("position-string-component", '[camera]\nposition = [1, "2", 3]\n', "camera.position"),
    ("position-bool-component", "[camera]\nposition = [1, true, 3]\n", "camera.position"),
    ("target-table", "[camera]\ntarget = { x = 0, y = 0, z = 0 }\n", "camera.target"),
    ("max-depth-string", '[render]\nmax_depth = "8"\n', "render.max_depth"),
    ("max-depth-float", "[render]\nmax_depth = 8.0\n", "render.max_depth"),
    ("max-depth-bool", "[render]\nmax_depth = true\n", "render.max_depth"),
    ("samples-float", "[render]\nsamples = 4.5\n", "render.samples"),
    ("samples-bool", "[render]\nsamples = true\n", "render.samples"),
    ("min-weight-bool", "[render]\nmin_weight = false\n", "render.min_weight"),
    ("min-weight-string", '[render]\nmin_weight = "0.1"\n', "render.min_weight"),
    ("exposure-string", '[render]\nexposure = "1"\n', "render.exposure"),
    ("render-not-table", "render = 3\n", "render"),
    ("ambient-scalar", "ambient = 0.5\n", "ambient"),
    ("ambient-short", "ambient = [1, 1]\n", "ambient"),
    ("ambient-bool-component", "ambient = [0.1, false, 0.1]\n", "ambient"),
    ("sky-not-table", 'sky = "gradient"\n', "sky"),
    ("sky-type-unknown", '[sky]\ntype = "hdri"\n', "sky.type"),
    ("sky-type-number", "[sky]\ntype = 1\n", "sky.type"),
    ("sky-horizon-string", '[sky]\nhorizon = "blue"\n', "sky.horizon"),
    ("sky-zenith-short", "[sky]\nzenith = [0, 0]\n", "sky.zenith"),
    ("sky-image-number", '[sky]\ntype = "image"\nimage = 5\n', "sky.image"),
    ("lights-table", "[lights]\nposition = [0, 1, 0]\n", "lights"),
    ("lights-of-numbers", "lights = [1, 2]\n", "lights[0]"),
    ("light-type-unknown", '[[lights]]\ntype = "spot"\nposition = [0, 5, 0]\n', "lights[0].type"),
    ("light-type-number", "[[lights]]\ntype = 1\nposition = [0, 5, 0]\n", "lights[0].type"),
    ("light-intensity-string", POINT + 'intensity = "bright"\n', "lights[0].intensity"),
    ("light-intensity-bool", POINT + "intensity = true\n", "lights[0].intensity"),
    ("light-color-short", POINT + "color = [1, 1]\n", "lights[0].color"),
    ("light-position-string", '[[lights]]\nposition = "up"\n', "lights[0].position"),
    ("light-position-table", "[[lights]]\nposition = { x = 1 }\n", "lights[0].position"),
    ("light-direction-short", '[[lights]]\ntype = "directional"\ndirection = [0, -1]\n', "lights[0].direction"),
    ("materials-array", "materials = [1]\n", "materials"),
    ("material-number", "[materials]\nglass = 1\n", "materials.glass"),
    ("material-color-string", '[materials.glass]\ncolor = "red"\n', "materials.glass.color"),
    ("material-ior-string", '[materials.glass]\nior = "1.5"\n', "materials.glass.ior"),
    ("material-ior-bool", "[materials.glass]\nior = true\n", "materials.glass.ior"),
    ("material-diffuse-array", "[materials.glass]\ndiffuse = [0.8]\n", "materials.glass.diffuse"),
    ("material-absorption-short", "[materials.glass]\nabsorption = [0.1, 0.1]\n", "materials.glass.absorption"),
    ("material-emission-scalar", "[materials.glass]\nemission = 1\n", "materials.glass.emission"),
    ("checker-number", "[materials.floor]\nchecker = 1\n", "materials.floor.checker"),
    ("checker-array", "[materials.floor]\nchecker = [1, 2]\n", "materials.floor.checker"),
    ("checker-size-string", '[materials.floor]\nchecker = { color = [0, 0, 0], size = "big" }\n',
     "materials.floor.checker.size"),
    ("checker-color-short", "[materials.floor]\nchecker = { color = [0, 0], size = 1 }\n",
     "materials.floor.checker.color"),
    ("objects-table", "[objects]\ntype = \"plane\"\n", "objects"),
    ("objects-of-numbers", "objects = [1]\n", "objects[0]"),
    ("object-type-unknown", objs('type = "torus"\nmaterial = "m"\n'), "objects[0].type"),
    ("object-type-number", objs('type = 3\nmaterial = "m"\n'), "objects[0].type"),
    ("object-material-number", MAT + '[[objects]]\ntype = "plane"\nmaterial = 1\n', "objects[0].material"),
    ("object-name-number", objs(PLANE + "name = 1\n"), "objects[0].name"),
    ("sphere-radius-string", objs('type = "sphere"\ncenter = [0, 1, 0]\nradius = "1"\nmaterial = "m"\n'),
     "objects[0].radius"),
    ("sphere-radius-bool", objs('type = "sphere"\ncenter = [0, 1, 0]\nradius = true\nmaterial = "m"\n'),
     "objects[0].radius"),
    ("sphere-center-short", objs('type = "sphere"\ncenter = [0, 1]\nradius = 1\nmaterial = "m"\n'),
     "objects[0].center"),
    ("sphere-center-table", objs('type = "sphere"\ncenter = { x = 0 }\nradius = 1\nmaterial = "m"\n'),
     "objects[0].center"),
    ("cylinder-axis-unknown", objs(CYL + 'axis = "w"\n'), "objects[0].axis"),
    ("cylinder-axis-number", objs(CYL + "axis = 1\n"), "objects[0].axis"),
    ("cylinder-wall-bool", objs(CYL + "wall = true\n"), "objects[0].wall"),
    ("plane-height-string", objs(PLANE + 'height = "0"\n'), "objects[0].height"),
    ("box-rotate-short", objs(BOX + "rotate = [0, 0]\n"), "objects[0].rotate"),
    ("box-min-string", objs('type = "box"\nmin = "0"\nmax = [1, 1, 1]\nmaterial = "m"\n'), "objects[0].min"),
    # ---- non-finite numbers
    ("fov-inf", "[camera]\nfov = inf\n", "camera.fov"),
    ("fov-nan", "[camera]\nfov = nan\n", "camera.fov"),
    ("fov-minus-inf", "[camera]\nfov = -inf\n", "camera.fov"),
    ("fov-float-overflow", "[camera]\nfov = 1e400\n", "camera.fov"),
    ("fov-integer-overflow", "[camera]\nfov = 1" + "0" * 400 + "\n", "camera.fov"),
    ("position-inf", "[camera]\nposition = [inf, 0, 0]\n", "camera.position"),
    ("target-nan", "[camera]\ntarget = [0, nan, 0]\n", "camera.target"),
    ("light-position-nan", "[[lights]]\nposition = [0, nan, 0]\n", "lights[0].position"),
    ("light-direction-inf", '[[lights]]\ntype = "directional"\ndirection = [0, -inf, 0]\n',
     "lights[0].direction"),
    ("light-intensity-inf", POINT + "intensity = inf\n", "lights[0].intensity"),
    ("light-color-nan", POINT + "color = [1, nan, 1]\n", "lights[0].color"),
    ("ior-inf", "[materials.glass]\nior = inf\n", "materials.glass.ior"),
    ("shininess-inf", "[materials.glass]\nshininess = inf\n", "materials.glass.shininess"),
    ("color-nan", "[materials.glass]\ncolor = [nan, 0, 0]\n", "materials.glass.color"),
    ("absorption-inf", "[materials.glass]\nabsorption = [inf, 0, 0]\n", "materials.glass.absorption"),
    ("checker-size-inf", "[materials.floor]\nchecker = { color = [0, 0, 0], size = inf }\n",
     "materials.floor.checker.size"),
    ("sphere-radius-nan", objs('type = "sphere"\ncenter = [0, 1, 0]\nradius = nan\nmaterial = "m"\n'),
     "objects[0].radius"),
    ("sphere-center-inf", objs('type = "sphere"\ncenter = [0, inf, 0]\nradius = 1\nmaterial = "m"\n'),
     "objects[0].center"),
    ("plane-height-minus-inf", objs(PLANE + "height = -inf\n"), "objects[0].height"),
    ("box-rotate-nan", objs(BOX + "rotate = [0, 0, nan]\n"), "objects[0].rotate"),
    ("box-max-inf", objs('type = "box"\nmin = [0, 0, 0]\nmax = [1, inf, 1]\nmaterial = "m"\n'),
     "objects[0].max"),
    ("cylinder-height-inf", objs('type = "cylinder"\nbase = [0, 0, 0]\nradius = 1\nheight = inf\nmaterial = "m"\n'),
     "objects[0].height"),
    ("min-weight-nan", "[render]\nmin_weight = nan\n", "render.min_weight"),
    ("exposure-inf", "[render]\nexposure = inf\n", "render.exposure"),
    ("ambient-inf", "ambient = [inf, 0, 0]\n", "ambient"),
    ("sky-zenith-inf", "[sky]\nzenith = [0, inf, 0]\n", "sky.zenith"),
    # ---- out of range
    ("fov-0", "[camera]\nfov = 0\n", "camera.fov"),
    ("fov-180", "[camera]\nfov = 180\n", "camera.fov"),
    ("fov-0.5", "[camera]\nfov = 0.5\n", "camera.fov"),
    ("fov-179.5", "[camera]\nfov = 179.5\n", "camera.fov"),
    ("fov-negative", "[camera]\nfov = -40\n", "camera.fov"),
    ("max-depth-0", "[render]\nmax_depth = 0\n", "render.max_depth"),
    ("max-depth-65", "[render]\nmax_depth = 65\n", "render.max_depth"),
    ("max-depth-negative", "[render]\nmax_depth = -1\n", "render.max_depth"),
    ("samples-0", "[render]\nsamples = 0\n", "render.samples"),
    ("samples-65537", "[render]\nsamples = 65537\n", "render.samples"),
    ("samples-huge", "[render]\nsamples = 1" + "0" * 40 + "\n", "render.samples"),
    ("min-weight-negative", "[render]\nmin_weight = -0.1\n", "render.min_weight"),
    ("min-weight-1.5", "[render]\nmin_weight = 1.5\n", "render.min_weight"),
    ("exposure-0", "[render]\nexposure = 0\n", "render.exposure"),
    ("exposure-negative", "[render]\nexposure = -1\n", "render.exposure"),
    ("ambient-negative", "ambient = [-0.1, 0, 0]\n", "ambient"),
    ("sky-color-negative", '[sky]\ntype = "color"\ncolor = [-1, 0, 0]\n', "sky.color"),
    ("sky-horizon-negative", "[sky]\nhorizon = [0.5, -0.5, 0.5]\n", "sky.horizon"),
    ("light-color-negative", POINT + "color = [-1, 1, 1]\n", "lights[0].color"),
    ("light-intensity-negative", POINT + "intensity = -1\n", "lights[0].intensity"),
    ("directional-zero", '[[lights]]\ntype = "directional"\ndirection = [0, 0, 0]\n', "lights[0].direction"),
    ("directional-zero-float", '[[lights]]\ntype = "directional"\ndirection = [0.0, -0.0, 0.0]\n',
     "lights[0].direction"),
    ("color-negative", "[materials.glass]\ncolor = [0.5, -0.01, 0.5]\n", "materials.glass.color"),
    ("material-ambient-negative", "[materials.glass]\nambient = -0.1\n", "materials.glass.ambient"),
    ("diffuse-negative", "[materials.glass]\ndiffuse = -1\n", "materials.glass.diffuse"),
    ("specular-negative", "[materials.glass]\nspecular = -1\n", "materials.glass.specular"),
    ("shininess-0.5", "[materials.glass]\nshininess = 0.5\n", "materials.glass.shininess"),
    ("shininess-0", "[materials.glass]\nshininess = 0\n", "materials.glass.shininess"),
    ("reflectivity-1.5", "[materials.glass]\nreflectivity = 1.5\n", "materials.glass.reflectivity"),
    ("reflectivity-negative", "[materials.glass]\nreflectivity = -0.1\n", "materials.glass.reflectivity"),
    ("transparency-negative", "[materials.glass]\ntransparency = -1\n", "materials.glass.transparency"),
    ("transparency-above-1", "[materials.glass]\ntransparency = 1.01\n", "materials.glass.transparency"),
    ("ior-0.9", "[materials.glass]\nior = 0.9\n", "materials.glass.ior"),
    ("ior-0", "[materials.glass]\nior = 0\n", "materials.glass.ior"),
    ("absorption-negative", "[materials.glass]\nabsorption = [-0.1, 0, 0]\n", "materials.glass.absorption"),
    ("emission-negative", "[materials.glass]\nemission = [0, 0, -1]\n", "materials.glass.emission"),
    ("checker-size-0", "[materials.floor]\nchecker = { color = [0, 0, 0], size = 0 }\n",
     "materials.floor.checker.size"),
    ("checker-size-negative", "[materials.floor]\nchecker = { color = [0, 0, 0], size = -0.5 }\n",
     "materials.floor.checker.size"),
    ("checker-color-negative", "[materials.floor]\nchecker = { color = [0, -1, 0], size = 1 }\n",
     "materials.floor.checker.color"),
    ("checker-emission-negative",
     "[materials.floor]\nchecker = { color = [0, 0, 0], emission = [-1, 0, 0], size = 1 }\n",
     "materials.floor.checker.emission"),
    ("sphere-radius-0", objs('type = "sphere"\ncenter = [0, 1, 0]\nradius = 0\nmaterial = "m"\n'),
     "objects[0].radius"),
    ("sphere-radius-negative", objs(PLANE, 'type = "sphere"\ncenter = [0, 1, 0]\nradius = -1\nmaterial = "m"\n'),
     "objects[1].radius"),
    ("cylinder-radius-0", objs('type = "cylinder"\nbase = [0, 0, 0]\nradius = 0\nheight = 2\nmaterial = "m"\n'),
     "objects[0].radius"),
    ("cylinder-height-0", objs('type = "cylinder"\nbase = [0, 0, 0]\nradius = 1\nheight = 0\nmaterial = "m"\n'),
     "objects[0].height"),
    ("cylinder-height-negative",
     objs('type = "cylinder"\nbase = [0, 0, 0]\nradius = 1\nheight = -2\nmaterial = "m"\n'), "objects[0].height"),
    ("box-min-eq-max-x", objs('type = "box"\nmin = [1, 0, 0]\nmax = [1, 1, 1]\nmaterial = "m"\n'),
     ("objects[0].min", "objects[0].max")),
    ("box-min-gt-max-x", objs('type = "box"\nmin = [2, 0, 0]\nmax = [1, 1, 1]\nmaterial = "m"\n'),
     ("objects[0].min", "objects[0].max")),
    ("box-min-eq-max-y", objs('type = "box"\nmin = [0, 1, 0]\nmax = [1, 1, 1]\nmaterial = "m"\n'),
     ("objects[0].min", "objects[0].max")),
    ("box-min-gt-max-y", objs('type = "box"\nmin = [0, 5, 0]\nmax = [1, 1, 1]\nmaterial = "m"\n'),
     ("objects[0].min", "objects[0].max")),
    ("box-min-eq-max-z", objs('type = "box"\nmin = [0, 0, 1]\nmax = [1, 1, 1]\nmaterial = "m"\n'),
     ("objects[0].min", "objects[0].max")),
    ("box-min-gt-max-z", objs('type = "box"\nmin = [0, 0, 1.5]\nmax = [1, 1, 1]\nmaterial = "m"\n'),
     ("objects[0].min", "objects[0].max")),
    ("box-swapped", objs('type = "box"\nmin = [1, 1, 1]\nmax = [0, 0, 0]\nmaterial = "m"\n'),
     ("objects[0].min", "objects[0].max")),
    ("wall-eq-radius", objs(CYL + "wall = 1\n"), "objects[0].wall"),
    ("wall-gt-radius", objs(CYL + "wall = 1.5\n"), "objects[0].wall"),
    ("wall-eq-height",
     objs('type = "cylinder"\nbase = [0, 0, 0]\nradius = 5\nheight = 2\nwall = 2\nmaterial = "m"\n'),
     "objects[0].wall"),
    ("wall-gt-height",
     objs('type = "cylinder"\nbase = [0, 0, 0]\nradius = 5\nheight = 2\nwall = 3\nmaterial = "m"\n'),
     "objects[0].wall"),
    ("wall-0", objs(CYL + "wall = 0\n"), "objects[0].wall"),
    ("wall-negative", objs(CYL + "wall = -0.1\n"), "objects[0].wall"),
    # ---- missing required keys
    ("missing-material", objs('type = "sphere"\ncenter = [0, 1, 0]\nradius = 1\n'), "objects[0].material"),
    ("missing-material-plane", objs(PLANE, 'type = "plane"\n'), "objects[1].material"),
    ("missing-object-type", objs('material = "m"\n'), "objects[0].type"),
    ("missing-sphere-center", objs('type = "sphere"\nradius = 1\nmaterial = "m"\n'), "objects[0].center"),
    ("missing-sphere-radius", objs('type = "sphere"\ncenter = [0, 1, 0]\nmaterial = "m"\n'), "objects[0].radius"),
    ("missing-box-min", objs('type = "box"\nmax = [1, 1, 1]\nmaterial = "m"\n'), "objects[0].min"),
    ("missing-box-max", objs('type = "box"\nmin = [0, 0, 0]\nmaterial = "m"\n'), "objects[0].max"),
    ("missing-cylinder-base", objs('type = "cylinder"\nradius = 1\nheight = 2\nmaterial = "m"\n'),
     "objects[0].base"),
    ("missing-cylinder-radius", objs('type = "cylinder"\nbase = [0, 0, 0]\nheight = 2\nmaterial = "m"\n'),
     "objects[0].radius"),
    ("missing-cylinder-height", objs('type = "cylinder"\nbase = [0, 0, 0]\nradius = 1\nmaterial = "m"\n'),
     "objects[0].height"),
    ("missing-point-position", '[[lights]]\ntype = "point"\nintensity = 1\n', "lights[0].position"),
    ("missing-default-light-position", "[[lights]]\ncolor = [1, 1, 1]\n", "lights[0].position"),
    ("missing-directional-direction", '[[lights]]\ntype = "directional"\n', "lights[0].direction"),
    ("missing-second-light-position", POINT + "[[lights]]\n", "lights[1].position"),
    ("missing-checker-color", "[materials.floor]\nchecker = { size = 1 }\n", "materials.floor.checker.color"),
    ("missing-checker-size", "[materials.floor]\nchecker = { color = [0, 0, 0] }\n",
     "materials.floor.checker.size"),
    # ---- cross-references and semantic rules
    ("unknown-material-name", objs('type = "plane"\nmaterial = "marble"\n'), "objects[0].material"),
    ("unknown-material-no-materials", '[[objects]]\ntype = "plane"\nmaterial = "m"\n', "objects[0].material"),
    ("material-name-case", objs('type = "plane"\nmaterial = "M"\n'), "objects[0].material"),
    ("duplicate-object-name", objs(PLANE + 'name = "a"\n', SPHERE + 'name = "a"\n'), "objects[1].name"),
    ("duplicate-object-name-later",
     objs(PLANE + 'name = "a"\n', SPHERE + 'name = "b"\n', BOX + 'name = "a"\n'), "objects[2].name"),
    ("reflective-dielectric", "[materials.glass]\ntransparency = 0.5\nreflectivity = 0.1\n",
     "materials.glass.reflectivity"),
    ("reflective-dielectric-full", "[materials.glass]\ntransparency = 1\nior = 1.5\nreflectivity = 1\n",
     "materials.glass.reflectivity"),
    ("camera-position-eq-target", "[camera]\nposition = [1, 2, 3]\ntarget = [1, 2, 3]\n", CAMERA_KEYS),
    ("camera-position-eq-default-target", "[camera]\nposition = [0, 0.9, 0]\n", CAMERA_KEYS),
    ("camera-target-eq-default-position", "[camera]\ntarget = [3.2, 2.2, 4.6]\n", CAMERA_KEYS),
    ("camera-straight-up", "[camera]\nposition = [0, 0, 0]\ntarget = [0, 5, 0]\n", CAMERA_KEYS),
    ("camera-straight-down", "[camera]\nposition = [1, 5, 1]\ntarget = [1, 0, 1]\n", CAMERA_KEYS),
    ("camera-down-onto-default-target", "[camera]\nposition = [0, 5, 0]\n", CAMERA_KEYS),
    ("camera-0.005deg-off-up", _cam_dir(0.005, down=False), CAMERA_KEYS),
    ("camera-0.005deg-off-down", _cam_dir(0.005, down=True), CAMERA_KEYS),
    ("camera-0.009deg-off-up", _cam_dir(0.009, down=False, azimuth_deg=200), CAMERA_KEYS),
    ("sky-image-without-image", '[sky]\ntype = "image"\n', "sky.image"),
    ("sky-image-missing-file", '[sky]\ntype = "image"\nimage = "missing.png"\n', "sky.image"),
    ("sky-image-missing-file-in-subdir", '[sky]\ntype = "image"\nimage = "env/sky.pfm"\n', "sky.image"),
    ("sky-image-is-directory", '[sky]\ntype = "image"\nimage = "."\n', "sky.image"),
    # ---- files that are not TOML
    ("invalid-toml-unterminated-string", 'name = "unterminated\n', None),
    ("invalid-toml-unclosed-table", "[camera\nfov = 40\n", None),
    ("invalid-toml-duplicate-key", "name = \"a\"\nname = \"b\"\n", None),
    ("invalid-toml-unclosed-array", "ambient = [1, 2\n", None),
    ("invalid-toml-bare-value", "just some words\n", None),
    ("invalid-toml-integer-too-long", "[camera]\nfov = 1" + "0" * 5000 + "\n", None),
    ("invalid-toml-nested-too-deep", "x = " + "[" * 20000 + "]" * 20000 + "\n", None),
]


@pytest.mark.parametrize("text, keys", [pytest.param(t, k, id=i) for i, t, k in BAD])
def test_rejected(tmp_path, text, keys):
    assert_rejected(write(tmp_path, text), keys)


def test_bad_ids_are_unique():
    ids = [i for i, _, _ in BAD]
    assert len(ids) == len(set(ids))


def test_sky_image_with_unsupported_suffix(tmp_path):
    (tmp_path / "sky.bmp").write_bytes(b"BM")
    assert_rejected(write(tmp_path, '[sky]\ntype = "image"\nimage = "sky.bmp"\n'), "sky.image")


def test_sky_image_relative_to_the_scene_file_not_the_cwd(tmp_path, monkeypatch):
    # the picture lies beside the cwd, not beside the scene: rejected
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    (tmp_path / "sky.pfm").write_bytes(b"PF\n1 1\n-1.0\n" + b"\0" * 12)
    monkeypatch.chdir(tmp_path)
    assert_rejected(write(scenes, '[sky]\ntype = "image"\nimage = "sky.pfm"\n'), "sky.image")


def test_missing_file(tmp_path):
    for p in (tmp_path / "nope.toml", tmp_path / "nope", tmp_path / "no-dir" / "scene.toml"):
        with pytest.raises(SceneError) as info:
            load_scene(p)
        assert str(p) in str(info.value)
        with pytest.raises(SceneError) as info:
            load_scene(str(p))
        assert str(p) in str(info.value)


def test_directory(tmp_path):
    d = tmp_path / "a-dir.toml"
    d.mkdir()
    for p in (tmp_path, d):
        with pytest.raises(SceneError) as info:
            load_scene(p)
        assert str(p) in str(info.value)


@pytest.mark.parametrize("data", [
    b'name = "\xff\xfe"\n',
    b"\x80\n",
    b'name = "caf\xe9"\n',  # latin-1
    "name = \"x\"\n".encode("utf-16"),
])
def test_not_utf8(tmp_path, data):
    assert_rejected(write(tmp_path, data), None)


def test_error_is_a_value_error_with_one_line(tmp_path):
    p = write(tmp_path, objs('type = "sphere"\ncenter = [0, 1, 0]\nradius = 0\nmaterial = "m"\n'))
    with pytest.raises(ValueError) as info:
        load_scene(p)
    assert isinstance(info.value, SceneError)
    assert "\n" not in str(info.value)


def test_scene_from_dict_names_the_source():
    with pytest.raises(SceneError) as info:
        scene_from_dict({"camera": {"fov": 0}}, source="my-source.toml")
    assert "my-source.toml" in str(info.value) and _names_key(str(info.value), "camera.fov")


# --------------------------------------------------------------------------- accepted inputs


def test_empty_file_gives_the_documented_defaults(tmp_path):
    s = load_text(tmp_path, "", "empty-scene.toml")
    assert s.name == "empty-scene"
    assert s.camera.position == (3.2, 2.2, 4.6)
    assert s.camera.target == (0.0, 0.9, 0.0)
    assert s.camera.fov == 40
    assert (s.render.max_depth, s.render.samples) == (8, 1)
    assert s.render.min_weight == pytest.approx(0.001)
    assert s.render.exposure == 1.0
    assert s.sky.type == "gradient"
    assert s.sky.color == (0.6, 0.7, 0.9)
    assert s.sky.horizon == (0.8, 0.85, 0.9)
    assert s.sky.zenith == (0.25, 0.4, 0.75)
    assert s.ambient == (0.05, 0.05, 0.05)
    assert s.lights == [] and s.materials == {} and s.objects == []


def test_defaults_of_lights_materials_and_objects(tmp_path):
    s = load_text(tmp_path, objs(PLANE, CYL, BOX) + "[[lights]]\nposition = [1, 2, 3]\n")
    lt = s.lights[0]
    assert lt.type == "point" and lt.position == (1, 2, 3)
    assert lt.color == (1, 1, 1) and lt.intensity == 1
    m = load_text(tmp_path, "[materials.x]\n").materials["x"]
    assert m.color == (0.8, 0.8, 0.8)
    assert (m.ambient, m.diffuse, m.specular, m.shininess) == pytest.approx((0.1, 0.8, 0.0, 32))
    assert (m.reflectivity, m.transparency, m.ior) == (0, 0, 1)
    assert m.absorption == (0, 0, 0) and m.emission == (0, 0, 0)
    assert m.checker is None and not m.is_dielectric
    plane, cyl, box = s.objects
    assert plane.height == 0
    assert cyl.axis == "y" and cyl.wall is None
    assert box.rotate == (0, 0, 0)


def test_checker_emission_defaults_to_the_material_emission(tmp_path):
    s = load_text(tmp_path, "[materials.f]\nemission = [1, 2, 3]\nchecker = { color = [0, 0, 0], size = 1 }\n")
    c = s.materials["f"].checker
    assert c.color == (0, 0, 0) and c.size == 1
    assert c.emission is None or c.emission == (1, 2, 3)


def test_integers_where_floats_are_expected(tmp_path):
    text = """
ambient = [0, 1, 0]
[camera]
position = [3, 2, 4]
target = [0, 1, 0]
fov = 40
[render]
min_weight = 0
exposure = 2
[sky]
type = "color"
color = [1, 1, 1]
[[lights]]
position = [4, 6, 3]
color = [1, 1, 1]
intensity = 2
[[lights]]
type = "directional"
direction = [0, -1, 0]
[materials.g]
color = [1, 1, 1]
ambient = 0
diffuse = 1
specular = 1
shininess = 200
transparency = 1
ior = 2
absorption = [1, 0, 0]
emission = [0, 0, 0]
checker = { color = [0, 0, 0], emission = [1, 1, 1], size = 1 }
[materials.o]
reflectivity = 1
[[objects]]
type = "plane"
height = -1
material = "o"
[[objects]]
type = "sphere"
center = [0, 1, 0]
radius = 1
material = "g"
[[objects]]
type = "box"
min = [0, 0, 0]
max = [1, 2, 3]
rotate = [10, 20, 30]
material = "o"
[[objects]]
type = "cylinder"
axis = "z"
base = [0, 0, 0]
radius = 2
height = 3
wall = 1
material = "g"
"""
    s = load_text(tmp_path, text)
    assert s.camera.position == (3, 2, 4) and s.camera.fov == 40
    assert s.render.min_weight == 0 and s.render.exposure == 2
    assert s.lights[0].intensity == 2 and s.lights[1].direction == (0, -1, 0)
    g = s.materials["g"]
    assert (g.ior, g.shininess, g.transparency) == (2, 200, 1)
    assert s.materials["o"].reflectivity == 1
    plane, sphere, box, cyl = s.objects
    assert plane.height == -1 and sphere.radius == 1
    assert box.max == (1, 2, 3) and box.rotate == (10, 20, 30)
    assert (cyl.axis, cyl.radius, cyl.height, cyl.wall) == ("z", 2, 3, 1)


def test_empty_lights_and_objects(tmp_path):
    s = load_text(tmp_path, "lights = []\nobjects = []\n")
    assert s.lights == [] and s.objects == []
    s = load_text(tmp_path, "lights = []\nobjects = []\n" + MAT)
    assert list(s.materials) == ["m"]


def test_empty_materials_table(tmp_path):
    assert load_text(tmp_path, "[materials]\n").materials == {}


def test_colours_above_one(tmp_path):
    s = load_text(tmp_path, """
ambient = [2, 2, 2]
[sky]
type = "color"
color = [5, 6, 7]
horizon = [10, 10, 10]
zenith = [3, 3, 3]
[[lights]]
position = [0, 5, 0]
color = [3, 3, 3]
intensity = 7.5
[materials.hot]
color = [5, 0.5, 1.5]
emission = [10, 10, 10]
absorption = [4, 5, 6]
checker = { color = [2, 2, 2], emission = [100, 0, 0], size = 1 }
""")
    assert s.ambient == (2, 2, 2)
    assert s.sky.color == (5, 6, 7)
    assert s.lights[0].color == (3, 3, 3)
    assert s.materials["hot"].emission == (10, 10, 10)
    assert s.materials["hot"].checker.emission == (100, 0, 0)


@pytest.mark.parametrize("text", [
    '[sky]\ntype = "color"\ncolor = [1, 0, 0]\nhorizon = [0, 1, 0]\nzenith = [0, 0, 1]\n',
    '[sky]\ntype = "color"\nimage = "does-not-exist.png"\n',
    '[sky]\ntype = "color"\nimage = "not-a-picture.txt"\n',
    '[sky]\ntype = "gradient"\ncolor = [1, 0, 0]\nimage = "does-not-exist.hdr"\n',
    '[sky]\nimage = "does-not-exist.png"\n',  # gradient by default
], ids=["color-with-gradient-keys", "color-with-missing-image", "color-with-txt-image",
        "gradient-with-other-keys", "default-type-with-image"])
def test_keys_of_other_sky_types_are_accepted_and_ignored(tmp_path, text):
    s = load_text(tmp_path, text)
    assert s.sky.type in ("color", "gradient")
    assert s.sky.image_path is None


@pytest.mark.parametrize("text, kept", [
    ('type = "color"\ncolor = [1, 0, 0]\nhorizon = [-1, 0, 0]\nzenith = "x"\n', {"color": (1, 0, 0)}),
    ('type = "color"\ncolor = [1, 0, 0]\nimage = 5\n', {"color": (1, 0, 0)}),
    ('type = "gradient"\nhorizon = [1, 1, 0]\ncolor = [-1, 0, 0]\nimage = ["a"]\n', {"horizon": (1, 1, 0)}),
    ('color = "red"\nzenith = [0, 0, 1]\n', {"zenith": (0, 0, 1)}),             # gradient by default
], ids=["color-with-bad-gradient-keys", "color-with-image-not-a-path", "gradient-with-bad-others",
        "default-type-with-bad-color"])
def test_invalid_keys_of_other_sky_types_are_ignored_too(tmp_path, text, kept):
    # "accepted and ignored": a value another sky type would reject is no
    # error here; it is dropped for the default (the spec's defaults, by hand)
    defaults = {"color": (0.6, 0.7, 0.9), "horizon": (0.8, 0.85, 0.9), "zenith": (0.25, 0.4, 0.75)}
    s = load_text(tmp_path, "[sky]\n" + text)
    for key, default in defaults.items():
        assert getattr(s.sky, key) == pytest.approx(kept.get(key, default)), key
    assert s.sky.image is None


@pytest.mark.parametrize("text, key", [
    ('type = "color"\ncolor = [-1, 0, 0]\nhorizon = [1, 1, 1]\n', "sky.color"),
    ('type = "gradient"\nhorizon = [-1, 0, 0]\n', "sky.horizon"),
    ('zenith = "blue"\n', "sky.zenith"),
    ('type = "image"\nimage = 5\n', "sky.image"),
])
def test_invalid_keys_of_the_active_sky_type_are_errors(tmp_path, text, key):
    with pytest.raises(SceneError) as err:
        load_text(tmp_path, "[sky]\n" + text)
    assert _names_key(str(err.value), key), str(err.value)


def test_image_sky_keeps_the_other_keys_too(tmp_path, monkeypatch):
    env = tmp_path / "env"
    env.mkdir()
    (env / "sky.pfm").write_bytes(b"PF\n1 1\n-1.0\n" + b"\0" * 12)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    s = load_text(tmp_path, '[sky]\ntype = "image"\nimage = "env/sky.pfm"\ncolor = [1, 1, 1]\n'
                            'horizon = [1, 1, 1]\nzenith = [1, 1, 1]\n')
    assert s.sky.type == "image"
    assert Path(s.sky.image_path).resolve() == (env / "sky.pfm").resolve()


def write_picture(path: Path, value: float = 0.5) -> None:
    """A real 8x4 picture of one grey `value` (0..1) in the format its
    extension names (PFM: linear; the others: 8-bit sRGB-encoded)."""
    import numpy as np
    from PIL import Image

    from viewer.base.imageio import encode_pfm

    if path.suffix.lower() == ".pfm":
        path.write_bytes(encode_pfm(np.full((4, 8, 3), value, np.float32)))
    else:
        fmt = "JPEG" if path.suffix.lower() in (".jpg", ".jpeg") else "PNG"
        Image.fromarray(np.full((4, 8, 3), round(255 * value), np.uint8)).save(path, format=fmt)


@pytest.mark.parametrize("name", ["sky.png", "sky.jpg", "sky.jpeg", "sky.pfm", "SKY.PNG"])
def test_image_sky_formats(tmp_path, name):
    write_picture(tmp_path / name)
    s = load_text(tmp_path, f'[sky]\ntype = "image"\nimage = "{name}"\n')
    assert Path(s.sky.image_path).resolve() == (tmp_path / name).resolve()


def _pfm_header(w: int, h: int) -> bytes:
    return f"PF\n{w} {h}\n-1.0\n".encode()


@pytest.mark.parametrize("name, content, says", [
    ("garbage.png", b"this is not a png", "cannot decode"),
    ("garbage.jpg", b"\xff\xd8 not a jpeg", "cannot decode"),
    ("short.pfm", _pfm_header(8, 4) + bytes(48), "truncated PFM: 8x4 needs 384 bytes"),
    ("header.pfm", b"P7\n8 4\n-1.0\n" + bytes(384), "not a PFM file"),
    ("empty.pfm", b"", "not a PFM file"),
    ("nan.pfm", _pfm_header(2, 1) + struct.pack("<6f", 0.5, float("nan"), 0.5, 0.5, 0.5, 0.5), "finite and >= 0"),
    ("neg.pfm", _pfm_header(2, 1) + struct.pack("<6f", 0.5, 0.5, 0.5, 0.5, -1.0, 0.5), "finite and >= 0"),
    ("inf.pfm", _pfm_header(2, 1) + struct.pack("<6f", float("inf"), 0.5, 0.5, 0.5, 0.5, 0.5), "finite and >= 0"),
])
def test_a_sky_picture_that_cannot_be_used_is_a_bad_scene(tmp_path, name, content, says):
    # the picture is decoded and checked when the scene is, so check fails
    # (exit 2) rather than a render later (exit 1, or NaN pixels)
    (tmp_path / name).write_bytes(content)
    with pytest.raises(SceneError) as e:
        load_text(tmp_path, f'[sky]\ntype = "image"\nimage = "{name}"\n')
    msg = str(e.value)
    assert "sky.image" in msg and name in msg and says in msg


def test_a_folder_named_like_a_picture_is_not_one(tmp_path):
    (tmp_path / "dir.png").mkdir()
    with pytest.raises(SceneError, match=r"sky\.image: .*dir\.png is a folder, not a picture"):
        load_text(tmp_path, '[sky]\ntype = "image"\nimage = "dir.png"\n')


def test_a_16_bit_png_sky_keeps_its_depth(tmp_path):
    import numpy as np
    from PIL import Image

    from viewer.base.imageio import read_sky_image

    Image.fromarray(np.full((2, 4), 40000, np.uint16)).save(tmp_path / "deep.png")
    img = read_sky_image(tmp_path / "deep.png")
    # sRGB-decoded 40000 / 65535 (PIL's 8-bit conversion would clip it to 1.0)
    expected = ((40000 / 65535 + 0.055) / 1.055) ** 2.4
    np.testing.assert_allclose(img, expected, rtol=1e-6)


def test_image_sky_absolute_path(tmp_path):
    pic = tmp_path / "pics" / "sky.png"
    pic.parent.mkdir()
    write_picture(pic)
    sub = tmp_path / "scenes"
    sub.mkdir()
    s = load_text(sub, f'[sky]\ntype = "image"\nimage = "{pic.as_posix()}"\n')
    assert Path(s.sky.image_path).resolve() == pic.resolve()


def test_name_defaults_to_the_file_stem(tmp_path):
    assert load_text(tmp_path, "", "my glass.scene.toml").name == "my glass.scene"
    assert load_text(tmp_path, MAT, "rod-in-water.toml").name == "rod-in-water"
    assert load_text(tmp_path, 'name = "Explicit"\n', "file.toml").name == "Explicit"


def test_object_name_is_optional(tmp_path):
    s = load_text(tmp_path, objs(PLANE, SPHERE, SPHERE, BOX + 'name = "rod"\n', CYL))
    assert [o.name for o in s.objects] == [None, None, None, "rod", None]


def test_unreferenced_materials_are_fine(tmp_path):
    s = load_text(tmp_path, MAT + "[materials.unused]\ntransparency = 1\nior = 1.5\n")
    assert set(s.materials) == {"m", "unused"}


def test_object_key_order_does_not_matter(tmp_path):
    # objects may be written before the materials table
    s = load_text(tmp_path, '[[objects]]\ntype = "plane"\nmaterial = "late"\n\n[materials.late]\n')
    assert s.objects[0].material == "late"


@pytest.mark.parametrize("text", [
    "[camera]\nfov = 1\n",
    "[camera]\nfov = 179\n",
    "[camera]\nfov = 179.0\n",
    "[render]\nmax_depth = 1\n",
    "[render]\nmax_depth = 64\n",
    "[render]\nsamples = 1\n",
    "[render]\nsamples = 65536\n",
    "[render]\nmin_weight = 0\n",
    "[render]\nmin_weight = 1\n",
    "[render]\nmin_weight = 0.0\n",
    "[render]\nexposure = 1e-6\n",
    "[render]\nexposure = 1000\n",
    "ambient = [0, 0, 0]\n",
    "[materials.x]\nshininess = 1\n",
    "[materials.x]\nreflectivity = 0\ntransparency = 1\n",
    "[materials.x]\nreflectivity = 1\n",
    "[materials.x]\ntransparency = 1\n",
    "[materials.x]\ntransparency = 0\nreflectivity = 0.5\n",
    "[materials.x]\nior = 1\n",
    "[materials.x]\nior = 1.0\ntransparency = 0.5\n",
    "[materials.x]\nambient = 0\ndiffuse = 0\nspecular = 0\n",
    "[materials.x]\nspecular = 5\nambient = 3\ndiffuse = 2\n",
    "[materials.x]\nchecker = { color = [0, 0, 0], size = 1e-3 }\n",
    POINT + "intensity = 0\n",
    '[[lights]]\ntype = "directional"\ndirection = [0, -5, 0]\n',
    '[[lights]]\ntype = "directional"\ndirection = [1e-3, 0, 0]\n',
    objs(CYL + "wall = 0.999\n"),
    objs('type = "cylinder"\nbase = [0, 0, 0]\nradius = 5\nheight = 2\nwall = 1.999\nmaterial = "m"\n'),
    objs(CYL + 'axis = "x"\n', CYL + 'axis = "y"\n', CYL + 'axis = "z"\n'),
    objs('type = "box"\nmin = [-1, -1, -1]\nmax = [-0.999, -0.5, 0]\nmaterial = "m"\n'),
    objs(BOX + "rotate = [-720, 45.5, 1000]\n"),
    objs(PLANE + "height = -3.5\n"),
    objs('type = "sphere"\ncenter = [0, 0, 0]\nradius = 1e-6\nmaterial = "m"\n'),
    objs(PLANE + 'name = "a"\n', SPHERE + 'name = "b"\n', BOX),
    _cam_dir(0.02, down=False),
    _cam_dir(0.02, down=True),
    _cam_dir(0.02, down=True, azimuth_deg=123),
    _cam_dir(0.02, down=False, azimuth_deg=-90),
    "[camera]\nposition = [1e200, 1e200, 1e200]\ntarget = [0, 0, 0]\n",
    "[camera]\nposition = [0, 0, 0]\ntarget = [1, 1e-3, 0]\n",
], ids=lambda t: re.sub(r"\W+", "-", t)[:60])
def test_accepted_boundaries(tmp_path, text):
    assert isinstance(load_text(tmp_path, text), Scene)


# --------------------------------------------------------------------------- round trip and saving


def _reload_via_dict(s: Scene) -> Scene:
    text = scene_to_toml(s)
    data = tomllib.loads(text)
    base = s.path.parent if s.path is not None else None
    return scene_from_dict(data, source="round-trip", base_dir=base)


@pytest.mark.parametrize("name", BUILTINS)
def test_round_trip_builtin(name):
    s = load_scene(name)
    assert _reload_via_dict(s) == replace(s, path=None)


KITCHEN_SINK = """
name = "Everything"
ambient = [0.1, 0.2, 0.3]
[camera]
position = [1, 2, 3]
target = [0, 0.5, 0]
fov = 55.5
[render]
max_depth = 12
samples = 7
min_weight = 0
exposure = 1.75
[sky]
type = "color"
color = [0.3, 0.2, 0.1]
horizon = [1, 1, 1]
[[lights]]
type = "directional"
direction = [0.1, -1, 0.2]
color = [1, 0.9, 0.8]
intensity = 0.5
[[lights]]
position = [3, 4, 5]
[materials.floor]
emission = [0.5, 0.5, 0.5]
checker = { color = [0, 0, 0], emission = [0.1, 0, 0], size = 0.25 }
[materials.plain]
checker = { color = [1, 1, 1], size = 2 }
[materials."glass with spaces"]
transparency = 0.9
ior = 1.52
absorption = [0.1, 0.2, 0.3]
specular = 0.5
shininess = 150
[materials.mirror]
reflectivity = 0.75
[[objects]]
type = "plane"
height = -0.5
material = "floor"
[[objects]]
type = "cylinder"
name = "vessel"
axis = "x"
base = [-1, 0.5, 0]
radius = 0.5
height = 2
wall = 0.05
material = "glass with spaces"
[[objects]]
type = "box"
min = [-0.1, 0, -0.1]
max = [0.1, 2, 0.1]
rotate = [5, -10, 15]
material = "mirror"
[[objects]]
type = "sphere"
name = "ball"
center = [2, 1, -1]
radius = 0.3
material = "plain"
"""


def test_round_trip_every_feature(tmp_path):
    s = load_text(tmp_path, KITCHEN_SINK)
    assert _reload_via_dict(s) == replace(s, path=None)


def test_save_scene_and_load_back(tmp_path):
    s = load_text(tmp_path, KITCHEN_SINK, "in.toml")
    out = tmp_path / "out" / "saved.toml"
    out.parent.mkdir()
    save_scene(s, out)
    assert sorted(os.listdir(out.parent)) == ["saved.toml"]
    back = load_scene(out)
    assert replace(back, path=None) == replace(s, path=None)
    assert back.name == "Everything"


@pytest.mark.parametrize("name", BUILTINS)
def test_save_builtin_and_load_back(tmp_path, name):
    s = load_scene(name)
    out = tmp_path / "copy.toml"
    save_scene(s, out)
    assert replace(load_scene(out), path=None) == replace(s, path=None)


def test_save_image_sky_scene_elsewhere_keeps_the_picture(tmp_path):
    src = tmp_path / "src"
    dst = tmp_path / "dst"
    src.mkdir()
    dst.mkdir()
    (src / "sky.pfm").write_bytes(b"PF\n1 1\n-1.0\n" + b"\0" * 12)
    s = load_text(src, '[sky]\ntype = "image"\nimage = "sky.pfm"\n')
    save_scene(s, dst / "moved.toml")
    back = load_scene(dst / "moved.toml")
    assert back.sky.type == "image"
    assert Path(back.sky.image_path).resolve() == (src / "sky.pfm").resolve()


def test_save_overwrites_completely(tmp_path):
    target = tmp_path / "scene.toml"
    target.write_text("# old\n" + "x" * 100000, encoding="utf-8")
    s = load_scene("glass-sphere" if "glass-sphere" in BUILTINS else None)
    save_scene(s, target)
    assert replace(load_scene(target), path=None) == replace(s, path=None)
    assert sorted(os.listdir(tmp_path)) == ["scene.toml"]


OLD = b"# the old scene, which must survive\nname = \"old\"\n"


@pytest.mark.parametrize("failing", ["replace", "fsync", "write"])
def test_save_is_atomic_when_the_write_fails(tmp_path, monkeypatch, failing):
    target = tmp_path / "scene.toml"
    target.write_bytes(OLD)
    s = load_scene(None)

    def boom(*a, **k):
        raise OSError(28, "No space left on device")

    if failing == "replace":
        monkeypatch.setattr(os, "replace", boom)
        monkeypatch.setattr(os, "rename", boom)
    elif failing == "fsync":
        monkeypatch.setattr(os, "fsync", boom)
    else:
        real_fdopen = os.fdopen

        class Failing:
            def __init__(self, f):
                self.f = f

            def __enter__(self):
                return self

            def __exit__(self, *exc):
                self.f.close()
                return False

            def write(self, data):
                self.f.write(data[: len(data) // 2])
                self.f.flush()
                raise OSError(28, "No space left on device")

            def __getattr__(self, name):
                return getattr(self.f, name)

        monkeypatch.setattr(os, "fdopen", lambda *a, **k: Failing(real_fdopen(*a, **k)))
    with pytest.raises(OSError):
        save_scene(s, target)
    monkeypatch.undo()
    assert target.read_bytes() == OLD
    assert sorted(os.listdir(tmp_path)) == ["scene.toml"]


def test_save_into_missing_directory_fails_cleanly(tmp_path):
    target = tmp_path / "no-such-dir" / "scene.toml"
    with pytest.raises(OSError):
        save_scene(load_scene(None), target)
    assert not target.parent.exists()
    assert os.listdir(tmp_path) == []


def test_save_fails_before_writing_if_the_scene_cannot_be_serialised(tmp_path, monkeypatch):
    target = tmp_path / "scene.toml"
    target.write_bytes(OLD)

    def boom(scene, *args, **kwargs):
        raise RuntimeError("serialiser broke")

    monkeypatch.setattr(scene_save, "scene_file_text", boom)
    with pytest.raises(RuntimeError):
        save_scene(load_scene(None), target)
    assert target.read_bytes() == OLD
    assert sorted(os.listdir(tmp_path)) == ["scene.toml"]


# --------------------------------------------------------------------------- overrides


def test_with_overrides_applies_everything_and_copies():
    s = load_scene(None)
    before = copy.deepcopy(s)
    o = with_overrides(s, samples=4, max_depth=3, min_weight=0.05, camera_position=(5, 3, 5),
                       camera_target=(0, 1, 0), fov=60, light_position=(1, 7, 2))
    assert o.render.samples == 4
    assert o.render.max_depth == 3
    assert o.render.min_weight == 0.05
    assert tuple(o.camera.position) == (5, 3, 5)
    assert tuple(o.camera.target) == (0, 1, 0)
    assert o.camera.fov == 60
    assert tuple(o.lights[0].position) == (1, 7, 2)
    # the rest is unchanged
    assert o.render.exposure == s.render.exposure
    assert o.objects == s.objects and o.materials == s.materials and o.sky == s.sky
    assert o.name == s.name
    # and the original scene is untouched
    assert s == before


@pytest.mark.parametrize("kw", [
    {"samples": 2}, {"max_depth": 1}, {"min_weight": 0.0}, {"fov": 10},
    {"camera_position": (0, 3, 6)}, {"camera_target": (0.5, 0.5, 0.5)}, {"light_position": (0, 9, 0)},
])
def test_with_overrides_one_at_a_time_leaves_the_original(kw):
    s = load_scene(None)
    before = copy.deepcopy(s)
    o = with_overrides(s, **kw)
    assert s == before
    assert o != s


def test_with_overrides_none_keeps_everything():
    s = load_scene(None)
    assert with_overrides(s) == s
    assert with_overrides(s, samples=None, max_depth=None, min_weight=None, camera_position=None,
                          camera_target=None, fov=None, light_position=None) == s


def test_light_position_moves_the_first_point_light(tmp_path):
    s = load_text(tmp_path, DIRL + POINT + "[[lights]]\nposition = [9, 9, 9]\n")
    before = copy.deepcopy(s)
    o = with_overrides(s, light_position=(1, 2, 3))
    assert o.lights[0] == s.lights[0]
    assert tuple(o.lights[1].position) == (1, 2, 3)
    assert o.lights[2] == s.lights[2]
    assert s == before


@pytest.mark.parametrize("where", ["mirror-ball", "whitted-exact", "directional-only", "no-lights"])
def test_light_position_without_a_point_light(tmp_path, where):
    if where == "directional-only":
        s = load_text(tmp_path, DIRL)
    elif where == "no-lights":
        s = load_text(tmp_path, MAT)
    else:
        if where not in BUILTINS:
            pytest.skip(f"no built-in scene {where}")
        s = load_scene(where)
    assert not any(lt.type == "point" for lt in s.lights)
    before = copy.deepcopy(s)
    with pytest.raises(SceneError):
        with_overrides(s, light_position=(0, 5, 0))
    assert s == before


@pytest.mark.parametrize("kw", [
    {"camera_position": (0, 10, 0), "camera_target": (0, 0, 0)},
    {"camera_position": (0, -10, 0), "camera_target": (0, 0, 0)},
    {"camera_position": (0, 0.9, 0)},  # equals the default scene's target
    {"camera_target": (3.2, 2.2, 4.6)},  # equals the default scene's position
    {"camera_position": (1, 2, 3), "camera_target": (1, 2, 3)},
])
def test_with_overrides_rejects_a_bad_camera(kw):
    s = load_scene(None)
    assert s.camera.position == (3.2, 2.2, 4.6) and s.camera.target == (0.0, 0.9, 0.0)
    before = copy.deepcopy(s)
    with pytest.raises(SceneError):
        with_overrides(s, **kw)
    assert s == before


# --------------------------------------------------------------------------- features


def test_features_of_an_opaque_diffuse_scene(tmp_path):
    s = load_text(tmp_path, '[materials.d]\ncolor = [0.5, 0.5, 0.5]\n'
                            '[[objects]]\ntype = "plane"\nmaterial = "d"\n'
                            '[[objects]]\ntype = "sphere"\ncenter = [0, 1, 0]\nradius = 1\nmaterial = "d"\n'
                            '[[objects]]\ntype = "box"\nmin = [2, 0, 0]\nmax = [3, 1, 1]\nmaterial = "d"\n')
    f = s.features()
    for absent in ("dielectric", "reflection", "absorption", "vessel", "checker", "emission", "shadows"):
        assert absent not in f
    for present in ("plane", "sphere", "box", "sky:gradient"):
        assert present in f


def test_features_of_the_default_scene():
    f = load_scene(None).features()
    for present in ("dielectric", "reflection", "absorption", "checker", "vessel", "shadows",
                    "plane", "cylinder", "box", "sphere", "sky:gradient"):
        assert present in f
    assert "emission" not in f
    assert len(f) == len(set(f))


def test_features_follow_the_materials_in_use(tmp_path):
    # a dielectric, reflective, absorbing material nobody uses adds nothing
    s = load_text(tmp_path, MAT + "[materials.glass]\ntransparency = 1\nior = 1.5\nabsorption = [1, 1, 1]\n"
                                  "[materials.mirror]\nreflectivity = 1\n"
                                  '[[objects]]\ntype = "plane"\nmaterial = "m"\n')
    f = s.features()
    assert "dielectric" not in f and "reflection" not in f and "absorption" not in f
    # absorption only matters inside a medium: an opaque material's absorption is not used
    s = load_text(tmp_path, "[materials.o]\nabsorption = [1, 1, 1]\n"
                            '[[objects]]\ntype = "plane"\nmaterial = "o"\n')
    assert "absorption" not in s.features()
    # a clear dielectric without absorption
    s = load_text(tmp_path, "[materials.g]\ntransparency = 1\nior = 1.5\n"
                            '[[objects]]\ntype = "sphere"\ncenter = [0, 1, 0]\nradius = 1\nmaterial = "g"\n')
    f = s.features()
    assert "dielectric" in f and "absorption" not in f and "reflection" not in f


def test_features_emission_lights_and_sky(tmp_path):
    s = load_text(tmp_path, '[sky]\ntype = "color"\n' + DIRL +
                  "[materials.e]\nemission = [0, 0, 0]\nchecker = { color = [0, 0, 0], emission = [1, 0, 0], size = 1 }\n"
                  '[[objects]]\ntype = "plane"\nmaterial = "e"\n')
    f = s.features()
    assert "emission" in f and "checker" in f and "shadows" in f and "sky:color" in f
    assert "sky:gradient" not in f


@pytest.mark.parametrize("name", BUILTINS)
def test_features_of_builtins_are_consistent(name):
    s = load_scene(name)
    f = s.features()
    used = [s.materials[o.material] for o in s.objects]
    assert ("dielectric" in f) == any(m.transparency > 0 for m in used)
    assert ("reflection" in f) == any(m.reflectivity > 0 for m in used)
    assert ("shadows" in f) == bool(s.lights)
    assert f"sky:{s.sky.type}" in f
    for o in s.objects:
        assert o.type in f


def test_far_apart_camera_points_are_not_taken_for_equal(tmp_path):
    # target - position overflows a double; the points still differ and the
    # view is along +x
    s = load_text(tmp_path, "[camera]\nposition = [-1e308, 0, 0]\ntarget = [1e308, 0, 0]\n")
    assert s.camera.target == (1e308, 0.0, 0.0)
    with pytest.raises(SceneError, match="straight up or down"):
        load_text(tmp_path, "[camera]\nposition = [0, -1e308, 0]\ntarget = [0, 1e308, 0]\n")


@pytest.mark.parametrize("v", [(1e-320, -1e-320, 0.0), (3.0, 4.0, 0.0), (1e308, 1e308, -1e308), (0.0, 0.0, -5e-324)])
def test_unit_vector_neither_underflows_nor_overflows(v):
    u = scene_load.unit_vector(v)
    assert math.isclose(math.hypot(*u), 1.0, rel_tol=1e-15)
    # the same direction: u is a positive multiple of v
    k = max(range(3), key=lambda i: abs(v[i]))
    assert all(math.isclose(u[i], v[i] / v[k] * u[k], rel_tol=1e-12, abs_tol=1e-300) for i in range(3))


def test_an_unknown_key_names_the_type_it_was_checked_for(tmp_path):
    with pytest.raises(SceneError, match=r'lights\[0\]\.direction: unknown key for a "point" light \(the default type\)'):
        load_text(tmp_path, "[[lights]]\ndirection = [1, -1, 0]\n")
    with pytest.raises(SceneError, match=r'objects\[0\]\.height: unknown key for a "sphere"'):
        load_text(tmp_path, '[materials.m]\n[[objects]]\ntype = "sphere"\ncenter = [0, 0, 0]\nradius = 1\n'
                            'height = 2\nmaterial = "m"\n')


def test_messages_quote_keys_name_dates_and_show_close_numbers_exactly(tmp_path):
    # a material name with a dot is quoted in the key path, as TOML writes it
    with pytest.raises(SceneError, match=r'materials\."a\.b"\.foo: unknown key'):
        load_text(tmp_path, '[materials."a.b"]\nfoo = 1\n')
    # TOML dates and times are named like the other types
    for value, name in (("1979-05-27", "a date"), ("07:32:00", "a time"), ("1979-05-27T07:32:00", "a date-time")):
        with pytest.raises(SceneError, match=f"camera.fov: expected a number, got {name}$"):
            load_text(tmp_path, f"[camera]\nfov = {value}\n")
    # min and max that differ past the 6th digit are printed so that they differ
    with pytest.raises(SceneError, match=r"x: 1\.0000001 >= 1\.0\)"):
        load_text(tmp_path, '[materials.m]\n[[objects]]\ntype = "box"\nmin = [1.0000001, 0, 0]\n'
                            'max = [1.0, 1, 1]\nmaterial = "m"\n')


def test_a_key_with_control_characters_keeps_the_message_on_one_line(tmp_path):
    # a quoted key may hold a newline (TOML "\n"): the key path shows it
    # escaped as TOML writes it, so the message stays one line
    for text, path in (('"a\\nb" = 1\n', '"a\\nb"'),
                       ('[materials."x\\ty\\u0007"]\nfoo = 1\n', 'materials."x\\ty\\u0007".foo')):
        msg = assert_rejected(write(tmp_path, text), None)
        assert "\n" not in msg and "\t" not in msg and "\x07" not in msg, repr(msg)
        assert f": {path}: unknown key" in msg, msg


def test_the_summary_of_a_scene_whose_name_has_a_newline_is_one_line(tmp_path):
    s = load_text(tmp_path, 'name = "two\\nlines \\u001b[31mred"\n')
    assert s.name == "two\nlines \x1b[31mred"                 # the name itself is kept as written
    assert s.summary().startswith("two\\nlines \\x1b[31mred: 0 objects, ")
    assert len(s.summary().splitlines()) == 1
    assert load_text(tmp_path, 'name = "Café \\"au\\" lait"\n').summary().startswith('Café "au" lait: 0 objects')


def test_saving_through_a_symbolic_link_replaces_the_file_it_points_to(tmp_path):
    # a scene kept elsewhere and linked in (dotfiles, a shared folder): the
    # link stays a link, the file it points to gets the new scene
    real_dir = tmp_path / "real"
    real_dir.mkdir()
    real = real_dir / "scene.toml"
    real.write_bytes(OLD)
    link = tmp_path / "linked.toml"
    link.symlink_to(real)
    s = load_scene("glass-sphere")
    save_scene(s, link)
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert load_scene(real).name == s.name
    assert sorted(os.listdir(real_dir)) == ["scene.toml"] and sorted(os.listdir(tmp_path)) == ["linked.toml", "real"]


@pytest.mark.parametrize("text, says", [
    ("[camera]\nfov = 0.5\n", "camera.fov: expected a number in 1..179, got 0.5"),    # below: the whole range
    ("[camera]\nfov = 200\n", "camera.fov: expected a number in 1..179, got 200"),    # above: the same words
    ("[render]\nexposure = 0\n", "render.exposure: expected a number > 0, got 0"),
])
def test_a_value_out_of_range_is_told_the_whole_range(tmp_path, text, says):
    # (it used to name only the bound broken: "expected a number >= 1")
    with pytest.raises(SceneError, match=re.escape(says)):
        load_text(tmp_path, text)


def test_range_text_of_open_and_half_open_ranges():
    from viewer.scene.load import _range_text

    assert _range_text(0, 1, True, False) == "> 0 and <= 1"
    assert _range_text(0, 1, False, True) == ">= 0 and < 1"
    assert _range_text(None, 5, False, False) == "<= 5"


def test_a_sky_picture_that_is_not_one_is_said_so_plainly(tmp_path):
    (tmp_path / "sky.jpg").write_bytes(b"not a picture at all")
    with pytest.raises(SceneError) as err:
        load_text(tmp_path, '[sky]\ntype = "image"\nimage = "sky.jpg"\n')
    msg = str(err.value)
    assert _names_key(msg, "sky.image") and "cannot decode it: not a JPG picture" in msg, msg
    assert "Error" not in msg and msg.count("sky.jpg") == 1, msg      # no class name, the file named once
