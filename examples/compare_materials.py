"""Change the liquid in the glass in code and compare two renders (notebook style).

    python examples/compare_materials.py [--size 640x360] [--out compare/]

In a notebook, each `img` displays itself; here the two renders and their
difference are saved as PNGs, and the script prints how much changed.
"""

from __future__ import annotations

import argparse
import copy
from pathlib import Path

import numpy as np

import viewer

p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
p.add_argument("--size", default="640x360", help="WxH (640x360)")
p.add_argument("--out", type=Path, default=Path("compare"), help="folder for the PNGs (compare/)")
args = p.parse_args()
size = tuple(int(v) for v in args.size.split("x"))
args.out.mkdir(parents=True, exist_ok=True)

# %% the scene as shipped: a rod in a glass of water
water = viewer.load_scene("default")
print(water.summary())
liquid = next(name for name, m in water.materials.items() if m.is_dielectric and m.ior < 1.45)
print(f"liquid material: {liquid!r}, ior {water.materials[liquid].ior}")

# %% the same glass filled with something denser and tinted
syrup = copy.deepcopy(water)
syrup.materials[liquid].ior = 1.49                     # validated again at render: 1 <= ior <= 4
syrup.materials[liquid].absorption = (0.05, 0.4, 0.9)  # per unit length: red passes, blue is absorbed

# %% render both (one context for the two, its programs reused)
a = viewer.render(water, size=size, samples=2)
b = viewer.render(syrup, size=size, samples=2)

# %% compare
diff = np.abs(b - a).max(axis=2)
changed = float((diff > 1 / 255).mean())
print(f"{100 * changed:.1f}% of pixels changed visibly; largest change {float(diff.max()):.3f}")
viewer.save_image(a, args.out / "water.png")
viewer.save_image(b, args.out / "syrup.png")
viewer.save_image(np.repeat(diff[..., None] / max(float(diff.max()), 1e-9), 3, axis=2), args.out / "difference.png")
