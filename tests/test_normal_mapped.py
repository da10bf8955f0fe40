"""GS+N, the relief as a baked normal map on the smooth mesh, against RC+R (GS+POM, the same
maps marched by parallax occlusion mapping: tests/test_parallax_mapped.py): on the body of a
relief frustum seen face-on it shades as the ray caster does (float64 normals against the
reference ray caster, and plantgen's rasteriser against its ray caster); at the
silhouette it does not (the relief's own edge is RC+R's: a normal map has none)."""

from __future__ import annotations

import numpy as np
import pytest
from _relief_frustum import LENGTH, RADIUS, axis_bands, face_on_camera, relief_frustum

from plantgen.geometry.meshes import textures as tx
from plantgen.geometry.meshes.mesh import generator_points, tessellate
from plantgen.geometry.rays.reference import render_reference
from plantgen.geometry.skeletons import relief
from plantgen.geometry.skeletons.skin import skin_skeleton


def _relief_normals(frusta, name, u, v, radial):
    """The ray caster's relief normal (raycast.glsl; its numpy twin generator_points with
    relief_slope) at (u, v) on the concentric cone of radius ``radial``."""
    hmap = relief.height_map(name)
    h, w = hmap.shape
    shell = frusta.shell[0]
    du = (relief.sample_height(hmap, u + 1 / w, v) - relief.sample_height(hmap, u - 1 / w, v)) * w / 2
    dv = (relief.sample_height(hmap, u, v + 1 / h) - relief.sample_height(hmap, u, v - 1 / h)) * h / 2
    _, normals = generator_points(frusta, np.zeros(u.shape, int), u, v, offset=radial - RADIUS,
                                  relief_slope=(shell * du, shell * dv))
    return normals


def _mapped_normals(normal_map, u, v, n, points):
    """What a glTF reader shades with: the map sampled bilinearly (repeat) at (u, v),
    decoded, in the frame (T along +u, B = cross(N, T)·w along -v, N)."""
    m = normal_map.astype(np.float64)
    h, w = m.shape[:2]
    x, y = u * w - 0.5, v * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    i0, j0 = np.mod(x0, w).astype(int), np.mod(y0, h).astype(int)
    i1, j1 = (i0 + 1) % w, (j0 + 1) % h
    texel = (m[j0, i0] * (1 - fx) + m[j0, i1] * fx) * (1 - fy) + (m[j1, i0] * (1 - fx) + m[j1, i1] * fx) * fy
    t_space = texel / 255.0 * 2.0 - 1.0
    e_r = points * [1.0, 0.0, 1.0]
    e_r /= np.linalg.norm(e_r, axis=1, keepdims=True)
    tangent = np.cross([0.0, 1.0, 0.0], e_r)
    bitangent = -np.cross(n, tangent)                # w = -1 on this frustum (mesh_tangents)
    out = t_space[:, :1] * tangent + t_space[:, 1:2] * bitangent + t_space[:, 2:] * n
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _angle(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


@pytest.fixture(scope="module", params=["cactus", "stone"])
def face_on(request):
    name = request.param
    frusta = relief_frustum(name)
    camera = face_on_camera(60, 80)
    rc_r = render_reference(frusta, camera, relief=True)      # RC+R in float64
    smooth = render_reference(frusta, camera)                  # the mesh's surface, exactly
    return name, frusta, camera, rc_r, smooth


def test_normal_map_gives_the_ray_casters_relief_normal_where_the_mesh_is(face_on):
    """At the (u, v) the smooth surface shows in each pixel, the baked map's normal is the
    ray caster's relief normal there: the map's 8 bits and its filtering (a reader blends
    unit normals, the ray caster blends gradients, which part most on the stone's steep
    mortar edges) are all that differ: median under 0.3 degrees, mean under 1.5 (cactus
    0.13 and 0.28, stone 0.24 and 1.3; at most 2.4 and 14)."""
    name, frusta, camera, _, smooth = face_on
    baked = tx.bake_material(name, np.array([RADIUS / LENGTH]))
    origins, dirs = camera.rays()
    points = (origins + smooth.t[..., None] * dirs)[smooth.hit] - frusta.base[0]
    u, v = smooth.u[smooth.hit], smooth.v[smooth.hit]
    mapped = _mapped_normals(baked.normal, u, v, smooth.normal[smooth.hit], points)
    exact = _relief_normals(frusta, name, u, v, np.full(u.shape, RADIUS))
    angle = _angle(mapped, exact)
    assert np.median(angle) < 0.3 and angle.mean() < 1.5, (np.median(angle), angle.mean())


def test_on_the_body_it_shades_like_rc_r_at_the_silhouette_it_does_not(face_on):
    """Against RC+R's own hits (on the relief surface, seen through it), the normal-mapped
    smooth surface differs by the parallax a normal map cannot show: on the body's middle
    (within a quarter of the radius of the axis on screen) a few degrees, much less than
    the smooth surface without its map; towards the silhouette the error grows, and there
    RC+R draws pixels the mesh never covers (its relief's edge)."""
    name, frusta, camera, rc_r, smooth = face_on
    baked = tx.bake_material(name, np.array([RADIUS / LENGTH]))
    origins, dirs = camera.rays()
    both = rc_r.hit & smooth.hit
    relief_points = (origins + rc_r.t[..., None] * dirs)[both] - frusta.base[0]
    exact = _relief_normals(frusta, name, rc_r.u[both], rc_r.v[both], np.hypot(relief_points[:, 0],
                                                                                relief_points[:, 2]))
    points = (origins + smooth.t[..., None] * dirs)[both] - frusta.base[0]
    mapped = _mapped_normals(baked.normal, smooth.u[both], smooth.v[both], smooth.normal[both], points)
    angle = _angle(mapped, exact)
    plain = _angle(smooth.normal[both], exact)
    off = axis_bands(camera, both)[both]
    middle, edge = off < 0.25, off > 0.9
    assert angle[middle].mean() < 6.0, angle[middle].mean()
    assert angle[middle].mean() < 0.4 * plain[middle].mean()
    assert angle[edge].mean() > 3 * angle[middle].mean()
    assert np.count_nonzero(rc_r.hit & ~smooth.hit) > 0 and np.count_nonzero(smooth.hit & ~rc_r.hit) == 0


@pytest.mark.parametrize("name", ["cactus", "stone"])
def test_plantgens_rasteriser_draws_gs_n_like_its_ray_caster_draws_rc_r(gl_ctx, name):
    """plantgen's rasteriser with the baked map (NORMAL_MAP) against its ray caster with
    relief, face-on: on the middle half of the body the colours differ by under 10 grey
    levels on average (cactus 3.9, stone 8.2: the parallax above), under half what the mesh
    without its map leaves (10.6, 21.3); RC+R covers pixels at the silhouette that GS+N
    does not."""
    from plantgen.gl.raster import RasterRenderer
    from plantgen.gl.raycast import Raycaster
    from plantgen.settings import RaycastSettings

    frusta = relief_frustum(name)
    camera = face_on_camera(120, 160)
    rc_r = Raycaster(gl_ctx).render(frusta, camera, RaycastSettings(relief=True), material_names=(name,))
    mesh = tessellate(frusta, 3)
    raster = RasterRenderer(gl_ctx)
    gs_n = raster.render(mesh, frusta, camera, normal_maps={name: tx.bake_material(name, np.array([0.25])).normal})
    gs = raster.render(mesh, frusta, camera)
    raster.release()
    hit = np.isfinite(rc_r.distance) & np.isfinite(gs_n.distance)
    body = hit & (axis_bands(camera, hit) < 0.5)

    def mean_difference(image):
        return np.abs(image.color[..., :3].astype(float) - rc_r.color[..., :3].astype(float))[body].mean()

    assert mean_difference(gs_n) < 10.0 and mean_difference(gs_n) < 0.5 * mean_difference(gs)
    assert np.count_nonzero(np.isfinite(rc_r.distance) & ~np.isfinite(gs_n.distance)) > 0


def test_the_gallery_picture_has_three_panels(gl_ctx):
    """RC+R | GS+N | GS (benchmarks.normal_mapped): the middle panel differs from the plain
    mesh's, the normal maps having something to show."""
    from plantgen.benchmarks.normal_mapped import normal_mapped
    from plantgen.benchmarks.side_by_side import gallery_camera
    from plantgen.pipeline import load_skeleton

    frusta = skin_skeleton(load_skeleton("well"))
    image = normal_mapped(frusta, gallery_camera(frusta, 80, 60, zoom=0.6), level=1, aspect_step=2.0)
    assert image.shape == (60, 240, 3)
    assert np.abs(image[:, 80:160].astype(int) - image[:, 160:].astype(int)).mean() > 0.5


def test_the_gallery_picture_with_parallax_has_four_panels(gl_ctx):
    """RC+R | GS+POM | GS+N | GS (``--parallax``): the GS+POM panel differs from GS+N's."""
    from plantgen.benchmarks.normal_mapped import normal_mapped
    from plantgen.benchmarks.side_by_side import gallery_camera
    from plantgen.pipeline import load_skeleton
    from plantgen.settings import ParallaxSettings

    frusta = skin_skeleton(load_skeleton("well"))
    image = normal_mapped(frusta, gallery_camera(frusta, 80, 60, zoom=0.6), level=1, aspect_step=2.0,
                          parallax=ParallaxSettings())
    assert image.shape == (60, 320, 3)
    assert np.abs(image[:, 80:160].astype(int) - image[:, 160:240].astype(int)).mean() > 0.5
