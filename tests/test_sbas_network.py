"""``overbound sbas --campaign``: raw data of a network, station-day by station-day into a dataset
(issue 15, item 2), in this process and on a real ``dask scheduler`` with two workers."""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import re
import shutil
from pathlib import Path

import numpy as np
import polars as pl
import pymap3d
import pytest
from click.testing import CliRunner

from overbound.campaign import campaign_client
from overbound.cli import main
from overbound.io.dataset import partition_path, partitions, read_manifest
from overbound.io.schema import InputError
from overbound.sbas.engine import SbasOptions
from overbound.sbas.run import process, process_inputs, read_inputs, write_run
from overbound.sbas_network import expand, period_inputs, read_campaign, run_network, satellites_root

FIX = Path(__file__).resolve().parent / "data" / "sbas" / "engine"
DAY = dt.date(2019, 1, 14)
CAMPAIGN = """
start = "2019-01-13"   # no observation file that day
end = "2019-01-14"
nav = ["nav/brdc{doy}0.{yy}n.gz"]
sbas = ["ems/*.ems.gz"]

[[stations]]
id = "SYNT"
obs = ["obs/{id}{doy}0.{yy}o.gz"]

[[stations]]
id = "SYNB"
obs = ["obs/{id}{doy}0.{yy}o.gz"]
reference_ecef = [4027884.5253, 307029.6236, 4919494.3651]
"""


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """The campaign's files laid out as a network's archive would be."""
    root = tmp_path / "archive"
    for sub, name, src in (
        ("obs", "SYNT0140.19o.gz", "SYNT0140_1930-2210.19o.gz"),
        ("obs", "SYNB0140.19o.gz", "SYNB0140_1930-2210.19o.gz"),
        ("nav", "brdc0140.19n.gz", "brdc0140.19n.gz"),
        ("ems", "ems_1930-2210.ems.gz", "ems_1930-2210.ems.gz"),
    ):
        (root / sub).mkdir(parents=True, exist_ok=True)
        shutil.copy(FIX / src, root / sub / name)
    (root / "campaign.toml").write_text(CAMPAIGN)
    return root


def _alone(folder: Path, station: str, reference=None):
    obs = folder / "obs" / f"{station}0140.19o.gz"
    return process(obs, FIX / "brdc0140.19n.gz", FIX / "ems_1930-2210.ems.gz", reference=reference)


def _assert_partitions_equal_single_runs(folder: Path, dataset: Path, tmp_path: Path) -> None:
    campaign = read_campaign(folder / "campaign.toml")
    for s in campaign.stations:
        run = _alone(folder, s.id, s.reference)
        written = pl.read_parquet(partition_path(dataset, s.id, DAY))
        alone = pl.read_parquet(write_run(run, tmp_path / f"{s.id}.parquet")[0])
        assert written.equals(alone)
        assert pl.read_parquet(partition_path(satellites_root(dataset), s.id, DAY)).equals(run.satellites)


def test_each_station_day_equals_the_station_processed_alone(folder: Path, tmp_path: Path) -> None:
    dataset = tmp_path / "net"
    outcomes = run_network(read_campaign(folder / "campaign.toml"), dataset)
    assert [(o.station, o.date, o.status) for o in outcomes] == [
        ("SYNT", "2019-01-13", "no observations"),
        ("SYNT", "2019-01-14", "written"),
        ("SYNB", "2019-01-13", "no observations"),
        ("SYNB", "2019-01-14", "written"),
    ]
    assert [p.key for p in partitions(dataset)] == [
        "station=SYNB/date=2019-01-14",
        "station=SYNT/date=2019-01-14",
    ]
    _assert_partitions_equal_single_runs(folder, dataset, tmp_path)
    assert pl.scan_parquet(dataset / "**" / "*.parquet", hive_partitioning=True).collect().height == 640
    synt = outcomes[1]
    assert synt.epochs == 320 and synt.solutions == 308
    assert synt.counts["reasons"] == _alone(folder, "SYNT").counts["engine"]["reasons"]
    assert synt.files == ("obs/SYNT0140.19o.gz",)
    manifest = read_manifest(dataset)
    [entry] = manifest["sbas_network"]
    assert [o["status"] for o in entry["outcomes"]] == [o.status for o in outcomes]
    assert outcomes[0].reason == "no observation file"
    # each station's reference: the one given, else the RINEX header the engine used
    given = pymap3d.ecef2geodetic(4027884.5253, 307029.6236, 4919494.3651)
    assert manifest["stations"]["SYNB"]["reference"] == pytest.approx(list(given), abs=1e-9)
    assert manifest["stations"]["SYNT"]["reference"][0] == pytest.approx(43.56, abs=0.01)


def test_a_period_processed_warm_equals_one_continuous_run() -> None:
    """A split at 21:00 with 20 minutes of messages read first gives the continuous run's epochs
    and satellites to the last bit; without them (cold), the first minutes differ."""
    inp = read_inputs(
        FIX / "SYNT0140_1930-2210.19o.gz", FIX / "brdc0140.19n.gz", FIX / "ems_1930-2210.ems.gz"
    )
    options = SbasOptions()
    whole = process_inputs(inp, None, options)
    split = int(np.datetime64("2019-01-14T21:00:00", "us").astype(np.int64))
    end = split + 86_400_000_000

    def after(table: pl.DataFrame) -> pl.DataFrame:
        return table.filter(pl.col("time") >= dt.datetime(2019, 1, 14, 21))

    warm = process_inputs(period_inputs(inp, split, end, 1200.0), None, options)
    assert warm.epochs.equals(after(whole.epochs))
    assert warm.satellites.equals(after(whole.satellites))
    cold = process_inputs(period_inputs(inp, split, end, 0.0), None, options)
    assert cold.epochs.height == warm.epochs.height
    lost = (cold.epochs["vpl"].is_finite() != warm.epochs["vpl"].is_finite()).sum()
    assert lost > 0, "a cold start loses solutions, which the warm start keeps"
    before = process_inputs(period_inputs(inp, 0, split, 0.0), None, options)
    assert pl.concat([before.epochs, warm.epochs]).equals(whole.epochs)


def test_on_a_real_scheduler_with_two_workers(folder: Path, tmp_path: Path, scheduler: str) -> None:
    client = campaign_client(scheduler=scheduler)
    try:
        client.wait_for_workers(2, timeout=60)
        outcomes = run_network(read_campaign(folder / "campaign.toml"), tmp_path / "net", client=client)
    finally:
        client.close()
    local = run_network(read_campaign(folder / "campaign.toml"), tmp_path / "here")
    assert outcomes == local
    _assert_partitions_equal_single_runs(folder, tmp_path / "net", tmp_path)


def test_a_station_day_that_fails_is_reported_and_the_rest_goes_on(folder: Path, tmp_path: Path) -> None:
    (folder / "obs" / "BADS0140.19o.gz").write_bytes(b"not a RINEX file\n")
    text = (
        CAMPAIGN.replace('start = "2019-01-13"', 'start = "2019-01-14"')
        + '\n[[stations]]\nid = "BADS"\nobs = ["obs/{id}{doy}0.{yy}o.gz"]\n'
    )
    (folder / "campaign.toml").write_text(text)
    outcomes = run_network(read_campaign(folder / "campaign.toml"), tmp_path / "net")
    assert [o.status for o in outcomes] == ["written", "written", "failed"]
    assert "unknown format for --obs" in outcomes[2].reason
    assert [p.station for p in partitions(tmp_path / "net")] == ["SYNB", "SYNT"]
    # run again with Toulouse's file gone: its earlier partition is removed, not left behind
    (folder / "obs" / "SYNT0140.19o.gz").unlink()
    again = run_network(read_campaign(folder / "campaign.toml"), tmp_path / "net")
    assert [(o.status, o.replaced) for o in again] == [
        ("no observations", True),
        ("written", True),
        ("failed", False),
    ]
    assert [p.station for p in partitions(tmp_path / "net")] == ["SYNB"]
    assert not partition_path(satellites_root(tmp_path / "net"), "SYNT", DAY).exists()
    assert len(read_manifest(tmp_path / "net")["sbas_network"]) == 2


def test_the_command_line_and_the_analysis_per_station(folder: Path, tmp_path: Path) -> None:
    r = CliRunner()
    dataset = tmp_path / "net"
    res = r.invoke(
        main,
        ["sbas", "--campaign", str(folder / "campaign.toml"), "--dataset", str(dataset), "--workers", "0"],
    )
    assert res.exit_code == 0, res.output
    assert (
        "station SYNT: 1 of 2 days written, 320 epochs, 308 with a PA solution; 2019-01-13 no observations"
        in res.output
    )
    res = r.invoke(
        main, ["analyze", str(dataset), "-o", str(tmp_path / "out"), "--counting-only", "--workers", "0"]
    )
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert sorted(summary["stations"]) == ["SYNB", "SYNT"]
    assert summary["epochs"]["total"] == 640
    res = r.invoke(
        main, ["sbas", "--campaign", str(folder / "campaign.toml"), "--obs", str(FIX / "brdc0140.19n.gz")]
    )
    assert res.exit_code == 2 and "--campaign names its own files" in res.output
    res = r.invoke(
        main, ["sbas", "--campaign", str(folder / "campaign.toml"), "--dataset", "d", "--mode", "NPA"]
    )
    assert res.exit_code == 2 and "--mode with --campaign" in res.output
    res = r.invoke(main, ["sbas", "--obs", str(FIX / "brdc0140.19n.gz"), "-o", "x.parquet", "--workers", "2"])
    assert res.exit_code == 2 and "--workers: with --campaign only" in res.output


_ONE = '[[stations]]\nid = "A"\nobs = ["a"]\n'


def test_patterns_and_errors(folder: Path, tmp_path: Path) -> None:
    campaign = read_campaign(folder / "campaign.toml")
    assert expand(folder, ["obs/{id}{doy}0.{yy}o.gz"], DAY, "SYNT") == [folder / "obs" / "SYNT0140.19o.gz"]
    assert expand(folder, ["x/{week}{dow}/{yyyy}-{mm}-{dd}"], DAY) == []  # GPS week 2036, Monday
    assert campaign.days == [dt.date(2019, 1, 13), DAY]
    assert dataclasses.asdict(campaign.options) == dataclasses.asdict(SbasOptions())
    bad = tmp_path / "bad.toml"
    for text, message in (
        ("end = 1", "start missing"),
        ('start = "2019-01-14"\n', "no [[stations]]"),
        ('start = "2019-01-14"\n[[stations]]\nobs = ["a"]\n', "stations[0].id missing"),
        (
            'start = "2019-01-14"\nend = "2019-01-01"\n[[stations]]\nid = "A"\nobs = ["a"]\n',
            "is before start",
        ),
        ("start = [", "not TOML"),
        ('start = "2019-01-14"\n[stations]\nid = "A"\n', "stations: a list of tables"),
        ('start = "2019-01-14"\ngeo = "120"\n' + _ONE, "geo '120': a GEO PRN"),
        ('start = "2019-01-14"\nmask = 95\n' + _ONE, "mask 95: degrees"),
        ("start = 2019-01-14T12:00:00\n" + _ONE, "a GPS day (YYYY-MM-DD), without a time"),
        ('start = "2019-01-14"\n[[stations]]\nid = "A/B"\nobs = ["a"]\n', "a partition's folder name"),
        ('start = "2019-01-14"\nsbas = ["{month}/*.ems"]\n' + _ONE, "unknown token 'month'"),
    ):
        bad.write_text(text)
        with pytest.raises(InputError, match=re.escape(message)) as err:
            read_campaign(bad)
        assert str(bad) in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(InputError, match="unknown token"):
        expand(folder, ["{month}"], DAY)
