"""The scene model: plain dataclasses, TOML loading with full validation, saving.

The contract is ``shared/spec/scene-format.md`` (a copy of the rules is in
``docs/scene-format.md``).  Everything the renderer, the reference tracer, the
viewer and the tests know about a scene comes from here; nothing else parses
TOML.  Validation collects the first error with the file name and the key path
(``objects[2].radius``) and raises :class:`SceneError`; the CLI turns that into
one line on stderr and exit status 2.
"""

from __future__ import annotations

import datetime
import errno
import itertools
import math
import os
import re
import stat
import tempfile
import tomllib
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

Vec3 = tuple[float, float, float]

SCENES_PACKAGE = "viewer.scenes"
DEFAULT_SCENE_NAME = "default"

# Implementation limits (documented in the README): the shader keeps the set of
# transparent solids a ray is inside as a 32-bit mask, and the uniform block
# holds the objects, materials and lights of one scene.
MAX_TRANSPARENT_OBJECTS = 32
MAX_OBJECTS = 256
MAX_MATERIALS = 256
MAX_LIGHTS = 64


class SceneError(ValueError):
    """A scene that cannot be used; the message names the file and key path."""


# --------------------------------------------------------------------------- data


@dataclass
class Camera:
    position: Vec3 = (3.2, 2.2, 4.6)
    target: Vec3 = (0.0, 0.9, 0.0)
    fov: float = 40.0


@dataclass
class RenderSettings:
    max_depth: int = 8
    samples: int = 1
    min_weight: float = 0.001
    exposure: float = 1.0


@dataclass
class Sky:
    type: str = "gradient"
    color: Vec3 = (0.6, 0.7, 0.9)
    horizon: Vec3 = (0.8, 0.85, 0.9)
    zenith: Vec3 = (0.25, 0.4, 0.75)
    image: str | None = None  # as written in the file
    image_path: Path | None = None  # resolved against the scene file


@dataclass
class Light:
    type: str = "point"
    position: Vec3 | None = None
    direction: Vec3 | None = None
    color: Vec3 = (1.0, 1.0, 1.0)
    intensity: float = 1.0


@dataclass
class Checker:
    color: Vec3
    size: float
    emission: Vec3 | None = None  # None: the material's emission


@dataclass
class Material:
    color: Vec3 = (0.8, 0.8, 0.8)
    ambient: float = 0.1
    diffuse: float = 0.8
    specular: float = 0.0
    shininess: float = 32.0
    reflectivity: float = 0.0
    transparency: float = 0.0
    ior: float = 1.0
    absorption: Vec3 = (0.0, 0.0, 0.0)
    emission: Vec3 = (0.0, 0.0, 0.0)
    checker: Checker | None = None

    @property
    def is_dielectric(self) -> bool:
        return self.transparency > 0.0


@dataclass
class SceneObject:
    """One solid.  Only the keys of its ``type`` are meaningful."""

    type: str
    material: str
    name: str | None = None
    # plane: height; cylinder: height (length along the axis)
    height: float = 0.0
    # sphere
    center: Vec3 = (0.0, 0.0, 0.0)
    radius: float = 0.0
    # box
    min: Vec3 = (0.0, 0.0, 0.0)
    max: Vec3 = (0.0, 0.0, 0.0)
    rotate: Vec3 = (0.0, 0.0, 0.0)
    # cylinder
    axis: str = "y"
    base: Vec3 = (0.0, 0.0, 0.0)
    wall: float | None = None


@dataclass
class Scene:
    name: str
    camera: Camera = field(default_factory=Camera)
    render: RenderSettings = field(default_factory=RenderSettings)
    sky: Sky = field(default_factory=Sky)
    ambient: Vec3 = (0.05, 0.05, 0.05)
    lights: list[Light] = field(default_factory=list)
    materials: dict[str, Material] = field(default_factory=dict)
    objects: list[SceneObject] = field(default_factory=list)
    path: Path | None = None  # the file it came from, if any
    # how error messages name it: the file as given, or the built-in scene
    # (not compared: the same scene from another place is equal)
    source: str | None = field(default=None, compare=False)
    # the file has no `name`: it is the file stem, and a saved copy leaves it
    # out too (so that it is titled by its own file name)
    name_from_file: bool = field(default=False, compare=False)

    def material_of(self, obj: SceneObject) -> Material:
        return self.materials[obj.material]

    def is_transparent(self, obj: SceneObject) -> bool:
        return self.materials[obj.material].is_dielectric

    def scatters(self, obj: SceneObject) -> bool:
        """Whether a ray that meets it goes on (refracted or reflected): it
        is transparent or reflects."""
        return self.is_transparent(obj) or self.materials[obj.material].reflectivity > 0

    def features(self) -> list[str]:
        """The shading features this scene uses (what ``check`` prints and the
        shader specialisation keys on)."""
        used = [self.materials[o.material] for o in self.objects]
        feats: list[str] = sorted({o.type for o in self.objects})
        if any(o.type == "cylinder" and o.wall is not None for o in self.objects):
            feats.append("vessel")
        if self.lights:
            feats.append("shadows")
        if any(m.reflectivity > 0 for m in used):
            feats.append("reflection")
        if any(m.is_dielectric for m in used):
            feats.append("dielectric")
        if any(m.is_dielectric and max(m.absorption) > 0 for m in used):
            feats.append("absorption")
        if any(m.checker is not None for m in used):
            feats.append("checker")
        if any(max(m.emission) > 0 or (m.checker and m.checker.emission and max(m.checker.emission) > 0)
               for m in used):
            feats.append("emission")
        feats.append(f"sky:{self.sky.type}")
        return feats

    def summary(self) -> str:
        # (the name may hold a newline: the summary stays one line)
        return (f"{printable(self.name)}: {_count(self.objects, 'object')}, {_count(self.materials, 'material')}, "
                f"{_count(self.lights, 'light')}; features: {', '.join(self.features())}")


# --------------------------------------------------------------------------- validation


class _Ctx:
    """Where we are while validating: the file and the key path."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, path: str, what: str) -> SceneError:
        where = f"{self.source}: {path}: " if path else f"{self.source}: "
        return SceneError(where + what)


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


#: TOML's short escapes in a basic string; any other control character is \uXXXX
_TOML_ESCAPES = {"\\": "\\\\", '"': '\\"', "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}


def _toml_quote(key: str) -> str:
    """A key as TOML writes it in a basic string: quotes and backslashes
    escaped, and control characters too, so that a message stays one line."""
    return '"' + "".join(_TOML_ESCAPES.get(c) or (f"\\u{ord(c):04X}" if _is_control(c) else c)
                         for c in key) + '"'


def _is_control(c: str) -> bool:
    return ord(c) < 0x20 or 0x7F <= ord(c) < 0xA0 or c in "\u2028\u2029"


def printable(text: str) -> str:
    """`text` with its control characters (a newline, an escape sequence)
    written as escapes, so that it shows on one line as it is."""
    if not any(_is_control(c) for c in text):
        return text
    return "".join(c.encode("unicode_escape").decode("ascii") if _is_control(c) else c for c in text)


#: The longest key, string or number a message quotes in full: a longer one
#: (a key of a megabyte of junk) is shown by its start and end, so that the
#: message stays a line a person can read.
MAX_SHOWN = 80


#: The same for a file's path (a real one is at most PATH_MAX, 4096, long)
MAX_SHOWN_PATH = 1000


def _shown(text: str, limit: int = MAX_SHOWN) -> str:
    """`text` as a message shows it: in full up to `limit` characters,
    otherwise its start and end around the number of characters left out."""
    if len(text) <= limit:
        return text
    head, tail = text[:limit * 3 // 4], text[-(limit // 4):]
    return f"{head}...({len(text) - len(head) - len(tail)} more characters)...{tail}"


def _rv(v: Any) -> str:
    """repr(v) (a string quoted, a number as written), shortened by _shown."""
    return _shown(repr(v))


def _join(path: str, key: str | int) -> str:
    if isinstance(key, int):
        return f"{path}[{key}]"
    if not _BARE_KEY.fullmatch(key):
        key = _toml_quote(key)       # as TOML quotes it: materials."a.b"
    return f"{path}.{_shown(key)}" if path else _shown(key)


def _check_keys(ctx: _Ctx, path: str, table: dict, allowed: set[str], kind: str = "") -> None:
    """Every key of `table` in `allowed`; `kind` names what the keys depend
    on (for example 'for a "point" light', whose type may be the default)."""
    for key in table:
        if key not in allowed:
            raise ctx.fail(_join(path, key), f"unknown key{' ' + kind if kind else ''} "
                                             f"(expected one of: {', '.join(sorted(allowed))})")


def _table(ctx: _Ctx, path: str, value: Any) -> dict:
    if not isinstance(value, dict):
        raise ctx.fail(path, f"expected a table, got {_typename(value)}")
    return value


def _typename(v: Any) -> str:
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, int):
        return "an integer"
    if isinstance(v, float):
        return "a float"
    if isinstance(v, str):
        return "a string"
    if isinstance(v, list):
        return "an array"
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, datetime.datetime):     # (a datetime is a date too: first)
        return "a date-time"
    if isinstance(v, datetime.date):
        return "a date"
    if isinstance(v, datetime.time):
        return "a time"
    return type(v).__name__


def _float(ctx: _Ctx, path: str, v: Any, *, lo: float | None = None, hi: float | None = None,
           lo_open: bool = False, hi_open: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ctx.fail(path, f"expected a number, got {_typename(v)}")
    try:
        x = float(v)
    except OverflowError:  # a TOML integer too large for a double
        raise ctx.fail(path, "expected a finite number, got an integer too large for a float") from None
    if not math.isfinite(x):
        raise ctx.fail(path, f"expected a finite number, got {_rv(v)}")
    if (lo is not None and (x <= lo if lo_open else x < lo)) or (hi is not None and (x >= hi if hi_open else x > hi)):
        raise ctx.fail(path, f"expected a number {_range_text(lo, hi, lo_open, hi_open)}, got {_rv(v)}")
    return x


def _range_text(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    """The whole allowed range, not only the bound a value broke: "in 1..179",
    "> 0 and <= 1", ">= 0"."""
    if lo is not None and hi is not None and not (lo_open or hi_open):
        return f"in {lo:g}..{hi:g}"
    parts = ([f"{'>' if lo_open else '>='} {lo:g}"] if lo is not None else []) + \
            ([f"{'<' if hi_open else '<='} {hi:g}"] if hi is not None else [])
    return " and ".join(parts)


def _int(ctx: _Ctx, path: str, v: Any, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise ctx.fail(path, f"expected an integer, got {_typename(v)}")
    if not lo <= v <= hi:
        raise ctx.fail(path, f"expected an integer in {lo}..{hi}, got {_rv(v)}")
    return v


def _str(ctx: _Ctx, path: str, v: Any, choices: tuple[str, ...] | None = None) -> str:
    if not isinstance(v, str):
        raise ctx.fail(path, f"expected a string, got {_typename(v)}")
    if choices is not None and v not in choices:
        raise ctx.fail(path, f"expected one of {', '.join(repr(c) for c in choices)}, got {_rv(v)}")
    return v


def _vec3(ctx: _Ctx, path: str, v: Any) -> Vec3:
    if not isinstance(v, list) or len(v) != 3:
        raise ctx.fail(path, f"expected an array of 3 numbers [x, y, z], got {_describe(v)}")
    x, y, z = (_float(ctx, _join(path, i), c) for i, c in enumerate(v))
    return (x, y, z)


def _color(ctx: _Ctx, path: str, v: Any) -> Vec3:
    if not isinstance(v, list) or len(v) != 3:
        raise ctx.fail(path, f"expected a colour [r, g, b], got {_describe(v)}")
    r, g, b = (_float(ctx, _join(path, i), c, lo=0.0) for i, c in enumerate(v))
    return (r, g, b)


def _describe(v: Any) -> str:
    if isinstance(v, list):
        return f"an array of {len(v)}"
    return _typename(v)


def _camera(ctx: _Ctx, t: dict) -> Camera:
    _check_keys(ctx, "camera", t, {"position", "target", "fov"})
    cam = Camera()
    if "position" in t:
        cam.position = _vec3(ctx, "camera.position", t["position"])
    if "target" in t:
        cam.target = _vec3(ctx, "camera.target", t["target"])
    if "fov" in t:
        cam.fov = _float(ctx, "camera.fov", t["fov"], lo=1.0, hi=179.0)
    validate_camera(cam, ctx)
    return cam


def unit_vector(v) -> tuple[float, float, float]:
    """v / |v| for any finite non-zero v: scaled by its largest component
    first, so that neither tiny (1e-320) nor huge components underflow or
    overflow the length."""
    s = max(abs(float(c)) for c in v)
    x, y, z = (float(c) / s for c in v)
    n = math.hypot(x, y, z)
    return (x / n, y / n, z / n)


def validate_camera(cam: Camera, ctx: _Ctx | None = None) -> None:
    """position != target, and the view is not within 0.01 degrees of +-y."""
    ctx = ctx or _Ctx("camera")
    if tuple(cam.target) == tuple(cam.position):
        raise ctx.fail("camera.target", "must differ from camera.position")
    # scaled, so that the difference of far-apart points cannot overflow
    s = max(abs(c) for c in (*cam.target, *cam.position))
    f = unit_vector([t / s - p / s for t, p in zip(cam.target, cam.position)])
    cos_up = abs(f[1])
    if cos_up > math.cos(math.radians(0.01)):
        raise ctx.fail("camera.target",
                       "the view direction is (within 0.01 degrees of) straight up or down; "
                       "move the target or the position sideways")


def _render(ctx: _Ctx, t: dict) -> RenderSettings:
    _check_keys(ctx, "render", t, {"max_depth", "samples", "min_weight", "exposure"})
    r = RenderSettings()
    if "max_depth" in t:
        r.max_depth = _int(ctx, "render.max_depth", t["max_depth"], 1, 64)
    if "samples" in t:
        r.samples = _int(ctx, "render.samples", t["samples"], 1, 65536)
    if "min_weight" in t:
        r.min_weight = _float(ctx, "render.min_weight", t["min_weight"], lo=0.0, hi=1.0)
    if "exposure" in t:
        r.exposure = _float(ctx, "render.exposure", t["exposure"], lo=0.0, lo_open=True)
    return r


def _sky(ctx: _Ctx, t: dict, base_dir: Path | None) -> Sky:
    _check_keys(ctx, "sky", t, {"type", "color", "horizon", "zenith", "image"})
    s = Sky()
    if "type" in t:
        s.type = _str(ctx, "sky.type", t["type"], ("color", "gradient", "image"))
    # the spec: "Keys of the other sky types are accepted and ignored" -- so
    # only the active type's keys are validated; another type's are kept (the
    # panel switches type, a saved scene writes them) where they are valid,
    # and otherwise dropped for their defaults, never an error
    active = {"color": ("color",), "gradient": ("horizon", "zenith"), "image": ("image",)}[s.type]
    for key in ("color", "horizon", "zenith"):
        if key in t:
            try:
                setattr(s, key, _color(ctx, f"sky.{key}", t[key]))
            except SceneError:
                if key in active:
                    raise
    if "image" in t:
        if "image" in active:
            s.image = _str(ctx, "sky.image", t["image"])
        elif isinstance(t["image"], str):
            s.image = t["image"]
    if s.type == "image":
        if s.image is None:
            raise ctx.fail("sky.image", "required when sky.type is \"image\"")
        p = Path(s.image)
        if not p.is_absolute():
            p = (base_dir or Path.cwd()) / p
        if p.suffix.lower() not in (".png", ".jpg", ".jpeg", ".pfm"):
            raise ctx.fail("sky.image", f"expected a .png, .jpg, .jpeg or .pfm picture, got {_rv(s.image)}")
        shown = _shown(printable(str(p)), MAX_SHOWN_PATH)
        try:
            if p.is_dir():
                raise ctx.fail("sky.image", f"{shown} is a folder, not a picture")
            if p.exists() and not p.is_file():
                # a device or a named pipe: decoding would read it forever or wait for a writer
                raise ctx.fail("sky.image", f"{shown} is not a regular file, not a picture")
            if not p.is_file():
                raise ctx.fail("sky.image", f"no such file: {shown}")
        except OSError as e:
            # what pathlib does not take for "no such file": a name too long
            # for the file system, a folder on the way that cannot be searched
            raise ctx.fail("sky.image", f"{shown}: cannot read: {e.strerror or e}") from None
        from .imageio import ImageReadError, read_sky_image   # (imageio imports this module)

        try:
            read_sky_image(p)
        except ImageReadError as e:
            raise ctx.fail("sky.image", f"{shown}: {e}") from None
        s.image_path = p
    return s


def _light(ctx: _Ctx, path: str, t: dict) -> Light:
    typ = _str(ctx, _join(path, "type"), t.get("type", "point"), ("point", "directional"))
    own = "position" if typ == "point" else "direction"
    _check_keys(ctx, path, t, {"type", own, "color", "intensity"},
                f'for a "{typ}" light' + ("" if "type" in t else " (the default type)"))
    light = Light(type=typ)
    if own not in t:
        raise ctx.fail(_join(path, own), f"required for a {typ} light")
    v = _vec3(ctx, _join(path, own), t[own])
    if typ == "point":
        light.position = v
    else:
        if v == (0.0, 0.0, 0.0):
            raise ctx.fail(_join(path, own), "must be non-zero")
        light.direction = v
    if "color" in t:
        light.color = _color(ctx, _join(path, "color"), t["color"])
    if "intensity" in t:
        light.intensity = _float(ctx, _join(path, "intensity"), t["intensity"], lo=0.0)
    return light


_MATERIAL_KEYS = {"color", "ambient", "diffuse", "specular", "shininess", "reflectivity",
                  "transparency", "ior", "absorption", "emission", "checker"}


def _material(ctx: _Ctx, path: str, t: dict) -> Material:
    _check_keys(ctx, path, t, _MATERIAL_KEYS)
    m = Material()
    for key in ("color", "absorption", "emission"):
        if key in t:
            setattr(m, key, _color(ctx, _join(path, key), t[key]))
    for key in ("ambient", "diffuse", "specular"):
        if key in t:
            setattr(m, key, _float(ctx, _join(path, key), t[key], lo=0.0))
    if "shininess" in t:
        m.shininess = _float(ctx, _join(path, "shininess"), t["shininess"], lo=1.0)
    for key in ("reflectivity", "transparency"):
        if key in t:
            setattr(m, key, _float(ctx, _join(path, key), t[key], lo=0.0, hi=1.0))
    if "ior" in t:
        m.ior = _float(ctx, _join(path, "ior"), t["ior"], lo=1.0)
    if m.transparency > 0 and m.reflectivity > 0:
        raise ctx.fail(_join(path, "reflectivity"),
                       "must be 0 on a dielectric (transparency > 0): Fresnel decides its reflection")
    if "checker" in t:
        cpath = _join(path, "checker")
        c = _table(ctx, cpath, t["checker"])
        _check_keys(ctx, cpath, c, {"color", "emission", "size"})
        for key in ("color", "size"):
            if key not in c:
                raise ctx.fail(_join(cpath, key), "required")
        m.checker = Checker(
            color=_color(ctx, _join(cpath, "color"), c["color"]),
            size=_float(ctx, _join(cpath, "size"), c["size"], lo=0.0, lo_open=True),
            emission=_color(ctx, _join(cpath, "emission"), c["emission"]) if "emission" in c else None,
        )
    return m


_OBJECT_KEYS = {
    "plane": {"height"},
    "sphere": {"center", "radius"},
    "box": {"min", "max", "rotate"},
    "cylinder": {"axis", "base", "radius", "height", "wall"},
}
_REQUIRED = {"plane": (), "sphere": ("center", "radius"), "box": ("min", "max"),
             "cylinder": ("base", "radius", "height")}


def _object(ctx: _Ctx, path: str, t: dict, materials: dict[str, Material]) -> SceneObject:
    if "type" not in t:
        raise ctx.fail(_join(path, "type"), "required (one of 'plane', 'sphere', 'box', 'cylinder')")
    typ = _str(ctx, _join(path, "type"), t["type"], tuple(_OBJECT_KEYS))
    _check_keys(ctx, path, t, {"type", "material", "name"} | _OBJECT_KEYS[typ], f'for a "{typ}"')
    if "material" not in t:
        raise ctx.fail(_join(path, "material"), "required (a name from [materials])")
    mat = _str(ctx, _join(path, "material"), t["material"])
    if mat not in materials:
        known = _shown(", ".join(sorted(materials)), 5 * MAX_SHOWN) or "none defined"   # (a list: more room)
        raise ctx.fail(_join(path, "material"), f"unknown material {_rv(mat)} (known: {known})")
    o = SceneObject(type=typ, material=mat)
    if "name" in t:
        o.name = _str(ctx, _join(path, "name"), t["name"])
    for key in _REQUIRED[typ]:
        if key not in t:
            raise ctx.fail(_join(path, key), f"required for a {typ}")
    p = lambda k: _join(path, k)  # noqa: E731
    if typ == "plane":
        if "height" in t:
            o.height = _float(ctx, p("height"), t["height"])
    elif typ == "sphere":
        o.center = _vec3(ctx, p("center"), t["center"])
        o.radius = _float(ctx, p("radius"), t["radius"], lo=0.0, lo_open=True)
    elif typ == "box":
        o.min = _vec3(ctx, p("min"), t["min"])
        o.max = _vec3(ctx, p("max"), t["max"])
        for i, axis in enumerate("xyz"):
            if not o.min[i] < o.max[i]:
                raise ctx.fail(p("max"), f"each component of min must be < max ({axis}: "
                                         f"{o.min[i]!r} >= {o.max[i]!r})")
        if "rotate" in t:
            o.rotate = _vec3(ctx, p("rotate"), t["rotate"])
    else:
        if "axis" in t:
            o.axis = _str(ctx, p("axis"), t["axis"], ("x", "y", "z"))
        o.base = _vec3(ctx, p("base"), t["base"])
        o.radius = _float(ctx, p("radius"), t["radius"], lo=0.0, lo_open=True)
        o.height = _float(ctx, p("height"), t["height"], lo=0.0, lo_open=True)
        if "wall" in t:
            w = _float(ctx, p("wall"), t["wall"], lo=0.0, lo_open=True)
            if not (w < o.radius and w < o.height):
                raise ctx.fail(p("wall"), f"expected 0 < wall < radius and wall < height, got {w!r} "
                                          f"(radius {o.radius!r}, height {o.height!r})")
            o.wall = w
    # finite extents: a box or cylinder whose size overflows is not a solid we can trace
    return o


_TOP_KEYS = {"name", "camera", "render", "sky", "ambient", "lights", "materials", "objects"}


def scene_from_dict(data: dict, source: str = "<scene>", base_dir: Path | None = None,
                    default_name: str = "scene") -> Scene:
    """Validate a parsed TOML document and build the Scene (raises SceneError)."""
    ctx = _Ctx(source)
    _check_keys(ctx, "", data, _TOP_KEYS)
    name = _str(ctx, "name", data["name"]) if "name" in data else default_name
    scene = Scene(name=name, name_from_file="name" not in data)
    if "camera" in data:
        scene.camera = _camera(ctx, _table(ctx, "camera", data["camera"]))
    if "render" in data:
        scene.render = _render(ctx, _table(ctx, "render", data["render"]))
    if "sky" in data:
        scene.sky = _sky(ctx, _table(ctx, "sky", data["sky"]), base_dir)
    if "ambient" in data:
        scene.ambient = _color(ctx, "ambient", data["ambient"])
    if "materials" in data:
        mats = _table(ctx, "materials", data["materials"])
        for mname, mt in mats.items():
            mpath = _join("materials", mname)
            scene.materials[mname] = _material(ctx, mpath, _table(ctx, mpath, mt))
    if "lights" in data:
        lights = data["lights"]
        if not isinstance(lights, list):
            raise ctx.fail("lights", f"expected an array of tables ([[lights]]), got {_typename(lights)}")
        for i, lt in enumerate(lights):
            lpath = f"lights[{i}]"
            scene.lights.append(_light(ctx, lpath, _table(ctx, lpath, lt)))
    if "objects" in data:
        objs = data["objects"]
        if not isinstance(objs, list):
            raise ctx.fail("objects", f"expected an array of tables ([[objects]]), got {_typename(objs)}")
        names: set[str] = set()
        for i, ot in enumerate(objs):
            opath = f"objects[{i}]"
            o = _object(ctx, opath, _table(ctx, opath, ot), scene.materials)
            if o.name is not None:
                if o.name in names:
                    raise ctx.fail(_join(opath, "name"), f"duplicate object name {_rv(o.name)}")
                names.add(o.name)
            scene.objects.append(o)
    _check_limits(ctx, scene)
    return scene


def _check_limits(ctx: _Ctx, scene: Scene) -> None:
    if len(scene.objects) > MAX_OBJECTS:
        raise ctx.fail("objects", f"at most {MAX_OBJECTS} objects are supported, got {len(scene.objects)}")
    if len(scene.materials) > MAX_MATERIALS:
        raise ctx.fail("materials", f"at most {MAX_MATERIALS} materials are supported")
    if len(scene.lights) > MAX_LIGHTS:
        raise ctx.fail("lights", f"at most {MAX_LIGHTS} lights are supported")
    n_transparent = sum(scene.is_transparent(o) for o in scene.objects)
    if n_transparent > MAX_TRANSPARENT_OBJECTS:
        raise ctx.fail("objects", f"at most {MAX_TRANSPARENT_OBJECTS} transparent objects are supported, "
                                  f"got {n_transparent}")


# --------------------------------------------------------------------------- loading


def builtin_scene_names() -> list[str]:
    files = resources.files(SCENES_PACKAGE)
    return sorted(p.name[:-5] for p in files.iterdir() if p.name.endswith(".toml"))


def resolve_scene_path(spec: str | os.PathLike | None) -> Path:
    """A path as given, or the name of a scene shipped with the package;
    None is the shipped default scene, whatever the current folder holds
    (a file or folder there named ``default`` is read only when named)."""
    if spec is None:
        return Path(str(resources.files(SCENES_PACKAGE) / f"{DEFAULT_SCENE_NAME}.toml"))
    p = Path(spec)
    try:
        exists = p.exists()
    except OSError:
        # a name too long for the file system (ENAMETOOLONG): not a built-in
        # name either; reading it says what is wrong
        return p
    if exists or p.suffix == ".toml" or os.sep in str(spec):
        return p
    builtin = resources.files(SCENES_PACKAGE) / f"{spec}.toml"
    try:
        if builtin.is_file():
            return Path(str(builtin))
    except OSError:
        pass
    return p


def _count(items, noun: str) -> str:
    return f"{len(items)} {noun}{'' if len(items) == 1 else 's'}"


def load_scene(spec: str | os.PathLike | None = None) -> Scene:
    """Load and validate a scene file (or a built-in scene by name)."""
    if spec is not None and not str(spec).strip():
        raise SceneError(f"{str(spec)!r}: empty scene path (give a scene file or a built-in scene name)")
    path = resolve_scene_path(spec)
    # (a name with a newline in it would break the one-line message)
    source = printable(str(spec)) if spec is not None else f"<default scene> {path}"
    raw = _read_scene_file(path, source)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise SceneError(f"{source}: not UTF-8 text ({e.reason} at byte {e.start})") from None
    # A leading byte order mark (Windows Notepad writes one) marks the text as
    # UTF-8; it is no part of the TOML (toml-test accepts it), and tomllib
    # would reject it as "Invalid statement (at line 1, column 1)", an
    # error at a character the user cannot see
    text = text.removeprefix("\ufeff")
    try:
        data = tomllib.loads(text)
    except (ValueError, RecursionError) as e:  # TOMLDecodeError; an integer too long to convert; deep nesting
        raise SceneError(f"{source}: not valid TOML: {e}") from None
    scene = scene_from_dict(data, source=source, base_dir=path.parent.resolve(), default_name=path.stem)
    scene.path = path
    scene.source = source
    return scene


#: A scene file is a small TOML text (the largest shipped is a few KB); one
#: larger than this is not a scene, and is refused before it is read.
MAX_SCENE_BYTES = 16 * 1024 * 1024


def _read_scene_file(path: Path, name: str) -> bytes:
    """The bytes of a scene file, read only when it is a regular file of at
    most MAX_SCENE_BYTES: a device (/dev/zero) would be read until memory
    runs out, a named pipe would wait for a writer forever."""
    try:
        # O_NONBLOCK: opening a named pipe does not wait for a writer (no
        # effect on a regular file)
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        names = ", ".join(builtin_scene_names())
        raise SceneError(f"{name}: no such scene file (built-in scenes: {names})") from None
    except IsADirectoryError:
        raise SceneError(f"{name}: is a directory, not a scene file") from None
    except OSError as e:
        raise SceneError(f"{name}: cannot read: {e.strerror or e}") from None
    try:
        st = os.fstat(fd)                 # of what was opened, not of what the name says now
        if stat.S_ISDIR(st.st_mode):
            raise SceneError(f"{name}: is a directory, not a scene file")
        if not stat.S_ISREG(st.st_mode):
            raise SceneError(f"{name}: is not a regular file (it is {_file_kind(st.st_mode)})")
        if st.st_size > MAX_SCENE_BYTES:
            raise SceneError(f"{name}: {st.st_size} bytes is too large for a scene file "
                             f"(at most {MAX_SCENE_BYTES // (1024 * 1024)} MiB)")
        with os.fdopen(fd, "rb") as f:
            fd = None                     # (closed with f)
            raw = f.read(MAX_SCENE_BYTES + 1)      # a file that grew since: still bounded
    except OSError as e:
        raise SceneError(f"{name}: cannot read: {e.strerror or e}") from None
    finally:
        if fd is not None:
            os.close(fd)
    if len(raw) > MAX_SCENE_BYTES:
        raise SceneError(f"{name}: too large for a scene file (over {MAX_SCENE_BYTES // (1024 * 1024)} MiB)")
    return raw


def _file_kind(mode: int) -> str:
    for test, kind in ((stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISFIFO, "a named pipe"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return kind
    return "a special file"


def default_scene() -> Scene:
    return load_scene(None)


# --------------------------------------------------------------------------- saving


def _sky_image_for(sky: Sky, scene_path: Path | None, dest: Path | None) -> str:
    """``sky.image`` as the file ``dest`` must write it to name the same
    picture: an absolute path as it is; a relative one rebased from the folder
    it was relative to onto dest's folder (the one load_scene(dest) resolves
    it against).  Without dest (or where it cannot be relative): absolute."""
    image = sky.image
    rel = Path(image)
    if rel.is_absolute():
        return image
    if sky.image_path is not None:
        # image_path is base / image, part by part (see _sky)
        parts = Path(sky.image_path).parts
        n = len(rel.parts)
        if n and tuple(parts[len(parts) - n:]) == rel.parts:
            src = Path(*parts[:len(parts) - n])
        else:
            return str(sky.image_path)
        absolute = str(sky.image_path)
    elif scene_path is not None:
        src = Path(scene_path).parent.resolve()
        absolute = str(src / rel)
    else:
        return image                       # nothing known to rebase it from
    if dest is None:
        return absolute
    dest = Path(dest)
    folder = dest.parent.resolve()
    # saved through a link in another folder: the target is read by other
    # names too; an absolute path holds for all of them
    if folder != Path(os.path.realpath(dest)).parent:
        return absolute
    try:
        up = os.path.relpath(src, folder)
    except ValueError:                     # another drive (Windows)
        return absolute
    return image if up == "." else str(Path(up) / image)


def scene_to_dict(scene: Scene, dest: Path | None = None) -> dict:
    """The TOML document for a scene; loading it gives back an equal scene.
    ``dest``: the file it is written to (save_scene).  A relative sky image is
    then written relative to dest's folder (it names the same picture), and a
    name that was the file stem (no `name` in the file) is left out, so that
    the saved file is named by its own stem, as its source was."""
    d: dict[str, Any] = {"ambient": list(scene.ambient)}
    if dest is None or not scene.name_from_file:
        d = {"name": scene.name, **d}
    c = scene.camera
    d["camera"] = {"position": list(c.position), "target": list(c.target), "fov": c.fov}
    r = scene.render
    d["render"] = {"max_depth": r.max_depth, "samples": r.samples, "min_weight": r.min_weight,
                   "exposure": r.exposure}
    s = scene.sky
    sky: dict[str, Any] = {"type": s.type, "color": list(s.color), "horizon": list(s.horizon),
                           "zenith": list(s.zenith)}
    if s.image is not None:
        sky["image"] = _sky_image_for(s, scene.path, dest)
    d["sky"] = sky
    lights = []
    for lt in scene.lights:
        ld: dict[str, Any] = {"type": lt.type}
        if lt.type == "point":
            ld["position"] = list(lt.position)
        else:
            ld["direction"] = list(lt.direction)
        ld["color"] = list(lt.color)
        ld["intensity"] = lt.intensity
        lights.append(ld)
    if lights:
        d["lights"] = lights
    mats = {}
    for name, m in scene.materials.items():
        md: dict[str, Any] = {
            "color": list(m.color), "ambient": m.ambient, "diffuse": m.diffuse, "specular": m.specular,
            "shininess": m.shininess, "reflectivity": m.reflectivity, "transparency": m.transparency,
            "ior": m.ior, "absorption": list(m.absorption), "emission": list(m.emission),
        }
        if m.checker is not None:
            ck: dict[str, Any] = {"color": list(m.checker.color), "size": m.checker.size}
            if m.checker.emission is not None:
                ck["emission"] = list(m.checker.emission)
            md["checker"] = ck
        mats[name] = md
    if mats:
        d["materials"] = mats
    objs = []
    for o in scene.objects:
        od: dict[str, Any] = {"type": o.type, "material": o.material}
        if o.name is not None:
            od["name"] = o.name
        if o.type == "plane":
            od["height"] = o.height
        elif o.type == "sphere":
            od.update(center=list(o.center), radius=o.radius)
        elif o.type == "box":
            od.update(min=list(o.min), max=list(o.max), rotate=list(o.rotate))
        else:
            od.update(axis=o.axis, base=list(o.base), radius=o.radius, height=o.height)
            if o.wall is not None:
                od["wall"] = o.wall
        objs.append(od)
    if objs:
        d["objects"] = objs
    return d


def scene_to_toml(scene: Scene, dest: Path | None = None) -> str:
    import tomli_w

    return tomli_w.dumps(scene_to_dict(scene, dest))


def _new_file_mode() -> int:
    """The mode a plain open() gives a new file: 0666 less the umask."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _write_temp(folder: Path, name: str, data: bytes, mode: int) -> str:
    """A temporary file in `folder` (named after `name`) holding `data`,
    flushed to disk, with `mode`; its path.  Removed again if that fails."""
    fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=folder)
    try:
        f = os.fdopen(fd, "wb")           # (closes fd whatever happens next)
        try:
            os.chmod(tmp, mode)           # mkstemp makes it 0600
        except OSError:
            pass  # a file system without modes (FAT, some network mounts): the file is still written
        with f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    except BaseException:
        _unlink_quietly(tmp)
        raise
    return tmp


def _unlink_quietly(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def write_atomic(path: Path, data: bytes) -> None:
    """Write to a temporary file beside ``path`` and rename it into place, so a
    failed write never leaves a half-written or destroyed file.  A symbolic
    link is followed: the file it points to is replaced and the link kept,
    as a plain open() for writing would."""
    tmp, path = _stage(path, data)
    try:
        os.replace(tmp, path)
    except BaseException:
        _unlink_quietly(tmp)
        raise


def _stage(path: Path, data: bytes) -> tuple[str, Path]:
    """`data` in full in a temporary file beside `path` (its link's target,
    for a symbolic link), checked as a plain open() for writing would check
    `path`; (the temporary file, the path to rename it to)."""
    path = Path(path)
    if path.is_symlink():
        path = Path(os.path.realpath(path))
    # a rename replaces a file whatever its own mode: one the user made
    # read-only is refused, as a plain open() for writing refuses it
    if path.exists() and not path.is_dir() and not os.access(path, os.W_OK):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
    try:
        mode = path.stat().st_mode & 0o7777      # the existing file's, as open() keeps it
    except OSError:
        mode = _new_file_mode()
    return _write_temp(path.parent, path.name, data, mode), path


class AtomicSet:
    """Files written as one set (a benchmark's CSV, tables and plots): each
    is written in full beside its name first, and only when every one is
    are they renamed into place, and the files to remove removed.  An error
    before that (a full disk, a read-only file among them, Ctrl-C) leaves
    every file as it was, never some of one run and some of another.  (The
    renames themselves could still fail part way: they do not allocate,
    so only a folder changed under the run can make them fail.)"""

    def __init__(self) -> None:
        self._staged: list[tuple[str, Path]] = []
        self._removals: list[Path] = []

    def write(self, path: Path, data: bytes) -> None:
        self._staged.append(_stage(path, data))

    def remove(self, path: Path) -> None:
        self._removals.append(Path(path))

    def commit(self) -> None:
        staged, self._staged = self._staged, []
        try:
            while staged:
                tmp, path = staged[0]
                os.replace(tmp, path)
                staged.pop(0)
        finally:
            for tmp, _ in staged:
                _unlink_quietly(tmp)
        removals, self._removals = self._removals, []
        for path in removals:
            path.unlink(missing_ok=True)

    def discard(self) -> None:
        for tmp, _ in self._staged:
            _unlink_quietly(tmp)
        self._staged, self._removals = [], []


def write_new(paths, data: bytes) -> Path:
    """Write `data` under the first of `paths` (an iterable of names in one
    folder, tried in order) that no file has, and return it.  Never
    replaces a file, also one another program creates between the check
    and the write (two viewers saving a screenshot in the same second): the
    complete file is linked to the name, which fails if the name is taken.
    Where the file system has no hard links, the name is created exclusively
    (O_EXCL) and written: still never a replaced file; a failed write
    removes it, but a crash during the write can leave a short one."""
    paths = iter(paths)
    first = Path(next(paths))
    tmp = _write_temp(first.parent, first.name, data, _new_file_mode())
    try:
        linked = True
        for path in itertools.chain([first], map(Path, paths)):
            if linked:
                try:
                    os.link(tmp, path)
                    return path
                except FileExistsError:
                    continue
                except OSError as e:
                    if e.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EMLINK, errno.ENOSYS):
                        raise
                    linked = False               # no hard links here: exclusive creation instead
            try:
                f = open(path, "xb")
            except FileExistsError:
                continue
            try:
                with f:
                    f.write(data)
                    f.flush()
                    os.fsync(f.fileno())
            except BaseException:
                _unlink_quietly(str(path))           # ours, and short: no half-written screenshot
                raise
            return path
        raise FileExistsError(errno.EEXIST, "every name is taken", str(first))
    finally:
        _unlink_quietly(tmp)


def save_scene(scene: Scene, path: Path) -> None:
    write_atomic(Path(path), scene_to_toml(scene, Path(path)).encode("utf-8"))


def with_overrides(scene: Scene, **kw) -> Scene:
    """A copy of the scene with command-line overrides applied (None = keep)."""
    s = replace(scene, camera=replace(scene.camera), render=replace(scene.render),
                lights=[replace(lt) for lt in scene.lights])
    if kw.get("samples") is not None:
        s.render.samples = kw["samples"]
    if kw.get("max_depth") is not None:
        s.render.max_depth = kw["max_depth"]
    if kw.get("min_weight") is not None:
        s.render.min_weight = kw["min_weight"]
    if kw.get("camera_position") is not None:
        s.camera.position = tuple(kw["camera_position"])
    if kw.get("camera_target") is not None:
        s.camera.target = tuple(kw["camera_target"])
    if kw.get("fov") is not None:
        s.camera.fov = kw["fov"]
    if kw.get("light_position") is not None:
        points = [lt for lt in s.lights if lt.type == "point"]
        if not points:
            raise SceneError(f"{s.source or s.name}: --light-position: the scene has no point light to move")
        points[0].position = tuple(kw["light_position"])
    validate_camera(s.camera, _Ctx("command line"))
    return s
