"""Simulated laser scans: terrestrial scanners around a plant, or airborne passes over it,
cast against the exact frusta and the leaf triangles (first return).

**Beams.** A scanner fires beams on a regular grid of two integers (a, b):

- *terrestrial* (``mode="terrestrial"``): scanners at ``positions``, or ``scanners`` of
  them evenly on a circle of radius ``distance`` around the plant's centre, at
  ``scanner_height`` above its base, the first at ``azimuth`` (degrees, 0 towards +x,
  90 towards +z). Beam (a, b) leaves the scanner at azimuth φ = φ_c + a·Δ and elevation
  θ = b·Δ (Δ = ``angular_step``, φ_c the azimuth of the plant's centre from the
  scanner), direction (cos θ cos φ, sin θ, cos θ sin φ), y up. A scanner fires only the
  beams whose direction can meet the plant's bounding box: it looks at the plant (from
  inside the box, at the whole sphere). Point spacing is Δ times the range.
- *airborne* (``mode="airborne"``): parallel flight lines heading ``azimuth`` at
  ``flight_height`` above the plant's base, ``line_spacing`` apart, over the plant; along
  each, a scan line every ``pulse_spacing``: beam (a, b) leaves the point a·``pulse_spacing``
  along the line, at b·Δ from the nadir across the track, |b·Δ| <= ``scan_angle`` (a
  rotating mirror's sweep, the aircraft taken as still during one sweep). ``scan_angle``
  0 gives one nadir beam per pulse: parallel lines of downward rays. A point's
  ``scanner`` is its flight line.

**Returns.** A beam's first return is the nearest hit of the frusta (the exact ray-cone
intersection of :class:`~plantgen.geometry.rays.reference.PairTester`, float64, clipped by
the cutting planes, open ends capped) and of the leaf triangles (Möller-Trumbore, both
faces; a ray in a leaf's plane misses it). A beam that hits nothing gives no point.

**Beam divergence** γ (``divergence``, full angle, milliradians): the beam is a cone of
half-angle γ/2 around its direction, sampled by ``beam_samples`` sub-rays spread
uniformly over its cross-section (a Vogel spiral, turned by a random angle per beam). The
beam's range is the nearest of its sub-rays' hits (``beam_return="first"``, a
discrete-return scanner's first echo) or their mean (``"mean"``: a mixed pixel, which at
an edge lands between the surfaces, as real scans do); the point lies on the beam's axis
at that range and takes the labels of the sub-ray that gave it (for the mean: the sub-ray
nearest to it). A first-return point is off the surface by at most range·γ/2. γ = 0:
one ray on the axis.

**Range noise**: the range gains Gaussian noise of sigma ``range_noise`` (model units),
along the beam.

**Determinism.** Every random number is a counter-based hash (SplitMix64) of the seed,
the scanner, the beam and a stream number: a point does not depend on how the pairs are
chunked or binned, nor on the other beams, so a seed gives the same cloud every time.

**Labels** of each point: ``plant`` (the ``plant`` given per segment, or one number),
``part`` (:data:`PART_NAMES`: ``stem`` for a segment of branch order 0 of
:mod:`plantgen.geometry.skeletons.topology`, ``branch`` above, ``leaf`` for a leaf triangle),
``order`` (the branch order; a leaf: the order of the segment it hangs from, -1 for
none), ``segment`` (the skeleton segment; a leaf: the one it hangs from, -1 for none),
``leaf`` (the leaf polygon, -1 for wood) and ``scanner``.

**Speed.** Every beam (every sub-ray) is traced through the target's bounding volume
hierarchy (:mod:`plantgen.geometry.rays.bvh`, built once per target), which finds its nearest
hit among the primitives whose boxes it meets, nearest boxes first; the beams stream in
chunks (``max_pairs`` sub-rays, at most :data:`SCAN_CHUNK_RAYS`), so memory stays bounded
whatever their count. A scene (:func:`scan_scene`, :class:`SceneTarget`) is traced in
two levels, each distinct plant once and the beams moved into each copy's frame in
float64, so it costs the memory of its distinct plants, not of its copies placed.
``precision="float32"`` with a ``finder`` (``plantgen scan`` passes the GPU's search,
:func:`plantgen.gl.trace.trace_target`) finds each beam's primitive in float32 and solves
its range again in float64 against that primitive (the reference's ranges wherever both
find the same primitive); without one it tests the frusta in float32 relative to the
scanner on the CPU (leaves stay float64): ``python -m plantgen.benchmarks.scan`` measures
what each saves and costs.

The scan lives in four modules: :mod:`plantgen.geometry.rays.scan_settings` (ScanSettings,
the labels, PointCloud), :mod:`plantgen.geometry.rays.scan_targets` (what is cast against,
first returns, labels of a hit), :mod:`plantgen.geometry.rays.beams` (the random numbers, beam
grids, scanner positions, sub-rays) and this one (casting the beams in chunks, each beam's
return, the point and memory budgets, the point cloud's assembly), which re-exports their
public names.

Pure numpy, no GL, no click. Files: :mod:`plantgen.scanfiles` (LAS, LAZ, PLY).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...limits import LimitError, Limits, hint
from ...limits import limits as default_limits
from ..meshes.polygons import Polygons
from ..skeletons.frusta import Frusta
from ..skeletons.skeleton import Skeleton
from ..skeletons.topology import Branches
from .beams import AirborneBeams, TerrestrialBeams, beam_grids, diverging_rays, normal_noise, scanner_positions
from .scan_settings import LABELS, PART_NAMES, SCAN_MODES, PointCloud, ScanError, ScanSettings
from .scan_targets import (
    ScanTarget,
    SceneTarget,
    cast_first_returns,
    primitive_labels,
    scan_target,
    scene_target,
    target_hits,
)

__all__ = ["LABELS", "PART_NAMES", "SCAN_MODES", "AirborneBeams", "BeamReturns", "PointCloud", "ScanError",
           "ScanSettings", "ScanTarget", "TerrestrialBeams", "beam_grids", "expected_points", "beam_returns",
           "cast_first_returns",
           "SceneTarget", "primitive_labels", "scan_plant", "scan_points", "scan_scene", "scan_target",
           "scanner_positions", "scene_target", "target_hits"]


#: Memory a returned point takes at a scan's peak (its range, primitive and sub-ray kept
#: while the scanner's beams are traced, their sort, then the point's compact columns and
#: the file's record), rounded up: the budget ``scan_bytes`` counts the points kept as they
#: come (measured: the forest from 2,1.5,10 at 0.05° and at 0.2°, 8,798,263 and 550,215
#: points, 1.34 GB and 0.32 GB peak resident: 124 bytes a point more).
POINT_BYTES = 160
#: Beams traced at a time (times a diverging beam's sub-rays): what bounds a scan's
#: working memory whatever its beam count.
SCAN_CHUNK_RAYS = 1 << 18
#: Neighbouring beams of a scanner (one origin) that walk the BVH's upper levels together.
PACKET_RAYS = 64


def _found_again(target, finder, origins, dirs) -> tuple[np.ndarray, np.ndarray]:
    """The first hits (t, primitive) of rays whose primitive ``finder(target, origins,
    dirs) -> (t, primitive)`` finds (the GPU's float32 search), each range solved again in
    float64 against that primitive (``target.hit_distance``); a ray whose primitive the
    float64 test then misses (a graze rounding decided the other way) is traced again by
    the float64 reference."""
    _, prim = finder(target, origins, dirs)
    prim = np.asarray(prim, np.int64).copy()
    t = np.full(len(prim), np.inf)
    found = np.flatnonzero(prim >= 0)
    t[found] = target.hit_distance(prim[found], origins[found], dirs[found])
    lost = found[~np.isfinite(t[found])]
    if len(lost):
        t[lost], prim[lost] = target.first_hits(origins[lost], dirs[lost])
    return t, np.where(np.isfinite(t), prim, -1)


def _candidates(target: ScanTarget, grid, settings: ScanSettings, seed: int, scanner: int, max_pairs: int,
                progress=None, finder=None, hold=None):
    """(sub-ray ids, t, primitive) of the first hit of each of the scanner's sub-rays that
    hits, traced through the target's BVH ``max_pairs`` sub-rays at a time (with a
    ``finder`` and precision float32: found by it, solved again in float64,
    :func:`_found_again`). ``hold(hits)`` is told each chunk's hits as they are kept (the
    scan's memory budget)."""
    s = settings.sub_rays
    step = max(1, min(max_pairs, SCAN_CHUNK_RAYS) // s)
    found = []
    for start in range(0, grid.count, step):
        beam = np.arange(start, min(start + step, grid.count), dtype=np.int64)
        origins, dirs = grid.rays(grid.a0 + beam // grid.nb, grid.b0 + beam % grid.nb)
        dirs = diverging_rays(dirs, beam, seed, scanner, s, settings.divergence / 2000.0)
        sub = (beam[:, None] * s + np.arange(s)).reshape(-1)
        if finder is not None and settings.precision == "float32":
            t, prim = _found_again(target, finder, np.repeat(origins, s, axis=0), dirs)
        else:
            t, prim = target.first_hits(np.repeat(origins, s, axis=0), dirs, precision=settings.precision,
                                        origin=grid.origin, packets=PACKET_RAYS)
        hit = np.isfinite(t)
        found.append((sub[hit], t[hit], prim[hit]))
        if hold is not None:
            hold(len(found[-1][0]))
        if progress is not None:
            progress(len(beam))
    if not found:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
    return tuple(np.concatenate(parts) for parts in zip(*found, strict=True))


def _nearest(key: np.ndarray, t: np.ndarray, *others) -> tuple:
    """The rows with the smallest t of each key, ordered by key."""
    order = np.lexsort((t, key))
    first = order[np.r_[True, key[order][1:] != key[order][:-1]]] if len(order) else order
    return (key[first], t[first], *(o[first] for o in others))


def _beam_returns(sub, t, prim, samples: int, how: str):
    """(beams, range, primitive) of every beam with a return, in beam order. The sub-rays
    come from :func:`_candidates` increasing, one hit each: then they are sorted already
    (no sort, no copy: a scan's peak memory is its points), else each one's nearest hit
    is taken first."""
    if len(sub) > 1 and not (sub[1:] > sub[:-1]).all():
        sub, t, prim = _nearest(sub, t, prim)          # each sub-ray's first hit
    if samples == 1:
        return sub, t, prim
    beam = sub // samples
    if how == "first":
        beam, t, prim = _nearest(beam, t, prim)
        return beam, t, prim
    starts = np.flatnonzero(np.r_[True, beam[1:] != beam[:-1]])
    counts = np.diff(np.r_[starts, len(beam)])
    mean = np.add.reduceat(t, starts) / counts
    group = np.repeat(np.arange(len(starts)), counts)
    closest = _nearest(group, np.abs(t - mean[group]), np.arange(len(t)))[2]
    return beam[starts], mean, prim[closest]


@dataclass(frozen=True, eq=False)
class BeamReturns:
    """One scanner's returns before noise: ``beam`` (k,) the beams with a return (index
    a·nb + b into the scanner's grid, increasing), ``range`` (k,) their exact ranges and
    ``primitive`` (k,) what each hit (a frustum row, or rows + a leaf triangle)."""

    scanner: int
    beam: np.ndarray
    range: np.ndarray
    primitive: np.ndarray
    beams: int                       # beams the scanner fired


def beam_returns(target: ScanTarget, settings: ScanSettings, seed: int = 0, *,
                 max_pairs: int = 1 << 20, finder=None) -> list[BeamReturns]:
    """Every scanner's :class:`BeamReturns` (what :func:`scan_plant` turns into points;
    the benchmark compares precisions beam by beam); ``finder`` as :func:`scan_points`."""
    out = []
    for k, grid in enumerate(beam_grids(target, settings)):
        sub, t, prim = _candidates(target, grid, settings, seed, k, max_pairs, finder=finder)
        beam, t, prim = _beam_returns(sub, t, prim, settings.sub_rays, settings.beam_return)
        out.append(BeamReturns(k, beam, t, prim, grid.count))
    return out


#: Beams a scanner samples (at random, a fixed seed) to estimate how many of its beams
#: return, before a scan starts (:func:`expected_points`).
RETURN_SAMPLE = 4096


def expected_points(target, grids, sample: int = RETURN_SAMPLE) -> float:
    """About how many points the scanners' beam ``grids`` return from ``target``: each
    grid's beam count times the share of ``sample`` of its beams (drawn at random, seed 0)
    that hit, traced by the float64 reference (with 4,096, a 3-sigma error of about 2 % of
    the beams; the scan's budget also counts the points as they come)."""
    rng = np.random.default_rng(0)
    out = 0.0
    for grid in grids:
        if grid.count <= 0:
            continue
        beam = np.unique(rng.integers(0, grid.count, min(grid.count, max(sample, 1)), dtype=np.int64))
        origins, dirs = grid.rays(grid.a0 + beam // grid.nb, grid.b0 + beam % grid.nb)
        t, _ = target.first_hits(origins, dirs, origin=grid.origin)
        out += grid.count * float(np.isfinite(t).mean())
    return out


#: Points labelled and placed at a time by :func:`_scan_one` (its temporaries' bound).
LABEL_CHUNK = 1 << 20


def _scan_one(target: ScanTarget, grid, settings: ScanSettings, seed: int, scanner: int, max_pairs: int,
              progress=None, finder=None, hold=None) -> dict:
    """One scanner's points as :class:`PointCloud`'s columns (its compact dtypes), labelled
    and placed :data:`LABEL_CHUNK` points at a time, so that no int64 or float64
    temporary of every point is made beside them."""
    sub, t, prim = _candidates(target, grid, settings, seed, scanner, max_pairs, progress, finder, hold)
    beam, t, prim = _beam_returns(sub, t, prim, settings.sub_rays, settings.beam_return)
    del sub
    if settings.range_noise > 0:
        t = t + settings.range_noise * normal_noise(seed, scanner, beam)
    n = len(beam)
    out = {"xyz": np.empty((n, 3)), **{name: np.empty(n, dtype) for name, dtype in LABELS.items()}}
    out["scanner"][:] = scanner
    for a in range(0, n, LABEL_CHUNK):
        part = slice(a, min(a + LABEL_CHUNK, n))
        b = beam[part]
        origins, dirs = grid.rays(grid.a0 + b // grid.nb, grid.b0 + b % grid.nb)
        out["xyz"][part] = origins + t[part, None] * dirs
        for name, values in target.primitive_labels(prim[part]).items():
            out[name][part] = values
    return out


def _metadata(settings: ScanSettings, seed: int) -> dict:
    from dataclasses import asdict

    meta = {k: (list(map(list, v)) if k == "positions" and v is not None else v) for k, v in asdict(settings).items()}
    return {"generator": "plantgen scan", "seed": int(seed), **meta}


def scan_plant(skeleton: Skeleton, leaves: Polygons | None = None, settings: ScanSettings | None = None,
               seed: int = 0, *, frusta: Frusta | None = None, plant=0, leaf_plant=None,
               topology: Branches | None = None, limits: Limits | None = None,
               max_pairs: int = 1 << 20, progress=None, finder=None) -> PointCloud:
    """A simulated laser scan of a plant (see the module docstring): ``skeleton`` (skinned
    here unless its ``frusta`` are given) and its ``leaves`` (or None), scanned as
    ``settings`` say, noise and beam turns drawn from ``seed``. ``plant`` labels the points
    (one number, or (n,) per segment: a scene's instances; ``leaf_plant`` (p,) per leaf).
    The beams fired (times the sub-rays of a diverging beam) are counted against the limit
    ``scan_rays`` before anything is cast; ``progress`` and ``finder`` as
    :func:`scan_points` takes them."""
    settings = settings or ScanSettings()
    target = scan_target(skeleton, leaves, frusta=frusta, plant=plant, leaf_plant=leaf_plant, topology=topology)
    return scan_points(target, settings, seed, limits=limits, max_pairs=max_pairs, progress=progress, finder=finder)


def scan_points(target, settings: ScanSettings, seed: int = 0, *, limits: Limits | None = None,
                max_pairs: int = 1 << 20, progress=None, finder=None) -> PointCloud:
    """The :class:`PointCloud` of a scan of ``target`` (a :class:`ScanTarget` or a
    :class:`SceneTarget`): what :func:`scan_plant` and :func:`scan_scene` return.
    ``progress("scan", beams done, beams)`` is called after each chunk of beams.
    ``finder``: with ``settings.precision`` float32, ``finder(target, origins, dirs) ->
    (t, primitive)`` finds each beam's primitive (the GPU's search,
    :func:`plantgen.gl.trace.trace_target`; this module draws nothing) and each range is
    solved again in float64 against it, so ranges are the reference's."""
    if not len(target):
        return PointCloud.empty(metadata=_metadata(settings, seed))
    grids = beam_grids(target, settings, limits)
    total = sum(g.count for g in grids)
    (limits or default_limits).check("scan_rays", total * settings.sub_rays, f"a scan of {len(grids)} scanners")
    most = (limits or default_limits).max_scan_bytes
    expected = expected_points(target, grids, min(RETURN_SAMPLE, max_pairs, SCAN_CHUNK_RAYS))
    if expected * POINT_BYTES > most:
        raise LimitError(f"a scan of {len(grids)} scanners: its {total:,} beams would return about {expected:,.0f} "
                         f"points (from a sample of its beams), about {expected * POINT_BYTES / 2**20:,.0f} MiB, over "
                         f"the limit of {most / 2**20:,.0f} MiB ({hint('scan_bytes')}; or a coarser --angular-step)")
    done, held = [0], [0]

    def step(beams: int) -> None:
        done[0] += beams
        if progress is not None:
            progress("scan", done[0], total)

    def hold(hits: int) -> None:         # the points kept so far, against the budget, as they come
        held[0] += hits
        if held[0] * POINT_BYTES > most:
            raise LimitError(f"a scan of {len(grids)} scanners: its first {done[0] + 1:,} of {total:,} beams "
                             f"already returned {held[0]:,} points, about {held[0] * POINT_BYTES / 2**20:,.0f} MiB, "
                             f"over the limit of {most / 2**20:,.0f} MiB ({hint('scan_bytes')}; or a coarser "
                             "--angular-step)")

    parts = [_scan_one(target, g, settings, seed, k, max_pairs, step, finder, hold) for k, g in enumerate(grids)]
    merged = {}
    for name in ("xyz", *LABELS):        # joined column by column, each scanner's freed as it goes
        merged[name] = parts[0][name] if len(parts) == 1 else np.concatenate([p[name] for p in parts])
        for p in parts:
            del p[name]
    return PointCloud(**merged, scanners=np.array([g.origin for g in grids]).reshape(-1, 3),
                      metadata=_metadata(settings, seed))


def scan_scene(plants, settings: ScanSettings | None = None, seed: int = 0, *, skin=None,
               limits: Limits | None = None, max_pairs: int = 1 << 20, progress=None, finder=None) -> PointCloud:
    """A simulated laser scan of an instanced scene (its distinct ``plants``, as
    :func:`scene_target` takes them), each plant skinned once and its copies traced
    through a two-level BVH: the same points, labels numbered as for the merged scene,
    as :func:`scan_plant` of the merged skeleton gives (ranges to rounding), in the
    memory of the distinct plants."""
    settings = settings or ScanSettings()
    return scan_points(scene_target(plants, skin=skin), settings, seed, limits=limits, max_pairs=max_pairs,
                       progress=progress, finder=finder)
