"""Reader for RINEX-B files (RINEX 2.10/2.11 "GEO SBAS broadcast data"): raw SBAS messages.

A RINEX-B file starts with a header (first line ``RINEX VERSION / TYPE`` with type ``B`` in
column 21, last line ``END OF HEADER``), then holds one record per received message: a record
line, then the message bytes in hex over continuation lines, 18 bytes a line::

    123 19 01 14 02 59 59.1  L1    32     0   SBA
      4    C6 11 00 24 00 00 14 00 3F E8 00 00 00 00 00 00 00 00
           00 00 00 01 B9 B9 7B 80 00 00 26 69 A9 80

The record line is the GEO (``123``, or ``S23`` = S + PRN - 100, or ``S123``, which shifts the
rest of the line one column right), the epoch (two-digit year, read as 20YY below 80 as for EMS,
month, day, hour, minute, seconds F5.1), then, optional, the band and frequency (``L1``), the
number of message bytes (I3, 32 = the 250 bits and 6 zero pad bits; a larger count carries
receiver bytes after them, which are ignored), the receiver index and the source (``SBA``). The
first data line holds the message type in columns 1-6; every data line holds up to 18 bytes
as `` XX`` from column 7 on. Headers repeated inside a file (files joined with ``cat``) are
skipped. Input may be plain or gzip; lines end in LF or CRLF.

Time tag
--------
The RINEX-B epoch is the transmission time of the message's first bit (GPS time), i.e. the
*start* of the one-second slot, a whole GPS second (DO-229D A.4.3: messages last 1 s and every
other preamble starts on a 6-s GPS subframe epoch); writers may add the signal flight time
(gLAB writes the EMS tag - 1 s + 0.12 s as ``59.1``, receivers the reception time). EMS tags
the *end* of the slot (:mod:`overbound.io.ems`). So that the same message gets the same
``time`` from either file, the reader keeps the whole seconds of the epoch (the fraction, the
flight time, is dropped, as gLAB's own RINEX-B reader does) and adds 1 s: EMS
``123 19 01 14 03 00 00 4 C611...`` and gLAB's RINEX-B ``123 19 01 14 02 59 59.1`` both give
2019-01-14 03:00:00. ``tests/io/test_rinex_b.py`` checks this on every message of a real gLAB
conversion.

Parsing is vectorised as in :mod:`overbound.io.ems` (whose line splitting, duplicate handling and
report it reuses): every line is classified (header, record, data) by a few columns, records and
data lines are checked column by column at once, the hex pairs of all data lines are decoded by
one table look-up. gLAB's conversion of the 24 EMS hours of a day (73,335 records, 220,000
lines, 11 MB) reads in about 0.2 s.

Rejections are counted per record with file and line (``frames.rejected``): ``layout`` (record
or data line out of the layout, e.g. cut short, or a data line with no record), ``bad_hex``
(a byte that is not two hex digits; the data line is named), ``byte_count`` (the data lines do
not hold the declared number of bytes, at least 32: a truncated record), ``bad_time``,
``time_out_of_range`` (an epoch outside :data:`~overbound.io.gpstime.PLAUSIBLE_SPAN`),
``not_sbas_prn``, ``not_l1`` (band/frequency other than L1, e.g. DFMC L5), ``type_mismatch`` and
``duplicate`` as for EMS. A wrong CRC keeps the message with ``crc_ok`` False.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from overbound.io.ems import _HEX, _frames_in_time_order, _gather, _join, _Lines, _report
from overbound.io.gpstime import PLAUSIBLE_SPAN, plausible_us
from overbound.io.open import Source, read_bytes, source_name
from overbound.io.sbas_bits import FRAME_BYTES, message_type
from overbound.io.sbas_crc import crc_ok
from overbound.io.sbas_frames import SbasFrames
from overbound.io.schema import InputError, ReadReport

__all__ = ["RINEX_B_LAYOUT", "read_rinex_b"]

RINEX_B_LAYOUT = "PRN YY MM DD hh mm ss.s [L1 nbytes ...], then the bytes as ' XX' from column 8, 18 a line"
#: Rejection reasons, by code (0: the record is kept).
_REASONS = (
    "", "layout", "bad_hex", "byte_count", "bad_time", "not_sbas_prn", "not_l1", "type_mismatch",
    "time_out_of_range",
)  # fmt: skip
_R = {r: i for i, r in enumerate(_REASONS)}
_SBAS_PRN = (120, 158)
_US = 1_000_000
_PER_LINE = 18  # bytes on a data line
_FIRST_HEX = 7  # column of the first hex digit on a data line
_REC_WIDTH = 33  # record line columns read (up to the byte count)
_VERSION = np.frombuffer(b"RINEX VERSION / TYPE", np.uint8)
_END = np.frombuffer(b"END OF HEADER", np.uint8)
_BLANK, _DOT = ord(" "), ord(".")


def read_rinex_b(
    sources: Source | Sequence[Source], *, strict: bool = False
) -> tuple[SbasFrames, ReadReport]:
    """Read one or several RINEX-B files (plain or gzip) into time-ordered :class:`SbasFrames`.

    Parameters
    ----------
    sources : a path or stream, or a sequence of them (any order: messages are sorted by time,
        stably).
    strict : raise :class:`InputError` at the first malformed record instead of counting it.

    Returns
    -------
    frames : every readable message, bad CRC included (``crc_ok`` False); ``time`` is the EMS
        time tag of the message (epoch whole seconds + 1 s, see the module notes), ``line`` the
        line of its record line.
    report : ``rows_read`` = records (and stray data lines), ``rows_kept`` = messages,
        ``rejected`` = unreadable records by reason, ``invalidated`` = {"bad_crc": n};
        ``first_bad`` names file and line of the first rejection. The full list is
        ``frames.rejected`` (``file``, ``line``, ``reason``).

    Raises
    ------
    InputError
        A file does not exist, is not RINEX-B (no ``RINEX VERSION / TYPE`` line of type B first),
        is not version 2, has no ``END OF HEADER``, or (``strict``) has a malformed record.
    """
    many = isinstance(sources, Sequence) and not isinstance(sources, str | bytes)
    items = list(sources) if many else [sources]  # type: ignore[list-item]
    names = tuple(source_name(s) for s in items)
    buf, file_start = _join([read_bytes(s) for s in items])
    lines = _Lines.of(buf, file_start)
    header = _header_lines(names, lines)
    rec = ~header & _record_like(lines.mat)
    owner, stray = _owners(lines, header, rec)
    recs = _Records.parse(buf, lines, np.flatnonzero(rec))
    dat = _DataLines.parse(lines, np.flatnonzero(~header & ~rec & ~stray), owner)
    data, field_mt, reason, bad_at = _assemble(recs, dat)
    good_crc = crc_ok(data)
    mismatch = (reason == 0) & good_crc & (field_mt != message_type(data))
    reason[mismatch] = _R["type_mismatch"]

    rej_lines = np.concatenate([bad_at[reason != 0], np.flatnonzero(stray)])
    rej_reason = np.concatenate([reason[reason != 0], np.full(int(stray.sum()), _R["layout"], np.uint8)])
    order = np.argsort(rej_lines, kind="stable")
    rej_lines, rej_reason = rej_lines[order], rej_reason[order]
    if strict and rej_lines.size:
        i = int(rej_lines[0])
        raise InputError(names[lines.file[i]], _explain(_REASONS[rej_reason[0]]), line=int(lines.lineno[i]))
    keep = reason == 0
    kept_line = recs.line_index[keep]
    fields = {"time": recs.time[keep], "prn": recs.prn[keep], "data": data[keep], "crc_ok": good_crc[keep]}
    rejected = (lines.file[rej_lines], lines.lineno[rej_lines], np.asarray(_REASONS)[rej_reason])
    kept_file, kept_lineno = lines.file[kept_line], lines.lineno[kept_line]
    frames = _frames_in_time_order(fields, kept_file, kept_lineno, names, rejected, strict)
    report = _report(items, frames)
    source = report.source if len(items) <= 3 else f"{len(items)} RINEX-B files"
    return frames, dataclasses.replace(report, format="rinex-b", source=source)


# --------------------------------------------------------------------------- line classes


def _header_lines(names: tuple[str, ...], lines: _Lines) -> np.ndarray:
    """Lines from a ``RINEX VERSION / TYPE`` line to the next ``END OF HEADER``; each file checked."""
    mat, n = lines.mat, len(lines.start)
    ver = (mat[:, 60:80] == _VERSION).all(axis=1)
    end = (mat[:, 60:73] == _END).all(axis=1)
    idx = np.arange(n)
    last_ver = np.maximum.accumulate(np.where(ver, idx, -1)) if n else idx
    last_end = np.maximum.accumulate(np.where(end, idx, -1)) if n else idx
    end_before = np.concatenate([[-1], last_end[:-1]]) if n else idx
    for f, name in enumerate(names):
        mine = np.flatnonzero(lines.file == f)
        if not mine.size:
            continue  # an empty file holds no message
        first = int(mine[0])
        if not ver[first]:
            head = bytes(mat[first, : min(int(lines.length[first]), 60)]).decode("ascii", "replace")
            raise InputError(
                name, f"not a RINEX-B file: expected a RINEX VERSION / TYPE line, got {head!r}",
                line=int(lines.lineno[first]),
            )  # fmt: skip
        for i in mine[ver[mine]].tolist():
            _check_version(name, mat[i], int(lines.lineno[i]))
        if last_end[mine[-1]] < last_ver[mine[-1]]:
            i = int(last_ver[mine[-1]])
            raise InputError(name, "RINEX-B header without END OF HEADER", line=int(lines.lineno[i]))
    return last_ver > end_before


def _check_version(name: str, row: np.ndarray, line: int) -> None:
    text = bytes(row[:20]).decode("ascii", "replace")
    kind = chr(row[20])
    try:
        version = float(text[:9])
    except ValueError:
        raise InputError(name, f"unreadable RINEX version {text[:9].strip()!r}", line=line) from None
    if kind != "B":
        raise InputError(name, f"a RINEX file of type {kind!r}, not B (GEO SBAS broadcast data)", line=line)
    if int(version) != 2:
        raise InputError(name, f"RINEX-B version {version:.2f} not supported (2.10, 2.11 are)", line=line)


def _record_like(mat: np.ndarray) -> np.ndarray:
    """Record lines: they start in column 1 (data lines start blank) or have the epoch's decimal point."""
    return (mat[:, 0] != _BLANK) | (mat[:, 21] == _DOT) | (mat[:, 22] == _DOT)


def _owners(lines: _Lines, header: np.ndarray, rec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Record index owning each line (-1: none), and the data lines that follow no record (stray)."""
    n = len(lines.start)
    new_file = np.ones(n, bool)
    new_file[1:] = lines.file[1:] != lines.file[:-1]
    starts = rec | header | new_file  # a data line belongs to the record above it, if nothing else is between
    seg = np.cumsum(starts) - 1
    head = np.flatnonzero(starts)[seg] if n else seg
    rec_no = np.cumsum(rec) - 1
    owner = np.where(rec[head], rec_no[head], -1) if n else seg
    stray = ~header & ~rec & (owner < 0)
    return owner, stray


# --------------------------------------------------------------------------- records


def _digit(c: np.ndarray) -> np.ndarray:
    return (c >= ord("0")) & (c <= ord("9"))


def _int(mat: np.ndarray, cols: range | tuple[int, ...]) -> np.ndarray:
    """Integer of the digits in the columns, blanks skipped (the layout is checked by the caller)."""
    out = np.zeros(len(mat), dtype=np.int64)
    for c in cols:
        out = np.where(_digit(mat[:, c]), 10 * out + (mat[:, c].astype(np.int64) - ord("0")), out)
    return out


def _i_field(mat: np.ndarray, cols: range) -> np.ndarray:
    """Whether columns hold an I-format integer: leading blanks, then digits, the last one a digit."""
    ok = _digit(mat[:, cols[-1]])
    seen = np.zeros(len(mat), bool)
    for c in cols:
        d = _digit(mat[:, c])
        ok &= d | (~seen & (mat[:, c] == _BLANK))
        seen |= d
    return ok


@dataclasses.dataclass(frozen=True, slots=True)
class _Records:
    """Fields of the record lines."""

    line_index: np.ndarray  # index into the lines
    prn: np.ndarray
    time: np.ndarray  # GPS microseconds, EMS convention (end of the slot)
    nbytes: np.ndarray
    reason: np.ndarray  # 0 or a code of _REASONS

    @staticmethod
    def parse(buf: np.ndarray, lines: _Lines, idx: np.ndarray) -> _Records:
        head = lines.mat[idx]
        # "S123": a three-digit PRN after the S shifts every later field one column right.
        shift = (head[:, 0] == ord("S")) & _digit(head[:, 1:4]).all(axis=1) & (head[:, 4] == _BLANK)
        m = _gather(buf, lines.start[idx] + shift, _REC_WIDTH)
        length = lines.length[idx] - shift
        c0 = head[:, 0]
        two_digit = 100 + _int(head, (1, 2))  # "S23" (or " 23"): S + PRN - 100
        prn = np.where(shift, _int(head, (1, 2, 3)), np.where(_digit(c0), _int(head, (0, 1, 2)), two_digit))
        prn_ok = shift | ((_digit(c0) | (c0 == ord("S")) | (c0 == _BLANK)) & _digit(head[:, 1:3]).all(axis=1))
        two = [_i_field(m, range(c, c + 2)) for c in (4, 7, 10, 13, 16)]
        fixed = (m[:, [3, 6, 9, 12, 15]] == _BLANK).all(axis=1) & np.logical_and.reduce(two)
        secs = _i_field(m, range(18, 21)) & (m[:, 21] == _DOT) & _digit(m[:, 22])
        # Optional fields: band and frequency (columns 26-27), number of bytes (31-33); the receiver
        # index and source after them are not needed.
        gap = (m[:, [23, 24]] == _BLANK).all(axis=1)
        has_count = (length >= _REC_WIDTH) & gap & (m[:, [27, 28, 29]] == _BLANK).all(axis=1)
        tail_ok = (length == 23) | ((length == 27) & gap) | (has_count & _i_field(m, range(30, 33)))
        layout_ok = prn_ok & fixed & secs & tail_ok
        band, freq = m[:, 25], m[:, 26]
        l1 = (
            ((band == ord("L")) & (freq == ord("1"))) | ((band == _BLANK) & (freq == _BLANK)) | (length == 23)
        )
        nbytes = np.where(length >= _REC_WIDTH, _int(m, range(30, 33)), FRAME_BYTES)  # gLAB assumes 32
        time, bad_time = _gps_time(m)

        reason = np.zeros(len(idx), np.uint8)
        reason[~l1] = _R["not_l1"]
        reason[(prn < _SBAS_PRN[0]) | (prn > _SBAS_PRN[1])] = _R["not_sbas_prn"]
        epoch = time - _US  # the tag is the epoch's whole seconds + 1 s
        reason[~plausible_us(epoch)] = _R["time_out_of_range"]
        reason[bad_time] = _R["bad_time"]
        reason[~layout_ok] = _R["layout"]
        return _Records(idx, prn, time, nbytes, reason)


def _gps_time(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """EMS time tag (whole seconds of the epoch + 1 s, GPS microseconds) and out-of-range dates."""
    yy, mo, dd = _int(m, (4, 5)), _int(m, (7, 8)), _int(m, (10, 11))
    hh, mi, ss = _int(m, (13, 14)), _int(m, (16, 17)), _int(m, (18, 19, 20))
    year = np.where(yy < 80, 2000 + yy, 1900 + yy)
    first = ((year - 1970) * 12 + np.clip(mo - 1, 0, 11)).astype("datetime64[M]")
    days_in_month = ((first + 1).astype("datetime64[D]") - first.astype("datetime64[D]")).astype(np.int64)
    bad = (mo < 1) | (mo > 12) | (dd < 1) | (dd > days_in_month) | (hh > 23) | (mi > 59) | (ss > 59)
    day = first.astype("datetime64[D]").astype(np.int64) + dd - 1
    return (day * 86_400 + hh * 3600 + mi * 60 + ss + 1) * _US, bad


# --------------------------------------------------------------------------- data lines


@dataclasses.dataclass(frozen=True, slots=True)
class _DataLines:
    """Data lines of the records, in file order (the lines of one record are consecutive)."""

    line_index: np.ndarray
    owner: np.ndarray  # record index
    npairs: np.ndarray  # bytes on the line (0-18)
    first: np.ndarray  # first data line of its record
    mt: np.ndarray  # type field of a first line
    reason: np.ndarray  # 0, layout or bad_hex
    bytes: np.ndarray  # (n, 18) uint8 decoded pairs (garbage where not valid)

    @staticmethod
    def parse(lines: _Lines, idx: np.ndarray, owner: np.ndarray) -> _DataLines:
        m, length, own = lines.mat[idx], lines.length[idx], owner[idx]
        first = np.ones(len(idx), bool)
        first[1:] = own[1:] != own[:-1]
        body = length - (_FIRST_HEX - 1)  # " XX" per byte after the type columns
        npairs = np.clip(body // 3, 0, _PER_LINE)
        whole = (body >= 3) & (body % 3 == 0) & (body <= 3 * _PER_LINE)
        valid = np.arange(_PER_LINE) < npairs[:, None]
        triples = m[:, _FIRST_HEX - 1 : _FIRST_HEX - 1 + 3 * _PER_LINE].reshape(len(idx), _PER_LINE, 3)
        seps = ((triples[:, :, 0] == _BLANK) | ~valid).all(axis=1)
        lead = m[:, : _FIRST_HEX - 1]
        has_mt = _digit(lead).any(axis=1)
        lead_ok = (_digit(lead) | (lead == _BLANK)).all(axis=1) & (has_mt == first)
        hi, lo = _HEX[triples[:, :, 1]], _HEX[triples[:, :, 2]]
        hex_ok = (((hi | lo) >= 0) | ~valid).all(axis=1)
        code = np.where(hex_ok, 0, _R["bad_hex"])
        reason = np.where(whole & seps & lead_ok, code, _R["layout"]).astype(np.uint8)
        pairs = ((hi << 4) | (lo & 0xF)).astype(np.uint8)
        return _DataLines(idx, own, npairs, first, _int(lead, range(_FIRST_HEX - 1)), reason, pairs)


def _assemble(recs: _Records, dat: _DataLines) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per record: the 32 message bytes, the type field, the reason code and the line to name."""
    n = len(recs.line_index)
    reason = recs.reason.copy()
    bad_at = recs.line_index.copy()
    # The first bad data line of a record names it, unless the record line itself is bad.
    bad = np.flatnonzero(dat.reason != 0)
    rec_of_bad, first_bad = np.unique(dat.owner[bad], return_index=True)
    line_ok = reason[rec_of_bad] != _R["layout"]
    take = rec_of_bad[line_ok]
    reason[take] = dat.reason[bad[first_bad[line_ok]]]
    bad_at[take] = dat.line_index[bad[first_bad[line_ok]]]

    total = np.bincount(dat.owner, weights=dat.npairs, minlength=n).astype(np.int64)
    count_bad = (total != recs.nbytes) | (recs.nbytes < FRAME_BYTES)
    reason[(reason == 0) & count_bad] = _R["byte_count"]

    valid = np.arange(_PER_LINE) < dat.npairs[:, None]
    flat = dat.bytes[valid]
    line_off = np.concatenate([[0], np.cumsum(dat.npairs)[:-1]]).astype(np.int64)
    first_line = np.full(n, -1, np.int64)
    first_line[dat.owner[dat.first]] = np.flatnonzero(dat.first)
    ok = reason == 0
    data = np.zeros((n, FRAME_BYTES), np.uint8)
    data[ok] = flat[line_off[first_line[ok]][:, None] + np.arange(FRAME_BYTES)]
    data[:, -1] &= np.uint8(0xC0)  # the 6 pad bits
    field_mt = np.full(n, -1, np.int64)
    field_mt[ok] = dat.mt[first_line[ok]]
    return data, field_mt, reason, bad_at


def _explain(reason: str) -> str:
    return {
        "layout": f"malformed RINEX-B record, expected {RINEX_B_LAYOUT}",
        "bad_hex": "message byte that is not two hex digits",
        "byte_count": "truncated record: the data lines do not hold the record's number of bytes (32)",
        "bad_time": "date or time out of range",
        "time_out_of_range": f"epoch outside {PLAUSIBLE_SPAN}",
        "not_sbas_prn": "PRN outside the SBAS range 120-158",
        "not_l1": "message of another band or frequency than L1 (not read)",
        "type_mismatch": "message type field differs from the type in the message bits",
    }.get(reason, reason)
