"""Ray queries on the GPU: a BVH (:mod:`plantgen.geometry.bvh`) and its primitives in
storage buffers, searched by ``shaders/bvh.glsl`` (one compute invocation per ray,
``shaders/trace.glsl``), closest hit or any hit.

Precision: everything the GPU holds is float32 relative to a frame origin formed in
float64 here: row records (:func:`plantgen.gl.records.pack_records`), leaf triangles and
node boxes (rounded outward, :func:`plantgen.geometry.bvh.float32_boxes`, so a float32
box never loses a ray its float64 box keeps). An instanced scene keeps each distinct
plant once, relative to its own box centre, and per copy the map from the frame into the
plant's (its offset formed in float64). The GPU finds the primitive; callers that need
float64 distances solve that one primitive again on the CPU (:mod:`plantgen.trace`, the
scan).

A copy costs :data:`COPY_BYTES` (32) for its map and plant index: the map x -> (x - offset)
as the quaternion u = conj(q) / sqrt(scale) turns it, u·v·conj(u) = turnᵀ·v / scale for
its rotation q and uniform scale (a quaternion times a real turns and scales at once),
where every copy of the scene is a similarity that keeps handedness (the scene format's:
a positive scale and a rotation). A scene with a copy that mirrors, scales unevenly or
shears (possible only through the API, :class:`~plantgen.geometry.instances.PlacedPlants`
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
from ..geometry.bvh import BVH, build_bvh, float32_boxes
from ..geometry.frames import similarity_trs
from ..geometry.instances import similarity_parts
from ..limits import LimitError, hint
from ..tolerances import tol
from .records import RECORD_FLOATS, pack_records
from .shaders import build_compute, set_uniforms

__all__ = ["GpuBvh", "GpuPlant", "upload_bvh", "trace_rays", "trace_target", "target_bvh", "TRACE_CHUNK",
           "BVH_BINDING", "BVH_STACK", "COPY_BYTES", "AFFINE_COPY_BYTES", "copy_words", "GPU_LEAF_SIZE",
           "node_words", "stack_need", "wide_nodes"]

#: Primitives a leaf of a BVH built for the GPU holds at most (the ray tracer's, and the one
#: a scan or a trace uploads; the float64 reference keeps its own): 2 tests about half the
#: primitives of 4 a ray (the forest's eye rays: 5.5 against 12.1) for 13 % more GPU memory,
#: eye and shadow rays 1.1-1.3x faster on llvmpipe; 1 is no faster than 2
#: (docs/benchmarks/rt.md).
GPU_LEAF_SIZE = 2
#: Rays per dispatch of :func:`trace_rays` (a knob: memory against dispatch overhead).
TRACE_CHUNK = 1 << 16
#: First SSBO binding of the BVH's buffers in ``shaders/bvh.glsl`` (6 in all).
BVH_BINDING = 3
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
    plants: int = 0
    copies: int = 0
    empty: bool = False      # no primitive: nothing to trace (the buffers hold a dummy word)
    affine: bool = False     # the copies' maps are full 3x4 maps (not every copy a similarity)
    copy_ids: np.ndarray | None = None   # (copies,) int64: the copy held in each GPU slot

    def defines(self) -> dict:
        return {"TWO_LEVEL": self.two_level, "BVH_AFFINE_COPIES": self.two_level and self.affine}

    def bind(self) -> None:
        for i, buf in enumerate(self.buffers):
            buf.bind_to_storage_buffer(BVH_BINDING + i)

    def release(self) -> None:
        for buf in self.buffers:
            buf.release()
        self.buffers = []


#: Words (vec4) of one node on the GPU: four child boxes by coordinate, their references.
NODE_VEC4 = 7
#: A leaf reference packs its primitive offset above these bits and its count in them.
LEAF_COUNT_BITS = 8
_EMPTY = -1          # the reference of an unused child slot


def wide_nodes(bvh: BVH) -> tuple[np.ndarray, np.ndarray]:
    """The binary BVH collapsed into a 4-wide one, as the GPU walks it: per wide node its
    (up to) four children, the binary node's grandchildren (a child that is a leaf stays
    itself). Returns ``slots`` (w, 4) int64, the binary node in each slot (-1: unused), and
    ``wide`` (w, 4) int64, the wide node an internal slot becomes (-1 for a leaf or an unused
    slot). Wide node 0 is the root; a tree whose root is a leaf gets one wide node holding it.
    Nodes are numbered level by level (every two binary levels one), vectorised."""
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


def node_words(bvh: BVH, origin, slots: np.ndarray, wide: np.ndarray) -> np.ndarray:
    """(w, 28) float32, NODE_VEC4 vec4 a wide node: its children's boxes by coordinate (lo x,
    lo y, lo z, hi x, hi y, hi z of the four slots; float32 rounded outward relative to
    ``origin``), then the four references as int bits: a wide node's index, a leaf's
    -1 - (offset << LEAF_COUNT_BITS | count), -1 for an unused slot."""
    lo, hi = float32_boxes(bvh, origin)
    used = slots >= 0
    s = np.maximum(slots, 0)
    words = np.zeros((len(slots), NODE_VEC4, 4), np.float32)
    for axis in range(3):
        words[:, axis] = np.where(used, lo[s, axis], 0.0)
        words[:, 3 + axis] = np.where(used, hi[s, axis], 0.0)
    first, count = np.asarray(bvh.first, np.int64)[s], np.asarray(bvh.count, np.int64)[s]
    if bvh.nodes and (count.max() >= 1 << LEAF_COUNT_BITS or first.max() >= 1 << (31 - LEAF_COUNT_BITS)):
        raise PlantgenError(f"BVH leaves too large for the GPU's node references (at most "
                            f"{(1 << LEAF_COUNT_BITS) - 1} primitives a leaf, {1 << (31 - LEAF_COUNT_BITS):,} in all)")
    ref = np.where(wide >= 0, wide, -1 - ((first << LEAF_COUNT_BITS) | count))
    words[:, 6] = np.where(used, ref, _EMPTY).astype(np.int32).view(np.float32)
    return words.reshape(len(slots), 4 * NODE_VEC4)


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


def upload_bvh(ctx, plants, origin=None, *, top: BVH | None = None, matrices=None, copy_plant=None,
               max_bytes: int | None = None) -> GpuBvh:
    """Upload ``plants`` (a list of :class:`GpuPlant`) to storage buffers.

    One level (``top`` None): one plant, in the frame of ``origin`` ((3,) float64; default
    the centre of its root box). Two levels: ``top`` a BVH over the copies (copy ids), per
    copy its similarity ``matrices`` (k, 4, 4) from its plant's frame to the world and
    ``copy_plant`` (k,) its plant; ``origin`` the world frame's origin (rays are given
    relative to it). Raises PlantgenError for a tree deeper than the GPU's stack, and a
    LimitError (one line) when the buffers would pass ``max_bytes`` (nothing uploaded).
    """
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
    nodes, prims, rows, tris, offsets = [], [], [], [], []
    counts = np.zeros(4, np.int64)
    for p, c, tree in zip(plants, centres, trees, strict=True):
        offsets.append([*counts, p.rows, 0, 0, 0])
        nodes.append(node_words(p.bvh, c, *tree[1:]))
        prims.append(np.asarray(p.bvh.prims, np.int32))
        rows.append(pack_records(p.frusta, c) if p.rows else np.zeros((0, RECORD_FLOATS), np.float32))
        tris.append(_triangle_words(p.triangles, c))
        counts += [len(nodes[-1]), len(p.bvh.prims), p.rows, len(tris[-1])]
    if two_level:     # the top level's nodes follow the plants' (one node array)
        offsets[0][5] = counts[0]
        nodes.append(node_words(top, origin, *top_tree[1:]))
    arrays = [np.concatenate(nodes), np.concatenate(prims), np.concatenate(rows), np.concatenate(tris),
              np.asarray(offsets, np.int32)]
    copies, affine, copy_ids = 0, False, None
    if two_level:     # the copies in the top level's leaf order: a leaf's `first` is its first copy's slot
        copy_ids = np.asarray(top.prims, np.int64)
        matrices = np.asarray(matrices, np.float64).reshape(-1, 4, 4)
        words, affine = copy_words(matrices[copy_ids], np.asarray(copy_plant)[copy_ids], centres, origin)
        copies = len(words)
        arrays.append(words)
    need = sum(a.nbytes for a in arrays)
    if max_bytes is not None and need > max_bytes:
        raise LimitError(f"the BVH of {len(plants):,} plants and {copies:,} copies needs {need / 2**20:,.0f} MiB on "
                         f"the GPU, over the limit of {max_bytes / 2**20:,.0f} MiB ({hint('render_bytes')})")
    gpu = GpuBvh(ctx, origin, two_level, plants=len(plants), copies=copies, affine=affine, copy_ids=copy_ids)
    for a in arrays:
        data = np.ascontiguousarray(a).tobytes()
        gpu.buffers.append(ctx.buffer(data or b"\0" * 16))
        gpu.nbytes += len(data)
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
            prim[start:stop] = p
            slot = np.where(p >= 0, ids[:, 2], 0)
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
    """The uploaded BVH of a :class:`~plantgen.geometry.scan.ScanTarget` (its rows and leaf
    triangles, a BVH over its boxes with leaves of GPU_LEAF_SIZE, relative to its root
    box's centre) or of a
    :class:`~plantgen.geometry.scan.SceneTarget` (each distinct plant's, and the top level
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
