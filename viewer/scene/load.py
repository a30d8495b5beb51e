"""Scene loading: TOML (a file, a built-in name, or text) to a validated :class:`Scene`.

Validation collects the first error with the file name and the key path
(``objects[2].radius``) and raises :class:`SceneError`; the CLI turns that into
one line on stderr and exit status 2.  Nothing else in the package parses TOML.
"""

from __future__ import annotations

import datetime
import math
import os
import re
import stat
import tomllib
from dataclasses import replace
from importlib import resources
from pathlib import Path
from typing import Any

from ..base.imageio import ImageReadError, read_sky_image
from ..base.text import _is_control, printable
from .model import (
    DEFAULT_SCENE_NAME,
    MAX_LIGHTS,
    MAX_MATERIALS,
    MAX_OBJECTS,
    MAX_TRANSPARENT_OBJECTS,
    SCENES_PACKAGE,
    Camera,
    Checker,
    Light,
    Material,
    RenderSettings,
    Scene,
    SceneError,
    SceneObject,
    Sky,
)

Vec3 = tuple[float, float, float]

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
    scene = scene_from_toml(text, source=source, base_dir=path.parent.resolve(), default_name=path.stem)
    scene.path = path
    return scene


def scene_from_toml(text: str, source: str = "<TOML text>", base_dir: Path | None = None,
                    default_name: str = "scene") -> Scene:
    """Parse and validate a scene's TOML text (raises SceneError, its
    message starting with `source`).  A relative sky.image is resolved
    against base_dir (the current folder when None)."""
    # A leading byte order mark (Windows Notepad writes one) marks the text as
    # UTF-8; it is no part of the TOML (toml-test accepts it), and tomllib
    # would reject it as "Invalid statement (at line 1, column 1)", an
    # error at a character the user cannot see
    text = text.removeprefix("\ufeff")
    try:
        data = tomllib.loads(text)
    except (ValueError, RecursionError) as e:  # TOMLDecodeError; an integer too long to convert; deep nesting
        raise SceneError(f"{source}: not valid TOML: {e}") from None
    scene = scene_from_dict(data, source=source, base_dir=base_dir, default_name=default_name)
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
