"""The knobs of one bench run."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from ..settings import ParallaxSettings
from .paper import TABLE1_MODELS
from .quality import MATCH_ABS_TOL, MATCH_REL_TOL

__all__ = ["BenchOptions", "QUICK_MODELS", "RELIEF_ERROR"]

#: The models of the quick (CI) run: two tiny ones, one of them with shadows and ground.
QUICK_MODELS = ("saguaro", "well")
#: Default error bound of the RC+R configuration Table 1 times (:attr:`BenchOptions.relief_error`).
RELIEF_ERROR = 0.01


@dataclass
class BenchOptions:
    """Knobs of one bench run.

    models : grammar/scene names or paths
    size : (width, height) of the timed frames, pixels
    frames : timed frames of each Table 1 method (after one warm-up frame)
    curve_frames : timed frames of each configuration of the accuracy curves
    eval_size : (width, height) of the evaluation window (same angle per pixel as ``size``)
    linear_steps, binary_steps : relief step counts swept for RC+R with the paper's fixed
        march (the other knob at 32 linear / 6 binary)
    march_densities : samples per relief texel swept for RC+R with the adaptive march (the
        ray caster's default); the swept knobs are listed in
        :data:`plantgen.table1.configs.RELIEF_SWEEPS`
    parallax : GS+POM's knobs for its level walk and Table 1 (the command's
        ``--pom-*`` options)
    pom_layers, pom_refine_steps : GS+POM's knobs swept at its matched level
        (:data:`plantgen.table1.configs.PARALLAX_SWEEPS`): the layers at grazing angles
        (a quarter of them face-on), the secant steps after them
    relief_error : Table 1 times the fastest RC+R configuration of the curves whose error
        is at most this (the most accurate one if none is), and matches GS+R against it
    max_triangles : the triangle budget: GS, GS+R, GS+N and GS+POM go up from m = 0 until a level
        qualifies or the next level has more triangles than this (not built)
    reference_relief_samples : linear samples of the reference's relief march before
        bisection to 1e-9
    rel_tol, abs_tol : the quality criterion's tolerance
    images : write the compared images
    quick : the CI run (small sizes, few knobs)
    """

    models: tuple = TABLE1_MODELS
    size: tuple = (1024, 768)
    frames: int = 9
    curve_frames: int = 5
    eval_size: tuple = (128, 96)
    linear_steps: tuple = (4, 8, 16, 32, 64)
    binary_steps: tuple = (0, 2, 4, 6, 8)
    march_densities: tuple = (0.5, 1.0, 2.0, 4.0, 8.0)
    parallax: ParallaxSettings = ParallaxSettings()
    pom_layers: tuple = (4, 8, 16, 64)
    pom_refine_steps: tuple = (0, 4)
    relief_error: float = RELIEF_ERROR
    max_triangles: int = 6_000_000
    reference_relief_samples: int = 384
    rel_tol: float = MATCH_REL_TOL
    abs_tol: float = MATCH_ABS_TOL
    images: bool = False
    quick: bool = False

    @classmethod
    def quick_run(cls, **overrides) -> BenchOptions:
        """The small run CI drives end to end (two tiny models, small images)."""
        base = dict(models=QUICK_MODELS, size=(256, 192), frames=2, curve_frames=2, eval_size=(64, 48),
                    linear_steps=(4, 32), binary_steps=(0, 6), march_densities=(2.0,),
                    pom_layers=(4,), pom_refine_steps=(0,),
                    max_triangles=500_000, reference_relief_samples=96, quick=True)
        base.update(overrides)
        return cls(**base)

    def as_json(self) -> dict:
        """The options as the results record them (tuples as lists)."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}
