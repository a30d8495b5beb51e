"""Where rays meet the scene: the reference tracer's surface and medium
queries over all objects at once.

:class:`Surfaces` holds the scene's solids and media in array form and
answers, for batches of rays, where each ray's next interaction is
(:meth:`Surfaces.next_interaction`) and how much of a light reaches a
point (:meth:`Surfaces.shadow`); :func:`first_hit` and :func:`medium_at`
are its public queries:

* ``first_hit(scene, origins, dirs)`` -> (t, obj_index, outward normal) of the
  first geometric surface, media ignored (t = inf, index -1 when none).
* ``medium_at(scene, points)`` -> index of the first transparent object whose
  solid contains each point (-1: air).

How surfaces are found.  Every solid is described, along a ray, by the
interval(s) of t where the ray is inside it (:mod:`.primitives`).  The
endpoints of those intervals are the surface crossings.  At the nearest
crossings (grouped within a small epsilon, so coincident surfaces are
found together) an opaque surface, if any, is the interaction; otherwise
the medium on the far side is found by point containment at the middle of
the next stretch of the ray, and the crossing is an interaction only where
it differs from the medium the ray travels in (itself found by containment
at the middle of its first stretch).  A new ray starts exactly at its
interaction point and ignores crossings closer than the epsilon, which
scales with the scene size and the point's magnitude (``EPS_REL``, about
1e-7 of them: far below the thinnest feature, far above float64 error).

Invariants: per-object arrays have one extra entry at the end, so that
index -1 reads air (ior 1, no absorption); the surface crossings are
columns in object order, so that ties go to the first object; nothing
here shades.
"""

from __future__ import annotations

import numpy as np

from ..scene.model import Scene
from .optics import transmittance
from .primitives import primitive
from .vectors import normalize

__all__ = ["Surfaces", "first_hit", "medium_at", "EPS_REL"]

EPS_REL = 1e-7          # secondary-ray offset / coincidence tolerance, relative to the scene size
_INF = np.inf


class Surfaces:
    """The scene's solids and media in array form, and the ray queries on them."""

    def __init__(self, scene: Scene):
        self.scene = scene
        objs = scene.objects
        self.prims = [primitive(o) for o in objs]
        self.materials = [scene.materials[o.material] for o in objs]
        self.n = len(objs)
        self.transp = self.per_object(lambda m: m.transparency)
        self.absorb = self.per_object(lambda m: m.absorption, 3)
        self.transparent = [k for k, m in enumerate(self.materials) if m.transparency > 0.0]
        # one column per surface crossing; columns in object order
        col_obj = []
        for k, p in enumerate(self.prims):
            col_obj += [k] * p.ncols
        self.col_obj = np.array(col_obj, dtype=np.int64)
        self.col_opq = np.array([self.transp[k] == 0.0 for k in col_obj], dtype=bool)
        self.K = len(col_obj)
        # scene size for the epsilon, and the step past a ray's last crossing
        # at which its medium is probed: no absolute floor or step, so that
        # the tracer is scale-free (tests/scene/test_scale.py: 1e-30 to 1e30; a
        # floor of 1.0 made a 1e-5 scene acne, a step of 1.0 vanished
        # against t at 1e20).  position != target, so size > 0.
        size = max([1e-300, float(np.linalg.norm(scene.camera.position)),
                    float(np.linalg.norm(scene.camera.target))]
                   + [p.extent() for p in self.prims])
        # (not the point lights: a light 1e20 away, a sun, made every offset
        # 1e14 and the rays passed through the whole scene)
        self.size = size

    def per_object(self, fn, dim=None, air=0.0):
        """``fn(material)`` of every object, (n + 1,) or (n + 1, dim), with one
        extra entry at the end for "air / none", so that index -1 reads air."""
        shape = (self.n + 1,) if dim is None else (self.n + 1, dim)
        a = np.full(shape, air, dtype=np.float64)
        for k, m in enumerate(self.materials):
            a[k] = fn(m)
        return a

    # -- geometry

    def eps(self, P):
        """Offset of a ray starting at P: crossings closer than this are the surface
        it leaves.  Crossings within eps + EPS_REL * t of the nearest one (at t)
        are taken as one coincident group."""
        return EPS_REL * (self.size + np.linalg.norm(P, axis=1))

    def table(self, O, D, normals=True):
        N = len(O)
        T = np.full((N, max(self.K, 1)), _INF)
        NR = np.zeros((N, max(self.K, 1), 3)) if normals else None
        c = 0
        for p in self.prims:
            for t, nrm in p.columns(O, D, normals):
                T[:, c] = t
                if normals:
                    NR[:, c] = nrm
                c += 1
        T[~np.isfinite(T)] = _INF  # nan or -inf: no crossing ahead
        return T, NR

    def medium(self, P):
        med = np.full(len(P), -1, dtype=np.int64)
        for k in reversed(self.transparent):
            med[self.prims[k].contains(P)] = k
        return med

    def _first_group(self, T, lo):
        return np.where(T > lo[:, None], T, _INF).min(axis=1)

    # -- the next interaction of each ray

    def next_interaction(self, O, D):
        """For each ray: kind (0 escape, 1 opaque, 2 dielectric), t, object S,
        outward normal of S, medium travelled in, medium beyond (dielectric)."""
        N = len(O)
        T, NR = self.table(O, D)
        eps = self.eps(O)
        kind = np.zeros(N, dtype=np.int64)
        t_hit = np.full(N, _INF)
        S = np.full(N, -1, dtype=np.int64)
        nrm = np.zeros((N, 3))
        med_after = np.full(N, -1, dtype=np.int64)
        lo = eps.copy()
        tg = self._first_group(T, lo)
        mid = np.where(np.isfinite(tg), 0.5 * (lo + tg), lo + self.size)
        med = self.medium(O + mid[:, None] * D) if self.transparent else np.full(N, -1, dtype=np.int64)
        act = np.arange(N)
        while act.size:
            Ta = T[act]
            lo_a = lo[act]
            tg = np.where(Ta > lo_a[:, None], Ta, _INF).min(axis=1)
            fin = np.isfinite(tg)
            act, Ta, lo_a, tg = act[fin], Ta[fin], lo_a[fin], tg[fin]
            if not act.size:
                break
            hi = tg + eps[act] + EPS_REL * tg
            grp = (Ta > lo_a[:, None]) & (Ta <= hi[:, None])
            opq = grp & self.col_opq[None, :]
            any_opq = opq.any(axis=1)
            if any_opq.any():
                sel = act[any_opq]
                Tm = np.where(opq[any_opq], Ta[any_opq], _INF)
                col = np.argmin(Tm, axis=1)
                kind[sel] = 1
                t_hit[sel] = Tm[np.arange(len(sel)), col]
                S[sel] = self.col_obj[col]
                nrm[sel] = NR[sel, col]
            rest = ~any_opq
            act, Ta, tg, hi, grp = act[rest], Ta[rest], tg[rest], hi[rest], grp[rest]
            if not act.size:
                break
            tn = np.where(Ta > hi[:, None], Ta, _INF).min(axis=1)
            mid = np.where(np.isfinite(tn), 0.5 * (tg + tn), tg + self.size)
            after = self.medium(O[act] + mid[:, None] * D[act])
            inter = after != med[act]
            if inter.any():
                sel = act[inter]
                g = grp[inter] & ~self.col_opq[None, :]
                col = np.argmax(g, axis=1)  # first transparent surface in object order
                kind[sel] = 2
                t_hit[sel] = tg[inter]
                S[sel] = self.col_obj[col]
                nrm[sel] = NR[sel, col]
                med_after[sel] = after[inter]
            keep = ~inter
            act = act[keep]
            lo[act] = hi[keep]
        return kind, t_hit, S, nrm, med, med_after

    # -- shadow rays

    def shadow(self, P, L, tmax):
        """Fraction (N, 3) of a light's radiance reaching P along unit L over
        distance tmax (inf for a directional light)."""
        N = len(P)
        V = np.ones((N, 3))
        if N == 0:
            return V
        T, _ = self.table(P, L, normals=False)
        eps = self.eps(P)
        lo = eps.copy()
        tg = self._first_group(T, lo)
        end = np.minimum(tg, tmax)
        mid = np.where(np.isfinite(end), 0.5 * (lo + end), lo + self.size)
        med = self.medium(P + mid[:, None] * L) if self.transparent else np.full(N, -1, dtype=np.int64)
        t_prev = np.zeros(N)
        act = np.arange(N)
        while act.size:
            Ta = T[act]
            tg = np.where(Ta > lo[act][:, None], Ta, _INF).min(axis=1)
            done = tg >= tmax[act]
            if done.any():
                d = act[done]
                V[d] *= transmittance(self.absorb[med[d]], tmax[d] - t_prev[d])
            act, Ta, tg = act[~done], Ta[~done], tg[~done]
            if not act.size:
                break
            hi = tg + eps[act] + EPS_REL * tg
            grp = (Ta > lo[act][:, None]) & (Ta <= hi[:, None])
            blocked = (grp & self.col_opq[None, :]).any(axis=1)
            V[act[blocked]] = 0.0
            keep = ~blocked
            act, Ta, tg, hi, grp = act[keep], Ta[keep], tg[keep], hi[keep], grp[keep]
            if not act.size:
                break
            tn = np.where(Ta > hi[:, None], Ta, _INF).min(axis=1)
            mid = np.where(np.isfinite(tn), 0.5 * (tg + tn), tg + self.size)
            after = self.medium(P[act] + mid[:, None] * L[act])
            inter = after != med[act]
            if inter.any():
                sel = act[inter]
                col = np.argmax(grp[inter] & ~self.col_opq[None, :], axis=1)
                V[sel] *= self.transp[self.col_obj[col]][:, None]
            V[act] *= transmittance(self.absorb[med[act]], tg - t_prev[act])
            t_prev[act] = tg
            med[act] = after
            lo[act] = hi
            act = act[V[act].max(axis=1) > 0.0]
        return V


def first_hit(scene: Scene, origins, dirs, tmin: float = 0.0):
    """First geometric surface along each ray (media ignored): t (N,), object
    index (N,) into scene.objects (-1 with t = inf when none), and the unit
    outward normal (N, 3) of that solid at the hit."""
    O = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    D = normalize(np.asarray(dirs, dtype=np.float64).reshape(-1, 3))
    ctx = Surfaces(scene)
    N = len(O)
    if ctx.K == 0:
        return np.full(N, _INF), np.full(N, -1, dtype=np.int64), np.zeros((N, 3))
    T, NR = ctx.table(O, D)
    T = np.where(T > tmin, T, _INF)
    col = np.argmin(T, axis=1)
    idx = np.arange(N)
    t = T[idx, col]
    hit = np.isfinite(t)
    obj = np.where(hit, ctx.col_obj[col], -1)
    nrm = np.where(hit[:, None], NR[idx, col], 0.0)
    return t, obj, nrm


def medium_at(scene: Scene, points) -> np.ndarray:
    """Index of the first transparent object containing each point, -1 for air."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return Surfaces(scene).medium(P)
