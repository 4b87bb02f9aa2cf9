"""SBAS ionospheric grid: pierce point, IGP cell selection, interpolation (DO-229D A.4.4.10).

Geometry (A.4.4.10.1): shell height h_I = 350 km, Earth radius R_e = 6378.1363 km; the Earth's
central angle psi_pp = pi/2 - E - asin(R_e / (R_e + h_I) cos E), the pierce point latitude and
longitude from the user's, the azimuth A and psi_pp, and the obliquity factor
F_pp = [1 - (R_e cos E / (R_e + h_I))^2]^(-1/2).

Cell selection (A.4.4.10.2), for |phi_pp| <= 75 deg: from the IGP mask alone, the 5x5 deg cell
(5x10 poleward of 60 deg) around the pierce point, else a triangle of three of its IGPs that
contains it, else a 10x10 cell, else a 10x10 triangle; then the selected IGPs' state decides
between four-point, three-point and no interpolation (details in :func:`select_and_interpolate`).
Pierce points poleward of 75 deg are not handled here (flagged unavailable; no user of the
EGNOS data here has one).

Interpolation (A.4.4.10.3): with x, y the pierce point's position within the cell (0..1 from
its south-west corner), the four-point weights are xy (NE), (1-x)y (NW), (1-x)(1-y) (SW),
x(1-y) (SE); the three-point weights are the barycentric coordinates of the pierce point in the
right triangle of the three remaining corners (W = y, 1-x-y, x for the triangle without NE),
which is what DO-229 writes out corner by corner.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

__all__ = [
    "FAIL_DONT_USE", "FAIL_NO_CELL", "FAIL_OUTSIDE", "FAIL_POLAR", "FAIL_UNUSABLE", "H_IONO", "R_EARTH",
    "GridSelection", "obliquity", "pierce_point", "select_and_interpolate",
]  # fmt: skip

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
    """IGP longitudes (multiples of 5 deg in [-190, 190)) into [-180, 180), exactly, by a select."""
    return np.where(lon >= 180, lon - 360, np.where(lon < -180, lon + 360, lon))


def _triangle_weights(x: np.ndarray, y: np.ndarray, missing: np.ndarray) -> np.ndarray:
    """Barycentric weights (n, 4) of (x, y) in the right triangle of the corners other than ``missing``.

    Columns are NE, NW, SW, SE; ``missing`` is the index of the corner left out (0..3).
    """
    out = np.empty((x.size, 4))
    for k in range(4):  # each point's own form only
        i = np.flatnonzero(missing == k)
        xi, yi = x[i], y[i]
        zero = np.zeros_like(xi)
        if k == 0:  # without NE: SW + x (SE - SW) + y (NW - SW)
            form = (zero, yi, 1 - xi - yi, xi)
        elif k == 1:  # without NW: SW + x (SE - SW) + y (NE - SE)
            form = (yi, zero, 1 - xi, xi - yi)
        elif k == 2:  # without SW: NE - (1-x)(NE - NW) - (1-y)(NE - SE)
            form = (xi + yi - 1.0, 1 - xi, zero, 1 - yi)
        else:  # without SE: SW + y (NW - SW) + x (NE - NW)
            form = (xi, yi - xi, 1 - yi, zero)
        out[i] = np.stack(form, axis=-1)
    return out


class GridSelection(NamedTuple):
    """Result of :func:`select_and_interpolate` (arrays over the pierce points).

    ok : a correction is available. clat, clon : (n, 4) coordinates of the selected cell's corners
    (NE, NW, SW, SE). weights : (n, 4), 0 for a corner not used. mode : 0 four points, 1..4 the
    corner left out of a triangle (gLAB's code), -1 none; the engine's ``iono_mode`` column is this
    code, or 5 (:data:`overbound.sbas.engine.IONO_MODE_KLOBUCHAR`) where NPA fell back on the GPS
    broadcast model. fail : why not (``FAIL_*``, 0 if ok).
    """

    ok: np.ndarray
    clat: np.ndarray
    clon: np.ndarray
    weights: np.ndarray
    mode: np.ndarray
    fail: np.ndarray


#: Failure codes of :func:`select_and_interpolate`.
FAIL_NO_CELL = 1  # no cell or triangle of IGPs in the mask around the pierce point
FAIL_UNUSABLE = 2  # the selected cell has too few usable IGPs
FAIL_OUTSIDE = 3  # one IGP of a four-point cell unusable, the pierce point outside the other three
FAIL_DONT_USE = 4  # a selected IGP is "don't use"
FAIL_POLAR = 5  # pierce point poleward of 75 deg (not implemented)


def _candidates(lat: np.ndarray, lon: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, float, float]]:
    """Cells to try after the first one, as (south-west latitude, longitude, dlat, dlon), in order.

    Every 10x10 deg cell that contains the pierce point and has its corners on the 5-degree IGP
    grid: south-west corner at the first cell's, then 5 deg west, 5 deg west and south, 5 deg
    south (for 60 < |lat| <= 75, where the IGPs are 10 deg apart in longitude, the first and
    5 deg south). DO-229D A.4.4.10.2 asks for "any" such cell; this order is gLAB's.
    """
    mid = np.abs(lat) <= 60
    lat0 = np.floor(lat / 5) * 5
    lon0 = np.where(mid, np.floor(lon / 5) * 5, np.floor(lon / 10) * 10)
    west = np.where(mid, 5.0, np.nan)  # no westward shift where IGPs are 10 deg apart
    return [
        (lat0, lon0, 10.0, 10.0),
        (lat0, lon0 - west, 10.0, 10.0),
        (lat0 - 5, lon0 - west, 10.0, 10.0),
        (lat0 - 5, lon0, 10.0, 10.0),
    ]


def _triangle_ok(sel: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For cells with exactly three selected corners: the left-out corner, weights, and inside."""
    missing = np.argmin(sel, axis=1)
    w3 = _triangle_weights(x, y, missing)
    return missing, w3, (w3 >= -1e-12).all(axis=1)


def select_and_interpolate(
    lat_pp_deg: np.ndarray,
    lon_pp_deg: np.ndarray,
    in_mask: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    status: Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
) -> GridSelection:
    """Select the IGPs around each pierce point and their interpolation weights (DO-229D A.4.4.10.2-3).

    The cell is chosen from the IGP mask alone, whatever the IGPs' state (A.4.4.10.2): for
    |lat| <= 60 deg (a) the 5x5 deg cell around the pierce point if its four IGPs are in the mask,
    (b) else its three IGPs in the mask if their triangle contains the pierce point, (c) else a
    10x10 deg cell around it with four IGPs in the mask, (d) else a 10x10 triangle of three that
    contains it; for 60 < |lat| <= 75 the same with the 5 (latitude) by 10 deg cell first. Then
    the selected IGPs' state decides: any "don't use" -> no correction; four selected and one not
    usable (not monitored, timed out, no data) -> three-point interpolation if the pierce point
    lies in the triangle of the other three, else no correction (there is no fall-back to another
    cell); four with two or more unusable, or three with any unusable -> no correction.

    Parameters
    ----------
    lat_pp_deg, lon_pp_deg : pierce points (deg), shape (n,).
    in_mask : ``in_mask(rows, lat, lon)`` -> (len(rows), 4) bool, the IGP at (lat, lon) is in the
        mask in force at pierce point ``rows``' epoch (``rows`` index the inputs).
    status : ``status(rows, lat, lon)`` -> (usable, dont_use), each (len(rows), 4) bool.
    """
    lat = np.asarray(lat_pp_deg, float)
    lon = np.asarray(lon_pp_deg, float)
    n = lat.size
    found = np.zeros(n, bool)
    clat = np.zeros((n, 4))
    clon = np.zeros((n, 4))
    x = np.zeros(n)
    y = np.zeros(n)
    sel = np.zeros((n, 4), bool)
    mid = np.abs(lat) <= 60
    high = (np.abs(lat) > 60) & (np.abs(lat) <= 75)
    first = (np.floor(lat / 5) * 5, np.where(mid, np.floor(lon / 5) * 5, np.floor(lon / 10) * 10),
             5.0, np.where(mid, 5.0, 10.0))  # fmt: skip
    todo_all = mid | high

    def take(idx: np.ndarray, la0: np.ndarray, lo0: np.ndarray, dlat: float, dlon: np.ndarray,
             want: int) -> None:  # fmt: skip
        """Try one cell for the pierce points idx; keep those with ``want`` (4 or 3) corners in the mask."""
        ok_geom = np.isfinite(lo0)
        idx, la0, lo0, dlon = idx[ok_geom], la0[ok_geom], lo0[ok_geom], dlon[ok_geom]
        if idx.size == 0:
            return
        la = la0[:, None] + _CORNERS[:, 1] * dlat
        lo = _wrap(lo0[:, None] + _CORNERS[:, 0] * dlon[:, None])
        m = in_mask(idx, la, lo)
        xx = (lon[idx] - lo0) / dlon  # lo0 <= lon < lo0 + 15 (lo0 not wrapped): no wrap
        yy = (lat[idx] - la0) / dlat
        if want == 4:
            good = m.all(axis=1)
        else:
            good = m.sum(axis=1) == 3
            good[good] = _triangle_ok(m[good], xx[good], yy[good])[2]  # only where three are in the mask
        g = idx[good]
        found[g] = True
        clat[g], clon[g], x[g], y[g], sel[g] = la[good], lo[good], xx[good], yy[good], m[good]

    idx = np.flatnonzero(todo_all)
    # (a), (b): the first cell, tried for every pierce point at once (most end here with four IGPs)
    la = first[0][idx, None] + _CORNERS[:, 1] * first[2]
    lo = _wrap(first[1][idx, None] + _CORNERS[:, 0] * first[3][idx, None])
    m = in_mask(idx, la, lo)
    xx = (lon[idx] - first[1][idx]) / first[3][idx]
    yy = (lat[idx] - first[0][idx]) / first[2]
    good = m.all(axis=1)
    three = ~good & (m.sum(axis=1) == 3)
    good[three] = _triangle_ok(m[three], xx[three], yy[three])[2]
    found[idx], clat[idx], clon[idx], x[idx], y[idx], sel[idx] = good, la, lo, xx, yy, m
    cands = _candidates(lat, lon)
    for want in (4, 3):  # (c), (d): the 10x10 cells
        for la0, lo0, dlat, dlon in cands:
            rest = idx[~found[idx]]
            take(rest, la0[rest], lo0[rest], dlat, np.full(rest.size, dlon), want)
    lost = ~found  # what the first cell left behind is no selection
    sel[lost], clat[lost], clon[lost] = False, 0.0, 0.0

    fail = np.where(todo_all, FAIL_NO_CELL, FAIL_POLAR)
    ok = np.zeros(n, bool)
    weights = np.zeros((n, 4))
    mode = np.full(n, -1)
    f = np.flatnonzero(found)
    if f.size:
        usable, dnu = status(f, clat[f], clon[f])
        s = sel[f]
        bad = s & ~usable
        n_sel, n_bad = s.sum(axis=1), bad.sum(axis=1)
        four = (n_sel == 4) & (n_bad == 0)
        dont = (s & dnu).any(axis=1)
        xf, yf = x[f], y[f]
        w = np.stack([xf * yf, (1 - xf) * yf, (1 - xf) * (1 - yf), xf * (1 - yf)], axis=-1)
        m_f = np.where(four, 0, -1)
        # triangles only where one is asked for: three selected, or four with one unusable
        tri = np.flatnonzero(((n_sel == 3) & (n_bad == 0)) | ((n_sel == 4) & (n_bad == 1)))
        missing, w3, inside = _triangle_ok((s & ~bad)[tri], xf[tri], yf[tri])
        three = np.zeros(f.size, bool)
        three[tri] = (n_sel[tri] == 3) | inside
        good = (four | three) & ~dont
        w[tri] = w3
        m_f[tri] = np.where(three[tri], missing + 1, -1)
        ok[f] = good
        weights[f] = np.where(good[:, None], w, 0.0)
        mode[f] = np.where(good, m_f, -1)
        outside = (n_sel == 4) & (n_bad == 1) & ~three
        fail[f] = np.select([good, dont, outside], [0, FAIL_DONT_USE, FAIL_OUTSIDE], FAIL_UNUSABLE)
    return GridSelection(ok, clat, clon, weights, mode, fail)
