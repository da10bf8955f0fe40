"""plantgen: L-system plants skinned with relief-mapped conical frusta.

The public API mirrors the command line::

    import plantgen
    skel = plantgen.grow("pine", seed=3)   # a shipped name or a file -> plantgen.Skeleton
    image = plantgen.render("pine", azimuth=60, ssaa=2)    # -> plantgen.RenderedImage
    image.save("pine.png")                                 # (in Jupyter: shows itself)
    plantgen.export("pine", "pine.glb", subdiv=2)          # -> summary dict
    hits = plantgen.trace("pine", origins, directions)     # -> plantgen.TraceResult
"""

from .geometry.skeletons.skeleton import Skeleton, SkeletonError

__version__ = "0.1.0"

__all__ = ["RenderedImage", "Skeleton", "SkeletonError", "TraceResult", "export", "grow", "render", "trace",
           "__version__"]


def grow(path, *, seed=None, iterations=None, max_modules=None, limits=None, allow_paths=()):
    """Grow a grammar or scene file, or a shipped one by name (``"pine"``: ``plantgen list``
    names them), into a Skeleton (see ``plantgen grow --help``);
    ``limits`` (a :class:`plantgen.limits.Limits`) and ``allow_paths`` as ``--limit`` and
    ``--allow-path``."""
    from .pipeline import grow as _grow

    return _grow(path, seed=seed, iterations=iterations, max_modules=max_modules, limits=limits,
                 allow_paths=allow_paths)


def render(path, output=None, settings=None, *, seed=None, iterations=None, smooth_bends=None, limits=None,
           allow_paths=(), **options):
    """Ray cast a grammar, scene, skeleton file or shipped name (``"pine"``) into an image,
    as ``plantgen render`` does.

    The render's settings come whole (``settings``, a :class:`plantgen.settings.RenderSettings`)
    or as keywords named as the command's options, with their defaults (see
    ``plantgen render --help``): ``size=(w, h)``, ``camera`` (``"auto"``, a camera JSON
    path or a :class:`plantgen.geometry.rays.camera.Camera`), ``azimuth``, ``elevation``,
    ``distance``, ``zoom``, ``fov``, ``effects``, ``relief``, ``shadows``, ``shadow_res``,
    ``shadow_caster``, ``ssaa``, ``aa`` (``"coverage"``, ``"edges"``, ``"none"``),
    ``background`` (``"sky"``, a colour, ``"none"``), ``time``,
    and the relief march's ``march``, ``linear_steps``, ``binary_steps``,
    ``march_density``, ``v_exact``.

    Returns a :class:`plantgen.RenderedImage`: ``.array`` (h, w, 3) uint8 (RGBA with
    ``background="none"``), ``.distance``, ``.camera``, ``.report``, ``.save(path)``; in a
    Jupyter notebook it displays itself. ``output`` (a ``.png``, ``.jpg`` or ``.webp`` path) also writes it.
    """
    from .images import RenderedImage
    from .pipeline import check_image_output, render_model

    if output is not None:
        check_image_output(output)          # before any work, as every command
    report = render_model(path, settings, seed=seed, iterations=iterations, smooth_bends=smooth_bends, limits=limits,
                          allow_paths=allow_paths, **options)
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
    ``instancing``, ``key_rate`` and ``duration`` of a swaying scene's animation,
    ``lod_levels`` and ``lod_pixels`` of the levels of detail, ...).
    Returns the summary dict of :func:`plantgen.pipeline.export_model` (segments,
    triangles, vertices, path, timings, animation)."""
    from .pipeline import export_model
    from .settings import DetailSettings, KeyframeSettings, LevelSettings, build_settings, option_names

    for cls, keyword in ((KeyframeSettings, "keyframes"), (LevelSettings, "levels"), (DetailSettings, "detail")):
        keys = {name: options.pop(name) for name in option_names(cls) if name in options}
        if keys:
            options[keyword] = build_settings(cls, keys)
    return export_model(path, output, level=subdiv, relief=relief, seed=seed, limits=limits,
                        allow_paths=allow_paths, **options)


def __getattr__(name):
    if name in ("trace", "TraceResult"):        # the tracer (and the scan's geometry) on first use
        from . import tracer

        return getattr(tracer, name)
    if name == "RenderedImage":      # Pillow is imported only when an image is asked for
        from .images import RenderedImage

        return RenderedImage
    raise AttributeError(f"module 'plantgen' has no attribute {name!r}")
