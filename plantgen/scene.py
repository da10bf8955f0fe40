"""Scene files: instances of grammars or explicit skeletons, with ground, camera, light,
effects and motion. This module loads, validates and grows them; renderers read the result.

A scene is a YAML mapping with an ``instances`` list::

    name: desert
    description: saguaros and aloes on sand
    seed: 7
    effects: [relief, shadows]            # any of EFFECTS
    ground: {size: 60, height: 0, material: sand}
    camera: auto                          # or {eye, target, up, fov_y}
    light: {direction: [-0.4, -1, -0.3]}  # direction the light travels
    instances:
      - grammar: saguaro                  # shipped name, or a path relative to this file
        seed: 3                           # default: scene seed + instance number
        position: [0, 0, 0]
        rotation: [0, 30, 0]              # degrees about x, then y, then z
        scale: 1.0
        iterations: 4                     # optional override
        grid: {count: [10, 10], spacing: [3, 3], jitter: 0.4}   # optional: many copies
        motion: {sway: {amplitude: 8, frequency: 0.5}}          # optional (animation)
      - skeleton:                         # explicit segments (no L-system)
          materials: [stone]
          segments:
            - {start: [0, 0, 0], end: [0, 1, 0], r_start: 1, r_end: 1}
            - {start: [0, 1, 0], end: [0, 2, 0], r_start: 1, r_end: 0.5, parent: 0, continues: true}

Copies made by ``grid`` get seeds ``seed + k`` and, if ``jitter`` is set, positions
jittered and yaw turned from a generator seeded by the instance seed: deterministic.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._resources import grammars_dir
from .errors import PlantgenError
from .geometry.skeleton import Skeleton, SkeletonError

__all__ = ["EFFECTS", "Scene", "SceneInstance", "SceneError", "load_scene", "parse_scene",
           "is_scene", "rotation_matrix"]

EFFECTS = ("relief", "shadows", "animation")
SCENE_KEYS = {"name", "description", "seed", "effects", "ground", "camera", "light", "instances"}
INSTANCE_KEYS = {"grammar", "skeleton", "seed", "position", "rotation", "scale", "iterations",
                 "grid", "motion"}
GROUND_KEYS = {"size", "height", "material"}
LIGHT_KEYS = {"direction", "intensity"}
MOTION_KEYS = {"sway"}
SWAY_KEYS = {"amplitude", "frequency", "phase"}
SEGMENT_KEYS = {"start", "end", "r_start", "r_end", "parent", "continues", "material"}


class SceneError(PlantgenError):
    """A scene file that cannot be used."""


@dataclass(frozen=True)
class SceneInstance:
    """One placed plant. ``skeleton`` is in the plant's own frame; ``matrix`` places it."""

    source: str
    seed: int
    matrix: np.ndarray            # (4, 4) similarity transform
    skeleton: Skeleton            # local coordinates
    motion: dict | None = None    # e.g. {"sway": {"amplitude": deg, "frequency": Hz, "phase": rad}}


@dataclass(frozen=True)
class Scene:
    name: str
    description: str
    effects: tuple[str, ...]
    instances: tuple[SceneInstance, ...]
    ground: dict | None = None
    camera: dict | str = "auto"
    light: dict = field(default_factory=lambda: {"direction": [-0.4, -1.0, -0.3], "intensity": 1.0})
    path: str = "<scene>"

    def skeleton(self) -> Skeleton:
        """All instances in world coordinates, as one skeleton."""
        return Skeleton.concatenate([i.skeleton.transformed(i.matrix) for i in self.instances])

    def segment_instance(self) -> np.ndarray:
        """(n,) int: the instance each segment of :meth:`skeleton` belongs to."""
        return np.repeat(np.arange(len(self.instances)), [len(i.skeleton) for i in self.instances])


def rotation_matrix(degrees_xyz) -> np.ndarray:
    """(3, 3) rotation: about x, then y, then z, by the given angles in degrees."""
    ax, ay, az = np.radians(np.asarray(degrees_xyz, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _vec3(value, what, where):
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value)):
        raise SceneError(f"{where}: {what} must be three numbers, got {value!r}")
    out = np.array(value, dtype=np.float64)
    if not np.all(np.isfinite(out)):
        raise SceneError(f"{where}: {what} must be finite")
    return out


def _num(value, what, where, positive=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise SceneError(f"{where}: {what} must be a number, got {value!r}")
    if positive and value <= 0:
        raise SceneError(f"{where}: {what} must be positive")
    return float(value)


def _check_keys(d, allowed, where):
    if not isinstance(d, dict):
        raise SceneError(f"{where}: must be a mapping")
    unknown = set(d) - allowed
    if unknown:
        raise SceneError(f"{where}: unknown key(s) {sorted(unknown)} (allowed: {sorted(allowed)})")


def _explicit_skeleton(d, where) -> Skeleton:
    _check_keys(d, {"materials", "segments"}, where)
    materials = d.get("materials", ["bark"])
    if not isinstance(materials, list) or not materials or not all(isinstance(m, str) for m in materials):
        raise SceneError(f"{where}: materials must be a non-empty list of names")
    segs = d.get("segments")
    if not isinstance(segs, list) or not segs:
        raise SceneError(f"{where}: segments must be a non-empty list")
    cols = {k: [] for k in ("start", "end", "r_start", "r_end", "parent", "continues", "material")}
    for i, s in enumerate(segs):
        w = f"{where}: segment {i}"
        _check_keys(s, SEGMENT_KEYS, w)
        for key in ("start", "end", "r_start", "r_end"):
            if key not in s:
                raise SceneError(f"{w}: missing {key}")
        cols["start"].append(_vec3(s["start"], "start", w))
        cols["end"].append(_vec3(s["end"], "end", w))
        cols["r_start"].append(_num(s["r_start"], "r_start", w))
        cols["r_end"].append(_num(s["r_end"], "r_end", w))
        parent = s.get("parent", -1)
        if isinstance(parent, bool) or not isinstance(parent, int):
            raise SceneError(f"{w}: parent must be an integer")
        cols["parent"].append(parent)
        cols["continues"].append(bool(s.get("continues", False)))
        mat = s.get("material", materials[0])
        if mat not in materials:
            raise SceneError(f"{w}: material {mat!r} not in {materials}")
        cols["material"].append(materials.index(mat))
    skel = Skeleton(**{k: np.array(v) for k, v in cols.items()}, material_names=tuple(materials))
    try:
        skel.validate(tol=1e-6)
    except SkeletonError as exc:
        raise SceneError(f"{where}: {exc}") from None
    return skel


def _resolve_grammar(name: str, base: Path, where: str) -> Path:
    cand = [base / name, base / f"{name}.yaml", grammars_dir() / name, grammars_dir() / f"{name}.yaml"]
    for c in cand:
        if c.is_file():
            return c
    raise SceneError(f"{where}: grammar {name!r} not found next to the scene or among the shipped grammars")


def is_scene(data) -> bool:
    return isinstance(data, dict) and "instances" in data


def parse_scene(data, path: str = "<scene>", *, seed: int | None = None, grow_grammar=None) -> Scene:
    """Validate a scene mapping and grow its instances.

    ``grow_grammar(path, seed, iterations) -> Skeleton`` grows one grammar (injected by
    the pipeline, which keeps this module free of L-system details).
    """
    _check_keys(data, SCENE_KEYS, path)
    if not isinstance(data.get("instances"), list) or not data["instances"]:
        raise SceneError(f"{path}: instances must be a non-empty list")
    base_seed = int(data.get("seed", 0)) if seed is None else int(seed)
    effects = data.get("effects", [])
    if not isinstance(effects, list) or not all(isinstance(e, str) for e in effects):
        raise SceneError(f"{path}: effects must be a list of names")
    bad = [e for e in effects if e not in EFFECTS]
    if bad:
        raise SceneError(f"{path}: unknown effect(s) {bad} (known: {list(EFFECTS)})")
    ground = data.get("ground")
    if ground is not None:
        _check_keys(ground, GROUND_KEYS, f"{path}: ground")
        ground = {"size": _num(ground.get("size", 10.0), "size", f"{path}: ground", positive=True),
                  "height": _num(ground.get("height", 0.0), "height", f"{path}: ground"),
                  "material": str(ground.get("material", "sand"))}
    camera = data.get("camera", "auto")
    if camera != "auto":
        from .geometry.camera import Camera, CameraError
        if not isinstance(camera, dict):
            raise SceneError(f"{path}: camera must be 'auto' or a mapping")
        try:
            Camera.from_dict(camera, f"{path}: camera")
        except CameraError as exc:
            raise SceneError(str(exc)) from None
    light = {"direction": [-0.4, -1.0, -0.3], "intensity": 1.0}
    if "light" in data:
        _check_keys(data["light"], LIGHT_KEYS, f"{path}: light")
        if "direction" in data["light"]:
            d = _vec3(data["light"]["direction"], "direction", f"{path}: light")
            if not np.linalg.norm(d):
                raise SceneError(f"{path}: light direction must not be zero")
            light["direction"] = (d / np.linalg.norm(d)).tolist()
        if "intensity" in data["light"]:
            light["intensity"] = _num(data["light"]["intensity"], "intensity", f"{path}: light")

    base = Path(path).parent
    instances: list[SceneInstance] = []
    cache: dict[tuple, Skeleton] = {}
    for k, inst in enumerate(data["instances"]):
        where = f"{path}: instance {k + 1}"
        _check_keys(inst, INSTANCE_KEYS, where)
        if ("grammar" in inst) == ("skeleton" in inst):
            raise SceneError(f"{where}: give exactly one of 'grammar' or 'skeleton'")
        inst_seed = inst.get("seed", base_seed + k)
        if isinstance(inst_seed, bool) or not isinstance(inst_seed, int) or inst_seed < 0:
            raise SceneError(f"{where}: seed must be a non-negative integer")
        if seed is not None and "seed" in inst:
            inst_seed = inst_seed + int(seed)   # an override seed shifts every instance
        position = _vec3(inst.get("position", [0, 0, 0]), "position", where)
        rotation = _vec3(inst.get("rotation", [0, 0, 0]), "rotation", where)
        scale = _num(inst.get("scale", 1.0), "scale", where, positive=True)
        iterations = inst.get("iterations")
        if iterations is not None and (isinstance(iterations, bool) or not isinstance(iterations, int)
                                       or iterations < 0):
            raise SceneError(f"{where}: iterations must be a non-negative integer")
        motion = inst.get("motion")
        if motion is not None:
            _check_keys(motion, MOTION_KEYS, f"{where}: motion")
            sway = motion.get("sway")
            if sway is not None:
                _check_keys(sway, SWAY_KEYS, f"{where}: motion: sway")
                motion = {"sway": {key: _num(v, key, f"{where}: motion: sway") for key, v in sway.items()}}

        copies = [(np.zeros(3), 0.0, 0)]
        if "grid" in inst:
            g = inst["grid"]
            _check_keys(g, {"count", "spacing", "jitter"}, f"{where}: grid")
            count = g.get("count", [1, 1])
            if (not isinstance(count, list) or len(count) != 2
                    or not all(isinstance(c, int) and not isinstance(c, bool) and c > 0 for c in count)):
                raise SceneError(f"{where}: grid count must be two positive integers")
            spacing = g.get("spacing", [1.0, 1.0])
            if not isinstance(spacing, list) or len(spacing) != 2:
                raise SceneError(f"{where}: grid spacing must be two numbers")
            sx, sz = (_num(s, "grid spacing", where, positive=True) for s in spacing)
            jitter = _num(g.get("jitter", 0.0), "grid jitter", where)
            rng = np.random.default_rng(inst_seed)
            nx, nz = count
            copies = []
            for iz in range(nz):
                for ix in range(nx):
                    off = np.array([(ix - (nx - 1) / 2) * sx, 0.0, (iz - (nz - 1) / 2) * sz])
                    if jitter:
                        off[[0, 2]] += rng.uniform(-jitter, jitter, 2) * np.array([sx, sz])
                    yaw = float(rng.uniform(0, 360)) if jitter else 0.0
                    copies.append((off, yaw, len(copies)))

        for off, yaw, c in copies:
            s = inst_seed + c
            if "grammar" in inst:
                gpath = _resolve_grammar(str(inst["grammar"]), base, where)
                key = (str(gpath), s, iterations)
                if key not in cache:
                    try:
                        cache[key] = grow_grammar(gpath, s, iterations)
                    except PlantgenError as exc:
                        raise SceneError(f"{where}: {exc}") from None
                skel = cache[key]
                source = str(inst["grammar"])
            else:
                skel = _explicit_skeleton(inst["skeleton"], f"{where}: skeleton")
                source = "skeleton"
            m = np.eye(4)
            m[:3, :3] = scale * rotation_matrix(rotation + np.array([0.0, yaw, 0.0]))
            m[:3, 3] = position + off
            inst_motion = None
            if motion:
                inst_motion = {"sway": dict(motion["sway"])}
                if "phase" not in inst_motion["sway"]:
                    inst_motion["sway"]["phase"] = float(np.random.default_rng(s).uniform(0, 2 * np.pi))
            instances.append(SceneInstance(source, s, m, skel, inst_motion))

    return Scene(str(data.get("name", Path(path).stem)), str(data.get("description", "")),
                 tuple(effects), tuple(instances), ground, camera, light, path)


def load_scene(path: str | Path, *, seed: int | None = None, grow_grammar=None) -> Scene:
    from .lsystem.grammar import read_yaml
    return parse_scene(read_yaml(path), str(path), seed=seed, grow_grammar=grow_grammar)
