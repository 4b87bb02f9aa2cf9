"""The command line end to end on the embedded real WAAS day, and its bad-input behaviour."""

from __future__ import annotations

import gzip
import json
import math
import re
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from overbound.cli import DEMO_POS, USLO_REFERENCE, main
from overbound.io.geodesy import Reference, enu_errors_geodetic
from overbound.methods.parametric import AXIS_KEYS as PAR_AXIS_KEYS
from overbound.methods.parametric import SERVICE_KEYS as PAR_SERVICE_KEYS
from overbound.methods.parametric import TOP_EXTRA_KEYS as PAR_TOP_EXTRA_KEYS
from overbound.methods.parametric import TOP_KEYS as PAR_TOP_KEYS
from overbound.methods.tail_extrapolation import EVT_EXTRA_KEYS, EVT_KEYS

POS = Path(str(files("overbound.data") / DEMO_POS))


def _hand_parse():
    """The USLO file read with plain Python: hpl, vpl and positions of every data line."""
    rows = []
    for line in gzip.open(POS, "rt"):
        if line.startswith("%") or not line.strip():
            continue
        f = line.split()
        rows.append(tuple(float(x) for x in (f[2], f[3], f[4], f[-2], f[-1])))
    return rows


@pytest.fixture(scope="module")
def uslo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("uslo")
    res = CliRunner().invoke(main, ["analyze", str(POS), "--reference", USLO_REFERENCE, "-o", str(out)])
    assert res.exit_code == 0, res.output
    return out, json.loads((out / "summary.json").read_text()), res


def test_analyze_uslo_counts_by_hand(uslo_run):
    _, doc, _ = uslo_run
    rows = _hand_parse()
    assert doc["schema"] == "overbound.summary/1"
    assert doc["epochs"] == {
        "total": len(rows),
        "with_solution": len(rows),
        "no_solution": 0,
        "rejected": 0,
        "invalidated": 0,
    }
    assert len(rows) == 2865
    for name, hal, val in (("APV-I", 40, 50), ("LPV-200", 40, 35), ("CAT-I", 40, 15)):
        s = doc["services"][name]
        h = sum(r[3] < hal for r in rows)
        v = sum(r[4] < val for r in rows)
        hv = sum(r[3] < hal and r[4] < val for r in rows)
        assert s["availability"] == pytest.approx(
            {"horizontal": h / 2865, "vertical": v / 2865, "combined": hv / 2865}, rel=0, abs=1e-12
        )
    # the provenance's quick statistic: HPL<40 and VPL<50 at 86.7 % of epochs
    assert doc["services"]["APV-I"]["availability"]["combined"] == pytest.approx(0.867, abs=5e-4)


def test_analyze_uslo_stanford_counts_by_hand(uslo_run):
    _, doc, _ = uslo_run
    rows = _hand_parse()
    ref = Reference.parse(USLO_REFERENCE)
    lat, lon, h = (np.array([r[i] for r in rows]) for i in range(3))
    e, n, u = enu_errors_geodetic(lat, lon, h, ref)
    hpe, vpe = np.hypot(e, n), np.abs(u)
    hpl, vpl = np.array([r[3] for r in rows]), np.array([r[4] for r in rows])
    st = doc["services"]["LPV-200"]["stanford"]["vertical"]
    assert st["normal"] == int(np.sum((vpl < 35) & (vpe <= vpl)))
    assert st["unavailable"] == int(np.sum((vpl >= 35) & (vpe <= vpl)))
    assert st["mi"] + st["hmi"] + st["unavailable_mi"] == int(np.sum(vpe > vpl))
    sh = doc["services"]["APV-I"]["stanford"]["horizontal"]
    assert sh["normal"] == int(np.sum((hpl < 40) & (hpe <= hpl)))
    assert sh["unavailable"] == int(np.sum((hpl >= 40) & (hpe <= hpl)))
    assert doc["accuracy"]["hpe95"] == pytest.approx(float(np.percentile(hpe, 95)), rel=1e-9)
    assert doc["accuracy"]["vpe95"] == pytest.approx(float(np.percentile(vpe, 95)), rel=1e-9)


def test_analyze_uslo_continuity_at_30_s(uslo_run):
    _, doc, _ = uslo_run
    lpv = doc["services"]["LPV"]
    assert lpv["continuity_risk"]["combined"] is None
    assert "30 s exceeds the 15 s exposure" in lpv["continuity"]["combined"]["reason"]
    npa = doc["services"]["NPA"]["continuity"]["horizontal"]
    assert npa["risk"] is not None and npa["window_s"] == 3600 and npa["interval_s"] == 30
    assert npa["n_gap_windows"] > 0  # the file has gaps (2865 of 2880 epochs)
    assert doc["services"]["NPA"]["availability"]["vertical"] is None


def test_analyze_writes_report_and_is_reproducible(uslo_run, tmp_path):
    out, _, res = uslo_run
    assert (out / "report.html").stat().st_size > 10_000
    assert "report:" in res.output
    again = CliRunner().invoke(
        main, ["analyze", str(POS), "--reference", USLO_REFERENCE, "-o", str(tmp_path)]
    )
    assert again.exit_code == 0
    assert (tmp_path / "summary.json").read_bytes() == (out / "summary.json").read_bytes()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["analyze", "nope.pos", "-o", "x"], "nope.pos: no such file"),
        (["analyze", str(POS), "-o", "x"], "needs a reference position"),
        (["analyze", str(POS), "-o", "x", "--reference", "1,2"], "expected lat,lon,h"),
        (
            ["analyze", str(POS), "-o", "x", "--reference", USLO_REFERENCE, "--service", "FOO"],
            "unknown service",
        ),
    ],
)
def test_bad_input_one_line_error(args, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 2
    assert message in res.output


def test_unknown_format_names_file(tmp_path):
    bad = tmp_path / "random.bin"
    bad.write_bytes(bytes(range(256)) * 4)
    res = CliRunner().invoke(main, ["analyze", str(bad), "-o", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert f"{bad}: unknown format" in res.output


def test_simulate_and_demo(tmp_path):
    sim = tmp_path / "s.parquet"
    res = CliRunner().invoke(main, ["simulate", "-o", str(sim), "--days", "0.1", "--seed", "3"])
    assert res.exit_code == 0, res.output
    assert sim.exists() and "true P(|VPE|>VPL)" in res.output
    res = CliRunner().invoke(main, ["demo", "-o", str(tmp_path / "demo"), "--days", "0.2"])
    assert res.exit_code == 0, res.output
    for sub in ("uslo", "simulated"):
        doc = json.loads((tmp_path / "demo" / sub / "summary.json").read_text())
        assert doc["epochs"]["total"] > 0
        assert (tmp_path / "demo" / sub / "report.html").exists()
    sim_doc = json.loads((tmp_path / "demo" / "simulated" / "summary.json").read_text())
    # 1 Hz: continuity is countable for the approach services
    assert not math.isnan(sim_doc["services"]["LPV"]["continuity"]["combined"]["n_windows"])
    assert sim_doc["services"]["LPV"]["continuity"]["combined"]["n_windows"] > 10_000
    assert "index:" in res.output
    assert (tmp_path / "demo" / "simulated" / "parametric.json").exists()


def test_column_mapping_from_the_command_line(tmp_path):
    csv = tmp_path / "rx.csv"
    csv.write_text(
        "t,HPE_m,VPE_m,HPL_m,VPL_m\n"
        "2024-01-07T00:00:00,1.0,-2.0,12.0,18.0\n"
        "2024-01-07T00:00:01,1.5,2.5,12.5,55.0\n"
    )
    cols = [
        "--column",
        "time=t",
        "--column",
        "hpe=HPE_m",
        "--column",
        "vpe=VPE_m",
        "--column",
        "hpl=HPL_m",
        "--column",
        "vpl=VPL_m",
    ]
    out = tmp_path / "o"
    res = CliRunner().invoke(main, ["analyze", str(csv), "-o", str(out), "--service", "LPV", *cols])
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "summary.json").read_text())
    assert doc["services"]["LPV"]["availability"] == {"horizontal": 1.0, "vertical": 0.5, "combined": 0.5}
    bad = CliRunner().invoke(main, ["analyze", str(csv), "-o", str(out), "--column", "vpl"])
    assert bad.exit_code == 2 and "expected NAME=COLUMN" in bad.output
    missing = CliRunner().invoke(main, ["convert", str(csv), "-o", str(tmp_path / "e.parquet")])
    assert missing.exit_code == 2 and "missing column(s)" in missing.output and "rx.csv" in missing.output


def test_time_window_from_the_command_line(tmp_path):
    out = tmp_path / "o"
    res = CliRunner().invoke(
        main,
        ["analyze", str(POS), "--reference", USLO_REFERENCE, "-o", str(out), "--service", "LPV",
         "--start", "2006-12-27T06:00:00", "--end", "2006-12-27T12:00:00"],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "summary.json").read_text())
    times = [ln.split()[1] for ln in gzip.open(POS, "rt") if not ln.startswith("%")]
    assert doc["epochs"]["total"] == sum("06:00:00" <= t < "12:00:00" for t in times) == 719  # one gap
    assert doc["time"]["start"] == "2006-12-27T06:00:00.000"
    assert doc["time"]["end"] == "2006-12-27T11:59:30.000"
    (read,) = doc["inputs"]
    assert read["rows_kept"] == 719 and read["rejected"]["outside_time_range"] == len(times) - 719
    assert read["rows_kept"] + read["n_rejected"] == read["rows_read"], "the epochs outside are counted"


def test_gh3_confidence_command_and_report_section(tmp_path):
    """`overbound confidence` writes confidence.json; `analyze` adds its section and summary brief."""
    sim = tmp_path / "c.parquet"
    args = ["simulate", "-o", str(sim), "--days", "6", "--seed", "3", "--tail-fraction", "0",
            "--anomaly", "band:15:16:3"]  # fmt: skip
    assert CliRunner().invoke(main, args).exit_code == 0
    res = CliRunner().invoke(main, ["confidence", str(sim), "-o", str(tmp_path / "cl")])
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "cl" / "confidence.json").read_text())
    assert doc["schema"] == "overbound.confidence/1" and doc["axis"] == "vertical" and doc["risk"] == 1e-7
    suspect = [b["target"] for b in doc["bins"] if b["confidence"] is not None and b["confidence"] < 0.01]
    assert suspect and all(14.0 <= t <= 17.0 for t in suspect)
    assert (tmp_path / "cl" / "confidence.html").exists()
    out = tmp_path / "an"
    res = CliRunner().invoke(main, ["analyze", str(sim), "-o", str(out), "--service", "LPV", "--no-evt"])
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["confidence"]["vertical"]["suspect_targets"] == suspect
    assert set(summary["confidence"]) == {"vertical", "horizontal"}  # the simulator writes east/north
    page = (out / "report.html").read_text()
    assert '<section id="confidence-vertical">' in page and '<section id="confidence-horizontal">' in page
    assert json.loads((out / "confidence-vertical.json").read_text())["bins"] == doc["bins"]
    res = CliRunner().invoke(
        main, ["analyze", str(sim), "-o", str(tmp_path / "nc"), "--no-confidence", "--no-evt"]
    )
    assert res.exit_code == 0 and "confidence-vertical" not in (tmp_path / "nc" / "report.html").read_text()


# --------------------------------------------------------------------------- EVT (issue 4)

DAY_ONE = ["--end", "2024-01-08T00:00:00"]  # the first day of the simulated campaign: fewer epochs, faster
EVT_FIGURES = ("acf", "vk", "clusters", "mean-excess", "shape-stability", "p-mi-threshold", "tail-fit", "krs")


@pytest.fixture(scope="module")
def rich_sim(tmp_path_factory):
    """Two simulated days whose errors are 1.2 times their PL/K: a rich SI tail with a few epochs near 1."""
    path = tmp_path_factory.mktemp("evt") / "rich.parquet"
    args = ["simulate", "-o", str(path), "--days", "2", "--seed", "1", "--sigma-ratio", "1.2",
            "--tail-fraction", "0"]  # fmt: skip
    assert CliRunner().invoke(main, args).exit_code == 0
    return path


def test_gh4_evt_command_is_reproducible(rich_sim, tmp_path):
    """`overbound evt`: evt.json with the issue's keys, a self-contained evt.html, the same bytes twice."""
    outputs = []
    for name in ("a", "b"):
        out = tmp_path / name
        args = ["evt", str(rich_sim), "-o", str(out), "--bootstrap", "100", "--seed", "5",
                "--service", "LPV-200"]  # fmt: skip
        res = CliRunner().invoke(main, [*args, *DAY_ONE])
        assert res.exit_code == 0, res.output
        outputs.append(res.output)
        for f in ("evt.json", "evt.html"):
            assert (out / f).exists()
    doc = json.loads((tmp_path / "a" / "evt.json").read_text())
    assert set(doc) == EVT_KEYS | EVT_EXTRA_KEYS
    assert (doc["seed"], doc["n_boot"], doc["decluster"], doc["service"]) == (5, 100, True, "LPV-200")
    assert doc["threshold_method"] != "given" and list(doc["services"]) == ["LPV-200"]
    for f in ("evt.json", "evt.html"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes()
    assert (
        f"evt: {tmp_path / 'a' / 'evt.json'}" in outputs[0]
        and f"report: {tmp_path / 'a' / 'evt.html'}" in outputs[0]
    )
    assert "EVT vertical: P_MI" in outputs[0] and "P_MI95" in outputs[0] and "LPV-200" in outputs[0]
    page = (tmp_path / "a" / "evt.html").read_text()
    assert not re.search(r"""(?:src|href|action)\s*=\s*(?!["']?(?:data:image/png;base64,|#))""", page)
    assert re.findall(
        r'<img src="data:image/png;base64,[^"]+"[^>]*data-figure="evt-vertical-([a-z-]+)"', page
    ) == list(EVT_FIGURES)


def test_gh4_evt_options_reach_the_json(rich_sim, tmp_path):
    args = ["evt", str(rich_sim), "-o", str(tmp_path), "--no-decluster", "--threshold", "0.6",
            "--cluster-gap", "30", "--bootstrap", "50", "--confidence", "0.9", "--axis", "horizontal",
            "--service", "LPV-200", "--end", "2024-01-07T12:00:00"]  # fmt: skip
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "evt.json").read_text())
    assert (doc["decluster"], doc["threshold"], doc["threshold_method"]) == (False, 0.6, "given")
    options = (doc["cluster_gap_s"], doc["n_boot"], doc["confidence"], doc["axis"])
    assert options == (30.0, 50, 0.9, "horizontal")


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("--threshold", "high", "expected 'auto' or a number"),
        ("--threshold", "1.5", "finite number below 1"),
        ("--threshold", "nan", "finite number below 1"),
        ("--cluster-gap", "-3", "finite number at least 0"),
    ],
)
def test_gh4_evt_bad_option_is_a_usage_error(option, value, message, tmp_path):
    res = CliRunner().invoke(
        main, ["evt", str(POS), "--reference", USLO_REFERENCE, "-o", str(tmp_path), option, value]
    )
    assert res.exit_code == 2
    assert f"Invalid value for '{option}'" in res.output and message in res.output
    assert not (tmp_path / "evt.json").exists()


def test_gh4_evt_too_few_tail_values_is_a_clean_error(tmp_path):
    """The USLO day (2865 epochs at 30 s) has too few tail values: one error line, no traceback."""
    res = CliRunner().invoke(main, ["evt", str(POS), "--reference", USLO_REFERENCE, "-o", str(tmp_path)])
    assert res.exit_code == 2
    assert res.output.startswith("error: ") and "too few tail values" in res.output
    assert res.output.count("\n") == 1 and "Traceback" not in res.output
    assert not (tmp_path / "evt.json").exists()


def test_gh4_analyze_uslo_says_why_there_is_no_estimate(uslo_run, tmp_path):
    out, doc, res = uslo_run
    for axis in ("vertical", "horizontal"):  # the file has HPL: both axes tried
        brief = doc["evt"][axis]
        assert brief["p_mi"] is None and brief["services"] == {}
        assert brief["message"].startswith("no estimate: ") and "too few tail values" in brief["message"]
        assert not (out / f"evt-{axis}.json").exists()
    page = (out / "report.html").read_text()
    assert '<section id="evt-vertical">' in page and "No estimate of P<sub>MI</sub>" in page
    assert "EVT vertical: no estimate" in res.output
    # --no-evt: no EVT at all (a two-epoch CSV: quick)
    csv = tmp_path / "rx.csv"
    csv.write_text(
        "time,station,hpe,vpe,hpl,vpl\n2024-01-07T00:00:00,A,1,2,12,18\n2024-01-07T00:00:01,A,1,2,12,18\n"
    )
    res = CliRunner().invoke(
        main, ["analyze", str(csv), "-o", str(tmp_path / "o"), "--no-evt", "--service", "LPV"]
    )
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["evt"] == {}
    assert (
        not list((tmp_path / "o").glob("evt*"))
        and "evt-vertical" not in (tmp_path / "o" / "report.html").read_text()
    )


# --------------------------------------------------------------------------- parametric (issue 5)


@pytest.fixture(scope="module")
def quarter_day(tmp_path_factory):
    """Six simulated hours at 1 Hz: every parametric figure has data, and the run is quick."""
    path = tmp_path_factory.mktemp("parametric") / "q.parquet"
    res = CliRunner().invoke(main, ["simulate", "-o", str(path), "--days", "0.25", "--seed", "3"])
    assert res.exit_code == 0, res.output
    return path


def test_gh5_parametric_command_writes_the_issue_keys(quarter_day, tmp_path):
    args = ["parametric", str(quarter_day), "-o", str(tmp_path), "--service", "LPV-200", "--service", "NPA",
            "--decorrelation", "120", "--confidence", "0.9"]  # fmt: skip
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "parametric.json").read_text())
    assert set(doc) == PAR_TOP_KEYS | PAR_TOP_EXTRA_KEYS and doc["schema"] == "overbound.parametric/1"
    assert (doc["confidence"], doc["decorrelation"], doc["decorrelation_rule"]) == (0.9, 120.0, "given")
    for axis, law in (("vertical", "normal"), ("horizontal", "rayleigh")):
        a = doc[axis]
        assert PAR_AXIS_KEYS <= set(a)
        assert set(a["ratio_fit"]) == {"distribution", "mean", "sigma"}
        assert a["ratio_fit"]["distribution"] == law
        assert set(a["weibull"]) == {"a", "b"}
        assert a["decorrelation_s"] == a["pl_decorrelation_s"] == 120.0
        scale = 1.0 if axis == "vertical" else 2.0  # integral time scale of the Rayleigh's r^2: 2 tau
        assert a["n_effective"] == pytest.approx(a["n_epochs"] * a["interval_s"] / (scale * 120.0))
        assert 0 < a["p_mi"] < a["p_mi_bound"] < 1
        for s in a["services"].values():
            assert s is None or PAR_SERVICE_KEYS <= set(s)
    assert list(doc["horizontal"]["services"]) == ["LPV-200", "NPA"]
    assert doc["vertical"]["services"]["NPA"] is None  # no VAL
    page = (tmp_path / "parametric.html").read_text()
    assert '<section id="parametric-vertical">' in page and '<section id="parametric-horizontal">' in page
    assert 'data-figure="parametric-horizontal-noncontinuity-3600"' in page
    assert f"parametric: {tmp_path / 'parametric.json'}" in res.output
    assert f"report: {tmp_path / 'parametric.html'}" in res.output
    line = next(ln for ln in res.output.splitlines() if ln.startswith("parametric vertical: P_MI"))
    assert "integrity/availability/continuity: LPV-200 " in line and "NPA" not in line


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("--decorrelation", "soon", "expected 'auto' or a number"),
        ("--decorrelation", "0", "seconds above 0"),
        ("--decorrelation", "nan", "expected 'auto' or a finite number"),
        ("--confidence", "1", "not in the range 0<x<1"),
    ],
)
def test_gh5_parametric_bad_option_is_a_usage_error(option, value, message, tmp_path):
    res = CliRunner().invoke(
        main, ["parametric", str(POS), "--reference", USLO_REFERENCE, "-o", str(tmp_path), option, value]
    )
    assert res.exit_code == 2
    assert f"Invalid value for '{option}'" in res.output and message in res.output
    assert not (tmp_path / "parametric.json").exists()


def test_gh5_parametric_unknown_service_is_one_line(quarter_day, tmp_path):
    res = CliRunner().invoke(main, ["parametric", str(quarter_day), "-o", str(tmp_path), "--service", "FOO"])
    assert res.exit_code == 2 and res.output.startswith("error: unknown service 'FOO'")
    assert res.output.count("\n") == 1 and not (tmp_path / "parametric.json").exists()


def test_gh5_analyze_adds_the_parametric_section(uslo_run):
    """The USLO day: P_MI below 1e-300 on both axes, kept by its log10; 30 s sampling: no 15 s window."""
    out, doc, res = uslo_run
    par = json.loads((out / "parametric.json").read_text())
    for axis in ("vertical", "horizontal"):
        brief = doc["parametric"][axis]
        assert brief["p_mi"] == par[axis]["p_mi"] == 0.0 and brief["log10_p_mi"] < -300
        assert brief["unavailable_reason"] is None
        assert brief["services"]["APV-I"]["meets_continuity"] is None  # not countable at 30 s
    assert doc["parametric"]["vertical"]["services"]["APV-I"]["unavailability_counted"] == pytest.approx(
        1 - doc["services"]["APV-I"]["availability"]["vertical"]
    )
    page = (out / "report.html").read_text()
    assert (
        '<section id="parametric-vertical">' in page and "no 15 s continuity window could be counted" in page
    )
    # the closing lines are the verdict matrix, never a model's raw tiny probability (issue 12)
    assert "Verdicts" in res.output and "PL bounding (MI)" in res.output
    assert not re.search(r"e-\d{2,3}\b", res.output.replace("e-0", ""))


def test_gh5_analyze_no_parametric_and_too_few_epochs(tmp_path):
    csv = tmp_path / "rx.csv"
    csv.write_text(
        "time,station,hpe,vpe,hpl,vpl\n2024-01-07T00:00:00,A,1,2,12,18\n2024-01-07T00:00:01,A,1,2,12,18\n"
    )
    res = CliRunner().invoke(
        main, ["analyze", str(csv), "-o", str(tmp_path / "a"), "--no-evt", "--service", "LPV"]
    )
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "a" / "parametric.json").read_text())
    assert doc["vertical"] is None and "at least 10 needed" in doc["reasons"]["vertical"]
    assert "No parametric estimate" in (tmp_path / "a" / "report.html").read_text()
    assert "parametric vertical: no estimate" in res.output
    res = CliRunner().invoke(
        main,
        ["analyze", str(csv), "-o", str(tmp_path / "b"), "--no-evt", "--no-parametric", "--service", "LPV"],
    )
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "b" / "summary.json").read_text())["parametric"] == {}
    assert not (tmp_path / "b" / "parametric.json").exists()
    assert "parametric-vertical" not in (tmp_path / "b" / "report.html").read_text()


def test_summary_is_byte_identical_from_another_folder(tmp_path):
    """The same input under two folders gives the same summary.json (no absolute path in it)."""
    import shutil

    outs = []
    for folder in ("a", "b/deeper/still"):
        d = tmp_path / folder
        d.mkdir(parents=True)
        shutil.copy(POS, d / POS.name)
        out = d / "out"
        res = CliRunner().invoke(
            main,
            [
                "analyze",
                str(d / POS.name),
                "--reference",
                USLO_REFERENCE,
                "-o",
                str(out),
                "--no-evt",
                "--no-parametric",
                "--no-confidence",
            ],
        )
        assert res.exit_code == 0, res.output
        outs.append((out / "summary.json").read_bytes())
    assert outs[0] == outs[1]
    doc = json.loads(outs[0])
    assert str(tmp_path) not in outs[0].decode()
    assert doc["provenance"]["inputs"][0]["name"] == POS.name
    assert set(doc["verdicts"]["LPV"]) == {
        "availability",
        "continuity",
        "accuracy",
        "integrity",
        "pl_bounding",
        "overall",
    }
