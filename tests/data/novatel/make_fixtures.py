"""Write the NovAtel OEM7 fixtures with novatel-edie's own encoder (no public recording of RAIMSTATUS
with valid protection levels exists; see PROVENANCE.md).

    python tests/data/novatel/make_fixtures.py   # writes bestpos_raimstatus.asc.gz and .bin.gz here

Five minutes at 1 Hz (GPS week 2300, from 345,600 s), a static receiver in Calgary with small scatter:
each second a BESTPOS (SOL_COMPUTED, position type WAAS, orthometric height and undulation -16.875 m,
base ID "138", the WAAS GEO) and a RAIMSTATUS (mode DEFAULT, integrity PASS, HPL 8-15 m and VPL
12-25 m, both PASS). The messages are built as ``novatel_edie.oem.messages.BESTPOS`` / ``RAIMSTATUS``
objects and written by their ``to_ascii()`` (``#BESTPOSA``...) and ``to_binary()`` (sync AA 44 12)
encoders; the values are rounded to what the ASCII form prints (HPL/VPL mm, heights 0.1 mm,
latitude/longitude 1e-9 deg), so both files decode to the same numbers. Quirks at known seconds:

* 40-49: HPL and VPL status NOT_AVAILABLE with 0.000 (as in the OEM7 manual's RAIMSTATUS example),
  integrity NOT_AVAILABLE;
* 100: VPL status ALERT (VPL 55 m); 150: integrity status FAIL;
* 120: position type SINGLE (SBAS lost for a second);
* 200: solution status INSUFFICIENT_OBS, position type NONE (no solution);
* 230-239: nothing logged (a gap);
* 260: the RAIMSTATUS record corrupted (one byte changed, its CRC fails);
* the file cut inside the last record.

Seeded: the same bytes every run.
"""

from __future__ import annotations

import gzip
from pathlib import Path

import novatel_edie as ne
import numpy as np
from novatel_edie.oem import Header
from novatel_edie.oem import enums as E
from novatel_edie.oem import messages as M

HERE = Path(__file__).parent
WEEK, MS0, SECONDS = 2300, 345_600_000, 300
LAT, LON, H_MSL, UNDULATION = 51.116_350, -114.038_900, 1048.200, -16.875
GAP = range(230, 240)
PL = E.RAIMProtectionLevelStatus


def _header(k: int) -> Header:
    return Header(
        week=WEEK, milliseconds=float(MS0 + 1000 * k), time_status=ne.TIME_STATUS.FINESTEERING,
        port_address=0x20, idle_time=100, receiver_sw_version=16809,
    )  # fmt: skip


def _bestpos(k: int, rng: np.random.Generator):
    dn, de, du = rng.normal(0.0, (0.5, 0.5, 0.9))
    status, ptype = E.SolStatus.SOL_COMPUTED, E.SolType.WAAS
    if k == 120:
        ptype = E.SolType.SINGLE
    if k == 200:
        status, ptype = E.SolStatus.INSUFFICIENT_OBS, E.SolType.NONE
    return M.BESTPOS(
        _header(k), solution_status=status, position_type=ptype,
        latitude=round(LAT + dn / 111_200.0, 9),
        longitude=round(LON + de / (111_200.0 * np.cos(np.radians(LAT))), 9),
        orthometric_height=round(H_MSL + du, 4), undulation=UNDULATION, datum_id=E.Datum.WGS84,
        latitude_std_dev=0.625, longitude_std_dev=0.5, height_std_dev=1.25, base_id="138",
        diff_age=float(3 + k % 5), solution_age=0.0, num_svs=14, num_soln_svs=12 - (k % 3),
        num_soln_L1_svs=12 - (k % 3), num_soln_multi_svs=0, extended_solution_status2=0, ext_sol_stat=0,
        gal_and_bds_mask=0, gps_and_glo_mask=1,
    )  # fmt: skip


def _raimstatus(k: int, rng: np.random.Generator):
    hpl, vpl = round(float(rng.uniform(8.0, 15.0)), 3), round(float(rng.uniform(12.0, 25.0)), 3)
    integrity, hs, vs = E.RAIMIntegrityStatus.PASS, PL.PASS, PL.PASS
    if 40 <= k < 50:
        integrity, hs, vs, hpl, vpl = (
            E.RAIMIntegrityStatus.NOT_AVAILABLE,
            PL.NOT_AVAILABLE,
            PL.NOT_AVAILABLE,
            0.0,
            0.0,
        )
    if k == 100:
        vs, vpl = PL.ALERT, 55.0
    if k == 150:
        integrity = E.RAIMIntegrityStatus.FAIL
    return M.RAIMSTATUS(
        _header(k), mode=E.RAIMMode.DEFAULT, integrity_status=integrity, hpl_status=hs, hpl=hpl,
        vpl_status=vs, vpl=vpl,
    )  # fmt: skip


def records(binary: bool) -> list[bytes]:
    rng = np.random.default_rng(16)
    out = []
    for k in range(SECONDS):
        pos, raim = _bestpos(k, rng), _raimstatus(k, rng)  # drawn in the gap too: the same values either way
        if k in GAP:
            continue
        for msg in (pos, raim):
            out.append(bytes((msg.to_binary() if binary else msg.to_ascii()).message))
        if k == 260:  # a changed byte inside the RAIMSTATUS payload: its CRC fails
            bad = bytearray(out[-1])
            bad[len(bad) // 2 + 5] ^= 0x01
            out[-1] = bytes(bad)
    out[-1] = out[-1][: len(out[-1]) // 2]  # the recording stops inside the last record
    return out


if __name__ == "__main__":
    for name, binary in (("bestpos_raimstatus.asc.gz", False), ("bestpos_raimstatus.bin.gz", True)):
        path = HERE / name
        path.write_bytes(gzip.compress(b"".join(records(binary)), mtime=0))
        print(path, path.stat().st_size, "bytes")
