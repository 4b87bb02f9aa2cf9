"""Reader for IONEX global ionosphere maps, and the slant ionospheric delay they give.

Format (IONEX 1.0, Schaer, Gurtner & Feltens 1998)
--------------------------------------------------
A header whose labels sit in columns 61-80 (``EPOCH OF FIRST MAP``, ``INTERVAL``, ``MAPPING
FUNCTION``, ``BASE RADIUS``, ``HGT1 / HGT2 / DHGT``, ``LAT1 / LAT2 / DLAT``, ``LON1 / LON2 /
DLON``, ``EXPONENT``...; an optional ``START/END OF AUX DATA`` block of differential code
biases), then maps: ``START OF TEC MAP`` with its ``EPOCH OF CURRENT MAP`` and, per latitude, a
``LAT/LON1/LON2/DLON/H`` line followed by the values of the longitudes, 16 per line in ``I5``,
in units of ``10**EXPONENT`` TECU (an ``EXPONENT`` line inside a map overrides the header's for
that map); ``9999`` means no value. ``RMS`` maps have the same layout. Only 2-D maps (one
height) are read; epochs are UT (the specification), stored here as GPS time.

Accounting (kept + rejected = read)
-----------------------------------
The rows of the report are the grid values of the TEC maps. A map is rejected whole, with its
values, as ``bad_epoch`` (unreadable or missing epoch line), ``duplicate_map`` (an epoch already
read), ``bad_row`` (a latitude row that is not on the header's grid, or short of values) or
``incomplete_map`` (not every latitude of the grid). A kept value of ``9999`` is ``NaN`` in
:attr:`Ionex.tec` and counted as ``invalidated: no_value``.

Slant delay
-----------
:func:`slant_delay_l1` follows the specification's recommendation (section 2.3): the
ionosphere as a single layer at the map height ``H`` above a sphere of the ``BASE RADIUS``
``R``; the pierce point of the line of sight; the vertical TEC there from the two maps around
the time, each rotated with the Sun (eq. 3, ``lambda' = lambda + (t - T_i)`` at 360 deg per day)
and interpolated bilinearly in its grid cell (eq. 2); the slant TEC through the ``COSZ``
mapping ``1 / cos z'``, ``sin z' = R / (R + H) sin z``; the delay ``40.3e16 / f1**2`` m per
TECU. Choices where the specification leaves room: the receiver's geodetic latitude and the
elevation and azimuth of its local (ellipsoidal) vertical enter the spherical pierce-point
formulas (as RTKLIB's ``ionppp`` and gLAB do), and longitudes wrap around the globe.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from overbound.io._rinex import US, civil_to_us, load_bytes, to_gpst
from overbound.io.open import Source, source_name
from overbound.io.schema import InputError, ReadReport

__all__ = ["L1_DELAY_PER_TECU", "Ionex", "pierce_points", "read_ionex", "slant_delay_l1", "vertical_tec"]

F_L1 = 1575.42e6
#: Group delay on L1 of one TEC unit (10**16 electrons/m**2), m: 40.3e16 / f1**2.
L1_DELAY_PER_TECU = 40.3e16 / F_L1**2
_NO_VALUE = 9999
_DAY_S = 86_400.0


@dataclass(frozen=True, slots=True, eq=False)
class Ionex:
    """Vertical TEC maps on a latitude/longitude grid at one height.

    Attributes
    ----------
    time : map epochs, int64 GPS microseconds since 1970, increasing.
    lat, lon : grid latitudes and longitudes, degrees, in the file's order (latitudes usually
        from north to south).
    tec : vertical TEC, TECU, (n_maps, n_lat, n_lon); NaN where the file has no value.
    rms : its RMS maps where the file has them (same shape), else None.
    height_km, base_radius_km : the single-layer height and the Earth radius of the maps.
    mapping_function : ``COSZ``, ``QFAC`` or ``NONE`` as written.
    files : the files read.
    """

    time: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    tec: np.ndarray
    rms: np.ndarray | None
    height_km: float
    base_radius_km: float
    mapping_function: str
    files: tuple[str, ...] = ()
    dcb_ns: dict[str, float] = field(default_factory=dict)


@dataclass
class _Header:
    first: int = 0
    exponent: int = -1
    height: float = math.nan
    radius: float = math.nan
    mapping: str = "COSZ"
    lat: tuple[float, float, float] | None = None
    lon: tuple[float, float, float] | None = None
    dims: int = 2
    dcb: dict[str, float] = field(default_factory=dict)


def read_ionex(sources: Source | Sequence[Source]) -> tuple[Ionex, ReadReport]:
    """Read one or several IONEX files (plain or compressed) into one :class:`Ionex`.

    Several files (consecutive days) must share the grid; their maps are merged in time, the
    first file's map kept where two give the same epoch (the later one is rejected as
    ``duplicate_map``).

    Raises
    ------
    InputError
        Not an IONEX file, a 3-D file, a header without its grid or height, or no usable map.
    """
    many = isinstance(sources, Sequence) and not isinstance(sources, str | bytes)
    items = list(sources) if many else [sources]  # type: ignore[list-item]
    parts = [_read_one(s) for s in items]
    names = tuple(p["name"] for p in parts)
    first = parts[0]
    for p in parts[1:]:
        if p["lat"].shape != first["lat"].shape or not (
            np.array_equal(p["lat"], first["lat"]) and np.array_equal(p["lon"], first["lon"])
        ):
            raise InputError(p["name"], f"IONEX grid differs from that of {first['name']}")
    times, tec, rms, rejected = [], [], [], Counter()
    for p in parts:
        rejected.update(p["rejected"])
        for t, m in zip(p["time"], p["tec"], strict=True):
            if t in times:
                rejected["duplicate_map"] += m.size
                continue
            times.append(t)
            tec.append(m)
            rms.append(p["rms"].get(t))
    order = np.argsort(times, kind="stable")
    tec_all = np.stack([tec[i] for i in order])
    has_rms = all(r is not None for r in rms)
    ionex = Ionex(
        time=np.asarray(times, np.int64)[order],
        lat=first["lat"],
        lon=first["lon"],
        tec=tec_all,
        rms=np.stack([rms[i] for i in order]) if has_rms else None,
        height_km=first["header"].height,
        base_radius_km=first["header"].radius,
        mapping_function=first["header"].mapping,
        files=names,
        dcb_ns=first["header"].dcb,
    )
    n_nan = int(np.isnan(tec_all).sum())
    report = ReadReport(
        source=", ".join(names),
        format="ionex",
        rows_read=sum(p["n_read"] for p in parts),
        rows_kept=int(tec_all.size),
        rejected=dict(sorted(rejected.items())),
        invalidated={"no_value": n_nan} if n_nan else {},
        first_bad=next((p["first_bad"] for p in parts if p["first_bad"]), ""),
        notes=(
            f"{len(ionex.time)} TEC maps, {len(ionex.lat)} x {len(ionex.lon)} grid, "
            f"height {ionex.height_km:g} km, base radius {ionex.base_radius_km:g} km, "
            f"mapping {ionex.mapping_function}",
        ),
    )
    return ionex, report


def _read_one(source: Source) -> dict:
    name = source_name(source)
    lines = load_bytes(source).decode("ascii", "replace").splitlines()
    if not lines or lines[0][60:].strip() != "IONEX VERSION / TYPE":
        raise InputError(name, "not an IONEX file: no 'IONEX VERSION / TYPE' first line")
    header, body = _parse_header(lines, name)
    lat = _grid(*header.lat)  # type: ignore[misc]
    lon = _grid(*header.lon)  # type: ignore[misc]
    out = {"name": name, "header": header, "lat": lat, "lon": lon, "time": [], "tec": [], "rms": {},
           "rejected": Counter(), "n_read": 0, "first_bad": ""}  # fmt: skip
    i = body
    while i < len(lines):
        label = lines[i][60:].strip()
        if label in ("START OF TEC MAP", "START OF RMS MAP"):
            kind = label.split()[2]
            end = _find(lines, i + 1, f"END OF {kind} MAP")
            t, values, reason = _parse_map(lines[i + 1 : end], header, lat, lon, name)
            if kind == "TEC":
                out["n_read"] += values.size
                if reason:
                    out["rejected"][reason] += values.size
                    out["first_bad"] = out["first_bad"] or f"{name}:{i + 1}: {reason}"
                elif t in out["time"]:
                    out["rejected"]["duplicate_map"] += values.size
                    out["first_bad"] = out["first_bad"] or f"{name}:{i + 1}: duplicate_map"
                else:
                    out["time"].append(t)
                    out["tec"].append(values)
            elif not reason:
                out["rms"][t] = values
            i = end + 1
            continue
        if label == "END OF FILE":
            break
        i += 1
    if not out["time"]:
        raise InputError(name, "no usable TEC map in the IONEX file")
    return out


def _parse_header(lines: list[str], name: str) -> tuple[_Header, int]:
    h = _Header()
    in_aux = False
    for i, line in enumerate(lines):
        label, body = line[60:].strip(), line[:60]
        try:
            if label == "END OF HEADER":
                break
            if label == "START OF AUX DATA":
                in_aux = True
            elif label == "END OF AUX DATA":
                in_aux = False
            elif in_aux and label == "PRN / BIAS / RMS":
                h.dcb[body[3:6].strip()] = float(body[6:16])
            elif label == "EXPONENT":
                h.exponent = int(body.split()[0])
            elif label == "MAPPING FUNCTION":
                h.mapping = body.strip()
            elif label == "BASE RADIUS":
                h.radius = float(body.split()[0])
            elif label == "MAP DIMENSION":
                h.dims = int(body.split()[0])
            elif label == "HGT1 / HGT2 / DHGT":
                h1, h2, _ = (float(v) for v in body.split()[:3])
                if h1 != h2:
                    raise InputError(name, "3-D IONEX maps (several heights) are not supported", line=i + 1)
                h.height = h1
            elif label == "LAT1 / LAT2 / DLAT":
                h.lat = tuple(float(v) for v in body.split()[:3])  # type: ignore[assignment]
            elif label == "LON1 / LON2 / DLON":
                h.lon = tuple(float(v) for v in body.split()[:3])  # type: ignore[assignment]
        except (ValueError, IndexError):
            raise InputError(name, f"unreadable header line {label!r}", line=i + 1) from None
    else:
        raise InputError(name, "no 'END OF HEADER' line")
    if h.dims != 2:
        raise InputError(name, f"{h.dims}-D IONEX maps are not supported (only 2-D)")
    missing = [what for what, v in (("LAT1 / LAT2 / DLAT", h.lat), ("LON1 / LON2 / DLON", h.lon),
                                     ("HGT1 / HGT2 / DHGT", h.height), ("BASE RADIUS", h.radius))
               if v is None or (isinstance(v, float) and math.isnan(v))]  # fmt: skip
    if missing:
        raise InputError(name, f"IONEX header without {', '.join(missing)}")
    return h, i + 1


def _grid(first: float, last: float, step: float) -> np.ndarray:
    n = round((last - first) / step) + 1
    return first + step * np.arange(n)


def _find(lines: list[str], start: int, label: str) -> int:
    for j in range(start, len(lines)):
        if lines[j][60:].strip() == label:
            return j
    return len(lines)


def _parse_map(
    block: list[str], header: _Header, lat: np.ndarray, lon: np.ndarray, name: str
) -> tuple[int, np.ndarray, str]:
    """A map's epoch (GPS us), its values (TECU; NaN for 9999), and its rejection reason or ''."""
    values = np.full((len(lat), len(lon)), np.nan)
    exponent, t, seen, reason = header.exponent, -1, np.zeros(len(lat), bool), ""
    rows_per_lat = -(-len(lon) // 16)
    j = 0
    while j < len(block):
        label = block[j][60:].strip()
        if label == "EPOCH OF CURRENT MAP":
            t = _epoch(block[j][:60], name)
        elif label == "EXPONENT":
            try:
                exponent = int(block[j].split()[0])
            except (ValueError, IndexError):
                reason = reason or "bad_row"
        elif label == "LAT/LON1/LON2/DLON/H":
            row = _lat_row(block[j][:60], lat, lon)
            data = "".join(line[:80].ljust(80) for line in block[j + 1 : j + 1 + rows_per_lat])
            fields = [data[k : k + 5] for k in range(0, 5 * len(lon), 5)]
            try:
                ints = np.array([int(f) for f in fields], np.int64)
            except ValueError:
                row = -1
            if row < 0:
                reason = reason or "bad_row"
            else:
                values[row] = np.where(ints == _NO_VALUE, np.nan, ints * 10.0**exponent)
                seen[row] = True
            j += rows_per_lat
        j += 1
    if t < 0:
        return t, values, "bad_epoch"
    if reason:
        return t, values, reason
    return t, values, "" if seen.all() else "incomplete_map"


def _epoch(text: str, name: str) -> int:
    try:
        y, mo, d, h, mi, s = (int(v) for v in text.split()[:6])
    except ValueError:
        return -1
    t, ok = civil_to_us(np.array([y]), np.array([mo]), np.array([d]), np.array([h]), np.array([mi]),
                        np.array([s * US]))  # fmt: skip
    return int(to_gpst(t, "UTC", name)[0]) if ok[0] else -1


def _lat_row(text: str, lat: np.ndarray, lon: np.ndarray) -> int:
    """The grid row of a ``LAT/LON1/LON2/DLON/H`` line, -1 if it is not on the header's grid."""
    try:
        la, lo1, lo2, dlo = (float(text[k : k + 6]) for k in (2, 8, 14, 20))
    except ValueError:
        return -1
    row = np.flatnonzero(np.isclose(lat, la))
    if len(row) != 1 or not np.allclose(_grid(lo1, lo2, dlo), lon):
        return -1
    return int(row[0])


# --------------------------------------------------------------------------- slant delay


def pierce_points(
    lat_deg: np.ndarray, lon_deg: np.ndarray, elevation: np.ndarray, azimuth: np.ndarray,
    radius_km: float, height_km: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Latitude, longitude (deg) of the ionospheric pierce points and the slant factor 1/cos z'.

    Single-layer model (IONEX 1.0, section 2.3): ``sin z' = R / (R + H) cos(elevation)``; Earth
    central angle ``psi = pi/2 - elevation - z'``; ``lat_pp = asin(sin lat cos psi + cos lat sin
    psi cos A)``, ``lon_pp = lon + asin(sin psi sin A / cos lat_pp)``, with the pierce point past
    the pole (high latitudes) turned over as RTKLIB's ``ionppp`` does. Angles in radians except the
    receiver and result latitudes and longitudes.
    """
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    sin_zp = radius_km / (radius_km + height_km) * np.cos(elevation)
    psi = np.pi / 2 - elevation - np.arcsin(sin_zp)
    lat_pp = np.arcsin(np.sin(lat) * np.cos(psi) + np.cos(lat) * np.sin(psi) * np.cos(azimuth))
    dlon = np.arcsin(np.sin(psi) * np.sin(azimuth) / np.cos(lat_pp))
    over = ((lat > np.radians(70)) & (np.tan(psi) * np.cos(azimuth) > np.tan(np.pi / 2 - lat))) | (
        (lat < np.radians(-70)) & (-np.tan(psi) * np.cos(azimuth) > np.tan(np.pi / 2 + lat))
    )
    lon_pp = lon + np.where(over, np.pi - dlon, dlon)
    return np.degrees(lat_pp), np.degrees(lon_pp), 1.0 / np.sqrt(1.0 - sin_zp**2)


def vertical_tec(ionex: Ionex, time_us: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    """Vertical TEC (TECU) at GPS times and places: IONEX eq. 3 between the two maps around each
    time, each rotated by ``t - T_i`` (360 deg per day) and read bilinearly (eq. 2). NaN outside
    the maps' time span or where a grid value is missing."""
    t = np.asarray(time_us, np.int64)
    k = np.clip(np.searchsorted(ionex.time, t, side="right") - 1, 0, max(len(ionex.time) - 2, 0))
    if len(ionex.time) == 1:
        inside = t == ionex.time[0]
        return np.where(inside, _bilinear(ionex, np.zeros_like(k), lat_deg, lon_deg), np.nan)
    t0, t1 = ionex.time[k], ionex.time[k + 1]
    w = (t - t0) / (t1 - t0)
    e0 = _bilinear(ionex, k, lat_deg, lon_deg + (t - t0) / US * 360.0 / _DAY_S)
    e1 = _bilinear(ionex, k + 1, lat_deg, lon_deg + (t - t1) / US * 360.0 / _DAY_S)
    out = (1.0 - w) * e0 + w * e1
    return np.where((w >= 0) & (w <= 1), out, np.nan)


def _bilinear(ionex: Ionex, k: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    lat0, dlat = ionex.lat[0], ionex.lat[1] - ionex.lat[0]
    lon0, dlon = ionex.lon[0], ionex.lon[1] - ionex.lon[0]
    span = dlon * (len(ionex.lon) - 1)
    lon = (
        lon0 + np.mod(np.asarray(lon_deg) - lon0, 360.0) if abs(span - 360.0) < 1e-9 else np.asarray(lon_deg)
    )
    y = (np.asarray(lat_deg) - lat0) / dlat
    x = (lon - lon0) / dlon
    i = np.clip(np.floor(y).astype(np.int64), 0, len(ionex.lat) - 2)
    j = np.clip(np.floor(x).astype(np.int64), 0, len(ionex.lon) - 2)
    q, p = y - i, x - j
    m = ionex.tec
    value = ((1 - p) * (1 - q) * m[k, i, j] + p * (1 - q) * m[k, i, j + 1] + q * (1 - p) * m[k, i + 1, j]
             + p * q * m[k, i + 1, j + 1])  # fmt: skip
    outside = (q < -1e-9) | (q > 1 + 1e-9) | (p < -1e-9) | (p > 1 + 1e-9)
    return np.where(outside, np.nan, value)


def slant_delay_l1(
    ionex: Ionex, time_us: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray,
    elevation: np.ndarray, azimuth: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """Ionospheric group delay on L1 (m) of lines of sight (elevation, azimuth in radians) from
    receivers at geodetic ``lat_deg``, ``lon_deg``: slant factor x vertical TEC at the pierce
    point x :data:`L1_DELAY_PER_TECU` (see the module notes). Only ``COSZ`` maps (the IGS maps')."""
    if ionex.mapping_function.upper() != "COSZ":
        raise InputError(
            ", ".join(ionex.files), f"mapping function {ionex.mapping_function!r}: only COSZ is supported"
        )
    lat_pp, lon_pp, slant = pierce_points(
        lat_deg, lon_deg, elevation, azimuth, ionex.base_radius_km, ionex.height_km
    )
    return slant * vertical_tec(ionex, time_us, lat_pp, lon_pp) * L1_DELAY_PER_TECU
