"""The GLSL ray caster for conical frusta (RC) and relief-mapped frusta (RC+R).

Data path: :class:`plantgen.geometry.frusta.Frusta` (float64, world coordinates) ->
:func:`pack_records` (one 96-byte float32 record per segment, positions relative to the
camera eye so float32 keeps its digits far from the world origin) -> one instanced draw of
the 12-triangle bounding pyramid (built in the vertex shader from the record) -> the
fragment shader in ``shaders/raycast.glsl`` intersects the pixel's ray with the frustum
(``shaders/cone.glsl``), shades it and writes ``gl_FragDepth``.

Effects (plantgen.render.passes): with shadows a first pass ray casts the same records
along the light into a depth map that every surface then samples (``SHADOWS``); with
relief the relief shell is marched (``RELIEF``). Neither is compiled or run otherwise.
:func:`render_file` also writes animations (plantgen.render.animate).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import PlantgenError
from ..geometry.camera import Camera
from ..geometry.frusta import PYRAMID_CORNERS as _FRUSTA_CORNERS
from ..geometry.frusta import PYRAMID_TRIANGLES as _FRUSTA_TRIANGLES
from .context import gl_context, release_framebuffer
from .passes import (ShadowPass, ShadowSettings, box_corners, frame_passes, light_window,
                     program_variants)
from .shaders import build_program

__all__ = ["RaycastSettings", "RenderResult", "Raycaster", "pack_records", "RECORD_FLOATS",
           "RECORD_BYTES", "PYRAMID_CORNERS", "PYRAMID_TRIANGLES", "frusta_bounds",
           "material_palette", "render_frusta", "MAX_MATERIALS", "shading_uniforms",
           "height_maps_for", "render_file", "RenderReport", "auto_camera", "depth_range"]

#: float32 values in one segment's record: base, h, axis, r1, ref_dir, r2, plane_lo,
#: plane_hi, (u_offset, twist, shell, material).
RECORD_FLOATS = 24
RECORD_BYTES = 4 * RECORD_FLOATS
MAX_MATERIALS = 16  # shaders/shading.glsl MAX_MATERIALS


# The bounding pyramid's template (§2.6), shared with the CPU geometry: corner i is
# (sx, sz, end); 12 triangles wound counter-clockwise seen from outside.
PYRAMID_CORNERS = _FRUSTA_CORNERS.astype(np.float32)
PYRAMID_TRIANGLES = _FRUSTA_TRIANGLES.astype(np.int32)


def frusta_bounds(frusta) -> np.ndarray:
    """(2, 3) float64 axis-aligned box around every frustum, relief shells included.

    An oblique cutting plane cuts the cone in an ellipse that reaches past the axis end
    point (up to R / cos θ from it, θ the plane's tilt from the axis), so each end
    contributes a ball of that radius around where its plane crosses the axis.
    """
    if len(frusta.base) == 0:
        return np.zeros((2, 3))
    h = frusta.length
    k = (frusta.r2 - frusta.r1) / h
    slope = np.abs(k)
    centres, reach = [], []
    for plane, r_end, y_end in ((frusta.plane_lo, frusta.r1, 0.0), (frusta.plane_hi, frusta.r2, h)):
        normal, offset = plane[:, :3], plane[:, 3]
        cos_t = np.clip(np.einsum("ij,ij->i", normal, frusta.axis), 1e-3, 1.0)
        sin_t = np.sqrt(1.0 - cos_t ** 2)
        y_cross = (offset - np.einsum("ij,ij->i", normal, frusta.base)) / cos_t
        y_cross = np.where(np.isfinite(y_cross), y_cross, y_end)
        radius = np.maximum(frusta.r1 + k * y_cross, 0.0) + frusta.shell
        grow = 1.0 / np.maximum(cos_t - slope * sin_t, 0.05)
        centres.append(frusta.base + frusta.axis * y_cross[:, None])
        reach.append(np.maximum(radius, r_end + frusta.shell) * grow)
    pts = np.concatenate(centres)
    r = np.concatenate(reach)[:, None]
    return np.stack([(pts - r).min(axis=0), (pts + r).max(axis=0)])


def section_points(frusta, samples: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Points around the two plane sections of every frustum's outer (relief) surface.

    Returns
    -------
    points : (n, 2, samples, 3) float64, world units; [:, 0] on ``plane_lo``, [:, 1] on
        ``plane_hi``. The solid frustum is the convex hull of its two sections.
    slack : (n, 2, samples) float64, how far the true section may bulge past the polygon
        through the samples (its radius times 1/cos(π/samples) - 1), world units
    """
    phi = 2 * np.pi * np.arange(samples) / samples
    side = np.cross(frusta.ref_dir, frusta.axis)
    e = (np.cos(phi)[None, :, None] * frusta.ref_dir[:, None, :]
         + np.sin(phi)[None, :, None] * side[:, None, :])                  # (n, S, 3)
    k = ((frusta.r2 - frusta.r1) / frusta.length)[:, None]
    r_base = (frusta.r1 + frusta.shell)[:, None]
    out, slack = [], []
    for plane, y_end in ((frusta.plane_lo, 0.0), (frusta.plane_hi, frusta.length)):
        normal = plane[:, None, :3]
        gap = (plane[:, 3] - np.einsum("ij,ij->i", plane[:, :3], frusta.base))[:, None]
        n_e = np.sum(normal * e, axis=-1)
        rise = np.einsum("ij,ij->i", plane[:, :3], frusta.axis)[:, None] + k * n_e
        y = np.where(rise > 1e-9, (gap - r_base * n_e) / np.maximum(rise, 1e-9),
                     np.broadcast_to(np.asarray(y_end, dtype=np.float64).reshape(-1, 1), n_e.shape))
        ring = np.maximum(r_base + k * y, 0.0)
        out.append(frusta.base[:, None, :] + y[..., None] * frusta.axis[:, None, :] + ring[..., None] * e)
        slack.append(ring * (1 / np.cos(np.pi / samples) - 1))
    return np.stack(out, axis=1), np.stack(slack, axis=1)


def auto_camera(frusta, width: int = 1024, height: int = 768, *, fov_y: float = 40.0,
                direction=(0.35, 0.25, 1.0), fill: float = 0.9) -> Camera:
    """A camera looking from ``direction`` at the model, as close as it can be while every
    frustum stays inside ``fill`` of the viewport: the model spans most of the viewport
    (as the paper measured). Tighter than a bounding sphere for tall, thin plants.

    Parameters
    ----------
    frusta : Frusta, n rows (world units)
    direction : (3,) from the model towards the eye (not normalised)
    fill : fraction of the half-width and half-height the model may reach
    """
    box = frusta_bounds(frusta)
    if len(frusta.base) == 0:
        return Camera.auto(box, width, height, fov_y=fov_y, direction=direction, fill=fill)
    toward_eye = np.asarray(direction, dtype=np.float64)
    toward_eye /= np.linalg.norm(toward_eye)
    probe = Camera(tuple(toward_eye), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), fov_y, width, height)
    right, up, fwd = probe.basis()
    tan_y = np.tan(np.radians(fov_y) / 2) * fill
    tan_x = tan_y * width / height
    # the solid frustum is the convex hull of its two plane sections: sample them
    centres, radius = section_points(frusta)
    centres = centres.reshape(-1, 3)
    radius = radius.reshape(-1) + 1e-9
    target = 0.5 * (box[0] + box[1])
    for _ in range(2):   # solve the distance, re-centre on the projected extent, solve again
        rel = centres - target
        a, b, z = rel @ right, rel @ up, rel @ fwd
        need = np.maximum((np.abs(a) + radius) / tan_x, (np.abs(b) + radius) / tan_y) - z + radius
        dist = max(float(need.max()), 1e-6)
        depth = dist + z
        x_lo, x_hi = np.min((a - radius) / depth), np.max((a + radius) / depth)
        y_lo, y_hi = np.min((b - radius) / depth), np.max((b + radius) / depth)
        target = target + dist * (0.5 * (x_lo + x_hi) * right + 0.5 * (y_lo + y_hi) * up)
    rel = centres - target
    a, b, z = rel @ right, rel @ up, rel @ fwd
    need = np.maximum((np.abs(a) + radius) / tan_x, (np.abs(b) + radius) / tan_y) - z + radius
    dist = max(float(need.max()), 1e-6)
    eye = target - fwd * dist
    return Camera(tuple(eye.tolist()), tuple(target.tolist()), (0.0, 1.0, 0.0), fov_y, width, height)


def pack_records(frusta, origin) -> np.ndarray:
    """One float32 record per segment for upload.

    Parameters
    ----------
    frusta : Frusta (see plantgen.geometry.frusta), n rows, float64, world units
    origin : (3,) float64, the render origin (the camera eye); positions and plane offsets
        are made relative to it in float64 before the cast to float32

    Returns
    -------
    (n, 24) float32: base - origin, h | axis, r1 | ref_dir, r2 | plane_lo | plane_hi |
    u_offset, twist, shell, tag. Plane offsets are relative to the base point
    (d - n·base, formed in float64), as plantgen.geometry.reference uploads them. 96 bytes per segment. ``tag`` = material + 256·(lower end
    open) + 512·(upper end open); an end is open unless a continuing row shares its plane
    (open ends are capped surfaces, shared joint planes are not).
    """

    origin = np.asarray(origin, dtype=np.float64)
    n = len(frusta.base)
    rec = np.empty((n, RECORD_FLOATS), dtype=np.float64)
    rec[:, 0:3] = frusta.base - origin
    rec[:, 3] = frusta.length
    rec[:, 4:7] = frusta.axis
    rec[:, 7] = frusta.r1
    rec[:, 8:11] = frusta.ref_dir
    rec[:, 11] = frusta.r2
    for col, plane in ((12, frusta.plane_lo), (16, frusta.plane_hi)):
        rec[:, col:col + 3] = plane[:, :3]
        rec[:, col + 3] = plane[:, 3] - np.einsum("ij,ij->i", plane[:, :3], frusta.base)
    rec[:, 20] = frusta.u_offset
    rec[:, 21] = frusta.twist
    rec[:, 22] = frusta.shell
    parent_row = frusta.parent_row
    open_lo = parent_row < 0
    open_hi = np.ones(n, dtype=bool)
    open_hi[parent_row[parent_row >= 0]] = False
    material = np.asarray(frusta.material, dtype=np.int64)
    if n and (material.min() < 0 or material.max() > 255):
        raise PlantgenError("material indices must lie in 0..255 for the ray caster")
    rec[:, 23] = material + 256 * open_lo + 512 * open_hi
    return rec.astype(np.float32)


# name fragment -> (dark albedo, light albedo, (specular, exponent)), linear RGB
_PALETTE = {
    "bark": ((0.10, 0.065, 0.04), (0.36, 0.25, 0.16), (0.04, 12.0)),
    "saguaro": ((0.06, 0.16, 0.05), (0.22, 0.42, 0.16), (0.18, 30.0)),
    "cactus": ((0.06, 0.16, 0.05), (0.22, 0.42, 0.16), (0.18, 30.0)),
    "aloe": ((0.10, 0.25, 0.12), (0.30, 0.52, 0.30), (0.25, 40.0)),
    "leaf": ((0.05, 0.20, 0.03), (0.18, 0.45, 0.08), (0.15, 24.0)),
    "needle": ((0.03, 0.13, 0.04), (0.10, 0.30, 0.10), (0.10, 20.0)),
    "frond": ((0.06, 0.22, 0.04), (0.22, 0.48, 0.10), (0.15, 24.0)),
    "stone": ((0.22, 0.20, 0.18), (0.55, 0.52, 0.47), (0.05, 10.0)),
    "wood": ((0.18, 0.10, 0.05), (0.45, 0.30, 0.16), (0.06, 14.0)),
    "sand": ((0.45, 0.36, 0.22), (0.70, 0.58, 0.38), (0.02, 8.0)),
    "grass": ((0.10, 0.22, 0.05), (0.25, 0.40, 0.10), (0.02, 8.0)),
    "soil": ((0.20, 0.14, 0.09), (0.38, 0.28, 0.18), (0.02, 8.0)),
}
_DEFAULT = ((0.25, 0.25, 0.25), (0.6, 0.6, 0.6), (0.1, 16.0))


def material_palette(material_names) -> dict[str, np.ndarray]:
    """Shading constants per material slot, looked up by name (substring, case-insensitive).

    Returns arrays ``dark``, ``light`` of shape (MAX_MATERIALS, 3) float32 (linear RGB albedo
    where the texture is low / high) and ``gloss`` (MAX_MATERIALS, 2) (specular, exponent).
    """
    dark = np.tile(np.float32(_DEFAULT[0]), (MAX_MATERIALS, 1))
    light = np.tile(np.float32(_DEFAULT[1]), (MAX_MATERIALS, 1))
    gloss = np.tile(np.float32(_DEFAULT[2]), (MAX_MATERIALS, 1))
    for i, name in enumerate(list(material_names)[:MAX_MATERIALS]):
        for key, (lo, hi, gl) in _PALETTE.items():
            if key in name.lower():
                dark[i], light[i], gloss[i] = lo, hi, gl
                break
    return {"dark": dark, "light": light, "gloss": gloss}


LIGHT_COLOR = (1.0, 0.96, 0.9)
AMBIENT_COLOR = (0.35, 0.4, 0.5)
SKY = {"sky_zenith": (0.18, 0.36, 0.75), "sky_horizon": (0.72, 0.8, 0.9),
       "ground_tint": (0.35, 0.33, 0.3)}


def shading_uniforms(light_dir=(0.45, 0.8, 0.35)) -> dict:
    """Uniform values of shaders/shading.glsl other than the palette: the light (``light_dir``
    (3,) towards the light, normalised here), its colour, the ambient term and the sky.
    Every renderer sets these so RC, GS and the sky agree."""
    light = np.asarray(light_dir, dtype=np.float64)
    light = light / np.linalg.norm(light)
    return {"light_dir": tuple(light), "light_color": LIGHT_COLOR,
            "ambient_color": AMBIENT_COLOR, **SKY}


@dataclass(frozen=True)
class RaycastSettings:
    """Knobs of one render. Every accuracy/speed trade-off is one field.

    relief : march the relief shell of segments with ``shell > 0`` (§3)
    linear_steps : uniform samples along the shell interval
    binary_steps : bisection steps after the first sample under the relief surface
    v_exact : v of (7) per sample (exact) instead of interpolated between entry and exit
    hull_padding : growth of the bounding pyramid relative to the radius, so pixels on
        a silhouette tangent to the pyramid are not lost to rasterisation rules
    proxy : ``"pyramid"`` (§2.6) or ``"screen"``: every segment covers the whole screen, a
        slow oracle that shows what a too-tight pyramid would lose (tests)
    """

    relief: bool = False
    linear_steps: int = 32
    binary_steps: int = 6
    v_exact: bool = False
    hull_padding: float = 0.02
    proxy: str = "pyramid"

    def __post_init__(self):
        if self.proxy not in ("pyramid", "screen"):
            raise PlantgenError(f"proxy must be 'pyramid' or 'screen', not {self.proxy!r}")
        if self.linear_steps < 1 or self.binary_steps < 0:
            raise PlantgenError("relief steps: linear steps must be >= 1, binary steps >= 0")
        if not 0 <= self.hull_padding < 1:
            raise PlantgenError("hull padding must lie in [0, 1)")

    def defines(self) -> dict[str, bool]:
        return {"RELIEF": self.relief, "V_EXACT": self.relief and self.v_exact,
                "SCREEN_PROXY": self.proxy == "screen"}


@dataclass
class RenderResult:
    """color: (height, width, 3) uint8, row 0 the top row; distance: (height, width) float32,
    distance from the eye along each pixel's ray, inf for a miss; frame_ms: GPU frame time
    (draw to finish, excluding upload and read-back); camera: the view rendered."""

    color: np.ndarray
    distance: np.ndarray
    frame_ms: float
    camera: Camera
    stats: dict = field(default_factory=dict)


def height_maps_for(material_names) -> tuple[np.ndarray, np.ndarray]:
    """(n_layers, H, W) uint8 height maps, one layer per material slot, and
    (MAX_MATERIALS, 2) float32 texture repeats (u around, v per segment)."""
    names = list(material_names) or ["bark"]
    repeats = np.ones((MAX_MATERIALS, 2), dtype=np.float32)
    try:
        from ..geometry import relief
    except ImportError:
        relief = None
    if relief is not None and hasattr(relief, "height_maps"):
        maps, rep = relief.height_maps(names)
        maps = np.ascontiguousarray(maps, dtype=np.uint8)
        repeats[:len(rep)] = np.asarray(rep, dtype=np.float32)[:MAX_MATERIALS]
        return maps, repeats
    return np.full((len(names), 4, 4), 128, dtype=np.uint8), repeats




class OffscreenRenderer:
    """What every plantgen renderer shares: the GL context, an offscreen framebuffer
    (colour RGBA8 + float32 distance + depth) resized on demand, the relief height maps
    uploaded once per material list, and the scene's extras: the ground square and the
    light's shadow map (plantgen.render.passes), drawn the same way for RC and GS."""

    def __init__(self, ctx=None):
        self.ctx = ctx if ctx is not None else gl_context()
        self._fbo = None
        self._fbo_size = None
        self._textures = {}
        self._shadow = ShadowPass(self.ctx)
        self.last_light_window = None

    def release(self) -> None:
        """Free the framebuffer, the height textures and the shadow map (they are made
        again on the next render)."""
        if self._fbo is not None:
            release_framebuffer(self._fbo)
        self._fbo = self._fbo_size = None
        for tex, _ in self._textures.values():
            tex.release()
        self._textures = {}
        self._shadow.release()

    def shadow_depths(self) -> np.ndarray:
        """(res, res) float32 light depth map of the last shadowed render, (z - near) /
        (far - near) in :attr:`last_light_window`, row 0 the window's bottom; 1: empty."""
        return self._shadow.depths()

    def _light(self, shadows: ShadowSettings | None, caster_box, light_dir, eye):
        """(window, receiver uniforms) of this frame's shadow map: (None, {}) without
        shadows. ``caster_box`` (2, 3) is the world box the light's window must cover."""
        if shadows is None:
            return None, {}
        window = light_window(caster_box, -np.asarray(light_dir, dtype=np.float64), eye)
        self.last_light_window = window
        receiver = dict(window.uniforms(), shadow_bias=shadows.bias * window.texel_size(shadows.resolution),
                        shadow_max_slope=shadows.max_slope, shadow_map=1)
        return window, receiver

    def _ground_draws(self, quad, eye, view_projection, palette, ground_material: int,
                      shading: dict, receiver: dict, window):
        """Draws of the ground square ``quad`` ((4, 3) world, strip order): its vertex array
        for the frame and, with a light ``window``, a callable drawing it into the light's
        map (for :meth:`_draw_shadow_map`).

        Returns (frame vao, light draw or None, [objects to release after the frame]).
        """
        ctx = self.ctx
        shadowed = window is not None
        program = build_program(ctx, "ground.glsl", {"SHADOWS": shadowed})
        _set(program, **shading, **receiver, view_projection=_mat4(view_projection),
             ground_material=ground_material, origin_offset=tuple(np.asarray(eye, np.float64)))
        for key in ("dark", "light", "gloss"):
            _write(program, f"material_{key}", palette[key])
        buf = ctx.buffer((np.asarray(quad) - eye).astype(np.float32).tobytes())
        vao = ctx.vertex_array(program, [(buf, "3f", "position")])
        light_vao = light_draw = None
        if shadowed:
            caster = build_program(ctx, "ground.glsl", {"SHADOW_PASS": True})
            _set(caster, view_projection=_mat4(window.matrix()))
            light_vao = ctx.vertex_array(caster, [(buf, "3f", "position")])

            def light_draw():
                ctx.disable(ctx.CULL_FACE)
                light_vao.render(mode=ctx.TRIANGLE_STRIP, vertices=4)
        return vao, light_draw, [vao, light_vao, buf]

    def _draw_shadow_map(self, resolution: int, draws) -> float:
        """Clear the light's depth map, run each callable of ``draws`` into it with the depth
        test on, and bind the map to texture unit 1 for the receivers. Returns the pass's
        milliseconds (to glFinish)."""
        ctx = self.ctx
        t0 = time.perf_counter()
        fbo = self._shadow.target(int(resolution))
        fbo.use()
        fbo.viewport = (0, 0, resolution, resolution)
        fbo.clear(depth=1.0)
        ctx.enable(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        for draw in draws:
            draw()
        ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)
        ctx.finish()
        self._shadow.texture.use(1)
        return (time.perf_counter() - t0) * 1e3

    def _framebuffer(self, width: int, height: int):
        if self._fbo_size != (width, height):
            if self._fbo is not None:
                release_framebuffer(self._fbo)
            ctx = self.ctx
            self._fbo = ctx.framebuffer(
                color_attachments=[ctx.renderbuffer((width, height), 4),
                                   ctx.renderbuffer((width, height), 1, dtype="f4")],
                depth_attachment=ctx.depth_renderbuffer((width, height)))
            self._fbo_size = (width, height)
        return self._fbo

    def _height_texture(self, material_names):
        key = tuple(material_names)
        if key not in self._textures:
            maps, repeats = height_maps_for(material_names)
            layers, h, w = maps.shape
            tex = self.ctx.texture_array((w, h, layers), 1, maps.tobytes(), dtype="f1")
            tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)  # bilinear is done in GLSL
            self._textures[key] = (tex, repeats)
        return self._textures[key]


class Raycaster(OffscreenRenderer):
    """Renders Frusta with the GLSL ray caster into an offscreen framebuffer.

    Programs are compiled per variant (defines) and cached; nothing is compiled or run that
    the settings do not ask for (no relief march without relief).
    """

    def __init__(self, ctx=None):
        super().__init__(ctx)
        self._template_vbo = self.ctx.buffer(PYRAMID_CORNERS.tobytes())
        self._template_ibo = self.ctx.buffer(PYRAMID_TRIANGLES.tobytes())
        self._sky_vao = None
        self.programs_used: set[tuple] = set()

    # ------------------------------------------------------------------ render
    def render(self, frusta, camera: Camera, settings: RaycastSettings = RaycastSettings(),
               material_names=("bark",), light_dir=(0.45, 0.8, 0.35),
               ground: dict | None = None, *, shadows: ShadowSettings | None = None,
               shadow_box=None, record_buffer=None) -> RenderResult:
        """Ray cast ``frusta`` as seen by ``camera``.

        Parameters
        ----------
        frusta : Frusta, n rows (world units, float64)
        camera : the view; rays go through pixel centres
        settings : relief on/off and its step knobs
        material_names : names of the material indices (choose colours and height maps)
        light_dir : (3,) direction towards the light (normalised here)
        ground : optional ``{"size", "height", "material"}``: a square of side ``size`` at
            y = ``height`` centred under the origin, rasterised into the same depth buffer
        shadows : None (no shadow pass, no shadow map sampled) or the shadow map's knobs:
            the frusta and the ground first write their depth into the light's map, then
            every surface samples it (plantgen.render.passes)
        shadow_box : (2, 3) world box the light's window must cover (default: the frusta's
            bounds); an animation passes one box for all frames, so the map's texels stay
            put and shadows do not shimmer
        record_buffer : a moderngl buffer already holding ``pack_records(frusta,
            camera.eye)`` (an animation updates only what moved); None: packed and
            uploaded here
        """
        ctx = self.ctx
        width, height = camera.width, camera.height
        fbo = self._framebuffer(width, height)
        eye = np.asarray(camera.eye, dtype=np.float64)
        t0 = time.perf_counter()
        records = pack_records(frusta, eye) if record_buffer is None else None
        upload_s = time.perf_counter() - t0

        right, up, fwd = camera.basis()
        tan_y = np.tan(np.radians(camera.fov_y) / 2)
        tan_x = tan_y * camera.aspect
        ground_quad = _ground_quad(ground) if ground else None
        near, far = self._depth_range(frusta, eye, fwd, ground_quad)
        view = camera.view_matrix()
        view[:3, 3] = 0.0  # the render origin is the eye
        view_projection = camera.projection_matrix(near, far) @ view
        proj = camera.projection_matrix(near, far)
        common = {"viewport": (float(width), float(height)), "cam_forward": tuple(fwd),
                  "cam_right_scaled": tuple(right * tan_x), "cam_up_scaled": tuple(up * tan_y)}

        n = len(frusta.base)
        variants = program_variants(settings, shadows, ground_quad is not None)
        programs_built = [(name, tuple(sorted(k for k, v in d.items() if v))) for name, d in variants]
        self.programs_used.update(programs_built)
        built = {(name, tuple(sorted(d.items()))): build_program(ctx, name, d) for name, d in variants}

        def variant(name, **flags):
            return built[(name, tuple(sorted(flags.items())))]

        shadowed = shadows is not None
        sky = variant("sky.glsl")
        material_names = tuple(material_names)
        tex, repeats = self._height_texture(material_names)
        if ground_quad is not None:
            material_names = material_names + (ground["material"],)
        program = variant("raycast.glsl", **settings.defines(), SHADOWS=shadowed)
        palette = material_palette(material_names)
        shading = shading_uniforms(light_dir)
        for prog in (sky, program):
            _set(prog, **common, **shading)
        for key in ("dark", "light", "gloss"):
            _write(program, f"material_{key}", palette[key])
        box = None if not shadowed else (frusta_bounds(frusta) if shadow_box is None
                                         else np.asarray(shadow_box, np.float64))
        window, receiver = self._light(shadows, box, light_dir, eye)
        _set(program, **receiver)
        ground_vao = ground_light_draw = None
        ground_objects = []
        if ground_quad is not None:
            ground_vao, ground_light_draw, ground_objects = self._ground_draws(
                ground_quad, eye, view_projection, palette,
                min(len(material_names) - 1, MAX_MATERIALS - 1), shading, receiver, window)
        _write(program, "texture_repeat", repeats)
        _set(program, view_projection=_mat4(view_projection),
             depth_coeffs=(proj[2, 2], proj[2, 3]), hull_padding=settings.hull_padding,
             linear_steps=settings.linear_steps, binary_steps=settings.binary_steps,
             height_maps=0)

        own_buffer = record_buffer is None
        rec_buf = (ctx.buffer(records.tobytes()) if n else None) if own_buffer else record_buffer
        vao = None
        screen_proxy = settings.proxy == "screen"
        if n:
            vao = ctx.vertex_array(
                program,
                [(self._template_vbo, "3f", "corner"),
                 (rec_buf, "4f 4f 4f 4f 4f 4f/i", "rec0", "rec1", "rec2", "rec3", "rec4", "rec5")],
                index_buffer=None if screen_proxy else self._template_ibo, index_element_size=4)
        shadow_draws, shadow_objects = [], []
        if shadowed:
            caster = variant("raycast.glsl", SHADOW_PASS=True,
                             RELIEF=settings.relief and shadows.caster == "relief")
            _set(caster, **window.uniforms(), viewport=(float(shadows.resolution),) * 2,
                 hull_padding=settings.hull_padding, linear_steps=settings.linear_steps,
                 binary_steps=settings.binary_steps, height_maps=0,
                 view_projection=_mat4(window.matrix()))
            _write(caster, "texture_repeat", repeats)
            if ground_light_draw is not None:
                shadow_draws.append(ground_light_draw)
            if n:
                frusta_light_vao = ctx.vertex_array(
                    caster,
                    [(self._template_vbo, "3f", "corner"),
                     (rec_buf, "4f 4f 4f 4f 4f 4f/i", "rec0", "rec1", "rec2", "rec3", "rec4", "rec5")],
                    index_buffer=self._template_ibo, index_element_size=4)
                shadow_objects.append(frusta_light_vao)

                def draw_frusta_depth():
                    tex.use(0)
                    ctx.enable(ctx.CULL_FACE)
                    ctx.front_face = "ccw"
                    ctx.cull_face = "front"
                    frusta_light_vao.render(mode=ctx.TRIANGLES, vertices=len(PYRAMID_TRIANGLES) * 3,
                                            instances=n)
                shadow_draws.append(draw_frusta_depth)
        if self._sky_vao is None or self._sky_vao.program is not sky:
            self._sky_vao = ctx.vertex_array(sky, [])

        ctx.finish()
        t_draw = time.perf_counter()
        shadow_ms = self._draw_shadow_map(shadows.resolution, shadow_draws) if shadowed else 0.0
        fbo.use()
        fbo.viewport = (0, 0, width, height)
        fbo.clear(depth=1.0)
        ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE | ctx.BLEND)
        self._sky_vao.render(mode=ctx.TRIANGLES, vertices=3)
        ctx.enable(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        if ground_vao is not None:
            ground_vao.render(mode=ctx.TRIANGLE_STRIP, vertices=4)
        if vao is not None:
            tex.use(0)
            if screen_proxy:
                vao.render(mode=ctx.TRIANGLES, vertices=3, instances=n)
            else:
                ctx.enable(ctx.DEPTH_TEST | ctx.CULL_FACE)
                ctx.front_face = "ccw"
                ctx.cull_face = "front"   # back faces: an eye inside a pyramid still sees it
                vao.render(mode=ctx.TRIANGLES, vertices=len(PYRAMID_TRIANGLES) * 3, instances=n)
        ctx.finish()
        frame_ms = (time.perf_counter() - t_draw) * 1e3
        ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)

        color = np.frombuffer(fbo.read(components=3, attachment=0, alignment=1), np.uint8)
        color = color.reshape(height, width, 3)[::-1].copy()
        dist = np.frombuffer(fbo.read(components=1, attachment=1, dtype="f4", alignment=1),
                             np.float32).reshape(height, width)[::-1].copy()
        for obj in (vao, rec_buf if own_buffer else None, *ground_objects, *shadow_objects):
            if obj is not None:
                obj.release()
        passes = frame_passes(shadowed, ground_vao is not None, n > 0)
        stats = {"segments": n, "record_bytes": RECORD_BYTES,
                 "upload_bytes": records.nbytes if records is not None else 0,
                 "pack_ms": upload_s * 1e3, "near": near, "far": far, "passes": passes,
                 "program": ("raycast.glsl", settings.defines()), "programs": programs_built,
                 "shadow_ms": shadow_ms, "light_window": window}
        return RenderResult(color, dist, frame_ms, camera, stats)

    @staticmethod
    def _depth_range(frusta, eye: np.ndarray, fwd: np.ndarray, extra=None) -> tuple[float, float]:
        """Near and far distances along the view direction enclosing every frustum (and the
        (k, 3) points ``extra``)."""
        pts = [] if extra is None else [np.asarray(extra, dtype=np.float64)]
        if len(frusta.base):
            box = frusta_bounds(frusta)
            pts.append(box_corners(box))
        return depth_range(pts, eye, fwd)


def depth_range(point_sets, eye: np.ndarray, fwd: np.ndarray) -> tuple[float, float]:
    """Near and far distances along the unit view direction ``fwd`` from ``eye`` enclosing
    every (k, 3) array of ``point_sets`` with a 5 % margin of their extent; (0.1, 10) for
    none. near stays above far·1e-5, so the depth buffer keeps its precision."""
    pts = [np.asarray(p, dtype=np.float64) for p in point_sets if len(p)]
    if not pts:
        return 0.1, 10.0
    corners = np.concatenate(pts)
    box = np.stack([corners.min(axis=0), corners.max(axis=0)])
    depths = (corners - eye) @ fwd
    size = float(np.linalg.norm(box[1] - box[0]))
    far = max(float(depths.max()), 0.0) + 0.05 * size + 1e-6
    near = max(float(depths.min()) - 0.05 * size, far * 1e-5)
    return near, far


def _ground_quad(ground: dict) -> np.ndarray:
    """(4, 3) float64 corners of the ground square, in triangle-strip order, facing up."""
    half = float(ground["size"]) / 2
    y = float(ground.get("height", 0.0))
    return np.array([[-half, y, half], [half, y, half], [-half, y, -half], [half, y, -half]])


def _set(program, **values) -> None:
    for name, value in values.items():
        if name in program:
            program[name].value = value


def _write(program, name: str, array: np.ndarray) -> None:
    if name in program:
        program[name].write(np.ascontiguousarray(array, dtype=np.float32).tobytes())


def _mat4(matrix: np.ndarray) -> tuple:
    """A (4, 4) float64 matrix as a GLSL mat4 uniform value (column-major float32)."""
    return tuple(np.asarray(matrix).T.astype(np.float32).ravel())


_default_raycaster: Raycaster | None = None


def render_frusta(frusta, camera: Camera, settings: RaycastSettings = RaycastSettings(),
                  material_names=("bark",)) -> RenderResult:
    """Render with the shared context's cached :class:`Raycaster`."""
    global _default_raycaster
    ctx = gl_context()
    if _default_raycaster is None or _default_raycaster.ctx is not ctx:
        _default_raycaster = Raycaster(ctx)
    return _default_raycaster.render(frusta, camera, settings, material_names)


# ---------------------------------------------------------------------- files in, files out
@dataclass
class RenderReport:
    """What :func:`render_file` did: for the CLI to print and tests to check."""

    renderer: str
    segments: int          # skeleton segments
    rows: int              # frusta rows drawn (sharp bends add knuckle rows)
    frame_ms: float
    camera: Camera
    settings: RaycastSettings
    written: list = field(default_factory=list)
    result: RenderResult | None = None
    effects: tuple = ()
    shadows: object = None         # ShadowSettings, or None without shadows
    frames: int = 1
    update_ms: float = 0.0         # median per-frame CPU update (pose, skin, pack, upload)
    skin_calls: int = 0


def _write_atomically(path, write) -> None:
    """Call ``write(tmp_path)`` then rename onto ``path``: nothing half-written survives."""
    from pathlib import Path

    path = Path(path)
    tmp = path.with_name(f".{path.name}.part{path.suffix}")
    try:
        write(tmp)
        tmp.replace(path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise PlantgenError(f"{path}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def render_file(input_path, output, *, size=None, camera="auto", camera_out=None,
                depth_out=None, seed=None, iterations=None, relief=None,
                linear_steps=32, binary_steps=6, v_exact=False, timed_frames=3,
                effects=None, shadows=None, shadow_res=2048, shadow_caster="relief",
                time_s=None, frames=None, fps=12.0, progress=None) -> RenderReport:
    """Grow or load ``input_path`` (grammar, scene or skeleton ``.npz``), skin it, ray cast
    it and write a PNG (and optionally the camera JSON and the depth ``.npy``), or, with
    ``frames``, an animated GIF/WebP.

    Parameters
    ----------
    size : (width, height) in pixels; default: the camera file's size, else 1024x768
    camera : ``"auto"`` (the scene's camera if it has one, else the model framed to fill
        most of the viewport) or a path to a camera JSON
    relief, shadows : True/False add/remove that effect; None: as the effects say
    effects : None (the scene's list; none for a grammar or skeleton) or a list of effect
        names that replaces it (plantgen.scene.EFFECTS; an unknown name is an error)
    shadow_res : shadow map texels per side; shadow_caster : "relief" or "inner"
    time_s : seconds: the pose of an animated scene for a still (default 0), or the first
        frame's time of an animation
    frames, fps : write ``frames`` frames at ``fps`` to a ``.gif``/``.webp`` output
    progress : callable(done, total) called after each animation frame
    depth_out : path of a float32 (height, width) array of distances along each pixel's
        ray from the eye (``inf`` for a miss), row 0 the top row of the PNG
    timed_frames : frames rendered after a warm-up frame; the report quotes their median
    """
    from pathlib import Path

    from PIL import Image

    from ..pipeline import grow_file
    from .animate import ANIMATION_SUFFIXES, AnimatedScene, write_animation
    from .context import renderer_name
    from .passes import resolve_effects

    output = Path(output)
    animation_out = frames is not None
    if animation_out:
        if output.suffix.lower() not in ANIMATION_SUFFIXES:
            raise PlantgenError(f"{output}: an animation (--frames) must end in .gif or .webp")
        if int(frames) < 1 or not fps > 0:
            raise PlantgenError("--frames must be >= 1 and --fps > 0")
        if depth_out is not None:
            raise PlantgenError("--depth-out writes one frame: leave out --frames")
    elif output.suffix.lower() != ".png":
        raise PlantgenError(f"{output}: the image output must end in .png "
                            "(or .gif/.webp with --frames)")
    if depth_out is not None and Path(depth_out).suffix.lower() != ".npy":
        raise PlantgenError(f"{depth_out}: the depth output must end in .npy")
    if camera_out is not None and Path(camera_out).suffix.lower() != ".json":
        raise PlantgenError(f"{camera_out}: the camera output must end in .json")
    add, remove = [], []
    for name, flag in (("relief", relief), ("shadows", shadows)):
        if flag is not None:
            (add if flag else remove).append(name)
    grown = grow_file(input_path, seed=seed, iterations=iterations)
    skeleton, scene = grown.skeleton, grown.scene
    chosen = resolve_effects(scene.effects if scene is not None else (), replace=effects,
                             add=add, remove=remove)
    if len(skeleton) == 0:
        raise PlantgenError(f"{input_path}: nothing to render (the skeleton has no segments)")
    if scene is not None and "animation" in chosen:
        anim = AnimatedScene.from_scene(scene)
    else:   # a static scene (or one whose animation is switched off) is skinned once
        anim = AnimatedScene(skeleton, np.zeros(len(skeleton), dtype=np.int64), [None])
    t_start = float(time_s or 0.0)
    frusta = anim.frusta_at(t_start)

    if camera == "auto" or camera is None:
        width, height = size or (1024, 768)
        if scene is not None and isinstance(scene.camera, dict):
            cam = Camera.from_dict({**scene.camera, "width": width, "height": height},
                                   f"{input_path}: camera")
        else:
            cam = auto_camera(frusta, width, height)
    else:
        cam = Camera.load(camera)
        if size is not None:
            cam = Camera(cam.eye, cam.target, cam.up, cam.fov_y, size[0], size[1])
    settings = RaycastSettings(relief="relief" in chosen, linear_steps=linear_steps,
                               binary_steps=binary_steps, v_exact=v_exact)
    shadow_settings = (ShadowSettings(resolution=int(shadow_res), caster=shadow_caster)
                       if "shadows" in chosen else None)
    light_dir = (0.45, 0.8, 0.35)
    ground = None
    if scene is not None:
        light_dir = tuple(-np.asarray(scene.light["direction"], dtype=np.float64))
        ground = scene.ground
    names = getattr(frusta, "material_names", skeleton.material_names)
    n_frames = int(frames) if animation_out else 1
    times = t_start + np.arange(n_frames) / float(fps)
    shadow_box = None
    if shadow_settings is not None and anim.animated and n_frames > 1:
        shadow_box = anim.bounds(times[:: max(n_frames // 8, 1)])   # one light window for all frames

    raycaster = Raycaster()
    colors, frame_times, update_times = [], [], []
    result = None
    if animation_out:
        # one warm-up frame pays for the driver's shader compilation
        fr, buf, _ = anim.upload(raycaster.ctx, times[0], cam.eye)
        raycaster.render(fr, cam, settings, names, light_dir, ground, shadows=shadow_settings,
                         shadow_box=shadow_box, record_buffer=buf)
        for i, t in enumerate(times):
            fr, buf, update = anim.upload(raycaster.ctx, t, cam.eye)
            result = raycaster.render(fr, cam, settings, names, light_dir, ground,
                                      shadows=shadow_settings, shadow_box=shadow_box,
                                      record_buffer=buf)
            colors.append(result.color)
            frame_times.append(result.frame_ms)
            update_times.append(update.total_ms)
            if progress is not None:
                progress(i + 1, n_frames)
    else:
        for _ in range(max(int(timed_frames), 1) + 1):
            result = raycaster.render(frusta, cam, settings, names, light_dir, ground,
                                      shadows=shadow_settings)
            frame_times.append(result.frame_ms)
        frame_times = frame_times[1:]
    anim.release()
    frame_ms = float(np.median(frame_times))
    written = []
    if animation_out:
        write_animation(output, colors, fps)
    else:
        _write_atomically(output, lambda p: Image.fromarray(result.color).save(p, format="PNG"))
    written.append(output)
    if camera_out is not None:
        _write_atomically(camera_out, lambda p: cam.save(p))
        written.append(Path(camera_out))
    if depth_out is not None:
        def save_depth(p):
            with open(p, "wb") as fh:
                np.save(fh, result.distance.astype(np.float32))
        _write_atomically(depth_out, save_depth)
        written.append(Path(depth_out))
    return RenderReport(renderer_name(), len(skeleton), len(frusta.base), frame_ms, cam,
                        settings, written, result, chosen, shadow_settings, n_frames,
                        float(np.median(update_times)) if update_times else 0.0, anim.skin_calls)
