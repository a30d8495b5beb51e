"""``glassray stress``: its options, and the command that checks them, makes
the OpenGL context and runs the suite (viewer/measure/stress.py).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..gpu.context import ContextError, create_offscreen_context
from ..measure import stress
from ..measure.outputs import OutputError, remove_if_empty, results_folder_problem
from ..measure.stress import DEFAULT_OUT, DEFAULT_SIZE, print_line, run_suite
from ..measure.stress_cases import CASES, case_names
from .args import int_range, size_type

#: The subcommand's description (``glassray stress --help``): the first line
#: of the suite's own docstring
DESCRIPTION = stress.__doc__.strip().splitlines()[0]

def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``glassray stress``."""
    p.add_argument("--list", action="store_true", help="list the cases with what they test and their tolerance")
    p.add_argument("--case", action="append", metavar="NAME", help="run only this case (repeatable)")
    p.add_argument("--size", type=size_type(4, 4096), default=DEFAULT_SIZE, metavar="WxH",
                   help="image size of every case (%dx%d); cases that need a pixel on the view axis use "
                        "the next odd width and height" % DEFAULT_SIZE)
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"folder for contact-sheet.png and results.md (./{DEFAULT_OUT})")
    p.add_argument("--columns", type=int_range(1, 1000), default=3, metavar="N",
                   help="cases per row of the contact sheet (3)")
    p.add_argument("--naive", action="store_true",
                   help="measure the textbook intersection formulas instead (NAIVE_INTERSECT)")
    p.add_argument("--intersections", action="store_true",
                   help="also print the float32 intersection error per primitive, textbook against robust")
    p.add_argument("--backend", choices=("auto", "egl", "osmesa"), default="auto",
                   help="OpenGL context: EGL, OSMesa, or EGL falling back to OSMesa (auto)")


def run(args) -> int:
    """``glassray stress`` with the parsed options; the exit status."""
    if args.list:
        for c in CASES:
            print_line(f"{c.name}\n    {c.what}\n    tolerance: {c.tolerance()}")
        return 0
    names = args.case or case_names()
    unknown = [n for n in names if n not in case_names()]
    if unknown:
        print(f"glassray stress: unknown case {', '.join(map(repr, unknown))} (see --list)", file=sys.stderr)
        return 2
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:       # it ran and reported such a case twice
        print(f"glassray stress: --case names {', '.join(twice)} more than once", file=sys.stderr)
        return 2
    if not str(args.out):
        print("glassray stress: --out names no folder", file=sys.stderr)
        return 2
    out = Path(args.out)
    made = not out.exists()
    problem = results_folder_problem(out)     # before the cases run, not after them
    if problem:
        print(f"glassray: {problem}", file=sys.stderr)
        return 1
    try:
        return _run_cases(args, names, out)
    finally:
        if made:
            remove_if_empty(out)      # a run that wrote nothing leaves no folder of its own behind


def _run_cases(args, names: list[str], out: Path) -> int:
    try:
        ctx, _backend = create_offscreen_context(args.backend)
    except ContextError as e:
        print(f"glassray: {e}", file=sys.stderr)
        return 1
    try:
        return run_suite(ctx, names, args.size, out, naive=args.naive, columns=args.columns,
                         intersections=args.intersections)
    except KeyboardInterrupt:
        print("glassray: interrupted", file=sys.stderr)
        return 130
    except OutputError as e:
        if getattr(args, "debug", False):
            raise
        print(f"glassray: {e}", file=sys.stderr)
        return 1
    except Exception as e:
        if getattr(args, "debug", False):
            raise
        print(f"glassray: stress failed: {type(e).__name__}: {e} (run with --debug for the traceback)",
              file=sys.stderr)
        return 1
    finally:
        ctx.release()
