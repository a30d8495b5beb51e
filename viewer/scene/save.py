"""Scene saving: a :class:`Scene` back to TOML, written atomically."""

from __future__ import annotations

import copy
import os
from pathlib import Path
from typing import Any

import tomli_w
import tomlkit

from ..base.files import write_atomic
from .load import load_scene, scene_from_toml
from .model import Material, Scene, SceneError, Sky


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
    """Every value of the scene as TOML, in one fixed form (the digests that
    key caches read it: the same scene, the same text)."""
    return tomli_w.dumps(scene_to_dict(scene, dest))


# --------------------------------------------------------------------------- the file a user keeps


def _inline(value: Any) -> Any:
    """A value as tomlkit writes it: vectors (lists of numbers) on one line."""
    if isinstance(value, list) and all(isinstance(v, (int, float)) for v in value):
        arr = tomlkit.array()
        arr.extend(value)
        return arr
    if isinstance(value, dict):
        return {k: _inline(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_inline(v) for v in value]
    return value


def _is_table_list(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def _edit(container, before: dict, after: dict) -> None:
    """Change `container` (a tomlkit table of the user's file, which said
    `before`) so that it says `after`, touching only what differs: a table
    or an array of tables of the same length is edited inside (its comments
    and order stay), any other changed value is rewritten, a key gone from
    `after` is removed."""
    for key, new in after.items():
        old = before.get(key)
        if key in before and old == new:
            continue
        here = container.get(key) if key in container else None
        if isinstance(new, dict) and isinstance(old, dict) and isinstance(here, dict):
            _edit(here, old, new)
        elif (_is_table_list(new) and _is_table_list(old) and len(new) == len(old)
              and isinstance(here, list) and len(here) == len(new)):
            for item, o, n in zip(here, old, new):
                if o != n:
                    _edit(item, o, n)
        else:
            item = tomlkit.item(_inline(new))
            trivia = getattr(here, "trivia", None)
            if trivia is not None and trivia.comment and hasattr(item, "trivia"):
                # `fov = 40  # wide`: the comment stays with its value
                item.trivia.comment_ws, item.trivia.comment = trivia.comment_ws, trivia.comment
            container[key] = item
    for key in list(before):
        if key not in after and key in container:
            del container[key]


def _defaults_left_out(d: dict) -> dict:
    """A new file's document: the values that differ from the format's
    defaults (an empty table left out too)."""
    base = scene_to_dict(Scene(name=d.get("name", "scene")))
    out: dict[str, Any] = {}
    for key, value in d.items():
        if key in ("camera", "render", "sky"):
            table = {k: v for k, v in value.items() if base[key].get(k) != v}
            if table:
                out[key] = table
        elif key == "ambient":
            if value != base["ambient"]:
                out[key] = value
        elif key == "materials":
            plain = {k: v for k, v in scene_to_dict(Scene(name="m", materials={"m": Material()}))["materials"]["m"].items()}
            out[key] = {name: {k: v for k, v in m.items() if k == "color" or plain.get(k) != v} for name, m in value.items()}
        elif key == "lights":
            out[key] = [{k: v for k, v in lt.items() if not (k == "color" and v == [1.0, 1.0, 1.0])
                         and not (k == "intensity" and v == 1.0)} for lt in value]
        elif key == "objects":
            out[key] = [{k: v for k, v in o.items() if not (k == "rotate" and v == [0.0, 0.0, 0.0])} for o in value]
        else:
            out[key] = value
    return out


def scene_file_text(scene: Scene, dest: Path | None = None) -> str:
    """The text save_scene writes to `dest`.  For a scene read from a file
    (scene.path) that is still there, that file's text with only the values
    that changed rewritten: its comments, order and formatting stay, and an
    unedited scene gives back its own text.  Otherwise a new file: the
    values that differ from the defaults, vectors on one line."""
    after = scene_to_dict(scene, dest)
    source = Path(scene.path) if scene.path is not None else None
    text = None
    if source is not None:
        try:
            text = source.read_text(encoding="utf-8")
            # the file as its own loader reads it (relative pictures from its folder)
            original = scene_from_toml(text, source=str(source), base_dir=source.parent.resolve(),
                                       default_name=source.stem)
            original.path = source
            doc = tomlkit.parse(text.removeprefix("\ufeff"))
        except (OSError, UnicodeDecodeError, SceneError, tomlkit.exceptions.TOMLKitError):
            text = None
    if text is None:
        return tomlkit.dumps(_inline(_defaults_left_out(after)))
    before = scene_to_dict(original, source)
    _edit(doc, before, after)
    return tomlkit.dumps(doc)


def save_scene(scene: Scene, path: Path) -> None:
    """Write the scene to `path` atomically (scene_file_text says what)."""
    write_atomic(Path(path), scene_file_text(scene, Path(path)).encode("utf-8"))


# ------------------------------------------------------------ the command line's values

def _override_paths(scene: Scene) -> list[tuple]:
    """Where the values a command line can set live in a scene
    (scene.load.with_overrides), as attribute paths (an int: a list index)."""
    return [("render", "samples"), ("render", "max_depth"), ("render", "min_weight"),
            ("camera", "position"), ("camera", "target"), ("camera", "fov"),
            *(("lights", i, "position") for i in range(len(scene.lights)))]


def _get(obj: Any, path: tuple) -> Any:
    for p in path:
        obj = obj[p] if isinstance(p, int) else getattr(obj, p)
    return obj


def overrides_of(loaded: Scene, from_file: Scene) -> dict[tuple, tuple[Any, Any]]:
    """The values of `loaded` (a file read with command-line overrides) that
    the command line set: {path: (its value, the file's)}."""
    out = {}
    for path in _override_paths(loaded):
        try:
            mine, theirs = _get(loaded, path), _get(from_file, path)
        except (IndexError, AttributeError):
            continue
        if mine != theirs:
            out[path] = (mine, theirs)
    return out


def overrides_of_file(loaded: Scene) -> dict[tuple, tuple[Any, Any]]:
    """overrides_of `loaded` against its own file read again alone: what
    the command line set.  Empty when there is no file or it no longer
    loads (then there is nothing to put back)."""
    if loaded.path is None:
        return {}
    try:
        return overrides_of(loaded, load_scene(str(loaded.path)))
    except (SceneError, OSError):
        return {}


def as_the_file_had(scene: Scene, overrides: dict[tuple, tuple[Any, Any]]) -> Scene:
    """`scene` to be saved, with each value the command line set
    (overrides_of) and nobody changed since put back as the file had it: an
    override is how this run looked at the file, not an edit of it
    (`glassray view my.toml --samples 1`, saved unedited, is my.toml).  A
    value changed since (in the panel, by orbiting) is an edit and stays."""
    out = copy.deepcopy(scene)
    for path, (mine, theirs) in overrides.items():
        try:
            if _get(out, path) == mine:
                setattr(_get(out, path[:-1]), path[-1], theirs)
        except (IndexError, AttributeError):
            continue
    return out
