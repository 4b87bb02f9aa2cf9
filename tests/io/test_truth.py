"""Truth trajectory (``--truth``, issue 16): interpolation against analytic trajectories, gaps and the span,
the file variants agreeing, a static truth equal to ``--reference``, and the CLI end to end."""

from __future__ import annotations

import datetime as dt
import io
import json
from importlib.resources import files
from pathlib import Path

import numpy as np
import polars as pl
import pytest
import wgs84
from click.testing import CliRunner

from overbound.cli import main
from overbound.io.geodesy import Reference
from overbound.io.open import read
from overbound.io.schema import InputError
from overbound.io.truth import Truth, read_truth

DATA = Path(__file__).parents[1] / "data" / "truth"
ROVER = DATA / "rover.pos.gz"
TRUTH_FILES = (
    "rover-truth.pos.gz",
    "rover-truth-xyz-utc.pos.gz",
    "rover-truth.csv.gz",
    "rover-truth-ecef.csv.gz",
)
USLO = Path(str(files("overbound") / "data" / "uslo-2006-361-waas.pos.gz"))
USLO_REF = Reference(35.311803, -120.661092, 134.6419)
# The construction of tests/data/truth/make_fixtures.py: every rover error is ERROR_ENU, the trajectory
# a circle of radius R at rate OMEGA; rover epochs 0.5 ... 299.5 s, truth samples 10 ... 290 s without
# 101-104, Q = 2 at 200-209; the rover has no solution at 102.5 s.
ERROR_ENU = (1.0, -2.0, 3.0)
R, OMEGA = 500.0, 0.04
US = 1_000_000


def _circle(t_s: np.ndarray) -> np.ndarray:
    """ECEF positions of a horizontal circle about USLO (analytic in ECEF: a plane circle)."""
    e, n = R * np.cos(OMEGA * t_s), R * np.sin(OMEGA * t_s)
    return _enu_to_ecef(e, n, np.zeros_like(e))


def _enu_to_ecef(e, n, u) -> np.ndarray:
    # the local frame of USLO by the test's own WGS-84 (tests/reference/wgs84.py), not overbound's
    lat, lon = np.radians(USLO_REF.lat_deg), np.radians(USLO_REF.lon_deg)
    x0 = np.array(wgs84.ecef(USLO_REF.lat_deg, USLO_REF.lon_deg, USLO_REF.height_m))
    rot = np.array(
        [
            [-np.sin(lon), -np.sin(lat) * np.cos(lon), np.cos(lat) * np.cos(lon)],
            [np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat) * np.sin(lon)],
            [0.0, np.cos(lat), np.sin(lat)],
        ]
    )
    return x0 + (rot @ np.vstack([e, n, u])).T


def _truth(t_s: np.ndarray, xyz: np.ndarray, method: str, max_gap_s: float = 1.5) -> Truth:
    return Truth("analytic", "test", (np.asarray(t_s) * US).astype(np.int64), xyz, max_gap_s, method)


@pytest.mark.parametrize("method", ["linear", "cubic"])
def test_straight_line_is_interpolated_exactly(method):
    t = np.arange(0.0, 20.0)
    v = np.array([30.0, -12.0, 2.5])  # m/s
    x0 = np.array(wgs84.ecef(45.0, 7.0, 300.0))
    truth = _truth(t, x0 + t[:, None] * v, method)
    at = np.array([0.0, 0.25, 3.5, 7.0, 18.9, 19.0])
    xyz, status = truth.at((at * US).astype(np.int64))
    assert list(status) == [""] * 6
    np.testing.assert_allclose(xyz, x0 + at[:, None] * v, rtol=0, atol=1e-6)


def test_circle_linear_error_is_the_sagitta_and_cubic_within_its_bound():
    h = 1.0
    t = np.arange(0.0, 60.0, h)
    mid = t[5:-5] + h / 2
    lin, _ = _truth(t, _circle(t), "linear").at((mid * US).astype(np.int64))
    cub, _ = _truth(t, _circle(t), "cubic").at((mid * US).astype(np.int64))
    exact = _circle(mid)
    sagitta = R * (1 - np.cos(OMEGA * h / 2))  # the chord's distance from the arc at its middle
    np.testing.assert_allclose(np.linalg.norm(lin - exact, axis=1), sagitta, rtol=1e-6)
    # the cubic spline's bound 5/384 h^4 max|x''''|, x'''' = R w^4 on a circle (Hall & Meyer 1976)
    assert np.linalg.norm(cub - exact, axis=1).max() <= 5 / 384 * h**4 * R * OMEGA**4 * 1.01
    assert sagitta > 0.09  # the linear error is not small at 1 Hz in a turn: why cubic is the default


def test_gaps_span_and_sample_times():
    t = np.array([0.0, 1.0, 2.0, 3.0, 8.0, 9.0, 10.0])  # a 5 s gap between 3 and 8
    truth = _truth(t, _circle(t), "cubic", max_gap_s=1.5)
    at = np.array([-0.5, 0.0, 2.5, 3.0, 5.0, 7.99, 8.0, 9.5, 10.0, 10.5])
    xyz, status = truth.at((at * US).astype(np.int64))
    expect = [
        "outside_truth_span",
        "",
        "",
        "",
        "no_truth_gap",
        "no_truth_gap",
        "",
        "",
        "",
        "outside_truth_span",
    ]
    assert list(status) == expect
    assert np.isnan(xyz[[0, 4, 5, 9]]).all()
    np.testing.assert_array_equal(xyz[[1, 3, 6, 8]], _circle(at[[1, 3, 6, 8]]))  # samples taken as they are
    assert truth.gaps() == 1
    wide = _truth(t, _circle(t), "cubic", max_gap_s=6.0)
    assert list(wide.at((at * US).astype(np.int64))[1]).count("no_truth_gap") == 0


@pytest.mark.parametrize("name", TRUTH_FILES)
def test_fixture_errors_and_counts(name):
    truth = read_truth(DATA / name)
    assert (truth.time_us.size, truth.gaps(), truth.max_gap_s) == (277, 1, 1.5)
    table, report = read(ROVER, reference=truth)
    assert report.rows_read == 300 and report.unaccounted == 0
    assert report.rejected == {"outside_truth_span": 20}  # 0.5-9.5 s and 290.5-299.5 s
    assert report.invalidated == {"no_truth_gap": 4}  # 100.5-104.5 s but 102.5 (no solution already)
    assert table.height == 280
    solved = table.filter(pl.col("hpe").is_finite())
    assert solved.height == 275
    for col, want in zip(("east", "north", "vpe"), ERROR_ENU, strict=True):
        np.testing.assert_allclose(solved[col].to_numpy(), want, atol=1e-3)  # files round to 0.1 mm
    np.testing.assert_allclose(solved["hpe"].to_numpy(), np.hypot(*ERROR_ENU[:2]), atol=1e-3)
    t = table["time"]
    assert str(t[0]) == "2006-12-27 01:00:10.500000" and str(t[-1]) == "2006-12-27 01:04:49.500000"
    gap = table.filter(
        pl.col("time").is_between(pl.datetime(2006, 12, 27, 1, 1, 40), pl.datetime(2006, 12, 27, 1, 1, 45))
    )
    assert gap.height == 5 and gap["hpl"].is_nan().all()  # no-solution epochs, PLs too


def test_llh_ecef_csv_and_utc_truths_agree():
    tables = [read(ROVER, reference=read_truth(DATA / name))[0] for name in TRUTH_FILES]
    for other in tables[1:]:
        assert other["time"].equals(tables[0]["time"])
        for col in ("east", "north", "vpe"):
            np.testing.assert_allclose(other[col].to_numpy(), tables[0][col].to_numpy(), atol=5e-4)


def test_linear_interpolation_in_the_turn_is_off_by_the_sagitta():
    table, _ = read(ROVER, reference=read_truth(DATA / "rover-truth.pos.gz", interpolation="linear"))
    solved = table.filter(pl.col("hpe").is_finite())
    t_s = (solved["time"] - dt.datetime(2006, 12, 27, 1, 0, 0)).dt.total_microseconds().to_numpy() / US
    sagitta = R * (1 - np.cos(OMEGA * 0.5))
    # the interpolated truth lies inside the circle: the error grows by the sagitta outward
    np.testing.assert_allclose(solved["east"].to_numpy(), 1.0 + sagitta * np.cos(OMEGA * t_s), atol=1e-3)
    np.testing.assert_allclose(solved["north"].to_numpy(), -2.0 + sagitta * np.sin(OMEGA * t_s), atol=1e-3)


def test_quality_filter_makes_gaps():
    truth = read_truth(DATA / "rover-truth.pos.gz", quality=(1,))
    assert truth.rejected == {"quality_not_kept": 10} and truth.gaps() == 2
    _, report = read(ROVER, reference=truth)
    assert report.invalidated == {"no_truth_gap": 4 + 11}  # and 199.5-209.5 s


@pytest.mark.parametrize("ecef", [False, True])
def test_static_truth_equals_the_reference(tmp_path, ecef):
    if ecef:
        x, y, z = wgs84.ecef(USLO_REF.lat_deg, USLO_REF.lon_deg, USLO_REF.height_m)
        text = f"gps_seconds,x,y,z\n851212800,{x!r},{y!r},{z!r}\n851299200,{x!r},{y!r},{z!r}\n"
    else:
        pos = f"{USLO_REF.lat_deg},{USLO_REF.lon_deg},{USLO_REF.height_m}"
        text = f"time,lat,lon,height\n2006-12-27 00:00:00,{pos}\n2006-12-28T00:00:00,{pos}\n"
    (tmp_path / "static.csv").write_text(text)
    fixed, _ = read(USLO, reference=USLO_REF)
    moving, report = read(USLO, reference=read_truth(tmp_path / "static.csv"))
    assert moving.height == fixed.height == 2865 and report.unaccounted == 0
    for col in ("hpe", "vpe", "east", "north"):
        np.testing.assert_allclose(moving[col].to_numpy(), fixed[col].to_numpy(), rtol=0, atol=1e-6)
    assert moving["hpl"].equals(fixed["hpl"])


def test_truth_file_errors(tmp_path):
    bad = tmp_path / "t.csv"
    bad.write_text("time,lat,lon\n2006-12-27T00:00:00,1,2\n")
    with pytest.raises(InputError, match=r"need time .* lat, lon, height"):
        read_truth(bad)
    bad.write_text("gps_seconds,x,y,z\n10,6378137,0,0\n9,6378137,0,0\n")
    with pytest.raises(InputError, match=r"t.csv:3: truth time goes backwards"):
        read_truth(bad)
    bad.write_text("gps_seconds,x,y,z\n10,6378137,0,0\n11,6378x37,0,0\n11,6378137,0,0\n12,6378137,0,0\n")
    truth = read_truth(bad)
    assert truth.rows_read == 4 and truth.rejected == {"malformed_line": 1} and truth.time_us.size == 3
    with pytest.raises(InputError, match="quality filter applies to RTKLIB"):
        read_truth(bad, quality=(1,))


def test_truth_needs_an_input_with_positions(tmp_path):
    errors = tmp_path / "errors.csv"
    errors.write_text("time,hpe,vpe,hpl,vpl\n2006-12-27T01:00:20,1,2,10,20\n")
    with pytest.raises(InputError, match="a truth trajectory cannot apply"):
        read(errors, reference=read_truth(DATA / "rover-truth.csv.gz"))


def test_cli_analyze_and_convert_with_truth(tmp_path):
    out = tmp_path / "out"
    args = ["analyze", str(ROVER), "--truth", str(DATA / "rover-truth.pos.gz"), "--no-confidence"]
    res = CliRunner().invoke(main, [*args, "--no-evt", "--no-parametric", "-o", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "summary.json").read_text())
    t = doc["truth_trajectory"]
    assert (t["file"], t["samples"], t["gaps"], t["span_gpst"]) == (
        "rover-truth.pos.gz", 277, 1, ["2006-12-27T01:00:10.000", "2006-12-27T01:04:50.000"]
    )  # fmt: skip
    assert t["statement"] in (out / "report.html").read_text()
    (inp,) = doc["inputs"]
    assert inp["rejected"] == {"outside_truth_span": 20} and inp["invalidated"] == {"no_truth_gap": 4}
    assert "warnings" not in doc  # a statement of the basis, not a warning
    parquet = tmp_path / "rover.parquet"
    res = CliRunner().invoke(
        main,
        [
            "convert",
            str(ROVER),
            "--truth",
            str(DATA / "rover-truth.csv.gz"),
            "--truth-max-gap",
            "6",
            "-o",
            str(parquet),
        ],
    )
    assert res.exit_code == 0, res.output
    table = pl.read_parquet(parquet)
    assert table.height == 280 and table["hpe"].is_finite().sum() == 279  # the 5 s gap bridged
    res = CliRunner().invoke(main, ["convert", str(ROVER), "--truth", str(DATA / "rover-truth.csv.gz"),
                                    "--reference", "mean", "-o", str(parquet)])  # fmt: skip
    assert res.exit_code == 2 and "--truth or --reference" in res.output


def test_statement_without_stream_digest():
    stream = io.StringIO("gps_seconds,x,y,z\n10,6378137,0,0\n11,6378137,0,0\n")
    truth = read_truth(stream)
    assert truth.sha256 == "" and "2 samples" in truth.statement()


def test_a_truth_that_misses_the_input_is_one_line(tmp_path):
    """A truth of another day (or UTC written as GPS time over a short run): no traceback, no empty table."""
    novatel = Path(__file__).parents[1] / "data" / "novatel" / "bestpos_raimstatus.asc.gz"  # 2024
    run = CliRunner().invoke(main, ["analyze", str(novatel), "--truth", str(DATA / "rover-truth.pos.gz"),
                                    "-o", str(tmp_path / "out")])  # fmt: skip
    assert run.exit_code == 2 and "no epoch inside the span of the truth trajectory" in run.output, run.output
    assert "Traceback" not in run.output and not (tmp_path / "out").exists()


def test_a_dataset_ingested_with_a_truth_says_so_when_analysed(tmp_path):
    """The manifest keeps the truth's summary; the dataset's report and summary.json state it."""
    ds, out = tmp_path / "ds", tmp_path / "out"
    run = CliRunner().invoke(main, ["ingest", str(ds), str(DATA / "rover.pos.gz"), "--truth",
                                    str(DATA / "rover-truth.pos.gz")])  # fmt: skip
    assert run.exit_code == 0, run.output
    station = json.loads((ds / "dataset.json").read_text())["stations"]["rover"]
    assert station["reference"] == "truth" and station["truth"][0]["file"] == "rover-truth.pos.gz"
    run = CliRunner().invoke(main, ["analyze", str(ds), "-o", str(out), "--workers", "0", "--counting-only"])
    assert run.exit_code == 0, run.output
    doc = json.loads((out / "summary.json").read_text())
    assert doc["truth_trajectory"]["stations"]["rover"][0]["sha256"] == station["truth"][0]["sha256"]
    assert "rover-truth.pos.gz" in (out / "report.html").read_text()


def test_a_dataset_ingested_against_the_mean_warns_when_analysed(tmp_path):
    ds, out = tmp_path / "ds", tmp_path / "out"
    run = CliRunner().invoke(main, ["ingest", str(ds), str(USLO), "--reference", "mean"])
    assert run.exit_code == 0, run.output
    run = CliRunner().invoke(main, ["analyze", str(ds), "-o", str(out), "--workers", "0", "--counting-only"])
    assert run.exit_code == 0, run.output
    doc = json.loads((out / "summary.json").read_text())
    assert any("against the mean" in w for w in doc["warnings"])


def test_many_gaps_each_epoch_interpolated_in_its_own_stretch():
    """A truth with hundreds of gaps (RTK fix lost and regained), epochs shuffled: each epoch between
    two samples of a stretch gets that stretch's interpolation, as np.interp over the stretch alone."""
    rng = np.random.default_rng(8)
    t = np.cumsum(np.where(rng.random(3000) < 0.1, 5.0, 1.0))  # 1 s steps, 10 % of them 5 s gaps
    xyz = _circle(t)
    truth = _truth(t, xyz, "linear")
    at_us = (rng.uniform(t[0] - 3, t[-1] + 3, 4000) * US).astype(np.int64)
    at = at_us / US
    got, status = truth.at(at_us)
    for i in rng.choice(at.size, 300, replace=False):
        j = np.searchsorted(t, at[i], side="right") - 1
        if at[i] < t[0] or at[i] > t[-1]:
            assert status[i] == "outside_truth_span" and np.isnan(got[i]).all()
        elif t[j] != at[i] and t[j + 1] - t[j] > 1.5:
            assert status[i] == "no_truth_gap" and np.isnan(got[i]).all()
        else:
            s = np.flatnonzero(np.r_[True, np.diff(t) > 1.5]).searchsorted(j, side="right") - 1
            first = np.flatnonzero(np.r_[True, np.diff(t) > 1.5])[s]
            last = np.r_[np.flatnonzero(np.diff(t) > 1.5) + 1, t.size][s]
            want = [np.interp(at[i], t[first:last], xyz[first:last, k]) for k in range(3)]
            assert status[i] == "" and np.allclose(got[i], want, rtol=0, atol=1e-6)
