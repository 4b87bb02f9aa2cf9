"""Deterministic JSON text: the one serialisation of every document overbound writes.

Keys are sorted and floats are written with 12 significant digits, so that the same inputs give
the same bytes on every run. NaN and infinities become ``null``. Lowest layer: the methods write
their documents with it, the report reuses it.
"""

from __future__ import annotations

import dataclasses
import json
import math
from typing import Any

import numpy as np

__all__ = ["dumps", "to_jsonable"]

_DIGITS = 12


def to_jsonable(obj: Any) -> Any:
    """Plain JSON types: dataclasses to dicts, numpy scalars to Python, NaN to None, floats to 12 digits."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [to_jsonable(v) for v in obj.tolist()]
    if isinstance(obj, bool | np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        x = float(obj)
        return float(f"{x:.{_DIGITS}g}") if math.isfinite(x) else None
    return obj


def dumps(doc: dict) -> str:
    """Deterministic JSON text (sorted keys, two-space indent, trailing newline)."""
    return json.dumps(to_jsonable(doc), sort_keys=True, indent=2, allow_nan=False) + "\n"
