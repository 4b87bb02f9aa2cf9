"""Reader for NMEA 0183 logs with protection levels: ``GFA`` (GNSS fix accuracy and integrity) with the
position of ``GGA`` and the date of ``RMC`` or ``ZDA`` (NMEA 0183 v4.11 [1]_).

Sentences are decoded and their checksums checked by :mod:`pynmeagps` (``NMEAReader.parse``); one that
fails is a rejected row, counted with its line. One epoch per ``GFA`` sentence:

* ``hpl``, ``vpl``: its horizontal and vertical protection levels (m); empty fields make a no-solution
  epoch (``nan_pl``);
* ``alert``: an ``U`` (unsafe) in its integrity status (RAIM, SBAS, Galileo characters);
* the time: its UTC time of day on the date of the last ``RMC``/``ZDA`` before it (the first one for
  the sentences before any), a day added when the time of day steps back across midnight; then GPS
  time with the GPS-UTC leap seconds in force (:mod:`overbound.io.gpstime`);
* the position: the ``GGA`` of the same time of day (latitude, longitude, ellipsoidal height = altitude
  above the geoid + geoid separation); quality 0 or no GGA is no solution; ``mode`` names the GGA
  quality (``SBAS/DGNSS`` for 2) and ``nsv`` its satellites;
* errors against ``reference`` (a surveyed position, or ``MEAN_POSITION``).

Comment lines (``#``), blank lines and other talkers' sentences are not rows; the other sentence types
are counted in the notes (``GBS`` says so: RAIM error estimates, not protection levels).

.. [1] NMEA 0183 Standard for Interfacing Marine Electronic Devices, version 4.11, 2018: GFA, GGA,
   RMC, ZDA.
"""

from __future__ import annotations

import datetime as dt
from collections import Counter
from pathlib import Path
from typing import BinaryIO, TextIO

import numpy as np
import polars as pl
from pynmeagps import NMEAMessageError, NMEAParseError, NMEAReader, NMEATypeError

from overbound.io._common import (
    RowLog,
    errors_against,
    file_station,
    finalize_epochs,
    reference_note,
    solution_columns,
)
from overbound.io.geodesy import (
    MeanPosition,
    Reference,
)
from overbound.io.gpstime import utc_to_gpst
from overbound.io.open import read_bytes, source_name
from overbound.io.schema import InputError, ReadReport

__all__ = ["read_nmea"]

_QUALITY = {0: "no fix", 1: "GPS", 2: "SBAS/DGNSS", 3: "PPS", 4: "RTK", 5: "RTK float", 6: "dead reckoning",
            7: "manual", 8: "simulator"}  # fmt: skip
_DAY_US = 86_400 * 1_000_000


def read_nmea(
    source: str | Path | BinaryIO | TextIO,
    *,
    reference: Reference | MeanPosition | None = None,
    station: str | None = None,
    strict: bool = False,
) -> tuple[pl.DataFrame, ReadReport]:
    """Read an NMEA log with ``GFA`` sentences into the epoch table (see the module notes).

    Raises :class:`InputError` naming the file without a ``GFA`` sentence, without a date (no ``RMC``
    or ``ZDA``), or (``strict``) at the first bad sentence, with its line.
    Without ``reference`` the errors are unknown (NaN, ``truth`` false: protection levels alone).
    """
    name = source_name(source)
    log = RowLog(name, strict)
    lines = read_bytes(source).splitlines()
    found: dict[str, list[tuple[int, object]]] = {"GFA": [], "GGA": [], "DATE": []}
    other: Counter = Counter()
    for no, raw in enumerate(lines, start=1):
        text = raw.strip()
        if not text or text[:1] == b"#":
            continue
        kind = _sentence(text, no, log, found)
        if kind:
            other[kind] += 1
    if not found["GFA"]:
        gbs = (
            f"; its {other['GBS']} GBS sentences are RAIM error estimates, not protection levels"
            if other["GBS"]
            else ""
        )
        raise InputError(name, f"no GFA sentence (the protection levels){gbs}")
    if not found["DATE"]:
        raise InputError(
            name, "no date: GFA and GGA give the time of day only, and no RMC or ZDA gives the day"
        )
    log.rows_read = len(found["GFA"]) + log.n_rejected
    table, used = _epochs(found, reference, name)
    counts = f"{len(found['GFA'])} GFA, {len(found['GGA'])} GGA and {len(found['DATE'])} RMC/ZDA sentences"
    notes = [
        f"{counts}; others: " + (", ".join(f"{k} {v}" for k, v in sorted(other.items())) or "none"),
        "UTC times converted to GPS time",
        reference_note(reference, used),
    ]
    stn = file_station(station, name)
    return finalize_epochs(
        table.with_columns(pl.lit(stn).alias("station")),
        log,
        format="nmea",
        notes=tuple(notes),
        errors=used is not None,
    )


def _sentence(text: bytes, line: int, log: RowLog, found: dict) -> str | None:
    """Sort one sentence into ``found`` (GFA, GGA, a date); its type when it is another; None else."""
    kind = text[3:6].decode("ascii", "replace") if text[:1] == b"$" else ""
    if kind not in ("GFA", "GGA", "RMC", "ZDA"):
        return kind or "not a sentence"
    try:
        msg = NMEAReader.parse(text + b"\r\n", validate=1)
    except (NMEAParseError, NMEAMessageError, NMEATypeError, ValueError) as exc:
        log.reject(line, f"bad sentence: {exc}")
        return None
    if msg is None:  # pynmeagps gives no message for an address it cannot read (a corrupt talker)
        log.reject(line, f"bad sentence: undecodable address {text[1:6]!r}")
        return None
    if kind == "RMC" and isinstance(getattr(msg, "date", None), dt.date):
        found["DATE"].append((line, msg.date))
    elif kind == "ZDA" and all(
        isinstance(getattr(msg, k, None), int) and getattr(msg, k) for k in ("day", "month", "year")
    ):
        found["DATE"].append((line, dt.date(msg.year, msg.month, msg.day)))
    elif kind in ("GFA", "GGA"):
        found[kind].append((line, msg))
    return None


def _tod_us(t) -> float:
    """Microseconds of the day of a ``datetime.time`` (NaN when the field is empty)."""
    if not isinstance(t, dt.time):
        return np.nan
    return ((t.hour * 60 + t.minute) * 60 + t.second) * 1e6 + t.microsecond


def _float(v) -> float:
    return float(v) if isinstance(v, int | float) else np.nan


def _epochs(found: dict, reference, name: str) -> tuple[pl.DataFrame, Reference | None]:
    gfa = pl.DataFrame(
        {
            "_line": [ln for ln, _ in found["GFA"]],
            "tod": [_tod_us(m.time) for _, m in found["GFA"]],
            "hpl": [_float(m.hprotlvl) for _, m in found["GFA"]],
            "vpl": [_float(m.vprotlvl) for _, m in found["GFA"]],
            "alert": ["U" in str(m.integrity or "") for _, m in found["GFA"]],
        }
    )
    # the day of each sentence: the last date line before it (the first date before any), one more
    # day each time the time of day steps back (midnight without a new date line)
    date_lines = np.array([ln for ln, _ in found["DATE"]])
    date_us = np.array([(d - dt.date(1970, 1, 1)).days * _DAY_US for _, d in found["DATE"]], dtype=np.int64)
    gfa = gfa.with_columns(_day_us(gfa["_line"].to_numpy(), gfa["tod"].to_numpy(), date_lines, date_us))
    gga = pl.DataFrame(
        {
            "_gga_line": [ln for ln, _ in found["GGA"]],
            "tod": [_tod_us(m.time) for _, m in found["GGA"]],
            "lat": [_float(m.lat) for _, m in found["GGA"]],
            "lon": [_float(m.lon) for _, m in found["GGA"]],
            "alt": [_float(m.alt) for _, m in found["GGA"]],
            "sep": [_float(m.sep) for _, m in found["GGA"]],
            "quality": [int(m.quality) if isinstance(m.quality, int) else 0 for _, m in found["GGA"]],
            "nsv": [int(m.numSV) if isinstance(m.numSV, int) else None for _, m in found["GGA"]],
        },
        schema_overrides={"nsv": pl.Int64},
    )
    # ellipsoidal height: altitude above the geoid + the geoid separation (the altitude alone without one)
    gga = gga.with_columns(
        _day_us(gga["_gga_line"].to_numpy(), gga["tod"].to_numpy(), date_lines, date_us),
        (pl.col("alt") + pl.col("sep").fill_nan(0.0)).alias("h"),
    )
    gga = gga.unique(["day_us", "tod"], keep="first", maintain_order=True)
    ep = gfa.join(gga.drop("_gga_line"), on=["day_us", "tod"], how="left", maintain_order="left")
    quality = ep["quality"].fill_null(0).to_numpy()
    llh = [ep[c].fill_null(np.nan).to_numpy() for c in ("lat", "lon", "h")]
    positioned = (quality > 0) & np.isfinite(llh[0]) & np.isfinite(llh[1]) & np.isfinite(llh[2])
    llh = [np.where(positioned, v, np.nan) for v in llh]
    solved = positioned & np.isfinite(ep["hpl"].to_numpy()) & np.isfinite(ep["vpl"].to_numpy())
    e, n, u, used = errors_against(reference, llh, solved, name)  # the mean of the epochs with a solution
    utc_us = (ep["day_us"] + ep["tod"]).to_numpy()
    ok_time = np.isfinite(utc_us)
    utc = pl.Series(np.where(ok_time, utc_us, 0).astype(np.int64), dtype=pl.Int64).cast(pl.Datetime("us"))
    time = utc_to_gpst(utc)
    table = pl.DataFrame(
        {
            "_line": ep["_line"],
            "time": time,
            **solution_columns(positioned, e, n, u, ep["hpl"].to_numpy(), ep["vpl"].to_numpy()),
            "nsv": ep["nsv"],
            "mode": pl.Series(quality).replace_strict(_QUALITY, default="other", return_dtype=pl.String),
            "alert": ep["alert"],
        }
    )
    # a GFA without a time of day has no time: the common rules reject it (time_out_of_range)
    return table.with_columns(
        pl.when(pl.Series(ok_time)).then(pl.col("time")).otherwise(None).alias("time")
    ), used


def _day_us(lines: np.ndarray, tod: np.ndarray, date_lines: np.ndarray, date_us: np.ndarray) -> pl.Series:
    """UTC midnight (us since 1970) of each sentence (see :func:`_epochs`)."""
    k = np.searchsorted(date_lines, lines, side="right") - 1
    base = date_us[np.maximum(k, 0)]
    # a step back of the time of day by more than 12 h since the last date line is a midnight passed:
    # the midnights counted from the start of each date line's segment of sentences
    t = np.where(np.isfinite(tod), tod, -1.0)
    new_seg = np.ones(lines.size, bool)
    new_seg[1:] = k[1:] != k[:-1]
    back = np.zeros(lines.size, np.int64)
    back[1:] = (t[1:] < t[:-1] - 43_200e6) & ~new_seg[1:]
    cum = np.cumsum(back)
    extra = cum - np.maximum.accumulate(np.where(new_seg, cum, 0))
    return pl.Series("day_us", base + extra * _DAY_US)
