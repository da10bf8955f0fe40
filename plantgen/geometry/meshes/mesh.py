"""Geometric subdivision (GS, GS+R): tessellate conical frusta into triangle meshes.

Level ``m`` puts ``N = 8·2^m`` columns around each frustum's axis and ``B = 2^m`` bands
along it, so every frustum row gives exactly ``16·4^m`` lateral triangles, the count of
Table 1's caption in Bhagvat et al. 2009. Open chain ends (``Frusta.open_lo`` /
``open_hi``) are closed by flat caps, ``8·2^m`` triangles each (a fan on the cutting
plane), as the ray caster closes them. :func:`triangle_count` gives the total.

Every vertex lies on the exact frustum surface, on a generator between the two cutting
planes (§2.3): column ``j`` of ring ``r`` is the point with ``u = j/N`` and ``v = r/B``,
so rings follow the oblique planes at both ends. Its normal is the interpolated normal
(8). A continuing row reuses its parent's top ring as its bottom ring (the joint's plane
is shared bit for bit), so chains are watertight; that ring lies on the parent's cone and
meets the child's cone up to the seam mismatch of §2.2 (zero with ``skin_skeleton(...,
seam_fit=True)``). The seam column ``u = 1`` is a copy of column ``u = 0`` (same position,
its own texture coordinate); weld vertices by position to see the closed surface.

Texture coordinates are ``(u, v + k)`` with ``k`` the row's place in its continuing
chain, so the shared joint ring has one ``v`` for both rows and no triangle interpolates
v backwards; a renderer subtracts ``k`` to get the per-row ``v`` of (7).

GS+R moves each vertex to the concentric cone ``r + w·shell`` at the same ``(u, v)``,
``w`` the relief height there: the shell of §3, whose ``(u, v)`` map "exactly along the
normals" of §2.4, the surface the ray caster marches. Its normals are (8) tilted by the
height map's gradient, as the ray caster shades relief.

**Cones closing to a point.** Where a row's radius reaches 0 on a cutting plane through
its tip (the well's roof), the end ring is one point. Its band is graded instead of
collapsed: the ring before the tip (``N`` columns) meets a half ring of ``N/2`` columns
a quarter band from the tip (``3N/2`` triangles), which a fan of ``N/2`` triangles joins
to the apex: still ``2N`` triangles a band, ``16·4^m`` a row, none of zero area (the
half ring sits close to the tip so that the coarser polygon costs little volume: at
m = 0 a cone keeps 88 % of its volume, against 90 % for ``N`` columns to the tip). The apex ring's
``N + 1`` vertices hold the half ring (even columns) and the apex (odd columns, each with
the ``u`` of its fan triangle); a closed end gets no cap. A row continuing from such a
point owns its own apex ring.

**Knuckles** (``skin_skeleton(max_bend_deg=...)``: bends past 120° by default) are found and
cut in :mod:`plantgen.geometry.meshes.knuckles`, whose docstring says how the mesh bounds them;
their rows no longer all carry ``16·4^m`` triangles (:attr:`TessellatedMesh.uniform_rows`).

Everything is vectorised over rows with index templates (one quad template shifted by
ring and column strides); rows are processed in chunks only to bound memory. Apex rings
are fixed up afterwards vectorised over the rows, knuckles knuckle by knuckle (they are
few).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ...tolerances import tol
from ..skeletons import relief as relief_maps
from ..skeletons.frusta import Frusta, relief_scale
from ..vec import cross, dot, reduce_to_root, unit
from .generators import bands_along, columns_around, generator_points, lateral_triangles_per_row, slice_triangles
from .knuckles import Knuckles, cut_height, find_knuckles

__all__ = [
    "TessellatedMesh", "tessellate", "triangle_count", "lateral_triangles_per_row",
    "slice_triangles", "columns_around", "bands_along", "generator_points", "outer_shell_mesh",
]

#: A relief height function: (material (k,) int, u (k,) float, v (k,) float) -> w (k,) in [0, 1].
HeightFunction = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def _check_level(m) -> int:
    if isinstance(m, bool) or int(m) != m or not 0 <= int(m) <= 8:
        raise ValueError(f"subdivision level must be an integer in 0..8, got {m!r}")
    return int(m)


# ---------------------------------------------------------------------------- the mesh
@dataclass(frozen=True, eq=False)
class TessellatedMesh:
    """A tessellated skin: lateral faces row by row, then the caps.

    ==================  ============  ======================================================
    ``vertices``        (V, 3) f8     positions, model units (y up)
    ``normals``         (V, 3) f4     unit interpolated normals (8) (GS+R: tilted by relief)
    ``uv``              (V, 2) f4     ``(u, v_tex + chain)``, u in [0, 1]; v_tex the row's
                                      share of the texture's v (``Frusta.v_part``), chain
                                      the texture v of the rows before it in its chain
    ``faces``           (F, 3) i4     counter-clockwise seen from outside
    ``face_row``        (F,) i4       frustum row of each face (nondecreasing over the
                                      lateral faces)
    ``material``        (n,) i4       material index per frustum row
    ``material_names``  tuple         names for ``material``
    ``level``           int           subdivision level m
    ``n_caps``          int           number of caps: the last ``n_caps·8·2^m`` faces,
                                      ``8·2^m`` a cap
    ==================  ============  ======================================================
    """

    vertices: np.ndarray
    normals: np.ndarray
    uv: np.ndarray
    faces: np.ndarray
    face_row: np.ndarray
    material: np.ndarray
    material_names: tuple
    level: int
    n_caps: int

    @property
    def n_rows(self) -> int:
        return len(self.material)

    @property
    def n_lateral(self) -> int:
        """Lateral faces (all but the caps)."""
        return len(self.faces) - self.n_caps * columns_around(self.level)

    @property
    def uniform_rows(self) -> bool:
        """Every row has exactly ``16·4^m`` lateral faces, in row order (no knuckle fans):
        a face's row is then its index // 16·4^m, as the raster shader assumes."""
        return self.n_lateral == self.n_rows * lateral_triangles_per_row(self.level)

    @property
    def face_material(self) -> np.ndarray:
        """(F,) int32 material index of each face."""
        return self.material[self.face_row]

    def buffer_bytes(self, index_dtype=np.uint32) -> dict:
        """Bytes a GPU draw of this mesh holds: float32 position, normal, uv; indices.

        Returns a dict with ``vertex``, ``index`` and ``total`` byte counts (the raster
        renderer uploads exactly these buffers).
        """
        vertex = len(self.vertices) * (3 + 3 + 2) * 4
        index = self.faces.size * np.dtype(index_dtype).itemsize
        return {"vertex": vertex, "index": index, "total": vertex + index}

    def to_trimesh(self, *, merge: bool = False):
        """A ``trimesh.Trimesh`` with the normals and uv kept (``merge``: weld the seam copies)."""
        import trimesh  # here, not at the top: importing trimesh takes about a second

        visual = trimesh.visual.TextureVisuals(uv=self.uv)
        mesh = trimesh.Trimesh(self.vertices, self.faces, vertex_normals=self.normals,
                               visual=visual, process=False, validate=False)
        if merge:
            mesh.merge_vertices(merge_tex=True, merge_norm=True)
        return mesh


def triangle_count(rows, m: int, n_caps: int | None = None, *, caps: bool | str = True) -> int:
    """Faces of a tessellation at level ``m``.

    ``rows`` a number of rows: ``rows·16·4^m + n_caps·8·2^m``, exact for frusta without
    knuckle fans (every row, a cone closing to a point included, gets ``16·4^m`` lateral
    triangles, every cap ``8·2^m``) and an upper bound with them (a knuckle's rows get
    fewer: ``(8·2^m - 2)·2^m`` an outer slice, none an inner slice, plus a bridge band
    where P's and C's cuts differ).

    ``rows`` a :class:`~plantgen.geometry.skeletons.frusta.Frusta`: exactly
    ``len(tessellate(rows, m, caps=caps).faces)`` (``n_caps`` is not used: ends closing
    to a point and inner knuckle slices get no cap).
    """
    if isinstance(rows, Frusta):
        plan = _plan(rows, _check_level(m), caps)
        return int(plan.row_faces.sum()) + plan.n_caps * columns_around(m)
    return int(rows) * lateral_triangles_per_row(m) + int(n_caps) * columns_around(m)


def _default_height(material_names) -> HeightFunction:
    """Heights from :mod:`plantgen.geometry.skeletons.relief`: the maps, repeats and bilinear sampler
    that the ray caster and the reference use."""
    maps, repeats = relief_maps.height_maps(material_names)

    def height(material, u, v):
        out = np.zeros(len(u))
        material = np.clip(material, 0, len(maps) - 1)
        for mat in np.unique(material):
            sel = material == mat
            rep_u, rep_v = repeats[mat]
            out[sel] = relief_maps.sample_height(maps[mat], u[sel] * rep_u, v[sel] * rep_v)
        return out

    return height


# ---------------------------------------------------------------------------- the plan
@dataclass
class _Plan:
    """What :func:`tessellate` builds for each of the n rows, before any vertex.

    ``grid`` rows get the ``N × B`` quad grid (``16·4^m`` triangles); ``lune`` rows are
    outer knuckle slices (their outer half); ``hidden`` rows get nothing (inner knuckle
    slices: no rings either). ``apex_lo``/``apex_hi``: the end ring is a point (graded
    band). ``owns_ring`` (n, B + 1) and ``ring_id`` (n, B + 1): the vertex ring of each
    row's ring (a continuing row shares its parent's top ring). ``row_faces`` (n,) lateral
    triangles per row; ``cap_rows``/``cap_is_top`` the caps; ``switch`` (K,) the lune ring
    where the hinge vertices change from P's to C's (unmerged knuckles); ``bridge_ring``
    (K,) the vertex ring after the ``n_rings`` lateral ones that copies C's ring at J for
    P's bridge, with P's texture coordinates (-1: no bridge).
    """

    columns: int
    bands: int
    knuckles: Knuckles | None
    grid: np.ndarray
    lune: np.ndarray
    hidden: np.ndarray
    apex_lo: np.ndarray
    apex_hi: np.ndarray
    owns_ring: np.ndarray
    ring_id: np.ndarray
    n_rings: int
    row_faces: np.ndarray
    cap_rows: np.ndarray
    cap_is_top: np.ndarray
    switch: np.ndarray
    bridge_ring: np.ndarray

    @property
    def n_caps(self) -> int:
        return len(self.cap_rows)

    @property
    def n_vertex_rings(self) -> int:
        """Rings of ``N + 1`` vertices before the caps: the lateral ones, the bridges'."""
        return self.n_rings + int(np.count_nonzero(self.bridge_ring >= 0))


def _apex_ends(frusta: Frusta, proper: np.ndarray):
    """(n,) bool pairs: rows whose lower / upper end ring is one point (radius 0 on a
    plane through the tip). A shared ring counts only where both rows agree; a row closing
    at both ends (no surface) keeps the plain grid."""
    scale = np.maximum(np.maximum(np.abs(frusta.r1), np.abs(frusta.r2)), frusta.length)
    eps = tol.zero_length * scale
    off_lo = np.abs(dot(frusta.plane_lo[:, :3], frusta.base) - frusta.plane_lo[:, 3])
    off_hi = np.abs(dot(frusta.plane_hi[:, :3], frusta.top) - frusta.plane_hi[:, 3])
    lo = proper & (np.abs(frusta.r1) <= eps) & (off_lo <= eps)
    hi = proper & (np.abs(frusta.r2) <= eps) & (off_hi <= eps)
    both = lo & hi
    lo, hi = lo & ~both, hi & ~both
    shared = np.flatnonzero(frusta.parent_row >= 0)
    parent = frusta.parent_row[shared]
    disagree = hi[parent] != lo[shared]
    hi[parent[disagree]] = False
    lo[shared[disagree]] = False
    return lo, hi


def _plan(frusta: Frusta, m: int, caps) -> _Plan:
    """The :class:`_Plan` of ``frusta`` at level ``m`` with ``caps`` (see :func:`tessellate`)."""
    if caps not in (True, False, "tips"):
        raise ValueError(f"caps must be True, False or 'tips', got {caps!r}")
    n = len(frusta.length)
    columns, bands = columns_around(m), bands_along(m)
    kn = find_knuckles(frusta)
    grid, lune, hidden = np.ones(n, bool), np.zeros(n, bool), np.zeros(n, bool)
    if kn is not None:
        grid[kn.slices] = grid[kn.inner] = False
        hidden[kn.inner] = True
        lune[kn.slices[~kn.flat[kn.slice_knuckle]]] = True
    apex_lo, apex_hi = _apex_ends(frusta, grid)
    parent = frusta.parent_row
    shared = parent >= 0
    owns_ring = np.ones((n, bands + 1), dtype=bool)
    owns_ring[:, 0] = ~shared | apex_lo
    owns_ring[hidden] = False
    ring_id = np.full((n, bands + 1), -1, np.int64)
    ring_id[owns_ring] = np.arange(int(owns_ring.sum()))
    borrow = np.flatnonzero(~owns_ring[:, 0] & ~hidden)     # parent first: one pass suffices
    ring_id[borrow, 0] = ring_id[parent[borrow], bands]

    row_faces = np.where(grid, lateral_triangles_per_row(m), 0).astype(np.int64)
    row_faces[lune] = slice_triangles(m)
    switch = bridge_ring = np.zeros(0, np.int64)
    open_lo = ~shared & ~hidden & ~apex_lo
    continued = np.zeros(n, bool)
    continued[parent[shared]] = True
    open_hi = ~continued & ~hidden & ~apex_hi
    if kn is not None:
        count = np.diff(kn.start)
        switch = ((count * bands + 1) // 2).astype(np.int64)     # lune ring index ℓ, P's top is 0
        split = ~kn.flat & ~kn.merged
        band = switch - 1
        row_faces[kn.slices[kn.start[:-1] + band // bands][split]] += 2
        bridged = ~kn.flat & ~kn.mitred
        row_faces[kn.parent[bridged]] += np.where(kn.merged[bridged], columns - 2, columns)
        bridge_ring = np.full(len(kn.parent), -1, np.int64)
        bridge_ring[bridged] = int(owns_ring.sum()) + np.arange(int(bridged.sum()))
        stepped = kn.flat & ~kn.merged
        open_hi[kn.parent[stepped]] = True
        open_lo[kn.child[stepped]] = True
    none = np.zeros(0, np.int64)
    bottom = np.flatnonzero(open_lo) if caps is True else none
    top = np.flatnonzero(open_hi) if caps else none
    return _Plan(columns, bands, kn, grid, lune, hidden, apex_lo, apex_hi, owns_ring, ring_id,
                 int(owns_ring.sum()), row_faces, np.concatenate([bottom, top]),
                 np.concatenate([np.zeros(len(bottom), bool), np.ones(len(top), bool)]), switch,
                 bridge_ring)


def _column_turns(frusta: Frusta, plan: _Plan):
    """(n,) pairs ``(delta_lo, delta_inc)``: ring r of a row puts its columns at
    ``u = j/N + delta_lo + (r/B)·delta_inc``. Zero without knuckles. P's top ring turns by
    at most half a column so that its column ``hinge_col`` sits on the hinge point;
    slices carry that on (their increment is their twist, which keeps the hinge on one
    column); later rows inherit the turn. Sets ``knuckles.hinge_col``."""
    n, kn = len(frusta.length), plan.knuckles
    inc = np.zeros(n)
    if kn is None:
        return inc, inc
    columns, parent = plan.columns, frusta.parent_row
    inc[kn.slices] = frusta.twist[kn.slices]
    is_p = np.zeros(n, np.int64)
    is_p[kn.parent] = 1
    level = reduce_to_root(parent, is_p, np.add)[kn.parent] - 1   # knuckles upstream
    kn.hinge_col = np.zeros(len(kn.parent), np.int64)
    for lv in range(int(level.max()) + 1):
        sel = (level == lv) & ~kn.flat
        if not sel.any():
            continue
        rows = kn.parent[sel]
        delta_lo = reduce_to_root(parent, inc, np.add)[rows] - inc[rows]
        axis, ref = frusta.axis[rows], frusta.ref_dir[rows]
        e = unit(kn.hinge[sel] - axis * dot(kn.hinge[sel], axis)[:, None])
        phi = np.arctan2(dot(e, cross(axis, ref)), dot(e, ref))
        u_hinge = phi / (2 * np.pi) + frusta.u_offset[rows] + frusta.twist[rows]
        t = (u_hinge - delta_lo) * columns
        nearest = np.round(t)
        inc[rows] = (t - nearest) / columns
        kn.hinge_col[sel] = np.mod(nearest, columns).astype(np.int64)
    total = reduce_to_root(parent, inc, np.add)
    return total - inc, inc


# ---------------------------------------------------------------------------- vertices
def _surface(frusta: Frusta, relief: bool, height, step_u: float, step_v: float):
    """``evaluate(rows, u, v) -> (points, normals)``: :func:`generator_points` of rows
    (k, 1) at texture coordinates (k, C) (broadcast), on the relief shell if ``relief``
    (heights ``height``, gradient by central differences ``step_u``, ``step_v`` apart)."""
    material, shell = frusta.material, frusta.shell
    slot, slots = frusta.v_part[:, 0].astype(np.float64), frusta.v_part[:, 1].astype(np.float64)

    def evaluate(rows, u, v):
        if not relief:
            return generator_points(frusta, rows, u, v)
        uu, vv = np.broadcast_arrays(u, v)
        shape = np.broadcast_shapes(uu.shape, rows.shape)
        uu, vv = np.broadcast_to(uu, shape), np.broadcast_to(vv, shape)
        mm = np.broadcast_to(material[rows], shape).ravel()
        n_slots = np.broadcast_to(slots[rows], shape)
        # the heights at the texture's v (Frusta.v_part), the geometry at the row's own v
        uu, vv = uu.ravel() % 1.0, ((np.broadcast_to(slot[rows], shape) + vv) / n_slots).ravel()

        def w_at(du, dv):
            return np.asarray(height(mm, (uu + du) % 1.0, vv + dv), dtype=np.float64).reshape(shape)

        # the relief's depth where the inner cone's point lies (relief_scale: it follows
        # the radius, as the ray caster's does)
        inner, _ = generator_points(frusta, rows, u, v)
        rows_b = np.broadcast_to(rows, shape)
        along = dot(inner - frusta.base[rows_b], frusta.axis[rows_b]).reshape(shape)
        thick = shell[rows] * relief_scale(frusta, rows_b.ravel(), along.ravel()).reshape(shape)
        offset = np.clip(w_at(0.0, 0.0), 0.0, 1.0) * thick
        # Central differences one texel apart, as the ray caster takes them (per unit of the
        # row's own v: the texture's v moves 1/slots as fast).
        slope = ((w_at(step_u, 0.0) - w_at(-step_u, 0.0)) / (2 * step_u) * thick,
                 (w_at(0.0, step_v) - w_at(0.0, -step_v)) / (2 * step_v) * thick / n_slots)
        return generator_points(frusta, rows, u, v, offset, slope)

    return evaluate


@dataclass
class _Buffers:
    """The vertex arrays being filled: lateral rings (``N + 1`` slots each, ring by ring
    in ``ring_id`` order) then the caps."""

    vertices: np.ndarray
    normals: np.ndarray
    uv: np.ndarray
    ring_size: int

    def put(self, ring, slots, pts, nrm, u, v) -> None:
        """Write points, normals and texture coordinates (broadcast) at ``slots`` of the
        vertex rings ``ring`` (broadcast against ``slots``)."""
        idx = np.asarray(ring)[..., None] * self.ring_size + slots
        self.vertices[idx] = pts
        self.normals[idx] = nrm
        self.uv[idx, 0] = u
        self.uv[idx, 1] = v


def _ring_vertices(frusta: Frusta, plan: _Plan, turns, evaluate, buf: _Buffers, chunk: int) -> None:
    """Every owned ring at ``u = j/N`` (turned by ``turns``) and ``v = r/B``, chunked."""
    columns, bands = plan.columns, plan.bands
    u_col = np.arange(columns + 1) / columns
    chain_v, span = frusta.chain_texture_v, frusta.v_span
    delta_lo, delta_inc = turns
    turned = plan.knuckles is not None
    rows_all, ring_all = np.nonzero(plan.owns_ring)  # row-major: matches ring_id order
    step = max(1, int(chunk) // (columns + 1))
    for lo in range(0, plan.n_rings, step):
        hi = min(plan.n_rings, lo + step)
        rows, ring = rows_all[lo:hi], ring_all[lo:hi]
        v = (ring / bands)[:, None]
        u = u_col[None, :]
        if turned:
            u = u + (delta_lo[rows] + ring / bands * delta_inc[rows])[:, None]
        pts, nrm = evaluate(rows[:, None], u, v)
        sl = slice(lo * (columns + 1), hi * (columns + 1))
        buf.vertices[sl] = pts.reshape(-1, 3)
        buf.normals[sl] = nrm.reshape(-1, 3)
        buf.uv[sl, 0] = np.broadcast_to(u, pts.shape[:2]).ravel()
        buf.uv[sl, 1] = np.broadcast_to(v * span[rows][:, None] + chain_v[rows][:, None], pts.shape[:2]).ravel()


def _apex_vertices(frusta: Frusta, plan: _Plan, turns, evaluate, buf: _Buffers) -> None:
    """Apex rings: the half ring (even columns) a quarter band from the tip, and one apex
    position for the odd columns (their mean: a relief shell moves them apart)."""
    columns, bands = plan.columns, plan.bands
    chain_v, span = frusta.chain_texture_v, frusta.v_span
    even = np.arange(0, columns + 1, 2)
    odd = np.arange(1, columns, 2)
    for rows, ring, v_half in ((np.flatnonzero(plan.apex_hi), bands, 1 - 0.25 / bands),
                               (np.flatnonzero(plan.apex_lo), 0, 0.25 / bands)):
        if rows.size == 0:
            continue
        u = even / columns + (turns[0][rows] + ring / bands * turns[1][rows])[:, None]
        pts, nrm = evaluate(rows[:, None], u, np.full((1, 1), v_half))
        rid = plan.ring_id[rows, ring]
        buf.put(rid, even, pts, nrm, u, v_half * span[rows][:, None] + chain_v[rows][:, None])
        tip = rid[:, None] * buf.ring_size + odd
        buf.vertices[tip] = buf.vertices[tip].mean(axis=1, keepdims=True)


def _trimmed_rings(frusta: Frusta, plan: _Plan, turns, evaluate, rows):
    """Rings 0..B of ``rows`` (T,) cut by their knuckles' trimming planes: each column's
    generator (fixed by ``u = j/N`` turned and ``v = r/B``) runs from its lower to its
    upper cut, where on the inner half a trimming plane may replace the row's own plane
    (the nearer one wins); the vertex sits at the fraction r/B of that, with the ray
    caster's (u, v) and normal (8) there. Returns points, normals, u, v (T, B + 1, N + 1)."""
    kn, columns, bands = plan.knuckles, plan.columns, plan.bands
    r = rows[:, None, None]
    v_nom = (np.arange(bands + 1) / bands)[None, :, None]
    u = (np.arange(columns + 1) / columns)[None, None, :] + (
        turns[0][rows][:, None] + np.arange(bands + 1) / bands * turns[1][rows][:, None])[..., None]
    phi = 2 * np.pi * (u - frusta.u_offset[r] - v_nom * frusta.twist[r])
    ref = frusta.ref_dir[r]
    e = np.cos(phi)[..., None] * ref + np.sin(phi)[..., None] * cross(frusta.axis[r], ref)
    y_lo = cut_height(frusta, r, e, frusta.plane_lo[r])[0]
    y_hi = cut_height(frusta, r, e, frusta.plane_hi[r])[0]
    y_a, y_b = y_lo, y_hi
    for ends, planes, inner in ((kn.child, kn.plane_c, kn.inner_c), (kn.parent, kn.plane_p, kn.inner_p)):
        which = np.full(len(frusta.length), -1, np.int64)
        keep = ~kn.flat
        which[ends[keep]] = np.flatnonzero(keep)
        k = which[rows]
        has = k >= 0
        if not has.any():
            continue
        kk = np.maximum(k, 0)[:, None, None]
        y_t = cut_height(frusta, r, e, planes[kk])[0]
        side = has[:, None, None] & (dot(e, inner[kk]) > 0)
        if ends is kn.child:
            y_a = np.where(side, np.maximum(y_lo, y_t), y_a)
        else:
            y_b = np.where(side, np.minimum(y_hi, y_t), y_b)
    y = y_a + v_nom * (y_b - y_a)
    span = y_hi - y_lo
    v = (y - y_lo) / np.where(span != 0, span, 1.0)
    u_rc = u + (v - v_nom) * frusta.twist[r]
    pts, nrm = evaluate(rows[:, None, None], u_rc, v)
    return pts, nrm, u_rc, v


def _knuckle_vertices(frusta: Frusta, plan: _Plan, turns, evaluate, buf: _Buffers) -> None:
    """Trimmed rings of P and C, C's inner half ring at J (a copy of P's where mitred),
    one position per hinge point along each lune, and the flat knuckles' copies."""
    kn, columns, bands = plan.knuckles, plan.columns, plan.bands
    chain_v, span = frusta.chain_texture_v, frusta.v_span
    live = ~kn.flat
    rows = np.unique(np.concatenate([kn.parent[live], kn.child[live]]))
    if rows.size:
        pts, nrm, u, v = _trimmed_rings(frusta, plan, turns, evaluate, rows)
        v_tex = v * span[rows][:, None, None] + chain_v[rows][:, None, None]
        own = plan.owns_ring[rows]
        buf.put(plan.ring_id[rows][own], np.arange(columns + 1), pts[own], nrm[own], u[own], v_tex[own])
        # C's ring at J belongs to the last slice: C writes its inner half and hinges
        at = np.searchsorted(rows, kn.child[live])
        jh = kn.hinge_col[live]
        slots = np.arange(columns + 1)
        from_hinge = (slots[None, :] - jh[:, None]) % columns
        inner = (from_hinge >= columns // 2) | (from_hinge == 0)
        ring_c = plan.ring_id[kn.child[live], 0]
        ring_p = plan.ring_id[kn.parent[live], bands]
        for i in range(int(live.sum())):
            s = slots[inner[i]]
            buf.put(ring_c[i], s, pts[at[i], 0, s], nrm[at[i], 0, s], u[at[i], 0, s], v_tex[at[i], 0, s])
        mitred = kn.mitred[live]
        for i in np.flatnonzero(mitred):
            s = slots[inner[i]]
            buf.vertices[ring_c[i] * buf.ring_size + s] = buf.vertices[ring_p[i] * buf.ring_size + s]
        _hinge_points(plan, buf, np.flatnonzero(live))
        size = buf.ring_size
        for k in np.flatnonzero(plan.bridge_ring >= 0):   # C's cut, in P's texture frame
            copy = slice(plan.bridge_ring[k] * size, (plan.bridge_ring[k] + 1) * size)
            c0 = plan.ring_id[kn.child[k], 0] * size
            p_top = plan.ring_id[kn.parent[k], bands] * size
            buf.vertices[copy] = buf.vertices[c0:c0 + size]
            buf.normals[copy] = buf.normals[c0:c0 + size]
            buf.uv[copy] = buf.uv[p_top:p_top + size]
    for k in np.flatnonzero(kn.flat & kn.merged):
        top = plan.ring_id[kn.parent[k], bands] * buf.ring_size
        bottom = plan.ring_id[kn.child[k], 0] * buf.ring_size
        buf.vertices[bottom:bottom + buf.ring_size] = buf.vertices[top:top + buf.ring_size]


def _hinge_points(plan: _Plan, buf: _Buffers, knuckles) -> None:
    """Give every lune ring's hinge columns one position a side: P's hinge point up to
    the switch ring, C's after it (the same point where the knuckle is merged)."""
    kn, columns, bands = plan.knuckles, plan.columns, plan.bands
    size = buf.ring_size
    for k in knuckles:
        jh = int(kn.hinge_col[k])
        sides = [[jh] + ([columns] if jh == 0 else []),
                 [(jh + columns // 2) % columns] + ([columns] if (jh + columns // 2) % columns == 0 else [])]
        ring_p = plan.ring_id[kn.parent[k], bands]
        ring_c = plan.ring_id[kn.child[k], 0]
        slices = kn.slices[kn.start[k]:kn.start[k + 1]]
        lune = plan.ring_id[slices, 1:].ravel()          # ℓ = 1 .. L - 1
        for side in sides:
            h_p = buf.vertices[ring_p * size + side[0]].copy()
            h_c = h_p if kn.merged[k] else buf.vertices[ring_c * size + side[0]].copy()
            for ell, ring in enumerate(lune, start=1):
                buf.vertices[ring * size + np.array(side)] = h_p if ell < plan.switch[k] else h_c
            buf.vertices[ring_p * size + np.array(side)] = h_p


# ---------------------------------------------------------------------------- faces
def _quads(lower, upper, a, b):
    """(..., 2, 3) the two triangles (l_a, l_b, u_b), (l_a, u_b, u_a) of the quads between
    vertex indices ``lower + a``, ``lower + b`` and ``upper + b``, ``upper + a``
    (broadcast): counter-clockwise from outside when ``b`` follows ``a`` around the axis
    and ``upper`` is the ring above ``lower``."""
    la, lb, ua, ub = lower + a, lower + b, upper + a, upper + b
    out = np.empty(np.broadcast_shapes(la.shape, ub.shape) + (2, 3), np.result_type(la, ub))
    out[..., 0, 0] = la
    out[..., 0, 1] = lb
    out[..., 0, 2] = ub
    out[..., 1, 0] = la
    out[..., 1, 1] = ub
    out[..., 1, 2] = ua
    return out


def _grid_faces(plan: _Plan, rows, dtype) -> np.ndarray:
    """(len(rows), 16·4^m, 3): the quad grid of each row, band by band (graded at apexes)."""
    columns, bands, size = plan.columns, plan.bands, plan.columns + 1
    band_start = (plan.ring_id[rows, :-1] * size).astype(dtype)
    band_next = (plan.ring_id[rows, 1:] * size).astype(dtype)
    j = np.arange(columns, dtype=dtype)
    faces = _quads(band_start[:, :, None], band_next[:, :, None], j, j + 1)
    faces = faces.reshape(len(rows), -1, 3)
    half = np.arange(columns // 2, dtype=dtype)
    for apex, band, at_top in ((plan.apex_hi[rows], bands - 1, True), (plan.apex_lo[rows], 0, False)):
        if not apex.any():
            continue
        lo = band_start[apex, band][:, None]
        hi = band_next[apex, band][:, None]
        if at_top:
            h0, h1, tip = hi + 2 * half, hi + 2 * half + 2, hi + 2 * half + 1
            l0, l1, l2 = lo + 2 * half, lo + 2 * half + 1, lo + 2 * half + 2
            graded = [(l0, l1, h0), (l1, l2, h1), (l1, h1, h0), (h0, h1, tip)]
        else:
            h0, h1, tip = lo + 2 * half, lo + 2 * half + 2, lo + 2 * half + 1
            u0, u1, u2 = hi + 2 * half, hi + 2 * half + 1, hi + 2 * half + 2
            graded = [(tip, h1, h0), (h0, h1, u1), (h1, u2, u1), (h0, u1, u0)]
        block = np.stack([np.stack(t, -1) for t in graded], -2).reshape(int(apex.sum()), -1, 3)
        faces[np.flatnonzero(apex), band * 2 * columns:(band + 1) * 2 * columns] = block
    return faces


def _strip_faces(lower, upper, first, columns, fan_a, fan_b) -> np.ndarray:
    """Triangles of the ``columns // 2`` quads from column ``first`` on between the
    vertex rings starting at ``lower`` and ``upper`` (scalars); where ``fan_a`` (``fan_b``)
    the first (last) quad has one corner pair on a hinge point and keeps one triangle."""
    t = np.arange(columns // 2)
    a = (first + t) % columns
    tri = _quads(lower, upper, a, a + 1)
    keep = np.ones((len(t), 2), bool)
    keep[0, 1] = not fan_a
    keep[-1, 0] = not fan_b
    return tri[keep]


def _knuckle_faces(plan: _Plan) -> dict:
    """{row: (k, 3) faces} of the knuckles: each outer slice's strips over the outer half
    (fanned at the hinge points, except across the switch ring of an unmerged knuckle),
    and P's bridge band to C's cut where they are not one curve."""
    kn, columns, bands, size = plan.knuckles, plan.columns, plan.bands, plan.columns + 1
    out = {}
    for k in np.flatnonzero(~kn.flat):
        jh = int(kn.hinge_col[k])
        for i, row in enumerate(kn.slices[kn.start[k]:kn.start[k + 1]]):
            strips = []
            for band in range(bands):
                ell = i * bands + band + 1                  # the upper ring's ℓ
                fan = bool(kn.merged[k]) or ell != plan.switch[k]
                strips.append(_strip_faces(plan.ring_id[row, band] * size,
                                           plan.ring_id[row, band + 1] * size, jh, columns, fan, fan))
            out[int(row)] = np.concatenate(strips)
        if not kn.mitred[k]:
            merged = bool(kn.merged[k])
            out[int(kn.parent[k])] = _strip_faces(plan.ring_id[kn.parent[k], bands] * size,
                                                  plan.bridge_ring[k] * size,
                                                  jh + columns // 2, columns, merged, merged)
    return out


def _lateral_faces(plan: _Plan, dtype) -> np.ndarray:
    """All lateral faces, row by row: each grid row's grid, then (P rows) its bridge;
    each outer slice's strips."""
    n = len(plan.grid)
    total = int(plan.row_faces.sum())
    grid_rows = np.flatnonzero(plan.grid)
    per_row = 2 * plan.columns * plan.bands
    if plan.knuckles is None:
        return _grid_faces(plan, grid_rows, dtype).reshape(-1, 3)
    first = np.concatenate([[0], np.cumsum(plan.row_faces)[:-1]]) if n else np.zeros(0, np.int64)
    faces = np.empty((total, 3), dtype)
    grid = _grid_faces(plan, grid_rows, dtype)
    faces[(first[grid_rows][:, None] + np.arange(per_row)).ravel()] = grid.reshape(-1, 3)
    for row, extra in _knuckle_faces(plan).items():
        at = first[row] + (per_row if plan.grid[row] else 0)
        faces[at:at + len(extra)] = extra
    return faces


def _cap_faces(frusta: Frusta, plan: _Plan, buf: _Buffers, first_vertex: int, dtype) -> np.ndarray:
    """Caps: a copy of the end ring with the plane's normal, plus a centre vertex; a fan."""
    columns, bands, size = plan.columns, plan.bands, plan.columns + 1
    cap_rows, cap_is_top = plan.cap_rows, plan.cap_is_top
    if not len(cap_rows):
        return np.zeros((0, 3), dtype)
    ring_of_cap = np.where(cap_is_top, plan.ring_id[cap_rows, bands], plan.ring_id[cap_rows, 0])
    src = ring_of_cap[:, None] * size + np.arange(size)  # (n_caps, ring_size)
    cap_first = first_vertex + np.arange(len(cap_rows)) * (size + 1)
    dst = cap_first[:, None] + np.arange(size)
    centre = cap_first + size
    buf.vertices[dst] = buf.vertices[src]
    buf.uv[dst] = buf.uv[src]
    plane = np.where(cap_is_top[:, None], frusta.plane_hi[cap_rows], frusta.plane_lo[cap_rows])
    outward = np.where(cap_is_top[:, None], plane[:, :3], -plane[:, :3])
    buf.normals[dst] = outward[:, None, :]
    buf.normals[centre] = outward
    buf.vertices[centre] = buf.vertices[src[:, :columns]].mean(axis=1)  # centroid of the ring (on the plane)
    buf.uv[centre, 0] = 0.5
    buf.uv[centre, 1] = buf.uv[src[:, 0], 1]
    first, second = dst[:, :columns], dst[:, 1:]
    ctr = np.broadcast_to(centre[:, None], first.shape)
    top_tri = np.stack([ctr, first, second], -1)
    bottom_tri = np.stack([ctr, second, first], -1)
    return np.where(cap_is_top[:, None, None], top_tri, bottom_tri).reshape(-1, 3).astype(dtype)


# ---------------------------------------------------------------------------- tessellate
def tessellate(frusta: Frusta, m: int = 1, *, relief: bool = False, height: HeightFunction | None = None,
               caps: bool | str = True, gradient_step: tuple[float, float] | None = None,
               chunk_vertices: int = 1 << 19) -> TessellatedMesh:
    """Tessellate frusta at subdivision level ``m`` (GS), optionally displaced (GS+R).

    Parameters
    ----------
    frusta : a Frusta (see :mod:`plantgen.geometry.skeletons.frusta`) with ``n`` rows
    m : subdivision level, 0..8; ``16·4^m`` lateral triangles per row (knuckle fan rows:
        see the module docstring and :func:`triangle_count`)
    relief : displace vertices by ``w·shell`` onto the relief shell (rows with
        ``shell = 0`` stay on the base cone)
    height : ``height(material, u, v) -> w`` in [0, 1] for (k,) arrays; default: the
        height maps of :mod:`plantgen.geometry.skeletons.relief`, sampled as the ray caster samples
    caps : True: close every open chain end (roots, side branch starts, tips) with a flat
        cap, so each chain is a closed solid (export); ``"tips"``: cap only the upper
        ends (side branch bases sit inside their parent, unseen: the rendering choice);
        False: no caps. Ends closing to a point need no cap and get none.
    gradient_step : (du, dv) of the central differences that tilt relief normals (GS+R);
        default one texel of the relief maps (1/256 for a custom ``height``)
    chunk_vertices : vertices computed at a time; bounds the float64 scratch memory
        (about 0.4 KiB per vertex)

    Returns
    -------
    TessellatedMesh
    """
    m = _check_level(m)
    plan = _plan(frusta, m, caps)
    names = frusta.material_names
    step_u = step_v = 1.0 / 256
    if relief and height is None:
        height = _default_height(names)
        texels_v, texels_u = relief_maps.height_maps(names)[0].shape[1:]
        step_u, step_v = 1.0 / texels_u, 1.0 / texels_v
    if gradient_step is not None:
        step_u, step_v = (float(x) for x in gradient_step)
    evaluate = _surface(frusta, relief, height, step_u, step_v)
    turns = _column_turns(frusta, plan)

    size = plan.columns + 1  # seam column duplicated
    n_lateral_vertices = plan.n_vertex_rings * size
    n_vertices = n_lateral_vertices + plan.n_caps * (size + 1)
    buf = _Buffers(np.empty((n_vertices, 3)), np.empty((n_vertices, 3), np.float32),
                   np.empty((n_vertices, 2), np.float32), size)
    _ring_vertices(frusta, plan, turns, evaluate, buf, chunk_vertices)
    if plan.apex_lo.any() or plan.apex_hi.any():
        _apex_vertices(frusta, plan, turns, evaluate, buf)
    if plan.knuckles is not None:
        _knuckle_vertices(frusta, plan, turns, evaluate, buf)
    seam = np.arange(plan.n_vertex_rings) * size
    buf.vertices[seam + plan.columns] = buf.vertices[seam]   # the u = 1 copy, bit for bit

    dtype = np.int32 if n_vertices < 2**31 else np.int64
    lateral = _lateral_faces(plan, dtype)
    cap_faces = _cap_faces(frusta, plan, buf, n_lateral_vertices, dtype)
    faces = np.concatenate([lateral, cap_faces])
    face_row = np.concatenate([np.repeat(np.arange(len(plan.grid), dtype=np.int32), plan.row_faces),
                               np.repeat(plan.cap_rows.astype(np.int32), plan.columns)])
    vertices, normals, uv = buf.vertices, buf.normals, buf.uv
    if plan.knuckles is not None:                          # drop the vertices no face uses
        used = np.zeros(n_vertices, bool)
        used[faces.ravel()] = True
        if not used.all():
            new_index = np.cumsum(used) - 1
            faces = new_index[faces].astype(dtype)
            vertices, normals, uv = vertices[used], normals[used], uv[used]
    return TessellatedMesh(vertices, normals, uv, faces, face_row, frusta.material, names, m, plan.n_caps)


def _top_of_shell(material, u, v):
    """The relief height w = 1 everywhere: the outer shell."""
    return np.ones(np.shape(u))


def outer_shell_mesh(frusta: Frusta, m: int = 1, *, caps: bool | str = "tips") -> TessellatedMesh:
    """The mesh of GS+POM: :func:`tessellate` at level ``m`` on the relief's outer shell
    (every vertex at ``r + shell``, the top of the relief, its normal the cone's (8); rows
    with ``shell = 0`` stay on the base cone), so that what the mesh covers holds the whole
    relief and the parallax march goes down from it (``shaders/raster.glsl``, PARALLAX)."""
    return tessellate(frusta, m, relief=True, height=_top_of_shell, caps=caps)
