"""Bit-field extraction from many SBAS messages at once.

An L1 SBAS message is 250 bits sent MSB first (DO-229D A.4.3): bit 0 is the first bit of the
8-bit preamble, bits 8-13 the message type, bits 14-225 the 212 data bits and bits 226-249 the
24-bit CRC. Here a message is held as 32 bytes (256 bits, the last 6 bits padding), bit ``i``
being bit ``7 - i % 8`` of byte ``i // 8``: the layout of the EMS hex string and of RTKLIB's
``sbsmsg_t.msg``. Bit positions in this package are 0-based as in DO-229's field tables.

:func:`field` reads one field, or the same-width field at many offsets (the 13 fast
corrections of a message, the 51 UDREIs...), for all messages in one numpy expression: the
bytes spanning the field are gathered into a ``uint64`` and shifted, so the cost does not
depend on the field width.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FRAME_BYTES", "MESSAGE_BITS", "bit_array", "field", "message_type", "preamble"]

#: Bits of one L1 SBAS message, CRC included (DO-229D A.4.3).
MESSAGE_BITS = 250
#: Bytes that hold one message (250 bits + 6 pad bits).
FRAME_BYTES = 32


def field(frames: np.ndarray, start: int | np.ndarray, width: int, *, signed: bool = False) -> np.ndarray:
    """Unsigned (or two's-complement) field of ``width`` bits at bit ``start`` of every frame.

    Parameters
    ----------
    frames : (n, 32) uint8 messages.
    start : first bit of the field (0 = first preamble bit); an array of starts gives one
        column per start.
    width : 1 to 33 bits.
    signed : read the field as two's complement.

    Returns
    -------
    int64 array of shape (n,) for a scalar ``start``, (n, k) for k starts.

    Examples
    --------
    >>> f = np.zeros((1, 32), np.uint8); f[0, :2] = (0x9A, 0x49)
    >>> int(field(f, 0, 8)[0]), int(field(f, 8, 6)[0]), int(field(f, 12, 4, signed=True)[0])
    (154, 18, -7)
    """
    if not 1 <= width <= 33:
        raise ValueError(f"field width {width} outside 1..33 bits")
    frames = np.asarray(frames, dtype=np.uint8)
    starts = np.asarray(start, dtype=np.int64)
    last = frames.shape[1] - 1
    if starts.size and (starts.min() < 0 or starts.max() + width > 8 * frames.shape[1]):
        raise ValueError(
            f"field [{starts.min()}, {starts.max() + width}) outside the {frames.shape[1]}-byte frame"
        )
    first = starts // 8
    nbytes = int(((starts % 8) + width + 7).max() // 8) if starts.size else 1
    # Bytes past the end of the frame would only be shifted out below: clip instead of padding.
    acc = frames[:, first].astype(np.int64)
    for j in range(1, nbytes):
        acc = (acc << 8) | frames[:, np.minimum(first + j, last)]
    out = (acc >> (8 * nbytes - (starts % 8) - width)) & ((1 << width) - 1)
    if signed:
        out = np.where(out >= 1 << (width - 1), out - (1 << width), out)
    return out


def bit_array(frames: np.ndarray, start: int, stop: int) -> np.ndarray:
    """Bits ``start`` to ``stop - 1`` of every frame as an (n, stop - start) bool array (mask fields).

    >>> f = np.zeros((1, 32), np.uint8); f[0, 1] = 0b00000101
    >>> np.flatnonzero(bit_array(f, 8, 16)[0]).tolist()
    [5, 7]
    """
    frames = np.asarray(frames, dtype=np.uint8).reshape(-1, FRAME_BYTES)
    return np.unpackbits(frames, axis=1)[:, start:stop].astype(bool)


def preamble(frames: np.ndarray) -> np.ndarray:
    """The 8-bit preamble (bits 0-7) of every frame: 0x53, 0x9A or 0xC6 in turn (DO-229D A.4.3)."""
    return np.asarray(frames, dtype=np.uint8)[:, 0].astype(np.int64)


def message_type(frames: np.ndarray) -> np.ndarray:
    """The 6-bit message type identifier (bits 8-13) of every frame."""
    return field(frames, 8, 6)
