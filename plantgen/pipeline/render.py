"""``plantgen render`` from a grown model to the image, top to bottom: the model made
ready to draw, then the render.

- :func:`prepare_model`: a grown input (:func:`~plantgen.pipeline.growing.grow_file`)
  with its effects settled and its animation ready (what ``plantgen render`` and
  ``plantgen view`` draw); :func:`skinning` / :func:`skin_model`: the skin every command
  uses (``plantgen export`` and ``plantgen scan`` too);
- :func:`stage_model`: what a renderer needs of a grown model besides its frusta (camera,
  light, ground), from the scene where there is one; :func:`frame_arguments`: the
  renderers' arguments for one frame, in one place (the knobs come whole, as a
  :class:`~plantgen.settings.RenderSettings`);
- the render's budget (:func:`estimate_render_bytes`, checked before anything is skinned
  and again once the segments are known) and its outputs' checks (:func:`check_render_outputs`);
- :func:`render_model` (``plantgen.render``): skin and ray cast, in memory;
  :func:`render_file` (``plantgen render``): the same, then write PNG / GIF / WebP, the
  camera JSON and the depth ``.npy``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..animation import AnimatedScene
from ..errors import PlantgenError
from ..files import check_outputs, write_all_atomically
from ..geometry.meshes.polygons import Polygons
from ..geometry.rays.camera import Camera, Orbit, auto_camera, orbit_view
from ..geometry.rays.instances import PlacedPlants
from ..geometry.skeletons.frusta import Frusta, frusta_bounds
from ..geometry.skeletons.skin import skin_skeleton
from ..geometry.stage import MODEL_LIGHT, Ground, model_ground
from ..gl.context import renderer_name
from ..gl.frame import coverage_aa
from ..gl.pose import PoseStream
from ..gl.raycast import Raycaster
from ..gl.records import RecordStream
from ..gl.result import RenderResult
from ..gl.rt import RayTracer, choose_method
from ..images import (
    ANIMATION_SUFFIXES,
    IMAGE_FORMATS,
    TRANSPARENT,
    check_transparency,
    image_format,
    parse_background,
    write_animation,
    write_image,
)
from ..limits import MAX_IMAGE_SIDE, LimitError, Limits, hint
from ..scene import Scene
from ..settings import (
    DEFAULT_SIZE,
    EffectSettings,
    ImageSettings,
    MotionSettings,
    RaycastSettings,
    RenderSettings,
    ShadowSettings,
    ViewSettings,
    option_names,
)
from .checks import SKIN_BYTES_PER_SEGMENT, check_finite_frusta, distinct_segments, in_force
from .growing import GrowResult, grow_file


# ---------------------------------------------------------------------- model -> renderer
@dataclass(frozen=True)
class Staging:
    """What a renderer needs of a model besides its frusta: the view, the light (``light_dir``
    (3,) towards it) and the ground (None: none drawn)."""

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
                camera: Camera | None = None, orbit: Orbit | None = None, ground: str | None = None) -> Staging:
    """The scene's camera (at ``width`` x ``height``), light and ground; for a grammar or a
    skeleton, or a scene whose camera is ``auto``, the model framed to fill the view
    (:func:`auto_camera`) and the default model light. ``camera`` replaces the view;
    ``orbit`` then turns, moves or zooms it around its target (:func:`orbit_view`; a
    framed view is framed anew from the new direction). ``ground`` is ``--ground``
    (:class:`~plantgen.settings.ImageSettings`): ``auto`` puts a single plant on its
    ground disc (:func:`model_ground`), ``none`` drops every ground; ``scene`` or None
    (the benches') keep the scene's ground only, as the paper's figures were measured."""
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
        floor = model_ground(_model_box(frusta, points)) if ground == "auto" else None
        return Staging(camera, tuple(MODEL_LIGHT.towards()), floor, leaves)
    return Staging(camera, tuple(scene.light.towards()), None if ground == "none" else scene.ground, leaves)


def ground_asked(image: ImageSettings) -> str:
    """``--ground`` as a render stages it (:func:`stage_model`): ``auto`` draws no ground
    disc under a single plant on a transparent background (the alpha stays the plant's
    coverage; a scene keeps its ground)."""
    if image.ground == "auto" and parse_background(image.background) is not None \
            and parse_background(image.background)[3] < 1:
        return "scene"
    return image.ground


def _model_box(frusta: Frusta, points) -> np.ndarray:
    """(2, 3) world box of a model's frusta (a placed scene's copies) and ``points``."""
    box = frusta.box if isinstance(frusta, PlacedPlants) else frusta_bounds(frusta)
    if points is not None and len(points):
        box = np.stack([np.minimum(box[0], points.min(axis=0)), np.maximum(box[1], points.max(axis=0))])
    return box


def skinning(smooth_bends: float | None = None):
    """The skinning function the commands use: :func:`skin_skeleton`, with bends past
    ``smooth_bends`` degrees smoothed into arcs when given (``--smooth-bends``)."""
    return skin_skeleton if smooth_bends is None else functools.partial(skin_skeleton, smooth_bends=smooth_bends)


def smoothing(grown: GrowResult, smooth_bends):
    """The command line's ``--smooth-bends``, else the grammar's ``turtle: smooth_bends``."""
    return smooth_bends if smooth_bends is not None else grown.smooth_bends


def skin_model(grown: GrowResult, smooth_bends: float | None = None, source=None) -> Frusta:
    """A still grown model's frusta, skinned as ``plantgen render`` and ``plantgen export``
    skin it: bends past ``smooth_bends`` degrees (``--smooth-bends``), else past the
    grammar's ``turtle: smooth_bends``, smoothed into arcs (:func:`skinning`); every row
    checked finite (:func:`check_finite_frusta`, naming ``source``, default the model's name)."""
    frusta = skinning(smoothing(grown, smooth_bends))(grown.skeleton)
    return check_finite_frusta(frusta, grown.name if source is None else source)


def animate_model(grown: GrowResult, effects, smooth_bends: float | None = None) -> AnimatedScene:
    """The model as an :class:`AnimatedScene`: a scene's instances moving as their motion
    says when ``effects`` hold ``animation``; otherwise skinned once (by :func:`skinning`)."""
    if grown.scene is not None and "animation" in effects:
        return AnimatedScene.from_scene(grown.scene, skinning(smooth_bends))
    return AnimatedScene.still(grown.skeleton, skinning(smoothing(grown, smooth_bends)), model_leaves(grown))


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
                  budget=None, jobs: int | None = None) -> PreparedModel:
    """Grow or load ``input_path`` and settle its effects (``effects``, an
    :class:`~plantgen.settings.EffectSettings`, resolved against the scene's list);
    ``smooth_bends``: see :func:`skinning`. One line for a model with no segment. A still
    scene with the ``lod`` effect is placed (:func:`place_scene`), not merged. ``progress``:
    :func:`grow_file`'s, then the stage ``skin``. ``budget(segments, effects)``, if given,
    is called with the segments that will be skinned (every placed copy's, or a placed
    scene's distinct plants') before any is. ``jobs``: :func:`grow_file`'s."""
    grown = grow_file(input_path, seed=seed, iterations=iterations, limits=limits, allow_paths=allow_paths,
                      progress=progress, jobs=jobs)
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
            "ssaa": image.ssaa, "aa": image.aa, "leaves": staging.leaves}


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
    """A still's output (``.png``, ``.jpg`` or ``.webp``), checked before any work (one line)."""
    output = Path(output)
    image_format(output)
    return check_outputs([output])[0]


def check_render_outputs(output: Path, motion: MotionSettings, depth_out=None, camera_out=None) -> None:
    """Fail before any work on outputs :func:`render_file` cannot write: one line naming
    the file."""
    if motion.frames is not None:
        if output.suffix.lower() not in ANIMATION_SUFFIXES:
            raise PlantgenError(f"{output}: an animation (--frames) must end in .gif or .webp")
        if depth_out is not None:
            raise PlantgenError("--depth-out writes one frame: leave out --frames")
    elif output.suffix.lower() not in IMAGE_FORMATS:
        raise PlantgenError(f"{output}: the image output must end in .png, .jpg or .webp (or .gif/.webp with "
                            "--frames)")
    if depth_out is not None and Path(depth_out).suffix.lower() != ".npy":
        raise PlantgenError(f"{depth_out}: the depth output must end in .npy")
    if camera_out is not None and Path(camera_out).suffix.lower() != ".json":
        raise PlantgenError(f"{camera_out}: the camera output must end in .json")
    check_outputs([output, camera_out, depth_out])


# Memory a render takes, measured (tracemalloc and the GL targets' sizes) and rounded up (and
# checks.SKIN_BYTES_PER_SEGMENT each skinned segment):
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
    supersampling or coverage anti-aliasing and ``exact_distance``, the distances come from
    one more draw at one sample a pixel (rays through the pixel centres). The shadow map is drawn by the first
    draw and reused by the others (the light, the geometry and the map stay). Returns
    (result, frame ms, distances, ShadowUse)."""
    runs = [raycaster.render(frusta, **view) for _ in range(int(timed_frames) + 1 if timed_frames else 1)]
    result = runs[-1]
    frame_times = [r.frame_ms for r in (runs[1:] if timed_frames else runs)]
    distance = result.distance
    if exact_distance and (view["ssaa"] > 1 or coverage_aa(view["aa"], view["ssaa"], False, view["background"])):
        distance = raycaster.render(frusta, **{**view, "ssaa": 1, "aa": "none"}).distance
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
                 allow_paths=(), smooth_bends=None, jobs: int | None = None, **options) -> RenderReport:
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
    limits, allow_paths, jobs : the budgets in force (``max_render_bytes`` bounds the memory
        the render is estimated to take, before any is allocated), the folders a scene may
        read grammars from, and the processes its plants may grow in (:func:`grow_file`)
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
                          allow_paths=allow_paths, smooth_bends=smooth_bends, progress=progress, budget=budget,
                          jobs=jobs)
    _check_render_memory(limits, str(input_path), width, height, frames,
                         shadow_res if "shadows" in model.effects else None, model.skinned_segments, image.ssaa)
    if frames is not None and model.placed is not None:
        raise PlantgenError(f"{input_path}: a scene drawn with the lod effect is a still (leave out --frames)")
    frusta = model.frusta_at(motion.start)
    staging = stage_model(model.grown, frusta, width, height, camera=camera, orbit=request.view.orbit,
                          ground=ground_asked(image))
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
               else (lambda p: write_image(p, result.color)))]
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
    """:func:`render_model`, then write the image: a PNG, JPEG or WebP by its suffix (RGBA
    over a transparent background: a JPEG refuses it, before any work), or with ``frames``
    an animated GIF/WebP; optionally the camera JSON
    (``camera_out``) and the depth ``.npy`` (``depth_out``: float32 (height, width)
    distances along each pixel's ray from the eye, ``inf`` for a miss, row 0 the top row
    of the PNG; with supersampling, from one more draw through the pixel centres).
    ``options`` are :func:`render_model`'s. Every output is written atomically, and the
    outputs are checked before any work (one line naming a file that cannot be written)."""
    output = Path(output)
    keywords = {k: options.pop(k) for k in option_names(RenderSettings) if k in options}
    request = request_settings(settings, keywords)
    check_render_outputs(output, request.motion, depth_out, camera_out)
    if request.motion.frames is None:
        check_transparency(output, parse_background(request.image.background) == TRANSPARENT)
    report = render_model(input_path, request, exact_distance=depth_out is not None, **options)
    report.written = _write_render_outputs(output, report, camera_out, depth_out)
    return report
