// Shading a surface point: its material and checker colour, and the light
// it takes from the scene's lights (with shadow rays, lib/walk.glsl).

struct Surface { vec3 color; vec3 emission; };

// The checker rule: parity of floor(x/s) + floor(z/s) in world x, z.  The
// eye's world position modulo 2s is added back (the pattern repeats every 2s).
// The point is first moved toward +x and +z by 2e-6 of its magnitude: far
// more than its rounding, far less than a pixel, and the same in every
// scene (so media that vanish leave the checker behind them as it was).  A
// face that lies on a checker line (a box face at x = 0) then has the
// spec's floor(0 / s) = 0 all over, where the rounding of its points to
// either side of the line made salt and pepper of it.
Surface surfaceAt(Material m, vec3 p) {
    Surface s;
    s.color = m.colorAmbient.rgb;
    s.emission = m.emission.rgb;
    if (m.dielectric.z > 0.5) {
        float size = m.dielectric.w;
        vec2 w = p.xz + m.checkerOffset.xy;
        w += params.y * max(max(abs(p.x), max(abs(p.y), abs(p.z))), max(abs(w.x), abs(w.y)));
        vec2 cell = checkerCell(w, size);
        if (mod(cell.x + cell.y, 2.0) > 0.5) {
            s.color = m.checkerColor.rgb;
            s.emission = m.checkerEmission.rgb;
        }
    }
    return s;
}

// Light j, and the material of object k.  A block read at an index that
// differs between SIMD lanes (an object's material) or that llvmpipe
// cannot prove the same for all of them (the light loop's counter, which
// it keeps per lane) is a gather: every component of every lane loaded on
// its own, through its own address.  In the default scene's frame these
// two were most of the 16% of perf's samples that fell in per-lane loads
// (tools/jit_profile.py), and the selects below made it 5% faster on
// Mesa 25.  So where a scene
// has at most 8 of them (gpu/packing.py PICK_MAX) the specialised shader reads
// every light and material at a literal index, one broadcast each, and
// keeps the one asked for: a select per component and entry, cheaper than
// the gather (some 17 instructions a component against 2).  The indices
// come as literals (SCENE_LIGHT_INDICES(X), SCENE_MATERIAL_INDICES(X):
// X(1) .. X(n - 1)), not as a loop's counter, so that no driver has to
// unroll a loop to see constants.  On Mesa 22.3's llvmpipe the material
// selects made the default frame 25% slower, so there the renderer drops
// SCENE_MATERIAL_INDICES (gpu/packing.py driver_defines) and the gather stays.
// The values are the same either way.
#ifdef SCENE_LIGHT_INDICES
Light pickLight(int j) {
    Light light = lights[0];
#define PICK_LIGHT(q) light.vector = j == q ? lights[q].vector : light.vector; light.radiance = j == q ? lights[q].radiance : light.radiance;
    SCENE_LIGHT_INDICES(PICK_LIGHT)
#undef PICK_LIGHT
    return light;
}
#else
Light pickLight(int j) { return lights[j]; }
#endif

#ifdef SCENE_MATERIAL_INDICES
void keepMaterialIf(bool hit, int q, inout Material m) {
    m.colorAmbient = hit ? materials[q].colorAmbient : m.colorAmbient;
    m.phong = hit ? materials[q].phong : m.phong;
    m.dielectric = hit ? materials[q].dielectric : m.dielectric;
    m.absorption = hit ? materials[q].absorption : m.absorption;
    m.emission = hit ? materials[q].emission : m.emission;
    m.checkerColor = hit ? materials[q].checkerColor : m.checkerColor;
    m.checkerEmission = hit ? materials[q].checkerEmission : m.checkerEmission;
    m.checkerOffset = hit ? materials[q].checkerOffset : m.checkerOffset;
}

Material pickMaterial(int k) {
    int index = objects[k].info.y;
    Material m = materials[0];
#define PICK_MATERIAL(q) keepMaterialIf(index == q, q, m);
    SCENE_MATERIAL_INDICES(PICK_MATERIAL)
#undef PICK_MATERIAL
    return m;
}
#else
Material pickMaterial(int k) { return materials[objects[k].info.y]; }
#endif

// The light a surface's colour C takes at p, the bracket of
// E + C * (k_a A + sum_j L_j V_j [n.l > 0] (k_d n.l + k_s max(0, r.v)^p)).
vec3 lightAt(Material m, vec3 p, vec3 n, vec3 v, uint mask) {
    vec3 lit = m.colorAmbient.a * ambient.rgb;
#ifdef HAS_LIGHTS
    float kd = m.phong.x, ks = m.phong.y;
    if (kd > 0.0 || ks > 0.0) {
        for (int j = 0; j < NUM_LIGHTS; ++j) {
            Light light = pickLight(j);
            vec3 l;
            float dist;
            if (light.vector.w > 0.5) { l = -light.vector.xyz; dist = INF; }
            else { vec3 tl = light.vector.xyz - p; dist = length(tl); l = tl / dist; }
            float ndl = dot(n, l);
            if (ndl <= 0.0) continue;
            vec3 r = 2.0 * ndl * n - l;
            // max(0, r.v)^p; pow() of a tiny or denormal base returns garbage
            // on some drivers (llvmpipe gave 2^63), and below 1e-6 the term is
            // far under one display step anyway.
            float rv = dot(r, v);
            float spec = (ks > 0.0 && rv > 1e-6) ? ks * pow(min(rv, 1.0), m.phong.z) : 0.0;
            float term = kd * ndl + spec;
            // A term of zero adds nothing whatever the light's visibility: no
            // shadow ray.  That is most of a glass's (diffuse 0, a highlight
            // of shininess 200: r.v^200 is 0 in float32 below r.v = 0.65),
            // and the shadow rays through glass cross every medium on the way.
            if (term <= 0.0) continue;
            // Leave the surface along its normal: at a grazing light a start
            // offset along l alone would not clear the hit point's error.
            // It aims at a point light from where it starts and ends short
            // of it by the light's own offset: a light on a surface (a lamp
            // on the floor, or 1e-300 above it) is not shadowed by that
            // surface, as a ray leaving a surface does not meet it again
            // (it was salt and pepper, and along l from the offset start the
            // ray passed under the light and met the floor first).
            vec3 o = p + surfaceEps(p) * n;
            vec3 ls = l;
            float reach = INF;
            if (light.vector.w <= 0.5) {
                vec3 to = light.vector.xyz - o;
                reach = length(to);
                ls = to / reach;
                reach -= surfaceEps(light.vector.xyz);
            }
            vec3 vis = shadowTransmittance(o, ls, reach, mask);
            if (maxComponent(vis) <= 0.0) continue;
            lit += light.radiance.rgb * vis * term;
        }
    }
#endif
    return lit;
}
