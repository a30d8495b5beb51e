// Ray-primitive intersection.  Every routine returns the nearest hit with
// t in (tmin, tmax) (or INF) and the unit OUTWARD normal of the solid there.
// Directions are unit length.  Invariant kept by all of them: a ray that
// starts exactly on a surface gets that surface only at t ~ 0, which the
// caller's tmin skips.

const float INF = 1e30;

// The nearest hit on a cylinder's surfaces so far: t, and what its normal
// needs: a side's radius r and s = +1 (outer side) or -1 (inner side, the
// normal points to the axis), or r = 0 and s = the normal's y for a cap.
// The normal is computed once, for the nearest surface (cylinderNormal).
struct CylinderHit { float t; float r; float s; };

void keepSurface(float t, float r, float s, float tmin, inout CylinderHit best) {
    if (t > tmin && t < best.t) best = CylinderHit(t, r, s);
}

#ifdef NAIVE_INTERSECT
// Textbook: no guard for rays parallel to the plane (t = +-inf or NaN).
float hitPlane(float height, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    n = vec3(0.0, 1.0, 0.0);
    float t = (height - ro.y) / rd.y;
    return (t > tmin && t < tmax) ? t : INF;
}
#else
float hitPlane(float height, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    n = vec3(0.0, 1.0, 0.0);
    if (rd.y == 0.0) return INF;
    float t = (height - ro.y) / rd.y;
    return (t > tmin && t < tmax) ? t : INF;
}
#endif

#ifdef NAIVE_INTERSECT
// NAIVE_INTERSECT (measurements only, see viewer/measure/stress.py): the textbook
// quadratic t^2 + b t + c = 0, discriminant b^2 - 4c and roots (-b +- sqrt)/2,
// which cancel catastrophically for distant or grazing rays.
float hitSphere(vec3 center, float radius, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    vec3 oc = ro - center;
    float b = 2.0 * dot(oc, rd);
    float c = dot(oc, oc) - radius * radius;
    float disc = b * b - 4.0 * c;
    n = vec3(0.0);
    if (disc < 0.0) return INF;
    float s = sqrt(disc);
    float tn = 0.5 * (-b - s), tf = 0.5 * (-b + s);
    float t = (tn > tmin) ? tn : tf;
    if (!(t > tmin && t < tmax)) return INF;
    n = (oc + t * rd) / radius;
    return t;
}
#else
// Roots of |o + t d - c|^2 = r^2 without cancellation: the discriminant from
// the closest-approach vector, and the stable pair q, c/q.
float hitSphere(vec3 center, float radius, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    vec3 oc = ro - center;
    float b = dot(oc, rd);
    vec3 qc = oc - b * rd;
    float h = radius * radius - dot(qc, qc);
    n = vec3(0.0);
    if (h < 0.0) return INF;
    h = sqrt(h);
    float q = -b - (b >= 0.0 ? h : -h);
    float c = dot(oc, oc) - radius * radius;
    float t0 = q;
    float t1 = (q != 0.0) ? c / q : q;
    float tn = min(t0, t1), tf = max(t0, t1);
    float t = (tn > tmin) ? tn : tf;
    if (!(t > tmin && t < tmax)) return INF;
    n = (oc + t * rd) / radius;
    return t;
}
#endif

// The box's hit from its slab interval [tEnter, tExit] (in the box frame,
// with the axes that set each end): the entry if it lies past tmin, else the
// exit, with the outward normal turned back to world space.
float boxHitFromSlabs(float tEnter, float tExit, int axisEnter, int axisExit, vec3 d, mat3 localFromWorld,
                      float tmin, float tmax, out vec3 n) {
    n = vec3(0.0);
    if (tEnter > tExit) return INF;
    vec3 nl = vec3(0.0);
    float t;
    if (tEnter > tmin) { t = tEnter; nl[axisEnter] = -sign(d[axisEnter]); }
    else if (tExit > tmin) { t = tExit; nl[axisExit] = sign(d[axisExit]); }
    else return INF;
    if (t >= tmax) return INF;
    n = transpose(localFromWorld) * nl;
    return t;
}

#ifdef NAIVE_INTERSECT
// Textbook slabs with plain 1/d: a zero direction component gives +-inf,
// and 0 * inf = NaN when the origin lies on that slab's plane.
float hitBox(Object o, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    mat3 localFromWorld = transpose(mat3(o.c.xyz, o.d.xyz, o.e.xyz));
    vec3 p = localFromWorld * (ro - o.a.xyz);
    vec3 d = localFromWorld * rd;
    vec3 half_ = o.b.xyz;
    vec3 inv = 1.0 / d;
    vec3 t0 = (-half_ - p) * inv, t1 = (half_ - p) * inv;
    vec3 tn = min(t0, t1), tf = max(t0, t1);
    float tEnter = max(tn.x, max(tn.y, tn.z)), tExit = min(tf.x, min(tf.y, tf.z));
    int axisEnter = tEnter == tn.x ? 0 : (tEnter == tn.y ? 1 : 2);
    int axisExit = tExit == tf.x ? 0 : (tExit == tf.y ? 1 : 2);
    return boxHitFromSlabs(tEnter, tExit, axisEnter, axisExit, d, localFromWorld, tmin, tmax, n);
}
#else
// Slab test in the box's own frame; zero direction components are handled
// explicitly (no 0 * inf NaN).
float hitBox(Object o, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    mat3 localFromWorld = mat3(o.c.xyz, o.d.xyz, o.e.xyz);   // columns ...
    localFromWorld = transpose(localFromWorld);              // ... rows c, d, e
    vec3 p = localFromWorld * (ro - o.a.xyz);
    vec3 d = localFromWorld * rd;
    vec3 half_ = o.b.xyz;
    float tEnter = -INF, tExit = INF;
    int axisEnter = 0, axisExit = 0;
    for (int i = 0; i < 3; ++i) {
        if (d[i] == 0.0) {
            if (abs(p[i]) > half_[i]) return INF;
            continue;
        }
        float inv = 1.0 / d[i];
        float t0 = (-half_[i] - p[i]) * inv;
        float t1 = (half_[i] - p[i]) * inv;
        float tn = min(t0, t1), tf = max(t0, t1);
        if (tn > tEnter) { tEnter = tn; axisEnter = i; }
        if (tf < tExit) { tExit = tf; axisExit = i; }
    }
    return boxHitFromSlabs(tEnter, tExit, axisEnter, axisExit, d, localFromWorld, tmin, tmax, n);
}
#endif

// The cylinder's axis becomes local y by swapping two coordinates (its own inverse).
vec3 toAxisFrame(vec3 v, int axis) {
    return axis == 0 ? v.yxz : (axis == 2 ? v.xzy : v);
}

#ifdef NAIVE_INTERSECT
// Textbook side: a t^2 + b t + c = 0 with disc = b^2 - 4ac and roots
// (-b +- sqrt(disc)) / 2a; no guard for rays parallel to the axis (a = 0).
void cylinderSide(vec3 p, vec3 d, float r, float y0, float y1, bool inward, float tmin,
                  inout CylinderHit best) {
    float a = d.x * d.x + d.z * d.z;
    float b = 2.0 * (p.x * d.x + p.z * d.z);
    float c = p.x * p.x + p.z * p.z - r * r;
    float disc = b * b - 4.0 * a * c;
    if (disc < 0.0) return;
    float s = sqrt(disc);
    float roots[2];
    roots[0] = (-b - s) / (2.0 * a);
    roots[1] = (-b + s) / (2.0 * a);
    for (int i = 0; i < 2; ++i) {
        float t = roots[i];
        float y = p.y + t * d.y;
        if (y >= y0 && y <= y1) keepSurface(t, r, inward ? -1.0 : 1.0, tmin, best);
    }
}
#else
// Side of an infinite cylinder of radius r about local y, both roots, the
// hits kept when their y lies in [y0, y1].  inward: the normal points to the axis.
void cylinderSide(vec3 p, vec3 d, float r, float y0, float y1, bool inward, float tmin,
                  inout CylinderHit best) {
    float a = d.x * d.x + d.z * d.z;
    if (a == 0.0) return;                      // parallel to the axis: no side hit
    float b = p.x * d.x + p.z * d.z;
    float cross_ = p.x * d.z - p.z * d.x;      // closest-approach form of the discriminant
    float h = r * r * a - cross_ * cross_;
    if (h < 0.0) return;
    h = sqrt(h);
    float q = -(b + (b >= 0.0 ? h : -h));
    float c = p.x * p.x + p.z * p.z - r * r;
    float roots[2];
    roots[0] = q / a;
    roots[1] = (q != 0.0) ? c / q : q / a;
    for (int i = 0; i < 2; ++i) {
        float t = roots[i];
        float y = p.y + t * d.y;
        if (y >= y0 && y <= y1) keepSurface(t, r, inward ? -1.0 : 1.0, tmin, best);
    }
}
#endif

#ifdef NAIVE_INTERSECT
// Textbook cap: no guard for rays parallel to the cap (t = +-inf or NaN).
void cylinderCap(vec3 p, vec3 d, float y, float rIn, float rOut, float ny, float tmin,
                 inout CylinderHit best) {
    float t = (y - p.y) / d.y;
    float x = p.x + t * d.x, z = p.z + t * d.z;
    float rho2 = x * x + z * z;
    if (rho2 <= rOut * rOut && rho2 >= rIn * rIn) keepSurface(t, 0.0, ny, tmin, best);
}
#else
// Disc or annulus at local height y with rho in [rIn, rOut]; normal +-y.
void cylinderCap(vec3 p, vec3 d, float y, float rIn, float rOut, float ny, float tmin,
                 inout CylinderHit best) {
    if (d.y == 0.0) return;
    float t = (y - p.y) / d.y;
    float x = p.x + t * d.x, z = p.z + t * d.z;
    float rho2 = x * x + z * z;
    if (rho2 <= rOut * rOut && rho2 >= rIn * rIn) keepSurface(t, 0.0, ny, tmin, best);
}
#endif

// The unit outward normal (axis frame) of the nearest surface; 0 for none.
vec3 cylinderNormal(vec3 p, vec3 d, CylinderHit hit) {
    if (hit.r > 0.0) {
        // (x, 0, z) / r, without dividing the 0 (r > 0: the same +0)
        vec3 nr = vec3((p.x + hit.t * d.x) / hit.r, 0.0, (p.z + hit.t * d.z) / hit.r);
        return hit.s < 0.0 ? -nr : nr;
    }
    return vec3(0.0, hit.s, 0.0);
}

// Capped cylinder, or (hollow: wall > 0) the vessel: outer side, bottom, rim,
// inner side and inner bottom.  `hollow` is a literal in the specialised
// shader, so a solid cylinder compiles without the vessel's surfaces.
float hitCylinder(Object o, bool hollow, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    int axis = o.info.z;
    vec3 p = toAxisFrame(ro - o.a.xyz, axis);
    vec3 d = toAxisFrame(rd, axis);
    float r = o.a.w, height = o.b.x, wall = o.b.y;
    CylinderHit best = CylinderHit(tmax, 0.0, 0.0);
    cylinderSide(p, d, r, 0.0, height, false, tmin, best);
    cylinderCap(p, d, 0.0, 0.0, r, -1.0, tmin, best);
    if (hollow) {
        float ri = r - wall;
        cylinderSide(p, d, ri, wall, height, true, tmin, best);
        cylinderCap(p, d, wall, 0.0, ri, 1.0, tmin, best);
        cylinderCap(p, d, height, ri, r, 1.0, tmin, best);
    } else {
        cylinderCap(p, d, height, 0.0, r, 1.0, tmin, best);
    }
    n = toAxisFrame(cylinderNormal(p, d, best), axis);
    return best.t < tmax ? best.t : INF;
}

#ifdef NAIVE_INTERSECT
// Textbook bounding-sphere test: discriminant b^2 - c.
bool mayHitBound(vec4 bound, vec3 ro, vec3 rd, float tmin, float tmax) {
    if (bound.w < 0.0) return true;
    vec3 oc = ro - bound.xyz;
    float b = dot(oc, rd);
    float h = b * b - (dot(oc, oc) - bound.w * bound.w);
    if (h < 0.0) return false;
    h = sqrt(h);
    return -b + h > tmin && -b - h < tmax;
}
#else
// Cheap rejection before the exact routine: can the ray meet the bounding
// sphere anywhere in (tmin, tmax)?
bool mayHitBound(vec4 bound, vec3 ro, vec3 rd, float tmin, float tmax) {
    if (bound.w < 0.0) return true;
    vec3 oc = ro - bound.xyz;
    float b = dot(oc, rd);
    vec3 qc = oc - b * rd;
    float h = bound.w * bound.w - dot(qc, qc);
    if (h < 0.0) return false;
    h = sqrt(h);
    return -b + h > tmin && -b - h < tmax;
}
#endif

// Shapes: the object types, plus SHAPE_VESSEL for a cylinder with a wall.
// The specialised shader passes each object's shape as a literal (see
// FOR_EACH_OBJECT in lib/walk.glsl), so only that primitive's code is compiled
// for it; the generic one passes the shape read from the block at run time.
#define SHAPE_VESSEL 4

bool isCylinder(int shape) { return shape == OBJ_CYLINDER || shape == SHAPE_VESSEL; }

int runtimeShape(Object o) {
    return (o.info.x == OBJ_CYLINDER && o.b.y > 0.0) ? SHAPE_VESSEL : o.info.x;
}

// The exact routine of `shape`, no bounding test.
float hitShapeExact(Object o, int shape, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    n = vec3(0.0);
#ifdef HAS_PLANE
    if (shape == OBJ_PLANE) return hitPlane(o.a.x, ro, rd, tmin, tmax, n);
#endif
#ifdef HAS_SPHERE
    if (shape == OBJ_SPHERE) return hitSphere(o.a.xyz, o.a.w, ro, rd, tmin, tmax, n);
#endif
#ifdef HAS_BOX
    if (shape == OBJ_BOX) return hitBox(o, ro, rd, tmin, tmax, n);
#endif
#ifdef HAS_CYLINDER
    if (isCylinder(shape)) return hitCylinder(o, shape == SHAPE_VESSEL, ro, rd, tmin, tmax, n);
#endif
    return INF;
}

// Object k.  The generic shader tests its bounding sphere first; the
// specialised one goes straight to the exact routine: llvmpipe runs both
// sides of every branch (its SIMD lanes follow a mask), so there the test
// never skips the routine and only adds its own cost, 15-20% of a frame
// (measured on the opaque benchmark scene and the default scene).
float hitShape(int k, int shape, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    Object o = objects[k];
    n = vec3(0.0);
#ifdef GENERIC
    if (!mayHitBound(o.bound, ro, rd, tmin, tmax)) return INF;
#endif
    return hitShapeExact(o, shape, ro, rd, tmin, tmax, n);
}

// Object k with its run-time shape (the debug views).
float hitObject(int k, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    return hitShape(k, runtimeShape(objects[k]), ro, rd, tmin, tmax, n);
}

// Point-in-solid, strict (points on the surface count as outside).  Used to
// decide which media lie on the far side of a crossing.
bool insideShape(int k, int shape, vec3 p) {
    Object o = objects[k];
    if (shape == OBJ_PLANE) return p.y < o.a.x;
    if (shape == OBJ_SPHERE) { vec3 q = p - o.a.xyz; return dot(q, q) < o.a.w * o.a.w; }
    if (shape == OBJ_BOX) {
        mat3 localFromWorld = transpose(mat3(o.c.xyz, o.d.xyz, o.e.xyz));
        vec3 q = abs(localFromWorld * (p - o.a.xyz));
        return all(lessThan(q, o.b.xyz));
    }
    vec3 q = toAxisFrame(p - o.a.xyz, o.info.z);
    float rho2 = q.x * q.x + q.z * q.z;
    float r = o.a.w, height = o.b.x, wall = o.b.y;
    bool inOuter = rho2 < r * r && q.y > 0.0 && q.y < height;
    if (shape == SHAPE_VESSEL) {
        float ri = r - wall;
        bool inHollow = rho2 < ri * ri && q.y > wall;
        return inOuter && !inHollow;
    }
    return inOuter;
}
