"""Effects decide programs and passes; the shadow-map pass of one directional light.

A scene lists its effects (:data:`plantgen.settings.EFFECTS`; :class:`plantgen.settings.EffectSettings`
applies the command line's overrides); :func:`program_variants` turns the effects into the shader
variants (preprocessor defines) a frame needs, and :func:`frame_passes` into the passes it
runs. Nothing more is built or run than asked: without ``shadows`` there is no shadow
pass and no program samples a shadow map; without ``relief`` no relief march is compiled.

The shadow map (:class:`ShadowPass`) is an orthographic depth image along the light. The
ray-cast frusta write their *analytic* hit depth into it (``shaders/raycast.glsl`` with
``SHADOW_PASS``: the light's parallel rays are intersected with each cone in the fragment
shader, so the shadow is the frustum's, not its bounding pyramid's); the ground writes
its plane. Receivers filter it with percentage-closer filtering and a receiver-plane bias
(``shaders/shadow.glsl``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.camera import box_corners
from ..settings import ShadowSettings
from ..tolerances import tol
from .context import release_framebuffer

__all__ = ["LightWindow", "light_window", "ShadowPass",
           "program_variants", "frame_passes"]


def program_variants(settings, shadows: ShadowSettings | None, ground: bool, flat_background: bool = False,
                     leaves: bool = False) -> list:
    """(program file, defines) of every program one frame uses.

    ``settings`` is the :class:`~plantgen.gl.raycast.RaycastSettings` (relief on iff the
    effects hold ``relief``); ``shadows`` is None without the ``shadows`` effect (then no
    shadow pass runs and no program samples a map); ``ground``: the scene has a ground;
    ``flat_background``: a flat colour (or transparency) instead of the sky; ``leaves``:
    the model has leaf polygons (shaders/leaf.glsl, drawn by either renderer).
    """
    shadowed = shadows is not None
    out = [("sky.glsl", {"FLAT_BACKGROUND": True} if flat_background else {})]
    if shadowed:
        out.append(("raycast.glsl", {"SHADOW_PASS": True,
                                     "RELIEF": settings.relief and shadows.caster == "relief"}))
        if ground:
            out.append(("ground.glsl", {"SHADOW_PASS": True}))
        if leaves:
            out.append(("leaf.glsl", {"SHADOW_PASS": True}))
    if ground:
        out.append(("ground.glsl", {"SHADOWS": shadowed}))
    out.append(("raycast.glsl", {**settings.defines(), "SHADOWS": shadowed}))
    if leaves:
        labels = bool(getattr(settings, "labels", False))
        out.append(("leaf.glsl", {"SHADOWS": shadowed and not labels, "LABELS": labels}))
    return out


def frame_passes(shadows: bool, ground: bool, segments: bool, leaves: bool = False) -> list[str]:
    """Names of the passes of one frame, in order."""
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
    """The light's depth map: a depth texture of ``resolution``² and its framebuffer."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._fbo = None
        self.texture = None
        self.resolution = None

    def target(self, resolution: int):
        """The framebuffer (depth only) for a map of ``resolution`` texels per side."""
        if self.resolution != resolution:
            self.release()
            self.texture = self.ctx.depth_texture((resolution, resolution))
            self.texture.compare_func = ""          # read depths, compare in the shader
            self.texture.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
            self._fbo = self.ctx.framebuffer(depth_attachment=self.texture)
            self.resolution = resolution
        return self._fbo

    def depths(self) -> np.ndarray:
        """(resolution, resolution) float32 window depths in [0, 1], row 0 the window's
        bottom (light_up = -1); 1 where nothing was drawn."""
        raw = self.texture.read(alignment=1)
        return np.frombuffer(raw, dtype=np.float32).reshape(self.resolution, self.resolution).copy()

    def release(self) -> None:
        if self._fbo is not None:
            release_framebuffer(self._fbo)
        self._fbo = self.texture = self.resolution = None
