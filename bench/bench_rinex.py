"""Speed of the raw-data readers: RINEX observations (24 h at 1 Hz), navigation and SP3.

Usage: ``python bench/bench_rinex.py [--workdir DIR] [--glab PATH]``.

The real observation files of the repository's data are 30 s (the synthetic Toulouse and
Brussels files, 2,820 epochs each, and the ESBC RINEX 3 Hatanaka day, 2,880 epochs), so the
script first writes 24 h of 1 Hz GPS observations (86,400 epochs, every satellite above 5 deg
seen from the Toulouse point of ``synthetic-obs/``), with the geometry of the real broadcast
ephemeris of 2019-01-14: C1 = geometric range - c dt_sv, L1 = C1 / lambda1, D1 from the range
rate, S1 = 30 + 20 sin(elevation). The values only need the right layout and magnitude: the
files are for timing the reader, not for positioning. They are written once (about 1.5 min) into ``--workdir``
(default: the system temporary directory) as

* RINEX 2.11 with C1 L1 S1 (one line per satellite, like the synthetic files), plain and gzip;
* RINEX 2.11 with C1 P1 L1 D1 S1 P2 L2 S2 (two lines per satellite);
* RINEX 3.04 with C1C L1C D1C S1C C2W L2W S2W, plain and Hatanaka + gzip (``.crx.gz``).

Each read is timed (median of 3 after a warm-up, wall and CPU time) and reported as epochs per
second. With
``--glab`` (a gLAB binary) the same RINEX 2 file is also read by gLAB in its show-input mode
with all printing off, for a ratio.
"""

from __future__ import annotations

import argparse
import gzip
import os
import resource
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import polars as pl

from _timing import median_time
from overbound.io.rinex_nav import (
    SPEED_OF_LIGHT,
    broadcast_state,
    read_rinex_nav,
    rotate_earth,
    select_ephemeris,
)
from overbound.io.rinex_obs import read_rinex_obs
from overbound.io.sp3 import interpolate_position, read_sp3

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
EGNOS = DATA / "egnos-ems-prn123-2019-014"
ESBC = DATA / "esbc-2020-177-no-sbas-msgs"
RECEIVER = np.array([4627851.2711, 119640.7753, 4372993.8468])  # SYNT0140 header position
DAY_US = 1_547_424_000_000_000  # 2019-01-14 00:00:00 GPST, us since 1970
LAMBDA1 = SPEED_OF_LIGHT / 1575.42e6


def simulate_day(step_s: int = 1) -> pl.DataFrame:
    """One row per (epoch, satellite above 5 deg): time (s of day), prn, C1, L1, D1, S1."""
    eph, _ = read_rinex_nav(EGNOS / "brdc0140.19n")
    t = np.arange(0, 86_400, step_s, dtype=np.int64)
    prn = np.arange(1, 33)
    tt, pp = np.meshgrid(t, prn, indexing="ij")
    t_us = DAY_US + tt * 1_000_000
    rows = select_ephemeris(eph.table, pp, t_us)
    ok = rows >= 0
    tau = 0.075
    st = broadcast_state(eph.table, rows[ok], t_us[ok], -tau)
    pos = rotate_earth(st.position, tau)
    los = pos - RECEIVER
    rho = np.linalg.norm(los, axis=1)
    up = RECEIVER / np.linalg.norm(RECEIVER)
    sin_el = los @ up / rho
    vis = sin_el > np.sin(np.radians(5.0))
    st2 = broadcast_state(eph.table, rows[ok][vis], t_us[ok][vis], 1.0 - tau)
    rate = np.linalg.norm(rotate_earth(st2.position, tau) - RECEIVER, axis=1) - rho[vis]
    c1 = rho[vis] - SPEED_OF_LIGHT * st.clock[vis]
    return pl.DataFrame(
        {
            "t": tt[ok][vis],
            "prn": pp[ok][vis],
            "C1": c1,
            "L1": c1 / LAMBDA1,
            "D1": -rate / LAMBDA1,
            "S1": 30.0 + 20.0 * sin_el[vis],
        }
    ).sort("t", "prn")


def _f(v: float) -> str:
    return f"{v:14.3f}  "


def write_rinex2(df: pl.DataFrame, path: Path, dual: bool) -> None:
    types = ["C1", "P1", "L1", "D1", "S1", "P2", "L2", "S2"] if dual else ["C1", "L1", "S1"]
    head = [
        f"{'2.11':>9}{'':11}{'OBSERVATION DATA':20}{'G (GPS)':20}RINEX VERSION / TYPE",
        f"{'bench_rinex.py':60}PGM / RUN BY / DATE",
        f"{'BNCH':60}MARKER NAME",
        f"{RECEIVER[0]:14.4f}{RECEIVER[1]:14.4f}{RECEIVER[2]:14.4f}{'':18}APPROX POSITION XYZ",
        f"{0.0:14.4f}{0.0:14.4f}{0.0:14.4f}{'':18}ANTENNA: DELTA H/E/N",
        f"{len(types):6d}" + "".join(f"{'':4}{c:2}" for c in types).ljust(54) + "# / TYPES OF OBSERV",
        f"{1.0:10.3f}{'':50}INTERVAL",
        f"{2019:6d}{1:6d}{14:6d}{0:6d}{0:6d}{0.0:13.7f}{'':5}GPS{'':9}TIME OF FIRST OBS",
        f"{'':60}END OF HEADER",
    ]
    out = ["\n".join(head)]
    for (t,), grp in df.group_by("t", maintain_order=True):
        prns = grp["prn"].to_list()
        h, m, s = t // 3600, t // 60 % 60, t % 60
        ids = "".join(f"G{p:02d}" for p in prns)
        lines = [f" 19  1 14 {h:2d} {m:2d}{s:11.7f}  0{len(prns):3d}{ids[:36]}"]
        lines += [f"{'':32}{ids[k : k + 36]}" for k in range(36, len(ids), 36)]
        for c1, l1, d1, s1 in zip(grp["C1"], grp["L1"], grp["D1"], grp["S1"], strict=True):
            if dual:
                vals = [c1, c1 + 0.4, l1, d1, s1, c1 + 3.1, l1 * 60 / 77, s1 - 6.0]
                lines.append("".join(_f(v) for v in vals[:5]).rstrip())
                lines.append("".join(_f(v) for v in vals[5:]).rstrip())
            else:
                lines.append("".join(_f(v) for v in (c1, l1, s1)).rstrip())
        out.append("\n".join(lines))
    path.write_text("\n".join(out) + "\n")


def write_rinex3(df: pl.DataFrame, path: Path) -> None:
    types = ["C1C", "L1C", "D1C", "S1C", "C2W", "L2W", "S2W"]
    head = [
        f"{'3.04':>9}{'':11}{'OBSERVATION DATA':20}{'G: GPS':20}RINEX VERSION / TYPE",
        f"{'bench_rinex.py':60}PGM / RUN BY / DATE",
        f"{'BNCH':60}MARKER NAME",
        f"{RECEIVER[0]:14.4f}{RECEIVER[1]:14.4f}{RECEIVER[2]:14.4f}{'':18}APPROX POSITION XYZ",
        f"{0.0:14.4f}{0.0:14.4f}{0.0:14.4f}{'':18}ANTENNA: DELTA H/E/N",
        f"G{len(types):5d}" + "".join(f" {c}" for c in types).ljust(54) + "SYS / # / OBS TYPES",
        f"{1.0:10.3f}{'':50}INTERVAL",
        f"{2019:6d}{1:6d}{14:6d}{0:6d}{0:6d}{0.0:13.7f}{'':5}GPS{'':9}TIME OF FIRST OBS",
        f"{'':60}END OF HEADER",
    ]
    out = ["\n".join(head)]
    for (t,), grp in df.group_by("t", maintain_order=True):
        h, m, s = t // 3600, t // 60 % 60, t % 60
        lines = [f"> 2019 01 14 {h:02d} {m:02d}{s:11.7f}  0{grp.height:3d}"]
        for p, c1, l1, d1, s1 in zip(grp["prn"], grp["C1"], grp["L1"], grp["D1"], grp["S1"], strict=True):
            vals = [c1, l1, d1, s1, c1 + 3.1, l1 * 60 / 77, s1 - 6.0]
            lines.append((f"G{p:02d}" + "".join(_f(v) for v in vals)).rstrip())
        out.append("\n".join(lines))
    path.write_text("\n".join(out) + "\n")


def make_files(workdir: Path) -> dict[str, Path]:
    files = {
        "rinex2 3 obs": workdir / "BNCH0140.19o",
        "rinex2 3 obs gzip": workdir / "BNCH0140.19o.gz",
        "rinex2 8 obs": workdir / "BNC80140.19o",
        "rinex3 7 obs": workdir / "BNCH00XXX_R_20190140000_01D_01S_GO.rnx",
        "rinex3 7 obs crx.gz": workdir / "BNCH00XXX_R_20190140000_01D_01S_GO.crx.gz",
    }
    if all(p.exists() for p in files.values()):
        return files
    t0 = time.perf_counter()
    df = simulate_day()
    write_rinex2(df, files["rinex2 3 obs"], dual=False)
    files["rinex2 3 obs gzip"].write_bytes(gzip.compress(files["rinex2 3 obs"].read_bytes(), mtime=0))
    write_rinex2(df, files["rinex2 8 obs"], dual=True)
    write_rinex3(df, files["rinex3 7 obs"])
    import hatanaka

    files["rinex3 7 obs crx.gz"].write_bytes(hatanaka.compress(files["rinex3 7 obs"].read_bytes()))
    print(f"wrote the 1 Hz files in {time.perf_counter() - t0:.1f} s ({df.height} satellite records)")
    return files


def _timed(fn, repeat: int) -> tuple[float, float]:
    """Median wall and CPU time (s) of ``repeat`` calls after a warm-up; CPU time is steadier on a
    shared machine (subprocesses included, for gLAB)."""
    fn()
    wall, cpu = [], []
    for _ in range(repeat):
        c0 = time.process_time() + resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime
        t0 = time.perf_counter()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() + resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime - c0)
    return float(np.median(wall)), float(np.median(cpu))


def time_obs(label: str, path: Path, repeat: int = 3) -> float:
    obs, report = read_rinex_obs(path)
    wall, cpu = _timed(lambda: read_rinex_obs(path), repeat)
    n = obs.epochs.height
    size = os.path.getsize(path) / 1e6
    print(
        f"{label:28} {size:6.1f} MB {n:6d} epochs {obs.table.height:7d} records  wall {wall:5.2f} s"
        f" {n / wall:7.0f} ep/s  cpu {cpu:5.2f} s {n / cpu:7.0f} ep/s  (rejected {report.n_rejected})"
    )
    return cpu


def time_glab(glab: str, path: Path) -> None:
    """gLAB's show-input mode on the same file, all output off (its reading of the file)."""
    cmd = [glab, "-input:obs", str(path), "-print:none"]
    if subprocess.run(cmd, capture_output=True).returncode != 0:
        print("gLAB did not run:", " ".join(cmd))
        return
    wall, cpu = _timed(lambda: subprocess.run(cmd, capture_output=True, check=True), 3)
    print(f"{'gLAB show-input, same file':28} {'':34} wall {wall:5.2f} s {'':12} cpu {cpu:5.2f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "overbound-bench-rinex")
    ap.add_argument("--glab", default=shutil.which("gLAB_linux") or "/tmp/glab-build/core/gLAB_linux")
    args = ap.parse_args()
    args.workdir.mkdir(parents=True, exist_ok=True)
    print("real files (30 s):")
    for label, path in (
        ("SYNT0140.19o.gz (RINEX 2)", EGNOS / "synthetic-obs" / "SYNT0140.19o.gz"),
        ("SYNB0140.19o.gz (RINEX 2)", EGNOS / "synthetic-obs" / "SYNB0140.19o.gz"),
        ("ESBC crx.gz (RINEX 3 mixed)", ESBC / "ESBC00DNK_R_20201770000_01D_30S_MO.crx.gz"),
    ):
        time_obs(label, path)
    print("24 h at 1 Hz (GPS):")
    files = make_files(args.workdir)
    for label, path in files.items():
        time_obs(label, path)
    if args.glab and Path(args.glab).exists():
        time_glab(args.glab, files["rinex2 3 obs"])
    nav = EGNOS / "brdc0140.19n"
    mixed = ESBC / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"
    print(f"{'brdc0140.19n':28} {median_time(lambda: read_rinex_nav(nav), 5) * 1e3:6.1f} ms")
    print(f"{'ESBC MN.rnx.gz (mixed)':28} {median_time(lambda: read_rinex_nav(mixed), 5) * 1e3:6.1f} ms")
    sp3_path = EGNOS / "igs20361.sp3"
    sp3, _ = read_sp3(sp3_path)
    print(f"{'igs20361.sp3':28} {median_time(lambda: read_sp3(sp3_path), 5) * 1e3:6.1f} ms")
    t = DAY_US + np.arange(0, 86_400, 1, dtype=np.int64) * 1_000_000
    cols = np.arange(len(sp3.sats))
    tq, cq = np.meshgrid(t[:3600], cols, indexing="ij")
    s = median_time(lambda: interpolate_position(sp3, cq, tq), 3)
    print(f"{'SP3 degree-10 interpolation':28} {tq.size / s:9.0f} positions/s ({tq.size} per call)")


if __name__ == "__main__":
    main()
