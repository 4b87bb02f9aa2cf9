"""Protection levels without truth (issue 16): the eight G1000 flights analysed with no option.

The availabilities are recomputed here from the reader's table with numpy (PL below the alert limit,
the counting's rule, over every epoch of the flight, a no-solution epoch unavailable), independently
of the counting code the analysis reuses.
"""

from __future__ import annotations

import json
from html import escape as html_escape
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from click.testing import CliRunner

from overbound.analysis import analyze
from overbound.cli import main
from overbound.io.open import expand_archives, read
from overbound.io.schema import InputError
from overbound.methods.protection_levels import NEEDS_ERRORS
from overbound.services import resolve_services

DATA = Path(__file__).resolve().parent / "data" / "g1000"
FILES = [*sorted(DATA.glob("*.csv.gz")), DATA / "ProximityTestFlights.zip"]


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[dict, str, Path]:
    out = tmp_path_factory.mktemp("a") / "out"
    res = CliRunner().invoke(main, ["analyze", *map(str, FILES), "-o", str(out)])
    assert res.exit_code == 0, res.output
    return json.loads((out / "summary.json").read_text()), (out / "report.html").read_text(), out


@pytest.fixture(scope="module")
def tables() -> dict[str, pl.DataFrame]:
    out = {}
    for src in expand_archives(FILES):
        t, _ = read(src)
        out[t["station"][0]] = t
    return out


def test_eight_flights_read_with_no_option(run, tables):
    doc, _, out = run
    assert doc["schema"] == "overbound.pl-summary/1"
    assert sorted(doc["stations"]) == sorted(tables) and len(tables) == 8
    assert [r["format"] for r in doc["inputs"]] == ["g1000"] * 8
    for r in doc["inputs"]:  # kept + rejected = read, for every input
        assert r["rows_kept"] + r["n_rejected"] == r["rows_read"] and r["truth"] is False
    assert doc["epochs"]["total"] == sum(t.height for t in tables.values())
    assert doc["epochs"]["rejected"] == sum(r["n_rejected"] for r in doc["inputs"])
    assert doc["not_computed"]["needs_errors"] == list(NEEDS_ERRORS)
    assert doc["warnings"] and "no truth" in doc["warnings"][0]
    # the error-based methods are skipped, not run on NaN errors
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "report.html",
        "summary.json",
    ]


@pytest.mark.parametrize("service", ["NPA", "LPV", "LPV-200"])
def test_availability_per_flight_is_the_share_of_epochs_within_the_limits(run, tables, service):
    doc, _, _ = run
    s = next(x for x in resolve_services([service]))
    for name, t in tables.items():
        hpl, vpl = t["hpl"].to_numpy(), t["vpl"].to_numpy()
        with np.errstate(invalid="ignore"):
            ok = (
                (hpl < s.hal) & (True if s.val is None else vpl < s.val) & np.isfinite(hpl) & np.isfinite(vpl)
            )
        got = doc["stations"][name]["services"][service]["availability"]
        assert got["combined"] == pytest.approx(ok.mean(), abs=1e-12), name
        assert got["horizontal"] == pytest.approx(((hpl < s.hal) & np.isfinite(vpl)).mean(), abs=1e-12)
    n = np.array([doc["stations"][k]["epochs"] for k in tables])
    a = np.array([doc["stations"][k]["services"][service]["availability"]["combined"] for k in tables])
    assert doc["services"][service]["availability"]["combined"] == pytest.approx((n * a).sum() / n.sum())


def test_pl_distributions_and_spans(run, tables):
    doc, _, _ = run
    for name, t in tables.items():
        st = doc["stations"][name]
        hpl = t["hpl"].to_numpy()
        hpl = hpl[np.isfinite(hpl)]
        assert st["with_pl"] == hpl.size
        assert st["hpl"]["p95"] == pytest.approx(np.quantile(hpl, 0.95)) and st["hpl"]["max"] == hpl.max()
        assert st["time"]["start_gpst"] == t["time"].min().isoformat()
        # UTC is GPS time minus the leap seconds: 15 s in 2011, 16 in 2014, 18 from 2017
        leap = {"2011": 15, "2014": 16, "2018": 18, "2024": 18}[st["time"]["start_gpst"][:4]]
        gps = np.datetime64(st["time"]["start_gpst"])
        assert np.datetime64(st["time"]["start_utc"].rstrip("Z")) == gps - np.timedelta64(leap, "s")
        assert st["within_logged_hal"] == 1.0  # no HPL above the HAL in force (PROVENANCE)


def test_report_says_first_what_needs_errors_and_draws_every_flight(run, tables):
    _, html, _ = run
    first = html[: html.index('id="services"')]
    assert "Without truth" in first and 'class="warning"' in first
    for item in NEEDS_ERRORS:
        assert html_escape(item) in first
    for name in tables:
        assert f'data-figure="pl-series-{name}"' in html
    assert 'data-figure="pl-distribution"' in html


def test_same_bytes_from_another_folder(run, tmp_path):
    doc, _, _ = run
    out = tmp_path / "elsewhere" / "out"
    res = CliRunner().invoke(main, ["analyze", *map(str, FILES), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert json.loads((out / "summary.json").read_text()) == doc


def test_inputs_with_and_without_truth_are_refused_together(tmp_path):
    csv = tmp_path / "errors.csv"
    csv.write_text("time,station,hpe,vpe,hpl,vpl\n2011-07-01T18:20:00,X,1.0,1.0,20.0,30.0\n")
    with pytest.raises(InputError, match="analyse them separately"):
        analyze([csv, FILES[0]])


@pytest.mark.parametrize("command", ["convert", "ingest"])
def test_no_truth_is_not_written_as_an_epoch_table(tmp_path, command):
    """Its NaN errors would read back as no-solution epochs: refused, naming the file, nothing written."""
    out = tmp_path / ("x.parquet" if command == "convert" else "ds")
    args = (
        [command, str(FILES[0]), "-o", str(out)]
        if command == "convert"
        else [command, str(out), str(FILES[0])]
    )
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 2
    assert FILES[0].name in res.output and "no truth" in res.output
    assert not list(tmp_path.rglob("*.parquet"))


def test_epochs_and_single_methods_are_refused_without_truth(tmp_path):
    res = CliRunner().invoke(main, ["analyze", str(FILES[0]), "-o", str(tmp_path / "o"), "--epochs",
                                    str(tmp_path / "e.parquet")])  # fmt: skip
    assert res.exit_code == 2 and "no truth" in res.output and not (tmp_path / "e.parquet").exists()
    for command in ("confidence", "evt", "parametric"):
        res = CliRunner().invoke(main, [command, str(FILES[0]), "-o", str(tmp_path / command)])
        assert res.exit_code == 2, res.output
        assert FILES[0].name in res.output and "this method needs them" in res.output


def test_zip_folders_and_macos_entries_are_not_members(tmp_path):
    import zipfile

    z = tmp_path / "flights.zip"
    with zipfile.ZipFile(z, "w") as out, zipfile.ZipFile(FILES[-1]) as src:
        out.writestr("logs/", b"")
        out.writestr("__MACOSX/logs/._flight_1934579.csv", b"\x00\x05\x16\x07")
        out.writestr("logs/.DS_Store", b"junk")
        out.writestr("logs/flight_1934579.csv", src.read("flight_1934579.csv"))
    members = expand_archives([z])
    assert [m.name for m in members] == [f"{z}/logs/flight_1934579.csv"]
