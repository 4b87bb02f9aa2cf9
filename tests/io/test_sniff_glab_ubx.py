"""The sniffer recognises the gLAB and UBX fixtures, from paths and from streams."""

from __future__ import annotations

import gzip
import io
from pathlib import Path

import pytest

from overbound.io.open import sniff
from overbound.io.schema import InputError

DATA = Path(__file__).resolve().parents[1] / "data"
GLAB = sorted(
    p
    for p in (DATA / "glab").rglob("*")
    if p.is_file()
    and p.name not in ("PROVENANCE.md", "empty.glab")
    and not p.name.endswith(".summary.txt")
    and p.parent.name != "bad"  # the bad corpus: tests/io/test_bad_corpus.py
)
UBX = sorted((DATA / "ubx").glob("*.ubx"))


def test_fixture_lists_are_not_empty():
    assert len(GLAB) == 12 and len(UBX) == 9


@pytest.mark.parametrize("path", GLAB, ids=lambda p: p.name)
def test_glab_files_sniff_as_glab(path):
    assert sniff(path) == "glab"


@pytest.mark.parametrize("path", UBX, ids=lambda p: p.name)
def test_ubx_files_sniff_as_ubx(path):
    assert sniff(path) == "ubx"
    assert sniff(io.BytesIO(path.read_bytes())) == "ubx"
    assert sniff(io.BytesIO(gzip.compress(path.read_bytes()))) == "ubx"


def test_glab_streams_sniff_as_glab():
    raw = (DATA / "glab" / "synt0140_egnos123_v6.glab.gz").read_bytes()
    assert sniff(io.BytesIO(raw)) == "glab"
    assert sniff(io.StringIO(gzip.decompress(raw).decode())) == "glab"


def test_glab_sbasout_only_sniffs_as_glab():
    """Output of ``-print:none -print:sbasout`` has no INFO line at all."""
    with gzip.open(DATA / "glab" / "synt0140_egnos123_v6.glab.gz", "rt") as f:
        text = "".join(ln for ln in f if ln.startswith("SBASOUT"))
    assert sniff(io.StringIO(text)) == "glab"


def test_empty_glab_is_unknown():
    with pytest.raises(InputError, match="unknown format"):
        sniff(DATA / "glab" / "edge" / "empty.glab")
