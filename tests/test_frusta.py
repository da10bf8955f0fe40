"""Skinning (§2): the Frusta contract, joint planes, sharp bends, side branches, seams,
texture frames, normals and bounding pyramids, with physical invariants."""

import dataclasses

import numpy as np
import pytest
from _geometry_helpers import chain_skeleton, random_tree, y_junction

from plantgen.geometry.rays.camera import auto_camera, box_corners, depth_range
from plantgen.geometry.rays.reference import inside_frusta
from plantgen.geometry.rays.stability import surface_samples
from plantgen.geometry.skeletons.frusta import (
    PYRAMID_TRIANGLES,
    Frusta,
    bounding_pyramids,
    frusta_bounds,
    plane_height,
    plane_heights,
    pyramid_volume_ratio,
    seam_mismatch,
    surface_normals,
    surface_uv,
    true_normals,
)
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import lead_forks, skin_skeleton


def _rim_points(f, rows, which, count=16):
    """Points on the lower (0) or upper (1) elliptical cut of each row, (len(rows)*count, 3)."""
    rows = np.repeat(rows, count)
    psi = np.tile(np.linspace(0, 2 * np.pi, count, endpoint=False), len(rows) // count)
    e = np.cos(psi)[:, None] * f.ref_dir[rows] + np.sin(psi)[:, None] * np.cross(f.axis[rows], f.ref_dir[rows])
    y = plane_heights(f, rows, e)[which]
    return rows, f.base[rows] + y[:, None] * f.axis[rows] + (f.r1[rows] + f.slope[rows] * y)[:, None] * e


def test_contract_on_a_random_tree():
    sk = random_tree(300, seed=3)
    f = skin_skeleton(sk)
    assert isinstance(f, Frusta) and len(f) >= len(sk)
    for name in ("base", "axis", "length", "r1", "r2", "plane_lo", "plane_hi", "ref_dir", "u_offset",
                 "twist", "shell", "material", "segment"):
        assert np.all(np.isfinite(getattr(f, name))), name
    assert np.allclose(np.linalg.norm(f.axis, axis=1), 1)
    assert np.allclose(np.linalg.norm(f.plane_lo[:, :3], axis=1), 1)
    assert np.allclose(np.linalg.norm(f.ref_dir, axis=1), 1)
    assert np.abs(np.einsum("ij,ij->i", f.ref_dir, f.axis)).max() < 1e-12
    c = np.flatnonzero(f.parent_row >= 0)
    # shared joint planes, bit for bit; the planes face along the axis
    assert np.array_equal(f.plane_lo[c], f.plane_hi[f.parent_row[c]])
    assert np.all(np.einsum("ij,ij->i", f.plane_lo[:, :3], f.axis) > 0)
    assert np.all(np.einsum("ij,ij->i", f.plane_hi[:, :3], f.axis) > 0)
    assert np.all((f.u_offset >= 0) & (f.u_offset < 1))
    assert set(np.unique(f.segment)) == set(range(len(sk)))
    # the skeleton's continuing joints and one leader per fork (lead_forks)
    assert f.report.joints == int(lead_forks(sk).continues.sum()) > int(sk.continues.sum())
    assert skin_skeleton(sk, lead=False).report.joints == int(sk.continues.sum())


def test_roots_and_tips_are_cut_square_and_capped():
    f = skin_skeleton(chain_skeleton([20, 10], 1.0, [0.1, 0.09, 0.08, 0.0]))
    assert np.allclose(f.plane_lo[0, :3], f.axis[0]) and f.open_lo[0]
    assert np.allclose(f.plane_hi[-1, :3], f.axis[-1]) and f.open_hi[-1]
    assert not f.open_hi[0] and not f.open_lo[1]


@pytest.mark.parametrize("radii", [[0.1, 0.1, 0.1], [0.1, 0.08, 0.05], [0.1, 0.05, 0.05]])
def test_near_collinear_planes_blend_continuously_into_the_perpendicular(radii):
    """The joint normal departs from the parent axis at most linearly in the bend angle:
    no jump at any threshold, including a radius step (where A and B run away)."""
    small = np.concatenate([[0.0], np.logspace(-12, -3, 20)])
    sweep = np.linspace(0.0, 0.3, 1201)

    def deviation(a):
        f = skin_skeleton(chain_skeleton([np.degrees(a)], 1.0, radii))
        return np.linalg.norm(f.plane_hi[0, :3] - f.axis[0])

    dev = np.array([deviation(a) for a in small])
    assert dev[0] < 1e-15
    assert np.all(dev[1:] <= 10.0 * small[1:] + 1e-15)
    # a fine sweep of the bend: the plane moves by small steps only (no threshold jump)
    dev = np.array([deviation(a) for a in sweep])
    assert np.abs(np.diff(dev)).max() < 0.01


def test_sharp_bends_are_detected_split_and_reported():
    sk = chain_skeleton([45, 179, 100], 1.0, [0.1, 0.1, 0.1, 0.1, 0.1])
    f = skin_skeleton(sk, max_bend_deg=120)
    r = f.report
    assert r.sharp_joints == 1 and r.bend_limit == 1 and r.fan_rows >= 179 // 10
    # short segments next to a moderate bend: the planes would cross inside
    g = skin_skeleton(chain_skeleton([80, 80], [1.0, 0.05, 1.0], 0.3))
    assert g.report.planes_crossing + g.report.not_ellipse + g.report.bend_limit == g.report.sharp_joints
    assert g.report.sharp_joints >= 1
    for fr in (f, g):
        c = np.flatnonzero(fr.parent_row >= 0)
        assert np.array_equal(fr.plane_lo[c], fr.plane_hi[fr.parent_row[c]])
        # every row's rows are ordered parent-first
        assert np.all(fr.parent_row < np.arange(len(fr)))


def test_side_branch_starts_inside_its_parent():
    sk = y_junction(50.0)
    f = skin_skeleton(sk)
    branch = np.flatnonzero(f.segment == 2)[0]
    assert f.open_lo[branch] and f.report.side_branches == 1
    assert f.length[branch] > np.linalg.norm(sk.end[2] - sk.start[2])
    # the extended base point lies inside the parent's or the continuing child's solid
    assert inside_frusta(f, f.base[branch][None], rows=np.flatnonzero(f.segment != 2))[0]


@pytest.mark.parametrize("angle, ratio", [(50.0, 0.6), (90.0, 0.8), (80.0, 0.95), (30.0, 0.3)])
def test_side_branch_base_cap_stays_hidden_in_the_trunk(angle, ratio):
    # Thick arms (a saguaro's) must not poke their base disc out of the trunk: every point
    # of the capped base lies inside the parent or the continuing trunk.
    a = np.radians(angle)
    rp = 0.2
    sk = Skeleton(start=[[0, 0, 0], [0, 1, 0], [0, 1, 0]],
                  end=[[0, 1, 0], [0, 2, 0], [np.sin(a), 1 + np.cos(a), 0]],
                  r_start=[rp, rp, ratio * rp], r_end=[rp, rp, 0.8 * ratio * rp],
                  parent=[-1, 0, 0], continues=[False, True, False], material=[0, 0, 0])
    f = skin_skeleton(sk)
    b = np.flatnonzero(f.segment == 2)[0]
    e1 = f.ref_dir[b]
    e2 = np.cross(f.axis[b], e1)
    ang = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    rho = np.linspace(0, 1, 6)[:, None] * 0.999 * f.r1[b]
    disc = f.base[b] + (rho[..., None] * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)).reshape(-1, 3)
    trunk = np.flatnonzero(f.segment != 2)
    assert inside_frusta(f, disc, rows=trunk).all()


def test_seam_fitting_matches_the_minor_axes():
    sk = chain_skeleton([30, 50, 20], [1.0, 0.4, 1.5, 0.7], [0.2, 0.12, 0.11, 0.03, 0.02])
    plain = skin_skeleton(sk, seam_fit=False)
    fitted = skin_skeleton(sk)
    before, after = seam_mismatch(plain), seam_mismatch(fitted)
    assert before.max() > 1e-4                      # real mismatch without fitting
    assert after.max() < 1e-8
    assert fitted.report.seam_mismatch_max_after < 1e-9
    assert plain.report.seam_mismatch_max_after is None
    # fitting only changes the child's base radius at each joint
    assert np.array_equal(plain.r2, fitted.r2)


def test_uv_runs_from_lower_to_upper_plane():
    f = skin_skeleton(chain_skeleton([35, 60], [1, 0.7, 1.2], [0.2, 0.15, 0.12, 0.05]))
    rows = np.arange(len(f))
    for which, expect in ((0, 0.0), (1, 1.0)):
        r, p = _rim_points(f, rows, which)
        _, v = surface_uv(f, r, p)
        assert np.allclose(v, expect, atol=1e-12)
    rng = np.random.default_rng(0)
    r, p = surface_samples(f, 500, rng)
    u, v = surface_uv(f, r, p)
    assert np.all((v > 0) & (v < 1)) and np.all((u >= 0) & (u < 1))


def test_u_is_continuous_across_joints_and_does_not_twist():
    sk = chain_skeleton([25, 40, 15], 1.0, 0.1, plane_turn_deg=70)
    f = skin_skeleton(sk, twist=0.0)
    c = np.flatnonzero(f.parent_row >= 0)
    p = f.parent_row[c]
    # the parent's u = 0 generator meets the shared plane at a point both rows give the same u
    y_u = plane_heights(f, p, f.ref_dir[p])[1]
    point = f.base[p] + y_u[:, None] * f.axis[p] + (f.r1[p] + f.slope[p] * y_u)[:, None] * f.ref_dir[p]
    u_p, v_p = surface_uv(f, p, point)
    u_c, v_c = surface_uv(f, c, point)
    assert np.allclose(v_p, 1) and np.allclose(v_c, 0, atol=1e-9)
    du = (u_p - u_c + 0.5) % 1 - 0.5
    assert np.abs(du).max() < 1e-9
    # straight chain: the rotation-minimising frame does not turn
    g = skin_skeleton(chain_skeleton([0, 0, 0], 1.0, 0.1))
    assert np.allclose(g.ref_dir, g.ref_dir[0]) and np.allclose(g.u_offset, g.u_offset[0])


def test_twist_adds_v_times_theta():
    sk = chain_skeleton([], 1.0, 0.1)
    f0, f1 = skin_skeleton(sk), skin_skeleton(sk, twist=0.25)
    r, p = surface_samples(f0, 100, np.random.default_rng(1))
    u0, v0 = surface_uv(f0, r, p, wrap=False)
    u1, _ = surface_uv(f1, r, p, wrap=False)
    assert np.allclose(u1 - u0, 0.25 * v0)


def test_interpolated_normals_are_continuous_and_close_to_true_ones():
    sk = chain_skeleton([40], 1.0, [0.1, 0.1, 0.1])   # equal radii: exactly matching cuts
    f = skin_skeleton(sk)
    r, p = _rim_points(f, np.array([0]), 1, 32)
    n_parent = surface_normals(f, r, p)
    n_child = surface_normals(f, np.ones_like(r), p)
    assert np.allclose(n_parent, n_child, atol=1e-12)
    rs, ps = surface_samples(f, 300, np.random.default_rng(2))
    ni, nt = surface_normals(f, rs, ps), true_normals(f, rs, ps)
    assert np.allclose(np.linalg.norm(ni, axis=1), 1)
    assert np.all(np.einsum("ij,ij->i", ni, nt) > np.cos(np.radians(25)))


def test_interpolated_normals_on_a_straight_cylinder_are_radial():
    f = skin_skeleton(chain_skeleton([], 2.0, 0.3))
    r, p = surface_samples(f, 200, np.random.default_rng(3))
    assert np.allclose(surface_normals(f, r, p), surface_normals(f, r, p, interpolated=False), atol=1e-12)


@pytest.mark.parametrize("maker", [
    lambda: random_tree(150, seed=5),
    lambda: chain_skeleton([60, 179, 90], [1, 0.3, 1, 1], [0.2, 0.1, 0.3, 0.05, 0.0]),
    lambda: chain_skeleton([10], 1.0, [0.01, 0.5, 0.6]),
])
@pytest.mark.parametrize("with_shell", [False, True])
def test_bounding_pyramids_contain_the_frustum(maker, with_shell):
    f = skin_skeleton(maker(), shell={"bark": 0.3})
    corners = bounding_pyramids(f, shell=with_shell)
    assert corners.shape == (len(f), 8, 3) and PYRAMID_TRIANGLES.shape == (12, 3)
    # sample the outer shell cone (r + shell) when the shell counts
    outer = dataclasses.replace(f, r1=f.r1 + f.shell, r2=f.r2 + f.shell) if with_shell else f
    rows, pts = surface_samples(outer, 4000, np.random.default_rng(7))
    tri = corners[rows][:, PYRAMID_TRIANGLES]             # (m, 12, 3, 3)
    a, b, c = tri[:, :, 0], tri[:, :, 1], tri[:, :, 2]
    outward = np.cross(b - a, c - a)
    side = np.einsum("mti,mti->mt", outward, pts[:, None, :] - a)
    scale = np.maximum(f.r1[rows], f.r2[rows])[:, None] + f.length[rows, None]
    # inside every face's half-space (faces of a convex-enough hexahedron)
    assert np.all(side <= 1e-9 * scale * np.linalg.norm(outward, axis=2))


def test_bounding_pyramids_stay_tight():
    f = skin_skeleton(random_tree(300, seed=2))
    ratio = pyramid_volume_ratio(f, shell=False)
    assert 4 / np.pi - 1e-6 <= np.median(ratio) < 1.6


def test_radius_steps_are_modelled_not_fitted():
    start = np.array([[0, 0, 0], [0, 1, 0.0]])
    end = np.array([[0, 1, 0], [0.3, 2, 0.0]])
    from plantgen.geometry.skeletons.skeleton import Skeleton

    sk = Skeleton(start, end, [0.5, 0.2], [0.5, 0.15], [-1, 0], [False, True], [0, 0])
    f = skin_skeleton(sk, seam_fit=True)
    assert f.report.step_joints == 1
    assert f.r1[1] == 0.2          # the step stays as modelled
    # still watertight from the inside of the thinner segment outwards
    from plantgen.geometry.rays.reference import intersect_frusta
    from plantgen.geometry.rays.stability import medial_axis_rays

    o, d = medial_axis_rays(f, 500, seed=2)
    assert intersect_frusta(f, o, d).hit.all()


# ---------------------------------------------------------------------------- the frozen contract
def test_frusta_are_frozen_with_open_ends_set_at_construction():
    f = skin_skeleton(y_junction(40.0))
    with pytest.raises(dataclasses.FrozenInstanceError):
        f.parent_row = np.zeros(len(f), np.int64)
    assert np.array_equal(f.open_lo, f.parent_row < 0)
    continued = np.zeros(len(f), bool)
    continued[f.parent_row[f.parent_row >= 0]] = True
    assert np.array_equal(f.open_hi, ~continued)
    # a changed copy derives its ends again
    g = dataclasses.replace(f, parent_row=np.full(len(f), -1))
    assert g.open_lo.all() and g.open_hi.all()
    with pytest.raises(ValueError, match="parent_row"):
        dataclasses.replace(f, parent_row=[0])


def test_concatenate_and_subset_keep_chains_and_materials():
    a = skin_skeleton(chain_skeleton([20, 30], 1.0, 0.1))
    b = skin_skeleton(chain_skeleton([10], 1.0, 0.2, start=(3.0, 0, 0), material_names=("leaf",)))
    both = Frusta.concatenate([a, b])
    assert len(both) == len(a) + len(b) and both.material_names == ("bark", "leaf")
    assert both.parent_row.tolist() == a.parent_row.tolist() + [p + len(a) if p >= 0 else -1
                                                                 for p in b.parent_row]
    assert np.array_equal(both.material, [0] * len(a) + [1] * len(b))
    assert np.array_equal(both.plane_lo[len(a):], b.plane_lo)
    tail = both.subset(np.arange(len(a), len(both)))
    assert np.array_equal(tail.parent_row, b.parent_row) and np.array_equal(tail.base, b.base)
    assert np.array_equal(both.chain_position, np.concatenate([a.chain_position, b.chain_position]))
    assert len(Frusta.concatenate([])) == 0


def test_chain_position_counts_the_rows_before_each_row():
    f = skin_skeleton(chain_skeleton([20, 30, 10], 1.0, 0.1))
    assert f.chain_position.tolist() == list(range(len(f)))


def test_knuckle_fan_rows_have_no_length():
    f = skin_skeleton(chain_skeleton([150], 1.0, 0.1))
    assert f.report.fan_rows > 0
    assert (~f.has_length).sum() == f.report.fan_rows
    assert set(f.segment[~f.has_length]) == {1}


def test_plane_height_puts_the_generator_point_on_the_plane():
    f = skin_skeleton(random_tree(60, seed=8))
    rows, _ = surface_samples(f, 500, np.random.default_rng(4))
    psi = np.random.default_rng(5).uniform(0, 2 * np.pi, len(rows))
    e = np.cos(psi)[:, None] * f.ref_dir[rows] + np.sin(psi)[:, None] * f.side_dir[rows]
    for which, plane in enumerate((f.plane_lo[rows], f.plane_hi[rows])):
        y = plane_heights(f, rows, e)[which]
        k, n = f.slope[rows], plane[:, :3]
        gap = plane[:, 3] - np.einsum("ij,ij->i", n, f.base[rows])
        y2, rise = plane_height(gap, np.einsum("ij,ij->i", n, f.axis[rows]), np.einsum("ij,ij->i", n, e),
                                f.r1[rows], k)
        np.testing.assert_allclose(y, y2, rtol=1e-12, atol=1e-12)
        p = f.base[rows] + y[:, None] * f.axis[rows] + (f.r1[rows] + k * y)[:, None] * e
        assert np.abs(np.einsum("ij,ij->i", n, p) - plane[:, 3]).max() < 1e-12
        assert np.all(rise > 0)     # every generator runs through the plane, upwards


@pytest.mark.parametrize("direction", [(0.35, 0.25, 1.0), (0.0, 1.0, 1e-3), (1.0, -0.3, 0.0)])
def test_auto_camera_frames_every_frustum_inside_the_viewport(direction):
    f = skin_skeleton(random_tree(120, seed=6))
    camera = auto_camera(f, 160, 90, direction=direction, fill=0.9)
    right, up, fwd = camera.basis()
    rows, pts = surface_samples(f, 3000, np.random.default_rng(3))
    rel = pts - np.asarray(camera.eye)
    z = rel @ fwd
    tan_y = np.tan(np.radians(camera.fov_y) / 2)
    x_ndc = (rel @ right) / z / (tan_y * camera.aspect)
    y_ndc = (rel @ up) / z / tan_y
    assert np.all(z > 0) and np.abs(x_ndc).max() <= 0.9 + 1e-9 and np.abs(y_ndc).max() <= 0.9 + 1e-9
    # and it is tight: the model reaches the edge of the allowed part on some side
    assert max(np.abs(x_ndc).max(), np.abs(y_ndc).max()) > 0.75
    near, far = depth_range([box_corners(frusta_bounds(f))], np.asarray(camera.eye), fwd)
    assert 0 < near < z.min() and far > z.max()


def test_texture_slots_are_checked_where_frusta_are_made():
    # (slot, slots) must name a slot that exists and fit the record's 7-bit fields
    from plantgen.geometry.skeletons.frusta import MAX_V_SLOTS

    f = skin_skeleton(Skeleton(np.zeros((1, 3)), np.array([[0.0, 1.0, 0.0]]), np.array([0.1]), np.array([0.1]),
                               np.array([-1]), np.array([False]), np.zeros(1, int), ("bark",)))
    assert f.v_part.tolist() == [[0, 1]]
    for bad in ([[1, 1]], [[-1, 2]], [[0, MAX_V_SLOTS + 1]]):
        with pytest.raises(ValueError, match="v_part"):
            dataclasses.replace(f, v_part=np.array(bad))
    assert dataclasses.replace(f, v_part=np.array([[MAX_V_SLOTS - 1, MAX_V_SLOTS]])).v_part[0, 0] == MAX_V_SLOTS - 1


def test_the_paper_seam_figures_are_worked_out_when_read_and_bounds_are_kept():
    """The report's 'before' seam figures (the paper's planes on the skeleton's radii) are
    worked out from the skeleton when first read, and kept; they do not depend on how the
    seams were then cut. A Frusta's box is worked out once and handed out as a copy."""
    sk = random_tree(500, seed=9)
    fitted, plain = skin_skeleton(sk), skin_skeleton(sk, seam_fit=False)
    assert callable(fitted.report._paper_seams)              # not worked out by skinning
    assert fitted.report.seam_mismatch_max_before == plain.report.seam_mismatch_max_before > 0
    assert fitted.report.seam_mismatch_mean_before == plain.report.seam_mismatch_mean_before > 0
    assert not callable(fitted.report._paper_seams)          # kept once read
    box = frusta_bounds(fitted)
    box[0] = 1e9                                             # the caller's copy
    again = frusta_bounds(fitted)
    assert again.tobytes() == frusta_bounds(dataclasses.replace(fitted)).tobytes()
    assert (again[0] < 1e9).all()


def test_skinning_without_texture_leaves_u_offsets_zero_and_every_other_number_as_it_is():
    """``texture=False`` (a light's target, which reads no texture coordinate): the same
    rows, every array the same, but ``u_offset``, all zero; a tree with knuckle fans and
    side branches among its rows."""
    from plantgen.geometry.skeletons.frusta import ROW_FIELDS

    skel = random_tree(120, seed=6, max_bend_deg=150.0)
    full, bare = skin_skeleton(skel), skin_skeleton(skel, texture=False)
    assert len(full) > len(skel)                              # fan rows among them
    assert (full.u_offset != 0).any() and not bare.u_offset.any()
    for name in ROW_FIELDS:
        if name != "u_offset":
            assert np.array_equal(getattr(full, name), getattr(bare, name)), name
    assert np.array_equal(full.open_lo, bare.open_lo) and np.array_equal(full.open_hi, bare.open_hi)
