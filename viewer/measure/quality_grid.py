"""The max-error measurement's plan: the candidate settings, the pick among
what was measured, and which pixels are measured (the layout of tiles).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Candidate samples per pixel.
SAMPLES = (1, 2, 4, 8, 16)
#: Candidate (max depth, min weight) pairs, cheapest first.
TRACE = ((2, 0.01), (4, 0.003), (6, 0.001), (10, 0.0001))
#: Pixels measured: a GRID x GRID mosaic of tiles of the real image, about
#: this many pixels in all (a smaller image is measured whole).
MEASURE_PIXELS = 160 * 90
GRID = 8
#: Images of at most this many pixels are timed at their own size, larger
#: ones scaled down to about this many; FULL_TIMED_PASSES timed passes.
FULL_TIMING_PIXELS = 1280 * 720


# ---------------------------------------------------------------- candidates and the pick


@dataclass(frozen=True)
class Candidate:
    samples: int
    max_depth: int
    min_weight: float

    def key(self) -> str:
        return f"s{self.samples}-d{self.max_depth}-w{self.min_weight:g}"

    def describe(self) -> str:
        return f"samples {self.samples}, max depth {self.max_depth}, min weight {self.min_weight:g}"


@dataclass(frozen=True)
class Measured:
    candidate: Candidate
    time_ms: float  # at the measuring size
    rmse: float
    frac_off: float = 0.0  # fraction of pixels more than 1/255 off (display space)
    #: the standard error of `rmse` as an estimate of the whole image's (0
    #: where the image is measured whole): see tile_standard_error
    rmse_se: float = 0.0

    @property
    def bound(self) -> float:
        """What the pick holds against the budget: rmse plus one standard error."""
        return self.rmse + self.rmse_se


def candidate_grid(samples: int | None = None, max_depth: int | None = None,
                   min_weight: float | None = None) -> list[Candidate]:
    """The candidates; a given value replaces that axis of the grid."""
    ss = (samples,) if samples is not None else SAMPLES
    out: list[Candidate] = []
    for d, w in TRACE:
        c_d = max_depth if max_depth is not None else d
        c_w = min_weight if min_weight is not None else w
        for s in ss:
            c = Candidate(int(s), int(c_d), float(c_w))
            if c not in out:
                out.append(c)
    return out


def pick(measured: list[Measured], max_error: float) -> tuple[Measured, bool]:
    """The fastest measurement with rmse + its standard error <= max_error
    (ties: the smaller error) and True; when none meets it, the most
    accurate one (ties: the faster) and False.  A larger budget never gives
    a slower pick.  (Against rmse alone, the default scene's pick for 0.02
    at 640x360, 2 samples measured at 0.0183 +- 0.0026, had 0.0225 over the
    whole image.)"""
    if not measured:
        raise ValueError("no measured candidates")
    if not any(math.isfinite(m.rmse) for m in measured):
        # no error could be measured (every measured pixel's tree was cut by
        # the driver's loop limit): the slowest setting traces the most
        return max(measured, key=lambda m: (m.time_ms, -m.rmse, m.candidate.key())), False
    ok = [m for m in measured if m.bound <= max_error]
    if ok:
        return min(ok, key=lambda m: (m.time_ms, m.rmse, m.candidate.key())), True
    return min(measured, key=lambda m: (m.rmse, m.time_ms, m.candidate.key())), False


@dataclass(frozen=True)
class Layout:
    """Which pixels are measured.  Error: ``tiles`` (x, y, w, h) of the full
    image (x right, y down from the top row), packed in a mosaic of ``size``
    (tile k at ``packed[k]``, x, y from the top).  Time: the whole picture
    at ``timing_size`` (the full size, or about FULL_TIMING_PIXELS)."""
    full: tuple[int, int]
    size: tuple[int, int]
    tiles: tuple[tuple[int, int, int, int], ...]
    packed: tuple[tuple[int, int], ...]
    timing_size: tuple[int, int]

    @property
    def pixels(self) -> int:
        return self.size[0] * self.size[1]


def layout(width: int, height: int, pixels: int = MEASURE_PIXELS, grid: int = GRID) -> Layout:
    """The measured pixels of a width x height image: all of them when there
    are at most about ``pixels``; else grid x grid tiles, one in each cell of
    a grid x grid partition of the image at a seeded random place in it
    (stratified, so that no part of the picture is favoured), about
    ``pixels`` in all.  The tiles are pixels of the real image (the same
    footprint and rays), so their error is the error at the real size."""
    width, height = int(width), int(height)
    if width * height <= pixels * 1.25:
        return Layout((width, height), (width, height), ((0, 0, width, height),), ((0, 0),), (width, height))
    f = math.sqrt(pixels / (width * height))
    # timed at the real size up to FULL_TIMING_PIXELS, else at about that
    # many pixels: scaled down to the mosaic's size, a pass's fixed cost
    # (draw calls, the GPU's finish) was scaled up with the pixels, and the
    # default scene's estimates ran 20-40% high at 640x360, 1.6-2.6x at 1920x1080
    ft = math.sqrt(FULL_TIMING_PIXELS / (width * height))
    timing = ((width, height) if width * height <= FULL_TIMING_PIXELS
              else (max(1, round(width * ft)), max(1, round(height * ft))))
    tw = max(1, min(width // grid, round(width * f / grid)))
    th = max(1, min(height // grid, round(height * f / grid)))
    rng = np.random.default_rng(width * 100003 + height)
    tiles, packed = [], []
    for j in range(grid):
        for i in range(grid):
            cx0, cx1 = (i * width) // grid, ((i + 1) * width) // grid
            cy0, cy1 = (j * height) // grid, ((j + 1) * height) // grid
            x0 = cx0 + int(rng.integers(0, max(1, cx1 - cx0 - tw + 1)))
            y0 = cy0 + int(rng.integers(0, max(1, cy1 - cy0 - th + 1)))
            tiles.append((min(x0, width - tw), min(y0, height - th), tw, th))
            packed.append((i * tw, j * th))
    return Layout((width, height), (grid * tw, grid * th), tuple(tiles), tuple(packed), timing)
