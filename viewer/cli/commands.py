"""Command line: ``glassray [view|render|check|bench|stress] ...``.

Exit status (shared/spec/cli.md): 0 success; 2 bad usage, a scene that is
missing, unreadable or invalid, or an output with an unknown extension; 1 any
other failure (no OpenGL context, an output that cannot be written).  One
clear message on stderr; a traceback only with --debug.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

from .. import api
from ..adaptive.render import DEFAULT_TARGET_ERROR
from ..base import interrupt
from ..base.errors import Failure, UsageError
from ..base.imageio import OUTPUT_EXTENSIONS, SkyImageError
from ..base.version import __version__
from ..gpu.context import ContextError, size_failure
from ..gpu.shaders import ShaderError
from ..measure.quality import scene_for_max_error
from ..scene.load import load_scene, printable, with_overrides
from ..scene.model import SceneError
from . import bench, stress
from .args import (
    Parser,
    add_common,
    add_overrides,
    float_range,
    int_range,
    max_error,
    size,
)

SUBCOMMANDS = ("view", "render", "check", "bench", "stress")
VECTOR_OPTIONS = ("--camera-position", "--camera-target", "--light-position")
#: Options whose value may start with a minus (argparse would take it for an
#: option): the vectors, and --size, whose range message is then the one shown.
DASH_VALUE_OPTIONS = VECTOR_OPTIONS + ("--size",)


def build_parser() -> argparse.ArgumentParser:

    parser = Parser(
        prog="glassray",
        description="A real-time Whitted ray tracer: a rod in a glass of liquid, traced in a fragment shader.",
        epilog="Without a subcommand, 'view' is run. See 'glassray SUBCOMMAND --help'.")
    parser.add_argument("--version", action="version", version=f"glassray {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="{view,render,check,bench,stress}")

    v = sub.add_parser("view", help="the interactive viewer (default)",
                       description="Open the interactive viewer on SCENE (the default scene without one).")
    v.add_argument("scene", nargs="?", metavar="SCENE", help="scene file or built-in scene name")
    v.add_argument("--size", type=size, default=(1280, 720), metavar="WxH", help="window size (1280x720)")
    v.add_argument("--vsync", action=argparse.BooleanOptionalAction, default=True, help="sync to the display")
    v.add_argument("--watch", action=argparse.BooleanOptionalAction, default=True,
                   help="reload when the scene file, its sky picture or (from a source checkout or "
                        "GLASSRAY_SHADERS) a shader is saved; F5 reloads either way")
    v.add_argument("--adaptive", action=argparse.BooleanOptionalAction, default=False,
                   help="once the view is still, add samples only where pixels still need them (off by "
                        "default: it reaches a given error sooner but then keeps tracing a still view several "
                        "times as long; the panel switches it too)")
    # hidden: `make run` checks that a window can be opened; the soak test drives N frames
    v.add_argument("--probe", action="store_true", help=argparse.SUPPRESS)
    v.add_argument("--soak", type=int_range(1, 10**7), default=0, metavar="N", help=argparse.SUPPRESS)
    add_overrides(v)
    add_common(v)

    r = sub.add_parser("render", help="render offscreen to .png, .npy or .pfm",
                       description="Render SCENE offscreen (EGL, OSMesa as a fallback) and write OUT "
                                   "by its extension: .png (8-bit sRGB), .npy (float32 HxWx3 linear), "
                                   ".pfm (linear float map).")
    r.add_argument("scene", nargs="?", metavar="SCENE", help="scene file or built-in scene name")
    r.add_argument("-o", "--output", required=True, metavar="OUT", help="output file (.png, .npy or .pfm)")
    r.add_argument("--size", type=size, default=(1280, 720), metavar="WxH", help="image size (1280x720)")
    r.add_argument("--seed", type=int_range(0, 2**63 - 1), default=0, metavar="N",
                   help="sample pattern seed (0); the same seed gives the same image")
    r.add_argument("--backend", choices=("auto", "egl", "osmesa"), default="auto",
                   help="OpenGL context: EGL, OSMesa, or EGL falling back to OSMesa (auto)")
    r.add_argument("--timing", action="store_true",
                   help="after a warm-up, render --repeat more times and print the median ms per frame")
    r.add_argument("--repeat", type=int_range(1, 1000), default=5, metavar="N", help="timed renders (5)")
    r.add_argument("--view", choices=("color", "normals", "depth", "objects", "cost", "samples"), default="color",
                   help="what to draw: the image (color), or the first hit's normals, distance or object, "
                        "or rays traced per pixel (cost), or samples per pixel of the adaptive render "
                        "(samples); PNG gets a legend, .npy/.pfm the raw values")
    r.add_argument("--adaptive", action=argparse.BooleanOptionalAction, default=None,
                   help="adaptive anti-aliasing: --samples is the mean per pixel, spent where a pixel's "
                        f"estimated error is above --target-error ({'on' if ADAPTIVE_DEFAULT else 'off'} by "
                        "default; on when --target-error is given)")
    r.add_argument("--target-error", type=float_range(0.0, 1e9, lo_open=True), metavar="E",
                   help="adaptive sampling's per-pixel error target, linear radiance on the largest channel "
                        f"(default {DEFAULT_TARGET_ERROR:g})")
    r.add_argument("--max-error", type=max_error, metavar="E",
                   help="use the fastest settings (samples, max depth, min weight) whose measured RMSE "
                        "(linear) against a converged reference is at most E; measured once per scene, size "
                        "and machine and cached; --samples/--max-depth/--min-weight fix their value")
    add_overrides(r)
    add_common(r)

    c = sub.add_parser("check", help="validate a scene file",
                       description="Validate SCENE (the default scene without one) and print a summary.")
    c.add_argument("scene", nargs="?", metavar="SCENE")
    add_common(c)

    # bench and stress own their options (cli/bench.py, cli/stress.py:
    # add_arguments(parser) and run(args) -> exit status).
    for name, mod, text in (("bench", bench, "the speed-against-error benchmark"),
                            ("stress", stress, "the numerical stability suite")):
        b = sub.add_parser(name, help=text, description=mod.DESCRIPTION)
        mod.add_arguments(b)
        add_common(b)
    parser.subcommands = sub.choices      # name -> its parser (main() reports leftovers with it)
    return parser


def normalise_argv(argv: list[str]) -> list[str]:
    """Default subcommand and vector (and size) values with a leading minus:
    ``--camera-position -1,2,3`` becomes ``--camera-position=-1,2,3``
    (options are whole names only: see args.Parser)."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        a = argv[i]
        takes_dash = a in DASH_VALUE_OPTIONS
        if takes_dash and i + 1 < len(argv) and argv[i + 1].startswith("-") and argv[i + 1][1:2] not in ("-", ""):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    first = next((a for a in out if not a.startswith("-")), None)
    wants_top_level = any(a in ("-h", "--help", "--version") for a in out) and first is None
    if not wants_top_level and (first is None or first not in SUBCOMMANDS):
        out = ["view", *out]
    return out


# ---------------------------------------------------------------- commands


def _load(args) -> "object":

    scene = load_scene(args.scene)
    overrides = {k: getattr(args, k, None) for k in ("samples", "max_depth", "min_weight", "camera_position",
                                                      "camera_target", "fov", "light_position")}
    return with_overrides(scene, **overrides)


#: A render shows its progress bar once it has taken this long.
PROGRESS_AFTER_S = 0.5
#: and draws it again at most this often: a render calls back after every
#: tile, hundreds of times a second, and each redraw is a line of text (a
#: 4-second render wrote about 75 KB to the terminal)
PROGRESS_EVERY_S = 0.1


def _progress_bar(label: str, again: str | None = None):
    """A progress callback drawing a bar on stderr when it is a terminal:
    only for renders longer than PROGRESS_AFTER_S (a short one stays quiet),
    and erased when done (so --timing leaves its one line).  A count that
    goes back (render() drawing the image again in resumable passes after
    the driver cut ray trees) starts the bar over, labelled `again`, with
    its own clock for the estimate."""
    if not sys.stderr.isatty():
        return None
    start = [time.perf_counter()]
    shown = [0]                               # width of the line drawn (0: none)
    last = [0]
    name = [label]
    drawn_at = [-float("inf")]

    def show(done: int, total: int) -> None:
        restart = done < last[0]
        if restart:
            start[0] = time.perf_counter()
            name[0] = again or label
        last[0] = done
        frac = done / total
        now = time.perf_counter()
        elapsed = now - start[0]
        if done >= total:
            if shown[0]:
                sys.stderr.write("\r" + " " * shown[0] + "\r")
                sys.stderr.flush()
            return
        if elapsed < PROGRESS_AFTER_S or (now - drawn_at[0] < PROGRESS_EVERY_S and not restart):
            return
        drawn_at[0] = now
        bar = "#" * int(30 * frac)
        eta = elapsed / frac - elapsed if frac > 0 else 0.0
        line = f"{name[0]} [{bar:<30}] {100 * frac:5.1f}%  {elapsed:5.1f}s  eta {eta:5.1f}s"
        sys.stderr.write("\r" + line + " " * max(0, shown[0] - len(line)))
        sys.stderr.flush()
        shown[0] = max(shown[0], len(line))
    return show


# Adaptive anti-aliasing is off unless asked for: --samples N then keeps the
# spec's meaning (N samples in every pixel); README "Adaptive anti-aliasing"
# has the measurements.
ADAPTIVE_DEFAULT = False


def _adaptive(args) -> bool:
    if args.adaptive is not None:
        return args.adaptive
    return ADAPTIVE_DEFAULT or args.target_error is not None or args.view == "samples"


def cmd_render(args) -> int:


    out = Path(args.output)
    shown = printable(args.output)           # (a newline in the name would break the one-line message)
    if out.suffix.lower() not in OUTPUT_EXTENSIONS:
        what = f"unknown output extension {out.suffix!r}" if out.suffix else "no output extension"
        raise UsageError(f"{shown}: {what} (expected .png, .npy or .pfm)")
    scene = _load(args)
    parent = out.parent if str(out.parent) else Path(".")
    # every check of the output that is cheap and certain comes before the
    # render (which can take minutes); the atomic write stays the real one
    try:
        if out.is_dir():
            raise Failure(f"{shown}: cannot write: it is a folder, not a file")
        if not parent.is_dir():
            what = "is a file, not a folder" if parent.exists() else "does not exist"
            raise Failure(f"{shown}: cannot write: folder {printable(str(parent))} {what}")
        if not os.access(parent, os.W_OK):
            raise Failure(f"{shown}: cannot write: folder {printable(str(parent))} is not writable")
        # the atomic write (a rename) would replace a read-only file: refuse, as a
        # plain open() would
        if out.is_file() and not os.access(out, os.W_OK):
            raise Failure(f"{shown}: cannot write: the file is read-only")
    except OSError as e:
        # what pathlib's tests raise instead of answering: a name too long
        # for the file system (ENAMETOOLONG), a folder on the way that
        # cannot be searched
        raise Failure(f"{shown}: cannot write: {e.strerror or e}") from None

    adaptive = _adaptive(args)
    if args.view == "samples" and not adaptive:      # bad usage: before any OpenGL
        raise UsageError("--view samples shows an adaptive render's samples per pixel; drop --no-adaptive")
    if args.target_error is not None and args.adaptive is False:
        raise UsageError("--target-error is the adaptive render's target; drop --no-adaptive")
    first_hit_or_cost = args.view in ("normals", "depth", "objects", "cost")
    if first_hit_or_cost and (args.adaptive or args.target_error is not None):
        # these views trace one centred ray per pixel: sampling options would be ignored
        given = "--adaptive" if args.adaptive else "--target-error"
        raise UsageError(f"--view {args.view} traces one centred ray per pixel; {given} does not apply")
    if args.view in ("normals", "depth", "objects") and getattr(args, "max_error", None) is not None:
        # the settings --max-error picks (samples, depth, weight) never change a first hit
        raise UsageError(f"--view {args.view} shows the first hit, which --max-error's settings do not change; "
                         "drop --max-error")
    if args.timing and args.view != "color":
        # the spec's line is the time of the image; a debug picture's would
        # pass for it and tell nothing about rendering
        raise UsageError(f"--timing times the colour image; it does not apply to --view {args.view}")


    try:
        r = api.Renderer(args.backend)
    except ContextError as e:
        raise Failure(str(e)) from e
    w, h = args.size
    timing = None
    try:
        if getattr(args, "max_error", None) is not None:
            scene = scene_for_max_error(r.context, scene, args, w, h, progress=_progress_bar("max-error: measuring"))
        samples = scene.render.samples
        # (the scene carries the overrides: _load applied them)
        draw = r.prepare(scene, size=(w, h), adaptive=adaptive, target_error=args.target_error,
                         view=args.view, seed=args.seed)
        one_draw = "the adaptive render" if adaptive and args.view in ("color", "samples") else (
            "the cost view" if args.view == "cost" else None)
        warning = r.one_draw_warning(one_draw) if one_draw else None
        if warning:
            print(warning, file=sys.stderr)
        again = f"render {w}x{h} again in passes (ray trees were cut)"
        image = draw(_progress_bar(f"render {w}x{h}", again=again) if args.view in ("color", "samples") else None)
        if adaptive and args.view == "color":
            target = args.target_error if args.target_error is not None else DEFAULT_TARGET_ERROR
            print(f"render: adaptive, {image.info['mean_spp']:.2f} samples per pixel on average "
                  f"(budget {samples}, target error {target:g})", file=sys.stderr)
        if args.timing:
            med = statistics.median(time_frames(draw, args.repeat))
            # exactly the contract's line (the adaptive line above tells the mode)
            timing = f"render: {med:.1f} ms per frame (median of {args.repeat}, {w}x{h}, {samples} samples)"
    except api.RenderError as e:
        raise (size_failure(e.__cause__, w, h) or Failure(str(e))) from e
    finally:
        r.close()
    try:
        api.save_image(image, out)
    except OSError as e:
        raise Failure(f"{shown}: cannot write: {e.strerror or e}") from e
    if timing is not None:
        print(timing, file=sys.stderr)       # the last line on stderr, whatever came before
    return 0


def time_frames(draw, repeat: int) -> list[float]:
    """Wall-clock ms of `repeat` calls of draw() after one warm-up (the image
    is read back, so the GPU has finished before each clock stops)."""
    draw()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        draw()
        times.append((time.perf_counter() - t0) * 1000.0)
    return times


def cmd_check(args) -> int:

    scene = load_scene(args.scene)
    print(scene.summary())
    return 0


def cmd_view(args) -> int:
    _load(args)  # a bad scene is exit 2, as in every subcommand, display or not
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise Failure("no display: the viewer needs a window (DISPLAY is not set). "
                      "Render offscreen instead: glassray render -o out.png")
    try:
        from ..window import app, backend    # glfw, imgui-bundle: only for the viewer
    except ImportError as e:
        raise Failure(f"the interactive viewer cannot start ({e}); "
                      "render offscreen instead: glassray render -o out.png") from None
    if args.probe:
        try:
            return backend.probe(args)
        except backend.WindowError as e:
            raise Failure(str(e)) from None
    return app.run(args, _load)


COMMANDS = {"view": cmd_view, "render": cmd_render, "check": cmd_check,
            "bench": bench.run, "stress": stress.run}


def _quiet_stdout() -> None:
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        return                       # not a file (a test's capture): nothing left to flush into a pipe
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, fd)
    finally:
        os.close(devnull)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args, extra = parser.parse_known_args(normalise_argv(argv))
    if extra:
        # as parse_args would, but with the subcommand's usage line
        parser.subcommands.get(args.command, parser).error(f"unrecognized arguments: {' '.join(extra)}")
    if args.command is None:
        parser.print_help()
        return 0
    # a scene name or path the terminal's encoding cannot show (a snowman
    # under PYTHONIOENCODING=ascii) is written escaped, not a crash
    for stream in (sys.stdout, sys.stderr):
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")


    try:
        # Ctrl-C is taken between draw calls only (viewer/base/interrupt.py: one
        # arriving inside a shader compile crashed llvmpipe)
        with interrupt.deferred():
            return COMMANDS[args.command](args)
    except (SceneError, UsageError) as e:
        print(f"glassray: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("glassray: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader of stdout went away (`glassray stress --list | head -1`):
        # stop quietly, as the tools around it do; stdout goes to /dev/null so
        # the interpreter's final flush does not report the pipe again
        _quiet_stdout()
        return 1
    except (Failure, ShaderError, SkyImageError) as e:
        if args.debug:
            raise
        print(f"glassray: {e}", file=sys.stderr)
        return 1
    except Exception as e:  # anything unexpected: still one line, traceback with --debug
        if args.debug:
            raise
        print(f"glassray: {type(e).__name__}: {e} (run with --debug for the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
