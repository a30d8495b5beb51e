"""The numerical stability suite (viewer/measure/stress.py, ``glassray stress``) as
tests: every case at a tiny size must stay within its stated tolerance
against the float64 reference, the textbook intersection formulas
(NAIVE_INTERSECT) must be caught by it, and the command line lists, runs
and fails cases as documented.  The whole file runs in well under a minute
on two cores (Mesa llvmpipe)."""

from __future__ import annotations

import argparse
import subprocess
import sys

import numpy as np
import pytest

from viewer.gpu import block as gpu_block
from viewer.cli import stress as cli_stress
from viewer.measure import stress_cases, stress_report, stress_suite

SIZE = (48, 27)   # cases that need a pixel on the view axis use 49x27


@pytest.fixture(scope="module")
def suite(gl):
    gl.__enter__()  # current even if an earlier test left another context current
    return stress_suite.Suite(gl)


def _describe(r: stress_suite.CaseResult) -> str:
    return "\n".join([stress_report.format_table([r])])


# The 1e-4 wall needs surface offsets below half the wall where the glass is
# (about 6 units from the eye: EPS_REL * 6 + EPS_SCENE * 6 < 5e-5); with
# EPS_REL = 1e-5 the media probe 2 eps past the outer surface lands beyond the
# inner one and the wall is skipped.  See README, "Numerical stability".
_OFFSETS_TOO_LARGE = gpu_block.EPS_REL > 5e-6
_XFAIL = {"thin-wall-1e-4": pytest.mark.xfail(_OFFSETS_TOO_LARGE, strict=True,
                                              reason="gpu_block.EPS_REL too large for a 1e-4 wall")}


@pytest.mark.parametrize("name", [pytest.param(n, marks=_XFAIL.get(n, ())) for n in stress_cases.case_names()])
def test_case_within_tolerance(suite, name):
    case = stress_cases.get_case(name)
    r = suite.run_case(case, SIZE)
    assert r.nonfinite == 0, _describe(r)
    assert r.off1 <= case.tol, _describe(r)
    for c in r.checks:
        assert c.ok, f"{c.text()}\n{_describe(r)}"
    assert r.ok


def test_every_shipped_scene_is_a_case():
    from viewer.scene.load import builtin_scene_names

    assert {f"scene-{n}" for n in builtin_scene_names()} <= set(stress_cases.case_names())


def test_the_suite_catches_the_textbook_formulas(gl):
    # NAIVE_INTERSECT (b^2 - 4c discriminant, -b +- sqrt roots): the default
    # view from ~200 units away loses the hit points to cancellation (wrong
    # shading, self-shadowing) while the robust shader passes the same case.
    case = stress_cases.get_case("far-camera")
    naive = stress_suite.Suite(gl, naive=True).run_case(case, SIZE)
    assert not naive.ok and naive.off1 > 0.01 and naive.acne > 0.005
    robust = stress_suite.Suite(gl).run_case(case, SIZE)
    assert robust.ok


def test_translation_and_scale_helpers_keep_the_image():
    doc = stress_cases._base()
    moved = stress_cases.translated(doc, (1e6, 1e6, 1e6))
    assert moved["camera"]["position"][0] == doc["camera"]["position"][0] + 1e6
    with pytest.raises(AssertionError):
        stress_cases.translated(doc, (0.25, 0, 0))        # not a multiple of the checker period (1.0)
    small = stress_cases.scaled(doc, 1e-3)
    water = next(m for n, m in small["materials"].items() if n == "water")
    assert np.allclose(water["absorption"], np.array(doc["materials"]["water"]["absorption"]) * 1e3)
    assert small["materials"]["floor"]["checker"]["size"] == pytest.approx(0.5e-3)
    glass = next(o for o in small["objects"] if o.get("name") == "glass")
    assert glass["wall"] == pytest.approx(0.06e-3) and glass["radius"] == pytest.approx(1e-3)


def test_metrics_on_hand_made_images():
    a = np.zeros((4, 5, 3), np.uint8)
    b = a.copy()
    b[0, 0] = (2, 0, 0)       # off by 2 levels
    b[1, 1] = (1, 1, 1)       # off by 1 level: within 1/255
    assert stress_suite.off_fraction(a, b) == pytest.approx(1 / 20)
    mask = np.zeros((4, 5), bool)
    mask[0, 0] = True
    assert stress_suite.off_fraction(a, b, mask) == 0.0
    heat = stress_report.error_heat(a, b, mask)
    assert heat.shape == (4, 5, 3) and heat.dtype == np.uint8


def _stress(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "viewer", "stress", *map(str, args)], capture_output=True,
                          text=True, timeout=120, cwd=cwd)


def test_list_names_every_case():
    r = _stress("--list")
    assert r.returncode == 0, r.stderr
    for name in stress_cases.case_names():
        assert f"\n{name}\n" in "\n" + r.stdout
    assert "tolerance:" in r.stdout


def test_case_option_runs_one_case_and_writes_the_sheet(tmp_path):
    r = _stress("--case", "axis-x", "--size", "32x18", "--out", tmp_path / "res")
    assert r.returncode == 0, r.stdout + r.stderr
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("axis-x")]
    assert len(lines) == 1 and lines[0].split()[1] == "33x19" and lines[0].rstrip().endswith("ok")
    assert "1 of 1 cases within tolerance" in r.stdout
    from PIL import Image

    with Image.open(tmp_path / "res" / "contact-sheet.png") as im:
        assert im.size[0] > 3 * 33 and im.size[1] > 19
    assert "axis-x" in (tmp_path / "res" / "results.md").read_text()


def test_unknown_case_is_bad_usage():
    r = _stress("--case", "no-such-case")
    assert r.returncode == 2 and "no-such-case" in r.stderr and "Traceback" not in r.stderr


def test_a_case_named_twice_is_bad_usage(tmp_path):
    # it ran and reported the case twice ("2 of 2 cases")
    r = _stress("--case", "axis-x", "--case", "axis-x", "--out", tmp_path / "res")
    assert r.returncode == 2 and "--case names axis-x more than once" in r.stderr, r.stderr
    assert not (tmp_path / "res").exists()


def test_exit_status_1_when_a_case_exceeds_its_tolerance(monkeypatch, tmp_path, capsys):
    # the same case with an impossible tolerance (negative) must fail the run
    strict = stress_cases.Case("axis-x-strict", "axis-x with a negative tolerance", stress_cases.get_case("axis-x").build,
                         centre=True, tol=-1.0)
    monkeypatch.setattr(stress_cases, "CASES", stress_cases.CASES + [strict])
    args = argparse.Namespace(list=False, case=["axis-x-strict"], size=(16, 9), out=str(tmp_path), columns=3,
                              naive=False, intersections=False, backend="auto", debug=True)
    assert cli_stress.run(args) == 1
    out = capsys.readouterr().out
    assert "FAIL" in out and "failed: axis-x-strict" in out


# ---------------------------------------------------------------- outputs (audit)


def _args(tmp_path, **kw) -> argparse.Namespace:
    a = dict(list=False, case=["axis-x"], size=(16, 9), out=str(tmp_path / "res"), columns=3, naive=False,
             intersections=False, backend="auto", debug=False)
    a.update(kw)
    return argparse.Namespace(**a)


def test_results_md_names_the_machine_and_the_renderer(gl, tmp_path):
    from viewer.measure.kit import machine_info
    from viewer.gpu.context import describe

    assert cli_stress.run(_args(tmp_path)) == 0
    md = (tmp_path / "res" / "results.md").read_text()
    mi = machine_info()
    assert describe(gl) in md
    assert f"{mi['cpu'] or mi['machine']} ({mi['cpus_usable']} usable CPUs)" in md and mi["platform"] in md
    # the verdict and the command, as stdout and bench's files have them
    assert md.rstrip().endswith("1 of 1 cases within tolerance") and "command: `glassray" in md
    assert md.startswith("glassray stress: 1 case, ")


@pytest.mark.parametrize("args, text", [
    (["--columns", "0"], "1..1000"),
    (["--columns", "-2"], "1..1000"),
    (["--out", ""], "--out names no folder"),
])
def test_bad_columns_and_empty_out_are_bad_usage(args, text, tmp_path):
    # they used to be taken: 0 and -2 columns as 1, "" as the current folder
    r = _stress("--case", "axis-x", "--size", "8x8", *args, cwd=tmp_path)
    assert r.returncode == 2 and text in r.stderr and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_unwritable_out_is_found_before_the_cases_run(monkeypatch, tmp_path, capsys):
    import errno
    from pathlib import Path

    from viewer.measure import outputs

    real = outputs.tempfile.mkstemp      # the write check's probe file

    def read_only(*a, dir=None, **kw):
        if Path(dir) == tmp_path / "res":
            raise OSError(errno.EROFS, "Read-only file system")
        return real(*a, dir=dir, **kw)

    monkeypatch.setattr(outputs.tempfile, "mkstemp", read_only)
    monkeypatch.setattr(stress_suite.Suite, "run_case", lambda *a: pytest.fail("a case ran before the folder was checked"))
    assert cli_stress.run(_args(tmp_path)) == 1
    assert "cannot write results there: Read-only file system" in capsys.readouterr().err


def test_full_disk_names_the_file(monkeypatch, tmp_path, capsys):
    import errno

    from viewer.base import files

    def full_disk(folder, name, data, mode):     # what every atomic write writes through
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(files, "_write_temp", full_disk)
    assert cli_stress.run(_args(tmp_path)) == 1
    cap = capsys.readouterr()
    assert "res/contact-sheet.png: cannot write: No space left on device" in cap.err
    assert "axis-x" in cap.out and "Traceback" not in cap.err
