"""Reader for Septentrio SBF logs: the receiver's protection levels (``DOP``) with its positions
(``PVTGeodetic``).

Blocks are found here (sync ``$@``, CRC, ID, length: SBF reference guide [1]_, "SBF outline") and
decoded and CRC-checked by :mod:`pysbf2` (``SBFReader.parse``), whose definitions give the field names
and scaling; a block that fails is counted with its byte offset and the scan resynchronises on the
next sync. One epoch per ``PVTGeodetic`` (4007) block, joined on its time stamp (``WNc``, ``TOW``:
GPS week and milliseconds of week, GPS time) to the ``DOP`` (4001) block of the same epoch:

* ``hpl``, ``vpl``: the DOP block's ``HPL``, ``VPL`` (m, the receiver's DO-229 protection levels); the
  Do-Not-Use value (-2e10), or no DOP block for the epoch, makes a no-solution epoch (``nan_pl``);
* the position: ``Latitude``, ``Longitude`` (radians), ``Height`` (ellipsoidal m); a solution needs
  ``Error`` 0, a PVT ``Type`` other than 0 ("no PVT") and no Do-Not-Use coordinate; the errors are
  against ``reference`` (a :class:`~overbound.io.geodesy.Reference` or ``MEAN_POSITION``);
* ``mode``: the PVT type by name (``SBAS`` for type 6, SBAS-aided, with ``ReferenceID`` the GEO),
  ``DO-229`` appended when ``Corr_DO229Active`` says the receiver ran in DO-229 mode;
* ``alert``: ``RAIMIntegrity`` 2 (the receiver's integrity test failed);
* ``nsv``: ``NrSV``.

Rows are the PVTGeodetic blocks plus the blocks rejected whole (bad CRC, undecodable, cut by the end
of the file), whatever their type: kept + rejected = read. Other blocks are counted in the notes.

.. [1] Septentrio, mosaic-X5 Reference Guide, "SBF Reference Guide" (SBF outline, blocks 4001 DOP
   and 4007 PVTGeodetic), 2023.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import BinaryIO

import numpy as np
import polars as pl
from pysbf2 import SBFReader
from pysbf2.exceptions import SBFMessageError, SBFParseError, SBFTypeError

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

__all__ = ["read_sbf"]

_SYNC = b"$@"
_PVT, _DOP = "PVTGeodetic", "DOP"
_DNU = -2e10  # Do-Not-Use of the float fields
#: PVT types (``Mode`` bits 0-3) by name.
_TYPES = {0: "no PVT", 1: "standalone", 2: "DGNSS", 3: "fixed", 4: "RTK", 5: "RTK float", 6: "SBAS",
          7: "moving-base RTK", 8: "moving-base RTK float", 10: "PPP"}  # fmt: skip
_WEEK_US = 604_800 * US


def read_sbf(
    source: str | Path | BinaryIO,
    *,
    reference: Reference | MeanPosition | None = None,
    station: str | None = None,
    strict: bool = False,
) -> tuple[pl.DataFrame, ReadReport]:
    """Read an SBF log into the epoch table (see the module notes).

    Raises :class:`InputError` without any PVTGeodetic block, or (``strict``) at the first corrupt block,
    naming the file and byte offset.
    Without ``reference`` the errors are unknown (NaN, ``truth`` false: protection levels alone).
    """
    name = source_name(source)
    data = read_bytes(source)
    log = RowLog(name, strict)
    blocks, other = _blocks(data, log)
    if not blocks[_PVT]:
        raise InputError(name, "no PVTGeodetic block (4007): no epoch to read")
    log.rows_read = len(blocks[_PVT]) + log.n_rejected
    table, used = _epochs(blocks, reference, name)
    notes = [
        f"{len(blocks[_PVT])} PVTGeodetic and {len(blocks[_DOP])} DOP blocks; other blocks: "
        + (", ".join(f"{k} {v}" for k, v in sorted(other.items())) or "none"),
        reference_note(reference, used),
        "protection levels: the DOP block's HPL and VPL (the receiver's DO-229 levels)",
    ]
    n_no_dop = int(table["_no_dop"].sum())
    if n_no_dop:
        notes.append(f"{n_no_dop} epochs without a DOP block: no protection levels (no solution)")
    stn = file_station(station, name)
    table = table.drop("_no_dop").with_columns(pl.lit(stn).alias("station"))
    return finalize_epochs(table, log, format="sbf", notes=tuple(notes), errors=used is not None)


def _blocks(data: bytes, log: RowLog) -> tuple[dict[str, list[tuple[int, object]]], Counter]:
    """The decoded PVTGeodetic and DOP blocks with their byte offsets; the other blocks counted."""
    out: dict[str, list[tuple[int, object]]] = {_PVT: [], _DOP: []}
    other: Counter = Counter()
    i = data.find(_SYNC)
    while 0 <= i:
        length = int.from_bytes(data[i + 6 : i + 8], "little") if i + 8 <= len(data) else 0
        if length < 8 or length % 4 or i + length > len(data):
            cut = length >= 8 and length % 4 == 0  # a plausible length that runs past the end
            reason = "truncated block: the file ends inside it" if cut else f"bad length: {length} bytes"
            log.reject(i, f"{reason} (byte {i})")
            i = data.find(_SYNC, i + 2)
            continue
        try:
            msg = SBFReader.parse(data[i : i + length])
        except (SBFMessageError, SBFParseError, SBFTypeError, ValueError, IndexError) as exc:
            log.reject(i, f"bad block: {exc} (byte {i})")
            i = data.find(_SYNC, i + 2)
            continue
        if msg.identity in out:
            out[msg.identity].append((i, msg))
        else:
            other[msg.identity] += 1
        i = data.find(_SYNC, i + length)
    return out, other


def _time_key(msg) -> int:
    """GPS microseconds since 1970 of a block's time stamp (-1: Do-Not-Use)."""
    if msg.WNc == 65535 or msg.TOW == 4294967295:
        return -1
    return int(GPS_EPOCH_US + msg.WNc * _WEEK_US + msg.TOW * 1000)


def _pvt_row(offset: int, m) -> dict:
    return {
        "_line": offset, "_t": _time_key(m), "type": int(m.Type), "error": int(m.Error),
        "lat": float(m.Latitude), "lon": float(m.Longitude), "h": float(m.Height), "nsv": int(m.NrSV),
        "raim": int(m.RAIMIntegrity), "do229": int(m.Corr_DO229Active),
    }  # fmt: skip


def _epochs(blocks: dict, reference, name: str) -> tuple[pl.DataFrame, Reference | None]:
    pvt = pl.DataFrame([_pvt_row(off, m) for off, m in blocks[_PVT]])
    dop = pl.DataFrame(
        [{"_t": _time_key(m), "hpl_raw": float(m.HPL), "vpl_raw": float(m.VPL)} for _, m in blocks[_DOP]],
        schema={"_t": pl.Int64, "hpl_raw": pl.Float64, "vpl_raw": pl.Float64},
    ).unique("_t", keep="first", maintain_order=True)
    ep = pvt.join(dop, on="_t", how="left", maintain_order="left")
    lat, lon, h = (ep[c].to_numpy() for c in ("lat", "lon", "h"))
    positioned = (
        (ep["error"].to_numpy() == 0)
        & (ep["type"].to_numpy() != 0)
        & (lat != _DNU)
        & (lon != _DNU)
        & (h != _DNU)
    )
    llh = [np.where(positioned, np.degrees(lat), np.nan), np.where(positioned, np.degrees(lon), np.nan),
           np.where(positioned, h, np.nan)]  # fmt: skip
    hpl = ep["hpl_raw"].fill_null(np.nan).to_numpy()
    vpl = ep["vpl_raw"].fill_null(np.nan).to_numpy()
    has_pl = positioned & (hpl != _DNU) & (vpl != _DNU) & np.isfinite(hpl) & np.isfinite(vpl)
    e, n, u, used = errors_against(reference, llh, has_pl, name)  # the mean of the epochs with a solution
    mode = [
        _TYPES.get(t, f"type {t}") + (" DO-229" if d else "")
        for t, d in zip(ep["type"], ep["do229"], strict=True)
    ]
    table = pl.DataFrame(
        {
            "_line": ep["_line"],
            "time": pl.Series(ep["_t"].to_numpy(), dtype=pl.Int64).cast(pl.Datetime("us")),
            **solution_columns(
                positioned, e, n, u, np.where(has_pl, hpl, np.nan), np.where(has_pl, vpl, np.nan)
            ),
            "nsv": ep["nsv"],
            "mode": mode,
            "alert": ep["raim"].to_numpy() == 2,
            "_no_dop": ep["hpl_raw"].is_null(),
        }
    )
    # a DNU time stamp is no time: the common rules reject it (time_out_of_range)
    table = table.with_columns(pl.when(ep["_t"] < 0).then(None).otherwise(pl.col("time")).alias("time"))
    return table, used
