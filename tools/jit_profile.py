"""Where llvmpipe's machine code spends a frame's time, sampled with perf.

llvmpipe compiles each shader to x86 code at run time, into anonymous
memory that perf can sample but not name (``[JIT]``, ``perf-PID.map``).
This script renders a scene's frame repeatedly under ``perf record``;
the rendering process then copies every executable anonymous mapping
out of ``/proc/self/mem`` (the code is still there), and the mapping
with the most samples is disassembled with objdump.  It prints:

- the samples per instruction mnemonic;
- the share in per-lane gather or scatter blocks: basic blocks with 8 or
  more ``vpextrd`` / ``vpinsrd``, the shape of a load or store whose
  address differs from SIMD lane to SIMD lane (a uniform block read at a
  per-lane index, an array indexed by a per-lane value), which llvmpipe
  does lane by lane;
- the share on instructions that address the stack frame (``%rsp``):
  register spills and reloads, and local arrays;
- the hottest basic blocks with their instruction mix (``--dump N``:
  the code of the N hottest).

A sample lands on the instruction after the one that stalled (skid), so
read single instructions loosely and blocks firmly.  perf comes from
Debian's ``linux-perf`` package (not installed by ``make``); without
permission to sample (``perf_event_paranoid``) run as root.

Usage (repository root, the project's virtual environment)::

    python tools/jit_profile.py [SCENE] [--size WxH] [--frames N] [--blocks N] [--dump N]

The findings of 2026-12-05 (docs/performance.md) came from this.
"""
from __future__ import annotations

import argparse
import collections
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

_LINE = re.compile(r"\s*([0-9a-f]+):\s+(?:[0-9a-f]{2} )+\s*(.*)")
_LANE_OP = re.compile(r"(vpextr|vpinsr)")


def parse_objdump(text: str) -> list[tuple[int, str]]:
    """(address, instruction) for every instruction line of objdump -D
    output; the continuation lines of long encodings (no text) are kept
    with an empty instruction."""
    out = []
    for line in text.splitlines():
        m = _LINE.match(line)
        if m:
            out.append((int(m.group(1), 16), m.group(2).strip()))
    return out


def basic_blocks(lines: list[tuple[int, str]]) -> list[list[tuple[int, str]]]:
    """The instructions cut after every jump or return (a block here ends
    at a branch; a jump into its middle is not looked for: close enough
    for attributing samples)."""
    blocks, current = [], []
    for addr, ins in lines:
        current.append((addr, ins))
        if ins.startswith("j") or ins.startswith("ret"):
            blocks.append(current)
            current = []
    if current:
        blocks.append(current)
    return blocks


def is_lane_block(block: list[tuple[int, str]], at_least: int = 8) -> bool:
    """A block of per-lane loads or stores: at least `at_least` lane
    extracts or inserts (8 lanes of one 256-bit vector)."""
    return sum(1 for _, ins in block if _LANE_OP.match(ins)) >= at_least


def summary(lines: list[tuple[int, str]], samples: dict[int, int]) -> dict:
    """Samples by mnemonic, in lane blocks, on %rsp operands, and per block
    (hottest first).  `samples`: address -> count, addresses outside
    `lines` ignored."""
    at = {addr: ins for addr, ins in lines}
    total = sum(v for a, v in samples.items() if a in at)
    mnemonics = collections.Counter()
    stack = 0
    for addr, count in samples.items():
        ins = at.get(addr)
        if ins is None:
            continue
        mnemonics[ins.split()[0] if ins else "?"] += count
        if "(%rsp" in ins:
            stack += count
    blocks = basic_blocks(lines)
    per_block = sorted(((sum(samples.get(a, 0) for a, _ in b), i) for i, b in enumerate(blocks)), reverse=True)
    lane = sum(s for s, i in per_block if is_lane_block(blocks[i]))
    return {"total": total, "mnemonics": mnemonics, "lane": lane, "stack": stack,
            "blocks": blocks, "per_block": per_block}


def _child(scene_name: str, size: str, frames: int, out: Path) -> None:
    """Render under perf, then copy the executable anonymous mappings."""
    import moderngl

    from viewer.gpu.renderer import Renderer
    from viewer.scene.load import load_scene

    w, h = (int(v) for v in size.split("x"))
    ctx = moderngl.create_standalone_context(backend="egl")
    r = Renderer(ctx, load_scene(scene_name), eager=False)
    for _ in range(2):
        r.render(w, h, 1)                       # compile every variant first
    for _ in range(frames):
        r.render(w, h, 1)
    with open("/proc/self/maps") as maps, open("/proc/self/mem", "rb", 0) as mem:
        for line in maps:
            parts = line.split()
            if "x" not in parts[1] or len(parts) >= 6:      # executable, no file behind it
                continue
            lo, hi = (int(v, 16) for v in parts[0].split("-"))
            try:
                mem.seek(lo)
                data = mem.read(hi - lo)
            except OSError:
                continue
            (out / f"{lo:x}-{hi:x}.bin").write_bytes(data)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", nargs="?", default="default")
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--frames", type=int, default=15)
    ap.add_argument("--blocks", type=int, default=20, help="hottest blocks listed")
    ap.add_argument("--dump", type=int, default=0, help="print the code of the N hottest blocks")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        _child(args.scene, args.size, args.frames, Path(args.child))
        return 0
    for tool in ("perf", "objdump"):
        if shutil.which(tool) is None:
            print(f"jit_profile: {tool} not found (apt-get install linux-perf binutils)", file=sys.stderr)
            return 1
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        data = tmp / "perf.data"
        cmd = ["perf", "record", "-F", "2999", "-o", str(data), "--", sys.executable, __file__,
               args.scene, "--size", args.size, "--frames", str(args.frames), "--child", str(tmp)]
        run = subprocess.run(cmd, capture_output=True, text=True,
                             env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])})
        if run.returncode:
            print(f"jit_profile: perf record failed:\n{run.stderr[-2000:]}", file=sys.stderr)
            return 1
        script = subprocess.run(["perf", "script", "-i", str(data), "-F", "ip,dso"],
                                capture_output=True, text=True).stdout
        ips = collections.Counter()
        all_samples = 0
        for line in script.splitlines():
            all_samples += 1
            if "perf-" in line or "[JIT]" in line or "unknown" in line:
                ips[int(line.split()[0], 16)] += 1
        regions = []
        for f in tmp.glob("*.bin"):
            lo, hi = (int(v, 16) for v in f.stem.split("-"))
            regions.append((sum(v for a, v in ips.items() if lo <= a < hi), lo, f))
        if not regions or max(regions)[0] == 0:
            print("jit_profile: no samples in JIT code", file=sys.stderr)
            return 1
        count, lo, path = max(regions)
        asm = subprocess.run(["objdump", "-D", "-b", "binary", "-mi386:x86-64", f"--adjust-vma={lo:#x}", str(path)],
                             capture_output=True, text=True).stdout
    lines = parse_objdump(asm)
    s = summary(lines, ips)
    total = s["total"] or 1
    print(f"{args.scene} {args.size}, {args.frames} frames: {all_samples} samples, "
          f"{count} ({100 * count / max(all_samples, 1):.0f}%) in the hottest JIT code")
    print(f"  per-lane gather/scatter blocks: {100 * s['lane'] / total:.1f}% of them; "
          f"on %rsp operands (spills, local arrays): {100 * s['stack'] / total:.1f}%")
    print("  mnemonics: " + ", ".join(f"{k} {100 * v / total:.1f}%" for k, v in s["mnemonics"].most_common(15)))
    for rank, (n, i) in enumerate(s["per_block"][:args.blocks]):
        block = s["blocks"][i]
        mix = collections.Counter(ins.split()[0] for _, ins in block if ins)
        lane = " [per-lane]" if is_lane_block(block) else ""
        print(f"  block @{block[0][0]:x}: {100 * n / total:.1f}%, {len(block)} instructions{lane}: "
              + ", ".join(f"{k} {v}" for k, v in mix.most_common(8)))
        if rank < args.dump:
            for addr, ins in block:
                if ins:
                    print(f"    {ips.get(addr, 0):5d}  {ins}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
