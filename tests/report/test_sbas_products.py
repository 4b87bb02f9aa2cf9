"""``overbound sbas --all-subsets / --sp3``: the products of overbound.report.sbas_products against direct
calls."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from click.testing import CliRunner

from overbound.cli import main
from overbound.io.rinex_nav import read_rinex_nav
from overbound.io.sp3 import read_sp3
from overbound.io.table import read_epochs_metadata
from overbound.report.sbas_products import (
    SUBSETS_SCHEMA,
    range_product,
    subsets_dict,
    subsets_product,
)
from overbound.sbas.engine import SbasOptions
from overbound.sbas.range_domain import RANGE_COLUMNS, range_errors
from overbound.sbas.run import SbasRun, process
from overbound.sbas.subsets import all_subsets

DATA = Path(__file__).resolve().parents[1] / "data" / "sbas"
FIX = DATA / "engine"
OBS = FIX / "SYNT0140_h02-04.19o.gz"
NAV = FIX / "brdc0140.19n.gz"
EMS = [DATA / "ems" / "h02.ems.gz", FIX / "h03.ems.gz", FIX / "h04.ems.gz"]
SP3 = DATA / "range_domain" / "igs20361_h00-07.sp3.gz"
SP3_2020 = Path(__file__).resolve().parents[1] / "data" / "rinex" / "GRG0MGXFIN_cut.sp3.gz"
SP3_SIX = Path(__file__).resolve().parents[1] / "data" / "rinex" / "igs20361_cut.sp3.gz"  # 6 satellites
ARGS = ["--obs", OBS, "--nav", NAV, "--sbas", *EMS]
PRODUCTS = ("e.subsets.json", "e.subsets.png", "e.range.parquet")


def _cli(out: Path, *args):
    return CliRunner().invoke(main, ["sbas", *map(str, args), "-o", str(out / "e.parquet")])


@pytest.fixture(scope="module")
def cli_out(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("products")
    res = _cli(out, *ARGS, "--all-subsets", "--sp3", SP3)
    assert res.exit_code == 0, res.output
    assert "e.subsets.json: " in res.output and "e.range.parquet: " in res.output  # the summary lines
    return out


@functools.cache
def _run() -> SbasRun:
    return process(OBS, NAV, EMS)


def _assert_service_is(s: dict, direct, hal: float, val: float) -> None:
    """One service of the JSON against a direct :func:`all_subsets` result."""
    assert s["alert_limits"] == {"horizontal": hal, "vertical": val}
    for axis in ("horizontal", "vertical"):
        assert s[axis]["counts"] == direct.counts[axis].to_dict()
        h, d = s[axis]["histogram"], getattr(direct, axis)
        dense = np.zeros_like(d.counts)
        dense[h["pe_bin"], h["pl_bin"]] = h["count"]
        np.testing.assert_array_equal(dense, d.counts)
        np.testing.assert_allclose(h["edges"], d.edges, rtol=1e-11)
        assert h["clipped"] == d.clipped


def test_subsets_json_counts_are_all_subsets_of_the_written_satellites(cli_out):
    doc = json.loads((cli_out / "e.subsets.json").read_text())
    sats = pl.read_parquet(cli_out / "e.sats.parquet")
    direct = all_subsets(sats, mode="PA", horizontal_al=40.0, vertical_al=50.0)
    assert doc["schema"] == SUBSETS_SCHEMA and doc["mode"] == "PA" and list(doc["services"]) == ["LPV"]
    _assert_service_is(doc["services"]["LPV"], direct, 40.0, 50.0)  # LPV: the default of PA
    assert doc["n_epochs"] == direct.n_epochs == 297
    assert doc["n_subsets"] == direct.n_subsets and doc["n_singular"] == direct.n_singular
    assert doc["by_size"] == {str(k): v for k, v in direct.by_size.items()}
    assert doc["worst_ratio"] == pytest.approx(direct.worst_ratio, rel=1e-11)


def test_several_services_share_passes_of_equal_alert_limits():
    run = _run()
    product = subsets_product(run, ["LPV", "APV-I", "LPV-200"], max_size=5)
    assert product.results["LPV"] is product.results["APV-I"]  # 40/50 m both: one pass
    doc = subsets_dict(product, run)
    assert list(doc["services"]) == ["LPV", "APV-I", "LPV-200"]
    direct = all_subsets(run.satellites, horizontal_al=40.0, vertical_al=35.0, max_size=5)
    _assert_service_is(doc["services"]["LPV-200"], direct, 40.0, 35.0)
    # the alert limit moves subsets between regions: LPV-200's VAL of 35 m makes more unavailable
    lpv, lpv200 = (doc["services"][n]["vertical"]["counts"] for n in ("LPV", "LPV-200"))
    assert lpv200["unavailable"] > lpv["unavailable"]


def test_histogram_cells_sum_to_the_non_singular_subsets():
    # one epoch of the fixture plus a copy of one of its satellites under another PRN: every subset
    # holding both has a repeated geometry row, so its normal matrix is singular (left out)
    sats = _run().satellites
    used = sats.filter(pl.col("used"))
    t = used["time"].unique().sort()[100]
    epoch = used.filter(pl.col("time") == t).head(6)
    twin = epoch.head(1).with_columns(pl.lit(99, epoch.schema["prn"]).alias("prn"))
    run = SbasRun(pl.DataFrame(), pl.concat([epoch, twin]), _run().reference_ecef, "given", "X",
                  SbasOptions(), ())  # fmt: skip
    doc = subsets_dict(subsets_product(run), run)
    assert doc["n_singular"] > 0
    for axis in ("horizontal", "vertical"):
        cells = doc["services"]["LPV"][axis]["histogram"]["count"]
        assert sum(cells) == doc["n_subsets"] == sum(doc["by_size"].values()) - doc["n_singular"]
        assert sum(doc["services"]["LPV"][axis]["counts"].values()) == doc["n_subsets"]


def test_npa_mode_defaults_to_the_npa_service_without_vertical():
    run = process(OBS, NAV, EMS, options=SbasOptions(mode="NPA"))
    product = subsets_product(run, max_size=5)
    assert product.results["NPA"].vertical is None and set(product.results["NPA"].counts) == {"horizontal"}
    doc = subsets_dict(product, run)
    assert list(doc["services"]) == ["NPA"] and doc["services"]["NPA"]["vertical"] is None
    direct = all_subsets(run.satellites, mode="NPA", horizontal_al=556.0, vertical_al=556.0, max_size=5)
    assert doc["services"]["NPA"]["horizontal"]["counts"] == direct.counts["horizontal"].to_dict()
    assert set(doc["by_size"]) == {"4", "5"}


def test_range_parquet_is_range_errors_of_the_run(cli_out):
    table = pl.read_parquet(cli_out / "e.range.parquet")
    run = _run()
    nav, _ = read_rinex_nav(NAV)
    sp3, report = read_sp3(SP3)
    direct = range_errors(run.satellites, sp3, nav.table, run.reference_ecef)
    assert table.columns == list(RANGE_COLUMNS)
    assert table.equals(direct)
    used = pl.read_parquet(cli_out / "e.sats.parquet")["used"].sum()
    assert table.height == used  # this SP3 covers every used satellite
    assert np.isfinite(table["normalised"].to_numpy()).all()
    meta = read_epochs_metadata(cli_out / "e.range.parquet")
    r = meta["extra"]["range"]
    assert r["sp3_files"] == [str(SP3)] and r["counts"]["rows"] == table.height
    assert r["counts"]["rows_without_sp3"] == 0 and r["counts"]["epochs"] == table["time"].n_unique()
    assert meta["report"]["rows_read"] == report.rows_read and meta["extra"]["sbas"]["reference_source"]


def test_partial_sp3_counts_the_ranges_it_lacks():
    p = range_product(_run(), SP3_SIX)
    c = p.counts
    assert 0 < c["rows"] < c["used_rows"] and c["rows"] + c["rows_without_sp3"] == c["used_rows"]
    have = {int(s[1:]) for s in read_sp3(SP3_SIX)[0].sats if s.startswith("G")}
    assert set(p.table["prn"].to_list()) <= have and not have & set(c["prns_without_sp3"])


def test_outputs_are_byte_identical_on_a_second_run(cli_out, tmp_path):
    res = _cli(tmp_path, *ARGS, "--all-subsets", "--sp3", SP3)
    assert res.exit_code == 0, res.output
    for name in PRODUCTS:
        assert (tmp_path / name).read_bytes() == (cli_out / name).read_bytes(), name
    assert b"tIME" not in (tmp_path / "e.subsets.png").read_bytes()  # no PNG time chunk


@pytest.mark.parametrize(
    ("args", "message", "one_line"),
    [
        (
            ["--sp3", SP3_2020],
            "the SP3 orbits (2020-06-25 00:00:00 - 2020-06-25 02:45:00 GPST) do not cover",
            True,
        ),
        (["--all-subsets", "--service", "FOO"], "unknown service 'FOO'", True),
        (["--service", "LPV"], "give --all-subsets too", False),  # a usage error: click adds its usage lines
    ],
)
def test_bad_products_are_clear_errors_and_write_nothing(tmp_path, args, message, one_line):
    res = _cli(tmp_path, *ARGS, *args)
    assert res.exit_code == 2
    assert message in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1 or not one_line
    assert not list(tmp_path.iterdir())
