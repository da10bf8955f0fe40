"""What coverage anti-aliasing (``--aa coverage``, the default; ``--aa edges`` with the edge
pass) costs and buys, against one ray a pixel (``--aa none``, the default before it) and
2 x 2 supersampling (``--ssaa 2``).

Run as ``python -m plantgen.benchmarks.anti_aliasing [--sizes 512x384,1024x768] [--frames 5]
[--out FILE.md] [MODEL ...]`` (default models: saguaro, broadleaf, pine). Each model is
drawn as ``plantgen render`` draws it by default (the automatic camera, the ground under a
single plant, the looks on by default: tone and translucency), by the ray caster.

Times: per model and size, the variants are drawn in interleaved rounds after one warm-up
round each (so a load that comes and goes on shared cores touches them alike), and the
table quotes medians: *frame*, the draw to glFinish; *wall*, the whole
:meth:`~plantgen.gl.raycast.Raycaster.render` call (packing, upload, draw, the edge pass
or the averaging, the read back). Ratios are of medians to ``--aa none``'s.

Quality: each image against a 4 x 4 supersampled reference of the same frame (16 rays a
pixel, averaged in linear light): the mean absolute difference in levels of 255 over the
image, and with the ``bench`` extra (``flip-evaluator``) NVIDIA's FLIP (mean, 0 is
identical).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from ..gl.context import renderer_name
from ..gl.raycast import Raycaster
from ..pipeline import frame_arguments, ground_asked, prepare_model, stage_model
from ..settings import RenderSettings
from .arguments import image_size

MODELS = ("saguaro", "broadleaf", "pine")
SIZES = ((512, 384), (1024, 768))
#: The variants timed and judged: (name, keyword arguments of Raycaster.render).
VARIANTS = (("none", {"aa": "none"}), ("coverage", {"aa": "coverage"}), ("edges", {"aa": "edges"}),
            ("ssaa 2", {"aa": "none", "ssaa": 2}))
REFERENCE = {"aa": "none", "ssaa": 4}


def flip_error(image: np.ndarray, reference: np.ndarray) -> float | None:
    """Mean FLIP of two (h, w, 3) uint8 sRGB images, None without ``flip-evaluator``."""
    try:
        import flip_evaluator
    except ImportError:
        return None
    _, mean, _ = flip_evaluator.evaluate(reference[..., :3].astype(np.float32) / 255.0,
                                         image[..., :3].astype(np.float32) / 255.0, "LDR")
    return float(mean)


def staged_view(model, frusta, width: int, height: int, request: RenderSettings) -> dict:
    """The keyword arguments of the ray caster's frame of ``model`` (a prepared model, its
    ``frusta``) as ``plantgen render`` draws it with ``request``'s options: the effects,
    the ground and the anti-aliasing they ask for."""
    effects = request.effects.resolve(model.grown.scene.effects if model.grown.scene is not None else ())
    staging = stage_model(model.grown, frusta, width, height, ground=ground_asked(request.image))
    settings, shadows = request.frame(effects)
    return {**frame_arguments(frusta, staging, shadows, request.image), "settings": settings}


def frame_view(model_name: str, width: int, height: int, **options):
    """(frusta, the keyword arguments of the ray caster's default frame) of ``model_name``;
    ``options``: ``plantgen render``'s, by their settings names (``tone=False``, ``aa="none"``)."""
    request = RenderSettings.from_options(size=(width, height), **options)
    model = prepare_model(model_name, effects=request.effects)
    frusta = model.frusta_at(0.0)
    return frusta, staged_view(model, frusta, width, height, request)


def interleaved_times(caster: Raycaster, frusta, views: dict, frames: int) -> tuple[dict, dict]:
    """Draw each of ``views`` (name: the keyword arguments of ``caster.render``) in
    ``frames`` interleaved rounds after one warm-up round (so a load that comes and goes on
    shared cores touches them alike). Returns ({name: (frame ms list, wall ms list, CPU ms
    list)}, {name: the last round's colour image}). The CPU time is the process's over the
    render call, every thread's (llvmpipe rasterises and shades in this process's threads,
    so it is the frame's work, which waiting for a shared core does not lengthen)."""
    times: dict = {name: ([], [], []) for name in views}
    images = {}
    for round_ in range(frames + 1):
        for name, kw in views.items():
            t0, c0 = time.perf_counter(), time.process_time()
            result = caster.render(frusta, **kw)
            wall, cpu = (time.perf_counter() - t0) * 1e3, (time.process_time() - c0) * 1e3
            images[name] = result.color
            if round_:           # the first round warms the programs and the driver up
                for k, value in enumerate((result.frame_ms, wall, cpu)):
                    times[name][k].append(value)
    return times, images


def measure(model_name: str, width: int, height: int, frames: int) -> list[dict]:
    """One row per variant: median frame and wall ms over ``frames`` interleaved rounds
    (after a warm-up round), their ratios to ``none``'s, and the error against the 4 x 4
    supersampled reference."""
    frusta, view = frame_view(model_name, width, height)
    caster = Raycaster()
    reference = caster.render(frusta, **{**view, **REFERENCE}).color
    times, images = interleaved_times(caster, frusta, {name: {**view, **kw} for name, kw in VARIANTS}, frames)
    base = [statistics.median(t) for t in times["none"][:2]]
    rows = []
    for name, _ in VARIANTS:
        frame, wall = (statistics.median(t) for t in times[name][:2])
        rows.append({"model": model_name, "size": f"{width}x{height}", "variant": name, "frame_ms": frame,
                     "wall_ms": wall, "frame_ratio": frame / base[0], "wall_ratio": wall / base[1],
                     "mae": float(np.abs(images[name].astype(float) - reference.astype(float)).mean()),
                     "flip": flip_error(images[name], reference)})
    return rows


def table(rows: list[dict]) -> str:
    """The Markdown table of :func:`measure`'s rows."""
    lines = ["| plant | size | anti-aliasing | frame | wall | frame ratio | wall ratio | error | FLIP |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        flip = "" if r["flip"] is None else f"{r['flip']:.3f}"
        aa = "`--ssaa 2`" if r["variant"] == "ssaa 2" else f"`--aa {r['variant']}`"
        lines.append(f"| {r['model']} | {r['size']} | {aa} | {r['frame_ms']:.0f} ms | {r['wall_ms']:.0f} ms | "
                     f"{r['frame_ratio']:.2f} | {r['wall_ratio']:.2f} | {r['mae']:.2f} | {flip} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plantgen.benchmarks.anti_aliasing",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="*", default=list(MODELS), help="shipped names or paths (default: "
                        + ", ".join(MODELS) + ")")
    parser.add_argument("--sizes", default=",".join(f"{w}x{h}" for w, h in SIZES),
                        help="comma-separated WIDTHxHEIGHT sizes")
    parser.add_argument("--frames", type=int, default=5, help="timed rounds (after one warm-up round)")
    parser.add_argument("--out", type=Path, help="also write the table (Markdown) here")
    args = parser.parse_args(argv)
    sizes = [image_size(s) for s in args.sizes.split(",") if s]
    rows = [row for size in sizes for name in args.models for row in measure(name, *size, args.frames)]
    text = (f"GL renderer: {renderer_name()}; median of {args.frames} interleaved rounds after a warm-up; "
            "error: mean absolute difference to `--ssaa 4` in levels of 255\n\n" + table(rows) + "\n")
    print(text)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
