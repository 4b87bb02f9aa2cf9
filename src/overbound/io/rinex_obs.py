"""Reader for RINEX 2.xx and 3.0x observation files: plain, gzip or Hatanaka-compressed.

One call reads a whole file into a tidy table, one row per (epoch, satellite) with one column per
observation code, plus the header fields an SBAS user engine needs.

Output model
------------
:class:`RinexObs` holds

* ``table``: ``time`` (``Datetime("us")``, GPS time, whatever the file's time system), ``sat``
  (``"G07"``), ``system`` (one letter), ``prn`` (Int16, as written: SBAS ``S23`` is PRN 123),
  ``flag`` (epoch flag, 0 or 1 = power failure before this epoch), then each observation code as
  Float64 (NaN where the field is blank), and ``<code>_lli`` and ``<code>_ssi`` (UInt8; a blank
  indicator is 0, which RINEX defines as "OK or not known"). Rows are in file order.
* ``epochs``: one row per observation epoch: ``time``, ``flag``, ``nsat``, ``clock`` (receiver
  clock offset in s from the epoch line, NaN when blank), ``line`` (1-based).
* ``events``: the special records of epoch flags 2-5 (antenna moved, new occupation, header
  information, external event) and the cycle-slip records of flag 6: ``line``, ``flag``, ``time``
  (null when the epoch fields are blank, as RINEX 2 allows for events), ``records``, ``text``.
  Their content is not applied, except that a change of observation types refuses the file
  (clear error) rather than misreading it.
* ``header``: :class:`ObsHeader`; ``rejected``: ``file``, ``line``, ``reason`` of every record
  that could not be read and of every observation field that was unreadable (set to NaN).

Observation codes
-----------------
RINEX 3 codes are kept (``C1C``, ``L1C``, ``S1C``, ``C1W``...). RINEX 2 codes, which do not say
the tracking mode, are renamed to RINEX 3 codes by :data:`RINEX2_CODES`, per system:

======  ========================================================================================
GPS     C1→C1C P1→C1W L1→L1C D1→D1C S1→S1C; C2→C2X (L2C, RINEX 2.11) P2→C2W L2→L2W D2→D2W
        S2→S2W; C5/L5/D5/S5→…5X
GLO     C1→C1C P1→C1P L1→L1C D1→D1C S1→S1C; C2→C2C P2→C2P L2→L2P D2→D2P S2→S2P
GAL     band 1/5/6/7/8 (E1, E5a, E6, E5b, E5): C1→C1X L1→L1X ... C8→C8X (data+pilot "X")
SBAS    C1→C1C L1→L1C D1→D1C S1→S1C; C5/L5/D5/S5→…5X
======  ========================================================================================

The carrier phase and SNR of band 1 follow the C/A code (``L1C``, ``S1C``), those of GPS band 2
the semi-codeless P(Y) tracking (``W``) that RINEX 2-era receivers used; these letters are a
convention, not information in the file. :attr:`ObsHeader.obs_types` keeps the names as written.

Speed
-----
The file is one byte array (:mod:`overbound.io._rinex`): epoch lines are found by their fixed
columns (``>`` in RINEX 3; date blanks, the seconds' decimal point and the flag digit in RINEX 2),
record lengths are checked all at once, and each observation code of all records is one
``(n, 16)`` byte matrix decoded with integer arithmetic. Python loops only over header lines,
codes, and (when records are damaged) epochs. A day of 1 Hz GPS observations reads in about a
second; ``bench/bench_rinex.py`` measures it.

Malformed input
---------------
The report keeps issue 13's rule, ``rows_read = rows_kept + rejected`` (``unaccounted == 0``),
where a *row* is

* a satellite record of an observation epoch (flags 0 and 1): kept as a table row, or rejected
  by itself (``bad_satellite``: unreadable identifier; ``unknown_system``: a system without
  observation types; ``duplicate_satellite``: repeated in its epoch). Records of systems left
  out by ``systems=`` are skipped, neither read nor rejected;
* a rejected epoch record, counted as **one** row whatever its satellite count, because that
  count is what cannot be trusted (or read) in a damaged record: ``bad_epoch`` (unreadable
  date, flag or count, or a time outside :data:`overbound.io.gpstime.PLAUSIBLE_SPAN`, GPS
  time), ``record_length`` (the record's lines do not end on an epoch line), ``truncated`` (the
  file ends inside it), ``bad_event`` (an event record of flags 2-5 whose count of lines are not
  all header lines, label in columns 61-80: a damaged flag or count that would swallow
  observations as "header records"), ``orphan_slips`` (a cycle-slip record, flag 6, at a time
  that has no observation epoch: most likely an observation epoch whose flag was damaged, whose
  satellites would otherwise vanish from the table unseen), and ``no_epoch`` (non-blank lines
  before the first epoch line). The lines from a rejected epoch line to the next epoch line read
  belong to that row.

Event records (flags 2-5) and cycle-slip records (flag 6) that are sound are not rows (their
count is in the notes, by flag). Each rejection is listed with file, line (1-based) and reason
in ``rejected``; ``first_bad`` names the first. An unreadable observation field becomes NaN and
is counted under ``invalidated`` (the row is kept). A file that is not RINEX observation data,
an unsupported version, a truncated header, an unreadable header time, or a truncated or corrupt
compressed stream (including one that ``crx2rnx`` expands only with a warning, see
:func:`overbound.io._rinex.load_bytes`) raises :class:`~overbound.io.schema.InputError` with a
one-line message naming the file (and line).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
import polars as pl

from overbound.io._rinex import (
    GPS_EPOCH_US,
    US,
    Lines,
    civil_to_us,
    load_bytes,
    parse_digits,
    parse_fixed,
    parse_float,
    rinex_version,
    to_gpst,
)
from overbound.io.gpstime import PLAUSIBLE_SPAN, plausible_us
from overbound.io.open import Source, source_name
from overbound.io.sbas_frames import REJECTED_SCHEMA
from overbound.io.schema import InputError, ReadReport

__all__ = ["RINEX2_CODES", "ObsHeader", "RinexObs", "read_rinex_obs"]

_GPS2 = {
    "C1": "C1C", "P1": "C1W", "L1": "L1C", "D1": "D1C", "S1": "S1C",
    "C2": "C2X", "P2": "C2W", "L2": "L2W", "D2": "D2W", "S2": "S2W",
    "C5": "C5X", "L5": "L5X", "D5": "D5X", "S5": "S5X",
}  # fmt: skip
_GLO2 = {
    "C1": "C1C", "P1": "C1P", "L1": "L1C", "D1": "D1C", "S1": "S1C",
    "C2": "C2C", "P2": "C2P", "L2": "L2P", "D2": "D2P", "S2": "S2P",
}  # fmt: skip
_GAL2 = {f"{k}{b}": f"{k}{b}X" for k in "CLDS" for b in "15678"}
_SBS2 = {
    "C1": "C1C",
    "L1": "L1C",
    "D1": "D1C",
    "S1": "S1C",
    "C5": "C5X",
    "L5": "L5X",
    "D5": "D5X",
    "S5": "S5X",
}
#: RINEX 2 observation code -> RINEX 3 code, per system letter (see the module notes).
RINEX2_CODES = MappingProxyType(
    {"G": MappingProxyType(_GPS2), "R": MappingProxyType(_GLO2), "E": MappingProxyType(_GAL2),
     "S": MappingProxyType(_SBS2)}
)  # fmt: skip

_SYSTEMS = "GRECJSI"
_DEFAULT_TIME_SYSTEM = {"G": "GPS", "R": "GLO", "E": "GAL", "C": "BDT", "J": "QZS", "I": "IRN", "S": "GPS"}
_FIELD = 16  # F14.3 value + LLI + SSI
_BASE_COLUMNS = ("time", "sat", "system", "prn", "flag")
_CHUNK = 1 << 15  # satellite records decoded at once (cache-sized temporaries)
_REASONS_TEXT = {
    "no_epoch": "line outside any epoch record",
    "record_length": "lines of the record do not match the count on its epoch line",
    "truncated": "file ends inside this epoch record",
    "bad_epoch": f"unreadable epoch line (date, flag or count) or time outside {PLAUSIBLE_SPAN}",
    "bad_event": "event record (flags 2-5) not followed by its count of header lines (label in cols 61-80)",
    "orphan_slips": "cycle-slip record (flag 6) at a time without an observation epoch",
    "bad_satellite": "unreadable satellite identifier",
    "unknown_system": "satellite system without observation types in the header",
    "duplicate_satellite": "satellite repeated in the epoch",
    "bad_value": "unreadable observation field (set to NaN)",
}
#: Reasons that reject a whole epoch record (one row each, whatever its satellite count).
_RECORD_REASONS = ("no_epoch", "record_length", "truncated", "bad_epoch", "bad_event", "orphan_slips")


@dataclass(frozen=True, slots=True)
class ObsHeader:
    """The header of a RINEX observation file.

    Attributes
    ----------
    version : e.g. 2.11 or 3.05.
    system : file satellite system letter (``G``, ``R``, ``E``, ``M`` mixed...).
    marker_name, marker_number, observer, agency : as written.
    receiver_number, receiver_type, receiver_version : ``REC # / TYPE / VERS``.
    antenna_number, antenna_type : ``ANT # / TYPE`` (type includes the radome, cols 36-39).
    approx_position : ``APPROX POSITION XYZ``, ECEF metres (``None`` if absent).
    antenna_delta_hen : ``ANTENNA: DELTA H/E/N``, metres (ARP above the marker, east, north).
    interval : ``INTERVAL`` in seconds, ``None`` if absent.
    time_of_first_obs, time_of_last_obs : GPS time, microseconds since 1970 (``None`` if absent).
    time_system : the epochs' time system (``GPS``, ``GLO`` = UTC, ``GAL``, ``BDT``...).
    obs_types : per system, the codes as written (RINEX 2: the one list, under every system).
    codes : per system, the codes as named in the table (RINEX 3 names), same order; for a RINEX 2
        type that the system does not have (P1 of an SBAS satellite) ``None``.
    glonass_slots : GLONASS slot -> frequency number (RINEX 3 ``GLONASS SLOT / FRQ #``).
    leap_seconds : ``LEAP SECONDS`` if present.
    comments : the ``COMMENT`` lines.
    """

    version: float
    system: str
    marker_name: str = ""
    marker_number: str = ""
    observer: str = ""
    agency: str = ""
    receiver_number: str = ""
    receiver_type: str = ""
    receiver_version: str = ""
    antenna_number: str = ""
    antenna_type: str = ""
    approx_position: tuple[float, float, float] | None = None
    antenna_delta_hen: tuple[float, float, float] = (0.0, 0.0, 0.0)
    interval: float | None = None
    time_of_first_obs: int | None = None
    time_of_last_obs: int | None = None
    time_system: str = "GPS"
    obs_types: dict[str, tuple[str, ...]] = field(default_factory=dict)
    codes: dict[str, tuple[str | None, ...]] = field(default_factory=dict)
    glonass_slots: dict[int, int] = field(default_factory=dict)
    leap_seconds: int | None = None
    comments: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True, eq=False)
class RinexObs:
    """A RINEX observation file as tables (see the module notes)."""

    header: ObsHeader
    table: pl.DataFrame
    epochs: pl.DataFrame
    events: pl.DataFrame
    rejected: pl.DataFrame
    file: str

    @property
    def codes(self) -> list[str]:
        """The observation code columns of :attr:`table`."""
        return [c for c in self.table.columns if c not in _BASE_COLUMNS and not c.endswith(("_lli", "_ssi"))]


def read_rinex_obs(
    source: Source,
    *,
    systems: str | None = None,
    codes: list[str] | tuple[str, ...] | None = None,
    strict: bool = False,
) -> tuple[RinexObs, ReadReport]:
    """Read a RINEX 2.xx / 3.0x observation file (plain, gzip, Hatanaka ``.crx``/``.yyd``, ``.Z``).

    Parameters
    ----------
    source : path or binary stream.
    systems : keep only these system letters (e.g. ``"G"``); default all.
    codes : keep only these observation codes (RINEX 3 names, after the RINEX 2 mapping); default
        all. Reading fewer codes is faster.
    strict : raise :class:`InputError` at the first rejected record or unreadable field.

    Returns
    -------
    obs : :class:`RinexObs`.
    report : ``rows_read`` = ``rows_kept`` + rejected rows (satellite records, and one row per
        rejected epoch record: see "Malformed input" in the module notes), ``rejected`` by
        reason, ``invalidated`` (``bad_value``: fields set to NaN), ``first_bad``; notes give
        the epoch counts by flag.

    Raises
    ------
    InputError
        Not a RINEX observation file, unsupported version, no ``END OF HEADER``, an unreadable
        header field, a truncated or corrupt compressed stream (Hatanaka: also one that
        ``crx2rnx`` warns about), observation types changed by an event record, or
        (``strict``) any malformed record.
    """
    name = source_name(source)
    lines = Lines.of(load_bytes(source))
    header, body = _parse_header(lines, name)
    log = _Log(name, strict)
    v3 = header.version >= 3
    epochs = _epoch_records(lines, body, header, v3, log)
    _refuse_type_changes(lines, epochs, v3, name)
    keep_sys = set(systems) if systems else None
    sat = _satellite_records(lines, epochs, header, v3, keep_sys, log)
    columns = _code_columns(header, {chr(c) for c in np.unique(sat.system).tolist()}, codes, name)
    values = _observations(lines, sat, header, v3, columns, log)
    table = _table(epochs, sat, columns, values)
    obs = RinexObs(
        header=header,
        table=table,
        epochs=_epochs_frame(epochs),
        events=_events_frame(lines, epochs, v3),
        rejected=log.frame(),
        file=name,
    )
    return obs, _report(obs, log, sat.n_seen)


# --------------------------------------------------------------------------- header


def _parse_header(lines: Lines, name: str) -> tuple[ObsHeader, int]:
    """The header fields and the index of the first body line."""
    version, first = rinex_version(lines, name, "observation")
    kind, system = first[20:21], (first[40:41].strip() or "G")
    if kind != "O":
        what = {"N": "navigation", "G": "GLONASS navigation", "H": "GEO navigation", "M": "meteorological"}
        raise InputError(
            name, f"RINEX {what.get(kind, repr(kind))} file, expected observation data ('O')", line=1
        )
    if not (2.0 <= version < 4.0):
        raise InputError(name, f"RINEX version {version:.2f} not supported (2.xx and 3.0x)", line=1)
    fields: dict = {"version": version, "system": system}
    obs_types: dict[str, list[str]] = {}
    comments: list[str] = []
    glo: dict[int, int] = {}
    pending: tuple[str, int] | None = None  # (system, count) of an obs-type list still being read
    end = None
    for i in range(1, min(len(lines), 10_000)):
        text = lines.text(i)
        label = text[60:].strip()
        body = text[:60]
        if label == "END OF HEADER":
            end = i + 1
            break
        if label == "COMMENT":
            comments.append(body.rstrip())
        elif label in ("# / TYPES OF OBSERV", "SYS / # / OBS TYPES"):
            pending = _obs_type_line(body, label, obs_types, pending, name, i)
        else:
            _header_field(label, body, fields, glo, name, i)
    if end is None:
        raise InputError(name, "no END OF HEADER: truncated or not a RINEX observation file")
    if not obs_types:
        raise InputError(
            name, "no observation types in the header ('# / TYPES OF OBSERV' / 'SYS / # / OBS TYPES')"
        )
    ts = fields.pop("time_system", "") or _DEFAULT_TIME_SYSTEM.get(system, "GPS")
    to_gpst(np.zeros(0, np.int64), ts, name)  # refuses an unknown time system here, with the file name
    for key in ("time_of_first_obs", "time_of_last_obs"):
        if key in fields:
            fields[key] = int(to_gpst(np.array([fields[key]]), ts, name)[0])
    typed = {s: tuple(v) for s, v in obs_types.items()}
    if version < 3:
        present = [system] if system != "M" else ["G", "R", "E", "S"]
        typed = {s: typed["*"] for s in present}
        mapped = {s: tuple(_rinex3_name(s, c) for c in typed[s]) for s in present}
    else:
        mapped = dict(typed)
    header = ObsHeader(
        **fields,
        time_system=ts,
        obs_types=typed,
        codes=mapped,
        glonass_slots=glo,
        comments=tuple(comments),
    )
    return header, end


def _rinex3_name(system: str, code: str) -> str | None:
    """RINEX 3 name of a RINEX 2 code for one system; ``None`` for a RINEX 2.11 code that this
    system does not have (e.g. P1 for SBAS: always blank); a non-standard code keeps its name."""
    table = RINEX2_CODES.get(system, {})
    if code in table:
        return table[code]
    return None if any(code in t for t in RINEX2_CODES.values()) else code


def _obs_type_line(
    body: str,
    label: str,
    out: dict[str, list[str]],
    pending: tuple[str, int] | None,
    name: str,
    i: int,
) -> tuple[str, int] | None:
    """Add the codes of one obs-type header line; return what is still expected."""
    if label == "# / TYPES OF OBSERV":  # RINEX 2: I6, 9(4X, A2)
        if body[:6].strip():
            pending = ("*", _int(body[:6], name, i))
            out["*"] = []
        width, first, per_line = 6, 10, 9
        size = 2
    else:  # RINEX 3: A1, 2X, I3, 13(1X, A3)
        if body[0] != " ":
            pending = (body[0], _int(body[3:6], name, i))
            out[body[0]] = []
        width, first, per_line = 4, 7, 13
        size = 3
    if pending is None:
        raise InputError(name, f"'{label}' continuation line without a first line", line=i + 1)
    sys_, count = pending
    codes = [body[first + width * k : first + width * k + size].strip() for k in range(per_line)]
    out[sys_].extend(c for c in codes[: count - len(out[sys_])] if c)
    return pending if len(out[sys_]) < count else None


def _header_field(label: str, body: str, f: dict, glo: dict[int, int], name: str, i: int) -> None:
    """Store one recognised header line into ``f`` (others are ignored)."""
    if label == "MARKER NAME":
        f["marker_name"] = body.strip()
    elif label == "MARKER NUMBER":
        f["marker_number"] = body[:20].strip()
    elif label == "OBSERVER / AGENCY":
        f["observer"], f["agency"] = body[:20].strip(), body[20:60].strip()
    elif label == "REC # / TYPE / VERS":
        f["receiver_number"], f["receiver_type"] = body[:20].strip(), body[20:40].strip()
        f["receiver_version"] = body[40:60].strip()
    elif label == "ANT # / TYPE":
        f["antenna_number"], f["antenna_type"] = body[:20].strip(), body[20:40].strip()
    elif label == "APPROX POSITION XYZ":
        f["approx_position"] = _floats(body, 3, 14, name, i)
    elif label == "ANTENNA: DELTA H/E/N":
        f["antenna_delta_hen"] = _floats(body, 3, 14, name, i)
    elif label == "INTERVAL":
        f["interval"] = _floats(body, 1, 10, name, i)[0]
    elif label in ("TIME OF FIRST OBS", "TIME OF LAST OBS"):
        key = "time_of_first_obs" if label.endswith("FIRST OBS") else "time_of_last_obs"
        f[key] = _header_time(body, name, i)
        if label == "TIME OF FIRST OBS" or not f.get("time_system"):
            f["time_system"] = body[48:51].strip()
    elif label == "LEAP SECONDS":
        f["leap_seconds"] = _int(body[:6], name, i)
    elif label == "GLONASS SLOT / FRQ #":
        for k in range(8):
            slot, frq = body[4 + 7 * k : 7 + 7 * k].strip(), body[8 + 7 * k : 10 + 7 * k].strip()
            if slot and frq:
                glo[_int(slot[1:] if slot[0] == "R" else slot, name, i)] = _int(frq, name, i)


def _header_time(body: str, name: str, i: int) -> int:
    """``TIME OF FIRST/LAST OBS`` (5I6, F13.7) as microseconds since 1970, file time system."""
    try:
        y, mo, d, h, mi = (int(body[6 * k : 6 * k + 6]) for k in range(5))
        sec = float(body[30:43])
    except ValueError:
        raise InputError(name, f"unreadable time {body[:43].strip()!r}", line=i + 1) from None
    if not (0 <= sec < 61 and 0 <= y < 10_000):  # also NaN and inf
        raise InputError(name, f"date out of range {body[:43].strip()!r}", line=i + 1)
    t, ok = civil_to_us(*(np.array([v]) for v in (y, mo, d, h, mi, round(sec * US))))
    if not ok[0]:
        raise InputError(name, f"date out of range {body[:43].strip()!r}", line=i + 1)
    return int(t[0])


def _floats(body: str, n: int, width: int, name: str, i: int) -> tuple[float, ...]:
    try:
        return tuple(float(body[width * k : width * (k + 1)]) for k in range(n))
    except ValueError:
        raise InputError(
            name, f"expected {n} numbers of width {width}, got {body.rstrip()!r}", line=i + 1
        ) from None


def _int(text: str, name: str, i: int) -> int:
    try:
        return int(text)
    except ValueError:
        raise InputError(name, f"expected an integer, got {text.strip()!r}", line=i + 1) from None


# --------------------------------------------------------------------------- rejections


@dataclass
class _Log:
    """Rejected records and unreadable fields: (line index, reason), or raise when strict."""

    name: str
    strict: bool
    lines: list[np.ndarray] = field(default_factory=list)
    reasons: list[str] = field(default_factory=list)
    counts: Counter = field(default_factory=Counter)

    def add(self, line_index: np.ndarray, reason: str) -> None:
        line_index = np.atleast_1d(np.asarray(line_index, dtype=np.int64))
        if not line_index.size:
            return
        if self.strict:
            raise InputError(self.name, _REASONS_TEXT[reason], line=int(line_index.min()) + 1)
        self.lines.append(line_index)
        self.reasons.extend([reason] * line_index.size)
        self.counts[reason] += line_index.size

    def frame(self) -> pl.DataFrame:
        if not self.lines:
            return pl.DataFrame(schema=REJECTED_SCHEMA)
        line = np.concatenate(self.lines) + 1
        order = np.argsort(line, kind="stable")
        return pl.DataFrame(
            {"file": [self.name] * len(line), "line": line[order], "reason": np.asarray(self.reasons)[order]},
            schema=REJECTED_SCHEMA,
        )


# --------------------------------------------------------------------------- epochs


@dataclass(frozen=True, slots=True)
class _Epochs:
    """Accepted epoch records (all flags), in file order."""

    line: np.ndarray  # 0-based index of the epoch line
    flag: np.ndarray  # int8
    count: np.ndarray  # satellites (flags 0, 1, 6) or special records (2-5)
    n_head: np.ndarray  # epoch lines (RINEX 2: one per 12 satellites)
    time: np.ndarray  # int64 GPS microseconds; -1 where blank (events)
    clock: np.ndarray  # receiver clock offset, s


def _epoch_records(lines: Lines, body: int, header: ObsHeader, v3: bool, log: _Log) -> _Epochs:
    """Find the epoch lines, check every record's length, parse date, flag and count."""
    rows = np.arange(body, len(lines), dtype=np.int64)
    cand = _candidates(lines, rows, v3)
    flag_col, count_col = (31, 32) if v3 else (28, 29)
    flag = lines.col(cand, flag_col).astype(np.int64) - ord("0")
    count, count_ok, _ = parse_digits(lines.chars(cand, count_col, 3))
    n_obs = max(len(v) for v in header.obs_types.values())
    per_sat = 1 if v3 else -(-n_obs // 5)
    sat_flags = (flag <= 1) | (flag == 6)
    n_head = np.where(v3 | ~sat_flags, 1, np.maximum(1, -(-count // 12)))
    size = np.where(sat_flags & ~v3, n_head + count * per_sat, 1 + count)
    size = np.where(count_ok & (count >= 0), size, 1)
    special = count_ok & (count >= 0) & (flag >= 2) & (flag <= 5)
    keep = _walk(lines, body, cand, size, _headers_follow(lines, cand, count, special), log)
    cand, flag, count, n_head = cand[keep], flag[keep], count[keep], n_head[keep]
    bad = ~count_ok[keep] | (flag < 0) | (flag > 6)
    time, clock, time_ok = _epoch_times(lines, cand, flag, header, v3)
    bad |= ~time_ok
    log.add(cand[bad], "bad_epoch")
    slips = ~bad & (flag == 6)
    if slips.any():  # cycle slips of an epoch that has no observations: a damaged flag, most likely
        orphan = slips & ~np.isin(time, time[~bad & (flag <= 1)])
        log.add(cand[orphan], "orphan_slips")
        bad |= orphan
    good = ~bad
    return _Epochs(cand[good], flag[good].astype(np.int8), count[good], n_head[good], time[good], clock[good])


def _candidates(lines: Lines, rows: np.ndarray, v3: bool) -> np.ndarray:
    """Lines that look like epoch lines (a superset; :func:`_walk` keeps those the record lengths reach)."""
    if v3:
        return rows[lines.col(rows, 0) == ord(">")]
    blank = ord(" ")
    c18 = lines.col(rows, 18)  # the seconds' decimal point: a digit or blank on observation lines
    rows = rows[(c18 == ord(".")) | (c18 == blank)]
    c = {k: lines.col(rows, k) for k in (0, 3, 6, 9, 12, 18, 26, 27, 28)}
    flag_digit = (c[28] >= ord("0")) & (c[28] <= ord("6"))
    frame = flag_digit & (c[26] == blank) & (c[27] == blank) & (c[0] == blank)
    dated = (
        frame & (c[18] == ord(".")) & (c[3] == blank) & (c[6] == blank) & (c[9] == blank) & (c[12] == blank)
    )
    maybe_event = np.flatnonzero(frame & ~dated & (c[28] >= ord("2")) & (c[28] <= ord("5")))
    undated = np.zeros(len(rows), bool)
    if maybe_event.size:  # RINEX 2 lets event epochs leave the date blank
        undated[maybe_event] = (lines.chars(rows[maybe_event], 0, 26) == blank).all(axis=1)
    return rows[dated | undated]


def _headers_follow(lines: Lines, cand: np.ndarray, count: np.ndarray, special: np.ndarray) -> np.ndarray:
    """False for an event record (``special``: flags 2-5) whose ``count`` following lines (those
    the file has) are not all header lines; True for every other candidate.

    A header line carries its label from column 61 on, which begins with a letter or ``#``;
    column 61 of an observation line is a digit or blank (inside the 4th F14.3 field), that of a
    RINEX 2 epoch line with 10 or more satellites the digit of a PRN. So an epoch flag or count
    damaged into an event record that would swallow observations is found at its first line.
    """
    out = np.ones(len(cand), bool)
    ev = np.flatnonzero(special)
    if not ev.size:
        return out
    first = cand[ev] + 1
    last = np.minimum(first + count[ev], len(lines))  # lines past the end are the walk's "truncated"
    lo = int(first.min())
    c60 = lines.col(np.arange(lo, max(int(last.max()), lo)), 60) | 0x20  # lower case
    label = ((c60 >= ord("a")) & (c60 <= ord("z"))) | (c60 == ord("#"))
    done = np.concatenate([[0], np.cumsum(label)])  # done[i]: header-like lines in lo .. lo+i-1
    out[ev] = done[last - lo] - done[first - lo] == last - first
    return out


def _walk(
    lines: Lines, body: int, cand: np.ndarray, size: np.ndarray, sound: np.ndarray, log: _Log
) -> np.ndarray:
    """Indices of the candidates that start records, following the record lengths from the first.

    The usual case (every record ends where the next candidate starts, every event record is
    ``sound``) is checked at once; only a damaged file goes through the loop, which rejects an
    event record not followed by header lines (``bad_event``) or a record whose end does not
    fall on an epoch line or the end of the file (``record_length``), and resumes at the next
    candidate.
    """
    n = len(lines)
    if not len(cand):
        if (lines.length[body:] > 0).any():
            log.add(body + int(np.flatnonzero(lines.length[body:] > 0)[0]), "no_epoch")
        return np.zeros(0, np.int64)
    nonblank_before = np.flatnonzero(lines.length[body : cand[0]] > 0)
    if nonblank_before.size:
        log.add(body + nonblank_before[0], "no_epoch")
    end = cand + size
    tail_blank = _blank_from(lines)
    if sound.all() and (end[:-1] == cand[1:]).all() and end[-1] <= n and tail_blank[end[-1]]:
        return np.arange(len(cand))
    index_of = np.full(n + 1, -1, np.int64)
    index_of[cand] = np.arange(len(cand))
    keep, k = [], 0
    while k < len(cand):
        j = int(end[k])
        if not sound[k]:
            log.add(cand[k], "bad_event")
            k += 1
            continue
        if j > n:
            log.add(cand[k], "truncated")
            break
        if tail_blank[j]:
            keep.append(k)
            break
        if index_of[j] >= 0:
            keep.append(k)
            k = int(index_of[j])
        else:
            log.add(cand[k], "record_length")
            k += 1
    return np.asarray(keep, dtype=np.int64)


def _blank_from(lines: Lines) -> np.ndarray:
    """``out[j]``: lines ``j`` to the end are all blank (length ``n + 1``)."""
    nonblank = np.flatnonzero(lines.length > 0)
    last = nonblank[-1] if nonblank.size else -1
    out = np.zeros(len(lines) + 1, bool)
    out[last + 1 :] = True
    return out


def _epoch_times(
    lines: Lines, cand: np.ndarray, flag: np.ndarray, header: ObsHeader, v3: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """GPS microseconds (-1 for blank event dates), receiver clock offset (s), and which parsed."""
    if v3:  # A1, 1X, I4, 4(1X, I2.2), F11.7, 2X, I1, I3, 6X, F15.12
        ycol, cols, sec_col, clock_col, clock_w, clock_d = 2, (7, 10, 13, 16), 18, 41, 15, 12
        year, y_ok, _ = parse_digits(lines.chars(cand, ycol, 4))
    else:  # 1X, I2.2, 4(1X, I2), F11.7, 2X, I1, I3, 12(A1, I2), F12.9
        ycol, cols, sec_col, clock_col, clock_w, clock_d = 1, (4, 7, 10, 13), 15, 68, 12, 9
        year, y_ok, _ = parse_digits(lines.chars(cand, ycol, 2))
        year = np.where(year < 80, 2000 + year, 1900 + year)
    parts = [parse_digits(lines.chars(cand, c, 2)) for c in cols]
    sec, s_ok, s_blank = parse_fixed(lines.chars(cand, sec_col, 11), 7)
    us = np.round(np.nan_to_num(sec) * US).astype(np.int64)
    t, date_ok = civil_to_us(year, *(p[0] for p in parts), us)
    ok = y_ok & s_ok & ~s_blank & date_ok & np.logical_and.reduce([p[1] for p in parts])
    t = to_gpst(np.where(ok, t, GPS_EPOCH_US), header.time_system, "")
    ok &= plausible_us(t)  # 1980-01-06 to the present and a margin, in GPS time
    event = (flag >= 2) & (flag <= 5)
    undated = event & (lines.chars(cand, 0 if not v3 else 2, 26 if not v3 else 27) == ord(" ")).all(axis=1)
    clock, c_ok, _ = parse_fixed(lines.chars(cand, clock_col, clock_w), clock_d)
    if not c_ok.all():
        fallback, _, _ = parse_float(lines.chars(cand[~c_ok], clock_col, clock_w))
        clock[~c_ok] = fallback
    return np.where(undated | ~ok, -1, t), clock, ok | undated


def _refuse_type_changes(lines: Lines, epochs: _Epochs, v3: bool, name: str) -> None:
    """An event record that redefines the observation types would shift every later field."""
    for k in np.flatnonzero((epochs.flag >= 2) & (epochs.flag <= 5)).tolist():
        first = int(epochs.line[k]) + 1
        for i in range(first, first + int(epochs.count[k])):
            if lines.text(i)[60:].strip() in ("# / TYPES OF OBSERV", "SYS / # / OBS TYPES"):
                raise InputError(
                    name,
                    "observation types redefined by an event record (epoch flag 4): not supported; "
                    "split the file there",
                    line=i + 1,
                )


# --------------------------------------------------------------------------- satellites


@dataclass(frozen=True, slots=True)
class _Sats:
    """Satellite records of the observation epochs (flags 0 and 1) that are kept."""

    epoch: np.ndarray  # index into _Epochs
    system: np.ndarray  # uint8 letter
    prn: np.ndarray  # int64
    first_line: np.ndarray  # index of the record's first data line
    n_seen: int  # satellite records read: kept, or rejected for a satellite-level reason


def _satellite_records(
    lines: Lines, epochs: _Epochs, header: ObsHeader, v3: bool, keep_sys: set[str] | None, log: _Log
) -> _Sats:
    obs_ep = np.flatnonzero(epochs.flag <= 1)
    count = epochs.count[obs_ep]
    epoch = np.repeat(obs_ep, count)
    j = np.arange(len(epoch)) - np.repeat(np.cumsum(count) - count, count)
    line0 = epochs.line[epoch]
    if v3:
        first_line = line0 + 1 + j
        ident = lines.chars(first_line, 0, 3)
        id_line = first_line
    else:
        per_sat = -(-max(len(v) for v in header.obs_types.values()) // 5)
        id_line = line0 + j // 12
        ident = lines.chars(id_line, 32 + 3 * (j % 12), 3)
        first_line = line0 + epochs.n_head[epoch] + j * per_sat
    default = "G" if header.system == "M" else header.system
    system = np.where(ident[:, 0] == ord(" "), ord(default), ident[:, 0]).astype(np.uint8)
    prn, prn_ok, prn_blank = parse_digits(ident[:, 1:3])
    bad = ~prn_ok | prn_blank | ~np.isin(system, np.frombuffer(_SYSTEMS.encode(), np.uint8))
    log.add(id_line[bad], "bad_satellite")
    known = np.isin(system, np.frombuffer("".join(header.codes).encode(), np.uint8))
    unknown = ~bad & ~known
    log.add(id_line[unknown], "unknown_system")
    ok = ~bad & ~unknown
    key = (epoch * 256 + system) * 1000 + prn
    ok &= _first_occurrence(key, ok, id_line, log)
    n_seen = len(epoch)
    if keep_sys is not None:  # records of the other systems are skipped unread (not rejected)
        wanted = np.isin(system, np.frombuffer("".join(sorted(keep_sys)).encode(), np.uint8))
        n_seen -= int((ok & ~wanted).sum())
        ok &= wanted
    return _Sats(epoch[ok], system[ok], prn[ok], first_line[ok], n_seen=n_seen)


def _first_occurrence(key: np.ndarray, ok: np.ndarray, where: np.ndarray, log: _Log) -> np.ndarray:
    """False for a repeated (epoch, satellite); counts the repeats.

    Keys grow with the epoch; when the satellites of every epoch are listed in increasing order
    (the usual case) the keys increase strictly and no sort is needed.
    """
    out = np.ones(len(key), bool)
    idx = np.flatnonzero(ok)
    k = key[idx]
    if (np.diff(k) > 0).all():
        return out
    order = np.argsort(k, kind="stable")
    same = np.flatnonzero(np.diff(k[order]) == 0)
    if same.size:
        dup = idx[order[same + 1]]
        out[dup] = False
        log.add(where[dup], "duplicate_satellite")
    return out


# --------------------------------------------------------------------------- observations


def _code_columns(header: ObsHeader, present: set[str], codes, name: str) -> list[str]:
    """Table columns: the codes of the systems present in the records, in header order, or
    ``codes`` if given (each must be an observation type of the header)."""
    out: list[str] = []
    for s, names in header.codes.items():
        if s in present:
            out.extend(c for c in names if c is not None and c not in out)
    if codes is None:
        return out
    known = {c for names in header.codes.values() for c in names if c is not None}
    missing = [c for c in codes if c not in known]
    if missing:
        raise InputError(
            name, f"observation codes {missing} not in the file (it has {', '.join(sorted(known))})"
        )
    return list(dict.fromkeys(codes))


def _observations(
    lines: Lines, sat: _Sats, header: ObsHeader, v3: bool, columns: list[str], log: _Log
) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per column: values (NaN blank), LLI and SSI (uint8), over the satellite records."""
    n = len(sat.epoch)
    out = {c: (np.full(n, np.nan), np.zeros(n, np.uint8), np.zeros(n, np.uint8)) for c in columns}
    wanted = set(columns)
    for s, names in header.codes.items():
        rows = np.flatnonzero(sat.system == ord(s))
        if not rows.size:
            continue
        for m, code in enumerate(names):
            if code is None or code not in wanted:
                continue
            if v3:
                line, col = sat.first_line[rows], 3 + _FIELD * m
            else:
                line, col = sat.first_line[rows] + m // 5, _FIELD * (m % 5)
            value, lli, ssi = _decode_fields(lines, line, col, log)
            out[code][0][rows] = value
            out[code][1][rows] = lli
            out[code][2][rows] = ssi
    return out


def _decode_fields(lines: Lines, line: np.ndarray, col: int, log: _Log) -> tuple[np.ndarray, ...]:
    """F14.3 value, LLI and SSI digits of one 16-column field on each line, in cache-sized chunks."""
    n = len(line)
    value = np.empty(n)
    lli = np.empty(n, np.uint8)
    ssi = np.empty(n, np.uint8)
    for s in range(0, n, _CHUNK):
        part = line[s : s + _CHUNK]
        mat = lines.chars(part, col, _FIELD)
        v, ok, _ = parse_fixed(mat, 3, width=14)
        if not ok.all():  # another layout (exponent, shifted point): read it generically, else NaN
            bad = np.flatnonzero(~ok)
            retry, retry_ok, _ = parse_float(mat[bad, :14])
            v[bad] = np.where(retry_ok, retry, np.nan)
            log.add(part[bad[~retry_ok]], "bad_value")
        flags = mat[:, 14:16] - np.uint8(ord("0"))
        flags[flags > 9] = 0  # a blank indicator is 0 ("OK or not known")
        value[s : s + _CHUNK] = v
        lli[s : s + _CHUNK] = flags[:, 0]
        ssi[s : s + _CHUNK] = flags[:, 1]
    return value, lli, ssi


# --------------------------------------------------------------------------- output


def _time_series(name: str, us: np.ndarray) -> pl.Series:
    return pl.Series(name, us, dtype=pl.Int64).cast(pl.Datetime("us"))


def _table(
    epochs: _Epochs, sat: _Sats, columns: list[str], values: dict[str, tuple[np.ndarray, ...]]
) -> pl.DataFrame:
    code = sat.system.astype(np.int64) * 1000 + sat.prn  # < 91 000: a lookup table, not a sort
    present = np.bincount(code, minlength=1) > 0 if len(code) else np.zeros(1, bool)
    uniq = np.flatnonzero(present)
    lut = np.zeros(len(present), np.int64)
    lut[uniq] = np.arange(len(uniq))
    inverse = lut[code]
    names = pl.Series([f"{chr(u // 1000)}{u % 1000:02d}" for u in uniq.tolist()], dtype=pl.String)
    letters = pl.Series([chr(u // 1000) for u in uniq.tolist()], dtype=pl.String)
    idx = pl.Series(inverse.astype(np.uint32))
    cols: dict[str, pl.Series] = {
        "time": _time_series("time", epochs.time[sat.epoch]),
        "sat": names.gather(idx).rename("sat"),
        "system": letters.gather(idx).rename("system"),
        "prn": pl.Series("prn", sat.prn.astype(np.int16)),
        "flag": pl.Series("flag", epochs.flag[sat.epoch].astype(np.uint8)),
    }
    for c in columns:
        cols[c] = pl.Series(c, values[c][0])
    for c in columns:
        cols[f"{c}_lli"] = pl.Series(f"{c}_lli", values[c][1])
        cols[f"{c}_ssi"] = pl.Series(f"{c}_ssi", values[c][2])
    return pl.DataFrame(list(cols.values()))


def _epochs_frame(epochs: _Epochs) -> pl.DataFrame:
    obs = epochs.flag <= 1
    return pl.DataFrame(
        [
            _time_series("time", epochs.time[obs]),
            pl.Series("flag", epochs.flag[obs].astype(np.uint8)),
            pl.Series("nsat", epochs.count[obs].astype(np.int32)),
            pl.Series("clock", epochs.clock[obs]),
            pl.Series("line", epochs.line[obs] + 1),
        ]
    )


def _events_frame(lines: Lines, epochs: _Epochs, v3: bool) -> pl.DataFrame:
    """Flag 2-5 records with their special lines as text; flag 6 (cycle slips) with their count only."""
    ev = np.flatnonzero(epochs.flag >= 2)
    text = []
    for k in ev.tolist():
        first = int(epochs.line[k] + epochs.n_head[k])
        special = epochs.flag[k] != 6
        text.append(
            "\n".join(lines.text(i) for i in range(first, first + int(epochs.count[k]))) if special else ""
        )
    t = [None if x < 0 else x for x in epochs.time[ev].tolist()]
    return pl.DataFrame(
        [
            pl.Series("line", epochs.line[ev] + 1, dtype=pl.Int64),
            pl.Series("flag", epochs.flag[ev].astype(np.uint8), dtype=pl.UInt8),
            pl.Series("time", t, dtype=pl.Int64).cast(pl.Datetime("us")),
            pl.Series("records", epochs.count[ev].astype(np.int32), dtype=pl.Int32),
            pl.Series("text", text, dtype=pl.String),
        ]
    )


def _report(obs: RinexObs, log: _Log, n_seen: int) -> ReadReport:
    rej = obs.rejected
    first = ""
    if rej.height:
        row = rej.row(0, named=True)
        first = f"{row['line']}: {row['reason']}"
    counts = dict(log.counts)
    invalid = {"bad_value": counts.pop("bad_value")} if "bad_value" in counts else {}
    flags = Counter(obs.epochs["flag"].to_list()) + Counter(obs.events["flag"].to_list())
    h = obs.header
    return ReadReport(
        source=obs.file,
        format=f"rinex-obs {h.version:.2f}",
        rows_read=n_seen + sum(log.counts[r] for r in _RECORD_REASONS),
        rows_kept=obs.table.height,
        rejected=counts,
        invalidated=invalid,
        first_bad=first,
        notes=(
            f"epochs: {obs.epochs.height} with observations, by flag {dict(sorted(flags.items()))}",
            f"systems: {''.join(sorted(set(obs.table['system'].unique().to_list())))}, "
            f"codes: {', '.join(obs.codes)}",
            f"time system: {h.time_system} (table in GPS time)",
        ),
    )
