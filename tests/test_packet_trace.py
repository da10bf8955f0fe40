"""The packet walk of the BVH (shaders/bvh.glsl's BVH_PACKET: the lanes of a subgroup walk
one node stream together) against the per-ray walk, hit for hit: the same primitive and
the same t (both run the same primitive test on the same ray) on random rays, incoherent
rays (every workgroup a mix of origins and directions), coherent eye rays, rays that end
early or start late, any hit, two levels, 1e4 units from the origin and grazing rays; and
the choice of the variant (plantgen.gl.trace.packet_traversal).

Runs where the context offers the packet walk's extensions (llvmpipe does).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_gpu_trace import T_RELATIVE, _copy_boxes, _random_rays, _similarities, _target

from plantgen.errors import PlantgenError
from plantgen.geometry.bvh import build_bvh
from plantgen.gl.shaders import shader_source
from plantgen.gl.trace import PACKET_EXTENSIONS, GpuPlant, packet_traversal, trace_rays, upload_bvh


@pytest.fixture
def packet_ctx(gl_ctx):
    missing = [e for e in PACKET_EXTENSIONS if e not in gl_ctx.extensions]
    if missing:
        pytest.skip(f"the GL context lacks {', '.join(missing)} (the packet walk's extensions)")
    return gl_ctx


def _both(ctx, plants, **upload):
    return [upload_bvh(ctx, plants, traversal=v, **upload) for v in ("ray", "packet")]


def _same_hits(gpus, origins, dirs, *, any_hit=False, min_same=0.999, min_hit=0.1, **query):
    """Both variants' hits of the rays; the same primitive (and copy) on >= min_same of
    them and there the same t within float32 rounding; hit or miss the same for all but
    1e-3 (and more than min_hit of them hit). Returns the per-ray walk's (t, prim, copy)."""
    (t, prim, copy, _), (pt, pprim, pcopy, _) = (trace_rays(g, origins, dirs, any_hit=any_hit, chunk=1000, **query)
                                                 for g in gpus)
    assert ((prim >= 0) == (pprim >= 0)).mean() >= 0.999
    assert (prim >= 0).mean() > min_hit
    if any_hit:       # the first hit found depends on the order the nodes are walked
        return t, prim, copy
    same = (prim == pprim) & (copy == pcopy)
    assert same.mean() >= min_same, f"{(~same).sum()} of {len(same)} rays hit another primitive"
    hit = same & (prim >= 0)
    np.testing.assert_allclose(pt[hit], t[hit], rtol=T_RELATIVE)
    return t, prim, copy


@pytest.mark.parametrize("shift", [(0.0, 0.0, 0.0), (1e4, -1e4, 5e3)], ids=["origin", "far"])
@pytest.mark.parametrize("any_hit", [False, True], ids=["closest", "any"])
def test_random_and_incoherent_rays_hit_as_the_per_ray_walk(packet_ctx, shift, any_hit):
    target = _target(shift=shift)
    gpus = _both(packet_ctx, [GpuPlant(target.frusta, target.triangles, build_bvh(target.lo, target.hi))])
    assert [g.packet for g in gpus] == [False, True]
    origins, dirs = _random_rays(target.lo, target.hi, 3000, seed=11)    # a workgroup: 64 unrelated rays
    _same_hits(gpus, origins, dirs, any_hit=any_hit)


def test_coherent_eye_rays_hit_as_the_per_ray_walk(packet_ctx):
    """A pinhole's rays in image order (neighbours in a subgroup): the frame's case."""
    target = _target(n=300, seed=4)
    gpus = _both(packet_ctx, [GpuPlant(target.frusta, target.triangles, build_bvh(target.lo, target.hi))])
    lo, hi = target.lo.min(0), target.hi.max(0)
    eye = 0.5 * (lo + hi) - np.array([0.0, 2.0 * (hi - lo)[1], 0.0])
    u, v = np.meshgrid(np.linspace(lo[0], hi[0], 80), np.linspace(lo[2], hi[2], 60))   # the box's middle plane
    dirs = np.stack([u.ravel(), np.full(u.size, 0.5 * (lo + hi)[1]), v.ravel()], axis=1) - eye
    origins = np.broadcast_to(eye, dirs.shape)
    for any_hit in (False, True):
        _same_hits(gpus, origins, dirs, any_hit=any_hit, min_hit=0.01)   # a sparse tree: 2 % of the pixels


def test_rays_that_end_early_or_start_late(packet_ctx):
    """t_max and t_min differ ray by ray: lanes stop (or skip hits) at their own t while
    the others walk on; neither walk finds a hit outside (t_min, t_max)."""
    target = _target()
    gpus = _both(packet_ctx, [GpuPlant(target.frusta, target.triangles, build_bvh(target.lo, target.hi))])
    origins, dirs = _random_rays(target.lo, target.hi, 3000, seed=12)
    t, prim, _, _ = trace_rays(gpus[0], origins, dirs)
    rng = np.random.default_rng(13)
    t_max = np.where(rng.random(len(t)) < 0.5, np.where(prim >= 0, rng.uniform(0.5, 1.5, len(t)) * t, 1.0), np.inf)
    t_min = np.where(rng.random(len(t)) < 0.3, np.where(prim >= 0, 1.001 * t, 0.0), 0.0)
    for any_hit in (False, True):
        for gpu in gpus:
            st, sprim, _, _ = trace_rays(gpu, origins, dirs, any_hit=any_hit, t_min=t_min, t_max=t_max)
            assert ((st[sprim >= 0] < t_max[sprim >= 0]) & (st[sprim >= 0] > t_min[sprim >= 0])).all()
        _same_hits(gpus, origins, dirs, any_hit=any_hit, t_min=t_min, t_max=t_max)


def test_grazing_rays_hit_as_the_per_ray_walk(packet_ctx):
    """Rays tangent to rows' cones 1e4 units from the origin, mixed in a workgroup with
    rays that hit squarely: both walks give the same primitive (the same test on the same
    ray) wherever the hierarchy lets both reach it."""
    target = _target(shift=(1e4, 0.0, 0.0))
    f = target.frusta
    rng = np.random.default_rng(14)
    m = 2000
    rows = rng.integers(0, len(f), m)
    y = rng.uniform(0.1, 0.9, m) * f.length[rows]
    radius = f.r1[rows] + (f.r2[rows] - f.r1[rows]) / f.length[rows] * y
    radial = rng.normal(size=(m, 3))
    radial -= np.einsum("ij,ij->i", radial, f.axis[rows])[:, None] * f.axis[rows]
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    side = 1.0 + 1e-4 * rng.choice([-1.0, 1.0], m)                 # just outside, just inside
    point = f.base[rows] + y[:, None] * f.axis[rows] + (side * radius)[:, None] * radial
    tangent = np.cross(radial, f.axis[rows])
    origins, dirs = point - 3.0 * tangent, tangent
    square = rng.random(m) < 0.5                 # aimed at the axis instead
    dirs[square] = -radial[square]
    origins[square] = point[square] + 2.0 * radial[square]
    gpus = _both(packet_ctx, [GpuPlant(target.frusta, target.triangles, build_bvh(target.lo, target.hi))])
    _same_hits(gpus, origins, dirs)


@pytest.mark.parametrize("offset", [0.0, 1e4], ids=["origin", "far"])
def test_two_levels_hit_as_the_per_ray_walk(packet_ctx, offset):
    """Copies entered by some lanes of a subgroup and not others, each lane's ray in the
    copy's frame: the same (copy, primitive) and t, closest and any hit."""
    plants = [_target(60, seed=7, leaves=20), _target(40, seed=8, leaves=0)]
    blas = [build_bvh(p.lo, p.hi, leaf_size=2) for p in plants]
    matrices = _similarities(24, seed=9, spread=8.0)
    matrices[:, :3, 3] += offset
    copy_plant = np.arange(24) % 2
    lo, hi = np.zeros((24, 3)), np.zeros((24, 3))
    for k in (0, 1):
        lo[copy_plant == k], hi[copy_plant == k] = _copy_boxes(blas[k], matrices[copy_plant == k])
    gpus = _both(packet_ctx, [GpuPlant(p.frusta, p.triangles, b) for p, b in zip(plants, blas, strict=True)],
                 origin=np.full(3, offset), top=build_bvh(lo, hi, leaf_size=2), matrices=matrices,
                 copy_plant=copy_plant)
    origins, dirs = _random_rays(lo, hi, 3000, seed=15)
    _, prim, copy = _same_hits(gpus, origins, dirs)
    assert len(np.unique(copy[prim >= 0])) >= 12
    _same_hits(gpus, origins, dirs, any_hit=True)


class _Context:
    def __init__(self, extensions):
        self.extensions = set(extensions)


def test_the_variant_is_chosen_from_the_contexts_extensions():
    full, bare = _Context(PACKET_EXTENSIONS), _Context(PACKET_EXTENSIONS[:1])
    assert packet_traversal(full, "auto") and packet_traversal(full, "packet")
    assert not packet_traversal(full, "ray")
    assert not packet_traversal(bare, "auto") and not packet_traversal(bare, "ray")
    with pytest.raises(PlantgenError, match="GL_ARB_shader_group_vote"):
        packet_traversal(bare, "packet")
    with pytest.raises(PlantgenError, match="traversal must be one of"):
        packet_traversal(full, "warp")


def test_the_packet_extensions_are_enabled_only_in_the_packet_variant():
    """The loader moves bvh.glsl's #extension lines above any code with the #if that
    guards them: a per-ray program enables none."""
    packet = shader_source("trace.glsl", "COMPUTE_SHADER", {"BVH_PACKET": True}).splitlines()
    ext = [i for i, line in enumerate(packet) if line.startswith("#extension")]
    assert len(ext) == len(PACKET_EXTENSIONS)
    code = next(i for i, line in enumerate(packet) if line.strip() and not line.lstrip().startswith(("#", "//")))
    assert max(ext) < code
    assert packet[ext[0] - 1] == "#if defined BVH_PACKET" and packet[ext[-1] + 1].startswith("#endif")
