"""Seeded fuzzing of every input reader (issue 13: nothing lost, nothing half-written).

Each target reads the first ``CASES`` cases of ``validation/fuzz_readers.py`` (seed 0): real
fixtures of tests/data (and a small simulated CSV / Parquet table) cut, bit-flipped, with lines
deleted, duplicated or swapped, digits and fields changed, epochs moved, bad encodings, CR LF and
corrupt gzip or Parquet. Every case must end in one of two ways:

- the reader returns, and its report accounts for every row it read
  (``rows_read == rows_kept + n_rejected``; invalidated rows are kept), or
- it raises :class:`overbound.io.schema.InputError` whose message names the file.

A traceback, an unnamed error or rows lost without a count fail the test, which lists each
failing case with the command that replays it alone
(``python validation/fuzz_readers.py --seed 0 --repro CASE``). The cases run in this process,
a few seconds per target; the resident-memory peak of each target's cases stays under 2 GiB.
The 10,000-case run with time-outs and a memory watchdog is the script itself.
"""

from __future__ import annotations

import time

import fuzz_readers as fz
import pytest

#: Cases per target: about 40 x 10-100 ms (the u-blox raw logs about 0.1-0.3 s each).
CASES = 40
SEED = 0


@pytest.mark.parametrize("target", fz.TARGETS)
def test_mutated_inputs_give_a_named_error_or_balanced_counts(target: str) -> None:
    fz.reset_peak_rss()
    t0 = time.perf_counter()
    outcomes = fz.run_cases(target, CASES, seed=SEED)
    elapsed = time.perf_counter() - t0
    peak_kib = max([fz.peak_rss_kib(), *(o.peak_rss_kib for o in outcomes)])

    assert len(outcomes) == CASES
    assert {o.target for o in outcomes} == {target}
    bad = [o for o in outcomes if o.outcome not in fz.ACCEPTABLE]
    tally = dict(sorted((k, sum(o.outcome == k for o in outcomes)) for k in {o.outcome for o in outcomes}))
    assert not bad, (
        f"{target}: {len(bad)} of {CASES} cases neither ok nor a clean error {tally}:\n"
        + "\n".join(o.summary() for o in bad)
    )
    for o in outcomes:
        if o.outcome == "clean_error":  # the file is named (run_case classifies unnamed errors apart)
            assert o.exc_type == "InputError" and f"-{o.index:06d}-" in o.message
    assert peak_kib < fz.MEMORY_LIMIT_KIB, f"{target}: peak resident memory {peak_kib // 1024} MiB"
    assert elapsed < 60, f"{target}: {CASES} cases took {elapsed:.0f} s"


def test_cases_are_reproducible_and_cover_every_mutation() -> None:
    """The same seed gives the same bytes; the mutations of each kind of seed file all occur."""
    a = fz.make_case(SEED, 123)
    b = fz.make_case(SEED, 123)
    assert (a.data, a.filename, a.detail) == (b.data, b.filename, b.detail)
    assert fz.make_case(SEED + 1, 123).data != a.data
    seen = {fz.make_case(SEED, i).mutation for i in range(len(fz.TARGETS) * 40)}
    generic = {
        n.replace("frame_", "line_").replace("token_", "line_").replace("block_", "line_") for n in seen
    }
    assert set(fz.MUTATIONS) <= generic, f"never drawn: {sorted(set(fz.MUTATIONS) - generic)}"
