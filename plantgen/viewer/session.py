"""What the viewer shows and how it changes, apart from any window: the model, the camera,
the method and its knobs, the time of an animated scene, a grammar's growth step by step,
live reload, and the frames,
drawn by the same :class:`~plantgen.gl.raycast.Raycaster` (RC, RC+R) and
:class:`~plantgen.gl.raster.RasterRenderer` (GS, GS+R) as ``plantgen render``, with the
same arguments (:func:`plantgen.pipeline.frame_arguments`), so a saved camera reproduces a
frame pixel for pixel.

A :class:`ViewerSession` needs only a moderngl context: the window (``window.py``) feeds it
events and presents its frames; the tests drive it headless too.
"""

from __future__ import annotations

import math
import shlex
import statistics
import time
from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import PlantgenError
from ..files import write_atomically
from ..geometry.camera import MAX_ELEVATION, Camera, Orbit, orbit_angles, orbit_view
from ..geometry.instances import PlacedMeshes, PlacedPlants
from ..geometry.mesh import tessellate, triangle_count
from ..gl.pose import PoseStream
from ..gl.raster import RasterRenderer
from ..gl.raycast import Raycaster
from ..gl.rt import RayTracer
from ..images import write_png
from ..knobs import knob_args, knob_of
from ..limits import Limits
from ..pipeline import PreparedModel, frame_arguments, prepare_model, stage_model
from ..settings import (
    DEFAULT_SIZE,
    MAX_SSAA,
    MAX_SUBDIV,
    EffectSettings,
    MeshSettings,
    MotionSettings,
    RaycastSettings,
    RenderSettings,
    ViewSettings,
)
from .keys import GROW_STEP_S, binding_for
from .watch import BackgroundJob, FileWatcher

__all__ = ["METHODS", "ViewOptions", "ViewerSession", "FrameStats", "one_line", "stored_triangles"]


def stored_triangles(frusta, level: int) -> int:
    """Triangles the GS mesh of ``frusta`` holds at ``level``: a placed scene's distinct
    plants once each (its copies share them)."""
    parts = [p.frusta for p in frusta.plants] if isinstance(frusta, PlacedPlants) else [frusta]
    return sum(triangle_count(len(f), level, int(f.open_lo.sum() + f.open_hi.sum())) for f in parts)

#: The methods of Table 1, as the keys 1..4 choose them.
METHODS = ("RC", "RC+R", "GS", "GS+R", "RT", "RT+R")

#: The most triangles a GS level may have in the viewer (the level is refused above).
VIEW_MAX_TRIANGLES = 24_000_000

#: Degrees the view turns per pixel of a left drag.
DRAG_TURN = 0.4

#: How many frames the heads-up line's medians look back.
HUD_FRAMES = 30



def one_line(exc: BaseException) -> str:
    """An exception as the viewer shows it: a PlantgenError's message, else its class and
    message, on one line."""
    text = " ".join(str(exc).split()) or exc.__class__.__name__
    if not isinstance(exc, PlantgenError):
        text = f"unexpected failure: {exc.__class__.__name__}: {text}"
    return text[:300]


@dataclass
class ViewOptions:
    """How ``plantgen view`` was asked to start (its options; see ``plantgen view --help``):
    the render settings whole (:class:`~plantgen.settings.RenderSettings`), the window's
    ``size``, and what only the viewer has (the method, the GS level, shots, watching)."""

    input: Path
    settings: RenderSettings = RenderSettings()
    size: tuple = DEFAULT_SIZE
    seed: int | None = None
    iterations: int | None = None
    method: str | None = None
    level: int = MeshSettings().level
    shots: Path = Path(".")
    watch: bool = True
    poll_s: float = 0.025
    snapshot: Path | None = None
    limits: Limits | None = None
    allow_paths: tuple = ()
    smooth_bends: float | None = None

    def prepare(self, iterations: int | None = None) -> PreparedModel:
        """Grow the input with these options (the first model, and each reload); a grammar
        ``iterations`` steps deep when given (a growth step), else as the options say."""
        iterations = self.iterations if iterations is None else iterations
        return prepare_model(self.input, effects=self.settings.effects, seed=self.seed, iterations=iterations,
                             limits=self.limits, allow_paths=self.allow_paths, smooth_bends=self.smooth_bends)


@dataclass
class FrameStats:
    """One drawn frame: the renderer's frame ms (draw to finish) and the wall ms of the
    whole frame (skin or pose, draw, read-back), when it was drawn."""

    frame_ms: float
    wall_ms: float
    at: float


class ViewerSession:
    """The viewer's state and its frames (see the module's docstring).

    Parameters
    ----------
    ctx : the moderngl context to draw with (the window's)
    options : :class:`ViewOptions`
    model : the first model, grown by the caller (:func:`prepare_model`)
    say, warn : callables printing one line on stdout / stderr
    """

    def __init__(self, ctx, options: ViewOptions, model: PreparedModel, *, say=print, warn=print):
        self.ctx, self.options, self.say, self.warn = ctx, options, say, warn
        self.model = model
        self.renderer = str(ctx.info["GL_RENDERER"])
        self.raycaster = Raycaster(ctx, limits=options.limits)
        self.tracer: RayTracer | None = None   # RT, RT+R (made when first asked for)
        self._mesh_caster_said = False     # the mesh caster's fallback told once
        self._rt_playing_said = False      # RT's playing frames drawn by RC, told once
        self.raster: RasterRenderer | None = None
        self.method = options.method or ("RC+R" if "relief" in model.effects else "RC")
        self.level = int(options.level)
        self.march = options.settings.march          # the knobs the keys change (relief: by the method)
        self.shadows = "shadows" in model.effects
        self.ssaa = options.settings.image.ssaa
        self.t = options.settings.motion.start
        self.playing = False
        self.show_help = False
        self.closing = False                   # Q or Esc: the window's loop ends
        self.want_window_shot = False          # Shift+P: the window saves itself after its next draw
        self.status, self.error = "", None
        self.frames: deque[FrameStats] = deque(maxlen=HUD_FRAMES)
        self.last = None                       # the last RenderResult
        self.dirty = True
        self._frusta_key = self._frusta = self._leaves = None
        self._mesh_key = self._mesh = None
        self._stream = self._skinned = None    # a playing animation's GPU pose, its skinned mesh
        self._shadow_box = None
        self._saved_ns = None                  # a reload's save time, until its frame is shown
        self._reload_timings: dict = {}
        self.step_target: int | None = None   # the growth step N, Shift+N and G asked for (None: none)
        self.steps_end = model.grown.iterations   # a grammar's last step (its iterations); None otherwise
        self.growing = False                   # G: the growth plays, a step each GROW_STEP_S
        self._grow_clock = 0.0                 # seconds since the last step was taken in
        self._steps_need_said = False          # "steps need a grammar" printed once
        self.camera = self._initial_camera(*options.size)
        self.watcher = FileWatcher(model.grown.sources if options.watch else (), options.poll_s)
        self.reloader = BackgroundJob(self._grow)

    # ------------------------------------------------------------------ the model
    def _grow(self, t: float, saved_ns: int | None, step: int | None = None):
        """The reload's work (background thread): grow (a grammar ``step`` derivation steps
        deep when given), skin at ``t``; returns (model, frusta, seconds of each stage).
        ``saved_ns`` is the save's time for a reload, None for a growth step."""
        t0 = time.perf_counter()
        model = self.options.prepare(step)
        frusta = model.frusta_at(t)
        total = time.perf_counter() - t0
        grow = sum(model.grown.timings.values())      # read, parse, derive, interpret (place)
        return model, frusta, {"grow": grow, "skin": max(total - grow, 0.0)}

    def _initial_camera(self, width: int, height: int) -> Camera:
        o = self.options
        frusta = self.frusta()
        view = o.settings.view
        base = None if view.auto else Camera.load(view.camera, o.limits)
        if base is not None:
            base = Camera(base.eye, base.target, base.up, base.fov_y, width, height)
        return stage_model(self.model.grown, frusta, width, height, camera=base, orbit=view.orbit).camera

    def frusta(self):
        """The model's rows at the current time (skinned once for a still model)."""
        t = self.t if self.model.animated else 0.0
        key = self._frusta_key
        if key is None or key[0] is not self.model or key[1] != t:     # the objects, not their ids
            self._frusta, self._frusta_key = self.model.frusta_at(t), (self.model, t)
            self._leaves = self.model.anim.leaves_at(t) if self.model.animated else None
        return self._frusta

    def leaves(self):
        """An animated model's leaves at the current time, posed once per time (the same
        object while the time holds, so the shadow map drawn with them is reused); None for
        a still model (its leaves come with the staging)."""
        self.frusta()
        return self._leaves

    def mesh(self, frusta):
        """The GS / GS+R tessellation of ``frusta`` at the current level (cached)."""
        relief = self.method == "GS+R"
        key = self._mesh_key
        if key is None or key[0] is not frusta or key[1:] != (self.level, relief):
            self._mesh = None
            self._mesh = (PlacedMeshes.tessellate(frusta, self.level, relief) if isinstance(frusta, PlacedPlants)
                          else tessellate(frusta, self.level, relief=relief))
            self._mesh_key = (frusta, self.level, relief)
        return self._mesh

    # ------------------------------------------------------------------ the frame
    def effects(self) -> tuple:
        """The effects of the frame: the model's, with relief and shadows as the viewer
        has them now."""
        keep = [e for e in self.model.effects if e not in ("relief", "shadows")]
        return tuple(keep + (["relief"] if self.method.endswith("+R") else [])
                     + (["shadows"] if self.shadows else []))

    def request(self) -> RenderSettings:
        """What the frame asks for now: the options' settings with the keys' changes (the
        method's relief, shadows, the march, supersampling, the time)."""
        s = self.options.settings
        return replace(s, effects=EffectSettings(effects=s.effects.effects, relief=self.method.endswith("+R"),
                                                 shadows=self.shadows),
                       march=replace(self.march, method="rt" if self.method.startswith("RT") else "rc"),
                       image=replace(s.image, ssaa=self.ssaa),
                       motion=MotionSettings(time=self.t if self.model.animated else None))

    def settings(self) -> RaycastSettings:
        return self.request().frame(self.effects())[0]

    def posing_on_gpu(self) -> bool:
        """Whether this frame is posed on the GPU: an animation playing, ``--pose gpu``, and
        a plan the GPU can pose (a paused frame is skinned on the CPU, as ``plantgen
        render --time`` draws it)."""
        anim = self.model.anim
        return (self.playing and anim.animated and anim.plan is not None
                and self.options.settings.motion.pose == "gpu")

    def _draw_posed(self, staging, request, settings, shadow):
        """A playing frame posed on the GPU: RC and RC+R draw the records the compute
        program writes; GS and GS+R the mesh built once at rest, posed by the vertex shader."""
        anim = self.model.anim
        if self._stream is None or self._stream[0] is not self.model:
            self._release_stream()
            self._stream = (self.model, PoseStream(self.ctx))
        stream = self._stream[1]
        rest = anim.rest_frusta()[0]
        args = frame_arguments(rest, staging, shadow, request.image)
        if shadow is not None:
            args["shadow_box"] = self._playing_shadow_box()
        args["leaves"] = anim.leaves_at(self.t)
        if not self.method.startswith("GS"):
            if self.method.startswith("RT") and not self._rt_playing_said:
                self.warn("RT traces still frames: a playing animation posed on the GPU is drawn by RC")
                self._rt_playing_said = True
            rows, records, _ = anim.upload(stream, self.t, self.camera.eye)
            return self.raycaster.render(rows, settings=settings, record_buffer=records, **args)
        if self.raster is None:
            self.raster = RasterRenderer(self.ctx)
        poses, _ = anim.pose_segments(stream, self.t, self.camera.eye)
        return self.raster.render(self.skinned_mesh(rest), rest, poses=poses, bounds=anim.motion_box(), **args)

    def skinned_mesh(self, rest):
        """The playing animation's GS / GS+R mesh at rest, bound for vertex skinning (cached)."""
        relief = self.method == "GS+R"
        key = (self.model, self.level, relief)
        if self._skinned is None or self._skinned[0] != key:
            self._skinned = None
            self._skinned = (key, self.model.anim.skinned(tessellate(rest, self.level, relief=relief)))
        return self._skinned[1]

    def _release_stream(self) -> None:
        if self._stream is not None:
            self._stream[1].release()
            self._stream = None

    def draw(self, width: int, height: int):
        """Render the current frame at ``width`` x ``height`` (the window's pixels);
        returns the :class:`~plantgen.gl.result.RenderResult`."""
        if (width, height) != (self.camera.width, self.camera.height):
            self.camera = replace(self.camera, width=int(width), height=int(height))
        t0 = time.perf_counter()
        if self.posing_on_gpu():
            request = self.request()
            settings, shadow = request.frame(self.effects())
            staging = stage_model(self.model.grown, self.model.anim.rest_frusta()[0], width, height,
                                  camera=self.camera)
            return self._drawn(self._draw_posed(staging, request, settings, self._merged_caster(shadow)), t0)
        frusta = self.frusta()
        staging = stage_model(self.model.grown, frusta, width, height, camera=self.camera)
        request = self.request()
        settings, shadow = request.frame(self.effects())
        args = frame_arguments(frusta, staging, shadow, request.image)
        if shadow is not None and self.playing and self.model.animated:
            args["shadow_box"] = self._playing_shadow_box()
        if self.model.animated:
            args["leaves"] = self.leaves()     # moved with their branches
        if self.raster is None and self.method.startswith("GS"):
            self.raster = RasterRenderer(self.ctx)
        if isinstance(frusta, PlacedPlants):   # a forest: instanced, its detail as the knob says
            args["shadows"] = self._merged_caster(shadow)
            return self._drawn(self._draw_placed(frusta, args, settings, request.lod_pixels(self.effects())), t0)
        if not self.method.startswith("GS"):
            result = self.caster().render(frusta, settings=settings, **args)
        else:
            result = self.raster.render(self.mesh(frusta), frusta, **args)
        return self._drawn(result, t0)

    def _merged_caster(self, shadow):
        """The shadow knobs of a frame the mesh caster cannot cast (posed on the GPU, or a
        scene drawn instanced: ``--shadow-caster mesh`` casts still frusta drawn merged):
        the march's instead, said once; other knobs as they are. GS and GS+R cast their own
        meshes whatever the caster, so theirs stay as asked."""
        if shadow is None or shadow.caster != "mesh" or self.method.startswith("GS"):
            return shadow
        if not self._mesh_caster_said:
            self.warn("--shadow-caster mesh casts still frusta drawn merged: this model's playing or instanced "
                      "frames cast with the relief march")
            self._mesh_caster_said = True
        return replace(shadow, caster="relief")

    def _draw_placed(self, placed: PlacedPlants, args: dict, settings, lod_pixels: float):
        """A placed scene's frame: RC and RC+R from its records per plant, RT and RT+R
        through its two-level BVH, GS and GS+R from its meshes per plant."""
        if not self.method.startswith("GS"):
            return self.caster().render(placed, settings=settings, lod_pixels=lod_pixels, **args)
        keep = {k: v for k, v in args.items() if k not in ("material_names", "leaves")}
        return self.raster.render_placed(self.mesh(placed), lod_pixels=lod_pixels, **keep)

    def caster(self):
        """The ray caster (RC, RC+R) or the ray tracer (RT, RT+R) of the method."""
        if not self.method.startswith("RT"):
            return self.raycaster
        if self.tracer is None:
            self.tracer = RayTracer(self.ctx, limits=self.options.limits)
        return self.tracer

    def _drawn(self, result, t0: float):
        """Keep ``result`` as the last frame and its times for the heads-up line."""
        self.last = result
        self.frames.append(FrameStats(result.frame_ms, (time.perf_counter() - t0) * 1e3, time.monotonic()))
        self.dirty = False
        return result

    def _playing_shadow_box(self):
        """One light window for the whole animation while it plays (shadows do not shimmer)."""
        if self._shadow_box is None or self._shadow_box[0] is not self.model:
            times = np.linspace(0.0, 10.0, 16, endpoint=False)
            self._shadow_box = (self.model, self.model.anim.bounds(times))
        return self._shadow_box[1]

    def presented(self) -> dict | None:
        """The window calls this after a frame is on screen: a reload's time from the save
        to this frame is printed here, and returned ({"total": s, "detect": s, "grow": s,
        "skin": s, "draw": s}; None when no reload waited for this frame)."""
        if self._saved_ns is None:
            return None
        total = (time.time_ns() - self._saved_ns) / 1e9
        timings = {**self._reload_timings, "draw": self.frames[-1].wall_ms / 1e3 if self.frames else 0.0}
        parts = ", ".join(f"{k} {v:.2f}" for k, v in timings.items())
        self.say(f"reloaded {self.model.source}: {self.model.grown.segments:,} segments, "
                 f"{total:.2f} s from save to frame ({parts} s)")
        self.status = f"reloaded: {total:.2f} s from save to frame"
        self._saved_ns = None
        return {"total": total, **timings}

    # ------------------------------------------------------------------ time passes
    def tick(self, dt: float, now: float | None = None) -> bool:
        """Advance the clock by ``dt`` seconds: play an animation, poll the watched files
        and take a finished reload in. Returns True when the frame must be drawn again."""
        if self.playing and self.model.animated:
            self.t += dt
            self.dirty = True
        if self.options.watch:
            change = self.watcher.poll(now)
            if change is not None:
                self.reloader.start(self.t, change.saved_ns, self.step_target)   # at the step shown
                self.status = "reloading ..."
        done = self.reloader.result()
        if done is not None:
            self._take_reload(*done)
        if self.growing:
            self._grow_clock += dt
            if self._grow_clock >= GROW_STEP_S and not self.reloader.busy:
                if self.step_target >= self.steps_end:
                    self.growing = False
                    self.status = f"grown: step {self.step} of {self.steps_end}"
                else:
                    self._ask_step(self.step_target + 1)
        return self.dirty

    def _take_reload(self, args, value, exc) -> None:
        t, saved_ns, step = args
        if exc is not None:
            self.error = one_line(exc) if saved_ns is not None else f"step {step}: {one_line(exc)}"
            self.status = ""
            self.warn(f"plantgen view: error: {self.error} (keeping the last good model)")
            if saved_ns is None and not self.growing:     # a step that cannot be drawn: stay at the one shown
                self.step_target = self.step
            return
        model, frusta, timings = value
        self.model, self.error = model, None
        self._frusta, self._frusta_key = frusta, (model, t if model.animated else 0.0)
        self._mesh_key = None
        self.watcher.watch(model.grown.sources)
        self._grow_clock = 0.0
        if model.grown.iterations is None:              # no longer a grammar
            self.step_target, self.steps_end, self.growing = None, None, False
        elif step is None:
            self.steps_end = model.grown.iterations
        if saved_ns is None:
            self.status = f"step {self.step} of {self.steps_end}: {model.grown.segments:,} segments"
            self.say(f"{model.grown.name}: {self.status}")
        else:
            waited = max(0.0, (time.time_ns() - saved_ns) / 1e9 - timings["grow"] - timings["skin"])
            self._reload_timings = {"detect": waited, **timings}
            self._saved_ns = saved_ns
        self.dirty = True

    # ------------------------------------------------------------------ the controls
    def key(self, name: str, shift: bool = False) -> bool:
        """Handle key ``name`` (a pyglet key name); returns False for a key with no binding."""
        binding = binding_for(name, shift)
        if binding is None:
            return False
        getattr(self, binding.action)(*binding.args)
        return True

    def orbit(self, d_azimuth: float, d_elevation: float) -> None:
        """Turn the view around its target by degrees."""
        az, el, _ = orbit_angles(self.camera)
        el = float(np.clip(el + d_elevation, -MAX_ELEVATION, MAX_ELEVATION))
        self.camera = orbit_view(self.camera, Orbit(azimuth=(az + d_azimuth + 180.0) % 360.0 - 180.0, elevation=el))
        self.dirty = True

    def drag(self, dx: float, dy: float, pan: bool = False) -> None:
        """A mouse drag of (dx, dy) window pixels (y down): turn, or with ``pan`` move."""
        if pan:
            self.pan(dx, dy)
        else:
            self.orbit(-DRAG_TURN * dx, DRAG_TURN * dy)

    def pan(self, dx: float, dy: float) -> None:
        """Move eye and target across the view by (dx, dy) pixels (the target follows the
        cursor)."""
        right, up, _ = self.camera.basis()
        dist = float(np.linalg.norm(np.subtract(self.camera.eye, self.camera.target)))
        per_pixel = 2.0 * dist * math.tan(math.radians(self.camera.fov_y) / 2) / self.camera.height
        shift = (-dx * right + dy * up) * per_pixel
        self.camera = replace(self.camera, eye=tuple((np.asarray(self.camera.eye) + shift).tolist()),
                              target=tuple((np.asarray(self.camera.target) + shift).tolist()))
        self.dirty = True

    def pan_view(self, fx: float, fy: float) -> None:
        """Move the view right and up by fractions of its height (keys; a drag moves the
        model with the cursor instead)."""
        self.pan(-fx * self.camera.height, fy * self.camera.height)

    def zoom(self, factor: float) -> None:
        """Move the eye ``factor`` times closer to the target."""
        self.camera = orbit_view(self.camera, Orbit(zoom=factor))
        self.dirty = True

    def scroll(self, notches: float) -> None:
        self.zoom(1.1 ** notches)

    def reset_view(self) -> None:
        self.camera = stage_model(self.model.grown, self.frusta(), self.camera.width, self.camera.height).camera
        self.dirty = True

    def set_method(self, method: str) -> None:
        self.method = method
        if method.startswith("GS"):
            self.change_level(0)
        self.dirty = True

    def change_level(self, delta: int) -> None:
        level = int(np.clip(self.level + delta, 0, MAX_SUBDIV))
        frusta = self.frusta()
        n = stored_triangles(frusta, level)
        while n > VIEW_MAX_TRIANGLES and level > 0:
            self.status = f"m = {level} would make {n:,} triangles, over the viewer's {VIEW_MAX_TRIANGLES:,}"
            level -= 1
            n = stored_triangles(frusta, level)
        self.level = level
        self.dirty = True

    def scale_linear_steps(self, factor: float) -> None:
        steps = knob_of(RaycastSettings, "linear_steps").clamp(int(round(self.march.linear_steps * factor)))
        self.march = replace(self.march, linear_steps=steps)
        self.dirty = True

    def change_binary_steps(self, delta: int) -> None:
        steps = knob_of(RaycastSettings, "binary_steps").clamp(self.march.binary_steps + delta)
        self.march = replace(self.march, binary_steps=steps)
        self.dirty = True

    def toggle_march(self) -> None:
        self.march = replace(self.march, march="fixed" if self.march.march == "adaptive" else "adaptive")
        self.dirty = True

    def toggle_shadows(self) -> None:
        self.shadows = not self.shadows
        self.dirty = True

    def cycle_ssaa(self) -> None:
        self.ssaa = self.ssaa % min(4, MAX_SSAA) + 1
        self.dirty = True

    def toggle_play(self) -> None:
        if not self.model.animated:
            self.status = "nothing moves in this model (a scene with motion plays)"
            return
        self.playing = not self.playing
        self.dirty = True

    def scrub(self, dt: float) -> None:
        if not self.model.animated:
            self.status = "nothing moves in this model (a scene with motion plays)"
            return
        self.t = max(0.0, self.t + dt)
        self.dirty = True

    # ------------------------------------------------------------------ growth step by step
    @property
    def step(self) -> int | None:
        """The derivation step of the grammar shown (its iterations); None for a scene or
        a skeleton file."""
        return self.model.grown.iterations

    def _steps_allowed(self) -> bool:
        """Whether the model grows step by step (a grammar); else says so (on stdout once)."""
        if self.step is not None:
            return True
        self.status = f"growth steps need a grammar (this is a {self.model.grown.kind})"
        if not self._steps_need_said:
            self.say(self.status)
            self._steps_need_said = True
        return False

    def _ask_step(self, step: int) -> None:
        """Grow the grammar ``step`` derivation steps deep with the same seed (on the reload
        thread; a newer step asked meanwhile supersedes it)."""
        self.step_target = step
        self.reloader.start(self.t, None, step)
        self.status = f"growing step {step} ..."

    def grow_step(self, delta: int) -> None:
        """N, Shift+N: the growth one derivation step forward or back (from the step last
        asked for), between the axiom (0) and the grammar's iterations; stops playing."""
        if not self._steps_allowed():
            return
        self.growing = False
        current = self.step if self.step_target is None else self.step_target
        step = min(max(current + delta, 0), self.steps_end)
        if step == current:
            self.step_target = current
            self.status = (f"step {step} is the grammar's last (its iterations)" if delta > 0
                           else "step 0 is the axiom")
            return
        self._ask_step(step)

    def toggle_growth(self) -> None:
        """G: play the growth, a step each :data:`GROW_STEP_S` seconds (or as fast as a
        step grows), up to the grammar's iterations; from the axiom when there already;
        G again stops it."""
        if not self._steps_allowed():
            return
        if self.growing:
            self.growing = False
            self.status = f"growth stopped at step {self.step}"
            return
        self.growing, self._grow_clock = True, 0.0
        current = self.step if self.step_target is None else self.step_target
        if current >= self.steps_end:
            self._ask_step(0)
        else:
            self.step_target = current
            self.status = "growing ..."

    def toggle_help(self) -> None:
        self.show_help = not self.show_help

    def quit(self) -> None:
        self.closing = True

    # ------------------------------------------------------------------ saving
    def _next_name(self, suffix: str) -> Path:
        folder = Path(self.options.shots)
        stem = self.model.grown.name or Path(self.model.source).stem
        for i in range(1, 100000):
            path = folder / f"{stem}-{i:03d}{suffix}"
            if not path.exists() and not path.with_suffix(".png").exists() and not path.with_suffix(".json").exists():
                return path
        raise PlantgenError(f"{folder}: no free name for {stem}-NNN{suffix}")

    def current(self):
        """The frame of the current state: the last one, drawn again first if anything
        changed since (a key pressed in the same moment as P or C counts)."""
        if self.dirty or self.last is None:
            self.draw(self.camera.width, self.camera.height)
        return self.last

    def screenshot(self) -> Path | None:
        """Write the current frame as drawn (no heads-up line) as a PNG."""
        self.current()
        try:
            path = write_png(self._next_name(".png"), self.last.color)
        except PlantgenError as exc:
            return self._failed(exc)
        self.say(f"saved screenshot {path} ({self.last.camera.width}x{self.last.camera.height})")
        self.status = f"saved {path.name}"
        return path

    def window_shot(self, pixels: np.ndarray | None = None) -> Path | None:
        """Write ``pixels`` (the window as shown; the window passes them) as a PNG."""
        if pixels is None:
            self.want_window_shot = True
            return None
        self.want_window_shot = False
        try:
            path = write_png(self._next_name(".png"), pixels)
        except PlantgenError as exc:
            return self._failed(exc)
        self.say(f"saved window {path}")
        self.status = f"saved {path.name}"
        return path

    def save_camera(self) -> Path | None:
        """Write the camera of the last frame as JSON and print the ``plantgen render``
        command that draws the same frame."""
        camera = self.current().camera
        try:
            path = write_atomically(self._next_name(".json"), camera.save)
        except PlantgenError as exc:
            return self._failed(exc)
        self.say(f"saved camera {path}; the same frame: {self.render_command(path)}")
        self.status = f"saved {path.name}"
        return path

    def _failed(self, exc) -> None:
        self.error = one_line(exc)
        self.warn(f"plantgen view: error: {self.error}")

    def render_command(self, camera_path: Path) -> str:
        """The ``plantgen render`` command line that draws the current frame from
        ``camera_path`` (pixel for pixel for RC and RC+R): the options of the settings
        that differ from their defaults (:func:`plantgen.knobs.knob_args`)."""
        o = self.options
        out = Path(camera_path).with_suffix(".render.png")
        request = replace(self.request(), view=ViewSettings(camera=str(camera_path)),
                          image=replace(self.request().image, size=None))
        args = ["plantgen", "render", str(o.input), "-o", str(out), *knob_args(request)]
        iterations = o.iterations if self.step_target is None else self.step
        for flag, value in (("--seed", o.seed), ("--iterations", iterations), ("--smooth-bends", o.smooth_bends)):
            if value is not None:
                args += [flag, str(value)]
        text = shlex.join(args)
        if self.method.startswith("GS"):
            text += f"   (ray cast; the viewer drew {self.method} m = {self.level} with the raster renderer)"
        return text

    # ------------------------------------------------------------------ the heads-up line
    def hud_lines(self) -> list[tuple[str, str]]:
        """(text, kind) lines of the heads-up display; kind is "info", "status" or "error"."""
        s = self.settings()
        if self.method in ("RC", "RT"):
            method = self.method
        elif self.method in ("RC+R", "RT+R"):
            method = (f"{self.method} adaptive <= {s.linear_steps} + {s.binary_steps} steps" if s.march == "adaptive"
                      else f"{self.method} fixed {s.linear_steps} + {s.binary_steps} steps")
        else:
            method = f"{self.method} m = {self.level}"
            if self.posing_on_gpu() and self._skinned is not None and self._skinned[0][1] == self.level:
                method += f", {len(self._skinned[1].mesh.faces):,} triangles, skinned on the GPU"
            elif self._mesh is not None and self._mesh_key is not None and self._mesh_key[1] == self.level:
                method += f", {len(self._mesh.faces):,} triangles"
        frames = list(self.frames)
        timing = "-"
        if frames:
            frame_ms = statistics.median(f.frame_ms for f in frames)
            wall_ms = statistics.median(f.wall_ms for f in frames)
            timing = f"{frame_ms:.1f} ms frame, {1000.0 / max(wall_ms, 1e-3):.1f} fps (median of {len(frames)})"
        cam = self.camera
        leaves = self.model.grown.polygons
        count = 0 if leaves is None else len(leaves)
        leafy = f", {count:,} {'leaf' if count == 1 else 'leaves'}" if count else ""
        lines = [(f"{self.model.grown.name}: {self.model.grown.segments:,} segments{leafy} | {method} | shadows "
                  f"{self._shadow_text()} | ssaa {self.ssaa}", "info"),
                 (f"{timing} | {cam.width}x{cam.height} | {self.renderer} | H: keys", "info")]
        if self.model.animated:
            lines.append((f"t = {self.t:.2f} s {'playing' if self.playing else 'paused'} (Space, , .)", "info"))
        if self.step_target is not None:
            lines.append((f"growth: step {self.step} of {self.steps_end}, {'playing' if self.growing else 'paused'}"
                          " (N, Shift+N, G)", "info"))
        if self.error:
            lines.append((self.error, "error"))
        elif self.status:
            lines.append((self.status, "status"))
        return lines

    def _shadow_text(self) -> str:
        """``off``, or ``on`` and how the last frame had its map: drawn (in how many ms) or
        reused (a camera move does not draw it again)."""
        if not self.shadows:
            return "off"
        stats = self.last.stats if self.last is not None else None
        if stats is None or "shadow" not in stats.passes:
            return "on"
        return "on (map reused)" if stats.shadow_cached else f"on (map drawn, {stats.shadow_ms:.0f} ms)"

    def release(self) -> None:
        """Free the renderers' GL objects."""
        self._release_stream()
        self.raycaster.release()
        if self.tracer is not None:
            self.tracer.release()
        if self.raster is not None:
            self.raster.release()
