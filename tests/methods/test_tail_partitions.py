"""The EVT tail extrapolation by partition (issue 14): its reduced input gathered station-day by
station-day equals the pooled table's to the last bit, whatever the blocks' boundaries hold
(alerts and PL >= AL whose TTA reaches into the day before, a grid slot shared across midnight,
gaps, several stations), and the lagged sums of the ACF merge exactly in any order."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from overbound.analysis import analyze
from overbound.campaign_tail import campaign_tail_data
from overbound.io.dataset import ingest, partitions, read_dataset
from overbound.jsontext import dumps
from overbound.methods.tail_extrapolation import evt_dict, tail_analysis, tail_analysis_of, tail_filters
from overbound.methods.tail_partitions import table_tail_data
from overbound.services import SERVICES
from overbound.simulate import SimulationConfig, simulate
from overbound.stats.dependence import autocorrelation
from overbound.stats.lagged import acf_from_sums, fixed_point_bits, lagged_sums, merge_lagged

DAY_US = 86_400_000_000


def test_lagged_sums_merge_exactly_in_any_order_and_give_the_autocorrelation() -> None:
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(size=30_000)) * 0.01 + 0.3
    x[rng.random(x.size) < 0.05] = np.nan
    m = 400
    bits = fixed_point_bits(x.size, float(np.nanmax(np.abs(x))))
    cuts = [0, 5000, 5001, 12_000, 30_000]
    parts = [lagged_sums(x[a:b], m, bits, before=x[max(a - m, 0) : a]) for a, b in itertools.pairwise(cuts)]
    forward, backward = merge_lagged(*parts), merge_lagged(*parts[::-1])
    tree = merge_lagged(merge_lagged(parts[0], parts[3]), merge_lagged(parts[2], parts[1]))
    for a in (backward, tree):
        assert np.array_equal(forward.xx, a.xx) and np.array_equal(forward.ww, a.ww) and forward.sx == a.sx
    one = lagged_sums(x, m, bits)
    assert np.array_equal(one.ww, forward.ww) and one.sw == forward.sw  # every pair counted once
    ref = autocorrelation(x, max_lag=m)
    np.testing.assert_allclose(acf_from_sums(forward), ref, rtol=0, atol=1e-13)
    np.testing.assert_allclose(acf_from_sums(one), ref, rtol=0, atol=1e-13)


@pytest.mark.parametrize("seed", range(6))
def test_the_sums_with_missing_samples_from_their_runs_equal_the_fft_route(seed: int, monkeypatch) -> None:
    """Blocks with few runs of missing samples (gaps, alerts) take the prefix-sum route: the same
    pair counts exactly, and the same weighted sums to rounding, as three more FFT correlations."""
    from overbound.stats import lagged

    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(50, 5000)), int(rng.integers(1, 400))
    x = rng.random(n)
    x[rng.random(n) < [0.0, 0.01, 0.2, 0.9, 1.0, 0.05][seed]] = np.nan
    start = int(rng.integers(0, n))
    x[start : start + int(rng.integers(1, 1000))] = np.nan  # an outage
    before = rng.random(int(rng.integers(0, m + 1)))
    before[rng.random(before.size) < 0.3] = np.nan
    runs = lagged_sums(x, m, 40, before)
    monkeypatch.setattr(lagged, "RUNS_LIMIT", -1)
    fft = lagged_sums(x, m, 40, before)
    assert np.array_equal(runs.ww, fft.ww) and runs.sw == fft.sw and runs.sx == fft.sx
    assert np.max(np.abs(runs.xw - fft.xw)) < 1000 and np.max(np.abs(runs.wx - fft.wx)) < 1000  # 1e-9
    np.testing.assert_allclose(acf_from_sums(runs), acf_from_sums(fft), rtol=0, atol=1e-9)


def _network_table() -> pl.DataFrame:
    """Two stations, two days at 1 Hz, with the boundaries' hard cases: station A's last epoch of
    day 1 shares its grid slot with the first of day 2 (time-tag jitter), an alert burst and a
    VPL above the LPV alert limit in the first seconds of day 2 (their TTA reaches back into day 1),
    alerts and gaps elsewhere."""
    tables = []
    for i, name in enumerate(("A", "B")):
        t = simulate(SimulationConfig(days=2, seed=40 + i, gap_rate_per_day=4.0, gap_mean_s=300)).table
        t = t.with_columns(pl.lit(name).alias("station"), pl.lit(False).alias("alert"))
        tables.append(t)
    table = pl.concat(tables)
    time_us = table["time"].dt.epoch("us").to_numpy().copy()
    midnight = (int(time_us[0]) // DAY_US + 1) * DAY_US
    a = (table["station"] == "A").to_numpy()
    last_day1 = np.flatnonzero(a & (time_us < midnight))[-1]
    assert time_us[last_day1] == midnight - 1_000_000
    time_us[last_day1] += 700_000  # 23:59:59.7: the slot of 00:00:00
    alert = table["alert"].to_numpy().copy()
    vpl = table["vpl"].to_numpy().copy()
    after = (time_us - midnight) // 1_000_000
    alert[a & (after >= 3) & (after < 20)] = True  # its 6-10 s TTA reaches into day 1 for B? no: A
    b = ~a
    vpl[b & (after >= 4) & (after < 60)] = 70.0  # PL >= AL of every service at the start of B's day 2
    rng = np.random.default_rng(1)
    alert |= rng.random(alert.size) < 2e-4
    return table.with_columns(
        pl.Series("time", time_us).cast(pl.Datetime("us")), pl.Series("alert", alert), pl.Series("vpl", vpl)
    )


@pytest.fixture(scope="module")
def network(tmp_path_factory) -> tuple[pl.DataFrame, Path]:
    table = _network_table()
    root = tmp_path_factory.mktemp("tail")
    src = root / "network.parquet"
    table.write_parquet(src)
    ingest(root / "ds", [src])
    pooled, _ = read_dataset(root / "ds", columns=("alert",))
    return pooled, root / "ds"


def _same(a, b) -> None:
    da, db = evt_dict(a), evt_dict(b)
    for d in (da, db):
        d.pop("timings", None)
    assert dumps(da) == dumps(db)
    assert np.array_equal(a.dependence.acf, b.dependence.acf, equal_nan=True)
    assert np.array_equal(a.tail.clusters.peak_index, b.tail.clusters.peak_index)
    assert (a.krs.statistic, a.krs.n) == (b.krs.statistic, b.krs.n)
    assert np.array_equal(a.gev.block_maxima, b.gev.block_maxima)
    for name in a.services:
        assert a.services[name].counts == b.services[name].counts


@pytest.mark.parametrize("axis", ["vertical", "horizontal"])
def test_dataset_passes_equal_the_pooled_table(network, axis: str) -> None:
    table, ds = network
    assert len(partitions(ds)) == 4
    expected = tail_analysis(table, axis=axis, n_boot=50, rng=2)
    lpv = expected.services["LPV"].counts if axis == "vertical" else None
    if lpv is not None:  # the boundary cases are there
        assert lpv.n_pl_above_al > 0 and lpv.n_tta > 0 and expected.counts.n_alert > 0
    inputs = campaign_tail_data(partitions(ds), {axis: tail_filters(axis)})
    got = tail_analysis_of(inputs.data[axis], axis=axis, n_boot=50, rng=2)
    _same(expected, got)


def test_the_shared_slot_and_the_tta_across_midnight_are_those_of_the_pooled_grid(network) -> None:
    """The pooled table's series is the reference: the block reduction reproduces its regular-grid
    ACF (one slot holds the two epochs around midnight) and its TTA counts."""
    from overbound.methods.pooling import pool_epochs
    from overbound.stats.dependence import regular_series

    table, _ = network
    data = table_tail_data(table, "vertical", tail_filters("vertical"))
    d = pool_epochs(table, "vertical")
    keep = ~d.alert
    reg = regular_series(d.t_us[keep], d.pe[keep] / d.pl[keep], interval_s=d.interval_us / 1e6)
    assert reg.n_merged == 1
    ref = autocorrelation(reg.values, max_lag=data.acf.size - 1)
    np.testing.assert_allclose(data.acf, ref, rtol=0, atol=1e-12)
    assert data.counts == (int(d.alert.sum()), 0, 0, int(keep.sum()))


def test_analyze_dataset_runs_the_evt_by_partition(network, tmp_path: Path) -> None:
    """``analyze`` of the dataset without the confidence level and the parametric analysis reads no
    pooled table, and its EVT equals that of the same epochs as one table."""
    table, ds = network
    by_parts = analyze([ds], confidence=(), evt=None, evt_n_boot=30, cache=False)
    assert by_parts.table.is_empty() and len(by_parts.evt) == 2
    pooled = analyze(table, confidence=(), evt=None, evt_n_boot=30)
    for a, b in zip(pooled.evt, by_parts.evt, strict=True):
        _same(a, b)


def test_a_time_window_cuts_the_dataset_as_the_table(network) -> None:
    """--start/--end: the partitions cut at the window's edges give the EVT of the table filtered."""
    import datetime as dt

    table, ds = network
    day0 = table["time"].min().replace(hour=0, minute=0, second=0, microsecond=0)
    window = (day0 + dt.timedelta(hours=6, minutes=30), day0 + dt.timedelta(days=1, hours=12))
    cut = table.filter(pl.col("time") >= window[0], pl.col("time") < window[1])
    by_parts = analyze([ds], confidence=(), evt=None, evt_n_boot=30, cache=False, time_range=window)
    pooled = analyze(cut, confidence=(), evt=None, evt_n_boot=30)
    assert len(by_parts.evt) == len(pooled.evt) == 2
    for a, b in zip(pooled.evt, by_parts.evt, strict=True):
        _same(a, b)


def test_a_table_whose_first_epoch_has_no_solution_is_analysed(network) -> None:
    """The column check reads no epoch: a first row without a solution is just left out."""
    table, _ = network
    assert np.isfinite(table["vpe"][0]) and table["vpl"][0] > 0
    before = int(table.select((~pl.col("vpe").is_finite() | ~(pl.col("vpl") > 0)).sum()).item())
    first_nan = table.with_columns(
        pl.when(pl.int_range(pl.len()) == 0).then(float("nan")).otherwise(pl.col("vpe")).alias("vpe")
    )
    a = tail_analysis(first_nan, axis="vertical", n_boot=20, rng=2)
    assert a.counts.n_no_solution == before + 1 and a.counts.n_rows == table.height


def _random_network(seed: int) -> pl.DataFrame:
    """1-3 stations of 1-2 days at 1 or 5 s, starting at any second of the day, with jittered time
    tags, gaps, alert bursts, PLs above the alert limits or missing, and sometimes no horizontal."""
    rng = np.random.default_rng(seed)
    tables = []
    for i in range(int(rng.integers(1, 4))):
        cfg = SimulationConfig(
            days=int(rng.integers(1, 3)),
            interval_s=float(rng.choice([1.0, 5.0])),
            seed=seed * 10 + i,
            gap_rate_per_day=float(rng.uniform(0, 20)),
            gap_mean_s=float(rng.uniform(5, 3000)),
        )
        t = simulate(cfg).table
        tu = t["time"].dt.epoch("us").to_numpy() + int(rng.integers(0, 86_400)) * 1_000_000
        tu = tu + rng.integers(-200_000, 200_000, size=tu.size) * (rng.random(tu.size) < 0.01)
        tu = np.maximum.accumulate(tu)
        t = t.with_columns(pl.Series("time", tu).cast(pl.Datetime("us")))
        t = t.filter(pl.Series(np.concatenate([[True], np.diff(tu) > 0])))
        n = t.height
        alert = rng.random(n) < rng.choice([0.0, 1e-4, 1e-2])
        vpl, hpe = t["vpl"].to_numpy().copy(), t["hpe"].to_numpy().copy()
        for _ in range(int(rng.integers(0, 5))):
            s = int(rng.integers(0, n))
            alert[s : s + int(rng.integers(1, 400))] = True
            vpl[int(rng.integers(0, n)) :][: int(rng.integers(1, 200))] = rng.choice([45.0, 60.0, np.nan])
        if rng.random() < 0.2:
            hpe[:] = np.nan
        tables.append(
            t.with_columns(
                pl.lit(f"S{i}").alias("station"),
                pl.Series("alert", alert),
                pl.Series("vpl", vpl),
                pl.Series("hpe", hpe),
            )
        )
    return pl.concat(tables, how="diagonal_relaxed")


def _outcome(run) -> str:
    """The analysis's ``evt_dict`` JSON without timings, or the failure's text."""
    try:
        doc = evt_dict(run())
    except ValueError as exc:  # InputError too: no solution, too few tail values
        return f"failed: {exc}"
    doc.pop("timings", None)
    return dumps(doc)


@pytest.mark.parametrize("seed", [3, 5, 104])
def test_random_networks_give_the_same_evt_by_partition(seed: int, tmp_path: Path) -> None:
    src = tmp_path / "network.parquet"
    _random_network(seed).write_parquet(src)
    ingest(tmp_path / "ds", [src])
    table, _ = read_dataset(tmp_path / "ds", columns=("alert",))
    parts = partitions(tmp_path / "ds")
    for axis in ("vertical", "horizontal"):
        expected = _outcome(lambda axis=axis: tail_analysis(table, axis=axis, n_boot=20, rng=1))

        def by_parts(axis=axis):
            inputs = campaign_tail_data(parts, {axis: tail_filters(axis)})
            if axis not in inputs.data:
                raise ValueError(inputs.failed[axis])
            return tail_analysis_of(inputs.data[axis], axis=axis, n_boot=20, rng=1)

        got = _outcome(by_parts)
        assert got == expected


def _tta_counts(table: pl.DataFrame, axis: str, al: float, tta_s: float) -> tuple[int, int, int]:
    """An independent reference of section 3.6's filter per station: ``(n_above, n_tta, n_used)``
    of the solution epochs, the next alert (PL >= AL or flagged) found by ``searchsorted``."""
    pe_col, pl_col = ("vpe", "vpl") if axis == "vertical" else ("hpe", "hpl")
    above = tta = used = 0
    for _, st in table.group_by("station", maintain_order=True):
        st = st.sort("time")
        pe, pls = st[pe_col].to_numpy(), st[pl_col].to_numpy()
        ok = np.isfinite(pe) & np.isfinite(pls) & (pls > 0)
        t = st["time"].dt.epoch("us").to_numpy()[ok]
        alert, pls = st["alert"].to_numpy()[ok], pls[ok]
        is_alert = (pls >= al) | alert
        alert_times = t[is_alert]
        kept = ~alert & (pls < al)
        nxt = np.searchsorted(alert_times, t, side="right")
        ahead = np.where(
            nxt < alert_times.size, alert_times[np.minimum(nxt, alert_times.size - 1)] - t, 1 << 62
        )
        in_tta = kept & (ahead <= round(tta_s * 1e6))
        above += int(np.count_nonzero((pls >= al) & ~alert))
        tta += int(in_tta.sum())
        used += int((kept & ~in_tta).sum())
    return above, tta, used


def test_the_hmi_filters_equal_an_independent_reference_across_midnight(network) -> None:
    """Every epoch within the TTA before an alert is dropped, the alert in the next day included."""
    table, _ = network
    data = table_tail_data(table, "vertical", tail_filters("vertical"))
    names = [s.name for s in SERVICES.values() if s.alert_limit("vertical")]
    for name, (_, _, counts) in zip(names, data.services, strict=True):
        s = SERVICES[name]
        assert counts[1:] == _tta_counts(table, "vertical", s.alert_limit("vertical"), s.tta_s), name
    lpv = dict(zip(names, data.services, strict=True))["LPV"][2]
    assert lpv[2] >= 2  # 23:59:58 and 23:59:59 before the PL above the AL at 00:00:04 (TTA 6 s)


def test_a_service_keeping_epochs_the_filtering_service_drops_is_fitted_on_its_own_epochs(network) -> None:
    """tail_analysis(service=LPV-200, services=(APV-I,)): APV-I's HMI fit sees every epoch APV-I
    keeps, not only those LPV-200 keeps (its exceedances of the threshold, counted independently)."""
    table, _ = network
    a = tail_analysis(table, axis="vertical", service="LPV-200", services=("APV-I",), n_boot=20, rng=1)
    s = SERVICES["APV-I"]
    hmi = a.services["APV-I"]
    assert (hmi.counts.n_pl_above_al, hmi.counts.n_tta, hmi.counts.n_used) == _tta_counts(
        table, "vertical", s.alert_limit("vertical"), s.tta_s
    )
    from overbound.methods.tail_extrapolation import analysed_series

    _, si = analysed_series(table, axis="vertical", service="APV-I")
    assert hmi.tail.n_exceedances == int(np.count_nonzero(si > hmi.tail.threshold))


def test_short_first_days_an_empty_grid_and_a_window_in_the_last_hour(tmp_path: Path) -> None:
    """A station whose first day holds only its last 30 minutes (a block shorter than the ACF's
    lags, with no day before), another whose first day is one epoch at 23:59:59.7 sharing its slot
    with the next day's first (an empty grid), and a window opening at 23:30: the dataset equals
    the table."""
    import datetime as dt

    a = simulate(SimulationConfig(days=2, seed=7)).table.with_columns(pl.lit("A").alias("station"))
    day0 = a["time"].min()
    a = a.filter(pl.col("time") >= day0 + dt.timedelta(hours=23, minutes=30))
    b = simulate(SimulationConfig(days=1, seed=8)).table.with_columns(
        pl.lit("B").alias("station"), pl.col("time") + dt.timedelta(days=1)
    )
    lone = b.head(1).with_columns(pl.col("time") - dt.timedelta(milliseconds=300))
    table = pl.concat([a, lone, b]).with_columns(pl.lit(False).alias("alert"))
    src = tmp_path / "t.parquet"
    table.write_parquet(src)
    ingest(tmp_path / "ds", [src])
    pooled, _ = read_dataset(tmp_path / "ds", columns=("alert",))
    assert len(partitions(tmp_path / "ds")) == 4
    for window in (None, (day0 + dt.timedelta(hours=23, minutes=30, seconds=20), None)):
        cut = pooled if window is None else pooled.filter(pl.col("time") >= window[0])
        by_parts = analyze(
            [tmp_path / "ds"], confidence=(), evt=None, evt_n_boot=20, cache=False, time_range=window
        )
        one = analyze(cut, confidence=(), evt=None, evt_n_boot=20)
        assert len(one.evt) == len(by_parts.evt) == 2 and one.evt_failures == by_parts.evt_failures == ()
        for x, y in zip(one.evt, by_parts.evt, strict=True):
            _same(x, y)


def test_the_station_order_does_not_depend_on_live_categoricals(network) -> None:
    """Stations are placed on the pooled axis in the order of their first row, whatever
    Categorical of their names the process holds (polars' codes are process-wide)."""
    table, _ = network
    before = tail_analysis(table, axis="vertical", n_boot=20, rng=1)
    held = pl.Series(["B", "A"]).cast(pl.Categorical)
    after = tail_analysis(table, axis="vertical", n_boot=20, rng=1)
    assert held.len() == 2
    _same(before, after)


@pytest.mark.parametrize("axis", ["vertical", "horizontal"])
def test_candidate_positions_index_each_series_of_the_pooled_table(network, axis: str) -> None:
    """The candidates' positions (kept per station-day as int32 with the days' offsets) point at
    the same epochs in the main series and in each service's, as the pooled table's own series."""
    from overbound.methods.tail_extrapolation import analysed_series

    table, ds = network
    filters = tail_filters(axis)
    data = campaign_tail_data(partitions(ds), {axis: filters}).data[axis]
    t_main, si_main = analysed_series(table, axis=axis)
    assert data.position.dtype == np.int64 and data.main.sum() > 10
    assert np.array_equal(si_main[data.position], data.x[data.main])
    assert np.array_equal(t_main[data.position], data.t_s[data.main])
    names = [n for n, s in SERVICES.items() if s.alert_limit(axis) is not None]
    assert len(data.services) == len(names) > 1
    for name, (keep, positions, counts) in zip(names, data.services, strict=True):
        t_s, si = analysed_series(table, axis=axis, service=name)
        assert counts[3] == si.size and keep.sum() > 0
        assert np.array_equal(si[positions], data.x[keep]) and np.array_equal(t_s[positions], data.t_s[keep])
