"""Stage-by-stage scaling: each stage of ``grow``, ``render``, ``export`` and ``scan``, its
CPU time and peak memory at sizes ten times apart, and how it grows per 10x.

Run: ``python -m plantgen.benchmarks.pipeline [--quick | --full] [--gl] [--out FILE]``.

Inputs (every size from one generator, so the sizes differ in size only):

- *npz*: a skeleton synthesised with numpy (:func:`synthetic_skeleton`: chains of 20
  segments, each hanging from a random earlier segment), saved and read back;
- *grammar*: a ternary tree grammar (``X -> F[+X][-X][&X]``) whose iterations give
  about 10 k, 90 k and 800 k segments (:func:`tree_grammar`);
- *scene 1 seed* and *scene N seeds*: a grid of saguaros, its copies of one grown plant
  or each of its own seed (``grid: seeds``), written instanced.

Stages: *read* (load the npz, parse the grammar or scene), *derive* and *interpret* (the
L-system; a scene's copies grow in *derive*), *skin* (frusta; a scene's distinct plants),
*grow, 1 job* and *grow, all cores* (a distinct-seed scene grown again, untraced, one
plant at a time and in a pool of processes: wall seconds, the median of
:data:`GROW_REPEATS`), *frame* (the automatic camera: :func:`~plantgen.geometry.rays.camera.auto_camera`, or
:func:`~plantgen.geometry.rays.camera.frame_copies` for a scene), *check* (finite rows and
the export's budget), *upload/BVH* (the scan's BVH over the rows' boxes), *draw* (one
64x48 ray-cast frame, with ``--gl``), *mesh* (tessellate at m = 0 and bake the relief's
maps, as an export does by default) and *write* (the .glb writer, tangents included; the
table's notes give its MB/s: the file's bytes over the stage's CPU seconds).
grow runs read to interpret, render adds skin, frame, check and draw, export skin,
frame, check, mesh and write, scan skin and upload/BVH.

Times are CPU seconds of this process (``time.process_time``: steadier than wall time on
busy cores; a GL draw's driver threads count too), of runs with no allocation traced;
memory is the peak Python and numpy allocations of the stage over what was held before
it (``tracemalloc``), from one more run of the stage, traced (tracing slows work that makes
many Python objects, the more the more objects are alive: 1,024 distinct plants' skins
took 11-14 times 100's traced, 9.3 times untraced). *per 10x* is
the growth of the largest size's figure over the one before, scaled to a tenfold step
((t2/t1)^(1/log10(n2/n1))). A run that a limit refuses shows *refused* and how long the
refusal took. ``--quick`` (the tests') runs the two smallest sizes; the default adds the
middle ones; ``--full`` all, up to 1 M segments and 10,000 copies.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import platform
import statistics
import sys
import tempfile
import time
import tracemalloc
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..errors import PlantgenError
from ..exporters import Plant, write_plants
from ..exporters.textures import bake_textures
from ..geometry.meshes.mesh import tessellate
from ..geometry.rays.bvh import build_bvh
from ..geometry.rays.camera import auto_camera, frame_copies
from ..geometry.skeletons.frusta import row_end_balls
from ..geometry.skeletons.skeleton import Skeleton
from ..geometry.skeletons.skin import skin_skeleton
from ..limits import Limits
from ..pipeline import check_export_size, grow_file
from ..pipeline.checks import check_finite_frusta
from ..pipeline.growing import available_cores
from .arguments import report

__all__ = ["STAGES", "SIZES", "synthetic_skeleton", "tree_grammar", "measure", "markdown", "writer_speed", "main"]

#: The stages, in pipeline order; a distinct-seed scene's growth is also timed in wall
#: seconds one plant at a time and in a pool over every core (``--jobs``).
STAGES = ("read", "derive", "grow, 1 job", "grow, all cores", "interpret", "skin", "frame", "check", "upload/BVH",
          "draw", "mesh", "write")
#: How many times a distinct-seed scene is grown each way for the medians of its wall times.
GROW_REPEATS = 3
#: Sizes a run measures: segments (npz, grammar iterations) and copies (scenes), by run.
SIZES = {
    "quick": {"npz": (1_000, 10_000), "grammar": (6, 8), "scene": (10, 100)},
    "default": {"npz": (10_000, 100_000), "grammar": (9, 11), "scene": (100, 1_000)},
    "full": {"npz": (10_000, 100_000, 1_000_000), "grammar": (9, 11, 13), "scene": (100, 1_000, 10_000)},
}


#: The grammar runs' limits: the largest tree derives about 9.6 M modules (11 a segment),
#: over the default ``max_modules``.
GRAMMAR_LIMITS = Limits().raised(modules=20_000_000, derive_bytes=4 << 30, derive_work=200_000_000)


def synthetic_skeleton(n: int, seed: int = 0, chain: int = 20) -> Skeleton:
    """A branching skeleton of ``n`` segments (rounded down to whole chains of ``chain``):
    chain b starts at the end of a random segment of an earlier chain and runs straight,
    upward-leaning, in steps of 5 cm; radii taper with the distance from the root."""
    rng = np.random.default_rng(seed)
    m = max(n // chain, 1)
    n = m * chain
    hang = np.concatenate([[-1], (rng.random(m - 1) * (np.arange(1, m) * chain)).astype(np.int64)])
    direction = rng.normal(size=(m, 3))
    direction[:, 1] = np.abs(direction[:, 1]) + 1.0
    direction *= 0.05 / np.linalg.norm(direction, axis=1, keepdims=True)
    on = np.where(hang >= 0, hang // chain, 0)
    step = np.where(hang >= 0, hang % chain + 1, 0)
    root = np.zeros((m, 3))
    for _ in range(m):                       # a chain's root follows its parent chain's: settle by depth
        new = np.where((hang >= 0)[:, None], root[on] + direction[on] * step[:, None], 0.0)
        if np.array_equal(new, root):
            break
        root = new
    k = np.arange(chain + 1)
    points = root[:, None, :] + k[None, :, None] * direction[:, None, :]          # (m, chain + 1, 3)
    start, end = points[:, :-1].reshape(-1, 3), points[:, 1:].reshape(-1, 3)
    parent = np.arange(-1, n - 1, dtype=np.int64)
    parent[::chain] = hang
    continues = np.ones(n, bool)
    continues[::chain] = False
    radius = 0.02 / (1.0 + np.linalg.norm(start, axis=1))
    return Skeleton(start=start, end=end, r_start=radius, r_end=radius * 0.97, parent=parent, continues=continues,
                    material=np.zeros(n, np.int32), material_names=("bark",))


def tree_grammar(iterations: int) -> str:
    """A ternary tree grammar: ``(3^iterations - 1) / 2`` segments, deterministic."""
    return ("name: ternary_bench\nseed: 1\n"
            f"iterations: {int(iterations)}\naxiom: X\n"
            "turtle: {step: 0.1, angle: 30, radius: 0.01, width_factor: 0.9}\n"
            "rules:\n  - \"X -> F[+X][-X][&X]\"\n")


class Run:
    """One input at one size: each stage's (CPU seconds, peak bytes), or its refusal."""

    def __init__(self, kind: str, size: int, label: str, repeats: int = 1):
        self.kind, self.size, self.label, self.repeats = kind, size, label, repeats
        self.stages: dict[str, tuple[float, int]] = {}
        self.samples: dict[str, list[tuple[float, int]]] = {}
        self.refused: tuple[str, float, str] | None = None
        self.skipped: dict[str, str] = {}      # stage: the refusal that left it out
        self.walls: dict[str, list[float]] = {}   # stage: wall seconds of each repeat (no memory traced)
        self.written = 0                       # bytes of the .glb the write stage wrote

    @contextmanager
    def stage(self, name: str, traced: bool = False):
        """One run of stage ``name``: untraced, a sample of its CPU time; ``traced``, of its
        peak allocations (:func:`traced_peak`). ``stages[name]`` is the median CPU time of
        its untraced runs so far and the largest traced peak."""
        t0 = time.process_time()
        try:
            with traced_peak() if traced else contextlib.nullcontext([0]) as peak:
                yield
        except PlantgenError as exc:
            if not traced:
                self.refused = (name, time.process_time() - t0, str(exc).splitlines()[0])
            raise
        finally:
            samples = self.samples.setdefault(name, [])
            samples.append((None, peak[0]) if traced else (time.process_time() - t0, 0))
            self.note(name)

    def note(self, name: str) -> None:
        """``stages[name]`` from its samples: (median untraced CPU seconds, largest peak)."""
        samples = self.samples[name]
        times = [t for t, _ in samples if t is not None]
        self.stages[name] = (statistics.median(times) if times else 0.0, max(p for _, p in samples))

    def timed(self, name: str, work, repeats: int | None = None):
        """``work()`` run ``repeats`` times untraced (default :attr:`repeats`), each a
        sample of stage ``name``'s time, then once traced, its memory; the last result."""
        for _ in range(self.repeats if repeats is None else repeats):
            with self.stage(name):
                work()
        with self.stage(name, traced=True):
            return work()


@contextmanager
def traced_peak():
    """Trace allocations for the block: yields a one-item list that holds, after it, the
    peak of what was allocated during it (what was held before is not traced)."""
    peak = [0]
    tracemalloc.start()
    try:
        yield peak
    finally:
        peak[0] = max(tracemalloc.get_traced_memory()[1], 0)
        tracemalloc.stop()


def _plant_stages(run: Run, skeleton: Skeleton, grown, gl: bool) -> None:
    """The stages after growing of one plant: skin, frame, check, upload/BVH, draw, write."""
    frusta = run.timed("skin", lambda: skin_skeleton(skeleton))
    camera = run.timed("frame", lambda: auto_camera(frusta, 64, 48))

    def check():
        check_finite_frusta(frusta, run.label)
        try:
            check_export_size([frusta], [None], len(skeleton), 0, "glb", None, run.label, "bench.glb")
        except PlantgenError as exc:         # the write is refused: the check's time is the refusal's
            run.skipped["write"] = str(exc).splitlines()[0]
    run.timed("check", check)

    def bvh():
        (c_lo, r_lo), (c_hi, r_hi) = row_end_balls(frusta)
        build_bvh(np.minimum(c_lo - r_lo[:, None], c_hi - r_hi[:, None]),
                  np.maximum(c_lo + r_lo[:, None], c_hi + r_hi[:, None]))
    run.timed("upload/BVH", bvh)
    if gl:
        _draw(run, grown, frusta, camera)
    if "write" in run.skipped:
        run.skipped["mesh"] = run.skipped["write"]
        return
    _write(run, [(run.label, skeleton, frusta, None)])


def _write(run: Run, plants: list) -> None:
    """The export's last stages for ``plants`` [(name, skeleton, frusta, matrices)]: *mesh*
    (tessellate at m = 0 and bake the relief's maps, as ``plantgen export`` does by
    default) and *write* (the .glb writer: material split, up turn, tangents, packing, JSON
    and the file); ``run.written`` gets the file's bytes."""
    def mesh():
        meshes = [tessellate(frusta, 0) for _, _, frusta, _ in plants]
        return meshes, bake_textures(meshes)
    meshes, textures = run.timed("mesh", mesh)

    def write():
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "bench.glb"
            write_plants([Plant(name, skeleton, mesh, matrices) for (name, skeleton, _, matrices), mesh
                          in zip(plants, meshes, strict=True)], path, textures=textures)
            run.written = path.stat().st_size
    run.timed("write", write)


def _draw(run: Run, grown, frusta, camera) -> None:
    """One 64x48 ray-cast frame (headless GL)."""
    from ..gl.raycast import Raycaster
    from ..pipeline import frame_arguments, stage_model
    view = frame_arguments(frusta, stage_model(grown, frusta, 64, 48, camera=camera), None)
    raycaster = Raycaster()
    run.timed("draw", lambda: raycaster.render(frusta, **view))


def _npz_run(n: int, tmp: Path, gl: bool, repeats: int = 1) -> Run:
    run = Run("npz", n, f"npz {n:,}", repeats)
    path = tmp / f"plant{n}.npz"
    synthetic_skeleton(n).save(path)
    grown = run.timed("read", lambda: grow_file(path))
    _plant_stages(run, grown.skeleton, grown, gl)
    return run


def _grammar_run(iterations: int, tmp: Path, gl: bool, repeats: int = 1) -> Run:
    path = tmp / f"tree{iterations}.yaml"
    path.write_text(tree_grammar(iterations))
    run = Run("grammar", (3 ** iterations - 1) // 2, f"grammar {iterations} steps", repeats)
    for k in range(repeats + 1):      # each grow a sample of read, derive and interpret; the last traced
        traced = k == repeats
        t0 = time.process_time()
        try:
            with traced_peak() if traced else contextlib.nullcontext([0]) as peak:
                grown = grow_file(path, limits=GRAMMAR_LIMITS)
        except PlantgenError as exc:
            run.refused = ("derive", time.process_time() - t0, str(exc).splitlines()[0])
            run.stages["derive"] = (time.process_time() - t0, 0)
            return run
        spent = time.process_time() - t0
        timed = {"read": grown.timings.get("parse", 0.0), "derive": grown.timings.get("derive", 0.0),
                 "interpret": grown.timings.get("interpret", 0.0)}
        scale = spent / max(sum(timed.values()), 1e-9)       # wall timings to this process's CPU
        for name, seconds in timed.items():         # one peak for the three: grown together
            run.samples.setdefault(name, []).append((None, peak[0]) if traced else (seconds * scale, 0))
            run.note(name)
    run.size = len(grown.skeleton)
    _plant_stages(run, grown.skeleton, grown, gl)
    return run


def _scene_run(copies: int, distinct: bool, tmp: Path, repeats: int = 1) -> Run:
    side = max(int(round(math.sqrt(copies))), 1)
    run = Run("scene N seeds" if distinct else "scene 1 seed", side * side, "", repeats)
    run.label = f"{run.kind} {run.size:,}"
    path = tmp / f"grid{copies}{distinct}.yaml"
    seeds = "" if distinct else ", seeds: 1"
    path.write_text(f"name: grid\ninstances:\n  - {{grammar: saguaro, seed: 1, "
                    f"grid: {{count: [{side}, {side}], spacing: [4, 4], jitter: 0.3{seeds}}}}}\n")
    try:
        grown = run.timed("derive", lambda: grow_file(path, jobs=1), repeats=1)   # once, in this process
        plants = grown.scene.plants()
        skinned = run.timed("skin", lambda: [(skin_skeleton(p.skeleton), p.matrices, None) for p in plants])
        run.timed("frame", lambda: frame_copies(skinned, 64, 48))
        run.timed("check", lambda: check_export_size([f for f, _, _ in skinned], [None] * len(skinned),
                                                     sum(len(p.skeleton) for p in plants), 0, "glb", None,
                                                     run.label, "bench.glb"))
        _write(run, [(p.name, p.skeleton, f, m) for p, (f, m, _) in zip(plants, skinned, strict=True)])
    except PlantgenError:
        return run
    if distinct:
        _grow_walls(run, path)
    return run


def _grow_walls(run: Run, path: Path) -> None:
    """The scene grown one plant at a time and in a pool over every core this process may
    use, alternately, :data:`GROW_REPEATS` times each, untraced: wall seconds (the pool's
    work is its processes' CPU time, which this process's clock does not see)."""
    for _ in range(GROW_REPEATS):
        for stage, jobs in (("grow, 1 job", 1), ("grow, all cores", available_cores())):
            before, t0 = os.times(), time.perf_counter()
            grow_file(path, jobs=jobs)
            wall, after = time.perf_counter() - t0, os.times()
            cpu = sum(after[:4]) - sum(before[:4])        # this process's and its pool's, user and system
            run.walls.setdefault(stage, []).append(wall)
            run.walls.setdefault(f"{stage} cpu", []).append(cpu)
    for stage in ("grow, 1 job", "grow, all cores"):
        run.stages[stage] = (statistics.median(run.walls[stage]), -1)


def measure(sizes: dict, gl: bool = False, kinds=("npz", "grammar", "scene"), repeats: int = 1) -> list[Run]:
    """Every run of ``sizes`` (one of :data:`SIZES`), smallest first; each stage timed
    ``repeats`` times (the median; a scene's growth once)."""
    with tempfile.TemporaryDirectory() as tmp:
        runs = [_npz_run(n, Path(tmp), gl, repeats) for n in (sizes["npz"] if "npz" in kinds else ())]
        runs += [_grammar_run(its, Path(tmp), gl, repeats)
                 for its in (sizes["grammar"] if "grammar" in kinds else ())]
        runs += [_scene_run(copies, distinct, Path(tmp), repeats) for distinct in (False, True)
                 for copies in (sizes["scene"] if "scene" in kinds else ())]
    return runs


def _cell(run: Run, stage: str) -> str:
    if run.refused is not None and run.refused[0] == stage:
        return f"refused in {run.refused[1]:.2f} s"
    if stage in run.skipped:
        return "refused at check"
    if stage not in run.stages:
        return ""
    seconds, peak = run.stages[stage]
    if peak < 0:                             # a wall time, its memory not traced
        return f"{seconds:.3f} s wall"
    return f"{seconds:.3f} s, {peak / 2**20:,.1f} MiB"


def growth(runs: list[Run], stage: str) -> str:
    """The growth per 10x of ``stage`` between the two largest sizes that ran it."""
    done = [r for r in runs if stage in r.stages and (r.refused is None or r.refused[0] != stage)]
    if len(done) < 2:
        return ""
    (a, b) = done[-2:]
    ta, tb = a.stages[stage][0], b.stages[stage][0]
    if b.size <= a.size or ta < 0.005:
        return ""
    return f"{(tb / ta) ** (1 / math.log10(b.size / a.size)):.1f}x"


def markdown(runs: list[Run], title: str) -> str:
    """The table: a row per input kind and stage, a column per size, the growth per 10x."""
    kinds = list(dict.fromkeys(r.kind for r in runs))
    width = max(sum(1 for r in runs if r.kind == k) for k in kinds)
    lines = [f"### {title}", "",
             "| input | stage | " + " | ".join(f"size {i + 1}" for i in range(width)) + " | per 10x |",
             "|---|---|" + "---|" * width + "---|"]
    for kind in kinds:
        mine = [r for r in runs if r.kind == kind]
        lines.append(f"| **{kind}** | *size* | " + " | ".join(f"{r.size:,}" for r in mine)
                     + " |" * (width - len(mine)) + " |  |")
        for stage in STAGES:
            if not any(stage in r.stages or stage in r.skipped for r in mine):
                continue
            cells = [_cell(r, stage) for r in mine] + [""] * (width - len(mine))
            lines.append(f"| {kind} | {stage} | " + " | ".join(cells) + f" | {growth(mine, stage)} |")
    pools = [r for r in runs if "grow, all cores" in r.stages]
    if pools:
        lines += ["", f"Growth of the distinct-seed scenes, one plant at a time against a pool over "
                      f"{available_cores()} cores (wall seconds, median of {GROW_REPEATS}, alternated; then the CPU "
                      f"seconds of this process and its pool's processes):", ""]
        lines += [f"- {r.label}: {r.stages['grow, 1 job'][0]:.2f} s and {r.stages['grow, all cores'][0]:.2f} s, "
                  f"{r.stages['grow, 1 job'][0] / max(r.stages['grow, all cores'][0], 1e-9):.2f} times as fast; "
                  f"CPU of every process {statistics.median(r.walls['grow, 1 job cpu']):.2f} s and "
                  f"{statistics.median(r.walls['grow, all cores cpu']):.2f} s" for r in pools]
    writes = [f"- {r.label}: {r.written / 1e6:,.1f} MB in {r.stages['write'][0]:.3f} s, "
              f"{writer_speed(r):,.0f} MB/s" for r in runs if r.written and r.stages["write"][0] > 0]
    if writes:
        lines += ["", "The glb writer (the file's bytes over the write stage's CPU seconds; 1 MB = 10^6 bytes):",
                  "", *writes]
    refusals = [f"- {r.label}: {r.refused[2]}" for r in runs if r.refused is not None]
    refusals += [f"- {r.label}, {stage}: {why}" for r in runs for stage, why in r.skipped.items() if stage != "mesh"]
    if refusals:
        lines += ["", "Refused:", "", *refusals]
    return "\n".join(lines) + "\n"


def writer_speed(run: Run) -> float:
    """The glb writer's MB/s in ``run``: the file's bytes (10^6 a MB) over the CPU seconds
    of its write stage (the material split, up turn, tangents, packing, JSON and file,
    after the mesh and its maps are built)."""
    return run.written / 1e6 / run.stages["write"][0]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--quick", action="store_true", help="the two smallest sizes (the tests')")
    group.add_argument("--full", action="store_true", help="every size: 1 M segments, 10,000 copies")
    parser.add_argument("--gl", action="store_true", help="time a 64x48 ray-cast draw (headless GL)")
    parser.add_argument("--kinds", default="npz,grammar,scene", help="comma-separated inputs to run")
    parser.add_argument("--out", type=Path, help="also write the Markdown table here")
    parser.add_argument("--repeats", type=int, default=None,
                        help="times each stage runs, the median quoted (default: 3 with --full, else 1)")
    args = parser.parse_args(argv)
    run = "quick" if args.quick else "full" if args.full else "default"
    repeats = max(1, args.repeats if args.repeats is not None else 3 if args.full else 1)
    runs = measure(SIZES[run], args.gl, tuple(args.kinds.split(",")), repeats)
    title = (f"Stage scaling ({run} run; {platform.machine()}, {os.cpu_count()} cores; CPU seconds, the median of "
             f"{repeats} runs, and peak allocations a stage)")
    return report(markdown(runs, title), args.out)


if __name__ == "__main__":
    sys.exit(main())
