"""Service-volume maps (issue 15, item 3): the engine over many virtual receivers at once, the map
table, and ``overbound sbas-map``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from click.testing import CliRunner

from overbound.campaign import campaign_client
from overbound.cli import main
from overbound.methods.counting import continuity_risk
from overbound.sbas.engine import SbasOptions, run_sbas
from overbound.sbas.maps import MapGrid, grid_points, map_times, point_epochs, summarise, virtual_observations
from overbound.sbas.messages import decode
from overbound.sbas.run import read_stations
from overbound.sbas_map import MapOptions, compute_map
from overbound.services import resolve_services

FIX = Path(__file__).resolve().parents[1] / "data" / "sbas" / "engine"
NAV, EMS = FIX / "brdc0140.19n.gz", FIX / "ems_1930-2210.ems.gz"
T20 = int(np.datetime64("2019-01-14T20:00:00", "us").astype(np.int64))
GRID = MapGrid(-10.0, 30.0, 35.0, 65.0, 10.0)  # 5 x 4 points over Europe


@pytest.fixture(scope="module")
def inputs():
    inp = read_stations((), NAV, EMS)[0]
    return inp, decode(inp.frames)


@pytest.mark.parametrize("mode", ["PA", "NPA"])
def test_many_points_are_each_point_alone(inputs, mode: str) -> None:
    """The engine over every point at once gives, for each point, its own run's epoch and satellite
    tables to the last bit: the same code, each row with its receiver."""
    inp, msgs = inputs
    _, _, ecef = grid_points(GRID)
    times = T20 + np.arange(0, 1800, 60) * 1_000_000
    opt = SbasOptions(mode=mode)
    obs = virtual_observations(times, ecef, inp.eph, opt.mask_deg)
    many = run_sbas(obs, inp.eph, msgs, ecef, options=opt, klobuchar=inp.klobuchar, points=True)
    for p in (0, 7, 19):
        one = run_sbas(obs.filter(pl.col("point") == p).drop("point"), inp.eph, msgs, tuple(ecef[p]),
                       options=opt, klobuchar=inp.klobuchar)  # fmt: skip
        mine = many.epochs.filter(pl.col("point") == p).drop("point")
        assert mine.equals(one.epochs)
        assert many.satellites.filter(pl.col("point") == p).drop("point").equals(one.satellites)
    assert many.epochs["vpl"].is_finite().mean() > 0.9


def test_the_map_table_from_the_points_epochs(inputs) -> None:
    inp, msgs = inputs
    lat, lon, ecef = grid_points(GRID)
    times = T20 + np.arange(0, 600, 1) * 1_000_000  # 10 min at 1 s: 15 s windows fit
    epochs = point_epochs(times, ecef, inp.eph, msgs, SbasOptions())
    assert epochs.height == times.size * lat.size
    services = resolve_services(["LPV", "LPV-200"])
    table = summarise(epochs, lat, lon, services)
    for p in (3, 12):
        mine = epochs.filter(pl.col("point") == p)
        hpl, vpl = mine["hpl"].to_numpy(), mine["vpl"].to_numpy()
        solved = np.isfinite(hpl) & np.isfinite(vpl)
        for s in services:
            ok = solved & (hpl <= s.hal) & (vpl <= s.val)
            row = table.filter(
                (pl.col("lat") == lat[p]) & (pl.col("lon") == lon[p]) & (pl.col("service") == s.name)
            )
            assert row["n_epochs"][0] == times.size and row["n_available"][0] == ok.sum()
            assert row["availability"][0] == ok.mean()
            assert row["continuity_risk"][0] == continuity_risk(times, ok, window_s=15.0).risk
            assert row["hpl_p95"][0] == np.percentile(hpl[solved], 95)
            assert row["vpl_p99"][0] == np.percentile(vpl[solved], 99)
            assert row["iono_availability"][0] == mine["iono_ok"].mean()
    assert table.height == 2 * lat.size and table["hour"].is_null().all()


def test_hourly_rows_and_times(inputs) -> None:
    inp, msgs = inputs
    times = map_times(msgs, 60.0)
    assert times[0] == int(np.datetime64("2019-01-14T00:00:00", "us").astype(np.int64))
    assert times.size == 1440  # the GPS day of the messages
    lat, lon, ecef = grid_points(MapGrid(0.0, 10.0, 40.0, 50.0, 10.0))
    sub = times[(times >= T20) & (times < T20 + 2 * 3600 * 1_000_000)]
    epochs = point_epochs(sub, ecef, inp.eph, msgs, SbasOptions())
    table = summarise(epochs, lat, lon, resolve_services(["LPV"]), hourly=True)
    assert sorted(table["hour"].drop_nulls().unique().to_list()) == [20, 21]
    whole = table.filter(pl.col("hour").is_null()).sort("lat", "lon")
    hours = table.filter(pl.col("hour").is_not_null()).group_by("lat", "lon").agg(pl.col("n_available").sum())
    assert (
        whole.join(hours, on=["lat", "lon"])["n_available_right"].to_list() == whole["n_available"].to_list()
    )
    assert whole["continuity_risk"].is_null().all()  # 15 s windows do not fit 60 s epochs


def test_the_command_writes_the_map(tmp_path: Path) -> None:
    area = ["--area", "-10", "30", "35", "65", "--step", "10"]
    span = ["--start", "2019-01-14T20:00:00", "--end", "2019-01-14T21:00:00"]
    services = ["--service", "LPV", "--service", "LPV-200", "--hourly"]
    args = ["sbas-map", "--nav", str(NAV), "--sbas", str(EMS), *area, *span, *services]
    r = CliRunner().invoke(main, [*args, "-o", str(tmp_path / "a")])
    assert r.exit_code == 0, r.output
    table = pl.read_parquet(tmp_path / "a" / "map.parquet")
    assert table.columns == [
        *("lat", "lon", "service", "hour", "n_epochs", "n_available", "availability", "continuity_risk"),
        *("hpl_p95", "vpl_p95", "hpl_p99", "vpl_p99", "iono_availability"),
    ]
    assert table.height == 20 * 2 * 2  # points x services x (whole span, hour 20)
    doc = json.loads((tmp_path / "a" / "map.json").read_text())
    assert (
        doc["schema"] == "overbound.sbas-map/1" and doc["epochs"]["count"] == 60 and doc["grid_points"] == 20
    )
    assert {i["name"] for i in doc["inputs"]} == {NAV.name, EMS.name} and all(
        len(i["sha256"]) == 64 for i in doc["inputs"]
    )
    whole = table.filter(pl.col("hour").is_null() & (pl.col("service") == "LPV"))
    assert doc["services"]["LPV"]["share_of_points_at_least_99"] == pytest.approx(
        (whole["availability"] >= 0.99).mean()
    )
    assert f"LPV: {100 * (whole['availability'] >= 0.99).mean():.1f} % of the grid points" in r.output
    html = (tmp_path / "a" / "map.html").read_text()
    assert 'data-figure="availability-LPV"' in html and 'data-figure="iono_availability"' in html
    assert 'src="http' not in html and "<link" not in html  # self-contained
    r2 = CliRunner().invoke(main, [*args, "-o", str(tmp_path / "b")])
    assert r2.exit_code == 0
    for name in ("map.parquet", "map.json", "map.html"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name


def test_on_a_real_scheduler_the_same_map(scheduler: str) -> None:
    options = MapOptions(grid=GRID, start_us=T20, end_us=T20 + 3 * 3600 * 1_000_000 // 2,
                         services=resolve_services(["LPV"]))  # fmt: skip
    client = campaign_client(scheduler=scheduler)
    try:
        client.wait_for_workers(2, timeout=60)
        remote = compute_map(NAV, EMS, options, client=client)
    finally:
        client.close()
    local = compute_map(NAV, EMS, options)
    assert remote.table.equals(local.table)
    assert remote.table.height == 20
