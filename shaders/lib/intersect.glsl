// Ray-primitive intersection.  Every routine returns the nearest hit with
// t in (tmin, tmax) (or INF) and the unit OUTWARD normal of the solid there.
// Directions are unit length.  Invariant kept by all of them: a ray that
// starts exactly on a surface gets that surface only at t ~ 0, which the
// caller's tmin skips.

const float INF = 1e30;

void keepNearest(float t, vec3 n, float tmin, inout float best, inout vec3 bestN) {
    if (t > tmin && t < best) { best = t; bestN = n; }
}

float hitPlane(float height, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    n = vec3(0.0, 1.0, 0.0);
    if (rd.y == 0.0) return INF;
    float t = (height - ro.y) / rd.y;
    return (t > tmin && t < tmax) ? t : INF;
}

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

// The cylinder's axis becomes local y by swapping two coordinates (its own inverse).
vec3 toAxisFrame(vec3 v, int axis) {
    return axis == 0 ? v.yxz : (axis == 2 ? v.xzy : v);
}

// Side of an infinite cylinder of radius r about local y, both roots, the
// hits kept when their y lies in [y0, y1].  inward: the normal points to the axis.
void cylinderSide(vec3 p, vec3 d, float r, float y0, float y1, bool inward, float tmin,
                  inout float best, inout vec3 bestN) {
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
        if (y >= y0 && y <= y1) {
            vec3 nr = vec3(p.x + t * d.x, 0.0, p.z + t * d.z) / r;
            keepNearest(t, inward ? -nr : nr, tmin, best, bestN);
        }
    }
}

// Disc or annulus at local height y with rho in [rIn, rOut]; normal +-y.
void cylinderCap(vec3 p, vec3 d, float y, float rIn, float rOut, float ny, float tmin,
                 inout float best, inout vec3 bestN) {
    if (d.y == 0.0) return;
    float t = (y - p.y) / d.y;
    float x = p.x + t * d.x, z = p.z + t * d.z;
    float rho2 = x * x + z * z;
    if (rho2 <= rOut * rOut && rho2 >= rIn * rIn) keepNearest(t, vec3(0.0, ny, 0.0), tmin, best, bestN);
}

// Capped cylinder, or with wall > 0 the vessel: outer side, bottom, rim,
// inner side and inner bottom.
float hitCylinder(Object o, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    int axis = o.info.z;
    vec3 p = toAxisFrame(ro - o.a.xyz, axis);
    vec3 d = toAxisFrame(rd, axis);
    float r = o.a.w, height = o.b.x, wall = o.b.y;
    float best = tmax;
    vec3 bestN = vec3(0.0);
    cylinderSide(p, d, r, 0.0, height, false, tmin, best, bestN);
    cylinderCap(p, d, 0.0, 0.0, r, -1.0, tmin, best, bestN);
    if (wall > 0.0) {
        float ri = r - wall;
        cylinderSide(p, d, ri, wall, height, true, tmin, best, bestN);
        cylinderCap(p, d, wall, 0.0, ri, 1.0, tmin, best, bestN);
        cylinderCap(p, d, height, ri, r, 1.0, tmin, best, bestN);
    } else {
        cylinderCap(p, d, height, 0.0, r, 1.0, tmin, best, bestN);
    }
    n = toAxisFrame(bestN, axis);
    return best < tmax ? best : INF;
}

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

float hitObject(int k, vec3 ro, vec3 rd, float tmin, float tmax, out vec3 n) {
    Object o = objects[k];
    int type = o.info.x;
    n = vec3(0.0);
    if (!mayHitBound(o.bound, ro, rd, tmin, tmax)) return INF;
#ifdef HAS_PLANE
    if (type == OBJ_PLANE) return hitPlane(o.a.x, ro, rd, tmin, tmax, n);
#endif
#ifdef HAS_SPHERE
    if (type == OBJ_SPHERE) return hitSphere(o.a.xyz, o.a.w, ro, rd, tmin, tmax, n);
#endif
#ifdef HAS_BOX
    if (type == OBJ_BOX) return hitBox(o, ro, rd, tmin, tmax, n);
#endif
#ifdef HAS_CYLINDER
    if (type == OBJ_CYLINDER) return hitCylinder(o, ro, rd, tmin, tmax, n);
#endif
    return INF;
}

// Point-in-solid, strict (points on the surface count as outside).  Used to
// decide which media lie on the far side of a crossing.
bool insideObject(int k, vec3 p) {
    Object o = objects[k];
    int type = o.info.x;
    if (type == OBJ_PLANE) return p.y < o.a.x;
    if (type == OBJ_SPHERE) { vec3 q = p - o.a.xyz; return dot(q, q) < o.a.w * o.a.w; }
    if (type == OBJ_BOX) {
        mat3 localFromWorld = transpose(mat3(o.c.xyz, o.d.xyz, o.e.xyz));
        vec3 q = abs(localFromWorld * (p - o.a.xyz));
        return all(lessThan(q, o.b.xyz));
    }
    vec3 q = toAxisFrame(p - o.a.xyz, o.info.z);
    float rho2 = q.x * q.x + q.z * q.z;
    float r = o.a.w, height = o.b.x, wall = o.b.y;
    bool inOuter = rho2 < r * r && q.y > 0.0 && q.y < height;
    if (wall > 0.0) {
        float ri = r - wall;
        bool inHollow = rho2 < ri * ri && q.y > wall;
        return inOuter && !inHollow;
    }
    return inOuter;
}
