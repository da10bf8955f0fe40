"""The cull of a stand's leaves (:mod:`plantgen.geometry.rays.native_cull`): which boxes
(clusters of the other plants' leaf triangles) some ray may meet. A box it leaves out must
hold no primitive whose box the compiled walk's slab test passes, or a plant's light
among the others would change; a stand grown with the cull derives what it derives with
every leaf kept."""

from __future__ import annotations

import numpy as np
import pytest

import plantgen.environment.together as together
import plantgen.pipeline.growing as growing
from plantgen.geometry.rays import native_cull, native_trace
from plantgen.geometry.rays.bvh import slab

pytestmark = pytest.mark.skipif(not native_trace.available(), reason="numba does not run here: the cull then "
                                                                     "keeps every box, which the stand test covers")


def _met(lo, hi, origins, dirs, skip=-1, block=None, group=None):
    n = len(lo)
    block = np.array([0, n]) if block is None else block
    group = np.array([0, len(block) - 1]) if group is None else group
    return native_cull.boxes_met(np.asarray(lo, float), np.asarray(hi, float), block, group,
                                 np.asarray(origins, float), np.asarray(dirs, float), skip=skip)


def test_a_box_a_ray_passes_is_met_and_boxes_beside_behind_or_skipped_are_not():
    lo = np.array([[-1.0, 2, -1], [3, 2, -1], [-1, -3, -1], [-1, 5, -1]])
    hi = lo + 1.0
    up = ([[-0.5, 0, -0.5]], [[0.0, 1, 0]])
    assert _met(lo, hi, *up).tolist() == [True, False, False, True]
    # two groups of two boxes, each box its own block: the first group skipped
    block, group = np.arange(5), np.array([0, 2, 4])
    assert _met(lo, hi, *up, skip=0, block=block, group=group).tolist() == [False, False, False, True]
    assert not _met(lo, hi, np.zeros((0, 3)), np.zeros((0, 3))).any()


def test_a_ray_in_a_face_plane_parallel_to_it_meets_the_box():
    """A ray along y in the plane x = 1: the walk's slab test passes a box of no width in
    x at that plane (its NaN axis is skipped), so the cull must meet a box holding it
    whose face lies in the plane (0 times infinity there too) or beyond it."""
    inner = (np.array([[1.0, 2, 0]]), np.array([[1.0, 3, 1]]))
    ray = np.array([[1.0, 0, 0.5]]), np.array([[0.0, 1, 0]])
    near, far = slab(*inner, ray[0], np.array([[np.inf, 1.0, np.inf]]))      # 1 / d, d = (+0, 1, +0)
    assert near[0] <= far[0] and far[0] > 0                     # the walk's test passes the inner box
    assert _met([[1.0, 2, 0], [0.0, 2, 0]], [[2.0, 3, 1], [1.0, 3, 1]], *ray).tolist() == [True, True]


def test_the_cull_is_never_tighter_than_the_walks_slab_test():
    """Random boxes, each holding an inner box (a face shared now and then), and rays
    with some components exactly 0 starting now and then on a face plane: wherever the
    walk's slab test (the numpy oracle's, NaN rule included) passes an inner box, the
    cull meets its outer box; and it does leave boxes out."""
    rng = np.random.default_rng(7)
    n, m = 400, 300
    lo = rng.uniform(-5, 5, (n, 3))
    hi = lo + rng.uniform(0.01, 2, (n, 3))
    a, b = rng.uniform(0, 1, (2, n, 3))
    in_lo = lo + (hi - lo) * np.minimum(a, b) * (rng.random((n, 3)) < 0.7)
    in_hi = hi - (hi - lo) * (1 - np.maximum(a, b)) * (rng.random((n, 3)) < 0.7)
    origins = rng.uniform(-6, 6, (m, 3))
    dirs = rng.normal(size=(m, 3))
    dirs[rng.random((m, 3)) < 0.3] = 0.0
    dirs[np.all(dirs == 0, axis=1), 1] = 1.0
    on_face = rng.random(m) < 0.3                     # an origin coordinate on an inner box's face plane
    axis, box = rng.integers(0, 3, m), rng.integers(0, n, m)
    origins[on_face, axis[on_face]] = in_lo[box[on_face], axis[on_face]]
    met_any = 0
    for r in range(m):
        with np.errstate(divide="ignore"):
            inv = np.broadcast_to(1.0 / dirs[r], (n, 3))
        near, far = slab(in_lo, in_hi, np.broadcast_to(origins[r], (n, 3)), inv)
        passes = (np.maximum(near, 0.0) <= far) & (far > 0.0)
        met = _met(lo, hi, origins[r:r + 1], dirs[r:r + 1])
        assert not (passes & ~met).any(), f"ray {r}: an inner box passed, its box left out"
        met_any += met.sum()
    assert 0 < met_any < n * m


def test_boxes_moved_by_a_matrix_hold_the_moved_triangles_padded_boxes():
    """Clusters of triangles boxed in the world, culled in a plant's frame (``matrix``):
    wherever the walk's slab test passes a triangle's padded box in the frame (its
    vertices moved as :meth:`Polygons.transformed` moves them, boxed as the scan target
    boxes them), the cull meets its cluster."""
    rng = np.random.default_rng(3)
    t = 600
    world = rng.uniform(-8, 8, (t, 1, 3)) + rng.normal(scale=0.05, size=(t, 3, 3))   # small triangles
    lo, hi = world.min(axis=1), world.max(axis=1)                                    # a cluster a triangle
    angle = 0.7
    m = np.eye(4)
    m[:3, :3] = 1.3 * np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    m[:3, 3] = [3.1, 0.0, -1.7]
    back = np.linalg.inv(m)
    frame = (world.reshape(-1, 3) @ back[:3, :3].T + back[:3, 3]).reshape(t, 3, 3)
    t_lo, t_hi = frame.min(axis=1), frame.max(axis=1)
    pad = 1e-9 * np.maximum(np.abs(t_lo), np.abs(t_hi)).max(axis=1)[:, None] + 1e-12
    t_lo, t_hi = t_lo - pad, t_hi + pad
    origins, dirs = rng.uniform(-6, 6, (200, 3)), rng.normal(size=(200, 3))
    met_any = 0
    for r in range(len(origins)):
        near, far = slab(t_lo, t_hi, np.broadcast_to(origins[r], (t, 3)), np.broadcast_to(1.0 / dirs[r], (t, 3)))
        passes = (np.maximum(near, 0.0) <= far) & (far > 0.0)
        met = native_cull.boxes_met(lo, hi, np.array([0, 8 * (t // 16), t]), np.array([0, 2]), origins[r:r + 1],
                                    dirs[r:r + 1], matrix=back)
        assert not (passes & ~met).any()
        met_any += met.sum()
    assert 0 < met_any < 0.5 * t * len(origins)


def test_a_stand_grown_with_the_cull_derives_what_it_derives_with_every_leaf_kept(tmp_path, monkeypatch):
    scene = tmp_path / "stand.yaml"
    scene.write_text("name: stand\nseed: 5\ngrow: together\ninstances:\n  - grammar: self_organizing\n"
                     "    iterations: 11\n    grid: {count: [3, 2], spacing: [1.6, 1.6], jitter: 0.2}\n")
    seen, kept = [], []
    grow_together, cull = growing.grow_together, native_cull.boxes_met

    def spy(*args, **kwargs):
        out = grow_together(*args, **kwargs)
        seen.append([(s.symbols, s.sym.tobytes(), s.nparam.tobytes(), s.params.tobytes()) for s in out])
        return out

    def counted(*args, **kwargs):
        met = cull(*args, **kwargs)
        kept.append((int(met.sum()), len(met)))
        return met

    monkeypatch.setattr(growing, "grow_together", spy)
    monkeypatch.setattr(native_cull, "boxes_met", counted)
    growing.grow_file(scene)
    assert together.CLUSTER >= 1 and sum(k for k, _ in kept) < 0.8 * sum(n for _, n in kept)   # leaves left out

    def every(lo, hi, block, group, origins, dirs, *, matrix=None, skip=-1, t_min=0.0, box=None):
        met = np.ones(len(lo), bool)
        met[block[group[skip]]:block[group[skip + 1]]] = False
        return met

    monkeypatch.setattr(native_cull, "boxes_met", every)
    growing.grow_file(scene)
    assert len(seen) == 2 and seen[0] == seen[1]
