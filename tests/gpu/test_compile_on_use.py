"""`glassray render` compiles only the programs its draws use.

A glass scene's render draws cut-checked variants of the scene's program,
and a multi-sample render of a checkered floor draws footprint variants:
the plain full program is never bound there, and compiling it cost 3.5 s on
llvmpipe (bench-many, cold shader cache) and 15 s on an NVIDIA driver.  The
viewer's renderers stay eager: a shader the driver rejects must fail where
the scene changes, so that the last good one keeps running
(test_render.py's F5 test)."""

from __future__ import annotations

import numpy as np
import pytest

from viewer.cli import commands as cli
from viewer.gpu import renderer as renderer_mod
from viewer.scene.load import load_scene


@pytest.fixture
def compiled_and_bound(monkeypatch):
    """Every program the renderer builds, and every program it binds."""
    built, bound = [], set()
    real_build, real_bind = renderer_mod.build_program, renderer_mod.Renderer.bind

    def build(*a, **k):
        prog = real_build(*a, **k)
        built.append((prog, dict(k.get("defines") or {})))
        return prog

    def bind(self, prog, *a, **k):
        bound.add(id(prog))
        return real_bind(self, prog, *a, **k)

    monkeypatch.setattr(renderer_mod, "build_program", build)
    monkeypatch.setattr(renderer_mod.Renderer, "bind", bind)
    return built, bound


@pytest.mark.parametrize("scene, samples, extra", [
    ("default", 1, []),          # glass: cut-checked culling variants only
    ("whitted-glass", 2, []),    # glass and a checker: cut-checked footprint variants
    ("bench-opaque", 2, []),     # no glass, a checker: footprint variants
    ("bench-opaque", 1, []),     # the plain program, culled: it is drawn, so it is built
    ("default", 2, ["--adaptive"]),
    ("default", 1, ["--view", "normals"]),
    # at 160x90 no group of bench-opaque's tiles meets every object: the
    # full program (plain, or with footprints) is drawn nowhere
    ("bench-opaque", 1, ["--size", "160x90"]),
    ("bench-opaque", 2, ["--size", "160x90"]),
])
def test_render_builds_only_programs_it_draws(tmp_path, compiled_and_bound, scene, samples, extra):
    built, bound = compiled_and_bound
    out = tmp_path / "out.png"
    assert cli.main(["render", scene, "-o", str(out), "--size", "48x27", "--samples", str(samples), *extra]) == 0
    assert out.is_file()
    assert built, "the render built no program at all"
    unused = [d for prog, d in built if id(prog) not in bound]
    assert not unused, f"{len(unused)} of {len(built)} programs built and never drawn with: " + \
        ", ".join(sorted({k for d in unused for k in d if k in ("CUT_CHECK", "FOOTPRINT_AA")}) or ["plain"])


def test_eager_and_on_use_renderers_draw_the_same_image(gl):
    scene = load_scene("default")
    images = []
    for eager in (True, False):
        r = renderer_mod.Renderer(gl, scene, eager=eager)
        try:
            built_at_start = r.programs_built
            images.append(r.render(48, 27, 1))
        finally:
            r.release()
        assert built_at_start == (1 if eager else 0)
    assert np.array_equal(images[0], images[1])
