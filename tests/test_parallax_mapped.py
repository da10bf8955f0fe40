"""GS+POM, parallax occlusion mapping of the baked height on the mesh at the relief's outer
shell, against RC+R (plantgen's ray caster with relief): face-on its body shows the relief
where RC+R does (the distance to the displaced point, and the colours, closer than GS+N's);
towards the silhouette the planar march fails and the outline stays the mesh's; more layers
converge; the variant is compiled only when asked for; its knobs are checked."""

from __future__ import annotations

import numpy as np
import pytest
from _relief_frustum import LENGTH, RADIUS, axis_bands, face_on_camera, relief_frustum
from click.testing import CliRunner

from plantgen.geometry.meshes import textures as tx
from plantgen.geometry.meshes.mesh import outer_shell_mesh, tessellate
from plantgen.geometry.rays.camera import Camera
from plantgen.settings import ParallaxSettings, RaycastSettings

LEVEL = 3


def _oblique(width, height):
    """From above and aside: the relief seen at 30 to 90 degrees off its normals."""
    return Camera((5.0, 4.0, 5.0), (0.0, LENGTH / 2, 0.0), (0, 1, 0), 25.0, width, height)


class _Renders:
    """One material's frustum, RC+R and the rasteriser's maps, rendered on demand."""

    def __init__(self, ctx, name):
        from plantgen.gl.raster import RasterRenderer
        from plantgen.gl.raycast import Raycaster

        self.name, self.frusta = name, relief_frustum(name)
        self.caster, self.raster = Raycaster(ctx), RasterRenderer(ctx)
        self.baked = tx.bake_material(name, np.array([RADIUS / LENGTH]))
        self.smooth, self.outer = tessellate(self.frusta, LEVEL), outer_shell_mesh(self.frusta, LEVEL)

    def rc_r(self, camera):
        return self.caster.render(self.frusta, camera, RaycastSettings(relief=True), material_names=(self.name,))

    def gs_n(self, camera):
        return self.raster.render(self.smooth, self.frusta, camera, normal_maps={self.name: self.baked.normal})

    def gs_pom(self, camera, parallax=None):
        return self.raster.render(self.outer, self.frusta, camera, parallax=parallax or ParallaxSettings(),
                                  normal_maps={self.name: tx.parallax_map(self.baked)})

    def release(self):
        self.caster.release()
        self.raster.release()


@pytest.fixture(params=["cactus", "stone"])
def renders(request, gl_ctx):
    out = _Renders(gl_ctx, request.param)
    yield out
    out.release()


def _body(camera, *images, within=0.5):
    """Pixels every image covers, within ``within`` of the half width of the axis on screen."""
    hit = np.logical_and.reduce([np.isfinite(i.distance) for i in images])
    return hit & (axis_bands(camera, hit) < within)


def _distance_error(image, reference, where):
    """(k,) |distance - reference's| on the pixels ``where`` (both cover them)."""
    return np.abs(image.distance[where] - reference.distance[where])


def _colour_difference(image, reference, where):
    return np.abs(image.color[..., :3].astype(float) - reference.color[..., :3].astype(float))[where].mean()


def test_the_mesh_sits_on_the_outer_shell():
    """Every lateral vertex of the GS+POM mesh lies at r + shell from the axis: the top of the
    relief, which the march walks down from."""
    frusta = relief_frustum("stone")
    mesh = outer_shell_mesh(frusta, 2)
    lateral = np.unique(mesh.faces[: mesh.n_rows * 16 * 4 ** 2])
    radial = np.hypot(mesh.vertices[lateral, 0], mesh.vertices[lateral, 2])
    assert np.allclose(radial, RADIUS + frusta.shell[0], rtol=1e-9)


def test_the_uv_scales_are_the_cones_own():
    """The march's model units per unit of (u, v) at each lateral vertex of the outer-shell
    mesh: around, the polygon's perimeter (2π(r + shell) to 0.05 %), along, the texture
    period's length (the frustum's, v running 0..1); the caps' vertices get 0 (no march)."""
    from plantgen.geometry.meshes.textures import mesh_uv_scales

    frusta = relief_frustum("stone")
    mesh = outer_shell_mesh(frusta, LEVEL)
    scales = mesh_uv_scales(mesh.vertices, mesh.uv, mesh.faces)
    lateral = np.zeros(len(mesh.vertices), bool)
    lateral[mesh.faces[: mesh.n_rows * 16 * 4 ** LEVEL]] = True
    np.testing.assert_allclose(scales[lateral, 0], 2 * np.pi * (RADIUS + frusta.shell[0]), rtol=5e-4)
    np.testing.assert_allclose(scales[lateral, 1], LENGTH, rtol=1e-6)
    assert np.all(scales[~lateral] == 0) and np.any(~lateral)


def test_face_on_it_shows_the_relief_where_rc_r_does(renders):
    """Face-on, on the middle half of the body, GS+POM's distance to the displaced point is
    RC+R's relief surface within a tenth of the shell on average (cactus 0.006, stone 0.008
    of it on llvmpipe), where GS+N's smooth mesh is off by most of the shell (0.75, 0.82);
    its colours are closer to RC+R's than GS+N's (cactus 2.1 against 4.2 grey levels, stone
    4.9 against 8.2)."""
    camera = face_on_camera(120, 160)
    rc_r, gs_n, gs_pom = renders.rc_r(camera), renders.gs_n(camera), renders.gs_pom(camera)
    body = _body(camera, rc_r, gs_n, gs_pom)
    shell = renders.frusta.shell[0]
    pom_off = _distance_error(gs_pom, rc_r, body).mean() / shell
    plain_off = _distance_error(gs_n, rc_r, body).mean() / shell
    assert pom_off < 0.1 and plain_off > 0.5, (pom_off, plain_off)
    assert _colour_difference(gs_pom, rc_r, body) < 0.8 * _colour_difference(gs_n, rc_r, body)


def test_the_silhouette_stays_the_meshs(renders):
    """Seen obliquely, the march is planar (a facet's tangent plane): towards the outline it
    parts from RC+R's relief, which curves away with the cone; the outline is the outer
    shell's, so GS+POM covers pixels where RC+R sees between the relief's bumps, and
    RC+R's relief never reaches out of the mesh by more than a few pixels (the polygon's
    chords). On llvmpipe: 111 (cactus) and 128 (stone) pixels GS+POM's alone, none RC+R's
    alone; the distance error on the outer tenth 3.1 and 13.6 times the middle's."""
    camera = _oblique(120, 160)
    rc_r, gs_pom = renders.rc_r(camera), renders.gs_pom(camera)
    hit_rc, hit_pom = np.isfinite(rc_r.distance), np.isfinite(gs_pom.distance)
    only_pom, only_rc = np.count_nonzero(hit_pom & ~hit_rc), np.count_nonzero(hit_rc & ~hit_pom)
    assert only_pom > 3 * max(only_rc, 1), (only_pom, only_rc)
    both = hit_rc & hit_pom
    bands = axis_bands(camera, both)
    middle, edge = both & (bands < 0.3), both & (bands > 0.9)
    assert _distance_error(gs_pom, rc_r, edge).mean() > 2 * _distance_error(gs_pom, rc_r, middle).mean()


def test_more_layers_converge(gl_ctx):
    """The distance error against RC+R on the stone's body, seen obliquely, with 2, 4, ... 64
    layers (min = max, no refinement: steep parallax, whose error is the layers' own): it
    does not grow from one count to the next beyond noise (5 %), and 64 layers leave under
    a third of what 2 leave (on llvmpipe 0.0177, 0.0072, 0.0029, 0.0020, 0.0012, 0.0008)."""
    renders = _Renders(gl_ctx, "stone")
    camera = _oblique(90, 120)
    rc_r = renders.rc_r(camera)
    errors = []
    for layers in (2, 4, 8, 16, 32, 64):
        image = renders.gs_pom(camera, ParallaxSettings(min_layers=layers, max_layers=layers, refine_steps=0))
        body = _body(camera, rc_r, image)
        errors.append(float(_distance_error(image, rc_r, body).mean()))
    renders.release()
    assert all(b <= 1.05 * a for a, b in zip(errors, errors[1:], strict=False)), errors
    assert errors[-1] < errors[0] / 3, errors


def test_the_secant_refinement_helps_few_layers(gl_ctx):
    """With 4 layers, the classic interpolation (1 secant step) and 4 steps each leave less
    distance error than steep parallax (0) (on llvmpipe 0.0072, 0.0006, 0.0005)."""
    renders = _Renders(gl_ctx, "stone")
    camera = _oblique(90, 120)
    rc_r = renders.rc_r(camera)
    errors = []
    for steps in (0, 1, 4):
        image = renders.gs_pom(camera, ParallaxSettings(min_layers=4, max_layers=4, refine_steps=steps))
        errors.append(float(_distance_error(image, rc_r, _body(camera, rc_r, image)).mean()))
    renders.release()
    assert errors[1] < errors[0] and errors[2] < errors[0], errors


def test_the_variant_is_compiled_only_when_asked_for(gl_ctx):
    from plantgen.gl.raster import RasterRenderer

    renders = _Renders(gl_ctx, "cactus")
    camera = face_on_camera(40, 50)
    plain = RasterRenderer(gl_ctx)
    plain.render(renders.smooth, renders.frusta, camera)
    plain.render(renders.smooth, renders.frusta, camera, normal_maps={"cactus": renders.baked.normal})
    assert all("PARALLAX" not in defines for _, defines in plain.programs_used)
    renders.gs_pom(camera)
    assert ("raster.glsl", ("NORMAL_MAP", "PARALLAX")) in renders.raster.programs_used
    plain.release()
    renders.release()
    with pytest.raises(ValueError, match="normal_maps"):
        RasterRenderer(gl_ctx).render(renders.outer, renders.frusta, camera, parallax=ParallaxSettings())


@pytest.mark.parametrize("kwargs", [dict(min_layers=0), dict(max_layers=257), dict(refine_steps=-1),
                                    dict(min_layers=16, max_layers=8)])
def test_bad_knobs_are_one_line(kwargs):
    from plantgen.errors import PlantgenError

    with pytest.raises(PlantgenError) as err:
        ParallaxSettings(**kwargs)
    assert "\n" not in str(err.value) and "--pom-" in str(err.value)


@pytest.mark.parametrize("args", [["--pom-min-layers", "0"], ["--pom-refine-steps", "17"],
                                  ["--pom-min-layers", "40", "--pom-max-layers", "20"]])
def test_the_bench_refuses_bad_knobs_with_exit_2(args, tmp_path):
    from plantgen.cli.bench import bench

    result = CliRunner().invoke(bench, ["--quick", "--out", str(tmp_path), *args])
    assert result.exit_code == 2, result.output
    message = [line for line in result.output.splitlines() if line.startswith("Error")]
    assert len(message) == 1 and "pom" in message[0], result.output
