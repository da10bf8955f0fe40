"""Raster renderer for tessellated frusta (GS, GS+R), the polygonal side of Table 1.

A :class:`~plantgen.geometry.mesh.TessellatedMesh` is uploaded once (float32 positions
relative to the mesh's own origin, normals, texture coordinates, uint32 indices) and
drawn with one indexed draw call, back faces culled (the mesh is closed). The camera,
light, material palette, height maps and shading code are the ray caster's
(:mod:`plantgen.render.raycast`, ``shaders/shading.glsl``), so an RC image and a GS image
of the same model differ only by geometry. The output is the ray caster's
:class:`~plantgen.render.raycast.RenderResult` (colour, distance along the ray, frame time).
"""

from __future__ import annotations

import time

import numpy as np

from ..geometry.camera import Camera
from ..geometry.mesh import TessellatedMesh
from .context import gl_context
from .passes import ShadowSettings, box_corners, frame_passes
from .raycast import (MAX_MATERIALS, RECORD_BYTES, OffscreenRenderer, RenderResult, _ground_quad,
                      _mat4, _set, _write, depth_range, material_palette, shading_uniforms)
from .shaders import build_program

__all__ = ["RasterRenderer", "render_mesh", "gs_buffer_bytes", "rc_buffer_bytes", "row_data"]

def row_data(frusta) -> np.ndarray:
    """(n, 2) float32 per frustum row: chain position, material (8 bytes a row).

    The chain position turns the mesh's texture v (which counts rows along a chain) back
    into the per-row v of (7) in the fragment shader.
    """
    out = np.zeros((len(frusta.length), 2), dtype=np.float32)
    out[:, 0] = frusta.chain_position
    out[:, 1] = frusta.material
    return out


def gs_buffer_bytes(mesh: TessellatedMesh) -> int:
    """GPU buffer bytes of a GS draw: vertices (32 B each), uint32 indices, 8 B per row,
    4 B per cap (height maps, shared with RC, are not counted)."""
    return mesh.buffer_bytes()["total"] + 8 * mesh.n_rows + 4 * mesh.n_caps


def rc_buffer_bytes(n_rows: int) -> int:
    """GPU buffer bytes of the ray caster's draw: one 96-byte record per row (the 8-corner,
    12-triangle pyramid template is shared by all rows and not counted)."""
    return RECORD_BYTES * int(n_rows)


class RasterRenderer(OffscreenRenderer):
    """Draws tessellated meshes into an offscreen framebuffer like the ray caster's."""

    def __init__(self, ctx=None):
        super().__init__(ctx)
        self._uploaded = None  # (mesh id, buffers, vao, origin)

    def release_mesh(self) -> None:
        """Free the uploaded mesh's buffers (the renderer stays usable)."""
        if self._uploaded is not None:
            for obj in self._uploaded[1]:
                obj.release()
            self._uploaded = None

    def release(self) -> None:
        """Free every GL object of this renderer: the mesh's buffers, the framebuffer, the
        height textures and the shadow map."""
        self.release_mesh()
        super().release()

    def upload(self, mesh: TessellatedMesh, frusta, program):
        """Upload ``mesh`` (once per mesh object); returns (vao, origin)."""
        key = (mesh, program)  # strong references: identity stays valid while cached
        if self._uploaded is not None and self._uploaded[0][0] is mesh and self._uploaded[0][1] is program:
            return self._uploaded[2], self._uploaded[3]
        self.release_mesh()
        ctx = self.ctx
        origin = mesh.vertices.mean(axis=0) if len(mesh.vertices) else np.zeros(3)
        # One interleaved buffer, 32 bytes a vertex: position, normal, uv (float32).
        interleaved = np.empty((len(mesh.vertices), 8), dtype=np.float32)
        interleaved[:, 0:3] = mesh.vertices - origin
        interleaved[:, 3:6] = mesh.normals
        interleaved[:, 6:8] = mesh.uv
        vbo = ctx.buffer(interleaved.tobytes())
        del interleaved
        ibo = ctx.buffer(np.ascontiguousarray(mesh.faces, np.uint32).tobytes())
        rows = ctx.buffer(row_data(frusta).tobytes())
        lateral = mesh.n_rows * 16 * 4 ** mesh.level
        cap_rows = mesh.face_row[lateral::_cap_tris(mesh)] if mesh.n_caps else np.zeros(1, np.int32)
        caps_buf = ctx.buffer(np.ascontiguousarray(cap_rows, np.int32).tobytes())
        vao = ctx.vertex_array(program, [(vbo, "3f 3f 2f", "position", "normal", "texcoord")],
                               index_buffer=ibo, index_element_size=4)
        self._uploaded = (key, (vbo, ibo, rows, caps_buf, vao), vao, origin)
        return vao, origin

    def render(self, mesh: TessellatedMesh, frusta, camera: Camera, *, material_names=None,
               light_dir=(0.45, 0.8, 0.35), ground: dict | None = None,
               shadows: ShadowSettings | None = None, shadow_box=None) -> RenderResult:
        """Rasterise ``mesh`` (tessellated from ``frusta``) as seen by ``camera``.

        Parameters
        ----------
        mesh : the tessellation (GS, or GS+R when made with ``relief=True``: displaced,
            with normals tilted as RC+R tilts them)
        frusta : the rows it was made from (materials, chains)
        camera : the view, as for the ray caster
        material_names : default ``mesh.material_names``
        light_dir : (3,) towards the light, as for the ray caster
        ground : optional ``{"size", "height", "material"}`` square, as for the ray caster
        shadows : None (no shadow pass) or the shadow map's knobs, as for the ray caster:
            the mesh and the ground first write their depth into the light's map
        shadow_box : (2, 3) world box the light's window must cover (default: the mesh's
            bounds), as for the ray caster
        """
        ctx = self.ctx
        names = tuple(material_names or mesh.material_names)
        width, height = camera.width, camera.height
        fbo = self._framebuffer(width, height)
        shadowed = shadows is not None
        defines = {"TRIANGLES_PER_ROW": 16 * 4 ** mesh.level, "SHADOWS": shadowed}
        program = build_program(ctx, "raster.glsl", defines)
        sky = build_program(ctx, "sky.glsl")
        t0 = time.perf_counter()
        vao, origin = self.upload(mesh, frusta, program)
        upload_s = time.perf_counter() - t0

        eye = np.asarray(camera.eye, dtype=np.float64)
        right, up, fwd = camera.basis()
        ground_quad = _ground_quad(ground) if ground else None
        bounds = _mesh_bounds(mesh)
        near, far = depth_range([box_corners(bounds)] + ([] if ground_quad is None else [ground_quad]),
                                eye, fwd)
        view = camera.view_matrix()
        view[:3, 3] = 0.0  # render origin: the eye
        view_projection = camera.projection_matrix(near, far) @ view
        tan_y = np.tan(np.radians(camera.fov_y) / 2)
        tex, repeats = self._height_texture(names)
        palette_names = names if ground_quad is None else names + (ground["material"],)
        palette = material_palette(palette_names)
        shading = shading_uniforms(light_dir)
        _set(sky, viewport=(float(width), float(height)), cam_forward=tuple(fwd),
             cam_right_scaled=tuple(right * tan_y * camera.aspect), cam_up_scaled=tuple(up * tan_y),
             **shading)
        box = None if not shadowed else (bounds if shadow_box is None else np.asarray(shadow_box, np.float64))
        window, receiver = self._light(shadows, box, light_dir, eye)
        _set(program, **shading, **receiver, view_projection=_mat4(view_projection),
             origin_from_eye=tuple((origin - eye).tolist()), n_rows=mesh.n_rows, height_maps=0)
        for key in ("dark", "light", "gloss"):
            _write(program, f"material_{key}", palette[key])
        _write(program, "texture_repeat", repeats)
        buffers = self._uploaded[1]
        buffers[2].bind_to_storage_buffer(0)
        buffers[3].bind_to_storage_buffer(1)
        sky_vao = ctx.vertex_array(sky, [])
        ground_vao = ground_light_draw = None
        extras = [sky_vao]
        if ground_quad is not None:
            ground_vao, ground_light_draw, objects = self._ground_draws(
                ground_quad, eye, view_projection, palette,
                min(len(palette_names) - 1, MAX_MATERIALS - 1), shading, receiver, window)
            extras += objects
        shadow_draws = []
        if shadowed:
            caster = build_program(ctx, "raster.glsl", {"SHADOW_PASS": True})
            _set(caster, view_projection=_mat4(window.matrix()),
                 origin_from_eye=tuple((origin - eye).tolist()))
            mesh_light_vao = ctx.vertex_array(caster, [(buffers[0], "3f 20x", "position")],
                                              index_buffer=buffers[1], index_element_size=4)
            extras.append(mesh_light_vao)

            def draw_mesh_depth():
                ctx.enable(ctx.CULL_FACE)
                ctx.front_face = "ccw"
                ctx.cull_face = "back"
                mesh_light_vao.render(mode=ctx.TRIANGLES, vertices=mesh.faces.size)
            shadow_draws.append(draw_mesh_depth)
            if ground_light_draw is not None:
                shadow_draws.append(ground_light_draw)

        ctx.finish()
        t_draw = time.perf_counter()
        shadow_ms = self._draw_shadow_map(shadows.resolution, shadow_draws) if shadowed else 0.0
        fbo.use()
        fbo.viewport = (0, 0, width, height)
        fbo.clear(depth=1.0)
        ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE | ctx.BLEND)
        sky_vao.render(mode=ctx.TRIANGLES, vertices=3)
        ctx.enable(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        if ground_vao is not None:
            ground_vao.render(mode=ctx.TRIANGLE_STRIP, vertices=4)
        ctx.enable(ctx.CULL_FACE)
        ctx.front_face = "ccw"
        ctx.cull_face = "back"
        tex.use(0)
        vao.render(mode=ctx.TRIANGLES, vertices=mesh.faces.size)
        ctx.finish()
        frame_ms = (time.perf_counter() - t_draw) * 1e3
        ctx.disable(ctx.DEPTH_TEST | ctx.CULL_FACE)
        for obj in extras:
            if obj is not None:
                obj.release()

        color = np.frombuffer(fbo.read(components=3, attachment=0, alignment=1), np.uint8)
        color = color.reshape(height, width, 3)[::-1].copy()
        dist = np.frombuffer(fbo.read(components=1, attachment=1, dtype="f4", alignment=1),
                             np.float32).reshape(height, width)[::-1].copy()
        stats = {"triangles": len(mesh.faces), "vertices": len(mesh.vertices), "level": mesh.level,
                 "buffer_bytes": gs_buffer_bytes(mesh), "upload_ms": upload_s * 1e3,
                 "near": near, "far": far, "draw_calls": 1 + (ground_vao is not None),
                 "passes": frame_passes(shadowed, ground_vao is not None, len(mesh.faces) > 0),
                 "shadow_ms": shadow_ms, "light_window": window}
        return RenderResult(color, dist, frame_ms, camera, stats)


def _cap_tris(mesh: TessellatedMesh) -> int:
    return 8 * 2 ** mesh.level


def _mesh_bounds(mesh: TessellatedMesh) -> np.ndarray:
    """(2, 3) world box of the mesh's vertices (a unit box at the origin when empty)."""
    if len(mesh.vertices) == 0:
        return np.array([[-0.5] * 3, [0.5] * 3])
    return np.stack([mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)])


_default: RasterRenderer | None = None


def render_mesh(mesh: TessellatedMesh, frusta, camera: Camera, *, material_names=None) -> RenderResult:
    """Render with the shared context's cached :class:`RasterRenderer`."""
    global _default
    ctx = gl_context()
    if _default is None or _default.ctx is not ctx:
        _default = RasterRenderer(ctx)
    return _default.render(mesh, frusta, camera, material_names=material_names)


def side_by_side(frusta, camera: Camera, *, gs_level: int = 2, gsr_level: int = 4,
                 material_names=("bark",), linear_steps: int = 64, binary_steps: int = 8) -> np.ndarray:
    """RC+R | GS | GS+R images of one model and camera, labelled, as one (h, 3w, 3) uint8 image.

    GS+R takes its heights from :mod:`plantgen.geometry.relief`, the maps the ray caster samples.
    """
    from PIL import Image, ImageDraw

    from ..geometry.mesh import tessellate
    from .raycast import RaycastSettings, Raycaster

    ctx = gl_context()
    rc = Raycaster(ctx).render(frusta, camera, RaycastSettings(relief=True, linear_steps=linear_steps,
                                                               binary_steps=binary_steps),
                               material_names)
    raster = RasterRenderer(ctx)
    gs_mesh = tessellate(frusta, gs_level, caps="tips")  # side branch bases sit unseen in parents
    gs = raster.render(gs_mesh, frusta, camera, material_names=material_names)
    gsr_mesh = tessellate(frusta, gsr_level, relief=True, caps="tips")
    gsr = raster.render(gsr_mesh, frusta, camera, material_names=material_names)
    raster.release()
    n = len(frusta.length)
    panels = [(rc.color, f"RC+R: {n:,} frusta, {rc_buffer_bytes(n):,} B"),
              (gs.color, f"GS m={gs_level}: {len(gs_mesh.faces):,} triangles, "
                         f"{gs_buffer_bytes(gs_mesh):,} B"),
              (gsr.color, f"GS+R m={gsr_level}: {len(gsr_mesh.faces):,} triangles, "
                          f"{gs_buffer_bytes(gsr_mesh):,} B")]
    image = Image.fromarray(np.concatenate([p[0] for p in panels], axis=1))
    draw = ImageDraw.Draw(image)
    for i, (_, label) in enumerate(panels):
        x = i * camera.width + 4
        draw.rectangle(draw.textbbox((x, 3), label), fill=(255, 255, 255))
        draw.text((x, 3), label, fill=(0, 0, 0))
    return np.asarray(image)


def main(argv=None) -> None:
    """``python -m plantgen.render.raster MODEL OUT.png``: the RC+R | GS | GS+R gallery image.

    The camera frames the model as ``Camera.auto`` does from direction (0.3, 0.1, 1), then
    moves ``--zoom`` of the way towards a target raised by ``--raise`` of the model height.
    """
    import argparse

    from PIL import Image

    from ..geometry.skin import skin_skeleton
    from ..pipeline import load_skeleton
    from .raycast import frusta_bounds

    parser = argparse.ArgumentParser(description=main.__doc__.splitlines()[0])
    parser.add_argument("model", help="grammar, scene or skeleton .npz")
    parser.add_argument("output")
    parser.add_argument("--gs", type=int, default=2, help="GS subdivision level")
    parser.add_argument("--gsr", type=int, default=4, help="GS+R subdivision level")
    parser.add_argument("--zoom", type=float, default=1.0, help="eye distance factor (< 1: closer)")
    parser.add_argument("--raise", dest="lift", type=float, default=0.0,
                        help="raise the target by this fraction of the model's extent")
    parser.add_argument("--size", type=int, nargs=2, default=(400, 400))
    args = parser.parse_args(argv)
    frusta = skin_skeleton(load_skeleton(args.model))
    box = frusta_bounds(frusta)
    full = Camera.auto(box, *args.size, direction=(0.3, 0.1, 1.0))
    target = np.asarray(full.target) + np.array([0.0, args.lift, 0.0]) * (box[1] - box[0])
    eye = target + (np.asarray(full.eye) - np.asarray(full.target)) * args.zoom
    camera = Camera(tuple(eye), tuple(target), (0.0, 1.0, 0.0), full.fov_y, *args.size)
    image = side_by_side(frusta, camera, gs_level=args.gs, gsr_level=args.gsr,
                         material_names=frusta.material_names)
    Image.fromarray(image).save(args.output)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
