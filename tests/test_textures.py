"""The relief baked into textures (plantgen.geometry.meshes.textures): sizes from the map's own
detail, the normal map against the ray caster's shading of relief (its numpy twin,
plantgen.geometry.meshes.mesh.generator_points with relief_slope), the base colour against the
palette, tangents against the frustum's own frame, and the PNG writer against Pillow."""

from __future__ import annotations

import io

import numpy as np
import pytest

from plantgen.exporters.textures import bake_textures, texture_image
from plantgen.geometry.meshes import textures as tx
from plantgen.geometry.meshes.mesh import columns_around, generator_points, tessellate
from plantgen.geometry.skeletons import relief
from plantgen.geometry.skeletons.materials import material_palette
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.images import png_bytes


def _cylinder(radius=0.5, length=2.0, material="cactus"):
    skeleton = Skeleton(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, length, 0.0]]), np.array([radius]),
                        np.array([radius]), np.array([-1]), np.array([False]), np.zeros(1, int), (material,))
    return skin_skeleton(skeleton)


@pytest.mark.parametrize("name", ["bark", "cactus", "stone", "aloe"])
def test_shipped_maps_need_their_native_size(name):
    # every shipped map has detail down to its texel (noise): halving an axis moves texels
    # by more than one 8-bit step, so the texture keeps the renderers' 256 x 256
    size = tx.texture_size(relief.height_map(name))
    assert size.shape == size.native == (256, 256)
    assert size.error <= tx.SIZE_TOLERANCE


def test_size_follows_the_detail():
    u = (np.arange(64) + 0.5) / 64
    ribs = np.rint(127.5 + 127.5 * np.cos(2 * np.pi * 3 * u)).astype(np.uint8)
    along_u_only = np.broadcast_to(ribs, (32, 64))
    size = tx.texture_size(along_u_only)
    assert size.shape[0] == 1 and size.shape[1] <= 64 and size.error <= 1.0
    assert tx.texture_size(np.full((16, 16), 90, np.uint8)).shape == (1, 1)
    # the chosen size, read back at the native texel centres, is within one step
    small = tx.resample_height(along_u_only, size.shape)
    assert np.max(np.abs(tx._read_back(small, (32, 64)) * 255 - along_u_only)) <= 1.0


def test_flat_relief_bakes_the_unperturbed_normal():
    normal = tx.bake_normal_map(np.full((8, 8), 0.4), 0.15, 0.3)
    assert np.all(normal == [128, 128, 255])


def test_normal_map_leans_against_the_slope():
    # height rising along +u tilts the normal towards -u (x < 0); rising along +v tilts it
    # towards -v, which glTF's "up in the image" (+y) is
    u = (np.arange(32) + 0.5) / 32
    ramp_u = np.broadcast_to(0.5 + 0.3 * np.sin(2 * np.pi * u), (16, 32))
    n = tx.decode_normal(tx.bake_normal_map(ramp_u, 0.2, 0.3))
    assert n[5, 0, 0] < -0.01 and abs(n[5, 0, 1]) < 1e-2          # sin rising at u ~ 0
    v = (np.arange(32) + 0.5) / 32
    ramp_v = np.broadcast_to((0.5 + 0.3 * np.sin(2 * np.pi * v))[:, None], (32, 16))
    n = tx.decode_normal(tx.bake_normal_map(ramp_v, 0.2, 0.3))
    assert n[1, 3, 1] > 0.01 and abs(n[1, 3, 0]) < 1e-2


@pytest.mark.parametrize("name, length", [("cactus", 2.0), ("stone", 0.7), ("bark", 5.0)])
def test_normal_map_is_the_ray_casters_relief_normal(name, length):
    """On a segment of the aspect it was baked for, the decoded map in the mesh's tangent
    frame (T around, B = -v, N the interpolated normal) is the ray caster's tilted normal,
    texel by texel, to the 8-bit encoding (under 0.5 degrees)."""
    radius = 0.5
    frusta = _cylinder(radius, length, name)
    shell = frusta.shell[0]
    native = relief.height_map(name)
    h, w = native.shape
    baked = tx.bake_material(name, np.array([radius / length]))
    assert baked.aspect == pytest.approx(radius / length)
    j, i = np.meshgrid(np.arange(0, h, 7), np.arange(0, w, 5), indexing="ij")
    u, v = (i + 0.5) / w, (j + 0.5) / h
    dw_du = (relief.sample_height(native, u + 1 / w, v) - relief.sample_height(native, u - 1 / w, v)) * w / 2
    dw_dv = (relief.sample_height(native, u, v + 1 / h) - relief.sample_height(native, u, v - 1 / h)) * h / 2
    rows = np.zeros_like(u, dtype=int)
    _, exact = generator_points(frusta, rows, u, v, relief_slope=(shell * dw_du, shell * dw_dv))
    points, plain = generator_points(frusta, rows, u, v)
    e_r = points.copy()
    e_r[..., 1] = 0
    e_r /= np.linalg.norm(e_r, axis=-1, keepdims=True)
    around = np.cross(frusta.axis[0], e_r)
    along = np.broadcast_to(frusta.axis[0], around.shape)
    t = tx.decode_normal(baked.normal[j, i])
    world = t[..., :1] * around - t[..., 1:2] * along + t[..., 2:] * plain
    world /= np.linalg.norm(world, axis=-1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip(np.sum(world * exact, axis=-1), -1, 1)))
    assert angle.max() < 0.5, angle.max()
    tilt = np.degrees(np.arccos(np.clip(np.sum(plain * exact, axis=-1), -1, 1)))
    assert tilt.max() > 5.0           # the relief does tilt the normal: the test has teeth


def test_base_colour_is_the_ray_casters_albedo():
    palette = material_palette(["bark"])
    colour = tx.bake_base_colour("bark", np.array([[0.0, 1.0, 0.5]]))
    assert np.array_equal(colour[0, 0], tx.linear_to_srgb(palette["dark"][0]))
    assert np.array_equal(colour[0, 1], tx.linear_to_srgb(palette["light"][0]))
    mid = tx.linear_to_srgb((palette["dark"][0].astype(float) + palette["light"][0]) / 2)
    assert np.array_equal(colour[0, 2], mid)
    assert tx.linear_to_srgb(np.array([0.0, 0.0031308, 0.5, 1.0])).tolist() == [0, 10, 188, 255]


def test_materials_without_relief_bake_nothing():
    assert tx.bake_material("leaf") is None


def test_aspects_and_tangents_of_a_cylinder():
    radius, length = 0.5, 2.0
    frusta = _cylinder(radius, length)
    mesh = tessellate(frusta, 2)
    aspects = tx.mesh_aspects(mesh)
    [(aspect, area, rho)] = aspects.values()
    # chords around: |dP/du| = N·2r·sin(π/N) of 2πr (0.16 % short at N = 32)
    assert np.allclose(aspect, radius / length, rtol=3e-3)
    assert np.allclose(rho, radius, rtol=3e-3)
    assert len(aspect) == mesh.n_lateral and np.all(area > 0)
    tangents = tx.mesh_tangents(mesh.vertices, mesh.normals, mesh.uv, mesh.faces)
    assert tangents.shape == (len(mesh.vertices), 4) and tangents.dtype == np.float32
    assert np.allclose(np.linalg.norm(tangents[:, :3], axis=1), 1, atol=1e-6)
    assert set(np.unique(tangents[:, 3]).tolist()) <= {-1.0, 1.0}
    assert np.allclose(np.sum(tangents[:, :3] * mesh.normals, axis=1), 0, atol=1e-5)
    lateral = np.unique(mesh.faces[:mesh.n_lateral])
    capped = np.unique(mesh.faces[mesh.n_lateral:])
    side = np.setdiff1d(lateral, capped)
    p = mesh.vertices[side]
    e_r = p * [1, 0, 1] / np.linalg.norm(p * [1, 0, 1], axis=1, keepdims=True)
    around = np.cross([0.0, 1.0, 0.0], e_r)
    assert np.min(np.sum(tangents[side, :3] * around, axis=1)) > 0.999
    bitangent = np.cross(mesh.normals[side], tangents[side, :3]) * tangents[side, 3:]
    assert np.max(bitangent[:, 1]) < -0.999          # glTF's +y of the map: towards -v, down the axis
    assert columns_around(2) == 32


def test_one_aspect_is_exact_and_a_spread_costs():
    height = relief.height_map("stone") / 255.0
    same = tx.aspect_error(height, 0.1, 0.3, np.full(10, 0.3), np.ones(10))
    assert same["worst"] < 1e-3
    spread = tx.aspect_error(height, 0.1, 0.3, np.array([0.1, 0.3, 0.9]), np.ones(3))
    wider = tx.aspect_error(height, 0.1, 0.3, np.array([0.03, 0.3, 3.0]), np.ones(3))
    assert 0 < spread["mean"] < wider["mean"] and spread["worst"] < wider["worst"]


def test_bake_textures_by_material_name():
    a = tessellate(_cylinder(0.5, 2.0, "cactus"), 1)
    b = tessellate(_cylinder(0.5, 0.5, "cactus"), 1)
    baked = bake_textures([a, b, None])
    assert list(baked.materials) == ["cactus"] and baked.kinds == ("basecolor", "normal", "height")
    # the median over both meshes' faces (equal areas: each mesh half the weight)
    assert 0.25 * 0.99 <= baked.get("cactus").aspect <= 1.0 * 1.01
    assert bake_textures([a], displaced=True).kinds == ("basecolor",)


def test_png_bytes_read_back_by_pillow():
    from PIL import Image as pil

    rng = np.random.default_rng(3)
    for image in (rng.integers(0, 256, (5, 7), dtype=np.uint8), rng.integers(0, 256, (4, 3, 3), dtype=np.uint8)):
        back = np.asarray(pil.open(io.BytesIO(png_bytes(image))))
        assert np.array_equal(back, image)


def test_v_up_images_are_flipped_with_green_negated():
    baked = bake_textures([tessellate(_cylinder(), 1)]).get("cactus")
    up = texture_image(baked, "normal", v_up=True)
    assert np.array_equal(up[::-1, :, 0], baked.normal[..., 0])
    assert np.array_equal(255 - up[::-1, :, 1], baked.normal[..., 1])
    assert np.array_equal(texture_image(baked, "height", v_up=True)[::-1], baked.height)
