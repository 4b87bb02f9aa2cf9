"""--start/--end: ISO 8601 with ``T`` or a space, a trailing ``Z`` or an offset, and --time-scale utc|gps.

GPS-UTC values from IERS Bulletin C: 14 s from 2006-01-01, 18 s from 2017-01-01.
"""

from __future__ import annotations

import datetime as dt
import json
from importlib.resources import files
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from overbound.cli import _gps_time, _Instant, main

USLO = str(files("overbound") / "data" / "uslo-2006-361-waas.pos.gz")
TRUTH = "35.311803,-120.661092,134.6419"


@pytest.mark.parametrize(
    "text, want",
    [
        ("2024-01-07T06:00:00", (dt.datetime(2024, 1, 7, 6), False)),
        ("2024-01-07 06:00:00", (dt.datetime(2024, 1, 7, 6), False)),
        ("2024-01-07 06:00:00Z", (dt.datetime(2024, 1, 7, 6), True)),
        ("2024-01-07T06:00:00.5z", (dt.datetime(2024, 1, 7, 6, 0, 0, 500_000), True)),
        ("2024-01-07T08:00:00+02:00", (dt.datetime(2024, 1, 7, 6), True)),
        ("2024-01-07", (dt.datetime(2024, 1, 7), False)),
    ],
)
def test_instant_spellings(text, want):
    assert _Instant().convert(text, None, None) == want


def test_instant_refuses_a_bad_date():
    with pytest.raises(click.BadParameter, match="expected an ISO 8601 time"):
        _Instant().convert("2024-13-01", None, None)


def test_utc_to_gps_time_with_the_leap_seconds_then():
    assert _gps_time((dt.datetime(2017, 1, 1), True), "gps") == dt.datetime(2017, 1, 1, 0, 0, 18)
    assert _gps_time((dt.datetime(2016, 12, 31, 23, 59, 59), False), "utc") == dt.datetime(
        2017, 1, 1, 0, 0, 16
    )
    assert _gps_time((dt.datetime(2006, 12, 27), False), "utc") == dt.datetime(2006, 12, 27, 0, 0, 14)
    assert _gps_time((dt.datetime(2006, 12, 27), False), "gps") == dt.datetime(2006, 12, 27)
    assert _gps_time(None, "utc") is None


def _epochs(tmp_path: Path, name: str, *window: str) -> dict:
    out = tmp_path / name
    args = ["analyze", USLO, "--reference", TRUTH, "-o", str(out), "--no-evt", "--no-parametric",
            "--no-confidence", *window]  # fmt: skip
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    return json.loads((out / "summary.json").read_text())["time"]


def test_a_utc_window_is_the_gps_window_14_s_later(tmp_path: Path):
    gps = _epochs(tmp_path, "gps", "--start", "2006-12-27T00:30:14", "--end", "2006-12-27T00:45:14")
    zulu = _epochs(tmp_path, "z", "--start", "2006-12-27 00:30:00Z", "--end", "2006-12-27T00:45:00Z")
    scale = _epochs(tmp_path, "s", "--time-scale", "utc", "--start", "2006-12-27 00:30", "--end",
                    "2006-12-27T00:45:00")  # fmt: skip
    assert gps == zulu == scale
    assert gps["start"] >= "2006-12-27T00:30:14" and gps["end"] < "2006-12-27T00:45:14"
    plain = _epochs(tmp_path, "p", "--start", "2006-12-27T00:30:00", "--end", "2006-12-27T00:45:00")
    assert plain != gps  # 14 s apart: the window moves


@pytest.mark.parametrize(
    "start, first", [("2006-12-27T00:29:46Z", "00:30:00"), ("2006-12-27T00:29:47Z", "00:30:30")]
)
def test_utc_start_to_the_second(tmp_path: Path, start: str, first: str):
    """USLO has an epoch every 30 s: 00:29:46 UTC is 00:30:00 GPST, one second later is past it."""
    assert _epochs(tmp_path, "w", "--start", start)["start"].startswith(f"2006-12-27T{first}")


def test_a_window_that_leaves_no_epoch_is_one_line(tmp_path: Path):
    run = CliRunner().invoke(main, ["analyze", USLO, "--reference", "35.311803,-120.661092,134.6419",
                                    "--start", "2007-01-01", "-o", str(tmp_path / "out")])  # fmt: skip
    assert (
        run.exit_code == 2 and "no epoch left to analyse" in run.output and "outside_time_range" in run.output
    )
    assert not (tmp_path / "out").exists()
