"""CRC-24Q and bit fields on real EGNOS messages, against bit-by-bit reference implementations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from overbound.io.ems import read_ems
from overbound.io.sbas_bits import field
from overbound.io.sbas_crc import POLY, crc24q, crc_ok, parity, parity_of_data

EMS = Path(__file__).resolve().parents[1] / "data" / "sbas" / "ems"


@pytest.fixture(scope="module")
def frames():
    return read_ems(EMS / "h00.ems.gz")[0]


def _bits(frame: np.ndarray) -> str:
    return "".join(f"{b:08b}" for b in frame.tolist())


def _crc_by_division(bits: str) -> int:
    """Remainder of bits * X^24 modulo the generator, one bit at a time (no table)."""
    reg = 0
    for b in bits:
        reg ^= int(b) << 23
        reg = ((reg << 1) ^ POLY) if reg & 0x800000 else reg << 1
        reg &= 0xFFFFFF
    return reg


def test_check_value_of_crc24q():
    # The published check value of CRC-24Q (and of RTCM 3's parity) for the ASCII string "123456789".
    assert int(crc24q(b"123456789")) == 0xCDE703
    assert int(crc24q(b"")) == 0


def test_table_driven_equals_bit_by_bit_division(frames):
    sample = frames.data[::97]
    expected = [_crc_by_division(_bits(f)[:226]) for f in sample]
    assert parity_of_data(sample).tolist() == expected
    assert parity(sample).tolist() == [int(_bits(f)[226:250], 2) for f in sample]


def test_real_messages_pass_and_every_single_bit_flip_fails(frames):
    assert crc_ok(frames.data).all()
    for frame in frames.data[[0, 1, 2, 1234]]:
        flips = np.repeat(frame[None, :], 250, axis=0)
        k = np.arange(250)
        flips[k, k // 8] ^= (0x80 >> (k % 8)).astype(np.uint8)
        assert not crc_ok(flips).any()
        # A flip in the 6 pad bits is not part of the message.
        pad = frame.copy()
        pad[31] ^= 0x01
        assert crc_ok(pad[None, :])[0]


def test_field_equals_string_slicing(frames):
    rng = np.random.default_rng(7)
    sample = frames.data[:300]
    strings = [_bits(f) for f in sample]
    for _ in range(200):
        width = int(rng.integers(1, 34))
        start = int(rng.integers(0, 256 - width))
        raw = [int(s[start : start + width], 2) for s in strings]
        assert field(sample, start, width).tolist() == raw
        signed = [r - (1 << width) if r >> (width - 1) else r for r in raw]
        assert field(sample, start, width, signed=True).tolist() == signed
    starts = np.array([18, 30, 42])
    many = field(sample, starts, 12, signed=True)
    assert many.shape == (300, 3)
    assert np.array_equal(many[:, 1], field(sample, 30, 12, signed=True))


def test_field_rejects_out_of_frame_reads(frames):
    with pytest.raises(ValueError, match="outside"):
        field(frames.data, 250, 8)
    with pytest.raises(ValueError, match="width"):
        field(frames.data, 0, 40)
