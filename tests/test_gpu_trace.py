"""The GPU traversal of the BVH (shaders/bvh.glsl through plantgen.gl.trace) against the
float64 reference, hit for hit: the same primitive for >= 99.9 % of random rays, t within
float32 rounding; far from the origin, grazing rays, any hit, instanced scenes.

The reference is brute force in float64 (every ray against every primitive,
plantgen.geometry.rays.scan.cast_first_returns), so the tests also prove that the hierarchy
loses no hit. Models are small (a few hundred primitives, a few thousand rays).
"""

from __future__ import annotations

import numpy as np
import pytest
from _geometry_helpers import random_tree
from hypothesis import given, settings
from hypothesis import strategies as st

from plantgen.errors import PlantgenError
from plantgen.geometry.rays.bvh import BVH, build_bvh
from plantgen.geometry.rays.instances import place_frusta
from plantgen.geometry.rays.reference import row_boxes
from plantgen.geometry.rays.scan import ScanTarget, cast_first_returns, scan_target
from plantgen.geometry.skeletons.frusta import Frusta
from plantgen.gl.trace import BVH_STACK, LEAF_COUNT_BITS, GpuPlant, trace_rays, upload_bvh

#: float32 rounding of a hit's distance: the cone's quadratic in float32 after
#: re-centring loses a few ulps more where the ray is oblique (measured: ~1e-6 at worst).
T_RELATIVE = 2e-5


def _skeleton(n, seed, shift=(0.0, 0.0, 0.0)):
    sk = random_tree(n, seed=seed)
    shift = np.asarray(shift, np.float64)
    from dataclasses import replace
    return replace(sk, start=sk.start + shift, end=sk.end + shift)


def _target(n=120, seed=3, shift=(0.0, 0.0, 0.0), leaves=40):
    """A random tree's rows and ``leaves`` random triangles among its branches."""
    sk = _skeleton(n, seed, shift)
    target = scan_target(sk)
    rng = np.random.default_rng(seed)
    centre = rng.uniform(sk.end.min(0), sk.end.max(0), size=(leaves, 3))
    tri = centre[:, None, :] + rng.normal(scale=0.25, size=(leaves, 3, 3))
    pad = 1e-9 * np.abs(tri).max(axis=(1, 2))[:, None] + 1e-12
    lo = np.concatenate([target.lo, tri.min(1) - pad])
    hi = np.concatenate([target.hi, tri.max(1) + pad])
    return ScanTarget(target.frusta, tri, np.arange(leaves), lo, hi, target.segment_order, target.segment_plant,
                      np.full(leaves, -1, np.int64), np.zeros(leaves, np.int64), target.base)


def _random_rays(lo, hi, m, seed, margin=2.0):
    """Rays from random points around the boxes (lo, hi) (k, 3), half of them aimed at a
    random point of a random box (most hit), half anywhere in the whole box."""
    rng = np.random.default_rng(seed)
    box = np.stack([lo.min(axis=0), hi.max(axis=0)])
    origins = rng.uniform(box[0] - margin, box[1] + margin, size=(m, 3))
    aims = rng.uniform(box[0], box[1], size=(m, 3))
    pick = rng.integers(0, len(lo), m // 2)
    aims[: m // 2] = lo[pick] + rng.random((m // 2, 3)) * (hi[pick] - lo[pick])
    return origins, aims - origins


def _upload(gl_ctx, target, **build):
    bvh = build_bvh(target.lo, target.hi, **build)
    return upload_bvh(gl_ctx, [GpuPlant(target.frusta, target.triangles, bvh)])


def _compare(t, prim, ref_t, ref_prim, *, min_same=0.999, t_relative=T_RELATIVE):
    same = prim == ref_prim
    assert same.mean() >= min_same, f"{(~same).sum()} of {len(same)} rays hit another primitive"
    both = same & (ref_prim >= 0)
    assert both.sum() > 0.1 * len(t)
    rel = np.abs(t[both] - ref_t[both]) / ref_t[both]
    assert rel.max() <= t_relative, rel.max()
    assert np.isinf(t[prim < 0]).all()


def _assert_t_rounding(t, ref_t, origins, dirs, frame_origin):
    """t against the reference's within float32 rounding of the hit point: of the ray's
    origin relative to the GPU's frame origin as much as of the distance travelled."""
    norm = np.linalg.norm(dirs, axis=1)
    scale = np.maximum(ref_t * norm, np.linalg.norm(origins - frame_origin, axis=1))
    error = np.abs(t - ref_t) * norm
    assert (error <= T_RELATIVE * scale).all(), (error / scale).max()


def _assert_same_beams(ref, got):
    """Scanner by scanner: the same beams return (>= 99.9 %), >= 99.9 % of them from the
    same primitive, and there with the reference's range exactly."""
    for a, b in zip(ref, got, strict=True):
        assert len(a.beam) > 1000
        common, ia, ib = np.intersect1d(a.beam, b.beam, return_indices=True)
        assert len(common) >= 0.999 * max(len(a.beam), len(b.beam))
        same = a.primitive[ia] == b.primitive[ib]
        assert same.mean() >= 0.999
        np.testing.assert_array_equal(a.range[ia][same], b.range[ib][same])


@pytest.mark.parametrize("shift", [(0.0, 0.0, 0.0), (1e4, -1e4, 5e3)], ids=["origin", "far"])
@pytest.mark.parametrize("method", ["lbvh", "sah"])
def test_closest_hit_matches_the_float64_reference(gl_ctx, shift, method):
    target = _target(shift=shift)
    gpu = _upload(gl_ctx, target, method=method)
    origins, dirs = _random_rays(target.lo, target.hi, 2500, seed=1)
    t, prim, copy, _ = trace_rays(gpu, origins, dirs, chunk=1000)   # three chunks
    ref_t, ref_prim = cast_first_returns(target, origins, dirs)
    _compare(t, prim, ref_t, ref_prim)
    assert set(np.unique(copy)) <= {-1, 0}
    assert (prim >= target.rows).any() and ((prim >= 0) & (prim < target.rows)).any()   # leaves and rows


@pytest.mark.parametrize("shift", [(0.0, 0.0, 0.0), (1e4, 0.0, 0.0)], ids=["origin", "far"])
def test_grazing_rays_find_the_reference_primitive(gl_ctx, shift):
    """Rays that graze a row's cone (tangent to it at a random point, moved 1e-4 of the
    radius out or in: about 0.8 degrees from the surface where they cross it) and rays
    that graze a leaf triangle (0.06 degrees from its plane): the GPU picks the
    reference's primitive for >= 99.9 % of them, 1e4 units from the origin too. (Closer
    to tangency than float32 resolves, about 1e-5 of the radius here, hit or miss is
    decided by rounding on either side: the float64 re-solve of the caller settles it.)"""
    target = _target(shift=shift)
    f = target.frusta
    rng = np.random.default_rng(5)
    m = 1500
    rows = rng.integers(0, len(f), m)
    y = rng.uniform(0.1, 0.9, m) * f.length[rows]
    radius = f.r1[rows] + (f.r2[rows] - f.r1[rows]) / f.length[rows] * y
    radial = rng.normal(size=(m, 3))
    radial -= np.einsum("ij,ij->i", radial, f.axis[rows])[:, None] * f.axis[rows]
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    side = np.where(np.arange(m) % 2 == 0, 1.0 + 1e-4, 1.0 - 1e-4)     # just outside, just inside
    point = f.base[rows] + y[:, None] * f.axis[rows] + (side * radius)[:, None] * radial
    tangent = np.cross(radial, f.axis[rows])                           # around the axis
    tri = target.triangles
    j = rng.integers(0, len(tri), 500)
    along = tri[j, 1] - tri[j, 0]
    normal = np.cross(tri[j, 1] - tri[j, 0], tri[j, 2] - tri[j, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    along = along + 1e-3 * np.linalg.norm(along, axis=1)[:, None] * normal
    origins = np.concatenate([point - 3.0 * tangent, tri[j].mean(axis=1) - 2.0 * along])
    dirs = np.concatenate([tangent, along])
    gpu = _upload(gl_ctx, target)
    t, prim, _, _ = trace_rays(gpu, origins, dirs)
    ref_t, ref_prim = cast_first_returns(target, origins, dirs)
    assert (ref_prim[:m:2] != rows[::2]).all() and (ref_prim[1:m:2] == rows[1::2]).mean() > 0.8
    assert (ref_prim[m:] == j + target.rows).all()
    # a grazing hit's t is ill-conditioned (its error grows as 1/sin of the angle to the
    # surface): the callers solve it again in float64; here it is only near the reference
    _compare(t, prim, ref_t, ref_prim, t_relative=1e-2)


def test_any_hit_finds_a_hit_exactly_where_the_closest_hit_does(gl_ctx):
    target = _target()
    gpu = _upload(gl_ctx, target)
    origins, dirs = _random_rays(target.lo, target.hi, 2000, seed=2)
    t, prim, _, _ = trace_rays(gpu, origins, dirs)
    any_t, any_prim, _, _ = trace_rays(gpu, origins, dirs, any_hit=True)
    assert ((any_prim >= 0) == (prim >= 0)).mean() >= 0.999
    hit = (any_prim >= 0) & (prim >= 0)
    assert (any_t[hit] >= t[hit] * (1 - T_RELATIVE)).all()     # never before the closest
    # the primitive it names is hit there (float64)
    check_t, _ = cast_first_returns(target, origins[hit], dirs[hit], primitives=any_prim[hit])
    assert (np.abs(check_t - any_t[hit]) <= T_RELATIVE * check_t).mean() >= 0.999
    # the segment (t_min, t_max) bounds it: just before the closest hit there is none
    short_t, short_prim, _, _ = trace_rays(gpu, origins, dirs, any_hit=True, t_max=np.where(prim >= 0, 0.999 * t, 1.0))
    assert (short_prim[prim >= 0] < 0).mean() >= 0.999
    assert (short_t[short_prim >= 0] < 1.0).all()
    # and t_min skips the closest hit: the next one is further
    later_t, later_prim, _, _ = trace_rays(gpu, origins, dirs, t_min=np.where(prim >= 0, 1.001 * t, 0.0))
    assert (later_t[prim >= 0] > t[prim >= 0]).all()


def _copy_boxes(bvh, matrices):
    """World boxes of a plant's root box under each matrix (k, 4, 4)."""
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float64)
    pts = bvh.lo[0] + corners * (bvh.hi[0] - bvh.lo[0])
    world = np.einsum("kij,pj->kpi", matrices[:, :3, :3], pts) + matrices[:, None, :3, 3]
    return world.min(axis=1), world.max(axis=1)


def _similarities(m, seed, spread):
    rng = np.random.default_rng(seed)
    out = np.zeros((m, 4, 4))
    for i in range(m):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        q *= np.sign(np.linalg.det(q))
        out[i, :3, :3] = rng.uniform(0.5, 2.0) * q
        out[i, :3, 3] = rng.uniform(-spread, spread, 3)
        out[i, 3, 3] = 1.0
    return out


@pytest.mark.parametrize("offset", [0.0, 1e4], ids=["origin", "far"])
def test_two_levels_match_the_merged_reference(gl_ctx, offset):
    """Two distinct plants, 12 copies turned, scaled and moved: the GPU's (copy, row)
    is the merged model's row for >= 99.9 % of rays, t within float32 rounding."""
    plants = [_target(60, seed=7, leaves=0), _target(40, seed=8, leaves=0)]
    blas = [build_bvh(p.lo, p.hi) for p in plants]
    matrices = _similarities(12, seed=9, spread=6.0)
    matrices[:, :3, 3] += offset
    copy_plant = np.arange(12) % 2
    lo, hi = np.zeros((12, 3)), np.zeros((12, 3))
    for k in (0, 1):
        lo[copy_plant == k], hi[copy_plant == k] = _copy_boxes(blas[k], matrices[copy_plant == k])
    top = build_bvh(lo, hi, leaf_size=2)
    gpu = upload_bvh(gl_ctx, [GpuPlant(p.frusta, None, b) for p, b in zip(plants, blas, strict=True)],
                     origin=np.full(3, offset), top=top, matrices=matrices, copy_plant=copy_plant)
    assert gpu.two_level and gpu.copies == 12
    # the merged reference: copy by copy, its rows placed in the world
    parts = [place_frusta(plants[copy_plant[c]].frusta, matrices[c]) for c in range(12)]
    first_row = np.concatenate([[0], np.cumsum([len(p) for p in parts])])
    merged = Frusta.concatenate(parts)
    r_lo, r_hi = row_boxes(merged)
    target = ScanTarget(merged, np.zeros((0, 3, 3)), np.zeros(0, np.int64), r_lo, r_hi, np.zeros(len(merged), np.int64),
                        np.zeros(len(merged), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(3))
    origins, dirs = _random_rays(r_lo, r_hi, 2000, seed=4)
    t, prim, copy, _ = trace_rays(gpu, origins, dirs)
    ref_t, ref_prim = cast_first_returns(target, origins, dirs)
    row = np.where(prim >= 0, first_row[np.maximum(copy, 0)] + prim, -1)
    _compare(t, row, ref_t, ref_prim)
    any_t, any_prim, any_copy, _ = trace_rays(gpu, origins, dirs, any_hit=True)
    assert ((any_prim >= 0) == (prim >= 0)).mean() >= 0.999


def _quat_turn(u, v):
    """shaders/bvh.glsl's bvh_quat_turn in float64: u v conj(u) for (k, 4) u, (k, 3) v."""
    w, x = u[:, 3:], u[:, :3]
    return (w * w - (x * x).sum(1, keepdims=True)) * v + 2 * (x * v).sum(1, keepdims=True) * x \
        + 2 * w * np.cross(x, v)


def test_a_copys_32_byte_map_is_its_inverse_placement():
    """The quaternion map of a similarity copy (applied as the shader does, here in
    float64) takes a world point to the plant frame as the float64 inverse does, to
    float32 rounding; its plant index survives the packing; turned back it gives the
    world normal."""
    from plantgen.gl.trace import copy_words

    matrices = _similarities(50, seed=21, spread=1e4)
    centres = np.random.default_rng(22).normal(size=(3, 3))
    plant = np.arange(50) % 3
    origin = np.array([100.0, -50.0, 20.0])
    words, affine = copy_words(matrices, plant, centres, origin)
    assert not affine and words.shape == (50, 8) and words.dtype == np.float32
    np.testing.assert_array_equal(words[:, 7].view(np.int32), plant)
    u, offset = words[:, :4].astype(np.float64), words[:, 4:7].astype(np.float64)
    x = np.random.default_rng(23).normal(scale=5.0, size=(50, 3)) + matrices[:, :3, 3]
    got = _quat_turn(u, x - origin - offset)
    want = np.einsum("kij,kj->ki", np.linalg.inv(matrices)[:, :3, :3], x - matrices[:, :3, 3]) - centres[plant]
    size = np.linalg.norm(x - origin, axis=1) / np.cbrt(np.linalg.det(matrices[:, :3, :3]))
    assert (np.linalg.norm(got - want, axis=1) <= 1e-6 * size).all()
    n = np.random.default_rng(24).normal(size=(50, 3))
    back = _quat_turn(u * [-1, -1, -1, 1], n)
    world = np.einsum("kij,kj->ki", matrices[:, :3, :3], n)
    np.testing.assert_allclose(back / np.linalg.norm(back, axis=1, keepdims=True),
                               world / np.linalg.norm(world, axis=1, keepdims=True), atol=1e-6)


@pytest.mark.parametrize("kind", ["mirror", "uneven"])
def test_copies_that_are_not_similarities_keep_full_maps(gl_ctx, kind):
    """A scene with one copy mirrored or scaled unevenly (possible through the API only)
    keeps the 64-byte 3x4 maps for all its copies, and still traces as the float64
    two-level reference does, copy for copy and row for row; without it, 32 bytes."""
    from plantgen.geometry.rays.bvh import scene_bvh, trace_scene
    from plantgen.geometry.rays.scan import target_hits
    from plantgen.gl.trace import AFFINE_COPY_BYTES, COPY_BYTES

    plant = _target(50, seed=31, leaves=0)
    blas = build_bvh(plant.lo, plant.hi)
    matrices = _similarities(16, seed=32, spread=8.0)
    odd = np.diag([-1.0, 1.0, 1.0, 1.0]) if kind == "mirror" else np.diag([1.0, 2.5, 0.6, 1.0])
    bent = matrices.copy()
    bent[5] = bent[5] @ odd
    uploads = {}
    for name, m in (("similar", matrices), (kind, bent)):
        scene = scene_bvh([blas], [m])
        gpu = upload_bvh(gl_ctx, [GpuPlant(plant.frusta, None, blas)], top=scene.tlas, matrices=scene.matrix,
                         copy_plant=scene.plant)
        uploads[name] = (scene, gpu)
    assert not uploads["similar"][1].affine and uploads[kind][1].affine
    assert uploads[kind][1].nbytes - uploads["similar"][1].nbytes == 16 * (AFFINE_COPY_BYTES - COPY_BYTES)
    scene, gpu = uploads[kind]
    origins, dirs = _random_rays(scene.copy_lo, scene.copy_hi, 2000, seed=33)
    centres = 0.5 * (plant.lo + plant.hi) @ bent[5, :3, :3].T + bent[5, :3, 3]       # the odd copy's rows
    o5, d5 = _random_rays(centres, centres, 500, seed=34)
    origins, dirs = np.concatenate([origins, o5]), np.concatenate([dirs, d5])
    t, prim, copy, _ = trace_rays(gpu, origins, dirs)
    ref_t, ref_copy, ref_prim = trace_scene(scene, origins, dirs, [target_hits(plant)])
    rows = len(plant.frusta)
    key = np.where(prim >= 0, copy * rows + prim, -1)
    ref_key = np.where(ref_prim >= 0, ref_copy * rows + ref_prim, -1)
    same = key == ref_key
    assert same.mean() >= 0.999
    hit = same & (ref_key >= 0)
    assert hit.sum() > 0.1 * len(t) and (hit & (ref_copy == 5)).sum() >= 100   # the odd copy is hit, alike
    _assert_t_rounding(t[hit], ref_t[hit], origins[hit], dirs[hit], gpu.origin)


def test_an_empty_model_hits_nothing(gl_ctx):
    empty = build_bvh(np.zeros((0, 3)), np.zeros((0, 3)))
    gpu = upload_bvh(gl_ctx, [GpuPlant(None, None, empty)])
    t, prim, copy, _ = trace_rays(gpu, np.zeros((5, 3)), np.ones((5, 3)))
    assert np.isinf(t).all() and (prim == -1).all() and (copy == -1).all()


def test_a_tree_deeper_than_the_stack_is_refused(gl_ctx):
    """A chain of BVH_STACK + 1 internal nodes (each a leaf on the left): refused in one
    line rather than traced with nodes dropped."""
    inner = BVH_STACK + 1
    nodes = 2 * inner + 1
    first = np.zeros(nodes, np.int32)
    count = np.zeros(nodes, np.int32)
    spine = 2 * np.arange(inner)            # node 0, 2, 4, ...: children 2i+1 (leaf), 2i+2
    first[spine] = spine + 1
    leaves = np.r_[spine + 1, nodes - 1]
    first[leaves], count[leaves] = np.arange(inner + 1), 1
    box = np.zeros((nodes, 3))
    bvh = BVH(box, box + 1.0, first, count, np.arange(inner + 1, dtype=np.int32))
    assert bvh.depth() > BVH_STACK
    with pytest.raises(PlantgenError, match="too deep"):
        upload_bvh(gl_ctx, [GpuPlant(None, None, bvh)])


@pytest.mark.parametrize("any_hit", [False, True], ids=["closest", "any"])
def test_plantgen_trace_float32_is_the_float64_reference(gl_ctx, any_hit):
    """plantgen.trace's float32 path (the GPU finds the primitive, its t is solved again in
    float64) against the float64 path on a grammar with leaves: the same primitive for
    >= 99.9 % of the rays, and there the very same t."""
    from plantgen.pipeline import grow_file, model_leaves, skin_model
    from plantgen.tracer import trace_target

    grown = grow_file("broadleaf")
    target = scan_target(grown.skeleton, model_leaves(grown), frusta=skin_model(grown))
    assert len(target.triangles) and target.rows
    origins, dirs = _random_rays(target.lo, target.hi, 3000, seed=6)
    gpu = trace_target(target, origins, dirs, precision="float32", any_hit=any_hit)
    ref = trace_target(target, origins, dirs, precision="float64", any_hit=any_hit)
    assert (gpu.hit == ref.hit).mean() >= 0.999 and ref.hit.mean() > 0.1
    if not any_hit:
        same = gpu.primitive == ref.primitive
        assert same.mean() >= 0.999
        np.testing.assert_array_equal(gpu.t[same], ref.t[same])
        assert (gpu.part[ref.hit] == 2).any() and (gpu.part[ref.hit] < 2).any()      # leaves and wood


def test_the_scans_gpu_path_gives_the_reference_ranges(gl_ctx):
    """--scan-precision float32 with the GPU's search: each beam's primitive found on the
    GPU, its range solved again in float64: beam for beam the float64 scan's primitive
    (>= 99.9 %) and there exactly its range; the beams stream in chunks (the finder never
    sees more than the chunk), and progress counts every beam."""
    from plantgen.geometry.rays.scan import ScanSettings, beam_returns, scan_plant
    from plantgen.gl.trace import trace_target
    from plantgen.pipeline import grow_file, model_leaves, skin_model

    grown = grow_file("broadleaf")
    leaves, frusta = model_leaves(grown), skin_model(grown)
    target = scan_target(grown.skeleton, leaves, frusta=frusta)
    seen = []

    def finder(tg, origins, dirs):
        seen.append(len(origins))
        return trace_target(tg, origins, dirs)

    ref = beam_returns(target, ScanSettings(angular_step=0.3))
    got = beam_returns(target, ScanSettings(angular_step=0.3, precision="float32"), max_pairs=20000, finder=finder)
    assert max(seen) <= 20000 and len(seen) > 1
    _assert_same_beams(ref, got)
    done = []
    cloud = scan_plant(grown.skeleton, leaves, ScanSettings(angular_step=1.0, precision="float32"), frusta=frusta,
                       finder=finder, progress=lambda stage, d, total: done.append((d, total)))
    assert len(cloud) > 0 and done[-1][0] == done[-1][1] and all(x[0] <= x[1] for x in done)


def test_a_scenes_scan_on_the_gpu_gives_the_reference_ranges(gl_ctx):
    """A scene's scan (each distinct plant once, two levels) with the GPU's search: beam
    for beam the float64 two-level scan's primitive (>= 99.9 %) and there its range."""
    from plantgen.geometry.rays.scan import ScanSettings, beam_returns, scene_target
    from plantgen.gl.trace import trace_target
    from plantgen.pipeline import grow_file

    target = scene_target(grow_file("desert").scene.plants())
    ref = beam_returns(target, ScanSettings(angular_step=0.25, scanners=2))
    got = beam_returns(target, ScanSettings(angular_step=0.25, scanners=2, precision="float32"),
                       finder=lambda tg, o, d: trace_target(tg, o, d))
    _assert_same_beams(ref, got)


def test_one_plant_placed_100000_times_far_from_the_origin(gl_ctx):
    """The two-level traversal against the float64 two-level reference
    (plantgen.geometry.rays.bvh.trace_scene) on one plant placed 100,000 times over 3 km, 1e4
    from the origin: the same (copy, row) for >= 99.9 % of the rays, t within float32
    rounding; the plant is held once, each copy costs its 32-byte map and its share of the
    top level, under 64 bytes in all."""
    from plantgen.geometry.rays.bvh import build_scene_bvh, trace_scene
    from plantgen.geometry.rays.instances import PlacedPlants
    from plantgen.geometry.rays.scan import target_hits
    from plantgen.geometry.skeletons.skin import skin_skeleton
    from plantgen.gl.trace import COPY_BYTES

    skel = _skeleton(30, seed=4)
    matrices = _similarities(100_000, seed=13, spread=1500.0)
    matrices[:, 1, 3] = 0.0
    matrices[:, :3, 3] += [1e4, 0.0, -1e4]
    placed = PlacedPlants.build([("p", skin_skeleton(skel), skel.parent, matrices)])
    scene = build_scene_bvh(placed)
    hits = [target_hits(scan_target(skel, frusta=placed.plants[0].frusta))]
    plant = GpuPlant(placed.plants[0].frusta, None, scene.blas[0])
    gpu = upload_bvh(gl_ctx, [plant], origin=np.array([1e4, 0.0, -1e4]), top=scene.tlas, matrices=scene.matrix,
                     copy_plant=scene.plant)
    alone = upload_bvh(gl_ctx, [plant])
    per_copy = (gpu.nbytes - alone.nbytes) / 100_000
    assert not gpu.affine
    assert COPY_BYTES < per_copy <= 64, per_copy        # the map and the top level's share
    rng = np.random.default_rng(14)
    lo, hi = placed.box
    origins = lo + (hi - lo) * rng.random((400, 3))
    origins[:, 1] = rng.uniform(0, 2, 400)
    dirs = rng.normal(size=(400, 3)) * [1, 0.1, 1]
    t, prim, copy, _ = trace_rays(gpu, origins, dirs)
    ref_t, ref_copy, ref_prim = trace_scene(scene, origins, dirs, hits)
    rows = len(placed.plants[0].frusta)
    key = np.where(prim >= 0, copy * rows + prim, -1)
    ref_key = np.where(ref_prim >= 0, ref_copy * rows + ref_prim, -1)
    assert (ref_key >= 0).sum() >= 40
    same = key == ref_key
    assert same.mean() >= 0.999
    hit = same & (ref_key >= 0)
    # the ray's origins lie up to 1,500 units from the frame's origin here
    _assert_t_rounding(t[hit], ref_t[hit], origins[hit], dirs[hit], [1e4, 0.0, -1e4])


@pytest.mark.parametrize("n", [1, 5, 300, 2000])
def test_wide_nodes_hold_every_primitive_once(n):
    """The GPU's layout: the binary tree collapsed 4-wide keeps every primitive in exactly
    one leaf slot, enters each wide node from one parent (a node's internal children
    consecutive), gives each slot a box holding its binary node's float32 box, and its
    reference the leaf's primitives in the GPU's order; the stack a walk needs is what the
    bound says."""
    from plantgen.geometry.rays.bvh import float32_boxes
    from plantgen.gl.trace import decode_nodes, leaf_order, node_words, stack_need, wide_nodes

    rng = np.random.default_rng(n)
    lo = rng.uniform(-5, 5, (n, 3))
    bvh = build_bvh(lo, lo + rng.uniform(0, 0.5, (n, 3)), leaf_size=2)
    slots, wide = wide_nodes(bvh)
    used = slots >= 0
    leaf = used & (wide < 0)
    prims = np.concatenate([bvh.prims[bvh.first[b]:bvh.first[b] + bvh.count[b]] for b in slots[leaf]])
    assert np.sort(prims).tolist() == list(range(n))
    assert sorted(wide[wide >= 0].tolist()) == list(range(1, len(slots)))
    assert ((wide >= 0) == (used & (bvh.count[np.maximum(slots, 0)] == 0))).all()
    order = leaf_order(bvh, slots, wide)
    assert np.sort(order).tolist() == list(range(n))
    d_lo, d_hi, refs = decode_nodes(node_words(bvh, np.zeros(3), slots, wide))
    f_lo, f_hi = float32_boxes(bvh)
    s = np.maximum(slots, 0)
    assert (d_lo[used] <= f_lo[s][used]).all() and (d_hi[used] >= f_hi[s][used]).all()     # conservative
    assert (refs[wide >= 0] == wide[wide >= 0]).all()
    codes = -1 - refs[leaf]
    first, count = codes >> LEAF_COUNT_BITS, codes & ((1 << LEAF_COUNT_BITS) - 1)
    assert (count == bvh.count[slots[leaf]]).all()
    for b, f, c in zip(slots[leaf], first, count, strict=True):      # the same primitives, in the GPU's order
        assert sorted(order[f:f + c]) == sorted(bvh.prims[bvh.first[b]:bvh.first[b] + c])
    assert (refs[~used] == -1).all()
    # the bound: the largest sum over a root-to-leaf path of (children - 1)
    def need(w):
        kids = wide[w][wide[w] >= 0]
        return used[w].sum() - 1 + max((need(k) for k in kids), default=0)
    assert stack_need(bvh, slots, wide) == (need(0) if len(slots) else 0)


_SCALES = st.sampled_from([0.0, 1e-30, 1e-7, 1e-3, 1.0, 50.0, 1e6, 1e30])


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 40), _SCALES, _SCALES, st.sampled_from([0.0, 1.0, -3.7e3, 1e4, -2.5e7]),
       st.booleans(), st.integers(0, 2 ** 31 - 1))
def test_quantised_child_boxes_hold_their_float64_boxes(n, spread, size, far, equal, seed):
    """Every child box decoded from the GPU's 8-bit grid holds its float64 box (relative
    to the frame's origin) whatever the scale: zero-size boxes, huge ones, boxes far from
    the origin in float32, a child equal to its parent; the grid's steps are powers of two
    and a decoded bound is exact in float32."""
    from plantgen.gl.trace import decode_nodes, node_words, wide_nodes

    rng = np.random.default_rng(seed)
    lo = far + rng.uniform(-spread, spread, (n, 3))
    hi = lo + rng.uniform(0.0, size, (n, 3))
    if equal:            # a box as large as all the others together: a child equal to its parent
        lo[0], hi[0] = lo.min(axis=0), hi.max(axis=0)
    bvh = build_bvh(lo, hi, leaf_size=2)
    slots, wide = wide_nodes(bvh)
    origin = np.array([far * 0.999, 0.0, -far]) if far else np.zeros(3)
    d_lo, d_hi, refs = decode_nodes(node_words(bvh, origin, slots, wide))
    used = slots >= 0
    s = np.maximum(slots, 0)
    assert (d_lo[used].astype(np.float64) <= (bvh.lo - origin)[s][used]).all()
    assert (d_hi[used].astype(np.float64) >= (bvh.hi - origin)[s][used]).all()
    assert np.isfinite(d_lo).all() and np.isfinite(d_hi).all()
    # tight: a decoded box is at most a 254th of its node's extent (or float32's own
    # resolution there) larger on each side
    box_lo = np.where(used[..., None], d_lo, np.inf).min(axis=1, keepdims=True)
    box_hi = np.where(used[..., None], d_hi, -np.inf).max(axis=1, keepdims=True)
    slack = (box_hi - box_lo) / 127.0 + 2.0 ** -20 * np.maximum(np.abs(box_lo), np.abs(box_hi)) + 1e-37
    assert ((bvh.lo - origin)[s][used] - d_lo[used] <= slack.repeat(4, axis=1)[used]).all()
    assert (d_hi[used] - (bvh.hi - origin)[s][used] <= slack.repeat(4, axis=1)[used]).all()
    assert (refs[~used] == -1).all()


def test_boxes_beyond_float32_are_refused():
    from plantgen.gl.trace import node_words, wide_nodes

    lo = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    bvh = build_bvh(lo, lo + np.array([[1e39, 1.0, 1.0], [1.0, 1.0, 1.0]]))
    with pytest.raises(PlantgenError, match="float32"), np.errstate(over="ignore"):
        node_words(bvh, np.zeros(3), *wide_nodes(bvh))


def test_triangles_of_every_scale_far_from_the_origin(gl_ctx):
    """Leaf triangles from a millionth of a unit to a hundred thousand units, 1e4 units
    from the origin, some of zero size: the GPU's closest hits (through the quantised
    boxes) are brute force's in float64."""
    rng = np.random.default_rng(5)
    k = 400
    centre = np.array([1e4, -2e3, 1e4]) + rng.uniform(-50, 50, (k, 3))
    size = 10.0 ** rng.uniform(-6, 5, k)
    size[:20] = 0.0
    tri = centre[:, None, :] + size[:, None, None] * rng.normal(size=(k, 3, 3))
    pad = 1e-9 * np.abs(tri).max(axis=(1, 2))[:, None] + 1e-12
    lo, hi = tri.min(1) - pad, tri.max(1) + pad
    target = ScanTarget(Frusta.empty(), tri, np.arange(k), lo, hi, np.zeros(0, np.int64), np.zeros(0, np.int64),
                        np.full(k, -1, np.int64), np.zeros(k, np.int64), None)
    origins, dirs = _random_rays(lo[20:200], hi[20:200], 3000, seed=6, margin=20.0)
    origins += np.array([1e4, -2e3, 1e4]) - origins.mean(axis=0)
    ref_t, ref_prim = cast_first_returns(target, origins, dirs)
    gpu = upload_bvh(gl_ctx, [GpuPlant(None, tri, build_bvh(lo, hi, leaf_size=2))])
    t, prim, _, _ = trace_rays(gpu, origins, dirs)
    assert (prim == ref_prim).mean() >= 0.999
    assert (ref_prim >= 0).sum() >= 100


_NODE_DUMP = """
#if defined COMPUTE_SHADER
layout(local_size_x = 64) in;
#include "bvh.glsl"
layout(std430, binding = 0) writeonly buffer Dump { vec4 dump[]; };
uniform int node_count;
void main() {
    int w = int(gl_GlobalInvocationID.x);
    if (w >= node_count) return;
    ivec4 ref;
    bvh_node(w, dump[7 * w], dump[7 * w + 1], dump[7 * w + 2], dump[7 * w + 3], dump[7 * w + 4], dump[7 * w + 5],
             ref);
    dump[7 * w + 6] = intBitsToFloat(ref);
}
#endif
"""


def test_the_shader_decodes_nodes_as_the_cpu_does(gl_ctx, tmp_path):
    """bvh.glsl's bvh_node, run on the GPU over nodes of every scale (tiny, huge, 1e4 units
    from the origin, zero-size), gives bit for bit the boxes and references that
    plantgen.gl.trace.decode_nodes gives (which the property test above proves
    conservative): origin + bytes · step is exact in float32, whatever the compiler fuses."""
    import shutil

    from plantgen._resources import shaders_dir
    from plantgen.gl.shaders import build_compute, set_uniforms
    from plantgen.gl.trace import BVH_BINDING, decode_nodes, node_words, wide_nodes

    rng = np.random.default_rng(11)
    words = []
    for far, spread, size in [(0.0, 5.0, 0.5), (1e4, 30.0, 1e-3), (-2.5e7, 1e3, 1e5), (0.0, 1e-30, 0.0),
                              (3.0, 1e30, 1e29), (1e4, 0.0, 0.0)]:
        lo = far + rng.uniform(-spread, spread, (300, 3))
        hi = lo + rng.uniform(0.0, size, (300, 3))
        bvh = build_bvh(lo, hi, leaf_size=2)
        words.append(node_words(bvh, np.array([far * 0.999, 0.0, 0.0]), *wide_nodes(bvh)))
    words = np.concatenate(words)
    folder = tmp_path / "shaders"
    shutil.copytree(shaders_dir(), folder)
    (folder / "node_dump.glsl").write_text(_NODE_DUMP)
    program = build_compute(gl_ctx, "node_dump.glsl", directory=folder)
    nodes = gl_ctx.buffer(words.tobytes())
    out = gl_ctx.buffer(reserve=len(words) * 7 * 16)
    try:
        nodes.bind_to_storage_buffer(BVH_BINDING)
        out.bind_to_storage_buffer(0)
        set_uniforms(program, node_count=len(words))
        program.run(group_x=(len(words) + 63) // 64)
        dump = np.frombuffer(out.read(), np.float32).reshape(-1, 7, 4)
    finally:
        nodes.release()
        out.release()
    lo, hi, ref = decode_nodes(words)
    np.testing.assert_array_equal(np.moveaxis(dump[:, 0:3], 1, 2), lo)
    np.testing.assert_array_equal(np.moveaxis(dump[:, 3:6], 1, 2), hi)
    np.testing.assert_array_equal(dump[:, 6].view(np.int32), ref)
