"""``plantgen bench``: Table 1 of Bhagvat et al. 2009 on the machine at hand, and what
accuracy costs in time.

For each model the bench

1. grows and skins it, frames it with the Table 1 camera (the scene's camera, else
   ``auto_camera``: the model spans most of the ``size`` viewport, 1024x768 by default);
2. picks an **evaluation window**: a ``eval_size`` camera with the same eye and the same
   angle per pixel as the timing camera, aimed at the window of the timing image with the
   most surface and silhouette (a crop at full angular resolution: the float64 reference
   is too slow for 1024x768 on a CPU, and a down-scaled view would hide exactly the facets
   and relief that the knobs trade away);
3. renders the **reference** in that window: the float64 reference ray caster
   (:func:`plantgen.geometry.reference.render_reference`), once without relief (for RC
   and GS) and once with the relief marched with ``reference_relief_samples`` samples and
   bisected to 1e-9 (for RC+R and GS+R). 384 samples is converged to the metric's
   resolution: on the elm (thin bark furrows, the hardest map) 384 and 1024 samples differ
   by an error of 7e-4, 512 and 1024 by 2e-3, while 192 samples still miss 1 % of the
   silhouette (error 0.011). The window is 128x96 by default so the nine references take
   about six minutes on two cores;
4. renders every **configuration** (RC, GS at m = 0..5, RC+R over linear and binary
   relief steps and v exact/interpolated, GS+R at m = 0..5) in the window for its error,
   and at the full size for its time;
5. computes the **matched level** (the quality criterion, below) of GS and GS+R;
6. times RC, RC+R, GS at its level and GS+R at its level **in one interleaved run**
   (frame by frame in turn, after a warm-up), under the paper's conditions, the same for
   all four methods: the shadow map and the ground where the scene asks for them, the
   animated scene posed, re-skinned and uploaded in every frame (GS also re-tessellated;
   counted in the frame), leaves not relief mapped (their material has no shell);
7. counts the GPU bytes of each method (memory table).

Error metric (documented criterion)
-----------------------------------
Each image is reduced to what the knobs change, its geometry: from the per-pixel distance
along the ray (every renderer writes it; the reference gives it in float64) the surface
point is rebuilt, its normal taken from the neighbouring pixels, and the image shaded as
``0.15 + 0.85·max(0, n·l)`` (0 where the ray misses). The same operator is applied to the
reference and to every method, so colours and texturing cancel out and relief bumps,
polygon facets and silhouettes remain. The error of a method is

    error = (1 - SSIM) + silhouette mismatch

SSIM with an 11x11 Gaussian window (sigma 1.5) on that shading, silhouette mismatch the
pixels covered by exactly one of method and reference over the pixels the reference
covers. Both parts are reported.

Quality criterion: the GS level reported is the smallest m whose error is at most the
ray caster's error times ``1 + rel_tol`` plus ``abs_tol`` (defaults 10 % and 0.01: an SSIM
difference of 0.01 is hard to see); GS
is matched against RC (no relief, non-relief reference), GS+R against RC+R (relief
reference). A level over the triangle budget (``max_triangles``) is not built; when no
level qualifies, the table shows the best level measured as ``>m``.

fps are ``1000 / median frame time``; frame times are measured by the renderers
(draw calls to ``glFinish``, excluding read-back), plus the per-frame CPU update of an
animated scene. Nothing is taken from the paper but its own columns, printed beside ours.
"""

from __future__ import annotations

import csv
import datetime
import io
import json
import math
import os
import platform
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .errors import PlantgenError

__all__ = ["BenchOptions", "PAPER_TABLE1", "TABLE1_MODELS", "run_bench", "ssim",
           "silhouette_mismatch", "depth_shading", "image_error", "matched_level",
           "pareto_front", "eval_camera", "write_outputs", "QUICK_MODELS", "check_models",
           "bench_model"]

#: The nine models of Table 1, in the paper's order, as shipped grammar/scene names.
TABLE1_MODELS = ("coconut", "pine", "elm", "aloe", "saguaro", "well", "desert", "oasis",
                 "dancing_cacti")
QUICK_MODELS = ("saguaro", "well")

#: Table 1 of the paper (NVidia 8800 GTX, 1024x768): printed beside our numbers, never
#: used as ours. model -> (segments, RC fps, RC+R fps, (GS fps, sub), (GS+R fps, sub)).
PAPER_TABLE1 = {
    "coconut": (3713, 83, 71, (240, 1), (63, 2)),
    "pine": (16997, 34, 16, (55, 1), (15, 2)),
    "elm": (1833, 193, 20, (375, 1), (102, 2)),
    "aloe": (229, 171, 20, (820, 2), (53, 4)),
    "saguaro": (30, 305, 105, (830, 2), (54, 4)),
    "well": (8, 303, 105, (296, 2), (21, 4)),
    "desert": (799, 421, 151, (1100, 0), (79, 2)),
    "oasis": (18557, 46, 31, (174, 0), (13, 2)),
    "dancing_cacti": (2158, 35, 33, (170, 0), (12, 2)),
}
#: §4: "the vertices for polygons at the same sampling density will take twelve times as
#: much space" as the 8-bit relief map.
PAPER_MEMORY_RATIO = 12.0


@dataclass
class BenchOptions:
    """Knobs of one bench run.

    models : grammar/scene names or paths
    size : (width, height) of the timed frames, pixels
    frames : timed frames of each Table 1 method (after one warm-up frame)
    curve_frames : timed frames of each configuration of the accuracy curves
    eval_size : (width, height) of the evaluation window (same angle per pixel as ``size``)
    levels : GS / GS+R subdivision levels tried
    linear_steps, binary_steps : relief step counts swept for RC+R (the other knob at
        the ray caster's default, 32 linear / 6 binary)
    max_triangles : GS meshes above this many triangles are not built (memory, time)
    reference_relief_samples : linear samples of the reference's relief march before
        bisection to 1e-9
    rel_tol, abs_tol : the quality criterion's tolerance
    images : write the compared images
    quick : the CI run (small sizes, few knobs)
    """

    models: tuple = TABLE1_MODELS
    size: tuple = (1024, 768)
    frames: int = 9
    curve_frames: int = 5
    eval_size: tuple = (128, 96)
    levels: tuple = (0, 1, 2, 3, 4, 5)
    linear_steps: tuple = (4, 8, 16, 32, 64, 128)
    binary_steps: tuple = (0, 2, 4, 6, 8)
    max_triangles: int = 6_000_000
    reference_relief_samples: int = 384
    rel_tol: float = 0.10
    abs_tol: float = 0.01
    images: bool = False
    quick: bool = False

    @classmethod
    def quick_run(cls, **overrides) -> "BenchOptions":
        """The small run CI drives end to end (two tiny models, small images)."""
        base = dict(models=QUICK_MODELS, size=(256, 192), frames=2, curve_frames=2, eval_size=(64, 48),
                    levels=(0, 1, 2), linear_steps=(4, 32), binary_steps=(0, 6),
                    max_triangles=500_000, reference_relief_samples=96, quick=True)
        base.update(overrides)
        return cls(**base)


# ---------------------------------------------------------------------------- image metrics
def _gaussian_kernel(size: int = 11, sigma: float = 1.5) -> np.ndarray:
    x = np.arange(size) - (size - 1) / 2
    k = np.exp(-0.5 * (x / sigma) ** 2)
    return k / k.sum()


def _blur(image: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Separable 'valid' filter of an (H, W) float image with a (k,) kernel."""
    k = len(kernel)
    rows = np.lib.stride_tricks.sliding_window_view(image, k, axis=1) @ kernel
    return np.lib.stride_tricks.sliding_window_view(rows, k, axis=0) @ kernel


def ssim(a: np.ndarray, b: np.ndarray, data_range: float = 1.0) -> float:
    """Mean structural similarity (Wang et al. 2004) of two (H, W) images in [0, data_range]:
    11x11 Gaussian window, sigma 1.5, K1 = 0.01, K2 = 0.03; 1 for identical images."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 2:
        raise ValueError(f"ssim needs two equal (H, W) images, got {a.shape} and {b.shape}")
    size = min(11, *a.shape)
    kernel = _gaussian_kernel(size, 1.5 * size / 11)
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    mu_a, mu_b = _blur(a, kernel), _blur(b, kernel)
    var_a = _blur(a * a, kernel) - mu_a ** 2
    var_b = _blur(b * b, kernel) - mu_b ** 2
    cov = _blur(a * b, kernel) - mu_a * mu_b
    s = ((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (var_a + var_b + c2))
    return float(s.mean())


def silhouette_mismatch(covered: np.ndarray, reference_covered: np.ndarray) -> float:
    """Pixels covered by exactly one of the two (H, W) bool masks, over the pixels the
    reference covers (0: the same silhouette)."""
    covered = np.asarray(covered, dtype=bool)
    reference_covered = np.asarray(reference_covered, dtype=bool)
    return float((covered ^ reference_covered).sum() / max(int(reference_covered.sum()), 1))


def _neighbour_difference(points: np.ndarray, hit: np.ndarray, axis: int) -> np.ndarray:
    """(H, W, 3) point difference to the next pixel along ``axis`` (0: down, 1: right) where
    both hit, else to the previous one where both hit, else 0."""
    diff = np.diff(points, axis=axis)
    both = np.logical_and(np.take(hit, range(hit.shape[axis] - 1), axis=axis),
                          np.take(hit, range(1, hit.shape[axis]), axis=axis))
    diff = np.where(both[..., None], diff, 0.0)
    pad_after = [(0, 0)] * 3
    pad_before = [(0, 0)] * 3
    pad_after[axis] = (0, 1)
    pad_before[axis] = (1, 0)
    forward = np.pad(diff, pad_after)
    backward = np.pad(diff, pad_before)
    has_forward = np.pad(both, pad_after[:2])
    return np.where(has_forward[..., None], forward, backward)


def depth_shading(distance: np.ndarray, camera, light_dir) -> np.ndarray:
    """(H, W) float64 shading in [0, 1] of the surface rebuilt from per-pixel distances.

    distance : (H, W) distance from the eye along each pixel's unit ray (world units),
        inf (or nan) where the ray misses; row 0 the top row
    camera : the Camera that made the rays
    light_dir : (3,) direction towards the light

    The normal comes from the cross product of the point differences to the right and
    downward neighbours (backward differences at the last row/column, and wherever the
    forward neighbour misses); shading 0.15 + 0.85·max(0, n·l) on hits, 0 on misses.
    """
    _, dirs = camera.rays()
    dist = np.asarray(distance, dtype=np.float64)
    hit = np.isfinite(dist)
    points = dirs * np.where(hit, dist, 0.0)[..., None]   # relative to the eye
    dx = _neighbour_difference(points, hit, axis=1)
    dy = _neighbour_difference(points, hit, axis=0)
    normal = np.cross(dy, dx)
    length = np.linalg.norm(normal, axis=-1, keepdims=True)
    normal = np.where(length > 0, normal / np.where(length > 0, length, 1.0), 0.0)
    facing = np.einsum("hwc,hwc->hw", normal, dirs)
    normal = np.where((facing > 0)[..., None], -normal, normal)   # towards the eye
    light = np.asarray(light_dir, dtype=np.float64)
    light = light / np.linalg.norm(light)
    lambert = np.clip(normal @ light, 0.0, 1.0)
    return np.where(hit, 0.15 + 0.85 * lambert, 0.0)


@dataclass
class ImageError:
    """Error of one image against the reference: ``dssim`` = 1 - SSIM of the depth
    shading, ``silhouette`` the coverage mismatch, ``total`` their sum."""

    dssim: float
    silhouette: float

    @property
    def total(self) -> float:
        return self.dssim + self.silhouette


def image_error(distance, reference_distance, camera, light_dir) -> ImageError:
    """:class:`ImageError` of a (H, W) distance image against the reference's."""
    shade = depth_shading(distance, camera, light_dir)
    ref_shade = depth_shading(reference_distance, camera, light_dir)
    return ImageError(1.0 - ssim(shade, ref_shade),
                      silhouette_mismatch(np.isfinite(distance), np.isfinite(reference_distance)))


def matched_level(level_errors: dict, target_error: float, rel_tol: float = 0.10,
                  abs_tol: float = 0.01):
    """The smallest level whose error is at most ``target_error·(1 + rel_tol) + abs_tol``.

    level_errors : {m: error} of the levels measured
    Returns (level, matched): the level and True, or the level of least error and False.
    """
    if not level_errors:
        return None, False
    bound = target_error * (1 + rel_tol) + abs_tol
    for m in sorted(level_errors):
        if level_errors[m] <= bound:
            return m, True
    return min(level_errors, key=lambda m: (level_errors[m], m)), False


def pareto_front(ms, errors, min_gain: float = 1e-4) -> np.ndarray:
    """(k,) indices of the points no other point beats in both time and error (ascending ms).

    A slower point joins the front only if it lowers the error by more than ``min_gain``
    (below that, errors are rounding noise of the metric, not a quality gain)."""
    ms = np.asarray(ms, dtype=np.float64)
    errors = np.asarray(errors, dtype=np.float64)
    order = np.lexsort((errors, ms))
    front, best = [], np.inf
    for i in order:
        if errors[i] < best - (min_gain if front else 0.0):
            front.append(int(i))
            best = errors[i]
    return np.asarray(front, dtype=np.int64)


# ---------------------------------------------------------------------------- cameras
def eval_camera(camera, covered: np.ndarray, eval_size) -> "object":
    """The evaluation window: a ``eval_size`` camera with ``camera``'s eye, up and angle
    per pixel, aimed at the window of ``covered`` ((H, W) bool, the timing image's hits)
    with the most surface plus (4x weighted) silhouette pixels."""
    from .geometry.camera import Camera

    width, height = camera.width, camera.height
    ew, eh = min(int(eval_size[0]), width), min(int(eval_size[1]), height)
    covered = np.asarray(covered, dtype=bool)
    edge = np.zeros_like(covered)
    edge[:, 1:] |= covered[:, 1:] ^ covered[:, :-1]
    edge[1:] |= covered[1:] ^ covered[:-1]
    score = covered.astype(np.float64) + 4.0 * edge
    integral = np.zeros((height + 1, width + 1))
    integral[1:, 1:] = score.cumsum(0).cumsum(1)
    sums = (integral[eh:, ew:] - integral[:-eh, ew:] - integral[eh:, :-ew] + integral[:-eh, :-ew])
    y0, x0 = np.unravel_index(int(np.argmax(sums)), sums.shape)
    cx, cy = x0 + ew / 2, y0 + eh / 2          # window centre, pixel units
    right, up, fwd = camera.basis()
    tan_y = math.tan(math.radians(camera.fov_y) / 2)
    tan_x = tan_y * camera.aspect
    direction = fwd + (cx / width * 2 - 1) * tan_x * right + (1 - cy / height * 2) * tan_y * up
    direction /= np.linalg.norm(direction)
    eye = np.asarray(camera.eye, dtype=np.float64)
    # same angle per pixel at the window's centre: scale the field of view with the height
    fov = math.degrees(2 * math.atan(tan_y * eh / height))
    return Camera(tuple(eye.tolist()), tuple((eye + direction).tolist()), tuple(up.tolist()),
                  fov, ew, eh)


# ---------------------------------------------------------------------------- models
@dataclass
class _Model:
    name: str
    frusta: object
    names: tuple
    camera: object
    light_dir: tuple
    ground: dict | None
    shadows: bool
    animation: object | None     # AnimatedScene or None
    relief: bool                 # any row with a relief shell


def _load_model(name: str, size) -> _Model:
    from .geometry.camera import Camera
    from .pipeline import grow_file
    from .render.animate import AnimatedScene
    from .render.raycast import auto_camera

    grown = grow_file(name)
    scene = grown.scene
    effects = tuple(scene.effects) if scene is not None else ()
    if scene is not None and "animation" in effects:
        anim = AnimatedScene.from_scene(scene)
        frusta = anim.frusta_at(0.0)
        if not anim.animated:
            anim = None
    else:
        from .geometry.skin import skin_skeleton

        anim = None
        frusta = skin_skeleton(grown.skeleton)
    if len(frusta) == 0:
        raise PlantgenError(f"{name}: nothing to bench (no segments)")
    width, height = size
    if scene is not None and isinstance(scene.camera, dict):
        camera = Camera.from_dict({**scene.camera, "width": width, "height": height}, f"{name}: camera")
    else:
        camera = auto_camera(frusta, width, height)
    light = (0.45, 0.8, 0.35)
    if scene is not None:
        light = tuple(-np.asarray(scene.light["direction"], dtype=np.float64))
    model_name = Path(str(name)).stem
    return _Model(model_name, frusta, tuple(frusta.material_names), camera, light,
                  scene.ground if scene is not None else None, "shadows" in effects, anim,
                  bool(np.any(np.asarray(frusta.shell) > 0)))


# ---------------------------------------------------------------------------- configurations
@dataclass
class _Config:
    key: str            # e.g. "rc+r:linear=16"
    method: str         # RC, RC+R, GS, GS+R
    knob: str           # what varies ("", "m", "linear", "binary", "v")
    value: object
    settings: object = None   # RaycastSettings for RC methods
    level: int | None = None


def _configs(opts: BenchOptions, relief: bool) -> list[_Config]:
    from .render.raycast import RaycastSettings

    out = [_Config("rc", "RC", "", "", RaycastSettings())]
    out += [_Config(f"gs:m={m}", "GS", "m", m, level=m) for m in opts.levels]
    if relief:
        base = RaycastSettings(relief=True)
        seen = set()
        for n in opts.linear_steps:
            s = RaycastSettings(relief=True, linear_steps=n, binary_steps=base.binary_steps)
            out.append(_Config(f"rc+r:linear={n}", "RC+R", "linear", n, s))
            seen.add((n, base.binary_steps))
        for n in opts.binary_steps:
            if (base.linear_steps, n) in seen:
                continue
            s = RaycastSettings(relief=True, linear_steps=base.linear_steps, binary_steps=n)
            out.append(_Config(f"rc+r:binary={n}", "RC+R", "binary", n, s))
        out.append(_Config("rc+r:v=exact", "RC+R", "v", "exact", RaycastSettings(relief=True, v_exact=True)))
        out += [_Config(f"gs+r:m={m}", "GS+R", "m", m, level=m) for m in opts.levels]
    return out


def _default_rcr_key(configs) -> str:
    from .render.raycast import RaycastSettings

    d = RaycastSettings(relief=True)
    for c in configs:
        if c.method == "RC+R" and c.knob == "linear" and c.value == d.linear_steps:
            return c.key
    for c in configs:
        if c.method == "RC+R" and c.knob == "binary" and c.value == d.binary_steps:
            return c.key
    return next(c.key for c in configs if c.method == "RC+R")


def _median(values) -> float:
    return float(np.median(np.asarray(values, dtype=np.float64))) if len(values) else float("nan")


class _Renderers:
    """The GL side of one model: one ray caster, one raster renderer per mesh (so the
    interleaved run does not re-upload), meshes cached per (level, relief)."""

    def __init__(self, model: _Model, max_triangles: int, shadow_box=None):
        from .render.raster import RasterRenderer
        from .render.raycast import Raycaster

        self.model = model
        self.max_triangles = max_triangles
        self.raycaster = Raycaster()
        self._raster_cls = RasterRenderer
        self.rasters: dict = {}
        self.meshes: dict = {}
        self.tessellate_ms: dict = {}
        self.shadow_box = shadow_box   # (2, 3) one light window for every animation frame

    def mesh(self, level: int, relief: bool, frusta=None):
        """The tessellation (cached for the static frusta), or None over the triangle budget."""
        from .geometry.mesh import tessellate, triangle_count

        frusta = self.model.frusta if frusta is None else frusta
        key = (level, relief)
        static = frusta is self.model.frusta
        if static and key in self.meshes:
            return self.meshes[key]
        estimate = triangle_count(len(frusta), level, 0)
        if estimate > self.max_triangles:
            return None
        t0 = time.perf_counter()
        mesh = tessellate(frusta, level, relief=relief, caps="tips")
        ms = (time.perf_counter() - t0) * 1e3
        if static:
            self.meshes[key] = mesh
            self.tessellate_ms[key] = ms
        return mesh

    def raster(self, key):
        if key not in self.rasters:
            self.rasters[key] = self._raster_cls(self.raycaster.ctx)
        return self.rasters[key]

    def render_config(self, cfg: _Config, camera, *, conditions: bool = False, t: float = 0.0):
        """Render ``cfg`` once; returns (RenderResult, frame ms including the per-frame
        CPU work the conditions ask for)."""
        from .render.passes import ShadowSettings

        m = self.model
        shadows = ShadowSettings() if conditions and m.shadows else None
        ground = m.ground if conditions else None
        animated = conditions and m.animation is not None
        if cfg.method in ("RC", "RC+R"):
            if animated:
                frusta, buf, update = m.animation.upload(self.raycaster.ctx, t, camera.eye)
                res = self.raycaster.render(frusta, camera, cfg.settings, m.names, m.light_dir, ground,
                                            shadows=shadows, shadow_box=self.shadow_box,
                                            record_buffer=buf)
                return res, res.frame_ms + update.total_ms
            res = self.raycaster.render(m.frusta, camera, cfg.settings, m.names, m.light_dir, ground,
                                        shadows=shadows)
            return res, res.frame_ms
        relief = cfg.method == "GS+R"
        extra_ms = 0.0
        if animated:
            t0 = time.perf_counter()
            frusta = m.animation.frusta_at(t)           # pose + re-skin, as RC does
            mesh = self.mesh(cfg.level, relief, frusta)  # re-tessellate
            extra_ms = (time.perf_counter() - t0) * 1e3
        else:
            frusta = m.frusta
            mesh = self.mesh(cfg.level, relief)
        if mesh is None:
            return None, float("nan")
        res = self.raster(cfg.key).render(mesh, frusta, camera, material_names=m.names,
                                          light_dir=m.light_dir, ground=ground, shadows=shadows,
                                          shadow_box=self.shadow_box if animated else None)
        return res, res.frame_ms + extra_ms + (res.stats.get("upload_ms", 0.0) if animated else 0.0)

    def release_raster(self, key):
        """Free the GPU buffers of ``key``'s raster renderer (the mesh stays cached)."""
        raster = self.rasters.pop(key, None)
        if raster is not None:
            raster.release()

    def keep_meshes(self, keys):
        """Drop the cached meshes other than ``keys`` ((level, relief) pairs)."""
        self.meshes = {k: v for k, v in self.meshes.items() if k in keys}

    def release(self):
        for key in list(self.rasters):
            self.release_raster(key)
        self.raycaster.release()
        if self.model.animation is not None:
            self.model.animation.release()


def _time_configs(renderers: _Renderers, configs, camera, frames: int, *, conditions: bool,
                  tick=None, passes: dict | None = None) -> dict:
    """Interleaved timing: one warm-up frame each, then ``frames`` rounds rendering every
    config once per round. Returns {key: [ms, ...]}; ``passes``, if given, receives
    {key: the render passes of the warm-up frame}."""
    samples = {c.key: [] for c in configs}
    alive = list(configs)
    for c in list(alive):
        res, _ = renderers.render_config(c, camera, conditions=conditions, t=0.0)
        if res is None:
            alive.remove(c)
        elif passes is not None:
            passes[c.key] = list(res.stats.get("passes", []))
    for i in range(frames):
        t = (i + 1) / 30.0
        for c in alive:
            _, ms = renderers.render_config(c, camera, conditions=conditions, t=t)
            samples[c.key].append(ms)
        if tick:
            tick()
    return samples


# ---------------------------------------------------------------------------- one model
def bench_model(name: str, opts: BenchOptions, progress=None, images_dir: Path | None = None) -> dict:
    """Everything the bench measures for one model (a JSON-ready dict)."""
    from .geometry.reference import render_reference
    from .render.raster import gs_buffer_bytes, rc_buffer_bytes
    from .render.raycast import height_maps_for

    def step(label):
        if progress is not None:
            progress(label)

    model = _load_model(name, opts.size)
    shadow_box = None
    if model.animation is not None and model.shadows:
        shadow_box = model.animation.bounds(np.arange(0, opts.frames + 2, 4) / 30.0)
    renderers = _Renderers(model, opts.max_triangles, shadow_box)
    configs = _configs(opts, model.relief)
    try:
        # 1. evaluation window, from the timing image's coverage
        first, _ = renderers.render_config(configs[0], model.camera)
        ecam = eval_camera(model.camera, np.isfinite(first.distance), opts.eval_size)
        step(f"{model.name}: reference")
        t0 = time.perf_counter()
        refs = {False: render_reference(model.frusta, ecam)}
        if model.relief:
            refs[True] = render_reference(model.frusta, ecam, relief=True,
                                          relief_samples=opts.reference_relief_samples)
        reference_s = time.perf_counter() - t0
        ref_dist = {k: np.where(r.hit, r.t, np.inf) for k, r in refs.items()}   # unit rays

        # 2. every configuration: error in the window, time at full size
        curve = []
        saved = {}
        for cfg in configs:
            step(f"{model.name}: {cfg.key}")
            relief = cfg.method in ("RC+R", "GS+R")
            res, _ = renderers.render_config(cfg, ecam)
            if res is None:
                tris = 16 * 4 ** cfg.level * len(model.frusta)
                curve.append({"key": cfg.key, "method": cfg.method, "knob": cfg.knob,
                              "value": cfg.value, "skipped": f"{tris:,} triangles over the budget "
                              f"of {opts.max_triangles:,}"})
                continue
            err = image_error(res.distance, ref_dist[relief], ecam, model.light_dir)
            samples = _time_configs(renderers, [cfg], model.camera, opts.curve_frames,
                                    conditions=False)[cfg.key]
            ms = _median(samples)
            row = {"key": cfg.key, "method": cfg.method, "knob": cfg.knob, "value": cfg.value,
                   "ms": ms, "fps": 1000.0 / ms, "ms_samples": samples, "error": err.total,
                   "dssim": err.dssim, "silhouette": err.silhouette}
            if cfg.level is not None:
                mesh = renderers.mesh(cfg.level, relief)
                row["triangles"] = int(len(mesh.faces))
                row["gpu_bytes"] = int(gs_buffer_bytes(mesh))
            curve.append(row)
            saved[cfg.key] = res
            renderers.release_raster(cfg.key)
        by_key = {r["key"]: r for r in curve if "error" in r}

        # 3. the quality criterion
        rc_err = by_key["rc"]["error"]
        gs_level, gs_ok = matched_level({r["value"]: r["error"] for r in curve
                                         if r["method"] == "GS" and "error" in r},
                                        rc_err, opts.rel_tol, opts.abs_tol)
        table_cfgs = [c for c in configs if c.key == "rc"]
        rcr_key = gsr_level = None
        gsr_ok = False
        if model.relief:
            rcr_key = _default_rcr_key(configs)
            gsr_level, gsr_ok = matched_level({r["value"]: r["error"] for r in curve
                                               if r["method"] == "GS+R" and "error" in r},
                                              by_key[rcr_key]["error"], opts.rel_tol, opts.abs_tol)
            table_cfgs.append(next(c for c in configs if c.key == rcr_key))
        if gs_level is not None:
            table_cfgs.append(next(c for c in configs if c.key == f"gs:m={gs_level}"))
        if gsr_level is not None:
            table_cfgs.append(next(c for c in configs if c.key == f"gs+r:m={gsr_level}"))

        renderers.keep_meshes({(gs_level, False), (gsr_level, True)})
        # 4. Table 1 timing: the four methods interleaved, under the paper's conditions
        step(f"{model.name}: Table 1 timing")
        table_passes: dict = {}
        table_samples = _time_configs(renderers, table_cfgs, model.camera, opts.frames,
                                      conditions=True, passes=table_passes)

        def entry(key):
            if key is None or key not in table_samples or not table_samples[key]:
                return None
            ms = _median(table_samples[key])
            return {"key": key, "ms": ms, "fps": 1000.0 / ms, "ms_samples": table_samples[key],
                    "passes": table_passes.get(key, []),
                    "error": by_key[key]["error"], "dssim": by_key[key]["dssim"],
                    "silhouette": by_key[key]["silhouette"]}

        # 5. memory: bytes on the GPU
        n_rows = len(model.frusta)
        maps = height_maps_for(model.names)[0]
        rc_bytes = rc_buffer_bytes(n_rows)
        memory = {"rc_bytes": rc_bytes, "relief_map_bytes": int(maps.nbytes) if model.relief else 0,
                  "rcr_bytes": rc_bytes + (int(maps.nbytes) if model.relief else 0),
                  "gs_bytes": by_key.get(f"gs:m={gs_level}", {}).get("gpu_bytes"),
                  "gsr_bytes": by_key.get(f"gs+r:m={gsr_level}", {}).get("gpu_bytes")}
        memory["gs_over_rc"] = (memory["gs_bytes"] / rc_bytes) if memory["gs_bytes"] else None
        memory["gsr_over_rcr"] = (memory["gsr_bytes"] / memory["rcr_bytes"]
                                  if memory["gsr_bytes"] else None)

        if images_dir is not None:
            _save_images(images_dir, model, ecam, refs, ref_dist, saved,
                         [c.key for c in table_cfgs])
        notes = []
        if model.shadows:
            notes.append("shadow map (2048², PCF) and ground for RC, RC+R, GS and GS+R alike")
        if model.animation is not None:
            notes.append("animated: pose + re-skin (+ re-tessellate for GS) counted in every frame")
        return {
            "model": model.name, "segments": n_rows, "relief": model.relief,
            "shadows": model.shadows, "animated": model.animation is not None,
            "ground": model.ground is not None,
            "camera": model.camera.to_dict(), "eval_camera": ecam.to_dict(),
            "reference_s": reference_s,
            "rc": entry("rc"), "rcr": entry(rcr_key),
            "gs": entry(f"gs:m={gs_level}") if gs_level is not None else None,
            "gs_level": gs_level, "gs_matched": gs_ok,
            "gsr": entry(f"gs+r:m={gsr_level}") if gsr_level is not None else None,
            "gsr_level": gsr_level, "gsr_matched": gsr_ok,
            "memory": memory, "curve": curve, "notes": notes,
        }
    finally:
        renderers.release()


def _save_images(directory: Path, model, ecam, refs, ref_dist, saved, table_keys):
    from PIL import Image

    directory.mkdir(parents=True, exist_ok=True)

    def grey(img):
        return Image.fromarray(np.clip(img * 255 + 0.5, 0, 255).astype(np.uint8))

    for relief, dist in ref_dist.items():
        tag = "reference_relief" if relief else "reference"
        grey(depth_shading(dist, ecam, model.light_dir)).save(directory / f"{model.name}_{tag}.png")
    for key in table_keys:
        res = saved.get(key)
        if res is None:
            continue
        tag = key.replace(":", "_").replace("=", "").replace("+", "p")
        Image.fromarray(res.color).save(directory / f"{model.name}_{tag}_color.png")
        grey(depth_shading(res.distance, ecam, model.light_dir)).save(
            directory / f"{model.name}_{tag}_shading.png")


# ---------------------------------------------------------------------------- the run
def machine_info() -> dict:
    from .render.context import gl_context, renderer_name

    ctx = gl_context()
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {"gl_renderer": renderer_name(), "gl_version": str(ctx.info.get("GL_VERSION", "")),
            "gl_vendor": str(ctx.info.get("GL_VENDOR", "")), "cpu": cpu, "cpus": os.cpu_count(),
            "platform": platform.platform(), "python": platform.python_version(),
            "numpy": np.__version__,
            "date_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}


def count_steps(opts: BenchOptions) -> int:
    """Progress steps of a run (an upper bound: reference, configurations, table timing)."""
    relief_cfgs = len(opts.linear_steps) + len(opts.binary_steps) + 1 + len(opts.levels)
    return len(opts.models) * (3 + len(opts.levels) + relief_cfgs)


def check_models(models) -> None:
    """Raise PlantgenError naming every model that is neither a shipped name nor a file."""
    from .pipeline import resolve_input

    missing = [str(m) for m in models if not resolve_input(m).is_file()]
    if missing:
        raise PlantgenError(f"no such model: {', '.join(missing)} (a shipped grammar/scene name "
                            f"such as {', '.join(TABLE1_MODELS[:3])}, or a path)")


def run_bench(opts: BenchOptions, progress=None, out_dir: str | Path | None = None) -> dict:
    """Run the bench over ``opts.models``; returns the JSON-ready results.

    progress : callable(label) called at each step (:func:`count_steps` of them at most)
    out_dir : where ``--images`` go (``out_dir/images``)
    """
    check_models(opts.models)
    t0 = time.perf_counter()
    info = machine_info()
    images_dir = Path(out_dir) / "images" if (opts.images and out_dir is not None) else None
    models = []
    for name in opts.models:
        models.append(bench_model(name, opts, progress, images_dir))
    return {"machine": info, "options": {k: (list(v) if isinstance(v, tuple) else v)
                                         for k, v in asdict(opts).items()},
            "models": models, "wall_s": time.perf_counter() - t0}


# ---------------------------------------------------------------------------- outputs
def _fmt_fps(e) -> str:
    return "–" if e is None else f"{e['fps']:.1f}"


def _level(level, ok) -> str:
    return "–" if level is None else (str(level) if ok else f">{level}")


def rcr_over_gsr(m: dict):
    """RC+R fps over GS+R fps (the ratio column), None if either is missing."""
    if m.get("rcr") and m.get("gsr"):
        return m["rcr"]["fps"] / m["gsr"]["fps"]
    return None


def markdown_table(results: dict) -> str:
    """Table 1 beside the paper's, with errors, the ratio column and the memory table."""
    info = results["machine"]
    o = results["options"]
    lines = [f"# plantgen bench: Table 1 on {info['gl_renderer']}", "",
             f"{info['date_utc']} · GL {info['gl_version']} · {info['cpu']} ({info['cpus']} CPUs) · "
             f"{o['size'][0]}x{o['size'][1]} · median of {o['frames']} frames after a warm-up "
             f"(curves: {o['curve_frames']}) · "
             f"run took {results['wall_s']:.0f} s" + (" · QUICK run" if o.get("quick") else ""), "",
             "fps = 1000 / median frame time (draw to glFinish). err = (1 - SSIM) + silhouette "
             f"mismatch against the float64 reference in a {o['eval_size'][0]}x{o['eval_size'][1]} "
             "window at full angular resolution. Level m: smallest m with err <= "
             f"RC err·(1 + {o['rel_tol']}) + {o['abs_tol']} (GS vs RC, GS+R vs RC+R); '>m': "
             "none qualified, best measured shown. RC+R/GS+R: fps ratio of the Table 1 run, where "
             "all four methods run the scene's passes (shadow map and ground where it lists "
             "shadows; pose and re-skin, and re-tessellation for GS, in every frame of an "
             "animated scene). Paper: 8800 GTX, 2009.", "",
             "| model | segments (paper) | RC fps (paper) | RC err | RC+R fps (paper) | RC+R err | "
             "GS fps / m (paper) | GS err | GS+R fps / m (paper) | GS+R err | RC+R/GS+R ours | "
             "paper |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for m in results["models"]:
        p = PAPER_TABLE1.get(m["model"])
        ps = (lambda i: f" ({p[i]})" if p else "")
        pgs = f" ({p[3][0]} / {p[3][1]})" if p else ""
        pgsr = f" ({p[4][0]} / {p[4][1]})" if p else ""
        err = (lambda e: "–" if e is None else f"{e['error']:.3f}")
        ratio = rcr_over_gsr(m)
        paper_ratio = p[2] / p[4][0] if p else None
        lines.append(
            f"| {m['model']} | {m['segments']:,}{ps(0)} | {_fmt_fps(m['rc'])}{ps(1)} | {err(m['rc'])} | "
            f"{_fmt_fps(m['rcr'])}{ps(2)} | {err(m['rcr'])} | "
            f"{_fmt_fps(m['gs'])} / {_level(m['gs_level'], m['gs_matched'])}{pgs} | {err(m['gs'])} | "
            f"{_fmt_fps(m['gsr'])} / {_level(m['gsr_level'], m['gsr_matched'])}{pgsr} | {err(m['gsr'])} | "
            f"{'–' if ratio is None else f'{ratio:.2f}'} | "
            f"{'–' if paper_ratio is None else f'{paper_ratio:.2f}'} |")
    lines += ["", "## Memory on the GPU (§4: relief-mapped frusta vs polygons)", "",
              "| model | RC records B | relief maps B | GS B (m) | GS/RC | GS+R B (m) | GS+R / RC+R | paper |",
              "|---|---|---|---|---|---|---|---|"]
    for m in results["models"]:
        mem = m["memory"]
        f = (lambda v: "–" if v is None else f"{v:,}")
        r = (lambda v: "–" if v is None else f"{v:.1f}x")
        lines.append(f"| {m['model']} | {mem['rc_bytes']:,} | {mem['relief_map_bytes']:,} | "
                     f"{f(mem['gs_bytes'])} ({_level(m['gs_level'], m['gs_matched'])}) | {r(mem['gs_over_rc'])} | "
                     f"{f(mem['gsr_bytes'])} ({_level(m['gsr_level'], m['gsr_matched'])}) | "
                     f"{r(mem['gsr_over_rcr'])} | {PAPER_MEMORY_RATIO:.0f}x |")
    notes = sorted({f"{m['model']}: {n}" for m in results["models"] for n in m["notes"] + _budget_notes(m)})
    if notes:
        lines += ["", "Notes:", *[f"- {n}" for n in notes]]
    return "\n".join(lines) + "\n"


def _budget_notes(model: dict) -> list[str]:
    """Notes for methods left unmatched (``>m``) whose finer levels were not built because
    they exceeded the triangle budget: the criterion did not fail there, the budget did."""
    notes = []
    for method, matched in (("GS", model.get("gs_matched")), ("GS+R", model.get("gsr_matched"))):
        skipped = [c for c in model["curve"] if c["method"] == method and "skipped" in c]
        if skipped and not matched:
            levels = ", ".join(str(c["value"]) for c in skipped)
            notes.append(f"{method} m = {levels} not built: {skipped[0]['skipped']} (--max-triangles)")
    return notes


TABLE_FIELDS = ["model", "segments", "rc_fps", "rc_ms", "rc_error", "rcr_fps", "rcr_ms", "rcr_error",
                "gs_fps", "gs_ms", "gs_level", "gs_matched", "gs_error", "gsr_fps", "gsr_ms",
                "gsr_level", "gsr_matched", "gsr_error", "rcr_over_gsr",
                "paper_segments",
                "paper_rc_fps", "paper_rcr_fps", "paper_gs_fps", "paper_gs_sub", "paper_gsr_fps",
                "paper_gsr_sub", "paper_rcr_over_gsr", "rc_bytes", "rcr_bytes", "gs_bytes",
                "gsr_bytes", "shadows", "animated", "gl_renderer"]
CURVE_FIELDS = ["model", "method", "knob", "value", "ms", "fps", "error", "dssim", "silhouette",
                "triangles", "gpu_bytes", "pareto", "skipped"]


def table_rows(results: dict) -> list[dict]:
    rows = []
    for m in results["models"]:
        p = PAPER_TABLE1.get(m["model"])
        row = {"model": m["model"], "segments": m["segments"], "shadows": m["shadows"],
               "animated": m["animated"], "gl_renderer": results["machine"]["gl_renderer"],
               "gs_level": m["gs_level"], "gs_matched": m["gs_matched"],
               "gsr_level": m["gsr_level"], "gsr_matched": m["gsr_matched"],
               "rcr_over_gsr": rcr_over_gsr(m)}
        for k in ("rc", "rcr", "gs", "gsr"):
            e = m[k]
            row[f"{k}_fps"] = e["fps"] if e else None
            row[f"{k}_ms"] = e["ms"] if e else None
            row[f"{k}_error"] = e["error"] if e else None
        for k in ("rc_bytes", "rcr_bytes", "gs_bytes", "gsr_bytes"):
            row[k] = m["memory"][k]
        if p:
            row.update(paper_segments=p[0], paper_rc_fps=p[1], paper_rcr_fps=p[2],
                       paper_gs_fps=p[3][0], paper_gs_sub=p[3][1], paper_gsr_fps=p[4][0],
                       paper_gsr_sub=p[4][1], paper_rcr_over_gsr=p[2] / p[4][0])
        rows.append(row)
    return rows


#: The two families of the accuracy curves: each is measured against its own reference
#: (analytic cones, or the relief surface), so each has its own Pareto front.
FAMILIES = {"plain": ("RC", "GS"), "relief": ("RC+R", "GS+R")}
#: Error levels at which :func:`winners` names the fastest configuration.
QUALITY_LEVELS = (0.3, 0.1, 0.03, 0.01, 0.003)


def _family_points(model: dict, family: str) -> list[dict]:
    return [c for c in model["curve"] if "error" in c and c["method"] in FAMILIES[family]]


def curve_rows(results: dict) -> list[dict]:
    """Every measured configuration, with ``pareto`` True on its family's front."""
    rows = []
    for m in results["models"]:
        on_front = set()
        for family in FAMILIES:
            pts = _family_points(m, family)
            if pts:
                on_front |= {id(pts[i]) for i in pareto_front([c["ms"] for c in pts],
                                                              [c["error"] for c in pts])}
        for c in m["curve"]:
            row = {k: c.get(k) for k in CURVE_FIELDS if k in c}
            row.update(model=m["model"], pareto=(id(c) in on_front) if "error" in c else None)
            rows.append(row)
    return rows


def pareto_summary(results: dict) -> list[str]:
    """Per model and family: the Pareto front from fastest to most accurate."""
    lines = []
    for m in results["models"]:
        for family in FAMILIES:
            pts = _family_points(m, family)
            if not pts:
                continue
            front = pareto_front([c["ms"] for c in pts], [c["error"] for c in pts])
            steps = [f"{pts[i]['key']} ({pts[i]['ms']:.1f} ms, err {pts[i]['error']:.4f})" for i in front]
            lines.append(f"- **{m['model']}** ({family}): " + " → ".join(steps))
    return lines


def winners(results: dict) -> list[str]:
    """Markdown rows: per model and family, the fastest configuration whose error is at
    most each of :data:`QUALITY_LEVELS`."""
    head = "| model | family | " + " | ".join(f"err ≤ {q}" for q in QUALITY_LEVELS) + " |"
    lines = [head, "|" + "---|" * (2 + len(QUALITY_LEVELS))]
    for m in results["models"]:
        for family in FAMILIES:
            pts = _family_points(m, family)
            if not pts:
                continue
            cells = []
            for q in QUALITY_LEVELS:
                ok = [c for c in pts if c["error"] <= q]
                best = min(ok, key=lambda c: c["ms"]) if ok else None
                cells.append("–" if best is None else f"{best['key']} {best['ms']:.1f} ms")
            lines.append(f"| {m['model']} | {family} | " + " | ".join(cells) + " |")
    return lines


def _write_csv(path: Path, fields, rows) -> None:
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        for r in rows:
            writer.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in fields})


def plot_curves(results: dict, out_dir: Path) -> list[Path] | str:
    """Error against ms per frame, one PNG per model, Pareto front marked. Returns the
    paths, or a message when matplotlib (the ``bench`` extra) is missing."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return ("matplotlib is not installed: curves written as CSV only "
                "(install the extra: pip install 'plantgen[bench]')")
    written = []
    styles = {"GS": ("tab:blue", "o"), "GS+R": ("tab:orange", "s"), "RC": ("tab:green", "D"),
              "RC+R": ("tab:red", "^")}
    for m in results["models"]:
        families = [f for f in FAMILIES if _family_points(m, f)]
        if not families:
            continue
        fig, axes = plt.subplots(1, len(families), figsize=(6.5 * len(families), 4.5), dpi=110,
                                 squeeze=False)
        for ax, family in zip(axes[0], families):
            pts = _family_points(m, family)
            series = {}
            for c in pts:
                label = c["method"] if c["knob"] in ("", "m") else f"{c['method']} {c['knob']}"
                series.setdefault(label, []).append(c)
            for label, cs in series.items():
                color, marker = styles[label.split(" ")[0]]
                if label.endswith("binary"):
                    marker, color = "v", "tab:purple"
                elif label.endswith(" v"):
                    marker, color = "*", "tab:brown"
                cs = sorted(cs, key=lambda c: c["ms"])
                ax.plot([c["ms"] for c in cs], [max(c["error"], 1e-6) for c in cs], marker=marker,
                        color=color, linestyle="-" if len(cs) > 1 else "none", label=label, alpha=0.8)
                for c in cs:
                    ax.annotate(str(c["value"]), (c["ms"], max(c["error"], 1e-6)), fontsize=6,
                                textcoords="offset points", xytext=(3, 3))
            front = pareto_front([c["ms"] for c in pts], [c["error"] for c in pts])
            ax.step([pts[i]["ms"] for i in front], [max(pts[i]["error"], 1e-6) for i in front],
                    where="post", color="black", linewidth=1.2, linestyle="--", label="Pareto front")
            ax.scatter([pts[i]["ms"] for i in front], [max(pts[i]["error"], 1e-6) for i in front],
                       s=80, facecolors="none", edgecolors="black")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("ms per frame (median, %dx%d)" % tuple(results["options"]["size"]))
            ax.set_ylabel("error: (1 - SSIM) + silhouette mismatch (floor 1e-6)")
            ax.set_title(f"{m['model']}, {'relief' if family == 'relief' else 'no relief'}: "
                         "error vs time", fontsize=9)
            ax.legend(fontsize=7)
            ax.grid(True, which="both", alpha=0.3)
        fig.suptitle(results["machine"]["gl_renderer"] + " · " + results["machine"]["date_utc"], fontsize=8)
        path = out_dir / f"curves_{m['model']}.png"
        fig.tight_layout()
        fig.savefig(path)
        plt.close(fig)
        written.append(path)
    return written


def write_outputs(results: dict, out_dir: str | Path) -> dict:
    """Write ``table.md``, ``table1.csv``, ``curves.csv``, ``results.json`` and the curve
    plots into ``out_dir``; returns {"markdown": text, "files": [...], "plots": message}."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    md = markdown_table(results)
    summary = pareto_summary(results)
    md_full = md
    if summary:
        md_full += ("\n## Who wins at which quality (fastest configuration under each error; "
                    "curves, no shadows)\n\n" + "\n".join(winners(results)) + "\n"
                    "\n## Pareto front per model (fastest → most accurate)\n\n"
                    + "\n".join(summary) + "\n")
    files = []
    (out / "table.md").write_text(md_full)
    files.append(out / "table.md")
    _write_csv(out / "table1.csv", TABLE_FIELDS, table_rows(results))
    files.append(out / "table1.csv")
    _write_csv(out / "curves.csv", CURVE_FIELDS, curve_rows(results))
    files.append(out / "curves.csv")
    with open(out / "results.json", "w") as fh:
        json.dump(results, fh, indent=1, default=_json_default)
    files.append(out / "results.json")
    plots = plot_curves(results, out)
    message = plots if isinstance(plots, str) else None
    if not isinstance(plots, str):
        files += plots
    return {"markdown": md_full, "files": files, "plots": message}


def _json_default(obj):
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, io.IOBase):
        return None
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")
