"""Build the synthetic UBX fixtures of tests/data/ubx/ and their expected values.

Run from the repository root: ``python tests/reference/make_ubx_fixtures.py``. It rewrites
``tests/data/ubx/*.ubx`` (except nothing else) and ``tests/data/ubx/expected.csv``, byte for
byte the same on every run.

The messages are built with pyubx2 (``UBXMessage(..., msgmode=GET).serialize()``), then the
encoded integers are read back with :mod:`struct` at the offsets of the u-blox interface
description, so that the fixture does not depend on pyubx2 alone. The expected errors are
computed here from the *encoded* positions with a closed-form WGS-84 geodetic -> ECEF -> ENU
conversion (not pymap3d, which the reader uses), so they are exact to float precision.

The old real log ``old_ublox_no_navpl.ubx`` is the first frames (cut at a frame boundary, at
most 4096 bytes) of RTKLIB's ``test/data/rcvraw/ubx_20080526.ubx``, as kept in
``shared/data/rtklib-rcvraw-msas-2008-147/``.
"""

from __future__ import annotations

import csv
import datetime as dt
import math
import struct
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import pymap3d
import wgs84  # tests/reference/wgs84.py, beside this script
from pyubx2 import GET, UBXMessage

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "tests" / "data" / "ubx"
OLD_LOG = ROOT.parent / "shared" / "data" / "rtklib-rcvraw-msas-2008-147" / "ubx_20080526.ubx"

#: True antenna position (near Toulouse, the synthetic-obs point of the EGNOS data set).
REF_LAT, REF_LON, REF_H = 43.5607, 1.4809, 207.0
WEEK, TOW0_MS = 2036, 86_400_000  # 2019-01-14 00:00:00 GPST
LEAP = 18  # GPS-UTC in January 2019
GPS_EPOCH = dt.datetime(1980, 1, 6)


@dataclass(frozen=True)
class Epoch:
    """One navigation epoch as the generator encodes it."""

    week: int
    itow: int  # ms
    east: float  # design offsets from the reference, metres
    north: float
    up: float
    pl: tuple[int, int, int]  # plPos1..3, mm
    frame: int = 1
    pl_valid: int = 1
    fix_type: int = 3
    fix_ok: int = 1
    valid_date: int = 1


def design(n: int = 10, *, week: int = WEEK, tow0_ms: int = TOW0_MS, frame: int = 1) -> list[Epoch]:
    out = []
    for k in range(n):
        tow = tow0_ms + 1000 * k
        if tow >= 604_800_000:
            week, tow0_ms, tow = week + 1, tow0_ms - 604_800_000, tow - 604_800_000
        out.append(
            Epoch(
                week,
                tow,
                east=0.5 + 0.113 * k,
                north=-0.3 + 0.071 * k,
                up=1.0 - 0.237 * k,
                pl=(8000 + 111 * k, 5000 + 37 * k, 12000 + 173 * k),
                frame=frame,
            )
        )
    return out


def geodetic(ep: Epoch) -> tuple[float, float, float]:
    lat, lon, h = pymap3d.enu2geodetic(ep.east, ep.north, ep.up, REF_LAT, REF_LON, REF_H)
    return float(lat), float(lon), float(h)


def enu(lat: float, lon: float, h: float) -> tuple[float, float, float]:
    """Closed-form ENU of a geodetic point relative to the reference (:mod:`wgs84`)."""
    return wgs84.enu(lat, lon, h, REF_LAT, REF_LON, REF_H)


def _scaled(n: int, res: float) -> float:
    """A float that pyubx2 (``int(value / res)``, truncating) encodes as exactly ``n``."""
    return (n + math.copysign(0.25, n)) * res if n else 0.0


def _utc(ep: Epoch) -> dt.datetime:
    return GPS_EPOCH + dt.timedelta(weeks=ep.week, milliseconds=ep.itow) - dt.timedelta(seconds=LEAP)


@dataclass(frozen=True)
class Encoded:
    """The integers written for one epoch and the position they stand for."""

    lat_e7: int
    lon_e7: int
    h_mm: int
    lat_e9: int
    lon_e9: int
    h_e4: int  # 0.1 mm


def encode_position(ep: Epoch) -> Encoded:
    lat, lon, h = geodetic(ep)
    return Encoded(
        round(lat * 1e7),
        round(lon * 1e7),
        round(h * 1000),
        round(lat * 1e9),
        round(lon * 1e9),
        round(h * 1e4),
    )


def timegps(ep: Epoch) -> bytes:
    msg = UBXMessage(
        "NAV", "NAV-TIMEGPS", GET, iTOW=ep.itow, fTOW=0, week=ep.week, leapS=LEAP,
        towValid=1, weekValid=1, leapSValid=1, tAcc=20,
    )  # fmt: skip
    raw = msg.serialize()
    assert struct.unpack_from("<IihbB", raw, 6)[:4] == (ep.itow, 0, ep.week, LEAP)
    return raw


def pvt(ep: Epoch, pos: Encoded, num_sv: int) -> bytes:
    t = _utc(ep)
    msg = UBXMessage(
        "NAV", "NAV-PVT", GET, iTOW=ep.itow, year=t.year, month=t.month, day=t.day, hour=t.hour, min=t.minute,
        second=t.second, nano=t.microsecond * 1000, validDate=ep.valid_date, validTime=ep.valid_date,
        fullyResolved=1, tAcc=30, fixType=ep.fix_type, gnssFixOk=ep.fix_ok, diffSoln=1, numSV=num_sv,
        lon=_scaled(pos.lon_e7, 1e-7), lat=_scaled(pos.lat_e7, 1e-7), height=pos.h_mm,
        hMSL=pos.h_mm - 51_000, hAcc=900, vAcc=1400, pDOP=_scaled(150, 0.01),
    )  # fmt: skip
    raw = msg.serialize()
    itow, lon, lat, height = struct.unpack_from("<I20xiii", raw, 6)
    assert (itow, lon, lat, height) == (ep.itow, pos.lon_e7, pos.lat_e7, pos.h_mm), "NAV-PVT encoding"
    assert raw[6 + 20] == ep.fix_type and raw[6 + 21] & 1 == ep.fix_ok
    return raw


def hpposllh(ep: Epoch, pos: Encoded) -> bytes:
    lat_e7, lat_hp = divmod(pos.lat_e9, 100)
    lon_e7, lon_hp = divmod(pos.lon_e9, 100)
    h_mm, h_hp = divmod(pos.h_e4, 10)
    if lat_hp > 50:
        lat_e7, lat_hp = lat_e7 + 1, lat_hp - 100
    if lon_hp > 50:
        lon_e7, lon_hp = lon_e7 + 1, lon_hp - 100
    if h_hp > 5:
        h_mm, h_hp = h_mm + 1, h_hp - 10
    hp = {"_HPlat": _scaled(lat_hp, 1e-9), "_HPlon": _scaled(lon_hp, 1e-9), "_HPheight": _scaled(h_hp, 0.1)}
    msg = UBXMessage(
        "NAV", "NAV-HPPOSLLH", GET, version=0, invalidLlh=0, iTOW=ep.itow, lon=_scaled(lon_e7, 1e-7),
        lat=_scaled(lat_e7, 1e-7), height=h_mm, hMSL=h_mm - 51_000, hAcc=_scaled(90, 0.1),
        vAcc=_scaled(140, 0.1), **hp,
    )  # fmt: skip
    raw = msg.serialize()
    got = struct.unpack_from("<4xIiiiibbbb", raw, 6)
    assert got[:4] == (ep.itow, lon_e7, lat_e7, h_mm) and got[5:8] == (lon_hp, lat_hp, h_hp), (
        "HPPOSLLH encoding"
    )
    return raw


def navpl(ep: Epoch) -> bytes:
    msg = UBXMessage(
        "NAV", "NAV-PL", GET, version=1, tmirCoeff=1, tmirExp=-4, plPosValid=ep.pl_valid, plPosFrame=ep.frame,
        plVelValid=0, plVelFrame=0, plTimeValid=0, iTOW=ep.itow, plPos1=ep.pl[0], plPos2=ep.pl[1],
        plPos3=ep.pl[2], plPosHorizOrient=3000 if ep.frame == 3 else 0,
    )  # fmt: skip
    raw = msg.serialize()
    assert struct.unpack_from("<12xIIII", raw, 6) == (ep.itow, *ep.pl), "NAV-PL encoding"
    assert raw[6 + 3] == ep.pl_valid and raw[6 + 4] == ep.frame
    return raw


NMEA = b"$GNGGA,000000.00,4333.64200,N,00128.85400,E,2,09,0.9,156.0,M,51.0,M,,0000*4B\r\n"


@dataclass(frozen=True)
class Row:
    """One expected epoch-table row."""

    file: str
    time: str
    east: float
    north: float
    up: float
    hpl: float
    vpl: float
    alert: bool


def build(
    name: str,
    epochs: list[Epoch],
    *,
    with_timegps: bool = True,
    with_hp: bool = False,
    drop_pl: frozenset[int] = frozenset(),
    drop_pvt: frozenset[int] = frozenset(),
    repeat: frozenset[int] = frozenset(),
    nmea_after: frozenset[int] = frozenset(),
) -> tuple[bytes, list[Row]]:
    """The bytes of one fixture and its expected rows (NaN where the epoch has no solution)."""
    chunks: list[bytes] = []
    rows: list[Row] = []
    for k, ep in enumerate(epochs):
        pos = encode_position(ep)
        frames = []
        if with_timegps:
            frames.append(timegps(ep))
        if k not in drop_pvt:
            frames.append(pvt(ep, pos, num_sv=9 + k % 3))
        if with_hp:
            frames.append(hpposllh(ep, pos))
        if k not in drop_pl:
            frames.append(navpl(ep))
        chunks.extend(frames * (2 if k in repeat else 1))
        if k in nmea_after:
            chunks.append(NMEA)
        if k in drop_pl:
            continue
        if with_hp:
            e, n, u = enu(pos.lat_e9 * 1e-9, pos.lon_e9 * 1e-9, pos.h_e4 * 1e-4)
        else:
            e, n, u = enu(pos.lat_e7 * 1e-7, pos.lon_e7 * 1e-7, pos.h_mm * 1e-3)
        p1, p2, p3 = (v / 1000 for v in ep.pl)
        hpl = p1 if ep.frame == 3 else math.hypot(p1, p2)
        usable = ep.pl_valid == 1 and ep.frame in (1, 2, 3) and ep.fix_ok == 1 and ep.fix_type in (3, 4)
        if k in drop_pvt:  # PL without position: the reader keeps the epoch as no-solution
            e = n = u = hpl = p3 = math.nan
            usable = True  # not flagged by the receiver; the solution is simply missing
        if not usable:
            e = n = u = hpl = p3 = math.nan
        t = GPS_EPOCH + dt.timedelta(weeks=ep.week, milliseconds=ep.itow)
        rows.append(Row(name, t.isoformat(), e, n, u, hpl, p3, not usable))
    return b"".join(chunks), rows


def fixtures() -> dict[str, tuple[bytes, list[Row]]]:
    base = design()
    invalid = list(base)
    invalid[2] = replace(invalid[2], pl_valid=0)
    invalid[3] = replace(invalid[3], frame=0)
    invalid[5] = replace(invalid[5], fix_ok=0)
    invalid[6] = replace(invalid[6], fix_type=2)
    rollover = design(6, week=WEEK - 1, tow0_ms=604_797_000)
    rollover[4] = replace(rollover[4], valid_date=0)
    out = {
        "pvt_pl_timegps.ubx": build("pvt_pl_timegps.ubx", base, nmea_after=frozenset({0})),
        "hpposllh_ellipse.ubx": build("hpposllh_ellipse.ubx", design(frame=3), with_hp=True),
        "invalid_pl.ubx": build("invalid_pl.ubx", invalid),
        "missing_pl.ubx": build("missing_pl.ubx", base, drop_pl=frozenset({4, 5}), drop_pvt=frozenset({8})),
        "utc_week_rollover.ubx": build("utc_week_rollover.ubx", rollover, with_timegps=False),
        "duplicate_epoch.ubx": build("duplicate_epoch.ubx", base, repeat=frozenset({4})),
    }
    data, rows = out["pvt_pl_timegps.ubx"]
    out["bad_checksum.ubx"] = corrupt_checksums(data, rows)
    # Cut in the middle of the last NAV-PL frame: the epoch is lost and the frame counted.
    cut = data[: data.rfind(b"\xb5\x62\x01\x62") + 30]
    out["truncated_frame.ubx"] = (cut, [replace(r, file="truncated_frame.ubx") for r in rows[:-1]])
    return out


def _frame_offsets(data: bytes, cls_id: bytes) -> list[int]:
    offs, i = [], 0
    while (i := data.find(b"\xb5\x62" + cls_id, i)) >= 0:
        offs.append(i)
        i += 2
    return offs


def corrupt_checksums(data: bytes, rows: list[Row]) -> tuple[bytes, list[Row]]:
    """Flip one payload byte of epoch 3's NAV-PVT and one checksum byte of epoch 6's NAV-PL."""
    buf = bytearray(data)
    pvt3 = _frame_offsets(data, b"\x01\x07")[3]
    buf[pvt3 + 6 + 28] ^= 0x40  # a latitude byte
    pl6 = _frame_offsets(data, b"\x01\x62")[6]
    buf[pl6 + 6 + 52] ^= 0xFF  # CK_A
    out = []
    for k, r in enumerate(rows):
        r = replace(r, file="bad_checksum.ubx")
        if k == 3:
            r = replace(r, east=math.nan, north=math.nan, up=math.nan, hpl=math.nan, vpl=math.nan)
        if k != 6:
            out.append(r)
    return bytes(buf), out


def old_log_cut(limit: int = 4096) -> bytes:
    """The log up to its last whole UBX frame within ``limit`` bytes (NMEA between frames kept)."""
    data = OLD_LOG.read_bytes()
    end = 0
    while (i := data.find(b"\xb5\x62", end)) >= 0:
        nxt = i + 8 + int.from_bytes(data[i + 4 : i + 6], "little")
        if nxt > limit:
            break
        end = nxt
    return data[:end]


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    all_rows: list[Row] = []
    for name, (data, rows) in sorted(fixtures().items()):
        (OUT / name).write_bytes(data)
        all_rows.extend(rows)
    with (OUT / "expected.csv").open("w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["file", "time", "east", "north", "up", "hpl", "vpl", "alert"])
        for r in all_rows:
            w.writerow(
                [r.file, r.time, *(f"{v:.9f}" for v in (r.east, r.north, r.up, r.hpl, r.vpl)), int(r.alert)]
            )
    if OLD_LOG.exists():
        (OUT / "old_ublox_no_navpl.ubx").write_bytes(old_log_cut())
    else:
        print(f"{OLD_LOG} not found: old_ublox_no_navpl.ubx left as it is", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
