"""The application layer: input files -> skeleton -> renderer or mesh -> output files.

Every stage below is a pure function or a renderer that knows nothing of files or of the
command line; this package glues them, and it is what ``plantgen.cli`` and the Python API
call. A module per command, over one module of the checks they share (each imports only
those below it):

- :mod:`~plantgen.pipeline.export` (``plantgen export``): :func:`export_model`: skin,
  tessellate, write a mesh file (a scene's repeated plants once, instanced, where the
  format can); or write the skeleton as SWC or a forestry cylinder model; its budget
  (:func:`check_export_size`, :func:`check_sway_size`);
- :mod:`~plantgen.pipeline.render` (``plantgen render``, and what ``plantgen view`` draws),
  its whole path in one module: :func:`prepare_model` (a grown input with its effects
  settled and its animation ready), :func:`skinning` / :func:`skin_model` (the skin every
  command uses), :func:`stage_model` (camera, light, ground) and :func:`frame_arguments`
  (the renderers' arguments for one frame), the render's budget and output checks,
  :func:`render_model` (skin and ray cast, in memory) and :func:`render_file` (the same,
  then write PNG / GIF / WebP, the camera JSON and the depth ``.npy``);
- :mod:`~plantgen.pipeline.scan` (``plantgen scan``): its budget, :func:`check_scan_memory`;
- :mod:`~plantgen.pipeline.growing` (``plantgen grow``, and where every command starts):
  :func:`grow_file` / :func:`grow`: a grammar, scene or skeleton ``.npz`` / ``.swc`` to
  a :class:`~plantgen.geometry.skeletons.skeleton.Skeleton`, with the time of each stage;
- :mod:`~plantgen.pipeline.checks`: the limits in force, the finite checks of a skin and
  of a mesh, the memory of a skinned segment.

Every entry point takes ``limits`` (the budgets in force, :class:`plantgen.limits.Limits`;
default: ``plantgen.limits.limits``) and ``allow_paths`` (folders a scene may read grammars
from besides its own). One input's derivations share one ``derive_work`` meter, and a
render or an export estimates its memory from the sizes it knows before it allocates.
Every public name of the modules is imported here: ``from plantgen.pipeline import
render_model``.
"""

from __future__ import annotations

from .checks import SKIN_BYTES_PER_SEGMENT, check_finite_frusta, check_finite_mesh, distinct_segments
from .export import (
    INSTANCING,
    SWAY_BYTES_PER_JOINT,
    SWAY_BYTES_PER_KEY,
    check_export_size,
    check_sway_size,
    export_model,
    plant_detail,
    scene_extras,
)
from .growing import (
    SKELETON_SUFFIXES,
    GrowResult,
    existing_input,
    grow,
    grow_file,
    load_input,
    load_skeleton,
    read_skeleton,
    resolve_input,
)
from .render import (
    FRAME_BYTES_PER_PIXEL,
    RENDER_BYTES_PER_PIXEL,
    SHADOW_BYTES_PER_TEXEL,
    PreparedModel,
    RenderReport,
    ShadowUse,
    Staging,
    animate_model,
    check_image_output,
    check_render_outputs,
    estimate_render_bytes,
    frame_arguments,
    ground_asked,
    model_leaves,
    place_scene,
    prepare_model,
    render_file,
    render_model,
    request_settings,
    skin_model,
    skinning,
    stage_model,
)
from .scan import SCAN_BYTES_PER_SEGMENT, check_scan_memory

__all__ = [
    # growing: plantgen grow
    "GrowResult", "grow", "grow_file", "load_skeleton", "load_input", "read_skeleton", "resolve_input",
    "existing_input", "SKELETON_SUFFIXES",
    # render: the model made ready, then plantgen render
    "Staging", "stage_model", "ground_asked", "model_leaves", "PreparedModel",
    "prepare_model", "place_scene", "animate_model",
    "skinning", "skin_model", "frame_arguments", "request_settings", "RenderReport", "ShadowUse",
    "check_image_output", "check_render_outputs", "estimate_render_bytes", "render_model", "render_file",
    "RENDER_BYTES_PER_PIXEL", "FRAME_BYTES_PER_PIXEL", "SHADOW_BYTES_PER_TEXEL",
    # export: plantgen export
    "export_model", "INSTANCING", "check_export_size", "scene_extras", "plant_detail", "check_sway_size",
    "SWAY_BYTES_PER_JOINT", "SWAY_BYTES_PER_KEY",
    # scan: plantgen scan's budget
    "check_scan_memory", "SCAN_BYTES_PER_SEGMENT",
    # checks: shared by every command
    "check_finite_frusta", "check_finite_mesh", "distinct_segments", "SKIN_BYTES_PER_SEGMENT",
]
