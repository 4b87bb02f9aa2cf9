"""The readers of positions without a reference: the protection levels alone, nothing else changed.

Issue 16: when no error can be formed (no surveyed position, no truth trajectory), the log is still
read; its errors are unknown (NaN, ``truth`` false) and ``overbound analyze`` gives the PL-only report.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from overbound.cli import main
from overbound.io.geodesy import MEAN_POSITION
from overbound.io.open import read

DATA = Path(__file__).resolve().parents[1] / "data"
LOGS = {
    "ubx": DATA / "ubx" / "pvt_pl_timegps.ubx",
    "sbf": DATA / "sbf" / "log_0000.sbf.gz",
    "novatel": DATA / "novatel" / "bestpos_raimstatus.bin.gz",
    "nmea": DATA / "nmea" / "gfa_sbas.nmea.gz",
    "sbp": DATA / "sbp" / "pl_sbas.sbp.gz",
}


@pytest.mark.parametrize("fmt", sorted(LOGS))
def test_without_a_reference_the_same_epochs_and_pls_and_no_errors(fmt):
    bare, r0 = read(LOGS[fmt])
    ref, r1 = read(LOGS[fmt], reference=MEAN_POSITION)
    assert r0.format == r1.format == fmt and not r0.truth and r1.truth
    assert (r0.rows_read, r0.rows_kept, r0.rejected) == (r1.rows_read, r1.rows_kept, r1.rejected)
    assert r0.rows_kept + sum(r0.rejected.values()) == r0.rows_read
    assert bare["time"].to_list() == ref["time"].to_list()
    assert np.isnan(bare["hpe"].to_numpy()).all() and np.isnan(bare["vpe"].to_numpy()).all()
    with_pl = np.isfinite(bare["hpl"].to_numpy())
    assert with_pl.any()
    # the epochs the reference version solves have the same protection levels without it
    solved = np.isfinite(ref["hpe"].to_numpy())
    assert np.array_equal(bare["hpl"].to_numpy()[solved], ref["hpl"].to_numpy()[solved])
    assert any("no reference: errors unknown" in n for n in r0.notes)


@pytest.mark.parametrize("fmt", ["sbf", "nmea"])
def test_analyze_without_a_reference_is_the_pl_only_report(fmt, tmp_path):
    run = CliRunner().invoke(main, ["analyze", str(LOGS[fmt]), "-o", str(tmp_path / "out")])
    assert run.exit_code == 0, run.output
    assert "Protection levels only, no truth" in run.output
    assert (tmp_path / "out" / "summary.json").read_text().count('"overbound.pl-summary/1"') == 1
