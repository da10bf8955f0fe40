"""``plantgen list``: the shipped grammars and scenes, with their descriptions, and their
sizes on request.

The listing reads each file's own description and grows nothing, so it is as quick cold as
warm (issue 45: growing them all took 52 s the first time). ``--segments`` adds each
model's segment count, the model grown at its own seed (a scene: every copy placed).
Growing all of them takes seconds (the forest alone places six million segments), so the
counts are kept in a small cache in the user's cache folder (``$XDG_CACHE_HOME/plantgen``,
else ``~/.cache/plantgen``), each keyed on plantgen's version and the bytes of every file
the model reads (the file and a scene's grammars): an edited grammar is grown again, and a
cache that cannot be read or written only costs the time.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from pathlib import Path

import click

from .. import __version__
from .._resources import grammars_dir, shipped_names
from ..files import read_yaml, write_atomically
from ..pipeline import grow_file
from .progress import StageBars

__all__ = ["cache_path", "list_models", "shipped_models"]


def cache_path() -> Path:
    """The file the segment counts are cached in."""
    root = os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")   # never raises
    return Path(root) / "plantgen" / "list.json"


def _digest(sources) -> str | None:
    """A digest of plantgen's version and the bytes of ``sources``; None if one is unreadable."""
    h = hashlib.sha256(__version__.encode())
    try:
        for source in sources:
            h.update(Path(source).read_bytes())
    except OSError:
        return None
    return h.hexdigest()


def _read_cache(path: Path) -> dict:
    with contextlib.suppress(OSError, ValueError):
        data = json.loads(path.read_text())
        if isinstance(data, dict):
            return data
    return {}


def shipped_models(progress=None, *, segments: bool = False) -> list[dict]:
    """``{"name", "kind", "description"}`` of every shipped grammar and scene, sorted by
    name, read from the files alone; with ``segments``, also each one's ``"segments"``,
    from the cache where it holds them for these very files, else grown."""
    names = shipped_names()
    rows = []
    for name in names:
        data = read_yaml(grammars_dir() / f"{name}.yaml")
        kind = "scene" if isinstance(data, dict) and "instances" in data else "grammar"
        description = str(data.get("description", "")) if isinstance(data, dict) else ""
        rows.append({"name": name, "kind": kind, "description": description})
    if segments:
        _add_segments(rows, progress)
    return rows


def _add_segments(rows: list[dict], progress=None) -> None:
    """Each row's ``"segments"``: cached counts where the cache holds them for these very
    files, else the model grown at its own seed (and the cache written)."""
    path = cache_path()
    cache = _read_cache(path)
    for k, row in enumerate(rows):
        name = row["name"]
        entry = cache.get(name)
        if not (isinstance(entry, dict) and entry.get("digest") and
                entry.get("digest") == _digest(entry.get("sources", ()))):
            if progress is not None:
                progress("grow", k, len(rows))
            grown = grow_file(grammars_dir() / f"{name}.yaml")
            sources = [str(s) for s in grown.sources]
            entry = cache[name] = {"segments": grown.segments, "sources": sources, "digest": _digest(sources)}
        row["segments"] = int(entry["segments"])
    if cache != _read_cache(path):
        with contextlib.suppress(Exception):      # a cache that cannot be written costs only time
            path.parent.mkdir(parents=True, exist_ok=True)
            write_atomically(path, lambda tmp: tmp.write_text(json.dumps(cache, indent=1)))


@click.command("list")
@click.option("--segments", is_flag=True,
              help="Also count each model's segments, grown at its own seed (a scene: every copy placed). "
                   "The first time this grows every model (about a minute); the counts are then cached.")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON list of {name, kind, description} "
                                                      "(and segments, with --segments).")
def list_models(segments: bool, as_json: bool) -> None:
    """List the shipped grammars and scenes: each one's name (what every command and
    plantgen.grow take, from any folder), kind and description, read from the files
    (nothing is grown).

    \b
    Examples:
      plantgen list
      plantgen render ocotillo                  # writes ocotillo.png
      plantgen list --segments --json
    """
    if segments:
        with StageBars() as bars:
            rows = shipped_models(bars, segments=True)
    else:
        rows = shipped_models()
    if as_json:
        click.echo(json.dumps(rows, indent=1))
        return
    width = max(len(r["name"]) for r in rows)
    count = (lambda r: f"  {r['segments']:>9,}") if segments else (lambda r: "")
    click.echo(f"{'NAME':<{width}}  {'KIND':<7}{'   SEGMENTS' if segments else ''}  DESCRIPTION")
    for r in rows:
        click.echo(f"{r['name']:<{width}}  {r['kind']:<7}{count(r)}  {r['description']}")
