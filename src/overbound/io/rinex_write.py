"""Writer of RINEX 2.11 observation files (GPS, one line of up to five observations per satellite).

The layout is the one :mod:`overbound.io.rinex_obs` reads (RINEX 2.11, section 5 and table A1):
epoch lines ``yy mm dd hh mm ss.sssssss  0 nn`` with up to 12 satellites, continuation lines
for more; observations in ``F14.3`` followed by blank LLI and signal-strength flags. The header
carries no run date, so that the same observations give the same bytes. A ``.gz`` name is
written gzip-compressed (no time stamp in the gzip header either).
"""

from __future__ import annotations

import contextlib
import gzip
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import polars as pl

__all__ = ["write_rinex2_obs"]

_PER_LINE = 12  # satellites on an epoch line
_MAX_TYPES = 5  # observations on one line (this writer writes no continuation lines)


def write_rinex2_obs(
    path: Path,
    table: pl.DataFrame,
    types: Sequence[str],
    *,
    marker: str,
    position_ecef: Sequence[float],
    interval_s: float,
    comments: Sequence[str] = (),
    program: str = "overbound",
) -> Path:
    """Write ``table`` (columns ``time`` (Datetime, GPS), ``sat`` (``"G07"``) and ``types``, sorted by
    time then satellite) as a RINEX 2.11 observation file at ``path``; returns ``path``."""
    if not 1 <= len(types) <= _MAX_TYPES:
        raise ValueError(f"1 to {_MAX_TYPES} observation types, got {len(types)}")
    times = table["time"].dt.epoch("us").to_numpy()
    starts = np.flatnonzero(np.r_[True, times[1:] != times[:-1]]) if len(times) else np.zeros(0, int)
    ends = np.r_[starts[1:], len(times)]
    records = _observation_lines(table, types)
    sats = table["sat"].to_list()
    stamps = table["time"].gather(starts).dt.strftime("%y %m %d %H %M").to_list() if len(times) else []
    seconds = (times[starts] % 60_000_000 / 1e6).tolist()
    body: list[str] = []
    for stamp, sec, a, b in zip(stamps, seconds, starts.tolist(), ends.tolist(), strict=True):
        ids = sats[a:b]
        head = " " + " ".join(f"{int(v):2d}" for v in stamp.split()) + f"{sec:11.7f}  0{b - a:3d}"
        body.append(head + "".join(ids[:_PER_LINE]))
        body += [" " * 32 + "".join(ids[k : k + _PER_LINE]) for k in range(_PER_LINE, b - a, _PER_LINE)]
        body += records[a:b]
    first = table["time"][0] if len(times) else None
    text = (
        "\n".join([*_header(types, marker, position_ecef, interval_s, comments, program, first), *body])
        + "\n"
    )
    data = text.encode("ascii")
    if path.suffix == ".gz":
        data = gzip.compress(data, mtime=0)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:  # atomic: a run killed halfway leaves no half-written file
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
    return path


def _observation_lines(table: pl.DataFrame, types: Sequence[str]) -> list[str]:
    """One ``F14.3`` + two blank flags per observation; blank for a missing value."""
    cols = []
    for t in types:
        v = table[t].cast(pl.Float64).to_numpy()
        text = np.char.mod("%14.3f  ", np.nan_to_num(v))
        cols.append(np.where(np.isfinite(v), text, " " * 16))
    line = cols[0]
    for c in cols[1:]:
        line = np.char.add(line, c)
    return np.char.rstrip(line).tolist()


def _header(types, marker, position, interval_s, comments, program, first) -> list[str]:
    def line(body: str, label: str) -> str:
        return f"{body[:60]:<60}{label}"

    x, y, z = position
    lines = [
        line(f"{'2.11':>9}{'':11}{'OBSERVATION DATA':<20}{'G (GPS)':<20}", "RINEX VERSION / TYPE"),
        line(f"{program:<20}{'':<20}{'':<20}", "PGM / RUN BY / DATE"),
        *(line(c, "COMMENT") for c in comments),
        line(marker, "MARKER NAME"),
        line("", "OBSERVER / AGENCY"),
        line(f"{'0':<20}{'SYNTHETIC':<20}", "REC # / TYPE / VERS"),
        line(f"{'0':<20}{'SYNTHETIC':<20}", "ANT # / TYPE"),
        line(f"{x:14.4f}{y:14.4f}{z:14.4f}", "APPROX POSITION XYZ"),
        line(f"{0.0:14.4f}{0.0:14.4f}{0.0:14.4f}", "ANTENNA: DELTA H/E/N"),
        line(f"{1:6d}{1:6d}", "WAVELENGTH FACT L1/2"),
        line(f"{len(types):6d}" + "".join(f"{t:>6}" for t in types), "# / TYPES OF OBSERV"),
        line(f"{interval_s:10.3f}", "INTERVAL"),
    ]
    if first is not None:
        f = first
        sec = f.second + f.microsecond / 1e6
        date = f"{f.year:6d}{f.month:6d}{f.day:6d}{f.hour:6d}{f.minute:6d}{sec:13.7f}     GPS"
        lines.append(line(date, "TIME OF FIRST OBS"))
    lines.append(line("", "END OF HEADER"))
    return lines
