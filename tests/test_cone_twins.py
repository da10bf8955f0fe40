"""The GLSL cone maths (shaders/cone.glsl) and its numpy twins agree on the GPU's float32.

A small program includes cone.glsl and evaluates difference_of_products, solve_quadratic
and plane_height per pixel on inputs from a float texture; the numpy twins
(plantgen.geometry.rays.reference, plantgen.geometry.skeletons.frusta) evaluate the same inputs in
float32.
"""

from __future__ import annotations

import shutil
from fractions import Fraction

import numpy as np
import pytest

from plantgen._resources import shaders_dir
from plantgen.geometry.rays.reference import difference_of_products, solve_quadratic
from plantgen.geometry.skeletons.frusta import plane_height
from plantgen.gl.context import release_framebuffer
from plantgen.gl.shaders import build_program

PROGRAM = """
#include "cone.glsl"
#if defined VERTEX_SHADER
void main() {
    vec2 corner = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);   // one full-screen triangle
    gl_Position = vec4(2.0 * corner - 1.0, 0.0, 1.0);
}
#elif defined FRAGMENT_SHADER
uniform sampler2D first;    // per pixel: a, b, c, d (mode 0) or gap, n_axis, n_radial, r1 (mode 1)
uniform sampler2D second;   // per pixel: k (mode 1)
uniform int mode;
out vec4 result;
void main() {
    vec4 x = texelFetch(first, ivec2(gl_FragCoord.xy), 0);
    if (mode == 0) {
        float t_q, t_c;
        float disc = solve_quadratic(x.x, x.y, x.z, t_q, t_c);
        result = vec4(disc, t_q, t_c, difference_of_products(x.x, x.y, x.z, x.w));
    } else {
        float rise;
        float k = texelFetch(second, ivec2(gl_FragCoord.xy), 0).x;
        result = vec4(plane_height(x.x, x.y, x.z, x.w, k, 0.0, rise), rise, 0.0, 0.0);
    }
}
#endif
"""

SIDE = 64


@pytest.fixture
def evaluate(gl_ctx, tmp_path):
    shutil.copy(shaders_dir() / "cone.glsl", tmp_path / "cone.glsl")
    (tmp_path / "twins.glsl").write_text(PROGRAM)
    program = build_program(gl_ctx, "twins.glsl", directory=tmp_path)
    vao = gl_ctx.vertex_array(program, [])
    fbo = gl_ctx.framebuffer([gl_ctx.texture((SIDE, SIDE), 4, dtype="f4")])

    def run(mode, first, second=None):
        textures = []
        for unit, values in enumerate((first, np.zeros_like(first) if second is None else second)):
            tex = gl_ctx.texture((SIDE, SIDE), 4, np.ascontiguousarray(values, np.float32).tobytes(),
                                 dtype="f4")
            tex.filter = (gl_ctx.NEAREST, gl_ctx.NEAREST)
            tex.use(unit)
            textures.append(tex)
        program["first"].value, program["second"].value = 0, 1
        if "mode" in program:
            program["mode"].value = mode
        fbo.use()
        fbo.viewport = (0, 0, SIDE, SIDE)
        vao.render(mode=gl_ctx.TRIANGLES, vertices=3)
        out = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(SIDE * SIDE, 4)
        for tex in textures:
            tex.release()
        return out.copy()

    yield run
    vao.release()
    release_framebuffer(fbo)


def _ulps(x, y):
    """|x - y| in float32 ulps of y (finite entries)."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float32)
    return np.abs(x - y) / np.spacing(np.abs(y)).astype(np.float64)


def test_quadratic_twins_agree_and_the_gpu_discriminant_does_not_cancel(evaluate):
    rng = np.random.default_rng(3)
    n = SIDE * SIDE
    a = rng.uniform(0.1, 2.0, n)
    b = rng.uniform(-3.0, 3.0, n)
    # half the pixels: b² ≈ a·c to 1e-5 (a ray grazing a silhouette); the rest: anything
    c = np.where(np.arange(n) % 2 == 0, b * b / a * (1 + rng.uniform(-1e-5, 1e-5, n)),
                 rng.uniform(-4.0, 4.0, n))
    d = rng.uniform(0.1, 2.0, n)
    x = np.stack([a, b, c, d], axis=1).astype(np.float32)
    gpu = evaluate(0, x)
    disc, t_q, t_c = solve_quadratic(x[:, 0], x[:, 1], x[:, 2])
    dop = difference_of_products(x[:, 0], x[:, 1], x[:, 2], x[:, 3])
    assert np.all(_ulps(gpu[:, 0], disc) <= 1) and np.all(_ulps(gpu[:, 3], dop) <= 1)
    # the roots go through sqrt and two divisions (GLSL allows 2.5 ulps for a division)
    real = disc >= 0
    assert np.all(_ulps(gpu[real, 1], t_q[real]) <= 4) and np.all(_ulps(gpu[real, 2], t_c[real]) <= 4)
    assert np.array_equal(gpu[:, 0] >= 0, real)
    # the GPU's discriminant is the exact one to an ulp, even where b² and a·c cancel
    exact = np.array([float(Fraction(float(bb)) ** 2 - Fraction(float(aa)) * Fraction(float(cc)))
                      for aa, bb, cc in x[:, :3]])
    assert np.all(_ulps(gpu[:, 0], exact.astype(np.float32)) <= 1.5)


def test_plane_height_twins_agree(evaluate):
    rng = np.random.default_rng(4)
    n = SIDE * SIDE
    gap = rng.uniform(-2, 2, n)
    n_axis = rng.uniform(0.3, 1.0, n)
    n_radial = rng.uniform(-0.7, 0.7, n)
    r1 = rng.uniform(0.01, 1.0, n)
    k = rng.uniform(-0.3, 0.3, n)
    x = np.stack([gap, n_axis, n_radial, r1], axis=1).astype(np.float32)
    ks = np.zeros((n, 4), np.float32)
    ks[:, 0] = k
    gpu = evaluate(1, x, ks)
    y, rise = plane_height(x[:, 0], x[:, 1], x[:, 2], x[:, 3], ks[:, 0])
    assert y.dtype == np.float32
    # the GPU may fuse a product into its sum: an ulp of the terms, not of the result
    terms = np.abs(x[:, 0]) + np.abs(x[:, 3] * x[:, 2])
    assert np.all(np.abs(gpu[:, 1] - rise) <= 2 * np.spacing(np.abs(x[:, 1]) + np.abs(ks[:, 0] * x[:, 2])))
    assert np.all(np.abs(gpu[:, 0] - y) <= 4 * np.spacing(terms) / np.abs(rise) + 4 * np.spacing(np.abs(y)))
