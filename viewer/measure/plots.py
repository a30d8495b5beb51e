"""The benchmark's plots (matplotlib, imported when drawing: ``pip install
glassray[bench]``): pareto.png and pareto-cpu.png of the sweep, peer.png
of the peer comparison, and their axis of milliseconds.
"""

from __future__ import annotations

import io
import math
import textwrap
from pathlib import Path

from .outputs import write_output
from .peer_report import Point
from .sweep import Result, Setting

def _group(setting: Setting) -> str:
    """The plot's group of a setting: "adaptive", or its label's knob."""
    if setting.adaptive is not None:
        return "adaptive"
    return setting.label.split("=")[0].split(":")[0]


def ms_axis(ax) -> None:
    """A logarithmic x axis of milliseconds, labelled in plain numbers at
    1, 2 and 5 of every decade (on a span under a decade with fewer than
    two of them, the locator falls back to evenly spaced ticks, labelled
    the same way).  (Matplotlib's default labels every minor tick in
    scientific notation where an axis shows one major tick, and on a span
    of 15 to 600 ms they ran into each other.)  Over more than three
    decades of data (the peer comparison: 10 ms to 40 s) only 1 and 3 are
    labelled: "5000 10000 20000" ran together.  Call it after plotting."""
    from matplotlib.ticker import FuncFormatter, LogLocator

    ax.set_xscale("log")
    lo, hi = ax.dataLim.intervalx
    wide = lo > 0 and math.isfinite(hi) and math.log10(hi / lo) > 3.0
    labelled = (1.0, 3.0) if wide else (1.0, 2.0, 5.0)
    ax.xaxis.set_major_locator(LogLocator(base=10, subs=labelled))
    ax.xaxis.set_minor_locator(LogLocator(base=10, subs=tuple(float(k) for k in range(2, 10)
                                                              if float(k) not in labelled)))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(FuncFormatter(lambda v, _: ""))


def pareto_plot(path: Path, by_scene: dict[str, list[Result]], titles: dict[str, str], subtitle: str,
         clock: str = "wall") -> bool:
    """pareto.png: per scene, median frame time against RMSE (log axes), the
    Pareto front (of all settings) as a staircase, the default settings
    labelled; adaptive settings in their own colour and marker, and, when
    there are any, the front of the uniform settings alone as a dotted
    staircase (where the front would be without adaptive sampling).  False
    when matplotlib is missing."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    n = len(by_scene)
    cols = 1 if n == 1 else 2
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.2 * cols if n > 1 else 8.0, 4.4 * rows), squeeze=False)
    groups = (("default", "default", "#d62728", "*", 180), ("max_depth", "max depth", "#1f77b4", "o", 36),
              ("samples", "samples", "#2ca02c", "s", 36), ("min_weight", "min weight", "#9467bd", "^", 40),
              ("scale", "resolution scale", "#8c564b", "D", 32), ("generic", "generic shader", "#ff7f0e", "X", 60),
              ("schlick", "Schlick Fresnel", "#e377c2", "P", 60), ("preset", "combined preset", "#7f7f7f", "v", 40),
              ("point samples", "point samples (no footprint samples)", "#bcbd22", "d", 50),
              ("adaptive", "adaptive (e target \u2264 mean budget)", "#17becf", "h", 70))
    for ax, (stem, results) in zip(axes.flat, by_scene.items()):
        floor = min((r.errors["rmse"] for r in results if r.errors["rmse"] > 0), default=1e-6) / 2
        err = lambda r: max(r.errors["rmse"], floor)  # noqa: E731 - log axes need > 0
        for prefix, name, colour, marker, size in groups:
            pts = [r for r in results if _group(r.setting) == prefix]
            if pts:
                ax.scatter([r.t(clock) for r in pts], [err(r) for r in pts], c=colour, marker=marker, s=size,
                           label=name, zorder=3, edgecolors="black" if prefix in ("default", "adaptive") else "none",
                           linewidths=0.6)

        def staircase(points):
            xs, ys = [], []
            for r in sorted(points, key=lambda r: (r.t(clock), err(r))):
                if xs:
                    xs.append(r.t(clock))
                    ys.append(ys[-1])
                xs.append(r.t(clock))
                ys.append(err(r))
            return xs, ys

        front = [r for r in results if r.front[clock]]
        if any(r.setting.adaptive is not None for r in results):
            uniform_front = [r for r in results if r.front_uniform.get(clock)]
            if uniform_front:
                ax.plot(*staircase(uniform_front), color="#7f7f7f", lw=1.0, ls=":", zorder=1,
                        label="front of uniform settings only")
        if front:
            ax.plot(*staircase(front), color="black", lw=1.0, ls="--", zorder=2, label="Pareto front")
            ax.scatter([r.t(clock) for r in front], [err(r) for r in front], s=110, facecolors="none",
                       edgecolors="black", linewidths=1.0, zorder=4)
        # Labels: the default settings always (with an arrow), then the front,
        # then the rest, each skipped when it would land on an earlier label.
        lt = [math.log10(max(r.t(clock), 1e-9)) for r in results]
        le = [math.log10(err(r)) for r in results]
        span_t = (max(lt) - min(lt)) or 1.0
        span_e = (max(le) - min(le)) or 1.0
        placed: list[tuple[float, float]] = []
        order = sorted(range(len(results)), key=lambda i: (results[i].setting.label != "default",
                                                            not results[i].front[clock], results[i].t(clock)))
        for i in order:
            r = results[i]
            lab = r.setting.label
            x, y = (lt[i] - min(lt)) / span_t, (le[i] - min(le)) / span_e
            if lab == "default":
                ax.annotate("default", (r.t(clock), err(r)), textcoords="offset points", xytext=(-30, 26),
                            fontsize=8, color="#d62728", fontweight="bold",
                            arrowprops=dict(arrowstyle="->", color="#d62728", lw=0.8))
                placed.append((x - 0.05, y + 0.12))
                continue
            if any(abs(x - px) < 0.07 and abs(y - py) < 0.045 for px, py in placed):
                continue
            placed.append((x, y))
            if r.setting.adaptive is not None:
                short = f"e{r.setting.adaptive:g} \u2264{r.setting.samples}"
            else:
                short = lab.replace("max_depth=", "d").replace("samples=", "spp ").replace("min_weight=", "w ") \
                           .replace("scale=", "x").replace("preset:", "")
            ax.annotate(short, (r.t(clock), err(r)), textcoords="offset points", xytext=(4, 3), fontsize=6.5,
                        color="#333333")
        ms_axis(ax)
        ax.set_yscale("log")
        ax.set_xlabel("frame time, ms (median, wall clock)" if clock == "wall" else
                      "CPU time per frame, ms (median, all threads)")
        ax.set_ylabel("RMSE against reference (linear)")
        ax.set_title(titles.get(stem, stem), fontsize=10)
        ax.grid(True, which="both", alpha=0.25)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    seen = dict(zip(labels, handles))
    for ax in list(axes.flat)[1:n]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(lab, h)
    fig.legend(list(seen.values()), list(seen.keys()), loc="lower center", ncol=min(4, len(seen)),
               fontsize=8, frameon=False)
    fig.suptitle("\n".join(textwrap.wrap(subtitle, 95 * cols if n > 1 else 120)), fontsize=8)
    fig.tight_layout(rect=(0, 0.06 if rows > 1 else 0.1, 1, 0.96))
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    write_output(path, buf.getvalue())
    return True


def peer_plot(path, series: dict[str, list[Point]], targets, subtitle: str) -> bool:
    """peer.png (``glassray bench --peer``): per clock, each series' RMSE
    against its time per image (log axes), the target errors as dotted
    lines.  False when matplotlib is missing."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    styles = {"glassray": ("#d62728", "o"), "mitsuba": ("#1f77b4", "s"), "glassray adaptive": ("#2ca02c", "^")}
    fig, axes = plt.subplots(1, 2, figsize=(12.0, 4.8))
    for ax, clock in zip(axes, ("wall", "cpu")):
        for name, pts in series.items():
            if not pts:
                continue
            colour, marker = styles.get(name, ("#7f7f7f", "x"))
            xs = [p.t(clock) for p in pts]
            ys = [max(p.errors["rmse"], 1e-6) for p in pts]
            ax.plot(xs, ys, color=colour, marker=marker, ms=5, lw=1.2, label=name)
            for p, x, y in zip(pts, xs, ys):
                ax.annotate(p.label, (x, y), textcoords="offset points", xytext=(4, 3), fontsize=6.5,
                            color=colour)
        for e in targets:
            ax.axhline(e, color="#999999", lw=0.5, ls=":")
        ms_axis(ax)
        ax.set_yscale("log")
        ax.set_xlabel("time per image, ms (median, wall clock)" if clock == "wall" else
                      "CPU time per image, ms (median, all threads of the process)")
        ax.set_ylabel("RMSE against the float64 reference (linear)")
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=8)
    fig.suptitle("\n".join(textwrap.wrap(subtitle, 150)), fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    write_output(path, buf.getvalue())
    return True
