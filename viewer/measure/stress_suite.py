"""Running the stress suite's cases: the GPU image and the float64
reference of each case, the pixels masked as straddling an edge, and the
metrics of the table (display space: the spec's 8-bit encoding).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field

import numpy as np

from ..base.imageio import to_display8
from ..gpu.renderer import Renderer
from ..reference import trace as reference
from .stress_cases import DEFAULT_TOL, Case, case_scene

STRADDLE_DELTA = 1 / 64      # pixels: how close to the sample point an edge must pass to mask it
STRADDLE_LEVELS = 2          # a change (8-bit levels) within STRADDLE_DELTA that marks an edge
ACNE_LEVEL = 0.05            # darker than the reference by this much (display 0..1)


# ---------------------------------------------------------------- image metrics


def display8(linear: np.ndarray) -> np.ndarray:
    return to_display8(np.nan_to_num(linear, nan=0.0, posinf=1.0, neginf=0.0))


def level_diff(a8: np.ndarray, b8: np.ndarray) -> np.ndarray:
    """(H, W) largest channel difference in 8-bit levels."""
    return np.abs(a8.astype(np.int32) - b8.astype(np.int32)).max(axis=-1)


def off_fraction(a8: np.ndarray, b8: np.ndarray, mask: np.ndarray | None = None, levels: float = 1) -> float:
    """Fraction of the unmasked pixels whose largest channel difference exceeds `levels`."""
    off = level_diff(a8, b8) > levels
    keep = np.ones(off.shape, bool) if mask is None else ~mask
    return float(np.sum(off & keep) / max(1, np.sum(keep)))


@dataclass
class CheckResult:
    label: str
    value: float
    limit: float
    ok: bool

    def text(self) -> str:
        if "furnace" in self.label:
            return f"{self.label} {self.value:.1e}<={self.limit:g}"
        return f"{self.label} {100 * self.value:.2f}%<={100 * self.limit:g}%"


@dataclass
class CaseResult:
    name: str
    size: tuple[int, int]
    max_err: float          # 8-bit levels, unmasked
    mean_err: float         # 8-bit levels, unmasked
    off1: float             # fraction of unmasked pixels > 1 level
    off05: float            # fraction of unmasked pixels > 0.05
    masked: float           # fraction of pixels masked
    nonfinite: int
    acne: float
    ms: float
    checks: list[CheckResult] = field(default_factory=list)
    tol: float = DEFAULT_TOL
    gpu8: np.ndarray | None = None
    ref8: np.ndarray | None = None
    mask: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return self.nonfinite == 0 and self.off1 <= self.tol and all(c.ok for c in self.checks)


class Suite:
    """Renders and caches what the cases need: GPU images, reference images,
    straddle masks and the reference's primary hits, keyed by scene content."""

    def __init__(self, ctx, naive: bool = False):
        self.ctx = ctx
        self.naive = naive
        self._cache: dict = {}

    scene = staticmethod(case_scene)

    def _memo(self, kind: str, doc: dict, w: int, h: int, fn):
        key = (kind, json.dumps(doc, sort_keys=True), w, h, self.naive)
        if key not in self._cache:
            self._cache[key] = fn()
        return self._cache[key]

    def gpu(self, doc: dict, w: int, h: int) -> tuple[np.ndarray, float]:
        """(image, ms of one render after a warm-up)."""
        def go():
            r = Renderer(self.ctx, self.scene(doc),
                         extra_defines={"NAIVE_INTERSECT": True} if self.naive else None)
            try:
                r.render(w, h, 1)
                t0 = time.perf_counter()
                img = r.render(w, h, 1)
                self.ctx.finish()
                return img, (time.perf_counter() - t0) * 1000.0
            finally:
                r.release()
        return self._memo("gpu", doc, w, h, go)

    def reference(self, doc: dict, w: int, h: int) -> np.ndarray:
        return self._memo("ref", doc, w, h, lambda: reference.render_reference(self.scene(doc), w, h, samples=1))

    def straddle(self, doc: dict, w: int, h: int) -> np.ndarray:
        """Pixels whose footprint straddles an edge at the sample point: the
        reference traced STRADDLE_DELTA of a pixel left, right, above and below
        the centre differs from the centred ray by more than STRADDLE_LEVELS
        8-bit levels (some edge passes within STRADDLE_DELTA of the centre)."""
        def go():
            scene = self.scene(doc)
            centre = display8(self.reference(doc, w, h)).astype(np.int32)
            spread = np.zeros((h, w), np.int32)
            for du, dv in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                off = (0.5 + du * STRADDLE_DELTA, 0.5 + dv * STRADDLE_DELTA)
                o, d = reference.camera_rays(scene, w, h, off)
                rad = reference.trace(scene, o.reshape(-1, 3), d.reshape(-1, 3)).reshape(h, w, 3)
                v = display8(rad * scene.render.exposure).astype(np.int32)
                spread = np.maximum(spread, np.abs(v - centre).max(axis=-1))
            return spread > STRADDLE_LEVELS
        return self._memo("mask", doc, w, h, go)

    def opaque_hits(self, doc: dict, w: int, h: int) -> np.ndarray:
        """Pixels whose centred primary ray meets an opaque surface first (reference)."""
        def go():
            scene = self.scene(doc)
            o, d = reference.camera_rays(scene, w, h)
            _, obj, _ = reference.first_hit(scene, o.reshape(-1, 3), d.reshape(-1, 3))
            opaque = np.array([not scene.is_transparent(ob) for ob in scene.objects] + [False])
            return opaque[obj].reshape(h, w)      # index -1 (a miss) picks the trailing False
        return self._memo("opaque", doc, w, h, go)

    def run_case(self, case: Case, size: tuple[int, int]) -> CaseResult:
        w, h = size
        if case.centre:
            w, h = w | 1, h | 1
        doc = case.build()
        ref_doc = case.reference() if case.reference is not None else doc
        gpu, ms = self.gpu(doc, w, h)
        ref = self.reference(ref_doc, w, h)
        mask = self.straddle(ref_doc, w, h)
        nonfinite = int(np.sum(~np.all(np.isfinite(gpu), axis=-1)))
        g8, r8 = display8(gpu), display8(ref)
        diff = level_diff(g8, r8)
        keep = ~mask
        vals = diff[keep] if keep.any() else np.zeros(1)
        darker = (r8.astype(np.int32) - g8.astype(np.int32)).max(axis=-1) > ACNE_LEVEL * 255
        opq = self.opaque_hits(ref_doc, w, h) & keep
        res = CaseResult(
            name=case.name, size=(w, h), max_err=float(vals.max()), mean_err=float(vals.mean()),
            off1=off_fraction(g8, r8, mask), off05=off_fraction(g8, r8, mask, ACNE_LEVEL * 255),
            masked=float(mask.mean()), nonfinite=nonfinite,
            acne=float(np.sum(darker & opq) / max(1, np.sum(opq))), ms=ms, tol=case.tol,
            gpu8=g8, ref8=r8, mask=mask)
        for chk in case.checks:
            if chk.kind == "furnace":
                err = float(np.max(np.abs(np.nan_to_num(gpu, nan=np.inf) - np.array(chk.colour)))) if gpu.size else 0.0
                res.checks.append(CheckResult(chk.label, err, chk.limit, err <= chk.limit))
            else:
                other_doc = chk.other()
                other, _ = self.gpu(other_doc, w, h)
                m = mask | self.straddle(other_doc, w, h)
                frac = off_fraction(g8, display8(other), m)
                res.checks.append(CheckResult(chk.label, frac, chk.limit, frac <= chk.limit))
        return res
