"""The shader variant a scene compiles: its preprocessor defines.

Only the scene's structure goes in (counts, which shapes, media and
features exist, the object list as X-macros); every value stays in the
uniform block (gpu/block.py), so editing a value never recompiles.  The
generic all-features shader (specialise=False) reads the counts at run time.
"""

from __future__ import annotations

from ..scene.model import Scene, SceneObject
from .driver import PICK_MAX


OBJ_TYPES = {"plane": 0, "sphere": 1, "box": 2, "cylinder": 3}


# Array sizes of the GENERIC shader (all features, counts read at run time);
# its uniform block stays under the 64 KiB that llvmpipe and most GPUs allow.
GENERIC_LENS = {"OBJECTS_LEN": 64, "MATERIALS_LEN": 64, "LIGHTS_LEN": 16, "MEDIA_LEN": 32}


GENERIC_STACK = 65


# The compile-time shape of an object (shaders/lib/intersect.glsl): its type,
# and SHAPE_VESSEL for a cylinder with a wall.
SHAPE_VESSEL = 4


def object_shape(obj: SceneObject) -> int:
    return SHAPE_VESSEL if obj.type == "cylinder" and obj.wall else OBJ_TYPES[obj.type]


def object_list_macros(scene: Scene, subset: tuple[int, ...] | None = None) -> dict[str, str]:
    """The scene's objects as X-macros for the specialised shader (see
    FOR_EACH_OBJECT in shaders/lib/walk.glsl): SCENE_OBJECTS(X) lists X(k, shape, slot)
    per object (slot: transparent slot, -1 opaque), SCENE_MEDIA(X) lists
    X(slot, k, shape) per transparent object.  Only the structure (shapes,
    order, which objects are transparent) goes in: every value stays in the
    uniform block, so editing one never recompiles.  `subset`: only these
    object indices are listed (viewer/gpu/culling.py); slots keep their numbers."""
    objects, media = [], []
    slot_of = 0
    for k, o in enumerate(scene.objects):
        shape = object_shape(o)
        slot = slot_of if scene.is_transparent(o) else -1
        slot_of += slot >= 0
        if subset is not None and k not in subset:
            continue
        if slot >= 0:
            media.append(f"X({slot},{k},{shape})")
        objects.append(f"X({k},{shape},{slot})")
    return {"SCENE_OBJECTS(X)": " ".join(objects), "SCENE_MEDIA(X)": " ".join(media)}


def index_list_macros(scene: Scene) -> dict[str, str]:
    """SCENE_LIGHT_INDICES(X) and SCENE_MATERIAL_INDICES(X): X(1) .. X(n - 1)
    for the scene's n lights and n materials where 1 <= n <= PICK_MAX (with
    one, an empty list: index 0 is read anyway).  None for 0 or for more
    than PICK_MAX (the shader gathers).  The counts are compile-time
    constants already (the block's array lengths), so these add no
    recompiles."""
    out = {}
    for name, n in (("SCENE_LIGHT_INDICES(X)", len(scene.lights)),
                    ("SCENE_MATERIAL_INDICES(X)", len(scene.materials))):
        if 1 <= n <= PICK_MAX:
            out[name] = " ".join(f"X({q})" for q in range(1, n))
    return out


def max_passes(scene: Scene) -> int:
    """MAX_PASSES of shaders/lib/walk.glsl: the most groups of transparent surfaces a
    ray or shadow ray can cross before its interaction (a line crosses at
    most 1 surface of a plane, 2 of a sphere, box or cylinder, 4 of a
    vessel), plus the pass that finds the interaction or the sky, plus one;
    never fewer than the 2 * objects + 2 the shader had before."""
    per = {"plane": 1, "sphere": 2, "box": 2, "cylinder": 2}
    crossings = sum(4 if o.type == "cylinder" and o.wall else per[o.type]
                    for o in scene.objects if scene.is_transparent(o))
    return max(crossings, 2 * len(scene.objects)) + 2


#: Sizes of the ray-tree stack a program is compiled with: the smallest that
#: holds max_depth + 1 entries.  Max depth itself is a uniform (iparams.x),
#: so a new depth within a size (1..8, 9..16, 17..32, 33..64) compiles
#: nothing: the panel's slider and --max-error's candidates reuse the
#: program.  The default depth 8 gets 9, exactly what it needs.
STACK_SIZES = (9, 17, 33, 65)


def stack_size(max_depth: int) -> int:
    """Entries of the ray-tree stack for trees of max_depth (shaders/lib/tree.glsl:
    max_depth + 1 suffice)."""
    need = max_depth + 1
    return next((n for n in STACK_SIZES if n >= need), need)


def shader_defines(scene: Scene, specialise: bool = True, fresnel: str = "exact",
                   subset: tuple[int, ...] | None = None) -> dict[str, object]:
    """Compile-time constants of the shader for this scene: counts, the
    features present and the object list (specialise=True), or the generic
    all-features shader.  `subset` (object indices): a shader for the part
    of the image that can meet only those objects (viewer/gpu/culling.py): the
    features are theirs, the counts and the block stay the scene's."""
    extra: dict[str, object] = {"FRESNEL_SCHLICK": True} if fresnel == "schlick" else {}
    if not specialise:
        return {"GENERIC": True, **GENERIC_LENS, "STACK_SIZE": GENERIC_STACK, "HAS_LIGHTS": True,
                "HAS_PLANE": True, "HAS_SPHERE": True, "HAS_BOX": True, "HAS_CYLINDER": True,
                "HAS_DIELECTRIC": True, "HAS_REFLECTION": True, "HAS_SKY_IMAGE": True, **extra}
    n_obj = len(scene.objects)
    n_tr = sum(scene.is_transparent(o) for o in scene.objects)
    present = [o for k, o in enumerate(scene.objects) if subset is None or k in subset]
    used = [scene.materials[o.material] for o in present]
    d: dict[str, object] = {
        "NUM_OBJECTS": n_obj, "OBJECTS_LEN": max(1, n_obj),
        "MATERIALS_LEN": max(1, len(scene.materials)),
        "NUM_LIGHTS": len(scene.lights), "LIGHTS_LEN": max(1, len(scene.lights)),
        "NUM_TRANSPARENT": n_tr, "MEDIA_LEN": max(1, n_tr),
        "MAX_PASSES": max_passes(scene),
        **object_list_macros(scene, subset),
        **index_list_macros(scene),
        **extra,
    }

    if scene.lights:
        d["HAS_LIGHTS"] = True
    for t in OBJ_TYPES:
        if any(o.type == t for o in present):
            d[f"HAS_{t.upper()}"] = True
    if any(scene.is_transparent(o) for o in present):
        d["HAS_DIELECTRIC"] = True
        # only the dielectric tree has a stack (shaders/lib/tree.glsl): without glass
        # the depth compiles nothing at all
        d["STACK_SIZE"] = stack_size(scene.render.max_depth)
    if any(m.reflectivity > 0 for m in used):
        d["HAS_REFLECTION"] = True
    if scene.sky.type == "image":
        d["HAS_SKY_IMAGE"] = True
    return d
