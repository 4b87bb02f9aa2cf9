"""Reader for SP3 precise orbits and clocks (versions a, b, c, d), and their interpolation.

Format (SP3-c/d)
----------------
A header (``#c``/``#d`` line with the first epoch, the number of epochs, the coordinate system,
orbit type and agency; ``##`` with week, interval and MJD; ``+`` lines with the satellites;
``%c`` with the time system), then per epoch a ``*`` line with the date and one ``P`` line per
satellite: identifier, x, y, z in km and the clock in microseconds (4 x F14.6), optional
standard-deviation exponents and flags (column 75 ``E`` clock event, 76 ``P`` clock predicted,
79 ``M`` manoeuvre, 80 ``P`` orbit predicted). Optional ``V`` lines carry velocities (dm/s) and
clock rates (10^-4 us/s); ``EP``/``EV`` correlation lines are skipped; ``EOF`` ends the file.

Output model
------------
:class:`Sp3` holds dense arrays over (epoch, satellite): ``time`` (GPS time, int64 us since
1970, whatever the file's time system), ``position`` (m), ``clock`` (s), ``velocity`` (m/s) and
``clock_rate`` (s/s) when a file has ``V`` lines, and ``flags`` (bit 0 clock event, 1 clock
predicted, 2 manoeuvre, 3 orbit predicted). Several files (consecutive days) merge into one set
of epochs.

Accounting (issue 13: kept + rejected = read)
---------------------------------------------
The rows of the report are the ``P`` and ``V`` lines (and any body line of no SP3 record type,
rejected as ``unknown_line``). Each is either stored in the arrays (``rows_kept``) or rejected
once, with the first reason that applies: ``no_epoch`` (before the first ``*`` line); the
reason of its epoch line when that is rejected, ``bad_epoch`` (unreadable), ``time_out_of_range``
(outside :data:`overbound.io.gpstime.PLAUSIBLE_SPAN`), ``duplicate_epoch`` or
``epoch_out_of_order``; ``unlisted_satellite``; ``bad_record`` (unreadable x, y or z);
``duplicate`` (satellite repeated in the epoch); ``epoch_in_earlier_file`` (several files: an
epoch present in two files keeps the first file's values). Epoch times must increase through a
file: the epochs kept are the longest strictly increasing run of them, in file order, so an
epoch line whose time was corrupted (02:30 written 00:30) is rejected with its lines and
overwrites nothing, and the epochs after it stay; among equal times the first line is kept.
The report's ``first_bad`` names an epoch's rejection at its ``*`` line, and a note counts the
rejected epoch lines.

A stored line whose value is missing or unusable keeps NaN there and is counted under
``invalidated``: ``missing_position`` (0.000000, as SP3 prescribes), ``non_finite_position``
(``inf``/``nan`` written, or beyond the float range), ``implausible_position`` (a coordinate of
100,000 km or more), ``missing_clock`` (999999.999999 or more, as SP3 prescribes, or blank),
``non_finite_clock``, ``bad_clock`` (unreadable, or running past column 60) and, for ``V``
lines, ``non_finite_velocity``.

Parsing is vectorised over the byte buffer like the RINEX readers (:mod:`overbound.io._rinex`):
all ``P`` lines at once, F14.6 read as integers.

Interpolation
-------------
:func:`interpolate_position` uses a Lagrange polynomial of degree 10 (11 epochs, centred on the
epoch nearest to the time, shifted inward at the ends of the data), the usual choice for
15-minute GNSS orbits and gLAB's default. On ``igs20361.sp3`` it gives back held-out epochs
(every fourth interior epoch removed) to 1 mm median, 7 mm at most, and agrees with gLAB's
interpolation of the same file to about 1 mm; near the first and last epochs, where the window
is one-sided, errors reach about 0.1 m. Clocks are not smooth enough for a polynomial:
:func:`interpolate_clock` is linear between the two epochs around the time (gLAB's default too);
with every other epoch of ``igs20361.sp3`` held out (30-min spacing) it misses them by 1.6 cm
median and 0.42 m at most, so range-domain work should use 30-s clock (CLK) files. Times outside
the data, or whose window holds a missing value, give NaN.
"""

from __future__ import annotations

from bisect import bisect_left
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import polars as pl

from overbound.io._rinex import (
    US,
    Lines,
    civil_to_us,
    load_bytes,
    parse_digits,
    parse_fixed,
    parse_float,
    to_gpst,
)
from overbound.io.gpstime import PLAUSIBLE_SPAN, PLAUSIBLE_YEARS, plausible_us
from overbound.io.open import Source, source_name
from overbound.io.sbas_frames import REJECTED_SCHEMA
from overbound.io.schema import InputError, ReadReport

__all__ = [
    "FLAG_CLOCK_EVENT",
    "FLAG_CLOCK_PREDICTED",
    "FLAG_MANEUVER",
    "FLAG_ORBIT_PREDICTED",
    "Sp3",
    "Sp3Header",
    "interpolate_clock",
    "interpolate_position",
    "read_sp3",
]

_BAD_CLOCK_US = 999_999.0  # SP3: a clock of 999999.999999 us means bad or missing
_MAX_RADIUS_M = 1e8  # no GNSS (or LEO) coordinate reaches 100,000 km (GEO radius: 42,164 km)
FLAG_CLOCK_EVENT, FLAG_CLOCK_PREDICTED, FLAG_MANEUVER, FLAG_ORBIT_PREDICTED = 1, 2, 4, 8
_FLAG_COLUMNS = ((74, "E", FLAG_CLOCK_EVENT), (75, "P", FLAG_CLOCK_PREDICTED), (78, "M", FLAG_MANEUVER),
                 (79, "P", FLAG_ORBIT_PREDICTED))  # fmt: skip
_REASONS_TEXT = {
    "no_epoch": "record before the first epoch line",
    "bad_epoch": "unreadable epoch line",
    "time_out_of_range": f"epoch outside {PLAUSIBLE_SPAN}",
    "duplicate_epoch": "epoch line repeating the time of an earlier one",
    "epoch_out_of_order": "epoch line whose time is not after the epochs before it",
    "unlisted_satellite": "satellite not in the header list",
    "bad_record": "unreadable position/velocity line",
    "duplicate": "satellite repeated in the epoch",
    "unknown_line": "line of no SP3 record type",
    "epoch_in_earlier_file": "epoch already read from an earlier file",
}
#: Rejection reasons, in order of precedence (a line gets the first that applies); code 0 = kept.
_REASONS = ("", "no_epoch", "bad_epoch", "time_out_of_range", "duplicate_epoch", "epoch_out_of_order",
            "unlisted_satellite", "bad_record", "duplicate")  # fmt: skip
_CODE = {r: i for i, r in enumerate(_REASONS)}
_EPOCH_REASONS = ("bad_epoch", "time_out_of_range", "duplicate_epoch", "epoch_out_of_order")
#: Invalidations that are SP3's own way of writing "no value" (not worth a ``first_bad``).
_CONVENTION = ("missing_position", "missing_clock")


@dataclass(frozen=True, slots=True)
class Sp3Header:
    """Header fields of the first file: version letter, ``P``/``V`` flag, coordinate system (e.g.
    ``IGS14``), orbit type (``FIT``, ``HLM``...), agency, time system, epoch interval (s) and the
    number of epochs the header announces (summed over files)."""

    version: str
    pv_flag: str
    coordinate_system: str
    orbit_type: str
    agency: str
    time_system: str
    interval: float
    n_epochs_declared: int


@dataclass(frozen=True, slots=True, eq=False)
class Sp3:
    """Precise orbits and clocks on the SP3 epoch grid (see the module notes)."""

    time: np.ndarray
    sats: tuple[str, ...]
    position: np.ndarray
    clock: np.ndarray
    flags: np.ndarray
    header: Sp3Header
    velocity: np.ndarray | None = None
    clock_rate: np.ndarray | None = None
    rejected: pl.DataFrame = field(default_factory=lambda: pl.DataFrame(schema=REJECTED_SCHEMA))
    files: tuple[str, ...] = ()

    def sat_index(self, sats: Sequence[str] | np.ndarray) -> np.ndarray:
        """Column of each satellite identifier (``"G07"``) in the arrays, -1 if absent."""
        lookup = {s: i for i, s in enumerate(self.sats)}
        return np.array([lookup.get(str(s), -1) for s in np.asarray(sats).ravel()], dtype=np.int64).reshape(
            np.shape(sats)
        )

    def to_frame(self) -> pl.DataFrame:
        """Long table: ``time`` (GPST), ``sat``, ``x``, ``y``, ``z`` (m), ``clock`` (s), ``flags``."""
        n, m = self.clock.shape
        sat = pl.Series("sat", list(self.sats), dtype=pl.String).gather(np.tile(np.arange(m), n))
        return pl.DataFrame(
            [
                pl.Series("time", np.repeat(self.time, m), dtype=pl.Int64).cast(pl.Datetime("us")),
                sat,
                pl.Series("x", self.position[..., 0].ravel()),
                pl.Series("y", self.position[..., 1].ravel()),
                pl.Series("z", self.position[..., 2].ravel()),
                pl.Series("clock", self.clock.ravel()),
                pl.Series("flags", self.flags.ravel()),
            ]
        )


def read_sp3(sources: Source | Sequence[Source], *, strict: bool = False) -> tuple[Sp3, ReadReport]:
    """Read one or several SP3 files (plain or gzip) into one :class:`Sp3`.

    Parameters
    ----------
    sources : a path or stream, or several (e.g. three consecutive days, to interpolate across
        midnight); satellites are the union of the files', epochs the sorted union (an epoch
        present in two files keeps the first file's values, the later file's lines of it are
        rejected as ``epoch_in_earlier_file``).
    strict : raise :class:`InputError` at the first rejected line or epoch line (lines of an
        epoch already read from an earlier file are not an error).

    Returns
    -------
    sp3, report : ``rows_read`` = ``P`` and ``V`` lines (and unrecognised body lines),
        ``rows_kept`` = those stored in the arrays, ``rejected`` = the others by reason (see the
        module notes), ``invalidated`` = stored lines with a missing or unusable value.

    Raises
    ------
    InputError
        Not an SP3 file, unknown version, a truncated compressed stream, no usable epoch at all,
        or (``strict``) a malformed line.
    """
    many = isinstance(sources, Sequence) and not isinstance(sources, str | bytes)
    items = list(sources) if many else [sources]  # type: ignore[list-item]
    parts = [_read_one(s, strict) for s in items]
    sp3, kept = _merge(parts, tuple(source_name(s) for s in items))
    return sp3, _report(sp3, parts, kept)


def _read_one(source: Source, strict: bool) -> dict:
    name = source_name(source)
    lines = Lines.of(load_bytes(source))
    header, sats, body = _parse_header(lines, name)
    rows = np.arange(1, len(lines), dtype=np.int64)  # P and V lines in the header are counted too
    c0 = lines.col(rows, 0)
    c1 = lines.col(rows, 1)
    epoch_lines = rows[c0 == ord("*")]
    pos_lines = rows[c0 == ord("P")]
    vel_lines = rows[c0 == ord("V")]  # "EV" correlation records start with E
    other = ~np.isin(c0, np.frombuffer(b"*PVE", np.uint8)) & (lines.length[rows] > 0) & (rows >= body)
    other &= ~((c0 == ord("/")) & (c1 == ord("*")))  # comments
    starts_e = rows[(c0 == ord("E")) & (rows >= body)]
    e_known = np.zeros(len(starts_e), bool)
    for tag in (b"EOF", b"EP", b"EV"):
        e_known |= (lines.chars(starts_e, 0, len(tag)) == np.frombuffer(tag, np.uint8)).all(axis=1)
    unknown = np.sort(np.concatenate([rows[other], starts_e[~e_known]]))
    t, epoch_reason = _epoch_status(lines, epoch_lines, header.time_system, name)
    good = epoch_reason == 0
    if strict and not good.all():
        i = int(np.flatnonzero(~good)[0])
        raise InputError(name, _REASONS_TEXT[_REASONS[epoch_reason[i]]], line=int(epoch_lines[i]) + 1)
    if not good.any():
        raise InputError(name, "no usable epoch ('*' line) in the SP3 file")
    accepted = np.cumsum(good) - 1  # index among the accepted epochs of each epoch line
    n, m = int(good.sum()), len(sats)
    out = {
        "name": name,
        "header": header,
        "sats": sats,
        "time": t[good],
        "position": np.full((n, m, 3), np.nan),
        "clock": np.full((n, m), np.nan),
        "flags": np.zeros((n, m), np.uint8),
        "velocity": np.full((n, m, 3), np.nan) if len(vel_lines) else None,
        "clock_rate": np.full((n, m), np.nan) if len(vel_lines) else None,
        "n_read": len(pos_lines) + len(vel_lines) + len(unknown),
        "epoch_lines": epoch_lines,
        "epoch_rejected": Counter(_REASONS[r] for r in epoch_reason[~good].tolist()),
    }
    rej = [(int(i), "unknown_line") for i in unknown]
    kept_line, kept_ep, inv_line, inv_ep, inv_reason = [], [], [], [], []
    lookup = {s: i for i, s in enumerate(sats)}
    for kind, recs in (("P", pos_lines), ("V", vel_lines)):
        if not len(recs):
            continue
        scales = (3, -6) if kind == "P" else (-1, -10)  # km, us; dm/s, 1e-4 us/s
        reason, ep, col, values, clk, flags = _records(lines, recs, epoch_lines, epoch_reason, lookup, scales)
        bad = reason > 0
        rej += [(int(i), _REASONS[r]) for i, r in zip(recs[bad].tolist(), reason[bad].tolist(), strict=True)]
        keep = ~bad
        ep, col, values, clk, flags = accepted[ep[keep]], col[keep], values[keep], clk[keep], flags[keep]
        store = _store_positions if kind == "P" else _store_velocities
        for what, mask in store(out, ep, col, values, clk, flags).items():
            inv_line.append(recs[keep][mask])
            inv_ep.append(ep[mask])
            inv_reason += [what] * int(mask.sum())
        kept_line.append(recs[keep])
        kept_ep.append(ep)
    rej.sort()
    if strict and rej:
        raise InputError(name, _REASONS_TEXT[rej[0][1]], line=rej[0][0] + 1)
    empty = np.zeros(0, np.int64)
    out["rejected"] = rej
    out["kept_line"] = np.concatenate([empty, *kept_line])
    out["kept_ep"] = np.concatenate([empty, *kept_ep])
    out["inv_line"] = np.concatenate([empty, *inv_line])
    out["inv_ep"] = np.concatenate([empty, *inv_ep])
    out["inv_reason"] = np.array(inv_reason, dtype=object)
    return out


def _records(
    lines: Lines,
    recs: np.ndarray,
    epoch_lines: np.ndarray,
    epoch_reason: np.ndarray,
    lookup: dict[str, int],
    scales: tuple,
):
    """Of ``P`` or ``V`` lines: the rejection reason (code into :data:`_REASONS`, 0 = kept), epoch
    line index, satellite column, the four numbers (x, y, z, clock; scaled to SI by
    ``10**scales``; NaN where blank or unreadable), the state of the clock field (0 read, 1 blank,
    2 unreadable) and the flags."""
    ep = np.searchsorted(epoch_lines, recs, side="right") - 1
    reason = np.where(ep >= 0, epoch_reason[np.maximum(ep, 0)], _CODE["no_epoch"]).astype(np.int8)
    ident = lines.chars(recs, 1, 3)
    ident[ident[:, 1] == ord(" "), 1] = ord("0")  # "G 1" -> "G01"
    ident[ident[:, 0] == ord(" "), 0] = ord("G")  # SP3-a: a blank system is GPS
    ids = np.ascontiguousarray(ident).view("S3").ravel()
    uniq, inv = np.unique(ids, return_inverse=True)
    code = np.array([lookup.get(u.decode("ascii", "replace"), -1) for u in uniq.tolist()], np.int64)
    col = code[inv] if len(uniq) else np.zeros(0, np.int64)
    reason[(reason == 0) & (col < 0)] = _CODE["unlisted_satellite"]
    pos_scale, clk_scale = scales
    n = len(recs)
    xyz, xyz_ok, xyz_blank = _numbers(
        lines.chars(np.repeat(recs, 3), np.tile(4 + 14 * np.arange(3), n), 14), pos_scale
    )
    clk, clk_ok, clk_blank = _numbers(lines.chars(recs, 46, 14), clk_scale)
    values = np.column_stack([xyz.reshape(n, 3), clk])
    reason[(reason == 0) & ~(xyz_ok & ~xyz_blank).reshape(n, 3).all(axis=1)] = _CODE["bad_record"]
    flags = np.zeros(n, np.uint8)
    for c, letter, bit in _FLAG_COLUMNS:
        flags |= np.where(lines.col(recs, c) == ord(letter), bit, 0).astype(np.uint8)
    cand = np.flatnonzero(reason == 0)
    reason[cand[_repeats(ep[cand], col[cand])]] = _CODE["duplicate"]
    clk_ok &= lines.col(recs, 60) == ord(" ")  # a longer field is no F14.6 (column 61 is blank)
    clk_state = np.where(clk_blank & clk_ok, 1, np.where(clk_ok, 0, 2)).astype(np.int8)
    return reason, ep, col, values, clk_state, flags


def _numbers(mat: np.ndarray, scale: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """F14.6 fields times ``10**scale`` (exactly rounded); other layouts read generically."""
    values, ok, blank = parse_fixed(mat, 6, scale=scale)
    if not ok.all():
        redo = np.flatnonzero(~ok)
        redo = redo[((mat[redo] >= 32) & (mat[redo] <= 126)).all(axis=1)]  # numpy drops a trailing NUL
        retry, retry_ok, _ = parse_float(mat[redo])
        with np.errstate(over="ignore"):  # 1e308 km is inf m: a non-finite value, counted as such
            values[redo] = np.where(retry_ok, retry * 10.0**scale, np.nan)
        ok[redo] = retry_ok
    return values, ok, blank


def _repeats(ep: np.ndarray, col: np.ndarray) -> np.ndarray:
    """Which (epoch, column) pairs repeat an earlier one (in the given order)."""
    key = ep * 4096 + col
    order = np.argsort(key, kind="stable")
    dup = np.zeros(len(key), bool)
    dup[order[1:][np.diff(key[order]) == 0]] = True
    return dup


def _store_positions(
    out: dict, ep: np.ndarray, col: np.ndarray, values: np.ndarray, clk_state: np.ndarray, flags: np.ndarray
) -> dict[str, np.ndarray]:
    """Positions (m) and clocks (s) into the arrays, NaN where missing or unusable; the lines of
    each invalidation reason (masks over the lines)."""
    xyz = values[:, :3].copy()
    missing_pos = (xyz == 0).all(axis=1)
    non_finite_pos = ~np.isfinite(xyz).all(axis=1)
    implausible_pos = ~non_finite_pos & (np.abs(np.nan_to_num(xyz)) >= _MAX_RADIUS_M).any(axis=1)
    xyz[missing_pos | non_finite_pos | implausible_pos] = np.nan
    clk = values[:, 3]
    read = clk_state == 0
    non_finite_clk = read & ~np.isfinite(clk)
    missing_clk = (clk_state == 1) | (read & np.isfinite(clk) & ~(np.abs(clk) < _BAD_CLOCK_US * 1e-6))
    usable = read & ~non_finite_clk & ~missing_clk
    out["position"][ep, col] = xyz
    out["clock"][ep, col] = np.where(usable, clk, np.nan)
    out["flags"][ep, col] = flags
    return {
        "missing_position": missing_pos,
        "non_finite_position": non_finite_pos,
        "implausible_position": implausible_pos,
        "missing_clock": missing_clk,
        "non_finite_clock": non_finite_clk,
        "bad_clock": clk_state == 2,
    }


def _store_velocities(
    out: dict, ep: np.ndarray, col: np.ndarray, values: np.ndarray, clk_state: np.ndarray, flags: np.ndarray
) -> dict[str, np.ndarray]:
    """Velocities (m/s) and clock rates (s/s) into the arrays, NaN where missing or unusable."""
    vel = values[:, :3].copy()
    non_finite = ~np.isfinite(vel).all(axis=1)
    vel[non_finite] = np.nan
    rate = values[:, 3]
    read = clk_state == 0
    non_finite_rate = read & ~np.isfinite(rate)
    out["velocity"][ep, col] = vel
    out["clock_rate"][ep, col] = np.where(read & (np.abs(rate) < _BAD_CLOCK_US * 1e-10), rate, np.nan)
    return {"non_finite_velocity": non_finite | non_finite_rate, "bad_clock": clk_state == 2}


def _epoch_status(
    lines: Lines, rows: np.ndarray, time_system: str, name: str
) -> tuple[np.ndarray, np.ndarray]:
    """Of the ``*  yyyy mm dd hh mm ss.ssssssss`` lines: GPS microseconds, and the rejection reason
    (code into :data:`_REASONS`, 0 = accepted): unreadable, outside the plausible span, or not
    after the epochs kept before it (:func:`_increasing`)."""
    year, y_ok, _ = _digits(lines.chars(rows, 3, 4))
    parts = [_digits(lines.chars(rows, c, 2)) for c in (8, 11, 14, 17)]
    sec, s_ok, s_blank = parse_fixed(lines.chars(rows, 20, 11), 8)
    us = np.round(np.nan_to_num(sec) * US).astype(np.int64)
    # the date's validity with the year brought into civil_to_us's range, the span checked apart
    t, ok = civil_to_us(np.clip(year, 1980, 2199), *(p[0] for p in parts), us)
    ok &= y_ok & s_ok & ~s_blank & np.logical_and.reduce([p[1] for p in parts])
    t, _ = civil_to_us(year, *(p[0] for p in parts), us)
    t = to_gpst(t, time_system, name)
    reason = np.where(ok, 0, _CODE["bad_epoch"]).astype(np.int8)
    reason[ok & ~(np.isin(year, PLAUSIBLE_YEARS) & plausible_us(t))] = _CODE["time_out_of_range"]
    cand = np.flatnonzero(reason == 0)
    inc = _increasing(t[cand])
    late = cand[~inc]
    reason[late] = np.where(
        np.isin(t[late], t[cand[inc]]), _CODE["duplicate_epoch"], _CODE["epoch_out_of_order"]
    )
    return t, reason


def _digits(mat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`~overbound.io._rinex.parse_digits` of a date field, where a blank is no value (not 0)."""
    value, ok, blank = parse_digits(mat)
    return value, ok & ~blank, blank


def _increasing(t: np.ndarray) -> np.ndarray:
    """The longest strictly increasing subsequence of ``t`` (mask), preferring earlier elements among
    equal times: an epoch line moved or repeated is the one left out, not the epochs after it."""
    if np.all(np.diff(t) > 0):
        return np.ones(len(t), bool)
    tails: list[int] = []  # tails[k]: the smallest last time of an increasing run of length k + 1
    ends: list[int] = []  # its element
    prev = np.full(len(t), -1, np.int64)
    for i, x in enumerate(t.tolist()):
        k = bisect_left(tails, x)
        if k < len(tails) and tails[k] == x:
            continue  # an equal time already ends a run of this length: keep the earlier line
        prev[i] = ends[k - 1] if k else -1
        if k == len(tails):
            tails.append(x)
            ends.append(i)
        else:
            tails[k], ends[k] = x, i
    keep = np.zeros(len(t), bool)
    i = ends[-1] if ends else -1
    while i >= 0:
        keep[i] = True
        i = int(prev[i])
    return keep


def _parse_header(lines: Lines, name: str) -> tuple[Sp3Header, tuple[str, ...], int]:
    """Header fields, satellite list and the first line after the header."""
    first = lines.text(0) if len(lines) else ""
    if not first.startswith("#") or len(first) < 3:
        raise InputError(name, f"not an SP3 file: first line {first[:40]!r} does not start with '#a'-'#d'")
    version = first[1]
    if version not in "abcd":
        raise InputError(name, f"SP3 version {version!r} not supported (a, b, c, d)", line=1)
    sats: list[str] = []
    n_sats, interval, time_system, body, seen_pc = 0, 0.0, "GPS", None, False
    for i in range(1, min(len(lines), 2000)):
        text = lines.text(i)
        if text.startswith("*"):
            body = i
            break
        if text.startswith("##"):
            interval = _float(text[24:38], name, i)
        elif text.startswith("+ "):
            if not sats and not n_sats:
                n_sats = _count(text[1:6], name, i)
            sats.extend(text[9 + 3 * k : 12 + 3 * k].replace(" ", "0") for k in range(17))
        elif text.startswith("%c") and not seen_pc:  # the first %c line holds the time system
            time_system, seen_pc = text[9:12].strip() or "GPS", True
    if body is None:
        raise InputError(name, "no epoch line ('*'): truncated header or not an SP3 file")
    sats = [s if s[0] != "0" else "G" + s[1:] for s in sats[:n_sats]]  # SP3-a: blank system means GPS
    if version == "a":
        time_system = "GPS"
    to_gpst(np.zeros(0, np.int64), time_system, name)
    header = Sp3Header(
        version=version,
        pv_flag=first[2],
        coordinate_system=first[46:51].strip(),
        orbit_type=first[52:55].strip(),
        agency=first[56:60].strip(),
        time_system=time_system,
        interval=interval,
        n_epochs_declared=_count(first[32:39], name, 0),
    )
    return header, tuple(sats), body


def _float(text: str, name: str, i: int) -> float:
    try:
        return float(text)
    except ValueError:
        raise InputError(name, f"expected a number, got {text.strip()!r}", line=i + 1) from None


def _count(text: str, name: str, i: int) -> int:
    try:
        return int(text)
    except ValueError:
        raise InputError(name, f"expected an integer, got {text.strip()!r}", line=i + 1) from None


def _merge(parts: list[dict], files: tuple[str, ...]) -> tuple[Sp3, list[np.ndarray]]:
    """One epoch grid and satellite list for several files; the first file wins on shared epochs,
    the lines of a later file for them are rejected (``epoch_in_earlier_file``). Also which
    accepted epochs of each part are stored."""
    sats = sorted({s for p in parts for s in p["sats"]}, key=lambda s: (s[0], s))
    times = np.unique(np.concatenate([p["time"] for p in parts]))
    n, m = len(times), len(sats)
    col = {s: i for i, s in enumerate(sats)}
    has_v = any(p["velocity"] is not None for p in parts)
    out = {
        "position": np.full((n, m, 3), np.nan),
        "clock": np.full((n, m), np.nan),
        "flags": np.zeros((n, m), np.uint8),
        "velocity": np.full((n, m, 3), np.nan) if has_v else None,
        "clock_rate": np.full((n, m), np.nan) if has_v else None,
    }
    filled = np.zeros(n, bool)
    stored, frames = [], []  # per part: its epochs stored (not in an earlier file), its rejections
    for p, name in zip(parts, files, strict=True):
        rows = np.searchsorted(times, p["time"])
        new = ~filled[rows]
        cols = np.array([col[s] for s in p["sats"]], np.int64)
        for key, arr in out.items():
            if arr is not None and p[key] is not None:
                arr[np.ix_(rows[new], cols)] = p[key][new]
        filled[rows] = True
        keep = new[p["kept_ep"]]
        stored.append(new)
        rej = sorted(p["rejected"] + [(int(i), "epoch_in_earlier_file") for i in p["kept_line"][~keep]])
        frames.append(
            pl.DataFrame(
                {"file": [name] * len(rej), "line": [i + 1 for i, _ in rej], "reason": [r for _, r in rej]},
                schema=REJECTED_SCHEMA,
            )
        )
    h0 = parts[0]["header"]
    header = Sp3Header(
        h0.version, h0.pv_flag, h0.coordinate_system, h0.orbit_type, h0.agency, h0.time_system,
        h0.interval, sum(p["header"].n_epochs_declared for p in parts),
    )  # fmt: skip
    rejected = pl.concat(frames, how="vertical")
    return Sp3(times, tuple(sats), rejected=rejected, files=files, header=header, **out), stored


def _report(sp3: Sp3, parts: list[dict], stored: list[np.ndarray]) -> ReadReport:
    invalid: Counter = Counter()
    first = ""
    frames = sp3.rejected.partition_by("file", maintain_order=True, as_dict=True)
    for p, new, name in zip(parts, stored, sp3.files, strict=True):
        inv = new[p["inv_ep"]]
        invalid.update(p["inv_reason"][inv].tolist())
        bad = [(int(i), r) for i, r in zip(p["inv_line"][inv].tolist(), p["inv_reason"][inv].tolist(),
                                            strict=True) if r not in _CONVENTION]  # fmt: skip
        rej = frames.get((name,))
        if rej is not None:  # an epoch's rejection is named at its epoch line
            line, reason = int(rej["line"][0]) - 1, rej["reason"][0]
            if reason in _EPOCH_REASONS:
                line = int(p["epoch_lines"][np.searchsorted(p["epoch_lines"], line) - 1])
            bad.append((line, reason))
        if bad and not first:
            line, reason = min(bad)
            first = f"{name}:{line + 1}: {reason}"
    epoch_rejected = sum((p["epoch_rejected"] for p in parts), Counter())
    h = sp3.header
    notes = [
        f"{len(sp3.time)} epochs (header: {h.n_epochs_declared}), {len(sp3.sats)} satellites, "
        f"interval {h.interval:g} s, {h.coordinate_system} {h.orbit_type} {h.agency}",
        f"time system {h.time_system} (times given in GPS time)",
    ]
    if epoch_rejected:
        notes.append(f"epoch lines rejected (with their lines): {dict(sorted(epoch_rejected.items()))}")
    return ReadReport(
        source=", ".join(sp3.files),
        format=f"sp3-{h.version}",
        rows_read=sum(p["n_read"] for p in parts),
        rows_kept=sum(int(new[p["kept_ep"]].sum()) for p, new in zip(parts, stored, strict=True)),
        rejected=dict(Counter(sp3.rejected["reason"].to_list())),
        invalidated=dict(sorted(invalid.items())),
        first_bad=first,
        notes=tuple(notes),
    )


# --------------------------------------------------------------------------- interpolation


def interpolate_position(
    sp3: Sp3,
    sat: np.ndarray,
    time_us: np.ndarray,
    offset_s: np.ndarray | float = 0.0,
    *,
    degree: int = 10,
) -> np.ndarray:
    """Satellite positions (m, ECEF of the SP3 frame) at GPS times ``time_us + offset_s``, (..., 3).

    Lagrange interpolation of degree ``degree`` on the ``degree + 1`` epochs centred on the epoch
    nearest to the time (shifted inward near the ends of the data), computed per query in a
    normalised time variable, vectorised over queries. NaN outside the data span or when a
    window epoch lacks the satellite.

    Parameters
    ----------
    sat : column indices into ``sp3.sats`` (see :meth:`Sp3.sat_index`) or identifiers (``"G07"``).
    time_us : int64 GPS microseconds, broadcast with ``sat`` and ``offset_s``.

    Raises
    ------
    InputError
        Fewer than ``degree + 1`` epochs (a truncated SP3 file), naming the SP3 file(s).
    """
    col, t, off = _queries(sp3, sat, time_us, offset_s)
    n_nodes = degree + 1
    if len(sp3.time) < n_nodes:
        raise InputError(
            ", ".join(sp3.files) or "<sp3>",
            f"{len(sp3.time)} SP3 epochs, too few to interpolate orbits: degree {degree} needs {n_nodes}",
        )
    window, u, nodes, inside = _window(sp3.time, t, off, n_nodes)
    weights = _lagrange_weights(u, nodes)
    values = sp3.position[window, np.maximum(col, 0)[:, None]]  # (q, n_nodes, 3)
    out = np.einsum("qk,qkc->qc", weights, values)
    out[~inside | (col < 0)] = np.nan
    return out.reshape(*np.shape(t), 3) if np.ndim(t) else out[0]


def interpolate_clock(
    sp3: Sp3, sat: np.ndarray, time_us: np.ndarray, offset_s: np.ndarray | float = 0.0
) -> np.ndarray:
    """Satellite clock offsets (s) at GPS times ``time_us + offset_s``, linear between epochs."""
    col, t, off = _queries(sp3, sat, time_us, offset_s)
    if len(sp3.time) < 2:
        return np.full(np.shape(t), np.nan)
    tq = t.ravel()
    # the interval holding the query time itself (time + offset), not just its whole part
    tf = tq + np.floor(off.ravel() * US).astype(np.int64)
    i = np.clip(np.searchsorted(sp3.time, tf, side="right") - 1, 0, len(sp3.time) - 2)
    t0, t1 = sp3.time[i], sp3.time[i + 1]
    frac = ((tq - t0) / US + off.ravel()) / ((t1 - t0) / US)
    c = np.maximum(col.ravel(), 0)
    out = sp3.clock[i, c] + frac * (sp3.clock[i + 1, c] - sp3.clock[i, c])
    outside = (frac < 0) | (frac > 1) | (col.ravel() < 0)
    out[outside] = np.nan
    return out.reshape(np.shape(t))


def _queries(sp3: Sp3, sat, time_us, offset_s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    sat = np.asarray(sat)
    col = sp3.sat_index(sat) if sat.dtype.kind in "USO" else sat.astype(np.int64)
    col, t, off = np.broadcast_arrays(col, np.asarray(time_us, np.int64), np.asarray(offset_s, float))
    return col.ravel(), t, off.ravel()


def _window(
    grid: np.ndarray, t: np.ndarray, off: np.ndarray, n_nodes: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Window epochs (q, n_nodes), normalised query time and node times, and which queries are inside."""
    tq = t.ravel()
    exact = tq + np.round(off).astype(np.int64) * US  # nearest epoch by the whole-second time
    right = np.clip(np.searchsorted(grid, exact), 1, len(grid) - 1)
    nearest = np.where(exact - grid[right - 1] <= grid[right] - exact, right - 1, right)
    start = np.clip(nearest - n_nodes // 2, 0, len(grid) - n_nodes)
    window = start[:, None] + np.arange(n_nodes)
    scale = (grid[-1] - grid[0]) / max(len(grid) - 1, 1) / US  # typical interval, s
    ref = grid[nearest]
    u = ((tq - ref) / US + off) / scale
    nodes = (grid[window] - ref[:, None]) / US / scale
    seconds = (tq - grid[0]) / US + off
    inside = (seconds >= 0) & (seconds <= (grid[-1] - grid[0]) / US)
    return window, u, nodes, inside


def _lagrange_weights(u: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """Lagrange basis polynomials l_j(u) = prod_{k != j} (u - x_k) / (x_j - x_k), (q, n_nodes)."""
    n = nodes.shape[1]
    diff = u[:, None] - nodes  # (q, n)
    denom = nodes[:, :, None] - nodes[:, None, :]  # (q, n, n)
    eye = np.eye(n, dtype=bool)
    denom[:, eye] = 1.0
    numer = np.broadcast_to(diff[:, None, :], denom.shape).copy()
    numer[:, eye] = 1.0
    return np.prod(numer / denom, axis=2)
