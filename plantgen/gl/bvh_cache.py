"""The BVH of a model on the GPU, built and uploaded once per model (and eye): what the
ray tracer (:mod:`plantgen.gl.rt`) traces every pixel's ray through, and what the ray
caster's sky light (the ``sky`` effect, ``shaders/sky_light.glsl``) traces its rays
through. :class:`BvhCache` is a mixin of :class:`~plantgen.gl.raycast.Raycaster` (the ray
tracer's base): the rows (Frusta, or a PlacedPlants with two levels) and the leaves'
triangles, built with :func:`~plantgen.geometry.rays.bvh.build_bvh` (refitted for an
animation's next frame with ``refit``) and uploaded by :func:`~plantgen.gl.trace.upload_bvh`.
"""

from __future__ import annotations

import time

import numpy as np

from ..geometry.rays.bvh import TOP_LEAF_SIZE, build_bvh, build_scene_bvh, copy_boxes, refit_bvh
from ..geometry.rays.instances import PlacedPlants
from ..geometry.rays.reference import row_boxes
from .trace import GPU_LEAF_SIZE, GpuPlant, upload_bvh

__all__ = ["BvhCache", "leaf_triangles"]


def leaf_triangles(leaves) -> np.ndarray:
    """(t, 3, 3) float64 world triangles of a Polygons (none: (0, 3, 3))."""
    if leaves is None or not len(leaves.triangles):
        return np.zeros((0, 3, 3))
    return np.asarray(leaves.vertices, np.float64)[np.asarray(leaves.triangles)]


def _triangle_boxes(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boxes of triangles padded for rounding (as the scan's)."""
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    pad = 1e-9 * np.maximum(np.abs(lo), np.abs(hi)).max(axis=1, keepdims=True) + 1e-12
    return lo - pad, hi + pad


class BvhCache:
    """The GPU BVH of the last model drawn (a mixin: the renderer has ``ctx`` and
    ``limits``). ``leaf_size``, ``method``: the build's knobs; ``refit``: rows (Frusta) as
    many as the last ones refit the BVH instead of building another."""

    leaf_size: int = GPU_LEAF_SIZE
    method: str = "lbvh"
    refit: bool = False

    def _init_bvh(self) -> None:
        self.refits = 0          # BVHs refitted (not built) so far
        self._built = None       # (model, leaves, plants, top, matrices, copy_plant)
        self._gpu = None         # (model, leaves, eye, GpuBvh)
        #: milliseconds of the last BVH build (0 when kept) and upload
        self.last_build_ms = 0.0
        self.last_upload_ms = 0.0

    def _release_bvh(self) -> None:
        if self._gpu is not None:
            self._gpu[3].release()
            self._gpu = None

    # ------------------------------------------------------------------ the BVH
    def _build(self, model, leaves):
        """The BVH of ``model`` (Frusta or PlacedPlants) and ``leaves`` (world Polygons or
        None), built once per pair of objects."""
        if self._built is not None and self._built[0] is model and self._built[1] is leaves:
            self.last_build_ms = 0.0
            return self._built[2:]
        t0 = time.perf_counter()
        tri = leaf_triangles(leaves)
        build = {"leaf_size": self.leaf_size, "method": self.method}
        if isinstance(model, PlacedPlants):
            scene = build_scene_bvh(model, **build)
            plants = [GpuPlant(p.frusta, None, b) for p, b in zip(model.plants, scene.blas, strict=True)]
            top, matrices, copy_plant = scene.tlas, scene.matrix, scene.plant
            if len(tri):      # the leaves: one more plant, placed once where they are
                t_lo, t_hi = _triangle_boxes(tri)
                bvh = build_bvh(t_lo, t_hi, **build)
                plants.append(GpuPlant(None, tri, bvh))
                c_lo, c_hi = copy_boxes(bvh.lo[0], bvh.hi[0], np.eye(4)[None])
                top = build_bvh(np.concatenate([scene.copy_lo, c_lo]), np.concatenate([scene.copy_hi, c_hi]),
                                leaf_size=TOP_LEAF_SIZE, method=self.method)
                matrices = np.concatenate([matrices, np.eye(4)[None]])
                copy_plant = np.r_[copy_plant, len(plants) - 1]
        else:
            lo, hi = row_boxes(model, shell=True) if len(model) else (np.zeros((0, 3)), np.zeros((0, 3)))
            if len(tri):
                t_lo, t_hi = _triangle_boxes(tri)
                lo, hi = np.concatenate([lo, t_lo]), np.concatenate([hi, t_hi])
            last = self._built[2][0] if self._built is not None and self._built[3] is None else None
            if self.refit and last is not None and last.rows == len(model) and len(last.bvh.prims) == len(lo):
                bvh = refit_bvh(last.bvh, lo, hi)        # an animation's next frame: the same rows moved
                self.refits += 1
            else:
                bvh = build_bvh(lo, hi, **build)
            plants = [GpuPlant(model if len(model) else None, tri, bvh)]
            top = matrices = copy_plant = None
        self._built = (model, leaves, plants, top, matrices, copy_plant)
        self.last_build_ms = (time.perf_counter() - t0) * 1e3
        return self._built[2:]

    def gpu_bvh(self, model, leaves, eye):
        """The uploaded BVH of ``model`` and ``leaves`` relative to ``eye`` (kept while all
        three stay the same)."""
        eye = np.asarray(eye, np.float64)
        g = self._gpu
        if g is not None and g[0] is model and g[1] is leaves and np.array_equal(g[2], eye):
            self.last_build_ms = self.last_upload_ms = 0.0
            return g[3]
        plants, top, matrices, copy_plant = self._build(model, leaves)
        t0 = time.perf_counter()
        if g is not None:
            g[3].release()
            self._gpu = None
        gpu = upload_bvh(self.ctx, plants, eye, top=top, matrices=matrices, copy_plant=copy_plant,
                         max_bytes=self.limits.max_render_bytes)
        self._gpu = (model, leaves, eye.copy(), gpu)
        self.last_upload_ms = (time.perf_counter() - t0) * 1e3
        return gpu

