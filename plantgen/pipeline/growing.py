"""``plantgen grow`` and what every other command starts with: an input (a grammar, a
scene, a skeleton ``.npz`` / ``.swc``, or a shipped name) read and grown into a
:class:`GrowResult`, with the time of each stage.

:func:`grow_file` grows a grammar (derive, interpret, draw), a scene (each grammar it
places read and parsed once, each plant grown, ``grow: together`` plants derived in
lockstep) or loads a skeleton; :func:`grow` and :func:`load_skeleton` keep its skeleton.
One input's derivations share one ``derive_work`` meter.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from .._resources import grammars_dir, missing_hint, short_names
from ..environment import environment_for
from ..environment.together import TogetherPlant, grow_together
from ..errors import PlantgenError
from ..geometry.meshes.polygons import Polygons
from ..geometry.skeletons.skeleton import Skeleton
from ..geometry.skeletons.swc import read_swc
from ..limits import Limits, Meter
from ..lsystem.derive import apply_interpretation, derive
from ..lsystem.grammar import GrammarError, parse_grammar
from ..lsystem.lpy import read_grammar_data
from ..lsystem.turtle import Drawing, interpret_plant
from ..scene import Scene, grows_together, is_scene, parse_scene, resolve_grammar
from .checks import in_force

#: Skeleton files by suffix; anything else is read as YAML (a grammar or a scene).
SKELETON_SUFFIXES = (".npz", ".swc")

#: The least derive work (``max_derive_work``'s units) a scene's distinct plants must be
#: forecast to cost, from its probe plants, before they are grown in a pool of processes:
#: below it, one by one costs less than starting the pool and sending the plants back
#: (forked processes start in about 15 ms). A saguaro spends 13,656 units and grows,
#: drawn, in about 3 ms on a quiet 2-core machine: 300,000 is 22 saguaros, about 70 ms.
PARALLEL_WORK = 300_000


def available_cores() -> int:
    """The CPU cores this process may run on (its affinity where the system says)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except (AttributeError, OSError):          # no affinity on this system (macOS, Windows)
        return max(os.cpu_count() or 1, 1)


class _PlacedOnFirstUse:
    """:attr:`GrowResult.polygons`: a scene's (None given) are placed, every copy's leaves
    in the world, on first use, as its skeleton is (a scan of a forest, which traces the
    copies through two levels, never places its million leaves)."""

    def __get__(self, obj, owner=None):
        if obj is None:
            return None                      # the field's default
        value = obj.__dict__.get("_polygons")
        if value is None and obj.__dict__.get("scene") is not None:
            t0 = time.perf_counter()
            value = obj.__dict__["_polygons"] = obj.scene.polygons()
            obj.timings["place"] = obj.timings.get("place", 0.0) + time.perf_counter() - t0
        return value

    def __set__(self, obj, value) -> None:
        obj.__dict__["_polygons"] = value


@dataclass
class GrowResult:
    """A grown skeleton with what it took: module count and seconds per stage. A scene's
    merged skeleton and its leaves (every copy placed) are built on first use: an
    instanced render of a forest never builds the skeleton, its scan neither."""

    skeleton: Skeleton | None
    kind: str                        # "grammar", "scene" or "skeleton"
    name: str
    modules: int = 0
    timings: dict = field(default_factory=dict)   # stage -> seconds
    scene: Scene | None = None
    sources: tuple = ()              # every file read: the input, and a scene's grammars
    polygons: Polygons | None = _PlacedOnFirstUse()  # the filled polygons (leaves) of a grammar or a
                                      # scene, in place (a scene's placed on first use); None for a skeleton file
    warnings: tuple[str, ...] = ()   # one line each: what the turtle skipped (for stderr)
    smooth_bends: float | None = None  # a grammar's turtle: smooth_bends (degrees), the default
    iterations: int | None = None    # a grammar's derivation steps (its own, or as asked); None otherwise

    def __post_init__(self):
        if self.skeleton is None and self.scene is not None:
            del self.skeleton            # a scene's: placed on first use (__getattr__)

    def __getattr__(self, name):
        scene = self.__dict__.get("scene")
        if name != "skeleton" or scene is None:
            raise AttributeError(name)
        t0 = time.perf_counter()
        self.skeleton = scene.skeleton()
        self.timings["place"] = self.timings.get("place", 0.0) + time.perf_counter() - t0
        return self.skeleton

    @property
    def segments(self) -> int:
        """Segments placed (a scene's every copy), without building a scene's skeleton."""
        if "skeleton" not in self.__dict__ and self.scene is not None:
            return sum(len(i.skeleton) for i in self.scene.instances)
        return len(self.skeleton)


def _grow_grammar(grammar, path: str, seed, iterations, progress, timings, limits: Limits,
                  work) -> tuple[Drawing, int]:
    """Derive a parsed grammar, apply its interpretation rules and draw the result, adding
    each stage's seconds to ``timings``."""
    t1 = time.perf_counter()
    steps = grammar.iterations if iterations is None else int(iterations)
    ms = derive(grammar, iterations=iterations, seed=seed, limits=limits, work=work,
                progress=None if progress is None else lambda step, n: progress("derive", step, steps),
                environment=environment_for(grammar, seed=seed, limits=limits))
    t2 = time.perf_counter()
    if progress is not None:
        progress("interpret", 0, None)
    drawn = apply_interpretation(grammar, ms, seed, limits=limits, work=work)
    drawing = interpret_plant(drawn, grammar.turtle, grammar.materials, path, limits)
    t3 = time.perf_counter()
    for k, v in (("derive", t2 - t1), ("interpret", t3 - t2)):
        timings[k] = timings.get(k, 0.0) + v
    if ms.fixed_point is not None and iterations is not None:   # said once, where --iterations asked for more
        note = (f"{path}: note: the derivation reached a fixed point at step {ms.fixed_point} (steps past it "
                f"change nothing: --iterations {int(iterations)} draws the plant of --iterations {ms.fixed_point})")
        drawing = dataclasses.replace(drawing, warnings=(*drawing.warnings, note))
    return drawing, len(ms)


def resolve_input(path: str | Path) -> Path:
    """A path as given, or the name of a shipped grammar or scene (``pine``, ``desert``)."""
    p = Path(path)
    if not p.exists() and not p.suffix and p.name == str(path):
        shipped = grammars_dir() / f"{p.name}.yaml"
        if shipped.is_file():
            return shipped
    return p


def existing_input(path: str | Path) -> Path:
    """:func:`resolve_input`, refusing in one line a name that is neither a file nor a
    shipped grammar or scene, with the closest name (:func:`plantgen._resources.missing_hint`)."""
    resolved = resolve_input(path)
    if not os.path.lexists(resolved):
        raise PlantgenError(f"{path}: no such file{missing_hint(path)}")
    return resolved


def load_input(path: str | Path, limits: Limits | None = None, warnings: list | None = None):
    """Read an input: returns ("grammar" | "scene", parsed mapping), or ("skeleton", None)
    for a skeleton file (``.npz``, ``.swc``: see :func:`read_skeleton`). An L-Py file
    (``.lpy``) is translated to a grammar mapping; what its reading warns of is added to
    ``warnings``."""
    path = Path(path)
    if path.suffix.lower() in SKELETON_SUFFIXES:
        return "skeleton", None
    data, said = read_grammar_data(path, GrammarError, in_force(limits))
    if warnings is not None:
        warnings.extend(said)
    if data is None:
        raise PlantgenError(f"{path}: empty file, not a grammar or scene")
    if is_scene(data):
        return "scene", data
    if isinstance(data, dict) and "axiom" in data:
        return "grammar", data
    raise PlantgenError(f"{path}: not a grammar or scene (a grammar has 'axiom', a scene 'instances')")


def read_skeleton(path: str | Path, limits: Limits | None = None) -> Skeleton:
    """A skeleton file, ``.npz`` or ``.swc``, read and validated (one line naming the file
    for anything wrong with it)."""
    path = Path(path)
    if path.suffix.lower() == ".swc":
        return read_swc(path, in_force(limits))
    return Skeleton.load(path, in_force(limits))


def grow_file(path: str | Path, *, seed: int | None = None, iterations: int | None = None,
              max_modules: int | None = None, progress=None, limits: Limits | None = None,
              allow_paths=(), defines=None, jobs: int | None = None, variants=None) -> GrowResult:
    """Grow a grammar or scene, or load a skeleton ``.npz`` / ``.swc``; time every stage.

    ``max_modules`` sets the limit of that name (as ``--max-modules`` does); the grammars
    of a scene are read from its folder, the folders of ``allow_paths`` and the shipped ones.
    ``defines`` ({name: number}) overrides a grammar's defines of those names (as
    ``--define`` does; a name the grammar does not define is an error). ``variants``
    ({grammar file stem: {name: number}}) sets defines in every grammar of that stem
    this input grows, itself or a scene's (each grammar keeps the names it does not
    define): Table 1's paper variants, inside its scenes too. ``progress``:
    ``progress(stage, done, total)`` (stages ``derive``, ``interpret``, ``grow``,
    ``place``; ``total`` None where not known). A name that is neither a file nor a
    shipped grammar is one line with the closest shipped name; a shipped grammar's
    errors and warnings name it as commands take it (``pine``), not by its path.
    ``jobs``: the processes a scene's distinct plants may grow in (default: the cores
    this process may use, :func:`available_cores`; 1 grows them one by one). A scene
    whose plants are forecast to cost under :data:`PARALLEL_WORK` grows them one by one
    anyway; either way the plants are the same, array for array."""
    if jobs is not None and (isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1):
        raise PlantgenError(f"jobs must be a positive integer, got {jobs!r}")
    limits = in_force(limits).raised(modules=max_modules)
    if iterations is not None:
        limits.check("iterations", int(iterations), "--iterations")
    path = existing_input(path)
    try:
        result = _grow_path(path, seed, iterations, progress, limits, allow_paths, defines,
                            available_cores() if jobs is None else jobs, variants or {})
    except PlantgenError as exc:     # a shipped grammar is named as commands take it, not by its long path
        exc.args = (short_names(str(exc)), *exc.args[1:])
        raise
    result.warnings = tuple(short_names(w) for w in result.warnings)
    return result


def _grow_path(path: Path, seed, iterations, progress, limits: Limits, allow_paths, defines, jobs: int,
               variants: dict) -> GrowResult:
    """:func:`grow_file` of a path that exists."""
    said: list[str] = []
    kind, data = load_input(path, limits, said)
    if kind == "grammar":
        data = _variant(data, path, variants)
    timings: dict = {}
    if kind == "skeleton":
        t0 = time.perf_counter()
        skel = read_skeleton(path, limits)
        timings["load"] = time.perf_counter() - t0
        return GrowResult(skel, kind, path.stem, 0, timings, sources=(path,))
    work = limits.meter("derive_work")    # one budget for every derivation of this input
    if defines:
        data = _override_defines(data, kind, dict(defines), path)
    if kind == "grammar":
        t0 = time.perf_counter()
        grammar = parse_grammar(data, str(path), limits)
        timings["parse"] = time.perf_counter() - t0
        drawing, n = _grow_grammar(grammar, str(path), seed, iterations, progress, timings, limits, work)
        return GrowResult(drawing.skeleton, kind, grammar.name, n, timings, sources=(path,),
                          polygons=drawing.polygons, warnings=(*said, *drawing.warnings),
                          smooth_bends=grammar.turtle.smooth_bends,
                          iterations=grammar.iterations if iterations is None else int(iterations))

    modules, grown = [0], [0]
    warnings: list[str] = said
    grammars: dict[str, object] = {}   # each grammar file is read and parsed once per scene
    sources: dict[str, object] = {}    # and its mapping kept, for the processes that grow in parallel

    def parsed(gpath):
        key = str(gpath)
        t0 = time.perf_counter()
        if key not in grammars:
            data, said_here = read_grammar_data(gpath, GrammarError, limits)
            data = _variant(data, Path(gpath), variants)
            warnings.extend(w for w in said_here if w not in warnings)
            grammars[key] = parse_grammar(data, key, limits)
            sources[key] = data
        timings["parse"] = timings.get("parse", 0.0) + time.perf_counter() - t0
        return grammars[key]

    def took(drawing, n):
        modules[0] += n
        grown[0] += 1
        if progress is not None:
            progress("grow", grown[0], None)
        warnings.extend(w for w in drawing.warnings if w not in warnings)

    together = (_grow_together(data, path, seed, limits, work, allow_paths, parsed, timings)
                if grows_together(data, str(path)) else {})

    def grow_one(gpath, s, its):
        key = str(gpath)
        grammar = parsed(gpath)
        if (key, s, its) in together:       # grown with the others: drawn as it is
            ms = together[(key, s, its)]
            drawn = apply_interpretation(grammar, ms, s, limits=limits, work=work)
            drawing, n = interpret_plant(drawn, grammar.turtle, grammar.materials, key, limits), len(ms)
        else:
            drawing, n = _grow_grammar(grammar, key, s, its, None, timings, limits, work)
        took(drawing, n)
        return drawing             # the skeleton and its leaves: the scene's copies carry both

    def grow_many(requests, estimate):
        if together or jobs < 2 or estimate < PARALLEL_WORK or multiprocessing.current_process().daemon:
            return None            # one by one (grow_one); a daemon process (a pool's worker) may start none
        for gpath, _, _ in requests:
            parsed(gpath)
        return _grow_in_pool(requests, min(jobs, len(requests)), sources, limits, work, timings, took)

    scene = parse_scene(data, str(path), seed=seed, grow_grammar=grow_one, limits=limits,
                        allow_paths=allow_paths, work=work, grow_many=grow_many)
    return GrowResult(None, kind, scene.name, modules[0], timings, scene,     # placed on first use
                      sources=(path, *(Path(k) for k in grammars)), warnings=tuple(warnings))


#: A pool process's state: the scene's grammar mappings, the limits, and the grammars it parsed.
_WORKER: dict = {}


def _start_worker(sources: dict, limits: Limits) -> None:
    """A pool process's initializer: the grammars it may grow and the limits in force."""
    _WORKER.clear()
    _WORKER.update(sources=sources, limits=limits, grammars={})


def _grow_in_worker(request: tuple) -> tuple:
    """Grow one plant in a pool process: (drawing, modules, derive work spent, timings).
    ``request``: (grammar path, seed, iterations, derive work the scene had spent when
    the pool started): the plant may spend what was left."""
    key, seed, iterations, before = request
    grammars, limits = _WORKER["grammars"], _WORKER["limits"]
    if key not in grammars:
        grammars[key] = parse_grammar(_WORKER["sources"][key], key, limits)
    work, timings = limits.meter("derive_work"), {}
    work.spent = before
    drawing, n = _grow_grammar(grammars[key], key, seed, iterations, None, timings, limits, work)
    return drawing, n, work.spent - before, timings


def _pool_context():
    """Forked processes where the system has them (they start in milliseconds, with
    plantgen imported); else the platform's default."""
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("fork" if "fork" in methods else None)


def _grow_in_pool(requests, jobs: int, sources: dict, limits: Limits, work: Meter, timings: dict, took):
    """Grow ``requests`` [(grammar path, seed, iterations)] in a pool of ``jobs``
    processes; yields each drawing in the order asked, as it comes. Each process's
    plant may spend the derive work the scene has left; the scene's meter is charged
    with each plant's work as it comes, so the scene is refused at the plant where
    growing one by one would refuse it. ``took(drawing, modules)`` counts each (the
    progress line). The stage times are the pool's wall time, split as its processes spent it.
    Left before the last plant (a refusal, an error, an interrupt), the pool's processes
    are stopped at once: none grows on past the refusal, nor holds the command's exit."""
    tasks = [(str(g), s, its, work.spent) for g, s, its in requests]
    t0 = time.perf_counter()
    spent: dict = {}
    pool = ProcessPoolExecutor(jobs, mp_context=_pool_context(), initializer=_start_worker,
                               initargs=(sources, limits))
    came = 0
    try:
        chunk = max(1, min(16, len(tasks) // (jobs * 8)))
        for (drawing, n, used, times), (g, s, _) in zip(pool.map(_grow_in_worker, tasks, chunksize=chunk),
                                                         requests, strict=True):
            came += 1
            work.spend(used, f"{g}: seed {s}")
            for stage, seconds in times.items():
                spent[stage] = spent.get(stage, 0.0) + seconds
            took(drawing, n)
            yield drawing
    finally:
        _close_pool(pool, came == len(tasks))
        wall, total = time.perf_counter() - t0, sum(spent.values()) or 1.0
        for stage, seconds in spent.items():
            timings[stage] = timings.get(stage, 0.0) + wall * seconds / total


def _close_pool(pool: ProcessPoolExecutor, finished: bool) -> None:
    """Shut ``pool`` down: its processes are idle once every plant came back; else they are
    stopped where they stand (a refusal must not wait for the plants still growing)."""
    if finished:
        pool.shutdown(wait=True)
        return
    processes = list((getattr(pool, "_processes", None) or {}).values())   # the executor has no public stop
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(timeout=5)


def _grow_together(data, path, seed, limits: Limits, work, allow_paths, parsed, timings) -> dict:
    """A ``grow: together`` scene's plants derived in lockstep (:mod:`plantgen.environment.together`):
    {(grammar path, seed, iterations): derived string}. Where they stand comes from a first
    reading of the scene that grows nothing; copies that share a grammar, seed and
    iterations share one plant, grown where the first of them stands."""
    keys: list[tuple] = []

    def record(gpath, s, its):
        keys.append((str(gpath), s, its))
        return Skeleton.empty()

    t0 = time.perf_counter()
    placed = parse_scene(data, str(path), seed=seed, grow_grammar=record, limits=limits, allow_paths=allow_paths)
    where = Path(path).parent
    plants, grown, taken = [], [], set()
    resolved: dict[str, str] = {}             # a grammar's name: its path, resolved once, not once a copy
    by_seed: dict[tuple, list] = {}           # (grammar, seed): its keys in order (a lookup, not a scan a copy)
    for k in keys:
        by_seed.setdefault(k[:2], []).append(k)
    for inst in placed.instances:
        if inst.source == "skeleton":
            continue
        if inst.source not in resolved:
            resolved[inst.source] = str(resolve_grammar(inst.source, where, str(path), allow_paths))
        gpath = resolved[inst.source]
        key = next((k for k in by_seed.get((gpath, inst.seed), ()) if k not in taken), None)
        if key is not None:
            grown.append(key)
            taken.add(key)
            plants.append(TogetherPlant(parsed(gpath), key[1], key[2], inst.matrix))
    strings = grow_together(plants, limits=limits, work=work)
    timings["derive"] = timings.get("derive", 0.0) + time.perf_counter() - t0
    return dict(zip(grown, strings, strict=True))


def _variant(data, path: Path, variants: dict):
    """A grammar's mapping with the defines ``variants`` sets for its file's stem (the
    names it defines; the others left), else the mapping itself."""
    wanted = variants.get(path.stem)
    own = data.get("defines") if isinstance(data, dict) else None
    if not wanted or not isinstance(own, dict):
        return data
    return {**data, "defines": {**own, **{k: v for k, v in wanted.items() if k in own}}}


def _override_defines(data, kind: str, defines: dict, path) -> dict:
    """A grammar's mapping with ``defines`` replacing the values of its defines of those names."""
    if kind != "grammar":
        raise PlantgenError(f"{path}: defines can be set for a grammar, not a {kind}")
    own = data.get("defines")
    own = dict(own) if isinstance(own, dict) else {}
    unknown = sorted(set(defines) - set(own))
    if unknown:
        raise PlantgenError(f"{path}: the grammar has no define {', '.join(unknown)} "
                            f"(it defines: {', '.join(sorted(map(str, own))) or 'none'})")
    own.update(defines)
    return {**data, "defines": own}


def grow(path: str | Path, *, seed: int | None = None, iterations: int | None = None,
         max_modules: int | None = None, limits: Limits | None = None, allow_paths=()) -> Skeleton:
    """Grow a grammar or a scene file into a Skeleton (the twin of ``plantgen grow``)."""
    return grow_file(path, seed=seed, iterations=iterations, max_modules=max_modules, limits=limits,
                     allow_paths=allow_paths).skeleton


def load_skeleton(path: str | Path, *, seed: int | None = None, iterations: int | None = None,
                  limits: Limits | None = None, allow_paths=()) -> Skeleton:
    """Any input kind (grammar, scene, ``.npz``, ``.swc``) to a Skeleton."""
    return grow_file(path, seed=seed, iterations=iterations, limits=limits, allow_paths=allow_paths).skeleton
