"""Pieces shared by overbound's self-contained HTML pages: the style sheet and embedded figures."""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Sequence
from functools import partial
from pathlib import Path

from matplotlib.axes import Axes

from overbound.numbers import PRINT_FLOOR
from overbound.report.rendering import active_renderer, resolve_figures
from overbound.report.style import close_figure, figure_png

__all__ = [
    "BELOW_FLOOR_HTML",
    "FIGURE_DPI",
    "PAGE_CSS",
    "badge",
    "escape",
    "figure_element",
    "figure_html",
    "percent",
    "row_table",
    "scientific",
    "section_html",
    "write_page",
]

#: Resolution of the figures embedded in the pages.
FIGURE_DPI = 110


def escape(text: object) -> str:
    """``text`` escaped for HTML text and attribute values."""
    return html.escape(str(text), quote=True)


#: A figure wider than this (PNG pixels) takes a whole row of a ``figrow``: two-up in a 1024 px window
#: (474 px a column) it would be shrunk below 0.81, and its smallest, 6.5 pt annotations (9.9 px at
#: 110 dpi) below 8 px on screen.
WIDE_FIGURE_PX = 580


def figure_html(ax: Axes, *, name: str, alt: str, caption: str) -> str:
    """Render ``ax``'s figure to a PNG, close it, and return a ``<figure>`` with the PNG inline.

    The ``<img>`` carries its pixel size, ``alt`` text and a ``data-figure`` name (for tests and
    readers); the page loads nothing. Inside :func:`~overbound.report.rendering.parallel_figures` the
    figure is drawn by a worker process and a placeholder is returned, which
    :func:`~overbound.report.rendering.resolve_figures` (called by :func:`write_page`) replaces.
    """
    fig = ax.figure
    renderer = active_renderer()
    try:
        if renderer is not None:
            return renderer.submit(
                fig, dpi=FIGURE_DPI, wrap=partial(figure_element, name=name, alt=alt, caption=caption)
            )
        png = figure_png(fig, dpi=FIGURE_DPI)
    finally:
        close_figure(fig)
    return figure_element(png, name=name, alt=alt, caption=caption)


def figure_element(png: bytes, *, name: str, alt: str, caption: str) -> str:
    """The ``<figure>`` of one PNG (inline, as base64), its pixel size read from the PNG header."""
    width, height = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
    data = base64.b64encode(png).decode("ascii")
    wide = ' class="wide"' if width > WIDE_FIGURE_PX else ""
    return (
        f'<figure{wide}><img src="data:image/png;base64,{data}" width="{width}" height="{height}" '
        f'alt="{escape(alt)}" data-figure="{escape(name)}">'
        f"<figcaption>{escape(caption)}</figcaption></figure>"
    )


#: Style sheet of every overbound page (inline: the pages are self-contained).
PAGE_CSS = """
:root{--ink:#1d2733;--muted:#5b6673;--line:#d5dbe1;--band:#f4f6f8;--accent:#1f5fa8;
--pass:#1b7a3a;--pass-bg:#e3f4e8;--fail:#b3261e;--fail-bg:#fbe4e2;--na:#5b6673;--na-bg:#eceff2}
*{box-sizing:border-box}
html{font-size:15px}
body{margin:0;color:var(--ink);background:#fff;
font-family:system-ui,-apple-system,"Segoe UI",Roboto,"Helvetica Neue","DejaVu Sans",Arial,sans-serif;
line-height:1.45}
main{max-width:1180px;margin:0 auto;padding:0 24px 48px}
header{border-bottom:3px solid var(--accent);padding:28px 0 14px;margin-bottom:8px}
.kicker{margin:0;color:var(--accent);font-weight:600;letter-spacing:.06em;text-transform:uppercase;font-size:.8rem}
h1{margin:.15em 0 .1em;font-size:1.9rem;overflow-wrap:anywhere}
.sub{margin:0 0 12px;color:var(--muted)}
.warning{margin:8px 0;padding:8px 12px;border-left:4px solid #b45309;background:#fff7ed;color:#7c2d12}
nav ul{list-style:none;margin:0;padding:0;display:flex;flex-wrap:wrap;gap:6px}
nav a{display:inline-block;padding:3px 10px;border:1px solid var(--line);border-radius:14px;
color:var(--accent);text-decoration:none;font-size:.85rem;background:var(--band)}
section{padding:18px 0 8px;border-bottom:1px solid var(--line)}
h2{font-size:1.4rem;margin:.3em 0 .5em;color:var(--ink)}
h3{font-size:1.05rem;margin:1.2em 0 .4em;color:var(--muted)}
p{max-width:75em}
code{font-family:ui-monospace,"DejaVu Sans Mono",Menlo,Consolas,monospace;font-size:.9em}
dl.facts{display:grid;grid-template-columns:max-content 1fr;gap:3px 18px;margin:0 0 8px}
dl.facts dt{color:var(--muted)}
dl.facts dd{margin:0;font-variant-numeric:tabular-nums}
table{border-collapse:collapse;margin:6px 0 12px;font-size:.9rem;font-variant-numeric:tabular-nums;width:100%}
caption{caption-side:bottom;text-align:left;color:var(--muted);font-size:.8rem;padding-top:4px}
th,td{border-bottom:1px solid var(--line);padding:4px 8px;text-align:left;vertical-align:top}
th{background:var(--band);font-weight:600;border-bottom:2px solid var(--line)}
td code{overflow-wrap:anywhere}
tbody tr:nth-child(even){background:#fafbfc}
.num{text-align:right;white-space:nowrap}
th.num{white-space:normal}
td small{color:var(--muted)}
.alarm{color:var(--fail);font-weight:700}
tr.suspect{background:var(--fail-bg)}
.badge{display:inline-block;min-width:3.6em;text-align:center;padding:1px 8px;border-radius:10px;
font-weight:700;font-size:.78rem;letter-spacing:.04em;border:1px solid}
.badge.pass{color:var(--pass);background:var(--pass-bg);border-color:var(--pass)}
.badge.fail{color:var(--fail);background:var(--fail-bg);border-color:var(--fail)}
.badge.na{color:var(--na);background:var(--na-bg);border-color:#b8c0c8}
.badge.within{color:var(--accent);background:#fff;border-color:var(--accent);font-weight:600}
.badge.above{color:#8a4b00;background:#fff;border-color:#c77d1a;font-weight:600}
.limits{color:var(--muted)}
.swatch{display:inline-block;width:.9em;height:.9em;border:1px solid #999;margin:0 3px 0 8px;
vertical-align:-1px}
figure{margin:8px 0;break-inside:avoid}
figure img{max-width:100%;height:auto;display:block;border:1px solid var(--line)}
figcaption{color:var(--muted);font-size:.8rem;margin-top:3px}
.figrow{display:grid;grid-template-columns:repeat(auto-fit,minmax(360px,1fr));gap:14px;align-items:start}
.figrow figure.wide{grid-column:1/-1}
dl.notes dt{font-weight:600;margin-top:.7em}
dl.notes dd{margin:.15em 0 0;max-width:75em}
ol.refs{font-size:.88rem;color:var(--muted)}
details pre{background:var(--band);padding:10px;overflow:auto;max-height:40em;font-size:.75rem}
@media print{
html{font-size:10.5pt}
main{max-width:none;padding:0}
nav,#summary-data{display:none}
section{break-inside:auto;border:none}
section[id^="service-"],#time-series,#method-notes{break-before:page}
table,figure,tr{break-inside:avoid}
th{white-space:normal}
.badge,th,.swatch,tbody tr{-webkit-print-color-adjust:exact;print-color-adjust:exact}
}
@page{size:A4;margin:14mm}
"""


#: What a probability below :data:`overbound.numbers.PRINT_FLOOR` reads as in HTML.
BELOW_FLOOR_HTML = "&lt;&nbsp;10<sup>−15</sup>"


def scientific(x: float | None) -> str:
    """A probability as HTML: plain down to 0.001, else ``m·10<sup>e</sup>``; 0 is 0, None/NaN ``n.a.``."""
    if x is None or not math.isfinite(x):
        return "n.a."
    if x == 0:
        return "0"
    if 1e-3 <= abs(x) < 1e4:
        return f"{x:.4g}"
    if 0 < x < PRINT_FLOOR:  # no probability below 1e-15 is printed as a number
        return BELOW_FLOOR_HTML
    exp = math.floor(math.log10(abs(x)))
    mant = x / 10.0**exp
    if round(mant, 2) >= 10:
        mant, exp = mant / 10, exp + 1
    return f"{mant:.3g}·10<sup>{'−' if exp < 0 else ''}{abs(exp)}</sup>"


#: Badge class and text of one method's own reading of its bound against a requirement (``None``: no
#: estimate). Not a verdict: the verdicts (:mod:`overbound.verdict`) weigh every method with the counts
#: and the adequacy tests, so the method sections say "bound within/above", never "pass".
VERDICT = {True: ("within", "bound within"), False: ("above", "bound above"), None: ("na", "no estimate")}


def percent(level: float) -> str:
    """A level as a percentage with a non-breaking space: ``0.95`` -> ``95&nbsp;%``."""
    return f"{100 * level:g}&nbsp;%"


def row_table(head: Sequence[str], rows: Sequence[Sequence[str]], cls: str) -> str:
    """A table of HTML cells; the first cell of a row is its header."""
    thead = "".join(f"<th>{h}</th>" for h in head)
    body = "\n".join(f"<tr><th>{r[0]}</th>" + "".join(f"<td>{c}</td>" for c in r[1:]) + "</tr>" for r in rows)
    return f'<table class="{cls}"><thead><tr>{thead}</tr></thead>\n<tbody>\n{body}\n</tbody></table>'


def badge(meets: bool | None, name: str, note: str) -> str:
    """A method's "bound within / bound above / no estimate" badge for ``name``, ``note`` as its tooltip."""
    kind, text = VERDICT[meets]
    return f'<span class="badge {kind}" data-kpi="{escape(name)}" title="{escape(note)}">{text}</span>'


def write_page(path: str | Path, *, title: str, intro_html: str, body_html: str) -> Path:
    """Write a standalone, self-contained page (inline CSS, no external resource, no timestamp).

    ``intro_html`` is the paragraph under the title (already HTML), ``body_html`` the sections; the same
    arguments give the same bytes.
    """
    from overbound import __version__  # the package imports report modules: import on use

    text = (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        f'<meta name="generator" content="overbound {escape(__version__)}">\n'
        f"<title>{escape(title)} — overbound</title>\n<style>{PAGE_CSS}</style>\n</head>\n<body>\n<main>\n"
        f"<h1>{escape(title)}</h1>\n<p>{intro_html}</p>\n{resolve_figures(body_html)}\n</main>\n</body>\n</html>\n"
    )
    path = Path(path)
    path.write_bytes(text.encode("utf-8"))
    return path


def section_html(sid: str, title: str, parts: Sequence[str], skipped: Sequence[str] = ()) -> str:
    """A ``<section id=sid>`` with an ``<h2>`` title, the HTML ``parts`` one per line, and a line
    naming the figures not drawn (``skipped``) when there are any."""
    body = list(parts)
    if skipped:
        body.append(f'<p class="limits">Not drawn: {escape(", ".join(skipped))}.</p>')
    return f'<section id="{escape(sid)}">\n<h2>{escape(title)}</h2>\n' + "\n".join(body) + "\n</section>"
