"""GPS broadcast (Klobuchar) ionosphere and its SBAS variance (IS-GPS-200 20.3.3.5.2.5, DO-229D J.2.3).

DO-229D J.2.3 lets an NPA user apply the GPS broadcast ionospheric model where the SBAS grid
gives no correction, with the model variance

    sigma_UIRE^2 = max((T_iono / 5)^2, (F_pp tau_vert)^2),

T_iono the model's slant delay (m), F_pp the SBAS obliquity factor (A.4.4.10.4,
:func:`overbound.sbas.iono.obliquity`) and tau_vert, by the geomagnetic latitude phi_m of the
pierce point of IS-GPS-200: 9 m for |phi_m| <= 20 deg, 4.5 m for 20 < |phi_m| <= 55 deg, 6 m
above 55 deg.

The delay is the algorithm of IS-GPS-200 20.3.3.5.2.5 as written there (its approximate pierce
point, geomagnetic latitude, obliquity F = 1 + 16 (0.53 - E)^3 and fourth-order cosine). gLAB
evaluates a variant (spherical pierce point at 350 km, exact geomagnetic latitude of the 78.3 N,
291 E pole, exact obliquity and cosine), which differs from it by up to a few decimetres at low
elevation.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from overbound.io.rinex_nav import SPEED_OF_LIGHT
from overbound.sbas.iono import obliquity

__all__ = ["geomagnetic_latitude", "klobuchar_delay", "klobuchar_sigma2", "tau_vert"]

#: Seconds in a day; t = 4.32e4 lambda_i + t_GPS is taken modulo this (IS-GPS-200 20.3.3.5.2.5).
_DAY = 86_400.0


def _pierce(lat_rad, lon_rad, elev_rad, azim_rad) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Elevation E, pierce-point latitude phi_i and longitude lambda_i, all in semicircles."""
    e = np.asarray(elev_rad, float) / np.pi
    azim = np.asarray(azim_rad, float)
    psi = 0.0137 / (e + 0.11) - 0.022  # Earth's central angle user - pierce point
    phi_i = np.clip(np.asarray(lat_rad, float) / np.pi + psi * np.cos(azim), -0.416, 0.416)
    lam_i = np.asarray(lon_rad, float) / np.pi + psi * np.sin(azim) / np.cos(np.pi * phi_i)
    return e, phi_i, lam_i


def geomagnetic_latitude(lat_rad, lon_rad, elev_rad, azim_rad) -> np.ndarray:
    """Geomagnetic latitude phi_m (rad) of the pierce point, IS-GPS-200 20.3.3.5.2.5.

    With E the elevation and A the azimuth (semicircles and radians): psi = 0.0137 / (E + 0.11) -
    0.022, phi_i = phi_u + psi cos A (limited to +-0.416), lambda_i = lambda_u + psi sin A /
    cos phi_i, phi_m = phi_i + 0.064 cos(lambda_i - 1.617), all angles in semicircles.

    Parameters
    ----------
    lat_rad, lon_rad : user's geodetic latitude and longitude (rad).
    elev_rad, azim_rad : satellite elevation and azimuth (rad).
    """
    _, phi_i, lam_i = _pierce(lat_rad, lon_rad, elev_rad, azim_rad)
    return np.pi * (phi_i + 0.064 * np.cos(np.pi * (lam_i - 1.617)))


def klobuchar_delay(
    alpha: Sequence[float],
    beta: Sequence[float],
    lat_rad,
    lon_rad,
    elev_rad,
    azim_rad,
    t_gps_sow,
) -> np.ndarray:
    """L1 slant ionospheric delay (m) of the GPS broadcast model, IS-GPS-200 20.3.3.5.2.5.

    With phi_i, lambda_i, phi_m from :func:`geomagnetic_latitude` (semicircles):

    * local time t = 4.32e4 lambda_i + t_GPS, reduced to [0, 86400) s;
    * obliquity F = 1 + 16 (0.53 - E)^3 (E in semicircles);
    * AMP = sum_n alpha_n phi_m^n (set to 0 if negative), PER = sum_n beta_n phi_m^n (at least
      72000 s), x = 2 pi (t - 50400) / PER;
    * T_iono = F [5e-9 + AMP (1 - x^2 / 2 + x^4 / 24)] for |x| < 1.57, else F 5e-9 (s), times c.

    Parameters
    ----------
    alpha, beta : the four broadcast coefficients each (s, s/semicircle^n; s, s/semicircle^n).
    lat_rad, lon_rad : user's geodetic latitude and longitude (rad).
    elev_rad, azim_rad : satellite elevation and azimuth (rad), broadcast together.
    t_gps_sow : GPS time (s of week, or of day: only its value modulo 86400 s matters).

    Returns
    -------
    The delay on L1 (m), the shape of the broadcast inputs.
    """
    a, b = _coefficients(alpha, "alpha"), _coefficients(beta, "beta")
    e, phi_i, lam_i = _pierce(lat_rad, lon_rad, elev_rad, azim_rad)
    phi_m = phi_i + 0.064 * np.cos(np.pi * (lam_i - 1.617))
    t = np.mod(4.32e4 * lam_i + np.asarray(t_gps_sow, float), _DAY)
    f = 1.0 + 16.0 * (0.53 - e) ** 3
    amp = np.maximum(np.polynomial.polynomial.polyval(phi_m, a), 0.0)
    per = np.maximum(np.polynomial.polynomial.polyval(phi_m, b), 72_000.0)
    x = 2.0 * np.pi * (t - 50_400.0) / per
    day = amp * (1.0 - x**2 / 2.0 + x**4 / 24.0)
    return SPEED_OF_LIGHT * f * (5e-9 + np.where(np.abs(x) < 1.57, day, 0.0))


def tau_vert(geomagnetic_lat_rad) -> np.ndarray:
    """tau_vert (m) of DO-229D J.2.3: 9 m for |phi_m| <= 20 deg, 4.5 m up to 55 deg, 6 m above."""
    m = np.abs(np.rad2deg(np.asarray(geomagnetic_lat_rad, float)))
    return np.where(m <= 20.0, 9.0, np.where(m <= 55.0, 4.5, 6.0))


def klobuchar_sigma2(delay_m, elev_rad, geomagnetic_lat_rad) -> np.ndarray:
    """sigma_UIRE^2 (m^2) of the broadcast model, DO-229D J.2.3.

    sigma_UIRE^2 = max((T_iono / 5)^2, (F_pp tau_vert)^2), with F_pp the SBAS obliquity factor
    (A.4.4.10.4) and tau_vert from :func:`tau_vert`.

    Parameters
    ----------
    delay_m : T_iono, the slant delay of :func:`klobuchar_delay` (m).
    elev_rad : satellite elevation (rad).
    geomagnetic_lat_rad : phi_m of :func:`geomagnetic_latitude` (rad).
    """
    fpp = obliquity(np.asarray(elev_rad, float))
    return np.maximum((np.asarray(delay_m, float) / 5.0) ** 2, (fpp * tau_vert(geomagnetic_lat_rad)) ** 2)


def _coefficients(values: Sequence[float], name: str) -> np.ndarray:
    out = np.asarray(values, float)
    if out.shape != (4,) or not np.isfinite(out).all():
        raise ValueError(f"Klobuchar {name}: expected 4 finite coefficients, got {values!r}")
    return out
