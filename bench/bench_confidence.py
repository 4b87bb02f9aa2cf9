"""Throughput of the PL confidence-level analysis (Comby et al. 2003) on a 6-day 1 Hz station.

Usage: ``python bench/bench_confidence.py [DAYS] [--axis vertical|horizontal] [--brute N]``
(default 6 days, vertical, brute force on 3 bins). Simulates a campaign with the ENAC-like
``band:15:16:3`` anomaly, then times the whole analysis (selection of every band, sigma
inflation, confidence level, ideal PL, PL1, PL99) plus the JSON document, and prints seconds
and epochs per second. The target is under 5 s for 6 days (518 400 epochs) on 2 cores.

It then times the two-dimensional brute-force integral of eq. (34)
(:func:`overbound.stats.confidence.confidence_level_bruteforce`) on a few sufficient bins,
checks that it gives the same CL, and extrapolates its cost to every bin that has a CL: the
ratio against the one-dimensional :func:`~overbound.stats.confidence.confidence_level`.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from overbound.methods.confidence_level import confidence_analysis
from overbound.report.confidence import confidence_dict
from overbound.report.json import dumps
from overbound.simulate import SimulationConfig, simulate
from overbound.stats import confidence as cl_module


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("days", nargs="?", type=float, default=6.0)
    parser.add_argument("--axis", default="vertical", choices=("vertical", "horizontal"))
    parser.add_argument("--brute", type=int, default=3, help="bins integrated by brute force (0: skip)")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()

    anomaly = "band:15:16:3" if args.axis == "vertical" else "band:8:9:3:h"
    sim = simulate(SimulationConfig(days=args.days, seed=args.seed, tail_fraction=0.0, anomalies=(anomaly,)))
    table = sim.table
    confidence_analysis(table.head(20_000), axis=args.axis)  # warm-up: imports, first-touch of memory

    t0 = time.perf_counter()
    analysis = confidence_analysis(table, axis=args.axis)
    t1 = time.perf_counter()
    text = dumps(confidence_dict(analysis))
    t2 = time.perf_counter()
    wall = t2 - t0
    with_cl = [i for i, b in enumerate(analysis.bins) if np.isfinite(b.confidence)]
    print(
        f"{args.days:g} d {args.axis}: {table.height:,} epochs, {len(analysis.bins)} bins "
        f"({len(with_cl)} with a CL, {len(analysis.suspect)} suspect); analysis {t1 - t0:.2f} s + JSON "
        f"{t2 - t1:.2f} s ({len(text):,} bytes) = {wall:.2f} s, {table.height / wall:,.0f} epochs/s"
    )

    brute = getattr(cl_module, "confidence_level_bruteforce", None)
    if brute is None or args.brute <= 0 or not with_cl:
        return
    # the worst bin (a CL far in the tail) and bins spread over the rest
    spread = [with_cl[k] for k in np.linspace(0, len(with_cl) - 1, max(args.brute - 1, 1)).astype(int)]
    picks = list(dict.fromkeys([analysis.worst, *spread]))[: args.brute]
    fast_s = brute_s = 0.0
    for i in picks:
        b, s = analysis.bins[i], analysis.samples[i]
        model = {"mean": b.mean, "sigma": b.sigma_inflated, "n": b.n, "axis": args.axis}
        t0 = time.perf_counter()
        fast = cl_module.confidence_level(s.pl, **model)
        t1 = time.perf_counter()
        slow = brute(s.pl, **model)
        t2 = time.perf_counter()
        fast_s, brute_s = fast_s + t1 - t0, brute_s + t2 - t1
        print(
            f"  bin {b.target:6.2f} m, n = {b.n}: CL {fast:.6g} in {1e3 * (t1 - t0):.1f} ms; "
            f"brute force {slow:.6g} in {t2 - t1:.2f} s (difference {abs(fast - slow):.1e})"
        )
    per_bin = brute_s / len(picks)
    print(
        f"  brute force: {per_bin:.2f} s per bin, about {per_bin * len(with_cl):.0f} s for the "
        f"{len(with_cl)} bins with a CL (the whole analysis takes {wall:.2f} s): "
        f"{brute_s / fast_s:,.0f} times the one-dimensional integral"
    )


if __name__ == "__main__":
    main()
