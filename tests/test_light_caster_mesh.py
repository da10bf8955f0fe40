"""The light caster bench's mesh casters (plantgen.benchmarks.light_caster): the relief
tessellated and displaced (GS+R) and rasterised into the shadow map, measured by the
same clock and against the same float64 reference as the ray caster's marches."""

from __future__ import annotations

import math

from plantgen.benchmarks.light_caster import CASTERS, MESH_CASTER_TRIANGLES, markdown, measure_scene
from plantgen.geometry.mesh import triangle_count
from plantgen.gl.raycast import Raycaster
from plantgen.table1.models import load_model


def test_a_displaced_mesh_casts_the_relief_less_exactly_than_the_march_and_finer_levels_close_in(gl_ctx):
    """On the well, the GS+R meshes draw the relief into the same window as the marches
    (their depths sit near the float64 reference's where the plain caster's miss it by
    texels), a finer level is closer, and neither is as close as the secant march."""
    rows = {r["caster"].split(" (")[0]: r for r in measure_scene("well", (64, 48), 1, 3000, 512, Raycaster())}
    mesh5, mesh6 = rows["GS+R mesh m=5"], rows["GS+R mesh m=6"]
    assert rows["plain"]["median_texels"] > 5 > mesh5["median_texels"]
    assert mesh6["half_texel"] < mesh5["half_texel"] and mesh6["median_texels"] < mesh5["median_texels"]
    assert rows["secant"]["half_texel"] < mesh6["half_texel"]
    assert mesh5["shadow_ms"] > 0 and mesh5["coverage"] < 0.02


def test_a_scene_of_many_rows_is_not_tessellated_past_the_budget(gl_ctx):
    """The dancing cacti's 2,151 rows would make tens of millions of triangles at m = 5:
    the row says so and holds no time or error, and the table prints a dash."""
    model = load_model("dancing_cacti", (16, 12))
    assert triangle_count(model.frusta, 5) > MESH_CASTER_TRIANGLES
    casters = [c for c in CASTERS if c.label in ("plain", "GS+R mesh m=5")]
    rows = measure_scene("dancing_cacti", (16, 12), 1, 200, 64, Raycaster(), casters=casters)
    mesh = rows[1]
    assert "too many, not drawn" in mesh["caster"] and math.isnan(mesh["shadow_ms"]) and math.isnan(mesh["coverage"])
    assert "| — |" in markdown(rows, (16, 12), 1, 200, 64)
