"""Throughput of :func:`overbound.simulate.simulate`.

Usage: ``python bench/bench_simulate.py [DAYS ...]`` (default 1 and 30 days). Prints
epochs per second and the peak resident memory of the process. The target is one
year at 1 Hz (``python bench/bench_simulate.py 365``) in well under 60 s and 6 GB on
2 cores.
"""

from __future__ import annotations

import resource
import sys
import time

from overbound.simulate import SimulationConfig, simulate


def bench(days: float, seed: int = 0) -> tuple[int, float]:
    """Rows simulated and wall time (s) of one campaign of ``days`` days."""
    t0 = time.perf_counter()
    sim = simulate(SimulationConfig(days=days, seed=seed))
    return sim.table.height, time.perf_counter() - t0


def main(argv: list[str]) -> None:
    for days in [float(a) for a in argv] or [1.0, 30.0]:
        rows, wall = bench(days)
        peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
        rate = rows / wall
        print(f"{days:g} d: {rows} epochs in {wall:.2f} s = {rate:,.0f} epochs/s (peak RSS {peak_gb:.2f} GB)")


if __name__ == "__main__":
    main(sys.argv[1:])
