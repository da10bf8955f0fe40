"""The GL side of the bench: one model's renderers, and the interleaved frame timing.

Frame times are measured by the renderers (draw calls to ``glFinish``, excluding
read-back), plus the per-frame CPU update of an animated scene. An animated scene is posed
on the GPU by every method (:mod:`plantgen.gl.pose`): RC and RC+R get their records from
the compute program (a frame where a joint may turn sharp is skinned on the CPU), GS and
GS+R draw a mesh built once at rest and posed by the vertex shader from the same program's
pose buffer (:mod:`plantgen.geometry.meshes.skinned_mesh`); the CPU time of that (the dispatch)
is added to each frame.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..exporters.textures import bake_textures
from ..geometry.meshes.mesh import TessellatedMesh, outer_shell_mesh, tessellate, triangle_count
from ..geometry.meshes.textures import parallax_map
from ..gl.pose import PoseStream
from ..gl.raster import RasterRenderer, normal_map_bytes
from ..gl.raycast import Raycaster
from ..gl.result import RenderResult
from ..settings import ShadowSettings
from .configs import Config
from .models import BenchModel

__all__ = ["Renderers", "time_configs", "median_ms", "animation_time", "shadow_box",
           "time_after_warm_up"]

#: Frames per second of the animation clock: timed frame i shows the scene at (i + 1) / 30 s.
ANIMATION_FPS = 30.0


def animation_time(frame) -> float | np.ndarray:
    """Seconds of the animation clock at ``frame`` (an int or an array of them)."""
    return frame / ANIMATION_FPS


def shadow_box(model: BenchModel, frames: int) -> np.ndarray | None:
    """(2, 3) world box one light window covers for every timed frame of an animated
    scene with shadows (so the map's texels stay put); None otherwise."""
    if model.animation is None or not model.shadows:
        return None
    return model.animation.bounds(animation_time(np.arange(0, frames + 2, 4)))


def median_ms(samples) -> float:
    """Median of frame times in ms, nan for none."""
    return float(np.median(np.asarray(samples, dtype=np.float64))) if len(samples) else float("nan")


@dataclass
class _Conditions:
    """What a frame draws besides the model: the paper's conditions, or none of them."""

    shadows: ShadowSettings | None
    ground: dict | None
    animated: bool
    leaves: object = None     # the model's leaf polygons (a Polygons), or None

    @classmethod
    def of(cls, model: BenchModel, paper: bool) -> _Conditions:
        """The paper's conditions for ``model`` (shadow map and ground where the scene lists
        them, the animation posed every frame, a leafy model's leaves drawn by RC and GS
        alike), or bare frames when ``paper`` is False: the error against the float64
        reference, which casts frusta only, measures the frusta's accuracy."""
        if not paper:
            return cls(None, None, False)
        return cls(ShadowSettings() if model.shadows else None, model.ground,
                   model.animation is not None, model.leaves)


class Renderers:
    """The GL side of one model: one ray caster, one raster renderer per configuration key
    (so the interleaved run does not re-upload), meshes cached per (level, surface)
    (:attr:`Config.surface`), baked maps per level."""

    def __init__(self, model: BenchModel, max_triangles: int, shadow_box=None):
        self.model = model
        self.max_triangles = max_triangles
        self.raycaster = Raycaster()
        self.records = PoseStream(self.raycaster.ctx)     # an animation's records, posed on the GPU
        self.rasters: dict = {}
        self.meshes: dict = {}
        self.skinned: dict = {}          # an animation's vertex-skinned meshes, per (level, surface)
        self.baked: dict = {}            # GS+N, GS+POM: {level: {"textures" | kind: {material name: ...}}}
        self.shadow_box = shadow_box   # (2, 3) one light window for every animation frame

    def mesh(self, level: int, surface: str, frusta=None) -> TessellatedMesh | None:
        """The tessellation at ``level`` on ``surface`` (:attr:`Config.surface`; cached for
        the static frusta), or None over the triangle budget."""
        frusta = self.model.frusta if frusta is None else frusta
        key = (level, surface)
        static = frusta is self.model.frusta
        if static and key in self.meshes:
            return self.meshes[key]
        if triangle_count(len(frusta), level, 0) > self.max_triangles:
            return None
        mesh = _tessellation(frusta, level, surface)
        if static:
            self.meshes[key] = mesh
        return mesh

    def maps(self, level: int, kind: str) -> dict | None:
        """The baked maps of the still smooth mesh at ``level`` (cached), each baked as
        ``plantgen export`` bakes it (at the median aspect of the material's faces), as
        :attr:`Method.maps` ``kind`` draws them: {material name: (H, W, 3) uint8 normal
        map} (``normal``) or (H, W, 4) with the height in the alpha (``parallax``); None
        over the triangle budget."""
        if level not in self.baked:
            mesh = self.mesh(level, "cone")
            if mesh is None:
                return None
            baked = bake_textures([mesh])
            self.baked[level] = {"textures": {n: baked.get(n) for n in mesh.material_names
                                              if baked.get(n) is not None}}
        cached = self.baked[level]
        if kind not in cached:      # one array per map: the raster renderer keys its texture by them
            cached[kind] = {n: _MAP_TEXELS[kind](t) for n, t in cached["textures"].items()}
        return cached[kind]

    def texture_bytes(self, level: int, kind: str) -> int:
        """GPU bytes of the maps' texture array (``kind`` as :meth:`maps`) at ``level``
        (mipmaps included), 0 over the budget."""
        maps = self.maps(level, kind)
        return 0 if maps is None else normal_map_bytes(self.model.names, maps)

    def skinned_mesh(self, level: int, surface: str):
        """The animation's mesh at rest on ``surface``, bound for vertex skinning (cached), or
        None over the triangle budget."""
        key = (level, surface)
        if key not in self.skinned:
            rest = self.model.animation.rest_frusta()[0]
            if triangle_count(len(rest), level, 0) > self.max_triangles:
                return None
            self.skinned[key] = self.model.animation.skinned(_tessellation(rest, level, surface))
        return self.skinned[key]

    def raster(self, key: str) -> RasterRenderer:
        """The raster renderer of configuration ``key`` (made on first use)."""
        if key not in self.rasters:
            self.rasters[key] = RasterRenderer(self.raycaster.ctx)
        return self.rasters[key]

    def render_config(self, cfg: Config, camera, *, conditions: bool = False,
                      t: float = 0.0) -> tuple[RenderResult | None, float]:
        """Render ``cfg`` once, under the paper's conditions if ``conditions``, at
        animation time ``t``; returns (RenderResult, frame ms including the per-frame CPU
        work the conditions ask for), or (None, nan) for a level over the budget."""
        frame = _Conditions.of(self.model, conditions)
        if cfg.ray_cast:
            return self._ray_cast(cfg, camera, frame, t)
        return self._rasterise(cfg, camera, frame, t)

    def _ray_cast(self, cfg: Config, camera, frame: _Conditions, t: float):
        m = self.model
        frusta, records, box, update_ms = m.frusta, None, None, 0.0
        leaves = frame.leaves
        if frame.animated:
            frusta, records, update = m.animation.upload(self.records, t, camera.eye)
            box, update_ms = self.shadow_box, update.total_ms
            if leaves is not None:                       # the leaves move with their branches
                t0 = time.perf_counter()
                leaves = m.animation.leaves_at(t)
                update_ms += (time.perf_counter() - t0) * 1e3
        res = self.raycaster.render(frusta, camera, cfg.settings, m.names, m.light_dir, frame.ground,
                                    shadows=frame.shadows, shadow_box=box, record_buffer=records, leaves=leaves)
        return res, res.frame_ms + update_ms

    def _rasterise(self, cfg: Config, camera, frame: _Conditions, t: float):
        m = self.model
        extra_ms, leaves = 0.0, frame.leaves
        if frame.animated and m.animation.plan is not None:
            return self._rasterise_skinned(cfg, camera, frame, t)
        if frame.animated:
            t0 = time.perf_counter()
            frusta = m.animation.frusta_at(t)              # pose + re-skin, as RC does
            leaves = m.animation.leaves_at(t) if leaves is not None else None
            mesh = self.mesh(cfg.level, cfg.surface, frusta)  # re-tessellate
            extra_ms = (time.perf_counter() - t0) * 1e3
        else:
            frusta = m.frusta
            mesh = self.mesh(cfg.level, cfg.surface)
        if mesh is None:
            return None, float("nan")
        res = self.raster(cfg.key).render(mesh, frusta, camera, material_names=m.names,
                                          light_dir=m.light_dir, ground=frame.ground,
                                          shadows=frame.shadows,
                                          shadow_box=self.shadow_box if frame.animated else None,
                                          leaves=leaves, normal_maps=self._maps_of(cfg), parallax=cfg.parallax)
        upload_ms = res.stats.upload_ms if frame.animated else 0.0
        return res, res.frame_ms + extra_ms + upload_ms

    def _rasterise_skinned(self, cfg: Config, camera, frame: _Conditions, t: float):
        """An animated frame of GS / GS+R / GS+N / GS+POM: the mesh built once at rest, posed
        by the vertex shader from the pose buffer the compute program fills at ``t`` (its CPU
        time and the leaves' counted in the frame; the rasteriser draws a skinned mesh
        without maps, so GS+N is GS there, and GS+POM its outer shell)."""
        m = self.model
        mesh = self.skinned_mesh(cfg.level, cfg.surface)
        if mesh is None:
            return None, float("nan")
        poses, update = m.animation.pose_segments(self.records, t, camera.eye)
        t0 = time.perf_counter()
        leaves = m.animation.leaves_at(t) if frame.leaves is not None else None
        extra_ms = update.pose_ms + (time.perf_counter() - t0) * 1e3
        res = self.raster(cfg.key).render(mesh, m.animation.rest_frusta()[0], camera, material_names=m.names,
                                          light_dir=m.light_dir, ground=frame.ground, shadows=frame.shadows,
                                          shadow_box=self.shadow_box, leaves=leaves, poses=poses,
                                          bounds=m.animation.motion_box())
        return res, res.frame_ms + extra_ms

    def count_work(self, cfg: Config, camera):
        """The work of one counting render of ``cfg`` (no scene passes): fragments shaded
        and relief samples (:class:`plantgen.gl.result.WorkCounts`), None over the
        budget."""
        m = self.model
        if cfg.ray_cast:
            return self.raycaster.render(m.frusta, camera, cfg.settings, m.names, m.light_dir,
                                         count_work=True).stats.work
        mesh = self.mesh(cfg.level, cfg.surface)
        if mesh is None:
            return None
        return self.raster(cfg.key).render(mesh, m.frusta, camera, material_names=m.names, light_dir=m.light_dir,
                                           count_work=True, normal_maps=self._maps_of(cfg),
                                           parallax=cfg.parallax).stats.work

    def _maps_of(self, cfg: Config) -> dict | None:
        """The maps ``cfg`` draws with (GS+N, GS+POM), else None."""
        return None if cfg.maps is None else self.maps(cfg.level, cfg.maps)

    def release_raster(self, key: str) -> None:
        """Free the GPU buffers of ``key``'s raster renderer (the mesh stays cached)."""
        raster = self.rasters.pop(key, None)
        if raster is not None:
            raster.release()

    def keep_meshes(self, keys) -> None:
        """Drop the cached meshes other than ``keys`` ((level, surface) pairs), and the
        baked maps of levels not among them."""
        self.meshes = {k: v for k, v in self.meshes.items() if k in keys}
        self.baked = {k: v for k, v in self.baked.items() if any(level == k for level, _ in keys)}
        self.skinned = {k: v for k, v in self.skinned.items() if k in keys}

    def release(self) -> None:
        """Free every GL object: the raster renderers, the ray caster, the animation's."""
        for key in list(self.rasters):
            self.release_raster(key)
        self.raycaster.release()
        self.records.release()


#: How each kind of :attr:`Method.maps` reads a material's baked textures.
_MAP_TEXELS = {"normal": lambda baked: baked.normal, "parallax": parallax_map}


def _tessellation(frusta, level: int, surface: str) -> TessellatedMesh:
    """The bench's tessellation of ``frusta`` at ``level`` on ``surface`` (:attr:`Method.mesh`),
    tips capped."""
    if surface == "outer":
        return outer_shell_mesh(frusta, level, caps="tips")
    return tessellate(frusta, level, relief=surface == "relief", caps="tips")


def time_configs(renderers: Renderers, configs, camera, frames: int, *, conditions: bool,
                 passes: dict | None = None, reused: dict | None = None) -> dict:
    """Interleaved timing: one warm-up frame each, then ``frames`` rounds rendering every
    config once per round, round i at animation time (i + 1) / 30 s. A still scene's
    shadow map is drawn by each config's warm-up and reused by its timed frames (the
    renderers keep it while nothing it depends on changes); an animated scene's moves, so
    each frame draws its map.

    Returns {key: [ms, ...]} (empty for a level over the budget); ``passes``, if given,
    receives {key: the render passes of the warm-up frame}, ``reused`` {key: timed frames
    that reused their shadow map}.
    """
    samples = {c.key: [] for c in configs}
    alive = []
    for c in configs:
        res, _ = renderers.render_config(c, camera, conditions=conditions, t=0.0)
        if res is None:
            continue
        alive.append(c)
        if passes is not None:
            passes[c.key] = list(res.stats.passes)
    for i in range(frames):
        t = animation_time(i + 1)
        for c in alive:
            res, ms = renderers.render_config(c, camera, conditions=conditions, t=t)
            samples[c.key].append(ms)
            if reused is not None:
                reused[c.key] = reused.get(c.key, 0) + int(res.stats.shadow_cached)
    return samples


def time_after_warm_up(render, frames: int) -> tuple[RenderResult, list[RenderResult]]:
    """Call ``render()`` once to warm up (shader compilation, first upload), then ``frames``
    times in a row; returns (the warm-up result, the timed results)."""
    first = render()
    return first, [render() for _ in range(frames)]
