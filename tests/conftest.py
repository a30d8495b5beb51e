"""Shared fixtures: one EGL context for the session (real rendering on
Mesa's llvmpipe on CI), golden-image options, and small scene builders."""

from __future__ import annotations

import copy
import os
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

GOLDEN_DIR = Path(__file__).parent / "goldens"
FAILURE_DIR = Path(__file__).parent / "_failures"


def pytest_addoption(parser):
    parser.addoption("--update-goldens", action="store_true", default=False,
                     help="rewrite tests/goldens/*.png from the current renderer")


@pytest.fixture(scope="session")
def update_goldens(request) -> bool:
    return request.config.getoption("--update-goldens")


_SESSION: dict = {}


@pytest.fixture(scope="session")
def gl():
    """One EGL context for the whole session."""
    from viewer.gpu.context import create_offscreen_context

    ctx, _backend = create_offscreen_context("egl")
    _SESSION["ctx"] = ctx
    yield ctx
    _SESSION.clear()
    ctx.release()


@pytest.fixture(autouse=True)
def _gl_current():
    """Make the session's context current again before every test: tests of
    contexts and of the benchmark create, switch and release their own."""
    ctx = _SESSION.get("ctx")
    if ctx is not None:
        ctx.__enter__()
    yield


@pytest.fixture
def render(gl):
    """render(scene, w, h, samples=1, seed=0) -> (H, W, 3) float32 linear."""
    from viewer.gpu.renderer import Renderer

    made = []

    def _render(scene, w=96, h=54, samples=1, seed=0):
        r = Renderer(gl, scene, eager=False)    # as `glassray render`: compiles what it draws
        made.append(r)
        return r.render(w, h, samples, seed)

    yield _render
    for r in made:
        r.release()


@pytest.fixture(scope="module")
def api_renderer():
    """A viewer.Renderer (the public API's, an EGL context of its own) for a module."""
    import viewer

    with viewer.Renderer("egl") as r:
        yield r


def make_scene(doc: dict, name: str = "test"):
    from viewer.scene.load import scene_from_dict

    return scene_from_dict(copy.deepcopy(doc), source=f"<{name}>", default_name=name)


def mean_abs(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean(np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))))


def no_matplotlib_env(tmp_path) -> dict:
    """An environment whose `import matplotlib` fails (a stub first on the path)."""
    import os

    stub = tmp_path / "no-mpl" / "matplotlib"
    stub.mkdir(parents=True)
    (stub / "__init__.py").write_text("raise ImportError('No module named matplotlib')\n")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(stub.parent), env.get("PYTHONPATH", "")) if p)
    return env


# ---------------------------------------------------------------- X server


@pytest.fixture(scope="module")
def xdisplay():
    for n in range(90, 190):
        if os.path.exists(f"/tmp/.X{n}-lock") or os.path.exists(f"/tmp/.X11-unix/X{n}"):
            continue
        proc = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline and proc.poll() is None:
            if os.path.exists(f"/tmp/.X11-unix/X{n}"):
                break
            time.sleep(0.05)
        if proc.poll() is None and os.path.exists(f"/tmp/.X11-unix/X{n}"):
            time.sleep(0.2)
            try:
                yield f":{n}"
            finally:
                proc.terminate()
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    proc.kill()
            return
        proc.kill()
        proc.wait()
    pytest.skip("no free X display number for Xvfb")


# ---------------------------------------------------------------- markers

#: Fixtures that mean a test draws with OpenGL (llvmpipe here) or opens a
#: real window on an X server; the markers follow from them, so that
#: `pytest -m "not window"` or `-m "not gl"` selects by what a test needs.
GL_FIXTURES = {"gl", "render", "api_renderer"}
WINDOW_FIXTURES = {"xdisplay"}


def pytest_configure(config):
    config.addinivalue_line("markers", "gl: draws with an OpenGL context (EGL, llvmpipe on a machine without a GPU)")
    config.addinivalue_line("markers", "window: opens a real GLFW window on an Xvfb server (needs Xvfb and xdotool)")


def pytest_collection_modifyitems(config, items):
    for item in items:
        used = set(getattr(item, "fixturenames", ()))
        if used & WINDOW_FIXTURES:
            item.add_marker(pytest.mark.window)
        if used & GL_FIXTURES:
            item.add_marker(pytest.mark.gl)
