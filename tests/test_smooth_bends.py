"""Smooth bends (issue 17): bent continuing joints become arcs of short frusta.

Invariants with a physical meaning: the refined centre line is tangent to both segments
and lies on a circle of the chosen radius; radii and the chain stay continuous; the
segment count grows by what the report says; the skin stays closed (every medial-axis ray
hits it, seams have no radial gap); and the skin converges to the true torus-section bend
as the chord sag R·(1 - cos(θ/2k)) with k frusta per arc.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from plantgen.benchmarks.skinning import torus_bend_error
from plantgen.geometry.rays.reference import intersect_frusta
from plantgen.geometry.rays.stability import chain, medial_axis_rays
from plantgen.geometry.skeletons.frusta import seam_gap
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.geometry.skeletons.smooth import DEFAULT_RADIUS_FACTOR, MIN_ARC_RATIO, smooth_bends


def _frusta_arrays(f):
    return {name: getattr(f, name) for name in ("base", "axis", "length", "r1", "r2", "plane_lo", "plane_hi",
                                                 "ref_dir", "u_offset", "segment", "parent_row", "material")}


def _closed(frusta, rays=600) -> int:
    """Rays from inside the solid that escape (0: the skin is closed)."""
    o, d = medial_axis_rays(frusta, rays)
    return int((~intersect_frusta(frusta, o, d).hit).sum())


def _links_continuous(sk: Skeleton) -> tuple[float, float]:
    """Largest gap between a continuing segment's start and its parent's end, and the
    largest radius step there."""
    c = np.flatnonzero(sk.continues & (sk.parent >= 0))
    p = sk.parent[c]
    return (float(np.abs(sk.start[c] - sk.end[p]).max()), float(np.abs(sk.r_start[c] - sk.r_end[p]).max()))


def test_option_off_or_above_every_bend_changes_no_skin():
    sk = chain([10.0, 25.0, 40.0], lengths=[1.0, 0.8, 0.6, 0.5], radii=[0.12, 0.1, 0.09, 0.07, 0.05])
    plain = _frusta_arrays(skin_skeleton(sk))
    above = skin_skeleton(sk, smooth_bends=45.0)
    assert above.report.smooth_joints == 0 and above.report.smooth_segments == 0
    for name, value in _frusta_arrays(above).items():
        np.testing.assert_array_equal(value, plain[name], err_msg=name)


def test_arc_is_tangent_to_both_segments_and_lies_on_one_circle():
    theta = 70.0
    sk = chain([theta], lengths=1.0, radii=0.1)
    res = smooth_bends(sk, 30.0, step_deg=10.0)
    k = int(np.ceil(theta / 10.0))
    assert res.joints == 1 and res.added == k and len(res.skeleton) == 2 + k
    out = res.skeleton
    np.testing.assert_array_equal(out.parent, np.arange(-1, len(out) - 1))   # one chain, in order
    arc = slice(1, 1 + k)
    R = DEFAULT_RADIUS_FACTOR * 0.1
    d = R * np.tan(np.radians(theta) / 2)
    J = sk.end[0]
    # the two segments are shortened by the tangent length d, keeping their directions
    np.testing.assert_allclose(np.linalg.norm(out.end[0] - J), d, rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(out.start[-1] - J), d, rtol=1e-12)
    np.testing.assert_allclose(out.end[-1], sk.end[1], atol=1e-15)
    # every arc vertex is R from one centre, which is R from both tangent points along
    # their normals: the arc is tangent to both segments
    verts = np.concatenate([out.start[arc], out.end[arc][-1:]])
    centre = out.end[0] + R * np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(np.linalg.norm(verts - centre, axis=1), R, rtol=1e-12)
    chords = out.end[arc] - out.start[arc]
    turn = np.degrees(np.arctan2(chords[:, 0], chords[:, 1]))
    np.testing.assert_allclose(np.diff(turn), theta / k, rtol=1e-9)       # equal chords
    np.testing.assert_allclose(turn[0], theta / (2 * k), rtol=1e-9)     # symmetric about the tangents
    assert _links_continuous(out) == pytest.approx((0.0, 0.0), abs=1e-15)


def test_radii_taper_continuously_through_the_arc():
    sk = chain([80.0], lengths=1.0, radii=[0.15, 0.1, 0.05])
    out = smooth_bends(sk, 10.0, step_deg=8.0).skeleton
    gap, step = _links_continuous(out)
    assert gap < 1e-15 and step < 1e-15
    radii = np.concatenate([out.r_start, out.r_end[-1:]])
    assert np.all(np.diff(radii) < 0)                    # still tapering, never a bulge
    assert radii[0] == 0.15 and radii[-1] == 0.05


def test_report_counts_the_added_segments_and_rows_keep_original_segments():
    sk = chain([50.0, 5.0, 95.0], lengths=1.0, radii=0.08)
    sk = Skeleton(sk.start, sk.end, sk.r_start, sk.r_end, sk.parent, sk.continues, np.array([0, 1, 0, 1]),
                  material_names=("bark", "moss"))
    f = skin_skeleton(sk, smooth_bends=20.0, smooth_step_deg=10.0)
    r = f.report
    assert r.smooth_joints == 2
    assert r.smooth_segments == 5 + 10                  # ceil(50/10) + ceil(95/10)
    assert r.n_segments == 4
    assert r.n_rows == 4 + r.smooth_segments + r.fan_rows
    assert any("smooth bends: 2 joints" in line for line in r.lines())
    assert set(f.segment) == {0, 1, 2, 3}
    np.testing.assert_array_equal(f.material, sk.material[f.segment])
    assert np.all(np.diff(f.segment) >= 0)               # rows in chain order


def test_arc_rows_continue_the_chain_with_closed_seams():
    f = skin_skeleton(chain([60.0, 40.0], lengths=1.0, radii=[0.1, 0.09, 0.08, 0.07]), smooth_bends=15.0)
    assert f.report.sharp_joints == 0
    # one chain: every row but the root shares its lower plane with the row before it,
    # so v runs on and u is carried by the skinning's texture frames
    np.testing.assert_array_equal(f.parent_row, np.arange(-1, len(f) - 1))
    assert seam_gap(f).max() < 1e-9
    assert _closed(f) == 0


@pytest.mark.parametrize("bend", [45.0, 90.0, 135.0])
def test_error_against_the_torus_decreases_with_frusta_per_arc(bend):
    ks = (1, 2, 4, 8, 16)
    res = [torus_bend_error(bend, k, rays=1500) for k in ks]
    errors = np.array([e["error"] for e in res])
    assert all(e["missed"] == 0 for e in res)            # the chain stays closed
    assert [e["segments_added"] for e in res] == list(ks)
    assert np.all(np.diff(errors) < 0)
    # the chords sag inside the arc by R(1 - cos(θ/2k)); the outer wall follows them
    R_over_r = res[0]["R"] / 0.1
    assert R_over_r == pytest.approx(min(DEFAULT_RADIUS_FACTOR, 0.45 / np.tan(np.radians(bend) / 2) / 0.1))
    sag = R_over_r * (1 - np.cos(np.radians(bend) / (2 * np.array(ks))))
    # (from k = 2: one chord across a 135° bend meets its segments at 67.5° joints, whose
    # seams, not the sag, set the largest distance)
    np.testing.assert_allclose(errors[1:], sag[1:], rtol=0.1)
    assert errors[-1] < 0.02


def test_side_branch_at_a_smoothed_joint_moves_onto_the_arc():
    base = chain([60.0], lengths=1.0, radii=0.1)
    J = base.end[0]
    side_end = J + np.array([-0.6, 0.3, 0.2])
    start = np.vstack([base.start[:1], [J], base.start[1:]])
    end = np.vstack([base.end[:1], [side_end], base.end[1:]])
    sk = Skeleton(start, end, [0.1, 0.05, 0.1], [0.1, 0.03, 0.1], [-1, 0, 0], [False, False, True],
                  np.zeros(3, int))
    res = smooth_bends(sk, 20.0)
    out = res.skeleton
    side = int(np.flatnonzero(res.origin == 1)[0])
    host = out.parent[side]
    assert res.origin[host] == 2 and out.continues[host]          # hangs from an arc chord
    mid = 0.5 * (out.start[host] + out.end[host])
    np.testing.assert_allclose(out.start[side], mid, atol=1e-15)   # on the arc's axis
    np.testing.assert_array_equal(out.end[side], side_end)
    assert np.all(out.parent < np.arange(len(out)))
    assert _closed(skin_skeleton(sk, smooth_bends=20.0)) == 0


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(bends=st.lists(st.floats(0.0, 150.0), min_size=1, max_size=4),
       lengths=st.floats(0.2, 2.0), r0=st.floats(0.02, 0.3), taper=st.floats(0.3, 1.0),
       threshold=st.floats(1.0, 60.0), step=st.floats(3.0, 30.0))
def test_random_chains_stay_closed_and_continuous(bends, lengths, r0, taper, threshold, step):
    # a bend equal to the threshold is measured from the axes to round-off: either side is right
    assume(all(abs(b - threshold) > 1e-6 for b in bends))
    n = len(bends) + 1
    radii = r0 * np.linspace(1.0, taper, n + 1)
    sk = chain(bends, lengths=lengths, radii=radii)
    res = smooth_bends(sk, threshold, step_deg=step)
    # an arc narrower than MIN_ARC_RATIO joint radii is not made
    with np.errstate(divide="ignore", over="ignore"):      # a bend of 1e-300°: the arc always fits
        arc_r = [min(DEFAULT_RADIUS_FACTOR * radii[j + 1], 0.45 * lengths / np.tan(np.radians(b) / 2))
                 for j, b in enumerate(bends)]
    expect = sum(int(np.ceil(b / step - 1e-9)) for j, b in enumerate(bends)
                 if threshold < b < 179.0 and arc_r[j] >= MIN_ARC_RATIO * radii[j + 1])
    assert res.added == expect
    if res.added:
        gap, rstep = _links_continuous(res.skeleton)
        assert gap < 1e-12 * max(lengths, 1.0) and rstep < 1e-12
        lengths_out = np.linalg.norm(res.skeleton.end - res.skeleton.start, axis=1)
        assert np.all(lengths_out > 0)
    f = skin_skeleton(sk, smooth_bends=threshold, smooth_step_deg=step)
    assert f.report.smooth_segments == res.added
    assert _closed(f, rays=300) == 0


# ------------------------------------------------------------------- the commands
def test_export_smooth_bends_loads_back_watertight_with_the_bent_tube_volume(tmp_path):
    import trimesh
    from _cli import run_cli

    theta, r, length = 90.0, 0.1, 1.0
    chain([theta], lengths=length, radii=r).save(tmp_path / "bend.npz")
    out = tmp_path / "bend.stl"
    code, stdout, stderr = run_cli("export", tmp_path / "bend.npz", "-o", out, "--subdiv", "3",
                                   "--smooth-bends", "30")
    assert code == 0, stderr
    assert "smooth bends: +9 arc segments" in stdout           # ceil(90° / 10°)
    assert "2 branch segments (11 pieces written)" in stdout
    mesh = trimesh.load(out)
    mesh.merge_vertices()
    assert mesh.is_watertight
    # Pappus: two straight cylinders shortened by d and a torus section of centre-line
    # length R·θ; the chords and the tessellation lose a little of it
    R = DEFAULT_RADIUS_FACTOR * r
    d = R * np.tan(np.radians(theta) / 2)
    tube = np.pi * r * r * (2 * (length - d) + R * np.radians(theta))
    assert mesh.volume == pytest.approx(tube, rel=0.02)
    assert mesh.volume < tube


def test_a_bad_smooth_bends_angle_is_one_line_and_exit_2(tmp_path):
    from _cli import run_cli

    for bad in ("-1", "180", "nan", "ten"):
        out = tmp_path / "x.obj"
        code, stdout, stderr = run_cli("export", "saguaro", "-o", out, "--smooth-bends", bad)
        assert code == 2 and "--smooth-bends" in stderr and len(stderr.strip().splitlines()) == 1
        assert not out.exists()
    with pytest.raises(ValueError, match="smooth_bends"):
        skin_skeleton(chain([30.0]), smooth_bends=-5.0)


def test_render_smooth_bends_adds_the_arc_rows(gl_ctx):
    from plantgen.pipeline import render_model

    plain = render_model("saguaro", size=(160, 120), smooth_bends=179.0)   # its grammar smooths past 20°
    smooth = render_model("saguaro", size=(160, 120), smooth_bends=15.0)
    assert smooth.segments == plain.segments == 30
    expected = skin_skeleton(load_saguaro(), smooth_bends=15.0).report
    assert smooth.rows == plain.rows + expected.smooth_segments > plain.rows
    # same framing, different silhouette at the bends
    assert not np.array_equal(plain.result.color, smooth.result.color)


def load_saguaro():
    from plantgen.pipeline import load_skeleton

    return load_skeleton("saguaro")


def test_the_grammars_turtle_key_smooths_as_the_option_does(tmp_path):
    """``turtle: {smooth_bends: ANGLE}`` in a grammar is the default of ``--smooth-bends``
    (which overrides it): export, render and the viewer skin through the same default."""
    from _cli import run_cli

    from plantgen.pipeline import grow_file, prepare_model

    text = ("name: bent\naxiom: \"F(1) &(60) F(1)\"\nturtle: {radius: 0.1, smooth_bends: 30}\n"
            "materials: [bark]\n")
    (tmp_path / "bent.yaml").write_text(text)
    assert grow_file(tmp_path / "bent.yaml").smooth_bends == 30.0
    code, stdout, stderr = run_cli("export", tmp_path / "bent.yaml", "-o", tmp_path / "a.obj")
    assert code == 0, stderr
    assert "smooth bends: +6 arc segments" in stdout                  # ceil(60° / 10°)
    code, stdout, stderr = run_cli("export", tmp_path / "bent.yaml", "-o", tmp_path / "b.obj",
                                   "--smooth-bends", "90")                # the option overrides
    assert code == 0, stderr
    assert "smooth bends" not in stdout
    assert len(prepare_model(tmp_path / "bent.yaml").anim.frusta_at(0.0)) == 2 + 6
    (tmp_path / "bad.yaml").write_text(text.replace("smooth_bends: 30", "smooth_bends: 200"))
    code, _, stderr = run_cli("grow", tmp_path / "bad.yaml", "-o", tmp_path / "x.npz")
    assert code == 2 and "smooth_bends" in stderr


def _rim_texture_v(f, row, top: bool):
    """The texture v (surface_uv) of points on ``row``'s rim at its upper (``top``) or lower plane."""
    from plantgen.geometry.skeletons.frusta import surface_uv

    phi = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
    e1 = f.ref_dir[row]
    e2 = np.cross(f.axis[row], e1)
    radius = f.r2[row] if top else f.r1[row]
    y = f.length[row] if top else 0.0
    pts = f.base[row] + y * f.axis[row] + radius * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    # move each point along the axis onto the plane (the planes are oblique at joints)
    plane = f.plane_hi[row] if top else f.plane_lo[row]
    pts = pts + ((plane[3] - pts @ plane[:3]) / (f.axis[row] @ plane[:3]))[:, None] * f.axis[row]
    return surface_uv(f, np.full(len(pts), row), pts)[1]


@pytest.mark.parametrize("lengths", [1.0, [1.0, 0.5, 1.0]])
def test_an_arc_spans_one_texture_period_and_v_runs_on(lengths):
    # before: every chord of an arc took the whole texture (k periods squeezed into the
    # arc); now chord i of k takes slot i, the texture v is continuous at every joint, and
    # along the chain the texture advances about as fast per unit length on the arc as on
    # the segments (an elbow shorter than its arc joins the arc's period)
    f = skin_skeleton(chain([80.0, 70.0], lengths=lengths, radii=0.1), smooth_bends=10.0)
    arcs = f.v_part[:, 1] > 1
    assert arcs.sum() >= 7 and np.all(f.v_part[:, 0] < f.v_part[:, 1])
    for row in range(1, len(f)):
        top = _rim_texture_v(f, row - 1, True)
        bottom = _rim_texture_v(f, row, False)
        gap = np.abs((top - bottom + 0.5) % 1.0 - 0.5)          # continuous modulo whole periods
        assert gap.max() < 1e-9, (row, f.v_part[row - 1], f.v_part[row])
    density = 1.0 / (f.v_part[:, 1] * f.length)             # periods per unit length
    assert density.max() / density.min() < 6.0, density     # a whole period per chord: 30-40x


def test_texture_slots_reach_the_mesh_and_the_raster_renderers_rows():
    # GS: the mesh's texture v, less its row's chain offset (what raster.glsl subtracts),
    # is the texture v the ray caster and the reference take (surface_uv)
    from plantgen.geometry.meshes.mesh import tessellate
    from plantgen.geometry.skeletons.frusta import surface_uv
    from plantgen.gl.raster import row_data

    f = skin_skeleton(chain([80.0], lengths=1.0, radii=0.1), smooth_bends=10.0)
    mesh = tessellate(f, 1, caps=False)
    lateral = mesh.faces[: len(mesh.face_row)]
    rows = np.repeat(mesh.face_row, 3)
    verts = lateral.ravel()
    v_mesh = mesh.uv[verts, 1] - row_data(f)[rows, 0]
    v_ref = surface_uv(f, rows, mesh.vertices[verts])[1]
    assert np.abs(v_mesh - v_ref).max() < 1e-5
    assert (f.v_part[rows, 1] > 1).mean() > 0.5                 # most of it is the arc


def test_a_joint_too_tight_for_a_wide_enough_arc_stays_a_joint():
    # found by the random chains: segments 0.2 long, radius 0.28 tapering to 0.09: the arc
    # that fits (R = 0.45 L / tan(θ/2) = 0.21) is 1.42 joint radii; its 3° chords, 0.011
    # long and 0.15 thick, became knuckles and 2 of 300 medial rays escaped; such a joint
    # is not smoothed
    sk = chain([0.0, 46.0], lengths=0.203125, radii=0.28125 * np.linspace(1.0, 0.3125, 4))
    res = smooth_bends(sk, 1.0, step_deg=3.0)
    assert res.added == 0 and res.joints == 0
    assert _closed(skin_skeleton(sk, smooth_bends=1.0, smooth_step_deg=3.0), rays=300) == 0
    wide = chain([0.0, 46.0], lengths=2.0, radii=0.28125 * np.linspace(1.0, 0.3125, 4))
    assert smooth_bends(wide, 1.0, step_deg=3.0).added == 16           # room for the arc: smoothed
