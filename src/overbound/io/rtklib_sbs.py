"""Reader for RTKLIB SBAS message logs (``.sbs``, written by ``convbin -s`` / ``str2str`` / RTKNAVI).

RTKLIB writes one line per received message (``sbsoutmsg`` in ``src/sbas.c``, RTKLIB 2.4.2)::

    1481 108093 129 26 : 5369C407E20F0EF89783DC17E08F033813C07E01F81FC41E1BF12F6000

that is ``fprintf("%4d %6d %3d %2d : ", week, tow, prn, type)`` and the 29 bytes of
``sbsmsg_t.msg`` as 58 hex digits: GPS week, time of week (whole seconds), the GEO's PRN, the
message type (bits 8-13) and the 226 message bits **without the 24-bit CRC** (preamble, type,
data; ``rtklib.h``: "SBAS message (226bit) padded by 0"), MSB first, the 6 last bits zero.
RTKLIB's own reader (``readmsgs``) splits the fields on blanks and reads the time of week as a
real number, rounded to the second; this reader does the same (and, as ``readmsgs``, clears the
6 pad bits). It does not take the EMS and NovAtel ASCII lines ``readmsgs`` also accepts: EMS
files are read by :func:`overbound.io.ems.read_ems`.

CRC
---
:class:`~overbound.io.sbas_frames.SbasFrames` holds the 250 bits of each message with their CRC-24Q
(DO-229D A.4.3.3). A ``.sbs`` line has no CRC, so none can be checked here: the reader appends
the CRC-24Q computed from the 226 bits (``crc_ok`` is then True for every message) and relies on
the check made before the line was written. RTKLIB writes a u-blox RXM-SFRB message only when
its received parity matches (``sbsdecodemsg``, called by ``decode_rxmsfrb``); a Hemisphere BIN80
or NovAtel RAWWAASFRAME message is written as the receiver output it, the receiver having
decoded it (RTKLIB's ``decode_cresraw80`` and ``decode_rawwaasframeb`` check nothing; NovAtel
removes the parity). RTKLIB's positioning uses every ``.sbs`` message the same way. The report's
notes say that the CRC was recomputed. A message whose first byte is not one of the three
preambles 0x53, 0x9A, 0xC6 is rejected (``bad_preamble``): without a CRC the preamble is the only
check left on the bits, and the time tag needs it (below).

Time tag
--------
The week and time of week are the *receiver's* time of the message (``sbsmsg_t``: "receiption
time"), which RTKLIB takes from different places per receiver: u-blox, the RXM-RAW epoch before
the RXM-SFRB frame, which is the **end** of the one-second transmission slot on RTKLIB's test log
(every 0x53 message at a TOW = 1 mod 3); Hemisphere BIN80 and NovAtel RAWWAASFRAME, the message's
own time, the **start** of the slot (0x53 at TOW = 0 mod 3). DO-229D A.4.3 starts the 0x53,
0x9A and 0xC6 messages at GPS seconds 0, 1 and 2 modulo 3. As for u-blox logs
(:mod:`overbound.io.ubx_raw`), the slot start is therefore the first GPS second t >= TOW - 1
whose phase modulo 3 fits the preamble, and the time kept is t + 1 s, the end of the slot, as in
EMS files (:mod:`overbound.io.ems`), so a message gets the same time from an EMS, RINEX-B,
u-blox or ``.sbs`` file. This holds when the written time lies within the slot (start to end),
true of the three RTKLIB decoders above (``tests/io/test_rtklib_sbs.py`` checks all three).

Parsing is vectorised: all files are joined into one buffer, split into lines and matched by
one regular expression in polars; the hex digits of all good lines are decoded by one
``bytes.fromhex`` call and the CRCs by :func:`overbound.io.sbas_crc.parity_of_data`.

Rejections are counted per line with file and line number (``frames.rejected``): ``layout`` (not
``week tow prn type : hex``), ``message_length`` (not 58 hex digits, e.g. a cut line),
``bad_time`` (time of week >= 604800 s), ``time_out_of_range`` (outside
:data:`~overbound.io.gpstime.PLAUSIBLE_SPAN`), ``not_sbas_prn`` (outside 120-158),
``type_mismatch`` (the type field differs from bits 8-13), ``bad_preamble`` and ``duplicate``
(same GEO, time and bits as an earlier line, as for EMS). A file in which no line has the
layout is not a ``.sbs`` file and raises :class:`~overbound.io.schema.InputError`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import polars as pl

from overbound.io._rinex import GPS_EPOCH_US, US
from overbound.io.ems import _frames_in_time_order, _join, _lines, _report
from overbound.io.gpstime import PLAUSIBLE_SPAN, plausible_us
from overbound.io.open import Source, read_bytes, source_name
from overbound.io.sbas_bits import FRAME_BYTES, message_type
from overbound.io.sbas_crc import parity_of_data
from overbound.io.sbas_frames import SbasFrames
from overbound.io.schema import InputError, ReadReport

__all__ = ["RTKLIB_SBS_LAYOUT", "SBS_LINE", "read_rtklib_sbs"]

RTKLIB_SBS_LAYOUT = "week tow PRN type : HEX (58 hex digits, the 226 message bits without CRC)"
#: One ``.sbs`` line (RTKLIB ``sbsoutmsg``), blanks as loose as RTKLIB's ``readmsgs`` takes them.
SBS_LINE = r"^\s*(\d{1,4})\s+(\d{1,6}(?:\.\d*)?)\s+(\d{1,3})\s+(\d{1,2})\s+:\s*(\S*)\s*$"
_MSG_BYTES = 29  # sbsmsg_t.msg: 226 bits and 6 zero bits
_REASONS = (
    "", "layout", "message_length", "bad_time", "time_out_of_range", "not_sbas_prn", "type_mismatch",
    "bad_preamble",
)  # fmt: skip
_R = {r: i for i, r in enumerate(_REASONS)}
_SBAS_PRN = (120, 158)
_WEEK_S = 604_800
#: Transmission start (GPS s) modulo 3 of each preamble (DO-229D A.4.3).
_PHASE = np.full(256, -1, np.int64)
_PHASE[[0x53, 0x9A, 0xC6]] = (0, 1, 2)


def read_rtklib_sbs(
    sources: Source | Sequence[Source], *, strict: bool = False
) -> tuple[SbasFrames, ReadReport]:
    """Read one or several RTKLIB ``.sbs`` files (plain or gzip) into time-ordered :class:`SbasFrames`.

    Parameters
    ----------
    sources : a path or stream, or a sequence of them (any order: messages are sorted by time,
        stably).
    strict : raise :class:`InputError` at the first malformed line instead of counting it.

    Returns
    -------
    frames : every readable message; ``data`` holds the 226 bits read and the CRC-24Q computed
        from them (``crc_ok`` True: the CRC was checked before RTKLIB wrote the line, see the module
        notes); ``time`` the end of the transmission slot, as for EMS.
    report : ``rows_read`` = non-blank lines, ``rows_kept`` = messages, ``rejected`` = unreadable
        lines by reason; ``first_bad`` names file and line of the first rejection. The full list is
        ``frames.rejected`` (``file``, ``line``, ``reason``).

    Raises
    ------
    InputError
        A file does not exist, holds lines but none in the ``.sbs`` layout, or (``strict``) has a
        malformed line.
    """
    many = isinstance(sources, Sequence) and not isinstance(sources, str | bytes)
    items = list(sources) if many else [sources]  # type: ignore[list-item]
    names = tuple(source_name(s) for s in items)
    buf, file_start = _join([read_bytes(s) for s in items])
    file, lineno, text = _text_lines(buf, file_start)
    cols = pl.DataFrame({"t": text}).select(pl.col("t").str.extract_groups(SBS_LINE)).unnest("t")
    reason = np.where(cols["1"].is_null().to_numpy(), _R["layout"], 0).astype(np.uint8)
    reason[(reason == 0) & (cols["5"].str.len_bytes().fill_null(0).to_numpy() != 2 * _MSG_BYTES)] = _R[
        "message_length"
    ]
    reason[(reason == 0) & ~cols["5"].str.contains(r"^[0-9A-Fa-f]*$").fill_null(False).to_numpy()] = _R[
        "layout"
    ]
    _refuse_files_without_sbs(names, file, lineno, text, reason)
    ok = np.flatnonzero(reason == 0)
    fields, bad = _decode(cols[ok])
    reason[ok[bad[0]]] = bad[1]
    rej = np.flatnonzero(reason != 0)
    if strict and rej.size:
        i = int(rej[0])
        raise InputError(names[file[i]], _explain(_REASONS[reason[i]]), line=int(lineno[i]))
    keep = ok[reason[ok] == 0]
    rejected = (file[rej], lineno[rej], np.asarray(_REASONS)[reason[rej]])
    frames = _frames_in_time_order(fields, file[keep], lineno[keep], names, rejected, strict)
    report = _report(items, frames)
    source = report.source if len(items) <= 3 else f"{len(items)} RTKLIB .sbs files"
    notes = (
        *report.notes,
        "no CRC in .sbs lines: CRC-24Q recomputed, the messages taken as checked upstream",
    )
    return frames, dataclasses.replace(report, format="rtklib-sbs", source=source, notes=notes)


def _text_lines(buf: np.ndarray, file_start: np.ndarray) -> tuple[np.ndarray, np.ndarray, pl.Series]:
    """File index, 1-based line number and text of every non-blank line of the joined files."""
    start, length = _lines(buf)
    file = (np.searchsorted(file_start, start, side="right") - 1).astype(np.int16)
    first_line = np.searchsorted(start, file_start)  # global index of each file's first line
    lineno = np.arange(len(start)) - first_line[file] + 1
    pieces = pl.Series([buf.tobytes().decode("latin-1")]).str.split("\n").explode()
    keep = np.flatnonzero(length > 0)  # blank lines are skipped, not counted
    return file[keep], lineno[keep], pieces.head(len(start)).gather(keep)


def _decode(cols: pl.DataFrame) -> tuple[dict[str, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Fields of lines in the layout; also (index, reason) of those rejected on content."""
    week = cols["1"].cast(pl.Int64).to_numpy()
    tow = np.floor(cols["2"].cast(pl.Float64).to_numpy() + 0.5).astype(np.int64)  # RTKLIB: (int)(tow+0.5)
    prn = cols["3"].cast(pl.Int64).to_numpy()
    field_mt = cols["4"].cast(pl.Int64).to_numpy()
    msg = np.frombuffer(bytes.fromhex("".join(cols["5"].to_list())), np.uint8).reshape(-1, _MSG_BYTES)
    data = _with_crc(msg)
    phase = _PHASE[data[:, 0]]
    slot_start = tow - 1 + np.mod(phase - (tow - 1), 3)
    time = GPS_EPOCH_US + (week * _WEEK_S + slot_start + 1) * US

    reason = np.zeros(len(cols), dtype=np.uint8)
    reason[phase < 0] = _R["bad_preamble"]
    reason[field_mt != message_type(data)] = _R["type_mismatch"]
    reason[(prn < _SBAS_PRN[0]) | (prn > _SBAS_PRN[1])] = _R["not_sbas_prn"]
    reason[~plausible_us(time)] = _R["time_out_of_range"]
    reason[cols["2"].cast(pl.Float64).to_numpy() >= _WEEK_S] = _R["bad_time"]
    keep = reason == 0
    fields = {
        "time": time[keep],
        "prn": prn[keep].astype(np.int16),
        "data": np.ascontiguousarray(data[keep]),
        "crc_ok": np.ones(int(keep.sum()), dtype=bool),
    }
    return fields, (np.flatnonzero(~keep), reason[~keep])


def _with_crc(msg: np.ndarray) -> np.ndarray:
    """(n, 32) frames: the 226 bits of each 29-byte message, then their CRC-24Q as bits 226-249."""
    data = np.zeros((len(msg), FRAME_BYTES), np.uint8)
    data[:, :_MSG_BYTES] = msg
    data[:, _MSG_BYTES - 1] &= np.uint8(0xC0)  # the pad bits, cleared as RTKLIB's readmsgs does
    crc = parity_of_data(data)
    data[:, 28] |= (crc >> 18).astype(np.uint8)  # bits 226-231
    data[:, 29] = (crc >> 10).astype(np.uint8)  # bits 232-239
    data[:, 30] = (crc >> 2).astype(np.uint8)  # bits 240-247
    data[:, 31] = ((crc & 3) << 6).astype(np.uint8)  # bits 248-249, then 6 pad bits
    return data


def _refuse_files_without_sbs(
    names: tuple[str, ...], file: np.ndarray, lineno: np.ndarray, text: pl.Series, reason: np.ndarray
) -> None:
    """Raise for the first file that has lines but none in the ``.sbs`` layout."""
    fits = np.bincount(file[reason == 0], minlength=len(names))
    has_lines = np.bincount(file, minlength=len(names)) > 0
    for f in np.flatnonzero(has_lines & (fits == 0)).tolist():
        i = int(np.flatnonzero(file == f)[0])
        head = str(text[i])[:60]
        raise InputError(
            names[f],
            f"not an RTKLIB .sbs file: expected {RTKLIB_SBS_LAYOUT}, got {head!r}",
            line=int(lineno[i]),
        )


def _explain(reason: str) -> str:
    return {
        "layout": f"malformed .sbs line, expected {RTKLIB_SBS_LAYOUT}",
        "message_length": f"message of other than {2 * _MSG_BYTES} hex digits (a cut line?)",
        "bad_time": "time of week of 604800 s or more",
        "time_out_of_range": f"time outside {PLAUSIBLE_SPAN}",
        "not_sbas_prn": "PRN outside the SBAS range 120-158",
        "type_mismatch": "message type field differs from the type in the message bits",
        "bad_preamble": "first byte is not an SBAS preamble (0x53, 0x9A, 0xC6)",
    }.get(reason, reason)
