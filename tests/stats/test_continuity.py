"""Non-continuity against the alert limit: equal to the one-AL count at every AL, events, bound, fit."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.stats

from overbound.methods.counting import continuity_risk
from overbound.stats.continuity import (
    ContinuityCurve,
    _rank,
    alert_limit_grid,
    clopper_pearson_upper,
    fit_loglinear,
    noncontinuity_curve,
    pool_curves,
    station_grid,
)
from overbound.stats.dependence import regular_series


def _station(rng: np.random.Generator, n: int, interval_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A station with time-tag jitter, gaps of every length, NaN PLs and a wandering PL (m)."""
    dt = round(interval_s * 1e6)
    t = np.arange(n, dtype=np.int64) * dt + rng.integers(-dt // 20, dt // 20, n)
    keep = np.ones(n, dtype=bool)
    for start in rng.integers(0, n - 40, 6):
        keep[start : start + rng.integers(1, 30)] = False
    pl = 15.0 + np.cumsum(rng.normal(0.0, 0.6, n)) + rng.normal(0.0, 1.0, n)
    pl[rng.random(n) < 0.01] = np.nan
    pl[rng.random(n) < 0.01] += 30.0  # lone spikes
    return t[keep], np.abs(pl[keep])


def _brute(t: np.ndarray, pl: np.ndarray, al: float, w: int) -> tuple[int, int, int]:
    """Windows, failures and loss events at one AL by an explicit loop over the grid slots."""
    grid = regular_series(t, pl)  # same slot rule, no duplicates here
    up = grid.values < al  # NaN (gap, no solution) is never available
    n = n_fail = events = 0
    previous_failed = False  # the last window's state: slots starting no window do not break a run
    for k in range(up.size - w):
        if not up[k]:
            continue
        fail = not up[k + 1 : k + w + 1].all()
        n += 1
        n_fail += fail
        events += fail and not previous_failed
        previous_failed = fail
    return n, n_fail, events


@pytest.mark.parametrize(("interval_s", "window_s"), [(1.0, 15.0), (5.0, 15.0), (1.0, 60.0), (2.0, 4.0)])
def test_counts_equal_continuity_risk_at_every_alert_limit(interval_s, window_s):
    rng = np.random.default_rng(7)
    t, pl = _station(rng, 3000, interval_s)
    al = alert_limit_grid(pl, extra=(20.0, 35.0), n=80)
    curve = noncontinuity_curve(t, pl, al, window_s=window_s)
    assert np.any(curve.n_fail > 0) and np.any(curve.n_fail < curve.n_windows)
    for j, a in enumerate(al):
        ref = continuity_risk(t, pl < a, window_s=window_s)
        assert (curve.n_windows[j], curve.n_fail[j]) == (ref.n_windows, ref.n_fail), a


def test_unavailable_mask_counts_as_loss_of_service():
    rng = np.random.default_rng(3)
    t, pl = _station(rng, 2000)
    alert = rng.random(t.size) < 0.005
    al = alert_limit_grid(pl, n=40)
    curve = noncontinuity_curve(t, pl, al, unavailable=alert)
    for j, a in enumerate(al):
        ref = continuity_risk(t, (pl < a) & ~alert, window_s=15.0)
        assert (curve.n_windows[j], curve.n_fail[j]) == (ref.n_windows, ref.n_fail)
    assert np.all(curve.n_windows <= noncontinuity_curve(t, pl, al).n_windows)


def test_events_against_brute_force_loop():
    rng = np.random.default_rng(11)
    t, pl = _station(rng, 1200)
    al = alert_limit_grid(pl, n=25)
    curve = noncontinuity_curve(t, pl, al)
    assert np.any(curve.n_events > 1)
    for j, a in enumerate(al):
        assert (curve.n_windows[j], curve.n_fail[j], curve.n_events[j]) == _brute(t, pl, a, 15)


def test_isolated_excursion_has_factor_equal_to_the_run_length():
    t = np.arange(1000, dtype=np.int64) * 1_000_000
    pl = np.full(1000, 10.0)
    pl[500] = 30.0
    curve = noncontinuity_curve(t, pl, np.array([5.0, 20.0, 30.0, 40.0]))
    assert curve.n_windows.tolist() == [0, 984, 984, 985]  # 1000 - 15 starts; PL 30 starts at AL 40
    assert curve.n_fail.tolist() == [0, 15, 15, 0]
    assert curve.n_events.tolist() == [0, 1, 1, 0]
    assert curve.decorrelation_factor.tolist() == [15.0, 15.0, 15.0, 15.0]
    # an excursion of three epochs still fails 15 windows (485..499); one back 5 s later fails 4 more
    # (501..504): a run across the unavailable start slots, one event
    pl[500:503] = 30.0
    assert noncontinuity_curve(t, pl, np.array([20.0])).n_fail[0] == 15
    pl[501:505] = 10.0
    pl[505] = 30.0
    longer = noncontinuity_curve(t, pl, np.array([20.0]))
    assert (longer.n_fail[0], longer.n_events[0], longer.decorrelation_factor[0]) == (19, 1, 19.0)
    apart = pl.copy()
    apart[505], apart[600] = 10.0, 30.0  # two isolated excursions: two events
    c = noncontinuity_curve(t, apart, np.array([20.0]))
    assert (c.n_fail[0], c.n_events[0], c.decorrelation_factor[0]) == (30, 2, 15.0)


def test_gap_is_a_loss_event():
    t = np.delete(np.arange(600, dtype=np.int64) * 1_000_000, [300, 301])
    curve = noncontinuity_curve(t, np.full(t.size, 10.0), np.array([20.0]))
    assert (curve.n_fail[0], curve.n_events[0]) == (15, 1)  # starts 285..299 see the 2-slot gap


def test_risk_and_bound_follow_the_counts():
    rng = np.random.default_rng(5)
    t, pl = _station(rng, 5000)
    c = noncontinuity_curve(t, pl, alert_limit_grid(pl, n=50), confidence=0.9)
    ok = c.n_windows > 0
    assert np.allclose(c.risk[ok], c.n_fail[ok] / c.n_windows[ok])
    assert np.all(np.isnan(c.risk[~ok])) and np.all(np.isnan(c.risk_bound[~ok]))
    n_eff = c.n_windows / c.decorrelation_factor
    inner = ok & (c.n_events < n_eff)
    ref = scipy.stats.beta.ppf(0.9, c.n_events[inner] + 1, (n_eff - c.n_events)[inner])
    assert np.allclose(c.risk_bound[inner], ref, rtol=1e-12)
    assert np.all(c.risk_bound[ok] >= c.risk[ok])
    with pytest.raises(ValueError, match="read-only"):
        c.risk[0] = 0.0


@pytest.mark.parametrize("confidence", [0.5, 0.95, 0.999])
def test_clopper_pearson_defining_property(confidence):
    k = np.array([0, 1, 5, 40, 99])
    n = np.array([100, 100, 100, 100, 100])
    p_u = clopper_pearson_upper(k, n, confidence)
    # the upper limit is the p at which seeing k or fewer events has probability 1 - c
    assert np.allclose(scipy.stats.binom.cdf(k, n, p_u), 1.0 - confidence, rtol=1e-9)
    assert p_u[0] == pytest.approx(1.0 - (1.0 - confidence) ** (1.0 / 100), rel=1e-12)
    edge = clopper_pearson_upper(np.array([3, 3, 0]), np.array([3.0, 0.0, 2.5]), confidence)
    assert edge[0] == 1.0 and np.isnan(edge[1])
    assert edge[2] == pytest.approx(scipy.stats.beta.ppf(confidence, 1, 2.5), rel=1e-12)


def test_pool_curves_sums_stations():
    rng = np.random.default_rng(2)
    stations = [_station(rng, 1500) for _ in range(3)]
    al = alert_limit_grid(np.concatenate([p for _, p in stations]), n=30)
    curves = [noncontinuity_curve(t, p, al) for t, p in stations]
    pooled = pool_curves(curves)
    for j, a in enumerate(al):
        refs = [continuity_risk(t, p < a, window_s=15.0) for t, p in stations]
        assert pooled.n_windows[j] == sum(r.n_windows for r in refs)
        assert pooled.n_fail[j] == sum(r.n_fail for r in refs)
    assert np.array_equal(pooled.n_events, sum(c.n_events for c in curves))
    with pytest.raises(ValueError, match="alert-limit grids"):
        pool_curves([curves[0], noncontinuity_curve(*stations[0], al[:-1])])
    with pytest.raises(ValueError, match="windows or confidence"):
        pool_curves([curves[0], noncontinuity_curve(*stations[0], al, window_s=30.0)])
    with pytest.raises(ValueError, match="at least one"):
        pool_curves([])


def test_shared_station_grid_gives_the_same_curve():
    rng = np.random.default_rng(4)
    t, pl = _station(rng, 2000)
    al = alert_limit_grid(pl, n=60)
    g = station_grid(t)
    assert g.interval_s == pytest.approx(1.0, abs=1e-3) and g.n_epochs == t.size
    for window in (15.0, 120.0):
        a = noncontinuity_curve(t, pl, al, window_s=window)
        b = noncontinuity_curve(None, pl, al, window_s=window, grid=g)
        assert all(
            np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True)
            for f in ContinuityCurve.__slots__
            if f not in ("window_s", "confidence")
        )
    with pytest.raises(ValueError, match="one value per epoch"):
        noncontinuity_curve(None, pl[:-1], al, grid=g)
    with pytest.raises(ValueError, match="needs time_us"):
        noncontinuity_curve(None, pl, al)


def test_too_short_or_too_coarse_gives_no_window():
    al = np.array([10.0, 20.0])
    one = noncontinuity_curve(np.array([0]), np.array([5.0]), al)
    coarse = noncontinuity_curve(np.arange(10) * 30_000_000, np.full(10, 5.0), al)  # 30 s > 15 s
    short = noncontinuity_curve(np.arange(10) * 1_000_000, np.full(10, 5.0), al)  # 10 s < 15 s + 1
    for c in (one, coarse, short):
        assert c.n_windows.tolist() == [0, 0] and np.all(np.isnan(c.risk))


def test_bad_input_is_rejected():
    t, pl, al = np.arange(5) * 1_000_000, np.ones(5), np.array([1.0, 2.0])
    with pytest.raises(ValueError, match="strictly increasing"):
        noncontinuity_curve(t, pl, np.array([2.0, 1.0]))
    with pytest.raises(ValueError, match="finite"):
        noncontinuity_curve(t, pl, np.array([1.0, np.inf]))
    with pytest.raises(ValueError, match="sorted"):
        noncontinuity_curve(t[::-1], pl, al)
    with pytest.raises(ValueError, match="one value per epoch"):
        noncontinuity_curve(t, pl[:3], al)
    with pytest.raises(ValueError, match="integer microseconds"):
        noncontinuity_curve(t.astype(float), pl, al)
    with pytest.raises(ValueError, match="confidence"):
        noncontinuity_curve(t, pl, al, confidence=1.0)
    with pytest.raises(ValueError, match="window_s"):
        noncontinuity_curve(t, pl, al, window_s=0.0)
    with pytest.raises(ValueError, match="unavailable"):
        noncontinuity_curve(t, pl, al, unavailable=np.zeros(3, bool))


def test_rank_equals_searchsorted():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.lognormal(2.6, 0.6, 20_000), [0.0, -1.0, np.inf]])
    grids = [
        np.linspace(3.0, 60.0, 400),
        np.union1d(np.linspace(3.0, 60.0, 400), [12.0, 12.0 + 1e-9, 50.0]),  # crowded buckets
        np.sort(rng.uniform(0.0, 100.0, 37)),
        np.array([14.0]),
    ]
    for al in grids:
        xs = np.concatenate([x, al, np.nextafter(al, -np.inf), np.nextafter(al, np.inf)])
        assert np.array_equal(_rank(al, xs), np.searchsorted(al, xs, side="right"))


def test_alert_limit_grid():
    pl = np.array([12.0, np.nan, 30.0, 18.0, np.inf])
    g = alert_limit_grid(pl, extra=(20.0, 12.0, 40.0, 5.0), n=400)
    assert g[0] == 12.0 and g[-1] == 30.0 and 20.0 in g
    assert g.size == 401 and np.all(np.diff(g) > 0)  # 12 already on the grid, 40 and 5 outside
    assert alert_limit_grid(np.array([7.0, 7.0])).tolist() == [7.0]
    assert alert_limit_grid(np.array([np.nan])).size == 0


def test_loglinear_fit_recovers_exact_line():
    al = np.linspace(10.0, 60.0, 26)
    risk = 10.0 ** (-2.133 - 0.012 * al)
    risk[[3, 7]] = 0.0  # zero risk cannot be fitted in log: left out
    risk[5] = np.nan
    f = fit_loglinear(al, risk)
    assert f.a == pytest.approx(-2.133, abs=1e-12) and f.b == pytest.approx(-0.012, abs=1e-13)
    assert (f.n_points, f.al_min, f.al_max) == (23, 10.0, 60.0)
    assert f.risk(50.0) == pytest.approx(10.0 ** (-2.133 - 0.6), rel=1e-12)
    assert fit_loglinear(al[:3], np.array([1e-3, 0.0, 1e-4])) is None
    assert fit_loglinear(np.full(4, 20.0), np.full(4, 1e-3)) is None


@pytest.mark.parametrize("seed", range(6))
def test_window_counter_fed_in_runs_equals_one_station(seed):
    """The counts of a station fed a run of slots at a time (station-days: gaps between them, a
    slot shared by two runs, runs shorter than a window) equal noncontinuity_curve of all its epochs."""
    from overbound.stats.continuity import WindowCounter, availability_ranks

    rng = np.random.default_rng(seed)
    n = int(rng.integers(200, 3000))
    t = np.cumsum(rng.choice([1, 1, 1, 1, 2, 7], size=n)).astype(np.int64) * 1_000_000
    t[rng.random(n) < 0.02] += 200_000  # jitter: some epochs off their slot, a few share one
    t = np.sort(t)
    pl = rng.gamma(4.0, 5.0, size=n)
    pl[rng.random(n) < 0.03] = np.nan
    alert = rng.random(n) < 0.01
    al = np.linspace(5.0, 40.0, 37)
    for window_s in (3.0, 15.0):
        whole = noncontinuity_curve(t, pl, al, window_s=window_s, unavailable=alert)
        g = station_grid(t)._grid
        w = max(1, round(window_s / g.interval_s))
        counter = WindowCounter(al.size, w)
        ranks = availability_ranks(al, pl, alert)
        cuts = np.sort(rng.choice(np.arange(1, n), size=int(rng.integers(1, 12)), replace=False))
        runs = np.split(np.arange(n), cuts)
        for i, run in enumerate(runs):
            k = g.index[run]
            dense = np.full(int(k[-1] - k[0]) + 1, al.size, dtype=counter.dtype)
            dense[k - k[0]] = ranks[run]
            counter.feed(int(k[0]), dense, last=i == len(runs) - 1)
        got = counter.counts()
        assert np.array_equal(got[0], whole.n_windows)
        assert np.array_equal(got[1], whole.n_fail)
        assert np.array_equal(got[2], whole.n_events)
        assert whole.n_fail.sum() > 0


def test_window_counter_refuses_slots_out_of_order():
    from overbound.stats.continuity import WindowCounter

    c = WindowCounter(4, 3)
    c.feed(10, np.zeros(8, dtype=np.int16))
    with pytest.raises(ValueError, match="in order"):
        c.feed(12, np.zeros(2, dtype=np.int16))


def test_window_counter_keeps_a_long_gap_as_one_window_of_missing_slots():
    """Two runs a year of slots apart: the counts of the whole station, with the counter holding
    a few slots, not the gap."""
    from overbound.stats.continuity import WindowCounter, availability_ranks

    rng = np.random.default_rng(3)
    al = np.linspace(5.0, 30.0, 26)
    runs = [np.arange(0, 500), np.arange(31_536_000, 31_536_700)]
    t = np.concatenate(runs).astype(np.int64) * 1_000_000
    pl = rng.gamma(4.0, 4.0, size=t.size)
    whole = noncontinuity_curve(t, pl, al, window_s=15.0)
    counter = WindowCounter(al.size, 15)
    ranks = availability_ranks(al, pl)
    counter.feed(0, ranks[:500])
    counter.feed(31_536_000, ranks[500:])
    assert counter._pending.size == 15 + 1  # the slots of the windows not yet counted, not the gap
    counter.finish()
    for got, want in zip(counter.counts(), (whole.n_windows, whole.n_fail, whole.n_events), strict=True):
        assert np.array_equal(got, want)
    assert whole.n_fail.max() > 0
