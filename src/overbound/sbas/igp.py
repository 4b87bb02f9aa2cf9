"""Ionospheric grid point (IGP) bands of the MT 18 mask: where each mask bit is on the globe.

DO-229D appendix A (MT 18, IGP mask) defines 11 bands. Bands 0-8 are 40-degree wide strips of
longitude, from 180 W eastwards; each holds eight meridians 5 degrees apart, and the bits of a
band run meridian by meridian from west to east, each meridian from south to north:

* meridians at an odd multiple of 5 degrees carry 23 IGPs, 55 S to 55 N every 5 degrees;
* the other meridians add 65 and 75 degrees on both sides (27 IGPs);
* 85 N is added at 180 W, 90 W, 0 and 90 E, and 85 S at 140 W, 50 W, 40 E and 130 E (28 IGPs).

Bands 9 (north) and 10 (south) are polar caps read ring by ring from 60 degrees poleward, each
ring from 180 W eastwards: 60 degrees every 5 degrees of longitude (72), 65, 70 and 75 every 10
degrees (36 each) and 85 every 30 degrees (12), from 180 W in band 9 and from 170 W in band 10.
Bands 0-7 have 201 bits, band 8 has 200 and bands 9-10 have 192; the MT 18 mask field is always
201 bits wide and the rest is unused.

The tables are generated from these rules, not typed in.
"""

from __future__ import annotations

from functools import cache

import numpy as np

__all__ = ["BAND_SIZES", "N_BANDS", "band_igps"]

N_BANDS = 11
_NORTH_85 = (-180, -90, 0, 90)
_SOUTH_85 = (-140, -50, 40, 130)


def _meridian(lon: int) -> list[int]:
    lats = list(range(-55, 56, 5))
    if lon % 10:
        return lats
    lats = [-75, -65, *lats, 65, 75]
    if lon in _NORTH_85:
        lats.append(85)
    if lon in _SOUTH_85:
        lats.insert(0, -85)
    return lats


@cache
def band_igps(band: int) -> tuple[np.ndarray, np.ndarray]:
    """Latitudes and longitudes (degrees, int16) of the IGPs of ``band``, in mask-bit order.

    Element ``k`` is the IGP of mask bit ``k + 1``.

    >>> lat, lon = band_igps(4)
    >>> len(lat), (int(lat[0]), int(lon[0])), (int(lat[26]), int(lon[26])), (int(lat[27]), int(lon[27]))
    (201, (-75, -20), (75, -20), (-55, -15))
    """
    if not 0 <= band < N_BANDS:
        raise ValueError(f"IGP band {band} outside 0..10")
    lat: list[int] = []
    lon: list[int] = []
    if band <= 8:
        for m in range(-180 + 40 * band, -180 + 40 * band + 40, 5):
            col = _meridian(m)
            lat += col
            lon += [m] * len(col)
    else:
        sign = 1 if band == 9 else -1
        rings = (
            (60, 5, -180),
            (65, 10, -180),
            (70, 10, -180),
            (75, 10, -180),
            (85, 30, -180 if band == 9 else -170),
        )
        for ring_lat, step, start in rings:
            lons = list(range(start, start + 360, step))
            lat += [sign * ring_lat] * len(lons)
            lon += lons
    return np.asarray(lat, dtype=np.int16), np.asarray(lon, dtype=np.int16)


#: Number of IGPs (used mask bits) per band.
BAND_SIZES: tuple[int, ...] = tuple(len(band_igps(b)[0]) for b in range(N_BANDS))
