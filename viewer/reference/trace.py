"""The float64 reference tracer proper: the Whitted ray tree of the scene,
written from the scene-format specification (``shared/spec/scene-format.md``)
alone, independently of the GPU shader, which it checks.

It favours clarity and exactness over speed, but it is vectorised over rays:
the ray tree is processed as a wavefront (batches of at most ``CHUNK`` rays
with their throughput, depth and pixel index), never with per-pixel Python
loops.  At each interaction (:mod:`.surfaces`) a ray takes the surface's
local Phong shading with shadow rays to every light, and spawns a reflected
and, at a dielectric, a refracted ray (:mod:`.optics`) while its depth is
below ``max_depth`` and its throughput at least ``min_weight``; a ray that
escapes sees the sky (:mod:`.sky`); a ray through a medium is absorbed.

Conventions (all arrays float64):

* ``render_reference(scene, W, H, samples=None, seed=0)`` -> (H, W, 3) linear
  RGB, exposure applied, not clamped, row 0 at the top: the box-filtered mean
  of the shared sub-pixel sample pattern (``base.sampling``).
* ``trace(scene, origins, dirs)`` -> (N, 3) radiance (no exposure) of arbitrary
  rays; each ray starts in the medium that contains its origin.

This module is also the reference's usual entry point: callers that import
it as a module (``from viewer.reference import trace as reference``) reach
``camera_rays``, ``pixel_rays`` (:mod:`.camera`) and ``first_hit``
(:mod:`.surfaces`) through it, so it re-exports them.  The refined
reference is :mod:`.refine`'s.
"""

from __future__ import annotations

import numpy as np

from ..base.sampling import sample_offsets
from ..scene.load import unit_vector
from ..scene.model import Scene
from .camera import camera_rays, pixel_rays
from .optics import fresnel_dielectric, refract, transmittance
from .sky import sky_radiance
from .surfaces import EPS_REL, Surfaces, first_hit
from .vectors import dot, normalize

__all__ = ["render_reference", "trace", "camera_rays", "pixel_rays", "first_hit"]

CHUNK = 1 << 15         # rays per wavefront batch (bounds memory of deep ray trees)
_INF = np.inf


class _Tracer(Surfaces):
    """The scene's surfaces (:class:`.surfaces.Surfaces`) with their shading
    and the ray tree over them."""

    def __init__(self, scene: Scene):
        super().__init__(scene)
        arr = self.per_object
        mats = self.materials
        self.color = arr(lambda m: m.color, 3)
        self.emission = arr(lambda m: m.emission, 3)
        self.ka = arr(lambda m: m.ambient)
        self.kd = arr(lambda m: m.diffuse)
        self.ks = arr(lambda m: m.specular)
        self.shin = arr(lambda m: m.shininess, air=1.0)
        self.refl = arr(lambda m: m.reflectivity)
        self.ior = arr(lambda m: m.ior, air=1.0)
        self.has_ck = np.array([m.checker is not None for m in mats] + [False])
        self.ck_size = arr(lambda m: m.checker.size if m.checker else 1.0, air=1.0)
        self.ck_color = arr(lambda m: m.checker.color if m.checker else (0, 0, 0), 3)
        self.ck_emis = arr(lambda m: (m.checker.emission if m.checker and m.checker.emission is not None
                                      else m.emission), 3)
        self.ambient = np.array(scene.ambient, dtype=np.float64)
        self.max_depth = scene.render.max_depth
        self.min_weight = scene.render.min_weight

    # -- local shading

    def shade(self, P, D, S, n_f):
        """E + C * (k_a A + sum_j L_j V_j [n.l > 0] (k_d n.l + k_s max(0, r.v)^p))."""
        C = self.color[S].copy()
        E = self.emission[S].copy()
        ck = self.has_ck[S]
        if ck.any():
            s = self.ck_size[S[ck]]
            # moved a little toward +x and +z (far more than the rounding of
            # P, far less than any feature): on a surface that lies on a
            # checker line (a box face at x = 0) floor(x / s) is then that of
            # the exact x all over, not of its rounding to either side
            e = 1e-9 * (self.size + np.linalg.norm(P[ck], axis=1))
            par = np.mod(np.floor((P[ck, 0] + e) / s) + np.floor((P[ck, 2] + e) / s), 2.0) == 1.0
            idx = np.nonzero(ck)[0][par]
            C[idx] = self.ck_color[S[idx]]
            E[idx] = self.ck_emis[S[idx]]
        local = E + C * (self.ka[S][:, None] * self.ambient)
        kd, ks, p = self.kd[S], self.ks[S], self.shin[S]
        lit = ((kd > 0) | (ks > 0)) & (C.max(axis=1) > 0)
        if not lit.any():
            return local
        v = -D
        for lt in self.scene.lights:
            with np.errstate(over="ignore"):        # beyond float64: inf (lit pixels are)
                Lc = np.array(lt.color, dtype=np.float64) * lt.intensity
            if not (Lc > 0).any():
                continue
            if lt.type == "point":
                # scaled by the largest component first, so that a light
                # 1e300 away neither overflows the length nor loses l
                half = np.array(lt.position, dtype=np.float64) / 2 - P / 2
                big = np.abs(half).max(axis=1, keepdims=True)
                with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                    u = half / big
                    n = np.linalg.norm(u, axis=1)
                    l = u / n[:, None]
                    dist = 2.0 * big[:, 0] * n
            else:
                l = np.broadcast_to(-np.array(unit_vector(lt.direction)), P.shape)
                dist = np.full(len(P), _INF)
            ndl = dot(n_f, l)
            m = lit & (ndl > 0.0)
            if not m.any():
                continue
            reach = dist[m]
            if lt.type == "point":
                # short of the light by its own offset (as a ray leaving a
                # surface): a light on a surface is not shadowed by it
                reach = reach - (EPS_REL * self.size + EPS_REL * float(np.max(np.abs(lt.position))))
            Vj = self.shadow(P[m], np.ascontiguousarray(l[m]), reach)
            r = 2.0 * ndl[m][:, None] * n_f[m] - l[m]
            rv = np.maximum(dot(r, v[m]), 0.0)
            term = kd[m] * ndl[m] + ks[m] * rv ** p[m]
            # a light whose colour * intensity overflows (1e200 * 1e200) is
            # inf: in shadow (V = 0) it adds 0, not inf * 0 = NaN
            with np.errstate(invalid="ignore", over="ignore"):
                add = C[m] * Lc * Vj * term[:, None]
            local[m] += np.where((Vj > 0) & (term[:, None] > 0) & (C[m] > 0), add, 0.0)
        return local

    # -- the ray tree

    def render_rays(self, O, D, pix, out, thr=None):
        """Trace rays and add their radiance (times throughput) into out[pix]."""
        N = len(O)
        thr = np.ones((N, 3)) if thr is None else thr
        depth = np.ones(N, dtype=np.int64)
        stack = [(O, D, thr, depth, pix)]
        npix = len(out)
        while stack:
            O, D, thr, depth, pix = stack.pop()
            if len(O) > CHUNK:
                stack.append((O[CHUNK:], D[CHUNK:], thr[CHUNK:], depth[CHUNK:], pix[CHUNK:]))
                O, D, thr, depth, pix = O[:CHUNK], D[:CHUNK], thr[:CHUNK], depth[:CHUNK], pix[:CHUNK]
            kind, t, S, nrm, med, med_after = self.next_interaction(O, D)
            thr = thr * transmittance(self.absorb[med], t)
            contrib = np.zeros((len(O), 3))
            esc = kind == 0
            if esc.any():
                contrib[esc] = thr[esc] * sky_radiance(self.scene, D[esc])
            h = np.nonzero(~esc)[0]
            children = []
            if h.size:
                Oh, Dh, th, Sh = O[h], D[h], t[h], S[h]
                P = Oh + th[:, None] * Dh
                n = nrm[h]
                n_f = np.where((dot(n, Dh) > 0.0)[:, None], -n, n)
                contrib[h] = thr[h] * self.shade(P, Dh, Sh, n_f)
                go = depth[h] < self.max_depth
                cos_i = np.clip(-dot(n_f, Dh), 0.0, 1.0)
                mirror = Dh + 2.0 * cos_i[:, None] * n_f
                diel = kind[h] == 2
                R = np.zeros(len(h))
                if diel.any():
                    R[diel] = fresnel_dielectric(cos_i[diel], self.ior[med[h][diel]],
                                                 self.ior[med_after[h][diel]])
                f_refl = np.where(diel, R, self.refl[Sh])
                f_refr = np.where(diel, (1.0 - R) * self.transp[Sh], 0.0)
                # reflected branch
                tr = thr[h] * f_refl[:, None]
                w = tr.max(axis=1)
                ok = go & (w > 0.0) & (w >= self.min_weight)
                if ok.any():
                    children.append((P[ok], normalize(mirror[ok]), tr[ok], depth[h][ok] + 1, pix[h][ok]))
                # refracted branch
                tt = thr[h] * f_refr[:, None]
                w = tt.max(axis=1)
                ok = go & diel & (w > 0.0) & (w >= self.min_weight)
                if ok.any():
                    sel = np.nonzero(ok)[0]
                    dirs, good = refract(Dh[sel], n_f[sel], self.ior[med[h][sel]],
                                         self.ior[med_after[h][sel]])
                    sel = sel[good]
                    children.append((P[sel], dirs[good], tt[sel], depth[h][sel] + 1, pix[h][sel]))
            for c in range(3):
                out[:, c] += np.bincount(pix, weights=contrib[:, c], minlength=npix)
            if children:
                stack.append(tuple(np.concatenate([ch[k] for ch in children]) for k in range(5)))
        return out


def trace(scene: Scene, origins, dirs) -> np.ndarray:
    """Radiance (N, 3) along arbitrary rays (no exposure)."""
    O = np.ascontiguousarray(np.asarray(origins, dtype=np.float64).reshape(-1, 3))
    D = normalize(np.asarray(dirs, dtype=np.float64).reshape(-1, 3))
    ctx = _Tracer(scene)
    out = np.zeros((len(O), 3))
    if len(O):
        ctx.render_rays(O, D, np.arange(len(O)), out)
    return out


def render_reference(scene: Scene, width: int, height: int, samples: int | None = None,
                     seed: int = 0) -> np.ndarray:
    """(H, W, 3) float64 linear image: box-filtered average of ``samples`` rays per
    pixel at the shared sub-pixel offsets, times the exposure; not clamped."""
    n = scene.render.samples if samples is None else int(samples)
    offs = sample_offsets(n, seed)
    ctx = _Tracer(scene)
    npix = width * height
    out = np.zeros((npix, 3))
    per = max(1, CHUNK // max(npix, 1))
    for k0 in range(0, n, per):
        Os, Ds = [], []
        for k in range(k0, min(n, k0 + per)):
            o, d = camera_rays(scene, width, height, offs[k])
            Os.append(o.reshape(-1, 3))
            Ds.append(d.reshape(-1, 3))
        O = np.concatenate(Os)
        D = np.concatenate(Ds)
        pix = np.tile(np.arange(npix), len(Os))
        ctx.render_rays(O, D, pix, out)
    img = out.reshape(height, width, 3) / n
    return img * scene.render.exposure
