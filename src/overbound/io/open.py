"""One entry point for every input: sniff the format, dispatch to its reader.

Detection is by content first (magic bytes, then the first meaningful lines) and by
suffix only as a tie-breaker, so a renamed file still reads; ``format=`` overrides it.
Gzip-compressed inputs are decompressed transparently.
"""

from __future__ import annotations

import binascii
import dataclasses
import datetime as dt
import gzip
import io
import re
import zipfile
import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO, TextIO

import polars as pl

from overbound.io.dataset import is_dataset, read_dataset
from overbound.io.geodesy import MeanPosition, Reference
from overbound.io.schema import REQUIRED, InputError, ReadReport

if TYPE_CHECKING:
    from overbound.io.truth import Truth

__all__ = ["FORMATS", "Source", "open_binary", "open_text", "read", "read_bytes", "sniff", "source_name"]

Source = str | Path | TextIO | BinaryIO

#: Format names accepted by ``format=`` / ``--format``.
FORMATS: tuple[str, ...] = ("parquet", "csv", "rtklib-pos", "glab", "ubx", "g1000", "sbf", "nmea", "sbp",
                            "novatel")  # fmt: skip

_GZIP = b"\x1f\x8b"
_RTKLIB_DATA = re.compile(rb"^\s*\d{4}/\d{2}/\d{2}\s+\d{2}:\d{2}:\d{2}(\.\d+)?\s")
_RTKLIB_WEEK = re.compile(rb"^\s*\d{3,4}\s+\d+(\.\d+)?\s+-?\d")


def source_name(source: Source) -> str:
    """A printable name for a path or stream (``<stream>`` when it has none)."""
    if isinstance(source, str | Path):
        return str(source)
    return str(getattr(source, "name", "<stream>"))


def open_binary(source: Source) -> BinaryIO:
    """A binary stream over ``source``, gunzipped when it starts with the gzip magic."""
    if isinstance(source, str | Path):
        path = Path(source)
        if not path.exists():
            raise InputError(str(path), "no such file")
        if path.is_dir():
            raise InputError(str(path), "is a directory, expected a file")
        raw: BinaryIO = path.open("rb")
    elif isinstance(source, io.TextIOBase):
        raw = io.BytesIO(source.read().encode())
    else:
        raw = source  # type: ignore[assignment]
    head = raw.read(2)
    raw.seek(0)
    if head == _GZIP:
        stream = _CheckedGzip(source_name(source), raw)
        if isinstance(source, str | Path):
            stream.myfileobj = raw  # GzipFile.close() then closes the file it reads too
        return stream  # type: ignore[return-value]
    return raw


class _CheckedGzip(gzip.GzipFile):
    """A gzip stream whose corruption (bad header, CRC, truncation) is one :class:`InputError`
    naming the file, whichever way the reader reads it."""

    def __init__(self, name: str, raw: BinaryIO):
        super().__init__(fileobj=raw, mode="rb")
        self._source = name

    def _checked(method):
        def call(self, *args):
            try:
                return method(self, *args)
            except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
                why = str(exc) or type(exc).__name__
                raise InputError(self._source, f"truncated or corrupt gzip stream ({why})") from None

        return call

    read = _checked(gzip.GzipFile.read)
    read1 = _checked(gzip.GzipFile.read1)
    readline = _checked(gzip.GzipFile.readline)
    readinto = _checked(gzip.GzipFile.readinto)
    readinto1 = _checked(gzip.GzipFile.readinto1)
    peek = _checked(gzip.GzipFile.peek)
    seek = _checked(gzip.GzipFile.seek)


def open_text(source: Source) -> TextIO:
    """A text stream over ``source`` (gunzipped if needed); undecodable bytes become U+FFFD."""
    if isinstance(source, io.TextIOBase):
        return source  # type: ignore[return-value]
    return io.TextIOWrapper(open_binary(source), encoding="utf-8", errors="replace", newline=None)


_ZIP = b"PK\x03\x04"


def expand_archives(sources: Sequence[Source]) -> list[Source]:
    """``sources`` with every zip archive (a path whose content is one) replaced by its member files,
    in archive order, each an in-memory stream named ``archive.zip/member``: a zip of three flights
    is three inputs, not one file. Folders, ``__MACOSX/`` entries and hidden files are not members."""
    out: list[Source] = []
    for src in sources:
        if not isinstance(src, str | Path) or not Path(src).is_file():
            out.append(src)
            continue
        with Path(src).open("rb") as f:
            if f.read(4) != _ZIP:
                out.append(src)
                continue
        try:
            with zipfile.ZipFile(src) as archive:
                for info in archive.infolist():
                    base = info.filename.rsplit("/", 1)[-1]
                    # not data: folders, macOS resource forks (__MACOSX/, ._name) and other hidden files
                    if not info.is_dir() and not info.filename.startswith("__MACOSX/") and base[:1] != ".":
                        member = io.BytesIO(archive.read(info))
                        member.name = f"{src}/{info.filename}"  # type: ignore[attr-defined]
                        out.append(member)
        except (zipfile.BadZipFile, OSError) as exc:
            raise InputError(str(src), f"unreadable zip archive: {exc}") from None
    return out


def read_text(source: Source) -> str:
    """All of ``source`` as text (:func:`open_text`); a file opened here is closed, a stream is left open."""
    stream = open_text(source)
    try:
        return stream.read()
    finally:
        if isinstance(source, str | Path):
            stream.close()


def read_bytes(source: Source) -> bytes:
    """All bytes of ``source`` (gunzipped if needed); a file opened here is closed, a stream is left open."""
    stream = open_binary(source)
    try:
        return stream.read()
    finally:
        if isinstance(source, str | Path):
            stream.close()


def _head(source: Source, n: int = 8192) -> bytes:
    if isinstance(source, io.TextIOBase):
        pos = source.tell()
        text = source.read(n)
        source.seek(pos)
        return text.encode()
    stream = open_binary(source)
    try:
        return stream.read(n)
    finally:
        if isinstance(source, str | Path):
            stream.close()
        else:
            stream.seek(0)
            if hasattr(source, "seek"):
                source.seek(0)  # type: ignore[union-attr]


def sniff(source: Source) -> str:
    """The format of ``source``, one of :data:`FORMATS`.

    Raises
    ------
    InputError
        Nothing recognisable in the first 8 KiB.
    """
    head = _head(source)
    name = source_name(source)
    if head.startswith(b"PAR1"):
        return "parquet"
    if _looks_ubx(head):
        return "ubx"
    if head.startswith(b"#airframe_info"):
        return "g1000"
    if _looks_sbf(head):
        return "sbf"
    if _looks_sbp(head):
        return "sbp"
    if _looks_novatel(head):
        return "novatel"
    lines = [ln for ln in head.splitlines()[:200] if ln.strip()]
    if any(
        ln.startswith((b"SBASOUT", b"SBASIONO", b"SBASCORR", b"SBASVAR", b"SBASUNSEL")) for ln in lines
    ) or any(b"gLAB" in ln and ln.startswith(b"INFO") for ln in lines):
        return "glab"
    if any(ln.startswith(b"%") and (b"RTKLIB" in ln or b"GPST" in ln or b"UTC" in ln) for ln in lines) or any(
        _RTKLIB_DATA.match(ln) for ln in lines[:50]
    ):
        return "rtklib-pos"
    if _looks_nmea([ln.strip() for ln in lines]):
        return "nmea"
    first = lines[0] if lines else b""
    if (b"," in first or b";" in first or b"\t" in first) and re.search(rb"[A-Za-z_]", first):
        return "csv"
    if name.lower().endswith((".parquet", ".pq")):
        return "parquet"
    raise InputError(name, f"unknown format (not {', '.join(FORMATS)}); use --format to force one")


def _looks_ubx(head: bytes) -> bool:
    """UBX frames: sync 0xB5 0x62, class, id, little-endian length; at least two in a row."""
    i = head.find(b"\xb5\x62")
    hits = 0
    while 0 <= i and i + 6 <= len(head):
        length = int.from_bytes(head[i + 4 : i + 6], "little")
        nxt = i + 8 + length
        if nxt + 2 <= len(head) and head[nxt : nxt + 2] == b"\xb5\x62":
            hits += 1
            if hits >= 2 or i == 0:
                return True
        i = head.find(b"\xb5\x62", i + 2)
    return hits > 0


def _looks_sbf(head: bytes) -> bool:
    """Septentrio SBF: a block (sync ``$@``, a length that is a multiple of 4) that leads to the next sync."""
    i = head.find(b"$@")
    while 0 <= i and i + 8 <= len(head):
        length = int.from_bytes(head[i + 6 : i + 8], "little")
        if length >= 8 and length % 4 == 0 and head[i + length : i + length + 2] == b"$@":
            return True
        i = head.find(b"$@", i + 2)
    return False


def _looks_sbp(head: bytes) -> bool:
    """Swift SBP: three consecutive frames (preamble 0x55, type, sender, length, payload) whose CRC-16
    (CCITT, over type to payload, as :mod:`sbp` checks it) passes."""
    i = head.find(b"\x55")
    while 0 <= i:
        j, good = i, 0
        while good < 3 and j + 6 <= len(head) and head[j] == 0x55:
            end = j + 8 + head[j + 5]
            if end > len(head) or binascii.crc_hqx(head[j + 1 : end - 2], 0) != int.from_bytes(
                head[end - 2 : end], "little"
            ):
                break
            good, j = good + 1, end
        if good == 3:
            return True
        i = head.find(b"\x55", i + 1)
    return False


_NOVATEL_ASCII = re.compile(rb"^#[A-Z0-9_]+A,[^;\r\n]*;[^\r\n]*\*([0-9a-fA-F]{8})\s*$", re.M)


def _novatel_crc(data: bytes) -> int:
    """NovAtel's 32-bit CRC (reflected polynomial 0xEDB88320, no initial or final inversion: OEM7
    manual, "32-Bit CRC"), which is zlib's CRC-32 with both inversions undone."""
    return binascii.crc32(data, 0xFFFFFFFF) ^ 0xFFFFFFFF


def _looks_novatel(head: bytes) -> bool:
    """NovAtel OEM: a binary record (sync 0xAA 0x44 0x12, header length, message length at bytes 8-9)
    or an ASCII one (``#NAMEA,header;fields*crc``) whose CRC-32 passes (OEM7 manual, "Binary", "ASCII")."""
    i = head.find(b"\xaa\x44\x12")
    while 0 <= i and i + 10 <= len(head):
        end = i + head[i + 3] + int.from_bytes(head[i + 8 : i + 10], "little") + 4
        if end <= len(head) and _novatel_crc(head[i : end - 4]) == int.from_bytes(
            head[end - 4 : end], "little"
        ):
            return True
        i = head.find(b"\xaa\x44\x12", i + 1)
    for m in _NOVATEL_ASCII.finditer(head):
        body = head[m.start() + 1 : m.start(1) - 1]
        if _novatel_crc(body) == int(m.group(1), 16):
            return True
    return False


def _looks_nmea(lines: list[bytes]) -> bool:
    """NMEA 0183: at least two sentences (``$``, a 5-letter address, ``*`` and a checksum at the end)."""
    return sum(1 for ln in lines if ln[:1] == b"$" and b"*" in ln[-6:] and ln[1:6].isalpha()) >= 2


def _readers() -> dict[str, Callable[..., tuple[pl.DataFrame, ReadReport]]]:
    # Imported lazily: a reader's optional heavy dependency loads only when it is used.
    from overbound.io.g1000 import read_g1000
    from overbound.io.glab import read_glab
    from overbound.io.nmea import read_nmea
    from overbound.io.novatel import read_novatel
    from overbound.io.rtklib import read_rtklib_pos
    from overbound.io.sbf import read_sbf
    from overbound.io.sbp import read_sbp
    from overbound.io.table import read_csv, read_parquet
    from overbound.io.ubx import read_ubx

    return {
        "parquet": read_parquet,
        "csv": read_csv,
        "rtklib-pos": read_rtklib_pos,
        "glab": read_glab,
        "ubx": read_ubx,
        "g1000": read_g1000,
        "sbf": read_sbf,
        "nmea": read_nmea,
        "sbp": read_sbp,
        "novatel": read_novatel,
    }


def read(
    source: Source,
    *,
    format: str | None = None,
    reference: Reference | MeanPosition | Truth | None = None,
    station: str | None = None,
    mapping: Mapping[str, str] | None = None,
    time_range: tuple[dt.datetime | None, dt.datetime | None] | None = None,
    columns: Sequence[str] | None = None,
    strict: bool = False,
) -> tuple[pl.DataFrame, ReadReport]:
    """Read any supported input into the epoch table.

    Parameters
    ----------
    source : path or open stream (text or binary); ``.gz`` is handled by content; a campaign
        dataset directory (:mod:`overbound.io.dataset`) reads as its whole epoch table.
    format : one of :data:`FORMATS`; sniffed from the content when ``None``.
    reference : true antenna position, for formats that carry positions rather than errors; or a
        :class:`~overbound.io.truth.Truth` trajectory (a moving receiver), interpolated to each epoch
        (:func:`~overbound.io.truth.apply_truth`: epochs outside its span are rejected, those in its
        gaps invalidated).
    station : station name; by default the reader takes it from the content or the file name.
    mapping : for ``csv``/``parquet``: canonical column name -> column name in the file.
    time_range : keep epochs with ``start <= time < stop`` (GPS time); either end may be ``None``.
        The epochs outside are counted in the report (``rejected["outside_time_range"]``).
    columns : optional columns to keep besides the required ones (default: all the input has);
        a Parquet input does not even read the others.
    strict : raise on the first malformed row instead of counting it.

    Returns
    -------
    (table, report) : the epoch table (see :mod:`overbound.io.schema`) and a
        :class:`~overbound.io.schema.ReadReport` of rows read, kept and rejected.
    """
    if format is None and isinstance(source, str | Path) and is_dataset(source):
        table, report = read_dataset(source, columns=columns)
    else:
        table, report = _read_one(source, format, reference, station, strict, mapping, columns)
    if columns is not None and report.truth:  # without truth: all (the PL-only analysis reports them)
        keep = set(REQUIRED) | set(columns)
        table = table.select([c for c in table.columns if c in keep])
    if time_range is not None:
        inside = table.select(_in_window(time_range)).to_series().to_numpy()
        # counted like any row not kept; the invalidated ones among them no longer count as invalidated
        report = report.keep(inside, "outside_time_range")
        table = table.filter(pl.Series(inside))
    return table, dataclasses.replace(report, invalid_rows=None, invalid_reasons=None)


def _read_one(
    source, format, reference, station, strict, mapping, columns
) -> tuple[pl.DataFrame, ReadReport]:
    """One file or stream, by the reader of its (given or sniffed) format."""
    fmt = format or sniff(source)
    readers = _readers()
    if fmt not in readers:
        raise InputError(source_name(source), f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}")
    from overbound.io.truth import Truth, apply_truth

    truth = reference if isinstance(reference, Truth) else None
    # with a truth trajectory the reader forms errors against its first sample, then apply_truth
    # takes them against the trajectory
    kwargs: dict = {"reference": truth.anchor if truth else reference, "station": station, "strict": strict}
    if fmt in ("csv", "parquet"):
        kwargs["mapping"] = mapping
    if fmt == "parquet" and truth is None:  # the truth needs east and north, whatever is kept
        kwargs["columns"] = columns
    table, report = readers[fmt](source, **kwargs)
    return apply_truth(table, report, truth) if truth else (table, report)


def filter_time(
    table: pl.DataFrame, time_range: tuple[dt.datetime | None, dt.datetime | None]
) -> pl.DataFrame:
    """The epochs with ``start <= time < stop`` (either end ``None``: open)."""
    return table.filter(_in_window(time_range))


def _in_window(time_range: tuple[dt.datetime | None, dt.datetime | None]) -> pl.Expr:
    start, stop = time_range
    expr = pl.lit(True)
    if start is not None:
        expr = expr & (pl.col("time") >= start)
    if stop is not None:
        expr = expr & (pl.col("time") < stop)
    return expr
