"""The viewer's state apart from any window: the model, the camera, the method and its
knobs, the time of an animated scene, a grammar's growth step, live reload's bookkeeping,
the renderers and the caches of the frame (:class:`ViewerState`), with what the frame
reads from them (the frusta at the time, the GS mesh, the settings asked for).

The key handlers (``handlers.py``, ``growth.py``, ``shots.py``), the drawing
(``frame.py``), the reload (``reload.py``) and the heads-up text (``hud.py``) are
functions over this state; :class:`~plantgen.viewer.session.ViewerSession` binds them
as its methods.
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace
from functools import partial

from ..geometry.meshes.mesh import tessellate
from ..geometry.rays.camera import Camera
from ..geometry.rays.instances import PlacedMeshes, PlacedPlants
from ..gl.raster import RasterRenderer
from ..gl.raycast import Raycaster
from ..gl.rt import RayTracer
from ..pipeline import PreparedModel, stage_model
from ..settings import EffectSettings, MotionSettings, RaycastSettings, RenderSettings
from .options import HUD_FRAMES, FrameStats, ViewOptions, grow_model
from .watch import BackgroundJob, FileWatcher

__all__ = ["ViewerState"]


class ViewerState:
    """What the viewer shows and how it was asked for (see the module's docstring).

    Parameters
    ----------
    ctx : the moderngl context to draw with (the window's)
    options : :class:`~plantgen.viewer.options.ViewOptions`
    model : the first model, grown by the caller (:func:`~plantgen.pipeline.prepare_model`)
    say, warn : callables printing one line on stdout / stderr
    """

    def __init__(self, ctx, options: ViewOptions, model: PreparedModel, *, say=print, warn=print):
        self.ctx, self.options, self.say, self.warn = ctx, options, say, warn
        self.model = model
        self.renderer = str(ctx.info["GL_RENDERER"])
        self.raycaster = Raycaster(ctx, limits=options.limits)
        self.tracer: RayTracer | None = None  # RT, RT+R (made when first asked for)
        self.mesh_caster_said = False         # the mesh caster's fallback told once
        self.rt_playing_said = False          # RT's playing frames drawn by RC, told once
        self.raster: RasterRenderer | None = None
        self.method = options.method or ("RC+R" if "relief" in model.effects else "RC")
        self.level = int(options.level)
        self.march = options.settings.march   # the knobs the keys change (relief: by the method)
        self.shadows = "shadows" in model.effects
        self.ssaa = options.settings.image.ssaa
        self.t = options.settings.motion.start
        self.playing = False
        self.show_help = False
        self.closing = False                  # Q or Esc: the window's loop ends
        self.want_window_shot = False         # Shift+P: the window saves itself after its next draw
        self.status, self.error = "", None
        self.frames: deque[FrameStats] = deque(maxlen=HUD_FRAMES)
        self.last = None                      # the last RenderResult
        self.dirty = True
        self.frusta_key = self.frusta_cache = self.leaves_cache = None   # frusta() and leaves() at a time
        self.mesh_key = self.mesh_cache = None  # mesh() at a level
        self.stream = self.skinned = None     # a playing animation's GPU pose, its skinned mesh
        self.shadow_box = None                # a playing animation's light window
        self.saved_ns = None                  # a reload's save time, until its frame is shown
        self.reload_timings: dict = {}        # a reload's stages (s), told with its frame
        self.step_target: int | None = None   # the growth step N, Shift+N and G asked for (None: none)
        self.steps_end = model.grown.iterations   # a grammar's last step (its iterations); None otherwise
        self.growing = False                  # G: the growth plays, a step each GROW_STEP_S
        self.grow_clock = 0.0                 # seconds since the last step was taken in
        self.steps_need_said = False          # "steps need a grammar" printed once
        self.camera = self._initial_camera(*options.size)
        self.watcher = FileWatcher(model.grown.sources if options.watch else (), options.poll_s)
        self.reloader = BackgroundJob(partial(grow_model, options))

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
        key = self.frusta_key
        if key is None or key[0] is not self.model or key[1] != t:     # the objects, not their ids
            self.frusta_cache, self.frusta_key = self.model.frusta_at(t), (self.model, t)
            self.leaves_cache = self.model.anim.leaves_at(t) if self.model.animated else None
        return self.frusta_cache

    def leaves(self):
        """An animated model's leaves at the current time, posed once per time (the same
        object while the time holds, so the shadow map drawn with them is reused); None for
        a still model (its leaves come with the staging)."""
        self.frusta()
        return self.leaves_cache

    def mesh(self, frusta):
        """The GS / GS+R tessellation of ``frusta`` at the current level (cached)."""
        relief = self.method == "GS+R"
        key = self.mesh_key
        if key is None or key[0] is not frusta or key[1:] != (self.level, relief):
            self.mesh_cache = None
            self.mesh_cache = (PlacedMeshes.tessellate(frusta, self.level, relief) if isinstance(frusta, PlacedPlants)
                               else tessellate(frusta, self.level, relief=relief))
            self.mesh_key = (frusta, self.level, relief)
        return self.mesh_cache

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

    @property
    def step(self) -> int | None:
        """The derivation step of the grammar shown (its iterations); None for a scene or
        a skeleton file."""
        return self.model.grown.iterations
