"""The GLSL ray caster (issue 4): hits on the surface, no holes, depth, relief, determinism.

Every test draws through the ``gl_ctx`` fixture (tests/conftest.py), which asserts that
the GL error flag is clear before and after. Images are small (at most 192x144) so the
file runs in well under a minute on llvmpipe.
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pytest

from plantgen.geometry.rays.camera import Camera, auto_camera
from plantgen.geometry.skeletons.frusta import Frusta, frusta_bounds
from plantgen.geometry.skeletons.materials import MAX_MATERIALS
from plantgen.geometry.stage import Ground
from plantgen.gl import material_uniforms as render_materials
from plantgen.gl.raycast import Raycaster
from plantgen.gl.records import PYRAMID_CORNERS, PYRAMID_TRIANGLES, RECORD_BYTES, pack_records
from plantgen.settings import RaycastSettings

W, H = 160, 120
FIELDS = ("base", "axis", "length", "r1", "r2", "plane_lo", "plane_hi", "ref_dir", "u_offset",
          "twist", "material", "shell", "segment")


# ---------------------------------------------------------------------------- builders
def frusta_chain(points, radii, *, shell=0.0, tilt_ends=(None, None)):
    """Frusta rows (the contract of plantgen.geometry.skeletons.frusta) along one continuing chain.

    Joints are cut by the bisector plane of the two axes (the paper's plane (5) when both
    radii at the joint agree); the chain's ends are cut square unless ``tilt_ends`` gives
    an end-plane normal. The u = 0 direction is carried along the chain (no twist).
    """
    pts = np.asarray(points, dtype=np.float64)
    radius = np.broadcast_to(np.asarray(radii, dtype=np.float64), (len(pts),))
    axis = np.diff(pts, axis=0)
    length = np.linalg.norm(axis, axis=1)
    axis = axis / length[:, None]
    normal = np.concatenate([axis[:1], axis[:-1] + axis[1:], axis[-1:]])
    for end, tilt in zip((0, -1), tilt_ends, strict=True):
        if tilt is not None:
            normal[end] = tilt
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    planes = np.concatenate([normal, np.einsum("ij,ij->i", normal, pts)[:, None]], axis=1)
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 0, 1.0]])
    ref = helper - axis * np.einsum("ij,ij->i", helper, axis)[:, None]
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    n = len(length)
    return Frusta(base=pts[:-1], axis=axis, length=length, r1=radius[:-1].copy(),
                  r2=radius[1:].copy(), plane_lo=planes[:-1], plane_hi=planes[1:],
                  ref_dir=ref, u_offset=np.zeros(n), twist=np.zeros(n),
                  material=np.zeros(n, np.int32), shell=np.full(n, float(shell)),
                  segment=np.arange(n), parent_row=np.arange(n) - 1)


def join(*parts):
    offsets = np.cumsum([0] + [len(p.length) for p in parts[:-1]])
    parent = [np.where(p.parent_row >= 0, p.parent_row + o, -1) for p, o in zip(parts, offsets, strict=True)]
    return Frusta(**{k: np.concatenate([getattr(p, k) for p in parts]) for k in FIELDS},
                  parent_row=np.concatenate(parent))


def model_box(frusta):
    return frusta_bounds(frusta)


def look_at(frusta, direction, *, width=W, height=H, distance=None):
    """A camera framing ``frusta`` from ``direction`` (auto), or from ``distance`` times
    the model size away along it."""
    box = model_box(frusta)
    if distance is None:
        return Camera.auto(box, width, height, direction=direction)
    centre = box.mean(axis=0)
    d = np.asarray(direction, dtype=np.float64)
    eye = centre + d / np.linalg.norm(d) * distance * np.linalg.norm(box[1] - box[0])
    up = (0.0, 1.0, 0.0) if abs(d[1]) < 0.99 * np.linalg.norm(d) else (1.0, 0.0, 0.0)
    return Camera(tuple(eye), tuple(centre), up, 40.0, width, height)


def hit_points(camera, distance):
    """(k, 3) float64 world points of the hit pixels and the (h, w) hit mask."""
    origins, dirs = camera.rays()
    hit = np.isfinite(distance)
    return origins[hit] + dirs[hit] * distance[hit, None].astype(np.float64), hit


def surface_distance(frusta, points):
    """(k,) float64 distance of each point from the nearest frustum's closed boundary
    (its cone or its two cap discs), and whether it is inside that frustum's planes."""
    best = np.full(len(points), np.inf)
    for i in range(len(frusta.length)):   # a handful of rows per test scene
        e = points - frusta.base[i]
        y = e @ frusta.axis[i]
        radial = np.linalg.norm(e - y[:, None] * frusta.axis[i], axis=1)
        k = (frusta.r2[i] - frusta.r1[i]) / frusta.length[i]
        r = frusta.r1[i] + k * y
        lo = points @ frusta.plane_lo[i, :3] - frusta.plane_lo[i, 3]
        hi = points @ frusta.plane_hi[i, :3] - frusta.plane_hi[i, 3]
        scale = max(frusta.length[i], frusta.r1[i], frusta.r2[i])
        between = (lo >= -1e-4 * scale) & (hi <= 1e-4 * scale)
        on_cone = np.where(between & (r >= 0), np.abs(radial - r) / np.sqrt(1 + k * k), np.inf)
        in_disc = radial <= r + 1e-4 * scale
        on_caps = np.where(in_disc, np.minimum(np.abs(lo), np.abs(hi)), np.inf)
        best = np.minimum(best, np.minimum(on_cone, on_caps))
    return best


def holes_and_speckles(hit):
    """Pixels whose four neighbours all disagree with them (a miss inside a hit region or
    a lone hit): the symptoms of cracks between frusta or of a bad bounding pyramid."""
    inner = hit[1:-1, 1:-1]
    nbrs = np.stack([hit[:-2, 1:-1], hit[2:, 1:-1], hit[1:-1, :-2], hit[1:-1, 2:]])
    return int(np.sum(~inner & nbrs.all(axis=0))), int(np.sum(inner & ~nbrs.any(axis=0)))


@pytest.fixture(scope="module")
def caster():
    from plantgen.gl.context import gl_context
    return Raycaster(gl_context())


# ---------------------------------------------------------------------------- hard cases
BEND = [[0, 0, 0], [0, 1, 0], [0.45, 1.9, 0], [0.45, 2.8, 0.6], [0.1, 3.3, 1.3]]
HARD_CASES = {
    "cylinder": frusta_chain([[0, 0, 0], [0, 2, 0]], 0.4),
    "near_cylinder": frusta_chain([[0, 0, 0], [0, 2, 0]], [0.4, 0.4 * (1 + 1e-12)]),
    "flaring": frusta_chain([[0, 0, 0], [0, 1.5, 0]], [0.1, 0.8]),
    "closing_to_a_point": frusta_chain([[0, 0, 0], [0, 2, 0]], [0.5, 0.0]),
    "oblique_caps": frusta_chain([[0, 0, 0], [0, 2, 0]], [0.5, 0.3],
                                 tilt_ends=([0.5, 1, 0], [-0.4, 1, 0.3])),
    "apex_oblique": frusta_chain([[0, 0, 0], [0, 1.5, 0]], [0.5, 0.0], tilt_ends=(None, [0.8, 1, 0])),
    "flare_oblique": frusta_chain([[0, 0, 0], [0, 1, 0]], [0.1, 0.9], tilt_ends=([0.9, 1, 0], [0, 1, 0.7])),
    "bent_chain": frusta_chain(BEND, [0.3, 0.27, 0.24, 0.2, 0.16]),
    "fold_135": frusta_chain([[0, 0, 0], [0, 1, 0], [0.7, 0.3, 0]], 0.15),
    "thin": frusta_chain([[0, 0, 0], [0, 1, 0]], 1e-4),
    "fat": frusta_chain([[0, 0, 0], [0, 0.01, 0]], 1.0),
    "far_from_origin": frusta_chain(np.array(BEND) + 1e4, [0.3, 0.27, 0.24, 0.2, 0.16]),
    "crossing": join(frusta_chain([[-1, 0.5, 0], [1, 0.5, 0]], 0.3),
                     frusta_chain([[0, 0, -1], [0, 1, 1]], 0.25)),
}
VIEWS = {"oblique": (0.6, 0.35, 1.0), "along_axis": (0.0, 1.0, 1e-3), "below": (0.2, -1.0, 0.3)}
CLOSE_UP = {"thin": 2e-3}   # eye distance in model sizes, for cases too small to frame whole


@pytest.mark.parametrize("view", VIEWS)
@pytest.mark.parametrize("case", HARD_CASES)
def test_every_hit_lies_on_the_surface_and_nothing_is_nan(gl_ctx, caster, case, view):
    frusta = HARD_CASES[case]
    camera = look_at(frusta, VIEWS[view], distance=CLOSE_UP.get(case))
    result = caster.render(frusta, camera)
    assert not np.isnan(result.distance).any()
    assert np.all((result.distance > 0) | np.isinf(result.distance))
    points, hit = hit_points(camera, result.distance)
    assert hit.mean() > 0.01, "the model should be in view"
    # float32 evaluates each point to a few ulps of its distance from the eye
    size = np.linalg.norm(np.subtract(*model_box(frusta)))
    eye_dist = np.linalg.norm(points - np.asarray(camera.eye), axis=1)
    off = surface_distance(frusta, points)
    assert np.all(off <= 2e-5 * eye_dist + 1e-6 * size), f"worst {off.max():.3g}"
    holes, speckles = holes_and_speckles(hit)
    assert holes == 0 and speckles == 0
    # the bounding pyramids lose nothing: a full-screen proxy per segment sees the same
    oracle = caster.render(frusta, camera, RaycastSettings(proxy="screen")).distance
    assert np.array_equal(np.isfinite(oracle), hit)
    assert np.array_equal(oracle[hit], result.distance[hit])


@pytest.mark.parametrize("case", ["cylinder", "closing_to_a_point", "oblique_caps", "bent_chain"])
def test_an_eye_inside_a_bounding_pyramid_still_sees_the_frustum(gl_ctx, caster, case):
    frusta = HARD_CASES[case]
    # just outside the cone, inside the square pyramid around it, at the first segment's middle
    i = 0
    mid = frusta.base[i] + 0.5 * frusta.length[i] * frusta.axis[i]
    r_mid = 0.5 * (frusta.r1[i] + frusta.r2[i])
    side = np.cross(frusta.ref_dir[i], frusta.axis[i])
    eye = mid + 0.97 * r_mid * (frusta.ref_dir[i] + side)       # radial 1.37 r, inside 1.0 r square
    camera = Camera(tuple(eye), tuple(frusta.base[i] + 0.1 * frusta.axis[i]), (0, 1, 0) if
                    abs(frusta.axis[i][1]) < 0.9 else (1, 0, 0), 70.0, W, H)
    result = caster.render(frusta, camera)
    oracle = caster.render(frusta, camera, RaycastSettings(proxy="screen")).distance
    hit = np.isfinite(result.distance)
    assert hit.mean() > 0.2
    assert np.array_equal(np.isfinite(oracle), hit)
    points, _ = hit_points(camera, result.distance)
    assert surface_distance(frusta, points).max() < 1e-5


# ---------------------------------------------------------------------------- depth
def test_frusta_cut_each_other_by_depth(gl_ctx, caster):
    # Drawn together, each pixel keeps the nearer of the two frusta: gl_FragDepth is the
    # hit's depth, not the bounding pyramid's.
    a = frusta_chain([[-1, 0.5, 0], [1, 0.5, 0]], 0.3)
    b = frusta_chain([[0, 0, -1], [0, 1, 1]], 0.25)
    camera = look_at(join(a, b), (0.5, 0.6, 1.0))
    both = caster.render(join(a, b), camera).distance
    nearer = np.minimum(caster.render(a, camera).distance, caster.render(b, camera).distance)
    overlap = np.isfinite(both)
    assert np.array_equal(overlap, np.isfinite(nearer))
    rel = np.abs(both[overlap] - nearer[overlap]) / nearer[overlap]
    assert rel.max() < 1e-5   # the same float32 ray per pixel, so near-identical distances
    # and the pyramids really do overlap on screen where the surfaces interpenetrate
    assert np.sum(np.isfinite(caster.render(a, camera).distance)
                  & np.isfinite(caster.render(b, camera).distance)) > 100


def test_the_ground_cuts_a_frustum_that_reaches_below_it(gl_ctx, caster):
    frusta = frusta_chain([[0, -1, 0], [0, 1.5, 0]], 0.4)
    camera = Camera((2.5, 1.2, 3.0), (0, 0.2, 0), (0, 1, 0), 40.0, W, H)
    ground = Ground(size=8.0, height=0.0, material="sand")
    result = caster.render(frusta, camera, ground=ground)
    points, hit = hit_points(camera, result.distance)
    below = points[:, 1] < -1e-3
    assert not below.any(), "nothing below the ground is visible"
    on_ground = np.abs(points[:, 1]) < 1e-4
    on_cone = surface_distance(frusta, points) < 1e-4
    assert np.all(on_ground | on_cone)
    assert on_ground.sum() > 100 and on_cone.sum() > 100


# ---------------------------------------------------------------------------- contract
def test_the_pyramid_template_is_closed_and_wound_outwards():
    assert PYRAMID_CORNERS.shape == (8, 3) and PYRAMID_TRIANGLES.shape == (12, 3)
    # every directed edge appears once and its reverse once: a closed, oriented surface
    edges = np.concatenate([PYRAMID_TRIANGLES[:, [0, 1]], PYRAMID_TRIANGLES[:, [1, 2]],
                            PYRAMID_TRIANGLES[:, [2, 0]]])
    directed = {tuple(e) for e in edges.tolist()}
    assert len(directed) == 36 and all((b, a) in directed for a, b in directed)
    # in the right-handed frame (ref_dir, axis, ref_dir x axis) the enclosed volume is positive
    sx, sz, end = PYRAMID_CORNERS.T
    box = np.stack([sx, 2 * end - 1, sz], axis=1).astype(np.float64)
    a, b, c = (box[PYRAMID_TRIANGLES[:, i]] for i in range(3))
    assert np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6 == pytest.approx(8.0)


def test_records_are_compact_and_relative_to_the_eye():
    frusta = HARD_CASES["far_from_origin"]
    eye = frusta.base[0] + [3.0, 1.0, 2.0]
    rec = pack_records(frusta, eye)
    assert rec.dtype == np.float32 and rec.shape == (len(frusta.length), 24)
    assert RECORD_BYTES == rec.itemsize * rec.shape[1] == 96
    # positions far from the world origin keep their digits: the record holds base - eye
    assert np.allclose(rec[:, :3], frusta.base - eye, rtol=1e-7, atol=1e-6)
    # plane offsets are relative to each row's base point (formed in float64, as the
    # reference uploads them): small numbers, not the 1e4 of world coordinates
    top = frusta.length[:, None] * frusta.axis
    assert np.allclose(rec[:, 15], 0.0, atol=1e-6)       # plane_lo passes through the base
    assert np.allclose(np.einsum("ij,ij->i", rec[:, 16:19], top), rec[:, 19], rtol=1e-6, atol=1e-6)


def test_renders_are_deterministic(gl_ctx, caster):
    frusta = HARD_CASES["bent_chain"]
    camera = look_at(frusta, (0.6, 0.35, 1.0))
    for settings in (RaycastSettings(), RaycastSettings(relief=True, linear_steps=8)):
        runs = [caster.render(frusta, camera, settings) for _ in range(2)]
        assert np.array_equal(runs[0].color, runs[1].color)
        assert np.array_equal(runs[0].distance.view(np.uint32), runs[1].distance.view(np.uint32))


# ---------------------------------------------------------------------------- relief
TEX_W, TEX_H = 64, 16


def bilinear(table, u, v):
    """Height in [0, 1] of a (TEX_H, TEX_W) uint8 map at (u, v): u repeats, v clamps,
    texel centres at (i + 0.5) / size (the sampling the shader implements)."""
    h = table.astype(np.float64) / 255
    x, y = u * TEX_W - 0.5, np.clip(v, 0, 1) * TEX_H - 0.5
    i, j = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - i, y - j
    i0, i1 = i % TEX_W, (i + 1) % TEX_W
    j0, j1 = np.clip(j, 0, TEX_H - 1), np.clip(j + 1, 0, TEX_H - 1)
    top = (1 - fx) * h[j0, i0] + fx * h[j0, i1]
    bottom = (1 - fx) * h[j1, i0] + fx * h[j1, i1]
    return (1 - fy) * top + fy * bottom


def height_table(kind):
    u = (np.arange(TEX_W) + 0.5) / TEX_W
    v = (np.arange(TEX_H) + 0.5) / TEX_H
    if kind == "ribs":      # depends on u only, like the saguaro's ribs
        w = 0.5 + 0.5 * np.cos(2 * np.pi * 6 * u)[None, :] + 0 * v[:, None]
    else:                   # a helix: depends on u and v
        w = 0.5 + 0.5 * np.cos(2 * np.pi * (3 * u[None, :] + 2 * v[:, None]))
    return np.round(255 * w).astype(np.uint8)


@pytest.fixture
def relief_caster(monkeypatch):
    """A Raycaster whose height maps are the given table for every material."""
    def make(table):
        monkeypatch.setattr(render_materials, "material_height_maps",
                            lambda names: (np.repeat(table[None], max(len(names), 1), axis=0),
                                           np.ones((MAX_MATERIALS, 2), np.float32)))
        return Raycaster()
    return make


def relief_coordinates(frusta, points):
    """Relief height w of (12) (a fraction of the relief's depth there), u of (6) and exact v
    of (7) of points near row 0."""
    i = 0
    axis, ref = frusta.axis[i], frusta.ref_dir[i]
    e = points - frusta.base[i]
    y = e @ axis
    perp = e - y[:, None] * axis
    radial = np.linalg.norm(perp, axis=1)
    k = (frusta.r2[i] - frusta.r1[i]) / frusta.length[i]
    # the relief is shell·r(y)/max(r1, r2) deep (relief_scale: it follows the radius)
    depth = frusta.shell[i] * np.clip((frusta.r1[i] + k * y) / max(frusta.r1[i], frusta.r2[i]), 0.0, 1.0)
    w = (radial - (frusta.r1[i] + k * y)) / depth
    u = np.mod(np.arctan2(perp @ np.cross(axis, ref), perp @ ref) / (2 * np.pi), 1.0)
    g = axis + k * perp / radial[:, None]
    s_lo = -(points @ frusta.plane_lo[i, :3] - frusta.plane_lo[i, 3]) / (g @ frusta.plane_lo[i, :3])
    s_hi = -(points @ frusta.plane_hi[i, :3] - frusta.plane_hi[i, 3]) / (g @ frusta.plane_hi[i, :3])
    v = -s_lo / (s_hi - s_lo)
    on_caps = (np.abs(s_lo) < 1e-4) | (np.abs(s_hi) < 1e-4)
    return w, u, v, on_caps


RELIEF_SEGMENT = frusta_chain([[0, 0, 0], [0, 2, 0]], [0.5, 0.35], shell=0.15)


def test_relief_hits_lie_on_the_relief_surface_and_silhouettes_follow_it(gl_ctx, relief_caster):
    table = height_table("ribs")
    caster = relief_caster(table)
    frusta = RELIEF_SEGMENT
    camera = look_at(frusta, (0.6, 0.35, 1.0))
    result = caster.render(frusta, camera, RaycastSettings(relief=True, march="fixed",
                                                           linear_steps=64, binary_steps=8))
    points, hit = hit_points(camera, result.distance)
    w, u, v, on_caps = relief_coordinates(frusta, points)
    side = ~on_caps
    assert np.all((w[side] > -1e-4) & (w[side] < 1 + 1e-4)), "side hits lie inside the shell"
    # cap hits lie on the cutting plane within the relief's cross-section
    assert on_caps.any() and np.all(w[on_caps] <= bilinear(table, u, v)[on_caps] + 1e-3)
    residual = np.abs(w - bilinear(table, u, v))[side]
    assert np.percentile(residual, 99) < 2e-3 and residual.max() < 1e-2
    # silhouettes: rays through the outer cone that pass between ribs are discarded
    outer = frusta_chain([[0, 0, 0], [0, 2, 0]], [0.65, 0.5])
    inner = frusta_chain([[0, 0, 0], [0, 2, 0]], [0.5, 0.35])
    outer_hit = np.isfinite(caster.render(outer, camera).distance)
    inner_hit = np.isfinite(caster.render(inner, camera).distance)
    assert np.all(hit <= outer_hit) and np.all(inner_hit <= hit)
    assert (outer_hit & ~hit).sum() > 20
    holes, speckles = holes_and_speckles(hit)
    assert holes == 0


def test_relief_error_falls_as_the_steps_rise(gl_ctx, relief_caster):
    table = height_table("helix")
    caster = relief_caster(table)
    frusta = RELIEF_SEGMENT
    camera = look_at(frusta, (0.6, 0.35, 1.0))
    errors = []
    for linear, binary in ((2, 0), (4, 1), (8, 2), (16, 4), (64, 8)):
        result = caster.render(frusta, camera, RaycastSettings(relief=True, v_exact=True, march="fixed",
                                                               linear_steps=linear,
                                                               binary_steps=binary))
        points, _ = hit_points(camera, result.distance)
        w, u, v, on_caps = relief_coordinates(frusta, points)
        errors.append(np.mean(np.abs(w - bilinear(table, u, v))[~on_caps]))
    # measured: each doubling of the work lowers the mean distance from the relief surface
    assert all(b < a for a, b in pairwise(errors)), errors
    assert errors[-1] < errors[0] / 100, errors


def test_exact_v_follows_oblique_planes_where_interpolated_v_swims(gl_ctx, relief_caster):
    table = height_table("helix")
    caster = relief_caster(table)
    steps = {"march": "fixed", "linear_steps": 64, "binary_steps": 8}
    oblique = frusta_chain([[0, 0, 0], [0, 2, 0]], [0.5, 0.35], shell=0.15,
                           tilt_ends=([0.6, 1, 0], [-0.5, 1, 0.4]))
    mean_error = {}
    for name, frusta in (("square", RELIEF_SEGMENT), ("oblique", oblique)):
        camera = look_at(frusta, (0.6, 0.35, 1.0))
        for v_exact in (False, True):
            result = caster.render(frusta, camera, RaycastSettings(relief=True, v_exact=v_exact,
                                                                   **steps))
            points, _ = hit_points(camera, result.distance)
            w, u, v, on_caps = relief_coordinates(frusta, points)
            mean_error[name, v_exact] = np.mean(np.abs(w - bilinear(table, u, v))[~on_caps])
    # parallel planes: interpolating v is exact (§3); oblique planes: only V_EXACT is
    assert mean_error["square", False] < 1e-3 and mean_error["square", True] < 1e-3
    assert mean_error["oblique", True] < 1e-3
    assert mean_error["oblique", False] > 5 * mean_error["oblique", True]


@pytest.mark.parametrize("case", ["bent_chain", "crossing", "fat", "flare_oblique"])
def test_auto_camera_makes_the_model_span_most_of_the_viewport(gl_ctx, caster, case):
    frusta = HARD_CASES[case]
    camera = auto_camera(frusta, W, H)
    hit = np.isfinite(caster.render(frusta, camera).distance)
    rows, cols = np.nonzero(hit)
    # nothing is cut off at the border ...
    assert rows.min() > 0 and cols.min() > 0 and rows.max() < H - 1 and cols.max() < W - 1
    # ... and the model reaches most of the way across in its tighter direction
    span = max((rows.max() - rows.min() + 1) / H, (cols.max() - cols.min() + 1) / W)
    assert span > 0.7


def test_only_what_the_settings_ask_for_is_compiled_and_run(gl_ctx):
    caster = Raycaster()
    frusta = HARD_CASES["cylinder"]
    camera = look_at(frusta, (0.6, 0.35, 1.0))
    plain = caster.render(frusta, camera)
    assert plain.stats.passes == ["sky", "frusta"]
    assert plain.stats.program[1] == {"RELIEF": False, "V_EXACT": False, "MARCH_FIXED": False,
                                      "HEIGHT_FETCH4": False, "SCREEN_PROXY": False, "LABELS": False}
    # programs_used: (file, names of the defines switched on) of every program a frame used
    assert ("raycast.glsl", ()) in caster.programs_used
    assert all("RELIEF" not in defines for _, defines in caster.programs_used)
    # a different size reuses the programs with a new framebuffer, without a GL error
    ground = Ground(size=6.0, height=0.0, material="sand")
    small = caster.render(frusta, look_at(frusta, (0.6, 0.35, 1.0), width=64, height=48),
                          RaycastSettings(relief=True), ground=ground)
    assert small.distance.shape == (48, 64) and small.stats.passes == ["sky", "ground", "frusta"]
    # a segment without a shell is not marched even in the relief program: same surface
    assert np.array_equal(np.isfinite(caster.render(frusta, camera, RaycastSettings(relief=True)).distance),
                          np.isfinite(plain.distance))


# ---------------------------------------------------------------------------- skinned skeletons
def skinned_cases():
    from _geometry_helpers import chain_skeleton, random_tree, y_junction

    from plantgen.geometry.skeletons.skin import skin_skeleton

    cases = {f"bend_{b:g}": chain_skeleton([b, b / 2], lengths=1.0, radii=[0.2, 0.18, 0.15, 0.1])
             for b in (0.0, 1e-8 * 180 / np.pi, 45.0, 90.0, 135.0, 179.0)}
    cases["fold_back"] = chain_skeleton([180.0], lengths=1.0, radii=0.15)
    cases["short_next_to_long"] = chain_skeleton([20.0, 20.0], lengths=[2.0, 0.01, 2.0], radii=0.1)
    cases["y_junction"] = y_junction(40.0)
    cases["far_away"] = chain_skeleton([30.0, 60.0], radii=0.15, start=(1e4, 1e4, -1e4))
    cases["random_tree"] = random_tree(40, seed=3)
    return {name: skin_skeleton(skel) for name, skel in cases.items()}


@pytest.fixture(scope="module")
def skinned():
    return skinned_cases()


SKINNED = ["bend_0", "bend_5.72958e-07", "bend_45", "bend_90", "bend_135", "bend_179",
           "fold_back", "short_next_to_long", "y_junction", "far_away", "random_tree"]


@pytest.mark.parametrize("name", SKINNED)
def test_skinned_skeletons_render_on_the_surface_without_holes(gl_ctx, caster, skinned, name):
    frusta = skinned[name]
    for direction in ((0.6, 0.35, 1.0), (0.1, -1.0, 0.2)):
        camera = auto_camera(frusta, W, H, direction=direction)
        result = caster.render(frusta, camera, material_names=frusta.material_names)
        assert not np.isnan(result.distance).any()
        points, hit = hit_points(camera, result.distance)
        size = np.linalg.norm(np.subtract(*model_box(frusta)))
        eye_dist = np.linalg.norm(points - np.asarray(camera.eye), axis=1)
        off = surface_distance(frusta, points)
        assert np.all(off <= 2e-5 * eye_dist + 1e-6 * size), f"worst {off.max():.3g}"
        oracle = caster.render(frusta, camera, RaycastSettings(proxy="screen")).distance
        assert np.array_equal(np.isfinite(oracle), hit), "a bounding pyramid lost pixels"
        if name != "random_tree":      # a lone miss between two close branches is no hole
            assert holes_and_speckles(hit) == (0, 0)
        # relief: the pyramids (grown by the shell) cover the relief shells as well
        relief = RaycastSettings(relief=True, linear_steps=16, binary_steps=4)
        shelled = caster.render(frusta, camera, relief, frusta.material_names).distance
        oracle = caster.render(frusta, camera, RaycastSettings(relief=True, linear_steps=16,
                                                               binary_steps=4, proxy="screen"),
                               frusta.material_names).distance
        assert np.array_equal(np.isfinite(oracle), np.isfinite(shelled))
        assert np.all(np.isfinite(shelled) >= hit)   # relief only adds to the base cone


# ---------------------------------------------------------------------------- the reference
def silhouette_edges(hit):
    """Pixels whose 3x3 neighbourhood holds both hits and misses of the reference."""
    padded = np.pad(hit, 1, mode="edge")
    edges = np.zeros_like(hit)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            edges |= padded[1 + dy:1 + dy + hit.shape[0], 1 + dx:1 + dx + hit.shape[1]] != hit
    return edges


AGREEMENT_CASES = list(HARD_CASES) + SKINNED


@pytest.mark.parametrize("name", AGREEMENT_CASES)
def test_agrees_with_the_float64_reference(gl_ctx, caster, skinned, name):
    from plantgen.geometry.rays.reference import render_reference

    frusta = HARD_CASES[name] if name in HARD_CASES else skinned[name]
    direction = (0.6, 0.35, 1.0) if AGREEMENT_CASES.index(name) % 2 == 0 else (0.1, -1.0, 0.2)
    if name in CLOSE_UP:
        camera = look_at(frusta, direction, distance=CLOSE_UP[name])
    else:
        camera = auto_camera(frusta, W, H, direction=direction)
    gl = caster.render(frusta, camera, material_names=frusta.material_names).distance
    ref = render_reference(frusta, camera)                        # float64
    emulated = render_reference(frusta, camera, dtype=np.float32)  # the GPU's float32, on the CPU
    assert not np.isnan(gl).any()
    hit = np.isfinite(gl)
    assert ref.hit.any()
    # hit/miss agrees on >= 99.5% of pixels, and every disagreement is on a silhouette edge
    disagree = hit != ref.hit
    edges = silhouette_edges(ref.hit)
    assert disagree.mean() <= 0.005 and not (disagree & ~edges).any()
    # the depth error stays inside what the float32 emulation predicts (with a margin of
    # 4x and a few ulps: the GPU's rounding differs from numpy's in detail)
    both = hit & ref.hit & ~edges & np.isfinite(emulated.t)
    rel = np.abs(gl[both] - ref.t[both]) / ref.t[both]
    rel32 = np.abs(emulated.t[both] - ref.t[both]) / ref.t[both]
    ulp = np.finfo(np.float32).eps
    assert rel.max() <= 4 * rel32.max() + 8 * ulp, (rel.max(), rel32.max())
    assert np.percentile(rel, 99) <= 4 * np.percentile(rel32, 99) + 4 * ulp


def relief_cases():
    from _geometry_helpers import chain_skeleton, y_junction

    from plantgen.geometry.skeletons.skin import skin_skeleton

    return {"bark_chain": skin_skeleton(chain_skeleton([30.0, 40.0], radii=[0.3, 0.25, 0.2, 0.15])),
            "y_junction": skin_skeleton(y_junction(40.0))}


@pytest.mark.parametrize("name", ["bark_chain", "y_junction"])
def test_relief_agrees_with_the_reference_and_its_error_falls_with_the_steps(gl_ctx, caster, name):
    from plantgen.geometry.rays.reference import render_reference

    frusta = relief_cases()[name]
    assert (frusta.shell > 0).all()
    camera = auto_camera(frusta, 96, 72)
    ref = render_reference(frusta, camera, relief=True)   # dense marching + bisection, float64
    edges = silhouette_edges(ref.hit)
    errors = []
    for linear, binary in ((4, 0), (8, 2), (16, 4), (64, 6), (256, 10)):
        settings = RaycastSettings(relief=True, v_exact=True, march="fixed", linear_steps=linear,
                                   binary_steps=binary)
        gl = caster.render(frusta, camera, settings, frusta.material_names).distance
        hit = np.isfinite(gl)
        both = hit & ref.hit
        rel = np.abs(gl[both] - ref.t[both]) / ref.t[both]
        errors.append(np.median(rel))
    disagree = hit != ref.hit   # at the highest step count
    assert disagree.mean() <= 0.005 and not (disagree & ~edges).any()
    assert np.percentile(rel, 99) < 1e-5
    # measured, not assumed: every step up lowers the (median) depth error against the
    # reference, from ~1e-3 at 4 steps to ~1e-7 at 256 + 10
    assert all(b < a for a, b in pairwise(errors)), errors
    assert errors[-1] < 1e-6, errors
