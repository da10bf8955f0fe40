"""The heads-up text: what it says of a :class:`~plantgen.viewer.state.ViewerState`
(:func:`hud_lines`: the model, the method and its knobs, the frame times, the time, the
growth step, the last status or error), and those lines drawn by Pillow into an RGBA image
over a dark, half-transparent panel, which the window lays over the frame."""

from __future__ import annotations

import statistics

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from .keys import help_lines
from .state import ViewerState

__all__ = ["hud_lines", "text_panel", "help_panel", "FONT_SIZE"]

#: Pixel height of the heads-up font.
FONT_SIZE = 14

COLOURS = {"info": (235, 235, 235, 255), "status": (150, 225, 150, 255), "error": (255, 120, 110, 255),
           "key": (255, 220, 120, 255)}

_fonts: dict = {}


def _the_font(size: int = FONT_SIZE):
    if size not in _fonts:
        _fonts[size] = ImageFont.load_default(size=size)
    return _fonts[size]


def text_panel(lines, max_width: int) -> np.ndarray:
    """(h, w, 4) uint8 RGBA image of ``lines`` ((text, kind) pairs, kind a key of
    :data:`COLOURS`), at most ``max_width`` pixels wide (longer lines are cut)."""
    font = _the_font()
    pad, step = 6, FONT_SIZE + 4
    width = min(max_width, pad * 2 + max((int(font.getlength(t)) for t, _ in lines), default=0))
    image = Image.new("RGBA", (max(width, 1), pad * 2 + step * len(lines)), (16, 18, 22, 170))
    draw = ImageDraw.Draw(image)
    for i, (text, kind) in enumerate(lines):
        draw.text((pad, pad + i * step), text, font=font, fill=COLOURS.get(kind, COLOURS["info"]))
    return np.asarray(image)


def _help_layout(rows, max_width: int, max_height: int | None):
    """(font size, columns, per column, key width, column width, width, height) of the
    help panel: the largest font from :data:`FONT_SIZE` down to 9 pixels, in one column or
    two, that fits the window (else the smallest, cut)."""
    for size in range(FONT_SIZE, 8, -1):
        font, pad, step = _the_font(size), 10, size + 5
        key_w = max(int(font.getlength(k)) for k, _ in rows) + 16
        col_w = key_w + max(int(font.getlength(t)) for _, t in rows) + 2 * pad
        for columns in (1, 2):
            per_column = -(-len(rows) // columns)
            width, height = pad + columns * col_w, pad * 2 + step * (per_column + 1)
            if width <= max_width and (max_height is None or height <= max_height):
                return size, columns, per_column, key_w, col_w, width, height
    return size, columns, per_column, key_w, col_w, min(width, max_width), height


def help_panel(max_width: int, max_height: int | None = None) -> np.ndarray:
    """The keys, as :func:`text_panel` draws them (key names in yellow), laid out to fit
    ``max_width`` x ``max_height`` pixels (see :func:`_help_layout`)."""
    rows = help_lines()
    size, columns, per_column, key_w, col_w, width, height = _help_layout(rows, max_width, max_height)
    font, pad, step = _the_font(size), 10, size + 5
    image = Image.new("RGBA", (width, height), (16, 18, 22, 210))
    draw = ImageDraw.Draw(image)
    draw.text((pad, pad), "plantgen view: keys (H hides)", font=font, fill=COLOURS["status"])
    for i, (keys, text) in enumerate(rows):
        x, y = pad + (i // per_column) * col_w, pad + (i % per_column + 1) * step
        draw.text((x, y), keys, font=font, fill=COLOURS["key"])
        draw.text((x + key_w, y), text, font=font, fill=COLOURS["info"])
    return np.asarray(image)


def hud_lines(state: ViewerState) -> list[tuple[str, str]]:
    """(text, kind) lines of the heads-up display; kind is "info", "status" or "error"."""
    s = state.settings()
    if state.method in ("RC", "RT"):
        method = state.method
    elif state.method in ("RC+R", "RT+R"):
        method = (f"{state.method} adaptive <= {s.linear_steps} + {s.binary_steps} steps" if s.march == "adaptive"
                  else f"{state.method} fixed {s.linear_steps} + {s.binary_steps} steps")
    else:
        method = f"{state.method} m = {state.level}"
        if state.posing_on_gpu() and state.skinned is not None and state.skinned[0][1] == state.level:
            method += f", {len(state.skinned[1].mesh.faces):,} triangles, skinned on the GPU"
        elif state.mesh_cache is not None and state.mesh_key is not None and state.mesh_key[1] == state.level:
            method += f", {len(state.mesh_cache.faces):,} triangles"
    frames = list(state.frames)
    timing = "-"
    if frames:
        frame_ms = statistics.median(f.frame_ms for f in frames)
        wall_ms = statistics.median(f.wall_ms for f in frames)
        timing = f"{frame_ms:.1f} ms frame, {1000.0 / max(wall_ms, 1e-3):.1f} fps (median of {len(frames)})"
    cam = state.camera
    leaves = state.model.grown.polygons
    count = 0 if leaves is None else len(leaves)
    leafy = f", {count:,} {'leaf' if count == 1 else 'leaves'}" if count else ""
    lines = [(f"{state.model.grown.name}: {state.model.grown.segments:,} segments{leafy} | {method} | shadows "
              f"{_shadow_text(state)} | ssaa {state.ssaa}", "info"),
             (f"{timing} | {cam.width}x{cam.height} | {state.renderer} | H: keys", "info")]
    if state.model.animated:
        lines.append((f"t = {state.t:.2f} s {'playing' if state.playing else 'paused'} (Space, , .)", "info"))
    if state.step_target is not None:
        lines.append((f"growth: step {state.step} of {state.steps_end}, {'playing' if state.growing else 'paused'}"
                      " (N, Shift+N, G)", "info"))
    if state.error:
        lines.append((state.error, "error"))
    elif state.status:
        lines.append((state.status, "status"))
    return lines


def _shadow_text(state: ViewerState) -> str:
    """``off``, or ``on`` and how the last frame had its map: drawn (in how many ms) or
    reused (a camera move does not draw it again)."""
    if not state.shadows:
        return "off"
    stats = state.last.stats if state.last is not None else None
    if stats is None or "shadow" not in stats.passes:
        return "on"
    return "on (map reused)" if stats.shadow_cached else f"on (map drawn, {stats.shadow_ms:.0f} ms)"
