// The ray tree in resumable passes (resume.frag; Renderer.render of deep
// trees), over the walk of lib/tree.glsl.
//
// Mesa's llvmpipe stops every loop of a shader invocation, silently, after
// 65535 loop iterations counted over all its loops together (a few
// thousand nodes here: the rest of the tree was dropped), and a GPU's
// watchdog ends a long draw.  So a pass traces at most resumeBudget nodes
// and writes into its state output (resumeOut) where it stopped: the path
// from the camera ray to the next node, one bit per level (0: the child
// walked first, 1: the other), its length, and w = 1 (0: the tree is done).
// The next pass of the same sample traces that path again, adding nothing
// (its light is in already), rebuilds the stack on the way and goes on.

#include "tree.glsl"
#include "loop_limit.glsl"

uniform usampler2D resumeIn;   // the last pass's resumeOut (read where resumeFirst == 0)
uniform int resumeFirst;       // 1: the sample's first pass, from the camera ray
uniform int resumeBudget;      // nodes a pass traces at most

#ifdef HAS_DIELECTRIC
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

// The next node of the walk after the path `st` (st.z levels of the bits
// st.xy) from the camera ray, traced again without its light, with the
// stack rebuilt on the way (the path is where an earlier pass stopped).
void replayPath(uvec4 st, inout Branch br, inout int sp, float minWeight) {
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
}
#endif

// radiance(origin, dir) of this pass's share of the tree, and in `state`
// where the walk stopped (see above; uvec4(0): the tree is done).  A scene
// with no glass has no stack to resume: its tree (a chain) in one pass.
vec3 resumedRadiance(vec3 origin, vec3 dir, out uvec4 state) {
    state = uvec4(0u);
#ifndef HAS_DIELECTRIC
    return radiance(origin, dir);
#else
    int sp = 0;     // branches waiting on the stack
    float minWeight = params.z;
    vec3 sum = vec3(0.0);
    Branch br = cameraBranch(origin, dir);
    uvec2 path = uvec2(0u);        // br's path
    int budget = resumeBudget;
    if (resumeFirst == 0) {
        uvec4 st = texelFetch(resumeIn, ivec2(gl_FragCoord.xy), 0);
        if (st.w == 0u) return sum;                     // done in an earlier pass
        replayPath(st, br, sp, minWeight);
        // the path itself was cut: the same state again, with no light
        if (loopsCut()) {
            state = uvec4(st.xyz, 2u);
            return vec3(0.0);
        }
        path = st.xy;
    }
    vec3 sumBefore;
    uvec2 pathBefore;
    int depthBefore;
    bool walking = true;
    while (walking) {
        if (budget-- <= 0) {
            state = uvec4(path, uint(br.depth - 1), 1u);
            return sum;
        }
        sumBefore = sum;
        pathBefore = path;
        depthBefore = br.depth;
        int n = walkStep(br, sp, sum, minWeight, walking);
        // a child one level down the first way, or a waiting branch: the
        // other way at its own level
        if (n > 0) path = pathAt(path, br.depth - 2, false);
        else if (walking) path = pathAt(path, br.depth - 2, true);
        // this node was cut short by the loop limit: its light and children
        // are not to be trusted; the next pass traces it again
        if (loopsCut()) {
            state = uvec4(pathBefore, uint(depthBefore - 1), 2u);
            return sumBefore;
        }
    }
    // the walk itself stopped at the limit after a whole node: go on at br
    if (walking) state = uvec4(path, uint(br.depth - 1), 2u);
    return sum;
#endif
}
