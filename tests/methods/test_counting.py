"""Counting KPIs: region boundaries, availability, continuity against a brute-force count."""

from __future__ import annotations

import datetime as dt

import numpy as np
import polars as pl
import pytest

from overbound.methods.counting import (
    Region,
    continuity_risk,
    count_kpis,
    safety_index,
    stanford_counts,
    stanford_histogram,
    stanford_regions,
)
from overbound.services import SERVICES, parse_service

AL = 40.0
# (PE, PL, region): every boundary of the Stanford diagram, both sides.
BOUNDARY_CASES = [
    (10.0, 10.0, Region.NORMAL),  # PE == PL is bounded
    (10.000001, 10.0, Region.MI),
    (40.0, 30.0, Region.MI),  # PE == AL is not hazardous
    (40.000001, 30.0, Region.HMI),
    (39.0, 40.0, Region.UNAVAILABLE),  # PL == AL is unavailable
    (40.0, 40.0, Region.UNAVAILABLE),
    (41.0, 40.0, Region.UNAVAILABLE_MI),
    (0.0, 39.999999, Region.NORMAL),
    (np.nan, 10.0, Region.NO_SOLUTION),
    (1.0, np.nan, Region.NO_SOLUTION),
]


@pytest.mark.parametrize(("pe", "pl_", "region"), BOUNDARY_CASES)
def test_region_boundaries(pe, pl_, region):
    assert stanford_regions(np.array([pe]), np.array([pl_]), AL)[0] == region


def test_region_enum_round_trip():
    for r in Region:
        assert Region.parse(r.key) is r
    with pytest.raises(ValueError, match="unknown Stanford region"):
        Region.parse("bogus")


def test_stanford_counts_partition_all_epochs():
    rng = np.random.default_rng(1)
    pe = np.abs(rng.normal(0, 15, 10_000))
    pl_ = rng.uniform(0, 80, 10_000)
    pe[::97] = np.nan
    c = stanford_counts(pe, pl_, AL)
    assert c.total == 10_000
    # independent count of each region
    ok = ~np.isnan(pe)
    assert c.no_solution == np.count_nonzero(~ok)
    assert c.hmi == np.count_nonzero(ok & (pl_ < AL) & (pe > AL))
    assert c.mi == np.count_nonzero(ok & (pl_ < AL) & (pe > pl_) & (pe <= AL))
    assert c.unavailable_mi == np.count_nonzero(ok & (pl_ >= AL) & (pe > pl_))
    assert c.unavailable == np.count_nonzero(ok & (pl_ >= AL) & (pe <= pl_))


def _brute_force_continuity(t_s, avail, window_s):
    """Kannemans 2.1.4 literally: for each available t, look at every grid time in (t, t+T]."""
    present = dict(zip(t_s.tolist(), avail.tolist(), strict=True))
    end = t_s.max()
    n = fail = gap = 0
    for t, a in present.items():
        if not a or t + window_s > end:
            continue
        n += 1
        slots = [t + k for k in range(1, window_s + 1)]
        if any(not present.get(s, False) for s in slots):
            fail += 1
        if any(s not in present for s in slots):
            gap += 1
    return n, fail, gap


@pytest.mark.parametrize("seed", range(5))
def test_continuity_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    t = np.arange(3000)
    keep = rng.random(3000) > 0.01  # ~1 % missing epochs (gaps)
    t = t[keep]
    avail = rng.random(t.size) > 0.005
    res = continuity_risk(t * 1_000_000, avail, window_s=15)
    n, fail, gap = _brute_force_continuity(t, avail, 15)
    assert (res.n_windows, res.n_fail, res.n_gap_windows) == (n, fail, gap)
    assert res.risk == pytest.approx(fail / n)


def test_continuity_single_outage_fails_exactly_window_starts():
    t = np.arange(100) * 1_000_000
    avail = np.ones(100, bool)
    avail[50] = False
    res = continuity_risk(t, avail, window_s=15)
    assert res.n_fail == 15  # starts 35..49
    assert res.n_windows == 84  # starts 0..84 except 50
    assert res.n_truncated == 15


def test_continuity_gap_counts_as_loss_of_service():
    t = np.delete(np.arange(100), [30]) * 1_000_000
    res = continuity_risk(t, np.ones(99, bool), window_s=15)
    assert res.n_fail == 15 and res.n_gap_windows == 15


def test_continuity_null_when_sampling_exceeds_exposure():
    t = np.arange(0, 4 * 3600, 30) * 1_000_000
    res = continuity_risk(t, np.ones(t.size, bool), window_s=15)
    assert res.risk is None
    assert "30 s exceeds the 15 s" in res.reason
    # but the one-hour NPA window is countable
    assert continuity_risk(t, np.ones(t.size, bool), window_s=3600).reason == ""


def test_safety_index_percentiles():
    pe = np.array([1.0, 2.0, 3.0, np.nan, 4.0])
    pl_ = np.array([10.0, 10.0, 10.0, 10.0, 2.0])
    si = safety_index(pe, pl_)
    assert si.n == 4
    assert si.max == 2.0
    assert si.percentiles["p50"] == pytest.approx(np.percentile([0.1, 0.2, 0.3, 2.0], 50))


def test_histogram_counts_every_solution_epoch_once():
    rng = np.random.default_rng(3)
    pe = np.abs(rng.normal(0, 20, 5000))
    pl_ = rng.uniform(0, 90, 5000)
    h = stanford_histogram(pe, pl_, axis="vertical", max_value=60.0, bins=60)
    assert h.counts.sum() == 5000
    assert h.clipped == np.count_nonzero((pe >= 60) | (pl_ >= 60))
    assert h.counts[0, 0] == np.count_nonzero((pe < 1) & (pl_ < 1))


def _table(hpe, vpe, hpl, vpl, seconds, station="S1"):
    t0 = dt.datetime(2024, 1, 7)
    return pl.DataFrame(
        {
            "time": [t0 + dt.timedelta(seconds=float(s)) for s in seconds],
            "station": [station] * len(seconds),
            "hpe": hpe,
            "vpe": vpe,
            "hpl": hpl,
            "vpl": vpl,
        }
    ).with_columns(pl.col("station").cast(pl.Categorical), pl.col("time").cast(pl.Datetime("us")))


def test_count_kpis_hand_checked():
    # 6 epochs at 1 Hz: one no-solution, one VPL over LPV-200's 35 m, one vertical MI.
    hpe = [1.0, 2.0, 1.0, np.nan, 1.0, 3.0]
    vpe = [-1.0, 2.0, -20.0, np.nan, 1.0, 12.0]
    hpl = [10.0, 10.0, 10.0, np.nan, 45.0, 10.0]
    vpl = [20.0, 20.0, 15.0, np.nan, 30.0, 36.0]
    res = count_kpis(_table(hpe, vpe, hpl, vpl, range(6)), [SERVICES["LPV-200"], SERVICES["NPA"]])
    k = res.services["LPV-200"]
    assert res.n_total == 6 and res.n_with_solution == 5
    assert k.horizontal.availability == pytest.approx(4 / 6)  # NaN and 45 m are unavailable
    assert k.vertical.availability == pytest.approx(4 / 6)  # NaN and 36 m
    assert k.combined.availability == pytest.approx(3 / 6)
    assert k.vertical.stanford.to_dict() == {
        "normal": 3,
        "mi": 1,
        "hmi": 0,
        "unavailable": 1,
        "unavailable_mi": 0,
        "no_solution": 1,
    }
    npa = res.services["NPA"]
    assert npa.vertical.availability is None
    assert npa.combined.availability == npa.horizontal.availability == pytest.approx(5 / 6)
    assert res.hpe95 == pytest.approx(np.percentile([1, 2, 1, 1, 3], 95))
    assert res.vpe95 == pytest.approx(np.percentile([1, 2, 20, 1, 12], 95))


def test_count_kpis_pools_continuity_over_stations():
    n = 200
    vpl = np.full(n, 10.0)
    vpl[100] = 60.0
    one = _table(np.ones(n), np.ones(n), np.full(n, 10.0), vpl, range(n), "A")
    two = _table(np.ones(n), np.ones(n), np.full(n, 10.0), np.full(n, 10.0), range(n), "B")
    both = pl.concat([one, two])
    res = count_kpis(both, [parse_service("X:40:50")])
    c = res.services["X"].vertical.continuity
    a = continuity_risk(np.arange(n) * 1_000_000, vpl < 50, window_s=15)
    b = continuity_risk(np.arange(n) * 1_000_000, np.ones(n, bool), window_s=15)
    assert c.n_windows == a.n_windows + b.n_windows
    assert c.n_fail == a.n_fail == 15
    assert res.stations == ("A", "B")


def test_counts_equal_bincount_of_regions():
    rng = np.random.default_rng(7)
    pe = np.abs(rng.normal(0, 20, 20_000))
    pl_ = rng.uniform(0, 80, 20_000)
    pe[::53] = np.nan
    pl_[::71] = np.nan
    pe[::89] = pl_[::89]  # ties PE == PL
    pl_[::97] = AL  # ties PL == AL
    codes = np.bincount(stanford_regions(pe, pl_, AL), minlength=len(Region))
    assert stanford_counts(pe, pl_, AL).to_dict() == {r.key: int(codes[r]) for r in Region}


def test_histogram_matches_histogram2d():
    rng = np.random.default_rng(11)
    pe = rng.normal(0, 15, 30_000)  # signed: the histogram takes |PE|
    pl_ = rng.uniform(0, 70, 30_000)
    pe[::41] = np.nan
    h = stanford_histogram(pe, pl_, axis="vertical", max_value=60.0, bins=50)
    ok = ~np.isnan(pe)
    ref, _, _ = np.histogram2d(
        np.minimum(np.abs(pe[ok]), 59.999), np.minimum(pl_[ok], 59.999), bins=50, range=[[0, 60], [0, 60]]
    )
    np.testing.assert_array_equal(h.counts, ref.astype(np.int64))


def test_grid_with_jitter_and_gaps():
    t = np.arange(0, 600) * 1_000_000 + np.tile([0, 30_000, -20_000], 200)  # +-30 ms jitter
    t = np.delete(t, [100, 101, 102])
    res = continuity_risk(t, np.ones(t.size, bool), window_s=15)
    assert res.interval_s == pytest.approx(1.0, abs=0.03) and res.n_off_grid == 0
    assert res.n_gap_windows == 15  # windows starting at slots 85..99 reach into the gap 100-102


def test_alerted_epochs_are_unavailable():
    n = 6
    table = _table([1.0] * n, [1.0] * n, [10.0] * n, [10.0] * n, range(n)).with_columns(
        pl.Series("alert", [False, True, False, False, None, False])
    )
    res = count_kpis(table, [SERVICES["LPV"]])
    k = res.services["LPV"]
    assert k.combined.availability == pytest.approx(5 / 6)
    assert k.vertical.stanford.unavailable == 1 and k.vertical.stanford.normal == 5
    assert res.safety["vertical"].n == 5
    assert table["hpl"][1] == 10.0  # the table itself is untouched


def test_continuity_risks_of_many_series_equal_each_alone():
    """The service-volume map's per-point continuity (one grid for every point) against the single count."""
    from overbound.methods.counting import continuity_risk, continuity_risks

    rng = np.random.default_rng(5)
    t = np.arange(0, 4000, dtype=np.int64) * 1_000_000
    t = np.delete(t, np.r_[100:130, 2000:2003])  # gaps
    t[500] += 400_000  # an epoch off the grid
    avail = rng.random((60, t.size)) > np.linspace(0.0, 0.3, 60)[:, None]
    avail[0] = True
    avail[1] = False
    for window in (15.0, 3600.0, 0.5):  # 0.5 s: the interval exceeds the window, no count
        many = continuity_risks(t, avail, window_s=window)
        assert len(many) == avail.shape[0]
        assert many == [continuity_risk(t, a, window_s=window) for a in avail]
    assert continuity_risks(t[:1], avail[:, :1], window_s=15.0)[0].reason == "fewer than two epochs"


def test_continuity_says_when_the_data_are_shorter_than_the_window():
    from overbound.methods.counting import continuity_risk

    t = np.arange(300, dtype=np.int64) * 1_000_000
    short = continuity_risk(t, np.ones(300, bool), window_s=3600.0)
    assert short.risk is None and short.n_truncated == 300
    assert "shorter than the 3600 s window" in short.reason
    none_up = continuity_risk(t, np.zeros(300, bool), window_s=15.0)
    assert none_up.risk is None and none_up.reason == "no window starts on an available epoch"
    last_up = np.zeros(300, bool)
    last_up[-5:] = True  # windows fit in the data, but only the last five epochs start one
    late = continuity_risk(t, last_up, window_s=15.0)
    assert (
        late.risk is None
        and late.n_truncated == 5
        and late.reason == "no window starts on an available epoch"
    )
