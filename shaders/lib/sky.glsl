// What a ray that leaves the scene sees.
const float PI = 3.14159265358979;

vec3 skyRadiance(vec3 d) {
    int type = iparams.z;
    if (type == SKY_COLOR) return skyColor.rgb;
#ifdef HAS_SKY_IMAGE
    if (type == SKY_IMAGE) {
        // -z is the centre of the picture, the top row is the zenith.
        float u = 0.5 + atan(d.x, -d.z) / (2.0 * PI);
        float v = acos(clamp(d.y, -1.0, 1.0)) / PI;
        return texture(skyImage, vec2(u, v)).rgb;   // wraps in u, clamps in v, bilinear
    }
#endif
    return mix(skyHorizon.rgb, skyZenith.rgb, max(d.y, 0.0));
}
