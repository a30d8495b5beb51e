#version 330 core
// The viewer's selection outline, drawn over the displayed image with
// blending (the window's own pass, like display.frag; never in an image
// that glassray saves with P or renders).
//
// idTex holds, per pixel of the traced image, what debug_view.frag's
// VIEW_MODE 1 writes: (t, object index) of the first surface the camera ray
// meets, index -1 for the sky.  A window pixel is on the outline when the
// pixel it shows and one within `radius` pixels of it disagree on whether
// they show the selected object: a band `radius` wide on each side of the
// object's silhouette, drawn wherever that silhouette is seen, so an object
// seen through glass is outlined where the glass is not in front of it.
// Invariant: with nothing selected the viewer does not draw this pass, so
// the window shows display.frag's pixels unchanged.

uniform sampler2D idTex;
uniform vec2 outSize;      // the output viewport in pixels
uniform float selected;    // the selected object's index
uniform vec3 outlineColor; // display colour (sRGB-encoded already)
uniform int radius;        // the band's half width in window pixels

out vec4 fragColor;

bool isSelected(ivec2 p) {
    ivec2 size = textureSize(idTex, 0);
    p = clamp(p, ivec2(0), size - 1);
    return abs(texelFetch(idTex, p, 0).g - selected) < 0.5;
}

void main() {
    ivec2 size = textureSize(idTex, 0);
    vec2 scale = vec2(size) / outSize;                 // 1 unless the window is resizing
    ivec2 p = ivec2(floor(gl_FragCoord.xy * scale));
    bool here = isSelected(p);
    bool edge = false;
    for (int dy = -radius; dy <= radius; ++dy) {       // radius <= 3: at most 49 reads
        for (int dx = -radius; dx <= radius; ++dx) {
            if (isSelected(ivec2(floor((gl_FragCoord.xy + vec2(dx, dy)) * scale))) != here) edge = true;
        }
    }
    if (!edge) discard;
    // the object's own side of the band opaque, the outer side half covered
    fragColor = vec4(outlineColor, here ? 1.0 : 0.55);
}
