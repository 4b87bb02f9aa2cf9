"""Confidence level in a PL (Comby et al. 2003, appendix 2): exceedance, ideal PL, CL, PL1/PL99.

Mathematical facts first (limits, monotonicity, symmetry, scale invariance), then the one-dimensional
CL against the two-dimensional integration of eq. (34) and against a plain tensor-grid integration
written here, then PL_q against a seeded simulation of the (mu, sigma) model.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, special, stats

from overbound.stats import confidence as cf
from overbound.stats.confidence import (
    AXES,
    confidence_level,
    confidence_level_bruteforce,
    exceedance,
    ideal_pl,
    pl_at_confidence,
)

RISK = 1e-7


# ---------------------------------------------------------------------------------------------
# exceedance and ideal PL
# ---------------------------------------------------------------------------------------------


def test_exceedance_vertical_closed_forms_and_symmetry():
    assert exceedance(0.0, mean=0.0, sigma=1.0) == 1.0
    assert float(exceedance(1.0, mean=0.0, sigma=1.0)) == pytest.approx(2 * special.ndtr(-1.0), rel=1e-15)
    # far tail keeps its relative accuracy (1 - erf would give 0)
    assert float(exceedance(35.0, mean=0.0, sigma=1.0)) == pytest.approx(2 * special.ndtr(-35.0), rel=1e-14)
    assert float(exceedance(35.0, mean=0.0, sigma=1.0)) > 1e-268
    pl = np.array([3.0, 5.0, 8.0])
    np.testing.assert_array_equal(exceedance(pl, mean=1.3, sigma=0.7), exceedance(pl, mean=-1.3, sigma=0.7))
    assert exceedance(pl[:, None], mean=np.array([0.0, 1.0]), sigma=1.0).shape == (3, 2)


@pytest.mark.parametrize(("mean", "pl"), [(0.0, 5.677), (1.0, 6.5), (3.0, 8.0), (0.5, 12.0), (10.0, 15.0)])
def test_exceedance_horizontal_against_rice_tail_integral(mean, pl):
    """P(HPE > L) = integral of the Rice density beyond L (scipy.stats.rice, quad)."""
    ref, _ = integrate.quad(
        lambda r: stats.rice.pdf(r, mean), pl, pl + 40.0, epsabs=0, epsrel=1e-13, limit=200
    )
    assert float(exceedance(pl, mean=mean, sigma=1.0, axis="horizontal")) == pytest.approx(ref, rel=1e-9)


def test_exceedance_horizontal_zero_mean_is_continuous():
    zero = float(exceedance(5.0, mean=0.0, sigma=1.3, axis="horizontal"))
    assert zero == pytest.approx(math.exp(-0.5 * (5.0 / 1.3) ** 2), rel=1e-15)
    assert float(exceedance(5.0, mean=1e-7, sigma=1.3, axis="horizontal")) == pytest.approx(zero, rel=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"pl": -1.0, "mean": 0, "sigma": 1}, "protection"), ({"pl": 1.0, "mean": 0, "sigma": 0}, "sigma")],
)
def test_exceedance_invalid(kwargs, match):
    pl = kwargs.pop("pl")
    with pytest.raises(ValueError, match=match):
        exceedance(pl, **kwargs)


def test_ideal_pl_is_the_sbas_k_factor():
    """K_V = Phi^-1(1 - 1e-7/2) = 5.3267 (DO-229, Comby eq. (3)); horizontal sqrt(-2 ln 1e-7) = 5.6777."""
    assert ideal_pl(mean=0.0, sigma=1.0) == pytest.approx(-special.ndtri(0.5e-7), rel=1e-15)
    assert round(ideal_pl(mean=0.0, sigma=1.0), 4) == 5.3267
    assert ideal_pl(mean=0.0, sigma=1.0, axis="horizontal") == pytest.approx(
        math.sqrt(-2 * math.log(1e-7)), rel=1e-15
    )
    assert round(ideal_pl(mean=0.0, sigma=1.0, axis="horizontal"), 3) == 5.678


@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize("mean", [0.0, 1e-6, 0.3, -2.0, 7.5])
@pytest.mark.parametrize("risk", [1e-3, 1e-7, 1e-9, 1e-15])
def test_ideal_pl_solves_eq9(axis, mean, risk):
    sigma = 1.7
    pl = ideal_pl(mean=mean, sigma=sigma, risk=risk, axis=axis)
    assert float(exceedance(pl, mean=mean, sigma=sigma, axis=axis)) == pytest.approx(risk, rel=1e-11)
    # scale equivariance
    assert ideal_pl(mean=3 * mean, sigma=3 * sigma, risk=risk, axis=axis) == pytest.approx(3 * pl, rel=1e-12)


@pytest.mark.parametrize("axis", AXES)
def test_ideal_pl_increases_with_mean_and_sigma(axis):
    by_mean = [ideal_pl(mean=m, sigma=1.0, axis=axis) for m in np.linspace(0, 5, 21)]
    by_sigma = [ideal_pl(mean=1.0, sigma=s, axis=axis) for s in np.linspace(0.2, 5, 21)]
    assert np.all(np.diff(by_mean) > 0) and np.all(np.diff(by_sigma) > 0)
    # large mean: one tail only, L = |m| + sigma z(risk)
    assert ideal_pl(mean=50.0, sigma=1.0) == pytest.approx(50.0 - special.ndtri(RISK), rel=1e-14)


# ---------------------------------------------------------------------------------------------
# the shape of the domain D (eqs. (45)-(46)) and the root s*(mu)
# ---------------------------------------------------------------------------------------------


def _g(pl, mu, s, axis):
    p = exceedance(np.asarray(pl)[:, None], mean=mu, sigma=np.asarray(s)[None, :], axis=axis)
    return 1.0 - np.prod(1.0 - p, axis=0)  # eq. (44); plain form, fine away from the far tail


@pytest.mark.parametrize("axis", AXES)
def test_g_increases_with_sigma_inside_and_exceeds_half_outside(axis):
    pl = np.array([6.0, 6.3, 7.1, 9.0])
    s = np.geomspace(0.05, 50.0, 2000)
    for mu in (0.0, 1.0, 3.0, 5.9):
        g = _g(pl, mu, s, axis)
        assert np.all(np.diff(g) >= 0) and np.any(np.diff(g) > 0)
    for mu in (6.0, 6.5, 8.0, 20.0):  # |mu| >= min PL: g >= 1/2 whatever sigma (eq. (46), sharpened)
        assert np.all(_g(pl, mu, s, axis) >= 0.5 - 1e-15)
    # eq. (45): g(0, sigma) <= g(mu, sigma)
    assert np.all(_g(pl, 0.0, s, axis) <= _g(pl, 1.5, s, axis) + 1e-300)


@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize("n", [5, 200, 1500])
def test_root_solver_is_exact_to_1e12(axis, n):
    """The returned w* = 1/s* brackets the root of sum log1p(-P_i) = n log1p(-risk) within 1e-12.

    (At |mu| = 0.9999 min PL, s* ~ 3e-5 min PL, the horizontal error is ~1e-12: the Rice
    exceedance itself is then ill-conditioned.)"""
    rng = np.random.default_rng(n)
    pl = np.sort(rng.uniform(14.8, 15.2, n)) if n > 5 else np.array([10.0, 12.0, 15.0, 15.5, 30.0])
    levels, counts = np.unique(pl, return_counts=True)
    counts = counts.astype(float)
    # up to 0.999 min PL; the quadrature never gets closer than its support edge (F_sigma < 1e-18)
    r = levels[0] * np.array([0.0, 0.03, 0.2, 0.6, 0.93, 0.986, 0.999])
    w = cf._solve_w(levels, counts, r, RISK, axis)
    target = n * math.log1p(-RISK)
    for factor, sign in ((1 - 1e-12, -1), (1 + 1e-12, 1)):
        p = cf._exceedance(levels[:, None], r, 1.0 / (w * factor), axis)
        h = counts @ np.log1p(-p)
        assert np.all(np.sign(h - target) == sign)


# ---------------------------------------------------------------------------------------------
# confidence level: against the two-dimensional integral of eq. (34)
# ---------------------------------------------------------------------------------------------


def _cases():
    rng = np.random.default_rng(34)
    out = []
    for n, base, sigma in ((5, 6.0, 1.0), (12, 7.0, 1.0), (30, 6.0, 1.0), (50, 6.0, 1.0), (50, 5.0, 1.0)):
        patterns = {
            "equal": np.full(n, base),
            "band": base + rng.uniform(-0.125, 0.125, n),
            "unequal": base * rng.uniform(0.9, 1.6, n),
        }
        for name, pl in patterns.items():
            for mean in (0.0, 0.8, -1.5):
                out.append(pytest.param(pl, mean, sigma, n, id=f"n{n}-L{base}-{name}-m{mean}"))
    # near 1 and near 0
    out.append(pytest.param(np.full(40, 9.0), 0.2, 1.0, 40, id="near-one"))
    out.append(pytest.param(np.full(40, 3.5), 0.2, 1.0, 40, id="near-zero"))
    return out


CASES = _cases()
# every pattern and mean at every n is covered once across the two axes; near 0 and 1 on both
VERTICAL_CASES = CASES[:-2:2] + CASES[-2:]
HORIZONTAL_CASES = [c for c in CASES[1:-2:2] if c.values[3] <= 30][::2] + CASES[-2:]


@pytest.mark.parametrize(("pl", "mean", "sigma", "n"), VERTICAL_CASES)
def test_vertical_cl_matches_2d_integral(pl, mean, sigma, n):
    one_d = confidence_level(pl, mean=mean, sigma=sigma, n=n)
    two_d = confidence_level_bruteforce(pl, mean=mean, sigma=sigma, n=n)
    assert one_d == pytest.approx(two_d, abs=1e-6)


@pytest.mark.parametrize(("pl", "mean", "sigma", "n"), HORIZONTAL_CASES)
def test_horizontal_cl_matches_2d_integral(pl, mean, sigma, n):
    one_d = confidence_level(pl, mean=abs(mean), sigma=sigma, n=n, axis="horizontal")
    two_d = confidence_level_bruteforce(pl, mean=abs(mean), sigma=sigma, n=n, axis="horizontal")
    assert one_d == pytest.approx(two_d, abs=1e-6)


def test_cases_cover_the_range_of_cl():
    values = [
        confidence_level(c.values[0], mean=c.values[1], sigma=c.values[2], n=c.values[3]) for c in CASES
    ]
    assert min(values) < 1e-3 and max(values) > 0.999
    assert any(0.2 < v < 0.8 for v in values)


@pytest.mark.parametrize("axis", AXES)
def test_cl_against_a_plain_tensor_grid(axis):
    """Independent of both implementations: midpoint rule on a 1000 x 1000 grid of the probability
    coordinates (u, v) of (mu, sigma), with the indicator g <= R_n; the indicator's boundary limits
    this rule to ~1e-5."""
    pl = np.array([5.5, 6.0, 6.2, 6.8, 7.5])
    n, mean, sigma_hat = 5, 0.4, 1.0
    tau = sigma_hat / math.sqrt(n - 2)
    m = 1000
    u = (np.arange(m) + 0.5) / m
    chi = stats.chi2.isf(u, n - 1)  # sigma increases with u
    sig = sigma_hat * np.sqrt((n - 1) / chi)
    if axis == "vertical":
        mu = mean + tau * special.ndtri(u)
        r = np.abs(mu)
    else:  # |mu| for mu ~ N((mean, 0), tau^2 I): Rice quantiles, by interpolating its cdf
        radius = np.linspace(0.0, mean + 12 * tau, 200_001)
        r = np.interp(u, stats.rice.cdf(radius, mean / tau, scale=tau), radius)
    r_n = -np.expm1(n * np.log1p(-RISK))
    h = np.zeros((m, m))
    for level in pl:
        h += np.log1p(-cf._exceedance(level, r[:, None], sig[None, :], axis))
    grid_cl = np.mean(-np.expm1(h) <= r_n)
    assert confidence_level(pl, mean=mean, sigma=sigma_hat, n=n, axis=axis) == pytest.approx(
        grid_cl, abs=2e-4
    )


# ---------------------------------------------------------------------------------------------
# confidence level: quadrature convergence, facts, speed-independent properties
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize(("pl", "mean", "sigma", "n"), CASES[::3])
def test_64_nodes_agree_with_128(axis, pl, mean, sigma, n):
    a = confidence_level(pl, mean=mean, sigma=sigma, n=n, axis=axis)
    b = confidence_level(pl, mean=mean, sigma=sigma, n=n, axis=axis, nodes=128)
    assert a == pytest.approx(b, abs=1e-10 if n >= 10 else 3e-9)


@pytest.mark.parametrize("axis", AXES)
def test_64_nodes_agree_with_128_large_n(axis):
    rng = np.random.default_rng(1500)
    for n, base in ((200, 5.4), (1500, 5.2), (1500, 5.6)):
        pl = base + rng.uniform(-0.1, 0.1, n)
        a = confidence_level(pl, mean=0.2, sigma=1.0, n=n, axis=axis)
        b = confidence_level(pl, mean=0.2, sigma=1.0, n=n, axis=axis, nodes=128)
        assert a == pytest.approx(b, abs=1e-12)


@pytest.mark.parametrize("axis", AXES)
def test_cl_monotone_in_pl_and_sigma(axis):
    rng = np.random.default_rng(5)
    pl = 6.0 + rng.uniform(-0.2, 0.2, 60)
    by_shift = [
        confidence_level(pl + d, mean=0.5, sigma=1.0, n=60, axis=axis) for d in np.linspace(-2, 3, 26)
    ]
    assert np.all(np.diff(by_shift) >= 0)
    assert by_shift[0] < 1e-3 and by_shift[-1] > 0.9999
    for mean in (0.0, 0.5, 1.5):
        by_sigma = [
            confidence_level(pl, mean=mean, sigma=s, n=60, axis=axis) for s in np.linspace(0.6, 2.0, 15)
        ]
        assert np.all(np.diff(by_sigma) <= 0)


def test_cl_symmetric_in_mean():
    rng = np.random.default_rng(6)
    pl = 6.0 + rng.uniform(-0.2, 0.2, 80)
    for mean in (0.3, 1.0, 2.5):
        a = confidence_level(pl, mean=mean, sigma=1.0, n=80)
        b = confidence_level(pl, mean=-mean, sigma=1.0, n=80)
        assert a == pytest.approx(b, abs=1e-15)


@pytest.mark.parametrize("axis", AXES)
def test_cl_scale_invariance_and_limits(axis):
    pl = np.linspace(5.8, 6.4, 40)
    base = confidence_level(pl, mean=0.4, sigma=1.0, n=40, axis=axis)
    assert confidence_level(2.5 * pl, mean=1.0, sigma=2.5, n=40, axis=axis) == pytest.approx(base, abs=1e-12)
    assert confidence_level(pl, mean=7.0, sigma=1.0, n=40, axis=axis) == 0.0  # mean beyond every PL
    assert confidence_level(100.0, mean=0.0, sigma=1.0, n=40, axis=axis) == pytest.approx(1.0, abs=1e-14)
    # scalar PL = n equal PLs
    assert confidence_level(6.0, mean=0.4, sigma=1.0, n=40, axis=axis) == confidence_level(
        np.full(40, 6.0), mean=0.4, sigma=1.0, n=40, axis=axis
    )


def test_cl_single_pl_bounds_for_unequal_pls():
    """PLs between a and b: CL(all a) <= CL <= CL(all b)."""
    pl = np.linspace(5.5, 7.0, 50)
    cl = confidence_level(pl, mean=0.2, sigma=1.0, n=50)
    assert (
        confidence_level(5.5, mean=0.2, sigma=1.0, n=50)
        < cl
        < confidence_level(7.0, mean=0.2, sigma=1.0, n=50)
    )


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"pl": np.ones(3), "n": 4}, "n = 4 values"),
        ({"pl": np.array([1.0, 0.0, 2.0]), "n": 3}, "> 0"),
        ({"pl": 5.0, "n": 2}, "n must be"),
        ({"pl": 5.0, "n": 10, "sigma": 0.0}, "sigma"),
        ({"pl": 5.0, "n": 10, "risk": 1.0}, "risk"),
        ({"pl": 5.0, "n": 10_000_000}, "R_n"),
        ({"pl": 5.0, "n": 10, "axis": "up"}, "axis"),
        ({"pl": 5.0, "n": 10, "nodes": 50}, "multiple of 16"),
    ],
)
def test_cl_invalid(kwargs, match):
    args = {"mean": 0.0, "sigma": 1.0} | kwargs
    pl = args.pop("pl")
    with pytest.raises(ValueError, match=match):
        confidence_level(pl, **args)


# ---------------------------------------------------------------------------------------------
# PL at a confidence level (PL1, PL99)
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize(
    ("mean", "sigma", "n"), [(0.0, 1.0, 30), (0.7, 2.0, 200), (-1.5, 0.8, 1500), (0.1, 1.0, 5)]
)
@pytest.mark.parametrize("level", [0.01, 0.5, 0.99])
def test_pl_at_confidence_inverts_cl(axis, mean, sigma, n, level):
    mean = abs(mean) if axis == "horizontal" else mean
    pl = pl_at_confidence(level, mean=mean, sigma=sigma, n=n, axis=axis)
    assert confidence_level(pl, mean=mean, sigma=sigma, n=n, axis=axis) == pytest.approx(level, abs=1e-9)


@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize("n", [30, 200, 1500])
def test_pl1_below_ideal_below_pl99(axis, n):
    for mean in (0.0, 0.5):
        pl1 = pl_at_confidence(0.01, mean=mean, sigma=1.0, n=n, axis=axis)
        pl99 = pl_at_confidence(0.99, mean=mean, sigma=1.0, n=n, axis=axis)
        assert pl1 < ideal_pl(mean=mean, sigma=1.0, axis=axis) < pl99
    # the interval narrows as n grows
    widths = [
        pl_at_confidence(0.99, mean=0.0, sigma=1.0, n=k, axis=axis)
        - pl_at_confidence(0.01, mean=0.0, sigma=1.0, n=k, axis=axis)
        for k in (30, 200, 1500)
    ]
    assert np.all(np.diff(widths) < 0)


def _simulated_ideal_pl(axis, mean, sigma_hat, n, draws, rng):
    """Draw (mu, sigma) from eqs. (24)-(25) and solve exceedance = risk for each draw by bisection."""
    tau = sigma_hat / math.sqrt(n - 2)
    sigma = sigma_hat * np.sqrt((n - 1) / rng.chisquare(n - 1, draws))
    if axis == "vertical":
        r = np.abs(mean + tau * rng.standard_normal(draws))
    else:
        r = np.hypot(mean + tau * rng.standard_normal(draws), tau * rng.standard_normal(draws))
    lo, hi = r + 4.0 * sigma, r + 7.0 * sigma  # exceedance(lo) > 1e-7 > exceedance(hi)
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        above = cf._exceedance(mid, r, sigma, axis) > RISK
        lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
    return 0.5 * (lo + hi)


@pytest.mark.parametrize(("axis", "draws"), [("vertical", 200_000), ("horizontal", 20_000)])
def test_pl1_pl99_by_simulation(axis, draws):
    """Share of simulated ideal PLs below PL_q equals q within 4.5 binomial standard deviations."""
    rng = np.random.default_rng(2003)
    mean, sigma_hat, n = 0.4, 1.3, 250
    ideal = _simulated_ideal_pl(axis, mean, sigma_hat, n, draws, rng)
    for q in (0.01, 0.99):
        pl = pl_at_confidence(q, mean=mean, sigma=sigma_hat, n=n, axis=axis)
        share = np.mean(ideal <= pl)
        assert abs(share - q) < 4.5 * math.sqrt(q * (1 - q) / draws)
        assert abs(np.quantile(ideal, q) / pl - 1) < 5e-3


# ---------------------------------------------------------------------------------------------
# horizontal model: the isotropic Gaussian is conservative in the far tail
# ---------------------------------------------------------------------------------------------


def _anisotropic_exceedance(pl, m_e, m_n, s_e, s_n):
    """P(|(E, N)| > L) for independent E ~ N(m_e, s_e), N ~ N(m_n, s_n), by quad over E."""

    def inside(e):
        half = math.sqrt(max(pl * pl - e * e, 0.0))
        out_n = special.ndtr((m_n - half) / s_n) + special.ndtr((-half - m_n) / s_n)
        return stats.norm.pdf(e, m_e, s_e) * out_n

    core, _ = integrate.quad(inside, -pl, pl, epsabs=0, epsrel=1e-12, limit=400)
    outside_e = special.ndtr((m_e - pl) / s_e) + special.ndtr((-pl - m_e) / s_e)
    return core + outside_e


@pytest.mark.parametrize(
    ("m_e", "m_n", "s_e", "s_n"),
    [
        (0.0, 0.0, 0.5, 1.0),
        (1.0, 0.0, 0.6, 1.0),
        (0.0, 1.0, 0.6, 1.0),
        (0.7, 0.7, 0.9, 1.0),
        (2.0, 1.0, 1.0, 0.3),
    ],
)
def test_isotropic_model_bounds_anisotropic_error_in_the_far_tail(m_e, m_n, s_e, s_n):
    sigma = max(s_e, s_n)
    for pl in (6.0, 7.0, 8.0):
        iso = float(exceedance(pl, mean=math.hypot(m_e, m_n), sigma=sigma, axis="horizontal"))
        assert _anisotropic_exceedance(pl, m_e, m_n, s_e, s_n) <= iso * (1 + 1e-9)


@pytest.mark.parametrize("axis", ["vertical", "horizontal"])
def test_halley_sums_by_blocks_of_pls_equal_one_sum(axis, monkeypatch):
    """The sums over PLs run by blocks (bounded memory for a campaign's 45 k PLs): any block size gives
    the confidence level of one block to rounding, and one block is the plain sum bit for bit."""
    rng = np.random.default_rng(11)
    pls = rng.uniform(5.3, 5.5, 3000) + (0.35 if axis == "horizontal" else 0.0)
    model = {"mean": 0.2, "sigma": 1.0, "n": pls.size, "axis": axis}
    whole = confidence_level(pls, **model)
    assert 0.01 < whole < 0.99  # a level the sums decide, not a saturated 0 or 1
    monkeypatch.setattr(cf, "_PL_BLOCK", 7)  # 429 blocks, the last partial
    assert confidence_level(pls, **model) == pytest.approx(whole, rel=1e-12, abs=1e-14)
    monkeypatch.setattr(cf, "_PL_BLOCK", 1 << 20)
    assert confidence_level(pls, **model) == whole
