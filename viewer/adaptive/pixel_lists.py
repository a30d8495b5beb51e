"""The layout of the adaptive sampler's pixel lists (viewer/adaptive/sampler.py):
which texel of the list each entry (a pixel's first sample and count) takes,
in coherent order (Z-order inside 8x8 image tiles, 4x4 blocks of the list),
one run of the list per culling group and sample count, a short run dealt
over several bands of BIN rows, and into how many entries each pixel's
samples are split.  Pure numpy: no GL.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

#: Width of the pixel-list framebuffer (a multiple of LIST_BLOCK).
LIST_WIDTH = 64
#: The most rows a pixel list takes (a longer list is made wider: list_width,
#: list_layout).
MAX_LIST_HEIGHT = 16384
#: Side of the blocks the pixel list is laid out in (llvmpipe shades 4x4
#: blocks; a GPU's warps are 2x2 quads, which the Z-order inside keeps).
LIST_BLOCK = 4
#: The least number of 64-row bands a pixel list spans (list_width).
LIST_MIN_BINS = 8


def _spread_bits(v: np.ndarray) -> np.ndarray:
    """Bits b0 b1 b2 ... of v (< 2^16) moved to b0 b2 b4 ... (Z-order keys)."""
    v = v.astype(np.int64)
    out = np.zeros_like(v)
    for bit in range(16):
        out |= ((v >> bit) & 1) << (2 * bit)
    return out


def z_index(i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """The Z-order (Morton) index of (i, j): i's bits in the even places."""
    return _spread_bits(i) | (_spread_bits(j) << 1)


def coherent_order(pixels: np.ndarray, width: int, tile: int = 8) -> np.ndarray:
    """Flat pixel indices (j * width + i) sorted by tile x tile squares of
    the image (row of squares by row of squares), in Z-order inside a square:
    neighbours in the list are neighbours in the image, so their rays take
    similar paths (less SIMD divergence), and 16 consecutive entries of a
    full square are one of its 4x4 blocks (what list_slots puts in one 4x4
    block of the list, the block a software rasteriser shades at once)."""
    i, j = pixels % width, pixels // width
    tiles_x = (width + tile - 1) // tile
    inside = np.arange(tile * tile)
    z = z_index(inside % tile, inside // tile)          # a table: the Z-order index inside a square
    key = ((j // tile) * tiles_x + i // tile) * (tile * tile) + z[(j % tile) * tile + i % tile]
    return pixels[np.argsort(key, kind="stable")]


@lru_cache(maxsize=4)
def image_coherent_order(width: int, height: int) -> np.ndarray:
    """coherent_order of every pixel of a width x height image (read-only,
    cached: the viewer restarts a render at every change of view)."""
    out = coherent_order(np.arange(width * height), width)
    out.setflags(write=False)
    return out


def list_width(count: int) -> int:
    """The width of the pixel list for `count` entries: LIST_WIDTH, or
    narrower (down to LIST_BLOCK) so that the list spans at least
    LIST_MIN_BINS rows of 64: llvmpipe shades each 64x64 square of a
    framebuffer on one thread, and a short list one square wide would run
    on one core.  Wider when MAX_LIST_HEIGHT rows would not hold it."""
    lw = LIST_WIDTH
    while lw > LIST_BLOCK and count < lw * 64 * LIST_MIN_BINS:
        lw //= 2
    if count > LIST_WIDTH * MAX_LIST_HEIGHT:
        lw = LIST_WIDTH * -(-count // (LIST_WIDTH * MAX_LIST_HEIGHT))
    return lw


def list_rows(count: int, list_width: int) -> int:
    """Rows of a list list_width wide that list_slots fills with `count`
    entries: whole blocks of LIST_BLOCK rows."""
    return LIST_BLOCK * max(1, -(-count // (LIST_BLOCK * list_width)))


def list_slots(count: int, list_width: int) -> np.ndarray:
    """Where list entries 0..count-1 go in a list list_width wide (a
    multiple of LIST_BLOCK = 4): texel indices y * list_width + x.  Runs of
    16 consecutive entries fill one 4x4 block of texels in Z-order, the
    blocks left to right, then the next row of blocks, so that a block the
    rasteriser shades together holds entries that are neighbours in the
    list (and, through coherent_order, in the image)."""
    k = np.arange(count, dtype=np.int64)
    per_block = LIST_BLOCK * LIST_BLOCK
    blocks_x = list_width // LIST_BLOCK
    b, r = k // per_block, k % per_block
    x = (r & 1) | ((r >> 1) & 2)              # the Z-order index r of a 4x4 block: x from the even bits,
    y = ((r >> 1) & 1) | ((r >> 2) & 2)       # y from the odd ones
    return ((b // blocks_x) * LIST_BLOCK + y) * list_width + (b % blocks_x) * LIST_BLOCK + x


#: Rows of the llvmpipe bins a framebuffer is cut into (64x64 squares, each
#: shaded by one thread).
BIN = 64


def run_bands(count: int, list_width: int) -> int:
    """How many bands of BIN rows a run of `count` entries is spread over:
    1 where it fills LIST_MIN_BINS bands or more (dense, list_slots), else
    as many as it has blocks of 16, at most LIST_MIN_BINS (run_slots)."""
    blocks = -(-count // (LIST_BLOCK * LIST_BLOCK))
    per_band = (list_width // LIST_BLOCK) * (BIN // LIST_BLOCK)
    if blocks >= LIST_MIN_BINS * per_band:
        return 1
    return max(1, min(LIST_MIN_BINS, blocks))


def run_rows(count: int, list_width: int, bands: int) -> int:
    """Rows a run of `count` entries takes in run_slots' layout."""
    if bands <= 1:
        return list_rows(count, list_width)
    blocks = -(-count // (LIST_BLOCK * LIST_BLOCK))
    in_first = -(-blocks // bands)                       # band 0 holds the most
    return BIN * (bands - 1) + LIST_BLOCK * -(-in_first // (list_width // LIST_BLOCK))


def run_slots(count: int, list_width: int, bands: int) -> np.ndarray:
    """Where a run's entries go (texel indices from the run's first row,
    which is a multiple of BIN when bands > 1): list_slots' blocks of 16,
    dealt round the `bands` bands of BIN rows (block b into band b % bands),
    so that a short run (a few pixels that take many samples: the last
    rounds' glass) is shaded by every thread instead of one."""
    if bands <= 1:
        return list_slots(count, list_width)
    k = np.arange(count, dtype=np.int64)
    b, r = k // (LIST_BLOCK * LIST_BLOCK), k % (LIST_BLOCK * LIST_BLOCK)
    x = (r & 1) | ((r >> 1) & 2)              # the Z-order inside a block, as in list_slots
    y = ((r >> 1) & 1) | ((r >> 2) & 2)
    s = b // bands                            # the block's place in its band
    blocks_x = list_width // LIST_BLOCK
    return (((b % bands) * BIN + (s // blocks_x) * LIST_BLOCK + y) * list_width
            + (s % blocks_x) * LIST_BLOCK + x)


#: A run of the pixel list (one group, one sample count) with fewer pixels
#: than this has each pixel's samples dealt to several entries (split_factor),
#: up to one sample each: a few pixels with many samples would otherwise fill
#: a few SIMD lanes of one thread.
MIN_RUN_ENTRIES = 512
#: The most samples one entry of a costly pixel traces (add_samples'
#: `cost`: where a sample traces more than HEAVY_RAYS rays, the glass): the
#: power of two nearest under ENTRY_RAYS / its rays per sample, at least 1.
#: The lanes of a SIMD block run each ray tree in step, as long as the
#: longest; more entries of one pixel in a block are more alike trees, and
#: a short list keeps every thread busy.  Measured, entries of at most 4
#: samples for every costly pixel (the rule before): a list pass over the
#: default scene's 10765 glass pixels, 16 samples each, took 436 ms as one
#: entry a pixel, 379 / 330 / 344 / 354 ms at 8 / 4 / 2 / 1 samples an
#: entry; but whole adaptive renders (320x180, 7 interleaved runs each,
#: CPU time) took 10-12% less at 2 or 1 on the default scene (26 rays a
#: glass sample), and 4-7% more on glass-sphere (6 rays a sphere sample),
#: hence a size by cost: 1 sample an entry on the default scene's glass, 4
#: on glass-sphere's sphere.  Not for the cheap pixels: every pixel at one
#: sample an entry took 731 ms against 518 (the entry's own work, a
#: footprint's closed form among it, is no longer small beside a sample of
#: the floor).
ENTRY_RAYS = 32
HEAVY_RAYS = 4


def entry_samples(cost: np.ndarray) -> np.ndarray:
    """The most samples one entry of each pixel traces (0: no limit), from
    its rays per sample `cost`: for a pixel above HEAVY_RAYS, the largest
    power of two at most ENTRY_RAYS / cost, and at least 1."""
    cost = np.asarray(cost, np.float64)
    most = np.exp2(np.floor(np.log2(np.maximum(ENTRY_RAYS / np.maximum(cost, 1.0), 1.0))))
    return np.where(cost > HEAVY_RAYS, most, 0).astype(np.int64)


def split_factor(length: int, samples: int, most: int | None = None) -> int:
    """Into how many entries each of a run's `length` pixels, taking
    `samples` more samples, is split: the least divisor d of samples with
    length x d >= MIN_RUN_ENTRIES and samples / d <= `most` (None: no
    limit), else samples (one sample an entry).  Equal parts: every entry
    of a run loops alike."""
    if samples <= 1:
        return 1
    most = samples if most is None else max(1, most)
    for d in range(1, samples):
        if samples % d == 0 and length * d >= MIN_RUN_ENTRIES and samples // d <= most:
            return d
    return samples


def list_layout(groups: np.ndarray, count: np.ndarray):
    """The pixel list of entries that take count[k] samples each and are
    drawn by culling group groups[k]: one run of rows per group and sample
    count (drawn with that group's program, all its fragments looping
    alike), entries placed by run_slots in the order given (a short run
    spread over several bands of BIN rows, each starting on a band).
    Returns (list width, rows, [(group, samples, first row, rows, entries)],
    texel index of each entry)."""
    n = len(groups)
    # runs in order of group, then count
    key = groups * (int(count.max(initial=0)) + 1) + count
    runs_of = [np.flatnonzero(key == k) for k in np.unique(key)]
    lw = list_width(n)

    def plan(lw, spread):
        row, out = 0, []
        for m in runs_of:
            bands = run_bands(len(m), lw) if spread else 1
            if bands > 1:
                row = -(-row // BIN) * BIN            # a spread run starts on a band
            out.append((row, bands))
            row += run_rows(len(m), lw, bands)
        return row, out

    height, placed = plan(lw, True)
    if height > MAX_LIST_HEIGHT:                      # too tall for a texture: dense runs, wider
        while plan(lw, False)[0] > MAX_LIST_HEIGHT and lw < n:
            lw += LIST_WIDTH
        height, placed = plan(lw, False)
    slot = np.empty(n, np.int64)
    runs = []
    for m, (row, bands) in zip(runs_of, placed):
        rows = run_rows(len(m), lw, bands)
        slot[m] = row * lw + run_slots(len(m), lw, bands)
        runs.append((int(groups[m[0]]), int(count[m[0]]), row, rows, len(m)))
    return lw, max(height, 1), runs, slot
