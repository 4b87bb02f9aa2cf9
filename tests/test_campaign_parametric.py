"""The parametric analysis by partition (issue 14): read a station-day at a time, its fits, ACFs,
bounds and continuity curves equal those of the pooled table to the last bit, whatever the data
hold: jittered and missing epochs, two epochs of a station in one grid slot across midnight,
alerts, a day of alerts only, a day without a solution, a station of one epoch, stations
interleaved in the input, a time window that cuts days; and a partition that cannot be read
fails the analysis."""

from __future__ import annotations

import dataclasses
import datetime as dt

import numpy as np
import polars as pl
import pytest

from overbound.campaign import partitions_in
from overbound.campaign_parametric import campaign_parametric
from overbound.io.dataset import ingest, partitions, read_dataset
from overbound.io.open import filter_time
from overbound.io.schema import InputError
from overbound.methods.parametric import parametric_analysis, parametric_dict

DAY_US = 86_400_000_000
T0 = 1_388_534_400_000_000 + 3 * DAY_US  # a GPS midnight


def _network(
    seed: int, *, stations: int = 3, days: int = 3, step_s: float = 10.0, late: tuple[int, ...] = ()
) -> pl.DataFrame:
    """``late``: the stations that start a day late."""
    rng = np.random.default_rng(seed)
    frames = []
    n = int(days * 86400 / step_s)
    for k in range(stations):
        t = T0 + (np.arange(n) * step_s * 1e6).astype(np.int64) + DAY_US * (k in late)
        jitter = rng.random(n) < 0.1
        t[jitter] += rng.integers(1, 3_000_000, jitter.sum())
        keep = rng.random(n) > 0.1
        keep[int(rng.integers(0, n)) : int(rng.integers(0, n))] = False  # an outage
        t = np.unique(t[keep])
        if k == 0:  # two epochs in the slot of midnight, one on each day
            t = np.unique(np.concatenate([t, [T0 + DAY_US - 2_000_000, T0 + DAY_US + 1_000_000]]))
        m = t.size
        level = 12 + 5 * np.sin(np.arange(m) / 400 + k) + rng.normal(0, 0.5, m)
        vpl = np.abs(level) + 1.0
        hpl = 0.7 * vpl + rng.gamma(2.0, 0.5, m)
        vpe = rng.normal(0.05, vpl / 5.33 / 1.5)
        hpe = np.hypot(rng.normal(0, hpl / 8), rng.normal(0, hpl / 8))
        vpl[rng.random(m) < 0.01] = np.nan
        alert = rng.random(m) < 0.02
        day = (t - T0) // DAY_US
        if k == 1:
            alert |= day == 1  # a day of alerts only
            hpl[day == 2] = np.nan  # a day without a horizontal solution
        frames.append(
            pl.DataFrame(
                {
                    "time": pl.Series(t).cast(pl.Datetime("us")),
                    "station": f"S{k}",
                    "hpe": hpe,
                    "vpe": vpe,
                    "hpl": hpl,
                    "vpl": vpl,
                    "alert": alert,
                }
            )
        )
    frames.append(frames[0].head(1).with_columns(pl.lit("LONE").alias("station")))  # one epoch
    table = pl.concat(frames)
    return table.sort("time", maintain_order=True) if seed % 2 else table  # stations interleaved


def assert_same(a, b) -> None:
    """Two parametric analyses equal to the last bit: every field of both axes, and the JSON."""
    assert parametric_dict(a) == parametric_dict(b)
    assert a.reasons == b.reasons and a.n_rows == b.n_rows
    for axis in ("vertical", "horizontal"):
        x, y = a.axis(axis), b.axis(axis)
        assert (x is None) == (y is None)
        if x is None:
            continue
        for f in dataclasses.fields(x):
            u, v = getattr(x, f.name), getattr(y, f.name)
            if f.name == "continuity_curves":
                assert u.keys() == v.keys()
                for w in u:
                    for g in dataclasses.fields(u[w]):
                        p, q = getattr(u[w], g.name), getattr(v[w], g.name)
                        assert np.array_equal(p, q, equal_nan=True) if isinstance(p, np.ndarray) else p == q
            elif isinstance(u, np.ndarray):
                assert np.array_equal(u, v, equal_nan=True), f.name
            else:
                assert repr(u) == repr(v), f.name


def _dataset(table: pl.DataFrame, tmp_path) -> object:
    table.write_parquet(tmp_path / "net.parquet")
    ingest(tmp_path / "ds", [tmp_path / "net.parquet"])
    return tmp_path / "ds"


@pytest.mark.parametrize("seed", range(3))
def test_partitions_equal_the_pooled_table(seed: int, tmp_path) -> None:
    ds = _dataset(_network(seed), tmp_path)
    pooled, _ = read_dataset(ds, columns=("alert",))
    want = parametric_analysis(pooled)
    got = campaign_parametric(partitions(ds))
    assert_same(got, want)
    v = want.vertical
    assert v.n_alert > 0 and v.n_stations == 4 and v.weibull_cov is not None
    assert all(c.n_fail.sum() > 0 for c in v.continuity_curves.values())
    assert want.horizontal.n_no_solution > 0


def test_stations_that_start_on_different_days_pool_in_the_tables_order(tmp_path) -> None:
    """The pooled table orders the stations by name (the dataset's order), not by their first day."""
    ds = _dataset(_network(11, late=(0,)), tmp_path)
    pooled, _ = read_dataset(ds, columns=("alert",))
    assert pooled["station"][0] == "LONE" and pooled["time"].min() < pooled.filter(station="LONE")["time"][0]
    want = parametric_analysis(pooled)
    assert_same(campaign_parametric(partitions(ds)[::-1]), want)


def test_subsampled_grids_equal_the_pooled_table(tmp_path, monkeypatch) -> None:
    """Long campaigns: the ACF on every q-th slot and the Weibull fit started on a subsample (the
    limits lowered so that a small network reaches them)."""
    import overbound.methods.parametric_partitions as pp
    import overbound.stats.parametric as sp

    monkeypatch.setattr(pp, "ACF_MAX_SLOTS", 4096)
    monkeypatch.setattr(sp, "_WEIBULL_SUBSAMPLE", 2048)
    ds = _dataset(_network(5, days=2), tmp_path)
    pooled, _ = read_dataset(ds, columns=("alert",))
    want = parametric_analysis(pooled)
    assert want.vertical.acf_step > 1 and want.vertical.weibull.iterations > 2
    assert_same(campaign_parametric(partitions(ds)), want)


def test_time_window_equals_the_pooled_table(tmp_path) -> None:
    ds = _dataset(_network(6, days=3), tmp_path)
    day0 = dt.datetime.combine(partitions(ds)[0].date, dt.time())
    window = (day0 + dt.timedelta(hours=7.5), day0 + dt.timedelta(days=2, hours=3))  # cuts two days
    pooled, _ = read_dataset(ds, columns=("alert",))
    want = parametric_analysis(filter_time(pooled, window))
    assert_same(campaign_parametric(partitions_in(ds, window), time_range=window), want)


def test_an_axis_that_cannot_be_fitted_has_the_pooled_reason(tmp_path) -> None:
    table = _network(7, stations=2, days=2).with_columns(pl.lit(0.0).alias("hpe"))
    ds = _dataset(table, tmp_path)
    got = campaign_parametric(partitions(ds))
    want = parametric_analysis(read_dataset(ds, columns=("alert",))[0])
    assert got.horizontal is None and got.vertical is not None
    why = "r is all zero: a Rayleigh fit needs a positive scale"
    assert got.reasons == want.reasons == {"horizontal": why}
    assert_same(got, want)


def test_an_unreadable_partition_fails_the_analysis(tmp_path) -> None:
    ds = _dataset(_network(8, stations=2, days=2), tmp_path)
    parts = partitions(ds)
    parts[1].path.write_bytes(b"not parquet")
    with pytest.raises(InputError, match="unreadable in the parametric passes"):
        campaign_parametric(parts)


def test_bad_options_are_refused_before_any_pass(tmp_path) -> None:
    ds = _dataset(_network(9, stations=1, days=1), tmp_path)
    with pytest.raises(ValueError, match="confidence"):
        campaign_parametric(partitions(ds), confidence=1.5)
    with pytest.raises(ValueError):
        campaign_parametric(partitions(ds), decorrelation="soon")


def test_parametric_command_on_a_dataset_equals_its_epochs_as_one_file(tmp_path) -> None:
    """``overbound parametric DATASET`` runs by partition; its JSON equals that of the same epochs as
    one file, and its page says why the figures drawn from the epochs are left out."""
    from click.testing import CliRunner

    from overbound.cli import main
    from overbound.io.table import write_epochs

    ds = _dataset(_network(12, stations=2, days=2), tmp_path)
    pooled, _ = read_dataset(ds, columns=("alert",))
    write_epochs(pooled, tmp_path / "one.parquet")
    for src, out in ((ds, "by-parts"), (tmp_path / "one.parquet", "file")):
        args = ["parametric", str(src), "-o", str(tmp_path / out), "--service", "LPV"]
        res = CliRunner().invoke(main, args)
        assert res.exit_code == 0, res.output
    by_parts, by_file = ((tmp_path / d / "parametric.json").read_text() for d in ("by-parts", "file"))
    assert by_parts == by_file and '"weibull"' in by_parts
    page = (tmp_path / "by-parts" / "parametric.html").read_text()
    assert "a dataset analysed partition by partition" in page


def test_an_axis_that_fails_after_its_fits_is_null_with_its_reason(tmp_path, monkeypatch) -> None:
    """As in the pooled analysis, a failure in the last step of one axis leaves the other axis."""
    import overbound.campaign_parametric as cp

    real = cp.axis_result

    def failing(axis, *args):
        if axis == "horizontal":
            raise ValueError("singular information matrix")
        return real(axis, *args)

    monkeypatch.setattr(cp, "axis_result", failing)
    got = campaign_parametric(partitions(_dataset(_network(13, stations=2, days=2), tmp_path)))
    assert got.vertical is not None and got.horizontal is None
    assert got.reasons == {"horizontal": "singular information matrix"}
