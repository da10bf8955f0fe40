"""Relief levers on and off (issue 12): what each one buys per model, and what it costs in
error, all measured in one run.

Each lever is a pair of ray caster settings that differ only in that lever; the two are
timed interleaved (median of ``--frames``) at the bench's size, and the eye's levers are
scored against the float64 reference in the bench's evaluation window (err = 1 - SSIM of
the depth-rebuilt shading + silhouette mismatch, :mod:`plantgen.table1.quality`). The
shadow lever is timed in the scene's own frame (ground, shadow map drawn every frame) and
scored on the light's depth map against the float64 reference (share of texels more than
half a texel off: the receivers' bias); a scene with shadows also gets the light casters'
table of :mod:`plantgen.benchmarks.light_caster` (the relief shadow pass ÷ the plain one,
before and after, and each caster's error against the float64 reference).

Levers:

* ``march``: the adaptive march (samples per relief texel the ray crosses, at least a pixel
  footprint each; bisection to 1/50 pixel) against the paper's fixed 32 + 6 steps.
* ``gather``: one textureGather per bilinear height against four texelFetch (same heights).
* ``v``: v interpolated between entry and exit (the paper's) against v of (7) per sample.
* ``skipping bound``: one linear sample per ray against the default march: the most that
  empty-space skipping (relaxed cone stepping, maximum mipmaps) could save here, since
  it can at best remove linear samples (its error column is the 1-sample march's, wrong
  by design).
* ``light march``: the light's pass marched at the map's texel footprint (0.5 samples per
  texel, half-texel bracket) against the eye's settings (2 per texel, 1/50 texel), both
  with the light's own (secant) march.

Writes Markdown (``--out``) and prints it.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
from pathlib import Path

import numpy as np

from ..geometry.rays.reference import render_reference
from ..gl.context import renderer_name
from ..gl.raycast import Raycaster
from ..settings import DEFAULT_SIZE, RaycastSettings, ShadowSettings
from ..table1.eval_window import eval_camera
from ..table1.models import load_model
from ..table1.paper import TABLE1_MODELS
from ..table1.quality import image_error
from .arguments import image_size, report
from .light_caster import CASTERS, REFERENCE_SAMPLES, Caster, measure_scene
from .light_caster import markdown as light_markdown

__all__ = ["EYE_LEVERS", "LIGHT_EYE", "measure_model", "main"]

ON = RaycastSettings(relief=True)
#: (lever, settings with it on, settings with it off) of the eye's pass.
EYE_LEVERS = (
    ("march", ON, RaycastSettings(relief=True, march="fixed", linear_steps=32, binary_steps=6)),
    ("gather", ON, dataclasses.replace(ON, height_fetch="texel")),
    ("v interpolated", ON, dataclasses.replace(ON, v_exact=True)),
    # not a lever but its bound: one linear sample per ray (then the same bisection) is
    # what an oracle that skipped all empty space (cone stepping, maximum mipmaps) would
    # leave of the linear march; its speed-up over the default is the most they can win
    ("skipping bound", dataclasses.replace(ON, march="fixed", linear_steps=1), ON),
)
#: The light's pass at the eye's density and precision: the light march lever's "off".
LIGHT_EYE = Caster("secant, the eye's density and precision", ON,
                   ShadowSettings(cache=False, march_density=ON.march_density, march_precision=ON.march_precision))


def _interleaved(render_a, render_b, frames: int) -> tuple[float, float]:
    """Median ms of two renders timed in alternation (one warm-up each)."""
    render_a(), render_b()
    a, b = [], []
    for _ in range(frames):
        a.append(render_a().frame_ms)
        b.append(render_b().frame_ms)
    return statistics.median(a), statistics.median(b)


def _eye_rows(caster, model, window, reference, frames: int) -> list[dict]:
    rows = []
    for lever, on, off in EYE_LEVERS:
        def render(settings, camera=model.camera):
            return caster.render(model.frusta, camera, settings, model.names, model.light_dir)
        on_ms, off_ms = _interleaved(lambda s=on: render(s), lambda s=off: render(s), frames)
        errors = [image_error(render(s, window).distance, reference, window, model.light_dir).total
                  for s in (on, off)]
        rows.append({"lever": lever, "on_ms": on_ms, "off_ms": off_ms, "speedup": off_ms / on_ms,
                     "on_error": errors[0], "off_error": errors[1], "unit": "err"})
    return rows


def _light_row(casters: list[dict]) -> dict:
    """The light's march lever from the light casters' rows of one scene (shadow ms; the
    share of texels more than half a texel off the float64 reference)."""
    by = {r["caster"]: r for r in casters}
    on, off = by["secant"], by[LIGHT_EYE.label]
    return {"lever": "light march", "on_ms": on["shadow_ms"], "off_ms": off["shadow_ms"],
            "speedup": off["shadow_ms"] / on["shadow_ms"], "on_error": on["half_texel"],
            "off_error": off["half_texel"], "unit": "texels off"}


def measure_model(name: str, size, eval_size, frames: int, caster: Raycaster, *, light_only: bool = False,
                  rays: int = 20000) -> tuple[list[dict], list[dict]]:
    """Every lever's rows for one model (the light's lever only where the scene has
    shadows), and its light casters' rows (:func:`plantgen.benchmarks.light_caster.
    measure_scene`; none without shadows). ``light_only``: the light's rows alone."""
    model = load_model(name, size)
    if not model.relief:
        return [], []
    rows, lights = [], []
    if not light_only:
        first = caster.render(model.frusta, model.camera, RaycastSettings(), model.names)
        window = eval_camera(model.camera, np.isfinite(first.distance), eval_size)
        ref = render_reference(model.frusta, window, relief=True, relief_samples=384)
        reference = np.where(ref.hit, ref.t, np.inf)
        rows = _eye_rows(caster, model, window, reference, frames)
    if model.shadows:
        lights = measure_scene(name, size, frames, rays, REFERENCE_SAMPLES, caster, casters=(*CASTERS, LIGHT_EYE))
        rows.append(_light_row(lights))
    return [{"model": model.name, **r} for r in rows], lights


def markdown(rows: list[dict], size, frames: int, lights: list[dict] = ()) -> str:
    lines = [f"# Relief levers on and off ({renderer_name()})", "",
             f"{size[0]}x{size[1]}, median of {frames} frames timed in alternation. speed-up = off ms ÷ "
             "on ms. err: (1 - SSIM) + silhouette mismatch against the float64 reference (the bench's "
             "criterion); light march: ms of the shadow pass (its map drawn every frame), error = share of "
             "the light's texels more than half a texel from the float64 reference's depth.", "",
             "| model | lever | on ms | off ms | speed-up | on error | off error |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['model']} | {r['lever']} | {r['on_ms']:.1f} | {r['off_ms']:.1f} | "
              f"{r['speedup']:.2f}x | {r['on_error']:.4f} | {r['off_error']:.4f} |" for r in rows]
    by_lever: dict[str, list] = {}
    for r in rows:
        by_lever.setdefault(r["lever"], []).append(r["speedup"])
    lines += ["", "Geometric mean speed-up per lever: " + ", ".join(
        f"{k} {float(np.exp(np.mean(np.log(v)))):.2f}x ({len(v)} models)" for k, v in by_lever.items())]
    if lights:
        lines += ["", light_markdown(list(lights), size, frames, 20000, REFERENCE_SAMPLES).rstrip()]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plantgen.benchmarks.ablation",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="*", help=f"grammar/scene names (default: {', '.join(TABLE1_MODELS)})")
    parser.add_argument("--size", type=image_size, default=DEFAULT_SIZE)
    parser.add_argument("--eval-size", type=image_size, default="128x96")
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--out", type=Path, help="write the Markdown table here")
    parser.add_argument("--light-only", action="store_true",
                        help="only the light's pass (the shadowed models' light march lever and casters)")
    args = parser.parse_args(argv)
    caster = Raycaster()
    rows, lights = [], []
    for name in args.models or TABLE1_MODELS:
        print(f"{name} ...", file=sys.stderr, flush=True)
        model_rows, model_lights = measure_model(name, args.size, args.eval_size, args.frames, caster,
                                                 light_only=args.light_only)
        rows += model_rows
        lights += model_lights
    return report(markdown(rows, args.size, args.frames, lights), args.out)


if __name__ == "__main__":
    raise SystemExit(main())
