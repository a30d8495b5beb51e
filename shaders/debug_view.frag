#version 330 core
// Debug views (VIEW_MODE injected by the renderer, Renderer.variant):
//   1 first hit: (t, object index, 0), t = INF and index -1 where nothing is hit
//   2 first hit's unit outward normal (xyz), 0 where nothing is hit
//   3 cost: the number of rays (camera, reflected, refracted, shadow) traced
// "First hit" is the first geometric surface along the ray, whatever the media.
#if !defined(VIEW_MODE) || VIEW_MODE < 1 || VIEW_MODE > 3
#error "debug_view.frag needs VIEW_MODE 1, 2 or 3"
#endif

#include "lib/tree.glsl"

out vec4 fragColor;

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

// The view's value for the camera ray d.
vec4 debugView(vec3 d) {
#if VIEW_MODE == 3
    radiance(vec3(0.0), d);
    return vec4(float(rayCount), 0.0, 0.0, 1.0);
#else
    return firstHit(vec3(0.0), d);
#endif
}

void main() {
    vec2 ij = fragmentPixel();
    vec3 dir = cameraRay(ij, sampleOffset);
    footprintPixel(ij);
    footprintSample(sampleOffset);
    fragColor = debugView(dir);
}
