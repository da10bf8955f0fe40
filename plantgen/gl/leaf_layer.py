"""Leaves in the frame: a grammar's filled polygons rasterised beside the frusta.

Both renderers draw a model's :class:`~plantgen.geometry.meshes.polygons.Polygons` the same way
(shaders/leaf.glsl): one indexed draw into the frame's depth buffer, where the ray-cast
frusta write ``gl_FragDepth`` from the same projection (so leaves and frusta hide each
other correctly), and, with shadows, one draw into the light's map, so leaves cast and
receive shadows. A model without leaves builds no leaf program and runs no leaf draw.

The vertex data (:func:`leaf_vertices`) is made once per ``Polygons`` object and kept on
the GPU while the same object is drawn again (an orbit or an animation redraws it).
"""

from __future__ import annotations

import numpy as np

from ..geometry.meshes.polygons import Polygons
from ..geometry.skeletons.materials import leaf_tones
from ..geometry.vec import norm, unit
from ..settings import AA_ALPHA_EXPONENT
from .coverage import coverage_pass
from .shaders import build_program, mat4, set_uniforms

__all__ = ["LeafLayer", "leaf_vertices", "thin_leaf_data", "THIN_LEAF_LAYOUT",
           "leaf_bounds", "union_box", "LEAF_VERTEX_LAYOUT"]

#: One interleaved float32 vertex: position (relative to the leaves' origin), normal,
#: (material slot, tone).
LEAF_VERTEX_LAYOUT = ("3f 3f 2f", "position", "normal", "shade")


def _vertex_normals(polygons: Polygons) -> np.ndarray:
    """(v, 3) unit normals: each vertex's area-weighted mean of its triangles' normals
    (a curled blade shades smoothly); a vertex in no triangle takes its polygon's normal."""
    v, t = polygons.vertices, polygons.triangles
    normals = np.zeros_like(v)
    if len(t):
        face = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])   # 2 * area * unit normal
        for k in range(3):
            np.add.at(normals, t[:, k], face)
    fallback = norm(normals) <= 0
    if fallback.any():
        owner = polygons.vertex_polygon
        normals[fallback] = polygons.normal[owner[fallback]] if len(polygons) else (0.0, 1.0, 0.0)
    return unit(normals)


def leaf_vertices(polygons: Polygons, origin, labels=None) -> np.ndarray:
    """(v, 8) float32 interleaved vertices (:data:`LEAF_VERTEX_LAYOUT`), positions relative
    to ``origin`` (float64 subtraction first). ``labels`` (p,) replaces each polygon's
    material slot (a part mask)."""
    owner = polygons.vertex_polygon
    slot = polygons.material if labels is None else np.asarray(labels)
    out = np.empty((len(polygons.vertices), 8), np.float32)
    out[:, 0:3] = polygons.vertices - np.asarray(origin, np.float64)
    out[:, 3:6] = _vertex_normals(polygons)
    out[:, 6] = slot[owner] if len(polygons) else 0
    out[:, 7] = leaf_tones(len(polygons))[owner] if len(polygons) else 0.5
    return out


#: Coverage anti-aliasing's per-vertex data of the leaves (:func:`thin_leaf_data`): the
#: leaf's centroid, the vertex's offset across the leaf's long axis, the leaf's width.
THIN_LEAF_LAYOUT = ("3f 3f 1f", "thin_centre", "thin_offset", "thin_width")


def thin_leaf_data(polygons: Polygons, origin) -> np.ndarray:
    """(v, 7) float32 per vertex (:data:`THIN_LEAF_LAYOUT`): its polygon's centroid relative to
    ``origin``, the vertex's offset from the polygon's long axis along the polygon's second
    principal axis (across the leaf, in its plane), and the polygon's width along that axis
    (the spread of those offsets). A needle's width is its thickness; the shader widens a
    leaf narrower than a pixel by scaling the offsets (leaf.glsl's THIN_LEAVES)."""
    v = np.asarray(polygons.vertices, np.float64)
    owner = polygons.vertex_polygon
    count = max(len(polygons), 1)
    n = np.maximum(np.bincount(owner, minlength=count), 1).astype(np.float64)
    centre = np.stack([np.bincount(owner, weights=v[:, k], minlength=count) for k in range(3)], axis=1) / n[:, None]
    d = v - centre[owner]
    spread = np.zeros((count, 3, 3))
    np.add.at(spread, owner, d[:, :, None] * d[:, None, :])
    across = np.linalg.eigh(spread)[1][:, :, 1]          # the second principal axis (ascending order)
    offset = np.einsum("ij,ij->i", d, across[owner])
    high = np.full(count, -np.inf)
    low = np.full(count, np.inf)
    np.maximum.at(high, owner, offset)
    np.minimum.at(low, owner, offset)
    out = np.empty((len(v), 7), np.float32)
    out[:, 0:3] = centre[owner] - np.asarray(origin, np.float64)
    out[:, 3:6] = offset[:, None] * across[owner]
    out[:, 6] = (high - low)[owner] if len(v) else 0.0
    return out


def leaf_bounds(polygons: Polygons | None) -> np.ndarray | None:
    """(2, 3) world box of the leaves' vertices, None without leaves."""
    if polygons is None or len(polygons.triangles) == 0:
        return None
    return polygons.bounds


def union_box(*boxes) -> np.ndarray | None:
    """(2, 3) box around every (2, 3) box of ``boxes`` that is not None; None if none is."""
    given = [np.asarray(b, np.float64) for b in boxes if b is not None]
    if not given:
        return None
    return np.stack([np.min([b[0] for b in given], axis=0), np.max([b[1] for b in given], axis=0)])


class LeafLayer:
    """The GL side of one renderer's leaves: the uploaded vertices of the last ``Polygons``
    drawn, and the draws of one frame."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._uploaded = None   # (polygons, labels key, vbo, ibo, origin)
        self._thin = None       # (polygons, buffer of thin_leaf_data, (least, greatest) leaf width)

    def release(self) -> None:
        if self._uploaded is not None:
            for obj in self._uploaded[2:4]:
                obj.release()
        self._uploaded = None
        if self._thin is not None:
            self._thin[1].release()
        self._thin = None

    def _thin_buffer(self, polygons: Polygons, origin):
        """The buffer of :func:`thin_leaf_data` (kept while the same Polygons is drawn)."""
        if self._thin is None or self._thin[0] is not polygons:
            if self._thin is not None:
                self._thin[1].release()
            data = thin_leaf_data(polygons, origin)
            widths = (float(data[:, 6].min()), float(data[:, 6].max())) if len(data) else (0.0, 0.0)
            self._thin = (polygons, self.ctx.buffer(data.tobytes()), widths)
        return self._thin[1]

    def thin_share(self, polygons: Polygons, origin, eye, coverage_floor: float) -> str:
        """Whether every leaf is narrower than the floor's width at its distance from
        ``eye`` (``"all"``), none is (``"none"``), or either may be (``"some"``): leaf.glsl's
        THIN_LEAVES test bounded over the leaves' box and their least and greatest width,
        with a margin for its float32 rounding. A pass that would draw no leaf is skipped:
        the pine's needles, all thin at a whole-tree view, took a tenth of its frame to
        be run through the opaque pass and clipped there (llvmpipe, 256x192)."""
        self._thin_buffer(polygons, origin)
        least, greatest = self._thin[2]
        box = np.asarray(polygons.bounds, np.float64)
        eye = np.asarray(eye, np.float64)
        near = float(np.linalg.norm(np.clip(eye, box[0], box[1]) - eye))
        far = float(np.linalg.norm(np.maximum(np.abs(box[0] - eye), np.abs(box[1] - eye))))
        margin = 1e-4
        if greatest < 2.0 * coverage_floor * near * (1.0 - margin):
            return "all"
        if least > 2.0 * coverage_floor * far * (1.0 + margin):
            return "none"
        return "some"

    def _upload(self, polygons: Polygons, labels):
        key = None if labels is None else np.asarray(labels).tobytes()
        up = self._uploaded
        if up is not None and up[0] is polygons and up[1] == key:
            return up[2], up[3], up[4]
        self.release()
        origin = polygons.vertices.mean(axis=0)
        vbo = self.ctx.buffer(leaf_vertices(polygons, origin, labels).tobytes())
        ibo = self.ctx.buffer(np.ascontiguousarray(polygons.triangles, np.uint32).tobytes())
        self._uploaded = (polygons, key, vbo, ibo, origin)
        return vbo, ibo, origin

    def draws(self, polygons: Polygons, view, lighting, *, labels=None, coverage_floor: float = 0.0):
        """The leaves' draws for one frame seen through ``view`` (a FrameView) and lit by
        ``lighting`` (a FrameLighting; its window, if any, gets the light's draw). With
        ``coverage_floor`` (coverage anti-aliasing: the floor radius per unit of distance)
        the leaves narrower than the floor's width are left to a draw of their own after
        everything opaque (:func:`~plantgen.gl.coverage.coverage_pass`, leaf.glsl's
        THIN_LEAVES; not with the sky light, whose depth pass draws every leaf as it is):
        they hide nothing and leave no distance.

        Returns (frame draw, light draw or None, [vertex arrays to release after the frame],
        the thin leaves' draw or None).
        """
        ctx = self.ctx
        vbo, ibo, origin = self._upload(polygons, labels)
        shadowed = lighting.window is not None and labels is None
        receives = lighting.shadowed and labels is None
        looks = lighting.defines("leaf.glsl") if labels is None else {}
        thin = coverage_floor > 0 and labels is None and not looks.get("SKY_LIGHT")
        program = build_program(ctx, "leaf.glsl", {"SHADOWS": receives, "LABELS": labels is not None,
                                                   **(lighting.receiver_defines if receives else {}), **looks,
                                                   "THIN_LEAVES": thin})
        shading = {**lighting.shading, **lighting.receiver, **(lighting.sky if looks.get("SKY_LIGHT") else {})}
        set_uniforms(program, **({} if labels is not None else shading),
                     view_projection=mat4(view.view_projection),
                     origin_from_eye=tuple((origin - view.eye).tolist()),
                     **({"coverage_floor": coverage_floor, "coverage_pass": 0,
                         "coverage_exponent": AA_ALPHA_EXPONENT} if thin else {}))
        count = polygons.triangles.size
        layout = LEAF_VERTEX_LAYOUT if labels is None else ("3f 12x 2f", "position", "shade")  # no normal
        attributes = [(vbo, *layout)] + ([(self._thin_buffer(polygons, origin), *THIN_LEAF_LAYOUT)] if thin else [])
        vao = ctx.vertex_array(program, attributes, index_buffer=ibo, index_element_size=4)
        nearest = self._nearest_first(vbo, ibo, origin, view, count) if looks.get("SKY_LIGHT") else None

        share = self.thin_share(polygons, origin, view.eye, coverage_floor) if thin else "none"

        def frame_draw():
            ctx.disable(ctx.CULL_FACE)
            if nearest is not None:
                nearest[0]()
            if share != "all":          # else every leaf is the thin pass's
                vao.render(mode=ctx.TRIANGLES, vertices=count)
            ctx.depth_func = "<"
        thin_draw = coverage_pass(ctx, program, lambda: vao.render(mode=ctx.TRIANGLES, vertices=count)) \
            if share != "none" else None
        if not shadowed:
            return frame_draw, None, [vao, *(nearest[1:] if nearest else [])], thin_draw
        caster = build_program(ctx, "leaf.glsl", {"SHADOW_PASS": True})      # relative to the light's anchor
        set_uniforms(caster, view_projection=mat4(lighting.caster_window.matrix()),
                     origin_from_eye=tuple((origin - lighting.anchor).tolist()))
        light_vao = ctx.vertex_array(caster, [(vbo, "3f 20x", "position")], index_buffer=ibo,
                                     index_element_size=4)

        def light_draw():
            ctx.disable(ctx.CULL_FACE)
            light_vao.render(mode=ctx.TRIANGLES, vertices=count)
        return frame_draw, light_draw, [vao, light_vao, *(nearest[1:] if nearest else [])], thin_draw

    def _nearest_first(self, vbo, ibo, origin, view, count: int):
        """A depth-only pass of the leaves from the eye (``leaf.glsl``'s SHADOW_PASS, no colour
        written), after which the shaded pass draws with the depth test ``<=``: only the
        nearest leaf of a pixel runs the shading, for a shading that costs (the sky light's
        rays); leaves behind it are dropped by the early depth test. Returns (the draw,
        its vertex array to release)."""
        ctx = self.ctx
        depth = build_program(ctx, "leaf.glsl", {"SHADOW_PASS": True, "EYE_DEPTH": True})
        set_uniforms(depth, view_projection=mat4(view.view_projection),
                     origin_from_eye=tuple((origin - view.eye).tolist()))
        vao = ctx.vertex_array(depth, [(vbo, "3f 20x", "position")], index_buffer=ibo, index_element_size=4)

        def draw():
            fbo = ctx.fbo
            mask = fbo.color_mask
            fbo.color_mask = tuple((False,) * 4 for _ in mask) if isinstance(mask[0], tuple) else (False,) * 4
            vao.render(mode=ctx.TRIANGLES, vertices=count)
            fbo.color_mask = mask
            ctx.depth_func = "<="
        return draw, vao
