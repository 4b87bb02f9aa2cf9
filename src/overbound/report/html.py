"""``report.html``: one self-contained, offline, printable page of an analysis.

The page holds its figures as base64 PNG data URIs and its style as inline CSS; it
loads nothing (no links, scripts or fonts), so it opens offline and can be archived
or mailed as one file. The same :class:`~overbound.analysis.Analysis` gives the same
bytes on every run: there is no timestamp, and the PNGs carry no software or date
metadata.

Sections (each a ``<section id=...>`` with an ``<h2>``): ``overview``, ``accuracy``,
``stations`` (only for several stations), one ``service-<name>`` per service level,
one ``confidence-<axis>`` per PL confidence-level axis, one ``evt-<axis>`` per EVT axis (an axis
that could not be analysed says why), ``parametric-vertical`` and ``parametric-horizontal`` when the
parametric analysis ran, ``time-series``, ``method-notes`` and ``summary-data`` (the
``summary.json`` document, folded).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from overbound import __version__
from overbound.analysis import Analysis, Verdict, verdicts
from overbound.io.gpstime import utc_iso
from overbound.methods.counting import (
    AXES,
    SAFETY_PERCENTILES,
    AxisKPI,
    ContinuityResult,
    CountingResult,
    Region,
    ServiceKPI,
)
from overbound.methods.tail_extrapolation import TailAnalysis
from overbound.numbers import format_share
from overbound.report.confidence import confidence_section_html
from overbound.report.evt import analysed_series, evt_failure_html, evt_section_html
from overbound.report.figures import (
    REGION_COLOURS,
    REGION_LABELS,
    plot_safety_index,
    plot_stanford,
    plot_timeseries,
)
from overbound.report.json import base_names, dumps, summary_dict
from overbound.report.network import SORTABLE_SCRIPT, network_section_html
from overbound.report.page import PAGE_CSS, escape, figure_html, scientific, section_html
from overbound.report.parametric import parametric_section_html
from overbound.report.parametric import section_ids as parametric_ids
from overbound.report.rendering import resolve_figures
from overbound.report.verdicts import VERDICT_CSS, verdict_section
from overbound.services import ServiceLevel
from overbound.verdict import Assessment, assess

__all__ = ["REPORT_NAME", "render_report", "section_ids", "write_report"]

#: File name written by :func:`write_report`.
REPORT_NAME = "report.html"
_AXIS_NAMES = {"horizontal": "Horizontal", "vertical": "Vertical", "combined": "Combined"}
_PE = {"horizontal": "HPE", "vertical": "|VPE|"}
_PL = {"horizontal": "HPL", "vertical": "VPL"}


def write_report(
    analysis: Analysis,
    directory: str | Path,
    *,
    summary: dict | None = None,
    assessment: Assessment | None = None,
) -> Path:
    """Write ``report.html`` into ``directory`` (created if needed); return its path.

    Parameters
    ----------
    analysis : the result of :func:`~overbound.analysis.analyze`.
    directory : output folder.
    summary : the ``summary.json`` document of the same analysis
        (:func:`~overbound.report.json.summary_dict`), embedded folded at the end of the
        page; computed when ``None``. The tables themselves are drawn from ``analysis``.

    Returns
    -------
    Path
        ``directory / "report.html"``.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / REPORT_NAME
    path.write_bytes(render_report(analysis, summary=summary, assessment=assessment).encode("utf-8"))
    return path


def section_ids(analysis: Analysis) -> tuple[str, ...]:
    """The ``id`` of every ``<section>`` of the report of ``analysis``, in page order."""
    return (
        "verdicts",
        "overview",
        "accuracy",
        *(("stations",) if analysis.counting.by_station else ()),
        *(("network",) if analysis.network is not None else ()),
        *(_service_id(group[0]) for group in service_groups(analysis.services)),
        *(f"confidence-{c.axis}" for c in analysis.confidence),
        *(f"{method}-{axis}" for method, axis, _ in analysis.method_failures),
        *(f"evt-{axis}" for axis, _ in _evt_items(analysis)),
        *(parametric_ids() if analysis.parametric is not None else ()),
        "time-series",
        "method-notes",
        "summary-data",
    )


def render_report(
    analysis: Analysis, *, summary: dict | None = None, assessment: Assessment | None = None
) -> str:
    """The text of ``report.html`` (see :func:`write_report`): the verdicts first, then the details."""
    if assessment is None and analysis.evidence is not None:
        assessment = assess(analysis)
    doc = summary if summary is not None else summary_dict(analysis, assessment=assessment)
    c = analysis.counting
    body = [
        _header(analysis),
        verdict_section(assessment) if assessment is not None else _no_verdicts(),
        _overview(analysis),
        _accuracy(c),
        *((_stations(analysis),) if c.by_station else ()),
        *((_network(analysis, doc["network"]),) if analysis.network is not None else ()),
        *(_service(analysis, group) for group in service_groups(analysis.services)),
        *(confidence_section_html(c) for c in analysis.confidence),
        *(_failure_section(*failure) for failure in analysis.method_failures),
        *(_evt_section(analysis, axis, item) for axis, item in _evt_items(analysis)),
        *(
            # a dataset's analysis gathers no epochs: the figures drawn from them are left out
            (parametric_section_html(analysis.parametric, _epochs(analysis), timeseries=False),)
            if analysis.parametric is not None
            else ()
        ),
        _time_series(analysis),
        _method_notes(c),
        _section(
            "summary-data",
            "Summary data",
            "<p>The machine-readable summary of this analysis (schema "
            f"<code>{_e(str(doc.get('schema', '')))}</code>), as written to <code>summary.json</code>.</p>"
            f"<details><summary>summary.json</summary><pre>{_e(dumps(doc))}</pre></details>",
        ),
    ]
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        f'<meta name="generator" content="overbound {_e(__version__)}">\n'
        f"<title>{_e(analysis.title)} — overbound integrity report</title>\n"
        f"<style>{PAGE_CSS}{VERDICT_CSS}</style>\n</head>\n<body>\n<main>\n"
        + resolve_figures("\n".join(body))
        + "\n</main>\n"
        + (SORTABLE_SCRIPT + "\n" if c.by_station else "")
        + "</body>\n</html>\n"
    )


# ---------------------------------------------------------------------------
# formatting: every _h_* function returns HTML; everything else is escaped with _e


_e = escape


def _h_int(n: int | None) -> str:
    return "n.a." if n is None else f"{n:,}"


def _h_m(x: float | None, digits: int = 2) -> str:
    return "n.a." if x is None or not math.isfinite(x) else f"{x:.{digits}f}&nbsp;m"


def _h_ratio(x: float | None) -> str:
    """A safety index PE/PL to four decimals."""
    return "n.a." if x is None or not math.isfinite(x) else f"{x:.4f}"


def _h_share(x: float) -> str:
    """A requirement share (0.99) as a percentage without needless digits."""
    return f"{100 * x:.10g}&nbsp;%"


def _h_badge(passed: bool | None, kpi: str, note: str = "") -> str:
    # the point estimate against the requirement; the verdicts (with bounds) open the report
    kind, text = {True: ("within", "within"), False: ("above", "outside"), None: ("na", "n.a.")}[passed]
    title = f' title="{_e(note)}"' if note else ""
    return f'<span class="badge {kind}" data-kpi="{_e(kpi)}"{title}>{text}</span>'


class _Num(str):
    """An HTML table cell holding a number (right-aligned)."""


def _num(cell: str) -> _Num:
    return _Num(cell)


def _section(sid: str, title: str, content: str) -> str:
    return section_html(sid, title, [content])


def _table(head: list[str], rows: list[list[str]], *, cls: str = "", caption: str = "") -> str:
    """A table from HTML cells; :func:`_num` cells are right-aligned (numbers)."""

    def cell(tag: str, c: str) -> str:
        return f'<{tag} class="num">{c}</{tag}>' if isinstance(c, _Num) else f"<{tag}>{c}</{tag}>"

    cap = f"<caption>{caption}</caption>" if caption else ""
    thead = "<tr>" + "".join(cell("th", h) for h in head) + "</tr>"
    tbody = "\n".join("<tr>" + "".join(cell("td", c) for c in r) + "</tr>" for r in rows)
    cls_attr = f' class="{cls}"' if cls else ""
    return f"<table{cls_attr}>{cap}<thead>{thead}</thead>\n<tbody>\n{tbody}\n</tbody></table>"


def _service_id(s: ServiceLevel) -> str:
    return "service-" + "-".join(s.name.split())


# ---------------------------------------------------------------------------
# figures


def _render(ax, name: str, alt: str, caption: str) -> str:
    return figure_html(ax, name=name, alt=alt, caption=caption)


# ---------------------------------------------------------------------------
# sections


def _header(a: Analysis) -> str:
    links = "".join(
        f'<li><a href="#{_e(sid)}">{_e(label)}</a></li>'
        for sid, label in [
            ("verdicts", "Verdicts"),
            ("overview", "Overview"),
            ("accuracy", "Accuracy"),
            *((("stations", "Stations"),) if a.counting.by_station else ()),
            *((("network", "Network"),) if a.network is not None else ()),
            *((_service_id(g[0]), " and ".join(s.name for s in g)) for g in service_groups(a.services)),
            *((f"confidence-{c.axis}", f"{c.axis.capitalize()} PL confidence") for c in a.confidence),
            *((f"{m}-{axis}", _failure_label(m, axis)) for m, axis, _ in a.method_failures),
            *((f"evt-{axis}", f"{axis.capitalize()} EVT") for axis, _ in _evt_items(a)),
            *(
                (sid, f"{sid.removeprefix('parametric-').capitalize()} parametric")
                for sid in (parametric_ids() if a.parametric is not None else ())
            ),
            ("time-series", "Time series"),
            ("method-notes", "Method notes"),
            ("summary-data", "Summary data"),
        ]
    )
    return (
        f'<header><p class="kicker">GNSS integrity verification report</p><h1>{_e(a.title)}</h1>'
        f'<p class="sub">overbound {_e(__version__)} · verdicts for '
        f"{_e(', '.join(s.name for s in a.services))} · all times GPS time</p>"
        + (f'<p class="sub">{_e(a.truth["statement"])}</p>' if a.truth else "")
        + "".join(f'<p class="warning" role="alert">{_e(w)}</p>' for w in a.warnings)
        + "</header>"
        f'<nav class="sticky" aria-label="Contents"><ul>{links}</ul></nav>'
    )


_FAILED_METHOD = {
    "confidence": "PL confidence level (Comby et al. 2003)",
    "parametric": "Parametric availability, integrity and continuity (Kannemans 2006)",
}


def _failure_label(method: str, axis: str) -> str:
    """The contents link of a failed method: ``Vertical PL confidence (failed)``."""
    what = {"confidence": "PL confidence"}.get(method, method)
    return f"{what.capitalize() if axis == 'both' else f'{axis.capitalize()} {what}'} (failed)"


def _failure_section(method: str, axis: str, reason: str) -> str:
    """The section of a method that could not run on this input: which stage failed, and why."""
    title = _FAILED_METHOD.get(method, method) + ("" if axis == "both" else f", {axis}")
    return _section(
        f"{method}-{axis}",
        title,
        f'<p class="alarm">Not computed: a numerical step failed on this input ({_e(reason)}). '
        "The other sections do not depend on it; its evidence is missing from the verdicts.</p>",
    )


def _evt_items(a: Analysis) -> list[tuple[str, TailAnalysis | str]]:
    """``(axis, TailAnalysis or the reason it failed)``, vertical first."""
    items = [(t.axis, t) for t in a.evt] + list(a.evt_failures)
    return sorted(items, key=lambda item: item[0] != "vertical")


def _evt_section(a: Analysis, axis: str, item: TailAnalysis | str) -> str:
    if isinstance(item, str):
        return evt_failure_html(axis, item)
    return evt_section_html(item, series=analysed_series(a.table, item))


def _duration(start: str | None, end: str | None) -> str:
    if not start or not end:
        return "n.a."
    seconds = float((np.datetime64(end, "ms") - np.datetime64(start, "ms")) / np.timedelta64(1, "s"))
    days, rest = divmod(seconds, 86400.0)
    hours, rest = divmod(rest, 3600.0)
    minutes, secs = divmod(rest, 60.0)
    text = f"{int(hours):02d}:{int(minutes):02d}:{secs:06.3f}".removesuffix(".000")
    return f"{int(days)} d {text}" if days else text


def _overview(a: Analysis) -> str:
    c = a.counting
    no_sol = c.n_total - c.n_with_solution
    facts = [
        (
            "Time span (GPS)",
            f"{_e(c.start or 'n.a.')} – {_e(c.end or 'n.a.')} ({_e(_duration(c.start, c.end))})",
        ),
        ("Time span (UTC)", f"{_e(utc_iso(c.start) or 'n.a.')} – {_e(utc_iso(c.end) or 'n.a.')}"),
        (f"Station{'s' if len(c.stations) != 1 else ''}", _e(", ".join(c.stations) or "none")),
        ("Epochs", f"{c.n_total:,}"),
        ("with a solution", f"{c.n_with_solution:,} ({format_share(c.n_with_solution, c.n_total)})"),
        ("without a solution", f"{no_sol:,} ({format_share(no_sol, c.n_total)})"),
        ("Rows rejected while reading", f"{a.n_rejected:,}"),
        ("Service levels", _e(", ".join(s.name for s in a.services))),
    ]
    dl = '<dl class="facts">' + "".join(f"<dt>{_e(k)}</dt><dd>{v}</dd>" for k, v in facts) + "</dl>"
    if a.reports:
        inputs = _table(
            [
                "Input",
                "Format",
                _num("Rows read"),
                _num("Rows kept"),
                _num("Rejected"),
                _num("Invalidated"),
                "First bad line",
                "Notes",
            ],
            [
                [
                    f"<code>{_e(base_names(r.source))}</code>",
                    _e(r.format),
                    _num(f"{r.rows_read:,}"),
                    _num(f"{r.rows_kept:,}"),
                    _num(f"{r.n_rejected:,}"),
                    _num(f"{sum(r.invalidated.values()):,}"),
                    _e(r.first_bad or "none"),
                    "<br>".join(_e(n) for n in r.notes),
                ]
                for r in a.reports
            ],
        )
        drops = []
        for r in a.reports:
            rows = [("rejected (removed)", k, v) for k, v in sorted(r.rejected.items())]
            rows += [("invalidated (kept as no solution)", k, v) for k, v in sorted(r.invalidated.items())]
            if not rows:
                rows = [("none", "no row rejected or invalidated", 0)]
            drops += [
                [f"<code>{_e(base_names(r.source))}</code>", _e(kind), _e(reason), _num(f"{n:,}")]
                for kind, reason, n in rows
            ]
        total_inv = sum(sum(r.invalidated.values()) for r in a.reports)
        drops.append(
            [
                "<strong>Total</strong>",
                "",
                "",
                _num(f"<strong>{a.n_rejected:,} rejected, {total_inv:,} invalidated</strong>"),
            ]
        )
    else:
        inputs = "<p>The epoch table was passed to the analysis directly: there is no reader report.</p>"
        drops = [["epoch table", "none", "no reader ran", _num("0")]]
    drop_table = _table(
        ["Input", "Kind", "Reason", _num("Rows")],
        drops,
        cls="drops",
        caption="Rejected rows are removed from the table; invalidated rows stay as epochs without a "
        "solution and count as unavailable. Every row the readers did not keep as read is counted here.",
    )
    return _section(
        "overview",
        "Overview",
        f"{dl}\n<h3>Inputs</h3>\n{inputs}\n<h3>Rejected and invalidated rows</h3>\n{drop_table}",
    )


def _accuracy(c: CountingResult) -> str:
    keys = [f"p{p:g}" for p in SAFETY_PERCENTILES]
    rows = []
    for axis, p95 in (("horizontal", c.hpe95), ("vertical", c.vpe95)):
        si = c.safety[axis]
        rows.append(
            [
                _e(_AXIS_NAMES[axis]),
                _num(_h_m(p95)),
                _num(f"{si.n:,}"),
                _num(_h_ratio(si.max)),
                _e((si.time_of_max or "n.a.").replace("T", " ")),
                *(_num(_h_ratio(si.percentiles[k])) for k in keys),
            ]
        )
    head = [
        "Axis",
        _num("95th percentile error"),
        _num("SI epochs"),
        _num("SI max"),
        "SI max at (GPS)",
        *(_num(f"SI {p:g} %") for p in SAFETY_PERCENTILES),
    ]
    return _section(
        "accuracy",
        "Accuracy",
        f"<p>Over the {c.n_with_solution:,} epochs with a solution: the 95th percentiles of HPE and |VPE|, "
        "and the safety index SI = PE/PL (epochs with PL &gt; 0) with its maximum and percentiles. "
        "SI &gt; 1 is misleading information.</p>\n"
        + _table(head, rows, caption="Errors in metres; SI is dimensionless."),
    )


def _stations(a: Analysis) -> str:
    """Per-station KPIs: a campaign's weak stations are where its pooled figures come from."""
    rows = []
    for name, c in a.counting.by_station.items():
        for s in a.services:
            k = c.services[s.name]
            v = k.vertical.stanford
            h = k.horizontal.stanford
            cont = k.combined.continuity
            rows.append(
                [
                    _e(name),
                    _num(_h_int(c.n_total)),
                    _num(_h_m(c.hpe95)),
                    _num(_h_m(c.vpe95)),
                    _e(s.name),
                    *(_num(_h_pct(x, c.n_total)) for x in (k.horizontal, k.vertical, k.combined)),
                    _num(scientific(cont.risk if cont else None)),
                    _num(f"{h.mi} / {'–' if v is None else v.mi}"),
                    _num(f"{h.hmi} / {'–' if v is None else v.hmi}"),
                ]
            )
    head = [
        "Station",
        _num("Epochs"),
        _num("HPE95"),
        _num("|VPE|95"),
        "Service",
        _num("Avail. H"),
        _num("Avail. V"),
        _num("Avail. H+V"),
        _num("Cont. risk H+V"),
        _num("MI H / V"),
        _num("HMI H / V"),
    ]
    return _section(
        "stations",
        "Stations",
        f"<p>The same counts for each of the {len(a.counting.by_station)} stations alone; the sections below "
        "pool them (continuity windows never span two stations).</p>\n"
        + _table(
            head,
            rows,
            cls="sortable",
            caption="Availability in % of each station's epochs; click a column head to sort by it.",
        ),
    )


def _h_pct(k: AxisKPI, n_total: int) -> str:
    return "n.a." if k.availability is None else format_share(k.n_available, n_total)


def _value(v: Verdict) -> str:
    if v.value is None:
        return "n.a."
    if v.kpi.startswith("availability"):
        return _h_share(float(v.value))
    if v.kpi.startswith("continuity"):
        return scientific(float(v.value))
    if v.kpi.endswith("(m)"):
        return _h_m(float(v.value))
    return _h_int(int(v.value))


def _requirement(v: Verdict) -> str:
    if v.required is None:
        return "none"
    sign = {">=": "≥", "<=": "≤"}.get(v.comparison, _e(v.comparison))
    if v.kpi.startswith("availability"):
        return f"{sign} {_h_share(float(v.required))}"
    if v.kpi.startswith("continuity"):
        return f"{sign} {scientific(float(v.required))}"
    if v.kpi.endswith("(m)"):
        return f"{sign} {float(v.required):g}&nbsp;m"
    return f"{sign} {_h_int(int(v.required))}"


def _availability_counts(k: AxisKPI, n_total: int) -> str:
    return f"{k.n_available:,} of {n_total:,} epochs with PL below AL"


def _continuity_counts(r: ContinuityResult | None) -> str:
    if r is None:
        return "n.a."
    if r.risk is None:
        return f"not counted: {_e(r.reason)}"
    parts = [
        f"{r.n_fail:,} of {r.n_windows:,} windows of {r.window_s:g} s lost service",
        f"{r.n_gap_windows:,} touched by data gaps",
        f"{r.n_truncated:,} cut by the end of data (not counted)",
    ]
    if r.interval_s is not None:
        parts.append(f"sampling {r.interval_s:g} s")
    if r.n_off_grid:
        parts.append(f"{r.n_off_grid:,} epochs off the time grid")
    return _e("; ".join(parts))


def _kpi_name(kpi: str) -> str:
    """``continuity risk (combined)`` -> ``Continuity risk``: the axis and unit are shown elsewhere."""
    name = kpi.removesuffix(" (combined)").removesuffix(" (m)")
    return name[:1].upper() + name[1:]


def _kpi_rows(a: Analysis, s: ServiceLevel, k: ServiceKPI) -> list[list[str]]:
    n_total = a.counting.n_total
    pending = list(verdicts(a, s))
    axes = [k.axis(axis) for axis in AXES if k.axis(axis).alert_limit is not None]
    rows: list[list[str]] = []

    def verdict_row(kpi: str, axis: str, counts: str, value: str | None = None) -> None:
        v = next((v for v in pending if v.kpi == kpi), None)
        if v is None:
            return
        pending.remove(v)
        note = v.note if v.passed is not None or v.note else "not computable"
        # the MI / HMI counts carry no pass of their own: their verdicts open the report
        count_only = v.passed is None and v.kpi.endswith("(counted)")
        shown = value if value is not None and v.value is not None else _value(v)
        rows.append(
            [
                _e(_kpi_name(v.kpi)),
                _e(axis),
                _num(shown),
                counts or _e(note),
                _num("—" if count_only and v.required is None else _requirement(v)),
                '<a href="#verdicts">see the verdicts</a>' if count_only else _h_badge(v.passed, v.kpi, note),
            ]
        )

    for x in axes:
        rows.append(
            [
                "Availability",
                _e(x.axis),
                _num(format_share(x.n_available, n_total)),
                _availability_counts(x, n_total),
                _num("—"),
                "—",
            ]
        )
    verdict_row(
        "availability (combined)",
        "combined",
        _availability_counts(k.combined, n_total),
        format_share(k.combined.n_available, n_total),
    )
    for x in axes:
        risk = x.continuity.risk if x.continuity else None
        rows.append(
            [
                "Continuity risk",
                _e(x.axis),
                _num(scientific(risk)),
                _continuity_counts(x.continuity),
                _num("—"),
                "—",
            ]
        )
    verdict_row("continuity risk (combined)", "combined", _continuity_counts(k.combined.continuity))
    for v in list(pending):
        axis = "vertical" if "VPE" in v.kpi else "horizontal" if "HPE" in v.kpi else "both"
        over = (
            f"over the {a.counting.n_with_solution:,} epochs with a solution" if v.kpi.endswith("(m)") else ""
        )
        verdict_row(v.kpi, axis, over)
    return rows


def _stanford_table(a: Analysis, s: ServiceLevel, k: ServiceKPI) -> str:
    regions = list(Region)
    head = [
        "Axis",
        _num("AL"),
        *(_num(_e(REGION_LABELS.get(r, "No solution"))) for r in regions),
        _num("Total"),
        _num("Beyond plot"),
    ]
    rows = []
    for axis in AXES:
        x = k.axis(axis)
        if x.stanford is None or x.alert_limit is None:
            continue
        total = x.stanford.total
        cells = []
        for r in regions:
            n = getattr(x.stanford, r.key)
            cls = ' class="alarm"' if r in (Region.HMI, Region.UNAVAILABLE_MI, Region.MI) and n else ""
            cells.append(_num(f"<span{cls}>{n:,}</span><br><small>{format_share(n, total)}</small>"))
        hist = a.counting.histogram(axis, x.alert_limit)
        rows.append(
            [
                _e(_AXIS_NAMES[axis]),
                _num(_h_m(x.alert_limit, 0)),
                *cells,
                _num(f"{total:,}"),
                _num(f"{hist.clipped:,}"),
            ]
        )
    swatches = "".join(
        f'<span class="swatch" style="background:{REGION_COLOURS[r]}"></span>{_e(label)} '
        for r, label in REGION_LABELS.items()
    )
    return _table(head, rows, cls="stanford", caption=f"Epochs per Stanford region. {swatches}")


def _counted_key(s: ServiceLevel) -> tuple:
    """Everything a service section shows: alert limits and the counted requirements (not the TTA,
    which only the EVT's HMI filter uses)."""
    return (
        s.hal, s.val, s.integrity_risk, s.integrity_exposure_s, s.continuity_risk, s.continuity_window_s,
        s.availability, s.availability_max, s.accuracy_h95, s.accuracy_v95,
    )  # fmt: skip


def service_groups(services: tuple[ServiceLevel, ...]) -> list[tuple[ServiceLevel, ...]]:
    """Services that share every number of their section (APV-I and LPV), in first-appearance order."""
    groups: dict[tuple, list[ServiceLevel]] = {}
    for s in services:
        groups.setdefault(_counted_key(s), []).append(s)
    return [tuple(g) for g in groups.values()]


def _service(a: Analysis, group: tuple[ServiceLevel, ...]) -> str:
    s = group[0]
    k = a.counting.services[s.name]
    limits = f"HAL {s.hal:g} m, " + (f"VAL {s.val:g} m" if s.val is not None else "no vertical alert limit")
    shared = (
        "<br><small>"
        + _e(" and ".join(x.name for x in group))
        + " share these alert limits and requirements, so every number below is theirs alike (TTA "
        + _e(", ".join(f"{x.name} {x.tta_s:g} s" for x in group))
        + ")."
        + "".join(f'<span id="{_e(_service_id(x))}"></span>' for x in group[1:])
        + "</small>"
        if len(group) > 1
        else ""
    )
    intro = (
        f'<p class="limits">{_e(limits)} · integrity risk {scientific(s.integrity_risk)} per '
        f"{s.integrity_exposure_s:g} s · continuity risk {scientific(s.continuity_risk)} per "
        f"{s.continuity_window_s:g} s · availability "
        f"{_h_share(s.availability)}–{_h_share(s.availability_max)}"
        f"<br><small>Requirements: {_e('; '.join(dict.fromkeys(x.source or 'user-defined' for x in group)))}"
        f"</small>{shared}</p>"
    )
    kpis = _table(
        ["KPI", "Axis", _num("Value"), "Counts / note", _num("Requirement"), "Estimate vs requirement"],
        _kpi_rows(a, s, k),
        cls="kpi",
    )
    figures = []
    for axis in AXES:
        x = k.axis(axis)
        if x.alert_limit is None or x.stanford is None:
            continue
        hist = a.counting.histogram(axis, x.alert_limit)
        ax = plot_stanford(hist, x.stanford, alert_limit=x.alert_limit, service=s.name)
        figures.append(
            _render(
                ax,
                f"stanford-{s.name}-{axis}",
                f"Stanford diagram of {s.name}, {axis}: {_PE[axis]} against {_PL[axis]} with alert limit "
                f"{x.alert_limit:g} m; {x.stanford.hmi:,} HMI, {x.stanford.mi:,} MI epochs",
                f"Stanford diagram, {s.name} {axis} (AL {x.alert_limit:g} m).",
            )
        )
    figs = '<div class="figrow">' + "".join(figures) + "</div>"
    return _section(
        _service_id(s),
        " and ".join(x.name for x in group),
        f"{intro}\n<h3>KPIs against requirements</h3>\n{kpis}\n"
        f"<h3>Stanford regions</h3>\n{_stanford_table(a, s, k)}\n{figs}",
    )


def _strictest(services: tuple[ServiceLevel, ...], axis: str) -> tuple[float | None, list[str]]:
    limits = [(s.alert_limit(axis), s.name) for s in services if s.alert_limit(axis) is not None]
    if not limits:
        return None, []
    al = min(v for v, _ in limits)
    return al, [n for v, n in limits if v == al]


def _network(a: Analysis, network: dict) -> str:
    """The network section: daily compliance, heat maps, and the station map."""
    stations = a.counting.by_station or {a.counting.stations[0]: a.counting}
    availability = {
        s.name: {n: c.services[s.name].combined.availability for n, c in stations.items()} for s in a.services
    }
    return network_section_html(network, a.network.daily, a.services, a.network.positions, availability)


def _no_verdicts() -> str:
    return _section(
        "verdicts",
        "Verdicts",
        '<p class="alarm">Not assessed: this is a counting-only analysis of a campaign dataset. The '
        "verdicts weigh the counts with the counted evidence (by partition too) and the statistical "
        "methods; run <code>overbound analyze</code> without <code>--counting-only</code> for them "
        "(with <code>--no-confidence --no-evt --no-parametric</code>, nothing is read whole).</p>",
    )


def _time_series(a: Analysis) -> str:
    if a.table.is_empty() and a.network is not None:
        return _section(
            "time-series",
            "Time series",
            "<p>Not drawn: a campaign analysed by partition without the statistical methods (or with "
            "<code>--counting-only</code>) does not read the pooled epoch table.</p>",
        )
    series, hists = [], []
    for axis in AXES:
        al, names = _strictest(a.services, axis)
        which = (
            f"AL {al:g} m ({', '.join(names)}, the most stringent analysed)" if al is not None else "no AL"
        )
        ax = plot_timeseries(a.table, axis=axis, alert_limit=al)
        series.append(
            _render(
                ax,
                f"timeseries-{axis}",
                f"Time series of {_PE[axis]} and {_PL[axis]} against GPS time with {which}",
                f"{_PE[axis]} and {_PL[axis]} against GPS time, {which}. Long series are drawn as the "
                "per-pixel minimum/maximum envelope.",
            )
        )
        ax = plot_safety_index(a.table, axis=axis)
        hists.append(
            _render(
                ax,
                f"safety-index-{axis}",
                f"Histogram of the safety index {_PE[axis]}/{_PL[axis]} on a log count scale, SI = 1 marked",
                f"Safety index {_PE[axis]}/{_PL[axis]}: epochs per bin (log scale); "
                "SI > 1 is misleading information.",
            )
        )
    content = "".join(series) + '<div class="figrow">' + "".join(hists) + "</div>"
    return _section("time-series", "Time series", content)


#: Method notes: (term, definition); ``{bins}`` is the Stanford histogram's bin count.
_NOTES: tuple[tuple[str, str], ...] = (
    (
        "Time base",
        "All times are GPS time (GPST: continuous, no leap seconds). Readers convert inputs tagged in"
        " UTC by adding the GPS−UTC leap seconds. ISO 8601 times in this report carry no time-zone "
        "suffix.",
    ),
    (
        "Epochs",
        "One row per receiver epoch. An epoch has a solution when HPE, VPE, HPL and VPL are all "
        "finite; epochs without a solution stay in the table and count as unavailable for every "
        "service. Errors are estimate minus truth in the local east-north-up frame of the reference "
        "position.",
    ),
    (
        "Availability",
        "The share of all epochs, with or without a solution, whose protection level is below the "
        "alert limit: HPL < HAL, VPL < VAL; combined needs both. PL = AL is unavailable, and so is an "
        "epoch the receiver flagged with an alert. A service without a VAL (NPA) is horizontal only.",
    ),
    (
        "Continuity risk",
        "Counted over sliding windows as in Kannemans (2006), section 2.1.4: P = N_fail / (N_success "
        "+ N_fail). A window starts at every available epoch and covers the exposure time T after it "
        "(15 s for approaches, 3600 s for NPA); it fails when any epoch in (t, t + T] is unavailable "
        "or missing. The epochs are placed on a regular grid whose step is the mean epoch spacing "
        "within 25 % of the median spacing (gaps left out, time-tag jitter averaged); a grid "
        "slot without an epoch (a data gap) counts as loss of service. Windows that would run past "
        "the end of the data are not counted, and windows never span two stations. When the sampling "
        "interval exceeds T no window can be counted and the risk is n.a., with the reason.",
    ),
    (
        "Stanford regions",
        "Per axis and alert limit AL, with PE the absolute error and PL the protection level: PL ≥ AL"
        " is system unavailable (PE ≤ PL) or unavailable & MI (PE > PL); with PL < AL an epoch is HMI"
        " when PE > AL, MI when PL < PE ≤ AL, and normal operation when PE ≤ PL. Ties: PE = PL is "
        "bounded (normal), PL = AL is unavailable, PE = AL is not hazardous. Percentages are of all "
        "epochs, including those without a solution, which the diagrams do not draw. The diagrams use"
        " {bins} × {bins} square bins from 0 to 1.5 AL rounded up to 10 m, with a logarithmic colour "
        "scale; epochs beyond the range are drawn in the border bins and counted.",
    ),
    (
        "Percentiles",
        "HPE95, |VPE|95 and the safety-index percentiles interpolate linearly between order "
        "statistics (Hyndman and Fan type 7, numpy's default), over the epochs with a solution (and "
        "PL > 0 for the safety index SI = PE/PL).",
    ),
    (
        "Verdicts",
        "PASS or FAIL compares a KPI with the requirement of the service level; n.a. means the KPI "
        "could not be computed or the service states no requirement. Availability uses the lower end "
        "of the ICAO range. The integrity verdict here is only the count of HMI epochs: an integrity "
        "risk of the order of 2·10⁻⁷ per approach cannot be shown by counting and needs the "
        "statistical methods.",
    ),
    (
        "Time series",
        "Drawn as the minimum/maximum of each time bin (about one bin per pixel column), which marks "
        "the same pixels as the raw series; lines break at data gaps of two sampling intervals or "
        "more.",
    ),
)
#: Plain-text citations of the method notes (no links: the page loads nothing).
_REFERENCES: tuple[str, ...] = (
    "ICAO Annex 10, Volume I (7th ed., 2018), Table 3.7.2.4-1, Signal-in-space performance requirements.",
    "RTCA DO-229E (2016), Minimum Operational Performance Standards for GPS/SBAS airborne equipment, 2.2.4.",
    "Kannemans, H. (2006), An integrity, availability and continuity test method for EGNOS/WAAS, "
    "NLR-TP-2006-594, section 2.1.4.",
    "Tossaint, M. et al. (2006), The Stanford-ESA integrity diagram: focusing on SBAS integrity, ION "
    "GNSS 2006.",
    "Hyndman, R. J., Fan, Y. (1996), Sample quantiles in statistical packages, The American "
    "Statistician 50(4), 361–365.",
)


def _epochs(analysis: Analysis):
    """The analysed epoch table (a ``polars.DataFrame``), ``None`` for a dataset (analysed partition
    by partition)."""
    return None if analysis.network is not None else analysis.table


def _method_notes(c: CountingResult) -> str:
    bins = next(iter(c.histograms.values())).counts.shape[0] if c.histograms else 200
    dl = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v.replace('{bins}', str(bins)))}</dd>" for k, v in _NOTES)
    ol = "".join(f"<li>{_e(r)}</li>" for r in _REFERENCES)
    return _section(
        "method-notes",
        "Method notes",
        f'<dl class="notes">{dl}</dl>\n<h3>References</h3>\n<ol class="refs">{ol}</ol>',
    )
