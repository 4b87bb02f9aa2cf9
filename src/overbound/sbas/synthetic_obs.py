"""Noise-free GPS L1 observations of static points, made from precise products.

For a receiver network where no observations can be had (the EGNOS day of the repository's
messages has none in public), :func:`synthesize` computes what an error-free single-frequency
receiver at a known point would have measured, with the orbit, clock and ionosphere of the day,
so that the SBAS corrections, variances and protection levels computed from these files are the
ones a real receiver there would have got (and position errors are the SBAS residuals alone):

    C1 = rho - c (dt_sp3 + dt_rel) + c TGD - c DCB(P1-C1) + T + I
    L1 = (rho - c (dt_sp3 + dt_rel) + c TGD - c DCB(P1-C1) + T - I) / lambda1
    S1 = 30 + 20 sin E   (dB-Hz)

* ``rho``: distance from the point to the SP3 position at the transmission time (light time
  iterated on the geometric range; the receiver clock is zero), turned with the Earth over the
  travel time (:func:`overbound.io.rinex_nav.rotate_earth`). SP3 positions by 10th-degree
  Lagrange interpolation, clocks linear (:mod:`overbound.io.sp3`).
* ``dt_rel = -2 r.v / c**2`` (IS-GPS-200 20.3.3.3.3.1, the periodic relativistic effect that
  precise clocks leave out); ``v`` by central difference of the interpolated orbit over 1 s.
* ``TGD`` of the broadcast record a receiver would use at that time (the L1 P(Y) user's clock is
  ``dt - TGD``), and CODE's monthly P1-C1 bias (C1 = P1 - c DCB), so that a receiver that
  applies TGD to C/A code sees the C1 bias real receivers see.
* ``T = 2.3 exp(-0.116e-3 h) 1.001 / sqrt(0.002001 + sin**2 E)`` m (the zenith delay of the
  standard atmosphere with a simple obliquity factor; h the point's height, m).
* ``I``: slant delay of the IGS global ionosphere map (:func:`overbound.io.ionex.slant_delay_l1`).

Satellites: every GPS satellite with a healthy broadcast record, an SP3 orbit and clock, and an
elevation above the mask (5 deg). Elevation and azimuth are those of the point's ellipsoidal
vertical. The recipe and its values are those of the two files of
``egnos-ems-prn123-2019-014/synthetic-obs`` (Toulouse and Brussels), which the tests rebuild.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import polars as pl
import pymap3d

from overbound.io.dcb import CodeBiases, read_code_dcb
from overbound.io.ionex import Ionex, read_ionex, slant_delay_l1
from overbound.io.rinex_nav import (
    SPEED_OF_LIGHT,
    GpsEphemerides,
    read_rinex_nav,
    rotate_earth,
    select_ephemeris,
)
from overbound.io.rinex_write import write_rinex2_obs
from overbound.io.schema import InputError, ReadReport
from overbound.io.sp3 import Sp3, interpolate_clock, interpolate_position, read_sp3

__all__ = [
    "EUROPE",
    "LAMBDA_L1",
    "SyntheticPoint",
    "day_times",
    "rinex_name",
    "synthesize",
    "troposphere_delay",
    "write_network",
    "write_observations",
]

LAMBDA_L1 = SPEED_OF_LIGHT / 1575.42e6
_US = 1_000_000
_LIGHT_TIME_ITERATIONS = 3  # 75 ms -> below 1e-12 s after three


@dataclass(frozen=True, slots=True)
class SyntheticPoint:
    """A static receiver: its 4-character marker name and WGS-84 geodetic position."""

    name: str
    lat_deg: float
    lon_deg: float
    height_m: float

    @classmethod
    def parse(cls, text: str) -> SyntheticPoint:
        """From ``"NAME,lat,lon,h"`` (degrees, degrees, metres).

        >>> SyntheticPoint.parse("TLSE,43.5607,1.4809,207").name
        'TLSE'
        """
        parts = [p.strip() for p in text.split(",")]
        if len(parts) != 4 or not parts[0]:
            raise ValueError(f"point {text!r}: expected NAME,lat,lon,h")
        try:
            lat, lon, h = (float(p) for p in parts[1:])
        except ValueError:
            raise ValueError(f"point {text!r}: latitude, longitude and height must be numbers") from None
        if not (-90 <= lat <= 90 and -180 <= lon <= 360 and -500 <= h <= 10_000):
            raise ValueError(f"point {text!r}: latitude in [-90, 90], longitude in [-180, 360], h in m")
        return cls(parts[0], lat, lon, h)

    def ecef(self) -> np.ndarray:
        return np.array(pymap3d.geodetic2ecef(self.lat_deg, self.lon_deg, self.height_m), float)


def troposphere_delay(height_m: float, elevation: np.ndarray) -> np.ndarray:
    """Slant tropospheric delay, m: ``2.3 exp(-0.116e-3 h) 1.001 / sqrt(0.002001 + sin**2 E)``."""
    return 2.3 * np.exp(-0.116e-3 * height_m) * 1.001 / np.sqrt(0.002001 + np.sin(elevation) ** 2)


def synthesize(
    point: SyntheticPoint,
    time_us: np.ndarray,
    sp3: Sp3,
    nav: GpsEphemerides,
    ionex: Ionex,
    p1c1: CodeBiases,
    *,
    mask_deg: float = 5.0,
) -> pl.DataFrame:
    """Observations of ``point`` at GPS times ``time_us`` (int64 us), one row per satellite in view.

    Returns
    -------
    Columns ``time`` (Datetime us, GPS), ``sat`` (``"G07"``), ``C1`` (m), ``L1`` (cycles), ``S1``
    (dB-Hz), ``elevation`` and ``azimuth`` (deg), sorted by time and satellite. A satellite
    without a healthy broadcast record, SP3 orbit or clock, IONEX value or P1-C1 bias at a time
    is left out there.
    """
    t = np.asarray(time_us, np.int64)
    prn = np.arange(1, 33)
    tt, pp = (a.ravel() for a in np.meshgrid(t, prn, indexing="ij"))
    sats = np.array([f"G{p:02d}" for p in prn])[pp - 1]
    col = sp3.sat_index(sats)
    rows = select_ephemeris(nav.table, pp, tt)
    keep = (col >= 0) & (rows >= 0)
    tt, pp, sats, col, rows = tt[keep], pp[keep], sats[keep], col[keep], rows[keep]
    receiver = point.ecef()
    tau = np.full(len(tt), 0.075)
    for _ in range(_LIGHT_TIME_ITERATIONS):
        sat_pos = rotate_earth(interpolate_position(sp3, col, tt, -tau), tau)
        tau = np.linalg.norm(sat_pos - receiver, axis=1) / SPEED_OF_LIGHT
        tau[np.isnan(tau)] = 0.075  # outside the SP3 span: dropped below
    az, el, _ = pymap3d.ecef2aer(*sat_pos.T, point.lat_deg, point.lon_deg, point.height_m, deg=True)
    seen = np.isfinite(el) & (el > mask_deg)
    tt, pp, sats, col, rows, tau = tt[seen], pp[seen], sats[seen], col[seen], rows[seen], tau[seen]
    az, el = np.radians(az[seen]), np.radians(el[seen])
    rho = tau * SPEED_OF_LIGHT
    r = interpolate_position(sp3, col, tt, -tau)
    v = interpolate_position(sp3, col, tt, -tau + 0.5) - interpolate_position(sp3, col, tt, -tau - 0.5)
    edge = np.isnan(v[:, 0])  # within 0.5 s of the ends of the SP3 data: a one-sided difference
    if edge.any():
        ahead = interpolate_position(sp3, col[edge], tt[edge], -tau[edge] + 1.0) - r[edge]
        behind = r[edge] - interpolate_position(sp3, col[edge], tt[edge], -tau[edge] - 1.0)
        v[edge] = np.where(np.isnan(ahead), behind, ahead)
    rel = -2.0 * np.einsum("ij,ij->i", r, v) / SPEED_OF_LIGHT**2
    clock = interpolate_clock(sp3, col, tt, -tau) + rel
    tgd = nav.table["tgd"].to_numpy()[rows]
    dcb = np.array([p1c1.satellites.get(f"G{p:02d}", np.nan) for p in prn])[pp - 1] * 1e-9
    iono = slant_delay_l1(ionex, tt, point.lat_deg, point.lon_deg, el, az)
    common = rho - SPEED_OF_LIGHT * (clock - tgd + dcb) + troposphere_delay(point.height_m, el)
    c1 = common + iono
    ok = np.isfinite(c1)
    return pl.DataFrame(
        {
            "time": pl.Series(tt[ok], dtype=pl.Int64).cast(pl.Datetime("us")),
            "sat": sats[ok],
            "C1": c1[ok],
            "L1": (common[ok] - iono[ok]) / LAMBDA_L1,
            "S1": 30.0 + 20.0 * np.sin(el[ok]),
            "elevation": np.degrees(el[ok]),
            "azimuth": np.degrees(az[ok]) % 360.0,
        }
    ).sort("time", "sat")


#: Ten points across the EGNOS service area, from the Canaries' latitude to Iceland: the two
#: points of ``synthetic-obs`` (Toulouse, Brussels) and eight capitals (city centres, rounded).
EUROPE = (
    SyntheticPoint("SYNT", 43.5607, 1.4809, 207.0),
    SyntheticPoint("SYNB", 50.7980, 4.3590, 158.0),
    SyntheticPoint("MADR", 40.4168, -3.7038, 667.0),
    SyntheticPoint("LISB", 38.7223, -9.1393, 100.0),
    SyntheticPoint("ROMA", 41.9028, 12.4964, 50.0),
    SyntheticPoint("ATHN", 37.9838, 23.7275, 150.0),
    SyntheticPoint("WARS", 52.2297, 21.0122, 110.0),
    SyntheticPoint("OSLO", 59.9139, 10.7522, 50.0),
    SyntheticPoint("HELS", 60.1699, 24.9384, 30.0),
    SyntheticPoint("REYK", 64.1466, -21.9426, 30.0),
)


def day_times(day: dt.date, interval_s: float, start_s: float = 0.0, end_s: float = 86_400.0) -> np.ndarray:
    """GPS times (int64 us) of ``day`` from ``start_s`` to before ``end_s`` seconds of the day."""
    midnight = (day - dt.date(1970, 1, 1)).days * 86_400 * _US
    step = round(interval_s * _US)
    return midnight + np.arange(round(start_s * _US), round(end_s * _US), step, dtype=np.int64)


def rinex_name(point: SyntheticPoint, day: dt.date) -> str:
    """RINEX 2 short name of a daily file: ``SSSSDDD0.YYo.gz``."""
    return f"{point.name[:4].upper():_<4}{day.timetuple().tm_yday:03d}0.{day.year % 100:02d}o.gz"


def write_observations(
    point: SyntheticPoint, table: pl.DataFrame, path: Path, interval_s: float, products: Sequence[str]
) -> Path:
    """``table`` of :func:`synthesize` as a RINEX 2.11 file (C1 L1 S1) whose header gives the
    point's position (the truth) and, as comments, the recipe and the product files."""
    comments = [
        "SYNTHETIC NOISE-FREE GPS L1 OBS (overbound synth-obs):",
        "SP3 ORBIT+CLOCK, BRDC TGD, P1-C1 DCB, IONEX SLANT TEC,",
        "T=2.3EXP(-0.116E-3H)1.001/SQRT(0.002001+SIN2E), CLOCK 0",
        *(f"PRODUCT {Path(p).name}" for p in products),
        f"TRUTH LAT {point.lat_deg:.7f} LON {point.lon_deg:.7f} H {point.height_m:.3f}",
    ]
    return write_rinex2_obs(
        path, table, ("C1", "L1", "S1"), marker=point.name, position_ecef=point.ecef(),
        interval_s=interval_s, comments=comments,
    )  # fmt: skip


@dataclass(frozen=True, slots=True)
class WrittenFile:
    """A file of :func:`write_network`: the point, the path, its epochs and satellite records."""

    point: SyntheticPoint
    path: Path
    n_epochs: int
    n_records: int


def write_network(
    points: Sequence[SyntheticPoint],
    day: dt.date,
    out_dir: Path,
    *,
    sp3: Sequence[Path],
    nav: Sequence[Path],
    ionex: Sequence[Path],
    p1c1: Path,
    interval_s: float = 30.0,
    start_s: float = 0.0,
    end_s: float = 86_400.0,
    mask_deg: float = 5.0,
) -> tuple[list[WrittenFile], list[ReadReport]]:
    """Read the products once and write one RINEX file per point (:func:`rinex_name`) into
    ``out_dir``; the files and the products' read reports.

    Epochs where the products cover no satellite are not written: before the first SP3 epoch's
    transmission time, after its last, and outside the IONEX maps (UT: the IGS day's first map is
    00:00:18 GPS in 2019); give the adjoining days' files to cover midnight.
    """
    orbits, r_sp3 = read_sp3(list(sp3))
    eph, r_nav = read_rinex_nav(list(nav))
    maps, r_ionex = read_ionex(list(ionex))
    biases, r_dcb = read_code_dcb(p1c1)
    if biases.kind != "P1-C1":
        raise InputError(str(p1c1), f"{biases.kind} biases given, P1-C1 needed (C1 = P1 - c DCB)")
    times = day_times(day, interval_s, start_s, end_s)
    products = [*sp3, *nav, *ionex, p1c1]
    out: list[WrittenFile] = []
    for point in points:
        table = synthesize(point, times, orbits, eph, maps, biases, mask_deg=mask_deg)
        path = write_observations(point, table, out_dir / rinex_name(point, day), interval_s, products)
        out.append(WrittenFile(point, path, table["time"].n_unique(), table.height))
    return out, [r_sp3, r_nav, r_ionex, r_dcb]
