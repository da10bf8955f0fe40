"""Ray tracing through the BVH (``render --method rt``; with relief, RT+R).

The ray caster (:mod:`plantgen.gl.raycast`) rasterises one bounding pyramid per row and
casts the pixel's ray against that row: its cost grows with the rows drawn. The ray
tracer draws one full-screen triangle whose fragments trace their pixel's ray through a
bounding volume hierarchy (:mod:`plantgen.geometry.rays.bvh`, searched by ``shaders/bvh.glsl``,
uploaded by :mod:`plantgen.gl.trace`): a ray costs about the log of the rows. The row it
finds is hit and shaded by the ray caster's own code (``shaders/row.glsl``), so the two
methods show the same surfaces.

Everything else of the frame is the ray caster's: the sky, the ground, the leaves
(rasterised after the rows, depth-tested against them), read-back, supersampling. With
shadows, nothing is drawn into a map: every receiver (rows, ground, leaves) asks a shadow
ray towards the light whether anything of the BVH (rows, with relief their relief
surface, and the leaves' triangles) lies in its way (``SHADOW_RAYS`` in
``shaders/shadow.glsl``). The ground casts no shadow here (it lies under everything it
could shade).

An instanced scene (:class:`~plantgen.geometry.rays.instances.PlacedPlants`) is traced with
two levels: each distinct plant's BVH once, a top level over the copies; its leaves (world
polygons) are one more "plant" placed once. The BVH is built once per model (kept while
the same objects are rendered) and uploaded relative to the eye.

Animation (``refit``): a frame's rows (posed and skinned on the CPU) replace the last
frame's; where they are as many (rows and leaf triangles), the BVH is not rebuilt but
refitted (:func:`~plantgen.geometry.rays.bvh.refit_bvh`: the same tree, every box recomputed
from the posed rows' boxes bottom up, in numpy) and uploaded again with the rows. The
refit is done on the CPU, not on the GPU from the records a pose program writes
(:mod:`plantgen.gl.pose`): a row's box (relief shell and oblique ends,
:func:`~plantgen.geometry.rays.reference.row_boxes`) rounded outward has no GLSL twin yet, and
the frame's float64 rows are what a refit from the float64 boxes needs to lose no ray.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..errors import PlantgenError
from ..geometry.rays.bvh import TOP_LEAF_SIZE, build_bvh, build_scene_bvh, copy_boxes, refit_bvh
from ..geometry.rays.instances import PlacedPlants
from ..geometry.rays.reference import row_boxes
from .frame import FrameLighting, FrameView
from .passes import frame_passes
from .raycast import Raycaster
from .shaders import build_program, set_uniforms
from .trace import GPU_LEAF_SIZE, GpuPlant, upload_bvh

__all__ = ["RayTracer", "leaf_triangles", "SHADOW_RAY_OFFSET", "choose_method", "RT_ROWS_PER_PIXEL",
           "RT_PLACED_PER_DISTINCT"]

#: Pixel footprints a shadow ray starts off its receiver's surface (along the receiver's
#: normal on the light's side): more than the rounding of a hit and the relief march's
#: final bracket (``march_precision``, a fraction of a footprint).
SHADOW_RAY_OFFSET = 1.0

#: ``method="auto"``: placed rows a traced ray (pixel times supersamples) from which RT's
#: frame beats RC's. RC pays about 1.2 µs of llvmpipe a placed row, RT a walk a pixel:
#: measured (llvmpipe, 2 cores, 512x384 and 1024x768) RC and RT even at 0.086 and 0.111
#: rows a pixel (the pine; the forest cut to 19 copies), RT 2.3-3.1x faster at 0.40-0.45,
#: RC 2-11x faster at 0.002-0.03 (single plants). docs/benchmarks/rt.md, "Which method".
RT_ROWS_PER_PIXEL = 0.15
#: ``method="auto"``: placed rows a distinct row, times the draws, from which RT's BVH
#: build (360-690 ms over the forest's 82,499 distinct rows, paid before the first frame)
#: is repaid by RC's rows (about 1.2 µs a placed row a frame): measured, a still of the
#: forest cut to 48 copies (3.8 placed rows a distinct one) is faster with RC, of 136
#: copies (9.6) with RT at 512x384 (docs/benchmarks/rt.md, "Which method").
RT_PLACED_PER_DISTINCT = 8.0


def choose_method(method: str, *, placed_rows: int, distinct_rows: int, pixels: int, lod_pixels: float = 0.0,
                  animated: bool = False, labels: bool = False, draws: int = 1) -> str:
    """The method a frame is drawn with: ``method`` itself unless it is ``"auto"``. Auto
    takes the ray tracer ("rt") for a still, in colour, of an instanced scene drawn at full
    detail (``lod_pixels`` 0; a level of detail is RC's, cheaper at the error it states)
    whose ``placed_rows`` are at least :data:`RT_ROWS_PER_PIXEL` a traced ray (``pixels``)
    and, times the ``draws`` the BVH serves (a warm-up and the timed frames), at least
    :data:`RT_PLACED_PER_DISTINCT` times its ``distinct_rows`` (what the BVH is built
    over); else the ray caster ("rc"), which is faster there (the measurements above)."""
    if method != "auto":
        return method
    if animated or labels or lod_pixels > 0 or distinct_rows <= 0:
        return "rc"
    many = (placed_rows >= RT_ROWS_PER_PIXEL * pixels
            and placed_rows * max(int(draws), 1) >= RT_PLACED_PER_DISTINCT * distinct_rows)
    return "rt" if many else "rc"


#: The defines of RaycastSettings that the traced rows' programs take.
_ROW_DEFINES = ("RELIEF", "V_EXACT", "MARCH_FIXED", "HEIGHT_FETCH4")


def leaf_triangles(leaves) -> np.ndarray:
    """(t, 3, 3) float64 world triangles of a Polygons (none: (0, 3, 3))."""
    if leaves is None or not len(leaves.triangles):
        return np.zeros((0, 3, 3))
    return np.asarray(leaves.vertices, np.float64)[np.asarray(leaves.triangles)]


def _triangle_boxes(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boxes of triangles padded for rounding (as the scan's)."""
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    pad = 1e-9 * np.maximum(np.abs(lo), np.abs(hi)).max(axis=1, keepdims=True) + 1e-12
    return lo - pad, hi + pad


class RayTracer(Raycaster):
    """Renders Frusta or a PlacedPlants by tracing each pixel's ray through a BVH (module
    docstring); the same ``render`` arguments as :class:`Raycaster` but for GPU-posed
    frames (``record_buffer``), work counts and labels, which stay the ray caster's. The
    shadow knobs of the map (resolution, caster, its march) do not apply: a shadow ray
    meets what the eye's rays meet (with relief, the relief surface).

    ``leaf_size``, ``method``: the BVH's build knobs (:func:`plantgen.geometry.rays.bvh.build_bvh`);
    ``shadow_ray_offset``: pixel footprints a shadow ray starts off its surface; ``refit``:
    rows (Frusta) as many as the last ones drawn refit their BVH instead of building
    another (an animation's frames, module docstring).
    """

    def __init__(self, ctx=None, limits=None, *, leaf_size: int = GPU_LEAF_SIZE, method: str = "lbvh",
                 shadow_ray_offset: float = SHADOW_RAY_OFFSET, refit: bool = False):
        super().__init__(ctx, limits)
        self.leaf_size, self.method, self.refit = leaf_size, method, bool(refit)
        self.refits = 0          # BVHs refitted (not built) so far
        self.shadow_ray_offset = float(shadow_ray_offset)
        self._built = None       # (model, leaves, plants, top, matrices, copy_plant)
        self._gpu = None         # (model, leaves, eye, GpuBvh)
        self._frame = None       # the frame being rendered: model, leaves, settings
        #: milliseconds of the last BVH build (0 when kept) and upload
        self.last_build_ms = 0.0
        self.last_upload_ms = 0.0

    def release(self) -> None:
        if self._gpu is not None:
            self._gpu[3].release()
            self._gpu = None
        super().release()

    # ------------------------------------------------------------------ the BVH
    def _build(self, model, leaves):
        """The BVH of ``model`` (Frusta or PlacedPlants) and ``leaves`` (world Polygons or
        None), built once per pair of objects."""
        if self._built is not None and self._built[0] is model and self._built[1] is leaves:
            self.last_build_ms = 0.0
            return self._built[2:]
        t0 = time.perf_counter()
        tri = leaf_triangles(leaves)
        build = {"leaf_size": self.leaf_size, "method": self.method}
        if isinstance(model, PlacedPlants):
            scene = build_scene_bvh(model, **build)
            plants = [GpuPlant(p.frusta, None, b) for p, b in zip(model.plants, scene.blas, strict=True)]
            top, matrices, copy_plant = scene.tlas, scene.matrix, scene.plant
            if len(tri):      # the leaves: one more plant, placed once where they are
                t_lo, t_hi = _triangle_boxes(tri)
                bvh = build_bvh(t_lo, t_hi, **build)
                plants.append(GpuPlant(None, tri, bvh))
                c_lo, c_hi = copy_boxes(bvh.lo[0], bvh.hi[0], np.eye(4)[None])
                top = build_bvh(np.concatenate([scene.copy_lo, c_lo]), np.concatenate([scene.copy_hi, c_hi]),
                                leaf_size=TOP_LEAF_SIZE, method=self.method)
                matrices = np.concatenate([matrices, np.eye(4)[None]])
                copy_plant = np.r_[copy_plant, len(plants) - 1]
        else:
            lo, hi = row_boxes(model, shell=True) if len(model) else (np.zeros((0, 3)), np.zeros((0, 3)))
            if len(tri):
                t_lo, t_hi = _triangle_boxes(tri)
                lo, hi = np.concatenate([lo, t_lo]), np.concatenate([hi, t_hi])
            last = self._built[2][0] if self._built is not None and self._built[3] is None else None
            if self.refit and last is not None and last.rows == len(model) and len(last.bvh.prims) == len(lo):
                bvh = refit_bvh(last.bvh, lo, hi)        # an animation's next frame: the same rows moved
                self.refits += 1
            else:
                bvh = build_bvh(lo, hi, **build)
            plants = [GpuPlant(model if len(model) else None, tri, bvh)]
            top = matrices = copy_plant = None
        self._built = (model, leaves, plants, top, matrices, copy_plant)
        self.last_build_ms = (time.perf_counter() - t0) * 1e3
        return self._built[2:]

    def gpu_bvh(self, model, leaves, eye):
        """The uploaded BVH of ``model`` and ``leaves`` relative to ``eye`` (kept while all
        three stay the same)."""
        eye = np.asarray(eye, np.float64)
        g = self._gpu
        if g is not None and g[0] is model and g[1] is leaves and np.array_equal(g[2], eye):
            self.last_build_ms = self.last_upload_ms = 0.0
            return g[3]
        plants, top, matrices, copy_plant = self._build(model, leaves)
        t0 = time.perf_counter()
        if g is not None:
            g[3].release()
            self._gpu = None
        gpu = upload_bvh(self.ctx, plants, eye, top=top, matrices=matrices, copy_plant=copy_plant,
                         max_bytes=self.limits.max_render_bytes)
        self._gpu = (model, leaves, eye.copy(), gpu)
        self.last_upload_ms = (time.perf_counter() - t0) * 1e3
        return gpu

    # ------------------------------------------------------------------ the frame
    def render(self, frusta, camera, settings=None, material_names=("bark",), light_dir=None, ground=None, *,
               shadows=None, shadow_box=None, record_buffer=None, count_work: bool = False, background=None,
               ssaa: int = 1, leaves=None, leaf_labels=None, lod_pixels: float = 0.0):
        """Trace ``frusta`` (Frusta or PlacedPlants) as seen by ``camera``: the arguments of
        :meth:`Raycaster.render` (``lod_pixels`` is ignored: every row is traced)."""
        from ..settings import RaycastSettings

        settings = settings if settings is not None else RaycastSettings()
        if record_buffer is not None or count_work or settings.labels or settings.proxy != "pyramid":
            raise PlantgenError("the ray tracer renders still frusta in colour: GPU-posed frames, work counts, "
                                "labels and proxies are the ray caster's (--method rc)")
        gpu = self.gpu_bvh(frusta, leaves, camera.eye)
        tex, repeats = self._heights.get(tuple(material_names))
        self._frame = {"gpu": gpu, "settings": settings, "tex": tex, "repeats": repeats}
        try:
            result = super().render(frusta, camera, settings, material_names, light_dir, ground, shadows=shadows,
                                    shadow_box=shadow_box, background=background, ssaa=ssaa, leaves=leaves,
                                    leaf_labels=leaf_labels)
        finally:
            self._frame = None
        stats = replace(result.stats, program=("rt.glsl", self._defines(settings, shadows, gpu)),
                        passes=frame_passes(False, ground is not None, len(frusta) > 0,
                                            leaves is not None and len(leaves.triangles) > 0),
                        upload_bytes=gpu.nbytes if self.last_upload_ms else 0)
        return replace(result, stats=stats)

    @staticmethod
    def _defines(settings, shadows, gpu) -> dict:
        defines = {k: v for k, v in settings.defines().items() if k in _ROW_DEFINES}
        return {**defines, **gpu.defines(), "SHADOWS": shadows is not None,
                "SHADOW_RAYS": shadows is not None}

    def _programs(self, settings, shadows, ground: bool, count_work: bool = False, flat_background: bool = False,
                  leaves: bool = False) -> dict:
        frame = self._frame
        defines = self._defines(settings, shadows, frame["gpu"])
        receivers = {k: v for k, v in defines.items() if k != "SHADOWS"} if shadows is not None else {}
        variants = [("sky.glsl", {"FLAT_BACKGROUND": True} if flat_background else {})]
        if ground:
            variants.append(("ground.glsl", {"SHADOWS": shadows is not None, **receivers,
                                             "FLAT_BACKGROUND": flat_background}))
        variants.append(("rt.glsl", defines))
        if leaves:
            variants.append(("leaf.glsl", {"SHADOWS": shadows is not None, "LABELS": False, **receivers}))
        built = [(name, tuple(sorted(k for k, v in d.items() if v))) for name, d in variants]
        self.programs_used.update(built)
        for name, d in variants:
            build_program(self.ctx, name, d)
        return {"frame": build_program(self.ctx, "rt.glsl", defines), "light": None, "built": built}

    def _lighting(self, material_names, ground, light_dir, shadows, caster_box, eye, anchor=None) -> FrameLighting:
        base = super()._lighting(material_names, ground, light_dir, None, caster_box, eye, anchor)
        frame = self._frame
        if shadows is None or frame is None:
            return base
        settings = frame["settings"]
        defines = self._defines(settings, shadows, frame["gpu"])
        receiver = {"shadow_ray_offset": self.shadow_ray_offset, "texture_repeat": frame["repeats"],
                    **self._march(settings)}
        return replace(base, receiver=receiver,
                       receiver_defines={k: v for k, v in defines.items() if k != "SHADOWS"})

    @staticmethod
    def _march(settings) -> dict:
        return {k: v for k, v in settings.march_uniforms().items() if k != "hull_padding"}

    def _surroundings(self, ground, leaves, view: FrameView, lighting: FrameLighting, *, labels=None,
                      background=None):
        if lighting.receiver_defines:
            lighting = replace(lighting, receiver={**lighting.receiver, "pixel_footprint": view.pixel_footprint()})
        out = super()._surroundings(ground, leaves, view, lighting, labels=labels, background=background)
        frame = self._frame
        if frame is not None:
            out.before.insert(0, self._bind)        # the BVH and heights for every receiver
        return out

    def _bind(self) -> None:
        frame = self._frame
        frame["tex"].use(0)
        frame["gpu"].bind()

    def _frusta_draw(self, program, view: FrameView, lighting: FrameLighting, settings, rec_buf, repeats, tex,
                     n: int, lod_pixels: float = 0.0):
        set_uniforms(program, **{**view.ray_uniforms(), **lighting.shading, **lighting.receiver,
                                 **self._march(settings), "texture_repeat": repeats,
                                 "pixel_footprint": view.pixel_footprint(),
                                 "depth_coeffs": (view.projection[2, 2], view.projection[2, 3])})
        frame = self._frame
        if not n or frame["gpu"].empty:
            return (lambda: None), [], 0
        ctx = self.ctx
        vao = ctx.vertex_array(program, [])

        def draw():
            self._bind()
            ctx.disable(ctx.CULL_FACE)
            ctx.enable(ctx.DEPTH_TEST)
            vao.render(mode=ctx.TRIANGLES, vertices=3)
        return draw, [vao], n

    def _light_pass(self, *args, **kwargs):
        return None      # shadow rays: no map
