"""EVT figures: the right artists at the right values, degenerate inputs without warnings, same PNG bytes."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from matplotlib.axes import Axes
from scipy import stats

from overbound.report.evt_figures import (
    REQUIREMENTS,
    plot_acf,
    plot_clusters,
    plot_krs,
    plot_mean_excess,
    plot_p_mi_vs_threshold,
    plot_shape_stability,
    plot_tail_fit,
    plot_vk,
)
from overbound.report.figures import close_figure, figure_png
from overbound.stats.dependence import (
    autocorrelation,
    cluster_gap,
    decluster_runs,
    decorrelation_time,
    vk_curve,
)
from overbound.stats.evt import fit_gpd
from overbound.stats.krs import krs_test
from overbound.stats.threshold import mean_excess, shape_stability


@pytest.fixture(autouse=True)
def _no_warnings():
    """Every figure here must draw without any warning (log of zero, all-NaN, empty legend, ...)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def _one(ax: Axes, gid: str):
    found = ax.findobj(lambda a: a.get_gid() == gid)
    assert len(found) == 1, (gid, found)
    return found[0]


def _none(ax: Axes, gid: str) -> bool:
    return not ax.findobj(lambda a: a.get_gid() == gid)


def _hline(ax: Axes, gid: str) -> float:
    y = np.asarray(_one(ax, gid).get_ydata(), dtype=float)
    assert y[0] == y[1]
    return float(y[0])


def _vline(ax: Axes, gid: str) -> float:
    x = np.asarray(_one(ax, gid).get_xdata(), dtype=float)
    assert x[0] == x[1]
    return float(x[0])


def _png_twice(draw) -> None:
    pngs = []
    for _ in range(2):
        ax = draw()
        pngs.append(figure_png(ax.figure, dpi=60))
        close_figure(ax.figure)
    assert pngs[0][:8] == b"\x89PNG\r\n\x1a\n"
    assert pngs[0] == pngs[1]


# ---------------------------------------------------------------------------
# synthetic inputs built with the stats functions


def _ar1(n: int = 4000, phi: float = 0.9, seed: int = 1) -> np.ndarray:
    g = np.random.default_rng(seed)
    e = g.standard_normal(n)
    # AR(1) by a linear filter (no loop over samples)
    from scipy.signal import lfilter

    return lfilter([1.0], [1.0, -phi], e)


def _clustered_series(seed: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """A day at 1 Hz of SI ~ 0.2 with 12 bursts of 30 s reaching 0.5-0.9."""
    g = np.random.default_rng(seed)
    t = np.arange(86_400.0)
    si = 0.2 + 0.03 * g.standard_normal(t.size)
    starts = np.sort(g.choice(np.arange(100, 86_000, 600), 12, replace=False))
    burst = (starts[:, None] + np.arange(30)[None, :]).ravel()
    si[burst] += 0.3 + 0.4 * g.random(burst.size)
    return t, si


def _gpd_sample(xi: float, n: int = 400, seed: int = 3, u: float = 0.4, sigma: float = 0.05) -> np.ndarray:
    return u + stats.genpareto.rvs(xi, scale=sigma, size=n, random_state=seed)


# ---------------------------------------------------------------------------
# ACF


def test_acf_lines_at_one_over_e_and_the_decorrelation_time():
    x = _ar1()
    rho = autocorrelation(x, max_lag=60)
    tau = decorrelation_time(x, max_lag=60)
    # AR(1) with phi = 0.9: 1/e reached near -1/ln(0.9) = 9.5 lags
    assert 7 <= tau <= 13
    ax = plot_acf(np.arange(61.0), rho, decorrelation_s=tau)
    assert _hline(ax, "one-over-e") == pytest.approx(math.exp(-1.0))
    assert _hline(ax, "zero") == 0.0
    assert _vline(ax, "decorrelation") == tau
    np.testing.assert_array_equal(_one(ax, "acf").get_ydata(), rho)
    assert ax.get_xlabel() == "lag (s)"
    assert any(f"{tau:g} s" in t.get_text() for t in ax.get_legend().get_texts())
    close_figure(ax.figure)


@pytest.mark.parametrize("tau", [math.inf, math.nan])
def test_acf_undefined_or_never_decorrelated(tau):
    ax = plot_acf(np.arange(5.0), np.full(5, np.nan), decorrelation_s=tau)
    assert _none(ax, "decorrelation") and _none(ax, "acf")
    assert _one(ax, "note").get_text() == "autocorrelation undefined"
    ax = plot_acf(np.zeros(0), np.zeros(0), decorrelation_s=tau)
    assert _none(ax, "acf")


# ---------------------------------------------------------------------------
# V_K


def test_vk_poisson_and_upper_line_and_cluster_gap():
    t, si = _clustered_series()
    times = t[si > 0.45]
    curve = vk_curve(times, k_values=np.arange(0.0, 301.0, 5.0))
    kt = cluster_gap(curve)
    # bursts last 30 s: K_T somewhat below 30 s (cluster_gap's docstring: 0.75-0.8 D)
    assert 15 <= kt <= 40
    ax = plot_vk(curve, cluster_gap_s=kt)
    assert _vline(ax, "cluster-gap") == kt
    np.testing.assert_allclose(_one(ax, "poisson").get_ydata(), curve.poisson(curve.k))
    # the upper line is that of cluster_gap: least squares over K >= 150 s
    upper = curve.k >= 150.0
    b, a = np.polyfit(curve.k[upper], curve.v[upper], 1)
    line = _one(ax, "upper-fit")
    np.testing.assert_allclose(line.get_xdata(), [0.0, 300.0])
    np.testing.assert_allclose(line.get_ydata(), [a, a + 300.0 * b])
    # clusters: the line's intercept (within-cluster pairs per exceedance) is far above Poisson's 0
    assert a > 5.0
    close_figure(ax.figure)


@pytest.mark.parametrize("times", [np.zeros(0), np.array([12.0])])
def test_vk_fewer_than_two_exceedances(times):
    curve = vk_curve(times, k_values=np.arange(0.0, 50.0, 5.0))
    ax = plot_vk(curve, cluster_gap_s=cluster_gap(curve))
    assert _none(ax, "upper-fit") and _none(ax, "poisson") and _none(ax, "cluster-gap")
    assert "no pairs" in _one(ax, "note").get_text()
    close_figure(ax.figure)


# ---------------------------------------------------------------------------
# clusters


def test_clusters_threshold_peaks_and_envelope():
    t, si = _clustered_series()
    c = decluster_runs(t, si, threshold=0.45, run_length=20.0)
    assert c.n_clusters == 12
    ax = plot_clusters(t, si, c, threshold=0.45)
    assert _hline(ax, "threshold") == 0.45
    peaks = _one(ax, "cluster-peaks")
    np.testing.assert_array_equal(peaks.get_ydata(), c.peak_value)
    # the envelope keeps every extreme: its maximum is the largest SI, and it is decimated
    env = _one(ax, "si")
    assert np.nanmax(env.get_ydata()) == si.max()
    assert len(env.get_ydata()) <= 2 * 2000 + 10
    assert ax.get_ylim() == pytest.approx((0.0, 1.35 * si.max()))  # head room for the legend
    # peaks in hours from the window's start, which lies before the first cluster
    hours = np.asarray(peaks.get_xdata())
    assert hours.min() > 0 and hours.max() < 24
    np.testing.assert_allclose(np.diff(hours) * 3600.0, np.diff(c.peak_time))
    close_figure(ax.figure)


def test_clusters_without_exceedance_and_without_epochs():
    t, si = _clustered_series()
    c = decluster_runs(t, si, threshold=5.0, run_length=20.0)
    ax = plot_clusters(t, si, c, threshold=5.0)
    assert _none(ax, "cluster-peaks")
    assert _one(ax, "note").get_text() == "no exceedance of 5"
    assert _hline(ax, "threshold") == 5.0
    e = np.zeros(0)
    ax = plot_clusters(e, e, decluster_runs(e, e, threshold=0.5, run_length=1.0), threshold=0.5)
    assert _one(ax, "note").get_text() == "no epochs"
    close_figure(ax.figure)


# ---------------------------------------------------------------------------
# threshold plots


def test_mean_excess_curve_and_chosen_threshold():
    x = _gpd_sample(0.1)
    u = np.linspace(0.4, 0.7, 16)
    me = mean_excess(x, u)
    ax = plot_mean_excess(u, me, chosen=0.46)
    np.testing.assert_array_equal(_one(ax, "mean-excess").get_ydata(), me)
    assert _vline(ax, "chosen-threshold") == 0.46
    close_figure(ax.figure)
    # all NaN (no value above any threshold), no choice
    ax = plot_mean_excess(u, np.full(u.size, np.nan), chosen=None)
    assert _none(ax, "chosen-threshold")
    assert _one(ax, "note").get_text() == "no exceedance above any threshold"
    close_figure(ax.figure)


def test_shape_stability_band_and_reference_lines():
    x = _gpd_sample(0.1, n=300)
    u = np.array([0.4, 0.45, 0.5, 0.55, 2.0])  # the last has fewer than 3 exceedances: NaN
    s = shape_stability(x, u)
    assert np.isnan(s.xi[-1])
    ax = plot_shape_stability(s, chosen=0.45)
    np.testing.assert_array_equal(_one(ax, "xi").get_ydata(), s.xi)
    assert _hline(ax, "xi-nonregular") == -0.5
    assert _hline(ax, "xi-zero") == 0.0
    assert _vline(ax, "chosen-threshold") == 0.45
    band = _one(ax, "xi-band")
    ys = np.concatenate([p.vertices[:, 1] for p in band.get_paths()])
    lo, hi = ax.get_ylim()
    assert ys.min() >= lo and ys.max() <= hi
    # the band spans the finite profile intervals
    assert ys.min() == pytest.approx(np.nanmin(s.xi_lower))
    close_figure(ax.figure)


def test_shape_stability_infinite_or_missing_ends():
    from overbound.stats.threshold import ShapeStability

    u = np.array([0.1, 0.2, 0.3])
    s = ShapeStability(
        u,
        np.array([0.2, 0.3, np.nan]),
        np.array([-0.1, -1.0, np.nan]),
        np.array([0.6, np.inf, np.nan]),
        np.array([50, 6, 2]),
        0.95,
    )
    ax = plot_shape_stability(s, chosen=math.nan)
    hi = ax.get_ylim()[1]
    assert math.isfinite(hi) and hi < 2.0  # inf drawn at the top, not stretching the axes
    assert _none(ax, "chosen-threshold")
    nan = np.full(3, np.nan)
    ax = plot_shape_stability(ShapeStability(u, nan, nan, nan, np.zeros(3, int), 0.95), chosen=0.2)
    assert _one(ax, "note").get_text() == "too few exceedances for any shape"
    close_figure(ax.figure)


def test_p_mi_vs_threshold_on_log_axis_with_zeros():
    u = np.array([0.3, 0.4, 0.5, 0.6, 0.7])
    p = np.array([3e-8, 2e-8, 0.0, 1e-8, np.nan])
    lo = np.array([1e-9, 0.0, 0.0, 1e-10, np.nan])
    hi = np.array([1e-7, 9e-8, 4e-8, 5e-7, np.nan])
    ax = plot_p_mi_vs_threshold(u, p, lo, hi, chosen=0.4)
    assert ax.get_yscale() == "log"
    y = np.asarray(_one(ax, "p-mi").get_ydata())
    np.testing.assert_array_equal(y[[0, 1, 3]], p[[0, 1, 3]])
    assert np.isnan(y[2]) and np.isnan(y[4])  # zero and NaN are not drawn on the line
    np.testing.assert_array_equal(_one(ax, "p-mi-zero").get_xdata(), [0.5])
    assert _vline(ax, "chosen-threshold") == 0.4
    lo_y, hi_y = ax.get_ylim()
    assert lo_y == pytest.approx(1e-11) and hi_y == pytest.approx(1.5e-6)
    close_figure(ax.figure)
    # nothing positive at all
    z = np.zeros(3)
    ax = plot_p_mi_vs_threshold(u[:3], z, z, z, chosen=None)
    assert _one(ax, "note").get_text() == "no positive P_MI"
    assert ax.get_ylim() == pytest.approx((1e-9, 1.0))
    close_figure(ax.figure)


# ---------------------------------------------------------------------------
# tail fit


def test_tail_fit_model_point_and_requirements():
    x = _gpd_sample(0.15, n=400, u=0.4, sigma=0.05)
    fit = fit_gpd(x, threshold=0.4)
    n_total = 1_000_000
    zeta = x.size / n_total
    p_mi = zeta * float(fit.sf(1.0))
    ax = plot_tail_fit(
        x, fit=fit, n_total=n_total, exceedance_rate=zeta, p_mi=p_mi, p_mi_ci=(p_mi / 4, p_mi * 5)
    )
    assert ax.get_yscale() == "log"
    model = _one(ax, "gpd")
    mx, my = np.asarray(model.get_xdata()), np.asarray(model.get_ydata())
    assert mx[0] == 0.4 and mx[-1] >= 1.2  # from the threshold past SI = 1
    np.testing.assert_allclose(my, zeta * stats.genpareto.sf(mx - 0.4, fit.xi, scale=fit.sigma), rtol=1e-10)
    assert np.all(np.diff(my) <= 0)
    # empirical: Weibull plotting positions zeta * i / (n + 1) at the sorted values
    emp = _one(ax, "empirical")
    np.testing.assert_array_equal(emp.get_xdata(), np.sort(x)[::-1])
    np.testing.assert_allclose(emp.get_ydata(), zeta * np.arange(1, 401) / 401)
    # P_MI with its interval at SI = 1
    point = _one(ax, "p-mi")
    assert list(point.get_xdata()) == [1.0] and list(point.get_ydata()) == [p_mi]
    (segment,) = _one(ax, "p-mi-interval").get_segments()
    np.testing.assert_allclose(segment, [[1.0, p_mi / 4], [1.0, p_mi * 5]])
    assert _vline(ax, "si-one") == 1.0
    assert _hline(ax, "one-epoch") == 1e-6
    for r in REQUIREMENTS:
        assert _hline(ax, f"requirement-{r:g}") == r
    assert _none(ax, "endpoint") and _none(ax, "p-mi-zero")
    lo, hi = ax.get_ylim()
    assert lo <= p_mi / 4 and hi >= zeta
    close_figure(ax.figure)


def test_tail_fit_endpoint_below_one_gives_p_mi_zero():
    x = _gpd_sample(-0.4, n=400, u=0.4, sigma=0.1)  # endpoint 0.4 + 0.1/0.4 = 0.65
    fit = fit_gpd(x, threshold=0.4)
    assert fit.endpoint < 1.0
    zeta = 400 / 1e6
    assert float(fit.sf(1.0)) == 0.0
    ax = plot_tail_fit(x, fit=fit, n_total=1_000_000, exceedance_rate=zeta, p_mi=0.0, p_mi_ci=(0.0, 3e-9))
    assert _vline(ax, "endpoint") == pytest.approx(fit.endpoint)
    assert _none(ax, "p-mi")
    zero = _one(ax, "p-mi-zero")
    assert list(zero.get_xdata()) == [1.0]
    assert "P_{MI}$ = 0" in zero.get_label()
    # the model is sampled densely towards the endpoint and stops there
    my = np.asarray(_one(ax, "gpd").get_ydata())
    mx = np.asarray(_one(ax, "gpd").get_xdata())
    assert mx.max() == pytest.approx(fit.endpoint)  # nothing beyond: the probability is 0 there
    assert np.nanmin(my) < 1e-9 * zeta
    close_figure(ax.figure)


def test_tail_fit_without_exceedances():
    ax = plot_tail_fit(
        np.zeros(0),
        fit=None,
        n_total=86_400,
        exceedance_rate=0.0,
        p_mi=0.0,
        p_mi_ci=(0.0, 0.0),
        requirements=(2e-7,),
    )
    assert _one(ax, "note").get_text() == "no exceedances: no tail fit"
    assert _none(ax, "gpd") and _none(ax, "empirical") and _none(ax, "requirement-1e-07")
    assert _hline(ax, "requirement-2e-07") == 2e-7
    close_figure(ax.figure)


# ---------------------------------------------------------------------------
# KRS


def test_krs_statistic_critical_and_minimum():
    g = np.random.default_rng(5)
    r = krs_test(g.standard_normal(2000) * 0.8, l_min=0.5, l_tail=2.5)
    ax = plot_krs(r.levels, r.t_values, critical=r.critical)
    assert _hline(ax, "critical") == pytest.approx(stats.norm.isf(0.05))
    m = _one(ax, "minimum")
    assert m.get_ydata()[0] == pytest.approx(r.statistic)
    assert m.get_xdata()[0] == pytest.approx(r.l_at_min)
    close_figure(ax.figure)
    ax = plot_krs(np.zeros(0), np.zeros(0), critical=1.645)
    assert _one(ax, "note").get_text() == "no KRS statistic" and _none(ax, "minimum")
    close_figure(ax.figure)


# ---------------------------------------------------------------------------
# determinism


def test_png_bytes_identical_across_runs():
    t, si = _clustered_series()
    c = decluster_runs(t, si, threshold=0.45, run_length=20.0)
    curve = vk_curve(t[si > 0.45], k_values=np.arange(0.0, 301.0, 10.0))
    x = _gpd_sample(0.15, n=200)
    fit = fit_gpd(x, threshold=0.4)
    u = np.linspace(0.4, 0.6, 6)
    p = np.array([1e-8, 2e-8, 0.0, 3e-8, 1e-8, np.nan])
    draws = [
        lambda: plot_acf(np.arange(30.0), autocorrelation(si[:3000], max_lag=29), decorrelation_s=3.0),
        lambda: plot_vk(curve, cluster_gap_s=cluster_gap(curve)),
        lambda: plot_clusters(t, si, c, threshold=0.45),
        lambda: plot_mean_excess(u, mean_excess(x, u), chosen=0.45),
        lambda: plot_p_mi_vs_threshold(u, p, p / 2, p * 3, chosen=0.45),
        lambda: plot_tail_fit(
            x, fit=fit, n_total=10**6, exceedance_rate=2e-4, p_mi=1e-8, p_mi_ci=(0.0, 5e-8)
        ),
        lambda: plot_krs(np.linspace(0.5, 2, 20), np.linspace(3, 1, 20), critical=1.645),
    ]
    for draw in draws:
        _png_twice(draw)
