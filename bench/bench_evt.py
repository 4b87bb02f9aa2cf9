"""Speed of the whole EVT tail analysis (:func:`overbound.methods.tail_extrapolation.tail_analysis`).

Usage: ``python bench/bench_evt.py [DAYS]``. Simulates a 1 Hz station of ``DAYS`` days (default 90,
a 3-month campaign: 7.8e6 epochs; sigma ratio 1.2, no heavy-tail regime), then times one
``tail_analysis`` with the defaults (automatic threshold and cluster gap, declustering, 1000
bootstrap resamples, GEV on daily maxima, KRS and tail overbounding, HMI for every vertical service)
and prints the breakdown per step (target: whole analysis under 30 s on 2 cores). The simulation
and the table are not counted.
"""

from __future__ import annotations

import os
import sys
import time
import warnings

from overbound.methods.tail_extrapolation import evt_dict, tail_analysis
from overbound.simulate import SimulationConfig, simulate


def main() -> None:
    days = float(sys.argv[1]) if len(sys.argv) > 1 else 90.0
    t0 = time.perf_counter()
    sim = simulate(SimulationConfig(days=days, sigma_ratio=1.2, tail_fraction=0.0, seed=1))
    print(f"simulated {sim.table.height} epochs in {time.perf_counter() - t0:.1f} s ({os.cpu_count()} cores)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        t1 = time.perf_counter()
        a = tail_analysis(sim.table, n_boot=1000, rng=0)
        total = time.perf_counter() - t1
    for step, sec in a.timings.items():
        print(f"  {step:<14s} {sec:7.2f} s")
    d = evt_dict(a)
    print(
        f"tail_analysis: {total:.2f} s (target < 30 s); threshold {d['threshold']:.4g}, "
        f"{d['n_clusters']} clusters, P_MI {d['p_mi']:.3e} [{d['p_mi_ci'][0]:.3e}, {d['p_mi_ci'][1]:.3e}], "
        f"truth {sim.p_mi_true('vertical'):.3e}"
    )


if __name__ == "__main__":
    main()
