"""Driver knowledge: every define and tuning constant that exists because of
a particular OpenGL driver (Mesa's llvmpipe, a GPU's watchdog), each with the
measurement that justifies it.  The rest of gpu/ is driver-neutral.
"""

from __future__ import annotations

import re


#: The most lights or materials the specialised shader reads by literal
#: index and select (shaders/lib/shade.glsl, pickLight / pickMaterial) rather than
#: through a per-lane index: a select per component and entry against a
#: gather of about 17 instructions a component.
PICK_MAX = 8


def driver_defines(renderer: str, version: str) -> dict[str, object]:
    """What a driver changes in every program (GL_RENDERER, GL_VERSION).
    llvmpipe before Mesa 25 keeps the per-lane gather of a hit's material:
    there the literal-index selects made the default frame 25% slower
    (22.3.6: 330 -> 405 ms), where 25.0.7 is 3% faster with them.  (A
    value None drops the define: shaders.load_source skips it.)"""
    m = re.search(r"\bMesa (\d+)\.", version)
    if "llvmpipe" in renderer and m and int(m.group(1)) < 25:
        return {"SCENE_MATERIAL_INDICES(X)": None}
    return {}


# ---------------------------------------------------------------- one draw

# Side of the tiles a render draws and finishes one at a time (Ctrl-C and the
# progress bar act between them): a frame up to 2048x2048 is one tile.  On
# llvmpipe each finish leaves a core idle while the other ends its last bins:
# 512 (six tiles at 1280x720) cost the default frame 5% (1 sample, Mesa 25).
# Deep trees, which could meet a slow GPU's ~2 s watchdog, are drawn in their
# own resumable passes of RESUME_TILE (Renderer.render).
DEFAULT_TILE = 2048


#: Scenes with more objects are drawn unculled: a shader listing dozens of
#: objects takes seconds to compile on llvmpipe, and culling would compile
#: several (bench-many, 43 objects: 5 s each).
CULL_MAX_OBJECTS = 24


#: Nodes of a ray tree one resumable pass traces at most, to begin with
#: (shaders/resume.frag, lib/resume.glsl): well below what ends a shader on
#: llvmpipe (65535 loop iterations in all: about a hundred a node with
#: one light, more with many) or a draw on a GPU's watchdog.  A pass
#: that meets the limit anyway hands its cut nodes back and the next
#: passes take half as many.
RESUME_BUDGET = 512
#: Tile side of resumable renders: a pass over it stays well under a
#: second on llvmpipe, so Ctrl-C (taken between passes) ends at once.
RESUME_TILE = 64

#: Trees whose bound (Renderer.resumes) exceeds this many nodes are drawn in
#: resumable passes at once: one draw would only be cut and drawn again.
RESUME_AT_ONCE = 16384
