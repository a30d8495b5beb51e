"""The package's floors, read from its source: every import of every module of
``viewer/`` (function-level ones included, and ``importlib.import_module`` of a
literal name) goes down the declared order, never up or sideways, and no
modules import each other in a cycle.

The order, bottom first (docs/design.md draws it):

    base  <  scene  <  reference | gpu  <  adaptive  <  api  <  measure  <  window  <  cli

A module may import its own subpackage and any floor below its own.
``reference`` and ``gpu`` stand side by side: neither imports the other (the
float64 tracer is the GPU's independent check).  ``viewer/__init__.py`` and
``viewer/__main__.py`` are the roof: they may import anything, nothing imports
them (``viewer.base.version`` holds the version).

Each check is a function of {module name: source}, so the ``*_catches_*``
tests feed it a made-up package with one bad import and see it fail.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "viewer"

#: floors, bottom first; a tuple holds floors that stand side by side
ORDER: tuple[tuple[str, ...], ...] = (("base",), ("scene",), ("reference", "gpu"), ("adaptive",), ("api",),
                                      ("measure",), ("window",), ("cli",))
RANK = {name: i for i, names in enumerate(ORDER) for name in names}
ROOF = len(ORDER)


def sources(package: Path = PACKAGE) -> dict[str, str]:
    """{dotted module name: source} of every .py under the package."""
    out = {}
    for f in sorted(package.rglob("*.py")):
        rel = f.relative_to(package.parent).with_suffix("")
        parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
        out[".".join(parts)] = f.read_text(encoding="utf-8")
    return out


def _is_package(name: str, mods: dict[str, str]) -> bool:
    return any(m.startswith(name + ".") for m in mods)


def imports(mods: dict[str, str]) -> dict[str, set[tuple[str, int]]]:
    """{module: {(imported module of the package, line)}}: `import`, `from`
    (relative ones resolved, each name that is a submodule taken as that
    module) and importlib.import_module("literal"), at any depth."""
    out: dict[str, set[tuple[str, int]]] = {}
    top = next(iter(mods)).split(".")[0]
    for name, src in mods.items():
        found = out.setdefault(name, set())
        pkg = name if _is_package(name, mods) or name == top else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(src)):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = pkg.split(".")
                    base = base[:len(base) - (node.level - 1)]
                    stem = ".".join(base + ([node.module] if node.module else []))
                else:
                    stem = node.module or ""
                targets = [stem] + [f"{stem}.{a.name}" for a in node.names]
            elif (isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module"
                  and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
                targets = [node.args[0].value]
            for t in targets:
                # the top package itself runs for any import of the package: only its modules count
                if t in mods and t != name and t != top:
                    found.add((t, node.lineno))
    return out


def floor(module: str) -> str | None:
    """The floor a module stands on: its first subpackage, or the module
    itself for a module at the package's top (viewer.api); None: the roof."""
    parts = module.split(".")
    if len(parts) == 1 or parts[1] in ("__main__",):
        return None
    return parts[1]


def violations(mods: dict[str, str]) -> list[str]:
    """Every import that goes up or sideways against ORDER, and every module
    on no declared floor."""
    bad = []
    for m, targets in imports(mods).items():
        fm = floor(m)
        if fm is not None and fm not in RANK:
            bad.append(f"{m}: on no declared floor (add {fm!r} to ORDER, and to docs/design.md)")
            continue
        for t, line in sorted(targets):
            ft = floor(t)
            if ft is None:
                bad.append(f"{m}:{line} imports the roof {t}")
                continue
            if fm is None or ft == fm or ft not in RANK:
                continue
            if RANK[ft] > RANK[fm]:
                bad.append(f"{m}:{line} imports {t}: {ft} stands above {fm}")
            elif RANK[ft] == RANK[fm]:
                bad.append(f"{m}:{line} imports {t}: {ft} stands beside {fm}, not below")
    return bad


def cycles(mods: dict[str, str]) -> list[list[str]]:
    """The groups of modules that import each other (strongly connected
    components of more than one module, or a module importing itself)."""
    edges = {m: {t for t, _ in ts} for m, ts in imports(mods).items()}
    # a package's __init__ re-exporting its children is not an import of them by anything else
    for m in edges:
        if _is_package(m, mods):
            edges[m] = {t for t in edges[m] if not t.startswith(m + ".")}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in edges:
        if v not in index:
            strong(v)
    return found


# ---------------------------------------------------------------- the package


def test_every_import_goes_down_the_floors():
    bad = violations(sources())
    assert not bad, "imports against the floors:\n" + "\n".join(bad)


def test_no_modules_import_each_other_in_a_cycle():
    found = cycles(sources())
    assert not found, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in found)


def test_every_floor_is_a_subpackage_of_the_listing():
    """The folder listing shows the floors: each one is a subpackage (or,
    for the api, one module) of viewer/."""
    for name in RANK:
        assert (PACKAGE / name / "__init__.py").is_file() or (PACKAGE / f"{name}.py").is_file(), name


# ---------------------------------------------------------------- the checks can fail


def _fake(**files: str) -> dict[str, str]:
    base = {"viewer": "", "viewer.base": "", "viewer.base.files": "", "viewer.gpu": "",
            "viewer.gpu.renderer": "from ..base import files\n", "viewer.reference": "",
            "viewer.reference.trace": "", "viewer.scene": "", "viewer.scene.model": "",
            "viewer.cli": "", "viewer.cli.commands": "from ..gpu import renderer\n"}
    base.update(files)
    return base


def test_the_fake_package_itself_passes():
    assert violations(_fake()) == [] and cycles(_fake()) == []


@pytest.mark.parametrize("module, source, says", [
    ("viewer.scene.model", "from ..gpu.renderer import Renderer\n", "gpu stands above scene"),
    ("viewer.base.files", "def f():\n    from viewer.cli import commands\n", "cli stands above base"),
    ("viewer.gpu.renderer", "from ..reference import trace\n", "reference stands beside gpu"),
    ("viewer.scene.model", "import importlib\nm = importlib.import_module('viewer.gpu.renderer')\n", "gpu stands above scene"),
    ("viewer.gpu.renderer", "from viewer import cli\n", "cli stands above gpu"),
    ("viewer.base.files", "from viewer import something\n", None),
])
def test_the_floor_check_catches_an_upward_or_sideways_import(module, source, says):
    bad = violations(_fake(**{module: source}))
    if says is None:
        assert bad == []               # a name of the top package that is no module is no import
    else:
        assert any(says in b for b in bad), bad


def test_the_floor_check_catches_a_module_on_no_floor():
    assert any("no declared floor" in b for b in violations(_fake(**{"viewer.plugins": "", "viewer.plugins.x": ""})))


def test_the_cycle_check_catches_two_modules_of_one_floor_importing_each_other():
    mods = _fake(**{"viewer.scene.load": "from .model import Scene\n",
                    "viewer.scene.model": "def f():\n    from .load import load_scene\n"})
    assert violations(mods) == []
    assert cycles(mods) == [["viewer.scene.load", "viewer.scene.model"]]
