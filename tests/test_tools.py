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


# tools/jit_profile.py: objdump parsing and sample attribution
from jit_profile import basic_blocks, is_lane_block, parse_objdump, summary  # noqa: E402

OBJDUMP = """
/tmp/x.bin:     file format binary

Disassembly of section .data:

0000000000001000 <.data>:
    1000:	c5 f4 59 c2          	vmulps %ymm2,%ymm1,%ymm0
    1004:	48 b8 00 10 00 00 00 	movabs $0x1000,%rax
    100b:	00 00 00 
    100e:	c5 fc 29 44 24 20    	vmovaps %ymm0,0x20(%rsp)
    1014:	74 10                	je     0x1026
    1016:	c4 e3 79 16 c0 01    	vpextrd $0x1,%xmm0,%eax
    101c:	c4 e3 79 22 04 82 01 	vpinsrd $0x1,(%rdx,%rax,4),%xmm0,%xmm0
    1023:	c3                   	ret
    1024:	90                   	nop
"""


def test_parse_objdump_keeps_addresses_and_text():
    lines = parse_objdump(OBJDUMP)
    assert lines[0] == (0x1000, "vmulps %ymm2,%ymm1,%ymm0")
    assert (0x100b, "") in lines                      # an encoding's continuation line
    assert lines[-1] == (0x1024, "nop")
    assert len(lines) == 9


def test_basic_blocks_end_at_jumps_and_returns():
    blocks = basic_blocks(parse_objdump(OBJDUMP))
    assert [b[0][0] for b in blocks] == [0x1000, 0x1016, 0x1024]
    assert blocks[0][-1][1].startswith("je") and blocks[1][-1][1] == "ret"


def test_lane_blocks_need_eight_lane_ops():
    ops = [(i, "vpextrd $0x1,%xmm0,%eax") for i in range(4)] + [(i + 4, "vpinsrd $0x1,(%rdx),%xmm0,%xmm0") for i in range(4)]
    assert is_lane_block(ops)
    assert not is_lane_block(ops[:7])
    assert not is_lane_block([(0, "vmulps %ymm2,%ymm1,%ymm0")] * 20)


def test_summary_attributes_samples_by_block_mnemonic_and_stack():
    lines = parse_objdump(OBJDUMP)
    samples = {0x1000: 3, 0x100e: 5, 0x101c: 2, 0x9999: 100}     # the last one is outside the code
    s = summary(lines, samples)
    assert s["total"] == 10
    assert s["mnemonics"] == {"vmulps": 3, "vmovaps": 5, "vpinsrd": 2}
    assert s["stack"] == 5                            # the spill to 0x20(%rsp)
    assert s["lane"] == 0                             # two lane ops are not a gather block
    assert [n for n, _ in s["per_block"]] == [8, 2, 0]
