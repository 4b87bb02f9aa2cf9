"""Reader for Swift Binary Protocol (SBP) logs: ``MSG_PROTECTION_LEVEL`` (0x0217; 0x0216, its deprecated
form) with ``MSG_POS_LLH`` (libsbp specification [1]_).

Frames (preamble 0x55, type, sender, length, payload, CRC-16) are found here and decoded and
CRC-checked by the :mod:`sbp` package (``SBP.unpack``, ``sbp.table.dispatch``). A stretch of bytes
that gives no valid frame is one rejected row (its first byte offset), however many 0x55 bytes it
holds, and the scan resynchronises on the next valid frame. One epoch per protection-level message:

* ``hpl``, ``vpl``: its HPL and VPL (cm in the message, m here);
* the time: GPS week ``wn`` and ``tow`` (ms) of the message (0x0216 has no week: that of the
  ``MSG_GPS_TIME`` with the same ``tow``, else the last one before it);
* the position: its own ``lat``, ``lon`` (deg) and ``height`` (ellipsoidal m); fix mode 0 (flags
  bits 15-17, "invalid") is no solution; errors against ``reference``;
* ``mode``: the fix mode by name (``SBAS`` for 6); ``nsv``: ``n_sats`` of the ``MSG_POS_LLH`` of the
  same ``tow``;
* ``alert``: target integrity risk level 0 ("safe state: protection level shall not be used for a
  safety-critical application", bits 0-2) or the safe-state flag of the HPL or VPL (bits 23, 24).

Rows are the protection-level messages plus the rejected stretches: kept + rejected = read. The other
messages are counted in the notes.

.. [1] Swift Navigation, libsbp, ``spec/yaml/swiftnav/sbp/navigation.yaml`` (MSG_PROTECTION_LEVEL,
   MSG_POS_LLH, MSG_GPS_TIME), v6.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import BinaryIO

import numpy as np
import polars as pl
from sbp.msg import SBP, UnpackError
from sbp.table import dispatch

from overbound.io._common import (
    RowLog,
    errors_against,
    file_station,
    finalize_epochs,
    reference_note,
    solution_columns,
)
from overbound.io._rinex import GPS_EPOCH_US, US
from overbound.io.geodesy import (
    MeanPosition,
    Reference,
)
from overbound.io.open import read_bytes, source_name
from overbound.io.schema import InputError, ReadReport

__all__ = ["read_sbp"]

_PREAMBLE = 0x55
_PL, _PL_DEP_A, _POS_LLH, _GPS_TIME = 0x0217, 0x0216, 0x020A, 0x0102
_MODES = {-1: "not given", 0: "invalid", 1: "SPP", 2: "DGNSS", 3: "float RTK", 4: "fixed RTK",
          5: "dead reckoning", 6: "SBAS"}  # fmt: skip
_WEEK_US = 604_800 * US


def _frame_end(data: bytes, i: int) -> int:
    """End of the frame a preamble at ``i`` announces (beyond ``len(data)`` when cut)."""
    return i + 8 + data[i + 5] if i + 6 <= len(data) else len(data) + 1


def read_sbp(
    source: str | Path | BinaryIO,
    *,
    reference: Reference | MeanPosition | None = None,
    station: str | None = None,
    strict: bool = False,
) -> tuple[pl.DataFrame, ReadReport]:
    """Read an SBP log with protection-level messages into the epoch table (see the module notes).

    Raises :class:`InputError` naming the file without any protection-level message (its SBAS-mode
    ``MSG_POS_LLH`` are counted in the message), or (``strict``) at the first corrupt stretch, with its
    byte offset.
    Without ``reference`` the errors are unknown (NaN, ``truth`` false: protection levels alone).
    """
    name = source_name(source)
    data = read_bytes(source)
    log = RowLog(name, strict)
    msgs, other = _frames(data, log)
    pls = msgs[_PL] + msgs[_PL_DEP_A]
    if not pls:
        llh = msgs[_POS_LLH]
        sbas = sum(1 for _, m in llh if m.flags & 7 == 6)
        seen = f"{len(llh)} MSG_POS_LLH, {sbas} in SBAS mode"
        raise InputError(name, f"no MSG_PROTECTION_LEVEL (0x0217 or 0x0216): no protection levels ({seen})")
    log.rows_read = len(pls) + log.n_rejected
    table, used = _epochs(msgs, reference, name)
    notes = [
        f"{len(msgs[_PL])} MSG_PROTECTION_LEVEL, {len(msgs[_PL_DEP_A])} MSG_PROTECTION_LEVEL_DEP_A, "
        f"{len(msgs[_POS_LLH])} MSG_POS_LLH; others: "
        + (", ".join(f"{k} {v}" for k, v in sorted(other.items())) or "none"),
        reference_note(reference, used),
    ]
    stn = file_station(station, name)
    return finalize_epochs(
        table.with_columns(pl.lit(stn).alias("station")),
        log,
        format="sbp",
        notes=tuple(notes),
        errors=used is not None,
    )


def _frames(data: bytes, log: RowLog) -> tuple[dict[int, list], Counter]:
    """The decoded frames of interest with their offsets; the others counted by name. A stretch that
    is no frame (bytes out of frame, failed CRC, a frame cut by the end) is one rejected row."""
    out: dict[int, list] = {_PL: [], _PL_DEP_A: [], _POS_LLH: [], _GPS_TIME: []}
    other: Counter = Counter()
    i, in_bad = 0, False
    while i < len(data):
        end = _frame_end(data, i) if data[i] == _PREAMBLE else -1
        try:
            if end < 0:
                raise UnpackError("no preamble")
            if end > len(data):
                raise UnpackError("truncated")
            frame = SBP.unpack(data[i:end])
            msg = dispatch(frame)
        except (UnpackError, AssertionError, ValueError, IndexError, KeyError) as exc:
            if not in_bad:
                cut = end > len(data)
                log.reject(i, f"truncated frame: the file ends inside it (byte {i})" if cut
                           else f"bad frame: {exc} (byte {i})")  # fmt: skip
                in_bad = True
            nxt = data.find(bytes([_PREAMBLE]), i + 1)  # resynchronise on the next preamble
            i = nxt if nxt >= 0 else len(data)
            continue
        in_bad = False
        if frame.msg_type in out:
            out[frame.msg_type].append((i, msg))
        else:
            other[type(msg).__name__] += 1
        i = end
    return out, other


def _epochs(msgs: dict, reference, name: str) -> tuple[pl.DataFrame, Reference | None]:
    weeks = {int(m.tow): int(m.wn) for _, m in msgs[_GPS_TIME]}
    week_tows = np.array(sorted(weeks), dtype=np.int64)
    rows = []
    for off, m in msgs[_PL] + msgs[_PL_DEP_A]:
        wn = getattr(m, "wn", None)
        if wn is None:  # the deprecated message: the week of MSG_GPS_TIME
            k = np.searchsorted(week_tows, int(m.tow), side="right") - 1
            wn = weeks.get(int(m.tow), weeks[int(week_tows[k])] if k >= 0 else None)
        dep = getattr(m, "wn", None) is None
        rows.append(
            (off, int(m.tow), wn, m.hpl / 100.0, m.vpl / 100.0, m.lat, m.lon, m.height, int(m.flags), dep)
        )
    ep = pl.DataFrame(
        rows, schema=["_line", "tow", "wn", "hpl", "vpl", "lat", "lon", "h", "flags", "dep"], orient="row"
    )
    ep = ep.sort("_line")
    llh = msgs[_POS_LLH]
    nsv = pl.DataFrame(
        {"tow": [int(m.tow) for _, m in llh], "nsv": [int(m.n_sats) for _, m in llh]},
        schema={"tow": pl.Int64, "nsv": pl.Int64},
    ).unique("tow", keep="first")
    ep = ep.join(nsv, on="tow", how="left", maintain_order="left")
    flags = ep["flags"].to_numpy().astype(np.int64)
    dep = ep["dep"].to_numpy()  # 0x0216's flags hold the TIR level only: no fix mode (-1: not given)
    fix = np.where(dep, -1, (flags >> 15) & 7)
    flags = np.where(dep, flags & 7, flags)
    positioned = (fix != 0) & np.isfinite(ep["lat"].to_numpy()) & np.isfinite(ep["lon"].to_numpy())
    llh = [np.where(positioned, ep[c].to_numpy(), np.nan) for c in ("lat", "lon", "h")]
    e, n, u, used = errors_against(reference, llh, positioned, name)
    wn = ep["wn"].to_numpy(allow_copy=True).astype(float)
    t_us = GPS_EPOCH_US + wn * _WEEK_US + ep["tow"].to_numpy() * 1000.0
    table = pl.DataFrame(
        {
            "_line": ep["_line"],
            "time": pl.Series(np.where(np.isfinite(t_us), t_us, 0).astype(np.int64)).cast(pl.Datetime("us")),
            **solution_columns(positioned, e, n, u, ep["hpl"].to_numpy(), ep["vpl"].to_numpy()),
            "nsv": ep["nsv"],
            "mode": pl.Series(fix).replace_strict(_MODES, default="other", return_dtype=pl.String),
            "alert": ((flags & 7) == 0) | (((flags >> 23) & 1) == 1) | (((flags >> 24) & 1) == 1),
        }
    )
    # an epoch without a GPS week has no time: the common rules reject it (time_out_of_range)
    return table.with_columns(
        pl.when(pl.Series(np.isfinite(t_us))).then(pl.col("time")).otherwise(None)
    ), used
