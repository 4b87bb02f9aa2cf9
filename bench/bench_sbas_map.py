"""Speed of the service-volume maps (``overbound sbas-map``) against gLAB's SBAS plots mode.

Usage: ``python bench/bench_sbas_map.py [--glab PATH] [--repeat N] [--step DEG] [--workers N]``.

The issue-15 case: a 1 deg map of the EGNOS area (lon -30..40, lat 25..70: 3266 nodes) at 60 s over
the EGNOS day of the repository (``tests/data/sbas/network/egnos123_2019014.ems.gz`` and
``tests/data/sbas/engine/brdc0140.19n.gz``; 1381 epochs, up to the last message), LPV, PA, mask
5 deg, height 0 m. Timed, alternately ``--repeat`` times, each in a fresh process (wall time and CPU
time of the process tree):

* ``overbound sbas-map`` in this process (``--workers 0``) and on ``--workers`` local Dask workers;
* with ``--glab``, gLAB v6 in its SBAS plots mode on the same files and options (the command of
  ``tests/data/sbas/maps/PROVENANCE.md`` with ``-sbasplots:availstep`` = ``--step``, the ionosphere
  map off), single-threaded as built by its default Makefile.

Printed: node-epochs per second of each and the ratios against gLAB (the target is 10x gLAB's
throughput on the same 2 cores).
"""

from __future__ import annotations

import argparse
import gzip
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[1]
NAV = ROOT / "tests" / "data" / "sbas" / "engine" / "brdc0140.19n.gz"
EMS = ROOT / "tests" / "data" / "sbas" / "network" / "egnos123_2019014.ems.gz"
EPOCHS = 1381  # 00:00:00 to 23:00:00 every 60 s (the last message is 23:00:29)


def run(cmd: list[str], cwd: Path) -> tuple[float, float]:
    """Wall time and CPU time (user + system of the process and its children) of ``cmd``."""
    t0 = time.perf_counter()
    proc = psutil.Popen(cmd, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    cpu = 0.0
    while proc.poll() is None:
        try:
            procs = [proc, *proc.children(recursive=True)]
            cpu = max(cpu, sum(sum(p.cpu_times()[:4]) for p in procs if p.is_running()))
        except psutil.Error:
            pass
        time.sleep(0.2)
    if proc.returncode:
        raise SystemExit(f"{cmd[0]} failed ({proc.returncode}): {' '.join(cmd)}")
    return time.perf_counter() - t0, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--glab", help="gLAB v6 binary (gLAB_linux)")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--step", type=float, default=1.0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    nodes = (int(70 / args.step + 1e-4) + 1) * (int(45 / args.step + 1e-4) + 1)
    work = nodes * EPOCHS
    print(f"cores: {os.cpu_count()}; {nodes} nodes x {EPOCHS} epochs = {work:,} node-epochs")
    tmp = Path(tempfile.mkdtemp(prefix="bench-sbas-map-"))
    ems = tmp / "egnos123.ems"
    ems.write_bytes(gzip.decompress(EMS.read_bytes()))
    nav = tmp / "brdc0140.19n"
    nav.write_bytes(gzip.decompress(NAV.read_bytes()))
    ours = [sys.executable, "-m", "overbound", "sbas-map", "--nav", str(nav), "--sbas", str(ems), "--step",
            str(args.step), "--service", "LPV", "-o", str(tmp / "out")]  # fmt: skip
    cmds = {"overbound, this process": [*ours, "--workers", "0"],
            f"overbound, {args.workers} workers": [*ours, "--workers", str(args.workers)]}  # fmt: skip
    if args.glab:
        options = (
            "-pre:starttime 2019/014 0 -pre:geosel 123 -pre:elevation 5 -model:sbasmode PA "
            "-sbasplots:plotarea -30 40 25 70 -sbasplots:recheight 0 -sbasplots:hal 40 -sbasplots:val 50 "
            f"-sbasplots:availstep {args.step:g} -sbasplots:availtimestep 60 -sbasplots:noionoplot "
            "-output:sbasavailplots avail.txt -output:sbasriskplots risk.txt "
            "-output:sbasriskmarplots riskmar.txt -output:sbasriskdisc disc.txt"
        )
        glab = str(Path(args.glab).resolve())
        cmds["gLAB plots mode"] = [glab, "-input:nav", str(nav), "-input:sbas1f", str(ems), *options.split()]
    times: dict[str, list[tuple[float, float]]] = {k: [] for k in cmds}
    for _ in range(args.repeat):
        for name, cmd in cmds.items():  # alternately: the machine's state is shared
            times[name].append(run(cmd, tmp))
    rates = {}
    for name, runs in times.items():
        wall = statistics.median(w for w, _ in runs)
        cpu = statistics.median(c for _, c in runs)
        rates[name] = work / wall
        print(f"{name:28s} wall {wall:7.1f} s  CPU {cpu:7.1f} s  {work / wall:>10,.0f} node-epochs/s")
    if "gLAB plots mode" in rates:
        g = rates["gLAB plots mode"]
        for name, r in rates.items():
            if name != "gLAB plots mode":
                print(f"ratio {name} / gLAB: {r / g:.2f} (target 10)")


if __name__ == "__main__":
    main()
