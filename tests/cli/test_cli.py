"""The command line as users and outside checks drive it (shared/spec/cli.md):
exit codes, output formats and their orientation, overrides, messages."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from viewer.base.imageio import read_pfm, to_display8


def glassray(*args, cwd=None, env=None):
    e = dict(os.environ)
    e.update(env or {})
    return subprocess.run([sys.executable, "-m", "viewer", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, env=e, timeout=300)


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """The default scene at 40x24 as npy, pfm and png (samples 1)."""
    d = tmp_path_factory.mktemp("out")
    for ext in ("npy", "pfm", "png"):
        r = glassray("render", "-o", d / f"img.{ext}", "--size", "40x24", "--samples", "1")
        assert r.returncode == 0, r.stderr
    return d


def test_npy_is_float32_hxwx3_top_row_first(outputs):
    img = np.load(outputs / "img.npy")
    assert img.dtype == np.float32 and img.shape == (24, 40, 3)
    # top row is sky (gradient toward zenith: blue > red), bottom row is floor (grey)
    top, bottom = img[0].mean(axis=0), img[-1].mean(axis=0)
    assert top[2] > top[0] + 0.05
    assert abs(bottom[2] - bottom[0]) < 0.02


def test_pfm_is_the_same_data_stored_bottom_to_top(outputs):
    raw = (outputs / "img.pfm").read_bytes()
    assert raw.startswith(b"PF\n40 24\n-1.0\n")
    body = np.frombuffer(raw[len(b"PF\n40 24\n-1.0\n"):], "<f4").reshape(24, 40, 3)
    npy = np.load(outputs / "img.npy")
    np.testing.assert_array_equal(body[::-1], npy)   # first stored row = bottom of the image
    np.testing.assert_array_equal(read_pfm(outputs / "img.pfm"), npy)


def test_png_is_the_srgb_encoding_of_the_linear_image(outputs):
    png = np.asarray(Image.open(outputs / "img.png"))
    assert png.dtype == np.uint8 and png.shape == (24, 40, 3)
    npy = np.load(outputs / "img.npy")
    # the spec's encoding, computed independently here
    x = np.clip(npy.astype(np.float64), 0, 1)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    expect = np.round(255 * srgb).astype(np.uint8)
    assert np.array_equal(png, expect)
    assert np.array_equal(to_display8(npy), expect)


def test_timing_prints_the_median_line(tmp_path):
    r = glassray("render", "-o", tmp_path / "t.png", "--size", "16x16", "--samples", "1", "--timing",
                 "--repeat", "3")
    assert r.returncode == 0, r.stderr
    assert re.search(r"^render: \d+\.\d ms per frame \(median of 3, 16x16, 1 samples\)$", r.stderr, re.M)
    assert (tmp_path / "t.png").is_file()


def test_overrides_change_the_image_and_leading_minus_vectors_work(tmp_path):
    a, b = tmp_path / "a.npy", tmp_path / "b.npy"
    assert glassray("render", "-o", a, "--size", "24x16", "--samples", "1").returncode == 0
    r = glassray("render", "-o", b, "--size", "24x16", "--samples", "1", "--camera-position", "-3.2,2.2,4.6")
    assert r.returncode == 0, r.stderr
    r2 = glassray("render", "-o", tmp_path / "c.npy", "--size", "24x16", "--samples", "1",
                  "--camera-position=-3.2,2.2,4.6")
    assert r2.returncode == 0, r2.stderr
    assert not np.array_equal(np.load(a), np.load(b))
    np.testing.assert_array_equal(np.load(b), np.load(tmp_path / "c.npy"))


def test_same_seed_same_image(tmp_path):
    for name in ("a", "b"):
        assert glassray("render", "glass-sphere", "-o", tmp_path / f"{name}.npy", "--size", "24x16",
                        "--samples", "4", "--seed", "7").returncode == 0
    np.testing.assert_array_equal(np.load(tmp_path / "a.npy"), np.load(tmp_path / "b.npy"))


@pytest.mark.parametrize("args", [
    ["render", "-o", "x.bmp"],                                   # unknown extension
    ["render", "-o", "x"],                                       # no extension
    ["render", "no-such-scene.toml", "-o", "x.png"],             # missing scene
    ["render", "-o", "x.png", "--size", "0x10"],
    ["render", "-o", "x.png", "--size", "banana"],
    ["render", "-o", "x.png", "--samples", "0"],
    ["render", "-o", "x.png", "--max-depth", "65"],
    ["render", "-o", "x.png", "--min-weight", "2"],
    ["render", "-o", "x.png", "--fov", "180"],
    ["render", "-o", "x.png", "--camera-position", "1,2"],
    ["render", "-o", "x.png", "--camera-position", "1,2,nan"],
    ["render", "-o", "x.png", "--camera-target", "3.2,2.2,4.6"],  # target == position
    ["render", "whitted-exact", "-o", "x.png", "--light-position", "1,2,3"],  # no point light
    ["render", "-o", "x.png", "--backend", "vulkan"],
    ["render"],                                                  # -o is required
    ["render", "-o", "x.png", "--bogus"],
    ["render", "-o", "x.png", "--size", "-16x9"],                # a size with a minus is a bad size
    ["check", "no-such-scene.toml"],
    ["check", ""],                                               # an empty scene path
    ["check", "a.toml", "b.toml"],
])
def test_bad_usage_exits_2_with_one_message(tmp_path, args):
    r = glassray(*args, cwd=tmp_path)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr     # cli.md: one clear message
    assert not (tmp_path / "x.png").exists()


def test_a_usage_error_is_one_line_that_says_where_the_usage_is(tmp_path):
    # argparse printed render's nine-line usage block before the error
    r = glassray("render", "-o", "x.png", "--samples", "0", cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr.splitlines() == ["glassray render: error: argument --samples: expected an integer in "
                                     "1..65536, got 0 (see 'glassray render --help')"]


def test_without_a_scene_the_shipped_default_is_used_whatever_the_folder_holds(tmp_path):
    # cli.md: "without one, the built-in default scene is used"; a file or a
    # folder named `default` in the current folder took its place
    import tomllib
    from importlib import resources

    shipped = tomllib.loads((resources.files("viewer.scene.builtin") / "default.toml").read_text())
    want = f"{len(shipped['objects'])} objects"
    (tmp_path / "with-file").mkdir()
    (tmp_path / "with-file" / "default").write_text('[sky]\ntype = "color"\ncolor = [0.25, 0.5, 1.0]\n')
    (tmp_path / "with-folder" / "default").mkdir(parents=True)
    for cwd in (tmp_path / "with-file", tmp_path / "with-folder"):
        r = glassray("check", cwd=cwd)
        assert r.returncode == 0 and want in r.stdout, (cwd, r.stdout, r.stderr)
    r = glassray("render", "-o", "x.npy", "--size", "8x4", "--samples", "1", cwd=tmp_path / "with-file")
    assert r.returncode == 0, r.stderr
    assert not np.allclose(np.load(tmp_path / "with-file" / "x.npy"), [0.25, 0.5, 1.0])
    # named, the file in the folder is what is read (a path as given)
    r = glassray("check", "default", cwd=tmp_path / "with-file")
    assert r.returncode == 0 and "0 objects" in r.stdout, r.stdout


@pytest.mark.parametrize("args, says", [
    (["render", "-o", "x.png", "--bogus"], "glassray render: error: unrecognized arguments: --bogus"),
    (["check", "a.toml", "b.toml"], "glassray check: error: unrecognized arguments: b.toml"),
    (["render", "-o", "x.png", "--size", "-16x9"], "width and height must be in 1..16384, got '-16x9'"),
    (["check", ""], "empty scene path"),
    (["render", "-o", "x", "--size", "8x8"], "x: no output extension (expected .png, .npy or .pfm)"),
    (["render", "-o", "x.jpg", "--size", "8x8"], "x.jpg: unknown output extension '.jpg'"),
])
def test_usage_messages_say_what_is_wrong(tmp_path, args, says):
    # leftover arguments are reported with the subcommand's own usage line
    r = glassray(*args, cwd=tmp_path)
    assert r.returncode == 2 and says in r.stderr, r.stderr
    usage = [line for line in r.stderr.splitlines() if line.startswith("usage:")]
    assert not usage or usage[0].startswith(f"usage: glassray {args[0]} ")


def test_output_under_a_file_says_the_folder_is_a_file(tmp_path):
    (tmp_path / "base.png").write_bytes(b"old")
    r = glassray("render", "-o", tmp_path / "base.png" / "x.png", "--size", "8x8")
    assert r.returncode == 1 and "base.png is a file, not a folder" in r.stderr
    assert (tmp_path / "base.png").read_bytes() == b"old"


def test_a_read_only_output_file_is_not_replaced(tmp_path, monkeypatch, capsys):
    # The atomic write (a rename) could replace a read-only file; it must
    # fail as a plain write would.  os.access is what the check asks (root
    # would pass it, so it is answered here as for another user).
    from viewer.cli import commands as cli

    old = tmp_path / "x.png"
    old.write_bytes(b"old")
    real = os.access
    monkeypatch.setattr(cli.os, "access", lambda p, mode: False if Path(p) == old else real(p, mode))
    assert cli.main(["render", "-o", str(old), "--size", "8x8"]) == 1
    assert "x.png: cannot write: the file is read-only" in capsys.readouterr().err
    assert old.read_bytes() == b"old"


def test_view_checks_the_scene_before_the_display(tmp_path):
    # a bad scene is exit 2 in every subcommand, also without a display
    env = {"DISPLAY": "", "WAYLAND_DISPLAY": ""}
    r = glassray("view", tmp_path / "missing.toml", env=env)
    assert r.returncode == 2 and "missing.toml" in r.stderr and "Traceback" not in r.stderr


class _Tty:
    """A terminal for the progress bar: stderr that says it is a tty, and a
    clock the test moves (viewer.cli's perf_counter)."""

    def __init__(self, monkeypatch):
        from viewer.cli import commands as cli

        self.monkeypatch, self.clock = monkeypatch, [100.0]
        monkeypatch.setattr(cli.time, "perf_counter", lambda: self.clock[0])
        self.new_stderr()

    def new_stderr(self):
        import io

        from viewer.cli import commands as cli

        class Tty(io.StringIO):
            def isatty(self):
                return True

        self.err = Tty()
        self.monkeypatch.setattr(cli.sys, "stderr", self.err)
        return self.err


def test_the_progress_bar_waits_for_a_long_render_and_is_erased(monkeypatch):
    from viewer.cli import commands as cli

    tty = _Tty(monkeypatch)
    clock = tty.clock
    for long in (False, True):
        err = tty.new_stderr()
        show = cli._progress_bar("render 8x8")
        show(1, 4)                                 # at once: nothing yet
        assert err.getvalue() == ""
        if long:
            clock[0] += 2 * cli.PROGRESS_AFTER_S
            show(2, 4)
            assert "render 8x8 [" in err.getvalue() and "50.0%" in err.getvalue()
        show(4, 4)
        out = err.getvalue()
        # a short render draws nothing; a long one ends on an erased line,
        # so that what follows (the --timing line) is the only text left
        if long:
            assert out.endswith("\r") and out.rsplit("\r", 2)[1].strip() == ""
        else:
            assert out == ""


def test_the_progress_bar_is_drawn_at_most_ten_times_a_second(monkeypatch):
    # a render calls back after every tile: 1000 calls in 2 s must not be
    # 1000 lines of terminal text (a 4 s render wrote about 75 KB)
    from viewer.cli import commands as cli

    tty = _Tty(monkeypatch)
    clock, err = tty.clock, tty.err
    show = cli._progress_bar("render 8x8")
    for done in range(1000):
        show(done, 1000)
        clock[0] += 0.002 + 0.5 * (done == 0)    # past PROGRESS_AFTER_S, then 2 ms a tile
    draws = err.getvalue().count("\r")
    assert 10 <= draws <= 1 + 2.0 / cli.PROGRESS_EVERY_S + 1, draws
    last = float(err.getvalue().rsplit("\r", 1)[1].split("]")[1].split("%")[0])
    assert last >= 90.0, last                    # it still follows the render to its end
    show(1000, 1000)
    assert err.getvalue().endswith("\r")


def test_the_progress_bar_starts_over_when_render_draws_again_in_passes(monkeypatch):
    # render() reports the count going back when a cut tree makes it draw the
    # image again: the bar is labelled so and its estimate uses its own clock
    from viewer.cli import commands as cli

    tty = _Tty(monkeypatch)
    clock, err = tty.clock, tty.err
    show = cli._progress_bar("render 8x8", again="render 8x8 again")
    clock[0] += 10.0
    show(4, 4)                                   # the one-pass image: 10 s
    show(0, 8)                                   # cut: drawn again in 8 parts
    clock[0] += 1.0
    show(2, 8)                                   # a quarter in 1 s
    line = err.getvalue().rsplit("\r", 1)[1]
    assert line.startswith("render 8x8 again [") and "25.0%" in line
    assert "1.0s" in line and "eta   3.0s" in line, line


def test_a_tiny_directional_light_direction_lights_as_any_other_length(tmp_path):
    # non-zero is all the spec asks; 1e-320 must not underflow to a zero length
    scene = ('[materials.m]\n[[objects]]\ntype = "sphere"\ncenter = [0, 0.9, 0]\nradius = 0.5\nmaterial = "m"\n'
             '[[lights]]\ntype = "directional"\ndirection = {d}\n')
    images = []
    for d in ("[1e-320, -1e-320, 0]", "[1, -1, 0]", "[1e300, -1e300, 0]"):
        f = tmp_path / "s.toml"
        f.write_text(scene.format(d=d))
        r = glassray("render", f, "-o", tmp_path / "s.npy", "--size", "32x18", "--samples", "1")
        assert r.returncode == 0, r.stderr
        images.append(np.load(tmp_path / "s.npy"))
    assert np.isfinite(images[1]).all() and images[1].max() > 0.5
    for img in images:
        np.testing.assert_array_equal(img, images[1])


def test_invalid_scene_exits_2_naming_file_and_key(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[[objects]]\ntype = "sphere"\ncenter = [0, 0, 0]\nradius = -1\nmaterial = "m"\n'
                   '[materials.m]\n')
    for cmd in (["check", bad], ["render", bad, "-o", tmp_path / "x.png"]):
        r = glassray(*cmd)
        assert r.returncode == 2
        assert str(bad) in r.stderr and "objects[0].radius" in r.stderr
        assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_unwritable_output_exits_1_and_keeps_old_files(tmp_path):
    r = glassray("render", "-o", tmp_path / "missing" / "x.png", "--size", "8x8")
    assert r.returncode == 1 and "Traceback" not in r.stderr
    # an existing output that cannot be replaced is left as it was
    ro = tmp_path / "ro"
    ro.mkdir()
    old = ro / "x.png"
    old.write_bytes(b"old")
    ro.chmod(0o500)
    try:
        if os.access(ro, os.W_OK):  # root ignores permissions
            pytest.skip("running as root: permissions do not stop writes")
        r = glassray("render", "-o", old, "--size", "8x8")
        assert r.returncode == 1
        assert old.read_bytes() == b"old"
    finally:
        ro.chmod(0o700)


def test_output_write_is_atomic(tmp_path, monkeypatch):
    # A failing write (simulated at the rename) leaves the old file untouched
    # and no temporary file behind.
    from viewer.base import imageio
    from viewer.base import files

    out = tmp_path / "img.npy"
    out.write_bytes(b"precious")

    def boom(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(files.os, "replace", boom)
    with pytest.raises(OSError):
        imageio.write_image(out, np.zeros((2, 2, 3), np.float32))
    assert out.read_bytes() == b"precious"
    assert [p.name for p in tmp_path.iterdir()] == ["img.npy"]


def test_outputs_get_ordinary_file_permissions(outputs):
    # atomic writes go through a private temporary file; the result must not
    # stay private (0600) but get the mode a plain write would give
    umask = os.umask(0)
    os.umask(umask)
    for ext in ("npy", "pfm", "png"):
        assert (outputs / f"img.{ext}").stat().st_mode & 0o777 == 0o666 & ~umask


def test_check_prints_a_one_line_summary():
    r = glassray("check")
    assert r.returncode == 0
    line = r.stdout.strip()
    assert len(line.splitlines()) == 1
    assert "5 objects" in line and "1 light;" in line and "dielectric" in line and "absorption" in line
    r = glassray("check", "mirror-ball")
    assert r.returncode == 0 and "dielectric" not in r.stdout and "reflection" in r.stdout


def test_every_subcommand_has_help():
    for sub in ("view", "render", "check", "bench", "stress"):
        r = glassray(sub, "--help")
        assert r.returncode == 0 and "usage:" in r.stdout
    assert glassray("--help").returncode == 0


def test_view_without_display_fails_with_a_hint():
    env = {"DISPLAY": "", "WAYLAND_DISPLAY": ""}
    for args in ([], ["view"]):
        r = glassray(*args, env=env)
        assert r.returncode == 1
        assert "glassray render" in r.stderr and "Traceback" not in r.stderr


def test_python_dash_m_and_console_script_agree():
    script = Path(sys.executable).parent / "glassray"
    if not script.exists():
        pytest.skip("console script not installed in this environment")
    r = subprocess.run([str(script), "check"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stdout == glassray("check").stdout


def test_osmesa_backend_renders_the_same_image(tmp_path):
    a, b = tmp_path / "egl.npy", tmp_path / "osmesa.npy"
    assert glassray("render", "-o", a, "--size", "32x18", "--samples", "1", "--backend", "egl").returncode == 0
    r = glassray("render", "-o", b, "--size", "32x18", "--samples", "1", "--backend", "osmesa")
    assert r.returncode == 0, r.stderr
    # both are Mesa llvmpipe: the same compiler, so (nearly) the same numbers
    assert np.max(np.abs(np.load(a) - np.load(b))) < 1e-4


@pytest.mark.parametrize("delay", [1.0, 4.0])
def test_ctrl_c_ends_a_long_render_cleanly(tmp_path, delay):
    # At 1 s the shaders are being compiled (Mesa's shader cache is off, so
    # they really are): a Ctrl-C there crashed llvmpipe (SIGSEGV) before
    # viewer/base/interrupt.py deferred it to the next draw call; at 4 s it is
    # rendering.  Another run once took 47 s to stop: Python had left the
    # signal to a BLAS thread.
    import signal
    import time

    out = tmp_path / "long.png"
    env = dict(os.environ, MESA_SHADER_CACHE_DISABLE="true")
    p = subprocess.Popen([sys.executable, "-m", "viewer", "render", "-o", str(out), "--size", "640x360",
                          "--samples", "256"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    time.sleep(delay)
    assert p.poll() is None, "the render should still be running"
    t0 = time.monotonic()
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert time.monotonic() - t0 < 15
    assert p.returncode == 130
    assert err.count("interrupted") == 1 and "Traceback" not in err, err
    assert not out.exists()


def test_one_ctrl_c_is_taken_once():
    # One SIGINT reaches interrupt.py twice: the C-level handler writes it to
    # the wakeup pipe (in whichever thread took it) and the Python-level one
    # runs later in the main thread.  check() reading the pipe before the
    # latter ran, a flag it set was a second Ctrl-C when deferred() ended:
    # "glassray: interrupted" printed twice (bench, Ctrl-C in its timed rounds).
    import signal

    from viewer.base import interrupt

    try:
        with interrupt.deferred():
            os.write(interrupt._pipe[1], bytes([signal.SIGINT]))     # the C-level handler's part
            with pytest.raises(KeyboardInterrupt):
                interrupt.check()                                    # taken here
            signal.getsignal(signal.SIGINT)(signal.SIGINT, None)     # then the Python-level handler runs
            interrupt.check()                                        # nothing more to take
    except KeyboardInterrupt:         # (caught: one escaping would stop pytest itself)
        pytest.fail("one Ctrl-C was taken twice")


def test_check_stays_one_line_for_a_name_with_a_newline(tmp_path):
    (tmp_path / "s.toml").write_text('name = "two\\nlines"\n')
    r = glassray("check", tmp_path / "s.toml")
    assert r.returncode == 0, r.stderr
    assert r.stdout == "two\\nlines: 0 objects, 0 materials, 0 lights; features: sky:gradient\n"


def test_a_vector_option_takes_a_leading_minus_and_abbreviations_are_refused():
    from viewer.cli.commands import build_parser, normalise_argv

    parser = build_parser()
    full = parser.parse_args(normalise_argv(["render", "-o", "x.png", "--camera-position", "-1,2,3"]))
    joined = parser.parse_args(normalise_argv(["render", "-o", "x.png", "--camera-position=-1,2,3"]))
    assert joined.camera_position == full.camera_position == (-1.0, 2.0, 3.0)
    # options are whole names only (tests/test_cli_edges.py): an abbreviation is bad usage (exit 2)
    for short in ("--camera-pos", "--camera"):
        with pytest.raises(SystemExit) as e:
            parser.parse_args(normalise_argv(["render", "-o", "x.png", short, "-1,2,3"]))
        assert e.value.code == 2
    # a value that is an option is not swallowed
    assert normalise_argv(["render", "--camera-position", "--debug"])[-2:] == ["--camera-position", "--debug"]


def test_a_reader_that_goes_away_ends_it_quietly():
    # `glassray stress --list | head -1`: the pipe's reader is gone before
    # the listing is written; it printed "glassray: BrokenPipeError: ..."
    p = subprocess.Popen([sys.executable, "-m", "viewer", "stress", "--list"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()                     # long before the child has imported what it needs
    _, err = p.communicate(timeout=120)
    assert err.decode() == "" and p.returncode == 1
