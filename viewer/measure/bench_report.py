"""The benchmark's results as files and text: results.csv's rows, the
Markdown tables and the summary lines (speed-ups, the default settings and
adaptive sampling on the Pareto front).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

from .outputs import write_output
from .sweep import CLOCKS, DEFAULT_ERROR_TOLERANCE, DEFAULT_TIME_TOLERANCE, Result, dominates, format_weight

CSV_COLUMNS = ("scene", "setting", "is_default", "pareto_wall", "pareto_cpu", "max_depth", "samples",
               "adaptive_target", "mean_spp", "min_weight", "scale", "width", "height", "specialise", "fresnel",
               "footprint",
               "time_ms", "time_min_ms", "time_max_ms", "cpu_ms", "repeat", "rmse", "frac_off_1_255", "max_abs_err")


# ---------------------------------------------------------------- output


def _row(res: Result) -> dict:
    st = res.setting
    return {"scene": res.scene, "setting": st.label, "is_default": int(st.label == "default"),
            "pareto_wall": int(res.front["wall"]), "pareto_cpu": int(res.front["cpu"]),
            "max_depth": st.max_depth, "samples": st.samples,
            "adaptive_target": "" if st.adaptive is None else f"{st.adaptive:g}",
            "mean_spp": f"{res.spp_used:.4f}" if st.adaptive is not None else str(st.samples),
            "min_weight": format_weight(st.min_weight), "scale": f"{st.scale:g}", "width": res.width,
            "height": res.height, "specialise": int(st.specialise), "fresnel": st.fresnel,
            "footprint": int(st.footprint),
            "time_ms": f"{res.time_ms:.4f}", "time_min_ms": f"{min(res.times):.4f}",
            "time_max_ms": f"{max(res.times):.4f}", "cpu_ms": f"{res.cpu_ms:.4f}", "repeat": len(res.times),
            "rmse": f"{res.errors['rmse']:.10g}", "frac_off_1_255": f"{res.errors['frac_off']:.6g}",
            "max_abs_err": f"{res.errors['max_abs']:.6g}"}


def write_csv(path: Path, results: list[Result]) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_COLUMNS, lineterminator="\n")
    w.writeheader()
    for res in results:
        w.writerow(_row(res))
    write_output(path, buf.getvalue().encode("utf-8"))


def speedup(results: list[Result], a: str = "generic", b: str = "default", clock: str = "wall") -> float | None:
    """Median time of setting ``a`` over that of ``b`` (same scene)."""
    ta = [r.t(clock) for r in results if r.setting.label == a]
    tb = [r.t(clock) for r in results if r.setting.label == b]
    return ta[0] / tb[0] if ta and tb and tb[0] > 0 else None


def scene_table(results: list[Result], title: str, clock: str = "wall") -> str:
    """A Markdown table (also readable as plain text), fastest first on
    ``clock``.  "spp" is the samples per pixel (for an adaptive setting the
    mean budget), "mean spp" what was used on average."""
    head = ("setting", "size", "depth", "spp", "mean spp", "min_w", "shader", "fresnel", "ms (median)",
            "min..max", "CPU ms", "RMSE", ">1/255", "max err", "front")
    rows = []
    for res in sorted(results, key=lambda r: r.t(clock)):
        st = res.setting
        rows.append((st.label, f"{res.width}x{res.height}", str(st.max_depth), str(st.samples),
                     str(st.samples) if st.adaptive is None else f"{res.spp_used:.2f}",
                     format_weight(st.min_weight), "spec" if st.specialise else "generic", st.fresnel,
                     f"{res.time_ms:.1f}", f"{min(res.times):.1f}..{max(res.times):.1f}", f"{res.cpu_ms:.0f}",
                     f"{res.errors['rmse']:.2e}", f"{100 * res.errors['frac_off']:.2f}%",
                     f"{res.errors['max_abs']:.3f}",
                     "**" if res.front["wall"] and res.front["cpu"] else ("w" if res.front["wall"] else
                                                                            ("c" if res.front["cpu"] else ""))))
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    right = {2, 3, 4, 5, 8, 9, 10, 11, 12, 13}

    def line(cells):
        return "| " + " | ".join(c.rjust(wd) if i in right else c.ljust(wd)
                                 for i, (c, wd) in enumerate(zip(cells, widths))) + " |"

    sep = "|" + "|".join(("-" * (wd + 1) + ":") if i in right else ("-" * (wd + 2))
                         for i, wd in enumerate(widths)) + "|"
    return "\n".join([f"### {title}", "", line(head), sep, *(line(r) for r in rows)])


def scene_summary(results: list[Result], time_tol: float = DEFAULT_TIME_TOLERANCE,
                  error_tol: float = DEFAULT_ERROR_TOLERANCE) -> list[str]:
    out = []
    default = next((r for r in results if r.setting.label == "default"), None)
    generic = next((r for r in results if r.setting.label == "generic"), None)
    if default is not None and generic is not None:
        out.append(f"specialised vs generic shader: {speedup(results):.2f}x faster by wall clock "
                   f"({default.time_ms:.1f} ms against {generic.time_ms:.1f} ms), "
                   f"{speedup(results, clock='cpu'):.2f}x by CPU time "
                   f"({default.cpu_ms:.0f} ms against {generic.cpu_ms:.0f} ms)")
    if default is not None:
        for clock, name in (("wall", "wall clock"), ("cpu", "CPU time")):
            if default.front[clock]:
                out.append(f"default settings: on the Pareto front ({name})")
            else:
                doms = [r.setting.label for r in results if r is not default and
                        dominates(r.t(clock), r.errors["rmse"], default.t(clock), default.errors["rmse"],
                                  time_tol, error_tol)]
                out.append(f"default settings: NOT on the Pareto front ({name}; dominated by {', '.join(doms)})")
    out.extend(adaptive_summary(results))
    return out


def adaptive_on_front(results: list[Result]) -> dict[str, list[str]] | None:
    """Per clock, the adaptive settings on the Pareto front (of all settings
    together); None when the sweep had no adaptive setting."""
    if not any(r.setting.adaptive is not None for r in results):
        return None
    return {clock: [r.setting.label for r in results if r.setting.adaptive is not None and r.front[clock]]
            for clock in CLOCKS}


def adaptive_summary(results: list[Result]) -> list[str]:
    """Whether adaptive sampling moves the front, per clock: the adaptive
    settings on it, and the uniform settings that were on the front of the
    uniform settings alone and that adaptive ones push off it."""
    on = adaptive_on_front(results)
    if on is None:
        return []
    out = []
    for clock, name in (("wall", "wall clock"), ("cpu", "CPU time")):
        if not on[clock]:
            out.append(f"adaptive sampling ({name}): no adaptive setting on the Pareto front")
            continue
        pushed = [r.setting.label for r in results if r.front_uniform.get(clock) and not r.front[clock]]
        out.append(f"adaptive sampling ({name}): on the Pareto front: {', '.join(on[clock])}"
                   + (f"; pushes off the front of the uniform settings: {', '.join(pushed)}" if pushed else
                      "; every point of the uniform settings' front stays on it"))
    return out
