"""``plantgen list``: the shipped grammars and scenes, with their descriptions and sizes.

A segment count is the model grown at its own seed (a scene: every copy placed). Growing
all of them takes seconds (the forest alone places six million segments), so the counts
are kept in a small cache in the user's cache folder (``$XDG_CACHE_HOME/plantgen``, else
``~/.cache/plantgen``), each keyed on plantgen's version and the bytes of every file the
model reads (the file and a scene's grammars): an edited grammar is grown again, and a
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


def shipped_models(progress=None) -> list[dict]:
    """``{"name", "kind", "segments", "description"}`` of every shipped grammar and scene,
    sorted by name; the counts come from the cache where it holds them for these very files."""
    cache, path = None, cache_path()
    names = shipped_names()
    rows = []
    for k, name in enumerate(names):
        data = read_yaml(grammars_dir() / f"{name}.yaml")
        kind = "scene" if isinstance(data, dict) and "instances" in data else "grammar"
        description = str(data.get("description", "")) if isinstance(data, dict) else ""
        if cache is None:
            cache = _read_cache(path)
        entry = cache.get(name)
        if not (isinstance(entry, dict) and entry.get("digest") and
                entry.get("digest") == _digest(entry.get("sources", ()))):
            if progress is not None:
                progress("grow", k, len(names))
            grown = grow_file(grammars_dir() / f"{name}.yaml")
            sources = [str(s) for s in grown.sources]
            entry = cache[name] = {"segments": grown.segments, "sources": sources, "digest": _digest(sources)}
        rows.append({"name": name, "kind": kind, "segments": int(entry["segments"]), "description": description})
    if cache is not None and cache != _read_cache(path):
        with contextlib.suppress(Exception):      # a cache that cannot be written costs only time
            path.parent.mkdir(parents=True, exist_ok=True)
            write_atomically(path, lambda tmp: tmp.write_text(json.dumps(cache, indent=1)))
    return rows


@click.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON list of {name, kind, segments, description}.")
def list_models(as_json: bool) -> None:
    """List the shipped grammars and scenes: each one's name (what every command and
    plantgen.grow take, from any folder), kind, segments at its own seed (a scene: every
    copy placed) and description.

    \b
    Examples:
      plantgen list
      plantgen render ocotillo                  # writes ocotillo.png
      plantgen list --json
    """
    with StageBars() as bars:
        rows = shipped_models(bars)
    if as_json:
        click.echo(json.dumps(rows, indent=1))
        return
    width = max(len(r["name"]) for r in rows)
    click.echo(f"{'NAME':<{width}}  {'KIND':<7}  {'SEGMENTS':>9}  DESCRIPTION")
    for r in rows:
        click.echo(f"{r['name']:<{width}}  {r['kind']:<7}  {r['segments']:>9,}  {r['description']}")
