"""Debug views of a scene (``glassray render --view ...``): the first hit's
normal, distance and object, and the ray cost per pixel, as pictures with a
legend (PNG) or raw values (.npy / .pfm)."""

from __future__ import annotations

import colorsys

import numpy as np

VIEWS = ("normals", "depth", "objects", "cost", "samples")

# A perceptually ordered heat map (dark blue -> purple -> orange -> yellow),
# piecewise linear between these stops; display-space sRGB in 0..1.
_HEAT = np.array([[0.02, 0.02, 0.15], [0.30, 0.05, 0.50], [0.75, 0.20, 0.35], [0.98, 0.55, 0.10],
                  [0.99, 0.95, 0.55]])
_PALETTE = np.array([[0.90, 0.30, 0.25], [0.30, 0.65, 0.95], [0.95, 0.80, 0.25], [0.45, 0.80, 0.40],
                     [0.75, 0.45, 0.90], [0.95, 0.55, 0.20], [0.40, 0.85, 0.85], [0.85, 0.85, 0.85]])


def _object_palette(n: int = 256) -> np.ndarray:
    """(n, 3) display colours of the objects view: the 8 of _PALETTE first,
    then hues spaced by the golden angle at alternating saturation and
    value, so that no two of the 256 objects a scene may hold share a colour
    (a repeating palette drew objects 8, 16, ... in the floor's)."""
    cols = [tuple(c) for c in _PALETTE]
    for k in range(n - len(_PALETTE)):
        cols.append(colorsys.hsv_to_rgb((k * 0.6180339887498949) % 1.0, 0.55 if k % 2 == 0 else 0.85,
                                        0.95 if (k // 2) % 2 == 0 else 0.70))
    return np.array(cols)


_OBJECT_COLOURS = _object_palette()
#: The depth view's colour of a pixel where nothing is hit (display space).
DEPTH_SKY = 0.5


def heat(x: np.ndarray) -> np.ndarray:
    """x in [0, 1] -> (..., 3) display colours."""
    x = np.clip(np.asarray(x, np.float64), 0, 1) * (len(_HEAT) - 1)
    i = np.minimum(np.floor(x).astype(int), len(_HEAT) - 2)
    f = (x - i)[..., None]
    return _HEAT[i] * (1 - f) + _HEAT[i + 1] * f


def raw_view(renderer, view: str, width: int, height: int, samples_map: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 3) float32 raw values: normals xyz; depth t (inf: no hit);
    object index (-1: none); rays per pixel; samples per pixel of an
    adaptive render (`samples_map`, which the caller renders)."""
    if view == "samples":
        return np.repeat(np.asarray(samples_map, np.float32)[..., None], 3, axis=2)
    if view == "cost":
        v = renderer.ray_cost(width, height).astype(np.float32)
        return np.repeat(v[..., None], 3, axis=2)
    t, obj, normal = renderer.first_hits(width, height)
    if view == "normals":
        return normal.astype(np.float32)
    v = t if view == "depth" else obj.astype(np.float32)
    return np.repeat(v[..., None], 3, axis=2).astype(np.float32)


def _legend(width: int, lo: float, hi: float, unit: str, note: str | None = None) -> np.ndarray:
    """A colour bar with its end values, 16 rows high, display colours 0..1;
    with `note`, that text instead of the values (a depth view with nothing
    hit has no range to name)."""
    from PIL import Image, ImageDraw

    bar = np.repeat(heat(np.linspace(0, 1, width))[None], 16, axis=0)
    im = Image.fromarray(np.round(bar * 255).astype(np.uint8))
    draw = ImageDraw.Draw(im)
    if note is not None:
        draw.text((2, 2), note, fill=(255, 255, 255))
        return np.asarray(im, np.float64) / 255
    # four significant digits, not a fixed number of decimals: a scene in
    # micrometres has depths of 1e-6 (its legend read "0 ... 0.001")
    left, right = f"{lo:.4g} {unit}", f"{hi:.4g} {unit}"
    if draw.textlength(left) + draw.textlength(right) + 8 > width:
        left, right = f"{lo:.4g}", f"{hi:.4g}"       # a narrow image: the numbers only
    draw.text((2, 2), left, fill=(255, 255, 255))
    tw = draw.textlength(right)
    if draw.textlength(left) + tw + 8 <= width:
        draw.text((width - tw - 2, 2), right, fill=(0, 0, 0))
    return np.asarray(im, np.float64) / 255


def picture(view: str, raw: np.ndarray) -> np.ndarray:
    """Display-space (H', W, 3) picture in 0..1 of a raw view, with a legend
    strip below for depth, cost and samples."""
    v = raw[..., 0]
    if view == "normals":
        hit = np.any(raw != 0, axis=2, keepdims=True)
        return np.where(hit, 0.5 + 0.5 * raw, 0.0)
    if view == "objects":
        idx = v.round().astype(int)
        out = _OBJECT_COLOURS[np.clip(idx, 0, len(_OBJECT_COLOURS) - 1)]
        return np.where((idx >= 0)[..., None], out, 0.0)
    finite = np.isfinite(v)
    lo, hi = (float(v[finite].min()), float(v[finite].max())) if finite.any() else (0.0, 1.0)
    if view == "cost":
        lo = 0.0
    if view == "samples":
        # from 1 sample to the most any pixel took, on a log scale
        lo, hi = 1.0, max(hi, 2.0)
        norm = np.log2(np.maximum(v, 1.0)) / np.log2(hi)
    elif view == "depth" and lo > 0:
        # distances span orders of magnitude (a floor to the horizon): log scale
        norm = np.log(np.where(finite, v, lo) / lo) / max(np.log(hi / lo), 1e-12)
    else:
        norm = (v - lo) / max(hi - lo, 1e-12)
    # no hit (depth inf): black elsewhere, but the depth map's nearest colour
    # is nearly black, so there the sky is a neutral grey, off the heat map
    img = np.where(finite[..., None], heat(norm), DEPTH_SKY if view == "depth" else 0.0)
    unit = {"cost": "rays", "samples": "samples (log)"}.get(view, "(log)")
    note = "nothing hit" if view == "depth" and not finite.any() else None
    return np.concatenate([img, _legend(raw.shape[1], lo, hi, unit, note)], axis=0)
