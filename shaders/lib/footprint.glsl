// Footprint samples (viewer/adaptive/): the checker of a plane
// box-filtered over a pixel's square, exactly, instead of point-sampled.
// Adaptive renders take them, and so do uniform renders of more than one
// sample (Renderer.render, the viewer's accumulation), with direct
// footprints only (exact shares: the same limit as point samples); their
// mask comes from AdaptiveSampler.direct_footprints, the shares from its
// share pass (footprint_shares.frag), and every sample reads
// them (FOOTPRINT_SHARES).
//
// Texel (i, H - 1 - j) of footprintMask (RG32F) holds in r k + 1 where the
// four corner rays of pixel (i, j) meet checkered plane k first, -(e + 1)
// where the pixel has chain footprint e (below), 0 for point samples; in g
// the pixel's share (pixelCoverage) as the first pass found it, -1 where
// the closed form is out of reach or before the first pass.  The first
// pass computes the shares and reports them (footprint_shares.frag); the list passes
// (FOOTPRINT_SHARES) read them from g.
// The directions that meet a plane form a convex set, so every ray through
// the pixel's square meets plane k, unless another object pokes in between
// the corners (a sample that meets that object first stays a point sample).
// There a camera ray that meets plane k takes as its colour the checker's
// two colours mixed by their exact shares of the pixel's square in image
// space (the box filter); its lighting stays its own.
//
// That alone converges to mean colour x mean lighting, not to the mean of
// colour x lighting: where the lighting changes inside the pixel (a
// shadow's edge across a checker line) it stopped short of the box filter
// (mirror-ball at 48x27, pixel (22, 19): 0.052 off at any sample count).
// So a direct footprint sample is a control variate: colour c(x) and
// lighting L(x) at its point, c_bar the exact mean colour and L_ref the
// lighting where the pixel's centre ray meets the plane (the same for
// every sample of the pixel), it adds
//     c_bar L(x) + (c(x) - c_bar) (L(x) - L_ref) = c(x) L(x) - (c(x) - c_bar) L_ref,
// whose mean is exactly the mean of c L, since the mean of c is c_bar.
// Where the lighting is the same across the pixel the second term is 0:
// the checker costs no samples, as before; only where both the checker and
// the lighting change inside the pixel does it take samples again.  A
// pixel in one checker square (c = c_bar) skips L_ref.  Chain footprints
// (adaptive renders, through glass) keep c_bar L(x).
//
// The camera ray through (i + u, j + v) is pixD00 + u pixEu + v pixEv
// (unnormalised, linear in u and v).  A world coordinate a on the plane
// y = h (camera-relative) exceeds b exactly where D_a - (b / h) D_y > 0,
// since the ray meets the plane at t = h / D_y > 0: every checker line is a
// straight line in (u, v), and the share of the square beyond it has a
// closed form.
//
// Chain footprints: where the four corner rays do not meet a plane first
// but follow one principal chain (the refracted branch at every crossing,
// the reflected one at total internal reflection) through the same
// surfaces to one checkered plane, the map from the pixel's square to the
// plane is taken as the homography through the four corners' points
// (viewer/adaptive/'s chain_footprints, which also rejects pixels where
// the corner grid bends more than CHAIN_TOLERANCE allows).  A sample whose
// own principal chain matches (and ends on that plane) takes the shares;
// any other takes a point sample (see takesFootprint).
//
// FOOTPRINT_DIRECT_ONLY (uniform renders): no chain footprints, compiled
// out, so that the rows are dead once a sample's share is set.
//
// Both kinds reach the closed form as three rows: plane coordinate x (z) =
// (fpX . w) / (fpW . w) ((fpZ . w) / (fpW . w)), w = (u, v, 1), camera-relative,
// with fpW . w > 0 over the square.
//
// Cost: the shares are computed once per pixel, in the first pass
// (setFootprintPixel; the list passes read them back), and once per sample
// only where the closed form is out of reach (the row fallback).  On a
// SIMD rasteriser every lane runs every branch, so each loop's trip count
// is 0 in the lanes that do not need it.

uniform sampler2D footprintMask;
// Chain footprint e at texels (3 (e % chainEntriesPerRow) + r, e /
// chainEntriesPerRow), r = 0, 1, 2: (fpX, chain id), (fpZ, k + 1), (fpW,
// tolerance^2; not read here: the tolerance is applied per pixel, in
// viewer/adaptive/).
uniform sampler2D footprintChain;
uniform int chainEntriesPerRow;
int footprintObject = -1;     // k, or -1: this pixel takes point samples
float footprintChainId = 0.0; // the principal chain its samples must follow (0: the camera ray itself)
float pixelShare = -1.0;      // the closed form's share (-1: none)
float footprintShare = -1.0;  // this sample's share (-1: a point sample)
vec3 pixD00, pixEu, pixEv;
vec3 fpX, fpZ, fpW;           // the rows (see above)
vec3 fpCentreDir;             // the camera ray through the pixel's centre (the lighting's control variate)

// More products of crossing lines than MAX_PIXEL_CORNERS (checker corners
// inside the pixel), or more lines than MAX_PIXEL_LINES: no closed form;
// the sample's row is integrated.  Both come from viewer/adaptive/ (the
// footprint variants' defines), where the reasons for their values are.
#if !defined(MAX_PIXEL_CORNERS) || !defined(MAX_PIXEL_LINES)
#error "FOOTPRINT_AA needs MAX_PIXEL_CORNERS and MAX_PIXEL_LINES (viewer/adaptive/)"
#endif
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

// The area of {l1 > 0} and {l2 > 0} in [0, 1]^2 by the shoelace formula
// over the region's boundary (Green's theorem: area = 1/2 sum of p x q over
// its edges p -> q, counter-clockwise): the part of each square edge inside
// both half-planes, and the part of each line inside the square and the
// other half-plane, each one segment (a convex set meets a segment in a
// segment), each clipped in its parameter (Liang-Barsky).  No arrays: a
// clipped polygon in local arrays, indexed per lane, took three quarters
// of glass-sphere's first pass on llvmpipe.

// Clip t in [t0, t1] to where g0 + g1 t > 0 (>= 0 where `closed`); an
// empty range ends with t1 < t0.
void clipRange(float g0, float g1, bool closed, inout float t0, inout float t1) {
    if (g1 > 0.0) t0 = max(t0, -g0 / g1);
    else if (g1 < 0.0) t1 = min(t1, -g0 / g1);
    else if (closed ? g0 < 0.0 : g0 <= 0.0) t1 = -1e30;
}

// Twice the signed area a segment's clipped part adds: square edge a -> b
// (counter-clockwise), inside both half-planes (open: a line along the edge
// brings that stretch itself).
float edgeTerm(vec2 a, vec2 b, vec3 l1, vec3 l2) {
    vec2 e = b - a;
    float t0 = 0.0, t1 = 1.0;
    clipRange(dot(l1, vec3(a, 1.0)), dot(l1.xy, e), false, t0, t1);
    clipRange(dot(l2, vec3(a, 1.0)), dot(l2.xy, e), false, t0, t1);
    if (t1 <= t0) return 0.0;
    vec2 p = a + t0 * e, q = a + t1 * e;
    return p.x * q.y - q.x * p.y;
}

// Line l = 0 inside the square and on the closed side of `other`, run with
// {l > 0} on its left: from its point nearest the square's corner (0, 0)
// (within sqrt(2) of it wherever the line meets the square: no
// cancellation) along the unit direction (l.y, -l.x).
float lineTerm(vec3 l, vec3 other) {
    float len = length(l.xy);
    if (len == 0.0) return 0.0;
    l /= len;
    vec2 d = vec2(l.y, -l.x), p0 = -l.z * l.xy;
    float t0 = -1e30, t1 = 1e30;
    clipRange(p0.x, d.x, true, t0, t1);
    clipRange(1.0 - p0.x, -d.x, true, t0, t1);
    clipRange(p0.y, d.y, true, t0, t1);
    clipRange(1.0 - p0.y, -d.y, true, t0, t1);
    clipRange(dot(other, vec3(p0, 1.0)), dot(other.xy, d), true, t0, t1);
    if (t1 <= t0) return 0.0;
    vec2 p = p0 + t0 * d, q = p0 + t1 * d;
    return p.x * q.y - q.x * p.y;
}

float quarterSquareArea(vec3 l1, vec3 l2) {
    float twice = edgeTerm(vec2(0.0, 0.0), vec2(1.0, 0.0), l1, l2) + edgeTerm(vec2(1.0, 0.0), vec2(1.0, 1.0), l1, l2)
                + edgeTerm(vec2(1.0, 1.0), vec2(0.0, 1.0), l1, l2) + edgeTerm(vec2(0.0, 1.0), vec2(0.0, 0.0), l1, l2)
                + lineTerm(l1, l2) + lineTerm(l2, l1);
    return clamp(0.5 * twice, 0.0, 1.0);
}

// The half-plane of (u, v) where plane coordinate `axis` (0: x, 1: z)
// exceeds b (camera-relative): (row - b fpW) . w > 0, as fpW . w > 0.
vec3 beyondLine(int axis, float b) {
    return (axis == 0 ? fpX : fpZ) - b * fpW;
}

// The plane point (x, z) of (u, v) in the square.
vec2 planePoint(vec2 uv) {
    vec3 w = vec3(uv, 1.0);
    return vec2(dot(fpX, w), dot(fpZ, w)) / dot(fpW, w);
}

// The checker cell (x, z) of (u, v).
vec2 cellOf(vec2 uv, vec2 off, float size) {
    return checkerCell(planePoint(uv) + off, size);
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
    float size = m.dielectric.w;
    vec2 off = m.checkerOffset.xy;
    vec2 c00 = cellOf(vec2(0.0), off, size), c01 = cellOf(vec2(1.0, 0.0), off, size);
    vec2 c10 = cellOf(vec2(0.0, 1.0), off, size), c11 = cellOf(vec2(1.0), off, size);
    vec2 lo = min(min(c00, c01), min(c10, c11)), hi = max(max(c00, c01), max(c10, c11));
    vec2 span = hi - lo;
    bool ok = k >= 0 && span.x * span.y <= float(MAX_PIXEL_CORNERS) && span.x + span.y <= float(MAX_PIXEL_LINES);
    // 0 trips where not needed; clamped as well, after the conversion (an
    // integer clamp is exact: int() of a NaN or of a float out of int's
    // range is undefined, and so is a float clamp of a NaN), so the trip
    // count is bounded even where a driver's comparisons let a NaN through
    // (GLSL leaves NaN undefined, and a GPU has no loop limit)
    ivec2 n = ok ? clamp(ivec2(span), 0, MAX_PIXEL_LINES) : ivec2(0);
    float o00 = mod(lo.x + lo.y, 2.0);               // parity of cell (0, 0); cell (a, b): o00 + a + b
    float f = o00;
    for (int b = 1; b <= n.y; ++b) {
        float par = mod(o00 + float(b), 2.0);
        f += (2.0 * par - 1.0) * halfSquareArea(beyondLine(1, (lo.y + float(b)) * size - off.y));
    }
    for (int a = 1; a <= n.x; ++a) {
        vec3 la = beyondLine(0, (lo.x + float(a)) * size - off.x);
        f += (2.0 * mod(o00 + float(a), 2.0) - 1.0) * halfSquareArea(la);
        for (int b = 1; b <= n.y; ++b) {
            float par = mod(o00 + float(a + b), 2.0);
            f += (4.0 * par - 2.0) * quarterSquareArea(la, beyondLine(1, (lo.y + float(b)) * size - off.y));
        }
    }
    return ok ? clamp(f, 0.0, 1.0) : -1.0;
}

// Where along the row at v (u) plane coordinate `axis` equals b: the line
// (row - b fpW) . (u, v, 1) = 0.
float rowCrossing(float v, int axis, float b) {
    vec3 l = beyondLine(axis, b);
    return -(l.y * v + l.z) / l.x;
}

// The share of the pixel's row at v, u in [0, 1), on the checker's second
// colour, or -1 (too many lines).  Called only where a sample needs it (a
// branch in setFootprintSample).  The row's
// two ends meet the plane, so along it x and z are monotone in u and each
// checker line is crossed once: the crossings of the two axes, merged in
// order of u, flip the parity.
float rowCoverage(int k, float v) {
    Object o = objects[max(k, 0)];
    Material m = materials[o.info.y];
    float size = m.dielectric.w;
    vec2 off = m.checkerOffset.xy;
    vec2 c0 = cellOf(vec2(0.0, v), off, size), c1 = cellOf(vec2(1.0, v), off, size);
    vec2 dir = sign(c1 - c0);
    bool ok = k >= 0 && abs(c1.x - c0.x) + abs(c1.y - c0.y) <= float(MAX_ROW_CROSSINGS);
    // 0 trips past the limit, and bounded as in pixelCoverage
    ivec2 nc = ok ? clamp(ivec2(abs(c1 - c0)), 0, MAX_ROW_CROSSINGS) : ivec2(0);
    // the j-th line crossed along an axis (j = 0, 1, ...) is at the cell
    // boundary c0 + 1 + j going up, c0 - j going down
    vec2 first = (c0 + max(dir, 0.0)) * size - off;
    float par = mod(c0.x + c0.y, 2.0), acc = 0.0, u = 0.0;
    int kx = 0, kz = 0;
    for (int s = 0; s < nc.x + nc.y; ++s) {
        float ux = kx < nc.x ? rowCrossing(v, 0, first.x + float(kx) * dir.x * size) : 2.0;
        float uz = kz < nc.y ? rowCrossing(v, 1, first.y + float(kz) * dir.y * size) : 2.0;
        float next = clamp(min(ux, uz), u, 1.0);
        acc += par * (next - u);
        u = next;
        par = 1.0 - par;
        if (ux <= uz) ++kx; else ++kz;
    }
    return ok ? acc + par * (1.0 - u) : -1.0;
}

// Once per pixel (i, j): its plane, its square's rows and the closed form.
// The rows of a directly seen plane's pixel (i, j): the camera ray
// through (i + u, j + v) meets footprintObject's plane.
void setDirectRows(vec2 ij) {
    vec2 uv0 = ij / imageSize;
    pixD00 = camForward + (2.0 * uv0.x - 1.0) * camRight + (1.0 - 2.0 * uv0.y) * camUp;
    pixEu = (2.0 / imageSize.x) * camRight;
    pixEv = (-2.0 / imageSize.y) * camUp;
    // the camera ray D = pixD00 + u pixEu + v pixEv meets the plane y = h
    // at t = h / D.y > 0: x = h D.x / D.y, z = h D.z / D.y
    // (h != 0 wherever a pixel's corners all meet the plane; the guard
    // keeps the rows finite where footprintObject is -1 and unused)
    float h = objects[max(footprintObject, 0)].a.x;
    fpX = vec3(pixEu.x, pixEv.x, pixD00.x);
    fpZ = vec3(pixEu.z, pixEv.z, pixD00.z);
    fpW = vec3(pixEu.y, pixEv.y, pixD00.y) / (h != 0.0 ? h : 1.0);
}

#if defined(FOOTPRINT_DIRECT_ONLY) && defined(FOOTPRINT_SHARES)
// Uniform renders read every share and need the rows only for a sample's
// row fallback: they are set there (setFootprintSample), not per pixel.
#define FOOTPRINT_LAZY_ROWS
vec2 fpPixel;
#endif

void setFootprintPixel(vec2 ij) {
    // cameraRay(ij, vec2(0.5)) (lib/camera.glsl): the centre sample's own ray
    vec2 uvC = (ij + vec2(0.5)) / imageSize;
    fpCentreDir = normalize(camForward + (2.0 * uvC.x - 1.0) * camRight + (1.0 - 2.0 * uvC.y) * camUp);
    int row = int(imageSize.y - 1.0 - ij.y);
    vec4 texel = texelFetch(footprintMask, ivec2(ij.x, row), 0);
    float code = texel.r;
    footprintObject = code > 0.5 ? int(code + 0.5) - 1 : -1;
    footprintChainId = 0.0;
#ifdef FOOTPRINT_LAZY_ROWS
    fpPixel = ij;
#else
    setDirectRows(ij);
#endif
#ifndef FOOTPRINT_DIRECT_ONLY
    if (code < -0.5) {
        int e = int(-code + 0.5) - 1;
        // (an unset uniform is 0: integer division by 0 is undefined)
        int perRow = max(chainEntriesPerRow, 1);
        ivec2 at = ivec2(3 * (e % perRow), e / perRow);
        vec4 t0 = texelFetch(footprintChain, at, 0);
        vec4 t1 = texelFetch(footprintChain, at + ivec2(1, 0), 0);
        vec4 t2 = texelFetch(footprintChain, at + ivec2(2, 0), 0);
        footprintObject = int(t1.w + 0.5) - 1;
        footprintChainId = t0.w;
        fpX = t0.xyz; fpZ = t1.xyz; fpW = t2.xyz;
    }
#endif
#ifdef FOOTPRINT_SHARES
    // the share the first pass computed for this pixel (-1: none; read,
    // not recomputed: the closed form's loops run up to MAX_PIXEL_CORNERS
    // times, once per pixel in the first pass instead of once per entry)
    pixelShare = footprintObject >= 0 ? texel.g : -1.0;
#else
    pixelShare = pixelCoverage(footprintObject);
#endif
}

// Once per sample at `offset`: the share its camera ray takes on the plane.
void setFootprintSample(vec2 offset) {
    footprintShare = pixelShare;
    // (a branch: a SIMD group none of whose pixels needs its row skips it)
    if (footprintObject >= 0 && pixelShare < 0.0) {
#ifdef FOOTPRINT_LAZY_ROWS
        setDirectRows(fpPixel);
#endif
        footprintShare = rowCoverage(footprintObject, offset.y);
    }
}

// Whether a ray of this sample that met plane k
// along principal chain `chain` takes the footprint's share: the pixel's
// plane and chain.
bool takesFootprint(int k, float chain) {
#ifdef FOOTPRINT_DIRECT_ONLY
    // only the camera ray itself (chain 0): nothing of the homography stays
    // live through the ray tree
    return k == footprintObject && chain == 0.0 && footprintShare >= 0.0;
#else
    // Every sample of the pixel's chain takes the share, whatever its own
    // point: the share is the whole square's, so a sample that took a point
    // sample instead (one further than the tolerance from the homography's point)
    // left the pixel's mean the share over the samples within it plus the
    // point-sampled checker beyond it, biased where the two regions' shares
    // differ (glass-sphere at 96x54, the row of chain pixels at j = 22: off
    // by up to 0.087 of the pixel where the homography's own share is
    // within 0.01; tests/test_aa_audit.py).  The homography's error is
    // bounded per pixel, by chain_footprints' check of its neighbours.
    return k == footprintObject && chain == footprintChainId && footprintShare >= 0.0;
#endif
}
