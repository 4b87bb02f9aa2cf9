"""Reader for u-blox UBX binary logs: protection levels (UBX-NAV-PL) and positions (NAV-PVT, NAV-HPPOSLLH).

Frames are found and checked here (sync ``0xB5 0x62``, class, id, little-endian length, payload,
8-bit Fletcher checksum over class..payload) so that every corrupt frame is counted with its
byte offset and the scan resynchronises on the next sync word. The four messages used are
decoded by :mod:`pyubx2` (``UBXReader.parse``), whose definitions give field names and scaling.
Message layouts and semantics: u-blox F9 / M10 interface descriptions [1]_ [2]_.
"""

from __future__ import annotations

import datetime as dt
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, TextIO

import numpy as np
import polars as pl
from pyubx2 import GET, VALNONE, UBXReader
from pyubx2.exceptions import UBXMessageError, UBXParseError, UBXTypeError

from overbound.io._common import RowLog, errors_against, file_station, finalize_epochs, reference_note
from overbound.io.geodesy import (
    MeanPosition,
    Reference,
)
from overbound.io.gpstime import leap_seconds
from overbound.io.open import read_bytes, source_name
from overbound.io.schema import InputError, ReadReport

__all__ = ["PL_FRAMES", "read_ubx"]

_SYNC = b"\xb5\x62"
_HEADER = 6  # sync (2), class, id, length (2)
_NAV = 0x01
#: (class, id) -> name, and the fixed payload length of each message used.
_WANTED = {
    (_NAV, 0x62): ("NAV-PL", 52),
    (_NAV, 0x07): ("NAV-PVT", 92),
    (_NAV, 0x14): ("NAV-HPPOSLLH", 36),
    (_NAV, 0x20): ("NAV-TIMEGPS", 16),
}
#: UBX-NAV-PL ``plPosFrame`` values [1]_.
PL_FRAMES = {
    0: "invalid",
    1: "north-east-down",
    2: "longitudinal-lateral-vertical",
    3: "horizontal semi-major axis, semi-minor axis, vertical",
}
#: UBX-NAV-PVT ``fixType`` names, used for the ``mode`` column.
_FIX_NAMES = {0: "no fix", 1: "DR", 2: "2D", 3: "3D", 4: "GNSS+DR", 5: "time only"}
_CARR = {1: "/RTK-float", 2: "/RTK-fixed"}
_FIX_3D = (3, 4)
_GPS_EPOCH = dt.datetime(1980, 1, 6)
_WEEK_MS = 604_800_000
_KEY = ["seg", "iTOW"]
_NO_PL = "no UBX-NAV-PL messages (protection levels); enable NAV-PL output on the receiver"


@dataclass(frozen=True, slots=True)
class _Frame:
    offset: int
    name: str
    raw: bytes


def read_ubx(
    source: str | Path | TextIO | BinaryIO,
    *,
    reference: Reference | None = None,
    station: str | None = None,
    strict: bool = False,
) -> tuple[pl.DataFrame, ReadReport]:
    """Read a u-blox UBX log into the epoch table, one row per UBX-NAV-PL message.

    Parameters
    ----------
    source : UBX log (path or binary stream, plain or gzip).
    reference : true antenna position (or ``MEAN_POSITION``); the errors are the NAV-PVT /
        NAV-HPPOSLLH positions minus this point in its local east-north-up frame. None: errors
        unknown (NaN, ``truth`` false), the protection levels analysed alone.
    station : station name; by default the file name up to its first dot.
    strict : raise on the first corrupt frame instead of counting it.

    Returns
    -------
    (table, report) : the epoch table with ``east``, ``north``, ``nsv`` (NAV-PVT ``numSV``),
        ``mode`` (NAV-PVT ``fixType``, plus ``/DGNSS``, ``/RTK-float`` or ``/RTK-fixed``) and
        ``alert`` (PL invalid or no 3D fix), and its :class:`~overbound.io.schema.ReadReport`.
        ``rows_read`` counts the NAV-PL messages (the epochs) plus the frames rejected whole
        (corrupt, truncated or undecodable, of any class); the notes count frames by class.

    Raises
    ------
    InputError
        No NAV-PL message; no GPS week anywhere in the log; with
        ``strict``, a corrupt or truncated frame (``file.ubx:@<byte offset>: bad checksum ...``).

    Notes
    -----
    Steps:

    1. Scan frames. A frame whose checksum fails is counted (``bad_checksum``) and skipped;
       when its end is not followed by a sync word its length is not trusted and the scan
       resumes two bytes after its sync. A frame running past the end of the data is counted
       as ``truncated_frame``. Bytes outside frames (NMEA, RTCM) are skipped and noted.
    2. Decode NAV-PL, NAV-PVT, NAV-HPPOSLLH and NAV-TIMEGPS with pyubx2. Messages of one
       navigation epoch share ``iTOW`` (GPS time of week, ms); a drop of ``iTOW`` by more than
       half a week starts a new week, so the key is (week segment, ``iTOW``).
    3. Epochs are the NAV-PL messages. Position: NAV-HPPOSLLH at the same key when present
       and ``invalidLlh`` is 0 (``lat + latHp``: 1e-9 deg; ``height + heightHp``: 0.1 mm),
       else NAV-PVT (1e-7 deg, mm). ``height`` is above the ellipsoid. The fix is usable when
       NAV-PVT has ``gnssFixOK`` = 1 and ``fixType`` 3 (3D) or 4 (GNSS + dead reckoning); with
       no NAV-PVT, a valid NAV-HPPOSLLH counts as a fix.
    4. Protection levels from ``plPos1..3`` (mm) [1]_: VPL = ``plPos3`` (down or vertical axis)
       in every frame. HPL is the radius of the smallest circle sure to hold the horizontal PL
       region: ``plPos1`` (the semi-major axis) in frame 3, and ``hypot(plPos1, plPos2)`` in
       frames 1 and 2 (north/east or along/across-track), whose per-axis bounds define a box,
       not an ellipse. u-blox specifies the target misleading-information risk per axis [2]_.
    5. Time: GPS week from NAV-TIMEGPS (``weekValid``) at the same key, else from NAV-PVT's UTC
       date and time (``validDate`` and ``validTime``) plus GPS-UTC (NAV-TIMEGPS ``leapS`` when
       some message has ``leapSValid``, else :data:`GPS_UTC_LEAP_SECONDS`), rounded to the
       week that holds ``iTOW``; else carried from the nearest dated epoch. The time within
       the week is always ``iTOW``.

    Epochs whose PL is invalid (``plPosValid`` = 0 or ``plPosFrame`` = 0) or that have no
    usable fix are kept as no-solution epochs (NaN errors and PLs, ``alert`` true) and
    counted in the notes. A NAV-PL without a position message at its key keeps its PLs and
    NaN errors, so :func:`~overbound.io._common.finalize_epochs` invalidates it as
    ``nan_error``. Position messages without a NAV-PL are not epochs of the table (the PL
    stream defines the epochs; the receiver may output positions faster) and are counted in
    the notes.

    References
    ----------
    .. [1] u-blox, "u-blox F9 interface description" (HPG / HPS firmware 1.3x): UBX frame
       structure and checksum; UBX-NAV-PL, UBX-NAV-PVT, UBX-NAV-HPPOSLLH, UBX-NAV-TIMEGPS.
    .. [2] u-blox, "ZED-F9R Integration manual", UBX-20039643 R06, section 3.5 "Protection
       level"; "SAM-M10Q Integration manual", UBX-22020019 R01, section 2.11 (TMIR per axis).

    Examples
    --------
    >>> import io
    >>> from pyubx2 import GET, UBXMessage
    >>> msgs = [
    ...     UBXMessage("NAV", "NAV-TIMEGPS", GET, iTOW=86400000, week=2036, weekValid=1, towValid=1),
    ...     UBXMessage("NAV", "NAV-PVT", GET, iTOW=86400000, fixType=3, gnssFixOk=1, numSV=9,
    ...                lat=43.56071, lon=1.4809, height=207000),
    ...     UBXMessage("NAV", "NAV-PL", GET, iTOW=86400000, plPosValid=1, plPosFrame=1,
    ...                plPos1=3000, plPos2=4000, plPos3=9000),
    ... ]
    >>> log = io.BytesIO(b"".join(m.serialize() for m in msgs))
    >>> table, report = read_ubx(log, reference=Reference(43.5607, 1.4809, 207.0))
    >>> row = table.row(0, named=True)
    >>> row["time"], round(row["north"], 2), row["hpl"], row["vpl"], row["mode"]
    (datetime.datetime(2019, 1, 14, 0, 0), 1.11, 5.0, 9.0, '3D')
    """
    name = source_name(source)
    data = read_bytes(source)
    log = RowLog(name, strict=strict)
    frames, counts, skipped = _scan(data, log)
    decoded = _decode(frames, log)
    if not decoded["NAV-PL"]:
        raise InputError(name, _NO_PL)
    # Rows are epochs (NAV-PL messages) plus the frames rejected whole (corrupt, truncated,
    # undecodable), whatever their class: kept + rejected = read. Other frames are noted.
    log.rows_read = len(decoded["NAV-PL"]) + log.n_rejected
    tables = _tables(decoded)
    epochs, notes = _epochs(tables, reference, name)
    stn = file_station(station, name)
    epochs = epochs.with_columns(pl.lit(stn).alias("station"))
    frame_note = "frames: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
    if skipped:
        frame_note += f"; {skipped} bytes outside UBX frames skipped"
    truth = reference is not None
    return finalize_epochs(epochs, log, format="ubx", notes=(frame_note, *notes), errors=truth)


def _reject(log: RowLog, offset: int, reason: str) -> None:
    """Count a corrupt frame; with ``strict`` raise ``file:@offset: reason``."""
    if log.strict:
        err = InputError(f"{log.source}:@{offset}", reason)
        err.source = log.source
        raise err
    log.reject(offset, reason)
    if log.first_line == offset and not log.first_bad.startswith("@"):
        log.first_bad = f"@{offset}: {reason}"


_WEIGHTS: dict[int, np.ndarray] = {}


def _checksum_ok(data: bytes, start: int, end: int) -> bool:
    """8-bit Fletcher over ``data[start:end]`` (class..payload) equals the two bytes at ``end``."""
    n = end - start
    b = np.frombuffer(data, dtype=np.uint8, count=n, offset=start).astype(np.int64)
    w = _WEIGHTS.get(n)
    if w is None:
        w = _WEIGHTS.setdefault(n, np.arange(n, 0, -1, dtype=np.int64))
    return (int(b.sum()) & 0xFF) == data[end] and (int(w @ b) & 0xFF) == data[end + 1]


def _frame_name(cls: int, msg_id: int) -> str:
    known = _WANTED.get((cls, msg_id))
    return known[0] if known else f"0x{cls:02x} 0x{msg_id:02x}"


def _scan(data: bytes, log: RowLog) -> tuple[list[_Frame], Counter, int]:
    """Frames of the wanted messages, frame counts by name, and bytes outside frames."""
    frames: list[_Frame] = []
    counts: Counter = Counter()
    pos = skipped = 0
    n = len(data)
    while True:
        i = data.find(_SYNC, pos)
        if i < 0:
            skipped += n - pos
            break
        skipped += i - pos
        if i + _HEADER > n:
            counts["corrupt"] += 1
            _reject(log, i, f"truncated frame: {n - i} bytes left, header needs {_HEADER}")
            break
        cls, msg_id = data[i + 2], data[i + 3]
        length = int.from_bytes(data[i + 4 : i + 6], "little")
        end = i + _HEADER + length  # checksum at end, end + 1
        what = _frame_name(cls, msg_id)
        if end + 2 > n:
            counts["corrupt"] += 1
            _reject(
                log, i, f"truncated frame: {what} length {length} needs {end + 2 - i} bytes, {n - i} left"
            )
            pos = i + 2
            continue
        if not _checksum_ok(data, i + 2, end):
            counts["corrupt"] += 1
            _reject(log, i, f"bad checksum: {what}, length {length}")
            pos = end + 2 if (end + 2 == n or data.startswith(_SYNC, end + 2)) else i + 2
            continue
        counts[what if (cls, msg_id) in _WANTED else "other"] += 1
        if (cls, msg_id) in _WANTED:
            frames.append(_Frame(i, what, data[i : end + 2]))
        pos = end + 2
    return frames, counts, skipped


def _decode(frames: list[_Frame], log: RowLog) -> dict[str, list[tuple[int, object]]]:
    """Parse the wanted frames with pyubx2 (checksums already verified)."""
    out: dict[str, list[tuple[int, object]]] = {name: [] for name, _ in _WANTED.values()}
    expected = dict(_WANTED.values())
    for f in frames:
        length = len(f.raw) - _HEADER - 2
        if length != expected[f.name]:
            _reject(
                log, f.offset, f"bad length: {f.name} payload {length} bytes, expected {expected[f.name]}"
            )
            continue
        try:
            msg = UBXReader.parse(f.raw, validate=VALNONE, msgmode=GET)
        except (UBXParseError, UBXMessageError, UBXTypeError) as exc:
            _reject(log, f.offset, f"undecodable: {f.name}: {exc}")
            continue
        out[f.name].append((f.offset, msg))
    return out


_FIELDS = {
    "NAV-PL": ("iTOW", "plPosValid", "plPosFrame", "plPos1", "plPos2", "plPos3"),
    "NAV-PVT": (
        "iTOW",
        "year",
        "month",
        "day",
        "hour",
        "min",
        "second",
        "nano",
        "validDate",
        "validTime",
        "fixType",
        "gnssFixOk",
        "diffSoln",
        "carrSoln",
        "numSV",
        "lat",
        "lon",
        "height",
    ),
    "NAV-HPPOSLLH": ("iTOW", "invalidLlh", "lat", "lon", "height"),
    "NAV-TIMEGPS": ("iTOW", "week", "leapS", "towValid", "weekValid", "leapSValid"),
}
_FLOAT_FIELDS = ("lat", "lon", "height")


def _tables(decoded: dict[str, list[tuple[int, object]]]) -> dict[str, pl.DataFrame]:
    """One DataFrame per message, with the (segment, iTOW) key of step 2."""
    order = sorted((off, msg.iTOW) for rows in decoded.values() for off, msg in rows)
    itow = np.array([t for _, t in order], dtype=np.int64)
    seg = np.concatenate([[0], np.cumsum(np.diff(itow) < -_WEEK_MS // 2)]) if itow.size else itow
    seg_of = {off: int(s) for (off, _), s in zip(order, seg, strict=True)}
    tables = {}
    for name, rows in decoded.items():
        cols = _FIELDS[name]
        schema = {"_line": pl.Int64, "seg": pl.Int64} | {
            c: pl.Float64 if c in _FLOAT_FIELDS else pl.Int64 for c in cols
        }
        recs = [(off, seg_of[off], *(getattr(m, c) for c in cols)) for off, m in rows]
        tables[name] = pl.DataFrame(recs, schema=schema, orient="row")
    return tables


def _first(df: pl.DataFrame) -> pl.DataFrame:
    """One message per (segment, iTOW): the first in the file."""
    return df.unique(subset=_KEY, keep="first", maintain_order=True).drop("_line")


def _epochs(
    tables: dict[str, pl.DataFrame], reference: Reference | MeanPosition, name: str
) -> tuple[pl.DataFrame, list[str]]:
    notes: list[str] = []
    pvt, hp = tables["NAV-PVT"], tables["NAV-HPPOSLLH"]
    epochs = tables["NAV-PL"]
    pl_keys = epochs.select(_KEY).unique()
    for msg, df in (("NAV-PVT", pvt), ("NAV-HPPOSLLH", hp)):
        orphans = df.select(_KEY).unique().join(pl_keys, on=_KEY, how="anti").height
        if orphans:
            notes.append(f"{orphans} {msg} epochs without a NAV-PL: not in the table")
        repeats = df.height - df.select(_KEY).n_unique()
        if repeats:
            notes.append(f"{repeats} repeated {msg} messages (same iTOW): the first one used")
    epochs = epochs.join(
        _first(pvt).rename({"lat": "pvt_lat", "lon": "pvt_lon", "height": "pvt_h"}),
        on=_KEY,
        how="left",
        maintain_order="left",
    ).join(
        _first(hp).rename({"lat": "hp_lat", "lon": "hp_lon", "height": "hp_h"}),
        on=_KEY,
        how="left",
        maintain_order="left",
    )
    time, time_note = _time(epochs, tables["NAV-TIMEGPS"], name)
    notes.append(time_note)

    use_hp = (pl.col("hp_lat").is_not_null() & (pl.col("invalidLlh") == 0)).fill_null(False)
    has_pvt = pl.col("pvt_lat").is_not_null()
    fix = (
        pl.when(has_pvt)
        .then((pl.col("gnssFixOk") == 1) & pl.col("fixType").is_in(list(_FIX_3D)))
        .otherwise(use_hp)
    )
    epochs = epochs.with_columns(
        pl.when(use_hp).then(pl.col("hp_lat")).otherwise(pl.col("pvt_lat")).alias("lat"),
        pl.when(use_hp).then(pl.col("hp_lon")).otherwise(pl.col("pvt_lon")).alias("lon"),
        (pl.when(use_hp).then(pl.col("hp_h")).otherwise(pl.col("pvt_h")) / 1000.0).alias("h"),
        fix.fill_null(False).alias("fix"),
        ((pl.col("plPosValid") == 1) & pl.col("plPosFrame").is_in([1, 2, 3])).alias("pl_valid"),
        (has_pvt | use_hp).alias("positioned"),
        use_hp.alias("use_hp"),
    )
    p1, p2, p3 = (epochs[c].cast(pl.Float64).to_numpy() / 1000.0 for c in ("plPos1", "plPos2", "plPos3"))
    hpl = np.where(epochs["plPosFrame"].to_numpy() == 3, p1, np.hypot(p1, p2))
    pl_valid = epochs["pl_valid"].to_numpy()
    positioned = epochs["positioned"].to_numpy()
    fixed = epochs["fix"].to_numpy()
    usable = pl_valid & (fixed | ~positioned)
    llh = [epochs[c].fill_null(np.nan).to_numpy() for c in ("lat", "lon", "h")]
    e, n, u, used = errors_against(reference, llh, usable & positioned, name)
    nan = np.full(epochs.height, np.nan)
    out = (
        epochs.select(
            "_line",
            "numSV",
            _mode().alias("mode"),
        )
        .with_columns(
            time,
            pl.Series("east", np.where(usable, e, nan)),
            pl.Series("north", np.where(usable, n, nan)),
            pl.Series("hpe", np.where(usable, np.hypot(e, n), nan)),
            pl.Series("vpe", np.where(usable, u, nan)),
            pl.Series("hpl", np.where(usable, hpl, nan)),
            pl.Series("vpl", np.where(usable, p3, nan)),
            pl.col("numSV").alias("nsv"),
            pl.Series("alert", ~usable),
        )
        .drop("numSV")
    )
    n_hp = int(epochs["use_hp"].sum())
    notes.append(
        f"positions: NAV-HPPOSLLH for {n_hp} epochs, NAV-PVT for {int(positioned.sum()) - n_hp}; "
        + reference_note(reference, used)
    )
    frames = Counter(epochs.filter(pl.col("pl_valid"))["plPosFrame"].to_list())
    if frames:
        notes.append(
            "HPL from plPosFrame "
            + ", ".join(f"{k} ({PL_FRAMES[k]}): {v} epochs" for k, v in sorted(frames.items()))
        )
    counts = (
        (
            int((~pl_valid).sum()),
            "epochs with invalid PL (plPosValid=0 or plPosFrame=0): kept as no-solution",
        ),
        (
            int((pl_valid & positioned & ~fixed).sum()),
            "epochs without a 3D fix (gnssFixOK=0 or fixType not 3/4): kept as no-solution",
        ),
        (int((~positioned).sum()), "NAV-PL epochs without NAV-PVT/NAV-HPPOSLLH at the same iTOW: errors NaN"),
    )
    notes.extend(f"{k} {what}" for k, what in counts if k)
    return out, notes


def _mode() -> pl.Expr:
    """``fixType`` name, plus ``/DGNSS`` (``diffSoln``), ``/RTK-float`` or ``/RTK-fixed`` (``carrSoln``)."""
    base = pl.col("fixType").replace_strict(_FIX_NAMES, default="unknown", return_dtype=pl.String)
    diff = pl.when(pl.col("diffSoln") == 1).then(pl.lit("/DGNSS")).otherwise(pl.lit(""))
    carr = pl.col("carrSoln").replace_strict(_CARR, default="", return_dtype=pl.String)
    return pl.concat_str([base, diff, carr])


def _leap_from_table(days: np.ndarray) -> np.ndarray:
    """GPS-UTC (s) on each UTC day (``datetime64[D]``) from :data:`GPS_UTC_LEAP_SECONDS`."""
    return leap_seconds(days.astype("datetime64[us]").astype(np.int64))


def _time(epochs: pl.DataFrame, tg: pl.DataFrame, name: str) -> tuple[pl.Series, str]:
    """GPS time of each epoch (step 5): week from TIMEGPS, PVT UTC or neighbours; iTOW within it."""
    good_tg = _first(tg.filter((pl.col("weekValid") == 1) & (pl.col("towValid") == 1)))
    e = epochs.select(
        *_KEY,
        pl.when((pl.col("validDate") == 1) & (pl.col("validTime") == 1))
        .then(pl.datetime("year", "month", "day", "hour", "min", "second", time_unit="us"))
        .alias("utc"),
        "nano",
    ).join(good_tg.select(*_KEY, "week"), on=_KEY, how="left", maintain_order="left")
    itow = e["iTOW"].to_numpy().astype(np.int64)
    seg = e["seg"].to_numpy()
    week = e["week"].fill_null(-1).to_numpy().astype(np.int64)
    source = np.where(week >= 0, 1, 0)  # 1 TIMEGPS, 2 PVT UTC, 3 carried
    leaps = tg.filter(pl.col("leapSValid") == 1)["leapS"]
    utc = e["utc"].to_numpy()
    has_utc = ~np.isnat(utc)
    leap_note = ""
    need = (week < 0) & has_utc
    if need.any():
        if len(leaps):
            leap = np.full(len(e), int(leaps[0]))
            leap_note = f"GPS-UTC {int(leaps[0])} s from NAV-TIMEGPS leapS"
        else:
            leap = _leap_from_table(utc.astype("datetime64[D]"))
            values = "/".join(str(v) for v in sorted(set(leap[need].tolist())))
            leap_note = f"GPS-UTC {values} s from the IERS Bulletin C table"
        utc_ms = (utc - np.datetime64(_GPS_EPOCH, "us")).astype("timedelta64[us]").astype(np.float64) / 1000
        utc_ms += e["nano"].fill_null(0).to_numpy() / 1e6
        from_utc = np.round((utc_ms + leap * 1000 - itow) / _WEEK_MS)
        week[need] = from_utc[need].astype(np.int64)
        source[need] = 2
    known = week >= 0
    if not known.any():
        raise InputError(
            name,
            "no GPS week for the NAV-PL epochs: no NAV-TIMEGPS with a valid week and no NAV-PVT with a valid "
            "UTC date at the same iTOW",
        )
    if not known.all():
        # Carry from the nearest dated epoch, one week per week segment between them.
        m = len(e)
        prev = np.maximum.accumulate(np.where(known, np.arange(m), -1))
        nxt = np.minimum.accumulate(np.where(known, np.arange(m), m)[::-1])[::-1]
        anchor = np.where(prev >= 0, prev, nxt)
        unknown = ~known
        week[unknown] = week[anchor[unknown]] + (seg[unknown] - seg[anchor[unknown]])
        source[unknown] = 3
    gps_us = (week * _WEEK_MS + itow) * 1000
    time = pl.Series("time", np.datetime64(_GPS_EPOCH, "us") + gps_us.astype("timedelta64[us]"))
    parts = [
        f"{int((source == k).sum())} from {what}"
        for k, what in ((1, "NAV-TIMEGPS"), (2, "NAV-PVT UTC date"), (3, "neighbouring epochs"))
        if (source == k).any()
    ]
    note = "GPS week: " + ", ".join(parts) + (f" ({leap_note})" if leap_note else "")
    return time, note
