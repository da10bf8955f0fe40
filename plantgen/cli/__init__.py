"""The ``plantgen`` command line: a thin click layer over the library.

``group`` holds the command group and the console entry point :func:`main`; each command
lives in its own module (``grow``, ``export``, ``render``, ``bench``), converts its options
and calls one library function; ``options`` declares the options they share.
"""

from .group import cli, main

__all__ = ["cli", "main"]
