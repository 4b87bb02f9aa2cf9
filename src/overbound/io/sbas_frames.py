"""Received SBAS messages, whatever file they came from: the input of the message decoder.

Every SBAS message reader (EMS now; RINEX-B and u-blox RXM-SFRB later) returns
:class:`SbasFrames`: one row per received 250-bit message with its time tag, the broadcasting
GEO, the raw bits, and whether its CRC-24Q holds. Messages that fail the CRC stay in, flagged:
the decoder drops them, but a DO-229 receiver needs to see them (four consecutive bad or
missing messages end precision approach in DO-229D), so they must not vanish at read
time. Lines that cannot be read at all are in :attr:`SbasFrames.rejected`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import polars as pl

from overbound.io.sbas_bits import FRAME_BYTES, message_type, preamble

__all__ = ["PREAMBLES", "REJECTED_SCHEMA", "SbasFrames", "empty_frames"]

#: The three 8-bit preambles, sent in this order on consecutive messages (DO-229D A.4.3).
PREAMBLES = (0x53, 0x9A, 0xC6)
#: Columns of :attr:`SbasFrames.rejected`.
REJECTED_SCHEMA = {"file": pl.String, "line": pl.Int64, "reason": pl.String}


@dataclass(frozen=True, slots=True, eq=False)
class SbasFrames:
    """Raw SBAS messages as received, in time order.

    Attributes
    ----------
    time : int64, GPS time in microseconds since 1970-01-01 (the physical value of the epoch
        table's ``Datetime("us")`` column). For EMS input it is the file's time tag, the end of
        the one-second transmission slot (see :mod:`overbound.io.ems`).
    prn : int16, PRN of the GEO that broadcast the message (120-158).
    data : (n, 32) uint8, message bits 0-249, MSB first, the 6 last bits zero.
    crc_ok : bool, the CRC-24Q over bits 0-225 equals bits 226-249.
    file : int16, index into :attr:`files` of the file each message came from.
    line : int64, 1-based line (or record) number in that file.
    files : names of the input files.
    rejected : one row per unreadable line: ``file``, ``line``, ``reason``.
    """

    time: np.ndarray
    prn: np.ndarray
    data: np.ndarray
    crc_ok: np.ndarray
    file: np.ndarray
    line: np.ndarray
    files: tuple[str, ...] = ()
    rejected: pl.DataFrame = field(default_factory=lambda: pl.DataFrame(schema=REJECTED_SCHEMA))

    def __post_init__(self) -> None:
        n = len(self.time)
        if self.data.shape != (n, FRAME_BYTES) or self.data.dtype != np.uint8:
            raise ValueError(
                f"data must be ({n}, {FRAME_BYTES}) uint8, got {self.data.shape} {self.data.dtype}"
            )
        for name in ("prn", "crc_ok", "file", "line"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{name} has {len(getattr(self, name))} rows, time has {n}")

    def __len__(self) -> int:
        return len(self.time)

    @property
    def mt(self) -> np.ndarray:
        """Message type (bits 8-13) of every message, int64."""
        return message_type(self.data)

    @property
    def preamble(self) -> np.ndarray:
        """Preamble byte (bits 0-7) of every message, int64."""
        return preamble(self.data)

    def take(self, index: np.ndarray) -> SbasFrames:
        """The messages at ``index`` (integer positions or a boolean mask), same files and rejections."""
        return SbasFrames(
            time=self.time[index],
            prn=self.prn[index],
            data=self.data[index],
            crc_ok=self.crc_ok[index],
            file=self.file[index],
            line=self.line[index],
            files=self.files,
            rejected=self.rejected,
        )

    def to_frame(self) -> pl.DataFrame:
        """Polars view: ``time`` (GPST), ``prn``, ``mt``, ``crc_ok``, ``file``, ``line``, ``data`` (bytes)."""
        names = np.asarray(self.files, dtype=object)
        return pl.DataFrame(
            {
                "time": pl.Series(self.time, dtype=pl.Int64).cast(pl.Datetime("us")),
                "prn": pl.Series(self.prn, dtype=pl.Int16),
                "mt": pl.Series(self.mt, dtype=pl.UInt8),
                "crc_ok": pl.Series(self.crc_ok, dtype=pl.Boolean),
                "file": pl.Series(names[self.file] if len(self) else [], dtype=pl.String),
                "line": pl.Series(self.line, dtype=pl.Int64),
                "data": pl.Series([bytes(r) for r in self.data], dtype=pl.Binary),
            }
        )

    @staticmethod
    def concat(parts: list[SbasFrames]) -> SbasFrames:
        """Several reads as one, files renumbered, rows sorted by time (stable, then by file order)."""
        files: list[str] = []
        offs = []
        for p in parts:
            offs.append(len(files))
            files.extend(p.files)
        if not parts:
            return empty_frames()
        time = np.concatenate([p.time for p in parts])
        order = np.argsort(time, kind="stable")
        rej = [p.rejected for p in parts if p.rejected.height]
        return SbasFrames(
            time=time[order],
            prn=np.concatenate([p.prn for p in parts])[order],
            data=np.concatenate([p.data for p in parts])[order],
            crc_ok=np.concatenate([p.crc_ok for p in parts])[order],
            file=np.concatenate([p.file + o for p, o in zip(parts, offs, strict=True)]).astype(np.int16)[
                order
            ],
            line=np.concatenate([p.line for p in parts])[order],
            files=tuple(files),
            rejected=pl.concat(rej) if rej else pl.DataFrame(schema=REJECTED_SCHEMA),
        )


def empty_frames(files: tuple[str, ...] = ()) -> SbasFrames:
    """No messages."""
    return SbasFrames(
        time=np.zeros(0, np.int64),
        prn=np.zeros(0, np.int16),
        data=np.zeros((0, FRAME_BYTES), np.uint8),
        crc_ok=np.zeros(0, bool),
        file=np.zeros(0, np.int16),
        line=np.zeros(0, np.int64),
        files=files,
    )
