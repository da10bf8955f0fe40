"""The heads-up text: lines drawn by Pillow into an RGBA image over a dark, half-transparent
panel, which the window lays over the frame."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from .keys import help_lines

__all__ = ["text_panel", "help_panel", "FONT_SIZE"]

#: Pixel height of the heads-up font.
FONT_SIZE = 14

COLOURS = {"info": (235, 235, 235, 255), "status": (150, 225, 150, 255), "error": (255, 120, 110, 255),
           "key": (255, 220, 120, 255)}

_font = None


def _the_font():
    global _font
    if _font is None:
        _font = ImageFont.load_default(size=FONT_SIZE)
    return _font


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


def help_panel(max_width: int) -> np.ndarray:
    """The keys, as :func:`text_panel` draws them (key names in yellow)."""
    font = _the_font()
    rows = help_lines()
    pad, step = 10, FONT_SIZE + 5
    key_w = max(int(font.getlength(k)) for k, _ in rows) + 16
    width = min(max_width, pad * 2 + key_w + max(int(font.getlength(t)) for _, t in rows))
    image = Image.new("RGBA", (width, pad * 2 + step * (len(rows) + 1)), (16, 18, 22, 210))
    draw = ImageDraw.Draw(image)
    draw.text((pad, pad), "plantgen view: keys (H hides)", font=font, fill=COLOURS["status"])
    for i, (keys, text) in enumerate(rows, start=1):
        draw.text((pad, pad + i * step), keys, font=font, fill=COLOURS["key"])
        draw.text((pad + key_w, pad + i * step), text, font=font, fill=COLOURS["info"])
    return np.asarray(image)
