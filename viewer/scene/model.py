"""The scene model: plain dataclasses that everything else reads.

A :class:`Scene` holds the camera, render settings, sky, lights, materials and
objects of one scene, as loaded and validated by :mod:`viewer.scene.load`.
Its values can be changed in code; a render validates them again.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from ..base.text import printable

Vec3 = tuple[float, float, float]

SCENES_PACKAGE = "viewer.scene.builtin"
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


def _count(items, noun: str) -> str:
    return f"{len(items)} {noun}{'' if len(items) == 1 else 's'}"
