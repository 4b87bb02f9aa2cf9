"""Tests of the campaign simulator: determinism, error model, exact truth, missing data, files."""

from __future__ import annotations

import datetime as dt
import json
import math

import numpy as np
import polars as pl
import pytest
from scipy import integrate, special, stats

import overbound.simulate as simmod
from overbound.io.schema import validate_epochs
from overbound.simulate import (
    BandAnomaly,
    BiasAnomaly,
    OutageAnomaly,
    SimulationConfig,
    p_exceed,
    parse_anomaly,
    read_simulation,
    simulate,
    write_simulation,
)

# Clean error model: no tail regime, no missing data.
CLEAN = dict(tail_fraction=0.0, gap_rate_per_day=0.0, outage_rate_per_day=0.0)


def _count_bound(p: np.ndarray, phi: float) -> float:
    """Upper bound of the sd of a count of exceedances of a stationary Gaussian AR(1).

    By Lancaster's theorem the correlation of any two functions of a bivariate normal
    pair is at most |rho|, so Var(sum 1[MI]) <= sum p(1-p) * (1 + phi) / (1 - phi).
    """
    return math.sqrt(float(np.sum(p * (1 - p))) * (1 + phi) / (1 - phi))


# --------------------------------------------------------------------------- determinism


def test_same_seed_same_bytes_different_seed_differs(tmp_path):
    cfg = SimulationConfig(days=0.5, seed=7, anomalies=("band:15:16:3", "bias:1:600:2:v:60", "outage:2:300"))
    a, b = simulate(cfg), simulate(cfg)
    assert a.table.equals(b.table)
    pa, pb = write_simulation(a, tmp_path / "a.parquet"), write_simulation(b, tmp_path / "b.parquet")
    assert pa.read_bytes() == pb.read_bytes()
    c = simulate(SimulationConfig(days=0.5, seed=8, anomalies=cfg.anomalies))
    assert not np.allclose(a.table["vpl"].to_numpy()[:1000], c.table["vpl"].to_numpy()[:1000], equal_nan=True)
    assert not np.allclose(a.table["vpe"].to_numpy()[:1000], c.table["vpe"].to_numpy()[:1000], equal_nan=True)


def test_longer_campaign_extends_shorter_one():
    one = simulate(SimulationConfig(days=1, seed=3, gap_rate_per_day=20, outage_rate_per_day=20)).table
    two = simulate(SimulationConfig(days=2, seed=3, gap_rate_per_day=20, outage_rate_per_day=20)).table
    head = two.filter(pl.col("time") < dt.datetime(2024, 1, 8))
    assert head.equals(one)
    assert two.height > 1.9 * one.height


def test_chunking_does_not_change_the_output(monkeypatch):
    cfg = SimulationConfig(
        days=0.1, seed=11, tail_fraction=0.2, tail_dwell_s=30, anomalies=("bias:0.5:900:3:h:100",)
    )
    ref = simulate(cfg).table
    monkeypatch.setattr(simmod, "_CHUNK", 997)
    assert simulate(cfg).table.equals(ref)


# --------------------------------------------------------------------------- error model


def test_ar1_autocorrelation_at_correlation_time_is_exp_minus_one():
    tau = 30.0
    t = simulate(SimulationConfig(days=2, seed=5, correlation_s=tau, **CLEAN)).table
    phi = math.exp(-1 / tau)
    n = t.height
    k = int(tau)
    # Bartlett variance of the lag-k sample autocorrelation of an AR(1)
    se = math.sqrt(((1 + phi**2) * (1 - phi ** (2 * k)) / (1 - phi**2) - 2 * k * phi ** (2 * k)) / n)
    for err, sig in (("vpe", "sigma_v_true"), ("east", "sigma_h_true"), ("north", "sigma_h_true")):
        z = (t[err] / t[sig]).to_numpy()
        z = z - z.mean()
        r1 = np.dot(z[:-1], z[1:]) / np.dot(z, z)
        rk = np.dot(z[:-k], z[k:]) / np.dot(z, z)
        assert abs(rk - math.exp(-1)) < 4 * se, (err, rk)
        assert abs(r1 - phi) < 0.002, (err, r1)


def test_normalised_errors_are_standard_normal():
    t = simulate(SimulationConfig(days=1, seed=2, correlation_s=5.0, **CLEAN)).table
    thin = t.gather_every(25)  # 5 correlation times apart: nearly independent
    for err, sig in (("vpe", "sigma_v_true"), ("east", "sigma_h_true"), ("north", "sigma_h_true")):
        z = (thin[err] / thin[sig]).to_numpy()
        assert stats.kstest(z, "norm").pvalue > 1e-3, err
        assert abs(z.mean()) < 4 / math.sqrt(z.size)
        assert abs(z.var() - 1) < 5 * math.sqrt(2 / z.size)
    assert np.allclose(t["hpe"], np.hypot(t["east"], t["north"]), rtol=0, atol=1e-12)


def test_regime_column_gives_the_conditional_sigma():
    cfg = SimulationConfig(
        days=1,
        seed=4,
        correlation_s=5.0,
        tail_fraction=0.2,
        tail_scale=3.0,
        tail_dwell_s=60,
        gap_rate_per_day=0,
        outage_rate_per_day=0,
    )
    t = simulate(cfg).table.gather_every(25)
    z_core = (t["vpe"] / t["sigma_v_true"]).to_numpy()
    assert stats.kstest(z_core, "norm").pvalue < 1e-6  # the mixture is not N(0, 1)
    z = z_core / 3.0 ** t["regime"].to_numpy()
    assert stats.kstest(z, "norm").pvalue > 1e-3
    assert abs(t["regime"].mean() - 0.2) < 0.06


@pytest.mark.parametrize(("f", "days"), [(1.5, 4.0), (2.0, 2.0)])
def test_empirical_mi_frequency_matches_truth(f, days):
    t = simulate(SimulationConfig(days=days, seed=1, sigma_ratio=f, correlation_s=1.0, **CLEAN))
    tab = t.table
    p_v = 2 * special.ndtr(-5.33 / f)
    p_h = math.exp(-(6.0**2) / (2 * f * f))
    assert np.allclose(tab["p_mi_v_true"], p_v, rtol=1e-12)
    assert np.allclose(tab["p_mi_h_true"], p_h, rtol=1e-12)
    assert t.p_mi_true("vertical") == pytest.approx(p_v, rel=1e-12)
    phi = math.exp(-1.0)
    for err, plc, col in (("vpe", "vpl", "p_mi_v_true"), ("hpe", "hpl", "p_mi_h_true")):
        count = int((tab[err].abs() > tab[plc]).sum())
        p = tab[col].to_numpy()
        assert abs(count - p.sum()) < 4 * _count_bound(p, phi), (err, count, p.sum())


def test_empirical_mi_with_tail_regime_matches_mixture_truth():
    eps, c, f = 0.1, 2.0, 1.2
    sim = simulate(
        SimulationConfig(
            days=3,
            seed=9,
            sigma_ratio=f,
            correlation_s=1.0,
            tail_fraction=eps,
            tail_scale=c,
            tail_dwell_s=20.0,
            gap_rate_per_day=0,
            outage_rate_per_day=0,
        )
    )
    tab = sim.table
    u = 5.33 / f
    mix = (1 - eps) * 2 * special.ndtr(-u) + eps * 2 * special.ndtr(-u / c)
    assert sim.p_mi_true("v") == pytest.approx(mix, rel=1e-12)
    reg = tab["regime"].to_numpy()
    p_cond = np.where(reg == 1, 2 * special.ndtr(-u / c), 2 * special.ndtr(-u))
    count = int((tab["vpe"].abs() > tab["vpl"]).sum())
    assert abs(count - p_cond.sum()) < 4 * _count_bound(p_cond, math.exp(-1.0))
    assert count / tab.height == pytest.approx(mix, rel=0.2)  # regime share noise: ~1300 tail episodes


def test_band_anomaly_raises_only_its_band():
    sim = simulate(
        SimulationConfig(
            days=2, seed=6, sigma_ratio=1.0, correlation_s=2.0, anomalies=(BandAnomaly(15, 16, 3.0),), **CLEAN
        )
    )
    tab = sim.table
    nominal, raised = 2 * special.ndtr(-5.33), 2 * special.ndtr(-5.33 / 3)
    assert sim.p_mi_true_band("v", 15, 16) == pytest.approx(raised, rel=1e-12)
    assert sim.p_mi_true_band("v", 10, 15) == pytest.approx(nominal, rel=1e-12)
    assert sim.p_mi_true_band("v", 16, 1000) == pytest.approx(nominal, rel=1e-12)
    assert sim.p_mi_true_band("h", 0, 1000) == pytest.approx(math.exp(-18), rel=1e-12)
    in_band = (tab["vpl"] >= 15) & (tab["vpl"] < 16)
    ratio = (tab["sigma_v_true"] * 5.33 / tab["vpl"]).to_numpy()
    assert np.allclose(ratio[in_band.to_numpy()], 3.0) and np.allclose(ratio[~in_band.to_numpy()], 1.0)
    mi = tab["vpe"].abs() > tab["vpl"]
    band = tab.filter(in_band)
    assert band.height > 5000
    count = int(mi.filter(in_band).sum())
    expected = raised * band.height
    # within-band epochs come in runs, so the AR(1) bound applies to the subsequence
    assert abs(count - expected) < 4 * _count_bound(np.full(band.height, raised), math.exp(-0.5))
    assert int(mi.filter(~in_band).sum()) <= 1  # expected 0.017
    assert sim.p_mi_true("v") > 100 * nominal


def test_horizontal_band_anomaly():
    sim = simulate(SimulationConfig(days=0.5, seed=6, sigma_ratio=1.0, anomalies=("band:8:9:4:h",), **CLEAN))
    assert sim.p_mi_true_band("h", 8, 9) == pytest.approx(math.exp(-18 / 16), rel=1e-12)
    assert sim.p_mi_true_band("h", 9, 100) == pytest.approx(math.exp(-18), rel=1e-12)
    assert sim.p_mi_true_band("v", 0, 1000) == pytest.approx(2 * special.ndtr(-5.33), rel=1e-12)


# --------------------------------------------------------------------------- truth formulas


@pytest.mark.parametrize(("limit", "bias"), [(3.0, 0.0), (3.0, 2.0), (4.0, 3.5), (2.0, -1.0)])
def test_exceedance_formulas_against_monte_carlo(limit, bias):
    rng = np.random.default_rng(123)
    n = 2_000_000
    e, nn = rng.standard_normal(n), rng.standard_normal(n) + bias
    for axis, hit in (("h", np.hypot(e, nn) > limit), ("v", np.abs(nn) > limit)):
        p = float(p_exceed(axis, limit, 1.0, bias=bias))
        assert abs(hit.mean() - p) < 5 * math.sqrt(p * (1 - p) / n) + 1e-7, (axis, hit.mean(), p)


def test_exceedance_formulas_far_tail_and_limits():
    assert float(p_exceed("v", 30, 1)) == pytest.approx(2 * stats.norm.sf(30), rel=1e-12)
    assert float(p_exceed("v", 30, 1)) > 0
    assert float(p_exceed("h", 37, 1)) == pytest.approx(math.exp(-684.5), rel=1e-12)
    # a tiny bias takes the ncx2 branch, which must meet the Rayleigh value
    assert float(p_exceed("h", 10, 1, bias=1e-8)) == pytest.approx(math.exp(-50), rel=1e-6)
    assert float(p_exceed("v", 5, 2, bias=1)) == pytest.approx(stats.norm.sf(2) + stats.norm.sf(3), rel=1e-12)
    mix = float(p_exceed("v", 5.33, 1, tail_fraction=0.01, tail_scale=3))
    assert mix == pytest.approx(
        0.99 * 2 * stats.norm.sf(5.33) + 0.01 * 2 * stats.norm.sf(5.33 / 3), rel=1e-12
    )
    with pytest.raises(ValueError, match="axis"):
        p_exceed("z", 1, 1)


def test_horizontal_bias_truth_against_simulation():
    sim = simulate(
        SimulationConfig(
            days=1, seed=8, sigma_ratio=2.0, correlation_s=1.0, anomalies=("bias:0:86400:3:h",), **CLEAN
        )
    )
    tab = sim.table
    assert (tab["bias_h_true"] == 3.0).all() and (tab["bias_v_true"] == 0.0).all()
    s, hpl = tab["sigma_h_true"].to_numpy(), tab["hpl"].to_numpy()
    assert np.allclose(tab["p_mi_h_true"], stats.ncx2.sf((hpl / s) ** 2, 2, (3.0 / s) ** 2), rtol=1e-10)
    assert sim.p_mi_true("h") > 1.5 * math.exp(-4.5)  # the bias raises the unbiased Rayleigh value
    p = tab["p_mi_h_true"].to_numpy()
    count = int((tab["hpe"] > tab["hpl"]).sum())
    assert abs(count - p.sum()) < 4 * _count_bound(p, math.exp(-1.0))


def test_bias_shape_step_and_ramp():
    t = np.array([3599.0, 3600.0, 3630.0, 3660.0, 4000.0, 4170.0, 4199.0, 4200.0])
    assert np.array_equal(BiasAnomaly(1, 600, 2.0).value(t), [0, 2, 2, 2, 2, 2, 2, 0])
    ramp = BiasAnomaly(1, 600, 2.0, ramp_s=60).value(t)
    assert np.allclose(ramp, [0, 0, 1, 2, 2, 1, 2 / 60, 0])


def test_p_hmi_true_against_numerical_integration():
    eps, c = 0.05, 2.0
    sim = simulate(
        SimulationConfig(
            days=0.02,
            seed=12,
            sigma_ratio=1.0,
            tail_fraction=eps,
            tail_scale=c,
            gap_rate_per_day=0,
            outage_rate_per_day=0,
            anomalies=("bias:0:1728:1.5:v", "bias:0:1728:1:h"),
        )
    )
    tab = sim.table
    for axis, plc, sc, bc in (
        ("vertical", "vpl", "sigma_v_true", "bias_v_true"),
        ("horizontal", "hpl", "sigma_h_true", "bias_h_true"),
    ):
        al = round(float(tab[plc].quantile(0.7)), 1)  # an alert limit that some PLs exceed
        sub = tab.filter(pl.col(plc) < al)
        assert 0.5 * tab.height < sub.height < 0.9 * tab.height
        s, b = sub[sc].to_numpy()[:, None], sub[bc].to_numpy()[:, None]
        total = np.zeros(sub.height)
        for w, scale in ((1 - eps, 1.0), (eps, c)):
            ss = s * scale
            x = al + np.linspace(0.0, 40.0, 2001)[None, :] * ss  # to 40 sigma beyond AL
            if axis == "vertical":
                dens = stats.norm.pdf(x, b, ss) + stats.norm.pdf(-x, b, ss)
            else:  # Rice density of the radius, i0e for stability
                dens = x / ss**2 * np.exp(-((x - b) ** 2) / (2 * ss**2)) * special.i0e(x * b / ss**2)
            total += w * integrate.simpson(dens, x=x, axis=1)
        expected = total.mean()
        assert sim.p_hmi_true(axis, al) == pytest.approx(expected, rel=1e-6)
        joint = sim.p_hmi_true(axis, al, conditional=False)
        assert joint == pytest.approx(expected * sub.height / tab.height, rel=1e-6)
    assert math.isnan(sim.p_hmi_true("vertical", 1.0))  # no epoch with VPL < 1 m
    assert sim.p_hmi_true("vertical", 1.0, conditional=False) == 0.0


# --------------------------------------------------------------------------- PLs


def test_protection_levels_are_realistic():
    sim = simulate(SimulationConfig(days=7, seed=0))
    tab = sim.table.filter(pl.col("vpl").is_not_nan())
    v, h = tab["vpl"].to_numpy(), tab["hpl"].to_numpy()
    assert v.min() > 0 and h.min() > 0
    assert 11 < np.median(v) < 17
    assert 0.003 < np.mean(v > 50) < 0.05  # a few per mille to per cent unavailable for APV-I
    assert np.mean(h > 40) < np.mean(v > 50)
    assert np.mean(h > 556) == 0  # NPA
    assert stats.skew(v) > 1 and stats.skew(np.log(v)) > 0  # right skewed beyond log-normal
    assert set(tab["nsv"].unique().to_list()) <= set(range(6, 13))
    # nsv falls when the PL rises (geometry), ionosphere peaks in the afternoon
    assert np.corrcoef(tab["nsv"].to_numpy(), np.log(v))[0, 1] < -0.5
    hour = tab["time"].dt.hour()
    assert (
        tab.filter(hour.is_between(13, 15))["vpl"].median()
        > 1.3 * tab.filter(hour.is_between(1, 3))["vpl"].median()
    )
    for st in sim.stations:
        for geo, sd in ((st.geometry_v, 0.25), (st.geometry_h, 0.1)):
            assert sum(a * a / 2 for _, a, _ in geo) == pytest.approx(sd**2, rel=1e-12)
            assert [p for p, _, _ in geo] == pytest.approx([86164.09 / j for j in range(1, 7)])


# --------------------------------------------------------------------------- missing data


def _covered(intervals, n: int) -> np.ndarray:
    k = np.arange(n, dtype=float)
    m = np.zeros(n, dtype=bool)
    for s, e in intervals:
        m |= (k >= s) & (k < e)
    return m


def test_gaps_are_missing_rows_and_outages_nan_rows():
    days, rate, gmean, omean = 2.0, 24.0, 300.0, 200.0
    cfg = SimulationConfig(
        days=days,
        seed=21,
        gap_rate_per_day=rate,
        gap_mean_s=gmean,
        outage_rate_per_day=rate,
        outage_mean_s=omean,
        anomalies=(OutageAnomaly(30, 1800),),
    )
    sim = simulate(cfg)
    tab, st = sim.table, sim.stations[0]
    n = cfg.n_epochs
    k = ((tab["time"] - dt.datetime(2024, 1, 7)).dt.total_microseconds() // 1_000_000).to_numpy()
    gap = _covered(st.gaps, n)
    out = _covered(st.outages, n)
    assert np.array_equal(k, np.flatnonzero(~gap))
    nan_rows = tab["vpl"].is_nan().to_numpy()
    assert np.array_equal(nan_rows, out[k])
    assert (30 * 3600.0, 30 * 3600.0 + 1800) in st.outages
    forced = (k >= 108000) & (k < 109800)
    assert nan_rows[forced].all() and forced.sum() + gap[108000:109800].sum() == 1800
    # compound Poisson totals: mean rate*days*mean, sd sqrt(rate*days*2)*mean
    random_outages = [iv for iv in st.outages if iv != (108000.0, 109800.0)]
    for ivs, mean in ((st.gaps, gmean), (random_outages, omean)):
        total = sum(e - s for s, e in ivs)
        assert abs(total - rate * days * mean) < 4 * math.sqrt(rate * days * 2) * mean
    solution_cols = [
        "hpe",
        "vpe",
        "hpl",
        "vpl",
        "east",
        "north",
        "sigma_v_true",
        "sigma_h_true",
        "p_mi_v_true",
        "p_mi_h_true",
    ]
    bad = tab.filter(pl.col("vpl").is_nan())
    assert all(bad[c].is_nan().all() for c in solution_cols)
    assert bad["nsv"].null_count() == bad.height and bad["mode"].null_count() == bad.height
    good = tab.filter(pl.col("vpl").is_not_nan())
    assert not any(good[c].is_nan().any() for c in solution_cols)
    assert good["mode"].cast(pl.String).unique().to_list() == ["PA"]
    assert sim.p_mi_true("v") == pytest.approx(good["p_mi_v_true"].mean(), rel=1e-12)
    validate_epochs(tab)


# --------------------------------------------------------------------------- stations and files


def test_multi_station_independent_and_named():
    sim = simulate(SimulationConfig(days=0.2, seed=5, stations=3))
    names = sim.table["station"].cast(pl.String).unique(maintain_order=True).to_list()
    assert names == ["SIM01", "SIM02", "SIM03"] == [s.name for s in sim.stations]
    assert [s.spawn_key for s in sim.stations] == [(0,), (1,), (2,)]
    v = [sim.table.filter(pl.col("station") == s)["vpl"].head(100).to_numpy() for s in names]
    assert not np.allclose(v[0], v[1]) and not np.allclose(v[1], v[2])
    validate_epochs(sim.table)
    per = [sim.p_mi_true("v", station=s) for s in names]
    assert all(p > 0 for p in per)
    again = simulate(SimulationConfig(days=0.2, seed=5, stations=3))
    assert again.table.equals(sim.table)


def test_write_and_read_back(tmp_path):
    sim = simulate(SimulationConfig(days=0.1, seed=2, anomalies=("band:15:16:3",)))
    path = write_simulation(sim, tmp_path / "sim.parquet")
    meta = json.loads(pl.read_parquet_metadata(path)["overbound"])["extra"]["simulation"]
    assert meta["config"]["anomalies"] == ["band:15:16:3:v"]
    assert meta["p_mi_v_true"] == pytest.approx(sim.p_mi_true("v"), rel=1e-15)
    assert meta["n_rows"] == sim.table.height
    back = read_simulation(path)
    assert back.table.equals(sim.table) and back.config == sim.config and back.stations == sim.stations
    csv = write_simulation(sim, tmp_path / "sim.csv")
    assert pl.read_csv(csv).height == sim.table.height
    assert json.loads((tmp_path / "sim.csv.json").read_text())["config"]["seed"] == 2
    with pytest.raises(ValueError, match="suffix"):
        write_simulation(sim, tmp_path / "sim.txt")
    with pytest.raises(ValueError, match="metadata"):
        pl.DataFrame({"a": [1]}).write_parquet(tmp_path / "plain.parquet")
        read_simulation(tmp_path / "plain.parquet")


# --------------------------------------------------------------------------- specs and config


@pytest.mark.parametrize(
    ("spec", "expected", "canonical"),
    [
        ("band:15:16:3", BandAnomaly(15, 16, 3), "band:15:16:3:v"),
        ("BAND:7.5:9.25:0.5:h", BandAnomaly(7.5, 9.25, 0.5, "horizontal"), "band:7.5:9.25:0.5:h"),
        ("bias:2:600:4.5", BiasAnomaly(2, 600, 4.5), "bias:2:600:4.5:v"),
        ("bias:0.5:600:-3:vertical:120", BiasAnomaly(0.5, 600, -3, "v", 120), "bias:0.5:600:-3:v:120"),
        ("outage:12:1800", OutageAnomaly(12, 1800), "outage:12:1800"),
    ],
)
def test_parse_anomaly_round_trip(spec, expected, canonical):
    a = parse_anomaly(spec)
    assert a == expected
    assert str(a) == a.spec == canonical
    assert parse_anomaly(str(a)) == a


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("bnd:15:16:3", "unknown kind 'bnd'"),
        ("band:15:16", r"expected band:LO:HI:FACTOR\[:AXIS\], got 2 field"),
        ("band:15:16:3:v:9", "got 5 field"),
        ("band:16:15:3", "LO < HI"),
        ("band:15:16:x", "FACTOR must be a number, got 'x'"),
        ("band:15:16:0", "FACTOR must be > 0"),
        ("band:15:16:2:z", "AXIS must be v or h"),
        ("bias:1:0:3", "DURATION_S must be > 0"),
        ("bias:1:100:3:v:60", "RAMP_S"),
        ("bias:-1:100:3", "START_H must be >= 0"),
        ("outage:1", "expected outage:START_H:DURATION_S"),
        ("outage:1:nan", "DURATION_S must be > 0"),
        ("", "unknown kind"),
    ],
)
def test_parse_anomaly_errors(spec, message):
    with pytest.raises(ValueError, match=message) as info:
        parse_anomaly(spec)
    assert repr(spec) in str(info.value)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"days": 0}, "days must be > 0"),
        ({"interval_s": 1e-7}, "whole number of microseconds"),
        ({"tail_fraction": 1.5}, "tail_fraction"),
        ({"sigma_ratio": -1}, "sigma_ratio must be > 0"),
        ({"seed": -1}, "seed >= 0"),
        ({"stations": 0}, "stations >= 1"),
        ({"tail_axis": "up"}, "tail_axis"),
        ({"anomalies": ("band:1:2",)}, "band:1:2"),
        ({"start": "2024-01-07"}, "naive datetime"),
        ({"correlation_s": math.inf}, "finite"),
    ],
)
def test_config_validation(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SimulationConfig(**kwargs)


def test_config_normalises_and_round_trips():
    cfg = SimulationConfig(tail_axis="v", anomalies=["band:15:16:3", BiasAnomaly(1, 60, 2)])
    assert cfg.tail_axis == "vertical"
    assert cfg.anomalies == (BandAnomaly(15, 16, 3), BiasAnomaly(1, 60, 2))
    assert SimulationConfig.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg
    assert SimulationConfig(days=1, interval_s=0.5).n_epochs == 172800


def test_vertical_tail_axis_leaves_horizontal_nominal():
    sim = simulate(
        SimulationConfig(days=0.2, seed=1, sigma_ratio=1.0, tail_fraction=0.1, tail_axis="vertical")
    )
    assert sim.p_mi_true("h") == pytest.approx(math.exp(-18), rel=1e-12)
    assert sim.p_mi_true("v") == pytest.approx(
        0.9 * 2 * special.ndtr(-5.33) + 0.1 * 2 * special.ndtr(-5.33 / 3), rel=1e-12
    )
    d = sim.truth_dict()
    assert d["mixture"]["horizontal"] == {"tail_fraction": 0.0, "tail_scale": 1.0}
    assert d["p_hmi_true_given_available"]["NPA"]["vertical"] is None
