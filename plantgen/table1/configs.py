"""The configurations the bench measures: the four methods of Table 1, GS+N, and their knobs.

The ray caster's knobs are swept one at a time (:data:`RELIEF_SWEEPS`): each
:class:`Sweep` sets one :class:`~plantgen.gl.raycast.RaycastSettings` field over its
values, every other field at the ray caster's default. Adding a swept RC+R knob is one
line there, e.g. ``Sweep("march", "march", ("adaptive",))``, or, for a knob that only means
something under another setting, ``Sweep("texel", "samples_per_texel", (0.5, 1, 2),
base=(("march", "adaptive"),))``. The GS, GS+R and GS+N levels are not a fixed list: the bench
goes up from m = 0 (:func:`level_config`) until a level matches (:mod:`plantgen.table1.matching`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

from ..settings import RaycastSettings
from .params import BenchOptions

__all__ = ["Config", "Sweep", "RELIEF_SWEEPS", "ray_cast_configs", "relief_configs", "level_config",
           "TABLE_METHODS", "MATCHED_AGAINST", "LEVEL_METHODS"]

#: The methods of the bench by their short names in the results ("rc", "rcr", ...): the
#: four of Table 1, then GS+N (the smooth mesh at level m with the relief baked into a
#: normal map, :func:`plantgen.exporters.textures.bake_textures`, as a glTF reader draws it).
TABLE_METHODS = {"rc": "RC", "rcr": "RC+R", "gs": "GS", "gsr": "GS+R", "gsn": "GS+N"}
#: The quality criterion: each polygonal method's level is matched against the error of
#: the ray caster without relief (GS) or with it (GS+R and GS+N, at RC+R's Table 1
#: configuration).
MATCHED_AGAINST = {"gs": "rc", "gsr": "rcr", "gsn": "rcr"}
#: The methods measured level by level (m = 0, 1, ...).
LEVEL_METHODS = ("GS", "GS+R", "GS+N")


@dataclass
class Config:
    """One measured configuration: a method and the value of one of its knobs.

    method : RC, RC+R, GS, GS+R or GS+N
    knob : what varies ("", "m", or a :class:`Sweep`'s knob: "linear", "binary", "v", ...)
    value : the knob's value ("" for no knob)
    settings : the ray caster's settings (RC, RC+R)
    level : the subdivision level m (GS, GS+R, GS+N)
    """

    method: str
    knob: str = ""
    value: object = ""
    settings: RaycastSettings | None = None
    level: int | None = None

    @property
    def key(self) -> str:
        """The configuration's name in the results, e.g. ``rc``, ``gs:m=2``,
        ``rc+r:linear=16``."""
        return self.method.lower() + (f":{self.knob}={self.value}" if self.knob else "")

    @property
    def ray_cast(self) -> bool:
        """RC or RC+R (else a tessellation: GS or GS+R)."""
        return self.method.startswith("RC")

    @property
    def relief(self) -> bool:
        """RC+R, GS+R or GS+N: measured against the relief reference."""
        return self.method.endswith("+R") or self.normal_mapped

    @property
    def displaced(self) -> bool:
        """GS+R: a mesh with the relief in its vertices (GS+N's mesh is GS's, smooth)."""
        return self.method == "GS+R"

    @property
    def normal_mapped(self) -> bool:
        """GS+N: the smooth mesh drawn with the baked normal maps."""
        return self.method == "GS+N"

    def identity(self) -> dict:
        """The fields that name this configuration in a results row (with the ray
        caster's settings, all fields, for RC and RC+R)."""
        out = {"key": self.key, "method": self.method, "knob": self.knob, "value": self.value}
        if self.settings is not None:
            out["settings"] = asdict(self.settings)
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


def level_config(method: str, level: int) -> Config:
    """GS, GS+R or GS+N at subdivision level ``level``."""
    if method not in LEVEL_METHODS:
        raise ValueError(f"{method} has no subdivision level")
    return Config(method, "m", level, level=level)
