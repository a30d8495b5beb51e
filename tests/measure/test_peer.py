"""The physically based peer (viewer/measure/peer.py): which scenes qualify, the
conventions of the conversion (camera, pixel filter, checker, dielectric,
sky) against the float64 reference, and ``glassray bench --peer mitsuba``
end to end.  Skipped where Mitsuba 3 is not installed (pip install
'glassray[peer]'; the test extra installs it)."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")

from viewer.measure import peer  # noqa: E402
from viewer.reference.trace import render_reference  # noqa: E402
from viewer.scene.load import load_scene, scene_from_dict, with_overrides
from viewer.scene.save import scene_to_toml  # noqa: E402
from viewer.measure import peer_check
from viewer.measure import peer_mitsuba
from viewer.measure import peer_report

import tomllib  # noqa: E402


def _dict(scene) -> dict:
    return tomllib.loads(scene_to_toml(scene))


def _whitted() -> dict:
    return _dict(load_scene("whitted-exact"))


# ---------------------------------------------------------------- which scenes qualify


def test_whitted_exact_qualifies():
    assert peer_check.reasons(load_scene("whitted-exact")) == []
    peer_check.check_scene(load_scene("whitted-exact"))


def test_default_scene_is_rejected_with_every_reason():
    with pytest.raises(peer_check.PeerError) as e:
        peer_check.check_scene(load_scene("default"))
    msg = str(e.value)
    assert msg.count("\n") == 0
    assert "cannot be compared with a physically based renderer" in msg
    for what in ("Phong terms", "sky.type is 'gradient'", "vessels", "absorption"):
        assert what in msg, what


@pytest.mark.parametrize("change, expected", [
    (lambda d: d["materials"]["glass"].update(transparency=0.5), "transparency 0.5 < 1"),
    (lambda d: d["materials"]["glass"].update(absorption=[0.1, 0, 0]), "absorption is not supported"),
    (lambda d: d["materials"]["glass"].update(emission=[0.1, 0, 0]), "emissive dielectric"),
    (lambda d: d["materials"]["floor"].update(diffuse=0.8, color=[1, 1, 1]) or
     d.setdefault("lights", []).append({"position": [1, 4, 1]}), "Phong terms"),
    (lambda d: d["materials"]["floor"].update(ambient=0.1, color=[1, 1, 1]) or d.update(ambient=[0.1, 0.1, 0.1]),
     "Phong terms"),
    (lambda d: d["sky"].update(type="gradient"), "only a constant sky"),
    (lambda d: d["objects"][1].update(center=[0, 0.5, 0]), "emits inside the medium"),
    (lambda d: d["objects"].append({"type": "sphere", "center": [0.5, 0.7, 0], "radius": 0.3,
                                    "material": "glass"}), "overlapping transparent objects"),
    (lambda d: d["camera"].update(position=[0, 0.7, 0.2]), "the camera is inside objects[1]"),
    (lambda d: d["camera"].update(position=[0, -1, 4]), "below the plane"),
])
def test_non_qualifying_scenes_are_rejected(change, expected):
    d = _whitted()
    change(d)
    scene = scene_from_dict(d, "changed.toml")
    with pytest.raises(peer_check.PeerError, match="cannot be compared") as e:
        peer_check.check_scene(scene)
    assert expected in str(e.value)
    with pytest.raises(peer_check.PeerError):
        peer_mitsuba.scene_dict(scene, 8, 8)


_GLASS_BOX = {"type": "box", "min": [1.2, 0.0, -0.3], "max": [1.8, 0.6, 0.3], "material": "glass"}
_FLOOR = {"type": "box", "min": [-3, -0.1, -3], "max": [3, 0.0, 3], "material": "floor"}


@pytest.mark.parametrize("objects, touching", [
    ([_GLASS_BOX], True),                                                   # a face on the plane
    ([dict(_GLASS_BOX, min=[1.2, 0.01, -0.3])], False),                     # a gap
    ([dict(_GLASS_BOX, rotate=[0, 30, 0])], True),                          # turned about y: still flat
    ([dict(_GLASS_BOX, min=[1.2, -0.2, -0.3], rotate=[45, 0, 0])], False),  # into the floor: opaque wins
    ([{"type": "cylinder", "base": [1.5, 0, 0], "radius": 0.3, "height": 0.5, "material": "glass"}], True),
    ([{"type": "cylinder", "axis": "x", "base": [1.2, 0.3, 0], "radius": 0.3, "height": 0.5,
       "material": "glass"}], False),                                       # along a line
    # face to face with an opaque box, off the floor; and two glass boxes face to face
    ([dict(_GLASS_BOX, min=[1.2, 0.5, -0.3], max=[1.8, 1.1, 0.3]),
      {"type": "box", "min": [1.8, 0.6, -0.1], "max": [2.2, 0.8, 0.1], "material": "floor"}], True),
    ([dict(_GLASS_BOX, min=[1.2, 0.5, -0.3], max=[1.8, 1.1, 0.3]),
      dict(_GLASS_BOX, min=[1.8, 0.6, -0.1], max=[2.2, 0.8, 0.1])], True),
    # the same two, touching only along an edge
    ([dict(_GLASS_BOX, min=[1.2, 0.5, -0.3], max=[1.8, 1.1, 0.3]),
      {"type": "box", "min": [1.8, 0.6, 0.3], "max": [2.2, 0.8, 0.5], "material": "floor"}], False),
])
def test_flat_faces_lying_on_each_other_are_refused(objects, touching):
    """A glass box standing on the floor: Mitsuba met the box's bottom face or
    the floor first at random, and converged 0.013 RMSE away from the
    reference at 320x180 (a scene drawn for the comparison, 2026-12-03)."""
    d = _whitted()
    d["objects"][1]["center"] = [-1.0, 0.7, 0.0]
    d["objects"] += objects
    why = [w for w in peer_check.reasons(scene_from_dict(d, "faces.toml")) if "a flat face" in w]
    assert bool(why) == touching, why
    if touching:
        assert "objects[2]" in why[0]


def test_clip_area_of_convex_polygons():
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    assert peer_check._clip_area(sq, sq + [0.5, 0.25]) == pytest.approx(0.375)
    assert peer_check._clip_area(sq, (sq + [1.0, 0])[::-1]) == pytest.approx(0.0)    # an edge, either winding
    tri = np.array([[0, 0], [2, 0], [0, 2]], float)
    assert peer_check._clip_area(sq, tri) == pytest.approx(1.0)
    assert peer_check._clip_area(tri, sq * 3 - 0.5) == pytest.approx(2.0)


def test_lights_alone_do_not_disqualify():
    # a light lights nothing when every material's Phong terms are 0
    d = _whitted()
    d["lights"] = [{"position": [2, 5, 3]}]
    assert peer_check.reasons(scene_from_dict(d, "lit.toml")) == []


def test_bench_peer_rejects_a_scene_with_one_clear_message(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "viewer", "bench", "--peer", "mitsuba", "glass-sphere",
                           "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr
    assert "glass-sphere" in lines[0] and "cannot be compared with a physically based renderer" in lines[0]


# ---------------------------------------------------------------- time to error


def _pts(pairs):
    out = []
    for t, e in pairs:
        p = peer.Point("s", "x", 1, None)
        p.times, p.cpu_times, p.errors = [t], [t], {"rmse": e}
        out.append(p)
    return out


@pytest.mark.parametrize("value", ["0", "-5", "ten", "1.5"])
def test_bad_peer_time_limit_is_bad_usage(tmp_path, value):
    proc = subprocess.run([sys.executable, "-m", "viewer", "bench", "--peer", "mitsuba", "--peer-time-limit", value,
                           "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "--peer-time-limit" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "o").exists()


def test_time_to_error_interpolates_log_log_and_never_extrapolates():
    pts = _pts([(10.0, 0.4), (20.0, 0.2), (40.0, 0.1)])
    t, flag = peer_report.time_to_error(pts, 0.2 / np.sqrt(2))      # halfway in log error -> halfway in log time
    assert flag == "" and t == pytest.approx(np.sqrt(20.0 * 40.0))
    assert peer_report.time_to_error(pts, 0.2) == (pytest.approx(20.0), "")
    assert peer_report.time_to_error(pts, 0.05) == (None, "not reached")
    assert peer_report.time_to_error(pts, 0.5) == (10.0, "<=")       # only a bound
    # the first crossing counts, even when noise brings the error back up later
    pts = _pts([(10.0, 0.4), (20.0, 0.15), (40.0, 0.25), (80.0, 0.1)])
    assert peer_report.time_to_error(pts, 0.2)[0] < 20.0


# ---------------------------------------------------------------- conventions against the reference


def _emitters_scene() -> dict:
    """Three emitters of different colours off-centre, a black sky, a camera
    looking sideways and down: any flip, a wrong fov axis or a wrong box
    rotation moves a colour's centroid."""
    return {
        "name": "emitters", "ambient": [0, 0, 0],
        "camera": {"position": [1.5, 1.2, 4.0], "target": [0.3, 0.4, 0.0], "fov": 35},
        "render": {"max_depth": 2, "min_weight": 0.0},
        "sky": {"type": "color", "color": [0, 0, 0]},
        "materials": {
            "red": {"color": [0, 0, 0], "emission": [1, 0, 0]},
            "green": {"color": [0, 0, 0], "emission": [0, 1, 0]},
            "blue": {"color": [0, 0, 0], "emission": [0, 0, 1]},
        },
        "objects": [
            {"type": "sphere", "center": [-0.9, 1.1, 0.2], "radius": 0.35, "material": "red"},
            {"type": "box", "min": [0.6, -0.3, -0.2], "max": [1.4, 0.1, 0.1], "rotate": [20, 35, 15],
             "material": "green"},
            {"type": "cylinder", "axis": "x", "base": [-1.2, -0.6, 0.5], "radius": 0.15, "height": 0.9,
             "material": "blue"},
        ],
    }


def _centroids(img):
    h, w = img.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    out = []
    for c in range(3):
        m = img[..., c]
        s = m.sum()
        out.append((s, (m * xs).sum() / s, (m * ys).sum() / s))
    return out


def test_camera_and_shapes_land_on_the_same_pixels():
    scene = scene_from_dict(_emitters_scene(), "emitters.toml")
    w, h = 64, 36                                            # 16:9: a wrong fov axis scales one direction
    mine = peer.MitsubaPeer(scene, w, h).render(256, seed=5)
    ref = render_reference(scene, w, h, 64, seed=1)
    for c, ((sm, xm, ym), (sr, xr, yr)) in enumerate(zip(_centroids(mine), _centroids(ref))):
        assert sr > 5.0, c                                    # each emitter covers several pixels
        assert sm == pytest.approx(sr, rel=0.03), c          # same area: fov, aspect, sizes, rotation
        assert abs(xm - xr) < 0.1 and abs(ym - yr) < 0.1, (c, xm, xr, ym, yr)
    # and pixel by pixel: everything off the edges is identical
    assert np.mean(np.abs(mine - ref).max(-1) > 0.25) < 0.05


def test_floor_checker_and_orientation_match_first_samples(gl):
    """The checker's parity, its anchoring and the image's orientation: the
    floor of whitted-exact seen from above, no sphere."""
    d = _whitted()
    d["objects"] = d["objects"][:1]
    d["camera"] = {"position": [0.3, 3.0, 2.0], "target": [0.6, 0.0, -0.4], "fov": 50}
    scene = scene_from_dict(d, "floor.toml")
    w, h = 48, 27
    mine = peer.MitsubaPeer(scene, w, h).render(64, seed=2)
    ref = render_reference(scene, w, h, 64, seed=1)
    # pixels whose 64 reference samples all see one square (0.1 or 0.9
    # exactly; 41% of them at this size) lie inside it: Mitsuba's agree there
    # exactly but for the few where an edge grazes the footprint
    pure = np.isclose(ref, 0.1, atol=1e-6).all(-1) | np.isclose(ref, 0.9, atol=1e-6).all(-1)
    assert pure.mean() > 0.3
    same = np.abs(mine - ref).max(-1) < 1e-3
    assert same[pure].mean() > 0.95
    # a swapped checker would make the interiors disagree everywhere
    assert np.mean(np.abs(mine - ref).max(-1) > 0.7) < 0.02


@pytest.mark.parametrize("name", ["whitted-exact", "whitted-glass"])
def test_converged_mitsuba_matches_the_reference_within_noise(name):
    """whitted-exact (glass sphere, emissive checker, constant sky) and
    whitted-glass (spheres, a lying cylinder, boxes, a lamp) at 48x27:
    the difference of Mitsuba (mean of 4 independent renders) and the
    reference (mean of 2 seeds) has the RMSE their sampling noise predicts,
    estimated from the spread of the repeats: measured 1.04x the prediction
    at 160x90; allowed 1.25x.  A convention error (fov axis, Gaussian pixel
    filter, checker parity or offset, ext_ior 1.000277 instead of 1, a
    mirrored camera) gives several times more."""
    scene = load_scene(name)
    ref_scene = with_overrides(scene, max_depth=16, min_weight=1e-4)
    w, h, k = 48, 27, 4
    p = peer.MitsubaPeer(scene, w, h, max_depth=16)
    ims = np.stack([p.render(256, seed=10 + i) for i in range(k)])
    r1 = render_reference(ref_scene, w, h, 128, seed=1)
    r2 = render_reference(ref_scene, w, h, 128, seed=2)
    d = ims.mean(0) - (r1 + r2) / 2
    var_mi = ims.var(0, ddof=1).mean() / k
    var_ref = ((r1 - r2) ** 2).mean() / 4
    expected = np.sqrt(var_mi + var_ref)
    rmse = np.sqrt(np.mean(d ** 2))
    assert rmse < 1.25 * expected, (rmse, expected)
    # no bias: the mean difference is within 4 standard errors
    assert abs(d.mean()) < 4 * expected / np.sqrt(d.size) + 1e-4, d.mean()
    # the sky is exact
    assert np.abs(d[0]).max() < 1e-4


def test_scene_dict_conventions():
    scene = load_scene("whitted-exact")
    peer_mitsuba.select_variant()
    d = peer_mitsuba.scene_dict(scene, 32, 18)
    s = d["sensor"]
    assert s["fov_axis"] == "y" and s["fov"] == 40.0
    assert s["film"]["rfilter"] == {"type": "box"}
    assert d["integrator"]["max_depth"] == 12 and d["integrator"]["hide_emitters"] is False
    glass = [v for v in d.values() if isinstance(v, dict) and v.get("type") == "sphere"][0]
    assert glass["bsdf"] == {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0}
    assert d["sky"]["type"] == "constant"
    m = np.array(s["to_world"].matrix)
    np.testing.assert_allclose(m[:3, 3], scene.camera.position)
    f = np.array(scene.camera.target) - np.array(scene.camera.position)
    np.testing.assert_allclose(m[:3, 2], f / np.linalg.norm(f), atol=1e-6)
    assert m[0, 0] < 0          # camera +x is the image's left: -right, right = +x here


# ---------------------------------------------------------------- the bench command


def test_bench_peer_end_to_end(tmp_path):
    """At 320x180 the culling plan of whitted-exact has more groups than the
    quick series' first renders compile (one variant a draw): without
    rendering them again until nothing is left to compile, a timed render
    built one."""
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "viewer", "bench", "--peer", "mitsuba", "--size", "320x180",
                           "--quick", "--repeat", "1", "--out", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "### Measured series" in proc.stdout and "mitsuba / glassray" in proc.stdout
    assert "variant llvm_ad_rgb" in proc.stdout or "variant scalar_rgb" in proc.stdout
    rows = list(csv.DictReader((out / "peer.csv").open()))
    series = {r["series"] for r in rows}
    assert {"glassray", "mitsuba"} <= series
    assert [int(r["samples"]) for r in rows if r["series"] == "glassray"] == list(peer.QUICK_GLASSRAY_SPP)
    for r in rows:
        assert float(r["time_ms"]) > 0 and 0 < float(r["rmse"]) < 1, r
    # more samples, less error, on both renderers
    for name in ("glassray", "mitsuba"):
        e = [float(r["rmse"]) for r in rows if r["series"] == name]
        assert e[-1] < e[0], name
    tte = list(csv.DictReader((out / "peer-time-to-error.csv").open()))
    assert {r["clock"] for r in tte} == {"wall", "cpu"}
    assert [float(r["target_rmse"]) for r in tte if r["clock"] == "wall"] == list(peer.TARGET_ERRORS)
    info = json.loads((out / "peer-machine.json").read_text())
    assert info["peer"]["mitsuba"] == mi.__version__
    assert info["peer"]["variant"] in ("llvm_ad_rgb", "scalar_rgb")
    assert info["cpus_usable"] >= 1 and info["size"] == "320x180"
    assert info["glassray"]["programs_built_in_timed_rounds"] == 0
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        assert "glassray[bench]" in proc.stdout
    else:
        assert (out / "peer.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bench_peer_without_matplotlib_removes_an_earlier_runs_plot(tmp_path):
    """peer.png of an earlier run must not stay next to results it does not show."""
    from conftest import no_matplotlib_env

    env = no_matplotlib_env(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "peer.png").write_bytes(b"\x89PNG\r\n\x1a\n an earlier run")
    proc = subprocess.run([sys.executable, "-m", "viewer", "bench", "--peer", "mitsuba", "--size", "16x9",
                           "--quick", "--repeat", "1", "--out", str(out)],
                          capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    assert "glassray[bench]" in proc.stdout and "removed the plot of an earlier run" in proc.stdout
    assert not (out / "peer.png").exists() and (out / "peer.csv").is_file()
