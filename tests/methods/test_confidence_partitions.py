"""The PL confidence level by partition (issue 14): gathered station-day by station-day, walked
across the days, it equals the pooled table's analysis to the last bit (bins, samples and their
pooled rows), whatever the data hold: ties in time between stations and in the largest error, PLs
on the band edges, widening, empty and insufficient bands, alerts, irregular times, stations
interleaved in the table, a column missing on some days; and the slot bound behind the chains
skipped holds."""

from __future__ import annotations

import numpy as np
import polars as pl
import pytest

from overbound.analysis import analyze
from overbound.campaign_confidence import campaign_confidence
from overbound.io.dataset import ingest, partitions, read_dataset
from overbound.methods.confidence_level import confidence_analysis
from overbound.methods.confidence_partitions import ConfidenceParameters, table_confidence
from overbound.stats.dependence import select_spaced

DAY_US = 86_400_000_000
T0 = 1_388_534_400_000_000 + 3 * DAY_US  # a GPS midnight


def assert_same(a, b) -> None:
    """Two :class:`ConfidenceAnalysis` equal to the last bit, samples included."""
    assert (a.axis, a.stations, a.n_epochs) == (b.axis, b.stations, b.n_epochs)
    assert a.pl_min == b.pl_min or (np.isnan(a.pl_min) and np.isnan(b.pl_min))
    assert len(a.bins) == len(b.bins)
    for i, (x, y) in enumerate(zip(a.bins, b.bins, strict=True)):
        assert repr(x) == repr(y), i
        sx, sy = a.samples[i], b.samples[i]
        for f in ("rows", "time_us", "station", "pl", "error"):
            assert np.array_equal(getattr(sx, f), getattr(sy, f)), (i, f)
        for u, v in zip(sx.signed, sy.signed, strict=True):
            assert np.array_equal(u, v)


def _random_network(seed: int, *, stations: int = 3, days: int = 3, step_s: float = 30.0) -> pl.DataFrame:
    """Stations sharing a time grid (ties in time), with jittered and missing epochs, PLs on a
    0.125 m lattice (on the band edges), errors on a coarse lattice (ties in the largest error),
    alerts; rows interleaved by time when ``seed`` is odd."""
    rng = np.random.default_rng(seed)
    frames = []
    n = int(days * 86400 / step_s)
    for k in range(stations):
        t = T0 + (np.arange(n) * step_s * 1e6).astype(np.int64)
        jitter = rng.random(n) < 0.1
        t[jitter] += rng.integers(1, 5_000_000, jitter.sum())
        keep = rng.random(n) > 0.15
        keep[int(rng.integers(0, n)) : int(rng.integers(0, n))] = False  # an outage
        t = np.unique(t[keep])
        m = t.size
        level = 8 + 4 * np.sin(np.arange(m) / 300 + k) + rng.normal(0, 0.5, m)
        vpl = np.round(np.abs(level) / 0.125) * 0.125 + 0.125
        vpe = np.round(rng.normal(0, vpl / 5.33) * 4) / 4
        east, north = rng.normal(0, vpl / 8), rng.normal(0, vpl / 8)
        hpl = np.round(vpl * 0.8 / 0.125) * 0.125 + 0.125
        vpe[rng.random(m) < 0.01] = np.nan
        east[rng.random(m) < 0.01] = np.nan
        frames.append(
            pl.DataFrame(
                {
                    "time": pl.Series(t).cast(pl.Datetime("us")),
                    "station": f"S{k}",
                    "hpe": np.hypot(east, north),
                    "vpe": vpe,
                    "hpl": hpl,
                    "vpl": vpl,
                    "east": east,
                    "north": north,
                    "alert": rng.random(m) < 0.02,
                }
            )
        )
    table = pl.concat(frames)
    return table.sort("time", maintain_order=True) if seed % 2 else table


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("axis", ["vertical", "horizontal"])
def test_partitions_equal_the_pooled_table(seed: int, axis: str) -> None:
    table = _random_network(seed)
    for params in (
        ConfidenceParameters(min_samples=40),
        ConfidenceParameters(min_samples=200, spacing=500.0),
    ):
        got = table_confidence(table, axis, params)
        want = confidence_analysis(table, axis=axis, **{k: getattr(params, k) for k in _PARAMS})
        assert_same(got, want)
        widened = [b for b in want.bins if b.tolerance_used > params.tolerance]
        assert widened and any(b.sufficient for b in want.bins), "the cases are exercised"


def test_the_rated_bands_solves_through_a_runner_give_the_same_bins() -> None:
    """``dataset_confidence(starmap=)``: a campaign's workers solve the rated bands (confidence
    level, PL1, PL99), here in reverse order; the bins are those solved in place."""
    table = _random_network(5)
    params = ConfidenceParameters(min_samples=40)
    items: list = []

    def reverse_starmap(fn, args: list[tuple]) -> list:
        items.extend(args)
        return [fn(*a) for a in args[::-1]][::-1]

    got = table_confidence(table, "vertical", params, reverse_starmap)
    want = confidence_analysis(table, axis="vertical", **{k: getattr(params, k) for k in _PARAMS})
    assert_same(got, want)
    rated = [b for b in want.bins if b.sufficient and np.isfinite(b.confidence)]
    assert len(items) == len(rated) > 5
    assert [i[0].n for i in items] == [b.n for b in rated]


_PARAMS = ("min_samples", "spacing", "tolerance", "step", "max_pl", "max_tolerance", "risk", "core")


def test_the_parameters_default_to_those_of_the_pooled_analysis() -> None:
    """``ConfidenceParameters`` repeats the defaults of ``confidence_analysis``: they must not drift."""
    import inspect

    defaults = inspect.signature(confidence_analysis).parameters
    assert {k: defaults[k].default for k in _PARAMS} == {
        k: getattr(ConfidenceParameters(), k) for k in _PARAMS
    }


def test_ties_in_time_and_error_across_stations() -> None:
    """Three stations with the same times and the same errors, the largest at mid-span: the anchor
    is the earliest row of the pooled table (station C), forward picks the first station at a
    time (C), backward the last (B)."""
    t = T0 + np.arange(0, 4 * 3600, 10, dtype=np.int64) * 1_000_000
    vpe = np.where(np.arange(t.size) % 7 == 0, 3.0, 1.0)
    vpe[t.size // 2] = 5.0
    frames = [
        pl.DataFrame(
            {
                "time": pl.Series(t).cast(pl.Datetime("us")),
                "station": name,
                "hpe": 1.0,
                "vpe": vpe,
                "hpl": 10.0,
                "vpl": 10.0 + 0.125 * (np.arange(t.size) % 3),
            }
        )
        for name in ("C", "A", "B")
    ]
    table = pl.concat(frames)
    params = ConfidenceParameters(min_samples=5, max_pl=11.0)
    want = confidence_analysis(table, min_samples=5, max_pl=11.0)
    assert_same(table_confidence(table, "vertical", params), want)
    s = want.samples[0]
    mid = t[t.size // 2]
    assert set(s.station[s.time_us < mid].tolist()) == {2} and set(s.station[s.time_us >= mid].tolist()) == {
        0
    }


def test_a_column_missing_on_some_days_and_one_day_without_solution(tmp_path) -> None:
    """A dataset whose partitions differ: east/north absent on one station's days (read as missing
    in the pooled table), a day without any solution."""
    table = _random_network(10, stations=2, days=3)
    day = pl.col("time").dt.epoch("us") // DAY_US
    a = table.filter(pl.col("station") == "S0").drop("east", "north")
    b = table.filter(pl.col("station") == "S1")
    b = b.with_columns(pl.when(day == day.min()).then(None).otherwise(pl.col("vpe")).alias("vpe"))
    for name, part in (("a", a), ("b", b)):
        part.write_parquet(tmp_path / f"{name}.parquet")
    ds = tmp_path / "ds"
    ingest(ds, [tmp_path / "a.parquet", tmp_path / "b.parquet"])
    pooled, _ = read_dataset(ds, columns=("east", "north", "alert"))
    run = campaign_confidence(partitions(ds), None)
    assert [c.axis for c in run.done] == ["vertical", "horizontal"] and run.failed == ()
    for c in run.done:
        assert_same(c, confidence_analysis(pooled, axis=c.axis))


def test_horizontal_without_east_fails_as_the_pooled_table(tmp_path) -> None:
    table = _random_network(2, stations=1, days=2).drop("east", "north")
    table.write_parquet(tmp_path / "a.parquet")
    ingest(tmp_path / "ds", [tmp_path / "a.parquet"])
    parts = partitions(tmp_path / "ds")
    assert [c.axis for c in campaign_confidence(parts, None).done] == ["vertical"]
    run = campaign_confidence(parts, ("horizontal",))
    assert run.done == () and "needs the signed east and north errors" in str(run.failed[0][1])
    pooled, _ = read_dataset(tmp_path / "ds")
    with pytest.raises(type(run.failed[0][1]), match="signed east and north"):
        confidence_analysis(pooled, axis="horizontal")


def test_a_partition_unreadable_in_a_walk_fails_both_axes_naming_it(tmp_path, monkeypatch) -> None:
    """A station-day that can no longer be read when the chains are walked (pass 3: a task per
    axis and way, each reading its axis' columns) fails every axis, with the partition named, as
    when it fails in pass 1 or 2."""
    import overbound.campaign_confidence as cc

    _random_network(4, stations=2, days=3).write_parquet(tmp_path / "a.parquet")
    ingest(tmp_path / "ds", [tmp_path / "a.parquet"])
    parts = partitions(tmp_path / "ds")
    bad = parts[-2]  # not its day's first station
    assert bad.station != parts[0].station
    read, columns_read = cc._read, []

    def flaky(partition, window, only, extra):
        columns_read.append((tuple(only), tuple(extra)))
        if partition.key == bad.key and "station" in only and len(only) == 4:  # a walk's read
            raise OSError("gone")
        return read(partition, window, only, extra)

    monkeypatch.setattr(cc, "_read", flaky)
    run = campaign_confidence(parts, None)
    assert run.done == () and [a for a, _ in run.failed] == ["vertical", "horizontal"]
    assert all(
        why == f"partition {bad.station} {bad.date} unreadable in the confidence passes: OSError: gone"
        for _, why in run.failed
    )
    walks = {c for c in columns_read if len(c[0]) == 4}
    assert walks == {
        (("time", "station", "vpe", "vpl"), ("alert",)),
        (("time", "station", "hpe", "hpl"), ("east", "north", "alert")),
    }


def test_dataset_with_a_time_window_equals_the_pooled_table(tmp_path) -> None:
    import datetime as dt

    from overbound.io.open import filter_time
    from overbound.simulate import SimulationConfig, write_simulation_dataset

    write_simulation_dataset(SimulationConfig(days=3, interval_s=5.0, stations=2, seed=9), tmp_path / "ds")
    day0 = dt.datetime.combine(partitions(tmp_path / "ds")[0].date, dt.time())
    window = (day0 + dt.timedelta(hours=7.5), day0 + dt.timedelta(days=1, hours=19))  # cuts two days
    got = analyze([tmp_path / "ds"], confidence=None, evt=(), time_range=window, cache=False, columns=None)
    pooled, _ = read_dataset(tmp_path / "ds", columns=("east", "north", "alert"))
    pooled = filter_time(pooled, window)
    assert [c.axis for c in got.confidence] == ["vertical", "horizontal"] and got.table.is_empty()
    for a in got.confidence:
        assert_same(a, confidence_analysis(pooled, axis=a.axis))


def test_the_columns_read_and_a_wrong_axis_as_for_the_pooled_table(tmp_path) -> None:
    """``analyze(DATASET, columns=...)`` sees the optional columns a pooled table read with them
    would have (without ``alert`` alerted epochs count, without east/north no horizontal axis);
    an unknown axis is a method failure with the pooled analysis' reason, the others go on."""
    table = _random_network(4, stations=2, days=2)
    table.write_parquet(tmp_path / "a.parquet")
    ds = tmp_path / "ds"
    ingest(ds, [tmp_path / "a.parquet"])
    for columns in ((), ("alert",), ("east", "north")):
        got = analyze([ds], confidence=None, evt=(), columns=columns, cache=False)
        want = analyze(read_dataset(ds, columns=columns)[0], confidence=None, evt=())
        assert [c.axis for c in got.confidence] == [c.axis for c in want.confidence]
        for a, b in zip(got.confidence, want.confidence, strict=True):
            assert_same(a, b)
    assert [c.axis for c in want.confidence] == ["vertical", "horizontal"]
    got = analyze([ds], confidence=("vertical", "Horizontal"), evt=(), columns=("alert",), cache=False)
    want = analyze(read_dataset(ds, columns=("alert",))[0], confidence=("vertical", "Horizontal"), evt=())
    assert [c.axis for c in got.confidence] == ["vertical"] and got.method_failures == want.method_failures
    assert "axis must be 'vertical' or 'horizontal'" in got.method_failures[0][2]


@pytest.mark.parametrize("seed", range(40))
def test_the_greedy_chain_covers_at_most_two_slots_per_sample(seed: int) -> None:
    """The bound behind the chains not walked: a spaced selection of n samples from candidates that
    occupy ``slots`` slots of ``spacing`` has n >= slots / 2 - 1."""
    rng = np.random.default_rng(seed)
    spacing = int(rng.integers(1, 50))
    t = np.sort(rng.integers(0, int(rng.integers(10, 5000)), int(rng.integers(1, 3000))))
    n = select_spaced(t, anchor=int(rng.integers(0, t.size)), spacing=spacing).size
    slots = np.unique(t // spacing).size
    assert n >= slots / 2 - 1


@pytest.mark.parametrize("seed", range(5))
def test_slot_bits_merge_is_the_union_of_the_pairs_in_any_order(seed: int) -> None:
    """Pass 2's occupied (slice, slot) pairs: bits merged by or, in any grouping and order, hold
    exactly the set union of the pieces' pairs (slots not on multiples of 8, empty pieces)."""
    from overbound.methods.confidence_partitions import SlotBits, merge_slot_bits

    rng = np.random.default_rng(seed)
    n_slices, n_slots = 7, 1000
    pieces, pairs = [], set()
    for _ in range(9):
        n = int(rng.integers(0, 40))
        lo = int(rng.integers(0, n_slots - 50))
        s, slot = rng.integers(0, n_slices, n), lo + rng.integers(0, 50, n)
        pieces.append(SlotBits.of(s, slot, n_slices))
        pairs |= set(zip(s.tolist(), slot.tolist(), strict=True))
    expected = np.zeros((n_slices, n_slots), dtype=bool)
    for s, slot in pairs:
        expected[s, slot] = True
    order = rng.permutation(len(pieces))
    split = int(rng.integers(1, len(pieces)))
    grouped = merge_slot_bits(
        merge_slot_bits(*(pieces[i] for i in order[:split])),
        merge_slot_bits(*(pieces[i] for i in order[split:])),
    )
    for merged in (merge_slot_bits(*pieces), grouped):
        assert merged.lo % 8 == 0
        assert np.array_equal(merged.dense(n_slots), expected)
    empty = SlotBits.of(np.empty(0, np.int64), np.empty(0, np.int64), n_slices)
    assert not merge_slot_bits(empty, empty).dense(n_slots).any()
