"""Septentrio SBF (issue 16): DOP (HPL/VPL) with PVTGeodetic, on the real samples of tests/data/sbf.

The decoded values are checked against pysbf2's own streaming reader (``SBFReader`` over the file,
not the block scan of the reader), the counts and spans against the samples' PROVENANCE.
"""

from __future__ import annotations

import binascii
import gzip
import io
import math
import struct
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from click.testing import CliRunner
from pysbf2 import SBFReader

from overbound.cli import main
from overbound.io.geodesy import MEAN_POSITION, Reference
from overbound.io.open import read, sniff
from overbound.io.sbf import read_sbf
from overbound.io.schema import InputError

DATA = Path(__file__).resolve().parents[1] / "data" / "sbf"
LOG = DATA / "log_0000.sbf.gz"
LEUVEN = Reference(50.848642, 4.732128, 128.33)  # the receiver's own fix (no surveyed position exists)


def _stream(path: Path) -> dict[str, list]:
    """PVTGeodetic and DOP blocks as pysbf2's stream reader decodes them."""
    out: dict[str, list] = {"PVTGeodetic": [], "DOP": []}
    for _, msg in SBFReader(io.BytesIO(gzip.decompress(path.read_bytes())), quitonerror=0):
        if msg is not None and msg.identity in out:
            out[msg.identity].append(msg)
    return out


def test_sniffed_as_sbf():
    assert {sniff(p) for p in DATA.glob("*.gz")} == {"sbf"}


def test_log_0000_against_pysbf2_and_the_provenance():
    table, report = read(LOG, reference=LEUVEN)
    blocks = _stream(LOG)
    assert report.format == "sbf" and report.rows_read == report.rows_kept == 12 and report.unaccounted == 0
    assert str(table["time"][0]) == "2025-04-01 11:02:21" and str(table["time"][-1]) == "2025-04-01 11:02:32"
    np.testing.assert_array_equal(table["hpl"].to_numpy(), [m.HPL for m in blocks["DOP"]])
    np.testing.assert_array_equal(table["vpl"].to_numpy(), [m.VPL for m in blocks["DOP"]])
    # PROVENANCE, to 2 decimals: HPL 3.34-3.69 m, VPL 5.22-5.76 m
    assert round(table["hpl"].min(), 2) == 3.34 and round(table["hpl"].max(), 2) == 3.69
    assert round(table["vpl"].min(), 2) == 5.22 and round(table["vpl"].max(), 2) == 5.76
    assert set(table["mode"].cast(str)) == {"SBAS"} and table["nsv"].to_list() == [
        m.NrSV for m in blocks["PVTGeodetic"]
    ]
    assert not table["alert"].any()
    pvt = blocks["PVTGeodetic"]
    lat, lon = np.degrees([m.Latitude for m in pvt]), np.degrees([m.Longitude for m in pvt])
    ref = (LEUVEN.lat_deg, LEUVEN.lon_deg, LEUVEN.height_m)
    e, n, u = pymap3d.geodetic2enu(lat, lon, [m.Height for m in pvt], *ref)
    np.testing.assert_allclose(table["east"].to_numpy(), e, atol=1e-9)
    np.testing.assert_allclose(table["vpe"].to_numpy(), u, atol=1e-9)
    np.testing.assert_allclose(table["hpe"].to_numpy(), np.hypot(e, n), atol=1e-9)


def test_mean_reference_gives_zero_mean_errors():
    table, report = read(LOG, reference=MEAN_POSITION)
    assert any("the mean of the receiver's own positions" in n for n in report.notes)
    for c in ("east", "north", "vpe"):
        assert abs(table[c].mean()) < 1e-6


def test_no_fix_and_do_not_use_levels_are_no_solution():
    table, report = read(DATA / "all_blocks_0000.sbf.gz", reference=LEUVEN)
    assert report.rows_read == report.rows_kept == 2 and report.invalidated == {}
    assert table["hpl"].is_nan().all() and table["hpe"].is_nan().all()
    assert set(table["mode"].cast(str)) == {"no PVT"}


def test_epoch_without_dop_is_counted():
    _, report = read(DATA / "pygpsdata_x5_pvtgeod.log.gz", reference=Reference(53.344, -2.2467, 131.0))
    assert report.rows_kept == 1 and report.invalidated == {"nan_pl": 1}
    assert any("1 epochs without a DOP block" in n for n in report.notes)


def test_refusals_name_the_file():
    with pytest.raises(InputError, match=r"pvtextra\.log\.gz: no PVTGeodetic block"):
        read_sbf(DATA / "pygpsdata_x5_pvtextra.log.gz", reference=LEUVEN)


def _pvt_offsets(data: bytes) -> list[int]:
    out, i = [], data.find(b"$@")
    while i >= 0:
        length = int.from_bytes(data[i + 6 : i + 8], "little")
        if int.from_bytes(data[i + 4 : i + 6], "little") & 0x1FFF == 4007:
            out.append(i)
        i = data.find(b"$@", i + length)
    return out


def test_corrupt_and_cut_blocks_are_counted():
    data = bytearray(gzip.decompress(LOG.read_bytes()))
    first = _pvt_offsets(bytes(data))[3]
    data[first + 20] ^= 0xFF  # inside the 4th PVTGeodetic: its CRC fails
    last = _pvt_offsets(bytes(data))[-1]
    cut = bytes(data[: last + 30])  # the file ends inside the last PVTGeodetic
    _, report = read_sbf(io.BytesIO(cut), reference=LEUVEN)
    assert report.rows_read == 12 and report.rows_kept == 10 and report.unaccounted == 0
    assert report.rejected == {"bad_block": 1, "truncated_block": 1}
    assert report.first_bad.startswith(f"{first}: bad block")
    with pytest.raises(InputError, match=rf"<stream>:{first}: bad block"):
        read_sbf(io.BytesIO(cut), reference=LEUVEN, strict=True)


def test_analyze_an_sbf_log(tmp_path):
    args = [
        "analyze",
        str(LOG),
        "--reference",
        "mean",
        "-o",
        str(tmp_path / "o"),
        "--no-evt",
        "--no-parametric",
    ]
    res = CliRunner().invoke(main, [*args, "--no-confidence"])
    assert res.exit_code == 0, res.output
    assert "12 epochs, 12 with solution" in res.output
    assert math.isfinite(float(res.output.split("HPE95 ")[1].split()[0]))


def test_do_not_use_levels_of_a_positioned_epoch_are_invalidated():
    """The 2nd DOP block's HPL set to -2e10 (its CRC recomputed: CRC-16-CCITT from the ID on)."""
    data = bytearray(gzip.decompress(LOG.read_bytes()))
    i, seen = data.find(b"$@"), 0
    while True:
        length = int.from_bytes(data[i + 6 : i + 8], "little")
        if int.from_bytes(data[i + 4 : i + 6], "little") & 0x1FFF == 4001:
            seen += 1
            if seen == 2:
                break
        i = data.find(b"$@", i + length)
    struct.pack_into("<f", data, i + 24, -2e10)  # HPL: float32 at byte 24 of the DOP block
    data[i + 2 : i + 4] = binascii.crc_hqx(bytes(data[i + 4 : i + length]), 0).to_bytes(2, "little")
    table, report = read_sbf(io.BytesIO(bytes(data)), reference=LEUVEN)
    assert report.invalidated == {"nan_pl": 1} and report.rows_kept == 12
    assert np.isnan(table["hpl"][1]) and np.isnan(table["hpe"][1]) and np.isfinite(table["hpl"][2])
