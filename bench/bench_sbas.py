"""Speed of the DO-229 SBAS engine on 24 h of 1 Hz observations, and the ratio against gLAB.

Usage: ``python bench/bench_sbas.py [--workdir DIR] [--glab PATH] [--repeat N]``.

Input (written once into ``--workdir``, default the system temporary directory, about 2 min):
``BNCH0140.19o``, RINEX 2.11 C1 L1 S1 at 1 Hz for 2019-01-14 00:00:00-23:44:59 GPST (the SP3 file
ends at 23:45) at the Toulouse point of ``synthetic-obs/`` (the header position), every GPS
satellite of the IGS final orbits above 5 deg, made the way ``synthetic-obs/README.md`` describes
with two simplifications (documented here, irrelevant for timing, a few metres for accuracy):

    C1 = rho(SP3 position at transmit time, Earth rotation applied)
         - c (SP3 clock - 2 r.v / c^2) + c TGD(broadcast) + T + I

with T = 2.3 exp(-0.116e-3 h) 1.001 / sqrt(0.002001 + sin^2 E) m (as in the synthetic files) and
I the broadcast Klobuchar delay of the navigation file's header (IS-GPS-200 20.3.3.5.2.5)
instead of the IONEX map; no P1-C1 DCB. L1 = (C1 - 2 I) / lambda1, S1 = 30 + 20 sin E. Messages:
the 24 real EGNOS PRN 123 EMS hours of that day; ephemerides: ``brdc0140.19n``.

Timed (median of ``--repeat`` after a warm-up, one process, 2-core machine, with the memory settings
of :func:`overbound._allocator.keep_freed_memory` that ``overbound sbas`` applies):

* ``run_sbas`` alone on tables already read and messages already decoded;
* :func:`overbound.sbas.run.process` (reading the three inputs + decoding + engine);
* the whole ``overbound sbas`` command in a fresh process (start-up, writing both tables);
* gLAB v6 on the same three files, SBAS 1F PA, without the pre-processing DO-229 does not have
  (``--pre:minsnr --pre:cs:sf -pre:smooth 0 -pre:smoothmin 0``), printing only SBASOUT lines to
  a file: its epochs per second and the ratio.

The two commands run alternately ``--repeat`` times; each is reported as the median wall time and
the median CPU time (user + system of the child process), whose ratio is steadier on a busy machine.
"""

from __future__ import annotations

import argparse
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import polars as pl

from _timing import median_time
from bench_rinex import DAY_US, RECEIVER, write_rinex2
from overbound._allocator import keep_freed_memory
from overbound.io.ems import read_ems
from overbound.io.rinex_nav import SPEED_OF_LIGHT, read_rinex_nav, rotate_earth, select_ephemeris
from overbound.io.rinex_obs import read_rinex_obs
from overbound.io.sp3 import interpolate_clock, interpolate_position, read_sp3
from overbound.sbas.engine import run_sbas
from overbound.sbas.klobuchar import klobuchar_delay
from overbound.sbas.messages import decode
from overbound.sbas.run import process

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
EGNOS = DATA / "egnos-ems-prn123-2019-014"
EMS = [EGNOS / "ems" / f"h{h:02d}.ems" for h in range(24)]
NAV = EGNOS / "brdc0140.19n"
F1 = 1575.42e6
LAMBDA1 = SPEED_OF_LIGHT / F1
SECONDS = 85_500  # 00:00:00-23:44:59: the SP3 file's last epoch is 23:45
GLAB_OPTIONS = (
    "--pre:minsnr",
    "--pre:cs:sf",
    "-pre:smooth",
    "0",
    "-pre:smoothmin",
    "0",
    "-pre:geosel",
    "123",
    "-model:sbasmode",
    "PA",
    "-print:none",
    "-print:sbasout",
)


def simulate(step_s: int = 1) -> pl.DataFrame:
    """One row per (epoch, satellite above 5 deg): t (s of day), prn, C1, L1, D1 (0), S1."""
    import pymap3d

    sp3, _ = read_sp3(EGNOS / "igs20361.sp3")
    nav, _ = read_rinex_nav(NAV)
    lat, lon, h = pymap3d.ecef2geodetic(*RECEIVER)
    sats = [s for s in sp3.sats if s.startswith("G")]
    cols = sp3.sat_index(sats)
    prn = np.array([int(s[1:]) for s in sats])
    tgd_rows = select_ephemeris(
        nav.table, prn, np.full(prn.size, DAY_US + 43_200 * 1_000_000), healthy_only=False
    )
    tgd = np.where(tgd_rows >= 0, nav.table["tgd"].to_numpy()[np.maximum(tgd_rows, 0)], 0.0)
    up = RECEIVER / np.linalg.norm(RECEIVER)
    parts = []
    for start in range(0, SECONDS, 3600):
        t = np.arange(start, min(start + 3600, SECONDS), step_s, dtype=np.int64)
        tt, kk = np.meshgrid(t, np.arange(len(sats)), indexing="ij")
        t_us = DAY_US + tt * 1_000_000
        tau = np.full(tt.shape, 0.075)
        for _ in range(3):
            pos = interpolate_position(sp3, cols[kk], t_us, -tau)
            rot = rotate_earth(pos, tau)
            rho = np.linalg.norm(rot - RECEIVER, axis=-1)
            tau = rho / SPEED_OF_LIGHT
        los = rot - RECEIVER
        sin_e = (los @ up) / rho
        ok = np.isfinite(rho) & (sin_e > np.sin(np.radians(5.0)))
        vel = interpolate_position(sp3, cols[kk], t_us, -tau + 0.5) - interpolate_position(
            sp3, cols[kk], t_us, -tau - 0.5
        )
        rel = -2.0 * np.einsum("...i,...i", pos, vel) / SPEED_OF_LIGHT**2
        clk = interpolate_clock(sp3, cols[kk], t_us, -tau)
        e, n, _ = pymap3d.ecef2enu(rot[..., 0], rot[..., 1], rot[..., 2], lat, lon, h)
        elev, azim = np.arcsin(np.clip(sin_e, -1, 1)), np.arctan2(e, n)
        trop = 2.3 * np.exp(-0.116e-3 * h) * 1.001 / np.sqrt(0.002001 + sin_e**2)
        iono = klobuchar_delay(
            nav.header.ion_alpha,
            nav.header.ion_beta,
            np.radians(lat),
            np.radians(lon),
            elev,
            azim,
            (tt + 86_400) % 604_800,
        )  # 2019-01-14 is a Monday: day 1 of the week
        c1 = rho - SPEED_OF_LIGHT * (clk + rel) + SPEED_OF_LIGHT * tgd[kk] + trop + iono
        ok &= np.isfinite(c1)
        parts.append(
            pl.DataFrame(
                {
                    "t": tt[ok],
                    "prn": prn[kk][ok],
                    "C1": c1[ok],
                    "L1": (c1 - 2 * iono)[ok] / LAMBDA1,
                    "D1": np.zeros(ok.sum()),
                    "S1": 30.0 + 20.0 * sin_e[ok],
                }
            )
        )
    return pl.concat(parts).sort("t", "prn")


def make_inputs(workdir: Path) -> tuple[Path, Path]:
    obs, ems = workdir / "BNCH0140.19o", workdir / "egnos123_2019014.ems"
    if not obs.exists():
        t0 = time.perf_counter()
        df = simulate()
        write_rinex2(df, obs, dual=False)
        print(f"wrote {obs} ({df.height} satellite records) in {time.perf_counter() - t0:.0f} s")
    if not ems.exists():
        ems.write_bytes(b"".join(p.read_bytes() for p in EMS))
    return obs, ems


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "overbound-bench-sbas")
    ap.add_argument("--glab", default=shutil.which("gLAB_linux") or "/tmp/glab-build/core/gLAB_linux")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    args.workdir.mkdir(parents=True, exist_ok=True)
    keep_freed_memory()  # as the command does, so that the in-process figures are the command's
    obs_path, ems_path = make_inputs(args.workdir)
    obs, _ = read_rinex_obs(obs_path)
    nav, _ = read_rinex_nav(NAV)
    frames, _ = read_ems(ems_path)
    msgs = decode(frames)
    n = obs.epochs.height
    ref = obs.header.approx_position
    result = run_sbas(obs.table, nav.table, msgs, ref, station="BNCH")
    sol = result.epochs.filter(pl.col("vpl").is_finite())
    print(
        f"input: {n} epochs, {obs.table.height} satellite records; {sol.height} epochs with a PA solution; "
        f"HPE95 {np.percentile(sol['hpe'], 95):.2f} m, |VPE|95 {np.percentile(sol['vpe'].abs(), 95):.2f} m"
    )
    s = median_time(lambda: run_sbas(obs.table, nav.table, msgs, ref, station="BNCH"), args.repeat)
    print(f"{'run_sbas (engine only)':34} {s:6.2f} s  {n / s:8.0f} epochs/s")
    s = median_time(lambda: process(obs_path, NAV, ems_path), args.repeat)
    print(f"{'process (read + decode + engine)':34} {s:6.2f} s  {n / s:8.0f} epochs/s")
    out = args.workdir / "bench.parquet"
    cmd = [sys.executable, "-m", "overbound", "sbas", "--obs", str(obs_path), "--nav", str(NAV), "--sbas",
           str(ems_path), "-o", str(out)]  # fmt: skip
    glab_out = args.workdir / "glab.out"
    gcmd = [args.glab, "-input:obs", str(obs_path), "-input:nav", str(NAV), "-input:sbas1f", str(ems_path),
            *GLAB_OPTIONS, "-output:file", str(glab_out)]  # fmt: skip
    have_glab = bool(args.glab and Path(args.glab).exists())
    ours, theirs = [], []
    for _ in range(args.repeat):  # alternated, so that both see the same machine
        ours.append(_run_timed(cmd))
        if have_glab:
            theirs.append(_run_timed(gcmd))
    wall, cpu = np.median(ours, axis=0)
    print(f"{'overbound sbas (whole command)':34} {wall:6.2f} s  {n / wall:8.0f} epochs/s  "
          f"(CPU {cpu:.2f} s: {n / cpu:.0f} epochs per CPU second)")  # fmt: skip
    if not have_glab:
        print("gLAB not found: no ratio")
        return
    g_wall, g_cpu = np.median(theirs, axis=0)
    n_glab = sum(1 for line in glab_out.open() if line.startswith("SBASOUT"))
    print(f"{'gLAB v6 (same files, SBASOUT only)':34} {g_wall:6.2f} s  {n / g_wall:8.0f} epochs/s  "
          f"(CPU {g_cpu:.2f} s: {n / g_cpu:.0f} epochs per CPU second; {n_glab} solutions)")  # fmt: skip
    print(f"ratio overbound sbas / gLAB (epochs/s): wall {g_wall / wall:.2f}, CPU {g_cpu / cpu:.2f}")


def _run_timed(cmd: list[str]) -> tuple[float, float]:
    """Wall time and CPU time (user + system, from the child's rusage) of one run of ``cmd``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


if __name__ == "__main__":
    main()
