"""The viewer's frames: the current state drawn by the same
:class:`~plantgen.gl.raycast.Raycaster` (RC, RC+R), :class:`~plantgen.gl.rt.RayTracer`
(RT, RT+R) and :class:`~plantgen.gl.raster.RasterRenderer` (GS, GS+R) as ``plantgen
render``, with the same arguments (:func:`plantgen.pipeline.frame_arguments`), so a saved
camera reproduces a frame pixel for pixel; functions over a
:class:`~plantgen.viewer.state.ViewerState`."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..geometry.meshes.mesh import tessellate
from ..geometry.rays.instances import PlacedPlants
from ..gl.pose import PoseStream
from ..gl.raster import RasterRenderer
from ..gl.rt import RayTracer
from ..pipeline import frame_arguments, ground_asked, stage_model
from .options import FrameStats
from .state import ViewerState

__all__ = ["draw", "caster", "skinned_mesh", "current", "release"]


def draw(state: ViewerState, width: int, height: int):
    """Render the current frame at ``width`` x ``height`` (the window's pixels);
    returns the :class:`~plantgen.gl.result.RenderResult`."""
    if (width, height) != (state.camera.width, state.camera.height):
        state.camera = replace(state.camera, width=int(width), height=int(height))
    t0 = time.perf_counter()
    if state.posing_on_gpu():
        request = state.request()
        settings, shadow = request.frame(state.effects())
        staging = stage_model(state.model.grown, state.model.anim.rest_frusta()[0], width, height,
                              camera=state.camera, ground=ground_asked(state.options.settings.image))
        return _drawn(state, _draw_posed(state, staging, request, settings, _merged_caster(state, shadow)), t0)
    frusta = state.frusta()
    staging = stage_model(state.model.grown, frusta, width, height, camera=state.camera,
                          ground=ground_asked(state.options.settings.image))
    request = state.request()
    settings, shadow = request.frame(state.effects())
    args = frame_arguments(frusta, staging, shadow, request.image)
    if shadow is not None and state.playing and state.model.animated:
        args["shadow_box"] = _playing_shadow_box(state)
    if state.model.animated:
        args["leaves"] = state.leaves()     # moved with their branches
    if state.raster is None and state.method.startswith("GS"):
        state.raster = RasterRenderer(state.ctx)
    if isinstance(frusta, PlacedPlants):   # a forest: instanced, its detail as the knob says
        args["shadows"] = _merged_caster(state, shadow)
        return _drawn(state, _draw_placed(state, frusta, args, settings, request.lod_pixels(state.effects())), t0)
    if not state.method.startswith("GS"):
        result = caster(state).render(frusta, settings=settings, **args)
    else:
        result = state.raster.render(state.mesh(frusta), frusta, **args)
    return _drawn(state, result, t0)


def _draw_posed(state: ViewerState, staging, request, settings, shadow):
    """A playing frame posed on the GPU: RC and RC+R draw the records the compute
    program writes; GS and GS+R the mesh built once at rest, posed by the vertex shader."""
    anim = state.model.anim
    if state.stream is None or state.stream[0] is not state.model:
        _release_stream(state)
        state.stream = (state.model, PoseStream(state.ctx))
    stream = state.stream[1]
    rest = anim.rest_frusta()[0]
    args = frame_arguments(rest, staging, shadow, request.image)
    if shadow is not None:
        args["shadow_box"] = _playing_shadow_box(state)
    args["leaves"] = anim.leaves_at(state.t)
    if not state.method.startswith("GS"):
        if state.method.startswith("RT") and not state.rt_playing_said:
            state.warn("RT traces still frames: a playing animation posed on the GPU is drawn by RC")
            state.rt_playing_said = True
        rows, records, _ = anim.upload(stream, state.t, state.camera.eye)
        return state.raycaster.render(rows, settings=settings, record_buffer=records, **args)
    if state.raster is None:
        state.raster = RasterRenderer(state.ctx)
    poses, _ = anim.pose_segments(stream, state.t, state.camera.eye)
    return state.raster.render(skinned_mesh(state, rest), rest, poses=poses, bounds=anim.motion_box(), **args)


def _merged_caster(state: ViewerState, shadow):
    """The shadow knobs of a frame the mesh caster cannot cast (posed on the GPU, or a
    scene drawn instanced: ``--shadow-caster mesh`` casts still frusta drawn merged):
    the march's instead, said once; other knobs as they are. GS and GS+R cast their own
    meshes whatever the caster, so theirs stay as asked."""
    if shadow is None or shadow.caster != "mesh" or state.method.startswith("GS"):
        return shadow
    if not state.mesh_caster_said:
        state.warn("--shadow-caster mesh casts still frusta drawn merged: this model's playing or instanced "
                   "frames cast with the relief march")
        state.mesh_caster_said = True
    return replace(shadow, caster="relief")


def _draw_placed(state: ViewerState, placed: PlacedPlants, args: dict, settings, lod_pixels: float):
    """A placed scene's frame: RC and RC+R from its records per plant, RT and RT+R
    through its two-level BVH, GS and GS+R from its meshes per plant."""
    if not state.method.startswith("GS"):
        return caster(state).render(placed, settings=settings, lod_pixels=lod_pixels, **args)
    keep = {k: v for k, v in args.items() if k not in ("material_names", "leaves")}
    return state.raster.render_placed(state.mesh(placed), lod_pixels=lod_pixels, **keep)


def caster(state: ViewerState):
    """The ray caster (RC, RC+R) or the ray tracer (RT, RT+R) of the method."""
    if not state.method.startswith("RT"):
        return state.raycaster
    if state.tracer is None:
        state.tracer = RayTracer(state.ctx, limits=state.options.limits)
    return state.tracer


def skinned_mesh(state: ViewerState, rest):
    """The playing animation's GS / GS+R mesh at rest, bound for vertex skinning (cached)."""
    relief = state.method == "GS+R"
    key = (state.model, state.level, relief)
    if state.skinned is None or state.skinned[0] != key:
        state.skinned = None
        state.skinned = (key, state.model.anim.skinned(tessellate(rest, state.level, relief=relief)))
    return state.skinned[1]


def _release_stream(state: ViewerState) -> None:
    if state.stream is not None:
        state.stream[1].release()
        state.stream = None


def _drawn(state: ViewerState, result, t0: float):
    """Keep ``result`` as the last frame and its times for the heads-up line."""
    state.last = result
    state.frames.append(FrameStats(result.frame_ms, (time.perf_counter() - t0) * 1e3, time.monotonic()))
    state.dirty = False
    return result


def _playing_shadow_box(state: ViewerState):
    """One light window for the whole animation while it plays (shadows do not shimmer)."""
    if state.shadow_box is None or state.shadow_box[0] is not state.model:
        times = np.linspace(0.0, 10.0, 16, endpoint=False)
        state.shadow_box = (state.model, state.model.anim.bounds(times))
    return state.shadow_box[1]


def current(state: ViewerState):
    """The frame of the current state: the last one, drawn again first if anything
    changed since (a key pressed in the same moment as P or C counts)."""
    if state.dirty or state.last is None:
        draw(state, state.camera.width, state.camera.height)
    return state.last


def release(state: ViewerState) -> None:
    """Free the renderers' GL objects."""
    _release_stream(state)
    state.raycaster.release()
    if state.tracer is not None:
        state.tracer.release()
    if state.raster is not None:
        state.raster.release()
