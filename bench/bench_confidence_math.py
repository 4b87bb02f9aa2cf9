"""Speed of the confidence-level mathematics (:mod:`overbound.stats.confidence`, :mod:`...overbounding`).

Usage: ``python bench/bench_confidence_math.py``. Prints the median wall time of
:func:`confidence_level` and :func:`pl_at_confidence` for PL bands of n = 200 and 1500 samples on
both axes, of :func:`sigma_inflation`, and the ratio of the two-dimensional integration of eq. (34)
(:func:`confidence_level_bruteforce`) to the one-dimensional method, with the difference of their
values. Targets: ``confidence_level`` at n = 1500 well under 20 ms (vertical), ``pl_at_confidence``
under 50 ms.
"""

from __future__ import annotations

import time

import numpy as np

from _timing import median_time
from overbound.stats.confidence import confidence_level, confidence_level_bruteforce, pl_at_confidence
from overbound.stats.overbounding import sigma_inflation


def band(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian errors (sigma 2.3 m, one 9 m outlier) and a 0.25 m PL band around the PL whose
    vertical confidence level is 1/2, so that the integrals are neither 0 nor 1."""
    errors = rng.normal(0.3, 2.3, n)
    errors[0] = 9.0
    fit = sigma_inflation(errors)
    centre = pl_at_confidence(0.5, mean=fit.mean, sigma=fit.sigma_inflated, n=n)
    return centre + rng.uniform(-0.125, 0.125, n), errors


def main() -> None:
    rng = np.random.default_rng(1)
    for n in (200, 1500):
        pl, errors = band(n, rng)
        inflation = sigma_inflation(errors)
        t = median_time(lambda e=errors: sigma_inflation(e), 50)
        print(f"n = {n}: sigma_inflation {t * 1e3:.3f} ms (Sigma = {inflation.sigma_inflated:.3f} m)")
        for axis in ("vertical", "horizontal"):
            kw = {"mean": abs(inflation.mean), "sigma": inflation.sigma_inflated, "n": n, "axis": axis}
            cl = confidence_level(pl, **kw)
            t1 = median_time(lambda kw=kw, pl=pl: confidence_level(pl, **kw), 20 if axis == "vertical" else 5)
            tq = median_time(lambda kw=kw: pl_at_confidence(0.01, **kw), 5)
            t0 = time.perf_counter()
            brute = confidence_level_bruteforce(pl, **kw)
            t2 = time.perf_counter() - t0
            print(
                f"  {axis:10s} CL = {cl:.6f}: confidence_level {t1 * 1e3:7.2f} ms, "
                f"pl_at_confidence {tq * 1e3:6.2f} ms, 2-D integral {t2:6.2f} s "
                f"= {t2 / t1:,.0f} x the 1-D time, |1-D - 2-D| = {abs(cl - brute):.1e}"
            )


if __name__ == "__main__":
    main()
