"""The offscreen frame every renderer draws into, and what every frame shares.

:class:`OffscreenRenderer` owns the GL context's offscreen framebuffer (colour RGBA8 +
float32 distance + depth, resized on demand), the relief height textures, the sky, the
ground square and the light's shadow map. A renderer (:class:`~plantgen.gl.raycast.
Raycaster`, :class:`~plantgen.gl.raster.RasterRenderer`) prepares its programs and
its model's draw, then :meth:`OffscreenRenderer._draw_frame` runs the passes in order
(shadow map, ground, sky, model) and :meth:`OffscreenRenderer._read_back` returns the
image and the distances.

The shadow map is paid once: the light's pass is drawn relative to its own origin (the
*anchor*: the centre of the casters' box), never the eye's, and each renderer names what
its map depends on in a :class:`ShadowKey`; a frame whose key matches a kept map
(:class:`~plantgen.gl.passes.ShadowPass`) samples that map and draws no light pass.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..geometry.rays.camera import Camera, depth_range
from ..geometry.skeletons.materials import MAX_MATERIALS
from ..geometry.stage import MODEL_LIGHT, Ground
from ..settings import AA_CHOICES, AA_FLOOR_PIXELS, MAX_SSAA, ShadowSettings
from .context import gl_context, release_framebuffer
from .instanced import IDENTITY_TURN
from .leaf_layer import LeafLayer
from .material_uniforms import HeightTextures, ground_uniforms, palette_uniforms, shading_uniforms
from .passes import LightWindow, ShadowPass, light_window, traced_look
from .result import WorkCounter
from .shaders import build_program, mat4, set_uniforms
from .supersample import GpuResolve

__all__ = ["OffscreenRenderer", "FrameView", "frame_view", "FrameLighting", "Surroundings", "ShadowKey", "LightPass",
           "light_anchor", "check_background", "check_ssaa", "coverage_aa"]


def check_background(background) -> tuple | None:
    """``background`` as the frame takes it: None (the sky) or (r, g, b, a) floats in
    [0, 1], display-encoded; a = 0 makes the background transparent (the image gets an
    alpha channel: coverage)."""
    if background is None:
        return None
    values = tuple(float(v) for v in background)
    if len(values) != 4 or not all(0.0 <= v <= 1.0 for v in values):
        raise ValueError(f"background must be (r, g, b, a) in [0, 1], got {background!r}")
    return values


def check_ssaa(ssaa) -> int:
    """The supersampling factor as an int in 1..MAX_SSAA."""
    n = int(ssaa)
    if n != ssaa or not 1 <= n <= MAX_SSAA:
        raise ValueError(f"ssaa must be an integer in 1..{MAX_SSAA}, got {ssaa!r}")
    return n


def coverage_aa(aa: str, ssaa: int = 1, labels: bool = False, background=None) -> bool:
    """Whether a frame draws with coverage anti-aliasing: ``aa`` is ``"coverage"`` or
    ``"edges"`` (of :data:`~plantgen.settings.AA_CHOICES`; ``"none"``: one ray a pixel), at
    one sample a side (supersampling replaces it), in colour (a part mask's labels are never
    mixed) and over an opaque background (a transparent one has no colour to blend a thin
    row with). With ``"edges"`` the frame then goes through the edge pass."""
    if aa not in AA_CHOICES:
        raise ValueError(f"aa must be one of {', '.join(AA_CHOICES)}, got {aa!r}")
    return aa != "none" and ssaa == 1 and not labels and (background is None or background[3] >= 1)


@dataclass(frozen=True)
class FrameView:
    """The camera of one frame, relative to the render origin (the eye).

    eye : (3,) float64 world position (the render origin); right, up, forward : (3,) unit
    basis; near, far : depth range; projection : (4, 4) float64; view_projection : (4, 4)
    float64, eye-relative world -> clip.
    """

    camera: Camera
    eye: np.ndarray
    right: np.ndarray
    up: np.ndarray
    forward: np.ndarray
    near: float
    far: float
    projection: np.ndarray
    view_projection: np.ndarray

    def ray_uniforms(self) -> dict:
        """Uniforms that rebuild each pixel's ray (sky.glsl, raycast.glsl)."""
        tan_y = np.tan(np.radians(self.camera.fov_y) / 2)
        tan_x = tan_y * self.camera.aspect
        return {"viewport": (float(self.camera.width), float(self.camera.height)),
                "cam_forward": tuple(self.forward), "cam_right_scaled": tuple(self.right * tan_x),
                "cam_up_scaled": tuple(self.up * tan_y)}


    def pixel_footprint(self) -> tuple[float, float]:
        """(a, b): a pixel near the image centre spans about a*s + b world units at
        distance s from the eye (the adaptive relief march's footprint)."""
        return (float(2.0 * np.tan(np.radians(self.camera.fov_y) / 2) / self.camera.height), 0.0)

    def floor_radius(self) -> float:
        """Coverage anti-aliasing's floor radius per unit of distance from the eye: half of
        :data:`~plantgen.settings.AA_FLOOR_PIXELS` pixels."""
        return 0.5 * AA_FLOOR_PIXELS * self.pixel_footprint()[0]


def frame_view(camera: Camera, point_sets) -> FrameView:
    """The :class:`FrameView` whose depth range encloses every (k, 3) array of world points
    in ``point_sets`` (see :func:`plantgen.geometry.rays.camera.depth_range`)."""
    eye = np.asarray(camera.eye, dtype=np.float64)
    right, up, fwd = camera.basis()
    near, far = depth_range(point_sets, eye, fwd)
    view = camera.view_matrix()
    view[:3, 3] = 0.0  # the render origin is the eye
    projection = camera.projection_matrix(near, far)
    return FrameView(camera, eye, right, up, fwd, near, far, projection, projection @ view)


@dataclass(frozen=True)
class Surroundings:
    """What a frame draws besides the model: callables drawn before it (the ground) and
    after it (the leaves), into the light's map (``light``), GL objects to release once
    the frame is drawn, and coverage anti-aliasing's blended passes of thin pieces
    (``thin``), drawn after everything opaque (:mod:`~plantgen.gl.coverage`)."""

    before: list
    after: list
    light: list
    garbage: list
    thin: list = field(default_factory=list)


@dataclass(frozen=True)
class FrameLighting:
    """The light and materials of one frame.

    names : material slot names of the model, plus the ground's material when there is one
    shading : uniforms of shaders/shading.glsl (light, ambient, sky) and the palette
    window : the light's window as the eye's receivers see it (relative to the eye; None
        without shadows)
    receiver : uniforms of shaders/shadow.glsl for surfaces that sample the map ({} without)
    anchor : (3,) float64 world origin of the light's pass (None without shadows): the
        casters are drawn into the map relative to it, so the map does not depend on the eye
    caster_window : the light's window relative to ``anchor`` (the light pass's)
    receiver_defines : defines of the receivers' programs besides ``SHADOWS``: with shadow
        rays instead of a map (``SHADOW_RAYS``, render --method rt, :mod:`plantgen.gl.rt`)
        those of the BVH they trace; then ``window`` is None and no map is drawn
    look : the looks (:class:`~plantgen.settings.LookSettings`; None: none, today's
        shading), their defines by program :func:`~plantgen.gl.passes.traced_look`
    bvh_defines : with the sky light, the defines of the BVH its rays trace
    sky : with the sky light, the uniforms of the programs that trace it (the leaves')
    """

    names: tuple
    shading: dict
    window: LightWindow | None
    receiver: dict
    anchor: np.ndarray | None = None
    caster_window: LightWindow | None = None
    receiver_defines: dict = field(default_factory=dict)
    look: object = None
    bvh_defines: dict = field(default_factory=dict)
    sky: dict = field(default_factory=dict)

    def defines(self, program: str) -> dict:
        """The looks' defines of ``program`` in this frame (:func:`traced_look`)."""
        return traced_look(self.look, program, self.shadowed, self.bvh_defines)

    @property
    def srgb(self) -> bool:
        """Whether the frame is encoded with the tone curve and sRGB (else c^(1/2.2))."""
        return self.look is not None and self.look.tone

    @property
    def shadowed(self) -> bool:
        """Whether receivers are shadowed (by the map or by shadow rays)."""
        return self.window is not None or bool(self.receiver_defines.get("SHADOW_RAYS"))

    @property
    def ground_material(self) -> int:
        """The ground's palette slot (the last name)."""
        return min(len(self.names) - 1, MAX_MATERIALS - 1)


def light_anchor(caster_box) -> np.ndarray:
    """The light pass's origin for casters in ``caster_box`` (2, 3): the box's centre, a
    world point that depends on the casters alone (not on the eye)."""
    box = np.asarray(caster_box, dtype=np.float64)
    return 0.5 * (box[0] + box[1])


class ShadowKey:
    """Everything the light's depth map depends on, and nothing else (not the eye).

    caster : values: the renderer's light program (its defines), the relief knobs that
        shape the caster (march, density, precision, steps), the material list (height
        maps), the frusta's hull padding
    objects : the geometry drawn into the map, compared by identity: the Frusta (or the
        tessellated mesh) and the leaves (a Polygons or None). These are frozen values,
        built once and never written: a moving frame brings new objects, so its map is
        drawn again. (Records a caller packed and may rewrite in place are no such value:
        a frame drawn from them has no key, and draws its map every time.)
    ground : the ground (a frozen value, compared by value) or None
    resolution : texels per side
    anchor : the light pass's origin (world)
    window : the light's window relative to the anchor (its direction, extent and depth
        range: the light direction and the casters' box)
    """

    __slots__ = ("caster", "objects", "ground", "resolution", "anchor", "window")

    def __init__(self, caster: tuple, objects: tuple, ground, resolution: int, anchor, window: LightWindow):
        self.caster = tuple(caster)
        self.objects = tuple(objects)
        self.ground = ground
        self.resolution = int(resolution)
        self.anchor = tuple(float(x) for x in anchor)
        self.window = window.values()

    def __eq__(self, other) -> bool:
        return (isinstance(other, ShadowKey) and self.caster == other.caster and self.ground == other.ground
                and self.resolution == other.resolution and self.anchor == other.anchor
                and self.window == other.window and len(self.objects) == len(other.objects)
                and all(a is b for a, b in zip(self.objects, other.objects, strict=True)))

    __hash__ = None     # compared, never hashed: the objects count by identity


@dataclass(frozen=True)
class LightPass:
    """A renderer's part of the light's pass for one frame: its :class:`ShadowKey` (None:
    the map cannot be kept, it is drawn every frame), and ``draws()`` returning (draw
    callables, GL objects to release after the frame), called only when the map must be
    drawn (nothing is packed, uploaded or bound for a reused map)."""

    key: ShadowKey | None
    draws: Callable[[], tuple]


@dataclass(frozen=True)
class FrameOutput:
    """What a drawn frame gives back: the colour and distance images, the frame's and the
    shadow pass's milliseconds (0 when the map was reused: ``shadow_cached``), and the work
    counted (None unless asked)."""

    color: np.ndarray
    distance: np.ndarray
    frame_ms: float
    shadow_ms: float
    work: object = None
    shadow_cached: bool = False


class OffscreenRenderer:
    """What every plantgen renderer shares: the GL context, an offscreen framebuffer
    (colour RGBA8 + float32 distance + depth) resized on demand, the relief height maps
    uploaded once per material list, and the scene's extras: the ground square and the
    light's shadow map (plantgen.gl.passes), drawn the same way for RC and GS."""

    def __init__(self, ctx=None):
        self.ctx = ctx if ctx is not None else gl_context()
        self._fbo = None
        self._fbo_size = None
        self._heights = HeightTextures(self.ctx)
        self._shadow = ShadowPass(self.ctx)
        self._leaves = LeafLayer(self.ctx)
        self._sky_vao = None
        self._resolver = GpuResolve(self.ctx)
        self.last_light_window = None
        self.last_resolve_ms = 0.0

    def _mesh_light_draw(self, caster, lighting: FrameLighting, origin, attributes, index_buffer, indices: int,
                         before: Callable[[], None] | None = None):
        """A mesh's front faces into the light's depth map (``caster``: ``raster.glsl``'s
        SHADOW_PASS), its positions relative to ``origin`` drawn relative to the light's
        anchor; ``before`` runs ahead of each draw (a skinned mesh binds its poses):
        ([draw callable], [vertex array to release after the frame])."""
        ctx = self.ctx
        set_uniforms(caster, view_projection=mat4(lighting.caster_window.matrix()), **IDENTITY_TURN,
                     origin_from_eye=tuple((origin - lighting.anchor).tolist()))
        vao = ctx.vertex_array(caster, attributes, index_buffer=index_buffer, index_element_size=4)

        def draw():
            ctx.enable(ctx.CULL_FACE)
            ctx.front_face = "ccw"
            ctx.cull_face = "back"
            if before is not None:
                before()
            vao.render(mode=ctx.TRIANGLES, vertices=indices)
        return [draw], [vao]

    def release(self) -> None:
        """Free the framebuffer, the height textures and the shadow map (they are made
        again on the next render)."""
        if self._fbo is not None:
            release_framebuffer(self._fbo)
        self._fbo = self._fbo_size = None
        self._resolver.release()
        self._heights.release()
        self._shadow.release()
        self._leaves.release()

    def shadow_depths(self) -> np.ndarray:
        """(res, res) float32 light depth map of the last shadowed render, (z - near) /
        (far - near) in :attr:`last_light_window`, row 0 the window's bottom; 1: empty."""
        return self._shadow.depths()

    def forget_shadow_maps(self) -> None:
        """Draw the next frame's shadow map again even if a kept map fits it (the maps stay
        allocated)."""
        self._shadow.forget()

    # ------------------------------------------------------------------ frame set-up
    def _lighting(self, material_names, ground: Ground | None, light_dir, shadows, caster_box,
                  eye, anchor=None, look=None) -> FrameLighting:
        """The frame's palette and light: ``light_dir`` (3,) towards the light (None: the
        model light); with ``shadows``, the light's window around ``caster_box`` (2, 3)
        world box, relative to the light pass's ``anchor`` (default :func:`light_anchor`
        of the box) and, for the receivers, to ``eye``; ``look`` the looks (a
        :class:`~plantgen.settings.LookSettings` or None)."""
        if light_dir is None:
            light_dir = MODEL_LIGHT.towards()
        names = tuple(material_names) + ((ground.material,) if ground is not None else ())
        bounce = look is not None and look.bounce and ground is not None
        shading = {**shading_uniforms(light_dir), **palette_uniforms(names),
                   **(look.shading_uniforms() if look is not None else {}),
                   **ground_uniforms(ground if bounce else None, light_dir, eye)}
        if shadows is None:
            return FrameLighting(names, shading, None, {}, look=look)
        anchor = light_anchor(caster_box) if anchor is None else np.asarray(anchor, dtype=np.float64)
        caster_window = light_window(caster_box, -np.asarray(light_dir, dtype=np.float64), anchor)
        window = caster_window.shifted(anchor - np.asarray(eye, dtype=np.float64))
        self.last_light_window = window
        receiver = dict(window.uniforms(), shadow_bias=shadows.bias * window.texel_size(shadows.resolution),
                        shadow_max_slope=shadows.max_slope, shadow_map=1,
                        **(look.sun_uniforms() if look is not None and look.sun_angle > 0 else {}))
        return FrameLighting(names, shading, window, receiver, anchor, caster_window, look=look)

    def _sky(self, view: FrameView, lighting: FrameLighting, background=None):
        """The background's full-screen triangle (vertex array cached per program): the sky,
        or with ``background`` (r, g, b, a) a flat colour (see :func:`check_background`)."""
        if background is None:
            sky = build_program(self.ctx, "sky.glsl", lighting.defines("sky.glsl"))
            set_uniforms(sky, **view.ray_uniforms(), **lighting.shading)
        else:
            sky = build_program(self.ctx, "sky.glsl", {"FLAT_BACKGROUND": True})
            set_uniforms(sky, background=tuple(background))
        if self._sky_vao is None or self._sky_vao.program is not sky:
            self._sky_vao = self.ctx.vertex_array(sky, [])
        return self._sky_vao

    def _ground_draws(self, ground: Ground, view: FrameView, lighting: FrameLighting, background=None):
        """Draws of the ground (its square; a disc is cut out of it): a callable drawing it
        into the frame and, with a light window, one drawing it into the light's map
        (relative to the light's anchor; for :meth:`_draw_frame`). It fades at its edge
        into the sky, or into ``background`` (r, g, b, a) where the frame's is flat.

        Returns (frame draw, light draw or None, [objects to release after the frame]).
        """
        ctx = self.ctx
        shadowed = lighting.window is not None
        looks = lighting.defines("ground.glsl")
        program = build_program(ctx, "ground.glsl", {"SHADOWS": lighting.shadowed, **lighting.receiver_defines,
                                                     **looks, "FLAT_BACKGROUND": background is not None})
        shading = {**lighting.shading, **lighting.receiver, **(lighting.sky if looks.get("SKY_LIGHT") else {})}
        set_uniforms(program, **shading, **ground.uniforms(),
                     **({} if background is None else {"background": tuple(background)}),
                     view_projection=mat4(view.view_projection),
                     ground_material=lighting.ground_material, origin_offset=tuple(view.eye))
        buf = ctx.buffer((ground.quad() - view.eye).astype(np.float32).tobytes())
        vao = ctx.vertex_array(program, [(buf, "3f", "position")])
        light_vao = light_buf = light_draw = None
        if shadowed:
            caster = build_program(ctx, "ground.glsl", {"SHADOW_PASS": True})
            set_uniforms(caster, view_projection=mat4(lighting.caster_window.matrix()))
            light_buf = ctx.buffer((ground.quad() - lighting.anchor).astype(np.float32).tobytes())
            light_vao = ctx.vertex_array(caster, [(light_buf, "3f", "position")])

            def light_draw():
                ctx.disable(ctx.CULL_FACE)
                light_vao.render(mode=ctx.TRIANGLE_STRIP, vertices=4)

        def frame_draw():
            ctx.disable(ctx.CULL_FACE)
            vao.render(mode=ctx.TRIANGLE_STRIP, vertices=4)
        return frame_draw, light_draw, [vao, light_vao, buf, light_buf]

    def _surroundings(self, ground: Ground | None, leaves, view: FrameView, lighting: FrameLighting,
                      *, labels=None, background=None, coverage_floor: float = 0.0) -> Surroundings:
        """The frame's draws besides the model's own: the ground (fading into ``background``
        where it is flat) and the leaves (``leaves``: a Polygons or None; ``labels`` (p,):
        draw them as a part mask; ``coverage_floor``: coverage anti-aliasing's floor
        radius a unit of distance, the thin leaves' pass in ``thin``,
        :meth:`~plantgen.gl.leaf_layer.LeafLayer.draws`)."""
        out = Surroundings([], [], [], [])
        if ground is not None:
            draw, light_draw, garbage = self._ground_draws(ground, view, lighting, background)
            out.before.append(draw)
            out.light.append(light_draw)
            out.garbage.extend(garbage)
        if leaves is not None and len(leaves.triangles):
            draw, light_draw, garbage, thin = self._leaves.draws(leaves, view, lighting, labels=labels,
                                                                 coverage_floor=coverage_floor)
            out.after.append(draw)
            out.thin.extend([thin] if thin is not None else [])
            out.light.append(light_draw)
            out.garbage.extend(garbage)
        out.light[:] = [d for d in out.light if d is not None]
        return out

    def _framebuffer(self, width: int, height: int):
        if self._fbo_size != (width, height):
            if self._fbo is not None:
                release_framebuffer(self._fbo)
            ctx = self.ctx
            # textures, not renderbuffers: supersampling's resolve samples them (GpuResolve)
            self._fbo = ctx.framebuffer(
                color_attachments=[ctx.texture((width, height), 4), ctx.texture((width, height), 1, dtype="f4")],
                depth_attachment=ctx.depth_renderbuffer((width, height)))
            self._fbo_size = (width, height)
        return self._fbo

    # ------------------------------------------------------------------ the frame
    def _draw_shadow_map(self, shadows: ShadowSettings, light: LightPass, extra_draws) -> tuple[float, bool]:
        """The light's depth map for ``light.key``: a kept map when one fits (with
        ``shadows.cache``), else cleared and drawn (``light.draws()``, then each callable
        of ``extra_draws``) with the depth test on. The map is bound to texture unit 1 for
        the receivers. Returns (milliseconds of the pass to glFinish, 0 for a kept map;
        whether the map was kept)."""
        ctx = self.ctx
        if shadows.cache and light.key is not None and self._shadow.find(light.key) is not None:
            self._shadow.texture.use(1)
            return 0.0, True
        t0 = time.perf_counter()
        resolution = shadows.resolution
        fbo = self._shadow.target(light.key, resolution)
        fbo.use()
        fbo.viewport = (0, 0, resolution, resolution)
        fbo.clear(depth=1.0)
        ctx.enable(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        draws, garbage = light.draws()
        for draw in (*draws, *extra_draws):
            draw()
        ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)
        ctx.finish()
        self._shadow.texture.use(1)
        for obj in garbage:
            if obj is not None:
                obj.release()
        return (time.perf_counter() - t0) * 1e3, False

    def _draw_frame(self, view: FrameView, sky_vao, draw_model: Callable[[], None],
                    shadows: ShadowSettings | None, light: LightPass | None,
                    extras: Surroundings) -> tuple[float, float, bool]:
        """Run one frame's passes in order: the shadow map (with ``shadows``: drawn by
        ``light`` and the light draws of ``extras``, or reused, :meth:`_draw_shadow_map`),
        the ground (``extras.before``), the sky where nothing covers the far plane, the
        model (``draw_model()``) and the leaves (``extras.after``), depth tested.

        Returns (frame_ms, shadow_ms, shadow_cached): wall milliseconds from the first pass
        to glFinish, those of the shadow pass alone (0 for a reused map), and whether the
        map was reused.
        """
        ctx = self.ctx
        width, height = view.camera.width, view.camera.height
        fbo = self._framebuffer(width, height)
        ctx.finish()
        t_draw = time.perf_counter()
        shadow_ms, cached = (self._draw_shadow_map(shadows, light, extras.light)
                             if shadows is not None and light is not None else (0.0, False))
        fbo.use()
        fbo.viewport = (0, 0, width, height)
        fbo.clear(depth=1.0)
        ctx.disable(ctx.CULL_FACE | ctx.BLEND)
        ctx.enable(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        for draw in extras.before:
            draw()
        # the sky after the ground, at the far plane: the depth test skips the sky's
        # fragments the ground covers before they are shaded
        ctx.depth_func = "<="
        sky_vao.render(mode=ctx.TRIANGLES, vertices=3)
        ctx.depth_func = "<"
        for draw in (draw_model, *extras.after, *extras.thin):
            draw()
        ctx.finish()
        frame_ms = (time.perf_counter() - t_draw) * 1e3
        ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)
        for obj in extras.garbage:
            if obj is not None:
                obj.release()
        return frame_ms, shadow_ms, cached

    def _finish_frame(self, camera: Camera, view: FrameView, lighting: FrameLighting, background, draw_model,
                      shadows: ShadowSettings | None, light: LightPass | None, extras: Surroundings, *, ssaa: int,
                      count_work: bool, smooth: bool = False) -> FrameOutput:
        """The frame's tail, the same for both renderers: count the work if asked, run the
        passes (:meth:`_draw_frame`; ``light`` the renderer's part of the light's pass),
        read the frame back at ``camera``'s size (:meth:`_read_back`; ``smooth``: through
        coverage anti-aliasing's edge pass) and read the counters."""
        counter = WorkCounter(self.ctx) if count_work else None
        frame_ms, shadow_ms, cached = self._draw_frame(view, self._sky(view, lighting, background), draw_model,
                                                       shadows, light, extras)
        color, dist = self._read_back(camera.width, camera.height, ssaa=ssaa, smooth=smooth,
                                      alpha=background is not None and background[3] < 1, srgb=lighting.srgb)
        work = counter.read(dist) if counter is not None else None
        return FrameOutput(color, dist, frame_ms, shadow_ms, work, cached)

    def _read_back(self, width: int, height: int, *, ssaa: int = 1, smooth: bool = False,
                   alpha: bool = False, srgb: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """The frame's (height, width, 3) uint8 colour ((.., 4) with ``alpha``: coverage)
        and (height, width) float32 distance, row 0 the top row; a frame drawn with
        ``ssaa`` samples per side (``width`` x ``height`` being the final image's) is
        averaged down on the GPU first, in linear light (``srgb`` the frame's encoding;
        :class:`plantgen.gl.supersample.GpuResolve`; ``last_resolve_ms``: that pass and its
        read back); with ``smooth`` a frame of one ray a pixel goes through coverage
        anti-aliasing's edge pass the same way (:meth:`~plantgen.gl.supersample.GpuResolve.
        smooth_edges`)."""
        fbo = self._fbo
        self.last_resolve_ms = 0.0
        if ssaa > 1 or smooth:
            t0 = time.perf_counter()
            color, distance = fbo.color_attachments[0], fbo.color_attachments[1]
            out = (self._resolver.resolve(color, distance, width, height, ssaa, alpha, srgb=srgb) if ssaa > 1
                   else self._resolver.smooth_edges(color, distance, width, height, alpha))
            self.last_resolve_ms = (time.perf_counter() - t0) * 1e3
            return out
        k = 4 if alpha else 3
        color = np.frombuffer(fbo.read(components=k, attachment=0, alignment=1), np.uint8)
        dist = np.frombuffer(fbo.read(components=1, attachment=1, dtype="f4", alignment=1), np.float32)
        return color.reshape(height, width, k)[::-1].copy(), dist.reshape(height, width)[::-1].copy()

