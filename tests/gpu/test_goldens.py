"""Golden images of focused scenes (one per primitive, per cylinder axis, the
vessel, TIR, nested media, absorption, shadows through glass) and of the
default scene, 160x90, one centred sample.

Tolerance: an 8-bit display value may differ by at most 2 levels in at most
0.1% of the pixels, and the mean difference stays below 0.1 level.  The
goldens were made on Mesa llvmpipe; another driver's float maths (fused
multiply-add, pow/exp approximations) moves silhouette pixels by a level or
two, which this tolerance allows, while a broken intersection or shading
term changes hundreds of pixels by far more.

The goldens are not trusted on their own: test_reference.py compares the
same scenes against the independent float64 reference tracer.

    pytest tests/test_goldens.py --update-goldens   # rewrite them after a deliberate change
On failure the actual, expected and diff images go to tests/_failures/.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from conftest import FAILURE_DIR, GOLDEN_DIR
from viewer.base.imageio import to_display8
from viewer.scene.load import load_scene, with_overrides

SCENE_DIR = Path(__file__).parents[1] / "scenes"
FOCUSED = sorted(p.stem for p in SCENE_DIR.glob("*.toml"))
SIZE = (160, 90)


def golden_scene(name: str):
    scene = load_scene(SCENE_DIR / f"{name}.toml") if name in FOCUSED else load_scene(name)
    return with_overrides(scene, samples=1)


@pytest.mark.parametrize("name", FOCUSED + ["default"])
def test_golden(render, update_goldens, name):
    img = to_display8(render(golden_scene(name), *SIZE))
    path = GOLDEN_DIR / f"{name}.png"
    if update_goldens:
        GOLDEN_DIR.mkdir(exist_ok=True)
        Image.fromarray(img).save(path)
        return
    assert path.exists(), f"no golden {path}: run pytest --update-goldens"
    gold = np.asarray(Image.open(path).convert("RGB"))
    diff = np.abs(img.astype(np.int16) - gold.astype(np.int16)).max(axis=2)
    bad = float(np.mean(diff > 2))
    if bad > 0.001 or diff.mean() > 0.1:
        FAILURE_DIR.mkdir(exist_ok=True)
        Image.fromarray(img).save(FAILURE_DIR / f"{name}-actual.png")
        Image.fromarray(gold).save(FAILURE_DIR / f"{name}-expected.png")
        Image.fromarray(np.clip(diff * 8, 0, 255).astype(np.uint8)).save(FAILURE_DIR / f"{name}-diff.png")
        pytest.fail(f"{name}: {100 * bad:.2f}% of pixels differ by more than 2 levels "
                    f"(mean {diff.mean():.3f}); images in {FAILURE_DIR}")
