"""Effects decide programs and passes; the shadow-map pass of one directional light.

A scene lists its effects (:data:`plantgen.settings.EFFECTS`; :class:`plantgen.settings.EffectSettings`
applies the command line's overrides); :func:`program_variants` turns the effects into the shader
variants (preprocessor defines) a frame needs, and :func:`frame_passes` into the passes it
runs. Nothing more is built or run than asked: without ``shadows`` there is no shadow
pass and no program samples a shadow map; without ``relief`` no relief march is compiled.

The shadow map (:class:`ShadowPass`) is an orthographic depth image along the light. The
ray-cast frusta write their *analytic* hit depth into it (``shaders/raycast.glsl`` with
``SHADOW_PASS``: the light's parallel rays are intersected with each cone in the fragment
shader, so the shadow is the frustum's, not its bounding pyramid's; with relief the relief
surface casts, found by ``shaders/light_march.glsl``); the ground writes its plane.
Receivers filter it with percentage-closer filtering and a receiver-plane bias
(``shaders/shadow.glsl``).

The light's pass does not depend on the eye: it is drawn relative to its own origin (the
*anchor*, a world point of the casters' box), so a map drawn for one camera serves every
other, and :class:`ShadowPass` keeps the last few maps by what they depend on
(:class:`plantgen.gl.frame.ShadowKey`) for the frames that follow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.rays.camera import box_corners
from ..settings import ShadowSettings
from ..tolerances import tol
from .context import release_framebuffer

__all__ = ["LightWindow", "light_window", "ShadowPass", "light_defines", "light_program", "look_defines", "traced_look",
           "program_variants", "frame_passes"]

#: Shadow maps a renderer keeps (by what they depend on): two, so a run that alternates
#: two casters (the bench's RC and RC+R) reuses both.
SHADOW_MAPS_KEPT = 2


def light_defines(settings, shadows: ShadowSettings) -> dict:
    """The defines of the frusta's program for the light's pass: the relief surface casts
    when relief is on and the caster is ``relief``; ``LIGHT_BISECT`` marches it with the
    eye's march instead of the light's own (``shaders/light_march.glsl``)."""
    relief = bool(settings.relief) and shadows.caster == "relief"
    return {"SHADOW_PASS": True, "RELIEF": relief, "LIGHT_BISECT": relief and shadows.march == "bisect"}


def light_program(settings, shadows: ShadowSettings) -> tuple[str, dict]:
    """(file, defines) of the frusta's program in the light's pass: the ray caster's
    (:func:`light_defines`), or with the mesh caster the rasteriser's depth-only pass of
    the tessellated frusta."""
    if shadows.caster == "mesh":
        return "raster.glsl", {"SHADOW_PASS": True, "SKINNED": False}
    return "raycast.glsl", light_defines(settings, shadows)


def look_defines(look, program: str, shadowed: bool = False) -> dict:
    """The defines of the looks (:class:`~plantgen.settings.LookSettings`, None: none) that
    ``program`` takes: every program its tone curve (``TONE_MAP``, ``TONE_ACES``), the shadow receivers the
    soft sun (``SOFT_SUN``, with ``shadowed``), the frusta (``raycast.glsl``, ``rt.glsl``),
    the leaves and the ground the sky light (``SKY_LIGHT``), the leaves ``TRANSLUCENT``,
    every program but the sky and the ground (which faces up, away from itself) the
    ground's light (``GROUND_BOUNCE``). A look that is off gives no define: the program is
    today's."""
    if look is None:
        return {}
    on = look.defines()
    out = {"TONE_MAP": on["TONE_MAP"], "TONE_ACES": on["TONE_ACES"]}
    if program == "sky.glsl":
        return out
    out["SOFT_SUN"] = on["SOFT_SUN"] and shadowed
    if program != "ground.glsl":
        out["GROUND_BOUNCE"] = on["GROUND_BOUNCE"]
    if program in ("raycast.glsl", "rt.glsl", "leaf.glsl", "ground.glsl"):
        out["SKY_LIGHT"] = on["SKY_LIGHT"]
    if program == "leaf.glsl":
        out["TRANSLUCENT"] = on["TRANSLUCENT"]
    return out


def traced_look(look, program: str, shadowed: bool, bvh_defines: dict | None) -> dict:
    """:func:`look_defines`, with those of the BVH (``bvh_defines``) where the sky light
    traces it."""
    out = look_defines(look, program, shadowed)
    return {**out, **(bvh_defines or {})} if out.get("SKY_LIGHT") else out


def program_variants(settings, shadows: ShadowSettings | None, ground: bool, flat_background: bool = False,
                     leaves: bool = False, bvh_defines: dict | None = None) -> list:
    """(program file, defines) of every program one frame uses.

    ``settings`` is the :class:`~plantgen.gl.raycast.RaycastSettings` (relief on iff the
    effects hold ``relief``); ``shadows`` is None without the ``shadows`` effect (then no
    shadow pass runs and no program samples a map); ``ground``: the scene has a ground;
    ``flat_background``: a flat colour (or transparency) instead of the sky; ``leaves``:
    the model has leaf polygons (shaders/leaf.glsl, drawn by either renderer);
    ``bvh_defines``: those of the BVH the sky light traces (with ``SKY_LIGHT``).
    """
    shadowed = shadows is not None
    look = getattr(settings, "look", None)
    labels = bool(getattr(settings, "labels", False))
    out = [("sky.glsl", {"FLAT_BACKGROUND": True} if flat_background else look_defines(look, "sky.glsl"))]
    if shadowed:
        out.append(light_program(settings, shadows))
        if ground:
            out.append(("ground.glsl", {"SHADOW_PASS": True}))
        if leaves:
            out.append(("leaf.glsl", {"SHADOW_PASS": True}))
    if ground:
        out.append(("ground.glsl", {"SHADOWS": shadowed, "FLAT_BACKGROUND": flat_background,
                                    **traced_look(look, "ground.glsl", shadowed, bvh_defines)}))
    out.append(("raycast.glsl", {**settings.defines(), "SHADOWS": shadowed,
                                 **({} if labels else traced_look(look, "raycast.glsl", shadowed, bvh_defines))}))
    if leaves:
        out.append(("leaf.glsl", {"SHADOWS": shadowed and not labels, "LABELS": labels,
                                  **({} if labels else traced_look(look, "leaf.glsl", shadowed, bvh_defines))}))
    return out


def frame_passes(shadows: bool, ground: bool, segments: bool, leaves: bool = False) -> list[str]:
    """Names of the passes of one frame, in order, but for the sky: it is drawn after the
    ground, at the far plane, so the depth test skips it where the ground covers it
    (:meth:`plantgen.gl.frame.OffscreenRenderer._draw_frame`); it is named before."""
    return ((["shadow"] if shadows and (segments or ground or leaves) else []) + ["sky"]
            + (["ground"] if ground else []) + (["frusta"] if segments else []) + (["leaves"] if leaves else []))


@dataclass(frozen=True)
class LightWindow:
    """The orthographic window of a directional light, render-origin relative.

    origin : (3,) window centre; right, up, forward : (3,) unit vectors (forward: the
    direction the light travels); half : (2,) half extents in world units; depth : (2,)
    near and far along ``forward`` from ``origin`` (world units).
    """

    origin: np.ndarray
    right: np.ndarray
    up: np.ndarray
    forward: np.ndarray
    half: np.ndarray
    depth: np.ndarray

    def matrix(self) -> np.ndarray:
        """(4, 4) float64: render-origin relative world -> clip coordinates (orthographic;
        window depth = (z - near) / (far - near))."""
        near, far = self.depth
        m = np.zeros((4, 4))
        m[0, :3] = self.right / self.half[0]
        m[1, :3] = self.up / self.half[1]
        m[2, :3] = 2.0 * self.forward / (far - near)
        m[0, 3] = -self.right @ self.origin / self.half[0]
        m[1, 3] = -self.up @ self.origin / self.half[1]
        m[2, 3] = -2.0 * (self.forward @ self.origin + near) / (far - near) - 1.0
        m[3, 3] = 1.0
        return m

    def uniforms(self) -> dict:
        return {"light_origin": tuple(self.origin), "light_right": tuple(self.right),
                "light_up": tuple(self.up), "light_forward": tuple(self.forward),
                "light_half": tuple(self.half), "light_depth": tuple(self.depth)}

    def texel_size(self, resolution: int) -> float:
        """World size of one texel (the larger side)."""
        return float(2.0 * self.half.max() / resolution)

    def shifted(self, offset) -> LightWindow:
        """The same window relative to an origin ``offset`` (3,) behind this one's: the
        light pass's window (relative to its anchor) as the eye's receivers see it
        (``offset`` = anchor - eye, formed in float64). Depths along the light stay as
        they are: they are measured from the window's origin."""
        return LightWindow(self.origin + np.asarray(offset, dtype=np.float64), self.right, self.up, self.forward,
                           self.half, self.depth)

    def values(self) -> tuple:
        """Every number of the window, as a tuple of floats (a cache key's part)."""
        return tuple(float(x) for x in np.concatenate([self.origin, self.right, self.up, self.forward,
                                                         self.half, self.depth]))


def light_window(caster_box, light_travel, origin, margin: float = 0.02) -> LightWindow:
    """The light's window around every shadow caster.

    Parameters
    ----------
    caster_box : (2, 3) float64 world box around the casters (the frusta, relief shells
        included)
    light_travel : (3,) direction the light travels (not necessarily unit)
    origin : (3,) float64 render origin (the camera eye), subtracted first
    margin : relative growth of the window on every side

    A directional light's shadows fall along its rays, so every shadow lies inside the
    casters' own window: receivers outside it (in x, y) are lit, and receivers beyond
    ``far`` see only the casters in front of them.
    """
    forward = np.asarray(light_travel, dtype=np.float64)
    forward = forward / np.linalg.norm(forward)
    helper = np.array([0.0, 1.0, 0.0]) if abs(forward[1]) < 0.99 else np.array([1.0, 0.0, 0.0])
    right = np.cross(forward, helper)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    corners = box_corners(np.asarray(caster_box, dtype=np.float64) - np.asarray(origin, dtype=np.float64))
    local = corners @ np.stack([right, up, forward]).T
    lo, hi = local.min(axis=0), local.max(axis=0)
    size = float(np.max(hi - lo)) or 1.0
    pad = margin * size + tol.light_window_pad
    lo, hi = lo - pad, hi + pad
    centre_xy = 0.5 * (lo[:2] + hi[:2])
    origin_rel = centre_xy[0] * right + centre_xy[1] * up
    half = 0.5 * (hi[:2] - lo[:2])
    return LightWindow(origin_rel, right, up, forward, half, np.array([lo[2], hi[2]]))


class ShadowPass:
    """The light's depth maps: a depth texture of ``resolution``² and its framebuffer per
    map, the last :data:`SHADOW_MAPS_KEPT` kept with the key they were drawn for, the most
    recent first. :attr:`texture` is the map of the last frame (the receivers sample it)."""

    def __init__(self, ctx, kept: int = SHADOW_MAPS_KEPT):
        self.ctx = ctx
        self.kept = max(int(kept), 1)
        self._maps: list[list] = []      # [key, texture, framebuffer, resolution], most recent first
        self.texture = None
        self.resolution = None

    def find(self, key):
        """The map drawn for ``key`` (now the current one), or None."""
        for entry in self._maps:
            if entry[0] is not None and entry[0] == key:
                self._use(entry)
                return entry[1]
        return None

    def target(self, key, resolution: int):
        """The framebuffer (depth only) of a map of ``resolution`` texels per side for
        ``key``: the oldest map's textures when the maps kept are all in use."""
        resolution = int(resolution)
        entry = next((e for e in self._maps if e[0] is None and e[3] == resolution), None)
        if entry is None and len(self._maps) >= self.kept:
            entry = self._maps[-1]
            if entry[3] != resolution:
                release_framebuffer(entry[2])
                self._maps.remove(entry)
                entry = None
        if entry is None:
            texture = self.ctx.depth_texture((resolution, resolution))
            texture.compare_func = ""          # read depths, compare in the shader
            texture.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
            entry = [None, texture, self.ctx.framebuffer(depth_attachment=texture), resolution]
            self._maps.append(entry)
        entry[0] = key
        self._use(entry)
        return entry[2]

    def _use(self, entry) -> None:
        self._maps.remove(entry)
        self._maps.insert(0, entry)
        self.texture, self.resolution = entry[1], entry[3]

    def forget(self) -> None:
        """Forget what the maps were drawn for (the next frame draws its map again)."""
        for entry in self._maps:
            entry[0] = None

    def depths(self) -> np.ndarray:
        """(resolution, resolution) float32 window depths in [0, 1] of the current map, row
        0 the window's bottom (light_up = -1); 1 where nothing was drawn."""
        raw = self.texture.read(alignment=1)
        return np.frombuffer(raw, dtype=np.float32).reshape(self.resolution, self.resolution).copy()

    def release(self) -> None:
        for entry in self._maps:
            release_framebuffer(entry[2])
        self._maps = []
        self.texture = self.resolution = None
