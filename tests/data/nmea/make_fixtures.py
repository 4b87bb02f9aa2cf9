"""Write the NMEA GFA fixture with pynmeagps's own encoder (no real GFA recording exists; see PROVENANCE.md).

    python tests/data/nmea/make_fixtures.py      # writes tests/data/nmea/gfa_sbas.nmea.gz

Ten minutes at 1 Hz across a UTC midnight (2016-12-31 23:55 to 2017-01-01 00:05: the leap second of
2016-12-31 changes GPS-UTC from 17 to 18 s), a receiver at a fixed position with small scatter, each
second ``RMC`` (date), ``GGA`` (position, fix quality 2 = SBAS), ``GFA`` (HPL, VPL, integrity status
``VSV``: SBAS safe) and a ``GBS``. Quirks, at known seconds: a GFA with a bad checksum (second 30), a GGA
with quality 0 (second 60: no solution), a GFA with empty protection levels (second 90), a GFA whose SBAS
integrity is ``U`` (second 120: alert), no RMC after midnight for 60 s (the day must roll over by
itself), a comment line and a blank line. Seeded: the same bytes every run.
"""

from __future__ import annotations

import datetime as dt
import gzip
from pathlib import Path

import numpy as np
from pynmeagps import NMEAMessage

OUT = Path(__file__).with_name("gfa_sbas.nmea.gz")
START = dt.datetime(2016, 12, 31, 23, 55, 0)
SECONDS = 600
LAT, LON, ALT, SEP = 50.848642, 4.732128, 80.93, 47.40


def sentences() -> list[bytes]:
    rng = np.random.default_rng(16)
    out = [b"# gfa_sbas: written by tests/data/nmea/make_fixtures.py with pynmeagps\r\n", b"\r\n"]
    for k in range(SECONDS):
        t = START + dt.timedelta(seconds=k)
        dn, de, du = rng.normal(0.0, (0.5, 0.5, 0.9))
        lat, lon = LAT + dn / 111_200.0, LON + de / (111_200.0 * np.cos(np.radians(LAT)))
        if not (
            t.date() == dt.date(2017, 1, 1) and t.time() < dt.time(0, 1, 0)
        ):  # no RMC for 60 s after midnight
            rmc = {
                "status": "A",
                "lat": lat,
                "NS": "N",
                "lon": lon,
                "EW": "E",
                "date": t.date(),
                "posMode": "D",
            }
            out.append(NMEAMessage("GN", "RMC", 0, time=t.time(), **rmc).serialize())
        quality = 0 if k == 60 else 2
        gga = {"lat": lat, "NS": "N", "lon": lon, "EW": "E", "quality": quality, "numSV": 14, "HDOP": 0.7,
               "alt": round(ALT + du, 2), "altUnit": "M", "sep": SEP, "sepUnit": "M"}  # fmt: skip
        out.append(NMEAMessage("GN", "GGA", 0, time=t.time(), **gga).serialize())
        hpl, vpl = round(9.0 + 2.0 * rng.random(), 2), round(13.0 + 3.0 * rng.random(), 2)
        integrity = "VUV" if k == 120 else "VSV"
        gfa = NMEAMessage("GN", "GFA", 0, time=t.time(), hprotlvl=hpl, vprotlvl=vpl, semimajstddev=0.6,
                          semiminstddev=0.5, semimajorientation=12.0, altstddev=0.9, accuracy=1.2,
                          integrity=integrity).serialize()  # fmt: skip
        if k == 90:  # empty protection levels
            body = gfa[1:].split(b"*")[0].split(b",")
            body[2] = body[3] = b""
            text = b",".join(body)
            check = 0
            for c in text:
                check ^= c
            gfa = b"$" + text + f"*{check:02X}\r\n".encode()
        if k == 30:  # a corrupt checksum
            gfa = gfa[:-4] + (b"00" if gfa[-4:-2] != b"00" else b"11") + b"\r\n"
        out.append(gfa)
        out.append(NMEAMessage("GN", "GBS", 0, time=t.time(), errLat=0.9, errLon=0.9, errAlt=2.9).serialize())
    return out


if __name__ == "__main__":
    OUT.write_bytes(gzip.compress(b"".join(sentences()), mtime=0))
    print(OUT, OUT.stat().st_size, "bytes")
