"""Sigma inflation (Comby et al. 2003, eqs. (10)-(16), appendix 1): exactness, minimality, invariances."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import special

from overbound.stats.overbounding import SigmaInflation, sigma_inflation

C_CORE = -special.ndtri(0.4)  # core 0.2


def _samples() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(20031)
    gauss = rng.standard_normal(300)
    right = gauss.copy()
    right[0] = 10.0
    left = rng.standard_normal(200)
    left[:3] = [-6.0, -5.5, -7.0]
    return {
        "right-outlier": right,
        "left-outliers": left,
        "student-t3": rng.standard_t(3, 500),
        "ties": np.round(rng.standard_normal(400) * 1.5, 1),
        "two-points": np.array([-1.0] * 5 + [1.0] * 5),
        "skewed": rng.exponential(2.0, 250) - 1.0,
        "tiny": np.array([0.1, -0.3, 2.5]),
    }


SAMPLES = _samples()


def _violations(x: np.ndarray, mean: float, sigma: float, core: float = 0.2) -> dict[str, np.ndarray]:
    """Where the overbounding inequalities fail, on a fine grid plus every order statistic and its neighbours.

    Left: Phi((L-m)/S) >= F_n(L) = P_n(X <= L) for L < m - cS. Right: Phibar((L-m)/S) >= P_n(X >= L)
    for L > m + cS, and also the paper's 1 - cdf form P_n(X > L). Relative tolerance 1e-13.
    """
    c = -special.ndtri(0.5 - core / 2)
    xs = np.sort(x)
    n = xs.size
    eps = 1e-13 * (np.abs(xs).max() + 1.0)
    grid = np.concatenate([np.linspace(xs[0] - 1.0, xs[-1] + 1.0, 40001), xs, xs - eps, xs + eps])
    cdf = np.searchsorted(xs, grid, side="right") / n
    sf_ge = (n - np.searchsorted(xs, grid, side="left")) / n
    sf_gt = (n - np.searchsorted(xs, grid, side="right")) / n
    left = grid < mean - c * sigma
    right = grid > mean + c * sigma
    g_cdf = special.ndtr((grid - mean) / sigma)
    g_sf = special.ndtr((mean - grid) / sigma)
    tol = 1.0 - 1e-13
    return {
        "left": grid[left & (g_cdf < cdf * tol)],
        "right": grid[right & (g_sf < sf_ge * tol)],
        "right_gt": grid[right & (g_sf < sf_gt * tol)],
    }


@pytest.mark.parametrize("name", list(SAMPLES))
def test_inflated_sigma_bounds_both_tails(name):
    res = sigma_inflation(SAMPLES[name])
    v = _violations(SAMPLES[name], res.mean, res.sigma_inflated)
    assert all(a.size == 0 for a in v.values()), v


@pytest.mark.parametrize("name", [k for k in SAMPLES if k != "tiny"])
def test_inflated_sigma_is_minimal(name):
    """Sigma*(1 - 1e-9) violates the bound, in both right-tail forms (P(X >= L) and P(X > L))."""
    res = sigma_inflation(SAMPLES[name])
    assert res.binding in ("left", "right")
    v = _violations(SAMPLES[name], res.mean, res.sigma_inflated * (1.0 - 1e-9))
    if res.binding == "left":
        assert v["left"].size > 0
        assert np.any(np.isclose(v["left"], res.binding_error, rtol=0, atol=1e-9))
    else:
        assert v["right"].size > 0 and v["right_gt"].size > 0
        assert np.any(np.isclose(v["right"], res.binding_error, rtol=0, atol=1e-9))


def test_sample_sigma_when_tails_are_light():
    """Uniform data with a 90 % core: the sample sigma already bounds the remaining tails ('sample').

    With the default 20 % core the floor Sigma >= sigma practically never binds for data: the
    extreme order statistics and the shoulders next to the core always ask for more (none of 10^5
    random samples of sizes 3-40 in development did). The 90 % core leaves only the outer 5 % per side.
    """
    x = np.linspace(-1.0, 1.0, 101)
    res = sigma_inflation(x, core=0.9)
    assert res.binding == "sample" and res.binding_error is None
    assert res.sigma_inflated == res.sigma == pytest.approx(np.std(x, ddof=1), rel=1e-15)
    assert res.inflation == 1.0
    assert all(a.size == 0 for a in _violations(x, res.mean, res.sigma_inflated, core=0.9).values())
    assert sigma_inflation(x).binding == "left"  # default core: the shoulders need inflation


def test_closed_form_single_outlier():
    """One outlier at the top: share >= it is 1/n, Sigma = (x - m) / -Phi^-1(1/n)."""
    x = np.array([-1.2, -0.4, 0.0, 0.3, 0.5, 0.8, 1.1, 6.0])
    res = sigma_inflation(x)
    m = x.mean()
    assert res.binding == "right" and res.binding_error == 6.0
    assert res.sigma_inflated == pytest.approx((6.0 - m) / -special.ndtri(1 / 8), rel=1e-14)


def test_point_beyond_the_core_share_must_leave_the_region():
    """Two clusters at -1 and +1: the points have 50 % on their side (> 40 %), so they cannot be
    bounded inside a tail region and must lie in the core: Sigma = 1/c (c = 0.2533), attained
    because the tail regions are open; an exact tie between the tails is reported as 'left'."""
    res = sigma_inflation(SAMPLES["two-points"])
    assert res.sigma_inflated == pytest.approx(1.0 / C_CORE, rel=1e-15)
    assert res.binding == "left" and res.binding_error == -1.0
    lo, hi = res.core_limits
    assert lo == pytest.approx(-1.0, abs=1e-15) and hi == pytest.approx(1.0, abs=1e-15)


def test_ties_counted_with_all_equal_values():
    """Ties: F at a repeated value counts all copies (side='right'); the share >= it too."""
    x = np.array([-3.0, -3.0, -3.0, 0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8])
    res = sigma_inflation(x)
    m = x.mean()
    assert res.binding == "left" and res.binding_error == -3.0
    assert res.sigma_inflated == pytest.approx((m + 3.0) / -special.ndtri(3 / 12), rel=1e-14)


@pytest.mark.parametrize("name", list(SAMPLES))
def test_location_scale_equivariance_and_mirror_symmetry(name):
    x = SAMPLES[name]
    base = sigma_inflation(x)
    shifted = sigma_inflation(3.7 + 2.5 * x)
    assert shifted.mean == pytest.approx(3.7 + 2.5 * base.mean, rel=1e-12, abs=1e-12)
    assert shifted.sigma_inflated == pytest.approx(2.5 * base.sigma_inflated, rel=1e-12)
    assert shifted.binding == base.binding
    mirrored = sigma_inflation(-x)
    assert mirrored.sigma_inflated == pytest.approx(base.sigma_inflated, rel=1e-14)
    assert mirrored.mean == pytest.approx(-base.mean, abs=1e-15)
    if base.binding != "sample" and name != "two-points":  # two-points is an exact tie
        assert mirrored.binding == {"left": "right", "right": "left"}[base.binding]
        assert mirrored.binding_error == -base.binding_error


def test_cdf_and_sf_of_the_overbound():
    res = SigmaInflation(
        n=10, mean=1.0, sigma=1.0, sigma_inflated=2.0, core=0.2, binding="right", binding_error=9
    )
    assert res.inflation == 2.0
    assert res.cdf(1.0) == 0.5 and res.sf(1.0) == 0.5
    # far tail stays accurate (no 1 - cdf cancellation)
    assert res.sf(1.0 + 2.0 * 12.0) == pytest.approx(special.ndtr(-12.0), rel=1e-14)
    assert res.sf(1.0 + 2.0 * 12.0) > 0


@pytest.mark.parametrize(
    ("errors", "core", "match"),
    [
        (np.array([1.0]), 0.2, "at least 2"),
        (np.array([1.0, np.nan, 2.0]), 0.2, "NaN"),
        (np.array([2.0, 2.0, 2.0]), 0.2, "all errors are equal"),
        (np.array([1.0, 2.0, 3.0]), 1.0, "core"),
        (np.ones((2, 2)), 0.2, "one-dimensional"),
    ],
)
def test_invalid_input(errors, core, match):
    with pytest.raises(ValueError, match=match):
        sigma_inflation(errors, core=core)


def test_core_share_changes_the_limits():
    """A larger core leaves more of the sample out: the inflation cannot grow."""
    x = SAMPLES["student-t3"]
    values = [sigma_inflation(x, core=core).sigma_inflated for core in (0.05, 0.2, 0.5, 0.9)]
    assert np.all(np.diff(values) <= 1e-15)


def _appendix1_curve(outlier: float, sizes: list[int], reps: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out = []
    for n in sizes:
        values = []
        for _ in range(reps):
            x = rng.standard_normal(n)
            x[0] = outlier
            values.append(sigma_inflation(x).sigma_inflated)
        out.append(np.mean(values))
    return np.array(out)


SIZES = [30, 50, 100, 200, 300, 500, 1000]


def test_appendix1_sigma_inflation_against_sample_count_10m_outlier():
    """Comby et al. 2003, appendix 1, figure 12: unit Gaussian VPE with one 10 m sample, n = 30 ... 1000.

    Mean inflated sigma over 100 seeded repetitions (seed 2003):

    ====  =====  =====  =====  =====  =====  =====  =====
    n       30     50    100    200    300    500   1000
    Sigma  5.28   4.77   4.26   3.87   3.67   3.47   3.23
    ====  =====  =====  =====  =====  =====  =====  =====

    Ratios: 30 -> 200 divides by 1.365 (paper: "a 1.3 factor"), 200 -> 1000 by 1.196 (paper: 1.2).
    The outlier sets Sigma = (10 - m) / -Phi^-1(1/n); with the plotting position (i - 1/2)/n instead
    of i/n the ratios would be 1.28 and 1.17, so the paper's own convention is not pinned down
    by these figures: tolerance 1.3 +- 0.1 and 1.2 +- 0.06.
    """
    curve = _appendix1_curve(10.0, SIZES, reps=100, seed=2003)
    assert np.all(np.diff(curve) < 0)
    r1, r2 = curve[0] / curve[3], curve[3] / curve[-1]
    assert abs(r1 - 1.3) < 0.1
    assert abs(r2 - 1.2) < 0.06
    np.testing.assert_allclose(curve, [5.276, 4.771, 4.256, 3.865, 3.674, 3.470, 3.232], atol=0.05)


def test_appendix1_sigma_inflation_against_sample_count_4m_outlier():
    """Appendix 1, figure 13: the same with a single 4 m error; "the same conclusion could be drawn".

    Mean inflated sigma over 100 repetitions (seed 2004): 2.19, 1.94, 1.71, 1.55, 1.47, 1.39, 1.30
    for n = 30 ... 1000; ratios 1.42 (30 -> 200) and 1.19 (200 -> 1000). The first ratio is larger
    than with 10 m because at n = 30 the 4 m point still dominates while at n = 200 the Gaussian
    sample's own tail fluctuations start to compete: tolerance [1.2, 1.5] and 1.2 +- 0.06.
    """
    curve = _appendix1_curve(4.0, SIZES, reps=100, seed=2004)
    assert np.all(np.diff(curve) < 0)
    r1, r2 = curve[0] / curve[3], curve[3] / curve[-1]
    assert 1.2 < r1 < 1.5
    assert abs(r2 - 1.2) < 0.06


def test_gaussian_data_inflation_is_modest():
    """Gaussian data without outliers, n = 1000, 100 repetitions: mean Sigma/sigma = 1.17, max 1.37.

    Exact cdf overbounding has no allowance for sampling noise: the largest of n Gaussian samples
    exceeds the 1 - 1/n quantile with probability 1 - (1 - 1/n)^n = 63 %, and then the top order
    statistic alone requires inflation. Hence the mean is about 1.17, not 1 (the paper's figure 4 shows
    1.13 -> 1.22, a factor 1.08, and figure 10 0.88 -> 1.27 called "a small sigma inflation").
    """
    rng = np.random.default_rng(7)
    ratios = np.array([sigma_inflation(rng.standard_normal(1000)).inflation for _ in range(100)])
    assert np.all(ratios >= 1.0)
    assert 1.0 < ratios.mean() < 1.25
    assert np.median(ratios) < 1.25
