"""Ray queries on the GPU: a BVH (:mod:`plantgen.geometry.rays.bvh`) and its primitives in
storage buffers, searched by ``shaders/bvh.glsl`` (one compute invocation per ray,
``shaders/trace.glsl``), closest hit or any hit.

Precision: everything the GPU holds is float32 relative to a frame origin formed in
float64 here: row records (:func:`plantgen.gl.records.pack_records`), leaf triangles and
node boxes (rounded outward, :func:`plantgen.geometry.rays.bvh.float32_boxes`, so a float32
box never loses a ray its float64 box keeps, then put on each node's 8-bit grid rounded
outward again, :func:`node_words`: 48 bytes a 4-wide node). A plant of one kind (rows or
leaf triangles) uploads its data in the GPU's leaf order (:func:`leaf_order`), with no
table of primitive ids; the hits name those slots and :func:`trace_rays` maps them back
to the plant's ids (:meth:`GpuBvh.primitive_ids`). An instanced scene keeps each distinct
plant once, relative to its own box centre, and per copy the map from the frame into the
plant's (its offset formed in float64). The GPU finds the primitive; callers that need
float64 distances solve that one primitive again on the CPU (:mod:`plantgen.trace`, the
scan).

A copy costs :data:`COPY_BYTES` (32) for its map and plant index: the map x -> (x - offset)
as the quaternion u = conj(q) / sqrt(scale) turns it, u·v·conj(u) = turnᵀ·v / scale for
its rotation q and uniform scale (a quaternion times a real turns and scales at once),
where every copy of the scene is a similarity that keeps handedness (the scene format's:
a positive scale and a rotation). A scene with a copy that mirrors, scales unevenly or
shears (possible only through the API, :class:`~plantgen.geometry.rays.instances.PlacedPlants`
built by hand) keeps the full 3x4 map instead, :data:`AFFINE_COPY_BYTES` a copy (the
shader's ``BVH_AFFINE_COPIES``), exact for any invertible map. The copies go up in the
top level's leaf order, so a top-level leaf's ``first`` is its first copy's slot and no
table of copy ids is needed on the GPU (:attr:`GpuBvh.copy_ids` maps the slots back).

Memory stays bounded: rays go up in chunks of ``chunk`` (32 bytes a ray up, 16 back).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import PlantgenError
from ..geometry.rays.bvh import BVH, build_bvh, float32_boxes
from ..geometry.rays.instances import similarity_parts
from ..geometry.skeletons.frames import similarity_trs
from ..geometry.skeletons.frusta import plane_height
from ..limits import LimitError, hint
from ..tolerances import tol
from .records import RECORD_FLOATS, pack_records
from .shaders import build_compute, set_uniforms

__all__ = ["GpuBvh", "GpuPlant", "upload_bvh", "trace_rays", "trace_target", "target_bvh", "TRACE_CHUNK",
           "BVH_BINDING", "BVH_STACK", "COPY_BYTES", "AFFINE_COPY_BYTES", "copy_words", "GPU_LEAF_SIZE",
           "node_words", "stack_need", "wide_nodes", "leaf_order", "quantise_boxes", "decode_nodes",
           "NODE_VEC4", "MAX_LEAF_PRIMS", "BUFFER_NAMES", "row_bounds", "ROW_BOUND", "ROW_BOUND_BINDING",
           "ROW_BOUND_BYTES"]

#: Primitives a leaf of a BVH built for the GPU holds at most (the ray tracer's, and the one
#: a scan or a trace uploads; the float64 reference keeps its own): 2 tests about half the
#: primitives of 4 a ray (the forest's eye rays: 5.5 against 12.1) for 13 % more GPU memory,
#: eye and shadow rays 1.1-1.3x faster on llvmpipe; 1 is no faster than 2
#: (docs/benchmarks/rt.md).
GPU_LEAF_SIZE = 2
#: The BVH's storage buffers in binding order (from :data:`BVH_BINDING`; the copies' with
#: two levels only): :attr:`GpuBvh.parts` gives their bytes.
BUFFER_NAMES = ("nodes", "primitive ids", "row records", "triangles", "plants", "copies")
#: Rays per dispatch of :func:`trace_rays` (a knob: memory against dispatch overhead).
TRACE_CHUNK = 1 << 16
#: First SSBO binding of the BVH's buffers in ``shaders/bvh.glsl`` (6 in all).
BVH_BINDING = 3
#: Whether the traversal tests a row's cheap bound before its row test (``BVH_ROW_BOUND``
#: in ``shaders/bvh.glsl``: the distance of the ray's line from the row's axis segment
#: against :func:`row_bounds`, :data:`ROW_BOUND_BYTES` more a row on the GPU). Off: it drops
#: 90 % of the rows an eye ray tests, but llvmpipe runs a shader's branches on all of a
#: vector's lanes, so the row test still runs and the bound only adds work (0.8-1.0x on the
#: forest's frames, docs/benchmarks/rt.md); a GPU, whose warps skip a branch none of their
#: lanes take, may gain: measure it there (``python -m plantgen.benchmarks.row_bound``).
ROW_BOUND = False
#: SSBO binding of the rows' bounds (:func:`row_bounds`) in ``shaders/bvh.glsl``.
ROW_BOUND_BINDING = 9
#: GPU bytes of one row's bound (beside its 96-byte record).
ROW_BOUND_BYTES = 4
#: The traversal stack's entries in ``shaders/bvh.glsl``; a deeper tree is refused.
BVH_STACK = 96
#: GPU bytes of one copy's map and plant index in an instanced scene whose copies are all
#: similarities that keep handedness (a scaled quaternion, the offset, the plant).
COPY_BYTES = 32
#: The same for a scene with a copy that mirrors, scales unevenly or shears (a 3x4 map).
AFFINE_COPY_BYTES = 64
_GROUP = 64   # local_size_x of shaders/trace.glsl


@dataclass(frozen=True, eq=False)
class GpuPlant:
    """One distinct plant's primitives for :func:`upload_bvh`: ``frusta`` (rows 0..r-1,
    or None), ``triangles`` ((t, 3, 3) float64 leaf triangles r..r+t-1, or None) and the
    ``bvh`` over them (primitive ids as above), all in the plant's frame."""

    frusta: object
    triangles: np.ndarray | None
    bvh: BVH

    @property
    def rows(self) -> int:
        return 0 if self.frusta is None else len(self.frusta)


@dataclass(eq=False)
class GpuBvh:
    """The uploaded buffers (:func:`upload_bvh`); :meth:`bind` before a dispatch or draw
    whose program includes ``bvh.glsl`` (with ``TWO_LEVEL`` where :attr:`two_level`)."""

    ctx: object
    origin: np.ndarray
    two_level: bool
    buffers: list = field(default_factory=list)
    nbytes: int = 0
    parts: dict = field(default_factory=dict)   # bytes of each buffer as uploaded, by name (BUFFER_NAMES)
    plants: int = 0
    copies: int = 0
    empty: bool = False      # no primitive: nothing to trace (the buffers hold a dummy word)
    affine: bool = False     # the copies' maps are full 3x4 maps (not every copy a similarity)
    copy_ids: np.ndarray | None = None   # (copies,) int64: the copy held in each GPU slot
    slot_plant: np.ndarray | None = None  # (copies,) int64: the plant of each GPU slot's copy
    prim_ids: np.ndarray | None = None   # the plant-local primitive of each plant's GPU slots, plant after plant
    prim_starts: np.ndarray | None = None   # (plants,) int64: where each plant's slots start in prim_ids

    bounds: object = None    # the rows' bounds (row_bounds; uploaded with the row bound on)
    row_bound: bool | None = None        # test them (BVH_ROW_BOUND, where uploaded); None: ROW_BOUND

    def primitive_ids(self, slot, plant) -> np.ndarray:
        """The plant-local primitive ids of GPU primitive slots (what the shaders' hits
        name: a position in the plant's data as uploaded) of the given plants."""
        return self.prim_ids[self.prim_starts[plant] + slot]

    def defines(self) -> dict:
        on = ROW_BOUND if self.row_bound is None else self.row_bound
        return {"TWO_LEVEL": self.two_level, "BVH_AFFINE_COPIES": self.two_level and self.affine,
                "BVH_ROW_BOUND": bool(on) and self.bounds is not None}

    def bind(self) -> None:
        for i, buf in enumerate(self.buffers):
            buf.bind_to_storage_buffer(BVH_BINDING + i)
        if self.bounds is not None:
            self.bounds.bind_to_storage_buffer(ROW_BOUND_BINDING)

    def release(self) -> None:
        for buf in [*self.buffers, self.bounds]:
            if buf is not None:
                buf.release()
        self.buffers, self.bounds = [], None


#: Words (vec4) of one node on the GPU (48 bytes): the node's grid (its origin and a
#: power-of-two step per axis), its four children's boxes on it (a byte a bound), where
#: their references start and what each child is (:func:`node_words`).
NODE_VEC4 = 3
#: A leaf reference (the traversal's) packs its primitive offset above these bits and its
#: count in them.
LEAF_COUNT_BITS = 6
#: Primitives a leaf of a GPU tree may hold (a child's 6-bit code: 0 unused, 63 a node).
MAX_LEAF_PRIMS = 62
_INTERNAL = 63       # a child's code: a wide node
_BASE_BITS = 24      # a node's first child node and first primitive: 24-bit fields
_MAX_OFFSET = 1 << 23   # a leaf's offset: the traversal's stack holds 4 * its reference
_EXP_BIAS = 127      # a step 2^e is stored as its float32 exponent bits (e + 127)
_EXP_MAX = 119       # 255 steps of 2^119 stay finite in float32
_EMPTY = -1          # the reference of an unused child slot


def wide_nodes(bvh: BVH) -> tuple[np.ndarray, np.ndarray]:
    """The binary BVH collapsed into a 4-wide one, as the GPU walks it: per wide node its
    (up to) four children, the binary node's grandchildren (a child that is a leaf stays
    itself). Returns ``slots`` (w, 4) int64, the binary node in each slot (-1: unused), and
    ``wide`` (w, 4) int64, the wide node an internal slot becomes (-1 for a leaf or an unused
    slot). Wide node 0 is the root; a tree whose root is a leaf gets one wide node holding it.
    Nodes are numbered level by level (every two binary levels one), vectorised, so that a
    wide node's internal children are consecutive wide nodes."""
    first, count = np.asarray(bvh.first, np.int64), np.asarray(bvh.count, np.int64)
    if not bvh.nodes:
        return np.zeros((0, 4), np.int64), np.zeros((0, 4), np.int64)
    if count[0] > 0:
        return np.array([[0, -1, -1, -1]]), np.full((1, 4), -1)
    slots, wide = [], []
    frontier, total = np.array([0]), 1
    while frontier.size:
        pair = np.stack([first[frontier], first[frontier] + 1], axis=1).reshape(-1)
        inner = count[pair] == 0
        grand = np.where(inner[:, None], np.stack([first[pair], first[pair] + 1], axis=1),
                         np.stack([pair, np.full_like(pair, -1)], axis=1))
        level = grand.reshape(-1, 4)
        level = np.take_along_axis(level, np.argsort(level < 0, axis=1, kind="stable"), axis=1)  # unused last
        internal = (level >= 0) & (count[np.maximum(level, 0)] == 0)
        ids = np.full(level.shape, -1)
        ids[internal] = total + np.arange(internal.sum())
        total += int(internal.sum())
        slots.append(level)
        wide.append(ids)
        frontier = level[internal]
    return np.concatenate(slots), np.concatenate(wide)


def stack_need(bvh: BVH, slots: np.ndarray, wide: np.ndarray, leaf_push: bool = False) -> int:
    """Traversal stack entries a ray may hold inside this tree: along a path, a wide node
    pushes all its hit children but the one it walks into; with ``leaf_push`` (the top
    level) a leaf pushes its copies."""
    if not len(slots):
        return 0
    leaf = (slots >= 0) & (wide < 0)
    below = np.where(leaf, np.asarray(bvh.count)[np.maximum(slots, 0)] if leaf_push else 0, 0).astype(np.int64)
    levels, a, b = [], 0, 1             # wide nodes are numbered level by level
    while a < b:
        levels.append((a, b))
        a, b = b, max(b, int(wide[a:b].max()) + 1)
    need = np.zeros(len(slots) + 1, np.int64)         # need[-1]: 0, for a slot with no wide node
    for a, b in reversed(levels):
        deepest = np.maximum(below[a:b], need[wide[a:b]]).max(axis=1)
        need[a:b] = (slots[a:b] >= 0).sum(axis=1) - 1 + deepest
    return int(need[0])


def leaf_order(bvh: BVH, slots: np.ndarray, wide: np.ndarray) -> np.ndarray:
    """(n,) int64 the primitive ids in the GPU's order: wide node by wide node, its leaf
    children's primitives in slot order, so that a node's leaves are consecutive (a node
    keeps one offset for them, :func:`node_words`). The GPU's primitive data goes up in
    this order: position k of a leaf holds primitive ``leaf_order(...)[k]``."""
    leaf = (slots >= 0) & (wide < 0)
    s = slots[leaf]                                   # row-major: node by node, slot by slot
    first, count = np.asarray(bvh.first, np.int64)[s], np.asarray(bvh.count, np.int64)[s]
    start = np.repeat(first - (np.cumsum(count) - count), count)
    return np.asarray(bvh.prims, np.int64)[start + np.arange(int(count.sum()))]


def _exponents(lo, hi) -> np.ndarray:
    """(w, 3) int64 the smallest power-of-two step 2^e per node and axis (float64 node
    boxes ``lo``, ``hi`` (w, 3), float32 values) on which the node's box fits 254 steps
    and its origin, a whole number of steps, stays under 2^23 steps (so that origin +
    steps·2^e is exact in float32), at least 2^-126."""
    extent = hi - lo
    e_ext = np.where(extent > 0, np.frexp(extent / 254.0)[1], -126)
    mag = np.maximum(np.abs(lo), np.abs(hi))
    e_mag = np.where(mag > 0, np.frexp(mag)[1] - 23, -126)
    return np.maximum(np.maximum(e_ext, e_mag), -126).astype(np.int64)


def quantise_boxes(c_lo, c_hi, used) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each wide node's four child boxes (``c_lo``, ``c_hi`` (w, 4, 3) float64 holding
    float32 values, ``used`` (w, 4)) on an 8-bit grid of the node's own: returns the grid's
    origin (w, 3) (float32 values, a whole number of steps), its exponent e (w, 3) (a step
    2^e per axis) and the children's bounds in steps, ``q_lo``, ``q_hi`` (w, 4, 3) uint8:
    lo rounded down and hi up, so that origin + q·2^e (exact in float32) holds each child
    box. Unused slots get 0. Raises PlantgenError for boxes beyond float32's range."""
    w = len(c_lo)
    inf = np.inf
    n_lo = np.where(used[..., None], c_lo, inf).min(axis=1) if w else np.zeros((0, 3))
    n_hi = np.where(used[..., None], c_hi, -inf).max(axis=1) if w else np.zeros((0, 3))
    if not (np.isfinite(n_lo).all() and np.isfinite(n_hi).all()):
        raise PlantgenError("BVH boxes beyond float32's range for the GPU's nodes")
    e = _exponents(n_lo, n_hi)
    for _ in range(4):                 # a node whose hi needs 256 steps takes the next step
        step = np.ldexp(1.0, e)
        origin = np.floor(n_lo / step) * step
        sc = step[:, None, :]
        q_lo = np.floor((c_lo - origin[:, None]) / sc)
        q_lo -= origin[:, None] + q_lo * sc > c_lo                 # rounding: never above lo
        q_hi = np.ceil((c_hi - origin[:, None]) / sc)
        q_hi += origin[:, None] + q_hi * sc < c_hi                 # never below hi
        q_lo = np.where(used[..., None], np.maximum(q_lo, 0), 0)
        q_hi = np.where(used[..., None], q_hi, 0)
        over = (q_hi > 255).any(axis=1)
        if not over.any():
            break
        e = e + over
    if (e > _EXP_MAX).any() or (q_hi > 255).any():
        raise PlantgenError("BVH boxes too large for the GPU's nodes (beyond 1e38)")
    return origin, e, q_lo.astype(np.uint8), q_hi.astype(np.uint8)


def node_words(bvh: BVH, origin, slots: np.ndarray, wide: np.ndarray) -> np.ndarray:
    """(w, 12) float32, NODE_VEC4 vec4 a wide node (48 bytes), as uint32 bits:

    - 0-2: the node's grid origin (float32, relative to ``origin``);
    - 3: its first internal child's wide node (24 bits; the others follow it) | (e_x + 127) << 24;
    - 4-9: the four children's bounds in steps of the grid, a byte a child (child j in bits
      8j): lo x, lo y, lo z, hi x, hi y, hi z; the box decoded, origin + steps·2^e, holds the
      child's float32 box rounded outward from its float64 one (:func:`quantise_boxes`);
    - 10: its leaf children's first primitive position (24 bits; :func:`leaf_order`, the
      leaves' primitives follow one another in slot order) | (e_y + 127) << 24;
    - 11: each child's 6-bit code (child j in bits 6j: 0 unused, 63 a wide node, else a
      leaf of that many primitives) | (e_z + 127) << 24.
    """
    lo, hi = float32_boxes(bvh, origin)
    used = slots >= 0
    s = np.maximum(slots, 0)
    w = len(slots)
    count = np.asarray(bvh.count, np.int64)[s]
    internal = wide >= 0
    leaf = used & ~internal
    if w and count[leaf].max(initial=0) > MAX_LEAF_PRIMS:
        raise PlantgenError(f"BVH leaves too large for the GPU's nodes (at most {MAX_LEAF_PRIMS} primitives a leaf)")
    code = np.where(internal, _INTERNAL, np.where(leaf, count, 0)).astype(np.uint64)
    leaf_count = np.where(leaf, count, 0)
    prim_base = np.cumsum(leaf_count.sum(axis=1)) - leaf_count.sum(axis=1)
    node_base = np.where(internal, wide, np.iinfo(np.int64).max).min(axis=1, initial=np.iinfo(np.int64).max)
    node_base = np.where(internal.any(axis=1), node_base, 0)
    if w and (leaf_count.sum() >= _MAX_OFFSET or node_base.max() >= 1 << _BASE_BITS):
        raise PlantgenError(f"BVH too large for the GPU's node references (at most {_MAX_OFFSET:,} primitives "
                            f"and {1 << _BASE_BITS:,} nodes a tree)")
    grid, e, q_lo, q_hi = quantise_boxes(lo[s].astype(np.float64), hi[s].astype(np.float64), used)
    exp_bits = (e + _EXP_BIAS).astype(np.uint64) << np.uint64(24)
    words = np.zeros((w, 12), np.uint32)
    words[:, 0:3] = grid.astype(np.float32).view(np.uint32)
    shifts = (8 * np.arange(4)).astype(np.uint64)
    for axis in range(3):
        words[:, 4 + axis] = (q_lo[:, :, axis].astype(np.uint64) << shifts).sum(axis=1)
        words[:, 7 + axis] = (q_hi[:, :, axis].astype(np.uint64) << shifts).sum(axis=1)
    words[:, 3] = node_base.astype(np.uint64) | exp_bits[:, 0]
    words[:, 10] = prim_base.astype(np.uint64) | exp_bits[:, 1]
    words[:, 11] = (code << (6 * np.arange(4)).astype(np.uint64)).sum(axis=1) | exp_bits[:, 2]
    return words.view(np.float32)


def decode_nodes(words: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What ``shaders/bvh.glsl``'s ``bvh_node`` decodes from :func:`node_words`' words (w,
    12): the children's boxes ``lo``, ``hi`` (w, 4, 3) float32 and their references (w, 4)
    int32 as the traversal holds them (a wide node's index, a leaf's
    -1 - (offset << LEAF_COUNT_BITS | count), -1 unused). The tests' mirror of the shader."""
    u = np.asarray(words, np.float32).reshape(-1, 12).view(np.uint32).astype(np.int64)
    grid = u[:, 0:3].astype(np.uint32).view(np.float32)
    step = np.stack([((u[:, k] >> 24) << 23).astype(np.uint32).view(np.float32) for k in (3, 10, 11)], axis=1)
    q = np.stack([(u[:, 4:10] >> (8 * j)) & 0xFF for j in range(4)], axis=1).astype(np.float32)    # (w, 4, 6)
    lo = grid[:, None, :] + q[:, :, 0:3] * step[:, None, :]
    hi = grid[:, None, :] + q[:, :, 3:6] * step[:, None, :]
    code = np.stack([(u[:, 11] >> (6 * j)) & 63 for j in range(4)], axis=1)
    internal = code == _INTERNAL
    leaf_count = np.where(internal, 0, code)
    node = (u[:, 3] & 0xFFFFFF)[:, None] + np.cumsum(internal, axis=1) - internal
    offset = (u[:, 10] & 0xFFFFFF)[:, None] + np.cumsum(leaf_count, axis=1) - leaf_count
    ref = np.where(internal, node, np.where(code > 0, -1 - ((offset << LEAF_COUNT_BITS) | code), _EMPTY))
    return lo.astype(np.float32), hi.astype(np.float32), ref.astype(np.int32)


#: Plane rises (n·axis + k·n·e, the generator's approach to a cutting plane) below this
#: leave a row unbounded for the cheap reject (its bound infinite: never rejected): its
#: oblique end reaches far along the axis, and float32 rounding of so flat a crossing could
#: move it further than the bound's margin.
_BOUND_RISE = 1e-3
#: The bound's relative widening: float32 rounding of the record against the float64 row
#: (the shader adds 1e-5 of the row's length for its own rounding).
_BOUND_WIDEN = 1e-3


def row_bounds(frusta, origin) -> np.ndarray:
    """(n,) float32 per row: the largest distance from its axis segment {C1 + s·axis,
    0 <= s <= h} of any point of the solid row (the cone grown by its relief shell, between
    its cutting planes moved out by the GPU's joint slack, relative to ``origin`` as
    :func:`~plantgen.gl.records.pack_records` packs it), widened by ``_BOUND_WIDEN`` and
    rounded up; inf where no finite bound holds (a zero-length row, a plane nearly along a
    generator). A ray whose line passes farther than this from the segment misses the row
    (``bvh_row_near`` in ``shaders/bvh.glsl``).

    The solid is convex: its extreme points lie where the cone meets a plane, or at the apex
    of a cone closing to a point inside it. A generator of direction e meets a plane at the
    height y(x) = (gap - r1·x) / (n·a + k·x) of x = n·e (:func:`plantgen.geometry.skeletons.frusta.
    plane_height`), monotone in x, so over every generator the heights lie between its
    values at x = ±|n_perp|. A point at height y lies at most g(y) = hypot(max(-y, y - h, 0),
    max(r1 + shell + k·y, 0)) from the segment, convex in y: its largest value over the
    extreme points' heights is at the lowest or highest of them.
    """
    n = len(frusta.base)
    if n == 0:
        return np.zeros(0, np.float32)
    h = np.asarray(frusta.length, np.float64)
    base_rel = np.asarray(frusta.base, np.float64) - np.asarray(origin, np.float64)
    slack = tol.joint_slack * 2.0 ** -24 * (np.linalg.norm(base_rel.astype(np.float32), axis=1) + h)
    r = np.asarray(frusta.r1, np.float64) + frusta.shell
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        k = (frusta.r2 - frusta.r1) / h
        ys, ok = [], np.isfinite(k) & (h > 0)
        inside = np.ones(n, bool)
        apex = -r / k
        for plane, sign in ((frusta.plane_lo, -1.0), (frusta.plane_hi, 1.0)):
            normal = plane[:, :3]
            gap = plane[:, 3] - np.einsum("ij,ij->i", normal, frusta.base) + sign * slack   # moved out
            n_axis = np.einsum("ij,ij->i", normal, frusta.axis)
            n_perp = np.sqrt(np.maximum(1.0 - n_axis ** 2, 0.0))
            rises = []
            for x in (-n_perp, n_perp):
                y, rise = plane_height(gap, n_axis, x, r, k)
                ys.append(y)
                rises.append(rise)
            ok &= (np.abs(rises[0]) > _BOUND_RISE) & (np.abs(rises[1]) > _BOUND_RISE) & (rises[0] * rises[1] > 0)
            side = n_axis * apex - gap              # the apex's side of the moved plane
            inside &= np.isfinite(apex) & (sign * side <= 0)
        y_lo, y_hi = np.minimum.reduce(ys), np.maximum.reduce(ys)
        y_lo = np.where(inside, np.minimum(y_lo, apex), y_lo)
        y_hi = np.where(inside, np.maximum(y_hi, apex), y_hi)

        def reach(y):
            return np.hypot(np.maximum(np.maximum(-y, y - h), 0.0), np.maximum(r + k * y, 0.0))

        bound = np.maximum(reach(y_lo), reach(y_hi)) * (1.0 + _BOUND_WIDEN)
    bound = np.where(ok & np.isfinite(bound), bound, np.inf)
    out = bound.astype(np.float32)
    return np.where(out < bound, np.nextafter(out, np.float32(np.inf)), out).astype(np.float32)


def _triangle_words(triangles, origin) -> np.ndarray:
    """(t, 12) float32: (v0, |e1||e2|), (e1, 0), (e2, 0), v0 relative to ``origin``."""
    tri = np.zeros((0, 3, 3)) if triangles is None else np.asarray(triangles, np.float64)
    words = np.zeros((len(tri), 12), np.float32)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    words[:, 0:3] = tri[:, 0] - origin
    words[:, 3] = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    words[:, 4:7], words[:, 8:11] = e1, e2
    return words


def _is_similarity(matrices) -> bool:
    """Whether every (k, 4, 4) matrix is a similarity that keeps handedness: a positive
    determinant and a turn (linear part over the uniform scale) within ``tol.similarity``
    of a rotation."""
    lin = matrices[:, :3, :3]
    det = np.linalg.det(lin)
    if not np.all(det > 0):
        return False
    turn = lin / np.cbrt(det)[:, None, None]
    gap = np.einsum("kji,kjl->kil", turn, turn) - np.eye(3)
    return bool(np.abs(gap).max(initial=0.0) <= tol.similarity)


def copy_words(matrices, copy_plant, centres, origin, *, affine: bool | None = None) -> tuple[np.ndarray, bool]:
    """Per copy, its map from the world frame (relative to ``origin`` (3,)) into its
    plant's frame (relative to the plant's centre, ``centres`` (plants, 3)): x_plant =
    turnᵀ·(x - offset) / scale, offset = shift + scale·turn·centre - origin formed in
    float64 and rounded once; and its plant (``copy_plant`` (k,)). Returns the words and
    whether they are full maps: (k, 8) float32 (u = conj(q) / sqrt(scale) as x, y, z, w;
    offset, the plant index's bits) where every copy is a similarity that keeps
    handedness (:data:`COPY_BYTES`), else (k, 16) (three rows of the 3x4 map
    turnᵀ / scale | -turnᵀ·offset / scale, then the plant's bits;
    :data:`AFFINE_COPY_BYTES`), or as ``affine`` asks (True: full maps always)."""
    matrices = np.asarray(matrices, np.float64).reshape(-1, 4, 4)
    copy_plant = np.asarray(copy_plant, np.int64)
    copies = len(matrices)
    if affine is None:
        affine = not _is_similarity(matrices)
    elif not affine and not _is_similarity(matrices):
        raise PlantgenError("copy_words: a copy that mirrors, scales unevenly or shears needs full maps")
    turn, scale, shift = similarity_parts(matrices)
    centre = np.asarray(centres, np.float64).reshape(-1, 3)[copy_plant] if copies else np.zeros((0, 3))
    plant_bits = copy_plant.astype(np.int32).view(np.float32)
    if not affine:
        offset = shift + scale[:, None] * np.einsum("kij,kj->ki", turn, centre) - origin
        _, q, _ = similarity_trs(matrices)
        words = np.empty((copies, 8), np.float32)
        words[:, 0:3] = -q[:, :3] / np.sqrt(scale)[:, None]
        words[:, 3] = q[:, 3] / np.sqrt(scale)
        words[:, 4:7] = offset
        words[:, 7] = plant_bits
        return words, False
    lin = matrices[:, :3, :3]            # any invertible map: its own inverse, not turn's
    inverse = np.linalg.inv(lin) if copies else np.zeros((0, 3, 3))
    offset = matrices[:, :3, 3] + np.einsum("kij,kj->ki", lin, centre) - origin
    words = np.zeros((copies, 16), np.float32)
    words[:, [0, 1, 2, 4, 5, 6, 8, 9, 10]] = inverse.reshape(copies, 9)
    words[:, [3, 7, 11]] = -np.einsum("kij,kj->ki", inverse, offset)
    words[:, 12] = plant_bits
    return words, True


def _plant_words(p: GpuPlant, centre, tree, with_bounds: bool) -> tuple:
    """One plant's GPU words in its frame (``centre``): its nodes, its primitive id table
    (None for a plant of one kind, whose data goes up in the GPU's leaf order instead),
    its row records, triangles and rows' bounds, and the plant's primitive held in each
    GPU slot."""
    order = leaf_order(*tree)     # the primitives in the GPU's order
    mixed = p.rows > 0 and p.triangles is not None and len(p.triangles) > 0
    node = node_words(p.bvh, centre, *tree[1:])
    rec = pack_records(p.frusta, centre) if p.rows else np.zeros((0, RECORD_FLOATS), np.float32)
    tri = _triangle_words(p.triangles, centre)
    bound = row_bounds(p.frusta, centre) if p.rows and with_bounds else np.zeros(0, np.float32)
    if mixed:         # rows and triangles: a table of ids in the GPU's order, the data in id order
        return node, order.astype(np.int32), rec, tri, bound, np.arange(len(order))
    if p.rows:        # one kind: the data itself in the GPU's order (no table)
        rec, bound = rec[order], bound[order] if len(bound) else bound
    elif len(order):
        tri = tri[order]
    return node, None, rec, tri, bound, order


def upload_bvh(ctx, plants, origin=None, *, top: BVH | None = None, matrices=None, copy_plant=None,
               max_bytes: int | None = None, row_bound: bool | None = None) -> GpuBvh:
    """Upload ``plants`` (a list of :class:`GpuPlant`) to storage buffers.

    One level (``top`` None): one plant, in the frame of ``origin`` ((3,) float64; default
    the centre of its root box). Two levels: ``top`` a BVH over the copies (copy ids), per
    copy its similarity ``matrices`` (k, 4, 4) from its plant's frame to the world and
    ``copy_plant`` (k,) its plant; ``origin`` the world frame's origin (rays are given
    relative to it). Raises PlantgenError for a tree deeper than the GPU's stack, and a
    LimitError (one line) when the buffers would pass ``max_bytes`` (nothing uploaded).
    ``row_bound`` (None: :data:`ROW_BOUND`): upload the rows' bounds for the cheap reject.
    """
    with_bounds = ROW_BOUND if row_bound is None else bool(row_bound)
    two_level = top is not None
    if not two_level and len(plants) != 1:
        raise PlantgenError("upload_bvh: one plant without a top level")
    trees = [(p.bvh, *wide_nodes(p.bvh)) for p in plants]
    stack = max((stack_need(*t) for t in trees), default=0)
    if two_level:
        top_tree = (top, *wide_nodes(top))
        stack += stack_need(*top_tree, leaf_push=True)
    if stack > BVH_STACK:
        raise PlantgenError(f"BVH too deep for the GPU traversal's stack ({stack} > {BVH_STACK} entries)")
    if origin is None:
        root = top if two_level else plants[0].bvh
        origin = 0.5 * (root.lo[0] + root.hi[0]) if root.nodes else np.zeros(3)
    origin = np.asarray(origin, np.float64)
    # each plant's frame: its own root box centre (the world frame's origin with one level)
    centres = [origin if not two_level else (0.5 * (p.bvh.lo[0] + p.bvh.hi[0]) if p.bvh.nodes else np.zeros(3))
               for p in plants]
    nodes, prims, rows, tris, offsets, ids, bounds = [], [], [], [], [], [], []
    counts = np.zeros(4, np.int64)
    for p, c, tree in zip(plants, centres, trees, strict=True):
        node, prim, rec, tri, bound, held = _plant_words(p, c, tree, with_bounds)
        offsets.append([counts[0], counts[1] if prim is not None else -1, counts[2], counts[3], p.rows, 0, 0, 0])
        if prim is not None:
            prims.append(prim)
        for out, a in ((nodes, node), (rows, rec), (tris, tri), (bounds, bound), (ids, held)):
            out.append(a)
        counts += [len(node), 0 if prim is None else len(prim), p.rows, len(tri)]
    if two_level:     # the top level's nodes follow the plants' (one node array)
        offsets[0][5] = counts[0]
        nodes.append(node_words(top, origin, *top_tree[1:]))
    arrays = [np.concatenate(nodes), np.concatenate(prims) if prims else np.zeros(0, np.int32), np.concatenate(rows),
              np.concatenate(tris), np.asarray(offsets, np.int32)]
    copies, affine, copy_ids, slot_plant = 0, False, None, None
    if two_level:     # the copies in the top level's GPU order: a leaf's offset is its first copy's slot
        copy_ids = leaf_order(*top_tree)
        matrices = np.asarray(matrices, np.float64).reshape(-1, 4, 4)
        slot_plant = np.asarray(copy_plant, np.int64)[copy_ids]
        words, affine = copy_words(matrices[copy_ids], slot_plant, centres, origin)
        copies = len(words)
        arrays.append(words)
    bound_words = np.concatenate(bounds)
    need = sum(a.nbytes for a in arrays) + bound_words.nbytes
    if max_bytes is not None and need > max_bytes:
        raise LimitError(f"the BVH of {len(plants):,} plants and {copies:,} copies needs {need / 2**20:,.0f} MiB on "
                         f"the GPU, over the limit of {max_bytes / 2**20:,.0f} MiB ({hint('render_bytes')})")
    gpu = GpuBvh(ctx, origin, two_level, plants=len(plants), copies=copies, affine=affine, copy_ids=copy_ids,
                 slot_plant=slot_plant, prim_ids=np.concatenate(ids).astype(np.int64),
                 prim_starts=np.cumsum([0] + [len(i) for i in ids[:-1]]).astype(np.int64))
    for name, a in zip(BUFFER_NAMES, arrays, strict=False):
        data = np.ascontiguousarray(a).tobytes()
        gpu.buffers.append(ctx.buffer(data or b"\0" * 16))
        gpu.parts[name] = len(data)
        gpu.nbytes += len(data)
    gpu.row_bound = row_bound
    if with_bounds:
        gpu.bounds = ctx.buffer(bound_words.tobytes() or b"\0" * 16)
        gpu.nbytes += bound_words.nbytes
    gpu.empty = not (top.nodes if two_level else plants[0].bvh.nodes)
    return gpu


def trace_rays(gpu: GpuBvh, origins, directions, *, any_hit: bool = False, t_min=0.0, t_max=np.inf,
               chunk: int = TRACE_CHUNK, progress=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Trace rays (m, 3) (world float64 origins, directions; t in units of |direction|)
    through the uploaded BVH: the closest hit with t_min < t < t_max, or with ``any_hit``
    the first found. Returns t (m,) float64 (float32 values; inf: none), primitive (m,)
    int64 (plant-local id; -1: none), copy (m,) int64 (0 with one level; -1: none) and the
    face (m,) (cone.glsl's FACE_*). ``progress(done, total)`` after each chunk."""
    origins = np.asarray(origins, np.float64).reshape(-1, 3)
    directions = np.asarray(directions, np.float64).reshape(-1, 3)
    m = len(origins)
    t_lo = np.broadcast_to(np.asarray(t_min, np.float64), (m,))
    t_hi = np.broadcast_to(np.asarray(t_max, np.float64), (m,))
    t = np.full(m, np.inf)
    prim = np.full(m, -1, np.int64)
    copy = np.full(m, -1, np.int64)
    face = np.zeros(m, np.int64)
    if m == 0 or gpu.empty:
        return t, prim, copy, face
    ctx = gpu.ctx
    program = build_compute(ctx, "trace.glsl", gpu.defines())
    chunk = max(int(chunk), _GROUP)
    size = min(chunk, m)
    ray_buf = ctx.buffer(reserve=32 * size)
    hit_buf = ctx.buffer(reserve=16 * size)
    words = np.empty((size, 8), np.float32)
    try:
        gpu.bind()
        ray_buf.bind_to_storage_buffer(0)
        hit_buf.bind_to_storage_buffer(1)
        set_uniforms(program, any_hit=int(bool(any_hit)))
        for start in range(0, m, chunk):
            stop = min(start + chunk, m)
            n = stop - start
            w = words[:n]
            w[:, 0:3] = origins[start:stop] - gpu.origin
            w[:, 3] = t_lo[start:stop]
            w[:, 4:7] = directions[start:stop]
            w[:, 7] = np.minimum(t_hi[start:stop], 3.0e38)
            ray_buf.write(w.tobytes())
            set_uniforms(program, ray_count=n)
            program.run(group_x=(n + _GROUP - 1) // _GROUP)
            out = np.frombuffer(hit_buf.read(size=16 * n), np.float32).reshape(n, 4)
            ids = out.view(np.int32)
            p = ids[:, 1].astype(np.int64)
            slot = np.where(p >= 0, ids[:, 2], 0)
            plant = gpu.slot_plant[slot] if gpu.two_level else np.zeros_like(slot)
            prim[start:stop] = np.where(p >= 0, gpu.primitive_ids(np.maximum(p, 0), plant), -1)
            c = gpu.copy_ids[slot] if gpu.two_level else slot
            copy[start:stop] = np.where(p >= 0, c, -1)
            face[start:stop] = ids[:, 3]
            t[start:stop] = np.where(p >= 0, out[:, 0].astype(np.float64), np.inf)
            if progress is not None:
                progress(stop, m)
    finally:
        ray_buf.release()
        hit_buf.release()
    return t, prim, copy, face


_targets: list = []      # [(target, GpuBvh)]: the last targets uploaded (a scan, a trace batch)
_TARGETS_KEPT = 2


def target_bvh(target, ctx=None) -> GpuBvh:
    """The uploaded BVH of a :class:`~plantgen.geometry.rays.scan.ScanTarget` (its rows and leaf
    triangles, a BVH over its boxes with leaves of GPU_LEAF_SIZE, relative to its root
    box's centre) or of a
    :class:`~plantgen.geometry.rays.scan.SceneTarget` (each distinct plant's, and the top level
    over its copies); the last few targets stay uploaded."""
    for i, (t, gpu) in enumerate(_targets):
        if t is target and (ctx is None or gpu.ctx is ctx):
            _targets.append(_targets.pop(i))
            return gpu
    if ctx is None:
        from .context import gl_context
        ctx = gl_context()
    def plant(t):        # its own tree with the GPU's leaves (the copies' boxes stay: the same root)
        return GpuPlant(t.frusta if t.rows else None, t.triangles, build_bvh(t.lo, t.hi, leaf_size=GPU_LEAF_SIZE))

    if hasattr(target, "targets"):        # a SceneTarget: two levels
        scene = target.bvh
        gpu = upload_bvh(ctx, [plant(t) for t in target.targets], top=scene.tlas, matrices=scene.matrix,
                         copy_plant=scene.plant)
    else:
        gpu = upload_bvh(ctx, [plant(target)])
    _targets.append((target, gpu))
    while len(_targets) > _TARGETS_KEPT:
        _targets.pop(0)[1].release()
    return gpu


def trace_target(target, origins, directions, *, any_hit: bool = False, t_min: float = 0.0, t_max=np.inf,
                 chunk: int = TRACE_CHUNK, progress=None) -> tuple[np.ndarray, np.ndarray]:
    """The GPU's hit of each ray (m, 3) against a ScanTarget or a SceneTarget: t (m,)
    (float32 values; inf: none) and the primitive (m,) (-1: none; a row, or rows + a leaf
    triangle; a scene's as copy · stride + its plant's), closest or any
    (:func:`trace_rays`). The float32 search of :func:`plantgen.trace` and the scan, which
    solve each found primitive again in float64."""
    t, prim, copy, _ = trace_rays(target_bvh(target), origins, directions, any_hit=any_hit, t_min=t_min,
                                  t_max=t_max, chunk=chunk, progress=progress)
    if hasattr(target, "targets"):
        prim = np.where(prim >= 0, copy * target.stride + prim, -1)
    return t, prim
