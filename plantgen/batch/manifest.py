"""The batch manifest: one Parquet row per plant (pyarrow), rewritten atomically.

Columns (:func:`plantgen.batch.plant.row_fields`): ``id``, ``grammar``, ``index``,
``seed``, ``defines`` (JSON), ``status`` (``ok`` or ``failed``), ``error`` (the one-line
error of a failed plant), ``files`` (JSON: kind -> paths relative to the batch folder),
``segments``, ``tips``, ``height``, ``bbox`` (JSON: min x, y, z, max x, y, z of the
geometry, radii included), ``metrics`` (JSON: the tree metrics of :mod:`plantgen.metrics`
and the branch count per order), ``timings`` (JSON:
seconds per stage). The file is replaced whole (a temporary name renamed onto it), so it
is valid whenever it exists, an interrupted batch included.
"""

from __future__ import annotations

import json
from pathlib import Path

from ..errors import PlantgenError
from ..files import write_atomically
from .plant import row_fields
from .spec import PlantTask

__all__ = ["Manifest", "MANIFEST_NAME"]

MANIFEST_NAME = "manifest.parquet"


def _pyarrow():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise PlantgenError("plantgen batch needs the batch extra: pip install 'plantgen[batch]'") from None
    return pa, pq


class Manifest:
    """The rows of a batch folder's manifest, by plant id."""

    def __init__(self, folder: Path):
        self.path = Path(folder) / MANIFEST_NAME
        self.rows: dict[str, dict] = {}
        if self.path.is_file():
            _, pq = _pyarrow()
            try:
                table = pq.read_table(self.path)
            except Exception as exc:   # pyarrow raises several kinds for a damaged file
                raise PlantgenError(f"{self.path}: not a readable manifest ({exc.__class__.__name__}); "
                                    "move it away to start the batch afresh") from None
            for row in table.to_pylist():
                if "id" in row:
                    self.rows[str(row["id"])] = row

    def done(self, task: PlantTask, folder: Path) -> bool:
        """Whether ``task`` finished before with the same seed and defines and its files are
        all there."""
        row = self.rows.get(task.id)
        if row is None or row.get("status") != "ok" or row.get("seed") != task.seed:
            return False
        if row.get("defines") != json.dumps(dict(task.defines), sort_keys=True):
            return False
        files = json.loads(row.get("files") or "{}")
        return all((folder / f).is_file() for paths in files.values() for f in paths)

    def add(self, row: dict) -> None:
        self.rows[row["id"]] = row

    def save(self) -> Path:
        """Write every row (sorted by id) to the manifest, atomically."""
        pa, pq = _pyarrow()
        names = row_fields()
        rows = sorted(self.rows.values(), key=lambda r: r["id"])
        table = pa.table({k: [r.get(k) for r in rows] for k in names},
                         schema=pa.schema([(k, _TYPES[k](pa)) for k in names]))
        return write_atomically(self.path, lambda tmp: pq.write_table(table, tmp))


_TYPES = {
    "id": lambda pa: pa.string(), "grammar": lambda pa: pa.string(), "index": lambda pa: pa.int64(),
    "seed": lambda pa: pa.int64(), "defines": lambda pa: pa.string(), "status": lambda pa: pa.string(),
    "error": lambda pa: pa.string(), "files": lambda pa: pa.string(), "segments": lambda pa: pa.int64(),
    "tips": lambda pa: pa.int64(), "height": lambda pa: pa.float64(), "bbox": lambda pa: pa.string(),
    "metrics": lambda pa: pa.string(), "timings": lambda pa: pa.string(),
}
