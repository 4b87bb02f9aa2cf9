r"""Outputs of the parametric analysis (Kannemans 2006, NLR-TP-2006-594): HTML sections, page, one call.

* ``parametric.json`` (schema ``overbound.parametric/1``) is written by
  :func:`~overbound.methods.parametric.write_parametric`.
* HTML: :func:`parametric_section_html` (one ``<section id="parametric-<axis>">`` per axis for a
  report: a plain-words summary per service with verdict badges, the fits, the per-service table,
  every note and the figures of :mod:`overbound.report.parametric_figures`; an axis that could not be
  analysed says why) and :func:`write_parametric_report` (a standalone, self-contained
  ``parametric.html``).
* :func:`parametric_brief`: the few numbers of ``summary.json`` under ``parametric``.
* :func:`run_parametric`: analyse, and write the JSON and the page, in one call (the CLI's).

**Verdicts** (:func:`service_verdicts`), each on the conservative value, a bound at the analysis's
confidence:

* integrity: the bound of :math:`P_{HMI}` per epoch, turned into a probability per exposure (150 s per
  approach, 3600 s NPA) by the union bound :math:`\min(1, n\,p)` with :math:`n` = exposure / sampling
  interval epochs (valid whatever the dependence between epochs), against the service's integrity risk;
* availability: the bound of the unavailability :math:`S(AL)` against :math:`1 -` the availability
  requirement (0.99);
* continuity: the log-linear fit of the Clopper-Pearson bound at AL (``continuity_fit_bound``, per
  15 s window; 3600 s for NPA) against the continuity risk (8e-6 per 15 s).

A missing bound gives ``None`` (badge "no estimate"). Probabilities below :math:`10^{-300}` are
written from their :math:`\log_{10}` (``1.3·10⁻⁴¹²``), never as 0.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import polars as pl

from overbound.io.schema import as_numpy
from overbound.methods.parametric import (
    AxisParametric,
    ParametricAnalysis,
    ServiceParametric,
    parametric_analysis,
    write_parametric,
)
from overbound.methods.pooling import PE_PL
from overbound.report.figures import plot_timeseries
from overbound.report.page import (
    BELOW_FLOOR_HTML,
    badge,
    escape,
    figure_html,
    percent,
    row_table,
    scientific,
    section_html,
    write_page,
)
from overbound.report.parametric_figures import (
    TINY,
    LocalFit,
    RegionLabels,
    format_probability,
    mantissa_exponent,
    mark_alert_limits,
    plot_acf_pair,
    plot_noncontinuity,
    plot_pe_pl_contours,
    plot_pl_histogram,
    plot_ratio_probability,
    plot_ratio_timeseries,
    plot_weibull_probability,
)
from overbound.report.style import style
from overbound.services import ServiceLevel
from overbound.stats.sums import dot

__all__ = [
    "JSON_NAME",
    "REPORT_NAME",
    "ParametricRun",
    "ParametricSeries",
    "analysed_series",
    "log10_per_exposure",
    "parametric_brief",
    "parametric_section_html",
    "run_parametric",
    "section_ids",
    "service_verdicts",
    "write_parametric_report",
]

#: File name of the JSON document written by :func:`run_parametric` (and by ``overbound analyze``).
JSON_NAME = "parametric.json"
#: File name written by :func:`write_parametric_report`.
REPORT_NAME = "parametric.html"
AXES = ("vertical", "horizontal")
_AXIS = {"vertical": "Vertical", "horizontal": "Horizontal"}
_RATIO = {"vertical": "VPE/VPL", "horizontal": "HPE/HPL"}
_PE = {"vertical": "|VPE|", "horizontal": "HPE"}
_PL = {"vertical": "VPL", "horizontal": "HPL"}
#: Badge class and text of a verdict.
_e = escape


def section_ids() -> tuple[str, ...]:
    """The ``id`` of the sections :func:`parametric_section_html` writes: one per axis, vertical first."""
    return tuple(f"parametric-{axis}" for axis in AXES)


# ---------------------------------------------------------------------------
# the analysed series, for the figures


@dataclass(frozen=True, slots=True)
class ParametricSeries:
    """The epochs one axis of the analysis was fitted on, in table order, for the figures.

    Attributes
    ----------
    time_us : GPS time (µs).
    ratio : VPE/VPL with the signed VPE, or HPE/HPL.
    pl : protection level.
    """

    time_us: np.ndarray
    ratio: np.ndarray
    pl: np.ndarray


def analysed_series(table: pl.DataFrame, axis: AxisParametric) -> ParametricSeries | None:
    """The (time, ratio, PL) of the epochs ``axis`` was fitted on, rebuilt from the epoch table.

    The rule of :func:`~overbound.methods.parametric.analysed_series` (finite PE, PL > 0, no alert;
    the vertical ratio signed) on the table's own GPS times (not the pooled axis), then checked against
    the analysis: the same number of epochs, the same PL range and the same ratio fit (to 1e-9).
    ``None`` when a check fails (not the analysed table): the figures that need the series are then
    not drawn rather than drawn wrong.
    """
    pe_col, pl_col = PE_PL[axis.axis]
    if any(c not in table.columns for c in ("time", pe_col, pl_col)):
        return None
    pe = as_numpy(table[pe_col]).astype(np.float64, copy=False)
    pls = as_numpy(table[pl_col]).astype(np.float64, copy=False)
    ok = np.isfinite(pe) & np.isfinite(pls) & (pls > 0)
    if "alert" in table.columns:
        ok &= ~as_numpy(table["alert"].fill_null(False)).astype(bool)
    if int(np.count_nonzero(ok)) != axis.n_epochs:
        return None
    pls = pls[ok]
    ratio = pe[ok] / pls
    if (float(pls.min()), float(pls.max())) != tuple(axis.pl_range):
        return None
    f = axis.ratio_fit
    if f.distribution == "normal":
        moments = (float(ratio.mean()), float(np.std(ratio, ddof=1)))
    else:
        moments = (f.mean, math.sqrt(dot(ratio, ratio) / (2.0 * ratio.size)))
    if not np.allclose(moments, (f.mean, f.sigma), rtol=1e-9, atol=1e-15):
        return None
    t = as_numpy(table["time"]).astype(np.int64, copy=False)[ok]
    return ParametricSeries(t, ratio, pls)


# ---------------------------------------------------------------------------
# numbers and verdicts


def log10_per_exposure(log10_p: float | None, exposure_s: float, interval_s: float) -> float | None:
    r""":math:`\log_{10}\min(1, n p)`, :math:`n` = ``exposure_s / interval_s`` epochs (at least 1).

    The union bound: the probability that one of :math:`n` epochs is hazardous is at most the sum of
    theirs, whatever their dependence. ``None`` when ``log10_p`` is ``None`` or NaN.

    >>> round(log10_per_exposure(-9.0, 150.0, 1.0), 6)
    -6.823909
    """
    if log10_p is None or math.isnan(log10_p):
        return None
    n = max(1.0, exposure_s / interval_s)
    return min(0.0, float(log10_p) + math.log10(n))


def _exp10(lg: float | None) -> float | None:
    return None if lg is None else 10.0**lg


def _integrity_log10(a: AxisParametric, s: ServiceParametric, level: ServiceLevel) -> float | None:
    return log10_per_exposure(s.log10_p_hmi_bound, level.integrity_exposure_s, a.interval_s)


def service_verdicts(a: AxisParametric, level: ServiceLevel) -> dict[str, bool | None]:
    """``{"integrity", "availability", "continuity"}`` -> meets the requirement (``None``: no bound).

    See the module docstring for the rules. ``{}`` when the service has no alert limit on the axis.
    """
    s = a.services.get(level.name)
    if s is None:
        return {}
    lg = _integrity_log10(a, s, level)
    unav = s.unavailability_bound
    cont = s.continuity_fit_bound
    return {
        "integrity": None if lg is None else bool(lg <= math.log10(level.integrity_risk)),
        "availability": None if unav is None else bool(unav <= 1.0 - level.availability),
        "continuity": None if cont is None else bool(cont <= level.continuity_risk),
    }


def _levels(analysis: ParametricAnalysis) -> dict[str, ServiceLevel]:
    return {s.name: s for s in analysis.services}


def parametric_brief(analysis: ParametricAnalysis) -> dict:
    """Per axis, the parametric result in a few numbers for ``summary.json`` (the rest: ``parametric.json``).

    Per axis: ``p_mi``, ``p_mi_bound`` and their ``log10_*`` (finite where the probability underflows),
    ``unavailable_reason`` (``null``, or why the axis has no result, all numbers then ``null``) and per
    service with an alert limit on the axis ``p_hmi_bound``, ``log10_p_hmi_bound``,
    ``log10_p_hmi_bound_per_exposure``, ``unavailability_fit``, ``unavailability_bound``,
    ``unavailability_counted``, ``continuity_counted``, ``continuity_fit_bound`` and the three verdicts
    ``meets_integrity``, ``meets_availability``, ``meets_continuity`` (:func:`service_verdicts`).
    """
    levels = _levels(analysis)
    out: dict = {}
    for axis in AXES:
        a = analysis.axis(axis)
        if a is None:
            out[axis] = {
                "p_mi": None,
                "log10_p_mi": None,
                "p_mi_bound": None,
                "log10_p_mi_bound": None,
                "services": {},
                "unavailable_reason": analysis.reasons.get(axis, "not analysed"),
            }
            continue
        services = {}
        for name, s in a.services.items():
            if s is None:
                continue
            v = service_verdicts(a, levels[name])
            services[name] = {
                "p_hmi_bound": s.p_hmi_bound,
                "log10_p_hmi_bound": s.log10_p_hmi_bound,
                "log10_p_hmi_bound_per_exposure": _integrity_log10(a, s, levels[name]),
                "unavailability_fit": s.unavailability_fit,
                "unavailability_bound": s.unavailability_bound,
                "unavailability_counted": s.unavailability_counted,
                "continuity_counted": s.continuity_counted,
                "continuity_fit_bound": s.continuity_fit_bound,
                "meets_integrity": v["integrity"],
                "meets_availability": v["availability"],
                "meets_continuity": v["continuity"],
            }
        out[axis] = {
            "p_mi": a.p_mi,
            "log10_p_mi": a.log10_p_mi,
            "p_mi_bound": a.p_mi_bound,
            "log10_p_mi_bound": a.log10_p_mi_bound,
            "services": services,
            "unavailable_reason": None,
        }
    return out


# ---------------------------------------------------------------------------
# formatting: every _h_* function returns HTML


def _h_p(p: float | None, lg: float | None = None) -> str:
    """A probability: :func:`~overbound.report.page.scientific`, or from its log10 below 1e-300."""
    if p is not None and math.isfinite(p) and p >= TINY:
        return scientific(p)
    me = mantissa_exponent(p, lg)
    if me is None:
        return "0" if p == 0 else "n.a."
    m, e = me
    if e < -15:  # not printed as a number (overbound.numbers.PRINT_FLOOR)
        return BELOW_FLOOR_HTML
    return f"{m:.3g}·10<sup>{'−' if e < 0 else ''}{abs(e)}</sup>"


def _h_pb(p: float | None, lg: float | None, pb: float | None, lgb: float | None) -> str:
    """``nominal [bound]``."""
    return f"{_h_p(p, lg)} [{_h_p(pb, lgb)}]"


def _mi(axis: str) -> str:
    """The MI event of the ratio (HTML): two-sided for the signed vertical ratio."""
    return "|VPE/VPL| &gt; 1" if axis == "vertical" else "HPE/HPL &gt; 1"


def _h_x(x: float | None, digits: int = 4) -> str:
    return "n.a." if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def _h_s(x: float) -> str:
    """A duration in seconds (``inf``: not reached)."""
    if math.isinf(x):
        return "not reached (ACF above 1/e)"
    return "n.a." if math.isnan(x) else f"{x:g}&nbsp;s"


def _t_pb(p: float | None, lg: float | None, pb: float | None, lgb: float | None) -> str:
    """``nominal [bound]`` as plain text for the figures."""
    return f"{format_probability(p, lg)} [{format_probability(pb, lgb)}]"


# ---------------------------------------------------------------------------
# summary on top


def _summary_rows(analysis: ParametricAnalysis, a: AxisParametric) -> list[list[str]]:
    levels = _levels(analysis)
    rows = []
    for name, s in a.services.items():
        if s is None:
            continue
        lv = levels[name]
        v = service_verdicts(a, lv)
        lg = _integrity_log10(a, s, lv)
        n_exp = max(1.0, lv.integrity_exposure_s / a.interval_s)
        integ = (
            f"P<sub>HMI</sub> {_h_pb(s.p_hmi, s.log10_p_hmi, s.p_hmi_bound, s.log10_p_hmi_bound)} per epoch; "
            f"bound per {lv.integrity_exposure_s:g}&nbsp;s {_h_p(_exp10(lg), lg)} against "
            f"{scientific(lv.integrity_risk)} "
            + badge(v["integrity"], f"{name}-integrity", f"union bound over {n_exp:g} epochs")
        )
        unav = _h_pb(
            s.unavailability_fit,
            s.log10_unavailability_fit,
            s.unavailability_bound,
            s.log10_unavailability_bound,
        )
        avail = (
            f"unavailability {unav}, counted {_h_p(s.unavailability_counted)} against "
            f"{scientific(1.0 - lv.availability)} "
            + badge(v["availability"], f"{name}-availability", "bound of the Weibull unavailability")
        )
        cont = (
            f"counted {_h_p(s.continuity_counted)}, fit {_h_p(s.continuity_fit)} "
            f"[{_h_p(s.continuity_fit_bound)}] per {s.continuity_window_s:g}&nbsp;s against "
            f"{scientific(lv.continuity_risk)} "
            + badge(v["continuity"], f"{name}-continuity", "log-linear fit of the bound at AL")
        )
        rows.append([_e(name), f"{s.alert_limit:g}&nbsp;m", integ, avail, cont])
    return rows


def _lead(analysis: ParametricAnalysis, a: AxisParametric) -> str:
    conf = percent(analysis.confidence)
    r = a.ratio_fit
    law = (
        f"normal (mean {_h_x(r.mean, 3)}, σ {_h_x(r.sigma, 3)})"
        if r.distribution == "normal"
        else f"Rayleigh (σ {_h_x(r.sigma, 3)})"
    )
    bound = (
        f"its one-sided {conf} bound {_h_p(a.p_mi_bound, a.log10_p_mi_bound)} from "
        f"{a.n_effective:,.0f} effective samples (decorrelation time {_h_s(a.decorrelation_s)})"
        if a.p_mi_bound is not None or a.log10_p_mi_bound is not None
        else "no bound (see the notes)"
    )
    return (
        f"<p>Kannemans (2006) method: the ratio {_e(_RATIO[a.axis])} over {a.n_epochs:,} epochs is "
        f"{law}, so P<sub>MI</sub> = P({_mi(a.axis)}) = {_h_p(a.p_mi, a.log10_p_mi)} per "
        f"epoch, {bound}; the {_e(_PL[a.axis])} is Weibull (a {_h_x(a.weibull.a, 4)}, b "
        f"{_h_x(a.weibull.b, 4)}). Per service, in brackets the bounds, and the verdicts on them: "
        "integrity from the HMI bound per exposure (union bound over its epochs), availability from the "
        "unavailability bound, continuity from the fit of the bound at the alert limit.</p>"
    )


# ---------------------------------------------------------------------------
# tables


def _fit_text(f) -> str:
    if f is None:
        return "none (fewer than 3 alert limits with a loss)"
    return (
        f"log<sub>10</sub> P = {f.a:.4g} {'+' if f.b >= 0 else '−'} {abs(f.b):.4g}·AL over "
        f"{f.al_min:.4g}–{f.al_max:.4g}&nbsp;m ({f.n_points} points)"
    )


def _fits_rows(analysis: ParametricAnalysis, a: AxisParametric) -> list[list[str]]:
    conf = percent(analysis.confidence)
    r, rb = a.ratio_fit, a.ratio_bound_fit
    ratio = _e(_RATIO[a.axis])
    how = "auto: first lag with ACF below 1/e" if a.decorrelation_auto else "given"
    if r.distribution == "normal":
        fit = f"normal: m {_h_x(r.mean)}, σ {_h_x(r.sigma)}"
        fit_how = f"sample mean and standard deviation of {ratio} (signed)"
        b_how = "Bonferroni: σ by χ², m by Student t, each at (1 + c)/2"
        b_val = "n.a." if rb is None else f"m {_h_x(rb.mean)}, σ {_h_x(rb.sigma)}"
    else:
        fit = f"Rayleigh: σ {_h_x(r.sigma)} (mean {_h_x(r.mean)})"
        fit_how = f"maximum likelihood, σ² = Σr²/2n of {ratio}"
        b_how = "χ²(2n<sub>e</sub>) bound of σ²"
        b_val = "n.a." if rb is None else f"σ {_h_x(rb.sigma)}"
    w = a.weibull
    rows = [
        ["ratio fit", fit, fit_how],
        [
            "P<sub>MI</sub> per epoch",
            _h_p(a.p_mi, a.log10_p_mi),
            f"P({_mi(a.axis)}), computed in log space",
        ],
        [
            f"bound of P<sub>MI</sub> ({conf})",
            _h_p(a.p_mi_bound, a.log10_p_mi_bound),
            f"at the bound fit {b_val}",
        ],
        ["bound of the ratio fit", b_val, b_how],
        [
            f"decorrelation time of {ratio}",
            _h_s(a.decorrelation_s),
            f"{how}; n<sub>e</sub> = N·Δ/τ = {_h_x(a.n_effective, 5)} effective samples",
        ],
        [
            f"decorrelation time of {_e(_PL[a.axis])}",
            _h_s(a.pl_decorrelation_s),
            f"{how}; n<sub>e</sub> = {_h_x(a.pl_n_effective, 5)} for the Weibull bound",
        ],
        [
            f"Weibull fit of {_e(_PL[a.axis])}",
            f"a {_h_x(w.a)}, b {_h_x(w.b)}",
            f"maximum likelihood, pdf a b x<sup>b−1</sup> e<sup>−a x<sup>b</sup></sup>; scale "
            f"{_h_x(w.a ** (-1.0 / w.b))}&nbsp;m; {'converged' if w.converged else 'NOT converged'} in "
            f"{w.iterations} evaluations",
        ],
        [
            "epochs fitted",
            f"{a.n_epochs:,}",
            f"of {a.n_rows:,} rows: {a.n_no_solution:,} without a solution, {a.n_alert:,} with an alert "
            f"(counted unavailable); {a.n_stations} station(s), sampling {a.interval_s:g}&nbsp;s",
        ],
        [
            f"{_e(_PL[a.axis])} range",
            f"{a.pl_range[0]:.4g}–{a.pl_range[1]:.4g}&nbsp;m",
            "alert limits of the continuity curve",
        ],
    ]
    for win in sorted(a.continuity_curves):
        rows.append(
            [
                f"non-continuity per {win:g}&nbsp;s, whole range",
                _fit_text(a.continuity_fits[win]),
                f"bound: {_fit_text(a.continuity_fits_bound[win])}",
            ]
        )
    return rows


def _services_rows(a: AxisParametric) -> list[list[str]]:
    rows = []
    for name, s in a.services.items():
        if s is None:
            continue
        src = f" ({s.continuity_fit_source})" if s.continuity_fit_source else ""
        rows.append(
            [
                _e(name),
                f"{s.alert_limit:g}&nbsp;m",
                _h_pb(
                    s.unavailability_fit,
                    s.log10_unavailability_fit,
                    s.unavailability_bound,
                    s.log10_unavailability_bound,
                ),
                f"{_h_p(s.unavailability_counted)} "
                f"<small>(fitted epochs {_h_p(s.unavailability_counted_fitted)})</small>",
                _h_pb(s.p_hmi, s.log10_p_hmi, s.p_hmi_bound, s.log10_p_hmi_bound),
                _h_pb(
                    s.p_mi_pl_above_al,
                    s.log10_p_mi_pl_above_al,
                    s.p_mi_pl_above_al_bound,
                    s.log10_p_mi_pl_above_al_bound,
                ),
                _h_pb(
                    s.p_mi_pl_below_al,
                    s.log10_p_mi_pl_below_al,
                    s.p_mi_pl_below_al_bound,
                    s.log10_p_mi_pl_below_al_bound,
                ),
                f"{_h_p(s.continuity_counted)} <small>({s.continuity_n_fail:,} of "
                f"{s.continuity_n_windows:,} windows, {s.continuity_n_events:,} events)</small>",
                f"{_h_p(s.continuity_fit)} [{_h_p(s.continuity_fit_bound)}]{_e(src)}",
            ]
        )
    return rows


def _none_services(a: AxisParametric) -> list[str]:
    return [name for name, s in a.services.items() if s is None]


def _messages(a: AxisParametric) -> list[str]:
    out = list(a.notes)
    for win, curve in sorted(a.continuity_curves.items()):
        if not np.any(curve.n_windows):
            why = f": the sampling interval {a.interval_s:g} s exceeds it" if a.interval_s > win else ""
            out.append(f"no {win:g} s continuity window could be counted{why}")
    for name, s in a.services.items():
        if s is not None and s.reason:
            out.append(f"{name}: {s.reason}")
    missing = _none_services(a)
    if missing:
        out.append(f"no alert limit on this axis: {', '.join(missing)}")
    return list(dict.fromkeys(out))


# ---------------------------------------------------------------------------
# figures


def _alert_limits(a: AxisParametric) -> dict[str, float]:
    return {name: s.alert_limit for name, s in a.services.items() if s is not None}


def _groups(
    a: AxisParametric, *, by_window: bool = False
) -> list[tuple[float, float, list[ServiceParametric]]]:
    """Services with the same alert limit (and window): one figure or fit each, in AL order."""
    groups: dict[tuple[float, float], list[ServiceParametric]] = {}
    for s in a.services.values():
        if s is not None:
            key = (s.alert_limit, s.continuity_window_s if by_window else 0.0)
            groups.setdefault(key, []).append(s)
    return [(al, w, ss) for (al, w), ss in sorted(groups.items())]


def _names(ss: Sequence[ServiceParametric]) -> str:
    return ", ".join(s.name for s in ss)


def _labels(s: ServiceParametric) -> RegionLabels:
    return RegionLabels(
        _t_pb(
            s.unavailability_fit,
            s.log10_unavailability_fit,
            s.unavailability_bound,
            s.log10_unavailability_bound,
        ),
        _t_pb(
            s.p_mi_pl_above_al,
            s.log10_p_mi_pl_above_al,
            s.p_mi_pl_above_al_bound,
            s.log10_p_mi_pl_above_al_bound,
        ),
        _t_pb(
            s.p_mi_pl_below_al,
            s.log10_p_mi_pl_below_al,
            s.p_mi_pl_below_al_bound,
            s.log10_p_mi_pl_below_al_bound,
        ),
        _t_pb(s.p_hmi, s.log10_p_hmi, s.p_hmi_bound, s.log10_p_hmi_bound),
    )


def _timeseries(table: pl.DataFrame, a: AxisParametric):
    ax = plot_timeseries(table, axis=a.axis)
    with style():
        top = ax.get_ylim()[1]
        mark_alert_limits(ax, _alert_limits(a), vertical=False, lo=0.0, hi=top)
        ax.set_ylim(0.0, top)
        ax.legend(loc="upper right", ncols=3)
    return ax


def _figures(
    analysis: ParametricAnalysis, a: AxisParametric, table: pl.DataFrame | None, timeseries: bool
) -> tuple[list[tuple[bool, str]], list[str]]:
    """The figures (HTML) of one axis in reading order, and the names of those not drawn and why."""
    sid = f"parametric-{a.axis}"
    ratio, pe, pl_ = _RATIO[a.axis], _PE[a.axis], _PL[a.axis]
    series = None if table is None else analysed_series(table, a)
    why = (
        "the epochs are not at hand: no epoch table given, or a dataset analysed partition by partition"
        if table is None
        else "the table is not the analysed one"
    )
    drawn: list[tuple[bool, str]] = []  # (full width, HTML)
    skipped: list[str] = []
    levels = _levels(analysis)

    def add(ok: bool, reason: str, name: str, draw, alt: str, caption: str, wide: bool = False) -> None:
        if ok:
            drawn.append((wide, figure_html(draw(), name=f"{sid}-{name}", alt=alt, caption=caption)))
        else:
            skipped.append(f"{name} ({reason})")

    if timeseries:
        add(
            table is not None,
            why,
            "timeseries",
            lambda: _timeseries(table, a),
            f"time series of {pe} and {pl_} against GPS time with the services' alert limits",
            f"{pe} and {pl_} against GPS time (figures 1 and 17 of the paper), drawn as the per-pixel "
            "minimum/maximum envelope, with the alert limits.",
            wide=True,
        )
        add(
            series is not None,
            why,
            "ratio-timeseries",
            lambda: plot_ratio_timeseries(series.time_us, series.ratio, axis=a.axis),
            f"time series of the ratio {ratio} against GPS time",
            f"The ratio {ratio} the MI probability is fitted to (figures 3 and 19), as its per-pixel "
            "minimum/maximum envelope; MI is a ratio beyond 1.",
            wide=True,
        )
    add(
        series is not None,
        why,
        "ratio-probability",
        lambda: plot_ratio_probability(
            series.ratio, a.ratio_fit, axis=a.axis, bound=a.ratio_bound_fit, p_mi=(a.p_mi, a.log10_p_mi)
        ),
        f"{a.ratio_fit.distribution} probability plot of {ratio} with the fitted line and its bound",
        f"{a.ratio_fit.distribution.capitalize()} probability plot of {ratio} (figure 4): data of the "
        "fitted law lie on the straight line; the dashed line is the bound P_MI is computed at.",
    )
    add(
        series is not None,
        why,
        "weibull-probability",
        lambda: plot_weibull_probability(series.pl, a.weibull, axis=a.axis, alert_limits=_alert_limits(a)),
        f"Weibull probability plot of {pl_} with the fitted line and the alert limits",
        f"Weibull probability plot of {pl_} (figure 6): a Weibull sample lies on the line "
        "ln a + b ln x; the unavailability is read where it crosses each alert limit.",
    )
    add(
        a.acf_lags_s.size > 0,
        "no autocorrelation",
        "acf",
        lambda: plot_acf_pair(
            a.acf_lags_s,
            a.ratio_acf,
            a.pl_acf,
            axis=a.axis,
            ratio_decorrelation_s=a.decorrelation_s,
            pl_decorrelation_s=a.pl_decorrelation_s,
        ),
        f"autocorrelation of {ratio} and of {pl_} against lag with the 1/e line and each decorrelation time",
        f"Autocorrelation of {ratio} and of {pl_} (figures 5 and 8): each decorrelation time sets the "
        "effective sample size of its bounds.",
    )
    add(
        series is not None,
        why,
        "pl-histogram",
        lambda: plot_pl_histogram(
            series.pl,
            a.weibull,
            axis=a.axis,
            cov=a.weibull_cov,
            confidence=analysis.confidence,
            alert_limits=_alert_limits(a),
        ),
        f"histogram of {pl_} as a density with the Weibull density and its confidence band",
        f"Histogram of {pl_} with the Weibull density and its pointwise {100 * analysis.confidence:g} % "
        "band from the decorrelated sample (figures 7 and 20).",
    )
    for al, _, ss in _groups(a):
        names = _names(ss)
        add(
            True,
            "",
            f"contours-{al:g}",
            lambda al=al, ss=ss, names=names: plot_pe_pl_contours(
                a.ratio_fit,
                a.weibull,
                alert_limit=al,
                axis=a.axis,
                labels=_labels(ss[0]),
                title=f"{names}: AL {al:g} m",
            ),
            f"joint density of {pe} and {pl_} as contours relative to its maximum with the Stanford lines "
            f"and the region probabilities at AL {al:g} m ({names})",
            f"{names} (AL {al:g} m): density of ({pe}, {pl_}) at 1, 0.5, 0.1, 0.01, 1e-3, 1e-5 and 1e-10 of "
            "its maximum, and per epoch the unavailability, P_MI with PL above and below AL and P_HMI, "
            "bounds in brackets (figures 11 and 22).",
        )
    for win in sorted(a.continuity_curves):
        local = [
            LocalFit(
                _names(ss),
                al,
                ss[0].continuity_local_fit,
                ss[0].continuity_local_fit_bound,
                min(levels[s.name].continuity_risk for s in ss),
            )
            for al, w, ss in _groups(a, by_window=True)
            if w == win
        ]
        add(
            bool(np.any(a.continuity_curves[win].n_windows)),
            f"no {win:g} s window countable",
            f"noncontinuity-{win:g}",
            lambda win=win, local=local: plot_noncontinuity(
                a.continuity_curves[win],
                axis=a.axis,
                fit=a.continuity_fits[win],
                fit_bound=a.continuity_fits_bound[win],
                local=local,
            ),
            f"non-continuity per {win:g} s window against the alert limit, log scale, with the log-linear "
            "fits of the risk and of its bound over the whole range and around each service's alert limit",
            f"Non-continuity per {win:g} s against the alert limit (figures 12-16 and 23): counted points, "
            "their one-sided bounds, the log-linear fit over the PL range and within ±10 m of each AL "
            "(thick), dashed the fits of the bounds.",
            wide=True,
        )
    return drawn, skipped


def _figure_rows(drawn: list[tuple[bool, str]]) -> str:
    """Full-width figures alone, runs of the others side by side in a ``figrow``."""
    out: list[str] = []
    run: list[str] = []
    for wide, html in [*drawn, (True, "")]:
        if not wide:
            run.append(html)
            continue
        if run:
            out.append('<div class="figrow">' + "".join(run) + "</div>")
            run = []
        if html:
            out.append(html)
    return "\n".join(out)


# ---------------------------------------------------------------------------
# sections and page


def _axis_section(
    analysis: ParametricAnalysis, a: AxisParametric, table: pl.DataFrame | None, timeseries: bool
) -> str:
    sid = f"parametric-{a.axis}"
    title = f"{_AXIS[a.axis]} parametric availability, integrity and continuity"
    summary = _summary_rows(analysis, a)
    parts = [_lead(analysis, a)]
    if summary:
        parts.append(
            row_table(
                ["service", "AL", "integrity", "availability", "continuity"], summary, "parametric-summary"
            )
        )
    else:
        parts.append("<p>No service level with an alert limit on this axis.</p>")
    msgs = _messages(a)
    if msgs:
        parts.append('<ul class="parametric-notes">' + "".join(f"<li>{_e(m)}</li>" for m in msgs) + "</ul>")
    parts += [
        "<h3>Fits</h3>",
        row_table(["quantity", "value", "how"], _fits_rows(analysis, a), "parametric-fits"),
    ]
    if summary:
        parts += [
            "<h3>Per service (per epoch; continuity per window)</h3>",
            row_table(
                [
                    "service",
                    "AL",
                    "unavail. fit [bound]",
                    "unavail. counted",
                    "P<sub>HMI</sub> [bound]",
                    "P<sub>MI</sub>, PL ≥ AL",
                    "P<sub>MI</sub>, PL &lt; AL",
                    "non-cont. counted",
                    "non-cont. fit [bound]",
                ],
                _services_rows(a),
                "parametric-services",
            ),
        ]
    drawn, skipped = _figures(analysis, a, table, timeseries)
    parts += ["<h3>Figures</h3>", _figure_rows(drawn)]
    return section_html(sid, title, parts, skipped)


def _failure_section(axis: str, reason: str) -> str:
    title = f"{_AXIS.get(axis, axis)} parametric availability, integrity and continuity"
    alarm = f'<p class="alarm">No parametric estimate: {_e(reason)}</p>'
    return section_html(f"parametric-{axis}", title, [alarm])


def parametric_section_html(
    analysis: ParametricAnalysis, table: pl.DataFrame | None = None, *, timeseries: bool = True
) -> str:
    """The HTML sections of a :class:`~overbound.methods.parametric.ParametricAnalysis`, one per axis.

    Parameters
    ----------
    analysis : the result of :func:`~overbound.methods.parametric.parametric_analysis`.
    table : the analysed epoch table, for the figures drawn from the epochs (time series, probability
        plots, PL histogram); they are listed as not drawn without it.
    timeseries : draw the time series of PE and PL and of their ratio; ``report.html`` passes ``False``
        (it has its own time series and safety-index histograms, and each figure costs about 0.2 s).

    Returns
    -------
    str
        ``<section id="parametric-vertical">`` then ``parametric-horizontal`` (:func:`section_ids`).
        Each holds: a lead in plain words (ratio law, P_MI and its bound, Weibull); the per-service
        summary (``parametric-summary``: integrity, availability and continuity against the service's
        requirements with verdict badges, see the module docstring); the notes of the analysis; the
        fits (``parametric-fits``); the per-service probabilities (``parametric-services``, nominal
        [bound]); the figures, each an inline PNG with alt text and a caption, those that could not
        be drawn listed. An axis without a result says why. The fragment loads nothing.
    """
    out = []
    for axis in AXES:
        a = analysis.axis(axis)
        if a is None:
            out.append(_failure_section(axis, analysis.reasons.get(axis, "not analysed")))
        else:
            out.append(_axis_section(analysis, a, table, timeseries))
    return "\n".join(out)


def write_parametric_report(
    analysis: ParametricAnalysis,
    directory: str | Path,
    *,
    title: str = "Parametric availability, integrity and continuity",
    table: pl.DataFrame | None = None,
) -> Path:
    """Write a standalone, self-contained ``parametric.html`` into ``directory``; return its path.

    The sections of :func:`parametric_section_html`, inline CSS, no external resource, no timestamp: the
    same analysis (and table) gives the same bytes.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    return write_page(
        directory / REPORT_NAME,
        title=title,
        intro_html=(
            f"Method of Kannemans, “An integrity, availability and continuity test "
            "method for EGNOS/WAAS” (NLR-TP-2006-594): the ratio PE/PL fitted by a normal (vertical) or "
            "Rayleigh (horizontal) law gives P<sub>MI</sub>; a Weibull fit of the PL the unavailability; "
            "their product, integrated over the Stanford regions, P<sub>HMI</sub>; the 15&nbsp;s count "
            "over a range of alert limits the non-continuity and its log-linear fit. Bounds at "
            f"{percent(analysis.confidence)} from the effective sample sizes of the correlated series."
        ),
        body_html=parametric_section_html(analysis, table),
    )


# ---------------------------------------------------------------------------
# one call for the CLI


@dataclass(frozen=True, slots=True)
class ParametricRun:
    """What :func:`run_parametric` computed and wrote.

    Attributes
    ----------
    analysis : the :class:`~overbound.methods.parametric.ParametricAnalysis`.
    json_path : the ``parametric.json`` written.
    report : the ``parametric.html`` written.
    """

    analysis: ParametricAnalysis
    json_path: Path
    report: Path


def run_parametric(
    table: pl.DataFrame,
    directory: str | Path,
    *,
    services: Sequence[str | ServiceLevel] | None = None,
    decorrelation: str | float = "auto",
    confidence: float = 0.95,
    title: str = "Parametric availability, integrity and continuity",
) -> ParametricRun:
    """Analyse ``table`` and write ``parametric.json`` and ``parametric.html`` into ``directory``.

    The parameters are those of :func:`~overbound.methods.parametric.parametric_analysis`.

    Raises
    ------
    ValueError
        Bad options (from :func:`~overbound.methods.parametric.parametric_analysis`); nothing is
        written then.
    """
    analysis = parametric_analysis(
        table,
        services=None if services is None else tuple(services),
        decorrelation=decorrelation,
        confidence=confidence,
    )
    return write_parametric_run(analysis, directory, title=title, table=table)


def write_parametric_run(
    analysis: ParametricAnalysis,
    directory: str | Path,
    *,
    title: str = "Parametric availability, integrity and continuity",
    table: pl.DataFrame | None = None,
) -> ParametricRun:
    """Write ``parametric.json`` and ``parametric.html`` of ``analysis`` into ``directory``
    (``table``: the analysed epochs, for the figures drawn from them; a dataset's analysis has none)."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    json_path = directory / JSON_NAME
    write_parametric(analysis, json_path)
    report = write_parametric_report(analysis, directory, title=title, table=table)
    return ParametricRun(analysis, json_path, report)
