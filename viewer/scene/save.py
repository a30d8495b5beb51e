"""Scene saving: a :class:`Scene` back to TOML, written atomically."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any
from ..base.files import write_atomic
from .model import Scene, Sky


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



def save_scene(scene: Scene, path: Path) -> None:
    write_atomic(Path(path), scene_to_toml(scene, Path(path)).encode("utf-8"))


