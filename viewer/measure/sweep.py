"""The benchmark's sweep: the settings measured for a scene, one result per
setting, and the Pareto front of time against error over them.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from ..adaptive.render import DEFAULT_TARGET_ERROR
from ..gpu.footprint import footprint_default
from .kit import Timings

#: Times closer than this (relative) are one time: measurement noise.
DEFAULT_TIME_TOLERANCE = 0.05
#: RMSEs closer than this (relative) are one error.  Two settings that
#: differ only slightly (depth 8 against 10 behind a glass sphere) change
#: the image far less than its sampling noise, and the sign of such a small
#: RMSE difference is then set by that noise, not by quality.
DEFAULT_ERROR_TOLERANCE = 0.01
CLOCKS = ("wall", "cpu")


# ---------------------------------------------------------------- settings


@dataclass(frozen=True)
class Setting:
    """One point of the sweep.  ``label`` names what differs from the scene's
    own settings ("default" for none).  ``adaptive``: None for uniform
    sampling (``samples`` per pixel everywhere), else the per-pixel target
    error of adaptive sampling (viewer.adaptive), ``samples`` then being the
    mean budget per pixel.  ``footprint`` False: point samples only (no
    footprint samples on a checkered plane: Renderer.render's and
    render_adaptive's footprint=False)."""
    label: str
    max_depth: int
    samples: int
    min_weight: float
    scale: float = 1.0
    specialise: bool = True
    fresnel: str = "exact"
    adaptive: float | None = None
    footprint: bool = True

    def key(self) -> tuple:
        return (self.max_depth, self.samples, self.min_weight, self.scale, self.specialise, self.fresnel,
                self.adaptive, self.footprint)


#: Adaptive points of the full sweep: (target error, budget as a multiple of
#: the scene's samples).  0.05 and 0.01 stop before the budget on some
#: scenes; the default target (viewer.adaptive.DEFAULT_TARGET_ERROR) spends
#: it, at 1x, 2x and 4x the scene's samples: what adaptive sampling reaches
#: with more samples to spend.  The uniform sweep gets a setting at every
#: adaptive budget, so each has its uniform counterpart.
ADAPTIVE_SWEEP = ((0.05, 1), (0.01, 1), (DEFAULT_TARGET_ERROR, 1), (DEFAULT_TARGET_ERROR, 2),
                  (DEFAULT_TARGET_ERROR, 4))
#: --quick: one adaptive point, the default target at the scene's samples.
QUICK_ADAPTIVE_SWEEP = ((DEFAULT_TARGET_ERROR, 1),)


def adaptive_label(target: float, samples: int) -> str:
    return f"adaptive e={target:g} spp<={samples}"


def format_weight(w: float) -> str:
    """A min weight as labels and tables write it."""
    return f"{w:g}"


def sweep(scene, quick: bool = False, reference_samples: int | None = None) -> list[Setting]:
    """The settings benchmarked for one scene: its own settings ("default"),
    each knob moved on its own, and a few combined presets.  Sample counts
    at or above the reference's are left out (they would measure the
    reference's own noise)."""
    r = scene.render
    base = Setting("default", r.max_depth, r.samples, r.min_weight)
    out: list[Setting] = [base]

    def add(s: Setting) -> None:
        if reference_samples is not None and s.samples != base.samples and s.samples >= reference_samples:
            return
        if all(s.key() != o.key() for o in out):
            out.append(s)

    def add_adaptive(points) -> None:
        for target, factor in points:
            n = r.samples * factor
            add(replace(base, label=adaptive_label(target, n), samples=n, adaptive=target))

    if quick:
        add(replace(base, label="max_depth=2", max_depth=2))
        add(replace(base, label=f"samples={1 if r.samples > 1 else 2}", samples=1 if r.samples > 1 else 2))
        add(replace(base, label="min_weight=0.01", min_weight=0.01))
        add(replace(base, label="scale=0.5", scale=0.5))
        add(replace(base, label="generic", specialise=False))
        add(replace(base, label="schlick", fresnel="schlick"))
        add_adaptive(QUICK_ADAPTIVE_SWEEP)
        return out
    for d in (1, 2, 4, 6, 8, 12):
        if d != r.max_depth:
            add(replace(base, label=f"max_depth={d}", max_depth=d))
    # every adaptive budget as a uniform setting too: a like-for-like comparison
    for s in sorted({1, 4, 8, 16, 32} | {r.samples * f for _, f in ADAPTIVE_SWEEP}):
        if s != r.samples:
            add(replace(base, label=f"samples={s}", samples=s))
    for w in (0.03, 0.01, 0.001, 0.0001):
        if w != r.min_weight:
            add(replace(base, label=f"min_weight={format_weight(w)}", min_weight=w))
    for sc in (0.25, 0.5, 0.75):
        add(replace(base, label=f"scale={sc:g}", scale=sc))
    add(replace(base, label="generic", specialise=False))
    add(replace(base, label="schlick", fresnel="schlick"))
    # What footprint samples bring (render's default from 2 samples on a
    # checkered plane): the same samples, point-sampled
    if r.samples > 1 and footprint_default(scene):
        add(replace(base, label="point samples", footprint=False))
    # Combined presets: where several cheap changes together land.
    add(Setting("preset:preview", 4, 1, 0.01, scale=0.5))
    add(Setting("preset:fast", 4, 4, 0.01))
    # Adaptive sampling: the scene's samples and larger budgets, a few targets.
    add_adaptive(ADAPTIVE_SWEEP)
    return out


# ---------------------------------------------------------------- results and the Pareto front


def dominates(tj: float, ej: float, ti: float, ei: float, time_tol: float = 0.0, error_tol: float = 0.0) -> bool:
    """Whether point j = (time, error) dominates point i: no slower and no
    worse, and better in at least one.  With tolerances, differences within
    them (relative) are ties: j must be faster than i by more than time_tol
    or better by more than error_tol, and no slower or worse beyond them."""
    no_worse = tj <= ti * (1 + time_tol) and ej <= ei * (1 + error_tol)
    better = tj < ti * (1 - time_tol) or ej < ei * (1 - error_tol)
    return no_worse and better


def pareto_mask(times, errors, time_tol: float = 0.0, error_tol: float = 0.0) -> list[bool]:
    """True for the points that no other point dominates (see dominates)."""
    pts = list(zip((float(t) for t in times), (float(e) for e in errors)))
    return [not any(dominates(tj, ej, ti, ei, time_tol, error_tol) for j, (tj, ej) in enumerate(pts) if j != i)
            for i, (ti, ei) in enumerate(pts)]


@dataclass
class Result(Timings):
    """One setting's measurement on one scene: its timed renders (medians:
    Timings), its errors against the reference, its place on the fronts."""
    scene: str
    setting: Setting
    width: int
    height: int
    times: list[float] = field(default_factory=list)       # wall clock, ms
    cpu_times: list[float] = field(default_factory=list)   # process CPU time, ms
    errors: dict[str, float] = field(default_factory=dict)
    front: dict[str, bool] = field(default_factory=dict)   # on the Pareto front, per clock
    #: on the front of the uniform settings alone (None for adaptive ones)
    front_uniform: dict[str, bool | None] = field(default_factory=dict)
    #: samples per pixel used on average (adaptive: measured; uniform: samples)
    mean_spp: float | None = None
    #: shader programs its timed renders built (0 unless warm_up gave up)
    built_in_timed: int = 0

    @property
    def spp_used(self) -> float:
        return float(self.setting.samples) if self.mean_spp is None else self.mean_spp


def mark_fronts(results: list[Result], time_tol: float = DEFAULT_TIME_TOLERANCE,
                error_tol: float = DEFAULT_ERROR_TOLERANCE) -> None:
    """Set each result's Pareto membership for both clocks (time against
    RMSE): over all settings (``front``: the front), and over the uniform
    settings alone (``front_uniform``: where the front would be without
    adaptive sampling; None for the adaptive settings)."""
    uniform = [r for r in results if r.setting.adaptive is None]
    for clock in CLOCKS:
        mask = pareto_mask([r.t(clock) for r in results], [r.errors["rmse"] for r in results],
                           time_tol, error_tol)
        for res, m in zip(results, mask):
            res.front[clock] = m
        mask = pareto_mask([r.t(clock) for r in uniform], [r.errors["rmse"] for r in uniform],
                           time_tol, error_tol)
        for res in results:
            res.front_uniform[clock] = None
        for res, m in zip(uniform, mask):
            res.front_uniform[clock] = m
