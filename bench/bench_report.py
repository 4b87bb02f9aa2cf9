"""Cost of writing the report against the cost of the analysis, on a simulated 6-day 1 Hz station.

Usage: ``python bench/bench_report.py [DAYS] [--processes N]`` (default 6 days; N rendering processes,
default :func:`overbound.report.rendering.default_processes`).

Runs the analysis of ``overbound analyze`` (counting, PL confidence level, EVT, parametric, verdicts) and
of ``overbound confidence``, then writes each report twice: figures drawn inline, and drawn by N worker
processes (:func:`~overbound.report.rendering.parallel_figures`, as the CLI does). Prints the seconds
of each and the ratio report / analysis, the anchor of issue 12: writing the report must cost less
than the analysis (before: the figures of a 6-day ``confidence`` run took 5.6 s against 1.9 s of
analysis). The pool is started before the analysis, as in the CLI, so its start-up is part of what
the analysis pays. Checks that both ways give the same bytes.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

# The heavy imports are made inside the functions: a rendering worker (spawned) imports this script as
# its main module, as it imports the ``overbound`` console script, and must not pay for the analysis stack.


def _analyze(table):
    """The analysis of ``overbound analyze`` with its default methods."""
    from overbound.analysis import analyze
    from overbound.verdict import assess

    a = analyze(table, columns=None, confidence=None, evt=None, parametric=True)
    return a, assess(a)


def _one(name: str, run, write, processes: int, out: Path) -> None:
    from overbound.report.rendering import parallel_figures

    t0 = time.perf_counter()
    result = run()
    t1 = time.perf_counter()
    inline = write(result, out / f"{name}-inline").read_bytes()
    t2 = time.perf_counter()
    with parallel_figures(processes):
        t3 = time.perf_counter()
        result = run()
        t4 = time.perf_counter()
        pooled = write(result, out / f"{name}-pooled").read_bytes()
        t5 = time.perf_counter()
    n_fig = inline.count(b"<img ")
    print(
        f"{name}: {n_fig} figures\n"
        f"  inline:       analysis {t1 - t0:6.2f} s, report {t2 - t1:6.2f} s, "
        f"report/analysis {(t2 - t1) / (t1 - t0):.2f}\n"
        f"  {processes} processes: analysis {t4 - t3:6.2f} s, report {t5 - t4:6.2f} s, "
        f"report/analysis {(t5 - t4) / (t4 - t3):.2f}; whole run {(t5 - t3) / (t2 - t0):.2f} of inline; "
        f"same bytes: {inline == pooled}"
    )


def main() -> None:
    from overbound.analysis import analyze
    from overbound.methods.confidence_level import confidence_analysis
    from overbound.report.confidence import write_confidence_report
    from overbound.report.html import write_report
    from overbound.report.rendering import default_processes
    from overbound.simulate import SimulationConfig, simulate

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("days", nargs="?", type=float, default=6.0)
    parser.add_argument("--processes", type=int, default=default_processes())
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    sim = simulate(SimulationConfig(days=args.days, seed=args.seed, anomalies=("band:15:16:3",)))
    table = sim.table
    print(f"{args.days:g} d, {table.height:,} epochs")
    analyze(table.head(20_000))  # warm-up: imports, first-touch of memory
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        _one(
            "overbound analyze",
            lambda: _analyze(table),
            lambda r, d: write_report(r[0], d, assessment=r[1]),
            args.processes,
            out,
        )
        _one(
            "overbound confidence",
            lambda: [confidence_analysis(table, axis="vertical")],
            lambda r, d: write_confidence_report(r, d),
            args.processes,
            out,
        )


if __name__ == "__main__":
    main()
