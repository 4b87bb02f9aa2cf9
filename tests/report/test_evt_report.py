"""Outputs of the EVT tail extrapolation: HTML section, standalone page, report.html and summary.json."""

from __future__ import annotations

import dataclasses
import re
from html import unescape

import numpy as np
import polars as pl
import pytest

from overbound.analysis import analyze
from overbound.methods.tail_extrapolation import tail_analysis
from overbound.report.evt import (
    REPORT_NAME,
    _vk_curve,
    analysed_series,
    evt_failure_html,
    evt_section_html,
    write_evt_report,
)
from overbound.report.html import render_report, section_ids
from overbound.report.json import summary_dict
from overbound.simulate import SimulationConfig, simulate

FIGURES = ("acf", "vk", "clusters", "mean-excess", "shape-stability", "p-mi-threshold", "tail-fit", "krs")
#: Small options: a few seconds per analysis.
FAST = {"n_boot": 100, "gev_boot": 10, "n_sim": 50}


@pytest.fixture(scope="module")
def table():
    """Two days at 1 Hz with errors 1.2 times their PL/K: a rich SI tail with a few epochs near 1."""
    return simulate(SimulationConfig(days=2, seed=1, sigma_ratio=1.2, tail_fraction=0.0)).table


@pytest.fixture(scope="module")
def analysis(table):
    # TINY: its VAL keeps the 0.2 % of epochs with the lowest VPL: too few tail values, "no estimate"
    val = float(np.nanquantile(table["vpl"].to_numpy(), 0.002))
    return tail_analysis(table, rng=4, services=("LPV-200", "CAT-I", f"TINY:40:{val:.4f}"), **FAST)


@pytest.fixture(scope="module")
def bare(table):
    """No threshold diagnostics and no service: the figures without data are not drawn."""
    return tail_analysis(table, rng=0, services=(), diagnostics=False, **FAST)


@pytest.fixture(scope="module")
def section(table, analysis):
    return evt_section_html(analysis, series=analysed_series(table, analysis))


def _text(html: str) -> str:
    return " ".join(unescape(re.sub(r"<[^>]+>", " ", html)).split())


def _rows(html: str, cls: str) -> dict[str, list[str]]:
    """Rows of the table of class ``cls``: first cell (text) -> the other cells (text)."""
    body = re.search(rf'<table class="{cls}">(.*?)</table>', html, re.S).group(1)
    rows = {}
    for tr in re.findall(r"<tr>(.*?)</tr>", body, re.S)[1:]:
        cells = [_text(c) for c in re.findall(r"<t[hd]>(.*?)</t[hd]>", tr, re.S)]
        rows[cells[0]] = cells[1:]
    return rows


def test_analysed_series_is_the_analysed_one(table, analysis):
    time_s, si = analysed_series(table, analysis)
    c = analysis.tail.clusters
    assert si.size == analysis.counts.n_used == analysis.tail.n_total
    assert np.array_equal(si[c.peak_index], c.peak_value)
    assert int(np.count_nonzero(si > c.threshold)) == c.n_exceedances
    assert np.all(np.diff(time_s) > 0)
    # another table is not the analysed one: no series rather than a wrong figure
    other = table.with_columns(pl.col("vpe") * 1.01)
    assert analysed_series(other, analysis) is None
    assert analysed_series(table.drop("vpl"), analysis) is None


def test_vk_curve_is_rebuilt_with_its_poisson_line(analysis):
    curve = _vk_curve(analysis)
    d = analysis.dependence
    assert curve.n == analysis.tail.clusters.n_exceedances > 1
    np.testing.assert_allclose(curve.poisson(), d.vk_poisson)
    assert np.array_equal(curve.v, d.vk_v)


def test_section_headline_counts_and_messages(analysis, section):
    a, t = analysis, analysis.tail
    assert section.startswith('<section id="evt-vertical">\n<h2>Vertical EVT tail extrapolation</h2>')
    head = _rows(section, "evt-headline")
    assert head["threshold u"][0] == f"{t.threshold:.4g}"
    assert "automatic" in head["threshold u"][1]
    assert head["clusters above u"][0] == f"{t.n_clusters:,}"
    assert head["exceedances of u"][0] == f"{t.n_exceedances:,}"
    assert head["cluster gap K T"][0] == f"{a.dependence.cluster_gap_s:g} s"
    assert head["GPD shape ξ"][0] == f"{t.gpd.xi:.3g}"
    assert head["KRS core test"][1].endswith(f"{'overbounded' if a.krs.overbounded else 'not overbounded'} "
                                             f"({a.krs.n:,} samples)")  # fmt: skip
    for key in ("P MI per epoch", "upper bound P MI95", "upper bound per approach"):
        assert key in head
    # the headline numbers are those of the analysis (mantissa of P_MI95 to 3 digits)
    m = re.match(r"([\d.]+)·10 −(\d+)$", head["upper bound P MI95"][0])
    assert float(m.group(1)) * 10.0 ** -int(m.group(2)) == pytest.approx(t.p_95, rel=5e-3)
    epochs = _rows(section, "evt-epochs")
    assert epochs["used"] == [f"{a.counts.n_used:,}"]
    assert epochs["rows of the table"] == [f"{a.counts.n_rows:,}"]
    assert epochs["without a solution"] == [f"{a.counts.n_no_solution:,}"]
    text = _text(section)
    for statement in a.message.split(";"):
        assert statement.strip() in text
    assert t.threshold_choice.message in text


def test_service_verdicts_and_no_estimate(analysis, section):
    services = _rows(section, "evt-services")
    assert list(services) == list(analysis.services)
    words = {
        True: "bound within",
        False: "bound above",
        None: "no estimate",
    }  # a method's reading, no verdict
    for name, h in analysis.services.items():
        assert services[name][8] == words[h.meets_requirement]
        assert services[name][9] == h.message
    assert analysis.services["TINY"].meets_requirement is None
    badges = re.findall(r'<span class="badge (\w+)" data-kpi="([^"]+)"', section)
    kinds = {True: "within", False: "above", None: "na"}
    assert badges == [(kinds[h.meets_requirement], n) for n, h in analysis.services.items()]
    assert f"TINY: no HMI estimate: {analysis.services['TINY'].message}" in _text(section)


def test_every_figure_with_alt_and_caption(section):
    figures = re.findall(
        r'<figure(?: class="wide")?><img src="data:image/png;base64,[^"]+" '
        r'width="\d+" height="\d+" alt="([^"]+)" '
        r'data-figure="evt-vertical-([a-z-]+)"><figcaption>([^<]+)</figcaption>',
        section,
    )
    assert [name for _, name, _ in figures] == list(FIGURES)
    for alt, _, caption in figures:
        assert len(alt) > 40 and caption.endswith(".") and caption.count(". ") == 0
    assert "Not drawn" not in section
    assert not re.search(r"""(?:src|href)\s*=\s*["'](?!data:image/png;base64,)""", section)


def test_figures_without_data_are_skipped(bare):
    html = evt_section_html(bare)  # no series: no clusters figure either
    names = re.findall(r'data-figure="evt-vertical-([a-z-]+)"', html)
    assert names == ["acf", "vk", "tail-fit", "krs"]
    note = re.search(r'<p class="limits">Not drawn: ([^<]+)</p>', html).group(1)
    for skipped in ("clusters", "mean-excess", "shape-stability", "p-mi-threshold"):
        assert skipped in note
    assert "No service level" in html


def test_failure_section_says_why():
    html = evt_failure_html("horizontal", "SI: too few tail values <here>")
    assert html.startswith('<section id="evt-horizontal">\n<h2>Horizontal EVT tail extrapolation</h2>')
    assert "No estimate of P<sub>MI</sub>: SI: too few tail values &lt;here&gt;" in html


def test_standalone_page(table, analysis, section, tmp_path):
    path = write_evt_report(analysis, tmp_path, table=table)
    assert path == tmp_path / REPORT_NAME
    page = path.read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>") and page.count("<section") == 1
    assert section in page  # drawn again, the same bytes: no timestamp, deterministic PNGs
    assert page.count("<img ") == len(FIGURES)
    assert not re.search(r"""(?:src|href|action)\s*=\s*(?!["']?(?:data:image/png;base64,|#))""", page)
    assert "<script" not in page and "<link" not in page


def test_report_html_and_summary_brief(table, analysis, bare):
    """analyze's report gets one section per EVT axis, the failed one saying why; summary.json a brief."""
    base = analyze(table.head(20_000), services=["LPV-200"])
    assert base.evt == () and summary_dict(base)["evt"] == {}
    fail = (("horizontal", "too few tail values"),)
    brief = summary_dict(dataclasses.replace(base, evt=(analysis,), evt_failures=fail))["evt"]
    a = dataclasses.replace(base, evt=(bare,), evt_failures=fail)  # bare: fewer figures to draw
    ids = section_ids(a)
    assert ids.index("evt-vertical") + 1 == ids.index("evt-horizontal") == ids.index("time-series") - 1
    page = render_report(a)
    assert re.findall(r'<section id="(evt-[a-z]+)">', page) == ["evt-vertical", "evt-horizontal"]
    assert 'href="#evt-vertical"' in page and 'href="#evt-horizontal"' in page
    assert "No estimate of P<sub>MI</sub>: too few tail values" in page
    t = analysis.tail
    assert brief["vertical"] == {
        "p_mi": t.p,
        "p_mi_95": t.p_95,
        "p_mi_per_approach_95": t.p_approach_95,
        "services": {n: {"meets_requirement": h.meets_requirement} for n, h in analysis.services.items()},
        "message": analysis.message,
    }
    assert brief["horizontal"]["p_mi"] is None
    assert brief["horizontal"]["message"] == "no estimate: too few tail values"


def test_analyze_runs_evt_per_axis_and_keeps_failures(table):
    """analyze(evt=...): the services with an AL on the axis; an axis without enough tail fails alone."""
    a = analyze(table, services=["NPA", "LPV-200"], evt=["vertical"], evt_n_boot=50)
    (v,) = a.evt
    assert (v.axis, v.n_boot, v.seed, a.evt_failures) == ("vertical", 50, 0, ())
    assert list(v.services) == ["LPV-200"]  # NPA has no VAL
    short = analyze(table.head(3000), services=["LPV-200"], evt=None, evt_n_boot=50)
    assert short.evt == ()
    assert [axis for axis, _ in short.evt_failures] == ["vertical", "horizontal"]
    assert all("too few tail values" in why for _, why in short.evt_failures)
