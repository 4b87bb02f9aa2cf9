"""``overbound sbas`` and overbound.sbas.run.process: wiring, counts, errors, the real u-blox EGNOS cut."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np
import polars as pl
import pymap3d
import pytest
from click.testing import CliRunner

from overbound.cli import main
from overbound.io.ems import read_ems
from overbound.io.open import read
from overbound.io.rinex_nav import read_rinex_nav
from overbound.io.rinex_obs import read_rinex_obs
from overbound.io.table import read_epochs_metadata
from overbound.sbas.engine import run_sbas
from overbound.sbas.messages import decode
from overbound.sbas.run import process

DATA = Path(__file__).resolve().parents[1] / "data" / "sbas"
FIX = DATA / "engine"
OBS = FIX / "SYNT0140_h02-04.19o.gz"
NAV = FIX / "brdc0140.19n.gz"
EMS = [DATA / "ems" / "h02.ems.gz", FIX / "h03.ems.gz", FIX / "h04.ems.gz"]
SDK = DATA / "ublox" / "egnos_sdk_20121025_1202-1217.txt.gz"


def test_process_is_run_sbas_on_the_files():
    run = process(OBS, NAV, EMS)
    obs, _ = read_rinex_obs(OBS)
    nav, _ = read_rinex_nav(NAV)
    frames, _ = read_ems(EMS)
    direct = run_sbas(obs.table, nav.table, decode(frames), obs.header.approx_position, station="SYNT")
    assert run.reference_source == "rinex header"
    assert run.epochs.drop("geo").equals(direct.epochs)
    assert set(run.epochs["geo"].to_list()) == {123}


def test_every_engine_option_reaches_the_engine_and_the_record():
    """``relativity="rv"`` was dropped when the options were rebuilt per GEO (issue 13): it now gives
    the engine's rv results, and the metadata records every option."""
    from overbound.sbas.engine import SbasOptions

    opt = SbasOptions(relativity="rv")
    run = process(OBS, NAV, EMS, options=opt)
    obs, _ = read_rinex_obs(OBS)
    nav, _ = read_rinex_nav(NAV)
    frames, _ = read_ems(EMS)
    ref = obs.header.approx_position
    direct = run_sbas(obs.table, nav.table, decode(frames), ref, station="SYNT", options=opt)
    kepler = process(OBS, NAV, EMS)
    assert run.epochs.drop("geo").equals(direct.epochs)
    assert not run.epochs["vpe"].equals(kepler.epochs["vpe"])  # the term changes the ranges (cm)
    assert run.metadata()["sbas"]["options"]["relativity"] == "rv"
    assert kepler.metadata()["sbas"]["options"]["relativity"] == "kepler"


def test_duplicate_observations_are_dropped_and_counted(tmp_path):
    """The same file given twice (or overlapping files): the first record is kept, the rest counted."""
    once = process(OBS, NAV, EMS)
    twice = process([OBS, OBS], NAV, EMS)
    assert twice.epochs.equals(once.epochs)
    assert twice.satellites.equals(once.satellites)
    assert once.counts["duplicate_observation_rows"] == 0
    assert twice.counts["duplicate_observation_rows"] == once.counts["observation_rows"]
    res = _cli(tmp_path, "--obs", OBS, "--obs", OBS, "--nav", NAV, "--sbas", *EMS)
    assert res.exit_code == 0, res.output
    assert f"duplicate observation records dropped: {once.counts['observation_rows']}" in res.output


def _cli(tmp_path, *args):
    return CliRunner().invoke(main, ["sbas", *map(str, args), "-o", str(tmp_path / "e.parquet")])


def test_cli_writes_both_tables_and_counts(tmp_path):
    # one EMS file damaged: a truncated line and a flipped bit (bad CRC)
    lines = gzip.decompress(EMS[0].read_bytes()).decode().splitlines(keepends=True)
    lines[10] = lines[10][:40] + "\n"
    text = lines[20].rstrip()
    flip = f"{int(text[-30], 16) ^ 1:X}"  # a data bit inside the 64 hex digits
    lines[20] = text[:-30] + flip + text[-29:] + "\n"
    bad = tmp_path / "h02.ems"
    bad.write_text("".join(lines))
    res = _cli(tmp_path, "--obs", OBS, "--nav", NAV, "--sbas", bad, *EMS[1:])
    assert res.exit_code == 0, res.output
    assert "bad CRC 1" in res.output and "sbas:line_length 1" in res.output
    meta = read_epochs_metadata(tmp_path / "e.parquet")
    c = meta["extra"]["sbas"]["counts"]
    assert c["bad_crc"] == 1 and c["rejected"] == {"sbas:line_length": 1}
    sats = pl.read_parquet(tmp_path / "e.sats.parquet")
    epochs, _ = read(tmp_path / "e.parquet")  # what `overbound analyze` reads
    assert sats["time"].n_unique() == epochs.height == 360
    assert {"reason", "sigma_flt", "sigma_uire", "residual"} <= set(sats.columns)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--obs", OBS, "--sbas", *EMS], "no GPS broadcast ephemerides"),
        (["--obs", OBS, "--nav", NAV], "no SBAS messages"),
        (["--obs", OBS, "--nav", NAV, "--sbas", DATA / "ems" / "h00.ems.gz"], "do not overlap"),
        (["--obs", NAV, "--nav", NAV, "--sbas", *EMS], "navigation file given as --obs"),
        (["--obs", OBS, "--nav", NAV, "--sbas", FIX / "PROVENANCE.md"], "unknown format for --sbas"),
        (
            ["--obs", DATA.parent / "novatel" / "bestpos_raimstatus.bin.gz", "--nav", NAV, "--sbas", *EMS],
            "convert them with RTKLIB's convbin",
        ),  # a receiver's own binary log: the route is said
        (["--obs", OBS, "--nav", NAV, "--sbas", *EMS, "--geo", "126"], "no messages of GEO 126"),
        (["--obs", SDK], "no reference position"),
    ],
)
def test_cli_errors_are_one_line(tmp_path, args, message):
    res = _cli(tmp_path, *args)
    assert res.exit_code == 2
    assert message in res.output and len(res.output.strip().splitlines()) == 1


def test_ublox_egnos_hour_cut_end_to_end(tmp_path):
    """Plausible PLs on the real u-blox EGNOS cut (12:02-12:17 GPST, PRN 120), errors about the mean.

    Criterion: after the start-up a DO-229 receiver in central Europe with 9-12 satellites gets
    HPL of roughly 5-20 m and VPL of 8-30 m (EGNOS LPV availability maps of the time give VPL
    around 10-20 m); every epoch bounded (HPE < HPL, |VPE| < VPL; no surveyed truth, so only the
    scatter about the mean is tested); no solution before the mask, fast corrections and iono
    grid are in (at least 3 min at 2/3 of the messages); mean errors zero by construction.
    """
    res = CliRunner().invoke(main, ["sbas", "--obs", str(SDK), "--reference", "mean", "-o",
                                    str(tmp_path / "u.parquet")])  # fmt: skip
    assert res.exit_code == 0, res.output
    e = pl.read_parquet(tmp_path / "u.parquet")
    sol = e.filter(pl.col("vpl").is_finite())
    assert e.height == 283 and sol.height > 150
    assert (sol["time"].min() - e["time"].min()).total_seconds() > 180
    assert 5 < sol["hpl"].median() < 20 and 8 < sol["vpl"].median() < 30
    assert (sol["hpe"] < sol["hpl"]).all() and (sol["vpe"].abs() < sol["vpl"]).all()
    assert sol["nsv"].min() >= 4
    assert max(abs(sol[c].mean()) for c in ("east", "north", "vpe")) < 0.01
    ref = json.loads(json.dumps(read_epochs_metadata(tmp_path / "u.parquet")["extra"]["sbas"]))
    assert ref["reference_source"] == "mean"
    x = ref["reference_ecef"]
    e_, n_, _ = pymap3d.ecef2enu(*x, *pymap3d.ecef2geodetic(4245483.5, 701697.9, 4692764.0))
    assert np.hypot(e_, n_) < 5.0  # the data set author's SPP, horizontally
