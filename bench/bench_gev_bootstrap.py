"""Speed of the GEV bootstrap on block maxima (:func:`overbound.stats.bootstrap.bootstrap_gev`).

Usage: ``python bench/bench_gev_bootstrap.py``. Draws 90 GEV(xi=0.1) "daily maxima" of a safety index
(Veerman et al., section 4: a quarter of daily maxima) and times a 1000-resample iid bootstrap (target:
well under 1 s), then the same work done the generic way, each timed on 10 resamples and extrapolated
to 1000:

* a Python loop of :func:`overbound.stats.evt.fit_gev` (Nelder-Mead from two starts + BFGS polish),
  the per-resample fit the bootstrap replaces;
* R's evd ``fgev`` in an R loop (``Rscript``, timed inside R with ``system.time``, so R's start-up
  is excluded), when ``Rscript`` and evd are installed (otherwise it says "R not available").

Prints every time and the ratios against ours, and checks that our resample fits agree with
``fit_gev`` on the timed resamples.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
from scipy import stats

from _timing import median_time, run_r
from overbound.stats.bootstrap import bootstrap_gev
from overbound.stats.evt import _gev_mle_rows, fit_gev

N_BLOCKS = 90
N_BOOT = 1000
N_SLOW = 10


def time_ours(x: np.ndarray) -> tuple[float, int]:
    start = fit_gev(x)
    seeds = iter(range(100))
    t = median_time(lambda: bootstrap_gev(x, n_boot=N_BOOT, rng=next(seeds), start=start), repeat=5)
    return t, bootstrap_gev(x, n_boot=N_BOOT, rng=0, start=start).n_failed


def time_fit_gev(r: np.ndarray) -> tuple[float, np.ndarray]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        fits = [fit_gev(row) for row in r]
        dt = time.perf_counter() - t0
    return dt / len(r) * N_BOOT, np.array([[f.xi, f.loc, f.scale] for f in fits])


_R_LOOP = """
idx <- matrix(as.integer(idx), nrow = nrow) + 1L
tt <- system.time(for (k in seq_len(nrow)) fgev(x[idx[k, ]], std.err = FALSE))
cat("seconds", tt[["elapsed"]], "\\n")
"""


def time_r(x: np.ndarray, idx: np.ndarray) -> float | None:
    res = run_r(f"nrow <- {idx.shape[0]}L\n{_R_LOOP}", {"x": x, "idx": idx.T})
    return None if res is None else res["seconds"] / len(idx) * N_BOOT


def main() -> None:
    rng = np.random.default_rng(2024)
    x = stats.genextreme.rvs(-0.1, loc=0.3, scale=0.05, size=N_BLOCKS, random_state=rng)  # c = -xi
    idx = rng.integers(0, N_BLOCKS, size=(N_SLOW, N_BLOCKS))
    ours, n_failed = time_ours(x)
    print(
        f"bootstrap_gev: {N_BOOT} resamples of {N_BLOCKS} block maxima: {ours:.3f} s "
        f"(target well under 1 s), {n_failed} not converged"
    )
    t_loop, ref = time_fit_gev(x[idx])
    print(f"fit_gev loop (extrapolated from {N_SLOW}): {t_loop:.1f} s, ratio {t_loop / ours:.0f}x")
    f = fit_gev(x)
    xi, loc, scale, _, status = _gev_mle_rows(x[idx], (f.xi, f.loc, f.scale))
    dev = max(
        float(np.max(np.abs(xi - ref[:, 0]))),
        float(np.max(np.abs(loc - ref[:, 1]))),
        float(np.max(np.abs(scale / ref[:, 2] - 1.0))),
    )
    print(
        f"  max deviation from fit_gev on those resamples (xi, loc, rel. scale): {dev:.1e}, "
        f"all converged: {bool(np.all(status == 0))}"
    )
    t_r = time_r(x, idx)
    if t_r is not None:
        print(f"R evd fgev loop (extrapolated from {N_SLOW}): {t_r:.1f} s, ratio {t_r / ours:.0f}x")


if __name__ == "__main__":
    main()
