"""The named bad-input corpus of the epoch-table readers (issue 13): each file has one defect,
named after it (``tests/data/make_bad_corpus.py`` makes them from real fixtures), and reads
either to one clean error naming the file or to counts that add up, the defect counted."""

from __future__ import annotations

from pathlib import Path

import pytest

from overbound.io.geodesy import Reference
from overbound.io.gpstime import PLAUSIBLE_SPAN
from overbound.io.open import read
from overbound.io.schema import InputError

DATA = Path(__file__).parents[1] / "data"
USLO = Reference.parse("35.311803,-120.661092,134.6419")
UBX_TRUTH = Reference(43.5607, 1.4809, 207.0)
REFERENCE = {"rtklib-pos": USLO, "ubx": UBX_TRUTH}

#: file -> an error pattern (str), or (rows read, rows kept, rejected by reason, first_bad start)
EXPECTED: dict[str, str | tuple[int, int, dict[str, int], str]] = {
    # gLAB: one character of a no-solution INFO line changed dropped that epoch uncounted
    "glab/bad/info-line-one-char-changed.glab": (
        129,
        128,
        {"malformed_line": 1},
        "155: malformed line: no-solution INFO line that does not parse",
    ),
    # gLAB: one character of the line type itself (SBASOUY, INFP): read and rejected, not skipped
    "glab/bad/line-type-one-char-changed.glab": (
        129,
        127,
        {"malformed_line": 2},
        "157: malformed line: line type 'INFP', one character from an epoch line",
    ),
    # gLAB: a NaN second of day was a polars traceback
    "glab/bad/seconds-of-day-nan.glab": (129, 128, {"time_out_of_range": 1}, "176: time out of range"),
    "glab/bad/gzip-truncated.glab.gz": "truncated or corrupt gzip stream",
    "glab/bad/gzip-crc-mismatch.glab.gz": r"truncated or corrupt gzip stream \(CRC check failed",
    "rtklib-pos/bad/gzip-header-only.pos.gz": "truncated or corrupt gzip stream",
    # year 0 in the middle of a file stopped the run with "year 0 is out of range", no file or line
    "rtklib-pos/bad/year-0000-mid-file.pos": (
        8,
        7,
        {"malformed_line": 1},
        f"19: malformed line: time '0000/12/27 00:06:00.000' outside {PLAUSIBLE_SPAN}",
    ),
    "ubx/bad/gzip-truncated.ubx.gz": "truncated or corrupt gzip stream",
    "table/bad/csv-gzip-truncated.csv.gz": "truncated or corrupt gzip stream",
    # year 0 stopped the run with "error: year 0 is out of range", naming neither file nor line
    "table/bad/csv-year-0000-mid-file.csv": (
        40,
        39,
        {"time_out_of_range": 1},
        f"22: time out of range: 0000-01-07 00:00:20 outside {PLAUSIBLE_SPAN}",
    ),
    "table/bad/parquet-page-header-bit-flipped.parquet": "not a readable Parquet file",
    # the provenance JSON of the footer: a JSONDecodeError without a file name
    "table/bad/parquet-provenance-not-json.parquet": r"not a readable Parquet file \(JSONDecodeError",
    "table/bad/parquet-cut-in-half.parquet": "not a readable Parquet file",
    # found by the 10,000-case fuzzing run: formatting this time made polars panic
    "table/bad/parquet-time-beyond-calendar.parquet": (
        20,
        19,
        {"time_out_of_range": 1},
        "8: time out of range: 9223372036854763463 µs from 1970-01-01",
    ),
}


def test_corpus_is_listed() -> None:
    found = {
        p.relative_to(DATA).as_posix()
        for folder in ("glab", "rtklib-pos", "ubx", "table")
        for p in (DATA / folder / "bad").iterdir()
    }
    assert found == set(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_bad_file(name: str) -> None:
    path = DATA / name
    expected = EXPECTED[name]
    kwargs = {"reference": REFERENCE.get(name.split("/")[0])}
    if isinstance(expected, str):
        with pytest.raises(InputError, match=expected) as err:
            read(path, **kwargs)
        assert str(path) in str(err.value) and "\n" not in str(err.value)
        return
    table, report = read(path, **kwargs)
    n_read, n_kept, rejected, first = expected
    assert (report.rows_read, report.rows_kept, report.rejected) == (n_read, n_kept, rejected)
    assert report.unaccounted == 0 and table.height == n_kept
    assert report.first_bad.startswith(first), report.first_bad
