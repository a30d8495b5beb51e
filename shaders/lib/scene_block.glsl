// The scene as the GPU sees it.  Mirrored on the Python side by the numpy
// dtypes in viewer/gpu/packing.py: every member is vec4/ivec4 sized so std140
// never inserts padding.  All positions are camera-relative (the eye is at
// the origin; the shift is done in float64 on the CPU).
//
// Compile-time constants injected by viewer/gpu/packing.py (shader_defines):
//   NUM_OBJECTS, NUM_LIGHTS, NUM_TRANSPARENT (counts, may be 0)
//   OBJECTS_LEN, MATERIALS_LEN, LIGHTS_LEN, MEDIA_LEN (array sizes, >= 1)
//   STACK_SIZE (ray-tree stack: max_depth + 1 entries suffice for a
//   depth-first walk that pushes at most one child per node: it holds
//   branches of strictly increasing depth, at most max_depth - 1); with
//   HAS_DIELECTRIC only, and rounded up to 9, 17, 33 or 65 so that a new
//   max depth (a uniform) rarely compiles (gpu/packing.py stack_size)
//   HAS_PLANE/SPHERE/BOX/CYLINDER, HAS_LIGHTS, HAS_DIELECTRIC,
//   HAS_REFLECTION, HAS_SKY_IMAGE: the features the scene uses; code for
//   the others is not compiled.
// GENERIC (the all-features shader the benchmark compares against): every
// feature compiled in, arrays at their maximum sizes, counts read at run
// time from `counts`.

#define OBJ_PLANE 0
#define OBJ_SPHERE 1
#define OBJ_BOX 2
#define OBJ_CYLINDER 3

#define SKY_COLOR 0
#define SKY_GRADIENT 1
#define SKY_IMAGE 2

struct Object {
    vec4 a;      // plane: a.x = height | sphere: centre, radius | box: centre | cylinder: base, radius
    vec4 b;      // box: half extents | cylinder: b.x = height, b.y = wall (0: solid)
    vec4 c;      // box: rows of localFromWorld (rotation), c, d, e
    vec4 d;
    vec4 e;
    ivec4 info;  // x: type, y: material index, z: cylinder axis (0,1,2), w: transparent slot or -1
    vec4 bound;  // bounding sphere (centre, radius) of a bounded solid; radius < 0: unbounded (plane)
};

struct Material {
    vec4 colorAmbient;       // rgb: C, a: k_a
    vec4 phong;              // k_d, k_s, p, reflectivity
    vec4 dielectric;         // transparency, ior, hasChecker (0/1), checker size
    vec4 absorption;         // rgb
    vec4 emission;           // rgb
    vec4 checkerColor;       // rgb
    vec4 checkerEmission;    // rgb
    vec4 checkerOffset;      // xy: eye's world (x, z) modulo 2 * size, for the parity
};

// A transparent slot: its object and material, and the material's optics
// again, so that a medium's ior, transparency and absorption are read at
// the slot's own index (lib/walk.glsl mediumOptics).
struct Medium {
    ivec4 index;        // x: object index, y: material index
    vec4 optics;        // x: ior, y: transparency
    vec4 absorption;    // rgb
};

struct Light {
    vec4 vector;    // xyz: camera-relative position (point) or unit direction of travel; w: 0 point, 1 directional
    vec4 radiance;  // rgb: color * intensity
};

layout(std140) uniform SceneBlock {
    Object objects[OBJECTS_LEN];
    Material materials[MATERIALS_LEN];
    Light lights[LIGHTS_LEN];
    Medium media[MEDIA_LEN];  // per transparent slot
    vec4 ambient;             // rgb
    vec4 skyColor;
    vec4 skyHorizon;
    vec4 skyZenith;
    vec4 params;              // x: epsAbs, y: epsRel, z: minWeight, w: exposure * 2^-r
    ivec4 iparams;            // x: maxDepth, y: initial medium mask (uint bits), z: sky type, w: unused
    ivec4 counts;             // objects, lights, transparent objects, unused
};

#ifdef GENERIC
#define NUM_OBJECTS counts.x
#define NUM_LIGHTS counts.y
#define NUM_TRANSPARENT counts.z
#endif

uniform sampler2D skyImage;
