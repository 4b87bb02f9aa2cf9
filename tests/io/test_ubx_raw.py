"""u-blox raw-log reader: real EGNOS SDK (hex-wrapped) and RTKLIB MSAS (binary) cuts, and bad input.

Fixtures: tests/data/sbas/ublox (PROVENANCE.md there).
"""

from __future__ import annotations

import datetime as dt
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
    assert rep.unaccounted == 0 and rep.rows_read == 1019 + 1  # the bad token is a row too
    good, _ = read_ubx_raw(SDK)
    assert raw.obs["time"].n_unique() == good.obs["time"].n_unique() - 1


def test_not_ubx():
    with pytest.raises(InputError, match="not a u-blox UBX log"):
        read_ubx_raw(io.BytesIO(b"     2.11           OBSERVATION DATA"))


# --------------------------------------------------------------------------- issue 13: rows are frames

BAD = DATA / "ublox" / "bad"


def _frames(data: bytes) -> list[tuple[int, int]]:
    """(start, end) of every UBX frame of a clean binary log (NMEA text between frames skipped)."""
    out, pos = [], 0
    while (j := data.find(b"\xb5\x62", pos)) >= 0:
        end = j + 8 + int.from_bytes(data[j + 4 : j + 6], "little")
        out.append((j, end))
        pos = end
    return out


def _checksummed(frame: bytes) -> bytes:
    """The frame with its 8-bit Fletcher checksum recomputed over class .. payload."""
    a = b = 0
    for x in frame[2:-2]:
        a = (a + x) & 0xFF
        b = (b + a) & 0xFF
    return frame[:-2] + bytes([a, b])


@pytest.mark.parametrize(("path", "n_frames"), [(MSAS, 270), (SDK, 1019)])
def test_rows_are_frames_and_balance(path, n_frames):
    """kept + rejected = read, in frames: every frame of the clean logs is kept (used or not)."""
    raw, rep = read_ubx_raw(path)
    assert rep.rows_read == rep.rows_kept == n_frames and rep.unaccounted == 0
    assert rep.first_bad == ""
    assert f"observation rows: {raw.obs.height} " in "\n".join(rep.notes)
    frames = {k: v for k, v in raw.counts.items() if k not in ("markers_skipped", "nmea_skipped")}
    assert sum(frames.values()) == n_frames


@pytest.mark.parametrize(
    ("name", "offset"), [("ubx-raw-cut-inside-frame.ubx", 992), ("ubx-raw-hex-cut-inside-frame.txt", 1139)]
)
def test_file_cut_inside_a_frame_is_a_counted_truncated_frame(name, offset):
    """Binary: the first 1,100 bytes of the MSAS log, cut inside its second RXM-RAW. Hex-wrapped: the
    first 1,240 characters of the SDK log, cut after 101 hex digits of an AID-EPH token (an odd count,
    which was a ``bad_hex`` token before)."""
    raw, rep = read_ubx_raw(BAD / name)
    assert rep.rejected == {"truncated_frame": 1}
    assert (rep.rows_read, rep.rows_kept, rep.unaccounted) == (4, 3, 0)
    assert rep.first_bad.startswith(f"@{offset}: truncated_frame")
    assert raw.obs["time"].n_unique() == 1


def test_truncated_gzip_is_one_input_error_naming_the_file():
    path = BAD / "ubx-raw-truncated.gz"
    with pytest.raises(InputError, match="truncated or corrupt gzip") as err:
        read_ubx_raw(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_bad_epochs_repeats_and_unframed_bytes_are_counted_frames():
    """A week outside 1980..PLAUSIBLE_END (checksum still right), a repeated raw epoch, a repeated SBAS
    frame and a frame whose sync bytes are damaged: each one frame rejected, its reason and offset named."""
    data = gzip.decompress(MSAS.read_bytes())
    spans = _frames(data)
    raws = [s for s in spans if data[s[0] + 2 : s[0] + 4] == b"\x02\x10"]
    sbas = [s for s in spans if data[s[0] + 2 : s[0] + 4] == b"\x02\x11" and data[s[0] + 7] >= 120]  # svid
    (a1, e1), (a2, e2), (a3, e3) = raws[1], raws[2], raws[3]
    future = bytearray(data[a1:e1])
    future[6 + 4 : 6 + 6] = (32767).to_bytes(2, "little", signed=True)  # week 32767: year 2608
    past = bytearray(data[a3:e3])
    past[6 + 4 : 6 + 6] = (-1).to_bytes(2, "little", signed=True)  # before 1980-01-06
    s0, t0 = sbas[-1]
    k0, k1 = spans[-1]
    damaged = (
        data[:a1] + _checksummed(bytes(future)) + data[e1:a2] + data[a2:e2] + data[a2:e2] + data[e2:a3]
        + _checksummed(bytes(past)) + data[e3:s0] + data[s0:t0] + data[s0:t0] + data[t0:k0]
        + b"\xb5\x00" + data[k0 + 2 : k1]
    )  # fmt: skip
    good, _ = read_ubx_raw(MSAS)
    raw, rep = read_ubx_raw(io.BytesIO(damaged))
    assert rep.rejected == {
        "time_out_of_range": 2,
        "duplicate_epoch": 1,
        "duplicate_sbas": 1,
        "unframed_bytes": 1,
    }
    assert rep.unaccounted == 0 and rep.rows_read == 270 + 2  # the two repeats
    assert rep.first_bad.startswith(f"@{a1}: time_out_of_range")
    assert raw.obs["time"].n_unique() == good.obs["time"].n_unique() - 2
    assert raw.obs["time"].max() < dt.datetime(2009, 1, 1) and raw.obs["time"].min() > dt.datetime(2008, 1, 1)
    assert len(raw.frames) == len(good.frames)
