"""Every render setting in one home: frozen, typed values with one default each.

A render is asked for once, where input enters (the command line, the API, the viewer,
a batch spec, the bench), as a :class:`RenderSettings`, and the value travels whole down
to the shader's defines and uniforms. Each field is a :func:`~plantgen.knobs.knob`: its
default here is the only default, and the command line builds its options (name, type,
range, help) from it. A new effect or knob is one field here plus the code that uses it.

- :class:`EffectSettings`: the effects a frame simulates (``--effects``, ``--relief``,
  ``--shadows``), resolved against a scene's list (:data:`EFFECTS`);
- :class:`RaycastSettings`: the ray caster's knobs, the relief march's among them;
- :class:`ShadowSettings`: the shadow map;
- :class:`DetailSettings`: the level of detail of an instanced scene (``lod``);
- :class:`ImageSettings`: size, supersampling, background;
- :class:`MotionSettings`: the time of a still, an animation's frames and rate;
- :class:`ViewSettings`: the camera file or ``auto``, and the orbit around it;
- :class:`ParallaxSettings`: GS+POM's parallax occlusion mapping (the rasteriser's march of
  a baked height map);
- :class:`LevelSettings`: the levels of detail an export writes (glTF, USD);
- :class:`KeyframeSettings`: the keyframes of the sway an export writes (glTF, USD);
- :class:`RenderSettings`: all of them, built from flat keywords by :meth:`RenderSettings.from_options`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, is_dataclass, replace

from .errors import PlantgenError
from .geometry.rays.camera import Orbit
from .knobs import check_knobs, knob

__all__ = ["EFFECTS", "DEFAULT_EFFECTS", "DEFAULT_SIZE", "GROUND_CHOICES", "AA_CHOICES", "AA_FLOOR_PIXELS",
           "AA_ALPHA_EXPONENT",
           "LookSettings", "LOD_EXPORT_LEVELS",
           "MAX_SSAA", "MAX_SUBDIV", "EffectSettings", "RaycastSettings", "ShadowSettings", "ParallaxSettings",
           "DetailSettings",
           "ImageSettings", "MotionSettings", "ViewSettings", "RenderSettings", "MeshSettings", "LevelSettings",
           "KeyframeSettings",
           "resolve_effects",
           "parse_effect_list", "build_settings", "option_names", "settings_knobs"]

#: The effects a scene may list; a render simulates only those in force. ``lod``: a still
#: scene is drawn instanced (each distinct plant once on the GPU, a transform per copy)
#: with detail that follows the pixel (:class:`DetailSettings`). The looks
#: (:class:`LookSettings`): ``tone`` (a filmic tone curve in linear light, then the sRGB
#: transfer curve), ``translucency`` (leaves lit from behind glow: sun and sky through the
#: leaf), ``sky`` (the sky's light occluded by the model: hemisphere rays through its BVH),
#: ``bounce`` (the light the sunlit ground reflects lights the model from below).
EFFECTS = ("relief", "shadows", "animation", "lod", "tone", "translucency", "sky", "bounce")
#: Effects in force unless the command removes them (``--no-tone``, ``--effects``): cheap,
#: they cost a plain frame next to nothing.
DEFAULT_EFFECTS = ("tone", "translucency")
#: The levels of detail an export writes for a scene that lists ``lod`` (level 0 full).
LOD_EXPORT_LEVELS = 4
#: The image size when neither the command nor a camera file gives one.
DEFAULT_SIZE = (1024, 768)
#: The ``--ground`` values: ``auto`` (the scene's ground; a disc under a single plant) or ``none``.
GROUND_CHOICES = ("auto", "none")
#: ``--aa``: coverage anti-aliasing (branches thinner than a pixel cast a pixel wide, drawn
#: last, blended by their share of the pixel), the same and an edge pass (``edges``: the
#: frame's edges smoothed along their direction), or none (one ray a pixel, as before).
AA_CHOICES = ("coverage", "edges", "none")
#: Coverage anti-aliasing's floor: a row thinner than this many pixels across is cast this wide.
AA_FLOOR_PIXELS = 1.0
#: Coverage anti-aliasing blends a thin piece by its coverage to this power: the frame is
#: blended in its display encoding, where a dark twig or needle over the bright sky at a
#: given coverage comes out darker than the average of the pixel in linear light (what
#: supersampling gives); the power lightens it. Chosen on the pine at 512x384 against
#: ``--ssaa 4``: 1.3 gave the lowest FLIP and error of 1, 1.2, 1.3, 1.5, 1.7 and 2.
AA_ALPHA_EXPONENT = 1.3
#: The most samples per pixel side of supersampling.
MAX_SSAA = 8
#: The finest GS subdivision level m anyone may ask for (the triangle budgets may stop it sooner).
MAX_SUBDIV = 8
#: The adaptive march's bisection stops at this many pixel footprints.
MARCH_PRECISION = 0.02


def resolve_effects(scene_effects=(), *, replace=None, add=(), remove=()) -> tuple[str, ...]:
    """The effects a render simulates: the scene's list, or ``replace``, plus ``add`` minus
    ``remove`` (in :data:`EFFECTS` order). One line naming the known effects for an
    unknown name."""
    chosen = list(scene_effects if replace is None else replace)
    for name in (*chosen, *add, *remove):
        if name not in EFFECTS:
            raise PlantgenError(f"unknown effect {name!r} (known: {', '.join(EFFECTS)})")
    wanted = (set(chosen) | set(add)) - set(remove)
    return tuple(e for e in EFFECTS if e in wanted)


def parse_effect_list(text: str) -> tuple[str, ...]:
    """``"relief,shadows"`` -> ("relief", "shadows"); empty items are ignored; names checked."""
    names = tuple(s.strip() for s in str(text).split(",") if s.strip() and s.strip() != "none")
    return resolve_effects(replace=names)


@dataclass(frozen=True)
class EffectSettings:
    """Which effects a frame simulates: ``effects`` replaces the scene's list (None keeps
    it, with :data:`DEFAULT_EFFECTS` added); ``relief``, ``shadows``, ``tone``,
    ``translucency``, ``sky`` and ``bounce`` True or False add or remove that effect (None:
    as the list says)."""

    effects: tuple | None = knob(None, "--effects", "Comma-separated effects replacing the scene's list, e.g. "
                                 f"relief,shadows (known: {', '.join(EFFECTS)}; 'none' for none).",
                                 kind="list", metavar="LIST")
    relief: bool | None = knob(None, "--relief", "Carve the bark's relief into the branches (relief mapping). "
                               "Default: on when the effects list it.", kind="bool")
    shadows: bool | None = knob(None, "--shadows", "Cast the light's shadows (a shadow map). Default: on when the "
                                "effects list it.", kind="bool")
    tone: bool | None = knob(None, "--tone", "A filmic tone curve and the sRGB encoding (--no-tone: clip and a plain "
                             "2.2 power, as before). Default: on unless --effects leaves it out.", kind="bool")
    translucency: bool | None = knob(None, "--translucency", "Leaves let light through: a leaf lit from behind glows "
                                     "with the sun and the sky behind it. Default: on unless --effects leaves it "
                                     "out.", kind="bool")
    sky: bool | None = knob(None, "--sky-light", "Sky light with occlusion: a few rays a pixel towards the sky "
                            "through the model's ray-tracing tree, so crevices and the inside of a crown darken "
                            "(costs; see "
                            "--sky-samples). Default: on when the effects list sky.", kind="bool")
    bounce: bool | None = knob(None, "--bounce", "The ground's light: the sunlit ground lights the model from "
                               "below, as the sky does from above (traced with --sky-light; else a crown does not hide "
                               "the ground from itself; none with --ground none). Default: on when the effects list "
                               "bounce.",
                               kind="bool")

    def __post_init__(self):
        if isinstance(self.effects, str):
            object.__setattr__(self, "effects", parse_effect_list(self.effects))
        elif self.effects is not None:
            object.__setattr__(self, "effects", resolve_effects(replace=tuple(self.effects)))

    def resolve(self, scene_effects=()) -> tuple[str, ...]:
        """The effects in force for a model whose scene lists ``scene_effects``."""
        flags = (("relief", self.relief), ("shadows", self.shadows), ("tone", self.tone),
                 ("translucency", self.translucency), ("sky", self.sky), ("bounce", self.bounce))
        defaults = list(DEFAULT_EFFECTS) if self.effects is None else []
        return resolve_effects(scene_effects, replace=self.effects, add=defaults + [n for n, f in flags if f],
                               remove=[n for n, f in flags if f is False])


#: The sky light's rays a pixel by default (``--sky-samples``).
SKY_SAMPLES = 8
#: The filmic tone curve's knee: linear light below it is kept, above it rolled off towards 1.
TONE_KNEE = 0.7
#: Pixel footprints a sky ray starts off its surface (as RT's shadow rays).
SKY_RAY_OFFSET = 1.0


@dataclass(frozen=True)
class LookSettings:
    """How light reads (the effects ``tone``, ``translucency``, ``sky``, ``bounce``; set from the effects
    in force by :meth:`RenderSettings.frame`; all off by default, today's shading, for a
    caller that builds its settings itself: :meth:`defaults` gives those of
    :data:`DEFAULT_EFFECTS`), and the knob of each accuracy trade-off.

    tone : the tone curve (``tone_curve``, in linear light, after ``exposure``) and the
        real sRGB transfer curve; off: clip, then c^(1/2.2) (as before). ``filmic``: the
        identity up to :data:`TONE_KNEE`, then an exponential shoulder with slope 1 at the
        knee towards 1 (shadows and mid-tones as before, highlights rolled off); ``aces``:
        the rational fit of ACES's RRT+ODT published by K. Narkowicz (2016), whose toe
        darkens deep shadows about five-fold
    translucency : leaves transmit: the sun behind a leaf, and the sky on its far side,
        come through it, tinted by its albedo, ``transmission`` of it
    sky : the ambient light is the sky's seen along ``sky_samples`` cosine-weighted rays a
        pixel traced through the BVH (up to ``sky_reach`` times the model's size), instead
        of an unoccluded hemisphere; the sequence is a hash of the pixel (deterministic)
    bounce : the ground's light: the ground's albedo times the light falling on it (sun and
        sky) reaches a surface from below, over the share of its view the ground's disc
        fills (``shaders/shading.glsl``'s ``ground_share``: (1 - n_y) / 2 at the ground, less
        higher up), unoccluded, as the sky's ambient reaches it from above; with ``sky`` it
        is traced with the sky's rays below the horizon; none where no ground is drawn
    exposure : the tone curve's input scale
    sun_angle : the sun's angular diameter in degrees (0: a point, hard shadows): a
        penumbra in the shadow map's filter, shadow rays jittered over the disc in RT,
        ``sun_samples`` a pixel either way
    """

    tone: bool = False
    translucency: bool = False
    sky: bool = False
    bounce: bool = False
    transmission: float = knob(0.5, "--leaf-transmission", "Translucency: the fraction of the light falling on a "
                               "leaf's far side that comes through it (0..1).", lo=0, hi=1, metavar="F")
    sky_samples: int = knob(SKY_SAMPLES, "--sky-samples", "Sky light: rays a pixel towards the sky (more: less "
                            "noise, each costs about one shadow ray).", kind="int", lo=1, hi=256, metavar="N")
    sky_reach: float = knob(0.5, "--sky-reach", "Sky light: how far a sky ray looks for an occluder, in model "
                            "sizes (the diagonal of its box); farther rays cost more.", lo=0, lo_open=True,
                            metavar="F")
    tone_curve: str = knob("filmic", "--tone-curve", "Tone curve: filmic (linear up to a knee, then a smooth "
                           "shoulder towards white: shadows as before, highlights no longer clipped) or aces (the "
                           "ACES film look: more contrast, deep shadows darker).", kind="choice",
                           choices=("filmic", "aces"))
    exposure: float = knob(1.0, "--exposure", "Tone curve: scale the linear light by this before the curve "
                           "(above 1 brighter).", lo=0, lo_open=True, hi=100, metavar="F")
    sun_samples: int = knob(16, "--sun-samples", "Soft sun: shadow-map taps, or shadow rays with --method rt, a "
                            "pixel (more: smoother penumbrae, slower).", kind="int", lo=1, hi=256, metavar="N")
    sun_angle: float = knob(0.0, "--sun-angle", "The sun's angular diameter in degrees (the real sun: 0.53): soft "
                            "shadow edges, widening with the distance to the occluder (0: a point light, hard "
                            "shadows).", lo=0, hi=30, metavar="DEG")

    def __post_init__(self):
        check_knobs(self)

    @classmethod
    def defaults(cls) -> LookSettings:
        """The looks of :data:`DEFAULT_EFFECTS` (what a render gets unless it says otherwise)."""
        return cls(tone="tone" in DEFAULT_EFFECTS, translucency="translucency" in DEFAULT_EFFECTS,
                   sky="sky" in DEFAULT_EFFECTS, bounce="bounce" in DEFAULT_EFFECTS)

    def defines(self) -> dict[str, bool]:
        """The shader variant: ``TONE_MAP`` (``TONE_ACES``), ``TRANSLUCENT``, ``SKY_LIGHT``,
        ``SOFT_SUN``, ``GROUND_BOUNCE``."""
        return {"TONE_MAP": self.tone, "TONE_ACES": self.tone and self.tone_curve == "aces",
                "TRANSLUCENT": self.translucency, "SKY_LIGHT": self.sky, "SOFT_SUN": self.sun_angle > 0,
                "GROUND_BOUNCE": self.bounce}

    def shading_uniforms(self) -> dict:
        """Uniforms of ``shaders/shading.glsl`` (every program's)."""
        return {"leaf_transmission": self.transmission, "exposure": self.exposure, "tone_knee": TONE_KNEE}

    def sun_uniforms(self) -> dict:
        """Uniforms of ``shaders/shadow.glsl`` (the receivers'): the sun disc's radius as the
        tangent of its half angle, its samples."""
        return {"sun_radius": math.tan(math.radians(self.sun_angle) / 2), "sun_samples": self.sun_samples}

    def sky_uniforms(self, model_size: float) -> dict:
        """Uniforms of ``shaders/sky_light.glsl`` for a model whose box has diagonal
        ``model_size`` (world units)."""
        return {"sky_samples": self.sky_samples, "sky_reach": self.sky_reach * max(float(model_size), 1e-6),
                "sky_ray_offset": SKY_RAY_OFFSET}


@dataclass(frozen=True)
class RaycastSettings:
    """The ray caster's knobs. Every accuracy/speed trade-off is one field.

    relief : march the relief shell of segments with ``shell > 0`` (§3); set from the
        effects in force (:meth:`RenderSettings.frame`)
    march : ``"adaptive"``: the linear samples of each ray are sized to what its pixel
        sees, ``march_density`` per relief texel the ray crosses in the shell, where a
        texel counts at least one pixel's footprint (a far branch takes
        ``march_min_steps``, a grazing close-up up to ``linear_steps``); ``"fixed"``:
        ``linear_steps`` samples for every ray (the paper's uniform sampling)
    linear_steps : fixed march: the samples along the shell interval; adaptive: the most
    march_density : adaptive march: samples per relief texel crossed
    march_min_steps : adaptive march: the fewest samples
    march_precision : adaptive march: bisection stops when the bracket around the hit is
        shorter than this many pixel footprints (along the ray)
    binary_steps : bisection steps after the first sample under the relief surface (the
        adaptive march: the most)
    v_exact : v of (7) per sample (exact) instead of interpolated between entry and exit
    hull_padding : growth of the bounding pyramid relative to the radius, so pixels on
        a silhouette tangent to the pyramid are not lost to rasterisation rules
    look : how light reads (:class:`LookSettings`: the looks' effects and knobs)
    labels : write each pixel's row label instead of its colour: red = the row's
        ``material`` index / 255, unshaded (part masks)
    proxy : ``"pyramid"`` (§2.6) or ``"screen"``: every segment covers the whole screen, a
        slow oracle that shows what a too-tight pyramid would lose (tests)
    height_fetch : ``"gather"`` (one textureGather per bilinear height) or ``"texel"``
        (four texelFetch with the wrap in GLSL): the same heights; the bench's ablation
    method : ``"rc"`` (the ray caster: one bounding pyramid rasterised per row, the
        pixel's ray cast against that row; its cost grows with the rows drawn) or ``"rt"``
        (the ray tracer, :mod:`plantgen.gl.rt`: each pixel's ray traced through a bounding
        volume hierarchy, about the log of the rows; shadows by shadow rays, no map). The
        same surfaces either way ``"auto"`` (the default) chooses per input
        (:func:`plantgen.gl.rt.choose_method`): rt for an instanced scene drawn at full
        detail whose placed rows are many for the pixels and for its distinct plants, rc
        otherwise, from what the benchmarks measure.
    """

    relief: bool = False
    method: str = knob("auto", "--method", "How each pixel finds the branches: ray cast each branch piece over "
                       "its patch of screen (rc), or trace each pixel's ray through a tree of boxes (rt: it pays "
                       "off on scenes of very many pieces; shadows by shadow rays; an animation posed on the CPU); "
                       "auto: rt for an instanced scene at full detail (--lod-pixels 0) with many pieces a pixel, "
                       "else rc (the faster, as measured).",
                       kind="choice", choices=("auto", "rc", "rt"))
    march: str = knob("adaptive", "--march", "Relief: the samples a ray takes, sized to what each pixel sees "
                      "(adaptive), or --linear-steps for every ray (fixed, the paper's).", kind="choice",
                      choices=("adaptive", "fixed"))
    linear_steps: int = knob(32, "--linear-steps", "Relief: evenly spaced samples through the relief layer (adaptive "
                             "march: the most).", kind="int", lo=1, hi=4096)
    march_density: float = knob(2.0, "--march-density", "Relief, adaptive march: samples per texel of the relief "
                                "texture the ray crosses.", lo=0, lo_open=True)
    march_min_steps: int = 4
    march_precision: float = MARCH_PRECISION
    binary_steps: int = knob(12, "--binary-steps", "Relief: halving steps that refine the hit after the first sample "
                             f"below the surface (adaptive march: the most; it stops at {MARCH_PRECISION:g} pixel).",
                             kind="int", lo=0, hi=64)
    v_exact: bool = knob(False, "--v-exact", "Relief: compute the texture's lengthwise coordinate at every sample "
                         "(exact), or interpolate it between where the ray enters and leaves the relief layer (the "
                         "paper's fast path).", kind="bool", flag="--v-exact/--v-interpolated")
    hull_padding: float = 0.02
    proxy: str = "pyramid"
    height_fetch: str = "gather"
    labels: bool = False
    look: LookSettings = LookSettings()

    def __post_init__(self):
        check_knobs(self)
        if self.proxy not in ("pyramid", "screen"):
            raise PlantgenError(f"proxy must be 'pyramid' or 'screen', not {self.proxy!r}")
        if self.height_fetch not in ("gather", "texel"):
            raise PlantgenError(f"height fetch must be 'gather' or 'texel', not {self.height_fetch!r}")
        if self.march_min_steps < 1:
            raise PlantgenError("relief steps: the minimum steps must be >= 1")
        if not self.march_precision > 0:
            raise PlantgenError("march precision (pixels) must be > 0")
        if not 0 <= self.hull_padding < 1:
            raise PlantgenError("hull padding must lie in [0, 1)")

    def defines(self) -> dict[str, bool]:
        """The shader variant these settings select (preprocessor defines)."""
        return {"RELIEF": self.relief, "V_EXACT": self.relief and self.v_exact,
                "MARCH_FIXED": self.relief and self.march == "fixed",
                "HEIGHT_FETCH4": self.height_fetch == "texel",
                "SCREEN_PROXY": self.proxy == "screen", "LABELS": self.labels}

    def march_uniforms(self) -> dict:
        """Uniforms of the pyramid and the relief march, shared by the eye's and the light's
        pass."""
        return {"hull_padding": self.hull_padding, "linear_steps": self.linear_steps,
                "binary_steps": self.binary_steps, "march_density": self.march_density,
                "march_min_steps": self.march_min_steps, "march_precision": self.march_precision,
                "height_maps": 0}

    def describe(self) -> str:
        """RC, or RC+R with its march (RT, RT+R with ``method`` rt), as reports and the
        viewer's heads-up line name it."""
        name = self.method.upper()
        if not self.relief:
            return name
        steps = (f"{self.linear_steps} linear + {self.binary_steps} binary steps" if self.march == "fixed" else
                 f"adaptive march, {self.march_density:g} samples per texel, at most {self.linear_steps} linear "
                 f"+ {self.binary_steps} binary steps")
        return f"{name}+R ({steps}, v {'exact' if self.v_exact else 'interpolated'})"

    def summary(self) -> str:
        """How the frame was drawn, in plain words (``ray cast with relief mapping``): what
        a report prints without ``--verbose`` (:meth:`describe` is the detail)."""
        name = "ray traced" if self.method == "rt" else "ray cast"
        return name + (" with relief mapping" if self.relief else "")


@dataclass(frozen=True)
class ShadowSettings:
    """The shadow map's knobs.

    resolution : texels per side of the square map
    caster : ``"relief"`` (the relief surface casts the shadow when relief is on, ray cast
        and marched), ``"inner"`` (the inner cone casts it: cheaper, no march in the shadow
        pass) or ``"mesh"`` (what an engine does: the frusta tessellated at ``mesh_level``,
        displaced by the relief when it is on, built once and rasterised into the map;
        cheaper than the march on a few large rows, coarser, and its triangles grow as
        16·4^m a row: ``python -m plantgen.benchmarks.light_caster`` measures both)
    mesh_level : the mesh caster's subdivision level m (GS+R's)
    march : how the relief caster's light rays find the relief surface: ``"secant"`` (the
        light's own march, ``shaders/light_march.glsl``: only the band the relief occupies,
        (u, v) interpolated along the ray from three angles instead of one per sample,
        then regula falsi between the last sample above the relief and the first below)
        or ``"bisect"`` (the eye's march at the map's footprint: an angle per sample, then
        bisection)
    march_density, march_precision : the relief caster's adaptive march in the light's
        pass (see :class:`RaycastSettings`), measured in the map's texels instead of the
        eye's pixels: samples per relief texel the light's ray crosses (a relief texel
        counting at least one map texel), and the refinement's bracket in map texels (the
        receivers' bias is half a texel, so a finer depth is not seen); the eye's
        ``linear_steps``, ``march_min_steps`` and ``binary_steps`` bound the march
    cache : keep the map and draw it again only when what it depends on changes (the
        light, the casters' geometry and box, the map's size and caster, the relief's
        knobs: :class:`plantgen.gl.frame.ShadowKey`); False draws it every frame (to time it)
    bias : constant depth bias in texels (world size of one texel), subtracted from the
        receiver's light depth after the receiver-plane extrapolation
    max_slope : clamp of the receiver plane's depth gradient (|tan| of the light's angle
        to the normal); only surfaces lit at more than atan(max_slope) from their normal
        may self-shadow, where the diffuse term is below 1/max_slope anyway
    """

    resolution: int = knob(2048, "--shadow-res", "Shadow map texels per side.", kind="int", lo=16, hi=16384)
    caster: str = knob("relief", "--shadow-caster", "What casts the shadow: with relief the relief surface, ray cast "
                       "(relief), or the branch under its relief (inner, cheaper); or the branches as triangles at "
                       "--shadow-mesh-level (mesh: as a game engine casts, displaced by the relief).",
                       kind="choice", choices=("relief", "inner", "mesh"))
    mesh_level: int = knob(6, "--shadow-mesh-level", "Mesh caster: subdivision level m (16·4^m triangles a branch "
                           "piece).",
                           kind="int", lo=0, hi=8)
    march: str = knob("secant", "--shadow-march", "Relief caster: how the light's rays find the relief: the light's "
                      "own march (secant, cheaper) or the eye's (bisect).", kind="choice",
                      choices=("secant", "bisect"))
    march_density: float = knob(0.5, "--shadow-march-density", "Relief caster: samples per relief texel the light's "
                                "ray crosses (a texel counts at least one map texel).", lo=0, lo_open=True)
    march_precision: float = knob(0.5, "--shadow-march-precision", "Relief caster: refine each light ray's hit to this "
                                  "many map texels (the receivers' bias is half a texel).", lo=0, lo_open=True)
    cache: bool = knob(True, "--shadow-cache", "Draw the shadow map once and reuse it while the light, the geometry "
                       "and the map's knobs stay (a camera move does not redraw it).", kind="bool")
    bias: float = 0.5
    max_slope: float = 50.0

    def __post_init__(self):
        check_knobs(self)
        if self.bias < 0 or self.max_slope <= 0:
            raise PlantgenError("shadow bias must be >= 0 and max slope > 0")


@dataclass(frozen=True)
class DetailSettings:
    """The level of detail of a scene drawn instanced (the ``lod`` effect;
    :mod:`plantgen.geometry.rays.instances`): per copy, the segments whose subtree spans fewer
    than ``lod_pixels`` pixels from the copy's nearest point are left out, twigs first
    (in the light's pass: texels of the shadow map); 0 draws every segment."""

    lod_pixels: float = knob(2.0, "--lod-pixels", "With the lod effect: leave out, per plant copy, the segments "
                             "(and their subtrees) that span fewer pixels than this (0: full detail).", lo=0, hi=1e6,
                             metavar="PX")

    def __post_init__(self):
        check_knobs(self)


@dataclass(frozen=True)
class ImageSettings:
    """The picture: ``size`` (width, height) in pixels (None: a camera file's, else
    :data:`DEFAULT_SIZE`), ``ssaa`` samples per pixel side, ``aa`` the anti-aliasing of a
    frame drawn at one sample a side (:data:`AA_CHOICES`), ``background`` by name
    (``sky``, a colour, ``none``: :func:`plantgen.images.parse_background`), ``ground``
    (:data:`GROUND_CHOICES`: ``auto``, the scene's or a single plant's disc, or ``none``)."""

    size: tuple | None = knob(None, "--size", "Image size (WIDTHxHEIGHT pixels; default: the camera file's, else "
                              f"{DEFAULT_SIZE[0]}x{DEFAULT_SIZE[1]}).", kind="size", metavar="WxH")
    ssaa: int = knob(1, "--ssaa", "Supersampling: N x N rays a pixel, averaged in linear light (thin twigs stop "
                     "breaking into dots; the frame costs about N² times as much).", kind="int", lo=1, hi=MAX_SSAA,
                     metavar="N")
    aa: str = knob("coverage", "--aa", "Anti-aliasing: 'coverage' draws a twig thinner than a pixel as a "
                   "continuous line a pixel wide, blended by its share of the pixel; 'edges' also smooths the "
                   "image's edges along their direction (softer, and blurs fine detail); 'none' one ray a pixel, "
                   "as before (thin twigs break into dots). --ssaa N above 1 replaces it.",
                   kind="choice", choices=AA_CHOICES)
    background: str = knob("sky", "--background", "The background: 'sky', a colour (white, '#20304a') or 'none' "
                           "for a transparent PNG (RGBA: the alpha is the model's coverage).", kind="str",
                           metavar="COLOUR|none")
    ground: str = knob("auto", "--ground", "The ground: 'auto' is the scene's ground, and under a single plant a "
                       "sand disc that fades into the sky and takes the plant's shadow; 'none' draws no ground.",
                       kind="choice", choices=GROUND_CHOICES)

    def __post_init__(self):
        check_knobs(self)
        if self.size is not None:
            object.__setattr__(self, "size", (int(self.size[0]), int(self.size[1])))


@dataclass(frozen=True)
class MotionSettings:
    """Time: the pose of a still (``time``, seconds), or an animation of ``frames``
    frames at ``fps`` starting there; ``pose``: where the frames are posed (``"gpu"``:
    :mod:`plantgen.gl.pose` and the vertex-skinned mesh; ``"cpu"``: numpy every frame)."""

    time: float | None = knob(None, "--time", "Seconds: the pose of an animated scene for a still (default 0), or the "
                              "first frame's time.", lo=0, metavar="T")
    frames: int | None = knob(None, "--frames", "Write an animation of this many frames (-o .gif or .webp).",
                              kind="int", lo=1, hi=100_000)
    fps: float = knob(12.0, "--fps", "Frames per second of the animation (0.01..1000).", lo=0.01, hi=1000)
    pose: str = knob("gpu", "--pose", "Where an animation's moving branches are posed each frame: on the GPU (gpu; "
                     "a frame where a joint may turn sharp is posed on the CPU) or in numpy (cpu). "
                     "--method rt poses on the CPU.",
                     kind="choice", choices=("gpu", "cpu"))

    def __post_init__(self):
        check_knobs(self)

    @property
    def start(self) -> float:
        """The first (or only) pose's time."""
        return float(self.time or 0.0)


@dataclass(frozen=True)
class ViewSettings:
    """Where the camera is: ``camera`` ``"auto"`` (the scene's, else the model framed), a
    camera JSON path or a :class:`~plantgen.geometry.rays.camera.Camera`; ``orbit`` turns it."""

    camera: object = knob("auto", "--camera", "'auto' frames the model to span most of the viewport (or uses the "
                          "scene's camera); a camera JSON written by --camera-out or by the viewer's C key is taken "
                          "back.", kind="str", metavar="auto|FILE.json")
    orbit: Orbit = Orbit()

    @property
    def auto(self) -> bool:
        return isinstance(self.camera, str) and self.camera == "auto"


@dataclass(frozen=True)
class MeshSettings:
    """A tessellation (GS, GS+R): ``level`` m (16·4^m triangles per frustum, 8·2^m per
    cap) and ``relief`` (vertices displaced onto the relief shell)."""

    level: int = knob(1, "--subdiv", "Subdivision level m: 16·4^m triangles per frustum, plus 8·2^m per cap.",
                      kind="int", lo=0, hi=MAX_SUBDIV, metavar="M")
    relief: bool = False

    def __post_init__(self):
        check_knobs(self)


@dataclass(frozen=True)
class ParallaxSettings:
    """GS+POM: parallax occlusion mapping of the mesh on the relief's outer shell
    (``shaders/raster.glsl``'s PARALLAX). Each fragment walks its view ray down through the
    shell in ``min_layers`` (face-on) up to ``max_layers`` (grazing) layers of the baked
    height map, the count mixed by the view's cosine as engines do, then takes
    ``refine_steps`` secant steps between the last layer above the relief and the first
    below (1: the classic POM interpolation, no extra sample; 0: steep parallax mapping)."""

    min_layers: int = knob(8, "--pom-min-layers", "GS+POM: height-map layers a face-on ray walks (the fewest).",
                           kind="int", lo=1, hi=256, metavar="N")
    max_layers: int = knob(32, "--pom-max-layers", "GS+POM: height-map layers a grazing ray walks (the most; at "
                           "least --pom-min-layers).", kind="int", lo=1, hi=256, metavar="N")
    refine_steps: int = knob(1, "--pom-refine-steps", "GS+POM: secant steps after the layers (1: the classic "
                             "interpolation; 0: steep parallax).", kind="int", lo=0, hi=16, metavar="N")

    def __post_init__(self):
        check_knobs(self)
        if self.min_layers > self.max_layers:
            raise PlantgenError(f"--pom-min-layers ({self.min_layers}) must be at most --pom-max-layers "
                                f"({self.max_layers})")

    def uniforms(self) -> dict:
        """The PARALLAX program's uniforms."""
        return {"pom_min_layers": self.min_layers, "pom_max_layers": self.max_layers,
                "pom_refine_steps": self.refine_steps}


@dataclass(frozen=True)
class LevelSettings:
    """The levels of detail an export writes (glTF ``MSFT_lod``, a USD variantSet
    ``lod``): ``levels`` per plant, level 0 the full mesh and each next one at most half the
    rows of the one above (:func:`plantgen.geometry.rays.instances.detail_levels`); None: as the
    scene's effects say (:meth:`export_levels`). Their screen coverages follow
    :class:`DetailSettings`' ``lod_pixels``."""

    levels: int | None = knob(None, "--lod-levels", "glTF, USD: write N levels of detail per plant (level 0 full, "
                              "each next one at most half the segments, twigs first); 1 writes none. Default: 4 for "
                              "a scene that lists the lod effect, else 1.", kind="int", lo=1, hi=8, metavar="N",
                              param="lod_levels")

    def __post_init__(self):
        check_knobs(self)

    def export_levels(self, effects) -> int:
        """The levels of detail an export writes for a model whose effects are ``effects``:
        ``levels`` where given, else :data:`LOD_EXPORT_LEVELS` with ``lod`` and 1 without."""
        if self.levels is not None:
            return int(self.levels)
        return LOD_EXPORT_LEVELS if "lod" in effects else 1


@dataclass(frozen=True)
class KeyframeSettings:
    """The sway an export writes as an animation (glTF, USD; a scene that lists
    ``animation``; ``sway`` False: none, the plants at rest): ``rate`` keyframes per
    second, interpolated linearly (slerp) by the players, over ``duration`` seconds from
    t = 0 (None: one period of the scene's sway, the common period of its plants', so that
    the animation loops)."""

    sway: bool = knob(True, "--sway", "Write a swaying scene's sway as a looping animation (glTF, USD); "
                      "--no-sway writes its plants at rest, as a still file.", kind="bool")
    rate: float = knob(24.0, "--key-rate", "Keyframes per second of the sway a glTF or USD export writes "
                       "(interpolated linearly; the docs' 'Export a swaying scene' gives the error).", lo=0,
                       lo_open=True, hi=1000, metavar="HZ")
    duration: float | None = knob(None, "--duration", "Seconds of sway a glTF or USD export writes, from t = 0. "
                                  "Default: one period of the scene's sway (the common period of its plants'), "
                                  "so that the animation loops.", lo=0, lo_open=True, hi=3600, metavar="SECONDS")

    def __post_init__(self):
        check_knobs(self)


@dataclass(frozen=True)
class RenderSettings:
    """Everything a render is asked for, whole (see the module's docstring)."""

    effects: EffectSettings = EffectSettings()
    march: RaycastSettings = RaycastSettings()
    shadows: ShadowSettings = ShadowSettings()
    image: ImageSettings = ImageSettings()
    motion: MotionSettings = MotionSettings()
    view: ViewSettings = ViewSettings()
    detail: DetailSettings = DetailSettings()

    @classmethod
    def from_options(cls, **options) -> RenderSettings:
        """The settings from flat keywords named as the command line's options
        (``linear_steps=16, shadow_res=1024, azimuth=60, time=0.5``); a keyword left None
        keeps its default; an unknown one is one line naming the known ones."""
        return build_settings(cls, options)

    def frame(self, effects) -> tuple[RaycastSettings, ShadowSettings | None]:
        """The ray caster's knobs and the shadow map's for the ``effects`` in force: relief
        on iff they hold ``relief``, each look iff they hold it (:class:`LookSettings`); no
        shadow map without ``shadows``."""
        look = replace(self.march.look, tone="tone" in effects, translucency="translucency" in effects,
                       sky="sky" in effects, bounce="bounce" in effects)
        return (replace(self.march, relief="relief" in effects, look=look),
                self.shadows if "shadows" in effects else None)

    def lod_pixels(self, effects) -> float:
        """The level of detail's threshold in pixels for the ``effects`` in force (0: full
        detail; without ``lod`` a scene is drawn merged and whole)."""
        return self.detail.lod_pixels if "lod" in effects else 0.0


def settings_knobs(cls) -> list:
    """(knob, default) of every knob of ``cls``, nested settings included, in declaration order."""
    out = []
    for f in fields(cls):
        k = f.metadata.get("knob")
        if k is not None:
            out.append((k, f.default))
        elif is_dataclass(f.default):
            out += settings_knobs(type(f.default))
    return out


def option_names(cls) -> tuple[str, ...]:
    """Every knob name ``cls`` takes, nested settings included."""
    return tuple(k.name for k, _ in settings_knobs(cls))


def build_settings(cls, options: dict):
    """``cls`` (a settings dataclass, nested ones built in turn) from flat keywords named as
    the knobs; values left None keep their defaults."""
    unknown = sorted(set(options) - set(option_names(cls)))
    if unknown:
        raise PlantgenError(f"unknown setting {', '.join(unknown)} (known: {', '.join(option_names(cls))})")
    return _built(cls, options)


def _built(cls, options: dict):
    kw = {}
    for f in fields(cls):
        k = f.metadata.get("knob")
        if k is not None:
            if options.get(k.name) is not None:
                kw[f.name] = options[k.name]
        elif is_dataclass(f.default) and any(options.get(n) is not None for n in option_names(type(f.default))):
            kw[f.name] = _built(type(f.default), options)
    return cls(**kw)
