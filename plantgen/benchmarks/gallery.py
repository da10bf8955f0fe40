"""Rebuild every image of the gallery (``gallery/``), each with the command a user would
type, so an image and its caption in the documentation never disagree.

Run as ``python -m plantgen.benchmarks.gallery [--out gallery] [--only NAMES] [--size WxH]
[--list] [--bench]``. Each entry is one command (``plantgen render ...``, ``plantgen view
... --snapshot``, ``python -m plantgen.benchmarks.X ...``), run as its own process; the
progress and the time of each is printed. ``--size`` draws the renders smaller (the test
compares one entry with its command's output); ``--list`` prints the commands.

The viewer's screenshot needs a display: with no ``DISPLAY`` it runs under ``xvfb-run``
(Debian's xvfb), and is skipped with a note when neither is there. The bench's plots
(``gallery/bench/llvmpipe``, about six minutes on two cores, and they rewrite the bench's
tables) are rebuilt only with ``--bench``.
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from ..settings import DEFAULT_SIZE
from ..table1.paper import TABLE1_MODELS
from .arguments import image_size, shipped_model_paths

__all__ = ["Entry", "entries", "command_line", "main"]


#: The scenes of the paper's figures, shaded as their files ask (relief and shadows).
SCENES = ("well", "desert", "oasis", "dancing_cacti")


@dataclass(frozen=True)
class Entry:
    """One command and the gallery files it writes (relative to the gallery folder).

    ``argv`` is the command as typed, with ``{out}`` for the gallery folder and
    ``{size}`` / ``{width}`` / ``{height}`` for the image size (``size``, unless
    ``--size`` overrides it); ``display``: it opens a window."""

    name: str
    argv: tuple
    outputs: tuple
    size: tuple = DEFAULT_SIZE
    display: bool = False
    slow: bool = False


#: The looks bench's variants on this round's defaults (docs/benchmarks/looks.md).
LOOKS_ROUND_VARIANTS = ("default;--aa none;--no-tone --no-translucency --ground none --aa none;--shadows;"
                        "--shadows --sky-light --sky-samples 4")
#: The looks bench's variants in the void (no ground under the plant, nor in the reference).
LOOKS_VOID_VARIANTS = "--ground none;--no-tone --no-translucency --ground none --aa none"
#: Shipped grammars with leaves, rendered beside Table 1's models.
LEAFY_MODELS = ("abop_bush", "broadleaf", "pine_needles", "pine_sprays")
#: Shipped grammars that grow in an environment (?E): clipped to a shape, colonising
#: markers, grown by light.
ENVIRONMENT_MODELS = ("topiary", "colonised", "self_organizing", "stand")


def entries() -> list[Entry]:
    """Every gallery entry, in the order they are built."""
    # the Table 1 models ray cast with relief; the scenes as their files ask (relief, shadows)
    out = [Entry(model, ("plantgen", "render", model, "-o", f"{{out}}/{model}.png", "--relief", "--ssaa", "2",
                         "--size", "{size}"), (f"{model}.png",)) for model in TABLE1_MODELS]
    # the leafy models (issue 17): leaves rasterised beside the frusta, shadows on
    out += [Entry(model, ("plantgen", "render", model, "-o", f"{{out}}/{model}.png", "--relief", "--shadows",
                          "--ssaa", "2", "--size", "{size}"), (f"{model}.png",)) for model in LEAFY_MODELS]
    out += [Entry(f"scenes/{scene}", ("plantgen", "render", scene, "-o", f"{{out}}/scenes/{scene}.png", "--ssaa",
                                      "2", "--size", "{size}"), (f"scenes/{scene}.png",)) for scene in SCENES]
    # the models grown in an environment, and the tree against a wall with its wall
    out += [Entry(model, ("plantgen", "render", model, "-o", f"{{out}}/{model}.png", "--shadows", "--ssaa", "2",
                          "--size", "{size}"), (f"{model}.png",)) for model in ENVIRONMENT_MODELS]
    out.append(Entry("scenes/wall_garden", ("plantgen", "render", "wall_garden", "-o", "{out}/scenes/wall_garden.png",
                                            "--azimuth", "200", "--elevation", "15", "--ssaa", "2", "--size", "{size}"),
                     ("scenes/wall_garden.png",)))
    out.append(Entry("scenes/grove", ("plantgen", "render", "grove", "-o", "{out}/scenes/grove.png", "--elevation",
                                      "20", "--ssaa", "2", "--size", "{size}"), ("scenes/grove.png",)))
    # the forest (issue 25): instanced, its detail at the default --lod-pixels; no supersampling
    # (a frame of 1.3 M drawn rows costs about 8 s on llvmpipe, four times that at --ssaa 2)
    out.append(Entry("scenes/forest", ("plantgen", "render", "forest", "-o", "{out}/scenes/forest.png", "--size",
                                       "{size}"), ("scenes/forest.png",)))
    out.append(Entry("scenes/dancing_cacti.gif", (
        "plantgen", "render", "dancing_cacti", "--frames", "24", "--fps", "12", "--ssaa", "2", "--size", "{size}",
        "-o", "{out}/scenes/dancing_cacti.gif"), ("scenes/dancing_cacti.gif",), (512, 384)))
    out.append(Entry("rc_gs_gsr_saguaro", (
        "python", "-m", "plantgen.benchmarks.side_by_side", "saguaro", "{out}/rc_gs_gsr_saguaro.png",
        "--zoom", "0.3", "--raise", "0.1", "--size", "{width}", "{height}"), ("rc_gs_gsr_saguaro.png",), (400, 400)))
    # the exported normal maps on the smooth mesh (issue 24): RC+R | GS+N | GS
    out.append(Entry("rc_gsn_gs_saguaro", (
        "python", "-m", "plantgen.benchmarks.normal_mapped", "saguaro", "{out}/rc_gsn_gs_saguaro.png",
        "--zoom", "0.3", "--raise", "0.1", "--size", "{width}", "{height}"), ("rc_gsn_gs_saguaro.png",), (400, 400)))
    out.append(Entry("rc_gsn_gs_well", (
        "python", "-m", "plantgen.benchmarks.normal_mapped", "well", "{out}/rc_gsn_gs_well.png", "--zoom", "0.6",
        "--aspect-step", "2", "--size", "{width}", "{height}"), ("rc_gsn_gs_well.png",), (400, 400)))
    # parallax occlusion mapping of the same maps (issue 24, part 5): RC+R | GS+POM | GS+N | GS
    out.append(Entry("rc_gspom_gsn_gs_saguaro", (
        "python", "-m", "plantgen.benchmarks.normal_mapped", "saguaro", "{out}/rc_gspom_gsn_gs_saguaro.png",
        "--zoom", "0.3", "--raise", "0.1", "--parallax", "--size", "{width}", "{height}"),
        ("rc_gspom_gsn_gs_saguaro.png",), (400, 400)))
    out.append(Entry("rc_gspom_gsn_gs_well", (
        "python", "-m", "plantgen.benchmarks.normal_mapped", "well", "{out}/rc_gspom_gsn_gs_well.png", "--zoom",
        "0.6", "--aspect-step", "2", "--parallax", "--size", "{width}", "{height}"), ("rc_gspom_gsn_gs_well.png",),
        (400, 400)))
    # the exported glb rendered by Blender beside RC+R (needs Blender)
    out += [Entry(f"blender_{m}", ("python", "-m", "plantgen.benchmarks.in_blender", m, f"{{out}}/blender_{m}.png",
                                   "--size", "{width}", "{height}"), (f"blender_{m}.png",), (512, 384))
            for m in ("well", "saguaro")]
    # a game asset's levels side by side and its impostor's atlas (plantgen export --asset game)
    out.append(Entry("engine_assets", (
        "python", "-m", "plantgen.benchmarks.asset_levels", "broadleaf", "{out}/engine_assets/broadleaf_levels.png",
        "{out}/engine_assets/broadleaf_impostor_atlas.png", "--size", "{width}", "{height}"),
        ("engine_assets/broadleaf_levels.png", "engine_assets/broadleaf_impostor_atlas.png"), (1280, 300)))
    out.append(Entry("skeletons", ("python", "-m", "plantgen.benchmarks.draw_skeletons", "{out}/skeletons"),
                     tuple(f"skeletons/{p.stem}.png" for p in shipped_model_paths())))
    out.append(Entry("viewer", (
        "plantgen", "view", "desert", "--size", "{size}", "--elevation", "22", "--ssaa", "2", "--no-watch",
        "--snapshot", "{out}/viewer.png"), ("viewer.png",), (960, 600), display=True))
    out.append(Entry("bench", ("plantgen", "bench", "--out", "{out}/bench/llvmpipe"),
                     tuple(f"bench/llvmpipe/curves_{m}.png" for m in TABLE1_MODELS), slow=True))
    # plantgen beside Blender's Cycles of its own export, scored with FLIP (needs Blender)
    out.append(Entry("looks", ("python", "-m", "plantgen.benchmarks.looks", "--size", "256x192", "--reference-samples",
                               "256", "--samples", "1,4,16,64", "--out", "{out}/bench/llvmpipe"),
                     ("bench/llvmpipe/looks.png",), slow=True))
    # the same on this round's defaults, with the anti-aliasing and each effect as a variant
    out.append(Entry("looks_round", (
        "python", "-m", "plantgen.benchmarks.looks", "--size", "256x192", "--reference-samples", "256", "--samples",
        "1,4,16,64", "--variants", LOOKS_ROUND_VARIANTS, "--name", "looks_round", "--out", "{out}/bench/llvmpipe"),
        ("bench/llvmpipe/looks_round.png",), slow=True))
    # the single plants in the void (the baseline's scene): the new look and the old defaults, no ground
    out.append(Entry("looks_void", (
        "python", "-m", "plantgen.benchmarks.looks", "--scenes", "saguaro,broadleaf,pine,coconut", "--size", "256x192",
        "--reference-samples", "256", "--samples", "1,4,16,64", "--reference-ground", "none", "--reference-tone",
        "variant", "--variants", LOOKS_VOID_VARIANTS, "--name", "looks_void", "--out", "{out}/bench/llvmpipe"),
        ("bench/llvmpipe/looks_void.png",), slow=True))
    return out


def command_line(entry: Entry, out: Path, size: tuple | None = None) -> list[str]:
    """The entry's command with the gallery folder and the size filled in, as typed."""
    w, h = size or entry.size
    fill = {"{out}": str(out), "{size}": f"{w}x{h}", "{width}": str(w), "{height}": str(h)}
    args = []
    for a in entry.argv:
        for key, value in fill.items():
            a = a.replace(key, value)
        args.append(a)
    return args


def _process(args: list[str], display: bool) -> list[str] | None:
    """The command as this interpreter runs it (``plantgen`` and ``python`` are this
    Python); a window's command under ``xvfb-run`` when there is no display; None when it
    cannot run here."""
    head = [sys.executable, "-m", "plantgen"] if args[0] == "plantgen" else [sys.executable]
    command = head + args[1:]
    if display and not os.environ.get("DISPLAY"):
        if shutil.which("xvfb-run") is None:
            return None
        command = ["xvfb-run", "-a", "-s", "-screen 0 1280x1024x24", *command]
    return command


def main(argv: list[str] | None = None) -> int:
    """``python -m plantgen.benchmarks.gallery``: rebuild every gallery image."""
    parser = argparse.ArgumentParser(description=main.__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("gallery"), help="the gallery folder (default: gallery)")
    parser.add_argument("--only", help="comma-separated entry names (default: all but the bench)")
    parser.add_argument("--size", type=image_size, help="draw the renders at WxH instead of their sizes")
    parser.add_argument("--list", action="store_true", help="print the commands, run nothing")
    parser.add_argument("--bench", action="store_true", help="also re-run plantgen bench (minutes)")
    args = parser.parse_args(argv)
    chosen = [e for e in entries() if (args.only is None and (args.bench or not e.slow))
              or (args.only is not None and e.name in args.only.split(","))]
    if args.only is not None and len(chosen) != len(args.only.split(",")):
        known = ", ".join(e.name for e in entries())
        parser.error(f"unknown entry in --only {args.only!r} (known: {known})")
    failed = []
    for i, entry in enumerate(chosen, start=1):
        line = command_line(entry, args.out, args.size)
        if args.list:
            print(f"{entry.name}: {shlex.join(line)}")
            continue
        process = _process(line, entry.display)
        print(f"[{i}/{len(chosen)}] {entry.name}: {shlex.join(line)}", flush=True)
        if process is None:
            print("    skipped: it opens a window, and there is no DISPLAY and no xvfb-run", flush=True)
            continue
        for output in entry.outputs:
            (args.out / output).parent.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        proc = subprocess.run(process, capture_output=True, text=True)
        status = "ok" if proc.returncode == 0 else f"failed ({proc.returncode}): {proc.stderr.strip()[-300:]}"
        print(f"    {status}, {time.perf_counter() - t0:.1f} s", flush=True)
        if proc.returncode != 0:
            failed.append(entry.name)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
