"""Files in and out, in one place: reading input files and writing outputs atomically.

Every output plantgen writes goes through :func:`write_atomically` (or, for the files of
one command that belong together, :func:`write_all_atomically`): the bytes go to a hidden
temporary name beside the target, which is renamed onto it only when complete, so a
failure never leaves a half-written file, and the outputs of one command are renamed
together at the end (all of them, or none).

Every output is checked by :func:`check_output` before any work (each command calls it
for every file it will write, and the writers call it again just before they write),
with one wording, ``PATH: cannot write (REASON)``: the folder must exist, be a folder
and be writable; the name must hold no control character (files name each other: an
OBJ its MTL); the target must not be a folder; and a target that is not a regular
file (a device such as ``/dev/null``, a FIFO, a socket, a link to one) is refused,
never renamed over nor written through. A link to a regular file is replaced by the new
file (the file it pointed to is left as it was).

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

import numpy as np
import yaml

from .errors import PlantgenError
from .limits import LimitError, Limits, hint
from .limits import limits as default_limits

__all__ = ["check_finite", "check_folder", "check_output", "check_outputs", "escape_text", "open_input", "read_input",
           "read_text", "read_yaml", "real_path", "temporary_name", "unescape_text", "write_all_atomically",
           "write_atomically"]

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


def read_text(path: str | Path, error: type[PlantgenError], limits: Limits, what: str) -> str:
    """The UTF-8 text of the regular file ``path``, at most ``limits.max_input_bytes``
    (:func:`read_input`); bytes that are not UTF-8 are one ``error`` line."""
    data = read_input(path, error, max_bytes=limits.max_input_bytes, limit="input_bytes", what=what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: cannot read (not UTF-8 text: byte {exc.start})") from None


def read_yaml(path: str | Path, error: type[PlantgenError] = PlantgenError, limits: Limits | None = None):
    """Read a YAML file, turning every failure into one ``error`` line naming the file
    (and the line, for a syntax error or a document over its bounds).

    The bounds (``limits``: ``max_input_bytes``, ``max_yaml_depth``, ``max_yaml_nodes``)
    are checked on the parser's events, before a node is composed or a value built."""
    limits = limits or default_limits
    text = read_text(path, error, limits, "YAML")
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


def real_path(path: str | Path) -> Path:
    """``path`` with every link followed, as :meth:`Path.resolve` but never raising: a link
    loop (a file linked to itself) stays as it is, and opening it then fails in one line."""
    return Path(os.path.realpath(path))


def temporary_name(path: str | Path) -> Path:
    """The hidden name ``path`` is written under before the rename: ``.NAME.partSUFFIX``
    (the suffix stays last, so writers that pick a format by suffix still can)."""
    path = Path(path)
    return path.with_name(f".{path.name}.part{path.suffix}")


def _cannot(path, reason: str, error: type[PlantgenError]):
    """The one wording of an output plantgen cannot write."""
    raise error(f"{path}: cannot write ({reason})")


def check_output(path: str | Path, error: type[PlantgenError] = PlantgenError) -> Path:
    """``path`` if plantgen can write it, checked before any work; else one ``error`` line
    ``PATH: cannot write (REASON)``: no such folder, the folder is not a folder or not
    writable, the target (or its temporary name) is a folder, or it is not a regular file
    (a device, a FIFO, a socket: refused, never replaced). Returns ``path`` as a Path."""
    path = Path(path)
    if path.name in ("", ".", ".."):
        _cannot(path, "it is a folder", error)
    if not path.name.isprintable():      # a line break or an ESC would end up inside the files that name it
        _cannot(escape_text(str(path)), "its name holds a control character", error)
    _check_folder(path, path.parent, error)
    for target, what in ((path, "it"), (temporary_name(path), f"its temporary name '{temporary_name(path).name}'")):
        try:
            mode = os.stat(target).st_mode
        except FileNotFoundError:     # not there (or a dangling link, replaced by the rename)
            continue
        except OSError as exc:        # a link loop, a name too long
            _cannot(path, f"{what}: {exc.strerror or exc.__class__.__name__}", error)
        if stat.S_ISDIR(mode):
            _cannot(path, f"{what} is a folder", error)
        if not stat.S_ISREG(mode):
            _cannot(path, f"{what} is not a regular file; plantgen never replaces a device, pipe or socket", error)
    return path


def check_finite(path: str | Path, what: str, *arrays, error: type[PlantgenError] = PlantgenError) -> None:
    """One ``error`` line ``PATH: cannot write (WHAT holds a number that is not finite)``
    if any of ``arrays`` does: no writer writes NaN or infinity (a depth map's misses,
    ``inf`` by its contract, are the one exception)."""
    for values in arrays:
        if values is not None and not np.isfinite(np.asarray(values, dtype=np.float64)).all():
            _cannot(path, f"{what} holds a number that is not finite (lower the scale or the noise)", error)


def _check_folder(path: Path, folder: Path, error: type[PlantgenError]) -> None:
    try:
        st = os.stat(folder)
    except (FileNotFoundError, NotADirectoryError):
        _cannot(path, f"no such folder '{folder}'", error)
    except OSError as exc:
        _cannot(path, f"folder '{folder}': {exc.strerror or exc.__class__.__name__}", error)
    if not stat.S_ISDIR(st.st_mode):
        _cannot(path, f"'{folder}' is not a folder", error)
    if not os.access(folder, os.W_OK | os.X_OK):
        _cannot(path, f"permission denied in '{folder}'", error)


def check_folder(folder: str | Path, error: type[PlantgenError] = PlantgenError) -> Path:
    """``folder`` if plantgen can write files into it (there, a folder, writable), in
    :func:`check_output`'s wording; else one ``error`` line."""
    folder = Path(folder)
    _check_folder(folder, folder, error)
    return folder


def check_outputs(paths, error: type[PlantgenError] = PlantgenError) -> list[Path]:
    """:func:`check_output` for each of ``paths`` (None skipped), and no path named twice."""
    out: list[Path] = []
    for path in paths:
        if path is None:
            continue
        path = check_output(path, error)
        if any(os.path.abspath(path) == os.path.abspath(p) for p in out):
            _cannot(path, "named twice among the outputs", error)
        out.append(path)
    return out


def _fresh_temporary(path: Path, error: type[PlantgenError]) -> Path:
    """The temporary name of ``path``, checked (:func:`check_output`) and cleared of a file
    or link a failed run left (writing through a stale link would write where it points)."""
    check_output(path, error)
    tmp = temporary_name(path)
    if os.path.lexists(tmp):
        _discard(tmp)
    return tmp


def write_atomically(path: str | Path, write: Callable[[Path], object],
                     error: type[PlantgenError] = PlantgenError) -> Path:
    """Call ``write(tmp_path)``, then rename the temporary file onto ``path``.

    ``path`` is checked first (:func:`check_output`). Nothing half-written survives: on
    any failure the temporary file is removed; an ``OSError`` becomes one ``error`` line
    naming ``path``. Returns ``path``.
    """
    return write_all_atomically([(path, write)], error)[0]


def _discard(tmp: Path) -> None:
    """Remove a temporary file if it is there; an error doing so (a read-only file system
    refuses even to unlink a name that is not there) does not hide the first one."""
    with contextlib.suppress(OSError):
        tmp.unlink(missing_ok=True)


def write_all_atomically(writes: list[tuple[str | Path, Callable[[Path], object]]],
                         error: type[PlantgenError] = PlantgenError) -> list[Path]:
    """:func:`write_atomically` for files that belong together (an OBJ and its MTL, a glTF
    and its ``.bin``, an image and its camera and depth): every target is checked
    (:func:`check_outputs`), every ``write(tmp_path)`` runs, then the temporary files are
    renamed onto their targets in the given order (put the file that names the others
    last), each target checked again just before. On any failure no temporary file is
    left, and no target is touched unless the failure comes between two renames; then the
    targets this call created are removed again (an existing file already replaced stays
    replaced). Returns the paths."""
    check_outputs([path for path, _ in writes], error)
    done: list[tuple[Path, Path]] = []
    created: list[Path] = []
    failing = None
    try:
        for path, write in writes:
            path = failing = Path(path)
            done.append((path, _fresh_temporary(path, error)))
            write(done[-1][1])
        for path, tmp in done:
            failing = path
            check_output(path, error)
            new = not os.path.lexists(path)
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


_ESCAPES = {"\\": "\\\\", "\n": "\\n", "\r": "\\r", "\t": "\\t"}


def escape_text(text: str, *, ascii_only: bool = False) -> str:
    """``text`` safe to write into one line of a text file: a backslash, a line break, a
    tab and every other character that is not printable (ESC, BEL, a line separator)
    become an escape (``\\n``, ``\\x1b``, ``\\u2028``), and with ``ascii_only`` every
    character beyond ASCII too. :func:`unescape_text` reads it back."""
    out = []
    for ch in str(text):
        if ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ch.isprintable() and (ord(ch) < 128 or not ascii_only):
            out.append(ch)
        else:
            code = ord(ch)
            out.append(f"\\x{code:02x}" if code < 256 else f"\\u{code:04x}" if code < 65536 else f"\\U{code:08x}")
    return "".join(out)


def unescape_text(text: str) -> str:
    """The text :func:`escape_text` wrote (text with a malformed escape is kept as it is)."""
    if "\\" not in text:
        return text
    try:
        return text.encode("ascii", "backslashreplace").decode("unicode_escape")
    except (UnicodeDecodeError, UnicodeEncodeError):
        return text
