"""u-blox UBX reader: synthetic NAV-PL logs from tests/reference/make_ubx_fixtures.py and a real old log."""

from __future__ import annotations

import datetime as dt
import gzip
import io
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from polars.testing import assert_frame_equal

from overbound.io.geodesy import Reference
from overbound.io.gpstime import GPS_UTC_LEAP_SECONDS
from overbound.io.schema import InputError, validate_epochs
from overbound.io.ubx import read_ubx

DATA = Path(__file__).resolve().parents[1] / "data" / "ubx"
#: The generator's reference position (make_ubx_fixtures.REF_*).
REF = Reference(43.5607, 1.4809, 207.0)
EXPECTED = pl.read_csv(
    DATA / "expected.csv",
    schema_overrides={"alert": pl.Int8} | {c: pl.Float64 for c in ("east", "north", "up", "hpl", "vpl")},
).with_columns(pl.col("time").str.to_datetime("%Y-%m-%dT%H:%M:%S", time_unit="us"))
SYNTHETIC = sorted(EXPECTED["file"].unique().to_list())


def test_every_synthetic_file_has_expected_rows():
    on_disk = sorted(p.name for p in DATA.glob("*.ubx") if p.name != "old_ublox_no_navpl.ubx")
    assert on_disk == SYNTHETIC


@pytest.mark.parametrize("name", SYNTHETIC)
def test_errors_and_pls_match_the_generator(name):
    df, _ = read_ubx(DATA / name, reference=REF)
    exp = EXPECTED.filter(pl.col("file") == name)
    assert df["time"].to_list() == exp["time"].to_list()
    # Errors of the encoded positions: 1e-6 m with NAV-HPPOSLLH (1e-9 deg), 1e-3 m with NAV-PVT (1e-7 deg).
    tol = 1e-6 if "hpposllh" in name else 1e-3
    for got, want in (("east", "east"), ("north", "north"), ("vpe", "up")):
        np.testing.assert_allclose(df[got].to_numpy(), exp[want].to_numpy(), atol=tol, rtol=0, equal_nan=True)
    np.testing.assert_allclose(
        df["hpe"].to_numpy(),
        np.hypot(exp["east"].to_numpy(), exp["north"].to_numpy()),
        atol=tol,
        equal_nan=True,
    )
    # PLs are whole millimetres.
    np.testing.assert_allclose(
        df["hpl"].to_numpy(), exp["hpl"].to_numpy(), atol=5e-10, rtol=0, equal_nan=True
    )
    np.testing.assert_allclose(
        df["vpl"].to_numpy(), exp["vpl"].to_numpy(), atol=5e-10, rtol=0, equal_nan=True
    )
    assert df["alert"].to_list() == [bool(a) for a in exp["alert"]]
    validate_epochs(df)


def test_hpposllh_is_finer_than_pvt():
    """The HPPOSLLH file carries the same epochs as PVT rounded to 1e-7 deg; the reader must use HPPOSLLH."""
    df, rep = read_ubx(DATA / "hpposllh_ellipse.ubx", reference=REF)
    exp = EXPECTED.filter(pl.col("file") == "hpposllh_ellipse.ubx")
    np.testing.assert_allclose(df["north"].to_numpy(), exp["north"].to_numpy(), atol=1e-6, rtol=0)
    assert "positions: NAV-HPPOSLLH for 10 epochs, NAV-PVT for 0" in " ".join(rep.notes)
    # Frame 3: HPL is the semi-major axis plPos1 = 8000 + 111 k mm, not hypot(plPos1, plPos2).
    assert df["hpl"].to_list() == pytest.approx([8.0 + 0.111 * k for k in range(10)], abs=1e-12)


def test_hand_read_first_epoch():
    df, rep = read_ubx(DATA / "pvt_pl_timegps.ubx", reference=REF)
    row = df.row(0, named=True)
    assert row["time"] == dt.datetime(2019, 1, 14, 0, 0, 0)  # week 2036, iTOW 86400000 ms
    assert row["hpl"] == pytest.approx(np.hypot(8.0, 5.0), abs=1e-12)
    assert row["vpl"] == 12.0
    assert row["east"] == pytest.approx(0.5, abs=0.006) and row["north"] == pytest.approx(-0.3, abs=0.006)
    assert (row["station"], row["nsv"], row["mode"], row["alert"]) == ("pvt_pl_timegps", 9, "3D/DGNSS", False)
    assert df["nsv"].to_list() == [9 + k % 3 for k in range(10)]
    assert rep.rows_read == 10 and rep.rejected == {} and rep.invalidated == {}  # the 10 NAV-PL epochs
    assert "NAV-PL 10, NAV-PVT 10, NAV-TIMEGPS 10" in rep.notes[0]
    assert "frames: NAV-PL 10, NAV-PVT 10, NAV-TIMEGPS 10; 78 bytes outside UBX frames skipped" in rep.notes


#: Report per fixture: rows kept, rejected by reason, invalidated by reason, and phrases of the notes.
REPORTS = {
    "pvt_pl_timegps.ubx": (10, {}, {}, ["GPS week: 10 from NAV-TIMEGPS"]),
    "hpposllh_ellipse.ubx": (10, {}, {}, ["HPL from plPosFrame 3"]),
    "invalid_pl.ubx": (
        10,
        {},
        {},
        ["2 epochs with invalid PL (plPosValid=0 or plPosFrame=0)", "2 epochs without a 3D fix"],
    ),
    "missing_pl.ubx": (
        8,
        {},
        {"nan_error": 1},
        ["2 NAV-PVT epochs without a NAV-PL", "1 NAV-PL epochs without NAV-PVT/NAV-HPPOSLLH"],
    ),
    "utc_week_rollover.ubx": (
        6,
        {},
        {},
        [
            "GPS week: 5 from NAV-PVT UTC date, 1 from neighbouring epochs",
            "GPS-UTC 18 s from the IERS Bulletin C",
        ],
    ),
    "duplicate_epoch.ubx": (10, {"duplicate_time": 1}, {}, ["NAV-PL 11", "1 repeated NAV-PVT messages"]),
    "bad_checksum.ubx": (9, {"bad_checksum": 2}, {"nan_error": 1}, ["corrupt 2"]),
    "truncated_frame.ubx": (9, {"truncated_frame": 1}, {}, ["corrupt 1"]),
}


def test_report_table_is_complete():
    assert sorted(REPORTS) == SYNTHETIC


@pytest.mark.parametrize("name", sorted(REPORTS))
def test_report(name):
    rows, rejected, invalidated, phrases = REPORTS[name]
    df, rep = read_ubx(DATA / name, reference=REF)
    assert (df.height, rep.rows_kept, rep.rejected, rep.invalidated) == (rows, rows, rejected, invalidated)
    notes = " | ".join(rep.notes)
    for phrase in phrases:
        assert phrase in notes


def test_week_rollover_times():
    df, _ = read_ubx(DATA / "utc_week_rollover.ubx", reference=REF)
    start = dt.datetime(2019, 1, 12, 23, 59, 57)  # week 2035, TOW 604797 s
    assert df["time"].to_list() == [start + dt.timedelta(seconds=k) for k in range(6)]


def test_bad_checksum_names_the_byte_offset():
    data = (DATA / "bad_checksum.ubx").read_bytes()
    offset = [i for i in range(len(data)) if data.startswith(b"\xb5\x62\x01\x07", i)][3]
    _, rep = read_ubx(DATA / "bad_checksum.ubx", reference=REF)
    assert rep.first_bad == f"@{offset}: bad checksum: NAV-PVT, length 92"
    with pytest.raises(InputError, match=rf"bad_checksum.ubx:@{offset}: bad checksum: NAV-PVT, length 92$"):
        read_ubx(DATA / "bad_checksum.ubx", reference=REF, strict=True)


def test_truncated_frame_strict():
    with pytest.raises(InputError, match=r"truncated_frame.ubx:@\d+: truncated frame: NAV-PL length 52"):
        read_ubx(DATA / "truncated_frame.ubx", reference=REF, strict=True)


def test_real_old_log_without_navpl():
    with pytest.raises(InputError) as err:
        read_ubx(DATA / "old_ublox_no_navpl.ubx", reference=REF)
    assert str(err.value) == (
        f"{DATA / 'old_ublox_no_navpl.ubx'}: no UBX-NAV-PL messages (protection levels); "
        "enable NAV-PL output on the receiver"
    )


def test_no_position_and_no_week_anywhere():
    """NAV-PL alone cannot be dated."""
    data = (DATA / "pvt_pl_timegps.ubx").read_bytes()
    only_pl = b"".join(data[i : i + 60] for i in range(len(data)) if data.startswith(b"\xb5\x62\x01\x62", i))
    with pytest.raises(InputError, match="no GPS week for the NAV-PL epochs"):
        read_ubx(io.BytesIO(only_pl), reference=REF)


@pytest.mark.parametrize("wrap", ["bytes", "gzip-bytes", "gzip-file"])
def test_stream_equals_path(wrap, tmp_path):
    path = DATA / "missing_pl.ubx"
    ref, _ = read_ubx(path, reference=REF)
    raw = path.read_bytes()
    if wrap == "bytes":
        src: object = io.BytesIO(raw)
    elif wrap == "gzip-bytes":
        src = io.BytesIO(gzip.compress(raw))
    else:
        src = tmp_path / "missing_pl.ubx.gz"
        src.write_bytes(gzip.compress(raw))
    got, _ = read_ubx(src, reference=REF, station="missing_pl")
    assert_frame_equal(got, ref)


def test_leap_second_table_ends_with_2017():
    assert GPS_UTC_LEAP_SECONDS[-1] == (dt.date(2017, 1, 1), 18)
    assert [v for _, v in GPS_UTC_LEAP_SECONDS] == list(range(1, 19))
