"""Outputs of the PL confidence-level analysis: JSON, figures and an HTML section.

* ``confidence-<axis>.json`` (schema ``overbound.confidence/1``): :func:`confidence_dict`,
  :func:`write_confidence`; deterministic bytes (:func:`overbound.jsontext.dump`).
* Figures, drawn like those of :mod:`overbound.report.figures` (inside :func:`style`, on a
  :func:`new_figure` when no ``ax`` is given, never through pyplot): the confidence level per
  target PL (:func:`plot_confidence`, Comby et al. 2003 figure 6), the error histogram of a band
  with its Gaussian models (:func:`plot_band_histogram`, figures 4, 5, 7, 10) and a band's errors
  against its PLs, ideal PL, PL1 and PL99 (:func:`plot_band_errors`, figure 8).
* HTML: :func:`confidence_section_html` (a ``<section id="confidence-<axis>">`` for a report)
  and :func:`write_confidence_report` (a standalone, self-contained ``confidence.html``).
* :func:`run_confidence`: analyse, and write the JSON and the page, in one call (the CLI's).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import polars as pl
from matplotlib.axes import Axes
from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

from overbound import __version__
from overbound.jsontext import dump
from overbound.methods.confidence_level import (
    SUSPECT_BELOW,
    ConfidenceAnalysis,
    ConfidenceBin,
    confidence_analysis,
)
from overbound.numbers import PRINT_FLOOR
from overbound.report.page import escape, figure_html, section_html, write_page
from overbound.report.style import confidence_label, log_scale, new_figure, style
from overbound.stats.overbounding import SigmaInflation

__all__ = [
    "JSON_NAME",
    "REPORT_NAME",
    "SCHEMA",
    "ConfidenceRun",
    "confidence_dict",
    "confidence_section_html",
    "json_name",
    "plot_band_errors",
    "plot_band_histogram",
    "plot_confidence",
    "run_confidence",
    "write_confidence",
    "write_confidence_report",
]

SCHEMA = "overbound.confidence/1"
#: File name written by :func:`write_confidence_report`.
REPORT_NAME = "confidence.html"
#: Confidence levels are drawn on a logit axis clipped to [_CL_FLOOR, 1 - _CL_FLOOR].
_CL_FLOOR = 1e-6
#: At most this many suspect bins get their own figures (the lowest CLs first): neighbouring bands share
#: most of their samples (a band is widened to reach its 200), so more figures would repeat the same
#: picture at the cost of drawing it; the table lists every suspect band.
_MAX_DETAIL_BINS = 4
_PE = {"vertical": "VPE", "horizontal": "HPE"}
_PL = {"vertical": "VPL", "horizontal": "HPL"}
_ABS = {"vertical": "|VPE|", "horizontal": "HPE"}
_OK_COLOUR = "#1f5fa8"
_BAD_COLOUR = "#c0201a"
_PL_COLOUR = "#d9711c"
_GOOD_LINE = "#1b7a3a"


# ---------------------------------------------------------------------------
# JSON


#: File name of the JSON document of a single-axis run.
JSON_NAME = "confidence.json"


def json_name(axis: str) -> str:
    """File name of the JSON document of one axis: ``confidence-<axis>.json``."""
    return f"confidence-{axis}.json"


def confidence_dict(analysis: ConfidenceAnalysis) -> dict:
    """The JSON document (schema ``overbound.confidence/1``) of a :class:`ConfidenceAnalysis`.

    Keys: ``schema``, ``overbound_version``, ``axis``, ``risk``, ``parameters`` (``min_samples``,
    ``spacing``, ``tolerance``, ``step``, ``max_pl``, ``max_tolerance``, ``core``), ``stations``,
    ``n_epochs``, ``pl_min``, ``counts`` (``bins``, ``sufficient``, ``suspect``, ``empty``),
    ``suspect_targets``, ``worst_target`` and ``bins``: every field of each
    :class:`~overbound.methods.confidence_level.ConfidenceBin` (NaN written ``null``; the bin
    comes back with ``ConfidenceBin.from_dict``).
    """
    bins = analysis.bins
    worst = analysis.worst
    return {
        "schema": SCHEMA,
        "overbound_version": __version__,
        "axis": analysis.axis,
        "risk": analysis.risk,
        "parameters": analysis.parameters(),
        "stations": list(analysis.stations),
        "n_epochs": analysis.n_epochs,
        "pl_min": analysis.pl_min,
        "counts": {
            "bins": len(bins),
            "sufficient": sum(b.sufficient for b in bins),
            "suspect": sum(b.suspect for b in bins),
            "empty": sum(b.n == 0 for b in bins),
        },
        "suspect_targets": [bins[i].target for i in analysis.suspect],
        "worst_target": None if worst is None else bins[worst].target,
        "bins": [{f.name: getattr(b, f.name) for f in fields(b)} for b in bins],  # shallow: epochs stay lazy
    }


def write_confidence(analysis: ConfidenceAnalysis, path: str | Path) -> Path:
    """Write :func:`confidence_dict` as JSON (same analysis, same bytes); return the path."""
    return dump(confidence_dict(analysis), path)


# ---------------------------------------------------------------------------
# figures


def plot_confidence(analysis: ConfidenceAnalysis, ax: Axes | None = None) -> Axes:
    """Confidence level against target PL, with the 1 % and 99 % lines (Comby et al. 2003, figure 6).

    Parameters
    ----------
    analysis : the result of :func:`~overbound.methods.confidence_level.confidence_analysis`.
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists with ``gid`` ``cl`` (the bins' CLs, markers joined by a line), ``cl-suspect``
        (red rings around the bins with CL < 1 %), ``cl-insufficient`` (grey ticks along the
        bottom at the targets whose band has samples but fewer than ``min_samples``, which
        have no CL), ``cl-1`` and ``cl-99``.

    Notes
    -----
    The CL axis is a *logit* scale from 1e-6 to 1 − 1e-6: it spreads out both ends, the
    suspect bins (CLs of 1e-2 down to 1e-90 for a band like the paper's ENAC 15-16 m case)
    and the 99 % to 99.9999 % that separates a tight PL from a comfortable one, which a
    linear 0-1 axis squeezes into its borders and a log axis squeezes near 1. CLs beyond are
    drawn on the border (as 1e-6 or 1 − 1e-6).
    """
    bins = analysis.bins
    x = np.array([b.target for b in bins], dtype=float)
    cl = np.array([b.confidence for b in bins], dtype=float)
    has = np.isfinite(cl)
    y = np.clip(cl, _CL_FLOOR, 1.0 - _CL_FLOOR)
    few = np.array([0 < b.n and not b.sufficient for b in bins], dtype=bool)
    suspect = np.array([b.suspect for b in bins], dtype=bool)
    pl_name = _PL.get(analysis.axis, "PL")
    with style():
        if ax is None:
            fig = new_figure(8.0, 3.6)
            ax = fig.add_axes((0.1, 0.15, 0.86, 0.74))
        # a line through consecutive bins only: a NaN (no CL) breaks it
        ax.plot(
            x,
            np.where(has, y, np.nan),
            "o-",
            ms=3.2,
            lw=0.7,
            color=_OK_COLOUR,
            zorder=3,
            gid="cl",
            label="confidence level",
        )
        ax.scatter(
            x[suspect],
            y[suspect],
            s=46,
            facecolors="none",
            edgecolors=_BAD_COLOUR,
            linewidths=1.1,
            zorder=4,
            gid="cl-suspect",
            label="suspect (CL < 1 %)",
        )
        ax.scatter(
            x[few],
            np.full(int(few.sum()), _CL_FLOOR / 1.6),
            marker="|",
            s=30,
            color="#9aa5b1",
            zorder=2,
            gid="cl-insufficient",
            label=f"< {analysis.min_samples} samples: no CL",
        )
        ax.axhline(0.99, color=_GOOD_LINE, lw=0.9, ls="--", zorder=1, gid="cl-99", label="99 %")
        ax.axhline(SUSPECT_BELOW, color=_BAD_COLOUR, lw=0.9, ls="--", zorder=1, gid="cl-1", label="1 %")
        ax.set_yscale("logit")
        ax.set_ylim(_CL_FLOOR / 2.5, 1.0 - _CL_FLOOR / 2.5)
        ax.yaxis.set_major_locator(FixedLocator([1e-6, 1e-4, 1e-2, 0.5, 0.99, 1 - 1e-4, 1 - 1e-6]))
        ax.yaxis.set_major_formatter(FuncFormatter(confidence_label))
        ax.yaxis.set_minor_locator(NullLocator())
        if x.size:
            ax.set_xlim(x.min() - analysis.step, x.max() + analysis.step)
        else:
            ax.text(0.5, 0.5, "no epochs", transform=ax.transAxes, ha="center", va="center")
        ax.set_xlabel(f"target {pl_name} (m)")
        ax.set_ylabel("confidence level")
        ax.set_title(f"Confidence level in the {pl_name}, per {pl_name} band")
        ax.legend(loc="center right", fontsize=7)
    return ax


def _bin_title(bin: ConfidenceBin, axis: str) -> str:
    return (
        f"{_PL.get(axis, 'PL')} {bin.target:.2f} m (band {bin.lo:.2f}–{bin.hi:.2f} m), n = {bin.n}, "
        f"CL = {_text_cl(bin.confidence)}"
    )


def plot_band_histogram(
    bin: ConfidenceBin, errors: np.ndarray, inflation: SigmaInflation, ax: Axes | None = None
) -> Axes:
    r"""Histogram of a band's errors with :math:`G(\hat m, \hat\sigma)` and :math:`G(\hat m, \hat\Sigma)`.

    Comby et al. 2003, figures 4, 5, 7 and 10: the error density on a log scale, where a
    secondary peak in a tail shows, against the Gaussian of the sample sigma and the
    inflated Gaussian that overbounds the tails.

    Parameters
    ----------
    bin : the :class:`~overbound.methods.confidence_level.ConfidenceBin`.
    errors : the signed errors of the samples (``BandSamples.signed[k]``).
    inflation : their :class:`~overbound.stats.overbounding.SigmaInflation`
        (``BandSamples.inflations[k]``).
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists with ``gid`` ``histogram``, ``gauss-sigma``, ``gauss-inflated`` and ``binding``
        (the error that set the inflated sigma, when there is one).

    Notes
    -----
    Density = count / (n · bin width), about :math:`\sqrt n` equal bins over the errors;
    the density axis spans from a third of the smallest non-empty bin's density (one
    sample) to twice the largest, and the curves are drawn over :math:`\hat m \pm 5\hat\Sigma`.
    """
    x = np.asarray(errors, dtype=float)
    m, s, big = inflation.mean, inflation.sigma, inflation.sigma_inflated
    with style():
        if ax is None:
            fig = new_figure(5.2, 3.4)
            ax = fig.add_axes((0.13, 0.15, 0.83, 0.72))
        k = max(8, round(math.sqrt(x.size)))
        counts, edges = np.histogram(x, bins=k)
        density = counts / (x.size * np.diff(edges))
        ax.stairs(
            density,
            edges,
            fill=True,
            color=_OK_COLOUR,
            alpha=0.55,
            gid="histogram",
            label=f"selected errors (n = {x.size})",
        )
        lo = min(float(x.min()), m - 5 * big)
        hi = max(float(x.max()), m + 5 * big)
        grid = np.linspace(lo, hi, 400)
        for sd, colour, gid, name in (
            (s, "#555555", "gauss-sigma", f"G(m̂, σ̂), σ̂ = {s:.3g} m"),
            (big, _BAD_COLOUR, "gauss-inflated", f"G(m̂, Σ̂), Σ̂ = {big:.3g} m"),
        ):
            pdf = np.exp(-0.5 * ((grid - m) / sd) ** 2) / (sd * math.sqrt(2 * math.pi))
            ax.plot(grid, pdf, color=colour, lw=1.0, gid=gid, label=name)
        if inflation.binding_error is not None:
            ax.axvline(
                inflation.binding_error,
                color=_BAD_COLOUR,
                lw=0.7,
                ls=":",
                gid="binding",
                label=f"binding error {inflation.binding_error:.3g} m",
            )
        positive = density[density > 0]
        top = 2.0 * float(max(positive.max(initial=0.0), 1.0 / (s * math.sqrt(2 * math.pi))))
        bottom = float(positive.min(initial=top / 1e3)) / 3.0
        log_scale(ax)
        ax.set_ylim(bottom, top)
        ax.set_xlim(lo, hi)
        ax.set_xlabel("signed error (m)")
        ax.set_ylabel("density (1/m)")
        ax.set_title(f"band {bin.lo:.2f}–{bin.hi:.2f} m: m̂ = {m:.3g} m, n = {x.size}", fontsize=9)
        ax.legend(loc="upper right", fontsize=6.5)
    return ax


def plot_band_errors(
    bin: ConfidenceBin,
    errors: np.ndarray,
    pls: np.ndarray,
    ax: Axes | None = None,
    *,
    axis: str = "vertical",
) -> Axes:
    """A band's selected errors with their PLs, the ideal PL, PL1 and PL99 (Comby et al. 2003, figure 8).

    Parameters
    ----------
    bin : the :class:`~overbound.methods.confidence_level.ConfidenceBin`.
    errors : the samples' errors in time order: signed VPE (vertical) or HPE (horizontal).
    pls : their protection levels.
    ax : axes to draw on; a new figure when ``None``.
    axis : ``vertical`` draws the PL lines at plus and minus (the VPE is signed);
        ``horizontal`` at plus only.

    Returns
    -------
    Axes
        Artists with ``gid`` ``errors``, ``pl`` (and ``pl-neg``), ``pl-ideal``, ``pl-1``, ``pl-99``.

    Notes
    -----
    x is the sample number in time order. The paper reads the figure so: the ideal PL is
    likely between PL1 and PL99; a band whose PLs lie below PL1 has a CL below 1 %.
    """
    e = np.asarray(errors, dtype=float)
    p = np.asarray(pls, dtype=float)
    i = np.arange(e.size)
    signs = (1.0, -1.0) if axis == "vertical" else (1.0,)
    with style():
        if ax is None:
            fig = new_figure(5.2, 3.4)
            ax = fig.add_axes((0.13, 0.15, 0.83, 0.72))
        ax.plot(
            i,
            e,
            ".",
            ms=2.5,
            color=_OK_COLOUR,
            zorder=3,
            gid="errors",
            label=f"{_PE.get(axis, 'PE')} samples",
        )
        for sign in signs:
            ax.plot(
                i,
                sign * p,
                ".",
                ms=1.8,
                color=_PL_COLOUR,
                gid="pl" if sign > 0 else "pl-neg",
                label=f"{_PL.get(axis, 'PL')}" if sign > 0 else None,
            )
        for value, colour, ls, gid, name in (
            (bin.pl_ideal, "black", "-", "pl-ideal", "ideal PL"),
            (bin.pl_1, _BAD_COLOUR, "--", "pl-1", "PL1 (CL 1 %)"),
            (bin.pl_99, _GOOD_LINE, "--", "pl-99", "PL99 (CL 99 %)"),
        ):
            if math.isfinite(value):
                for sign in signs:
                    ax.axhline(
                        sign * value,
                        color=colour,
                        lw=0.9,
                        ls=ls,
                        gid=gid if sign > 0 else None,
                        label=f"{name} {value:.2f} m" if sign > 0 else None,
                    )
        ax.set_xlabel("sample (time order)")
        ax.set_ylabel("m")
        ax.set_title(_bin_title(bin, axis), fontsize=8.5)
        ax.legend(loc="upper right", fontsize=6.5, ncols=2)
    return ax


# ---------------------------------------------------------------------------
# HTML


_e = escape


def _text_cl(x: float) -> str:
    if not math.isfinite(x):
        return "n.a."
    if x >= 0.9999:
        q = 1.0 - x
        if q < PRINT_FLOOR:  # float rounding at 1, and no probability below 1e-15 is printed
            return "1" if q <= 0 else "> 1 − 1e-15"
        return f"1 − {q:.1e}"
    if 0 < x < PRINT_FLOOR:
        return "< 1e-15"
    return f"{x:.4g}" if x >= 1e-3 else f"{x:.2e}"


def _h_cl(x: float) -> str:
    return _e(_text_cl(x))


def _h_m(x: float) -> str:
    return "n.a." if not math.isfinite(x) else f"{x:.2f}"


def _figure(ax: Axes, name: str, alt: str, caption: str) -> str:
    return figure_html(ax, name=name, alt=alt, caption=caption)


def _detail_bins(analysis: ConfidenceAnalysis) -> list[int]:
    """The suspect bins (lowest CL first, at most _MAX_DETAIL_BINS) and the worst bin."""
    suspect = sorted(analysis.suspect, key=lambda i: (analysis.bins[i].confidence, i))[:_MAX_DETAIL_BINS]
    worst = analysis.worst
    if worst is not None and worst not in suspect:
        suspect.append(worst)
    return sorted(suspect)


def _bin_rows(analysis: ConfidenceAnalysis) -> list[str]:
    rows = []
    for i, b in enumerate(analysis.bins):
        if not b.sufficient:  # no confidence level: counted in one line under the table
            continue
        flags = []
        if b.suspect:
            flags.append('<span class="alarm">suspect</span>')
        if not b.sufficient:
            flags.append("few samples")
        cls = ' class="suspect"' if b.suspect else ""
        cells = [
            f"{b.target:.2f}",
            f"{b.lo:.2f}–{b.hi:.2f}",
            f"{b.n}",
            _h_m(b.mean),
            _h_m(b.sigma),
            _h_m(b.sigma_inflated),
            _h_cl(b.confidence),
            _h_m(b.pl_ideal),
            _h_m(b.pl_1),
            _h_m(b.pl_99),
            _h_m(b.max_abs_error),
            "n.a." if not math.isfinite(b.max_ratio) else f"{b.max_ratio:.3f}",
        ]
        tds = "".join(f'<td class="num">{c}</td>' for c in cells)
        rows.append(f'<tr{cls} data-bin="{i}">{tds}<td>{", ".join(flags)}</td></tr>')
    return rows


def confidence_section_html(analysis: ConfidenceAnalysis) -> str:
    """An HTML ``<section id="confidence-<axis>">`` presenting one :class:`ConfidenceAnalysis`.

    Contents: a summary (epochs, bins, parameters, suspect bands), the confidence-level
    figure (:func:`plot_confidence`), the table of non-empty bins (target, band, n,
    :math:`\\hat m`, :math:`\\hat\\sigma`, :math:`\\hat\\Sigma`, CL, ideal PL, PL1, PL99,
    max |error|, max ratio; suspect rows carry ``class="suspect"``), and for the suspect
    bins (the 4 lowest CLs) and the worst bin, their histogram and figure-8 plot. Figures
    are inline base64 PNGs: the fragment loads nothing. Classes used: ``num``, ``alarm``,
    ``figrow`` (those of ``report.html``) and ``suspect``.
    """
    a = analysis
    axis = a.axis
    pl_name, pe_name = _PL[axis], _PE[axis]
    sid = f"confidence-{axis}"
    nonempty = [b for b in a.bins if b.n > 0]
    n_suff = sum(b.sufficient for b in a.bins)
    suspect = [a.bins[i] for i in a.suspect]
    if suspect:
        verdict = (
            f'<p class="alarm">{len(suspect)} band(s) with a confidence level below 1 %: '
            + ", ".join(f"{b.target:.2f} m" for b in suspect)
            + f". The {pl_name} there does not bound the {pe_name} at the integrity risk.</p>"
        )
    elif nonempty:
        verdict = "<p>No band has a confidence level below 1 %.</p>"
    else:
        verdict = "<p>No epoch with a solution: nothing to analyse.</p>"
    p = a.parameters()
    n_empty = len(a.bins) - len(nonempty)
    empty = f"; {n_empty} bands without any epoch are not listed" if n_empty else ""
    summary = (
        f"<p>{a.n_epochs:,} epochs with a solution ({', '.join(_e(s) for s in a.stations)}); "
        f"{len(a.bins)} target {pl_name}s from {_h_m(a.pl_min)} m to {p['max_pl']:g} m every "
        f"{p['step']:g} m; {n_suff} bands reached {p['min_samples']} samples at least "
        f"{p['spacing']:g} s apart (band half-width {p['tolerance']:g} m, widened up to "
        f"{p['max_tolerance']:g} m){empty}. "
        f"Integrity risk {a.risk:g} per independent sample; cdf overbounding outside the central "
        f"{100 * p['core']:g} %.</p>"
    )
    parts = [summary, verdict]
    if nonempty:
        parts.append(
            _figure(
                plot_confidence(a),
                f"{sid}-cl",
                f"confidence level per target {pl_name}",
                f"Confidence level that the {pl_name}s of each band bound the {pe_name} at {a.risk:g} "
                "(logit scale; ringed: below 1 %; grey ticks: bands with too few samples for a CL).",
            )
        )
        head = [
            "target (m)",
            "band (m)",
            "n",
            "m̂ (m)",
            "σ̂ (m)",
            "Σ̂ (m)",
            "CL",
            f"ideal {pl_name} (m)",
            f"{pl_name}1 (m)",
            f"{pl_name}99 (m)",
            f"max {_ABS[axis]} (m)",
            f"max {_ABS[axis]}/{pl_name}",
            "",
        ]
        thead = "".join(f"<th>{_e(h)}</th>" for h in head)
        few = [b for b in a.bins if 0 < b.n and not b.sufficient]
        parts.append(
            f'<table class="confidence-bins"><thead><tr>{thead}</tr></thead>\n<tbody>\n'
            + "\n".join(_bin_rows(a))
            + "\n</tbody></table>"
            + (
                f'<p class="few-bands">{len(few)} further bands ({pl_name} '
                f"{min(b.lo for b in few):.2f}–{max(b.hi for b in few):.2f} m) hold fewer than "
                f"{a.min_samples} samples {a.spacing:g} s apart and have no confidence level; they are in "
                f"<code>{_e(json_name(axis))}</code>.</p>"
                if few
                else ""
            )
        )
    for i in _detail_bins(a):
        b, s = a.bins[i], a.samples[i]
        if not s.inflations:
            continue
        k = s.binding
        label = "worst band" if i == a.worst and not b.suspect else "suspect band"
        comp = s.components[k]
        shown = s.signed[0] if axis == "vertical" else s.error
        parts.append(
            f'<h3 data-bin="{i}">{_e(label.capitalize())}: {_e(_bin_title(b, axis))}</h3>\n'
            '<div class="figrow">'
            + _figure(
                plot_band_histogram(b, s.signed[k], s.inflations[k]),
                f"{sid}-hist-{i}",
                f"histogram of {comp} in the {b.target:.2f} m band",
                f"Selected {comp} errors of the band with the Gaussian of the sample sigma and the "
                "inflated Gaussian that overbounds both tails (log density).",
            )
            + _figure(
                plot_band_errors(b, shown, s.pl, axis=axis),
                f"{sid}-errors-{i}",
                f"errors and {pl_name}s of the {b.target:.2f} m band",
                f"Selected {pe_name} samples with their {pl_name}, the ideal {pl_name}, "
                f"{pl_name}1 and {pl_name}99.",
            )
            + "</div>"
        )
    title = f"{'Vertical' if axis == 'vertical' else 'Horizontal'} PL confidence level"
    return section_html(sid, title, parts)


def write_confidence_report(
    analyses: ConfidenceAnalysis | Sequence[ConfidenceAnalysis],
    directory: str | Path,
    *,
    title: str = "PL confidence level",
) -> Path:
    """Write a standalone, self-contained ``confidence.html`` into ``directory``; return its path.

    One :func:`confidence_section_html` per analysis (e.g. vertical and horizontal), inline CSS,
    no external resource, no timestamp: the same analyses give the same bytes.
    """
    items = [analyses] if isinstance(analyses, ConfidenceAnalysis) else list(analyses)
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    body = "\n".join(confidence_section_html(a) for a in items)
    return write_page(
        directory / REPORT_NAME,
        title=title,
        intro_html=(
            "Method of Comby, Farnworth and Macabiau, “EGNOS vertical protection "
            "level assessment”, ION GPS/GNSS 2003: per PL band, independent samples, cdf overbounding, "
            "and the probability that the PLs bound the errors at the integrity risk."
        ),
        body_html=body,
    )


# ---------------------------------------------------------------------------
# one call for the CLI


@dataclass(frozen=True, slots=True)
class ConfidenceRun:
    """What :func:`run_confidence` computed and wrote.

    Attributes
    ----------
    analyses : one :class:`ConfidenceAnalysis` per axis, in the order asked.
    json_paths : the ``confidence-<axis>.json`` written, parallel to ``analyses``.
    report : the ``confidence.html`` written.
    """

    analyses: tuple[ConfidenceAnalysis, ...]
    json_paths: tuple[Path, ...]
    report: Path


def run_confidence(
    table: pl.DataFrame,
    directory: str | Path,
    *,
    axes: Sequence[str] = ("vertical",),
    min_samples: int = 200,
    spacing: float = 360.0,
    tolerance: float = 0.125,
    step: float = 0.25,
    max_pl: float = 50.0,
    max_tolerance: float = 1.0,
    risk: float = 1e-7,
    station: str | None = None,
    title: str = "PL confidence level",
) -> ConfidenceRun:
    """Analyse ``table`` on each axis and write the JSON and ``confidence.html``.

    The JSON is ``confidence.json`` for one axis and ``confidence-<axis>.json`` for each of several.

    The parameters are those of :func:`~overbound.methods.confidence_level.confidence_analysis`;
    ``directory`` is created if needed.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    analyses = tuple(
        confidence_analysis(
            table,
            axis=axis,
            min_samples=min_samples,
            spacing=spacing,
            tolerance=tolerance,
            step=step,
            max_pl=max_pl,
            max_tolerance=max_tolerance,
            risk=risk,
            station=station,
        )
        for axis in dict.fromkeys(axes)
    )
    # One axis (the CLI's case) writes the issue's ``confidence.json``; several keep one file per axis.
    names = [JSON_NAME] if len(analyses) == 1 else [json_name(a.axis) for a in analyses]
    paths = tuple(write_confidence(a, directory / n) for a, n in zip(analyses, names, strict=True))
    return ConfidenceRun(analyses, paths, write_confidence_report(analyses, directory, title=title))
