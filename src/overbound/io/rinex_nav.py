"""GPS broadcast ephemerides from RINEX 2 and 3 navigation files, and satellite position and clock.

Reading
-------
:func:`read_rinex_nav` keeps the GPS LNAV records of a RINEX 2 GPS navigation file (``.yyn``)
or of a RINEX 3 GPS or mixed one (``...MN.rnx``), and counts the records of the other systems.
A record starts on a line whose first three columns are not blank (the PRN in RINEX 2, the
satellite identifier in RINEX 3) and holds the epoch (``toc``) and three numbers, followed by
seven lines of four numbers (``BROADCAST ORBIT - 1..7``; the last one may be shorter). All
numbers of all records form one byte matrix of 19-column fields; the Fortran ``D`` exponent
of RINEX 2 is turned into ``E`` and numpy reads them in one cast (:func:`overbound.io._rinex.parse_float`).

The table (:attr:`GpsEphemerides.table`) has one row per record, sorted by PRN then time of
clock, in SI units as RINEX gives them (s, m, rad, rad/s): ``sat``, ``prn``, ``toc`` (GPST),
``af0``, ``af1``, ``af2``, ``iode``, ``crs``, ``delta_n``, ``m0``, ``cuc``, ``e``, ``cus``,
``sqrt_a``, ``toe`` (s of GPS week), ``cic``, ``omega0``, ``cis``, ``i0``, ``crc``, ``omega``,
``omega_dot``, ``idot``, ``l2_codes``, ``week`` (continuous GPS week of ``toe``), ``l2p_flag``,
``sv_accuracy`` (URA in m), ``health``, ``tgd``, ``iodc``, ``ttx`` (transmission time of message,
s of ``week``), ``fit_interval`` (hours as written; 0 means unknown, i.e. 4 h), then
``toe_time`` and ``ttx_time`` (GPST datetimes of ``toe`` and ``ttx``), ``file`` and ``line``.

Each GPS record (and each record of no known system, e.g. a damaged identifier) counts once as
read, and is either kept or rejected once, with file, line and the first reason that applies:
``unknown_system``, ``record_length`` (not eight lines), ``bad_epoch`` (unreadable PRN or toc),
``time_out_of_range`` (toc or toe outside :data:`overbound.io.gpstime.PLAUSIBLE_SPAN`, or a
transmission time beyond 1e10 s), ``line_too_long`` (a field overflowing its 19 columns),
``bad_number`` (unreadable, ``NaN``/``Infinity``, a NUL byte, or an integer field beyond 32
bits), ``missing_field``, ``implausible_orbit`` (``sqrt_a`` <= 0, ``e`` outside [0, 1)),
``toc_toe_mismatch`` (toc and toe more than a week apart: a corrupted year or week), then
``duplicate``: repeated records (same PRN, toc, IODE and IODC, as merged daily files often
contain) keep the first. Records of the other systems are counted in the notes, not read.

Orbit and clock
---------------
:func:`broadcast_state` evaluates IS-GPS-200 Table 20-IV (user algorithm for ephemeris
determination) and 20.3.3.3.3.1 (satellite clock correction with the relativistic term),
vectorised over any number of (record, time) pairs. The position is in the ECEF frame *at the
time given*: for a range, the engine evaluates it at the transmission time and then rotates
it into the frame of the reception time with :func:`rotate_earth` (Sagnac effect).
:func:`select_ephemeris` picks, per satellite and time, the record a receiver would be using.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import polars as pl

from overbound.io._rinex import (
    GPS_EPOCH_US,
    US,
    Lines,
    civil_to_us,
    load_bytes,
    parse_digits,
    parse_float,
    rinex_version,
    to_gpst,
)
from overbound.io.gpstime import PLAUSIBLE_END_US, PLAUSIBLE_SPAN, PLAUSIBLE_YEARS, plausible_us
from overbound.io.open import Source, source_name
from overbound.io.sbas_frames import REJECTED_SCHEMA
from overbound.io.schema import InputError, ReadReport

__all__ = [
    "FIELDS",
    "GPS_F",
    "GPS_MU",
    "GPS_OMEGA_E",
    "SPEED_OF_LIGHT",
    "BroadcastState",
    "GpsEphemerides",
    "NavHeader",
    "broadcast_state",
    "clock_at",
    "ephemeris_elements",
    "read_rinex_nav",
    "rotate_earth",
    "select_ephemeris",
    "state_at",
]

#: Earth's gravitational constant for GPS user equations, m^3/s^2 (IS-GPS-200 Table 20-IV).
GPS_MU = 3.986005e14
#: WGS-84 Earth rotation rate, rad/s (IS-GPS-200 Table 20-IV).
GPS_OMEGA_E = 7.2921151467e-5
#: Relativistic clock constant F = -2 sqrt(mu) / c^2, s/m^(1/2) (IS-GPS-200 20.3.3.3.3.1).
GPS_F = -4.442807633e-10
SPEED_OF_LIGHT = 299_792_458.0
_WEEK_US = 604_800 * US
_HALF_WEEK_S = 302_400.0

#: The 29 numbers after the epoch, in record order (RINEX 2.11 Table A4, the same in RINEX 3).
FIELDS = (
    "af0", "af1", "af2",
    "iode", "crs", "delta_n", "m0",
    "cuc", "e", "cus", "sqrt_a",
    "toe", "cic", "omega0", "cis",
    "i0", "crc", "omega", "omega_dot",
    "idot", "l2_codes", "week", "l2p_flag",
    "sv_accuracy", "health", "tgd", "iodc",
    "ttx", "fit_interval",
)  # fmt: skip
_INTEGER = ("iode", "l2_codes", "week", "l2p_flag", "health", "iodc")
#: Fields that an orbit, clock or ephemeris selection cannot do without.
_REQUIRED = (
    "af0", "af1", "af2", "iode", "crs", "delta_n", "m0", "cuc", "e", "cus", "sqrt_a", "toe",
    "cic", "omega0", "cis", "i0", "crc", "omega", "omega_dot", "idot", "week", "health", "tgd",
    "iodc", "ttx",
)  # fmt: skip
_LINES_GPS = 8
#: RINEX 3 system letters of the records that are counted but not read (GPS ones are read).
_OTHER_SYSTEMS = b"RECJIS"
_REASONS_TEXT = {
    "unknown_system": "record of no RINEX satellite system",
    "record_length": "GPS record without exactly 8 lines",
    "bad_epoch": "unreadable PRN or time of clock",
    "time_out_of_range": f"time of clock, of ephemeris or of transmission outside {PLAUSIBLE_SPAN}",
    "line_too_long": "record line longer than 80 columns (a field overflows its columns)",
    "bad_number": "unreadable or non-finite number, or an integer field out of range",
    "missing_field": "blank orbit or clock field",
    "implausible_orbit": "sqrt(A) <= 0 or eccentricity outside [0, 1)",
    "toc_toe_mismatch": "time of clock and time of ephemeris more than a week apart",
    "duplicate": "same PRN, toc, IODE and IODC as an earlier record",
}
#: Seconds of GPS time from 1980-01-06 to :data:`overbound.io.gpstime.PLAUSIBLE_END`.
_SPAN_S = (PLAUSIBLE_END_US - GPS_EPOCH_US) / US
_TTX_LIMIT_S = 1e10  # |ttx| beyond this (s of week) is no time (0.9999e9 means "unknown" in RINEX 3)
#: toc and toe of one data set lie within its fit interval (hours; they are usually equal): a week
#: apart, one of them is corrupted (a changed year or week).
_TOC_TOE_LIMIT_S = 7 * 86_400.0
_MAX_COLUMNS = 80  # RINEX 2 records are 79 columns wide, RINEX 3 ones 80


@dataclass(frozen=True, slots=True)
class NavHeader:
    """Header of a navigation file: GPS Klobuchar coefficients, GPS-UTC parameters, leap seconds.

    ``ion_alpha``/``ion_beta``: the 4 + 4 Klobuchar coefficients (s, s/semicircle^n), ``None`` if
    absent; ``delta_utc``: (A0 s, A1 s/s, reference time s of week, reference week).
    """

    version: float
    ion_alpha: tuple[float, ...] | None = None
    ion_beta: tuple[float, ...] | None = None
    delta_utc: tuple[float, float, int, int] | None = None
    leap_seconds: int | None = None


@dataclass(frozen=True, slots=True, eq=False)
class GpsEphemerides:
    """GPS broadcast ephemerides of one or several navigation files (see the module notes)."""

    table: pl.DataFrame
    header: NavHeader
    other_systems: dict[str, int] = field(default_factory=dict)
    rejected: pl.DataFrame = field(default_factory=lambda: pl.DataFrame(schema=REJECTED_SCHEMA))
    files: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class BroadcastState:
    """Satellite position and clock from broadcast ephemerides at given GPS times.

    Attributes
    ----------
    position : (n, 3) ECEF metres, in the Earth-fixed frame of the evaluation time.
    clock : (n,) s, satellite clock offset af0 + af1 dt + af2 dt^2 + relativistic term, for
        the ionosphere-free P(Y) combination; an L1 C/A user subtracts ``tgd`` (IS-GPS-200 20.3.3.3.3.2).
    relativistic : (n,) s, F e sqrt(A) sin(E_k), included in ``clock``.
    tgd : (n,) s, group delay of the record.
    ecc_anomaly : (n,) rad, E_k.
    """

    position: np.ndarray
    clock: np.ndarray
    relativistic: np.ndarray
    tgd: np.ndarray
    ecc_anomaly: np.ndarray


def read_rinex_nav(
    sources: Source | Sequence[Source], *, strict: bool = False
) -> tuple[GpsEphemerides, ReadReport]:
    """Read the GPS ephemerides of one or several RINEX 2 / 3 navigation files (plain, gzip or ``.Z``).

    Parameters
    ----------
    sources : a path or stream, or several (e.g. the previous day and the day): their records are
        merged, repeated ones dropped.
    strict : raise :class:`InputError` at the first rejected record.

    Returns
    -------
    eph : :class:`GpsEphemerides` (the header is the first file's).
    report : ``rows_read`` GPS records (and records of no known system) seen, ``rows_kept``,
        ``rejected`` by reason (each record once), and in the notes the records of other systems.

    Raises
    ------
    InputError
        Not a RINEX navigation file, a RINEX 2 GLONASS or GEO navigation file, an unsupported
        version, no ``END OF HEADER``, a truncated compressed stream, or (``strict``) a bad record.
    """
    many = isinstance(sources, Sequence) and not isinstance(sources, str | bytes)
    items = list(sources) if many else [sources]  # type: ignore[list-item]
    parts = [_read_one(s, strict) for s in items]
    header = parts[0][1]
    table = pl.concat([p[0] for p in parts], how="vertical")
    rejected = pl.concat([p[3] for p in parts], how="vertical")
    table, dups = _drop_duplicates(table)
    if strict and dups.height:
        row = dups.row(0, named=True)
        raise InputError(row["file"], _REASONS_TEXT["duplicate"], line=int(row["line"]))
    rejected = pl.concat([rejected, dups], how="vertical").sort("file", "line", maintain_order=True)
    others: Counter = Counter()
    for p in parts:
        others.update(p[2])
    files = tuple(source_name(s) for s in items)
    eph = GpsEphemerides(table, header, dict(sorted(others.items())), rejected, files)
    return eph, _report(eph, sum(p[4] for p in parts))


def _read_one(source: Source, strict: bool) -> tuple[pl.DataFrame, NavHeader, Counter, pl.DataFrame, int]:
    """GPS records, header, other systems' record counts, rejections and records seen (GPS records and
    records of no known system) of one file."""
    name = source_name(source)
    lines = Lines.of(load_bytes(source))
    header, body = _parse_header(lines, name)
    v3 = header.version >= 3
    rows = np.arange(body, len(lines), dtype=np.int64)
    starts = rows[(lines.chars(rows, 0, 3) != ord(" ")).any(axis=1)]
    system = lines.col(starts, 0) if v3 else np.full(len(starts), ord("G"), np.uint8)
    known = np.isin(system, np.frombuffer(_OTHER_SYSTEMS, np.uint8))
    others = Counter(chr(c) for c in system[known].tolist())
    gps = system == ord("G")
    rej: list[tuple[int, str]] = [(int(i), "unknown_system") for i in starts[~gps & ~known]]
    nonblank = np.flatnonzero(lines.length > 0)
    ends = _record_ends(starts, nonblank, len(lines))[gps]
    first = starts[gps]
    good_len = (ends - first) == _LINES_GPS
    rej += [(int(i), "record_length") for i in first[~good_len]]
    first = first[good_len]
    table, reason = _decode_records(lines, first, v3)
    bad = reason != ""
    rej += [(int(i), str(r)) for i, r in zip(first[bad].tolist(), reason[bad].tolist(), strict=True)]
    table = table.filter(pl.Series(~bad)).with_columns(
        pl.lit(name).alias("file"), pl.Series("line", first[~bad] + 1)
    )
    rej.sort()
    if strict and rej:
        raise InputError(name, _REASONS_TEXT[rej[0][1]], line=rej[0][0] + 1)
    rejected = pl.DataFrame(
        {"file": [name] * len(rej), "line": [i + 1 for i, _ in rej], "reason": [r for _, r in rej]},
        schema=REJECTED_SCHEMA,
    )
    return table, header, others, rejected, int(np.count_nonzero(gps | ~known))


def _record_ends(starts: np.ndarray, nonblank: np.ndarray, n: int) -> np.ndarray:
    """One past the last non-blank line of each record (records end at the next start)."""
    nxt = np.append(starts[1:], n)
    last = np.searchsorted(nonblank, nxt, side="left") - 1  # last non-blank line before the next start
    return np.where(last >= 0, nonblank[np.maximum(last, 0)] + 1, starts + 1)


# --------------------------------------------------------------------------- header


def _parse_header(lines: Lines, name: str) -> tuple[NavHeader, int]:
    version, first = rinex_version(lines, name, "navigation")
    kind = first[20:21]
    if version < 3 and kind in ("G", "H"):
        what = "GLONASS" if kind == "G" else "GEO (SBAS)"
        raise InputError(name, f"RINEX 2 {what} navigation file: no GPS ephemerides", line=1)
    if kind != "N":
        raise InputError(name, f"RINEX file of type {kind!r}, expected navigation data ('N')", line=1)
    if not (2.0 <= version < 4.0):
        raise InputError(
            name, f"RINEX navigation version {version:.2f} not supported (2.xx and 3.0x)", line=1
        )
    out: dict = {"version": version}
    for i in range(1, min(len(lines), 5000)):
        text = lines.text(i)
        label, body = text[60:].strip(), text[:60]
        if label == "END OF HEADER":
            return NavHeader(**out), i + 1
        try:
            _header_line(label, body, out)
        except ValueError:
            raise InputError(name, f"unreadable header line {label!r}", line=i + 1) from None
    raise InputError(name, "no END OF HEADER: truncated or not a RINEX navigation file")


def _header_line(label: str, body: str, out: dict) -> None:
    num = lambda s: float(s.replace("D", "E").replace("d", "E"))  # noqa: E731
    if label in ("ION ALPHA", "ION BETA"):  # RINEX 2: 2X, 4D12.4
        out["ion_alpha" if label == "ION ALPHA" else "ion_beta"] = tuple(
            num(body[2 + 12 * k : 14 + 12 * k]) for k in range(4)
        )
    elif label == "IONOSPHERIC CORR" and body[:4] in ("GPSA", "GPSB"):  # RINEX 3: A4, 1X, 4D12.4
        out["ion_alpha" if body[:4] == "GPSA" else "ion_beta"] = tuple(
            num(body[5 + 12 * k : 17 + 12 * k]) for k in range(4)
        )
    elif label == "DELTA-UTC: A0,A1,T,W":  # RINEX 2: 3X, 2D19.12, 2I9
        out["delta_utc"] = (num(body[3:22]), num(body[22:41]), int(body[41:50]), int(body[50:59]))
    elif label == "TIME SYSTEM CORR" and body[:4] == "GPUT":  # RINEX 3: A4, 1X, D17.10, D16.9, I7, I5
        out["delta_utc"] = (num(body[5:22]), num(body[22:38]), int(body[38:45]), int(body[45:50]))
    elif label == "LEAP SECONDS":
        out["leap_seconds"] = int(body[:6])


# --------------------------------------------------------------------------- records


def _decode_records(lines: Lines, first: np.ndarray, v3: bool) -> tuple[pl.DataFrame, np.ndarray]:
    """All numbers of the GPS records at once, as a table; also each record's rejection reason
    (``""`` when kept; the first that applies, in the order of :data:`_REASONS_TEXT`)."""
    n = len(first)
    c0, step = (23, 4) if v3 else (22, 3)
    # (line offset, column) of the 3 + 7 x 4 = 31 numbers, the last two being spares.
    spots = [(0, c0 + 19 * k) for k in range(3)] + [
        (r, step + 19 * k) for r in range(1, _LINES_GPS) for k in range(4)
    ]
    spots = spots[: len(FIELDS)]
    line = (first[:, None] + np.array([r for r, _ in spots])[None, :]).ravel()
    col = np.tile(np.array([c for _, c in spots]), n)
    mat = lines.chars(line, col, 19)
    values, ok, blank = parse_float(mat)
    ok &= _printable(mat)  # numpy's cast would drop a trailing NUL byte
    values = values.reshape(n, len(FIELDS))
    ok = ok.reshape(n, len(FIELDS)) & (np.isfinite(values) | blank.reshape(n, len(FIELDS)))
    blank = blank.reshape(n, len(FIELDS))
    integer = np.array([f in _INTEGER for f in FIELDS])
    ok &= ~(integer[None, :] & ~(np.abs(values) < 2**31) & ~blank)  # fits the int32 column
    prn, toc, epoch_ok, toc_in_span = _record_epochs(lines, first, v3)
    cols = {f: np.where(ok[:, k], values[:, k], np.nan) for k, f in enumerate(FIELDS)}
    required = np.array([f in _REQUIRED for f in FIELDS])
    week = np.nan_to_num(cols["week"])
    toe_s = week * 604_800.0 + np.nan_to_num(cols["toe"])  # s since the GPS epoch
    ttx = np.nan_to_num(cols["ttx"])
    times_ok = (toe_s >= 0) & (toe_s < _SPAN_S) & (np.abs(ttx) < _TTX_LIMIT_S) & toc_in_span
    toc_s = (toc - GPS_EPOCH_US) / US
    longest = lines.length[first[:, None] + np.arange(_LINES_GPS)].max(axis=1)
    checks = {
        "bad_epoch": ~epoch_ok,
        "time_out_of_range": ~times_ok,
        "line_too_long": longest > _MAX_COLUMNS,
        "bad_number": ~ok.all(axis=1),
        "missing_field": (blank & required[None, :]).any(axis=1),
        "implausible_orbit": ~(cols["sqrt_a"] > 0) | ~((cols["e"] >= 0) & (cols["e"] < 1)),
        "toc_toe_mismatch": ~(np.abs(toc_s - toe_s) <= _TOC_TOE_LIMIT_S),
    }
    reason = np.full(n, "", dtype=object)
    for name, mask in checks.items():  # each record once, with the first reason that applies
        reason[(reason == "") & mask] = name
    # the times of the rejected records are not computed (they may overflow): they are dropped
    kept = reason == ""
    week_us = np.where(kept, week, 0).astype(np.int64) * _WEEK_US
    toe_us = GPS_EPOCH_US + week_us + np.round(np.where(kept, cols["toe"], 0) * US).astype(np.int64)
    ttx_us = GPS_EPOCH_US + week_us + np.round(np.where(kept, ttx, 0) * US).astype(np.int64)
    data: dict[str, pl.Series] = {
        "sat": pl.Series("sat", [f"G{p:02d}" for p in prn.tolist()], dtype=pl.String),
        "prn": pl.Series("prn", prn.astype(np.int16)),
        "toc": pl.Series("toc", toc, dtype=pl.Int64).cast(pl.Datetime("us")),
    }
    for f in FIELDS:
        if f in _INTEGER:
            data[f] = pl.Series(f, np.round(np.nan_to_num(cols[f])).astype(np.int32))
        else:
            data[f] = pl.Series(f, cols[f])
    data["toe_time"] = pl.Series("toe_time", toe_us, dtype=pl.Int64).cast(pl.Datetime("us"))
    data["ttx_time"] = pl.Series("ttx_time", ttx_us, dtype=pl.Int64).cast(pl.Datetime("us"))
    return pl.DataFrame(list(data.values())), reason


def _record_epochs(
    lines: Lines, first: np.ndarray, v3: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """PRN, time of clock (GPS microseconds), whether both read, and whether the time lies in
    :data:`overbound.io.gpstime.PLAUSIBLE_SPAN`."""
    if v3:  # A1, I2.2, 1X, I4, 5(1X, I2.2): seconds are whole
        prn, p_ok, _ = _digits(lines.chars(first, 1, 2))
        year, y_ok, _ = _digits(lines.chars(first, 4, 4))
        parts = [_digits(lines.chars(first, c, 2)) for c in (9, 12, 15, 18, 21)]
        sec_us = parts[4][0] * US
        sec_ok = parts[4][1]
        parts = parts[:4]
    else:  # I2, 1X, I2.2, 4(1X, I2), F5.1
        prn, p_ok, _ = _digits(lines.chars(first, 0, 2))
        year, y_ok, _ = _digits(lines.chars(first, 3, 2))
        year = np.where(year < 80, 2000 + year, 1900 + year)
        parts = [_digits(lines.chars(first, c, 2)) for c in (6, 9, 12, 15)]
        sec_mat = lines.chars(first, 17, 5)
        sec, sec_ok, _ = parse_float(sec_mat)
        sec_ok &= _printable(sec_mat) & np.isfinite(sec) & (np.abs(sec) < 100)
        sec_us = np.round(np.where(sec_ok, sec, 0) * US).astype(np.int64)
    # the date's validity with the year brought into civil_to_us's range, the span checked apart
    _, date_ok = civil_to_us(np.clip(year, 1980, 2199), *(p[0] for p in parts), sec_us)
    t, _ = civil_to_us(year, *(p[0] for p in parts), sec_us)
    ok = (
        p_ok
        & (prn >= 1)
        & (prn <= 63)
        & y_ok
        & sec_ok
        & date_ok
        & np.logical_and.reduce([p[1] for p in parts])
    )
    t = to_gpst(t, "GPS", "")
    return prn, t, ok, np.isin(year, PLAUSIBLE_YEARS) & plausible_us(t)


def _digits(mat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`~overbound.io._rinex.parse_digits` of a date field, where a blank is no value (not 0)."""
    value, ok, blank = parse_digits(mat)
    return value, ok & ~blank, blank


def _printable(mat: np.ndarray) -> np.ndarray:
    """Rows of a byte matrix that hold printable ASCII only."""
    return ((mat >= 32) & (mat <= 126)).all(axis=1)


def _drop_duplicates(table: pl.DataFrame) -> tuple[pl.DataFrame, pl.DataFrame]:
    """Sort by PRN and toc (then file order) and drop repeats of (PRN, toc, IODE, IODC)."""
    table = table.with_row_index("_order").sort("prn", "toc", "_order")
    dup = table.select(~pl.struct("prn", "toc", "iode", "iodc").is_first_distinct()).to_series()
    rejected = table.filter(dup).select(
        pl.col("file"), pl.col("line").cast(pl.Int64), pl.lit("duplicate").alias("reason")
    )
    return table.filter(~dup).drop("_order"), rejected


def _report(eph: GpsEphemerides, n_seen: int) -> ReadReport:
    rej = eph.rejected
    first = ""
    if rej.height:
        row = rej.row(0, named=True)
        first = f"{row['file']}:{row['line']}: {row['reason']}"
    t = eph.table
    sats = t["prn"].n_unique() if t.height else 0
    others = ", ".join(f"{s}: {n}" for s, n in eph.other_systems.items()) or "none"
    return ReadReport(
        source=", ".join(eph.files),
        format=f"rinex-nav {eph.header.version:.2f}",
        rows_read=n_seen,
        rows_kept=t.height,
        rejected=dict(Counter(rej["reason"].to_list())),
        first_bad=first,
        notes=(
            f"GPS records kept: {t.height} for {sats} satellites, "
            f"unhealthy: {int((t['health'] != 0).sum()) if t.height else 0}",
            f"records of other systems (not read): {others}",
        ),
    )


# --------------------------------------------------------------------------- selection


def select_ephemeris(
    eph: pl.DataFrame,
    prn: np.ndarray,
    time_us: np.ndarray,
    *,
    iode: np.ndarray | None = None,
    healthy_only: bool = True,
) -> np.ndarray:
    """Row of ``eph`` a receiver uses for each (PRN, GPS time), or -1 when there is none.

    The rule is a receiver's: among the records of that PRN already transmitted (``ttx_time`` <=
    t), whose fit interval covers t (``|t - toe_time|`` <= half of it, 4 h when unknown) and
    healthy (``health`` == 0, unless ``healthy_only`` is False), take the most recently
    transmitted; with ``iode``, only records with that IODE qualify (matching SBAS long-term
    corrections, DO-229 A.4.4.7). Vectorised: one search per query, then a backward walk over
    older records of the same PRN for the queries whose latest record does not qualify.

    Parameters
    ----------
    eph : :attr:`GpsEphemerides.table` (any row order).
    prn, time_us : query PRNs and GPS times (int64 microseconds), broadcast together.
    iode : required IODE per query (negative: any).
    """
    prn, time_us = np.broadcast_arrays(np.asarray(prn, np.int64), np.asarray(time_us, np.int64))
    want = None if iode is None else np.broadcast_to(np.asarray(iode, np.int64), prn.shape)
    rec_prn = eph["prn"].to_numpy().astype(np.int64)
    ttx = eph["ttx_time"].dt.epoch("us").to_numpy()
    toe = eph["toe_time"].dt.epoch("us").to_numpy()
    fit = eph["fit_interval"].to_numpy()
    half_fit = np.where(fit > 1, fit, 4.0) * 1800 * US
    usable = (eph["health"].to_numpy() == 0) if healthy_only else np.ones(eph.height, bool)
    rec_iode = eph["iode"].to_numpy().astype(np.int64)
    base = min(int(ttx.min()), int(time_us.min())) if eph.height and prn.size else 0
    span = np.int64(1) << np.int64(50)  # 35 years of microseconds: PRN in the upper bits
    key = rec_prn * span + np.clip(ttx - base, 0, span - 1)
    order = np.argsort(key, kind="stable")
    key = key[order]
    q = prn.ravel() * span + np.clip(time_us.ravel() - base, 0, span - 1)
    pos = np.searchsorted(key, q, side="right") - 1
    out = np.full(q.size, -1, np.int64)
    active = np.arange(q.size)
    t = time_us.ravel()
    while active.size:
        p = pos[active]
        alive = p >= 0
        active, p = active[alive], p[alive]
        row = order[p]
        alive = rec_prn[row] == prn.ravel()[active]
        active, p, row = active[alive], p[alive], row[alive]
        ok = usable[row] & (np.abs(t[active] - toe[row]) <= half_fit[row])
        if want is not None:
            w = want.ravel()[active]
            ok &= (w < 0) | (rec_iode[row] == w)
        out[active[ok]] = row[ok]
        active = active[~ok]
        pos[active] -= 1
    return out.reshape(prn.shape)


# --------------------------------------------------------------------------- orbit and clock


def broadcast_state(
    eph: pl.DataFrame,
    rows: np.ndarray,
    time_us: np.ndarray,
    offset_s: np.ndarray | float = 0.0,
) -> BroadcastState:
    """Position and clock of the satellites of ``eph[rows]`` at GPS times ``time_us + offset_s``.

    Implements IS-GPS-200 Table 20-IV: mean motion n = sqrt(mu / A^3) + delta_n, mean anomaly
    M_k = M0 + n t_k, Kepler's equation M_k = E_k - e sin E_k (Newton iterations to 1e-14 rad),
    true anomaly, argument of latitude with the second-harmonic corrections (cus/cuc, crs/crc,
    cis/cic), corrected inclination i0 + idot t_k, longitude of the ascending node
    Omega0 + (OmegaDot - OmegaDot_e) t_k - OmegaDot_e toe, and the rotation into ECEF. The clock is
    af0 + af1 dt + af2 dt^2 + F e sqrt(A) sin E_k with dt = t - toc (20.3.3.3.3.1). Times t_k and
    dt are exact differences of absolute times, so week crossovers need no special care.

    Parameters
    ----------
    eph : :attr:`GpsEphemerides.table`.
    rows : row of ``eph`` per evaluation (e.g. from :func:`select_ephemeris`); must be >= 0.
    time_us : GPS time, int64 microseconds; ``offset_s`` adds a float offset in seconds (for
        the sub-microsecond transmission time of a pseudorange).
    """
    rows = np.asarray(rows, np.int64)
    rows, time_us, offset = np.broadcast_arrays(
        rows, np.asarray(time_us, np.int64), np.asarray(offset_s, float)
    )
    return state_at(ephemeris_elements(eph, rows), time_us, offset)


#: Columns of :attr:`GpsEphemerides.table` that :func:`state_at` needs.
_ELEMENTS = ("e", "sqrt_a", "delta_n", "m0", "omega", "cuc", "cus", "crc", "crs", "cic", "cis", "i0", "idot",
             "omega0", "omega_dot", "toe", "af0", "af1", "af2", "tgd")  # fmt: skip


def ephemeris_elements(eph: pl.DataFrame, rows: np.ndarray) -> dict[str, np.ndarray]:
    """The broadcast elements of ``eph[rows]`` (and ``toe_us``, ``toc_us``), gathered once for
    :func:`state_at` and :func:`clock_at` (several evaluations of the same records).

    Also the terms of IS-GPS-200 Table 20-IV and 20.3.3.3.3.1 that depend on the record alone,
    computed once per record of ``eph`` and then gathered (the same numbers as per evaluation):
    ``a`` = sqrt_a^2, ``n`` = sqrt(mu / A^3) + delta_n, ``sqrt_1_e2`` = sqrt(1 - e^2),
    ``f_e_sqrt_a`` = F e sqrt(A), ``omega_dot_rel`` = OmegaDot - OmegaDot_e and ``omega_e_toe`` =
    OmegaDot_e toe.
    """
    rows = np.asarray(rows, np.int64)
    if (rows < 0).any():
        raise ValueError("rows must be >= 0 (select_ephemeris gives -1 where no ephemeris qualifies)")
    tab = {c: eph[c].to_numpy() for c in _ELEMENTS}
    tab["toe_us"] = eph["toe_time"].dt.epoch("us").to_numpy()
    tab["toc_us"] = eph["toc"].dt.epoch("us").to_numpy()
    tab["a"] = tab["sqrt_a"] ** 2
    tab["n"] = np.sqrt(GPS_MU / tab["a"] ** 3) + tab["delta_n"]
    tab["sqrt_1_e2"] = np.sqrt(1.0 - tab["e"] ** 2)
    tab["f_e_sqrt_a"] = GPS_F * tab["e"] * tab["sqrt_a"]
    tab["omega_dot_rel"] = tab["omega_dot"] - GPS_OMEGA_E
    tab["omega_e_toe"] = GPS_OMEGA_E * tab["toe"]
    return {c: v[rows] for c, v in tab.items()}


def _anomaly(g: dict[str, np.ndarray], time_us: np.ndarray, offset: np.ndarray | float) -> tuple:
    """t_k, A and E_k (IS-GPS-200 Table 20-IV)."""
    tk = (time_us - g["toe_us"]) / US + offset
    mk = g["m0"] + g["n"] * tk
    return tk, g["a"], _kepler(mk, g["e"])


def _clock(g: dict[str, np.ndarray], time_us: np.ndarray, offset: np.ndarray | float,
           sin_e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Clock offset and its relativistic term (IS-GPS-200 20.3.3.3.3.1)."""
    dt = (time_us - g["toc_us"]) / US + offset
    rel = g["f_e_sqrt_a"] * sin_e
    return g["af0"] + g["af1"] * dt + g["af2"] * dt**2 + rel, rel


def clock_at(g: dict[str, np.ndarray], time_us: np.ndarray, offset_s: np.ndarray | float = 0.0) -> np.ndarray:
    """``state_at(g, time_us, offset_s).clock`` without the orbit (the same numbers, less work)."""
    _, _, ek = _anomaly(g, np.asarray(time_us, np.int64), offset_s)
    return _clock(g, np.asarray(time_us, np.int64), offset_s, np.sin(ek))[0]


def state_at(
    g: dict[str, np.ndarray], time_us: np.ndarray, offset_s: np.ndarray | float = 0.0
) -> BroadcastState:
    """:func:`broadcast_state` of elements already gathered by :func:`ephemeris_elements`."""
    time_us = np.asarray(time_us, np.int64)
    tk, a, ek = _anomaly(g, time_us, offset_s)
    sin_e, cos_e = np.sin(ek), np.cos(ek)
    nu = np.arctan2(g["sqrt_1_e2"] * sin_e, cos_e - g["e"])
    phi = nu + g["omega"]
    two_phi = 2 * phi
    s2, c2 = np.sin(two_phi), np.cos(two_phi)
    u = phi + g["cus"] * s2 + g["cuc"] * c2
    r = a * (1.0 - g["e"] * cos_e) + g["crs"] * s2 + g["crc"] * c2
    inc = g["i0"] + g["cis"] * s2 + g["cic"] * c2 + g["idot"] * tk
    xp, yp = r * np.cos(u), r * np.sin(u)
    big_omega = g["omega0"] + g["omega_dot_rel"] * tk - g["omega_e_toe"]
    cos_o, sin_o, cos_i = np.cos(big_omega), np.sin(big_omega), np.cos(inc)
    pos = np.empty((*np.shape(xp), 3))
    pos[..., 0] = xp * cos_o - yp * cos_i * sin_o
    pos[..., 1] = xp * sin_o + yp * cos_i * cos_o
    pos[..., 2] = yp * np.sin(inc)
    clock, rel = _clock(g, time_us, offset_s, sin_e)
    return BroadcastState(pos, clock, rel, g["tgd"], ek)


def _kepler(m: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Eccentric anomaly from Kepler's equation by Newton's method (quadratic convergence), from E = M
    until no step exceeds 1e-14 rad.

    A value whose step is exactly 0 would stay as it is in every later iteration: once most values are
    there, the iterations go on with the others only (the same numbers, less work).
    """
    shape = np.shape(m)
    ek = np.array(m, float).ravel()  # a copy: updated in place
    m_k, e_k = np.asarray(m, float).ravel(), np.broadcast_to(np.asarray(e, float), shape).ravel()
    live: np.ndarray | None = None  # positions in ek of the values still iterated (None: all, in place)
    x = ek
    step, tmp = np.empty_like(x), np.empty_like(x)
    for _ in range(20):
        np.sin(x, out=step)  # step = (E - e sin E - M) / (1 - e cos E), the same operations in place
        np.multiply(e_k, step, out=step)
        np.subtract(x, step, out=step)
        np.subtract(step, m_k, out=step)
        np.cos(x, out=tmp)
        np.multiply(e_k, tmp, out=tmp)
        np.subtract(1.0, tmp, out=tmp)
        np.divide(step, tmp, out=step)
        x -= step
        if not np.abs(step, out=tmp).max(initial=0.0) > 1e-14:
            break
        moving = np.flatnonzero(step)
        if moving.size < x.size // 2:
            if live is not None:
                ek[live] = x
            live = moving if live is None else live[moving]
            x, m_k, e_k = x[moving], m_k[moving], e_k[moving]
            step, tmp = np.empty_like(x), np.empty_like(x)
    if live is not None:
        ek[live] = x
    return ek.reshape(shape)


def rotate_earth(position: np.ndarray, travel_time_s: np.ndarray | float) -> np.ndarray:
    """ECEF position at transmission expressed in the ECEF frame of reception (Sagnac correction).

    The Earth turns by theta = OmegaDot_e * tau during the signal travel time tau, so the frame
    of reception is the frame of transmission rotated by theta about z:
    x' = x cos(theta) + y sin(theta), y' = -x sin(theta) + y cos(theta), z' = z.
    """
    position = np.asarray(position, float)
    theta = GPS_OMEGA_E * np.asarray(travel_time_s, float)
    c, s = np.cos(theta), np.sin(theta)
    x, y = position[..., 0], position[..., 1]
    out = np.empty(np.broadcast_shapes(position.shape, (*np.shape(theta), 3)))
    out[..., 0] = x * c + y * s
    out[..., 1] = -x * s + y * c
    out[..., 2] = position[..., 2]
    return out
