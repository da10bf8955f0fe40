"""The batch manifest: a Parquet dataset, one row per plant, typed columns
(:mod:`plantgen.batch.schema`), written in parts as plants finish.

``DIR/manifest.parquet`` is a folder of parts ``part-NNNNNN.parquet``, each one file
replaced whole (a hidden temporary name renamed onto it), so the dataset is valid whenever
it is read, an interrupted batch included: ``pq.read_table``, pandas and DuckDB read the
folder as one table. A run appends: its rows go to the part it is filling (rewritten at
most every few seconds; a part holds at most :data:`PART_ROWS` rows), so the client keeps
at most one part's rows, whatever the number of plants.

A plant made again (its settings changed, its files went missing, it failed before) has
its new row in a newer part; when the run ends, interrupted or not, its older row is
taken out of the older part, and a row left twice by a run that was killed is dropped
the same way by the next. The rows already there are indexed compactly (sorted ids,
seeds, fingerprints: some 50 bytes a row) to tell which plants are done.

A manifest of another format (an older plantgen's single file, a Parquet file or a folder
some other program wrote, a damaged part) is refused with one line before any work, and
left as it is.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import PlantgenError, missing_extra
from ..files import temporary_name, write_atomically
from .plant import files_column, relative_files
from .schema import FORMAT, METRIC_COLUMNS, arrow_schema
from .spec import Outputs, PlantTask

__all__ = ["Manifest", "MANIFEST_NAME", "PART_ROWS", "figure_quantiles", "manifest_parts", "read_manifest"]

MANIFEST_NAME = "manifest.parquet"
#: Rows a part holds at most (the client keeps one part's rows in memory).
PART_ROWS = 10_000

_PART = re.compile(r"part-(\d{6,})\.parquet")
_TEMPORARY = re.compile(r"\.part-\d{6,}\.parquet\.part\.parquet")        # files.temporary_name of a part
_MOVE_AWAY = "move it away (or give another --out) to start afresh"


def _pyarrow():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise PlantgenError(missing_extra("plantgen batch", "batch")) from None
    return pa, pq


def _check_part(path: Path) -> None:
    """One line unless ``path`` is a readable part of this format."""
    _, pq = _pyarrow()
    try:
        schema = pq.read_schema(path)
    except Exception as exc:   # pyarrow raises several kinds for a damaged file
        raise PlantgenError(f"{path}: not a readable manifest part ({exc.__class__.__name__}); {_MOVE_AWAY}") from None
    found = (schema.metadata or {}).get(b"plantgen", b"").decode(errors="replace")
    if found != FORMAT:
        what = f"a manifest part of another format ({found})" if found else "not a plantgen manifest part"
        raise PlantgenError(f"{path}: {what}, not {FORMAT}; {_MOVE_AWAY}")


def manifest_parts(path: Path, tidy: bool = False) -> dict[int, Path]:
    """The parts of the manifest folder ``path`` by number ({} if there is none); one line
    for anything else there (a file in its place, a foreign file, a part of another format).
    Hidden temporary parts are passed over (a running batch may be writing one); with
    ``tidy`` (a run about to write) they are removed, as a killed run left them."""
    if not path.exists() and not path.is_symlink():
        return {}
    if not path.is_dir():
        raise PlantgenError(f"{path}: {_not_a_folder(path)}; {_MOVE_AWAY}")
    parts: dict[int, Path] = {}
    try:
        entries = sorted(path.iterdir())
    except OSError as exc:
        raise PlantgenError(f"{path}: cannot read ({exc.strerror or exc.__class__.__name__})") from None
    for entry in entries:
        m = _PART.fullmatch(entry.name)
        if m and entry.is_file():
            _check_part(entry)
            parts[int(m.group(1))] = entry
        elif _TEMPORARY.fullmatch(entry.name) and entry.is_file():
            if tidy:
                entry.unlink(missing_ok=True)
        else:
            raise PlantgenError(f"{path}: not a plantgen manifest (it holds {entry.name!r}); {_MOVE_AWAY}")
    return parts


def _not_a_folder(path: Path) -> str:
    """What is where a manifest folder belongs."""
    if not path.is_file():
        return "not a folder (a manifest is a folder of Parquet parts)"
    _, pq = _pyarrow()
    try:
        names = pq.read_schema(path).names
    except Exception:   # not Parquet at all
        names = []
    if {"id", "seed", "status"} <= set(names):
        return "a manifest of an older plantgen (one file; a manifest is now a folder of parts)"
    return "not a plantgen manifest (a manifest is a folder of Parquet parts)"


def read_manifest(folder: str | Path):
    """The whole manifest of a batch folder as one pyarrow table, a plant's newest row only
    (an empty table for none)."""
    pa, pq = _pyarrow()
    parts = manifest_parts(Path(folder) / MANIFEST_NAME)
    tables = [pq.read_table(parts[n], schema=arrow_schema()) for n in sorted(parts, reverse=True)]
    if not tables:
        return arrow_schema().empty_table()
    table = pa.concat_tables(tables)
    ids = table["id"].to_numpy(zero_copy_only=False)
    _, first = np.unique(ids, return_index=True)            # the newest part comes first
    return table.take(np.sort(first))


class _Index:
    """The rows already in the manifest, by id: sorted ``ids`` (bytes) with each row's
    ``part``, ``ok``, ``seed`` and ``fingerprint`` (bytes); ``stale``: (part, id) of rows
    a newer part repeats; ``remade``: the rows of plants this run makes again."""

    def __init__(self, parts: dict[int, Path]):
        _, pq = _pyarrow()
        import pyarrow.compute as pc

        cols: dict[str, list] = {"id": [], "part": [], "ok": [], "seed": [], "fingerprint": []}
        for number, path in parts.items():
            try:
                t = pq.read_table(path, columns=["id", "status", "seed", "fingerprint"], schema=arrow_schema())
            except Exception as exc:   # a part whose schema reads but whose data does not
                raise PlantgenError(f"{path}: not a readable manifest part ({exc.__class__.__name__}); "
                                    f"{_MOVE_AWAY}") from None
            cols["id"].append(t["id"].to_numpy(zero_copy_only=False).astype("S"))
            cols["ok"].append(pc.fill_null(pc.equal(t["status"], "ok"), False).to_numpy(zero_copy_only=False))
            cols["seed"].append(pc.fill_null(t["seed"], -1).to_numpy())
            cols["fingerprint"].append(pc.fill_null(t["fingerprint"], "").to_numpy(zero_copy_only=False).astype("S"))
            cols["part"].append(np.full(len(t), number, dtype=np.int64))
        empty = {"id": np.zeros(0, "S1"), "part": np.zeros(0, np.int64), "ok": np.zeros(0, bool),
                 "seed": np.zeros(0, np.int64), "fingerprint": np.zeros(0, "S1")}
        cat = {k: np.concatenate(v) if v else empty[k] for k, v in cols.items()}
        order = np.lexsort((-cat["part"], cat["id"]))           # by id, its newest part first
        ids = cat["id"][order]
        newest = np.ones(len(ids), dtype=bool)
        newest[1:] = ids[1:] != ids[:-1]
        self.stale = [(int(p), i) for p, i in zip(cat["part"][order][~newest], ids[~newest], strict=True)]
        keep = order[newest]
        self.ids = ids[newest]
        self.part, self.ok, self.seed = cat["part"][keep], cat["ok"][keep], cat["seed"][keep]
        self.fingerprint = cat["fingerprint"][keep]
        self.remade = np.zeros(len(self.ids), dtype=bool)

    def __len__(self) -> int:
        return len(self.ids)

    def find(self, plant_id: str) -> int | None:
        key = plant_id.encode()
        if len(key) > self.ids.dtype.itemsize:           # longer than every id listed
            return None
        i = int(np.searchsorted(self.ids, key))
        return i if i < len(self.ids) and self.ids[i] == key else None


class Manifest:
    """A batch folder's manifest: which plants are done (:meth:`check`), rows added as
    plants finish (:meth:`add`), written in parts (:meth:`flush`) and tidied at the end
    (:meth:`close`)."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.path = self.folder / MANIFEST_NAME
        self.parts = manifest_parts(self.path, tidy=True)
        self.index = _Index(self.parts)
        self.part = max(self.parts, default=-1) + 1
        self.rows = 0                      # rows added this run
        self._buffer: list[dict] = []
        self._tables: list = []            # the part being filled

    def check(self, task: PlantTask, outputs: Outputs) -> str | None:
        """None when ``task`` is done (an ``ok`` row with its seed and fingerprint, and every
        file ``outputs`` asks for there), else why it is to be made: ``new``, ``failed
        before``, ``other seed``, ``other settings`` or ``files missing``."""
        i = self.index.find(task.id)
        if i is None:
            return "new"
        if not self.index.ok[i]:
            reason = "failed before"
        elif self.index.seed[i] != task.seed:
            reason = "other seed"
        elif self.index.fingerprint[i] != task.fingerprint.encode():
            reason = "other settings"
        elif not all((self.folder / f).is_file() for paths in files_column(relative_files(task, outputs)).values()
                     for f in ([paths] if isinstance(paths, str) else paths)):
            reason = "files missing"
        else:
            return None
        self.index.remade[i] = True
        return reason

    def add(self, row: dict) -> None:
        self._buffer.append(row)
        self.rows += 1

    def flush(self) -> None:
        """Write the rows added since the last flush into the part being filled (atomically);
        a full part is left as it is and the next rows start another."""
        if not self._buffer:
            return
        pa, pq = _pyarrow()
        self._tables.append(pa.Table.from_pylist(self._buffer, schema=arrow_schema()))
        self._buffer = []
        table = pa.concat_tables(self._tables).combine_chunks()

        self.path.mkdir(exist_ok=True)           # the parts' folder first: outputs are checked before they are written
        write_atomically(self.path / f"part-{self.part:06d}.parquet", lambda tmp: pq.write_table(table, tmp))
        if len(table) >= PART_ROWS:
            self.part += 1
            self._tables = []

    def close(self) -> None:
        """Flush, then take out of the older parts the rows of plants made again (and the
        repeated rows a killed run left)."""
        self.flush()
        drop: dict[int, list] = {}
        for part, plant in self.index.stale:
            drop.setdefault(part, []).append(plant)
        for i in np.flatnonzero(self.index.remade):
            drop.setdefault(int(self.index.part[i]), []).append(self.index.ids[i])
        for part, ids in drop.items():
            _drop_rows(self.parts[part], [i.decode() for i in ids])
        self.index.stale = []
        self.index.remade[:] = False


def figure_quantiles(folder: str | Path, columns=("segments", "scan_points", *METRIC_COLUMNS)) -> dict:
    """The 5th, 50th and 95th percentile of each figure over the ``ok`` rows of a batch
    folder's manifest, read one column at a time: {column: (p5, p50, p95)}."""
    import pyarrow.compute as pc
    import pyarrow.dataset as ds

    path = Path(folder) / MANIFEST_NAME
    if not path.is_dir():
        return {}
    data = ds.dataset(path, format="parquet", schema=arrow_schema())
    out = {}
    for name in columns:
        values = data.to_table(columns=[name], filter=pc.field("status") == "ok")[name].drop_null()
        if len(values):
            out[name] = tuple(float(q) for q in pc.quantile(values, q=[0.05, 0.5, 0.95]).to_pylist())
    return out


def _drop_rows(path: Path, ids: list[str]) -> None:
    """Rewrite the part ``path`` without the rows of ``ids`` (remove it if none is left)."""
    pa, pq = _pyarrow()
    import pyarrow.compute as pc

    table = pq.read_table(path, schema=arrow_schema())
    kept = table.filter(pc.invert(pc.is_in(table["id"], value_set=pa.array(ids, pa.string()))))
    if len(kept) == len(table):
        return
    if len(kept) == 0:
        path.unlink()
        temporary_name(path).unlink(missing_ok=True)
    else:
        write_atomically(path, lambda tmp: pq.write_table(kept, tmp))
