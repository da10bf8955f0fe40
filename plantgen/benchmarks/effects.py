"""What each effect costs when on, and that it costs nothing when off (issue 6).

Run as ``python -m plantgen.benchmarks.effects [--size 1024x768] [--frames 5]
[--scenes well desert] [--anim-frames 12]``.

1. Per scene and effect set (none, relief, shadows, relief + shadows, relief + shadows
   cast by the inner cone): the median frame time (GPU draw to finish, ms), the shadow
   pass's share, and the programs compiled and passes run. "Off" runs exactly the plain
   ray caster's programs and passes, so it costs nothing: the table shows the same
   programs, no shadow pass and 0 ms shadow time for it.
2. Shadow map resolution: frame time at 512², 1024², 2048², 4096².
3. Relief vs inner-cone shadow casters: how far apart their light depth maps lie
   (texels that differ, median and 99th percentile depth difference in world units).
4. Animation of the dancing cacti (100 cacti, ~2158 segments): the per-frame CPU update
   (pose, re-skin of the moving instances, pack, upload of only their records), split
   by stage, against the frame's render time, medians over ``--anim-frames`` frames.
   The update runs on the CPU (as in the paper, §4); a vertex-shader version is not
   implemented, so there is nothing to compare it with.

Prints the GL renderer string first: on llvmpipe (a CPU rasteriser) the absolute times
say little about a GPU; the ratios show where time goes.
"""

from __future__ import annotations

import argparse
import statistics
import sys

import numpy as np

from ..animation import AnimatedScene
from ..gl.context import renderer_name
from ..gl.raycast import Raycaster
from ..gl.records import RecordStream
from ..pipeline import grow_file, stage_model
from ..settings import DEFAULT_SIZE, RaycastSettings, ShadowSettings
from ..table1.renderers import time_after_warm_up
from .arguments import image_size


def _scene_setup(name, width, height):
    """(animation, frusta at t = 0, camera, light towards, ground) of a shipped scene."""
    grown = grow_file(name)
    anim = AnimatedScene.from_scene(grown.scene)
    frusta = anim.frusta_at(0.0)
    stage = stage_model(grown, frusta, width, height)
    return anim, frusta, stage.camera, stage.light_dir, stage.ground


def _median_frame(caster, frusta, camera, settings, light, ground, shadows, frames):
    names = frusta.material_names
    first, runs = time_after_warm_up(
        lambda: caster.render(frusta, camera, settings, names, light, ground, shadows=shadows), frames)
    return (statistics.median(r.frame_ms for r in runs),
            statistics.median(r.stats.shadow_ms for r in runs), first.stats)


def effect_costs(scenes, width, height, frames):
    caster = Raycaster()
    configs = [("none", False, None), ("relief", True, None),
               ("shadows", False, ShadowSettings()), ("relief+shadows", True, ShadowSettings()),
               ("relief+shadows(inner caster)", True, ShadowSettings(caster="inner"))]
    print(f"\n1. effect costs at {width}x{height}, shadow map {ShadowSettings().resolution}², "
          f"median of {frames} frames")
    print(f"{'scene':<15}{'effects':<30}{'frame ms':>10}{'shadow ms':>11}{'+ms vs none':>13}  "
          "passes / programs")
    for name in scenes:
        anim, frusta, camera, light, ground = _scene_setup(name, width, height)
        base = None
        for label, relief, shadows in configs:
            ms, shadow_ms, stats = _median_frame(caster, frusta, camera, RaycastSettings(relief=relief),
                                                 light, ground, shadows, frames)
            base = ms if base is None else base
            programs = ", ".join(f"{p}[{'+'.join(d) or '-'}]" for p, d in stats.programs)
            print(f"{name:<15}{label:<30}{ms:>10.1f}{shadow_ms:>11.1f}{ms - base:>+13.1f}  "
                  f"{'/'.join(stats.passes)} | {programs}")


def resolution_costs(name, width, height, frames):
    caster = Raycaster()
    anim, frusta, camera, light, ground = _scene_setup(name, width, height)
    print(f"\n2. shadow map resolution ({name}, relief on)")
    for res in (512, 1024, 2048, 4096):
        ms, shadow_ms, _ = _median_frame(caster, frusta, camera, RaycastSettings(relief=True), light,
                                         ground, ShadowSettings(resolution=res), frames)
        print(f"  {res:>5}²: frame {ms:8.1f} ms, of which shadow pass {shadow_ms:8.1f} ms")


def caster_difference(name, width, height):
    """Relief vs inner-cone casters: their light depth maps and the images they give."""
    caster = Raycaster()
    anim, frusta, camera, light, ground = _scene_setup(name, width, height)
    maps, images, drawn = {}, {}, {}
    resolution = ShadowSettings().resolution
    for kind in ("relief", "inner"):
        shadows = ShadowSettings(resolution=resolution, caster=kind)
        # the map without the ground (only the frusta) ...
        caster.render(frusta, camera, RaycastSettings(relief=True), frusta.material_names, light,
                      None, shadows=shadows)
        window = caster.last_light_window
        depth = caster.shadow_depths()
        drawn[kind] = depth < 1.0
        maps[kind] = depth.astype(np.float64) * (window.depth[1] - window.depth[0])
        # ... and the image with it
        images[kind] = caster.render(frusta, camera, RaycastSettings(relief=True), frusta.material_names,
                                     light, ground, shadows=shadows).color.astype(int)
    both = drawn["relief"] & drawn["inner"]
    only = drawn["relief"] ^ drawn["inner"]
    diff = np.abs(maps["relief"] - maps["inner"])[both]
    texel = window.texel_size(resolution)
    pixel_diff = np.abs(images["relief"] - images["inner"]).max(axis=-1)
    print(f"\n3. relief vs inner-cone shadow caster ({name}, {resolution}², texel {texel * 100:.2f} cm)")
    print(f"  light map: {both.sum():,} texels covered by both, {only.sum():,} by one only (the relief "
          f"silhouette); where both: depth differs by median {np.median(diff) * 100:.2f} cm, "
          f"99th percentile {np.percentile(diff, 99) * 100:.2f} cm")
    print(f"  image at {width}x{height}: {np.mean(pixel_diff > 8) * 100:.1f} % of pixels change by "
          f"more than 8/255, mean change {pixel_diff.mean():.2f}/255")


def animation_update(width, height, frames):
    caster = Raycaster()
    anim, frusta, camera, light, ground = _scene_setup("dancing_cacti", width, height)
    settings = RaycastSettings(relief=True)
    shadows = ShadowSettings()
    box = anim.bounds(np.linspace(0, 2, 5))
    times = np.arange(frames + 1) / 24.0
    updates, renders = [], []
    stream = RecordStream(caster.ctx)
    for i, t in enumerate(times):
        fr, buf, update = anim.upload(stream, t, camera.eye)
        result = caster.render(fr, camera, settings, fr.material_names, light, ground,
                               shadows=shadows, shadow_box=box, record_buffer=buf)
        if i:   # the first frame uploads the static records and compiles shaders
            updates.append(update)
            renders.append(result.frame_ms)

    def med(key):
        return statistics.median(getattr(u, key) for u in updates)

    total = med("total_ms")
    print(f"\n4. animation: dancing cacti, {len(anim.moving_segments):,} moving segments -> "
          f"{updates[-1].rows_reskinned:,} rows, {width}x{height}, relief + shadows, "
          f"median of {frames} frames")
    print(f"  update (CPU): pose {med('pose_ms'):.2f} ms + skin {med('skin_ms'):.2f} ms + pack "
          f"{med('pack_ms'):.2f} ms + upload {med('upload_ms'):.2f} ms = {total:.2f} ms "
          f"({updates[-1].upload_bytes / 1024:.1f} KiB per frame)")
    frame = statistics.median(renders)
    print(f"  render: {frame:.1f} ms per frame; the update is {total / (total + frame) * 100:.1f} % "
          "of update + render")
    stream.release()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plantgen.benchmarks.effects",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--size", type=image_size, default=DEFAULT_SIZE)
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--anim-frames", type=int, default=12)
    parser.add_argument("--scenes", nargs="*", default=["well", "desert"])
    args = parser.parse_args(argv)
    width, height = args.size

    print(f"GL renderer: {renderer_name()}")
    effect_costs(args.scenes, width, height, args.frames)
    resolution_costs(args.scenes[-1], width, height, max(args.frames // 2, 1))
    caster_difference(args.scenes[0], width, height)
    animation_update(width, height, args.anim_frames)
    return 0


if __name__ == "__main__":
    sys.exit(main())
