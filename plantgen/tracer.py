"""Ray queries against a model: :func:`trace` casts rays of your own (light interception,
visibility, sensors) at the exact frusta and leaf triangles that ``plantgen scan`` and
the renderers see, through one bounding volume hierarchy (:mod:`plantgen.geometry.rays.bvh`).

``device="cpu"`` (``precision="float64"``) is the CPU reference: the BVH walked by
compiled, multi-threaded code (:mod:`plantgen.geometry.rays.native_trace`; by numpy where
numba does not run), every candidate tested with the reference's exact ray-cone
intersection (clipped by the cutting planes, open ends capped) and the scan's
leaf-triangle test, all in float64.
``device="gl"`` (``precision="float32"``) walks the BVH on the GPU (:mod:`plantgen.gl.trace`) to find the
primitive, then solves that primitive again in float64 (the scan's rule), so distances
are the reference's wherever the two find the same primitive.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import PlantgenError
from .geometry.rays.reference import Hits, PairTester, shade_hits
from .geometry.rays.scan import PART_NAMES, ScanTarget, SceneTarget, scan_target, scene_target
from .geometry.skeletons.skeleton import Skeleton
from .geometry.vec import cross, dot
from .limits import Limits
from .limits import limits as default_limits

__all__ = ["DEVICES", "PRECISIONS", "TraceError", "TraceResult", "trace", "trace_target"]

#: How :func:`trace` may walk the BVH.
PRECISIONS = ("float64", "float32")
#: Where :func:`trace` walks it: the compiled float64 CPU traversal, the GPU's float32
#: one (each hit solved again in float64), or the GPU where a hardware one exists.
DEVICES = ("cpu", "gl", "auto")


class TraceError(PlantgenError, ValueError):
    """Rays or a model that :func:`trace` cannot trace."""


@dataclass(frozen=True, eq=False)
class TraceResult:
    """What each ray hit; arrays of the rays' shape (``origins.shape[:-1]``).

    ==============  ============  ============================================================
    ``t``           f8            distance to the hit in units of the ray's direction's length
                                  (inf: a miss)
    ``hit``         bool          the ray hit something in (t_min, t_max)
    ``primitive``   i8            the primitive hit: a frustum row, or rows + a leaf triangle
                                  (-1: none)
    ``plant``       i8            the plant (a scene's instance; 0 for one plant; -1: none)
    ``part``        i1            index into ``part_names`` (stem, branch, leaf; -1: none)
    ``segment``     i8            the skeleton segment (a leaf: the one it hangs from; -1)
    ``leaf``        i8            the leaf polygon (-1 for wood and misses)
    ``normal``      f8 (..., 3)   the unit surface normal at the hit, world space, facing
                                  against the ray (0 for a miss)
    ==============  ============  ============================================================
    """

    t: np.ndarray
    hit: np.ndarray
    primitive: np.ndarray
    plant: np.ndarray
    part: np.ndarray
    segment: np.ndarray
    leaf: np.ndarray
    normal: np.ndarray
    part_names: tuple = PART_NAMES

    def __len__(self) -> int:
        return int(self.t.size)


def _rays(origins, directions, limits: Limits) -> tuple[np.ndarray, np.ndarray, tuple]:
    try:
        O = np.asarray(origins, dtype=np.float64)
        D = np.asarray(directions, dtype=np.float64)
    except (TypeError, ValueError):
        raise TraceError("trace needs origins and directions as arrays of numbers of shape (..., 3)") from None
    if O.ndim == 0 or O.shape[-1] != 3 or D.ndim == 0 or D.shape[-1] != 3:
        raise TraceError(f"trace needs origins and directions of shape (..., 3), got {O.shape} and {D.shape}")
    try:
        O, D = np.broadcast_arrays(O, D)
    except ValueError:
        raise TraceError(f"trace: origins {O.shape} and directions {D.shape} do not broadcast together") from None
    shape = O.shape[:-1]
    O, D = O.reshape(-1, 3), D.reshape(-1, 3)
    limits.check("scan_rays", len(O), "the rays given to trace")
    if not np.isfinite(O).all():
        raise TraceError(f"trace needs finite origins, {int((~np.isfinite(O).all(axis=1)).sum())} are not")
    if not np.isfinite(D).all():
        raise TraceError(f"trace needs finite directions, {int((~np.isfinite(D).all(axis=1)).sum())} are not")
    zero = ~(dot(D, D) > 0)
    if zero.any():
        raise TraceError(f"trace needs non-zero directions, {int(zero.sum())} are zero (the first: ray "
                         f"{int(np.flatnonzero(zero)[0])})")
    return np.ascontiguousarray(O), np.ascontiguousarray(D), shape


def _target(model, limits: Limits, seed=None) -> ScanTarget:
    """The primitives and labels of ``model``."""
    if isinstance(model, (ScanTarget, SceneTarget)):
        return model
    leaves = None
    if isinstance(model, tuple) and len(model) == 2 and isinstance(model[0], Skeleton):
        model, leaves = model
    if isinstance(model, Skeleton):
        return scan_target(model, leaves)
    from .pipeline import GrowResult, grow_file, model_leaves, skin_model

    if isinstance(model, (str, Path)):
        model = grow_file(model, seed=seed, limits=limits)
    if not isinstance(model, GrowResult):
        raise TraceError("trace's model must be a grammar or scene (a path or a shipped name), a grown model, a "
                         f"Skeleton or (Skeleton, leaves), or a ScanTarget; got {type(model).__name__}")
    if model.scene is not None:                          # each distinct plant once: two levels
        return scene_target(model.scene.plants())
    return scan_target(model.skeleton, model_leaves(model), frusta=skin_model(model))


def _gpu_primitives(target: ScanTarget, O, D, any_hit: bool, t_min: float, t_max: float):
    """The float32 GPU path's (t, primitive): :func:`plantgen.gl.trace.trace_target`
    (``(target, origins, dirs, *, any_hit, t_min, t_max) -> (t (m,), primitive (m,))``)
    where that exists."""
    try:
        from .gl import trace as gl_trace
    except ImportError:
        gl_trace = None
    find = getattr(gl_trace, "trace_target", None)
    if find is None:
        raise TraceError("precision='float32' needs the GPU traversal (plantgen.gl.trace.trace_target), which is "
                         "not available yet: use precision='float64'")
    return find(target, O, D, any_hit=any_hit, t_min=t_min, t_max=t_max)


def _device(device: str | None, precision: str) -> str:
    """"cpu" or "gl": ``device`` ("auto": the GPU where a hardware GL context exists,
    :func:`plantgen.gl.context.hardware_gl`), or by ``precision`` where it is None."""
    if precision not in PRECISIONS:
        raise TraceError(f"trace precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
    if device is None:
        return "gl" if precision == "float32" else "cpu"
    if device not in DEVICES:
        raise TraceError(f"trace device must be one of {', '.join(DEVICES)}, got {device!r}")
    if device == "auto":
        from .gl.context import hardware_gl

        device = "gl" if hardware_gl() else "cpu"
    if device == "cpu" and precision == "float32":
        raise TraceError("trace precision='float32' is the GPU's traversal: use device='gl' (or 'auto')")
    return device


def _normals(target, prim, O, D, t) -> np.ndarray:
    """Unit normals (k, 3) at hits (k,) of primitive ``prim``, facing against the rays."""
    if isinstance(target, SceneTarget):                 # in each copy's frame, turned back to the world
        copy, plant, local = target.split(prim)
        normal = np.zeros((len(prim), 3))
        for k in np.unique(plant):
            sel = np.flatnonzero(plant == k)
            o, d = target.bvh.rays_to_copies(copy[sel], O[sel], D[sel])
            n = _normals(target.targets[k], local[sel], o, d, t[sel])
            normal[sel] = np.einsum("kij,kj->ki", target.bvh.matrix[copy[sel], :3, :3], n)
        return _facing(normal, D)
    normal = np.zeros((len(prim), 3))
    wood = prim < target.rows
    if wood.any():
        rows = prim[wood]
        _, cap = PairTester(target.frusta)(rows, O[wood], D[wood])
        point = O[wood] + t[wood, None] * D[wood]
        hits = Hits(hit=np.ones(len(rows), bool), t=t[wood], row=rows, segment=target.frusta.segment[rows],
                    point=point, cap=cap)
        normal[wood] = shade_hits(target.frusta, hits, interpolated=False)[2]
    if (~wood).any():
        _, e1, e2, _ = (a[prim[~wood] - target.rows] for a in target.triangle_edges)
        normal[~wood] = cross(e1, e2)
    return _facing(normal, D)


def _facing(normal, D) -> np.ndarray:
    """Normals made unit and turned to face against the rays D."""
    length = np.sqrt(dot(normal, normal))
    normal = normal / np.where(length > 0, length, 1.0)[:, None]
    return normal * np.where(dot(normal, D) > 0, -1.0, 1.0)[:, None]


def trace_target(target: ScanTarget | SceneTarget, origins, directions, *, any_hit: bool = False,
                 precision: str = "float64", t_min: float = 0.0, t_max: float = np.inf,
                 limits: Limits | None = None, device: str | None = None) -> TraceResult:
    """:func:`trace` against a :class:`~plantgen.geometry.rays.scan.ScanTarget` or
    :class:`~plantgen.geometry.rays.scan.SceneTarget` already made (its BVH is built on the
    first call and kept)."""
    limits = limits or default_limits
    O, D, shape = _rays(origins, directions, limits)
    device = _device(device, precision)
    t_min, t_max = float(t_min), float(t_max)
    if not (np.isfinite(t_min) and t_min >= 0 and t_max > t_min):
        raise TraceError(f"trace needs 0 <= t_min < t_max with t_min finite, got t_min={t_min:g}, t_max={t_max:g}")
    m = len(O)
    t, prim = np.full(m, np.inf), np.full(m, -1, np.int64)
    if m and len(target):
        if device == "cpu":
            t, prim = target.first_hits(O, D, any_hit=any_hit, t_min=t_min, t_max=t_max)
        else:
            t, prim = (np.asarray(a) for a in _gpu_primitives(target, O, D, any_hit, t_min, t_max))
            t, prim = t.astype(np.float64).copy(), prim.astype(np.int64).copy()
            found = np.flatnonzero(prim >= 0)
            exact = target.hit_distance(prim[found], O[found], D[found], t_min=t_min)   # solved again in float64
            again = np.isfinite(exact) & (exact < t_max)
            t[found[again]] = exact[again]
    hit = prim >= 0
    out = {k: np.full(m, -1, np.int64) for k in ("plant", "segment", "leaf")}
    part = np.full(m, -1, np.int8)
    normal = np.zeros((m, 3))
    if hit.any():
        labels = target.primitive_labels(prim[hit])
        for k in out:
            out[k][hit] = labels[k]
        part[hit] = labels["part"]
        normal[hit] = _normals(target, prim[hit], O[hit], D[hit], t[hit])
    return TraceResult(t.reshape(shape), hit.reshape(shape), prim.reshape(shape), out["plant"].reshape(shape),
                       part.reshape(shape), out["segment"].reshape(shape), out["leaf"].reshape(shape),
                       normal.reshape(shape + (3,)))


def trace(model, origins, directions, *, any_hit: bool = False, precision: str = "float64", t_min: float = 0.0,
          t_max: float = np.inf, seed: int | None = None, limits: Limits | None = None,
          device: str | None = None) -> TraceResult:
    """Cast rays at a model; per ray the closest hit (or, with ``any_hit``, whether it hits
    anything: a shadow or visibility query, which stops at the first hit it finds).

    ``model``: a grammar or scene (a path, or a shipped name such as ``"pine"``, grown with
    ``seed``), a grown model (:func:`plantgen.pipeline.grow_file`), a
    :class:`~plantgen.Skeleton` or a (Skeleton, leaf Polygons) pair, or a
    :class:`~plantgen.geometry.rays.scan.ScanTarget` or
    :class:`~plantgen.geometry.rays.scan.SceneTarget` (reuse one to trace many batches: its BVH
    is built once). A scene is traced through two levels: each distinct plant once, the
    rays moved into each copy's frame in float64; its ``primitive`` is then
    ``copy · target.stride + the plant's primitive``, its labels those of the merged scene.
    ``origins``, ``directions``: arrays of shape (..., 3) (broadcast
    together; directions need not be unit, t is in units of their length). Hits count
    where ``t_min < t < t_max``. ``device``: "cpu" (the compiled float64 traversal,
    :mod:`plantgen.geometry.rays.native_trace`; the numpy one where numba does not run),
    "gl" (the GPU's float32 traversal, each hit's t solved again in float64) or "auto"
    (the GPU where a hardware one exists, else the CPU); left out, ``precision`` decides:
    "float64" the CPU, "float32" the GPU. Returns a :class:`TraceResult`.

    Bad rays (wrong shapes, non-finite numbers, zero directions) and more rays than the
    limit ``scan_rays`` allows raise a :class:`~plantgen.errors.PlantgenError` with a
    one-line message.

    Example::

        import numpy as np, plantgen
        sun = np.array([0.3, -1.0, 0.2])
        grid = np.stack(np.meshgrid(np.linspace(-2, 2, 200), [10.0], np.linspace(-2, 2, 200)), -1)
        hits = plantgen.trace("pine", grid, sun, any_hit=True)
        print("light intercepted:", hits.hit.mean())
    """
    limits = limits or default_limits
    _rays(origins, directions, limits)                    # refuse bad rays before growing anything
    _device(device if device != "auto" else None, precision)  # ... and bad choices
    return trace_target(_target(model, limits, seed), origins, directions, any_hit=any_hit, precision=precision,
                        t_min=t_min, t_max=t_max, limits=limits, device=device)
