"""NovAtel OEM logs (issue 16): the novatel-edie-written BESTPOS + RAIMSTATUS fixtures, ASCII and binary
(tests/data/novatel/PROVENANCE.md).

Values are checked against novatel-edie's own ``Parser`` (a different path through the library than
the reader's ``Framer`` + ``Decoder``), decoding the file in the test.
"""

from __future__ import annotations

import gzip
import io
import json
from pathlib import Path

import novatel_edie as ne
import numpy as np
import pymap3d
import pytest
from click.testing import CliRunner
from polars.testing import assert_frame_equal

from overbound.cli import main
from overbound.io.geodesy import MEAN_POSITION, Reference
from overbound.io.novatel import read_novatel
from overbound.io.open import _novatel_crc, read, sniff
from overbound.io.schema import InputError

DATA = Path(__file__).resolve().parents[1] / "data" / "novatel"
ASC = DATA / "bestpos_raimstatus.asc.gz"
BIN = DATA / "bestpos_raimstatus.bin.gz"
REF = Reference(51.11635, -114.0389, 1031.3)  # near the fixture's mean (ellipsoidal height)
GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "us")


def _parsed(path: Path) -> dict[str, dict[int, object]]:
    """novatel-edie's Parser over the whole file: the first BESTPOS and RAIMSTATUS of each time (µs
    since the GPS epoch), with the number of records of each."""
    parser = ne.oem.Parser()
    parser.write(gzip.decompress(path.read_bytes()))
    out: dict[str, dict[int, object]] = {"BESTPOS": {}, "RAIMSTATUS": {}}
    counts = {"BESTPOS": 0, "RAIMSTATUS": 0}
    for msg in parser:
        name = getattr(msg, "name", "")
        if name in out:
            t = msg.header.week * 604_800_000_000 + int(msg.header.milliseconds) * 1000
            out[name].setdefault(t, msg)
            counts[name] += 1
    out["counts"] = counts  # type: ignore[assignment]
    return out


def _times_us(table) -> np.ndarray:
    return (table["time"].to_numpy().astype("datetime64[us]") - GPS_EPOCH).astype(np.int64)


def test_sniffed_as_novatel_and_the_crc_is_novatels():
    assert sniff(ASC) == sniff(BIN) == "novatel"
    record = gzip.decompress(BIN.read_bytes())[:200]
    length = 28 + int.from_bytes(record[8:10], "little")
    assert _novatel_crc(record[:length]) == ne.calculate_crc(record[:length])
    assert _novatel_crc(record[:length]) == int.from_bytes(record[length : length + 4], "little")


@pytest.mark.parametrize("path", [ASC, BIN], ids=["ascii", "binary"])
def test_counts_kept_and_rejected(path):
    table, report = read(path)
    lib = _parsed(path)
    times = set(lib["BESTPOS"]) | set(lib["RAIMSTATUS"])
    assert lib["counts"] == {"BESTPOS": 290, "RAIMSTATUS": 288}  # one RAIMSTATUS corrupt, one cut
    assert report.format == "novatel" and report.rows_kept == len(times) == 290
    assert report.rejected == {"bad_record": 1, "truncated_record": 1}
    assert report.rows_read == 292 and report.unaccounted == 0 and report.truth is False
    assert "290 BESTPOS and 288 RAIMSTATUS records" in report.notes[0]
    np.testing.assert_array_equal(_times_us(table), sorted(times))
    gaps = np.diff(_times_us(table)) // 1_000_000
    assert sorted(set(gaps.tolist())) == [1, 11]  # 230-239 s not logged


@pytest.mark.parametrize("path", [ASC, BIN], ids=["ascii", "binary"])
def test_values_equal_novatel_edie_decoding(path):
    table, _ = read(path, reference=REF)
    lib = _parsed(path)
    t = _times_us(table)
    pos = [lib["BESTPOS"].get(k) for k in t]
    raim = [lib["RAIMSTATUS"].get(k) for k in t]
    NA = ne.oem.enums.RAIMProtectionLevelStatus.NOT_AVAILABLE
    solved = np.array(
        [p is not None and r is not None and p.solution_status.name == "SOL_COMPUTED"
         and p.position_type.name != "NONE" for p, r in zip(pos, raim, strict=True)]
    )  # fmt: skip
    have_pl = np.array([r is not None and r.hpl_status != NA and r.vpl_status != NA for r in raim])
    ok = solved & have_pl
    assert ok.sum() == 277 and (solved & ~have_pl).sum() == 10
    np.testing.assert_array_equal(
        table["hpl"].to_numpy()[ok], [r.hpl for r, k in zip(raim, ok, strict=True) if k]
    )
    np.testing.assert_array_equal(
        table["vpl"].to_numpy()[ok], [r.vpl for r, k in zip(raim, ok, strict=True) if k]
    )
    assert np.isnan(table["hpl"].to_numpy()[~ok]).all() and np.isnan(table["vpe"].to_numpy()[~ok]).all()
    # ellipsoidal height = height above mean sea level + undulation (OEM7 manual, BESTPOS)
    llh = np.array(
        [
            (p.latitude, p.longitude, p.orthometric_height + p.undulation)
            for p, k in zip(pos, ok, strict=True)
            if k
        ]
    )
    e, n, u = pymap3d.geodetic2enu(*llh.T, REF.lat_deg, REF.lon_deg, REF.height_m)
    np.testing.assert_allclose(table["vpe"].to_numpy()[ok], u, atol=1e-9)
    np.testing.assert_allclose(table["hpe"].to_numpy()[ok], np.hypot(e, n), atol=1e-9)
    assert table["mode"].cast(str).to_list() == [p.position_type.name if p else "no BESTPOS" for p in pos]
    assert table["nsv"].to_list() == [p.num_soln_svs if p else None for p in pos]
    alert = [r is not None and r.integrity_status.name == "FAIL" for r in raim]
    assert table["alert"].to_list() == alert and sum(alert) == 1
    vpl_alert = [r is not None and r.vpl_status.name == "ALERT" for r in raim]
    assert sum(vpl_alert) == 1 and table["vpl"].to_numpy()[vpl_alert][0] == 55.0  # kept, not dropped


def test_ascii_and_binary_give_the_same_table():
    for ref in (None, REF):
        (a, ra), (b, rb) = read(ASC, reference=ref), read(BIN, reference=ref)
        assert_frame_equal(a, b)
        assert (ra.rows_read, ra.rejected, ra.invalidated) == (rb.rows_read, rb.rejected, rb.invalidated)


def test_without_reference_the_pls_alone_with_reference_the_errors():
    table, report = read(BIN)
    assert report.truth is False and table["hpe"].is_nan().all() and table["vpe"].is_nan().all()
    assert table["hpl"].is_finite().sum() == 277 and not report.invalidated
    table, report = read(BIN, reference=MEAN_POSITION)
    assert report.truth is True and any("not truth" in n for n in report.notes)
    assert report.invalidated == {"nan_pl": 10}  # positioned, but HPL/VPL NOT_AVAILABLE
    assert abs(table["vpe"].fill_nan(None).mean()) < 0.05  # the mean of 275 solutions (ENU about it)


def test_corrupt_records_counted_strict_raises_and_no_raimstatus_refused():
    with pytest.raises(InputError, match=r"bestpos_raimstatus\.bin\.gz:\d+: bad record: .*\(byte \d+\)"):
        read_novatel(BIN, strict=True)
    data = gzip.decompress(ASC.read_bytes())
    lines = data.splitlines(keepends=True)
    doubled = b"".join(lines[:4] + lines[2:4] + lines[4:10])  # the records of second 1 repeated
    _, report = read_novatel(io.BytesIO(doubled))
    assert report.rejected == {"duplicate_record": 2} and report.rows_kept == 5 and report.unaccounted == 0
    pos_only = b"".join(ln for ln in lines if ln.startswith(b"#BESTPOSA"))
    with pytest.raises(InputError, match=r"no RAIMSTATUS log: .*290 BESTPOS, 288 of them WAAS"):
        read_novatel(io.BytesIO(pos_only))


def test_analyze_reads_it_pl_only_and_with_the_mean_reference(tmp_path):
    res = CliRunner().invoke(main, ["analyze", str(BIN), "-o", str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert (
        doc["epochs"]["total"] == 290 and doc["epochs"]["with_pl"] == 277 and doc["epochs"]["rejected"] == 2
    )
    args = ["analyze", str(ASC), "--reference", "mean", "-o", str(tmp_path / "b")]
    res = CliRunner().invoke(main, [*args, "--no-confidence", "--no-evt", "--no-parametric"])
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "b" / "summary.json").read_text())
    table, _ = read(ASC, reference=MEAN_POSITION)
    solved = int((table["hpe"].is_finite() & table["hpl"].is_finite()).sum())
    assert doc["epochs"]["with_solution"] == solved == 277 and doc["epochs"]["invalidated"] == 10
    assert 0 < doc["accuracy"]["hpe95"] < 3 and 0 < doc["accuracy"]["vpe95"] < 5


def test_ascii_log_places_are_lines_and_binary_ones_bytes():
    text = gzip.decompress(ASC.read_bytes())
    with pytest.raises(InputError) as info:
        read_novatel(io.BytesIO(text), strict=True)
    line = int(str(info.value).split("(line ")[1].rstrip(")"))
    bad = text.splitlines()[line - 1]
    star = bad.index(b"*")  # the corrupt record, found by its line: its CRC-32 fails
    assert bad.startswith(b"#RAIMSTATUSA") and _novatel_crc(bad[1:star]) != int(bad[star + 1 :], 16)
    with pytest.raises(InputError, match=r"\(byte \d+\)"):
        read_novatel(io.BytesIO(gzip.decompress(BIN.read_bytes())), strict=True)


def test_raimstatus_without_bestpos_is_refused():
    text = gzip.decompress(ASC.read_bytes())
    raim_only = b"\r\n".join(ln for ln in text.splitlines() if ln.startswith(b"#RAIMSTATUSA"))
    with pytest.raises(InputError, match="no BESTPOS log"):
        read_novatel(io.BytesIO(raim_only))
