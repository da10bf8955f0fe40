"""A batch, as data: which plants (grammars × seed indices × sweeps over their defines)
and which files each one gets.

A spec file (YAML, read through :func:`plantgen.files.read_yaml` with the input bounds)::

    seed: 7                       # the batch seed (default 0)
    plants:
      - grammar: pine             # a shipped name or a path (relative to the spec's folder)
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
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import fields
from ..errors import PlantgenError
from ..files import read_yaml
from ..geometry.scan import ScanSettings
from ..knobs import knob_of
from ..limits import Limits
from ..limits import limits as default_limits
from ..scanfiles import check_point_output
from ..settings import MeshSettings

__all__ = ["BatchError", "Outputs", "PlantTask", "BatchSpec", "plant_seed", "parse_spec", "simple_spec",
           "MASK_KINDS", "OUTPUT_KINDS", "POINT_FORMATS", "MAX_PLANTS"]

#: Per-pixel labels a part mask can hold.
MASK_KINDS = ("instance", "order", "material")
#: The outputs a plant may get.
OUTPUT_KINDS = ("npz", "swc", "glb", "png", "depth", "mask", "points")
#: Point file formats of the ``points`` output (a simulated laser scan), by suffix.
POINT_FORMATS = ("ply", "las", "laz")
#: Plants one batch may hold.
MAX_PLANTS = 10_000_000

_RANGE = re.compile(r"\s*(\d+)\s*:\s*(\d+)\s*")


class BatchError(PlantgenError):
    """A batch spec or argument that breaks the contract."""


@dataclass(frozen=True)
class Outputs:
    """What each plant gets: ``npz``, ``swc`` (bool), ``glb`` (level m or None), views
    (``size`` (w, h), ``azimuths`` degrees, ``relief``) as ``png`` and optionally ``depth``
    and a ``mask`` (one of :data:`MASK_KINDS` or None), and ``points``: a simulated laser
    scan (:func:`plantgen.geometry.scan.scan_plant` with ``scan``'s knobs, its noise drawn
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


@dataclass(frozen=True)
class PlantTask:
    """One plant: ``id`` (unique in the batch, a file name stem), the ``grammar`` path to
    grow and its ``name`` as the spec gave it, ``index`` in its seed range, the ``seed``
    and the ``defines`` overridden (a tuple of (name, value), sorted)."""

    id: str
    grammar: str
    name: str
    index: int
    seed: int
    defines: tuple = ()


@dataclass(frozen=True)
class BatchSpec:
    seed: int
    tasks: tuple[PlantTask, ...]
    outputs: Outputs
    folder: Path = field(default_factory=Path.cwd)


def plant_seed(batch_seed: int, grammar: str, index: int) -> int:
    """The seed of plant ``index`` of ``grammar`` in a batch seeded ``batch_seed``: 31 bits
    of BLAKE2b over the three (independent of worker count and order, stable across
    machines and Python versions)."""
    digest = hashlib.blake2b(f"{int(batch_seed)}/{grammar}/{int(index)}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little") & 0x7FFFFFFF


def _grammar_path(name: str, folder: Path) -> str:
    """A shipped grammar's name, or a path relative to the spec's folder."""
    from .._resources import grammars_dir

    p = Path(name)
    if not p.suffix and p.name == name and (grammars_dir() / f"{name}.yaml").is_file():
        return str(grammars_dir() / f"{name}.yaml")
    p = p if p.is_absolute() else folder / p
    if not p.is_file():
        raise BatchError(f"grammar {name!r}: no such file and no shipped grammar of that name")
    return str(p)


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


def _sweep_points(raw, where: str, rng_key: str) -> list[tuple]:
    """The define assignments of a sweep: [()] without one."""
    if raw is None:
        return [()]
    raw = fields.keys(raw, {"grid", "random"}, where, BatchError)
    if len(raw) != 1:
        raise BatchError(f"{where}: a sweep is either grid or random")
    kind, body = next(iter(raw.items()))
    if kind == "grid":
        grid = fields.keys(body, None, f"{where}: grid", BatchError)
        names = sorted(grid)
        values = []
        for n in names:
            vals = grid[n] if isinstance(grid[n], list) else [grid[n]]
            if not vals or len(vals) > 10_000:
                raise BatchError(f"{where}: grid: {n} needs 1..10000 values")
            values.append([fields.number(v, "a value", f"{where}: grid: {n}", BatchError) for v in vals])
        points = list(itertools.product(*values))
        if len(points) > MAX_PLANTS:
            raise BatchError(f"{where}: the grid has {len(points):,} points, over {MAX_PLANTS:,}")
        return [tuple(zip(names, p, strict=True)) for p in points]
    body = fields.keys(body, {"count", "ranges"}, f"{where}: random", BatchError)
    count = fields.integer(body.get("count"), "count", f"{where}: random", BatchError, lo=1, hi=MAX_PLANTS)
    ranges = fields.keys(body.get("ranges"), None, f"{where}: random: ranges", BatchError)
    names = sorted(ranges)
    bounds = []
    for n in names:
        pair = fields.vector(ranges[n], "a range [low, high]", f"{where}: random: ranges: {n}", BatchError, n=2)
        if not pair[0] <= pair[1]:
            raise BatchError(f"{where}: random: ranges: {n}: low must not exceed high")
        bounds.append(pair)
    rng = np.random.default_rng(int.from_bytes(hashlib.blake2b(rng_key.encode(), digest_size=8).digest(), "little"))
    draws = rng.uniform(0.0, 1.0, (count, len(names)))
    return [tuple((n, float(lo + u * (hi - lo))) for n, (lo, hi), u in zip(names, bounds, row, strict=True))
            for row in draws]


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
    mapping of ``format`` and :class:`~plantgen.geometry.scan.ScanSettings` knobs by field
    name)."""
    raw = raw if isinstance(raw, dict) else {}
    knobs = {f.name for f in dataclasses.fields(ScanSettings)}
    raw = fields.keys(raw, {"format", *knobs}, where, BatchError)
    fmt = raw.get("format", POINT_FORMATS[0])
    if fmt not in POINT_FORMATS:
        raise BatchError(f"{where}: format must be one of {', '.join(POINT_FORMATS)}, got {fields.show(fmt)}")
    try:
        check_point_output(Path(f"points.{fmt}"))       # laspy (and lazrs) for LAS and LAZ, before any work
        settings = ScanSettings(**{k: v for k, v in raw.items() if k != "format"})
    except (PlantgenError, TypeError, ValueError) as exc:
        raise BatchError(f"{where}: {str(exc).splitlines()[0]}") from None
    return {"points": fmt, "scan": settings}


def _view_fields(png: dict, where: str) -> dict:
    kw: dict = {}
    if "size" in png:
        m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", str(png["size"]))
        if not m or not (0 < int(m.group(1)) <= 4096 and 0 < int(m.group(2)) <= 4096):
            raise BatchError(f"{where}: size must be WIDTHxHEIGHT with sides 1..4096, got {fields.show(png['size'])}")
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


def _tasks(entries, batch_seed: int, folder: Path, where: str) -> tuple[PlantTask, ...]:
    if not isinstance(entries, list) or not entries:
        raise BatchError(f"{where}: plants must be a non-empty list")
    tasks: list[PlantTask] = []
    ids: set[str] = set()
    for i, entry in enumerate(entries):
        w = f"{where}: plants[{i}]"
        entry = fields.keys(entry, {"grammar", "seeds", "sweep"}, w, BatchError)
        name = fields.text(entry.get("grammar"), "grammar", w, BatchError, max_len=500)
        path = _grammar_path(name, folder)
        seeds = parse_seeds(entry.get("seeds", 1), w)
        stem = re.sub(r"[^A-Za-z0-9_-]+", "_", Path(name).stem) or "plant"
        points = _sweep_points(entry.get("sweep"), f"{w}: sweep", f"{batch_seed}/{name}/sweep")
        if len(points) * len(seeds) + len(tasks) > MAX_PLANTS:
            raise BatchError(f"{w}: over the {MAX_PLANTS:,} plants a batch may hold")
        for p, defines in enumerate(points):
            for index in seeds:
                pid = f"{stem}-{index:06d}" if len(points) == 1 else f"{stem}-s{p:04d}-{index:06d}"
                if pid in ids:
                    raise BatchError(f"{w}: plant {pid} appears twice (the same grammar twice: give one entry)")
                ids.add(pid)
                tasks.append(PlantTask(pid, path, name, index, plant_seed(batch_seed, name, index), defines))
    return tuple(tasks)


def parse_spec(path: str | Path, limits: Limits | None = None) -> BatchSpec:
    """Read a batch spec file (see the module docstring); one :class:`BatchError` line for
    anything wrong with it."""
    path = Path(path)
    data = read_yaml(path, BatchError, limits or default_limits)
    where = str(path)
    data = fields.keys(data, {"seed", "plants", "outputs"}, where, BatchError)
    seed = fields.integer(data.get("seed", 0), "seed", where, BatchError, lo=0, hi=2**63 - 1)
    folder = path.resolve().parent
    tasks = _tasks(data.get("plants"), seed, folder, where)
    return BatchSpec(seed, tasks, _parse_outputs(data.get("outputs"), f"{where}: outputs"), folder)


def simple_spec(grammar: str, seeds: str, outputs: list[str], *, seed: int = 0, size=None,
                azimuths=None, relief: bool = False, glb_level: int = 1, mask: str = "order",
                scan: ScanSettings | None = None) -> BatchSpec:
    """The spec of ``plantgen batch GRAMMAR --seeds a:b --outputs npz,png,...`` (``scan``:
    the knobs of the ``points`` output's scan; its points are PLY)."""
    unknown = sorted(set(outputs) - set(OUTPUT_KINDS))
    if unknown:
        raise BatchError(f"--outputs: unknown {', '.join(unknown)} (known: {', '.join(OUTPUT_KINDS)})")
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
    folder = Path.cwd()
    out = _parse_outputs(raw, "--outputs")
    if out.points is not None and scan is not None:
        out = dataclasses.replace(out, scan=scan)
    if ("depth" in outputs or "mask" in outputs) and "png" not in outputs:
        out = Outputs(**{**out.__dict__, **_view_fields(view, "--outputs")})
    tasks = _tasks([{"grammar": grammar, "seeds": seeds}], seed, folder, "batch")
    return BatchSpec(seed, tasks, out, folder)
