"""glassray bench: the metrics and the Pareto front on hand-made data, and the
whole command end to end on a tiny size.  No assertion on time: the numbers
live in the bench output and the README."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from viewer import bench


# ---------------------------------------------------------------- Pareto front


def test_pareto_known_front():
    # (time, error): the front is a, b, d; c is dominated by b, e by d, f by a
    # (same time, more error), g duplicates d exactly (neither dominates).
    pts = {"a": (1.0, 10.0), "b": (2.0, 5.0), "c": (3.0, 6.0), "d": (4.0, 1.0),
           "e": (5.0, 1.0), "f": (1.0, 12.0), "g": (4.0, 1.0)}
    mask = bench.pareto_mask([p[0] for p in pts.values()], [p[1] for p in pts.values()])
    front = {k for k, m in zip(pts, mask) if m}
    assert front == {"a", "b", "d", "g"}


def test_pareto_front_is_non_dominated_and_complete():
    rng = np.random.default_rng(3)
    t, e = rng.random(200), rng.random(200)
    mask = bench.pareto_mask(t, e)
    for i in range(len(t)):
        dominated = any(t[j] <= t[i] and e[j] <= e[i] and (t[j] < t[i] or e[j] < e[i]) for j in range(len(t)))
        assert mask[i] == (not dominated)
    # on the front, time up means error down
    front = sorted((t[i], e[i]) for i in range(len(t)) if mask[i])
    assert all(b[1] < a[1] for a, b in zip(front, front[1:]))


def test_pareto_single_point():
    assert bench.pareto_mask([5.0], [0.1]) == [True]


def test_pareto_with_tolerances():
    # b is 2% faster than a with the same error: dominates a exactly, a tie within 5%
    t, e = [100.0, 98.0], [0.5, 0.5]
    assert bench.pareto_mask(t, e) == [False, True]
    assert bench.pareto_mask(t, e, time_tol=0.05) == [True, True]
    # within the time tolerance, a lower error still wins: c (3% slower, error 10% lower) dominates a
    t, e = [100.0, 103.0], [0.5, 0.45]
    assert bench.pareto_mask(t, e, time_tol=0.05, error_tol=1e-4) == [False, True]
    # errors equal to float rounding are a tie: neither dominates
    t, e = [100.0, 101.0], [0.5, 0.5 * (1 + 1e-6)]
    assert bench.pareto_mask(t, e, time_tol=0.05, error_tol=1e-4) == [True, True]
    # far faster and worse: both on the front, with or without tolerances
    assert bench.pareto_mask([10.0, 100.0], [1.0, 0.1], 0.05, 1e-4) == [True, True]
    assert bench.dominates(1.0, 1.0, 2.0, 2.0) and not bench.dominates(2.0, 2.0, 1.0, 1.0)


# ---------------------------------------------------------------- error metrics


def test_error_of_an_image_against_itself_is_zero():
    img = np.random.default_rng(0).random((9, 16, 3)) * 2.0   # HDR values too
    err = bench.image_errors(img, img.copy())
    assert err == {"rmse": 0.0, "frac_off": 0.0, "max_abs": 0.0}


def test_error_uniform_offset():
    ref = np.full((10, 20, 3), 0.5)
    err = bench.image_errors(ref + 0.02, ref)
    assert err["rmse"] == pytest.approx(0.02, rel=1e-12)
    assert err["max_abs"] == pytest.approx(0.02, rel=1e-12)
    assert err["frac_off"] == 1.0          # 0.5 -> 0.52 linear is about 3.5 display levels


def test_error_known_perturbation():
    ref = np.full((8, 8, 3), 0.5)
    img = ref.copy()
    img[:4, :4, 1] += 0.1                  # a quarter of the pixels, one channel of three
    err = bench.image_errors(img, ref)
    assert err["rmse"] == pytest.approx(0.1 * math.sqrt(0.25 / 3), rel=1e-12)
    assert err["max_abs"] == pytest.approx(0.1, rel=1e-12)
    assert err["frac_off"] == 0.25


def test_error_display_threshold_is_more_than_one_level():
    ref = np.full((4, 4, 3), 0.5)
    # 1e-4 linear at 0.5 is well under one display level: counted in RMSE, not as "off"
    err = bench.image_errors(ref + 1e-4, ref)
    assert err["frac_off"] == 0.0 and err["rmse"] == pytest.approx(1e-4)
    # above 1: clamped on display, so not off there either, but off in linear
    err = bench.image_errors(np.full((2, 2, 3), 3.0), np.full((2, 2, 3), 2.0))
    assert err["frac_off"] == 0.0 and err["rmse"] == pytest.approx(1.0)


def test_error_rejects_mismatched_shapes():
    with pytest.raises(ValueError):
        bench.image_errors(np.zeros((2, 2, 3)), np.zeros((2, 3, 3)))


# ---------------------------------------------------------------- upscale and sweep


def test_upscale():
    img = np.random.default_rng(1).random((5, 7, 3))
    assert np.array_equal(bench.upscale(img, 7, 5), img)
    const = np.full((3, 4, 3), 0.25)
    assert np.allclose(bench.upscale(const, 17, 9), 0.25)
    # a horizontal linear ramp stays linear in the interior after a 2x upscale
    ramp = np.broadcast_to(np.arange(8.0)[None, :, None], (2, 8, 3))
    up = bench.upscale(ramp, 16, 4)
    assert up.shape == (4, 16, 3)
    assert np.allclose(np.diff(up[0, 1:-1, 0]), 0.5)


def test_sweep_covers_every_knob():
    from viewer.scene import load_scene

    scene = load_scene("default")
    full = bench.sweep(scene, reference_samples=64)
    assert full[0].label == "default"
    assert full[0].key() == (scene.render.max_depth, scene.render.samples, scene.render.min_weight, 1.0, True, "exact")
    assert len({s.key() for s in full}) == len(full)
    assert len({s.label for s in full}) == len(full)
    for knob in ("max_depth=", "samples=", "min_weight=", "scale=", "generic", "schlick"):
        assert any(s.label.startswith(knob) for s in full), knob
    assert all(s.samples < 64 for s in full if s.samples != scene.render.samples)
    quick = bench.sweep(scene, quick=True, reference_samples=4)
    assert 2 <= len(quick) <= 8 and quick[0].label == "default"


# ---------------------------------------------------------------- end to end


def _bench(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "viewer", "bench", *args], capture_output=True, text=True,
                          timeout=120, cwd=cwd)


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    proc = _bench("--quick", "--size", "32x18", "--repeat", "1", "--scenes", "default,bench-opaque",
                  "--out", str(out))
    return proc, out


def test_bench_end_to_end(quick_run):
    proc, out = quick_run
    assert proc.returncode == 0, proc.stderr
    with open(out / "results.csv", newline="") as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames) == bench.CSV_COLUMNS
        rows = list(reader)
    assert {r["scene"] for r in rows} == {"default", "bench-opaque"}
    labels = {r["setting"] for r in rows}
    assert {"default", "generic", "schlick"} <= labels
    for r in rows:
        for col in ("time_ms", "time_min_ms", "time_max_ms", "cpu_ms", "rmse", "frac_off_1_255", "max_abs_err",
                    "min_weight", "scale"):
            v = float(r[col])
            assert math.isfinite(v) and v >= 0.0, (col, r)
        assert float(r["time_ms"]) > 0.0
        assert 0.0 <= float(r["frac_off_1_255"]) <= 1.0
        assert int(r["repeat"]) == 1
        if float(r["scale"]) == 1.0:
            assert (int(r["width"]), int(r["height"])) == (32, 18)
    for scene in ("default", "bench-opaque"):
        sub = [r for r in rows if r["scene"] == scene]
        assert sum(int(r["is_default"]) for r in sub) == 1
        # the pareto columns are exactly the non-dominated sets of (time, rmse), per clock
        for clock, col in (("wall", "time_ms"), ("cpu", "cpu_ms")):
            mask = bench.pareto_mask([float(r[col]) for r in sub], [float(r["rmse"]) for r in sub],
                                     bench.DEFAULT_TIME_TOLERANCE, bench.DEFAULT_ERROR_TOLERANCE)
            assert [bool(int(r[f"pareto_{clock}"])) for r in sub] == mask, clock
        # the same image whichever shader: specialised and generic agree
        e = {r["setting"]: float(r["rmse"]) for r in sub}
        assert e["generic"] == pytest.approx(e["default"], rel=1e-3)
    info = json.loads((out / "machine.json").read_text())
    for key in ("gl", "platform", "cpu", "date", "reference", "size"):
        assert info[key], key
    assert info["size"] == "32x18"
    assert set(info["speedup_specialised_vs_generic"]) == {"default", "bench-opaque"}
    assert set(info["default_on_pareto_front"]["default"]) == {"wall", "cpu"}
    assert "### default" in proc.stdout and "### bench-opaque" in proc.stdout
    assert "specialised vs generic shader" in proc.stdout
    assert len(list(out.glob("ref-*.npy"))) == 2
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        assert "glassray[bench]" in proc.stdout
    else:
        assert (out / "pareto.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bench_reuses_cached_reference(quick_run, tmp_path):
    proc, out = quick_run
    assert proc.returncode == 0, proc.stderr
    before = {p.name: p.stat().st_mtime_ns for p in out.glob("ref-*.npy")}
    again = _bench("--quick", "--size", "32x18", "--repeat", "1", "bench-opaque", "--out", str(out))
    assert again.returncode == 0, again.stderr
    assert "reference from the cache" in again.stderr
    after = {p.name: p.stat().st_mtime_ns for p in out.glob("ref-*.npy")}
    assert after == before


def test_plot_without_matplotlib(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "matplotlib", None)   # import matplotlib -> ImportError
    assert bench.plot(tmp_path / "p.png", {}, {}, "") is False
    assert not (tmp_path / "p.png").exists()


@pytest.mark.parametrize("args, status, text", [
    (["no-such-scene.toml"], 2, "no-such-scene.toml"),
    (["default", "--scenes", "bench-opaque"], 2, "either SCENE or --scenes"),
    (["--size", "0x5"], 2, "1..16384"),
])
def test_bench_usage_errors(args, status, text, tmp_path):
    proc = _bench(*args, "--quick", "--out", str(tmp_path / "o"))
    assert proc.returncode == status
    assert text in proc.stderr
    assert "Traceback" not in proc.stderr


def test_bench_unwritable_out(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    proc = _bench("--quick", "--size", "8x8", "--out", str(blocker / "sub"))
    assert proc.returncode == 1
    assert "cannot write" in proc.stderr and "Traceback" not in proc.stderr


def test_bench_help_uses_docstring():
    proc = _bench("--help")
    assert proc.returncode == 0
    assert bench.__doc__.strip().splitlines()[0] in proc.stdout.replace("\n", " ")
    assert "--reference-samples" in proc.stdout and "--quick" in proc.stdout


def test_reference_falls_back_to_the_gpu(gl, monkeypatch, tmp_path):
    """Without viewer.reference the bench still runs, on a converged GPU render."""
    from viewer.scene import load_scene

    monkeypatch.setattr(bench, "reference_kind", lambda: "gpu")
    scene = load_scene("glass-sphere")
    img, kind, cached = bench.reference_image(scene, "glass-sphere", 16, 9, 2, tmp_path, ctx=gl)
    assert kind == "gpu" and not cached
    assert img.shape == (9, 16, 3) and img.dtype == np.float64 and np.all(np.isfinite(img))
    again, _, cached = bench.reference_image(scene, "glass-sphere", 16, 9, 2, tmp_path, ctx=gl)
    assert cached and np.array_equal(again, img)
    names = [p.name for p in tmp_path.glob("ref-*.npy")]
    assert len(names) == 1 and "-gpu-" in names[0]
