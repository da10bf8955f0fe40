"""The configurations the bench measures: the four methods of Table 1, GS+N, GS+POM, and their knobs.

Each method is declared once, as a row of :data:`METHODS` (:class:`Method`): its short
name in the results, what its level is matched against, its mesh, its maps, its family
of the curves, its style in the plots and its note in the table; the rest of the bench
reads that row.

The ray caster's knobs are swept one at a time (:data:`RELIEF_SWEEPS`): each
:class:`Sweep` sets one :class:`~plantgen.gl.raycast.RaycastSettings` field over its
values, every other field at the ray caster's default. Adding a swept RC+R knob is one
line there, e.g. ``Sweep("march", "march", ("adaptive",))``, or, for a knob that only means
something under another setting, ``Sweep("texel", "samples_per_texel", (0.5, 1, 2),
base=(("march", "adaptive"),))``. The GS, GS+R, GS+N and GS+POM levels are not a fixed list:
the bench goes up from m = 0 (:func:`level_config`) until a level matches
(:mod:`plantgen.table1.matching`). GS+POM's knobs (:data:`PARALLAX_SWEEPS`) are swept
one at a time at its matched level, from the run's :class:`~plantgen.settings.ParallaxSettings`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, replace

from ..settings import ParallaxSettings, RaycastSettings
from .params import BenchOptions

__all__ = ["Config", "Method", "METHODS", "METHOD_OF", "Sweep", "RELIEF_SWEEPS", "ParallaxSweep",
           "PARALLAX_SWEEPS", "ray_cast_configs", "relief_configs", "parallax_configs", "level_config",
           "TABLE_METHODS", "MATCHED_AGAINST", "LEVEL_METHODS", "MAPPED_METHODS"]


@dataclass(frozen=True)
class Method:
    """One method of the bench, declared once.

    short : its name in the results' fields (``rc``, ``gsr``: ``gsr_fps``, ``gsr_bytes``)
    name : its name in the tables and the configuration keys (``GS+R``: ``gs+r:m=2``)
    family : ``plain`` or ``relief``: the reference it is measured against (its curves'
        Pareto front)
    matched_against : a polygonal method's level walk target (``rc``, or ``rcr`` at RC+R's
        Table 1 configuration); None for the ray caster
    mesh : None (ray cast), ``cone`` (the smooth mesh), ``relief`` (displaced onto the
        relief, GS+R) or ``outer`` (on the relief's outer shell, GS+POM)
    maps : None, ``normal`` (the baked normal maps) or ``parallax`` (the normal maps with
        the height in their alpha, marched by parallax occlusion mapping)
    texture_field : the memory table's field of its maps' bytes
    style : (colour, marker) of its series in the plots
    about : what it is, one sentence for the table's notes (methods not in the paper)
    """

    short: str
    name: str
    family: str
    matched_against: str | None = None
    mesh: str | None = None
    maps: str | None = None
    texture_field: str | None = None
    style: tuple = ("tab:gray", "h")
    about: str = ""


#: The methods of the bench: the four of Table 1, then GS+N and GS+POM (the smooth mesh with
#: the relief baked into normal maps, :func:`plantgen.exporters.textures.bake_textures`, as a
#: glTF reader draws them; the mesh on the outer shell with parallax occlusion mapping of
#: the baked height, as game engines draw relief).
METHODS = (
    Method("rc", "RC", "plain", style=("tab:green", "D")),
    Method("rcr", "RC+R", "relief", style=("tab:red", "^")),
    Method("gs", "GS", "plain", "rc", "cone", style=("tab:blue", "o")),
    Method("gsr", "GS+R", "relief", "rcr", "relief", style=("tab:orange", "s")),
    Method("gsn", "GS+N", "relief", "rcr", "cone", "normal", "normal_map_bytes", ("tab:cyan", "p"),
           "GS's smooth mesh at level m with the relief baked into normal maps (as plantgen export writes "
           "them); its bytes count the tangents and the normal maps (mipmaps included)"),
    Method("gspom", "GS+POM", "relief", "rcr", "outer", "parallax", "pom_map_bytes", ("black", "8"),
           "the mesh at level m on the relief's outer shell with parallax occlusion mapping (the baked "
           "height marched per pixel in tangent space, then the normal map at the displaced (u, v); the "
           "distance is the displaced point's, the outline the mesh's); its bytes count the tangents, the "
           "RGBA maps (height in alpha, mipmaps included), 8 B a vertex of uv scales and 4 B a row of shell "
           "thickness"),
)
#: :data:`METHODS` by name (``GS+POM``).
METHOD_OF = {m.name: m for m in METHODS}
#: The methods of the bench by their short names in the results ("rc", "rcr", ...).
TABLE_METHODS = {m.short: m.name for m in METHODS}
#: The quality criterion: each polygonal method's level is matched against the error of
#: the ray caster without relief (GS) or with it (GS+R, GS+N, GS+POM at RC+R's Table 1
#: configuration).
MATCHED_AGAINST = {m.short: m.matched_against for m in METHODS if m.matched_against}
#: The methods measured level by level (m = 0, 1, ...).
LEVEL_METHODS = tuple(m.name for m in METHODS if m.mesh is not None)
#: The methods drawn with baked maps (not in the paper).
MAPPED_METHODS = tuple(m for m in METHODS if m.maps is not None)


@dataclass
class Config:
    """One measured configuration: a method and the value of one of its knobs.

    method : a name of :data:`METHODS` (RC, RC+R, GS, GS+R, GS+N, GS+POM)
    knob : what varies ("", "m", or a sweep's knob: "linear", "binary", "v", "layers", ...)
    value : the knob's value ("" for no knob)
    settings : the ray caster's settings (RC, RC+R)
    level : the subdivision level m (GS, GS+R, GS+N, GS+POM)
    parallax : GS+POM's parallax occlusion mapping knobs
    """

    method: str
    knob: str = ""
    value: object = ""
    settings: RaycastSettings | None = None
    level: int | None = None
    parallax: ParallaxSettings | None = None

    @property
    def spec(self) -> Method:
        """The method's row of :data:`METHODS`."""
        return METHOD_OF[self.method]

    @property
    def key(self) -> str:
        """The configuration's name in the results, e.g. ``rc``, ``gs:m=2``,
        ``rc+r:linear=16``."""
        return self.method.lower() + (f":{self.knob}={self.value}" if self.knob else "")

    @property
    def ray_cast(self) -> bool:
        """RC or RC+R (else a tessellation: GS, GS+R, GS+N, GS+POM)."""
        return self.spec.mesh is None

    @property
    def relief(self) -> bool:
        """RC+R, GS+R, GS+N or GS+POM: measured against the relief reference."""
        return self.spec.family == "relief"

    @property
    def surface(self) -> str | None:
        """The mesh drawn (:attr:`Method.mesh`): ``cone``, ``relief`` or ``outer``."""
        return self.spec.mesh

    @property
    def displaced(self) -> bool:
        """GS+R: a mesh with the relief in its vertices (GS+N's mesh is GS's, smooth)."""
        return self.surface == "relief"

    @property
    def normal_mapped(self) -> bool:
        """GS+N: the smooth mesh drawn with the baked normal maps."""
        return self.spec.maps == "normal"

    @property
    def maps(self) -> str | None:
        """The baked maps drawn (:attr:`Method.maps`), None without."""
        return self.spec.maps

    def identity(self) -> dict:
        """The fields that name this configuration in a results row (with the ray
        caster's settings, all fields, for RC and RC+R; GS+POM's knobs, and its level)."""
        out = {"key": self.key, "method": self.method, "knob": self.knob, "value": self.value}
        if self.settings is not None:
            out["settings"] = asdict(self.settings)
        if self.parallax is not None:
            out["parallax"] = asdict(self.parallax)
            out["level"] = self.level
        return out


def _same(value):
    return value


@dataclass(frozen=True)
class Sweep:
    """One swept RC+R knob.

    knob : its name in the configuration keys (``rc+r:KNOB=VALUE``)
    field : the :class:`RaycastSettings` field it sets
    values : the values, or the name of the :class:`BenchOptions` field that holds them
    base : ``(field, value)`` pairs set besides, e.g. the mode a density knob belongs to
    label : value -> how the key shows it (default: the value itself)
    """

    knob: str
    field: str
    values: tuple | str
    base: tuple = ()
    label: Callable = _same

    def values_of(self, opts: BenchOptions) -> tuple:
        """The values swept in a run with ``opts``."""
        return tuple(getattr(opts, self.values) if isinstance(self.values, str) else self.values)

    def configs(self, opts: BenchOptions) -> list[Config]:
        """One RC+R configuration per value, every other field at the ray caster's default."""
        return [Config("RC+R", self.knob, self.label(v),
                       RaycastSettings(relief=True, **{**dict(self.base), self.field: v}))
                for v in self.values_of(opts)]


def _exact(v_exact: bool) -> str:
    return "exact" if v_exact else "interpolated"


#: The fixed march the paper measured: ``linear_steps`` samples for every ray, then 6
#: bisection steps (the linear sweep's base; the binary sweep's linear count is 32).
FIXED_MARCH = (("march", "fixed"), ("linear_steps", 32), ("binary_steps", 6))

#: The RC+R knobs the bench sweeps, in order (one line per knob).
RELIEF_SWEEPS = (
    # the paper's march: a fixed count of uniform samples, then bisection
    Sweep("linear", "linear_steps", "linear_steps", base=FIXED_MARCH),
    Sweep("binary", "binary_steps", "binary_steps", base=FIXED_MARCH),
    # the adaptive march (the ray caster's default): samples per relief texel crossed
    Sweep("density", "march_density", "march_densities"),
    Sweep("v", "v_exact", (True,), label=_exact),
)


def relief_configs(opts: BenchOptions, sweeps=RELIEF_SWEEPS) -> list[Config]:
    """The RC+R configurations of ``sweeps`` in order; a configuration whose settings an
    earlier one already has (e.g. binary = 6, the default, after the linear sweep's 32) is
    left out."""
    out, seen = [], set()
    for sweep in sweeps:
        for cfg in sweep.configs(opts):
            if cfg.settings not in seen:
                seen.add(cfg.settings)
                out.append(cfg)
    return out


def ray_cast_configs(opts: BenchOptions, relief: bool) -> list[Config]:
    """The ray caster's configurations of a model, RC first (its image picks the evaluation
    window), then, for a model with relief, the RC+R sweeps."""
    out = [Config("RC", settings=RaycastSettings())]
    if relief:
        out += relief_configs(opts)
    return out


def level_config(method: str, level: int, parallax: ParallaxSettings | None = None) -> Config:
    """GS, GS+R, GS+N or GS+POM at subdivision level ``level`` (GS+POM with ``parallax``,
    default :class:`ParallaxSettings`' defaults)."""
    if method not in LEVEL_METHODS:
        raise ValueError(f"{method} has no subdivision level")
    if METHOD_OF[method].maps == "parallax":
        return Config(method, "m", level, level=level, parallax=parallax or ParallaxSettings())
    return Config(method, "m", level, level=level)


@dataclass(frozen=True)
class ParallaxSweep:
    """One swept GS+POM knob, at the method's matched level.

    knob : its name in the configuration keys (``gs+pom:KNOB=VALUE``)
    values : the name of the :class:`BenchOptions` field that holds its values
    apply : (the run's ParallaxSettings, value) -> the settings of that configuration
    """

    knob: str
    values: str
    apply: Callable

    def configs(self, opts: BenchOptions, method: str, level: int) -> list[Config]:
        return [Config(method, self.knob, v, level=level, parallax=self.apply(opts.parallax, v))
                for v in getattr(opts, self.values)]


#: GS+POM's knobs the bench sweeps, in order: the layers (``max_layers`` N at grazing
#: angles, N/4 face-on, the defaults' ratio), and the secant steps after them.
PARALLAX_SWEEPS = (
    ParallaxSweep("layers", "pom_layers", lambda p, n: replace(p, min_layers=max(1, n // 4), max_layers=n)),
    ParallaxSweep("refine", "pom_refine_steps", lambda p, n: replace(p, refine_steps=n)),
)


def parallax_configs(opts: BenchOptions, method: str, level: int, sweeps=PARALLAX_SWEEPS) -> list[Config]:
    """The sweeps' configurations of ``method`` (GS+POM) at ``level``, in order; one whose
    knobs the run's own (:attr:`BenchOptions.parallax`, measured by the level walk) or an
    earlier one already has is left out."""
    out, seen = [], {opts.parallax}
    for sweep in sweeps:
        for cfg in sweep.configs(opts, method, level):
            if cfg.parallax not in seen:
                seen.add(cfg.parallax)
                out.append(cfg)
    return out
