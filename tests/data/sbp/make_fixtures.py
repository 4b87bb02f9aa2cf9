"""Write the SBP protection-level fixture with the sbp package's own encoder (no real capture with
MSG_PROTECTION_LEVEL exists; see PROVENANCE.md).

    python tests/data/sbp/make_fixtures.py      # writes tests/data/sbp/pl_sbas.sbp.gz

Two minutes at 1 Hz (GPS week 2098, from tow 271,500 s), a static receiver near Emeryville (the fix of
libsbp's roundtrip.sbp) with small scatter, each second MSG_GPS_TIME, MSG_POS_LLH (fix mode 6, SBAS) and
MSG_PROTECTION_LEVEL (HPL 350-450 cm, VPL 550-650 cm, TIR level 3, fix mode 6). Quirks at known seconds:
the protection-level frame of second 30 with a wrong CRC, fix mode 0 at second 60 (no solution), the
safe-state VPL flag at second 90 (alert), 5 stray bytes after second 100, the deprecated
MSG_PROTECTION_LEVEL_DEP_A (no week) at second 110, and the file cut inside the last frame. Seeded.
"""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
from sbp.navigation import MsgGPSTime, MsgPosLLH, MsgProtectionLevel, MsgProtectionLevelDepA

OUT = Path(__file__).with_name("pl_sbas.sbp.gz")
WEEK, TOW0, SECONDS, SENDER = 2098, 271_500_000, 120, 22963
LAT, LON, H = 37.831240, -122.286510, -17.40
_ZERO = dict.fromkeys(
    ("atpl", "ctpl", "hvpl", "vvpl", "hopl", "popl", "ropl", "v_x", "v_y", "v_z", "roll", "pitch", "heading"),
    0,
)


def frames() -> list[bytes]:
    rng = np.random.default_rng(16)
    out = []
    for k in range(SECONDS):
        tow = TOW0 + 1000 * k
        dn, de, du = rng.normal(0.0, (0.4, 0.4, 0.8))
        lat, lon, h = LAT + dn / 111_000.0, LON + de / (111_000.0 * np.cos(np.radians(LAT))), H + du
        mode = 0 if k == 60 else 6
        out.append(MsgGPSTime(sender=SENDER, wn=WEEK, tow=tow, ns_residual=0, flags=1).to_binary())
        llh = {"lat": lat, "lon": lon, "height": h, "h_accuracy": 513, "v_accuracy": 1115, "n_sats": 14}
        out.append(MsgPosLLH(sender=SENDER, tow=tow, flags=mode, **llh).to_binary())
        hpl, vpl = int(rng.integers(350, 451)), int(rng.integers(550, 651))
        flags = 3 | (mode << 15) | ((1 << 24) if k == 90 else 0)
        if k == 110:
            pl = MsgProtectionLevelDepA(sender=SENDER, tow=tow, vpl=vpl, hpl=hpl, lat=lat, lon=lon, height=h,
                                        flags=3).to_binary()  # fmt: skip
        else:
            levels = {"hpl": hpl, "vpl": vpl, "lat": lat, "lon": lon, "height": h}
            pl = MsgProtectionLevel(
                sender=SENDER, tow=tow, wn=WEEK, flags=flags, **levels, **_ZERO
            ).to_binary()
        if k == 30:
            pl = pl[:-2] + bytes([pl[-2] ^ 0xFF, pl[-1]])
        out.append(pl)
        if k == 100:
            out.append(b"\x00\x13\x37\x42\x99")
    out[-1] = out[-1][:-10]  # the recording stops inside the last frame
    return out


if __name__ == "__main__":
    OUT.write_bytes(gzip.compress(b"".join(frames()), mtime=0))
    print(OUT, OUT.stat().st_size, "bytes")
