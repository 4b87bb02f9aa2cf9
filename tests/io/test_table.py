"""Parquet/CSV epoch tables: column rules, mapping, provenance, round trips."""

from __future__ import annotations

import contextlib
import datetime as dt
import gzip
import io
import json
from importlib.resources import files
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from polars.testing import assert_frame_equal

import overbound
from overbound.io.geodesy import Reference
from overbound.io.rtklib import read_rtklib_pos
from overbound.io.schema import InputError
from overbound.io.table import (
    METADATA_KEY,
    PER_COLUMN,
    read_csv,
    read_epochs_metadata,
    read_parquet,
    scan_epochs,
    write_epochs,
)

USLO = Path(str(files("overbound") / "data" / "uslo-2006-361-waas.pos.gz"))
TRUTH = Reference(35.311803, -120.661092, 134.6419)


@pytest.fixture(scope="module")
def uslo():
    return read_rtklib_pos(USLO, reference=TRUTH)


def _csv(text: str, **kw):
    return read_csv(io.StringIO(text), **kw)


# --------------------------------------------------------------------------- round trips


def test_round_trip_parquet_csv_identical(uslo, tmp_path: Path) -> None:
    table, report = uslo
    pq = write_epochs(table, tmp_path / "uslo.parquet", report=report, extra_metadata={"run": "test26-ws"})
    csv = write_epochs(table, tmp_path / "uslo.csv")
    from_pq, rep_pq = read_parquet(pq)
    from_csv, rep_csv = read_csv(csv)
    assert_frame_equal(from_pq, table)
    assert_frame_equal(from_csv, table)
    assert (rep_pq.rows_kept, rep_csv.rows_kept) == (2865, 2865)
    assert rep_pq.format == "parquet" and rep_csv.format == "csv"
    # CSV -> Parquet -> CSV again: still the same table
    pq2 = write_epochs(from_csv, tmp_path / "again.parquet")
    csv2 = write_epochs(read_parquet(pq2)[0], tmp_path / "again.csv")
    assert_frame_equal(read_csv(csv2)[0], table)
    assert csv2.read_bytes() == csv.read_bytes()


def test_round_trip_keeps_nan_null_and_optional_columns(tmp_path: Path) -> None:
    table = pl.DataFrame(
        {
            "time": [dt.datetime(2020, 1, 1, 0, 0, 0, 123456), dt.datetime(2020, 1, 1, 0, 0, 1)],
            "station": ["A", "A"],
            "hpe": [0.1 + 0.2, float("nan")],
            "vpe": [-1 / 3, float("nan")],
            "hpl": [1e-300, float("nan")],
            "vpl": [12.5, float("nan")],
            "nsv": [7, None],
            "mode": ["PA", None],
            "alert": [False, True],
        }
    )
    table, _ = read_parquet(write_epochs(table, tmp_path / "t.parquet"))
    for path in (tmp_path / "t.csv", tmp_path / "t.parquet"):
        back, _ = (read_csv if path.suffix == ".csv" else read_parquet)(write_epochs(table, path))
        assert_frame_equal(back, table)
    assert table["hpe"][0] == 0.30000000000000004 and table["time"][0].microsecond == 123456
    assert table["nsv"].to_list() == [7, None] and table["alert"].to_list() == [False, True]


def test_parquet_provenance(uslo, tmp_path: Path) -> None:
    table, report = uslo
    path = write_epochs(table, tmp_path / "uslo.parquet", report=report, extra_metadata={"run": "test26-ws"})
    meta = read_epochs_metadata(path)
    assert meta["source"] == str(USLO) and meta["format"] == "rtklib-pos"
    assert meta["overbound_version"] == overbound.__version__
    assert meta["report"] == report.to_dict() and meta["report"]["rows_kept"] == 2865
    assert meta["extra"] == {"run": "test26-ws"}
    raw = pl.read_parquet_metadata(path)[METADATA_KEY]
    assert json.loads(raw) == meta
    _, rep = read_parquet(path)
    assert f"written by overbound {overbound.__version__} from {USLO} (rtklib-pos)" in rep.notes
    _, rep = read_parquet(write_epochs(table, tmp_path / "bare.parquet"))  # no source (a simulation)
    assert f"written by overbound {overbound.__version__}" in rep.notes and "None" not in " ".join(rep.notes)
    assert read_epochs_metadata(write_epochs(table, tmp_path / "bare.parquet")) == {
        "extra": {},
        "format": None,
        "overbound_version": overbound.__version__,
        "report": None,
        "source": None,
    }


def test_parquet_is_zstd_and_reproducible(uslo, tmp_path: Path) -> None:
    import pyarrow.parquet as papq

    a = write_epochs(uslo[0], tmp_path / "a.parquet", report=uslo[1])
    b = write_epochs(uslo[0], tmp_path / "b.parquet", report=uslo[1])
    assert a.read_bytes() == b.read_bytes()
    assert papq.ParquetFile(a).metadata.row_group(0).column(0).compression == "ZSTD"


def _day_at_1hz(n: int = 3600) -> pl.DataFrame:
    rng = np.random.default_rng(5)
    start = dt.datetime(2024, 1, 7)
    return pl.DataFrame(
        {
            "time": pl.datetime_range(start, start + dt.timedelta(seconds=n - 1), "1s", eager=True),
            "station": ["SIM01"] * n,
            "hpe": np.abs(rng.normal(size=n)),
            "vpe": np.where(np.arange(n) % 97 == 0, np.nan, rng.normal(size=n)),
            "hpl": rng.uniform(5, 40, n),
            "vpl": rng.uniform(5, 50, n),
            "nsv": rng.integers(5, 12, n),
            "mode": rng.choice(["PA", "NPA", None], n),
            "alert": rng.random(n) < 0.01,
        }
    )


def test_per_column_layout_reads_back_the_table_and_provenance(tmp_path: Path) -> None:
    """The read-optimised layout of a campaign's partitions: the same table (NaN, nulls, categories,
    flags) and provenance as zstd's, each column encoded as documented, the same bytes every time."""
    import pyarrow.parquet as papq

    table, _ = read_parquet(write_epochs(_day_at_1hz(), tmp_path / "zstd.parquet"))
    a = write_epochs(table, tmp_path / "a.parquet", extra_metadata={"run": 1}, compression=PER_COLUMN)
    b = write_epochs(table, tmp_path / "b.parquet", extra_metadata={"run": 1}, compression=PER_COLUMN)
    assert a.read_bytes() == b.read_bytes()
    back, _ = read_parquet(a)
    assert_frame_equal(back, table)
    assert pl.read_parquet(a).schema == pl.read_parquet(tmp_path / "zstd.parquet").schema
    assert read_epochs_metadata(a)["extra"] == {"run": 1}
    group = papq.ParquetFile(a).metadata.row_group(0)
    chunks = {group.column(i).path_in_schema: group.column(i) for i in range(group.num_columns)}
    assert "DELTA_BINARY_PACKED" in chunks["time"].encodings and chunks["time"].compression == "UNCOMPRESSED"
    for name in ("hpe", "vpe", "hpl", "vpl"):  # float noise: plain, no codec
        assert chunks[name].compression == "UNCOMPRESSED" and "RLE_DICTIONARY" not in chunks[name].encodings
    for name in ("station", "nsv", "mode"):  # few values: dictionary, zstd
        assert chunks[name].compression == "ZSTD" and "RLE_DICTIONARY" in chunks[name].encodings
    assert chunks["alert"].compression == "ZSTD"
    assert chunks["time"].total_compressed_size < chunks["hpe"].total_compressed_size / 20


def test_partitions_are_written_per_column() -> None:
    from overbound.io.dataset import PARTITION_COMPRESSION

    assert PARTITION_COMPRESSION == PER_COLUMN


def test_scan_epochs(uslo, tmp_path: Path) -> None:
    path = write_epochs(uslo[0], tmp_path / "uslo.parquet")
    lf = scan_epochs(path)
    assert isinstance(lf, pl.LazyFrame)
    assert_frame_equal(lf.collect(), uslo[0])
    n_high = uslo[0].filter(pl.col("vpl") >= 50).height
    assert lf.filter(pl.col("vpl") >= 50).select(pl.len()).collect().item() == n_high > 0
    pl.DataFrame({"time": [dt.datetime(2020, 1, 1)], "hpl": [1.0]}).write_parquet(tmp_path / "bad.parquet")
    with pytest.raises(InputError, match="missing column"):
        scan_epochs(tmp_path / "bad.parquet")


def test_write_unknown_suffix(uslo, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"unknown suffix '\.txt'"):
        write_epochs(uslo[0], tmp_path / "x.txt")


# --------------------------------------------------------------------------- column rules

BASE = (
    "time,hpe,vpe,hpl,vpl\n"
    "2006-12-27T00:04:30,1.5,-2.0,20.0,30.0\n"
    "2006-12-27 00:05:00.250,0.5,1.0,21.0,31.0\n"
)


def test_basic_csv_values() -> None:
    table, report = _csv(BASE, station="USLO")
    assert table["time"].to_list() == [
        dt.datetime(2006, 12, 27, 0, 4, 30),
        dt.datetime(2006, 12, 27, 0, 5, 0, 250000),
    ]
    assert table["hpe"].to_list() == [1.5, 0.5] and table["vpl"].to_list() == [30.0, 31.0]
    assert table.columns == ["time", "station", "hpe", "vpe", "hpl", "vpl"]
    assert report.rows_read == 2 and report.n_rejected == 0


def test_stream_equals_path(tmp_path: Path) -> None:
    path = tmp_path / "USLO.csv"
    path.write_text(BASE)
    gz = tmp_path / "USLO.csv.gz"
    gz.write_bytes(gzip.compress(BASE.encode()))
    want, _ = read_csv(path)
    assert want["station"][0] == "USLO"
    for src in (gz, io.StringIO(BASE), io.BytesIO(BASE.encode()), io.BytesIO(gzip.compress(BASE.encode()))):
        got, _ = read_csv(src, station=None if isinstance(src, Path) else "USLO")
        assert_frame_equal(got, want)
    pq = tmp_path / "USLO.parquet"
    write_epochs(want, pq)
    assert_frame_equal(read_parquet(io.BytesIO(pq.read_bytes()))[0], read_parquet(pq)[0])


def test_mapping() -> None:
    text = "t,HPE_m,VPE_m,HPL_m,VPL_m\n2006-12-27T00:04:30,1.5,-2.0,20.0,30.0\n"
    mapping = {"time": "t", "hpe": "HPE_m", "vpe": "VPE_m", "hpl": "HPL_m", "vpl": "VPL_m"}
    table, _ = _csv(text, mapping=mapping, station="X")
    assert table.row(0) == (dt.datetime(2006, 12, 27, 0, 4, 30), "X", 1.5, -2.0, 20.0, 30.0)
    with pytest.raises(InputError, match="mapping names unknown column"):
        _csv(text, mapping={"VPL": "VPL_m"})


def test_missing_columns_lists_missing_and_present() -> None:
    with pytest.raises(InputError) as err:
        _csv("t,hpe,VPL_m\n2006-12-27T00:04:30,1,2\n", mapping={"vpl": "VPL_m"}, station="X")
    msg = str(err.value)
    assert msg.startswith(
        "<stream>: missing column(s) time (or week + tow); hpl; vpe (or positions lat + lon + height)"
    )
    assert msg.endswith("; have t, hpe, VPL_m")


def test_east_north_give_hpe() -> None:
    table, report = _csv("time,east,north,vpe,hpl,vpl\n2006-12-27T00:00:00,3,-4,1,10,20\n", station="X")
    assert table["hpe"][0] == 5.0 and table["east"][0] == 3.0 and table["north"][0] == -4.0
    assert "hpe computed as hypot(east, north)" in report.notes


def test_positions_need_reference_and_match_rtklib(uslo) -> None:
    lines = [ln.split() for ln in gzip.decompress(USLO.read_bytes()).decode().splitlines() if ln[:1] != "%"][
        :5
    ]
    text = "week,tow,lat,lon,height,hpl,vpl\n" + "".join(
        f"1407,{259200 + (dt.datetime.strptime(f[1], '%H:%M:%S.%f') - dt.datetime(1900, 1, 1)).seconds},"
        f"{f[2]},{f[3]},{f[4]},{f[13]},{f[14]}\n"
        for f in lines
    )
    with pytest.raises(InputError, match=r"needs a reference position \(--reference lat,lon,h"):
        _csv(text, station="USLO")
    table, report = _csv(text, station="USLO", reference=TRUTH)
    want = uslo[0].head(5).drop("nsv", "mode")
    assert table["time"].to_list() == want["time"].to_list()
    for c in ("hpe", "vpe", "east", "north"):
        np.testing.assert_allclose(table[c].to_numpy(), want[c].to_numpy(), rtol=0, atol=1e-9)
    assert any(n.startswith("errors computed from lat, lon, height") for n in report.notes)
    assert "time from week + tow (GPS week, seconds of week)" in report.notes


def test_station_column_argument_and_stem(tmp_path: Path) -> None:
    text = "time,station,hpe,vpe,hpl,vpl\n2006-12-27T00:00:00,A,1,1,10,20\n2006-12-27T00:00:00,,1,1,10,20\n"
    table, report = _csv(text, station="B")
    assert table["station"].cast(pl.String).to_list() == ["A", "B"]
    assert "1 empty station cells set to B from the station argument" in report.notes
    assert "station argument 'B' not used where the station column names A" in report.notes
    path = tmp_path / "site42.epochs.csv.gz"
    path.write_bytes(gzip.compress(BASE.encode()))
    assert read_csv(path)[0]["station"][0] == "site42"


# --------------------------------------------------------------------------- bad rows (CSV line numbers)

HEAD = "time,hpe,vpe,hpl,vpl,nsv,alert\n"
OK_ROW = "2006-12-27T00:00:{s:02d},1.0,-1.0,10.0,20.0,7,false\n"
CASES = {
    # name: (row text at line 3, rows kept, rejected, invalidated, first_bad)
    "non-numeric-hpl": (
        "2006-12-27T00:00:01,1.0,-1.0,abc,20.0,7,false\n",
        2,
        {"unparsable_value": 1},
        {},
        "3: unparsable value: hpl 'abc'",
    ),
    "bad-time": (
        "2006-13-27T00:00:01,1.0,-1.0,10.0,20.0,7,false\n",
        2,
        {"unparsable_value": 1},
        {},
        "3: unparsable value: time '2006-13-27T00:00:01'",
    ),
    "empty-time": (
        ",1.0,-1.0,10.0,20.0,7,false\n",
        2,
        {"missing_time": 1},
        {},
        "3: missing time: empty cell",
    ),
    "fractional-nsv": (
        "2006-12-27T00:00:01,1.0,-1.0,10.0,20.0,7.5,false\n",
        2,
        {"unparsable_value": 1},
        {},
        "3: unparsable value: nsv '7.5' is not a non-negative integer",
    ),
    "bad-alert": (
        "2006-12-27T00:00:01,1.0,-1.0,10.0,20.0,7,maybe\n",
        2,
        {"unparsable_value": 1},
        {},
        "3: unparsable value: alert 'maybe' is not a boolean",
    ),
    "empty-vpl": (
        "2006-12-27T00:00:01,1.0,-1.0,10.0,,7,false\n",
        3,
        {},
        {"nan_pl": 1},
        "3: nan_pl: solution set to no-solution",
    ),
    "negative-hpl": (
        "2006-12-27T00:00:01,1.0,-1.0,-10.0,20.0,7,false\n",
        3,
        {},
        {"negative_pl": 1},
        "3: negative_pl: solution set to no-solution",
    ),
    "duplicate-time": (
        "2006-12-27T00:00:00,1.0,-1.0,10.0,20.0,7,false\n",
        2,
        {"duplicate_time": 1},
        {},
        "3: duplicate time: 2006-12-27 00:00:00 repeats line 2",
    ),
    "negative-hpe": (
        "2006-12-27T00:00:01,-1.0,-1.0,10.0,20.0,7,false\n",
        2,
        {"negative_hpe": 1},
        {},
        "3: negative hpe: -1.0 (must be >= 0)",
    ),
    "blank-line": ("\n", 2, {}, {}, ""),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_rows(case: str) -> None:
    row, kept, rejected, invalidated, first_bad = CASES[case]
    text = HEAD + OK_ROW.format(s=0) + row + OK_ROW.format(s=2)
    table, report = _csv(text, station="X")
    assert (table.height, report.rejected, report.invalidated, report.first_bad) == (
        kept,
        rejected,
        invalidated,
        first_bad,
    )
    assert table["time"][-1] == dt.datetime(2006, 12, 27, 0, 0, 2)  # line 4 always kept
    if rejected or invalidated:
        # strict raises on rejected rows only; invalidated rows stay as no-solution epochs
        with pytest.raises(InputError, match=r"^<stream>:3: ") if rejected else contextlib.nullcontext():
            _csv(text, station="X", strict=True)


def test_all_rows_bad_is_no_epochs() -> None:
    with pytest.raises(
        InputError, match=r"no epochs: all 1 rows rejected \(first: line 2: unparsable value: hpl"
    ):
        _csv(HEAD + "2006-12-27T00:00:01,1.0,-1.0,abc,20.0,7,false\n", station="X")


def test_backward_time_raises_with_line() -> None:
    text = HEAD + OK_ROW.format(s=5) + OK_ROW.format(s=1)
    with pytest.raises(InputError, match="backward time") as err:
        _csv(text, station="X")
    assert err.value.line == 3


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", "empty file: no header line"),
        (HEAD, "no epochs"),
        (HEAD + "2006-12-27T00:00:00Z,1,1,1,1,1,true\n", "has a zone designator"),
        (HEAD + "2006-12-27T00:00:00+01:00,1,1,1,1,1,true\n", "has a zone designator"),
    ],
)
def test_file_level_errors(text: str, match: str) -> None:
    with pytest.raises(InputError, match=match):
        _csv(text, station="X")


def test_extra_columns_are_listed() -> None:
    _, report = _csv("time,hpe,vpe,hpl,vpl,sdn,sde\n2006-12-27T00:00:00,1,1,1,1,0.5,0.5\n", station="X")
    assert "columns not in the epoch table dropped: sdn, sde" in report.notes


# --------------------------------------------------------------------------- Parquet specifics


def test_parquet_datetime_units_and_week_tow(tmp_path: Path) -> None:
    base = {"hpe": [1.0], "vpe": [2.0], "hpl": [3.0], "vpl": [4.0]}
    t = dt.datetime(2006, 12, 27, 0, 4, 30)
    ms = pl.DataFrame({"time": pl.Series([t], dtype=pl.Datetime("ms")), **base})
    ms.write_parquet(tmp_path / "ms.parquet")
    assert read_parquet(tmp_path / "ms.parquet", station="S")[0]["time"].to_list() == [t]
    wt = pl.DataFrame({"gps_week": [1407], "sow": [259470.0], **base})
    wt.write_parquet(tmp_path / "wt.parquet")
    got, _ = read_parquet(tmp_path / "wt.parquet", station="S", mapping={"week": "gps_week", "tow": "sow"})
    assert got["time"].to_list() == [t]
    tz = pl.DataFrame({"time": pl.Series([t]).dt.replace_time_zone("UTC"), **base})
    tz.write_parquet(tmp_path / "tz.parquet")
    with pytest.raises(InputError, match="timezone-aware"):
        read_parquet(tmp_path / "tz.parquet")


def test_parquet_not_parquet(tmp_path: Path) -> None:
    path = tmp_path / "x.parquet"
    path.write_text("not parquet")
    with pytest.raises(InputError, match="not a readable Parquet file"):
        read_parquet(path)
    with pytest.raises(InputError, match="not a readable Parquet file"):
        read_epochs_metadata(path)


@pytest.mark.parametrize(
    ("row", "got"),
    [("2024-01-07T00:00:01,A,1,1,10", 5), ("2024-01-07T00:00:01,A,1,1,10,12,99", 7)],
)
def test_gh2_ragged_csv_line_is_malformed_not_an_empty_cell(row, got):
    """A row with too few or too many fields is rejected as malformed, naming its line."""
    good = "2024-01-07T00:00:00,A,1,1,10,12"
    text = f"time,station,hpe,vpe,hpl,vpl\n{good}\n{row}\n{good.replace(':00,', ':02,')}\n"
    table, report = read_csv(io.StringIO(text))
    assert table.height == 2
    assert report.rejected == {"malformed_line": 1} and report.invalidated == {}
    assert report.first_bad == f"3: malformed line: expected 6 fields, got {got}"
    with pytest.raises(InputError, match=r":3: malformed line: expected 6 fields"):
        read_csv(io.StringIO(text), strict=True)
