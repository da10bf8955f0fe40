"""``plantgen scan``: a simulated laser scan of a model, written as LAS, LAZ or PLY points."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import click
import numpy as np
from click.core import ParameterSource

from ..geometry.rays.scan import PART_NAMES, ScanSettings, scan_plant, scan_scene
from ..geometry.skeletons.frames import UP_AXES
from ..pipeline import check_finite_frusta, check_scan_memory, grow_file, model_leaves, skin_model, skinning
from ..scanfiles import check_point_output, las_scale, write_points
from .options import (
    allow_path_opt,
    input_arg,
    jobs_opt,
    knob_options,
    limit_opt,
    limits_from,
    output_opt,
    quiet_opt,
    seed_opt,
    smooth_bends_opt,
    take_settings,
)
from .progress import StageBars


def _gpu_finder(settings: ScanSettings, quiet: bool, chosen: bool):
    """(settings, the GPU's search or None): --scan-precision float32 finds each beam's
    primitive on the GPU, and so does a scan that left --scan-precision out where a GPU
    draws the GL context (float64 ranges either way); float64 asked for, no GL, or a
    software GL (llvmpipe) where the compiled CPU traversal runs, gives None (no GPU device
    node, :func:`gpu_device_nodes`: not even a GL context is made; float32
    asked for without GL: the frusta tested in float32 on the CPU, and a line on stderr
    says so)."""
    if settings.precision == "float64" and chosen:
        return settings, None
    from ..geometry.rays.native_trace import wanted

    if not chosen and not gpu_device_nodes() and wanted():   # no GPU here: EGL could only give llvmpipe
        return settings, None
    from ..gl.context import GLContextError, gl_context, hardware_gl
    from ..gl.trace import trace_target

    try:
        gl_context()
    except GLContextError as exc:
        if chosen and not quiet:
            click.echo(f"no GPU traversal ({exc}); float32 on the CPU", err=True)
        return settings, None
    if not chosen and not hardware_gl() and wanted():      # no GPU: the compiled float64 walk is faster
        return settings, None
    return replace(settings, precision="float32"), lambda target, origins, dirs: trace_target(target, origins, dirs)


#: Device nodes a GPU's EGL driver opens on Linux: DRM render nodes (Mesa's hardware
#: drivers), NVIDIA's, and WSL2's GPU.
GPU_DEVICE_NODES = ("/dev/dri/renderD*", "/dev/nvidia[0-9]*", "/dev/dxg")


def gpu_device_nodes() -> list[str]:
    """The GPU device nodes of this machine (Linux; elsewhere one placeholder, so that the
    GL context is asked): where there is none, EGL can only give a software rasteriser,
    and ``plantgen scan`` takes the compiled CPU walk without creating a GL context to
    learn that (llvmpipe's context costs about 0.6 s and its address space)."""
    import glob
    import sys

    if not sys.platform.startswith("linux"):
        return ["(not Linux: ask the GL context)"]
    return [p for pattern in GPU_DEVICE_NODES for p in glob.glob(pattern)]


def _plant_ids(grown) -> tuple[object, object]:
    """The plant label per segment and per leaf polygon: a scene's instances, else 0."""
    if grown.scene is None:
        return 0, None
    return grown.scene.segment_instance(), grown.scene.polygon_instance()


@click.command()
@input_arg
@output_opt("its suffix names the format: .las or .laz (LAS 1.4, point format 6, the labels as extra "
            "bytes; needs the scan extra: pip install '.[scan]') or .ply (binary, double coordinates). "
            "Default: INPUT's "
            "name with .ply, in the current directory.", required=False)
@knob_options(ScanSettings)
@click.option("--scan-seed", type=click.IntRange(min=0), default=0, show_default=True,
              help="Seed of the range noise and of the beams' sub-ray turns (the same seed, the same points).")
@click.option("--up", type=click.Choice(UP_AXES), default="z", show_default=True,
              help="The up axis of the file: z (LAS and scan tools' convention) turns the model +90° about x.")
@seed_opt
@smooth_bends_opt
@limit_opt
@allow_path_opt
@jobs_opt
@quiet_opt
def scan(input: Path, output: Path | None, scan_seed: int, up: str, seed, smooth_bends, limit_values, allow_paths,
         jobs, quiet, **knobs) -> None:
    """Scan INPUT (a grammar or scene .yaml, a shipped one by name, or a skeleton .npz /
    .swc) with simulated laser scanners and write the points, each labelled with its
    plant, part (stem, branch, leaf), branch order, segment, leaf and scanner.

    Terrestrial scanners stand on a circle around the plant (or at --scanner-positions)
    and fire beams every --angular-step degrees at it; airborne flight lines pass over it.
    Each beam's first return is cast against the exact frusta and the leaves, with
    Gaussian range noise and beam divergence if asked (docs: how-to/scan.md).

    \b
    Examples:
      plantgen scan pine                            # writes pine.ply
      plantgen scan pine -o pine.las --angular-step 0.05 --range-noise 0.002
      plantgen scan broadleaf -o leaf.ply --scan-mode airborne --scan-angle 30
    """
    output = output or Path(input.stem + ".ply")
    check_point_output(output)
    chosen = click.get_current_context().get_parameter_source("scan_precision") is not ParameterSource.DEFAULT
    settings = take_settings(ScanSettings, knobs)
    limits = limits_from(limit_values)
    grown = grow_file(input, seed=seed, limits=limits, allow_paths=allow_paths, jobs=jobs)
    check_scan_memory(grown, limits, input)
    settings, finder = _gpu_finder(settings, quiet, chosen)
    with StageBars(enabled=not quiet) as bars:
        if grown.scene is not None:          # each distinct plant once, its copies traced through two levels
            skin = skinning(smooth_bends if smooth_bends is not None else grown.smooth_bends)
            cloud = scan_scene(grown.scene.plants(), settings, scan_seed, limits=limits, progress=bars,
                               skin=lambda skel: check_finite_frusta(skin(skel), str(input)), finder=finder)
        else:
            frusta = skin_model(grown, smooth_bends)
            plant, leaf_plant = _plant_ids(grown)
            cloud = scan_plant(grown.skeleton, model_leaves(grown), settings, scan_seed, frusta=frusta, plant=plant,
                               leaf_plant=leaf_plant, limits=limits, progress=bars, finder=finder)
    write_points(cloud, output, up=up)
    if quiet:
        return
    parts = np.bincount(cloud.part, minlength=len(PART_NAMES))
    where = "flight lines" if settings.mode == "airborne" else "scanners"
    click.echo(f"{len(cloud):,} points from {len(cloud.scanners)} {where} ({settings.describe()}): "
               + ", ".join(f"{n} {k:,}" for n, k in zip(PART_NAMES, parts, strict=True)))
    if output.suffix.lower() in (".las", ".laz") and len(cloud):
        scale, _ = las_scale(*cloud.bounds())
        click.echo(f"coordinates stored to {scale:g} (within {scale / 2:g} of the points), {up}-up")
    click.echo(f"wrote {output}")
