"""The GLSL ray caster for conical frusta (RC) and relief-mapped frusta (RC+R).

Data path: :class:`plantgen.geometry.skeletons.frusta.Frusta` (float64, world coordinates) ->
:func:`plantgen.gl.records.pack_records` (one 96-byte float32 record per segment,
positions relative to the camera eye so float32 keeps its digits far from the world
origin) -> one instanced draw of the 12-triangle bounding pyramid (built in the vertex
shader from the record) -> the fragment shader in ``shaders/raycast.glsl`` intersects the
pixel's ray with the frustum (``shaders/cone.glsl``), shades it and writes
``gl_FragDepth``.

Effects (plantgen.gl.passes): with shadows a first pass ray casts the same rows along
the light into a depth map that every surface then samples (``SHADOWS``); with relief the
relief shell is marched (``RELIEF``). Neither is compiled or run otherwise. The light's
pass packs its own records, relative to the light's anchor instead of the eye, and only
when its map must be drawn (:class:`~plantgen.gl.frame.ShadowKey`): a static scene draws
it once.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..errors import PlantgenError
from ..geometry.meshes.mesh import tessellate, triangle_count
from ..geometry.rays.camera import Camera, box_corners
from ..geometry.rays.instances import PlacedPlants
from ..geometry.skeletons.frusta import ROW_FIELDS, Frusta
from ..geometry.stage import Ground
from ..limits import LimitError, Limits, hint
from ..limits import limits as default_limits
from ..settings import AA_ALPHA_EXPONENT, RaycastSettings, ShadowSettings
from .bvh_cache import BvhCache
from .context import gl_context
from .coverage import coverage_pass
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
from .instanced import IDENTITY_PLACEMENT, draw_copies, eye_copy_draws, light_copy_draws
from .leaf_layer import leaf_bounds, union_box
from .passes import frame_passes, light_defines, light_program, program_variants, traced_look
from .records import (
    PYRAMID_CORNERS,
    PYRAMID_TRIANGLES,
    RECORD_ATTRIBUTES,
    RECORD_BYTES,
    RECORD_LAYOUT,
    pack_records,
    rows_box,
)
from .result import RaycastStats, RenderResult
from .shaders import build_program, mat4, set_uniforms

__all__ = ["RaycastSettings", "Raycaster", "render_frusta", "label_image"]

#: Vertices of one instance's bounding pyramid (12 triangles).
PYRAMID_VERTICES = len(PYRAMID_TRIANGLES) * 3
#: Coverage anti-aliasing's screen quad of a thin row (raycast.glsl's THIN_RIBBON): two
#: triangles over the pyramid template's corners 0, 1, 4, 5 (sx = -1, +1 at either end).
RIBBON_TRIANGLES = np.array([[0, 1, 5], [0, 5, 4]], dtype=np.int32)


#: Bytes the mesh caster's mesh takes a triangle, host and GPU together (about half a
#: vertex a triangle: float64 position, normal and uv, the faces, their float32 upload).
CASTER_MESH_BYTES_PER_TRIANGLE = 96

#: Meshes of the mesh caster a ray caster keeps (by frusta, level and relief).
CASTER_MESHES_KEPT = 8


def _timed_pack(frusta, eye) -> tuple:
    """(:func:`pack_records` of ``frusta`` relative to ``eye``, its milliseconds)."""
    t0 = time.perf_counter()
    records = pack_records(frusta, eye)
    return records, (time.perf_counter() - t0) * 1e3


class Raycaster(OffscreenRenderer, BvhCache):
    """Renders Frusta with the GLSL ray caster into an offscreen framebuffer.

    Programs are compiled per variant (defines) and cached; nothing is compiled or run that
    the settings do not ask for (no relief march without relief).
    """

    #: Whether coverage anti-aliasing casts the rows thinner than its floor a floor wide and
    #: blends them (the ray caster: its rows' pyramids are built per frame, so they grow with
    #: the floor); the tracer's BVH boxes hold the rows' own radii, so it does not.
    casts_thin_rows = True
    #: Whether coverage anti-aliasing's pass draws each thin row as one screen quad around
    #: it (raycast.glsl's THIN_RIBBON: two triangles, the same pixels and colours) rather
    #: than by its pyramid's back faces (up to six triangles, each of which llvmpipe shades
    #: in 4 x 4 blocks of its own: on llvmpipe the pass took the elm and the coconut 1.5
    #: times the CPU time at 512x384).
    thin_ribbons = True

    def __init__(self, ctx=None, limits: Limits | None = None):
        super().__init__(ctx)
        #: the budgets in force (the mesh caster's mesh counts against ``max_render_bytes``)
        self.limits = limits if limits is not None else default_limits
        self._template_vbo = self.ctx.buffer(PYRAMID_CORNERS.tobytes())
        self._template_ibo = self.ctx.buffer(PYRAMID_TRIANGLES.tobytes())
        self._ribbon_ibo = self.ctx.buffer(RIBBON_TRIANGLES.tobytes())
        self.programs_used: set[tuple] = set()
        self._placed = None      # (PlacedPlants, [record buffer per plant]): uploaded once
        # the mesh caster's meshes, least recently used first:
        # (frusta, level, relief, origin, vbo, ibo, indices, bytes counted)
        self._caster_meshes: list[tuple] = []
        self._init_bvh()         # the sky light's BVH (BvhCache), built when asked

    def release(self) -> None:
        """Free every GL object of this renderer, a placed scene's records and the mesh
        caster's mesh included."""
        self._release_placed()
        self._release_caster_mesh()
        self._release_bvh()
        super().release()

    def _release_caster_mesh(self, keep: int = 0) -> None:
        """Release the mesh caster's meshes but the ``keep`` most recently used."""
        while len(self._caster_meshes) > keep:
            for buf in self._caster_meshes.pop(0)[4:6]:
                buf.release()

    def caster_mesh(self, frusta: Frusta, level: int, relief: bool):
        """(origin (3,), vertex buffer, index buffer, indices) of the mesh caster's mesh:
        ``frusta`` tessellated at ``level`` (displaced by the relief with ``relief``; tip
        caps, as GS+R renders), positions in float32 relative to the mesh's mean, built and
        uploaded once per frusta object, level and relief. The :data:`CASTER_MESHES_KEPT`
        last used are kept (a bench alternating levels does not rebuild them), within the
        render's memory limit together; one over it alone is refused (one line, a
        :class:`~plantgen.limits.LimitError`)."""
        for i, c in enumerate(self._caster_meshes):
            if c[0] is frusta and c[1:3] == (level, relief):
                self._caster_meshes.append(self._caster_meshes.pop(i))
                return c[3:7]
        triangles = triangle_count(frusta, level, caps="tips")
        need, allowed = triangles * CASTER_MESH_BYTES_PER_TRIANGLE, self.limits.max_render_bytes
        if need > allowed:
            raise LimitError(f"--shadow-caster mesh at level {level}: {triangles:,} triangles need about "
                             f"{need / 2**20:,.0f} MiB, over the limit of {allowed / 2**20:,.0f} MiB "
                             f"({hint('render_bytes')}; or lower --shadow-mesh-level)")
        self._release_caster_mesh(CASTER_MESHES_KEPT - 1)
        while self._caster_meshes and need + sum(c[7] for c in self._caster_meshes) > allowed:
            self._release_caster_mesh(len(self._caster_meshes) - 1)
        mesh = tessellate(frusta, level, relief=relief, caps="tips")
        origin = mesh.vertices.mean(axis=0) if len(mesh.vertices) else np.zeros(3)
        vbo = self.ctx.buffer(np.ascontiguousarray(mesh.vertices - origin, np.float32).tobytes() or b"\0" * 12)
        ibo = self.ctx.buffer(np.ascontiguousarray(mesh.faces, np.uint32).tobytes() or b"\0" * 4)
        self._caster_meshes.append((frusta, level, relief, origin, vbo, ibo, int(mesh.faces.size), need))
        return self._caster_meshes[-1][3:7]

    def _release_placed(self) -> None:
        if self._placed is not None:
            for buf in self._placed[1]:
                buf.release()
            self._placed = None

    def placed_buffers(self, placed: PlacedPlants) -> list:
        """The record buffer of each plant of ``placed`` (in its own frame), uploaded once
        per PlacedPlants object."""
        if self._placed is None or self._placed[0] is not placed:
            self._release_placed()
            self._placed = (placed, [self.ctx.buffer(pack_records(p.frusta, np.zeros(3)).tobytes())
                                     for p in placed.plants])
        return self._placed[1]

    def render(self, frusta, camera: Camera, settings: RaycastSettings = RaycastSettings(),
               material_names=("bark",), light_dir=None,
               ground: Ground | None = None, *, shadows: ShadowSettings | None = None,
               shadow_box=None, record_buffer=None, count_work: bool = False, background=None,
               ssaa: int = 1, leaves=None, leaf_labels=None, lod_pixels: float = 0.0,
               aa: str = "none") -> RenderResult:
        """Ray cast ``frusta`` as seen by ``camera``.

        Parameters
        ----------
        frusta : Frusta, n rows (world units, float64), or the rows of a frame posed on the
            GPU (:class:`plantgen.gl.records.StreamedRows`, with ``record_buffer``), or a
            :class:`~plantgen.geometry.rays.instances.PlacedPlants` drawn instanced
            (:mod:`plantgen.gl.instanced`: records per distinct plant, uploaded once)
        camera : the view; rays go through pixel centres
        settings : relief on/off and its step knobs, the looks (``look``; with ``sky`` a BVH)
        material_names : names of the material indices (choose colours and height maps)
        light_dir : (3,) direction towards the light (normalised here); default: the
            model light of :mod:`plantgen.geometry.stage`
        ground : optional ground square, rasterised into the same depth buffer
        shadows : None (no shadow pass, no shadow map sampled) or the shadow map's knobs:
            casters write their depth into the light's map, every surface samples it
        shadow_box : (2, 3) world box the light's window must cover (default: the frusta's
            bounds); an animation passes one for all frames (no shimmer)
        record_buffer : a moderngl buffer already holding ``pack_records(frusta, camera.eye)``
            (an animation updates only what moved); None: packed and uploaded here. Its
            contents are the caller's, so the light's pass draws them as they are and its
            map is drawn every frame; without it the light's records are packed relative
            to the light's anchor, once per map, and the map is kept
        count_work : a diagnostic render that also counts the fragments shaded and the
            relief samples taken (``stats.work``)
        background : None (the sky) or (r, g, b, a) in [0, 1], display-encoded: a flat
            colour; a = 0: transparent, ``color`` (h, w, 4)
        ssaa : samples per pixel side: the frame is drawn at ``ssaa`` times the camera's
            size and averaged down (:mod:`plantgen.gl.supersample`); ``frame_ms`` is
            the large frame's
        aa : ``"coverage"`` (:func:`~plantgen.gl.frame.coverage_aa`, :mod:`~plantgen.gl.coverage`),
            ``"edges"`` (and the edge pass, in ``resolve_ms``) or ``"none"`` (one ray a pixel)
        lod_pixels : with a PlacedPlants: each copy draws the rows whose detail spans at
            least this many pixels (the light's pass: texels of its map); 0 draws all
        """
        n, placed = len(frusta), isinstance(frusta, PlacedPlants)
        background, ssaa = check_background(background), check_ssaa(ssaa)
        coverage = coverage_aa(aa, ssaa, settings.labels, background)
        records, pack_ms = _timed_pack(frusta, camera.eye) if record_buffer is None and not placed else (None, 0.0)
        leaf_box = leaf_bounds(leaves)
        model_box = union_box(rows_box(frusta) if n else None, leaf_box)
        view = frame_view(camera.scaled(ssaa), [g.quad() for g in (ground,) if g is not None]
                          + [box_corners(b) for b in (model_box,) if b is not None])
        sky_bvh = self._sky_bvh(settings, frusta, leaves, camera, record_buffer)
        programs = self._programs(settings, shadows, ground is not None, count_work, background is not None,
                                  leaf_box is not None, sky_bvh.defines() if sky_bvh else None,
                                  coverage and self.casts_thin_rows)
        tex, repeats = self._heights.get(tuple(material_names))
        box = None if shadows is None else (np.asarray(shadow_box, np.float64) if shadow_box is not None
                                            else model_box if model_box is not None else rows_box(frusta))
        lighting = self._sky_lighting(self._lighting(
            material_names, ground, light_dir, shadows, box, view.eye, anchor=None if record_buffer is None
            else view.eye, look=None if settings.labels else settings.look), sky_bvh, settings, view, repeats,
            model_box)
        extras = self._surroundings(ground, leaves, view, lighting, background=background,
                                    labels=leaf_labels if settings.labels else None,
                                    coverage_floor=view.floor_radius() if coverage else 0.0)
        extras.before[:0] = [sky_bvh.bind] if sky_bvh is not None else []
        has_leaves = bool(extras.after)
        draw_frusta, drawn = self._eye_draws(programs["frame"], view, lighting, settings,
                                             frusta if placed else (records, record_buffer),
                                             (repeats, tex, n, lod_pixels), programs["thin"], extras)
        light = None if shadows is None else self._light_pass(
            frusta, programs["light"], lighting, settings, shadows, tuple(material_names), record_buffer,
            (leaves if has_leaves else None, ground), lod_pixels)
        out = self._finish_frame(camera, view, lighting, background, draw_frusta, shadows, light, extras,
                                 ssaa=ssaa, count_work=count_work, smooth=coverage and aa == "edges")
        stats = RaycastStats(
            passes=frame_passes(shadows is not None, ground is not None, n > 0, has_leaves), near=view.near,
            far=view.far, shadow_ms=out.shadow_ms, light_window=lighting.window, segments=drawn,
            record_bytes=RECORD_BYTES, upload_bytes=records.nbytes if records is not None else 0, pack_ms=pack_ms,
            program=("raycast.glsl", settings.defines()), ssaa=ssaa, resolve_ms=self.last_resolve_ms,
            programs=programs["built"], work=out.work, shadow_cached=out.shadow_cached)
        return RenderResult(out.color, out.distance, out.frame_ms, camera, stats)

    def _eye_draws(self, program, view: FrameView, lighting: FrameLighting, settings: RaycastSettings, rows,
                   textures: tuple, thin, extras) -> tuple:
        """The frusta's draw for the eye (:meth:`_frusta_draw` with ``textures`` = (repeats,
        height textures, rows, lod_pixels)) of ``rows``, a PlacedPlants or (records, a
        caller's record buffer or None: the records are uploaded here), what it leaves
        added to ``extras.garbage``; with ``thin`` (a program, None: no coverage
        anti-aliasing), coverage anti-aliasing's pass of the thin rows put first in
        ``extras.thin`` (drawn after everything opaque by ``thin``: ``program`` itself, or
        its THIN_RIBBON variant, :func:`~plantgen.gl.coverage.coverage_pass`). Returns
        (draw, rows drawn)."""
        repeats, tex, n, lod_pixels = textures
        if not isinstance(rows, PlacedPlants):
            records, record_buffer = rows
            rows = record_buffer if record_buffer is not None else (
                self.ctx.buffer(records) if n else None)     # the array's memory, not a copy of it
            extras.garbage.extend([rows] if record_buffer is None else [])
        draw, vaos, drawn = self._frusta_draw(program, view, lighting, settings, rows, repeats, tex, n, lod_pixels,
                                              thin is not None)
        extras.garbage.extend(vaos)
        if thin is not None:
            thin_draw = draw
            if thin is not program:      # the THIN_RIBBON variant: its own vertex arrays
                thin_draw, thin_vaos, _ = self._frusta_draw(thin, view, lighting, settings, rows, repeats, tex, n,
                                                            lod_pixels, True, ribbon=True)
                extras.garbage.extend(thin_vaos)
            extras.thin[:0] = [coverage_pass(self.ctx, thin, thin_draw)]
        return draw, drawn

    def _sky_bvh(self, settings: RaycastSettings, frusta, leaves, camera: Camera, record_buffer=None):
        """The GPU BVH the sky light traces (the ``sky`` effect; None without it): the
        model's rows and leaves, built and uploaded once per model and eye (BvhCache).
        Frames posed on the GPU (``record_buffer``) have no BVH: one line."""
        if settings.labels or not settings.look.sky or not (len(frusta) or leaves is not None):
            return None
        if record_buffer is not None:
            raise PlantgenError("the sky light traces a BVH, which the ray caster's animation frames (posed on the "
                                "GPU) do not have: animate it with --method rt, or leave out the sky effect")
        return self.gpu_bvh(frusta, leaves, camera.eye)

    @staticmethod
    def _sky_lighting(lighting: FrameLighting, gpu, settings: RaycastSettings, view: FrameView, repeats,
                      model_box) -> FrameLighting:
        """``lighting`` with the sky light's BVH defines and uniforms (its rays' march, the
        pixel footprint, the reach in the model's size) when ``gpu`` is given."""
        if gpu is None:
            return lighting
        size = float(np.linalg.norm(np.subtract(*model_box))) if model_box is not None else 1.0
        march = {k: v for k, v in settings.march_uniforms().items() if k != "hull_padding"}
        sky = {**settings.look.sky_uniforms(size), **march, "texture_repeat": repeats,
               "pixel_footprint": view.pixel_footprint()}
        return replace(lighting, bvh_defines=gpu.defines(), sky=sky)

    def _programs(self, settings: RaycastSettings, shadows, ground: bool, count_work: bool = False,
                  flat_background: bool = False, leaves: bool = False, bvh_defines: dict | None = None,
                  thin_rows: bool = False) -> dict:
        """Build every program the frame uses (plantgen.gl.passes.program_variants) and
        record them in :attr:`programs_used`. Returns the frusta program for the eye
        (``frame``), the light's pass (``light``, None without shadows) and the list of
        (file, defines switched on) built. ``bvh_defines``: those of the sky light's BVH;
        ``thin_rows``: the frusta cast with THIN_COVERAGE (coverage anti-aliasing), whose
        pass of thin rows is drawn by ``thin`` (the THIN_RIBBON variant with
        :attr:`thin_ribbons`, else the frame's program; None without ``thin_rows``)."""
        variants = program_variants(settings, shadows, ground, flat_background, leaves, bvh_defines)
        built = [(name, tuple(sorted(k for k, v in d.items() if v))) for name, d in variants]
        self.programs_used.update(built)
        for name, defines in variants:
            build_program(self.ctx, name, defines)
        shadowed = shadows is not None
        looks = {} if settings.labels else traced_look(settings.look, "raycast.glsl", shadowed, bvh_defines)
        defines = {**settings.defines(), "SHADOWS": shadowed, "STATS": count_work, **looks, "THIN_COVERAGE": thin_rows}
        frame = build_program(self.ctx, "raycast.glsl", defines)
        thin = None
        if thin_rows:
            ribbon = self.thin_ribbons and settings.proxy != "screen"
            thin = build_program(self.ctx, "raycast.glsl", {**defines, "THIN_RIBBON": True}) if ribbon else frame
        light = build_program(self.ctx, *light_program(settings, shadows)) if shadowed else None
        return {"frame": frame, "thin": thin, "light": light, "built": built}

    def _instances(self, program, rec_buf, *, indexed: bool = True, ribbon: bool = False):
        """The vertex array drawing one pyramid per record of ``rec_buf`` (with ``ribbon``:
        one screen quad, :data:`RIBBON_TRIANGLES`)."""
        ibo = self._ribbon_ibo if ribbon else self._template_ibo
        return self.ctx.vertex_array(
            program, [(self._template_vbo, "3f", "corner"), (rec_buf, RECORD_LAYOUT, *RECORD_ATTRIBUTES)],
            index_buffer=ibo if indexed else None, index_element_size=4)

    def _frusta_draw(self, program, view: FrameView, lighting: FrameLighting,
                     settings: RaycastSettings, rec_buf, repeats, tex, n: int, lod_pixels: float = 0.0,
                     thin_rows: bool = False, *, ribbon: bool = False):
        """Set the eye's frusta program and return (draw callable, vertex arrays to release,
        rows drawn). ``rec_buf``: the records' buffer, or a PlacedPlants drawn copy by copy
        (:mod:`plantgen.gl.instanced`) with ``lod_pixels``; ``thin_rows``: coverage
        anti-aliasing's floor radius is set, and the draw is its pass 0 (the rows at or
        above the floor; :func:`~plantgen.gl.coverage.coverage_pass` draws the rest, by
        this draw or, with ``ribbon``, by this one of ``program``, the THIN_RIBBON variant:
        one screen quad a row, no face culled)."""
        sky = {k: v for k, v in lighting.sky.items() if k.startswith("sky_")}   # the rest: set below
        set_uniforms(program, **view.ray_uniforms(), **lighting.shading, **lighting.receiver, **sky,
                     **settings.march_uniforms(), **IDENTITY_PLACEMENT, texture_repeat=repeats,
                     pixel_footprint=view.pixel_footprint(),
                     view_projection=mat4(view.view_projection),
                     depth_coeffs=(view.projection[2, 2], view.projection[2, 3]))
        if thin_rows:
            set_uniforms(program, coverage_floor=view.floor_radius(), coverage_pass=0,
                         coverage_exponent=AA_ALPHA_EXPONENT, **({"ribbon_near": view.near} if ribbon else {}))
        if not n:
            return (lambda: None), [], 0
        ctx = self.ctx
        screen_proxy = settings.proxy == "screen"
        placed = rec_buf if isinstance(rec_buf, PlacedPlants) else None
        buffers = self.placed_buffers(placed) if placed is not None else [rec_buf]
        vaos = [self._instances(program, buf, indexed=not screen_proxy, ribbon=ribbon) for buf in buffers]
        plan = eye_copy_draws(placed, view, lod_pixels) if placed is not None else None

        def render(vao, count):
            if screen_proxy:
                vao.render(mode=ctx.TRIANGLES, vertices=3, instances=count)
            else:
                vao.render(mode=ctx.TRIANGLES, vertices=RIBBON_TRIANGLES.size if ribbon else PYRAMID_VERTICES,
                           instances=count)

        def draw():
            tex.use(0)
            if ribbon:
                ctx.enable(ctx.DEPTH_TEST)
                ctx.disable(ctx.CULL_FACE)      # a quad: whichever way it winds
            elif not screen_proxy:
                ctx.enable(ctx.DEPTH_TEST | ctx.CULL_FACE)
                ctx.front_face = "ccw"
                ctx.cull_face = "front"   # back faces: an eye inside a pyramid still sees it
            _draw_rows(program, vaos, plan, render, n)
        return draw, vaos, (n if plan is None else sum(c.rows for c in plan))

    def _light_pass(self, frusta, caster, lighting: FrameLighting, settings: RaycastSettings,
                    shadows: ShadowSettings, material_names: tuple, record_buffer, surroundings,
                    lod_pixels: float = 0.0) -> LightPass:
        """The frusta's part of the light's pass: the :class:`ShadowKey` of the map (the
        light program's defines and knobs, the materials, the frusta and
        ``surroundings`` = (leaves or None, ground), the map's size, anchor and window; no
        key for a caller's ``record_buffer``, whose contents the renderer cannot vouch for),
        and the draws, made only when the map is drawn: orthographic rays along the light,
        the analytic (or relief) hit's depth into the map. A PlacedPlants is drawn copy by
        copy relative to the anchor, ``lod_pixels`` counted in the map's texels (the key
        holds it: the map does not depend on the eye)."""
        if shadows.caster == "mesh":
            return self._mesh_light_pass(frusta, caster, lighting, settings, shadows, material_names, record_buffer,
                                         surroundings)
        defines = light_defines(settings, shadows)
        knobs = (settings.hull_padding, settings.linear_steps, settings.march_min_steps, settings.binary_steps,
                 shadows.march_density, shadows.march_precision) if defines["RELIEF"] else (settings.hull_padding,)
        leaves, ground = surroundings
        key = None if record_buffer is not None else ShadowKey(
            ("raycast.glsl", tuple(sorted(defines.items())), knobs, material_names, float(lod_pixels)),
            (frusta, leaves), ground,
            shadows.resolution, lighting.anchor, lighting.caster_window)

        def draws():
            n = len(frusta)
            if not n:
                return [], []
            if isinstance(frusta, PlacedPlants):
                return self._frusta_light_draw(caster, defines, lighting, settings, shadows, frusta,
                                               material_names, n, None, lod_pixels)
            own = None if record_buffer is not None else self.ctx.buffer(
                pack_records(frusta, lighting.anchor).tobytes())
            return self._frusta_light_draw(caster, defines, lighting, settings, shadows,
                                           own if own is not None else record_buffer, material_names, n, own)
        return LightPass(key, draws)

    def _mesh_light_pass(self, frusta, caster, lighting: FrameLighting, settings: RaycastSettings,
                         shadows: ShadowSettings, material_names: tuple, record_buffer, surroundings) -> LightPass:
        """The frusta's part of the light's pass with the mesh caster (``--shadow-caster
        mesh``): the frusta tessellated at ``shadows.mesh_level`` (displaced with relief
        on), built once (:meth:`caster_mesh`), their front faces rasterised into the map
        (``raster.glsl``'s SHADOW_PASS, as GS+R's light pass). Still frusta drawn merged only:
        an animation's frames (records the caller streams) or a scene drawn instanced are
        refused in one line (the viewer casts those with the march and says so)."""
        if isinstance(frusta, PlacedPlants) or record_buffer is not None:
            what = "a scene drawn instanced (lod)" if isinstance(frusta, PlacedPlants) else "an animation's frames"
            raise PlantgenError(f"--shadow-caster mesh casts still frusta, not {what}: use --shadow-caster relief")
        relief = bool(settings.relief)
        leaves, ground = surroundings
        key = ShadowKey(("raster.glsl", "mesh", shadows.mesh_level, relief, material_names), (frusta, leaves), ground,
                        shadows.resolution, lighting.anchor, lighting.caster_window)

        def draws():
            if not len(frusta):
                return [], []
            origin, vbo, ibo, indices = self.caster_mesh(frusta, shadows.mesh_level, relief)
            return self._mesh_light_draw(caster, lighting, origin, [(vbo, "3f", "position")], ibo, indices)
        return LightPass(key, draws)

    def _frusta_light_draw(self, caster, defines: dict, lighting: FrameLighting, settings: RaycastSettings,
                           shadows: ShadowSettings, rec_buf, material_names, n: int, own_buffer,
                           lod_pixels: float = 0.0):
        """Set the light's frusta program (its window relative to the light's anchor) and
        return ([draw callable], [GL objects to release after the frame]); ``rec_buf`` a
        buffer of records, or a PlacedPlants drawn copy by copy."""
        window = lighting.caster_window
        tex, repeats = self._heights.get(material_names)
        march = {**settings.march_uniforms(), "march_density": shadows.march_density,
                 "march_precision": shadows.march_precision}
        secant = defines["RELIEF"] and not defines["LIGHT_BISECT"]     # shaders/light_march.glsl
        corners = self._heights.corners(material_names) if secant else None
        band = {"height_corners": 2, "height_range": self._heights.ranges(material_names)} if secant else {}
        texel = window.texel_size(shadows.resolution)
        set_uniforms(caster, **window.uniforms(), **march, **band, **IDENTITY_PLACEMENT,
                     viewport=(float(shadows.resolution),) * 2, texture_repeat=repeats,
                     pixel_footprint=(0.0, texel), view_projection=mat4(window.matrix()))
        placed = rec_buf if isinstance(rec_buf, PlacedPlants) else None
        vaos = [self._instances(caster, buf) for buf in (self.placed_buffers(placed) if placed else [rec_buf])]
        plan = light_copy_draws(placed, lighting.anchor, texel, lod_pixels) if placed else None
        ctx = self.ctx

        def render(vao, count):
            vao.render(mode=ctx.TRIANGLES, vertices=PYRAMID_VERTICES, instances=count)

        def draw():
            tex.use(0)
            if corners is not None:
                corners.use(2)
            ctx.enable(ctx.CULL_FACE)
            ctx.front_face = "ccw"
            ctx.cull_face = "front"
            _draw_rows(caster, vaos, plan, render, n)
        return [draw], [*vaos, own_buffer]


def _draw_rows(program, vaos, plan, render, n: int) -> None:
    """Draw the rows, the eye's or the light's: all ``n`` from one vertex array (``plan``
    None), or a placed scene plant by plant and copy by copy (each copy's placement set in
    ``program``, the identity again after), ``render(vao, count)`` drawing ``count`` rows."""
    if plan is None:
        render(vaos[0], n)
        return
    for vao, copies in zip(vaos, plan, strict=True):
        draw_copies(program, vao, copies, render)
    set_uniforms(program, **IDENTITY_PLACEMENT)


_default_raycaster: Raycaster | None = None


def _checked_labels(values, count: int, what: str) -> np.ndarray:
    """``values`` as an array of ``count`` labels in 1..255, else one line: ``what`` a value."""
    values = np.asarray(values)
    if len(values) != count or (len(values) and (values.min() < 1 or values.max() > 255)):
        raise PlantgenError(f"{what} a value in 1..255")
    return values


def label_image(caster: Raycaster, frusta, camera: Camera, labels, settings: RaycastSettings | None = None, *,
                leaves=None, leaf_labels=None):
    """(height, width) uint8: the label (``labels`` (rows,) in 1..255) of the row each pixel
    of ``camera`` sees, 0 where it sees nothing; the same hits as the colour render. With
    ``leaves`` (a Polygons), a pixel that sees a leaf gets its ``leaf_labels`` (p,) value."""
    labels = _checked_labels(labels, len(frusta), "labels must give every row")
    if leaves is not None:
        leaf_labels = _checked_labels(leaf_labels, len(leaves), "leaf labels must give every leaf polygon")
    tagged = Frusta.from_rows({f: getattr(frusta, f) for f in ROW_FIELDS} | {"material": labels.astype(np.int32)},
                              frusta.material_names, frusta.parent_row, frusta.open_lo, frusta.open_hi)
    base = settings or RaycastSettings()
    result = caster.render(tagged, camera, replace(base, labels=True), frusta.material_names, leaves=leaves,
                           leaf_labels=leaf_labels)
    return np.where(np.isfinite(result.distance), result.color[..., 0], 0).astype(np.uint8)


def render_frusta(frusta, camera: Camera, settings: RaycastSettings = RaycastSettings(),
                  material_names=("bark",)) -> RenderResult:
    """Render with the shared context's cached :class:`Raycaster`."""
    global _default_raycaster
    ctx = gl_context()
    if _default_raycaster is None or _default_raycaster.ctx is not ctx:
        _default_raycaster = Raycaster(ctx)
    return _default_raycaster.render(frusta, camera, settings, material_names)
