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

from dataclasses import replace

from ..errors import PlantgenError
from .bvh_cache import leaf_triangles
from .frame import FrameLighting, FrameView
from .passes import frame_passes, look_defines, traced_look
from .raycast import Raycaster
from .shaders import build_program, set_uniforms
from .trace import GPU_LEAF_SIZE

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

    casts_thin_rows = False

    def __init__(self, ctx=None, limits=None, *, leaf_size: int = GPU_LEAF_SIZE, method: str = "lbvh",
                 shadow_ray_offset: float = SHADOW_RAY_OFFSET, refit: bool = False):
        super().__init__(ctx, limits)
        self.leaf_size, self.method, self.refit = leaf_size, method, bool(refit)
        self.shadow_ray_offset = float(shadow_ray_offset)
        self._frame = None       # the frame being rendered: model, leaves, settings

    # ------------------------------------------------------------------ the frame
    def render(self, frusta, camera, settings=None, material_names=("bark",), light_dir=None, ground=None, *,
               shadows=None, shadow_box=None, record_buffer=None, count_work: bool = False, background=None,
               ssaa: int = 1, leaves=None, leaf_labels=None, lod_pixels: float = 0.0, aa: str = "none"):
        """Trace ``frusta`` (Frusta or PlacedPlants) as seen by ``camera``: the arguments of
        :meth:`Raycaster.render` (``lod_pixels`` is ignored: every row is traced; ``aa``
        ``"edges"`` smooths the edges, but no row is cast at the floor radius: the BVH's
        boxes hold the rows' own radii, :attr:`casts_thin_rows`)."""
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
                                    leaf_labels=leaf_labels, aa=aa)
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

    def _sky_bvh(self, settings, frusta, leaves, camera, record_buffer=None):
        frame = self._frame
        return frame["gpu"] if frame is not None and settings.look.sky and not frame["gpu"].empty else None

    def _programs(self, settings, shadows, ground: bool, count_work: bool = False, flat_background: bool = False,
                  leaves: bool = False, bvh_defines: dict | None = None, thin_rows: bool = False) -> dict:
        frame = self._frame
        defines = self._defines(settings, shadows, frame["gpu"])
        receivers = {k: v for k, v in defines.items() if k != "SHADOWS"} if shadows is not None else {}
        look, shadowed = settings.look, shadows is not None
        variants = [("sky.glsl", {"FLAT_BACKGROUND": True} if flat_background else look_defines(look, "sky.glsl"))]
        if ground:
            variants.append(("ground.glsl", {"SHADOWS": shadowed, **receivers, "FLAT_BACKGROUND": flat_background,
                                             **traced_look(look, "ground.glsl", shadowed, bvh_defines)}))
        defines = {**defines, **traced_look(look, "rt.glsl", shadowed, bvh_defines)}
        variants.append(("rt.glsl", defines))
        if leaves:
            variants.append(("leaf.glsl", {"SHADOWS": shadowed, "LABELS": False, **receivers,
                                           **traced_look(look, "leaf.glsl", shadowed, bvh_defines)}))
        built = [(name, tuple(sorted(k for k, v in d.items() if v))) for name, d in variants]
        self.programs_used.update(built)
        for name, d in variants:
            build_program(self.ctx, name, d)
        return {"frame": build_program(self.ctx, "rt.glsl", defines), "thin": None, "light": None, "built": built}

    def _lighting(self, material_names, ground, light_dir, shadows, caster_box, eye, anchor=None,
                  look=None) -> FrameLighting:
        base = super()._lighting(material_names, ground, light_dir, None, caster_box, eye, anchor, look)
        frame = self._frame
        if shadows is None or frame is None:
            return base
        settings = frame["settings"]
        defines = self._defines(settings, shadows, frame["gpu"])
        receiver = {"shadow_ray_offset": self.shadow_ray_offset, "texture_repeat": frame["repeats"],
                    **self._march(settings), **(look.sun_uniforms() if look is not None and look.sun_angle > 0 else {})}
        return replace(base, receiver=receiver,
                       receiver_defines={k: v for k, v in defines.items() if k != "SHADOWS"})

    @staticmethod
    def _march(settings) -> dict:
        return {k: v for k, v in settings.march_uniforms().items() if k != "hull_padding"}

    def _surroundings(self, ground, leaves, view: FrameView, lighting: FrameLighting, *, labels=None,
                      background=None, coverage_floor: float = 0.0):
        if lighting.receiver_defines:
            lighting = replace(lighting, receiver={**lighting.receiver, "pixel_footprint": view.pixel_footprint()})
        out = super()._surroundings(ground, leaves, view, lighting, labels=labels, background=background,
                                    coverage_floor=coverage_floor)
        frame = self._frame
        if frame is not None:
            out.before.insert(0, self._bind)        # the BVH and heights for every receiver
        return out

    def _bind(self) -> None:
        frame = self._frame
        frame["tex"].use(0)
        frame["gpu"].bind()

    def _frusta_draw(self, program, view: FrameView, lighting: FrameLighting, settings, rec_buf, repeats, tex,
                     n: int, lod_pixels: float = 0.0, thin_rows: bool = False):
        set_uniforms(program, **{**view.ray_uniforms(), **lighting.shading, **lighting.receiver, **lighting.sky,
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
