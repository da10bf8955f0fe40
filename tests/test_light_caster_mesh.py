"""The mesh caster (``--shadow-caster mesh``): the frusta tessellated and displaced by the
relief (GS+R at ``--shadow-mesh-level``), built once and rasterised into the ray caster's
shadow map; measured by the light caster bench with the same clock and against the same
float64 reference as the ray caster's marches, kept and redrawn as the other casters'
maps, refused in one line where it cannot cast."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from _cli import run_cli
from test_shadow_cache import CAMERAS, SHADOWS, bent_trunk, render

from plantgen.benchmarks.light_caster import CASTERS, MESH_CASTER_TRIANGLES, markdown, measure_scene
from plantgen.errors import PlantgenError
from plantgen.geometry.meshes.mesh import triangle_count
from plantgen.geometry.rays.instances import PlacedPlants
from plantgen.gl.raycast import Raycaster
from plantgen.limits import LimitError, limits
from plantgen.settings import ShadowSettings
from plantgen.table1.models import load_model

MESH = replace(SHADOWS, caster="mesh", mesh_level=4)


def test_a_displaced_mesh_casts_the_relief_less_exactly_than_the_march_and_finer_levels_close_in(gl_ctx):
    """On the well, the mesh caster draws the relief into the same window as the marches
    (its depths sit near the float64 reference's where the plain caster's miss it by
    texels), a finer level is closer, and none is as close as the secant march."""
    rows = {r["caster"].split(" (")[0]: r for r in measure_scene("well", (64, 48), 1, 3000, 512, Raycaster())}
    mesh3, mesh5, mesh6 = rows["mesh m=3"], rows["mesh m=5"], rows["mesh m=6"]
    assert rows["plain"]["median_texels"] > 5 > mesh5["median_texels"]
    assert mesh6["half_texel"] < mesh5["half_texel"] < mesh3["half_texel"]
    assert mesh6["median_texels"] < mesh5["median_texels"]
    assert rows["secant"]["half_texel"] < mesh6["half_texel"]
    assert mesh5["shadow_ms"] > 0 and mesh5["coverage"] < 0.02


def test_a_scene_of_many_rows_is_not_tessellated_past_the_budget(gl_ctx):
    """The dancing cacti's 2,151 rows would make tens of millions of triangles at m = 5:
    the row says so and holds no time or error, and the table prints a dash."""
    model = load_model("dancing_cacti", (16, 12))
    assert triangle_count(model.frusta, 5, caps="tips") > MESH_CASTER_TRIANGLES
    casters = [c for c in CASTERS if c.label in ("plain", "mesh m=5")]
    rows = measure_scene("dancing_cacti", (16, 12), 1, 200, 64, Raycaster(), casters=casters)
    mesh = rows[1]
    assert "too many, not drawn" in mesh["caster"] and math.isnan(mesh["shadow_ms"]) and math.isnan(mesh["coverage"])
    assert "| — |" in markdown(rows, (16, 12), 1, 200, 64)


def test_the_mesh_casts_where_the_march_casts(gl_ctx):
    """A bent trunk's map by the mesh caster covers the march's texels but for a rim of the
    outline, and where both drew, the depths agree to within a few texels (the mesh's chords
    against the relief's bilinear surface)."""
    caster, frusta = Raycaster(gl_ctx), bent_trunk()
    render(caster, frusta)
    march = caster.shadow_depths().astype(np.float64)
    render(caster, frusta, shadows=replace(MESH, mesh_level=5))
    mesh = caster.shadow_depths().astype(np.float64)
    window = caster.last_light_window
    drawn_march, drawn_mesh = march < 1, mesh < 1
    assert drawn_march.sum() > 1000
    assert np.mean(drawn_march != drawn_mesh) < 0.1 * drawn_march.mean()
    both = drawn_march & drawn_mesh
    texels = np.abs(march - mesh)[both] * (window.depth[1] - window.depth[0]) / window.texel_size(len(march))
    assert np.median(texels) < 0.5 and np.mean(texels > 4) < 0.02
    caster.release()


def test_the_mesh_casters_map_is_kept_and_redrawn_like_the_others(gl_ctx):
    """Its map is reused while only the camera moves, drawn again when the level or the
    caster changes, and its mesh built once per frusta object and level (two levels in
    turn keep both meshes)."""
    caster, frusta = Raycaster(gl_ctx), bent_trunk()
    assert not render(caster, frusta, shadows=MESH).stats.shadow_cached
    built = caster.caster_mesh(frusta, MESH.mesh_level, True)
    assert render(caster, frusta, CAMERAS[1], shadows=MESH).stats.shadow_cached
    assert caster.caster_mesh(frusta, MESH.mesh_level, True)[1] is built[1]        # the same buffer
    assert not render(caster, frusta, shadows=replace(MESH, mesh_level=3)).stats.shadow_cached
    assert caster.caster_mesh(frusta, MESH.mesh_level, True)[1] is built[1]        # levels alternating keep both
    assert not render(caster, frusta, shadows=SHADOWS).stats.shadow_cached          # the march again
    assert ("raster.glsl", ("SHADOW_PASS",)) in caster.programs_used
    caster.release()


def test_the_mesh_caster_refuses_what_it_cannot_cast_in_one_line(gl_ctx):
    """A scene drawn instanced and a mesh over the render's memory limit: one line each,
    naming the way out."""
    caster, frusta = Raycaster(gl_ctx, limits=limits.raised(render_bytes=1 << 20)), bent_trunk()
    placed = PlacedPlants.build([("trunk", frusta, np.array([-1, 0]), [np.eye(4)])])
    with pytest.raises(PlantgenError, match="--shadow-caster relief") as info:
        caster.render(placed, CAMERAS[0], material_names=placed.material_names, shadows=MESH)
    assert "\n" not in str(info.value)
    with pytest.raises(LimitError, match="--shadow-mesh-level") as info:
        render(caster, frusta, shadows=replace(MESH, mesh_level=7))
    assert "\n" not in str(info.value)
    caster.release()


def test_the_knobs_are_on_the_command_line(tmp_path):
    """``plantgen render`` takes the caster and its level; a bad level, and an animation
    (its frames are streamed, not still), are one line and exit 2, and write nothing."""
    out = tmp_path / "well.png"
    code, _, err = run_cli("render", "well", "--shadow-caster", "mesh", "--shadow-mesh-level", "3",
                           "--size", "96x72", "-o", out)
    assert code == 0 and out.exists(), err
    code, _, err = run_cli("render", "well", "--shadow-mesh-level", "9", "--size", "96x72", "-o", tmp_path / "x.png")
    assert code == 2 and len(err.strip().splitlines()) == 1 and not (tmp_path / "x.png").exists()
    code, _, err = run_cli("render", "dancing_cacti", "--frames", "3", "--shadow-caster", "mesh", "--size", "64x48",
                           "-o", tmp_path / "sway.gif")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "animation" in err
    assert not (tmp_path / "sway.gif").exists()
    with pytest.raises(PlantgenError):
        ShadowSettings(caster="mesh", mesh_level=-1)
