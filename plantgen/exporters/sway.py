"""A scene's sway as an animation other tools play: the joints, skin weights and keys
that glTF skins and UsdSkel hold (see the docs, "Export a swaying scene").

The sway (:mod:`plantgen.geometry.skeletons.motion`) turns every joint of a swaying plant copy
about one horizontal axis of the scene by an angle that is a closed form in t, and moves
each segment rigidly: turned by the sum of the angles on its path, about its start, which
stays on its parent's end. That is a skeleton animation, written as one:

- **joints**: one per segment, at its start, parented as the segments are. At rest a
  joint is a translation (its start from its parent's, :func:`joint_offsets`), so its
  inverse bind matrix is the translation by minus its start;
- **keys**: each joint turns about the copy's axis in the plant's own frame (the scene's
  axis turned back by the copy's rotation), by its own angle θ_i(t)
  (:func:`~plantgen.geometry.skeletons.motion.joint_angles`), at the times of a :class:`Timeline`;
  nested joints compose the turns, as :func:`~plantgen.geometry.skeletons.motion.pose` sums them;
- **weights** (:func:`vertex_influences`): a vertex on the faces of one segment follows
  its joint (weight 1: the segment is rigid); a vertex shared by the faces of several (the
  ring on a joint's cutting plane, which a segment shares with the one continuing it)
  follows each of them equally, so the ring turns by half the joint's angle, as the
  re-skinned joint's plane does (it bisects the two axes), and the rings stay together.
  A leaf follows the segment it hangs from rigidly, as plantgen's animation moves it; a
  leaf that hangs from none follows an extra joint that never moves.

Everything here is in a file's frame: ``up`` turns positions and axes
(:func:`~plantgen.geometry.skeletons.frames.up_rotation`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from ..geometry.skeletons.frames import up_rotation
from ..geometry.skeletons.motion import joint_angles, sway_rig
from ..geometry.skeletons.skeleton import Skeleton
from ..knobs import knob_of
from ..settings import KeyframeSettings
from .formats import ExportError

__all__ = ["MAX_INFLUENCES", "MAX_JOINTS", "JointRig", "PlantSway", "Timeline", "common_period", "copy_rotations",
           "joint_offsets", "joint_rig", "level_rig", "sway_timeline", "vertex_influences"]

#: Joints a vertex follows at most (glTF's JOINTS_0 holds four).
MAX_INFLUENCES = 4
#: Joints one skin may hold: glTF's joint indices are at most 16 bits.
MAX_JOINTS = 65536
#: Frequencies are read as fractions with denominators up to this to find a common period.
_FREQUENCY_DENOMINATOR = 10_000


@dataclass(frozen=True)
class Timeline:
    """The key times of an exported sway: ``times`` (k,) seconds from t = 0 of the scene,
    evenly spaced; ``loops``: the last key lies a whole number of every swaying plant's
    periods after the first, so a player that loops the animation shows no seam."""

    times: np.ndarray
    loops: bool

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    @property
    def keys(self) -> int:
        return len(self.times)

    @property
    def rate(self) -> float:
        """Keys per second (USD's timeCodesPerSecond: key i is time code i)."""
        return (self.keys - 1) / self.duration


def common_period(frequencies) -> float | None:
    """The shortest time (seconds) that is a whole number of periods of every frequency
    (Hz; zeros left out, signs ignored), each read as a fraction with a denominator of at
    most 10,000 (0.7 Hz and 0.5 Hz: 10 s); None when none is nonzero."""
    parts = [Fraction(abs(float(f))).limit_denominator(_FREQUENCY_DENOMINATOR) for f in frequencies if f]
    parts = [p for p in parts if p]
    if not parts:
        return None
    numerator = math.gcd(*(p.numerator for p in parts))
    denominator = math.lcm(*(p.denominator for p in parts))
    return float(Fraction(denominator, numerator))


def sway_timeline(sways, settings: KeyframeSettings = KeyframeSettings(), source="the scene") -> Timeline | None:
    """The key times of the sway of ``sways`` (every copy's :class:`Sway` or None), or None
    when nothing sways: keys ``settings.rate`` a second or a little more, evenly over
    ``settings.duration`` seconds, or over one common period of the swaying copies (one
    second for a sway that never changes: frequency 0). One line (naming ``source``) when
    the frequencies have no common period a duration may hold."""
    moving = [s for s in sways if s is not None and s.moves]
    if not moving:
        return None
    period = common_period([s.frequency for s in moving])
    longest = knob_of(KeyframeSettings, "duration").hi
    duration = settings.duration
    if duration is None:
        if period is not None and period > longest:
            shown = ", ".join(sorted({f"{abs(s.frequency):g}" for s in moving}))
            raise ExportError(f"{source}: the sway frequencies ({shown} Hz) have no common period under "
                              f"{longest:g} s, so no animation loops: give --duration")
        duration = period if period is not None else 1.0
    loops = period is None or abs(duration / period - round(duration / period)) <= 1e-9 * duration / period
    intervals = max(1, math.ceil(duration * settings.rate - 1e-9))
    return Timeline(np.linspace(0.0, float(duration), intervals + 1), bool(loops and duration >= (period or 0)))


@dataclass(frozen=True, eq=False)
class PlantSway:
    """How a plant's copies sway.

    groups : (n,) int, the sway group of each segment of the plant's skeleton: one group
        (0) for a plant written once for its copies, one per instance for a scene written
        in place
    copies : per copy, a tuple of one :class:`~plantgen.geometry.stage.Sway` (or None:
        still) per group
    row_segment : (rows,) int, the segment of each row of the plant's mesh
        (``Frusta.segment``)
    """

    groups: np.ndarray
    copies: tuple
    row_segment: np.ndarray

    def copy_moves(self, copy: int) -> bool:
        return any(s is not None and s.moves for s in self.copies[copy])

    @property
    def moves(self) -> bool:
        return any(self.copy_moves(c) for c in range(len(self.copies)))


def vertex_influences(faces: np.ndarray, face_segment: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """(joints, weights), each (v, :data:`MAX_INFLUENCES`): the segments whose faces use
    each vertex (at most four, in segment order), weighted equally; unused slots hold
    joint 0 with weight 0 (a vertex no face uses follows joint 0)."""
    faces = np.asarray(faces, dtype=np.int64)
    segments = int(face_segment.max()) + 1 if len(face_segment) else 1
    pairs = np.unique(faces.ravel() * segments + np.repeat(np.asarray(face_segment, np.int64), faces.shape[1]))
    vertex, segment = pairs // segments, pairs % segments
    first = np.searchsorted(vertex, vertex)             # pairs are sorted by vertex
    slot = np.arange(len(pairs)) - first
    kept = slot < MAX_INFLUENCES
    joints = np.zeros((n_vertices, MAX_INFLUENCES), np.int64)
    joints[vertex[kept], slot[kept]] = segment[kept]
    count = np.minimum(np.bincount(vertex, minlength=n_vertices), MAX_INFLUENCES)
    weights = (np.arange(MAX_INFLUENCES)[None, :] < count[:, None]) / np.maximum(count, 1)[:, None]
    weights[count == 0, 0] = 1.0
    return joints, weights


def joint_offsets(skeleton: Skeleton, up: str = "y") -> tuple[np.ndarray, np.ndarray]:
    """(bind, offset), each (n, 3), in the ``up`` frame: each joint's rest position (its
    segment's start) and its translation from its parent joint's (a root's: from the
    plant's origin)."""
    bind = skeleton.start @ up_rotation(up).T
    parent = skeleton.parent
    return bind, bind - np.where((parent >= 0)[:, None], bind[np.maximum(parent, 0)], 0.0)


@dataclass(frozen=True, eq=False)
class JointRig:
    """A plant's joints as a writer writes them (the ``up`` frame): ``parent`` (j,) (-1:
    a root), ``bind`` (j, 3) rest positions, ``offset`` (j, 3) rest translations from the
    parent; ``vertex_joints``/``vertex_weights`` (v, 4) for the mesh's vertices,
    ``leaf_joints`` (l,) for the leaves' (one each, weight 1). Joint i < n is segment i; a
    last joint at the origin that never moves is added (``still``) when a leaf hangs from
    no segment."""

    parent: np.ndarray
    bind: np.ndarray
    offset: np.ndarray
    vertex_joints: np.ndarray
    vertex_weights: np.ndarray
    leaf_joints: np.ndarray | None
    still: bool

    @property
    def joints(self) -> int:
        return len(self.parent)


def joint_rig(skeleton: Skeleton, mesh, sway: PlantSway, leaves=None, up: str = "y", source="the plant") -> JointRig:
    """The :class:`JointRig` of a plant: ``skeleton`` and ``mesh`` (a TessellatedMesh) in
    its own frame, ``leaves`` (Polygons or None), ``sway`` its rows' segments. One line
    (naming ``source``) when the joints would not fit one glTF skin."""
    n = len(skeleton)
    joints, weights = vertex_influences(mesh.faces, sway.row_segment[mesh.face_row], len(mesh.vertices))
    leaf_joints = None
    if leaves is not None and len(leaves.triangles):
        leaf_joints = leaves.segment[leaves.vertex_polygon].astype(np.int64)
    still = leaf_joints is not None and bool(np.any(leaf_joints < 0))
    if leaf_joints is not None:
        leaf_joints = np.where(leaf_joints < 0, n, leaf_joints)
    if n + still > MAX_JOINTS:
        raise ExportError(f"{source}: {n + still:,} joints, over the {MAX_JOINTS:,} a glTF skin holds: export the "
                          "scene with its plants instanced, or without its animation")
    bind, offset = joint_offsets(skeleton, up)
    parent = skeleton.parent.astype(np.int64)
    if still:
        bind, offset = np.vstack([bind, np.zeros(3)]), np.vstack([offset, np.zeros(3)])
        parent = np.append(parent, -1)
    return JointRig(parent, bind, offset, joints, weights, leaf_joints, still)


def level_rig(rig: JointRig, skeleton: Skeleton, mesh, sway: PlantSway, leaves=None, up: str = "y",
              source="the plant") -> JointRig:
    """The rig of one of a swaying plant's levels of detail (its ``mesh``, ``sway`` and
    ``leaves``: :func:`~plantgen.exporters.plants.level_plant`) on the joints of ``rig``
    (level 0's): the same skeleton, so one skin and one animation drive every level. A
    level's vertices follow the segments of their own rows, which are level 0's rows: a
    ring that level 0 shares with a dropped child follows its own segment alone, where
    level 0's follows both halfway (:func:`vertex_influences`), so a level's cap strays
    from level 0's ring by at most the ring's radius times the child joint's angle over 2."""
    own = joint_rig(skeleton, mesh, sway, leaves, up, source)
    return JointRig(rig.parent, rig.bind, rig.offset, own.vertex_joints, own.vertex_weights, own.leaf_joints,
                    rig.still)


def copy_rotations(skeleton: Skeleton, sway: PlantSway, copy: int, matrix, times, up: str = "y",
                   joints: int | None = None) -> np.ndarray:
    """(k, j, 4) unit quaternions (x, y, z, w) of each joint of copy ``copy`` at the k
    ``times``, relative to its parent, in the ``up`` frame: a turn by its own sway angle
    about the copy's axis. ``matrix`` (4, 4) places the copy (None: the plant stands
    where the scene has it); joints past the segments (``joints``: the rig's count) never
    turn."""
    rig = sway_rig(skeleton, sway.groups, list(sway.copies[copy]))
    turn = np.eye(3) if matrix is None else np.asarray(matrix, dtype=np.float64)[:3, :3]
    turn = turn / np.cbrt(np.linalg.det(turn))
    axis = (rig.axis @ turn) @ up_rotation(up).T          # the scene's axis in the plant's frame, turned up
    half = 0.5 * joint_angles(rig, np.asarray(times, dtype=np.float64))
    n = len(skeleton)
    out = np.zeros((len(times), n if joints is None else joints, 4))
    out[..., 3] = 1.0
    out[:, :n, :3] = np.sin(half)[..., None] * axis[None]
    out[:, :n, 3] = np.cos(half)
    return out
