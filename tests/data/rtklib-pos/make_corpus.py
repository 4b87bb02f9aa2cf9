"""Regenerate the RTKLIB ``.pos`` edge-case corpus in this folder (see PROVENANCE.md).

Run from the repository root with the shared data present::

    python tests/data/rtklib-pos/make_corpus.py ../shared/data/waas-uslo-2006-361/rtklib-mops-outputs

Every file starts from the first lines of the real RTKLIB-MOPS outputs and changes only
what its name says. The ECEF and d-m-s variants are converted with a closed-form WGS-84
formula (``tests/reference/wgs84.py``, not pymap3d), printed as RTKLIB's ``outecef``/``outpos`` do.
"""

from __future__ import annotations

import datetime as dt
import math
import sys
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parents[1] / "reference"))
import wgs84  # noqa: E402  (tests/reference, not a package)

N_DATA = 8  # data lines kept from the real file


def dms(deg: float) -> str:
    sign = "-" if deg < 0 else ""
    a = abs(deg)
    d = math.floor(a)
    m = math.floor((a - d) * 60)
    s = (a - d - m / 60) * 3600
    return f"{sign + str(d):>4s} {m:02d} {s:08.5f}"


def main(src: Path) -> None:
    ws = (src / "test26-ws.pos-expected").read_text().splitlines()
    head = [ln for ln in ws if ln.startswith("%")]
    data = [ln for ln in ws if not ln.startswith("%")][:N_DATA]
    colhdr = head[-1]
    base = head[:-1]

    def put(name: str, lines: list[str], nl: str = "\n") -> None:
        (HERE / name).write_bytes((nl.join(lines) + nl).encode() if lines else b"")

    def sub(i: int, old: str, new: str) -> list[str]:
        out = list(data)
        assert old in out[i], (old, out[i])
        out[i] = out[i].replace(old, new, 1)
        return out

    put("good-uslo-head.pos", head + data)
    put("crlf-line-endings.pos", head + data, nl="\r\n")
    put("truncated-line.pos", head + data[:3] + [" ".join(data[3].split()[:11])] + data[4:])
    put("non-numeric-field.pos", head + sub(2, "134.4215", "13x.4215"))
    put("year-0000.pos", head + sub(2, "2006/12/27", "0000/12/27"))
    put("year-9999.pos", head + sub(4, "2006/12/27", "9999/12/27"))
    # a file cut inside the last line's VPL: "24.6" became "24." and the line end is gone
    cut = "\n".join(head + data)
    (HERE / "cut-inside-vpl.pos").write_bytes(cut[: cut.rindex(".") + 1].encode())
    put("duplicate-time.pos", head + sub(4, "00:06:30.000", "00:06:00.000"))
    put("backward-time.pos", head + sub(5, "00:07:00.000", "00:05:45.000"))
    put("negative-hpl.pos", head + sub(3, "18.90", "-18.90"))
    put("nan-vpl.pos", head + sub(4, " 32.1", "  nan"))
    put("unknown-quality.pos", head + sub(1, "   3   5 ", "   9   5 "))
    put("no-solution-q0.pos", head + sub(6, "   3   9 ", "   0   9 "))
    put("empty.pos", [])
    put("header-only.pos", head)
    put("no-header.pos", data)

    # UTC time tags: GPS-UTC was 14 s in December 2006 (IERS Bulletin C).
    utc = []
    for ln in data:
        t = dt.datetime.strptime(ln[:23], "%Y/%m/%d %H:%M:%S.%f") - dt.timedelta(seconds=14)
        utc.append(t.strftime("%Y/%m/%d %H:%M:%S.%f")[:23] + ln[23:])
    put("utc-header.pos", [*base, colhdr.replace("%  GPST", "%  UTC ", 1), *utc])

    # GPS week and seconds of week, as outsols prints them ("%4d %10.3f").
    wt = []
    for ln in data:
        t = dt.datetime.strptime(ln[:23], "%Y/%m/%d %H:%M:%S.%f") - dt.datetime(1980, 1, 6)
        week, tow = divmod(t.total_seconds(), 604800)
        wt.append(f"{int(week):4d} {tow:10.3f}" + ln[23:])
    put("week-tow.pos", [*base, "%  GPST          " + colhdr[len("%  GPST                ") :], *wt])

    # x/y/z-ecef (outecef: %14.4f), covariance columns kept as they are.
    xyz_hdr = (
        "%  GPST                      x-ecef(m)      y-ecef(m)      z-ecef(m)   Q  ns"
        "   sdx(m)   sdy(m)   sdz(m)  sdxy(m)  sdyz(m)  sdzx(m) hpl (m) vpl (m)"
    )
    xyz = []
    for ln in data:
        f = ln.split()
        x, y, z = wgs84.ecef(float(f[2]), float(f[3]), float(f[4]))
        xyz.append(f"{f[0]} {f[1]} {x:14.4f} {y:14.4f} {z:14.4f} " + " ".join(f[5:]))
    put(
        "xyz.pos",
        [
            *base[:-1],
            "% (x/y/z-ecef=WGS84,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)",
            xyz_hdr,
            *xyz,
        ],
    )

    # lat/lon as degrees, minutes, seconds (outpos with degf: %4.0f %02.0f %08.5f).
    dms_hdr = colhdr.replace(" latitude(deg) longitude(deg)", "  latitude(d'\")  longitude(d'\")", 1)
    rows = []
    for ln in data:
        f = ln.split()
        rows.append(f"{f[0]} {f[1]} {dms(float(f[2]))} {dms(float(f[3]))} " + " ".join(f[4:]))
    put("dms.pos", [*base, dms_hdr, *rows])

    # Field separator "," (out-fieldsep): RTKLIB puts it between every two fields.
    comma = [f"{ln[:23]}," + ",".join(ln[23:].split()) for ln in data]
    put(
        "comma-separated.pos",
        [*base, colhdr[:24] + "," + ",".join(colhdr[24:].replace(" (m)", "(m)").split()), *comma],
    )

    r3 = [ln.replace("Uslo3610.06O", "ESBC00DNK_R_20201770000_01D_30S_MO.crx.gz") for ln in head]
    put("rinex3-station.pos", r3 + data)
    put("geodetic-height.pos", [ln.replace("WGS84/ellipsoidal", "WGS84/geodetic") for ln in head] + data)
    put(
        "enu-baseline.pos",
        [
            *base,
            "%  GPST                  e-baseline(m)  n-baseline(m)  u-baseline(m)   Q  ns"
            "   sde(m)   sdn(m)   sdu(m)  sden(m)  sdnu(m)  sdue(m) age(s)  ratio",
            *data,
        ],
    )

    # Real variants: without the MOPS code (age/ratio instead of hpl/vpl) and with RAIM FDE.
    for name, out, n in (
        ("test26.pos-expected", "no-hpl-test26-head.pos", N_DATA),
        ("test27.pos-expected", "no-hpl-test27-head.pos", N_DATA),
        ("test28-ws.pos-expected", "test28-ws-head.pos", 40),
    ):
        lines = (src / name).read_text().splitlines()
        h = [ln for ln in lines if ln.startswith("%")]
        put(out, h + [ln for ln in lines if not ln.startswith("%")][:n])


if __name__ == "__main__":
    main(Path(sys.argv[1]))
