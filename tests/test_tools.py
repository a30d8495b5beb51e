"""The pure helpers of the measurement scripts in tools/ (their numbers go
into the README, so their arithmetic is checked here, by hand-made cases)."""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
from frame_budget import simd_waste  # noqa: E402


def test_simd_waste_is_zero_when_every_lane_does_the_same():
    rays = np.full((8, 16), 3)
    assert simd_waste(rays, [(0, 0, 16, 8)], 8) == 0.0


def test_simd_waste_counts_each_4x2_block_at_its_busiest_lane():
    rays = np.ones((4, 8), int)          # four 4x2 blocks of 1 ray a pixel
    rays[0, 0] = 9                       # one lane of the top-left block traces 9
    # top-left block: 8 x 9 = 72 lane-rays; the three others 8 each; traced 32 + 8
    assert simd_waste(rays, [(0, 0, 8, 4)], 4) == (72 + 24) / 40 - 1


def test_simd_waste_reads_rectangles_from_the_bottom_like_opengl():
    rays = np.ones((4, 4), int)
    rays[0, 0] = 5                       # top row of the image
    assert simd_waste(rays, [(0, 0, 4, 2)], 4) == 0.0          # the bottom two rows
    assert simd_waste(rays, [(0, 2, 4, 2)], 4) == 40 / 12 - 1   # the top two rows


def test_simd_waste_leaves_out_partial_blocks():
    # blocks start at OpenGL's bottom-left: rows 1-2 (top first) pair up, row 0
    # and column 5 are partial
    rays = np.ones((3, 6), int)
    rays[0, :] = 100
    rays[:, 4:] = 100
    assert simd_waste(rays, [(0, 0, 6, 3)], 3) == 0.0
    rays[1, 0] = 3
    assert simd_waste(rays, [(0, 0, 6, 3)], 3) == 8 * 3 / 10 - 1
