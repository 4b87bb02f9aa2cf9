"""Reader for CODE's differential code bias files (``P1C1yymm.DCB``, ``P1P2yymm.DCB``).

Format: a title line naming the bias (``... P1-C1 DCB SOLUTION ...``), a few header lines, a
``***`` ruler, then one line per satellite (``G01``) or receiver (a 4-character or longer
station name in columns 7-26): the value and its RMS in nanoseconds, ``F12.3`` ending in
columns 35 and 47. The rows of the report are the lines after the ruler: satellite lines are
kept in :attr:`CodeBiases.satellites`, receiver lines in :attr:`CodeBiases.receivers`, blank
lines are skipped, and an unreadable line is rejected (``bad_record``) or, repeated,
``duplicate``.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from overbound.io._rinex import load_bytes
from overbound.io.open import Source, source_name
from overbound.io.schema import InputError, ReadReport

__all__ = ["CodeBiases", "read_code_dcb"]


@dataclass(frozen=True, slots=True)
class CodeBiases:
    """Differential code biases, ns: ``kind`` as in the title (``P1-C1``), per satellite and receiver."""

    kind: str
    satellites: dict[str, float] = field(default_factory=dict)
    receivers: dict[str, float] = field(default_factory=dict)


def read_code_dcb(source: Source) -> tuple[CodeBiases, ReadReport]:
    """Read one CODE DCB file.

    Raises
    ------
    InputError
        No bias kind in the title line, or no ``***`` ruler line.
    """
    name = source_name(source)
    lines = load_bytes(source).decode("ascii", "replace").splitlines()
    title = lines[0] if lines else ""
    kind = next((w for w in title.split() if w.count("-") == 1 and w[:1] in "PC" and len(w) == 5), "")
    if not kind:
        raise InputError(name, "not a CODE DCB file: no 'P1-C1'-like bias name in the title line", line=1)
    ruler = next((i for i, line in enumerate(lines) if line.startswith("***")), None)
    if ruler is None:
        raise InputError(name, "not a CODE DCB file: no '***' ruler line before the values")
    sats: dict[str, float] = {}
    rcvs: dict[str, float] = {}
    rejected: Counter = Counter()
    first_bad, n_read = "", 0
    for i, line in enumerate(lines[ruler + 1 :], start=ruler + 2):
        if not line.strip():
            continue
        n_read += 1
        ident, station = line[:3].strip(), line[6:26].strip()
        try:
            value = float(line[23:35])  # F12.3 ending in column 35
        except ValueError:
            reason = "bad_record"
        else:
            target, key = (sats, ident) if ident and not station else (rcvs, station)
            reason = "duplicate" if key in target or not key else ""
            if not reason:
                target[key] = value
                continue
            reason = reason if key else "bad_record"
        rejected[reason] += 1
        first_bad = first_bad or f"{name}:{i}: {reason}"
    report = ReadReport(
        source=name,
        format="code-dcb",
        rows_read=n_read,
        rows_kept=len(sats) + len(rcvs),
        rejected=dict(rejected),
        first_bad=first_bad,
        notes=(f"{kind} biases: {len(sats)} satellites, {len(rcvs)} receivers (ns)",),
    )
    return CodeBiases(kind, sats, rcvs), report
