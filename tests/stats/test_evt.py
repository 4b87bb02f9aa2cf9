"""GPD and GEV maximum-likelihood fits (Veerman et al., sections 2 and 3.5): limits, inverses, endpoints,
agreement with R's evd (fixtures in tests/data/evt/, made by tests/reference/make_evd_fixtures.R) and scipy,
recovery and profile-interval coverage by seeded simulation."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate, optimize, stats

from overbound.stats.evt import (
    _gpd_mle_rows,
    fit_gev,
    fit_gpd,
    gev_cdf,
    gev_logpdf,
    gev_sf,
    gpd_isf,
    gpd_logpdf,
    gpd_sf,
)

DATA = Path(__file__).resolve().parents[1] / "data" / "evt"
SHAPES = [-0.9, -0.6, -0.3, -1e-14, 0.0, 1e-14, 0.3, 0.7, 2.0]


def _evd_rows() -> list[dict[str, str]]:
    with open(DATA / "evd_fits.csv", newline="") as fh:
        return list(csv.DictReader(fh))


EVD = _evd_rows()


def _tight_fmin(func, x0, args=(), disp=0):
    """Nelder-Mead with tight tolerances, so that scipy's own fit reaches the maximum."""
    return optimize.fmin(func, x0, args=args, xtol=1e-10, ftol=1e-13, maxiter=4000, maxfun=8000, disp=0)


def _case(name: str) -> np.ndarray:
    return np.loadtxt(DATA / f"{name}.csv", skiprows=1)


# ---------------------------------------------------------------------------------------------- GPD: math


@pytest.mark.parametrize("xi", [0.0, 1e-14, -1e-14, 1e-300])
def test_gpd_shape_zero_is_exponential(xi: float) -> None:
    y = np.array([0.0, 1e-10, 0.5, 1.0, 10.0, 700.0])
    z = y / 2.0
    exact = np.exp(-(z - xi * z**2 / 2 + xi**2 * z**3 / 3))  # series of log1p(xi z)/xi, exact here
    np.testing.assert_allclose(gpd_sf(y, xi=xi, sigma=2.0), exact, rtol=1e-12, atol=0)
    np.testing.assert_allclose(gpd_sf(y[:5], xi=xi, sigma=2.0), np.exp(-z[:5]), rtol=1e-12)
    np.testing.assert_allclose(gpd_logpdf(y[:5], xi=xi, sigma=2.0), -math.log(2.0) - z[:5], rtol=1e-12)
    p = np.logspace(-12, math.log10(0.5), 9)
    np.testing.assert_allclose(gpd_isf(p, xi=xi, sigma=2.0), -2.0 * np.log(p), rtol=1e-12)


@pytest.mark.parametrize("xi", [-0.6, -0.3, 0.3, 0.7, 2.0])
def test_gpd_functions_match_scipy(xi: float) -> None:
    y = np.linspace(0.0, 5.0, 41)
    np.testing.assert_allclose(gpd_sf(y, xi=xi, sigma=1.3), stats.genpareto.sf(y, xi, scale=1.3), rtol=1e-12)
    inside = stats.genpareto.pdf(y, xi, scale=1.3) > 0
    np.testing.assert_allclose(
        gpd_logpdf(y, xi=xi, sigma=1.3)[inside], stats.genpareto.logpdf(y[inside], xi, scale=1.3), rtol=1e-12
    )


@pytest.mark.parametrize("xi", [-0.6, -0.3, 0.0, 0.4])
def test_gpd_density_integrates_to_sf(xi: float) -> None:
    # independent check: the survival function equals the integral of the density beyond y
    for y0 in (0.0, 0.7, 1.5):
        upper = -1.0 / xi if xi < 0 else np.inf
        if y0 >= upper:
            continue
        val, _ = integrate.quad(lambda t: math.exp(gpd_logpdf(t, xi=xi, sigma=1.0)), y0, upper, epsabs=1e-13)
        assert val == pytest.approx(float(gpd_sf(y0, xi=xi, sigma=1.0)), rel=1e-9)


@pytest.mark.parametrize("xi", SHAPES)
def test_gpd_sf_isf_roundtrip(xi: float) -> None:
    # |d log p / d log y| = z/(1 + xi z) (z = y/sigma) bounds the attainable accuracy: near a finite
    # endpoint (xi < 0, tiny p) y itself carries the rounding error of a double.
    p = np.logspace(-12, math.log10(0.5), 25)
    y = gpd_isf(p, xi=xi, sigma=0.8)
    z = y / 0.8
    cond = 1.0 + z * p**xi  # 1 + xi z == p**(-xi)
    np.testing.assert_array_less(np.abs(gpd_sf(y, xi=xi, sigma=0.8) / p - 1.0), 1e-14 * 8 * cond)


def test_gpd_continuity_in_shape_across_zero() -> None:
    y = np.array([0.1, 1.0, 5.0, 30.0])
    s0 = gpd_sf(y, xi=0.0, sigma=1.0)
    for xi in (1e-14, -1e-14, 1e-9, -1e-9):
        np.testing.assert_allclose(gpd_sf(y, xi=xi, sigma=1.0), s0, rtol=40 * abs(xi) * 900 + 1e-13)
    # monotone in the shape: heavier tail, larger survival
    shapes = [-0.5, -1e-9, 0.0, 1e-9, 0.5]
    sfs = [float(gpd_sf(3.0, xi=s, sigma=1.0)) for s in shapes]
    assert sfs == sorted(sfs)


def test_gpd_endpoint() -> None:
    xi, sigma = -0.4, 2.0
    end = -sigma / xi
    assert float(gpd_sf(end, xi=xi, sigma=sigma)) == 0.0
    assert float(gpd_sf(end + 1.0, xi=xi, sigma=sigma)) == 0.0
    assert 0.0 < float(gpd_sf(end * (1 - 1e-9), xi=xi, sigma=sigma)) < 1e-12
    assert gpd_logpdf(end + 0.1, xi=xi, sigma=sigma) == -np.inf
    assert float(gpd_isf(1e-300, xi=xi, sigma=sigma)) == pytest.approx(end, rel=1e-12)
    assert float(gpd_sf(-1.0, xi=xi, sigma=sigma)) == 1.0


# ---------------------------------------------------------------------------------------------- GPD: fits


def test_fit_gpd_result_methods() -> None:
    rng = np.random.default_rng(11)
    x = 2.0 + stats.genpareto.rvs(-0.3, scale=1.0, size=800, random_state=rng)
    fit = fit_gpd(x, threshold=2.0)
    assert fit.success and fit.regular and fit.n == 800
    assert fit.endpoint == pytest.approx(2.0 - fit.sigma / fit.xi)
    assert fit.endpoint >= x.max()
    assert float(fit.sf(1.0)) == 1.0 and float(fit.sf(fit.endpoint + 1)) == 0.0
    p = np.array([1e-12, 1e-6, 0.1, 0.5])
    np.testing.assert_allclose(fit.sf(fit.isf(p)), p, rtol=1e-10)
    assert fit.loglik == pytest.approx(
        float(np.sum(gpd_logpdf(x - 2.0, xi=fit.xi, sigma=fit.sigma))), rel=1e-12
    )
    # it is a maximum: every perturbation lowers the log-likelihood
    for dxi, ds in [(1e-4, 0), (-1e-4, 0), (0, 1e-4), (0, -1e-4), (1e-4, 1e-4)]:
        ll = float(np.sum(gpd_logpdf(x - 2.0, xi=fit.xi + dxi, sigma=fit.sigma * (1 + ds))))
        assert ll < fit.loglik
    heavy = fit_gpd(stats.genpareto.rvs(0.5, size=300, random_state=rng))
    assert heavy.endpoint == math.inf


def test_fit_gpd_rows_equal_single_fits() -> None:
    rng = np.random.default_rng(12)
    rows = np.stack(
        [stats.genpareto.rvs(xi, size=400, random_state=rng) for xi in (-0.6, -0.2, 0.0, 0.4, 1.0)]
    )
    xi, sig, ll, status = _gpd_mle_rows(rows)
    for i in range(rows.shape[0]):
        single = fit_gpd(rows[i])
        assert status[i] == 0
        assert xi[i] == pytest.approx(single.xi, rel=1e-9, abs=1e-12)
        assert sig[i] == pytest.approx(single.sigma, rel=1e-9)
        assert ll[i] == pytest.approx(single.loglik, rel=1e-12)


def test_fit_gpd_unbounded_likelihood_below_minus_one() -> None:
    # density increasing to the maximum (shape < -1): no interior maximum, reported not raised
    y = np.random.default_rng(13).uniform(size=200) ** 0.3
    fit = fit_gpd(y)
    assert not fit.success and "unbounded" in fit.message
    assert fit.xi == -1.0 and fit.sigma == pytest.approx(y.max()) and not fit.regular


def test_fit_gpd_nonregular_flag() -> None:
    y = stats.genpareto.rvs(-0.8, size=3000, random_state=np.random.default_rng(14))
    fit = fit_gpd(y)
    assert fit.success and not fit.regular and fit.xi < -0.5 and "non-regular" in fit.message
    assert fit.endpoint >= y.max()


def test_fit_gpd_validation() -> None:
    with pytest.raises(ValueError, match="at least 3"):
        fit_gpd(np.array([1.0, 2.0]))
    with pytest.raises(ValueError, match=">= threshold"):
        fit_gpd(np.array([1.0, 2.0, 3.0]), threshold=1.5)
    with pytest.raises(ValueError, match="NaN"):
        fit_gpd(np.array([1.0, np.nan, 3.0]))


@pytest.mark.parametrize("xi", [-0.4, 0.0, 0.4])
def test_fit_gpd_recovers_truth(xi: float) -> None:
    # n = 5000: sd(xi_hat) ~ (1 + xi)/sqrt(n) <= 0.02; tolerance 4 sd
    y = stats.genpareto.rvs(xi, scale=2.0, size=5000, random_state=np.random.default_rng(15))
    fit = fit_gpd(y)
    assert abs(fit.xi - xi) < 0.08
    assert fit.sigma == pytest.approx(2.0, rel=0.1)


@pytest.mark.parametrize("row", [r for r in EVD if r["model"] == "gpd"], ids=lambda r: r["case"])
def test_fit_gpd_matches_evd(row: dict[str, str]) -> None:
    u = float(row["threshold"])
    x = _case(row["case"])
    fit = fit_gpd(x[x > u], threshold=u)
    assert fit.success and fit.n == int(row["n"])
    assert fit.xi == pytest.approx(float(row["shape"]), rel=1e-4)
    assert fit.sigma == pytest.approx(float(row["scale"]), rel=1e-4)
    assert fit.loglik >= float(row["loglik"]) - 1e-9


@pytest.mark.parametrize("row", [r for r in EVD if r["model"] == "gpd"], ids=lambda r: r["case"])
def test_fit_gpd_matches_scipy(row: dict[str, str]) -> None:
    u = float(row["threshold"])
    x = _case(row["case"])
    x = x[x > u]
    fit = fit_gpd(x, threshold=u)
    c, _, scale = stats.genpareto.fit(x, floc=u, optimizer=_tight_fmin)  # genpareto c == xi
    ll_scipy = float(np.sum(stats.genpareto.logpdf(x, c, loc=u, scale=scale)))
    assert fit.loglik >= ll_scipy - 1e-9
    if ll_scipy > fit.loglik - 1e-8:  # scipy converged
        assert fit.xi == pytest.approx(c, rel=1e-4)
        assert fit.sigma == pytest.approx(scale, rel=1e-4)


def test_profile_ci_contains_estimate_and_hits_the_cut() -> None:
    y = stats.genpareto.rvs(0.2, size=500, random_state=np.random.default_rng(16))
    fit = fit_gpd(y)
    lo, hi = fit.profile_ci(0.95)
    assert lo < fit.xi < hi
    cut = fit.loglik - 0.5 * stats.chi2.isf(0.05, 1)
    assert fit.profile_loglik(lo) == pytest.approx(cut, abs=1e-6)
    assert fit.profile_loglik(hi) == pytest.approx(cut, abs=1e-6)
    assert fit.profile_loglik(fit.xi) == pytest.approx(fit.loglik, abs=1e-8)
    lo90, hi90 = fit.profile_ci(0.90)
    assert lo < lo90 < hi90 < hi
    with pytest.raises(ValueError, match="param"):
        fit.profile_ci(param="sigma")


def test_profile_ci_coverage() -> None:
    # 200 seeded repetitions of n = 500 from GPD(xi = 0.2): coverage of the 95 % interval
    rng = np.random.default_rng(17)
    covered = 0
    for _ in range(200):
        fit = fit_gpd(stats.genpareto.rvs(0.2, size=500, random_state=rng))
        lo, hi = fit.profile_ci(0.95)
        covered += lo <= 0.2 <= hi
    assert 0.90 <= covered / 200 <= 0.99


# ---------------------------------------------------------------------------------------------- GEV


@pytest.mark.parametrize("xi", [-0.4, -1e-14, 0.0, 1e-14, 0.3])
def test_gev_functions(xi: float) -> None:
    x = np.linspace(-2.0, 6.0, 33)
    cdf, sf = gev_cdf(x, xi=xi, loc=0.5, scale=1.2), gev_sf(x, xi=xi, loc=0.5, scale=1.2)
    np.testing.assert_allclose(cdf + sf, 1.0, rtol=1e-14)
    np.testing.assert_allclose(cdf, stats.genextreme.cdf(x, -xi, loc=0.5, scale=1.2), rtol=1e-10, atol=1e-300)
    inside = np.isfinite(gev_logpdf(x, xi=xi, loc=0.5, scale=1.2))
    np.testing.assert_allclose(
        gev_logpdf(x[inside], xi=xi, loc=0.5, scale=1.2),
        stats.genextreme.logpdf(x[inside], -xi, loc=0.5, scale=1.2),
        rtol=1e-10,
    )
    fit = fit_gev(stats.genextreme.rvs(-0.1, size=50, random_state=np.random.default_rng(1)))
    p = np.logspace(-12, math.log10(0.5), 12)
    np.testing.assert_allclose(fit.sf(fit.isf(p)), p, rtol=1e-9)


def test_gev_gumbel_limit() -> None:
    x = np.array([-1.0, 0.0, 2.0, 10.0])
    gumbel = np.exp(-np.exp(-x))
    for xi in (0.0, 1e-14, -1e-14):
        np.testing.assert_allclose(gev_cdf(x, xi=xi, loc=0.0, scale=1.0), gumbel, rtol=1e-12)
    # far upper tail: sf stays accurate (no 1 - cdf)
    assert float(gev_sf(40.0, xi=0.0, loc=0.0, scale=1.0)) == pytest.approx(math.exp(-40.0), rel=1e-12)


@pytest.mark.parametrize("row", [r for r in EVD if r["model"] == "gev"], ids=lambda r: r["case"])
def test_fit_gev_matches_evd_and_scipy(row: dict[str, str]) -> None:
    x = _case(row["case"])
    fit = fit_gev(x)
    assert fit.success and fit.n == int(row["n"])
    assert fit.xi == pytest.approx(float(row["shape"]), rel=1e-4)
    assert fit.scale == pytest.approx(float(row["scale"]), rel=1e-4)
    assert fit.loc == pytest.approx(float(row["loc"]), rel=1e-4)
    assert fit.loglik >= float(row["loglik"]) - 1e-9
    c, loc, scale = stats.genextreme.fit(x, optimizer=_tight_fmin)  # genextreme c == -xi
    ll_scipy = float(np.sum(stats.genextreme.logpdf(x, c, loc=loc, scale=scale)))
    assert fit.loglik >= ll_scipy - 1e-9
    if ll_scipy > fit.loglik - 1e-8:
        assert fit.xi == pytest.approx(-c, rel=1e-4)


def test_fit_gev_recovers_truth() -> None:
    x = stats.genextreme.rvs(-0.2, loc=3.0, scale=0.5, size=3000, random_state=np.random.default_rng(18))
    fit = fit_gev(x)
    assert abs(fit.xi - 0.2) < 0.06
    assert fit.loc == pytest.approx(3.0, abs=0.05)
    assert fit.scale == pytest.approx(0.5, rel=0.06)
