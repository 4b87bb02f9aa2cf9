"""Seeded fuzzing of every overbound input reader (issue 13, "Nothing lost, nothing half-written").

Usage::

    python validation/fuzz_readers.py [--cases 10000] [--seed 0] [--cli-share 0.02]
        [--timeout 60] [--memory-mib 2048] [--threads 1] [--out validation/results/fuzz_readers.json]
    python validation/fuzz_readers.py --repro CASE [--seed 0] [--keep DIR]

Each case takes one real fixture of ``tests/data`` (or a small CSV / Parquet epoch table made with
:mod:`overbound.simulate`), applies one named mutation (truncation, byte flips, line edits, changed
digits, NaN/inf/huge/empty fields, changed epoch year or hour, bad encodings, CRLF, corrupt gzip,
corrupt Parquet pages or footer) and reads the result with one reader ("target"). Case ``i`` goes
to target ``TARGETS[i % len(TARGETS)]`` and is drawn from ``numpy.random.default_rng((seed, i))``, so
``--seed`` and ``--repro i`` name a case for good, and :func:`run_cases` (``target``, ``n``) replays
the first ``n`` cases of that target of a script run.

Outcomes (issue 13's rule): ``ok`` (returned and ``report.unaccounted == 0``), ``clean_error``
(:class:`overbound.io.schema.InputError` whose message names the file), ``unnamed_error`` (an
``InputError`` that does not), ``traceback`` (any other exception: type, message, last frame),
``unbalanced`` (returned, but ``rows_read - rows_kept - n_rejected != 0``), ``hang`` (over
``--timeout`` s), ``memory`` (over ``--memory-mib`` of resident memory), ``crash`` (the worker
process died without an answer).

The script runs the cases in one persistent ``spawn`` worker process (polars is not fork-safe)
fed over a pipe; the parent kills and restarts it on a time-out, on a resident set above the limit
(``/proc/<pid>/status`` VmRSS read every 0.2 s, and each case's own peak: ``VmHWM`` reset before
the case, else ``ru_maxrss``) or when it dies. A share (``--cli-share``) of the cases also runs
the mutated file through the CLI (``overbound analyze`` for the epoch formats, ``overbound sbas``
for the raw ones whose fixture belongs to the SBAS engine's fixture set), one subprocess at a
time, where ``clean_error`` means a non-zero exit with one stderr line ``error: ...`` naming the
file.

The JSON summary (``--out``) holds the counts per outcome, target and mutation, the defects grouped
by target, outcome, exception type and message pattern (with the first case of each), every case
that is neither ``ok`` nor ``clean_error``, and the wall time, slowest case and worst peak memory.
"""

from __future__ import annotations

import argparse
import contextlib
import gzip
import importlib
import json
import multiprocessing
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import traceback
import warnings
from collections import Counter, defaultdict
from dataclasses import asdict, dataclass, field
from functools import cache
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
PACKAGE_DATA = ROOT / "src" / "overbound" / "data"

#: One target per reader. The first five go through ``overbound.io.open.read(path, format=...)``.
TARGETS: tuple[str, ...] = (
    "rtklib-pos",
    "glab",
    "ubx",
    "csv",
    "parquet",
    "rinex_obs",
    "rinex_nav",
    "sp3",
    "ems",
    "rinex_b",
    "rtklib_sbs",
    "ubx_raw",
    "g1000",
    "sbf",
    "nmea",
    "sbp",
    "novatel",
    "truth",
)
EPOCH_TARGETS = ("rtklib-pos", "glab", "ubx", "csv", "parquet", "g1000", "sbf", "nmea", "sbp", "novatel")
OUTCOMES = ("ok", "clean_error", "unnamed_error", "traceback", "unbalanced", "hang", "memory", "crash")
ACCEPTABLE = ("ok", "clean_error")

#: True antenna positions the formats with positions need (tests/io/test_rtklib.py, test_ubx.py).
RTKLIB_REFERENCE = "35.311803,-120.661092,134.6419"
UBX_REFERENCE = "43.5607,1.4809,207.0"
SBF_REFERENCE = "50.848642,4.732128,128.33"
NMEA_REFERENCE = "50.848642,4.732128,128.33"
SBP_REFERENCE = "37.83124,-122.28651,-17.40"
NOVATEL_REFERENCE = "51.11635,-114.0389,1031.3"
_REFERENCES = {
    "novatel": NOVATEL_REFERENCE,
    "sbp": SBP_REFERENCE,
    "rtklib-pos": RTKLIB_REFERENCE,
    "ubx": UBX_REFERENCE,
    "sbf": SBF_REFERENCE,
    "nmea": NMEA_REFERENCE,
}

SEED_LIMIT = 200_000  # bytes of decompressed content kept of a big fixture
ROLE_LIMIT = 300_000  # ... of one the `overbound sbas` CLI cases use (keeps the engine fixtures whole)
MEMORY_LIMIT_KIB = 2 * 1024 * 1024
TIMEOUT_S = 60.0

# --------------------------------------------------------------------------------------- seeds

_UBX_SYNC = b"\xb5\x62"

#: Lines that start a record / carry an epoch, per target: groups ``year`` (or ``week``) and
#: ``hour`` (or ``sod`` / ``tow``, seconds) are what the epoch mutations change.
_EPOCH_RE: dict[str, tuple[re.Pattern[bytes], ...]] = {
    "rtklib-pos": (
        re.compile(rb"^\s*(?P<year>\d{4})/\d\d/\d\d\s+(?P<hour>\d\d):\d\d:\d\d", re.M),
        re.compile(rb"^\s*(?P<week>\d{4})\s+(?P<tow>\d+\.\d+)\s", re.M),
    ),
    "glab": (re.compile(rb"^(?:SBASOUT|OUTPUT|INFO)\s+(?P<year>\d{4})\s+\d{3}\s+(?P<sod>\d+\.\d+)", re.M),),
    "csv": (re.compile(rb"^(?P<year>\d{4})-\d\d-\d\d[T ](?P<hour>\d\d):", re.M),),
    "nmea": (
        re.compile(rb"^\$G[A-Z]GFA,(?P<hour>\d\d)\d{4}", re.M),
        re.compile(
            rb"^\$G[A-Z]RMC,(?P<hour>\d\d)\d{4}[^,]*,[AV],[^,]*,[NS],[^,]*,[EW],[^,]*,[^,]*,\d{4}(?P<year>\d\d),",
            re.M,
        ),
    ),
    "novatel": (
        re.compile(rb"^#[A-Z0-9_]+A,[^,;]*,\d+,[\d.]+,[A-Z_]+,(?P<week>\d{4}),(?P<tow>\d+\.\d+),", re.M),
    ),
    "g1000": (re.compile(rb"^(?P<year>\d{4})-\d\d-\d\d,\s*(?P<hour>\d\d):\d\d:\d\d", re.M),),
    "truth": (
        re.compile(rb"^\s*(?P<year>\d{4})/\d\d/\d\d\s+(?P<hour>\d\d):\d\d:\d\d", re.M),
        re.compile(rb"^(?P<year>\d{4})-\d\d-\d\d[T ](?P<hour>\d\d):", re.M),
        re.compile(rb"^(?P<week>\d{4}),(?P<tow>\d+\.\d+),", re.M),
    ),
    "rinex_obs": (
        re.compile(rb"^> (?P<year>\d{4}) [ \d]\d [ \d]\d (?P<hour>[ \d]\d) ", re.M),
        re.compile(
            rb"^ (?P<year>[ \d]\d) [ \d]\d [ \d]\d (?P<hour>[ \d]\d) [ \d]\d [ \d]\d\.\d{7}  \d", re.M
        ),
    ),
    "rinex_nav": (
        re.compile(
            rb"^[ \d]\d (?P<year>[ \d]\d) [ \d]\d [ \d]\d (?P<hour>[ \d]\d) [ \d]\d [ \d]\d\.\d", re.M
        ),
        re.compile(rb"^[GRECJSI][ \d]\d (?P<year>\d{4}) \d\d \d\d (?P<hour>\d\d) \d\d \d\d", re.M),
    ),
    "sp3": (re.compile(rb"^\*  (?P<year>\d{4}) [ \d]\d [ \d]\d (?P<hour>[ \d]\d) ", re.M),),
    "ems": (re.compile(rb"^\d{3} (?P<year>\d\d) \d\d \d\d (?P<hour>\d\d) \d\d \d\d ", re.M),),
    "rinex_b": (re.compile(rb"^\d{3} (?P<year>\d\d) \d\d \d\d (?P<hour>\d\d) \d\d [ \d]\d\.\d", re.M),),
    "rtklib_sbs": (re.compile(rb"^\s*(?P<week>\d{4})\s+(?P<tow>\d+)\s+\d{3}\s+\d{1,2} : ", re.M),),
}


@dataclass(frozen=True)
class Seed:
    """One seed file: its (decompressed, possibly cut) content and how to mutate it."""

    target: str
    name: str  # file name without a ``.gz`` suffix
    content: bytes
    gz: bool  # the fixture was gzip-compressed
    unit: str  # "line", "comma" (hex-wrapped UBX), "frame" (binary UBX), "block" (SBF), "sbp", "novatel"
    # (binary SBP / NovAtel frames); "parquet" for Parquet
    fixed: bool = False  # fixed-width columns (RINEX, SP3): field mutations keep the width
    role: str = ""  # its place in the `overbound sbas` CLI cases: obs, nav, sbas, sp3, ubx
    origin: str = ""  # the fixture it comes from, relative to the repository


def _ubx_frames(data: bytes) -> list[tuple[int, int]]:
    """(start, end) of the pieces of a UBX log: whole frames, and the bytes between them (NMEA...)."""
    out, i, n = [], 0, len(data)
    while i < n:
        j = data.find(_UBX_SYNC, i)
        if j < 0:
            out.append((i, n))
            break
        if j > i:
            out.append((i, j))
        end = j + 8 + int.from_bytes(data[j + 4 : j + 6], "little") if j + 6 <= n else n + 1
        if end > n:
            out.append((j, n))
            break
        out.append((j, end))
        i = end
    return out


def _cut(content: bytes, target: str, unit: str, limit: int) -> bytes:
    """The first ``limit`` bytes of ``content``, ending on a whole record."""
    if len(content) <= limit:
        return content
    if unit == "frame":
        frames = [f for f in _ubx_frames(content) if f[1] <= limit and content[f[0] : f[0] + 2] == _UBX_SYNC]
        return content[: frames[-1][1]] if frames else content[:limit]
    if unit in _BINARY_UNITS:
        ends = [b for _, b in _binary_units(content, unit) if b <= limit]
        return content[: ends[-1]] if ends else content[:limit]
    sep = b"," if unit == "comma" else b"\n"
    head = content[: content.rfind(sep, 0, limit) + 1]
    matches = [m for p in _EPOCH_RE.get(target, ()) for m in p.finditer(head)]
    if matches:
        last = max(matches, key=lambda m: m.start())
        first_of_last = min((m for m in matches if m.group(0) == last.group(0)), key=lambda m: m.start())
        head = head[: first_of_last.start()]
    return head


def _fixture(
    target: str, rel: str, unit: str = "line", *, fixed: bool = False, role: str = "", limit: int = 0
) -> Seed:
    path = ROOT / rel
    raw = path.read_bytes()
    gz = raw[:2] == b"\x1f\x8b"
    content = gzip.decompress(raw) if gz else raw
    content = _cut(content, target, unit, limit or (ROLE_LIMIT if role else SEED_LIMIT))
    name = path.name[:-3] if gz and path.name.endswith(".gz") else path.name
    return Seed(target, name, content, gz, unit, fixed, role, rel)


def _generated() -> list[Seed]:
    """A small CSV and two small Parquet epoch tables, written by overbound itself (deterministic)."""
    import polars as pl

    from overbound.io.schema import COLUMNS, ReadReport
    from overbound.io.table import METADATA_KEY, write_epochs
    from overbound.simulate import SimulationConfig, simulate

    canonical = [c.name for c in COLUMNS]
    one = simulate(SimulationConfig(days=1 / 24, interval_s=4.0, seed=0, station="FUZZ")).table
    one = one.select([c for c in canonical if c in one.columns])
    two = simulate(SimulationConfig(days=1 / 48, interval_s=5.0, seed=1, stations=2, station="FZ")).table
    two = two.select([c for c in canonical if c in two.columns])
    seeds = []
    with tempfile.TemporaryDirectory(prefix="fuzz-seeds-") as tmp:
        csv = write_epochs(one, Path(tmp) / "sim.csv")
        seeds.append(Seed("csv", "sim.csv", csv.read_bytes(), False, "line", origin="simulate(seed=0)"))
        report = ReadReport(source="simulate", format="simulate", rows_read=one.height, rows_kept=one.height)
        pq = write_epochs(one, Path(tmp) / "sim.parquet", report=report, extra_metadata={"fuzz": "seed"})
        seeds.append(
            Seed("parquet", "sim.parquet", pq.read_bytes(), False, "parquet", origin="simulate(seed=0)")
        )
        meta = pl.read_parquet_metadata(pq)[METADATA_KEY]
        plain = Path(tmp) / "sim2-uncompressed.parquet"
        two.write_parquet(plain, compression="uncompressed", statistics=True, metadata={METADATA_KEY: meta})
        seeds.append(
            Seed(
                "parquet",
                plain.name,
                plain.read_bytes(),
                False,
                "parquet",
                origin="simulate(seed=1, stations=2)",
            )
        )
    return seeds


@cache
def load_seeds() -> dict[str, tuple[Seed, ...]]:
    """The seed files of every target (read once per process)."""
    rt = "tests/data/rtklib-pos/"
    good_pos = (
        "good-uslo-head",
        "crlf-line-endings",
        "comma-separated",
        "utc-header",
        "week-tow",
        "xyz",
        "dms",
        "rinex3-station",
        "test28-ws-head",
    )
    seeds: list[Seed] = [_fixture("rtklib-pos", f"{rt}{n}.pos") for n in good_pos]
    seeds.append(_fixture("rtklib-pos", "src/overbound/data/uslo-2006-361-waas.pos.gz"))
    seeds += [
        _fixture("glab", f"tests/data/glab/{n}")
        for n in (
            "synt0140_egnos123_v5format.glab.gz",
            "synt0140_egnos123_v6.glab.gz",
            "synt0140_egnos123_v6_fullday.glab.gz",
        )
    ]
    seeds += [
        _fixture("ubx", str(p.relative_to(ROOT)), "frame") for p in sorted((DATA / "ubx").glob("*.ubx"))
    ]
    seeds += _generated()
    r, s = "tests/data/rinex/", "tests/data/sbas/"
    seeds += [
        _fixture("rinex_obs", r + n, fixed=True)
        for n in ("SYNT0140_cut.19o.gz", "ESBC00DNK_cut.crx.gz", "ESBC00DNK_cut_v211.20o.gz")
    ]
    seeds.append(_fixture("rinex_obs", s + "engine/SYNT0140_h02-04.19o.gz", fixed=True, role="obs"))
    seeds += [
        _fixture("rinex_nav", r + n, fixed=True) for n in ("brdc0140_cut.19n.gz", "ESBC00DNK_cut_MN.rnx.gz")
    ]
    seeds.append(_fixture("rinex_nav", s + "engine/brdc0140.19n.gz", fixed=True, role="nav"))
    seeds += [_fixture("sp3", r + n, fixed=True) for n in ("igs20361_cut.sp3.gz", "GRG0MGXFIN_cut.sp3.gz")]
    seeds.append(_fixture("sp3", s + "range_domain/igs20361_h00-07.sp3.gz", fixed=True, role="sp3"))
    seeds.append(_fixture("ems", s + "ems/h00.ems.gz"))
    seeds.append(_fixture("ems", s + "ems/h02.ems.gz", role="sbas"))
    seeds.append(_fixture("ems", s + "msas/ubx_20080526_sbas.ems.gz"))
    seeds.append(_fixture("rinex_b", s + "rinexb/egnos123_h02-04.19b.gz", fixed=True, role="sbas"))
    seeds += [
        _fixture("rtklib_sbs", f"tests/data/rtklib-sbs/{n}.sbs.gz")
        for n in ("ubx_20080526", "oemv_200911218")
    ]
    seeds.append(
        _fixture(
            "ubx_raw", s + "ublox/egnos_sdk_20121025_1202-1217.txt.gz", "comma", role="ubx", limit=120_000
        )
    )
    seeds.append(_fixture("ubx_raw", s + "ublox/ubx_20080526_60s.ubx.gz", "frame"))
    seeds += [
        _fixture("g1000", f"tests/data/g1000/{p.name}") for p in sorted((DATA / "g1000").glob("*.csv.gz"))
    ]
    seeds += [
        _fixture("sbf", f"tests/data/sbf/{p.name}", "block") for p in sorted((DATA / "sbf").glob("*.gz"))
    ]
    seeds += [_fixture("nmea", f"tests/data/nmea/{p.name}") for p in sorted((DATA / "nmea").glob("*.gz"))]
    seeds += [_fixture("sbp", f"tests/data/sbp/{p.name}", "sbp") for p in sorted((DATA / "sbp").glob("*.gz"))]
    seeds += [
        _fixture("novatel", f"tests/data/novatel/{p.name}", "novatel" if ".bin" in p.name else "line")
        for p in sorted((DATA / "novatel").glob("*.gz"))
    ]
    seeds += [
        _fixture("truth", f"tests/data/truth/{p.name}") for p in sorted((DATA / "truth").glob("*truth*.gz"))
    ]
    out: dict[str, list[Seed]] = defaultdict(list)
    for seed in seeds:
        out[seed.target].append(seed)
    return {t: tuple(out[t]) for t in TARGETS}


# ----------------------------------------------------------------------------------- mutations

Rng = np.random.Generator


def _int(rng: Rng, lo: int, hi: int) -> int:
    """A uniform integer in [lo, hi) (lo when the range is empty)."""
    return int(rng.integers(lo, hi)) if hi > lo else lo


def _sbf_blocks(data: bytes) -> list[tuple[int, int]]:
    """(start, end) of the SBF blocks (sync ``$@``, length at bytes 6-7), the bytes between them their own."""
    out, i, start = [], data.find(b"$@"), 0
    while i >= 0:
        length = int.from_bytes(data[i + 6 : i + 8], "little")
        end = i + length if length >= 8 and i + length <= len(data) else len(data)
        if i > start:
            out.append((start, i))
        out.append((i, end))
        start = end
        i = data.find(b"$@", max(end, i + 2))
    if start < len(data):
        out.append((start, len(data)))
    return out


def _sbp_frames(data: bytes) -> list[tuple[int, int]]:
    """(start, end) of the SBP frames (preamble 0x55, payload length at byte 5), the bytes between them
    their own."""
    out, i, start = [], data.find(b"\x55"), 0
    while i >= 0 and i + 6 <= len(data):
        end = min(i + 8 + data[i + 5], len(data))
        if i > start:
            out.append((start, i))
        out.append((i, end))
        start = end
        i = data.find(b"\x55", end)
    if start < len(data):
        out.append((start, len(data)))
    return out


def _novatel_frames(data: bytes) -> list[tuple[int, int]]:
    """(start, end) of the binary NovAtel records (sync 0xAA 0x44 0x12, header length at byte 3, message
    length at bytes 8-9, CRC-32), the bytes between them their own."""
    out, i, start = [], data.find(b"\xaa\x44\x12"), 0
    while i >= 0 and i + 10 <= len(data):
        end = min(i + data[i + 3] + int.from_bytes(data[i + 8 : i + 10], "little") + 4, len(data))
        if i > start:
            out.append((start, i))
        out.append((i, end))
        start = end
        i = data.find(b"\xaa\x44\x12", end)
    if start < len(data):
        out.append((start, len(data)))
    return out


_BINARY_UNITS = {"block": _sbf_blocks, "sbp": _sbp_frames, "novatel": _novatel_frames}


def _binary_units(data: bytes, unit: str) -> list[tuple[int, int]]:
    return _BINARY_UNITS[unit](data)


def _units(data: bytes, seed: Seed) -> list[bytes]:
    """The file cut into lines (with their ends), comma-separated tokens, UBX frames or SBF blocks."""
    if seed.unit == "frame":
        return [data[a:b] for a, b in _ubx_frames(data)]
    if seed.unit in _BINARY_UNITS:
        return [data[a:b] for a, b in _binary_units(data, seed.unit)]
    sep = b"," if seed.unit == "comma" else b"\n"
    parts = data.split(sep)
    return [p + sep for p in parts[:-1]] + ([parts[-1]] if parts[-1] else [])


def m_truncate(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    pos = _int(rng, 0, len(data))
    return data[:pos], f"cut at byte {pos} of {len(data)}"


def _flip(
    data: bytes, rng: Rng, most: int, lo: int, hi: int, *, bits: bool = False
) -> tuple[bytes, list[int]]:
    """1 to ``most`` bytes of ``data[lo:hi]`` XOR-ed with a random byte (``bits``: one random bit each)."""
    buf = bytearray(data)
    k = _int(rng, 1, most + 1)
    pos = sorted(_int(rng, lo, hi) for _ in range(k))
    for p in pos:
        buf[p] ^= (1 << _int(rng, 0, 8)) if bits else _int(rng, 1, 256)
    return bytes(buf), pos


def m_byte_flip(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    out, pos = _flip(data, rng, 8, 0, len(data))
    return out, f"{len(pos)} byte(s) flipped at {pos}"


def m_byte_insert(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    pos, b = _int(rng, 0, len(data) + 1), _int(rng, 0, 256)
    return data[:pos] + bytes([b]) + data[pos:], f"byte 0x{b:02x} inserted at {pos}"


def m_byte_delete(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    pos = _int(rng, 0, len(data))
    return data[:pos] + data[pos + 1 :], f"byte {pos} deleted"


def _unit_word(seed: Seed) -> str:
    return {"frame": "frame", "comma": "token", "block": "block", "sbp": "frame", "novatel": "frame"}.get(
        seed.unit, "line"
    )


def m_line_delete(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    units = _units(data, seed)
    i = _int(rng, 0, len(units))
    return b"".join(units[:i] + units[i + 1 :]), f"{_unit_word(seed)} {i + 1} of {len(units)} deleted"


def m_line_duplicate(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    units = _units(data, seed)
    i = _int(rng, 0, len(units))
    return b"".join(units[: i + 1] + units[i:]), f"{_unit_word(seed)} {i + 1} of {len(units)} duplicated"


def m_line_swap(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    units = _units(data, seed)
    i = _int(rng, 0, len(units) - 1)
    j = min(len(units) - 1, i + _int(rng, 1, 6))
    units[i], units[j] = units[j], units[i]
    return b"".join(units), f"{_unit_word(seed)}s {i + 1} and {j + 1} of {len(units)} swapped"


def _line_of(data: bytes, pos: int) -> int:
    return data.count(b"\n", 0, pos) + 1


def m_digit_change(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    arr = np.frombuffer(data, dtype=np.uint8)
    digits = np.flatnonzero((arr >= 0x30) & (arr <= 0x39))
    if not len(digits):
        return m_byte_flip(data, rng, seed)
    pos = int(digits[_int(rng, 0, len(digits))])
    new = (data[pos] - 0x30 + _int(rng, 1, 10)) % 10 + 0x30
    return (
        data[:pos] + bytes([new]) + data[pos + 1 :],
        f"line {_line_of(data, pos)}: digit {chr(data[pos])} -> {chr(new)} at byte {pos}",
    )


_NUMBER = re.compile(rb"(?<![\w.])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eEdD][-+]?\d+)?(?![\w.])")
_FIELD_VALUES = {
    "field_nan": (b"nan", b"NaN", b"NAN"),
    "field_inf": (b"inf", b"-inf", b"Infinity"),
    "field_huge": (b"1e308", b"-1e300", b"99999999999999999999", b"1.7976931348623157e+309"),
    "field_empty": (b"",),
}


def _field(kind: str):
    def mutate(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
        # Skip the header (first 20 % of the numbers) most of the time: the data rows matter more.
        numbers = list(_NUMBER.finditer(data))
        if not numbers:
            return m_byte_flip(data, rng, seed)
        lo = len(numbers) // 5 if rng.random() < 0.8 else 0
        m = numbers[_int(rng, lo, len(numbers))]
        values = _FIELD_VALUES[kind]
        new = values[_int(rng, 0, len(values))]
        width = m.end() - m.start()
        if seed.fixed or (kind == "field_empty" and seed.unit == "line" and not seed.name.endswith(".csv")):
            new = new.rjust(width)  # keep fixed columns in place (an empty field is blanks)
        line = _line_of(data, m.start())
        return data[: m.start()] + new + data[
            m.end() :
        ], f"line {line}: {m.group().decode()!r} -> {new.decode()!r}"

    return mutate


def _epoch(which: str):
    def mutate(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
        need = ("year", "week") if which == "year" else ("hour", "sod", "tow")
        # the patterns with the field to change (NMEA: the year is in RMC only, the hour in GFA too)
        patterns = [p for p in _EPOCH_RE.get(seed.target, ()) if any(k in p.groupindex for k in need)]
        matches = [m for p in patterns for m in p.finditer(data)]
        if not matches:
            data, what = m_digit_change(data, rng, seed)
            return data, f"no epoch line; {what}"
        matches.sort(key=lambda m: m.start())
        m = matches[_int(rng, 0, len(matches))]
        groups = m.groupdict()
        if which == "year":
            key = "year" if "year" in groups else "week"
            old = m.group(key)
            width = len(old)
            if key == "week":
                choices = [b"0000", b"9999", b"%04d" % (int(old) - 1), b"%04d" % (int(old) + 1), b"0001"]
            elif width == 4:
                y = int(old)
                choices = [
                    b"0000",
                    b"9999",
                    b"1900",
                    b"1979",
                    b"2100",
                    b"2200",
                    b"%04d" % (y - 1),
                    b"%04d" % (y + 1),
                ]
            else:
                choices = [b"00", b"99", b"79", b"80", b"%2d" % ((int(old) + 1) % 100)]
        else:
            key = next(k for k in ("hour", "sod", "tow") if k in groups)
            old = m.group(key)
            width = len(old)
            if key == "hour":
                choices = [b"00", b"23", b"24", b"25", b"99", b"%2d" % _int(rng, 0, 24)]
                choices = [c.rjust(width) if old.startswith(b" ") else c.replace(b" ", b"0") for c in choices]
            else:
                s = float(old)
                shifts = (-7200.0, -3600.0, 3600.0, 86400.0, 1e6)
                choices = [b"%.2f" % (s + d) for d in shifts] + [b"-1.00", b"nan"]
        new = choices[_int(rng, 0, len(choices))]
        if len(new) < width:
            new = new.rjust(width)
        a, b = m.span(key)
        line = _line_of(data, a)
        return data[:a] + new + data[b:], f"line {line}: {key} {old.decode()!r} -> {new.decode()!r}"

    return mutate


def _pick_line_pos(data: bytes, rng: Rng) -> int:
    pos = _int(rng, 0, len(data))
    start = data.rfind(b"\n", 0, pos) + 1
    end = data.find(b"\n", pos)
    end = len(data) if end < 0 else end
    return _int(rng, start, end + 1)


def m_enc_latin1(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    pos = _pick_line_pos(data, rng)
    chars = (b"\xe9", b"\xb0", b"\xb5", b"\xe4\xf6\xfc", b"\xa0", b"\xff")
    c = chars[_int(rng, 0, len(chars))]
    replace = rng.random() < 0.5 and pos < len(data) and data[pos : pos + 1] != b"\n"
    tail = data[pos + len(c) :] if replace else data[pos:]
    how = "replacing" if replace else "inserted"
    return data[:pos] + c + tail, f"line {_line_of(data, pos)}: latin-1 {c!r} {how} at byte {pos}"


def m_enc_nul(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    pos = _pick_line_pos(data, rng)
    k = _int(rng, 1, 5)
    return data[:pos] + b"\x00" * k + data[pos:], f"line {_line_of(data, pos)}: {k} NUL byte(s) at byte {pos}"


def m_enc_utf16(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    return data.decode("latin-1").encode("utf-16"), "whole file re-encoded as UTF-16 with BOM"


def m_enc_utf8_bom(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    return b"\xef\xbb\xbf" + data, "UTF-8 BOM prepended"


def m_crlf(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    return re.sub(rb"\r?\n", b"\r\n", data), "line ends made CR LF"


def _gz(data: bytes) -> bytes:
    return gzip.compress(data, compresslevel=6, mtime=0)


def m_gzip_truncated(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    z = _gz(data)
    pos = _int(rng, 10, len(z) - 1)
    return z[:pos], f"gzip of {len(z)} bytes cut at {pos}"


def m_gzip_flip(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    z = _gz(data)
    out, pos = _flip(z, rng, 4, 10, len(z))
    return out, f"gzip of {len(z)} bytes, {len(pos)} byte(s) flipped at {pos}"


def m_gzip_header_only(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    return _gz(data)[:10], "gzip header only (10 bytes)"


def _footer(data: bytes) -> tuple[int, int]:
    """Start and end of a Parquet file's Thrift footer."""
    n = int.from_bytes(data[-8:-4], "little")
    return len(data) - 8 - n, len(data) - 8


def m_parquet_flip_data(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    start, _ = _footer(data)
    out, pos = _flip(data, rng, 4, 4, start, bits=True)
    return out, f"{len(pos)} bit(s) flipped in the data pages at {pos} (footer at {start})"


def m_parquet_flip_footer(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    start, end = _footer(data)
    out, pos = _flip(data, rng, 2, start, end, bits=True)
    return out, f"{len(pos)} bit(s) flipped in the footer [{start}, {end}) at {pos}"


def m_parquet_meta_json(data: bytes, rng: Rng, seed: Seed) -> tuple[bytes, str]:
    """One character of the overbound provenance JSON (key-value metadata) changed, lengths kept."""
    start, end = _footer(data)
    a = data.find(b'{"extra"', start, end)
    if a < 0:
        return m_parquet_flip_footer(data, rng, seed)
    b = data.find(b"}}", a, end) + 2
    b = b if b > a + 2 else end
    pos = _int(rng, a, b)
    choices = b'{}[]":,x0 \\'
    new = choices[_int(rng, 0, len(choices))]
    if new == data[pos]:
        new = ord("#")
    buf = bytearray(data)
    buf[pos] = new
    return bytes(buf), f"provenance JSON byte {pos - a} of {b - a}: {chr(data[pos])!r} -> {chr(new)!r}"


MUTATIONS = {
    "truncate": m_truncate,
    "byte_flip": m_byte_flip,
    "byte_insert": m_byte_insert,
    "byte_delete": m_byte_delete,
    "line_delete": m_line_delete,
    "line_duplicate": m_line_duplicate,
    "line_swap": m_line_swap,
    "digit_change": m_digit_change,
    "field_nan": _field("field_nan"),
    "field_inf": _field("field_inf"),
    "field_huge": _field("field_huge"),
    "field_empty": _field("field_empty"),
    "epoch_year": _epoch("year"),
    "epoch_hour": _epoch("hour"),
    "enc_latin1": m_enc_latin1,
    "enc_nul": m_enc_nul,
    "enc_utf16": m_enc_utf16,
    "enc_utf8_bom": m_enc_utf8_bom,
    "crlf": m_crlf,
    "gzip_truncated": m_gzip_truncated,
    "gzip_flip": m_gzip_flip,
    "gzip_header_only": m_gzip_header_only,
    "parquet_flip_data": m_parquet_flip_data,
    "parquet_flip_footer": m_parquet_flip_footer,
    "parquet_meta_json": m_parquet_meta_json,
}
_BYTE = ("truncate", "byte_flip", "byte_insert", "byte_delete")
_GZIP = ("gzip_truncated", "gzip_flip", "gzip_header_only")
_TEXT = (
    "line_delete",
    "line_duplicate",
    "line_swap",
    "digit_change",
    "field_nan",
    "field_inf",
    "field_huge",
    "field_empty",
    "epoch_year",
    "epoch_hour",
    "enc_latin1",
    "enc_nul",
    "enc_utf16",
    "enc_utf8_bom",
    "crlf",
)
_FRAME = ("line_delete", "line_duplicate", "line_swap")  # on UBX frames
_HEX = ("line_delete", "line_duplicate", "line_swap", "digit_change", "enc_latin1", "enc_nul", "crlf")
_PARQUET = ("parquet_flip_data", "parquet_flip_footer", "parquet_meta_json")


def mutations_for(seed: Seed) -> tuple[str, ...]:
    """The mutation names that apply to a seed's kind of content."""
    extra = {
        "line": _TEXT,
        "comma": _HEX,
        "frame": _FRAME,
        "block": _FRAME,
        "sbp": _FRAME,
        "novatel": _FRAME,
        "parquet": _PARQUET,
    }
    extra = extra[seed.unit]
    return _BYTE + extra + _GZIP


def _mutation_name(mutation: str, seed: Seed) -> str:
    """The recorded name: line operations on UBX frames or hex tokens say so."""
    if mutation.startswith("line_") and seed.unit in ("frame", "comma", "block", "sbp", "novatel"):
        words = {
            "frame": "frame_",
            "comma": "token_",
            "block": "block_",
            "sbp": "frame_",
            "novatel": "frame_",
        }
        prefix = words[seed.unit]
        return mutation.replace("line_", prefix)
    return mutation


# ------------------------------------------------------------------------------------- cases


@dataclass
class Case:
    target: str
    seed: int
    index: int
    seed_file: str
    mutation: str
    detail: str
    filename: str
    data: bytes = field(repr=False)
    role: str = ""

    def meta(self) -> dict:
        return {k: v for k, v in asdict(self).items() if k != "data"}


def case_target(index: int) -> str:
    """The target of case ``index``: the targets take turns."""
    return TARGETS[index % len(TARGETS)]


def target_cases(target: str, n: int) -> list[int]:
    """The numbers of the first ``n`` cases of ``target``."""
    return [TARGETS.index(target) + len(TARGETS) * j for j in range(n)]


def make_case(seed: int, index: int) -> Case:
    """Case ``index``: its target, a seed file, a mutation and the mutated bytes (deterministic)."""
    target = case_target(index)
    seeds = load_seeds()[target]
    rng = np.random.default_rng((seed, index))
    s = seeds[_int(rng, 0, len(seeds))]
    names = mutations_for(s)
    mutation = names[_int(rng, 0, len(names))]
    wrap = rng.random() < 0.5  # a gzip fixture's content mutations are gzipped again half the time
    data, detail = MUTATIONS[mutation](s.content, rng, s)
    name = s.name
    if mutation in _GZIP or (s.gz and wrap and mutation not in _GZIP):
        if mutation not in _GZIP:
            data = _gz(data)
            detail += ", gzipped"
        name += ".gz"
    mname = _mutation_name(mutation, s)
    filename = f"{target}-{seed}-{index:06d}-{mname}-{name}"
    return Case(target, seed, index, s.origin or s.name, mname, detail, filename, data, s.role)


# ----------------------------------------------------------------------------------- outcomes


@dataclass
class Outcome:
    target: str
    seed: int
    index: int
    seed_file: str
    mutation: str
    detail: str
    outcome: str
    message: str = ""
    exc_type: str = ""
    last_frame: str = ""
    last_overbound_frame: str = ""
    counts: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    seconds: float = 0.0
    peak_rss_kib: int = 0
    command: str = "api"  # "api", or the CLI command ("analyze", "sbas --obs", ...)

    def key(self) -> tuple:
        return (self.command != "api", self.target, self.index, self.command)

    def summary(self) -> str:
        """One line for an assertion message: the case, the outcome and what went wrong."""
        where = f" at {self.last_frame}" if self.last_frame else ""
        counts = f" {self.counts}" if self.counts else ""
        return (
            f"case {self.index} {self.target} (--seed {self.seed} --repro {self.index}; "
            f"{self.mutation}: {self.detail}; {self.seed_file}) "
            f"-> {self.outcome}: {self.exc_type + ': ' if self.exc_type else ''}{self.message}{counts}{where}"
        )

    def record(self) -> dict:
        """The JSON form (without the run-dependent seconds and memory)."""
        d = asdict(self)
        for k in ("seconds", "peak_rss_kib"):
            d.pop(k)
        return {k: v for k, v in d.items() if v not in ("", [], {}) or k in ("message",)}


def _short(path: str) -> str:
    for marker in ("/site-packages/", "/src/", "/lib/python"):
        if marker in path:
            return path.split(marker, 1)[1]
    with contextlib.suppress(ValueError):
        return str(Path(path).relative_to(ROOT))
    return path


def _frames(exc: BaseException) -> tuple[str, str]:
    tb = traceback.extract_tb(exc.__traceback__)
    if not tb:
        return "", ""
    last = f"{_short(tb[-1].filename)}:{tb[-1].lineno} in {tb[-1].name}"
    own = [f for f in tb if "/overbound/" in f.filename.replace("\\", "/")]
    mine = f"{_short(own[-1].filename)}:{own[-1].lineno} in {own[-1].name}" if own else ""
    return last, mine


def _clean(text: str, workdir: str) -> str:
    text = text.replace(workdir.rstrip("/") + "/", "<tmp>/").replace(workdir, "<tmp>")
    return text if len(text) <= 400 else text[:400] + "..."


def _call(target: str, path: Path):
    """Run one reader on ``path``; return its ReadReport."""
    if target in EPOCH_TARGETS:
        from overbound.io.geodesy import Reference
        from overbound.io.open import read

        ref = _REFERENCES.get(target)
        _, report = read(path, format=target, reference=Reference.parse(ref) if ref else None)
        return report
    if target == "rinex_obs":
        from overbound.io.rinex_obs import read_rinex_obs as reader
    elif target == "rinex_nav":
        from overbound.io.rinex_nav import read_rinex_nav as reader
    elif target == "sp3":
        from overbound.io.sp3 import read_sp3 as reader
    elif target == "ems":
        from overbound.io.ems import read_ems as reader
    elif target == "rinex_b":
        from overbound.io.rinex_b import read_rinex_b as reader
    elif target == "rtklib_sbs":
        from overbound.io.rtklib_sbs import read_rtklib_sbs as reader
    elif target == "ubx_raw":
        from overbound.io.ubx_raw import read_ubx_raw as reader
    elif target == "truth":  # the trajectory read, then interpolated to the rover's epochs
        from overbound.io.open import read
        from overbound.io.truth import read_truth

        truth = read_truth(path)
        read(DATA / "truth" / "rover.pos.gz", reference=truth)
        return truth.read_report()
    else:
        raise ValueError(f"unknown target {target!r}")
    _, report = reader(path)
    return report


def _unaccounted(report) -> int:
    """``ReadReport.unaccounted`` (rows read, neither kept nor counted as rejected); the same formula
    when the installed overbound predates the property."""
    value = getattr(report, "unaccounted", None)
    return int(value) if value is not None else report.rows_read - report.rows_kept - report.n_rejected


def reset_peak_rss() -> None:
    """Reset this process's resident-memory high-water mark (Linux ``/proc/self/clear_refs``)."""
    with contextlib.suppress(OSError):
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")


def peak_rss_kib() -> int:
    """This process's peak resident memory (KiB) since :func:`reset_peak_rss`: ``VmHWM``, else
    ``ru_maxrss`` (the peak of the whole life of the process)."""
    with contextlib.suppress(OSError, ValueError, IndexError):
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def run_case(case: Case, workdir: str | Path, keep: bool = False) -> Outcome:
    """Write the case's file into ``workdir``, read it, classify what happened (in this process)."""
    from overbound.io.schema import InputError

    workdir = str(workdir)
    path = Path(workdir) / case.filename
    path.write_bytes(case.data)
    out = Outcome(case.target, case.seed, case.index, case.seed_file, case.mutation, case.detail, "ok")
    reset_peak_rss()
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                report = _call(case.target, path)
            finally:
                out.seconds = time.perf_counter() - t0
                seen = dict.fromkeys(_clean(f"{w.category.__name__}: {w.message}", workdir) for w in caught)
                out.warnings = list(seen)[:3]
    except InputError as exc:
        out.message = _clean(str(exc), workdir)
        out.exc_type = "InputError"
        out.outcome = "clean_error" if case.filename in str(exc) else "unnamed_error"
        if out.outcome == "unnamed_error":
            out.last_frame, out.last_overbound_frame = _frames(exc)
    except KeyboardInterrupt:
        raise
    except BaseException as exc:  # PanicException derives from BaseException
        out.outcome = "traceback"
        out.exc_type = f"{type(exc).__module__}.{type(exc).__qualname__}".removeprefix("builtins.")
        out.message = _clean(str(exc).strip().splitlines()[0] if str(exc).strip() else "", workdir)
        out.last_frame, out.last_overbound_frame = _frames(exc)
    else:
        n_inv = sum(report.invalidated.values())
        unaccounted = _unaccounted(report)
        out.counts = {
            "rows_read": report.rows_read,
            "rows_kept": report.rows_kept,
            "rejected": report.n_rejected,
            "invalidated": n_inv,
            "unaccounted": unaccounted,
        }
        if unaccounted != 0:
            out.outcome = "unbalanced"
            out.counts["reasons"] = dict(sorted(report.rejected.items()))
            out.counts["format"] = report.format
            out.message = (
                f"rows_read {report.rows_read} - kept {report.rows_kept} - rejected {report.n_rejected}"
            )
            out.message += f" = {unaccounted} unaccounted (format {report.format})"
        else:
            out.counts = {}
    finally:
        if not keep:
            path.unlink(missing_ok=True)
    out.peak_rss_kib = peak_rss_kib()
    return out


def baseline(workdir: str | Path) -> list[Outcome]:
    """Every seed file read unmutated (index -1, mutation ``none``): what the mutations start from."""
    out = []
    for target, seeds in load_seeds().items():
        for k, s in enumerate(seeds):
            name = f"{target}-seed{k}-{s.name}"
            out.append(
                run_case(Case(target, 0, -1, s.origin or s.name, "none", "", name, s.content), workdir)
            )
    return out


def run_cases(
    target: str,
    n: int,
    seed: int = 0,
    in_process: bool = True,
    *,
    timeout: float = TIMEOUT_S,
    memory_kib: int = MEMORY_LIMIT_KIB,
) -> list[Outcome]:
    """Cases 0..n-1 of ``target``: in this process (no time-out), or in one watched worker process."""
    if target not in TARGETS:
        raise ValueError(f"unknown target {target!r}; choose one of {', '.join(TARGETS)}")
    with tempfile.TemporaryDirectory(prefix="fuzz-readers-") as tmp:
        if in_process:
            return [run_case(make_case(seed, i), tmp) for i in target_cases(target, n)]
        worker = Worker(tmp, timeout=timeout, memory_kib=memory_kib)
        try:
            return [worker.run(seed, i) for i in target_cases(target, n)]
        finally:
            worker.stop()


# ------------------------------------------------------------------------------ worker process


def _worker_main(conn, workdir: str) -> None:
    load_seeds()
    for module in ("overbound.io.open", "overbound.io.rinex_obs", "overbound.io.ems", "overbound.io.sp3"):
        importlib.import_module(module)  # the imports cost about a second: once per worker

    conn.send(("ready", os.getpid()))
    while True:
        msg = conn.recv()
        if msg is None:
            return
        if msg == "baseline":
            conn.send(("baseline", [asdict(o) for o in baseline(workdir)]))
            continue
        seed, index, keep = msg
        case = make_case(seed, index)
        conn.send(("start", case.meta()))
        conn.send(("done", asdict(run_case(case, workdir, keep))))


def _vmrss_kib(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except (OSError, ValueError):
        pass
    return 0


def _tree_rss_kib(pid: int) -> int:
    """Resident memory of ``pid`` and its descendants."""
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        total += _vmrss_kib(p)
        with contextlib.suppress(OSError):
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as f:
                    todo += [int(c) for c in f.read().split()]
    return total


class Worker:
    """One persistent ``spawn`` process that runs cases; killed and restarted on a hang, memory or crash."""

    def __init__(self, workdir: str, *, timeout: float = TIMEOUT_S, memory_kib: int = MEMORY_LIMIT_KIB):
        self.workdir = workdir
        self.timeout = timeout
        self.memory_kib = memory_kib
        self.ctx = multiprocessing.get_context("spawn")
        self.restarts = 0
        self.proc = None
        self.last_meta: dict = {}  # the "start" message of the last case: its file name and seed role
        self._start()

    def _start(self) -> None:
        self.conn, child = self.ctx.Pipe()
        self.proc = self.ctx.Process(target=_worker_main, args=(child, self.workdir), daemon=True)
        self.proc.start()
        child.close()
        if not self.conn.poll(300):
            raise RuntimeError("fuzz worker did not start within 300 s")
        self.conn.recv()

    def _kill(self) -> None:
        if self.proc is not None and self.proc.is_alive():
            self.proc.kill()
        if self.proc is not None:
            self.proc.join(10)
        self.conn.close()

    def restart(self) -> None:
        self._kill()
        self.restarts += 1
        self._start()

    def _killed(self, base: dict, outcome: str, message: str, elapsed: float, peak: int) -> Outcome:
        """Restart the worker that went over a limit; the case's outcome."""
        self.restart()
        return Outcome(**base, outcome=outcome, message=message, seconds=elapsed, peak_rss_kib=peak)

    def stop(self) -> None:
        with contextlib.suppress(OSError, BrokenPipeError):
            self.conn.send(None)
        if self.proc is not None:
            self.proc.join(10)
        self._kill()

    def baseline(self) -> list[Outcome]:
        """The unmutated seeds, read by the worker."""
        self.conn.send("baseline")
        if not self.conn.poll(600):
            raise RuntimeError("fuzz worker: no baseline within 600 s")
        return [Outcome(**d) for d in self.conn.recv()[1]]

    def run(self, seed: int, index: int, keep: bool = False) -> Outcome:
        self.conn.send((seed, index, keep))
        meta = {
            "target": case_target(index),
            "seed": seed,
            "index": index,
            "seed_file": "?",
            "mutation": "?",
            "detail": "",
        }
        self.last_meta = {}
        t0 = time.monotonic()
        peak = 0
        while True:
            try:
                ready = self.conn.poll(0.2)
                msg = self.conn.recv() if ready else None
            except (EOFError, OSError):
                msg, ready = None, False
                if self.proc.is_alive():
                    self.proc.join(1)
            if msg is not None and msg[0] == "start":
                meta = self.last_meta = msg[1]
                continue
            if msg is not None and msg[0] == "done":
                out = Outcome(**msg[1])
                if out.peak_rss_kib > self.memory_kib:
                    out.message = (
                        f"worker peak RSS {out.peak_rss_kib // 1024} MiB (was: {out.outcome} {out.message})"
                    )
                    out.outcome = "memory"
                    self.restart()
                return out
            elapsed = time.monotonic() - t0
            base = {k: meta[k] for k in ("target", "seed", "index", "seed_file", "mutation", "detail")}
            if not self.proc.is_alive():
                code = self.proc.exitcode
                self.restart()
                return Outcome(
                    **base, outcome="crash", message=f"worker died, exit code {code}", seconds=elapsed
                )
            rss = _vmrss_kib(self.proc.pid)
            peak = max(peak, rss)
            if rss > self.memory_kib:
                return self._killed(base, "memory", f"resident {rss // 1024} MiB, killed", elapsed, rss)
            if elapsed > self.timeout:
                return self._killed(
                    base, "hang", f"no answer after {self.timeout:.0f} s, killed", elapsed, peak
                )


# ---------------------------------------------------------------------------------------- CLI

_SBAS = DATA / "sbas"
_CLI_FILES = {
    "obs": [_SBAS / "engine" / "SYNT0140_h02-04.19o.gz"],
    "nav": [_SBAS / "engine" / "brdc0140.19n.gz"],
    "sbas": [_SBAS / "ems" / "h02.ems.gz", _SBAS / "engine" / "h03.ems.gz", _SBAS / "engine" / "h04.ems.gz"],
}


def cli_command(case_meta: dict, path: Path, outdir: Path) -> list[str] | None:
    """The ``overbound`` command line of a CLI case, or None when the case has none."""
    target, role = case_meta["target"], case_meta.get("role", "")
    base = [sys.executable, "-m", "overbound"]
    if target in EPOCH_TARGETS:
        cmd = [*base, "analyze", str(path), "-o", str(outdir / "out"), "--format", target]
        # every other analyze case runs the counting alone (fast); the others every method, whose
        # numerical steps must fail their section only (a root-finder meeting NaN stopped the run)
        if case_meta["index"] % 2:
            cmd += ["--no-confidence", "--no-evt", "--no-parametric"]
        return cmd + (["--reference", _REFERENCES[target]] if target in _REFERENCES else [])
    out = ["-o", str(outdir / "e.parquet")]
    if role == "ubx":
        return [*base, "sbas", "--obs", str(path), "--reference", "mean", *out]
    if role not in ("obs", "nav", "sbas", "sp3"):
        return None
    files = {k: [str(p) for p in v] for k, v in _CLI_FILES.items()}
    if role == "sbas":
        files["sbas"][0] = str(path)  # the first hour's messages, EMS or RINEX-B
    elif role in files:
        files[role] = [str(path)]
    cmd = [*base, "sbas", "--obs", *files["obs"], "--nav", *files["nav"], "--sbas", *files["sbas"], *out]
    return cmd + (["--sp3", str(path)] if role == "sp3" else [])


def run_cli(case_meta: dict, path: Path, workdir: str, *, timeout: float, memory_kib: int) -> Outcome | None:
    """Run the CLI case in a subprocess (its own session, killed with its children on a limit)."""
    outdir = Path(tempfile.mkdtemp(prefix="cli-", dir=workdir))
    cmd = cli_command(case_meta, path, outdir)
    if cmd is None:
        shutil.rmtree(outdir, ignore_errors=True)
        return None
    command = cmd[3] if cmd[3] == "analyze" else f"sbas {case_meta.get('role', '')}"
    base = {k: case_meta[k] for k in ("target", "seed", "index", "seed_file", "mutation", "detail")}
    env = dict(os.environ, OVERBOUND_FIGURE_PROCESSES="0", MPLBACKEND="Agg", COLUMNS="200")
    err_path, out_path = outdir / "stderr.txt", outdir / "stdout.txt"
    t0 = time.monotonic()
    with open(err_path, "wb") as err, open(out_path, "wb") as so:
        proc = subprocess.Popen(
            cmd, stdout=so, stderr=err, stdin=subprocess.DEVNULL, env=env, start_new_session=True, cwd=workdir
        )
    peak, killed, status, usage = 0, "", None, None
    while status is None:
        pid, st, ru = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            status, usage = st, ru
            proc.returncode = os.waitstatus_to_exitcode(st)  # reaped here: Popen must not wait again
            break
        rss = _tree_rss_kib(proc.pid)
        peak = max(peak, rss)
        if not killed and rss > memory_kib:
            killed = f"memory: resident {rss // 1024} MiB, killed"
        elif not killed and time.monotonic() - t0 > timeout:
            killed = f"hang: no exit after {timeout:.0f} s, killed"
        if killed:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
        time.sleep(0.2)
    elapsed = time.monotonic() - t0
    peak = max(peak, usage.ru_maxrss if usage else 0)
    rc = proc.returncode
    stderr = err_path.read_text(errors="replace")
    shutil.rmtree(outdir, ignore_errors=True)
    out = Outcome(**base, outcome="ok", seconds=elapsed, peak_rss_kib=peak, command=command)
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    name = Path(path).name
    if killed:
        out.outcome, out.message = killed.split(": ", 1)
    elif rc == 0:
        pass
    elif rc < 0:
        out.outcome, out.message = "crash", f"killed by signal {-rc}; stderr: {' | '.join(lines[-2:])}"
    elif "Traceback" in stderr or "panicked" in stderr or len(lines) != 1:
        out.outcome = "traceback"
        frames = re.findall(r'File "([^"]+)", line (\d+), in (\S+)', stderr)
        if frames:
            f, n, fn = frames[-1]
            out.last_frame = f"{_short(f)}:{n} in {fn}"
            own = [x for x in frames if "/overbound/" in x[0]]
            if own:
                out.last_overbound_frame = f"{_short(own[-1][0])}:{own[-1][1]} in {own[-1][2]}"
        out.message = f"exit {rc}; " + " | ".join(lines[-2:])
    else:  # one line: clean when it is an ``error:`` line naming the file (else e.g. click's "Aborted!")
        line = lines[0]
        out.outcome = "clean_error" if line.startswith("error:") and name in line else "unnamed_error"
        out.message = f"exit {rc}; {line}"
    out.message = _clean(out.message, workdir)
    return out


# ---------------------------------------------------------------------------------------- run


def _pattern(o: Outcome) -> str:
    """The message with the case's numbers and names blurred, to group the cases of one defect."""
    text = o.message.replace("<tmp>/", "")
    text = re.sub(rf"{re.escape(o.target)}-\d+-\d+-[\w.-]+", "<file>", text)
    text = re.sub(r"0x[0-9a-fA-F]+", "0x#", text)
    text = re.sub(r"\d+(\.\d+)?", "#", text)
    text = re.sub(r"'[^']{0,40}'", "'…'", text)
    return text[:140]


def _defect_groups(outs: list[Outcome]) -> list[dict]:
    groups: dict[tuple, list[Outcome]] = defaultdict(list)
    for o in outs:
        if o.outcome in ACCEPTABLE:
            continue
        where = o.last_overbound_frame.split(" in ")[0] if o.last_overbound_frame else ""
        pattern = _pattern(o)
        if o.outcome == "unbalanced":
            sign = "more counted than read" if o.counts["unaccounted"] < 0 else "rows lost without a count"
            pattern = f"{o.counts['format']}: {sign}; rejected reasons {sorted(o.counts['reasons'])}"
        groups[(o.command, o.target, o.outcome, o.exc_type, where, pattern)].append(o)
    rows = []
    for (command, target, outcome, exc, where, pattern), cases in sorted(groups.items()):
        first = min(cases, key=lambda c: c.index)
        rows.append(
            {
                "command": command,
                "target": target,
                "outcome": outcome,
                "exc_type": exc,
                "overbound_frame": where,
                "pattern": pattern,
                "count": len(cases),
                "mutations": dict(sorted(Counter(c.mutation for c in cases).items())),
                "example": first.record(),
            }
        )
    return rows


def _table(outs: list[Outcome], key) -> dict:
    counts: dict[str, Counter] = defaultdict(Counter)
    for o in outs:
        counts[key(o)][o.outcome] += 1
    return {k: {oc: v[oc] for oc in OUTCOMES if v[oc]} for k, v in sorted(counts.items())}


def summarize(
    api: list[Outcome], cli: list[Outcome], args: dict, wall: float, restarts: int, seeds: list[Outcome] = ()
) -> dict:
    """The JSON summary of a run."""
    api = sorted(api, key=Outcome.key)
    cli = sorted(cli, key=Outcome.key)
    everything = api + cli
    slow = max(everything, key=lambda o: o.seconds) if everything else None
    worst = max(everything, key=lambda o: o.peak_rss_kib) if everything else None
    return {
        "issue": 13,
        "args": args,
        "overbound": _version(),
        "seed_files": [
            {"target": o.target, "file": o.seed_file, "outcome": o.outcome, "message": o.message, **o.counts}
            for o in seeds
        ],
        "total_cases": len(api),
        "cli_cases": len(cli),
        "outcomes": {oc: n for oc in OUTCOMES if (n := sum(o.outcome == oc for o in api))},
        "by_target": _table(api, lambda o: o.target),
        "by_mutation": _table(api, lambda o: o.mutation),
        "by_target_and_mutation": {
            t: _table([o for o in api if o.target == t], lambda o: o.mutation) for t in TARGETS
        },
        "cli_outcomes": {oc: n for oc in OUTCOMES if (n := sum(o.outcome == oc for o in cli))},
        "cli_by_command": _table(cli, lambda o: f"{o.command} ({o.target})"),
        "defects": _defect_groups(everything),
        "failures": [o.record() for o in everything if o.outcome not in ACCEPTABLE],
        "wall_time_s": round(wall, 1),
        "api_seconds_total": round(sum(o.seconds for o in api), 1),
        "cli_seconds_total": round(sum(o.seconds for o in cli), 1),
        "wall_time_s_per_1000_cases": round(1000 * wall / max(len(api), 1), 1),
        "worker_restarts": restarts,
        "worst_peak_rss_mib": round(worst.peak_rss_kib / 1024, 1) if worst else 0,
        "worst_peak_rss_case": f"{worst.command} {worst.target}:{worst.index}" if worst else "",
        "slowest_case": (
            {
                "command": slow.command,
                "target": slow.target,
                "index": slow.index,
                "mutation": slow.mutation,
                "seconds": round(slow.seconds, 2),
            }
            if slow
            else {}
        ),
    }


def _version() -> dict:
    """The overbound tested: version, where it is imported from, the repository's commit and whether
    its tree has uncommitted changes (without importing overbound in this process)."""
    code = "import overbound, sys; sys.stdout.write(overbound.__version__ + ' ' + overbound.__file__)"
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=tempfile.gettempdir()
    )
    version, _, where = res.stdout.partition(" ")
    git = ["git", "-C", str(ROOT)]
    head = subprocess.run([*git, "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    dirty = subprocess.run([*git, "status", "--porcelain", "src"], capture_output=True, text=True).stdout
    if where and Path(where).parent != ROOT / "src" / "overbound":
        dirty = ""  # a copy elsewhere (PYTHONPATH): the repository's state says nothing about it
    return {
        "version": version,
        "imported_from": str(Path(where).parent) if where else "",
        "commit": head,
        "src_modified": sorted(ln[3:] for ln in dirty.splitlines()),
    }


def fuzz(
    cases: int,
    seed: int = 0,
    *,
    cli_share: float = 0.02,
    timeout: float = TIMEOUT_S,
    memory_kib: int = MEMORY_LIMIT_KIB,
    progress: bool = True,
) -> dict:
    """Run ``cases`` cases round-robin over :data:`TARGETS` in one watched worker; the summary dict."""
    t0 = time.monotonic()
    api: list[Outcome] = []
    cli: list[Outcome] = []
    tmp = tempfile.mkdtemp(prefix="fuzz-readers-")
    worker = Worker(tmp, timeout=timeout, memory_kib=memory_kib)
    try:
        seeds = worker.baseline()
        for k in range(cases):
            want_cli = np.random.default_rng((seed, k, 7919)).random() < cli_share
            out = worker.run(seed, k, keep=want_cli)
            api.append(out)
            if want_cli and worker.last_meta.get("filename"):
                case_file = Path(tmp) / worker.last_meta["filename"]
                if case_file.exists():
                    res = run_cli(worker.last_meta, case_file, tmp, timeout=timeout, memory_kib=memory_kib)
                    if res is not None:
                        cli.append(res)
                    case_file.unlink(missing_ok=True)
            if progress and (k + 1) % 100 == 0:
                bad = sum(o.outcome not in ACCEPTABLE for o in api + cli)
                print(
                    f"{k + 1}/{cases} cases, {len(cli)} CLI, {bad} not ok/clean, "
                    f"{time.monotonic() - t0:.0f} s",
                    file=sys.stderr,
                    flush=True,
                )
    finally:
        worker.stop()
        shutil.rmtree(tmp, ignore_errors=True)
    args = {
        "cases": cases,
        "seed": seed,
        "cli_share": cli_share,
        "timeout_s": timeout,
        "memory_mib": memory_kib // 1024,
    }
    return summarize(api, cli, args, time.monotonic() - t0, worker.restarts, seeds)


def repro(spec: str, seed: int, keep: str | None) -> int:
    """Run case ``spec`` (its number) in this process and print it; keep its file in ``keep``."""
    case = make_case(seed, int(spec))
    with tempfile.TemporaryDirectory(prefix="fuzz-repro-") as tmp:
        out = run_case(case, tmp, keep=True)
        if keep:
            Path(keep).mkdir(parents=True, exist_ok=True)
            shutil.copy(Path(tmp) / case.filename, Path(keep) / case.filename)
            print(f"file: {Path(keep) / case.filename}")
    print(json.dumps(out.record(), indent=1))
    return 0 if out.outcome in ACCEPTABLE else 1


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", type=int, default=1000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--cli-share", type=float, default=0.02)
    p.add_argument("--timeout", type=float, default=TIMEOUT_S)
    p.add_argument("--memory-mib", type=int, default=MEMORY_LIMIT_KIB // 1024)
    p.add_argument("--threads", type=int, default=1, help="polars / BLAS threads of the worker")
    p.add_argument("--out", type=Path)
    p.add_argument("--repro", metavar="CASE", help="run case number CASE alone, in this process")
    p.add_argument("--keep", metavar="DIR", help="with --repro: copy the mutated file there")
    a = p.parse_args(argv)
    if a.repro:
        return repro(a.repro, a.seed, a.keep)
    for var in ("POLARS_MAX_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(a.threads)  # inherited by the spawned worker (the parent imports no polars)
    summary = fuzz(a.cases, a.seed, cli_share=a.cli_share, timeout=a.timeout, memory_kib=a.memory_mib * 1024)
    text = json.dumps(summary, indent=1, ensure_ascii=False) + "\n"
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(text)
    brief = {
        k: summary[k]
        for k in (
            "total_cases",
            "outcomes",
            "cli_outcomes",
            "wall_time_s",
            "wall_time_s_per_1000_cases",
            "worst_peak_rss_mib",
            "slowest_case",
        )
    }
    print(json.dumps(brief | {"by_target": summary["by_target"]}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
