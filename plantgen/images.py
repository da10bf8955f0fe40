"""Images out: PNG stills and animated GIF/WebP through Pillow, written atomically; the
background colours the command line names; :class:`RenderedImage`, what the Python API's
``plantgen.render`` returns (it shows itself in a Jupyter notebook)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PIL import Image, ImageColor

from .errors import PlantgenError
from .files import write_atomically

__all__ = ["ANIMATION_SUFFIXES", "IMAGE_FORMATS", "TRANSPARENT", "check_transparency", "image_format",
           "write_image", "RenderedImage", "parse_background", "write_png", "png_bytes",
           "write_animation"]

#: The background value of a transparent image: (r, g, b, a) with a = 0.
TRANSPARENT = (0.0, 0.0, 0.0, 0.0)


def parse_background(text: str | None) -> tuple | None:
    """A background as the renderers take it, from its name: ``sky`` (or None) -> None
    (the shaded sky); ``none`` or ``transparent`` -> :data:`TRANSPARENT` (a PNG with an
    alpha channel); any colour Pillow names (``white``, ``#20304a``, ``rgb(32,48,74)``)
    -> (r, g, b, 1) in [0, 1], written to the image unchanged. One line for anything else."""
    if text is None or text.strip().lower() == "sky":
        return None
    name = text.strip().lower()
    if name in ("none", "transparent"):
        return TRANSPARENT
    try:
        rgb = ImageColor.getrgb(name)
    except ValueError:
        raise PlantgenError(f"background {text!r} is not a colour: give a name (white), #rrggbb, "
                            "'sky' or 'none' (transparent)") from None
    return (rgb[0] / 255.0, rgb[1] / 255.0, rgb[2] / 255.0, 1.0)


class RenderedImage:
    """A rendered image: ``array`` (h, w, 3) uint8 RGB, or (h, w, 4) RGBA over a transparent
    background, row 0 the top row; ``distance`` (h, w) float32 along each pixel's ray (inf
    for a miss), ``camera`` the view, ``report`` what the render did (frame time, GL
    renderer, ...). In a Jupyter notebook it displays itself (``_repr_png_``);
    :meth:`save` writes a PNG, :meth:`to_pil` gives a Pillow image."""

    def __init__(self, array: np.ndarray, *, distance: np.ndarray | None = None, camera=None, report=None):
        self.array = np.ascontiguousarray(array, dtype=np.uint8)
        self.distance = distance
        self.camera = camera
        self.report = report

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.array.shape[1], self.array.shape[0]

    def to_pil(self) -> Image.Image:
        return Image.fromarray(self.array)

    def save(self, path) -> Path:
        """Write the image at ``path`` (atomically), as its suffix says: PNG, JPEG or WebP
        (:func:`write_image`)."""
        return write_image(path, self.array)

    def _repr_png_(self) -> bytes:
        buffer = io.BytesIO()
        self.to_pil().save(buffer, format="PNG")
        return buffer.getvalue()

    def __array__(self, dtype=None, copy=None):
        return self.array if dtype is None else self.array.astype(dtype)

    def __repr__(self) -> str:
        mode = "RGBA" if self.array.shape[-1] == 4 else "RGB"
        return f"<plantgen.RenderedImage {mode} {self.size[0]}x{self.size[1]}>"

ANIMATION_SUFFIXES = (".gif", ".webp")
#: A still's suffixes and the format Pillow writes each in.
IMAGE_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".webp": "WEBP"}
#: JPEG's quality (Pillow's scale); WebP stills are written lossless.
JPEG_QUALITY = 92


def image_format(path) -> str:
    """The Pillow format of a still at ``path`` by its suffix; one line for another suffix."""
    path = Path(path)
    fmt = IMAGE_FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise PlantgenError(f"{path}: the image output must end in .png, .jpg or .webp")
    return fmt


def check_transparency(path, transparent: bool) -> None:
    """One line for a transparent image asked of a JPEG, which has no alpha."""
    if transparent and image_format(path) == "JPEG":
        raise PlantgenError(f"{path}: a JPEG has no transparency: write .png or .webp with --background none")


def write_image(path, color: np.ndarray) -> Path:
    """Write (h, w, 3) or (h, w, 4) uint8 ``color`` at ``path`` as its suffix says: PNG,
    JPEG (quality :data:`JPEG_QUALITY`; RGB only) or WebP (lossless)."""
    fmt = image_format(path)
    check_transparency(path, color.ndim == 3 and color.shape[-1] == 4)
    options = {"JPEG": {"quality": JPEG_QUALITY}, "WEBP": {"lossless": True}}.get(fmt, {})
    return write_atomically(path, lambda p: Image.fromarray(color).save(p, format=fmt, **options))


def write_png(path, color: np.ndarray) -> Path:
    """Write (h, w, 3) or (h, w, 4) uint8 ``color`` as a PNG at ``path``."""
    return write_atomically(path, lambda p: Image.fromarray(color).save(p, format="PNG"))


def png_bytes(image: np.ndarray) -> bytes:
    """The bytes of a PNG of ``image``: (h, w) grey, (h, w, 3) or (h, w, 4) uint8, row 0 at
    the top (an exporter's texture, embedded in a file or written beside it)."""
    out = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8)).save(out, format="PNG")
    return out.getvalue()


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
