"""Outputs of the PL confidence-level analysis: JSON document, figures, HTML section and page."""

from __future__ import annotations

import dataclasses
import json
import math
import re

import numpy as np
import pytest

from overbound.methods.confidence_level import ConfidenceBin, confidence_analysis
from overbound.report.confidence import (
    REPORT_NAME,
    SCHEMA,
    confidence_dict,
    confidence_section_html,
    json_name,
    plot_band_errors,
    plot_band_histogram,
    plot_confidence,
    run_confidence,
    write_confidence,
    write_confidence_report,
)
from overbound.report.figures import close_figure
from overbound.report.json import dumps, to_jsonable
from overbound.simulate import SimulationConfig, simulate


@pytest.fixture(scope="module")
def table():
    """Two days with the ENAC-like anomaly (errors x3 where VPL is in [15, 16) m) and a horizontal one."""
    config = SimulationConfig(days=2, seed=1, tail_fraction=0.0, anomalies=("band:15:16:3", "band:8:9:3:h"))
    return simulate(config).table


@pytest.fixture(scope="module")
def analysis(table):
    # 60 samples: two days hold only 480 slots of 360 s
    return confidence_analysis(table, min_samples=60, max_pl=25.0)


# --------------------------------------------------------------------------- JSON


def test_json_document(analysis):
    doc = confidence_dict(analysis)
    assert doc["schema"] == SCHEMA == "overbound.confidence/1"
    assert (doc["axis"], doc["risk"], doc["n_epochs"]) == ("vertical", 1e-7, analysis.n_epochs)
    assert doc["parameters"] == {
        "min_samples": 60,
        "spacing": 360.0,
        "tolerance": 0.125,
        "step": 0.25,
        "max_pl": 25.0,
        "max_tolerance": 1.0,
        "core": 0.2,
    }
    assert len(doc["bins"]) == doc["counts"]["bins"] == len(analysis.bins)
    assert doc["counts"]["suspect"] == len(doc["suspect_targets"]) > 0
    assert all(15.0 - 1.25 < t < 16.0 + 1.0 for t in doc["suspect_targets"])
    assert doc["worst_target"] == analysis.bins[analysis.worst].target
    fields = {f.name for f in dataclasses.fields(ConfidenceBin)}
    assert all(set(b) == fields for b in doc["bins"])


def test_json_round_trip_nulls_and_deterministic_bytes(analysis, table, tmp_path):
    text = dumps(confidence_dict(analysis))
    loaded = json.loads(text)
    assert loaded == to_jsonable(confidence_dict(analysis))  # nothing lost but float digits beyond 12
    few = next(i for i, b in enumerate(analysis.bins) if not b.sufficient and b.n >= 3)
    assert loaded["bins"][few]["confidence"] is None and loaded["bins"][few]["suspect"] is False
    assert loaded["bins"][few]["sigma_inflated"] is not None
    for original, back in zip(
        analysis.bins, (ConfidenceBin.from_dict(b) for b in loaded["bins"]), strict=True
    ):
        for f in dataclasses.fields(ConfidenceBin):
            x, y = getattr(original, f.name), getattr(back, f.name)
            if isinstance(x, float):
                assert (math.isnan(x) and math.isnan(y)) or y == pytest.approx(x, rel=1e-11, abs=1e-300)
            else:
                assert x == y
    # rerun from scratch: the same bytes; the file is the same text
    again = confidence_analysis(table, min_samples=60, max_pl=25.0)
    assert dumps(confidence_dict(again)) == text
    path = write_confidence(again, tmp_path / "c.json")
    assert path.read_bytes() == text.encode("utf-8")


# --------------------------------------------------------------------------- figures


def _gid(ax, gid):
    return [a for a in (*ax.lines, *ax.collections, *ax.patches) if a.get_gid() == gid]


def test_plot_confidence(analysis):
    ax = plot_confidence(analysis)
    try:
        assert ax.get_yscale() == "logit"
        (line,) = _gid(ax, "cl")
        y = np.asarray(line.get_ydata(), dtype=float)
        has = np.isfinite([b.confidence for b in analysis.bins])
        assert np.count_nonzero(np.isfinite(y)) == has.sum() > 0
        assert np.all((y[has] >= 1e-6) & (y[has] <= 1 - 1e-6))  # clipped to the plotted range
        (rings,) = _gid(ax, "cl-suspect")
        assert len(rings.get_offsets()) == len(analysis.suspect)
        (few,) = _gid(ax, "cl-insufficient")
        assert len(few.get_offsets()) == sum(0 < b.n and not b.sufficient for b in analysis.bins)
        assert [ln.get_ydata()[0] for ln in (*_gid(ax, "cl-1"), *_gid(ax, "cl-99"))] == [0.01, 0.99]
    finally:
        close_figure(ax.figure)


def test_plot_band_histogram_is_a_density_with_both_gaussians(analysis):
    i = analysis.worst
    b, s = analysis.bins[i], analysis.samples[i]
    ax = plot_band_histogram(b, s.signed[0], s.inflations[0])
    try:
        (hist,) = _gid(ax, "histogram")
        values, edges, _ = hist.get_data()
        assert np.sum(values * np.diff(edges)) == pytest.approx(1.0)
        assert ax.get_yscale() == "log"
        for gid, sd in (("gauss-sigma", b.sigma), ("gauss-inflated", b.sigma_inflated)):
            (curve,) = _gid(ax, gid)
            assert np.max(curve.get_ydata()) == pytest.approx(1 / (sd * math.sqrt(2 * math.pi)), rel=1e-3)
        assert _gid(ax, "binding")[0].get_xdata()[0] == s.inflations[0].binding_error
    finally:
        close_figure(ax.figure)


def test_plot_band_errors_draws_the_pl_lines(analysis):
    i = analysis.worst
    b, s = analysis.bins[i], analysis.samples[i]
    ax = plot_band_errors(b, s.signed[0], s.pl)
    try:
        assert list(_gid(ax, "errors")[0].get_ydata()) == list(s.signed[0])
        for gid, value in (("pl-ideal", b.pl_ideal), ("pl-1", b.pl_1), ("pl-99", b.pl_99)):
            (line,) = _gid(ax, gid)
            assert line.get_ydata()[0] == value
        assert b.pl_1 > s.pl.max()  # the paper's figure 8 reading: every VPL below VPL1 -> CL < 1 %
        lines = {ln.get_ydata()[0] for ln in ax.lines if len(ln.get_ydata()) == 2}
        assert -b.pl_ideal in lines  # vertical: signed, lines at plus and minus
    finally:
        close_figure(ax.figure)


# --------------------------------------------------------------------------- HTML


def test_section_html(analysis, monkeypatch):
    monkeypatch.setattr("overbound.report.confidence._MAX_DETAIL_BINS", 2)  # 4 by default; fewer to draw
    text = confidence_section_html(analysis)
    assert text.startswith('<section id="confidence-vertical">\n<h2>Vertical PL confidence level</h2>')
    rows = re.findall(r'<tr( class="suspect")? data-bin="(\d+)">', text)
    # only the bands with a confidence level are listed; the others are counted in one line
    assert len(rows) == sum(b.sufficient for b in analysis.bins)
    few = sum(b.n > 0 and not b.sufficient for b in analysis.bins)
    assert f'<p class="few-bands">{few} further bands' in text
    assert {int(i) for cls, i in rows if cls} == set(analysis.suspect)
    assert text.count('<span class="alarm">suspect</span>') == len(analysis.suspect)
    # the CL figure, then histogram + figure 8 for at most 2 suspect bins (the lowest CLs) and the worst
    assert len(analysis.suspect) > 2
    details = sorted(analysis.suspect, key=lambda i: (analysis.bins[i].confidence, i))[:2]
    assert analysis.worst in details
    assert text.count("<img ") == 1 + 2 * len(details)
    assert set(re.findall(r'data-figure="confidence-vertical-hist-(\d+)"', text)) == {str(i) for i in details}
    assert "http" not in text and "<script" not in text  # self-contained
    assert "band(s) with a confidence level below 1 %" in text


def test_standalone_page_is_deterministic_and_run_confidence_writes_everything(table, tmp_path):
    healthy = confidence_analysis(table, min_samples=60, max_pl=12.0)  # below the anomaly: no suspect bin
    assert not healthy.suspect
    first = write_confidence_report(healthy, tmp_path / "a").read_bytes()
    second = write_confidence_report([healthy], tmp_path / "b").read_bytes()
    assert first == second
    text = first.decode("utf-8")
    assert text.startswith("<!DOCTYPE html>") and text.count("<section") == 1
    assert text.count("<img ") == 3  # the CL figure and the worst bin's two figures
    assert "No band has a confidence level below 1 %." in text

    # max_pl below the lowest VPL: no vertical bin; the horizontal ones stop short of the 8-9 m anomaly
    run = run_confidence(
        table, tmp_path / "run", axes=("vertical", "horizontal", "vertical"), min_samples=60, max_pl=6.5
    )
    assert [a.axis for a in run.analyses] == ["vertical", "horizontal"]
    assert run.analyses[0].bins == () and len(run.analyses[1].bins) > 0
    assert [p.name for p in run.json_paths] == [json_name("vertical"), json_name("horizontal")]
    assert json.loads(run.json_paths[1].read_text())["axis"] == "horizontal"
    page = run.report.read_text(encoding="utf-8")
    assert run.report.name == REPORT_NAME
    assert 'id="confidence-vertical"' in page and 'id="confidence-horizontal"' in page
    for a, path in zip(run.analyses, run.json_paths, strict=True):
        assert path.read_text() == dumps(confidence_dict(a))


def test_empty_analysis_renders(table, tmp_path):
    nothing = confidence_analysis(table.head(0))
    assert nothing.bins == ()
    text = confidence_section_html(nothing)
    assert "No epoch with a solution" in text and "<img" not in text
    assert confidence_dict(nothing)["worst_target"] is None
    ax = plot_confidence(nothing)
    close_figure(ax.figure)


def test_confidence_levels_are_never_printed_below_1e_15():
    from overbound.report.confidence import _text_cl

    assert _text_cl(1 - 5.6e-16) == "> 1 − 1e-15"  # float rounding at 1 is no information
    assert _text_cl(3e-20) == "< 1e-15"
    assert _text_cl(1 - 2e-12) == "1 − 2.0e-12" and _text_cl(2e-9) == "2.00e-09" and _text_cl(1.0) == "1"
