// Exact unpolarised Fresnel reflectance and Snell refraction.
// cosI = -dot(d, n) > 0 with n facing the incoming ray; eta = n1 / n2.

float fresnelDielectric(float cosI, float n1, float n2, out float cosT) {
    // Equal iors: R = 0 and the ray goes straight on (the spec's rule).  The
    // formula below would agree but for float32: at grazing incidence
    // 1 - cosI^2 rounds to 1 (cosI < 2.4e-4) and gave total reflection.
    if (n1 == n2) { cosT = cosI; return 0.0; }
    float eta = n1 / n2;
    float sin2T = eta * eta * max(0.0, 1.0 - cosI * cosI);
    if (sin2T >= 1.0) { cosT = 0.0; return 1.0; }            // total internal reflection
    cosT = sqrt(1.0 - sin2T);
#ifdef FRESNEL_SCHLICK
    // Schlick's approximation, for the benchmark's comparison only (the cosine
    // on the denser side, as usual).
    float r0 = (n1 - n2) / (n1 + n2);
    r0 *= r0;
    float c = 1.0 - (n1 <= n2 ? cosI : cosT);
    return r0 + (1.0 - r0) * c * c * c * c * c;
#endif
    float rs = (n1 * cosI - n2 * cosT) / (n1 * cosI + n2 * cosT);
    float rp = (n1 * cosT - n2 * cosI) / (n1 * cosT + n2 * cosI);
    return 0.5 * (rs * rs + rp * rp);
}

vec3 refractDir(vec3 d, vec3 n, float eta, float cosI, float cosT) {
    return normalize(eta * d + (eta * cosI - cosT) * n);
}

float maxComponent(vec3 v) { return max(v.x, max(v.y, v.z)); }
