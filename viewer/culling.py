"""Screen-tile culling: for each tile of the image, the objects that a ray
starting in it can possibly meet, so that the tile is drawn with a shader
compiled for those objects only.

On a software rasteriser every line of a fragment shader runs for every
pixel (SIMD lanes follow a mask; a branch skips nothing), so a floor pixel
in a scene with a glass pays for all of the glass's code.  A shader
compiled without the objects that a tile cannot see, nor shadow, is exact
there and costs what its own objects cost.  (On a GPU the same holds in
part: fewer registers, more threads in flight.)

The tests are conservative, in float64 on bounding spheres padded by
PAD_REL of the scene's size:

* camera rays: a bounded object can be met by a ray of the tile only when
  its bounding sphere reaches into the tile's pyramid of rays (the four
  side planes through the eye); a plane y = h when some ray of the pyramid
  points toward it;
* secondary rays: when an object the tile may see is reflective or
  transparent, rays go anywhere: the tile gets every object;
* shadow rays: start on what the camera rays may meet and go to each light
  (with a non-zero colour): within the bounding sphere of a seen object or
  of the tile's footprint on a plane (the quad of its corner rays; a tile
  that reaches the horizon gets every object), so they stay inside the
  capsule from that sphere to the light (for a directional light, the
  half-infinite one against its direction); an object whose bounding sphere
  meets a capsule may shadow the tile.

An object whose solid holds the eye is always kept (it is the medium every
camera ray starts in).  Subsets are merged so that at most MAX_VARIANTS
shaders serve one image: the smallest groups of tiles join the group whose
subset grows least, up to the whole scene.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .gpu_scene import bounding_sphere, camera_uniforms, contains_point, scene_scale
from .scene import Scene, unit_vector

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


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray | None, direction: np.ndarray | None) -> np.ndarray:
    """Distance from points p (..., 3) to the segment a-b, or to the ray from
    a along `direction` when b is None."""
    if b is None:
        ab = direction
        t = np.maximum(np.sum((p - a) * ab, axis=-1) / np.dot(ab, ab), 0.0)
    else:
        ab = b - a
        denom = max(float(np.dot(ab, ab)), 1e-300)
        t = np.clip(np.sum((p - a) * ab, axis=-1) / denom, 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def tile_subsets(scene: Scene, width: int, height: int, tile: int = TILE) -> tuple[np.ndarray, list[tuple[int, ...]]]:
    """(labels (tiles_y, tiles_x) int, top row first; subsets): the object
    indices each tile needs, as an index into ``subsets``."""
    objs = scene.objects
    n = len(objs)
    everything = tuple(range(n))
    tx, ty = -(-width // tile), -(-height // tile)
    if n == 0:
        return np.zeros((ty, tx), np.int32), [()]
    eye = np.array(scene.camera.position, dtype=np.float64)
    pad = PAD_REL * scene_scale(scene)
    # bounding spheres, world frame (bounding_sphere gives them eye-relative)
    spheres = np.array([bounding_sphere(o, eye) for o in objs], dtype=np.float64)
    centres = spheres[:, :3] + eye
    radii = np.where(spheres[:, 3] >= 0, spheres[:, 3] + pad, -1.0)
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

    labels = np.zeros((ty, tx), np.int32)
    subsets: list[tuple[int, ...]] = []
    index: dict[tuple[int, ...], int] = {}
    rel = centres - eye                              # (n, 3)
    # signed distances of every sphere centre to every side plane: (ty, tx, 4, n)
    side = np.einsum("yxcd,nd->yxcn", normals, rel)
    in_pyramid = np.all(side > -radii[None, None, None, :], axis=2) & (radii > 0)   # (ty, tx, n)
    for j in range(ty):
        for i in range(tx):
            seen = set(np.flatnonzero(in_pyramid[j, i]).tolist())
            footprints = []                          # (centre, radius) of plane footprints
            unbounded = False
            for k in planes:
                h = objs[k].height
                dy = quad[j, i, :, 1]
                toward = dy < 0 if eye[1] > h else (dy > 0 if eye[1] < h else np.ones(4, bool))
                if not toward.any():
                    continue
                seen.add(k)
                if eye[1] == h or not toward.all():
                    unbounded = True
                    continue
                t = (h - eye[1]) / dy
                pts = eye + t[:, None] * quad[j, i]
                c = pts.mean(axis=0)
                footprints.append((c, float(np.max(np.linalg.norm(pts - c, axis=1))) + pad))
            seen.update(holds_eye)
            if unbounded or any(scatters[k] for k in seen):
                key = everything
            else:
                need = set(seen)
                if lights:
                    regions = footprints + [(centres[k], radii[k]) for k in seen if radii[k] > 0]
                    bounded = radii > 0
                    for c, rad in regions:
                        for lt in lights:
                            if lt.type == "directional":
                                dist = _segment_distance(centres, c, None, -np.array(unit_vector(lt.direction)))
                            else:
                                dist = _segment_distance(centres, c, np.array(lt.position, float), None)
                            hit = bounded & (dist < radii + rad)
                            need.update(np.flatnonzero(hit).tolist())
                    # planes are unbounded: any of them may cut a shadow ray
                    need.update(planes)
                key = tuple(sorted(need))
            if key not in index:
                index[key] = len(subsets)
                subsets.append(key)
            labels[j, i] = index[key]
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
