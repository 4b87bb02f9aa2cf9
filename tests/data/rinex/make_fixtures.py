"""Cut the raw-data reader fixtures of tests/data/rinex/ from ../shared/data (see PROVENANCE.md here).

Run from the repository root::

    python tests/data/rinex/make_fixtures.py [/path/to/gLAB_linux]

Every file is cut line by line in plain Python (no overbound code), so the fixtures do not depend
on the readers they test, and gzipped without name or time stamp (the same bytes on every run;
the Hatanaka file goes through the ``hatanaka`` package's ``rnx2crx``). With a gLAB binary, gLAB
v6's satellite positions from the cut navigation and SP3 files are written too (``glab_*``).
"""

from __future__ import annotations

import gzip
import itertools
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
OUT = Path(__file__).resolve().parent
SHARED = ROOT.parent / "shared" / "data"
EGNOS = SHARED / "egnos-ems-prn123-2019-014"
ESBC = SHARED / "esbc-2020-177-no-sbas-msgs"
#: GPS satellites kept in the navigation and SP3 cuts of 2019-01-14: G04 is unhealthy all day and
#: has no SP3 clock at most epochs, G18 lacks four SP3 clocks, G21 has the largest broadcast error.
SATS_2019 = ("G04", "G07", "G08", "G10", "G18", "G21")
SYNT_WINDOW = ("01:50:00", "01:59:30")  # 20 epochs in which 13 then 14 satellites are in view
ESBC_EPOCHS = 10  # 5 minutes at 30 s
NAV3_GPS = ("G01", "G02", "G05", "G13")
NAV3_OTHERS_PER_SYSTEM = 2
MGEX_SATS = ("E01", "E02", "G01", "G02", "R01", "R02")
MGEX_EPOCHS = 12
# RINEX 2.11 rewrite of the ESBC epochs: RINEX 2 code <- RINEX 3 code, per system.
V2_TYPES = ("C1", "P1", "L1", "D1", "S1", "P2", "L2", "D2", "S2")
V2_SOURCE = {
    "G": ("C1C", "C1W", "L1C", "D1C", "S1C", "C2W", "L2W", "D2W", "S2W"),
    "R": ("C1C", "C1P", "L1C", "D1C", "S1C", "C2P", "L2P", "D2P", "S2P"),
    "S": ("C1C", "", "L1C", "D1C", "S1C", "", "", "", ""),
}


def read_text(path: Path) -> str:
    raw = path.read_bytes()
    if raw[:2] == b"\x1f\x8b":
        raw = gzip.decompress(raw)
    if b"COMPACT RINEX FORMAT" in raw[:80]:
        import hatanaka

        raw = hatanaka.decompress(raw)
    return raw.decode("ascii")


def write_gz(path: Path, text: str) -> None:
    path.write_bytes(gzip.compress(text.encode("ascii"), compresslevel=9, mtime=0))


def header_end(lines: list[str]) -> int:
    return next(i for i, s in enumerate(lines) if s[60:].strip() == "END OF HEADER") + 1


def comment(text: str) -> str:
    return f"{text:60}COMMENT"


# --------------------------------------------------------------------------- observations


def cut_synt() -> str:
    """SYNT0140.19o: the 20 epochs of SYNT_WINDOW (RINEX 2.11 continuation lines for > 12 sats)."""
    lines = read_text(EGNOS / "synthetic-obs" / "SYNT0140.19o.gz").splitlines()
    body = header_end(lines)
    lo, hi = (_seconds(w) for w in SYNT_WINDOW)
    out = []
    i = body
    while i < len(lines):
        n = int(lines[i][29:32])
        size = -(-n // 12) + n  # epoch lines, then one observation line per satellite (3 types)
        sod = int(lines[i][10:12]) * 3600 + int(lines[i][13:15]) * 60 + float(lines[i][15:26])
        if lo <= sod <= hi:
            out.extend(lines[i : i + size])
        i += size
    head = [_first_obs(s, out[0]) if s[60:].strip() == "TIME OF FIRST OBS" else s for s in lines[: body - 1]]
    head.insert(5, comment(f"CUT: {SYNT_WINDOW[0]}-{SYNT_WINDOW[1]} BY MAKE_FIXTURES.PY"))
    return "\n".join([*head, lines[body - 1], *out]) + "\n"


def _seconds(hms: str) -> float:
    h, m, s = hms.split(":")
    return int(h) * 3600 + int(m) * 60 + float(s)


def _first_obs(header_line: str, epoch_line: str) -> str:
    h, m, s = int(epoch_line[10:12]), int(epoch_line[13:15]), float(epoch_line[15:26])
    return f"{2019:6d}{1:6d}{14:6d}{h:6d}{m:6d}{s:13.7f}{'':5}GPS{'':9}TIME OF FIRST OBS"


def esbc_epochs() -> tuple[list[str], list[list[str]]]:
    """Header lines and the first ESBC_EPOCHS epoch records (lists of lines) of the ESBC day."""
    lines = read_text(ESBC / "ESBC00DNK_R_20201770000_01D_30S_MO.crx.gz").splitlines()
    body = header_end(lines)
    records, i = [], body
    while len(records) < ESBC_EPOCHS:
        n = int(lines[i][32:35])
        records.append(lines[i : i + 1 + n])
        i += 1 + n
    return lines[:body], records


def cut_esbc_v3() -> str:
    head, records = esbc_epochs()
    head = [s for s in head if not s.startswith("GFZRNX.NUM_EPOCHS")]
    last = f"{2020:6d}{6:6d}{25:6d}{0:6d}{4:6d}{30.0:13.7f}{'':5}GPS{'':9}TIME OF LAST OBS"
    head = [last if s[60:].strip() == "TIME OF LAST OBS" else s for s in head]
    head.insert(5, comment(f"CUT: FIRST {ESBC_EPOCHS} EPOCHS BY MAKE_FIXTURES.PY"))
    return "\n".join(head + [s for r in records for s in r]) + "\n"


def esbc_as_rinex2() -> str:
    """The ESBC epochs rewritten as RINEX 2.11 (GPS, GLONASS, SBAS; 9 types: two lines per satellite)."""
    head, records = esbc_epochs()
    types = {}
    cur = None
    for s in head:
        if s[60:].strip() == "SYS / # / OBS TYPES":
            if s[0] != " ":
                cur = s[0]
                types[cur] = []
            types[cur] += s[7:60].split()
    out = [
        f"{'2.11':>9}{'':11}{'OBSERVATION DATA':20}{'M (MIXED)':20}RINEX VERSION / TYPE",
        f"{'make_fixtures.py':20}{'overbound':20}{'':20}PGM / RUN BY / DATE",
        comment("ESBC00DNK 2020-06-25 FIRST 10 EPOCHS OF THE RINEX 3.05 FILE"),
        comment("REWRITTEN AS RINEX 2.11 (G, R, S ONLY), VALUES UNCHANGED"),
        f"{'ESBC':60}MARKER NAME",
    ]
    out += [s for s in head if s[60:].strip() in ("REC # / TYPE / VERS", "ANT # / TYPE")]
    out += [s for s in head if s[60:].strip() in ("APPROX POSITION XYZ", "ANTENNA: DELTA H/E/N")]
    out.append(f"{1:6d}{1:6d}{'':48}WAVELENGTH FACT L1/2")
    out.append(
        f"{len(V2_TYPES):6d}" + "".join(f"{'':4}{c:2}" for c in V2_TYPES).ljust(54) + "# / TYPES OF OBSERV"
    )
    out.append(f"{30.0:10.3f}{'':50}INTERVAL")
    out.append(f"{2020:6d}{6:6d}{25:6d}{0:6d}{0:6d}{0.0:13.7f}{'':5}GPS{'':9}TIME OF FIRST OBS")
    out.append(f"{'':60}END OF HEADER")
    for rec in records:
        e = rec[0]
        sats = [s for s in rec[1:] if s[0] in V2_SOURCE]
        ids = "".join(s[:3] for s in sats)
        stamp = f" {e[4:6]} {int(e[7:9]):2d} {int(e[10:12]):2d} {int(e[13:15]):2d} {int(e[16:18]):2d}"
        stamp += f"{float(e[18:29]):11.7f}"
        out.append(f"{stamp}  {e[31]}{len(sats):3d}{ids[:36]}")
        out += [f"{'':32}{ids[k : k + 36]}" for k in range(36, len(ids), 36)]
        for s in sats:
            fields = [_v3_field(s, types[s[0]], code) for code in V2_SOURCE[s[0]]]
            out.append("".join(fields[:5]).rstrip())
            out.append("".join(fields[5:]).rstrip())
    return "\n".join(out) + "\n"


def _v3_field(line: str, types: list[str], code: str) -> str:
    if not code:
        return " " * 16
    k = types.index(code)
    return line[3 + 16 * k : 19 + 16 * k].ljust(16)


# --------------------------------------------------------------------------- navigation


def cut_brdc() -> str:
    lines = read_text(EGNOS / "brdc0140.19n").splitlines()
    body = header_end(lines)
    keep = {int(s[1:]) for s in SATS_2019}
    out = lines[:body]
    out.insert(3, comment(f"CUT: PRN {' '.join(s[1:] for s in SATS_2019)} BY MAKE_FIXTURES.PY"))
    for i in range(body, len(lines), 8):
        if int(lines[i][:2]) in keep:
            out.extend(lines[i : i + 8])
    return "\n".join(out) + "\n"


def cut_mixed_nav() -> str:
    lines = read_text(ESBC / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz").splitlines()
    body = header_end(lines)
    starts = [i for i in range(body, len(lines)) if lines[i][:3].strip()] + [len(lines)]
    out = [s for s in lines[:body] if not s.startswith(("B_", "GFZRNX"))]
    out.insert(3, comment("CUT: 4 GPS SATELLITES, 2 RECORDS PER OTHER SYSTEM"))
    seen: dict[str, int] = {}
    for a, b in itertools.pairwise(starts):
        sat = lines[a][:3]
        if sat[0] == "G":
            if sat in NAV3_GPS:
                out.extend(lines[a:b])
        elif seen.get(sat[0], 0) < NAV3_OTHERS_PER_SYSTEM:
            seen[sat[0]] = seen.get(sat[0], 0) + 1
            out.extend(lines[a:b])
    return "\n".join(out) + "\n"


# --------------------------------------------------------------------------- SP3


def cut_sp3(text: str, sats: tuple[str, ...], n_epochs: int | None) -> str:
    """Keep the ``P`` lines of ``sats`` (and the first ``n_epochs`` epochs), rewriting the satellite
    list, accuracy codes and epoch count of the header."""
    lines = text.splitlines()
    listed: list[str] = []
    acc: list[str] = []
    body = next(i for i, s in enumerate(lines) if s.startswith("*"))
    for s in lines[:body]:
        if s.startswith("+ "):
            listed += [s[9 + 3 * k : 12 + 3 * k] for k in range(17)]
        elif s.startswith("++"):
            acc += [s[9 + 3 * k : 12 + 3 * k] for k in range(17)]
    n_listed = int(lines[2][1:6]) if lines[2].startswith("+ ") else 0
    accuracy = dict(zip(listed[:n_listed], acc[:n_listed], strict=True))
    per = [*sats, *["  0"] * (17 * 5 - len(sats))]
    plus = [
        ("+ " + f"{len(sats):4d}   " if k == 0 else "+        ") + "".join(per[17 * k : 17 * k + 17])
        for k in range(5)
    ]
    acc_codes = [accuracy[s] for s in sats] + ["  0"] * (17 * 5 - len(sats))
    pp = ["++       " + "".join(acc_codes[17 * k : 17 * k + 17]) for k in range(5)]
    epochs = 0
    out = []
    for s in lines[body:]:
        if s.startswith("*"):
            epochs += 1
            if n_epochs is not None and epochs > n_epochs:
                break
            out.append(s)
        elif s.startswith(("P", "V")) and s[1:4] in sats:
            out.append(s)
    n_ep = epochs if n_epochs is None else min(epochs, n_epochs)
    first = lines[0][:32] + f"{n_ep:7d}" + lines[0][39:]
    head = [first, lines[1], *plus, *pp]
    head += [s for s in lines[:body] if s.startswith(("%", "/*"))]
    head.insert(len(head), "/* CUT BY TESTS/DATA/RINEX/MAKE_FIXTURES.PY")
    return "\n".join([*head, *out, "EOF"]) + "\n"


# --------------------------------------------------------------------------- gLAB


def glab_satpvt(glab: str, args: list[str], keep_every: int) -> str:
    """gLAB show-product output (SATPVT lines), one epoch in ``keep_every``, short columns."""
    with tempfile.TemporaryDirectory() as tmp:
        res = subprocess.run([glab, *args], capture_output=True, text=True, cwd=tmp, check=True)
    rows = []
    for s in res.stdout.splitlines():
        if not s.startswith("SATPVT"):
            continue
        f = s.split()
        if round(float(f[3])) % (30 * keep_every):
            continue
        # year doy sod prn x y z clock(m) iod health
        rows.append(" ".join([f[1], f[2], f[3], f[6], f[11], f[12], f[13], f[20], f[22], f[23]]))
    shown = " ".join(Path(a).name if "/" in a else a for a in args)
    head = f"# gLAB v6.0.0 SATPVT (show-product mode), one line in {keep_every}: {shown}\n"
    head += "# year doy sod prn x_m y_m z_m clock_m iod health"
    return "\n".join([head, *rows]) + "\n"


def main() -> None:
    import hatanaka

    write_gz(OUT / "SYNT0140_cut.19o.gz", cut_synt())
    v3 = cut_esbc_v3()
    crx = hatanaka.compress(v3.encode("ascii"), compression="none").decode("ascii").split("\n")
    crx[1] = f"{'RNX2CRX (hatanaka ' + hatanaka.__version__ + ')':40}{'':20}CRINEX PROG / DATE"  # no run date
    write_gz(OUT / "ESBC00DNK_cut.crx.gz", "\n".join(crx))
    write_gz(OUT / "ESBC00DNK_cut_v211.20o.gz", esbc_as_rinex2())
    write_gz(OUT / "brdc0140_cut.19n.gz", cut_brdc())
    write_gz(OUT / "ESBC00DNK_cut_MN.rnx.gz", cut_mixed_nav())
    write_gz(OUT / "igs20361_cut.sp3.gz", cut_sp3((EGNOS / "igs20361.sp3").read_text(), SATS_2019, None))
    grg = read_text(ESBC / "GRG0MGXFIN_20201770000_01D_15M_ORB.SP3.gz")
    write_gz(OUT / "GRG0MGXFIN_cut.sp3.gz", cut_sp3(grg, MGEX_SATS, MGEX_EPOCHS))
    if len(sys.argv) > 1:
        glab = sys.argv[1]
        with tempfile.TemporaryDirectory() as tmp:
            nav = Path(tmp) / "brdc0140.19n"
            nav.write_bytes(gzip.decompress((OUT / "brdc0140_cut.19n.gz").read_bytes()))
            sp3 = Path(tmp) / "igs20361.sp3"
            sp3.write_bytes(gzip.decompress((OUT / "igs20361_cut.sp3.gz").read_bytes()))
            write_gz(OUT / "glab_satpvt_brdc.txt.gz", glab_satpvt(glab, ["-input:nav", str(nav)], 40))
            sp3_args = ["-input:sp3", str(sp3), "--model:satphasecenter"]
            write_gz(OUT / "glab_satpvt_sp3.txt.gz", glab_satpvt(glab, sp3_args, 31))


if __name__ == "__main__":
    main()
