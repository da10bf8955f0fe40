"""What one normal map per material leaves: the relief's v-slope scales with each segment's
aspect (radius over texture period), one map is exact for one aspect.

Run as ``python -m plantgen.benchmarks.texture_aspects [--level 1] [--step 2] [MODEL ...]``
(default: the shipped models with relief). For each relief material of each model (its
mesh at ``--level``): the faces' aspects (5th, 50th, 95th percentile, area-weighted
median), and the angle between the baked normal and the exact one (the map baked at the
face's own aspect), area-weighted mean and the 95th percentile over faces, for one map
at the median (plantgen export's default) and for maps per bucket ``--step`` apart
(``plantgen export --aspect-step``), with the number of maps that takes. CPU only.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ..geometry.meshes.mesh import tessellate
from ..geometry.meshes.textures import aspect_error, mesh_aspects, weighted_median
from ..geometry.skeletons import relief
from ..geometry.skeletons.skin import skin_skeleton
from ..pipeline import grow_file

#: The shipped models with relief materials (Table 1's and the well).
MODELS = ("saguaro", "cactus", "aloe", "well", "pine", "elm", "abop_bush")


def measure(name: str, level: int, step: float) -> list[dict]:
    """One row per relief material of model ``name`` (see the module docstring)."""
    mesh = tessellate(skin_skeleton(grow_file(name).skeleton), level)
    rows = []
    merged: dict[str, list] = {}
    for index, (aspect, area, _) in mesh_aspects(mesh).items():
        merged.setdefault(mesh.material_names[index], []).append((aspect, area))
    for material, chunks in merged.items():
        shell = relief.default_shell(material)
        if shell <= 0:
            continue
        aspect, area = (np.concatenate(c) for c in zip(*chunks, strict=True))
        height = relief.height_map(material) / 255.0
        median = weighted_median(aspect, area)
        one = aspect_error(height, shell, median, aspect, area)
        bucket = np.rint(np.log(aspect / median) / np.log(step))
        total = 0.0
        for k in np.unique(bucket):
            sel = bucket == k
            total += aspect_error(height, shell, weighted_median(aspect[sel], area[sel]), aspect[sel],
                                  area[sel])["mean"] * area[sel].sum()
        rows.append({"model": name, "material": material, "faces": len(aspect), "median": median,
                     "p5": float(np.quantile(aspect, 0.05)), "p95": float(np.quantile(aspect, 0.95)),
                     "one_mean": one["mean"], "one_p95": one["p95"], "maps": len(np.unique(bucket)),
                     "bucket_mean": total / area.sum()})
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plantgen.benchmarks.texture_aspects",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="*", metavar="MODEL", help="grammar or scene names (default: %(default)s)")
    parser.add_argument("--level", type=int, default=1, help="subdivision level m of the mesh (default 1)")
    parser.add_argument("--step", type=float, default=2.0, help="bucket ratio of --aspect-step (default 2)")
    args = parser.parse_args(argv)
    if args.step <= 1:
        print(f"texture_aspects: --step must be over 1, got {args.step:g}", file=sys.stderr)
        return 2
    print(f"# normal map error by aspect (degrees), mesh m = {args.level}, buckets x{args.step:g}")
    print("| model | material | faces | r/L p5 · median · p95 | one map: mean | p95 | buckets: maps | mean |")
    print("|---|---|---|---|---|---|---|---|")
    for name in args.models or MODELS:
        for r in measure(name, args.level, args.step):
            print(f"| {r['model']} | {r['material']} | {r['faces']:,} | {r['p5']:.3g} · {r['median']:.3g} · "
                  f"{r['p95']:.3g} | {r['one_mean']:.2f} | {r['one_p95']:.2f} | {r['maps']} | {r['bucket_mean']:.2f} |")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
