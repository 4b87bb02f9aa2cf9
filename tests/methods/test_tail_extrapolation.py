"""EVT tail extrapolation of the safety index (Veerman et al., GIMAT): probabilities, filtering, JSON."""

from __future__ import annotations

import datetime as dt
import json

import numpy as np
import polars as pl
import pytest

from overbound.io.schema import InputError
from overbound.methods.tail_extrapolation import (
    EVT_EXTRA_KEYS,
    EVT_KEYS,
    SCHEMA,
    evt_dict,
    per_approach,
    tail_analysis,
    write_evt,
)
from overbound.simulate import SimulationConfig, simulate
from overbound.stats.evt import fit_gpd

START = dt.datetime(2024, 1, 7)
FAST = {"n_boot": 200, "services": (), "gev_boot": 0, "n_sim": 50, "diagnostics": False}


def _table(err, pls, *, alert=None, interval_s=1.0) -> pl.DataFrame:
    """A one-station epoch table at ``interval_s``, vertical and horizontal columns from ``err``, ``pls``."""
    err = np.asarray(err, dtype=float)
    start_us = int((START - dt.datetime(1970, 1, 1)).total_seconds() * 1e6)
    us = start_us + (np.arange(err.size) * interval_s * 1e6).astype(np.int64)
    df = pl.DataFrame(
        {
            "time": pl.Series(us).cast(pl.Datetime("us")),
            "station": pl.Series(["A"] * err.size, dtype=pl.Categorical),
            "hpe": np.abs(err),
            "vpe": err,
            "hpl": np.asarray(pls, dtype=float),
            "vpl": np.asarray(pls, dtype=float),
        }
    )
    if alert is not None:
        df = df.with_columns(alert=pl.Series(alert, dtype=pl.Boolean))
    return df


# ------------------------------------------------------------------------------------------------
# per approach: mathematical facts and a simple cluster process


def test_per_approach_limits():
    p = 1e-6
    assert float(per_approach(p, 0.0, 150)) == pytest.approx(p, rel=1e-12)  # fully persistent
    indep = 1.0 - (1.0 - p) ** 150
    assert float(per_approach(p, p, 150)) == pytest.approx(indep, rel=1e-6)  # independent epochs
    r = np.linspace(0.0, p, 11)
    assert np.all(np.diff(per_approach(p, r, 150)) > 0)  # more events, more risk
    assert float(per_approach(p, p, 1)) == pytest.approx(p, rel=1e-12)  # one epoch: the epoch


def test_per_approach_cluster_process():
    """MI clusters of 5 epochs starting as Bernoulli(r): windows of 150 epochs hit at the predicted rate."""
    rng = np.random.default_rng(3)
    n, r, length, win = 4_000_000, 2e-4, 5, 150
    starts = np.flatnonzero(rng.random(n) < r)
    mi = np.zeros(n + length, dtype=bool)
    for k in range(length):  # a loop over the cluster length
        mi[starts + k] = True
    mi = mi[:n]
    c = np.concatenate([[0], np.cumsum(mi)])
    hit = (c[win:] - c[:-win]) > 0
    p_emp = mi.mean()
    r_emp = starts.size / n
    pred = float(per_approach(p_emp, r_emp, win))
    assert hit.mean() == pytest.approx(pred, rel=0.03)
    # the independent-sample formula with the epoch probability would overstate it about 5 times
    assert 1.0 - (1.0 - p_emp) ** win > 3.0 * pred


# ------------------------------------------------------------------------------------------------
# coverage on simulated campaigns with exact truth


def test_p_mi_coverage_all_exceedances():
    """All exceedances + stationary bootstrap: the 95 % interval covers sim.p_mi_true in most runs."""
    reps, hits = 20, 0
    for i in range(reps):
        cfg = SimulationConfig(days=0.5, sigma_ratio=1.6, tail_fraction=0.0, seed=100 + i, correlation_s=10)
        sim = simulate(cfg)
        truth = sim.p_mi_true("vertical")
        a = tail_analysis(sim.table, decluster=False, rng=i, **{**FAST, "n_boot": 100})
        lo, hi = a.tail.p_ci
        hits += lo <= truth <= hi
    print(f"observed coverage {hits / reps:.2f} over {reps} runs")
    # Binomial(20, 0.95): P(X < 14) ~ 2e-4, so >= 0.7 fails a valid 95 % interval almost never
    assert hits / reps >= 0.7


def _moving_maximum(n: int, k: int, alpha: float, scale: float, seed: int) -> np.ndarray:
    """SI_t = scale * max(Z_t..Z_t-k+1), Z iid Pareto(alpha): a large Z makes a cluster of k equal values."""
    z = np.random.default_rng(seed).pareto(alpha, n + k - 1) + 1.0
    return scale * np.lib.stride_tricks.sliding_window_view(z, k).max(axis=1)


def test_declustered_p_mi_moving_maximum():
    """Clusters of exactly k at every level: the size near 1 is k and P_MI covers 1 - (1 - q)^k."""
    k, alpha, scale, n = 5, 4.0, 0.1, 400_000
    si = _moving_maximum(n, k, alpha, scale, seed=11)
    q = (1.0 / scale) ** -alpha  # P(scale * Z > 1) = 1e-4
    truth = 1.0 - (1.0 - q) ** k
    a = tail_analysis(_table(si * 10.0, np.full(n, 10.0)), threshold=0.3, cluster_gap=2.0, **FAST)
    t = a.tail
    assert t.cluster_size.mean == k and np.all(t.cluster_size.sizes == k)
    assert k <= t.cluster_size.at_threshold < 1.1 * k  # clusters of two large Z merge at u
    # P_MI = cluster rate x GPD survival of the cluster maxima x the cluster size near 1
    assert t.p == pytest.approx(t.n_clusters / n * float(t.gpd.sf(1.0)) * k, rel=1e-12)
    assert t.cluster_rate == pytest.approx(t.p / k, rel=1e-12)
    assert t.p_ci[0] <= truth <= t.p_ci[1]
    assert t.gpd.xi == pytest.approx(1.0 / alpha, abs=0.1)


def test_cluster_size_shrinks_with_the_level():
    """AR(1) |Gaussian| errors: clusters near SI = 1 are smaller than at the threshold; P_MI uses them."""
    sim = simulate(SimulationConfig(days=20, sigma_ratio=1.2, tail_fraction=0.0, seed=3))
    a = tail_analysis(sim.table, **FAST)
    c = a.tail.cluster_size
    assert a.tail.threshold <= c.level <= 1.0
    assert c.sizes.size >= 30 or c.level == 1.0
    assert 1.0 <= c.mean < c.at_threshold
    n_c_rate = a.tail.n_clusters / a.tail.n_total
    assert a.tail.p == pytest.approx(n_c_rate * float(a.tail.gpd.sf(1.0)) * c.mean, rel=1e-12)


# ------------------------------------------------------------------------------------------------
# options


@pytest.fixture(scope="module")
def sim_table():
    return simulate(
        SimulationConfig(days=1, sigma_ratio=1.5, tail_fraction=0.0, seed=7, correlation_s=10)
    ).table


def test_threshold_value_no_decluster_fits_all_exceedances(sim_table):
    a = tail_analysis(sim_table, threshold=0.6, decluster=False, **FAST)
    assert a.tail.p_ci[0] <= a.tail.p <= a.tail.p_ci[1]
    si = np.abs(sim_table["vpe"].to_numpy()) / sim_table["vpl"].to_numpy()
    si = si[np.isfinite(si)]
    exc = si[si > 0.6]
    assert a.tail.threshold == 0.6
    assert a.tail.gpd.n == exc.size == a.tail.n_exceedances
    ref = fit_gpd(exc, threshold=0.6)
    assert a.tail.gpd.xi == pytest.approx(ref.xi, rel=1e-10)
    assert a.tail.p == pytest.approx(exc.size / si.size * float(ref.sf(1.0)), rel=1e-10)


def test_threshold_value_decluster_fits_cluster_maxima(sim_table):
    a = tail_analysis(sim_table, threshold=0.6, cluster_gap=20.0, **FAST)
    t = a.tail
    assert a.dependence.cluster_gap_s == 20.0 and not a.dependence.cluster_gap_auto
    assert t.gpd.n == t.n_clusters < t.n_exceedances
    assert t.clusters.n_exceedances == t.n_exceedances
    assert t.p_ci[0] <= t.p <= t.p_ci[1] and t.p_ci[0] <= t.p_95 <= t.p_ci[1]
    # P_MI = cluster rate x GPD survival x mean cluster size near SI = 1
    assert t.p == pytest.approx(
        t.n_clusters / t.n_total * float(t.gpd.sf(1.0)) * t.cluster_size.mean, rel=1e-12
    )


def test_threshold_above_one_rejected(sim_table):
    with pytest.raises(ValueError, match="below 1"):
        tail_analysis(sim_table, threshold=1.2, **FAST)


def test_missing_column():
    with pytest.raises(InputError, match="vpl"):
        tail_analysis(pl.DataFrame({"time": [1], "station": ["A"], "vpe": [1.0]}), **FAST)


# ------------------------------------------------------------------------------------------------
# HMI filtering (section 3.6)


def test_hmi_filtering_counts():
    n = 20_000
    rng = np.random.default_rng(1)
    err = rng.normal(0.0, 2.0, n)
    pls = np.full(n, 10.0)
    pls[[5000, 5003]] = 60.0  # PL >= VAL 50: unavailable, an alert for the operation
    alert = np.zeros(n, dtype=bool)
    alert[10_000] = True  # a flagged epoch
    err[15_000] = np.nan  # no solution
    a = tail_analysis(
        _table(err, pls, alert=alert), service="TEST:40:50", threshold=0.3, decluster=False, **FAST
    )
    c = a.counts
    assert (c.n_rows, c.n_no_solution, c.n_alert, c.n_pl_above_al) == (n, 1, 1, 2)
    # TTA 6 s before each alert: 4994-4999 and 4997-5002 (without 5000) give 8; 9994-9999 give 6
    assert c.n_tta == 14
    assert c.n_used == n - 1 - 1 - 2 - 14
    assert a.service == "TEST"
    # without the service nothing but the alert and the no-solution epoch is dropped
    b = tail_analysis(_table(err, pls, alert=alert), threshold=0.3, decluster=False, **FAST)
    assert (b.counts.n_pl_above_al, b.counts.n_tta, b.counts.n_used) == (0, 0, n - 2)


def test_hmi_service_is_mi_of_the_filtered_si(sim_table):
    """Section 3.6: P_HMI is the MI extrapolation of SI on the epochs with PL < AL (TTA before alerts out)."""
    a = tail_analysis(sim_table, **{**FAST, "services": ("LPV-200",)}, decluster=False, threshold=0.6)
    h = a.services["LPV-200"]
    vpl = sim_table["vpl"].to_numpy()
    ok = np.isfinite(vpl)
    assert h.alert_limit == 35.0
    assert h.counts.n_pl_above_al == int(np.sum(vpl[ok] >= 35.0))
    assert h.tail.variable == "SI" and h.tail.threshold == a.tail.threshold
    assert h.tail.n_total == h.counts.n_used
    # the same fit as the main analysis on the filtered table
    t = sim_table["time"].dt.epoch("us").to_numpy()
    alert_t = t[ok & (vpl >= 35.0)]
    nxt = np.searchsorted(alert_t, t, side="right")  # next alert strictly after each epoch
    ahead = np.where(nxt < alert_t.size, alert_t[np.minimum(nxt, alert_t.size - 1)] - t, np.inf)
    keep = sim_table.filter(pl.Series(~(ok & (vpl >= 35.0)) & ~(ahead <= 6e6)))
    assert keep.filter(pl.col("vpl").is_not_nan()).height == h.counts.n_used
    b = tail_analysis(keep, **{**FAST, "services": ()}, decluster=False, threshold=0.6)
    assert h.tail.gpd.xi == pytest.approx(b.tail.gpd.xi, rel=1e-9)
    assert h.p_hmi == pytest.approx(b.tail.p, rel=1e-9)
    assert h.exposure_s == 150.0 and h.integrity_risk == 2e-7
    assert h.meets_requirement == (h.p_hmi_exposure_95 <= 2e-7)


# ------------------------------------------------------------------------------------------------
# finite endpoint below SI = 1


def test_finite_endpoint_gives_zero():
    """SI = 0.7 (1 - U^0.3): a GPD tail of shape -0.3 and endpoint 0.7 < 1, so P_MI = 0 is the answer."""
    rng = np.random.default_rng(5)
    n = 50_000
    si = 0.7 * (1.0 - rng.random(n) ** 0.3)
    a = tail_analysis(_table(si * 10.0, np.full(n, 10.0)), cluster_gap=0.0, **FAST)
    t = a.tail
    assert t.gpd.xi < 0 and t.gpd.endpoint < 1.0
    assert t.gpd.xi == pytest.approx(-0.3, abs=0.1)
    assert t.p == 0.0 and t.p_approach == 0.0
    assert "P = 0" in t.message and "valid answer" in a.message
    assert evt_dict(a)["p_mi"] == 0.0


# ------------------------------------------------------------------------------------------------
# JSON


ISSUE_KEYS = {
    "schema",
    "threshold",
    "n_exceedances",
    "cluster_gap_s",
    "n_clusters",
    "extremal_index",
    "gpd",
    "p_mi",
    "p_mi_ci",
    "p_mi_95",
    "p_mi_per_approach",
    "p_mi_per_approach_95",
    "gev",
    "krs",
    "tail_overbound_probability",
    "services",
}


def test_json_keys_and_determinism(sim_table, tmp_path):
    opts = {"n_boot": 100, "n_sim": 50, "gev_boot": 0, "services": ("APV-I",)}
    a = tail_analysis(sim_table, rng=3, **opts)
    b = tail_analysis(sim_table, rng=3, **opts)
    assert EVT_KEYS == ISSUE_KEYS
    d = evt_dict(a)
    assert set(d) == ISSUE_KEYS | EVT_EXTRA_KEYS
    assert d["schema"] == SCHEMA == "overbound.evt/1"
    assert {"shape", "scale", "shape_ci"} <= set(d["gpd"])
    assert {"shape", "loc", "scale", "p_mi_95"} <= set(d["gev"])
    assert set(d["krs"]) == {"statistic", "critical", "overbounded"}
    assert {"p_hmi", "p_hmi_95", "meets_requirement"} <= set(d["services"]["APV-I"])
    assert len(d["p_mi_ci"]) == 2 and d["p_mi_ci"][0] <= d["p_mi_95"] <= d["p_mi_ci"][1]
    p1, p2 = tmp_path / "a.json", tmp_path / "b.json"
    write_evt(a, p1)
    write_evt(b, p2)
    assert p1.read_bytes() == p2.read_bytes()
    assert json.loads(p1.read_text())["n_exceedances"] == a.tail.n_exceedances
    # the diagnostics for the figures are there
    t = a.tail
    assert t.candidates.size == t.mean_excess.size == t.p_vs_threshold.size == t.stability.xi.size > 0
    assert a.dependence.acf[0] == 1.0 and a.dependence.vk_k_s.size == a.dependence.vk_v.size


def test_service_without_epochs_gives_no_estimate(sim_table):
    a = tail_analysis(
        sim_table, threshold=0.6, services=("TINY:1:1",), **{k: v for k, v in FAST.items() if k != "services"}
    )
    h = a.services["TINY"]
    assert h.counts.n_used == 0 and h.tail is None and h.meets_requirement is None
    assert "no estimate" in h.message
