"""Build the u-blox raw-log fixtures of tests/data/sbas/ublox/ (see PROVENANCE.md there).

Run from the repository root::

    python tests/data/sbas/ublox/make_fixture.py

1. ``egnos_sdk_20121025_1202-1217.txt.gz``: the EGNOS SDK demo log (hex-wrapped UBX, one line of
   comma-separated tokens) from its first token up to, not including, the first RXM-RAW epoch at or
   after 12:17:00 GPST; tokens unmodified, joined by commas as in the original.
2. ``ubx_20080526_60s.ubx.gz``: RTKLIB's binary u-blox log from its first byte up to, not including,
   the first RXM-RAW frame 60 s or more after the first one; bytes unmodified.
Both are gzipped without name or time stamp, so they do not depend on the run.
"""

from __future__ import annotations

import gzip
import struct
from pathlib import Path

ROOT = Path(__file__).resolve().parents[4]
OUT = Path(__file__).resolve().parent
SHARED = ROOT.parent / "shared" / "data"
SDK = SHARED / "egnos-sdk-ublox-2012-299" / "RECEIVER_DATA.txt"
MSAS = SHARED / "rtklib-rcvraw-msas-2008-147" / "ubx_20080526.ubx"
RAW = b"\xb5\x62\x02\x10"  # sync, class RXM, id RAW


def write_gz(path: Path, data: bytes) -> None:
    path.write_bytes(gzip.compress(data, compresslevel=9, mtime=0))


def raw_tow_ms(frame: bytes) -> int | None:
    """iTOW (ms) of an RXM-RAW frame, else None."""
    return struct.unpack_from("<I", frame, 6)[0] if frame.startswith(RAW) else None


def cut_sdk(text: bytes, stop_tow_s: int) -> bytes:
    tokens = text.strip().split(b",")
    for k, tok in enumerate(tokens):
        if tok.startswith(b"b562") and (tow := raw_tow_ms(bytes.fromhex(tok.decode()))) is not None:
            if tow // 1000 >= stop_tow_s:
                return b",".join(tokens[:k])
    return text


def cut_binary(raw: bytes, seconds: int) -> bytes:
    i, first = 0, None
    while (j := raw.find(RAW, i)) >= 0 and j + 10 <= len(raw):
        tow = raw_tow_ms(raw[j : j + 10])
        first = tow if first is None else first
        if tow - first >= seconds * 1000:
            return raw[:j]
        i = j + 4
    return raw


def main() -> None:
    # 12:17:00 GPST of Thursday 2012-10-25 = 4 * 86400 + 12 * 3600 + 17 * 60 s of GPS week 1711
    write_gz(OUT / "egnos_sdk_20121025_1202-1217.txt.gz", cut_sdk(SDK.read_bytes(), 4 * 86400 + 44220))
    write_gz(OUT / "ubx_20080526_60s.ubx.gz", cut_binary(MSAS.read_bytes(), 60))


if __name__ == "__main__":
    main()
