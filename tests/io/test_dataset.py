"""The campaign dataset (issue 14, first part): ingest splits by station and GPS day, and the
dataset analyses as the same table as its inputs."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import polars as pl
import pytest
from click.testing import CliRunner

from overbound.cli import main
from overbound.io.dataset import MANIFEST, create_dataset, ingest, partitions, read_manifest
from overbound.io.open import read
from overbound.io.schema import InputError
from overbound.simulate import SimulationConfig, simulate, write_simulation


@pytest.fixture(scope="module")
def network(tmp_path_factory) -> Path:
    """3 stations x 2 days at 10 s: every station crosses one midnight."""
    path = tmp_path_factory.mktemp("net") / "net.parquet"
    write_simulation(simulate(SimulationConfig(days=2, stations=3, interval_s=10.0, seed=4)), path)
    return path


def test_ingest_splits_by_station_and_gps_day(network: Path, tmp_path: Path) -> None:
    table, _ = read(network)
    result = ingest(tmp_path / "ds", [network])
    parts = partitions(tmp_path / "ds")
    assert [p.key for p in parts] == [p.key for p in result.written]
    assert {p.station for p in parts} == set(table["station"].unique())
    assert len(parts) == 3 * 2 and result.replaced == ()
    assert sum(result.rows.values()) == table.height
    for p in parts:
        part, report = read(p.path)
        assert part["station"].unique().to_list() == [p.station]
        assert part["time"].dt.date().unique().to_list() == [p.date]
        assert report.unaccounted == 0 and part.height == result.rows[p.key]
    manifest = read_manifest(tmp_path / "ds")
    assert sorted(manifest["stations"]) == sorted(table["station"].unique().to_list())
    (entry,) = manifest["inputs"]
    assert entry["reports"][0]["rows_read"] == table.height and entry["partitions"] == [p.key for p in parts]


def test_reingesting_replaces_and_says_so(network: Path, tmp_path: Path) -> None:
    ingest(tmp_path / "ds", [network])
    day = read(network)[0].filter(pl.col("time").dt.date() == dt.date(2024, 1, 8))
    one = tmp_path / "day2.parquet"
    day.write_parquet(one)
    result = ingest(tmp_path / "ds", [one])
    assert sorted(result.replaced) == sorted(p.key for p in result.written) and len(result.written) == 3
    assert all(k.endswith("date=2024-01-08") for k in result.replaced)
    assert not list((tmp_path / "ds").rglob(".*tmp*")), "no temporary file left"
    assert len(read_manifest(tmp_path / "ds")["inputs"]) == 2


def test_an_unreadable_input_leaves_the_dataset_as_it_was(network: Path, tmp_path: Path) -> None:
    ingest(tmp_path / "ds", [network])
    before = {p: p.stat().st_mtime_ns for p in (tmp_path / "ds").rglob("*")}
    bad = tmp_path / "bad.pos"
    bad.write_text("not an epoch file\n")
    with pytest.raises(InputError, match=r"bad\.pos"):
        ingest(tmp_path / "ds", [network, bad])
    assert {p: p.stat().st_mtime_ns for p in (tmp_path / "ds").rglob("*")} == before


def test_a_directory_that_is_not_a_dataset_is_refused(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(InputError, match="not an overbound dataset"):
        create_dataset(tmp_path)
    res = CliRunner().invoke(main, ["analyze", str(tmp_path), "-o", str(tmp_path / "out")])
    assert res.exit_code == 2 and res.output.count("\n") == 1 and "is a directory" in res.output


def test_time_window_of_a_dataset_is_counted(network: Path, tmp_path: Path) -> None:
    ingest(tmp_path / "ds", [network])
    table, report = read(tmp_path / "ds", time_range=(dt.datetime(2024, 1, 7, 12), None))
    assert table["time"].min() >= dt.datetime(2024, 1, 7, 12)
    assert report.rejected["outside_time_range"] == report.rows_read - table.height > 0
    assert report.unaccounted == 0


def test_analyze_of_the_dataset_equals_analyze_of_the_file(network: Path, tmp_path: Path) -> None:
    """Counts, availability, continuity across both midnights, accuracy: the same numbers."""
    runner = CliRunner()
    assert runner.invoke(main, ["ingest", str(tmp_path / "ds"), str(network)]).exit_code == 0
    docs = []
    for source, out in ((network, "file"), (tmp_path / "ds", "dataset")):
        res = runner.invoke(
            main, ["analyze", str(source), "--no-evt", "--no-confidence", "-o", str(tmp_path / out)]
        )
        assert res.exit_code == 0, res.output
        docs.append(json.loads((tmp_path / out / "summary.json").read_text()))
    a, b = docs
    assert set(b) - set(a) == {"network"}  # the per-day availability and partitions of a dataset
    different = sorted(k for k in a if a[k] != b[k])
    assert different == ["inputs", "provenance", "title"], different
    assert a["services"]["LPV"]["continuity"] == b["services"]["LPV"]["continuity"]
    assert (
        b["inputs"][0]["format"] == "dataset" and b["inputs"][0]["rows_read"] == a["inputs"][0]["rows_kept"]
    )
    assert (tmp_path / "ds" / MANIFEST).exists()


def test_simulate_into_a_dataset_gives_the_simulators_station_days_byte_for_byte(tmp_path: Path) -> None:
    """Each partition is today's simulation restricted to that station-day, written the same way."""
    from overbound import __version__
    from overbound.io.dataset import write_partition
    from overbound.simulate import write_simulation_dataset

    config = SimulationConfig(days=2.5, stations=2, interval_s=2.0, seed=3)
    written = write_simulation_dataset(config, tmp_path / "ds")
    sim = simulate(config)
    truth = {t.name: t.to_dict() for t in sim.stations}
    assert [p.key for p in written] == [p.key for p in partitions(tmp_path / "ds")] and len(written) == 2 * 3
    for p in written:
        day = sim.table.filter((pl.col("station") == p.station) & (pl.col("time").dt.date() == p.date))
        generator = f"overbound.simulate {__version__}"
        extra = {
            "simulation": {"generator": generator, "config": config.to_dict(), "station": truth[p.station]}
        }
        reference = write_partition(tmp_path / "ref", day, extra=extra)
        assert reference.path.read_bytes() == p.path.read_bytes(), p.key
    assert sum(read(p.path)[0].height for p in written) == sim.table.height
    manifest = read_manifest(tmp_path / "ds")
    assert manifest["simulation"]["stations"] == [truth["SIM01"], truth["SIM02"]]


def test_simulate_command_writes_a_dataset_for_a_directory(tmp_path: Path) -> None:
    res = CliRunner().invoke(
        main, ["simulate", "--days", "1.5", "--stations", "2", "--interval", "30", "-o", str(tmp_path / "ds")]
    )
    assert res.exit_code == 0, res.output
    assert res.output.endswith("4 station-days of 2 stations (dataset)\n")
    assert len(partitions(tmp_path / "ds")) == 4


def test_ingest_says_when_the_input_names_another_station(tmp_path: Path) -> None:
    """--station names a station only where the input names none: an input that names its own
    (the .pos header's USLO) keeps it, and the terminal says so, not only the manifest."""
    pos = Path(__file__).parents[2] / "src" / "overbound" / "data" / "uslo-2006-361-waas.pos.gz"
    ref = "35.311803,-120.661092,134.6419"
    res = CliRunner().invoke(
        main, ["ingest", str(tmp_path / "ds"), str(pos), "--reference", ref, "--station", "FOO"]
    )
    assert res.exit_code == 0, res.output
    assert "station argument 'FOO' ignored: the header names USLO" in res.output
    assert [p.station for p in partitions(tmp_path / "ds")] == ["USLO"]
