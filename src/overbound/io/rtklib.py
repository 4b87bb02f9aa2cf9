"""RTKLIB position solution files (``.pos``) with protection levels.

RTKLIB writes one solution per line after a block of ``%`` comment lines (RTKLIB
2.4.x manual, appendix B "Output file formats", "solution file format"; the writer is
``outsolheads``/``outsols`` in RTKLIB ``src/solution.c``). The last header line names
the columns, e.g.::

    %  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m) ... hpl (m) vpl (m)

Variants handled (all found from that header line, never from column positions):

* time as ``yyyy/mm/dd hh:mm:ss.sss`` or as ``week tow`` (GPS week, seconds of week), in
  GPST, UTC or JST (the header's first word); UTC/JST are converted to GPS time with
  :data:`GPS_UTC_LEAP_SECONDS`;
* position as ``latitude(deg) longitude(deg) height(m)``, as degrees-minutes-seconds
  (``latitude(d'")``: three fields each) or as ``x-ecef(m) y-ecef(m) z-ecef(m)``;
* field separators other than blanks (RTKLIB ``out-fieldsep``), for ``,``, ``;`` and ``|``;
* the protection-level columns ``hpl (m)`` and ``vpl (m)`` of MOPS-enabled forks
  (Houghton Associates ``rtklib-mops``), required by overbound.
"""

from __future__ import annotations

import datetime as dt
import re
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
import polars as pl
import pymap3d

from overbound.io._common import RowLog, finalize_epochs
from overbound.io.geodesy import (
    MeanPosition,
    Reference,
    enu_errors_ecef,
    reference_text,
    resolve,
)
from overbound.io.gpstime import (
    PLAUSIBLE_END_US,
    PLAUSIBLE_SPAN,
    PLAUSIBLE_START_US,
    leap_seconds,
    utc_to_gpst,
)
from overbound.io.open import Source, read_text, source_name
from overbound.io.schema import InputError, ReadReport

__all__ = [
    "SOLUTION_QUALITY",
    "PosHeader",
    "parse_pos_header",
    "read_pos_positions",
    "read_rtklib_pos",
]

#: RTKLIB solution quality flag ``Q`` -> ``mode`` name. RTKLIB ``rtklib.h`` ``SOLQ_*``
#: (the ``.pos`` header comment lists 1-6; 7 = dead reckoning in 2.4.3; 0 = no solution).
SOLUTION_QUALITY: MappingProxyType[int, str] = MappingProxyType(
    {0: "none", 1: "fix", 2: "float", 3: "sbas", 4: "dgps", 5: "single", 6: "ppp", 7: "dr"}
)

_FORMAT = "rtklib-pos"
_GPS_EPOCH_UNIX_S = 315_964_800  # 1980-01-06T00:00:00 as seconds since 1970-01-01
_WEEK_S = 604_800
_US = 1_000_000
_JST_UTC_S = 9 * 3600  # JST = UTC + 9 h (RTKLIB TIMES_JST)
_TIME_SYSTEMS = ("GPST", "UTC", "JST")
_SEPARATORS = (",", ";", "|")  # non-blank field separators we undo (RTKLIB out-fieldsep)
_DMS_UNIT = "d'\""
_POSITION_NAMES = ("latitude(deg)", "latitude(d'\")", "x-ecef(m)", "e-baseline(m)")
_NEEDS_REFERENCE = "needs a reference position (--reference lat,lon,h or --reference-ecef x,y,z)"
_NO_PL = "no hpl/vpl columns: overbound needs protection levels"

# First observation file of the run (``% inp file  : ...``) -> station name.
_RINEX2_OBS = re.compile(r"^([A-Za-z0-9]{4})\d{3}[A-Za-z0-9]\.\d{2}[OoDd](\.(gz|Z|zip|bz2))?$")
_RINEX3_OBS = re.compile(
    r"^([A-Za-z0-9]{9})_[A-Za-z]_\d{11}_\d{2}[A-Za-z](_\d{2}[A-Za-z])?_[A-Za-z][Oo]\.(rnx|crx|RNX|CRX)(\.\w+)?$"
)


@dataclass(frozen=True, slots=True)
class PosHeader:
    """What the ``%`` header of a ``.pos`` file says about its data lines.

    Attributes
    ----------
    time_system : ``"GPST"``, ``"UTC"`` or ``"JST"``.
    columns : column names after the time, as the header spells them (``"hpl (m)"``).
    widths : data fields per column (3 for a d-m-s latitude/longitude, else 1).
    separator : the field separator (``" "`` for blanks).
    station : station from the first RINEX observation file named in ``% inp file``, or ``""``.
    line : 1-based line of the column header, 0 when there is none.
    """

    time_system: str
    columns: tuple[str, ...]
    widths: tuple[int, ...]
    separator: str
    station: str
    line: int

    @property
    def n_fields(self) -> int:
        """Whitespace-separated fields of a data line: 2 for the time plus the columns."""
        return 2 + sum(self.widths)

    def field_of(self, key: str) -> int | None:
        """Index of the first data field of column ``key`` (unit-less, lower case), or None."""
        i = 2
        for name, width in zip(self.columns, self.widths, strict=True):
            if _key(name) == key:
                return i
            i += width
        return None


def read_rtklib_pos(
    source: Source,
    *,
    reference: Reference | None = None,
    station: str | None = None,
    strict: bool = False,
) -> tuple[pl.DataFrame, ReadReport]:
    """Read an RTKLIB ``.pos`` solution file with HPL/VPL columns into the epoch table.

    Parameters
    ----------
    source : path or open stream (text or binary, gzip handled by content).
    reference : true antenna position; required (errors are computed against it).
    station : station name used when the header names no RINEX observation file.
    strict : raise on the first malformed data line instead of counting it.

    Returns
    -------
    (table, report) : the epoch table with ``time, station, hpe, vpe, hpl, vpl, east,
        north`` and, when the header has ``ns`` / ``Q``, ``nsv`` / ``mode``
        (:data:`SOLUTION_QUALITY` names), and the :class:`ReadReport`.

    Raises
    ------
    InputError
        No reference; no ``hpl``/``vpl`` columns; no column header line; no epochs;
        e/n/u-baseline or geoid-height output; a time going backwards (naming its line);
        with ``strict``, the first malformed line.

    Notes
    -----
    Steps:

    1. Parse the ``%`` header (:func:`parse_pos_header`): time system, column names,
       separator, station.
    2. Split all data lines at once (polars string kernels) and check each one: field
       count, time, numbers, quality flag. Bad lines are counted as ``malformed line``
       with their line number (or raised with ``strict``).
    3. Times become GPS time (UTC/JST via :data:`GPS_UTC_LEAP_SECONDS`); positions
       become east/north/up errors against ``reference`` (:mod:`overbound.io.geodesy`):
       ``vpe = up``, ``hpe = hypot(east, north)``.
    4. Rows with ``Q = 0`` (no solution) keep NaN errors and PLs. Duplicate times,
       backward times and NaN/negative PLs follow :func:`overbound.io._common.finalize_epochs`.

    The station comes from the first ``% inp file`` that is a RINEX observation file
    (RINEX 2 short name: its first 4 characters in upper case, ``Uslo3610.06O`` ->
    ``USLO``; RINEX 3 long name: its first 9 characters), else ``station``, else the
    file name without suffixes. A ``station`` argument that the header overrides is
    recorded in the report notes.

    References
    ----------
    .. [1] T. Takasu, RTKLIB ver. 2.4.2 Manual, appendix B.4 "Solution file format", 2013.
    .. [2] RTKLIB ``src/solution.c``: ``outsolheads``, ``outsols``, ``decode_solopt``.
    .. [3] IERS Bulletin C (leap seconds), https://hpiers.obspm.fr/eoppc/bul/bulc/.

    Examples
    --------
    >>> from importlib.resources import files
    >>> ref = Reference(35.311803, -120.661092, 134.6419)
    >>> table, report = read_rtklib_pos(files("overbound") / "data/uslo-2006-361-waas.pos.gz", reference=ref)
    >>> table.height, str(table["station"][0]), report.n_rejected
    (2865, 'USLO', 0)
    """
    name, text, lines, header = _load(source)
    log = RowLog(name, strict=strict)
    notes: list[str] = []

    if header.line and (header.field_of("hpl") is None or header.field_of("vpl") is None):
        raise InputError(name, f"{_NO_PL} (columns: {', '.join(header.columns)})", line=header.line)
    good = _good_lines(text, lines, header, log, _NO_PL, reference is None)

    time = _to_gpst(good["_time"], header.time_system)
    if header.time_system != "GPST" and good.height:
        utc_us = _utc_series(good["_time"], header.time_system).dt.epoch("us").to_numpy()
        offsets = sorted({int(v) for v in leap_seconds(utc_us)})
        notes.append(
            f"{header.time_system} times converted to GPST (GPS-UTC = {', '.join(map(str, offsets))} s)"
        )
    solved = (good["_q"] != 0).to_numpy() if "_q" in good.columns else None
    east, north, up, used = _errors(good, header, reference, name, solved)

    stn, how = _station(header, station, name)
    notes.append(f"station {stn} from {how}")
    if station is not None and station != stn:
        notes.append(f"station argument {station!r} ignored: the header names {stn}")
    notes.append(f"reference {reference_text(reference, used)}")

    q = good["_q"] if "_q" in good.columns else None
    none = (q == 0).to_numpy() if q is not None else np.zeros(good.height, dtype=bool)
    nan = np.where(none, np.nan, 1.0)
    cols: dict[str, object] = {
        "_line": good["_line"],
        "time": time,
        "station": pl.Series([stn] * good.height, dtype=pl.String),
        "hpe": np.hypot(east, north) * nan,
        "vpe": up * nan,
        "hpl": good["_hpl"].to_numpy() * nan,
        "vpl": good["_vpl"].to_numpy() * nan,
        "east": east * nan,
        "north": north * nan,
    }
    if "_ns" in good.columns:
        cols["nsv"] = good["_ns"]
    if q is not None:
        cols["mode"] = q.replace_strict(dict(SOLUTION_QUALITY), return_dtype=pl.String)
    if none.any():
        notes.append(f"{int(none.sum())} epochs with Q=0 (no solution) kept as no-solution epochs")
    return finalize_epochs(pl.DataFrame(cols), log, format=_FORMAT, notes=tuple(notes))


def read_pos_positions(source: Source, *, strict: bool = False) -> tuple[pl.DataFrame, RowLog, str]:
    """The positions of any RTKLIB ``.pos`` solution file, with or without protection levels (a truth
    trajectory: :mod:`overbound.io.truth`).

    Every variant :func:`read_rtklib_pos` reads (calendar or week/tow time in GPST, UTC or JST;
    latitude/longitude/height in degrees or d-m-s, or x/y/z-ecef; the separators) is parsed by the same
    code; malformed and cut lines are counted in the returned :class:`~overbound.io._common.RowLog`
    (raised with ``strict``).

    Returns
    -------
    (samples, log, time_system) : ``_line``, ``time`` (GPS time), ``x``, ``y``, ``z`` (ECEF m) and
        ``q`` (the RTKLIB quality flag, null without a ``Q`` column), in file order; the log; the
        header's time system.
    """
    name, text, lines, header = _load(source)
    log = RowLog(name, strict=strict)
    good = _good_lines(text, lines, header, log, "no positions", False)
    xyz = _ecef_positions(good, header, name)
    q = good["_q"] if "_q" in good.columns else pl.Series([None] * good.height, dtype=pl.Int64)
    samples = pl.DataFrame(
        {"_line": good["_line"], "time": _to_gpst(good["_time"], header.time_system),
         "x": xyz[0], "y": xyz[1], "z": xyz[2], "q": q}
    )  # fmt: skip
    return samples, log, header.time_system


def _load(source: Source) -> tuple[str, str, list[str], PosHeader]:
    """The file's name, text, lines and parsed ``%`` header."""
    name, text = source_name(source), read_text(source)
    lines = text.split("\n")
    return name, text, lines, parse_pos_header(lines, name)


def _good_lines(
    text: str, lines: list[str], header: PosHeader, log: RowLog, no_header: str, no_reference: bool
) -> pl.DataFrame:
    """The data lines that parse (:func:`_parse_fields`), the others counted in ``log``; ``InputError``
    without data lines, without a column header line (``no_header`` says what is missing then),
    ``no_reference``, or when every line is bad."""
    name = log.source
    raw = _data_lines(lines, header.separator)
    if raw.height == 0:
        raise InputError(name, "no epochs (no data lines after the % header)")
    if not header.line:
        raise InputError(
            name, "no column header line ('%  GPST  latitude(deg) ... hpl (m) vpl (m)'); " + no_header
        )
    if no_reference:
        raise InputError(name, _NEEDS_REFERENCE)
    log.rows_read = raw.height
    cut = _cut_last_line(text, raw)
    if cut:
        log.reject(cut, "truncated line: the last line has no line end and is shorter than the one before")
        raw = raw.filter(pl.col("_line") != cut)

    parsed = _parse_fields(raw, header)
    for line, reason in parsed.filter(pl.col("_bad").is_not_null()).select("_line", "_bad").iter_rows():
        log.reject(line, reason)
    good = parsed.filter(pl.col("_bad").is_null())
    if good.height == 0:
        raise InputError(
            name, f"no epochs: all {raw.height} data lines rejected (first: line {log.first_bad})"
        )
    return good


def parse_pos_header(lines: list[str], source: str = "<stream>") -> PosHeader:
    """Parse the ``%`` comment lines of a ``.pos`` file.

    Parameters
    ----------
    lines : the file's lines (only those starting with ``%`` are looked at).
    source : file name for error messages.

    Returns
    -------
    PosHeader : ``line == 0`` when no column header line was found.

    Raises
    ------
    InputError
        e/n/u-baseline positions (relative to a base, not to the truth), geoid
        (``geodetic``) heights or the Tokyo datum, or an unsupported field separator.

    Examples
    --------
    >>> h = parse_pos_header(["% inp file  : Uslo3610.06O",
    ...     "%  GPST   latitude(deg) longitude(deg) height(m) Q ns hpl (m) vpl (m)"])
    >>> h.station, h.columns[-1], h.n_fields, h.field_of("vpl")
    ('USLO', 'vpl (m)', 9, 8)
    """
    station = ""
    for i, raw in enumerate(lines, start=1):
        if not raw.startswith("%"):
            if raw.strip():
                break  # the header is the comment block before the first data line
            continue
        body = raw[1:].strip()
        if body.startswith("inp file") and not station:
            station = _station_from_file(body.split(":", 1)[-1].strip())
        if "lat/lon/height=" in body:
            datum_height = body.split("lat/lon/height=", 1)[1].split(",", 1)[0]
            if "geodetic" in datum_height:
                raise InputError(
                    source,
                    "heights are above the geoid ('geodetic'); overbound needs ellipsoidal heights "
                    "(RTKLIB out-height=ellipsoidal)",
                    line=i,
                )
            if "Tokyo" in datum_height:
                raise InputError(source, "positions in the Tokyo datum; overbound needs WGS84", line=i)
        words = body.split()
        if words and words[0] in _TIME_SYSTEMS and any(p in body for p in _POSITION_NAMES):
            return _column_header(body, words[0], station, source, i)
    return PosHeader("GPST", (), (), " ", station, 0)


def _column_header(body: str, system: str, station: str, source: str, line: int) -> PosHeader:
    if "e-baseline(m)" in body:
        raise InputError(
            source,
            "e/n/u-baseline solutions are relative to the base station, not to the truth; "
            "output lat/lon/height or x/y/z-ecef (RTKLIB out-solformat)",
            line=line,
        )
    name = next(p for p in _POSITION_NAMES if p in body)
    after = body[body.index(name) + len(name) : body.index(name) + len(name) + 1]
    sep = " " if (not after or after.isspace()) else after
    if sep != " ":
        if sep not in _SEPARATORS:
            raise InputError(
                source, f"unsupported field separator {sep!r} (use blanks, ',', ';' or '|')", line=line
            )
        body = body.replace(sep, " ")
    tokens: list[str] = []
    for word in body.split()[1:]:
        if word.startswith("(") and tokens:  # "hpl (m)": a unit belongs to the name before it
            tokens[-1] += f" {word}"
        else:
            tokens.append(word)
    widths = tuple(3 if _unit(t) == _DMS_UNIT else 1 for t in tokens)
    return PosHeader(system, tuple(tokens), widths, sep, station, line)


def _key(name: str) -> str:
    """Column key: lower case, unit removed (``"hpl (m)"`` -> ``"hpl"``, ``"x-ecef(m)"`` -> ``"x-ecef"``)."""
    return name.split("(", 1)[0].strip().lower()


def _unit(name: str) -> str:
    return name.split("(", 1)[1].rsplit(")", 1)[0].strip() if "(" in name else ""


def _station_from_file(path: str) -> str:
    base = re.split(r"[\\/]", path)[-1]
    if m := _RINEX2_OBS.match(base):
        return m.group(1).upper()
    if m := _RINEX3_OBS.match(base):
        return m.group(1).upper()
    return ""


def _station(header: PosHeader, station: str | None, name: str) -> tuple[str, str]:
    if header.station:
        return header.station, "the header's first observation file"
    if station is not None:
        return station, "the station argument"
    base = re.split(r"[\\/]", name)[-1]
    stem = base.split(".", 1)[0] if not base.startswith("<") else base
    return stem, "the file name"


def _cut_last_line(text: str, raw: pl.DataFrame) -> int:
    """The line number of a last data line cut short by a truncated file, or 0.

    RTKLIB writes every solution line with fixed field widths and a line end, so a last line
    without its line end that is shorter than the data line before it was cut (``24.6``
    read as ``24.``): a cut inside a number would otherwise parse as another value.
    """
    if text.endswith("\n") or raw.height < 2:
        return 0
    last, before = raw["_text"][-1], raw["_text"][-2]
    return int(raw["_line"][-1]) if len(last) < len(before) else 0


def _data_lines(lines: list[str], sep: str) -> pl.DataFrame:
    """Non-comment, non-blank lines with their 1-based line numbers, split into fields."""
    df = pl.DataFrame({"_text": lines}, schema={"_text": pl.String}).with_row_index("_line", offset=1)
    text = pl.col("_text")
    if sep != " ":
        text = text.str.replace_all(sep, " ", literal=True)
    df = df.with_columns(text.str.strip_chars().alias("_text"))
    df = df.filter((pl.col("_text") != "") & ~pl.col("_text").str.starts_with("%"))
    return df.with_columns(
        pl.col("_text").str.replace_all(r"\s+", " ").str.split(" ").alias("_f"),
        pl.col("_line").cast(pl.Int64),
    )


def _parse_fields(raw: pl.DataFrame, header: PosHeader) -> pl.DataFrame:
    """Typed columns ``_time`` (naive, file's time system), ``_hpl``, ... and ``_bad`` (reason or null)."""
    f = pl.col("_f")
    n = f.list.len()

    def tok(i: int) -> pl.Expr:
        return f.list.get(i, null_on_oob=True)

    # Calendar "yyyy/mm/dd hh:mm:ss.sss" or "week tow" (RTKLIB decode_soltime), chosen per line.
    cal = pl.concat_str([tok(0), tok(1)], separator=" ").str.strptime(
        pl.Datetime("us"), "%Y/%m/%d %H:%M:%S%.f", strict=False
    )
    week = tok(0).cast(pl.Int64, strict=False)
    tow = tok(1).cast(pl.Float64, strict=False)
    ok_wt = (week >= 0) & (week <= 9999) & (tow >= 0) & (tow < _WEEK_S)
    wt_us = week * (_WEEK_S * _US) + (tow * _US).round(0).cast(pl.Int64) + _GPS_EPOCH_UNIX_S * _US
    wt = pl.when(ok_wt).then(pl.from_epoch(wt_us, time_unit="us")).otherwise(None)
    time = pl.when(tok(0).str.contains("/", literal=True)).then(cal).otherwise(wt)

    numeric: dict[str, int] = {}
    for key in ("latitude", "longitude", "height", "x-ecef", "y-ecef", "z-ecef", "hpl", "vpl"):
        i = header.field_of(key)
        if i is not None:
            numeric[key] = i
    dms = [
        (_key(c), header.field_of(_key(c)))
        for c, w in zip(header.columns, header.widths, strict=True)
        if w == 3
    ]
    exprs: dict[str, pl.Expr] = {f"_{k}": tok(i).cast(pl.Float64, strict=False) for k, i in numeric.items()}
    checks: list[tuple[pl.Expr, pl.Expr]] = []  # (is bad, reason), the first true wins
    for k, i in numeric.items():
        checks.append(
            (exprs[f"_{k}"].is_null(), pl.format(f"malformed line: {k} {{}} is not a number", tok(i)))
        )
    for k, i in dms:
        parts = [tok(i + j).cast(pl.Float64, strict=False) for j in range(3)]
        negative = tok(i).str.starts_with("-")
        value = parts[0].abs() + parts[1] / 60.0 + parts[2] / 3600.0
        exprs[f"_{k}"] = pl.when(negative).then(-value).otherwise(value)
        checks.append(
            (
                pl.any_horizontal([p.is_null() for p in parts]),
                pl.format(f"malformed line: {k} {{}} {{}} {{}} is not d m s", tok(i), tok(i + 1), tok(i + 2)),
            )
        )
    if (i := header.field_of("q")) is not None:
        exprs["_q"] = tok(i).cast(pl.Int64, strict=False)
        checks.append(
            (
                exprs["_q"].is_null() | ~exprs["_q"].is_in(list(SOLUTION_QUALITY)),
                pl.format("malformed line: unknown quality flag Q={}", tok(i)),
            )
        )
    if (i := header.field_of("ns")) is not None:
        exprs["_ns"] = tok(i).cast(pl.Int64, strict=False)
        checks.append(
            (
                exprs["_ns"].is_null() | (exprs["_ns"] < 0) | (exprs["_ns"] > 999),
                pl.format("malformed line: ns {} is not a satellite count", tok(i)),
            )
        )
    reason = pl.when(n != header.n_fields).then(
        pl.format(f"malformed line: expected {header.n_fields} fields, got {{}}", n)
    )
    reason = reason.when(time.is_null()).then(pl.format("malformed line: bad time '{} {}'", tok(0), tok(1)))
    t_us = time.dt.epoch("us")
    # a corrupted year (0000, 9999) would otherwise span millennia and make the 1 Hz grids of the
    # analysis allocate gigabytes (issue 13): a malformed line, before any time conversion
    reason = reason.when((t_us < PLAUSIBLE_START_US) | (t_us >= PLAUSIBLE_END_US)).then(
        pl.format(f"malformed line: time '{{}} {{}}' outside {PLAUSIBLE_SPAN}", tok(0), tok(1))
    )
    for bad, why in checks:
        reason = reason.when(bad).then(why)
    reason = reason.otherwise(pl.lit(None, pl.String))
    return raw.select(
        "_line",
        time.alias("_time"),
        *[e.alias(k) for k, e in exprs.items()],
        reason.alias("_bad"),
    )


def _errors(
    good: pl.DataFrame, header: PosHeader, reference: Reference | MeanPosition, source: str, solved
) -> tuple[np.ndarray, np.ndarray, np.ndarray, Reference]:
    """East, north, up errors against ``reference`` (the mean of the ``solved`` epochs' positions for
    :data:`~overbound.io.geodesy.MEAN_POSITION`), and the reference used."""
    xyz = _ecef_positions(good, header, source)
    ref = resolve(reference, *xyz, solved, source)
    return (*enu_errors_ecef(*xyz, ref), ref)


def _ecef_positions(good: pl.DataFrame, header: PosHeader, source: str) -> tuple[np.ndarray, ...]:
    """The lines' positions as ECEF x, y, z (m): as written, or from latitude/longitude/height (WGS-84,
    :mod:`pymap3d`; ``geodetic2enu`` goes through ECEF the same way, so the errors are unchanged)."""
    if {"_x-ecef", "_y-ecef", "_z-ecef"} <= set(good.columns):
        return tuple(good[c].to_numpy() for c in ("_x-ecef", "_y-ecef", "_z-ecef"))
    if {"_latitude", "_longitude", "_height"} <= set(good.columns):
        llh = [good[c].to_numpy() for c in ("_latitude", "_longitude", "_height")]
        return tuple(np.asarray(v, float) for v in pymap3d.geodetic2ecef(*llh))
    raise InputError(
        source, "no position columns (latitude/longitude/height or x/y/z-ecef)", line=header.line
    )


def _utc_series(naive: pl.Series, system: str) -> pl.Series:
    """Times of ``system`` (UTC or JST) as UTC."""
    return naive - dt.timedelta(seconds=_JST_UTC_S) if system == "JST" else naive


def _to_gpst(naive: pl.Series, system: str) -> pl.Series:
    if system == "GPST":
        return naive.alias("time")
    return utc_to_gpst(_utc_series(naive, system)).alias("time")
