// Following one ray (or shadow ray) through the scene: the sweeps over the
// objects, the media a point lies in (nested by object priority, with
// Beer-Lambert absorption), a ray's next interaction and a shadow ray's
// transmittance.

// ---------------------------------------------------------------- the objects

// FOR_EACH_OBJECT(X) expands to X(k, shape, slot) for every object k (slot:
// its transparent slot, -1 for an opaque object) and FOR_EACH_MEDIUM(X) to
// X(slot, k, shape) for every transparent object in slot order.  In the
// specialised shader both are straight lines of literal arguments
// (SCENE_OBJECTS and SCENE_MEDIA from viewer/gpu/packing.py): every object test
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
// objects plus 2 (gpu/packing.py max_passes); the generic one the bound for
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
