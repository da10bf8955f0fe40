"""The batch manifest as typed columns (issue 27): figures a user filters with pyarrow or
pandas, files and timings as structs, defines as a map, the documented schema table the
code's, resuming on the typed columns, and a manifest of another format refused."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from _cli import run_cli

pytest.importorskip("dask.distributed", reason="plantgen[batch] (dask.distributed) is not installed")
pa = pytest.importorskip("pyarrow", reason="plantgen[batch] (pyarrow) is not installed")

import pyarrow.compute as pc  # noqa: E402
import pyarrow.dataset as ds  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402
from _docs import page, table_after  # noqa: E402
from test_batch import rows_of  # noqa: E402

from plantgen.batch.manifest import MANIFEST_NAME  # noqa: E402
from plantgen.batch.plant import measure  # noqa: E402
from plantgen.batch.schema import COLUMNS, FORMAT, arrow_schema  # noqa: E402
from plantgen.geometry.skeletons.skeleton import Skeleton  # noqa: E402


@pytest.fixture(scope="module")
def saguaros(tmp_path_factory) -> Path:
    """``plantgen batch saguaro --seeds 0:6 --outputs npz``'s folder."""
    out = tmp_path_factory.mktemp("saguaros") / "out"
    code, text, err = run_cli("batch", "saguaro", "--seeds", "0:6", "--outputs", "npz", "--out", out,
                              "--workers", "2")
    assert code == 0, err
    assert "6 plants: 6 made, 0 failed" in text
    return out


def test_figures_are_float_columns_a_user_filters(saguaros):
    table = pq.read_table(saguaros / MANIFEST_NAME)
    assert table.schema.names == arrow_schema().names
    assert table.schema.metadata[b"plantgen"] == FORMAT.encode()
    for name in ("dbh", "volume", "height", "crown_area", "bbox_max_y"):
        assert table.schema.field(name).type == pa.float64()
    assert table.schema.field("branches_per_order").type == pa.list_(pa.int64())
    dbh = np.array(table["dbh"].to_pylist())
    assert len(dbh) == 6 and np.all(dbh > 0)               # saguaros are taller than breast height
    cut = float(np.median(dbh))
    expected = sorted(np.array(table["id"].to_pylist())[dbh > cut].tolist())
    assert 0 < len(expected) < 6
    filtered = ds.dataset(saguaros / MANIFEST_NAME).to_table(filter=pc.field("dbh") > cut)
    assert sorted(filtered["id"].to_pylist()) == expected
    assert sorted(pq.read_table(saguaros / MANIFEST_NAME, filters=pc.field("dbh") > cut)["id"].to_pylist()) == expected
    df = pq.read_table(saguaros / MANIFEST_NAME).to_pandas()
    assert sorted(df[df.dbh > cut].id) == expected
    assert (df.volume > 0).all() and (df.trunk_volume + df.branch_volume - df.volume).abs().max() < 1e-9
    assert (df.bbox_max_y - df.bbox_min_y >= df.height - 1e-12).all()
    assert all(t["grow"] >= 0 and t["render"] is None for t in df.timings)
    assert all(f["npz"] == f"npz/{i}.npz" and f["png"] is None for f, i in zip(df.files, df.id, strict=True))


def test_duckdb_queries_the_manifest_with_sql(saguaros):
    duckdb = pytest.importorskip("duckdb", reason="DuckDB (the test extra) is not installed")
    path = str(saguaros / MANIFEST_NAME)
    rows = duckdb.sql(f"SELECT id, volume, files.npz AS npz FROM '{path}/*.parquet' WHERE volume > 0 ORDER BY id"
                      ).fetchall()
    assert [r[0] for r in rows] == [f"saguaro-{i:06d}" for i in range(6)]
    assert all(npz == f"npz/{i}.npz" for i, _, npz in rows)


def test_a_row_regrows_identically_alone(saguaros, tmp_path):
    row = rows_of(saguaros)["saguaro-000003"]
    code, _, err = run_cli("grow", "saguaro", "--seed", row["seed"], "-o", tmp_path / "alone.npz")
    assert code == 0, err
    alone = Skeleton.load(tmp_path / "alone.npz")
    batch = Skeleton.load(saguaros / row["files"]["npz"])
    for name in ("start", "end", "r_start", "r_end", "parent"):
        assert np.array_equal(getattr(alone, name), getattr(batch, name))
    figures = measure(alone)
    assert {k: row[k] for k in figures} == figures       # the row's figures are the plant's, exactly


def test_the_documented_schema_is_the_code_schema():
    """The file-format reference's table of the manifest's columns (generated from
    COLUMNS when the site is built) names the columns the Parquet schema has, with their
    types and units."""
    text = page("reference/formats.md")
    table = table_after(text[text.index("## Batch manifest"):], "| column | type | unit | meaning |")
    documented = {}
    for line in table[2:]:
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        for name in re.findall(r"`([a-z_]+)`", cells[0]):
            documented[name] = (cells[1].strip("`"), cells[2])
    assert documented == {name: (kind, unit) for name, kind, unit, _ in COLUMNS}
    assert list(documented) == arrow_schema().names


def test_a_resume_reads_the_typed_manifest(tmp_path):
    out = tmp_path / "out"
    args = ("batch", "saguaro", "--seeds", "0:4", "--outputs", "npz,swc", "--out", out, "--workers", "1")
    assert run_cli(*args)[0] == 0
    (out / "swc" / "saguaro-000002.swc").unlink()
    before = (out / "npz" / "saguaro-000001.npz").stat().st_mtime_ns
    code, text, err = run_cli(*args)
    assert code == 0, err
    assert "1 made, 0 failed, 3 already done" in text and "1 files missing" in text
    assert (out / "swc" / "saguaro-000002.swc").is_file()
    assert (out / "npz" / "saguaro-000001.npz").stat().st_mtime_ns == before
    assert len(rows_of(out)) == 4


def _old_json_manifest(path: Path) -> None:
    """A manifest as plantgen wrote it before issue 27: one file, lists and mappings as JSON text."""
    pq.write_table(pa.table({"id": ["saguaro-000000"], "grammar": ["saguaro"], "index": [0], "seed": [1],
                             "defines": ["{}"], "status": ["ok"], "error": [""],
                             "files": ['{"npz": ["npz/saguaro-000000.npz"]}'], "segments": [30], "tips": [5],
                             "height": [9.0], "bbox": ["[]"], "metrics": ['{"dbh": 0.6}'], "timings": ["{}"]}), path)


def _foreign_part(path: Path) -> None:
    path.mkdir()
    pq.write_table(pa.table({"x": [1, 2, 3]}), path / "part-000000.parquet")


def _typed_single_file(path: Path) -> None:
    """A typed manifest in one file (this branch before the manifest became a folder)."""
    pq.write_table(arrow_schema().empty_table().replace_schema_metadata({"plantgen": "plantgen-batch-manifest/2"}),
                   path)


def _stray_file(path: Path) -> None:
    path.mkdir()
    (path / "notes.txt").write_text("mine")


def _damaged_part(path: Path) -> None:
    path.mkdir()
    (path / "part-000000.parquet").write_bytes(b"PAR1 not really parquet")


MANIFESTS = {"old-json": _old_json_manifest, "typed-file": _typed_single_file, "foreign-part": _foreign_part,
             "stray-file": _stray_file, "damaged-part": _damaged_part,
             "foreign-file": lambda p: pq.write_table(pa.table({"x": [1]}), p),
             "garbage-file": lambda p: p.write_bytes(b"not parquet at all")}


def _snapshot(path: Path) -> dict:
    if path.is_file():
        return {"": path.read_bytes()}
    return {q.name: q.read_bytes() for q in sorted(path.iterdir())}


@pytest.mark.parametrize("kind", sorted(MANIFESTS))
def test_a_manifest_of_another_format_is_one_line_and_left_alone(tmp_path, kind):
    out = tmp_path / "out"
    out.mkdir()
    path = out / MANIFEST_NAME
    MANIFESTS[kind](path)
    before = _snapshot(path)
    code, text, err = run_cli("batch", "saguaro", "--seeds", "0:2", "--outputs", "npz", "--out", out, "-q",
                              "--scheduler", "tcp://127.0.0.1:1")      # refused before any connection
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and str(path) in err and "Traceback" not in err
    assert "cannot connect" not in err
    assert _snapshot(path) == before
    assert not (out / "npz").exists()                   # nothing made
