"""Raster renderer for tessellated frusta (GS, GS+R), the polygonal side of Table 1.

A :class:`~plantgen.geometry.meshes.mesh.TessellatedMesh` is uploaded once (float32 positions
relative to the mesh's own origin, normals, texture coordinates, uint32 indices) and
drawn with one indexed draw call, back faces culled (the mesh is closed). A swaying
scene's mesh is a :class:`~plantgen.geometry.meshes.skinned_mesh.SkinnedMesh`, uploaded once at
rest (moving vertices relative to their pivot segment's rest start, and their binding)
and posed by the vertex shader from the pose buffer of :mod:`plantgen.gl.pose`. The camera,
light, material palette, height maps, sky, ground and shadow map are the ray caster's
(:mod:`plantgen.gl.frame`, ``shaders/shading.glsl``), so an RC image and a GS image
of the same model differ only by geometry. The output is the same
:class:`~plantgen.gl.result.RenderResult` (colour, distance along the ray, frame time).
"""

from __future__ import annotations

import time

import numpy as np

from ..geometry.meshes.mesh import TessellatedMesh
from ..geometry.meshes.skinned_mesh import SkinnedMesh
from ..geometry.meshes.textures import mesh_tangents, mesh_uv_scales
from ..geometry.rays.camera import Camera, box_corners
from ..geometry.rays.instances import PlacedMeshes
from ..geometry.skeletons.frusta import relief_scale
from ..geometry.stage import Ground
from ..settings import ParallaxSettings, ShadowSettings
from .context import gl_context
from .frame import (
    FrameLighting,
    FrameView,
    LightPass,
    OffscreenRenderer,
    ShadowKey,
    check_background,
    check_ssaa,
    coverage_aa,
    frame_view,
)
from .instanced import IDENTITY_TURN, draw_copies, eye_copy_draws, light_copy_draws
from .leaf_layer import leaf_bounds, union_box
from .passes import frame_passes
from .result import RasterStats, RenderResult
from .shaders import build_program, mat4, set_uniforms

__all__ = ["RasterRenderer", "render_mesh", "gs_buffer_bytes", "placed_buffer_bytes", "normal_map_texture",
           "normal_map_bytes", "PARALLAX_SHELL_BYTES", "PARALLAX_SCALE_BYTES",
           "row_data"]


def row_data(frusta) -> np.ndarray:
    """(n, 2) float32 per frustum row: chain offset, material (8 bytes a row).

    The chain offset turns the mesh's texture v (which counts texture periods along a
    chain, :attr:`Frusta.chain_texture_v`) back into the row's texture v in the fragment
    shader: the row's v of (7) in its slot, ``(slot + v) / slots`` (``Frusta.v_part``).
    """
    out = np.zeros((len(frusta.length), 2), dtype=np.float32)
    out[:, 0] = frusta.chain_texture_v - frusta.v_part[:, 0] / frusta.v_part[:, 1]
    out[:, 1] = frusta.material
    return out


def gs_buffer_bytes(mesh: TessellatedMesh | SkinnedMesh) -> int:
    """GPU buffer bytes of a GS draw: vertices (32 B each; a skinned mesh's 8 B more for
    their binding), uint32 indices, 8 B per row, 4 B per cap (4 B per face where knuckles
    break the rows' uniform counts; height maps, shared with RC, and the pose buffer are
    not counted)."""
    skinned = isinstance(mesh, SkinnedMesh)
    mesh = mesh.mesh if skinned else mesh
    looked_up = mesh.n_caps if mesh.uniform_rows else len(mesh.faces)
    return (mesh.buffer_bytes()["total"] + 8 * mesh.n_rows + 4 * looked_up
            + (8 * len(mesh.vertices) if skinned else 0))


def _vertex_data(mesh: TessellatedMesh | SkinnedMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(origin (3,), (V, 8) float32 interleaved position, normal, uv, (V, 2) int32 binding
    or None): positions relative to the origin, a skinned mesh's moving ones to their
    pivot's rest start (both formed in float64)."""
    tm = mesh.mesh if isinstance(mesh, SkinnedMesh) else mesh
    origin = tm.vertices.mean(axis=0) if len(tm.vertices) else np.zeros(3)
    interleaved = np.empty((len(tm.vertices), 8), dtype=np.float32)
    interleaved[:, 0:3] = tm.vertices - origin
    interleaved[:, 3:6] = tm.normals
    interleaved[:, 6:8] = tm.uv
    if not isinstance(mesh, SkinnedMesh):
        return origin, interleaved, None
    moving = mesh.pivot >= 0
    interleaved[moving, 0:3] = mesh.offset[moving]
    return origin, interleaved, np.ascontiguousarray(np.stack([mesh.pivot, mesh.other], axis=1), np.int32)


class RasterRenderer(OffscreenRenderer):
    """Draws tessellated meshes into an offscreen framebuffer like the ray caster's."""

    def __init__(self, ctx=None):
        super().__init__(ctx)
        self._uploaded = None  # (mesh id, buffers, vao, origin, GS+POM's row shells or None)
        self._placed = None    # (PlacedMeshes, program, [per plant buffers, vao, origin])
        self._normal_tex = None  # (names and maps, texture array) of GS+N and GS+POM
        #: (file, names of the defines switched on) of every program a frame of this renderer used
        self.programs_used: set[tuple] = set()

    def release_mesh(self) -> None:
        """Free the uploaded mesh's buffers (the renderer stays usable)."""
        if self._uploaded is not None:
            for obj in self._uploaded[1]:
                obj.release()
            self._uploaded = None

    def release(self) -> None:
        """Free every GL object of this renderer: the mesh's buffers, the framebuffer, the
        height textures and the shadow map."""
        self.release_mesh()
        self.release_placed()
        if self._normal_tex is not None:
            self._normal_tex[1].release()
            self._normal_tex = None
        super().release()

    def upload(self, mesh: TessellatedMesh | SkinnedMesh, frusta, program):
        """Upload ``mesh`` (once per mesh object and program; a NORMAL_MAP program's with
        the mesh's tangents, :func:`~plantgen.geometry.meshes.textures.mesh_tangents`); returns
        (vao, origin)."""
        key = (mesh, program)  # strong references: identity stays valid while cached
        if self._uploaded is not None and self._uploaded[0][0] is mesh and self._uploaded[0][1] is program:
            return self._uploaded[2], self._uploaded[3]
        self.release_mesh()
        ctx = self.ctx
        # One interleaved buffer, 32 bytes a vertex: position, normal, uv (float32).
        origin, interleaved, binding = _vertex_data(mesh)
        vbo = ctx.buffer(interleaved.tobytes())
        del interleaved
        bind = ctx.buffer(binding.tobytes() if binding is not None and len(binding) else b"\0" * 8)
        mesh = mesh.mesh if binding is not None else mesh
        ibo = ctx.buffer(np.ascontiguousarray(mesh.faces, np.uint32).tobytes())
        rows = ctx.buffer(row_data(frusta).tobytes())
        if mesh.uniform_rows:     # row of a face by division; the caps' rows looked up
            lateral = mesh.n_rows * 16 * 4 ** mesh.level
            cap_rows = mesh.face_row[lateral::_cap_tris(mesh)] if mesh.n_caps else np.zeros(1, np.int32)
        else:                     # knuckle slices carry other counts: every face's row
            cap_rows = mesh.face_row if len(mesh.face_row) else np.zeros(1, np.int32)
        caps_buf = ctx.buffer(np.ascontiguousarray(cap_rows, np.int32).tobytes())
        tangents = _tangent_buffer(ctx, mesh, program)
        # GS+POM: each row's relief depth (model units) at its two ends and its v slot, 16 B a
        # row (row_depths); each vertex's uv scales, 8 B (mesh_uv_scales)
        parallax = "uv_scale" in program
        shells = ctx.buffer(row_depths(frusta).tobytes()) if parallax else None
        scales = ctx.buffer(mesh_uv_scales(mesh.vertices, mesh.uv, mesh.faces).tobytes()) if parallax else None
        vao = ctx.vertex_array(program, [(vbo, "3f 3f 2f", "position", "normal", "texcoord")]
                               + ([(bind, "2i", "bind")] if binding is not None else [])
                               + ([(tangents, "4f", "tangent")] if tangents is not None else [])
                               + ([(scales, "2f", "uv_scale")] if scales is not None else []),
                               index_buffer=ibo, index_element_size=4)
        extra = tuple(b for b in (tangents, shells, scales) if b is not None)
        self._uploaded = (key, (vbo, ibo, rows, caps_buf, vao, bind) + extra, vao, origin, shells)
        return vao, origin

    def render(self, mesh: TessellatedMesh | SkinnedMesh, frusta, camera: Camera, *, material_names=None,
               light_dir=None, ground: Ground | None = None,
               shadows: ShadowSettings | None = None, shadow_box=None,
               count_work: bool = False, background=None, ssaa: int = 1, leaves=None,
               poses=None, bounds=None, normal_maps=None,
               parallax: ParallaxSettings | None = None, aa: str = "none") -> RenderResult:
        """Rasterise ``mesh`` (tessellated from ``frusta``) as seen by ``camera``.

        Parameters
        ----------
        mesh : the tessellation (GS, or GS+R when made with ``relief=True``: displaced,
            with normals tilted as RC+R tilts them), or a swaying scene's
            :class:`SkinnedMesh` (built at rest), posed by the vertex shader from ``poses``
        poses : with a SkinnedMesh: the GPU pose buffer (per segment its posed start
            relative to the camera's eye and its turn: :meth:`plantgen.gl.pose.GpuPose.pose_buffer`)
        bounds : (2, 3) world box the mesh lies in (default: its vertices' box; a skinned
            mesh's posed vertices are not on the CPU: the animation's box)
        frusta : the rows it was made from (materials, chains)
        camera : the view, as for the ray caster
        material_names : default ``mesh.material_names``
        light_dir : (3,) towards the light, as for the ray caster (default: the model light)
        ground : optional ground square, as for the ray caster
        shadows : None (no shadow pass) or the shadow map's knobs, as for the ray caster:
            the mesh and the ground first write their depth into the light's map
        shadow_box : (2, 3) world box the light's window must cover (default: the mesh's
            bounds), as for the ray caster
        count_work : a diagnostic render that also counts the fragments shaded
            (``stats.work``), as for the ray caster
        background, ssaa, aa : background, supersampling and anti-aliasing, as for the ray
            caster (no floor radius here: only ``"edges"``'s edge pass changes the frame)
        leaves : a Polygons (the grammar's leaves) drawn beside the mesh, as for the ray
            caster
        normal_maps : GS+N: {material slot (int) or name: (H, W, 3) uint8 tangent-space
            normal map} (:func:`~plantgen.geometry.meshes.textures.bake_normal_map`, glTF's
            convention) shading the lateral faces of a still mesh as a glTF reader would;
            None: none. With ``parallax``: (H, W, 4) uint8, the alpha the relief height w
            (:func:`~plantgen.geometry.meshes.textures.parallax_map`)
        parallax : GS+POM: parallax occlusion mapping of these maps with these knobs
            (``raster.glsl``'s PARALLAX), on a mesh at the relief's outer shell
            (:func:`~plantgen.geometry.meshes.mesh.outer_shell_mesh`); None: none
        """
        skinned = isinstance(mesh, SkinnedMesh)
        if skinned and poses is None:
            raise ValueError("a skinned mesh is drawn with its pose buffer (poses=...)")
        uploaded, mesh = mesh, (mesh.mesh if skinned else mesh)
        names = tuple(material_names or mesh.material_names)
        background, ssaa = check_background(background), check_ssaa(ssaa)
        shadowed = shadows is not None
        program = self._mesh_program(mesh, shadowed, count_work, skinned, normal_maps, parallax)
        t0 = time.perf_counter()
        vao, origin = self.upload(uploaded, frusta, program)
        upload_ms = (time.perf_counter() - t0) * 1e3
        bounds = union_box(_mesh_bounds(mesh) if bounds is None else np.asarray(bounds, np.float64),
                           leaf_bounds(leaves))
        view = frame_view(camera.scaled(ssaa), [box_corners(bounds)] + ([] if ground is None else [ground.quad()]))
        tex, repeats = self._heights.get(names)
        box = None if not shadowed else (bounds if shadow_box is None else np.asarray(shadow_box, np.float64))
        lighting = self._lighting(names, ground, light_dir, shadows, box, view.eye,
                                  anchor=view.eye if skinned else None)
        draw_mesh = self._mesh_draw(program, vao, origin, view, lighting, repeats, tex, mesh, poses)
        draw_mesh = self._normal_mapped(program, names, normal_maps, draw_mesh, parallax)
        floor = view.floor_radius() if coverage_aa(aa, ssaa, False, background) else 0.0
        extras = self._surroundings(ground, leaves, view, lighting, background=background, coverage_floor=floor)
        light = None
        if shadowed:
            # a skinned mesh is posed by a buffer rewritten every frame: no key, its map drawn each time
            key = None if skinned else ShadowKey(("raster.glsl", mesh.level), (mesh, leaves if extras.after else None),
                                                 ground, shadows.resolution, lighting.anchor, lighting.caster_window)
            light = LightPass(key, lambda: self._mesh_light_pass(origin, lighting, mesh, poses))
        out = self._finish_frame(camera, view, lighting, background, draw_mesh, shadows, light, extras,
                                 ssaa=ssaa, count_work=count_work, smooth=aa == "edges" and floor > 0)
        leaf_tris = len(leaves.triangles) if extras.after else 0
        stats = RasterStats(
            passes=frame_passes(shadowed, ground is not None, len(mesh.faces) > 0, leaf_tris > 0),
            near=view.near, far=view.far, shadow_ms=out.shadow_ms, light_window=lighting.window,
            upload_ms=upload_ms, ssaa=ssaa, resolve_ms=self.last_resolve_ms, triangles=len(mesh.faces) + leaf_tris,
            vertices=len(mesh.vertices),
            level=mesh.level, buffer_bytes=gs_buffer_bytes(uploaded),
            draw_calls=1 + (ground is not None) + (leaf_tris > 0), work=out.work, shadow_cached=out.shadow_cached)
        return RenderResult(out.color, out.distance, out.frame_ms, camera, stats)

    def _mesh_program(self, mesh: TessellatedMesh, shadowed: bool, count_work: bool, skinned: bool, normal_maps,
                      parallax: ParallaxSettings | None):
        """The raster.glsl variant :meth:`render` draws ``mesh`` with (recorded in
        :attr:`programs_used`): NORMAL_MAP with ``normal_maps``, PARALLAX with ``parallax``
        besides (a skinned mesh: neither)."""
        if parallax is not None and normal_maps is None:
            raise ValueError("parallax occlusion mapping marches the maps' height: give normal_maps=...")
        defines = {"TRIANGLES_PER_ROW": 16 * 4 ** mesh.level, "SHADOWS": shadowed,
                   "STATS": count_work, "FACE_ROWS": not mesh.uniform_rows, "SKINNED": skinned,
                   "NORMAL_MAP": normal_maps is not None and not skinned,
                   "PARALLAX": parallax is not None and not skinned}
        self.programs_used.add(("raster.glsl", tuple(sorted(k for k, v in defines.items() if v is True))))
        return build_program(self.ctx, "raster.glsl", defines)

    def _mesh_draw(self, program, vao, origin, view: FrameView, lighting: FrameLighting,
                   repeats, tex, mesh: TessellatedMesh, poses=None):
        """Set the mesh program and return the callable that draws the mesh (posed from
        ``poses`` when skinned)."""
        set_uniforms(program, **lighting.shading, **lighting.receiver, **IDENTITY_TURN,
                     view_projection=mat4(view.view_projection),
                     origin_from_eye=tuple((origin - view.eye).tolist()), n_rows=mesh.n_rows,
                     height_maps=0, texture_repeat=repeats)
        buffers, shells = self._uploaded[1], self._uploaded[4]
        buffers[2].bind_to_storage_buffer(0)
        buffers[3].bind_to_storage_buffer(1)
        ctx = self.ctx

        def draw():
            ctx.enable(ctx.CULL_FACE)
            ctx.front_face = "ccw"
            ctx.cull_face = "back"
            tex.use(0)
            if shells is not None:
                shells.bind_to_storage_buffer(PARALLAX_SHELL_BINDING)
            if poses is not None:
                poses.bind_to_storage_buffer(3)
            vao.render(mode=ctx.TRIANGLES, vertices=mesh.faces.size)
        return draw

    def _normal_mapped(self, program, names, normal_maps, draw, parallax: ParallaxSettings | None = None):
        """``draw`` with the normal maps' texture array bound (unit :data:`NORMAL_MAP_UNIT`:
        0 holds the height maps, 1 the shadow map), where ``program`` reads one
        (NORMAL_MAP; PARALLAX: with ``parallax``'s uniforms): built once per list of names
        and maps."""
        if "normal_maps" not in program:
            return draw
        if parallax is not None:
            set_uniforms(program, **parallax.uniforms())
        key = (tuple(names), tuple(id(normal_maps.get(k, normal_maps.get(n))) for k, n in enumerate(names)))
        if self._normal_tex is None or self._normal_tex[0] != key:
            if self._normal_tex is not None:
                self._normal_tex[1].release()
            self._normal_tex = (key, normal_map_texture(self.ctx, names, normal_maps))
        tex = self._normal_tex[1]
        program["normal_maps"] = NORMAL_MAP_UNIT

        def mapped():
            tex.use(NORMAL_MAP_UNIT)
            draw()
        return mapped

    def _mesh_light_pass(self, origin, lighting: FrameLighting, mesh: TessellatedMesh, poses=None):
        """The mesh's front faces into the light's depth map, relative to the light's
        anchor (a skinned mesh's: the eye, as its poses are): ([draw callable], [vertex
        array to release after the frame])."""
        skinned = poses is not None
        caster = build_program(self.ctx, "raster.glsl", {"SHADOW_PASS": True, "SKINNED": skinned})
        buffers = self._uploaded[1]
        attributes = [(buffers[0], "3f 20x", "position")] + ([(buffers[5], "2i", "bind")] if skinned else [])
        return self._mesh_light_draw(caster, lighting, origin, attributes, buffers[1], mesh.faces.size,
                                     before=(lambda: poses.bind_to_storage_buffer(3)) if skinned else None)


    # ------------------------------------------------------------------ placed scenes
    def placed_upload(self, meshes: PlacedMeshes, program) -> list:
        """Per plant of ``meshes`` (vbo, ibo, rows, face rows, vao, local origin), uploaded
        once per PlacedMeshes object (faces in row order; every face's row looked up)."""
        if self._placed is not None and self._placed[0] is meshes and self._placed[1] is program:
            return self._placed[2]
        self.release_placed()
        ctx, out = self.ctx, []
        for pm, plant in zip(meshes.meshes, meshes.placed.plants, strict=True):
            origin, interleaved, _ = _vertex_data(pm.mesh)
            vbo, ibo = ctx.buffer(interleaved.tobytes()), ctx.buffer(pm.faces.astype(np.uint32).tobytes())
            rows = ctx.buffer(row_data(plant.frusta).tobytes())
            face_rows = ctx.buffer(pm.face_row.tobytes() if len(pm.face_row) else b"\0" * 4)
            vao = ctx.vertex_array(program, [(vbo, "3f 3f 2f", "position", "normal", "texcoord")],
                                   index_buffer=ibo, index_element_size=4)
            out.append((vbo, ibo, rows, face_rows, vao, origin))
        self._placed = (meshes, program, out)
        return out

    def release_placed(self) -> None:
        if self._placed is not None:
            for objects in self._placed[2]:
                for obj in objects[:5]:
                    obj.release()
            self._placed = None

    def render_placed(self, meshes: PlacedMeshes, camera: Camera, *, light_dir=None, ground: Ground | None = None,
                      shadows: ShadowSettings | None = None, shadow_box=None, background=None, ssaa: int = 1,
                      lod_pixels: float = 0.0, aa: str = "none") -> RenderResult:
        """Rasterise a placed scene's meshes (GS, GS+R), each plant's mesh uploaded once and
        drawn once per copy the view sees (:mod:`plantgen.gl.instanced`), each copy's first
        rows of the detail order as ``lod_pixels`` asks (the light's pass: in its texels).
        The arguments are :meth:`render`'s."""
        placed, names = meshes.placed, meshes.placed.material_names
        background, ssaa = check_background(background), check_ssaa(ssaa)
        shadowed = shadows is not None
        program = build_program(self.ctx, "raster.glsl", {"TRIANGLES_PER_ROW": 16 * 4 ** meshes.level,
                                                          "SHADOWS": shadowed, "FACE_ROWS": True})
        uploads = self.placed_upload(meshes, program)
        origins = [u[5] for u in uploads]
        view = frame_view(camera.scaled(ssaa), [box_corners(placed.box)] + ([] if ground is None else [ground.quad()]))
        tex, repeats = self._heights.get(names)
        box = None if not shadowed else (placed.box if shadow_box is None else np.asarray(shadow_box, np.float64))
        lighting = self._lighting(names, ground, light_dir, shadows, box, view.eye)
        set_uniforms(program, **lighting.shading, **lighting.receiver, view_projection=mat4(view.view_projection),
                     height_maps=0, texture_repeat=repeats, n_rows=0)
        plan = eye_copy_draws(placed, view, lod_pixels, origins)
        draw = self._placed_draws(program, uploads, meshes, plan, "origin_from_eye", tex)
        extras = self._surroundings(ground, None, view, lighting, background=background)
        light = None
        if shadowed:
            key = ShadowKey(("raster.glsl", meshes.level, float(lod_pixels)), (meshes,), ground, shadows.resolution,
                            lighting.anchor, lighting.caster_window)
            light = LightPass(key, lambda: self._placed_light_draw(meshes, uploads, lighting, shadows, lod_pixels))
        out = self._finish_frame(camera, view, lighting, background, draw, shadows, light, extras, ssaa=ssaa,
                                 count_work=False, smooth=aa == "edges" and coverage_aa(aa, ssaa, False, background))
        triangles = sum(int(pm.row_faces[c]) for pm, d in zip(meshes.meshes, plan, strict=True)
                        for c in d.counts.tolist())
        stats = RasterStats(
            passes=frame_passes(shadowed, ground is not None, triangles > 0, False), near=view.near, far=view.far,
            shadow_ms=out.shadow_ms, light_window=lighting.window, ssaa=ssaa, resolve_ms=self.last_resolve_ms,
            triangles=triangles, vertices=sum(len(pm.mesh.vertices) for pm in meshes.meshes), level=meshes.level,
            buffer_bytes=placed_buffer_bytes(meshes),
            draw_calls=sum(len(d.copies) for d in plan) + (ground is not None),
            shadow_cached=out.shadow_cached)
        return RenderResult(out.color, out.distance, out.frame_ms, camera, stats)

    def _placed_draws(self, program, uploads, meshes: PlacedMeshes, plan, offset_name: str, tex=None,
                      vaos=None):
        """The callable drawing ``plan`` (CopyDraws per plant): per plant its rows bound,
        per copy the faces of its first rows."""
        ctx = self.ctx
        vaos = vaos if vaos is not None else [u[4] for u in uploads]

        def draw():
            ctx.enable(ctx.CULL_FACE)
            ctx.front_face = "ccw"
            ctx.cull_face = "back"
            if tex is not None:
                tex.use(0)
            for u, vao, pm, copies in zip(uploads, vaos, meshes.meshes, plan, strict=True):
                u[2].bind_to_storage_buffer(0)
                u[3].bind_to_storage_buffer(1)
                faces = pm.row_faces

                def render(v, count, faces=faces):
                    v.render(mode=ctx.TRIANGLES, vertices=3 * int(faces[count]))
                draw_copies(program, vao, copies, render, offset_name)
            set_uniforms(program, **IDENTITY_TURN)
        return draw

    def _placed_light_draw(self, meshes: PlacedMeshes, uploads, lighting: FrameLighting, shadows: ShadowSettings,
                           lod_pixels: float):
        """A placed scene's copies into the light's map, relative to its anchor, each as
        many rows as ``lod_pixels`` texels ask: ([draw], [vertex arrays to release])."""
        caster = build_program(self.ctx, "raster.glsl", {"SHADOW_PASS": True})
        set_uniforms(caster, view_projection=mat4(lighting.caster_window.matrix()), **IDENTITY_TURN)
        texel = lighting.caster_window.texel_size(shadows.resolution)
        plan = light_copy_draws(meshes.placed, lighting.anchor, texel, lod_pixels, [u[5] for u in uploads])
        vaos = [self.ctx.vertex_array(caster, [(u[0], "3f 20x", "position")], index_buffer=u[1],
                                      index_element_size=4) for u in uploads]
        return [self._placed_draws(caster, uploads, meshes, plan, "origin_from_eye", vaos=vaos)], vaos


def row_depths(frusta) -> np.ndarray:
    """(n, 4) float32: each row's relief depth (model units) where its axis meets its lower
    and upper ends, shell·r1/max(r1, r2) and shell·r2/max(r1, r2) (the relief follows the
    radius: :func:`~plantgen.geometry.skeletons.frusta.relief_scale`), its v slots and its slot (a
    row's own v is its texture v times the slots less the slot), for GS+POM's march depth."""
    out = np.zeros((len(frusta), 4), np.float32)
    out[:, 0] = frusta.shell * relief_scale(frusta, np.arange(len(frusta)), np.zeros(len(frusta)))
    out[:, 1] = frusta.shell * relief_scale(frusta, np.arange(len(frusta)), frusta.length)
    out[:, 2], out[:, 3] = frusta.v_part[:, 1], frusta.v_part[:, 0]
    return out


def placed_buffer_bytes(meshes: PlacedMeshes) -> int:
    """GPU buffer bytes of a placed scene's GS draw: per plant its mesh's vertices and
    indices, 8 B a row and 4 B a face (every face's row); nothing per copy."""
    return sum(pm.mesh.buffer_bytes()["total"] + 8 * pm.mesh.n_rows + 4 * len(pm.faces) for pm in meshes.meshes)


def _tangent_buffer(ctx, mesh: TessellatedMesh, program):
    """The mesh's (V, 4) float32 tangents as a buffer where ``program`` reads them
    (NORMAL_MAP), else None."""
    if "tangent" not in program:
        return None
    return ctx.buffer(mesh_tangents(mesh.vertices, mesh.normals, mesh.uv, mesh.faces).tobytes())


#: The texture unit of GS+N's normal maps (the height maps are on 0, the shadow map on 1).
NORMAL_MAP_UNIT = 2
#: The storage binding of GS+POM's row shells (0 rows, 1 caps' rows, 2 work counts, 3 poses).
PARALLAX_SHELL_BINDING = 4
#: GPU bytes of GS+POM's shell thickness of one row (float32).
PARALLAX_SHELL_BYTES = 4
#: GPU bytes of GS+POM's uv scales of one vertex (2 float32: |∂P/∂u|, |∂P/∂v|).
PARALLAX_SCALE_BYTES = 8


def _normal_layers(names, normal_maps) -> tuple[list, tuple]:
    """The map of each slot of ``names`` (None: none) and the texture array's layer size."""
    maps = [normal_maps.get(k, normal_maps.get(n)) for k, n in enumerate(names)]
    shape = max((m.shape[:2] for m in maps if m is not None), default=(1, 1), key=lambda s: s[0] * s[1])
    return maps, shape


def _components(maps) -> int:
    """Channels of the maps' texture: 3 (RGB normal), 4 where they carry a height (GS+POM)."""
    return max((m.shape[2] for m in maps if m is not None), default=3)


def normal_map_bytes(names, normal_maps) -> int:
    """GPU bytes of :func:`normal_map_texture`'s array for these slots and maps: RGB8
    (RGBA8 with a height) layers at the largest map's size, with their mipmap chain."""
    maps, (h, w) = _normal_layers(names, normal_maps)
    components = _components(maps)
    total = 0
    while True:
        total += h * w * components * len(names)
        if h == 1 and w == 1:
            return total
        h, w = max(h // 2, 1), max(w // 2, 1)


def normal_map_texture(ctx, names, normal_maps):
    """RGB8 texture array of the normal maps ((H, W, 3) uint8, glTF convention, by slot
    index or by material name) of the material slots ``names`` (a slot without one: the
    flat (128, 128, 255), and height 255: no relief), every layer at the largest map's
    size (smaller ones repeated texel by texel), repeating in u and v, trilinear: as an
    engine samples the exported map (without anisotropic filtering: llvmpipe's made GS+POM's
    gathers 500 times slower and wrong). RGBA8 where the maps are (H, W, 4), the alpha the
    height (GS+POM, :func:`~plantgen.geometry.meshes.textures.parallax_map`)."""
    maps, shape = _normal_layers(names, normal_maps)
    components = _components(maps)
    layers = np.empty((len(names), *shape, components), np.uint8)
    for k, m in enumerate(maps):
        if m is None:
            layers[k] = (128, 128, 255, 255)[:components]
        else:
            layers[k] = np.repeat(np.repeat(m, shape[0] // m.shape[0], axis=0), shape[1] // m.shape[1], axis=1)
    tex = ctx.texture_array((shape[1], shape[0], len(names)), components, layers.tobytes(), dtype="f1")
    tex.build_mipmaps()
    tex.filter = (ctx.LINEAR_MIPMAP_LINEAR, ctx.LINEAR)
    tex.repeat_x, tex.repeat_y = True, True
    return tex


def _cap_tris(mesh: TessellatedMesh) -> int:
    return 8 * 2 ** mesh.level


def _mesh_bounds(mesh: TessellatedMesh) -> np.ndarray:
    """(2, 3) world box of the mesh's vertices (a unit box at the origin when empty)."""
    if len(mesh.vertices) == 0:
        return np.array([[-0.5] * 3, [0.5] * 3])
    return np.stack([mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)])


_default: RasterRenderer | None = None


def render_mesh(mesh: TessellatedMesh, frusta, camera: Camera, *, material_names=None) -> RenderResult:
    """Render with the shared context's cached :class:`RasterRenderer`."""
    global _default
    ctx = gl_context()
    if _default is None or _default.ctx is not ctx:
        _default = RasterRenderer(ctx)
    return _default.render(mesh, frusta, camera, material_names=material_names)
