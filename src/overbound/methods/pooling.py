"""Solution epochs of one axis pooled over stations on one time axis.

The dependence-aware methods (tail extrapolation, parametric fits) need one regular time
axis for the autocorrelation and for declustering. Stations are placed one after the other,
a day (a whole number of sampling intervals) apart, so that no lag and no cluster spans two
stations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import polars as pl

from overbound.io.schema import InputError, as_numpy
from overbound.stats.dependence import interval_from_steps, step_counts

__all__ = [
    "PE_PL",
    "PooledEpochs",
    "alert_flags",
    "axis_columns",
    "pool_epochs",
    "pooled_offsets",
    "solution_rows",
    "unavailable_at_alerts",
]

#: Position-error and protection-level columns of each axis.
PE_PL = {"vertical": ("vpe", "vpl"), "horizontal": ("hpe", "hpl")}
_DAY_US = 86_400_000_000


@dataclass(frozen=True, slots=True)
class PooledEpochs:
    """Solution epochs (finite PE, PL > 0) of one axis, stations one after the other.

    Attributes
    ----------
    t_us : pooled time of each epoch (µs); strictly increasing within a station.
    day : station-day block id (changes at each UTC day and each station).
    station : station code of each epoch (0, 1, ... in the order of the pooled axis).
    pe : position error; ``|PE|`` unless pooled with ``signed=True``.
    pl : protection level (> 0).
    alert : the receiver's alert flag (``False`` when the table has none).
    n_rows : rows of the table.
    n_no_solution : rows left out (PE or PL missing, PL <= 0).
    n_stations : stations.
    interval_us : nominal sampling interval (µs).
    """

    t_us: np.ndarray
    day: np.ndarray
    station: np.ndarray
    pe: np.ndarray
    pl: np.ndarray
    alert: np.ndarray
    n_rows: int
    n_no_solution: int
    n_stations: int
    interval_us: int


def _interval_us(t: np.ndarray, codes: np.ndarray) -> int:
    """The nominal interval of the pooled series: :func:`~overbound.stats.dependence.nominal_interval_us`'s
    rule (the mean of the steps within 25 % of their median) over the steps within each station,
    from their value counts, so that a series read a station-day at a time has the same."""
    steps = np.diff(t)[np.diff(codes) == 0]
    return interval_from_steps(*step_counts(steps)) or 1_000_000


def pooled_offsets(first: np.ndarray, last: np.ndarray, dt: int) -> np.ndarray:
    """Where each station starts on the pooled axis (µs), from the first and last times of its
    solution epochs, in pooled order: the stations one after the other, each span rounded up to a
    whole number of intervals ``dt`` and followed by a day (also a whole number of intervals)."""
    span = np.asarray(last, dtype=np.int64) - np.asarray(first, dtype=np.int64)
    gap = ((_DAY_US + dt - 1) // dt) * dt
    return np.concatenate([[0], np.cumsum(((span + dt - 1) // dt) * dt + gap)[:-1]]).astype(np.int64)


def _station_codes(station: pl.Series) -> np.ndarray:
    """Integer code per row; all zeros for one station without the cost of a categorical cast."""
    first = station[0]
    if first is not None and bool((station == first).all()):
        return np.zeros(station.len(), dtype=np.int64)
    names = station.cast(pl.String)
    order = names.unique(maintain_order=True)  # first appearance (a Categorical's codes are process-wide)
    return as_numpy(names.replace_strict(order, pl.int_range(order.len(), eager=True))).astype(np.int64)


def _sorted(t: np.ndarray, codes: np.ndarray) -> bool:
    """Rows already grouped by station in increasing code and in time order within each."""
    dc = np.diff(codes)
    return bool(np.all(dc >= 0) and np.all((np.diff(t) > 0) | (dc > 0)))


def axis_columns(table: pl.DataFrame, axis: str, *, signed: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The PE (``|PE|`` unless ``signed``) and PL of ``axis`` of every row, as float64."""
    pe_col, pl_col = PE_PL[axis]
    pe = as_numpy(table[pe_col]).astype(np.float64, copy=False)
    return (pe if signed else np.abs(pe)), as_numpy(table[pl_col]).astype(np.float64, copy=False)


def alert_flags(table: pl.DataFrame) -> np.ndarray:
    """The receiver's alert flag of every row (missing: ``False``; no column: all ``False``)."""
    if "alert" in table.columns:
        return as_numpy(table["alert"].fill_null(False)).astype(bool)
    return np.zeros(table.height, dtype=bool)


def unavailable_at_alerts(pl: np.ndarray, alert: np.ndarray) -> np.ndarray:
    """The PL with the epochs flagged ``alert`` (and a solution) at +inf: unavailable at every alert
    limit (the counting's convention; NaN stays NaN, no solution)."""
    return np.where(alert & ~np.isnan(pl), np.inf, pl)


def solution_rows(t: np.ndarray, codes: np.ndarray, pe: np.ndarray, pl: np.ndarray) -> np.ndarray:
    """The rows with a solution (finite PE and PL, PL > 0) in pooled order: by station code, in
    time order within a station, ties in row order."""
    ok = np.isfinite(pe) & np.isfinite(pl) & (pl > 0)
    if _sorted(t, codes):  # the usual case (one station, in time order): no sort, one gather
        return np.flatnonzero(ok)
    order = np.lexsort((t, codes))
    return order[ok[order]]


def pool_epochs(table: pl.DataFrame, axis: str, *, signed: bool = False) -> PooledEpochs:
    """Pool the solution epochs of ``axis`` (``vertical`` or ``horizontal``) of an epoch table.

    Raises
    ------
    ValueError
        Unknown axis.
    InputError
        A needed column is missing, or no epoch has a solution.
    """
    if axis not in PE_PL:
        raise ValueError(f"axis must be 'vertical' or 'horizontal', got {axis!r}")
    pe_col, pl_col = PE_PL[axis]
    missing = [c for c in ("time", "station", pe_col, pl_col) if c not in table.columns]
    if missing:
        raise InputError("<epoch table>", f"the {axis} analysis needs column(s) {', '.join(missing)}")
    pe, pls = axis_columns(table, axis, signed=signed)
    t = as_numpy(table["time"]).astype(np.int64, copy=False)
    codes = _station_codes(table["station"])
    alert = alert_flags(table)
    order = solution_rows(t, codes, pe, pls)
    t, codes, pe, pls, alert = t[order], codes[order], pe[order], pls[order], alert[order]
    if t.size == 0:
        raise InputError("<epoch table>", "no epoch with a solution")
    dt = _interval_us(t, codes)
    first = np.flatnonzero(np.concatenate([[True], np.diff(codes) != 0]))
    last = np.concatenate([first[1:], [t.size]]) - 1
    offs = pooled_offsets(t[first], t[last], dt)
    rep = np.repeat(np.arange(first.size), last - first + 1)
    pooled = t - t[first][rep] + offs[rep]
    day = t // _DAY_US
    day_id = np.concatenate([[0], np.cumsum((np.diff(day) != 0) | (np.diff(codes) != 0))])
    n_solution = int(t.size)
    return PooledEpochs(
        pooled, day_id, rep, pe, pls, alert, table.height, table.height - n_solution, first.size, dt
    )
