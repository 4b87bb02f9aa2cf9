"""Regenerate the named bad-input corpus of the epoch-table readers (issue 13).

Run from the repository root::

    python tests/data/make_bad_corpus.py

Every file is a real fixture of this repository with the one defect its name says, as the
seeded fuzzing of ``validation/fuzz_readers.py`` found it (each class reproduced by hand):

* ``tests/data/glab/bad/``: from ``synt0140_egnos123_v6.glab.gz`` (gLAB 6 output of the
  synthetic EGNOS day, see that folder's PROVENANCE.md), its first 400 lines;
* ``tests/data/rtklib-pos/bad/``: from ``good-uslo-head.pos`` (real RTKLIB-MOPS output);
* ``tests/data/ubx/bad/``: from ``pvt_pl_timegps.ubx`` (pyubx2-encoded, see PROVENANCE.md);
* ``tests/data/table/bad/``: an epoch table of ``overbound simulate`` (seed 1, 2 hours).

The expected outcome of each file is in ``tests/io/test_bad_corpus.py``.
"""

from __future__ import annotations

import gzip
import io
import sys
from pathlib import Path

DATA = Path(__file__).parent
#: gzip with a fixed mtime: the same bytes on every run.
_MTIME = 0


def gz(data: bytes) -> bytes:
    buf = io.BytesIO()
    with gzip.GzipFile(fileobj=buf, mode="wb", mtime=_MTIME) as f:
        f.write(data)
    return buf.getvalue()


def put(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)


def glab() -> None:
    lines = (
        gzip.open(DATA / "glab" / "synt0140_egnos123_v6.glab.gz", "rt").read().splitlines(keepends=True)[:400]
    )
    bad = DATA / "glab" / "bad"
    info = next(i for i, ln in enumerate(lines) if "Not enough satellites" in ln)
    changed = list(lines)
    changed[info] = changed[info].replace(" 014 ", " 0x4 ", 1)  # one character of the day of year
    put(bad / "info-line-one-char-changed.glab", "".join(changed).encode())
    sbasout = [i for i, ln in enumerate(lines) if ln.startswith("SBASOUT")][3]
    nan = list(lines)
    sod = nan[sbasout].split()[3]
    nan[sbasout] = nan[sbasout].replace(f" {sod} ", " NaN ".rjust(len(sod) + 2), 1)
    put(bad / "seconds-of-day-nan.glab", "".join(nan).encode())
    prefix = list(lines)
    prefix[sbasout + 2] = "SBASOUY" + prefix[sbasout + 2][7:]  # the line type itself hit
    prefix[info + 2] = "INFP" + prefix[info + 2][4:]
    put(bad / "line-type-one-char-changed.glab", "".join(prefix).encode())
    packed = gz("".join(lines).encode())
    put(bad / "gzip-truncated.glab.gz", packed[: len(packed) // 2])
    flipped = bytearray(packed)
    flipped[-6] ^= 0xFF  # inside the CRC-32 of the trailer
    put(bad / "gzip-crc-mismatch.glab.gz", bytes(flipped))


def rtklib() -> None:
    text = (DATA / "rtklib-pos" / "good-uslo-head.pos").read_bytes()
    bad = DATA / "rtklib-pos" / "bad"
    put(bad / "gzip-header-only.pos.gz", gz(text)[:10])
    lines = text.decode().splitlines(keepends=True)
    data = [i for i, ln in enumerate(lines) if not ln.startswith("%")]
    mid = list(lines)
    mid[data[3]] = mid[data[3]].replace("2006/", "0000/", 1)
    put(bad / "year-0000-mid-file.pos", "".join(mid).encode())


def ubx() -> None:
    raw = (DATA / "ubx" / "pvt_pl_timegps.ubx").read_bytes()
    packed = gz(raw)
    put(DATA / "ubx" / "bad" / "gzip-truncated.ubx.gz", packed[: len(packed) - 40])


def table() -> None:
    sys.path.insert(0, str(DATA.parents[1] / "src"))
    from overbound.simulate import SimulationConfig, simulate, write_simulation

    bad = DATA / "table" / "bad"
    bad.mkdir(parents=True, exist_ok=True)
    good = bad / "_good.parquet"
    write_simulation(simulate(SimulationConfig(days=2 / 24, seed=1)), good)
    data = good.read_bytes()
    good.unlink()
    flipped = bytearray(data)
    flipped[4] ^= 0x10  # one bit of the first page header, just after the magic
    put(bad / "parquet-page-header-bit-flipped.parquet", bytes(flipped))
    key = data.rfind(b'"overbound_version"')
    meta = bytearray(data)
    meta[key] = ord("0")  # the provenance JSON loses a quote: the footer still parses
    put(bad / "parquet-provenance-not-json.parquet", bytes(meta))
    put(bad / "parquet-cut-in-half.parquet", data[: len(data) // 2])
    # a time whose bits were hit: beyond any calendar (polars panicked formatting it)
    import polars as pl

    frame = pl.read_parquet(data)[:20]
    us = frame["time"].cast(pl.Datetime("us")).to_physical().to_list()
    us[7] = 2**63 - 12345
    frame = frame.with_columns(pl.Series("time", us, dtype=pl.Int64).cast(pl.Datetime("us")))
    out = io.BytesIO()
    frame.write_parquet(out)
    put(bad / "parquet-time-beyond-calendar.parquet", out.getvalue())
    csv = b"time,station,hpe,vpe,hpl,vpl\n" + b"".join(
        f"2024-01-07T00:00:{s:02d},SIM,1.0,1.5,10.0,15.0\n".encode() for s in range(40)
    )
    put(bad / "csv-gzip-truncated.csv.gz", gz(csv)[:-12])
    put(bad / "csv-year-0000-mid-file.csv", csv.replace(b"2024-01-07T00:00:20", b"0000-01-07T00:00:20"))


if __name__ == "__main__":
    glab()
    rtklib()
    ubx()
    table()
