"""Exact bounds of counted proportions and rates, and the integrated autocorrelation time."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal, stats

from overbound.stats.proportion import clopper_pearson, integrated_autocorrelation, poisson_bounds


@pytest.mark.parametrize(("k", "n"), [(0, 10), (3, 10), (10, 10), (17, 2000), (1999, 2000)])
def test_clopper_pearson_equals_scipy_exact_interval(k, n):
    # one-sided 95 % bounds are the ends of scipy's exact two-sided 90 % interval
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=0.90, method="exact")
    b = clopper_pearson(k, n, 0.95)
    assert b.estimate == k / n
    assert b.lower == pytest.approx(ci.low, abs=1e-12)
    assert b.upper == pytest.approx(ci.high, abs=1e-12)


def test_clopper_pearson_continuous_in_the_number_of_trials():
    # an effective number of trials keeps the proportion: the bounds move monotonically with it
    widths = [
        clopper_pearson(0.9 * n, n).upper - clopper_pearson(0.9 * n, n).lower for n in (10, 10.5, 11, 50)
    ]
    assert widths == sorted(widths, reverse=True)


@pytest.mark.parametrize("k", [0, 1, 5, 40])
def test_poisson_bounds_are_garwoods(k):
    b = poisson_bounds(k, 0.95)
    lower = 0.0 if k == 0 else stats.chi2.ppf(0.05, 2 * k) / 2
    assert b.lower == pytest.approx(lower, rel=1e-10)
    assert b.upper == pytest.approx(stats.chi2.ppf(0.95, 2 * k + 2) / 2, rel=1e-10)


def test_integrated_autocorrelation_of_ar1():
    # AR(1) with coefficient phi: tau = (1 + phi) / (1 - phi) = 19 for phi = 0.9
    rng = np.random.default_rng(5)
    x = signal.lfilter([1.0], [1.0, -0.9], rng.standard_normal(400_000))
    assert integrated_autocorrelation(x) == pytest.approx(19.0, rel=0.1)
    # a long series goes through block means: the same answer
    assert integrated_autocorrelation(x, max_points=20_000) == pytest.approx(19.0, rel=0.15)
    assert integrated_autocorrelation(rng.standard_normal(100_000)) == pytest.approx(1.0, abs=0.05)
    assert integrated_autocorrelation(np.ones(100)) == 1.0


def test_integrated_autocorrelation_of_a_binary_series_with_runs():
    # runs of geometric length (mean 50) in a two-state Markov chain: tau = (1 + l) / (1 - l), l = 1 - 2/50
    rng = np.random.default_rng(2)
    switch = rng.random(500_000) < 1 / 50
    state = np.cumsum(switch) % 2
    lam = 1 - 2 / 50
    assert integrated_autocorrelation(state.astype(float)) == pytest.approx((1 + lam) / (1 - lam), rel=0.15)


def test_bad_arguments():
    with pytest.raises(ValueError, match="0 <= k <= n"):
        clopper_pearson(3, 2)
    with pytest.raises(ValueError, match="confidence"):
        poisson_bounds(1, 1.0)
