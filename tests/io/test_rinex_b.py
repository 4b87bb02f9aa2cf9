"""RINEX-B reader: gLAB's conversion of three real EGNOS EMS hours (tests/data/sbas/rinexb, see
PROVENANCE.md there), damaged copies of it, the layout variants of other writers, and process()."""

from __future__ import annotations

import datetime as dt
import gzip
import io
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from overbound.cli import main
from overbound.io.ems import read_ems
from overbound.io.gpstime import PLAUSIBLE_END, PLAUSIBLE_SPAN
from overbound.io.rinex_b import read_rinex_b
from overbound.io.schema import InputError
from overbound.sbas.messages import decode
from overbound.sbas.run import process

DATA = Path(__file__).resolve().parents[1] / "data" / "sbas"
RINEXB = DATA / "rinexb" / "egnos123_h02-04.19b.gz"
EMS = [DATA / "ems" / "h02.ems.gz", DATA / "engine" / "h03.ems.gz", DATA / "engine" / "h04.ems.gz"]
OBS = DATA / "engine" / "SYNT0140_h02-04.19o.gz"
NAV = DATA / "engine" / "brdc0140.19n.gz"
_EPOCH = dt.datetime(1970, 1, 1)
_US = dt.timedelta(microseconds=1)
_HEADER = 3  # lines of the fixture's header


def _lines() -> list[str]:
    return gzip.decompress(RINEXB.read_bytes()).decode().splitlines()


def _write(tmp_path: Path, name: str, lines: list[str], end: str = "\n") -> Path:
    path = tmp_path / name
    path.write_bytes((end.join(lines) + end).encode())
    return path


def _slow_parse(lines: list[str]) -> list[tuple[int, int, bytes]]:
    """Independent reading of gLAB's records: (PRN, first-bit whole second + 1 s in GPST us, bytes)."""
    body = lines[lines.index(next(s for s in lines if "END OF HEADER" in s)) + 1 :]
    out = []
    for rec, d1, d2 in zip(body[0::3], body[1::3], body[2::3], strict=True):
        prn, yy, mo, dd, hh, mi, ss = rec.split()[:7]
        t = dt.datetime(2000 + int(yy), int(mo), int(dd), int(hh), int(mi), int(float(ss)))
        data = bytes.fromhex("".join(d1.split()[1:] + d2.split()))
        out.append((int(prn), (t + dt.timedelta(seconds=1) - _EPOCH) // _US, data))
    return out


def test_fixture_reads_record_by_record_the_same():
    lines = _lines()
    frames, report = read_rinex_b(RINEXB)
    expected = _slow_parse(lines)
    assert len(frames) == len(expected) == report.rows_read == report.rows_kept
    assert frames.prn.tolist() == [e[0] for e in expected]
    assert frames.time.tolist() == [e[1] for e in expected]
    assert [bytes(r) for r in frames.data] == [e[2] for e in expected]
    assert frames.crc_ok.all() and report.rejected == {} and report.format == "rinex-b"
    # The line of a message is its record line.
    assert frames.line.tolist() == list(range(_HEADER + 1, len(lines), 3))
    assert lines[frames.line[-1] - 1].startswith("123 19 01 14 04 59 58.1")


def test_same_messages_and_times_as_the_ems_hours():
    """gLAB wrote the EMS tag - 1 s (+ its 0.1 s flight time): the reader gives back the EMS tag."""
    rb, _ = read_rinex_b(RINEXB)
    ems, _ = read_ems(EMS)
    assert len(rb) == len(ems) == 9364
    for name in ("time", "prn", "data", "crc_ok"):
        assert np.array_equal(getattr(rb, name), getattr(ems, name)), name
    assert rb.to_frame()["time"][0] == dt.datetime(2019, 1, 14, 2, 0, 0)


def test_gzip_plain_stream_and_crlf_read_the_same(tmp_path):
    lines = _lines()
    ref, _ = read_rinex_b(RINEXB)
    plain = _write(tmp_path, "egnos123.19b", lines)
    crlf = _write(tmp_path, "crlf.19b", lines, end="\r\n")
    stream = io.BytesIO(RINEXB.read_bytes())
    for src in (plain, crlf, stream):
        got, rep = read_rinex_b(src)
        assert rep.rejected == {}
        assert np.array_equal(got.time, ref.time) and np.array_equal(got.data, ref.data)


def _damaged(tmp_path: Path) -> Path:
    """The first 12 records, damaged one by one (lines numbered from 1)."""
    good = _lines()[: _HEADER + 36]
    lines = list(good)
    # Record k (from 0) is on line 4 + 3k, its data lines follow.
    lines[4] = good[4][:29]  # record 0: first data line (line 5) cut inside a byte
    lines[10] = good[10][:10] + "G" + good[10][11:]  # record 2: not a hex digit on line 11
    lines[12] = good[12][:7] + "13" + good[12][9:]  # record 3 (line 13): month 13
    flipped = f"{int(good[17][8], 16) ^ 4:X}"  # record 4 (line 16): a data bit, the CRC fails
    lines[17] = good[17][:8] + flipped + good[17][9:]
    lines[18] = "033" + good[18][3:]  # record 5 (line 19): a GPS PRN, not an SBAS GEO
    del lines[23]  # record 6 (line 22): its second data line lost, a truncated record
    return _write(tmp_path, "damaged.19b", lines)


def test_malformed_records_are_counted_with_file_and_line(tmp_path):
    path = _damaged(tmp_path)
    frames, report = read_rinex_b(path)
    rej = frames.rejected
    assert rej.select("line", "reason").rows() == [
        (5, "layout"),
        (11, "bad_hex"),
        (13, "bad_time"),
        (19, "not_sbas_prn"),
        (22, "byte_count"),
    ]
    assert rej["file"].unique().to_list() == [str(path)]
    assert report.first_bad == f"{path}:5: layout"
    assert report.rows_read == 12 and len(frames) == 7
    assert frames.line.tolist() == [7, 16, 24, 27, 30, 33, 36]
    assert frames.crc_ok.tolist() == [True, False, True, True, True, True, True]
    assert report.invalidated == {"bad_crc": 1}
    assert decode(frames).counts["bad_crc"] == 1  # the decoder drops and counts it, as for EMS


@pytest.mark.parametrize(
    ("cut", "message"),
    [
        (lambda s: [*s[:4], s[4][:29], *s[5:]], r"damaged\.19b:5: malformed RINEX-B record"),
        (
            lambda s: [*s[:5], s[5][:10] + "x" + s[5][11:], *s[6:]],
            r"damaged\.19b:6: message byte that is not",
        ),
        (
            lambda s: [*s[:3], s[3][:13] + "24" + s[3][15:], *s[4:]],
            r"damaged\.19b:4: date or time out of range",
        ),
        (lambda s: s[:5] + s[6:], r"damaged\.19b:4: truncated record"),
        (lambda s: s + s[3:6], r"damaged\.19b:40: duplicate message"),
    ],
)
def test_strict_raises_naming_file_and_line(tmp_path, cut, message):
    lines = cut(_lines()[: _HEADER + 36])
    path = _write(tmp_path, "damaged.19b", lines)
    with pytest.raises(InputError, match=message) as err:
        read_rinex_b(path, strict=True)
    assert "\n" not in str(err.value)
    _, report = read_rinex_b(path)  # not strict: counted instead
    assert sum(report.rejected.values()) == 1


def test_prn_forms_two_digit_year_short_record_and_repeated_header(tmp_path):
    """Other writers: ``S23`` / ``S123`` for PRN 123, no optional fields, files joined with cat."""
    lines = _lines()
    head, body = lines[:_HEADER], lines[_HEADER : _HEADER + 12]
    variant = list(body)
    variant[0] = "S23" + body[0][3:]
    variant[3] = "S123" + body[3][3:]
    variant[6] = body[6][:23]  # epoch only: 32 bytes assumed
    joined = head + variant[:6] + ["COMMENT LINE BETWEEN FILES"] + head + variant[6:]
    frames, report = read_rinex_b(_write(tmp_path, "joined.19b", joined))
    ref, _ = read_rinex_b(_write(tmp_path, "ref.19b", head + body))
    assert report.rejected == {"layout": 1}  # the line between the files, named
    assert frames.rejected.row(0) == (str(tmp_path / "joined.19b"), 10, "layout")
    assert np.array_equal(frames.prn, ref.prn) and np.array_equal(frames.time, ref.time)
    assert np.array_equal(frames.data, ref.data)
    # 99 is 1999 (two-digit years below 80 are 20YY, as for EMS).
    old, _ = read_rinex_b(_write(tmp_path, "old.19b", [*head, "123 99" + body[0][6:], *body[1:3]]))
    assert old.to_frame()["time"][0].year == 1999


def test_other_band_and_extra_receiver_bytes(tmp_path):
    lines = _lines()
    head, rec, d1, d2 = lines[:_HEADER], *lines[_HEADER : _HEADER + 3]
    l5 = rec[:25] + "L5" + rec[27:]
    longer = rec[:30] + " 34" + rec[33:]  # two receiver bytes after the message
    frames, report = read_rinex_b(_write(tmp_path, "x.19b", [*head, l5, d1, d2, longer, d1, d2 + " 0A 0B"]))
    assert report.rejected == {"not_l1": 1}
    assert len(frames) == 1 and frames.crc_ok.all() and frames.line.tolist() == [7]


_END = f"{'':60}END OF HEADER"


@pytest.mark.parametrize(
    ("lines", "message"),
    [
        (["123 19 01 14 02 00 00 2 C6093F"], r"not a RINEX-B file: expected a RINEX VERSION / TYPE"),
        ([f"{'2.11':>9}{'O':>12}{'RINEX VERSION / TYPE':>59}", _END], "type 'O'"),
        ([f"{'3.04':>9}{'B':>12}{'RINEX VERSION / TYPE':>59}", _END], "version 3.04 not supported"),
        ([f"{'2.10':>9}{'B':>12}{'RINEX VERSION / TYPE':>59}"], "header without END OF HEADER"),
    ],
)
def test_not_rinex_b_is_one_clear_error(tmp_path, lines, message):
    path = _write(tmp_path, "other.19b", lines)
    with pytest.raises(InputError, match=message) as err:
        read_rinex_b(path)
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_process_with_rinex_b_is_process_with_the_ems_files():
    with_ems = process(OBS, NAV, EMS)
    with_rinexb = process(OBS, NAV, RINEXB)
    assert with_rinexb.epochs.equals(with_ems.epochs)
    assert with_rinexb.epochs["vpl"].is_finite().sum() > 250  # solutions, not only empty epochs
    assert [r.format for role, r in with_rinexb.reports if role == "sbas"] == ["rinex-b"]


def test_cli_recognises_rinex_b_by_content(tmp_path):
    plain = _write(tmp_path, "messages.txt", _lines())  # no telling extension
    out = tmp_path / "e.parquet"
    args = ["sbas", "--obs", str(OBS), "--nav", str(NAV), "--sbas", str(plain), "-o", str(out)]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    assert out.exists()
    res = CliRunner().invoke(main, ["sbas", "--obs", str(RINEXB), "--nav", str(NAV), "-o", str(out)])
    assert res.exit_code == 2 and "a RINEX-B SBAS message file given as --obs" in res.output


def test_epochs_outside_the_gnss_era_are_counted_rejections(tmp_path):
    """A two-digit year from PLAUSIBLE_END on, or a day before 1980-01-06, is a counted, named rejection."""
    lines = _lines()[: _HEADER + 9]
    future = f"{PLAUSIBLE_END.year % 100:02d}"
    lines[3] = lines[3][:4] + future + lines[3][6:]
    lines[6] = lines[6][:4] + "80 01 05" + lines[6][12:]
    path = _write(tmp_path, "era.19b", lines)
    frames, report = read_rinex_b(path)
    assert frames.rejected.select("line", "reason").rows() == [
        (4, "time_out_of_range"),
        (7, "time_out_of_range"),
    ]
    assert report.rejected == {"time_out_of_range": 2} and report.unaccounted == 0
    assert frames.line.tolist() == [10]
    with pytest.raises(InputError, match=rf"era\.19b:4: epoch outside {re.escape(PLAUSIBLE_SPAN)}"):
        read_rinex_b(path, strict=True)


def test_truncated_gzip_is_one_input_error_naming_the_file():
    """Header and first 10 records of the fixture gzipped, cut to half its bytes (PROVENANCE.md)."""
    path = DATA / "rinexb" / "bad" / "egnos123_h02-04-truncated.gz"
    with pytest.raises(InputError, match="truncated or corrupt gzip") as err:
        read_rinex_b(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_utf8_byte_order_mark_is_skipped(tmp_path):
    lines = _lines()[: _HEADER + 6]
    path = tmp_path / "bom.19b"
    path.write_bytes(b"\xef\xbb\xbf" + ("\n".join(lines) + "\n").encode())
    frames, report = read_rinex_b(path)
    assert len(frames) == 2 and report.rejected == {} and frames.line.tolist() == [4, 7]
