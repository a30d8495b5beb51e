// glassray: Whitted-style backward ray tracing of one pixel sample.
//
// Light transport is the one defined in shared/spec/scene-format.md: Phong
// with shadows, mirror reflection, exact Fresnel splitting into reflected and
// refracted branches (TIR included), nested media by object priority and
// Beer-Lambert absorption, with a real ray tree walked depth-first on an
// explicit stack (GLSL has no recursion).
//
// The shared library of every pass that traces (render.frag, resume.frag,
// adaptive_first.frag, adaptive_list.frag, debug_view.frag): an entry file
// defines its pass's macros (ADAPTIVE_FIRST), includes this file and has a
// main() of its own.  radiance() below is one sample's ray tree.

#include "scene_block.glsl"
#include "intersect.glsl"
#include "optics.glsl"
#include "sky.glsl"
#include "camera.glsl"
#include "checker.glsl"
#include "sample.glsl"
#include "walk.glsl"
#include "shade.glsl"

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

// One step of the walk: traces node br (its light into sum) and moves br on
// to the next node, the heavier child (the other one waits on the stack) or
// else the branch on top of the stack; walking becomes false where the tree
// is done.  Returns the number of children followed.
int walkStep(inout Branch br, inout int sp, inout vec3 sum, float minWeight, inout bool walking) {
    Branch reflected, refracted;
    walkNode(br, sum, reflected, refracted);
    Branch a, b;
    int n = followed(reflected, refracted, minWeight, a, b);
    if (n == 2) pushBranch(sp, b);
    if (n > 0) br = a;
    else if (sp > 0) br = popBranch(sp);
    else walking = false;
    return n;
}
#endif

// The camera ray's branch: the root of the tree.
Branch cameraBranch(vec3 origin, vec3 dir) {
    return Branch(origin, dir, vec3(1.0), 1, uint(iparams.y), 0.0);
}

// The ray tree, walked depth-first, the heavier child first (the order does
// not change the sum; where a driver cuts a walk short it leaves the lighter
// branches): a node's heavier child is walked next and the other waits on
// the stack, so a node pushes at most one branch and the stack holds
// branches of strictly increasing depth, at most max_depth - 1 of them
// (max_depth + 1 entries are more than enough).  A scene with no glass has
// chains only (no stack); one with no reflection either, the camera ray only.
// (RESUME: resumedRadiance, lib/resume.glsl, walks the same tree in passes.)
vec3 radiance(vec3 origin, vec3 dir) {
#ifdef HAS_DIELECTRIC
    int sp = 0;     // branches waiting on the stack
#endif
    float minWeight = params.z;
    vec3 sum = vec3(0.0);
    Branch br = cameraBranch(origin, dir);
    bool walking = true;
    while (walking) {
#ifdef HAS_DIELECTRIC
        walkStep(br, sp, sum, minWeight, walking);
#else
        Branch reflected, refracted;
        walkNode(br, sum, reflected, refracted);
        br = reflected;
        walking = worthFollowing(reflected.w, minWeight);
#endif
    }
    return sum;
}
