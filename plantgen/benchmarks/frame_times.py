"""Frame times of the GLSL ray caster, RC and RC+R, in the setting of Table 1.

Run as ``python -m plantgen.benchmarks.frame_times [--size 1024x768] [--frames 7] [--ssaa N] [MODEL ...]``.
MODEL is a grammar or scene (a shipped name such as ``saguaro``, or a path) or a skeleton
``.npz``; default: every shipped grammar and scene. Each model is framed by the ``auto``
camera (spanning most of the viewport, as the paper measured) and rendered ``--frames``
times after one warm-up frame (shader compilation); the table quotes the median.

Columns: segments, bytes per segment sent to the GPU (one record each) and in total,
median RC and RC+R frame times in milliseconds, and the GL renderer. With ``--ssaa N``,
RC+R supersampled N x N too: the frame drawn at N times the size, and the CPU time
averaging it down (what anti-aliasing costs). On llvmpipe (a
CPU rasteriser) the absolute numbers say little about a GPU; the ratios still show where
time goes (relief marching, fill rate).
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

from ..geometry.rays.camera import auto_camera
from ..geometry.skeletons.skin import skin_skeleton
from ..gl.context import renderer_name
from ..gl.raycast import Raycaster
from ..gl.records import RECORD_BYTES, rc_buffer_bytes
from ..pipeline import load_skeleton
from ..settings import DEFAULT_SIZE, RaycastSettings
from ..table1.renderers import time_after_warm_up
from .arguments import image_size, shipped_model_paths


def _models(names):
    if names:
        return list(names)
    try:
        return [str(p) for p in shipped_model_paths()]
    except FileNotFoundError:
        return []


def measure(path, width: int, height: int, frames: int, linear_steps: int, binary_steps: int, ssaa: int = 1):
    """Median frame times (ms) of RC and RC+R (and RC+R with ``ssaa``: frame and averaging
    ms) for one model, and its record sizes."""
    skeleton = load_skeleton(path)
    frusta = skin_skeleton(skeleton)
    camera = auto_camera(frusta, width, height)
    caster = Raycaster()
    row = {"model": Path(path).stem, "segments": len(skeleton), "rows": len(frusta.base),
           "bytes_per_segment": RECORD_BYTES,
           "upload_kib": rc_buffer_bytes(len(frusta.base)) / 1024}
    names = frusta.material_names
    for label, settings in (("rc_ms", RaycastSettings()),
                            ("rcr_ms", RaycastSettings(relief=True, linear_steps=linear_steps,
                                                       binary_steps=binary_steps))):
        _, runs = time_after_warm_up(lambda s=settings: caster.render(frusta, camera, s, names), frames)
        row[label] = statistics.median(r.frame_ms for r in runs)
        if ssaa > 1 and label == "rcr_ms":
            _, runs = time_after_warm_up(lambda s=settings: caster.render(frusta, camera, s, names, ssaa=ssaa), frames)
            row["ssaa_ms"] = statistics.median(r.frame_ms for r in runs)
            row["resolve_ms"] = statistics.median(r.stats.resolve_ms for r in runs)
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plantgen.benchmarks.frame_times",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="*", help="grammar, scene or .npz (default: all shipped)")
    parser.add_argument("--size", type=image_size, default=DEFAULT_SIZE)
    parser.add_argument("--frames", type=int, default=7)
    parser.add_argument("--linear-steps", type=int, default=32)
    parser.add_argument("--binary-steps", type=int, default=6)
    parser.add_argument("--ssaa", type=int, default=1, help="also time RC+R with N x N supersampling")
    args = parser.parse_args(argv)
    width, height = args.size
    models = _models(args.models)
    if not models:
        print("no models: pass grammar/scene/.npz paths", file=sys.stderr)
        return 2
    print(f"GL renderer: {renderer_name()}; {width}x{height}; median of {args.frames} frames; "
          f"relief {args.linear_steps} linear + {args.binary_steps} binary steps")
    header = (f"{'model':<16}{'segments':>9}{'frusta':>8}{'B/frustum':>10}{'upload KiB':>11}"
              f"{'RC ms':>9}{'RC+R ms':>9}" + (f"{f'ssaa {args.ssaa} ms':>12}{'avg ms':>8}" if args.ssaa > 1 else ""))
    print(header)
    print("-" * len(header))
    for path in models:
        r = measure(path, width, height, args.frames, args.linear_steps, args.binary_steps, args.ssaa)
        print(f"{r['model']:<16}{r['segments']:>9,}{r['rows']:>8,}{r['bytes_per_segment']:>10}"
              f"{r['upload_kib']:>11.1f}{r['rc_ms']:>9.1f}{r['rcr_ms']:>9.1f}"
              + (f"{r['ssaa_ms']:>12.1f}{r['resolve_ms']:>8.1f}" if args.ssaa > 1 else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
