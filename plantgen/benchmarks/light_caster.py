"""The light's relief caster: what the shadow pass costs against the plain one, and how far
its depth map lies from the float64 reference, for every shipped scene with shadows, all
in one run.

Run as ``python -m plantgen.benchmarks.light_caster [SCENE ...] [--size 1024x768]
[--frames 5] [--rays 20000] [--samples 2048] [--cpu] [--out light.md]`` (default: every shipped
scene whose effects list shadows). ``python -m plantgen.benchmarks.ablation`` prints the
same table for the shadowed models it measures.

Casters, each timed in the scene's own frame (its ground, leaves and 2048² map; the map
drawn every frame, ``ShadowSettings(cache=False)``) and interleaved frame by frame:

* ``plain``: RC's light pass, the frusta's analytic hit (no relief): the denominator;
* ``bisect``: the relief caster before (the eye's march at the map's footprint: an angle
  per sample, bisection to half a texel);
* ``secant``: the relief caster now, the default (``shaders/light_march.glsl``: (u, v)
  interpolated along the ray, one texel fetch a height, regula falsi to half a texel),
  and the same with each accuracy knob (``--shadow-march-density``,
  ``--shadow-march-precision``) moved, its error beside its time;
* ``secant, 4 samples, no refinement`` and ``secant, 2 samples, 1 step``: the same march
  cut to what no accurate caster can go below (``--linear-steps`` 4 or 2, the fewest
  steps as many, ``--binary-steps`` 0 or 1): the floor of a march on this GL, what its
  set-up and first samples cost, beside the error they leave;
* ``mesh m=1`` to ``m=6``: what an engine would do instead, ``--shadow-caster mesh``:
  the frusta tessellated and displaced by the relief (GS+R at level m,
  :func:`plantgen.geometry.meshes.mesh.tessellate`, built once and not timed) and rasterised
  into the same map by the ray caster's light pass (``raster.glsl``'s SHADOW_PASS): one
  more way of casting the relief, measured by the same clock and the same reference (a
  scene whose mesh would pass :data:`MESH_CASTER_TRIANGLES` is not drawn, and its row
  says so).

Error: the light's rays through ``--rays`` texels picked at random where any caster drew
(and two texels around) are cast by :func:`plantgen.geometry.rays.reference.intersect_frusta`
(float64, the relief marched with ``--samples`` samples and bisected to 1e-9 of the row)
into the same frusta (no ground, no leaves); per caster: the share of those texels covered
by one of the map and the reference only, and, where both hit, the share of texels whose
depth is more than half a texel (the receivers' bias) and two texels off, and the median
error in texels. The plain caster's row shows what casting no relief costs in accuracy.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .._resources import grammars_dir
from ..files import read_yaml
from ..geometry.meshes.mesh import triangle_count
from ..geometry.rays.reference import intersect_frusta
from ..gl.context import renderer_name
from ..gl.raycast import Raycaster
from ..settings import DEFAULT_SIZE, RaycastSettings, ShadowSettings
from ..table1.models import BenchModel, load_model
from .arguments import image_size, report

#: The float64 reference's relief samples a row (its map of the relief caster is the truth
#: the casters are measured against).
REFERENCE_SAMPLES = 2048

#: The most triangles a mesh caster's mesh may have here (a scene of many rows is not drawn
#: so: each row is 16·4^m triangles at level m; the dancing cacti's 2,151 rows at m = 5
#: would be 35 million).
MESH_CASTER_TRIANGLES = 3_000_000

#: The frame of ``--cpu`` timings: so small that a render's CPU time is its light pass's.
CPU_FRAME = (16, 12)

__all__ = ["CASTERS", "CPU_FRAME", "Caster", "shadowed_scenes", "time_casters", "measure_scene", "markdown", "main"]


@dataclass(frozen=True)
class Caster:
    """One light pass: its label, the ray caster's settings (relief on or off) and the map's."""

    label: str
    settings: RaycastSettings
    shadows: ShadowSettings

    @property
    def mesh_level(self) -> int | None:
        """The mesh caster's level, None for a ray-cast caster."""
        return self.shadows.mesh_level if self.shadows.caster == "mesh" else None


_MAP = ShadowSettings(cache=False)
_RELIEF = RaycastSettings(relief=True)
#: The casters compared: the plain one, the relief caster before and now, now with each
#: accuracy knob moved, now cut to its floor, and the mesh caster at five levels.
CASTERS = (
    Caster("plain", RaycastSettings(), _MAP),
    Caster("bisect", _RELIEF, replace(_MAP, march="bisect")),
    Caster("secant", _RELIEF, _MAP),
    Caster("secant, density 0.25", _RELIEF, replace(_MAP, march_density=0.25)),
    Caster("secant, density 1", _RELIEF, replace(_MAP, march_density=1.0)),
    Caster("secant, precision 0.25", _RELIEF, replace(_MAP, march_precision=0.25)),
    Caster("secant, precision 1", _RELIEF, replace(_MAP, march_precision=1.0)),
    Caster("secant, 4 samples, no refinement", RaycastSettings(relief=True, linear_steps=4, binary_steps=0), _MAP),
    Caster("secant, 2 samples, 1 step",
           RaycastSettings(relief=True, linear_steps=2, march_min_steps=2, binary_steps=1), _MAP),
    *(Caster(f"mesh m={m}", _RELIEF, replace(_MAP, caster="mesh", mesh_level=m)) for m in (1, 2, 3, 5, 6)),
)


def shadowed_scenes() -> list[str]:
    """The shipped scenes whose effects list shadows, by name; a forest (the ``lod``
    effect: millions of segments placed, beyond the float64 reference's reach) is
    ``python -m plantgen.benchmarks.forest``'s."""
    names = []
    for path in sorted(grammars_dir().glob("*.yaml")):
        doc = read_yaml(path)
        effects = (doc.get("effects") or ()) if isinstance(doc, dict) else ()
        if "shadows" in effects and "lod" not in effects:
            names.append(path.stem)
    return names


def _triangles(model: BenchModel, c: Caster) -> int | None:
    """A mesh caster's triangles in ``model`` (counted, not built); None for a ray caster."""
    return None if c.mesh_level is None else triangle_count(model.frusta, c.mesh_level, caps="tips")


def _fits(model: BenchModel, c: Caster) -> bool:
    """Whether ``c`` draws here: a ray caster, or a mesh caster whose mesh stays within
    :data:`MESH_CASTER_TRIANGLES`."""
    n = _triangles(model, c)
    return n is None or n <= MESH_CASTER_TRIANGLES


def _label(model: BenchModel, c: Caster) -> str:
    """The caster's label; a mesh caster's with its triangles (and whether it was drawn)."""
    n = _triangles(model, c)
    if n is None:
        return c.label
    return f"{c.label} ({n:,} triangles{'' if n <= MESH_CASTER_TRIANGLES else ': too many, not drawn'})"


def time_casters(caster: Raycaster, model: BenchModel, casters, frames: int, cpu: bool = False) -> dict:
    """Median shadow-pass ms of each caster in the scene's frame, timed in alternation after
    one warm-up each (which builds a mesh caster's mesh): the pass's wall ms, or with
    ``cpu`` the whole render's CPU ms of this process (:data:`CPU_FRAME`). A caster whose
    mesh is over the budget is not drawn (NaN)."""
    skipped = [c for c in casters if not _fits(model, c)]
    casters = [c for c in casters if _fits(model, c)]

    def render(c: Caster):
        t0 = time.process_time()
        result = caster.render(model.frusta, model.camera, c.settings, model.names, model.light_dir,
                               model.ground, shadows=c.shadows, leaves=model.leaves)
        return (time.process_time() - t0) * 1e3 if cpu else result.stats.shadow_ms
    for c in casters:
        render(c)
    samples: dict = {c.label: [] for c in casters}
    for _ in range(frames):
        for c in casters:
            samples[c.label].append(render(c))
    return {**{k: statistics.median(v) for k, v in samples.items()}, **{c.label: float("nan") for c in skipped}}


def _maps(caster: Raycaster, model: BenchModel, casters) -> tuple[dict, object]:
    """Each caster's light depth map of the frusta alone (no ground, no leaves), and the
    light's window (relative to the eye; the frusta's box)."""
    maps = {}
    for c in casters:
        if _fits(model, c):
            caster.render(model.frusta, model.camera, c.settings, model.names, model.light_dir, shadows=c.shadows)
            maps[c.label] = caster.shadow_depths().astype(np.float64)
    return maps, caster.last_light_window


def _reference(model: BenchModel, maps: dict, window, rays: int, samples: int):
    """(texel rows, columns, reference depths in [0, 1], 1 for a miss) of ``rays`` texels
    picked where any map drew, or two texels around, cast in float64."""
    res = len(next(iter(maps.values())))
    drawn = np.zeros((res, res), bool)
    for depths in maps.values():
        drawn |= depths < 1.0
    near = drawn.copy()
    for axis in (0, 1):
        for shift in (-2, -1, 1, 2):
            near |= np.roll(drawn, shift, axis=axis)
    candidates = np.flatnonzero(near)
    pick = np.random.default_rng(0).choice(candidates, size=min(rays, len(candidates)), replace=False)
    rows, cols = np.divmod(pick, res)
    x, y = 2 * (cols + 0.5) / res - 1, 2 * (rows + 0.5) / res - 1
    origins = (np.asarray(model.camera.eye, np.float64) + window.origin + window.depth[0] * window.forward
               + x[:, None] * window.half[0] * window.right + y[:, None] * window.half[1] * window.up)
    hits = intersect_frusta(model.frusta, origins, np.broadcast_to(window.forward, origins.shape), relief=True,
                            relief_samples=samples)
    span = window.depth[1] - window.depth[0]
    return rows, cols, np.where(hits.hit, hits.t / span, 1.0)


def _errors(depths: np.ndarray, reference, window) -> dict:
    """The map's errors at the reference's texels (see the module's docstring)."""
    rows, cols, ref = reference
    got = depths[rows, cols]
    both = (got < 1.0) & (ref < 1.0)
    texels = np.abs(got - ref)[both] * (window.depth[1] - window.depth[0]) / window.texel_size(len(depths))
    return {"coverage": float(np.mean((got < 1.0) != (ref < 1.0))),
            "half_texel": float(np.mean(texels > 0.5)) if texels.size else 0.0,
            "two_texels": float(np.mean(texels > 2.0)) if texels.size else 0.0,
            "median_texels": float(np.median(texels)) if texels.size else 0.0}


def measure_scene(name: str, size, frames: int, rays: int, samples: int, caster: Raycaster,
                  casters=CASTERS, cpu: bool = False) -> list[dict]:
    """One row per caster: shadow-pass ms (with ``cpu``: CPU ms, :data:`CPU_FRAME`), its
    ratio to the plain pass's and the errors."""
    model = load_model(name, CPU_FRAME if cpu else size)
    ms = time_casters(caster, model, casters, frames, cpu)
    maps, window = _maps(caster, model, casters)
    reference = _reference(model, maps, window, rays, samples)
    plain, before = ms[casters[0].label], ms.get("bisect")
    missing = dict.fromkeys(("coverage", "half_texel", "two_texels", "median_texels"), float("nan"))
    return [{"scene": model.name, "caster": _label(model, c),
             "shadow_ms": ms[c.label], "over_plain": ms[c.label] / plain,
             "over_bisect": ms[c.label] / before if before else float("nan"),
             **(_errors(maps[c.label], reference, window) if c.label in maps else missing)} for c in casters]


def markdown(rows: list[dict], size, frames: int, rays: int, samples: int, cpu: bool = False) -> str:
    timing = (f"{CPU_FRAME[0]}x{CPU_FRAME[1]} frame (the render is its light pass), {ShadowSettings().resolution}² "
              f"map drawn every frame, CPU ms of the render (LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', '')})"
              if cpu else f"{size[0]}x{size[1]} frame, {ShadowSettings().resolution}² map drawn every frame, "
              "shadow-pass ms")
    lines = [f"# The light's relief caster ({renderer_name()})", "",
             f"{timing} median of {frames} frames timed in alternation. Error against the float64 reference at "
             f"{rays:,} texels ({samples} samples a row, bisected): coverage = texels one of map and reference covers; "
             "> ½ and > 2 texels: depth off by more (where both hit); median in texels.", "",
             "| scene | caster | shadow ms | ÷ plain | ÷ bisect | coverage | > ½ texel | > 2 texels | median |",
             "|---|---|---|---|---|---|---|---|---|"]
    def cell(value: float, form: str) -> str:
        return "—" if np.isnan(value) else form.format(value)

    lines += [f"| {r['scene']} | {r['caster']} | {cell(r['shadow_ms'], '{:.1f}')} | "
              f"{cell(r['over_plain'], '{:.2f}x')} | {cell(r['over_bisect'], '{:.2f}x')} | "
              f"{cell(r['coverage'] * 100, '{:.3f} %')} | {cell(r['half_texel'] * 100, '{:.3f} %')} | "
              f"{cell(r['two_texels'] * 100, '{:.3f} %')} | {cell(r['median_texels'], '{:.3f}')} |" for r in rows]
    return "\n".join(lines) + "\n\n" + summary(rows) + "\n"


def summary(rows: list[dict]) -> str:
    """The 'relief shadow pass ÷ plain shadow pass' line, before and after, per scene."""
    by_scene: dict = {}
    for r in rows:
        by_scene.setdefault(r["scene"], {})[r["caster"]] = r
    parts = [f"{scene} {c['bisect']['over_plain']:.2f}x -> {c['secant']['over_plain']:.2f}x "
             f"({c['bisect']['shadow_ms']:.0f} -> {c['secant']['shadow_ms']:.0f} vs {c['plain']['shadow_ms']:.0f} ms)"
             for scene, c in by_scene.items() if {"plain", "bisect", "secant"} <= set(c)]
    return "Relief shadow pass ÷ plain shadow pass, before (bisect) -> after (secant): " + ", ".join(parts)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plantgen.benchmarks.light_caster",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="*", help="scene names (default: every shipped scene with shadows)")
    parser.add_argument("--size", type=image_size, default=DEFAULT_SIZE)
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--rays", type=int, default=20000, help="texels checked against the float64 reference")
    parser.add_argument("--samples", type=int, default=REFERENCE_SAMPLES, help="the reference's relief samples a row")
    parser.add_argument("--cpu", action="store_true",
                        help="time by this process's CPU time, llvmpipe on one thread (LP_NUM_THREADS=1) and a "
                             f"{CPU_FRAME[0]}x{CPU_FRAME[1]} frame, so that the render is its light pass: steady where "
                             "the cores are shared (llvmpipe only: a GPU's time is not this process's)")
    parser.add_argument("--out", type=Path, help="write the Markdown table here")
    args = parser.parse_args(argv)
    if args.cpu:
        os.environ["LP_NUM_THREADS"] = "1"        # read by Mesa when the context is made, below
    caster, rows = Raycaster(), []
    for name in args.scenes or shadowed_scenes():
        print(f"{name} ...", file=sys.stderr, flush=True)
        rows += measure_scene(name, args.size, args.frames, args.rays, args.samples, caster, cpu=args.cpu)
    return report(markdown(rows, args.size, args.frames, args.rays, args.samples, args.cpu), args.out)


if __name__ == "__main__":
    raise SystemExit(main())
