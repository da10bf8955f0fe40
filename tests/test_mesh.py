"""Geometric subdivision (issue 5): counts, exact surface, (6)-(8), watertight chains, relief."""

from __future__ import annotations

from itertools import pairwise
from types import SimpleNamespace

import numpy as np
import pytest

from plantgen.geometry.meshes.mesh import (
    bands_along,
    columns_around,
    lateral_triangles_per_row,
    tessellate,
    triangle_count,
)
from plantgen.geometry.skeletons.frusta import (
    ROW_FIELDS,
    Frusta,
    parent_rows_from_planes,
    relief_scale,
    surface_normals,
    surface_uv,
)
from plantgen.geometry.skeletons.skin import skin_skeleton


# ---------------------------------------------------------------------------- builders
def chain_frusta(points, radii, *, twist=0.0, u_offset=0.0, shell=0.0, material=None,
                 material_names=("bark",)):
    """Frusta rows (the Frusta contract) of one continuing chain through ``points``.

    Joint planes are the bisector planes of the two axes, which is exactly the paper's
    cutting plane (5) where both radii at the joint are equal; ends are cut square.
    """
    p = np.asarray(points, dtype=float)
    r = np.broadcast_to(np.asarray(radii, dtype=float), (len(p),)).copy()
    n = len(p) - 1
    axis = p[1:] - p[:-1]
    length = np.linalg.norm(axis, axis=1)
    axis /= length[:, None]
    normals = np.empty((n + 1, 3))
    normals[0], normals[-1] = axis[0], axis[-1]
    bisector = axis[:-1] + axis[1:]
    normals[1:-1] = bisector / np.linalg.norm(bisector, axis=1, keepdims=True)
    planes = np.concatenate([normals, np.einsum("ij,ij->i", normals, p)[:, None]], axis=1)
    # Parallel-transported reference direction (a test fixture; one row per joint).
    ref = np.empty((n, 3))
    t = np.array([1.0, 0.0, 0.0]) if abs(axis[0, 0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    for i in range(n):
        t = t - axis[i] * (t @ axis[i])
        t /= np.linalg.norm(t)
        ref[i] = t
    return Frusta(
        base=p[:-1].copy(), axis=axis, length=length, r1=r[:-1].copy(), r2=r[1:].copy(),
        plane_lo=planes[:-1].copy(), plane_hi=planes[1:].copy(), ref_dir=ref,
        u_offset=np.full(n, float(u_offset)), twist=np.full(n, float(twist)),
        material=np.zeros(n, np.int32) if material is None else np.asarray(material, np.int32),
        shell=np.full(n, float(shell)), segment=np.arange(n), material_names=material_names,
        parent_row=np.arange(n) - 1)


def concat_frusta(*parts):
    offsets = np.cumsum([0] + [len(p) for p in parts[:-1]])
    parent = np.concatenate([np.where(p.parent_row >= 0, p.parent_row + o, -1)
                             for p, o in zip(parts, offsets, strict=True)])
    return Frusta(**{k: np.concatenate([getattr(p, k) for p in parts]) for k in ROW_FIELDS},
                  material_names=parts[0].material_names, parent_row=parent)


BENT = [[0, 0, 0], [0, 1, 0], [0.5, 2, 0], [0.5, 3, 0.7], [0.2, 3.5, 1.5]]


def lateral_vertex_rows(mesh, frusta):
    """(V_lateral,) row of each lateral vertex that the row itself owns (rings it computed)."""
    m = mesh.level
    ring = columns_around(m) + 1
    parent = frusta.parent_row
    own_rings = bands_along(m) + (parent < 0)
    rows = np.repeat(np.arange(len(frusta.length)), own_rings * ring)
    first_ring = np.repeat(parent >= 0, own_rings * ring).astype(int)  # shared rows start at ring 1
    ring_in_row = np.concatenate([np.repeat(np.arange(k), ring) for k in own_rings]) + first_ring
    return rows, ring_in_row


def cone_residual(frusta, rows, points, offset=0.0):
    """Distance from the axis minus the cone radius r1 + offset + k·y at each point."""
    rel = points - frusta.base[rows]
    y = np.einsum("ij,ij->i", rel, frusta.axis[rows])
    radial = np.linalg.norm(rel - y[:, None] * frusta.axis[rows], axis=1)
    k = (frusta.r2[rows] - frusta.r1[rows]) / frusta.length[rows]
    return radial - (frusta.r1[rows] + offset + k * y)


def reference_uv(frusta, rows, points):
    """(6)-(7) of the docstring of plantgen.geometry.skeletons.frusta, for checking the vertices."""
    a, ref, c1 = frusta.axis[rows], frusta.ref_dir[rows], frusta.base[rows]
    b = np.cross(a, ref)
    rel = points - c1
    y = np.einsum("ij,ij->i", rel, a)
    radial = rel - y[:, None] * a
    e_r = radial / np.linalg.norm(radial, axis=1, keepdims=True)
    k = (frusta.r2[rows] - frusta.r1[rows]) / frusta.length[rows]
    g = a + k[:, None] * e_r

    def cut(plane):
        n, d = plane[rows, :3], plane[rows, 3]
        s = (d - np.einsum("ij,ij->i", n, points)) / np.einsum("ij,ij->i", n, g)
        return points + s[:, None] * g

    p_lo, p_hi = cut(frusta.plane_lo), cut(frusta.plane_hi)
    v = np.linalg.norm(points - p_lo, axis=1) / np.linalg.norm(p_hi - p_lo, axis=1)
    u = np.arctan2(np.einsum("ij,ij->i", rel, b), np.einsum("ij,ij->i", rel, ref)) / (2 * np.pi)
    u = (u + frusta.u_offset[rows] + v * frusta.twist[rows]) % 1.0
    n_lo = (p_lo - c1) / np.linalg.norm(p_lo - c1, axis=1, keepdims=True)
    c2 = c1 + frusta.length[rows, None] * a
    n_hi = (p_hi - c2) / np.linalg.norm(p_hi - c2, axis=1, keepdims=True)
    normal = (1 - v)[:, None] * n_lo + v[:, None] * n_hi
    return u, v, normal / np.linalg.norm(normal, axis=1, keepdims=True)


def circular_distance(a, b):
    d = np.abs(a - b) % 1.0
    return np.minimum(d, 1.0 - d)


# ---------------------------------------------------------------------------- counts
@pytest.mark.parametrize("m", [0, 1, 2, 3])
def test_each_row_gets_exactly_16_times_4_to_the_m_lateral_triangles(m):
    frusta = concat_frusta(chain_frusta(BENT, 0.2), chain_frusta([[3, 0, 0], [3, 2, 0]], [0.3, 0.1]))
    mesh = tessellate(frusta, m)
    n = len(frusta.length)
    assert lateral_triangles_per_row(m) == 16 * 4**m
    per_row = np.bincount(mesh.face_row[: n * 16 * 4**m], minlength=n)
    assert np.all(per_row == 16 * 4**m)
    # Two chains, each closed at both ends: four caps of 8·2^m triangles.
    assert mesh.n_caps == 4
    assert len(mesh.faces) == triangle_count(n, m, mesh.n_caps) == n * 16 * 4**m + 4 * 8 * 2**m
    # A continuing chain shares its joint rings: (2^m·rows + 1) rings of 8·2^m + 1 vertices.
    ring = 8 * 2**m + 1
    lateral = ring * ((2**m * 4 + 1) + (2**m + 1))
    assert len(mesh.vertices) == lateral + mesh.n_caps * (ring + 1)


def test_without_caps_the_count_is_table_1s_caption():
    frusta = chain_frusta(BENT, 0.2)
    for m in range(4):
        assert len(tessellate(frusta, m, caps=False).faces) == 16 * len(frusta.length) * 4**m


@pytest.mark.parametrize("bad", [-1, 9, 1.5, True, "2"])
def test_a_bad_level_is_refused(bad):
    with pytest.raises(ValueError):
        tessellate(chain_frusta(BENT, 0.2), bad)


# ---------------------------------------------------------------------------- the exact surface
@pytest.mark.parametrize("case", ["bent cylinder", "tapering twisted", "far from origin", "flaring"])
def test_vertices_lie_on_the_frustum_between_its_planes_with_the_uv_and_normals_of_6_to_8(case):
    if case == "bent cylinder":
        frusta = chain_frusta(BENT, 0.25)
    elif case == "tapering twisted":
        frusta = chain_frusta(BENT, np.linspace(0.3, 0.1, len(BENT)), twist=0.3, u_offset=0.17)
    elif case == "far from origin":
        frusta = chain_frusta(np.asarray(BENT) + 1e4, 0.25)
    else:
        frusta = chain_frusta([[0, 0, 0], [0, 1, 0.2], [0, 2, 0.2]], [0.01, 0.3, 1.2])
    m = 2
    mesh = tessellate(frusta, m)
    rows, ring = lateral_vertex_rows(mesh, frusta)
    pts = mesh.vertices[: len(rows)]
    scale = np.maximum(frusta.length, frusta.r1 + frusta.r2)[rows]
    assert np.all(np.abs(cone_residual(frusta, rows, pts)) <= 1e-12 * (scale + np.abs(pts).max(axis=1)))
    lo = np.einsum("ij,ij->i", frusta.plane_lo[rows, :3], pts) - frusta.plane_lo[rows, 3]
    hi = np.einsum("ij,ij->i", frusta.plane_hi[rows, :3], pts) - frusta.plane_hi[rows, 3]
    tol = 1e-11 * (scale + np.abs(pts).max(axis=1))
    assert np.all(lo >= -tol) and np.all(hi <= tol)
    # End rings follow the oblique planes exactly.
    assert np.all(np.abs(lo[ring == 0]) <= tol[ring == 0])
    assert np.all(np.abs(hi[ring == bands_along(m)]) <= tol[ring == bands_along(m)])
    # u, v and normals at the vertex are those of (6)-(8) at that point.
    u, v, normal = reference_uv(frusta, rows, pts)
    assert np.all(circular_distance(mesh.uv[: len(rows), 0], u) < 1e-5)
    assert np.allclose(v, ring / bands_along(m), atol=1e-9)
    # Texture v counts rows along the chain (every case here is one chain).
    assert np.allclose(mesh.uv[: len(rows), 1], rows + ring / bands_along(m), atol=1e-5)
    assert np.allclose(mesh.normals[: len(rows)], normal, atol=1e-6)
    assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-6)


def test_texture_v_counts_rows_along_a_chain_so_shared_joints_have_one_v():
    frusta = chain_frusta(BENT, 0.2)
    mesh = tessellate(frusta, 1, caps=False)
    lateral_v = mesh.uv[:, 1]
    assert lateral_v.min() == 0.0 and lateral_v.max() == pytest.approx(len(frusta.length))
    # Every face spans at most one band of v: no face runs backwards across a joint.
    span = np.ptp(lateral_v[mesh.faces], axis=1)
    assert span.max() <= 1 / bands_along(1) + 1e-6
    # And u steps by one column: the seam column carries u = 1, not 0.
    u_span = np.ptp(mesh.uv[:, 0][mesh.faces], axis=1)
    assert u_span.max() <= 1 / columns_around(1) + 1e-6


# ---------------------------------------------------------------------------- closed surfaces
@pytest.mark.parametrize("m", [0, 1, 3])
def test_a_continuing_chain_is_watertight_and_outward(m):
    frusta = chain_frusta(BENT, [0.3, 0.25, 0.25, 0.2, 0.15])
    mesh = tessellate(frusta, m).to_trimesh(merge=True)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.euler_number == 2
    assert mesh.volume > 0  # outward orientation
    # Joint rings are shared, not duplicated: merging only welds the u seam and the caps.
    raw = tessellate(frusta, m, caps=False)
    columns = columns_around(m)
    rings = bands_along(m) * len(frusta.length) + 1
    assert len(np.unique(raw.vertices.round(12), axis=0)) == columns * rings


def test_a_side_branch_is_closed_on_its_own():
    trunk = chain_frusta([[0, 0, 0], [0, 1, 0], [0, 2, 0]], 0.3)
    branch = chain_frusta([[0, 1, 0], [0.8, 1.6, 0], [1.4, 2.4, 0.3]], 0.1)
    frusta = concat_frusta(trunk, branch)
    assert frusta.parent_row.tolist() == [-1, 0, -1, 2]
    mesh = tessellate(frusta, 2)
    assert mesh.n_caps == 4
    tm = mesh.to_trimesh(merge=True)
    assert tm.is_watertight and tm.is_winding_consistent
    assert len(tm.split(only_watertight=True)) == 2


@pytest.mark.parametrize("kind", ["bent cylinder", "straight cone"])
def test_the_volume_approaches_the_analytic_frustum_volume(kind):
    if kind == "bent cylinder":
        # Oblique cuts through the axis keep a cylinder's volume: π r² · axis length.
        r = 0.25
        frusta = chain_frusta(BENT, r)
        exact = np.pi * r**2 * frusta.length.sum()
    else:
        frusta = chain_frusta([[0, 0, 0], [0, 2, 0]], [0.5, 0.2])
        exact = np.pi * 2 / 3 * (0.5**2 + 0.5 * 0.2 + 0.2**2)
    errors = [abs(tessellate(frusta, m).to_trimesh(merge=True).volume - exact) / exact for m in range(5)]
    assert all(b < a for a, b in pairwise(errors))
    # Inscribed polygons lose area as 1 - sin(2π/N)/(2π/N) ≈ (2π/N)²/6: second order.
    assert errors[4] < 1.2 * (2 * np.pi / columns_around(4)) ** 2 / 6
    assert errors[-2] / errors[-1] > 3.5


def test_a_cone_closing_to_a_point_gives_finite_unit_normals():
    frusta = chain_frusta([[0, 0, 0], [0, 1, 0], [0.3, 1.8, 0]], [0.2, 0.1, 0.0])
    mesh = tessellate(frusta, 2)
    assert np.all(np.isfinite(mesh.vertices)) and np.all(np.isfinite(mesh.normals))
    assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-6)
    apex = frusta.base[-1] + frusta.length[-1] * frusta.axis[-1]
    rows, ring = lateral_vertex_rows(mesh, frusta)
    tip_ring = mesh.vertices[: len(rows)][(rows == 1) & (ring == bands_along(2))]
    # The tip ring holds the apex (odd columns) and, a quarter band below it, a half ring
    # (even columns) on the cone: a graded band instead of zero-area triangles.
    assert np.allclose(tip_ring[1::2], apex, atol=1e-12)
    half = tip_ring[0::2]
    assert np.all(np.abs(cone_residual(frusta, np.ones(len(half), int), half)) < 1e-12)
    with np.errstate(invalid="ignore"):  # (8) at the tip divides by zero; only v is used
        _, v, _ = reference_uv(frusta, np.ones(len(half), int), half)
    assert np.allclose(v, 1 - 0.25 / bands_along(2), atol=1e-9)
    assert mesh.n_caps == 1  # the tip needs no cap


# ---------------------------------------------------------------------------- relief (GS+R)
def test_relief_moves_every_vertex_onto_the_shell_at_its_height():
    shell = 0.05
    frusta = chain_frusta(BENT, 0.25, shell=shell, twist=0.1)

    def height(material, u, v):
        return 0.5 + 0.5 * np.sin(2 * np.pi * (3 * u)) * np.cos(2 * np.pi * v)

    flat = tessellate(frusta, 2)
    mesh = tessellate(frusta, 2, relief=True, height=height)
    assert len(mesh.faces) == len(flat.faces)
    rows, ring = lateral_vertex_rows(mesh, frusta)
    u = mesh.uv[: len(rows), 0].astype(float)
    v = ring / bands_along(2)
    w = height(None, u % 1.0, v)
    residual = cone_residual(frusta, rows, mesh.vertices[: len(rows)], offset=w * shell)
    assert np.abs(residual).max() < 1e-12
    # The displacement is outward along the shell, at most one shell thick.
    moved = np.linalg.norm(mesh.vertices - flat.vertices, axis=1)
    assert moved.max() <= shell * 1.5 and moved.max() > 0.5 * shell
    tm = mesh.to_trimesh(merge=True)
    assert tm.is_watertight and tm.volume > flat.to_trimesh(merge=True).volume


def test_relief_leaves_rows_without_a_shell_on_the_base_cone():
    frusta = chain_frusta(BENT, 0.25, shell=0.0)
    flat = tessellate(frusta, 1)
    bumpy = tessellate(frusta, 1, relief=True, height=lambda mat, u, v: np.ones_like(u))
    assert np.array_equal(flat.vertices, bumpy.vertices)


# ---------------------------------------------------------------------------- skinned skeletons
def skinned_models():
    from _geometry_helpers import chain_skeleton, random_tree, y_junction

    bent = chain_skeleton((20, 30, -25), radii=(0.2, 0.18, 0.16, 0.12, 0.1), plane_turn_deg=40)
    return {
        "bent chain": skin_skeleton(bent),
        "bent chain, seams fitted": skin_skeleton(bent, seam_fit=True),
        "twisted chain": skin_skeleton(chain_skeleton((20, 30), radii=0.1), twist=0.3),
        "Y junction": skin_skeleton(y_junction()),
        "knuckle (150 degree bend)": skin_skeleton(chain_skeleton((150,), radii=0.1)),
        "random tree": skin_skeleton(random_tree(200, 1)),
    }


def vertex_owner_rows(mesh):
    """(V,) the row of the first lateral face that uses each vertex (-1: caps only). Faces
    come row by row, parents first, so a shared joint ring belongs to its parent."""
    owner = np.full(len(mesh.vertices), -1)
    faces, rows = mesh.faces[: mesh.n_lateral], mesh.face_row[: mesh.n_lateral]
    owner[faces.ravel()[::-1]] = np.repeat(rows, 3)[::-1]  # the last write wins: the first face
    return owner


@pytest.mark.parametrize("name", list(skinned_models()))
def test_skinned_vertices_carry_the_uv_and_normals_of_the_skinning(name):
    """plantgen's own (6)-(8) (surface_uv, surface_normals) at every vertex of a row's
    faces (knuckles: P's and C's trimmed rings too)."""
    frusta = skinned_models()[name]
    m = 2
    mesh = tessellate(frusta, m)
    owner = vertex_owner_rows(mesh)
    used = owner >= 0
    rows, pts = owner[used], mesh.vertices[used]
    assert np.all(np.abs(cone_residual(frusta, rows, pts)) <= 1e-12 * (1 + np.abs(pts).max(axis=1)))
    proper = frusta.length[rows] > 1e-6  # knuckle fan rows have no length: v is undefined there
    u, v = surface_uv(frusta, rows[proper], pts[proper])
    assert np.all(circular_distance(u, mesh.uv[used, 0][proper]) < 1e-6)
    v_mesh = mesh.uv[used, 1][proper] - frusta.chain_position[rows[proper]]
    assert np.allclose(v, v_mesh, atol=1e-6)
    normals = surface_normals(frusta, rows[proper], pts[proper])
    assert np.allclose(mesh.normals[used][proper], normals, atol=1e-6)
    assert np.all(np.isfinite(mesh.vertices)) and np.all(np.isfinite(mesh.normals))


@pytest.mark.parametrize("name", list(skinned_models()))
def test_skinned_models_are_closed_and_counted(name):
    frusta = skinned_models()[name]
    mesh = tessellate(frusta, 1)
    assert len(mesh.faces) == triangle_count(frusta, 1)
    open_ends = frusta.open_lo.sum() + frusta.open_hi.sum()
    if frusta.report.fan_rows:
        # knuckles (issue 18): inner fan slices lie inside the bend and get no caps, outer
        # slices fewer triangles; the count for a number of rows is an upper bound
        assert mesh.n_caps == open_ends - 2 * (~frusta.has_length & (frusta.parent_row < 0)).sum()
        assert len(mesh.faces) < triangle_count(len(frusta), 1, mesh.n_caps)
    else:
        assert mesh.n_caps == open_ends
        assert len(mesh.faces) == triangle_count(len(frusta), 1, mesh.n_caps)
    tm = mesh.to_trimesh(merge=True)
    assert tm.is_watertight and tm.is_winding_consistent and tm.volume > 0


def test_chains_are_found_from_shared_planes_when_parent_row_is_absent():
    frusta = skinned_models()["random tree"]
    bare = SimpleNamespace(**{k: getattr(frusta, k) for k in ROW_FIELDS})
    assert np.array_equal(parent_rows_from_planes(bare), frusta.parent_row)


def test_default_relief_heights_are_the_relief_modules_maps():
    from plantgen.geometry.skeletons import relief

    frusta = skinned_models()["bent chain"]
    flat = tessellate(frusta, 2)
    bumpy = tessellate(frusta, 2, relief=True)
    rows, ring = lateral_vertex_rows(flat, frusta)
    u = flat.uv[: len(rows), 0].astype(float)
    w = relief.sample_height(relief.height_map(frusta.material_names[0]), u, ring / bands_along(2))
    # the relief follows the radius: its depth where the flat (inner) vertex lies
    y = np.einsum("ij,ij->i", flat.vertices[: len(rows)] - frusta.base[rows], frusta.axis[rows])
    depth = frusta.shell[rows] * relief_scale(frusta, rows, y)
    residual = cone_residual(frusta, rows, bumpy.vertices[: len(rows)], offset=w * depth)
    assert np.abs(residual).max() < 1e-12
    assert frusta.shell.max() > 0 and np.ptp(w) > 0.2


def test_tip_caps_only_close_the_upper_ends():
    frusta = skinned_models()["Y junction"]
    mesh = tessellate(frusta, 1, caps="tips")
    assert mesh.n_caps == frusta.open_hi.sum()
    capped = mesh.face_row[len(frusta) * lateral_triangles_per_row(1):: columns_around(1)]
    assert np.array_equal(np.sort(capped), np.flatnonzero(frusta.open_hi))
    with pytest.raises(ValueError):
        tessellate(frusta, 1, caps="bottom")


def test_relief_normals_are_the_normals_of_the_displaced_surface():
    """The tilt of GS+R's vertex normals (the ray caster's relief shading) approaches the
    geometric normals of the displaced mesh as the mesh resolves the relief."""
    frusta = chain_frusta([[0, 0, 0], [0, 2, 0]], 0.25, shell=0.05)

    def height(material, u, v):
        return 0.5 + 0.5 * np.sin(2 * np.pi * 3 * u) * np.cos(2 * np.pi * v)

    errors = []
    for m in (2, 3, 4):
        mesh = tessellate(frusta, m, relief=True, height=height, caps=False,
                          gradient_step=(1e-4, 1e-4))
        # Interior vertices only: not the u seam nor the end rings, where the welded mesh
        # sees one side of the surface.
        ring, column = np.divmod(np.arange(len(mesh.vertices)), columns_around(m) + 1)
        inner = (ring > 0) & (ring < bands_along(m)) & (column > 0) & (column < columns_around(m))
        tm = mesh.to_trimesh()
        face_normals = np.zeros_like(mesh.vertices)
        weighted = np.repeat(tm.face_normals * tm.area_faces[:, None], 3, axis=0)
        np.add.at(face_normals, tm.faces.ravel(), weighted)
        face_normals /= np.linalg.norm(face_normals, axis=1, keepdims=True)
        cos = np.einsum("ij,ij->i", face_normals[inner], mesh.normals[inner])
        errors.append(np.degrees(np.arccos(np.clip(cos, -1, 1))).mean())
    flat_tilt = np.degrees(np.arctan(0.05 * 0.5 * 2 * np.pi * 3 / (2 * np.pi * 0.25)))
    # The relief tilts normals by up to ~flat_tilt; the mismatch falls well below it.
    assert errors[0] > errors[1] > errors[2] and errors[2] < flat_tilt / 10, (errors, flat_tilt)
