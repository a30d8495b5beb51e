"""The peer comparison's numbers as text: the measured points of each series,
the time each series takes to reach an error (log-log interpolation), the
ratios, the Markdown tables and the CSV files.
"""

from __future__ import annotations

import csv
import io
import math

from .kit import Timings

PEER_CSV_COLUMNS = ("series", "renderer", "point", "samples", "effective_spp", "width", "height", "time_ms",
                    "time_min_ms", "time_max_ms", "cpu_ms", "repeat", "rmse", "frac_off_1_255", "max_abs_err")
TTE_CSV_COLUMNS = ("target_rmse", "clock", "glassray_ms", "mitsuba_ms", "ratio_mitsuba_over_glassray",
                   "glassray_adaptive_ms", "ratio_mitsuba_over_adaptive")


class Point(Timings):
    """One measured point of a series (its medians: kit.Timings)."""

    def __init__(self, series: str, label: str, samples: int, run):
        self.series, self.label, self.samples, self.run = series, label, samples, run
        self.effective_spp: float = float(samples)
        self.times: list[float] = []
        self.cpu_times: list[float] = []
        self.errors: dict[str, float] = {}


def time_to_error(points: list[Point], target: float, clock: str = "wall") -> tuple[float | None, str]:
    """Time at which a series first reaches ``target`` RMSE, interpolated
    log-log between the two measured points around the first crossing (in
    order of increasing samples); (None, "not reached") when no measured point
    is at or below it (no extrapolation), (t0, "<=") when the first point is
    already there (only a bound: the series cannot be cheaper than measured)."""
    pts = [(p.t(clock), p.errors["rmse"]) for p in points]
    if not pts:
        return None, "not reached"
    if pts[0][1] <= target:
        return pts[0][0], "<="
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e0 > target >= e1:
            if e1 <= 0 or t0 <= 0 or t1 <= 0:
                return t1, ""
            f = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0))), ""
    return None, "not reached"


def _fmt_ms(t: float | None, flag: str) -> str:
    if t is None:
        return "not reached"
    return (f"<={t:.0f}" if flag == "<=" else f"{t:.0f}") if t >= 10 else (
        f"<={t:.1f}" if flag == "<=" else f"{t:.1f}")


def _ratio(a: tuple[float | None, str], b: tuple[float | None, str]) -> tuple[float | None, str]:
    """a / b (how many times sooner b reaches the error than a) and how sure:
    "" exact, ">=" a lower bound (b's time is an upper bound), "n/a"."""
    (ta, fa), (tb, fb) = a, b
    if ta is None or tb is None:
        if tb is not None and ta is None:
            return None, "peer not reached"
        return None, "n/a"
    if fa == "<=" and fb == "<=":
        return ta / tb, "~"
    if fa == "<=":
        return ta / tb, "<="
    if fb == "<=":
        return ta / tb, ">="
    return ta / tb, ""


def _fmt_ratio(r: tuple[float | None, str]) -> str:
    v, flag = r
    if v is None:
        return flag
    pre = {"<=": "<=", ">=": ">=", "~": "~", ">": ">"}.get(flag, "")
    return f"{pre}{v:.2f}x" if v < 10 else f"{pre}{v:.0f}x"


def series_table(series: dict[str, list[Point]]) -> str:
    head = ("series", "point", "spp (effective)", "ms (median)", "min..max", "CPU ms", "RMSE", ">1/255",
            "max err")
    rows = []
    for name, pts in series.items():
        for p in pts:
            rows.append((name, p.label, f"{p.effective_spp:.4g}", f"{p.time_ms:.1f}",
                         f"{min(p.times):.0f}..{max(p.times):.0f}", f"{p.cpu_ms:.0f}",
                         f"{p.errors['rmse']:.4f}", f"{100 * p.errors['frac_off']:.1f}%",
                         f"{p.errors['max_abs']:.3f}"))
    return _md_table(head, rows, right={2, 3, 4, 5, 6, 7, 8})


def _md_table(head, rows, right=frozenset()) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(head)]

    def line(cells):
        return "| " + " | ".join(c.rjust(w) if i in right else c.ljust(w)
                                 for i, (c, w) in enumerate(zip(cells, widths))) + " |"

    sep = "|" + "|".join(("-" * (w + 1) + ":") if i in right else ("-" * (w + 2)) for i, w in enumerate(widths)) + "|"
    return "\n".join([line(head), sep, *(line(r) for r in rows)])


def tte_rows(series: dict[str, list[Point]], targets, clock: str):
    rows = []
    g = series.get("glassray", [])
    m = series.get("mitsuba", [])
    a = series.get("glassray adaptive")
    if a is not None:   # an adaptive series' curve runs in order of its cost, not of its target
        a = sorted(a, key=lambda p: p.t(clock))
    for e in targets:
        tg, tm = time_to_error(g, e, clock), time_to_error(m, e, clock)
        ta = time_to_error(a, e, clock) if a is not None else None
        r = _ratio(tm, tg)
        ra = _ratio(tm, ta) if ta is not None else None
        if m and tm[0] is None:
            # the peer never got there: its slowest measured point bounds the ratio from below
            last = max(p.t(clock) for p in m)
            if tg[0] is not None:
                r = (last / tg[0], ">")
            if ta is not None and ta[0] is not None:
                ra = (last / ta[0], ">")
        rows.append((e, tg, tm, r, ta, ra))
    return rows


def tte_table(rows, adaptive: bool, clock: str) -> str:
    head = ["target RMSE", "glassray ms", "mitsuba ms", "mitsuba / glassray"]
    if adaptive:
        head += ["glassray adaptive ms", "mitsuba / adaptive"]
    out = []
    for e, tg, tm, r, ta, ra in rows:
        cells = [f"{e:g}", _fmt_ms(*tg), _fmt_ms(*tm), _fmt_ratio(r)]
        if adaptive:
            cells += [_fmt_ms(*ta), _fmt_ratio(ra)]
        out.append(tuple(cells))
    return _md_table(head, out, right=set(range(1, len(head))))


def series_csv(series: dict[str, list[Point]], width: int, height: int) -> bytes:
    """peer.csv: a row per measured point of every series."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=PEER_CSV_COLUMNS, lineterminator="\n")
    w.writeheader()
    for sname, pts in series.items():
        for p in pts:
            w.writerow({"series": sname, "renderer": "mitsuba" if sname == "mitsuba" else "glassray",
                        "point": p.label, "samples": p.samples, "effective_spp": f"{p.effective_spp:.6g}",
                        "width": width, "height": height, "time_ms": f"{p.time_ms:.4f}",
                        "time_min_ms": f"{min(p.times):.4f}", "time_max_ms": f"{max(p.times):.4f}",
                        "cpu_ms": f"{p.cpu_ms:.4f}", "repeat": len(p.times), "rmse": f"{p.errors['rmse']:.10g}",
                        "frac_off_1_255": f"{p.errors['frac_off']:.6g}",
                        "max_abs_err": f"{p.errors['max_abs']:.6g}"})
    return buf.getvalue().encode("utf-8")


def time_to_error_csv(tte: dict[str, list]) -> bytes:
    """peer-time-to-error.csv: per clock, a row per target error (the rows of :func:`tte_rows`)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=TTE_CSV_COLUMNS, lineterminator="\n")
    w.writeheader()

    def num(x):
        return "" if x is None else f"{x:.6g}"

    for clock, rows in tte.items():
        for e, tg, tm, r, ta, ra in rows:
            w.writerow({"target_rmse": f"{e:g}", "clock": clock, "glassray_ms": num(tg[0]), "mitsuba_ms": num(tm[0]),
                        "ratio_mitsuba_over_glassray": num(r[0]),
                        "glassray_adaptive_ms": num(ta[0]) if ta else "",
                        "ratio_mitsuba_over_adaptive": num(ra[0]) if ra else ""})
    return buf.getvalue().encode("utf-8")
