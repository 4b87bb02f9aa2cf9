"""Build the SBAS engine fixture of tests/data/sbas/engine/ (see PROVENANCE.md there).

Run from the repository root::

    python tests/data/sbas/engine/make_fixture.py /path/to/gLAB_linux

1. ``SYNT0140_h02-04.19o.gz``: the synthetic Toulouse observations (shared/data/egnos-ems-prn123-2019-014/
   synthetic-obs/SYNT0140.19o.gz), header and the epochs 02:00:00-04:59:30 GPST, unmodified.
2. ``h03.ems.gz``, ``h04.ems.gz``: the real EGNOS PRN 123 EMS hours 03 and 04 (hour 02 is
   ``../ems/h02.ems.gz``); ``brdc0140.19n.gz``: the day's broadcast ephemerides.
3. ``glab_h02-04.out.gz``: gLAB's processing of exactly these files (command in PROVENANCE.md),
   reduced to its INFO, SBASOUT, SBASVAR and SBASUNSEL lines.
4. The evening window 19:30:00-22:09:59 GPST, for both synthetic stations: ``ems_1930-2210.ems.gz``
   (the EMS lines of hours 19-22 inside the window), ``SYNT0140_1930-2210.19o.gz`` and
   ``SYNB0140_1930-2210.19o.gz`` (Toulouse, Brussels), and gLAB's processing of each,
   ``glab_synt_1930-2210.out.gz`` and ``glab_synb_1930-2210.out.gz``. The window holds PRN 26's
   ionospheric triangle rejections at Toulouse (19:46-19:54) and the IODE change-over of 22:03
   for which the daily navigation file has no new ephemerides.
5. ``glab_synt_1930-2210_npa.out.gz``: gLAB's processing of the evening Toulouse window in NPA mode
   (``-model:sbasmode NPA``, otherwise the same options); ``glab_synt_1930-2210_npa_klobuchar.out.gz``:
   the ``SBASCORR`` lines of the same run (``-print:sbascorr`` added) whose ionosphere is gLAB's
   Klobuchar model (field 51 = 1).
All gzip files are written without name or time stamp, so they do not depend on the run.
"""

from __future__ import annotations

import gzip
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[4]
OUT = Path(__file__).resolve().parent
DATA = ROOT.parent / "shared" / "data" / "egnos-ems-prn123-2019-014"
KEEP = ("INFO", "SBASOUT", "SBASVAR", "SBASUNSEL")
#: gLAB options: SBAS 1F, PA, GEO 123, without the pre-processing that DO-229 does not have.
GLAB_OPTIONS = (
    "--pre:minsnr", "--pre:cs:sf", "-pre:smooth", "0", "-pre:smoothmin", "0", "-pre:geosel", "123",
    "-model:sbasmode", "PA", "-print:none", "-print:info", "-print:sbasout", "-print:sbasvar",
    "-print:sbasunsel",
)  # fmt: skip


def write_gz(path: Path, data: bytes) -> None:
    path.write_bytes(gzip.compress(data, compresslevel=9, mtime=0))


def cut_obs(text: str, first: str = " 19  1 14  2  0  0", last: str = " 19  1 14  5  0  0") -> str:
    """Header plus the epochs from ``first`` (included) to ``last`` (excluded) of a RINEX 2 file."""
    end = text.index("END OF HEADER")
    end = text.index("\n", end) + 1
    start, stop = text.index("\n" + first, end) + 1, text.index("\n" + last, end) + 1
    return text[:end] + text[start:stop]


def run_glab(glab: str, obs_name: str, obs: str, ems: bytes, mode: str = "PA", extra: tuple[str, ...] = (),
             keep: tuple[str, ...] = KEEP) -> bytes:  # fmt: skip
    """gLAB's output for ``obs`` with ``ems`` and the day's navigation file (``extra`` options added), the
    ``keep`` lines only."""
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        (work / obs_name).write_text(obs)
        (work / "egnos123.ems").write_bytes(ems)
        (work / "brdc0140.19n").write_bytes((DATA / "brdc0140.19n").read_bytes())
        inputs = ["-input:obs", obs_name, "-input:nav", "brdc0140.19n", "-input:sbas1f", "egnos123.ems"]
        options = [mode if o == "PA" else o for o in GLAB_OPTIONS]
        cmd = [glab, *inputs, *options, *extra, "-output:file", "full.out"]
        subprocess.run(cmd, cwd=work, check=True, stdout=subprocess.DEVNULL)
        lines = (work / "full.out").read_text().splitlines(keepends=True)
    kept = [ln for ln in lines if ln.split(None, 1)[0].rstrip("*") in keep and "built on" not in ln]
    return "".join(kept).encode()


def cut_ems(data: bytes, first: str = "19 01 14 19 30 00", last: str = "19 01 14 22 10 00") -> bytes:
    """EMS lines whose time (columns 2-7) lies in [first, last)."""
    lines = data.decode().splitlines(keepends=True)
    return "".join(ln for ln in lines if first <= ln[4:21] < last).encode()


def evening(glab: str) -> None:
    """The 19:30-22:10 window for Toulouse and Brussels (item 4 of the module docstring)."""
    ems = cut_ems(b"".join((DATA / "ems" / f"h{h}.ems").read_bytes() for h in (19, 20, 21, 22)))
    write_gz(OUT / "ems_1930-2210.ems.gz", ems)
    for station in ("SYNT", "SYNB"):
        full = gzip.decompress((DATA / "synthetic-obs" / f"{station}0140.19o.gz").read_bytes()).decode()
        obs = cut_obs(full, " 19  1 14 19 30  0", " 19  1 14 22 10  0")
        write_gz(OUT / f"{station}0140_1930-2210.19o.gz", obs.encode())
        out = run_glab(glab, f"{station}0140.19o", obs, ems)
        write_gz(OUT / f"glab_{station.lower()}_1930-2210.out.gz", out)
        if station == "SYNT":
            out = run_glab(glab, f"{station}0140.19o", obs, ems, mode="NPA")
            write_gz(OUT / "glab_synt_1930-2210_npa.out.gz", out)
            corr = run_glab(glab, f"{station}0140.19o", obs, ems, mode="NPA", extra=("-print:sbascorr",),
                            keep=("SBASCORR",))  # fmt: skip
            klob = [ln for ln in corr.decode().splitlines(keepends=True) if ln.split()[50] == "1"]
            write_gz(OUT / "glab_synt_1930-2210_npa_klobuchar.out.gz", "".join(klob).encode())


def main(glab: str) -> None:
    obs = cut_obs(gzip.decompress((DATA / "synthetic-obs" / "SYNT0140.19o.gz").read_bytes()).decode())
    write_gz(OUT / "SYNT0140_h02-04.19o.gz", obs.encode())
    for hour in ("h03", "h04"):
        write_gz(OUT / f"{hour}.ems.gz", (DATA / "ems" / f"{hour}.ems").read_bytes())
    write_gz(OUT / "brdc0140.19n.gz", (DATA / "brdc0140.19n").read_bytes())
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        (work / "SYNT0140.19o").write_text(obs)
        ems = gzip.decompress((OUT.parent / "ems" / "h02.ems.gz").read_bytes())
        ems += (DATA / "ems" / "h03.ems").read_bytes() + (DATA / "ems" / "h04.ems").read_bytes()
        (work / "egnos123.ems").write_bytes(ems)
        (work / "brdc0140.19n").write_bytes((DATA / "brdc0140.19n").read_bytes())
        inputs = ["-input:obs", "SYNT0140.19o", "-input:nav", "brdc0140.19n", "-input:sbas1f", "egnos123.ems"]
        cmd = [glab, *inputs, *GLAB_OPTIONS, "-output:file", "full.out"]
        subprocess.run(cmd, cwd=work, check=True, stdout=subprocess.DEVNULL)
        lines = (work / "full.out").read_text().splitlines(keepends=True)
    kept = [ln for ln in lines if ln.split(None, 1)[0].rstrip("*") in KEEP and "built on" not in ln]
    write_gz(OUT / "glab_h02-04.out.gz", "".join(kept).encode())


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "gLAB_linux")
    evening(sys.argv[1] if len(sys.argv) > 1 else "gLAB_linux")
