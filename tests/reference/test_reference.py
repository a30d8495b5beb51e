"""The float64 NumPy reference tracer (viewer.reference) against expectations
that do not come from it: the Fresnel / refraction / Beer-Lambert numbers of
shared/spec/test-vectors.md, analytic intersections, and physical invariants
(media that vanish, a furnace, a ball lens that flips the image, mirror
symmetry, the spec's depth and coincident-surface rules)."""

from __future__ import annotations

import copy
import math
import struct
import time

import numpy as np
import pytest

from viewer.reference.camera import camera_rays
from viewer.reference.optics import fresnel_dielectric, refract
from viewer.reference.primitives import contains
from viewer.reference.surfaces import first_hit, medium_at
from viewer.reference.trace import render_reference, trace
from viewer.scene.load import load_scene, scene_from_dict

# --------------------------------------------------------------------------- helpers

CLEAR = {"color": [1, 1, 1], "ambient": 0, "diffuse": 0, "specular": 0, "transparency": 1}
EMISSIVE_BLACK = {"color": [0, 0, 0], "ambient": 0, "diffuse": 0}


def make_scene(objects, materials, *, sky=None, lights=(), camera=None, render=None, ambient=(0, 0, 0),
               base_dir=None):
    d = {"name": "t", "ambient": list(ambient), "materials": materials, "objects": list(objects),
         "lights": list(lights), "sky": sky or {"type": "color", "color": [1, 1, 1]}}
    if camera is not None:
        d["camera"] = camera
    if render is not None:
        d["render"] = render
    return scene_from_dict(d, base_dir=base_dir)


def rays(origins, dirs):
    o = np.atleast_2d(np.asarray(origins, dtype=float))
    d = np.atleast_2d(np.asarray(dirs, dtype=float))
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(o, d.shape).copy()
    return o, d


def rot(angles_deg):
    """Rz Ry Rx built from the spec's words: right-handed, positive z turns +x toward +y."""
    x, y, z = np.radians(angles_deg)
    rx = np.array([[1, 0, 0], [0, math.cos(x), -math.sin(x)], [0, math.sin(x), math.cos(x)]])
    ry = np.array([[math.cos(y), 0, math.sin(y)], [0, 1, 0], [-math.sin(y), 0, math.cos(y)]])
    rz = np.array([[math.cos(z), -math.sin(z), 0], [math.sin(z), math.cos(z), 0], [0, 0, 1]])
    return rz @ ry @ rx


def angle_deg(a, b):
    """Angle between row vectors, accurate near 0 and 180 degrees."""
    c = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.degrees(np.arctan2(c, np.einsum("ij,ij->i", a, b)))


# --------------------------------------------------------------------------- Fresnel and refraction

from vectors import ANGLES, CRITICAL, NEAR_CRITICAL, R_TABLE, T_TABLE, TIR  # noqa: E402


@pytest.mark.parametrize("pair", list(R_TABLE))
def test_fresnel_table(pair):
    n1, n2 = pair
    cos_i = np.cos(np.radians(ANGLES))
    R = fresnel_dielectric(cos_i, n1, n2)
    for a, want, got in zip(ANGLES, R_TABLE[pair], R):
        if want is TIR:
            assert got == 1.0, (pair, a)
        else:
            assert abs(got - want) <= 1e-6, (pair, a, got, want)
    if pair in CRITICAL:  # at and beyond the critical angle: R = 1
        crit = math.degrees(math.asin(n2 / n1))
        assert abs(crit - CRITICAL[pair]) < 1e-4
        beyond = np.cos(np.radians([crit + 1e-7, crit + 1, 80, 90]))
        assert np.all(fresnel_dielectric(beyond, n1, n2) == 1.0)


@pytest.mark.parametrize("pair", list(NEAR_CRITICAL))
def test_fresnel_near_critical(pair):
    n1, n2 = pair
    for a, want in NEAR_CRITICAL[pair]:
        got = fresnel_dielectric(math.cos(math.radians(a)), n1, n2)
        assert abs(got - want) <= 1e-6, (pair, a, got, want)


def test_fresnel_is_not_schlick_and_vectorised():
    # broadcasting over n1/n2 arrays, and equal media reflect nothing
    cos_i = np.cos(np.radians([60.0, 60.0, 30.0]))
    R = fresnel_dielectric(cos_i, np.array([1.5, 1.0, 1.33]), np.array([1.33, 1.5, 1.33]))
    assert np.allclose(R, [0.161223, 0.089187, 0.0], atol=1e-6)
    assert fresnel_dielectric(0.3, 1.2, 1.2) == 0.0
    r0 = ((1.5 - 1.33) / (1.5 + 1.33)) ** 2
    schlick = r0 + (1 - r0) * (1 - math.cos(math.radians(60))) ** 5
    assert abs(fresnel_dielectric(math.cos(math.radians(60)), 1.5, 1.33) - schlick) > 0.1


@pytest.mark.parametrize("pair", list(T_TABLE))
def test_refraction_angles(pair):
    n1, n2 = pair
    th = np.radians(ANGLES)
    n = np.tile([0.0, 1.0, 0.0], (len(ANGLES), 1))           # surface normal, +y
    d = np.stack([np.sin(th), -np.cos(th), np.zeros_like(th)], axis=1)  # going down into it
    t, ok = refract(d, n, n1, n2)
    got = angle_deg(t, np.tile([0.0, -1.0, 0.0], (len(ANGLES), 1)))
    for k, want in enumerate(T_TABLE[pair]):
        if want is TIR:
            assert not ok[k], (pair, ANGLES[k])
        else:
            assert ok[k]
            assert abs(got[k] - want) <= 1e-6, (pair, ANGLES[k], got[k], want)
            assert abs(np.linalg.norm(t[k]) - 1) < 1e-12
            assert t[k, 0] >= 0 and t[k, 1] < 0  # goes on forward, through the surface
    # the normal's orientation does not matter
    t2, ok2 = refract(d, -n, n1, n2)
    assert np.array_equal(ok, ok2) and np.allclose(t, t2, atol=1e-15)


def test_beer_lambert_through_tracer():
    # A clear (ior 1) absorbing box 1.2 thick in front of a white sky: a = 0.5
    # keeps 0.548812 (test-vectors.md); per channel.
    mats = {"tinted": dict(CLEAR, ior=1.0, absorption=[0.5, 0.25, 0.0])}
    s = make_scene([{"type": "box", "min": [-1, -1, -0.6], "max": [1, 1, 0.6], "material": "tinted"}],
                   mats, render={"max_depth": 4})
    L = trace(s, *rays([0.1, 0.2, 5.0], [0, 0, -1]))[0]
    assert np.allclose(L, [0.548812, math.exp(-0.25 * 1.2), 1.0], atol=1e-6)
    # a ray that starts inside the medium: the medium containing its origin (0.2 to go)
    L = trace(s, *rays([0.1, 0.2, -0.4], [0, 0, -1]))[0]
    assert np.allclose(L, np.exp(-np.array([0.5, 0.25, 0.0]) * 0.2), atol=1e-12)


# --------------------------------------------------------------------------- geometry

MAT1 = {"m": {}}


def one(obj):
    return make_scene([dict(obj, material="m")], MAT1)


def test_sphere_hits_analytic():
    c, r = np.array([0.3, 1.1, -0.4]), 0.7
    s = one({"type": "sphere", "center": c.tolist(), "radius": r})
    rng = np.random.default_rng(1)
    O = rng.uniform(-4, 4, (400, 3))
    O = O[np.linalg.norm(O - c, axis=1) > r + 0.1]
    target = c + rng.uniform(-0.9, 0.9, O.shape) * r
    D = target - O
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    t, idx, n = first_hit(s, O, D)
    # analytic: smallest positive root of |o + t d - c|^2 = r^2
    b = np.einsum("ij,ij->i", O - c, D)
    cc = np.einsum("ij,ij->i", O - c, O - c) - r * r
    disc = b * b - cc
    want = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    assert np.allclose(np.where(np.isfinite(want), t, 0), np.where(np.isfinite(want), want, 0), atol=1e-9)
    assert np.array_equal(np.isfinite(t), np.isfinite(want))
    hit = np.isfinite(t)
    assert hit.sum() > 100
    assert np.all(idx[hit] == 0) and np.all(idx[~hit] == -1)
    P = O[hit] + t[hit, None] * D[hit]
    assert np.allclose(n[hit], (P - c) / r, atol=1e-9)
    # from inside: the far side, normal still outward (along the ray)
    t, idx, n = first_hit(s, *rays(c, [[1, 0, 0], [0, -1, 0]]))
    assert np.allclose(t, r) and np.allclose(n, [[1, 0, 0], [0, -1, 0]])


def test_axis_aligned_box():
    s = one({"type": "box", "min": [-1, 0, -2], "max": [2, 0.5, 1]})
    O, D = rays([[5, 0.25, 0], [0.3, 3, 0.2], [0.3, 0.25, -7], [0.5, 0.25, 0], [0, 5, 5]],
                [[-1, 0, 0], [0, -1, 0], [0, 0, 1], [0, 1, 0], [0, 1, 0]])
    t, idx, n = first_hit(s, O, D)
    assert np.allclose(t[:4], [3, 2.5, 5, 0.25])
    assert np.allclose(n[:4], [[1, 0, 0], [0, 1, 0], [0, 0, -1], [0, 1, 0]])
    assert t[4] == np.inf and idx[4] == -1


def test_rotated_box_signs():
    # Bars 4 long turned by +30 deg about one axis each; a ray meets the face whose
    # position depends on the sign of the turn (a wrong sign gives another t).
    c30, s30 = math.cos(math.radians(30)), math.sin(math.radians(30))
    # about z, +x turns toward +y: the bar along x rises to the right; a ray down at
    # x = 1 meets the top face -x s30 + y c30 = 0.5
    s = one({"type": "box", "min": [-2, -0.5, -0.5], "max": [2, 0.5, 0.5], "rotate": [0, 0, 30]})
    t, idx, n = first_hit(s, *rays([1.0, 10, 0], [0, -1, 0]))
    assert abs((10 - t[0]) - (0.5 + 1.0 * s30) / c30) < 1e-9
    assert np.allclose(n[0], [-s30, c30, 0])
    # about y, +z turns toward +x: the bar along z leans to +x at its +z end; a ray
    # along -x at z = 1 meets the +x face x c30 - z s30 = 0.5
    s = one({"type": "box", "min": [-0.5, -0.5, -2], "max": [0.5, 0.5, 2], "rotate": [0, 30, 0]})
    t, _, n = first_hit(s, *rays([10, 0, 1.0], [-1, 0, 0]))
    assert abs((10 - t[0]) - (0.5 + 1.0 * s30) / c30) < 1e-9
    assert np.allclose(n[0], [c30, 0, -s30])
    # about x, +y turns toward +z: the bar along y leans to +z at its top; a ray along
    # -z at y = 1 meets the +z face -y s30 + z c30 = 0.5
    s = one({"type": "box", "min": [-0.5, -2, -0.5], "max": [0.5, 2, 0.5], "rotate": [30, 0, 0]})
    t, _, n = first_hit(s, *rays([0, 1.0, 10], [0, 0, -1]))
    assert abs((10 - t[0]) - (0.5 + 1.0 * s30) / c30) < 1e-9
    assert np.allclose(n[0], [0, -s30, c30])
    # the order: x first, then y, then z (Rz Ry Rx), seen on a long thin bar's far end
    ang = [40.0, 25.0, -60.0]
    s = one({"type": "box", "min": [-3, -0.01, -0.01], "max": [3, 0.01, 0.01], "rotate": ang})
    tip = rot(ang) @ [3.0, 0, 0]
    t, _, _ = first_hit(s, *rays(tip * 2, -tip))
    assert abs(t[0] - 3.0) < 0.02
    wrong = rot([ang[0], 0, 0]) @ rot([0, ang[1], 0]) @ rot([0, 0, ang[2]]) @ [3.0, 0, 0]  # z first
    assert np.linalg.norm(wrong - tip) > 0.5  # the check above distinguishes the order


def test_rotated_box_random_rays_and_reintersection():
    lo, hi, ang = np.array([-0.3, 0.2, -1.0]), np.array([0.9, 1.0, 0.5]), [25.0, -40.0, 70.0]
    s = one({"type": "box", "min": lo.tolist(), "max": hi.tolist(), "rotate": ang})
    c, h, R = (lo + hi) / 2, (hi - lo) / 2, rot(ang)
    rng = np.random.default_rng(7)
    # aim at known surface points from outside, along their face normals
    face = rng.integers(0, 3, 300)
    sign = rng.choice([-1.0, 1.0], 300)
    local = rng.uniform(-0.95, 0.95, (300, 3)) * h
    local[np.arange(300), face] = sign * h[face]
    nl = np.zeros((300, 3))
    nl[np.arange(300), face] = sign
    P = c + local @ R.T
    nw = nl @ R.T
    tilt = rng.normal(0, 0.3, (300, 3))
    D = -nw + tilt - np.einsum("ij,ij->i", tilt, nw)[:, None] * nw
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    O = P - 5 * D
    t, idx, n = first_hit(s, O, D)
    assert np.allclose(t, 5, atol=1e-9)
    assert np.allclose(n, nw, atol=1e-9)
    # re-intersect from just inside: the exit point lies on the surface, normal along the ray
    O2 = P + 1e-7 * D
    t2, idx2, n2 = first_hit(s, O2, D)
    assert np.all(np.isfinite(t2)) and np.all(idx2 == 0)
    Q = ((O2 + t2[:, None] * D) - c) @ R  # back to the box frame
    assert np.allclose(np.max(np.abs(Q) / h, axis=1), 1.0, atol=1e-9)
    assert np.all(np.einsum("ij,ij->i", n2, D) > 0)
    # just past the exit nothing is left
    t3, idx3, _ = first_hit(s, O2 + (t2[:, None] + 1e-7) * D, D)
    assert np.all(np.isinf(t3)) and np.all(idx3 == -1)


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_cylinder_each_axis(axis):
    a = "xyz".index(axis)
    e = np.eye(3)[a]
    p = np.eye(3)[(a + 1) % 3]  # a direction perpendicular to the axis
    base = np.array([0.2, -0.3, 0.5])
    r, hgt = 0.6, 1.5
    s = one({"type": "cylinder", "axis": axis, "base": base.tolist(), "radius": r, "height": hgt})
    mid = base + 0.7 * e
    O, D = rays([mid + 4 * p, base - 3 * e + 0.1 * p, base + (hgt + 2) * e - 0.2 * p,
                 base + 2 * p + 0.4 * e, base + 0.3 * p - 0.5 * e],
                [-p, e, -e, -p + 0.3 * e, e + 0.2 * p])
    t, idx, n = first_hit(s, O, D)
    assert np.allclose(t[:3], [4 - r, 3, 2])
    assert np.allclose(n[:3], [p, -e, e])
    # slanted ray hits the side: point at radius r, normal radial
    P = O[3] + t[3] * D[3]
    q = P - base - np.dot(P - base, e) * e
    assert abs(np.linalg.norm(q) - r) < 1e-9 and np.allclose(n[3], q / r)
    assert 0 < np.dot(P - base, e) < hgt
    # slanted ray from below through the bottom cap
    P = O[4] + t[4] * D[4]
    assert abs(np.dot(P - base, e)) < 1e-12 and np.allclose(n[4], -e)
    assert np.all(idx == 0)
    assert list(contains(s.objects[0], [mid, mid + 0.59 * p, mid + 0.61 * p, base - 0.01 * e])) == \
        [True, True, False, False]


@pytest.mark.parametrize("axis", ["y", "x"])
def test_vessel_inner_and_outer(axis):
    a = "xyz".index(axis)
    e = np.eye(3)[a]
    p = np.eye(3)[(a + 2) % 3]
    base = np.array([0.0, 0.0, 0.0]) + 0.25 * p
    r, w, hgt = 1.0, 0.06, 2.4
    s = one({"type": "cylinder", "axis": axis, "base": base.tolist(), "radius": r, "height": hgt,
             "wall": w})
    O, D = rays([base + 1.0 * e + 5 * p,       # from outside, horizontal: outer wall
                 base + 1.0 * e + 0.97 * p,    # inside the wall, inward: inner wall
                 base + 1.0 * e,               # in the hole (on the axis), outward: inner wall
                 base + 5 * e + 0.2 * p,       # from above into the opening: inner bottom
                 base + 5 * e + 0.97 * p,      # from above onto the rim
                 base - 2 * e + 0.5 * p,       # from below: outer bottom
                 base + 0.03 * e + 0.5 * p],   # inside the bottom, going up: inner bottom from below
                [-p, -p, p, -e, -e, e, e])
    t, idx, n = first_hit(s, O, D)
    assert np.allclose(t, [5 - r, 0.97 - (r - w), r - w, 5 - w, 5 - hgt, 2, w - 0.03])
    # outward normals of the solid: the inner surfaces face into the hole
    assert np.allclose(n, [p, -p, -p, e, e, -e, e])
    inside = [base + 0.5 * e + 0.97 * p, base + 0.03 * e, base + 0.5 * e, base + 2.39 * e + 0.97 * p,
              base + 2.41 * e + 0.97 * p, base + 0.5 * e + 1.01 * p]
    assert list(contains(s.objects[0], inside)) == [True, True, False, True, False, False]


# --------------------------------------------------------------------------- media and the default scene


def test_medium_at_default_scene():
    s = load_scene("default")
    names = [o.name for o in s.objects]
    glass, water = names.index("glass"), names.index("water")
    pts = {
        (0.5, 0.5, 0.0): water,      # in the water
        (-0.3, 1.0, 0.4): water,
        (0.0, 0.5, 0.0): water,      # inside the (opaque) rod, which is no medium
        (0.97, 1.0, 0.0): glass,     # in the glass wall
        (0.942, 0.5, 0.0): glass,    # where water and wall overlap, the glass (first) owns it
        (0.3, 0.03, 0.2): glass,     # glass bottom
        (0.0, 2.0, 0.5): -1,         # inside the glass, above the water: air
        (2.0, 1.0, 2.0): -1,         # outside
        (2.0, -1.0, 2.0): -1,        # below the floor (opaque: not a medium)
    }
    got = medium_at(s, list(pts))
    assert list(got) == list(pts.values())


def _nested_scene(floor_emission=(1.0, 1.0, 1.0), glass_em=(0, 0, 0), water_em=(0, 0, 0), ior=1.0,
                  max_depth=8):
    mats = {
        "floor": dict(EMISSIVE_BLACK, emission=list(floor_emission)),
        "glass": dict(CLEAR, ior=ior, emission=list(glass_em)),
        "water": dict(CLEAR, ior=ior, emission=list(water_em)),
    }
    objs = [{"type": "plane", "material": "floor"},
            {"type": "cylinder", "base": [0, 0, 0], "radius": 1.0, "height": 2.4, "wall": 0.06,
             "material": "glass"},
            {"type": "cylinder", "base": [0, 0.06, 0], "radius": 0.945, "height": 1.3, "material": "water"}]
    return make_scene(objs, mats, render={"max_depth": max_depth, "min_weight": 0.0})


def test_interactions_count_only_where_media_differ():
    # Horizontal ray through glass and water at ior 1: air|glass, glass|water (the
    # water's side inside the wall is no interaction), water|glass, glass|air:
    # 4 interactions, so the sky behind needs max_depth 5.
    for depth, want in [(4, 0.0), (5, 1.0)]:
        s = _nested_scene(max_depth=depth)
        L = trace(s, *rays([-5, 0.5, 0.3], [1, 0, 0]))[0]
        assert np.allclose(L, want, atol=1e-12), (depth, L)


def test_coincident_surfaces_are_one_interaction():
    # Straight down from above the liquid: air|water at the top (S = water), then the
    # liquid's bottom on the glass's inner bottom: ONE water|glass interaction whose
    # material is the glass (first in objects), then the floor, which wins over the
    # glass's outer bottom lying on it.  Three levels in all.
    ge, we, fe = np.array([0.1, 0, 0]), np.array([0, 0.01, 0]), np.array([0, 0, 1.0])
    for depth, want in [(2, ge + we), (3, ge + we + fe)]:
        s = _nested_scene(floor_emission=fe, glass_em=ge, water_em=we, max_depth=depth)
        L = trace(s, *rays([0.5, 2.0, 0.0], [0, -1, 0]))[0]
        assert np.allclose(L, want, atol=1e-12), (depth, L)


def test_flat_interface_split():
    # A ray at 45 deg onto a half-space of ior 1.5 under a gradient sky:
    # R * sky(mirror) + (1 - R) * T * sky(refracted; below the horizon: horizon).
    hor, zen = np.array([0.8, 0.85, 0.9]), np.array([0.25, 0.4, 0.75])
    for T in (1.0, 0.5):
        s = make_scene([{"type": "plane", "height": 0.0, "material": "g"}],
                       {"g": dict(CLEAR, ior=1.5, transparency=T)},
                       sky={"type": "gradient", "horizon": hor.tolist(), "zenith": zen.tolist()},
                       render={"max_depth": 2})
        L = trace(s, *rays([-1, 1, 0], [1, -1, 0]))[0]
        up = math.sqrt(0.5)
        want = 0.050240 * (hor * (1 - up) + zen * up) + (1 - 0.050240) * T * hor
        assert np.allclose(L, want, atol=2e-6)
    # max_depth 1: only the (black) local shading of the first interaction
    s.render.max_depth = 1
    assert np.allclose(trace(s, *rays([-1, 1, 0], [1, -1, 0])), 0.0)


def test_mirror_and_depth():
    s = make_scene([{"type": "plane", "material": "mirror"}],
                   {"mirror": dict(EMISSIVE_BLACK, reflectivity=0.75, emission=[0.1, 0.2, 0.3])},
                   sky={"type": "color", "color": [0.4, 0.5, 0.6]}, render={"max_depth": 1})
    O, D = rays([0, 1, 0], [0.3, -1, 0.2])
    assert np.allclose(trace(s, O, D)[0], [0.1, 0.2, 0.3])
    s.render.max_depth = 2
    assert np.allclose(trace(s, O, D)[0], [0.1 + 0.3, 0.2 + 0.375, 0.3 + 0.45])
    s.render.min_weight = 0.8  # the 0.75 branch is cut
    assert np.allclose(trace(s, O, D)[0], [0.1, 0.2, 0.3])


def test_phong_and_shadows_through_media():
    # Floor point under a light straight above; between them a box of a dielectric
    # (ior 1.3: no refraction on shadow rays) with transparency 0.5 and absorption:
    # V = 0.5 * 0.5 * exp(-a * 1.2).  Diffuse k_d (n.l) = 0.7, specular at r = v.
    mats = {"floor": {"color": [1.0, 0.5, 0.25], "ambient": 0.5, "diffuse": 0.7, "specular": 0.2,
                      "shininess": 10},
            "tinted": dict(CLEAR, transparency=0.5, ior=1.3, absorption=[0.5, 0.25, 0.0]),
            "black": dict(EMISSIVE_BLACK)}
    light = {"type": "point", "position": [0, 4, 0], "color": [1.0, 0.8, 0.6], "intensity": 2.0}
    box = {"type": "box", "min": [-1, 1, -1], "max": [1, 2.2, 1], "material": "tinted"}
    s = make_scene([{"type": "plane", "material": "floor"}, box], mats, lights=[light],
                   ambient=[0.1, 0.2, 0.3])
    C = np.array([1.0, 0.5, 0.25])
    Lj = np.array([2.0, 1.6, 1.2])
    V = 0.25 * np.exp(-np.array([0.5, 0.25, 0.0]) * 1.2)
    want = C * (0.5 * np.array([0.1, 0.2, 0.3]) + Lj * V * (0.7 + 0.2))
    assert np.allclose(trace(s, *rays([0, 0.5, 0], [0, -1, 0]))[0], want, atol=1e-12)
    # an opaque blocker anywhere on the way: ambient only
    s2 = make_scene([{"type": "plane", "material": "floor"}, box,
                     {"type": "sphere", "center": [0, 3, 0], "radius": 0.2, "material": "black"}],
                    mats, lights=[light], ambient=[0.1, 0.2, 0.3])
    assert np.allclose(trace(s2, *rays([0, 0.5, 0], [0, -1, 0]))[0], C * 0.5 * np.array([0.1, 0.2, 0.3]))
    # directional light from straight above: the same factor
    s3 = make_scene([{"type": "plane", "material": "floor"}, box], mats, ambient=[0.1, 0.2, 0.3],
                    lights=[{"type": "directional", "direction": [0, -3, 0], "color": [1.0, 0.8, 0.6],
                             "intensity": 2.0}])
    assert np.allclose(trace(s3, *rays([0, 0.5, 0], [0, -1, 0]))[0], want, atol=1e-12)


def test_phong_off_peak():
    # the specular lobe max(0, r.v)^p away from the mirror direction, and 0 behind it
    mats = {"floor": {"color": [1.0, 0.5, 0.25], "ambient": 0, "diffuse": 0.3, "specular": 0.6,
                      "shininess": 10}}
    C = np.array([1.0, 0.5, 0.25])
    for light, view, nl, rv in [([-2, 1, 0], [1, 1, 0], 1 / math.sqrt(5), 3 / math.sqrt(10)),
                                ([-4, 1, 0], [-1, 1, 0], 1 / math.sqrt(17), 0.0)]:
        s = make_scene([{"type": "plane", "material": "floor"}], mats,
                       lights=[{"type": "point", "position": light}])
        L = trace(s, *rays(view, -np.array(view, dtype=float)))[0]
        assert np.allclose(L, C * (0.3 * nl + 0.6 * rv ** 10), atol=1e-12)


def test_checker_parity_and_emission():
    mats = {"f": {"color": [0, 0, 0], "ambient": 0, "diffuse": 0, "emission": [0.9, 0.9, 0.9],
                  "checker": {"color": [0, 0, 0], "size": 0.5}},
            "g": {"color": [0, 0, 0], "ambient": 0, "diffuse": 0, "emission": [0.9, 0.9, 0.9],
                  "checker": {"color": [0, 0, 0], "size": 0.5, "emission": [0.1, 0.2, 0.3]}}}
    pts = np.array([[0.1, 0.1], [0.6, 0.1], [-0.1, 0.1], [-0.1, -0.1], [-0.6, -0.1], [1.2, -0.7]])
    odd = np.array([False, True, True, False, True, False])  # floor(x/.5)+floor(z/.5) odd
    O = np.stack([pts[:, 0], np.ones(len(pts)), pts[:, 1]], axis=1)
    D = np.tile([0, -1, 0], (len(pts), 1))
    L = trace(make_scene([{"type": "plane", "material": "f"}], mats), O, D)
    assert np.allclose(L[:, 0], np.where(odd, 0.9, 0.9))  # emission defaults to the material's
    L = trace(make_scene([{"type": "plane", "material": "g"}], mats), O, D)
    assert np.allclose(L, np.where(odd[:, None], [0.1, 0.2, 0.3], 0.9))


# --------------------------------------------------------------------------- whole images


def test_camera_rays_follow_the_pinhole_formula():
    s = make_scene([], {}, camera={"position": [1, 2, 3], "target": [0, 1, -1], "fov": 50})
    W, H = 9, 5
    O, D = camera_rays(s, W, H)
    f = np.array([-1.0, -1.0, -4.0]) / math.sqrt(18)
    assert D.shape == (H, W, 3) and np.allclose(O, [1, 2, 3])
    assert np.allclose(np.linalg.norm(D, axis=2), 1)
    assert np.allclose(D[2, 4], f)                       # centre pixel of an odd image
    _, Dt = camera_rays(s, W, H, offset=(0.5, 0.0))     # top edge of the middle column
    assert abs(angle_deg(Dt[0, 4][None], f[None])[0] - 25.0) < 1e-9
    assert Dt[0, 4, 1] > f[1]                            # row 0 is the top
    _, Dl = camera_rays(s, W, H, offset=(0.0, 0.5))     # left edge of the middle row
    half_h = math.degrees(math.atan(math.tan(math.radians(25)) * W / H))
    assert abs(angle_deg(Dl[2, 0][None], f[None])[0] - half_h) < 1e-9
    right = np.cross(f, [0, 1, 0])
    assert np.dot(Dl[2, 0], right) < 0                   # column 0 is the left


def _vanish_materials(ior, absorption):
    return dict(color=[1, 1, 1], ambient=0, diffuse=0, specular=0, transparency=1, ior=ior,
                absorption=absorption)


def test_clear_media_of_ior_one_vanish():
    base = load_scene("default")
    base.render.max_depth = 32
    base.render.min_weight = 0.0
    s = copy.deepcopy(base)
    for name in ("glass", "water"):
        s.materials[name] = type(s.materials[name])(**_vanish_materials(1.0, (0.0, 0.0, 0.0)))
    without = copy.deepcopy(base)
    without.objects = [o for o in base.objects if o.name not in ("glass", "water")]
    a = render_reference(s, 64, 36, samples=1)
    b = render_reference(without, 64, 36, samples=1)
    assert np.max(np.abs(a - b)) < 1e-9
    # and they do not vanish with the real materials (the test can fail)
    real = load_scene("default")
    real.render.max_depth = 32
    c = render_reference(real, 64, 36, samples=1)
    assert np.max(np.abs(c - b)) > 0.1


def test_furnace_clear_sphere_shows_only_the_sky():
    sky = [0.5, 0.6, 0.8]
    s = make_scene([{"type": "sphere", "center": [0, 0, 0], "radius": 1.0, "material": "g"}],
                   {"g": dict(CLEAR, color=[0, 0, 0], ior=1.5)},
                   sky={"type": "color", "color": sky}, lights=[{"type": "point", "position": [3, 3, 3]}],
                   camera={"position": [0, 0.5, 3.0], "target": [0, 0, 0], "fov": 45},
                   render={"max_depth": 64, "min_weight": 1e-9})
    W, H = 40, 30
    O, D = camera_rays(s, W, H)
    _, idx, _ = first_hit(s, O.reshape(-1, 3), D.reshape(-1, 3))
    assert (idx == 0).mean() > 0.3  # the sphere fills much of the view
    img = render_reference(s, W, H, samples=1)
    err = np.abs(img - np.array(sky)).max(axis=2)
    # only cut branches are missing: each of weight < 1e-9 (depth 64 is never reached
    # at these angles: R^63 < 1e-9)
    assert err.max() < 1e-7
    assert np.median(err) < 1e-8
    # with a little absorption (or a (n1/n2)^2 factor) it would show
    s.materials["g"].absorption = (0.05, 0.05, 0.05)
    assert np.abs(render_reference(s, W, H, samples=1) - np.array(sky)).max() > 0.02


@pytest.mark.parametrize("along", ["x", "z"])
def test_ball_lens_flips_the_checker(along):
    # Looking (almost) straight down at a checker edge, through a glass ball that fills
    # the view: the ball lens inverts the image, so the two sides swap.
    target = np.array([0.0, 0.0, 1.0]) if along == "x" else np.array([1.0, 0.0, 0.0])
    pos = target + [0.0, 10.0, 0.1]
    mats = {"floor": dict(EMISSIVE_BLACK, emission=[1, 1, 1], checker={"color": [0, 0, 0], "size": 2.0,
                                                                      "emission": [0, 0, 0]}),
            "glass": dict(CLEAR, ior=1.5)}
    cam = {"position": pos.tolist(), "target": target.tolist(), "fov": 8}
    floor = {"type": "plane", "material": "floor"}
    ball = {"type": "sphere", "center": (target + 0.6 * (pos - target)).tolist(), "radius": 1.0,
            "material": "glass"}
    kw = dict(sky={"type": "color", "color": [0, 0, 0]}, camera=cam, render={"max_depth": 10})
    W = H = 24
    plain = render_reference(make_scene([floor], mats, **kw), W, H, samples=1)[..., 0]
    lens = render_reference(make_scene([floor, ball], mats, **kw), W, H, samples=1)[..., 0]
    if along == "x":  # image right is +x: x < 0 (odd squares, dark) on the left
        a, b = plain[:, : W // 3].mean(), plain[:, -W // 3:].mean()
        la, lb = lens[:, : W // 3].mean(), lens[:, -W // 3:].mean()
    else:  # image up is -z: z < 0 (odd, dark) at the top rows
        a, b = plain[: H // 3].mean(), plain[-H // 3:].mean()
        la, lb = lens[: H // 3].mean(), lens[-H // 3:].mean()
    assert a == 0.0 and b == 1.0
    # through the lens: near-normal incidence twice, (1 - 0.04)^2 of the bright side
    assert lb < 0.01 and abs(la - 0.96 ** 2) < 0.01


def test_mirror_symmetric_scene_gives_a_symmetric_image():
    mats = {"floor": {"color": [0.8, 0.8, 0.8]}, "glass": dict(CLEAR, ior=1.5, specular=0.5),
            "water": dict(CLEAR, ior=1.33, absorption=[0.3, 0.1, 0.05]),
            "red": {"color": [0.8, 0.2, 0.1], "specular": 0.3}, "ball": {"reflectivity": 0.5}}
    objs = [{"type": "plane", "material": "floor"},
            {"type": "cylinder", "base": [0, 0, 0], "radius": 0.6, "height": 1.2, "wall": 0.05,
             "material": "glass"},
            {"type": "cylinder", "base": [0, 0.05, 0], "radius": 0.56, "height": 0.7, "material": "water"},
            {"type": "box", "min": [0.9, 0, -0.2], "max": [1.2, 1.0, 0.1], "rotate": [10, 0, 20],
             "material": "red"},
            {"type": "box", "min": [-1.2, 0, -0.2], "max": [-0.9, 1.0, 0.1], "rotate": [10, 0, -20],
             "material": "red"},
            {"type": "sphere", "center": [0, 0.4, -1.5], "radius": 0.4, "material": "ball"},
            {"type": "cylinder", "axis": "x", "base": [-1.0, 0.2, 0.9], "radius": 0.2, "height": 2.0,
             "material": "glass"}]
    s = make_scene(objs, mats, lights=[{"type": "point", "position": [0, 4, 2]}],
                   sky={"type": "gradient"}, ambient=[0.05, 0.05, 0.05],
                   camera={"position": [0, 1.6, 4.0], "target": [0, 0.5, 0], "fov": 45},
                   render={"max_depth": 8})
    img = render_reference(s, 48, 32, samples=1)
    assert np.max(np.abs(img - img[:, ::-1])) < 1e-9
    assert np.max(np.abs(img[:, 1:] - img[:, :-1])) > 0.1  # not trivially uniform


def test_samples_average_and_exposure():
    s = load_scene("glass-sphere")
    s.render.exposure = 2.0
    W, H = 12, 8
    img = render_reference(s, W, H, samples=3, seed=5)
    from viewer.base.sampling import sample_offsets
    acc = np.zeros((H, W, 3))
    for u, v in sample_offsets(3, 5):
        O, D = camera_rays(s, W, H, (u, v))
        acc += trace(s, O.reshape(-1, 3), D.reshape(-1, 3)).reshape(H, W, 3)
    assert np.allclose(img, 2.0 * acc / 3, atol=1e-12)
    assert render_reference(s, W, H, samples=2).shape == (H, W, 3)


# --------------------------------------------------------------------------- sky images


def _srgb_to_linear(c):
    c = np.asarray(c, dtype=float) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _dir_for(u, v):
    """Unit direction with the spec's u = 0.5 + atan2(x, -z) / 2pi, v = acos(y) / pi."""
    phi = 2 * math.pi * (u - 0.5)
    th = math.pi * v
    return [math.sin(th) * math.sin(phi), math.cos(th), -math.sin(th) * math.cos(phi)]


def test_sky_image_png_bilinear_wrap(tmp_path):
    from PIL import Image

    rng = np.random.default_rng(3)
    px = rng.integers(0, 256, (4, 8, 3)).astype(np.uint8)
    Image.fromarray(px).save(tmp_path / "sky.png")
    s = make_scene([], {}, sky={"type": "image", "image": "sky.png"}, base_dir=tmp_path)
    lin = _srgb_to_linear(px)
    cases = [((2 + 0.5) / 8, (1 + 0.5) / 4, lin[1, 2]),                         # a texel centre
             (0.5, 0.5, lin[1:3, 3:5].mean(axis=(0, 1))),                      # -z: between 4 texels
             (0.25 / 8, (2 + 0.5) / 4, 0.25 * lin[2, 7] + 0.75 * lin[2, 0]),   # wraps in u
             (7.75 / 8, (2 + 0.5) / 4, 0.75 * lin[2, 7] + 0.25 * lin[2, 0]),   # wraps in u
             ((3 + 0.5) / 8, 0.0001 / 4, lin[0, 3])]                           # zenith row (clamped)
    for u, v, want in cases:
        got = trace(s, np.zeros((1, 3)), np.array([_dir_for(u, v)]))[0]
        assert np.allclose(got, want, atol=1e-9), (u, v)


def test_sky_image_pfm_rows_bottom_to_top(tmp_path):
    w, h = 4, 2
    top, bottom = [1.5, 2.0, 3.0], [0.25, 0.5, 0.75]
    rows = [bottom] * w + [top] * w  # PFM stores the bottom row first
    data = b"PF\n%d %d\n-1.0\n" % (w, h) + struct.pack("<%df" % (3 * w * h), *np.ravel(rows))
    (tmp_path / "sky.pfm").write_bytes(data)
    s = make_scene([], {}, sky={"type": "image", "image": "sky.pfm"}, base_dir=tmp_path)
    L = trace(s, np.zeros((2, 3)), np.array([[0, 1.0, 0], [0, -1.0, 0]]))
    assert np.allclose(L, [top, bottom])


# --------------------------------------------------------------------------- cost


def test_deep_trees_terminate():
    # a single clear sphere: the tree stays linear even with min_weight 0 and depth 64
    s = load_scene("whitted-exact")
    s.render.max_depth = 64
    s.render.min_weight = 0.0
    t0 = time.perf_counter()
    img = render_reference(s, 24, 16, samples=1)
    assert np.all(np.isfinite(img))
    # nested media at depth 64: the weight cut prunes
    d = load_scene("default")
    d.render.max_depth = 64
    img = render_reference(d, 40, 24, samples=1)
    assert np.all(np.isfinite(img)) and img.min() >= 0
    assert time.perf_counter() - t0 < 20
