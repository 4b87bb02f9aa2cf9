"""Speed of the GPD bootstrap (:func:`overbound.stats.bootstrap.bootstrap_gpd`).

Usage: ``python bench/bench_gpd_bootstrap.py``. Draws 1e4 GPD(xi=0.2) excesses and times a
1000-resample iid bootstrap (target: under 1 s on 2 cores), then the same work done the generic way,
each timed on 20 resamples and extrapolated to 1000:

* a Python loop of ``scipy.stats.genpareto.fit(y, floc=0)``;
* R's evd ``fpot`` in an R loop (``Rscript``, timed inside R with ``system.time``, so R's start-up
  is excluded), when ``Rscript`` and evd are installed (otherwise it says "R not available");
* pyextremes' bootstrap (``EVA.get_summary(return_period=..., alpha=0.95, n_samples=20)`` on the
  same excesses as an hourly series, declustering off), when pyextremes is importable; its time
  includes the point fit and summary overhead, divided by ``n_samples``.

Prints every time and the ratios against ours, and checks that our resample fits agree with scipy's
on the timed resamples.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
from scipy import stats

from _timing import run_r
from overbound.stats.bootstrap import bootstrap_gpd

N_EXC = 10_000
N_BOOT = 1000
N_SLOW = 20


def time_ours(y: np.ndarray) -> float:
    bootstrap_gpd(y, n_boot=50, rng=0)  # warm-up
    times = []
    for k in range(5):
        t0 = time.perf_counter()
        bootstrap_gpd(y, n_boot=N_BOOT, rng=k)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def time_scipy(y: np.ndarray, idx: np.ndarray) -> tuple[float, np.ndarray]:
    t0 = time.perf_counter()
    xi = np.array([stats.genpareto.fit(y[i], floc=0)[0] for i in idx])
    return (time.perf_counter() - t0) / len(idx) * N_BOOT, xi


_R_LOOP = """
idx <- matrix(as.integer(idx), nrow = nrow) + 1L
tt <- system.time(for (k in seq_len(nrow)) fpot(y[idx[k, ]], threshold = 0, std.err = FALSE))
cat("seconds", tt[["elapsed"]], "\\n")
"""


def time_r(y: np.ndarray, idx: np.ndarray) -> float | None:
    res = run_r(f"nrow <- {idx.shape[0]}L\n{_R_LOOP}", {"y": y, "idx": idx.T})
    return None if res is None else res["seconds"] / len(idx) * N_BOOT


def time_pyextremes(y: np.ndarray) -> float | None:
    try:
        import pandas as pd
        from pyextremes import EVA
    except ImportError:
        print("pyextremes not importable: no pyextremes ratio")
        return None
    series = pd.Series(y + 1.0, index=pd.date_range("2020-01-01", periods=y.size, freq="h"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        eva = EVA(series)
        eva.get_extremes(method="POT", threshold=1.0 - 1e-12, r="1s")
        eva.fit_model()
        t0 = time.perf_counter()
        eva.get_summary(return_period=[10.0], alpha=0.95, n_samples=N_SLOW)
        dt = time.perf_counter() - t0
    return dt / N_SLOW * N_BOOT


def main() -> None:
    rng = np.random.default_rng(2024)
    y = stats.genpareto.rvs(0.2, size=N_EXC, random_state=rng)
    idx = rng.integers(0, N_EXC, size=(N_SLOW, N_EXC))
    ours = time_ours(y)
    print(f"bootstrap_gpd: {N_BOOT} resamples of {N_EXC} excesses: {ours:.3f} s (target < 1 s)")
    t_sc, xi_sc = time_scipy(y, idx)
    print(f"scipy genpareto.fit loop (extrapolated from {N_SLOW}): {t_sc:.1f} s, ratio {t_sc / ours:.0f}x")
    from overbound.stats.bootstrap import _fit_chunk
    from overbound.stats.evt import fit_gpd

    f = fit_gpd(y)
    xi_ours = _fit_chunk(y[idx], f.xi / f.sigma)[0]
    print(f"  max |xi ours - xi scipy| on those resamples: {np.max(np.abs(xi_ours - xi_sc)):.1e}")
    t_r = time_r(y, idx)
    if t_r is not None:
        print(f"R evd fpot loop (extrapolated from {N_SLOW}): {t_r:.1f} s, ratio {t_r / ours:.0f}x")
    t_pe = time_pyextremes(y)
    if t_pe is not None:
        print(f"pyextremes get_summary bootstrap (extrapolated): {t_pe:.1f} s, ratio {t_pe / ours:.0f}x")


if __name__ == "__main__":
    main()
