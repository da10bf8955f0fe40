"""A batch, as data: which plants (grammars × seed indices × sweeps over their defines)
and which files each one gets.

A spec file (YAML, read through :func:`plantgen.files.read_yaml` with the input bounds)::

    seed: 7                       # the batch seed (default 0)
    plants:
      - grammar: pine             # a shipped name or a path inside the spec's folder
        seeds: 0:100              # indices a:b (b excluded), or a count N (0:N)
        sweep:                    # optional, over the grammar's defines
          grid: {angle: [20, 25]} #   every combination, or
          random: {count: 8, ranges: {angle: [15, 35]}}   # draws from ranges
    outputs:
      npz: true                   # the skeleton, with branch order and id per segment
      swc: true
      glb: {level: 1}             # a mesh at subdivision m
      png: {size: 512x384, azimuths: [0, 90], relief: false}
      depth: true                 # float32 .npy of each view's distances (inf: miss)
      mask: order                 # a part mask PNG per view: instance, order or material

Every plant's seed derives from the batch seed, the grammar's name and the plant's index
(:func:`plant_seed`), never from the order plants run in, so any number of workers makes
the same files, and ``plantgen grow GRAMMAR --seed S --define k=v`` makes any one again.

A spec is read whole, but its plants are not built: each entry is a :class:`PlantGroup`
(a grammar, a seed range and a :class:`Sweep`) whose size is a product computed before
anything is made (a grid of 10^12 points is refused in microseconds), and
:meth:`BatchSpec.tasks` yields the plants one at a time. A grammar path stays inside the
spec's folder (and the folders of ``allow_paths``), by the rule scenes follow
(:func:`plantgen.scene.resolve_grammar`): ``../x.yaml``, ``/etc/passwd`` or a link
pointing out is refused before it is opened.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import re
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from .. import fields
from ..errors import PlantgenError
from ..files import read_input, read_yaml, real_path
from ..geometry.rays.scan import ScanSettings
from ..knobs import knob_of
from ..limits import Limits
from ..limits import limits as default_limits
from ..scanfiles import check_point_output
from ..scene import resolve_grammar
from ..settings import MeshSettings

__all__ = ["BatchError", "Outputs", "PlantTask", "PlantGroup", "Sweep", "BatchSpec", "plant_seed", "parse_spec",
           "simple_spec", "MASK_KINDS", "OUTPUT_KINDS", "POINT_FORMATS", "MAX_PLANTS", "MAX_VIEW_SIDE"]

#: Per-pixel labels a part mask can hold.
MASK_KINDS = ("instance", "order", "material")
#: The outputs a plant may get.
OUTPUT_KINDS = ("npz", "swc", "glb", "png", "depth", "mask", "points")
#: Point file formats of the ``points`` output (a simulated laser scan), by suffix.
POINT_FORMATS = ("ply", "las", "laz")
#: Plants one batch may hold.
MAX_PLANTS = 10_000_000
#: The largest side of a batch view, in pixels.
MAX_VIEW_SIDE = 4096
#: Values one name of a grid sweep may take.
MAX_GRID_VALUES = 10_000
#: Rows of random sweep draws made at a time (the draws do not depend on it).
DRAW_CHUNK = 4096

_RANGE = re.compile(r"\s*(\d{1,18})\s*:\s*(\d{1,18})\s*")   # bounded: no 5,000-digit int() is ever tried


class BatchError(PlantgenError):
    """A batch spec or argument that breaks the contract."""


@dataclass(frozen=True)
class Outputs:
    """What each plant gets: ``npz``, ``swc`` (bool), ``glb`` (level m or None), views
    (``size`` (w, h), ``azimuths`` degrees, ``relief``) as ``png`` and optionally ``depth``
    and a ``mask`` (one of :data:`MASK_KINDS` or None), and ``points``: a simulated laser
    scan (:func:`plantgen.geometry.rays.scan.scan_plant` with ``scan``'s knobs, its noise drawn
    from the plant's seed) written in that format (one of :data:`POINT_FORMATS`, or None)."""

    npz: bool = True
    swc: bool = False
    glb: int | None = None
    png: bool = False
    size: tuple[int, int] = (512, 384)
    azimuths: tuple[float, ...] = (0.0,)
    relief: bool = False
    depth: bool = False
    mask: str | None = None
    points: str | None = None
    scan: ScanSettings = ScanSettings()

    @property
    def views(self) -> bool:
        """Whether anything is rendered (a PNG, a depth image or a mask)."""
        return self.png or self.depth or self.mask is not None

    def key(self) -> dict:
        """What shapes the files, as plain data: every field, the view's only where there is
        a view (a new size does not make an npz-only batch again), the scan's only where
        there are points."""
        data = asdict(self)
        if not self.views:
            for name in ("size", "azimuths", "relief"):
                data.pop(name)
        if self.points is None:
            data.pop("scan")
        return data


@dataclass(frozen=True)
class PlantTask:
    """One plant: ``id`` (unique in the batch, a file name stem), the ``grammar`` path to
    grow and its ``name`` as the spec gave it, ``index`` in its seed range, the ``seed``,
    the ``defines`` overridden (a tuple of (name, value), sorted) and the ``fingerprint`` of
    everything else that shapes its files (:meth:`PlantGroup.fingerprint`)."""

    id: str
    grammar: str
    name: str
    index: int
    seed: int
    defines: tuple = ()
    fingerprint: str = ""


def _digest(*parts) -> str:
    return hashlib.blake2b(json.dumps(parts, sort_keys=True).encode(), digest_size=8).hexdigest()


@dataclass(frozen=True)
class Sweep:
    """The define assignments of one spec entry, made one at a time: every combination of
    ``grid`` (values per name), ``count`` uniform draws from ``bounds`` (low, high per name;
    the generator seeded by ``key``), or one empty assignment. ``names`` sorted."""

    names: tuple[str, ...] = ()
    grid: tuple[tuple[float, ...], ...] | None = None
    bounds: tuple[tuple[float, float], ...] | None = None
    count: int = 1
    key: str = ""

    def points(self) -> Iterator[tuple]:
        """Each assignment, a tuple of (name, value), in a fixed order."""
        if self.grid is not None:
            for values in itertools.product(*self.grid):
                yield tuple(zip(self.names, values, strict=True))
        elif self.bounds is not None:
            rng = np.random.default_rng(int.from_bytes(hashlib.blake2b(self.key.encode(), digest_size=8).digest(),
                                                       "little"))
            for start in range(0, self.count, DRAW_CHUNK):       # the generator's stream, a chunk at a time
                for row in rng.uniform(0.0, 1.0, (min(DRAW_CHUNK, self.count - start), len(self.names))):
                    yield tuple((n, float(lo + u * (hi - lo)))
                                for n, (lo, hi), u in zip(self.names, self.bounds, row, strict=True))
        else:
            yield ()


@dataclass(frozen=True)
class PlantGroup:
    """One entry of a spec: the ``grammar`` file (``name`` as the spec gave it), plant
    indices ``seeds``, a ``sweep`` over its defines, the ``stem`` of its plants' ids and the
    ``source`` digest of the grammar file's bytes."""

    name: str
    grammar: str
    seeds: range
    sweep: Sweep
    stem: str
    source: str = ""

    def __len__(self) -> int:
        return len(self.seeds) * self.sweep.count

    def plant_id(self, point: int, index: int) -> str:
        return f"{self.stem}-{index:06d}" if self.sweep.count == 1 else f"{self.stem}-s{point:04d}-{index:06d}"

    def fingerprint(self, outputs: Outputs, defines: tuple) -> str:
        """A digest of what shapes a plant's files besides its seed: the outputs, the
        grammar file's bytes, the defines and plantgen's version."""
        return _digest(outputs.key(), self.source, [list(d) for d in defines], _version())

    def tasks(self, batch_seed: int, outputs: Outputs) -> Iterator[PlantTask]:
        """The group's plants, one at a time (sweep points outer, seed indices inner)."""
        for p, defines in enumerate(self.sweep.points()):
            fingerprint = self.fingerprint(outputs, defines)
            for index in self.seeds:
                yield PlantTask(self.plant_id(p, index), self.grammar, self.name, index,
                                plant_seed(batch_seed, self.name, index), defines, fingerprint)


@dataclass(frozen=True)
class BatchSpec:
    """A batch: its ``seed``, plant ``groups``, ``outputs``, the spec's ``folder`` and the
    extra folders grammars may be read from (``allow_paths``, absolute)."""

    seed: int
    groups: tuple[PlantGroup, ...]
    outputs: Outputs
    folder: Path = field(default_factory=Path.cwd)
    allow_paths: tuple[str, ...] = ()

    @property
    def total(self) -> int:
        """Plants in the batch (computed, nothing built)."""
        return sum(len(g) for g in self.groups)

    def tasks(self) -> Iterator[PlantTask]:
        """Every plant, one at a time, in the spec's order."""
        for group in self.groups:
            yield from group.tasks(self.seed, self.outputs)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("plantgen")
    except PackageNotFoundError:
        return "unknown"


def plant_seed(batch_seed: int, grammar: str, index: int) -> int:
    """The seed of plant ``index`` of ``grammar`` in a batch seeded ``batch_seed``: 31 bits
    of BLAKE2b over the three (independent of worker count and order, stable across
    machines and Python versions)."""
    digest = hashlib.blake2b(f"{int(batch_seed)}/{grammar}/{int(index)}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little") & 0x7FFFFFFF


def parse_seeds(value, where: str) -> range:
    """``a:b`` (b excluded) or a count ``N`` (``0:N``) as a range."""
    if isinstance(value, str):
        m = _RANGE.fullmatch(value)
        if not m or int(m.group(2)) <= int(m.group(1)):
            raise BatchError(f"{where}: seeds must be a:b with a < b (b excluded) or a count, got {fields.show(value)}")
        lo, hi = int(m.group(1)), int(m.group(2))
    else:
        lo, hi = 0, fields.integer(value, "seeds", where, BatchError, lo=1, hi=MAX_PLANTS)
    if hi - lo > MAX_PLANTS:
        raise BatchError(f"{where}: {hi - lo:,} seeds, over the {MAX_PLANTS:,} a batch may hold")
    return range(lo, hi)


def _grid(body, where: str) -> Sweep:
    grid = fields.keys(body, None, f"{where}: grid", BatchError)
    names = tuple(sorted(grid))
    lists = [grid[n] if isinstance(grid[n], list) else [grid[n]] for n in names]
    for n, vals in zip(names, lists, strict=True):
        if not 1 <= len(vals) <= MAX_GRID_VALUES:
            raise BatchError(f"{where}: grid: {n} needs 1..{MAX_GRID_VALUES} values")
    count = math.prod(len(v) for v in lists)          # before a point is built
    if count > MAX_PLANTS:
        raise BatchError(f"{where}: the grid has {count:,} points, over the {MAX_PLANTS:,} plants a batch may hold")
    values = tuple(tuple(fields.number(v, "a value", f"{where}: grid: {n}", BatchError) for v in vals)
                   for n, vals in zip(names, lists, strict=True))
    return Sweep(names, grid=values, count=count)


def _random(body, where: str, rng_key: str) -> Sweep:
    body = fields.keys(body, {"count", "ranges"}, f"{where}: random", BatchError)
    count = fields.integer(body.get("count"), "count", f"{where}: random", BatchError, lo=1, hi=MAX_PLANTS)
    ranges = fields.keys(body.get("ranges"), None, f"{where}: random: ranges", BatchError)
    names = tuple(sorted(ranges))
    bounds = []
    for n in names:
        pair = fields.vector(ranges[n], "a range [low, high]", f"{where}: random: ranges: {n}", BatchError, n=2)
        if not pair[0] <= pair[1]:
            raise BatchError(f"{where}: random: ranges: {n}: low must not exceed high")
        bounds.append((float(pair[0]), float(pair[1])))
    return Sweep(names, bounds=tuple(bounds), count=count, key=rng_key)


def _sweep(raw, where: str, rng_key: str) -> Sweep:
    """The define assignments of a sweep (one empty assignment without one)."""
    if raw is None:
        return Sweep()
    raw = fields.keys(raw, {"grid", "random"}, where, BatchError)
    if len(raw) != 1:
        raise BatchError(f"{where}: a sweep is either grid or random")
    kind, body = next(iter(raw.items()))
    return _grid(body, where) if kind == "grid" else _random(body, where, rng_key)


def _parse_outputs(raw, where: str) -> Outputs:
    raw = fields.keys(raw if raw is not None else {"npz": True}, set(OUTPUT_KINDS), where, BatchError)
    kw: dict = {}
    for flag in ("npz", "swc", "depth"):
        if flag in raw:
            if not isinstance(raw[flag], bool):
                raise BatchError(f"{where}: {flag} must be true or false")
            kw[flag] = raw[flag]
    kw.setdefault("npz", False)
    if raw.get("glb") not in (None, False):
        level = knob_of(MeshSettings, "level")
        glb = raw["glb"] if isinstance(raw["glb"], dict) else {"level": MeshSettings().level}
        glb = fields.keys(glb, {"level"}, f"{where}: glb", BatchError)
        kw["glb"] = fields.integer(glb.get("level", MeshSettings().level), "level", f"{where}: glb", BatchError,
                                   lo=int(level.lo), hi=int(level.hi))
    if raw.get("png") not in (None, False):
        png = raw["png"] if isinstance(raw["png"], dict) else {}
        png = fields.keys(png, {"size", "azimuths", "relief"}, f"{where}: png", BatchError)
        kw["png"] = True
        kw.update(_view_fields(png, f"{where}: png"))
    if raw.get("mask") is not None:
        if raw["mask"] not in MASK_KINDS:
            raise BatchError(f"{where}: mask must be one of {', '.join(MASK_KINDS)}, got {fields.show(raw['mask'])}")
        kw["mask"] = raw["mask"]
    if raw.get("points") not in (None, False):
        kw.update(_point_fields(raw["points"], f"{where}: points"))
    out = Outputs(**kw)
    if not (out.npz or out.swc or out.glb is not None or out.views or out.points):
        raise BatchError(f"{where}: no output asked for")
    return out


def _point_fields(raw, where: str) -> dict:
    """``points`` and ``scan`` of :class:`Outputs` from a spec's ``points:`` (true, or a
    mapping of ``format`` and :class:`~plantgen.geometry.rays.scan.ScanSettings` knobs by field
    name)."""
    raw = raw if isinstance(raw, dict) else {}
    knobs = {f.name for f in dataclasses.fields(ScanSettings)}
    raw = fields.keys(raw, {"format", *knobs}, where, BatchError)
    fmt = raw.get("format", POINT_FORMATS[0])
    if fmt not in POINT_FORMATS:
        raise BatchError(f"{where}: format must be one of {', '.join(POINT_FORMATS)}, got {fields.show(fmt)}")
    try:
        check_point_output(Path(f"points.{fmt}"), place=False)     # laspy (and lazrs) for LAS and LAZ, before any work
        settings = ScanSettings(**{k: v for k, v in raw.items() if k != "format"})
    except (PlantgenError, TypeError, ValueError) as exc:
        raise BatchError(f"{where}: {str(exc).splitlines()[0]}") from None
    return {"points": fmt, "scan": settings}


def _view_fields(png: dict, where: str) -> dict:
    kw: dict = {}
    if "size" in png:
        m = re.fullmatch(r"\s*(\d{1,18})\s*[xX]\s*(\d{1,18})\s*", str(png["size"]))
        if not m or not (0 < int(m.group(1)) <= MAX_VIEW_SIDE and 0 < int(m.group(2)) <= MAX_VIEW_SIDE):
            raise BatchError(f"{where}: size must be WIDTHxHEIGHT with sides 1..{MAX_VIEW_SIDE}, "
                             f"got {fields.show(png['size'])}")
        kw["size"] = (int(m.group(1)), int(m.group(2)))
    if "azimuths" in png:
        az = png["azimuths"] if isinstance(png["azimuths"], list) else [png["azimuths"]]
        if not 1 <= len(az) <= 64:
            raise BatchError(f"{where}: azimuths needs 1..64 angles")
        kw["azimuths"] = tuple(fields.number(a, "an azimuth", where, BatchError, lo=-360, hi=360) for a in az)
    if "relief" in png:
        if not isinstance(png["relief"], bool):
            raise BatchError(f"{where}: relief must be true or false")
        kw["relief"] = png["relief"]
    return kw


def _clash(a: PlantGroup, b: PlantGroup) -> bool:
    """Whether two groups could give a plant the same id (so the same files)."""
    overlap = a.seeds.start < b.seeds.stop and b.seeds.start < a.seeds.stop
    if a.stem == b.stem:
        return overlap and (a.sweep.count == 1) == (b.sweep.count == 1)
    # "x" swept gives x-s0001-000005, as "x-s0001" unswept does
    short, long_ = sorted((a, b), key=lambda g: len(g.stem))
    return overlap and re.fullmatch(re.escape(short.stem) + r"-s\d{4,}", long_.stem) is not None


def _group(entry, i: int, batch_seed: int, resolve, limits: Limits, where: str) -> PlantGroup:
    w = f"{where}: plants[{i}]"
    entry = fields.keys(entry, {"grammar", "seeds", "sweep"}, w, BatchError)
    name = fields.text(entry.get("grammar"), "grammar", w, BatchError, max_len=500)
    path = resolve(name, w)
    seeds = parse_seeds(entry.get("seeds", 1), w)
    sweep = _sweep(entry.get("sweep"), f"{w}: sweep", f"{batch_seed}/{name}/sweep")
    if len(seeds) * sweep.count > MAX_PLANTS:
        raise BatchError(f"{w}: {len(seeds) * sweep.count:,} plants, over the {MAX_PLANTS:,} a batch may hold")
    source = hashlib.blake2b(read_input(path, BatchError, max_bytes=limits.max_input_bytes, limit="input_bytes",
                                        what="grammar"), digest_size=8).hexdigest()
    stem = re.sub(r"[^A-Za-z0-9_-]+", "_", Path(name).stem) or "plant"
    return PlantGroup(name, str(path), seeds, sweep, stem, source)


def _groups(entries, batch_seed: int, resolve, limits: Limits, where: str) -> tuple[PlantGroup, ...]:
    """The spec's entries as plant groups; their total and their ids checked, nothing built."""
    if not isinstance(entries, list) or not entries:
        raise BatchError(f"{where}: plants must be a non-empty list")
    if len(entries) > 10_000:
        raise BatchError(f"{where}: {len(entries):,} entries in plants, over 10,000 (give seed ranges)")
    groups: list[PlantGroup] = []
    total = 0
    for i, entry in enumerate(entries):
        group = _group(entry, i, batch_seed, resolve, limits, where)
        total += len(group)
        if total > MAX_PLANTS:
            raise BatchError(f"{where}: plants[{i}]: over the {MAX_PLANTS:,} plants a batch may hold")
        for j, other in enumerate(groups):
            if _clash(other, group):
                raise BatchError(f"{where}: plants[{i}]: its plants' ids (and files) would be those of plants[{j}] "
                                 "(the same grammar twice: give one entry, or seed ranges that do not overlap)")
        groups.append(group)
    return tuple(groups)


def parse_spec(path: str | Path, limits: Limits | None = None, allow_paths=()) -> BatchSpec:
    """Read a batch spec file (see the module docstring); one :class:`BatchError` line for
    anything wrong with it. A grammar is read only from inside the spec's folder, the
    folders of ``allow_paths`` and the shipped grammars."""
    path = Path(path)
    limits = limits or default_limits
    data = read_yaml(path, BatchError, limits)
    where = str(path)
    data = fields.keys(data, {"seed", "plants", "outputs"}, where, BatchError)
    seed = fields.integer(data.get("seed", 0), "seed", where, BatchError, lo=0, hi=2**63 - 1)
    folder = real_path(path).parent
    allowed = tuple(str(real_path(p)) for p in allow_paths)

    def resolve(name: str, w: str) -> Path:
        return resolve_grammar(name, folder, w, allowed, error=BatchError, owner="spec")

    outputs = _parse_outputs(data.get("outputs"), f"{where}: outputs")
    groups = _groups(data.get("plants"), seed, resolve, limits, where)
    return BatchSpec(seed, groups, outputs, folder, allowed)


def simple_spec(grammar: str, seeds: str, outputs: list[str], *, seed: int = 0, size=None,
                azimuths=None, relief: bool = False, glb_level: int = 1, mask: str = "order",
                limits: Limits | None = None, scan: ScanSettings | None = None) -> BatchSpec:
    """The spec of ``plantgen batch GRAMMAR --seeds a:b --outputs npz,png,...`` (the grammar
    a path or a shipped name, as ``plantgen grow`` takes it; ``scan``: the knobs of the
    ``points`` output's scan; its points are PLY)."""
    from .._resources import missing_hint
    from ..pipeline import resolve_input

    unknown = sorted(set(outputs) - set(OUTPUT_KINDS))
    if unknown:
        raise BatchError(f"--outputs: unknown {', '.join(unknown)} (known: {', '.join(OUTPUT_KINDS)})")
    if size is not None:
        _view_fields({"size": size}, "--size")
    raw: dict = {k: True for k in outputs if k in ("npz", "swc", "depth")}
    if "glb" in outputs:
        raw["glb"] = {"level": glb_level}
    view = {k: v for k, v in (("size", size), ("azimuths", azimuths), ("relief", relief)) if v is not None}
    if "png" in outputs:
        raw["png"] = view
    if "mask" in outputs:
        raw["mask"] = mask
    if "points" in outputs:
        raw["points"] = True
    out = _parse_outputs(raw, "--outputs")
    if out.points is not None and scan is not None:
        out = replace(out, scan=scan)
    if ("depth" in outputs or "mask" in outputs) and "png" not in outputs:
        out = replace(out, **_view_fields(view, "--outputs"))

    def resolve(name: str, w: str) -> Path:
        path = resolve_input(name)
        if not path.is_file():
            raise BatchError(f"grammar {name!r}: no such file and no shipped grammar of that name"
                             f"{missing_hint(name)}")
        return real_path(path)

    groups = _groups([{"grammar": grammar, "seeds": seeds}], seed, resolve, limits or default_limits, "batch")
    return BatchSpec(seed, groups, out, Path.cwd())
