"""Screen-tile culling: for each tile of the image, the objects that a ray
starting in it can possibly meet, so that the tile is drawn with a shader
compiled for those objects only.

On a software rasteriser every line of a fragment shader runs for every
pixel (SIMD lanes follow a mask; a branch skips nothing), so a floor pixel
in a scene with a glass pays for all of the glass's code.  A shader
compiled without the objects that a tile cannot see, nor shadow, is exact
there and costs what its own objects cost.  (On a GPU the same holds in
part: fewer registers, more threads in flight.)

The tests are conservative, in float64 on bounds padded by PAD_REL of the
scene's size:

* camera rays: a bounded object can be met by a ray of the tile only when
  its bounding sphere and the object itself (its exact support function:
  sphere, rotated box, cylinder) reach past each of the tile's four side
  planes through the eye; a plane y = h when some ray of the pyramid points
  toward it;
* secondary rays: when an object the tile may see is reflective or
  transparent, rays go anywhere: the tile gets every object;
* shadow rays: start on what the camera rays may meet and go to each light
  (with a non-zero colour).  From a seen object they stay inside the
  capsule from its bounding sphere to the light (for a directional light,
  the half-infinite one against its direction); an object whose bounding
  sphere meets that capsule may shadow the tile.  From a plane they start
  in the tile's footprint on it, and an object shadows only the points of
  the plane in its shadow region: a bounded ellipse when the light is above
  the object (shadow_disc bounds it by a disc), which the tile's pyramid
  must reach, and the capsule of the footprint's bounding sphere must meet
  the object too when the footprint is bounded.  So a tile that reaches
  the horizon (an unbounded footprint) keeps only the objects whose shadows
  it can see.

An object whose solid holds the eye is always kept (it is the medium every
camera ray starts in).  Subsets are merged so that at most MAX_VARIANTS
shaders serve one image: the smallest groups of tiles join the group whose
subset grows least, up to the whole scene.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .block import camera_uniforms
from .geometry import AXES, bounding_sphere, contains_point, rotation_world_from_local, scene_scale
from ..scene.model import Scene
from ..scene.load import unit_vector

#: Tile side in pixels.
TILE = 32
#: Most shader variants one image is drawn with (each costs a compile the
#: first time it is needed; Mesa caches them on disk).
MAX_VARIANTS = 4
#: Padding of every bounding sphere, relative to the scene's size (float32
#: rounding in the shader never brings a hit outside it).
PAD_REL = 1e-3


@dataclass(frozen=True)
class CullPlan:
    """Which objects each group of tiles needs: ``groups`` pairs a subset
    (sorted object indices) with its scissor rectangles (x, y, w, h) in
    framebuffer pixels, y up from the bottom row."""
    groups: tuple[tuple[tuple[int, ...], tuple[tuple[int, int, int, int], ...]], ...]


#: Culling works in float64 with squared lengths: a scene with a coordinate
#: or size beyond this (valid, but not drawn faithfully in float32) is not culled.
CULL_LIMIT = 1e150


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray | None, direction: np.ndarray | None) -> np.ndarray:
    """Distance from points p (n, 3) to the segment a-b, or to the ray from
    a along `direction` when b is None; a (and b) may be (..., 3) stacks of
    segments: the result is (..., n)."""
    a = np.asarray(a, dtype=np.float64)[..., None, :]                   # (..., 1, 3)
    if b is None:
        ab = np.asarray(direction, dtype=np.float64)
        t = np.maximum(np.sum((p - a) * ab, axis=-1) / np.dot(ab, ab), 0.0)
    else:
        ab = np.asarray(b, dtype=np.float64)[..., None, :] - a
        denom = np.maximum(np.sum(ab * ab, axis=-1), 1e-300)
        t = np.clip(np.sum((p - a) * ab, axis=-1) / denom, 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def _capsule_meets(centres: np.ndarray, radii: np.ndarray, c: np.ndarray, rad, light) -> np.ndarray:
    """Which spheres (centres (n, 3), radii (n,)) meet the capsule swept by a
    sphere (c (..., 3), rad (...)) toward `light` (to its position, or
    half-infinite against a directional light's direction): (..., n)."""
    if light.type == "directional":
        dist = _segment_distance(centres, c, None, -np.array(unit_vector(light.direction)))
    else:
        dist = _segment_distance(centres, c, np.array(light.position, dtype=np.float64), None)
    return dist < radii + np.asarray(rad, dtype=np.float64)[..., None]


def support(obj, n: np.ndarray) -> np.ndarray:
    """max over the object's points p of n . p, for directions n (..., 3)
    (+inf for a plane): the exact support function of a sphere, a (rotated)
    box and a cylinder (the hull of its two end discs: n . c + r |n x a| at
    each end; a wall changes nothing outside).  An object lies outside the
    half-space n . p >= d exactly when support(n) < d: a tile's pyramid
    cannot meet it when that holds for one of its side planes."""
    n = np.asarray(n, dtype=np.float64)
    if obj.type == "plane":
        return np.full(n.shape[:-1], np.inf)
    if obj.type == "sphere":
        return n @ np.array(obj.center, float) + obj.radius * np.linalg.norm(n, axis=-1)
    if obj.type == "box":
        lo, hi = np.array(obj.min, float), np.array(obj.max, float)
        rot = rotation_world_from_local(obj.rotate)        # columns: the box's axes
        # halves first: a valid box may span more than float64's 1.8e308
        return n @ (lo / 2 + hi / 2) + np.abs(n @ rot) @ (hi / 2 - lo / 2)
    axis = np.zeros(3)
    axis[AXES[obj.axis]] = 1.0
    base = np.array(obj.base, float)
    across = obj.radius * np.linalg.norm(np.cross(n, axis), axis=-1)
    return np.maximum(n @ base, n @ (base + obj.height * axis)) + across


def shadow_disc(centre: np.ndarray, radius: float, light, height: float, eye_y: float):
    """A disc on the plane y = height holding every point of it whose shadow
    ray toward `light` can meet the sphere (centre, radius): (disc centre
    (3,), disc radius), or None when that region is unbounded (or the light
    is not on the eye's side of the plane, where the plane is lit from
    behind and the question does not arise in the same form).

    Directional light (unit vector u toward it): the sphere projected along u
    onto the plane, an ellipse of semi-axes radius and radius / u_y around
    the centre's projection.  Point light at L, outside the sphere: the cone
    of rays from L that meet the sphere, angle a = asin(radius / |c - L|),
    its axis at angle t from straight down; the plane cuts it in an ellipse
    when t + a < 90 degrees (the gnomonic image of a circle on the sphere of
    directions): along the axis's azimuth it spans H tan(t - a) .. H tan(t + a)
    from the foot of L (H = L_y - height), across it the semi-axis is
    H sin a / sqrt(cos^2 t - sin^2 a)."""
    above = eye_y > height
    if light.type == "directional":
        u = -np.array(unit_vector(light.direction), dtype=np.float64)
        uy = u[1] if above else -u[1]
        if uy <= 1e-6:
            return None
        proj = centre - ((centre[1] - height) / u[1]) * u
        return proj, radius / uy
    L = np.array(light.position, dtype=np.float64)
    H = (L[1] - height) if above else (height - L[1])
    to_c = centre - L
    dist = float(np.linalg.norm(to_c))
    if H <= 0 or dist <= radius:
        return None
    a = math.asin(radius / dist)
    down = (-to_c[1] if above else to_c[1]) / dist
    t = math.acos(min(1.0, max(-1.0, down)))
    margin = math.radians(1e-3)
    if t + a >= math.pi / 2 - margin:
        return None
    near, far = H * math.tan(t - a), H * math.tan(t + a)
    minor = H * math.sin(a) / math.sqrt(math.cos(t) ** 2 - math.sin(a) ** 2)
    horiz = np.array([to_c[0], 0.0, to_c[2]])
    hn = float(np.linalg.norm(horiz))
    azimuth = horiz / hn if hn > 0 else np.array([1.0, 0.0, 0.0])
    foot = np.array([L[0], height, L[2]])
    return foot + azimuth * (near + far) / 2, max((far - near) / 2, minor)


def tile_subsets(scene: Scene, width: int, height: int, tile: int = TILE) -> tuple[np.ndarray, list[tuple[int, ...]]]:
    """(labels (tiles_y, tiles_x) int, top row first; subsets): the object
    indices each tile needs, as an index into ``subsets``."""
    objs = scene.objects
    n = len(objs)
    tx, ty = -(-width // tile), -(-height // tile)
    if n == 0:
        return np.zeros((ty, tx), np.int32), [()]
    eye = np.array(scene.camera.position, dtype=np.float64)
    pad = PAD_REL * scene_scale(scene)
    # bounding spheres, world frame (bounding_sphere gives them eye-relative)
    spheres = np.array([bounding_sphere(o, eye) for o in objs], dtype=np.float64)
    centres = spheres[:, :3] + eye
    radii = np.where(spheres[:, 3] >= 0, spheres[:, 3] + pad, -1.0)
    light_points = [lt.position for lt in scene.lights if lt.position is not None]
    if not np.all(np.abs([*centres.ravel(), *radii, *np.ravel(light_points), pad]) < CULL_LIMIT):
        # squares of such lengths overflow float64: every tile gets every
        # object (conservative; such a scene is not drawn faithfully anyway)
        return np.zeros((ty, tx), np.int32), [tuple(range(n))]
    planes = [k for k, o in enumerate(objs) if o.type == "plane"]
    scatters = np.array([scene.scatters(o) for o in objs])
    holds_eye = [k for k, o in enumerate(objs) if scene.is_transparent(o) and contains_point(o, eye)]
    lights = [lt for lt in scene.lights if lt.intensity > 0 and max(lt.color) > 0]

    cam = camera_uniforms(scene, width, height)
    f, r, u = (np.array(cam[k], dtype=np.float64) for k in ("camForward", "camRight", "camUp"))
    # corner directions of the pixel grid lines, half a pixel of margin
    xs = np.clip(np.arange(tx + 1) * tile, 0, width).astype(np.float64)
    ys = np.clip(np.arange(ty + 1) * tile, 0, height).astype(np.float64)
    xs[0] -= 0.5
    xs[-1] += 0.5
    ys[0] -= 0.5
    ys[-1] += 0.5
    X, Y = np.meshgrid(xs, ys)                      # (ty+1, tx+1)
    corner = (f + (2 * X / width - 1)[..., None] * r + (1 - 2 * Y / height)[..., None] * u)
    # the four corners of each tile, counter-clockwise seen from the eye
    c00, c10 = corner[:-1, :-1], corner[:-1, 1:]
    c11, c01 = corner[1:, 1:], corner[1:, :-1]
    quad = np.stack([c00, c10, c11, c01], axis=2)   # (ty, tx, 4, 3)
    centre_dir = quad.mean(axis=2)
    # side plane normals through the eye, pointing into the pyramid
    normals = np.cross(quad, np.roll(quad, -1, axis=2))
    flip = np.sum(normals * centre_dir[:, :, None, :], axis=-1) < 0
    normals = np.where(flip[..., None], -normals, normals)
    normals = _unit(normals)

    rel = centres - eye                              # (n, 3)
    # signed distances of every sphere centre to every side plane: (ty, tx, 4, n)
    side = np.einsum("yxcd,nd->yxcn", normals, rel)
    in_pyramid = np.all(side > -radii[None, None, None, :], axis=2) & (radii > 0)   # (ty, tx, n)
    # ... and the object itself reaches into it: its support along every
    # side normal passes the plane (exact per plane; the sphere test stays
    # as the cheap first cut)
    offset = normals @ eye                                              # (ty, tx, 4)
    for k, o in enumerate(objs):
        if o.type != "plane":
            in_pyramid[:, :, k] &= np.all(support(o, normals) - offset > -pad, axis=2)

    # Per plane and light, which tiles' pyramids reach each bounded object's
    # shadow disc on the plane (True also where the shadow is unbounded):
    # (ty, tx, n) masks; the discs do not depend on the tile.
    disc_reach = {}
    for k in planes:
        for li, lt in enumerate(lights):
            reach = np.zeros((ty, tx, n), bool)
            for m in np.flatnonzero(radii > 0):
                disc = shadow_disc(centres[m], radii[m], lt, objs[k].height, eye[1])
                if disc is None:
                    reach[:, :, m] = True
                else:
                    reach[:, :, m] = np.all(normals @ (disc[0] - eye) > -(disc[1] + pad), axis=2)
            disc_reach[k, li] = reach

    # What each tile needs, as (ty, tx, n) masks.
    bounded = radii > 0
    seen = in_pyramid.copy()
    seen[:, :, holds_eye] = True
    unbounded = np.zeros((ty, tx), bool)
    shadows = np.zeros((ty, tx, n), bool)        # may shadow what the tile sees
    for k in planes:
        h = objs[k].height
        dy = quad[..., 1]                                             # (ty, tx, 4)
        toward = dy < 0 if eye[1] > h else (dy > 0 if eye[1] < h else np.ones_like(dy, bool))
        hits = toward.any(axis=2)
        seen[:, :, k] |= hits
        if eye[1] == h:
            unbounded |= hits
            continue
        # the footprint's bounding sphere where all four corner rays meet the
        # plane; elsewhere (the tile reaches the horizon) it is unbounded
        closed = toward.all(axis=2)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(toward, (h - eye[1]) / np.where(toward, dy, 1.0), 0.0)
        pts = eye + t[..., None] * quad                               # (ty, tx, 4, 3)
        c = pts.mean(axis=2)
        rad = np.linalg.norm(pts - c[:, :, None, :], axis=3).max(axis=2) + pad
        for li, lt in enumerate(lights):
            # an object shadows a point of the plane only inside its shadow
            # region, which the tile's rays must reach; from a bounded
            # footprint, its capsule toward the light must meet the object too
            from_footprint = disc_reach[k, li] & (~closed[..., None] | _capsule_meets(centres, radii, c, rad, lt))
            shadows |= hits[..., None] & bounded & from_footprint
    for lt in lights:
        # from a seen object: what the capsule of its sphere toward the light meets
        between = _capsule_meets(centres, radii, centres, radii, lt) & bounded & bounded[:, None]   # (n, n)
        shadows |= (seen.astype(np.int32) @ between.astype(np.int32)) > 0
    need = seen | shadows
    if lights:
        need[:, :, planes] |= True           # planes are unbounded: any of them may cut a shadow ray
    need[unbounded | np.any(seen & scatters, axis=2)] = True
    # one subset per distinct mask, numbered in raster order of first use
    flat = need.reshape(-1, n)
    keys, first, inverse = np.unique(flat, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    labels = rank[inverse.ravel()].reshape(ty, tx).astype(np.int32)
    subsets = [tuple(np.flatnonzero(keys[g]).tolist()) for g in order]
    return labels, subsets


def merge_subsets(labels: np.ndarray, subsets: list[tuple[int, ...]],
                  max_variants: int = MAX_VARIANTS) -> tuple[np.ndarray, list[tuple[int, ...]]]:
    """At most max_variants subsets: repeatedly the group with the fewest
    tiles joins the group whose subset its own adds the fewest objects to
    (their union serves both, exactly)."""
    counts = np.bincount(labels.ravel(), minlength=len(subsets)).astype(np.int64)
    groups = {g: set(s) for g, s in enumerate(subsets) if counts[g] > 0}
    members = {g: [g] for g in groups}
    while len(groups) > max_variants:
        small = min(groups, key=lambda g: (counts[g], g))
        others = [g for g in groups if g != small]
        best = min(others, key=lambda g: (len(groups[g] | groups[small]) * (counts[g] + counts[small])
                                          - len(groups[g]) * counts[g], g))
        groups[best] |= groups.pop(small)
        counts[best] += counts[small]
        members[best] += members.pop(small)
    new_labels = np.zeros_like(labels)
    out: list[tuple[int, ...]] = []
    for new, g in enumerate(sorted(groups)):
        out.append(tuple(sorted(groups[g])))
        for old in members[g]:
            new_labels[labels == old] = new
    return new_labels, out


def rectangles(mask: np.ndarray, tile: int, width: int, height: int) -> list[tuple[int, int, int, int]]:
    """Scissor rectangles (x, y, w, h), y up from the bottom row, covering
    the tiles set in `mask` (tiles_y, tiles_x, top row first): runs along
    rows, merged with identical runs below them."""
    ty, tx = mask.shape
    out = []
    open_runs: dict[tuple[int, int], int] = {}          # run -> first row of its current block
    for j in range(ty + 1):
        row_runs = set()
        if j < ty:
            i = 0
            while i < tx:
                if mask[j, i]:
                    i0 = i
                    while i < tx and mask[j, i]:
                        i += 1
                    row_runs.add((i0, i))
                else:
                    i += 1
        for run in list(open_runs):
            if run not in row_runs:
                j0 = open_runs.pop(run)
                x0, x1 = run[0] * tile, min(run[1] * tile, width)
                top, bottom = j0 * tile, min(j * tile, height)   # rows from the top
                out.append((x0, height - bottom, x1 - x0, bottom - top))
        for run in row_runs:
            open_runs.setdefault(run, j)
    return out


def plan(scene: Scene, width: int, height: int, tile: int = TILE, max_variants: int = MAX_VARIANTS) -> CullPlan:
    labels, subsets = tile_subsets(scene, width, height, tile)
    labels, subsets = merge_subsets(labels, subsets, max_variants)
    groups = []
    for g, subset in enumerate(subsets):
        rects = rectangles(labels == g, tile, width, height)
        if rects:
            groups.append((subset, tuple(rects)))
    return CullPlan(tuple(groups))


def plan_key(scene: Scene, width: int, height: int) -> tuple:
    """What a plan depends on: size, camera, lights, and each object's
    geometry and whether it reflects or transmits."""
    c = scene.camera
    objs = tuple((o.type, o.height, o.center, o.radius, o.min, o.max, o.rotate, o.axis, o.base, o.wall,
                  scene.is_transparent(o), scene.scatters(o)) for o in scene.objects)
    lights = tuple((lt.type, lt.position, lt.direction, lt.intensity > 0 and max(lt.color) > 0)
                   for lt in scene.lights)
    return (width, height, tuple(c.position), tuple(c.target), c.fov, objs, lights)
