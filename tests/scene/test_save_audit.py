"""Audit of writing scenes back out (viewer.scene.save_scene and the panel's
"Save scene"): load -> save -> load gives the same scene (and the same
render), and the saved file is a valid scene file by the spec."""

from __future__ import annotations

import math
import os
import shutil
import stat
import struct
import tempfile
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from viewer.scene.model import SceneError
from viewer.scene.load import builtin_scene_names, load_scene, scene_from_dict
from viewer.scene.save import save_scene, scene_to_toml

TEST_SCENES = sorted((Path(__file__).parents[1] / "scenes").glob("*.toml"))

AWKWARD = ['q"uote', "back\\slash", "ünïcödé ☃", "ctl\x01\x7f\n\t\r\x1b", "sp ace", "d.o.t", " ", "true",
           "inf", "nan", "1", "-", "\u2028", "", "[x]", "# not a comment", "'single'", "a=b"]
FLOATS = [0.1, 1e-300, 5e-324, -0.0, 1e308, 1 / 3, 2.5e-8, 123456789.123456789, 40.0, 7.0]


def _bits(x: float) -> bytes:
    return struct.pack("<d", x)


def _write(folder: Path, doc: dict, name: str = "in.toml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / name
    p.write_text(tomli_w.dumps(doc), encoding="utf-8")
    return p


def _same(a, b) -> bool:
    """Equal scenes wherever they came from, material order included."""
    return replace(a, path=None) == replace(b, path=None) and list(a.materials) == list(b.materials)


# --------------------------------------------------------------------------- random scenes


def _num(rng, lo=None, hi=None) -> float:
    if rng.random() < 0.3:
        pick = [x for x in FLOATS if (lo is None or x >= lo) and (hi is None or x <= hi)]
        return float(pick[rng.integers(len(pick))])
    return float(rng.uniform(-5 if lo is None else lo, 5 if hi is None else hi))


def _v3(rng, lo=None):
    return [_num(rng, lo) for _ in range(3)]


def _random_doc(rng) -> dict:
    d: dict = {}
    if rng.random() < 0.5:
        d["name"] = AWKWARD[rng.integers(len(AWKWARD))]
    if rng.random() < 0.5:
        d["ambient"] = _v3(rng, 0.0)
    if rng.random() < 0.5:
        d["camera"] = {"position": [_num(rng), 2.5, _num(rng)], "target": [_num(rng), -1.0, _num(rng)],
                       "fov": _num(rng, 1, 179)}
    if rng.random() < 0.5:
        d["render"] = {"max_depth": int(rng.integers(1, 65)), "samples": int(rng.integers(1, 65537)),
                       "min_weight": _num(rng, 0, 1), "exposure": _num(rng, 1e-3, 10)}
    if rng.random() < 0.5:
        d["sky"] = {"type": ["color", "gradient"][rng.integers(2)], "color": _v3(rng, 0.0)}
        if rng.random() < 0.5:
            d["sky"]["horizon"] = _v3(rng, 0.0)
    mats: dict = {}
    for i in range(rng.integers(0, 5)):
        m: dict = {}
        for k in ("ambient", "diffuse", "specular"):
            if rng.random() < 0.5:
                m[k] = _num(rng, 0.0)
        if rng.random() < 0.5:
            m["shininess"] = _num(rng, 1.0)
        if rng.random() < 0.5:
            m["transparency"] = _num(rng, 0.0, 1.0)
        elif rng.random() < 0.5:
            m["reflectivity"] = _num(rng, 0.0, 1.0)
        if rng.random() < 0.5:
            m["ior"] = _num(rng, 1.0)
        for k in ("color", "absorption", "emission"):
            if rng.random() < 0.5:
                m[k] = _v3(rng, 0.0)
        if rng.random() < 0.4:
            m["checker"] = {"color": _v3(rng, 0.0), "size": _num(rng, 1e-3, 3)}
            if rng.random() < 0.5:
                m["checker"]["emission"] = _v3(rng, 0.0)
        mats[AWKWARD[rng.integers(len(AWKWARD))] + ("" if rng.random() < 0.5 else str(i))] = m
    if mats:
        d["materials"] = mats
    lights = []
    for _ in range(rng.integers(0, 4)):
        if rng.random() < 0.5:
            lt = {"position": _v3(rng)}
            if rng.random() < 0.5:
                lt["type"] = "point"
        else:
            lt = {"type": "directional", "direction": [1.0, _num(rng), _num(rng)]}
        if rng.random() < 0.5:
            lt["color"] = _v3(rng, 0.0)
        if rng.random() < 0.5:
            lt["intensity"] = _num(rng, 0.0)
        lights.append(lt)
    if lights:
        d["lights"] = lights
    objs, used = [], set()
    for _ in range(rng.integers(0, 6) if mats else 0):
        t = ["plane", "sphere", "box", "cylinder"][rng.integers(4)]
        o = {"type": t, "material": list(mats)[rng.integers(len(mats))]}
        name = AWKWARD[rng.integers(len(AWKWARD))]
        if rng.random() < 0.5 and name not in used:
            used.add(name)
            o["name"] = name
        if t == "plane":
            if rng.random() < 0.5:
                o["height"] = _num(rng)
        elif t == "sphere":
            o.update(center=_v3(rng), radius=_num(rng, 1e-3, 3))
        elif t == "box":
            lo = [float(x) for x in rng.uniform(-3, 0, 3)]
            o.update(min=lo, max=[x + _num(rng, 0.01, 2) for x in lo])
            if rng.random() < 0.5:
                o["rotate"] = _v3(rng)
        else:
            o.update(base=_v3(rng), radius=_num(rng, 0.1, 2), height=_num(rng, 0.1, 2))
            if rng.random() < 0.5:
                o["axis"] = "xyz"[rng.integers(3)]
            if rng.random() < 0.5:
                o["wall"] = 0.05
        objs.append(o)
    if objs:
        d["objects"] = objs
    return d


def test_random_scenes_round_trip_in_place_and_elsewhere(tmp_path):
    rng = np.random.default_rng(20261204)
    tried = 0
    for i in range(150):
        doc = _random_doc(rng)
        src = _write(tmp_path / "a", doc, "src.toml")
        s = load_scene(src)          # every generated scene is valid
        tried += 1
        for dst in (src, tmp_path / "b" / "src.toml"):
            dst.parent.mkdir(exist_ok=True)
            save_scene(s, dst)
            back = load_scene(dst)
            assert _same(back, s), (i, doc)
            # -0.0 == 0.0: compare the floats of the file bit for bit too
            assert _float_bits(tomllib.loads(dst.read_text("utf-8"))) >= _float_bits(doc), (i, doc)
    assert tried == 150


def _float_bits(doc) -> set:
    """(key path, bits) of every float in a document."""
    out = set()

    def walk(v, path):
        if isinstance(v, dict):
            for k, x in v.items():
                walk(x, path + (k,))
        elif isinstance(v, list):
            for i, x in enumerate(v):
                walk(x, path + (i,))
        elif isinstance(v, float):
            out.add((path, _bits(v)))
    walk(doc, ())
    return out


def test_floats_and_ints_are_written_exactly(tmp_path):
    doc = {"ambient": [0.1, 1e-300, 5e-324], "camera": {"position": [-0.0, 1.0, 1e308], "target": [0, -1, -1e308],
                                                       "fov": 40},
           "render": {"max_depth": 64, "samples": 65536, "min_weight": 5e-324, "exposure": 1e-300}}
    s = load_scene(_write(tmp_path, doc))
    out = tmp_path / "out.toml"
    save_scene(s, out)
    data = tomllib.loads(out.read_text("utf-8"))
    assert [_bits(x) for x in data["ambient"]] == [_bits(0.1), _bits(1e-300), _bits(5e-324)]
    assert [_bits(x) for x in data["camera"]["position"]] == [_bits(-0.0), _bits(1.0), _bits(1e308)]
    assert data["camera"]["fov"] == 40.0
    # ints stay TOML integers where the spec requires one
    assert type(data["render"]["max_depth"]) is int and data["render"]["max_depth"] == 64
    assert type(data["render"]["samples"]) is int and data["render"]["samples"] == 65536
    assert _bits(data["render"]["min_weight"]) == _bits(5e-324)
    assert math.copysign(1.0, load_scene(out).camera.position[0]) == -1.0


@pytest.mark.parametrize("name", AWKWARD)
def test_awkward_names_round_trip(tmp_path, name):
    doc = {"name": name, "materials": {name: {"color": [0.5, 0.5, 0.5]}, "x": {}},
           "objects": [{"type": "sphere", "name": name, "center": [0, 0, 0], "radius": 1, "material": name},
                       {"type": "plane", "material": "x", "name": name + "2"}]}
    s = load_scene(_write(tmp_path, doc))
    out = tmp_path / "out.toml"
    save_scene(s, out)
    back = load_scene(out)
    assert back.name == name
    assert list(back.materials) == [name, "x"]
    assert [o.name for o in back.objects] == [name, name + "2"]
    assert back.objects[0].material == name
    assert _same(back, s)


# --------------------------------------------------------------------------- shipped scenes


@pytest.mark.parametrize("spec", builtin_scene_names() + [str(p) for p in TEST_SCENES])
def test_shipped_scenes_round_trip_elsewhere(tmp_path, spec):
    s = load_scene(spec)
    out = tmp_path / "sub dir ü" / "copy.toml"
    out.parent.mkdir()
    save_scene(s, out)
    assert _same(load_scene(out), s)
    save_scene(load_scene(out), tmp_path / "again.toml")   # and saving the copy gives the same text
    assert (tmp_path / "again.toml").read_text("utf-8") == out.read_text("utf-8")


@pytest.mark.parametrize("spec", ["default", "coloured-liquid", TEST_SCENES[0]])
def test_saved_scene_renders_bit_identically(tmp_path, render, spec):
    s = load_scene(spec)
    out = tmp_path / "copy.toml"
    save_scene(s, out)
    a = render(s, 32, 18)
    b = render(load_scene(out), 32, 18)
    assert np.array_equal(a, b)
    assert a.std() > 0  # a picture, not a blank


# --------------------------------------------------------------------------- the name


def test_a_name_from_the_file_stem_follows_the_saved_file(tmp_path):
    """No `name` in the file: it is the file stem ("my-scene").  Saved under
    another file name the copy is titled by its own stem, as the original was
    (the spec's default); saved in place, the file still has no `name`."""
    src = _write(tmp_path, {"objects": [{"type": "plane", "material": "m"}], "materials": {"m": {}}},
                 "my-scene.toml")
    s = load_scene(src)
    assert s.name == "my-scene"
    save_scene(s, tmp_path / "brighter.toml")
    assert "name" not in tomllib.loads((tmp_path / "brighter.toml").read_text("utf-8"))
    assert load_scene(tmp_path / "brighter.toml").name == "brighter"
    save_scene(s, src)
    assert "name" not in tomllib.loads(src.read_text("utf-8"))
    assert _same(load_scene(src), s)
    # a name written in the file stays, whatever the file is called
    named = _write(tmp_path, {"name": "Kept"}, "named.toml")
    save_scene(load_scene(named), tmp_path / "other.toml")
    assert load_scene(tmp_path / "other.toml").name == "Kept"
    # and a scene named like its file, explicitly, keeps the name too
    same = _write(tmp_path, {"name": "same"}, "same.toml")
    save_scene(load_scene(same), tmp_path / "renamed.toml")
    assert load_scene(tmp_path / "renamed.toml").name == "same"


# --------------------------------------------------------------------------- the sky image


def _pfm(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"PF\n2 1\n-1.0\n" + struct.pack("<6f", 0.2, 0.4, 0.8, 1.0, 0.5, 0.25))
    return path


def test_relative_sky_image_stays_relative_and_points_at_the_same_picture(tmp_path):
    proj = tmp_path / "prøject ☃"
    pic = _pfm(proj / "skies" / "ciel é.pfm")
    src = _write(proj, {"sky": {"type": "image", "image": "skies/ciel é.pfm"}}, "scene.toml")
    s = load_scene(src)
    # saved in place: unchanged, and the same scene
    save_scene(s, src)
    assert tomllib.loads(src.read_text("utf-8"))["sky"]["image"] == "skies/ciel é.pfm"
    assert _same(load_scene(src), s)
    # saved into another folder: a relative path from there to the same picture
    for dst in (tmp_path / "elsewhere" / "deeper" / "moved.toml", proj / "skies" / "inner.toml"):
        dst.parent.mkdir(parents=True, exist_ok=True)
        save_scene(s, dst)
        written = tomllib.loads(dst.read_text("utf-8"))["sky"]["image"]
        assert not Path(written).is_absolute()
        assert (dst.parent / written).resolve() == pic.resolve()
        assert load_scene(dst).sky.image_path.resolve() == pic.resolve()
    # the project folder moved as a whole: the saved scene still finds its sky
    moved = tmp_path / "moved project"
    shutil.copytree(proj, moved)
    shutil.rmtree(proj)
    assert load_scene(moved / "scene.toml").sky.image_path.resolve() == (moved / "skies" / "ciel é.pfm").resolve()


def test_absolute_sky_image_stays_absolute(tmp_path):
    pic = _pfm(tmp_path / "pics" / "sky.pfm")
    s = load_scene(_write(tmp_path / "a", {"name": "abs", "sky": {"type": "image", "image": str(pic)}}))
    (tmp_path / "b").mkdir()
    save_scene(s, tmp_path / "b" / "c.toml")
    assert tomllib.loads((tmp_path / "b" / "c.toml").read_text("utf-8"))["sky"]["image"] == str(pic)
    assert _same(load_scene(tmp_path / "b" / "c.toml"), s)


def test_image_sky_saved_elsewhere_renders_the_same(tmp_path, render):
    _pfm(tmp_path / "src" / "sky.pfm")
    s = load_scene(_write(tmp_path / "src", {"sky": {"type": "image", "image": "sky.pfm"},
                                             "camera": {"fov": 120}}))
    out = tmp_path / "dst" / "x.toml"
    out.parent.mkdir()
    save_scene(s, out)
    assert np.array_equal(render(s, 32, 18), render(load_scene(out), 32, 18))


# --------------------------------------------------------------------------- optional keys, empty scenes


def test_optional_keys_keep_their_meaning(tmp_path):
    doc = {"name": "opt", "materials": {"m": {"emission": [0.5, 0.25, 0.0],
                               "checker": {"color": [0, 0, 0], "size": 0.5}},
                         "n": {"checker": {"color": [1, 1, 1], "size": 1, "emission": [0, 0, 0]}}},
           "lights": [{"position": [1, 2, 3]}, {"type": "directional", "direction": [0, -1, 0.5],
                                                "color": [2, 2, 2], "intensity": 0}],
           "objects": [{"type": "box", "min": [0, 0, 0], "max": [1, 1, 1], "material": "m"},
                       {"type": "cylinder", "base": [0, 0, 0], "radius": 1, "height": 1, "material": "n"},
                       {"type": "cylinder", "base": [0, 0, 0], "radius": 1, "height": 1, "wall": 0.1,
                        "axis": "z", "material": "n"}]}
    s = load_scene(_write(tmp_path, doc))
    out = tmp_path / "out.toml"
    save_scene(s, out)
    data = tomllib.loads(out.read_text("utf-8"))
    # checker.emission absent stays absent (it follows the material's emission)
    assert "emission" not in data["materials"]["m"]["checker"]
    assert data["materials"]["n"]["checker"]["emission"] == [0, 0, 0]
    assert "wall" not in data["objects"][1] and data["objects"][2]["wall"] == 0.1
    # (the file as written is kept: a light without `type` is a point light, and stays without it)
    assert data["lights"][0].get("type", "point") == "point" and "direction" not in data["lights"][0]
    assert data["lights"][1]["type"] == "directional" and "position" not in data["lights"][1]
    back = load_scene(out)
    assert back.materials["m"].checker.emission is None
    assert back.lights[1].intensity == 0.0 and back.lights[1].direction == (0.0, -1.0, 0.5)
    assert back.objects[0].rotate == (0.0, 0.0, 0.0) and back.objects[1].axis == "y"
    assert _same(back, s)


def test_an_empty_scene_round_trips_to_the_spec_defaults(tmp_path):
    s = load_scene(_write(tmp_path, {}, "empty.toml"))
    out = tmp_path / "empty.toml"
    save_scene(s, out)
    back = load_scene(out)
    assert (back.lights, back.materials, back.objects) == ([], {}, [])
    assert back.camera.position == (3.2, 2.2, 4.6) and back.camera.target == (0.0, 0.9, 0.0)
    assert back.camera.fov == 40.0
    assert (back.render.max_depth, back.render.samples, back.render.min_weight, back.render.exposure) == \
        (8, 1, 0.001, 1.0)
    assert back.sky.type == "gradient" and back.ambient == (0.05, 0.05, 0.05)
    assert _same(back, s)


def test_saved_text_is_a_valid_scene_document():
    # every key the writer uses is a key of the spec (scene_from_dict rejects unknown keys)
    for name in builtin_scene_names():
        data = tomllib.loads(scene_to_toml(load_scene(name)))
        scene_from_dict(data)


# --------------------------------------------------------------------------- failures


def _as_nobody(fn) -> int:
    """Run fn() in a child process as an unprivileged user (root may write
    anything); its return value is the exit status."""
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        code = 99
        try:
            if os.geteuid() == 0:
                os.setgid(65534)
                os.setuid(65534)
            code = fn()
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status)


def test_a_read_only_file_is_not_replaced(tmp_path):
    """A rename replaces a file whatever its mode: a scene the user made
    read-only was silently overwritten (a plain open() would refuse)."""
    folder = Path(tempfile.mkdtemp(prefix="save-audit-"))
    try:
        os.chmod(folder, 0o777)
        target = folder / "ro.toml"
        target.write_bytes(b'name = "precious"\n')
        os.chmod(target, 0o444)
        scene = load_scene(None)

        def child() -> int:
            try:
                save_scene(scene, target)
            except PermissionError:
                return 0
            except Exception:
                return 2
            return 1

        assert _as_nobody(child) == 0
        assert target.read_bytes() == b'name = "precious"\n'
        assert sorted(os.listdir(folder)) == ["ro.toml"]
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def test_read_only_folder_fails_cleanly(tmp_path):
    folder = Path(tempfile.mkdtemp(prefix="save-audit-"))
    try:
        os.chmod(folder, 0o555)
        scene = load_scene(None)

        def child() -> int:
            try:
                save_scene(scene, folder / "s.toml")
            except PermissionError:
                return 0
            return 1

        assert _as_nobody(child) == 0
        assert os.listdir(folder) == []
    finally:
        os.chmod(folder, 0o755)
        shutil.rmtree(folder, ignore_errors=True)


def test_a_file_system_that_refuses_chmod_still_saves(tmp_path, monkeypatch):
    """FAT or a network mount may refuse chmod (EPERM): a plain open() for
    writing works there, so a save must too (and leak no descriptor)."""
    def no_chmod(*a, **k):
        raise PermissionError(1, "Operation not permitted")

    scene = load_scene("default")
    fds = len(os.listdir("/proc/self/fd"))
    monkeypatch.setattr(os, "chmod", no_chmod)
    save_scene(scene, tmp_path / "s.toml")
    monkeypatch.undo()
    assert len(os.listdir("/proc/self/fd")) == fds
    assert _same(load_scene(tmp_path / "s.toml"), scene)
    assert sorted(os.listdir(tmp_path)) == ["s.toml"]


def test_image_sky_saved_through_a_link_in_another_folder(tmp_path):
    """The file is read both by the link's name and by its own: a relative
    sky path could hold for one folder only, so it is written absolute."""
    pic = _pfm(tmp_path / "a" / "sky.pfm")
    s = load_scene(_write(tmp_path / "a", {"name": "l", "sky": {"type": "image", "image": "sky.pfm"}}))
    (tmp_path / "b").mkdir()
    (tmp_path / "c").mkdir()
    link = tmp_path / "c" / "link.toml"
    link.symlink_to(tmp_path / "b" / "target.toml")
    save_scene(s, link)
    assert link.is_symlink()
    for name in (link, tmp_path / "b" / "target.toml"):
        assert load_scene(name).sky.image_path.resolve() == pic.resolve()


def test_saving_through_a_link_keeps_the_link(tmp_path):
    real = _write(tmp_path / "real", {"name": "r"}, "scene.toml")
    link = tmp_path / "link.toml"
    link.symlink_to(real)
    s = load_scene(link)
    s.render.samples = 7
    save_scene(s, link)
    assert link.is_symlink() and load_scene(real).render.samples == 7


# --------------------------------------------------------------------------- the panel


def test_panel_save_reports_failures_and_leaves_nothing_behind(tmp_path, capsys):
    from viewer.window.panel import Panel

    scene = load_scene("default")
    panel = Panel(scene)
    panel.save_path = str(tmp_path / "missing" / "s.toml")
    assert not panel.save(scene)
    assert panel.status.startswith("could not save") and "No such file or directory" in panel.status
    assert "could not save" in capsys.readouterr().err
    assert os.listdir(tmp_path) == []
    (tmp_path / "dir.toml").mkdir()
    panel.save_path = str(tmp_path / "dir.toml")
    assert not panel.save(scene)
    assert sorted(os.listdir(tmp_path)) == ["dir.toml"] and os.listdir(tmp_path / "dir.toml") == []


def test_panel_saves_over_the_scene_file_and_prints_the_path(tmp_path, capsys):
    from viewer.window.panel import Panel

    src = _write(tmp_path, {"name": "mine", "render": {"samples": 2}}, "mine.toml")
    scene = load_scene(src)
    panel = Panel(scene)
    assert panel.save_path == str(src)  # a user's file: saved in place
    scene.render.samples = 9
    assert panel.save(scene)
    assert load_scene(src).render.samples == 9
    assert capsys.readouterr().out.strip() == f"saved scene {src.resolve()}"
    assert not stat.S_ISLNK(os.lstat(src).st_mode) and sorted(os.listdir(tmp_path)) == ["mine.toml"]
    with pytest.raises(SceneError):   # (sanity: the helper writes files load_scene checks)
        load_scene(_write(tmp_path, {"nope": 1}, "bad.toml"))
