"""A method whose numerical step cannot run on an input is reported, and the analysis goes on."""

from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path

from click.testing import CliRunner
from scipy import optimize

import overbound.stats.confidence as confidence_stats
from overbound.cli import DEMO_POS, USLO_REFERENCE, main

POS = Path(str(files("overbound.data") / DEMO_POS))


def test_a_root_finder_meeting_nan_fails_its_section_not_the_run(tmp_path: Path, monkeypatch) -> None:
    """Issue 13: `analyze` stopped with scipy's "The function value at x=... is NaN; solver cannot
    continue", naming neither file nor stage. Inject exactly that failure into the PL
    confidence step (brentq on a function returning NaN)."""

    brentq = optimize.brentq

    def brentq_on_nan(f, a, b, **kwargs):
        return brentq(lambda x: float("nan"), a, b, **kwargs)

    monkeypatch.setattr(confidence_stats.optimize, "brentq", brentq_on_nan)
    out = tmp_path / "out"
    res = CliRunner().invoke(
        main, ["analyze", str(POS), "--reference", USLO_REFERENCE, "--no-evt", "-o", str(out)]
    )
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    failures = summary["method_failures"]
    assert {f["axis"] for f in failures} == {"vertical", "horizontal"}
    for f in failures:
        assert f["method"] == "confidence"
        assert "NaN; solver cannot continue" in f["reason"] and "ValueError in confidence." in f["reason"]
        assert summary["confidence"][f["axis"]] == {"failed": f["reason"]}
    assert summary["parametric"], "the parametric analysis still ran"
    html = (out / "report.html").read_text()
    assert 'id="confidence-vertical"' in html and "Not computed: a numerical step failed" in html
    assert ">Vertical PL confidence (failed)</a>" in html and ">Horizontal PL confidence (failed)</a>" in html
    assert not (out / "confidence-vertical.json").exists()
    assert "confidence vertical: not computed: ValueError" in res.output
    # the verdicts say what is missing, and no PL-bounding pass rests on the absent check
    for service in summary["verdicts"].values():
        bounding = service["pl_bounding"]
        assert bounding["verdict"] != "pass", bounding["sentence"]
        missing = [e for e in bounding["evidence"] if e["quantity"] == "not computed"]
        assert {e["axis"] for e in missing} <= {"vertical", "horizontal"} and missing


def test_the_confidence_command_names_the_stage_that_failed(tmp_path: Path, monkeypatch) -> None:
    brentq = optimize.brentq
    monkeypatch.setattr(
        confidence_stats.optimize, "brentq", lambda f, a, b, **kw: brentq(lambda x: float("nan"), a, b, **kw)
    )
    res = CliRunner().invoke(
        main, ["confidence", str(POS), "--reference", USLO_REFERENCE, "-o", str(tmp_path / "out")]
    )
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert res.output.startswith("error: ValueError in confidence._ideal_pl: The function value at x=")
    assert not (tmp_path / "out").exists(), "nothing half-written"
