"""The application layer: input files -> skeleton -> renderer or mesh -> output files.

Every stage below is a pure function or a renderer that knows nothing of files or of the
command line; this module glues them, and it is what ``plantgen.cli`` and the Python API
call:

- :func:`grow_file` / :func:`grow` (``plantgen grow``): a grammar, scene or skeleton
  ``.npz`` to a :class:`~plantgen.geometry.skeleton.Skeleton`, with the time of each stage;
- :func:`prepare_model`: a grown input with its effects settled and its animation ready
  (what ``plantgen render`` and ``plantgen view`` draw);
- :func:`stage_model`: what a renderer needs of a grown model besides its frusta (camera,
  light, ground), from the scene where there is one; :func:`frame_arguments`: the
  renderers' arguments for one frame, in one place (the knobs come whole, as a
  :class:`~plantgen.settings.RenderSettings`);
- :func:`render_model` (``plantgen.render``): skin and ray cast, in memory;
  :func:`render_file` (``plantgen render``): the same, then write PNG / GIF / WebP, the
  camera JSON and the depth ``.npy``;
- :func:`export_model` (``plantgen export``): skin, tessellate, write a mesh file (a
  scene's repeated plants once, instanced, where the format can); or write the skeleton
  as SWC or a forestry cylinder model.

Every entry point takes ``limits`` (the budgets in force, :class:`plantgen.limits.Limits`;
default: ``plantgen.limits.limits``) and ``allow_paths`` (folders a scene may read grammars
from besides its own). One input's derivations share one ``derive_work`` meter, and a
render or an export estimates its memory from the sizes it knows before it allocates.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..animation import AnimatedScene
from ..assets import AssetSettings, asset_lines, budget_warnings, finished_plants
from ..errors import PlantgenError
from ..exporters import (
    DetailLevel,
    ExportError,
    Plant,
    PlantDetail,
    PlantSway,
    SceneExtras,
    Timeline,
    check_extra,
    estimate_export_bytes,
    export_format,
    sway_timeline,
    write_plants,
    write_skeleton,
)
from ..exporters.formats import check_export_outputs
from ..exporters.plants import level_plant
from ..exporters.textures import bake_textures, split_by_aspect
from ..files import check_outputs, write_all_atomically
from ..geometry.camera import Camera, Orbit, auto_camera, orbit_view
from ..geometry.frames import UP_AXES
from ..geometry.frusta import Frusta, frusta_bounds
from ..geometry.instances import PlacedPlants, detail_levels, detail_order, screen_coverage
from ..geometry.mesh import tessellate, triangle_count
from ..geometry.polygons import Polygons
from ..geometry.skeleton import Skeleton
from ..geometry.skin import skin_skeleton
from ..geometry.stage import MODEL_LIGHT, Ground
from ..gl.context import renderer_name
from ..gl.pose import PoseStream
from ..gl.raycast import Raycaster
from ..gl.records import RecordStream
from ..gl.result import RenderResult
from ..gl.rt import RayTracer, choose_method
from ..images import ANIMATION_SUFFIXES, parse_background, write_animation, write_png
from ..limits import MAX_IMAGE_SIDE, LimitError, Limits, hint
from ..scene import Scene
from ..settings import (
    DEFAULT_SIZE,
    DetailSettings,
    EffectSettings,
    ImageSettings,
    KeyframeSettings,
    LevelSettings,
    MotionSettings,
    RaycastSettings,
    RenderSettings,
    ShadowSettings,
    ViewSettings,
    option_names,
)
from .checks import SKIN_BYTES_PER_SEGMENT, check_finite_frusta, check_finite_mesh, distinct_segments, in_force
from .growing import (
    GrowResult,
    existing_input,
    grow,
    grow_file,
    load_input,
    load_skeleton,
    read_skeleton,
    resolve_input,
)
from .scan import SCAN_BYTES_PER_SEGMENT, check_scan_memory

__all__ = ["GrowResult", "grow", "grow_file", "load_skeleton", "load_input", "read_skeleton", "resolve_input",
           "existing_input",
           "Staging", "stage_model", "model_leaves", "PreparedModel", "prepare_model", "place_scene",
           "frame_arguments", "request_settings", "RenderReport", "ShadowUse",
           "check_finite_frusta", "check_finite_mesh", "skin_model", "check_render_outputs",
           "estimate_render_bytes", "render_model", "render_file", "export_model", "INSTANCING", "check_export_size",
           "scene_extras", "check_sway_size", "check_scan_memory", "SCAN_BYTES_PER_SEGMENT"]

# ---------------------------------------------------------------------- model -> renderer
@dataclass(frozen=True)
class Staging:
    """What a renderer needs of a model besides its frusta: the view, the light (``light_dir``
    (3,) towards it) and the ground (None without a scene's ground)."""

    camera: Camera
    light_dir: tuple
    ground: Ground | None
    leaves: Polygons | None = None   # the model's leaf polygons, drawn beside the frusta


def model_leaves(grown: GrowResult) -> Polygons | None:
    """The grown model's leaf polygons (a grammar's ``{ . }`` and ``~`` surfaces), None if
    it has none: a model without leaves builds no leaf program and runs no leaf draw."""
    polygons = grown.polygons
    return polygons if polygons is not None and len(polygons.triangles) else None


def stage_model(grown: GrowResult, frusta: Frusta, width: int, height: int, *,
                camera: Camera | None = None, orbit: Orbit | None = None) -> Staging:
    """The scene's camera (at ``width`` x ``height``), light and ground; for a grammar or a
    skeleton, or a scene whose camera is ``auto``, the model framed to fill the view
    (:func:`auto_camera`) and the default model light. ``camera`` replaces the view;
    ``orbit`` then turns, moves or zooms it around its target (:func:`orbit_view`; a
    framed view is framed anew from the new direction)."""
    scene, leaves = grown.scene, model_leaves(grown)
    points = None if leaves is None else leaves.vertices
    framed = camera is None and (scene is None or scene.camera is None)
    if framed and isinstance(frusta, PlacedPlants):     # frame the copies' box
        camera = Camera.auto(frusta.box, width, height)
    if camera is None:
        camera = (scene.camera.at_size(width, height) if not framed
                  else auto_camera(frusta, width, height, points=points))
    if orbit is not None and not orbit.empty:
        reframe = None
        if framed:
            def reframe(direction, fov_y):
                return auto_camera(frusta, width, height, fov_y=fov_y, direction=direction, points=points)
        camera = orbit_view(camera, orbit, reframe)
    if scene is None:
        return Staging(camera, tuple(MODEL_LIGHT.towards()), None, leaves)
    return Staging(camera, tuple(scene.light.towards()), scene.ground, leaves)


def skinning(smooth_bends: float | None = None):
    """The skinning function the commands use: :func:`skin_skeleton`, with bends past
    ``smooth_bends`` degrees smoothed into arcs when given (``--smooth-bends``)."""
    return skin_skeleton if smooth_bends is None else functools.partial(skin_skeleton, smooth_bends=smooth_bends)


def _smoothing(grown: GrowResult, smooth_bends):
    """The command line's ``--smooth-bends``, else the grammar's ``turtle: smooth_bends``."""
    return smooth_bends if smooth_bends is not None else grown.smooth_bends


def skin_model(grown: GrowResult, smooth_bends: float | None = None, source=None) -> Frusta:
    """A still grown model's frusta, skinned as ``plantgen render`` and ``plantgen export``
    skin it: bends past ``smooth_bends`` degrees (``--smooth-bends``), else past the
    grammar's ``turtle: smooth_bends``, smoothed into arcs (:func:`skinning`); every row
    checked finite (:func:`check_finite_frusta`, naming ``source``, default the model's name)."""
    frusta = skinning(_smoothing(grown, smooth_bends))(grown.skeleton)
    return check_finite_frusta(frusta, grown.name if source is None else source)


def animate_model(grown: GrowResult, effects, smooth_bends: float | None = None) -> AnimatedScene:
    """The model as an :class:`AnimatedScene`: a scene's instances moving as their motion
    says when ``effects`` hold ``animation``; otherwise skinned once (by :func:`skinning`)."""
    if grown.scene is not None and "animation" in effects:
        return AnimatedScene.from_scene(grown.scene, skinning(smooth_bends))
    return AnimatedScene.still(grown.skeleton, skinning(_smoothing(grown, smooth_bends)), model_leaves(grown))


@dataclass
class PreparedModel:
    """An input grown and ready to draw, as ``plantgen render`` and ``plantgen view`` draw
    it: the grown model, the effects in force (the scene's list with the caller's
    overrides) and the :class:`AnimatedScene` (skinned once when nothing moves); or, for
    a still scene with the ``lod`` effect, its :class:`PlacedPlants` (each distinct plant
    skinned once, drawn instanced; ``anim`` is None)."""

    grown: GrowResult
    effects: tuple
    anim: AnimatedScene | None
    source: str
    placed: PlacedPlants | None = None

    @property
    def animated(self) -> bool:
        return self.anim is not None and self.anim.animated

    @property
    def skinned_segments(self) -> int:
        """Segments skinned (and held) for drawing: a placed scene's distinct plants', else all."""
        return self.placed.unique_rows if self.placed is not None else self.grown.segments

    def frusta_at(self, t: float = 0.0) -> Frusta | PlacedPlants:
        """Every frustum row at ``t`` seconds (a still model's rows at any t), checked
        finite; a placed scene's :class:`PlacedPlants`."""
        if self.placed is not None:
            return self.placed
        return check_finite_frusta(self.anim.frusta_at(float(t)), self.source)


def place_scene(scene: Scene, skin=skin_skeleton, source="scene") -> PlacedPlants:
    """A scene's distinct plants (:meth:`Scene.plants`), each skinned once in its own
    frame (checked finite), with its copies' placements: what the instanced renderers draw."""
    plants = []
    for plant in scene.plants():
        frusta = check_finite_frusta(skin(plant.skeleton), f"{source}: {plant.name}")
        plants.append((plant.name, frusta, plant.skeleton.parent, plant.matrices))
    return PlacedPlants.build(plants)


def prepare_model(input_path, *, effects: EffectSettings | None = None, seed=None, iterations=None,
                  limits: Limits | None = None, allow_paths=(), smooth_bends=None, progress=None,
                  budget=None) -> PreparedModel:
    """Grow or load ``input_path`` and settle its effects (``effects``, an
    :class:`~plantgen.settings.EffectSettings`, resolved against the scene's list);
    ``smooth_bends``: see :func:`skinning`. One line for a model with no segment. A still
    scene with the ``lod`` effect is placed (:func:`place_scene`), not merged. ``progress``:
    :func:`grow_file`'s, then the stage ``skin``. ``budget(segments, effects)``, if given,
    is called with the segments that will be skinned (every placed copy's, or a placed
    scene's distinct plants') before any is."""
    grown = grow_file(input_path, seed=seed, iterations=iterations, limits=limits, allow_paths=allow_paths,
                      progress=progress)
    if progress is not None:
        progress("skin", 0, None)
    chosen = (effects or EffectSettings()).resolve(grown.scene.effects if grown.scene is not None else ())
    if grown.segments == 0 and model_leaves(grown) is None:
        raise PlantgenError(f"{input_path}: nothing to render (no segments and no polygons)")
    placed = grown.scene is not None and "lod" in chosen and "animation" not in chosen
    if budget is not None:
        budget(distinct_segments(grown.scene) if placed else grown.segments, tuple(chosen))
    if placed:
        placed = place_scene(grown.scene, skinning(smooth_bends), str(input_path))
        return PreparedModel(grown, tuple(chosen), None, str(input_path), placed)
    return PreparedModel(grown, tuple(chosen), animate_model(grown, chosen, smooth_bends), str(input_path))


def frame_arguments(frusta: Frusta, staging: Staging, shadows, image: ImageSettings = ImageSettings()) -> dict:
    """The keyword arguments both renderers take for one frame of a staged model
    (``Raycaster.render`` adds ``settings``; ``RasterRenderer.render`` takes the mesh):
    ``shadows`` the shadow map's settings or None, ``image`` the background and the
    supersampling."""
    return {"camera": staging.camera, "material_names": frusta.material_names, "light_dir": staging.light_dir,
            "ground": staging.ground, "shadows": shadows, "background": parse_background(image.background),
            "ssaa": image.ssaa, "leaves": staging.leaves}


# ---------------------------------------------------------------------- plantgen render
@dataclass(frozen=True)
class ShadowUse:
    """The shadow map over a render's draws (warm-up included): ``drawn`` draws drew it,
    ``reused`` sampled a map drawn before (nothing it depends on had changed), ``ms`` the
    median milliseconds of the draws that drew it."""

    drawn: int
    reused: int
    ms: float

    @classmethod
    def of(cls, stats) -> ShadowUse | None:
        """The use over the draws' ``stats`` (RenderResult.stats); None without a shadow pass."""
        shadowed = [s for s in stats if "shadow" in s.passes]
        if not shadowed:
            return None
        drawn = [s.shadow_ms for s in shadowed if not s.shadow_cached]
        return cls(len(drawn), len(shadowed) - len(drawn), float(np.median(drawn)) if drawn else 0.0)


@dataclass
class RenderReport:
    """What :func:`render_model` / :func:`render_file` did: for the CLI to print and tests
    to check. ``frame_ms`` is the one draw's time (``timed`` = 0) or the median of
    ``timed`` draws after a warm-up; ``colors`` holds an animation's frames."""

    renderer: str
    segments: int          # skeleton segments
    rows: int              # frusta rows drawn (sharp bends add knuckle rows)
    frame_ms: float
    camera: Camera
    settings: RaycastSettings      # the ray caster's knobs as drawn (relief as the effects say)
    request: RenderSettings = RenderSettings()    # what was asked, whole
    written: list = field(default_factory=list)
    result: RenderResult | None = None
    effects: tuple = ()
    shadows: ShadowSettings | None = None
    frames: int = 1
    update_ms: float = 0.0         # median per-frame CPU update (pose, skin, pack, upload; or the dispatch)
    skin_calls: int = 0
    gpu_frames: int = 0            # frames posed and skinned on the GPU (the rest: on the CPU)
    timed: int = 0                 # draws the median was taken over (0: one untimed-median draw)
    colors: list = field(default_factory=list)
    distance: np.ndarray | None = None
    warnings: tuple = ()           # the turtle's warnings (GrowResult.warnings), for stderr
    shadow_use: ShadowUse | None = None    # how often the shadow map was drawn and reused
    placed: PlacedPlants | None = None     # a scene drawn instanced (the lod effect), else None
    lod_pixels: float = 0.0                # its level of detail's threshold


    @property
    def ssaa(self) -> int:
        return self.request.image.ssaa

    @property
    def background(self) -> tuple | None:
        return parse_background(self.request.image.background)


def check_image_output(output) -> Path:
    """A still's ``.png`` output, checked before any work (one line)."""
    output = Path(output)
    if output.suffix.lower() != ".png":
        raise PlantgenError(f"{output}: the image output must end in .png")
    return check_outputs([output])[0]


def check_render_outputs(output: Path, motion: MotionSettings, depth_out=None, camera_out=None) -> None:
    """Fail before any work on outputs :func:`render_file` cannot write: one line naming
    the file."""
    if motion.frames is not None:
        if output.suffix.lower() not in ANIMATION_SUFFIXES:
            raise PlantgenError(f"{output}: an animation (--frames) must end in .gif or .webp")
        if depth_out is not None:
            raise PlantgenError("--depth-out writes one frame: leave out --frames")
    elif output.suffix.lower() != ".png":
        raise PlantgenError(f"{output}: the image output must end in .png (or .gif/.webp with --frames)")
    if depth_out is not None and Path(depth_out).suffix.lower() != ".npy":
        raise PlantgenError(f"{depth_out}: the depth output must end in .npy")
    if camera_out is not None and Path(camera_out).suffix.lower() != ".json":
        raise PlantgenError(f"{camera_out}: the camera output must end in .json")
    check_outputs([output, camera_out, depth_out])


# Memory a render takes, measured (tracemalloc and the GL targets' sizes) and rounded up:
RENDER_BYTES_PER_PIXEL = 64      # colour, depth and distance targets, read-backs, the result's arrays
FRAME_BYTES_PER_PIXEL = 8        # one kept animation frame (RGB) and its share of the encoding
SHADOW_BYTES_PER_TEXEL = 8       # the shadow map's depth target and its read of it
def estimate_render_bytes(width: int, height: int, *, frames: int = 1, shadow_res: int | None = None,
                          segments: int = 0, ssaa: int = 1) -> int:
    """Bytes a render of ``width`` x ``height`` pixels takes (GPU and host together):
    the frame's targets (``ssaa``² samples a pixel), ``frames`` kept animation frames, the
    shadow map, the skinned ``segments``."""
    pixels = int(width) * int(height)
    return (pixels * int(ssaa) ** 2 * RENDER_BYTES_PER_PIXEL
            + (int(frames) * pixels * FRAME_BYTES_PER_PIXEL if frames > 1 else 0)
            + (int(shadow_res) ** 2 * SHADOW_BYTES_PER_TEXEL if shadow_res else 0)
            + int(segments) * SKIN_BYTES_PER_SEGMENT)


def _check_render_memory(limits: Limits, what: str, width, height, frames, shadow_res, segments=0,
                         ssaa: int = 1) -> None:
    """Refuse a render whose estimated memory is over ``limits.max_render_bytes``, or whose
    supersampled frame is over the largest image side."""
    if max(width, height) * ssaa > MAX_IMAGE_SIDE:
        raise LimitError(f"{what}: {width}x{height} pixels with {ssaa}x{ssaa} supersampling draw a "
                         f"{width * ssaa}x{height * ssaa} frame, over the largest side of {MAX_IMAGE_SIDE:,} "
                         "pixels (lower the size or the supersampling)")
    need = estimate_render_bytes(width, height, frames=frames or 1, shadow_res=shadow_res, segments=segments,
                                 ssaa=ssaa)
    if need > limits.max_render_bytes:
        parts = [f"{width}x{height} pixels", *([f"{frames:,} frames"] if frames and frames > 1 else []),
                 *([f"{segments:,} segments"] if segments else [])]
        raise LimitError(f"{what}: a render of {', '.join(parts)} needs about {need / 2**20:,.0f} MiB, over the "
                         f"limit of {limits.max_render_bytes / 2**20:,.0f} MiB ({hint('render_bytes')}; or lower "
                         "the size, the frames, the supersampling or the shadow resolution)")


def _render_frames(raycaster: Raycaster, anim: AnimatedScene, times, view: dict, progress, on_gpu: bool = True):
    """Render the animation at ``times`` after one warm-up frame (it pays for the driver's
    shader compilation), posed on the GPU (``on_gpu``: :class:`PoseStream`) or on the CPU.
    A :class:`RayTracer` takes each frame's rows posed on the CPU and refits its BVH to
    them (the refit and upload count as the frame's update).
    Returns (colours, frame ms, update ms, last result, frames posed on the GPU, ShadowUse)."""
    traced = isinstance(raycaster, RayTracer)
    stream = None if traced else PoseStream(raycaster.ctx) if on_gpu else RecordStream(raycaster.ctx)
    camera = view["camera"]
    colors, frame_times, update_times, gpu_frames = [], [], [], 0
    result, stats = None, []          # the last frame, and every frame's stats (the shadow map's use)
    try:
        for i, t in enumerate([times[0], *times]):
            if traced:
                fr, update = anim.posed(t)
                result = raycaster.render(fr, **{**view, "leaves": anim.leaves_at(t)})
                update.upload_ms = raycaster.last_build_ms + raycaster.last_upload_ms
            else:
                fr, buf, update = anim.upload(stream, t, camera.eye)
                result = raycaster.render(fr, record_buffer=buf, **{**view, "leaves": anim.leaves_at(t)})
            stats.append(result.stats)
            if i == 0:
                continue
            colors.append(result.color)
            frame_times.append(result.frame_ms)
            update_times.append(update.total_ms)
            gpu_frames += update.on_gpu
            if progress is not None:
                progress("frames", i, len(times))
    finally:
        if stream is not None:
            stream.release()
    return colors, frame_times, update_times, result, gpu_frames, ShadowUse.of(stats)


def _render_still(raycaster: Raycaster, frusta: Frusta, view: dict, timed_frames: int, exact_distance: bool):
    """One draw, or a warm-up and ``timed_frames`` timed draws (the last is kept). With
    supersampling and ``exact_distance``, the distances come from one more draw at one
    sample a pixel (rays through the pixel centres). The shadow map is drawn by the first
    draw and reused by the others (the light, the geometry and the map stay). Returns
    (result, frame ms, distances, ShadowUse)."""
    runs = [raycaster.render(frusta, **view) for _ in range(int(timed_frames) + 1 if timed_frames else 1)]
    result = runs[-1]
    frame_times = [r.frame_ms for r in (runs[1:] if timed_frames else runs)]
    distance = result.distance
    if exact_distance and view["ssaa"] > 1:
        distance = raycaster.render(frusta, **{**view, "ssaa": 1}).distance
    return result, frame_times, distance, ShadowUse.of([r.stats for r in runs])


def request_settings(settings: RenderSettings | None, options: dict) -> RenderSettings:
    """``settings`` whole, or built from flat keywords named as the command line's options
    (:meth:`RenderSettings.from_options`); not both."""
    if settings is not None and options:
        raise PlantgenError(f"give the settings whole or as keywords, not both ({', '.join(sorted(options))})")
    return settings if settings is not None else RenderSettings.from_options(**options)


def _render_camera(view: ViewSettings, size, limits: Limits) -> Camera | None:
    """The camera a render is given (a Camera, or a camera file's at ``size`` if given),
    None for ``auto``."""
    camera = view.camera
    if view.auto or camera is None:
        return None
    if not isinstance(camera, Camera):
        camera = Camera.load(camera, limits)
    if size is not None:
        camera = Camera(camera.eye, camera.target, camera.up, camera.fov_y, size[0], size[1])
    return camera


def _method_for(march: RaycastSettings, model: PreparedModel, frusta, pixels: int, lod_pixels: float,
                animated: bool, draws: int) -> RaycastSettings:
    """``march`` with its method chosen (:func:`~plantgen.gl.rt.choose_method`: ``auto``
    becomes rc or rt for this model, its rays and its draws)."""
    placed = model.placed
    return replace(march, method=choose_method(
        march.method, placed_rows=len(frusta), distinct_rows=placed.unique_rows if placed is not None else len(frusta),
        pixels=pixels, lod_pixels=lod_pixels if placed is not None else 0.0, animated=animated, labels=march.labels,
        draws=draws))


def render_model(input_path, settings: RenderSettings | None = None, *, seed=None, iterations=None,
                 timed_frames: int = 0, exact_distance: bool = False, progress=None, limits: Limits | None = None,
                 allow_paths=(), smooth_bends=None, **options) -> RenderReport:
    """Grow or load ``input_path`` (grammar, scene, skeleton ``.npz``/``.swc`` or shipped
    name), skin it and ray cast it as ``settings`` (a :class:`~plantgen.settings.RenderSettings`)
    ask; nothing is written (see :func:`render_file`).

    ``settings`` may instead be given as flat keywords named as ``plantgen render``'s
    options (``size=(w, h)``, ``relief=True``, ``linear_steps=16``, ``shadow_res=1024``,
    ``azimuth=60``, ``time=0.5``, ``frames=12``, ...: :meth:`RenderSettings.from_options`).

    Parameters
    ----------
    seed, iterations : override the file's
    timed_frames : 0 draws a still once; N draws a warm-up and N timed frames and the
        report quotes their median
    exact_distance : with supersampling, one more draw at one sample a pixel gives the
        distances through the pixel centres (else: the sub-sample nearest each centre)
    progress : ``progress(stage, done, total)``: :func:`prepare_model`'s stages, then
        ``render`` (a still) or ``frames`` (after each animation frame)
    limits, allow_paths : the budgets in force (``max_render_bytes`` bounds the memory the
        render is estimated to take, before any is allocated) and the folders a scene may
        read grammars from
    smooth_bends : None, or bends past this many degrees become arcs (:func:`skinning`)
    """
    limits, request = in_force(limits), request_settings(settings, options)
    if int(timed_frames) != timed_frames or int(timed_frames) < 0:
        raise PlantgenError("--time-frames must be an integer >= 0")
    image, motion = request.image, request.motion
    parse_background(image.background)       # a bad colour is one line before any work
    camera = _render_camera(request.view, image.size, limits)
    width, height = (camera.width, camera.height) if camera is not None else (image.size or DEFAULT_SIZE)
    frames, shadow_res = motion.frames, request.shadows.resolution
    _check_render_memory(limits, str(input_path), width, height, frames, shadow_res, ssaa=image.ssaa)
    def budget(segments, effects):       # before any segment is skinned or any copy placed
        _check_render_memory(limits, str(input_path), width, height, frames,
                             shadow_res if "shadows" in effects else None, segments, image.ssaa)
    model = prepare_model(input_path, effects=request.effects, seed=seed, iterations=iterations, limits=limits,
                          allow_paths=allow_paths, smooth_bends=smooth_bends, progress=progress, budget=budget)
    _check_render_memory(limits, str(input_path), width, height, frames,
                         shadow_res if "shadows" in model.effects else None, model.skinned_segments, image.ssaa)
    if frames is not None and model.placed is not None:
        raise PlantgenError(f"{input_path}: a scene drawn with the lod effect is a still (leave out --frames)")
    frusta = model.frusta_at(motion.start)
    staging = stage_model(model.grown, frusta, width, height, camera=camera, orbit=request.view.orbit)
    march, shadows = request.frame(model.effects)
    lod_pixels = request.lod_pixels(model.effects)
    march = _method_for(march, model, frusta, width * height * image.ssaa ** 2, lod_pixels, frames is not None,
                        1 + int(timed_frames))
    view = {**frame_arguments(frusta, staging, shadows, image), "settings": march,
            **({"lod_pixels": lod_pixels} if model.placed is not None else {})}
    # an animation's frames refit the tracer's BVH to the posed rows (plantgen.gl.rt)
    raycaster = RayTracer(limits=limits, refit=frames is not None) if march.method == "rt" \
        else Raycaster(limits=limits)
    anim, colors, update_times = model.anim, [], []
    if frames is not None:
        times = motion.start + np.arange(int(frames)) / float(motion.fps)
        if shadows is not None and anim.animated and len(times) > 1:
            view["shadow_box"] = anim.bounds(times[:: max(len(times) // 8, 1)])   # one window
        colors, frame_times, update_times, result, gpu_frames, shadow_use = _render_frames(
            raycaster, anim, times, view, progress, motion.pose == "gpu")
        distance = result.distance
    else:
        gpu_frames = 0
        if progress is not None:
            progress("render", 0, None)
        result, frame_times, distance, shadow_use = _render_still(raycaster, frusta, view, timed_frames,
                                                                  exact_distance)
    return RenderReport(
        renderer=renderer_name(), segments=model.grown.segments, rows=len(frusta),
        frame_ms=float(np.median(frame_times)), camera=staging.camera, settings=march, request=request,
        result=result, effects=model.effects, shadows=shadows, frames=len(colors) or 1,
        update_ms=float(np.median(update_times)) if update_times else 0.0,
        skin_calls=anim.skin_calls if anim is not None else len(model.placed.plants),
        gpu_frames=gpu_frames,
        timed=int(timed_frames) if frames is None else len(colors), colors=colors, distance=distance,
        warnings=model.grown.warnings, shadow_use=shadow_use, placed=model.placed,
        lod_pixels=view.get("lod_pixels", 0.0))


def _write_render_outputs(output: Path, report: RenderReport, camera_out, depth_out) -> list:
    """The image, the camera and the depth, renamed into place together (all or none)."""
    result = report.result
    fps = report.request.motion.fps
    writes = [(output, (lambda p: write_animation(p, report.colors, fps)) if report.colors
               else (lambda p: write_png(p, result.color)))]
    if camera_out is not None:
        writes.append((camera_out, report.camera.save))
    if depth_out is not None:
        def save_depth(p):
            with open(p, "wb") as fh:
                np.save(fh, report.distance.astype(np.float32))
        writes.append((depth_out, save_depth))
    return write_all_atomically(writes)


def render_file(input_path, output, settings: RenderSettings | None = None, *, camera_out=None, depth_out=None,
                **options) -> RenderReport:
    """:func:`render_model`, then write the image: a PNG (RGBA over a transparent
    background), or with ``frames`` an animated GIF/WebP; optionally the camera JSON
    (``camera_out``) and the depth ``.npy`` (``depth_out``: float32 (height, width)
    distances along each pixel's ray from the eye, ``inf`` for a miss, row 0 the top row
    of the PNG; with supersampling, from one more draw through the pixel centres).
    ``options`` are :func:`render_model`'s. Every output is written atomically, and the
    outputs are checked before any work (one line naming a file that cannot be written)."""
    output = Path(output)
    keywords = {k: options.pop(k) for k in option_names(RenderSettings) if k in options}
    request = request_settings(settings, keywords)
    check_render_outputs(output, request.motion, depth_out, camera_out)
    report = render_model(input_path, request, exact_distance=depth_out is not None, **options)
    report.written = _write_render_outputs(output, report, camera_out, depth_out)
    return report


# ---------------------------------------------------------------------- plantgen export
#: How ``export_model`` writes a scene's repeated plants (see :func:`export_model`).
INSTANCING = ("nodes", "gpu", "off")


def export_model(input_path, output_path, *, level: int = 1, relief: bool = False,
                 seed: int | None = None, limits: Limits | None = None, allow_paths=(),
                 up: str | None = None, instancing: str = "nodes", unit: float = 1.0,
                 qsm_tolerance: float = 1e-3, progress=None, smooth_bends: float | None = None,
                 keyframes: KeyframeSettings | None = None, textures: bool = True,
                 aspect_step: float | None = None, detail: DetailSettings | None = None,
                 levels: LevelSettings | None = None, asset: AssetSettings | None = None) -> dict:
    """The library side of ``plantgen export``: input file -> skin -> tessellate -> file,
    or, for a skeleton format (``.swc``, ``.qsm.csv``, ``.qsm.mat``), input -> file.

    Parameters
    ----------
    input_path : a skeleton ``.npz`` or ``.swc``, a grammar or a scene
    output_path : the file; its suffix names the format (:mod:`plantgen.exporters.formats`)
    level, relief, up : the tessellation (GS, GS+R); ``"y"`` or ``"z"`` (default: the format's)
    instancing : how a scene's repeated plants are written where the format can
        (glTF, USD): ``"nodes"`` (the default) once, with one node per copy sharing the
        plant's mesh (core glTF, which every reader opens; USD instanceable references);
        ``"gpu"`` once, with glTF's ``EXT_mesh_gpu_instancing`` (required by the file) or
        a USD ``PointInstancer``; ``"off"`` every copy's own mesh, as OBJ, PLY and STL
    unit : metres per model unit (USD's ``metersPerUnit``; QSM files are in metres)
    qsm_tolerance : the cylinder model's volume tolerance (:mod:`plantgen.exporters.qsm`)
    progress : ``progress(stage, done, total)``: :func:`grow_file`'s stages, ``tessellate``, ``write``
    smooth_bends : None, or bends past this many degrees become arcs of frusta before the
        mesh is made (:func:`skinning`; the summary's ``smooth_segments`` counts the
        segments they add)
    keyframes : the keys of the sway a glTF or USD export writes for a scene that lists
        ``animation`` and sways (:class:`~plantgen.settings.KeyframeSettings`; None: its
        defaults, over one common period); a format without animation writes the
        plants at rest and says so in ``warnings``
    textures, aspect_step : the relief baked into maps for glTF, OBJ, USD (with ``relief``: base
        colour only); with ``aspect_step``, normal maps per aspect bucket (:func:`_textured`)
    levels, detail : the levels of detail glTF and USD write (:meth:`LevelSettings.export_levels`: ``--lod-levels``,
        else 4 for a scene listing ``lod``; :func:`plant_detail`), their coverages for ``detail.lod_pixels``
    asset : leaf cards, impostor, a game asset (:class:`~plantgen.assets.AssetSettings`; None: its defaults)

    Returns a summary dict: ``format``, ``up``, ``segments``, ``paths`` (every file
    written), ``path`` (the main one), ``timings`` (seconds per stage) and, for meshes,
    ``rows``, ``caps``, ``triangles`` and ``vertices`` (written), ``plants`` and
    ``copies`` (distinct plants and their copies), ``drawn`` (triangles with every copy),
    ``level``, ``relief``, ``leaf_triangles`` (the leaf polygons of a grammar, or of a scene's
    plants (once per distinct plant when instanced), beside the frusta and counted in
    ``triangles``, ``vertices`` and ``drawn``), ``animation`` (None, or the
    sway written: ``keys``, ``duration``, ``rate``, ``loops``, ``joints``, ``skins``),
    ``levels`` ([(rows, triangles)] per level of detail, summed over the plants written
    once; empty: none), ``scene`` (what of a scene's ``"camera"``, ``"light"`` and ``"ground"`` the file holds
    besides its plants: glTF and USD, :func:`scene_extras`; empty for a grammar), ``textures``
    (:func:`_texture_summary`); for a cylinder model, what :func:`~plantgen.exporters.qsm.write_qsm`
    returns. Triangles and memory are estimated before anything is built and refused over ``limits``.
    """
    output_path, limits = Path(output_path), in_force(limits)
    fmt, asset = _export_checks(output_path, up, instancing, asset or AssetSettings(), unit)
    up, t0 = up or fmt.up, time.perf_counter()
    grown = grow_file(input_path, seed=seed, limits=limits, allow_paths=allow_paths, progress=progress)
    _export_budget(grown, fmt, instancing, level, limits, input_path, output_path)
    for skeleton in _distinct_skeletons(grown, fmt.kind == "skeleton"):
        skeleton.validate()
    timings = {"load": time.perf_counter() - t0}
    summary = {"format": fmt.name, "up": up, "segments": grown.segments, "timings": timings,
               "warnings": grown.warnings}
    timeline = _export_timeline(grown, fmt, keyframes, input_path, summary)
    if fmt.kind == "skeleton":
        return _export_skeleton(grown, fmt, output_path, up, unit, qsm_tolerance, summary)
    skin = skinning(_smoothing(grown, smooth_bends))
    plants, smoothed = _tessellated_plants(grown, fmt, instancing if fmt.instancing else "off", level, relief, limits,
                                           input_path, output_path, timings, progress, skin, timeline,
                                           _export_detail(grown, fmt, asset.levels(levels), detail, summary))
    t3 = time.perf_counter()
    extras = scene_extras(grown, skin, input_path) if fmt.scene else None
    plants, baked = _finished(plants, asset, skin, relief, textures and fmt.textures and aspect_step, summary, progress)
    paths = write_plants(plants, output_path, up=up, instancing="gpu" if instancing == "gpu" else "nodes", unit=unit,
                         name=grown.name, progress=progress, animation=timeline, extras=extras, textures=baked)
    timings["write"] = time.perf_counter() - t3
    summary.update(_mesh_counts(plants), level=level, relief=relief, paths=paths, path=paths[-1],
                   smooth_segments=smoothed, animation=_animation_counts(plants, timeline),
                   scene=() if extras is None else tuple(k for k in ("camera", "light", "ground")
                                                         if getattr(extras, k) is not None),
                   textures=_texture_summary(baked))
    return summary


def _export_checks(output_path: Path, up: str | None, instancing: str, asset: AssetSettings, unit: float = 1.0):
    """The export's format and ``asset``, after every check that needs no work: a known
    suffix, its extra installed, the up axis, the instancing, what the asset asks (cards
    and impostors: glTF), the unit, every output writable (one line each)."""
    if not 1e-9 <= unit <= 1e9:          # so a cylinder model's volumes (unit³) stay finite
        raise ExportError(f"the unit must be 1e-09..1e+09 metres, got {unit!r}")
    fmt = export_format(output_path)
    check_extra(fmt, output_path)
    asset.check(fmt, output_path)
    if up is not None and up not in UP_AXES:
        raise ExportError(f"up must be one of {', '.join(UP_AXES)}, got {up!r}")
    if instancing not in INSTANCING:
        raise ExportError(f"instancing must be one of {', '.join(INSTANCING)}, got {instancing!r}")
    check_export_outputs(output_path, fmt)
    return fmt, asset


def _export_budget(grown: GrowResult, fmt, instancing: str, level: int, limits: Limits, input_path,
                   output_path) -> None:
    """Refuse, before anything is skinned, a model with no segment or a mesh export whose
    memory is over ``limits.max_export_bytes`` at its least: the segments it skins (every
    placed copy where the format or ``instancing`` writes each copy, else each distinct
    plant once), 16·4^m triangles each at the format's bytes; and for a glTF or USD scene
    framed automatically, the skin of every placed copy its camera is framed on."""
    if grown.segments == 0:
        raise ExportError(f"{input_path}: the model has no segments" + (
            " (its polygons alone are not exported; plantgen render and scan draw them)"
            if model_leaves(grown) is not None else ""))
    if fmt.kind != "mesh":
        return
    each = instancing == "off" or not fmt.instancing or grown.scene is None
    skinned = grown.segments if each else distinct_segments(grown.scene)
    triangles = skinned * 16 * 4 ** int(level)
    if triangles > limits.max_export_triangles:
        raise ExportError(f"{input_path}: m = {level} gives at least {triangles:,} triangles, over the export limit "
                          f"of {limits.max_export_triangles:,}; choose a lower --subdiv ({hint('export_triangles')})")
    need = estimate_export_bytes(triangles, fmt.name) + skinned * SKIN_BYTES_PER_SEGMENT
    what = f"{skinned:,} segments{'' if each else ' (each distinct plant once)'} at m = {level}"
    if fmt.scene and grown.scene is not None and grown.scene.camera is None \
            and grown.segments * SKIN_BYTES_PER_SEGMENT > need:     # the framed camera skins every copy
        need = grown.segments * SKIN_BYTES_PER_SEGMENT
        what = f"framing the scene's camera on its {grown.segments:,} placed segments"
    if need > limits.max_export_bytes:
        raise LimitError(f"{output_path}: {what} needs at least {need / 2**20:,.0f} MiB to build and write as "
                         f"{fmt.name}, over the limit of {limits.max_export_bytes / 2**20:,.0f} MiB (choose a "
                         f"lower --subdiv, give a scene a camera, or {hint('export_bytes')})")


def _distinct_skeletons(grown: GrowResult, merged: bool) -> list[Skeleton]:
    """The skeletons an export checks: the whole model (``merged``, or not a scene), else a
    scene's distinct plants, each once (placing a valid plant keeps it valid: a placed
    copy was checked finite when the scene was read)."""
    if merged or grown.scene is None:
        return [grown.skeleton]
    return [plant.skeleton for plant in grown.scene.plants()]


def _finished(plants: list[Plant], asset: AssetSettings, skin, relief: bool, aspect_step, summary: dict,
              progress=None) -> tuple[list[Plant], object]:
    """The plants as written (:func:`~plantgen.assets.finished_plants`: an impostor, leaf
    cards, where ``asset`` asks; a game asset's levels over their budgets are warned of in
    ``summary``) and their textures (:func:`_textured`; ``aspect_step`` False: none)."""
    plants = finished_plants(plants, asset, skin, relief, progress)
    summary["warnings"] = (*summary["warnings"], *budget_warnings(_level_counts(plants), asset))
    summary["asset_lines"] = asset_lines(plants)
    return (plants, None) if aspect_step is False else _textured(plants, relief, aspect_step)


def _textured(plants: list[Plant], relief: bool, aspect_step: float | None) -> tuple[list[Plant], object]:
    """The plants (split by aspect where ``aspect_step`` is given and the mesh is not
    displaced: :func:`~plantgen.exporters.textures.split_by_aspect`) and their baked maps
    (:func:`~plantgen.exporters.textures.bake_textures`)."""
    bases = None
    if aspect_step and not relief:
        plants, bases = split_by_aspect(plants, aspect_step)
    return plants, bake_textures([p.mesh for p in plants], displaced=relief, bases=bases)


def _texture_summary(baked) -> dict:
    """{material: {"size": (H, W), "aspect", "kinds"}} of the baked textures (empty: none)."""
    if baked is None:
        return {}
    return {name: {"size": t.size.shape, "aspect": t.aspect, "kinds": baked.kinds}
            for name, t in baked.materials.items()}


def _export_skeleton(grown: GrowResult, fmt, output_path: Path, up: str, unit: float, tolerance: float,
                     summary: dict) -> dict:
    """:func:`export_model` of a skeleton format: ``summary`` with what the writer returns
    (a warning when a grammar's leaves are left out)."""
    if grown.polygons is not None and len(grown.polygons):
        summary["warnings"] = (*summary["warnings"], f"{fmt.suffix} carries the skeleton only: "
                               f"{len(grown.polygons)} leaf polygons not written (a mesh format keeps them)")
    t1 = time.perf_counter()
    summary.update(write_skeleton(grown.skeleton, output_path, up=up, unit=unit, tolerance=tolerance,
                                  name=grown.name))
    summary["timings"]["write"] = time.perf_counter() - t1
    return dict(summary, path=summary["paths"][-1])


def scene_extras(grown: GrowResult, skin=skin_skeleton, source=None) -> SceneExtras | None:
    """What a glTF or USD export writes around a scene's plants: the camera ``plantgen
    render`` would use at its default size (the scene's camera, or for ``camera: auto``
    the model framed as :func:`stage_model` frames it, its frusta skinned with ``skin``),
    the scene's light and its ground; None for a grammar or a skeleton."""
    scene = grown.scene
    if scene is None:
        return None
    width, height = DEFAULT_SIZE
    if scene.camera is not None:
        camera = scene.camera.at_size(width, height)
    else:
        camera = stage_model(grown, check_finite_frusta(skin(grown.skeleton), source or grown.name), width,
                             height).camera
    return SceneExtras(camera, scene.light, scene.ground)


def _export_timeline(grown: GrowResult, fmt, keyframes: KeyframeSettings | None, input_path,
                     summary: dict) -> Timeline | None:
    """The key times of the sway an export writes: a scene that lists ``animation`` and
    sways, written in a format that animates, unless ``keyframes.sway`` is off; else None (a warning in ``summary`` says
    when a format without animation leaves a sway out)."""
    scene, keyframes = grown.scene, keyframes or KeyframeSettings()
    if scene is None or "animation" not in scene.effects or not keyframes.sway:
        return None
    sways = [i.motion for i in scene.instances]
    if not fmt.animation:
        if any(s is not None and s.moves for s in sways):
            summary["warnings"] = (*summary["warnings"], f"{fmt.suffix} holds no animation: the scene's sway is "
                                   "not written, its plants stand at rest (glTF and USD carry the sway)")
        return None
    return sway_timeline(sways, keyframes, input_path)


def _animation_counts(plants: list[Plant], timeline: Timeline | None) -> dict | None:
    """What the sway written holds (see :func:`export_model`), or None."""
    swaying = [p for p in plants if timeline is not None and p.sway is not None and p.sway.moves]
    if not swaying:
        return None
    return dict(keys=timeline.keys, duration=timeline.duration, rate=timeline.rate, loops=timeline.loops,
                joints=sum(len(p.skeleton) * p.copies for p in swaying), skins=sum(p.copies for p in swaying))


def _export_detail(grown: GrowResult, fmt, levels: LevelSettings | None, detail: DetailSettings | None,
                   summary: dict) -> tuple[int, float]:
    """(levels, pixels) of the levels of detail the export writes (:func:`plant_detail`):
    1 (none) for a format without them, where a warning in ``summary`` says so if they
    were asked for."""
    asked, pixels = levels or LevelSettings(), (detail or DetailSettings()).lod_pixels
    count = asked.export_levels(grown.scene.effects if grown.scene is not None else ())
    if count > 1 and not fmt.instancing:
        if asked.levels is not None:
            summary["warnings"] = (*summary["warnings"], f"{fmt.suffix} holds no levels of detail: the full "
                                   "mesh only (glTF and USD carry them)")
        return 1, pixels
    return count, pixels


def plant_detail(frusta: Frusta, parent, mesh, leaves: Polygons | None, levels: int, pixels: float,
                 relief: bool = False, height: int = DEFAULT_SIZE[1]) -> PlantDetail | None:
    """A plant's levels of detail (None for ``levels`` < 2, or a plant too small to have
    two): level k tessellates the rows of ``frusta`` (``parent``: the skeleton's) that
    :func:`~plantgen.geometry.instances.detail_levels` keeps, at ``mesh``'s level (with
    ``relief``: displaced), with the ``leaves`` hanging from a kept segment; the screen coverages are for
    ``pixels`` on an image ``height`` pixels high (:func:`screen_coverage`)."""
    if levels < 2:
        return None
    order, sizes = detail_order(frusta, parent)
    counts, thresholds = detail_levels(sizes, levels)
    if len(counts) < 2:
        return None
    out = [DetailLevel(np.arange(len(frusta)), mesh, np.arange(0 if leaves is None else len(leaves)), 0.0)]
    for count, size in zip(counts[1:].tolist(), thresholds[1:].tolist(), strict=True):
        rows = np.sort(order[:count])
        kept = np.flatnonzero(np.isin(leaves.segment, frusta.segment[rows])) if leaves is not None else np.zeros(0, int)
        out.append(DetailLevel(rows, tessellate(frusta.subset(rows), mesh.level, relief=relief), kept, size))
    box = frusta_bounds(frusta)
    diameter = float(np.linalg.norm(box[1] - box[0]))
    return PlantDetail(tuple(out), screen_coverage(thresholds, float(sizes[0]), diameter, pixels, height))


def _mesh_counts(plants: list[Plant]) -> dict:
    """What an export wrote: rows, caps, triangles, vertices, drawn, plants, copies and
    leaf_triangles (a grammar's leaves, counted in triangles, vertices and drawn too)."""
    meshes = [p.mesh for p in plants]
    leaves = [len(p.leaves.triangles) if p.has_leaves else 0 for p in plants]
    leaf_vertices = sum(len(p.leaves.vertices) for p in plants if p.has_leaves)
    return dict(rows=sum(m.n_rows for m in meshes), caps=sum(m.n_caps for m in meshes),
                triangles=sum(len(m.faces) for m in meshes) + sum(leaves),
                vertices=sum(len(m.vertices) for m in meshes) + leaf_vertices,
                drawn=sum((len(p.mesh.faces) + n) * p.copies for p, n in zip(plants, leaves, strict=True)),
                plants=len(plants), copies=sum(p.copies for p in plants), leaf_triangles=sum(leaves),
                levels=_level_counts(plants))


def _level_counts(plants: list[Plant]) -> list[tuple[int, int]]:
    """[(rows, triangles)] of each level of detail written, summed over the plants (each
    once; a plant with fewer levels counted at its last); empty when none has levels."""
    depth = max((len(p.detail.levels) for p in plants if p.detail is not None), default=0)
    out = []
    for k in range(depth):
        rows = triangles = 0
        for plant in plants:
            lod = 0 if plant.detail is None else min(k, len(plant.detail.levels) - 1)
            at = level_plant(plant, lod)
            rows += plant.mesh.n_rows if plant.detail is None else len(plant.detail.levels[lod].rows)
            triangles += len(at.mesh.faces) + (len(at.leaves.triangles) if at.has_leaves else 0)
        out.append((rows, triangles))
    return out


def _export_parts(grown: GrowResult, instanced: bool) -> list[tuple[str, Skeleton, np.ndarray | None,
                                                                   Polygons | None, tuple | None]]:
    """(name, skeleton in its own frame, placements or None, leaves in the same frame or
    None, sways) of every plant to write: a scene's distinct plants with their own
    grammar's leaves and their copies' placements when ``instanced``, else the whole model
    in place. ``sways`` (a scene's): (the sway group of each segment, per copy the
    :class:`~plantgen.geometry.stage.Sway` or None of each group), as
    :class:`~plantgen.exporters.PlantSway` takes them; None for a grammar or a skeleton."""
    scene = grown.scene
    if instanced and scene is not None:
        return [(p.name, p.skeleton, p.matrices, p.polygons,
                 (np.zeros(len(p.skeleton), np.int64), tuple((scene.instances[k].motion,) for k in p.instances)))
                for p in scene.plants() if len(p.skeleton)]
    sways = None if scene is None else (scene.segment_instance(), (tuple(i.motion for i in scene.instances),))
    return [(grown.name, grown.skeleton, None, grown.polygons, sways)]


def _leaves_of(polygons: Polygons | None, mesh, input_path) -> Polygons | None:
    """``polygons`` if any, their materials checked against the mesh's names; else None."""
    if polygons is None or len(polygons) == 0:
        return None
    if int(polygons.material.max()) >= len(mesh.material_names):
        raise ExportError(f"{input_path}: a leaf polygon has material {int(polygons.material.max())}, "
                          f"but the model names {len(mesh.material_names)} materials")
    return polygons


def check_export_size(frusta: list[Frusta], leaves: list, segments: int, level: int, fmt_name: str,
                      limits: Limits | None, source, output) -> int:
    """The triangles an export of ``frusta`` at level m and of ``leaves`` (Polygons or None,
    each written once) builds, refused before anything is built (one line naming ``source``
    or ``output``) over ``limits.max_export_triangles``, or over ``limits.max_export_bytes``
    to build and write as ``fmt_name`` with the skin of ``segments`` skeleton segments."""
    limits = in_force(limits)
    estimate = sum(triangle_count(len(f), level, int(f.open_lo.sum() + f.open_hi.sum())) for f in frusta)
    estimate += sum(len(p.triangles) for p in leaves if p is not None)
    if estimate > limits.max_export_triangles:
        raise ExportError(f"{source}: m = {level} gives {estimate:,} triangles, over the "
                          f"export limit of {limits.max_export_triangles:,}; choose a lower --subdiv "
                          f"({hint('export_triangles')})")
    need = estimate_export_bytes(estimate, fmt_name) + segments * SKIN_BYTES_PER_SEGMENT
    if need > limits.max_export_bytes:
        raise LimitError(f"{output}: m = {level} gives {estimate:,} triangles, about "
                         f"{need / 2**20:,.0f} MiB to build and write as {fmt_name}, over the limit of "
                         f"{limits.max_export_bytes / 2**20:,.0f} MiB; choose a lower --subdiv "
                         f"({hint('export_bytes')})")
    return estimate


def _tessellated_plants(grown: GrowResult, fmt, instancing: str, level: int, relief: bool, limits: Limits,
                        input_path, output_path, timings: dict, progress,
                        skin=skin_skeleton, timeline: Timeline | None = None,
                        detail: tuple[int, float] = (1, 0.0)) -> tuple[list[Plant], int]:
    """Skin every plant with ``skin``, check the export's triangles and memory against the
    limits (and its sway's keys, with a ``timeline``), and tessellate (``timings`` gains
    ``skin`` and ``tessellate``), each plant at ``detail`` = (levels, pixels)
    (:func:`plant_detail`); also the segments smooth bends added."""
    t1 = time.perf_counter()
    parts = _export_parts(grown, instancing != "off")
    frusta = [check_finite_frusta(skin(part[1]), input_path) for part in parts]
    t2 = time.perf_counter()
    timings["skin"] = t2 - t1
    copies = 2 if detail[0] > 1 else 1      # the lower levels hold under n/2 + n/4 + ... rows: under the full's
    check_export_size(frusta * copies, [part[3] for part in parts] * copies, sum(len(part[1]) for part in parts),
                      level, fmt.name, limits, input_path, output_path)
    if timeline is not None:
        check_sway_size([(len(part[1]), 1 if part[2] is None else len(part[2])) for part in parts
                         if part[4] is not None and any(s is not None and s.moves for c in part[4][1] for s in c)],
                        timeline, limits, output_path)
    plants = []
    for k, ((name, skel, matrices, leaves, sways), fr) in enumerate(zip(parts, frusta, strict=True)):
        mesh = tessellate(fr, level, relief=relief)
        check_finite_mesh(mesh, fr, input_path)
        sway = PlantSway(sways[0], sways[1], fr.segment) if timeline is not None and sways is not None else None
        leaves = _leaves_of(leaves, mesh, input_path)
        lod = plant_detail(fr, skel.parent, mesh, leaves, *detail, relief=relief)
        plants.append(Plant(name, skel, mesh, matrices, leaves=leaves, sway=sway, detail=lod))
        if progress is not None:
            progress("tessellate", k + 1, len(parts))
    timings["tessellate"] = time.perf_counter() - t2
    return plants, sum(f.report.smooth_segments for f in frusta)


#: Bytes a written joint takes apart from its keys (its node, skin entry, channel and
#: sampler, as Python objects and JSON), and a key while it is built and written
#: (float64 angles and quaternions, the float32 copy, the written bytes), rounded up.
SWAY_BYTES_PER_JOINT, SWAY_BYTES_PER_KEY = 2048, 160


def check_sway_size(plants, timeline: Timeline, limits: Limits | None, output) -> int:
    """The bytes writing a sway takes: ``plants`` [(segments, copies)] each a joint a
    segment for every copy, ``timeline.keys`` keys each; one line naming ``output`` over
    ``limits.max_export_bytes``."""
    limits = in_force(limits)
    joints = sum(segments * copies for segments, copies in plants)
    need = joints * (SWAY_BYTES_PER_JOINT + timeline.keys * SWAY_BYTES_PER_KEY)
    if need > limits.max_export_bytes:
        raise LimitError(f"{output}: the sway's {joints:,} joints x {timeline.keys:,} keys take about "
                         f"{need / 2**20:,.0f} MiB to build and write, over the limit of "
                         f"{limits.max_export_bytes / 2**20:,.0f} MiB; lower --key-rate or --duration "
                         f"({hint('export_bytes')})")
    return need
