#version 330 core
// The render pass: one sample of every pixel of the image or tile
// (Renderer.render, draw_sample), its radiance times the exposure.
// CUT_CHECK (scenes with glass): a pixel whose tree llvmpipe's loop limit
// cut short is marked (-inf) and Renderer.render draws the image again in
// resumable passes (resume.frag).

#include "lib/tree.glsl"
#include "lib/loop_limit.glsl"

out vec4 fragColor;

void main() {
    vec2 ij = fragmentPixel();
    vec3 dir = cameraRay(ij, sampleOffset);
    footprintPixel(ij);
    footprintSample(sampleOffset);
    vec3 L = radiance(vec3(0.0), dir) * params.w;
    fragColor = vec4(L, 1.0);
#ifdef CUT_CHECK
    // a tree cut short: -inf, which no radiance is (every one is >= 0) and
    // which stays negative (or NaN) through the additive blending of samples
    if (loopsCut()) fragColor.rgb = vec3(uintBitsToFloat(0xff800000u));
#endif
}
