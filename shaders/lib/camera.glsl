// The camera (the spec's pinhole model) and the pixel a fragment draws.

uniform vec2 imageSize;        // W, H of the whole image (tiles use the scissor)
uniform vec2 sampleOffset;     // (u, v) in [0,1)^2 inside the pixel, v downward
uniform vec3 camForward;       // f
uniform vec3 camRight;         // right * tan(fov/2) * W/H
uniform vec3 camUp;            // up * tan(fov/2)

// The image pixel (i, j) this fragment draws: i to the right, j downward
// from the top row.
vec2 fragmentPixel() {
    return vec2(floor(gl_FragCoord.x), imageSize.y - 1.0 - floor(gl_FragCoord.y));
}

// The camera ray through offset (u, v) of pixel (i, j): i to the right, j
// downward from the top row (the spec's pinhole model).
vec3 cameraRay(vec2 ij, vec2 offset) {
    vec2 uv = (ij + offset) / imageSize;
    return normalize(camForward + (2.0 * uv.x - 1.0) * camRight + (1.0 - 2.0 * uv.y) * camUp);
}
