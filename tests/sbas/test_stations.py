"""Several receivers in one ``overbound sbas`` run: processed station by station, never merged.

A user once gave the synthetic Toulouse and Brussels files of the EGNOS day in one ``--obs``, and
Brussels' records were dropped as "duplicates" of Toulouse's epochs (issue 15).
"""

from __future__ import annotations

import gzip
from pathlib import Path

import polars as pl
import pytest
from click.testing import CliRunner

from overbound.cli import main
from overbound.io.schema import InputError
from overbound.io.table import read_epochs_metadata
from overbound.sbas.run import (
    SAME_STATION_M,
    process,
    process_stations,
    read_inputs,
    read_stations,
    station_names,
)

FIX = Path(__file__).resolve().parents[1] / "data" / "sbas" / "engine"
TLSE = FIX / "SYNT0140_1930-2210.19o.gz"
BRUX = FIX / "SYNB0140_1930-2210.19o.gz"
NAV = FIX / "brdc0140.19n.gz"
EMS = FIX / "ems_1930-2210.ems.gz"


def _split(path: Path, tmp_path: Path, at: str) -> tuple[Path, Path]:
    """The file cut in two at the epoch line starting with ``at``, each half with the header."""
    lines = gzip.open(path, "rt").read().splitlines(keepends=True)
    end = next(i for i, line in enumerate(lines) if "END OF HEADER" in line) + 1
    cut = next(i for i, line in enumerate(lines) if i >= end and line.startswith(at))
    a, b = tmp_path / f"a-{path.name[:-3]}", tmp_path / f"b-{path.name[:-3]}"
    a.write_text("".join(lines[:cut]))
    b.write_text("".join(lines[:end] + lines[cut:]))
    return a, b


def test_two_stations_given_together_equal_each_alone():
    runs = process_stations([TLSE, BRUX], NAV, EMS)
    alone = {r.station: r for r in (process(TLSE, NAV, EMS), process(BRUX, NAV, EMS))}
    assert [r.station for r in runs] == ["SYNB", "SYNT"]  # by name
    for run in runs:
        one = alone[run.station]
        assert run.epochs.height > 300
        assert run.epochs.equals(one.epochs)
        assert run.satellites.equals(one.satellites)
        assert run.counts == one.counts
        assert run.counts["duplicate_observation_rows"] == 0
        assert run.reference_ecef == one.reference_ecef


def test_the_cli_writes_every_station_and_each_equals_its_own_run(tmp_path):
    r = CliRunner()
    args = ["--nav", str(NAV), "--sbas", str(EMS)]
    res = r.invoke(main, ["sbas", "--obs", str(TLSE), str(BRUX), *args, "-o", str(tmp_path / "two.parquet")])
    assert res.exit_code == 0, res.output
    assert "two.parquet station SYNB: 320 epochs" in res.output
    assert "two.parquet station SYNT: 320 epochs" in res.output
    both = pl.read_parquet(tmp_path / "two.parquet")
    sats = pl.read_parquet(tmp_path / "two.sats.parquet")
    meta = read_epochs_metadata(tmp_path / "two.parquet")
    assert sorted(meta["extra"]["sbas_stations"]) == ["SYNB", "SYNT"]
    assert meta["report"]["rows_kept"] == both.height == 640
    for obs, name in ((TLSE, "SYNT"), (BRUX, "SYNB")):
        out = tmp_path / f"{name}.parquet"
        assert r.invoke(main, ["sbas", "--obs", str(obs), *args, "-o", str(out)]).exit_code == 0
        mine = both.filter(pl.col("station") == name)
        assert mine.equals(
            pl.read_parquet(out).with_columns(pl.col("station").cast(pl.String)).cast(mine.schema)
        )
        own = pl.read_parquet(tmp_path / f"{name}.sats.parquet")
        assert sats.filter(pl.col("station") == name).drop("station").equals(own)
        assert meta["extra"]["sbas_stations"][name] == read_epochs_metadata(out)["extra"]["sbas"]


def test_files_of_one_station_are_merged_and_only_their_overlap_is_duplicate(tmp_path):
    a, b = _split(TLSE, tmp_path, " 19  1 14 21  0  0.0")
    runs = process_stations([a, BRUX, b], NAV, EMS)
    whole = process(TLSE, NAV, EMS)
    assert [r.station for r in runs] == ["SYNB", "SYNT"]
    assert runs[1].epochs.equals(whole.epochs)
    assert runs[1].counts["duplicate_observation_rows"] == 0
    again = process_stations([TLSE, BRUX, a], NAV, EMS)  # a overlaps the whole Toulouse file
    assert again[1].counts["duplicate_observation_rows"] == read_inputs(a, NAV, EMS).obs.height
    assert again[1].epochs.equals(whole.epochs)
    assert again[0].counts["duplicate_observation_rows"] == 0


def test_station_names_rules():
    p, q = (4627851.0, 119640.0, 4372993.0), (4027884.0, 307029.0, 4919494.0)
    near = (p[0] + SAME_STATION_M / 2, p[1], p[2])
    far = (p[0] + 2 * SAME_STATION_M, p[1], p[2])
    # one marker, several files of the day: one station; a missing position agrees with any
    assert (
        station_names([("x.19o", "TLSE", p), ("y.19o", "TLSE", near), ("z.19o", "TLSE", None)])
        == ["TLSE"] * 3
    )
    # one marker at two places: two receivers, the second named after its file
    assert station_names([("x.19o", "UNKN", p), ("y.19o", "UNKN", far)]) == ["UNKN", "UNKN-y"]
    # no marker: the header position tells them apart; named after the first file
    assert station_names([("r1.19o", "", p), ("r2.19o", "", q), ("r3.19o", "", p)]) == ["r1", "r2", "r1"]
    # u-blox logs carry neither: one station, as before
    assert station_names([("h01.ubx", "", None), ("h02.ubx", "", None)]) == ["h01", "h01"]
    # a u-blox log joins the only station; with several it is its own, whatever the order of the files
    assert station_names([("t.19o", "SYNT", p), ("x.ubx", "", None)]) == ["SYNT", "SYNT"]
    files = [("x.ubx", "", None), ("r1.19o", "", p), ("r2.19o", "", q)]
    assert station_names(files) == ["x", "r1", "r2"]
    assert station_names(files[::-1]) == ["r2", "r1", "x"]
    # names stay unique: a marker at three places, and a file named as another station
    far2 = (p[0] + 10 * SAME_STATION_M, p[1], p[2])
    assert station_names([("a/X.19o", "M", p), ("b/X.19o", "M", far), ("c/X.19o", "M", far2)]) == [
        "M",
        "M-X",
        "M-X-2",
    ]
    assert station_names([("M-X.19o", "", p), ("X.19o", "M", q), ("Y.19o", "M", p)]) == ["M-X", "M", "M-Y"]
    # a converter's placeholder position (0, 0, 0) is no position
    assert station_names([("a.19o", "", (0.0, 0.0, 0.0)), ("b.ubx", "", None)]) == ["a", "a"]


def test_station_names_given_per_file_or_for_all(tmp_path):
    a, b = _split(TLSE, tmp_path, " 19  1 14 21  0  0.0")
    named = read_stations([a, b, BRUX], NAV, EMS, stations=["T", "T", "B"])
    assert [i.station for i in named] == ["B", "T"]
    assert named[1].obs.height == read_inputs(TLSE, NAV, EMS).obs.height
    # one name for all files: one receiver (today's --station); Brussels' records are then duplicates
    # only where a satellite is seen at one time by both, which the count says
    one = read_inputs([TLSE, BRUX], NAV, EMS, station="X")
    assert one.station == "X" and one.duplicate_observations > 0
    with pytest.raises(ValueError, match="3 station names for 2 observation files"):
        read_stations([TLSE, BRUX], NAV, EMS, stations=["A", "B", "C"])


def test_one_station_api_refuses_several_stations():
    with pytest.raises(InputError, match=r"2 stations \(SYNB, SYNT\)"):
        process([TLSE, BRUX], NAV, EMS)
    with pytest.raises(InputError, match="no GPS L1 C/A pseudoranges"):
        process([], NAV, EMS)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--reference", "43.6,1.4,150"], "one reference position for 2 stations (SYNB, SYNT)"),
        (["--all-subsets"], "--all-subsets and --sp3 take one station; the --obs files hold 2 (SYNB, SYNT)"),
        (["--station", "A", "B", "C"], "3 station names for 2 observation files"),
    ],
)
def test_cli_refuses_what_names_one_station(tmp_path, extra, message):
    out = tmp_path / "x.parquet"
    args = [
        "sbas",
        "--obs",
        str(TLSE),
        str(BRUX),
        "--nav",
        str(NAV),
        "--sbas",
        str(EMS),
        "-o",
        str(out),
        *extra,
    ]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 2
    assert message in res.output
    assert not out.exists()


def test_the_mean_reference_is_each_station_own():
    runs = process_stations([TLSE, BRUX], NAV, EMS, reference="mean")
    alone = {
        r.station: r
        for r in (process(TLSE, NAV, EMS, reference="mean"), process(BRUX, NAV, EMS, reference="mean"))
    }
    for run in runs:
        assert run.reference_source == "mean"
        assert run.reference_ecef == alone[run.station].reference_ecef
        assert run.epochs.equals(alone[run.station].epochs)
