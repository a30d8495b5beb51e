#version 330 core
// The viewer's display pass: the accumulated samples to the window.
//
// accumTex holds the sum of the samples traced so far (rgb) and their number
// (alpha: every sample writes alpha 1 under additive blending), at the full
// framebuffer resolution, so a pass that is only partly done still divides
// each pixel by its own count.  Where no full-resolution sample has landed
// yet, the latest reduced-resolution preview (previewTex, one sample per
// pixel, in its lower-left previewUsed fraction) is shown, upscaled
// bilinearly.  Then the spec's display encoding: clamp to [0,1] and the sRGB
// curve; the 8-bit framebuffer rounds to round(255 v).

uniform sampler2D accumTex;
uniform sampler2D previewTex;
uniform vec2 outSize;          // size of the output viewport in pixels
uniform vec2 accumSize;        // size of accumTex (equal to outSize, unless resizing)
uniform vec2 previewUsed;      // (pw / W, ph / H): the part of previewTex the preview fills
uniform vec2 previewTexel;     // 1 / size of previewTex
uniform int hasPreview;        // 0: no preview yet (show black where accum is empty)
// DISPLAY_MODE 4: an adaptive round in flight.  roundSums is its pixel
// list's target (sum of the round's new samples so far, count in alpha, at
// list texel k = (k mod width, k / width)); roundTexel gives each pixel's k,
// or -1 where the round does not sample the pixel.
uniform sampler2D roundSums;
uniform isampler2D roundTexel;

out vec4 fragColor;

vec3 srgbEncode(vec3 x) {
    x = clamp(x, 0.0, 1.0);
    vec3 lo = 12.92 * x;
    vec3 hi = 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055;
    return mix(hi, lo, lessThanEqual(x, vec3(0.0031308)));
}

// DISPLAY_MODE (a define, one program each): 0 accumulated samples, with the
// preview where a pixel has none yet; 1 the preview only (used to encode the
// preview once, at its own resolution, into an 8-bit texture); 2 the
// accumulated samples only (every pixel has one); 3 the encoded preview,
// scaled up (nothing accumulated yet: while things move); 4 as 2, plus the
// samples an adaptive round has traced so far.  The variants save
// a software renderer the texture reads and the arithmetic it does not need.
#ifndef DISPLAY_MODE
#define DISPLAY_MODE 0
#endif

vec3 previewColor(vec2 uv) {
    if (hasPreview == 0) return vec3(0.0);
    // stay inside the preview's texels so bilinear filtering never reads the unused part
    vec2 p = clamp(uv * previewUsed, 0.5 * previewTexel, previewUsed - 0.5 * previewTexel);
    vec4 pv = textureLod(previewTex, p, 0.0);  // no mipmaps: no derivatives needed
    return pv.rgb / max(pv.a, 1.0);
}

void main() {
    vec2 uv = gl_FragCoord.xy / outSize;             // 0..1 over the output
#if DISPLAY_MODE == 3
    vec2 p = clamp(uv * previewUsed, 0.5 * previewTexel, previewUsed - 0.5 * previewTexel);
    fragColor = vec4(textureLod(previewTex, p, 0.0).rgb, 1.0);  // already encoded
    return;
#elif DISPLAY_MODE == 1
    vec3 c = previewColor(uv);
#else
    ivec2 texel = ivec2(floor(uv * accumSize));
    vec4 acc = texelFetch(accumTex, clamp(texel, ivec2(0), ivec2(accumSize) - 1), 0);
#if DISPLAY_MODE == 4
    int k = texelFetch(roundTexel, clamp(texel, ivec2(0), ivec2(accumSize) - 1), 0).r;
    if (k >= 0) {
        int lw = textureSize(roundSums, 0).x;
        acc += texelFetch(roundSums, ivec2(k % lw, k / lw), 0);
    }
#endif
#if DISPLAY_MODE == 2 || DISPLAY_MODE == 4
    vec3 c = acc.rgb / max(acc.a, 1.0);
#else
    vec3 c = acc.a > 0.0 ? acc.rgb / acc.a : previewColor(uv);
#endif
#endif
#if DISPLAY_MODE != 3
    fragColor = vec4(srgbEncode(c), 1.0);
#endif
}
