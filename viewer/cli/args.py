"""The command line's argument types and shared options: what every
subcommand's parser is built from (commands.py's, bench.py's, stress.py's),
so that a value is checked, and its message worded, the same way everywhere.
"""

from __future__ import annotations

import argparse
import math

from ..measure.quality import parse_max_error


def vec3(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    try:
        vals = tuple(float(p) for p in parts)
    except ValueError:
        vals = ()
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"expected three finite numbers x,y,z, got {text!r}")
    return vals  # type: ignore[return-value]


def size_type(lo: int = 1, hi: int = 16384):
    """argparse type for WxH with both sides in lo..hi (shared by bench and stress)."""
    def parse(text: str) -> tuple[int, int]:
        try:
            w, h = (int(p) for p in text.lower().split("x"))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected WxH such as 1280x720, got {text!r}") from None
        if not (lo <= w <= hi and lo <= h <= hi):
            raise argparse.ArgumentTypeError(f"width and height must be in {lo}..{hi}, got {text!r}")
        return w, h
    return parse


size = size_type()


def int_range(lo: int, hi: int):
    """An argparse type: an integer in lo..hi (bench's options use it too)."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"expected an integer in {lo}..{hi}, got {v}")
        return v
    return parse


def float_range(lo: float, hi: float, lo_open: bool = False):
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not math.isfinite(v) or (v <= lo if lo_open else v < lo) or v > hi:
            raise argparse.ArgumentTypeError(f"expected a number in {'(' if lo_open else '['}{lo:g}, {hi:g}], "
                                             f"got {text!r}")
        return v
    return parse


def max_error(text: str) -> float:
    """argparse type of --max-error (its checks are the quality module's)."""
    return parse_max_error(text)


def add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--debug", action="store_true", help="show tracebacks on failure")


def add_overrides(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scene overrides (each replaces the scene file's value)")
    g.add_argument("--samples", type=int_range(1, 65536), metavar="N", help="samples per pixel")
    g.add_argument("--max-depth", type=int_range(1, 64), metavar="N", help="longest chain of interactions")
    g.add_argument("--min-weight", type=float_range(0.0, 1.0), metavar="X", help="branch weight cut-off")
    g.add_argument("--camera-position", type=vec3, metavar="x,y,z")
    g.add_argument("--camera-target", type=vec3, metavar="x,y,z")
    g.add_argument("--fov", type=float_range(1.0, 179.0), metavar="DEG", help="vertical field of view")
    g.add_argument("--light-position", type=vec3, metavar="x,y,z", help="moves the first point light")


class Parser(argparse.ArgumentParser):
    """argparse, with a usage error as one line on stderr (cli.md: "one
    clear message") instead of the usage block before it, which for render
    is nine lines that hide the error; the line says where the usage is.
    Options are taken by their whole names only: argparse's prefixes
    (`--sample 4` for `--samples 4`) would be an interface that the spec
    does not define and that a new option could make ambiguous."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)      # subcommands' parsers are made by this class too
        super().__init__(*args, **kwargs)

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")
