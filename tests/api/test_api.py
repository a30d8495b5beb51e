"""The Python API (viewer/api.py, docs/api.md): the names a script uses from
the package root, what render() returns against the renderer underneath and
the command line's .npy, a Renderer's reuse of its programs across changing
scenes, validation of scenes changed in code, and the image helpers."""

from __future__ import annotations

import copy
import inspect
import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image as PILImage

import viewer
from viewer.gpu.renderer import Renderer as GPURenderer
from viewer.scene.load import with_overrides

W, H = 48, 27
#: the names scripts rely on (docs/api.md's first table)
CONTRACT = ("load_scene", "Scene", "render", "Renderer", "save_image", "to_srgb8", "SceneError", "ContextError")


# ---------------------------------------------------------------- the package root

def test_the_contract_is_importable_from_the_package_root():
    for name in CONTRACT:
        assert name in viewer.__all__ and name in dir(viewer), name
    from viewer import load_scene, render  # noqa: F401  (the form scripts use)


def test_render_takes_the_command_lines_names_and_defaults_as_keywords():
    from viewer.cli.commands import build_parser

    sig = inspect.signature(viewer.render)
    params = list(sig.parameters.values())
    assert params[0].name == "scene" and params[0].kind is inspect.Parameter.POSITIONAL_OR_KEYWORD
    assert all(p.kind is inspect.Parameter.KEYWORD_ONLY for p in params[1:])
    defaults = build_parser().parse_args(["render", "-o", "x.png"])
    for name in ("size", "samples", "max_depth", "min_weight", "target_error", "view", "seed"):
        assert sig.parameters[name].default == getattr(defaults, name), name
    assert sig.parameters["adaptive"].default is False
    # a Renderer's render() is the same function of the same keywords
    rsig = inspect.signature(viewer.Renderer.render)
    assert [p.name for p in rsig.parameters.values()][1:] == [p.name for p in params]
    assert all(rsig.parameters[p.name].default == p.default for p in params[1:])


def test_the_errors_are_the_documented_types():
    assert issubclass(viewer.SceneError, ValueError)
    assert issubclass(viewer.ContextError, RuntimeError)


def test_the_package_is_marked_typed():
    assert (Path(viewer.__file__).parent / "py.typed").is_file()


# ---------------------------------------------------------------- scenes

def test_load_scene_takes_a_name_a_path_and_toml_text(tmp_path):
    by_name = viewer.load_scene("default")
    path = Path(by_name.path)
    by_path = viewer.load_scene(path)
    by_text = viewer.load_scene(path.read_text())
    assert by_name == by_path
    # from text there is no file: only the path differs
    assert by_text.path is None and by_text.source == "<TOML text>"
    assert by_text == viewer.Scene(**{**by_name.__dict__, "path": None})
    assert viewer.load_scene() == by_name          # None: the default scene
    assert viewer.builtin_scenes() and "default" in viewer.builtin_scenes()


def test_a_bad_scene_raises_scene_error_naming_the_key_path():
    with pytest.raises(viewer.SceneError, match=r"^<TOML text>: camera\.fov: expected a number in 1\.\.179, got 500$"):
        viewer.load_scene("[camera]\nfov = 500\n")
    with pytest.raises(viewer.SceneError, match="no-such-scene"):
        viewer.load_scene("no-such-scene")


def test_a_scene_changed_in_code_is_validated_with_the_files_messages():
    scene = viewer.load_scene("default")
    scene.camera.fov = 500
    with pytest.raises(viewer.SceneError, match=r"^default: camera\.fov: expected a number in 1\.\.179, got 500$"):
        viewer.validate_scene(scene)
    scene = viewer.load_scene("default")
    name = next(iter(scene.materials))
    scene.materials[name].ior = 0.5
    with pytest.raises(viewer.SceneError, match=rf"materials\.{name}\.ior"):
        viewer.validate_scene(scene)
    scene = viewer.load_scene("default")
    scene.objects[0].material = "nothing-by-this-name"
    with pytest.raises(viewer.SceneError, match=r"objects\[0\]\.material"):
        viewer.validate_scene(scene)
    scene = viewer.load_scene("default")
    scene.camera.position = "up there"
    with pytest.raises(viewer.SceneError, match="camera.position"):
        viewer.validate_scene(scene)


def test_validating_an_unchanged_scene_gives_it_back():
    for name in viewer.builtin_scenes():
        scene = viewer.load_scene(name)
        assert viewer.validate_scene(scene) == scene, name


# ---------------------------------------------------------------- render

def _direct(gl, scene, w=W, h=H, samples=None, seed=0, **over):
    """The renderer underneath, as the command line drove it before the API."""
    r = GPURenderer(gl, with_overrides(scene, samples=samples, **over), eager=False)
    try:
        return r.render(w, h, samples, seed)
    finally:
        r.release()


def test_render_is_the_renderers_image(gl, api_renderer):
    scene = viewer.load_scene("default")
    img = api_renderer.render(scene, size=(W, H), samples=2, seed=3)
    assert isinstance(img, np.ndarray) and img.dtype == np.float32 and img.shape == (H, W, 3)
    gl.__enter__()
    assert np.array_equal(np.asarray(img), _direct(gl, scene, samples=2, seed=3))
    assert img.kind == "color" and img.info["samples"] == 2


def test_render_writes_what_the_command_line_writes(tmp_path, api_renderer):
    from viewer.cli.commands import main

    scene = viewer.load_scene("glass-sphere")
    cases = [
        (["--samples", "2", "--seed", "5"], dict(samples=2, seed=5)),
        (["--adaptive", "--samples", "2", "--target-error", "0.05"], dict(samples=2, adaptive=True,
                                                                          target_error=0.05)),
        (["--view", "normals"], dict(view="normals")),
        (["--view", "samples", "--samples", "2"], dict(view="samples", samples=2, adaptive=True)),
        (["--max-depth", "3", "--min-weight", "0.1"], dict(max_depth=3, min_weight=0.1)),
    ]
    for flags, kw in cases:
        out = tmp_path / "cli.npy"
        assert main(["render", "glass-sphere", "-o", str(out), "--size", f"{W}x{H}", "--backend", "egl",
                     *flags]) == 0
        assert np.array_equal(np.load(out), api_renderer.render(scene, size=(W, H), **kw)), flags


def test_module_level_render_keeps_its_context_and_programs():
    scene = viewer.load_scene("default")
    first = viewer.render(scene, size=(W, H))
    shared = viewer.api._shared
    built = shared._gpu.programs_built
    scene.lights[0].position = (1.0, 5.0, 2.0)          # a new light: the same programs
    second = viewer.render(scene, size=(W, H))
    assert viewer.api._shared is shared and shared._gpu.programs_built == built
    assert not np.array_equal(first, second)


def test_a_renderer_gives_each_scene_the_image_a_fresh_one_gives(api_renderer):
    # scenes of different structure in turn: no state of one reaches the next
    names = ["default", "glass-sphere", "default", "whitted-exact"]
    seen = {}
    for name in names:
        img = api_renderer.render(viewer.load_scene(name), size=(W, H), samples=2)
        if name in seen:
            assert np.array_equal(img, seen[name]), name
        seen[name] = img
    with viewer.Renderer("egl") as fresh:
        assert np.array_equal(fresh.render(viewer.load_scene("whitted-exact"), size=(W, H), samples=2),
                              seen["whitted-exact"])


def test_a_scene_changed_between_frames_is_rendered_as_changed(api_renderer):
    scene = viewer.load_scene("default")
    before = api_renderer.render(scene, size=(W, H))
    scene.camera.fov = 20.0
    after = api_renderer.render(scene, size=(W, H))
    assert np.array_equal(after, api_renderer.render(copy.deepcopy(scene), size=(W, H)))
    assert not np.array_equal(before, after)


def test_bad_options_are_refused_before_any_rendering(api_renderer):
    scene = viewer.load_scene("default")
    for kw, says in [
        (dict(size=(0, 10)), "size width"), (dict(size="big"), "size"), (dict(samples=0), "samples"),
        (dict(max_depth=65), "max_depth"), (dict(min_weight=2.0), "min_weight"), (dict(seed=-1), "seed"),
        (dict(view="x-ray"), "view"), (dict(view="samples"), "adaptive=True"),
        (dict(target_error=0.1), "adaptive=True"), (dict(view="depth", adaptive=True), "adaptive"),
        (dict(target_error=0.0, adaptive=True), "target_error"),
    ]:
        with pytest.raises(ValueError, match=says):
            api_renderer.render(scene, **kw)
    with pytest.raises(TypeError, match="viewer.Scene"):
        api_renderer.render("default")


def test_no_context_raises_context_error_with_the_reason(monkeypatch):
    with pytest.raises(viewer.ContextError, match="unknown OpenGL backend 'metal'"):
        viewer.Renderer("metal")

    def refuse(backend):
        raise viewer.ContextError("no offscreen OpenGL 3.3 context could be created (tried EGL, then OSMesa)")

    monkeypatch.setattr(viewer.api, "create_offscreen_context", refuse)
    monkeypatch.setattr(viewer.api, "_shared", None)
    with pytest.raises(viewer.ContextError, match="tried EGL"):
        viewer.render(viewer.load_scene("default"), size=(8, 8))


def test_a_closed_renderer_refuses_and_its_frames_too():
    with viewer.Renderer("egl") as r:
        draw = r.prepare(viewer.load_scene("default"), size=(8, 8))
        assert draw().shape == (8, 8, 3)
    assert r.closed and r.context is None and r._gpu is None
    r.close()                                           # again: nothing
    with pytest.raises(RuntimeError, match="closed"):
        r.render(viewer.load_scene("default"), size=(8, 8))
    with pytest.raises(RuntimeError, match="closed"):
        draw()


# ---------------------------------------------------------------- images

def test_to_srgb8_is_the_srgb_curve():
    lin = np.array([[[0.0, 1.0, 0.5], [-1.0, 7.0, 0.0031308], [0.2, 0.04, 1e-4]]], np.float32)

    def srgb(x):            # IEC 61966-2-1, independently of the package
        x = min(max(float(x), 0.0), 1.0)
        return 12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055

    want = np.array([[[round(255 * srgb(v)) for v in px] for px in row] for row in lin], np.uint8)
    got = viewer.to_srgb8(lin)
    assert got.dtype == np.uint8 and np.array_equal(got, want)
    assert want[0, 0, 2] == 188 and want[0, 1, 0] == 0 and want[0, 1, 1] == 255
    with pytest.raises(ValueError, match=r"shape \(H, W, 3\)"):
        viewer.to_srgb8(np.zeros((4, 4)))


def test_save_image_writes_the_command_lines_files(tmp_path, api_renderer):
    from viewer.cli.commands import main

    scene = viewer.load_scene("default")
    for view in ("color", "depth"):
        img = api_renderer.render(scene, size=(W, H), view=view)
        for ext in (".png", ".npy", ".pfm"):
            mine, theirs = tmp_path / f"api{ext}", tmp_path / f"cli{ext}"
            viewer.save_image(img, mine)
            assert main(["render", "-o", str(theirs), "--size", f"{W}x{H}", "--view", view,
                         "--backend", "egl"]) == 0
            assert mine.read_bytes() == theirs.read_bytes(), (view, ext)
        png = PILImage.open(tmp_path / "api.png")
        # a debug view's picture adds its 16-row legend below the image
        assert png.size == (W, H + (16 if view == "depth" else 0)) and png.mode == "RGB"
        assert np.array_equal(np.load(tmp_path / "api.npy"), np.asarray(img))


def test_save_image_refuses_bad_input_and_keeps_the_file(tmp_path):
    old = tmp_path / "keep.png"
    old.write_bytes(b"precious")
    with pytest.raises(ValueError, match="shape"):
        viewer.save_image(np.zeros((2, 3)), old)
    with pytest.raises(ValueError, match="unknown output extension '.jpg'"):
        viewer.save_image(np.zeros((2, 3, 3)), tmp_path / "x.jpg")
    with pytest.raises(OSError):
        viewer.save_image(np.zeros((2, 3, 3)), tmp_path / "missing" / "x.png")
    assert old.read_bytes() == b"precious" and sorted(p.name for p in tmp_path.iterdir()) == ["keep.png"]


def test_an_image_displays_itself_as_its_png(api_renderer):
    img = api_renderer.render(viewer.load_scene("default"), size=(W, H))
    shown = np.asarray(PILImage.open(io.BytesIO(img._repr_png_())).convert("RGB"))
    assert np.array_equal(shown, viewer.to_srgb8(img))
    # an array computed from it displays too, and is still the same numbers
    assert np.array_equal(np.asarray(img * 0.5), np.asarray(img) * np.float32(0.5))


# ---------------------------------------------------------------- examples

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.mark.parametrize("script", ["light_sweep.py", "compare_materials.py"])
def test_the_examples_run(tmp_path, script, gl):
    r = subprocess.run([sys.executable, str(EXAMPLES / script), "--size", "32x18", "--out", str(tmp_path)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    pngs = sorted(tmp_path.glob("*.png"))
    assert pngs, r.stdout
    for p in pngs:
        assert PILImage.open(p).size == (32, 18), p
