"""The traversal's cheap reject before a row's test (plantgen.gl.trace.row_bounds,
``bvh_row_near`` in shaders/bvh.glsl) never loses a hit: every point of a solid row (its
relief shell, oblique ends and joint slack included) lies within its bound of the axis
segment, and the GPU finds exactly the hits with the reject that it finds without it, on
the hard cases: sharp bends (oblique ends), cones closing to a point, relief shells,
grazing rays, rays along the axis, 1e4 units from the origin."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from _geometry_helpers import chain_skeleton

from plantgen.geometry.rays.bvh import build_bvh
from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.rays.reference import row_boxes
from plantgen.geometry.skeletons.frusta import Frusta
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.gl import trace
from plantgen.gl.rt import RayTracer
from plantgen.gl.trace import GpuPlant, row_bounds, trace_rays, upload_bvh
from plantgen.settings import RaycastSettings
from plantgen.tolerances import tol

#: Chains: (bends in degrees, joint radii root first, relief shell).
CHAINS = [
    ((80.0, -100.0, 60.0), (0.1, 0.09, 0.07, 0.05, 0.0), 0.0),       # sharp bends, closing to a point
    ((120.0, 30.0), (0.05, 0.05, 0.05, 0.05), 0.02),                  # a knuckle, cylinders, a shell
    ((10.0, -45.0, 90.0, 5.0), (0.2, 0.1, 0.15, 0.02, 0.0, 0.0), 0.03),   # flaring, closing, a shell
    ((), (0.3, 0.0), 0.05),                                           # one cone to a point, thick shell
    ((0.0, 0.0), (0.001, 0.001, 0.001, 0.001), 0.0),                         # a hair
]


def _rows(offset=(0.0, 0.0, 0.0)) -> Frusta:
    """The chains skinned, each 10 units from the last (a ray aimed at one tests little else)."""
    parts = []
    for i, (bends, radii, shell) in enumerate(CHAINS):
        start = np.asarray(offset, np.float64) + (10.0 * i, 0.0, 0.0)
        sk = chain_skeleton(bends, lengths=1.0, radii=radii, start=start, plane_turn_deg=37.0 * i)
        f = skin_skeleton(sk)
        parts.append(replace(f, shell=np.full(len(f), shell)))
    return Frusta.concatenate(parts)


def _in_solid(f: Frusta, row: int, x: np.ndarray, slack: float) -> np.ndarray:
    """Whether points x (m, 3) lie in row ``row``'s solid: the cone grown by its shell
    (r >= 0), between its planes moved out by ``slack``."""
    e = x - f.base[row]
    y = e @ f.axis[row]
    rho = np.linalg.norm(e - y[:, None] * f.axis[row], axis=1)
    r = f.r1[row] + f.shell[row] + f.slope[row] * y
    lo, hi = f.plane_lo[row], f.plane_hi[row]
    return ((rho <= r) & (r >= 0) & (x @ lo[:3] - lo[3] >= -slack) & (x @ hi[:3] - hi[3] <= slack))


def _segment_distance(f: Frusta, row: int, x: np.ndarray) -> np.ndarray:
    e = x - f.base[row]
    s = np.clip(e @ f.axis[row], 0.0, f.length[row])
    return np.linalg.norm(e - s[:, None] * f.axis[row], axis=1)


@pytest.mark.parametrize("offset", [0.0, 1e4])
def test_every_point_of_a_solid_row_lies_within_its_bound(offset):
    f = _rows((offset, -offset, 0.5 * offset))
    origin = f.base[0] + 0.5                     # as pack_records: relative to a frame origin
    bound = row_bounds(f, origin).astype(np.float64)
    assert np.isfinite(bound).all()
    rng = np.random.default_rng(1)
    tight = []
    boxes = row_boxes(f, shell=True)
    for row in range(len(f)):
        slack = tol.joint_slack * 2.0 ** -24 * (np.linalg.norm(f.base[row] - origin) + f.length[row])
        box_lo, box_hi = boxes[0][row], boxes[1][row]
        x = rng.uniform(box_lo, box_hi, size=(20000, 3))
        inside = _in_solid(f, row, x, slack)
        # and the solid's extreme points: the rims where the cone meets its planes
        phi = np.linspace(0.0, 2 * np.pi, 721)
        side = np.cross(f.axis[row], f.ref_dir[row])
        e_r = np.cos(phi)[:, None] * f.ref_dir[row] + np.sin(phi)[:, None] * side
        rims = []
        for plane in (f.plane_lo[row], f.plane_hi[row]):
            gap = plane[3] - plane[:3] @ f.base[row]
            y = (gap - (f.r1[row] + f.shell[row]) * (e_r @ plane[:3])) / (
                plane[:3] @ f.axis[row] + f.slope[row] * (e_r @ plane[:3]))
            r = f.r1[row] + f.shell[row] + f.slope[row] * y
            rims.append((f.base[row] + y[:, None] * f.axis[row] + np.maximum(r, 0.0)[:, None] * e_r)[r >= 0])
        rims = np.concatenate(rims)
        rims = rims[_in_solid(f, row, rims, slack + 1e-9)]
        far = _segment_distance(f, row, np.concatenate([x[inside], rims]))
        assert far.max() <= bound[row], (row, far.max(), bound[row])
        tight.append(far.max() / bound[row])
    assert np.median(tight) > 0.99                # a bound, not a loose one


def test_rows_without_a_finite_bound_are_never_rejected():
    f = _rows()
    flat = f.plane_hi.copy()
    flat[0, :3] = np.cross(f.axis[0], f.ref_dir[0])        # a plane along the axis: no bound
    bound = row_bounds(replace(f, plane_hi=flat), np.zeros(3))
    assert np.isinf(bound[0]) and np.isfinite(bound[1:]).all()
    zero = f.length.copy()
    zero[1] = 0.0
    assert np.isinf(row_bounds(replace(f, length=zero), np.zeros(3))[1])


def _hard_rays(f: Frusta, m: int, seed: int):
    """Rays at the rows: at random points near each row, grazing its skin (tangent to the
    cone, shell included), and nearly along its axis just inside and outside its radius."""
    rng = np.random.default_rng(seed)
    row = rng.integers(0, len(f), m)
    y = rng.uniform(-0.1, 1.1, m) * f.length[row]
    phi = rng.uniform(0.0, 2 * np.pi, m)
    side = np.cross(f.axis[row], f.ref_dir[row])
    e_r = np.cos(phi)[:, None] * f.ref_dir[row] + np.sin(phi)[:, None] * side
    r = np.maximum(f.r1[row] + f.shell[row] * rng.integers(0, 2, m) + f.slope[row] * y, 0.0)
    kind = rng.integers(0, 3, m)
    # 0: at a point within 1.2 radii of the axis; 1: tangent to the skin; 2: along the axis
    radial = np.where(kind == 0, rng.uniform(0.0, 1.2, m), rng.uniform(0.999, 1.001, m)) * r
    p = f.base[row] + y[:, None] * f.axis[row] + radial[:, None] * e_r
    tangent = np.cross(e_r, f.axis[row])
    d = np.where((kind == 0)[:, None], rng.normal(size=(m, 3)),
                 np.where((kind == 1)[:, None], tangent + 0.3 * rng.normal(size=(m, 1)) * f.axis[row],
                          f.axis[row] + 1e-4 * rng.normal(size=(m, 3))))
    d /= np.linalg.norm(d, axis=1)[:, None]
    back = rng.uniform(0.5, 3.0, m)
    return p - back[:, None] * d, d


@pytest.mark.parametrize("offset", [0.0, 1e4])
def test_the_gpu_finds_the_same_hits_with_the_reject_as_without(gl_ctx, offset):
    f = _rows((offset, offset, -offset))
    lo, hi = row_boxes(f, shell=True)
    gpu = upload_bvh(gl_ctx, [GpuPlant(f, None, build_bvh(lo, hi, leaf_size=2))], origin=f.base[0] + 0.3,
                     row_bound=True)
    o, d = _hard_rays(f, 30000, seed=int(offset) + 5)
    try:
        out = {}
        for on in (False, True):
            gpu.row_bound = on
            out[on] = trace_rays(gpu, o, d)
    finally:
        gpu.release()
    (t0, p0, _, face0), (t1, p1, _, face1) = out[False], out[True]
    assert (p0 >= 0).mean() > 0.3
    np.testing.assert_array_equal(p1, p0)
    np.testing.assert_array_equal(face1, face0)
    np.testing.assert_array_equal(t1, t0)


def test_the_bound_is_off_by_default_and_its_bytes_are_counted_where_on(gl_ctx):
    f = _rows()
    lo, hi = row_boxes(f, shell=True)
    plain = upload_bvh(gl_ctx, [GpuPlant(f, None, build_bvh(lo, hi))])
    bounded = upload_bvh(gl_ctx, [GpuPlant(f, None, build_bvh(lo, hi))], row_bound=True)
    try:
        assert trace.ROW_BOUND is False and plain.bounds is None
        assert not plain.defines()["BVH_ROW_BOUND"] and bounded.defines()["BVH_ROW_BOUND"]
        assert bounded.nbytes - plain.nbytes == bounded.bounds.size == trace.ROW_BOUND_BYTES * len(f)
        plain.row_bound = True            # nothing to test without the bounds uploaded
        assert not plain.defines()["BVH_ROW_BOUND"]
    finally:
        plain.release()
        bounded.release()


@pytest.mark.parametrize("chain", range(4))
def test_rt_with_relief_draws_the_same_frame_with_the_reject_as_without(gl_ctx, monkeypatch, chain):
    f = _rows((1e4, 0.0, 1e4))
    lo, hi = row_boxes(f, shell=True)
    mine = (f.base[:, 0] >= f.base[0, 0] + 10.0 * chain - 5.0) & (f.base[:, 0] < f.base[0, 0] + 10.0 * chain + 5.0)
    centre = 0.5 * (lo[mine].min(0) + hi[mine].max(0))
    camera = Camera(tuple(centre + (0.5, 0.3, 2.0)), tuple(centre), fov_y=60.0, width=160, height=120)
    frames = {}
    for on in (False, True):
        monkeypatch.setattr(trace, "ROW_BOUND", on)
        frames[on] = RayTracer(gl_ctx).render(f, camera, settings=RaycastSettings(relief=True))
    assert ("rt.glsl", ("BVH_ROW_BOUND", "RELIEF")) in frames[True].stats.programs
    assert np.isfinite(frames[True].distance).sum() > 500
    np.testing.assert_array_equal(frames[True].distance, frames[False].distance)
    np.testing.assert_array_equal(frames[True].color, frames[False].color)
