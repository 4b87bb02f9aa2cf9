"""EMS reader: real EGNOS hours (tests/data/sbas/ems, see PROVENANCE.md there) and damaged copies of them."""

from __future__ import annotations

import datetime as dt
import gzip
import re
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from overbound.io.ems import read_ems
from overbound.io.gpstime import PLAUSIBLE_END, PLAUSIBLE_SPAN
from overbound.io.sbas_frames import SbasFrames
from overbound.io.schema import InputError

DATA = Path(__file__).resolve().parents[1] / "data" / "sbas"
EMS = DATA / "ems"
HOURS = [EMS / "h00.ems.gz", EMS / "h01.ems", EMS / "h02.ems.gz"]
_EPOCH = dt.datetime(1970, 1, 1)


def _lines(path: Path) -> list[str]:
    raw = gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_bytes()
    return raw.decode().splitlines()


def _slow_parse(line: str) -> tuple[int, int, int, bytes]:
    """Independent, per-line reading of one EMS line: (PRN, GPST microseconds, type field, bytes)."""
    prn, yy, mo, dd, hh, mi, ss, mt, hexs = line.split()
    t = dt.datetime(2000 + int(yy), int(mo), int(dd), int(hh), int(mi), int(ss))
    return int(prn), (t - _EPOCH) // dt.timedelta(microseconds=1), int(mt), bytes.fromhex(hexs)


def _write(tmp_path: Path, name: str, lines: list[str]) -> Path:
    path = tmp_path / name
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    return path


def test_real_hours_read_line_by_line_the_same():
    frames, report = read_ems(HOURS)
    expected = [_slow_parse(s) for p in HOURS for s in _lines(p)]
    assert len(frames) == len(expected) == report.rows_kept == report.rows_read
    assert frames.prn.tolist() == [e[0] for e in expected]
    assert frames.time.tolist() == [e[1] for e in expected]
    assert frames.mt.tolist() == [e[2] for e in expected]
    assert [bytes(r) for r in frames.data] == [e[3] for e in expected]
    assert frames.crc_ok.all()
    assert report.rejected == {} and report.invalidated == {} and frames.rejected.height == 0
    # File and line of each message lead back to its text.
    names = [Path(frames.files[i]).name for i in frames.file]
    assert names[0] == "h00.ems.gz" and frames.line[0] == 1
    assert names[-1] == "h02.ems.gz" and frames.line[-1] == len(_lines(HOURS[2]))


def test_time_is_gps_time_of_the_tag_and_dataframe_view():
    frames, _ = read_ems(HOURS[0])
    df = frames.to_frame()
    assert df["time"][0] == dt.datetime(2019, 1, 14, 0, 0, 0)
    assert df["time"][-1] == dt.datetime(2019, 1, 14, 0, 59, 59)
    assert df.schema["time"] == pl.Datetime("us")
    assert df["data"][1] == bytes.fromhex(_lines(HOURS[0])[1].split()[-1])


def test_tag_marks_the_end_of_the_transmission_slot():
    """DO-229 starts every other 0x53 preamble on a GPS 6-s subframe epoch, so 0x53 messages start at
    multiples of 3 s; EMS tags them one second later."""
    frames, _ = read_ems(HOURS)
    sec = frames.time // 1_000_000
    phase = {0x53: 1, 0x9A: 2, 0xC6: 0}
    assert all((s % 3) == phase[p] for s, p in zip(sec.tolist(), frames.preamble.tolist(), strict=True))


def test_empty_hour_file_gives_no_messages_and_no_error():
    frames, report = read_ems(EMS / "h01.ems")
    assert len(frames) == 0 and frames.data.shape == (0, 32)
    assert report.rows_read == 0 and report.rows_kept == 0 and report.first_bad == ""
    assert frames.to_frame().height == 0


def test_gzip_plain_and_file_order_do_not_matter(tmp_path):
    plain = tmp_path / "h00.ems"
    plain.write_bytes(gzip.decompress(HOURS[0].read_bytes()))
    a, _ = read_ems([HOURS[2], plain])
    b, _ = read_ems([plain, HOURS[2]])
    assert np.array_equal(a.time, b.time) and np.array_equal(a.data, b.data)
    assert np.all(np.diff(a.time) > 0)


def test_malformed_lines_are_counted_with_file_and_line(tmp_path):
    good = _lines(HOURS[0])[:12]
    lines = list(good)
    lines[1] = good[1][:60]  # truncated
    lines[2] = good[2][:40] + "G" + good[2][41:]  # not a hex digit
    lines[3] = good[3][:7] + "13" + good[3][9:]  # month 13
    lines[4] = "033" + good[4][3:]  # a GPS PRN, not an SBAS GEO
    lines[5] = ""  # blank: skipped, not counted
    flipped = bytearray(bytes.fromhex(good[6].split()[-1]))
    flipped[10] ^= 0x10
    lines[6] = good[6].rsplit(" ", 1)[0] + " " + flipped.hex().upper()  # bad CRC: kept, flagged
    mt = int(good[7].split()[7])
    lines[7] = good[7].replace(f" {mt} ", f" {mt + 1} ", 1)  # type field disagrees with the bits
    lines.append(good[8])  # exact duplicate of line 9
    path = _write(tmp_path, "damaged.ems", lines)

    frames, report = read_ems(path)
    rej = frames.rejected
    assert rej.select("line", "reason").rows() == [
        (2, "line_length"),
        (3, "layout"),
        (4, "bad_time"),
        (5, "not_sbas_prn"),
        (8, "type_mismatch"),
        (13, "duplicate"),
    ]
    assert rej["file"].unique().to_list() == [str(path)]
    assert report.rejected == {
        "line_length": 1,
        "layout": 1,
        "bad_time": 1,
        "not_sbas_prn": 1,
        "type_mismatch": 1,
        "duplicate": 1,
    }
    assert report.invalidated == {"bad_crc": 1}
    assert report.first_bad == f"{path}:2: line_length"
    assert frames.line.tolist() == [1, 7, 9, 10, 11, 12]
    assert frames.crc_ok.tolist() == [True, False, True, True, True, True]
    assert report.rows_read == len(frames) + rej.height == 12


def test_strict_raises_on_the_first_bad_line(tmp_path):
    lines = _lines(HOURS[0])[:3]
    lines[2] = lines[2][:70]
    path = _write(tmp_path, "cut.ems", lines)
    with pytest.raises(InputError, match=r"cut\.ems:3: line of 70 characters, expected 88 or 89"):
        read_ems(path, strict=True)


def test_one_digit_type_padded_with_a_blank_reads_the_same(tmp_path):
    lines = _lines(HOURS[0])[:6]
    padded = [
        s.replace(f" {s.split()[7]} ", f"  {s.split()[7]} ", 1) if len(s.split()[7]) == 1 else s
        for s in lines
    ]
    assert padded != lines
    a, _ = read_ems(_write(tmp_path, "a.ems", lines))
    b, rep = read_ems(_write(tmp_path, "b.ems", padded))
    assert rep.rejected == {} and np.array_equal(a.data, b.data) and np.array_equal(a.time, b.time)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "2019/01/14 00:00:00.000   43.5607   1.4809  207.0  1  8\n",
            r"not an EMS file: expected PRN YY MM DD",
        ),
        (
            "     2.11           B                   SBAS               RINEX VERSION / TYPE\n",
            r"a RINEX file",
        ),
        ("123 19 01 14 00 00 00.000000 L1 250  2 C60A00\n", r"fractional seconds"),
    ],
)
def test_unknown_format_is_one_clear_error(tmp_path, text, message):
    path = tmp_path / "other.ems"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as err:
        read_ems(path)
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_missing_file_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_ems(tmp_path / "h99.ems")


def test_rejections_follow_the_input_order_of_files(tmp_path):
    good = _lines(HOURS[0])[:4]
    z = _write(tmp_path, "z.ems", [good[0], good[1][:50], good[2]])
    a = _write(tmp_path, "a.ems", [good[3][:30], good[3]])
    frames, report = read_ems([z, a])
    assert frames.rejected.select("file", "line").rows() == [(str(z), 2), (str(a), 1)]
    assert report.first_bad == f"{z}:2: line_length"
    assert [Path(frames.files[i]).name for i in frames.file] == ["z.ems", "z.ems", "a.ems"]


def test_separate_reads_concatenate_to_one_read():
    parts = [read_ems(p)[0] for p in (HOURS[2], HOURS[0])]
    joined = SbasFrames.concat(parts)
    once, _ = read_ems([HOURS[2], HOURS[0]])
    assert joined.files == once.files
    for name in ("time", "prn", "data", "crc_ok", "file", "line"):
        assert np.array_equal(getattr(joined, name), getattr(once, name)), name
    first = joined.take(np.arange(5))
    assert len(first) == 5 and np.array_equal(first.data, once.data[:5])


def test_times_outside_the_gnss_era_are_counted_rejections(tmp_path):
    """Two-digit years read as 1980-2079: a year from PLAUSIBLE_END on, or a day before the GPS epoch
    (1980-01-06), comes from a corrupted digit and is rejected, counted and named (issue 13)."""
    good = _lines(HOURS[0])[:4]
    future = f"{PLAUSIBLE_END.year % 100:02d}"
    lines = [good[0], good[1][:4] + future + good[1][6:], good[2][:4] + "80 01 05" + good[2][12:], good[3]]
    path = _write(tmp_path, "era.ems", lines)
    frames, report = read_ems(path)
    assert frames.rejected.select("line", "reason").rows() == [
        (2, "time_out_of_range"),
        (3, "time_out_of_range"),
    ]
    assert report.rejected == {"time_out_of_range": 2} and report.unaccounted == 0
    assert report.first_bad == f"{path}:2: time_out_of_range"
    assert frames.line.tolist() == [1, 4]
    with pytest.raises(InputError, match=rf"era\.ems:2: time outside {re.escape(PLAUSIBLE_SPAN)}"):
        read_ems(path, strict=True)


def test_truncated_gzip_is_one_input_error_naming_the_file():
    """The first 20 lines of h00.ems gzipped, cut to half the compressed bytes (PROVENANCE.md)."""
    path = EMS / "bad" / "h00-truncated.gz"
    for arg in (path, [HOURS[0], path]):
        with pytest.raises(InputError, match="truncated or corrupt gzip") as err:
            read_ems(arg)
        assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_utf8_byte_order_mark_is_skipped(tmp_path):
    path = tmp_path / "bom.ems"
    path.write_bytes(b"\xef\xbb\xbf" + gzip.decompress(HOURS[0].read_bytes()))
    frames, report = read_ems(path)
    ref, _ = read_ems(HOURS[0])
    assert report.rejected == {} and np.array_equal(frames.data, ref.data) and frames.line[0] == 1
