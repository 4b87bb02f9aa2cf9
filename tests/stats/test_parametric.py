"""Parametric MI, availability and integrity statistics (Kannemans 2006, NLR-TP-2006-594, section 2):
ratio fits against scipy.stats and the paper's orders of magnitude, the Weibull ML fit against
scipy.stats.weibull_min.fit, the integrals of section 2.1.3 against scipy.integrate, and the bounds by
seeded simulation with known truth."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, optimize, signal, special, stats

from overbound.stats.parametric import (
    IntegrityProbabilities,
    RatioFit,
    WeibullFit,
    effective_sample_size,
    fit_normal_ratio,
    fit_rayleigh_ratio,
    fit_weibull,
    integrity_probabilities,
    log_ratio_exceedance,
    pe_pl_density,
    ratio_bound,
    ratio_exceedance,
    ratio_pdf,
    ratio_plot_positions,
    weibull_bound,
    weibull_covariance,
    weibull_logpdf,
    weibull_logsf,
    weibull_pdf,
    weibull_pdf_band,
    weibull_plot_positions,
    weibull_sf,
)

LN10 = math.log(10.0)


def _weibull(b: float, scale: float) -> WeibullFit:
    return WeibullFit(a=scale**-b, b=b, n=1, converged=True, iterations=0)


def _normal(m: float, s: float) -> RatioFit:
    return RatioFit("normal", m, s, 1)


def _rayleigh(s: float) -> RatioFit:
    return RatioFit("rayleigh", s * math.sqrt(math.pi / 2.0), s, 1)


def _tight_fmin(func, x0, args=(), disp=0):
    """Nelder-Mead with tight tolerances, so that scipy's own fit reaches the maximum."""
    return optimize.fmin(func, x0, args=args, xtol=1e-12, ftol=1e-10, maxiter=40000, maxfun=80000, disp=0)


def _ar1(rng: np.random.Generator, reps: int, n: int, phi: float) -> np.ndarray:
    """``reps`` stationary unit-variance AR(1) series of length ``n`` (rows)."""
    e = rng.standard_normal((reps, n)) * math.sqrt(1.0 - phi * phi)
    zi = phi * rng.standard_normal((reps, 1))
    return signal.lfilter([1.0], [1.0, -phi], e, axis=1, zi=zi)[0]


def _tolerance(confidence: float, reps: int) -> float:
    """Three binomial standard deviations of a share of ``reps`` repetitions at ``confidence``."""
    return 3.0 * math.sqrt(confidence * (1.0 - confidence) / reps)


# ---------------------------------------------------------------------------------------------
# ratio fits
# ---------------------------------------------------------------------------------------------


def test_paper_orders_of_magnitude():
    """Section 2.1.1: normal sigma 0.059 -> 1.5e-63; section 2.2.1: Rayleigh 0.065 -> 1.1e-52 (the paper's
    sigmas are rounded: the exact values at the rounded sigmas are 2.0e-64 and 4.0e-52)."""
    log_n = float(log_ratio_exceedance(_normal(0.0, 0.059), 1.0))
    assert log_n == pytest.approx(math.log(2.0) + stats.norm.logsf(1.0 / 0.059), rel=1e-13)
    assert abs(log_n / LN10 - math.log10(1.5e-63)) < 1.0
    log_r = float(log_ratio_exceedance(_rayleigh(0.065), 1.0))
    assert log_r == pytest.approx(stats.rayleigh.logsf(1.0, scale=0.065), rel=1e-13)
    assert abs(log_r / LN10 - math.log10(1.1e-52)) < 1.0
    # and the paper's values are reproduced exactly by a sigma inside each rounding interval
    for make, target, lo, hi in ((_normal, 1.5e-63, 0.0585, 0.0595), (_rayleigh, 1.1e-52, 0.0645, 0.0655)):

        def gap(sig, make=make, target=target):
            fit = make(0.0, sig) if make is _normal else make(sig)
            return float(log_ratio_exceedance(fit, 1.0)) - math.log(target)

        assert gap(lo) < 0 < gap(hi)  # a root in [lo, hi]: the paper's sigma rounds to 0.059 / 0.065


@pytest.mark.parametrize(("m", "s"), [(0.0, 0.059), (0.12, 0.2), (-0.3, 0.05), (0.9, 0.4)])
def test_normal_exceedance_matches_scipy(m, s):
    t = np.array([0.0, 0.3, 1.0, 1.7, 4.0, 12.0])
    want = np.logaddexp(stats.norm.logsf(t, m, s), stats.norm.logcdf(-t, m, s))
    got = log_ratio_exceedance(_normal(m, s), t)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-14)
    assert got[0] == pytest.approx(0.0, abs=1e-14)  # Q(0) = 1
    np.testing.assert_allclose(ratio_exceedance(_normal(m, s), t), np.exp(want), rtol=1e-12)
    assert np.all(np.diff(got) < 0)


@pytest.mark.parametrize("s", [0.02, 0.065, 0.5])
def test_rayleigh_exceedance_matches_scipy(s):
    t = np.array([0.0, 0.1, 1.0, 3.0])
    np.testing.assert_allclose(
        log_ratio_exceedance(_rayleigh(s), t), stats.rayleigh.logsf(t, scale=s), rtol=1e-13, atol=0
    )


def test_exceedance_rejects_negative_and_nan():
    with pytest.raises(ValueError, match=">= 0"):
        log_ratio_exceedance(_normal(0.0, 0.1), -0.5)
    with pytest.raises(ValueError, match="NaN"):
        ratio_exceedance(_rayleigh(0.1), np.array([1.0, np.nan]))
    assert float(ratio_exceedance(_normal(0.0, 0.1), np.inf)) == 0.0


def test_ratio_pdf_matches_scipy_and_exceedance():
    y = np.array([-0.2, 0.0, 0.05, 0.3, 1.0])
    m, s = 0.1, 0.2
    want = np.where(y >= 0, stats.foldnorm.pdf(y, m / s, scale=s), 0.0)
    np.testing.assert_allclose(ratio_pdf(_normal(m, s), y), want, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(ratio_pdf(_rayleigh(s), y), stats.rayleigh.pdf(y, scale=s), rtol=1e-12)
    for fit in (_normal(m, s), _rayleigh(s)):  # the pdf's survival function is Q
        tail = integrate.quad(lambda v, f=fit: float(ratio_pdf(f, v)), 0.4, np.inf, epsrel=1e-12)[0]
        assert tail == pytest.approx(float(ratio_exceedance(fit, 0.4)), rel=1e-9)


def test_fits_are_the_stated_estimators():
    rng = np.random.default_rng(3)
    r = rng.normal(0.05, 0.06, 5000)
    f = fit_normal_ratio(r)
    assert (f.distribution, f.n) == ("normal", 5000)
    assert f.mean == pytest.approx(r.mean(), rel=1e-14)
    assert f.sigma == pytest.approx(r.std(ddof=1), rel=1e-14)
    h = stats.rayleigh.rvs(scale=0.065, size=5000, random_state=rng)
    g = fit_rayleigh_ratio(h)
    _, scale = stats.rayleigh.fit(h, floc=0)
    assert g.sigma == pytest.approx(scale, rel=1e-12)  # scipy's ML estimate
    assert g.mean == pytest.approx(stats.rayleigh.mean(scale=g.sigma), rel=1e-14)


@pytest.mark.parametrize(
    ("func", "data", "match"),
    [
        (fit_normal_ratio, [0.1], "at least 2"),
        (fit_normal_ratio, [0.1, 0.1, 0.1], "constant"),
        (fit_normal_ratio, [0.1, np.nan], "finite"),
        (fit_rayleigh_ratio, [0.1, -0.2], ">= 0"),
        (fit_rayleigh_ratio, [0.0, 0.0], "zero"),
        (fit_rayleigh_ratio, [[0.1, 0.2]], "one-dimensional"),
    ],
)
def test_fit_errors(func, data, match):
    with pytest.raises(ValueError, match=match):
        func(np.asarray(data))


def test_effective_sample_size():
    assert effective_sample_size(23400, 1.0, 2000.0) == pytest.approx(11.7)
    assert effective_sample_size(100, 5.0, 1.0) == 100.0  # never more than n
    assert effective_sample_size(100, 1.0, math.inf) == 0.0
    for bad in [(-1, 1.0, 10.0), (10, 0.0, 10.0), (10, 1.0, 0.0), (10, 1.0, math.nan)]:
        with pytest.raises(ValueError):
            effective_sample_size(*bad)


def test_ratio_bound_is_exact_at_the_quantiles():
    """The bound returns the true sigma when the estimate sits at the chi-square quantile (and the mean
    moves by the t quantile): the stated formulas, inverted."""
    c, ne, sigma = 0.95, 40.0, 0.06
    cp = (1 + c) / 2
    s_hat = sigma * math.sqrt(stats.chi2.ppf(1 - cp, ne - 1) / (ne - 1))
    b = ratio_bound(_normal(-0.02, s_hat), ne, c)
    assert b.sigma == pytest.approx(sigma, rel=1e-12)
    assert b.mean == pytest.approx(-0.02 - stats.t.ppf(cp, ne / 2 - 1) * s_hat / math.sqrt(ne / 2), rel=1e-12)
    assert ratio_bound(_normal(0.0, s_hat), ne, c).mean > 0  # sign(0) -> +
    s_hat = sigma * math.sqrt(stats.chi2.ppf(1 - c, 2 * ne) / (2 * ne))
    r = ratio_bound(_rayleigh(s_hat), ne, c)
    assert r.sigma == pytest.approx(sigma, rel=1e-12)
    assert r.mean == pytest.approx(sigma * math.sqrt(math.pi / 2), rel=1e-12)


def test_ratio_bound_limits():
    f, g = _normal(0.03, 0.06), _rayleigh(0.065)
    assert ratio_bound(f, 1.99, 0.95) is None
    assert ratio_bound(f, 2.0, 0.95) is None  # t with n_eff/2 - 1 = 0 degrees of freedom
    assert ratio_bound(f, 2.5, 0.95) is not None
    assert ratio_bound(g, 1.5, 0.95) is None
    assert ratio_bound(g, 2.0, 0.95) is not None
    prev = math.inf
    for ne in [3.0, 30.0, 300.0, 3e6]:  # the bound tightens towards the fit as n_eff grows
        p = float(log_ratio_exceedance(ratio_bound(f, ne, 0.95), 1.0))
        assert float(log_ratio_exceedance(f, 1.0)) < p < prev
        prev = p
    assert ratio_bound(g, 3e8, 0.95).sigma == pytest.approx(g.sigma, rel=1e-3)
    with pytest.raises(ValueError, match="confidence"):
        ratio_bound(f, 10.0, 1.0)
    with pytest.raises(ValueError, match="n_effective"):
        ratio_bound(f, math.nan, 0.95)


def test_ratio_bound_coverage_ar1():
    """Seeded simulation with known truth: 200 ratio series of N = 20000 at 1 s, first-order Gauss-Markov
    with 1/e time 100 s (n_eff = 200), confidence 0.95; the share of series whose bound P_MI is >= the true
    P_MI must be >= 0.95 - 3 binomial sd (0.904). Measured with this seed: normal (m 0.05, sigma 0.059)
    0.98, Rayleigh (sigma 0.065, two independent AR(1) components) 0.95; with 1000 repetitions 0.986 and
    0.957 (Bonferroni makes the normal bound conservative; the Rayleigh chi-square bound is near exact).
    n_eff here comes from the known 1/e time of the components: the 1/e time of the ACF of the Rayleigh
    ratio itself is about half of it (ACF about rho^2), which would double n_eff (shares 0.84-0.87)."""
    rng = np.random.default_rng(20060926)
    reps, n, tau, c = 200, 20000, 100.0, 0.95
    phi = math.exp(-1.0 / tau)
    ne = effective_sample_size(n, 1.0, tau)
    m, s = 0.05, 0.059
    truth = float(log_ratio_exceedance(_normal(m, s), 1.0))
    shares = {}
    ok = [
        float(log_ratio_exceedance(ratio_bound(fit_normal_ratio(r), ne, c), 1.0)) >= truth
        for r in m + s * _ar1(rng, reps, n, phi)
    ]
    shares["normal"] = np.mean(ok)
    s = 0.065
    truth = float(log_ratio_exceedance(_rayleigh(s), 1.0))
    h = s * np.hypot(_ar1(rng, reps, n, phi), _ar1(rng, reps, n, phi))
    ok = [float(log_ratio_exceedance(ratio_bound(fit_rayleigh_ratio(r), ne, c), 1.0)) >= truth for r in h]
    shares["rayleigh"] = np.mean(ok)
    for name, share in shares.items():
        assert share >= c - _tolerance(c, reps), (name, share)


# ---------------------------------------------------------------------------------------------
# Weibull
# ---------------------------------------------------------------------------------------------


def _score(fit: WeibullFit, x: np.ndarray) -> np.ndarray:
    """Mean score of the Weibull log-likelihood in (ln a, b): zero at the ML point."""
    z = fit.a * x**fit.b
    return np.array([np.mean(1 - z), 1 / fit.b + np.mean(np.log(x) * (1 - z))])


@pytest.mark.parametrize(("b", "scale", "n"), [(0.6, 3.0, 400), (1.7, 12.0, 5000), (4.0, 30.0, 2000)])
def test_fit_weibull_matches_scipy(b, scale, n):
    x = stats.weibull_min.rvs(b, scale=scale, size=n, random_state=np.random.default_rng(int(10 * b)))
    f = fit_weibull(x)
    c, loc, lam = stats.weibull_min.fit(x, floc=0, optimizer=_tight_fmin)
    assert (loc, f.n, f.converged) == (0, n, True)
    assert f.b == pytest.approx(c, rel=1e-6)
    assert f.a ** (-1 / f.b) == pytest.approx(lam, rel=1e-6)
    np.testing.assert_allclose(_score(f, x), 0.0, atol=1e-12)
    c0, _, lam0 = stats.weibull_min.fit(x, floc=0)  # scipy's default fit: never a higher likelihood
    assert stats.weibull_min.logpdf(x, f.b, scale=f.a ** (-1 / f.b)).sum() >= (
        stats.weibull_min.logpdf(x, c0, scale=lam0).sum() - 1e-9
    )


def test_fit_weibull_large_sample_with_outliers():
    """Above 131072 values the root is first found on a subsample; the result solves the full likelihood
    equations, also with the PL outliers of the paper's figure 7, and is deterministic."""
    rng = np.random.default_rng(7)
    x = stats.weibull_min.rvs(2.3, scale=20.0, size=400_000, random_state=rng)
    x[rng.integers(0, x.size, 2000)] *= 6.0
    f = fit_weibull(x)
    assert f.converged
    np.testing.assert_allclose(_score(f, x), 0.0, atol=1e-11)
    assert fit_weibull(x) == f
    y = np.ones(300_000)
    y[1::4] = 2.0  # the regular subsample (every 4th value) is constant: start from all values instead
    g = fit_weibull(y)
    assert g.converged
    np.testing.assert_allclose(_score(g, y), 0.0, atol=1e-11)


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ([1.0], "at least 2"),
        ([1.0, 0.0], "> 0"),
        ([1.0, -2.0], "> 0"),
        ([2.0, 2.0], "constant"),
        ([1.0, np.inf], "finite"),
    ],
)
def test_fit_weibull_errors(data, match):
    with pytest.raises(ValueError, match=match):
        fit_weibull(np.asarray(data))


@pytest.mark.parametrize("b", [0.7, 1.0, 2.5])
def test_weibull_functions_match_scipy(b):
    f = _weibull(b, 15.0)
    x = np.array([0.5, 3.0, 15.0, 60.0, 200.0])
    ref = stats.weibull_min(b, scale=15.0)
    np.testing.assert_allclose(weibull_logsf(f, x), ref.logsf(x), rtol=1e-13)
    np.testing.assert_allclose(weibull_sf(f, x), ref.sf(x), rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(weibull_logpdf(f, x), ref.logpdf(x), rtol=1e-13)
    np.testing.assert_allclose(weibull_pdf(f, x), ref.pdf(x), rtol=1e-12, atol=1e-300)
    assert float(weibull_sf(f, -1.0)) == 1.0 and float(weibull_pdf(f, -1.0)) == 0.0
    assert float(weibull_logpdf(f, 0.0)) == pytest.approx(float(ref.logpdf(0.0)))


def test_weibull_covariance_is_the_inverse_observed_information():
    """J from a finite-difference Hessian of scipy's log-likelihood in (ln a, b), at the ML point."""
    x = stats.weibull_min.rvs(1.8, scale=20.0, size=3000, random_state=np.random.default_rng(5))
    f = fit_weibull(x)

    def mean_loglik(theta):
        lam = math.exp(theta[0]) ** (-1 / theta[1])
        return stats.weibull_min.logpdf(x, theta[1], scale=lam).mean()

    theta, h = np.array([math.log(f.a), f.b]), 1e-4
    hess = np.empty((2, 2))
    for i in range(2):
        for j in range(2):
            ei, ej = np.eye(2)[i] * h, np.eye(2)[j] * h
            hess[i, j] = (
                mean_loglik(theta + ei + ej)
                - mean_loglik(theta + ei - ej)
                - mean_loglik(theta - ei + ej)
                + mean_loglik(theta - ei - ej)
            ) / (4 * h * h)
    cov = weibull_covariance(f, x, 150.0)
    np.testing.assert_allclose(cov, np.linalg.inv(-hess) / 150.0, rtol=1e-5)
    with pytest.raises(ValueError, match="n_effective"):
        weibull_covariance(f, x, 0.0)


def test_weibull_bound_is_the_wald_ellipse_maximum():
    """The bound point lies on the ellipse (theta_b - theta)' C^-1 (theta_b - theta) = z^2 and maximises the
    linearised log S(AL) over it (checked against 20000 points of the ellipse)."""
    f = _weibull(2.0, 15.0)
    cov = np.array([[4e-3, -1.2e-3], [-1.2e-3, 5e-4]])
    al, c = 40.0, 0.95
    z = stats.norm.ppf(c)
    wb = weibull_bound(f, cov, al, c)
    d = np.array([math.log(wb.a) - math.log(f.a), wb.b - f.b])
    assert d @ np.linalg.solve(cov, d) == pytest.approx(z * z, rel=1e-10)
    g = -f.a * al**f.b * np.array([1.0, math.log(al)])
    ang = np.linspace(0, 2 * np.pi, 20000)
    ring = z * np.linalg.cholesky(cov) @ np.vstack([np.cos(ang), np.sin(ang)])
    assert g @ d >= (g @ ring).max() - 1e-12
    assert g @ d == pytest.approx(z * math.sqrt(g @ cov @ g), rel=1e-12)
    assert float(weibull_sf(wb, al)) > float(weibull_sf(f, al))
    assert weibull_bound(f, np.zeros((2, 2)), al, c) == f
    with pytest.raises(ValueError, match="b <= 0"):
        weibull_bound(f, cov * 1e4, al, 0.999)


def test_weibull_bound_student_quantile_for_few_effective_samples():
    """With ``dof`` the ellipse's radius is Student's t quantile: wider than the normal one for few
    degrees of freedom, the normal bound in the limit, and no bound for dof <= 0."""
    f = _weibull(2.0, 15.0)
    cov = np.array([[4e-3, -1.2e-3], [-1.2e-3, 5e-4]])
    al, c = 40.0, 0.95
    normal = weibull_bound(f, cov, al, c)
    for dof, radius in ((4.0, stats.t.ppf(c, 4.0)), (1e9, stats.norm.ppf(c))):
        wb = weibull_bound(f, cov, al, c, dof=dof)
        d = np.array([math.log(wb.a) - math.log(f.a), wb.b - f.b])
        assert d @ np.linalg.solve(cov, d) == pytest.approx(radius**2, rel=1e-8)
    assert float(weibull_sf(weibull_bound(f, cov, al, c, dof=4.0), al)) > float(weibull_sf(normal, al))
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="dof"):
            weibull_bound(f, cov, al, c, dof=bad)
    with pytest.raises(ValueError, match="outside floating point"):  # a scale that underflows is no bound
        weibull_bound(f, np.array([[1e6, 0.0], [0.0, 1e-8]]), al, c, dof=1.0)
    with pytest.raises(ValueError, match="outside floating point"):  # nor one that overflows (AL < 1)
        small = WeibullFit(0.01, 2.0, 100, True, 0)
        weibull_bound(small, np.array([[1.0, 1.0], [1.0, 2.0]]), 0.01, c, dof=0.2)


def test_weibull_pdf_band_is_the_delta_method():
    f = _weibull(1.5, 10.0)
    cov = np.array([[2e-3, -6e-4], [-6e-4, 3e-4]])
    x = np.array([-1.0, 0.0, 0.5, 5.0, 10.0, 40.0])
    lo, hi = weibull_pdf_band(f, cov, x, 0.95)
    p = weibull_pdf(f, x)
    z = stats.norm.ppf(0.975)
    theta, h = np.array([math.log(f.a), f.b]), 1e-6

    def logpdf(t, xi):
        return stats.weibull_min.logpdf(xi, t[1], scale=math.exp(t[0]) ** (-1 / t[1]))

    for k in range(2, x.size):  # numerical gradient of scipy's log density
        g = np.array([(logpdf(theta + e, x[k]) - logpdf(theta - e, x[k])) / (2 * h) for e in np.eye(2) * h])
        sd = math.sqrt(g @ cov @ g)
        assert math.log(hi[k] / p[k]) == pytest.approx(z * sd, rel=1e-6)
        assert math.log(p[k] / lo[k]) == pytest.approx(z * sd, rel=1e-6)
    assert lo[0] == hi[0] == 0.0 and lo[1] == hi[1] == p[1]


def test_weibull_plot_positions_small_sample_is_exact():
    x = stats.weibull_min.rvs(2.0, scale=10.0, size=500, random_state=np.random.default_rng(1))
    lx, ly = weibull_plot_positions(x)
    n = x.size
    np.testing.assert_array_equal(lx, np.log(np.sort(x)))
    np.testing.assert_allclose(ly, np.log(-np.log1p(-(np.arange(1, n + 1) - 0.3) / (n + 0.4))), rtol=1e-14)
    slope, intercept = np.polyfit(lx, ly, 1)  # a Weibull sample lies on ln a + b ln x
    assert slope == pytest.approx(2.0, rel=0.1) and intercept == pytest.approx(-2.0 * math.log(10.0), abs=0.3)


def test_plot_positions_thinning():
    """Large samples: at most max_points, every one of the max_points/8 most extreme points of each tail,
    log-spaced ranks to the 1st/99th percentiles, a regular subsample between, each at its own rank."""
    rng = np.random.default_rng(2)
    x = stats.weibull_min.rvs(1.5, scale=10.0, size=300_000, random_state=rng)
    lx, ly = weibull_plot_positions(x, max_points=2000)
    xs = np.sort(x)
    n = x.size
    assert 1500 <= lx.size <= 2000
    assert np.all(np.diff(lx) > 0) and np.all(np.diff(ly) > 0)
    rank = np.searchsorted(xs, np.exp(lx))
    rank = np.where(
        np.abs(xs[np.minimum(rank, n - 1)] - np.exp(lx)) <= np.abs(xs[rank - 1] - np.exp(lx)), rank, rank - 1
    )
    np.testing.assert_allclose(ly, np.log(-np.log1p(-(rank + 0.7) / (n + 0.4))), rtol=1e-12)
    assert set(range(250)) <= set(rank) and set(range(n - 250, n)) <= set(rank)
    inner = rank[(rank > n // 100) & (rank < n - 1 - n // 100)]
    assert np.ptp(np.diff(inner)) <= 1  # evenly spaced between the percentiles
    r = rng.normal(0.02, 0.06, 300_000)
    q_r, q = ratio_plot_positions(_normal(0.02, 0.06), r, max_points=2000)
    assert q_r.size == lx.size and np.all(np.diff(q_r) > 0)
    body = np.abs(q) < 2.0  # normal quantiles: a straight line (the extreme order statistics scatter)
    np.testing.assert_allclose(q_r[body], 0.02 + 0.06 * q[body], atol=2e-3)
    h = stats.rayleigh.rvs(scale=0.065, size=3000, random_state=rng)
    q_h, q = ratio_plot_positions(_rayleigh(0.065), h)
    np.testing.assert_allclose(q, np.sqrt(-2 * np.log1p(-(np.arange(1, 3001) - 0.3) / 3000.4)), rtol=1e-13)
    assert np.polyfit(q, q_h, 1)[0] == pytest.approx(0.065, rel=0.05)
    with pytest.raises(ValueError, match=">= 0"):
        ratio_plot_positions(_rayleigh(0.1), np.array([0.1, -0.1]))


# ---------------------------------------------------------------------------------------------
# integrals (section 2.1.3)
# ---------------------------------------------------------------------------------------------


def _ref_pdf_pl(w: WeibullFit):
    a, b = w.a, w.b
    return lambda x: a * b * x ** (b - 1) * math.exp(-a * x**b)


def _ref_pdf_ratio(fit: RatioFit):
    m, s = fit.mean, fit.sigma
    if fit.distribution == "normal":  # folded normal
        k = 1 / (s * math.sqrt(2 * math.pi))
        return lambda y: k * (math.exp(-0.5 * ((y - m) / s) ** 2) + math.exp(-0.5 * ((y + m) / s) ** 2))
    return lambda y: y / s**2 * math.exp(-0.5 * (y / s) ** 2)


def _ref_q(fit: RatioFit):
    m, s = fit.mean, fit.sigma
    if fit.distribution == "normal":
        r2 = math.sqrt(2.0)
        return lambda t: 0.5 * math.erfc((t - m) / (s * r2)) + 0.5 * math.erfc((t + m) / (s * r2))
    return lambda t: math.exp(-0.5 * (t / s) ** 2)


@pytest.mark.parametrize("ratio", [_normal(0.05, 0.3), _rayleigh(0.3)], ids=["normal", "rayleigh"])
def test_integrals_match_dblquad(ratio):
    """The three regions of the paper's equations, integrated in two dimensions by scipy over the density
    p_PL(x) p_r(y/x) / x (written out independently here)."""
    w, al = _weibull(1.8, 20.0), 20.0
    pl, pr = _ref_pdf_pl(w), _ref_pdf_ratio(ratio)

    def f(y, x):
        return pl(x) * pr(y / x) / x

    opts = {"epsabs": 0.0, "epsrel": 1e-10}
    got = integrity_probabilities(ratio, w, al)
    hmi = integrate.dblquad(f, 0.0, al, al, np.inf, **opts)[0]
    above = integrate.dblquad(f, al, np.inf, lambda x: x, np.inf, **opts)[0]
    below = integrate.dblquad(lambda x, y: f(y, x), 0.0, al, 0.0, lambda y: y, **opts)[0]  # y outer
    assert got.p_hmi == pytest.approx(hmi, rel=1e-6)
    assert got.p_mi_pl_above_al == pytest.approx(above, rel=1e-6)
    assert got.p_mi_pl_below_al == pytest.approx(below, rel=1e-6)


@pytest.mark.parametrize("ratio", [_normal(0.0, 0.2), _normal(-0.15, 0.4), _rayleigh(0.2), _rayleigh(0.4)])
@pytest.mark.parametrize(("b", "scale"), [(0.7, 8.0), (1.8, 20.0), (3.5, 12.0)])
@pytest.mark.parametrize("unavailability", [0.6, 1e-6])
def test_integrals_match_quad(ratio, b, scale, unavailability):
    """One-dimensional forms int_0^AL p_PL(x) Q(AL/x) dx and int_0^AL p_PL(x) [Q(1) - Q(AL/x)] dx (scipy
    quad), for AL in the bulk and far in the PL tail, Weibull shapes below and above 1."""
    w = _weibull(b, scale)
    al = scale * (-math.log(unavailability)) ** (1 / b)
    pl, q = _ref_pdf_pl(w), _ref_q(ratio)
    got = integrity_probabilities(ratio, w, al)
    opts = {"epsabs": 0.0, "epsrel": 1e-12, "limit": 200}
    hmi = integrate.quad(lambda x: pl(x) * q(al / x), 0.0, al, **opts)[0]
    below = integrate.quad(lambda x: pl(x) * (q(1.0) - q(al / x)), 0.0, al, **opts)[0]
    assert got.p_hmi == pytest.approx(hmi, rel=1e-6)
    assert got.p_mi_pl_below_al == pytest.approx(below, rel=1e-6)
    assert got.unavailability == pytest.approx(unavailability, rel=1e-12)
    assert got.p_mi == pytest.approx(q(1.0), rel=1e-12)


@pytest.mark.parametrize(
    "ratio", [_normal(0.0, 0.059), _normal(0.08, 0.3), _normal(0.0, 0.02), _rayleigh(0.065), _rayleigh(0.02)]
)
@pytest.mark.parametrize("al", [12.0, 20.0, 50.0, 120.0])
def test_integral_identities(ratio, al):
    """P_HMI + P_MI(PL<AL) = F(AL) Q(1), P_MI(PL>AL) = S(AL) Q(1) and the three parts sum to Q(1), in log
    space (so also where the probabilities underflow)."""
    w = _weibull(1.5, 18.0)
    got = integrity_probabilities(ratio, w, al)
    log_s = float(weibull_logsf(w, al))
    log_q1 = float(log_ratio_exceedance(ratio, 1.0))
    log_f = math.log(-math.expm1(log_s))
    assert np.logaddexp(got.log10_p_hmi * LN10, got.log10_p_mi_pl_below_al * LN10) == pytest.approx(
        log_f + log_q1, rel=1e-10
    )
    assert got.log10_p_mi_pl_above_al * LN10 == pytest.approx(log_s + log_q1, rel=1e-12)
    assert got.log10_unavailability * LN10 == pytest.approx(log_s, rel=1e-12)
    parts = np.logaddexp.reduce(
        np.array([got.log10_p_hmi, got.log10_p_mi_pl_below_al, got.log10_p_mi_pl_above_al]) * LN10
    )
    assert parts == pytest.approx(got.log10_p_mi * LN10, rel=1e-10)
    assert got.p_hmi == pytest.approx(10**got.log10_p_hmi, rel=1e-10, abs=0)


@pytest.mark.parametrize("ratio", [_normal(0.0, 0.02), _normal(0.03, 0.02), _rayleigh(0.02)])
def test_tiny_sigma_underflows_only_in_p(ratio):
    """sigma 0.02: P_MI about 1e-545 underflows to 0.0; the log10 values stay finite and correct. P_HMI is
    checked against scipy quad of the integrand scaled by Q(1) (log Q from scipy.stats)."""
    w, al = _weibull(2.0, 15.0), 20.0
    got = integrity_probabilities(ratio, w, al)
    if ratio.distribution == "normal":
        m, s = ratio.mean, ratio.sigma

        def log_q(t):
            return float(np.logaddexp(stats.norm.logsf(t, m, s), stats.norm.logcdf(-t, m, s)))
    else:

        def log_q(t):
            return float(stats.rayleigh.logsf(t, scale=ratio.sigma))

    assert got.p_mi == 0.0 and got.p_hmi == 0.0
    assert got.log10_p_mi == pytest.approx(log_q(1.0) / LN10, rel=1e-12)
    assert got.log10_p_mi < -500
    pl = _ref_pdf_pl(w)
    scaled = integrate.quad(
        lambda x: pl(x) * math.exp(log_q(al / x) - log_q(1.0)),
        al * 0.9,
        al,
        points=[al * (1 - 1e-2), al * (1 - 1e-3), al * (1 - 1e-4)],
        epsabs=0.0,
        epsrel=1e-12,
        limit=200,
    )[0]
    assert got.log10_p_hmi == pytest.approx((log_q(1.0) + math.log(scaled)) / LN10, rel=1e-10)
    assert math.isfinite(got.log10_p_mi_pl_below_al) and math.isfinite(got.log10_p_mi_pl_above_al)


def test_pe_pl_density():
    ratio, w = _normal(0.05, 0.3), _weibull(1.8, 20.0)
    x = np.array([[0.0], [-1.0], [5.0], [20.0], [45.0]])
    y = np.array([0.0, 1.0, 6.0, 30.0])
    d = pe_pl_density(ratio, w, x, y)
    assert d.shape == (5, 4)
    assert np.all(d[:2] == 0.0)
    want = stats.weibull_min.pdf(x[2:], 1.8, scale=20.0) * stats.foldnorm.pdf(y / x[2:], 1 / 6, scale=0.3)
    np.testing.assert_allclose(d[2:], want / x[2:], rtol=1e-12)
    hmi = integrate.dblquad(
        lambda v, u: float(pe_pl_density(ratio, w, u, v)), 0.0, 20.0, 20.0, np.inf, epsabs=0.0, epsrel=1e-9
    )[0]
    assert hmi == pytest.approx(integrity_probabilities(ratio, w, 20.0).p_hmi, rel=1e-6)


def test_integrity_probabilities_output_and_errors():
    got = integrity_probabilities(_rayleigh(0.065), _weibull(2.0, 20.0), 40.0)
    assert isinstance(got, IntegrityProbabilities)
    assert all(isinstance(v, float) for v in (got.p_hmi, got.log10_p_hmi, got.unavailability))
    assert got == integrity_probabilities(_rayleigh(0.065), _weibull(2.0, 20.0), 40.0)
    for al in (0.0, -5.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="alert_limit"):
            integrity_probabilities(_rayleigh(0.065), _weibull(2.0, 20.0), al)


@pytest.mark.parametrize("ratio", [_normal(0.0, 0.059), _rayleigh(0.065), _rayleigh(0.15)])
@pytest.mark.parametrize(("b", "scale"), [(3.0, 15.0), (2.0, 10.0)])
def test_hmi_far_beyond_the_pl(ratio, b, scale):
    """NPA-like: HAL 556 m over PLs of 10-20 m; the P_HMI integrand is a narrow interior peak (log10 P_HMI
    of -170 to -1300). Reference: scipy quad in ln x of the integrand divided by its maximum (log densities
    from scipy.stats), with the peak as a break point."""
    al = 556.0
    w = _weibull(b, scale)
    m, sd = ratio.mean, ratio.sigma
    if ratio.distribution == "normal":

        def log_q(t):
            return np.logaddexp(stats.norm.logsf(t, m, sd), stats.norm.logcdf(-t, m, sd))
    else:

        def log_q(t):
            return stats.rayleigh.logsf(t, scale=sd)

    def log_f(u):  # ln of p_PL(x) Q(AL/x) dx/du at x = e^u
        return stats.weibull_min.logpdf(np.exp(u), b, scale=scale) + u + log_q(al / np.exp(u))

    grid = np.linspace(math.log(al) - 8.0, math.log(al), 20001)
    vals = log_f(grid)
    peak, top = grid[np.argmax(vals)], float(vals.max())
    scaled = integrate.quad(
        lambda u: math.exp(float(log_f(u)) - top),
        grid[0],
        grid[-1],
        points=[peak],
        epsabs=0.0,
        epsrel=1e-12,
        limit=500,
    )[0]
    got = integrity_probabilities(ratio, w, al)
    assert got.log10_p_hmi * LN10 == pytest.approx(top + math.log(scaled), rel=1e-11)
    assert got.log10_p_hmi < -100


# ---------------------------------------------------------------------------------------------
# Weibull bound by seeded simulation with known truth
# ---------------------------------------------------------------------------------------------

REPS, N_PL, TAU_PL, CONF = 200, 20000, 100.0, 0.95
B_PL, SCALE_PL = 2.2, 15.0
#: True unavailabilities S(AL) at which the bound is checked (the paper's 2.5 % among them).
S_TRUE = (0.2, 0.025, 1e-3)


def _al(s_true: float) -> float:
    return SCALE_PL * (-math.log(s_true)) ** (1 / B_PL)


@pytest.fixture(scope="module")
def copula_pl() -> np.ndarray:
    """200 PL series of N = 20000 at 1 s, Weibull(b 2.2, scale 15 m) marginal through a Gaussian copula with
    AR(1) correlation of 1/e time 100 s: u = Phi(z_t), x = (-ln(1 - u)/a)^(1/b)."""
    z = _ar1(np.random.default_rng(19), REPS, N_PL, math.exp(-1.0 / TAU_PL))
    return (-special.log_ndtr(-z) * SCALE_PL**B_PL) ** (1 / B_PL)


def _weibull_shares(series: np.ndarray, n_effective: float) -> dict[float, float]:
    """Share of series whose unavailability bound at confidence 0.95 is >= the true S(AL)."""
    hits = np.zeros(len(S_TRUE))
    for x in series:
        f = fit_weibull(x)
        cov = weibull_covariance(f, x, n_effective)
        bounds = [weibull_bound(f, cov, _al(s), CONF) for s in S_TRUE]
        hits += [
            float(weibull_logsf(wb, _al(s))) >= math.log(s) for wb, s in zip(bounds, S_TRUE, strict=True)
        ]
    return dict(zip(S_TRUE, hits / len(series), strict=True))


def test_weibull_bound_coverage_independent():
    """Independent Weibull samples (n_eff = N = 20000, 200 repetitions): the delta-method bound holds the
    nominal 0.95 within 3 binomial sd (>= 0.904). Measured with this seed: 0.975, 0.95, 0.925 at S(AL) =
    0.2, 0.025, 1e-3 (with 1000 repetitions 0.943, 0.944, 0.941)."""
    x = stats.weibull_min.rvs(B_PL, scale=SCALE_PL, size=(REPS, N_PL), random_state=np.random.default_rng(23))
    for s, share in _weibull_shares(x, float(N_PL)).items():
        assert share >= CONF - _tolerance(CONF, REPS), (s, share)


def test_weibull_bound_coverage_copula_mean_effective_size(copula_pl):
    """Gaussian-copula AR(1) PL with the effective size of a mean, n_eff/2 = N dt/(2 tau) = 100 (the integral
    scale of an exponential autocorrelation is 2 tau): share >= 0.904. Measured with this seed: 0.955,
    0.975, 0.98 (with 1000 repetitions 0.953, 0.981, 0.988)."""
    for s, share in _weibull_shares(copula_pl, effective_sample_size(N_PL, 1.0, TAU_PL) / 2).items():
        assert share >= CONF - _tolerance(CONF, REPS), (s, share)


@pytest.mark.xfail(strict=True, reason="n_eff = N dt/tau is anti-conservative for the Weibull bound")
def test_weibull_bound_coverage_copula_spec_rule(copula_pl):
    """The spec's rule, n_eff = N dt/tau = 200 for the PL covariance, on the Gaussian-copula AR(1) PL: the
    share should be >= 0.904 at every S(AL) but is 0.88 at S = 0.2. Measured with this seed: 0.88, 0.91,
    0.92 at S(AL) = 0.2, 0.025, 1e-3 (with 1000 repetitions 0.872, 0.905, 0.93, and 0.941 at 1e-6; with
    tau estimated from the ACF of each PL series, 1/e rule: 0.859, 0.894, 0.916). The ML estimates are
    means of the score, whose autocorrelation is close to the latent one near the bulk (integral scale
    2 tau: empirical sd of ln S(AL) 1.30 times the delta-method sd at S = 0.2, 1.08 at 0.025, 0.99 at
    1e-3)."""
    for s, share in _weibull_shares(copula_pl, effective_sample_size(N_PL, 1.0, TAU_PL)).items():
        assert share >= CONF - _tolerance(CONF, REPS), (s, share)
