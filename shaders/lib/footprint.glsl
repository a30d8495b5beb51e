// Footprint samples (viewer/adaptive.py): the checker of a plane
// box-filtered over a pixel's square, exactly, instead of point-sampled.
//
// Texel (i, H - 1 - j) of footprintMask holds (k + 1) / 255 where the four
// corner rays of pixel (i, j) meet checkered plane k first (0: not so).
// The directions that meet a plane form a convex set, so every ray through
// the pixel's square meets plane k, unless another object pokes in between
// the corners (a sample that meets that object first stays a point sample).
// There a camera ray that meets plane k takes as its colour the checker's
// two colours mixed by their exact shares of the pixel's square in image
// space (the box filter); its lighting stays its own.
//
// The camera ray through (i + u, j + v) is pixD00 + u pixEu + v pixEv
// (unnormalised, linear in u and v).  A world coordinate a on the plane
// y = h (camera-relative) exceeds b exactly where D_a - (b / h) D_y > 0,
// since the ray meets the plane at t = h / D_y > 0: every checker line is a
// straight line in (u, v), and the share of the square beyond it has a
// closed form.
//
// Cost: the shares are computed once per pixel (setFootprintPixel) and
// once per sample only where the closed form is out of reach (the row
// fallback).  On a SIMD rasteriser every lane runs every branch, so each
// loop's trip count is 0 in the lanes that do not need it.

uniform sampler2D footprintMask;
int footprintObject = -1;     // k, or -1: this pixel takes point samples
float pixelShare = -1.0;      // the closed form's share (-1: none)
float footprintShare = -1.0;  // this sample's share (-1: a point sample)
vec3 pixD00, pixEu, pixEv;

// More products of crossing lines than this (checker corners inside the
// pixel), or more lines: no closed form; the sample's row is integrated.
#define MAX_PIXEL_CORNERS 16
#define MAX_PIXEL_LINES 32
// More lines than this along one row: a point sample (a checker that fine
// is where the plane meets the horizon).
#define MAX_ROW_CROSSINGS 24

// \int_0^1 clamp(alpha w + beta, 0, 1) dw, exactly: the pieces below 0,
// between and above 1 found by where the line crosses 0 and 1 (no
// difference quotient, so a line nearly parallel to an axis loses nothing).
float clampedRampIntegral(float alpha, float beta) {
    if (alpha < 0.0) { beta += alpha; alpha = -alpha; }    // w -> 1 - w
    if (alpha == 0.0) return clamp(beta, 0.0, 1.0);
    float a = clamp(-beta / alpha, 0.0, 1.0), b = clamp((1.0 - beta) / alpha, 0.0, 1.0);
    return (b - a) * (0.5 * alpha * (a + b) + beta) + (1.0 - b);
}

// The area of {(u, v) in [0, 1]^2 : l . (u, v, 1) > 0}: along the axis of
// the larger coefficient the covered length is a clamped linear function of
// the other coordinate.
float halfSquareArea(vec3 l) {
    vec3 m = abs(l.x) >= abs(l.y) ? l : l.yxz;
    if (m.x == 0.0) return m.z > 0.0 ? 1.0 : 0.0;
    float alpha = m.y / m.x, beta = m.z / m.x;
    return m.x > 0.0 ? clampedRampIntegral(alpha, 1.0 + beta) : clampedRampIntegral(-alpha, -beta);
}

// The area of {l1 > 0} and {l2 > 0} in [0, 1]^2: the square clipped by both
// half-planes (Sutherland-Hodgman: at most 6 corners), then the shoelace
// formula.
#define CLIP_BY(L, IN, NIN, OUT, NOUT) { \
    NOUT = 0; \
    for (int e_ = 0; e_ < NIN; ++e_) { \
        vec2 p_ = IN[e_], q_ = IN[e_ + 1 < NIN ? e_ + 1 : 0]; \
        float dp_ = dot(L, vec3(p_, 1.0)), dq_ = dot(L, vec3(q_, 1.0)); \
        if (dp_ > 0.0) OUT[NOUT++] = p_; \
        if ((dp_ > 0.0) != (dq_ > 0.0)) OUT[NOUT++] = mix(p_, q_, dp_ / (dp_ - dq_)); \
    } }

float quarterSquareArea(vec3 l1, vec3 l2) {
    vec2 a[8], b[8];
    a[0] = vec2(0.0, 0.0); a[1] = vec2(1.0, 0.0); a[2] = vec2(1.0, 1.0); a[3] = vec2(0.0, 1.0);
    int na = 4, nb;
    CLIP_BY(l1, a, na, b, nb)
    CLIP_BY(l2, b, nb, a, na)
    float area = 0.0;
    for (int k = 0; k < na; ++k) {
        vec2 p = a[k], q = a[k + 1 < na ? k + 1 : 0];
        area += p.x * q.y - q.x * p.y;
    }
    return 0.5 * abs(area);
}
#undef CLIP_BY

// The half-plane of (u, v) where world coordinate `axis` (0: x, 1: z) on the
// plane y = h exceeds b (both camera-relative).
vec3 beyondLine(int axis, float b, float h) {
    float q = b / h;
    return axis == 0 ? vec3(pixEu.x - q * pixEu.y, pixEv.x - q * pixEv.y, pixD00.x - q * pixD00.y)
                     : vec3(pixEu.z - q * pixEu.y, pixEv.z - q * pixEv.y, pixD00.z - q * pixD00.y);
}

// The checker cell (x, z) that the camera ray d meets on the plane y = h.
vec2 cellOf(vec3 d, float h, vec2 off, float size) {
    return floor((h * d.xz / d.y + off) / size);
}

// The share of the pixel's square on the checker's second colour (where
// surfaceAt's parity is odd), or -1 (no footprint, or too many lines).  The
// pixel spans cells lo + (a, b), a = 0..nx, b = 0..nz (the corners' cells
// bound them: a coordinate on the plane is monotone along every segment of
// the square).  With H_a the area beyond x line a (the lower edge of cell
// lo.x + a), G_b beyond z line b and Q_ab beyond both, by
// inclusion-exclusion over the cells, o_ab the parity of cell (a, b):
//   share = o_00 + sum_a (2 o_a0 - 1) H_a + sum_b (2 o_0b - 1) G_b
//           + sum_ab (4 o_ab - 2) Q_ab     (a, b >= 1)
float pixelCoverage(int k) {
    Object o = objects[max(k, 0)];
    Material m = materials[o.info.y];
    float h = o.a.x, size = m.dielectric.w;
    vec2 off = m.checkerOffset.xy;
    vec3 d01 = pixD00 + pixEu, d10 = pixD00 + pixEv, d11 = d01 + pixEv;
    vec2 c00 = cellOf(pixD00, h, off, size), c01 = cellOf(d01, h, off, size);
    vec2 c10 = cellOf(d10, h, off, size), c11 = cellOf(d11, h, off, size);
    vec2 lo = min(min(c00, c01), min(c10, c11)), hi = max(max(c00, c01), max(c10, c11));
    vec2 span = hi - lo;
    bool ok = k >= 0 && span.x * span.y <= float(MAX_PIXEL_CORNERS) && span.x + span.y <= float(MAX_PIXEL_LINES);
    ivec2 n = ok ? ivec2(span) : ivec2(0);          // 0 trips where not needed
    float o00 = mod(lo.x + lo.y, 2.0);               // parity of cell (0, 0); cell (a, b): o00 + a + b
    float f = o00;
    for (int b = 1; b <= n.y; ++b) {
        float par = mod(o00 + float(b), 2.0);
        f += (2.0 * par - 1.0) * halfSquareArea(beyondLine(1, (lo.y + float(b)) * size - off.y, h));
    }
    for (int a = 1; a <= n.x; ++a) {
        vec3 la = beyondLine(0, (lo.x + float(a)) * size - off.x, h);
        f += (2.0 * mod(o00 + float(a), 2.0) - 1.0) * halfSquareArea(la);
        for (int b = 1; b <= n.y; ++b) {
            float par = mod(o00 + float(a + b), 2.0);
            f += (4.0 * par - 2.0) * quarterSquareArea(la, beyondLine(1, (lo.y + float(b)) * size - off.y, h));
        }
    }
    return ok ? clamp(f, 0.0, 1.0) : -1.0;
}

// Where along the row at v (u) world coordinate `axis` of the point on the
// plane y = h equals b: h (D0a + u Ea) / (D0y + u Ey) = b.
float rowCrossing(vec3 d0, int axis, float b, float h) {
    float a0 = axis == 0 ? d0.x : d0.z, e = axis == 0 ? pixEu.x : pixEu.z;
    return (b * d0.y - h * a0) / (h * e - b * pixEu.y);
}

// The share of the pixel's row at v, u in [0, 1), on the checker's second
// colour, or -1 (not needed: `need` false, or too many lines).  The row's
// two ends meet the plane, so along it x and z are monotone in u and each
// checker line is crossed once: the crossings of the two axes, merged in
// order of u, flip the parity.
float rowCoverage(int k, float v, bool need) {
    Object o = objects[max(k, 0)];
    Material m = materials[o.info.y];
    float h = o.a.x, size = m.dielectric.w;
    vec2 off = m.checkerOffset.xy;
    vec3 d0 = pixD00 + v * pixEv;
    vec2 c0 = cellOf(d0, h, off, size), c1 = cellOf(d0 + pixEu, h, off, size);
    vec2 dir = sign(c1 - c0);
    bool ok = need && k >= 0 && abs(c1.x - c0.x) + abs(c1.y - c0.y) <= float(MAX_ROW_CROSSINGS);
    ivec2 nc = ok ? ivec2(abs(c1 - c0)) : ivec2(0);   // 0 trips where not needed
    // the j-th line crossed along an axis (j = 0, 1, ...) is at the cell
    // boundary c0 + 1 + j going up, c0 - j going down
    vec2 first = (c0 + max(dir, 0.0)) * size - off;
    float par = mod(c0.x + c0.y, 2.0), acc = 0.0, u = 0.0;
    int kx = 0, kz = 0;
    for (int s = 0; s < nc.x + nc.y; ++s) {
        float ux = kx < nc.x ? rowCrossing(d0, 0, first.x + float(kx) * dir.x * size, h) : 2.0;
        float uz = kz < nc.y ? rowCrossing(d0, 1, first.y + float(kz) * dir.y * size, h) : 2.0;
        float next = clamp(min(ux, uz), u, 1.0);
        acc += par * (next - u);
        u = next;
        par = 1.0 - par;
        if (ux <= uz) ++kx; else ++kz;
    }
    return ok ? acc + par * (1.0 - u) : -1.0;
}

// Once per pixel (i, j): its plane, its square's rays and the closed form.
void setFootprintPixel(vec2 ij) {
    float code = texelFetch(footprintMask, ivec2(ij.x, imageSize.y - 1.0 - ij.y), 0).r;
    footprintObject = int(code * 255.0 + 0.5) - 1;
    vec2 uv0 = ij / imageSize;
    pixD00 = camForward + (2.0 * uv0.x - 1.0) * camRight + (1.0 - 2.0 * uv0.y) * camUp;
    pixEu = (2.0 / imageSize.x) * camRight;
    pixEv = (-2.0 / imageSize.y) * camUp;
    pixelShare = pixelCoverage(footprintObject);
}

// Once per sample at `offset`: the share its camera ray takes on the plane.
void setFootprintSample(vec2 offset) {
    float row = rowCoverage(footprintObject, offset.y, footprintObject >= 0 && pixelShare < 0.0);
    footprintShare = pixelShare >= 0.0 ? pixelShare : row;
}
