"""Quick line drawings of grown skeletons: a look at each shipped model.

Run as ``python -m plantgen.benchmarks.draw_skeletons OUTDIR [NAME ...]``. For each
shipped grammar or scene (default: every ``*.yaml`` in the grammars directory) it grows
the default seed and writes ``OUTDIR/NAME.png``: three orthographic panels side by side,
front (x-y), side (z-y) and top (x-z), all at the same scale in metres. Each segment is
drawn as its projected outline (a trapezoid with the two end radii; a disc in the top view
for upright segments; a one-pixel line when thinner than that), coloured by material. A
scale bar under the panels says how long one metre is.

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
from ..geometry.skeleton import Skeleton
from ..geometry.stage import Ground
from ..pipeline import grow_file
from .arguments import shipped_model_paths

__all__ = ["MATERIAL_COLOURS", "draw_skeleton", "main"]

MATERIAL_COLOURS = {
    "bark": (110, 75, 45),
    "leaf": (60, 140, 50),
    "cactus": (70, 125, 70),
    "aloe": (120, 165, 110),
    "stone": (130, 130, 135),
}
_GROUND_COLOURS = {"sand": (215, 190, 130), "grass": (120, 170, 80)}
_UNKNOWN = (200, 40, 160)
_PANELS = (("front x-y", 0, 1, False), ("side z-y", 2, 1, False), ("top x-z", 0, 2, True))


def draw_skeleton(skeleton: Skeleton, title: str = "", panel_px: int = 420,
                  ground: Ground | None = None) -> Image.Image:
    """Draw three orthographic projections of ``skeleton`` into one RGB image.

    Parameters
    ----------
    skeleton : the model, coordinates in metres, y up
    title : text written in the top-left corner
    panel_px : width and height of each panel in pixels
    ground : optional scene ground, drawn as a line or square
    """
    margin, header, footer = 12, 22, 26
    width = 3 * panel_px + 4 * margin
    img = Image.new("RGB", (width, panel_px + header + footer + margin), (245, 242, 232))
    draw = ImageDraw.Draw(img)
    draw.text((margin, 4), title, fill=(0, 0, 0))
    if len(skeleton) == 0:
        return img
    points = np.concatenate([skeleton.start, skeleton.end])
    lo, hi = points.min(axis=0), points.max(axis=0)
    extent = float(max((hi - lo).max(), 1e-9))
    scale = (panel_px - 2 * margin) / extent                    # pixels per metre
    centre = (lo + hi) / 2
    axis = skeleton.end - skeleton.start
    # segments nearly along y show as discs in the top view
    top_view_disc = np.hypot(axis[:, 0], axis[:, 2]) < 0.5 * np.abs(axis[:, 1])
    names = skeleton.material_names
    colours = [MATERIAL_COLOURS.get(names[m], _UNKNOWN) for m in skeleton.material]
    for p, (label, ax_u, ax_v, top) in enumerate(_PANELS):
        x0 = margin + p * (panel_px + margin)
        y0 = header
        draw.rectangle([x0, y0, x0 + panel_px, y0 + panel_px], outline=(180, 180, 180))
        draw.text((x0 + 4, y0 + 2), label, fill=(90, 90, 90))
        sign_v = 1.0 if top else -1.0      # image rows grow downwards; y up, z towards viewer

        def to_px(xyz, ax_u=ax_u, ax_v=ax_v, sign_v=sign_v, x0=x0, y0=y0):
            u = x0 + panel_px / 2 + (xyz[..., ax_u] - centre[ax_u]) * scale
            v = y0 + panel_px / 2 + sign_v * (xyz[..., ax_v] - centre[ax_v]) * scale
            return np.stack([u, v], axis=-1)

        a, b = to_px(skeleton.start), to_px(skeleton.end)
        outlines = _frustum_outlines(a, b, skeleton.r_start * scale, skeleton.r_end * scale)
        # far segments first: depth is the axis not shown (z in front, x in side, y in top)
        depth_axis = 3 - ax_u - ax_v
        depth = (skeleton.start[:, depth_axis] + skeleton.end[:, depth_axis]) / 2
        order = np.argsort(-depth if depth_axis == 0 else depth, kind="stable")
        if ground is not None:
            _draw_ground(draw, ground, to_px, ax_u, top, (x0, y0, x0 + panel_px, y0 + panel_px))
        for i in order.tolist():
            quad = outlines[i]
            if np.ptp(quad[:, 0]) < 1.5 and np.ptp(quad[:, 1]) < 1.5:
                draw.line([tuple(a[i]), tuple(b[i])], fill=colours[i], width=1)
            else:
                draw.polygon([tuple(q) for q in quad], fill=colours[i])
            if top_view_disc[i] and top:
                r = max(skeleton.r_start[i], skeleton.r_end[i]) * scale
                cx, cy = a[i]
                draw.ellipse([cx - r, cy - r, cx + r, cy + r], fill=colours[i])
    # scale bar: the largest power of ten that fits in half a panel
    bar_m = 10 ** np.floor(np.log10(max(panel_px / 2 / scale, 1e-9)))
    y = header + panel_px + 12
    draw.line([(margin, y), (margin + bar_m * scale, y)], fill=(0, 0, 0), width=3)
    draw.text((margin + bar_m * scale + 6, y - 6),
              f"{bar_m:g} m   ({len(skeleton)} segments, extent {extent:.3g} m)",
              fill=(0, 0, 0))
    return img


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
        img = draw_skeleton(result.skeleton, f"{path.stem}: {result.name}", args.panel, ground)
        out = args.outdir / f"{path.stem}.png"
        img.save(out)
        print(f"{out}  {len(result.skeleton)} segments")
    return 0


if __name__ == "__main__":
    sys.exit(main())
