"""Coverage of the P_MI interval of the EVT tail extrapolation on simulated campaigns with known truth.

Usage::

    python validation/evt_coverage.py [--reps 200] [--days 30] [--sigma-ratio 1.2]
        [--tail-fraction 0] [--no-decluster] [--first-seed 0] [--workers 2] [--out FILE.json]

Each repetition simulates one 1 Hz station (:mod:`overbound.simulate`, seed = ``--first-seed`` +
repetition number; a fresh seed range checks a choice made on another) and
runs :func:`overbound.methods.tail_extrapolation.tail_analysis` with the defaults of ``overbound evt``
(automatic threshold and cluster gap, 1000 bootstrap resamples, 95 % intervals), leaving out what
does not touch P_MI (services, GEV bootstrap, diagnostics). The truth is the simulator's exact
campaign P(SI > 1) per epoch (:meth:`~overbound.simulate.Simulation.p_mi_true`).

Prints and writes (``--out``) the share of repetitions whose two-sided interval ``p_mi_ci`` covers
the truth (target about 0.95, with its binomial 95 % interval), the share whose one-sided upper bound
``p_mi_95`` is at or above the truth (conservative: at least about 0.95), and the median and
quartiles of estimate / truth.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import time
import warnings

import numpy as np
from scipy import stats

from overbound.methods.tail_extrapolation import tail_analysis
from overbound.simulate import SimulationConfig, simulate


def one(args: tuple[int, dict, bool, int]) -> dict:
    """One repetition: the truth, the estimate, its interval and upper bound."""
    seed, cfg, decluster, n_boot = args
    sim = simulate(SimulationConfig(seed=seed, **cfg))
    truth = sim.p_mi_true("vertical")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        a = tail_analysis(
            sim.table,
            decluster=decluster,
            n_boot=n_boot,
            rng=seed,
            services=(),
            gev_boot=0,
            diagnostics=False,
        )
    t = a.tail
    return {
        "seed": seed,
        "truth": truth,
        "p_mi": t.p,
        "p_mi_ci": list(t.p_ci),
        "p_mi_95": t.p_95,
        "p_mi_profile_ci": list(t.p_profile_ci),
        "p_mi_ci_bootstrap": list(t.p_ci_bootstrap),
        "threshold": t.threshold,
        "n_clusters": t.n_clusters,
        "shape": t.gpd.xi,
        "mi_observed": a.n_mi,
    }


def binomial_ci(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Clopper-Pearson interval of a share k/n."""
    a = 1.0 - level
    lo = stats.beta.ppf(a / 2, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(1 - a / 2, k + 1, n - k) if k < n else 1.0
    return float(lo), float(hi)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--days", type=float, default=30.0)
    ap.add_argument("--sigma-ratio", type=float, default=1.2)
    ap.add_argument("--tail-fraction", type=float, default=0.0)
    ap.add_argument("--no-decluster", action="store_true")
    ap.add_argument("--bootstrap", type=int, default=1000)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=None)
    o = ap.parse_args()
    cfg = {"days": o.days, "sigma_ratio": o.sigma_ratio, "tail_fraction": o.tail_fraction}
    seeds = range(o.first_seed, o.first_seed + o.reps)
    jobs = [(s, cfg, not o.no_decluster, o.bootstrap) for s in seeds]
    t0 = time.perf_counter()
    with multiprocessing.get_context("spawn").Pool(o.workers) as pool:
        rows = pool.map(one, jobs, chunksize=1)
    wall = time.perf_counter() - t0
    truth = np.array([r["truth"] for r in rows])
    est = np.array([r["p_mi"] for r in rows])
    lo = np.array([r["p_mi_ci"][0] for r in rows])
    hi = np.array([r["p_mi_ci"][1] for r in rows])
    up = np.array([r["p_mi_95"] for r in rows])
    n = len(rows)
    cover = int(np.count_nonzero((lo <= truth) & (truth <= hi)))
    conservative = int(np.count_nonzero(up >= truth))
    ratio = est / truth
    summary = {
        "config": {
            **cfg,
            "decluster": not o.no_decluster,
            "bootstrap": o.bootstrap,
            "reps": n,
            "first_seed": o.first_seed,
        },
        "truth_median": float(np.median(truth)),
        "coverage": cover / n,
        "coverage_ci": binomial_ci(cover, n),
        "below_interval": int(np.count_nonzero(hi < truth)),
        "above_interval": int(np.count_nonzero(lo > truth)),
        "upper_bound_conservative": conservative / n,
        "upper_bound_conservative_ci": binomial_ci(conservative, n),
        "ratio_quartiles": [float(q) for q in np.quantile(ratio, [0.25, 0.5, 0.75])],
        "log10_ratio_mean": float(np.mean(np.log10(np.where(ratio > 0, ratio, math.nan)))),
        "wall_s": round(wall, 1),
        "rows": rows,
    }
    print(
        f"{n} repetitions of {o.days:g} d, sigma ratio {o.sigma_ratio}, tail fraction {o.tail_fraction}, "
        f"decluster {not o.no_decluster}: truth (median) {summary['truth_median']:.3e}\n"
        f"  interval covers the truth: {cover}/{n} = {cover / n:.3f} "
        f"[{summary['coverage_ci'][0]:.3f}, {summary['coverage_ci'][1]:.3f}] "
        f"(truth below: {summary['above_interval']}, above: {summary['below_interval']})\n"
        f"  upper bound >= truth: {conservative}/{n} = {conservative / n:.3f}\n"
        f"  estimate/truth quartiles {', '.join(f'{q:.2f}' for q in summary['ratio_quartiles'])}; "
        f"{wall:.0f} s on {o.workers} workers"
    )
    if o.out:
        with open(o.out, "w", encoding="utf-8") as f:
            json.dump(summary, f, indent=1)
            f.write("\n")


if __name__ == "__main__":
    main()
