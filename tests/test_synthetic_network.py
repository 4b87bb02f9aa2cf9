"""A synthetic network over the EGNOS day (issue 15, item 4): ``overbound synth-obs`` writes the
observation files of points from the day's precise products, ``overbound sbas --campaign`` runs
them station-day by station-day on two workers into a dataset, ``overbound analyze`` reports per
station, and each station's table equals the station run alone."""

from __future__ import annotations

import datetime as dt
import json
import shutil
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from click.testing import CliRunner

from overbound.cli import main
from overbound.io.dataset import partition_path, partitions
from overbound.io.dcb import read_code_dcb
from overbound.io.ionex import read_ionex
from overbound.io.rinex_nav import read_rinex_nav
from overbound.io.rinex_obs import read_rinex_obs
from overbound.io.sp3 import read_sp3
from overbound.sbas.run import process, write_run
from overbound.sbas.synthetic_obs import EUROPE, SyntheticPoint, synthesize

DATA = Path(__file__).resolve().parent / "data" / "sbas"
NET, ENGINE = DATA / "network", DATA / "engine"
DAY = dt.date(2019, 1, 14)
#: Five of the ten points: the two of the shared files, Athens, Warsaw and Reykjavik (edge of the area).
FIVE = [p for p in EUROPE if p.name in ("SYNT", "SYNB", "ATHN", "WARS", "REYK")]
PRODUCTS = [
    "--sp3", str(NET / "igs20361.sp3.gz"), "--nav", str(ENGINE / "brdc0140.19n.gz"),
    "--ionex", str(NET / "igsg0140.19i.gz"), "--dcb", str(NET / "P1C11901.DCB"), "--day", "2019-01-14",
]  # fmt: skip
CAMPAIGN = """
start = "2019-01-14"
nav = ["nav/brdc{doy}0.{yy}n.gz"]
sbas = ["ems/egnos123_{yyyy}{doy}.ems.gz"]
"""


@pytest.fixture(scope="module")
def products():
    return (
        read_sp3(NET / "igs20361.sp3.gz")[0],
        read_rinex_nav(ENGINE / "brdc0140.19n.gz")[0],
        read_ionex(NET / "igsg0140.19i.gz")[0],
        read_code_dcb(NET / "P1C11901.DCB")[0],
    )


@pytest.mark.parametrize(
    ("name", "point"),
    [
        ("SYNT", SyntheticPoint("SYNT", 43.5607, 1.4809, 207.0)),
        ("SYNB", SyntheticPoint("SYNB", 50.7980, 4.3590, 158.0)),
    ],
)
def test_the_shared_synthetic_files_are_reproduced(name: str, point: SyntheticPoint, products) -> None:
    """The files of ``synthetic-obs`` were written by another implementation of the same recipe: the
    same satellites at every epoch, C1 within 1 cm (1 mm median), L1 within 0.05 cycle, S1 exact."""
    shared, _ = read_rinex_obs(ENGINE / f"{name}0140_1930-2210.19o.gz")
    times = shared.table["time"].unique().sort().dt.epoch("us").to_numpy()
    ours = synthesize(point, times, *products)
    both = shared.table.select("time", "sat", "C1C", "L1C", "S1C").join(ours, on=["time", "sat"], how="full")
    assert both.height == shared.table.height == ours.height, "the same satellites at every epoch"
    dc1 = (both["C1"] - both["C1C"]).abs().to_numpy()
    assert np.median(dc1) < 0.0012 and dc1.max() < 0.01
    assert (both["L1"] - both["L1C"]).abs().max() < 0.05
    assert (both["S1"] - both["S1C"]).abs().max() < 0.001  # written with 3 decimals
    header = np.array(shared.header.approx_position)
    assert np.abs(point.ecef() - header).max() < 1e-3  # the header position is the truth


@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> Path:
    """The five points' files of the whole day written by ``overbound synth-obs``, laid out as a
    network's archive with the day's navigation file and EMS messages, and its campaign."""
    root = tmp_path_factory.mktemp("archive")
    points = [f"--point={p.name},{p.lat_deg},{p.lon_deg},{p.height_m}" for p in FIVE]
    res = CliRunner().invoke(main, ["synth-obs", *PRODUCTS, *points, "-o", str(root / "obs")])
    assert res.exit_code == 0, res.output
    (root / "nav").mkdir()
    shutil.copy(ENGINE / "brdc0140.19n.gz", root / "nav")
    (root / "ems").mkdir()
    shutil.copy(NET / "egnos123_2019014.ems.gz", root / "ems")
    stations = "".join(
        f'\n[[stations]]\nid = "{p.name}"\nobs = ["obs/{{id}}{{doy}}0.{{yy}}o.gz"]\n' for p in FIVE
    )
    (root / "campaign.toml").write_text(CAMPAIGN + stations)
    return root


def test_the_files_of_synth_obs(archive: Path) -> None:
    """One file per point, named as a daily RINEX 2 file; its header position is the point; a file
    reads back with nothing rejected; the same command gives the same bytes."""
    files = sorted(p.name for p in (archive / "obs").glob("*.gz"))
    assert files == sorted(f"{p.name}0140.19o.gz" for p in FIVE)
    obs, report = read_rinex_obs(archive / "obs" / "REYK0140.19o.gz")
    assert report.n_rejected == 0 and not report.invalidated
    reyk = next(p for p in FIVE if p.name == "REYK")
    assert np.abs(np.array(obs.header.approx_position) - reyk.ecef()).max() < 1e-4
    assert obs.header.marker_name == "REYK"
    epochs = obs.table["time"].unique()
    # 00:00:30 (00:00:00 transmits before the first SP3 epoch) to 23:45:00 (the last SP3 epoch)
    assert epochs.min() == dt.datetime(2019, 1, 14, 0, 0, 30)
    assert epochs.max() == dt.datetime(2019, 1, 14, 23, 45, 0)
    assert epochs.len() == 2850
    again = archive / "again"
    point = f"--point=REYK,{reyk.lat_deg},{reyk.lon_deg},{reyk.height_m}"
    res = CliRunner().invoke(main, ["synth-obs", *PRODUCTS, point, "-o", str(again)])
    assert res.exit_code == 0, res.output
    assert (again / "REYK0140.19o.gz").read_bytes() == (archive / "obs" / "REYK0140.19o.gz").read_bytes()


def test_five_synthetic_stations_over_the_day_on_two_workers(archive: Path, tmp_path: Path) -> None:
    """Issue 15's "done when": the campaign runs on two workers into a dataset, the analysis of the
    dataset reports per station, and each station's partition equals the station run alone."""
    dataset = tmp_path / "net"
    r = CliRunner()
    res = r.invoke(
        main,
        ["sbas", "--campaign", str(archive / "campaign.toml"), "--dataset", str(dataset), "--workers", "2"],
    )
    assert res.exit_code == 0, res.output
    assert sorted(p.station for p in partitions(dataset)) == sorted(p.name for p in FIVE)
    tables = {}
    for p in FIVE:
        run = process(archive / "obs" / f"{p.name}0140.19o.gz", ENGINE / "brdc0140.19n.gz",
                      NET / "egnos123_2019014.ems.gz")  # fmt: skip
        alone = pl.read_parquet(write_run(run, tmp_path / f"{p.name}.parquet")[0])
        written = pl.read_parquet(partition_path(dataset, p.name, DAY))
        assert written.equals(alone), p.name
        tables[p.name] = written
        assert f"station {p.name}: 1 of 1 days written, {written.height} epochs" in res.output
    res = r.invoke(main, ["analyze", str(dataset), "-o", str(tmp_path / "out"), "--workers", "2"])
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert sorted(summary["stations"]) == sorted(tables)
    for name, table in tables.items():
        station = summary["stations"][name]
        assert station["epochs"]["total"] == table.height
        lpv = station["services"]["LPV"]
        solutions = table.filter(pl.col("vpl").is_finite() & pl.col("hpl").is_finite())
        available = solutions.filter((pl.col("vpl") <= 50) & (pl.col("hpl") <= 40)).height
        assert lpv["availability"]["combined"] == pytest.approx(available / table.height, abs=1e-12)
    assert summary["epochs"]["total"] == sum(t.height for t in tables.values())


def test_synth_obs_refuses_what_would_go_wrong(tmp_path: Path) -> None:
    """Two points whose files would have the same name; the P1-P2 biases given for P1-C1; no epoch."""
    r = CliRunner()
    points = ["--point=TOULOUSE,43.6,1.4,200", "--point=toul,43.5,1.5,150"]
    res = r.invoke(main, ["synth-obs", *PRODUCTS, *points, "-o", str(tmp_path / "a")])
    assert res.exit_code == 2 and "points would share a file: TOUL0140.19o.gz, TOUL0140.19o.gz" in res.output
    p1p2 = tmp_path / "P1P21901.DCB"
    p1p2.write_text(
        (NET / "P1C11901.DCB")
        .read_text()
        .replace("P1-C1 DCB SOLUTION", "P1-P2 DCB SOLUTION")
        .replace("(P1-C1)", "(P1-P2)")
    )
    args = [a if a != str(NET / "P1C11901.DCB") else str(p1p2) for a in PRODUCTS]
    res = r.invoke(main, ["synth-obs", *args, "--point=TEST,43.5,1.5,150", "-o", str(tmp_path / "b")])
    assert res.exit_code != 0 and "P1-P2 biases given, P1-C1 needed" in res.output
    assert not (tmp_path / "b").exists()
    res = r.invoke(
        main, ["synth-obs", *PRODUCTS, "--start", "600", "--end", "600", "-o", str(tmp_path / "c")]
    )
    assert res.exit_code == 2 and "--start must be before --end" in res.output
