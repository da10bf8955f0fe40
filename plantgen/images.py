"""Image files out: PNG stills and animated GIF/WebP, through Pillow, written atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from .errors import PlantgenError
from .files import write_atomically

__all__ = ["ANIMATION_SUFFIXES", "write_png", "write_animation"]

ANIMATION_SUFFIXES = (".gif", ".webp")


def write_png(path, color: np.ndarray) -> Path:
    """Write (h, w, 3) or (h, w, 4) uint8 ``color`` as a PNG at ``path``."""
    return write_atomically(path, lambda p: Image.fromarray(color).save(p, format="PNG"))


def write_animation(path, frames, fps: float) -> Path:
    """Write (h, w, 3) uint8 ``frames`` as an animated GIF or WebP at ``fps``, to a
    temporary name renamed onto ``path`` at the end. A GIF uses one palette for every
    frame (taken from frames spread over the clip), so colours do not flicker."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in ANIMATION_SUFFIXES:
        raise PlantgenError(f"{path}: an animation must end in {' or '.join(ANIMATION_SUFFIXES)}")
    images = [Image.fromarray(np.ascontiguousarray(f)) for f in frames]
    if not images:
        raise PlantgenError("an animation needs at least one frame")
    duration = max(int(round(1000.0 / fps)), 10)

    def save(tmp):
        if suffix == ".gif":
            picks = np.linspace(0, len(images) - 1, min(len(images), 4)).astype(int)
            strip = np.concatenate([np.asarray(images[i]) for i in picks], axis=0)
            palette = Image.fromarray(strip).quantize(colors=255, method=Image.Quantize.MEDIANCUT)
            frames_p = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
            frames_p[0].save(tmp, format="GIF", save_all=True, append_images=frames_p[1:],
                             duration=duration, loop=0, optimize=False, disposal=1)
        else:
            images[0].save(tmp, format="WEBP", save_all=True, append_images=images[1:],
                           duration=duration, loop=0, quality=85, method=4)

    return write_atomically(path, save)
