"""The counting KPIs merged from station-day partitions equal count_kpis of the pooled table."""

from __future__ import annotations

import dataclasses
import datetime as dt

import numpy as np
import polars as pl
import pytest

from overbound.methods.counting import count_kpis
from overbound.methods.counting_partitions import (
    bounds_from_second,
    count_partitioned,
    daily_availability,
    evidence_draft,
    evidence_partitioned,
    merge_second,
    plan_second,
    second_pass,
)
from overbound.methods.evidence import counted_evidence
from overbound.services import resolve_services
from overbound.simulate import SimulationConfig, simulate

SERVICES = resolve_services(None)
DAY_US = 86_400_000_000


def assert_same(a, b, path="result"):
    """Equal to the last bit: dataclasses field by field, arrays elementwise, floats by ==."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), path
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, dict):
        assert list(a) == list(b), path
        for k in a:
            assert_same(a[k], b[k], f"{path}[{k!r}]")
    elif isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, b, err_msg=path)
    elif isinstance(a, float) and np.isnan(a):
        assert isinstance(b, float) and np.isnan(b), path
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


def station_days(table: pl.DataFrame) -> list[pl.DataFrame]:
    """The partitions of a pooled table: one per station and GPS day, in table order."""
    t = table.with_columns((pl.col("time").dt.epoch("us") // DAY_US).alias("_day"))
    parts = t.partition_by(["station", "_day"], maintain_order=True)
    return [p.drop("_day") for p in parts]


def check(table: pl.DataFrame):
    """The counting and the verdicts' evidence by partition equal those of the pooled table."""
    pooled = count_kpis(table, SERVICES)
    parts = [lambda p=p: p for p in station_days(table)]
    merged, first = count_partitioned(parts, SERVICES)
    assert_same(merged, pooled)
    assert_same(
        evidence_partitioned(parts, SERVICES, first, merged), counted_evidence(table, pooled, SERVICES)
    )
    return pooled, first


def test_simulated_network_3_stations_7_days():
    cfg = SimulationConfig(days=7, interval_s=5.0, stations=3, seed=3, gap_rate_per_day=4.0, gap_mean_s=400)
    table = simulate(cfg).table
    pooled, first = check(table)
    assert len(pooled.stations) == 3 and pooled.by_station
    # windows cross each midnight: more windows than the days counted alone would give
    alone = sum(
        count_kpis(p, SERVICES, by_station=False).services["LPV"].combined.continuity.n_windows
        for p in station_days(table)
    )
    assert pooled.services["LPV"].combined.continuity.n_windows > alone
    daily = daily_availability(first, SERVICES)
    assert daily.height == 3 * 7 and daily["n_epochs"].sum() == table.height


def _table(times_s: np.ndarray, station: str, rng, alert=False) -> pl.DataFrame:
    n = times_s.size
    vpl = rng.uniform(5, 60, n)
    hpl = rng.uniform(5, 60, n)
    vpe = rng.normal(0, 8, n)
    hpe = np.abs(rng.normal(0, 8, n))
    vpe[rng.random(n) < 0.02] = np.nan
    cols = {
        "time": (np.datetime64("2024-01-07") + (times_s * 1e6).astype("timedelta64[us]")),
        "station": [station] * n,
        "hpe": hpe,
        "vpe": vpe,
        "hpl": hpl,
        "vpl": vpl,
    }
    if alert:
        cols["alert"] = rng.random(n) < 0.05
    return pl.DataFrame(cols).with_columns(pl.col("time").cast(pl.Datetime("us")))


@pytest.mark.parametrize("seed", range(6))
def test_day_boundary_edge_cases(seed):
    """Gaps across midnight, jittered epochs sharing a slot across midnight, a day of a few
    epochs, a one-epoch station, alerts, no-solution epochs and ties of the safety index."""
    rng = np.random.default_rng(seed)
    day = 86_400.0
    # station A: 1 Hz with jitter over 3 days; a gap over the first midnight; an epoch at
    # 23:59:59.8 and one at 00:00:00.3 on the second midnight (same slot)
    t = np.arange(0, 3 * day, 1.0)
    t = t[(t < day - 7) | (t > day + 3)]
    t = t + rng.uniform(-0.2, 0.2, t.size)
    t[np.argmin(np.abs(t - 2 * day))] = 2 * day - 0.2
    t = np.sort(np.append(t, 2 * day + 0.3))
    t = t[np.diff(np.append(t, np.inf)) > 0.05]
    a = _table(t, "A", rng, alert=True)
    # station B: 2 s interval, a day holding only 3 epochs just after midnight, then a last day
    tb = np.concatenate(
        [np.arange(0, day, 2.0), day + np.array([0.0, 2.0, 4.0]), np.arange(2 * day, 2.5 * day, 2.0)]
    )
    b = _table(tb, "B", rng, alert=True)
    # station C: one epoch
    c = _table(np.array([5.0]), "C", rng, alert=True)
    table = pl.concat([a, b, c], how="diagonal_relaxed")
    # a tie of the safety-index maximum in two partitions: the first in table order wins
    table = table.with_columns(
        pl.when(pl.int_range(pl.len()).is_in([10, table.height - 50]))
        .then(pl.lit(99.0))
        .otherwise(pl.col("hpe"))
        .alias("hpe"),
        pl.when(pl.int_range(pl.len()).is_in([10, table.height - 50]))
        .then(pl.lit(9.0))
        .otherwise(pl.col("hpl"))
        .alias("hpl"),
    ).with_columns(pl.lit(False).alias("alert") if seed == 0 else pl.col("alert"))
    pooled, _ = check(table)
    assert pooled.by_station["C"].services["LPV"].combined.continuity.reason == "fewer than two epochs"


def test_single_partition_equals_count_kpis():
    table = simulate(SimulationConfig(days=0.5, interval_s=1.0, seed=1)).table
    merged, first = count_partitioned([lambda: table], SERVICES)
    pooled = count_kpis(table, SERVICES)
    assert_same(merged, pooled)
    ev = evidence_partitioned([lambda: table], SERVICES, first, merged)
    assert_same(ev, counted_evidence(table, pooled, SERVICES))


def test_percentiles_bit_exact_on_ties():
    """Percentiles at ties and across partitions: HPE values drawn from a few levels."""
    rng = np.random.default_rng(7)
    t = np.arange(0, 2 * 86_400.0, 30.0)
    table = _table(t, "A", rng).with_columns(
        pl.Series("hpe", rng.choice([0.5, 1.25, 2.0, 7.75], t.size)), pl.Series("hpl", np.full(t.size, 12.0))
    )
    pooled, _ = check(table)
    assert pooled.hpe95 == np.percentile(table["hpe"].to_numpy()[np.isfinite(table["vpe"].to_numpy())], 95)


def test_daily_availability_dates():
    start = dt.datetime(2024, 1, 7)
    table = simulate(SimulationConfig(days=2, interval_s=60.0, seed=2, start=start)).table
    _, first = count_partitioned([lambda p=p: p for p in station_days(table)], SERVICES)
    daily = daily_availability(first, SERVICES)
    assert daily["date"].to_list() == [dt.date(2024, 1, 7), dt.date(2024, 1, 8)]
    lpv = [(p["vpl"] < 50) & (p["hpl"] < 40) for p in station_days(table)]
    assert daily["LPV"].to_list() == [float(m.mean()) for m in lpv]


def test_evidence_of_a_long_station_by_partition():
    """A station over 2**18 epochs: the effective sizes come from block means whose blocks cross
    the midnights; the evidence by partition is still that of the pooled table."""
    cfg = SimulationConfig(days=3.5, interval_s=1.0, seed=4, gap_rate_per_day=2.0, gap_mean_s=300)
    table = simulate(cfg).table
    assert table.height > 2**18
    check(table)


def test_evidence_bounds_from_pass_two_when_its_values_hold_them():
    """Errors nearly independent: many effective samples, bounds close to the 95th percentile, whose
    order statistics pass 2 has already collected (no third pass); the evidence is the same."""
    rng = np.random.default_rng(8)
    t = np.arange(0, 3 * 86_400.0, 5.0)
    table = pl.concat([_table(t, "A", rng), _table(t, "B", rng)])
    parts = [lambda p=p: p for p in station_days(table)]
    merged, first = count_partitioned(parts, SERVICES)
    plan = plan_second(first, SERVICES)
    second = merge_second(
        *(second_pass(p(), plan, SERVICES, label=str(i), evidence=True) for i, p in enumerate(parts))
    )
    draft = evidence_draft(second, plan, merged, SERVICES)
    found = bounds_from_second(first, plan, second, draft)
    assert found is not None
    assert_same(found, counted_evidence(table, count_kpis(table, SERVICES), SERVICES))


@pytest.mark.parametrize("seed", range(2))
def test_many_short_partitions(seed):
    """Partitions of 1 to a few dozen epochs cut anywhere (a window then spans several
    partitions, the far rows of the boundary strips) give the pooled counting to the last bit."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, 3000, 1.0)
    table = _table(t[rng.random(t.size) > 0.1], "A", rng, alert=True)
    cuts = np.sort(rng.choice(np.arange(1, table.height), 200, replace=False))
    parts = [table[i:j] for i, j in zip(np.r_[0, cuts], np.r_[cuts, table.height], strict=True)]
    merged, _ = count_partitioned([lambda p=p: p for p in parts], SERVICES)
    pooled = count_kpis(table, SERVICES)
    assert_same(merged, pooled)
    assert pooled.services["LPV"].combined.continuity.n_windows > 0
