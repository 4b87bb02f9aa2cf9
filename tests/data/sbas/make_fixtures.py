"""Build the SBAS message fixtures of tests/data/sbas/ (see PROVENANCE.md there).

Run from the repository root::

    python tests/data/sbas/make_fixtures.py [/path/to/gLAB_linux]

1. ``ems/h00.ems.gz``, ``ems/h02.ems.gz``: the real EMS hours 00 and 02 of EGNOS PRN 123 on
   2019-01-14, gzipped (``gzip -9 -n`` equivalent, so the bytes do not depend on the run), and
   ``ems/h01.ems``, the real empty hour file, copied as it is.
2. ``msas/ubx_20080526_sbas.ems.gz``: the MSAS messages (PRN 129 and 137) that RTKLIB's test
   log ``ubx_20080526.ubx`` carries in UBX RXM-SFRB frames, written as EMS lines (see
   :func:`ubx_sbas_lines` for the bit layout and the time tags).
3. With a gLAB binary: ``glab/*.gz``, gLAB's own decoding of the same messages in the Pegasus
   format (``-onlyconvert -output:pegasus``), the independent decode the tests compare with.
"""

from __future__ import annotations

import gzip
import shutil
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
OUT = Path(__file__).resolve().parent
SHARED = ROOT.parent / "shared" / "data"
EGNOS = SHARED / "egnos-ems-prn123-2019-014" / "ems"
MSAS_UBX = SHARED / "rtklib-rcvraw-msas-2008-147" / "ubx_20080526.ubx"
_PHASE = {0x53: 0, 0x9A: 1, 0xC6: 2}  # transmission start (GPS s) mod 3 for each preamble
_GPS_EPOCH_DAYS = 3657  # 1980-01-06 minus 1970-01-01, days


def write_gz(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(gzip.compress(data, compresslevel=9, mtime=0))


def ubx_frames(raw: bytes) -> list[tuple[int, int, int, bytes]]:
    """(week, RXM-RAW TOW s before the frame, PRN, 32-byte message) of every SBAS RXM-SFRB frame.

    u-blox 5/6 RXM-SFRB (class 0x02, id 0x11): ``chn``, ``svid``, ten little-endian uint32. For
    SBAS (svid >= 120), words 0-6 hold message bits 0-223 MSB first, and bits 25-0 of word 7 hold
    bits 224-249 (two data bits and the 24 parity bits), as RTKLIB's ``sbsdecodemsg`` reads them.
    """
    out = []
    i, week, tow = 0, 0, 0
    while (j := raw.find(b"\xb5\x62", i)) >= 0 and j + 8 <= len(raw):
        cls, mid, n = raw[j + 2], raw[j + 3], struct.unpack_from("<H", raw, j + 4)[0]
        if j + 8 + n > len(raw):
            break
        a = b = 0
        for byte in raw[j + 2 : j + 6 + n]:
            a = (a + byte) & 0xFF
            b = (b + a) & 0xFF
        if (a, b) != (raw[j + 6 + n], raw[j + 7 + n]):
            i = j + 2
            continue
        pay = raw[j + 6 : j + 6 + n]
        if (cls, mid) == (0x02, 0x10):
            tow, week = struct.unpack_from("<i", pay)[0] // 1000, struct.unpack_from("<h", pay, 4)[0]
        elif (cls, mid) == (0x02, 0x11) and pay[1] >= 120:
            w = struct.unpack_from("<8I", pay, 2)
            bits = 0
            for k in range(7):
                bits = (bits << 32) | w[k]
            bits = ((bits << 26) | (w[7] & 0x3FFFFFF)) << 6
            out.append((week, tow, pay[1], bits.to_bytes(32, "big")))
        i = j + 8 + n
    return out


def ubx_sbas_lines(raw: bytes) -> bytes:
    """EMS lines for the SBAS frames of a UBX log.

    RXM-SFRB has no time tag. A frame follows the RXM-RAW epoch T of its second; its transmission
    start is the first GPS second t >= T - 1 (after the previous frame of the same PRN) whose
    phase modulo 3 matches its preamble (0x53 starts at multiples of 3 s), and the EMS tag is
    t + 1 s, the end of the slot, as in ESA's files.
    """
    last: dict[int, int] = {}
    lines = []
    for week, tow, prn, msg in ubx_frames(raw):
        t = max(tow - 1, last.get(prn, -10) + 1)
        while t % 3 != _PHASE.get(msg[0], t % 3):
            t += 1
        last[prn] = t
        secs = week * 604_800 + t + 1
        days, sod = divmod(secs, 86_400)
        y, m, d = _civil(days + _GPS_EPOCH_DAYS)
        mt = msg[1] >> 2
        lines.append(
            f"{prn:3d} {y % 100:02d} {m:02d} {d:02d} {sod // 3600:02d} {sod % 3600 // 60:02d} {sod % 60:02d} "
            f"{mt} {msg.hex().upper()}\r\n"
        )
    return "".join(lines).encode()


def _civil(days: int) -> tuple[int, int, int]:
    """Year, month, day of a day count since 1970-01-01 (proleptic Gregorian)."""
    import datetime as dt

    d = dt.date(1970, 1, 1) + dt.timedelta(days=days)
    return d.year, d.month, d.day


def run_glab(glab: str, ems: bytes, prefix: str) -> None:
    """gLAB's Pegasus conversion of ``ems``; every output file gzipped into glab/<prefix><suffix>.gz.

    gLAB names its outputs after the first 8 characters of the input file name (here
    ``sbasmsgs``): ``.s01`` ... ``.sfc`` (columnar text, one per message type), ``.smt`` (every
    message with its CRC check), ``_BRDCddd0.yyH`` (MT 9 as RINEX-H) and ``_GEOwwww.alm`` (MT 17).
    """
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "sbasmsgs.ems"
        src.write_bytes(ems)
        out = Path(tmp) / "peg"
        out.mkdir()
        cmd = [
            glab,
            "-input:sbas1f",
            str(src),
            "-onlyconvert",
            "-output:pegasus",
            "-output:sbasdir",
            str(out),
        ]
        subprocess.run(cmd, check=True, capture_output=True)
        for f in sorted(out.iterdir()):
            if not f.name.startswith("sbasmsgs") or f.name.endswith(".log"):
                continue
            write_gz(OUT / "glab" / f"{prefix}{f.name[len('sbasmsgs') :]}.gz", f.read_bytes())


def main() -> None:
    glab = sys.argv[1] if len(sys.argv) > 1 else None
    hours = {h: (EGNOS / f"h{h}.ems").read_bytes() for h in ("00", "01", "02")}
    write_gz(OUT / "ems" / "h00.ems.gz", hours["00"])
    write_gz(OUT / "ems" / "h02.ems.gz", hours["02"])
    shutil.copyfile(EGNOS / "h01.ems", OUT / "ems" / "h01.ems")
    msas = ubx_sbas_lines(MSAS_UBX.read_bytes())
    write_gz(OUT / "msas" / "ubx_20080526_sbas.ems.gz", msas)
    if glab:
        if (OUT / "glab").exists():
            shutil.rmtree(OUT / "glab")
        run_glab(glab, hours["00"] + hours["01"] + hours["02"], "egnos_h00-02")
        run_glab(glab, msas, "msas")


if __name__ == "__main__":
    main()
