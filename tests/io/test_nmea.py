"""NMEA 0183 GFA (issue 16): the pynmeagps-written fixture (no real GFA recording exists) and the real
gpsd logs without GFA (tests/data/nmea/PROVENANCE.md).

Values are checked against pynmeagps's own stream reader (``NMEAReader`` over the file), times against
IERS Bulletin C (GPS-UTC 17 s before 2017-01-01, 18 s after).
"""

from __future__ import annotations

import datetime as dt
import gzip
import io
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from pynmeagps import NMEAReader

from overbound.io.geodesy import MEAN_POSITION, Reference
from overbound.io.nmea import read_nmea
from overbound.io.open import read, sniff
from overbound.io.schema import InputError

DATA = Path(__file__).resolve().parents[1] / "data" / "nmea"
GFA = DATA / "gfa_sbas.nmea.gz"
TRUTH = Reference(50.848642, 4.732128, 80.93 + 47.40)
GPSD = sorted(DATA.glob("*.log.gz"))


def _stream(path: Path) -> dict[str, list]:
    out: dict[str, list] = {"GFA": [], "GGA": []}
    reader = NMEAReader(io.BytesIO(gzip.decompress(path.read_bytes())), quitonerror=0, validate=0)
    for _, msg in reader:
        if msg is not None and msg.msgID in out:
            out[msg.msgID].append(msg)
    return out


def test_sniffed_as_nmea():
    assert {sniff(p) for p in [GFA, *GPSD]} == {"nmea"}


def test_fixture_counts_times_and_quirks():
    table, report = read(GFA, reference=TRUTH)
    assert report.format == "nmea" and report.rows_read == 600 and report.rows_kept == 599
    assert report.rejected == {"bad_sentence": 1} and report.first_bad.startswith("125: bad sentence")
    assert report.invalidated == {"nan_pl": 1}  # second 90: empty protection levels
    t = table["time"].to_list()
    assert t[0] == dt.datetime(2016, 12, 31, 23, 55, 17)  # 23:55:00 UTC + 17 s
    assert t[-1] == dt.datetime(2017, 1, 1, 0, 5, 17)  # 00:04:59 UTC + 18 s, the day rolled over without RMC
    gps = np.array(t, dtype="datetime64[us]")
    steps = np.diff(gps).astype(np.int64) // 1_000_000
    assert sorted(set(steps.tolist())) == [1, 2]  # 2 s: the corrupt sentence and the leap second
    assert int((steps == 2).sum()) == 2
    at = {k: dt.datetime(2016, 12, 31, 23, 55, 17) + dt.timedelta(seconds=k) for k in (60, 90, 120)}
    row = {k: table.row(t.index(v), named=True) for k, v in at.items()}  # seconds 60, 90, 120
    assert np.isnan(row[60]["hpe"]) and row[60]["mode"] == "no fix"  # GGA quality 0
    assert np.isnan(row[90]["hpl"])
    assert row[120]["alert"] and int(table["alert"].sum()) == 1  # SBAS integrity "U"


def test_values_equal_pynmeagps_decoding():
    table, _ = read(GFA, reference=TRUTH)
    s = _stream(GFA)
    gfa = [m for m in s["GFA"] if isinstance(m.hprotlvl, float)]
    gga = {m.time: m for m in s["GGA"]}
    ok = [m for m in gfa if gga[m.time].quality > 0 and m.time != dt.time(23, 55, 30)]
    got = table.filter(table["hpl"].is_finite())
    np.testing.assert_array_equal(got["hpl"].to_numpy(), [m.hprotlvl for m in ok])
    np.testing.assert_array_equal(got["vpl"].to_numpy(), [m.vprotlvl for m in ok])
    g = [gga[m.time] for m in ok]
    e, _, u = pymap3d.geodetic2enu([m.lat for m in g], [m.lon for m in g], [m.alt + m.sep for m in g],
                                   TRUTH.lat_deg, TRUTH.lon_deg, TRUTH.height_m)  # fmt: skip
    np.testing.assert_allclose(got["east"].to_numpy(), e, atol=1e-9)
    np.testing.assert_allclose(got["vpe"].to_numpy(), u, atol=1e-9)
    assert abs(float(np.mean(u))) < 0.2 and 0.6 < float(np.std(u)) < 1.2  # the fixture's 0.9 m noise


def test_mean_reference():
    table, report = read(GFA, reference=MEAN_POSITION)
    assert any("not truth" in n for n in report.notes)
    assert abs(table["vpe"].fill_nan(None).mean()) < 1e-6  # over the epochs with a solution


@pytest.mark.parametrize("path", GPSD, ids=lambda p: p.name)
def test_real_logs_without_gfa_are_refused_naming_the_file(path):
    with pytest.raises(
        InputError, match=rf"{path.name}: no GFA sentence .*GBS sentences are RAIM error estimates"
    ):
        read_nmea(path, reference=TRUTH)


def test_strict_and_missing_date():
    with pytest.raises(InputError, match=r"gfa_sbas\.nmea\.gz:125: bad sentence"):
        read_nmea(GFA, reference=TRUTH, strict=True)
    text = b"\n".join(ln for ln in gzip.decompress(GFA.read_bytes()).splitlines() if b"RMC" not in ln)
    with pytest.raises(InputError, match="no date"):
        read_nmea(io.BytesIO(text), reference=TRUTH)


def test_corrupt_address_is_a_counted_rejection():
    """A talker pynmeagps cannot read gives it no message (fuzz case 811): rejected, not a traceback."""
    lines = gzip.decompress(GFA.read_bytes()).splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith(b"$GNGFA"))
    lines[k] = b"$G\xffGFA" + lines[k][6:]
    _, report = read_nmea(io.BytesIO(b"\n".join(lines)), reference=TRUTH)
    assert report.rejected == {"bad_sentence": 2} and report.rows_kept == 598 and report.unaccounted == 0
    assert "undecodable address" in report.first_bad
