"""``python -m plantgen.benchmarks.default_cost`` (issue 43): what the new defaults cost a
single plant's frame against the old ones. Structure only, never timings."""

from __future__ import annotations

import json

from plantgen.benchmarks import default_cost
from plantgen.settings import RenderSettings


def test_the_old_and_new_defaults_are_the_render_commands():
    """No option at all gives every new default on; the old options turn each off."""
    plain, new, old = (RenderSettings.from_options(**o) for o in ({}, default_cost.NEW, default_cost.OLD))
    effects = [s.effects.resolve() for s in (plain, new, old)]
    assert effects[0] == effects[1] and {"tone", "translucency"} <= set(effects[0])
    assert not {"tone", "translucency"} & set(effects[2])
    assert (plain.image.aa, plain.image.ground) == (new.image.aa, new.image.ground) == ("coverage", "auto")
    assert (old.image.aa, old.image.ground) == ("none", "none")
    assert [name for name, _ in default_cost.VARIANTS] == ["old defaults", "new defaults", "tone only",
                                                            "translucency only", "ground only", "aa only"]


def test_single_plants_are_the_shipped_grammars_without_the_scenes():
    names = default_cost.shipped_plants()
    assert {"saguaro", "broadleaf", "pine", "coconut", "aloe", "ocotillo", "elm"} <= set(names)
    assert not {"forest", "desert", "oasis", "dancing_cacti", "well"} & set(names)


def test_the_bench_writes_its_page_and_rows(gl_ctx, tmp_path):
    """A row per variant, the old defaults' ratios 1, the renderer named, one table line
    per model and size."""
    out, rows_out = tmp_path / "cost.md", tmp_path / "cost.json"
    assert default_cost.main(["saguaro", "--sizes", "64x48", "--frames", "1", "--out", str(out),
                              "--json", str(rows_out)]) == 0
    data = json.loads(rows_out.read_text(encoding="utf-8"))
    assert data["renderer"] and data["frames"] == 1 and data["goal"] == default_cost.GOAL
    rows = data["rows"]
    assert [r["variant"] for r in rows] == [name for name, _ in default_cost.VARIANTS]
    assert rows[0]["frame_ratio"] == 1.0 and rows[0]["wall_ratio"] == 1.0
    assert all(r["frame_ms"] > 0 and r["model"] == "saguaro" and r["size"] == "64x48" for r in rows)
    text = out.read_text(encoding="utf-8")
    lines = [line for line in text.splitlines() if line.startswith("| saguaro | 64x48 |")]
    assert len(lines) == 1 and len(lines[0].split("|")) == 2 + 3 + len(default_cost.VARIANTS) - 1
    assert "GL renderer:" in text
    assert [line.split(":")[0] for line in text.splitlines() if "1.5x the old defaults'" in line] == ["frame",
                                                                                                     "CPU time"]
