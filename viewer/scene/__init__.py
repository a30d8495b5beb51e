"""The scene layer: the model, loading with validation, saving, the built-in scenes.

Imports only ``viewer.base``.  Everything above reads scenes through these names.
"""

from .load import builtin_scene_names, default_scene, load_scene, resolve_scene_path, scene_from_dict, with_overrides
from .model import Camera, Checker, Light, Material, RenderSettings, Scene, SceneError, SceneObject, Sky
from .save import save_scene, scene_to_dict, scene_to_toml

__all__ = ["Camera", "Checker", "Light", "Material", "RenderSettings", "Scene", "SceneError", "SceneObject", "Sky",
           "builtin_scene_names", "default_scene", "load_scene", "resolve_scene_path", "save_scene", "scene_from_dict",
           "scene_to_dict", "scene_to_toml", "with_overrides"]
