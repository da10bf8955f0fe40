"""The hard-case suite (docs: "Accuracy and stability"): each case as data, its checks, its table.

A case builds a skeleton, skins it, and casts a fixed set of rays: from an eye at a few
model sizes towards points sampled on the skin (plus the case's own special rays). For
each case :func:`evaluate_case` reports, against the float64 reference:

- ``nonfinite``: NaN or inf in any output of hit rays (t, point, u, v, normal);
- ``surface``: worst | |X⊥| - r(y) | / r over lateral hits (r: the row's larger radius);
- ``planes``: worst distance outside the two cutting planes over all hits, / r;
- ``nearest``: worst |t - t_march| / size against brute-force marching (f64), over rays
  that stay inside the solid for two marching steps past the hit; marching steps over
  thinner features (its step is about size/1000), so ``later`` (worst t - t_march,
  / size: the caster never finds a hit behind one the marcher saw) and ``march_only``
  (rays the marcher sees enter and the caster misses) are the one-sided checks that hold
  whatever the step;
- ``holes``: rays from medial-axis points outwards that miss the skin;
- ``f32`` / ``f32_raw``: worst depth error of the float32 emulation, relative to depth, with
  and without re-centring (positions uploaded relative to the eye); ``f32_world``: with
  re-centring but world coordinates cast directly (no eye-relative upload);
- ``px``: worst float32 (re-centred) hit-point error in pixels of a 768-pixel-high,
  40° view; ``flips``: rays whose hit/miss differs between float32 and float64, and
  ``flips_off_silhouette``: those of them whose float64 hit/miss does not change when the
  ray turns by 0.01 pixel (flips that are not silhouette rounding); ``far_side``: rays
  whose float32 hit/miss or depth (by more than 1 %) differs from float64 while the
  float64 hit and depth stay put when the ray turns by 0.05 pixel (off every silhouette,
  a row's own over a row behind included): a float32 ray that sees through a joint.

Nothing here imports GL or click.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ...tolerances import tol
from ..skeletons.frusta import Frusta, plane_height
from ..skeletons.skeleton import Skeleton
from ..skeletons.skin import skin_skeleton
from .reference import inside_frusta, intersect_frusta, march_rays, shade_hits

__all__ = ["HardCase", "HARD_CASES", "case_rays", "medial_axis_rays", "evaluate_case", "seam_points",
           "format_table", "chain", "surface_samples", "model_size", "hit_residuals"]


def chain(bends_deg=(), lengths=1.0, radii=0.1, offset=(0.0, 0.0, 0.0)) -> Skeleton:
    """A planar continuing chain up +y bending towards +x by ``bends_deg`` at each joint."""
    bends = np.radians(np.asarray(bends_deg, dtype=float))
    n = len(bends) + 1
    lengths = np.broadcast_to(np.asarray(lengths, dtype=float), (n,))
    radii = np.broadcast_to(np.asarray(radii, dtype=float), (n + 1,))
    ang = np.concatenate([[0.0], np.cumsum(bends)])
    d = np.stack([np.sin(ang), np.cos(ang), np.zeros(n)], axis=1)
    pts = np.concatenate([np.zeros((1, 3)), np.cumsum(d * lengths[:, None], axis=0)]) + np.asarray(offset)
    parent = np.arange(-1, n - 1)
    return Skeleton(pts[:-1], pts[1:], radii[:-1], radii[1:], parent, parent >= 0, np.zeros(n, int))


def _branch() -> Skeleton:
    p1 = np.array([0.0, 1.0, 0.0])
    start = np.array([[0, 0, 0], p1, p1, p1])
    end = np.array([p1, [0.05, 2, 0], p1 + [0.8, 0.5, 0], p1 + [-0.3, 0.2, 0.9]])
    return Skeleton(start, end, [0.2, 0.18, 0.1, 0.08], [0.18, 0.15, 0.06, 0.05],
                    [-1, 0, 0, 0], [False, True, False, False], np.zeros(4, int))


@dataclass(frozen=True)
class HardCase:
    name: str
    build: Callable[[], Skeleton]
    note: str = ""
    special: str = ""          # "", "grazing", "axis", "generator", "inside", "closeup"


HARD_CASES: tuple[HardCase, ...] = (
    HardCase("cylinder", lambda: chain((), 1.0, 0.1)),
    HardCase("near_cylinder", lambda: chain((), 1.0, [0.1, 0.1 * (1 - 1e-12)]), "|r1-r2| = 1e-12 r"),
    HardCase("flaring_cone", lambda: chain((), 1.0, [0.05, 0.3])),
    HardCase("cone_to_point", lambda: chain((), 1.0, [0.2, 0.0])),
    HardCase("bend_0", lambda: chain((0.0, 0.0), 1.0, [0.1, 0.09, 0.08, 0.07])),
    HardCase("bend_1e-8rad", lambda: chain((np.degrees(1e-8),), 1.0, [0.1, 0.09, 0.08])),
    HardCase("bend_45", lambda: chain((45.0,), 1.0, [0.1, 0.09, 0.08])),
    HardCase("bend_90", lambda: chain((90.0,), 1.0, [0.1, 0.09, 0.08])),
    HardCase("bend_135", lambda: chain((135.0,), 1.0, [0.1, 0.09, 0.08])),
    HardCase("bend_179", lambda: chain((179.0,), 1.0, [0.1, 0.09, 0.08])),
    HardCase("fold_back_180", lambda: chain((180.0,), 1.0, [0.1, 0.1, 0.1])),
    HardCase("short_and_long", lambda: chain((20.0, 20.0), [3.0, 1e-3, 3.0], [0.1, 0.1, 0.1, 0.1])),
    HardCase("thin_1e-4", lambda: chain((30.0,), 1.0, [1e-4, 1e-4, 1e-4]), "r = 1e-4 h"),
    HardCase("thin_closeup", lambda: chain((30.0, 20.0), 1.0, [1e-4, 1e-4, 9e-5, 8e-5]),
             "r = 1e-4 h, eyes 8 r from the seams", "closeup"),
    HardCase("fat_1e3", lambda: chain((30.0,), 1.0, [1e3, 1e3, 1e3]), "r = 1e3 h"),
    HardCase("far_1e4", lambda: chain((30.0, 20.0), 1.0, [0.1, 0.09, 0.08, 0.07], (1e4, 1e4, 1e4)),
             "model 1.7e4 from the origin"),
    HardCase("side_branch", _branch),
    HardCase("grazing", lambda: chain((30.0,), 1.0, [0.1, 0.09, 0.08]), "rays grazing the silhouette", "grazing"),
    HardCase("along_axis", lambda: chain((), 1.0, [0.1, 0.08]), "rays along the axis", "axis"),
    HardCase("parallel_generator", lambda: chain((), 1.0, [0.2, 0.05]), "rays parallel to a generator", "generator"),
    HardCase("eye_inside_pyramid", lambda: chain((), 1.0, [0.3, 0.3]), "eye inside the bounding pyramid", "inside"),
)


def surface_samples(frusta: Frusta, count: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """(count,) rows and (count, 3) points on the lateral skins (between the planes)."""
    rows = rng.integers(0, len(frusta), count)
    psi = rng.uniform(0, 2 * np.pi, count)
    ref, a = frusta.ref_dir[rows], frusta.axis[rows]
    e = np.cos(psi)[:, None] * ref + np.sin(psi)[:, None] * np.cross(a, ref)
    k = frusta.slope[rows]
    ys = []
    for plane in (frusta.plane_lo[rows], frusta.plane_hi[rows]):
        n, d = plane[:, :3], plane[:, 3]
        ys.append(plane_height(d - np.einsum("ij,ij->i", n, frusta.base[rows]), np.einsum("ij,ij->i", n, a),
                               np.einsum("ij,ij->i", n, e), frusta.r1[rows], k)[0])
    lo, hi = np.minimum(*ys), np.maximum(*ys)
    y = lo + rng.uniform(0.02, 0.98, count) * (hi - lo)
    pts = frusta.base[rows] + y[:, None] * a + (frusta.r1[rows] + k * y)[:, None] * e
    return rows, pts


def model_size(frusta: Frusta) -> float:
    """The model's size: the diagonal of its axis end points' box plus its widest diameter."""
    pts = np.concatenate([frusta.base, frusta.top])
    r = np.maximum(frusta.r1, frusta.r2).max()
    return float(np.linalg.norm(pts.max(0) - pts.min(0)) + 2 * r)


def seam_points(frusta: Frusta, count: int, rng):
    """(count, 3) points on the seams of continuing joints (a child's generator meeting its
    lower plane), (count, 3) the outward radial directions there and (count,) the radii."""
    child = np.flatnonzero(frusta.parent_row >= 0)
    rows = child[rng.integers(0, len(child), count)]
    psi = rng.uniform(0.0, 2.0 * np.pi, count)
    a, ref = frusta.axis[rows], frusta.ref_dir[rows]
    e = np.cos(psi)[:, None] * ref + np.sin(psi)[:, None] * np.cross(a, ref)
    plane = frusta.plane_lo[rows]
    k = frusta.slope[rows]
    y, _ = plane_height(plane[:, 3] - np.einsum("ij,ij->i", plane[:, :3], frusta.base[rows]),
                        np.einsum("ij,ij->i", plane[:, :3], a), np.einsum("ij,ij->i", plane[:, :3], e),
                        frusta.r1[rows], k)
    r = frusta.r1[rows] + k * y
    return frusta.base[rows] + y[:, None] * a + r[:, None] * e, e, r


def case_rays(case: HardCase, frusta: Frusta, count: int = 200, seed: int = 0):
    """(m, 3) origins, (m, 3) unit directions for a case, deterministic."""
    rng = np.random.default_rng(seed)
    size = model_size(frusta)
    centre = 0.5 * (np.concatenate([frusta.base, frusta.top]).max(0)
                    + np.concatenate([frusta.base, frusta.top]).min(0))
    _, targets = surface_samples(frusta, count, rng)
    dirs_eye = rng.normal(size=(count, 3))
    dirs_eye /= np.linalg.norm(dirs_eye, axis=1, keepdims=True)
    eyes = centre + dirs_eye * 3.0 * size
    if case.special == "grazing":
        # aim just outside and just inside the silhouette of the first row, seen from +z
        y = rng.uniform(0.2, 0.8, count) * frusta.length[0]
        r = frusta.r1[0] + frusta.slope[0] * y
        eps = r * 10.0 ** rng.uniform(-12, -3, count) * rng.choice([-1, 1], count)
        targets = frusta.base[0] + y[:, None] * frusta.axis[0] + (r + eps)[:, None] * frusta.ref_dir[0]
        eyes = targets + 3.0 * size * np.cross(frusta.ref_dir[0], frusta.axis[0])
    elif case.special == "axis":
        off = rng.normal(size=(count, 3)) * 1e-9
        eyes = frusta.base[0] - 2.0 * frusta.axis[0] + off * np.array([1, 0, 1])
        targets = frusta.top[0] + off
        eyes[: count // 2] = (frusta.base[0] - 2.0 * frusta.axis[0])
        targets[: count // 2] = frusta.top[0]
    elif case.special == "generator":
        psi = rng.uniform(0, 2 * np.pi, count)
        side = np.cross(frusta.axis[0], frusta.ref_dir[0])
        e = np.cos(psi)[:, None] * frusta.ref_dir[0] + np.sin(psi)[:, None] * side
        g = frusta.axis[0] + frusta.slope[0] * e
        start = frusta.base[0] + frusta.r1[0] * e * (1 + rng.uniform(-0.5, 0.5, count))[:, None]
        eyes = start - g * 1.5
        targets = start
    elif case.special == "closeup":
        targets, outward, r = seam_points(frusta, count, rng)
        # just either side of the seam, within 1e-3 r of the shared plane (whose float32
        # test runs relative to bases 1e4 r away), seen from 8 r outside it
        pick = np.flatnonzero(frusta.parent_row >= 0)[0]
        targets = targets + (r * rng.uniform(-1e-3, 1e-3, count))[:, None] * frusta.axis[pick]
        look = outward + 0.6 * dirs_eye
        eyes = targets + 8.0 * r[:, None] * look / np.linalg.norm(look, axis=1, keepdims=True)
    elif case.special == "inside":
        eyes = frusta.base[0] + 0.5 * frusta.axis[0] + frusta.ref_dir[0] * frusta.r1[0] * 1.2
        eyes = np.broadcast_to(eyes, (count, 3)).copy()
    d = targets - eyes
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return eyes, d


def medial_axis_rays(frusta: Frusta, count: int = 400, seed: int = 1, rows=None):
    """Rays from points on the medial axes (inside the solids) in random directions."""
    rng = np.random.default_rng(seed)
    rows = np.arange(len(frusta)) if rows is None else np.asarray(rows)
    long_rows = rows[frusta.has_length[rows]]
    pick = long_rows[rng.integers(0, len(long_rows), count)]
    y = rng.uniform(0.0, 1.0, count) * frusta.length[pick]
    o = frusta.base[pick] + y[:, None] * frusta.axis[pick]
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o, d


def _row_scale(frusta, rows):
    """(m,) the larger radius of rows (m,), the scale of their residuals."""
    return np.maximum(np.maximum(frusta.r1[rows], frusta.r2[rows]), tol.tiny)


def hit_residuals(frusta: Frusta, hits) -> tuple[np.ndarray, np.ndarray]:
    """(surface, planes) residuals of every hit, relative to the row's radius (see module)."""
    rows = hits.row[hits.hit]
    p = hits.point[hits.hit]
    rel = p - frusta.base[rows]
    a = frusta.axis[rows]
    y = np.einsum("ij,ij->i", rel, a)
    rad = np.linalg.norm(rel - y[:, None] * a, axis=1)
    r = frusta.r1[rows] + frusta.slope[rows] * y
    surface = np.where(hits.cap[hits.hit], 0.0, np.abs(rad - r)) / _row_scale(frusta, rows)
    lo = np.einsum("ij,ij->i", frusta.plane_lo[rows, :3], p) - frusta.plane_lo[rows, 3]
    hi = np.einsum("ij,ij->i", frusta.plane_hi[rows, :3], p) - frusta.plane_hi[rows, 3]
    planes = np.maximum(np.maximum(-lo, hi), 0.0) / _row_scale(frusta, rows)
    return surface, planes


def evaluate_case(case: HardCase, count: int = 200, march: bool = True) -> dict:
    skeleton = case.build()
    frusta = skin_skeleton(skeleton)
    O, D = case_rays(case, frusta, count)
    size = model_size(frusta)
    eye_ref = O[0]
    h64 = intersect_frusta(frusta, O, D)
    u, v, nrm = shade_hits(frusta, h64)
    out = {"case": case.name, "rows": len(frusta), "hits": int(h64.hit.sum())}
    vals = [h64.t[h64.hit], h64.point[h64.hit], u[h64.hit], v[h64.hit], nrm[h64.hit]]
    out["nonfinite"] = int(sum((~np.isfinite(x)).sum() for x in vals))
    s, p = hit_residuals(frusta, h64)
    out["surface"] = float(s.max()) if s.size else 0.0
    out["planes"] = float(p.max()) if p.size else 0.0
    if march and case.special != "inside":
        t_max = float(np.linalg.norm(O - O.mean(0), axis=1).max() + 4 * size)
        samples = 3000
        tm = march_rays(frusta, O, D, t_max, samples=samples)
        both = np.isfinite(tm) & h64.hit
        # two-sided only where the ray stays inside for two marching steps past the hit
        # (the marcher cannot step over such an entry)
        step = t_max / (samples - 1)
        deep = np.zeros(len(O), dtype=bool)
        if h64.hit.any():
            deep[h64.hit] = inside_frusta(frusta, h64.point[h64.hit] + 2 * step * D[h64.hit])
            deep[h64.hit] &= inside_frusta(frusta, h64.point[h64.hit] + step * D[h64.hit])
        sel = both & deep
        out["nearest"] = float(np.abs(tm[sel] - h64.t[sel]).max() / size) if sel.any() else 0.0
        out["later"] = float(np.maximum(h64.t[both] - tm[both], 0).max() / size) if both.any() else 0.0
        out["march_only"] = int((np.isfinite(tm) & ~h64.hit).sum())
        out["march_flips"] = int((np.isfinite(tm) != h64.hit).sum())
    else:
        out["nearest"], out["later"], out["march_only"], out["march_flips"] = float("nan"), 0.0, 0, 0
    mo, md = medial_axis_rays(frusta, 300)
    hm = intersect_frusta(frusta, mo, md, t_min=0.0)
    out["holes"] = int((~hm.hit).sum())
    depth = np.where(h64.hit, h64.t, 1.0)
    pix = np.radians(40.0) / 768
    for key, kw in (("f32", dict(recenter=True, origin=eye_ref)),
                    ("f32_raw", dict(recenter=False, origin=eye_ref)),
                    ("f32_world", dict(recenter=True, origin=None))):
        h32 = intersect_frusta(frusta, O, D, dtype=np.float32, **kw)
        both = h32.hit & h64.hit
        err = np.abs(np.where(both, h32.t, 0.0) - np.where(both, h64.t, 0.0))[both] / depth[both]
        out[key] = float(err.max()) if err.size else 0.0
        if key == "f32":
            stable = _depth_stable(frusta, O, D, h64, 0.05 * pix)
            with np.errstate(invalid="ignore"):
                wrong = (h32.hit != h64.hit) | (np.abs(np.where(both, h32.t - h64.t, 0.0)) > 1e-2 * depth)
            out["far_side"] = int((wrong & stable).sum())
            flipped = np.flatnonzero(h32.hit != h64.hit)
            out["flips"] = int(flipped.size)
            out["flips_off_silhouette"] = _off_silhouette(frusta, O[flipped], D[flipped],
                                                          h64.hit[flipped], 0.01 * pix)
            dp = np.linalg.norm(h32.point - h64.point, axis=-1)[both] / (depth[both] * pix)
            out["px"] = float(dp.max()) if dp.size else 0.0
    return out


def _turned(D, angle):
    """The four directions of rays ``D`` (m, 3) turned by ``angle`` radians: along two
    perpendiculars of each ray, both ways."""
    a = np.where(np.abs(D[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0.0, 0, 1]]))
    e1 = np.cross(D, a)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(D, e1)
    return [D + angle * e for e in (e1, -e1, e2, -e2)]


def _depth_stable(frusta, O, D, h64, angle) -> np.ndarray:
    """(m,) bool: rays whose float64 hit/miss and depth (to 1e-3) stay when the ray turns by
    ``angle`` radians in four directions: off every silhouette, a row's own silhouette
    over a row behind it included (a float32 flip there is rounding of a tangency)."""
    stable = np.ones(len(O), dtype=bool)
    for turned in _turned(D, angle):
        h = intersect_frusta(frusta, O, turned)
        with np.errstate(invalid="ignore"):
            same_t = np.abs(np.where(h.hit & h64.hit, h.t - h64.t, 0.0)) <= 1e-3 * np.where(h64.hit, h64.t, 1.0)
        stable &= (h.hit == h64.hit) & same_t
    return stable


def _off_silhouette(frusta, O, D, hit64, angle) -> int:
    """How many rays keep their float64 hit/miss status when turned by ``angle`` radians
    in four directions: flips on such rays are not silhouette effects."""
    if len(O) == 0:
        return 0
    stable = np.ones(len(O), dtype=bool)
    for turned in _turned(D, angle):
        stable &= intersect_frusta(frusta, O, turned).hit == hit64
    return int(stable.sum())


COLUMNS = ("case", "rows", "hits", "nonfinite", "surface", "planes", "nearest", "later",
           "march_only", "holes", "f32_raw", "f32", "f32_world", "px", "flips",
           "flips_off_silhouette", "far_side")


def format_table(results: list[dict]) -> str:
    """A fixed-width text table of :func:`evaluate_case` results."""
    def fmt(v):
        if isinstance(v, float):
            return "nan" if np.isnan(v) else f"{v:.1e}"
        return str(v)

    rows = [[fmt(r.get(c, "")) for c in COLUMNS] for r in results]
    widths = [max(len(c), *(len(r[i]) for r in rows)) for i, c in enumerate(COLUMNS)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(COLUMNS, widths, strict=True))]
    lines += ["  ".join(x.ljust(w) for x, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join(lines)
