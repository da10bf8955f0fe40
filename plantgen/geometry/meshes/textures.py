"""Relief baked into textures: what an exported mesh needs to look like RC+R (pure numpy).

For every material with relief (shell fraction > 0, :func:`plantgen.geometry.skeletons.relief.default_shell`)
:func:`bake_material` makes three maps over the ray caster's texture square (u around the
axis, v along the segment's texture period; rows are v, row 0 at v = 0, as
:mod:`~plantgen.geometry.skeletons.relief` lays out a height map):

- ``height`` (H, W) uint8: the relief height w in [0, 1] (0 the inner cone, 1 the outer
  shell), the renderers' map resampled to the texture size (:func:`texture_size`);
- ``normal`` (H, W, 3) uint8: the tangent-space normal the ray caster shades relief with
  (``shaders/raycast.glsl``: N - shell·(∂w/∂u·t_u/|∂P/∂u| + ∂w/∂v·t_v/|∂P/∂v|), the
  gradient by central differences one texel apart), in glTF's convention: x along +u
  (the tangent), y along -v (up in the image: glTF's v runs down it), z the surface
  normal, each component c stored as round((c + 1)/2·255);
- ``base_colour`` (H, W, 3) uint8: the ray caster's albedo mix(dark, light, w)
  (``shading.glsl``'s ``material_albedo``) encoded as sRGB.

The relief's slopes in the tangent frame. The relief is ``f·r̄`` deep (f the material's
fraction, r̄ the radius where the point lies: it follows the radius), u goes once around (|∂P/∂u| = 2πρ) and v spans
the texture period along the segment (|∂P/∂v| = L, the generator's length times the
row's ``v_part`` slots). So the tangent-space normal is (-f·(r̄/ρ)/(2π)·∂w/∂u,
-f·(r̄/L)·∂w/∂v, 1): the u-slope is the same on every segment (r̄/ρ = 1 up to the taper),
the v-slope scales with the segment's aspect r̄/L. A tangent frame of unit vectors (glTF's
TANGENT, every engine's) cannot carry that per-segment scale, so one map per material is
exact for one aspect: :func:`bake_material` bakes at the material's area-weighted median
aspect (:func:`mesh_aspects`), and :func:`aspect_error` measures what that leaves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..skeletons import relief
from ..skeletons.materials import material_palette
from ..vec import any_perpendicular, by_rows, cross, dot, norm

__all__ = ["MaterialTextures", "TextureSize", "aspect_error", "bake_base_colour", "bake_material",
           "bake_normal_map", "decode_normal", "linear_to_srgb", "mesh_aspects", "mesh_tangents", "mesh_uv_scales",
           "parallax_map",
           "resample_height", "row_aspects", "texture_size", "face_derivatives", "weighted_median"]

#: Largest difference, in units of the 8-bit height, a texture size may leave against the
#: renderers' map (:func:`texture_size`): one step, 1/255.
SIZE_TOLERANCE = 1.0
#: Faces from which :func:`mesh_tangents` runs compiled where numba does
#: (:mod:`~plantgen.geometry.meshes.native_tangents`): numpy takes about 0.8 µs of CPU a
#: face and the kernels 0.15, so numba's import and its cache's load, about 0.45 s of CPU
#: once a process, pay from about 700,000 faces; from a million they surely do.
COMPILED_FACES = 1 << 20


@dataclass(frozen=True)
class TextureSize:
    """A material's texture size and why: ``shape`` (H, W), the renderers' ``native``
    (H, W), and ``error`` the largest difference (8-bit steps) of the map resampled to
    ``shape`` and read back at the native texels."""

    shape: tuple[int, int]
    native: tuple[int, int]
    error: float


@dataclass(frozen=True, eq=False)
class MaterialTextures:
    """One material's baked maps (see the module docstring; rows are v, row 0 at v = 0).

    ``height`` (H, W) uint8, ``normal`` (H, W, 3) uint8 (glTF convention), ``base_colour``
    (H, W, 3) uint8 sRGB; ``shell`` the shell fraction f; ``aspect`` the r̄/L the normal
    map was baked for; ``amplitude`` the displacement of w = 1 on a segment of the median
    mean radius (model units: f·r̄); ``size`` how the size was chosen."""

    name: str
    height: np.ndarray
    normal: np.ndarray
    base_colour: np.ndarray
    shell: float
    aspect: float
    amplitude: float
    size: TextureSize
    base: str | None = None     # the material whose relief and colours these are (None: ``name``)


def resample_height(hmap: np.ndarray, shape) -> np.ndarray:
    """(h, w) float64 in [0, 1]: ``hmap`` (H, W) uint8 averaged down to ``shape`` (each of
    h, w divides H, W), as a texture of that size holds it."""
    hmap = np.asarray(hmap, dtype=np.float64) / 255.0
    big_h, big_w = hmap.shape
    h, w = int(shape[0]), int(shape[1])
    return hmap.reshape(h, big_h // h, w, big_w // w).mean(axis=(1, 3))


def _read_back(small: np.ndarray, native) -> np.ndarray:
    """(H, W) bilinear samples of ``small`` (h, w) at the texel centres of a ``native``
    (H, W) map (repeat in u, clamp in v: :func:`plantgen.geometry.skeletons.relief.sample_height`)."""
    big_h, big_w = native
    v, u = np.meshgrid((np.arange(big_h) + 0.5) / big_h, (np.arange(big_w) + 0.5) / big_w, indexing="ij")
    return relief.sample_height(np.asarray(small) * 255.0, u, v)


def texture_size(hmap: np.ndarray, tolerance: float = SIZE_TOLERANCE) -> TextureSize:
    """The smallest texture (fewest texels; powers of two dividing the map's size per axis)
    whose box-averaged map, read back bilinearly at the renderers' texel centres, stays
    within ``tolerance`` 8-bit steps of ``hmap`` (H, W) uint8 everywhere: the relief's own
    detail decides (a map constant along v needs one row; noise needs every texel)."""
    native = tuple(int(s) for s in np.shape(hmap))
    target = np.asarray(hmap, dtype=np.float64) / 255.0

    def divisors(n):
        return [d for d in (1 << k for k in range(n.bit_length())) if n % d == 0]

    def error(shape):
        return 255.0 * float(np.max(np.abs(_read_back(resample_height(hmap, shape), native) - target)))

    # each axis alone first (a size fails if either axis alone fails), then the pairs above
    least_h = next(h for h in divisors(native[0]) if h == native[0] or error((h, native[1])) <= tolerance)
    least_w = next(w for w in divisors(native[1]) if w == native[1] or error((native[0], w)) <= tolerance)
    candidates = sorted(((h, w) for h in divisors(native[0]) if h >= least_h
                         for w in divisors(native[1]) if w >= least_w), key=lambda s: (s[0] * s[1], s))
    for shape in candidates:
        e = error(shape)
        if e <= tolerance:
            return TextureSize(shape, native, e)
    return TextureSize(native, native, 0.0)


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    """uint8 sRGB of linear values in [0, 1] (the sRGB transfer function, rounded)."""
    c = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    return np.rint(s * 255.0).astype(np.uint8)


def bake_base_colour(name: str, height: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 sRGB: the ray caster's albedo mix(dark, light, w) of material
    ``name`` where its map reads ``height`` (H, W) in [0, 1]."""
    palette = material_palette([name])
    dark, light = palette["dark"][0].astype(np.float64), palette["light"][0].astype(np.float64)
    w = np.asarray(height, dtype=np.float64)[..., None]
    return linear_to_srgb(dark + (light - dark) * w)


def bake_normal_map(height: np.ndarray, shell: float, aspect: float) -> np.ndarray:
    """(H, W, 3) uint8 tangent-space normals (glTF convention, module docstring) of the
    relief ``height`` (H, W) in [0, 1] with shell fraction ``shell`` on a segment whose
    mean radius over texture period is ``aspect``: the gradient by central differences one
    texel apart (u wraps, v clamps), as the ray caster takes it."""
    w = np.asarray(height, dtype=np.float64)
    rows, cols = w.shape
    dw_du = (np.roll(w, -1, axis=1) - np.roll(w, 1, axis=1)) * cols / 2.0
    up = np.concatenate([w[1:], w[-1:]])
    down = np.concatenate([w[:1], w[:-1]])
    dw_dv = (up - down) * rows / 2.0
    x = -shell / (2.0 * np.pi) * dw_du
    y_along_v = -shell * aspect * dw_dv
    n = np.stack([x, -y_along_v, np.ones_like(x)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.rint((n + 1.0) * 0.5 * 255.0).astype(np.uint8)


def decode_normal(texels: np.ndarray) -> np.ndarray:
    """(..., 3) unit vectors of normal-map texels (..., 3) uint8 (or bilinear floats in
    0..255), as a reader decodes them: 2·c/255 - 1, normalised."""
    n = np.asarray(texels, dtype=np.float64) / 255.0 * 2.0 - 1.0
    return n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-30)


def face_derivatives(vertices: np.ndarray, uv: np.ndarray, faces: np.ndarray):
    """Per face (F,): ∂P/∂u and ∂P/∂v (F, 3) from its corners' positions (V, 3) and
    texture coordinates (V, 2), its area (F,), and ``ok`` (F,) bool where the texture
    coordinates span the face (not a cap, whose corners share one v)."""
    vertices, uv = np.asarray(vertices, dtype=np.float64), np.asarray(uv, dtype=np.float64)
    p0, p1, p2 = (vertices.take(faces[:, k], axis=0) for k in range(3))    # corner by corner:
    t0, t1, t2 = (uv.take(faces[:, k], axis=0) for k in range(3))          # contiguous rows
    e1, e2 = p1 - p0, p2 - p0
    d1, d2 = t1 - t0, t2 - t0
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    area = 0.5 * norm(cross(e1, e2))      # np.linalg.norm's sum, left to right, without its reduction
    ok = np.abs(det) > 1e-12
    safe = np.where(ok, det, 1.0)[:, None]
    dp_du = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) / safe
    dp_dv = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) / safe
    return dp_du, dp_dv, area, ok


def mesh_aspects(mesh) -> dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per material index of a :class:`~plantgen.geometry.meshes.mesh.TessellatedMesh`: the
    aspect ρ/L of each lateral face (ρ = |∂P/∂u|/2π, L = |∂P/∂v|: the radius over the
    texture period there), the face's area and its radius ρ, each (k,) float64."""
    vertices, uv = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.uv, dtype=np.float64)

    def per_face(faces):                 # row-wise: a block of faces at a time (by_rows)
        dp_du, dp_dv, area, ok = face_derivatives(vertices, uv, faces)
        lu, lv = np.linalg.norm(dp_du, axis=1), np.linalg.norm(dp_dv, axis=1)
        ok &= (lv > 0) & (area > 0)
        return lu / (2.0 * np.pi * np.where(ok, lv, 1.0)), area, lu / (2.0 * np.pi), ok
    aspect, area, radius, ok = by_rows(per_face, np.asarray(mesh.faces))
    material = mesh.face_material
    return {int(m): (aspect[ok & (material == m)], area[ok & (material == m)], radius[ok & (material == m)])
            for m in np.unique(material[ok])}


def row_aspects(mesh) -> tuple[np.ndarray, np.ndarray]:
    """Per mesh row (n,): the area-weighted mean aspect ρ/L of its lateral faces and their
    area (0 and 0 for a row without one)."""
    dp_du, dp_dv, area, ok = face_derivatives(mesh.vertices, mesh.uv, mesh.faces)
    lu, lv = np.linalg.norm(dp_du, axis=1), np.linalg.norm(dp_dv, axis=1)
    ok &= (lv > 0) & (area > 0)
    weight = np.where(ok, area, 0.0)
    aspect = np.where(ok, lu / (2.0 * np.pi * np.where(ok, lv, 1.0)), 0.0)
    total = np.bincount(mesh.face_row, weight, minlength=mesh.n_rows)
    summed = np.bincount(mesh.face_row, weight * aspect, minlength=mesh.n_rows)
    return summed / np.where(total > 0, total, 1.0), total


def weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    """The value below which half the total weight lies."""
    order = np.argsort(values)
    cum = np.cumsum(np.asarray(weights, dtype=np.float64)[order])
    return float(np.asarray(values)[order][np.searchsorted(cum, 0.5 * cum[-1])])


def aspect_error(height: np.ndarray, shell: float, aspect: float, aspects: np.ndarray,
                 weights: np.ndarray) -> dict:
    """What one normal map baked at ``aspect`` leaves on faces of ``aspects`` (k,) weighted
    by ``weights`` (k,): the angle (degrees) between the baked normal and the exact one
    (the map baked at the face's own aspect), over the map's texels, as ``mean`` (area-
    and texel-weighted), ``p95`` and ``max`` over faces of their texel mean, and ``worst``
    (the largest over every texel of every face)."""
    aspects = np.asarray(aspects, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    if len(aspects) == 0:
        return {"mean": 0.0, "p95": 0.0, "max": 0.0, "worst": 0.0}
    grid = np.quantile(aspects, np.linspace(0.0, 1.0, 33))
    baked = decode_normal(bake_normal_map(height, shell, aspect).astype(np.float64))
    per_mean, per_max = [], []
    for a in grid:
        exact = decode_normal(bake_normal_map(height, shell, a).astype(np.float64))
        angle = np.degrees(np.arccos(np.clip(np.sum(baked * exact, axis=-1), -1.0, 1.0)))
        per_mean.append(angle.mean())
        per_max.append(angle.max())
    face_mean = np.interp(aspects, grid, per_mean)
    face_max = np.interp(aspects, grid, per_max)
    return {"mean": float(np.sum(face_mean * weights) / np.sum(weights)),
            "p95": float(np.quantile(face_mean, 0.95)), "max": float(face_mean.max()), "worst": float(face_max.max())}


def bake_material(name: str, aspects: np.ndarray | None = None, weights: np.ndarray | None = None,
                  radius: float = 1.0, base: str | None = None) -> MaterialTextures | None:
    """The baked maps of material ``name`` (None for a material without relief), the normal
    map at the area-weighted median of ``aspects`` (k,) (faces' ρ/L, weighted by
    ``weights``; None: aspect 1/(2π), a segment as long as it is round); ``radius``: the
    median mean radius, for ``amplitude``; ``base``: the material whose relief and colours
    they are, where ``name`` is another name for it (an aspect bucket's)."""
    source = name if base is None else base
    shell = relief.default_shell(source)
    if shell <= 0.0:
        return None
    native = relief.height_map(source)
    size = texture_size(native)
    height = resample_height(native, size.shape)
    if aspects is None or len(aspects) == 0:
        aspect = 1.0 / (2.0 * np.pi)
    else:
        aspect = weighted_median(aspects, np.ones(len(aspects)) if weights is None else weights)
    return MaterialTextures(name, np.rint(height * 255.0).astype(np.uint8), bake_normal_map(height, shell, aspect),
                            bake_base_colour(source, height), shell, aspect, shell * float(radius), size, base)


def parallax_map(baked: MaterialTextures) -> np.ndarray:
    """(H, W, 4) uint8: the normal map with the relief height w in its alpha, the one texture
    GS+POM marches and shades with (engines pack a parallax height so)."""
    return np.concatenate([baked.normal, baked.height[..., None]], axis=2)


def mesh_tangents(vertices: np.ndarray, normals: np.ndarray, uv: np.ndarray, faces: np.ndarray,
                  compiled: bool | None = None) -> np.ndarray:
    """(V, 4) float32 glTF tangents: xyz the unit direction of increasing u (the faces'
    ∂P/∂u summed by area, made ⟂ the vertex normal), w = ±1 so that cross(N, T)·w points
    along -v (glTF's "up in the image"). Vertices no textured face uses (caps) get any unit
    vector ⟂ their normal and w = 1. The per-face and per-vertex work runs a block of
    rows at a time (:func:`~plantgen.geometry.vec.by_rows`: the same numbers, without
    full-size temporaries of every face's corners). ``compiled`` (None: from
    :data:`COMPILED_FACES` faces on) where numba runs: compiled kernels compute the same
    numbers bit for bit (:mod:`~plantgen.geometry.meshes.native_tangents`)."""
    if len(faces) >= COMPILED_FACES if compiled is None else compiled:
        compiled = _compiled_tangents(vertices, normals, uv, faces)
        if compiled is not None:
            return compiled
    vertices, uv = np.asarray(vertices, dtype=np.float64), np.asarray(uv, dtype=np.float64)

    def weighted(face_rows):
        dp_du, dp_dv, area, ok = face_derivatives(vertices, uv, face_rows)
        weight = np.where(ok, area, 0.0)[:, None]
        tu = dp_du / np.maximum(norm(dp_du), 1e-300)[:, None]
        tv = dp_dv / np.maximum(norm(dp_dv), 1e-300)[:, None]
        tu, tv = tu * weight, tv * weight
        return tuple(np.ascontiguousarray(d[:, k]) for d in (tu, tv) for k in range(3))
    sums = _vertex_sums(faces, by_rows(weighted, np.asarray(faces)), len(vertices))
    return by_rows(_vertex_tangents, sums[:, :3], sums[:, 3:], normals)


def _compiled_tangents(vertices, normals, uv, faces) -> np.ndarray | None:
    """:func:`mesh_tangents` by the compiled kernels; None where numba does not run (or
    fails to compile them for these arrays' types)."""
    from .native_tangents import tangent_kernels  # numba's import is paid by large meshes only
    kernels = tangent_kernels()
    if kernels is None:
        return None
    face_sums, vertex_tangents = kernels

    def exact(a):                 # float32 as it is (widened exactly in the kernels), else float64
        return np.ascontiguousarray(a, dtype=np.float32 if np.asarray(a).dtype == np.float32 else np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    vertices, uv, normals = np.asarray(vertices), np.asarray(uv), np.asarray(normals)
    count = len(vertices)
    if (vertices.shape != (count, 3) or uv.shape != (count, 2) or normals.shape != (count, 3)
            or faces.ndim != 2 or faces.shape[1] != 3 or (len(faces) and not 0 <= faces.min() <= faces.max() < count)):
        return None               # the kernels check no index: numpy's errors (or its wrapping) then
    try:                          # types not compiled yet (float64 maps) compile here: numba's errors are many
        sums = face_sums(np.ascontiguousarray(vertices, dtype=np.float64), exact(uv), faces, len(vertices))
        return vertex_tangents(sums, exact(normals))
    except Exception:             # noqa: BLE001 - numpy computes them then
        return None


def _vertex_tangents(t_sum, b_sum, normals) -> np.ndarray:
    """(m, 4) float32 tangents of vertices whose faces' area-weighted ∂P/∂u and ∂P/∂v
    directions sum to ``t_sum`` and ``b_sum`` (m, 3), with ``normals`` (m, 3) (see
    :func:`mesh_tangents`). Row-wise. Lengths and dot products add their three terms left
    to right, as numpy's reductions along a row do (the numbers of ``np.linalg.norm`` and
    ``np.sum(axis=1)``, without their slow reductions over rows of three)."""
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.maximum(norm(n), 1e-300)[:, None]
    t = t_sum - dot(t_sum, n)[:, None] * n
    length = norm(t)
    bad = length < 1e-12
    if np.any(bad):
        t[bad] = any_perpendicular(n[bad])
        length[bad] = norm(t[bad])
    t /= length[:, None]
    w = np.where(dot(cross(n, t), b_sum) > 0, -1.0, 1.0)
    return np.concatenate([t, w[:, None]], axis=1).astype(np.float32)


def _vertex_sums(faces: np.ndarray, per_face, n_vertices: int) -> np.ndarray:
    """(V, k) sums over each vertex's faces of ``per_face`` (F, k), or of its k columns
    given as (F,) arrays: a bincount over the corners in order (every face's first
    corner, then second, then third), so each sum adds up in the order ``np.add.at``
    corner by corner would, many times faster."""
    corners = np.asarray(faces).T.ravel()
    if isinstance(per_face, np.ndarray):
        per_face = [per_face[:, k] for k in range(per_face.shape[1])]
    count = len(faces)
    out = np.empty((n_vertices, len(per_face)))
    weights = np.empty(3 * count)          # a column three times over (np.tile's), one buffer for all
    for k, column in enumerate(per_face):
        for corner in range(3):
            weights[corner * count:(corner + 1) * count] = column
        out[:, k] = np.bincount(corners, weights=weights, minlength=n_vertices)
    return out


def mesh_uv_scales(vertices: np.ndarray, uv: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 2) float32 model units per unit of u and of v at each vertex: |∂P/∂u| and
    |∂P/∂v| of its textured faces, weighted by area (0 where none: caps). With the unit
    tangent frame (:func:`mesh_tangents`) they carry a ray's move in model units to its
    move in (u, v): GS+POM's march (``raster.glsl``'s PARALLAX), exact per segment, which a
    unit frame with one height scale per material cannot be (the module docstring)."""
    dp_du, dp_dv, area, ok = face_derivatives(vertices, uv, faces)
    weight = np.where(ok, area, 0.0)[:, None]
    lengths = np.stack([np.linalg.norm(dp_du, axis=1), np.linalg.norm(dp_dv, axis=1)], axis=1)
    summed = _vertex_sums(faces, np.concatenate([lengths * weight, weight], axis=1), len(vertices))
    return (summed[:, :2] / np.where(summed[:, 2:] > 0, summed[:, 2:], 1.0)).astype(np.float32)
