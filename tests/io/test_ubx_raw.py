"""u-blox raw-log reader: real EGNOS SDK (hex-wrapped) and RTKLIB MSAS (binary) cuts, and bad input.

Fixtures: tests/data/sbas/ublox (PROVENANCE.md there).
"""

from __future__ import annotations

import gzip
import io
from pathlib import Path

import numpy as np
import pymap3d
import pytest

from overbound.io.ems import read_ems
from overbound.io.schema import InputError
from overbound.io.ubx_raw import read_ubx_raw
from overbound.sbas.run import _spp

DATA = Path(__file__).resolve().parents[1] / "data" / "sbas"
SDK = DATA / "ublox" / "egnos_sdk_20121025_1202-1217.txt.gz"
MSAS = DATA / "ublox" / "ubx_20080526_60s.ubx.gz"
#: Median SPP of the whole hour, computed by the data set's author (its PROVENANCE.md).
SDK_SPP = (4245483.5, 701697.9, 4692764.0)


@pytest.fixture(scope="module")
def sdk():
    return read_ubx_raw(SDK)


def test_sdk_counts(sdk):
    raw, rep = sdk
    assert raw.counts["RXM-RAW"] == raw.obs["time"].n_unique()
    assert raw.counts["markers_skipped"] > 0  # the SDK's "ComputeP" notes
    assert set(raw.obs["system"].unique()) == {"G", "S"}
    assert raw.frames.crc_ok.all() and set(raw.frames.prn.tolist()) == {120}
    assert rep.rejected == {}
    # 15 PRNs carry AID-EPH in the whole hour; PRN 11's first comes at 12:33, after this cut
    assert sorted(raw.eph["prn"].to_list()) == [3, 6, 7, 8, 15, 16, 18, 19, 21, 22, 24, 26, 27, 30]


def test_sdk_ephemerides_place_the_receiver(sdk):
    """Decoded AID-EPH orbits and clocks put a plain SPP within metres of the author's independent one."""
    raw, _ = sdk
    x = _spp(raw.obs, raw.eph, "sdk")
    e, n, _ = pymap3d.ecef2enu(*x, *pymap3d.ecef2geodetic(*SDK_SPP))
    assert np.hypot(e, n) < 5.0


def test_sbas_time_tags_follow_the_preambles(sdk):
    raw, _ = sdk
    start_s = (raw.frames.time // 1_000_000) - 1  # EMS-style tag = end of the 1-s slot
    phase = {0x53: 0, 0x9A: 1, 0xC6: 2}
    assert all(s % 3 == phase[p] for s, p in zip(start_s.tolist(), raw.frames.preamble.tolist(), strict=True))
    assert (np.diff(raw.frames.time) > 0).all()


def test_msas_binary_frames_equal_the_ems_fixture():
    """The binary path gives the same messages and tags as the EMS lines made from the same log."""
    raw, rep = read_ubx_raw(MSAS)
    ems, _ = read_ems(DATA / "msas" / "ubx_20080526_sbas.ems.gz")
    k = len(raw.frames)
    assert k == 120 and rep.rejected == {}
    np.testing.assert_array_equal(raw.frames.time, ems.time[:k])
    np.testing.assert_array_equal(raw.frames.data, ems.data[:k])
    assert raw.eph["prn"].n_unique() == 9  # ephemerides from GPS RXM-SFRB subframes


def test_bad_tokens_and_frames_are_counted():
    text = gzip.decompress(SDK.read_bytes())
    tokens = text.split(b",")
    k = [i for i, t in enumerate(tokens) if t.startswith(b"b5620210")][5]  # a RAW epoch after the first
    bad = tokens[k][:-2] + (b"00" if tokens[k][-2:] != b"00" else b"11")  # checksum broken
    damaged = b",".join([*tokens[:k], bad, b"zz-not-hex", *tokens[k + 1 :]])
    raw, rep = read_ubx_raw(io.BytesIO(damaged))
    assert rep.rejected == {"bad_frame": 1, "bad_hex": 1}
    good, _ = read_ubx_raw(SDK)
    assert raw.obs["time"].n_unique() == good.obs["time"].n_unique() - 1


def test_not_ubx():
    with pytest.raises(InputError, match="not a u-blox UBX log"):
        read_ubx_raw(io.BytesIO(b"     2.11           OBSERVATION DATA"))
