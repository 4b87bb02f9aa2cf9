"""The ``provenance`` object of every JSON document overbound writes (``summary.json``, ``map.json``,
``pl-only.json``): the overbound version, the command line and the options with every path reduced
to its base name, and each input's base name, size and SHA-256, so that the same inputs give the
same bytes from any folder.

Kept apart from :mod:`overbound.report.json` so that a document that is not a summary (the SBAS maps)
does not import the analysis to describe its inputs.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from overbound import __version__

__all__ = ["base_names", "base_value", "base_word", "file_digest", "provenance_dict"]


def file_digest(path: str | Path) -> dict:
    """``{name, size, sha256}`` of an input file: its base name only (the same JSON from any folder)."""
    path = Path(path)
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return {"name": path.name, "size": path.stat().st_size, "sha256": h.hexdigest()}


def provenance_dict(
    inputs: list[str | Path] | tuple = (), command: list[str] | None = None, options: dict | None = None
) -> dict:
    """The ``provenance`` object: overbound version, the command line (paths reduced to their base
    names), the options (as JSON values, paths as base names, times in ISO 8601, other objects as
    their text) and each input file's base name, size and SHA-256."""
    files = [file_digest(p) for p in inputs if isinstance(p, str | Path) and Path(p).is_file()]
    return {
        "overbound_version": __version__,
        "command": None if command is None else [base_word(a) for a in command],
        "options": {k: base_value(v) for k, v in (options or {}).items()},
        "inputs": files,
    }


def base_word(arg: str) -> str:
    """A command-line word with any path reduced to its base name (``/x/in.pos`` -> ``in.pos``,
    ``--out=/x/dir`` -> ``--out=dir``, ``s3://bucket/x/net`` -> ``net``); an address without a path
    stays whole (``tcp://host:8786``)."""
    if "=" in arg and arg.startswith("--"):
        key, value = arg.split("=", 1)
        return f"{key}={base_word(value)}"
    scheme, sep, rest = arg.partition("://")
    if sep and scheme.isalnum() and "/" not in rest.rstrip("/"):  # an address (tcp://host:8786), no path
        return arg
    if "/" in arg or "\\" in arg:
        return Path(arg).name or arg
    return arg


def base_value(v):
    """An option value as JSON: paths as base names, times in ISO 8601, other objects as their text."""
    if isinstance(v, Path):
        return v.name
    if isinstance(v, str):
        return base_word(v)
    if isinstance(v, list | tuple):
        return [base_value(x) for x in v]
    if isinstance(v, dict):
        return {str(k): base_value(x) for k, x in v.items()}
    if isinstance(v, bool | int | float) or v is None:
        return v
    return v.isoformat() if hasattr(v, "isoformat") else str(v)


def base_names(source: str) -> str:
    """A source text (``a/b.pos, c/d.pos``) with every path reduced to its base name."""
    return ", ".join(Path(p.strip()).name or p.strip() for p in str(source).split(","))
