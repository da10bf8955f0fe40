"""Relief height maps: deterministic bytes, and a sampler that is GL_LINEAR + REPEAT (u) +
CLAMP_TO_EDGE (v) with texel centres at (i + 0.5)/W, as the GLSL sampler must be."""

import numpy as np
import pytest

from plantgen.geometry.skeletons import relief


@pytest.mark.parametrize("name", relief.MATERIALS)
def test_maps_are_deterministic_uint8(name):
    a = relief.height_map(name, (64, 48))
    b = relief._GENERATORS[name if name in relief._GENERATORS else "bark"]  # generator exists
    assert callable(b)
    assert a.shape == (64, 48) and a.dtype == np.uint8
    relief._cached.cache_clear()
    assert np.array_equal(a, relief.height_map(name, (64, 48)))


def test_leaf_is_flat_and_others_have_relief():
    assert relief.height_map("leaf").max() == 0
    for name in ("bark", "cactus", "stone", "aloe"):
        m = relief.height_map(name)
        assert int(m.max()) - int(m.min()) > 40, name


def test_unknown_material_falls_back_to_bark():
    assert np.array_equal(relief.height_map("mystery"), relief.height_map("bark"))
    assert relief.default_shell("mystery") == relief.DEFAULT_SHELL["bark"]


def test_cactus_ribs_run_along_the_axis():
    m = relief.height_map("cactus").astype(float)
    # variation across u (ribs) is far larger than along v
    assert np.abs(np.diff(m, axis=1)).mean() > 3 * np.abs(np.diff(m, axis=0)).mean()


def test_sampler_hits_texel_centres_exactly():
    m = relief.height_map("stone", (16, 32))
    j, i = np.meshgrid(np.arange(16), np.arange(32), indexing="ij")
    got = relief.sample_height(m, (i + 0.5) / 32, (j + 0.5) / 16)
    assert np.allclose(got, m / 255.0, atol=1e-12)


def test_sampler_is_bilinear_between_centres():
    m = np.array([[0, 255], [255, 0]], dtype=np.uint8)
    assert relief.sample_height(m, 0.5, 0.5) == pytest.approx(0.5)
    assert relief.sample_height(m, 0.5, 0.25) == pytest.approx(0.5)
    # a quarter of a texel right of centre (0, 0): 1/4 of the way to texel (0, 1)
    assert relief.sample_height(m, 0.25 + 0.125, 0.25) == pytest.approx(0.25)


def test_u_repeats_and_v_clamps():
    m = relief.height_map("bark", (32, 32))
    rng = np.random.default_rng(0)
    u, v = rng.random(500), rng.random(500)
    assert np.allclose(relief.sample_height(m, u, v), relief.sample_height(m, u + 3.0, v))
    assert np.allclose(relief.sample_height(m, u, v), relief.sample_height(m, u - 1.0, v))
    # u wraps between the last and the first column
    x = relief.sample_height(m, np.array([0.0]), np.array([0.5 / 32]))
    assert x[0] == pytest.approx((int(m[0, -1]) + int(m[0, 0])) / 2 / 255)
    # v clamps to the edge rows
    assert np.allclose(relief.sample_height(m, u, -5.0), relief.sample_height(m, u, 0.0))
    assert np.allclose(relief.sample_height(m, u, 7.0), relief.sample_height(m, u, 1.0))


def test_height_maps_stack_one_layer_per_material():
    maps, rep = relief.height_maps(["bark", "leaf", "stone"], (8, 8))
    assert maps.shape == (3, 8, 8) and maps.dtype == np.uint8 and rep.shape == (3, 2)
    assert maps[1].max() == 0
