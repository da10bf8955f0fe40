"""Raster renderer (GS): same view and shading as the ray caster, converging to it as m grows."""

from __future__ import annotations

import numpy as np
import pytest
from test_mesh import BENT, chain_frusta, concat_frusta

from plantgen.geometry.meshes.mesh import tessellate
from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.skeletons.frusta import frusta_bounds
from plantgen.gl.raster import RasterRenderer, gs_buffer_bytes
from plantgen.gl.raycast import Raycaster
from plantgen.gl.records import rc_buffer_bytes

SIZE = (200, 150)


def model():
    trunk = chain_frusta(BENT, [0.3, 0.25, 0.25, 0.2, 0.15])
    branch = chain_frusta([[0, 1, 0], [0.7, 1.5, 0.2], [1.2, 2.2, 0.4]], [0.12, 0.1, 0.06])
    return concat_frusta(trunk, branch)


def view(frusta):
    b = frusta_bounds(frusta)
    centre = b.mean(axis=0)
    return Camera(tuple(centre + [1.2, 0.6, 3.2]), tuple(centre), (0, 1, 0), 45.0, *SIZE)


def compare(rc, gs):
    """(mean colour difference in 0..255, fraction of pixels covered by one image only,
    median relative distance difference where both hit)."""
    hit_rc, hit_gs = np.isfinite(rc.distance), np.isfinite(gs.distance)
    both = hit_rc & hit_gs
    colour = np.abs(rc.color.astype(float) - gs.color.astype(float)).mean()
    coverage = float((hit_rc != hit_gs).mean())
    dist = float(np.median(np.abs(rc.distance[both] - gs.distance[both]) / rc.distance[both]))
    return colour, coverage, dist


def test_gs_images_converge_to_the_rc_image_as_m_grows(gl_ctx):
    frusta = model()
    camera = view(frusta)
    rc = Raycaster(gl_ctx).render(frusta, camera)
    assert np.isfinite(rc.distance).mean() > 0.05  # the model fills a fair part of the view
    raster = RasterRenderer(gl_ctx)
    scores = []
    for m in range(4):
        gs = raster.render(tessellate(frusta, m), frusta, camera)
        assert gs.stats.draw_calls == 1
        scores.append(compare(rc, gs))
    colour, coverage, dist = (np.array(s) for s in zip(*scores, strict=True))
    assert np.all(np.diff(colour) < 0), colour
    assert np.all(np.diff(coverage) <= 0) and coverage[-1] < coverage[0] / 4, coverage
    # At m = 3 the two images differ by under one grey level on average, and the depths
    # agree to a fraction of a percent: same camera, light, palette and shading.
    assert colour[-1] < 1.0 and dist[-1] < 2e-3
    raster.release()


def test_the_sky_and_the_shading_are_the_ray_casters(gl_ctx):
    """Background pixels are identical; lit pixels of a fine mesh match RC's closely."""
    frusta = model()
    camera = view(frusta)
    rc = Raycaster(gl_ctx).render(frusta, camera)
    gs = RasterRenderer(gl_ctx).render(tessellate(frusta, 4), frusta, camera)
    sky = ~np.isfinite(rc.distance) & ~np.isfinite(gs.distance)
    assert np.array_equal(rc.color[sky], gs.color[sky])
    both = np.isfinite(rc.distance) & np.isfinite(gs.distance)
    per_pixel = np.abs(rc.color[both].astype(int) - gs.color[both].astype(int)).max(axis=1)
    assert np.quantile(per_pixel, 0.95) <= 3


def test_relief_geometry_is_drawn_outside_the_base_cone(gl_ctx):
    """GS+R displaces the skin outwards: it covers every pixel GS covers, and more."""
    frusta = chain_frusta(BENT, 0.2, shell=0.08)
    camera = view(frusta)

    def bumps(material, u, v):
        return 0.5 + 0.5 * np.sin(2 * np.pi * 6 * u) * np.sin(2 * np.pi * 2 * v)

    raster = RasterRenderer(gl_ctx)
    flat = raster.render(tessellate(frusta, 3), frusta, camera)
    bumpy = raster.render(tessellate(frusta, 3, relief=True, height=bumps), frusta, camera)
    hit_flat, hit_bumpy = np.isfinite(flat.distance), np.isfinite(bumpy.distance)
    assert hit_bumpy.sum() > hit_flat.sum()
    assert (hit_flat & ~hit_bumpy).mean() < 1e-3
    both = hit_flat & hit_bumpy
    assert np.median(bumpy.distance[both] - flat.distance[both]) < 0  # nearer to the eye


def test_gs_buffers_approach_fourfold_growth_per_level_and_dwarf_rc_records():
    frusta = model()
    n = len(frusta.length)
    sizes = [gs_buffer_bytes(tessellate(frusta, m)) for m in range(4)]
    ratios = np.array(sizes[1:]) / np.array(sizes[:-1])
    # Triangles grow 4x per level; vertices too, up to the shared end rings and caps.
    assert np.all(np.diff(ratios) > 0) and ratios[-1] > 3.5 and np.all(ratios < 4), ratios
    # Even the coarsest mesh needs more GPU bytes than the ray caster's records.
    assert sizes[0] > rc_buffer_bytes(n)


def test_gs_plus_r_converges_to_the_relief_ray_caster(gl_ctx):
    """Same height maps, displaced geometry and tilted normals: the difference falls with m."""
    from plantgen.gl.raycast import RaycastSettings

    frusta = chain_frusta(BENT, [0.3, 0.25, 0.25, 0.2, 0.15], shell=0.06)
    camera = view(frusta)
    rc = Raycaster(gl_ctx).render(frusta, camera, RaycastSettings(relief=True, linear_steps=64,
                                                                  binary_steps=8))
    raster = RasterRenderer(gl_ctx)
    scores = [compare(rc, raster.render(tessellate(frusta, m, relief=True), frusta, camera))
              for m in (0, 2, 4)]
    colour, coverage, dist = (np.array(s) for s in zip(*scores, strict=True))
    assert np.all(np.diff(colour) < 0) and np.all(np.diff(coverage) <= 0), (colour, coverage)
    assert coverage[-1] < 0.01 and dist[-1] < 5e-3, (coverage, dist)


# ---------------------------------------------------------------- shadows and ground (GS)
# The Table 1 scenes with shadow maps (well, desert, oasis, cacti) time GS with the same
# passes as RC: the mesh and the ground write the light's depth map, both sample it.
from test_shadows import GROUND, column, light_towards, top_down_camera  # noqa: E402

from plantgen.geometry.skeletons.skin import skin_skeleton  # noqa: E402
from plantgen.gl.passes import ShadowSettings  # noqa: E402


@pytest.mark.parametrize("elevation", [60.0, 10.0, 3.0])
def test_a_faceted_convex_column_shadows_only_its_terminator_band(gl_ctx, elevation):
    """A tessellated frustum is convex, so a facet that faces the light is never in shadow:
    wherever the true surface normal faces the light by more than the facets can deviate
    from it (half a facet angle), the pixel is the same with shadows on as off, for grazing
    light too (the facet's own plane is the receiver plane, so no acne). Only near the
    terminator, where a facet already faces away while the smooth shading normal (8) still
    faces the light, may the mesh darken itself: the faceted geometry really blocks the
    light there (the 'shadow terminator' cost of GS), and that band narrows as m grows."""
    r0, r1, height = RADIUS_COLUMN
    frusta = skin_skeleton(column(radius=r0, r_top=r1, height=height))
    to_light = light_towards(elevation, azimuth_deg=10.0)   # lit side and terminator in view
    camera = Camera((3.0, 2.5, 4.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 40.0, 96, 96)
    eye, dirs = camera.rays()
    raster = RasterRenderer(gl_ctx)
    for m in (0, 2):
        mesh = tessellate(frusta, m)
        plain = raster.render(mesh, frusta, camera, material_names=("bark",), light_dir=to_light)
        shadowed = raster.render(mesh, frusta, camera, material_names=("bark",), light_dir=to_light,
                                 shadows=ShadowSettings(resolution=256))
        assert plain.stats.passes == ["sky", "frusta"]
        assert shadowed.stats.passes == ["shadow", "sky", "frusta"]
        hit = np.isfinite(plain.distance)
        p = eye[hit] + plain.distance[hit, None].astype(np.float64) * dirs[hit]
        radial = p * [1, 0, 1]
        radial /= np.linalg.norm(radial, axis=1, keepdims=True)
        normal = radial + [0.0, (r0 - r1) / height, 0.0]          # e_r - k·axis
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        normal[p[:, 1] > height - 1e-3] = [0.0, 1.0, 0.0]          # the tip's cap
        facing = normal @ to_light
        half_facet = np.pi / (8 * 2 ** m)
        surely_lit = facing > np.sin(half_facet) + 0.02
        assert surely_lit.sum() > 200
        diff = np.abs(plain.color[hit].astype(int) - shadowed.color[hit].astype(int)).max(axis=1)
        assert diff[surely_lit].max() <= 3, (m, diff[surely_lit].max(), (diff[surely_lit] > 3).sum())
    raster.release()


RADIUS_COLUMN = (0.3, 0.15, 2.0)


@pytest.mark.parametrize("elevation", [45.0, 12.0])
def test_gs_ground_shadow_matches_the_ray_casters(gl_ctx, elevation):
    """Column on the ground, shadows on: the ground the fine mesh shadows is the ground the
    ray caster shadows (whose shadow tests check against analytic occlusion). Outside a
    band of a few texels at the shadow's edge, ground pixels agree to a few grey levels,
    and the shadow is really there (many ground pixels darkened)."""
    frusta = skin_skeleton(column())
    to_light = light_towards(elevation)
    camera = top_down_camera()
    shadows = ShadowSettings(resolution=512)
    rc = Raycaster(gl_ctx).render(frusta, camera, light_dir=to_light, ground=GROUND, shadows=shadows)
    raster = RasterRenderer(gl_ctx)
    mesh = tessellate(frusta, 3)
    gs = raster.render(mesh, frusta, camera, material_names=("bark",), light_dir=to_light,
                       ground=GROUND, shadows=shadows)
    plain = raster.render(mesh, frusta, camera, material_names=("bark",), light_dir=to_light,
                          ground=GROUND)
    raster.release()
    assert gs.stats.passes == ["shadow", "sky", "ground", "frusta"]
    assert plain.stats.passes == ["sky", "ground", "frusta"]
    eye, dirs = camera.rays()
    points = eye + rc.distance[..., None].astype(np.float64) * dirs
    ground = (np.isfinite(rc.distance) & np.isfinite(gs.distance)
              & (np.abs(points[..., 1]) < 1e-3))
    lum = lambda r: r.color.astype(int).sum(axis=-1)   # noqa: E731
    darkened = (lum(plain) - lum(gs))[ground] > 20
    assert darkened.sum() > 20
    differ = np.abs(lum(rc) - lum(gs))[ground] > 6
    # the edge band: a 16-gon's silhouette moves the shadow edge by < 2 % of the radius
    assert differ.mean() < 0.01, (differ.sum(), ground.sum())


def test_released_renderers_free_their_targets_and_render_again_the_same(gl_ctx):
    """release() frees the framebuffer, height textures and shadow map of both renderers
    (the bench makes one raster renderer per configuration); a released renderer makes
    them again and renders the same image, shadows included."""
    frusta = skin_skeleton(column())
    camera = top_down_camera()
    shadows = ShadowSettings(resolution=128)
    mesh = tessellate(frusta, 1)
    raster, caster = RasterRenderer(gl_ctx), Raycaster(gl_ctx)
    draw = {"gs": lambda: raster.render(mesh, frusta, camera, material_names=("bark",),
                                        ground=GROUND, shadows=shadows),
            "rc": lambda: caster.render(frusta, camera, ground=GROUND, shadows=shadows)}
    for name, renderer in (("gs", raster), ("rc", caster)):
        first = draw[name]()
        renderer.release()
        assert renderer._fbo is None and renderer._shadow.texture is None and not renderer._heights._textures
        again = draw[name]()
        assert np.array_equal(first.color, again.color), name
        assert np.array_equal(first.distance, again.distance), name
        renderer.release()
