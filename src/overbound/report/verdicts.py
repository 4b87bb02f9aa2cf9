"""The verdicts as HTML: the matrix that opens every report, the "why" list and the evidence.

Every cell of the matrix links to the evidence its verdict rests on (``#ev-<service>-<kind>``).
Numbers follow :mod:`overbound.numbers`: no probability below 1e-15 is printed as a number.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

from overbound.numbers import format_percent, format_probability
from overbound.report.page import escape
from overbound.verdict import KINDS, Assessment, EvidenceItem, ServiceVerdicts, Verdict

__all__ = [
    "KIND_TITLES",
    "VERDICT_CSS",
    "evidence_html",
    "matrix_html",
    "station_matrix_html",
    "verdict_section",
]

KIND_TITLES = {
    "availability": "Availability",
    "continuity": "Continuity",
    "accuracy": "Accuracy",
    "integrity": "Integrity (HMI)",
    "pl_bounding": "PL bounding (MI)",
    "overall": "Overall",
}
_CLASS = {"pass": "pass", "fail": "fail", "not demonstrated": "nd"}

#: Styles of the matrix, added to the page's.
VERDICT_CSS = """
nav.sticky{position:sticky;top:0;z-index:10;background:#fff;padding:6px 0;border-bottom:1px solid var(--line)}
table.verdicts{width:auto;min-width:60%}
table.verdicts td{text-align:center;padding:0}
table.verdicts td a{display:block;padding:5px 10px;text-decoration:none;font-weight:700;font-size:.85rem;
color:inherit}
td.v-pass{background:var(--pass-bg);color:var(--pass)}
td.v-fail{background:var(--fail-bg);color:var(--fail)}
td.v-nd{background:#fff4d6;color:#7a5a00}
ul.why li{margin:.25em 0;max-width:75em}
.ev{border-left:3px solid var(--line);padding:2px 0 2px 12px;margin:10px 0}
.ev.v-pass{border-color:var(--pass)}.ev.v-fail{border-color:var(--fail)}.ev.v-nd{border-color:#c79a00}
.ev h4{margin:.2em 0}
table.evidence{font-size:.82rem}
table.evidence td{overflow-wrap:anywhere}
"""


def _sid(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "-", text).strip("-")


def anchor(service: str, kind: str, station: str | None = None) -> str:
    """The id of the evidence block of ``service`` and ``kind``."""
    return "ev-" + (_sid(station) + "-" if station else "") + _sid(service) + "-" + kind


def _cell(v: Verdict, href: str | None) -> str:
    text = escape(v.verdict)
    inner = f'<a href="{href}" title="{escape(v.sentence)}">{text}</a>' if href else f"<a>{text}</a>"
    return f'<td class="v-{_CLASS[v.verdict]}" data-kind="{v.kind}" data-verdict="{text}">{inner}</td>'


def matrix_html(
    services: Mapping[str, ServiceVerdicts], *, link: str | None = "", station: str | None = None
) -> str:
    """The service × verdict table; each cell links to ``link + #anchor`` (``None``: no links)."""
    head = "".join(f"<th>{KIND_TITLES[k]}</th>" for k in (*KINDS, "overall"))
    rows = []
    for name, sv in services.items():
        cells = "".join(
            _cell(sv.get(k), None if link is None else f"{link}#{anchor(name, k, station)}")
            for k in (*KINDS, "overall")
        )
        rows.append(f'<tr data-service="{escape(name)}"><th>{escape(name)}</th>{cells}</tr>')
    return (
        f'<table class="verdicts"><thead><tr><th>Service</th>{head}</tr></thead>'
        f"<tbody>{''.join(rows)}</tbody></table>"
    )


def station_matrix_html(by_station: Mapping[str, Mapping[str, ServiceVerdicts]]) -> str:
    """Stations × services, the overall verdict of each."""
    names = list(next(iter(by_station.values())))
    head = "".join(f"<th>{escape(n)}</th>" for n in names)
    rows = "".join(
        f"<tr><th>{escape(st)}</th>"
        + "".join(_cell(per[n].overall, f"#{anchor(n, 'overall', st)}") for n in names)
        + "</tr>"
        for st, per in by_station.items()
    )
    return (
        f'<table class="verdicts stations"><thead><tr><th>Station</th>{head}</tr></thead>'
        f"<tbody>{rows}</tbody></table>"
    )


def _why(services: Mapping[str, ServiceVerdicts]) -> str:
    items = []
    for name, sv in services.items():
        for k in KINDS:
            v = sv.get(k)
            if v.verdict != "pass":
                items.append(
                    f'<li><a href="#{anchor(name, k)}"><b>{escape(name)} {KIND_TITLES[k]}: '
                    f"{escape(v.verdict)}.</b></a> {escape(v.sentence)}</li>"
                )
    if not items:
        return "<p>Every requirement of every service is demonstrated.</p>"
    return f'<ul class="why">{"".join(items)}</ul>'


def _number(item: EvidenceItem, x: float | None, log10_x: float | None = None) -> str:
    """A figure in the unit of ``item.quantity`` (metres, a share, or a probability), as HTML."""
    return escape(_plain_number(item, x, log10_x))


def _plain_number(item: EvidenceItem, x: float | None, log10_x: float | None = None) -> str:
    if x is None:
        return "—"
    if "(m)" in item.quantity:
        return f"{x:.3g} m"
    if item.quantity.startswith("availability"):
        return format_percent(x)
    if item.quantity.startswith("confidence") or item.quantity.startswith("lowest confidence"):
        return format_probability(x)
    return format_probability(x, log10_x)


def _interval(item: EvidenceItem) -> str:
    lo = "—" if item.lower is None else _number(item, item.lower)
    hi = _number(item, item.upper, item.log10_upper)
    if item.upper == 0 and hi == "0":
        hi = "0 (" + escape(item.note or "no tail value reaches SI = 1") + ")"
    return f"{lo} … {hi}"


def _adequacy(item: EvidenceItem) -> str:
    a = item.adequacy
    if a is None:
        return ""
    checks = ", ".join(f"SI&gt;{c.level:.3g}: {c.observed} obs. / {c.predicted:.3g} pred." for c in a.checks)
    word = "<b>rejected</b>" if a.rejected else "adequate"
    return f"<br><small>adequacy: {word} ({checks})</small>"


def evidence_html(v: Verdict, service: str, station: str | None = None) -> str:
    """The evidence block of one verdict: requirement, basis, sentence and the items."""
    rows = []
    for it in v.evidence:
        rows.append(
            "<tr>"
            f"<td>{escape(it.method)}{'' if it.axis is None else ' · ' + escape(it.axis)}</td>"
            f"<td>{escape(it.quantity)}{_adequacy(it)}</td>"
            f'<td class="num">{_number(it, it.estimate, it.log10_estimate)}</td>'
            f'<td class="num">{_interval(it)}</td>'
            f"<td>{escape(it.vote)}</td>"
            f"<td><small>{escape(it.assumption)}{'; ' + escape(it.note) if it.note else ''}</small></td>"
            "</tr>"
        )
    table = (
        '<table class="evidence"><thead><tr><th>Method</th><th>Quantity</th><th>Estimate</th>'
        "<th>95&nbsp;% bounds</th><th>Vote</th><th>Rests on</th></tr></thead>"
        f"<tbody>{''.join(rows)}</tbody></table>"
        if rows
        else ""
    )
    return (
        f'<div class="ev v-{_CLASS[v.verdict]}" id="{anchor(service, v.kind, station)}">'
        f"<h4>{escape(service)} · {KIND_TITLES[v.kind]}: {escape(v.verdict)}</h4>"
        f"<p>{escape(v.sentence)}<br><small>Requirement: {escape(v.requirement)} · basis: "
        f"{escape(v.basis)}</small></p>{table}</div>"
    )


def verdict_section(assessment: Assessment) -> str:
    """The ``<section id="verdicts">`` that opens the report: matrix, why list, evidence."""
    parts = [
        '<section id="verdicts"><h2>Verdicts</h2>',
        matrix_html(assessment.services),
        "<p><small>Each cell links to its evidence. The rules (counted evidence first; tail models vote "
        "only when the data do not reject them; pass only when every admissible model passes) are in "
        "the method notes and the documentation (docs/verdicts.md).</small></p>",
        "<h3>Why not pass</h3>",
        _why(assessment.services),
    ]
    if assessment.by_station:
        parts += ["<h3>Per station (overall)</h3>", station_matrix_html(assessment.by_station)]
    parts.append("<details open><summary>Evidence of each verdict</summary>")
    for name, sv in assessment.services.items():
        parts += [evidence_html(sv.get(k), name) for k in (*KINDS, "overall")]
    for st, per in assessment.by_station.items():
        for name, sv in per.items():
            parts.append(
                f'<div class="ev v-{_CLASS[sv.overall.verdict]}" id="{anchor(name, "overall", st)}">'
                f"<h4>{escape(st)} · {escape(name)}: {escape(sv.overall.verdict)}</h4>"
                f"<p>{escape(sv.overall.sentence)}</p>"
                + "".join(
                    f"<p><small>{KIND_TITLES[k]}: {escape(sv.get(k).sentence)}</small></p>" for k in KINDS
                )
                + "</div>"
            )
    parts.append("</details></section>")
    return "\n".join(parts)
