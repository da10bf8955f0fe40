"""plantgen: L-system plants skinned with relief-mapped conical frusta.

The public API mirrors the command line::

    import plantgen
    skel = plantgen.grow("grammars/pine.yaml", seed=3)   # -> plantgen.Skeleton
"""

from .geometry.skeleton import Skeleton, SkeletonError

__version__ = "0.1.0"

__all__ = ["Skeleton", "SkeletonError", "grow", "__version__"]


def grow(path, *, seed=None, iterations=None, max_modules=None, limits=None, allow_paths=()):
    """Grow a grammar or scene file into a Skeleton (see ``plantgen grow --help``);
    ``limits`` (a :class:`plantgen.limits.Limits`) and ``allow_paths`` as ``--limit`` and
    ``--allow-path``."""
    from .pipeline import grow as _grow

    return _grow(path, seed=seed, iterations=iterations, max_modules=max_modules, limits=limits,
                 allow_paths=allow_paths)
