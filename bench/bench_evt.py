"""Speed of the whole EVT tail analysis (:func:`overbound.methods.tail_extrapolation.tail_analysis`).

Usage: ``python bench/bench_evt.py [DAYS]``. Simulates a 1 Hz station of ``DAYS`` days (default 90,
a 3-month campaign: 7.8e6 epochs; sigma ratio 1.2, no heavy-tail regime), then times one
``tail_analysis`` with the defaults (automatic threshold and cluster gap, declustering, 1000
bootstrap resamples, GEV on daily maxima, KRS and tail overbounding, HMI for every vertical service)
and prints the breakdown per step (target: whole analysis under 30 s on 2 cores). The simulation
and the table are not counted.

Then the same safety-index series (SI = |VPE|/VPL on the epochs with a solution, as analysed) goes
through the generic pipelines with the threshold u and cluster gap K_T that our analysis chose
(read from :func:`evt_dict`), and prints each time and its ratio (theirs / ours) to our whole
analysis and to our ``tail`` step alone (declustering, automatic threshold, GPD fit, bootstrap; the
cluster gap K_T is estimated in the ``dependence`` step, which the generic pipelines are spared):

* pyextremes (when importable): ``EVA`` on the series (DatetimeIndex), ``get_extremes(method="POT",
  threshold=u, r=K_T)``, ``fit_model("MLE", distribution="genpareto")`` and ``get_summary(
  return_period=[1], alpha=0.95, n_samples=N)`` timed with N = 50 resamples (one process) and
  extrapolated linearly to 1000 resamples (said in the output). Building the pandas Series is not
  counted.
* R evd (when ``Rscript`` and evd are installed; otherwise it says "R not available"): the series on
  its regular grid (1 s; ``NA`` in gaps) handed over as a binary file, then ``clusters(x, u, r, cmax
  = TRUE)`` with r = floor(K_T / 1 s) epochs (the same clusters as ours: a new one after a gap > K_T),
  ``fpot`` of the cluster maxima and a loop of 1000 ``fpot`` on resampled cluster maxima (each with
  its P(SI > 1)), all timed inside R with ``system.time`` (R's start-up and the data loading not
  counted).

These generic pipelines cover only declustering + GPD fit + bootstrap: our analysis also selects
the threshold automatically (goodness-of-fit tests), estimates the cluster gap and the extremal
index, fits a GEV, runs KRS and tail overbounding and repeats the tail fit for every service. Both
cluster counts are printed: the generic ones decluster at u, ours forms the clusters at the lower
dependence level and keeps those whose maximum exceeds u, so ours can be fewer; the plain runs
declustering at u (:func:`decluster_runs`) must match theirs.
"""

from __future__ import annotations

import math
import os
import sys
import time
import warnings

import numpy as np
import polars as pl

from _timing import run_r
from overbound.methods.tail_extrapolation import evt_dict, tail_analysis
from overbound.simulate import SimulationConfig, simulate
from overbound.stats.dependence import decluster_runs

N_BOOT = 1000
N_PYEXTREMES = 50  # one process (pyextremes pools above 50 samples); extrapolated to N_BOOT


def safety_index(table: pl.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """Times (datetime64[us]) and SI = |VPE|/VPL of the epochs the analysis uses (finite, PL > 0)."""
    t = table["time"].to_numpy()
    pe = np.abs(table["vpe"].to_numpy())
    pls = table["vpl"].to_numpy()
    ok = np.isfinite(pe) & np.isfinite(pls) & (pls > 0)
    if "alert" in table.columns:
        ok &= ~table["alert"].fill_null(False).to_numpy()
    return t[ok], pe[ok] / pls[ok]


def run_ours(table: pl.DataFrame) -> tuple[dict, dict[str, float], float]:
    """evt_dict, per-step timings and wall time of one tail_analysis with the defaults."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        t0 = time.perf_counter()
        a = tail_analysis(table, n_boot=N_BOOT, rng=0)
        total = time.perf_counter() - t0
    return evt_dict(a), dict(a.timings), total


def time_pyextremes(t: np.ndarray, si: np.ndarray, u: float, k_t: float) -> tuple[float, int] | None:
    """Extrapolated time of the pyextremes pipeline with N_BOOT resamples, and its cluster count."""
    try:
        import pandas as pd
        from pyextremes import EVA
    except ImportError:
        print("pyextremes not importable: no pyextremes ratio")
        return None
    series = pd.Series(si, index=pd.DatetimeIndex(t))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        eva = EVA(series)
        eva.get_extremes(method="POT", threshold=u, r=pd.Timedelta(seconds=k_t))
        eva.fit_model("MLE", distribution="genpareto")
        t1 = time.perf_counter()
        eva.get_summary(return_period=[1.0], alpha=0.95, n_samples=N_PYEXTREMES)
        t2 = time.perf_counter()
    return (t1 - t0) + (t2 - t1) / N_PYEXTREMES * N_BOOT, len(eva.extremes)


_R_PIPELINE = f"""
r <- max(1L, as.integer(floor(kt)))
t_decl <- system.time(cl <- clusters(x, u = u, r = r, cmax = TRUE))[["elapsed"]]
y <- as.numeric(cl)
zeta <- sum(x > u, na.rm = TRUE) / sum(!is.na(x))
p_mi <- function(f) zeta * pgpd(1, loc = u, scale = f$estimate[["scale"]], shape = f$estimate[["shape"]],
                                lower.tail = FALSE)
t_fit <- system.time(f <- fpot(y, threshold = u, std.err = FALSE))[["elapsed"]]
set.seed(1)
t_boot <- system.time(p <- vapply(seq_len({N_BOOT}), function(b)
  p_mi(fpot(sample(y, replace = TRUE), threshold = u, std.err = FALSE)), 0))[["elapsed"]]
cat("decluster", t_decl, "\\n")
cat("fit", t_fit, "\\n")
cat("boot", t_boot, "\\n")
cat("n_clusters", length(y), "\\n")
cat("shape", sprintf("%.6g", f$estimate[["shape"]]), "\\n")
cat("p_mi", sprintf("%.6g", p_mi(f)), "\\n")
"""


def time_r(t: np.ndarray, si: np.ndarray, u: float, k_t: float) -> dict[str, float] | None:
    """R evd pipeline on the series laid on its regular grid (NA in gaps), K_T in grid epochs."""
    t_us = t.astype("datetime64[us]").astype(np.int64)
    dt_us = float(np.median(np.diff(t_us)))
    k = np.rint((t_us - t_us[0]) / dt_us).astype(np.int64)
    x = np.full(int(k[-1]) + 1, np.nan)
    x[k] = si
    return run_r(_R_PIPELINE, {"x": x, "u": np.array([u]), "kt": np.array([k_t * 1e6 / dt_us])})


def print_ratio(name: str, theirs: float, total: float, timings: dict[str, float]) -> None:
    """Their time and the ratios to our whole analysis and (when timed) to our tail step."""
    line = f"{name}: {theirs:.2f} s, ratio {theirs / total:.2f}x our whole analysis"
    if timings.get("tail"):
        line += f", {theirs / timings['tail']:.1f}x our tail step"
    print(line)


def main() -> None:
    days = float(sys.argv[1]) if len(sys.argv) > 1 else 90.0
    t0 = time.perf_counter()
    sim = simulate(SimulationConfig(days=days, sigma_ratio=1.2, tail_fraction=0.0, seed=1))
    print(f"simulated {sim.table.height} epochs in {time.perf_counter() - t0:.1f} s ({os.cpu_count()} cores)")
    d, timings, total = run_ours(sim.table)
    for step, sec in timings.items():
        print(f"  {step:<14s} {sec:7.2f} s")
    print(
        f"tail_analysis: {total:.2f} s (target < 30 s); threshold {d['threshold']:.4g}, "
        f"K_T {d['cluster_gap_s']:.4g} s, {d['n_clusters']} clusters, shape {d['gpd']['shape']:.4g}, "
        f"P_MI {d['p_mi']:.3e} [{d['p_mi_ci'][0]:.3e}, {d['p_mi_ci'][1]:.3e}], "
        f"truth {sim.p_mi_true('vertical'):.3e}"
    )
    u, k_t = float(d["threshold"]), float(d["cluster_gap_s"])
    t, si = safety_index(sim.table)
    plain = decluster_runs(t.astype("datetime64[us]").astype(np.int64) / 1e6, si, threshold=u, run_length=k_t)
    print(
        "generic pipelines (declustering + GPD fit + 1000-resample bootstrap only) at the same u and K_T; "
        f"plain runs declustering at u: {plain.n_clusters} clusters"
    )
    pe = time_pyextremes(t, si, u, k_t)
    if pe is not None:
        print_ratio(
            f"pyextremes EVA + POT + MLE + get_summary ({N_PYEXTREMES} resamples extrapolated to {N_BOOT}; "
            f"{pe[1]} clusters)",
            pe[0],
            total,
            timings,
        )
        if pe[1] != plain.n_clusters:
            print("  pyextremes and decluster_runs at u give DIFFERENT cluster counts")
    r = time_r(t, si, u, k_t)
    if r is not None:
        t_r = r["decluster"] + r["fit"] + r["boot"]
        print_ratio(
            f"R evd clusters {r['decluster']:.2f} s + fpot {r['fit']:.3f} s + {N_BOOT} fpot "
            f"{r['boot']:.2f} s ({r['n_clusters']:.0f} clusters; shape {r['shape']:.4g}, "
            f"P_MI {r['p_mi']:.3e})",
            t_r,
            total,
            timings,
        )
        if not math.isclose(r["n_clusters"], plain.n_clusters):
            print("  R evd and decluster_runs at u give DIFFERENT cluster counts")


if __name__ == "__main__":
    main()
