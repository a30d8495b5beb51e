"""What keys the two caches of measurements (the bench's reference images,
the --max-error measurements) is the content of the package's code that
decides their values, declared as parts of the package (folders walked,
globs of files) and read from the installed files (viewer/measure/digests.py).
These tests hold the declared parts to the import graph: every module of
the package that the measuring code imports, at any depth, is inside them,
so that a module split off, added or moved cannot fall out of the key."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from test_layers import PACKAGE, imports, sources
from viewer.measure import digests, quality_cache, reference_cache

GRAPH = imports(sources())

#: modules the measuring code imports that decide no measured value, and why
DECIDE_NOTHING = {
    "viewer.measure.digests": "computes the keys themselves",
    "viewer.measure.outputs": "writes the finished files",
    "viewer.base.version": "the version printed in reports (base/ is in every key anyway)",
}


def closure(*modules: str) -> set[str]:
    """The modules of the package that `modules` import, at any depth, and
    themselves."""
    seen: set[str] = set()
    todo = list(modules)
    while todo:
        m = todo.pop()
        if m not in seen:
            seen.add(m)
            todo.extend(t for t, _line in GRAPH[m])
    return seen


def covered(parts: tuple[str, ...]) -> set[str]:
    """The dotted names of the modules inside `parts`."""
    out = set()
    for f in digests.code_files(parts, PACKAGE):
        rel = f.relative_to(PACKAGE.parent).with_suffix("")
        out.add(".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts))
    return out


def uncovered(parts: tuple[str, ...], *entries: str, also_exempt: tuple[str, ...] = ()) -> list[str]:
    return sorted(m for m in closure(*entries) - covered(parts)
                  if m not in DECIDE_NOTHING and not m.startswith(also_exempt))


def test_the_max_error_key_holds_every_module_the_measurement_imports():
    assert uncovered(quality_cache.MEASURED_CODE, "viewer.measure.quality_measure",
                     "viewer.measure.quality_cache") == []


def test_the_float64_reference_key_holds_every_module_the_tracer_imports():
    # the GPU fallback's modules are imported too; FALLBACK_CODE keys them
    assert uncovered(reference_cache.REFERENCE_CODE, "viewer.reference.trace",
                     "viewer.measure.reference_cache", also_exempt=("viewer.gpu", "viewer.adaptive")) == []


def test_the_gpu_fallback_reference_key_holds_every_module_it_imports():
    assert uncovered(reference_cache.FALLBACK_CODE, "viewer.measure.reference_cache",
                     also_exempt=("viewer.reference",)) == []


def test_the_check_sees_a_module_left_out():
    """Without its gpu/ part the --max-error key would miss the renderer."""
    parts = tuple(p for p in quality_cache.MEASURED_CODE if p != "gpu")
    assert "viewer.gpu.renderer" in uncovered(parts, "viewer.measure.quality_measure")


@pytest.fixture
def package_copy(tmp_path) -> Path:
    copy = tmp_path / "elsewhere" / "viewer"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    return copy


PARTS = [("max-error", quality_cache.MEASURED_CODE), ("reference", reference_cache.REFERENCE_CODE),
         ("fallback", reference_cache.FALLBACK_CODE)]


@pytest.mark.parametrize("what,parts", PARTS, ids=[p[0] for p in PARTS])
def test_a_key_is_the_packages_content_wherever_it_is_installed(package_copy, what, parts):
    assert digests.code_digest(parts, package_copy) == digests.code_digest(parts)


@pytest.mark.parametrize("what,parts", PARTS, ids=[p[0] for p in PARTS])
def test_an_edit_a_new_module_or_a_move_inside_the_parts_changes_the_key(package_copy, what, parts):
    before = digests.code_digest(parts, package_copy)
    files = digests.code_files(parts, package_copy)
    changed = set()
    for f in (files[0], files[-1]):           # an edit of any file counts
        original = f.read_text(encoding="utf-8")
        f.write_text(original + "\n# an edit\n", encoding="utf-8")
        changed.add(digests.code_digest(parts, package_copy))
        f.write_text(original, encoding="utf-8")
    folder = package_copy / "scene"           # a folder in every key
    new = folder / "split_off.py"
    new.write_text("X = 1\n", encoding="utf-8")
    changed.add(digests.code_digest(parts, package_copy))
    new.rename(folder.parent / "base" / "split_off.py")   # the same code, moved to another part
    changed.add(digests.code_digest(parts, package_copy))
    assert before not in changed and len(changed) == 4


def test_an_edit_of_the_window_keeps_the_max_error_key(package_copy):
    before = digests.code_digest(quality_cache.MEASURED_CODE, package_copy)
    app = package_copy / "window" / "app.py"
    app.write_text(app.read_text(encoding="utf-8") + "\n# an edit\n", encoding="utf-8")
    assert digests.code_digest(quality_cache.MEASURED_CODE, package_copy) == before
