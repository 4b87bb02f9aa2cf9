"""Reader for ESA EGNOS Message Server (EMS) files: raw SBAS messages with GPS time tags.

An EMS file (one per GEO and hour, ``hHH.ems``) holds one line per received message::

    123 19 01 14 00 00 01 4 53110003FFC003FFC0...B8D4AC0

that is ``PRN YY MM DD hh mm ss MT HEX``: the GEO's PRN (3 digits), the two-digit year (here
read as 20YY below 80, else 19YY), month, day, hour, minute and second, the message type (1 or
2 digits) and 64 hex digits = the 250 message bits (preamble, type, data, CRC) followed by 6
pad bits. Some writers pad a one-digit type with a leading space (``" 2"``). Lines end in LF or
CRLF. An hour without messages is an empty file.

Time tag
--------
The tag is GPS time and marks the *end* of the one-second transmission slot: on the real EGNOS
files the 0x53 preamble, which DO-229 sends at GPS seconds that are multiples of 3 s
(the start of every other preamble triple is aligned with a GPS 6-s subframe), is tagged at
3k + 1 s (``tests/io/test_ems.py`` checks this). The reader keeps the tag as it is; gLAB adds
the 0.12 s GEO signal flight time to it when it applies a message, and writes tag - 1 s
(+0.1 s) as the transmission time when it converts EMS to RINEX-B.

Parsing is vectorised: all files are joined into one ``uint8`` array, lines are gathered into
a fixed-width matrix and every column is checked at once (digits, blanks); the hex digits of
all lines are decoded by one ``bytes.fromhex`` call (a 256-entry table finds the bad lines when
that fails). The CRC-24Q of every message is checked on the way (:mod:`overbound.io.sbas_crc`).
The 24 hourly files of a day (73,335 messages) read in about 0.1 s.

A line that does not fit the layout is rejected and counted with its file and line number, and so
is a line whose time falls outside :data:`~overbound.io.gpstime.PLAUSIBLE_SPAN` (a two-digit year
reads as 1980-2079, whose future years only a corrupted digit gives); a file in which no line fits
is not an EMS file and raises :class:`~overbound.io.schema.InputError`.
The newer EMS layout with fractional seconds and a frequency band (L5 / DFMC) is recognised and
refused with a clear message. A RINEX-B file given here is refused with a pointer to
:func:`overbound.io.rinex_b.read_rinex_b`.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import polars as pl

from overbound.io.gpstime import PLAUSIBLE_SPAN, plausible_us
from overbound.io.open import Source, read_bytes, source_name
from overbound.io.sbas_bits import FRAME_BYTES, message_type
from overbound.io.sbas_crc import crc_ok
from overbound.io.sbas_frames import REJECTED_SCHEMA, SbasFrames
from overbound.io.schema import InputError, ReadReport

__all__ = ["EMS_LAYOUT", "read_ems"]

EMS_LAYOUT = "PRN YY MM DD hh mm ss MT HEX (64 hex digits)"
_HEX_DIGITS = 2 * FRAME_BYTES
_WIDTH = 25 + _HEX_DIGITS  # longest accepted line: two-character type
_DIGIT_COLS = np.array([0, 1, 2, 4, 5, 7, 8, 10, 11, 13, 14, 16, 17, 19, 20])
_BLANK_COLS = np.array([3, 6, 9, 12, 15, 18, 21])
_SBAS_PRN = (120, 158)
#: Rejection reasons, by code (0: the line is kept).
_REASONS = ("", "line_length", "layout", "bad_time", "not_sbas_prn", "type_mismatch", "time_out_of_range")
_OK = 0
_US = 1_000_000

_HEX = np.full(256, -1, dtype=np.int16)
for _i, _c in enumerate(b"0123456789ABCDEF"):
    _HEX[_c] = _i
    _HEX[bytes([_c]).lower()[0]] = _i


def read_ems(sources: Source | Sequence[Source], *, strict: bool = False) -> tuple[SbasFrames, ReadReport]:
    """Read one or several EMS files (plain or gzip) into time-ordered :class:`SbasFrames`.

    Parameters
    ----------
    sources : a path or stream, or a sequence of them (e.g. the 24 hourly files of a day, in
        any order: the messages are sorted by time, stably).
    strict : raise :class:`InputError` at the first malformed line instead of counting it.

    Returns
    -------
    frames : every readable message, bad CRC included (``crc_ok`` False).
    report : ``rows_read`` = non-blank lines, ``rows_kept`` = messages, ``rejected`` = unreadable
        lines by reason, ``invalidated`` = {"bad_crc": n}; ``first_bad`` names file and line of the
        first rejection. The full list is ``frames.rejected`` (``file``, ``line``, ``reason``).

    Raises
    ------
    InputError
        A file does not exist, is not an EMS file, or (``strict``) has a malformed line.

    Notes
    -----
    Rejection reasons: ``line_length`` (not 88 or 89 characters after the line end is removed,
    e.g. a truncated line), ``layout`` (a digit, blank or hex digit out of place),
    ``bad_time`` (month, day, hour, minute or second out of range), ``time_out_of_range`` (a time
    outside :data:`~overbound.io.gpstime.PLAUSIBLE_SPAN`), ``not_sbas_prn`` (PRN outside
    120-158), ``type_mismatch`` (the type field differs from bits 8-13 of a message whose CRC
    holds), ``duplicate`` (same GEO, time and bits as an earlier line).
    """
    many = isinstance(sources, Sequence) and not isinstance(sources, str | bytes)
    items = list(sources) if many else [sources]  # type: ignore[list-item]
    names = tuple(source_name(s) for s in items)
    buf, file_start = _join([read_bytes(s) for s in items])
    lines = _Lines.of(buf, file_start)
    data, hexok = _hex_bytes(buf, lines)
    reason = _check_layout(lines.mat, lines.length, hexok)
    _refuse_files_without_ems(names, lines, reason)
    ok = np.flatnonzero(reason == _OK)
    fields, bad = _decode_lines(lines.mat[ok], lines.length[ok], data[ok])
    reason[ok[bad[0]]] = bad[1]
    rej = np.flatnonzero(reason != _OK)
    if strict and rej.size:
        i = int(rej[0])
        raise InputError(
            names[lines.file[i]], _explain(_REASONS[reason[i]], lines.length[i]), line=int(lines.lineno[i])
        )
    keep = ok[reason[ok] == _OK]
    rejected = (lines.file[rej], lines.lineno[rej], np.asarray(_REASONS)[reason[rej]])
    frames = _frames_in_time_order(fields, lines.file[keep], lines.lineno[keep], names, rejected, strict)
    return frames, _report(items, frames)


def _frames_in_time_order(
    fields: dict[str, np.ndarray],
    file: np.ndarray,
    line: np.ndarray,
    names: tuple[str, ...],
    rejected: tuple[np.ndarray, np.ndarray, np.ndarray],
    strict: bool,
) -> SbasFrames:
    """The messages read (``fields``: time, prn, data, crc_ok; their file index and line) in time order
    (stable: files may come in any order), with the rejected lines (file index, line, reason), duplicates
    removed (:func:`_drop_duplicates`). Shared by the EMS and RINEX-B readers."""
    order = np.argsort(fields["time"], kind="stable")
    rej_file, rej_line, rej_reason = rejected
    frames = SbasFrames(
        time=fields["time"][order],
        prn=np.asarray(fields["prn"])[order].astype(np.int16),
        data=np.ascontiguousarray(fields["data"][order]),
        crc_ok=fields["crc_ok"][order],
        file=file[order],
        line=line[order],
        files=names,
        rejected=pl.DataFrame(
            {"file": [names[i] for i in rej_file], "line": rej_line, "reason": rej_reason},
            schema=REJECTED_SCHEMA,
        ),
    )
    return _sort_rejected(_drop_duplicates(frames, strict))


def _join(raws: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """All files as one byte array (each ending in a line feed, a leading UTF-8 byte-order mark
    dropped) and the offset where each starts."""
    raws = [r[3:] if r.startswith(b"\xef\xbb\xbf") else r for r in raws]
    raws = [r if not r or r.endswith(b"\n") else r + b"\n" for r in raws]
    sizes = np.array([len(r) for r in raws], dtype=np.int64)
    return np.frombuffer(b"".join(raws), dtype=np.uint8), np.concatenate([[0], np.cumsum(sizes)[:-1]])


@dataclass(frozen=True, slots=True)
class _Lines:
    """The non-blank lines of the joined files."""

    start: np.ndarray  # byte offset in the joined buffer
    length: np.ndarray  # characters, line end and trailing blanks removed
    file: np.ndarray  # index of the source file
    lineno: np.ndarray  # 1-based line number in that file
    mat: np.ndarray  # (n, 89) first characters of each line, zero padded

    @staticmethod
    def of(buf: np.ndarray, file_start: np.ndarray) -> _Lines:
        start, length = _lines(buf)
        file = (np.searchsorted(file_start, start, side="right") - 1).astype(np.int16)
        first_line = np.searchsorted(start, file_start)  # global index of each file's first line
        lineno = np.arange(len(start)) - first_line[file] + 1
        keep = length > 0  # blank lines are skipped, not counted
        start, length = start[keep], length[keep]
        return _Lines(start, length, file[keep], lineno[keep], _gather(buf, start, _WIDTH))


def _lines(buf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start offset and length (line end and trailing blanks removed) of every line."""
    nl = np.flatnonzero(buf == ord("\n"))
    ends = nl if len(buf) and buf[-1] == ord("\n") else np.append(nl, len(buf))
    starts = np.concatenate([[0], nl[: len(ends) - 1] + 1]).astype(np.int64)
    ends = ends.astype(np.int64)
    for _ in range(4):  # CR and a few trailing blanks
        last = buf[np.maximum(ends - 1, 0)] if len(buf) else np.zeros(0, np.uint8)
        trail = (ends > starts) & ((last == ord("\r")) | (last == ord(" ")) | (last == ord("\t")))
        if not trail.any():
            break
        ends[trail] -= 1
    return starts, ends - starts


def _gather(buf: np.ndarray, start: np.ndarray, width: int) -> np.ndarray:
    """(n, width) matrix of the first ``width`` bytes of each line, zero padded."""
    padded = np.concatenate([buf, np.zeros(width, np.uint8)])
    return np.lib.stride_tricks.sliding_window_view(padded, width)[start]


def _check_layout(mat: np.ndarray, length: np.ndarray, hexok: np.ndarray) -> np.ndarray:
    """Reason code per line: ``_OK`` for lines that fit the EMS layout."""
    reason = np.where((length != _WIDTH - 1) & (length != _WIDTH), _REASONS.index("line_length"), _OK)
    digits = mat[:, _DIGIT_COLS]
    fixed = ((digits >= ord("0")) & (digits <= ord("9"))).all(axis=1) & (mat[:, _BLANK_COLS] == ord(" ")).all(
        axis=1
    )
    # Type field: one digit then a blank (88 chars), or blank-or-digit + digit then a blank (89).
    c22, c23, c24 = mat[:, 22], mat[:, 23], mat[:, 24]
    isdig = lambda c: (c >= ord("0")) & (c <= ord("9"))  # noqa: E731
    short = (length == _WIDTH - 1) & isdig(c22) & (c23 == ord(" "))
    long_ = (length == _WIDTH) & (isdig(c22) | (c22 == ord(" "))) & isdig(c23) & (c24 == ord(" "))
    bad = (reason == _OK) & ~(fixed & (short | long_) & hexok)
    reason[bad] = _REASONS.index("layout")
    return reason.astype(np.uint8)


def _hex_bytes(buf: np.ndarray, lines: _Lines) -> tuple[np.ndarray, np.ndarray]:
    """The last 64 characters of each line as 32 bytes, and whether they were all hex digits."""
    first = lines.start + np.maximum(lines.length - _HEX_DIGITS, 0)
    padded = np.concatenate([buf, np.zeros(_HEX_DIGITS, np.uint8)])
    chars = np.lib.stride_tricks.sliding_window_view(padded, _HEX_DIGITS)[first]
    if not (chars <= ord(" ")).any():  # bytes.fromhex would skip blanks
        try:  # the common case, all lines clean: one C call
            raw = bytes.fromhex(chars.tobytes().decode("ascii"))
        except (ValueError, UnicodeDecodeError):
            pass
        else:
            data = np.frombuffer(raw, np.uint8).reshape(-1, FRAME_BYTES).copy()
            return data, np.ones(len(first), dtype=bool)
    nib = _HEX[chars]
    ok = (nib >= 0).all(axis=1)
    nib = np.maximum(nib, 0).astype(np.uint8)
    return (nib[:, 0::2] << np.uint8(4)) | nib[:, 1::2], ok


def _num(mat: np.ndarray, cols: tuple[int, ...]) -> np.ndarray:
    out = np.zeros(len(mat), dtype=np.int64)
    for c in cols:
        out = 10 * out + (mat[:, c].astype(np.int64) - ord("0"))
    return out


def _decode_lines(
    mat: np.ndarray, length: np.ndarray, data: np.ndarray
) -> tuple[dict[str, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Fields of well-formed lines; also (index, reason) of those rejected on content."""
    prn = _num(mat, (0, 1, 2))
    yy, mo, dd = _num(mat, (4, 5)), _num(mat, (7, 8)), _num(mat, (10, 11))
    hh, mi, ss = _num(mat, (13, 14)), _num(mat, (16, 17)), _num(mat, (19, 20))
    year = np.where(yy < 80, 2000 + yy, 1900 + yy)
    month0 = np.clip(mo - 1, 0, 11)
    first = ((year - 1970) * 12 + month0).astype("datetime64[M]")
    days_in_month = ((first + 1).astype("datetime64[D]") - first.astype("datetime64[D]")).astype(np.int64)
    bad_time = (mo < 1) | (mo > 12) | (dd < 1) | (dd > days_in_month) | (hh > 23) | (mi > 59) | (ss > 59)
    day = first.astype("datetime64[D]").astype(np.int64) + dd - 1
    time = ((day * 86_400) + hh * 3600 + mi * 60 + ss) * _US

    data[:, -1] &= np.uint8(0xC0)  # the 6 pad bits
    good_crc = crc_ok(data)
    tens = np.where(mat[:, 22] == ord(" "), 0, mat[:, 22].astype(np.int64) - ord("0"))
    field_mt = np.where(length == _WIDTH, 10 * tens + _num(mat, (23,)), _num(mat, (22,)))
    mismatch = good_crc & (field_mt != message_type(data))

    reason = np.zeros(len(mat), dtype=np.uint8)
    reason[mismatch] = _REASONS.index("type_mismatch")
    reason[(prn < _SBAS_PRN[0]) | (prn > _SBAS_PRN[1])] = _REASONS.index("not_sbas_prn")
    reason[~plausible_us(time)] = _REASONS.index("time_out_of_range")
    reason[bad_time] = _REASONS.index("bad_time")
    keep = reason == _OK
    frames = {
        "time": time[keep],
        "prn": prn[keep].astype(np.int16),
        "data": np.ascontiguousarray(data[keep]),
        "crc_ok": good_crc[keep],
    }
    return frames, (np.flatnonzero(~keep), reason[~keep])


def _refuse_files_without_ems(names: tuple[str, ...], lines: _Lines, reason: np.ndarray) -> None:
    """Raise for the first file that has lines but none in the EMS layout."""
    fits = np.bincount(lines.file[reason == _OK], minlength=len(names))
    has_lines = np.bincount(lines.file, minlength=len(names)) > 0
    for f in np.flatnonzero(has_lines & (fits == 0)).tolist():
        mine = np.flatnonzero(lines.file == f)
        i = int(mine[0])
        head = bytes(lines.mat[i, : min(int(lines.length[i]), 60)]).decode("ascii", "replace")
        line = int(lines.lineno[i])
        if b"RINEX VERSION / TYPE" in bytes(lines.mat[mine[:5]].ravel()):
            raise InputError(
                names[f], "a RINEX file, not EMS (RINEX-B: overbound.io.rinex_b.read_rinex_b)", line=line
            )
        if len(head) > 21 and head[21] == "." and head[:3].isdigit():
            raise InputError(
                names[f],
                f"EMS line with fractional seconds (newer L1/L5 layout) not supported; expected {EMS_LAYOUT}",
                line=line,
            )
        raise InputError(names[f], f"not an EMS file: expected {EMS_LAYOUT}, got {head!r}", line=line)


def _explain(reason: str, length: int) -> str:
    if reason == "line_length":
        return f"line of {length} characters, expected 88 or 89 ({EMS_LAYOUT})"
    return {
        "layout": f"malformed EMS line, expected {EMS_LAYOUT}",
        "bad_time": "date or time out of range",
        "time_out_of_range": f"time outside {PLAUSIBLE_SPAN}",
        "not_sbas_prn": "PRN outside the SBAS range 120-158",
        "type_mismatch": "message type field differs from the type in the message bits",
    }.get(reason, reason)


def _drop_duplicates(frames: SbasFrames, strict: bool) -> SbasFrames:
    """Drop lines that repeat an earlier (GEO, time, bits); keep the first."""
    if len(frames) < 2:
        return frames
    order = np.lexsort((frames.prn, frames.time))  # stable: file order within equal keys
    t, p, d = frames.time[order], frames.prn[order], frames.data[order]
    same = (t[1:] == t[:-1]) & (p[1:] == p[:-1]) & (d[1:] == d[:-1]).all(axis=1)
    if not same.any():
        return frames
    idx = np.sort(order[1:][same])
    names = [frames.files[i] for i in frames.file[idx]]
    if strict:
        raise InputError(
            names[0], "duplicate message (same GEO, time and bits)", line=int(frames.line[idx[0]])
        )
    extra = pl.DataFrame(
        {"file": names, "line": frames.line[idx], "reason": ["duplicate"] * len(idx)}, schema=REJECTED_SCHEMA
    )
    keep = np.ones(len(frames), dtype=bool)
    keep[idx] = False
    kept = frames.take(keep)
    return SbasFrames(
        time=kept.time,
        prn=kept.prn,
        data=kept.data,
        crc_ok=kept.crc_ok,
        file=kept.file,
        line=kept.line,
        files=kept.files,
        rejected=pl.concat([frames.rejected, extra]),
    )


def _sort_rejected(frames: SbasFrames) -> SbasFrames:
    """Rejections in input order: file as given, then line."""
    rank = {name: i for i, name in reversed(list(enumerate(frames.files)))}
    rej = frames.rejected.sort(pl.col("file").replace_strict(rank, return_dtype=pl.Int64), "line")
    return SbasFrames(
        frames.time, frames.prn, frames.data, frames.crc_ok, frames.file, frames.line, frames.files, rej
    )


def _report(items: list[Source], frames: SbasFrames) -> ReadReport:
    rej = frames.rejected
    first = ""
    if rej.height:
        row = rej.row(0, named=True)
        first = f"{row['file']}:{row['line']}: {row['reason']}"
    n_bad_crc = int((~frames.crc_ok).sum())
    return ReadReport(
        source=", ".join(source_name(s) for s in items) if len(items) <= 3 else f"{len(items)} EMS files",
        format="ems",
        rows_read=len(frames) + rej.height,
        rows_kept=len(frames),
        rejected=dict(Counter(rej["reason"].to_list())),
        invalidated={"bad_crc": n_bad_crc} if n_bad_crc else {},
        first_bad=first,
        notes=(f"files: {len(frames.files)}, GEOs: {sorted(set(frames.prn.tolist()))}",),
    )
