"""What each effect costs when on, and that it costs nothing when off (issue 6).

Run as ``python -m plantgen.benchmarks.effects [--size 1024x768] [--frames 5]
[--scenes well desert] [--anim-frames 12]``.

1. Per scene and effect set (none, relief, shadows, relief + shadows, relief + shadows
   cast by the inner cone, and relief + shadows with the map reused): the median frame
   time (GPU draw to finish, ms), the shadow pass's share, and the programs compiled and
   passes run. The shadow map is drawn every frame (``ShadowSettings(cache=False)``) to
   show what the pass costs; the last row keeps it (the default): a still scene draws its
   map once, and its frames then cost what the frames without the pass cost plus the
   map's sampling. "Off" runs exactly the plain ray caster's programs and passes, so it
   costs nothing: the table shows the same programs, no shadow pass and 0 ms shadow time
   for it.
2. Shadow map resolution: frame time at 512², 1024², 2048², 4096².
3. Relief vs inner-cone shadow casters: how far apart their light depth maps lie
   (texels that differ, median and 99th percentile depth difference in world units).
4. Animation of the dancing cacti (100 cacti, ~2158 segments), the CPU path against the
   GPU path in one interleaved run (frame by frame in turn), medians over
   ``--anim-frames`` frames: the per-frame update (CPU: pose, re-skin of the moving
   instances, pack, upload of only their records, as in the paper, §4; GPU: the compute
   program of plantgen.gl.pose writing the records: work groups taking whole trees, the
   ends level by level or by pointer doubling, or one dispatch a phase with every row
   walking its root path), the program's
   GPU time (glFinish-bracketed, a GL timer query beside it, and warm: five runs in a row
   with no frame drawn between), the CPU's own share (the same calls dispatching no work
   group), and the frame's render time; then GS and
   GS+R at
   ``--anim-level``: the posed frusta re-tessellated in numpy every frame against the mesh
   built once at rest and posed by the vertex shader.

Prints the GL renderer string first: on llvmpipe (a CPU rasteriser) the absolute times
say little about a GPU; the ratios show where time goes.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import replace

import numpy as np

from ..animation import AnimatedScene
from ..geometry.meshes.mesh import tessellate
from ..gl.context import gl_context, renderer_name
from ..gl.pose import ROWS_PER_GROUP, PoseStream, tree_groups
from ..gl.raster import RasterRenderer
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
    drawn = ShadowSettings(cache=False)
    configs = [("none", False, None), ("relief", True, None),
               ("shadows", False, drawn), ("relief+shadows", True, drawn),
               ("relief+shadows(inner caster)", True, replace(drawn, caster="inner")),
               ("relief+shadows(map reused)", True, ShadowSettings())]
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
                                         ground, ShadowSettings(resolution=res, cache=False), frames)
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


def _pose_paths(ctx, scene):
    """{label: (animation, record sink)}: the CPU path and the GPU path's schedules (work
    groups taking whole trees, level by level: the default, and all in one group; or one
    dispatch a phase, every row walking its root path and chain)."""
    anims = [AnimatedScene.from_scene(scene) for _ in range(5)]
    quarter = -(-anims[1].plan.n // 4)

    def groups(rows_per_group):
        count = len(tree_groups(anims[1].plan, rows_per_group))
        return f"{count} group{'s' if count > 1 else ''}"

    return {"CPU (numpy)": (anims[0], RecordStream(ctx)),
            f"GPU, levels, {groups(ROWS_PER_GROUP)}": (anims[1], PoseStream(ctx, "groups")),
            f"GPU, levels, {groups(quarter)}": (anims[2], PoseStream(ctx, "groups", rows_per_group=quarter)),
            f"GPU, doubling, {groups(ROWS_PER_GROUP)}": (anims[3], PoseStream(ctx, "doubling")),
            "GPU, walks, 4 dispatches": (anims[4], PoseStream(ctx, "walks"))}


def _program_ms(ctx, gpu, target, offset, t) -> tuple[float, float, float, float]:
    """(glFinish-bracketed ms, timer-query ms) of one frame's compute program, the median
    ms of five runs in a row (warm: no frame drawn between them), and the ms of the same
    calls dispatching no work group (the CPU's own share of the update)."""
    ctx.finish()
    query = ctx.query(time=True)
    t0 = time.perf_counter()
    with query:
        gpu.run(t, target, offset)
    ctx.finish()
    t1 = time.perf_counter()
    warm = []
    for _ in range(5):
        t2 = time.perf_counter()
        gpu.run(t, target, offset)
        warm.append((time.perf_counter() - t2) * 1e3)
    ctx.finish()
    t3 = time.perf_counter()
    gpu.run(t, target, offset, dry=True)
    return (t1 - t0) * 1e3, query.elapsed / 1e6, statistics.median(warm), (time.perf_counter() - t3) * 1e3


def animation_update(width, height, frames):
    caster = Raycaster()
    ctx = caster.ctx
    grown = grow_file("dancing_cacti")
    frusta = AnimatedScene.from_scene(grown.scene).frusta_at(0.0)
    stage = stage_model(grown, frusta, width, height)
    camera, settings, shadows = stage.camera, RaycastSettings(relief=True), ShadowSettings()
    paths = _pose_paths(ctx, grown.scene)
    box = next(iter(paths.values()))[0].bounds(np.linspace(0, 2, 5))
    updates = {k: [] for k in paths}
    renders = {k: [] for k in paths}
    programs = {k: [] for k in paths}
    for i, t in enumerate(np.arange(frames + 1) / 24.0):
        for label, (anim, stream) in paths.items():
            rows, buf, update = anim.upload(stream, t, camera.eye)
            result = caster.render(rows, camera, settings, rows.material_names, stage.light_dir, stage.ground,
                                   shadows=shadows, shadow_box=box, record_buffer=buf)
            if i:   # the first frame uploads the static records and compiles shaders
                updates[label].append(update)
                renders[label].append(result.frame_ms)
                if update.on_gpu:
                    gpu = stream.gpu(anim.plan)
                    programs[label].append(_program_ms(ctx, gpu, buf, len(rows) - anim.plan.n, t))
    moving = len(paths["CPU (numpy)"][0].moving_segments)
    print(f"\n4. animation: dancing cacti, {moving:,} moving segments, {width}x{height}, relief + shadows, "
          f"median of {frames} frames, {renderer_name()}")
    _print_update_table(updates, renders, programs)
    anim, stream = list(paths.values())[1]
    print(f"  GPU memory of the pose: {stream.gpu(anim.plan).gpu_bytes() / 1024:.0f} KiB (rest data, uploaded once, "
          "and scratch); per frame the CPU writes the wave's phase (4 B) and dispatches")
    for _, stream in paths.values():
        stream.release()


def _print_update_table(updates, renders, programs):
    def med(values):
        return statistics.median(values) if values else float("nan")

    print(f"  {'path':<28}{'update ms':>10}{'finish ms':>10}{'query ms':>10}{'warm ms':>9}{'CPU ms':>8}"
          f"{'render ms':>11}{'frame ms':>10}  update split")
    totals = {}
    for label, ups in updates.items():
        total = med([u.total_ms for u in ups])
        totals[label] = total
        render = med(renders[label])
        prog = programs[label]
        split = ("pose {:.2f} + skin {:.2f} + pack {:.2f} + upload {:.2f}".format(
            *(med([getattr(u, k) for u in ups]) for k in ("pose_ms", "skin_ms", "pack_ms", "upload_ms")))
            if not prog else f"{sum(u.on_gpu for u in ups)} of {len(ups)} frames on the GPU, "
                             f"{med([u.upload_bytes for u in ups]):.0f} B uploaded a frame")
        cols = "".join(f"{med([p[k] for p in prog]):>{w}.3f}" for k, w in ((0, 10), (1, 10), (2, 9), (3, 8)))
        print(f"  {label:<28}{total:>10.3f}{cols}{render:>11.1f}{render + total:>10.1f}  {split}")
    cpu = totals.pop("CPU (numpy)")
    for label, total in totals.items():
        print(f"  update, CPU path ÷ {label}: {cpu / total:.1f}x")


def animated_meshes(width, height, frames, level):
    """GS and GS+R of the dancing cacti at ``level``: re-tessellated every frame against
    the vertex-skinned mesh, interleaved frame by frame."""
    ctx = gl_context()
    grown = grow_file("dancing_cacti")
    anim = AnimatedScene.from_scene(grown.scene)
    stage = stage_model(grown, anim.frusta_at(0.0), width, height)
    camera, stream = stage.camera, PoseStream(ctx)
    rest = anim.rest_frusta()[0]
    box = anim.motion_box()
    kw = dict(material_names=rest.material_names, light_dir=stage.light_dir, ground=stage.ground,
              shadows=ShadowSettings(), shadow_box=box)
    print(f"\n   GS and GS+R at m = {level} (median of {frames} frames): re-tessellated every frame vs "
          "built once at rest and posed by the vertex shader")
    for relief in (False, True):
        skinned = anim.skinned(tessellate(rest, level, relief=relief, caps="tips"))
        rasters = (RasterRenderer(ctx), RasterRenderer(ctx))
        cpu, gpu = [], []
        for i, t in enumerate(np.arange(frames + 1) / 24.0):
            t0 = time.perf_counter()
            posed = anim.frusta_at(t)
            mesh = tessellate(posed, level, relief=relief, caps="tips")
            update = (time.perf_counter() - t0) * 1e3
            res = rasters[0].render(mesh, posed, camera, **kw)
            poses, up = anim.pose_segments(stream, t, camera.eye)
            skin = rasters[1].render(skinned, rest, camera, poses=poses, bounds=box, **kw)
            if i:
                cpu.append((update + res.stats.upload_ms, res.frame_ms))
                gpu.append((up.pose_ms, skin.frame_ms))
        name = "GS+R" if relief else "GS"
        for label, rows in (("re-tessellated", cpu), ("vertex-skinned", gpu)):
            update, draw = (statistics.median(r[k] for r in rows) for k in (0, 1))
            print(f"  {name:<5}{label:<16} update {update:9.2f} ms + draw {draw:7.1f} ms = {update + draw:8.1f} ms "
                  f"({len(skinned.mesh.faces):,} triangles)")
        for r in rasters:
            r.release()
    stream.release()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plantgen.benchmarks.effects",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--size", type=image_size, default=DEFAULT_SIZE)
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--anim-frames", type=int, default=12)
    parser.add_argument("--anim-level", type=int, default=1, help="GS level of the animated meshes' comparison")
    parser.add_argument("--scenes", nargs="*", default=["well", "desert"])
    args = parser.parse_args(argv)
    width, height = args.size

    print(f"GL renderer: {renderer_name()}")
    effect_costs(args.scenes, width, height, args.frames)
    resolution_costs(args.scenes[-1], width, height, max(args.frames // 2, 1))
    caster_difference(args.scenes[0], width, height)
    animation_update(width, height, args.anim_frames)
    animated_meshes(width, height, max(args.anim_frames // 2, 1), args.anim_level)
    return 0


if __name__ == "__main__":
    sys.exit(main())
