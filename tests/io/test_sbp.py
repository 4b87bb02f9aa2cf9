"""Swift Binary Protocol (issue 16): the sbp-written protection-level fixture and the real libsbp
capture without protection levels (tests/data/sbp/PROVENANCE.md).

Values are checked against the sbp package's own stream framer (``Framer`` over the file).
"""

from __future__ import annotations

import gzip
import io
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from sbp.client import Framer
from sbp.navigation import SBP_MSG_POS_LLH, SBP_MSG_PROTECTION_LEVEL

from overbound.io.geodesy import MEAN_POSITION, Reference
from overbound.io.open import read, sniff
from overbound.io.sbp import read_sbp
from overbound.io.schema import InputError

DATA = Path(__file__).resolve().parents[1] / "data" / "sbp"
PL = DATA / "pl_sbas.sbp.gz"
REAL = DATA / "roundtrip.sbp.gz"
REF = Reference(37.831240, -122.286510, -17.40)


def _framed(path: Path) -> dict[int, list]:
    out: dict[int, list] = {SBP_MSG_PROTECTION_LEVEL: [], SBP_MSG_POS_LLH: []}
    stream = io.BytesIO(gzip.decompress(path.read_bytes()))
    for msg, _ in Framer(stream.read, None, skip_metadata=True):
        if msg.msg_type in out:
            out[msg.msg_type].append(msg)
    return out


def test_sniffed_as_sbp():
    assert sniff(PL) == sniff(REAL) == "sbp"


def test_fixture_counts_and_quirks():
    table, report = read(PL, reference=REF)
    assert report.format == "sbp" and report.rows_read == 121 and report.rows_kept == 118
    assert report.rejected == {"bad_frame": 2, "truncated_frame": 1} and report.unaccounted == 0
    assert str(table["time"][0]) == "2020-03-25 03:25:00"  # GPS week 2098, tow 271,500 s
    assert int(table["alert"].sum()) == 1  # the safe-state VPL flag
    assert set(table.filter(table["hpl"].is_nan())["mode"].cast(str)) == {"invalid"}  # fix mode 0
    assert (
        table.filter(table["mode"] == "not given").height == 1
    )  # the deprecated message, timed by MSG_GPS_TIME


def test_values_equal_the_sbp_framer():
    table, _ = read(PL, reference=REF)
    framed = _framed(PL)[SBP_MSG_PROTECTION_LEVEL]
    ok = [m for m in framed if (m.flags >> 15) & 7]
    got = table.filter(table["hpl"].is_finite() & (table["mode"] != "not given"))
    np.testing.assert_array_equal(got["hpl"].to_numpy(), [m.hpl / 100.0 for m in ok])
    np.testing.assert_array_equal(got["vpl"].to_numpy(), [m.vpl / 100.0 for m in ok])
    llh = ([m.lat for m in ok], [m.lon for m in ok], [m.height for m in ok])
    _, _, u = pymap3d.geodetic2enu(*llh, REF.lat_deg, REF.lon_deg, REF.height_m)
    np.testing.assert_allclose(got["vpe"].to_numpy(), u, atol=1e-9)


def test_mean_reference():
    table, report = read(PL, reference=MEAN_POSITION)
    assert any("not truth" in n for n in report.notes)
    assert abs(table["vpe"].fill_nan(None).mean()) < 1e-6


def test_refusals_name_the_file():
    with pytest.raises(
        InputError, match=r"roundtrip\.sbp\.gz: no MSG_PROTECTION_LEVEL .*466 MSG_POS_LLH, 466 in SBAS"
    ):
        read_sbp(REAL, reference=REF)
    with pytest.raises(InputError, match=r"pl_sbas\.sbp\.gz:\d+: bad frame: CRC error"):
        read_sbp(PL, reference=REF, strict=True)
