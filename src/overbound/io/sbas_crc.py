"""CRC-24Q parity of SBAS messages, table driven and vectorised over messages.

DO-229D A.4.3.3: the 24 parity bits (message bits 226-249) protect the 226 bits before them
(preamble, type and data) with the generator

    g(X) = X^24 + X^23 + X^18 + X^17 + X^14 + X^11 + X^10 + X^7 + X^6 + X^5 + X^4 + X^3 + X + 1

(0x1864CFB), initial value 0 and no final XOR: the CRC-24Q of Qualcomm, also used by RTCM 3.
226 is not a multiple of 8, so the data bits are right-aligned behind 6 leading zero bits into
29 bytes; with a zero initial register, leading zeros do not change the remainder. The byte
table is built here from the polynomial; :func:`crc24q` then runs one table look-up per byte
column for all messages at once.
"""

from __future__ import annotations

import numpy as np

from overbound.io.sbas_bits import field

__all__ = ["POLY", "crc24q", "crc_ok", "parity", "parity_of_data"]

#: Generator polynomial of CRC-24Q, with its X^24 term (DO-229D A.4.3.3).
POLY = 0x1864CFB
_DATA_BITS = 226


def _table() -> np.ndarray:
    t = np.arange(256, dtype=np.uint32) << np.uint32(16)
    for _ in range(8):
        t = np.where(t & np.uint32(0x800000), (t << np.uint32(1)) ^ np.uint32(POLY), t << np.uint32(1))
    return t & np.uint32(0xFFFFFF)


_TABLE = _table()


def crc24q(data: bytes | np.ndarray) -> np.ndarray:
    """CRC-24Q of byte strings: a (n, m) uint8 array gives n remainders, bytes give one.

    >>> hex(int(crc24q(b"123456789")))  # the published check value of CRC-24Q
    '0xcde703'
    """
    arr = np.frombuffer(data, dtype=np.uint8)[None, :] if isinstance(data, bytes) else np.asarray(data)
    arr = np.atleast_2d(arr.astype(np.uint8, copy=False))
    crc = np.zeros(arr.shape[0], dtype=np.uint32)
    for k in range(arr.shape[1]):
        crc = ((crc << np.uint32(8)) & np.uint32(0xFFFFFF)) ^ _TABLE[(crc >> np.uint32(16)) ^ arr[:, k]]
    return crc[0] if isinstance(data, bytes) else crc


def parity_of_data(frames: np.ndarray) -> np.ndarray:
    """CRC-24Q computed over message bits 0-225 of each (n, 32) frame, as uint32."""
    frames = np.asarray(frames, dtype=np.uint8)
    prev = np.pad(frames[:, :28], ((0, 0), (1, 0)))  # byte k-1 (zero before byte 0)
    # Shift the 226 data bits right by 6: aligned byte k = low 6 bits of byte k-1, top 2 of byte k.
    aligned = ((prev & np.uint8(0x3F)) << np.uint8(2)) | (frames[:, :29] >> np.uint8(6))
    return crc24q(aligned)


def parity(frames: np.ndarray) -> np.ndarray:
    """The 24 parity bits as received (message bits 226-249), as uint32."""
    return field(frames, _DATA_BITS, 24).astype(np.uint32)


def crc_ok(frames: np.ndarray) -> np.ndarray:
    """True where the received parity equals the CRC-24Q of the message bits."""
    frames = np.asarray(frames, dtype=np.uint8)
    if frames.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    return parity_of_data(frames) == parity(frames)
