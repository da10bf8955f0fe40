"""Skinning throughput: segments per second of ``skin_skeleton`` (median of repeats).

Run: ``python -m plantgen.benchmarks.skinning [--segments N] [--repeats R]``.
The model is a synthetic tree: continuing chains of 17 segments bending up to 30°, each
chain starting as a side branch of an earlier segment, radii tapering along chains. Both
joint constructions are timed, interleaved: closed seams (the default: the children's
radii fitted, :func:`plantgen.geometry.skeletons.skin.seam_radii`) and the paper's planes, with the
cost of closing the seams as their ratio. It also prints the skin report and the mean
bounding-pyramid / frustum volume ratio.

Smooth bends (issue 17): a two-segment chain bent by ``--bend`` degrees is skinned with
``skin_skeleton(smooth_bends=...)`` at k = 1, 2, 4, 8, 16 frusta per arc, and the float64
reference's hits of medial-axis rays are compared with the true bent tube (two cylinders
joined by a torus section of the same centre-line radius R): the largest distance of a hit
from that surface, over the tube radius r (:func:`torus_bend_error`).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from ..geometry.rays.reference import intersect_frusta
from ..geometry.rays.stability import chain, medial_axis_rays
from ..geometry.skeletons.frusta import pyramid_volume_ratio
from ..geometry.skeletons.skeleton import Skeleton
from ..geometry.skeletons.skin import skin_skeleton
from ..geometry.skeletons.smooth import DEFAULT_RADIUS_FACTOR, smooth_bends
from ..pipeline import load_skeleton


def synthetic_tree(n: int, chain: int = 17, seed: int = 0) -> Skeleton:
    """A deterministic tree of ``n`` segments, vectorised (no loop per segment)."""
    rng = np.random.default_rng(seed)
    idx = np.arange(n)
    pos = idx % chain
    chain_id = idx // chain
    bend = np.radians(rng.uniform(0, 30, n))
    turn = rng.uniform(0, 2 * np.pi, n)
    dirs = np.stack([np.sin(bend) * np.cos(turn), np.cos(bend), np.sin(bend) * np.sin(turn)], 1)
    length = rng.uniform(0.2, 0.6, n)
    steps = dirs * length[:, None]
    # chains start at an earlier chain's segment end: place chain starts, then cumulate
    n_chains = chain_id.max() + 1 if n else 0
    start_of_chain = np.zeros((n_chains, 3))
    parent = np.where(pos > 0, idx - 1, -1)
    host = (rng.random(n_chains) * np.arange(n_chains) * chain).astype(np.int64)
    cum = np.cumsum(steps, axis=0)
    cum_chain_start = cum[np.minimum(chain_id * chain, n - 1)] - steps[np.minimum(chain_id * chain, n - 1)]
    local = cum - cum_chain_start
    # host end points, resolved chain by chain in order (chains depend only on earlier ones)
    ends = np.zeros((n, 3))
    for c in range(n_chains):      # per chain (n/17 iterations), not per segment
        seg = slice(c * chain, min((c + 1) * chain, n))
        origin = ends[host[c]] if c else np.zeros(3)
        start_of_chain[c] = origin
        ends[seg] = origin + local[seg]
    parent = np.where(pos > 0, idx - 1, np.where(chain_id > 0, host[chain_id], -1))
    start = np.where((pos > 0)[:, None], np.roll(ends, 1, axis=0), start_of_chain[chain_id])
    radius0 = 0.05 + 0.2 / (1 + chain_id)
    r_start = radius0 * (1 - pos / (chain + 1))
    r_end = radius0 * (1 - (pos + 1) / (chain + 1))
    continues = pos > 0
    return Skeleton(start, ends, r_start, r_end, parent, continues, np.zeros(n, int))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--segments", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--grammars", nargs="*", metavar="YAML",
                        help="also skin these grammars with and without seam fitting and "
                             "print the seam mismatch before and after (§2.2)")
    parser.add_argument("--bend", type=float, default=90.0,
                        help="bend (degrees) of the smooth-bend error table (default 90)")
    args = parser.parse_args(argv)
    _smooth_table(args.bend)
    if args.grammars:
        _seams(args.grammars)
    skeleton = synthetic_tree(args.segments)
    times = {True: [], False: []}
    frusta = {}
    for _ in range(args.repeats):             # interleaved: the ratio is from one run
        for fit in (True, False):
            t0 = time.perf_counter()
            frusta[fit] = skin_skeleton(skeleton, seam_fit=fit)
            times[fit].append(time.perf_counter() - t0)
    med = {fit: statistics.median(t) for fit, t in times.items()}
    for fit, label in ((True, "closed seams (default)"), (False, "the paper's planes, seams open")):
        print(f"skin_skeleton, {label}: {len(skeleton)} segments, median {med[fit] * 1e3:.1f} ms over "
              f"{args.repeats} runs = {len(skeleton) / med[fit]:,.0f} segments/s")
    print(f"  closing the seams costs {med[True] / med[False]:.2f}x the paper's construction")
    for line in frusta[True].report.lines():
        print("  " + line)
    print(f"  bounding pyramid / frustum volume: mean {_mean_ratio(frusta[True]):.3f} "
          f"(straight cylinder: 4/pi = 1.273)")
    _smooth_timing(skeleton, args.repeats, med[True])


def _seams(paths) -> None:
    for path in paths:
        skeleton = load_skeleton(path)
        t0 = time.perf_counter()
        fitted = skin_skeleton(skeleton, seam_fit=True)
        dt = time.perf_counter() - t0
        r = fitted.report
        print(f"{path}: {len(skeleton)} segments, {r.joints} joints; seam mismatch / radius "
              f"max {r.seam_mismatch_max_before:.2e} mean {r.seam_mismatch_mean_before:.2e} -> "
              f"fitted max {r.seam_mismatch_max_after:.2e} ({dt * 1e3:.0f} ms); knuckles {r.sharp_joints}; "
              f"pyramid/frustum volume {_mean_ratio(fitted):.3f}")


def torus_bend_error(bend_deg: float, k: int, radius: float = 0.1, length: float = 1.0,
                     rays: int = 2000, seed: int = 1) -> dict:
    """Skin a two-segment chain bent by ``bend_deg`` with k frusta per arc and measure the
    reference hits of ``rays`` medial-axis rays against the true bent tube.

    Returns ``error`` (max |distance of a hit from the centre line - r| / r over the hits
    off the end caps), ``missed`` (rays with no hit: the chain is not closed),
    ``segments_added`` (from the skin report) and ``R`` (the arc's centre-line radius)."""
    skeleton = chain([bend_deg], lengths=length, radii=radius)
    R = float(smooth_bends(skeleton, 0.5 * bend_deg).arc_radius[0])
    frusta = skin_skeleton(skeleton, smooth_bends=0.5 * bend_deg, smooth_step_deg=bend_deg / k)
    origins, dirs = medial_axis_rays(frusta, rays, seed=seed)
    hits = intersect_frusta(frusta, origins, dirs)
    side = hits.hit & ~hits.cap
    dist = _bent_axis_distance(hits.point[side], np.radians(bend_deg), R, length)
    return {"error": float(np.max(np.abs(dist - radius)) / radius), "missed": int((~hits.hit).sum()),
            "segments_added": frusta.report.smooth_segments, "R": R}


def _bent_axis_distance(points, theta: float, R: float, length: float) -> np.ndarray:
    """Distance of ``points`` (m, 3) from the centre line of :func:`chain`'s two-segment
    chain (up +y, then bent by ``theta`` towards +x at (0, length, 0)) smoothed by an arc
    of radius ``R``: straight, arc, straight."""
    d = R * np.tan(0.5 * theta)
    a_p, n = np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])
    a_c = np.cos(theta) * a_p + np.sin(theta) * n
    J = length * a_p
    P0, P1 = J - d * a_p, J + d * a_c
    centre = P0 + R * n

    def to_segment(a, b):
        t = np.clip((points - a) @ (b - a) / np.dot(b - a, b - a), 0.0, 1.0)
        return np.linalg.norm(points - (a + t[:, None] * (b - a)), axis=1)

    w = points - centre
    off_plane = w[:, 2]
    phi = np.arctan2(w @ a_p, -(w @ n))
    in_arc = (phi >= 0) & (phi <= theta)
    to_arc = np.where(in_arc, np.hypot(np.hypot(w[:, 0], w[:, 1]) - R, off_plane), np.inf)
    return np.minimum(np.minimum(to_segment(np.zeros(3), P0), to_segment(P1, J + length * a_c)), to_arc)


def _smooth_timing(skeleton: Skeleton, repeats: int, plain_s: float, angle: float = 15.0) -> None:
    """Median time of ``skin_skeleton(smooth_bends=angle)`` against the plain skin's."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        smooth = skin_skeleton(skeleton, smooth_bends=angle)
        times.append(time.perf_counter() - t0)
    r, med = smooth.report, statistics.median(times)
    print(f"skin_skeleton(smooth_bends={angle:g}): {r.smooth_joints} joints -> arcs, +{r.smooth_segments} "
          f"segments, {r.n_rows} rows; median {med * 1e3:.1f} ms over {repeats} runs "
          f"({med / plain_s:.2f}x the plain skin)")


def _smooth_table(bend_deg: float) -> None:
    for k in (1, 2, 4, 8, 16):
        e = torus_bend_error(bend_deg, k)
        if k == 1:
            print(f"smooth bends: {bend_deg:g} deg bend, r = 0.1, lengths 1, arc R = {e['R'] / 0.1:.3g} r "
                  f"(at most {DEFAULT_RADIUS_FACTOR:g} r), float64 reference, 2000 medial-axis rays")
        print(f"  k = {k:2d} frusta per arc (+{e['segments_added']} segments): max |hit - torus| / r = "
              f"{e['error']:.3e}, rays missed {e['missed']}")


def _mean_ratio(frusta) -> float:
    """Mean bounding-pyramid / frustum volume over rows of real length (not knuckle fans)."""
    return float(pyramid_volume_ratio(frusta.subset(frusta.has_length), shell=False).mean())


if __name__ == "__main__":
    main()
