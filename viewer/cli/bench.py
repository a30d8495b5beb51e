"""``glassray bench``: its options, and the command that checks them, loads
the scenes, makes the OpenGL context and runs the sweep
(viewer/measure/bench.py) or the peer comparison (viewer/measure/peer.py).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from ..gpu.context import ContextError, create_offscreen_context
from ..measure import bench
from ..measure.bench import (DEFAULT_REFERENCE_SAMPLES, DEFAULT_REPEAT, DEFAULT_SCENES, DEFAULT_SIZE,
                             QUICK_REFERENCE_SAMPLES, log_progress, run_sweep)
from ..measure.outputs import OutputError, remove_if_empty, results_folder_problem
from ..measure.peer import run_bench
from ..measure.peer_check import PeerError, check_scene
from ..measure.reference_cache import REFINE_TOLERANCE
from ..measure.sweep import DEFAULT_ERROR_TOLERANCE, DEFAULT_TIME_TOLERANCE
from ..scene.load import builtin_scene_names, load_scene, resolve_scene_path
from ..scene.model import SceneError
from .args import int_range, size_type

#: The subcommand's description (``glassray bench --help``): the first line
#: of the benchmark's own docstring
DESCRIPTION = bench.__doc__.strip().splitlines()[0]

def _fraction(text: str) -> float:
    """argparse type of the tolerances: a number in [0, 1)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0.0 <= v < 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1), got {text!r}")
    return v


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``glassray bench``."""
    p.add_argument("scene", nargs="?", metavar="SCENE",
                   help="benchmark only this scene (file or built-in name); default: "
                        + ", ".join(DEFAULT_SCENES))
    p.add_argument("--scenes", metavar="A,B,C", help="comma-separated scenes to benchmark (instead of SCENE)")
    p.add_argument("--size", type=size_type(), default=DEFAULT_SIZE, metavar="WxH",
                   help="full image size; error is measured at this size (%dx%d)" % DEFAULT_SIZE)
    p.add_argument("--repeat", type=int_range(1, 1000), default=DEFAULT_REPEAT, metavar="N",
                   help=f"timed renders per setting after the warm-up; the median is reported ({DEFAULT_REPEAT})")
    p.add_argument("--reference-samples", type=int_range(1, 65536), default=None, metavar="N",
                   help=f"samples per pixel of the reference ({DEFAULT_REFERENCE_SAMPLES}; "
                        f"{QUICK_REFERENCE_SAMPLES} with --quick)")
    p.add_argument("--reference-refine", type=int_range(0, 1 << 20), default=None, metavar="N",
                   help="samples per pixel of the reference where its samples disagree by more than "
                        f"{REFINE_TOLERANCE:g} (edges, a checker finer than the pixel); 0, or at most "
                        "--reference-samples: none (default: none for the sweep, "
                        "8192 with --peer, none with --peer --quick)")
    p.add_argument("--quick", action="store_true",
                   help="a tiny sweep (eight settings per scene, one of them adaptive), for tests")
    p.add_argument("--out", default="bench-results", metavar="DIR",
                   help="folder for results.csv, results.md, machine.json, pareto.png, pareto-cpu.png and the cached "
                        "reference images (./bench-results)")
    p.add_argument("--time-tolerance", type=_fraction, default=DEFAULT_TIME_TOLERANCE, metavar="F",
                   help="relative time difference treated as a tie (measurement noise) when finding the "
                        f"Pareto front ({DEFAULT_TIME_TOLERANCE:g}); 0 for the plain definition")
    p.add_argument("--error-tolerance", type=_fraction, default=DEFAULT_ERROR_TOLERANCE, metavar="F",
                   help="relative RMSE difference treated as a tie when finding the Pareto front "
                        f"({DEFAULT_ERROR_TOLERANCE:g}: smaller differences are within the sampling noise "
                        "of the images); 0 for the plain definition")
    p.add_argument("--backend", choices=("auto", "egl", "osmesa"), default="auto",
                   help="OpenGL context: EGL, OSMesa, or EGL falling back to OSMesa (auto)")
    p.add_argument("--peer", choices=("mitsuba",), default=None,
                   help="instead of the sweep: glassray side by side with a physically based path tracer "
                        "(Mitsuba 3: pip install 'glassray[peer]') on one scene that both draw identically "
                        "(default whitted-exact): error against time, time to reach an error "
                        "(peer.md, peer.csv, peer-time-to-error.csv, peer-machine.json, peer.png; see viewer/measure/peer.py)")
    p.add_argument("--peer-time-limit", type=int_range(1, 86400), default=None, metavar="S",
                   help="with --peer: a Mitsuba sample count whose first render took longer than S seconds "
                        "ends its series (30; the next count is 1.78-4 times as many samples)")


def _named_twice(names: list[str]) -> list[str]:
    """The scenes of `names` that name one file twice, however spelt
    (glass-sphere and glass-sphere; a/s.toml and /abs/a/s.toml): each
    spelling after the first of its file."""
    seen, twice = {}, []
    for name in names:
        key = os.path.realpath(resolve_scene_path(name))
        if key in seen:
            twice.append(name if name == seen[key] else f"{name} (the same file as {seen[key]})")
        else:
            seen[key] = name
    return twice


def run(args) -> int:
    """``glassray bench`` with the parsed options; the exit status."""
    debug = getattr(args, "debug", False)
    if args.scene and args.scenes:
        print("glassray bench: give either SCENE or --scenes, not both", file=sys.stderr)
        return 2
    peer = getattr(args, "peer", None)
    if peer and args.scenes:
        print("glassray bench: --peer compares on one SCENE, not --scenes", file=sys.stderr)
        return 2
    if not peer and getattr(args, "peer_time_limit", None) is not None:
        print("glassray bench: --peer-time-limit limits the peer's renders; it needs --peer", file=sys.stderr)
        return 2
    if args.scene is not None and not args.scene.strip():
        print("glassray bench: empty scene name (give a scene file or a built-in scene name)", file=sys.stderr)
        return 2
    names = [args.scene] if args.scene else (
        [s.strip() for s in args.scenes.split(",") if s.strip()] if args.scenes is not None else
        (["whitted-exact"] if peer else list(DEFAULT_SCENES)))
    if not names:
        print("glassray bench: --scenes names no scene", file=sys.stderr)
        return 2
    twice = _named_twice(names)
    if twice:
        print(f"glassray bench: --scenes names {', '.join(twice)} more than once", file=sys.stderr)
        return 2
    if not str(args.out):
        print("glassray bench: --out names no folder", file=sys.stderr)
        return 2
    scenes = []
    for name in names:
        try:
            scenes.append((name, load_scene(name)))
        except SceneError as e:
            missing = name in DEFAULT_SCENES and name not in builtin_scene_names()
            print(f"glassray: {name}: benchmark scene missing from this installation" if missing else
                  f"glassray: {e}", file=sys.stderr)
            return 2
    if peer:
        try:
            check_scene(scenes[0][1])
        except PeerError as e:
            print(f"glassray: {names[0]}: {e}", file=sys.stderr)
            return 2
    width, height = args.size
    ref_samples = args.reference_samples or (QUICK_REFERENCE_SAMPLES if args.quick else DEFAULT_REFERENCE_SAMPLES)
    out = Path(args.out)
    made = not out.exists()
    problem = results_folder_problem(out)
    if problem:
        print(f"glassray: {problem}", file=sys.stderr)
        return 1
    try:
        return _run_into(args, peer, scenes, width, height, ref_samples, out, debug)
    finally:
        if made:
            remove_if_empty(out)      # a run that wrote nothing leaves no folder of its own behind


def _run_into(args, peer, scenes, width, height, ref_samples, out: Path, debug: bool) -> int:
    try:
        ctx, backend = create_offscreen_context(args.backend)
    except ContextError as e:
        print(f"glassray: {e}", file=sys.stderr)
        return 1
    try:
        if peer:
            return run_bench(ctx, backend, scenes[0][0], scenes[0][1], width, height, out, log_progress,
                             quick=bool(getattr(args, "quick", False)), repeat=int(args.repeat),
                             reference_samples=args.reference_samples,
                             reference_refine=getattr(args, "reference_refine", None),
                             time_limit_s=getattr(args, "peer_time_limit", None))
        return run_sweep(ctx, backend, scenes, width, height, ref_samples, out, repeat=args.repeat,
                         quick=args.quick, refine=getattr(args, "reference_refine", None),
                         time_tol=args.time_tolerance, error_tol=args.error_tolerance)
    except KeyboardInterrupt:
        print("glassray: interrupted", file=sys.stderr)
        return 130
    except OutputError as e:
        if debug:
            raise
        print(f"glassray: {e}", file=sys.stderr)
        return 1
    except Exception as e:
        if debug:
            raise
        if isinstance(e, PeerError):    # a message for the user (Mitsuba missing, its variant unusable)
            print(f"glassray: {e}", file=sys.stderr)
            return 1
        print(f"glassray: bench failed: {type(e).__name__}: {e} (run with --debug for the traceback)",
              file=sys.stderr)
        return 1
    finally:
        ctx.release()
