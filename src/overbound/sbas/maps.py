"""Service-volume maps: what an SBAS offers over an area, from its messages and the GPS navigation data.

For every point of a latitude/longitude grid (a virtual receiver at height ``height_m``) and every
epoch, the satellites in view get their SBAS corrections and variances and the point its HPL and
VPL from :func:`overbound.sbas.engine.run_sbas` itself (``points=True``: each row with its own
receiver position; not a copy of the engine). No observation is involved: each satellite above the
horizon gets a pseudorange equal to its geometric range (the protection levels do not depend on
it; the position errors of these virtual receivers mean nothing and are not used).

Per grid point (and per hour with ``hourly``) :func:`summarise` gives, for every service level:

* ``availability``: the share of the epochs whose HPL <= HAL and VPL <= VAL (HPL only for NPA), the
  epochs without a solution (too few satellites, no messages) counted unavailable;
* ``continuity_risk``: :func:`overbound.methods.counting.continuity_risk` of the point's epochs
  (windows in time: 15 s, or 15 min with ``maritime``; null when the epoch interval is longer than
  the window, e.g. 15 s at 60 s);
* ``iono_availability``: the share of the epochs at which every satellite above the mask has a grid
  ionospheric correction (no ``no_iono``-type reason);
* ``hpl_p95``, ``vpl_p95``, ``hpl_p99``, ``vpl_p99``: numpy's linear-interpolation percentiles of the
  PLs of the epochs with a solution (null without one).

The epochs are computed in chunks (:func:`point_epochs`), each one call of the engine over a few
epochs of every point, so that memory is bounded by the chunk.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import polars as pl
import pymap3d

from overbound.io.rinex_nav import broadcast_state, rotate_earth
from overbound.methods.counting import continuity_risk
from overbound.sbas.engine import SbasOptions, run_sbas
from overbound.sbas.messages import SbasMessages
from overbound.services import ServiceLevel

__all__ = [
    "EGNOS_AREA",
    "IONO_REASONS",
    "MapGrid",
    "grid_points",
    "map_times",
    "point_epochs",
    "summarise",
    "virtual_observations",
]

#: gLAB's default SBAS plots area: longitude -30..40 deg E, latitude 25..70 deg N.
EGNOS_AREA = (-30.0, 40.0, 25.0, 70.0)
#: Reasons of a satellite above the mask without a grid ionospheric correction.
IONO_REASONS = ("iono_mask_timeout", "no_igp_cell", "iono_outside_triangle", "no_iono")
_US = 1_000_000
_ROWS_PER_CHUNK = 400_000  # satellite rows per engine call: ~60 float columns of this stay < 200 MB
_MARGIN_DEG = 2.0  # satellites this far below the mask are left to the engine's own elevation test


@dataclass(frozen=True, slots=True)
class MapGrid:
    """Grid points: latitudes ``lat0..lat1`` and longitudes ``lon0..lon1`` (deg, both ends included) every
    ``step`` deg, at ellipsoidal height ``height_m``; points in latitude-major order."""

    lon0: float
    lon1: float
    lat0: float
    lat1: float
    step: float
    height_m: float = 0.0

    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        n_lat = round((self.lat1 - self.lat0) / self.step) + 1
        n_lon = round((self.lon1 - self.lon0) / self.step) + 1
        return self.lat0 + self.step * np.arange(n_lat), self.lon0 + self.step * np.arange(n_lon)


def grid_points(grid: MapGrid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Latitude, longitude (deg) and ECEF position (m, (n, 3)) of every grid point."""
    lats, lons = grid.axes()
    lat, lon = (a.ravel() for a in np.meshgrid(lats, lons, indexing="ij"))
    ecef = np.stack(pymap3d.geodetic2ecef(lat, lon, np.full(lat.size, grid.height_m)), axis=1)
    return lat, lon, ecef


def map_times(msgs: SbasMessages, interval_s: float, start_us: int | None = None,
              end_us: int | None = None) -> np.ndarray:  # fmt: skip
    """Epochs (GPS us) every ``interval_s`` from the start of the GPS day of the first message (or
    ``start_us``) to the end of the day of the last message (or before ``end_us``)."""
    tags = msgs.log["time"].dt.epoch("us").to_numpy()
    day = 86_400 * _US
    first = int(tags.min()) // day * day if start_us is None else start_us
    last = (int(tags.max()) // day + 1) * day if end_us is None else end_us
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
            "system": pl.Series(["G"], dtype=pl.String).gather(np.zeros(s_i.size, np.int64)),
            "prn": (prn_idx[s_i] + 1).astype(np.int16),
            "C1C": rng[s_i, p_i],
        }
    )


def _nearest_records(eph: pl.DataFrame, times_us: np.ndarray) -> np.ndarray:
    """Per (time, PRN 1..32) the broadcast record whose toe is nearest (any health), -1 beyond 4 h."""
    prn = eph["prn"].to_numpy().astype(np.int64)
    toe = eph["toe_time"].dt.epoch("us").to_numpy()
    key = prn * (1 << 42) + (toe - toe.min() + (1 << 40))
    order = np.argsort(key)
    key = key[order]
    out = np.full((times_us.size, 32), -1, np.int64)
    for p in range(1, 33):  # 32 searches over the day's ~400 records
        q = p * (1 << 42) + (times_us - toe.min() + (1 << 40))
        pos = np.searchsorted(key, q)
        best = np.full(times_us.size, -1, np.int64)
        best_d = np.full(times_us.size, np.iinfo(np.int64).max)
        for cand in (pos - 1, pos):
            ok = (cand >= 0) & (cand < key.size)
            c = np.clip(cand, 0, key.size - 1)
            ok &= key[c] // (1 << 42) == p
            d = np.abs(key[c] - q)
            better = ok & (d < best_d)
            best = np.where(better, order[c], best)
            best_d = np.where(better, d, best_d)
        out[:, p - 1] = np.where(best_d <= 4 * 3600 * _US, best, -1)
    return out


def point_epochs(
    times_us: np.ndarray,
    points_ecef: np.ndarray,
    eph: pl.DataFrame,
    msgs: SbasMessages,
    options: SbasOptions,
    *,
    klobuchar=None,
) -> pl.DataFrame:
    """HPL, VPL, satellites used and whether the ionosphere was corrected for every (time, point).

    Columns ``time``, ``point``, ``hpl``, ``vpl`` (NaN without a solution), ``nsv``, ``iono_ok`` (every
    satellite above the mask has a grid ionospheric correction); one row per time and point, sorted
    so. The engine runs on chunks of epochs of about :data:`_ROWS_PER_CHUNK` satellite rows.
    """
    per_epoch = max(1, _ROWS_PER_CHUNK // max(points_ecef.shape[0] * 12, 1))
    parts = [
        _chunk(times_us[a : a + per_epoch], points_ecef, eph, msgs, options, klobuchar)
        for a in range(0, times_us.size, per_epoch)
    ]
    return pl.concat(parts)


def _chunk(t: np.ndarray, points_ecef: np.ndarray, eph: pl.DataFrame, msgs: SbasMessages,
           options: SbasOptions, klobuchar) -> pl.DataFrame:  # fmt: skip
    n_p = points_ecef.shape[0]
    full = pl.DataFrame({
        "time": pl.Series(np.repeat(t, n_p), dtype=pl.Int64).cast(pl.Datetime("us")),
        "point": np.tile(np.arange(n_p, dtype=np.int32), t.size),
    })  # fmt: skip
    obs = virtual_observations(t, points_ecef, eph, options.mask_deg)
    if obs.is_empty():
        return full.with_columns(hpl=pl.lit(np.nan), vpl=pl.lit(np.nan), nsv=pl.lit(0, pl.Int64),
                                 iono_ok=pl.lit(False))  # fmt: skip
    res = run_sbas(obs, eph, msgs, points_ecef, options=options, klobuchar=klobuchar, points=True)
    iono_fail = res.satellites.filter(pl.col("reason").is_in(IONO_REASONS)).group_by("time", "point").len()
    ep = res.epochs.select("time", "point", "hpl", "vpl", pl.col("nsv").cast(pl.Int64))
    ep = ep.join(iono_fail, on=["time", "point"], how="left").with_columns(iono_ok=pl.col("len").is_null())
    out = full.join(ep.drop("len"), on=["time", "point"], how="left", maintain_order="left")
    return out.with_columns(pl.col("hpl", "vpl").fill_null(np.nan), pl.col("nsv").fill_null(0),
                            pl.col("iono_ok").fill_null(False))  # fmt: skip


def summarise(
    epochs: pl.DataFrame,
    lat: np.ndarray,
    lon: np.ndarray,
    services: Sequence[ServiceLevel],
    *,
    hourly: bool = False,
    window_s: float = 15.0,
) -> pl.DataFrame:
    """The map table: one row per grid point and service (and hour when ``hourly``), see the module notes.

    ``epochs``: :func:`point_epochs` (every time with every point). Columns ``lat``, ``lon``, ``service``,
    ``hour`` (null for the whole span, else the hour since the first epoch's midnight), ``n_epochs``,
    ``n_available``, ``availability``, ``continuity_risk``, ``hpl_p95``, ``vpl_p95``, ``hpl_p99``,
    ``vpl_p99``, ``iono_availability``.
    """
    n_p = lat.size
    times = epochs["time"].dt.epoch("us").to_numpy()[::n_p]
    shape = (times.size, n_p)
    hpl = epochs["hpl"].to_numpy().reshape(shape).T
    vpl = epochs["vpl"].to_numpy().reshape(shape).T
    iono = epochs["iono_ok"].to_numpy().reshape(shape).T
    spans: list[tuple[int | None, np.ndarray]] = [(None, np.arange(times.size))]
    if hourly:
        hour = (times - times[0] // (86_400 * _US) * (86_400 * _US)) // (3600 * _US)
        spans += [(int(h), np.flatnonzero(hour == h)) for h in np.unique(hour)]
    parts = []
    for hour_value, cols in spans:
        parts.append(_span_rows(times[cols], hpl[:, cols], vpl[:, cols], iono[:, cols], lat, lon, services,
                                hour_value, window_s))  # fmt: skip
    return pl.concat(parts)


def _span_rows(times, hpl, vpl, iono, lat, lon, services, hour, window_s) -> pl.DataFrame:
    n_p, n_t = hpl.shape
    with np.errstate(invalid="ignore"):
        solved = np.isfinite(hpl) & np.isfinite(vpl)
        pct = {f"{name}_p{q}": _percentile(x, solved, q) for name, x in (("hpl", hpl), ("vpl", vpl))
               for q in (95, 99)}  # fmt: skip
    rows = []
    for s in services:
        with np.errstate(invalid="ignore"):
            ok = solved & (hpl <= s.hal) & ((vpl <= s.val) if s.val is not None else True)
        risk = [continuity_risk(times, ok[p], window_s=window_s).risk for p in range(n_p)]
        rows.append(pl.DataFrame({
            "lat": lat, "lon": lon, "service": [s.name] * n_p,
            "hour": pl.Series([hour] * n_p, dtype=pl.Int32),
            "n_epochs": np.full(n_p, n_t, np.int64), "n_available": ok.sum(axis=1).astype(np.int64),
            "availability": ok.mean(axis=1) if n_t else np.full(n_p, np.nan),
            "continuity_risk": pl.Series(risk, dtype=pl.Float64),
            **{k: pct[k] for k in ("hpl_p95", "vpl_p95", "hpl_p99", "vpl_p99")},
            "iono_availability": iono.mean(axis=1) if n_t else np.full(n_p, np.nan),
        }))  # fmt: skip
    return pl.concat(rows)


def _percentile(x: np.ndarray, solved: np.ndarray, q: float) -> pl.Series:
    """Per row, numpy's linear-interpolation percentile of the solved epochs' values (null without any)."""
    out = np.full(x.shape[0], np.nan)
    has = solved.any(axis=1)
    if has.any():
        out[has] = np.nanpercentile(np.where(solved[has], x[has], np.nan), q, axis=1)
    return pl.Series(out).fill_nan(None)
