"""The shapes an environment is made of: signed distance, volume, bounds, ray distance.

A shape is written as a mapping, every value typed and ranged::

    {shape: box, center: [0, 2, 0], size: [4, 4, 1]}        # axis-aligned, full side lengths
    {shape: ellipsoid, center: [0, 3, 0], radii: [2, 3, 2]}
    {shape: cylinder, center: [0, 0, 0], radius: 2, height: 5}   # base centre, axis +y
    {shape: cone, center: [0, 0, 0], radius: 2, height: 5}       # base centre, apex above it
    {shape: mesh, file: crown.obj}                           # a closed mesh in the grammar's folder

:meth:`Shape.distance` is the signed distance (negative inside), exact for every shape:
the box, cylinder and cone in closed form, the ellipsoid by bisection on Eberly's
closest-point equation (to ``tol``-level accuracy), the mesh as the distance to its
nearest triangle, signed by its winding number. :meth:`Shape.ray` is the distance along a
unit direction to the shape's surface (0 from inside, ``inf`` on a miss): slabs for a box,
the BVH's traversal for a mesh, sphere tracing the exact distance for the others.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import fields
from ..errors import PlantgenError
from ..files import read_input
from ..geometry.meshes.polygons import Polygons
from ..geometry.rays.scan import scan_target
from ..geometry.skeletons.skeleton import Skeleton
from ..limits import Limits
from ..tolerances import tol

__all__ = ["DEFAULT_BATCH", "KINDS", "EnvError", "batch_size", "Shape", "inside_folder", "parse_shape"]

KINDS = ("box", "ellipsoid", "cylinder", "cone", "mesh")
#: Bisection steps of the ellipsoid's closest-point equation (each halves the bracket).
ELLIPSOID_STEPS = 100
#: Steps of sphere tracing before a ray is called a miss (a step never undershoots).
TRACE_STEPS = 256
#: Triangles of a mesh shape at most (its distance costs points x triangles).
MAX_MESH_TRIANGLES = 20_000


#: Modules (or markers) an environment's part handles at a time, unless it says ``batch``.
DEFAULT_BATCH = 4096


def batch_size(d: dict, where: str) -> int:
    """A part's ``batch``: how many modules it answers at a time (memory, never the answer)."""
    return fields.integer(d.get("batch", DEFAULT_BATCH), "batch", where, EnvError, lo=1, hi=1 << 24)


class EnvError(PlantgenError):
    """An environment that cannot be used; the message names the grammar and the place."""


@dataclass(frozen=True, eq=False)
class Shape:
    kind: str
    center: np.ndarray              # (3,) the centre (box, ellipsoid) or base centre (cylinder, cone)
    size: np.ndarray                # (3,) box: half sides; ellipsoid: radii; cylinder, cone: (radius, height, 0)
    triangles: np.ndarray | None = None     # mesh: (T, 3, 3)

    # ------------------------------------------------------------------ distance
    def distance(self, points: np.ndarray) -> np.ndarray:
        """(n,) signed distance of (n, 3) points to the surface: negative inside."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.center
        return getattr(self, f"_{self.kind}")(p)

    def _box(self, p):
        q = np.abs(p) - self.size
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)

    def _cylinder(self, p):
        radius, height = self.size[0], self.size[1]
        q = np.stack([np.hypot(p[:, 0], p[:, 2]) - radius, np.abs(p[:, 1] - height / 2) - height / 2], axis=1)
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)

    def _cone(self, p):
        """The cone's (r, y) half-plane section is the triangle (0, 0), (R, 0), (0, h): the
        distance to its base and slant edges (the axis edge is inside the solid)."""
        radius, height = self.size[0], self.size[1]
        r, y = np.hypot(p[:, 0], p[:, 2]), p[:, 1]
        base = np.hypot(r - np.clip(r, 0.0, radius), y)
        e = np.array([-radius, height])                       # from (R, 0) to (0, h)
        w = np.stack([r - radius, y], axis=1)
        s = np.clip(w @ e / (e @ e), 0.0, 1.0)
        slant = np.linalg.norm(w - s[:, None] * e, axis=1)
        inside = (y >= 0) & (y <= height) & (r <= radius * (1 - y / height))
        d = np.minimum(base, slant)
        return np.where(inside, -d, d)

    def _ellipsoid(self, p):
        """Eberly's method: the closest point x_i = e_i² y_i / (t + e_i²), t the root of
        F(t) = Σ (e_i y_i / (t + e_i²))² - 1, bracketed in (0, e_max |y|) outside and
        (-e_min², 0) inside; on the smallest axis's plane inside (F without a pole there and
        positive nowhere) the closest point lies off that plane, in closed form."""
        e = self.size
        y = np.abs(p)
        e2 = e * e
        k = int(np.argmin(e))
        outside = np.einsum("ij,ij->i", y / e, y / e) > 1.0
        norm = np.linalg.norm(y, axis=1)
        lo = np.where(outside, 0.0, -e2[k])
        hi = np.where(outside, e.max() * norm, 0.0)

        def f(t):
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.sum((e * y / (t[:, None] + e2)) ** 2, axis=1) - 1.0

        for _ in range(ELLIPSOID_STEPS):
            mid = 0.5 * (lo + hi)
            above = f(mid) > 0
            lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
        t = 0.5 * (lo + hi)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = e2 * y / (t[:, None] + e2)
            # inside, on the smallest axis's plane: t = -e_k², the other axes' coordinates as
            # given by it, the k-th one whatever puts the point on the surface
            others = [i for i in range(3) if i != k]
            xo = e2[others] * y[:, others] / (e2[others] - e2[k])
        rest = 1.0 - np.sum((xo / e[others]) ** 2, axis=1)
        special = ~outside & (y[:, k] <= tol.parallel * e[k]) & (rest > 0) & np.all(e2[others] > e2[k])
        if special.any():
            xs = x[special]
            xs[:, others] = xo[special]
            xs[:, k] = e[k] * np.sqrt(rest[special])
            x[special] = xs
        d = np.linalg.norm(y - x, axis=1)
        bad = ~np.isfinite(d)            # the centre of a spheroid's circle: every direction is as near
        d[bad] = e[k] - norm[bad]
        return np.where(outside, d, -d)

    def _mesh(self, p):
        tri = self.triangles
        d = np.full(len(p), np.inf)
        winding = np.zeros(len(p))
        for lo in range(0, len(p), 256):
            q = p[lo:lo + 256]
            d[lo:lo + 256] = _point_triangle_distance(q, tri)
            winding[lo:lo + 256] = _winding_number(q, tri)
        return np.where(np.abs(winding) > 0.5, -d, d)

    # ------------------------------------------------------------------ other properties
    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The shape's axis-aligned bounding box (lo, hi)."""
        if self.kind == "mesh":
            v = self.triangles.reshape(-1, 3)
            return v.min(axis=0) + self.center, v.max(axis=0) + self.center
        if self.kind in ("box", "ellipsoid"):
            return self.center - self.size, self.center + self.size
        radius, height = self.size[0], self.size[1]
        return self.center - [radius, 0.0, radius], self.center + [radius, height, radius]

    @property
    def volume(self) -> float:
        s = self.size
        if self.kind == "box":
            return float(8 * s.prod())
        if self.kind == "ellipsoid":
            return float(4 / 3 * np.pi * s.prod())
        if self.kind == "cylinder":
            return float(np.pi * s[0] ** 2 * s[1])
        if self.kind == "cone":
            return float(np.pi * s[0] ** 2 * s[1] / 3)
        v0, v1, v2 = self.triangles[:, 0], self.triangles[:, 1], self.triangles[:, 2]
        return float(abs(np.einsum("ij,ij->i", v0, np.cross(v1, v2)).sum()) / 6)

    def ray(self, origins: np.ndarray, directions: np.ndarray, reach: float) -> np.ndarray:
        """(n,) distance along each unit direction from each origin to the shape (0 for
        an origin inside it), ``inf`` if it is not met within ``reach``."""
        o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        if self.kind == "mesh":
            return self._mesh_ray(o, d, reach)
        if self.kind == "box":
            lo, hi = self.bounds
            with np.errstate(divide="ignore", invalid="ignore"):
                a, b = (lo - o) / d, (hi - o) / d
            a = np.where(np.isnan(a), -np.inf, a)      # an origin on a face, parallel to it: inside the slab
            b = np.where(np.isnan(b), np.inf, b)
            enter = np.minimum(a, b).max(axis=1)
            leave = np.maximum(a, b).min(axis=1)
            t = np.where((enter <= leave) & (leave >= 0), np.maximum(enter, 0.0), np.inf)
            return np.where(t <= reach, t, np.inf)
        # sphere tracing: each step moves by the distance to the surface, never past it
        t = np.zeros(len(o))
        active = np.ones(len(o), dtype=bool)
        hit = np.zeros(len(o), dtype=bool)
        eps = tol.parallel * max(1.0, float(np.abs(self.size).max()))
        for _ in range(TRACE_STEPS):
            idx = np.flatnonzero(active)
            if not len(idx):
                break
            step = self.distance(o[idx] + t[idx, None] * d[idx])
            done = step <= eps
            hit[idx[done]] = True
            t[idx[~done]] += step[~done]
            active[idx[done | (t[idx] > reach)]] = False
        return np.where(hit & (t <= reach), t, np.inf)


    def _mesh_ray(self, o, d, reach):
        """A mesh's ray distance: its triangles traced by the one BVH traversal
        (:mod:`plantgen.geometry.rays.bvh`), built once; 0 from inside."""
        if self.__dict__.get("_bvh") is None:
            tri = self.triangles + self.center
            n = len(tri)
            normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
            faces = Polygons(tri.reshape(-1, 3), np.arange(3 * n).reshape(n, 3), np.arange(n), np.zeros(n, np.int32),
                             normal)
            target = scan_target(Skeleton.empty(), faces)
            object.__setattr__(self, "_bvh", target)
        t, _ = self.__dict__["_bvh"].first_hits(o, d, t_max=reach)
        return np.where(self.distance(o) < 0, 0.0, t)


def _point_triangle_distance(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(n,) distance of each point to the nearest of the triangles (T, 3, 3) (Ericson's
    closest point on a triangle, by Voronoi regions, vectorised over points x triangles)."""
    a, b, c = (tri[None, :, k] for k in range(3))
    p = p[:, None]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.sum(ab * ap, -1), np.sum(ac * ap, -1)
    bp = p - b
    d3, d4 = np.sum(ab * bp, -1), np.sum(ac * bp, -1)
    cp = p - c
    d5, d6 = np.sum(ab * cp, -1), np.sum(ac * cp, -1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v = np.where(denom != 0, vb / denom, 0.0)
        w = np.where(denom != 0, vc / denom, 0.0)
        x = a + ab * v[..., None] + ac * w[..., None]                           # inside the face
        t_ab = np.clip(d1 / (d1 - d3), 0, 1)
        t_ac = np.clip(d2 / (d2 - d6), 0, 1)
        t_bc = np.clip((d4 - d3) / ((d4 - d3) + (d5 - d6)), 0, 1)
    edges = [(a, ab, t_ab, (vc <= 0) & (d1 >= 0) & (d3 <= 0)), (a, ac, t_ac, (vb <= 0) & (d2 >= 0) & (d6 <= 0)),
             (b, c - b, t_bc, (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0))]
    for start, edge, t, region in edges:
        x = np.where(region[..., None], start + edge * np.nan_to_num(t)[..., None], x)
    for corner, region in ((a, (d1 <= 0) & (d2 <= 0)), (b, (d3 >= 0) & (d4 <= d3)), (c, (d6 >= 0) & (d5 <= d6))):
        x = np.where(region[..., None], corner, x)
    return np.sqrt(np.min(np.sum((p - x) ** 2, -1), axis=1))


def _winding_number(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(n,) the winding number of the closed triangle mesh about each point: the solid
    angles of its triangles (Van Oosterom and Strackee) summed, over 4π (1 inside, 0 out)."""
    a, b, c = (tri[None, :, k] - p[:, None] for k in range(3))
    la, lb, lc = (np.linalg.norm(v, axis=-1) for v in (a, b, c))
    num = np.einsum("ntk,ntk->nt", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("ntk,ntk->nt", a, b) * lc + np.einsum("ntk,ntk->nt", b, c) * la
           + np.einsum("ntk,ntk->nt", c, a) * lb)
    return 2 * np.arctan2(num, den).sum(axis=1) / (4 * np.pi)


def inside_folder(name: str, base: Path, where: str, error: type[PlantgenError]) -> Path:
    """The file ``name`` names inside the folder ``base`` (the grammar's): a path that
    leaves it (``../x``, ``/etc/passwd``, a link pointing out) is refused before it is opened."""
    if not name or "\0" in name:
        raise error(f"{where}: file must name a file, got {fields.show(name)}")
    root = base.resolve()
    real = (base / name).resolve()
    if not real.is_relative_to(root):
        raise error(f"{where}: file {fields.show(name)} lies outside the grammar's folder (only files under "
                    "it are read)")
    if not real.is_file():
        raise error(f"{where}: file {fields.show(name)} not found in the grammar's folder")
    return real


SHAPE_KEYS = {"box": {"center", "size"}, "ellipsoid": {"center", "radii"}, "cylinder": {"center", "radius", "height"},
              "cone": {"center", "radius", "height"}, "mesh": {"file", "center"}}


def parse_shape(d, where: str, base: Path, limits: Limits) -> Shape:
    """A shape from its mapping (see the module's notes); ``base``: the grammar's folder."""
    fields.keys(d, {"shape", *set().union(*SHAPE_KEYS.values())}, where, EnvError)
    kind = d.get("shape")
    if kind not in KINDS:
        raise EnvError(f"{where}: shape must be one of {', '.join(KINDS)}, got {fields.show(kind)}")
    fields.keys(d, {"shape", *SHAPE_KEYS[kind]}, where, EnvError)
    big = tol.max_coordinate
    center = fields.vector(d.get("center", [0, 0, 0]), "center", where, EnvError, max_abs=big)

    def positive(key):
        if key not in d:
            raise EnvError(f"{where}: a {kind} needs {key}")
        return fields.number(d[key], key, where, EnvError, positive=True, max_abs=big)

    if kind in ("box", "ellipsoid"):
        key = "size" if kind == "box" else "radii"
        if key not in d:
            raise EnvError(f"{where}: a {kind} needs {key}")
        size = fields.vector(d[key], key, where, EnvError, max_abs=big)
        if not (size > 0).all():
            raise EnvError(f"{where}: {key} must be positive, got {size.tolist()}")
        return Shape(kind, center, size / 2 if kind == "box" else size)
    if kind in ("cylinder", "cone"):
        return Shape(kind, center, np.array([positive("radius"), positive("height"), 0.0]))
    return Shape(kind, center, np.zeros(3), _read_mesh(d.get("file"), where, base, limits))


def _read_mesh(name, where: str, base: Path, limits: Limits) -> np.ndarray:
    """(T, 3, 3) the triangles of a mesh file (a format trimesh reads) in the grammar's folder."""
    import io

    import trimesh

    name = fields.text(name, "file", where, EnvError, max_len=1000)
    path = inside_folder(name, base, where, EnvError)
    data = read_input(path, EnvError, max_bytes=limits.max_skeleton_bytes, limit="skeleton_bytes",
                      what="mesh")
    try:
        mesh = trimesh.load(io.BytesIO(data), file_type=path.suffix.lstrip(".").lower(), force="mesh",
                            process=False)
    except Exception as exc:    # noqa: BLE001 - any reader failure is one line naming the file
        raise EnvError(f"{where}: {path.name}: cannot read the mesh ({str(exc).splitlines()[0][:100]})") \
            from None
    tri = np.asarray(mesh.triangles, dtype=np.float64)
    if not len(tri) or len(tri) > MAX_MESH_TRIANGLES or not np.isfinite(tri).all():
        raise EnvError(f"{where}: {path.name}: a mesh shape needs 1 to {MAX_MESH_TRIANGLES:,} finite "
                               f"triangles, got {len(tri):,}")
    return tri
