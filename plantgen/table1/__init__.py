"""``plantgen bench``: Table 1 of Bhagvat et al. 2009 on the machine at hand, and what
accuracy costs in time.

For each model the bench (:func:`~plantgen.table1.runs.bench_model`)

1. grows and skins it, frames it with the Table 1 camera (the scene's camera, else
   ``auto_camera``: the model spans most of the ``size`` viewport, 1024x768 by default);
2. picks an **evaluation window** (:mod:`plantgen.table1.eval_window`): a ``eval_size`` camera
   with the same eye and the same angle per pixel as the timing camera, aimed at the
   window of the timing image with the most surface and silhouette (a crop at full angular
   resolution: the float64 reference is too slow for 1024x768 on a CPU, and a down-scaled
   view would hide exactly the facets and relief that the knobs trade away);
3. renders the **reference** in that window: the float64 reference ray caster
   (:func:`plantgen.geometry.rays.reference.render_reference`), once without relief (for RC
   and GS) and once with the relief marched with ``reference_relief_samples`` samples and
   bisected to 1e-9 (for RC+R and GS+R). 384 samples is converged to the metric's
   resolution: on the elm (thin bark furrows, the hardest map) 384 and 1024 samples differ
   by an error of 7e-4, 512 and 1024 by 2e-3, while 192 samples still miss 1 % of the
   silhouette (error 0.011). The window is 128x96 by default so the nine references take
   about six minutes on two cores;
4. renders the ray caster's **configurations** (:mod:`plantgen.table1.configs`: RC, and RC+R
   over linear and binary relief steps and v exact/interpolated, one knob at a time) in the
   window for its error, and at the full size for its time;
5. picks **RC+R's Table 1 configuration** from those curves: the fastest one with error at
   most ``relief_error`` (0.01), else the most accurate (:mod:`plantgen.table1.matching`);
   then walks **GS, GS+R, GS+N and GS+POM up from m = 0** (measured the same way) until a
   level meets the quality criterion (:mod:`plantgen.table1.quality`) against RC (GS) and
   against that RC+R configuration (GS+R, GS+N, GS+POM), or the next level is over the
   triangle budget (``max_triangles``). GS+N is GS's smooth mesh drawn with the relief baked
   into normal maps (:func:`plantgen.exporters.textures.bake_textures`, as ``plantgen
   export`` writes them), measured against the relief reference: the metric sees geometry
   only, so its error is the smooth mesh's against the relief surface (the map shades, it
   moves no pixel's depth or silhouette). GS+POM is the mesh on the relief's outer shell
   with parallax occlusion mapping of the same maps' height (``raster.glsl``'s PARALLAX):
   its distance output is the displaced point's, so the metric sees the relief it marches,
   and its silhouette is the mesh's. At GS+POM's level its knobs are swept one at a time
   (:data:`plantgen.table1.configs.PARALLAX_SWEEPS`: layers, secant steps) for the curves;
6. times RC, RC+R, and GS, GS+R, GS+N, GS+POM at their levels **in one interleaved run**
   (frame by frame in turn, after a warm-up), under the paper's conditions, the same for
   all methods: the shadow map and the ground where the scene asks for them, the
   animated scene posed and skinned on the GPU in every frame (RC: a compute pass writes
   the records; GS: a mesh built once at rest, posed by the vertex shader; the dispatch
   counted in the frame), leaves not relief mapped (their material has no shell);
7. counts the GPU bytes of each method (memory table; GS+N's and GS+POM's with their
   tangents and their maps' texture array, mipmaps included, GS+POM's with 8 B a vertex
   of uv scales and 4 B a row of shell thickness).

The error metric and the quality criterion are documented in :mod:`plantgen.table1.quality`;
:mod:`plantgen.table1.summary` sums Table 1 up over the models (ratios' geometric means, beside
the paper's); :mod:`plantgen.table1.reports` writes the tables, CSV and JSON.
"""

from __future__ import annotations

from .configs import METHODS, PARALLAX_SWEEPS, RELIEF_SWEEPS, Method, Sweep, relief_configs
from .eval_window import eval_camera
from .matching import LevelMatch, choose_relief_config, walk_levels
from .models import check_models
from .paper import PAPER_MEMORY_RATIO, PAPER_TABLE1, TABLE1_MODELS
from .params import QUICK_MODELS, RELIEF_ERROR, BenchOptions
from .quality import (
    ImageError,
    depth_shading,
    image_error,
    matched_level,
    pareto_front,
    quality_bound,
    require_skimage,
    silhouette_mismatch,
    ssim,
)
from .reports import match_notes, write_outputs
from .runs import bench_model, count_steps, run_bench
from .summary import geometric_mean, summarise, summary_lines

__all__ = ["BenchOptions", "PAPER_TABLE1", "PAPER_MEMORY_RATIO", "TABLE1_MODELS", "QUICK_MODELS",
           "RELIEF_ERROR", "run_bench", "bench_model", "count_steps", "check_models", "write_outputs",
           "ssim", "require_skimage", "silhouette_mismatch", "depth_shading", "ImageError", "image_error",
           "matched_level", "quality_bound", "pareto_front", "eval_camera", "match_notes",
           "Sweep", "RELIEF_SWEEPS", "relief_configs", "Method", "METHODS",
           "PARALLAX_SWEEPS", "LevelMatch", "walk_levels",
           "choose_relief_config", "summarise", "summary_lines", "geometric_mean"]
