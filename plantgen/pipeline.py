"""From an input file (grammar, scene or skeleton ``.npz``) to a skeleton: the stages glued.

``grow(path)`` is the library twin of ``plantgen grow``; renderers use
``load_skeleton(path)`` (any input kind) and ``load_scene_or_none(path)``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

from ._resources import grammars_dir
from .errors import PlantgenError
from .files import read_yaml
from .geometry.skeleton import Skeleton
from .lsystem.derive import derive
from .lsystem.grammar import GrammarError, parse_grammar
from .lsystem.turtle import interpret
from .scene import Scene, is_scene, parse_scene

__all__ = ["GrowResult", "grow", "grow_file", "load_skeleton", "load_input", "resolve_input"]


@dataclass
class GrowResult:
    """A grown skeleton with what it took: module count and seconds per stage."""

    skeleton: Skeleton
    kind: str                        # "grammar", "scene" or "skeleton"
    name: str
    modules: int = 0
    timings: dict = field(default_factory=dict)   # stage -> seconds
    scene: Scene | None = None


def _grow_grammar_data(data, path: str, seed, iterations, max_modules, progress, timings) -> tuple[Skeleton, int]:
    t0 = time.perf_counter()
    grammar = parse_grammar(data, path)
    t1 = time.perf_counter()
    ms = derive(grammar, iterations=iterations, seed=seed, max_modules=max_modules, progress=progress)
    t2 = time.perf_counter()
    skel = interpret(ms, grammar.turtle, grammar.materials, path)
    t3 = time.perf_counter()
    for k, v in (("parse", t1 - t0), ("derive", t2 - t1), ("interpret", t3 - t2)):
        timings[k] = timings.get(k, 0.0) + v
    return skel, len(ms)


def resolve_input(path: str | Path) -> Path:
    """A path as given, or the name of a shipped grammar or scene (``pine``, ``desert``)."""
    p = Path(path)
    if not p.exists() and not p.suffix and p.name == str(path):
        shipped = grammars_dir() / f"{p.name}.yaml"
        if shipped.is_file():
            return shipped
    return p


def load_input(path: str | Path):
    """Read a YAML input: returns ("grammar" | "scene", parsed mapping)."""
    path = Path(path)
    if path.suffix.lower() == ".npz":
        return "skeleton", None
    data = read_yaml(path, GrammarError)
    if data is None:
        raise PlantgenError(f"{path}: empty file, not a grammar or scene")
    if is_scene(data):
        return "scene", data
    if isinstance(data, dict) and "axiom" in data:
        return "grammar", data
    raise PlantgenError(f"{path}: not a grammar or scene (a grammar has 'axiom', a scene 'instances')")


def grow_file(path: str | Path, *, seed: int | None = None, iterations: int | None = None,
              max_modules: int | None = None, progress=None) -> GrowResult:
    """Grow a grammar or scene, or load a skeleton ``.npz``; time every stage."""
    path = resolve_input(path)
    kind, data = load_input(path)
    timings: dict = {}
    if kind == "skeleton":
        t0 = time.perf_counter()
        skel = Skeleton.load(path)
        timings["load"] = time.perf_counter() - t0
        return GrowResult(skel, kind, path.stem, 0, timings)
    if kind == "grammar":
        skel, n = _grow_grammar_data(data, str(path), seed, iterations, max_modules, progress, timings)
        return GrowResult(skel, kind, str(data.get("name", path.stem)), n, timings)

    modules = [0]
    grammars: dict[str, object] = {}   # each grammar file is read and parsed once per scene

    def grow_one(gpath, s, its):
        key = str(gpath)
        t0 = time.perf_counter()
        if key not in grammars:
            grammars[key] = parse_grammar(read_yaml(gpath, GrammarError), key)
        g = grammars[key]
        t1 = time.perf_counter()
        ms = derive(g, iterations=its, seed=s, max_modules=max_modules)
        t2 = time.perf_counter()
        skel = interpret(ms, g.turtle, g.materials, key)
        t3 = time.perf_counter()
        for k, v in (("parse", t1 - t0), ("derive", t2 - t1), ("interpret", t3 - t2)):
            timings[k] = timings.get(k, 0.0) + v
        modules[0] += len(ms)
        return skel

    scene = parse_scene(data, str(path), seed=seed, grow_grammar=grow_one)
    t0 = time.perf_counter()
    skel = scene.skeleton()
    timings["place"] = time.perf_counter() - t0
    return GrowResult(skel, kind, scene.name, modules[0], timings, scene)


def grow(path: str | Path, *, seed: int | None = None, iterations: int | None = None,
         max_modules: int | None = None) -> Skeleton:
    """Grow a grammar or a scene file into a Skeleton (the twin of ``plantgen grow``)."""
    return grow_file(path, seed=seed, iterations=iterations, max_modules=max_modules).skeleton


def load_skeleton(path: str | Path, *, seed: int | None = None, iterations: int | None = None) -> Skeleton:
    """Any input kind (grammar, scene, ``.npz``) to a Skeleton."""
    return grow_file(path, seed=seed, iterations=iterations).skeleton
