"""GPD bootstrap (Veerman et al., sections 3.5 and 3.7): the Newton-from-the-point-estimate resample fits
equal the grid-scan core, determinism, the stationary bootstrap's block structure, the resampled
exceedance rate, and percentile-interval coverage by seeded simulation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from overbound.stats.bootstrap import (
    _fit_chunk,
    _stationary_counts,
    bca_ci,
    bootstrap_gpd,
    jackknife_gpd,
    p_exceed_ci,
    percentile_ci,
    stationary_indices,
)
from overbound.stats.evt import _gpd_mle_rows, fit_gpd, gpd_sf


def test_percentile_ci_is_type7_quantiles():
    v = np.arange(101.0)
    assert percentile_ci(v, 0.9) == pytest.approx((5.0, 95.0), abs=1e-12)
    assert percentile_ci(v, 0.5) == pytest.approx((25.0, 75.0), abs=1e-12)
    with pytest.raises(ValueError):
        percentile_ci(v, 1.0)


@pytest.mark.parametrize("xi", [-0.45, -1e-3, 0.0, 0.2, 0.8])
def test_resample_fits_equal_single_fits(xi):
    rng = np.random.default_rng(11)
    y = stats.genpareto.rvs(xi, scale=2.0, size=2000, random_state=rng)
    fit = fit_gpd(y)
    resamples = y[rng.integers(0, y.size, size=(40, y.size))]
    x_new, s_new, ok, _ = _fit_chunk(resamples, fit.xi / fit.sigma)
    x_ref, s_ref, _, st = _gpd_mle_rows(resamples)
    np.testing.assert_allclose(x_new, x_ref, rtol=0, atol=1e-8)
    np.testing.assert_allclose(s_new, s_ref, rtol=1e-8)
    np.testing.assert_array_equal(ok, st == 0)
    # and each row is the fit_gpd of that row
    for k in (0, 17):
        f = fit_gpd(resamples[k])
        assert abs(f.xi - x_new[k]) < 1e-8 and abs(f.sigma / s_new[k] - 1) < 1e-8


def test_fallback_rows_with_unbounded_likelihood():
    # tiny samples near a uniform: some resamples have no interior maximum (xi -> -1)
    rng = np.random.default_rng(3)
    y = rng.uniform(0, 1, size=8) ** 0.2
    resamples = y[rng.integers(0, y.size, size=(200, y.size))]
    x_new, _, ok, nfb = _fit_chunk(resamples, 0.0)
    x_ref, _, _, st = _gpd_mle_rows(resamples)
    np.testing.assert_allclose(x_new, x_ref, atol=1e-8)
    np.testing.assert_array_equal(ok, st == 0)
    assert nfb >= np.sum(st != 0) > 0


def test_same_seed_same_numbers_any_workers():
    y = np.random.default_rng(0).exponential(1.0, 3000)
    a = bootstrap_gpd(y, n_boot=300, rng=5)
    b = bootstrap_gpd(y, n_boot=300, rng=5, workers=1)
    c = bootstrap_gpd(y, n_boot=300, rng=6)
    np.testing.assert_array_equal(a.xi, b.xi)
    np.testing.assert_array_equal(a.sigma, b.sigma)
    assert not np.array_equal(a.xi, c.xi)
    assert a.n_fallback == 0 and a.xi.shape == (300,)


def test_stationary_indices_blocks():
    n, mb = 5000, 20.0
    idx = stationary_indices(n, n_boot=40, mean_block=mb, rng=1)
    assert idx.shape == (40, n) and idx.min() >= 0 and idx.max() < n
    cont = np.mean((np.diff(idx, axis=1) % n) == 1)
    # a block continues with probability 1 - 1/mb (plus 1/n chance of a new start landing next)
    assert abs(cont - (1 - 1 / mb)) < 0.01
    # stationarity: every index is equally likely
    counts = np.bincount(idx.ravel(), minlength=n)
    assert abs(counts.mean() - 40) < 1e-9 and counts.std() < 3 * np.sqrt(40 * mb)
    iid = stationary_indices(n, n_boot=5, mean_block=1.0, rng=1)
    assert np.mean((np.diff(iid, axis=1) % n) == 1) < 0.01


def test_stationary_bootstrap_wider_for_clustered_data():
    # excesses in runs of 10 identical values: the iid bootstrap underestimates the spread
    rng = np.random.default_rng(2)
    y = np.repeat(rng.exponential(1.0, 200), 10)
    iid = bootstrap_gpd(y, n_boot=400, rng=1)
    sb = bootstrap_gpd(y, n_boot=400, rng=1, method="stationary", mean_block=20)
    assert sb.method == "stationary" and sb.mean_block == 20
    assert np.std(sb.xi) > 1.8 * np.std(iid.xi)


def test_percentile_interval_coverage_of_shape():
    # 60 seeded repetitions, n = 400 GPD(0.2) excesses, 200 resamples: nominal 90 %; accept >= 78 %
    hits = 0
    for seed in range(60):
        y = stats.genpareto.rvs(0.2, size=400, random_state=np.random.default_rng(seed))
        lo, hi = bootstrap_gpd(y, n_boot=200, rng=seed).xi_ci(0.9)
        hits += lo <= 0.2 <= hi
    assert hits / 60 >= 0.78


def test_p_exceed_iid_rate_is_binomial():
    y = np.random.default_rng(0).exponential(0.1, 500)
    boot = bootstrap_gpd(y, n_boot=2000, rng=1)
    ci = p_exceed_ci(boot, x_excess=0.5, n_total=100_000, rng=2, level=0.95)
    p = 500 / 100_000
    assert abs(ci.zeta.mean() - p) < 4 * np.sqrt(p * (1 - p) / 100_000 / 2000)
    assert abs(ci.zeta.std() / np.sqrt(p * (1 - p) / 100_000) - 1) < 0.1
    assert ci.p == pytest.approx(p * float(gpd_sf(0.5, xi=boot.xi_hat, sigma=boot.sigma_hat)), rel=1e-12)
    assert ci.lower <= ci.p <= ci.upper_bound <= ci.upper
    np.testing.assert_allclose(ci.samples, ci.zeta * gpd_sf(0.5, xi=boot.xi, sigma=boot.sigma))


def test_stationary_counts_unbiased_and_reflect_clustering():
    n_total = 20_000
    g = np.random.default_rng(4)
    spread = np.sort(g.choice(n_total, 200, replace=False))
    clustered = np.sort((g.choice(n_total // 50, 20, replace=False) * 50)[:, None] + np.arange(10)).ravel()
    c1 = _stationary_counts(spread, n_total, n_boot=2000, mean_block=100.0, g=np.random.default_rng(1))
    c2 = _stationary_counts(clustered, n_total, n_boot=2000, mean_block=100.0, g=np.random.default_rng(1))
    # each resampled position is uniform on the circle: E count = n_u exactly
    assert abs(c1.mean() - 200) < 4 * c1.std() / np.sqrt(2000)
    assert abs(c2.mean() - 200) < 4 * c2.std() / np.sqrt(2000)
    assert c2.std() > 2.0 * c1.std()


def test_p_exceed_needs_positions_for_stationary():
    y = np.random.default_rng(0).exponential(1.0, 100)
    boot = bootstrap_gpd(y, n_boot=50, rng=1, method="stationary")
    with pytest.raises(ValueError):
        p_exceed_ci(boot, x_excess=3.0, n_total=1000)
    ci = p_exceed_ci(boot, x_excess=3.0, n_total=1000, positions=np.arange(0, 1000, 10), rng=3)
    assert ci.zeta.shape == (50,)


# Profile-likelihood interval of the exceedance probability (the other half of the P_MI confidence,
# overbound.stats.evt.profile_ci_exceedance), against a brute-force grid profile.


def _brute_profile_ci(y: np.ndarray, d: float, level: float) -> tuple[float, float, float]:
    """Grid profile: for each p, max over a fine xi grid of the GPD log-likelihood (textbook formula
    -log s - (1 + 1/xi) log(1 + xi y/s), -inf outside the support) with s tied to p."""
    fit = fit_gpd(y)
    cut = fit.loglik - 0.5 * stats.chi2.ppf(level, 1)
    xi = np.linspace(-0.999, 3.0, 1200)
    xi = xi[np.abs(xi) > 1e-9]
    ps = np.geomspace(1e-7, 0.95, 400)
    prof = np.empty(ps.size)
    for k, p in enumerate(ps):
        sig = xi * d / (p**-xi - 1.0)
        arg = 1.0 + xi[:, None] * y[None, :] / sig[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            terms = -np.log(sig)[:, None] - (1.0 + 1.0 / xi)[:, None] * np.log(arg)
        ll = np.where(np.all(arg > 0, axis=1), np.sum(terms, axis=1), -np.inf)
        prof[k] = np.max(ll)
    inside = ps[prof >= cut]
    return float(inside.min()), float(inside.max()), float(ps[1] / ps[0])


@pytest.mark.parametrize(("xi", "x"), [(0.2, 12.0), (-0.3, 2.0), (0.0, 6.0)])
def test_profile_ci_exceedance_matches_brute_force(xi, x):
    from overbound.stats.evt import profile_ci_exceedance

    y = stats.genpareto.rvs(xi, size=150, random_state=np.random.default_rng(7))
    fit = fit_gpd(y)
    lo, hi = profile_ci_exceedance(fit, x, level=0.95)
    blo, bhi, step = _brute_profile_ci(y, x, 0.95)
    assert lo < float(fit.sf(x)) < hi
    # brute-force ends are grid points inside the set: ours lie within one grid step outside them
    assert blo / step <= lo <= blo * 1.0001
    assert bhi / 1.0001 <= hi <= bhi * step
    lo90, hi90 = profile_ci_exceedance(fit, x, level=0.90)
    assert lo < lo90 < hi90 < hi


def test_profile_ci_exceedance_finite_endpoint_gives_zero_lower():
    from overbound.stats.evt import profile_ci_exceedance

    y = stats.genpareto.rvs(-0.4, size=300, random_state=np.random.default_rng(0))
    fit = fit_gpd(y)
    assert fit.xi < 0 and fit.endpoint < 2.45
    # level beyond the fitted endpoint: p_hat = 0 is admissible, lower end exactly 0
    lo, hi = profile_ci_exceedance(fit, 2.45)
    assert fit.sf(2.45) == 0.0 and lo == 0.0 and 0.0 < hi < 0.01
    # level between the data maximum and the endpoint: p = 0 (endpoint = x) still within the cut
    lo2, hi2 = profile_ci_exceedance(fit, 2.3)
    assert lo2 == 0.0 and hi2 > float(fit.sf(2.3)) > 0.0
    # brute force: some tiny p > 0 lies inside the cut at 2.3, consistent with a lower end of 0
    blo, _, _ = _brute_profile_ci(y, 2.3, 0.95)
    assert blo < 1e-6


def test_bootstrap_gpd_paired_sums_follow_the_resamples():
    """Paired values are summed over the same draws as the fit, and do not change the fits."""
    rng = np.random.default_rng(4)
    y = rng.exponential(1.0, 300)
    ones = np.ones(y.size)
    big = (y > 2.0).astype(float)
    a = bootstrap_gpd(y, n_boot=50, rng=9)
    b = bootstrap_gpd(y, n_boot=50, rng=9, paired=np.vstack([ones, big, y]))
    np.testing.assert_array_equal(a.xi, b.xi)
    assert a.paired_sums.shape == (50, 0) and b.paired_sums.shape == (50, 3)
    np.testing.assert_array_equal(b.paired_sums[:, 0], y.size)  # every resample draws n excesses
    assert np.all(b.paired_sums[:, 1] <= y.size) and b.paired_sums[:, 1].std() > 0
    # the mean excess of a resample (sum y / n) and its GPD scale move together
    assert np.corrcoef(b.paired_sums[:, 2], b.sigma)[0, 1] > 0.5
    with pytest.raises(ValueError, match="columns"):
        bootstrap_gpd(y, n_boot=5, rng=1, paired=np.ones((2, 10)))


# --------------------------------------------------------------------------------------------------
# BCa interval and the GPD jackknife


@pytest.mark.parametrize("seed", [4, 5])
def test_bca_ci_equals_scipy_bca_on_its_own_resamples(seed):
    """Given scipy's bootstrap distribution and the jackknife, bca_ci reproduces scipy's BCa interval."""
    x = np.random.default_rng(seed).exponential(1.0, 60)  # skewed: z0 and a are both non-zero
    res = stats.bootstrap((x,), np.mean, method="BCa", n_resamples=4000, rng=np.random.default_rng(1))
    jk = np.array([np.delete(x, i).mean() for i in range(x.size)])
    lo, hi = bca_ci(res.bootstrap_distribution, x.mean(), jk, 0.95)
    assert lo == pytest.approx(res.confidence_interval.low, rel=1e-12)
    assert hi == pytest.approx(res.confidence_interval.high, rel=1e-12)
    assert (lo, hi) != pytest.approx(percentile_ci(res.bootstrap_distribution, 0.95), rel=1e-6)


def test_bca_ci_reduces_to_percentile_without_bias_and_skew():
    s = np.random.default_rng(0).normal(size=2001)
    med = float(np.median(s))
    assert bca_ci(s, med, np.linspace(-1.0, 1.0, 41), 0.9) == pytest.approx(percentile_ci(s, 0.9), rel=1e-12)
    # an estimate above most replicates (a downward-biased bootstrap) moves both ends up
    lo, hi = bca_ci(s, float(np.quantile(s, 0.8)), np.linspace(-1.0, 1.0, 41), 0.9)
    plo, phi = percentile_ci(s, 0.9)
    assert lo > plo and hi > phi


@pytest.mark.parametrize(("xi", "n"), [(-0.3, 80), (0.0, 120), (0.4, 60)])
def test_jackknife_gpd_equals_leave_one_out_fits(xi, n):
    y = stats.genpareto.rvs(xi, scale=1.0, size=n, random_state=np.random.default_rng(7))
    jxi, jsig = jackknife_gpd(y)
    for i in (0, n // 2, n - 1, int(np.argmax(y))):
        f = fit_gpd(np.delete(y, i))
        assert jxi[i] == pytest.approx(f.xi, abs=1e-7)
        assert jsig[i] == pytest.approx(f.sigma, rel=1e-7)


def test_bca_acceleration_is_scale_free_down_to_underflow():
    # jackknife values of a P_MI near 1e-200: their cubed deviations underflow a float64; the
    # acceleration is scale-free and must not divide by zero (seen in the verdict validation)
    from overbound.stats.bootstrap import bca_ci

    rng = np.random.default_rng(3)
    samples = rng.lognormal(0.0, 1.0, 500)
    jack = rng.lognormal(0.0, 0.3, 40)
    ref = bca_ci(samples, 1.0, jack, 0.95)
    tiny = bca_ci(samples * 1e-200, 1e-200, jack * 1e-200, 0.95)
    assert tiny[0] == pytest.approx(ref[0] * 1e-200, rel=1e-9)
    assert tiny[1] == pytest.approx(ref[1] * 1e-200, rel=1e-9)
