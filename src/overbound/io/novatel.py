"""Reader for NovAtel OEM logs: ``RAIMSTATUS`` (the receiver's protection levels) with ``BESTPOS`` (its
position), ASCII (``#BESTPOSA``...) or binary (sync 0xAA 0x44 0x12), mixed freely (OEM7 Commands and Logs
Reference Manual [1]_).

Records are framed (CRC-32 checked) and decoded by NovAtel's own library, :mod:`novatel_edie`
(``novatel_edie.oem.Framer`` then ``Decoder.decode``, whose message database gives the field names and
enumerations). A stretch of bytes that is no valid record (a failed CRC, garbage, a record cut by the
end of the file) is one rejected row, with its place: the line in an ASCII log, the byte offset in a
log with binary records; the scan resynchronises on the next record.
Line ends and other blank bytes between records are no rows. The time of a record is the GPS week and
milliseconds of its header (GPS time); records of the same time make one epoch:

* ``hpl``, ``vpl``: the RAIMSTATUS ``HPL`` and ``VPL`` (m): the protection levels of the receiver's
  RAIM (NovAtel's NRAIM, set up by the ``RAIMMODE`` command), which need not be the DO-229 SBAS levels
  that the ICAO service limits were written for; the notes say so. A level whose status (Table "Protection
  Level Status") is ``NOT_AVAILABLE`` is no protection level (the manual's own example logs 0.000
  beside it): NaN, as the Do-Not-Use levels of SBF and SBP, so that epoch is unavailable. A level whose
  status is ``ALERT`` (above the alert limit of the ``RAIMMODE`` command) is a computed level and is
  kept, not flagged: dropping it would hide exactly the epochs that exceed a limit, and the analysis
  compares every level with each service's own alert limits, not the one the receiver was set to.
* the position: BESTPOS ``lat``, ``lon`` (deg) and ``hgt``, the height above mean sea level, plus
  ``undulation`` (the geoid above the ellipsoid), which gives the ellipsoidal height ``hgt +
  undulation`` ([1]_, BESTPOS: "hgt: height above mean sea level", "undulation: the relationship between
  the geoid and the ellipsoid"; novatel-edie names the field ``orthometric_height``), in the datum of
  ``datum_id`` (epochs in a datum other than WGS84 are counted in the notes). A solution needs
  solution status ``SOL_COMPUTED`` and a position type other than ``NONE``; an epoch without BESTPOS or
  without RAIMSTATUS has no solution (errors and PLs NaN), counted in the notes.
* errors: against ``reference`` (a surveyed position or ``MEAN_POSITION``). Without one the log is read
  without truth, like a flight log: errors NaN, the report's ``truth`` false, and the protection levels
  are analysed alone (``overbound analyze`` gives the PL-only report).
* ``mode``: the BESTPOS position type (``WAAS`` for an SBAS solution, ``SINGLE``, ``NONE``...);
  ``nsv``: its satellites used in the solution (``#solnSVs``);
* ``alert``: RAIMSTATUS integrity status ``FAIL`` (RAIM detected a fault: the receiver's own integrity
  alert, as SBF's ``RAIMIntegrity`` 2).

Rows are the epochs (distinct times of BESTPOS and RAIMSTATUS records), the rejected stretches and the
repeated records (a second BESTPOS or RAIMSTATUS of the same time, ``duplicate_record``): kept + rejected
= read. The other logs are counted in the notes by name.

.. [1] NovAtel, OEM7 Commands and Logs Reference Manual (OM-20000169): "ASCII", "Binary" and "32-Bit
   CRC" (message formats), logs BESTPOS (ID 42) and RAIMSTATUS (ID 1286) with Tables "Integrity Status"
   and "Protection Level Status"; https://docs.novatel.com/OEM7/Content/Logs/RAIMSTATUS.htm.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import BinaryIO

import numpy as np
import polars as pl

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

__all__ = ["read_novatel"]

_POS, _RAIM = "BESTPOS", "RAIMSTATUS"
_WEEK_US = 604_800 * US
_BLANK = b" \t\r\n\x00"


def read_novatel(
    source: str | Path | BinaryIO,
    *,
    reference: Reference | MeanPosition | None = None,
    station: str | None = None,
    strict: bool = False,
) -> tuple[pl.DataFrame, ReadReport]:
    """Read a NovAtel OEM log with RAIMSTATUS and BESTPOS into the epoch table (see the module notes).

    Without ``reference`` the table has no errors (``truth`` false: protection levels alone). Raises
    :class:`InputError` naming the file without any RAIMSTATUS record (its BESTPOS and their WAAS
    solutions counted in the message), or (``strict``) at the first corrupt stretch or repeated record,
    with its byte offset.
    """
    name = source_name(source)
    data = read_bytes(source)
    log = RowLog(name, strict)
    place = _Place(data)
    recs, other = _records(data, log, place)
    if not recs[_RAIM]:
        pos = recs[_POS]
        waas = sum(1 for r in pos if r["type"] == "WAAS")
        raise InputError(
            name,
            f"no RAIMSTATUS log: no protection levels ({len(pos)} BESTPOS, {waas} of them WAAS solutions)",
        )
    if not recs[_POS]:
        raise InputError(
            name, f"no BESTPOS log: no position at the {len(recs[_RAIM])} RAIMSTATUS records (log both)"
        )
    pos, raim = (_unique(recs[k], k, log, place) for k in (_POS, _RAIM))
    ep = pos.join(raim, on="_t", how="full", coalesce=True, suffix="_r")
    ep = ep.with_columns(pl.min_horizontal("_line", "_line_r").alias("_line"))
    ep = ep.sort("_line", maintain_order=True)
    log.rows_read = ep.height + log.n_rejected
    table, used = _epochs(ep, reference, name)
    n_pos, n_raim = int(ep["type"].is_null().sum()), int(ep["hpl_status"].is_null().sum())
    notes = [
        f"{len(recs[_POS])} BESTPOS and {len(recs[_RAIM])} RAIMSTATUS records; other logs: "
        + (", ".join(f"{k} {v}" for k, v in sorted(other.items())) or "none"),
        "protection levels: RAIMSTATUS HPL and VPL, the receiver's RAIM levels (RAIMMODE), not necessarily "
        "DO-229 SBAS levels; NOT_AVAILABLE ones are none (NaN), ALERT ones kept; alert: integrity status "
        "FAIL; ellipsoidal height = BESTPOS height above mean sea level + undulation",
        reference_note(reference, used),
    ]
    if n_other := int((ep["datum"].fill_null("WGS84") != "WGS84").sum()):
        notes.append(f"{n_other} BESTPOS positions in a datum other than WGS84 (datum_id), used as they are")
    if n_pos or n_raim:
        notes.append(
            f"{n_pos} epochs without BESTPOS and {n_raim} without RAIMSTATUS at their time: no solution"
        )
    table = table.with_columns(pl.lit(file_station(station, name)).alias("station"))
    return finalize_epochs(table, log, format="novatel", notes=tuple(notes), errors=used is not None)


def _frames(data: bytes):
    """``(offset, frame bytes, known)`` of every piece novatel-edie's framer cuts ``data`` into; the
    bytes left in it at the end (a record cut by the end of the file) last, as not known."""
    import novatel_edie as ne

    framer = ne.oem.Framer()
    framer.report_unknown_bytes = True
    unknown = ne.HEADER_FORMAT.UNKNOWN
    pos = off = 0
    while True:
        written = framer.write(data[pos : pos + framer.available_space]) if pos < len(data) else 0
        pos += written
        framed = off
        for frame, meta in framer:
            yield off, frame, meta.format != unknown
            off += len(frame)
        if pos >= len(data):
            break
        if not written and off == framed:  # a full buffer the framer cannot cut: hand it on as unknown
            stuck = framer.flush()
            yield off, stuck, False
            off += len(stuck)
    rest = framer.flush()
    if rest:
        yield off, rest, False


class _Place:
    """Where a record starts, as a user finds it: the line of an ASCII log, else the byte offset."""

    def __init__(self, data: bytes) -> None:
        ascii_only = b"\xaa\x44\x12" not in data
        self.newlines = np.flatnonzero(np.frombuffer(data, np.uint8) == 10) if ascii_only else None

    def number(self, off: int) -> int:
        return off if self.newlines is None else int(np.searchsorted(self.newlines, off)) + 1

    def label(self, number: int) -> str:
        """``line N`` or ``byte N`` of a :meth:`number`."""
        return f"byte {number}" if self.newlines is None else f"line {number}"

    def text(self, off: int) -> str:
        return self.label(self.number(off))


def _records(data: bytes, log: RowLog, place: _Place) -> tuple[dict[str, list[dict]], Counter]:
    """The decoded BESTPOS and RAIMSTATUS records as field dicts; the other logs counted by name; each
    stretch of bytes that gives no record rejected once (its first offset)."""
    import novatel_edie as ne

    decoder = ne.oem.Decoder()
    out: dict[str, list[dict]] = {_POS: [], _RAIM: []}
    other: Counter = Counter()
    in_bad = False
    for off, frame, known in _frames(data):
        msg = None
        if known:
            try:
                msg = decoder.decode(frame)
            except ne.NovatelEdieException as exc:
                why = f"bad record: {type(exc).__name__} {exc} ({place.text(off)})"
        elif not frame.strip(_BLANK):
            continue  # line ends, padding: between records, not a record
        else:
            cut = off + len(frame) == len(data) and frame[:1] in (b"#", b"\xaa")
            why = (
                "truncated record: the file ends inside it"
                if cut
                else "bad record: no valid record (CRC, syntax)"
            )
            why += f" ({place.text(off)})"
        if msg is None:
            if not in_bad:
                log.reject(place.number(off), why)
            in_bad = True
            continue
        in_bad = False
        kind = getattr(msg, "name", type(msg).__name__)
        if kind in out and isinstance(msg, ne.oem.Message):
            out[kind].append(_fields(kind, place.number(off), msg))
        else:
            other[kind] += 1
    return out, other


def _fields(kind: str, off: int, m) -> dict:
    h = m.header
    ms = float(h.milliseconds)  # a non-finite time is no time: the common rules reject it
    t = int(GPS_EPOCH_US + h.week * _WEEK_US + round(ms * 1000.0)) if np.isfinite(ms) else -(2**62)
    if kind == _RAIM:
        return {"_line": off, "_t": t, "integrity": m.integrity_status.name, "hpl_status": m.hpl_status.name,
                "hpl": float(m.hpl), "vpl_status": m.vpl_status.name, "vpl": float(m.vpl)}  # fmt: skip
    # older BESTPOS definitions (other message CRCs of the database) call the height ``height``
    hgt = getattr(m, "orthometric_height", None)
    h_ell = float(m.height if hgt is None else hgt) + float(m.undulation)
    return {"_line": off, "_t": t, "status": m.solution_status.name, "type": m.position_type.name,
            "lat": float(m.latitude), "lon": float(m.longitude), "h": h_ell,
            "nsv": int(m.num_soln_svs), "datum": m.datum_id.name}  # fmt: skip


_SCHEMA = {
    _POS: {"_line": pl.Int64, "_t": pl.Int64, "status": pl.String, "type": pl.String, "lat": pl.Float64,
           "lon": pl.Float64, "h": pl.Float64, "nsv": pl.Int64, "datum": pl.String},
    _RAIM: {"_line": pl.Int64, "_t": pl.Int64, "integrity": pl.String, "hpl_status": pl.String,
            "hpl": pl.Float64, "vpl_status": pl.String, "vpl": pl.Float64},
}  # fmt: skip


def _unique(rows: list[dict], kind: str, log: RowLog, place: _Place) -> pl.DataFrame:
    """One record of ``kind`` per time stamp, the first; a repeated one rejected (``duplicate_record``)."""
    df = pl.DataFrame(rows, schema=_SCHEMA[kind])
    repeated = df.filter(df["_t"].is_duplicated() & ~df["_t"].is_first_distinct())
    for line in repeated["_line"]:  # a line or a byte offset (_Place.number)
        log.reject(int(line), f"duplicate record: a second {kind} of the same time ({place.label(line)})")
    return df.unique("_t", keep="first", maintain_order=True)


def _epochs(ep: pl.DataFrame, reference, name: str) -> tuple[pl.DataFrame, Reference | None]:
    positioned = ((ep["status"] == "SOL_COMPUTED") & (ep["type"] != "NONE")).fill_null(False).to_numpy()
    positioned &= ep["hpl_status"].is_not_null().to_numpy()  # no RAIMSTATUS: no solution, as SBF's DOP
    llh = [np.where(positioned, ep[c].fill_null(np.nan).to_numpy(), np.nan) for c in ("lat", "lon", "h")]
    e, n, u, used = errors_against(reference, llh, positioned, name)
    hpl = np.where(
        (ep["hpl_status"] != "NOT_AVAILABLE").fill_null(False), ep["hpl"].fill_null(np.nan), np.nan
    )
    vpl = np.where(
        (ep["vpl_status"] != "NOT_AVAILABLE").fill_null(False), ep["vpl"].fill_null(np.nan), np.nan
    )
    cols = solution_columns(positioned, e, n, u, hpl, vpl)
    alert = ep["integrity"] == "FAIL"
    table = pl.DataFrame(
        {
            "_line": ep["_line"],
            "time": ep["_t"].cast(pl.Datetime("us")),
            **cols,
            "nsv": ep["nsv"],
            "mode": ep["type"].fill_null("no BESTPOS"),
            "alert": alert.fill_null(False),
        }
    )
    return table, used
