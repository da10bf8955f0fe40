"""The configurations the bench measures: the four methods of Table 1 and their knobs."""

from __future__ import annotations

from dataclasses import dataclass

from ..render.raycast import RaycastSettings
from .options import BenchOptions

__all__ = ["Config", "bench_configs", "default_relief_config", "find_level", "TABLE_METHODS",
           "MATCHED_AGAINST"]

#: The four methods of Table 1 by their short names in the results ("rc", "rcr", ...).
TABLE_METHODS = {"rc": "RC", "rcr": "RC+R", "gs": "GS", "gsr": "GS+R"}
#: The quality criterion: each polygonal method's level is matched against the error of
#: the ray caster without relief (GS) or with it (GS+R).
MATCHED_AGAINST = {"gs": "rc", "gsr": "rcr"}


@dataclass
class Config:
    """One measured configuration: a method and the value of one of its knobs.

    method : RC, RC+R, GS or GS+R
    knob : what varies ("", "m", "linear", "binary", "v")
    value : the knob's value ("" for no knob)
    settings : the ray caster's settings (RC, RC+R)
    level : the subdivision level m (GS, GS+R)
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
        """RC+R or GS+R: measured against the relief reference."""
        return self.method.endswith("+R")

    def identity(self) -> dict:
        """The fields that name this configuration in a results row."""
        return {"key": self.key, "method": self.method, "knob": self.knob, "value": self.value}


def _level_configs(method: str, levels) -> list[Config]:
    return [Config(method, "m", m, level=m) for m in levels]


def _relief_step_configs(opts: BenchOptions) -> list[Config]:
    """RC+R over the linear steps, then over the binary steps (the other knob at its
    default; a pair already swept is left out), then with v exact."""
    default = RaycastSettings(relief=True)
    out = [Config("RC+R", "linear", n, RaycastSettings(relief=True, linear_steps=n,
                                                        binary_steps=default.binary_steps))
           for n in opts.linear_steps]
    for n in opts.binary_steps:
        if n == default.binary_steps and default.linear_steps in opts.linear_steps:
            continue
        out.append(Config("RC+R", "binary", n, RaycastSettings(relief=True, linear_steps=default.linear_steps,
                                                               binary_steps=n)))
    out.append(Config("RC+R", "v", "exact", RaycastSettings(relief=True, v_exact=True)))
    return out


def bench_configs(opts: BenchOptions, relief: bool) -> list[Config]:
    """Every configuration of a model, RC first (its image picks the evaluation window):
    RC, GS at each level and, for a model with relief, the RC+R knobs and GS+R at each level."""
    out = [Config("RC", settings=RaycastSettings())]
    out += _level_configs("GS", opts.levels)
    if relief:
        out += _relief_step_configs(opts)
        out += _level_configs("GS+R", opts.levels)
    return out


def default_relief_config(configs) -> Config:
    """The RC+R configuration at the ray caster's default steps (32 linear, 6 binary): the
    linear sweep's, else the binary sweep's, else the first RC+R one."""
    default = RaycastSettings(relief=True)
    relief = [c for c in configs if c.method == "RC+R"]
    for knob, value in (("linear", default.linear_steps), ("binary", default.binary_steps)):
        for c in relief:
            if c.knob == knob and c.value == value:
                return c
    return relief[0]


def find_level(configs, method: str, level: int | None) -> Config | None:
    """The ``method`` configuration at subdivision ``level`` (None for no level)."""
    if level is None:
        return None
    return next(c for c in configs if c.method == method and c.level == level)
