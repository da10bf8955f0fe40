"""Command-line pieces the benchmark scripts share."""

from __future__ import annotations

from pathlib import Path

from .._resources import grammars_dir
from ..files import write_atomically

__all__ = ["image_size", "shipped_model_paths", "report", "view_options"]


def image_size(text: str) -> tuple[int, int]:
    """argparse type of a ``WIDTHxHEIGHT`` option such as ``1024x768``: (width, height)."""
    width, height = (int(x) for x in text.lower().split("x"))
    return width, height


def shipped_model_paths() -> list[Path]:
    """Every shipped grammar and scene (``grammars/*.yaml``), sorted by path: the default
    model list of the scripts that take ``MODEL ...``."""
    return sorted(grammars_dir().glob("*.yaml"))


def report(text: str, out: Path | None) -> int:
    """Print a benchmark's Markdown ``text`` and, with ``out``, write it there whole
    (atomically). Returns the script's exit status (0)."""
    print(text)
    if out is not None:
        write_atomically(out, lambda path: Path(path).write_text(text))
    return 0


def view_options(parser) -> None:
    """The options of a script that draws one model from the gallery's camera: --zoom,
    --raise, --size (read back by :func:`plantgen.benchmarks.side_by_side.model_view`)."""
    parser.add_argument("--zoom", type=float, default=1.0, help="eye distance factor (< 1: closer)")
    parser.add_argument("--raise", dest="lift", type=float, default=0.0,
                        help="raise the target by this fraction of the model's extent")
    parser.add_argument("--size", type=int, nargs=2, default=(400, 400))

