"""gLAB SBAS output reader: real gLAB v6.0.0 excerpts and the edge-case corpus of tests/data/glab/."""

from __future__ import annotations

import datetime as dt
import gzip
import io
import math
from pathlib import Path

import numpy as np
import polars as pl
import pymap3d
import pytest
from polars.testing import assert_frame_equal

from overbound.io.geodesy import Reference
from overbound.io.glab import read_glab
from overbound.io.schema import InputError, validate_epochs

DATA = Path(__file__).resolve().parents[1] / "data" / "glab"
V6 = DATA / "synt0140_egnos123_v6.glab.gz"
V5 = DATA / "synt0140_egnos123_v5format.glab.gz"
EDGE = DATA / "edge"
#: The true antenna position = gLAB's a priori position in the runs (PROVENANCE.md).
TRUTH = Reference.parse_ecef("4627851.2711,119640.7753,4372993.8468")


def _sbasout_fields(path: Path) -> list[list[str]]:
    with gzip.open(path, "rt") as f:
        return [ln.split() for ln in f if ln.startswith("SBASOUT")]


def test_v6_excerpt_rows_and_hand_read_cells():
    df, rep = read_glab(V6)
    assert (df.height, rep.rows_read, rep.rows_kept) == (361, 361, 361)
    assert rep.rejected == {} and rep.invalidated == {}
    assert df["time"][0] == dt.datetime(2019, 1, 14, 0, 0, 0)
    assert df["time"][-1] == dt.datetime(2019, 1, 14, 3, 0, 0)
    assert int(df["hpl"].is_not_nan().sum()) == 197
    assert int(df["alert"].sum()) == 164
    first = df.filter(pl.col("hpl").is_not_nan()).row(0, named=True)
    # SBASOUT 2019 014 390.00 00:06:30.00 2036 86790.00 synt 5 PA 123 0.4494 0.1299 1.2201 0.4677 10.7450 ...
    assert first["time"] == dt.datetime(2019, 1, 14, 0, 6, 30)
    assert (first["north"], first["east"], first["vpe"]) == (0.4494, 0.1299, 1.2201)
    assert (first["hpl"], first["vpl"]) == (10.7450, 17.4572)
    assert first["hpe"] == pytest.approx(0.4677, abs=1e-4)
    assert (first["station"], first["mode"], first["nsv"], first["alert"]) == ("synt", "PA", 7, False)
    nosol = df.row(0, named=True)
    assert math.isnan(nosol["hpe"]) and math.isnan(nosol["vpl"]) and nosol["alert"] and nosol["nsv"] is None
    assert "gLAB v6.0.0" in rep.notes
    assert any("[SET]" in n for n in rep.notes)
    assert any("164 no-solution epochs" in n and "Not enough satellites" in n for n in rep.notes)
    validate_epochs(df)


def test_v6_fields_map_to_columns_on_every_line():
    df, _ = read_glab(V6)
    sol = df.filter(pl.col("hpl").is_not_nan())
    f = np.array([[float(x) for x in row[11:21]] for row in _sbasout_fields(V6)])
    np.testing.assert_array_equal(sol["north"].to_numpy(), f[:, 0])  # field 12
    np.testing.assert_array_equal(sol["east"].to_numpy(), f[:, 1])  # field 13
    np.testing.assert_array_equal(sol["vpe"].to_numpy(), f[:, 2])  # field 14, signed
    np.testing.assert_allclose(sol["hpe"].to_numpy(), f[:, 3], atol=1.01e-4)  # field 15, print rounding
    np.testing.assert_array_equal(sol["hpl"].to_numpy(), f[:, 4])  # field 16
    np.testing.assert_array_equal(np.abs(sol["vpe"].to_numpy()), f[:, 6])  # field 18 = |up|
    np.testing.assert_array_equal(sol["vpl"].to_numpy(), f[:, 7])  # field 19
    assert (sol["vpe"] < 0).any() and (sol["vpe"] > 0).any()


def test_v5_layout_equals_v6_on_the_same_epochs():
    d6, _ = read_glab(V6)
    d5, rep = read_glab(V5)
    assert d5.height == 31 and "SBASOUT layout: v5 (18 lines)" in rep.notes
    assert_frame_equal(d5, d6.head(31))


@pytest.mark.parametrize("as_stream", ["text", "gzip-bytes", "plain-bytes"])
def test_stream_equals_path(as_stream):
    ref, _ = read_glab(V6)
    raw = V6.read_bytes()
    stream = {
        "text": io.StringIO(gzip.decompress(raw).decode()),
        "gzip-bytes": io.BytesIO(raw),
        "plain-bytes": io.BytesIO(gzip.decompress(raw)),
    }[as_stream]
    got, rep = read_glab(stream)
    assert_frame_equal(got, ref)
    assert rep.source == "<stream>"
    assert not stream.closed


def test_reference_recomputes_errors_from_output_lines():
    plain, _ = read_glab(V6)
    df, rep = read_glab(V6, reference=TRUTH)
    assert any(n.startswith("errors: recomputed against reference") for n in rep.notes)
    for col in ("east", "north", "vpe", "hpe"):
        np.testing.assert_allclose(df[col].to_numpy(), plain[col].to_numpy(), atol=1.5e-4, equal_nan=True)
    # A reference 1 m north and 0.5 m higher: north and up errors drop by that much.
    lat, lon, h = pymap3d.enu2geodetic(0.0, 1.0, 0.5, TRUTH.lat_deg, TRUTH.lon_deg, TRUTH.height_m)
    moved, _ = read_glab(V6, reference=Reference(float(lat), float(lon), float(h)))
    np.testing.assert_allclose(
        moved["north"].to_numpy(), df["north"].to_numpy() - 1.0, atol=1e-6, equal_nan=True
    )
    np.testing.assert_allclose(moved["vpe"].to_numpy(), df["vpe"].to_numpy() - 0.5, atol=1e-6, equal_nan=True)
    np.testing.assert_allclose(moved["east"].to_numpy(), df["east"].to_numpy(), atol=1e-6, equal_nan=True)


def _without_output_lines() -> str:
    with gzip.open(V6, "rt") as f:
        return "".join(ln for ln in f if not ln.startswith("OUTPUT"))


def test_reference_without_output_lines_checked_against_apriori():
    df, rep = read_glab(io.StringIO(_without_output_lines()), reference=TRUTH)
    assert df.height == 361
    assert any("which is reference" in n and "0.0 mm" in n for n in rep.notes)
    far = Reference(TRUTH.lat_deg + 1e-4, TRUTH.lon_deg, TRUTH.height_m)  # about 11 m north
    with pytest.raises(InputError, match=r"differs from gLAB's a priori position .* by 11\.\d{3} m"):
        read_glab(io.StringIO(_without_output_lines()), reference=far)


def test_station_argument_overrides_receiver_id():
    df, _ = read_glab(V5, station="TLSE")
    assert df["station"].cast(pl.String).unique().to_list() == ["TLSE"]


#: Edge-case corpus: file -> (rows kept, rejected by reason) or the InputError it raises.
EDGE_CASES: dict[str, tuple[int, dict[str, int]] | str] = {
    "truncated_line.glab": (4, {"truncated_line": 1}),
    "truncated_satlist.glab": (4, {"truncated_line": 1}),
    "non_numeric_field.glab": (4, {"non-numeric_field": 1}),
    "unknown_mode.glab": (4, {"unknown_mode": 1}),
    "inconsistent_time.glab": (4, {"inconsistent_time": 1}),
    "duplicate_time.glab": (5, {"duplicate_time": 1}),
    "backward_time.glab": r"time.glab:8: backward time 2019-01-14 00:07:00 after 2019-01-14 00:07:30",
    "apriori_calculated.glab": r"computed its a priori position \(\[TO_BE_CALCULATED\]\)",
    "no_sbasout.glab": r"no_sbasout.glab: no SBASOUT lines",
    "empty.glab": r"empty.glab: no SBASOUT lines",
}


def test_edge_corpus_is_complete():
    assert sorted(p.name for p in EDGE.iterdir()) == sorted(EDGE_CASES)


@pytest.mark.parametrize("name", sorted(EDGE_CASES))
def test_edge_corpus(name):
    expected = EDGE_CASES[name]
    if isinstance(expected, str):
        with pytest.raises(InputError, match=expected):
            read_glab(EDGE / name)
        return
    rows, rejected = expected
    df, rep = read_glab(EDGE / name)
    assert (df.height, rep.rejected) == (rows, rejected)
    assert rep.first_bad.split(":")[0] in ("7", "8", "9")
    assert int(df["alert"].sum()) == 1  # the INFO no-solution epoch at 00:06:00
    validate_epochs(df)


@pytest.mark.parametrize(
    ("name", "message"),
    [
        (
            "truncated_line.glab",
            r"line.glab:7: truncated line: expected at least 24 fields \(v6 layout\), got 12",
        ),
        ("truncated_satlist.glab", r":7: truncated line: field 23 says 8 satellites in view, the list has 4"),
        ("non_numeric_field.glab", r":7: non-numeric field: field 16 \(HPL\) is '10.33O5'"),
        ("inconsistent_time.glab", r":9: inconsistent time: year/doy/sod give 2019-01-14 00:07:30 GPST"),
        ("duplicate_time.glab", r":8: duplicate time: 2019-01-14 00:07:00 repeats line 7"),
    ],
)
def test_strict_raises_naming_file_and_line(name, message):
    with pytest.raises(InputError, match=message):
        read_glab(EDGE / name, strict=True)


def test_apriori_calculated_reads_with_reference():
    df, _ = read_glab(EDGE / "apriori_calculated.glab", reference=TRUTH)
    assert df.height == 5
    # Recomputed from OUTPUT X Y Z 4627851.8421 119640.9200 4372995.0133 at 00:06:30.
    assert df["north"][1] == pytest.approx(0.4494, abs=1.5e-4)
    assert df["vpe"][1] == pytest.approx(1.2201, abs=1.5e-4)


# A real v5-format line (v5 excerpt, 00:06:30); without field 15 (VPE) it has the layout of gLAB < 4.2.
V5_LINE = (
    "SBASOUT     synt  PA 2019 014   390.00 2036  86790.00 123         0.4494         0.1299         1.2201"
    "         0.4677        10.7450         1.2201        17.4572         2.3118  8  7"
    " +G08 +G10 +G16 +G20 +G21 +G26 +G27 -G07"
)


def test_v5_layout_without_vpe_field():
    fields = V5_LINE.split()
    old = " ".join(fields[:14] + fields[15:])  # drop field 15, the vertical positioning error
    df, rep = read_glab(io.StringIO(old + "\n"))
    assert rep.notes[0] == "SBASOUT layout: v5-no-vpe (1 lines)"
    row = df.row(0, named=True)
    assert (row["north"], row["vpe"], row["hpl"], row["vpl"], row["nsv"]) == (
        0.4494,
        1.2201,
        10.745,
        17.4572,
        7,
    )


def test_v5_line_with_one_unused_satellite_is_not_taken_for_the_old_layout():
    # 3 in view, 2 used: 19 + 2 fields would fit "v5" by count if the used count were not checked.
    line = " ".join(V5_LINE.split()[:17]) + " 3 2 +G08 +G10 -G07"
    df, rep = read_glab(io.StringIO(line))
    assert rep.notes[0] == "SBASOUT layout: v5 (1 lines)"
    assert (df["vpl"][0], df["nsv"][0]) == (17.4572, 2)


def test_all_lines_rejected_gives_an_empty_table():
    df, rep = read_glab(io.StringIO(V5_LINE[:60] + "\n"))
    assert (df.height, rep.rows_read, rep.rejected) == (0, 1, {"truncated_line": 1})
    assert df.columns[:6] == ["time", "station", "hpe", "vpe", "hpl", "vpl"]
