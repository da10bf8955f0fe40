"""Files in and out, in one place: reading input files and writing outputs atomically.

Every output plantgen writes goes through :func:`write_atomically`: the bytes go to a
hidden temporary name beside the target, which is renamed onto it only when complete,
so a failure never leaves a half-written file.

Every input is untrusted and goes through :func:`open_input`: only a regular file is read
(never a device, a pipe or a socket: ``/dev/zero`` is refused before a byte is read), and
only up to its size limit. YAML goes through :func:`read_yaml`, which bounds the document
before anything reads a value: its nesting depth and its size with every alias expanded
are counted from the parser's events, so an alias "bomb" or a 100,000-deep nest is one
error line, never a hang, an exhausted memory or a crash. Every failure is one
:class:`PlantgenError` line naming the file (and the line, where there is one).
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

import yaml

from .errors import PlantgenError
from .limits import LimitError, Limits, hint
from .limits import limits as default_limits

__all__ = ["open_input", "read_input", "read_yaml", "write_atomically", "write_all_atomically", "temporary_name"]

# The C parser where PyYAML has it (about 4x faster); the document is bounded before it
# is composed, so its recursive composer never sees a deep nest.
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def open_input(path: str | Path, error: type[PlantgenError] = PlantgenError, *,
               max_bytes: int, limit: str, what: str = "input") -> BinaryIO:
    """Open ``path`` for reading if it is a regular file of at most ``max_bytes`` bytes
    (the limit named ``limit``); else one ``error`` line naming it."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            _not_regular(path, os.stat(path).st_mode, error, what)
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    except FileNotFoundError:
        raise error(f"{path}: no such file") from None
    except NotADirectoryError:
        raise error(f"{path}: no such file (a part of the path is not a directory)") from None
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror or exc.__class__.__name__})") from None
    fh = os.fdopen(fd, "rb")
    try:
        st = os.fstat(fh.fileno())   # the file opened, not the name: nothing swapped in between
        if not stat.S_ISREG(st.st_mode):
            _not_regular(path, st.st_mode, error, what)
        if st.st_size > max_bytes:
            raise LimitError(f"{path}: {st.st_size:,} bytes, over the limit of {max_bytes:,} for a "
                             f"{what} file ({hint(limit)})")
    except BaseException:
        fh.close()
        raise
    return fh


def _not_regular(path, mode, error, what):
    if stat.S_ISDIR(mode):
        raise error(f"{path}: is a directory, not a {what} file")
    raise error(f"{path}: not a regular file (plantgen reads no device, pipe or socket)")


def read_input(path: str | Path, error: type[PlantgenError] = PlantgenError, *, max_bytes: int,
               limit: str, what: str = "input") -> bytes:
    """The bytes of the regular file ``path`` (see :func:`open_input`); a file that grows
    past ``max_bytes`` while it is read is refused too."""
    with open_input(path, error, max_bytes=max_bytes, limit=limit, what=what) as fh:
        try:
            data = fh.read(max_bytes + 1)
        except OSError as exc:
            raise error(f"{path}: cannot read ({exc.strerror or exc.__class__.__name__})") from None
    if len(data) > max_bytes:
        raise LimitError(f"{path}: over the limit of {max_bytes:,} bytes for a {what} file ({hint(limit)})")
    return data


def read_yaml(path: str | Path, error: type[PlantgenError] = PlantgenError, limits: Limits | None = None):
    """Read a YAML file, turning every failure into one ``error`` line naming the file
    (and the line, for a syntax error or a document over its bounds).

    The bounds (``limits``: ``max_input_bytes``, ``max_yaml_depth``, ``max_yaml_nodes``)
    are checked on the parser's events, before a node is composed or a value built."""
    limits = limits or default_limits
    data = read_input(path, error, max_bytes=limits.max_input_bytes, limit="input_bytes", what="YAML")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: cannot read (not UTF-8 text: byte {exc.start})") from None
    try:
        _bound_document(yaml.parse(text, Loader=_LOADER), limits, str(path), error)
        return yaml.load(text, Loader=_LOADER)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f" line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise error(f"{path}:{line}: YAML error: {problem}") from None
    except (ValueError, OverflowError, TypeError, RecursionError) as exc:   # a value PyYAML cannot build
        raise error(f"{path}: YAML error: cannot read a value ({str(exc).splitlines()[0][:100]})") from None


def _bound_document(events, limits: Limits, path: str, error: type[PlantgenError]) -> None:
    """Refuse a YAML event stream whose document, aliases expanded, is deeper than
    ``max_yaml_depth`` or larger than ``max_yaml_nodes`` (a node counts one, a scalar one
    more per character), or whose alias refers to a node that contains it.

    One pass over the events: each finished node's expanded size and height are kept per
    anchor, so an alias costs what it would expand to without expanding it."""
    stack: list[list] = []        # open collections: [anchor, size, height]
    finished: dict = {}           # anchor -> (size, height)
    open_anchors: set = set()
    max_nodes, max_depth = limits.max_yaml_nodes, limits.max_yaml_depth
    for event in events:
        line = event.start_mark.line + 1 if event.start_mark is not None else 0
        if isinstance(event, yaml.CollectionStartEvent):
            if len(stack) >= max_depth:
                raise LimitError(f"{path}: line {line}: YAML nested deeper than {max_depth} levels "
                                 f"({hint('yaml_depth')})")
            stack.append([event.anchor, 1, 1])
            if event.anchor is not None:
                finished.pop(event.anchor, None)
                open_anchors.add(event.anchor)
            continue
        if isinstance(event, yaml.ScalarEvent):
            anchor, node = event.anchor, (1 + len(event.value), 1)
        elif isinstance(event, yaml.AliasEvent):
            if event.anchor in open_anchors or event.anchor not in finished:
                kind = "inside the node it names" if event.anchor in open_anchors else "to no anchor"
                raise error(f"{path}: line {line}: YAML error: alias *{event.anchor} {kind}")
            anchor, node = None, finished[event.anchor]
        elif isinstance(event, yaml.CollectionEndEvent):
            anchor, size, height = stack.pop()
            node = (size, height)
            open_anchors.discard(anchor)
        else:
            continue
        if anchor is not None:
            finished[anchor] = node
        depth = len(stack) + node[1]
        size = node[0] + (stack[-1][1] if stack else 0)
        if depth > max_depth:
            raise LimitError(f"{path}: line {line}: YAML nested deeper than {max_depth} levels once "
                             f"its aliases are expanded ({hint('yaml_depth')})")
        if size > max_nodes:
            raise LimitError(f"{path}: line {line}: YAML document over {max_nodes:,} nodes once its "
                             f"aliases are expanded ({hint('yaml_nodes')})")
        if stack:
            stack[-1][1] = size
            stack[-1][2] = max(stack[-1][2], node[1] + 1)


def temporary_name(path: str | Path) -> Path:
    """The hidden name ``path`` is written under before the rename: ``.NAME.partSUFFIX``
    (the suffix stays last, so writers that pick a format by suffix still can)."""
    path = Path(path)
    return path.with_name(f".{path.name}.part{path.suffix}")


def write_atomically(path: str | Path, write: Callable[[Path], object],
                     error: type[PlantgenError] = PlantgenError) -> Path:
    """Call ``write(tmp_path)``, then rename the temporary file onto ``path``.

    Nothing half-written survives: on any failure the temporary file is removed; an
    ``OSError`` becomes one ``error`` line naming ``path``. Returns ``path``.
    """
    path = Path(path)
    tmp = temporary_name(path)
    try:
        write(tmp)
        tmp.replace(path)
    except OSError as exc:
        _discard(tmp)
        raise error(f"{path}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        _discard(tmp)
        raise
    return path


def _discard(tmp: Path) -> None:
    """Remove a temporary file if it is there; an error doing so (a read-only file system
    refuses even to unlink a name that is not there) does not hide the first one."""
    with contextlib.suppress(OSError):
        tmp.unlink(missing_ok=True)


def write_all_atomically(writes: list[tuple[str | Path, Callable[[Path], object]]],
                         error: type[PlantgenError] = PlantgenError) -> list[Path]:
    """:func:`write_atomically` for files that belong together (an OBJ and its MTL, a glTF
    and its ``.bin``): every ``write(tmp_path)`` runs first, then the temporary files are
    renamed onto their targets in the given order (put the file that names the others
    last). On any failure no temporary file is left, and no target is touched unless the
    failure comes between two renames; then the targets this call created are removed
    again (an existing file already replaced stays replaced). Returns the paths."""
    done: list[tuple[Path, Path]] = []
    created: list[Path] = []
    failing = None
    try:
        for path, write in writes:
            path = failing = Path(path)
            done.append((path, temporary_name(path)))
            write(done[-1][1])
        for path, tmp in done:
            failing, new = path, not path.exists()
            tmp.replace(path)
            if new:
                created.append(path)
    except OSError as exc:
        for path in [tmp for _, tmp in done] + created:
            _discard(path)
        raise error(f"{failing or writes[0][0]}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        for path in [tmp for _, tmp in done] + created:
            _discard(path)
        raise
    return [path for path, _ in done]
