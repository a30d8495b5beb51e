#version 330 core
// The footprint share pass (AdaptiveSampler.share_pass): no tracing, each
// pixel's closed-form share only, which the footprint samples of a uniform
// render then read (FOOTPRINT_SHARES, lib/footprint.glsl).

#include "lib/scene_block.glsl"
#include "lib/camera.glsl"
#include "lib/checker.glsl"
#include "lib/footprint.glsl"

out vec4 fragColor;

void main() {
    // the footprint mask's texel with the pixel's share in g (-1: none)
    setFootprintPixel(fragmentPixel());
    fragColor = vec4(texelFetch(footprintMask, ivec2(gl_FragCoord.xy), 0).r, pixelShare, 0.0, 1.0);
}
