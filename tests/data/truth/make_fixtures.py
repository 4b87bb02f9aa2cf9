"""Write the moving-receiver fixtures of ``--truth`` (issue 16): a rover on a known trajectory and its truth.

    python tests/data/truth/make_fixtures.py      # writes tests/data/truth/*.gz

The trajectory is analytic: in the local east-north-up frame of USLO (35.311803 N, 120.661092 W,
134.6419 m) the antenna circles at radius ``R`` with angular rate ``OMEGA`` and climbs at ``CLIMB``:
``(R cos wt, R sin wt, 10 + CLIMB t)`` m, ``t`` seconds from 2006-12-27 01:00:00 GPS time (GPS-UTC 14 s
then). ECEF and geodetic positions come from :mod:`pymap3d` (WGS-84).

* ``rover.pos.gz``: the receiver, an RTKLIB ``.pos`` with ``hpl``/``vpl`` (the layout of RTKLIB-MOPS,
  ``tests/data/rtklib-pos``), epochs at ``t = 0.5, 1.5, ..., 299.5`` s; its position is the true one
  plus ``ERROR_ENU`` in the local east-north-up frame of the true position, so every error is exactly
  ``ERROR_ENU``; Q = 0 (no solution) at ``t = 102.5``.
* ``rover-truth.pos.gz``: the truth, RTKLIB ``.pos`` latitude/longitude/height in GPST, samples at whole
  seconds 10 to 290 without 101-104 (a 5 s gap), Q = 2 (float) at 200-209, Q = 1 (fix) else.
* ``rover-truth-xyz-utc.pos.gz``: the same samples as x/y/z-ecef, times in UTC.
* ``rover-truth.csv.gz``: the same samples as CSV ``time,lat,lon,height`` (ISO GPS time).
* ``rover-truth-ecef.csv.gz``: the same samples as CSV ``week,tow,x,y,z``.

Numbers are written as RTKLIB writes them (``%14.9f`` degrees, ``%10.4f``/``%14.4f`` metres): 0.1 mm.
Deterministic: the same bytes every run (gzip mtime 0).
"""

from __future__ import annotations

import datetime as dt
import gzip
from pathlib import Path

import numpy as np
import pymap3d

HERE = Path(__file__).parent
CENTRE = (35.311803, -120.661092, 134.6419)
START = dt.datetime(2006, 12, 27, 1, 0, 0)  # GPS time
GPS_UTC_S = 14
R, OMEGA, CLIMB = 500.0, 0.04, 0.5  # m, rad/s, m/s
ERROR_ENU = (1.0, -2.0, 3.0)  # m, estimate minus truth
ROVER_T = np.arange(300) + 0.5
NO_SOLUTION_T = 102.5
TRUTH_T = np.array([t for t in range(10, 291) if not 101 <= t <= 104], dtype=float)
FLOAT_T = range(200, 210)
GPS_EPOCH = dt.datetime(1980, 1, 6)

_HEAD = """% program   : overbound tests/data/truth/make_fixtures.py (RTKLIB .pos layout)
% inp file  : {what}
% pos mode  : {mode}
%
% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)
"""


def true_enu(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The trajectory in the ENU frame of CENTRE (m)."""
    return R * np.cos(OMEGA * t), R * np.sin(OMEGA * t), 10.0 + CLIMB * t


def true_geodetic(t: np.ndarray):
    return pymap3d.enu2geodetic(*true_enu(t), *CENTRE)


def rover_geodetic(t: np.ndarray):
    lat, lon, h = true_geodetic(t)
    x, y, z = pymap3d.enu2ecef(*ERROR_ENU, lat, lon, h)  # the error in the true position's own frame
    return pymap3d.ecef2geodetic(x, y, z)


def _stamp(t: float, shift_s: float = 0.0) -> str:
    return (START + dt.timedelta(seconds=t - shift_s)).strftime("%Y/%m/%d %H:%M:%S.%f")[:-3]


def rover_pos() -> str:
    lat, lon, h = rover_geodetic(ROVER_T)
    columns = "%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns hpl (m) vpl (m)\n"
    rows = [_HEAD.format(what="rover (constructed)", mode="sbas"), columns]
    for k, t in enumerate(ROVER_T):
        q = 0 if t == NO_SOLUTION_T else 3
        hpl, vpl = 12.0 + (k % 7), 18.0 + (k % 5)
        rows.append(
            f"{_stamp(t)} {lat[k]:14.9f} {lon[k]:14.9f} {h[k]:10.4f} {q:3d} {8:3d} {hpl:7.2f} {vpl:7.1f}\n"
        )
    return "".join(rows)


def _q(t: float) -> int:
    return 2 if t in FLOAT_T else 1


def truth_pos(columns: str, system: str) -> str:
    """The truth as RTKLIB writes it: ``columns`` ``"llh"`` or ``"xyz"``, times in ``system`` (GPST, UTC)."""
    lat, lon, h = true_geodetic(TRUTH_T)
    if columns == "llh":
        names, formats, values = (
            "latitude(deg) longitude(deg)  height(m)",
            ("14.9f", "14.9f", "10.4f"),
            (lat, lon, h),
        )
    else:
        names, formats = "    x-ecef(m)      y-ecef(m)      z-ecef(m)", ("14.4f", "14.4f", "14.4f")
        values = pymap3d.geodetic2ecef(lat, lon, h)
    fields = [
        " ".join(format(v, f) for v, f in zip(row, formats, strict=True)) for row in zip(*values, strict=True)
    ]
    shift = GPS_UTC_S if system == "UTC" else 0
    rows = [_HEAD.format(what="truth (constructed)", mode="kinematic"),
            f"%  {system:<4}                  {names}   Q  ns\n"]  # fmt: skip
    rows += [f"{_stamp(t, shift)} {fields[k]} {_q(t):3d} {9:3d}\n" for k, t in enumerate(TRUTH_T)]
    return "".join(rows)


def truth_csv_llh() -> str:
    lat, lon, h = true_geodetic(TRUTH_T)
    rows = ["# truth trajectory, GPS time; tests/data/truth/make_fixtures.py\n", "time,lat,lon,height\n"]
    rows += [f"{(START + dt.timedelta(seconds=t)).isoformat()},{lat[k]:.9f},{lon[k]:.9f},{h[k]:.4f}\n"
             for k, t in enumerate(TRUTH_T)]  # fmt: skip
    return "".join(rows)


def truth_csv_ecef() -> str:
    x, y, z = pymap3d.geodetic2ecef(*true_geodetic(TRUTH_T))
    rows = ["week,tow,x,y,z\n"]
    for k, t in enumerate(TRUTH_T):
        s = (START + dt.timedelta(seconds=t) - GPS_EPOCH).total_seconds()
        rows.append(f"{int(s // 604800)},{s % 604800:.3f},{x[k]:.4f},{y[k]:.4f},{z[k]:.4f}\n")
    return "".join(rows)


def _write(name: str, text: str) -> None:
    with (HERE / name).open("wb") as f, gzip.GzipFile(filename="", mode="wb", fileobj=f, mtime=0) as gz:
        gz.write(text.encode())


def main() -> None:
    _write("rover.pos.gz", rover_pos())
    _write("rover-truth.pos.gz", truth_pos("llh", "GPST"))
    _write("rover-truth-xyz-utc.pos.gz", truth_pos("xyz", "UTC"))
    _write("rover-truth.csv.gz", truth_csv_llh())
    _write("rover-truth-ecef.csv.gz", truth_csv_ecef())


if __name__ == "__main__":
    main()
