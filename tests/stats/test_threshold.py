"""Threshold selection (Veerman et al., section 3.3; Bader, Yan & Zhang 2018): mean excess against a
direct sum and the GPD's linear mean-excess law, the Anderson-Darling statistic against its textbook
formula, the ForwardStop rule on hand-made p-values, and the automatic choice on simulated data whose
tail is exactly GPD above a known u0."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from overbound.stats.evt import fit_gpd, gpd_isf
from overbound.stats.threshold import (
    anderson_darling_gpd,
    forward_stop,
    mean_excess,
    select_threshold,
    shape_stability,
)

U0 = 2.0


def _mixture(seed: int, n: int = 2000) -> np.ndarray:
    """30 % exactly u0 + GPD(0.1, 1); 70 % below u0 with a rising density (2x/u0^2): not GPD below u0."""
    g = np.random.default_rng(seed)
    up = g.random(n) < 0.3
    return np.where(up, U0 + gpd_isf(g.random(n), xi=0.1, sigma=1.0), U0 * np.sqrt(g.random(n)))


def test_mean_excess_direct_and_gpd_law():
    x = np.random.default_rng(0).normal(size=300)
    u = np.array([-1.0, 0.0, 0.7, 2.0, 10.0])
    direct = [np.mean(x[x > v] - v) if np.any(x > v) else np.nan for v in u]
    np.testing.assert_allclose(mean_excess(x, u), direct, rtol=1e-12)
    # GPD(xi, sigma): E[Y - u | Y > u] = (sigma + xi u) / (1 - xi), linear in u
    xi, sigma = 0.25, 1.0
    y = gpd_isf(np.random.default_rng(1).random(400_000), xi=xi, sigma=sigma)
    uu = np.array([0.0, 0.5, 1.0, 2.0])
    np.testing.assert_allclose(mean_excess(y, uu), (sigma + xi * uu) / (1 - xi), rtol=0.03)


def test_anderson_darling_against_direct_formula():
    y = np.array([0.05, 0.3, 0.2, 1.7, 0.9, 0.4, 2.6, 0.11])
    xi, sigma = 0.15, 0.7
    z = np.sort(stats.genpareto.cdf(y, xi, scale=sigma))
    n = y.size
    a2 = -n - sum((2 * i - 1) * (math.log(z[i - 1]) + math.log(1 - z[n - i])) for i in range(1, n + 1)) / n
    assert anderson_darling_gpd(y, xi=xi, sigma=sigma) == pytest.approx(a2, rel=1e-12)
    # a perfect "quantile" sample of the hypothesised GPD gives a near-zero statistic
    q = gpd_isf((np.arange(1, 201) - 0.5) / 200, xi=xi, sigma=sigma)
    assert anderson_darling_gpd(q, xi=xi, sigma=sigma) < 0.01


def test_forward_stop_rule():
    assert forward_stop(np.array([0.5, 0.001]), alpha=0.05) == 0
    assert forward_stop(np.array([0.001, 0.01, 0.5, 0.9]), alpha=0.05) == 2
    # k = 3 still qualifies: mean of -log(1 - p) over the first three <= 0.1
    p = np.array([0.01, 0.01, 0.2, 0.9, 0.9])
    assert -np.mean(np.log1p(-p[:3])) <= 0.1 < -np.mean(np.log1p(-p[:4]))
    assert forward_stop(p, alpha=0.1) == 3
    assert forward_stop(np.full(4, 0.001), alpha=0.05) == 4


def test_shape_stability_covers_truth_above_u0():
    x = _mixture(3, n=6000)
    res = shape_stability(x, np.array([2.0, 2.5, 3.0, 1e6]), level=0.95)
    assert np.all(res.xi_lower[:3] <= 0.1) and np.all(res.xi_upper[:3] >= 0.1)
    assert np.all(res.xi_lower[:3] < res.xi[:3]) and np.all(res.xi[:3] < res.xi_upper[:3])
    assert res.n_exceedances[-1] == 0 and math.isnan(res.xi[-1])
    f = fit_gpd(x[x > 2.5], threshold=2.5)
    assert res.xi[1] == f.xi


def test_select_threshold_finds_the_gpd_region():
    # the chosen threshold lies at or above u0 (up to the spacing of the candidate quantiles) in most seeds
    chosen = [select_threshold(_mixture(s), n_sim=100, rng=s) for s in range(5)]
    near = sum(c.threshold >= U0 - 0.05 for c in chosen)
    assert near >= 4
    for seed, c in enumerate(chosen):
        assert c.n_exceedances == int(np.sum(_mixture(seed) > c.threshold))
        assert c.goodness_of_fit > 0.05 and "ForwardStop" in c.method
        assert np.all(c.p_values[c.candidates < 1.5] < 0.05)  # far below u0 the GPD is rejected


def test_select_threshold_pure_gpd_keeps_low_threshold_and_is_seeded():
    x = gpd_isf(np.random.default_rng(9).random(1000), xi=0.2, sigma=1.0)
    u = np.quantile(x, [0.0, 0.3, 0.6])
    a = select_threshold(x, candidates=u, n_sim=100, rng=1)
    b = select_threshold(x, candidates=u, n_sim=100, rng=1)
    assert a.threshold == u[0] and a.n_exceedances == 999
    np.testing.assert_array_equal(a.p_values, b.p_values)
    with pytest.raises(ValueError):
        select_threshold(x, candidates=u[::-1])
