#version 330 core
// The adaptive sampler's first pass (viewer/adaptive/, first_pass and
// corner_pass): sample 0 of the whole image (or of the grid of pixel
// corners), plus the first interaction of each camera ray.  Like every
// adaptive sample it adds (L, 1) to attachment 0 and (L.L, 0, 0, 0) to
// attachment 1, so that the sums give each pixel's mean and spread.

// the first interaction, the principal chain's end and the ray count are
// recorded (lib/sample.glsl); chains are followed (lib/tree.glsl)
#define ADAPTIVE_FIRST

#include "lib/tree.glsl"

out vec4 fragColor;
layout(location = 1) out vec4 fragMoments;
layout(location = 2) out vec4 fragFirstHit;     // (t, object index, rays, pixelShare); (INF, -1) for the sky
layout(location = 3) out vec4 fragFirstChecker; // rgb: firstChecker (exposure applied); a: footprint kind
layout(location = 4) out vec4 fragChainLeaf;    // chainLeaf

// the pixel's closed-form share (-1: none), which the list passes read
// back from the footprint mask instead of computing it again
float firstPixelShare() {
#ifdef FOOTPRINT_AA
    return pixelShare;
#else
    return -1.0;
#endif
}

// how this pixel's footprint samples take the checker: 2 exactly over the
// pixel, 1 along their rows, 0 not at all (point samples)
float footprintKind() {
#ifdef FOOTPRINT_AA
    return pixelShare >= 0.0 ? 2.0 : (footprintShare >= 0.0 ? 1.0 : 0.0);
#else
    return 0.0;
#endif
}

void main() {
    vec2 ij = fragmentPixel();
    vec3 dir = cameraRay(ij, sampleOffset);
    footprintPixel(ij);
    footprintSample(sampleOffset);
    vec3 L = radiance(vec3(0.0), dir) * params.w;
    fragColor = vec4(L, 1.0);
    fragMoments = vec4(dot(L, L), 0.0, 0.0, 0.0);
    fragFirstHit = vec4(firstT, float(firstObject), float(rayCount), firstPixelShare());
    fragFirstChecker = vec4(firstChecker * params.w, footprintKind());
    fragChainLeaf = chainLeaf;
}
