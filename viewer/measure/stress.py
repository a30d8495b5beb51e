"""Run the numerical stability suite: hard cases on the float32 GPU tracer, each checked against the float64 reference.

``glassray stress`` renders a named suite of cases that stress float32
arithmetic (grazing views, rays exactly along the axes, the eye on a box's
planes, the scene moved by up to 1e6 or scaled by 1e-30 to 1e30, glass walls
down to 1e-4 of the radius, coincident surfaces, interfaces that must vanish,
views at the critical angles, a 64-deep ray tree, and every shipped scene)
with the shader and with the independent float64 tracer
(``viewer.reference``), one centred sample per pixel on both sides.  It
prints one row per case and writes a contact sheet (GPU | reference | error
heat map per case).  Exit status 1 when any case exceeds its tolerance.

Metrics (display space: the spec's 8-bit sRGB encoding of each image):

* ``max``, ``mean``: the largest and the mean absolute difference, in 8-bit
  levels (1 level = 1/255), over the unmasked pixels (max over channels).
* ``>1/255``, ``>0.05``: the fraction of unmasked pixels with a channel off
  by more than 1 level, and by more than 0.05 (12.75 levels).
* ``masked``: the fraction of pixels whose footprint straddles an edge
  (silhouettes, checker edges, seen directly, reflected or refracted): the
  reference traced at the four points a quarter pixel around the centre
  differs by more than 8 levels between them.  Only there may a float32
  rounding of the ray flip the pixel to the other side of the edge.
* ``NaN/Inf``: pixels of the GPU image with a non-finite channel.
* ``acne``: among unmasked pixels whose primary ray (reference) meets an
  opaque surface, the fraction that comes out darker than the reference by
  more than 0.05 in some channel: the signature of self-shadowing (a
  secondary ray that re-hits the surface it leaves).
* ``ms``: wall-clock time of one GPU render of the case (after a warm-up
  render that compiles the shader), finished on the GPU.

Default tolerance of a case: no NaN/Inf pixel and at most 0.1% of the
unmasked pixels off by more than 1/255; some cases add a check of their own
(printed with ``--list``).  ``--naive`` compiles the shader with
``NAIVE_INTERSECT`` (the textbook intersection formulas kept in
shaders/lib/intersect.glsl for this comparison); ``--intersections`` also
prints the float32 intersection error distribution per primitive, before
(textbook) and after (robust formulations).
"""

from __future__ import annotations

import io
import sys
from pathlib import Path

from ..base import interrupt
from ..gpu.context import describe
from .kit import machine_info
from .outputs import results_written_together, write_output
from .stress_cases import get_case
from .stress_intersections import format_errors, intersection_errors
from .stress_report import contact_sheet, format_table
from .stress_suite import Suite

DEFAULT_SIZE = (96, 54)
DEFAULT_OUT = "stress-results"


def print_line(msg: str = "") -> None:
    """A line on stdout, at once."""
    print(msg, flush=True)


def run_suite(ctx, names: list[str], size: tuple[int, int], out: Path, *, naive: bool = False, columns: int = 3,
              intersections: bool = False) -> int:
    """``glassray stress``: the cases ``names`` at ``size`` (``naive``: the
    textbook intersections), the table on stdout, contact-sheet.png and
    results.md into ``out`` (``columns`` cases a row; ``intersections``:
    the intersection error distribution too); 1 when a case fails, else 0."""
    suite = Suite(ctx, naive=naive)
    results = []
    for name in names:
        interrupt.check()                         # Ctrl-C between cases (viewer/base/interrupt.py)
        results.append(suite.run_case(get_case(name), size))
        print(f"stress: {name}: {'ok' if results[-1].ok else 'FAIL'}", file=sys.stderr, flush=True)
    variant = "textbook intersections (NAIVE_INTERSECT)" if naive else "robust intersections"
    head = f"glassray stress: {len(results)} case{'' if len(results) == 1 else 's'}, {variant}, {describe(ctx)}"
    mi = machine_info()
    machine = (f"{mi['date']}, {mi['cpu'] or mi['machine']} ({mi['cpus_usable']} usable CPUs), "
               f"{mi['platform']}, glassray {mi['glassray']}")
    text = format_table(results)
    print_line(head)
    print_line(text)
    failed = [r.name for r in results if not r.ok]
    verdict = (f"{len(results) - len(failed)} of {len(results)} cases within tolerance"
               + (f"; failed: {', '.join(failed)}" if failed else ""))
    print_line(verdict)
    # the file says what stdout said: the verdict, and the command that reproduces it
    md = (f"{head}\n\nmachine: {machine}\n\ncommand: `{mi['command']}`\n\n"
          f"{format_table(results, markdown=True)}\n\n{verdict}\n")
    if intersections:
        stats = intersection_errors(ctx)
        print_line("\nfloat32 relative error of t, first hit against the float64 reference:")
        print_line(format_errors(stats, markdown=False))
        md += "\n" + format_errors(stats) + "\n"
    buf = io.BytesIO()
    contact_sheet(results, columns=columns).save(buf, format="PNG", optimize=True)
    with results_written_together():      # both, or neither
        write_output(out / "contact-sheet.png", buf.getvalue())
        write_output(out / "results.md", md.encode("utf-8"))
    print(f"stress: wrote {out / 'contact-sheet.png'} and {out / 'results.md'}", file=sys.stderr)
    return 1 if failed else 0
