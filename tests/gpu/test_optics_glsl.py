"""The shader's own Fresnel and refraction code (shaders/lib/optics.glsl),
run on the GPU for every entry of shared/spec/test-vectors.md."""

from __future__ import annotations

import math

import moderngl
import numpy as np
import pytest

from viewer.gpu.shaders import load_source

from vectors import ANGLES, R_TABLE, T_TABLE
from vectors import NEAR_CRITICAL as _NEAR

NEAR_CRITICAL = [(n1, n2, a, r) for (n1, n2), rows in _NEAR.items() for a, r in rows]  # (n1, n2, angle, R)

_FRAG = """#version 330 core
#include "lib/optics.glsl"
uniform sampler2D cases;   // per texel: cos_i, n1, n2
out vec4 result;           // R, angle of the refracted ray (degrees), TIR flag
void main() {
    vec3 c = texelFetch(cases, ivec2(gl_FragCoord.xy), 0).xyz;
    float cosI = c.x, n1 = c.y, n2 = c.z;
    float cosT;
    float R = fresnelDielectric(cosI, n1, n2, cosT);
    // incoming ray in the xy plane hitting a surface with normal +y
    vec3 n = vec3(0.0, 1.0, 0.0);
    vec3 d = vec3(sqrt(max(0.0, 1.0 - cosI * cosI)), -cosI, 0.0);
    float angle = -1.0;
    if (R < 1.0) {
        vec3 t = refractDir(d, n, n1 / n2, cosI, cosT);
        angle = degrees(atan(t.x, -t.y));
    }
    result = vec4(R, angle, R >= 1.0 ? 1.0 : 0.0, 1.0);
}
"""


def _run(gl, cases: list[tuple[float, float, float]]) -> np.ndarray:
    import tempfile
    from pathlib import Path

    from viewer.gpu.shaders import shader_root

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (root / "lib").mkdir()
        (root / "lib" / "optics.glsl").write_text((shader_root() / "lib" / "optics.glsl").read_text())
        (root / "t.frag").write_text(_FRAG)
        fs = load_source("t.frag", root=root).text
    vs = (shader_root() / "fullscreen.vert").read_text()
    prog = gl.program(vertex_shader=vs, fragment_shader=fs)
    n = len(cases)
    tex = gl.texture((n, 1), 3, np.array(cases, "f4").tobytes(), dtype="f4")
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    fbo = gl.simple_framebuffer((n, 1), components=4, dtype="f4")
    fbo.use()
    tex.use(0)
    prog["cases"] = 0
    vao = gl.vertex_array(prog, [])
    vao.render(moderngl.TRIANGLES, vertices=3)
    out = np.frombuffer(fbo.read(components=4, dtype="f4"), "f4").reshape(n, 4)
    for r in (vao, prog, tex, fbo):
        r.release()
    return out


def test_fresnel_and_snell_match_test_vectors(gl):
    cases, expect_r, expect_t = [], [], []
    for (n1, n2), rs in R_TABLE.items():
        for ang, r, t in zip(ANGLES, rs, T_TABLE[(n1, n2)]):
            cases.append((math.cos(math.radians(ang)), n1, n2))
            expect_r.append(1.0 if r is None else r)
            expect_t.append(t)
    out = _run(gl, cases)
    for k, (c, er, et) in enumerate(zip(cases, expect_r, expect_t)):
        # float32 shader maths: 2e-6 absolute on R (the table has 6 decimals)
        assert out[k, 0] == pytest.approx(er, abs=2e-6), f"R for {c}"
        if et is None:
            assert out[k, 2] == 1.0, f"expected total internal reflection for {c}"
        else:
            assert out[k, 1] == pytest.approx(et, abs=2e-3), f"refraction angle for {c}"


def test_fresnel_near_critical_angle(gl):
    # cos(theta) of angles this close to critical is where float32 loses most;
    # the test vectors sit 0.01 degrees from it.
    cases = [(math.cos(math.radians(a)), n1, n2) for n1, n2, a, _ in NEAR_CRITICAL]
    out = _run(gl, cases)
    for k, (_, _, a, r) in enumerate(NEAR_CRITICAL):
        assert out[k, 0] == pytest.approx(r, abs=2e-3), f"R at {a} degrees"


def test_schlick_is_not_what_the_shader_does(gl):
    # At glass -> water, 61.457 degrees, Schlick's approximation is off by > 0.1.
    n1, n2, a, r = NEAR_CRITICAL[6]
    r0 = ((n1 - n2) / (n1 + n2)) ** 2
    schlick = r0 + (1 - r0) * (1 - math.cos(math.radians(a))) ** 5
    out = _run(gl, [(math.cos(math.radians(a)), n1, n2)])
    assert abs(schlick - r) > 0.1
    assert out[0, 0] == pytest.approx(r, abs=2e-3)


def test_equal_iors_give_no_reflection_at_any_angle(gl):
    # The spec: two media of equal ior meet with R = 0, the ray going
    # straight on.  cos i down to 1e-6 (float32's 1 - cos^2 rounds to 1
    # below 2.4e-4: that was taken for total internal reflection).
    cosines = [1.0, 0.5, 1e-2, 1e-3, 3e-4, 1e-4, 1e-5, 1e-6]
    cases = [(c, n, n) for c in cosines for n in (1.0, 1.33, 1.5)]
    out = _run(gl, cases)
    for k, (c, _, _) in enumerate(cases):
        assert out[k, 0] == 0.0 and out[k, 2] == 0.0, f"R for {cases[k]}"
        assert out[k, 1] == pytest.approx(math.degrees(math.acos(c)), abs=2e-3), f"angle for {cases[k]}"
