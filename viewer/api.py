"""glassray as a library: load a scene, change it in code, render it, save it.

    import viewer
    scene = viewer.load_scene("default")
    scene.lights[0].position = (2.0, 4.0, 1.0)
    img = viewer.render(scene, size=(640, 360), samples=4)   # float32 (360, 640, 3), linear
    viewer.save_image(img, "out.png")

Everything here is what ``glassray render`` does, as functions: ``render``
returns exactly the array ``glassray render ... -o OUT.npy`` writes for the
same settings (the command line is a user of this module), and
``save_image`` writes the files it writes.  docs/api.md is the reference.

This floor sits on ``gpu`` and ``adaptive`` and below ``measure``, the
viewer and the command line; nothing under it imports it.
"""

from __future__ import annotations

import atexit
import copy
import io
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
from PIL import Image as _PILImage

from .adaptive.render import DEFAULT_TARGET_ERROR, render_adaptive
from .base.imageio import OUTPUT_EXTENSIONS, encode_png, to_display8, write_image
from .base.files import write_atomic
from .base.views import picture, raw_view
from .gpu.context import ContextError, create_offscreen_context, size_failure
from .gpu.renderer import Renderer as _GPURenderer
from .scene.load import (
    builtin_scene_names,
    load_scene as _load_scene_file,
    resolve_scene_path,
    scene_from_dict,
    scene_from_toml,
    with_overrides,
)
from .scene.model import Camera, Checker, Light, Material, RenderSettings, Scene, SceneError, SceneObject, Sky
from .scene.save import scene_to_dict

__all__ = [
    "load_scene", "validate_scene", "builtin_scenes", "render", "Renderer", "Image", "save_image", "to_srgb8",
    "VIEWS", "Scene", "Camera", "RenderSettings", "Sky", "Light", "Material", "Checker", "SceneObject",
    "SceneError", "ContextError", "RenderError",
]

#: What ``render(view=...)`` can draw: the image, or a debug view of the
#: first hit (normals, depth, objects), of the rays traced per pixel (cost) or
#: of an adaptive render's samples per pixel (samples).
VIEWS = ("color", "normals", "depth", "objects", "cost", "samples")
#: The views that trace one centred ray per pixel (sampling options do not apply).
FIRST_HIT_VIEWS = ("normals", "depth", "objects", "cost")
#: Largest image side, as the command line's --size.
MAX_SIDE = 16384


class RenderError(RuntimeError):
    """A render the OpenGL driver could not do (an image too large for it);
    the message says what to change."""


# ------------------------------------------------------------------ scenes


def builtin_scenes() -> list[str]:
    """The names of the scenes shipped with glassray (``load_scene`` takes them)."""
    return builtin_scene_names()


def _is_toml_text(source: str) -> bool:
    """A string that is TOML text rather than a file or a scene name: it has
    a line break or an ``=``, and names no file (a scene name never holds
    either)."""
    if "\n" not in source and "=" not in source:
        return False
    try:
        return not resolve_scene_path(source).exists()
    except (OSError, ValueError):
        return True


def load_scene(source: str | os.PathLike | None = None) -> Scene:
    """A validated Scene from a built-in scene name (``"default"``), a path
    to a TOML file, or TOML text; None is the default scene.

    Raises SceneError (a ValueError) whose message names the source and the
    key path, worded as ``glassray check`` words it.  A relative
    ``sky.image`` in TOML text is resolved against the current folder."""
    if isinstance(source, str) and _is_toml_text(source):
        return scene_from_toml(source, source="<TOML text>")
    return _load_scene_file(source)


def validate_scene(scene: Scene) -> Scene:
    """A validated copy of ``scene``, which may have been changed in code.

    Every value is checked as the scene file's loader checks it, and the
    message names the key path (``materials.glass.ior: expected a number
    in [1, 4], got 0.5``).  ``render`` calls this itself; call it to check a
    scene before rendering it.  Raises SceneError."""
    if not isinstance(scene, Scene):
        raise TypeError(f"expected a viewer.Scene (from load_scene), got {type(scene).__name__}")
    source = scene.source or scene.name or "<scene>"
    try:
        data = scene_to_dict(scene)
    except (AttributeError, TypeError, ValueError) as e:
        # a value of the wrong shape (a number where a vector belongs)
        raise SceneError(f"{source}: a value set in code cannot be read: {e}") from None
    checked = scene_from_dict(data, source=source, base_dir=Path(scene.path).parent if scene.path else None,
                              default_name=scene.name)
    checked.path, checked.source, checked.name_from_file = scene.path, scene.source, scene.name_from_file
    return checked


# ------------------------------------------------------------------ images


class Image(np.ndarray):
    """A rendered picture: a float32 ``numpy.ndarray`` of shape (H, W, 3),
    linear, first row the top, as ``glassray render -o OUT.npy`` writes it.

    ``kind`` is the view it shows (``"color"`` or a debug view's name) and
    ``info`` what the render reported (``mean_spp`` of an adaptive render).
    In a notebook it displays itself, encoded as the PNG ``save_image``
    writes.  Arithmetic on it gives plain arrays' values; ``np.asarray``
    gives the plain array."""

    kind: str
    info: dict

    def __new__(cls, array: np.ndarray, kind: str = "color", info: dict | None = None) -> Image:
        obj = np.ascontiguousarray(array, dtype=np.float32).view(cls)
        obj.kind = kind
        obj.info = dict(info or {})
        return obj

    def __array_finalize__(self, obj) -> None:
        self.kind = getattr(obj, "kind", "color")
        self.info = getattr(obj, "info", {})

    def _repr_png_(self) -> bytes:
        return _png_bytes(np.asarray(self), self.kind)


def _png_bytes(array: np.ndarray, kind: str) -> bytes:
    """The PNG glassray writes: the image in sRGB, or a debug view's picture
    with its legend."""
    if kind == "color":
        return encode_png(array)
    buf = io.BytesIO()
    _PILImage.fromarray(np.round(255 * picture(kind, array)).astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def _image_array(array) -> np.ndarray:
    a = np.asarray(array)
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"expected an image of shape (H, W, 3), got shape {a.shape}")
    if not np.issubdtype(a.dtype, np.number) or np.issubdtype(a.dtype, np.complexfloating):
        raise ValueError(f"expected an array of real numbers, got dtype {a.dtype}")
    return a


def to_srgb8(array) -> np.ndarray:
    """uint8 (H, W, 3) display colours of a linear image: clamped to [0, 1],
    the sRGB curve, rounded to 255 steps; the pixels of the PNG glassray
    writes."""
    return to_display8(_image_array(array))


def save_image(array, path: str | os.PathLike, *, kind: str | None = None) -> None:
    """Write an image by the file's extension, as ``glassray render -o``
    does, atomically (a reader never sees half a file; a failed write
    leaves what was there): ``.png`` 8-bit sRGB, ``.npy`` float32 (H, W, 3)
    linear, ``.pfm`` linear float map.  A debug view (``kind``, taken from
    an Image by default) goes to PNG as its false-colour picture with a
    legend, and to ``.npy`` / ``.pfm`` as its raw values.

    Raises ValueError for an unknown extension or an array that is not an
    image, OSError when the file cannot be written."""
    a = _image_array(array)
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in OUTPUT_EXTENSIONS:
        what = f"unknown output extension {ext!r}" if ext else "no output extension"
        raise ValueError(f"{path}: {what} (expected .png, .npy or .pfm)")
    kind = kind if kind is not None else getattr(array, "kind", "color")
    if kind not in VIEWS:
        raise ValueError(f"unknown view {kind!r}: expected one of {', '.join(VIEWS)}")
    if ext == ".png" and kind != "color":
        write_atomic(path, _png_bytes(a, kind))
    else:
        write_image(path, a)


# ------------------------------------------------------------------ rendering


def _check_int(name: str, v, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
        raise ValueError(f"{name}: expected an integer in {lo}..{hi}, got {v!r}")
    return int(v)


def _check_options(size, samples, max_depth, min_weight, adaptive, target_error, view, seed) -> tuple[int, int]:
    """Check render()'s keywords before any OpenGL; return (width, height).
    ValueError names the keyword, as the command line's usage errors name
    the option."""
    try:
        w, h = size
    except (TypeError, ValueError):
        raise ValueError(f"size: expected (width, height), got {size!r}") from None
    w, h = _check_int("size width", w, 1, MAX_SIDE), _check_int("size height", h, 1, MAX_SIDE)
    if samples is not None:
        _check_int("samples", samples, 1, 65536)
    if max_depth is not None:
        _check_int("max_depth", max_depth, 1, 64)
    if min_weight is not None and (isinstance(min_weight, bool) or not isinstance(min_weight, (int, float))
                                   or not 0.0 <= min_weight <= 1.0):
        raise ValueError(f"min_weight: expected a number in [0, 1], got {min_weight!r}")
    _check_int("seed", seed, 0, 2**63 - 1)
    if view not in VIEWS:
        raise ValueError(f"view: expected one of {', '.join(VIEWS)}, got {view!r}")
    if target_error is not None:
        if isinstance(target_error, bool) or not isinstance(target_error, (int, float)) \
                or not 0.0 < target_error <= 1e9:
            raise ValueError(f"target_error: expected a number in (0, 1e9], got {target_error!r}")
        if not adaptive:
            raise ValueError("target_error is the adaptive render's target: pass adaptive=True with it")
    if view == "samples" and not adaptive:
        raise ValueError("view='samples' shows an adaptive render's samples per pixel: pass adaptive=True")
    if view in FIRST_HIT_VIEWS and adaptive:
        raise ValueError(f"view={view!r} traces one centred ray per pixel: adaptive does not apply")
    return w, h


class Renderer:
    """An offscreen OpenGL context with its compiled shader programs, for
    many renders in one process::

        with viewer.Renderer() as r:
            for x in np.linspace(-3, 3, 24):
                scene.lights[0].position = (x, 4.0, 2.0)
                frames.append(r.render(scene, size=(320, 180)))

    ``backend``: ``"auto"`` (EGL, then OSMesa), ``"egl"`` or ``"osmesa"``.
    No context raises ContextError saying why.  A scene that keeps its
    structure (the same objects, materials and features) between renders
    reuses the programs compiled for it; ``close()`` (or leaving the
    ``with`` block) releases every GL object and the context.  Not for use
    from several threads at once."""

    def __init__(self, backend: str = "auto"):
        self.context, self.backend = create_offscreen_context(backend)
        self._gpu: _GPURenderer | None = None
        self._given: Scene | None = None       # the last scene passed in (a copy), and
        self._checked: Scene | None = None     # its validated copy, uploaded to the GPU

    # -- lifetime

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the GL objects and the context (again: nothing)."""
        if self._gpu is not None:
            with self.context:
                self._gpu.release()
            self._gpu = None
        if self.context is not None:
            self.context.release()
            self.context = None

    @property
    def closed(self) -> bool:
        return self.context is None

    # -- rendering

    def render(self, scene: Scene, *, size: tuple[int, int] = (1280, 720), samples: int | None = None,
               max_depth: int | None = None, min_weight: float | None = None, adaptive: bool = False,
               target_error: float | None = None, view: str = "color", seed: int = 0,
               progress: Callable[[int, int], None] | None = None) -> Image:
        """Render ``scene``: see :func:`render`."""
        return self.prepare(scene, size=size, samples=samples, max_depth=max_depth, min_weight=min_weight,
                            adaptive=adaptive, target_error=target_error, view=view, seed=seed)(progress)

    def prepare(self, scene: Scene, *, size: tuple[int, int] = (1280, 720), samples: int | None = None,
                max_depth: int | None = None, min_weight: float | None = None, adaptive: bool = False,
                target_error: float | None = None, view: str = "color",
                seed: int = 0) -> Callable[..., Image]:
        """Check the options, validate and upload the scene, and return
        ``draw(progress=None) -> Image``, which renders that frame (again
        at each call: for timing a frame without the upload).  A later
        prepare() or render() of another scene makes earlier draws stale."""
        if self.closed:
            raise RuntimeError("this Renderer is closed")
        w, h = _check_options(size, samples, max_depth, min_weight, adaptive, target_error, view, seed)
        scene = with_overrides(self._validated(scene), samples=samples, max_depth=max_depth, min_weight=min_weight)
        with self.context:                  # current for these GL calls, the caller's context again after
            gpu = self._upload(scene)
        spp = gpu.scene.render.samples
        target = DEFAULT_TARGET_ERROR if target_error is None else float(target_error)

        def _draw(progress: Callable[[int, int], None] | None) -> Image:
            if view in FIRST_HIT_VIEWS:
                return Image(raw_view(gpu, view, w, h), view)
            if adaptive:
                result = render_adaptive(gpu, w, h, spp, target, seed, progress=progress)
                info = {"mean_spp": float(result.mean_spp), "samples": spp, "target_error": target}
                if view == "samples":
                    return Image(raw_view(gpu, view, w, h, result.spp), view, info)
                return Image(result.image, "color", info)
            return Image(gpu.render(w, h, spp, seed, progress=progress), "color", {"samples": spp})

        def draw(progress: Callable[[int, int], None] | None = None) -> Image:
            if self._gpu is not gpu:
                raise RuntimeError("this frame's Renderer is closed")
            try:
                with self.context:
                    return _draw(progress)
            except Exception as e:
                too_large = size_failure(e, w, h)
                if too_large is None:
                    raise
                raise RenderError(str(too_large).replace("--size", "size")) from e
        return draw

    def _validated(self, scene: Scene) -> Scene:
        """The validated copy of scene; the last one again when the scene
        has not changed since (a frame redrawn checks nothing twice)."""
        if self._checked is None or scene != self._given:
            checked = validate_scene(scene)
            self._given, self._checked = copy.deepcopy(scene), checked
        return self._checked

    def _upload(self, scene: Scene) -> _GPURenderer:
        if self._gpu is None:
            # compiles each program when a draw first needs it (as glassray render)
            self._gpu = _GPURenderer(self.context, scene, eager=False)
        else:
            self._gpu.set_scene(scene)
        return self._gpu

    def one_draw_warning(self, what: str) -> str | None:
        """Whether the driver may cut the scene last prepared short when
        ``what`` is drawn in one go (the command line prints it)."""
        return None if self._gpu is None else self._gpu.one_draw_warning(what)


_shared: Renderer | None = None


def _shared_renderer() -> Renderer:
    global _shared
    if _shared is None or _shared.closed:
        _shared = Renderer()
        atexit.register(_shared.close)
    return _shared


def render(scene: Scene, *, size: tuple[int, int] = (1280, 720), samples: int | None = None,
           max_depth: int | None = None, min_weight: float | None = None, adaptive: bool = False,
           target_error: float | None = None, view: str = "color", seed: int = 0,
           progress: Callable[[int, int], None] | None = None) -> Image:
    """Render ``scene`` offscreen; an :class:`Image`: float32 (H, W, 3),
    linear, first row the top of the picture, exactly the array
    ``glassray render ... -o OUT.npy`` writes for the same settings.

    ``size`` (width, height); ``samples``, ``max_depth``, ``min_weight``
    replace the scene's values (None keeps them); ``adaptive`` spends the
    samples (the mean per pixel) where pixels need them, down to
    ``target_error``; ``view`` one of VIEWS (a debug view is its raw
    values); ``seed`` the sample pattern (the same seed, the same image);
    ``progress(done, total)`` is called as the render goes.

    The first call creates an offscreen context (``"auto"``) and keeps it,
    with its compiled programs, for later calls: a second call costs the
    frame.  Raises SceneError for a bad scene, ValueError for a bad option,
    ContextError without OpenGL, RenderError for an image the driver
    cannot hold."""
    return _shared_renderer().render(scene, size=size, samples=samples, max_depth=max_depth,
                                     min_weight=min_weight, adaptive=adaptive, target_error=target_error,
                                     view=view, seed=seed, progress=progress)
