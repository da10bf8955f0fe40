"""What leaves cost a frame: the leafy models drawn with and without their leaves.

Run as ``python -m plantgen.benchmarks.leaf_cost [--size 1024x768] [--frames 7] [MODEL ...]``
(default: the shipped grammars with leaves). For each model, in one interleaved run after
a warm-up (so the ratios compare like with like on a noisy machine), the median frame
time of RC (ray-cast frusta) and of GS (the frusta tessellated at ``--level``), each
bare, with the leaves, and with the leaves and a shadow map (the leaves drawn into the
light's map too). The leaf pass is one indexed draw of the leaves' triangles in either
renderer; the table gives its share. Every line names the GL renderer.
"""

from __future__ import annotations

import argparse
import statistics
import sys

from ..geometry.meshes.mesh import tessellate
from ..geometry.skeletons.skin import skin_skeleton
from ..gl.context import renderer_name
from ..gl.raster import RasterRenderer
from ..gl.raycast import Raycaster
from ..pipeline import grow_file, model_leaves, stage_model
from ..settings import DEFAULT_SIZE, RaycastSettings, ShadowSettings
from .arguments import image_size
from .gallery import LEAFY_MODELS

#: (label, leaves drawn, shadow map) of each timed variant.
VARIANTS = (("bare", False, False), ("leaves", True, False), ("leaves+shadows", True, True))


def measure(name: str, width: int, height: int, frames: int, level: int) -> dict:
    """Median frame ms of RC and GS for each of :data:`VARIANTS`, timed frame by frame in
    turn after one warm-up of each."""
    grown = grow_file(name)
    frusta = skin_skeleton(grown.skeleton)
    leaves = model_leaves(grown)
    stage = stage_model(grown, frusta, width, height)
    caster = Raycaster()
    raster = RasterRenderer(caster.ctx)
    mesh = tessellate(frusta, level)
    names = frusta.material_names
    shadow = ShadowSettings()

    def draw(method: str, with_leaves: bool, shadowed: bool):
        kw = {"light_dir": stage.light_dir, "shadows": shadow if shadowed else None,
              "leaves": leaves if with_leaves else None}
        if method == "RC":
            return caster.render(frusta, stage.camera, RaycastSettings(), names, **kw)
        return raster.render(mesh, frusta, stage.camera, material_names=names, **kw)

    jobs = [(m, label, lv, sh) for m in ("RC", "GS") for label, lv, sh in VARIANTS]
    times: dict = {(m, label): [] for m, label, _, _ in jobs}
    for m, _, lv, sh in jobs:
        draw(m, lv, sh)                                  # warm-up: compile, upload
    for _ in range(frames):
        for m, label, lv, sh in jobs:
            times[(m, label)].append(draw(m, lv, sh).frame_ms)
    row = {"model": name, "segments": len(grown.skeleton),
           "leaf_triangles": 0 if leaves is None else len(leaves.triangles), "gs_triangles": len(mesh.faces)}
    for (m, label), values in times.items():
        row[f"{m} {label}"] = statistics.median(values)
    caster.release()
    raster.release()
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plantgen.benchmarks.leaf_cost",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="*", metavar="MODEL", help="grammar names or paths (default: the leafy ones)")
    parser.add_argument("--size", type=image_size, default=DEFAULT_SIZE,
                        help="frame size WxH (default: the renders', {}x{})".format(*DEFAULT_SIZE))
    parser.add_argument("--frames", type=int, default=7, help="timed frames of each variant (default 7)")
    parser.add_argument("--level", type=int, default=1, help="GS subdivision level m (default 1)")
    args = parser.parse_args(argv)
    width, height = args.size
    print(f"# leaves: median of {args.frames} frames, {width}x{height}, GL renderer: {renderer_name()}")
    print("| model | segments | leaf tris | method | bare ms | + leaves ms | + leaves + shadows ms | leaves ÷ bare |")
    print("|---|---|---|---|---|---|---|---|")
    for name in args.models or LEAFY_MODELS:
        row = measure(name, width, height, args.frames, args.level)
        for m in ("RC", "GS"):
            bare, leafy, shadowed = (row[f"{m} {label}"] for label, _, _ in VARIANTS)
            method = m if m == "RC" else f"GS m={args.level} ({row['gs_triangles']:,} tris)"
            print(f"| {row['model']} | {row['segments']:,} | {row['leaf_triangles']:,} | {method} | {bare:.1f} | "
                  f"{leafy:.1f} | {shadowed:.1f} | {leafy / bare:.2f} |")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
