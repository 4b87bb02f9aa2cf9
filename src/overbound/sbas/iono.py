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
    "FAIL_DONT_USE", "FAIL_NO_CELL", "FAIL_OUTSIDE", "FAIL_POLAR", "FAIL_UNUSABLE", "H_IONO", "N_IGP_KEYS",
    "R_EARTH", "GridSelection", "igp_key", "igp_position", "obliquity", "pierce_point",
    "select_and_interpolate",
]  # fmt: skip

R_EARTH = 6378136.3  # m
H_IONO = 350_000.0  # m

#: Corner order NE, NW, SW, SE (as gLAB prints them, vertex 1..4), as (dx, dy) in the unit cell.
_CORNERS = np.array([[1, 1], [0, 1], [0, 0], [1, 0]])


def pierce_point(
    lat_rad: np.ndarray, lon_rad: np.ndarray, elev_rad: np.ndarray, azim_rad: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Latitude and longitude (rad, longitude in [-pi, pi)) of the ionospheric pierce point.

    The test for pierce points across the pole (A.4.4.10.1) only applies to users poleward of 70 deg
    and is skipped (the same numbers) when there is none.
    """
    psi = np.pi / 2 - elev_rad - np.arcsin(R_EARTH / (R_EARTH + H_IONO) * np.cos(elev_rad))
    lat_pp = np.arcsin(np.sin(lat_rad) * np.cos(psi) + np.cos(lat_rad) * np.sin(psi) * np.cos(azim_rad))
    dlon = np.arcsin(np.clip(np.sin(psi) * np.sin(azim_rad) / np.cos(lat_pp), -1, 1))
    north, south = lat_rad > np.deg2rad(70), lat_rad < np.deg2rad(-70)
    if not (np.any(north) or np.any(south)):
        lon_pp = lon_rad + dlon
        return lat_pp, (lon_pp + np.pi) % (2 * np.pi) - np.pi
    # pierce points across the pole (A.4.4.10.1)
    over_n = north & (np.tan(psi) * np.cos(azim_rad) > np.tan(np.pi / 2 - lat_rad))
    tan_s = np.tan(psi) * np.cos(azim_rad + np.pi)
    over_s = south & (tan_s > np.tan(np.pi / 2 + lat_rad))
    lon_pp = np.where(over_n | over_s, lon_rad + np.pi - dlon, lon_rad + dlon)
    return lat_pp, (lon_pp + np.pi) % (2 * np.pi) - np.pi


def obliquity(elev_rad: np.ndarray) -> np.ndarray:
    """Obliquity factor F_pp (A.4.4.10.4)."""
    return 1.0 / np.sqrt(1.0 - (R_EARTH * np.cos(elev_rad) / (R_EARTH + H_IONO)) ** 2)


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

    ok : a correction is available. key : (n, 4) :func:`igp_key` of the selected cell's corners (NE,
    NW, SW, SE), -1 without a cell; ``clat``, ``clon`` give their coordinates (0 without a cell).
    weights : (n, 4), 0 for a corner not used. mode : 0 four points, 1..4 the corner left out of a
    triangle (gLAB's code), -1 none; the engine's ``iono_mode`` column is this code, or 5
    (:data:`overbound.sbas.engine.IONO_MODE_KLOBUCHAR`) where NPA fell back on the GPS broadcast model.
    fail : why not (``FAIL_*``, 0 if ok).
    """

    ok: np.ndarray
    key: np.ndarray
    weights: np.ndarray
    mode: np.ndarray
    fail: np.ndarray

    @property
    def clat(self) -> np.ndarray:
        return np.where(self.key >= 0, igp_position(np.maximum(self.key, 0))[0], 0.0)

    @property
    def clon(self) -> np.ndarray:
        return np.where(self.key >= 0, igp_position(np.maximum(self.key, 0))[1], 0.0)


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


#: Number of :func:`igp_key` values (latitudes -90..90 by 5 deg, 72 longitudes).
N_IGP_KEYS = 37 * 72


def igp_key(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """One integer per 5-degree IGP position (latitude in [-90, 90], longitude in [-180, 180]).

    IGP coordinates are whole multiples of 5 deg, so the divisions are exact and the conversion
    needs no rounding.
    """
    i = ((np.asarray(lat, float) + 90) / 5).astype(np.int64)
    j = ((np.asarray(lon, float) + 180) / 5).astype(np.int64)
    return i * 72 + np.where(j >= 72, j - 72, j)


def igp_position(key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Latitude and longitude (deg, longitude in [-180, 180)) of :func:`igp_key` values."""
    key = np.asarray(key, np.int64)
    return (key // 72 * 5 - 90).astype(float), (key % 72 * 5 - 180).astype(float)


def _corner_keys(la0: np.ndarray, lo0: np.ndarray, dlat: float, dlon: np.ndarray) -> np.ndarray:
    """:func:`igp_key` of the corners (NE, NW, SW, SE) of cells given by their south-west corner (multiples
    of 5 deg, ``lo0`` possibly outside [-180, 180)) and size, in integers: longitudes wrap by a modulo."""
    i = ((la0 + 90) / 5).astype(np.int64) * 72
    i_n = i + round(dlat / 5) * 72
    j_w = ((lo0 + 180) / 5).astype(np.int64) % 72
    j_e = (j_w + (dlon / 5).astype(np.int64)) % 72
    return np.stack([i_n + j_e, i_n + j_w, i + j_w, i + j_e], axis=-1)


#: Per 4-bit corner code (bit k: corner k, in the order NE, NW, SW, SE): the number of corners, and for
#: three corners the one left out.
_N_CORNERS = np.array([bin(c).count("1") for c in range(16)])
_LEFT_OUT = np.array([(~c & 15).bit_length() - 1 if bin(c).count("1") == 3 else 0 for c in range(16)])


def _code(corners: np.ndarray) -> np.ndarray:
    """(n, 4) bool -> (n,) uint8 with bit k set for corner k (shifts of the bytes of the bools: the numbers
    of ``np.packbits(..., bitorder="little")``, six times faster)."""
    c = np.asarray(corners, bool).view(np.uint8)
    return c[:, 0] | (c[:, 1] << 1) | (c[:, 2] << 2) | (c[:, 3] << 3)


def _triangle_inside(code: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
    """For cells with three corners (``code``): the left-out corner, weights, and whether (x, y) is inside."""
    missing = _LEFT_OUT[code]
    w3 = _triangle_weights(x, y, missing)
    return missing, w3, (w3 >= -1e-12).all(axis=1)


def select_and_interpolate(
    lat_pp_deg: np.ndarray,
    lon_pp_deg: np.ndarray,
    in_mask: Callable[..., np.ndarray],
    status: Callable[..., tuple[np.ndarray, np.ndarray]],
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
    in_mask : ``in_mask(rows, key)`` -> (len(rows), 4) bool, the IGP of :func:`igp_key` ``key``
        ((len(rows), 4) int; :func:`igp_position` gives its latitude and longitude) is in the mask in
        force at pierce point ``rows``' epoch (``rows`` index the inputs).
    status : ``status(rows, key)`` -> (usable, dont_use), each (len(rows), 4) bool.
    """
    lat = np.asarray(lat_pp_deg, float)
    lon = np.asarray(lon_pp_deg, float)
    n = lat.size
    mid = np.abs(lat) <= 60
    todo = mid | ((np.abs(lat) > 60) & (np.abs(lat) <= 75))
    idx = np.flatnonzero(todo)
    at = slice(None) if idx.size == n else idx  # usually every point: views, not gathers
    # the selected cell per pierce point: south-west corner, size, corner keys, corners in the mask
    la0 = np.floor(lat / 5) * 5
    lo0 = np.where(mid, np.floor(lon / 5) * 5, np.floor(lon / 10) * 10)
    dlon = np.where(mid, 5.0, 10.0)
    key = np.zeros((n, 4), np.int64)
    x = (lon - lo0) / dlon  # lo0 <= lon < lo0 + 15 (lo0 not wrapped): no wrap
    y = (lat - la0) / 5.0
    # (a), (b): the first cell, tried for every pierce point at once (most end here with four IGPs)
    key[at] = _corner_keys(la0[at], lo0[at], 5.0, dlon[at])
    code = np.zeros(n, np.uint8)
    code[at] = _code(in_mask(idx, key[at]))
    found = code == 15
    three = np.flatnonzero(todo & (_N_CORNERS[code] == 3))
    found[three] = _triangle_inside(code[three], x[three], y[three])[2]

    def take(rest: np.ndarray, la_c: np.ndarray, lo_c: np.ndarray, dlat_c: float, dlon_c: float,
             want: int) -> None:  # fmt: skip
        """Try one 10x10 cell for the pierce points ``rest``; keep those with ``want`` (4 or 3) corners in
        the mask (three: their triangle containing the pierce point)."""
        ok_geom = np.isfinite(lo_c)
        rest, la_c, lo_c = rest[ok_geom], la_c[ok_geom], lo_c[ok_geom]
        if rest.size == 0:
            return
        k = _corner_keys(la_c, lo_c, dlat_c, np.full(rest.size, dlon_c))
        c = _code(in_mask(rest, k))
        xx = (lon[rest] - lo_c) / dlon_c
        yy = (lat[rest] - la_c) / dlat_c
        good = c == 15 if want == 4 else _N_CORNERS[c] == 3
        if want == 3:
            good[good] = _triangle_inside(c[good], xx[good], yy[good])[2]  # only where three are in the mask
        g = rest[good]
        found[g], key[g], code[g], x[g], y[g] = True, k[good], c[good], xx[good], yy[good]

    for want in (4, 3):  # (c), (d): the 10x10 cells, for the pierce points still without one
        for j in range(4):
            rest = idx[~found[idx]]
            take(rest, *_candidates(lat[rest], lon[rest])[j], want)

    fail = np.where(todo, FAIL_NO_CELL, FAIL_POLAR)
    ok = np.zeros(n, bool)
    weights = np.zeros((n, 4))
    mode = np.full(n, -1)
    key[np.flatnonzero(~found)] = -1
    f = np.flatnonzero(found)
    if f.size:
        usable, dnu = status(f, key[f])
        s = code[f]
        good_c = s & _code(usable)  # selected and usable
        n_sel, n_good = _N_CORNERS[s], _N_CORNERS[good_c]
        four = good_c == 15
        dont = (s & _code(dnu)) != 0
        xf, yf = x[f], y[f]
        w = np.stack([xf * yf, (1 - xf) * yf, (1 - xf) * (1 - yf), xf * (1 - yf)], axis=-1)
        m_f = np.where(four, 0, -1)
        # triangles only where one is asked for: three selected, or four with one unusable
        tri = np.flatnonzero(n_good == 3)
        missing, w3, inside = _triangle_inside(good_c[tri], xf[tri], yf[tri])
        three_ok = np.zeros(f.size, bool)
        three_ok[tri] = (n_sel[tri] == 3) | inside
        good = (four | three_ok) & ~dont
        w[tri] = w3
        m_f[tri] = np.where(three_ok[tri], missing + 1, -1)
        ok[f] = good
        w[~good] = 0.0
        weights[f] = w
        mode[f] = np.where(good, m_f, -1)
        outside = (n_sel == 4) & (n_good == 3) & ~three_ok
        fail[f] = np.select([good, dont, outside], [0, FAIL_DONT_USE, FAIL_OUTSIDE], FAIL_UNUSABLE)
    return GridSelection(ok, key, weights, mode, fail)
