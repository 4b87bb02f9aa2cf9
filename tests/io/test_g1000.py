"""Garmin G1000 flight-data logs (issue 16): the eight real flights of tests/data/g1000 and the quirks.

Expected counts are the table of tests/data/g1000/PROVENANCE.md (counted there with other tools):
rows, rows with WAAS PLs and a position, the UTC span. The values are checked against Python's own
``csv`` module reading the same files.
"""

from __future__ import annotations

import csv
import datetime as dt
import gzip
import io
import zipfile
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from overbound.io.g1000 import read_g1000
from overbound.io.geodesy import Reference
from overbound.io.open import expand_archives, read, sniff
from overbound.io.schema import InputError

DATA = Path(__file__).resolve().parents[1] / "data" / "g1000"
ZIP = DATA / "ProximityTestFlights.zip"

#: name: (rows, PL rows, first UTC, GPS-UTC) from PROVENANCE.md and IERS Bulletin C
FLIGHTS = {
    "log_110701_131851_KGFK.csv.gz": (6205, 6204, "2011-07-01 18:18:41", 15),
    "log_110812_095915_KCKN.csv.gz": (3967, 3966, "2011-08-12 14:59:07", 15),
    "log_111123_121305_KGFK.csv.gz": (6343, 6327, "2011-11-23 18:12:56", 15),
    "log_141029_100200_KGFK-2.csv.gz": (1973, 1928, "2014-10-29 15:01:49", 16),
    "log_180801_114937_KGFK.csv.gz": (5864, 5730, "2018-08-01 16:49:29", 18),
    "flight_1934579.csv": (10681, 10635, "2024-07-20 12:25:12", 18),
    "flight_1936026.csv": (7647, 7438, "2024-07-20 12:43:41", 18),
    "flight_1936336.csv": (8158, 8060, "2024-07-20 12:39:28", 18),
}


def _sources():
    return [*sorted(DATA.glob("*.csv.gz")), *expand_archives([ZIP])]


def _key(src) -> str:
    return Path(getattr(src, "name", str(src))).name


def _csv_rows(src) -> list[dict[str, str]]:
    """The data rows by Python's csv module, names and values stripped."""
    raw = gzip.decompress(src.read_bytes()) if isinstance(src, Path) else src.getvalue()
    lines = raw.rstrip(b"\x00").decode().splitlines()
    reader = csv.reader(lines[2:])
    head = [c.strip() for c in next(reader)]
    # a row cut short (the recording's last) is not a row the reader keeps
    return [dict(zip(head, (v.strip() for v in row), strict=True)) for row in reader if len(row) == len(head)]


def test_zip_is_three_flights_and_all_are_sniffed_as_g1000():
    members = expand_archives([ZIP])
    assert [_key(m) for m in members] == ["flight_1934579.csv", "flight_1936026.csv", "flight_1936336.csv"]
    with zipfile.ZipFile(ZIP) as z:
        assert [m.getvalue() for m in members] == [z.read(n) for n in z.namelist()]
    assert {sniff(s) for s in _sources()} == {"g1000"}


@pytest.mark.parametrize("src", _sources(), ids=_key)
def test_every_row_and_pl_epoch_of_the_provenance_table(src):
    rows, pl_rows, first_utc, leap = FLIGHTS[_key(src)]
    table, report = read(src)
    assert report.format == "g1000" and report.truth is False
    assert report.rows_read == rows
    assert report.unaccounted == 0  # kept + rejected = read
    note = next(n for n in report.notes if "rows with WAAS protection levels" in n)
    assert int(note.split()[0]) == pl_rows
    kept_pl = int(table["hpl"].is_finite().sum())
    assert int(note.split("; ")[1].split()[0]) == kept_pl
    assert report.rejected["truncated_line"] == 1  # every recording ends mid-line
    assert set(report.rejected) <= {"truncated_line", "repeated_second", "backward_time", "no_time"}
    # the repeated and backward seconds are exactly the rows whose local time does not increase
    local = [r["Lcl Date"] + " " + r["Lcl Time"] for r in _csv_rows(src)]
    times = [dt.datetime.strptime(t, "%Y-%m-%d %H:%M:%S") for t in local if t.strip()]
    assert report.rejected.get("no_time", 0) == len(local) - len(times)
    latest, not_after = times[0], 0
    for t in times[1:]:
        not_after += t <= latest
        latest = max(latest, t)
    assert report.rejected.get("repeated_second", 0) + report.rejected.get("backward_time", 0) == not_after
    # GPS time = local - offset + leap seconds; the first solution-bearing UTC second of the provenance
    first = dt.datetime.fromisoformat(first_utc) + dt.timedelta(seconds=leap)
    assert table["time"][0] == first
    assert table["time"].is_sorted() and table["time"].n_unique() == table.height
    assert table["hpe"].is_nan().all() and table["vpe"].is_nan().all()


@pytest.mark.parametrize("src", _sources()[:1] + _sources()[-1:], ids=_key)
def test_values_equal_pythons_csv_module(src):
    table, _ = read(src)
    rows = _csv_rows(src)
    seen: dict[str, dict[str, str]] = {}
    for r in rows:  # the first row of each local second is the one kept
        seen.setdefault(r["Lcl Date"] + " " + r["Lcl Time"], r)
    want = [
        r for r in seen.values()
        if r["HPLwas"] and r["VPLwas"] and r["Latitude"] and r["GPSfix"] != "NoSoln"
    ]  # fmt: skip
    got = table.filter(pl.col("hpl").is_finite())
    assert got.height == len(want)
    np.testing.assert_array_equal(got["hpl"].to_numpy(), [float(r["HPLwas"]) for r in want])
    np.testing.assert_array_equal(got["vpl"].to_numpy(), [float(r["VPLwas"]) for r in want])
    hal = [float(r["HAL"]) if r["HAL"] and float(r["HAL"]) > 0 else np.nan for r in want]
    np.testing.assert_array_equal(got["hal"].to_numpy(), hal)
    assert got["val"].is_nan().all()  # no approach with a VAL in these flights


_HEAD = (
    '#airframe_info, log_version="1.00", airframe_name="Cessna 172S", unit_software_version="10.01", '
    'system_id="X1", mode=NORMAL, \n'
    "#yyy-mm-dd, hh:mm:ss,   hh:mm,      degrees, ft wgs, enum,   mt,    mt,     mt,    mt,     mt\n"
    "  Lcl Date, Lcl Time, UTCOfst,     Latitude,  AltGPS, GPSfix,  HAL,   VAL, HPLwas, HPLfd, VPLwas\n"
)


def _log(*rows: str) -> io.StringIO:
    f = io.StringIO(_HEAD + "".join(r + "\n" for r in rows))
    f.name = "quirks.csv"
    return f


def test_quirks_are_counted_not_fatal():
    # no offset; a repeat; the new year; backward; no solution; NoSoln
    log = _log(
        "2016-12-31, 17:59:58,        ,   47.9, 800.0, 3DDiff, 1852,      ,     10,  11.0,     15",
        "2016-12-31, 17:59:59,  -06:00,   47.9, 800.0, 3DDiff, 1852,      ,     10,  11.0,     15",
        "2016-12-31, 17:59:59,  -06:00,   47.9, 800.0, 3DDiff, 1852,      ,     99,  11.0,     99",
        "2016-12-31, 18:00:01,  -06:00,   47.9, 800.0, 3DDiff,    0,    35,     12,  11.0,     16",
        "2016-12-31, 18:00:00,  -06:00,   47.9, 800.0, 3DDiff, 1852,      ,     12,  11.0,     16",
        "2016-12-31, 18:00:02,  -06:00,       , 800.0, NoSoln,    0,      ,       ,      ,       ",
        "2016-12-31, 18:00:03,  -06:00,   47.9, 800.0, NoSoln, 1852,      ,     12,  11.0,     16",
    )
    table, report = read_g1000(log)
    assert report.rows_read == 7 and report.rows_kept == 5 and report.unaccounted == 0
    assert report.rejected == {"repeated_second": 1, "backward_time": 1}
    # 17:59:58 local at -06:00 is 23:59:58 UTC on 2016-12-31 (17 s), 18:00:01 is 00:00:01 UTC in 2017 (18 s)
    assert table["time"].to_list()[:3] == [
        dt.datetime(2017, 1, 1, 0, 0, 15),
        dt.datetime(2017, 1, 1, 0, 0, 16),
        dt.datetime(2017, 1, 1, 0, 0, 19),
    ]
    assert table["hpl"].to_list()[:3] == [10.0, 10.0, 12.0]  # the first of the repeated second kept
    assert np.isnan(table["hpl"][3]) and np.isnan(table["hpl"][4])  # no PL, then NoSoln
    assert table["hal"].to_list()[:2] == [1852.0, 1852.0] and np.isnan(table["hal"][2])  # 0: none in force
    assert table["val"][2] == 35.0
    assert table["station"][0] == "quirks"
    assert any("1 rows with a time but no UTC offset took the next row" in n for n in report.notes)


def test_strict_names_the_line_of_a_repeated_second():
    log = _log(
        "2016-06-01, 10:00:00,  -05:00,   47.9, 800.0, 3DDiff, 1852,      ,     10,  11.0,     15",
        "2016-06-01, 10:00:00,  -05:00,   47.9, 800.0, 3DDiff, 1852,      ,     10,  11.0,     15",
    )
    with pytest.raises(InputError, match=r"quirks.csv:5: repeated second"):
        read_g1000(log, strict=True)


def test_refusals_name_the_file():
    with pytest.raises(InputError, match=r"quirks\.csv.*no truth"):
        read_g1000(_log(), reference=Reference(47.9, -97.0, 250.0))
    with pytest.raises(InputError, match=r"quirks\.csv.*no data rows"):
        read_g1000(_log())
    bad = io.StringIO(_HEAD.replace("HPLwas", "HPLxx"))
    bad.name = "bad.csv"
    with pytest.raises(InputError, match=r"bad.csv:3: G1000 log without column\(s\) HPLwas"):
        read_g1000(bad)
