"""glassray: a real-time Whitted ray tracer for a rod in a glass of liquid.

The package root is the Python API (docs/api.md)::

    import viewer
    img = viewer.render(viewer.load_scene("default"), size=(640, 360))
    viewer.save_image(img, "out.png")

Everything under the subpackages is internal.
"""

from .api import (
    VIEWS,
    Camera,
    Checker,
    ContextError,
    Image,
    Light,
    Material,
    Renderer,
    RenderError,
    RenderSettings,
    Scene,
    SceneError,
    SceneObject,
    Sky,
    builtin_scenes,
    load_scene,
    render,
    save_image,
    to_srgb8,
    validate_scene,
)
from .base.version import __version__

__all__ = [
    "load_scene", "validate_scene", "builtin_scenes", "render", "Renderer", "Image", "save_image", "to_srgb8",
    "VIEWS", "Scene", "Camera", "RenderSettings", "Sky", "Light", "Material", "Checker", "SceneObject",
    "SceneError", "ContextError", "RenderError", "__version__",
]
