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

#if defined(VIEW_MODE) && VIEW_MODE == 3
int rayCount = 0;           // the cost view: rays traced for this pixel sample
#define COUNT_RAY() (++rayCount)
#else
#define COUNT_RAY()
#endif

// ---------------------------------------------------------------- media

// The medium is the first transparent object (lowest slot, slots follow the
// order of `objects`) whose solid holds the point; -1 is air.
int mediumOf(uint mask) {
    for (int s = 0; s < NUM_TRANSPARENT; ++s)
        if ((mask & (1u << uint(s))) != 0u) return s;
    return -1;
}

float iorOf(int medium) {
    return medium < 0 ? 1.0 : materials[media[medium].y].dielectric.y;
}

vec3 absorptionOf(int medium) {
    return medium < 0 ? vec3(0.0) : materials[media[medium].y].absorption.rgb;
}

// Offsets for leaving a surface: relative to the magnitude of the point (the
// float32 error of a hit point grows with it) plus a small absolute floor tied
// to the scene's size; both far below the thinnest wall.
float surfaceEps(vec3 p) {
    vec3 a = abs(p);
    return params.x + params.y * max(a.x, max(a.y, a.z));
}

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
    for (int pass = 0; pass < 2 * NUM_OBJECTS + 2; ++pass) {
        float tmin = surfaceEps(o);
        float tk[OBJECTS_LEN];
        float tNear = INF;
        vec3 unused;
        for (int k = 0; k < NUM_OBJECTS; ++k) {
            tk[k] = hitObject(k, o, d, tmin, INF, unused);
            tNear = min(tNear, tk[k]);
        }
        vec3 a = absorptionOf(mediumOf(mask));
        if (tNear >= INF) {
            atten *= exp(-a * INF);     // escaping through an absorbing medium: nothing left
            return false;
        }
        vec3 p = o + tNear * d;
        float tGroup = tNear + surfaceEps(p);
        int opaque = -1;
        float tOpaque = INF;
        for (int k = 0; k < NUM_OBJECTS; ++k)
            if (objects[k].info.w < 0 && tk[k] <= tGroup && tk[k] < tOpaque) { opaque = k; tOpaque = tk[k]; }
        if (opaque >= 0) {
            atten *= exp(-a * tOpaque);
            it.p = o + tOpaque * d; it.object = opaque; it.dielectric = false;
            hitObject(opaque, o, d, tmin, INF, it.n);
            return true;
        }
        atten *= exp(-a * tNear);
#ifdef HAS_DIELECTRIC
        // Which transparent solids hold the point just past the crossing.
        vec3 probe = p + 2.0 * surfaceEps(p) * d;
        uint after = mask;
        int first = -1;
        for (int k = 0; k < NUM_OBJECTS; ++k) {
            int slot = objects[k].info.w;
            if (slot >= 0 && tk[k] <= tGroup) {
                uint bit = 1u << uint(slot);
                after = insideObject(k, probe) ? (after | bit) : (after & ~bit);
                if (first < 0) first = k;
            }
        }
        if (mediumOf(after) != mediumOf(mask)) {
            it.p = p; it.object = first; it.dielectric = true; it.maskAfter = after;
            hitObject(first, o, d, tmin, INF, it.n);
            return true;
        }
        mask = after;
#endif
        o = p;
    }
    return false;   // pathological stack of coincident surfaces: treat as escaped
}

// Fraction of light j that reaches p (no refraction on shadow rays): 0 at an
// opaque blocker, transparency at every transparent interaction, absorption
// along every stretch inside a medium.
vec3 shadowTransmittance(vec3 p, vec3 l, float dist, uint mask) {
    COUNT_RAY();
    vec3 v = vec3(1.0);
    vec3 o = p;
    float left = dist;
    for (int pass = 0; pass < 2 * NUM_OBJECTS + 2; ++pass) {
        float tmin = surfaceEps(o);
        float tk[OBJECTS_LEN];
        float tNear = INF;
        vec3 unused;
        for (int k = 0; k < NUM_OBJECTS; ++k) {
            tk[k] = hitObject(k, o, l, tmin, left, unused);
            // any opaque surface before the light blocks it: stop at the first
            if (tk[k] < left && objects[k].info.w < 0) return vec3(0.0);
            tNear = min(tNear, tk[k]);
        }
        vec3 a = absorptionOf(mediumOf(mask));
        if (tNear >= left) return v * exp(-a * min(left, INF));
        vec3 q = o + tNear * l;
        float tGroup = tNear + surfaceEps(q);
        v *= exp(-a * tNear);
#ifdef HAS_DIELECTRIC
        vec3 probe = q + 2.0 * surfaceEps(q) * l;
        uint after = mask;
        int first = -1;
        for (int k = 0; k < NUM_OBJECTS; ++k) {
            int slot = objects[k].info.w;
            if (slot >= 0 && tk[k] <= tGroup) {
                uint bit = 1u << uint(slot);
                after = insideObject(k, probe) ? (after | bit) : (after & ~bit);
                if (first < 0) first = k;
            }
        }
        if (mediumOf(after) != mediumOf(mask)) v *= materials[objects[first].info.y].dielectric.x;
        mask = after;
#endif
        if (maxComponent(v) <= 0.0) return vec3(0.0);
        o = q;
        left -= tNear;
    }
    return v;
}

// ---------------------------------------------------------------- shading

struct Surface { vec3 color; vec3 emission; };

// The checker rule: parity of floor(x/s) + floor(z/s) in world x, z.  The
// eye's world position modulo 2s is added back (the pattern repeats every 2s).
Surface surfaceAt(Material m, vec3 p) {
    Surface s;
    s.color = m.colorAmbient.rgb;
    s.emission = m.emission.rgb;
    if (m.dielectric.z > 0.5) {
        float size = m.dielectric.w;
        vec2 w = p.xz + m.checkerOffset.xy;
        if (mod(floor(w.x / size) + floor(w.y / size), 2.0) > 0.5) {
            s.color = m.checkerColor.rgb;
            s.emission = m.checkerEmission.rgb;
        }
    }
    return s;
}

// E + C * (k_a A + sum_j L_j V_j [n.l > 0] (k_d n.l + k_s max(0, r.v)^p))
vec3 shadeLocal(Material m, Surface s, vec3 p, vec3 n, vec3 v, uint mask) {
    vec3 lit = m.colorAmbient.a * ambient.rgb;
#ifdef HAS_LIGHTS
    float kd = m.phong.x, ks = m.phong.y;
    if (kd > 0.0 || ks > 0.0) {
        for (int j = 0; j < NUM_LIGHTS; ++j) {
            Light light = lights[j];
            vec3 l;
            float dist;
            if (light.vector.w > 0.5) { l = -light.vector.xyz; dist = INF; }
            else { vec3 tl = light.vector.xyz - p; dist = length(tl); l = tl / dist; }
            float ndl = dot(n, l);
            if (ndl <= 0.0) continue;
            // Leave the surface along its normal: at a grazing light a start
            // offset along l alone would not clear the hit point's error.
            vec3 vis = shadowTransmittance(p + surfaceEps(p) * n, l, dist, mask);
            if (maxComponent(vis) <= 0.0) continue;
            vec3 r = 2.0 * ndl * n - l;
            // max(0, r.v)^p; pow() of a tiny or denormal base returns garbage
            // on some drivers (llvmpipe gave 2^63), and below 1e-6 the term is
            // far under one display step anyway.
            float rv = dot(r, v);
            float spec = (ks > 0.0 && rv > 1e-6) ? ks * pow(min(rv, 1.0), m.phong.z) : 0.0;
            lit += light.radiance.rgb * vis * (kd * ndl + spec);
        }
    }
#endif
    return s.emission + s.color * lit;
}

// ---------------------------------------------------------------- the ray tree

struct Branch { vec3 o; vec3 d; vec3 w; int depth; uint mask; };

vec3 radiance(vec3 origin, vec3 dir) {
    Branch stack[STACK_SIZE];
    int sp = 0;
    stack[sp++] = Branch(origin, dir, vec3(1.0), 1, uint(iparams.y));
    float minWeight = params.z;
    int maxDepth = iparams.x;
    vec3 sum = vec3(0.0);
    while (sp > 0) {
        Branch br = stack[--sp];
        uint mask = br.mask;
        vec3 atten = vec3(1.0);
        Interaction it;
        bool hit = nextInteraction(br.o, br.d, mask, atten, it);
        vec3 w = br.w * atten;
        if (!hit) { sum += w * skyRadiance(br.d); continue; }
        if (maxComponent(w) <= 0.0) continue;
        Material m = materials[objects[it.object].info.y];
        vec3 n = dot(it.n, br.d) < 0.0 ? it.n : -it.n;     // facing the ray
        Surface s = surfaceAt(m, it.p);
        sum += w * shadeLocal(m, s, it.p, n, -br.d, mask);
        if (br.depth >= maxDepth) continue;                 // children would exceed max_depth
        vec3 mirror = reflect(br.d, n);
#ifdef HAS_DIELECTRIC
        if (it.dielectric) {
            float n1 = iorOf(mediumOf(mask));
            float n2 = iorOf(mediumOf(it.maskAfter));
            float cosI = -dot(br.d, n);
            float cosT;
            float R = fresnelDielectric(cosI, n1, n2, cosT);
            vec3 wt = w * ((1.0 - R) * m.dielectric.x);
            vec3 wr = w * R;
            // Push refraction first so reflection is walked first; the order
            // does not change the sum.
            if (maxComponent(wt) >= minWeight && maxComponent(wt) > 0.0 && sp < STACK_SIZE)
                stack[sp++] = Branch(it.p, refractDir(br.d, n, n1 / n2, cosI, cosT), wt, br.depth + 1, it.maskAfter);
            if (maxComponent(wr) >= minWeight && maxComponent(wr) > 0.0 && sp < STACK_SIZE)
                stack[sp++] = Branch(it.p, mirror, wr, br.depth + 1, mask);
            continue;
        }
#endif
#ifdef HAS_REFLECTION
        vec3 wr = w * m.phong.w;
        if (maxComponent(wr) >= minWeight && maxComponent(wr) > 0.0 && sp < STACK_SIZE)
            stack[sp++] = Branch(it.p, mirror, wr, br.depth + 1, mask);
#endif
    }
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

void main() {
    // Pixel (i, j): i to the right, j downward from the top row.
    vec2 ij = vec2(floor(gl_FragCoord.x), imageSize.y - 1.0 - floor(gl_FragCoord.y));
    vec2 uv = (ij + sampleOffset) / imageSize;
    vec3 dir = normalize(camForward + (2.0 * uv.x - 1.0) * camRight + (1.0 - 2.0 * uv.y) * camUp);
#if defined(VIEW_MODE) && VIEW_MODE == 3
    radiance(vec3(0.0), dir);
    fragColor = vec4(float(rayCount), 0.0, 0.0, 1.0);
#elif defined(VIEW_MODE)
    fragColor = firstHit(vec3(0.0), dir);
#else
    vec3 L = radiance(vec3(0.0), dir) * params.w;
    fragColor = vec4(L, 1.0);
#endif
}
