"""MOPS troposphere model and its residual error (RTCA DO-229D A.4.2.4).

The zenith delays follow from five meteorological parameters (pressure P, temperature T,
water-vapour pressure e, temperature lapse rate beta, water-vapour lapse rate lambda), each
an average xi_0 minus a seasonal variation Delta xi cos(2 pi (D - D_min) / 365.25), interpolated
linearly in latitude between the table rows at 15, 30, 45, 60 and 75 degrees (clamped outside);
D_min is day 28 in the northern and day 211 in the southern hemisphere. The slant delay is the
sum of the zenith delays times the mapping function m(E) = 1.001 / sqrt(0.002001 + sin^2 E)
(with the low-elevation term for E < 4 deg), and sigma_tropo = 0.12 m(E).
"""

from __future__ import annotations

import numpy as np

__all__ = ["mapping", "mops_tropo", "sigma_tropo", "zenith_delays"]

_LATS = np.array([15.0, 30.0, 45.0, 60.0, 75.0])
#: Average P (mbar), T (K), e (mbar), beta (K/m), lambda per latitude row (DO-229D Table A-2).
_AVG = np.array(
    [
        [1013.25, 299.65, 26.31, 6.30e-3, 2.77],
        [1017.25, 294.15, 21.79, 6.05e-3, 3.15],
        [1015.75, 283.15, 11.66, 5.58e-3, 2.57],
        [1011.75, 272.15, 6.78, 5.39e-3, 1.81],
        [1013.00, 263.65, 4.11, 4.53e-3, 1.55],
    ]
)
#: Seasonal variation of the same parameters (DO-229D Table A-3).
_SEASON = np.array(
    [
        [0.00, 0.00, 0.00, 0.00e-3, 0.00],
        [-3.75, 7.00, 8.85, 0.25e-3, 0.33],
        [-2.25, 11.00, 7.24, 0.32e-3, 0.46],
        [-1.75, 15.00, 5.36, 0.81e-3, 0.74],
        [-0.50, 14.50, 3.39, 0.62e-3, 0.30],
    ]
)
_K1, _K2, _RD, _GM, _G = 77.604, 382000.0, 287.054, 9.784, 9.80665


def _interp(table: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """Each column of ``table`` interpolated at |lat| (clamped to 15..75 deg), shape (n, 5)."""
    a = np.clip(np.abs(lat), 15.0, 75.0)
    return np.stack([np.interp(a, _LATS, table[:, k]) for k in range(table.shape[1])], axis=-1)


def zenith_delays(
    lat_deg: np.ndarray, height_m: np.ndarray, doy: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Hydrostatic and wet zenith delays (m) at the receiver (DO-229D A.4.2.4)."""
    lat = np.asarray(lat_deg, float)
    d_min = np.where(lat >= 0, 28.0, 211.0)
    season = np.cos(2 * np.pi * (np.asarray(doy, float) - d_min) / 365.25)[..., None]
    p, t, e, beta, lam = np.moveaxis(_interp(_AVG, lat) - _interp(_SEASON, lat) * season, -1, 0)
    z_hyd = 1e-6 * _K1 * _RD * p / _GM
    z_wet = 1e-6 * _K2 * _RD / (_GM * (lam + 1) - beta * _RD) * e / t
    base = 1.0 - beta * np.asarray(height_m, float) / t
    d_hyd = base ** (_G / (_RD * beta)) * z_hyd
    d_wet = base ** ((lam + 1) * _G / (_RD * beta) - 1) * z_wet
    return d_hyd, d_wet


def mapping(elev_rad: np.ndarray) -> np.ndarray:
    """Tropospheric mapping function m(E) of DO-229D A.4.2.4 (with the E < 4 deg term)."""
    elev = np.asarray(elev_rad, float)
    m = 1.001 / np.sqrt(0.002001 + np.sin(elev) ** 2)
    low = np.deg2rad(4.0) - elev
    return np.where(low > 0, m * (1 + 0.015 * np.maximum(low, 0) ** 2), m)


def sigma_tropo(elev_rad: np.ndarray) -> np.ndarray:
    """Residual tropospheric error sigma_tropo = 0.12 m(E) (DO-229D A.4.2.4), m."""
    return 0.12 * mapping(elev_rad)


def mops_tropo(
    lat_deg: np.ndarray, height_m: np.ndarray, doy: np.ndarray, elev_rad: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Slant tropospheric delay and its sigma (m), broadcast over the inputs."""
    d_hyd, d_wet = zenith_delays(lat_deg, height_m, doy)
    m = mapping(elev_rad)
    return (d_hyd + d_wet) * m, 0.12 * m
