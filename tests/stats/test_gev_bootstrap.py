"""GEV bootstrap on block maxima (Veerman et al., sections 3.7 and 4): the vectorised damped-Newton fits of
all resamples at once equal ``fit_gev`` on the same resample, the analytic derivatives and their Gumbel
limit, flags for degenerate and unbounded resamples, determinism."""

from __future__ import annotations

import warnings
from decimal import Decimal, localcontext

import numpy as np
import pytest
from scipy import stats

import overbound.stats.bootstrap as bootstrap_mod
from overbound.stats.bootstrap import bootstrap_gev
from overbound.stats.evt import (
    GEVFit,
    _chi,
    _gev_derivs_rows,
    _gev_loglik_rows,
    _gev_mle_rows,
    fit_gev,
    gev_logpdf,
    gev_sf,
)

SHAPES = [-0.4, -0.1, 0.0, 0.2, 0.5]


def _maxima(xi: float, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng([seed, n, int(1000 * (xi + 1))])
    return stats.genextreme.rvs(-xi, loc=0.3, scale=0.1, size=n, random_state=rng)  # scipy c == -xi


def _fit_gev_quiet(x: np.ndarray) -> GEVFit:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fit_gev(x)


def _chi_exact(w: float) -> float:
    with localcontext() as ctx:
        ctx.prec = 60
        d = Decimal(w)
        r = d / (1 + d)
        return float((2 * (1 + d).ln() - 2 * r - r * r) / d**3)


def test_chi_kernel() -> None:
    # d2t/dxi2 = z^3 chi(xi z): series below |w| = 1e-2, direct above, continuous across the switch
    w = np.array(
        [-0.5, -0.01 - 1e-12, -0.01 + 1e-12, -1e-5, 1e-7, 1e-3, 0.01 - 1e-12, 0.01 + 1e-12, 0.3, 5.0]
    )
    np.testing.assert_allclose(_chi(w), [_chi_exact(v) for v in w], rtol=1e-10)
    assert float(_chi(np.array([0.0]))[0]) == pytest.approx(2.0 / 3.0, rel=1e-15)


@pytest.mark.parametrize("xi", [-0.4, -1e-9, 0.0, 1e-9, 0.3])
def test_derivatives_match_finite_differences(xi: float) -> None:
    y = np.random.default_rng(5).gumbel(0.0, 0.3, size=(3, 40))  # inside every support below
    th = np.array([[xi, 0.1, 0.05], [xi, -0.2, -0.1], [xi, 0.0, 0.2]])
    ll, g, h = _gev_derivs_rows(y, th)
    ref = [np.sum(gev_logpdf(y[k], xi=xi, loc=th[k, 1], scale=np.exp(th[k, 2]))) for k in range(3)]
    np.testing.assert_allclose(ll, ref, rtol=1e-13)
    np.testing.assert_allclose(_gev_loglik_rows(y, th), ref, rtol=1e-13)
    eps = 1e-6
    fin = np.isfinite(ll)  # rows whose data lie inside the support (a row outside has no derivative)
    assert fin.all()
    for i in range(3):
        e = np.zeros(3)
        e[i] = eps
        g_fd = (_gev_loglik_rows(y, th + e) - _gev_loglik_rows(y, th - e))[fin] / (2 * eps)
        h_fd = (_gev_derivs_rows(y, th + e)[1] - _gev_derivs_rows(y, th - e)[1])[fin] / (2 * eps)
        np.testing.assert_allclose(g[fin, i], g_fd, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(h[fin, :, i], h_fd, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(h, np.swapaxes(h, 1, 2), rtol=0, atol=0)


def test_gumbel_limit_is_smooth() -> None:
    y = np.random.default_rng(6).gumbel(0.0, 1.0, size=(1, 60))
    at = {s: _gev_derivs_rows(y, np.array([[s, 0.1, -0.05]])) for s in (-1e-12, 0.0, 1e-12)}
    for s in (-1e-12, 1e-12):
        for k in range(3):
            np.testing.assert_allclose(at[s][k], at[0.0][k], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("n", [30, 90, 365])
@pytest.mark.parametrize("xi", SHAPES)
def test_resample_fits_equal_fit_gev(xi: float, n: int) -> None:
    # 3 resamples per case, 45 in all (fit_gev takes ~0.1 s each); all regular for this seed
    x = _maxima(xi, n, 2)
    full = _fit_gev_quiet(x)
    r = x[np.random.default_rng(n).integers(0, n, size=(3, n))]
    xs, locs, scales, lls, status = _gev_mle_rows(r, (full.xi, full.loc, full.scale))
    np.testing.assert_array_equal(status, 0)
    for k in range(3):
        ref = _fit_gev_quiet(r[k])
        assert ref.success
        assert abs(xs[k] - ref.xi) < 1e-5
        assert abs(locs[k] - ref.loc) < 1e-5
        assert abs(scales[k] / ref.scale - 1.0) < 1e-5
        assert lls[k] >= ref.loglik - 1e-8
        # an interior local maximum: zero gradient, negative definite Hessian
        _, g, h = _gev_derivs_rows(r[k : k + 1], np.array([[xs[k], locs[k], np.log(scales[k])]]))
        assert np.max(np.abs(g)) < 1e-6 * n / min(1.0, scales[k])
        assert np.all(np.linalg.eigvalsh(h[0]) < 0)


@pytest.mark.parametrize("n", [90, 365])
def test_share_converged_regular(n: int) -> None:
    for xi in SHAPES:
        bs = bootstrap_gev(_maxima(xi, n, 2), n_boot=400, rng=3)
        assert np.mean(bs.converged) >= 0.99
        assert bs.n_failed == int(np.sum(~bs.converged))
        ok = bs.converged
        assert np.all(np.isfinite(bs.xi[ok])) and np.all(np.isnan(bs.xi[~ok]))


def test_small_samples_mostly_converge() -> None:
    # n = 30: some resamples have no interior maximum (xi -> -1); most still converge
    bs = bootstrap_gev(_maxima(0.0, 30, 2), n_boot=1000, rng=4)
    assert np.mean(bs.converged) >= 0.95
    assert set(np.unique(bs.status[~bs.converged])) <= {1, 2, 3}


def test_bootstrap_rows_are_the_documented_resamples() -> None:
    x = _maxima(0.1, 90, 3)
    bs = bootstrap_gev(x, n_boot=200, rng=7)
    idx = np.random.default_rng(7).integers(0, x.size, size=(200, x.size))
    xs, locs, scales, _, status = _gev_mle_rows(x[idx], (bs.fit.xi, bs.fit.loc, bs.fit.scale))
    np.testing.assert_array_equal(bs.status, status)
    np.testing.assert_array_equal(bs.xi, xs)
    np.testing.assert_array_equal(bs.scale, scales)
    np.testing.assert_array_equal(bs.loc, locs)


def test_same_seed_same_numbers_any_chunking(monkeypatch: pytest.MonkeyPatch) -> None:
    x = _maxima(-0.1, 30, 4)
    a = bootstrap_gev(x, n_boot=300, rng=11)
    b = bootstrap_gev(x, n_boot=300, rng=np.random.default_rng(11))
    monkeypatch.setattr(bootstrap_mod, "_CHUNK_ELEMS", 30 * 7)  # chunks of 7 rows
    c = bootstrap_gev(x, n_boot=300, rng=11)
    for other in (b, c):
        for name in ("xi", "loc", "scale", "loglik", "converged", "status"):
            np.testing.assert_array_equal(getattr(a, name), getattr(other, name))
    d = bootstrap_gev(x, n_boot=300, rng=12)
    assert not np.array_equal(a.xi, d.xi, equal_nan=True)


def test_degenerate_and_unbounded_rows_are_flagged() -> None:
    rows = np.array(
        [
            [1.0] * 10,  # all equal
            [1.0] * 5 + [2.0] * 5,  # two values: the likelihood rises across xi = -1
            [1.0] * 9 + [2.0],  # ties at the minimum: the scale collapses, no maximum
            np.arange(10.0),
        ]
    )
    xs, _, _, _, status = _gev_mle_rows(rows, (0.0, 1.0, 1.0))
    assert status[0] == 1
    assert status[1] == 2 and status[2] in (2, 3)
    assert status[3] == 0 and xs[3] > -1.0
    # in a bootstrap: resamples of a sample dominated by one value are often all equal
    # (explicit start: fit_gev on such a sample is slow and collapses the scale)
    start = GEVFit(xi=0.0, loc=1.05, scale=0.1, n=6, loglik=np.nan, success=True, message="")
    bs = bootstrap_gev(np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.3]), n_boot=200, rng=0, start=start)
    all_equal = bs.status == 1
    assert np.sum(all_equal) > 20
    assert not np.any(bs.converged[all_equal])
    assert bs.n_failed >= np.sum(all_equal)
    assert np.all(np.isnan(bs.sf(1.1)[~bs.converged]))


def test_sf_matches_gev_sf() -> None:
    bs = bootstrap_gev(_maxima(0.2, 90, 5), n_boot=50, rng=2)
    for level in (0.2, 0.5, 1.0, 3.0):
        params = zip(bs.xi, bs.loc, bs.scale, strict=True)
        ref = [float(gev_sf(level, xi=a, loc=b, scale=c)) for a, b, c in params]
        np.testing.assert_allclose(bs.sf(level), ref, rtol=1e-12, atol=1e-300)


def test_affine_equivariance_and_start() -> None:
    x = _maxima(-0.1, 90, 6)
    a = bootstrap_gev(x, n_boot=200, rng=1)
    b = bootstrap_gev(x * 1e-3 + 10.0, n_boot=200, rng=1)
    np.testing.assert_array_equal(a.converged, b.converged)
    np.testing.assert_allclose(b.xi, a.xi, atol=1e-7)
    np.testing.assert_allclose(b.scale, a.scale * 1e-3, rtol=1e-7)
    np.testing.assert_allclose(b.loc, a.loc * 1e-3 + 10.0, rtol=0, atol=1e-9)
    # a poor start (outside the support of some values) reaches the same maxima
    f = a.fit
    poor = GEVFit(
        xi=0.8, loc=f.loc + 2 * f.scale, scale=0.3 * f.scale, n=f.n, loglik=np.nan, success=True, message=""
    )
    c = bootstrap_gev(x, n_boot=200, rng=1, start=poor)
    both = a.converged & c.converged
    assert np.mean(both) >= 0.99
    np.testing.assert_allclose(c.xi[both], a.xi[both], atol=1e-7)


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="all equal"):
        bootstrap_gev(np.ones(10))
    with pytest.raises(ValueError, match="NaN"):
        bootstrap_gev(np.array([1.0, np.nan, 2.0, 3.0]))
    with pytest.raises(ValueError, match="at least 3"):
        bootstrap_gev(np.array([1.0, 2.0]))
    with pytest.raises(ValueError, match="n_boot"):
        bootstrap_gev(np.arange(5.0), n_boot=0)
