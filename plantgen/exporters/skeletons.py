"""Write a skeleton in any skeleton format (SWC, the QSM cylinder models): :func:`write_skeleton`.

The format follows the file suffix (:mod:`plantgen.exporters.formats`), and its row names its
writer, called the same way for every skeleton format
(:class:`~plantgen.exporters.plants.SkeletonWriter`): :func:`write_swc_skeleton` (SWC,
:mod:`plantgen.geometry.skeletons.swc`) and :func:`plantgen.exporters.qsm.write_qsm` (``.qsm.csv``,
``.qsm.mat``).
"""

from __future__ import annotations

from pathlib import Path

from ..geometry.skeletons.skeleton import Skeleton
from ..geometry.skeletons.swc import write_swc
from .formats import writable_format
from .plants import SkeletonWriter

__all__ = ["write_skeleton", "write_swc_skeleton"]


def write_swc_skeleton(skeleton: Skeleton, path: str | Path, *, up: str = "y", unit: float = 1.0,
                       tolerance: float = 1e-3, name: str = "plant") -> dict:
    """:func:`~plantgen.geometry.skeletons.swc.write_swc` as a
    :class:`~plantgen.exporters.plants.SkeletonWriter`: SWC keeps model units and names no
    model, so ``unit``, ``tolerance`` and ``name`` are not written. Returns ``{"paths": [path]}``."""
    return {"paths": [write_swc(skeleton, path, up=up)]}


def write_skeleton(skeleton: Skeleton, path: str | Path, *, up: str | None = None, unit: float = 1.0,
                   tolerance: float = 1e-3, name: str = "plant") -> dict:
    """Write ``skeleton`` in the skeleton format ``path`` names, with the writer its row names
    (:data:`~plantgen.exporters.formats.EXPORT_FORMATS`).

    Parameters
    ----------
    skeleton : the model's skeleton
    path : target file; its suffix names the format (``.swc``, ``.qsm.csv``, ``.qsm.mat``)
    up : ``"y"`` or ``"z"``; default the format's convention
    unit : metres per model unit (QSM files are in metres)
    tolerance : the cylinder model's volume tolerance (:mod:`plantgen.exporters.qsm`)
    name : the model's name, where the format records it

    Returns
    -------
    dict : the writer's summary: ``paths`` (the written files, the main one last) and what
        else the format reports (:func:`plantgen.exporters.qsm.write_qsm`)
    """
    path = Path(path)
    fmt = writable_format(path, "skeleton")
    writer: SkeletonWriter = fmt.load_writer()
    return writer(skeleton, path, up=up or fmt.up, unit=unit, tolerance=tolerance, name=name)
