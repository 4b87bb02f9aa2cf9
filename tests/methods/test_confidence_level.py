"""The PL confidence-level procedure of Comby et al. (2003): selection, widening, statistics, simulation."""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
import polars as pl
import pytest

from overbound.io.schema import InputError, validate_epochs
from overbound.methods.confidence_level import MIN_COMPUTABLE, confidence_analysis
from overbound.simulate import SimulationConfig, simulate
from overbound.stats.confidence import confidence_level, ideal_pl, pl_at_confidence
from overbound.stats.dependence import select_spaced
from overbound.stats.overbounding import sigma_inflation

START = dt.datetime(2024, 1, 7)


def _table(time_s, pls, err, *, station="A", east=None, north=None, alert=None) -> pl.DataFrame:
    """A vertical (and, with east/north, horizontal) epoch table from plain arrays."""
    time_s = np.asarray(time_s, dtype=float)
    err = np.asarray(err, dtype=float)
    cols = {
        "time": [START + dt.timedelta(seconds=float(s)) for s in time_s],
        "station": [station] * time_s.size,
        "hpe": np.abs(err) if east is None else np.hypot(east, north),
        "vpe": err,
        "hpl": np.asarray(pls, dtype=float),
        "vpl": np.asarray(pls, dtype=float),
    }
    if east is not None:
        cols["east"], cols["north"] = np.asarray(east, float), np.asarray(north, float)
    if alert is not None:
        cols["alert"] = alert
    return validate_epochs(pl.DataFrame(cols).with_columns(pl.col("time").cast(pl.Datetime("us"))))


def _seconds(epochs: tuple[str, ...]) -> np.ndarray:
    t = np.array(epochs, dtype="datetime64[ms]")
    return (t - np.datetime64(START, "ms")).astype(np.int64) / 1e3


# --------------------------------------------------------------------------- bands and targets


def test_targets_start_at_the_lowest_pl_and_bands_are_half_open():
    # PLs 10.0 and 10.125 (exactly a band edge: 10 + 1/8 is a binary fraction), 10.3, 10.5, 10.7
    levels = np.array([10.0, 10.125, 10.3, 10.5, 10.7])
    pls = np.tile(levels, 40)
    err = np.random.default_rng(0).normal(0, 0.5, pls.size)
    a = confidence_analysis(
        _table(np.arange(pls.size) * 60.0, pls, err),
        spacing=0.0,
        min_samples=1,
        max_tolerance=0.125,
        max_pl=10.75,
    )
    assert a.pl_min == 10.0
    assert [b.target for b in a.bins] == [10.0, 10.25, 10.5, 10.75]  # max_pl inclusive
    assert [(b.lo, b.hi) for b in a.bins] == [
        (9.875, 10.125),
        (10.125, 10.375),
        (10.375, 10.625),
        (10.625, 10.875),
    ]
    # 10.125 is in the second band only: the un-widened bands partition the PLs
    assert [b.n_candidates for b in a.bins] == [40, 80, 40, 40]
    assert sum(b.n for b in a.bins) == pls.size
    assert all(b.tolerance_used == 0.125 for b in a.bins)


def test_no_target_above_max_pl_and_empty_bands_are_kept():
    pls = np.r_[np.full(30, 12.0), np.full(30, 13.0)]
    a = confidence_analysis(
        _table(np.arange(60) * 400.0, pls, np.linspace(-1, 1, 60)),
        min_samples=10,
        max_pl=13.1,
        max_tolerance=0.125,
    )
    assert [b.target for b in a.bins] == [12.0, 12.25, 12.5, 12.75, 13.0]
    empty = a.bins[1]
    assert (empty.n, empty.n_candidates, empty.sufficient, empty.suspect, empty.epochs) == (
        0,
        0,
        False,
        False,
        (),
    )
    assert all(math.isnan(getattr(empty, f)) for f in ("mean", "confidence", "max_abs_error", "max_ratio"))


# --------------------------------------------------------------------------- sample selection


def test_samples_are_spaced_contain_the_largest_error_and_are_as_many_as_possible():
    rng = np.random.default_rng(3)
    n = 20_000
    t = np.cumsum(rng.choice([1.0, 1.0, 1.0, 30.0], n))  # 1 Hz with gaps
    pls = rng.uniform(15.8, 16.2, n)
    err = rng.normal(0, 1.0, n)
    err[12_345] = -9.0  # the largest |error|; its PL is in some band
    a = confidence_analysis(_table(t, pls, err), min_samples=5, max_tolerance=0.125, max_pl=16.5)
    assert len(a.bins) >= 2
    for b, s in zip(a.bins, a.samples, strict=True):
        secs = _seconds(b.epochs)
        assert np.all(np.diff(secs) >= 360.0)
        assert list(b.epochs) == sorted(b.epochs)
        in_band = (pls >= b.lo) & (pls < b.hi)
        assert b.n_candidates == int(in_band.sum())
        worst = np.flatnonzero(in_band)[np.argmax(np.abs(err[in_band]))]
        assert worst in s.rows  # the epoch with the largest |VPE| of the band
        assert b.max_abs_error == np.abs(err[in_band]).max()
        assert b.max_ratio == pytest.approx(np.max(np.abs(err[s.rows]) / pls[s.rows]))
        # maximal: the greedy count from that anchor, which select_spaced proves optimal
        idx = np.flatnonzero(in_band)
        expect = select_spaced(t[idx], anchor=int(np.argmax(np.abs(err[idx]))), spacing=360.0).size
        assert b.n == expect
    assert 12_345 in np.concatenate([s.rows for s in a.samples])


def test_widening_reports_the_band_used():
    # 6 epochs at PL 20.0 and 14 at PL 20.2 (inside +-0.25 but not +-0.125), all 400 s apart
    pls = np.r_[np.full(6, 20.0), np.full(14, 20.2)]
    t = np.arange(20) * 400.0
    err = np.linspace(-2, 2, 20)
    a = confidence_analysis(_table(t, pls, err), min_samples=12, max_pl=20.0, max_tolerance=0.5)
    (b,) = a.bins
    assert (b.tolerance_used, b.lo, b.hi) == (0.25, 19.75, 20.25)
    assert (b.n, b.n_candidates, b.sufficient) == (20, 20, True)
    assert math.isfinite(b.confidence)


def test_insufficient_bins_are_kept_flagged_without_a_confidence_level():
    pls = np.r_[np.full(6, 20.0), np.full(14, 20.2)]
    err = np.linspace(-2, 2, 20)
    a = confidence_analysis(
        _table(np.arange(20) * 400.0, pls, err), min_samples=100, max_pl=20.0, max_tolerance=0.5
    )
    (b,) = a.bins
    assert (b.tolerance_used, b.lo, b.hi, b.n, b.sufficient, b.suspect) == (0.5, 19.5, 20.5, 20, False, False)
    assert math.isnan(b.confidence) and math.isnan(b.pl_1) and math.isnan(b.pl_99)
    inf = sigma_inflation(err)  # descriptive statistics are still there
    assert (b.mean, b.sigma, b.sigma_inflated) == pytest.approx((inf.mean, inf.sigma, inf.sigma_inflated))
    assert b.pl_ideal == pytest.approx(ideal_pl(mean=inf.mean, sigma=inf.sigma_inflated))


def test_fewer_than_three_samples_give_no_statistics():
    a = confidence_analysis(_table([0.0, 400.0], [20.0, 20.0], [0.1, -0.3]), min_samples=1, max_pl=20.0)
    (b,) = a.bins
    assert b.n == 2 < MIN_COMPUTABLE
    assert b.sufficient and not b.suspect and math.isnan(b.sigma_inflated) and math.isnan(b.confidence)
    assert b.max_abs_error == 0.3


def test_no_solution_alert_and_zero_pl_epochs_are_ignored():
    n = 600
    t = np.arange(n) * 400.0
    pls = np.full(n, 18.0)
    err = np.random.default_rng(5).normal(0, 1, n)
    pls[:10] = np.nan  # no solution
    err[10:20] = np.nan
    pls[20:25] = 0.0  # a zero PL bounds nothing (and the model needs PL > 0)
    alert = np.zeros(n, dtype=bool)
    alert[25:40] = True
    a = confidence_analysis(_table(t, pls, err, alert=alert), max_pl=18.0)
    assert a.n_epochs == n - 40
    (b,) = a.bins
    assert b.n == b.n_candidates == n - 40
    assert a.pl_min == 18.0


# --------------------------------------------------------------------------- statistics


def test_bin_statistics_are_those_of_the_stats_functions():
    rng = np.random.default_rng(11)
    n = 300
    pls = rng.uniform(11.9, 12.1, n)
    err = 0.3 + rng.normal(0, 1.5, n)
    a = confidence_analysis(_table(np.arange(n) * 400.0, pls, err), max_pl=12.0, max_tolerance=0.125)
    (b,) = a.bins
    s = a.samples[0]
    inf = sigma_inflation(err[s.rows])
    assert (b.mean, b.sigma, b.sigma_inflated) == (inf.mean, inf.sigma, inf.sigma_inflated)
    model = {"mean": inf.mean, "sigma": inf.sigma_inflated, "n": b.n}
    assert b.confidence == confidence_level(pls[s.rows], **model)
    assert b.pl_1 == pl_at_confidence(0.01, **model)
    assert b.pl_99 == pl_at_confidence(0.99, **model)
    assert b.pl_1 < b.pl_ideal < b.pl_99
    assert s.inflations == (inf,) and s.components == ("vpe",)


def test_horizontal_overbounds_east_and_north_separately():
    rng = np.random.default_rng(12)
    n = 300
    pls = np.full(n, 9.0)
    east, north = 0.2 + rng.normal(0, 0.8, n), -0.1 + rng.normal(0, 1.2, n)
    table = _table(np.arange(n) * 400.0, pls, np.zeros(n), east=east, north=north)
    a = confidence_analysis(table, axis="horizontal", max_pl=9.0)
    (b,) = a.bins
    ie, i_n = sigma_inflation(east), sigma_inflation(north)
    assert b.mean == math.hypot(ie.mean, i_n.mean)
    assert b.sigma_inflated == max(ie.sigma_inflated, i_n.sigma_inflated)
    assert b.sigma == max(ie.sigma, i_n.sigma)
    assert b.max_abs_error == pytest.approx(np.hypot(east, north).max())
    assert b.confidence == confidence_level(pls, mean=b.mean, sigma=b.sigma_inflated, n=n, axis="horizontal")
    assert a.samples[0].components == ("east", "north")
    assert a.samples[0].binding == int(i_n.sigma_inflated > ie.sigma_inflated)


def test_horizontal_needs_signed_east_and_north():
    table = _table(np.arange(10) * 400.0, np.full(10, 9.0), np.zeros(10))
    with pytest.raises(InputError, match="signed east and north errors"):
        confidence_analysis(table, axis="horizontal")
    with pytest.raises(InputError, match="vpl"):
        confidence_analysis(table.drop("vpl"))


def test_several_stations_share_one_time_axis():
    n = 7200  # two stations, the same two hours at 1 Hz, same PL
    t = np.arange(n, dtype=float)
    err = np.random.default_rng(2).normal(0, 1, 2 * n)
    both = pl.concat(
        [_table(t, np.full(n, 12.0), err[:n], station="A"), _table(t, np.full(n, 12.0), err[n:], station="B")]
    )
    a = confidence_analysis(both, min_samples=5, max_pl=12.0)
    (b,) = a.bins
    assert a.stations == ("A", "B") and a.n_epochs == 2 * n
    assert b.n == 20  # 7200 s / 360 s, not 40: simultaneous epochs of two stations are not independent
    assert np.all(np.diff(_seconds(b.epochs)) >= 360)
    worst = int(np.argmax(np.abs(err)))
    assert worst in a.samples[0].rows
    assert a.samples[0].station[a.samples[0].rows == worst][0] == (worst >= n)
    only_b = confidence_analysis(both, min_samples=5, max_pl=12.0, station="B")
    assert only_b.n_epochs == n and set(only_b.samples[0].station.tolist()) == {1}
    with pytest.raises(ValueError, match="station 'C'"):
        confidence_analysis(both, station="C")


def test_no_epochs_gives_no_bins():
    table = _table([0.0, 1.0], [np.nan, np.nan], [np.nan, np.nan])
    a = confidence_analysis(table)
    assert a.bins == () and a.n_epochs == 0 and math.isnan(a.pl_min) and a.worst is None


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"axis": "up"}, "axis"),
        ({"min_samples": 0}, "min_samples"),
        ({"spacing": -1.0}, "spacing"),
        ({"tolerance": 0.0}, "tolerance"),
        ({"step": 0.0}, "step"),
        ({"max_tolerance": 0.1}, "max_tolerance"),
        ({"risk": 1.0}, "risk"),
        ({"core": 0.0}, "core"),
        ({"max_pl": math.nan}, "max_pl"),
    ],
)
def test_parameter_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        confidence_analysis(_table([0.0], [10.0], [0.0]), **kwargs)


# --------------------------------------------------------------------------- simulated campaigns

# The simulator's heavy-tail regime multiplies the error sigma by 3 (0.4 x 3 = 1.2 PL/K: the PL then
# really fails), so the healthy campaigns switch it off: every band but the anomalous one is overbounded.
_HEALTHY = {"days": 6, "sigma_ratio": 0.4, "tail_fraction": 0.0}


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_gh3_enac_anomaly_gets_a_low_confidence_level_and_healthy_bands_a_high_one(seed):
    """The ENAC case of Comby et al. (2003) figure 6: errors x3 where the VPL is in [15, 16) m."""
    sim = simulate(SimulationConfig(seed=seed, anomalies=("band:15:16:3",), **_HEALTHY))
    a = confidence_analysis(sim.table)
    sufficient = [b for b in a.bins if b.sufficient]
    inside = [b for b in sufficient if 15.0 <= b.target < 16.0]
    touching = [b for b in sufficient if b.lo < 16.0 and b.hi > 15.0]
    healthy = [b for b in sufficient if b.hi <= 15.0 or b.lo >= 16.0]
    assert len(healthy) >= 10 and inside
    assert all(b.confidence < 0.01 and b.suspect for b in inside)
    assert all(b.confidence > 0.99 and not b.suspect for b in healthy)
    assert {a.bins[i].target for i in a.suspect} <= {b.target for b in touching}
    worst = a.bins[a.worst]
    assert worst.lo < 16.0 and worst.hi > 15.0 and worst.pl_1 > worst.hi  # fig. 8: the VPLs lie below VPL1


def test_horizontal_band_anomaly_on_simulated_east_north():
    sim = simulate(SimulationConfig(seed=1, anomalies=("band:8:9:3:h",), **_HEALTHY))
    a = confidence_analysis(sim.table, axis="horizontal")
    sufficient = [b for b in a.bins if b.sufficient]
    inside = [b for b in sufficient if 8.0 <= b.target < 9.0]
    healthy = [b for b in sufficient if b.hi <= 8.0 or b.lo >= 9.0]
    assert len(healthy) >= 10 and inside
    assert all(b.confidence < 0.01 for b in inside)
    assert all(b.confidence > 0.99 for b in healthy)
