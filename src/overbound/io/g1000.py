"""Garmin G1000 / G1000 NXi / GIFD flight-data logs (the SD-card CSV of the integrated flight deck).

Each row is one second of the avionics' data, among them the certified GPS/WAAS receiver's own
protection levels: ``HPLwas`` and ``VPLwas`` (SBAS, DO-229, metres), ``HPLfd`` (RAIM fault detection),
the alert limits in force ``HAL`` and ``VAL`` (metres; 0 or empty when none), the fix ``GPSfix``
(``3DDiff`` = WAAS-differential, ``3D``, ``NoSoln``) and the receiver's position. There is no truth:
the errors are unknown (``hpe``/``vpe`` NaN, the report's ``truth`` false), and the analysis is the
protection-level-only one (:func:`overbound.analysis.analyze`).

The quirks of the real files (``../shared/data/g1000-waas-flight-logs``), all handled here:

* three header lines: ``#airframe_info, ...`` (key="value" metadata, recorded in the notes), the units,
  the column names padded with spaces; the values are padded with spaces too;
* ``Lcl Date``, ``Lcl Time`` are local time and ``UTCOfst`` the offset (``-05:00``): UTC = local -
  offset, then GPS time = UTC + the GPS-UTC leap seconds in force
  (:data:`overbound.io.gpstime.GPS_UTC_LEAP_SECONDS`); a row whose offset is empty (the first rows
  of some NXi logs) takes the offset of the next row that has one (the last one at the end), and
  without any the row is rejected (``no_utc_offset``); a row without a date and time (before the
  unit has GPS time) is rejected (``no_time``);
* the recording stops mid-line: a last row with fewer fields than the header is rejected
  (``truncated_line``), and the NUL bytes an NXi card leaves after it are ignored (noted); with
  ``strict`` that cut line, like a repeated second, stops the read: every real log has one;
* the time stamps are whole seconds of a jittery clock: the older unit software repeats a second now
  and then, and steps 2 s elsewhere (a log of 3,967 rows has 728 repeats and 776 two-second steps):
  a repeated row is rejected (``repeated_second``, the first kept), and a row earlier than one before
  it (``backward_time``) too; counted, never fatal, and not re-timed (which second it belonged to is
  not known). The 2-s steps are gaps for the continuity (see the PL-only report's caution);
* ``AltGPS`` is in feet (WGS-84 ellipsoidal height, see the data's PROVENANCE): not needed for the PLs,
  it is not read;
* an epoch has a solution when ``HPLwas`` and ``VPLwas`` are numbers and ``GPSfix`` is not ``NoSoln``;
  the others are kept as no-solution epochs (unavailable), as in every reader.

The station is the file name's stem (``log_110701_131851_KGFK``; a member of a zip archive by its own
name) unless ``station`` is given. The alert limits in force are kept per epoch (``hal``, ``val``: NaN
when the unit logs none).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import BinaryIO, TextIO

import numpy as np
import polars as pl

from overbound.io._common import RowLog, file_station, finalize_epochs
from overbound.io.gpstime import PLAUSIBLE_SPAN, plausible_us, utc_to_gpst
from overbound.io.open import read_bytes, source_name
from overbound.io.schema import InputError, ReadReport

__all__ = ["MAGIC", "read_g1000"]

#: The first bytes of a G1000 log.
MAGIC = b"#airframe_info"
_NEEDED = ("Lcl Date", "Lcl Time", "UTCOfst", "Latitude", "HPLwas", "VPLwas", "GPSfix")
_OFFSET = re.compile(r"^([+-])(\d{1,2}):(\d{2})$")


def read_g1000(
    source: str | Path | BinaryIO | TextIO,
    *,
    reference=None,
    station: str | None = None,
    strict: bool = False,
) -> tuple[pl.DataFrame, ReadReport]:
    """Read a G1000 flight-data log into the epoch table (no errors: ``hpe``, ``vpe`` NaN).

    ``reference`` is refused: the log's positions are the receiver's own, in flight, and no truth
    trajectory goes with them (errors would need one). Raises :class:`InputError` for a file that is
    not a G1000 log or lacks the PL columns; rows are counted in the report (kept + rejected = read).

    """
    name = source_name(source)
    if reference is not None:
        raise InputError(
            name, "a G1000 log has no truth: its protection levels are analysed alone (no --reference)"
        )
    text = read_bytes(source).decode("utf-8", errors="replace")
    padded = len(text) - len(text.rstrip("\x00"))  # the SD card's unwritten end (a real NXi log has 508 kB)
    lines = text.rstrip("\x00").splitlines()
    if len(lines) < 3 or not lines[0].startswith(MAGIC.decode()):
        raise InputError(name, "not a G1000 flight-data log (no '#airframe_info' first line)", line=1)
    header = [c.strip() for c in lines[2].split(",")]
    missing = [c for c in _NEEDED if c not in header]
    if missing:
        raise InputError(name, f"G1000 log without column(s) {', '.join(missing)}", line=3)
    log = RowLog(name, strict)
    raw = _table(lines, header, log)
    if log.rows_read == 0:
        raise InputError(name, "no data rows after the three header lines")
    stn = file_station(station, name)
    n_pl = int(raw.select(_solved().sum()).item())
    df, notes = _epochs(raw, log, stn)
    kept = int(df.select(pl.col("hpl").is_finite().sum()).item())
    notes.append(
        f"{n_pl} rows with WAAS protection levels and a position; {kept} kept, {n_pl - kept} in rejected rows"
    )
    if padded:
        notes.append(f"{padded} NUL bytes at the end of the file (unwritten card space) ignored")
    meta = _metadata(lines[0])
    unit = ", ".join(f"{k} {meta.get(k, '?')}" for k in ("unit_software_version", "system_id"))
    notes = [
        f"G1000 log: {meta.get('airframe_name', '?')} ({unit})",
        *notes,
        "no truth: errors unknown, protection levels analysed alone",
    ]
    return finalize_epochs(df, log, format="g1000", notes=tuple(notes), errors=False)


def _table(lines: list[str], header: list[str], log: RowLog) -> pl.DataFrame:
    """The data rows' needed fields as stripped strings, with their 1-based line numbers; a row with
    fewer fields than the header (a line cut by the end of the recording) is rejected. Blank lines are
    no rows. Fields are split on commas (the logs quote nothing)."""
    body = pl.DataFrame(
        {
            "text": pl.Series(lines[3:], dtype=pl.String),
            "_line": np.arange(4, 4 + len(lines) - 3, dtype=np.int64),
        }
    )
    body = body.filter(pl.col("text").str.strip_chars() != "")
    log.rows_read = body.height
    fields = body.select(pl.col("text").str.split(",").alias("f"), "_line")
    short = fields["f"].list.len() < len(header)
    for line in fields.filter(short)["_line"].to_list():
        log.reject(int(line), f"truncated line: fewer than the header's {len(header)} fields")
    fields = fields.filter(~short)
    wanted = [c for c in (*_NEEDED, "HAL", "VAL") if c in header]
    return fields.select(
        *(pl.col("f").list.get(header.index(c)).str.strip_chars().alias(c) for c in wanted), "_line"
    )


def _epochs(raw: pl.DataFrame, log: RowLog, station: str) -> tuple[pl.DataFrame, list[str]]:
    local = (pl.col("Lcl Date") + " " + pl.col("Lcl Time")).str.to_datetime("%Y-%m-%d %H:%M:%S", strict=False)
    offset = pl.col("UTCOfst").str.extract_groups(_OFFSET.pattern)
    minutes = pl.when(offset.struct.field("1") == "-").then(-1).otherwise(1) * (
        offset.struct.field("2").cast(pl.Int64) * 60 + offset.struct.field("3").cast(pl.Int64)
    )
    df = raw.with_columns(local.alias("_local"), minutes.alias("_offset_min"))
    notes = []
    n_filled = int((df["_offset_min"].is_null() & df["_local"].is_not_null()).sum())
    df = df.with_columns(pl.col("_offset_min").fill_null(strategy="backward").fill_null(strategy="forward"))
    if n_filled:
        notes.append(
            f"{n_filled} rows with a time but no UTC offset took the next row's (at the end: the last)"
        )
    bad = df["_local"].is_null() | df["_offset_min"].is_null()
    for line, d, t, o in df.filter(bad).select("_line", "Lcl Date", "Lcl Time", "_offset_min").iter_rows():
        if not (d or t):
            reason = "no time: an empty date and time (the unit had no GPS time yet)"
        elif o is None:
            reason = "no utc offset: no row gives a UTC offset"
        else:
            reason = f"bad time: '{d} {t}'"
        log.reject(int(line), reason)
    df = df.filter(~bad)
    utc = df.select(pl.col("_local") - pl.duration(minutes=pl.col("_offset_min")))["_local"]
    df = df.with_columns(utc_to_gpst(utc).alias("time"))
    far = ~plausible_us(df["time"].dt.epoch("us").to_numpy())  # a corrupted year: no order to keep with it
    for line, d, t in df.filter(pl.Series(far)).select("_line", "Lcl Date", "Lcl Time").iter_rows():
        log.reject(int(line), f"time out of range: '{d} {t}' outside {PLAUSIBLE_SPAN}")
    df = _monotone(df.filter(pl.Series(~far)), log)
    offsets = sorted(set(df["UTCOfst"].unique().drop_nulls().to_list()) - {""})
    notes.append(f"local times with UTC offset {', '.join(offsets) or '?'} converted to UTC, then GPS time")
    return _solution(df, station), notes


def _monotone(df: pl.DataFrame, log: RowLog) -> pl.DataFrame:
    """Rows whose second repeats the last kept one, or lies before it, rejected (first one kept)."""
    t = df["time"].dt.epoch("us").to_numpy()
    latest = np.maximum.accumulate(t)
    prev = np.concatenate([[np.iinfo(np.int64).min], latest[:-1]])
    repeated, backward = t == prev, t < prev
    lines = df["_line"].to_numpy()
    for mask, reason in ((repeated, "repeated second"), (backward, "backward time")):
        idx = np.flatnonzero(mask)
        for i in idx:  # the reasons of the few bad rows only
            local = f"{df['Lcl Date'][int(i)]} {df['Lcl Time'][int(i)]}"
            log.reject(int(lines[i]), f"{reason}: {local} (local) after the row before")
    return df.filter(pl.Series(~(repeated | backward)))


def _number(column: str) -> pl.Expr:
    return pl.col(column).cast(pl.Float64, strict=False)


def _solved() -> pl.Expr:
    """A row with a solution: ``HPLwas`` and ``VPLwas`` numbers, a position, a fix other than ``NoSoln``."""
    fix = pl.col("GPSfix").fill_null("") != "NoSoln"
    return (
        _number("HPLwas").is_not_null()
        & _number("VPLwas").is_not_null()
        & _number("Latitude").is_not_null()
        & fix
    )


def _solution(df: pl.DataFrame, station: str) -> pl.DataFrame:
    nan = pl.lit(float("nan"))

    def limit(column: str) -> pl.Expr:  # 0 or empty: no limit in force
        if column not in df.columns:
            return nan
        return pl.when(_number(column) > 0).then(_number(column)).otherwise(nan)

    solved = _solved()
    return df.select(
        "_line",
        "time",
        pl.lit(station).alias("station"),
        nan.alias("hpe"),
        nan.alias("vpe"),
        pl.when(solved).then(_number("HPLwas")).otherwise(nan).alias("hpl"),
        pl.when(solved).then(_number("VPLwas")).otherwise(nan).alias("vpl"),
        pl.col("GPSfix").fill_null("").alias("mode"),
        limit("HAL").alias("hal"),
        limit("VAL").alias("val"),
    )


def _metadata(line: str) -> dict[str, str]:
    """``key="value"`` (or ``key=value``) pairs of the ``#airframe_info`` line."""
    return {k: v.strip('"') for k, v in re.findall(r'(\w+)=("[^"]*"|[^,\s]*)', line)}
