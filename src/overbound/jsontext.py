"""Deterministic JSON text: the one serialisation of every document overbound writes.

Keys are sorted and floats are written with 12 significant digits, so that the same inputs give
the same bytes on every run. NaN and infinities become ``null``. Lowest layer: the methods write
their documents with it, the report reuses it.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["IsoTimes", "dump", "dumps", "to_jsonable"]

_DIGITS = 12


class IsoTimes(Sequence[str]):
    """GPS times that read as ISO 8601 strings at millisecond precision (``2024-01-07T00:00:00.000``),
    held as int64 microseconds (floored to the millisecond) and formatted only when read or written.

    A campaign's PL-band samples are some 10 million epochs: as Python strings about 800 MB, as
    integers 80 MB. Compares equal to the tuple or list of its strings.
    """

    __slots__ = ("us",)
    _BLOCK = 1 << 16  # strings formatted at a time while written

    def __init__(self, us: np.ndarray | Sequence[int]) -> None:
        self.us = np.asarray(us, dtype=np.int64) // 1000 * 1000

    @classmethod
    def parse(cls, texts: Sequence[str]) -> IsoTimes:
        """From ISO 8601 strings (the JSON form)."""
        return cls(np.array(list(texts), dtype="datetime64[us]").view(np.int64))

    def __len__(self) -> int:
        return int(self.us.size)

    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return IsoTimes(self.us[i])
        return _iso(self.us[[i]])[0]

    def __iter__(self) -> Iterator[str]:
        for a in range(0, self.us.size, self._BLOCK):
            yield from _iso(self.us[a : a + self._BLOCK])

    def __eq__(self, other: object) -> bool:
        if isinstance(other, IsoTimes):
            return bool(np.array_equal(self.us, other.us))
        if isinstance(other, list | tuple):
            return len(other) == len(self) and all(a == b for a, b in zip(self, other, strict=True))
        return NotImplemented

    def __hash__(self) -> int:
        return hash(self.us.tobytes())

    def __repr__(self) -> str:
        return f"IsoTimes({len(self)} times)"


def _iso(us: np.ndarray) -> list[str]:
    return np.datetime_as_string(us.astype("datetime64[us]"), unit="ms").tolist()


class _WrittenLazily(list):
    """A list to json's pure-Python encoder (the one ``indent`` selects) whose items are made while
    it writes them: the strings of an :class:`IsoTimes` never all exist at once."""

    def __init__(self, items: Sequence) -> None:
        super().__init__()
        self._items = items

    def __iter__(self):
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __getitem__(self, i):  # read like the plain list it stands for
        return list(self._items)[i]

    def __eq__(self, other: object) -> bool:
        return list(self._items) == other

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return repr(list(self._items))


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
    if isinstance(obj, IsoTimes):
        return _WrittenLazily(obj)
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


def dump(doc: dict, path: str | Path) -> Path:
    """:func:`dumps` written to ``path`` as it is made (the same bytes, without the whole text in memory)."""
    encoder = json.JSONEncoder(sort_keys=True, indent=2, allow_nan=False)
    path = Path(path)
    with path.open("w", encoding="utf-8") as f:
        f.writelines(encoder.iterencode(to_jsonable(doc)))
        f.write("\n")
    return path
