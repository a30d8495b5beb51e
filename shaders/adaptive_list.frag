#version 330 core
// The adaptive sampler's list passes (viewer/adaptive/, add_samples).
// Fragment (x, y) of a small framebuffer traces samples of the image pixel
// (i, j) stored at (x, y) of pixelList with its first sample index s0 and
// count n (i < 0: padding, nothing traced): samples s0 + chunkStart .. s0 +
// min(n, chunkStart + chunkSize) - 1, at the offsets stored at texel
// (sample, 0) of sampleOffsets.  So only the pixels that still need samples
// are drawn and every SIMD lane does useful work.  Every sample adds (L, 1)
// to attachment 0 and (L.L, 0, 0, 0) to attachment 1, so that the sums
// give each pixel's mean and spread.

#include "lib/tree.glsl"

out vec4 fragColor;
layout(location = 1) out vec4 fragMoments;

uniform isampler2D pixelList;
uniform sampler2D sampleOffsets;
uniform int chunkStart;
uniform int chunkSize;

void main() {
    ivec4 listed = texelFetch(pixelList, ivec2(gl_FragCoord.xy), 0);
    fragColor = vec4(0.0);
    fragMoments = vec4(0.0);
    if (listed.x < 0) return;
    int end = min(listed.w, chunkStart + chunkSize);
    footprintPixel(vec2(listed.xy));
    for (int b = chunkStart; b < end; ++b) {
        vec2 offset = texelFetch(sampleOffsets, ivec2(listed.z + b, 0), 0).xy;
        footprintSample(offset);
        vec3 Lb = radiance(vec3(0.0), cameraRay(vec2(listed.xy), offset)) * params.w;
        fragColor += vec4(Lb, 1.0);
        fragMoments.x += dot(Lb, Lb);
    }
}
