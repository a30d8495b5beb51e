"""The wheel a user installs: it carries every shader and built-in scene,
finds them through importlib.resources (not the repository), and renders
the same image as the source tree.  Built offline from a copy of the
sources with the test environment's setuptools (`make venv` installs the
version pyproject.toml's build-system asks for)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent


def _version(text: str) -> tuple[int, ...]:
    return tuple(int(p) for p in re.findall(r"\d+", text)[:3])


def test_build_system_asks_for_a_setuptools_that_reads_the_license_field():
    # `license = "MIT"` (an SPDX expression, PEP 639) is read by setuptools
    # 77 and later; older ones stop with "project.license must be valid
    # exactly by one definition" (measured with 76.1.0 and 77.0.3)
    py = tomllib.loads((ROOT / "pyproject.toml").read_text())
    if not isinstance(py["project"].get("license"), str):
        return
    req = next(r for r in py["build-system"]["requires"] if r.startswith("setuptools"))
    m = re.search(r">=\s*([\d.]+)", req)
    assert m and _version(m.group(1)) >= (77,), req


@pytest.fixture(scope="module")
def wheel_site(tmp_path_factory):
    """The wheel built from a copy of the sources and installed into a folder of its own."""
    import setuptools

    if _version(setuptools.__version__) < (77,):
        pytest.skip(f"setuptools {setuptools.__version__} cannot build this project offline (make venv installs >= 77)")
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    for name in ("viewer", "shaders"):
        shutil.copytree(ROOT / name, src / name, ignore=shutil.ignore_patterns("__pycache__"))
    dist, site = tmp / "dist", tmp / "site"
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    subprocess.run(pip + ["wheel", "--no-deps", "--no-build-isolation", "--no-index", "-w", str(dist), str(src)],
                   check=True, cwd=tmp, capture_output=True, text=True, timeout=300)
    (whl,) = dist.glob("glassray-*.whl")
    subprocess.run(pip + ["install", "--no-deps", "--no-index", "--target", str(site), str(whl)],
                   check=True, cwd=tmp, capture_output=True, text=True, timeout=300)
    return whl, site


def test_wheel_carries_every_shader_and_scene(wheel_site):
    whl, _ = wheel_site
    names = set(zipfile.ZipFile(whl).namelist())
    want = {f"viewer/glsl/{p.relative_to(ROOT / 'shaders').as_posix()}"
            for p in (ROOT / "shaders").rglob("*") if p.is_file() and p.suffix in (".frag", ".vert", ".glsl")}
    want |= {f"viewer/scene/builtin/{p.name}" for p in (ROOT / "viewer" / "scene" / "builtin").iterdir()
             if p.suffix in (".toml", ".png", ".pfm")}
    want |= {f"viewer/{p.relative_to(ROOT / 'viewer').as_posix()}" for p in (ROOT / "viewer").rglob("*.py")}
    assert len(want) > 40
    assert not want - names, sorted(want - names)
    entry = next(n for n in names if n.endswith("entry_points.txt"))
    assert re.search(r"^glassray\s*=", zipfile.ZipFile(whl).read(entry).decode(), re.M)


def test_installed_wheel_renders_what_the_sources_render(wheel_site, tmp_path, gl):
    _, site = wheel_site
    out = tmp_path / "wheel.npy"
    script = f"""
import sys
sys.path.insert(0, {str(site)!r})
import viewer, viewer.gpu.shaders as sh, viewer.scene.load as sc
from pathlib import Path
site = Path({str(site)!r}).resolve()
assert Path(viewer.__file__).resolve().is_relative_to(site), viewer.__file__
root = sh.shader_root().resolve()
assert root.is_relative_to(site) and (root / "render.frag").is_file(), root
print(" ".join(sc.builtin_scene_names()))
from viewer import cli
sys.exit(cli.main(["render", "default", "-o", {str(out)!r}, "--size", "40x24", "--samples", "1"]))
"""
    env = {k: v for k, v in os.environ.items() if k != "GLASSRAY_SHADERS"}
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    from viewer.scene.load import builtin_scene_names

    assert done.stdout.split() == builtin_scene_names()
    mine = tmp_path / "source.npy"
    from viewer.cli import commands as cli

    assert cli.main(["render", "default", "-o", str(mine), "--size", "40x24", "--samples", "1"]) == 0
    assert np.array_equal(np.load(out), np.load(mine))
