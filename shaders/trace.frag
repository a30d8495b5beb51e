#version 330 core
// glassray: Whitted-style backward ray tracing of one pixel sample.
//
// Light transport is the one defined in shared/spec/scene-format.md: Phong
// with shadows, mirror reflection, exact Fresnel splitting into reflected and
// refracted branches (TIR included), nested media by object priority and
// Beer-Lambert absorption, with a real ray tree walked depth-first on an
// explicit stack (GLSL has no recursion).

#include "lib/scene_block.glsl"
#include "lib/intersect.glsl"
#include "lib/optics.glsl"
#include "lib/sky.glsl"

uniform vec2 imageSize;        // W, H of the whole image (tiles use the scissor)
uniform vec2 sampleOffset;     // (u, v) in [0,1)^2 inside the pixel, v downward
uniform vec3 camForward;       // f
uniform vec3 camRight;         // right * tan(fov/2) * W/H
uniform vec3 camUp;            // up * tan(fov/2)

out vec4 fragColor;

// floor(w / size) of the checker rule, per component.  A negative w has a
// negative quotient, so a cell of -1 or less; a quotient below float32's
// smallest normal (a square 1e38 or more across, |w| ~ 1) flushes to -0 and
// its floor to 0, which put the whole of x < 0 on the wrong side.
vec2 checkerCell(vec2 w, float size) {
    vec2 c = floor(w / size);
    return vec2(w.x < 0.0 ? min(c.x, -1.0) : c.x, w.y < 0.0 ? min(c.y, -1.0) : c.y);
}

#ifdef FOOTPRINT_AA
// Footprint samples: in adaptive renders, and in uniform renders of more
// than one sample (viewer/renderer.py).  FOOTPRINT_SHARE_PASS: no tracing,
// each pixel's closed-form share only (AdaptiveSampler.share_pass).
#include "lib/footprint.glsl"
#endif

#ifdef ADAPTIVE
// Adaptive sampling (viewer/adaptive.py).  Every sample adds (L, 1) to
// attachment 0 and (L.L, 0, 0, 0) to attachment 1, so that the sums give
// each pixel's mean and spread.  ADAPTIVE_LIST: fragment (x, y) of a small
// framebuffer traces samples of the image pixel (i, j) stored at (x, y) of
// pixelList with its first sample index s0 and count n (i < 0: padding,
// nothing traced): samples s0 + chunkStart .. s0 + min(n, chunkStart +
// chunkSize) - 1, at the offsets stored at texel (sample, 0) of
// sampleOffsets.  So only the pixels that still need samples are drawn and
// every SIMD lane does useful work.  ADAPTIVE_FIRST: the whole image (or
// the grid of pixel corners), plus the first interaction of each camera
// ray in attachment 2.
layout(location = 1) out vec4 fragMoments;
#ifdef ADAPTIVE_LIST
uniform isampler2D pixelList;
uniform sampler2D sampleOffsets;
uniform int chunkStart;
uniform int chunkSize;
#endif
#ifdef ADAPTIVE_FIRST
layout(location = 2) out vec4 fragFirstHit;     // (t, object index, rays, pixelShare); (INF, -1) for the sky
layout(location = 3) out vec4 fragFirstChecker; // rgb: firstChecker (exposure applied); a: footprint kind
layout(location = 4) out vec4 fragChainLeaf;    // chainLeaf
#endif
#endif
#ifdef ADAPTIVE_FIRST
float firstT = INF;
int firstObject = -1;
vec3 firstChecker = vec3(0.0);
// Where the camera ray's principal chain (see Branch) ends on an opaque
// surface: (x, z camera-relative, chain id, object); object -1: it leaves
// the scene (x, z 0; the id still the chain's) or is cut (max_depth,
// min_weight) first (all 0).
vec4 chainLeaf = vec4(0.0, 0.0, 0.0, -1.0);
#define RECORD_FIRST(br, it) if (br.depth == 1) { firstT = length(it.p - br.o); firstObject = it.object; }
#else
#define RECORD_FIRST(br, it)
#endif

#if (defined(VIEW_MODE) && VIEW_MODE == 3) || defined(ADAPTIVE_FIRST)
int rayCount = 0;           // the cost view: rays traced for this pixel sample
#define COUNT_RAY() (++rayCount)
#else
#define COUNT_RAY()
#endif

// ---------------------------------------------------------------- the objects

// FOR_EACH_OBJECT(X) expands to X(k, shape, slot) for every object k (slot:
// its transparent slot, -1 for an opaque object) and FOR_EACH_MEDIUM(X) to
// X(slot, k, shape) for every transparent object in slot order.  In the
// specialised shader both are straight lines of literal arguments
// (SCENE_OBJECTS and SCENE_MEDIA from viewer/gpu_scene.py): every object test
// compiles to its own primitive's code, with no loop, no switch on the type
// and only constant indices into local arrays (a software rasteriser spills
// dynamically indexed arrays to memory).  The generic shader loops and reads
// the same values from the block at run time.
#ifdef GENERIC
#define FOR_EACH_OBJECT(X) for (int k_ = 0; k_ < NUM_OBJECTS; ++k_) { X(k_, runtimeShape(objects[k_]), objects[k_].info.w) }
#define FOR_EACH_OBJECT_UNTIL(X, DONE) for (int k_ = 0; k_ < NUM_OBJECTS; ++k_) { X(k_, runtimeShape(objects[k_]), objects[k_].info.w) if (DONE) break; }
#define FOR_EACH_MEDIUM(X) for (int s_ = 0; s_ < NUM_TRANSPARENT; ++s_) { X(s_, media[s_].index.x, runtimeShape(objects[media[s_].index.x])) }
#else
#define FOR_EACH_OBJECT(X) SCENE_OBJECTS(X)
#define FOR_EACH_OBJECT_UNTIL(X, DONE) SCENE_OBJECTS(X)
#define FOR_EACH_MEDIUM(X) SCENE_MEDIA(X)
#endif

// MAX_PASSES bounds the passes of nextInteraction and shadowTransmittance:
// each pass crosses one group of transparent surfaces, and a line crosses
// at most 1 (plane), 2 (sphere, box, cylinder) or 4 (vessel) surfaces of an
// object, so the specialised shader gets that sum over the transparent
// objects plus 2 (gpu_scene.max_passes); the generic one the bound for
// NUM_OBJECTS vessels.  (2 * NUM_OBJECTS + 2 gave out inside a medium that
// holds two vessels of its own: the ray was taken for escaped.)
#ifndef MAX_PASSES
#define MAX_PASSES (4 * NUM_OBJECTS + 2)
#endif

// What one sweep over all objects found along o + t d, tmin < t < tmax.
struct Hits {
    float tNear;     // the nearest surface of any object (INF: none)
    float tOpaque;   // the nearest opaque surface (lowest index on a tie) ...
    vec3 nOpaque;    // ... its unit outward normal ...
    int kOpaque;     // ... and its object (-1: none)
};

#ifdef HAS_DIELECTRIC
// Per transparent slot, the last sweep's t and (specialised shader only)
// outward normal.  Globals, not parameters: GLSL copies an inout array into
// and out of every call.  The generic shader indexes them at run time, which
// puts them in memory, so it keeps no normals there and intersects a
// crossing's object again instead.
float slotT[MEDIA_LEN];
#ifndef GENERIC
vec3 slotN[MEDIA_LEN];
#endif
#endif

void keepHit(int k, int slot, float t, vec3 n, inout Hits h) {
    h.tNear = min(h.tNear, t);
    if (slot < 0) {
        if (t < h.tOpaque) { h.tOpaque = t; h.nOpaque = n; h.kOpaque = k; }
    }
#ifdef HAS_DIELECTRIC
    else {
        slotT[slot] = t;
#ifndef GENERIC
        slotN[slot] = n;
#endif
    }
#endif
}

// One pass over the objects; every hit's normal is kept as it is found (a
// normal nobody reads is never computed), so the nearest surface is not
// intersected a second time.
Hits sweep(vec3 o, vec3 d, float tmin, float tmax) {
    Hits h = Hits(INF, INF, vec3(0.0), -1);
#define SWEEP_OBJECT(k, shape, slot) { vec3 n; float t = hitShape(k, shape, o, d, tmin, tmax, n); keepHit(k, slot, t, n, h); }
    FOR_EACH_OBJECT(SWEEP_OBJECT)
#undef SWEEP_OBJECT
    return h;
}

// The sweep of a shadow ray: it may stop at the first opaque hit before
// tmax, which blocks the light whatever else lies on the way.  Only a loop
// can stop (when all of its SIMD lanes are done), so the straight-line
// specialised sweep always runs to the end.
Hits sweepShadow(vec3 o, vec3 d, float tmin, float tmax) {
    Hits h = Hits(INF, INF, vec3(0.0), -1);
#define SWEEP_OBJECT(k, shape, slot) { vec3 n; float t = hitShape(k, shape, o, d, tmin, tmax, n); keepHit(k, slot, t, n, h); }
    FOR_EACH_OBJECT_UNTIL(SWEEP_OBJECT, h.tOpaque < tmax)
#undef SWEEP_OBJECT
    return h;
}

#ifdef HAS_DIELECTRIC
// A ray's pass after a crossing at tGroup from the last pass's origin, now
// `step` further on along the same line.  The first pass of a ray (or
// shadow ray) swept every object and so knows the nearest opaque surface
// on the whole line: no opaque surface can come nearer along it, so only
// the transparent objects are looked at.  Of those, an object of the
// crossed group (slotT <= tGroup) is met again from the new origin o;
// every other one's nearest hit is still the one the last pass found, step
// nearer (it lies beyond tGroup, so beyond the new tmin), with its normal.
// (The first pass stays outside the loops that call this: llvmpipe 22.3
// runs both sides of a branch, even on the loop counter, so a
// `pass == 0 ? sweep : sweepMediaOn` would cost both there.)
Hits sweepMediaOn(vec3 o, vec3 d, float tmin, float tmax, float tGroup, float step) {
    Hits h = Hits(INF, INF, vec3(0.0), -1);
// (one line: GLSL 3.30 has no line continuation)
#define SWEEP_MEDIUM_ON(slot, k, shape) if (slotT[slot] <= tGroup) { vec3 n; float t = hitShape(k, shape, o, d, tmin, tmax, n); keepHit(k, slot, t, n, h); } else { slotT[slot] -= step; h.tNear = min(h.tNear, slotT[slot]); }
    FOR_EACH_MEDIUM(SWEEP_MEDIUM_ON)
#undef SWEEP_MEDIUM_ON
    return h;
}
#endif

// ---------------------------------------------------------------- media

// The medium is the first transparent object (lowest slot, slots follow the
// order of `objects`) whose solid holds the point; -1 is air.
int mediumOf(uint mask) {
    for (int s = 0; s < NUM_TRANSPARENT; ++s)
        if ((mask & (1u << uint(s))) != 0u) return s;
    return -1;
}

// A medium's (ior, transparency) and absorption; air for -1.  The
// specialised shader picks among its slots, each read at a constant index:
// an index that differs between SIMD lanes makes llvmpipe load every lane's
// value on its own, and these were read that way, two lookups deep
// (materials[media[medium].y]), at every pass and crossing of every ray
// and shadow ray: the default scene's frame took 8% longer.
#ifdef GENERIC
vec4 mediumOptics(int medium) {
    return medium < 0 ? vec4(1.0, 1.0, 0.0, 0.0) : media[medium].optics;
}

vec3 absorptionOf(int medium) {
    return medium < 0 ? vec3(0.0) : media[medium].absorption.rgb;
}
#else
vec4 mediumOptics(int medium) {
    vec4 v = vec4(1.0, 1.0, 0.0, 0.0);
#define PICK_OPTICS(slot, k, shape) v = medium == slot ? media[slot].optics : v;
    FOR_EACH_MEDIUM(PICK_OPTICS)
#undef PICK_OPTICS
    return v;
}

vec3 absorptionOf(int medium) {
    vec3 a = vec3(0.0);
#define PICK_ABSORPTION(slot, k, shape) a = medium == slot ? media[slot].absorption.rgb : a;
    FOR_EACH_MEDIUM(PICK_ABSORPTION)
#undef PICK_ABSORPTION
    return a;
}
#endif

float iorOf(int medium) { return mediumOptics(medium).x; }

// exp(-a t): what is left after t through a medium of absorption a.  Most
// rays travel in air or a clear medium (a = 0), where exp(0) = 1 exactly:
// behind the branch, a SIMD group all of whose rays do skips the three
// exponentials (Mesa 25's llvmpipe skips a branch no lane takes; 2% of the
// default scene's frame).
vec3 beerLambert(vec3 a, float t) {
    if (any(greaterThan(a, vec3(0.0)))) return exp(-a * t);
    return vec3(1.0);
}

// Offsets for leaving a surface: relative to the magnitude of the point (the
// float32 error of a hit point grows with it) plus a small absolute floor tied
// to the scene's size; both far below the thinnest wall.
float surfaceEps(vec3 p) {
    vec3 a = abs(p);
    return params.x + params.y * max(a.x, max(a.y, a.z));
}

#ifdef HAS_DIELECTRIC
// A crossing of the group of transparent surfaces hit at t <= tGroup (the
// last sweep's): the media on its far side, found by point-in-solid tests
// at `probe` just past it, and the group's first (lowest index) object, its
// slot and its outward normal (the normal: specialised shader only).
struct Crossing { uint after; int object; int slot; vec3 n; };

void probeSlot(int slot, int k, int shape, vec3 probe, float tGroup, inout Crossing c) {
    if (slotT[slot] <= tGroup) {
        uint bit = 1u << uint(slot);
        c.after = insideShape(k, shape, probe) ? (c.after | bit) : (c.after & ~bit);
#ifdef GENERIC
        if (c.object < 0) { c.object = k; c.slot = slot; }
#else
        if (c.object < 0) { c.object = k; c.slot = slot; c.n = slotN[slot]; }
#endif
    }
}

Crossing crossGroup(vec3 probe, float tGroup, uint mask) {
    Crossing c = Crossing(mask, -1, -1, vec3(0.0));
#define PROBE_SLOT(slot, k, shape) probeSlot(slot, k, shape, probe, tGroup, c);
    FOR_EACH_MEDIUM(PROBE_SLOT)
#undef PROBE_SLOT
    return c;
}
#endif

// ---------------------------------------------------------------- walking a ray

struct Interaction {
    vec3 p;          // the point
    vec3 n;          // unit outward normal of the surface of `object`
    int object;      // whose material S applies
    bool dielectric; // a crossing between two media (else: an opaque surface)
    uint maskAfter;  // media on the far side (dielectric only)
};

// Follows the ray from `o` until its next interaction: the nearest opaque
// surface, or a transparent surface whose two sides hold different media.
// Transparent surfaces with the same medium on both sides are passed
// untouched.  Surfaces within eps of the nearest hit are one crossing, so
// coincident surfaces (liquid on the glass bottom, glass on the floor) give
// the same interaction whichever is found first; an opaque one always wins.
// `atten` takes the absorption of every stretch travelled; `mask` is updated
// to the media of the last stretch.  Returns false when the ray leaves the scene.
bool nextInteraction(vec3 o, vec3 d, inout uint mask, inout vec3 atten, out Interaction it) {
    COUNT_RAY();
    it.p = vec3(0.0); it.n = vec3(0.0); it.object = -1; it.dielectric = false; it.maskAfter = mask;
#ifndef HAS_DIELECTRIC
    // Every object is opaque and the ray is in air: the interaction is the
    // nearest hit, found in a single pass.
    float tmin = surfaceEps(o);
    Hits h = sweep(o, d, tmin, INF);
    if (h.tOpaque >= INF) return false;
    it.p = o + h.tOpaque * d; it.n = h.nOpaque; it.object = h.kOpaque;
    return true;
#else
    // The first pass sweeps every object: the nearest opaque surface on the
    // line from o0, at tOpaque0; later passes sweep the media only and take
    // that surface at tOpaque0 - travelled from their own origin.
    vec3 o0 = o;
    float tmin = surfaceEps(o);
    Hits h = sweep(o, d, tmin, INF);
    float tOpaque0 = h.tOpaque, travelled = 0.0;
    for (int pass = 0; pass < MAX_PASSES; ++pass) {
        vec3 a = absorptionOf(mediumOf(mask));
        if (h.tNear >= INF) {
            atten *= beerLambert(a, INF);     // escaping through an absorbing medium: nothing left
            return false;
        }
        vec3 p = o + h.tNear * d;
        float tGroup = h.tNear + surfaceEps(p);
        if (h.tOpaque <= tGroup) {
            atten *= beerLambert(a, h.tOpaque);
            it.p = o0 + tOpaque0 * d; it.n = h.nOpaque; it.object = h.kOpaque;
            return true;
        }
        atten *= beerLambert(a, h.tNear);
        Crossing c = crossGroup(p + 2.0 * surfaceEps(p) * d, tGroup, mask);
        if (mediumOf(c.after) != mediumOf(mask)) {
            it.p = p; it.object = c.object; it.dielectric = true; it.maskAfter = c.after;
#ifdef GENERIC
            hitObject(c.object, o, d, tmin, INF, it.n);     // the sweep kept no transparent normals
#else
            it.n = c.n;
#endif
            return true;
        }
        mask = c.after;
        o = p;
        travelled += h.tNear;
        tmin = surfaceEps(o);
        Hits m = sweepMediaOn(o, d, tmin, INF, tGroup, h.tNear);
        m.tOpaque = tOpaque0 - travelled; m.nOpaque = h.nOpaque; m.kOpaque = h.kOpaque;
        m.tNear = min(m.tNear, m.tOpaque);
        h = m;
    }
    return false;   // pathological stack of coincident surfaces: treat as escaped
#endif
}

// Fraction of light j that reaches p (no refraction on shadow rays): 0 at an
// opaque blocker, transparency at every transparent interaction, absorption
// along every stretch inside a medium.
vec3 shadowTransmittance(vec3 p, vec3 l, float dist, uint mask) {
    COUNT_RAY();
#ifndef HAS_DIELECTRIC
    // Only opaque objects, in air: any hit before the light blocks it (the
    // normals the sweep would keep are never read, so never computed).
    return sweepShadow(p, l, surfaceEps(p), dist).tOpaque < dist ? vec3(0.0) : vec3(1.0);
#else
    vec3 v = vec3(1.0);
    vec3 o = p;
    float left = dist;
    // the first pass sees every opaque surface up to the light: any one
    // blocks it; later passes sweep the media only
    Hits h = sweepShadow(o, l, surfaceEps(o), left);
    if (h.tOpaque < left) return vec3(0.0);
    for (int pass = 0; pass < MAX_PASSES; ++pass) {
        vec3 a = absorptionOf(mediumOf(mask));
        if (h.tNear >= left) return v * beerLambert(a, min(left, INF));
        vec3 q = o + h.tNear * l;
        float tGroup = h.tNear + surfaceEps(q);
        v *= beerLambert(a, h.tNear);
        Crossing c = crossGroup(q + 2.0 * surfaceEps(q) * l, tGroup, mask);
        if (mediumOf(c.after) != mediumOf(mask)) v *= mediumOptics(c.slot).y;
        mask = c.after;
        if (maxComponent(v) <= 0.0) return vec3(0.0);
        o = q;
        left -= h.tNear;
        h = sweepMediaOn(o, l, surfaceEps(o), left, tGroup, h.tNear);
    }
    return v;
#endif
}

// ---------------------------------------------------------------- shading

struct Surface { vec3 color; vec3 emission; };

// The checker rule: parity of floor(x/s) + floor(z/s) in world x, z.  The
// eye's world position modulo 2s is added back (the pattern repeats every 2s).
// The point is first moved toward +x and +z by 2e-6 of its magnitude: far
// more than its rounding, far less than a pixel, and the same in every
// scene (so media that vanish leave the checker behind them as it was).  A
// face that lies on a checker line (a box face at x = 0) then has the
// spec's floor(0 / s) = 0 all over, where the rounding of its points to
// either side of the line made salt and pepper of it.
Surface surfaceAt(Material m, vec3 p) {
    Surface s;
    s.color = m.colorAmbient.rgb;
    s.emission = m.emission.rgb;
    if (m.dielectric.z > 0.5) {
        float size = m.dielectric.w;
        vec2 w = p.xz + m.checkerOffset.xy;
        w += params.y * max(max(abs(p.x), max(abs(p.y), abs(p.z))), max(abs(w.x), abs(w.y)));
        vec2 cell = checkerCell(w, size);
        if (mod(cell.x + cell.y, 2.0) > 0.5) {
            s.color = m.checkerColor.rgb;
            s.emission = m.checkerEmission.rgb;
        }
    }
    return s;
}

// Light j, and the material of object k.  A block read at an index that
// differs between SIMD lanes (an object's material) or that llvmpipe
// cannot prove the same for all of them (the light loop's counter, which
// it keeps per lane) is a gather: every component of every lane loaded on
// its own, through its own address.  In the default scene's frame these
// two were most of the 16% of perf's samples that fell in per-lane loads
// (tools/jit_profile.py), and the selects below made it 5% faster on
// Mesa 25.  So where a scene
// has at most 8 of them (gpu_scene.PICK_MAX) the specialised shader reads
// every light and material at a literal index, one broadcast each, and
// keeps the one asked for: a select per component and entry, cheaper than
// the gather (some 17 instructions a component against 2).  The indices
// come as literals (SCENE_LIGHT_INDICES(X), SCENE_MATERIAL_INDICES(X):
// X(1) .. X(n - 1)), not as a loop's counter, so that no driver has to
// unroll a loop to see constants.  On Mesa 22.3's llvmpipe the material
// selects made the default frame 25% slower, so there the renderer drops
// SCENE_MATERIAL_INDICES (gpu_scene.driver_defines) and the gather stays.
// The values are the same either way.
#ifdef SCENE_LIGHT_INDICES
Light pickLight(int j) {
    Light light = lights[0];
#define PICK_LIGHT(q) light.vector = j == q ? lights[q].vector : light.vector; light.radiance = j == q ? lights[q].radiance : light.radiance;
    SCENE_LIGHT_INDICES(PICK_LIGHT)
#undef PICK_LIGHT
    return light;
}
#else
Light pickLight(int j) { return lights[j]; }
#endif

#ifdef SCENE_MATERIAL_INDICES
void keepMaterialIf(bool hit, int q, inout Material m) {
    m.colorAmbient = hit ? materials[q].colorAmbient : m.colorAmbient;
    m.phong = hit ? materials[q].phong : m.phong;
    m.dielectric = hit ? materials[q].dielectric : m.dielectric;
    m.absorption = hit ? materials[q].absorption : m.absorption;
    m.emission = hit ? materials[q].emission : m.emission;
    m.checkerColor = hit ? materials[q].checkerColor : m.checkerColor;
    m.checkerEmission = hit ? materials[q].checkerEmission : m.checkerEmission;
    m.checkerOffset = hit ? materials[q].checkerOffset : m.checkerOffset;
}

Material pickMaterial(int k) {
    int index = objects[k].info.y;
    Material m = materials[0];
#define PICK_MATERIAL(q) keepMaterialIf(index == q, q, m);
    SCENE_MATERIAL_INDICES(PICK_MATERIAL)
#undef PICK_MATERIAL
    return m;
}
#else
Material pickMaterial(int k) { return materials[objects[k].info.y]; }
#endif

// The light a surface's colour C takes at p, the bracket of
// E + C * (k_a A + sum_j L_j V_j [n.l > 0] (k_d n.l + k_s max(0, r.v)^p)).
vec3 lightAt(Material m, vec3 p, vec3 n, vec3 v, uint mask) {
    vec3 lit = m.colorAmbient.a * ambient.rgb;
#ifdef HAS_LIGHTS
    float kd = m.phong.x, ks = m.phong.y;
    if (kd > 0.0 || ks > 0.0) {
        for (int j = 0; j < NUM_LIGHTS; ++j) {
            Light light = pickLight(j);
            vec3 l;
            float dist;
            if (light.vector.w > 0.5) { l = -light.vector.xyz; dist = INF; }
            else { vec3 tl = light.vector.xyz - p; dist = length(tl); l = tl / dist; }
            float ndl = dot(n, l);
            if (ndl <= 0.0) continue;
            vec3 r = 2.0 * ndl * n - l;
            // max(0, r.v)^p; pow() of a tiny or denormal base returns garbage
            // on some drivers (llvmpipe gave 2^63), and below 1e-6 the term is
            // far under one display step anyway.
            float rv = dot(r, v);
            float spec = (ks > 0.0 && rv > 1e-6) ? ks * pow(min(rv, 1.0), m.phong.z) : 0.0;
            float term = kd * ndl + spec;
            // A term of zero adds nothing whatever the light's visibility: no
            // shadow ray.  That is most of a glass's (diffuse 0, a highlight
            // of shininess 200: r.v^200 is 0 in float32 below r.v = 0.65),
            // and the shadow rays through glass cross every medium on the way.
            if (term <= 0.0) continue;
            // Leave the surface along its normal: at a grazing light a start
            // offset along l alone would not clear the hit point's error.
            // It aims at a point light from where it starts and ends short
            // of it by the light's own offset: a light on a surface (a lamp
            // on the floor, or 1e-300 above it) is not shadowed by that
            // surface, as a ray leaving a surface does not meet it again
            // (it was salt and pepper, and along l from the offset start the
            // ray passed under the light and met the floor first).
            vec3 o = p + surfaceEps(p) * n;
            vec3 ls = l;
            float reach = INF;
            if (light.vector.w <= 0.5) {
                vec3 to = light.vector.xyz - o;
                reach = length(to);
                ls = to / reach;
                reach -= surfaceEps(light.vector.xyz);
            }
            vec3 vis = shadowTransmittance(o, ls, reach, mask);
            if (maxComponent(vis) <= 0.0) continue;
            lit += light.radiance.rgb * vis * term;
        }
    }
#endif
    return lit;
}

// ---------------------------------------------------------------- the ray tree

// chain: the id of the principal chain a branch is on, -1 off it.  The
// camera ray is on the empty chain (0); at a crossing the refracted child
// continues it (the reflected one where the refracted has no weight: total
// internal reflection); every other child is off it.  The id hashes the
// crossings' objects and faces (chainStep), so rays through the same
// surfaces share it; footprint samples (lib/footprint.glsl) and the corner
// rays' chainLeaf use it.
struct Branch { vec3 o; vec3 d; vec3 w; int depth; uint mask; float chain; };

// Chains are followed only where something reads them (footprint samples,
// the adaptive first pass); elsewhere every branch has chain -1, and the
// hash below is not computed (it is per-lane integer conversion, which
// llvmpipe does lane by lane: 2% of the default scene's frame).
#if defined(FOOTPRINT_AA) || defined(ADAPTIVE_FIRST)
#define TRACK_CHAINS
#endif

// The id after a crossing of `object` through the face of outward normal n
// (its largest axis and sign), refracted or reflected: a 24-bit hash, held
// exactly by a float, never 0.
float chainStep(float chain, int object, vec3 n, bool reflected) {
#ifdef TRACK_CHAINS
    if (chain < 0.0) return -1.0;
    vec3 a = abs(n);
    int axis = a.x >= a.y && a.x >= a.z ? 0 : (a.y >= a.z ? 1 : 2);
    int face = 2 * axis + (n[axis] < 0.0 ? 1 : 0);
    uint code = uint(object) * 16u + uint(face) * 2u + (reflected ? 1u : 0u) + 1u;
    uint h = (uint(chain) * 1031u + code) & 0xFFFFFFu;
    return float(h == 0u ? 1u : h);
#else
    return -1.0;
#endif
}

// A child is followed when its weight reaches min_weight (and is not zero).
bool worthFollowing(vec3 w, float minWeight) {
    return maxComponent(w) >= minWeight && maxComponent(w) > 0.0;
}

// One node of the ray tree: adds the light it sends back along br.d to `sum`
// and returns its children, the reflected and the refracted branch (weight
// zero where there is none).
void walkNode(Branch br, inout vec3 sum, out Branch reflected, out Branch refracted) {
    reflected = Branch(vec3(0.0), vec3(0.0), vec3(0.0), 0, 0u, -1.0);
    refracted = reflected;
    uint mask = br.mask;
    vec3 atten = vec3(1.0);
    Interaction it;
    bool hit = nextInteraction(br.o, br.d, mask, atten, it);
    vec3 w = br.w * atten;
    if (!hit) {
        sum += w * skyRadiance(br.d);
#ifdef ADAPTIVE_FIRST
        if (br.chain >= 0.0) chainLeaf = vec4(0.0, 0.0, br.chain, -1.0);
#endif
        return;
    }
    RECORD_FIRST(br, it)
    if (maxComponent(w) <= 0.0) return;
    Material m = pickMaterial(it.object);
    vec3 n = dot(it.n, br.d) < 0.0 ? it.n : -it.n;     // facing the ray
    Surface s = surfaceAt(m, it.p);
#ifdef FOOTPRINT_AA
    // a ray of the principal chain on the checkered plane its pixel's
    // footprint lies on: the checker's colours mixed by their share of the
    // pixel
    bool footprint = takesFootprint(it.object, br.chain);
    vec3 pointColor = s.color;
    // (a share of 0 or 1 selects its colour exactly: mix() may round, and
    // then c(x) != c_bar would take the control variate's lighting below)
    if (footprint)
        s = footprintShare <= 0.0 ? Surface(m.colorAmbient.rgb, m.emission.rgb)
          : footprintShare >= 1.0 ? Surface(m.checkerColor.rgb, m.checkerEmission.rgb)
          : Surface(mix(m.colorAmbient.rgb, m.checkerColor.rgb, footprintShare),
                    mix(m.emission.rgb, m.checkerEmission.rgb, footprintShare));
#endif
#ifdef FOOTPRINT_AA
    // A direct footprint is a control variate (lib/footprint.glsl): plus
    // (c(x) - c_bar) (L(x) - L_ref), L_ref the lighting of the point where
    // the pixel's centre ray meets the plane (y = h camera-relative, as
    // hitPlane finds it; from the camera's medium: the same for every
    // sample).  Unbiased for any L_ref; zero where the lighting is even.
    // One call site for both lightings (a loop): a second inlined lightAt
    // cost 16-19% of a 16-sample render even where it never ran.
    bool needRef = footprint && br.chain == 0.0 && pointColor != s.color;
    vec3 lit = vec3(0.0), litRef = vec3(0.0);
    for (int k = 0; k < 2; ++k) {
        bool centre = k == 1;
        vec3 d = centre ? fpCentreDir : br.d;
        vec3 p = centre ? fpCentreDir * (objects[it.object].a.x / fpCentreDir.y) : it.p;
        vec3 l = lightAt(m, p, n, -d, centre ? uint(iparams.y) : mask);
        if (centre) litRef = l; else lit = l;
        if (!needRef) break;
    }
    sum += w * (s.emission + s.color * lit);
    if (needRef) sum += w * (pointColor - s.color) * (lit - litRef);
#else
    vec3 lit = lightAt(m, it.p, n, -br.d, mask);
    sum += w * (s.emission + s.color * lit);
#endif
#ifdef ADAPTIVE_FIRST
    // what the checker's second colour adds to the radiance where the
    // principal chain ends (0 off a checker): the adaptive flags take it
    // out where footprint samples take the checker exactly
    if (br.chain >= 0.0 && !it.dielectric) {
        firstChecker = w * ((s.emission - m.emission.rgb) + (s.color - m.colorAmbient.rgb) * lit);
        chainLeaf = vec4(it.p.xz, br.chain, float(it.object));
    }
#endif
    if (br.depth >= iparams.x) return;                  // children would exceed max_depth
#ifdef HAS_DIELECTRIC
    if (it.dielectric) {
        float n1 = iorOf(mediumOf(mask));
        float n2 = iorOf(mediumOf(it.maskAfter));
        float cosI = -dot(br.d, n);
        float cosT;
        float R = fresnelDielectric(cosI, n1, n2, cosT);
        bool tir = R >= 1.0 || m.dielectric.x <= 0.0;
        refracted = Branch(it.p, refractDir(br.d, n, n1 / n2, cosI, cosT), w * ((1.0 - R) * m.dielectric.x),
                           br.depth + 1, it.maskAfter, tir ? -1.0 : chainStep(br.chain, it.object, it.n, false));
        reflected = Branch(it.p, reflect(br.d, n), w * R, br.depth + 1, mask,
                           tir ? chainStep(br.chain, it.object, it.n, true) : -1.0);
        return;
    }
#endif
#ifdef HAS_REFLECTION
    reflected = Branch(it.p, reflect(br.d, n), w * m.phong.w, br.depth + 1, mask, -1.0);
#endif
}

// The ray tree, walked depth-first, the heavier child first (the order does
// not change the sum; where a driver cuts a walk short it leaves the lighter
// branches): a node's heavier child is walked next and the other waits on
// the stack, so a node pushes at most one branch and the stack holds
// branches of strictly increasing depth, at most max_depth - 1 of them
// (max_depth + 1 entries are more than enough).  A scene with no glass has
// chains only (no stack); one with no reflection either, the camera ray only.
//
// RESUME (Renderer.render of deep trees): Mesa's llvmpipe stops every loop
// of a shader invocation, silently, after 65535 loop iterations counted over
// all its loops together (a few thousand nodes here: the rest of the tree
// was dropped), and a GPU's watchdog ends a long draw.  So a pass traces at most
// resumeBudget nodes and writes into resumeOut where it stopped: the path
// from the camera ray to the next node, one bit per level (0: the child
// walked first, 1: the other), its length, and w = 1 (0: the tree is done).
// The next pass of the same sample traces that path again, adding nothing
// (its light is in already), rebuilds the stack on the way and goes on.
#ifdef RESUME
#ifdef ADAPTIVE
#error "RESUME is for uniform renders (its output takes location 1)"
#endif
uniform usampler2D resumeIn;   // the last pass's resumeOut (read where resumeFirst == 0)
uniform int resumeFirst;       // 1: the sample's first pass, from the camera ray
uniform int resumeBudget;      // nodes a pass traces at most
layout(location = 1) out uvec4 resumeOut;
#endif

#if defined(RESUME) || defined(CUT_CHECK)
uniform int loopProbe;         // 2 (a loop's trip count the compiler cannot know)

// Whether llvmpipe's loop limit has been reached in this invocation: from
// then on every loop stops after its first iteration, so a two-iteration
// loop runs once.  The limit counts iterations, not nodes (a node of many
// lights or objects takes hundreds), so a RESUME pass checks after every
// node and hands back the node that was cut, to be traced again (w = 2:
// Renderer then gives the passes fewer nodes); a CUT_CHECK render marks
// the pixel (-inf) and Renderer.render draws the image again in passes.
bool loopsCut() {
    int n = 0;
    for (int i = 0; i < loopProbe; ++i) ++n;
    return n < loopProbe;
}
#endif

#ifdef RESUME
// path p cut to `level` bits, then bit `level` set to `one`
uvec2 pathAt(uvec2 p, int level, bool one) {
    uint bit = one ? 1u : 0u;
    if (level < 32) {
        uint keep = level == 0 ? 0u : (0xFFFFFFFFu >> uint(32 - level));
        return uvec2((p.x & keep) | (bit << uint(level)), 0u);
    }
    uint keep = level == 32 ? 0u : (0xFFFFFFFFu >> uint(64 - level));
    return uvec2(p.x, (p.y & keep) | (bit << uint(level - 32)));
}
#endif

#ifdef HAS_DIELECTRIC
// The stack of waiting branches, one array per scalar of a Branch: an
// array indexed by a per-lane value (sp) lives in memory, where llvmpipe
// stores and loads it lane by lane, and an array of structs went through
// more of that per field than separate arrays do (2% of the default
// scene's frame).  The chain id is kept only where chains are followed.
#ifdef TRACK_CHAINS
float stackChain[STACK_SIZE];
#endif
float stackOx[STACK_SIZE], stackOy[STACK_SIZE], stackOz[STACK_SIZE];
float stackDx[STACK_SIZE], stackDy[STACK_SIZE], stackDz[STACK_SIZE];
float stackWx[STACK_SIZE], stackWy[STACK_SIZE], stackWz[STACK_SIZE];
int stackDepth[STACK_SIZE];
uint stackMask[STACK_SIZE];

// Pushes b where there is room (sp < STACK_SIZE; see radiance for why
// there always is).
void pushBranch(inout int sp, Branch b) {
    if (sp >= STACK_SIZE) return;
    stackOx[sp] = b.o.x; stackOy[sp] = b.o.y; stackOz[sp] = b.o.z;
    stackDx[sp] = b.d.x; stackDy[sp] = b.d.y; stackDz[sp] = b.d.z;
    stackWx[sp] = b.w.x; stackWy[sp] = b.w.y; stackWz[sp] = b.w.z;
    stackDepth[sp] = b.depth;
    stackMask[sp] = b.mask;
#ifdef TRACK_CHAINS
    stackChain[sp] = b.chain;
#endif
    ++sp;
}

// The last branch pushed (sp > 0), taken off.
Branch popBranch(inout int sp) {
    --sp;
    Branch b = Branch(vec3(stackOx[sp], stackOy[sp], stackOz[sp]), vec3(stackDx[sp], stackDy[sp], stackDz[sp]),
                      vec3(stackWx[sp], stackWy[sp], stackWz[sp]), stackDepth[sp], stackMask[sp], -1.0);
#ifdef TRACK_CHAINS
    b.chain = stackChain[sp];
#endif
    return b;
}

// The children a node's walk follows (n of them), the heavier one in a.
int followed(Branch reflected, Branch refracted, float minWeight, out Branch a, out Branch b) {
    bool r = worthFollowing(reflected.w, minWeight), t = worthFollowing(refracted.w, minWeight);
    bool reflectedFirst = r && (!t || maxComponent(reflected.w) > maxComponent(refracted.w));
    a = reflectedFirst ? reflected : refracted;
    b = reflectedFirst ? refracted : reflected;
    return int(r) + int(t);
}
#endif

vec3 radiance(vec3 origin, vec3 dir) {
#ifdef HAS_DIELECTRIC
    int sp = 0;     // branches waiting on the stack
#endif
    float minWeight = params.z;
    vec3 sum = vec3(0.0);
    Branch br = Branch(origin, dir, vec3(1.0), 1, uint(iparams.y), 0.0);
#ifdef RESUME
    resumeOut = uvec4(0u);
#ifdef HAS_DIELECTRIC
    uvec2 path = uvec2(0u);        // br's path
    int budget = resumeBudget;
    if (resumeFirst == 0) {
        uvec4 st = texelFetch(resumeIn, ivec2(gl_FragCoord.xy), 0);
        if (st.w == 0u) return sum;                     // done in an earlier pass
        // (st.z, a depth - 1, is below STACK_SIZE: the min only bounds the
        // loop whatever the texture holds)
        for (int level = 0; level < int(min(st.z, uint(STACK_SIZE))); ++level) {
            vec3 again = vec3(0.0);
            Branch reflected, refracted, a, b;
            walkNode(br, again, reflected, refracted);
            int n = followed(reflected, refracted, minWeight, a, b);
            bool second = ((level < 32 ? st.x >> uint(level) : st.y >> uint(level - 32)) & 1u) != 0u;
            if (second) br = b;
            else {
                if (n == 2) pushBranch(sp, b);
                br = a;
            }
        }
        // the path itself was cut: the same state again, with no light
        if (loopsCut()) {
            resumeOut = uvec4(st.xyz, 2u);
            return vec3(0.0);
        }
        path = st.xy;
    }
    vec3 sumBefore;
    uvec2 pathBefore;
    int depthBefore;
#endif
#endif
    bool walking = true;
    while (walking) {
        Branch reflected, refracted;
#if defined(RESUME) && defined(HAS_DIELECTRIC)
        if (budget-- <= 0) {
            resumeOut = uvec4(path, uint(br.depth - 1), 1u);
            return sum;
        }
        sumBefore = sum;
        pathBefore = path;
        depthBefore = br.depth;
#endif
        walkNode(br, sum, reflected, refracted);
#ifdef HAS_DIELECTRIC
        Branch a, b;
        int n = followed(reflected, refracted, minWeight, a, b);
        if (n == 2) pushBranch(sp, b);
        if (n > 0) br = a;
        else if (sp > 0) br = popBranch(sp);
        else walking = false;
#if defined(RESUME)
        // a child one level down the first way, or a waiting branch: the
        // other way at its own level
        if (n > 0) path = pathAt(path, br.depth - 2, false);
        else if (walking) path = pathAt(path, br.depth - 2, true);
        // this node was cut short by the loop limit: its light and children
        // are not to be trusted; the next pass traces it again
        if (loopsCut()) {
            resumeOut = uvec4(pathBefore, uint(depthBefore - 1), 2u);
            return sumBefore;
        }
#endif
#else
        br = reflected;
        walking = worthFollowing(reflected.w, minWeight);
#endif
    }
#if defined(RESUME) && defined(HAS_DIELECTRIC)
    // the walk itself stopped at the limit after a whole node: go on at br
    if (walking) resumeOut = uvec4(path, uint(br.depth - 1), 2u);
#endif
    return sum;
}

#ifdef VIEW_MODE
// Debug views (VIEW_MODE injected by the renderer):
//   1 first hit: (t, object index, 0), t = INF and index -1 where nothing is hit
//   2 first hit's unit outward normal (xyz), 0 where nothing is hit
//   3 cost: the number of rays (camera, reflected, refracted, shadow) traced
// "First hit" is the first geometric surface along the ray, whatever the media.
vec4 firstHit(vec3 o, vec3 d) {
    float best = INF;
    int bestK = -1;
    vec3 n = vec3(0.0), nk;
    for (int k = 0; k < NUM_OBJECTS; ++k) {
        float t = hitObject(k, o, d, 0.0, best, nk);
        if (t < best) { best = t; bestK = k; n = nk; }
    }
#if VIEW_MODE == 1
    return vec4(best, float(bestK), 0.0, 1.0);
#else
    return vec4(n, 1.0);
#endif
}
#endif

// The camera ray through offset (u, v) of pixel (i, j): i to the right, j
// downward from the top row (the spec's pinhole model).
vec3 cameraRay(vec2 ij, vec2 offset) {
    vec2 uv = (ij + offset) / imageSize;
    return normalize(camForward + (2.0 * uv.x - 1.0) * camRight + (1.0 - 2.0 * uv.y) * camUp);
}

void main() {
#ifdef FOOTPRINT_SHARE_PASS
    // the footprint mask's texel with the pixel's share in g (-1: none)
    setFootprintPixel(vec2(floor(gl_FragCoord.x), imageSize.y - 1.0 - floor(gl_FragCoord.y)));
    fragColor = vec4(texelFetch(footprintMask, ivec2(gl_FragCoord.xy), 0).r, pixelShare, 0.0, 1.0);
    return;
#endif
#ifdef ADAPTIVE_LIST
    ivec4 listed = texelFetch(pixelList, ivec2(gl_FragCoord.xy), 0);
    fragColor = vec4(0.0);
    fragMoments = vec4(0.0);
    if (listed.x < 0) return;
    int end = min(listed.w, chunkStart + chunkSize);
#ifdef FOOTPRINT_AA
    setFootprintPixel(vec2(listed.xy));
#endif
    for (int b = chunkStart; b < end; ++b) {
        vec2 offset = texelFetch(sampleOffsets, ivec2(listed.z + b, 0), 0).xy;
#ifdef FOOTPRINT_AA
        setFootprintSample(offset);
#endif
        vec3 Lb = radiance(vec3(0.0), cameraRay(vec2(listed.xy), offset)) * params.w;
        fragColor += vec4(Lb, 1.0);
        fragMoments.x += dot(Lb, Lb);
    }
#else
    vec2 ij = vec2(floor(gl_FragCoord.x), imageSize.y - 1.0 - floor(gl_FragCoord.y));
    vec3 dir = cameraRay(ij, sampleOffset);
#ifdef FOOTPRINT_AA
    setFootprintPixel(ij);
    setFootprintSample(sampleOffset);
#endif
#if defined(VIEW_MODE) && VIEW_MODE == 3
    radiance(vec3(0.0), dir);
    fragColor = vec4(float(rayCount), 0.0, 0.0, 1.0);
#elif defined(VIEW_MODE)
    fragColor = firstHit(vec3(0.0), dir);
#else
    vec3 L = radiance(vec3(0.0), dir) * params.w;
    fragColor = vec4(L, 1.0);
#ifdef CUT_CHECK
    // a tree cut short: -inf, which no radiance is (every one is >= 0) and
    // which stays negative (or NaN) through the additive blending of samples
    if (loopsCut()) fragColor.rgb = vec3(uintBitsToFloat(0xff800000u));
#endif
#ifdef ADAPTIVE
    fragMoments = vec4(dot(L, L), 0.0, 0.0, 0.0);
#endif
#ifdef ADAPTIVE_FIRST
#ifdef FOOTPRINT_AA
    // the pixel's closed-form share (-1: none), which the list passes read
    // back from the footprint mask instead of computing it again
    fragFirstHit = vec4(firstT, float(firstObject), float(rayCount), pixelShare);
#else
    fragFirstHit = vec4(firstT, float(firstObject), float(rayCount), -1.0);
#endif
    // a: how this pixel's footprint samples take the checker: 2 exactly
    // over the pixel, 1 along their rows, 0 not at all (point samples)
#ifdef FOOTPRINT_AA
    float kind = pixelShare >= 0.0 ? 2.0 : (footprintShare >= 0.0 ? 1.0 : 0.0);
#else
    float kind = 0.0;
#endif
    fragFirstChecker = vec4(firstChecker * params.w, kind);
    fragChainLeaf = chainLeaf;
#endif
#endif
#endif  // ADAPTIVE_LIST
}
