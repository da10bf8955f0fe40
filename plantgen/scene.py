"""Scene files: instances of grammars or explicit skeletons, with ground, camera, light,
effects and motion. This module loads, validates and grows them into a :class:`Scene` of
typed values (:class:`~plantgen.geometry.stage.Ground`, :class:`~plantgen.geometry.stage.Light`,
:class:`~plantgen.geometry.stage.Sway`, :class:`CameraSpec`); renderers read the result.
The effects vocabulary it reads (:data:`EFFECTS`, :func:`resolve_effects`) lives with the
other settings in :mod:`plantgen.settings`.

A scene is a YAML mapping with an ``instances`` list::

    name: desert
    description: saguaros and aloes on sand
    seed: 7
    effects: [relief, shadows]            # any of EFFECTS
    ground: {size: 60, height: 0, material: sand}
    camera: auto                          # or {eye, target, up, fov_y}
    light: {direction: [-0.4, -1, -0.3]}  # direction the light travels
    grow: apart                           # or together: all plants derived in lockstep in one
                                          # space, each environment seeing the others
    instances:
      - grammar: saguaro                  # shipped name, or a path inside this file's folder
        seed: 3                           # default: scene seed + instance number
        position: [0, 0, 0]
        rotation: [0, 30, 0]              # degrees about x, then y, then z
        scale: 1.0
        iterations: 4                     # optional override
        grid: {count: [10, 10], spacing: [3, 3], jitter: 0.4}   # optional: many copies
        # grid extras: seeds: 3 (copies cycle through 3 grown plants), scale_jitter: 0.2
        motion: {sway: {amplitude: 8, frequency: 0.5}}          # optional (animation)
      - skeleton:                         # explicit segments (no L-system)
          materials: [stone]
          segments:
            - {start: [0, 0, 0], end: [0, 1, 0], r_start: 1, r_end: 1}
            - {start: [0, 1, 0], end: [0, 2, 0], r_start: 1, r_end: 0.5, parent: 0, continues: true}

A grammar's copies carry its leaf polygons (its ``{ . }`` outlines) as well as its
skeleton: :meth:`Scene.polygons` places them all in world coordinates, and
:meth:`Scene.plants` gives each distinct plant its own, in its own frame.

Copies made by ``grid`` get seeds ``seed + k`` (with ``seeds: m``, ``seed + k mod m``: a
forest of m grown plants repeated) and, if ``jitter`` is set, positions jittered and yaw
turned, and with ``scale_jitter: j`` scales multiplied by a factor in [1 - j, 1 + j], from
a generator seeded by the instance seed: deterministic.

A scene is untrusted input: every value is typed and ranged (``plantgen.fields``), the
instances (grid copies included), the segments grown (each distinct plant once) and the
segments placed (every copy's) are counted against the limits in force, a placed copy
must stay finite and within ``tol.max_coordinate``, and a grammar path is read only
inside the scene's folder (or a folder the caller allows).
"""

from __future__ import annotations

import hashlib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import fields
from ._resources import grammars_dir, missing_hint
from .errors import PlantgenError
from .files import read_yaml, real_path
from .geometry.meshes.polygons import Polygons
from .geometry.rays.camera import Camera, CameraError, box_corners
from .geometry.skeletons.skeleton import Skeleton, SkeletonError
from .geometry.stage import SCENE_LIGHT, Ground, Light, Sway
from .limits import LimitError, Limits, hint
from .limits import limits as default_limits
from .lsystem.grammar import GrammarError
from .settings import EFFECTS, parse_effect_list, resolve_effects
from .tolerances import tol

__all__ = ["EFFECTS", "CameraSpec", "Scene", "SceneError", "SceneInstance", "ScenePlant", "is_scene",
           "load_scene", "parse_effect_list", "parse_scene", "resolve_effects", "resolve_grammar", "rotation_matrix"]

SCENE_KEYS = {"name", "description", "seed", "effects", "ground", "camera", "light", "instances", "grow"}
#: How a scene's plants grow: each on its own (``apart``, the default), or all in lockstep in
#: one shared space, each environment seeing the others (``together``).
GROW_MODES = ("apart", "together")
INSTANCE_KEYS = {"grammar", "skeleton", "seed", "position", "rotation", "scale", "iterations",
                 "grid", "motion"}
GROUND_KEYS = {"size", "height", "material"}
LIGHT_KEYS = {"direction", "intensity"}
MOTION_KEYS = {"sway"}
SWAY_KEYS = {"amplitude", "frequency", "phase"}
GRID_KEYS = {"count", "spacing", "jitter", "seeds", "scale_jitter"}
SKELETON_KEYS = {"materials", "segments"}
SEGMENT_KEYS = {"start", "end", "r_start", "r_end", "parent", "continues", "material"}


class SceneError(PlantgenError):
    """A scene file that cannot be used."""


# ---------------------------------------------------------------------------- effects
# ---------------------------------------------------------------------------- values
@dataclass(frozen=True)
class CameraSpec:
    """A scene's fixed camera: where it looks from and its vertical field of view. The
    image size is the render's, given by :meth:`at_size`."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov_y: float = 40.0           # degrees

    def at_size(self, width: int, height: int) -> Camera:
        """The :class:`Camera` for a ``width`` x ``height`` image."""
        return Camera(self.eye, self.target, self.up, self.fov_y, int(width), int(height))


@dataclass(frozen=True)
class SceneInstance:
    """One placed plant. ``skeleton`` and ``polygons`` (a grammar's leaves, their material
    indices into the skeleton's names) are in the plant's own frame; ``matrix`` places it."""

    source: str
    seed: int
    matrix: np.ndarray            # (4, 4) similarity transform
    skeleton: Skeleton            # local coordinates
    motion: Sway | None = None    # None: the plant stands still
    polygons: Polygons | None = None   # None: no leaves (an explicit skeleton)


@dataclass(frozen=True, eq=False)
class ScenePlant:
    """One distinct plant of a scene and where its copies stand: ``skeleton`` and
    ``polygons`` (its leaves, or None) in its own frame, ``matrices`` (k, 4, 4) the
    placements of its k copies, ``instances`` (k,) their numbers in :attr:`Scene.instances`."""

    name: str
    skeleton: Skeleton
    matrices: np.ndarray
    instances: np.ndarray
    polygons: Polygons | None = None


def _plant_key(skel: Skeleton, polygons: Polygons | None) -> bytes:
    """Equal for plants with equal skeleton arrays, material names and leaf polygons (a
    content digest): two copies with one skeleton but other leaves are two plants."""
    digest = hashlib.sha256()
    for name in ("start", "end", "r_start", "r_end", "parent", "continues", "material"):
        digest.update(getattr(skel, name).tobytes())
    digest.update("\0".join(skel.material_names).encode("utf-8"))
    if polygons is not None and len(polygons):
        digest.update(b"\0polygons")
        for name in ("vertices", "triangles", "polygon", "material", "normal", "segment"):
            array = getattr(polygons, name)
            digest.update(str(array.shape).encode("ascii"))
            digest.update(np.ascontiguousarray(array).tobytes())
    return digest.digest()


@dataclass(frozen=True)
class Scene:
    name: str
    description: str
    effects: tuple[str, ...]
    instances: tuple[SceneInstance, ...]
    ground: Ground | None = None
    camera: CameraSpec | None = None      # None: "auto", frame the model
    light: Light = SCENE_LIGHT
    path: str = "<scene>"

    def skeleton(self) -> Skeleton:
        """All instances in world coordinates, as one skeleton."""
        return Skeleton.concatenate([i.skeleton.transformed(i.matrix) for i in self.instances])

    def polygons(self) -> Polygons:
        """All instances' leaf polygons in world coordinates, as one :class:`Polygons`
        (instance by instance, in order): each placed by its copy's matrix, material
        indices into the names of :meth:`skeleton` (merged as its materials are), segment
        indices into :meth:`skeleton`'s segments."""
        names = Skeleton.merged_material_names([i.skeleton for i in self.instances])
        parts, offsets, first = [], [], 0
        for inst in self.instances:
            if inst.polygons is not None and len(inst.polygons):
                remap = [names.index(m) for m in inst.skeleton.material_names]
                parts.append(inst.polygons.with_materials(remap).transformed(inst.matrix))
                offsets.append(first)
            first += len(inst.skeleton)
        return Polygons.concatenate(parts, offsets)

    def plants(self) -> list[ScenePlant]:
        """The scene's distinct plants, each with the placements of all its copies: copies
        whose skeletons are equal (a grid of a deterministic grammar, an explicit skeleton
        placed many times, the same grammar and seed twice) are one plant. Named after
        their source (``saguaro``; ``saguaro-2``, ... where one source gives several)."""
        if "_plants" in self.__dict__:       # worked out once a scene (it is frozen)
            return list(self.__dict__["_plants"])
        groups: dict[bytes, list[int]] = {}
        keys: dict[tuple[int, int], bytes] = {}   # copies of one grown plant share its arrays: hashed once
        for k, inst in enumerate(self.instances):
            same = (id(inst.skeleton), id(inst.polygons))
            if same not in keys:
                keys[same] = _plant_key(inst.skeleton, inst.polygons)
            groups.setdefault(keys[same], []).append(k)
        sources = [Path(self.instances[ks[0]].source).stem or "plant" for ks in groups.values()]
        counts = Counter(sources)
        seen: dict[str, int] = {}
        out = []
        for ks, source in zip(groups.values(), sources, strict=True):
            seen[source] = seen.get(source, 0) + 1
            name = source if counts[source] == 1 else f"{source}-{seen[source]}"
            first = self.instances[ks[0]]
            out.append(ScenePlant(name, first.skeleton, np.stack([self.instances[k].matrix for k in ks]),
                                  np.array(ks), first.polygons))
        self.__dict__["_plants"] = tuple(out)
        return out

    def segment_instance(self) -> np.ndarray:
        """(n,) int: the instance each segment of :meth:`skeleton` belongs to."""
        return np.repeat(np.arange(len(self.instances)), [len(i.skeleton) for i in self.instances])

    def polygon_instance(self) -> np.ndarray:
        """(p,) int: the instance each polygon of :meth:`polygons` belongs to."""
        return np.repeat(np.arange(len(self.instances)),
                         [len(i.polygons) if i.polygons is not None else 0 for i in self.instances])


def rotation_matrix(degrees_xyz) -> np.ndarray:
    """(3, 3) rotation: about x, then y, then z, by the given angles in degrees."""
    ax, ay, az = np.radians(np.asarray(degrees_xyz, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


# ---------------------------------------------------------------------------- checks
# Every value is read through plantgen.fields (typed, finite, ranged); lengths and
# positions stay within tol.max_coordinate, so a placed model cannot overflow.
_MAX = tol.max_coordinate


def _vec3(value, what, where):
    return fields.vector(value, what, where, SceneError, max_abs=_MAX)


def _num(value, what, where, positive=False, lo=None):
    return fields.number(value, what, where, SceneError, positive=positive, lo=lo, max_abs=_MAX)


def _check_keys(d, allowed, where):
    fields.keys(d, allowed, where, SceneError)


# ---------------------------------------------------------------------------- scene header
def _parse_effects(effects, path: str) -> tuple[str, ...]:
    if not isinstance(effects, list) or not all(isinstance(e, str) for e in effects):
        raise SceneError(f"{path}: effects must be a list of names, got {fields.show(effects)}")
    bad = [e for e in effects if e not in EFFECTS]
    if bad:
        raise SceneError(f"{path}: unknown effect(s) {fields.show(bad)} (known: {list(EFFECTS)})")
    return tuple(effects)


def _parse_ground(ground, path: str) -> Ground | None:
    if ground is None:
        return None
    where = f"{path}: ground"
    _check_keys(ground, GROUND_KEYS, where)
    return Ground(size=_num(ground.get("size", 10.0), "size", where, positive=True),
                  height=_num(ground.get("height", 0.0), "height", where),
                  material=fields.text(ground.get("material", "sand"), "material", where, SceneError,
                                       max_len=100))


def _parse_camera(camera, path: str) -> CameraSpec | None:
    if camera == "auto":
        return None
    if not isinstance(camera, dict):
        raise SceneError(f"{path}: camera must be 'auto' or a mapping, got {fields.show(camera)}")
    try:   # the file may give a width and height: checked, though the render sets the size
        cam = Camera.from_dict(camera, f"{path}: camera")
    except CameraError as exc:
        raise SceneError(str(exc)) from None
    return CameraSpec(cam.eye, cam.target, cam.up, cam.fov_y)


def _parse_light(light, path: str) -> Light:
    """The scene's light: its direction of travel normalised; :data:`SCENE_LIGHT` (as given,
    not normalised) for what the file leaves out."""
    where = f"{path}: light"
    _check_keys(light, LIGHT_KEYS, where)
    travel, intensity = SCENE_LIGHT.travel, SCENE_LIGHT.intensity
    if "direction" in light:
        travel = fields.unit_vector(light["direction"], "direction", where, SceneError)
    if "intensity" in light:
        intensity = _num(light["intensity"], "intensity", where, lo=0.0)
    return Light(travel, intensity)


# ---------------------------------------------------------------------------- instances
@dataclass(frozen=True)
class _Placement:
    """One instance entry of the file, checked: what each of its copies shares."""

    where: str                    # "<path>: instance <k>", for messages
    seed: int
    position: np.ndarray          # (3,)
    rotation: np.ndarray          # (3,) degrees
    scale: float
    iterations: int | None
    sway: dict | None             # the file's sway values; a missing phase is drawn per copy
    copies: list                  # [(offset (3,), yaw degrees, seed offset, scale factor)]


@dataclass
class _Budget:
    """What a scene has placed so far, against ``max_instances``, ``max_segments`` (the
    segments grown: each distinct plant once) and ``max_drawn_segments`` (every copy's)."""

    limits: Limits
    instances: int = 0
    segments: int = 0
    drawn: int = 0

    def place(self, n: int, where: str) -> None:
        self.instances += n
        self.limits.check("instances", self.instances, f"{where}: instances placed")

    def add_segments(self, n: int, where: str) -> None:
        self.segments += n
        self.limits.check("segments", self.segments, f"{where}: segments grown for the scene")

    def add_drawn(self, n: int, where: str) -> None:
        self.drawn += n
        self.limits.check("drawn_segments", self.drawn, f"{where}: segments placed in the scene")


def _parse_placement(inst, k: int, path: str, base_seed: int, seed_override, budget: _Budget) -> _Placement:
    where = f"{path}: instance {k + 1}"
    _check_keys(inst, INSTANCE_KEYS, where)
    if ("grammar" in inst) == ("skeleton" in inst):
        raise SceneError(f"{where}: give exactly one of 'grammar' or 'skeleton'")
    inst_seed = fields.integer(inst.get("seed", base_seed + k), "seed", where, SceneError, hi=None)
    if seed_override is not None and "seed" in inst:
        inst_seed = inst_seed + int(seed_override)   # an override seed shifts every instance
    position = _vec3(inst.get("position", [0, 0, 0]), "position", where)
    rotation = fields.vector(inst.get("rotation", [0, 0, 0]), "rotation", where, SceneError, max_abs=1e6)
    scale = _num(inst.get("scale", 1.0), "scale", where, positive=True)
    iterations = inst.get("iterations")
    if iterations is not None:
        iterations = fields.integer(iterations, "iterations", where, SceneError, hi=None)
        budget.limits.check("iterations", iterations, f"{where}: iterations")
    sway = _parse_sway(inst.get("motion"), where)
    copies = (_grid_copies(inst["grid"], where, inst_seed, budget) if "grid" in inst
              else [(np.zeros(3), 0.0, 0, 1.0)])
    if "grid" not in inst:
        budget.place(1, where)
    return _Placement(where, inst_seed, position, rotation, scale, iterations, sway, copies)


def _parse_sway(motion, where: str) -> dict | None:
    """The sway values a ``motion`` entry gives, or None for a plant that stands still."""
    if motion is None:
        return None
    _check_keys(motion, MOTION_KEYS, f"{where}: motion")
    if "sway" not in motion:
        return None
    sway = motion["sway"]
    _check_keys(sway, SWAY_KEYS, f"{where}: motion: sway")
    return {key: fields.number(v, key, f"{where}: motion: sway", SceneError, max_abs=1e6)
            for key, v in sway.items()}


def _copy_sway(sway: dict | None, copy_seed: int) -> Sway | None:
    """A copy's sway; a phase the file does not give is drawn from the copy's seed."""
    if sway is None:
        return None
    phase = sway.get("phase")
    if phase is None:
        phase = float(np.random.default_rng(copy_seed).uniform(0, 2 * np.pi))
    return Sway(amplitude=sway.get("amplitude", 0.0), frequency=sway.get("frequency", 0.0),
                phase=phase)


def _grid_copies(grid, where: str, inst_seed: int, budget: _Budget) -> list:
    """The copies a ``grid`` entry asks for: [(offset (3,), yaw degrees, seed offset, scale
    factor)], row by row; jittered positions, yaws and scales come from a generator seeded
    by ``inst_seed``. Their number is counted against ``max_instances`` before any is made."""
    _check_keys(grid, GRID_KEYS, f"{where}: grid")
    count = grid.get("count", [1, 1])
    if not isinstance(count, list) or len(count) != 2:
        raise SceneError(f"{where}: grid count must be two positive integers, got {fields.show(count)}")
    nx, nz = (fields.integer(c, "grid count", where, SceneError, lo=1, hi=None) for c in count)
    budget.place(nx * nz, f"{where}: grid")
    spacing = grid.get("spacing", [1.0, 1.0])
    if not isinstance(spacing, list) or len(spacing) != 2:
        raise SceneError(f"{where}: grid spacing must be two numbers, got {fields.show(spacing)}")
    sx, sz = (_num(s, "grid spacing", where, positive=True) for s in spacing)
    jitter = _num(grid.get("jitter", 0.0), "grid jitter", where, lo=0.0)
    seeds = fields.integer(grid.get("seeds", nx * nz), "grid seeds", where, SceneError, lo=1, hi=None)
    scale_jitter = fields.number(grid.get("scale_jitter", 0.0), "grid scale_jitter", where, SceneError,
                                 lo=0.0, hi=0.9)
    rng = np.random.default_rng(inst_seed)
    copies = []
    for iz in range(nz):
        for ix in range(nx):
            off = np.array([(ix - (nx - 1) / 2) * sx, 0.0, (iz - (nz - 1) / 2) * sz])
            if jitter:
                off[[0, 2]] += rng.uniform(-jitter, jitter, 2) * np.array([sx, sz])
            yaw = float(rng.uniform(0, 360)) if jitter else 0.0
            factor = float(rng.uniform(1 - scale_jitter, 1 + scale_jitter)) if scale_jitter else 1.0
            copies.append((off, yaw, len(copies) % seeds, factor))
    return copies


def _explicit_segment(s, materials: list, cols: dict, w: str) -> None:
    _check_keys(s, SEGMENT_KEYS, w)
    for key in ("start", "end", "r_start", "r_end"):
        if key not in s:
            raise SceneError(f"{w}: missing {key}")
    cols["start"].append(_vec3(s["start"], "start", w))
    cols["end"].append(_vec3(s["end"], "end", w))
    cols["r_start"].append(_num(s["r_start"], "r_start", w, lo=0.0))
    cols["r_end"].append(_num(s["r_end"], "r_end", w, lo=0.0))
    cols["parent"].append(fields.integer(s.get("parent", -1), "parent", w, SceneError, lo=-1))
    continues = s.get("continues", False)
    if not isinstance(continues, bool):
        raise SceneError(f"{w}: continues must be true or false, got {fields.show(continues)}")
    cols["continues"].append(continues)
    mat = s.get("material", materials[0])
    if mat not in materials:
        raise SceneError(f"{w}: material {fields.show(mat)} not in {fields.show(materials)}")
    cols["material"].append(materials.index(mat))


def _explicit_skeleton(d, where, limits: Limits) -> Skeleton:
    _check_keys(d, SKELETON_KEYS, where)
    materials = d.get("materials", ["bark"])
    if not isinstance(materials, list) or not materials or not all(isinstance(m, str) for m in materials):
        raise SceneError(f"{where}: materials must be a non-empty list of names")
    segs = d.get("segments")
    if not isinstance(segs, list) or not segs:
        raise SceneError(f"{where}: segments must be a non-empty list")
    limits.check("segments", len(segs), f"{where}: segments")
    cols = {k: [] for k in ("start", "end", "r_start", "r_end", "parent", "continues", "material")}
    for i, s in enumerate(segs):
        _explicit_segment(s, materials, cols, f"{where}: segment {i}")
    skel = Skeleton(**{k: np.array(v) for k, v in cols.items()}, material_names=tuple(materials))
    try:
        skel.validate(tol=1e-6)
    except SkeletonError as exc:
        raise SceneError(f"{where}: {exc}") from None
    return skel


def resolve_grammar(name: str, base: Path, where: str, allow_paths=(), *, error: type[PlantgenError] = SceneError,
                    owner: str = "scene") -> Path:
    """The grammar file an instance (or a batch spec's entry: ``owner``, ``error``) names:
    a path inside the scene's folder (or a folder of ``allow_paths``), else a shipped
    grammar by plain name. A path that leaves the folder (``../x``, ``/etc/passwd``, a
    link pointing out) is refused before it is opened."""
    if not name or "\0" in name:
        raise error(f"{where}: grammar must name a file, got {fields.show(name)}")
    roots = [real_path(base), *(real_path(p) for p in allow_paths)]
    for cand in (base / name, base / f"{name}.yaml"):
        real = real_path(cand)       # a link loop stays a path that fails to open
        if not any(real.is_relative_to(root) for root in roots):
            raise error(f"{where}: grammar {fields.show(name)} lies outside the {owner}'s folder "
                             f"(only files under it are read; pass --allow-path DIR to allow DIR)")
        if real.is_file() or cand.is_symlink():    # a link loop: its read says so in one line
            return real
    if Path(name).name == name and name not in (".", ".."):   # a plain name: a shipped grammar
        for cand in (grammars_dir() / name, grammars_dir() / f"{name}.yaml"):
            if cand.is_file():
                return cand
    raise error(f"{where}: grammar {fields.show(name)} not found next to the {owner} or among the "
                f"shipped grammars{missing_hint(name, base)}")


def _placement_matrix(placement: _Placement, offset: np.ndarray, yaw: float, factor: float = 1.0) -> np.ndarray:
    """(4, 4) similarity transform of one copy: scale (times the copy's ``factor``),
    rotation (plus the copy's yaw about y), then the instance's position plus the copy's
    offset."""
    m = np.eye(4)
    m[:3, :3] = placement.scale * factor * rotation_matrix(placement.rotation + np.array([0.0, yaw, 0.0]))
    m[:3, 3] = placement.position + offset
    return m


def _local_extent(skel: Skeleton, polygons: Polygons | None) -> tuple[np.ndarray, float] | None:
    """A plant's box (its leaves' included) and largest radius in its own frame; None when
    it has neither segments nor leaves."""
    leaves = polygons is not None and len(polygons.vertices) > 0
    if not len(skel) and not leaves:
        return None
    with np.errstate(all="ignore"):
        boxes = [skel.bounds] if len(skel) else []
        if leaves:
            boxes.append(np.stack([polygons.vertices.min(axis=0), polygons.vertices.max(axis=0)]))
        box = np.stack([np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)])
        radius = max(float(skel.r_start.max()), float(skel.r_end.max())) if len(skel) else 0.0
    return box, radius


def _check_placed(skel: Skeleton, matrix: np.ndarray, where: str, polygons: Polygons | None = None,
                  extents: dict | None = None) -> None:
    """Refuse a copy whose placed coordinates (its leaves' too) or radii would not be
    finite or would lie beyond ``tol.max_coordinate`` (a huge position, scale or grid spacing).
    ``extents`` keeps each plant's box corners and radius (:func:`_local_extent`), so a copy
    of a plant seen before costs eight corners moved."""
    key = (id(skel), id(polygons))
    if extents is None or key not in extents:
        extent = _local_extent(skel, polygons)
        if extent is not None:
            extent = (box_corners(extent[0]), extent[1])
        if extents is not None:
            extents[key] = extent
    else:
        extent = extents[key]
    if extent is None:
        return
    corners, radius = extent
    with np.errstate(all="ignore"):
        corners = corners @ matrix[:3, :3].T + matrix[:3, 3]
        radius = radius * float(np.abs(matrix[:3, :3]).max())
        ok = bool(np.all(np.abs(corners) <= _MAX)) and radius <= _MAX
    if not ok:
        raise SceneError(f"{where}: placed, the plant reaches coordinates that are not finite or beyond "
                         f"{_MAX:g} (position, scale or grid spacing too large)")


def _grown_parts(grown) -> tuple[Skeleton, Polygons | None]:
    """What ``grow_grammar`` returned, as (skeleton, leaf polygons or None): a Skeleton, or
    a drawing with ``skeleton`` and ``polygons`` (:class:`plantgen.lsystem.turtle.Drawing`)."""
    if isinstance(grown, Skeleton):
        return grown, None
    return grown.skeleton, grown.polygons


#: The key under which a scene's plant cache keeps its running total of segments grown.
GROWN_SEGMENTS = "segments grown"


def _copy_skeleton(inst, placement: _Placement, seed: int, grammar: tuple[str, Path] | None, grow_grammar,
                   cache: dict, limits: Limits) -> tuple[Skeleton, Polygons | None, str]:
    """The skeleton and leaf polygons (None for none) of one copy, in its own frame, and
    its source name; ``grammar``: the entry's (name, resolved path), None for a skeleton."""
    if grammar is None:
        return _explicit_skeleton(inst["skeleton"], f"{placement.where}: skeleton", limits), None, "skeleton"
    name, gpath = grammar
    key = (str(gpath), seed, placement.iterations)
    if key not in cache:
        try:
            grown = grow_grammar(gpath, seed, placement.iterations)
        except PlantgenError as exc:
            raise SceneError(f"{placement.where}: {exc}") from None
        _keep(cache, key, grown, limits, placement.where)
    return *cache[key], name


def _keep(cache: dict, key: tuple, grown, limits: Limits, where: str) -> None:
    """Keep a grown plant in the scene's ``cache`` under ``key`` (grammar path, seed,
    iterations) and add its segments to the running total of segments grown."""
    cache[key] = _grown_parts(grown)
    total = cache.setdefault(GROWN_SEGMENTS, 0) + len(cache[key][0])    # a running total: O(1) a plant
    cache[GROWN_SEGMENTS] = limits.check("segments", total, f"{where}: segments grown for the scene")


def _forecast(entries, base: Path, grow_grammar, cache: dict, budget: _Budget, allow_paths=(), work=None) -> int:
    """Refuse a scene whose plants would pass a limit before its copies are grown.

    Copies of one grammar at one iteration count differ by seed only: one probe plant
    (its first seed; kept in ``cache``, so not grown twice) gives the segments and the
    ``derive_work`` (``work``, the meter, when given) of each, and the scene's totals are
    estimated as that times the distinct seeds (the segments grown and the derive work) or
    the copies (the segments placed). Where an estimate passes its limit, two more probes
    confirm it with the least of the three; the refusal names the estimate. Returns the
    estimated derive work of the scene's distinct plants (0 without ``work``)."""
    groups: dict[tuple, list] = {}
    for inst, placement in entries:
        if "skeleton" in inst:
            continue
        name = fields.text(inst["grammar"], "grammar", placement.where, SceneError)
        gpath = resolve_grammar(name, base, placement.where, allow_paths)
        group = groups.setdefault((str(gpath), placement.iterations), [set(), 0, inst, placement, (name, gpath)])
        group[0].update(placement.seed + c for _, _, c, _ in placement.copies)
        group[1] += len(placement.copies)
    totals = {"segments": [0, 0], "drawn_segments": [0, 0], "derive_work": [0, 0]}
    for seeds, copies, inst, placement, grammar in groups.values():
        order = sorted(seeds)
        each = [_probe(inst, placement, s, grammar, grow_grammar, cache, budget.limits, work) for s in order[:1]]
        if _over(totals, each[0], len(seeds), copies, budget.limits, work):
            each += [_probe(inst, placement, s, grammar, grow_grammar, cache, budget.limits, work) for s in order[1:3]]
        least = tuple(min(e[i] for e in each) for i in range(2))
        for key, per, count in (("segments", least[0], len(seeds)), ("drawn_segments", least[0], copies),
                                ("derive_work", least[1], len(seeds))):
            totals[key][0] += per * count
            totals[key][1] += count
    for key, (total, count) in totals.items():
        limit = work.limit if key == "derive_work" and work is not None else getattr(budget.limits, f"max_{key}")
        if total > limit:
            raise LimitError(f"{entries[0][1].where.rsplit(':', 1)[0]}: {key} of about {total:,} estimated "
                             f"from probe plants for {count:,} plants, over the limit of {limit:,} ({hint(key)})")
    return totals["derive_work"][0]


def _probe(inst, placement: _Placement, seed: int, grammar, grow_grammar, cache: dict, limits: Limits,
           work) -> tuple[int, int]:
    """(segments, derive work) of the plant of ``seed`` (grown into ``cache`` if new)."""
    before = work.spent if work is not None else 0
    known = (str(grammar[1]), seed, placement.iterations) in cache
    skel = _copy_skeleton(inst, placement, seed, grammar, grow_grammar, cache, limits)[0]
    spent = (work.spent - before) if work is not None and not known else 0
    return len(skel), spent


def _over(totals: dict, each: tuple[int, int], seeds: int, copies: int, limits: Limits, work) -> bool:
    """Whether one probe's counts alone, times the seeds or copies, pass a limit."""
    return (totals["segments"][0] + each[0] * seeds > limits.max_segments
            or totals["drawn_segments"][0] + each[0] * copies > limits.max_drawn_segments
            or (work is not None and totals["derive_work"][0] + each[1] * seeds > work.limit))


def _grow_copies(inst, placement: _Placement, base: Path, grow_grammar, cache: dict, budget: _Budget,
                 allow_paths=()) -> list[SceneInstance]:
    """Every copy of one instance entry, grown (grammars once per seed and iteration count,
    through ``cache``), counted against the scene's segment budget and placed."""
    out, extents, grammar = [], {}, None
    if "skeleton" not in inst:                   # one entry names one grammar: resolved once for all its copies
        name = fields.text(inst["grammar"], "grammar", placement.where, SceneError)
        grammar = name, resolve_grammar(name, base, placement.where, allow_paths)
    for offset, yaw, c, factor in placement.copies:
        s = placement.seed + c
        skel, polygons, source = _copy_skeleton(inst, placement, s, grammar, grow_grammar, cache, budget.limits)
        if "skeleton" in inst:
            budget.add_segments(len(skel), placement.where)
        budget.add_drawn(len(skel), placement.where)
        matrix = _placement_matrix(placement, offset, yaw, factor)
        _check_placed(skel, matrix, placement.where, polygons, extents)
        out.append(SceneInstance(source, s, matrix, skel, _copy_sway(placement.sway, s), polygons))
    return out


def _grow_ahead(entries, base: Path, grow_many, cache: dict, estimate: int, limits: Limits, allow_paths=()) -> None:
    """Grow the scene's distinct plants not yet in ``cache`` all at once, when
    ``grow_many`` takes them: ``grow_many(requests, estimate)``, ``requests`` [(grammar
    path, seed, iterations)] in the order the copies would grow them one by one,
    ``estimate`` the scene's derive work forecast from its probe plants, returns None to
    leave them to be grown one by one, or an iterator of the grown plants in the order
    asked (a pool of processes, :func:`plantgen.pipeline.growing.grow_file`'s ``jobs``).
    Each plant is kept and counted as it comes, so the segments grown are checked as the
    work goes, and an error names the first copy of its plant, as growing one by one does."""
    requests: dict[tuple, str] = {}          # (grammar path, seed, iterations): where its first copy is
    for inst, placement in entries:
        if "skeleton" in inst:
            continue
        name = fields.text(inst["grammar"], "grammar", placement.where, SceneError)
        gpath = str(resolve_grammar(name, base, placement.where, allow_paths))
        for _, _, c, _ in placement.copies:
            key = (gpath, placement.seed + c, placement.iterations)
            if key not in cache:
                requests.setdefault(key, placement.where)
    if len(requests) < 2:
        return
    grown = grow_many([(Path(g), s, its) for g, s, its in requests], estimate)
    if grown is None:
        return
    try:
        for key, where in requests.items():
            try:
                plant = next(grown)
            except PlantgenError as exc:            # the plant's own error, named as one by one names it
                raise SceneError(f"{where}: {exc}") from None
            _keep(cache, key, plant, limits, where)
    finally:
        close = getattr(grown, "close", None)
        if close is not None:
            close()


# ---------------------------------------------------------------------------- scene
def is_scene(data) -> bool:
    return isinstance(data, dict) and "instances" in data


def grows_together(data, path: str = "<scene>") -> bool:
    """Whether a scene mapping asks its plants to grow together (``grow: together``)."""
    mode = data.get("grow", "apart") if isinstance(data, dict) else "apart"
    if mode not in GROW_MODES:
        raise SceneError(f"{path}: grow must be one of {', '.join(GROW_MODES)}, got {fields.show(mode)}")
    return mode == "together"


def parse_scene(data, path: str = "<scene>", *, seed: int | None = None, grow_grammar=None,
                limits: Limits | None = None, allow_paths=(), work=None, grow_many=None) -> Scene:
    """Validate a scene mapping and grow its instances.

    ``grow_grammar(path, seed, iterations)`` grows one grammar (injected by the pipeline,
    which keeps this module free of L-system details) into a Skeleton, or into a drawing
    with ``skeleton`` and ``polygons`` (its leaves, which the copies carry). ``limits`` caps the
    instances and the scene's total segments; grammars are read only from the scene's
    folder, the folders of ``allow_paths`` and the shipped grammars. ``work``: the
    ``derive_work`` meter ``grow_grammar`` spends, if any: with it, a scene whose plants
    would pass it is refused from a probe plant's work before its copies grow
    (:func:`_forecast`; so are the segment limits, with or without it). ``grow_many``, if
    given, may grow the distinct plants left after the forecast all at once (in parallel:
    :func:`_grow_ahead`); the scene is the same either way.
    """
    limits = limits or default_limits
    _check_keys(data, SCENE_KEYS, path)
    grows_together(data, path)
    if not isinstance(data.get("instances"), list) or not data["instances"]:
        raise SceneError(f"{path}: instances must be a non-empty list")
    base_seed = fields.integer(data.get("seed", 0), "seed", path, SceneError) if seed is None else int(seed)
    effects = _parse_effects(data.get("effects", []), path)
    ground = _parse_ground(data.get("ground"), path)
    camera = _parse_camera(data.get("camera", "auto"), path)
    light = _parse_light(data["light"], path) if "light" in data else SCENE_LIGHT
    name = fields.text(data.get("name", Path(path).stem), "name", path, SceneError, max_len=200)
    description = fields.text(data.get("description", ""), "description", path, SceneError, max_len=10_000)

    base = Path(path).parent
    budget = _Budget(limits)
    instances: list[SceneInstance] = []
    cache: dict[tuple, tuple] = {}
    # Every instance (grid copies included) is read and counted before any plant is grown.
    placements = [_parse_placement(inst, k, path, base_seed, seed, budget) for k, inst in enumerate(data["instances"])]
    entries = list(zip(data["instances"], placements, strict=True))
    estimate = _forecast(entries, base, grow_grammar, cache, budget, allow_paths, work)
    if grow_many is not None:
        _grow_ahead(entries, base, grow_many, cache, estimate, limits, allow_paths)
    for inst, placement in zip(data["instances"], placements, strict=True):
        instances += _grow_copies(inst, placement, base, grow_grammar, cache, budget, allow_paths)

    return Scene(name, description, effects, tuple(instances), ground, camera, light, path)


def load_scene(path: str | Path, *, seed: int | None = None, grow_grammar=None,
               limits: Limits | None = None, allow_paths=()) -> Scene:
    """Read a scene file and :func:`parse_scene` it."""
    return parse_scene(read_yaml(path, GrammarError, limits), str(path), seed=seed, grow_grammar=grow_grammar,
                       limits=limits, allow_paths=allow_paths)
