"""Geometric subdivision (GS, GS+R): tessellate conical frusta into triangle meshes.

Level ``m`` puts ``8·2^m`` columns around each frustum's axis and ``2^m`` bands along it,
so every frustum row gives exactly ``16·4^m`` lateral triangles, the count of Table 1's
caption in Bhagvat et al. 2009. Open chain ends (``Frusta.open_lo`` / ``open_hi``) are
closed by flat caps, ``8·2^m`` triangles each (a fan on the cutting plane), as the ray
caster closes them; :func:`triangle_count` gives the total.

Every vertex lies on the exact frustum surface, on a generator between the two cutting
planes (§2.3): column ``j`` of ring ``r`` is the point with ``u = j/N`` (``N = 8·2^m``)
and ``v = r/2^m``, so rings follow the oblique planes at both ends. Its normal is the
interpolated normal (8). A continuing row reuses its parent's top ring as its bottom
ring (the joint's plane is shared bit for bit), so chains are watertight; that ring lies
on the parent's cone and meets the child's cone up to the seam mismatch of §2.2 (zero
with ``skin_skeleton(..., seam_fit=True)``). The seam column ``u = 1`` is a copy of
column ``u = 0`` (for texture coordinates); weld vertices by position to see the closed
surface.

Texture coordinates are ``(u, v + k)`` with ``k`` the row's place in its continuing
chain, so the shared joint ring has one ``v`` for both rows and no triangle interpolates
v backwards; a renderer subtracts ``k`` to get the per-row ``v`` of (7).

GS+R moves each vertex to the concentric cone ``r + w·shell`` at the same ``(u, v)``,
``w`` the relief height there: the shell of §3, whose ``(u, v)`` map "exactly along the
normals" of §2.4, the surface the ray caster marches. Its normals are (8) tilted by the
height map's gradient, as the ray caster shades relief.

Everything is vectorised over rows with index templates (one quad template shifted by
ring and column strides); rows are processed in chunks only to bound memory.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..tolerances import tol
from . import relief as relief_maps
from .frusta import Frusta, plane_height

__all__ = [
    "TessellatedMesh", "tessellate", "triangle_count", "lateral_triangles_per_row",
    "columns_around", "bands_along", "generator_points",
]

#: A relief height function: (material (k,) int, u (k,) float, v (k,) float) -> w (k,) in [0, 1].
HeightFunction = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def columns_around(m: int) -> int:
    """Number of vertex columns around the axis at level ``m``: ``8·2^m``."""
    return 8 * 2 ** int(m)


def bands_along(m: int) -> int:
    """Number of bands (rings minus one) along the axis at level ``m``: ``2^m``."""
    return 2 ** int(m)


def lateral_triangles_per_row(m: int) -> int:
    """Lateral triangles per frustum row at level ``m``: ``16·4^m`` (Table 1's caption)."""
    return 2 * columns_around(m) * bands_along(m)


def _check_level(m) -> int:
    if isinstance(m, bool) or int(m) != m or not 0 <= int(m) <= 8:
        raise ValueError(f"subdivision level must be an integer in 0..8, got {m!r}")
    return int(m)


# ---------------------------------------------------------------------------- geometry
def generator_points(frusta: Frusta, rows, u, v, offset=0.0, relief_slope=None):
    """Surface points at texture coordinates ``(u, v)``: the inverse of (6)–(7).

    The generator at angle ``φ = 2π(u - u_offset - v·twist)`` around the axis (``φ = 0``
    along ``ref_dir``) is cut by the two planes at ``P_l`` and ``P_u``; the point is
    ``P = P_l + v·(P_u - P_l)``. ``offset`` moves to the concentric cone with radii
    ``r1 + offset`` and ``r2 + offset`` (the relief shell of §3).

    All arguments broadcast against each other (numpy rules), so a grid of rows (k, 1, 1),
    rings (k, R, 1) and columns (1, 1, C) costs trigonometry only per column and per ring.

    Parameters
    ----------
    rows : int array, frustum row of each point
    u, v : float arrays, texture coordinates (u in turns, v in [0, 1])
    offset : float array or scalar, radial offset in model units
    relief_slope : optional pair ``(shell·∂w/∂u, shell·∂w/∂v)`` (model units per unit of
        u and v): tilt the normal by the relief's gradient as the ray caster shades
        relief (``N - shell·(∂w/∂u·t_u/|∂P/∂u| + ∂w/∂v·t_v/|∂P/∂v|)``, t_u around the
        axis, t_v along the generator, |∂P/∂u| = 2πρ, |∂P/∂v| the generator between
        the planes)

    Returns
    -------
    points : (..., 3) float64, model units
    normals : (..., 3) float64, unit interpolated normals (8)
    """
    rows = np.asarray(rows)
    u, v, offset = (np.asarray(x, dtype=np.float64) for x in (u, v, offset))
    length = frusta.length[rows]
    r1 = frusta.r1[rows]
    slope = frusta.slope[rows]
    axis = frusta.axis[rows]
    ref = frusta.ref_dir[rows]
    binormal = np.cross(axis, ref)
    # φ = 2πu - β with β = 2π(u_offset + v·twist): cos and sin by the angle-difference rule.
    beta = 2 * np.pi * (frusta.u_offset[rows] + v * frusta.twist[rows])
    cos_u, sin_u = np.cos(2 * np.pi * u), np.sin(2 * np.pi * u)
    cos_b, sin_b = np.cos(beta), np.sin(beta)
    cos_phi = cos_u * cos_b + sin_u * sin_b
    sin_phi = sin_u * cos_b - cos_u * sin_b
    start_radius = r1 + offset

    def axial_cut(plane):
        """Axial coordinate y (from C1) where each generator meets ``plane``."""
        normal, d = plane[rows, :3], plane[rows, 3]
        n_axis = np.einsum("...j,...j->...", normal, axis)
        n_radial = cos_phi * np.einsum("...j,...j->...", normal, ref) \
            + sin_phi * np.einsum("...j,...j->...", normal, binormal)
        # relative to C1 so far models keep digits; a generator ∥ the plane stays finite
        gap = d - np.einsum("...j,...j->...", normal, frusta.base[rows])
        return plane_height(gap, n_axis, n_radial, start_radius, slope,
                            guard=lambda rise: np.where(np.abs(rise) < tol.tiny,
                                                        np.copysign(tol.tiny, rise), rise))[0]

    y_lo, y_hi = axial_cut(frusta.plane_lo), axial_cut(frusta.plane_hi)
    y = y_lo + v * (y_hi - y_lo)  # P = P_l + v (P_u - P_l) along the straight generator
    radial = cos_phi[..., None] * ref + sin_phi[..., None] * binormal
    points = frusta.base[rows] + y[..., None] * axis + (start_radius + slope * y)[..., None] * radial

    # Normals (8): N_l = P_l - C1, N_u = P_u - C2, each made unit, blended by v. Both
    # lie in the plane of the axis and the radial direction, so the blend is done on
    # (axial, radial) components. Where a cone closes to a point on a plane (P_l = C1 or
    # P_u = C2) the cone's own outward normal on that generator, (-k, 1), stands in.
    cone_len = np.hypot(slope, 1.0)
    scale = np.maximum(np.maximum(np.abs(r1), np.abs(frusta.r2[rows])), length)

    def unit_or_cone(axial, radius):
        norm = np.hypot(axial, radius)
        tiny = norm <= tol.zero_length * scale
        safe = np.where(tiny, 1.0, norm)
        return (np.where(tiny, -slope / cone_len, axial / safe),
                np.where(tiny, 1.0 / cone_len, radius / safe))

    lo_axial, lo_radial = unit_or_cone(y_lo, start_radius + slope * y_lo)
    hi_axial, hi_radial = unit_or_cone(y_hi - length, start_radius + slope * y_hi)
    n_axial = (1 - v) * lo_axial + v * hi_axial
    n_radial = (1 - v) * lo_radial + v * hi_radial
    norm = np.hypot(n_axial, n_radial)
    degenerate = norm <= 0
    norm = np.where(degenerate, 1.0, norm)
    n_axial = np.where(degenerate, -slope / cone_len, n_axial / norm)
    n_radial = np.where(degenerate, 1.0 / cone_len, n_radial / norm)
    normals = n_axial[..., None] * axis + n_radial[..., None] * radial
    if relief_slope is not None:
        du, dv = (np.asarray(x, dtype=np.float64) for x in relief_slope)
        radius = np.maximum(start_radius + slope * y, tol.zero_length * scale)
        generator_length = np.maximum((y_hi - y_lo) * cone_len, tol.zero_length * scale)
        around = -sin_phi[..., None] * ref + cos_phi[..., None] * binormal  # axis × e_r
        along = (axis + slope[..., None] * radial) / cone_len[..., None]
        tilted = normals - (du / (2 * np.pi * radius))[..., None] * around \
            - (dv / generator_length)[..., None] * along
        normals = tilted / np.linalg.norm(tilted, axis=-1, keepdims=True)
    return points, normals


# ---------------------------------------------------------------------------- the mesh
@dataclass(frozen=True, eq=False)
class TessellatedMesh:
    """A tessellated skin: lateral faces row by row, then the caps.

    ==================  ============  ======================================================
    ``vertices``        (V, 3) f8     positions, model units (y up)
    ``normals``         (V, 3) f4     unit interpolated normals (8) (GS+R: tilted by relief)
    ``uv``              (V, 2) f4     ``(u, v + chain position)``, u in [0, 1]
    ``faces``           (F, 3) i4     counter-clockwise seen from outside
    ``face_row``        (F,) i4       frustum row of each face
    ``material``        (n,) i4       material index per frustum row
    ``material_names``  tuple         names for ``material``
    ``level``           int           subdivision level m
    ``n_caps``          int           number of caps (faces after ``16·4^m·n``)
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


def triangle_count(n_rows: int, m: int, n_caps: int) -> int:
    """Faces of a tessellation: ``16·4^m`` per row plus ``8·2^m`` per cap."""
    return n_rows * lateral_triangles_per_row(m) + n_caps * columns_around(m)


def _default_height(material_names) -> HeightFunction:
    """Heights from :mod:`plantgen.geometry.relief`: the maps, repeats and bilinear sampler
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


def tessellate(frusta: Frusta, m: int = 1, *, relief: bool = False, height: HeightFunction | None = None,
               caps: bool | str = True, gradient_step: tuple[float, float] | None = None,
               chunk_vertices: int = 1 << 19) -> TessellatedMesh:
    """Tessellate frusta at subdivision level ``m`` (GS), optionally displaced (GS+R).

    Parameters
    ----------
    frusta : a Frusta (see :mod:`plantgen.geometry.frusta`) with ``n`` rows
    m : subdivision level, 0..8; ``16·4^m`` lateral triangles per row
    relief : displace vertices by ``w·shell`` onto the relief shell (rows with
        ``shell = 0`` stay on the base cone)
    height : ``height(material, u, v) -> w`` in [0, 1] for (k,) arrays; default: the
        height maps of :mod:`plantgen.geometry.relief`, sampled as the ray caster samples
    caps : True: close every open chain end (roots, side branch starts, tips) with a flat
        cap, so each chain is a closed solid (export); ``"tips"``: cap only the upper
        ends (side branch bases sit inside their parent, unseen: the rendering choice);
        False: no caps, exactly ``16·4^m`` triangles per row
    gradient_step : (du, dv) of the central differences that tilt relief normals (GS+R);
        default one texel of the relief maps (1/256 for a custom ``height``)
    chunk_vertices : vertices computed at a time; bounds the float64 scratch memory
        (about 0.4 KiB per vertex)

    Returns
    -------
    TessellatedMesh
    """
    m = _check_level(m)
    n = len(frusta.length)
    columns, bands = columns_around(m), bands_along(m)
    ring_size = columns + 1  # seam column duplicated
    rings = bands + 1
    parent_row = frusta.parent_row
    shared = parent_row >= 0
    chain_v = frusta.chain_position.astype(np.float64)
    names = frusta.material_names
    material = frusta.material
    step_u = step_v = 1.0 / 256
    if relief and height is None:
        height = _default_height(names)
        texels_v, texels_u = relief_maps.height_maps(names)[0].shape[1:]
        step_u, step_v = 1.0 / texels_u, 1.0 / texels_v
    if gradient_step is not None:
        step_u, step_v = (float(x) for x in gradient_step)

    # Ring numbering: every row owns rings 1..bands, and ring 0 unless it is shared.
    owns_ring = np.ones((n, rings), dtype=bool)
    owns_ring[:, 0] = ~shared
    ring_id = (np.cumsum(owns_ring.ravel()) - 1).reshape(n, rings)
    ring_id[shared, 0] = ring_id[parent_row[shared], bands]
    n_rings = int(owns_ring.sum())

    # Caps: bottom of every unshared row, top of every row no row continues.
    top_shared = np.zeros(n, dtype=bool)
    top_shared[parent_row[shared]] = True
    if caps not in (True, False, "tips"):
        raise ValueError(f"caps must be True, False or 'tips', got {caps!r}")
    none = np.zeros(0, np.int64)
    bottom_cap_rows = np.flatnonzero(~shared) if caps is True else none
    top_cap_rows = np.flatnonzero(~top_shared) if caps else none
    cap_rows = np.concatenate([bottom_cap_rows, top_cap_rows])
    cap_is_top = np.concatenate([np.zeros(len(bottom_cap_rows), bool), np.ones(len(top_cap_rows), bool)])
    n_caps = len(cap_rows)

    n_lateral_vertices = n_rings * ring_size
    n_vertices = n_lateral_vertices + n_caps * (ring_size + 1)
    vertices = np.empty((n_vertices, 3), dtype=np.float64)
    normals = np.empty((n_vertices, 3), dtype=np.float32)
    uv = np.empty((n_vertices, 2), dtype=np.float32)

    u_col = np.arange(ring_size) / columns  # (ring_size,)
    v_ring = np.arange(rings) / bands  # (rings,)
    shell = frusta.shell

    def ring_points(rows, ring_index):
        """Points, normals, u, texture v of rings ``ring_index`` (k,) of ``rows`` (k,),
        each (k, ring_size, ...): per-ring data broadcast against per-column data."""
        rows_ = rows[:, None]
        u = u_col[None, :]
        v = v_ring[ring_index][:, None]
        offset, relief_slope = 0.0, None
        if relief:
            uu, vv = np.broadcast_arrays(u, v)
            mm = np.broadcast_to(material[rows_], uu.shape).ravel()
            uu, vv = uu.ravel() % 1.0, vv.ravel()

            def w_at(du, dv):
                return np.asarray(height(mm, (uu + du) % 1.0, vv + dv), dtype=np.float64).reshape(len(rows), ring_size)

            thick = shell[rows_]
            offset = np.clip(w_at(0.0, 0.0), 0.0, 1.0) * thick
            # Central differences one texel apart, as the ray caster takes them.
            relief_slope = ((w_at(step_u, 0.0) - w_at(-step_u, 0.0)) / (2 * step_u) * thick,
                            (w_at(0.0, step_v) - w_at(0.0, -step_v)) / (2 * step_v) * thick)
        pts, nrm = generator_points(frusta, rows_, u, v, offset, relief_slope)
        return pts, nrm, u, v + chain_v[rows_]

    # Lateral vertices: all owned rings, chunked.
    owned_rows, owned_ring_index = np.nonzero(owns_ring)  # row-major: matches ring_id order
    step = max(1, int(chunk_vertices) // ring_size)  # rings per chunk
    for lo in range(0, n_rings, step):
        hi = min(n_rings, lo + step)
        pts, nrm, uu, vv = ring_points(owned_rows[lo:hi], owned_ring_index[lo:hi])
        sl = slice(lo * ring_size, hi * ring_size)
        vertices[sl] = pts.reshape(-1, 3)
        normals[sl] = nrm.reshape(-1, 3)
        uv[sl, 0] = np.broadcast_to(uu, pts.shape[:2]).ravel()
        uv[sl, 1] = np.broadcast_to(vv, pts.shape[:2]).ravel()

    # Lateral faces: one quad template, (l, l+1, u+1) and (l, u+1, u) for lower ring l and
    # upper ring u, shifted by ring and column strides.
    index_dtype = np.int32 if n_vertices < 2**31 else np.int64
    # (n, bands): first vertex of each band's lower and upper ring
    band_start = (ring_id[:, :-1] * ring_size).astype(index_dtype)
    band_next = (ring_id[:, 1:] * ring_size).astype(index_dtype)
    j = np.arange(columns, dtype=index_dtype)
    lower = band_start[:, :, None] + j  # (n, bands, columns): vertex (ring r, column j)
    upper = band_next[:, :, None] + j
    lateral = np.empty((n, bands, columns, 2, 3), dtype=index_dtype)
    lateral[..., 0, 0] = lower
    lateral[..., 0, 1] = lower + 1
    lateral[..., 0, 2] = upper + 1
    lateral[..., 1, 0] = lower
    lateral[..., 1, 1] = upper + 1
    lateral[..., 1, 2] = upper
    lateral = lateral.reshape(-1, 3)
    del lower, upper

    # Caps: a copy of the end ring with the plane's normal, plus a centre vertex.
    cap_faces = np.zeros((0, 3), dtype=lateral.dtype)
    if n_caps:
        ring_of_cap = np.where(cap_is_top, ring_id[cap_rows, bands], ring_id[cap_rows, 0])
        src = ring_of_cap[:, None] * ring_size + np.arange(ring_size)  # (n_caps, ring_size)
        cap_first = n_lateral_vertices + np.arange(n_caps) * (ring_size + 1)
        dst = cap_first[:, None] + np.arange(ring_size)
        centre = cap_first + ring_size
        vertices[dst] = vertices[src]
        uv[dst] = uv[src]
        plane = np.where(cap_is_top[:, None], frusta.plane_hi[cap_rows], frusta.plane_lo[cap_rows])
        outward = np.where(cap_is_top[:, None], plane[:, :3], -plane[:, :3])
        normals[dst] = outward[:, None, :]
        normals[centre] = outward
        vertices[centre] = vertices[src[:, :columns]].mean(axis=1)  # centroid of the ring (on the plane)
        uv[centre, 0] = 0.5
        uv[centre, 1] = uv[src[:, 0], 1]
        first = dst[:, :columns]
        second = dst[:, 1:]
        ctr = np.broadcast_to(centre[:, None], first.shape)
        top_tri = np.stack([ctr, first, second], -1)
        bottom_tri = np.stack([ctr, second, first], -1)
        cap_faces = np.where(cap_is_top[:, None, None], top_tri, bottom_tri)
        cap_faces = cap_faces.reshape(-1, 3).astype(lateral.dtype)

    faces = np.concatenate([lateral, cap_faces])
    face_row = np.concatenate([
        np.repeat(np.arange(n, dtype=np.int32), lateral_triangles_per_row(m)),
        np.repeat(cap_rows.astype(np.int32), columns),
    ])
    return TessellatedMesh(vertices, normals, uv, faces, face_row, material, names, m, n_caps)
