"""report.html: sections, figures, badges, read reports, escaping, and byte-identical reruns."""

from __future__ import annotations

import base64
import dataclasses
import functools
import re
import struct
from html.parser import HTMLParser

import numpy as np
import polars as pl
import pytest

from overbound.analysis import Analysis, analyze, verdicts
from overbound.io.schema import ReadReport
from overbound.report.html import REPORT_NAME, render_report, section_ids, service_groups, write_report
from overbound.report.json import summary_dict

T0 = np.datetime64("2006-12-27T00:00:00", "us")
N = 3600


def epochs(*, n: int = N, step_s: int = 1, station: str = "SYN", fail: bool = False) -> pl.DataFrame:
    """One station at ``step_s`` sampling that meets every LPV-200 requirement, or fails four of them.

    Failing: VPL 40 m (> VAL 35 m) on epochs 1000-1099, |VPE| 6 m (> 4 m at 95 %), and one
    horizontal HMI epoch (HPE 45 m, HPL 30 m, HAL 40 m) at epoch 2000.
    """
    hpe = np.full(n, 1.0)
    hpl = np.full(n, 15.0)
    vpl = np.full(n, 20.0)
    vpe = np.where(np.arange(n) % 2 == 0, 1.5, -1.5)
    if fail:
        vpl[1000:1100] = 40.0
        vpe *= 4.0
        hpe[2000], hpl[2000] = 45.0, 30.0
    time = T0 + (np.arange(n) * step_s * 1_000_000).astype("timedelta64[us]")
    return pl.DataFrame({"time": time, "station": station, "hpe": hpe, "vpe": vpe, "hpl": hpl, "vpl": vpl})


class Page(HTMLParser):
    """The parts of the report the tests look at."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.sections: list[str] = []
        self.h2: dict[str, str] = {}
        self.imgs: list[dict[str, str]] = []
        self.badges: dict[str, list[tuple[str, str]]] = {}  # section -> (data-kpi, class)
        self.tables: dict[str, list[list[str]]] = {}  # "<section>/<table class>" -> rows of cell text
        self.facts: dict[str, str] = {}  # <dt> -> <dd> of the overview
        self._dt = ""
        self._section = ""
        self._table = ""
        self._cell: list[str] | None = None
        self._row: list[str] = []
        self._in_h2 = False
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        a = {k: v or "" for k, v in attrs}
        if tag == "section":
            self._section = a["id"]
            self.sections.append(a["id"])
        elif tag == "h2":
            self._in_h2 = True
            self.h2[self._section] = ""
        elif tag == "img":
            self.imgs.append(a | {"section": self._section})
        elif tag == "span" and "badge" in a.get("class", ""):
            self.badges.setdefault(self._section, []).append((a["data-kpi"], a["class"].split()[1]))
        elif tag == "table":
            self._table = f"{self._section}/{a.get('class', '')}"
            self.tables[self._table] = []
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th", "dt", "dd"):
            self._cell = []
        elif tag == "br" and self._cell is not None:
            self._cell.append(" ")

    def handle_endtag(self, tag):
        if tag == "h2":
            self._in_h2 = False
        elif tag in ("td", "th", "dt", "dd") and self._cell is not None:
            cell = " ".join("".join(self._cell).replace("\xa0", " ").split())
            self._cell = None
            if tag == "dt":
                self._dt = cell
            elif tag == "dd":
                self.facts.setdefault(self._dt, cell)
            else:
                self._row.append(cell)
        elif tag == "tr":
            self.tables[self._table].append(self._row)

    def handle_data(self, data):
        if self._in_h2:
            self.h2[self._section] += data
        if self._cell is not None:
            self._cell.append(data)

    def row(self, table: str, first: str, second: str | None = None) -> list[str]:
        rows = [r for r in self.tables[table] if r[0] == first and (second is None or r[1] == second)]
        assert len(rows) == 1, (table, first, second, rows)
        return rows[0]


SERVICES = ["NPA", "LPV-200", "TEST:25:30"]
# one LPV-200 station per case: passes everything, fails four KPIs, or too sparse to count continuity
CASES = {
    "pass": {},
    "fail": {"fail": True},
    "continuity-not-countable": {"n": 240, "step_s": 30},
}


@functools.cache
def lpv200(case: str) -> tuple[Analysis, Page]:
    """The analysis of ``CASES[case]`` and its rendered page (rendered once per test session)."""
    a = analyze(epochs(**CASES[case]), services=["LPV-200"])
    return a, Page(render_report(a))


@pytest.fixture(scope="module")
def analysis():
    table = pl.concat([epochs(station="AAAA"), epochs(station="BBBB", fail=True)])
    return analyze(table, services=SERVICES, title="two stations <synthetic> & co")


@pytest.fixture(scope="module")
def text(analysis):
    return render_report(analysis)


@pytest.fixture(scope="module")
def page(text):
    return Page(text)


def test_every_section_with_its_heading(analysis, page):
    assert page.sections == list(section_ids(analysis))
    assert page.sections == [
        "verdicts", "overview", "accuracy", "stations", "service-NPA", "service-LPV-200", "service-TEST",
        "time-series", "method-notes", "summary-data",
    ]  # fmt: skip
    assert [page.h2[s] for s in page.sections] == [
        "Verdicts", "Overview", "Accuracy", "Stations", "NPA", "LPV-200", "TEST", "Time series",
        "Method notes",
        "Summary data",
    ]  # fmt: skip


def test_every_figure_once_with_alt_text(analysis, page):
    # Stanford diagrams: services x axes (NPA has no vertical), plus 2 time series and 2 SI histograms
    expected = {
        "stanford-NPA-horizontal": "service-NPA",
        "stanford-LPV-200-horizontal": "service-LPV-200",
        "stanford-LPV-200-vertical": "service-LPV-200",
        "stanford-TEST-horizontal": "service-TEST",
        "stanford-TEST-vertical": "service-TEST",
        "timeseries-horizontal": "time-series",
        "timeseries-vertical": "time-series",
        "safety-index-horizontal": "time-series",
        "safety-index-vertical": "time-series",
    }
    assert len(page.imgs) == sum(1 + (s.val is not None) for s in analysis.services) + 4 == 9
    assert {img["data-figure"]: img["section"] for img in page.imgs} == expected
    for img in page.imgs:
        assert len(img["alt"]) > 40
        head, data = img["src"].split(",", 1)
        assert head == "data:image/png;base64"
        png = base64.b64decode(data, validate=True)
        assert png[:8] == b"\x89PNG\r\n\x1a\n"
        assert struct.unpack(">II", png[16:24]) == (int(img["width"]), int(img["height"]))


def test_self_contained(text):
    """Nothing loaded from elsewhere; the one script is the inline sorter of the station table."""
    from overbound.report.network import SORTABLE_SCRIPT

    assert text.count(SORTABLE_SCRIPT) == 1  # two stations: the station table is sortable
    text = text.replace(SORTABLE_SCRIPT, "")
    assert not re.search(r"""(?:src|href|action)\s*=\s*(?!["']?(?:data:image/png;base64,|#))""", text)
    for needle in ("<script", "<link", "<iframe", "url(", "@import", "http://", "https://"):
        assert needle not in text.lower()


def test_text_is_escaped(page, text):
    assert "<synthetic>" not in text
    assert "two stations &lt;synthetic&gt; &amp; co" in text
    assert page.h2["overview"] == "Overview"


def test_overview_facts_and_no_reader(page):
    assert page.facts["Epochs"] == "7,200"
    assert page.facts["Stations"] == "AAAA, BBBB"
    assert page.facts["with a solution"] == "7,200 (100 %)"
    assert page.facts["without a solution"] == "0 (0 %)"
    assert page.facts["Time span (GPS)"] == "2006-12-27T00:00:00.000 – 2006-12-27T00:59:59.000 (00:59:59)"
    # the rejected-rows table is there even when no reader ran
    assert page.tables["overview/drops"][1:] == [["epoch table", "none", "no reader ran", "0"]]


def test_read_reports_and_rejected_rows():
    analysis, _ = lpv200("pass")
    reports = (
        ReadReport(
            "day1.pos", "rtklib-pos", 3610, 3600,
            {"malformed line": 7, "duplicate time": 3}, {"negative PL": 2},
            "17: malformed line: expected 15 fields, got 11", ("reference 35.311803,-120.661092,134.6419",),
        ),
        ReadReport("day2.pos", "rtklib-pos", 3600, 3600),
    )  # fmt: skip
    page = Page(render_report(dataclasses.replace(analysis, reports=reports)))
    assert page.facts["Rows rejected while reading"] == "10"
    assert page.row("overview/", "day1.pos") == [
        "day1.pos", "rtklib-pos", "3,610", "3,600", "10", "2",
        "17: malformed line: expected 15 fields, got 11", "reference 35.311803,-120.661092,134.6419",
    ]  # fmt: skip
    assert page.row("overview/", "day2.pos") == [
        "day2.pos",
        "rtklib-pos",
        "3,600",
        "3,600",
        "0",
        "0",
        "none",
        "",
    ]
    assert page.tables["overview/drops"][1:] == [
        ["day1.pos", "rejected (removed)", "duplicate time", "3"],
        ["day1.pos", "rejected (removed)", "malformed line", "7"],
        ["day1.pos", "invalidated (kept as no solution)", "negative PL", "2"],
        ["day2.pos", "none", "no row rejected or invalidated", "0"],
        ["Total", "", "", "10 rejected, 2 invalidated"],
    ]


def test_accuracy_table(page):
    # HPE 1 m but one 45 m epoch; |VPE| 1.5 m on one station, 6 m on the other
    assert page.row("accuracy/", "Horizontal")[:5] == [
        "Horizontal",
        "1.00 m",
        "7,200",
        "1.5000",
        "2006-12-27 00:33:20.000",
    ]
    assert page.row("accuracy/", "Vertical")[:4] == ["Vertical", "6.00 m", "7,200", "0.3000"]


BADGE = {True: "within", False: "above", None: "na"}


@pytest.mark.parametrize(
    ("case", "kinds"),
    [
        ("pass", ["within", "within", "within", "within"]),
        ("fail", ["above", "above", "within", "above", "above"]),
        ("continuity-not-countable", ["within", "na", "within", "within"]),
    ],
)
def test_badges_follow_verdicts(case, kinds):
    a, page = lpv200(case)
    kpis = [
        "availability (combined)",
        "continuity risk (combined)",
        "HPE95 (m)",
        "|VPE|95 (m)",
        "HMI epochs (counted)",  # a badge only when HMI was observed: a count never shows a pass
    ]
    assert page.badges["service-LPV-200"] == list(zip(kpis, kinds, strict=False))
    assert page.badges["service-LPV-200"] == [
        (v.kpi, BADGE[v.passed])
        for v in verdicts(a, a.services[0])
        if v.passed is not None or not v.kpi.endswith("(counted)")
    ]


def test_kpi_table_of_a_failing_service():
    _, page = lpv200("fail")
    rows = page.tables["service-LPV-200/kpi"]
    assert rows[0] == ["KPI", "Axis", "Value", "Counts / note", "Requirement", "Estimate vs requirement"]
    lost = (
        "windows of 15 s lost service; 0 touched by data gaps; 15 cut by the end of data (not counted); "
        "sampling 1 s"
    )
    assert rows[1:] == [
        ["Availability", "horizontal", "100 %", "3,600 of 3,600 epochs with PL below AL", "—", "—"],
        ["Availability", "vertical", "97.22 %", "3,500 of 3,600 epochs with PL below AL", "—", "—"],
        [
            "Availability", "combined", "97.22 %", "3,500 of 3,600 epochs with PL below AL", "≥ 99 %",
            "outside",
        ],
        ["Continuity risk", "horizontal", "0", f"0 of 3,585 {lost}", "—", "—"],
        # VPL above VAL on epochs 1000-1099: the windows starting at 985..999 fail
        ["Continuity risk", "vertical", "0.004304", f"15 of 3,485 {lost}", "—", "—"],
        ["Continuity risk", "combined", "0.004304", f"15 of 3,485 {lost}", "≤ 8·10−6", "outside"],
        ["HPE95", "horizontal", "1.00 m", "over the 3,600 epochs with a solution", "≤ 16 m", "within"],
        ["|VPE|95", "vertical", "6.00 m", "over the 3,600 epochs with a solution", "≤ 4 m", "outside"],
        [
            "MI epochs (counted)", "both", "1",
            "PE > PL while PL < AL (HMI included); the PL-bounding verdict (2e-07 per 150 s) weighs "
            "the count with the tail models: see the verdicts",
            "—", "see the verdicts",
        ],
        ["HMI epochs (counted)", "both", "1", "an observed HMI is an integrity fail", "≤ 0", "outside"],
    ]  # fmt: skip
    stanford = page.tables["service-LPV-200/stanford"]
    # columns: axis, AL, normal, MI, HMI, unavailable, unavailable & MI, no solution, total, beyond plot
    assert stanford[1:] == [
        ["Horizontal", "40 m", "3,599 99.97 %", "0 0 %", "1 0.03 %", "0 0 %", "0 0 %", "0 0 %", "3,600", "0"],
        ["Vertical", "35 m", "3,500 97.22 %", "0 0 %", "0 0 %", "100 2.78 %", "0 0 %", "0 0 %", "3,600", "0"],
    ]


def test_continuity_reason_when_not_countable():
    _, page = lpv200("continuity-not-countable")
    row = page.row("service-LPV-200/kpi", "Continuity risk", "combined")
    assert row == [
        "Continuity risk", "combined", "n.a.",
        "not counted: sampling interval 30 s exceeds the 15 s exposure time", "≤ 8·10−6", "n.a.",
    ]  # fmt: skip


def test_npa_has_one_stanford_diagram_and_no_vertical_rows(page):
    rows = page.tables["service-NPA/kpi"]
    assert [r[1] for r in rows[1:]] == [
        "horizontal",
        "combined",
        "horizontal",
        "combined",
        "horizontal",
        "both",
        "both",
    ]
    assert [r[0] for r in page.tables["service-NPA/stanford"][1:]] == ["Horizontal"]


def test_byte_identical_reruns(tmp_path, text):
    # a second run from scratch: new table, new analysis, summary passed in, written to a file
    table = pl.concat([epochs(station="AAAA"), epochs(station="BBBB", fail=True)])
    again = analyze(table, services=SERVICES, title="two stations <synthetic> & co")
    path = write_report(again, tmp_path / "out", summary=summary_dict(again))
    assert path == tmp_path / "out" / REPORT_NAME
    assert path.read_bytes() == text.encode("utf-8")


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize(
    ("table", "n_epochs"),
    [
        (epochs().clear(), "0"),
        (epochs(n=1), "1"),
        (epochs().with_columns(vpe=pl.lit(float("nan")), vpl=pl.lit(float("nan"))), "3,600"),
    ],
    ids=["no-epochs", "one-epoch", "no-vertical-solution"],
)
def test_degenerate_tables_still_give_every_section(table, n_epochs):
    a = analyze(table, services=["NPA", "APV-I"])
    page = Page(render_report(a))
    assert page.sections == list(section_ids(a))
    assert page.facts["Epochs"] == n_epochs
    assert len(page.imgs) == 1 + 2 + 4


def test_gh2_stations_section_for_several_stations(tmp_path):
    """Several stations: per-station KPIs in the report and in summary.json."""
    import datetime as dt

    import numpy as np
    import polars as pl

    from overbound.analysis import analyze
    from overbound.report.html import render_report, section_ids
    from overbound.report.json import summary_dict

    n = 600
    t0 = dt.datetime(2024, 1, 7)
    frames = []
    for name, vpl in (("A", 10.0), ("B", 60.0)):
        frames.append(
            pl.DataFrame(
                {
                    "time": [t0 + dt.timedelta(seconds=i) for i in range(n)],
                    "station": [name] * n,
                    "hpe": np.ones(n),
                    "vpe": np.ones(n),
                    "hpl": np.full(n, 10.0),
                    "vpl": np.full(n, vpl),
                }
            )
        )
    a = analyze(pl.concat(frames), services=["LPV"])
    assert "stations" in section_ids(a)
    page = render_report(a)
    assert '<section id="stations">' in page
    doc = summary_dict(a)
    assert doc["stations"]["A"]["services"]["LPV"]["availability"]["combined"] == 1.0
    assert doc["stations"]["B"]["services"]["LPV"]["availability"]["combined"] == 0.0
    assert doc["services"]["LPV"]["availability"]["combined"] == 0.5
    assert doc["stations"]["B"]["epochs"] == {"total": n, "with_solution": n}


def test_services_sharing_every_number_share_one_section():
    a = analyze(epochs(), services=["APV-I", "LPV", "LPV-200"])
    assert [[s.name for s in g] for g in service_groups(a.services)] == [["APV-I", "LPV"], ["LPV-200"]]
    text = render_report(a)
    page = Page(text)
    assert [s for s in page.sections if s.startswith("service-")] == ["service-APV-I", "service-LPV-200"]
    assert page.h2["service-APV-I"] == "APV-I and LPV"
    assert '<span id="service-LPV"></span>' in text  # links to LPV still land on its numbers
    assert "TTA APV-I 10 s, LPV 6 s" in text
