"""Benchmark: tessellation speed and memory (GS, GS+R), up to the pine at m = 3.

Run as ``python -m plantgen.benchmarks.tessellate [--segments N] [--levels 0 1 2 3]
[--repeats R] [--grammar PATH]``. For each level it prints the median time of
``tessellate`` over the repeats, triangles per second, the peak memory that numpy
allocated during the call (tracemalloc), the mesh's own bytes, and the GPU buffer bytes
of a GS draw beside the ray caster's records for the same rows (§4's memory claim).

The model is the shipped pine grammar (the paper's pine has 16,997 segments), or with
``--synthetic`` (or where no pine ships) a tree of ``--segments`` bent chains of 17
tapering segments; either is skinned by ``plantgen.geometry.skeletons.skin.skin_skeleton``.
"""

from __future__ import annotations

import argparse
import gc
import statistics
import time
import tracemalloc

import numpy as np

from .._resources import shipped_grammar
from ..geometry.meshes.mesh import tessellate
from ..geometry.skeletons.skeleton import Skeleton
from ..geometry.skeletons.skin import skin_skeleton
from ..gl.raster import gs_buffer_bytes
from ..gl.records import rc_buffer_bytes
from ..pipeline import load_skeleton


def synthetic_tree(n_segments: int = 16997, chain_length: int = 17, seed: int = 1) -> Skeleton:
    """A skeleton of bent, tapering chains standing on a grid (no per-segment loop).

    Parameters
    ----------
    n_segments : total segments (rounded up to whole chains)
    chain_length : segments per chain
    seed : random generator seed (bend directions)
    """
    rng = np.random.default_rng(seed)
    n_chains = -(-n_segments // chain_length)
    grid = int(np.ceil(np.sqrt(n_chains)))
    roots = np.stack([np.arange(n_chains) % grid, np.zeros(n_chains), np.arange(n_chains) // grid], 1) * 2.0
    bend = rng.normal(scale=0.25, size=(n_chains, chain_length, 3))
    step = np.array([0.0, 1.0, 0.0]) + bend
    step /= np.linalg.norm(step, axis=2, keepdims=True)
    step *= 0.3
    pts = np.concatenate([roots[:, None, :], roots[:, None, :] + np.cumsum(step, axis=1)], axis=1)
    radius = np.linspace(0.12, 0.02, chain_length + 1)
    start = pts[:, :-1].reshape(-1, 3)
    end = pts[:, 1:].reshape(-1, 3)
    idx = np.arange(n_chains * chain_length)
    first = idx % chain_length == 0
    parent = np.where(first, -1, idx - 1)
    return Skeleton(start, end, np.tile(radius[:-1], n_chains), np.tile(radius[1:], n_chains),
                    parent, ~first, np.zeros(len(idx), np.int32), ("bark",))


def _measure(frusta, level: int, relief: bool, repeats: int):
    times = []
    peak = 0
    mesh = None
    for _ in range(repeats):
        mesh = None
        gc.collect()
        tracemalloc.start()
        t0 = time.perf_counter()
        mesh = tessellate(frusta, level, relief=relief)  # relief: the shipped height maps
        times.append(time.perf_counter() - t0)
        peak = max(peak, tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    return statistics.median(times), peak, mesh


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--segments", type=int, default=16997)
    parser.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--relief", action="store_true", help="GS+R (displace onto the shell)")
    parser.add_argument("--grammar", help="grow this grammar or scene (default: the shipped pine)")
    parser.add_argument("--synthetic", action="store_true",
                        help="use a synthetic tree of --segments segments instead of a grammar")
    args = parser.parse_args(argv)

    grammar = args.grammar
    if grammar is None and not args.synthetic:
        try:
            grammar = shipped_grammar("pine")
        except FileNotFoundError:
            grammar = None
    if grammar is not None:
        skeleton = load_skeleton(grammar)
        source = str(grammar)
    else:
        skeleton = synthetic_tree(args.segments)
        source = "synthetic tree in chains of 17"
    t0 = time.perf_counter()
    frusta = skin_skeleton(skeleton)
    skin_s = time.perf_counter() - t0
    n = len(frusta.length)
    print(f"model: {source}: {len(skeleton):,} segments -> {n:,} frusta rows "
          f"(skinned in {skin_s * 1e3:.0f} ms)")
    print(f"RC records: {rc_buffer_bytes(n) / 2**20:.2f} MiB ({rc_buffer_bytes(n) // n} B/row)")
    print(f"{'m':>2} {'triangles':>12} {'vertices':>11} {'median s':>9} {'Mtri/s':>7} "
          f"{'peak MiB':>9} {'mesh MiB':>9} {'GS GPU MiB':>11} {'GS/RC':>7}")
    for level in args.levels:
        reps = args.repeats if level < 3 else max(1, min(args.repeats, 3))
        seconds, peak, mesh = _measure(frusta, level, args.relief, reps)
        mesh_bytes = sum(a.nbytes for a in (mesh.vertices, mesh.normals, mesh.uv, mesh.faces, mesh.face_row))
        gpu = gs_buffer_bytes(mesh)
        print(f"{level:>2} {len(mesh.faces):>12,} {len(mesh.vertices):>11,} {seconds:>9.3f} "
              f"{len(mesh.faces) / seconds / 1e6:>7.2f} {peak / 2**20:>9.0f} {mesh_bytes / 2**20:>9.0f} "
              f"{gpu / 2**20:>11.1f} {gpu / rc_buffer_bytes(n):>7.1f}")
        del mesh
        gc.collect()


if __name__ == "__main__":
    main()
