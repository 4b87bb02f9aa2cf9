"""Service-volume maps: what an SBAS offers over an area, from its messages and the GPS navigation data.

For every point of a latitude/longitude grid (a virtual receiver at height ``height_m``) and every
epoch, the satellites in view get their SBAS corrections and variances and the point its HPL and
VPL from :func:`overbound.sbas.engine.run_sbas` itself (``points=True``: each row with its own
receiver position; not a copy of the engine). No observation is involved: each satellite above the
horizon gets a pseudorange equal to its geometric range (the protection levels do not depend on
it; the position errors of these virtual receivers mean nothing and are not used).

Per grid point (and per hour with ``hourly``) :func:`overbound.sbas_map.summarise` gives, for every
service level:

* ``availability``: the share of the epochs whose HPL <= HAL and VPL <= VAL (HPL only for NPA), the
  epochs without a solution (too few satellites, no messages) counted unavailable;
* ``continuity_risk``: :func:`overbound.methods.counting.continuity_risk` of the point's epochs
  (windows in time: 15 s, or 15 min with ``maritime``; null when the epoch interval is longer than
  the window, e.g. 15 s at 60 s);
* ``iono_availability``: the share of the epochs at which the grid gives an ionospheric correction at
  the point taken as a pierce point (:func:`overbound.sbas.engine.grid_iono_available`, gLAB's
  definition: a service area of the ionospheric grid, independent of the satellites in view);
* ``hpl_p95``, ``vpl_p95``, ``hpl_p99``, ``vpl_p99``: numpy's linear-interpolation percentiles of the
  PLs of the epochs with a solution (null without one).

The epochs are computed in chunks (:func:`point_epochs`), each one call of the engine over a few
epochs of every point, so that memory is bounded by the chunk.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import polars as pl
import pymap3d

from overbound.io.rinex_nav import broadcast_state, rotate_earth
from overbound.sbas.engine import SbasOptions, grid_iono_available, run_sbas
from overbound.sbas.messages import SbasMessages

__all__ = [
    "EGNOS_AREA",
    "GEO_MIN_ELEVATION_DEG",
    "MapGrid",
    "geo_elevation",
    "grid_points",
    "map_times",
    "point_epochs",
    "virtual_observations",
]

#: gLAB's default SBAS plots area: longitude -30..40 deg E, latitude 25..70 deg N.
EGNOS_AREA = (-30.0, 40.0, 25.0, 70.0)
_US = 1_000_000
#: A point that sees the GEO lower than this gets no message: unavailable (gLAB's -sbasplots:mingeoelev).
GEO_MIN_ELEVATION_DEG = 5.0
_ROWS_PER_CHUNK = 400_000  # satellite rows per engine call: ~60 float columns of this stay < 200 MB
_MARGIN_DEG = 2.0  # satellites this far below the mask are left to the engine's own elevation test


@dataclass(frozen=True, slots=True)
class MapGrid:
    """Grid points every ``step`` deg from ``lat0`` and ``lon0`` up to ``lat1`` and ``lon1`` (see
    :meth:`axes`), at ellipsoidal height ``height_m``; points in latitude-major order."""

    lon0: float
    lon1: float
    lat0: float
    lat1: float
    step: float
    height_m: float = 0.0

    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Latitudes and longitudes of the nodes: ``min + k step`` up to ``max`` (+ 1e-4 deg, gLAB's rule:
        the maximum is a node only when the span is a whole number of steps)."""
        n_lat = int(np.floor((self.lat1 - self.lat0) / self.step + 1e-4)) + 1
        n_lon = int(np.floor((self.lon1 - self.lon0) / self.step + 1e-4)) + 1
        return self.lat0 + self.step * np.arange(n_lat), self.lon0 + self.step * np.arange(n_lon)


def grid_points(grid: MapGrid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Latitude, longitude (deg) and ECEF position (m, (n, 3)) of every grid point."""
    lats, lons = grid.axes()
    lat, lon = (a.ravel() for a in np.meshgrid(lats, lons, indexing="ij"))
    ecef = np.stack(pymap3d.geodetic2ecef(lat, lon, np.full(lat.size, grid.height_m)), axis=1)
    return lat, lon, ecef


def geo_elevation(
    msgs: SbasMessages, geo: int, lat: np.ndarray, lon: np.ndarray, height_m: float
) -> np.ndarray:
    """Elevation (deg) of the GEO seen from each point, from the GEO's position in its first almanac of
    itself (MT 17), else its first MT 9; NaN without either. One position for the whole span, as
    gLAB's maps: a GEO moves by less than 0.1 deg in a day."""
    alm = msgs.geo_almanac.filter((pl.col("geo") == geo) & (pl.col("prn") == geo))
    nav = msgs.geo_nav.filter(pl.col("geo") == geo)
    src = alm if alm.height else nav
    if not src.height:
        return np.full(lat.size, np.nan)
    x, y, z = (float(src[c][0]) for c in ("x", "y", "z"))
    _, el, _ = pymap3d.ecef2aer(x, y, z, lat, lon, np.full(lat.size, height_m))
    return np.asarray(el, float)


def map_times(msgs: SbasMessages, interval_s: float, start_us: int | None = None,
              end_us: int | None = None, geo: int | None = None) -> np.ndarray:  # fmt: skip
    """Epochs (GPS us) every ``interval_s`` from the start of the GPS day of the first message (or
    ``start_us``) to the last message's time + 1 s, the last epoch at which it is received (or before
    ``end_us``): the span of the data, as gLAB's SBAS maps (a time without any message file is not
    counted; gaps inside the span are, as unavailable)."""
    log = msgs.log if geo is None else msgs.log.filter(pl.col("geo") == geo)
    tags = log["time"].dt.epoch("us").to_numpy()
    day = 86_400 * _US
    first = int(tags.min()) // day * day if start_us is None else start_us
    last = int(tags.max()) + _US + 1 if end_us is None else end_us
    return np.arange(first, last, round(interval_s * _US), dtype=np.int64)


def virtual_observations(times_us: np.ndarray, points_ecef: np.ndarray, eph: pl.DataFrame,
                         mask_deg: float) -> pl.DataFrame:  # fmt: skip
    """Rows (``time``, ``point``, ``system``, ``prn``, ``C1C``) sorted by time, point and PRN: every GPS
    satellite with a broadcast record within 4 h, seen from each point above ``mask_deg`` - 2 deg
    (the engine decides the mask itself), with its geometric range as pseudorange."""
    rec = _nearest_records(eph, times_us)  # (T, 32), -1 where none
    t_idx, prn_idx = np.nonzero(rec >= 0)
    st = broadcast_state(eph, rec[t_idx, prn_idx], times_us[t_idx], -0.075)
    sat = rotate_earth(st.position, 0.075)  # (S, 3) per (time, prn)
    up = points_ecef / np.linalg.norm(points_ecef, axis=1, keepdims=True)  # geocentric: margin covers it
    los = sat[:, None, :] - points_ecef[None, :, :]  # (S, P, 3)
    rng = np.linalg.norm(los, axis=2)
    sin_el = np.einsum("spk,pk->sp", los, up) / rng
    seen = sin_el > np.sin(np.radians(mask_deg - _MARGIN_DEG))
    s_i, p_i = np.nonzero(seen)
    # order (time, point, prn): rows of one time are contiguous in s (time-major), then by point
    order = np.lexsort((prn_idx[s_i], p_i, t_idx[s_i]))
    s_i, p_i = s_i[order], p_i[order]
    return pl.DataFrame(
        {
            "time": pl.Series(times_us[t_idx[s_i]], dtype=pl.Int64).cast(pl.Datetime("us")),
            "point": p_i.astype(np.int32),
            "system": pl.repeat("G", s_i.size, eager=True),
            "prn": (prn_idx[s_i] + 1).astype(np.int16),
            "C1C": rng[s_i, p_i],
        }
    )


def _nearest_records(eph: pl.DataFrame, times_us: np.ndarray) -> np.ndarray:
    """Per (time, PRN 1..32) the broadcast record whose toe is nearest (any health; the earlier of two
    equally near), -1 beyond 4 h: one search of (PRN, toe) keys for every (time, PRN)."""
    prn = eph["prn"].to_numpy().astype(np.int64)
    toe = eph["toe_time"].dt.epoch("us").to_numpy()
    key = prn * (1 << 42) + (toe - toe.min() + (1 << 40))
    order = np.argsort(key)
    key = key[order]
    q = np.arange(1, 33) * (1 << 42) + (times_us - toe.min() + (1 << 40))[:, None]  # (T, 32)
    pos = np.searchsorted(key, q)
    best = np.full(q.shape, -1, np.int64)
    best_d = np.full(q.shape, np.iinfo(np.int64).max)
    for cand in (pos - 1, pos):  # the records on either side of the time, the same PRN only
        c = np.clip(cand, 0, key.size - 1)
        d = np.abs(key[c] - q)
        better = (cand >= 0) & (cand < key.size) & (key[c] >> 42 == q >> 42) & (d < best_d)
        best = np.where(better, order[c], best)
        best_d = np.where(better, d, best_d)
    return np.where(best_d <= 4 * 3600 * _US, best, -1)


def point_epochs(
    times_us: np.ndarray,
    points_ecef: np.ndarray,
    eph: pl.DataFrame,
    msgs: SbasMessages,
    options: SbasOptions,
    *,
    klobuchar=None,
    latlon: tuple[np.ndarray, np.ndarray] | None = None,
) -> pl.DataFrame:
    """HPL, VPL, satellites used and whether the ionosphere was corrected for every (time, point).

    Columns ``time``, ``point``, ``hpl``, ``vpl`` (NaN without a solution), ``nsv``, ``iono_ok`` (the grid
    corrects a pierce point at the point, :func:`overbound.sbas.engine.grid_iono_available`); one row
    per time and point, sorted so. The engine runs on chunks of epochs of about :data:`_ROWS_PER_CHUNK`
    satellite rows. ``latlon``: the points' geodetic latitudes and longitudes as given (default: from
    ``points_ecef``, which moves a node on a 5 deg line of the ionospheric grid by 1e-14 deg, enough to
    change the cell its pierce point falls in).
    """
    per_epoch = max(1, _ROWS_PER_CHUNK // max(points_ecef.shape[0] * 12, 1))
    latlon = latlon if latlon is not None else pymap3d.ecef2geodetic(*points_ecef.T)[:2]
    parts = [
        _chunk(times_us[a : a + per_epoch], points_ecef, eph, msgs, options, klobuchar, latlon)
        for a in range(0, times_us.size, per_epoch)
    ]
    return pl.concat(parts)


def _chunk(t: np.ndarray, points_ecef: np.ndarray, eph: pl.DataFrame, msgs: SbasMessages,
           options: SbasOptions, klobuchar, latlon) -> pl.DataFrame:  # fmt: skip
    n_p = points_ecef.shape[0]
    full = pl.DataFrame({
        "time": pl.Series(np.repeat(t, n_p), dtype=pl.Int64).cast(pl.Datetime("us")),
        "point": np.tile(np.arange(n_p, dtype=np.int32), t.size),
    })  # fmt: skip
    full = full.with_columns(iono_ok=grid_iono_available(msgs, t, *latlon, options).ravel())
    obs = virtual_observations(t, points_ecef, eph, options.mask_deg)
    if obs.is_empty():
        return full.with_columns(hpl=pl.lit(np.nan), vpl=pl.lit(np.nan), nsv=pl.lit(0, pl.Int64))
    res = run_sbas(obs, eph, msgs, points_ecef, options=options, klobuchar=klobuchar, points=True)
    ep = res.epochs.select("time", "point", "hpl", "vpl", pl.col("nsv").cast(pl.Int64))
    out = full.join(ep, on=["time", "point"], how="left", maintain_order="left")
    out = out.with_columns(pl.col("hpl", "vpl").fill_null(np.nan), pl.col("nsv").fill_null(0))
    return out.select("time", "point", "hpl", "vpl", "nsv", "iono_ok")
