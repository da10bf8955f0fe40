"""Command-line pieces the benchmark scripts share."""

from __future__ import annotations

from pathlib import Path

from .._resources import grammars_dir

__all__ = ["image_size", "shipped_model_paths"]


def image_size(text: str) -> tuple[int, int]:
    """argparse type of a ``WIDTHxHEIGHT`` option such as ``1024x768``: (width, height)."""
    width, height = (int(x) for x in text.lower().split("x"))
    return width, height


def shipped_model_paths() -> list[Path]:
    """Every shipped grammar and scene (``grammars/*.yaml``), sorted by path: the default
    model list of the scripts that take ``MODEL ...``."""
    return sorted(grammars_dir().glob("*.yaml"))
