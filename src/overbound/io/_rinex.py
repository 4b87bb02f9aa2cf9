"""Fixed-column text machinery shared by the RINEX observation, RINEX navigation and SP3 readers.

These formats are Fortran fixed-width records. Rather than split every line in Python, a file is
held as one ``uint8`` array; line starts come from ``np.flatnonzero(buf == b"\\n")`` and a field
of width ``w`` at column ``c`` of many lines is one fancy-index of a sliding-window view (a
``(n, w)`` byte matrix), with the bytes past each line's end blanked. Numbers are decoded from
that matrix with integer arithmetic (:func:`parse_fixed`, Fortran ``Fw.d``) or, for the few
fields in exponent form, by numpy's string-to-float cast after the Fortran ``D`` exponent is
turned into ``E`` (:func:`parse_float`).

Input bytes come through :func:`load_bytes`: plain, gzip, and anything the ``hatanaka`` package
undoes (Hatanaka compact RINEX, Unix ``.Z``, bzip2, zip). Times read from records are checked
against the plausible span of GNSS epochs by :func:`overbound.io.gpstime.plausible_us`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from overbound.io.gpstime import leap_seconds
from overbound.io.open import Source, open_binary, source_name
from overbound.io.schema import InputError

__all__ = [
    "BLANK",
    "GPS_EPOCH_US",
    "US",
    "Lines",
    "civil_to_us",
    "load_bytes",
    "parse_digits",
    "parse_fixed",
    "parse_float",
    "rinex_version",
    "to_gpst",
]

US = 1_000_000
#: 1980-01-06 00:00:00 in microseconds since 1970-01-01 (GPS time's origin on the table's axis).
GPS_EPOCH_US = 315_964_800 * US
BLANK = ord(" ")
_MINUS, _POINT = ord("-"), ord(".")
_PAD = 512  # blank bytes after the text, so that every field window stays inside the buffer
_CHUNK = 1 << 15  # rows decoded at once: the temporaries stay in cache (and off fresh pages)
_OTHER_COMPRESSION = (b"\x1f\x9d", b"BZh", b"PK\x03\x04")  # .Z, bzip2, zip: left to `hatanaka`
_BDT_US = 14 * US  # BDT = GPST - 14 s (BeiDou ICD 3.3)
_TAI_US = 19 * US  # GPST = TAI - 19 s


def load_bytes(source: Source) -> bytes:
    """The decompressed text of ``source``: plain, gzip, Hatanaka (CRINEX), ``.Z``, bzip2 or zip.

    Raises
    ------
    InputError
        The file is missing, a compressed stream is truncated or corrupt, or a Hatanaka file
        cannot be expanded or expands only with a warning of ``crx2rnx`` (see :func:`_expand`).
    """
    name = source_name(source)
    stream = open_binary(source)
    try:
        raw = stream.read()  # a corrupt gzip stream raises InputError naming the file
    finally:
        if isinstance(source, str | Path):
            stream.close()
    if raw.startswith(_OTHER_COMPRESSION) or b"COMPACT RINEX FORMAT" in raw[:80]:
        raw = _expand(raw, name)
    return raw


def _expand(raw: bytes, name: str) -> bytes:
    """The text of a Hatanaka (CRINEX), ``.Z``, bzip2 or zip stream, or :class:`InputError`.

    ``crx2rnx`` reports the corruption it can detect (a duplicated, deleted or damaged line
    breaks the differential chain) as a *warning* and goes on: it skips records "until an
    initialized epoch is found", often to the end of the file, and the text it returns looks
    complete. Such a warning is treated as a corrupt stream and refused, not trusted up to the
    point of damage, because (1) the compact format is differential, so a damaged line can
    corrupt the values of every satellite it carries from there on without being detected, and
    what precedes the detection point is not known to be sound either (the detection comes lines
    after the damage); (2) the decompressor does not say how many records it dropped, so they
    could not be counted as rejected; (3) its line numbers are those of the compressed file,
    not of the text the reader reports lines of.
    """
    try:
        import hatanaka
    except ImportError:  # pragma: no cover - a dependency of the package
        raise InputError(
            name, "Hatanaka / .Z input needs the 'hatanaka' package (pip install hatanaka)"
        ) from None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            out = hatanaka.decompress(raw)
        except Exception as exc:  # hatanaka raises its own exception types and ValueError
            text = str(exc).strip().splitlines()
            raise InputError(name, f"cannot expand compressed RINEX: {text[-1] if text else exc!r}") from None
    corrupt = [w for w in caught if issubclass(w.category, UserWarning)]  # what `hatanaka` warns with
    for w in caught:
        if not issubclass(w.category, UserWarning):  # e.g. a dependency's DeprecationWarning
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if corrupt:
        text = " ".join(" ".join(str(w.message).split()) for w in corrupt)
        raise InputError(name, f"corrupt Hatanaka (CRINEX) stream: {text}")
    return out


@dataclass(frozen=True, slots=True)
class Lines:
    """Every line of a text buffer: start offset and length (line end, CR and trailing blanks removed)."""

    buf: np.ndarray  # uint8, the text followed by _PAD blanks
    start: np.ndarray  # int64
    length: np.ndarray  # int64

    @staticmethod
    def of(raw: bytes) -> Lines:
        text = np.frombuffer(raw, dtype=np.uint8)
        nl = np.flatnonzero(text == ord("\n"))
        ends = nl if len(text) and text[-1] == ord("\n") else np.append(nl, len(text))
        start = np.concatenate([[0], nl[: len(ends) - 1] + 1]).astype(np.int64)
        ends = ends.astype(np.int64)
        buf = np.concatenate([text, np.full(_PAD, BLANK, np.uint8)])
        todo = np.arange(len(ends))
        while todo.size:  # CR and trailing blanks: RINEX writers differ, the columns do not
            e = ends[todo]
            last = buf[np.maximum(e - 1, 0)]
            trail = (e > start[todo]) & ((last == ord("\r")) | (last == BLANK) | (last == ord("\t")))
            todo = todo[trail]
            ends[todo] -= 1
        return Lines(buf, start, ends - start)

    def __len__(self) -> int:
        return len(self.start)

    def text(self, i: int) -> str:
        """Line ``i`` (0-based) as text."""
        s = int(self.start[i])
        return bytes(self.buf[s : s + int(self.length[i])]).decode("ascii", "replace")

    def chars(self, rows: np.ndarray, col: int | np.ndarray, width: int) -> np.ndarray:
        """``(len(rows), width)`` bytes of columns ``col .. col+width-1``, blank past each line's end."""
        if width > _PAD:
            raise ValueError(f"field width {width} > {_PAD}")
        rows = np.asarray(rows, dtype=np.int64)
        col = np.asarray(col, dtype=np.int64)
        view = np.lib.stride_tricks.sliding_window_view(self.buf, width)
        out = view[np.minimum(self.start[rows] + col, len(self.buf) - width)]
        if (self.length[rows] < col + width).any():
            np.putmask(out, np.arange(width) >= (self.length[rows] - col)[:, None], BLANK)
        return out

    def col(self, rows: np.ndarray, col: int) -> np.ndarray:
        """The byte at column ``col`` of each row (blank past the line's end)."""
        rows = np.asarray(rows, dtype=np.int64)
        return np.where(self.length[rows] > col, self.buf[self.start[rows] + col], BLANK).astype(np.uint8)


def parse_digits(mat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Right-aligned integers (Fortran ``Iw``): values, well-formed, blank.

    A blank field is well-formed and reads as 0; a field with anything but blanks, one leading
    minus sign and digits, or with a blank inside the number, is not well-formed.
    """
    return _parse_decimal(mat, mat.shape[1], None)


def parse_fixed(
    mat: np.ndarray, decimals: int, width: int | None = None, scale: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fortran ``Fw.d`` fields (decimal point at column ``w - d - 1``): values, well-formed, blank.

    The digits are read as one integer and divided by a power of ten, so the result is the double
    nearest to the decimal text times ``10**scale`` (e.g. ``scale=3`` for km to m), as
    ``float(Decimal(text) * 10**scale)`` would give. Blank fields are NaN and count as
    well-formed; a field whose layout differs (point elsewhere, exponent, a letter, a blank
    inside the number) is NaN and not well-formed, for the caller to retry with
    :func:`parse_float` or reject. ``width`` (default: all columns) reads only the first
    ``width`` columns of ``mat``, which saves a copy when the matrix holds more (e.g. the
    LLI and SSI columns after an observation).
    """
    w = mat.shape[1] if width is None else width
    magnitude, ok, blank = _parse_decimal(mat, w, w - decimals - 1)
    shift = decimals - scale
    value = magnitude / 10.0**shift if shift >= 0 else magnitude * 10.0**-shift
    return np.where(ok & ~blank, value, np.nan), ok, blank


def _parse_decimal(mat: np.ndarray, w: int, point: int | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed integer of the digits in the first ``w`` columns (the decimal point at ``point``
    skipped), well-formed, blank.

    The character classes are boolean bytes; the checks combine them eight bytes at a time as
    ``uint64`` words (bitwise logic on 0/1 bytes; "the previous column" is a shift by one byte),
    since numpy is slow on 2-D slices with short rows and on boolean ``where``. Large inputs go in
    chunks of rows that stay in the processor cache.
    """
    n = len(mat)
    if n > _CHUNK:
        parts = [_parse_decimal(mat[s : s + _CHUNK], w, point) for s in range(0, n, _CHUNK)]
        return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))  # type: ignore[return-value]
    width = -(-mat.shape[1] // 8) * 8
    if width == mat.shape[1] and mat.flags.c_contiguous:
        flat = mat.ravel()
    else:
        m = np.full((n, width), BLANK, np.uint8)
        m[:, : mat.shape[1]] = mat
        flat = m.ravel()
    col = np.arange(width)
    word = lambda b: b.view(np.uint64)  # noqa: E731
    ones = np.uint64(0x0101010101010101)
    inside = word(np.tile(col < w, n))
    d = flat - np.uint8(ord("0"))  # wraps around below '0', so one comparison finds the digits
    isdig = d < 10
    nonblank = word(flat != BLANK) & inside
    minus = word(flat == _MINUS) & inside
    bad = (word(isdig) | (nonblank ^ ones) | minus) ^ ones  # neither digit, blank nor sign
    carry = np.zeros_like(nonblank)  # the last byte of the previous word
    carry[1:] = nonblank[:-1] >> np.uint64(56)
    after = (nonblank << np.uint64(8)) | carry
    after &= word(np.tile(col > 0, n))  # the previous column, in the same row, is not blank
    bad |= after & ((nonblank ^ ones) | minus)  # a blank or a sign inside the number
    if point is not None:
        at_point = word(np.tile(col == point, n))
        bad = (bad & (at_point ^ ones)) | (word(flat != _POINT) & at_point)
    bad &= inside
    blank = ~_row_any(nonblank.view(np.bool_).reshape(n, width))
    ok = blank | ~_row_any(bad.view(np.bool_).reshape(n, width))
    digits = (d * isdig).reshape(n, width)
    value = np.zeros(n, np.int64)
    for k in range(w):
        if k != point:
            value *= 10
            value += digits[:, k]
    return np.where(_row_any(minus.view(np.bool_).reshape(n, width)), -value, value), ok, blank


def _row_any(b: np.ndarray) -> np.ndarray:
    """Row-wise any of a C-contiguous boolean matrix whose width is a multiple of 8."""
    words = np.ascontiguousarray(b).view(np.uint64)
    out = words[:, 0] != 0
    for k in range(1, words.shape[1]):
        out |= words[:, k] != 0
    return out


def parse_float(mat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Any Fortran real (``F``, ``E``, ``D`` exponent, lower case too): values, well-formed, blank.

    The ``D`` (or ``d``) exponent letter of RINEX 2 navigation files is replaced by ``E`` in the
    whole matrix at once, blank fields become ``nan``, and numpy casts the byte strings to
    float64 (correctly rounded, like ``float()``); fields that still do not read are NaN and not
    well-formed.
    """
    mat = mat.copy()
    mat[(mat == ord("D")) | (mat == ord("d"))] = ord("E")
    blank = (mat == BLANK).all(axis=1)
    width = mat.shape[1]
    nan_text = np.frombuffer(b"nan".ljust(width), np.uint8)
    mat[blank] = nan_text
    strings = np.ascontiguousarray(mat).view(f"S{width}").ravel()
    try:
        return strings.astype(np.float64), np.ones(len(mat), bool), blank
    except ValueError:
        pass
    values = np.full(len(mat), np.nan)
    ok = np.ones(len(mat), bool)
    for i, s in enumerate(strings.tolist()):  # only when some field is bad: find which
        try:
            values[i] = float(s)
        except ValueError:
            ok[i] = False
    return values, ok, blank


def civil_to_us(
    year: np.ndarray, month: np.ndarray, day: np.ndarray, hour: np.ndarray, minute: np.ndarray, us: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Microseconds since 1970-01-01 of calendar fields (same time scale), and which are valid dates."""
    year = np.asarray(year, np.int64)
    month = np.asarray(month, np.int64)
    day = np.asarray(day, np.int64)
    hour = np.asarray(hour, np.int64)
    minute = np.asarray(minute, np.int64)
    us = np.asarray(us, np.int64)
    first = ((year - 1970) * 12 + np.clip(month - 1, 0, 11)).astype("datetime64[M]")
    days_in_month = ((first + 1).astype("datetime64[D]") - first.astype("datetime64[D]")).astype(np.int64)
    ok = (month >= 1) & (month <= 12) & (day >= 1) & (day <= days_in_month) & (hour >= 0) & (hour <= 23)
    ok &= (minute >= 0) & (minute <= 59) & (us >= 0) & (us <= 61 * US) & (year >= 1980) & (year < 2200)
    days = first.astype("datetime64[D]").astype(np.int64) + day - 1
    return ((days * 86_400 + hour * 3600 + minute * 60) * US + us).astype(np.int64), ok


def to_gpst(t_us: np.ndarray, time_system: str, name: str) -> np.ndarray:
    """Times of a RINEX / SP3 time system (``GPS``, ``GAL``, ``QZS``, ``IRN``, ``GLO``, ``UTC``, ``BDT``,
    ``TAI``) as GPS time, microseconds.

    GST, QZSST and IRNSST are aligned with GPST (their offsets are below 50 ns); GLONASS time is
    UTC(SU) + 3 h and RINEX writes it as UTC, so both get GPS-UTC added
    (:func:`overbound.io.gpstime.leap_seconds`, looked up at the UTC time); BDT = GPST - 14 s.
    """
    ts = time_system.strip().upper() or "GPS"
    if ts in ("GPS", "GAL", "QZS", "IRN", "GST"):
        return t_us
    if ts in ("GLO", "UTC"):
        return t_us + leap_seconds(t_us) * US
    if ts in ("BDT", "BDS"):
        return t_us + _BDT_US
    if ts == "TAI":
        return t_us - _TAI_US
    raise InputError(name, f"unknown time system {time_system!r} (GPS, GAL, QZS, IRN, GLO, UTC, BDT, TAI)")


def rinex_version(lines: Lines, name: str, expected: str) -> tuple[float, str]:
    """Version and first line of a RINEX file, checked (``expected``: "observation", "navigation"...).

    Raises
    ------
    InputError
        Empty file, no ``RINEX VERSION / TYPE`` first line, or an unreadable version.
    """
    if len(lines) == 0 or lines.length[0] == 0:
        raise InputError(name, f"empty file, expected a RINEX {expected} file")
    first = lines.text(0)
    if first[60:].strip() != "RINEX VERSION / TYPE":
        raise InputError(
            name, f"not a RINEX file: first line {first[:60].rstrip()!r} has no 'RINEX VERSION / TYPE'"
        )
    try:
        return float(first[:9]), first
    except ValueError:
        raise InputError(name, f"unreadable RINEX version {first[:9]!r}", line=1) from None
