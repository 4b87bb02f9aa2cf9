"""Closed-form WGS-84 geodesy for tests and fixture generators, independent of pymap3d.

Geodetic -> ECEF (NIMA TR8350.2, a = 6378137 m, 1/f = 298.257223563) and the ECEF -> local
east-north-up rotation, in plain ``math``, so that the readers' numbers (computed with pymap3d)
are checked against a second implementation.
"""

from __future__ import annotations

import math

A, F = 6378137.0, 1 / 298.257223563
E2 = F * (2 - F)


def ecef(lat: float, lon: float, h: float) -> tuple[float, float, float]:
    """ECEF (m) of a geodetic point (degrees, degrees, ellipsoidal metres)."""
    p, lam = math.radians(lat), math.radians(lon)
    n = A / math.sqrt(1 - E2 * math.sin(p) ** 2)
    return (
        (n + h) * math.cos(p) * math.cos(lam),
        (n + h) * math.cos(p) * math.sin(lam),
        (n * (1 - E2) + h) * math.sin(p),
    )


def enu(
    lat: float, lon: float, h: float, ref_lat: float, ref_lon: float, ref_h: float
) -> tuple[float, float, float]:
    """East, north, up (m) of a geodetic point relative to a geodetic reference."""
    x, y, z = ecef(lat, lon, h)
    x0, y0, z0 = ecef(ref_lat, ref_lon, ref_h)
    dx, dy, dz = x - x0, y - y0, z - z0
    p, lam = math.radians(ref_lat), math.radians(ref_lon)
    e = -math.sin(lam) * dx + math.cos(lam) * dy
    n = -math.sin(p) * math.cos(lam) * dx - math.sin(p) * math.sin(lam) * dy + math.cos(p) * dz
    u = math.cos(p) * math.cos(lam) * dx + math.cos(p) * math.sin(lam) * dy + math.sin(p) * dz
    return e, n, u
