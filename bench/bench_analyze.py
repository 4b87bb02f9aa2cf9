"""Benchmark: read and analyse a simulated 1 Hz station of growing length.

Target (foundation issue): a 1-year 1 Hz station (31.5 M epochs) read and analysed in
under 20 s and 4 GB peak memory on 2 cores, time and memory growing no faster than
the data. Each size runs in a fresh process so that its peak RSS is its own.

    python bench/bench_analyze.py                 # 30, 91, 182, 365 days
    python bench/bench_analyze.py --days 7 30     # other sizes

Prints, per size: epochs, simulate+write time, read time, KPI time (counting and the counted
evidence of the verdicts), JSON time (verdicts and the document), total
(read + KPIs + JSON), peak RSS of the analysing process, and time and memory per
million epochs (flat = linear growth).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHILD = r"""
import json, resource, sys, time
t0 = time.perf_counter()
from overbound.analysis import Analysis, load_epochs
from overbound.methods.counting import count_kpis
from overbound.methods.evidence import counted_evidence
from overbound.report.json import dumps, summary_dict
from overbound.services import resolve_services
t1 = time.perf_counter()
table, reports = load_epochs([sys.argv[1]], columns=())  # what `overbound analyze` reads
t2 = time.perf_counter()
services = resolve_services(None)
counting = count_kpis(table, services)
evidence = counted_evidence(table, counting, services)  # the counts' bounds behind the verdicts
t3 = time.perf_counter()
text = dumps(summary_dict(Analysis(table, reports, services, counting, "bench", evidence=evidence)))
t4 = time.perf_counter()
print(json.dumps({"epochs": table.height, "import": t1 - t0, "read": t2 - t1, "kpis": t3 - t2,
                  "json": t4 - t3, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def _simulate(days: float, path: Path) -> float:
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "overbound", "simulate", "-o", str(path), "--days", str(days), "--seed", "1"],
        check=True,
        stdout=subprocess.DEVNULL,
    )
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--days", type=float, nargs="+", default=[30, 91, 182, 365])
    ap.add_argument(
        "--keep", type=Path, help="directory to keep the simulated files in (reused when present)"
    )
    args = ap.parse_args()
    workdir = args.keep or Path(tempfile.mkdtemp(prefix="overbound-bench-"))
    workdir.mkdir(parents=True, exist_ok=True)
    print(f"cores available: {len(os.sched_getaffinity(0))}")
    print(
        f"{'days':>6} {'epochs':>11} {'sim s':>7} {'read s':>7} {'kpi s':>7} {'json s':>7} {'total s':>8} "
        f"{'peak MB':>8} {'s/Mep':>6} {'MB/Mep':>7}"
    )
    for days in args.days:
        path = workdir / f"sim-{days:g}d.parquet"
        sim_s = _simulate(days, path) if not path.exists() else float("nan")
        out = subprocess.run(
            [sys.executable, "-c", CHILD, str(path)], check=True, capture_output=True, text=True
        )
        r = json.loads(out.stdout.strip().splitlines()[-1])
        total = r["read"] + r["kpis"] + r["json"]
        mep = r["epochs"] / 1e6
        print(
            f"{days:6g} {r['epochs']:11d} {sim_s:7.1f} {r['read']:7.2f} {r['kpis']:7.2f} {r['json']:7.3f} "
            f"{total:8.2f} {r['peak_rss_mb']:8.0f} {total / mep:6.3f} {r['peak_rss_mb'] / mep:7.1f}"
        )


if __name__ == "__main__":
    main()
