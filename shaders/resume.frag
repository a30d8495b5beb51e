#version 330 core
// A resumable pass of the render (Renderer.render of deep trees, and where
// a CUT_CHECK render found a tree cut short): one sample of every pixel,
// at most resumeBudget nodes of its ray tree, and where the walk stopped
// for the next pass (lib/resume.glsl).  Uniform renders only: the state
// takes location 1, the adaptive passes' moments.

#include "lib/resume.glsl"

out vec4 fragColor;
layout(location = 1) out uvec4 resumeOut;

void main() {
    vec2 ij = fragmentPixel();
    vec3 dir = cameraRay(ij, sampleOffset);
    footprintPixel(ij);
    footprintSample(sampleOffset);
    vec3 L = resumedRadiance(vec3(0.0), dir, resumeOut) * params.w;
    fragColor = vec4(L, 1.0);
}
