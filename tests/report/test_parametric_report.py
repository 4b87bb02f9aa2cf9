"""Outputs of the parametric method (Kannemans 2006): figures, HTML sections and page, summary brief."""

from __future__ import annotations

import dataclasses
import math
import re
from html import unescape

import numpy as np
import polars as pl
import pytest
from scipy import special

from overbound.analysis import analyze
from overbound.methods.parametric import parametric_analysis
from overbound.report.html import render_report, section_ids
from overbound.report.json import summary_dict
from overbound.report.parametric import (
    REPORT_NAME,
    _h_p,
    analysed_series,
    log10_per_exposure,
    parametric_brief,
    parametric_section_html,
    service_verdicts,
    write_parametric_report,
)
from overbound.report.parametric_figures import (
    CONTOUR_LEVELS,
    LocalFit,
    RegionLabels,
    format_probability,
    mantissa_exponent,
    plot_acf_pair,
    plot_noncontinuity,
    plot_pe_pl_contours,
    plot_pl_histogram,
    plot_ratio_probability,
    plot_ratio_timeseries,
    plot_weibull_probability,
)
from overbound.simulate import SimulationConfig, simulate
from overbound.stats.parametric import pe_pl_density, weibull_pdf, weibull_pdf_band

AXIS_IDS = ("parametric-vertical", "parametric-horizontal")
SERVICES = ("LPV-200", "NPA")  # one vertical AL; two horizontal ALs and two continuity windows
#: Figures of each axis for SERVICES, in page order.
FIGURES = {
    "vertical": ["timeseries", "ratio-timeseries", "ratio-probability", "weibull-probability", "acf",
                 "pl-histogram", "contours-35", "noncontinuity-15"],
    "horizontal": ["timeseries", "ratio-timeseries", "ratio-probability", "weibull-probability", "acf",
                   "pl-histogram", "contours-40", "contours-556", "noncontinuity-15", "noncontinuity-3600"],
}  # fmt: skip


@pytest.fixture(scope="module")
def table() -> pl.DataFrame:
    """Half a day at 1 Hz (43 200 epochs): every figure has data."""
    return simulate(SimulationConfig(days=0.5, seed=3)).table


@pytest.fixture(scope="module")
def analysis(table):
    return parametric_analysis(table, services=SERVICES)


@pytest.fixture(scope="module")
def section(table, analysis):
    return parametric_section_html(analysis, table)


def _gid(ax, gid: str) -> list:
    return ax.figure.findobj(lambda a: a.get_gid() == gid)


def _text(html: str) -> str:
    return " ".join(unescape(re.sub(r"<[^>]+>", " ", html)).split())


def _rows(html: str, cls: str) -> dict[str, list[str]]:
    """Rows of the first table of class ``cls``: first cell (text) -> the other cells (HTML)."""
    body = re.search(rf'<table class="{cls}">(.*?)</table>', html, re.S).group(1)
    rows = {}
    for tr in re.findall(r"<tr>(.*?)</tr>", body, re.S)[1:]:
        cells = re.findall(r"<t[hd]>(.*?)</t[hd]>", tr, re.S)
        rows[_text(cells[0])] = cells[1:]
    return rows


# ---------------------------------------------------------------------------
# probabilities below 1e-300


def test_tiny_probabilities_are_written_from_their_log10():
    assert mantissa_exponent(0.0, -411.9) == (round(10**0.1, 2), -412)  # the exact value: the JSON's
    assert mantissa_exponent(1e-310, -309.5) == (3.16, -310)  # subnormal: below 1e-300, from the log
    # printed: nothing below 1e-15 as a number (issue 12), but never 0 for a positive value
    assert format_probability(0.0, -411.9) == "< 1e-15"
    assert format_probability(1e-310, -309.5) == "< 1e-15"
    assert format_probability(2.5e-7, -6.6) == "2.5e-07"  # a float64 value: its own digits
    assert format_probability(1.2e-15) == "1.2e-15" and format_probability(9.9e-16) == "< 1e-15"
    assert format_probability(0.0123) == "0.0123"
    assert format_probability(0.0) == "0" and format_probability(None) == "n.a."
    assert mantissa_exponent(9.9999e-5) == (1.0, -4)  # rounding carries into the exponent
    assert _h_p(0.0, -411.9) == "&lt;&nbsp;10<sup>−15</sup>"
    assert _h_p(3e-8, -7.52) == "3·10<sup>−8</sup>"  # report.page.scientific
    assert _h_p(3e-20, -19.5) == "&lt;&nbsp;10<sup>−15</sup>"


@pytest.fixture(scope="module")
def tiny(table):
    """Errors a tenth of their PL/K: P_MI far below 1e-300 on both axes."""
    small = simulate(SimulationConfig(days=0.1, seed=4, sigma_ratio=0.1, tail_fraction=0.0)).table
    return small, parametric_analysis(small, services=("LPV-200",))


def test_tiny_p_mi_is_shown_from_log10_never_as_zero(tiny):
    _, a = tiny
    v = a.vertical
    assert v.p_mi == 0.0 and v.log10_p_mi < -300  # underflows a float64
    html = parametric_section_html(a)  # no table: the figures from the epochs are skipped
    lead = re.search(r"<p>Kannemans.*?</p>", html, re.S).group(0)
    assert "&lt;&nbsp;10<sup>−15</sup> per epoch" in lead  # below the print floor, never 0
    assert "= 0 per" not in lead
    fits = _rows(html, "parametric-fits")
    assert fits["P MI per epoch"][0] == _h_p(0.0, v.log10_p_mi)
    brief = parametric_brief(a)["vertical"]
    assert brief["p_mi"] == 0.0 and brief["log10_p_mi"] == v.log10_p_mi
    s = v.services["LPV-200"]
    per_exposure = brief["services"]["LPV-200"]["log10_p_hmi_bound_per_exposure"]
    assert per_exposure == pytest.approx(s.log10_p_hmi_bound + math.log10(150.0 / v.interval_s))
    assert brief["services"]["LPV-200"]["meets_integrity"] is True
    assert "Not drawn: timeseries (the epochs are not at hand: no epoch table given" in html


def test_union_bound_per_exposure():
    assert log10_per_exposure(-9.0, 150.0, 1.0) == pytest.approx(-9.0 + math.log10(150.0))
    assert log10_per_exposure(-9.0, 150.0, 30.0) == pytest.approx(-9.0 + math.log10(5.0))
    assert log10_per_exposure(-9.0, 10.0, 30.0) == -9.0  # at least one epoch
    assert log10_per_exposure(-1.0, 3600.0, 1.0) == 0.0  # capped at probability 1
    assert log10_per_exposure(None, 150.0, 1.0) is None


# ---------------------------------------------------------------------------
# figures


def test_ratio_figures(table, analysis):
    a = analysis.vertical
    s = analysed_series(table, a)
    assert s.ratio.size == a.n_epochs and np.all(s.ratio == s.ratio)  # signed, finite
    assert np.any(s.ratio < 0)
    ax = plot_ratio_timeseries(s.time_us, s.ratio, axis="vertical")
    (line,) = _gid(ax, "ratio")
    y = line.get_ydata()
    assert y.size <= 2 * 2000 + 100  # a min/max envelope, not the 43 200 epochs
    assert np.nanmin(y) == s.ratio.min() and np.nanmax(y) == s.ratio.max()
    assert not _gid(ax, "mi-+1")  # |ratio| far below 1: no MI lines
    ax = plot_ratio_probability(s.ratio, a.ratio_fit, axis="vertical", bound=a.ratio_bound_fit)
    (data,) = _gid(ax, "ratio-data")
    x, q = data.get_xdata(), data.get_ydata()
    assert np.all(np.diff(x) >= 0) and x[0] == s.ratio.min() and x[-1] == s.ratio.max()
    assert q[-1] == pytest.approx(special.ndtri((a.n_epochs - 0.3) / (a.n_epochs + 0.4)))
    (fit,) = _gid(ax, "ratio-fit")
    np.testing.assert_allclose(fit.get_xdata(), a.ratio_fit.mean + a.ratio_fit.sigma * fit.get_ydata())
    (bound,) = _gid(ax, "ratio-bound")
    b = a.ratio_bound_fit
    np.testing.assert_allclose(bound.get_xdata(), b.mean + b.sigma * bound.get_ydata())
    h = analysis.horizontal
    hs = analysed_series(table, h)
    ax = plot_ratio_probability(hs.ratio, h.ratio_fit, axis="horizontal")
    (fit,) = _gid(ax, "ratio-fit")
    np.testing.assert_allclose(fit.get_xdata(), h.ratio_fit.sigma * fit.get_ydata())  # through 0
    assert "Rayleigh" in ax.get_title()


def test_weibull_figures(table, analysis):
    a = analysis.vertical
    s = analysed_series(table, a)
    w = a.weibull
    ax = plot_weibull_probability(s.pl, w, axis="vertical", alert_limits={"LPV-200": 35.0, "X": 1e4})
    (fit,) = _gid(ax, "weibull-fit")
    np.testing.assert_allclose(fit.get_ydata(), math.log(w.a) + w.b * np.log(fit.get_xdata()))
    assert _gid(ax, "alert-limit-35") and not _gid(ax, "alert-limit-10000")  # out of range: not drawn
    ax = plot_pl_histogram(s.pl, w, axis="vertical", cov=a.weibull_cov, alert_limits={"LPV-200": 35.0})
    (hist,) = _gid(ax, "pl-histogram")
    dens, edges = hist.get_data().values, hist.get_data().edges
    assert float(np.sum(dens * np.diff(edges))) == pytest.approx(1.0)
    (pdf,) = _gid(ax, "weibull-pdf")
    np.testing.assert_allclose(pdf.get_ydata(), weibull_pdf(w, pdf.get_xdata()))
    assert len(_gid(ax, "weibull-band")) == 1
    lo, hi = weibull_pdf_band(w, a.weibull_cov, pdf.get_xdata(), 0.95)
    assert np.all(lo <= pdf.get_ydata()) and np.all(pdf.get_ydata() <= hi) and np.any(hi > lo)
    no_band = plot_pl_histogram(s.pl, w, axis="vertical")
    assert not _gid(no_band, "weibull-band")


def test_acf_figure_marks_both_decorrelation_times(analysis):
    a = analysis.vertical
    ax = plot_acf_pair(
        a.acf_lags_s, a.ratio_acf, a.pl_acf, axis="vertical",
        ratio_decorrelation_s=a.decorrelation_s, pl_decorrelation_s=a.pl_decorrelation_s,
    )  # fmt: skip
    unit = 3600.0 if "(h)" in ax.get_xlabel() else 1.0
    for gid, tau in (("ratio-decorrelation", a.decorrelation_s), ("pl-decorrelation", a.pl_decorrelation_s)):
        (line,) = _gid(ax, gid)
        assert line.get_xdata()[0] == pytest.approx(tau / unit)
        # the ACF is below 1/e at the decorrelation time (it is read there)
    lags = a.acf_lags_s
    k = int(np.searchsorted(lags, a.decorrelation_s))
    assert a.ratio_acf[k] < math.exp(-1) <= a.ratio_acf[k - 1]
    ax = plot_acf_pair(lags, a.ratio_acf, a.pl_acf, axis="vertical", ratio_decorrelation_s=math.inf,
                       pl_decorrelation_s=a.pl_decorrelation_s)  # fmt: skip
    assert not _gid(ax, "ratio-decorrelation")
    assert any("not reached" in t.get_text() for t in ax.get_legend().get_texts())


def test_contour_figure(analysis):
    a = analysis.vertical
    s = a.services["LPV-200"]
    labels = RegionLabels("u [ub]", "above [ab]", "below [bb]", "hmi [hb]")
    ax = plot_pe_pl_contours(a.ratio_fit, a.weibull, alert_limit=35.0, axis="vertical", labels=labels)
    (cs,) = _gid(ax, "contours")
    expected = [math.log10(v) for v in CONTOUR_LEVELS if v < 1]
    np.testing.assert_allclose(cs.levels, expected)
    (peak,) = _gid(ax, "max")
    x, y = peak.get_xdata()[0], peak.get_ydata()[0]
    grid_x = np.linspace(0, 60, 121)  # the marker sits at the largest density of any coarser grid
    grid = pe_pl_density(a.ratio_fit, a.weibull, np.linspace(1, 60, 119)[:, None], grid_x[None, :])
    assert float(pe_pl_density(a.ratio_fit, a.weibull, y, x)) >= grid.max() * 0.999
    for gid, text in (("region-unavailability", "u [ub]"), ("region-mi-above", "above [ab]"),
                      ("region-mi-below", "below [bb]"), ("region-hmi", "hmi [hb]")):  # fmt: skip
        (t,) = _gid(ax, gid)
        assert text in t.get_text()
    assert _gid(ax, "diagonal") and _gid(ax, "alert-limit-pe") and _gid(ax, "alert-limit-pl")
    assert ax.get_xlim() == (0.0, 60.0) and s.alert_limit == 35.0  # 1.5 AL rounded up to 10 m
    # NPA: AL far above the data, the wedge is still resolved by the refined grid
    ax = plot_pe_pl_contours(
        analysis.horizontal.ratio_fit, analysis.horizontal.weibull, alert_limit=556.0, axis="horizontal",
        labels=labels,
    )  # fmt: skip
    (cs,) = _gid(ax, "contours")
    assert sum(len(p) for p in cs.allsegs) == len(expected) and all(cs.allsegs)


def test_noncontinuity_figure(analysis):
    a = analysis.vertical
    curve = a.continuity_curves[15.0]
    s = a.services["LPV-200"]
    local = [LocalFit("LPV-200", 35.0, s.continuity_local_fit, s.continuity_local_fit_bound, 8e-6)]
    ax = plot_noncontinuity(curve, axis="vertical", fit=a.continuity_fits[15.0],
                            fit_bound=a.continuity_fits_bound[15.0], local=local)  # fmt: skip
    (risk,) = _gid(ax, "risk")
    pos = curve.risk > 0
    np.testing.assert_array_equal(risk.get_xdata(), curve.alert_limit[pos])
    np.testing.assert_array_equal(risk.get_ydata(), curve.risk[pos])
    f = a.continuity_fits[15.0]
    (line,) = _gid(ax, "fit")
    np.testing.assert_allclose(np.log10(line.get_ydata()), f.a + f.b * line.get_xdata())
    (local_line,) = _gid(ax, "local-fit-35")
    assert local_line.get_xdata().min() >= 25.0 - 1e-9 and local_line.get_xdata().max() <= 45.0 + 1e-9
    (mark,) = _gid(ax, "service-35")
    assert mark.get_ydata()[0] == pytest.approx(s.continuity_fit)
    assert _gid(ax, "requirement-8e-06") and _gid(ax, "alert-limit-35")
    assert ax.get_ylim()[0] <= 8e-6


# ---------------------------------------------------------------------------
# HTML


def test_section_figures_alt_and_captions(section):
    for axis, names in FIGURES.items():
        found = re.findall(
            rf'<figure(?: class="wide")?><img src="data:image/png;base64,[^"]+" '
            rf'width="\d+" height="\d+" alt="([^"]+)" '
            rf'data-figure="parametric-{axis}-([a-z0-9-]+)"><figcaption>([^<]+)</figcaption>',
            section,
        )
        assert [n for _, n, _ in found] == names
        for alt, _, caption in found:
            assert len(alt) > 30 and caption.endswith(".")
    assert "Not drawn" not in section
    assert not re.search(r"""(?:src|href)\s*=\s*["'](?!data:image/png;base64,)""", section)


def test_section_summary_verdicts_and_tables(analysis, section):
    assert re.findall(r'<section id="([a-z-]+)">', section) == list(AXIS_IDS)
    levels = {s.name: s for s in analysis.services}
    for axis in ("vertical", "horizontal"):
        a = analysis.axis(axis)
        part = section.split(f'<section id="parametric-{axis}">')[1].split("</section>")[0]
        summary = _rows(part, "parametric-summary")
        expected = [n for n, s in a.services.items() if s is not None]
        assert list(summary) == expected
        badges = re.findall(r'<span class="badge (\w+)" data-kpi="([^"]+)"', part)
        kind = {True: "within", False: "above", None: "na"}
        want = []
        for name in expected:
            v = service_verdicts(a, levels[name])
            want += [(kind[v[k]], f"{name}-{k}") for k in ("integrity", "availability", "continuity")]
        assert badges == want
        for name in expected:
            s = a.services[name]
            row = _rows(part, "parametric-services")[name]
            assert row[3] == f"{_h_p(s.p_hmi, s.log10_p_hmi)} [{_h_p(s.p_hmi_bound, s.log10_p_hmi_bound)}]"
            assert f"{s.continuity_n_fail:,} of {s.continuity_n_windows:,} windows" in row[6]
    v = analysis.vertical
    assert "no alert limit on this axis: NPA" in _text(section)
    fits = _rows(section, "parametric-fits")
    assert fits["decorrelation time of VPE/VPL"][0] == f"{v.decorrelation_s:g}&nbsp;s"
    assert fits["epochs fitted"][0] == f"{v.n_epochs:,}"


def test_verdict_rules(analysis):
    a = analysis.vertical
    lvl = next(s for s in analysis.services if s.name == "LPV-200")
    s = a.services["LPV-200"]
    v = service_verdicts(a, lvl)
    assert v["availability"] == (s.unavailability_bound <= 0.01)
    assert v["continuity"] == (s.continuity_fit_bound <= 8e-6)
    n = 150.0 / a.interval_s
    assert v["integrity"] == (s.log10_p_hmi_bound + math.log10(n) <= math.log10(2e-7))
    loose = dataclasses.replace(lvl, continuity_risk=1.0, availability=0.0)  # any bound meets these
    assert service_verdicts(a, loose)["continuity"] is True and service_verdicts(a, loose)["availability"]
    npa = next(s for s in analysis.services if s.name == "NPA")
    assert service_verdicts(a, npa) == {}  # no VAL


def test_standalone_page_is_self_contained_and_deterministic(table, analysis, section, tmp_path):
    path = write_parametric_report(analysis, tmp_path, table=table)
    assert path == tmp_path / REPORT_NAME
    page = path.read_text(encoding="utf-8")
    # the sections drawn a second time are the same bytes: no timestamp, deterministic PNGs
    assert page.startswith("<!DOCTYPE html>") and section in page
    assert page.count("<img ") == sum(len(v) for v in FIGURES.values())
    assert "<script" not in page and "<link" not in page
    assert not re.search(r"""(?:src|href|action)\s*=\s*(?!["']?(?:data:image/png;base64,|#))""", page)


def test_figures_need_the_analysed_table(table, analysis):
    other = table.with_columns(pl.col("vpe") * 1.01)  # another table: its ratio fit differs
    assert analysed_series(other, analysis.vertical) is None
    assert analysed_series(table.head(1000), analysis.vertical) is None
    assert analysed_series(table.drop("vpl"), analysis.vertical) is None
    assert analysed_series(table, analysis.horizontal) is not None


def test_failed_axis_says_why(table):
    no_h = table.with_columns(hpe=pl.lit(float("nan")), hpl=pl.lit(float("nan")))
    a = parametric_analysis(no_h.head(3000), services=("LPV-200",))
    assert a.horizontal is None and a.vertical is not None
    html = parametric_section_html(a)
    part = html.split('<section id="parametric-horizontal">')[1]
    assert "No parametric estimate: " + a.reasons["horizontal"].replace("<", "&lt;") in part
    brief = parametric_brief(a)["horizontal"]
    assert brief["p_mi"] is None and brief["unavailable_reason"] == a.reasons["horizontal"]


def test_report_html_and_summary_brief(table, tiny):
    """analyze(parametric=True) adds both sections after EVT, the nav links, and the brief."""
    small, _ = tiny
    base = analyze(small, services=["LPV-200"])
    assert base.parametric is None and summary_dict(base)["parametric"] == {}
    assert "parametric-vertical" not in section_ids(base)
    a = analyze(small, services=["LPV-200"], parametric=True)
    ids = section_ids(a)
    at = ids.index("parametric-vertical")
    assert ids[at : at + 3] == (*AXIS_IDS, "time-series")
    page = render_report(a)
    assert re.findall(r'<section id="(parametric-[a-z]+)">', page) == list(AXIS_IDS)
    assert 'href="#parametric-vertical"' in page and 'href="#parametric-horizontal"' in page
    drawn = re.findall(r'data-figure="parametric-vertical-([a-z0-9-]+)"', page)
    assert drawn == [n for n in FIGURES["vertical"] if "timeseries" not in n]  # the report has its own
    assert summary_dict(a)["parametric"] == parametric_brief(a.parametric)
