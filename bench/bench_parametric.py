"""Speed of the whole parametric analysis (Kannemans 2006) and of the ``overbound parametric`` command.

Usage: ``python bench/bench_parametric.py [DAYS]``. Simulates the 3-month 1 Hz station of
``bench_evt.py`` (``DAYS`` days, default 90: 7.8e6 epochs; sigma ratio 1.2, no heavy-tail regime,
seed 1), then times

1. :func:`~overbound.methods.parametric.parametric_analysis` with the defaults (both axes, every
   built-in service: ratio fits, decorrelation times from the ACFs, Weibull fits and bounds, the
   integrals per service, the non-continuity curves over 400 alert limits for the 15 s and 3600 s
   windows with their fits), median of ``REPEAT`` runs after a warm-up, wall and CPU time (target:
   under 10 s on 2 cores);
2. in the same process, ``parametric.json`` (:func:`~overbound.methods.parametric.write_parametric`)
   and ``parametric.html`` with its figures (:func:`~overbound.report.parametric.write_parametric_report`);
3. the whole command ``overbound parametric FILE -o DIR`` on the station written as Parquet, in a
   fresh process (read, analysis, JSON, figures, HTML): wall time and its peak resident memory (run
   first, while this process is small; the Parquet file is written by another process).

The simulation and the Parquet file are not counted. It prints the main numbers of the analysis
beside the simulator's truth (P_MI per epoch) so that a wrong fast run does not pass unnoticed.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from overbound.methods.parametric import parametric_analysis, write_parametric
from overbound.report.parametric import write_parametric_report
from overbound.report.parametric_figures import format_probability as fp
from overbound.simulate import SimulationConfig, simulate

REPEAT = 3


def timed(fn):
    """Result, wall and CPU seconds of one call."""
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w0, time.process_time() - c0


def bench_analysis(table, sim):
    """Time parametric_analysis (warm-up, then the median of REPEAT runs) and print its main numbers."""
    a, wall, cpu = timed(lambda: parametric_analysis(table))  # warm-up (first touch of memory)
    print(f"parametric_analysis, first run: {wall:.2f} s wall, {cpu:.2f} s CPU")
    runs = [timed(lambda: parametric_analysis(table))[1:] for _ in range(REPEAT)]
    walls = sorted(w for w, _ in runs)
    cpus = sorted(c for _, c in runs)
    print(
        f"parametric_analysis: median {walls[len(walls) // 2]:.2f} s wall "
        f"(runs {', '.join(f'{w:.2f}' for w in walls)}), {cpus[len(cpus) // 2]:.2f} s CPU; target < 10 s"
    )
    for axis in ("vertical", "horizontal"):
        x = a.axis(axis)
        s = x.services["LPV-200"]
        print(
            f"  {axis}: {x.n_epochs:,} epochs, {x.ratio_fit.distribution} sigma {x.ratio_fit.sigma:.4g}, "
            f"P_MI {fp(x.p_mi, x.log10_p_mi)} (bound {fp(x.p_mi_bound, x.log10_p_mi_bound)}, truth "
            f"{sim.p_mi_true(axis):.3e}); tau ratio {x.decorrelation_s:g} s, PL {x.pl_decorrelation_s:g} s; "
            f"LPV-200 unavailability fit {s.unavailability_fit:.3g} [{fp(s.unavailability_bound)}] counted "
            f"{s.unavailability_counted:.3g}, non-continuity counted {fp(s.continuity_counted)} fit "
            f"{fp(s.continuity_fit)} [{fp(s.continuity_fit_bound)}]"
        )
    return a


def bench_outputs(a, table, out: Path) -> None:
    """Time the JSON and the page with its figures."""
    _, wall, _ = timed(lambda: write_parametric(a, out / "parametric.json"))
    print(f"write_parametric (JSON): {wall:.2f} s")
    page, wall, cpu = timed(lambda: write_parametric_report(a, out, table=table))
    n_fig = page.read_text(encoding="utf-8").count("<img ")
    print(f"write_parametric_report ({n_fig} figures): {wall:.2f} s wall, {cpu:.2f} s CPU")


#: Writes the station as Parquet (in its own process, so that this one stays small for the command).
_WRITE = """
import sys
from overbound.simulate import SimulationConfig, simulate, write_simulation
cfg = SimulationConfig(days=float(sys.argv[1]), sigma_ratio=1.2, tail_fraction=0.0, seed=1)
write_simulation(simulate(cfg), sys.argv[2])
"""
#: Runs the command and prints its own peak RSS on exit (read in the child: a forked child's peak would
#: include its parent's memory).
_CLI = """
import atexit, resource, runpy, sys
peak = lambda: print("PEAK_MB", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, file=sys.stderr)
atexit.register(peak)
sys.argv = ["overbound", "parametric", sys.argv[1], "-o", sys.argv[2]]
runpy.run_module("overbound", run_name="__main__")
"""


def bench_cli(path: Path, out: Path) -> None:
    """Time ``overbound parametric`` on the Parquet file in a fresh process, with its peak memory."""
    w0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", _CLI, str(path), str(out)], capture_output=True, text=True)
    wall = time.perf_counter() - w0
    if r.returncode:
        print("overbound parametric failed:", r.stderr.strip()[-500:])
        return
    peak = next(float(ln.split()[1]) for ln in r.stderr.splitlines() if ln.startswith("PEAK_MB"))
    n_fig = (out / "parametric.html").read_text(encoding="utf-8").count("<img ")
    print(
        f"overbound parametric on the Parquet file (read, analysis, JSON, {n_fig} figures, HTML): "
        f"{wall:.2f} s wall, peak {peak:,.0f} MB"
    )


def main() -> None:
    days = float(sys.argv[1]) if len(sys.argv) > 1 else 90.0
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "station.parquet"
        subprocess.run([sys.executable, "-c", _WRITE, str(days), str(path)], check=True)
        bench_cli(path, Path(tmp) / "cli")  # first, while this process is small
        t0 = time.perf_counter()
        sim = simulate(SimulationConfig(days=days, sigma_ratio=1.2, tail_fraction=0.0, seed=1))
        took = time.perf_counter() - t0
        print(f"simulated {sim.table.height:,} epochs in {took:.1f} s ({os.cpu_count()} cores)")
        out = Path(tmp) / "out"
        out.mkdir()
        a = bench_analysis(sim.table, sim)
        bench_outputs(a, sim.table, out)


if __name__ == "__main__":
    main()
