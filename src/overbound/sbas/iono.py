"""SBAS ionospheric grid: pierce point, IGP cell selection, interpolation (DO-229D A.4.4.10).

Geometry (A.4.4.10.1): shell height h_I = 350 km, Earth radius R_e = 6378.1363 km; the Earth's
central angle psi_pp = pi/2 - E - asin(R_e / (R_e + h_I) cos E), the pierce point latitude and
longitude from the user's, the azimuth A and psi_pp, and the obliquity factor
F_pp = [1 - (R_e cos E / (R_e + h_I))^2]^(-1/2).

Cell selection (A.4.4.10.2), for |phi_pp| <= 60 deg: the 5x5 deg cell around the pierce point
if its four IGPs are usable, else a triangle of three of them that contains the pierce point,
else the same with the 10x10 deg cell; for 60 < |phi_pp| <= 75 deg the 5 deg (latitude) by
10 deg (longitude) cell, then the 10x10 cell. "Usable" is decided by the caller (in the mask,
monitored, not timed out, IODI matching). Pierce points poleward of 75 deg are not handled here
(flagged unavailable; no user of the EGNOS data here has one).

Interpolation (A.4.4.10.3): with x, y the pierce point's position within the cell (0..1 from
its south-west corner), the four-point weights are xy (NE), (1-x)y (NW), (1-x)(1-y) (SW),
x(1-y) (SE); the three-point weights are the barycentric coordinates of the pierce point in the
right triangle of the three remaining corners (W = y, 1-x-y, x for the triangle without NE),
which is what DO-229 writes out corner by corner.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["H_IONO", "R_EARTH", "obliquity", "pierce_point", "select_and_interpolate"]

R_EARTH = 6378136.3  # m
H_IONO = 350_000.0  # m

#: Corner order NE, NW, SW, SE (as gLAB prints them, vertex 1..4), as (dx, dy) in the unit cell.
_CORNERS = np.array([[1, 1], [0, 1], [0, 0], [1, 0]])


def pierce_point(
    lat_rad: np.ndarray, lon_rad: np.ndarray, elev_rad: np.ndarray, azim_rad: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Latitude and longitude (rad, longitude in [-pi, pi)) of the ionospheric pierce point."""
    psi = np.pi / 2 - elev_rad - np.arcsin(R_EARTH / (R_EARTH + H_IONO) * np.cos(elev_rad))
    lat_pp = np.arcsin(np.sin(lat_rad) * np.cos(psi) + np.cos(lat_rad) * np.sin(psi) * np.cos(azim_rad))
    dlon = np.arcsin(np.clip(np.sin(psi) * np.sin(azim_rad) / np.cos(lat_pp), -1, 1))
    # pierce points across the pole (A.4.4.10.1)
    over_n = (lat_rad > np.deg2rad(70)) & (np.tan(psi) * np.cos(azim_rad) > np.tan(np.pi / 2 - lat_rad))
    tan_s = np.tan(psi) * np.cos(azim_rad + np.pi)
    over_s = (lat_rad < np.deg2rad(-70)) & (tan_s > np.tan(np.pi / 2 + lat_rad))
    lon_pp = np.where(over_n | over_s, lon_rad + np.pi - dlon, lon_rad + dlon)
    return lat_pp, (lon_pp + np.pi) % (2 * np.pi) - np.pi


def obliquity(elev_rad: np.ndarray) -> np.ndarray:
    """Obliquity factor F_pp (A.4.4.10.4)."""
    return 1.0 / np.sqrt(1.0 - (R_EARTH * np.cos(elev_rad) / (R_EARTH + H_IONO)) ** 2)


def _wrap(lon: np.ndarray) -> np.ndarray:
    return (lon + 180) % 360 - 180


def _cell(lat: np.ndarray, lon: np.ndarray, dlat: float, dlon: float):
    """South-west corner, corner coordinates (n, 4) and (x, y) of the pierce point in the cell."""
    lat0 = np.floor(lat / dlat) * dlat
    lon0 = np.floor(lon / dlon) * dlon
    x = (lon - lon0) / dlon
    y = (lat - lat0) / dlat
    clat = lat0[:, None] + _CORNERS[:, 1] * dlat
    clon = _wrap(lon0[:, None] + _CORNERS[:, 0] * dlon)
    return clat, clon, x, y


def _triangle_weights(x: np.ndarray, y: np.ndarray, missing: np.ndarray) -> np.ndarray:
    """Barycentric weights (n, 4) of (x, y) in the right triangle of the corners other than ``missing``.

    Columns are NE, NW, SW, SE; ``missing`` is the index of the corner left out (0..3).
    """
    one = np.ones_like(x)
    zero = np.zeros_like(x)
    forms = (
        (zero, y, 1 - x - y, x),  # without NE: SW + x (SE - SW) + y (NW - SW)
        (y, zero, 1 - x, x - y),  # without NW: SW + x (SE - SW) + y (NE - SE)
        (x + y - one, 1 - x, zero, 1 - y),  # without SW: NE - (1-x)(NE - NW) - (1-y)(NE - SE)
        (x, y - x, 1 - y, zero),  # without SE: SW + y (NW - SW) + x (NE - NW)
    )
    table = np.stack([np.stack(f, axis=-1) for f in forms])  # (4 forms, n, 4)
    return table[missing, np.arange(x.size)]


def select_and_interpolate(
    lat_pp_deg: np.ndarray,
    lon_pp_deg: np.ndarray,
    usable: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Select the IGPs around each pierce point and their interpolation weights.

    Parameters
    ----------
    lat_pp_deg, lon_pp_deg : pierce points (deg), shape (n,).
    usable : ``usable(rows, lat, lon)`` for the pierce points ``rows`` (indices into the inputs)
        and their IGP coordinates (len(rows), 4): True where the IGP can be used there (the caller
        checks mask, IODI, GIVEI and time-outs at each pierce point's epoch).

    Returns
    -------
    ok : (n,) a cell or triangle was found.
    clat, clon : (n, 4) IGP coordinates in the order NE, NW, SW, SE.
    weights : (n, 4) interpolation weights (0 for a corner that is not used).
    mode : (n,) 0 for four points, 1..4 for the corner left out of a triangle (gLAB's code),
        -1 where nothing was found.
    """
    lat = np.asarray(lat_pp_deg, float)
    lon = np.asarray(lon_pp_deg, float)
    n = lat.size
    ok = np.zeros(n, bool)
    clat = np.zeros((n, 4))
    clon = np.zeros((n, 4))
    weights = np.zeros((n, 4))
    mode = np.full(n, -1)
    mid = np.abs(lat) <= 60
    high = (np.abs(lat) > 60) & (np.abs(lat) <= 75)
    tries = ((mid, 5.0, 5.0), (high, 5.0, 10.0), (mid | high, 10.0, 10.0))  # first cell, then 10x10
    for region, dlat, dlon in tries:
        todo = region & ~ok
        if not todo.any():
            continue
        idx = np.flatnonzero(todo)
        la, lo, x, y = _cell(lat[idx], lon[idx], dlat, dlon)
        use = usable(idx, la, lo)
        n_use = use.sum(axis=1)
        four = n_use == 4
        w4 = np.stack([x * y, (1 - x) * y, (1 - x) * (1 - y), x * (1 - y)], axis=-1)
        missing = np.argmin(use, axis=1)
        w3 = _triangle_weights(x, y, missing)
        inside = (w3 >= -1e-12).all(axis=1)
        three = (n_use == 3) & inside
        good = four | three
        sel = idx[good]
        ok[sel] = True
        clat[sel], clon[sel] = la[good], lo[good]
        weights[sel] = np.where(four[good, None], w4[good], w3[good])
        mode[sel] = np.where(four[good], 0, missing[good] + 1)
    return ok, clat, clon, weights, mode
