"""What the new defaults cost a single plant's frame (issue 43): the tone curve, translucent
leaves, the ground disc under a single plant and coverage anti-aliasing, on by default,
against the old defaults (``--no-tone --no-translucency --ground none --aa none``, one ray a
pixel as before them).

Run as ``python -m plantgen.benchmarks.default_cost [--sizes 512x384,1024x768] [--frames 5]
[--out FILE.md] [--json FILE.json] [MODEL ...]`` (default: every shipped grammar; scenes
are left out). Each model is drawn by the ray caster from the automatic camera, as
``plantgen render MODEL`` draws it with (a) the old defaults, (b) the new defaults (no
option given) and (c) each new effect alone on top of the old defaults.

Times: per model and size, the variants are drawn in interleaved rounds after one warm-up
round each (:func:`~plantgen.benchmarks.anti_aliasing.interleaved_times`); the table quotes
medians: *frame*, the draw to glFinish (wall-clock); *CPU*, the process's CPU time over the
whole :meth:`~plantgen.gl.raycast.Raycaster.render` call, every thread's (llvmpipe draws in
this process's threads, so on shared cores it is the steadier measure of the work); the
JSON has the render call's wall time too. Ratios are of medians to the old defaults'.
Issue 43's goal: the new defaults' frame within 1.5 times the old defaults'.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

from .._resources import grammars_dir
from ..files import read_yaml
from ..gl.context import renderer_name
from ..gl.raycast import Raycaster
from ..pipeline import prepare_model
from ..scene import is_scene
from ..settings import RenderSettings
from .anti_aliasing import interleaved_times, staged_view
from .arguments import image_size, report

SIZES = ((512, 384), (1024, 768))
#: The goal: the new defaults' frame at most this many times the old defaults'.
GOAL = 1.5
#: ``plantgen render``'s options (settings names) giving the defaults before issue 43.
OLD = {"tone": False, "translucency": False, "ground": "none", "aa": "none"}
#: The options each new default takes when on (what no option gives).
NEW = {"tone": True, "translucency": True, "ground": "auto", "aa": "coverage"}
#: The variants timed: (name, options). ``new defaults`` gives no option at all.
VARIANTS = (("old defaults", OLD), ("new defaults", {}),
            *((f"{key} only", {**OLD, key: value}) for key, value in NEW.items()))
#: How the table names each variant's options.
LABELS = {"old defaults": "`--no-tone --no-translucency --ground none --aa none`", "new defaults": "(none)",
          "tone only": "old + `--tone`", "translucency only": "old + `--translucency`",
          "ground only": "old + `--ground auto`", "aa only": "old + `--aa coverage`"}


def shipped_plants() -> list[str]:
    """The shipped grammars' names (single plants: not scenes), sorted."""
    return sorted(p.stem for p in grammars_dir().glob("*.yaml") if not is_scene(read_yaml(p)))


def measure(model_name: str, width: int, height: int, frames: int) -> list[dict]:
    """One row per variant of :data:`VARIANTS`: median frame and wall ms over ``frames``
    interleaved rounds (after a warm-up round), the render call's CPU ms (every thread's),
    and their ratios to the old defaults'."""
    model = prepare_model(model_name)
    frusta = model.frusta_at(0.0)
    views = {name: staged_view(model, frusta, width, height, RenderSettings.from_options(size=(width, height),
                                                                                        **options))
             for name, options in VARIANTS}
    caster = Raycaster()
    times, _ = interleaved_times(caster, frusta, views, frames)
    base = [statistics.median(t) for t in times["old defaults"]]
    rows = []
    for name, _ in VARIANTS:
        frame, wall, cpu = (statistics.median(t) for t in times[name])
        rows.append({"model": model_name, "size": f"{width}x{height}", "variant": name, "frame_ms": frame,
                     "wall_ms": wall, "cpu_ms": cpu, "frame_ratio": frame / base[0], "wall_ratio": wall / base[1],
                     "cpu_ratio": cpu / base[2]})
    return rows


def over_goal(rows: list[dict], measure: str = "frame_ratio") -> list[dict]:
    """The new-default rows whose ``measure`` (``frame_ratio`` or ``cpu_ratio``) passes :data:`GOAL`."""
    return [r for r in rows if r["variant"] == "new defaults" and r[measure] > GOAL]


def verdict(rows: list[dict], measure: str, what: str) -> str:
    """One line: whether every model's new defaults keep ``measure`` within :data:`GOAL`."""
    over = over_goal(rows, measure)
    if not over:
        return f"{what}: every model's new defaults within {GOAL}x the old defaults'"
    return f"{what}: over {GOAL}x the old defaults': " + ", ".join(
        f"{r['model']} {r['size']} ({r[measure]:.2f}x)" for r in over)


def table(rows: list[dict]) -> str:
    """The Markdown table of :func:`measure`'s rows: one line per model and size, the old
    defaults' frame and CPU ms, then each other variant's frame ratio (CPU ratio)."""
    names = [name for name, _ in VARIANTS[1:]]
    lines = ["| plant | size | old defaults: frame (CPU) | " + " | ".join(names) + " |",
             "| --- | --- | --- | " + " | ".join("---" for _ in names) + " |"]
    for k in range(0, len(rows), len(VARIANTS)):
        group = {r["variant"]: r for r in rows[k:k + len(VARIANTS)]}
        old = group["old defaults"]
        cells = []
        for name in names:
            r = group[name]
            mark = "**" if name == "new defaults" and r["frame_ratio"] > GOAL else ""
            cells.append(f"{mark}{r['frame_ratio']:.2f}{mark} ({r['cpu_ratio']:.2f})")
        lines.append(f"| {old['model']} | {old['size']} | {old['frame_ms']:.0f} ms ({old['cpu_ms']:.0f} ms) | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines)


def document(rows: list[dict], frames: int, renderer: str) -> str:
    """The Markdown page: how it was measured, the table, the goal's verdict by the frame
    and by the CPU time (on a CPU rasteriser the work; on a GPU only the driver's share)."""
    legend = "; ".join(f"*{name}*: {LABELS[name]}" for name, _ in VARIANTS)
    return (f"GL renderer: {renderer}; median of {frames} interleaved rounds after a warm-up; each cell the "
            "frame's ratio to the old defaults' (in brackets: the ratio of the render call's CPU time, every "
            "thread's); in bold a frame over the goal\n\n"
            f"{legend}\n\n{table(rows)}\n\n{verdict(rows, 'frame_ratio', 'frame')}\n\n"
            f"{verdict(rows, 'cpu_ratio', 'CPU time')}\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plantgen.benchmarks.default_cost",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="*", help="shipped names or paths (default: every shipped grammar)")
    parser.add_argument("--sizes", default=",".join(f"{w}x{h}" for w, h in SIZES),
                        help="comma-separated WIDTHxHEIGHT sizes")
    parser.add_argument("--frames", type=int, default=5, help="timed rounds (after one warm-up round)")
    parser.add_argument("--out", type=Path, help="also write the page (Markdown) here")
    parser.add_argument("--json", type=Path, help="also write the rows (JSON) here")
    args = parser.parse_args(argv)
    sizes = [image_size(s) for s in args.sizes.split(",") if s]
    models = args.models or shipped_plants()
    rows = [row for size in sizes for name in models for row in measure(name, *size, args.frames)]
    renderer = renderer_name()
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"renderer": renderer, "frames": args.frames, "goal": GOAL, "rows": rows},
                                        indent=1) + "\n", encoding="utf-8")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
    return report(document(rows, args.frames, renderer), args.out)


if __name__ == "__main__":
    sys.exit(main())
