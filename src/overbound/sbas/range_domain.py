"""Range-domain errors of SBAS-corrected pseudoranges against precise orbits and clocks (GIMAT 3.4).

Veerman et al. (GIMAT), section 3.4: range-domain verification compares the SBAS-corrected range
rho_corr, computed as DO-229 prescribes from the SBAS messages, with its reference, the true
geometric range from IGS precise (SP3) orbits interpolated to the observation times. Normalised by
the SBAS sigma of each satellite, these errors are what the overbounding tests of section 3.5
(:func:`overbound.stats.krs.krs_test`, :func:`overbound.stats.krs.tail_overbound_probability`) take.

Definitions, per used satellite i of an epoch (all in metres; ``I``, ``T`` the ionospheric and
tropospheric delays as the engine applies them, TGD the broadcast group delay, PRC/RRC the fast
and range-rate corrections, :func:`overbound.sbas.engine.run_sbas`):

* true satellite term, from SP3: S_true = |R(r_sp3(t_tx)) - r_rx| - c (dt_sp3(t_tx) - 2 r.v / c^2)
  + c TGD, with t_tx = t - PR / c - dt_sp3 (receiver clock taken as GPS time, as the engine does),
  R the Earth's rotation during the flight time, positions by degree-10 Lagrange and clocks
  linearly between SP3 epochs (:mod:`overbound.io.sp3`; SP3 clocks exclude the relativistic term,
  hence -2 r.v / c^2 from the interpolated orbit);
* SBAS satellite term, what the SBAS-corrected ephemeris, clock and fast correction predict:
  S_sbas = |r_sbas - r_rx| - c dt_sbas + c TGD - PRC - RRC, read off the engine's table as
  PR - prefit - I - T;
* ``sis`` = S_sbas - S_true: the signal-in-space error of the SBAS-corrected orbit and clock on the
  line of sight (bounded by sigma_flt);
* ``measurement`` = PR - I - T - S_true: the corrected pseudorange minus the true range, i.e.
  residual ionosphere, troposphere, code noise and multipath (bounded by sigma_UIRE, sigma_tropo,
  sigma_air);
* ``error`` = measurement - sis: the SBAS-corrected range error the user's solution sees; the SP3
  terms cancel in it and it equals the engine's pre-fit residual at the reference (``prefit``),
  so it needs no precise orbit, only the reference position; it is bounded by ``sigma``.

Receiver clock: with the position known, the clock is the only unknown; per epoch it is estimated
as the weighted mean c b = sum w_i error_i / sum w_i (w_i = 1 / sigma_i^2, the least-squares clock
with the position held at the reference) and removed from ``error`` and ``measurement``. The SBAS
clock corrections refer to SBAS network time and SP3 clocks to IGS time: the common offset between
them is likewise removed from ``sis`` per epoch (weights 1 / sigma_flt^2), as in UDRE-bounding
analyses; without it the offset would appear as a bias of every satellite.

Only SP3 clocks are used (no 30-s CLK reader yet): between 15-min SP3 epochs linear interpolation
misses real clocks by 1.6 cm median and 0.4 m at most (see :mod:`overbound.io.sp3`), which enters
``sis`` and ``measurement`` but cancels in ``error``.
"""

from __future__ import annotations

import numpy as np
import polars as pl

from overbound.io.rinex_nav import SPEED_OF_LIGHT, rotate_earth
from overbound.io.sp3 import Sp3, interpolate_clock, interpolate_position

__all__ = ["RANGE_COLUMNS", "range_errors"]

C = SPEED_OF_LIGHT
#: Columns of :func:`range_errors`.
RANGE_COLUMNS = (
    "time", "prn", "sat", "elevation", "error", "sigma", "normalised", "sis", "sigma_flt", "sis_normalised",
    "measurement", "sigma_measurement", "measurement_normalised", "clock", "rho_sp3",
)  # fmt: skip
_NEEDED = ("time", "prn", "used", "elevation", "pseudorange", "prefit", "iono", "tropo", "sigma", "sigma_flt",
           "iode")  # fmt: skip


def range_errors(
    satellites: pl.DataFrame, sp3: Sp3, eph: pl.DataFrame, reference_ecef: tuple[float, float, float]
) -> pl.DataFrame:
    """SBAS-corrected range errors of the used satellites, normalised by their sigmas.

    Parameters
    ----------
    satellites : the per-satellite table of :func:`overbound.sbas.engine.run_sbas`.
    sp3 : precise orbits and clocks covering the observations (:func:`overbound.io.sp3.read_sp3`).
    eph : the broadcast ephemerides given to the engine (for TGD, by PRN and IODE).
    reference_ecef : the receiver's true position (m), as given to the engine.

    Returns
    -------
    polars.DataFrame
        One row per used satellite with SP3 data, columns :data:`RANGE_COLUMNS` (see the module notes):
        ``error``, ``sis``, ``measurement`` (m), their sigmas and normalised values, ``clock`` (the
        receiver clock estimate c b removed, m) and ``rho_sp3`` (the SP3 geometric range, m).
        ``normalised`` is what :func:`overbound.stats.krs.krs_test` takes.
    """
    missing = [c for c in _NEEDED if c not in satellites.columns]
    if missing:
        raise ValueError(f"per-satellite table lacks {missing} (expected run_sbas's satellites)")
    tgd = eph.select("prn", "iode", "tgd").unique(("prn", "iode"), keep="first", maintain_order=True)
    rows = (
        satellites.filter(pl.col("used"))
        .join(tgd, on=("prn", "iode"), how="left")
        .with_columns(sat=pl.format("G{}", pl.col("prn").cast(pl.String).str.zfill(2)))
        .sort("time", "prn")
    )
    if rows["tgd"].null_count():
        raise ValueError("no broadcast TGD for some used satellites: pass the engine's ephemerides")
    t = rows["time"].dt.cast_time_unit("us").to_physical().to_numpy()
    pr = rows["pseudorange"].to_numpy()
    rho, clock_true = _sp3_range(sp3, rows["sat"].to_numpy(), t, pr, np.asarray(reference_ecef, float))
    s_true = rho - C * clock_true + C * rows["tgd"].to_numpy()
    iono, tropo = rows["iono"].to_numpy(), rows["tropo"].to_numpy()
    s_sbas = pr - rows["prefit"].to_numpy() - iono - tropo
    ok = np.isfinite(s_true)
    sis_raw = (s_sbas - s_true)[ok]
    meas_raw = (pr - iono - tropo - s_true)[ok]
    rows = rows.filter(pl.Series(ok))
    _, epoch = np.unique(t[ok], return_inverse=True)
    sigma, sigma_flt = rows["sigma"].to_numpy(), rows["sigma_flt"].to_numpy()
    clock = _weighted_mean(epoch, meas_raw - sis_raw, 1.0 / sigma**2)
    sis = sis_raw - _weighted_mean(epoch, sis_raw, 1.0 / sigma_flt**2)
    error = meas_raw - sis_raw - clock
    measurement = error + sis
    sigma_meas = np.sqrt(np.maximum(sigma**2 - sigma_flt**2, 0.0))
    return rows.select(
        "time", "prn", "sat", "elevation",
        pl.Series("error", error), "sigma", pl.Series("normalised", error / sigma),
        pl.Series("sis", sis), "sigma_flt", pl.Series("sis_normalised", sis / sigma_flt),
        pl.Series("measurement", measurement), pl.Series("sigma_measurement", sigma_meas),
        pl.Series("measurement_normalised", measurement / sigma_meas),
        pl.Series("clock", clock), pl.Series("rho_sp3", rho[ok]),
    )  # fmt: skip


def _sp3_range(
    sp3: Sp3, sat: np.ndarray, t_us: np.ndarray, pr: np.ndarray, rx: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Geometric range to the SP3 position at transmission (Earth rotation applied) and the SP3 clock
    with its relativistic term (s), NaN where the SP3 data do not cover the time."""
    tau = pr / C
    clock = _clock(sp3, sat, t_us, -tau)
    tx = -tau - np.nan_to_num(clock)  # GPS time of transmission relative to the epoch
    clock = _clock(sp3, sat, t_us, tx)
    pos = interpolate_position(sp3, sat, t_us, tx)
    h = 0.5  # s, central difference of the degree-10 interpolant for the velocity
    vel = (interpolate_position(sp3, sat, t_us, tx + h) - interpolate_position(sp3, sat, t_us, tx - h)) / (
        2 * h
    )
    rho = np.linalg.norm(pos - rx, axis=-1)
    for _ in range(2):  # the rotation depends on the flight time, which depends on the range
        rho = np.linalg.norm(rotate_earth(pos, rho / C) - rx, axis=-1)
    relativistic = -2.0 * np.sum(pos * vel, axis=-1) / C**2
    return rho, clock + relativistic


def _clock(sp3: Sp3, sat: np.ndarray, t_us: np.ndarray, offset_s: np.ndarray) -> np.ndarray:
    """SP3 clock at ``t_us + offset_s``, the offset folded into the integer time first:
    :func:`~overbound.io.sp3.interpolate_clock` picks its interval from ``t_us`` alone, so a query
    just before an SP3 epoch given as (epoch, negative offset) would fall outside it (NaN)."""
    whole = np.floor(offset_s * 1e6).astype(np.int64)
    return interpolate_clock(sp3, sat, t_us + whole, offset_s - whole / 1e6)


def _weighted_mean(group: np.ndarray, x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Per-row weighted mean of ``x`` over the rows of the same group."""
    num = np.bincount(group, weights=w * x)
    den = np.bincount(group, weights=w)
    return (num / den)[group]
