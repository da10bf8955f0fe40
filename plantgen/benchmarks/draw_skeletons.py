"""Quick line drawings of grown skeletons: a look at each shipped model.

Run as ``python -m plantgen.benchmarks.draw_skeletons OUTDIR [NAME ...]``. For each
shipped grammar or scene (default: every ``*.yaml`` in the grammars directory) it grows
the default seed and writes ``OUTDIR/NAME.png``: three orthographic panels side by side,
front (x-y), side (z-y) and top (x-z), all at the same scale in metres. Each segment is
drawn as its projected outline (a trapezoid with the two end radii; a disc in the top view
for upright segments; a one-pixel line when thinner than that), coloured by material. Leaf
polygons (a grammar's ``{ . }``, a scene's plants' too) are filled triangles in their
material's colour (a leaf green for a material the drawing has no colour for), outlined
in a darker shade. Segments and
leaf triangles are painted together from far to near in each view, so a leaf in front of a
branch hides it and one behind it is hidden. A scale bar under the panels says how long one
metre is.

Pillow only (no matplotlib); one ``ImageDraw.polygon`` call per segment is fine for a
gallery script, which is not a hot path.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from .._resources import shipped_grammar
from ..geometry.meshes.polygons import Polygons
from ..geometry.skeletons.materials import PALETTE, material_colour
from ..geometry.skeletons.skeleton import Skeleton
from ..geometry.stage import Ground
from ..pipeline import grow_file
from .arguments import shipped_model_paths

__all__ = ["BACKGROUND", "LEAF_GREEN", "MATERIAL_COLOURS", "draw_skeleton", "leaf_colour", "main",
           "panel_projection"]

MATERIAL_COLOURS = {
    "bark": (110, 75, 45),
    "leaf": (60, 140, 50),
    "cactus": (70, 125, 70),
    "aloe": (120, 165, 110),
    "stone": (130, 130, 135),
}
_GROUND_COLOURS = {"sand": (215, 190, 130), "grass": (120, 170, 80)}
_UNKNOWN = (200, 40, 160)
#: Leaves of a material the drawing has no colour for (neither here nor in the renderers' palette).
LEAF_GREEN = MATERIAL_COLOURS["leaf"]
BACKGROUND = (245, 242, 232)
_MARGIN, _HEADER = 12, 22
_PANELS = (("front x-y", 0, 1, False), ("side z-y", 2, 1, False), ("top x-z", 0, 2, True))


def draw_skeleton(skeleton: Skeleton, title: str = "", panel_px: int = 420,
                  ground: Ground | None = None, polygons: Polygons | None = None) -> Image.Image:
    """Draw three orthographic projections of ``skeleton`` into one RGB image.

    Parameters
    ----------
    skeleton : the model, coordinates in metres, y up
    title : text written in the top-left corner
    panel_px : width and height of each panel in pixels
    ground : optional scene ground, drawn as a line or square
    polygons : optional leaf polygons in the same frame, their material indices into
        ``skeleton.material_names``; drawn filled, depth-sorted with the segments
    """
    margin, header, footer = _MARGIN, _HEADER, 26
    width = 3 * panel_px + 4 * margin
    img = Image.new("RGB", (width, panel_px + header + footer + margin), BACKGROUND)
    draw = ImageDraw.Draw(img)
    draw.text((margin, 4), title, fill=(0, 0, 0))
    leaves = polygons if polygons is not None and len(polygons.triangles) else None
    points = np.concatenate([skeleton.start, skeleton.end] + ([leaves.vertices] if leaves is not None else []))
    if len(points) == 0:
        return img
    for p, (label, ax_u, ax_v, top) in enumerate(_PANELS):
        x0, y0 = margin + p * (panel_px + margin), header
        draw.rectangle([x0, y0, x0 + panel_px, y0 + panel_px], outline=(180, 180, 180))
        draw.text((x0 + 4, y0 + 2), label, fill=(90, 90, 90))
        to_px, scale = panel_projection(points, panel_px, p)
        if ground is not None:
            _draw_ground(draw, ground, to_px, ax_u, top, (x0, y0, x0 + panel_px, y0 + panel_px))
        _draw_panel(draw, skeleton, leaves, to_px, scale, 3 - ax_u - ax_v, top)
    extent = float(max(np.ptp(points, axis=0).max(), 1e-9))
    # scale bar: the largest power of ten that fits in half a panel
    bar_m = 10 ** np.floor(np.log10(max(panel_px / 2 / scale, 1e-9)))
    y = header + panel_px + 12
    draw.line([(margin, y), (margin + bar_m * scale, y)], fill=(0, 0, 0), width=3)
    leaf_text = f", {len(leaves)} leaf polygons" if leaves is not None else ""
    draw.text((margin + bar_m * scale + 6, y - 6),
              f"{bar_m:g} m   ({len(skeleton)} segments{leaf_text}, extent {extent:.3g} m)",
              fill=(0, 0, 0))
    return img


def panel_projection(points: np.ndarray, panel_px: int, panel: int):
    """How :func:`draw_skeleton` projects into panel ``panel`` (0 front x-y, 1 side z-y,
    2 top x-z) of a drawing whose model spans ``points`` (n, 3): ``(to_px, scale)``, where
    ``to_px(xyz)`` gives (..., 2) pixel coordinates (column, row) in the whole image and
    ``scale`` is pixels per metre (the same in every panel: the model's largest extent
    fills the panel less its margins; the model's box is centred)."""
    _, ax_u, ax_v, top = _PANELS[panel]
    lo, hi = points.min(axis=0), points.max(axis=0)
    scale = (panel_px - 2 * _MARGIN) / float(max((hi - lo).max(), 1e-9))
    centre = (lo + hi) / 2
    x0, y0 = _MARGIN + panel * (panel_px + _MARGIN), _HEADER
    sign_v = 1.0 if top else -1.0      # image rows grow downwards; y up, z towards viewer

    def to_px(xyz):
        u = x0 + panel_px / 2 + (xyz[..., ax_u] - centre[ax_u]) * scale
        v = y0 + panel_px / 2 + sign_v * (xyz[..., ax_v] - centre[ax_v]) * scale
        return np.stack([u, v], axis=-1)

    return to_px, scale


def leaf_colour(name: str) -> tuple[int, int, int]:
    """The fill of leaves of material ``name``: the drawing's colour for it, else the
    renderers' (sRGB of :func:`~plantgen.geometry.skeletons.materials.material_colour`) where their
    palette knows the name, else :data:`LEAF_GREEN`."""
    if name in MATERIAL_COLOURS:
        return MATERIAL_COLOURS[name]
    if any(key in name.lower() for key in PALETTE):
        linear = np.asarray(material_colour(name))
        srgb = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
        return tuple(int(round(255 * c)) for c in np.clip(srgb, 0, 1))
    return LEAF_GREEN


def _draw_panel(draw, skeleton: Skeleton, leaves: Polygons | None, to_px, scale: float, depth_axis: int,
                top: bool) -> None:
    """One view: the segments and the leaf triangles, painted from far to near (the depth
    is the axis not shown: z in front, x in side, y in top; the viewer looks from +z, -x
    and +y)."""
    names = skeleton.material_names
    n = len(skeleton)
    depth = (skeleton.start[:, depth_axis] + skeleton.end[:, depth_axis]) / 2
    if leaves is not None:
        corners = leaves.vertices[leaves.triangles]                       # (t, 3, 3)
        depth = np.concatenate([depth, corners[:, :, depth_axis].mean(axis=1)])
        triangles_px = to_px(corners)                                     # (t, 3, 2)
        fills = [leaf_colour(name) for name in names]
        triangle_fill = [fills[m] if m < len(fills) else LEAF_GREEN for m in leaves.triangle_material.tolist()]
        rims = _outline_edges(leaves.triangles)
    order = np.argsort(-depth if depth_axis == 0 else depth, kind="stable")
    if n:
        a, b = to_px(skeleton.start), to_px(skeleton.end)
        outlines = _frustum_outlines(a, b, skeleton.r_start * scale, skeleton.r_end * scale)
        colours = [MATERIAL_COLOURS.get(names[m], _UNKNOWN) for m in skeleton.material]
        axis = skeleton.end - skeleton.start
        # segments nearly along y show as discs in the top view
        top_view_disc = np.hypot(axis[:, 0], axis[:, 2]) < 0.5 * np.abs(axis[:, 1])
    for i in order.tolist():
        if i >= n:
            _draw_leaf_triangle(draw, triangles_px[i - n], triangle_fill[i - n], rims[i - n])
            continue
        quad = outlines[i]
        if np.ptp(quad[:, 0]) < 1.5 and np.ptp(quad[:, 1]) < 1.5:
            draw.line([tuple(a[i]), tuple(b[i])], fill=colours[i], width=1)
        else:
            draw.polygon([tuple(q) for q in quad], fill=colours[i])
        if top_view_disc[i] and top:
            r = max(skeleton.r_start[i], skeleton.r_end[i]) * scale
            cx, cy = a[i]
            draw.ellipse([cx - r, cy - r, cx + r, cy + r], fill=colours[i])


def _outline_edges(triangles: np.ndarray) -> np.ndarray:
    """(t, 3) bool: whether edge k of each triangle (corner k to corner k + 1) lies on its
    polygon's outline (used by no other triangle; polygons share no vertices)."""
    edges = np.sort(np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=-1), axis=-1).reshape(-1, 2)
    _, inverse, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    return (counts[inverse.ravel()] == 1).reshape(-1, 3)


def _draw_leaf_triangle(draw, corners: np.ndarray, fill, rim: np.ndarray) -> None:
    """A leaf triangle (pixel corners (3, 2)) filled, with its outline edges in a darker
    shade where it spans a few pixels (so overlapping leaves stay apart; a needle-sized
    leaf is only its fill)."""
    draw.polygon([tuple(q) for q in corners], fill=fill)
    if np.ptp(corners, axis=0).max() < 6 or not rim.any():
        return
    dark = tuple(int(c * 0.6) for c in fill)
    for k in np.flatnonzero(rim).tolist():
        draw.line([tuple(corners[k]), tuple(corners[(k + 1) % 3])], fill=dark, width=1)


def _frustum_outlines(a: np.ndarray, b: np.ndarray, ra: np.ndarray, rb: np.ndarray) -> np.ndarray:
    """(n, 4, 2) pixel outlines of projected frusta: the trapezoid a±ra·n, b±rb·n.

    a, b : (n, 2) projected end points in pixels; ra, rb : (n,) radii in pixels. n is the
    unit normal of the projected axis (any unit vector where the axis projects to a point).
    """
    d = b - a
    length = np.linalg.norm(d, axis=1, keepdims=True)
    safe = np.where(length > 1e-9, length, 1.0)
    normal = np.where(length > 1e-9, np.stack([-d[:, 1], d[:, 0]], axis=1) / safe, [1.0, 0.0])
    ra = np.maximum(ra, 0.5)[:, None]
    rb = np.maximum(rb, 0.5)[:, None]
    return np.stack([a + ra * normal, b + rb * normal, b - rb * normal, a - ra * normal], axis=1)


def _draw_ground(draw, ground: Ground, to_px, ax_u: int, top: bool, box) -> None:
    """The ground as a line (front, side) or square (top), clipped to the panel ``box``."""
    colour = _GROUND_COLOURS.get(ground.material, (200, 185, 140))
    half = ground.size / 2
    ends = np.full((2, 3), 0.0)
    ends[:, 1] = ground.height
    if top:
        ends[:, 0] = ends[:, 2] = [-half, half]
    else:
        ends[:, ax_u] = [-half, half]
    px = to_px(ends)
    px[:, 0] = np.clip(px[:, 0], box[0], box[2])
    px[:, 1] = np.clip(px[:, 1], box[1], box[3])
    if top:
        draw.rectangle([*px.min(axis=0), *px.max(axis=0)], outline=colour, width=2)
    else:
        draw.line([tuple(px[0]), tuple(px[1])], fill=colour, width=2)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("outdir", type=Path)
    parser.add_argument("names", nargs="*", help="shipped model names (default: all)")
    parser.add_argument("--panel", type=int, default=420, help="panel size in pixels")
    args = parser.parse_args(argv)
    args.outdir.mkdir(parents=True, exist_ok=True)
    paths = [shipped_grammar(n) for n in args.names] if args.names else shipped_model_paths()
    for path in paths:
        result = grow_file(path)
        ground = result.scene.ground if result.scene is not None else None
        img = draw_skeleton(result.skeleton, f"{path.stem}: {result.name}", args.panel, ground, result.polygons)
        out = args.outdir / f"{path.stem}.png"
        img.save(out)
        leaves = len(result.polygons) if result.polygons is not None else 0
        print(f"{out}  {len(result.skeleton)} segments" + (f", {leaves} leaf polygons" if leaves else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
