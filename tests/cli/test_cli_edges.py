"""Edges of the command line an audit found (shared/spec/cli.md): a size
the driver cannot allocate, short soaks, --timing with debug views, special
files as scenes and skies, the file named by --light-position's error, and
an output that is a folder."""

from __future__ import annotations

import os
import re
import resource
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from test_cli import glassray

TIMING_LINE = r"render: \d+\.\d ms per frame \(median of {n}, {w}x{h}, {s} samples\)"

NO_POINT_LIGHT = """
name = "Only the sun"
[[lights]]
type = "directional"
direction = [0.0, -1.0, 0.0]
[materials.m]
[[objects]]
type = "plane"
material = "m"
"""

SKY_SCENE = """
name = "sky from a file"
[sky]
type = "image"
image = "{image}"
[materials.m]
[[objects]]
type = "plane"
material = "m"
"""


def bounded_glassray(*args, cwd=None, timeout=60):
    """glassray with its address space capped at 4 GiB: a scene loader that
    reads /dev/zero whole fails with MemoryError instead of taking the
    machine's memory."""
    def cap():
        resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))

    return subprocess.run([sys.executable, "-m", "viewer", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=timeout, preexec_fn=cap)


def one_message(r) -> str:
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    return lines[0]


# ---------------------------------------------------------------- 1. a size too large for the driver


def test_size_failure_names_the_size_and_the_driver():
    import moderngl
    from viewer.gpu.context import size_failure

    f = size_failure(moderngl.Error("the framebuffer is not complete (INCOMPLETE_ATTACHMENT)"), 16384, 8192)
    assert str(f).startswith("cannot render 16384x8192: the OpenGL driver could not allocate a framebuffer "
                             "of that size (try a smaller --size"), f
    assert "INCOMPLETE_ATTACHMENT" in str(f)                # the driver's own words, for a bug report
    assert "cannot render 64x64" in str(size_failure(moderngl.Error("GL_OUT_OF_MEMORY"), 64, 64))
    assert "not enough memory" in str(size_failure(MemoryError(), 12000, 12000))
    # any other error is not dressed up as a size problem
    assert size_failure(moderngl.Error("program link failed"), 64, 64) is None
    assert size_failure(ValueError("the framebuffer is not complete"), 64, 64) is None


def test_render_reports_a_framebuffer_the_driver_refuses(tmp_path, monkeypatch, capsys):
    # the driver refusing the sum framebuffer, whatever the size that makes
    # this driver refuse it
    import moderngl
    from viewer.cli import commands as cli
    from viewer.gpu.renderer import Renderer

    def refuse(self, width, height):
        raise moderngl.Error("the framebuffer is not complete (INCOMPLETE_ATTACHMENT)")

    monkeypatch.setattr(Renderer, "_target", refuse)
    out = tmp_path / "x.png"
    assert cli.main(["render", "-o", str(out), "--size", "32x18", "--samples", "1"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("glassray: cannot render 32x18: the OpenGL driver could not allocate a framebuffer "
                          "of that size (try a smaller --size"), err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


def _is_llvmpipe(gl) -> bool:
    return "llvmpipe" in gl.info.get("GL_RENDERER", "").lower()


def test_a_size_llvmpipe_cannot_allocate_fails_at_once_with_a_clear_message(gl, tmp_path):
    # llvmpipe refuses 16384x16384 RGBA32F at once; a GPU might render it
    # (minutes, gigabytes), so this is for llvmpipe only
    if not _is_llvmpipe(gl):
        pytest.skip("only llvmpipe is known to refuse this size quickly")
    r = glassray("render", "-o", tmp_path / "huge.png", "--samples", "1", "--size", "16384x16384")
    assert r.returncode == 1
    assert one_message(r).startswith("glassray: cannot render 16384x16384: the OpenGL driver could not "
                                     "allocate a framebuffer of that size (try a smaller --size"), r.stderr


# ---------------------------------------------------------------- viewer (Xvfb)

needs_x = pytest.mark.skipif(not shutil.which("Xvfb"), reason="needs Xvfb (make test installs it)")


def viewer_run(display: str, cwd: Path, *args: str):
    env = dict(os.environ, DISPLAY=display, XDG_CACHE_HOME=str(cwd / "cache"))
    env.pop("WAYLAND_DISPLAY", None)
    return subprocess.run([sys.executable, "-m", "viewer", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=240)


@needs_x
def test_viewer_reports_a_window_too_large_for_the_driver(xdisplay, tmp_path):
    # under Xvfb the context is llvmpipe's (GLX in software), which refuses it
    r = viewer_run(xdisplay, tmp_path, "view", "--size", "16384x16384", "--no-vsync", "--soak", "2")
    assert r.returncode == 1
    assert "glassray: cannot render 16384x16384: the OpenGL driver could not allocate a framebuffer " \
           "of that size (try a smaller --size" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


# ---------------------------------------------------------------- 2. short soaks


@needs_x
@pytest.mark.parametrize("frames, warmup", [(1, 0), (3, 1), (49, 24)])
def test_a_short_soak_runs_and_reports_both_counts(xdisplay, tmp_path, frames, warmup):
    r = viewer_run(xdisplay, tmp_path, "view", "--size", "64x36", "--no-vsync", "--soak", str(frames))
    assert r.returncode == 0, r.stderr
    m = re.search(r"soak: frames=(\d+) warmup=(\d+) rss_kb=(\d+)->(\d+) gl_objects=(\d+)->(\d+) "
                  r"culling_variants=(\d+)->(\d+)/(\d+) moving_frame_ms_median=(\S+)", r.stdout)
    assert m, r.stdout + r.stderr
    assert (int(m[1]), int(m[2])) == (frames, warmup)
    # no moving frame is timed in the first 11: no median rather than 0.0
    assert m[10] == "n/a" if frames <= 11 else float(m[10]) > 0


# ---------------------------------------------------------------- 3. --timing


@pytest.mark.parametrize("view", ["normals", "depth", "objects", "cost", "samples"])
def test_timing_a_debug_view_is_a_usage_error(tmp_path, view):
    r = glassray("render", "-o", tmp_path / "v.png", "--size", "32x18", "--samples", "1", "--view", view,
                 "--timing")
    assert r.returncode == 2
    assert one_message(r) == f"glassray: --timing times the colour image; it does not apply to --view {view}"
    assert not (tmp_path / "v.png").exists()


@pytest.mark.parametrize("args, says", [
    (["--view", "cost", "--adaptive"], "--view cost traces one centred ray per pixel; --adaptive does not apply"),
    (["--view", "depth", "--target-error", "0.01"],
     "--view depth traces one centred ray per pixel; --target-error does not apply"),
    (["--view", "objects", "--max-error", "0.02"],
     "--view objects shows the first hit, which --max-error's settings do not change; drop --max-error"),
    (["--target-error", "0.01", "--no-adaptive"], "--target-error is the adaptive render's target; drop --no-adaptive"),
])
def test_sampling_options_a_render_would_ignore_are_usage_errors(tmp_path, args, says):
    # silently dropped before: the picture was the same with or without them
    r = glassray("render", "-o", tmp_path / "v.png", "--size", "32x18", "--samples", "1", *args)
    assert r.returncode == 2
    assert one_message(r) == f"glassray: {says}"
    assert not (tmp_path / "v.png").exists()


def test_the_options_that_do_apply_to_a_view_still_work(tmp_path):
    # cost counts the rays the picked settings trace; --no-adaptive is the default anyway
    for args in (["--view", "cost", "--no-adaptive"], ["--view", "samples", "--target-error", "0.05"]):
        r = glassray("render", "-o", tmp_path / "v.npy", "--size", "32x18", "--samples", "2", *args)
        assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("extra", [[], ["--adaptive"]])
def test_the_timing_line_is_the_last_line_on_stderr(tmp_path, extra):
    r = glassray("render", "glass-sphere", "-o", tmp_path / "t.png", "--size", "32x18", "--samples", "4",
                 "--timing", "--repeat", "2", *extra)
    assert r.returncode == 0, r.stderr
    lines = r.stderr.strip().splitlines()
    assert re.fullmatch(TIMING_LINE.format(n=2, w=32, h=18, s=4), lines[-1]), r.stderr
    assert len([ln for ln in lines if "ms per frame" in ln]) == 1
    # --adaptive adds its one line (the mean samples per pixel), before it
    assert len(lines) == 1 + bool(extra), r.stderr
    assert (tmp_path / "t.png").is_file()


# ---------------------------------------------------------------- 4. special files as scenes


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/null"])
def test_a_device_is_not_a_scene(device):
    if not os.path.exists(device):
        pytest.skip(f"no {device}")
    r = bounded_glassray("check", device)
    assert r.returncode == 2
    assert one_message(r) == f"glassray: {device}: is not a regular file (it is a character device)"


def test_a_named_pipe_is_not_a_scene_and_does_not_hang(tmp_path):
    fifo = tmp_path / "scene.toml"
    os.mkfifo(fifo)
    for cmd in (["check", fifo], ["render", fifo, "-o", tmp_path / "x.png", "--size", "8x8"]):
        r = bounded_glassray(*cmd, timeout=30)
        assert r.returncode == 2
        assert one_message(r) == f"glassray: {fifo}: is not a regular file (it is a named pipe)"


def test_a_huge_scene_file_is_refused_unread(tmp_path):
    limit = 16 * 1024 * 1024                      # viewer.scene.MAX_SCENE_BYTES
    big = tmp_path / "big.toml"
    with open(big, "wb") as f:                    # sparse: nothing written
        f.truncate(limit + 1)
    r = bounded_glassray("check", big)
    assert r.returncode == 2
    assert one_message(r) == (f"glassray: {big}: {limit + 1} bytes is too large for a scene file "
                              "(at most 16 MiB)")
    ok = tmp_path / "ok.toml"                     # the limit is on the size, not on the kind of file
    ok.write_text(NO_POINT_LIGHT)
    assert glassray("check", ok).returncode == 0


@pytest.mark.parametrize("special", ["fifo", "device"])
def test_a_sky_image_that_is_not_a_regular_file_is_a_bad_scene(tmp_path, special):
    image = tmp_path / "sky.pfm"
    if special == "fifo":
        os.mkfifo(image)
    else:
        image.symlink_to("/dev/zero")
    scene = tmp_path / "sky.toml"
    scene.write_text(SKY_SCENE.format(image="sky.pfm"))
    r = bounded_glassray("check", scene, timeout=30)
    assert r.returncode == 2
    assert one_message(r) == f"glassray: {scene}: sky.image: {image} is not a regular file, not a picture"


# ---------------------------------------------------------------- 5. --light-position names the file


def test_light_position_without_a_point_light_names_the_scene_file(tmp_path):
    scene = tmp_path / "sun.toml"
    scene.write_text(NO_POINT_LIGHT)
    r = glassray("render", scene, "-o", tmp_path / "x.png", "--size", "8x8", "--light-position", "1,2,3")
    assert r.returncode == 2
    assert one_message(r) == f"glassray: {scene}: --light-position: the scene has no point light to move"
    # a built-in scene is named as it was given
    r = glassray("render", "whitted-exact", "-o", tmp_path / "x.png", "--light-position", "1,2,3")
    assert r.returncode == 2
    assert one_message(r).startswith("glassray: whitted-exact: --light-position: "), r.stderr


# ---------------------------------------------------------------- 6. outputs checked before rendering


@pytest.fixture
def no_rendering(monkeypatch):
    """Any attempt to render (an OpenGL context) fails the test."""
    from viewer import api

    def refuse(*a, **k):
        raise AssertionError("rendered before the output was checked")

    monkeypatch.setattr(api, "create_offscreen_context", refuse)   # the name render's Renderer makes its context with


@pytest.mark.parametrize("make, says", [
    (lambda d: (d / "out.png").mkdir() or d / "out.png", "out.png: cannot write: it is a folder, not a file"),
    (lambda d: d / "missing" / "out.png", "cannot write: folder {d}/missing does not exist"),
    (lambda d: (d / "f").write_bytes(b"x") and d / "f" / "out.png", "cannot write: folder {d}/f is a file, "
                                                                     "not a folder"),
])
def test_an_output_that_cannot_be_written_fails_before_rendering(tmp_path, no_rendering, capsys, make, says):
    from viewer.cli import commands as cli

    out = make(tmp_path)
    assert cli.main(["render", "-o", str(out), "--size", "8x8"]) == 1
    err = capsys.readouterr().err
    assert says.format(d=tmp_path) in err and len(err.strip().splitlines()) == 1, err


@needs_x
def test_the_viewer_warns_once_where_trees_may_be_cut(xdisplay, tmp_path):
    # the viewer traces a tree in one draw a sample: with trees far beyond
    # what llvmpipe's loop limit lets one draw trace it says so, once, at
    # the start (tests/test_depth_audit.py: render traces them whole)
    r = viewer_run(xdisplay, tmp_path, "view", "--size", "64x36", "--no-vsync", "--soak", "3",
                   "--max-depth", "20", "--min-weight", "0")
    assert r.returncode == 0, r.stderr
    assert r.stderr.count("glassray: warning: with max depth 20 and min weight 0") == 1, r.stderr
    assert "the viewer traces each tree in one draw" in r.stderr
    quiet = viewer_run(xdisplay, tmp_path, "view", "--size", "64x36", "--no-vsync", "--soak", "2")
    assert quiet.returncode == 0 and "warning" not in quiet.stderr, quiet.stderr


@pytest.mark.parametrize("argv, abbreviated", [
    (["render", "-o", "x.png", "--sample", "2"], "--sample"),
    (["render", "-o", "x.png", "--cam", "0,1,2"], "--cam"),
    (["view", "--no-vs"], "--no-vs"),
    (["bench", "--quic"], "--quic"),
    (["stress", "--lis"], "--lis"),
    (["check", "--deb"], "--deb"),
])
def test_options_are_taken_by_their_whole_names_only(argv, abbreviated, capsys):
    # argparse takes any unambiguous prefix by default: an interface the spec
    # does not define, and one that a new option would break
    from viewer.cli.commands import build_parser

    with pytest.raises(SystemExit) as e:
        build_parser().parse_args(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"unrecognized arguments: {abbreviated}" in err[0], err
    whole = build_parser().parse_args(["render", "-o", "x.png", "--samples", "2", "--camera-position=-1,2,3"])
    assert whole.samples == 2 and whole.camera_position == (-1.0, 2.0, 3.0)
