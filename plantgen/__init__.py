"""plantgen: L-system plants skinned with relief-mapped conical frusta.

The public API mirrors the command line::

    import plantgen
    skel = plantgen.grow("grammars/pine.yaml", seed=3)        # -> plantgen.Skeleton
    image = plantgen.render("pine", azimuth=60, ssaa=2)       # -> plantgen.RenderedImage
    image.save("pine.png")                                    # (in Jupyter: shows itself)
    plantgen.export("pine", "pine.glb", subdiv=2)             # -> summary dict
"""

import sys
import types

from .geometry.skeleton import Skeleton, SkeletonError

__version__ = "0.1.0"

__all__ = ["RenderedImage", "Skeleton", "SkeletonError", "export", "grow", "render", "__version__"]


def grow(path, *, seed=None, iterations=None, max_modules=None, limits=None, allow_paths=()):
    """Grow a grammar or scene file into a Skeleton (see ``plantgen grow --help``);
    ``limits`` (a :class:`plantgen.limits.Limits`) and ``allow_paths`` as ``--limit`` and
    ``--allow-path``."""
    from .pipeline import grow as _grow

    return _grow(path, seed=seed, iterations=iterations, max_modules=max_modules, limits=limits,
                 allow_paths=allow_paths)


def render(path, output=None, *, size=None, camera="auto", azimuth=None, elevation=None, distance=None,
           zoom=None, fov=None, relief=None, shadows=None, effects=None, ssaa=1, background="sky", time=None,
           seed=None, iterations=None, linear_steps=None, binary_steps=None, march=None, march_density=None,
           v_exact=False, shadow_res=2048, shadow_caster="relief", limits=None, allow_paths=()):
    """Ray cast a grammar, scene, skeleton file or shipped name (``"pine"``) into an image,
    as ``plantgen render`` does (see its ``--help`` for every option).

    Returns a :class:`plantgen.RenderedImage`: ``.array`` (h, w, 3) uint8 (RGBA with
    ``background="none"``), ``.distance``, ``.camera``, ``.report``, ``.save(path)``; in a
    Jupyter notebook it displays itself. ``output`` (a ``.png`` path) also writes it.

    ``size`` is (width, height) (default 1024x768, or the camera file's); ``camera`` is
    ``"auto"``, a camera JSON path or a :class:`plantgen.geometry.camera.Camera`;
    ``azimuth``, ``elevation``, ``distance`` or ``zoom`` and ``fov`` turn the view around
    the model; ``background`` is ``"sky"``, a colour name or ``#rrggbb``, or ``"none"``;
    ``ssaa`` N draws N x N rays a pixel; ``time`` poses an animated scene.
    """
    from .geometry.camera import Orbit
    from .images import RenderedImage, parse_background
    from .pipeline import render_model

    back = parse_background(background) if isinstance(background, str) or background is None else background
    report = render_model(path, size=size, camera=camera, orbit=Orbit(azimuth, elevation, distance, zoom, fov),
                          relief=relief, shadows=shadows, effects=effects, ssaa=ssaa, background=back,
                          time_s=time, seed=seed, iterations=iterations, linear_steps=linear_steps,
                          binary_steps=binary_steps, march=march, march_density=march_density, v_exact=v_exact,
                          shadow_res=shadow_res, shadow_caster=shadow_caster, limits=limits,
                          allow_paths=allow_paths)
    image = RenderedImage(report.result.color, distance=report.distance, camera=report.camera, report=report)
    if output is not None:
        report.written = [image.save(output)]
    return image


def export(path, output, *, subdiv=1, relief=False, seed=None, limits=None, allow_paths=(), **options):
    """Tessellate a grammar, scene, skeleton file or shipped name and write the file
    ``output`` names (mesh: ``.glb``, ``.gltf``, ``.obj``, ``.ply``, ``.stl``, ``.usda``,
    ``.usdc``; skeleton: ``.swc``, ``.qsm.csv``, ``.qsm.mat``), as ``plantgen export`` does:
    ``subdiv`` is the level m (16·4^m triangles per frustum plus 8·2^m per cap), ``relief``
    moves the vertices onto the relief surface; ``options`` as the command's (``up``,
    ``instancing``, ...). Returns the summary dict of
    :func:`plantgen.pipeline.export_model` (segments, triangles, vertices, path, timings)."""
    from .pipeline import export_model

    return export_model(path, output, level=subdiv, relief=relief, seed=seed, limits=limits,
                        allow_paths=allow_paths, **options)


class _Package(types.ModuleType):
    """plantgen's module type: the names ``render`` and ``export`` stay the API functions.

    Importing a submodule binds its name on the parent package, and plantgen has a
    ``render`` subpackage and an ``export`` module; without this, the first
    ``import plantgen.render.raycast`` (made by ``plantgen.render()`` itself) would replace
    the function. The submodules stay importable by their full names."""

    def __setattr__(self, name, value):
        if name in ("render", "export") and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package


def __getattr__(name):
    if name == "RenderedImage":      # Pillow is imported only when an image is asked for
        from .images import RenderedImage

        return RenderedImage
    raise AttributeError(f"module 'plantgen' has no attribute {name!r}")
