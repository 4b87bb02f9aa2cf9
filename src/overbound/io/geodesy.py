"""The true antenna position and position errors in its local east-north-up frame.

Conversions use :mod:`pymap3d` on the WGS-84 ellipsoid (NIMA TR8350.2), vectorised.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pymap3d

from overbound.io.schema import InputError

__all__ = [
    "MEAN_POSITION",
    "MeanPosition",
    "Reference",
    "enu_errors_along",
    "enu_errors_ecef",
    "enu_errors_geodetic",
    "reference_text",
    "resolve",
    "resolve_geodetic",
]


@dataclass(frozen=True, slots=True)
class Reference:
    """True antenna position, geodetic WGS-84 (degrees, degrees, ellipsoidal metres)."""

    lat_deg: float
    lon_deg: float
    height_m: float

    @classmethod
    def parse(cls, text: str) -> Reference:
        """From ``"lat,lon,h"`` (degrees, degrees, metres).

        >>> Reference.parse("35.311803,-120.661092,134.6419").height_m
        134.6419
        """
        lat, lon, h = _three_floats(text, "lat,lon,h")
        if not -90 <= lat <= 90 or not -180 <= lon <= 360:
            raise ValueError(
                f"reference {text!r}: latitude must be in [-90, 90] and longitude in [-180, 360]"
            )
        return cls(lat, lon, h)

    @classmethod
    def parse_ecef(cls, text: str) -> Reference:
        """From ``"x,y,z"`` ECEF metres.

        >>> r = Reference.parse_ecef("-2657201.1481,-4482167.4171,3666227.1204")
        >>> round(r.lat_deg, 4), round(r.lon_deg, 4)
        (35.3118, -120.6611)
        """
        x, y, z = _three_floats(text, "x,y,z")
        if np.hypot(np.hypot(x, y), z) < 6.0e6:
            raise ValueError(f"reference-ecef {text!r}: not an ECEF position (norm below 6000 km)")
        lat, lon, h = pymap3d.ecef2geodetic(x, y, z)
        return cls(float(lat), float(lon), float(h))

    def to_ecef(self) -> tuple[float, float, float]:
        x, y, z = pymap3d.geodetic2ecef(self.lat_deg, self.lon_deg, self.height_m)
        return float(x), float(y), float(z)

    def __str__(self) -> str:
        return f"{self.lat_deg:.9f},{self.lon_deg:.9f},{self.height_m:.4f}"


@dataclass(frozen=True, slots=True)
class MeanPosition:
    """No truth: the errors are taken against the mean of the receiver's own positions (``--reference
    mean``, a static receiver without a surveyed position). They then show the scatter of the solution
    about its mean, not its bias: a constant error of the receiver is invisible, and the HPE and VPE
    are a lower bound of the true errors. The mean is the ECEF mean of the positions given that are
    finite (and ``use``, when the reader says which are solutions); its geodetic value is what
    :func:`resolve` returns and the readers note."""

    def __str__(self) -> str:
        return "mean of the receiver's own positions"


#: The one :class:`MeanPosition` (``reference=MEAN_POSITION``).
MEAN_POSITION = MeanPosition()


def resolve(
    reference: Reference | MeanPosition,
    x: np.ndarray,
    y: np.ndarray,
    z: np.ndarray,
    use: np.ndarray | None = None,
    source: str = "<positions>",
) -> Reference:
    """``reference`` itself, or for :data:`MEAN_POSITION` the mean of the ECEF positions ``x``, ``y``,
    ``z`` (m) that are finite and ``use`` (:class:`InputError` naming ``source`` when none is)."""
    if isinstance(reference, Reference):
        return reference
    xyz = np.column_stack([np.asarray(v, float) for v in (x, y, z)])
    ok = np.isfinite(xyz).all(axis=1) & (True if use is None else np.asarray(use, bool))
    if not ok.any():
        raise InputError(source, "reference mean: no position to average (no epoch with a solution)")
    mx, my, mz = (float(v) for v in xyz[ok].mean(axis=0))
    lat, lon, h = pymap3d.ecef2geodetic(mx, my, mz)
    return Reference(float(lat), float(lon), float(h))


def resolve_geodetic(
    reference: Reference | MeanPosition,
    lat_deg: np.ndarray,
    lon_deg: np.ndarray,
    height_m: np.ndarray,
    use: np.ndarray | None = None,
    source: str = "<positions>",
) -> Reference:
    """:func:`resolve` of geodetic positions (deg, deg, ellipsoidal m)."""
    if isinstance(reference, Reference):
        return reference
    return resolve(reference, *pymap3d.geodetic2ecef(lat_deg, lon_deg, height_m), use, source)


def reference_text(asked: Reference | MeanPosition, used: Reference) -> str:
    """How a reader names the reference its errors are against: ``used``, and for
    :data:`MEAN_POSITION` that it is the mean of the receiver's own positions, not truth."""
    if isinstance(asked, MeanPosition):
        return f"{used} (the mean of the receiver's own positions, not truth)"
    return str(used)


def _three_floats(text: str, what: str) -> tuple[float, float, float]:
    parts = text.replace(" ", "").split(",")
    try:
        if len(parts) != 3:
            raise ValueError
        a, b, c = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"reference {text!r}: expected {what}") from None
    return a, b, c


def enu_errors_geodetic(
    lat_deg: np.ndarray,
    lon_deg: np.ndarray,
    height_m: np.ndarray,
    ref: Reference,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """East, north, up errors (estimate minus truth) of geodetic positions (``ref``: a position, the mean
    one resolved first by :func:`resolve_geodetic`)."""
    e, n, u = pymap3d.geodetic2enu(
        np.asarray(lat_deg, float),
        np.asarray(lon_deg, float),
        np.asarray(height_m, float),
        ref.lat_deg,
        ref.lon_deg,
        ref.height_m,
    )
    return np.asarray(e, float), np.asarray(n, float), np.asarray(u, float)


def enu_errors_ecef(
    x: np.ndarray, y: np.ndarray, z: np.ndarray, ref: Reference
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """East, north, up errors (estimate minus truth) of ECEF positions (``ref``: a position, the mean one
    resolved first by :func:`resolve`)."""
    return _ecef_to_enu(x, y, z, ref.lat_deg, ref.lon_deg, ref.height_m)


def enu_errors_along(
    x: np.ndarray,
    y: np.ndarray,
    z: np.ndarray,
    truth_x: np.ndarray,
    truth_y: np.ndarray,
    truth_z: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """East, north, up errors (estimate minus truth) of ECEF positions against a truth that moves: epoch
    ``i`` in the local east-north-up frame of its own truth position ``truth_*[i]`` (ECEF m), as
    :func:`enu_errors_ecef` takes them about one fixed position (the schema's sign convention)."""
    lat, lon, h = pymap3d.ecef2geodetic(truth_x, truth_y, truth_z)
    return _ecef_to_enu(x, y, z, lat, lon, h)


def _ecef_to_enu(x, y, z, lat0, lon0, h0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    # pymap3d broadcasts the origin: one fixed position, or one per epoch
    e, n, u = pymap3d.ecef2enu(
        np.asarray(x, float), np.asarray(y, float), np.asarray(z, float), lat0, lon0, h0
    )
    return np.asarray(e, float), np.asarray(n, float), np.asarray(u, float)
