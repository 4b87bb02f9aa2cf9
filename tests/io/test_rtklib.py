"""RTKLIB .pos reader: real USLO/WAAS output, golden cells, edge-case corpus, speed."""

from __future__ import annotations

import datetime as dt
import gzip
import io
import math
import time
from importlib.resources import files
from pathlib import Path

import numpy as np
import polars as pl
import pytest
import wgs84
from polars.testing import assert_frame_equal

from overbound.io.geodesy import Reference
from overbound.io.gpstime import GPS_UTC_LEAP_SECONDS, PLAUSIBLE_SPAN, gps_utc_offset, utc_to_gpst
from overbound.io.rtklib import SOLUTION_QUALITY, parse_pos_header, read_rtklib_pos
from overbound.io.schema import InputError

CORPUS = Path(__file__).parents[1] / "data" / "rtklib-pos"
USLO = Path(str(files("overbound") / "data" / "uslo-2006-361-waas.pos.gz"))
# Monument from the RINEX header comment (src/overbound/data/PROVENANCE.md).
TRUTH = Reference(35.311803, -120.661092, 134.6419)


def _enu(lat: float, lon: float, h: float, ref: Reference = TRUTH) -> tuple[float, float, float]:
    """Closed-form ENU (tests/reference/wgs84.py), independent of the reader's pymap3d."""
    return wgs84.enu(lat, lon, h, ref.lat_deg, ref.lon_deg, ref.height_m)


def _plain_rows(path: Path) -> list[list[str]]:
    """Data lines of a .pos file split on blanks, plain Python."""
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt") as fh:
        return [ln.split() for ln in fh if ln.strip() and not ln.startswith("%")]


@pytest.fixture(scope="module")
def uslo() -> tuple[pl.DataFrame, object]:
    return read_rtklib_pos(USLO, reference=TRUTH)


# --------------------------------------------------------------------------- real data


@pytest.mark.parametrize(
    ("row", "line"),
    [(0, 16), (1, 17), (2864, 2880)],  # first two epochs and the last one
)
def test_uslo_golden_cells(uslo, row: int, line: int) -> None:
    table, _ = uslo
    f = _plain_rows(USLO)[row]
    e, n, u = _enu(float(f[2]), float(f[3]), float(f[4]))
    got = table.row(row, named=True)
    assert got["time"] == dt.datetime.strptime(f"{f[0]} {f[1]}", "%Y/%m/%d %H:%M:%S.%f")
    assert got["east"] == pytest.approx(e, abs=1e-6)
    assert got["north"] == pytest.approx(n, abs=1e-6)
    assert got["vpe"] == pytest.approx(u, abs=1e-6)
    assert got["hpe"] == pytest.approx(math.hypot(e, n), abs=1e-6)
    assert (got["hpl"], got["vpl"], got["nsv"], got["mode"]) == (
        float(f[13]),
        float(f[14]),
        int(f[6]),
        "sbas",
    )


def test_uslo_golden_cell_values(uslo) -> None:
    """Hand-checked numbers of the first epoch (line 16: 35.311789409 -120.661114248 130.5055)."""
    first = uslo[0].row(0, named=True)
    assert first["time"] == dt.datetime(2006, 12, 27, 0, 4, 30)
    assert first["hpl"] == 135.11 and first["vpl"] == 179.5 and first["nsv"] == 4
    # 1e-9 deg of latitude is 0.111 mm: north = -13.591e-6 deg * 110.94 km/deg = -1.508 m.
    assert first["north"] == pytest.approx(-1.5079, abs=1e-4)
    assert first["east"] == pytest.approx(-2.0233, abs=1e-4)
    assert first["vpe"] == pytest.approx(-4.1364, abs=1e-4)


def test_uslo_whole_file_counts(uslo) -> None:
    table, report = uslo
    rows = _plain_rows(USLO)
    hpl = np.array([float(f[13]) for f in rows])
    vpl = np.array([float(f[14]) for f in rows])
    assert len(rows) == 2865 == table.height == report.rows_read == report.rows_kept
    assert report.rejected == {} and report.invalidated == {}
    n_pa = int(np.sum((hpl < 40) & (vpl < 50)))
    assert n_pa == 2485  # 86.7 % (data PROVENANCE.md)
    assert table.filter((pl.col("hpl") < 40) & (pl.col("vpl") < 50)).height == n_pa
    assert table["hpl"].max() == 135.11 and table["vpl"].max() == 208.8
    assert int(table["nsv"].sum()) == sum(int(f[6]) for f in rows) == 19956
    assert table["station"].cast(pl.String).unique().to_list() == ["USLO"]
    assert table["mode"].cast(pl.String).unique().to_list() == ["sbas"]
    assert table["time"].min() == dt.datetime(2006, 12, 27, 0, 4, 30)
    assert table["time"].max() == dt.datetime(2006, 12, 27, 23, 59, 30)
    # Mean solution 0.46 m below the monument (PROVENANCE.md): vpe mean -0.46 m.
    assert table["vpe"].mean() == pytest.approx(-0.46, abs=0.01)
    assert (table["hpe"] >= 0).all()
    assert table.schema["time"] == pl.Datetime("us") and table.schema["nsv"] == pl.Int16


def test_stream_equals_path(uslo) -> None:
    raw = USLO.read_bytes()
    text = gzip.decompress(raw).decode()
    for src in (io.BytesIO(raw), io.BytesIO(gzip.decompress(raw)), io.StringIO(text)):
        table, report = read_rtklib_pos(src, reference=TRUTH)
        assert_frame_equal(table, uslo[0])
        assert report.rows_kept == 2865 and report.source == "<stream>"


def test_test28_ws_real_variant() -> None:
    """Elevation mask 0 deg + RAIM FDE run of the same day: 10 satellites at line 21."""
    path = CORPUS / "test28-ws-head.pos"
    table, report = read_rtklib_pos(path, reference=TRUTH)
    rows = _plain_rows(path)
    assert table.height == len(rows) == 40 and report.n_rejected == 0
    assert table["hpl"].to_list() == [float(f[13]) for f in rows]
    assert table["nsv"].to_list()[:8] == [4, 6, 6, 8, 8, 10, 10, 10]
    e, n, u = _enu(*(float(v) for v in rows[5][2:5]))
    assert table["vpe"][5] == pytest.approx(u, abs=1e-6)
    assert table["hpe"][5] == pytest.approx(math.hypot(e, n), abs=1e-6)


# --------------------------------------------------------------------------- edge-case corpus

GOOD = "good-uslo-head.pos"
# file -> (rows kept, rejected, invalidated, first_bad) or (InputError text, line)
EXPECTED: dict[str, tuple] = {
    GOOD: (8, {}, {}, ""),
    "crlf-line-endings.pos": (8, {}, {}, ""),
    "comma-separated.pos": (8, {}, {}, ""),
    "utc-header.pos": (8, {}, {}, ""),
    "week-tow.pos": (8, {}, {}, ""),
    "xyz.pos": (8, {}, {}, ""),
    "dms.pos": (8, {}, {}, ""),
    "rinex3-station.pos": (8, {}, {}, ""),
    "no-solution-q0.pos": (8, {}, {}, ""),
    "test28-ws-head.pos": (40, {}, {}, ""),
    "truncated-line.pos": (7, {"malformed_line": 1}, {}, "19: malformed line: expected 15 fields, got 11"),
    "non-numeric-field.pos": (
        7,
        {"malformed_line": 1},
        {},
        "18: malformed line: height 13x.4215 is not a number",
    ),
    "unknown-quality.pos": (7, {"malformed_line": 1}, {}, "17: malformed line: unknown quality flag Q=9"),
    "duplicate-time.pos": (
        7,
        {"duplicate_time": 1},
        {},
        "20: duplicate time: 2006-12-27 00:06:00 repeats line 19",
    ),
    "cut-inside-vpl.pos": (
        7,
        {"truncated_line": 1},
        {},
        "23: truncated line: the last line has no line end and is shorter than the one before",
    ),
    "year-0000.pos": (
        7,
        {"malformed_line": 1},
        {},
        "18: malformed line: time '0000/12/27 00:05:30.000' outside " + PLAUSIBLE_SPAN,
    ),
    "year-9999.pos": (
        7,
        {"malformed_line": 1},
        {},
        "20: malformed line: time '9999/12/27 00:06:30.000' outside " + PLAUSIBLE_SPAN,
    ),
    "negative-hpl.pos": (8, {}, {"negative_pl": 1}, "19: negative_pl: solution set to no-solution"),
    "nan-vpl.pos": (8, {}, {"nan_pl": 1}, "20: nan_pl: solution set to no-solution"),
    "backward-time.pos": ("backward time 2006-12-27 00:05:45 after 2006-12-27 00:06:30", 21),
    "empty.pos": ("no epochs", None),
    "header-only.pos": ("no epochs", None),
    "no-header.pos": ("no column header line", None),
    "no-hpl-test26-head.pos": ("no hpl/vpl columns: overbound needs protection levels", 15),
    "no-hpl-test27-head.pos": ("no hpl/vpl columns: overbound needs protection levels", 13),
    "geodetic-height.pos": ("overbound needs ellipsoidal heights", 14),
    "enu-baseline.pos": ("e/n/u-baseline solutions are relative to the base station", 15),
}


def test_corpus_is_complete() -> None:
    assert sorted(p.name for p in CORPUS.glob("*.pos")) == sorted(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_corpus(name: str) -> None:
    expected = EXPECTED[name]
    path = CORPUS / name
    if isinstance(expected[0], str):
        text, line = expected
        with pytest.raises(InputError, match=text) as err:
            read_rtklib_pos(path, reference=TRUTH)
        assert err.value.line == line
        assert str(err.value).startswith(f"{path}")
        return
    kept, rejected, invalidated, first_bad = expected
    table, report = read_rtklib_pos(path, reference=TRUTH)
    assert (table.height, report.rows_kept) == (kept, kept)
    assert report.rejected == rejected
    assert report.invalidated == invalidated
    assert report.first_bad == first_bad
    assert report.rows_read == len(_plain_rows(path))


@pytest.mark.parametrize(
    ("name", "tol"),
    [
        ("crlf-line-endings.pos", 0.0),
        ("comma-separated.pos", 0.0),
        ("utc-header.pos", 0.0),
        ("week-tow.pos", 0.0),
        ("xyz.pos", 2e-4),  # ECEF printed to 0.1 mm
        ("dms.pos", 5e-4),  # seconds of arc printed to 1e-5" = 0.3 mm
    ],
)
def test_variants_give_the_same_epochs(name: str, tol: float) -> None:
    good, _ = read_rtklib_pos(CORPUS / GOOD, reference=TRUTH)
    table, report = read_rtklib_pos(CORPUS / name, reference=TRUTH)
    assert table["time"].to_list() == good["time"].to_list()
    assert table.columns == good.columns
    for col in ("hpe", "vpe", "east", "north"):
        np.testing.assert_allclose(table[col].to_numpy(), good[col].to_numpy(), rtol=0, atol=tol)
    assert table["hpl"].to_list() == good["hpl"].to_list()
    if name == "utc-header.pos":
        assert "UTC times converted to GPST (GPS-UTC = 14 s)" in report.notes


def test_jst_header(tmp_path: Path) -> None:
    """JST = UTC + 9 h (RTKLIB TIMES_JST): shift the UTC file's times by 9 h."""
    lines = (CORPUS / "utc-header.pos").read_text().splitlines()
    out = []
    for ln in lines:
        if ln.startswith("%  UTC "):
            ln = ln.replace("%  UTC ", "%  JST ", 1)
        elif not ln.startswith("%"):
            t = dt.datetime.strptime(ln[:23], "%Y/%m/%d %H:%M:%S.%f") + dt.timedelta(hours=9)
            ln = t.strftime("%Y/%m/%d %H:%M:%S.%f")[:23] + ln[23:]
        out.append(ln)
    path = tmp_path / "jst.pos"
    path.write_text("\n".join(out) + "\n")
    table, report = read_rtklib_pos(path, reference=TRUTH)
    good, _ = read_rtklib_pos(CORPUS / GOOD, reference=TRUTH)
    assert table["time"].to_list() == good["time"].to_list()
    assert "JST times converted to GPST (GPS-UTC = 14 s)" in report.notes


def test_invalid_rows_are_no_solution_epochs() -> None:
    table, _ = read_rtklib_pos(CORPUS / "negative-hpl.pos", reference=TRUTH)
    row = table.row(3, named=True)  # line 19
    assert all(math.isnan(row[c]) for c in ("hpe", "vpe", "hpl", "vpl", "east", "north"))
    assert row["nsv"] == 7 and row["time"] == dt.datetime(2006, 12, 27, 0, 6)


def test_q0_row_is_a_no_solution_epoch() -> None:
    table, report = read_rtklib_pos(CORPUS / "no-solution-q0.pos", reference=TRUTH)
    row = table.row(6, named=True)
    assert row["mode"] == "none" and math.isnan(row["hpe"]) and math.isnan(row["vpl"])
    assert table.filter(pl.col("hpe").is_nan()).height == 1
    assert "1 epochs with Q=0 (no solution) kept as no-solution epochs" in report.notes


@pytest.mark.parametrize(
    ("name", "line", "text"),
    [
        ("truncated-line.pos", 19, "expected 15 fields, got 11"),
        ("non-numeric-field.pos", 18, "height 13x.4215 is not a number"),
        ("duplicate-time.pos", 20, "duplicate time"),
    ],
)
def test_strict_raises_at_the_bad_line(name: str, line: int, text: str) -> None:
    with pytest.raises(InputError, match=text) as err:
        read_rtklib_pos(CORPUS / name, reference=TRUTH, strict=True)
    assert err.value.line == line
    assert str(err.value).startswith(f"{CORPUS / name}:{line}: ")


def test_all_lines_bad_is_no_epochs(tmp_path: Path) -> None:
    lines = (CORPUS / GOOD).read_text().splitlines()
    path = tmp_path / "all-bad.pos"
    path.write_text("\n".join(ln if ln.startswith("%") else ln[:40] for ln in lines) + "\n")
    with pytest.raises(
        InputError, match=r"no epochs: all 8 data lines rejected \(first: line 16: malformed line"
    ):
        read_rtklib_pos(path, reference=TRUTH)


def test_needs_a_reference() -> None:
    with pytest.raises(
        InputError, match=r"needs a reference position \(--reference lat,lon,h or --reference-ecef"
    ):
        read_rtklib_pos(CORPUS / GOOD)


# --------------------------------------------------------------------------- station


def test_station_sources(tmp_path: Path) -> None:
    text = (CORPUS / GOOD).read_text()
    no_inp = tmp_path / "roof-antenna.day1.pos"
    no_inp.write_text("\n".join(ln for ln in text.splitlines() if "inp file" not in ln) + "\n")
    table, report = read_rtklib_pos(no_inp, reference=TRUTH)
    assert table["station"][0] == "roof-antenna" and "station roof-antenna from the file name" in report.notes
    table, _ = read_rtklib_pos(no_inp, reference=TRUTH, station="ROOF")
    assert table["station"][0] == "ROOF"
    table, report = read_rtklib_pos(CORPUS / GOOD, reference=TRUTH, station="ROOF")
    assert table["station"][0] == "USLO"
    assert "station argument 'ROOF' ignored: the header names USLO" in report.notes
    table, _ = read_rtklib_pos(CORPUS / "rinex3-station.pos", reference=TRUTH)
    assert table["station"][0] == "ESBC00DNK"


def test_parse_pos_header_names_with_units() -> None:
    lines = (CORPUS / GOOD).read_text().splitlines()
    h = parse_pos_header(lines)
    assert h.time_system == "GPST" and h.line == 15 and h.station == "USLO"
    assert h.columns[-2:] == ("hpl (m)", "vpl (m)") and h.n_fields == 15
    assert (
        h.field_of("latitude"),
        h.field_of("q"),
        h.field_of("ns"),
        h.field_of("hpl"),
        h.field_of("vpl"),
    ) == (
        2,
        5,
        6,
        13,
        14,
    )
    dms = parse_pos_header((CORPUS / "dms.pos").read_text().splitlines())
    assert dms.widths[:3] == (3, 3, 1) and dms.n_fields == 19 and dms.field_of("hpl") == 17


# --------------------------------------------------------------------------- time scale


@pytest.mark.parametrize(
    ("utc", "offset"),
    [
        (dt.datetime(2005, 12, 31, 23, 59, 59), 13),
        (dt.datetime(2006, 12, 27), 14),
        (dt.datetime(2008, 12, 31, 23, 59, 59), 14),
        (dt.datetime(2009, 1, 1), 15),
        (dt.datetime(2012, 6, 30, 23, 59, 59), 15),
        (dt.datetime(2012, 7, 1), 16),
        (dt.datetime(2015, 7, 1), 17),
        (dt.datetime(2016, 12, 31, 23, 59, 59), 17),
        (dt.datetime(2017, 1, 1), 18),
        (dt.datetime(2025, 6, 1), 18),
        (dt.datetime(1980, 1, 6), 0),
    ],
)
def test_gps_utc_offset(utc: dt.datetime, offset: int) -> None:
    assert gps_utc_offset(utc) == offset
    assert utc_to_gpst(pl.Series([utc])).to_list() == [utc + dt.timedelta(seconds=offset)]


def test_leap_table_is_increasing_by_one() -> None:
    dates = [d for d, _ in GPS_UTC_LEAP_SECONDS]
    assert dates == sorted(dates)
    assert [s for _, s in GPS_UTC_LEAP_SECONDS] == list(range(1, 19))
    assert SOLUTION_QUALITY[1] == "fix" and SOLUTION_QUALITY[3] == "sbas" and SOLUTION_QUALITY[6] == "ppp"


# --------------------------------------------------------------------------- speed


def test_one_day_at_1hz_reads_fast(tmp_path: Path) -> None:
    lines = (CORPUS / GOOD).read_text().splitlines()
    head = [ln for ln in lines if ln.startswith("%")]
    body = lines[len(head)][23:]
    t0 = dt.datetime(2006, 12, 27)
    rows = [f"{t0 + dt.timedelta(seconds=i):%Y/%m/%d %H:%M:%S}.000{body}" for i in range(86_400)]
    path = tmp_path / "day.pos"
    path.write_text("\n".join(head + rows) + "\n")
    best = math.inf
    for _ in range(2):
        start = time.perf_counter()
        table, report = read_rtklib_pos(path, reference=TRUTH)
        best = min(best, time.perf_counter() - start)
    assert table.height == 86_400 and report.n_rejected == 0
    assert table["time"][-1] == dt.datetime(2006, 12, 27, 23, 59, 59)
    assert best < 1.0, f"{best:.2f} s"
