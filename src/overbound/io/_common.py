"""Shared reader machinery: row checks that every format applies the same way."""

from __future__ import annotations

import datetime as dt
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import polars as pl

from overbound.io.geodesy import (
    MeanPosition,
    Reference,
    enu_errors_geodetic,
    reference_text,
    resolve_geodetic,
)
from overbound.io.gpstime import PLAUSIBLE_END_US, PLAUSIBLE_SPAN, PLAUSIBLE_START_US
from overbound.io.schema import COLUMNS, InputError, ReadReport, as_numpy

_DTYPES = {c.name: c.dtype for c in COLUMNS}
_SOLUTION = ("hpe", "vpe", "hpl", "vpl", "east", "north")


@dataclass
class RowLog:
    """Accumulates rejected rows while a reader parses; turns into a :class:`ReadReport`."""

    source: str
    strict: bool = False
    rows_read: int = 0
    rejected: Counter = field(default_factory=Counter)
    first_bad: str = ""
    first_line: int = 0

    @property
    def n_rejected(self) -> int:
        return sum(self.rejected.values())

    def reject(self, line: int, reason: str) -> None:
        """Count one rejected row; with ``strict`` raise instead."""
        if self.strict:
            raise InputError(self.source, reason, line=line)
        self.rejected[_reason_key(reason)] += 1
        self._first(line, reason)

    def _first(self, line: int, reason: str) -> None:
        if not self.first_bad or line < self.first_line:
            self.first_bad, self.first_line = f"{line}: {reason}", line


def _reason_key(reason: str) -> str:
    """Counter key of a reason: its text before the first colon (details vary row by row)."""
    return reason.split(":", 1)[0].strip().replace(" ", "_")


def errors_against(
    reference: Reference | MeanPosition | None, llh: list[np.ndarray], solved: np.ndarray, name: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, Reference | None]:
    """East, north, up errors of the positions ``llh`` (deg, deg, ellipsoidal m) of the readers of
    positions (UBX, SBF, NovAtel, NMEA, SBP) against ``reference`` (``MEAN_POSITION``: the mean of the
    ``solved`` epochs), and the reference used. Without a reference the log is read without truth:
    NaN errors and ``None``, and the protection levels are analysed alone (the PL-only analysis)."""
    if reference is None:
        nan = np.full(np.shape(llh[0]), np.nan)
        return nan, nan.copy(), nan.copy(), None
    used = resolve_geodetic(reference, *llh, solved, name)
    return (*enu_errors_geodetic(*llh, used), used)


def reference_note(reference: Reference | MeanPosition | None, used: Reference | None) -> str:
    """The reader's note of what its errors are against (:func:`errors_against`)."""
    if used is None:
        return "no reference: errors unknown, protection levels analysed alone"
    return f"errors against reference {reference_text(reference, used)}"


def file_station(station: str | None, source: str) -> str:
    """``station``, else the stem of the file name (``log_110701.csv.gz`` -> ``log_110701``)."""
    return station or Path(source).name.split(".")[0]


def solution_columns(
    solved: np.ndarray, east: np.ndarray, north: np.ndarray, up: np.ndarray, hpl: np.ndarray, vpl: np.ndarray
) -> dict[str, np.ndarray]:
    """``hpe``, ``vpe``, ``east``, ``north``, ``hpl``, ``vpl`` of a reader's epochs, NaN where not ``solved``
    (the readers that form errors from positions: SBF, NMEA, SBP)."""
    nan = np.full(np.shape(solved), np.nan)
    cols = {"hpe": np.hypot(east, north), "vpe": up, "east": east, "north": north, "hpl": hpl, "vpl": vpl}
    return {k: np.where(solved, np.asarray(v, float), nan) for k, v in cols.items()}


def finalize_epochs(
    df: pl.DataFrame,
    log: RowLog,
    *,
    format: str,
    notes: tuple[str, ...] = (),
    errors: bool = True,
) -> tuple[pl.DataFrame, ReadReport]:
    """Apply the row rules common to all readers and build the report.

    ``df`` holds canonical columns plus ``_line`` (1-based source line of each row),
    in file order.

    Rules, in order:

    0. A row whose time is missing or outside the GNSS era
       (:data:`~overbound.io.gpstime.PLAUSIBLE_SPAN`) is rejected and counted as
       ``time_out_of_range``: a corrupted year must neither reach the analysis nor break
       the order check.
    1. A time earlier than the previous row of the same station raises
       :class:`InputError` naming the line: the file order is broken and no row-wise
       repair is defensible.
    2. A row whose time equals the previous row's (same station) is rejected and
       counted as ``duplicate_time``; the first occurrence is kept.
    3. A NaN, infinite or negative protection level, or a NaN or infinite error beside a
       finite PL, makes the epoch a no-solution epoch (all errors and PLs NaN), counted under
       ``invalidated`` as ``nan_pl``, ``negative_pl`` or ``nan_error``.
       Rows whose errors *and* PLs are all NaN are no-solution epochs already and are
       not counted.
       With ``errors=False`` (an input without truth: the errors are all NaN, the PLs alone are
       analysed) a NaN error is no reason: only the PLs are checked, and the report says ``truth``
       false.
    """
    df = _drop_implausible_times(df, log)
    df = _drop_duplicates_or_raise(df, log)
    df, invalid, rows, reasons = _invalidate(df, log, errors)
    cols = [c.name for c in COLUMNS if c.name in df.columns]
    out = df.select([pl.col(c).cast(_DTYPES[c]) for c in cols])
    report = ReadReport(
        source=log.source,
        format=format,
        rows_read=log.rows_read,
        rows_kept=out.height,
        rejected=dict(log.rejected),
        invalidated=invalid,
        first_bad=log.first_bad,
        notes=notes,
        truth=errors,
        invalid_rows=rows,
        invalid_reasons=reasons,
    )
    return out, report


def _drop_implausible_times(df: pl.DataFrame, log: RowLog) -> pl.DataFrame:
    # Compared as integers (microseconds since 1970): a corrupted time can lie beyond what
    # polars' calendar code formats (it panics) or a Python datetime holds (year 0).
    us = df["time"].cast(pl.Datetime("us")).to_physical()
    bad = us.is_null() | (us < PLAUSIBLE_START_US) | (us >= PLAUSIBLE_END_US)
    n_bad = int(bad.sum())
    if not n_bad:
        return df
    i = int(bad.arg_true()[0])
    log.reject(int(df["_line"][i]), f"time out of range: {_format_us(us[i])} outside {PLAUSIBLE_SPAN}")
    log.rejected["time_out_of_range"] += n_bad - 1
    return df.filter(~bad)


_UNIX = dt.datetime(1970, 1, 1)


def _format_us(us: int | None) -> str:
    """A time given as microseconds since 1970 as text, whatever its year."""
    if us is None:
        return "missing"
    try:
        return str(_UNIX + dt.timedelta(microseconds=us))
    except OverflowError:  # beyond years 1-9999: polars' calendar, inside the range it handles
        if abs(us) < 7 * 10**18:  # about 220,000 years
            t = pl.Series([us], dtype=pl.Int64).cast(pl.Datetime("us"))
            return str(t.dt.to_string("%Y-%m-%d %H:%M:%S%.f")[0])
        return f"{us} µs from 1970-01-01"


def _drop_duplicates_or_raise(df: pl.DataFrame, log: RowLog) -> pl.DataFrame:
    if df.height < 2:
        return df
    # Categorical codes compare like the names, without materialising millions of strings.
    st = as_numpy(df["station"].cast(pl.Categorical()).to_physical())
    same = np.concatenate([[False], st[1:] == st[:-1]])
    del st
    dt = np.diff(as_numpy(df["time"]), prepend=0)
    back = np.flatnonzero(same & (dt < 0))
    if back.size:
        i = int(back[0])
        raise InputError(
            log.source,
            f"backward time {df['time'][i]} after {df['time'][i - 1]} (station {df['station'][i]})",
            line=int(df["_line"][i]),
        )
    # A duplicate is a row whose time equals the last *kept* row's time; with no
    # backward steps that is simply dt == 0 against the previous row.
    dup = np.flatnonzero(same & (dt == 0))
    for i in dup[:1].tolist():
        log.reject(
            int(df["_line"][i]), f"duplicate time: {df['time'][i]} repeats line {int(df['_line'][i - 1])}"
        )
    if dup.size > 1:
        log.rejected["duplicate_time"] += dup.size - 1
    keep = np.ones(df.height, dtype=bool)
    keep[dup] = False
    return df.filter(pl.Series(keep)) if dup.size else df


def _invalidate(
    df: pl.DataFrame, log: RowLog, errors: bool = True
) -> tuple[pl.DataFrame, dict[str, int], np.ndarray, np.ndarray]:
    """The table with its unusable solutions made no-solution epochs (rule 3 of :func:`finalize_epochs`),
    their counts by reason, and their rows and reasons."""
    # An infinite value is no measurement either (an infinite error beside a finite PL would be an HMI).
    checked = ("hpl", "vpl", "hpe", "vpe") if errors else ("hpl", "vpl")
    missing = [(~pl.col(c).is_finite()).fill_null(True) for c in checked]
    all_nan = pl.all_horizontal([pl.col(c).is_nan().fill_null(True) for c in checked])
    neg = pl.any_horizontal([(pl.col(c) < 0).fill_null(False) for c in ("hpl", "vpl")])
    nan_pl = pl.any_horizontal(missing[:2])
    nan_err = pl.any_horizontal(missing[2:]) if errors else pl.lit(False)
    invalid = ~all_nan & (neg | nan_pl | nan_err)
    # One boolean pass over the table; reasons are spelled out only for the (few) bad rows.
    if not df.select(invalid.any()).item():
        return df, {}, np.zeros(0, np.int64), np.zeros(0, dtype=object)
    reason = (
        pl.when(neg)
        .then(pl.lit("negative_pl"))
        .when(nan_pl)
        .then(pl.lit("nan_pl"))
        .otherwise(pl.lit("nan_error"))
    )
    bad = df.with_row_index("_row").filter(invalid).select("_row", "_line", reason.alias("reason"))
    counts = dict(bad.group_by("reason").len().sort("reason").iter_rows())
    log._first(int(bad["_line"][0]), f"{bad['reason'][0]}: solution set to no-solution")
    nan = pl.lit(float("nan"))
    df = df.with_columns(
        [pl.when(invalid).then(nan).otherwise(pl.col(c)).alias(c) for c in _SOLUTION if c in df.columns]
    )
    return df, counts, bad["_row"].to_numpy().astype(np.int64), bad["reason"].to_numpy()
