"""Write the damaged RINEX observation files of tests/data/rinex/bad/ from the fixtures beside it.

Run from the repository root::

    python tests/data/rinex/bad/make_rinex_obs_bad.py

Each file is one defect of issue 13 reproduced on a cut of a real fixture (see ../PROVENANCE.md),
edited line by line in plain Python (no overbound code); the gzipped one has no name or time stamp,
so every run writes the same bytes.
"""

from __future__ import annotations

import gzip
from pathlib import Path

HERE = Path(__file__).resolve().parent
FIXTURES = HERE.parent


def _lines(name: str) -> list[str]:
    return gzip.decompress((FIXTURES / name).read_bytes()).decode("ascii").split("\n")


def event_flag_3_count_99() -> None:
    """ESBC00DNK_cut_v211.20o, header and epochs 3-6 (00:01:00-00:02:30): the epoch line of
    00:01:30 gets flag 3 (new site occupation) and a count of 99, so that its "header records"
    would run over its own 48 observation lines and all 50 lines of the next epoch, ending on
    the epoch line of 00:02:30."""
    lines = _lines("ESBC00DNK_cut_v211.20o.gz")
    end = next(k for k, s in enumerate(lines) if s[60:].strip() == "END OF HEADER")
    epochs = [k for k in range(end + 1, len(lines)) if lines[k][18:19] == "." and lines[k][26:28] == "  "]
    first, event, stop = epochs[2], epochs[3], epochs[6]
    assert event + 100 == epochs[5], "the record of count 99 must end on an epoch line"
    comment = f"{'DAMAGED: EPOCH 00:01:30 FLAG 0->3, COUNT 24->99':60}COMMENT"
    body = lines[first:stop]
    k = event - first
    body[k] = body[k][:28] + "3 99" + body[k][32:]
    text = "\n".join([*lines[:end], comment, lines[end], *body]) + "\n"
    (HERE / "rinex2-event-flag-3-count-99.20o").write_text(text)


def crinex_duplicated_line() -> None:
    """ESBC00DNK_cut.crx, the header and first 3 epochs (a whole CRINEX: the cut ends where the
    4th epoch's line begins), with the last line of the 2nd epoch written twice."""
    lines = _lines("ESBC00DNK_cut.crx.gz")
    cut, dup = 192, 146  # lines 1-192 kept; line 147 (0-based 146), the 2nd epoch's last, repeated
    assert lines[cut].startswith(" ") and lines[dup + 1].startswith(" "), "3rd and 4th epoch lines"
    kept = [*lines[: dup + 1], lines[dup], *lines[dup + 1 : cut]]
    data = ("\n".join(kept) + "\n").encode("ascii")
    (HERE / "crinex-duplicated-line.crx.gz").write_bytes(gzip.compress(data, compresslevel=9, mtime=0))


if __name__ == "__main__":
    event_flag_3_count_99()
    crinex_duplicated_line()
