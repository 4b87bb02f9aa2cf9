"""u-blox raw logs for the SBAS engine: observations, GPS ephemerides and SBAS frames from one UBX log.

A u-blox receiver with raw output logs, in one stream, what a DO-229 user engine needs:

* pseudoranges: UBX-RXM-RAW (u-blox 5/6: ``iTOW``, ``week``, per satellite ``prMes``, ``cpMes``,
  ``doMes``, ``sv``, ``mesQI``, ``cno``, ``lli``) or UBX-RXM-RAWX (u-blox 8 and later:
  ``rcvTow``, ``week``, per signal ``prMes``, ``cpMes``, ``doMes``, ``gnssId``, ``svId``,
  ``sigId``, ``cno``, ``trkStat``);
* GPS ephemerides: UBX-AID-EPH (subframes 1-3, words 3-10, parity removed, 24 data bits in the
  low bits of each uint32), UBX-RXM-SFRB (u-blox 5/6: ten words of 24 data bits for GPS) or
  UBX-RXM-SFRBX (ten 30-bit words with parity; data = bits 29-6);
* SBAS messages: UBX-RXM-SFRB for SV >= 120 (words 0-6 hold message bits 0-223 MSB first, bits
  25-0 of word 7 hold bits 224-249, RTKLIB ``sbsdecodemsg`` layout) or UBX-RXM-SFRBX with
  ``gnssId`` 1 (eight big-endian words, bits MSB first, RTKLIB ``decode_snav`` layout).

Frames are decoded by :mod:`pyubx2` (``UBXReader.parse``, which checks the checksum); this module
finds them, counts what cannot be read and turns the messages into the tables the engine takes:
the RINEX observation table of :mod:`overbound.io.rinex_obs` (``time``, ``sat``, ``system``,
``prn``, ``flag``, ``C1C``, ``L1C``, ``D1C``, ``S1C``), the ephemeris table of
:mod:`overbound.io.rinex_nav` and :class:`~overbound.io.sbas_frames.SbasFrames`.

Input
-----
Binary UBX (plain or gzip), or the *hex-wrapped* text form of the EGNOS SDK demo log: tokens
separated by commas (or line ends), each either one complete UBX frame written as hex (``b562...``)
or a marker word (``ComputeP``) that is skipped and counted. NMEA sentences between the frames of a
binary log (``$GPRMC,...``, the receiver's other output) are skipped and counted in the notes.

Rows
----
The report counts **frames** (``kept + rejected = read``): every UBX frame found, corrupt or cut
ones included, every hex token that is not hex, and every stretch of bytes between frames that is
neither a frame nor NMEA text (a frame whose sync bytes were damaged). A frame is kept when it is
read whole and its content is accepted, whether the engine uses it (raw epoch, ephemeris, SBAS
message) or not (another class, GPS subframes 4-5, subframes that never complete an ephemeris);
the notes split the kept frames and give the number of observation rows.

Time
----
RXM-RAW / RAWX epochs are GPS time (``week`` and time of week), the receiver's measurement time.
RXM-SFRB(X) carry no time tag. An SBAS message follows in the log the raw epoch T during or after
which it was received; its transmission started at the first GPS second t >= T - 1 (and after the
previous message of the same GEO) whose phase modulo 3 fits its preamble (0x53, 0x9A, 0xC6 start at
3k, 3k + 1, 3k + 2 s: DO-229D A.4.3, the 0x53 message at multiples of 3 s), and its tag is t + 1 s,
the end of the one-second slot, as in EMS files (:mod:`overbound.io.ems`), so the engine treats
both alike. A message without a preceding raw epoch cannot be dated and is counted
(``sbas_undated``). An ephemeris's transmission time (``ttx``) is the raw epoch before the message
that first carried it. A raw epoch outside :data:`~overbound.io.gpstime.PLAUSIBLE_SPAN` (a corrupted
week) is rejected (``time_out_of_range``) and dates nothing.

Ephemeris fields follow IS-GPS-200 20.3.3.3 (subframe 1) and 20.3.3.4 (subframes 2, 3), Table
20-I and 20-III for the scale factors; semicircles are turned into radians with the GPS value of
pi. The 10-bit week of subframe 1 is resolved with the raw epochs' week.
"""

from __future__ import annotations

import math
import re
import struct
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
import polars as pl
from pyubx2 import UBXReader

from overbound.io._rinex import GPS_EPOCH_US, US
from overbound.io.gpstime import PLAUSIBLE_END_US, PLAUSIBLE_SPAN, PLAUSIBLE_START_US
from overbound.io.open import Source, read_bytes, source_name
from overbound.io.sbas_bits import FRAME_BYTES
from overbound.io.sbas_crc import crc_ok
from overbound.io.sbas_frames import REJECTED_SCHEMA, SbasFrames, empty_frames
from overbound.io.schema import InputError, ReadReport

__all__ = ["UbxRaw", "is_ubx", "read_ubx_raw"]

_SYNC = b"\xb5\x62"
_WEEK_US = 604_800 * US
_GPS_PI = 3.1415926535898  # IS-GPS-200 20.3.3.4.3.1
_PHASE = {0x53: 0, 0x9A: 1, 0xC6: 2}  # transmission start modulo 3 s of each preamble
_OBS_COLUMNS = ("C1C", "L1C", "D1C", "S1C")
#: URA index -> URA (m), IS-GPS-200 20.3.3.3.1.3 (upper bounds; index 15: no accuracy prediction).
_URA = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0, 3072.0, 6144.0,
        np.nan)  # fmt: skip
_MARKERS = (b"computep",)
_NMEA = re.compile(rb"[$!][\x20-\x7e]*\r?\n")
_NMEA_CUT = re.compile(rb"[$!][\x20-\x7e]*\Z")  # the last sentence of a cut file
_TOKEN = re.compile(rb"[^,\r\n]+")
#: Payload length of the messages read, from the count field it holds (UBX protocol specifications).
_PAYLOAD: dict[str, Callable[[object], int]] = {
    "RXM-RAW": lambda m: 8 + 24 * m.numSV,
    "RXM-RAWX": lambda m: 16 + 32 * m.numMeas,
    "RXM-SFRB": lambda m: 42,
    "RXM-SFRBX": lambda m: 8 + 4 * m.numWords,
    "AID-EPH": lambda m: 104 if hasattr(m, "sf1d1_01") else 8,
}
_TAKE = {
    "RXM-RAW": "_raw",
    "RXM-RAWX": "_rawx",
    "RXM-SFRB": "_sfrb",
    "RXM-SFRBX": "_sfrbx",
    "AID-EPH": "_aid_eph",
}
#: Why a frame (or token, or stretch of bytes) is rejected.
_WHY = {
    "bad_hex": "token that is not hex digits",
    "bad_frame": "UBX frame with a bad checksum or length",
    "truncated_frame": "UBX frame cut short (end of the file or of its hex token)",
    "unframed_bytes": "bytes outside any UBX frame (a frame with damaged sync bytes?)",
    "bad_payload": "payload length differs from its own count field",
    "time_out_of_range": f"raw epoch outside {PLAUSIBLE_SPAN}",
    "duplicate_epoch": "raw epoch of the same time as an earlier one",
    "duplicate_sbas": "SBAS message repeating the previous one of its GEO bit for bit",
    "sbas_undated": "SBAS message before the first raw epoch",
    "ephemeris_undated": "ephemeris before the first raw epoch",
    "ephemeris_mismatch": "AID-EPH whose subframes carry different IODE/IODC",
}


@dataclass(frozen=True, slots=True, eq=False)
class UbxRaw:
    """What one u-blox log holds for the SBAS engine.

    Attributes
    ----------
    obs : observation table (RINEX table layout): one row per (epoch, satellite) with a pseudorange.
    eph : GPS ephemerides (:attr:`overbound.io.rinex_nav.GpsEphemerides.table` layout), one row per
        distinct (PRN, toc, IODE, IODC), first reception kept.
    frames : SBAS messages with reconstructed EMS-style time tags.
    counts : frames read whole by UBX message name, skipped markers (``markers_skipped``) and NMEA
        sentences (``nmea_skipped``).
    file : the log's name.
    """

    obs: pl.DataFrame
    eph: pl.DataFrame
    frames: SbasFrames
    counts: dict[str, object] = field(default_factory=dict)
    file: str = ""


def is_ubx(head: bytes) -> bool:
    """True for a binary UBX log or its hex-wrapped text form (first bytes after decompression)."""
    h = head.lstrip()
    return h.startswith(_SYNC) or h[:4].lower() == b"b562"


def read_ubx_raw(source: Source) -> tuple[UbxRaw, ReadReport]:
    """Read a u-blox raw log (binary or hex-wrapped text, plain or gzip).

    Returns
    -------
    raw : :class:`UbxRaw`.
    report : in frames (module notes, *Rows*): ``rows_read`` frames seen (corrupt ones, unreadable
        hex tokens and unframed stretches of bytes included), ``rows_kept`` frames read and accepted
        (used or not), ``rejected`` by reason: ``bad_hex`` (a token that is not hex), ``bad_frame``
        (checksum or length), ``truncated_frame`` (cut short at the end of the file or of its hex
        token), ``unframed_bytes`` (bytes outside frames that are not NMEA), ``bad_payload`` (length
        differs from the message's own count), ``time_out_of_range``, ``duplicate_epoch`` (a raw epoch
        of a time already read), ``duplicate_sbas`` (an SBAS message repeating the previous one of its
        GEO), ``sbas_undated``, ``ephemeris_undated`` (each frame of an ephemeris read before the
        first raw epoch), ``ephemeris_mismatch`` (AID-EPH of inconsistent IODs); ``invalidated``:
        ``bad_crc`` SBAS message frames (kept, ``crc_ok`` False). ``first_bad`` is
        ``@<byte offset>: <reason>`` of the first rejection (offset in the decompressed file: in the
        hex text for the hex form); the notes give the first offset of each reason, the kept frames
        by use, and the observation rows of ``raw.obs``.

    Raises
    ------
    InputError
        The file is missing, is not a UBX log, or holds no raw measurement (RXM-RAW/RAWX).
    """
    name = source_name(source)
    data = read_bytes(source)
    if not is_ubx(data[:64]):
        raise InputError(name, "not a u-blox UBX log (no 0xB5 0x62 sync, nor hex-wrapped 'b562...' frames)")
    tally = _Tally()
    counts: Counter = Counter()
    if data.lstrip().startswith(_SYNC):
        segments = [_Segment(data, 0, 1, True)]
    else:
        segments = _unwrap_hex(data, tally, counts)
    state = _State(tally)
    n_parsed = 0
    for seg in segments:
        for offset, length, msg in _scan(seg, tally, counts):
            n_parsed += 1
            counts[msg.identity] += 1
            state.take(msg, offset, length)
    if not state.obs:
        raise InputError(name, "no raw measurements (UBX-RXM-RAW or RXM-RAWX) in the log")
    obs, n_dup_obs = state.obs_table()
    eph = state.eph_table(name)
    frames = state.sbas_frames(name)
    raw = UbxRaw(obs=obs, eph=eph, frames=frames, counts=dict(sorted(counts.items())), file=name)
    bad_crc = int((~frames.crc_ok).sum())
    n_rejected = sum(tally.rejected.values())
    n_unreadable = n_rejected - tally.content_rejected  # never became a message
    rows_kept = n_parsed - tally.content_rejected
    used = state.epochs + state.eph_frames + len(frames)
    frame_counts = {k: v for k, v in sorted(counts.items()) if k not in ("markers_skipped", "nmea_skipped")}
    notes = [
        f"rows are frames: {n_parsed} read whole {frame_counts}, {n_unreadable} unreadable; "
        f"kept {rows_kept}: raw epochs {state.epochs}, ephemeris frames {state.eph_frames}, "
        f"SBAS messages {len(frames)}, not used {rows_kept - used}",
        f"observation rows: {obs.height} ({obs['time'].n_unique()} epochs)"
        + (f", {n_dup_obs} repeated (time, satellite) rows of one frame dropped" if n_dup_obs else ""),
        f"GPS ephemerides: {eph.height}, SBAS GEOs: {sorted(set(frames.prn.tolist()))}",
    ]
    if counts.get("markers_skipped") or counts.get("nmea_skipped"):
        notes.append(
            f"skipped: {counts.get('markers_skipped', 0)} marker tokens, "
            f"{counts.get('nmea_skipped', 0)} NMEA sentences"
        )
    if tally.first:
        notes.append(
            "first of each rejection: " + ", ".join(f"{r} @{o}" for r, o in sorted(tally.first.items()))
        )
    return raw, ReadReport(
        source=name,
        format="ubx-raw",
        rows_read=n_parsed + n_unreadable,
        rows_kept=rows_kept,
        rejected=dict(sorted(tally.rejected.items())),
        invalidated={"bad_crc": bad_crc} if bad_crc else {},
        first_bad=tally.first_bad(),
        notes=tuple(notes),
    )


# --------------------------------------------------------------------------- frames


@dataclass(slots=True)
class _Tally:
    """Rejections by reason, the first offset of each; ``content_rejected``: frames read whole but
    refused for their content (the others never became a message)."""

    rejected: Counter = field(default_factory=Counter)
    first: dict[str, int] = field(default_factory=dict)
    content_rejected: int = 0

    def reject(self, reason: str, offset: int, n: int = 1, *, content: bool = False) -> None:
        self.rejected[reason] += n
        self.first[reason] = min(offset, self.first.get(reason, offset))
        if content:
            self.content_rejected += n

    def first_bad(self) -> str:
        if not self.first:
            return ""
        reason, offset = min(self.first.items(), key=lambda kv: (kv[1], kv[0]))
        return f"@{offset}: {reason} ({_WHY[reason]})"


@dataclass(frozen=True, slots=True)
class _Segment:
    """Bytes scanned for frames: the whole binary log, or one hex token decoded."""

    data: bytes
    base: int  # offset in the file of the first byte (binary) or hex digit (token)
    scale: int  # file bytes per data byte: 1 binary, 2 hex
    last: bool  # the file ends with this segment (a cut frame here is a truncated file)

    def where(self, i: int) -> int:
        return self.base + self.scale * i


def _unwrap_hex(text: bytes, tally: _Tally, counts: Counter) -> list[_Segment]:
    """The decoded tokens of the hex-wrapped log (split at commas and line ends), in order.

    A last token with an odd number of hex digits and no separator after it was cut by a truncated
    file: its whole bytes are scanned (the cut frame counts as ``truncated_frame``)."""
    out = []
    tokens = list(_TOKEN.finditer(text))
    for k, m in enumerate(tokens):
        raw = m.group()
        tok = raw.strip()
        if not tok:
            continue
        at = m.start() + (len(raw) - len(raw.lstrip()))
        if tok.lower() in _MARKERS:
            counts["markers_skipped"] += 1
            continue
        last = k == len(tokens) - 1 and m.end() == len(text)
        cut = last and len(tok) % 2 == 1 and re.fullmatch(rb"[0-9A-Fa-f]+", tok) is not None
        try:
            data = bytes.fromhex((tok[:-1] if cut else tok).decode("ascii"))
        except (ValueError, UnicodeDecodeError):
            tally.reject("bad_hex", at)
            continue
        if cut and not data:
            tally.reject("truncated_frame", at)
            continue
        out.append(_Segment(data, at, 2, last))
    return out


def _scan(seg: _Segment, tally: _Tally, counts: Counter) -> Iterator[tuple[int, int, object]]:
    """(file offset, payload length, parsed message) of every frame read whole in ``seg``.

    A frame that fails the checksum is counted and skipped whole when its length lands on the next
    sync (or the end), else the scan resumes two bytes on and what precedes the next sync belongs to
    it. A frame running past the end is ``truncated_frame`` when no sync follows, else ``bad_frame``
    (a damaged length). Bytes between frames are NMEA sentences (counted in ``counts``), blanks, or an
    ``unframed_bytes`` rejection per stretch."""
    data, n = seg.data, len(seg.data)
    pos, resync = 0, False
    while True:
        j = data.find(_SYNC, pos)
        stop = n if j < 0 else j
        if stop > pos and not resync:
            _gap(seg, pos, stop, tally, counts)
        if j < 0:
            return
        resync = False
        length = struct.unpack_from("<H", data, j + 4)[0] if j + 6 <= n else -1
        end = j + 8 + length
        if length < 0 or end > n:
            if data.find(_SYNC, j + 2) < 0:
                tally.reject("truncated_frame", seg.where(j))
                return
            tally.reject("bad_frame", seg.where(j))
            pos, resync = j + 2, True
            continue
        try:
            msg = UBXReader.parse(data[j:end])
        except Exception:  # pyubx2 raises several types on corrupt payloads
            tally.reject("bad_frame", seg.where(j))
            if end == n or data.startswith(_SYNC, end):
                pos = end
            else:
                pos, resync = j + 2, True
            continue
        yield seg.where(j), length, msg
        pos = end


def _gap(seg: _Segment, start: int, stop: int, tally: _Tally, counts: Counter) -> None:
    """Classify the bytes between two frames: NMEA text and blanks are fine, the rest is rejected."""
    chunk = seg.data[start:stop]
    at_end = seg.last and stop == len(seg.data)
    if at_end and chunk.endswith(_SYNC[:1]):  # the file was cut after the first sync byte
        tally.reject("truncated_frame", seg.where(stop - 1))
        chunk = chunk[:-1]
    rest, n_nmea = _NMEA.subn(b"", chunk)
    if n_nmea:
        counts["nmea_skipped"] += n_nmea
    if at_end:
        rest = _NMEA_CUT.sub(b"", rest.rstrip())
    if rest.strip():
        tally.reject("unframed_bytes", seg.where(start))


# --------------------------------------------------------------------------- state


@dataclass(slots=True)
class _State:
    """Messages gathered in log order."""

    tally: _Tally
    obs: list = field(default_factory=list)  # (time_us, system, prn, pr, cp, dop, cno)
    epochs: int = 0  # raw epoch frames kept
    seen: set = field(default_factory=set)  # their times
    week: int = -1
    last_time: int | None = None  # raw epoch before the current frame, us
    last_tow_s: int | None = None
    sbas: list = field(default_factory=list)  # (tow_s of the epoch before or None, week, prn, bytes, offset)
    last_sbas: dict = field(default_factory=dict)  # prn -> bytes of its previous message
    gps_sub: dict = field(default_factory=dict)  # prn -> {subframe id: words}
    eph: list = field(default_factory=list)  # (prn, words of subframes 1-3 (3 x 10), time_us, frames, offset)
    eph_frames: int = 0  # frames of the ephemerides kept

    def take(self, msg, offset: int, length: int) -> None:
        ident = msg.identity
        if ident not in _TAKE:
            return  # another class: kept, not used
        try:
            if _PAYLOAD[ident](msg) != length:
                raise ValueError(ident)
            getattr(self, _TAKE[ident])(msg, offset)
        except (AttributeError, TypeError, ValueError, OverflowError, struct.error):
            self.tally.reject("bad_payload", offset, content=True)

    def _epoch(self, week: int, tow_s: float, offset: int) -> int | None:
        """The epoch's time (us), or None when rejected (out of range, or a repeat)."""
        t = GPS_EPOCH_US + week * _WEEK_US + round(tow_s * US) if math.isfinite(tow_s) else None
        if t is None or not (0 <= tow_s < 604_800 and PLAUSIBLE_START_US <= t < PLAUSIBLE_END_US):
            self.tally.reject("time_out_of_range", offset, content=True)
            return None
        if t in self.seen:
            self.tally.reject("duplicate_epoch", offset, content=True)
            return None
        self.seen.add(t)
        self.epochs += 1
        self.week = week
        self.last_time, self.last_tow_s = t, int(np.floor(tow_s))
        return t

    def _raw(self, m, offset: int) -> None:
        rows = []
        for k in range(1, m.numSV + 1):
            sv = getattr(m, f"sv_{k:02d}")
            qi = getattr(m, f"mesQI_{k:02d}")
            pr = getattr(m, f"prMes_{k:02d}") if qi >= 4 else np.nan  # u-blox 6: mesQI >= 4, PR+DO OK
            cp = getattr(m, f"cpMes_{k:02d}") if qi >= 5 else np.nan
            system = "S" if sv >= 120 else "G"
            rows.append((system, sv, pr, cp, getattr(m, f"doMes_{k:02d}"), getattr(m, f"cno_{k:02d}")))
        t = self._epoch(m.week, m.iTOW / 1000.0, offset)
        if t is not None:
            self.obs.extend((t, *r) for r in rows)

    def _rawx(self, m, offset: int) -> None:
        rows = []
        for k in range(1, m.numMeas + 1):
            gnss, sig = getattr(m, f"gnssId_{k:02d}"), getattr(m, f"sigId_{k:02d}")
            if gnss not in (0, 1) or sig != 0:  # GPS / SBAS L1 C/A only
                continue
            ok = getattr(m, f"prValid_{k:02d}")
            pr = getattr(m, f"prMes_{k:02d}") if ok else np.nan
            cp = getattr(m, f"cpMes_{k:02d}") if getattr(m, f"cpValid_{k:02d}") else np.nan
            rows.append(("G" if gnss == 0 else "S", getattr(m, f"svId_{k:02d}"), pr, cp,
                         getattr(m, f"doMes_{k:02d}"), getattr(m, f"cno_{k:02d}")))  # fmt: skip
        t = self._epoch(m.week, float(m.rcvTow), offset)
        if t is not None:
            self.obs.extend((t, *r) for r in rows)

    def _sbas(self, prn: int, msg: bytes, offset: int) -> None:
        if self.last_sbas.get(prn) == msg:  # preambles rotate: a GEO never sends the same bits twice running
            self.tally.reject("duplicate_sbas", offset, content=True)
            return
        self.last_sbas[prn] = msg
        self.sbas.append((self.last_tow_s, self.week, prn, msg, offset))

    def _sfrb(self, m, offset: int) -> None:
        w = [int.from_bytes(getattr(m, f"dwrd_{k:02d}"), "little") for k in range(1, 11)]
        if m.svid >= 120:
            bits = 0
            for k in range(7):
                bits = (bits << 32) | w[k]
            bits = ((bits << 26) | (w[7] & 0x3FFFFFF)) << 6
            self._sbas(m.svid, bits.to_bytes(FRAME_BYTES, "big"), offset)
        elif 1 <= m.svid <= 32:
            self._gps_subframe(m.svid, [x & 0xFFFFFF for x in w], offset)

    def _sfrbx(self, m, offset: int) -> None:
        w = [getattr(m, f"dwrd_{k:02d}") for k in range(1, m.numWords + 1)]
        if m.gnssId == 1 and len(w) >= 8:
            msg = b"".join(x.to_bytes(4, "big") for x in w[:8])
            self._sbas(m.svId, msg[:31] + bytes([msg[31] & 0xC0]), offset)
        elif m.gnssId == 0 and len(w) == 10:
            self._gps_subframe(m.svId, [(x >> 6) & 0xFFFFFF for x in w], offset)

    def _gps_subframe(self, prn: int, words: list[int], offset: int) -> None:
        sid = (words[1] >> 2) & 7
        if sid not in (1, 2, 3):
            return
        sub = self.gps_sub.setdefault(prn, {})
        sub[sid] = words
        if len(sub) == 3 and _iode_match(sub[1], sub[2], sub[3]):
            self.eph.append((prn, (sub[1], sub[2], sub[3]), self.last_time, 3, offset))
            self.gps_sub[prn] = {}

    def _aid_eph(self, m, offset: int) -> None:
        if not hasattr(m, "sf1d1_01"):  # 8-byte payload: no ephemeris for this SV
            return
        sf = []
        for s in (1, 2, 3):
            sf.append([0, 0] + [getattr(m, f"sf{s}d{k}_01") & 0xFFFFFF for k in range(1, 9)])
        if _iode_match(*sf):
            self.eph.append((int(m.svid), tuple(sf), self.last_time, 1, offset))
        else:
            self.tally.reject("ephemeris_mismatch", offset, content=True)

    # ------------------------------------------------------------------ tables
    def obs_table(self) -> tuple[pl.DataFrame, int]:
        """The observation table and the number of repeated (time, satellite) rows dropped."""
        t, system, prn, pr, cp, dop, cno = zip(*self.obs, strict=True)
        df = pl.DataFrame(
            {
                "time": pl.Series(np.asarray(t, np.int64)).cast(pl.Datetime("us")),
                "system": pl.Series(system, dtype=pl.String),
                "prn": pl.Series(np.asarray(prn, np.int16)),
                "C1C": np.asarray(pr, float),
                "L1C": np.asarray(cp, float),
                "D1C": np.asarray(dop, float),
                "S1C": np.asarray(cno, float),
            }
        )
        df = df.with_columns(
            sat=pl.col("system") + pl.col("prn").cast(pl.String).str.zfill(2), flag=pl.lit(0, pl.UInt8)
        )
        n = df.height
        df = df.unique(("time", "system", "prn"), keep="first", maintain_order=True)
        table = df.select("time", "sat", "system", "prn", "flag", *_OBS_COLUMNS).sort("time", "system", "prn")
        return table, n - df.height

    def eph_table(self, name: str) -> pl.DataFrame:
        rows = []
        for k, (prn, sf, t, n_frames, offset) in enumerate(self.eph):
            if t is None:
                self.tally.reject("ephemeris_undated", offset, n_frames, content=True)
                continue
            self.eph_frames += n_frames
            rows.append({"prn": prn, **_decode_ephemeris(*sf, week_hint=_week_of(t)), "_t": t, "line": k + 1})
        if not rows:
            return _empty_eph()
        df = pl.DataFrame(rows).sort("prn", "_t", maintain_order=True)
        ttx = df["_t"].to_numpy()
        # toe / toc across a week start from the transmission: the nearest week
        shift = {
            c: np.round((df[c].to_numpy() - ttx) / _WEEK_US).astype(np.int64) for c in ("toe_us", "toc_us")
        }
        df = df.with_columns(
            toe_us=pl.Series(df["toe_us"].to_numpy() - shift["toe_us"] * _WEEK_US),
            toc_us=pl.Series(df["toc_us"].to_numpy() - shift["toc_us"] * _WEEK_US),
            week=pl.Series(df["week"].to_numpy() - shift["toe_us"]),
        )
        df = df.unique(("prn", "toc_us", "iode", "iodc"), keep="first", maintain_order=True)
        ttx = df["_t"].to_numpy()
        week_start = GPS_EPOCH_US + df["week"].to_numpy() * _WEEK_US
        return df.with_columns(
            sat=pl.format("G{}", pl.col("prn").cast(pl.String).str.zfill(2)),
            prn=pl.col("prn").cast(pl.Int16),
            toc=pl.col("toc_us").cast(pl.Datetime("us")),
            ttx=pl.Series((ttx - week_start) / US),
            toe_time=pl.col("toe_us").cast(pl.Datetime("us")),
            ttx_time=pl.Series(ttx).cast(pl.Datetime("us")),
            file=pl.lit(name),
            line=pl.col("line").cast(pl.Int64),
            **{c: pl.col(c).cast(pl.Int32) for c in _INT_COLUMNS},
        ).select(_EPH_COLUMNS)

    def sbas_frames(self, name: str) -> SbasFrames:
        last: dict[int, int] = {}
        keep = []
        for k, (tow, week, prn, msg, offset) in enumerate(self.sbas):
            if tow is None:
                self.tally.reject("sbas_undated", offset, content=True)
                continue
            t = max(tow - 1, last.get(prn, -(10**9)) + 1)
            while t % 3 != _PHASE.get(msg[0], t % 3):
                t += 1
            last[prn] = t
            keep.append((GPS_EPOCH_US + week * _WEEK_US + (t + 1) * US, prn, msg, k + 1))
        if not keep:
            return empty_frames((name,))
        time, prn, msg, line = zip(*keep, strict=True)
        data = np.frombuffer(b"".join(msg), np.uint8).reshape(-1, FRAME_BYTES).copy()
        order = np.argsort(np.asarray(time), kind="stable")
        return SbasFrames(
            time=np.asarray(time, np.int64)[order],
            prn=np.asarray(prn, np.int16)[order],
            data=data[order],
            crc_ok=crc_ok(data)[order],
            file=np.zeros(len(time), np.int16),
            line=np.asarray(line, np.int64)[order],
            files=(name,),
            rejected=pl.DataFrame(schema=REJECTED_SCHEMA),
        )


def _week_of(t_us: int) -> int:
    return int((t_us - GPS_EPOCH_US) // _WEEK_US)


# --------------------------------------------------------------------------- ephemeris


def _bits(words: list[int], word: int, first: int, length: int) -> int:
    """Bits ``first .. first+length-1`` (1-based, MSB first) of 24-bit data word ``word`` (1-based)."""
    return (words[word - 1] >> (24 - first - length + 1)) & ((1 << length) - 1)


def _join(words: list[int], hi: tuple[int, int, int], lo: tuple[int, int, int]) -> int:
    """A field split over two words: its MSBs at ``hi`` and LSBs at ``lo`` (word, first bit, length)."""
    return (_bits(words, *hi) << lo[2]) | _bits(words, *lo)


def _signed(v: int, n: int) -> int:
    return v - (1 << n) if v >> (n - 1) else v


def _iode_match(sf1: list[int], sf2: list[int], sf3: list[int]) -> bool:
    """Subframes of one data set: IODE of 2 and 3 and the 8 LSBs of IODC agree (IS-GPS-200 20.3.4.4)."""
    return _bits(sf2, 3, 1, 8) == _bits(sf3, 10, 1, 8) == _bits(sf1, 8, 1, 8)


def _decode_ephemeris(sf1: list[int], sf2: list[int], sf3: list[int], *, week_hint: int) -> dict:
    """IS-GPS-200 20.3.3.3 / 20.3.3.4 fields of subframes 1-3 (24-bit data words 1-10 each), SI units."""
    wn = _bits(sf1, 3, 1, 10)
    week = week_hint - ((week_hint - wn) % 1024)  # the full week with these 10 LSBs, not after the hint
    if week_hint - week > 512:
        week += 1024
    toc = _bits(sf1, 8, 9, 16) * 16.0
    toe = _bits(sf2, 10, 1, 16) * 16.0
    pi = _GPS_PI
    out = {
        "af0": _signed(_bits(sf1, 10, 1, 22), 22) * 2.0**-31,
        "af1": _signed(_bits(sf1, 9, 9, 16), 16) * 2.0**-43,
        "af2": _signed(_bits(sf1, 9, 1, 8), 8) * 2.0**-55,
        "iode": _bits(sf2, 3, 1, 8),
        "crs": _signed(_bits(sf2, 3, 9, 16), 16) * 2.0**-5,
        "delta_n": _signed(_bits(sf2, 4, 1, 16), 16) * 2.0**-43 * pi,
        "m0": _signed(_join(sf2, (4, 17, 8), (5, 1, 24)), 32) * 2.0**-31 * pi,
        "cuc": _signed(_bits(sf2, 6, 1, 16), 16) * 2.0**-29,
        "e": _join(sf2, (6, 17, 8), (7, 1, 24)) * 2.0**-33,
        "cus": _signed(_bits(sf2, 8, 1, 16), 16) * 2.0**-29,
        "sqrt_a": _join(sf2, (8, 17, 8), (9, 1, 24)) * 2.0**-19,
        "toe": toe,
        "cic": _signed(_bits(sf3, 3, 1, 16), 16) * 2.0**-29,
        "omega0": _signed(_join(sf3, (3, 17, 8), (4, 1, 24)), 32) * 2.0**-31 * pi,
        "cis": _signed(_bits(sf3, 5, 1, 16), 16) * 2.0**-29,
        "i0": _signed(_join(sf3, (5, 17, 8), (6, 1, 24)), 32) * 2.0**-31 * pi,
        "crc": _signed(_bits(sf3, 7, 1, 16), 16) * 2.0**-5,
        "omega": _signed(_join(sf3, (7, 17, 8), (8, 1, 24)), 32) * 2.0**-31 * pi,
        "omega_dot": _signed(_bits(sf3, 9, 1, 24), 24) * 2.0**-43 * pi,
        "idot": _signed(_bits(sf3, 10, 9, 14), 14) * 2.0**-43 * pi,
        "l2_codes": _bits(sf1, 3, 11, 2),
        "week": week,
        "l2p_flag": _bits(sf1, 4, 1, 1),
        "sv_accuracy": _URA[_bits(sf1, 3, 13, 4)],
        "health": _bits(sf1, 3, 17, 6),
        "tgd": _signed(_bits(sf1, 7, 17, 8), 8) * 2.0**-31,
        "iodc": _join(sf1, (3, 23, 2), (8, 1, 8)),
        "fit_interval": 4.0 if _bits(sf2, 10, 17, 1) == 0 else 6.0,
    }
    # toc and toe are times of the week of WN; one more or less when they sit across the week start
    t0 = GPS_EPOCH_US + week * _WEEK_US
    out["toe_us"] = t0 + round(toe * US)
    out["toc_us"] = t0 + round(toc * US)
    return out


_EPH_COLUMNS = (
    "sat", "prn", "toc", "af0", "af1", "af2", "iode", "crs", "delta_n", "m0", "cuc", "e", "cus", "sqrt_a",
    "toe", "cic", "omega0", "cis", "i0", "crc", "omega", "omega_dot", "idot", "l2_codes", "week", "l2p_flag",
    "sv_accuracy", "health", "tgd", "iodc", "ttx", "fit_interval", "toe_time", "ttx_time", "file", "line",
)  # fmt: skip
_INT_COLUMNS = ("iode", "l2_codes", "week", "l2p_flag", "health", "iodc")


def _empty_eph() -> pl.DataFrame:
    schema = {c: pl.Float64 for c in _EPH_COLUMNS}
    schema.update({c: pl.Int32 for c in _INT_COLUMNS})
    schema.update({"sat": pl.String, "prn": pl.Int16, "toc": pl.Datetime("us"), "toe_time": pl.Datetime("us"),
                   "ttx_time": pl.Datetime("us"), "file": pl.String, "line": pl.Int64})  # fmt: skip
    return pl.DataFrame(schema=schema)
