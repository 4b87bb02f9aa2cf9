"""Tail dependence (Veerman et al., section 3.2): regular grid, autocorrelation, decorrelation time,
V_K curve and cluster gap, runs declustering, extremal index (Ferro & Segers 2003)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from overbound.stats.dependence import (
    autocorrelation,
    cluster_gap,
    decluster_runs,
    decorrelation_time,
    extremal_index,
    extremal_index_runs,
    regular_series,
    vk_curve,
)

DATA = Path(__file__).parents[1] / "data" / "evt"


# ---------------------------------------------------------------------------------------------- helpers


def _ar1(rng: np.random.Generator, n: int, phi: float) -> np.ndarray:
    """AR(1) with unit innovations, started from its stationary law; rho(k) = phi**k."""
    import scipy.signal

    e = rng.normal(size=n)
    e[0] /= np.sqrt(1 - phi**2)
    return scipy.signal.lfilter([1.0], [1.0, -phi], e)


def _armax(rng: np.random.Generator, n: int, a: float) -> np.ndarray:
    """X_t = max(a X_{t-1}, (1-a) Z_t), Z unit Frechet: extremal index 1 - a.

    X_t = max_{s<=t} a**(t-s) (1-a) Z_s, a running maximum in the log domain."""
    z = 1.0 / -np.log(rng.random(n))
    if a == 0:
        return z
    k = np.arange(n) * np.log(a)
    return np.exp(np.maximum.accumulate(np.log((1 - a) * z) - k) + k)


def _clustered_times(rng: np.random.Generator, n_clusters: int, duration: int, p: float) -> np.ndarray:
    """Exceedance times (s): Poisson cluster starts on [0, 1e6 s], each followed by exceedances
    at each second of the next `duration` s with probability p (first and last always)."""
    starts = np.round(rng.uniform(0, 1e6 - duration, n_clusters))
    t = starts[:, None] + np.arange(duration + 1)[None, :]
    keep = rng.random(t.shape) < p
    keep[:, [0, -1]] = True
    return np.unique(t[keep])


def _acf_loop(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Reference: mean lag-k product over the valid pairs / variance, one lag at a time."""
    w = np.isfinite(x)
    d = np.where(w, x - x[w].mean(), 0.0)
    var = np.sum(d[w] ** 2) / w.sum()
    out = []
    for k in range(max_lag + 1):
        pairs = w[: x.size - k] & w[k:]
        out.append(np.sum(d[: x.size - k][pairs] * d[k:][pairs]) / pairs.sum() / var)
    return np.array(out)


def _decluster_loop(t: np.ndarray, x: np.ndarray, u: float, r: float) -> list[tuple[int, int, float, float]]:
    """Reference: plain loop; rows (peak index, size, start, end)."""
    clusters: list[list[int]] = []
    last = None
    for i in range(t.size):
        if not x[i] > u:
            continue
        if last is None or t[i] - t[last] > r:
            clusters.append([])
        clusters[-1].append(i)
        last = i
    rows = []
    for c in clusters:
        best = c[0]
        for i in c:
            if x[i] > x[best]:
                best = i
        rows.append((best, len(c), t[c[0]], t[c[-1]]))
    return rows


# ---------------------------------------------------------------------------------------------- grid


def test_regular_series_gaps_are_nan_and_slots_are_exact():
    t = np.array([0, 1, 2, 5, 6, 9], dtype=np.int64) * 1_000_000 + 10**15
    s = regular_series(t, np.array([1.0, 2, 3, 4, 5, 6]))
    assert s.interval_s == 1.0 and s.start_us == 10**15
    np.testing.assert_array_equal(s.values, [1, 2, 3, np.nan, np.nan, 4, 5, np.nan, np.nan, 6])
    np.testing.assert_array_equal(s.slot, [0, 1, 2, 5, 6, 9])
    np.testing.assert_array_equal(s.time_s, np.arange(10.0))
    assert (s.n_off_grid, s.n_merged) == (0, 0)


def test_regular_series_jitter_rounds_to_nearest_slot_and_merges_keep_the_max():
    t = np.array([0, 1_000_100, 1_999_000, 2_400_000, 3_000_000, 6_000_000], dtype=np.int64)
    s = regular_series(t, np.array([0.1, 0.2, 0.3, 0.9, np.nan, 0.5]))
    np.testing.assert_array_equal(s.slot, [0, 1, 2, 2, 3, 6])
    np.testing.assert_array_equal(s.values, [0.1, 0.2, 0.9, np.nan, np.nan, np.nan, 0.5])
    assert (s.n_off_grid, s.n_merged) == (1, 1)


def test_regular_series_interval_estimate_ignores_gaps_and_accepts_override():
    t = np.concatenate([np.arange(100), np.arange(500, 600)]).astype(np.int64) * 5_000_000
    assert regular_series(t, np.zeros(t.size)).interval_s == 5.0
    # 10 s grid: the last epoch, 2995 s, is half-way and rounds up to slot 300
    assert regular_series(t, np.zeros(t.size), interval_s=10.0).values.size == 301


@pytest.mark.parametrize(
    ("t", "v", "match"),
    [
        (np.array([0.0, 1.0]), np.zeros(2), "integer"),
        (np.array([2, 1]), np.zeros(2), "sorted"),
        (np.array([0, 1]), np.zeros(3), "equal length"),
        (np.array([], dtype=np.int64), np.zeros(0), "empty"),
    ],
)
def test_regular_series_rejects_bad_input(t, v, match):
    with pytest.raises(ValueError, match=match):
        regular_series(t, v)


# ---------------------------------------------------------------------------------------------- ACF


def test_autocorrelation_without_gaps_is_the_unbiased_estimator():
    x = _ar1(np.random.default_rng(1), 500, 0.7)
    d = x - x.mean()
    brute = np.array([np.dot(d[: 500 - k], d[k:]) / (500 - k) for k in range(31)]) / np.mean(d * d)
    np.testing.assert_allclose(autocorrelation(x, max_lag=30), brute, rtol=1e-10, atol=1e-12)


def test_autocorrelation_with_gaps_uses_the_valid_pairs_only():
    rng = np.random.default_rng(2)
    x = _ar1(rng, 800, 0.8)
    x[rng.random(800) < 0.2] = np.nan
    x[300:400] = np.nan  # an outage
    np.testing.assert_allclose(autocorrelation(x, max_lag=50), _acf_loop(x, 50), rtol=1e-9, atol=1e-12)


def test_autocorrelation_facts_and_ar1_truth():
    x = _ar1(np.random.default_rng(3), 200_000, 0.9)
    rho = autocorrelation(x, max_lag=20)
    assert rho[0] == 1.0
    np.testing.assert_allclose(rho, 0.9 ** np.arange(21), atol=0.02)
    # invariant under an increasing affine map
    np.testing.assert_allclose(
        autocorrelation(3 * x[:5000] - 7, max_lag=20), autocorrelation(x[:5000], max_lag=20)
    )


def test_autocorrelation_degenerate_cases_are_nan():
    assert np.all(np.isnan(autocorrelation(np.full(10, 2.0), max_lag=3)))
    assert np.all(np.isnan(autocorrelation(np.array([1.0, np.nan, np.nan]), max_lag=2)))
    # a lag with no valid pair
    rho = autocorrelation(np.array([1.0, np.nan, 3.0, np.nan]), max_lag=3)
    assert rho[0] == 1.0 and np.isnan(rho[1]) and np.isnan(rho[3]) and rho[2] == pytest.approx(-1.0)
    with pytest.raises(ValueError, match="max_lag"):
        autocorrelation(np.zeros(5), max_lag=5)


def test_decorrelation_time_of_ar1():
    x = _ar1(np.random.default_rng(4), 200_000, 0.9)
    # first k with 0.9**k < 1/e: k > 1/-ln(0.9) = 9.49
    assert decorrelation_time(x, max_lag=100) in (9.0, 10.0, 11.0)
    assert decorrelation_time(x, interval_s=5.0, max_lag=100) == 5 * decorrelation_time(x, max_lag=100)
    # integral time scale (1 + phi) / (1 - phi) = 19
    assert decorrelation_time(x, rule="integral", max_lag=500) == pytest.approx(19.0, rel=0.15)
    assert decorrelation_time(x, rule="zero", max_lag=2000) > decorrelation_time(x, max_lag=100)


def test_decorrelation_time_limits():
    rng = np.random.default_rng(5)
    assert decorrelation_time(rng.normal(size=5000), max_lag=50) == 1.0  # white noise
    assert decorrelation_time(np.arange(1000.0), max_lag=10) == np.inf  # never drops within 10 lags
    assert np.isnan(decorrelation_time(np.ones(10)))
    with pytest.raises(ValueError, match="rule"):
        decorrelation_time(np.zeros(5), rule="half")  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------------------- V_K


def test_vk_curve_equals_brute_force_pair_count():
    rng = np.random.default_rng(6)
    t = rng.integers(0, 300, 150).astype(float)  # ties included
    k = np.array([0.0, 1, 2.5, 7, 40, 1000])
    c = vk_curve(rng.permutation(t), k_values=k[::-1])
    gaps = np.abs(t[:, None] - t[None, :])[np.triu_indices(t.size, 1)]
    np.testing.assert_allclose(c.v, [np.count_nonzero(gaps <= kk) / t.size for kk in k])
    assert c.n == 150 and c.duration_s == t.max() - t.min()
    assert c.v[-1] == (t.size - 1) / 2  # all pairs once K >= span
    assert np.all(np.diff(c.v) >= 0)


def test_vk_curve_of_poisson_times_is_linear():
    t = np.random.default_rng(7).uniform(0, 1e6, 5000)
    c = vk_curve(t, k_values=np.arange(0.0, 3001, 100))
    assert c.poisson_slope == pytest.approx(4999 / c.duration_s)
    np.testing.assert_allclose(c.v[1:], c.poisson()[1:], rtol=0.08)


def test_vk_curve_small_and_bad_input():
    assert np.all(vk_curve(np.array([3.0]), k_values=np.array([0.0, 10])).v == 0)
    assert np.isnan(cluster_gap(vk_curve(np.array([3.0]), k_values=np.arange(10.0))))
    with pytest.raises(ValueError, match="k_values"):
        vk_curve(np.arange(3.0), k_values=np.array([-1.0]))
    with pytest.raises(ValueError, match="finite"):
        vk_curve(np.array([0.0, np.nan]), k_values=np.array([1.0]))


@pytest.mark.parametrize(("duration", "p"), [(20, 1.0), (60, 0.5), (60, 0.2)])
def test_cluster_gap_recovers_the_cluster_duration(duration, p):
    """Documented: K_T comes out at 0.7-1.0 D (tangential join), never far above D."""
    ratios = []
    for seed in range(6):
        t = _clustered_times(np.random.default_rng(seed), 200, duration, p)
        ratios.append(cluster_gap(vk_curve(t, k_values=np.arange(0.0, 6 * duration + 1))) / duration)
    assert 0.65 <= min(ratios) and max(ratios) <= 1.5
    assert 0.7 <= np.median(ratios) <= 1.05


@pytest.mark.parametrize("n", [200, 2000, 20000])
def test_cluster_gap_of_independent_exceedances_is_zero(n):
    for seed in range(4):
        t = np.random.default_rng(seed).uniform(0, 1e6, n)
        assert cluster_gap(vk_curve(t, k_values=np.arange(0.0, 361))) == 0.0


# ---------------------------------------------------------------------------------------------- runs


@pytest.mark.parametrize("run_length", [0.0, 1.0, 2.5, 10.0, 1e9])
def test_decluster_runs_equals_loop_reference(run_length):
    rng = np.random.default_rng(8)
    t = np.cumsum(rng.choice([0.0, 1, 1, 1, 2, 7], 3000))  # irregular, with repeated times
    x = np.round(rng.exponential(size=3000), 1)  # ties within clusters
    x[rng.random(3000) < 0.05] = np.nan
    c = decluster_runs(t, x, threshold=1.5, run_length=run_length)
    ref = _decluster_loop(t, x, 1.5, run_length)
    np.testing.assert_array_equal(c.peak_index, [r[0] for r in ref])
    np.testing.assert_array_equal(c.size, [r[1] for r in ref])
    np.testing.assert_array_equal(c.start, [r[2] for r in ref])
    np.testing.assert_array_equal(c.end, [r[3] for r in ref])
    np.testing.assert_array_equal(c.peak_value, x[c.peak_index])
    np.testing.assert_array_equal(c.peak_time, t[c.peak_index])
    assert c.n_exceedances == np.count_nonzero(x > 1.5) == c.size.sum()
    assert (c.threshold, c.run_length) == (1.5, run_length)


def test_decluster_runs_limits():
    rng = np.random.default_rng(9)
    t, x = np.arange(1000.0), rng.normal(size=1000)
    every = decluster_runs(t, x, threshold=1.0, run_length=0.5)
    assert every.n_clusters == every.n_exceedances == np.count_nonzero(x > 1)
    one = decluster_runs(t, x, threshold=1.0, run_length=1e6)
    assert one.n_clusters == 1 and one.peak_index[0] == np.argmax(x)
    counts = [decluster_runs(t, x, threshold=1.0, run_length=r).n_clusters for r in range(0, 50, 5)]
    assert counts == sorted(counts, reverse=True)
    none = decluster_runs(t, x, threshold=10.0, run_length=5)
    assert none.n_clusters == 0 and none.n_exceedances == 0 and np.isnan(none.mean_size)
    assert (
        extremal_index_runs(t, x, threshold=1.0, run_length=3)
        == 1 / decluster_runs(t, x, threshold=1.0, run_length=3).mean_size
    )
    with pytest.raises(ValueError, match="run_length"):
        decluster_runs(t, x, threshold=1.0, run_length=-1)
    with pytest.raises(ValueError, match="sorted"):
        decluster_runs(t[::-1], x, threshold=1.0, run_length=1)


def _r_rows() -> list[dict[str, str]]:
    with open(DATA / "decluster_expected.csv", newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("row", _r_rows(), ids=lambda r: f"u{r['u']}-r{r['r']}")
def test_against_r_evd(row):
    """R evd clusters(x, u, r, cmax = TRUE) and exi(x, u, r): tests/data/evt/decluster_reference.R."""
    x = np.loadtxt(DATA / "decluster_series.csv", skiprows=1)
    t = np.arange(x.size, dtype=float)
    u, r = float(row["u"]), float(row["r"])
    c = decluster_runs(t, x, threshold=u, run_length=r)
    assert c.n_clusters == int(row["n_clusters"])
    np.testing.assert_array_equal(c.peak_index, np.array(row["peak_index"].split(), dtype=int))
    np.testing.assert_array_equal(c.peak_value, np.array(row["peak_value"].split(), dtype=float))
    assert extremal_index(t, x, threshold=u) == pytest.approx(float(row["exi_intervals"]), rel=1e-12)
    assert extremal_index_runs(t, x, threshold=u, run_length=r) == pytest.approx(
        float(row["exi_runs"]), rel=1e-12
    )


@pytest.mark.parametrize("r_s", [1, 30, 300])
def test_against_pyextremes(r_s):
    pyextremes = pytest.importorskip("pyextremes")
    import pandas as pd

    rng = np.random.default_rng(10)
    x = _armax(rng, 20_000, 0.7)
    keep = rng.random(x.size) > 0.1  # irregular times: 10 % of the epochs missing
    t = np.arange(x.size, dtype=float)[keep]
    x = x[keep]
    u = float(np.quantile(x, 0.97))
    series = pd.Series(x, index=pd.Timestamp("2026-01-01") + pd.to_timedelta(t, unit="s"))
    ref = pyextremes.get_extremes(series, method="POT", threshold=u, r=pd.Timedelta(seconds=r_s))
    c = decluster_runs(t, x, threshold=u, run_length=r_s)
    np.testing.assert_array_equal(c.peak_value, ref.to_numpy())
    ref_t = (ref.index - pd.Timestamp("2026-01-01")).total_seconds().to_numpy()
    np.testing.assert_array_equal(c.peak_time, ref_t)


# ------------------------------------------------------------------------------------------ extremal index


def test_extremal_index_hand_computed():
    # gaps 1, 1, 1, 10 (max > 2: bias-adjusted): 2 * 9**2 / (4 * 72) = 0.5625
    t = np.arange(14.0)
    x = np.zeros(14)
    x[[0, 1, 2, 3, 13]] = 1.0
    assert extremal_index(t, x, threshold=0.5) == pytest.approx(0.5625, rel=1e-15)
    # same on a 2 s grid
    assert extremal_index(2 * t, x, threshold=0.5, interval_s=2.0) == pytest.approx(0.5625, rel=1e-15)
    # gaps all <= 2: the simple estimator, which is >= 0.89 for gaps in {1, 2}, capped at 1
    x2 = np.zeros(14)
    x2[[0, 1, 3, 4, 6]] = 1.0
    assert extremal_index(t, x2, threshold=0.5) == 1.0
    assert np.isnan(extremal_index(t, x, threshold=5.0))
    assert extremal_index(t, np.eye(1, 14, 4)[0], threshold=0.5) == 1.0


def test_extremal_index_counts_gaps_as_non_exceedances():
    t = np.arange(14.0)
    x = np.zeros(14)
    x[[0, 1, 2, 3, 13]] = 1.0
    x[5:9] = np.nan
    keep = np.isfinite(x)
    assert extremal_index(t[keep], x[keep], threshold=0.5) == extremal_index(t, x, threshold=0.5) == 0.5625


@pytest.mark.parametrize("a", [0.0, 0.3, 0.6, 0.8])
def test_extremal_index_of_armax(a):
    """theta = 1 - a; n = 1e5 and the 98 % quantile give a Monte Carlo sd of about 0.016."""
    x = _armax(np.random.default_rng(11), 100_000, a)
    theta = extremal_index(np.arange(x.size, dtype=float), x, threshold=float(np.quantile(x, 0.98)))
    assert theta == pytest.approx(1 - a, abs=0.05)
    assert 0 < theta <= 1
