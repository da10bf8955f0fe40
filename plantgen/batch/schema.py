"""The manifest's columns, typed: one home for each column's name, Arrow type, unit and
meaning (the documentation's schema table is generated from :data:`COLUMNS`).

A scalar figure is one float64 (or int64) column, in metres, m² and m³ (a model unit is
taken as a metre: the shipped grammars are drawn in metres); the branch count per order
is a list; the files a plant got are a struct of paths relative to the batch folder, one
field per output kind (null for a kind not asked for); the bounding box is six float64
columns; the defines a sweep set are a map from name to value; the seconds each stage
took are a struct. A failed plant's figures are null. pyarrow is imported only when a
type is asked for (the ``batch`` extra).
"""

from __future__ import annotations

from .spec import OUTPUT_KINDS

__all__ = ["COLUMNS", "FORMAT", "METRIC_COLUMNS", "STAGES", "arrow_schema", "column_names", "empty_row"]

#: The manifest format: written into the Parquet schema's metadata (key ``plantgen``), so
#: a manifest of another format (an older plantgen's JSON text columns, a foreign file) is
#: told apart before any work.
FORMAT = "plantgen-batch-manifest/3"

#: The stages a plant's ``timings`` may hold, in the order they run.
STAGES = ("grow", "skeleton_files", "skin", "glb", "render", "scan", "metrics")

#: Output kinds with one file per plant (the others have one file per view).
SINGLE_FILE_KINDS = ("npz", "swc", "glb", "points")

#: The scalar tree figures (:meth:`plantgen.metrics.TreeMetrics.as_dict`, in metres), by
#: column: (Arrow type name, unit, meaning).
METRIC_COLUMNS = {
    "height": ("float64", "m", "from the trunk's base up to the highest point of the wood"),
    "dbh": ("float64", "m", "the trunk's diameter 1.3 m along it from its base; null for a shorter trunk"),
    "volume": ("float64", "m³", "wood volume, the sum of the frusta"),
    "trunk_volume": ("float64", "m³", "the trunk's share of volume"),
    "branch_volume": ("float64", "m³", "the branches' share of volume"),
    "length": ("float64", "m", "the segments' summed length"),
    "trunk_length": ("float64", "m", "the trunk's length"),
    "branch_length": ("float64", "m", "the branches' summed length"),
    "surface_area": ("float64", "m²", "the frusta's lateral area"),
    "crown_area": ("float64", "m²", "the convex hull of the vertical projection"),
    "crown_width_max": ("float64", "m", "the largest distance across that hull"),
    "crown_width_mean": ("float64", "m", "the hull's mean width (perimeter / π)"),
    "branches": ("int64", "", "branches besides the trunk"),
    "max_branch_order": ("int64", "", "the highest branch order (the trunk is 0)"),
}

#: Every column in order: (name, Arrow type name, unit, meaning). Type names are read by
#: :func:`arrow_type`; the documentation's table shows the same four fields.
COLUMNS = (
    ("id", "string", "", "the plant's id, unique in the batch (its files' stem)"),
    ("grammar", "string", "", "the grammar as the spec names it"),
    ("index", "int64", "", "the plant's index in its seed range"),
    ("seed", "int64", "", "the plant's seed (`plantgen grow GRAMMAR --seed SEED` makes it again)"),
    ("defines", "map<string, float64>", "", "the defines a sweep set (empty without a sweep)"),
    ("status", "string", "", "`ok` or `failed`"),
    ("error", "string", "", "the one-line error of a failed plant (empty when ok)"),
    ("files", "struct<npz, swc, glb, points: string; png, depth, mask: list<string>>", "",
     "the plant's files by kind, relative to the batch folder (null: not asked for)"),
    ("fingerprint", "string", "", "a digest of what shapes the files besides the seed: the outputs, views and "
     "scan knobs, the grammar file's bytes, the defines, plantgen's version"),
    ("segments", "int64", "", "skeleton segments"),
    ("scan_points", "int64", "", "points of the plant's simulated scan (null without the points output)"),
    ("tips", "int64", "", "branch tips: segments with no child"),
    *((name, kind, unit, meaning) for name, (kind, unit, meaning) in METRIC_COLUMNS.items()),
    ("branches_per_order", "list<int64>", "", "branches of each order, order 0 (the trunk) first"),
    *((f"bbox_{end}_{axis}", "float64", "m", f"the geometry's {'least' if end == 'min' else 'greatest'} {axis}, "
       "radii included (y is up)") for end in ("min", "max") for axis in "xyz"),
    ("timings", f"struct<{', '.join(STAGES)}: float64>", "s", "seconds per stage (null: the stage did not run)"),
)


def column_names() -> tuple[str, ...]:
    """The manifest's columns, in order."""
    return tuple(c[0] for c in COLUMNS)


def empty_row() -> dict:
    """A row with every column null."""
    return dict.fromkeys(column_names())


def arrow_type(name: str):
    """The pyarrow type of a type name of :data:`COLUMNS`."""
    import pyarrow as pa

    if name.startswith("map<"):
        return pa.map_(pa.string(), pa.float64())
    if name.startswith("struct<npz"):
        return pa.struct([(k, pa.string() if k in SINGLE_FILE_KINDS else pa.list_(pa.string())) for k in OUTPUT_KINDS])
    if name.startswith("struct<"):
        return pa.struct([(k, pa.float64()) for k in STAGES])
    if name == "list<int64>":
        return pa.list_(pa.int64())
    return {"string": pa.string(), "int64": pa.int64(), "float64": pa.float64()}[name]


def arrow_schema():
    """The manifest's pyarrow schema, its format in the metadata (key ``plantgen``)."""
    import pyarrow as pa

    return pa.schema([(name, arrow_type(kind)) for name, kind, _, _ in COLUMNS], metadata={"plantgen": FORMAT})
