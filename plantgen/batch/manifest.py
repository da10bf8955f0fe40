"""The batch manifest: one Parquet row per plant (pyarrow), typed columns
(:mod:`plantgen.batch.schema`), rewritten atomically.

The file is replaced whole (a temporary name renamed onto it), so it is valid whenever it
exists, an interrupted batch included. A manifest of another format (an older plantgen's
JSON text columns, a Parquet file some other program wrote, a damaged file) is refused
with one line before any work: it is never overwritten.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import PlantgenError
from ..files import write_atomically
from .plant import files_column, relative_files
from .schema import FORMAT, arrow_schema
from .spec import Outputs, PlantTask

__all__ = ["Manifest", "MANIFEST_NAME", "read_manifest"]

MANIFEST_NAME = "manifest.parquet"


def _pyarrow():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise PlantgenError("plantgen batch needs the batch extra: pip install 'plantgen[batch]'") from None
    return pa, pq


def read_manifest(path: Path):
    """The pyarrow table of the manifest at ``path``; one line if it is not one this
    plantgen writes."""
    _, pq = _pyarrow()
    try:
        schema = pq.read_schema(path)
    except Exception as exc:   # pyarrow raises several kinds for a damaged file
        raise PlantgenError(f"{path}: not a readable manifest ({exc.__class__.__name__}); "
                            "move it away to start the batch afresh") from None
    found = (schema.metadata or {}).get(b"plantgen", b"").decode(errors="replace")
    if found != FORMAT:
        if not found and {"id", "metrics"} <= set(schema.names):
            what = "a manifest of an older plantgen (JSON text columns)"
        else:
            what = f"a manifest of another format ({found})" if found else "not a plantgen batch manifest"
        raise PlantgenError(f"{path}: {what}, not {FORMAT}; move it away (or use another --out) to start afresh")
    try:
        return pq.read_table(path, schema=arrow_schema())
    except Exception as exc:
        raise PlantgenError(f"{path}: not a readable manifest ({exc.__class__.__name__}); "
                            "move it away to start the batch afresh") from None


class Manifest:
    """The rows of a batch folder's manifest, by plant id."""

    def __init__(self, folder: Path):
        self.path = Path(folder) / MANIFEST_NAME
        self.rows: dict[str, dict] = {}
        if self.path.exists():
            if not self.path.is_file():
                raise PlantgenError(f"{self.path}: not a file (a manifest is one Parquet file); move it away")
            for row in read_manifest(self.path).to_pylist():
                self.rows[str(row["id"])] = row

    def done(self, task: PlantTask, outputs: Outputs, folder: Path) -> bool:
        """Whether ``task`` finished before with the same seed and defines, and every file
        ``outputs`` asks for is there."""
        row = self.rows.get(task.id)
        if row is None or row.get("status") != "ok" or row.get("seed") != task.seed:
            return False
        if sorted(row.get("defines") or ()) != sorted(task.defines):
            return False
        want = files_column(relative_files(task, outputs))
        have = row.get("files") or {}
        if any(have.get(kind) != paths for kind, paths in want.items()):
            return False
        return all((folder / f).is_file() for paths in want.values() for f in ([paths] if isinstance(paths, str)
                                                                                   else paths))

    def add(self, row: dict) -> None:
        self.rows[row["id"]] = row

    def save(self) -> Path:
        """Write every row (sorted by id) to the manifest, atomically."""
        pa, pq = _pyarrow()
        rows = sorted(self.rows.values(), key=lambda r: r["id"])
        table = pa.Table.from_pylist(rows, schema=arrow_schema())
        return write_atomically(self.path, lambda tmp: pq.write_table(table, tmp))
