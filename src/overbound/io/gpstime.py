"""GPS time: the GPS-UTC leap-second table and UTC -> GPST conversion, shared by the readers."""

from __future__ import annotations

import datetime as dt

import numpy as np
import polars as pl

__all__ = [
    "GPS_EPOCH",
    "GPS_UTC_LEAP_SECONDS",
    "PLAUSIBLE_END",
    "PLAUSIBLE_END_US",
    "PLAUSIBLE_SPAN",
    "PLAUSIBLE_START_US",
    "PLAUSIBLE_YEARS",
    "gps_utc_offset",
    "gpst_to_utc",
    "leap_seconds",
    "plausible_us",
    "utc_iso",
    "utc_to_gpst",
]

#: Origin of GPS time, 1980-01-06 00:00:00 (UTC = GPST then).
GPS_EPOCH = dt.datetime(1980, 1, 6)
_US = 1_000_000
#: End (exclusive) of the times a GNSS record can carry: the present plus a margin, to the end
#: of next year. Readers reject a time outside ``GPS_EPOCH <= t < PLAUSIBLE_END`` as a counted
#: malformed row: a corrupted year (0000, 9999) must not reach the analysis, whose tables span
#: the campaign's time range.
PLAUSIBLE_END = dt.datetime(dt.datetime.now(dt.UTC).year + 2, 1, 1)
#: The years of :data:`GPS_EPOCH` to :data:`PLAUSIBLE_END` (for readers that parse a year field).
PLAUSIBLE_YEARS = range(GPS_EPOCH.year, PLAUSIBLE_END.year)
#: The span as rejection messages print it.
PLAUSIBLE_SPAN = f"1980-01-06 to {PLAUSIBLE_END.year - 1}-12-31 (GPS)"
#: :data:`GPS_EPOCH` and :data:`PLAUSIBLE_END` in microseconds since 1970-01-01 (the epoch table's
#: time axis): every reader checks its times against these two integers.
PLAUSIBLE_START_US, PLAUSIBLE_END_US = (
    (t - dt.datetime(1970, 1, 1)) // dt.timedelta(microseconds=1) for t in (GPS_EPOCH, PLAUSIBLE_END)
)


def plausible_us(t_us: np.ndarray) -> np.ndarray:
    """Which GPS times (microseconds since 1970) lie in :data:`PLAUSIBLE_SPAN`: a time outside is a
    corrupted record.

    >>> plausible_us(np.array([0, PLAUSIBLE_START_US, PLAUSIBLE_END_US])).tolist()
    [False, True, False]
    """
    t_us = np.asarray(t_us, dtype=np.int64)
    return (t_us >= PLAUSIBLE_START_US) & (t_us < PLAUSIBLE_END_US)


#: GPS-UTC in seconds, in force from 00:00 UTC of each date on. Source: IERS Bulletin C
#: (TAI-UTC, https://hpiers.obspm.fr/eoppc/bul/bulc/) minus TAI-GPS = 19 s. Bulletin C 69
#: (January 2025) announces no leap second at the end of June 2025, so 18 s still holds.
GPS_UTC_LEAP_SECONDS: tuple[tuple[dt.date, int], ...] = (
    (dt.date(1981, 7, 1), 1),
    (dt.date(1982, 7, 1), 2),
    (dt.date(1983, 7, 1), 3),
    (dt.date(1985, 7, 1), 4),
    (dt.date(1988, 1, 1), 5),
    (dt.date(1990, 1, 1), 6),
    (dt.date(1991, 1, 1), 7),
    (dt.date(1992, 7, 1), 8),
    (dt.date(1993, 7, 1), 9),
    (dt.date(1994, 7, 1), 10),
    (dt.date(1996, 1, 1), 11),
    (dt.date(1997, 7, 1), 12),
    (dt.date(1999, 1, 1), 13),
    (dt.date(2006, 1, 1), 14),
    (dt.date(2009, 1, 1), 15),
    (dt.date(2012, 7, 1), 16),
    (dt.date(2015, 7, 1), 17),
    (dt.date(2017, 1, 1), 18),
)


def leap_seconds(utc_us: np.ndarray) -> np.ndarray:
    """GPS-UTC (s) in force at each UTC time, given as microseconds since 1970-01-01."""
    starts = np.array([(d - dt.date(1970, 1, 1)).days * 86_400 * _US for d, _ in GPS_UTC_LEAP_SECONDS])
    leaps = np.array([0] + [s for _, s in GPS_UTC_LEAP_SECONDS], dtype=np.int64)
    return leaps[np.searchsorted(starts, np.asarray(utc_us, dtype=np.int64), side="right")]


def gps_utc_offset(utc: dt.datetime) -> int:
    """GPS-UTC (s) in force at UTC time ``utc``, from :data:`GPS_UTC_LEAP_SECONDS`.

    >>> gps_utc_offset(dt.datetime(2006, 12, 27)), gps_utc_offset(dt.datetime(2016, 12, 31, 23, 59, 59))
    (14, 17)
    """
    return int(leap_seconds(pl.Series([utc], dtype=pl.Datetime("us")).dt.epoch("us").to_numpy())[0])


def utc_to_gpst(utc: pl.Series) -> pl.Series:
    """Naive UTC datetimes -> naive GPS-time datetimes (``Datetime("us")``), vectorised.

    GPST = UTC + (GPS-UTC), with GPS-UTC from :data:`GPS_UTC_LEAP_SECONDS` (0 before
    1981-07-01). A leap second itself (``23:59:60``) cannot be represented.

    >>> utc_to_gpst(pl.Series([dt.datetime(2017, 1, 1)])).to_list()
    [datetime.datetime(2017, 1, 1, 0, 0, 18)]
    """
    utc = utc.cast(pl.Datetime("us"))
    t = utc.dt.epoch("us").to_numpy()
    us = t + leap_seconds(t) * _US
    return pl.from_epoch(pl.Series(utc.name, us), time_unit="us").cast(pl.Datetime("us"))


def gpst_to_utc(gpst: dt.datetime) -> dt.datetime:
    """GPS time -> UTC: GPST - (GPS-UTC), the leap seconds in force at that UTC time.

    >>> gpst_to_utc(dt.datetime(2017, 1, 1, 0, 0, 18)), gpst_to_utc(dt.datetime(2006, 12, 27, 0, 0, 14))
    (datetime.datetime(2017, 1, 1, 0, 0), datetime.datetime(2006, 12, 27, 0, 0))
    """
    utc = gpst - dt.timedelta(seconds=gps_utc_offset(gpst))
    return gpst - dt.timedelta(seconds=gps_utc_offset(utc))  # the offset of the UTC time itself


def utc_iso(gpst_iso: str | None) -> str | None:
    """An ISO 8601 GPS time as UTC, to the second with a trailing ``Z`` (None stays None).

    >>> utc_iso("2017-01-01T00:00:18.000")
    '2017-01-01T00:00:00Z'
    """
    if gpst_iso is None:
        return None
    return gpst_to_utc(dt.datetime.fromisoformat(gpst_iso)).isoformat(timespec="seconds") + "Z"
