"""Saving a scene keeps the user's file (viewer/scene/save.py,
scene_file_text): an unedited scene gives back its file byte for byte, an
edit changes only the lines of the values edited (comments, order and
formatting stay), and a scene without a file is written short: defaults
left out, vectors on one line.  Every saved text loads back to the same
scene."""

from __future__ import annotations

import copy
import difflib
from dataclasses import replace
from pathlib import Path

import pytest

from viewer.scene.load import builtin_scene_names, load_scene
from viewer.scene.model import Light, SceneObject
from viewer.scene.save import save_scene, scene_file_text, scene_to_toml


def changed_lines(a: str, b: str) -> list[str]:
    return [ln for ln in difflib.unified_diff(a.splitlines(), b.splitlines(), lineterm="", n=0)
            if ln[:1] in "+-" and ln[:3] not in ("+++", "---")]


def same_scene(a, b) -> bool:
    return replace(a, path=None) == replace(b, path=None)


@pytest.mark.parametrize("name", builtin_scene_names())
def test_an_unedited_scene_gives_back_its_own_text(tmp_path, name):
    scene = load_scene(name)
    out = tmp_path / "copy.toml"
    save_scene(scene, out)
    assert out.read_bytes() == Path(scene.path).read_bytes()


def test_an_edit_changes_only_its_lines(tmp_path):
    scene = load_scene("default")
    original = Path(scene.path).read_text(encoding="utf-8")
    scene.camera.fov = 33.0
    scene.materials["rod"].color = (0.5, 0.25, 0.125)
    out = tmp_path / "edited.toml"
    save_scene(scene, out)
    text = out.read_text(encoding="utf-8")
    diff = changed_lines(original, text)
    assert len(diff) == 4, diff                 # two lines out, two in
    assert {ln[0] for ln in diff} == {"-", "+"}
    assert "+fov = 33.0" in diff and "+color = [0.5, 0.25, 0.125]" in diff
    assert same_scene(load_scene(out), scene)
    # every comment of the file is still there
    comments = [ln for ln in original.splitlines() if ln.lstrip().startswith("#")]
    assert comments and all(c in text.splitlines() for c in comments)


def test_a_comment_after_a_value_stays_with_it(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text('# my scene\nname = "c"\n\n[camera]\nposition = [0, 2, 5]   # eye\nfov = 40  # wide\n')
    scene = load_scene(f)
    scene.camera.fov = 50.0
    scene.camera.position = (1.0, 2.0, 5.0)
    save_scene(scene, f)
    assert f.read_text() == ('# my scene\nname = "c"\n\n[camera]\nposition = [1.0, 2.0, 5.0]   # eye\n'
                             'fov = 50.0  # wide\n')


def test_structural_edits_load_back_to_the_edited_scene(tmp_path):
    scene = load_scene("default")
    scene.lights[0] = Light(type="directional", direction=(0.0, -1.0, 0.5), color=(1.0, 0.9, 0.8))
    scene.lights.append(Light(type="point", position=(-2.0, 3.0, 1.0), intensity=0.5))
    scene.objects.append(SceneObject(type="sphere", material="ball", name="second", center=(1.5, 0.3, 1.5),
                                     radius=0.3))
    scene.materials["floor"].checker = None                   # a sub-table removed
    out = tmp_path / "structure.toml"
    save_scene(scene, out)
    back = load_scene(out)
    assert same_scene(back, scene)
    assert "direction = [0.0, -1.0, 0.5]" in out.read_text()


@pytest.mark.parametrize("name", builtin_scene_names())
def test_a_new_file_leaves_the_defaults_out(tmp_path, name):
    scene = copy.deepcopy(load_scene(name))
    scene.path = None                           # made in code: no file to keep
    out = tmp_path / "new.toml"
    save_scene(scene, out)
    text = out.read_text(encoding="utf-8")
    assert same_scene(load_scene(out), scene)
    # vectors on one line: no line holds a lone number of a list spread out
    assert not [ln for ln in text.splitlines() if ln.strip().rstrip(",").replace(".", "").replace("-", "").isdigit()]
    assert len(text.splitlines()) < len(scene_to_toml(scene).splitlines()) / 2
    assert "fov =" not in text or scene.camera.fov != 40.0


def test_an_unreadable_original_falls_back_to_a_new_file(tmp_path):
    f = tmp_path / "gone.toml"
    f.write_text('name = "gone"\n[camera]\nfov = 30\n')
    scene = load_scene(f)
    f.unlink()
    text = scene_file_text(scene, tmp_path / "again.toml")
    assert text.splitlines()[:1] == ['name = "gone"'] and "fov = 30.0" in text


def test_the_command_line_s_values_are_saved_as_the_file_had_them(tmp_path):
    """`glassray view default --samples 1 --fov 30 --light-position ...`:
    the run looks at the file that way, it does not edit it.  Saved
    unedited, the file comes back byte for byte; a value changed since (the
    panel's samples, an orbit's camera) is an edit and is written."""
    from viewer.scene.load import with_overrides
    from viewer.scene.save import as_the_file_had, overrides_of, overrides_of_file

    from_file = load_scene("default")
    text = Path(from_file.path).read_text()
    loaded = with_overrides(from_file, samples=1, fov=30.0, light_position=(1.0, 5.0, 2.0))
    overrides = overrides_of(loaded, from_file)
    assert set(overrides) == {("render", "samples"), ("camera", "fov"), ("lights", 0, "position")}
    assert overrides_of_file(loaded) == overrides                  # the file read again, alone
    assert overrides_of_file(replace(loaded, path=None)) == {}     # no file: nothing to put back
    assert scene_file_text(as_the_file_had(loaded, overrides)) == text
    assert scene_file_text(loaded) != text                       # what it would write without
    edited = copy.deepcopy(loaded)
    edited.render.samples = 4
    edited.camera.position = (3.0, 2.0, 5.0)
    saved = as_the_file_had(edited, overrides)
    assert (saved.render.samples, saved.camera.fov, saved.camera.position) == (4, from_file.camera.fov, (3.0, 2.0, 5.0))
    assert saved.lights[0].position == from_file.lights[0].position
    assert edited.render.samples == 4 and edited.camera.fov == 30.0  # the viewer's own scene is left alone
    # a file without the overrides' light (a light removed since): no error
    gone = copy.deepcopy(loaded)
    gone.lights = []
    assert as_the_file_had(gone, overrides).lights == []
