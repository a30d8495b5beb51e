"""The scene examples a user reads, loaded as a user would load them.

tests/test_readme_audit.py checks that the commands shown parse and the
links resolve; this file checks the TOML the README and docs/scene-format.md
show, and the README's table of built-in scenes:

- every ``toml`` block of README.md and docs/scene-format.md passes
  ``glassray check`` (exit 0, one line on stdout);
- the README's "minimal scene" is what its text says: one red ball and one
  point light, everything else the spec's defaults (typed here from the
  spec's tables, not read from the program);
- the spec's example is the default scene with an upright rod and no ball
  ("This example's rod stands upright; the default scene leans it with
  `rotate`"), its liquid slightly wider than the inside of its glass and
  listed after it, as the format's text says a liquid is modelled;
- the README's table of built-in scenes names exactly the scenes shipped,
  and the counts it states (objects, glass, mirrors, lights) hold.

No rendering: the whole file runs in about a second.  Each check is a
function of the text, and the ``*_catches_*`` tests feed it a broken text
to see it fail.
"""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

from viewer.cli import main
from viewer.scene import builtin_scene_names, load_scene

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
SCENE_FORMAT = ROOT / "docs" / "scene-format.md"


def toml_blocks(text: str) -> list[str]:
    """The bodies of the fenced ``toml`` blocks of a markdown text."""
    return re.findall(r"^```toml[ \t]*\n(.*?)^```[ \t]*$", text, flags=re.S | re.M)


def check(path: Path) -> tuple[int, str, str]:
    """`glassray check PATH` in this process: (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(["check", str(path)])
    return rc, out.getvalue(), err.getvalue()


def _snippets() -> list[tuple[str, int, str]]:
    out = []
    for doc in (README, SCENE_FORMAT):
        for i, body in enumerate(toml_blocks(doc.read_text(encoding="utf-8"))):
            out.append((doc.relative_to(ROOT).as_posix(), i, body))
    return out


# ---------------------------------------------------------------- every snippet loads


def test_the_extraction_finds_the_snippets():
    found = {}
    for doc, _i, _body in _snippets():
        found[doc] = found.get(doc, 0) + 1
    # the README's minimal scene; the spec's full example
    assert found.get("README.md", 0) >= 1 and found.get("docs/scene-format.md", 0) >= 1, found


@pytest.mark.parametrize("doc,index,body", _snippets(), ids=lambda v: str(v)[:30] if isinstance(v, str) else str(v))
def test_every_toml_snippet_passes_glassray_check(tmp_path, doc, index, body):
    path = tmp_path / f"snippet-{index}.toml"
    path.write_text(body, encoding="utf-8")
    rc, out, err = check(path)
    assert rc == 0, f"{doc}, toml block {index}: glassray check exit {rc}: {err.strip()}"
    assert len(out.splitlines()) == 1 and err == "", (out, err)


def test_the_snippet_check_catches_an_invalid_snippet(tmp_path):
    body = toml_blocks("text\n```toml\n[[objects]]\ntype = \"sphere\"\nradius = -1\n```\n")[0]
    path = tmp_path / "broken.toml"
    path.write_text(body, encoding="utf-8")
    rc, out, err = check(path)
    assert rc == 2 and out == "" and "broken.toml" in err and "objects[0]" in err


# ---------------------------------------------------------------- the README's minimal scene


def readme_minimal_scene(text: str) -> str:
    m = re.search(r"^A minimal scene:\s*\n\s*```toml[ \t]*\n(.*?)^```", text, flags=re.S | re.M)
    assert m, "README: no 'A minimal scene:' toml block"
    return m.group(1)


def minimal_scene_problems(body: str, tmp_path: Path) -> list[str]:
    """What the README says of it: a named scene of one red ball under one
    point light; everything it leaves out takes the spec's defaults."""
    path = tmp_path / "minimal.toml"
    path.write_text(body, encoding="utf-8")
    s = load_scene(path)
    bad = []
    if s.name != "one ball":
        bad.append(f"name {s.name!r}")
    if [(o.type, o.center, o.radius, o.material) for o in s.objects] != [("sphere", (0, 1, 0), 1, "red")]:
        bad.append(f"objects {s.objects}")
    if [(l.type, l.position, l.color, l.intensity) for l in s.lights] != [("point", (2, 5, 3), (1, 1, 1), 1)]:
        bad.append(f"lights {s.lights}")
    red = s.materials.get("red")
    # the spec's material defaults (scene-format.md, [materials.NAME])
    if red is None or (red.color, red.ambient, red.diffuse, red.specular, red.shininess, red.reflectivity,
                       red.transparency, red.ior) != ((0.8, 0.2, 0.1), 0.1, 0.8, 0.0, 32, 0.0, 0.0, 1.0):
        bad.append(f"material red {red}")
    # the spec's defaults for everything the snippet leaves out
    if (s.camera.position, s.camera.target, s.camera.fov) != ((3.2, 2.2, 4.6), (0, 0.9, 0), 40):
        bad.append(f"camera {s.camera}")
    r = s.render
    if (r.max_depth, r.samples, r.min_weight, r.exposure) != (8, 1, 0.001, 1.0):
        bad.append(f"render {r}")
    if (s.sky.type, s.sky.horizon, s.sky.zenith) != ("gradient", (0.8, 0.85, 0.9), (0.25, 0.4, 0.75)):
        bad.append(f"sky {s.sky}")
    if s.ambient != (0.05, 0.05, 0.05):
        bad.append(f"ambient {s.ambient}")
    return bad


def test_the_readme_minimal_scene_is_one_red_ball_under_one_light(tmp_path):
    body = readme_minimal_scene(README.read_text(encoding="utf-8"))
    assert minimal_scene_problems(body, tmp_path) == []


def test_the_minimal_scene_check_catches_a_changed_snippet(tmp_path):
    body = readme_minimal_scene(README.read_text(encoding="utf-8"))
    assert minimal_scene_problems(body.replace("radius = 1", "radius = 2"), tmp_path)
    assert minimal_scene_problems(body.replace('material = "red"', 'material = "red"\n[camera]\nfov = 50'),
                                  tmp_path)


# ---------------------------------------------------------------- the spec's example


def example_problems(body: str, tmp_path: Path) -> list[str]:
    """scene-format.md's example against its text and the shipped default
    scene: the same floor, glass, water, light and camera; an upright rod
    (the default's leans by `rotate`); no ball; the liquid slightly wider
    than the inside of the glass and listed after it."""
    path = tmp_path / "example.toml"
    path.write_text(body, encoding="utf-8")
    ex = load_scene(path)
    default = load_scene(None)
    bad = []
    by_type = {}
    for o in ex.objects:
        by_type.setdefault(o.type, []).append(o)
    boxes, spheres = by_type.get("box", []), by_type.get("sphere", [])
    if len(boxes) != 1 or spheres:
        return [f"expected one box (the rod) and no sphere, got {[o.type for o in ex.objects]}"]
    rod = boxes[0]
    if tuple(rod.rotate) != (0, 0, 0):
        bad.append(f"the example's rod is turned by {rod.rotate}: the text says it stands upright")
    if not (rod.max[1] - rod.min[1]) > 5 * max(rod.max[0] - rod.min[0], rod.max[2] - rod.min[2]):
        bad.append("the example's box is not a rod (tall and thin)")
    default_rod = [o for o in default.objects if o.type == "box"]
    if len(default_rod) != 1 or tuple(default_rod[0].rotate) == (0, 0, 0):
        bad.append("the default scene's rod does not lean by `rotate`")
    if not [o for o in default.objects if o.type == "sphere"]:
        bad.append("the default scene has no ball")
    # the same camera, light, materials (but the ball's) and glass and water
    if ex.camera != default.camera:
        bad.append(f"camera {ex.camera} != the default's {default.camera}")
    if [(l.type, l.position) for l in ex.lights] != [(l.type, l.position) for l in default.lights]:
        bad.append("lights differ from the default's")
    for name, mat in ex.materials.items():
        if default.materials.get(name) != mat:
            bad.append(f"materials.{name} differs from the default's")

    def strip(o):
        return (o.type, o.base, o.radius, o.height, o.wall, o.axis, o.material)

    cylinders = [o for o in ex.objects if o.type == "cylinder"]
    default_cylinders = [o for o in default.objects if o.type == "cylinder"]
    if [strip(o) for o in cylinders] != [strip(o) for o in default_cylinders]:
        bad.append("the glass and water differ from the default's")
    glass = [i for i, o in enumerate(ex.objects) if o.type == "cylinder" and o.wall is not None]
    water = [i for i, o in enumerate(ex.objects) if o.type == "cylinder" and o.wall is None
             and ex.materials[o.material].transparency > 0]
    if len(glass) != 1 or len(water) != 1:
        return bad + ["expected one vessel and one liquid"]
    g, w = ex.objects[glass[0]], ex.objects[water[0]]
    inner = g.radius - g.wall
    if not (water[0] > glass[0] and inner < w.radius < g.radius):
        bad.append(f"the liquid (radius {w.radius}, object {water[0]}) is not slightly wider than the inside "
                   f"({inner}) of the glass (object {glass[0]}) and listed after it")
    if (ex.materials[g.material].ior, ex.materials[w.material].ior) != (1.5, 1.33):
        bad.append("the iors are not the text's 1.5 and 1.33")
    return bad


def test_the_spec_example_is_the_default_scene_with_an_upright_rod(tmp_path):
    blocks = toml_blocks(SCENE_FORMAT.read_text(encoding="utf-8"))
    assert len(blocks) == 1
    assert example_problems(blocks[0], tmp_path) == []


def test_the_example_check_catches_a_leaning_rod_and_a_liquid_listed_first(tmp_path):
    body = toml_blocks(SCENE_FORMAT.read_text(encoding="utf-8"))[0]
    leaning = body.replace('material = "rod"', 'material = "rod"\nrotate = [0, 0, -22]')
    assert any("upright" in p for p in example_problems(leaning, tmp_path))
    # the water's block moved before the glass's
    parts = body.split("[[objects]]")
    swapped = "[[objects]]".join([parts[0], parts[1], parts[3], parts[2], parts[4]])
    assert any("listed after it" in p for p in example_problems(swapped, tmp_path))


# ---------------------------------------------------------------- the README's table of built-in scenes


def readme_scene_table(text: str) -> dict[str, str]:
    lines = text.splitlines()
    i = next(k for k, l in enumerate(lines) if l.strip() == "| name | what it shows |")
    rows = {}
    for l in lines[i + 2:]:
        if not l.startswith("|"):
            break
        m = re.match(r"^\| `([^`]+)` \| (.*) \|$", l.strip())
        assert m, l
        rows[m.group(1)] = m.group(2)
    return rows


def test_the_readme_lists_exactly_the_shipped_scenes():
    assert sorted(readme_scene_table(README.read_text(encoding="utf-8"))) == sorted(builtin_scene_names())


def _count(scene, pred) -> int:
    return sum(1 for o in scene.objects if pred(o, scene.materials[o.material]))


def scene_claim_problems(rows: dict[str, str]) -> list[str]:
    """The counts and kinds the table states, against the shipped scenes."""
    bad = []
    s = load_scene("bench-opaque")
    row = rows["bench-opaque"]
    n = len(s.objects)
    if "ten objects with it" not in row or n != 10 or _count(s, lambda o, m: o.type != "plane") != 9:
        bad.append(f"bench-opaque: {n} objects")
    if _count(s, lambda o, m: m.reflectivity > 0 or m.transparency > 0):
        bad.append("bench-opaque: has reflection or glass")
    s = load_scene("bench-many")
    m43 = re.search(r"(\d+) objects", rows["bench-many"])
    glass = [o for o in s.objects if s.materials[o.material].transparency > 0]
    if not m43 or int(m43.group(1)) != len(s.objects) or "two of them glass spheres" not in rows["bench-many"] \
            or [o.type for o in glass] != ["sphere", "sphere"]:
        bad.append(f"bench-many: {len(s.objects)} objects, glass {[o.type for o in glass]}")
    s = load_scene("mirror-ball")
    if _count(s, lambda o, m: o.type == "sphere" and m.reflectivity > 0) != 1 \
            or _count(s, lambda o, m: o.type == "box") != 2 or [l.type for l in s.lights] != ["directional"]:
        bad.append("mirror-ball: not a mirror ball between two boxes under a directional light")
    s = load_scene("glass-sphere")
    if _count(s, lambda o, m: o.type == "sphere" and m.transparency > 0) != 1 \
            or _count(s, lambda o, m: o.type == "plane" and m.checker is not None) != 1:
        bad.append("glass-sphere: not a glass sphere on a checker")
    s = load_scene("whitted-exact")
    if s.sky.type != "color" or _count(s, lambda o, m: o.type == "sphere" and m.transparency > 0) != 1 \
            or _count(s, lambda o, m: m.checker is not None and any(m.emission)) != 1:
        bad.append("whitted-exact: not a clear sphere over an emissive checker under a constant sky")
    s = load_scene("whitted-glass")
    kinds = sorted(o.type for o in s.objects if s.materials[o.material].transparency > 0)
    if kinds != ["cylinder", "sphere", "sphere"] or s.sky.type != "color":
        bad.append(f"whitted-glass: glass {kinds}")
    s = load_scene("glass-rod-x")
    if _count(s, lambda o, m: o.type == "cylinder" and o.axis == "x" and o.wall is None and m.transparency > 0) != 1:
        bad.append("glass-rod-x: no solid glass cylinder along x")
    s = load_scene("coloured-liquid")
    if _count(s, lambda o, m: m.transparency > 0 and max(m.absorption) > 0) < 1 \
            or _count(s, lambda o, m: o.type == "cylinder" and o.wall is not None) != 1:
        bad.append("coloured-liquid: no glass of absorbing liquid")
    return bad


def test_the_readme_scene_table_describes_the_shipped_scenes():
    assert scene_claim_problems(readme_scene_table(README.read_text(encoding="utf-8"))) == []


def test_the_scene_table_check_catches_a_wrong_count():
    rows = readme_scene_table(README.read_text(encoding="utf-8"))
    rows["bench-many"] = rows["bench-many"].replace("43 objects", "44 objects")
    assert any(p.startswith("bench-many") for p in scene_claim_problems(rows))
