"""The compared images of ``plantgen bench --images``: each reference's depth shading, and
each Table 1 method's colour and depth shading, in the evaluation window."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from .quality import depth_shading

__all__ = ["save_images"]


def _grey(shading: np.ndarray) -> Image.Image:
    """An 8-bit grey image of (H, W) values in [0, 1]."""
    return Image.fromarray(np.clip(shading * 255 + 0.5, 0, 255).astype(np.uint8))


def _file_tag(key: str) -> str:
    """A configuration key as a file name part: ``gs+r:m=2`` -> ``gspr_m2``."""
    return key.replace(":", "_").replace("=", "").replace("+", "p")


def save_images(directory: Path, model_name: str, camera, light_dir, reference_distance: dict,
                results: dict, keys) -> None:
    """Write ``MODEL_reference[_relief].png`` and ``MODEL_KEY_{color,shading}.png``.

    Parameters
    ----------
    camera : the evaluation window's camera; light_dir : (3,) towards the light
    reference_distance : {relief: (H, W) reference distances along the rays, inf on a miss}
    results : {configuration key: RenderResult in the window}
    keys : the configuration keys to write (those missing from ``results`` are skipped)
    """
    directory.mkdir(parents=True, exist_ok=True)
    for relief, distance in reference_distance.items():
        tag = "reference_relief" if relief else "reference"
        _grey(depth_shading(distance, camera, light_dir)).save(directory / f"{model_name}_{tag}.png")
    for key in keys:
        res = results.get(key)
        if res is None:
            continue
        tag = _file_tag(key)
        Image.fromarray(res.color).save(directory / f"{model_name}_{tag}_color.png")
        _grey(depth_shading(res.distance, camera, light_dir)).save(
            directory / f"{model_name}_{tag}_shading.png")
