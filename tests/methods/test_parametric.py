"""Parametric method (Kannemans 2006): JSON keys, counted values equal to counting's, reasons, determinism."""

from __future__ import annotations

import datetime as dt
import json
import math

import numpy as np
import polars as pl
import pytest

from overbound.io.schema import InputError
from overbound.methods.counting import continuity_risk, count_kpis
from overbound.methods.parametric import (
    ACF_FIGURE_POINTS,
    AXIS_EXTRA_KEYS,
    AXIS_KEYS,
    SCHEMA,
    SERVICE_EXTRA_KEYS,
    SERVICE_KEYS,
    TOP_EXTRA_KEYS,
    TOP_KEYS,
    analysed_series,
    parametric_analysis,
    parametric_dict,
    write_parametric,
)
from overbound.report.json import dumps
from overbound.services import parse_service, resolve_services
from overbound.simulate import SimulationConfig, simulate
from overbound.stats.parametric import (
    fit_normal_ratio,
    fit_rayleigh_ratio,
    fit_weibull,
    log_ratio_exceedance,
    weibull_sf,
)

START = dt.datetime(2024, 1, 7)


def _with_alerts(table: pl.DataFrame, seed: int, share: float = 2e-4) -> pl.DataFrame:
    """Receiver alerts in short bursts (a few per day), as a receiver raises them."""
    rng = np.random.default_rng(seed)
    alert = np.zeros(table.height, dtype=bool)
    for start in rng.integers(0, table.height - 20, max(1, round(share * table.height / 5))):
        alert[start : start + 5] = True
    return table.with_columns(alert=pl.Series(alert))


@pytest.fixture(scope="module")
def sim_table() -> pl.DataFrame:
    """Two stations, half a day each, with gaps, outages and receiver alerts."""
    cfg = SimulationConfig(days=0.5, stations=2, seed=5, gap_rate_per_day=10.0, outage_rate_per_day=10.0)
    return _with_alerts(simulate(cfg).table, 1)


@pytest.fixture(scope="module")
def analysis(sim_table):
    return parametric_analysis(sim_table)


def _table(vpe, vpl, *, hpe=None, hpl=None, alert=None, keep=None) -> pl.DataFrame:
    """A handcrafted one-station 1 Hz table; ``keep`` removes rows (gaps)."""
    vpe = np.asarray(vpe, dtype=float)
    us = int((START - dt.datetime(1970, 1, 1)).total_seconds() * 1e6) + np.arange(vpe.size) * 1_000_000
    cols = {
        "time": pl.Series(us).cast(pl.Datetime("us")),
        "station": pl.Series(["A"] * vpe.size, dtype=pl.Categorical),
        "vpe": vpe,
        "vpl": np.asarray(vpl, dtype=float),
    }
    if hpe is not None:
        cols |= {"hpe": np.asarray(hpe, dtype=float), "hpl": np.asarray(hpl, dtype=float)}
    if alert is not None:
        cols["alert"] = np.asarray(alert, dtype=bool)
    df = pl.DataFrame(cols)
    return df if keep is None else df.filter(pl.Series(keep))


# ------------------------------------------------------------------------------------------------
# JSON


def test_json_has_the_issue_keys_and_the_documented_extras(analysis):
    doc = parametric_dict(analysis)
    assert doc["schema"] == SCHEMA
    assert set(doc) == TOP_KEYS | TOP_EXTRA_KEYS
    for axis in ("vertical", "horizontal"):
        a = doc[axis]
        assert set(a) == AXIS_KEYS | AXIS_EXTRA_KEYS
        assert set(a["ratio_fit"]) == {"distribution", "mean", "sigma"}
        assert set(a["weibull"]) == {"a", "b"}
        assert set(a["services"]) == {s.name for s in resolve_services(None)}
        for name, s in a["services"].items():
            if axis == "vertical" and name == "NPA":
                assert s is None  # no vertical alert limit
                continue
            assert set(s) == SERVICE_KEYS | SERVICE_EXTRA_KEYS
            assert s["continuity_window_s"] == (3600.0 if name == "NPA" else 15.0)
    assert doc["vertical"]["ratio_fit"]["distribution"] == "normal"
    assert doc["horizontal"]["ratio_fit"]["distribution"] == "rayleigh"
    assert doc["reasons"] == {}


def test_json_is_byte_deterministic(sim_table, analysis, tmp_path):
    a = write_parametric(analysis, tmp_path / "a.json")
    b = write_parametric(parametric_analysis(sim_table.clone()), tmp_path / "b.json")
    assert a == b == (tmp_path / "a.json").read_text(encoding="utf-8")
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()
    doc = json.loads(a)
    assert doc["vertical"]["services"]["APV-I"]["p_hmi"] is not None


# ------------------------------------------------------------------------------------------------
# counted values


def test_counted_values_equal_counting(sim_table, analysis):
    assert sim_table["alert"].sum() > 0 and sim_table["vpl"].is_nan().sum() > 0
    kpis = count_kpis(sim_table, resolve_services(None), histogram_bins=0, by_station=False)
    for name, k in kpis.services.items():
        for axis in ("vertical", "horizontal"):
            ref = k.axis(axis)
            s = analysis.axis(axis).services[name]
            if ref.alert_limit is None:
                assert s is None
                continue
            assert s.unavailability_counted == 1.0 - ref.availability
            assert s.n_available_counted == ref.n_available
            assert (s.continuity_n_windows, s.continuity_n_fail) == (
                ref.continuity.n_windows,
                ref.continuity.n_fail,
            )
            assert s.continuity_counted == ref.continuity.risk


def test_handcrafted_counts_with_gaps_and_alerts():
    n = 3000
    vpl = np.full(n, 12.0)
    vpl[[100, 101, 1500]] = 60.0  # above APV-I's VAL: unavailable
    vpl[700] = np.nan  # no solution
    alert = np.zeros(n, dtype=bool)
    alert[2000:2003] = True
    keep = np.ones(n, dtype=bool)
    keep[2500:2510] = False  # a 10 s gap
    vpe = np.random.default_rng(0).normal(0.0, 1.0, n)
    table = _table(vpe, vpl, alert=alert, keep=keep)
    a = parametric_analysis(table, services=("APV-I",)).vertical
    s = a.services["APV-I"]
    t_us = table["time"].dt.epoch("us").to_numpy()
    pls, al = table["vpl"].to_numpy(), table["alert"].to_numpy()
    ref = continuity_risk(t_us, (pls < 50.0) & ~al, window_s=15.0)
    assert (s.continuity_n_windows, s.continuity_n_fail) == (ref.n_windows, ref.n_fail)
    # events: the two outliers at 100/101, the one at 1500, the no-solution epoch, the alert, the gap
    assert s.continuity_n_events == 5
    assert s.n_available_counted == table.height - 3 - 1 - 3
    assert s.unavailability_counted == 1.0 - s.n_available_counted / table.height
    assert s.unavailability_counted_fitted == pytest.approx(3 / (table.height - 1 - 3))
    assert a.n_alert == 3 and a.n_epochs == table.height - 1 - 3


def test_alerts_are_left_out_of_the_fits(sim_table, analysis):
    for axis, fit in (("vertical", fit_normal_ratio), ("horizontal", fit_rayleigh_ratio)):
        _, ratio, pls = analysed_series(sim_table, axis)
        a = analysis.axis(axis)
        assert a.n_epochs == ratio.size == sim_table.height - a.n_no_solution - a.n_alert
        # the same fits to rounding: the analysis adds its sums station-day by station-day
        ref, wb = fit(ratio), fit_weibull(pls)
        assert (a.ratio_fit.distribution, a.ratio_fit.n) == (ref.distribution, ref.n)
        assert a.ratio_fit.mean == pytest.approx(ref.mean, rel=1e-9, abs=1e-15)
        assert a.ratio_fit.sigma == pytest.approx(ref.sigma, rel=1e-12)
        assert (a.weibull.n, a.weibull.converged) == (wb.n, wb.converged)
        assert (a.weibull.a, a.weibull.b) == pytest.approx((wb.a, wb.b), rel=1e-10)
        assert a.log10_p_mi == pytest.approx(float(log_ratio_exceedance(a.ratio_fit, 1.0)) / math.log(10))
        s = a.services["APV-I"]
        assert s.unavailability_fit == pytest.approx(float(weibull_sf(a.weibull, s.alert_limit)), rel=1e-12)


# ------------------------------------------------------------------------------------------------
# bounds, decorrelation, continuity fits


def test_bounds_lie_above_the_fits(analysis):
    for a in (analysis.vertical, analysis.horizontal):
        assert a.notes == ()
        assert a.log10_p_mi_bound > a.log10_p_mi
        # integral time scales (parametric_analysis step 3): tau for the normal's sigma, 2 tau otherwise
        scale = 1.0 if a.axis == "vertical" else 2.0
        assert a.n_effective == pytest.approx(a.n_epochs * a.interval_s / (scale * a.decorrelation_s))
        assert a.pl_n_effective == pytest.approx(a.n_epochs * a.interval_s / (2.0 * a.pl_decorrelation_s))
        for s in a.services.values():
            if s is None:
                continue
            assert s.reason == ""
            assert s.log10_unavailability_bound > s.log10_unavailability_fit
            assert s.log10_p_hmi_bound > s.log10_p_hmi
            assert s.p_mi_pl_above_al == pytest.approx(s.unavailability_fit * a.p_mi, rel=1e-9)


def test_auto_decorrelation_finds_the_error_correlation_time():
    # errors: Gauss-Markov with 1/e time 120 s, so the vertical ratio VPE/VPL (sigma proportional to
    # VPL, no heavy-tail regime) has the same autocorrelation
    table = simulate(SimulationConfig(days=2.0, seed=2, tail_fraction=0.0, correlation_s=120.0)).table
    a = parametric_analysis(table, services=("APV-I",)).vertical
    assert a.decorrelation_s == pytest.approx(120.0, rel=0.15)
    assert a.acf_lags_s.size <= ACF_FIGURE_POINTS + 10
    assert a.ratio_acf[0] == a.pl_acf[0] == 1.0 and np.all(np.diff(a.acf_lags_s) > 0)
    for tau, acf in ((a.decorrelation_s, a.ratio_acf), (a.pl_decorrelation_s, a.pl_acf)):
        k = int(np.searchsorted(a.acf_lags_s, tau))  # the crossing is kept on the thinned arrays
        assert a.acf_lags_s[k] == tau and acf[k] < math.exp(-1) <= acf[k - 1]


def test_given_decorrelation_and_too_few_effective_samples(sim_table):
    a = parametric_analysis(sim_table, decorrelation=60, services=("APV-I",))
    v = a.vertical
    assert v.decorrelation_s == v.pl_decorrelation_s == 60.0 and not v.decorrelation_auto
    assert v.n_effective == pytest.approx(v.n_epochs / 60.0)
    assert parametric_dict(a)["decorrelation_rule"] == "given"
    short = parametric_analysis(sim_table, decorrelation="1e6", services=("APV-I",))
    for ax in (short.vertical, short.horizontal):
        assert ax.ratio_bound_fit is None and ax.p_mi_bound is None and ax.weibull_cov is None
        assert len(ax.notes) == 2 and "too few" in ax.notes[0]
        s = ax.services["APV-I"]
        assert s.p_hmi_bound is None and s.unavailability_bound is None and "too few" in s.reason
        assert s.p_hmi is not None and s.continuity_counted is not None


def test_bad_options_are_rejected(sim_table):
    for bad in ("often", -5.0, float("inf"), 0):
        with pytest.raises(ValueError, match="decorrelation"):
            parametric_analysis(sim_table, decorrelation=bad)
    with pytest.raises(ValueError, match="confidence"):
        parametric_analysis(sim_table, confidence=1.5)
    with pytest.raises(ValueError, match="given twice"):
        parametric_analysis(sim_table, services=("APV-I", "apv-i"))
    with pytest.raises(ValueError, match="unknown service"):
        parametric_analysis(sim_table, services=("nope",))


def test_continuity_fit_local_or_global(analysis):
    v = analysis.vertical
    curve, fit = v.continuity_curves[15.0], v.continuity_fits[15.0]
    assert curve.alert_limit.size >= 400 and fit is not None and fit.n_points >= 3
    s = v.services["APV-II"]  # VAL 20 m, inside the PL range: a local fit
    assert s.continuity_fit_source == "local"
    lf = s.continuity_local_fit
    assert lf.al_min >= s.alert_limit - 10.0 and lf.al_max <= s.alert_limit + 10.0
    assert s.continuity_fit == pytest.approx(10.0 ** (lf.a + lf.b * s.alert_limit), rel=1e-12)
    # a half day whose PL never comes near 900 m: the local window of FAR:900:900 is empty
    far_table = simulate(SimulationConfig(days=0.5, seed=9)).table
    far = parametric_analysis(far_table, services=("FAR:900:900",)).vertical
    fs = far.services["FAR"]
    assert fs.continuity_fit_source == "global" and fs.continuity_local_fit is None
    g = far.continuity_fits[15.0]
    assert fs.continuity_fit == pytest.approx(10.0 ** (g.a + g.b * 900.0), rel=1e-12)


# ------------------------------------------------------------------------------------------------
# axes that cannot be analysed


def test_missing_columns_give_a_null_axis_with_its_reason(sim_table):
    a = parametric_analysis(sim_table.drop("hpe", "hpl"), services=("APV-I",))
    assert a.horizontal is None and a.vertical is not None
    assert "hpe" in a.reasons["horizontal"] and "hpl" in a.reasons["horizontal"]
    doc = parametric_dict(a)
    assert doc["horizontal"] is None and doc["reasons"] == a.reasons
    with pytest.raises(InputError, match="station"):
        parametric_analysis(sim_table.drop("station"))


def test_too_few_epochs_give_null_axes():
    table = _table(np.arange(1.0, 10.0), np.full(9, 10.0), hpe=np.ones(9), hpl=np.full(9, 8.0))
    a = parametric_analysis(table)
    assert a.vertical is None and a.horizontal is None
    assert "at least 10" in a.reasons["vertical"] and "9 epochs" in a.reasons["horizontal"]
    assert json.loads(dumps(parametric_dict(a)))["vertical"] is None


def test_constant_pl_gives_a_reason_not_a_crash():
    n = 200
    table = _table(np.random.default_rng(1).normal(0, 1, n), np.full(n, 10.0))
    a = parametric_analysis(table, services=(parse_service("APV-I"),))
    assert a.vertical is None and "constant" in a.reasons["vertical"]
    assert a.horizontal is None and "hpe" in a.reasons["horizontal"]
