"""adaptive: anti-aliasing that spends samples only where pixels still need
them (viewer/adaptive/render.py's docstring tells how).

render.py holds the policy (AdaptiveRender, render_adaptive), estimators.py
the per-pixel estimates, chains.py the chain footprints, pixel_lists.py the
layout of the pixel lists and sampler.py the GPU passes (AdaptiveSampler).
"""

from .render import DEFAULT_TARGET_ERROR, AdaptiveRender, AdaptiveResult, render_adaptive
from .sampler import AdaptiveSampler

__all__ = ["DEFAULT_TARGET_ERROR", "AdaptiveRender", "AdaptiveResult", "AdaptiveSampler", "render_adaptive"]
