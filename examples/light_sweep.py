"""Render the default scene with its light moving around the glass: one PNG a frame.

    python examples/light_sweep.py [--frames 12] [--size 640x360] [--out sweep/]

One viewer.Renderer draws every frame: the scene keeps its structure (only a
light moves), so the shader programs compiled for the first frame serve all.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import viewer


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=12, help="frames in the sweep (12)")
    p.add_argument("--size", default="640x360", help="WxH of each frame (640x360)")
    p.add_argument("--samples", type=int, default=2, help="samples per pixel (2)")
    p.add_argument("--out", type=Path, default=Path("sweep"), help="folder for the PNGs (sweep/)")
    args = p.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    args.out.mkdir(parents=True, exist_ok=True)

    scene = viewer.load_scene("default")
    light = next(lt for lt in scene.lights if lt.type == "point")
    x, y, z = light.position
    radius = math.hypot(x, z)
    with viewer.Renderer() as r:
        for i in range(args.frames):
            angle = 2 * math.pi * i / args.frames
            light.position = (radius * math.cos(angle), y, radius * math.sin(angle))
            img = r.render(scene, size=(w, h), samples=args.samples)
            path = args.out / f"frame-{i:03d}.png"
            viewer.save_image(img, path)
            print(f"{path}: light at ({light.position[0]:.2f}, {y:.2f}, {light.position[2]:.2f}), "
                  f"mean {float(img.mean()):.4f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
