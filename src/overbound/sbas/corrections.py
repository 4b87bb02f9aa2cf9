"""SBAS message state at the user's epochs: as-of look-ups of the decoded tables (DO-229D A.4).

Time model (the same for every look-up):

* ``tag`` is the reader's time of a message, for EMS the end of its one-second transmission slot;
* a message is *available* at epoch t once ``tag + flight`` <= t (``flight``: GEO signal flight
  time, 0.12 s by default as in gLAB); every time-out compares t - (tag + flight) with the limit;
* a correction's *time of applicability* is the start of the transmission second, tag - 1 s
  (DO-229D A.4.4.3: t_of; MT 12's time of week confirms the offset on the EGNOS day), used in
  the range-rate propagation and the degradation terms.

:func:`asof` is the one vectorised primitive: for query keys and times, the last table row with
the same key available at that time, by one ``searchsorted`` on (key, time)-sorted rows.
"""

from __future__ import annotations

import numpy as np
import polars as pl

__all__ = [
    "US", "asof", "earliest_within", "packed_order", "previous_other_value", "previous_same_key", "segments",
    "times_us",
]  # fmt: skip

US = 1_000_000
_SPAN = np.int64(1) << np.int64(42)  # 50 days of microseconds: key in the upper bits


def times_us(col: pl.Series) -> np.ndarray:
    """A Datetime column as int64 microseconds."""
    return col.dt.epoch("us").to_numpy().astype(np.int64)


def packed_order(key_tab: np.ndarray, t_tab: np.ndarray, base: int) -> tuple[np.ndarray, np.ndarray]:
    """The stable order of the table's rows by (key, time) packed into one int64, and those packed values
    in that order.

    Pass the pair as ``packed=`` to several look-ups of one table (:func:`asof`,
    :func:`previous_same_key`, :func:`earliest_within`) to sort it once. A table in time order (the
    decoded messages are) with keys below 2^16 is sorted by key alone, by a radix sort: the same
    order, as the sort is stable.
    """
    key_tab = np.asarray(key_tab, np.int64)
    t_tab = np.asarray(t_tab, np.int64)
    packed = key_tab * _SPAN + np.clip(t_tab - base, 0, _SPAN - 1)
    if key_tab.size and key_tab.min() >= 0 and key_tab.max() < 1 << 16 and (t_tab[1:] >= t_tab[:-1]).all():
        order = np.argsort(key_tab.astype(np.uint16), kind="stable")
    else:
        order = np.argsort(packed, kind="stable")
    return order, packed[order]


def asof(key_tab: np.ndarray, t_tab: np.ndarray, key_q: np.ndarray, t_q: np.ndarray, base: int, *,
         packed: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:  # fmt: skip
    """Row of the table with ``key_tab == key_q`` and the largest ``t_tab <= t_q`` (-1 if none).

    Ties in time keep the last row in table order. Times are int64 microseconds; ``base`` is
    subtracted so that (key, time) packs into one int64 (keys below 2^21). ``packed``: the
    table's :func:`packed_order`, when it is already at hand.
    """
    key_tab = np.asarray(key_tab, np.int64)
    if key_tab.size == 0:  # e.g. no MT 6 in a short window
        return np.full(np.shape(key_q), -1, np.int64)
    order, sp = packed or packed_order(key_tab, t_tab, base)
    kq = np.asarray(key_q, np.int64)
    q = kq * _SPAN + _offset(t_q, base)
    pos = np.searchsorted(sp, q, side="right") - 1
    row = order[np.maximum(pos, 0)]
    return np.where((pos >= 0) & (key_tab[row] == kq), row, -1)


def _offset(t: np.ndarray, base: int) -> np.ndarray:
    """``t - base`` clipped to the packing range (the clip, a full pass, only when something is outside)."""
    d = np.asarray(t, np.int64) - base
    if d.size and (d.min() < 0 or d.max() > _SPAN - 1):
        d = np.clip(d, 0, _SPAN - 1)
    return d


def previous_same_key(key_tab: np.ndarray, t_tab: np.ndarray, base: int, *,
                      packed: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:  # fmt: skip
    """For every row, the row before it in (key, time) order with the same key (-1 if none).

    ``packed``: the table's :func:`packed_order`, when it is already at hand.
    """
    key_tab = np.asarray(key_tab, np.int64)
    order = (packed or packed_order(key_tab, t_tab, base))[0]
    prev = np.full(key_tab.size, -1, np.int64)
    same = key_tab[order][1:] == key_tab[order][:-1]
    prev[order[1:][same]] = order[:-1][same]
    return prev


def earliest_within(
    key_tab: np.ndarray,
    t_tab: np.ndarray,
    rows: np.ndarray,
    window_us: np.ndarray,
    base: int,
    *,
    packed: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """For query rows of the table, the earliest earlier row of the same key less than ``window_us`` older.

    That is the previous row whose time difference is the largest one below the window (-1 if
    there is none, or for ``rows < 0``): the IODF = 3 rule of DO-229D A.4.4.3 with the window
    I_fc / 2. ``packed``: the table's :func:`packed_order`, when it is already at hand.
    """
    key_tab = np.asarray(key_tab, np.int64)
    t_tab = np.asarray(t_tab, np.int64)
    rows = np.asarray(rows, np.int64)
    if key_tab.size == 0:
        return np.full(rows.shape, -1, np.int64)
    order, sp = packed or packed_order(key_tab, t_tab, base)
    r = np.maximum(rows, 0)
    lo = np.nan_to_num(t_tab[r] - np.asarray(window_us, float), nan=np.inf)
    lo = np.clip(lo, base, base + _SPAN - 1).astype(np.int64)
    pos = np.searchsorted(sp, key_tab[r] * _SPAN + (lo - base), side="right")
    cand = order[np.minimum(pos, sp.size - 1)]
    ok = (rows >= 0) & (pos < sp.size) & (key_tab[cand] == key_tab[r]) & (t_tab[cand] < t_tab[r])
    return np.where(ok, cand, -1)


def previous_other_value(
    key_tab: np.ndarray, value_tab: np.ndarray, t_tab: np.ndarray, base: int
) -> np.ndarray:
    """For every row, the latest earlier row with the same key and a different value (-1 if none).

    Used for the long-term corrections of the previous IODE: in (key, time) order the rows form
    runs of equal value, and the row wanted is the last one of the run before the row's own.
    """
    key_tab = np.asarray(key_tab, np.int64)
    value_tab = np.asarray(value_tab, np.int64)
    packed = key_tab * _SPAN + np.clip(np.asarray(t_tab, np.int64) - base, 0, _SPAN - 1)
    order = np.argsort(packed, kind="stable")
    k, v = key_tab[order], value_tab[order]
    start = np.ones(k.size, bool)
    start[1:] = (k[1:] != k[:-1]) | (v[1:] != v[:-1])
    run_first = np.flatnonzero(start)[np.cumsum(start) - 1]  # sorted index of each row's run start
    before = run_first - 1
    ok = (before >= 0) & (k[np.maximum(before, 0)] == k)
    out = np.full(key_tab.size, -1, np.int64)
    out[order[ok]] = order[before[ok]]
    return out


def segments(tag_us: np.ndarray, max_missing: int = 4) -> np.ndarray:
    """Segment number of each message: a new segment starts after ``max_missing`` or more lost messages.

    DO-229D (2.1.1.4.12 / A.4.4.x): after four consecutive missed messages the user treats every
    fast correction as not monitored, so fast-correction history never spans such a gap.
    """
    tag_us = np.asarray(tag_us, np.int64)
    gap = np.diff(tag_us, prepend=tag_us[:1]) // US - 1 >= max_missing
    return np.cumsum(gap)
