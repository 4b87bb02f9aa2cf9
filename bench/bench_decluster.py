"""Speed of runs declustering and the extremal index (:mod:`overbound.stats.dependence`).

Usage: ``python bench/bench_decluster.py``. Simulates a 1 Hz safety-index series of 1e6 epochs
(|AR(1)| Gaussian errors over a constant PL, so that exceedances come in clusters), takes the
threshold giving about 5000 exceedances, and prints the median wall time of
:func:`decluster_runs` + :func:`extremal_index` (target: under 50 ms), of
:func:`extremal_index` alone, of :func:`vk_curve` + :func:`cluster_gap` on the exceedances, and,
then the same work done the generic way, with the ratio (theirs / ours) to our
:func:`decluster_runs` + :func:`extremal_index`:

* R evd (when ``Rscript`` and evd are installed; otherwise it says "R not available"): runs
  declustering ``clusters(x, u, r = 30, cmax = TRUE)`` (a cluster ends after 30 epochs below u,
  our ``run_length`` of 30 s on the 1 s grid) plus the Ferro-Segers intervals estimator
  ``exi(x, u, r = 0)``, our :func:`extremal_index`. Timed inside R (median of 5 ``system.time``
  after a warm-up: R's start-up and the data loading are not counted); prints both cluster
  counts and both extremal indices, which must agree;
* pyextremes (when importable): ``get_extremes(method="POT", threshold=u, r="30s")`` on the same
  data as a pandas Series with a DatetimeIndex (declustering only: pyextremes has no extremal
  index), checking that it gives the same cluster maxima.
"""

from __future__ import annotations

import numpy as np
import scipy.signal

from _timing import median_time, run_r
from overbound.stats.dependence import cluster_gap, decluster_runs, extremal_index, vk_curve

N = 1_000_000
RUN_LENGTH_S = 30.0


def safety_index(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """1 Hz times (s) and SI = |PE|/PL with PE an AR(1) (correlation time ~ 20 s), PL = 6 sigma."""
    phi = np.exp(-1 / 20)
    pe = scipy.signal.lfilter([np.sqrt(1 - phi**2)], [1.0, -phi], rng.normal(size=n))
    return np.arange(n, dtype=np.float64), np.abs(pe) / 6.0


def main() -> None:
    rng = np.random.default_rng(2026)
    t, si = safety_index(N, rng)
    u = float(np.quantile(si, 1 - 5000 / N))

    def ours() -> tuple[object, float]:
        c = decluster_runs(t, si, threshold=u, run_length=RUN_LENGTH_S)
        return c, extremal_index(t, si, threshold=u)

    c, theta = ours()
    print(
        f"{N:.0e} epochs, threshold {u:.4f}: {c.n_exceedances} exceedances, {c.n_clusters} clusters "
        f"(run length {RUN_LENGTH_S:g} s), extremal index {theta:.3f}"
    )
    t_ours = median_time(ours, 20)
    print(f"decluster_runs + extremal_index: {t_ours * 1e3:.1f} ms (target < 50 ms)")
    t_ei = median_time(lambda: extremal_index(t, si, threshold=u), 20)
    print(f"extremal_index alone:            {t_ei * 1e3:.1f} ms")
    te = t[si > u]
    k = np.arange(0.0, 601.0)
    t_vk = median_time(lambda: cluster_gap(vk_curve(te, k_values=k)), 5)
    k_t = cluster_gap(vk_curve(te, k_values=k))
    print(f"vk_curve (601 K) + cluster_gap:  {t_vk * 1e3:.1f} ms, K_T = {k_t:g} s")
    compare_r(si, u, c.n_clusters, theta, t_ours)
    compare_pyextremes(t, si, u, c.peak_value, t_ours)


_R_SCRIPT = f"""
r <- {round(RUN_LENGTH_S)}L
f <- function() list(cl = clusters(x, u = u, r = r, cmax = TRUE), theta = exi(x, u = u, r = 0))
res <- f()
tt <- replicate(5, system.time(f())[["elapsed"]])
cat("seconds", median(tt), "\\n")
cat("n_clusters", length(res$cl), "\\n")
cat("theta", sprintf("%.17g", res$theta), "\\n")
"""


def compare_r(si: np.ndarray, u: float, n_clusters: int, theta: float, t_ours: float) -> None:
    """R evd clusters() + exi(r = 0) on the same series and threshold (1 s grid: r = run length)."""
    res = run_r(_R_SCRIPT, {"x": si, "u": np.array([u])})
    if res is None:
        return
    same = "same" if res["n_clusters"] == n_clusters and np.isclose(res["theta"], theta) else "DIFFERENT"
    print(
        f"R evd clusters + exi(r = 0):     {res['seconds'] * 1e3:.1f} ms, "
        f"ratio {res['seconds'] / t_ours:.0f}x; clusters R {res['n_clusters']:.0f} / ours {n_clusters}, "
        f"extremal index R {res['theta']:.6f} / ours {theta:.6f} ({same})"
    )


def compare_pyextremes(t: np.ndarray, si: np.ndarray, u: float, peaks: np.ndarray, t_ours: float) -> None:
    """pyextremes' POT declustering with r = run length on the same series as a DatetimeIndex Series."""
    try:
        import pandas as pd
        import pyextremes
    except ImportError:
        print("pyextremes not importable: no pyextremes ratio")
        return
    series = pd.Series(si, index=pd.Timestamp("2026-01-01") + pd.to_timedelta(t, unit="s"))
    r = pd.Timedelta(seconds=RUN_LENGTH_S)

    def theirs() -> object:
        return pyextremes.get_extremes(series, method="POT", threshold=u, r=r)

    ext = theirs()
    assert np.array_equal(ext.to_numpy(), peaks), "pyextremes and decluster_runs disagree"
    t_theirs = median_time(theirs, 3)
    print(
        f"pyextremes get_extremes POT:     {t_theirs * 1e3:.1f} ms (declustering only), "
        f"ratio {t_theirs / t_ours:.0f}x our declustering + extremal index; same {peaks.size} cluster maxima"
    )


if __name__ == "__main__":
    main()
