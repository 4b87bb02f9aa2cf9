"""Decoding of L1 SBAS messages (RTCA DO-229D appendix A) into per-type polars tables.

:func:`decode` takes the frames of any reader (:class:`~overbound.io.sbas_frames.SbasFrames`),
drops those whose CRC-24Q fails (counted), and decodes every message type a DO-229 user
engine needs: MT 0, 1, 2-5, 6, 7, 9, 10, 12, 17, 18, 24, 25, 26, 27 and 28. Other types (8, 62
internal test, 63 null, ...) are counted as not decoded. The work is vectorised by type: all
messages of one type are decoded at once with :func:`overbound.io.sbas_bits.field`.

Output model
------------
One long, tidy polars table per kind of content (:class:`SbasMessages`), one row per message
*and* per satellite / grid point it carries, with the message's ``time`` (GPST time tag of the
frame, ``Datetime("us")``), the broadcasting ``geo`` and the issue-of-data fields needed to
match it with the masks: for example ``fast`` has a row per (message, PRN-mask position) with
``iodp``, ``iodf``, ``prc`` and ``udrei``. Every field is scaled to SI units (m, s, m/s, deg),
and indicator fields come with their DO-229 values (``sigma2_udre`` from UDREI, ``sigma2_give``
from GIVEI, ``ai`` from the MT 7 indicator, ``dudre_in/out`` from the MT 27 indicator), null
where the indicator means "not monitored" / "do not use". Tables are in time order.

Long tables are what the engine needs next: the state at an epoch is an as-of join (latest row
not after the epoch, per ``geo`` and ``position`` or IGP) followed by the DO-229 checks that
this module deliberately does not make, because they depend on the user's time:
IODP of MT 2-5/6/7/24/25/28 against the MT 1 mask in force, IODI of MT 26 against MT 18, IODF
of MT 6 against the fast corrections, the time-outs of DO-229D Table A-25 and Table A-8
(:data:`FC_TIMEOUT_PA`...), the range-rate correction from successive fast corrections, the
degradation terms (MT 7, 10), the PA loss after four missing messages (``log``), and the GEO
selection. No ephemeris or position enters here. ``time`` is the reader's tag (for EMS the end
of the one-second transmission slot); DO-229 dates a fast correction at the start of the second
in which its message was sent, i.e. ``time`` - 1 s for EMS input (MT 12's GPS time of week
confirms this on the real EGNOS day), and the engine must apply that offset, plus the signal
flight time where it models reception.

Seen in the real data: three EGNOS MT 12 of 2019-01-14 (10:38-10:45) are all zero except the
UTC standard identifier 7 (no UTC parameters); they decode as zeros and the engine must skip them.

Field layouts follow DO-229D appendix A (message formats of A.4.4: MT 1 A.4.4.2, MT 2-5
A.4.4.3, MT 7 A.4.4.5, MT 10 A.4.4.6, MT 24/25 A.4.4.7, MT 26 A.4.4.10, MT 9 A.4.4.11,
MT 17 A.4.4.12, MT 28 A.4.4.16). They were learnt from, and cross-checked field by field
against, gLAB v6 (``core/input.c``, ``readSBASmessage``), RTKLIB (``src/sbas.c``) and Stanford's
MAAST (``L1_decodeMT*.m``); the tests compare with gLAB's own decoding of the same EMS messages.
Table numbers are those of DO-229D as other public implementations cite them; the RTCA text
was not available here to confirm them.

MT 0 ("do not use this GEO for safety applications"): an all-zero MT 0 carries nothing. During
tests, EGNOS and WAAS have broadcast MT 0 whose body is an MT 2 (fast corrections for mask
positions 1-13); ``decode(..., mt0_as_mt2=True)`` adds those to ``fast`` with ``mt`` 0, as
gLAB's ``-model:usealarmmsgcorr`` and MAAST's test mode do. None of the three real message
sets here (EGNOS PRN 123 2019-01-14, EGNOS PRN 120/126 2012-10-25, MSAS 2008-05-26) contains
an MT 0, so that path is tested on a constructed message only.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np
import polars as pl

from overbound.io.sbas_bits import bit_array
from overbound.io.sbas_bits import field as bitfield
from overbound.io.sbas_frames import SbasFrames
from overbound.sbas.igp import BAND_SIZES, N_BANDS, band_igps

__all__ = [
    "AI",
    "DELTA_UDRE",
    "FC_MAX_UPDATE",
    "FC_TIMEOUT_NPA",
    "FC_TIMEOUT_PA",
    "GIVE",
    "SIGMA2_GIVE",
    "SIGMA2_UDRE",
    "SYSTEMS",
    "UDRE",
    "SbasMessages",
    "decode",
    "slot_satellite",
]

_US = 1_000_000
_DAY_US = 86_400 * _US
_NAN = float("nan")

# --- DO-229 indicator tables -------------------------------------------------------------------
#: UDRE (m, 99.9 %) and sigma^2_UDRE (m^2) for UDREI 0-13 (DO-229D Table A-6); 14 = not monitored,
#: 15 = do not use (NaN here).
UDRE = (0.75, 1.0, 1.25, 1.75, 2.25, 3.0, 3.75, 4.5, 5.25, 6.0, 7.5, 15.0, 50.0, 150.0, _NAN, _NAN)
SIGMA2_UDRE = (
    0.0520, 0.0924, 0.1444, 0.2830, 0.4678, 0.8315, 1.2992, 1.8709,
    2.5465, 3.3260, 5.1968, 20.7870, 230.9661, 2078.695, _NAN, _NAN,
)  # fmt: skip
#: GIVE (m, 99.9 %) and sigma^2_GIVE (m^2) for GIVEI 0-14 (DO-229D Table A-17); 15 = not monitored.
GIVE = (0.3, 0.6, 0.9, 1.2, 1.5, 1.8, 2.1, 2.4, 2.7, 3.0, 3.6, 4.5, 6.0, 15.0, 45.0, _NAN)
SIGMA2_GIVE = (
    0.0084, 0.0333, 0.0749, 0.1331, 0.2079, 0.2994, 0.4075, 0.5322,
    0.6735, 0.8315, 1.1974, 1.8709, 3.3260, 20.7870, 187.0826, _NAN,
)  # fmt: skip
#: Fast-correction degradation factor a_i (m/s^2) for the MT 7 indicator 0-15 (DO-229D Table A-7).
AI = (0.0, 0.00005, 0.00009, 0.00012, 0.00015, 0.00020, 0.00030, 0.00045,
      0.00060, 0.00090, 0.00150, 0.00210, 0.00270, 0.00330, 0.00460, 0.00580)  # fmt: skip
#: Fast-correction user time-out (s) by MT 7 indicator, en route to NPA and PA, and the maximum
#: fast-correction update interval (s) (DO-229D Table A-8). For the engine; not used here.
FC_TIMEOUT_NPA = (180, 180, 153, 135, 135, 117, 99, 81, 63, 45, 45, 27, 27, 27, 18, 18)
FC_TIMEOUT_PA = (120, 120, 102, 90, 90, 78, 66, 54, 42, 30, 30, 18, 18, 18, 12, 12)
FC_MAX_UPDATE = (60, 60, 51, 45, 45, 39, 33, 27, 21, 15, 15, 9, 9, 9, 6, 6)
#: delta-UDRE factor for the MT 27 delta-UDRE indicator 0-15 (DO-229D, MT 27).
DELTA_UDRE = (1.0, 1.1, 1.25, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 20.0, 30.0, 40.0, 50.0, 100.0)

#: Systems of the MT 1 mask slots (DO-229D A.4.4.2).
SYSTEMS = ("GPS", "GLONASS", "SBAS", "reserved")
_DECODED = (0, 1, 2, 3, 4, 5, 6, 7, 9, 10, 12, 17, 18, 24, 25, 26, 27, 28)


@dataclass(frozen=True, slots=True, eq=False)
class SbasMessages:
    """Decoded SBAS messages, one table per content; every table starts with ``time``, ``geo``.

    Attributes
    ----------
    log : every input frame: ``mt``, ``crc_ok``, ``decoded`` (False for a bad CRC or an
        undecoded type). The engine's message-loss logic reads it.
    dont_use : MT 0: ``all_zero`` (True for the plain "do not use" message).
    mask : MT 1, a row per set mask bit: ``iodp``, ``position`` (1-51, order in the mask),
        ``slot`` (1-210), ``system``, ``sv`` (see :func:`slot_satellite`).
    fast : MT 2-5, 24 (fast part) and MT 0 read as MT 2 when asked: ``mt``, ``iodp``, ``iodf``,
        ``position``, ``prc`` (m), ``udrei``, ``sigma2_udre`` (m^2).
    integrity : MT 6: ``position``, ``iodf`` (that of the position's MT 2-5 block; 3 means an
        alarm that applies whatever the fast corrections' IODF), ``udrei``, ``sigma2_udre``.
    fc_degradation : MT 7: ``iodp``, ``tlat`` (s), ``position``, ``ai_index``, ``ai`` (m/s^2).
    geo_nav : MT 9: ``iodn`` (the 8 spare bits, IODN in RINEX-B), ``t0_tod`` (s of day), ``t0``,
        ``ura``, ``x, y, z`` (m), ``vx, vy, vz`` (m/s), ``ax, ay, az`` (m/s^2), ``af0`` (s),
        ``af1`` (s/s); ECEF WGS-84, GPS time.
    degradation : MT 10: ``brrc`` (m), ``cltc_lsb`` (m), ``cltc_v1`` (m/s), ``iltc_v1`` (s),
        ``cltc_v0`` (m), ``iltc_v0`` (s), ``cgeo_lsb`` (m), ``cgeo_v`` (m/s), ``igeo`` (s),
        ``cer`` (m), ``ciono_step`` (m), ``iiono`` (s), ``ciono_ramp`` (m/s), ``rss_udre``,
        ``rss_iono``, ``ccovariance``.
    network_time : MT 12: ``a1`` (s/s), ``a0`` (s), ``t0t`` (s), ``wnt``, ``dt_ls`` (s),
        ``wn_lsf``, ``dn`` (day), ``dt_lsf`` (s), ``utc_id``, ``gps_tow`` (s), ``gps_week``
        (10 bits), ``glonass_indicator``.
    geo_almanac : MT 17, a row per non-empty almanac: ``data_id``, ``prn``, ``provider``
        (4 MSBs of health and status), ``health`` (4 LSBs), ``x, y, z`` (m), ``vx, vy, vz``
        (m/s), ``t0_tod``, ``t0``.
    igp_mask : MT 18, a row per set mask bit: ``n_bands``, ``band``, ``iodi``, ``bit`` (1-201),
        ``igp`` (order among the set bits, what MT 26 blocks count), ``lat``, ``lon`` (deg;
        null for a bit beyond the band's IGPs).
    iono : MT 26, 15 rows per message: ``band``, ``block``, ``iodi``, ``igp``
        (15 block + k + 1), ``givd`` (m), ``givd_dnu`` (raw 511: do not use), ``givei``,
        ``sigma2_give`` (m^2).
    long_term : MT 24 (second half) and MT 25 (both halves), a row per satellite:
        ``mt``, ``half``, ``velocity_code``, ``iodp``, ``position``, ``iode``, ``dx, dy, dz``
        (m), ``daf0`` (s), ``ddx, ddy, ddz`` (m/s), ``daf1`` (s/s), ``t0_tod``, ``t0`` (the rates
        are 0 and the times null for velocity code 0).
    service : MT 27: ``iods``, ``n_messages``, ``message_number``, ``n_regions``, ``priority``,
        ``dudrei_in``, ``dudrei_out``, ``dudre_in``, ``dudre_out``.
    service_regions : MT 27, a row per region: ``iods``, ``message_number``, ``region``,
        ``lat1, lon1, lat2, lon2`` (deg), ``square`` (False = triangle). Only the two broadcast
        corners are given: gLAB takes (lat1, lon2) as a triangle's third corner and MAAST
        (lat2, lon1), so the engine must settle that against DO-229 before it uses triangles.
    covariance : MT 28, a row per satellite: ``iodp``, ``position``, ``scale_exp``, and the
        scaled Cholesky factor ``r11 ... r34`` = 2^(scale_exp - 5) E_ij (C = R^T R).
    counts : messages read, with a bad CRC, decoded, and not decoded by type.
    """

    log: pl.DataFrame
    dont_use: pl.DataFrame
    mask: pl.DataFrame
    fast: pl.DataFrame
    integrity: pl.DataFrame
    fc_degradation: pl.DataFrame
    geo_nav: pl.DataFrame
    degradation: pl.DataFrame
    network_time: pl.DataFrame
    geo_almanac: pl.DataFrame
    igp_mask: pl.DataFrame
    iono: pl.DataFrame
    long_term: pl.DataFrame
    service: pl.DataFrame
    service_regions: pl.DataFrame
    covariance: pl.DataFrame
    counts: dict[str, object] = field(default_factory=dict)

    def tables(self) -> dict[str, pl.DataFrame]:
        """All tables by name."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "counts"}


def slot_satellite(slot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """System name and satellite number of MT 1 mask slots (DO-229D A.4.4.2).

    Slots 1-37 are GPS PRNs, 38-61 GLONASS slots 1-24, 120-138 SBAS PRNs; others are reserved
    for future systems ("reserved", number = slot).

    >>> slot_satellite(np.array([5, 40, 123, 70]))
    (array(['GPS', 'GLONASS', 'SBAS', 'reserved'], dtype='<U8'), array([  5,   3, 123,  70]))
    """
    code, sv = _slot_code(slot)
    return np.asarray(SYSTEMS)[code], sv


def _slot_code(slot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index into :data:`SYSTEMS` and satellite number of mask slots."""
    slot = np.asarray(slot, dtype=np.int64)
    code = np.select([slot <= 37, slot <= 61, (slot >= 120) & (slot <= 138)], [0, 1, 2], 3)
    return code, np.where((slot >= 38) & (slot <= 61), slot - 37, slot)


def decode(frames: SbasFrames, *, mt0_as_mt2: bool = False) -> SbasMessages:
    """Decode every message whose CRC holds; see the module docstring for the tables.

    Parameters
    ----------
    frames : messages from a reader (EMS...), in time order.
    mt0_as_mt2 : also read a non-zero MT 0 as the MT 2 it carries in test mode.
    """
    mt, ok = frames.mt, frames.crc_ok
    decoded = ok & np.isin(mt, _DECODED)
    by_type = _indices_by_type(np.where(ok, mt, 64))  # 64: no type, for a bad CRC

    def pick(types: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        parts = [by_type[m] for m in types if m in by_type]
        idx = np.sort(np.concatenate(parts)) if parts else np.zeros(0, np.int64)
        return frames.time[idx], frames.prn[idx], frames.data[idx], mt[idx]

    tables = {name: fn(*pick(types)[:3]) for name, (types, fn) in _ONE_TYPE.items()}
    t, g, f, m = pick((0, 2, 3, 4, 5) if mt0_as_mt2 else (2, 3, 4, 5))
    keep = m != 0
    keep[~keep] = ~_all_zero_body(f[~keep])  # an all-zero MT 0 carries no corrections
    fast = pl.concat([_fast(t[keep], g[keep], f[keep], m[keep]), _fast24(*pick((24,))[:3])])
    if 24 in by_type:  # MT 24 rows go between the others
        fast = fast.sort("time", maintain_order=True)
    return SbasMessages(
        log=_table(frames.time, frames.prn, {"mt": _u8(mt), "crc_ok": ok, "decoded": decoded}),
        fast=fast,
        long_term=_long_term(*pick((24, 25))),
        **tables,
        counts={
            "messages": len(frames),
            "bad_crc": int((~ok).sum()),
            "decoded": int(decoded.sum()),
            "by_type": _histogram(mt[decoded]),
            "not_decoded": _histogram(mt[ok & ~decoded]),
        },
    )


def _indices_by_type(mt: np.ndarray) -> dict[int, np.ndarray]:
    """Positions of the messages of each type, in input (time) order."""
    order = np.argsort(mt, kind="stable")
    types, first = np.unique(mt[order], return_index=True)
    return {int(m): idx for m, idx in zip(types, np.split(order, first[1:]), strict=True)}


def _histogram(values: np.ndarray) -> dict[int, int]:
    keys, counts = np.unique(values, return_counts=True)
    return {int(k): int(c) for k, c in zip(keys, counts, strict=True)}


# --- helpers -------------------------------------------------------------------------------------
def _time(us: np.ndarray) -> pl.Series:
    return pl.Series("time", np.asarray(us, dtype=np.int64).view("datetime64[us]"))


def _u8(x: np.ndarray) -> pl.Series:
    return pl.Series(np.asarray(x).astype(np.uint8))


def _i16(x: np.ndarray) -> pl.Series:
    return pl.Series(np.asarray(x).astype(np.int16))


def _i32(x: np.ndarray) -> pl.Series:
    return pl.Series(np.asarray(x).astype(np.int32))


def _table(t: np.ndarray, geo: np.ndarray, cols: dict[str, object], repeat: int = 1) -> pl.DataFrame:
    """A table with ``time`` and ``geo`` (each row repeated ``repeat`` times) then ``cols``."""
    base = {"time": _time(np.repeat(t, repeat)), "geo": _i16(np.repeat(geo, repeat))}
    return pl.DataFrame(base | cols)


def _lookup(table: tuple[float, ...], index: np.ndarray) -> pl.Series:
    return pl.Series(np.asarray(table)[index], nan_to_null=True)


def _tod_to_time(t_us: np.ndarray, tod_s: np.ndarray, valid: np.ndarray | None = None) -> pl.Series:
    """Absolute GPS time of a time of day, taken within +-12 h of the message time (null where not valid)."""
    t_us = np.asarray(t_us, dtype=np.int64)
    out = (t_us // _DAY_US) * _DAY_US + np.asarray(tod_s, dtype=np.int64) * _US
    out = np.where(out - t_us > _DAY_US // 2, out - _DAY_US, out)
    out = np.where(out - t_us < -_DAY_US // 2, out + _DAY_US, out)
    series = _time(out).alias("t0")
    if valid is not None and not valid.all():
        series = series.scatter(np.flatnonzero(~valid), None)
    return series


def _all_zero_body(f: np.ndarray) -> np.ndarray:
    """True for an all-zero data field (bits 14-225): the plain MT 0."""
    return ~bit_array(f, 14, 226).any(axis=1)


def _sat_rows(values: np.ndarray) -> np.ndarray:
    """(n, k) per-satellite fields as n*k rows, message by message."""
    return np.asarray(values).reshape(-1)


# --- MT 1: PRN mask (A.4.4.2) -------------------------------------------------------------------
def _mask(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    bits = bit_array(f, 14, 224)
    row, col = np.nonzero(bits)
    position = np.cumsum(bits, axis=1)[row, col]
    system, sv = _slot_code(col + 1)
    return pl.DataFrame(
        {
            "time": _time(t[row]),
            "geo": _i16(geo[row]),
            "iodp": _u8(bitfield(f, 224, 2)[row]),
            "position": _i16(position),
            "slot": _i16(col + 1),
            "system": _u8(system).replace_strict(dict(enumerate(SYSTEMS)), return_dtype=pl.Enum(SYSTEMS)),
            "sv": _i16(sv),
        }
    )


# --- MT 2-5 (and MT 0 as 2), MT 24: fast corrections (A.4.4.3) --------------------------------------
def _fast_rows(
    t: np.ndarray, geo: np.ndarray, mt: np.ndarray, iodp: np.ndarray, iodf: np.ndarray,
    position: np.ndarray, prc: np.ndarray, udrei: np.ndarray,
) -> pl.DataFrame:  # fmt: skip
    k = position.shape[1]
    keep = (position <= 51).reshape(-1)
    udrei = udrei.reshape(-1)[keep]
    return pl.DataFrame(
        {
            "time": _time(np.repeat(t, k)[keep]),
            "geo": _i16(np.repeat(geo, k)[keep]),
            "mt": _u8(np.repeat(mt, k)[keep]),
            "iodp": _u8(np.repeat(iodp, k)[keep]),
            "iodf": _u8(np.repeat(iodf, k)[keep]),
            "position": _i16(position.reshape(-1)[keep]),
            "prc": prc.reshape(-1)[keep],
            "udrei": _u8(udrei),
            "sigma2_udre": _lookup(SIGMA2_UDRE, udrei),
        }
    )


def _fast(t: np.ndarray, geo: np.ndarray, f: np.ndarray, mt: np.ndarray) -> pl.DataFrame:
    i = np.arange(13)
    block = np.where(mt == 0, 0, mt.astype(np.int64) - 2)
    return _fast_rows(
        t, geo, mt, bitfield(f, 16, 2), bitfield(f, 14, 2),
        13 * block[:, None] + i + 1,
        bitfield(f, 18 + 12 * i, 12, signed=True) * 0.125,
        bitfield(f, 174 + 4 * i, 4),
    )  # fmt: skip


def _fast24(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    i = np.arange(6)
    return _fast_rows(
        t, geo, np.full(len(t), 24), bitfield(f, 110, 2), bitfield(f, 114, 2),
        13 * bitfield(f, 112, 2)[:, None] + i + 1,
        bitfield(f, 14 + 12 * i, 12, signed=True) * 0.125,
        bitfield(f, 86 + 4 * i, 4),
    )  # fmt: skip


# --- MT 6: integrity information ------------------------------------------------------------------
def _integrity(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    i = np.arange(51)
    iodf = bitfield(f, 14 + 2 * np.arange(4), 2)[:, i // 13]
    udrei = _sat_rows(bitfield(f, 22 + 4 * i, 4))
    return _table(
        t, geo,
        {
            "position": _i16(np.tile(i + 1, len(t))),
            "iodf": _u8(_sat_rows(iodf)),
            "udrei": _u8(udrei),
            "sigma2_udre": _lookup(SIGMA2_UDRE, udrei),
        },
        repeat=51,
    )  # fmt: skip


# --- MT 7: fast-correction degradation factors (A.4.4.5) -----------------------------------------
def _fc_degradation(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    i = np.arange(51)
    ai = _sat_rows(bitfield(f, 22 + 4 * i, 4))
    return _table(
        t, geo,
        {
            "iodp": _u8(np.repeat(bitfield(f, 18, 2), 51)),
            "tlat": pl.Series(np.repeat(bitfield(f, 14, 4), 51), dtype=pl.Float64),
            "position": _i16(np.tile(i + 1, len(t))),
            "ai_index": _u8(ai),
            "ai": _lookup(AI, ai),
        },
        repeat=51,
    )  # fmt: skip


# --- MT 9: GEO navigation message (A.4.4.11) ------------------------------------------------------
def _geo_nav(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    tod = bitfield(f, 22, 13) * 16
    s = lambda a, w, lsb: bitfield(f, a, w, signed=True) * lsb  # noqa: E731
    return _table(
        t, geo,
        {
            "iodn": _u8(bitfield(f, 14, 8)),
            "t0_tod": tod.astype(np.float64),
            "t0": _tod_to_time(t, tod),
            "ura": _u8(bitfield(f, 35, 4)),
            "x": s(39, 30, 0.08), "y": s(69, 30, 0.08), "z": s(99, 25, 0.4),
            "vx": s(124, 17, 0.000625), "vy": s(141, 17, 0.000625), "vz": s(158, 18, 0.004),
            "ax": s(176, 10, 0.0000125), "ay": s(186, 10, 0.0000125), "az": s(196, 10, 0.0000625),
            "af0": s(206, 12, 2.0**-31), "af1": s(218, 8, 2.0**-40),
        },
    )  # fmt: skip


# --- MT 10: degradation parameters (A.4.4.6) -------------------------------------------------------
_MT10 = (  # name, first bit, width, LSB
    ("brrc", 14, 10, 0.002), ("cltc_lsb", 24, 10, 0.002), ("cltc_v1", 34, 10, 0.00005),
    ("iltc_v1", 44, 9, 1.0), ("cltc_v0", 53, 10, 0.002), ("iltc_v0", 63, 9, 1.0),
    ("cgeo_lsb", 72, 10, 0.0005), ("cgeo_v", 82, 10, 0.00005), ("igeo", 92, 9, 1.0),
    ("cer", 101, 6, 0.5), ("ciono_step", 107, 10, 0.001), ("iiono", 117, 9, 1.0),
    ("ciono_ramp", 126, 10, 0.000005), ("rss_udre", 136, 1, 1.0), ("rss_iono", 137, 1, 1.0),
    ("ccovariance", 138, 7, 0.1),
)  # fmt: skip


def _degradation(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    cols: dict[str, object] = {name: bitfield(f, a, w) * lsb for name, a, w, lsb in _MT10}
    cols["rss_udre"] = bitfield(f, 136, 1).astype(bool)
    cols["rss_iono"] = bitfield(f, 137, 1).astype(bool)
    return _table(t, geo, cols)


# --- MT 12: SBAS network time / UTC offset parameters ---------------------------------------------
def _network_time(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    u = lambda a, w: _i32(bitfield(f, a, w))  # noqa: E731
    return _table(
        t, geo,
        {
            "a1": bitfield(f, 14, 24, signed=True) * 2.0**-50,
            "a0": bitfield(f, 38, 32, signed=True) * 2.0**-30,
            "t0t": bitfield(f, 70, 8) * 4096.0,
            "wnt": u(78, 8),
            "dt_ls": _i32(bitfield(f, 86, 8, signed=True)),
            "wn_lsf": u(94, 8),
            "dn": u(102, 8),
            "dt_lsf": _i32(bitfield(f, 110, 8, signed=True)),
            "utc_id": u(118, 3),
            "gps_tow": u(121, 20),
            "gps_week": u(141, 10),
            "glonass_indicator": bitfield(f, 151, 1).astype(bool),
        },
    )  # fmt: skip


# --- MT 17: GEO almanacs (A.4.4.12) ---------------------------------------------------------------
def _geo_almanac(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    a = 14 + 67 * np.arange(3)
    prn = bitfield(f, a + 2, 8)
    row, k = np.nonzero(prn)
    s = lambda off, w, lsb: bitfield(f, a + off, w, signed=True)[row, k] * lsb  # noqa: E731
    health = bitfield(f, a + 10, 8)[row, k]
    tod = bitfield(f, 215, 11)[row] * 64
    return pl.DataFrame(
        {
            "time": _time(t[row]),
            "geo": _i16(geo[row]),
            "data_id": _u8(bitfield(f, a, 2)[row, k]),
            "prn": _i16(prn[row, k]),
            "provider": _u8(health >> 4),
            "health": _u8(health & 0xF),
            "x": s(18, 15, 2600.0), "y": s(33, 15, 2600.0), "z": s(48, 9, 26000.0),
            "vx": s(57, 3, 10.0), "vy": s(60, 3, 10.0), "vz": s(63, 4, 60.0),
            "t0_tod": tod.astype(np.float64),
            "t0": _tod_to_time(t[row], tod),
        }
    )  # fmt: skip


# --- MT 18: IGP mask ----------------------------------------------------------------------------------
def _igp_mask(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    bits = bit_array(f, 24, 225)
    band = bitfield(f, 18, 4)
    row, col = np.nonzero(bits)
    lat = np.full(len(row), np.nan)
    lon = np.full(len(row), np.nan)
    for b in np.unique(band[row]).tolist():
        if b >= N_BANDS:
            continue
        sel = (band[row] == b) & (col < BAND_SIZES[b])
        blat, blon = band_igps(b)
        lat[sel], lon[sel] = blat[col[sel]], blon[col[sel]]
    return pl.DataFrame(
        {
            "time": _time(t[row]),
            "geo": _i16(geo[row]),
            "n_bands": _u8(bitfield(f, 14, 4)[row]),
            "band": _u8(band[row]),
            "iodi": _u8(bitfield(f, 22, 2)[row]),
            "bit": _i16(col + 1),
            "igp": _i16(np.cumsum(bits, axis=1)[row, col]),
            "lat": pl.Series(lat, nan_to_null=True),
            "lon": pl.Series(lon, nan_to_null=True),
        }
    )


# --- MT 26: ionospheric delays (A.4.4.10) ---------------------------------------------------------
def _iono(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    k = np.arange(15)
    raw = _sat_rows(bitfield(f, 22 + 13 * k, 9))
    givei = _sat_rows(bitfield(f, 31 + 13 * k, 4))
    block = bitfield(f, 18, 4)
    return _table(
        t, geo,
        {
            "band": _u8(np.repeat(bitfield(f, 14, 4), 15)),
            "block": _u8(np.repeat(block, 15)),
            "iodi": _u8(np.repeat(bitfield(f, 217, 2), 15)),
            "igp": _i16(_sat_rows(15 * block[:, None] + k + 1)),
            "givd": raw * 0.125,
            "givd_dnu": raw == 511,
            "givei": _u8(givei),
            "sigma2_give": _lookup(SIGMA2_GIVE, givei),
        },
        repeat=15,
    )  # fmt: skip


# --- MT 24/25: long-term corrections (A.4.4.7; DO-229D Tables) -------------------------
def _half(f: np.ndarray, p: int) -> dict[str, np.ndarray]:
    """The 106-bit half message at bit ``p``, as (n, 2) arrays (second column unused for vc 1)."""
    vc = bitfield(f, p, 1)
    s = lambda a, w, lsb: bitfield(f, a, w, signed=True) * lsb  # noqa: E731
    sub = p + 1 + 51 * np.arange(2)  # velocity code 0: two satellites of 51 bits
    v0 = {
        "position": bitfield(f, sub, 6), "iode": bitfield(f, sub + 6, 8),
        "dx": s(sub + 14, 9, 0.125), "dy": s(sub + 23, 9, 0.125), "dz": s(sub + 32, 9, 0.125),
        "daf0": s(sub + 41, 10, 2.0**-31),
    }  # fmt: skip
    one = lambda x: np.column_stack([x, np.zeros_like(x)])  # noqa: E731
    v1 = {
        "position": one(bitfield(f, p + 1, 6)), "iode": one(bitfield(f, p + 7, 8)),
        "dx": one(s(p + 15, 11, 0.125)), "dy": one(s(p + 26, 11, 0.125)), "dz": one(s(p + 37, 11, 0.125)),
        "daf0": one(s(p + 48, 11, 2.0**-31)),
        "ddx": one(s(p + 59, 8, 2.0**-11)), "ddy": one(s(p + 67, 8, 2.0**-11)),
        "ddz": one(s(p + 75, 8, 2.0**-11)), "daf1": one(s(p + 83, 8, 2.0**-39)),
        "t0_tod": one(bitfield(f, p + 91, 13) * 16),
    }  # fmt: skip
    is1 = (vc == 1)[:, None]
    out = {key: np.where(is1, v1[key], v0[key]) for key in v0}
    for key in ("ddx", "ddy", "ddz", "daf1"):
        out[key] = np.where(is1, v1[key], 0.0)
    out["t0_tod"] = np.where(is1, v1["t0_tod"], -1)
    out["velocity_code"] = np.repeat(vc[:, None], 2, axis=1)
    out["iodp"] = np.repeat(
        np.where(vc == 1, bitfield(f, p + 104, 2), bitfield(f, p + 103, 2))[:, None], 2, axis=1
    )
    return out


_LT_VALUES = ("dx", "dy", "dz", "daf0", "ddx", "ddy", "ddz", "daf1")


def _long_term(t: np.ndarray, geo: np.ndarray, f: np.ndarray, mt: np.ndarray) -> pl.DataFrame:
    parts = []
    for half, p in ((0, 14), (1, 120)):
        sel = np.flatnonzero(mt == 25) if half == 0 else np.arange(len(t))
        h = _half(f[sel], p)
        row, k = np.nonzero(h["position"])  # mask position 0: no satellite in this slot
        tod = h["t0_tod"][row, k]
        tsel = t[sel][row]
        parts.append(
            pl.DataFrame(
                {
                    "time": _time(tsel),
                    "geo": _i16(geo[sel][row]),
                    "mt": _u8(mt[sel][row]),
                    "half": _u8(np.full(len(row), half)),
                    "velocity_code": _u8(h["velocity_code"][row, k]),
                    "iodp": _u8(h["iodp"][row, k]),
                    "position": _i16(h["position"][row, k]),
                    "iode": _i16(h["iode"][row, k]),
                    **{key: h[key][row, k].astype(np.float64) for key in _LT_VALUES},
                    "t0_tod": pl.Series(np.where(tod < 0, np.nan, tod), nan_to_null=True),
                    "t0": _tod_to_time(tsel, np.maximum(tod, 0), valid=tod >= 0),
                }
            )
        )
    return pl.concat(parts).sort("time", maintain_order=True)


# --- MT 27: SBAS service message -----------------------------------------------------------------------
def _service(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    u = lambda a, w: _u8(bitfield(f, a, w))  # noqa: E731
    din, dout = bitfield(f, 28, 4), bitfield(f, 32, 4)
    return _table(
        t, geo,
        {
            "iods": u(14, 3),
            "n_messages": _u8(bitfield(f, 17, 3) + 1),
            "message_number": _u8(bitfield(f, 20, 3) + 1),
            "n_regions": u(23, 3),
            "priority": u(26, 2),
            "dudrei_in": _u8(din),
            "dudrei_out": _u8(dout),
            "dudre_in": np.asarray(DELTA_UDRE)[din],
            "dudre_out": np.asarray(DELTA_UDRE)[dout],
        },
    )  # fmt: skip


def _service_regions(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    a = 36 + 35 * np.arange(5)
    row, r = np.nonzero(np.arange(5) < bitfield(f, 23, 3)[:, None])
    s = lambda off, w: _i16(bitfield(f, a + off, w, signed=True)[row, r])  # noqa: E731
    return pl.DataFrame(
        {
            "time": _time(t[row]),
            "geo": _i16(geo[row]),
            "iods": _u8(bitfield(f, 14, 3)[row]),
            "message_number": _u8(bitfield(f, 20, 3)[row] + 1),
            "region": _u8(r + 1),
            "lat1": s(0, 8), "lon1": s(8, 9), "lat2": s(17, 8), "lon2": s(25, 9),
            "square": bitfield(f, a + 34, 1)[row, r].astype(bool),
        }
    )  # fmt: skip


# --- MT 28: clock-ephemeris covariance (A.4.4.16) -----------------------------------------------------
_E = (("r11", 9, False), ("r22", 9, False), ("r33", 9, False), ("r44", 9, False),
      ("r12", 10, True), ("r13", 10, True), ("r14", 10, True), ("r23", 10, True),
      ("r24", 10, True), ("r34", 10, True))  # fmt: skip


def _covariance(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    a = 16 + 105 * np.arange(2)
    position = bitfield(f, a, 6)
    row, k = np.nonzero(position)
    sexp = bitfield(f, a + 6, 3)[row, k]
    scale = 2.0 ** (sexp - 5)
    cols: dict[str, object] = {}
    off = 9
    for name, width, signed in _E:
        cols[name] = bitfield(f, a + off, width, signed=signed)[row, k] * scale
        off += width
    return pl.DataFrame(
        {
            "time": _time(t[row]),
            "geo": _i16(geo[row]),
            "iodp": _u8(bitfield(f, 14, 2)[row]),
            "position": _i16(position[row, k]),
            "scale_exp": _u8(sexp),
        }
        | cols
    )


def _dont_use(t: np.ndarray, geo: np.ndarray, f: np.ndarray) -> pl.DataFrame:
    return _table(t, geo, {"all_zero": _all_zero_body(f)})


#: Tables built from one message type each: name -> (types, decoder).
_ONE_TYPE = {
    "dont_use": ((0,), _dont_use),
    "mask": ((1,), _mask),
    "integrity": ((6,), _integrity),
    "fc_degradation": ((7,), _fc_degradation),
    "geo_nav": ((9,), _geo_nav),
    "degradation": ((10,), _degradation),
    "network_time": ((12,), _network_time),
    "geo_almanac": ((17,), _geo_almanac),
    "igp_mask": ((18,), _igp_mask),
    "iono": ((26,), _iono),
    "service": ((27,), _service),
    "service_regions": ((27,), _service_regions),
    "covariance": ((28,), _covariance),
}
