"""Service-volume maps (issue 15, item 3): the engine over many virtual receivers at once, the map
table, and ``overbound sbas-map``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import polars as pl
import pymap3d
import pytest
from click.testing import CliRunner

from overbound.campaign import campaign_client
from overbound.cli import main
from overbound.methods.counting import continuity_risk
from overbound.sbas.engine import SbasOptions, run_sbas
from overbound.sbas.maps import MapGrid, grid_points, map_times, point_epochs, virtual_observations
from overbound.sbas.messages import decode
from overbound.sbas.run import read_stations
from overbound.sbas_map import MapOptions, compute_map, summarise
from overbound.services import resolve_services

FIX = Path(__file__).resolve().parents[1] / "data" / "sbas" / "engine"
NAV, EMS = FIX / "brdc0140.19n.gz", FIX / "ems_1930-2210.ems.gz"
T20 = int(np.datetime64("2019-01-14T20:00:00", "us").astype(np.int64))
GRID = MapGrid(-10.0, 30.0, 35.0, 65.0, 10.0)  # 5 x 4 points over Europe


@pytest.fixture(scope="module")
def inputs():
    inp = read_stations((), NAV, EMS)[0]
    return inp, decode(inp.frames)


#: Across the edges of EGNOS's one MT 27 region (20-70 N, 40 W-40 E): delta-UDRE_in inside, _out outside.
EDGE = MapGrid(30.0, 50.0, 60.0, 75.0, 5.0)


@pytest.mark.parametrize(("mode", "grid"), [("PA", GRID), ("NPA", GRID), ("PA", EDGE)])
def test_many_points_are_each_point_alone(inputs, mode: str, grid: MapGrid) -> None:
    """The engine over every point at once gives, for each point, its own run's epoch and satellite
    tables to the last bit: the same code, each row with its receiver."""
    inp, msgs = inputs
    _, _, ecef = grid_points(grid)
    times = T20 + np.arange(0, 1800, 60) * 1_000_000
    opt = SbasOptions(mode=mode)
    obs = virtual_observations(times, ecef, inp.eph, opt.mask_deg)
    many = run_sbas(obs, inp.eph, msgs, ecef, options=opt, klobuchar=inp.klobuchar, points=True)
    for p in sorted({0, 7, ecef.shape[0] - 1}):
        one = run_sbas(obs.filter(pl.col("point") == p).drop("point"), inp.eph, msgs, tuple(ecef[p]),
                       options=opt, klobuchar=inp.klobuchar)  # fmt: skip
        mine = many.epochs.filter(pl.col("point") == p).drop("point")
        assert mine.equals(one.epochs)
        assert many.satellites.filter(pl.col("point") == p).drop("point").equals(one.satellites)
    assert many.epochs["vpl"].is_finite().mean() > (0.9 if grid is GRID else 0.7)  # 75 N: few IGPs
    if grid is EDGE:  # both sides of the region: delta-UDRE 1 inside (EGNOS's _in), 100 outside (_out)
        used = many.satellites.filter(pl.col("used"))
        assert set(used["delta_udre"].unique().to_list()) == {1.0, 100.0}
    with pytest.raises(ValueError, match="sorted by time, point and PRN"):
        run_sbas(obs.reverse(), inp.eph, msgs, ecef, options=opt, points=True)


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
    # from the start of the messages' GPS day to the last message (22:09:59) + 1 s, as gLAB's maps
    assert times.size == 22 * 60 + 10 + 1
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


MAPS = Path(__file__).resolve().parents[1] / "data" / "sbas" / "maps"
NET = Path(__file__).resolve().parents[1] / "data" / "sbas" / "network"


def _glab(name: str) -> np.ndarray:
    """A gLAB SBAS map file: LAT, LON, value, count, epochs per node (its fixture's PROVENANCE)."""
    import gzip

    lines = gzip.decompress((MAPS / name).read_bytes()).decode().splitlines()
    return np.array([[float(x) for x in line.split()] for line in lines[3:] if line.strip()])


@pytest.fixture(scope="module")
def day_map():
    """The EGNOS day at 60 s on the 4 deg nodes (a quarter of gLAB's 2 deg nodes), LPV and LPV-200."""
    options = MapOptions(
        grid=MapGrid(-30.0, 40.0, 25.0, 70.0, 4.0), services=resolve_services(["LPV", "LPV-200"])
    )
    return compute_map(NAV, NET / "egnos123_2019014.ems.gz", options)


@pytest.mark.parametrize(
    ("service", "name"), [("LPV", "glab_lpv_2deg_60s"), ("LPV-200", "glab_lpv200_2deg_60s")]
)
def test_availability_agrees_with_glab(day_map, service: str, name: str) -> None:
    """Issue 15's criterion: per node within 1 percentage point of gLAB v6's SBAS maps on >= 98 % of the
    nodes (the whole 2 deg grid: 100 % for LPV, 99.9 % for LPV-200, at most 0.7 / 1.2 pp, comparison run
    outside the suite); the same epochs; the nodes below the GEO's 5 deg never available in both."""
    g = _glab(f"{name}_avail.txt.gz")
    ours = day_map.table.filter((pl.col("service") == service) & pl.col("hour").is_null())
    glab = pl.DataFrame({"lat": g[:, 0], "lon": g[:, 1], "g_avail": g[:, 3], "g_epochs": g[:, 4]})
    both = ours.join(glab, on=["lat", "lon"], how="inner")
    assert both.height == ours.height == 12 * 18
    assert (both["n_epochs"] == both["g_epochs"]).all() and both["n_epochs"][0] == 1381
    diff = (both["n_available"] - both["g_avail"]).to_numpy() / 1381
    assert np.mean(np.abs(diff) <= 0.01) >= 0.99  # the whole 2 deg grid: 100 % (LPV), 99.9 % (LPV-200)
    assert np.abs(diff).max() <= 0.0125
    hidden = both.filter(pl.col("g_avail") == 0)
    assert hidden.height > 0 and (hidden["n_available"] <= 2).all()  # north-west corner: GEO below 5 deg
    share = float((both["g_avail"] / both["g_epochs"] >= 0.5).mean())
    assert day_map.share_above(service, 0.5) == pytest.approx(share, abs=0.02)


def test_ionospheric_availability_against_glab(day_map) -> None:
    """gLAB's ionosphere map takes the node as a pierce point: the same definition. Most nodes agree
    to the epoch (79.6 % of the 2 deg grid, 93.4 % within 1 pp, at most 46 pp apart): the others lie on
    the 5 deg lines of the IGP grid, where the cell of a pierce point on a line is a convention, or at
    the edges of the mask."""
    g = _glab("glab_lpv_2deg_60s_iono.txt.gz")
    ours = day_map.table.filter((pl.col("service") == "LPV") & pl.col("hour").is_null())
    glab = pl.DataFrame({"lat": g[:, 0], "lon": g[:, 1], "g_iono": g[:, 3] / g[:, 4]})
    both = ours.join(glab, on=["lat", "lon"], how="inner")
    diff = (both["iono_availability"] - both["g_iono"]).abs().to_numpy()
    assert np.mean(diff <= 0.01) >= 0.88
    assert np.mean(diff == 0) >= 0.72


def _glab_risk_count(ok: np.ndarray, window: int = 15) -> int:
    """gLAB's NUMRISK of one node (its fixture's PROVENANCE): at each loss of service the last min(15,
    run) available epochs before it, and once more at the end of the run."""
    runs, n = [], 0
    for v in ok.tolist():
        if v:
            n += 1
        elif n:
            runs.append(n)
            n = 0
    return sum(min(window, r) for r in runs) + (min(window, n) if n else 0)


def test_continuity_at_one_second_against_glab() -> None:
    """12:00-15:00 at 1 s: the nodes' available epochs are gLAB's (185 of its 200 nodes with service
    on the 4 deg nodes, outside the suite), and gLAB's own continuity count on our series gives its
    NUMRISK. Our risk is Kannemans' (15 s windows in time, those that run past the data left out), which
    is below gLAB's by its end-of-run loss (0.93 of it, median)."""
    g = _glab("glab_lpv_2deg_1s_12to15_avail.txt.gz")
    r = _glab("glab_lpv_2deg_1s_12to15_risk.txt.gz")
    nodes = [(37.0, -6.0), (41.0, 2.0), (45.0, 10.0), (49.0, 6.0), (53.0, 14.0), (57.0, 22.0)]
    lat, lon = np.array([n[0] for n in nodes]), np.array([n[1] for n in nodes])
    ecef = np.stack(pymap3d.geodetic2ecef(lat, lon, np.zeros(lat.size)), axis=1)
    t12 = int(np.datetime64("2019-01-14T12:00:00", "us").astype(np.int64))
    times = t12 + np.arange(10801) * 1_000_000
    full = read_stations((), NAV, NET / "egnos123_2019014.ems.gz")[0]
    epochs = point_epochs(times, ecef, full.eph, decode(full.frames), SbasOptions())
    hpl = epochs["hpl"].to_numpy().reshape(times.size, lat.size).T
    vpl = epochs["vpl"].to_numpy().reshape(times.size, lat.size).T
    for k, (la, lo) in enumerate(nodes):
        row = np.flatnonzero((g[:, 0] == la) & (g[:, 1] == lo))[0]
        with np.errstate(invalid="ignore"):
            ok = (hpl[k] < 40) & (vpl[k] < 50)  # gLAB's test is strict; ours (<=) differs on a null set
        assert ok.sum() == g[row, 3], (la, lo)
        assert _glab_risk_count(ok) == r[row, 3], (la, lo)
        ours = continuity_risk(times, ok, window_s=15.0)
        assert 0.8 < ours.risk / (r[row, 3] / r[row, 4]) < 1.0
