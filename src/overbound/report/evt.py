"""Outputs of the EVT tail extrapolation (Veerman et al., GIMAT): HTML section, standalone page, one call.

* ``evt.json`` (schema ``overbound.evt/1``) is written by
  :func:`~overbound.methods.tail_extrapolation.write_evt`; :func:`json_name` names the per-axis file
  of ``overbound analyze``.
* HTML: :func:`evt_section_html` (a ``<section id="evt-<axis>">`` for a report: headline table,
  epoch counts, per-service HMI table, every message of the analysis and the figures of
  :mod:`overbound.report.evt_figures`), :func:`evt_failure_html` (the section of an axis that could
  not be analysed, saying why) and :func:`write_evt_report` (a standalone, self-contained
  ``evt.html``).
* :func:`run_evt`: analyse, and write the JSON and the page, in one call (the CLI's).
* :func:`analysed_series`: the safety-index series the analysis ran on, rebuilt from the epoch
  table for the clusters figure (the :class:`TailAnalysis` does not keep it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import polars as pl
from matplotlib.axes import Axes

from overbound.methods.tail_extrapolation import (
    APPROACH_S,
    TailAnalysis,
    TailFit,
    tail_analysis,
    write_evt,
)
from overbound.methods.tail_extrapolation import analysed_series as tail_series
from overbound.report.evt_figures import (
    plot_acf,
    plot_clusters,
    plot_krs,
    plot_mean_excess,
    plot_p_mi_vs_threshold,
    plot_shape_stability,
    plot_tail_fit,
    plot_vk,
)
from overbound.report.page import (
    badge,
    escape,
    figure_html,
    percent,
    row_table,
    scientific,
    section_html,
    write_page,
)
from overbound.report.style import style
from overbound.stats.dependence import VKCurve

__all__ = [
    "JSON_NAME",
    "REPORT_NAME",
    "EvtRun",
    "analysed_series",
    "evt_failure_html",
    "evt_section_html",
    "json_name",
    "run_evt",
    "write_evt_report",
]

#: File name of the JSON document written by :func:`run_evt`.
JSON_NAME = "evt.json"
#: File name written by :func:`write_evt_report`.
REPORT_NAME = "evt.html"
_AXIS = {"vertical": "Vertical", "horizontal": "Horizontal"}
_SI = {"vertical": "|VPE|/VPL", "horizontal": "HPE/HPL"}
#: Badge class and text of a service's verdict (``meets_requirement``).
_e = escape


def json_name(axis: str) -> str:
    """File name of the JSON document of one axis in ``overbound analyze``: ``evt-<axis>.json``."""
    return f"evt-{axis}.json"


# ---------------------------------------------------------------------------
# the analysed series, for the clusters figure


def analysed_series(table: pl.DataFrame, analysis: TailAnalysis) -> tuple[np.ndarray, np.ndarray] | None:
    """Times (s, on the analysis's pooled time axis) and SI of the epochs ``analysis`` ran on.

    The series is rebuilt by :func:`~overbound.methods.tail_extrapolation.analysed_series` (the
    analysis does not keep it), then checked against the analysis: the same number of epochs,
    and every cluster maximum at its index, time and value. ``None`` when the check fails (the rule
    changed, or ``table`` is not the analysed one): the clusters figure is then not drawn rather
    than drawn wrong.
    """
    t = analysis.tail
    if t is None:
        return None
    svc = analysis.services.get(analysis.service) if analysis.service is not None else None
    try:
        time_s, si = tail_series(
            table, axis=analysis.axis, service=svc.service if svc is not None else analysis.service
        )
    except ValueError:  # InputError included: not the analysed table; an unknown service name
        return None
    c = t.clusters
    if si.size != t.n_total or (c.n_clusters and int(c.peak_index.max()) >= si.size):
        return None
    if not (
        np.array_equal(si[c.peak_index], c.peak_value) and np.allclose(time_s[c.peak_index], c.peak_time)
    ):
        return None
    return time_s, si


# ---------------------------------------------------------------------------
# formatting: every _h_* function returns HTML


def _h_ci(ci: tuple[float, float]) -> str:
    return f"[{scientific(ci[0])}, {scientific(ci[1])}]"


def _h_x(x: float | None, digits: int = 4) -> str:
    """A plain number (shape, scale, SI) to ``digits`` significant digits."""
    return "n.a." if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def _h_ix(ci: tuple[float, float], digits: int = 3) -> str:
    return f"[{_h_x(ci[0], digits)}, {_h_x(ci[1], digits)}]"


# ---------------------------------------------------------------------------
# tables


def _headline_rows(a: TailAnalysis, t: TailFit) -> list[list[str]]:
    conf = percent(a.confidence)
    dep = a.dependence
    n_app = APPROACH_S / a.counts.interval_s
    choice = t.threshold_choice
    if choice is None:
        how = "given"
    else:
        how = f"automatic: {_e(choice.method)}; Anderson-Darling p-value {_h_x(choice.goodness_of_fit, 3)}"
    unit = "cluster maxima" if t.decluster else "all exceedances"
    bca = f", the BCa interval {_h_ci(t.p_ci_bca)}" if math.isfinite(t.p_ci_bca[1]) else ""
    rows = [
        ["P<sub>MI</sub> per epoch", scientific(t.p), f"P(SI &gt; 1), SI = {_e(_SI[a.axis])}"],
        [
            f"{conf} interval",
            _h_ci(t.p_ci),
            f"union of the bootstrap percentile interval {_h_ci(t.p_ci_bootstrap)} ({a.n_boot:,} "
            f"resamples){bca} and the profile-likelihood interval {_h_ci(t.p_profile_ci)}",
        ],
        [
            "upper bound P<sub>MI95</sub>",
            scientific(t.p_95),
            f"the upper end of the {conf} interval",
        ],
        [
            f"P<sub>MI</sub> per approach ({APPROACH_S:g}&nbsp;s)",
            scientific(t.p_approach),
            f"{n_app:g} epochs; {conf} interval {_h_ci(t.p_approach_ci)} (that of P<sub>MI</sub> mapped)",
        ],
        [
            "upper bound per approach",
            scientific(t.p_approach_95),
            f"the upper end of the {conf} interval per approach",
        ],
        [
            "MI epochs observed (SI &gt; 1)",
            f"{a.n_mi:,}",
            f"of {a.counts.n_used:,} epochs analysed; largest SI {_h_x(a.si_max)}",
        ],
        ["threshold u", _h_x(t.threshold), how],
    ]
    if dep is not None:
        gap_how = "read from the V<sub>K</sub> curve" if dep.cluster_gap_auto else "given"
        rows.append(
            [
                "cluster gap K<sub>T</sub>",
                f"{dep.cluster_gap_s:g}&nbsp;s",
                f"{gap_how}; decorrelation time {dep.decorrelation_s:g}&nbsp;s",
            ]
        )
    rows += [
        ["clusters above u", f"{t.n_clusters:,}", f"GPD fitted to the {unit}"],
        ["exceedances of u", f"{t.n_exceedances:,}", f"exceedance rate {scientific(t.zeta)} per epoch"],
        ["extremal index θ", _h_x(t.extremal_index, 3), "Ferro-Segers intervals estimator at u"],
    ]
    c = t.cluster_size
    if c is not None and t.decluster:
        rows.append(
            [
                "mean cluster size near SI = 1",
                _h_x(c.mean, 3),
                f"{c.sizes.size:,} clusters above SI = {_h_x(c.level)} (at u: {_h_x(c.at_threshold, 3)}); "
                f"P<sub>MI</sub> = MI clusters per epoch {scientific(t.cluster_rate)} × this size",
            ]
        )
    g = t.gpd
    if g is not None:
        end = f"; finite endpoint SI = {_h_x(g.endpoint)}" if math.isfinite(g.endpoint) else ""
        rows += [
            [
                "GPD shape ξ",
                _h_x(g.xi, 3),
                f"profile {conf} interval {_h_ix(t.shape_ci)}; bootstrap {_h_ix(t.shape_ci_bootstrap)}"
                + ("" if g.regular else '; <span class="alarm">non-regular (ξ &lt; −0.5)</span>'),
            ],
            ["GPD scale σ", _h_x(g.sigma, 3), f"{g.n:,} values above u{end}"],
        ]
    rows += _gev_rows(a, conf) + _overbound_rows(a)
    return rows


def _gev_rows(a: TailAnalysis, conf: str) -> list[list[str]]:
    gev = a.gev
    if gev is None:
        return [["GEV on daily maxima", "n.a.", "not computed"]]
    blocks = f"{gev.block_maxima.size} daily maxima of about {gev.epochs_per_block:,.0f} epochs"
    if gev.fit is None:
        return [["GEV on daily maxima", "no fit", f"{blocks}; {_e(gev.message)}"]]
    f = gev.fit
    return [
        [
            "GEV on daily maxima",
            f"ξ {_h_x(f.xi, 3)}, μ {_h_x(f.loc, 3)}, σ {_h_x(f.scale, 3)}",
            f"{blocks}; P(daily max &gt; 1) {scientific(gev.p_block)}",
        ],
        [
            "GEV P<sub>MI</sub> per epoch",
            scientific(gev.p_mi),
            f"upper bound P<sub>MI95</sub> {scientific(gev.p_mi_95)} ({conf}, {gev.n_boot} resamples)",
        ],
    ]


def _overbound_rows(a: TailAnalysis) -> list[list[str]]:
    k = a.krs
    if k is None:
        krs = ["KRS core test", "n.a.", "not computed (the tail starts below L = 0.5)"]
    else:
        verdict = "overbounded" if k.overbounded else '<span class="alarm">not overbounded</span>'
        krs = [
            "KRS core test",
            f"T<sub>KRS</sub> {_h_x(k.statistic, 3)}",
            f"critical z<sub>α</sub> {_h_x(k.critical, 3)}: {verdict} ({k.n:,} samples)",
        ]
    o = a.tail_overbound
    if o is None:
        tail = ["tail overbounding", "n.a.", "not computed"]
    else:
        verdict = "overbounded" if o.overbounded else '<span class="alarm">not overbounded</span>'
        tail = [
            "tail overbounding probability",
            scientific(o.probability),
            f"{verdict} (needs ≥ {_h_x(1.0 - o.alpha, 3)}; L<sub>Tail</sub> {_h_x(o.l_tail, 3)}, "
            f"{o.n_tail:,} of {o.n:,} samples in the tail)",
        ]
    return [krs, tail]


def _counts_table(a: TailAnalysis) -> str:
    c = a.counts
    rows = [
        ["rows of the table", f"{c.n_rows:,}"],
        ["without a solution", f"{c.n_no_solution:,}"],
        ["alerted (excluded)", f"{c.n_alert:,}"],
        ["PL ≥ AL dropped", f"{c.n_pl_above_al:,}"],
        ["TTA before an alert dropped", f"{c.n_tta:,}"],
        ["used", f"{c.n_used:,}"],
    ]
    return row_table(["epochs", "count"], rows, "evt-epochs")


def _service_rows(a: TailAnalysis) -> list[list[str]]:
    rows = []
    for name, h in a.services.items():
        rows.append(
            [
                _e(name),
                f"{h.alert_limit:g}&nbsp;m",
                f"{h.counts.n_used:,}",
                scientific(h.p_hmi),
                scientific(h.p_hmi_95),
                f"{h.exposure_s:g}&nbsp;s",
                scientific(h.p_hmi_exposure),
                scientific(h.p_hmi_exposure_95),
                scientific(h.integrity_risk),
                badge(h.meets_requirement, name, h.message),
                _e(h.message),
            ]
        )
    return rows


def _services_html(a: TailAnalysis) -> str:
    if not a.services:
        return "<p>No service level with an alert limit on this axis was analysed.</p>"
    # the variable extrapolated to 1 is the analysis's own (each service's TailFit names it)
    names = dict.fromkeys(h.tail.variable for h in a.services.values() if h.tail is not None)
    variable = f"the tail of {' / '.join(names)} extrapolated to 1" if names else "a tail extrapolation"
    head = [
        "service",
        "AL",
        "epochs used",
        "P<sub>HMI</sub> per epoch",
        "P<sub>HMI95</sub>",
        "exposure",
        "P<sub>HMI</sub> per exposure",
        "upper bound per exposure",
        "requirement",
        "verdict",
        "message",
    ]
    return (
        f"<p>HMI probability per service level (Veerman et al., section 3.6): {_e(variable)} on the "
        "epochs with PL &lt; AL, those in the time-to-alert before an alert dropped. The verdict "
        "compares the upper bound per exposure (the upper end of the "
        f"{percent(a.confidence)} interval) with the integrity requirement.</p>"
        + row_table(head, _service_rows(a), "evt-services")
    )


# ---------------------------------------------------------------------------
# messages


def _messages(a: TailAnalysis, t: TailFit) -> list[tuple[bool, str]]:
    """(is an alarm, text) for every statement of the analysis, in a fixed order, each once.

    The statements of the fit (non-regular shape, finite endpoint below 1 so P_MI = 0, every
    threshold rejected by the GOF test, optimiser trouble) are shown as written; alarms are the
    verdicts against the method's assumptions or the requirement.
    """
    out: list[tuple[bool, str]] = [(False, s) for s in _split(a.message)]
    if t.threshold_choice is not None and t.threshold_choice.message:
        out.append(
            (not math.isfinite(t.threshold_choice.threshold), f"threshold: {t.threshold_choice.message}")
        )
    if a.gev is not None and a.gev.message:
        out.append((a.gev.fit is None, f"GEV: {a.gev.message}"))
    if a.krs is not None and not a.krs.overbounded:
        out.append((True, "the KRS test does not accept that the Gaussian of the PL overbounds the core"))
    if a.tail_overbound is not None and not a.tail_overbound.overbounded:
        out.append((True, "the bootstrap tail-overbounding probability is below the confidence level"))
    if a.n_mi:
        out.append((True, f"{a.n_mi:,} epoch(s) with SI > 1 observed"))
    for name, h in a.services.items():
        if h.meets_requirement is None:
            out.append((True, f"{name}: no HMI estimate: {h.message}"))
    seen: dict[str, bool] = {}
    for alarm, text in out:
        seen[text] = seen.get(text, False) or alarm
    return [(alarm, text) for text, alarm in seen.items()]


def _split(message: str) -> list[str]:
    return [s.strip() for s in message.split(";") if s.strip()]


def _messages_html(items: list[tuple[bool, str]]) -> str:
    alarm = ' class="alarm"'
    lis = "".join(f"<li{alarm if warn else ''}>{_e(text)}</li>" for warn, text in items)
    return f'<ul class="evt-messages">{lis}</ul>'


# ---------------------------------------------------------------------------
# figures


def _vk_curve(a: TailAnalysis) -> VKCurve | None:
    """The V_K curve of the analysis: its exceedances are those of the clusters at the dependence level."""
    d, t = a.dependence, a.tail
    if d is None or t is None or d.vk_k_s.size == 0:
        return None
    c = t.clusters
    same = c.threshold == d.level and c.n_clusters > 0
    n = c.n_exceedances if same else 0
    duration = float(c.end.max() - c.start.min()) if same else 0.0
    curve = VKCurve(d.vk_k_s, d.vk_v, n, duration)
    # the Poisson line only when it is the analysis's own (else N and the span are not known)
    if not np.allclose(curve.poisson(), d.vk_poisson, equal_nan=True):
        curve = VKCurve(d.vk_k_s, d.vk_v, n, 0.0)
    return curve


def _p_mi_vs_threshold(t: TailFit) -> Axes:
    """:func:`plot_p_mi_vs_threshold` without the interval (none is kept per candidate) or its legend."""
    nan = np.full(t.candidates.size, np.nan)
    ax = plot_p_mi_vs_threshold(t.candidates, t.p_vs_threshold, nan, nan, chosen=t.threshold)
    with style():
        for art in ax.findobj(lambda x: x.get_gid() == "p-mi-band"):
            art.set_label("_nolegend_")
        ax.legend(loc="upper right")
    return ax


def _model_rate(t: TailFit) -> float:
    """The factor that makes the GPD's conditional tail a probability per epoch equal to P_MI at SI = 1.

    ``P_MI / G(1 - u)`` (the exceedance rate, times the cluster-size factor of a declustered fit
    when there is one), so the model curve of :func:`plot_tail_fit` passes through its P_MI point;
    the exceedance rate :math:`\\zeta_u` when the GPD ends below 1.
    """
    gbar = float(t.gpd.sf(1.0)) if t.gpd is not None else 0.0
    return t.p / gbar if gbar > 0 and math.isfinite(t.p) else t.zeta


def _figures(a: TailAnalysis, series: tuple[np.ndarray, np.ndarray] | None) -> tuple[list[str], list[str]]:
    """The figures (HTML) of the analysis in reading order, and the names of those not drawn and why."""
    sid = f"evt-{a.axis}"
    si = _SI[a.axis]
    t, d = a.tail, a.dependence
    assert t is not None
    drawn: list[str] = []
    skipped: list[str] = []
    chosen = t.threshold

    def add(ok: bool, why: str, name: str, draw, alt: str, caption: str) -> None:
        if ok:
            drawn.append(figure_html(draw(), name=f"{sid}-{name}", alt=alt, caption=caption))
        else:
            skipped.append(f"{name} ({why})")

    add(
        d is not None and d.acf.size > 0,
        "no autocorrelation",
        "acf",
        lambda: plot_acf(d.acf_lags_s, d.acf, decorrelation_s=d.decorrelation_s),
        f"autocorrelation of the safety index {si} against lag, with the 1/e line",
        "Autocorrelation of SI on its regular grid: the lag where it falls below 1/e is the "
        "decorrelation time, the spacing of the independent samples of the overbounding tests.",
    )
    curve = _vk_curve(a)
    add(
        curve is not None,
        "no V_K curve",
        "vk",
        lambda: plot_vk(curve, cluster_gap_s=d.cluster_gap_s),
        "V_K curve: pairs of exceedances at most K apart per exceedance, against the window K",
        "V_K against K (section 3.2): independent exceedances give a straight line; K_T, where the "
        "curve joins its upper straight line, is the gap that separates clusters.",
    )
    add(
        series is not None and t.clusters.n_clusters > 0,
        "the analysed series is not available" if series is None else "no cluster",
        "clusters",
        lambda: plot_clusters(series[0], series[1], t.clusters, threshold=t.cluster_level),
        f"safety index {si} around its exceedances with the maximum of each cluster marked",
        "SI around the exceedances of the clustering level (dashed) with one marker per cluster "
        "maximum: the cluster maxima are the independent values the GPD is fitted to.",
    )
    n_c = t.candidates.size
    add(
        n_c > 0 and t.mean_excess.size == n_c,
        "no threshold diagnostics",
        "mean-excess",
        lambda: plot_mean_excess(t.candidates, t.mean_excess, chosen=chosen),
        "mean-excess plot: mean excess of SI over each candidate threshold, with the chosen threshold",
        "Mean excess against the threshold (figure 2 of the paper): a GPD tail makes it linear; the "
        "threshold is read at the start of the linear part.",
    )
    add(
        t.stability is not None,
        "no threshold diagnostics",
        "shape-stability",
        lambda: plot_shape_stability(t.stability, chosen=chosen),
        "GPD shape estimate against the threshold with its profile-likelihood band",
        "GPD shape against the threshold (figure 3 of the paper): above a good threshold the shape "
        "is stable within its band; below −0.5 (dashed) the fit is non-regular.",
    )
    add(
        n_c > 0 and t.p_vs_threshold.size == n_c,
        "no threshold diagnostics",
        "p-mi-threshold",
        lambda: _p_mi_vs_threshold(t),
        "P_MI per epoch estimated at each candidate threshold, log scale, with the chosen threshold",
        "P_MI estimated at each candidate threshold: a result that moves little around the chosen "
        "threshold does not hang on that choice.",
    )
    g = t.gpd
    add(
        g is not None,
        "no GPD fit",
        "tail-fit",
        lambda: plot_tail_fit(
            g.excesses + g.threshold,
            fit=g,
            n_total=t.n_total,
            exceedance_rate=_model_rate(t),
            p_mi=t.p,
            p_mi_ci=t.p_ci,
        ),
        "exceedance probability of SI per epoch with the fitted GPD extrapolated to SI = 1 and P_MI",
        "P(SI > x) per epoch of the values the GPD was fitted to (dots) and of the model (line) up to "
        "SI = 1, where P_MI is read with its bootstrap interval, against the requirements.",
    )
    k = a.krs
    add(
        k is not None,
        "KRS not computed",
        "krs",
        lambda: plot_krs(k.levels, k.t_values, critical=k.critical),
        "KRS statistic T_N(L) against the normalised error L with the critical value",
        "KRS statistic over the core of the normalised error L = |PE|/(PL/K): overbounding is "
        "accepted when its minimum stays above the critical value (dashed).",
    )
    return drawn, skipped


# ---------------------------------------------------------------------------
# sections and page


def evt_section_html(analysis: TailAnalysis, *, series: tuple[np.ndarray, np.ndarray] | None = None) -> str:
    """An HTML ``<section id="evt-<axis>">`` presenting one :class:`TailAnalysis`.

    Parameters
    ----------
    analysis : the result of :func:`~overbound.methods.tail_extrapolation.tail_analysis`.
    series : the analysed (time s, SI) series (:func:`analysed_series`) for the clusters figure;
        that figure is not drawn without it.

    Notes
    -----
    Contents: a lead paragraph; every statement of the analysis as a list (those of the fit as
    written: non-regular shape, finite endpoint below SI = 1 so P_MI = 0, every threshold rejected
    by the GOF test, the threshold choice, the GEV; in the ``alarm`` class: a failed GEV fit,
    overbounding rejected, MI observed, services without an estimate);
    the headline table (``evt-headline``: P_MI per epoch, its intervals and upper bound, per
    approach, threshold and how it was chosen, K_T, clusters, exceedances, extremal index, GPD,
    GEV, KRS, tail overbounding); the epoch counts (``evt-epochs``); the per-service HMI table
    (``evt-services``, verdict badges ``meets`` / ``does not meet`` / ``no estimate``); the
    figures, each an inline PNG with alt text and a caption, those without data listed as not
    drawn. The fragment loads nothing.
    """
    a = analysis
    t = a.tail
    sid = f"evt-{a.axis}"
    title = f"{_AXIS.get(a.axis, a.axis)} EVT tail extrapolation"
    if t is None:
        return evt_failure_html(a.axis, a.message or "no tail fit")
    filt = f"; HMI filtering by {_e(a.service)}" if a.service else ""
    lead = (
        f"<p>Probability of misleading information per epoch, P<sub>MI</sub> = P(SI &gt; 1) with SI = "
        f"{_e(_SI[a.axis])}, extrapolated from the tail of SI by a generalised Pareto distribution "
        f"(Veerman et al., GIMAT, sections 3.2–3.7): P<sub>MI</sub> = {scientific(t.p)}, "
        f"{percent(a.confidence)} interval {_h_ci(t.p_ci)}, upper bound P<sub>MI95</sub> = "
        f"{scientific(t.p_95)}; per {APPROACH_S:g}&nbsp;s approach {scientific(t.p_approach)}, upper bound "
        f"{scientific(t.p_approach_95)}. {a.counts.n_used:,} epochs analysed{filt}; "
        f"{a.n_boot:,} bootstrap resamples, seed {a.seed if a.seed is not None else 'none'}.</p>"
    )
    drawn, skipped = _figures(a, series)
    parts = [
        lead,
        _messages_html(_messages(a, t)),
        row_table(["quantity", "value", "how"], _headline_rows(a, t), "evt-headline"),
        "<h3>Epochs</h3>",
        _counts_table(a),
        "<h3>HMI per service level</h3>",
        _services_html(a),
        "<h3>Figures</h3>",
        '<div class="figrow">' + "".join(drawn) + "</div>",
    ]
    return section_html(sid, title, parts, skipped)


def evt_failure_html(axis: str, message: str) -> str:
    """The ``<section id="evt-<axis>">`` of an axis whose EVT analysis could not run: no estimate, and why."""
    title = f"{_AXIS.get(axis, axis)} EVT tail extrapolation"
    return section_html(
        f"evt-{axis}",
        title,
        [
            f'<p class="alarm">No estimate of P<sub>MI</sub>: {_e(message)}</p>',
            "<p>The tail extrapolation needs enough independent values (cluster maxima) in the tail of the "
            "safety index to choose a threshold and fit it; a longer campaign or a higher sampling rate "
            "gives more.</p>",
        ],
    )


def write_evt_report(
    analyses: TailAnalysis | Sequence[TailAnalysis],
    directory: str | Path,
    *,
    title: str = "EVT tail extrapolation",
    table: pl.DataFrame | None = None,
) -> Path:
    """Write a standalone, self-contained ``evt.html`` into ``directory``; return its path.

    One :func:`evt_section_html` per analysis, inline CSS, no external resource, no timestamp: the
    same analyses give the same bytes. With ``table`` (the analysed epoch table) the clusters
    figure is drawn from :func:`analysed_series`.
    """
    items = [analyses] if isinstance(analyses, TailAnalysis) else list(analyses)
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    body = "\n".join(
        evt_section_html(a, series=None if table is None else analysed_series(table, a)) for a in items
    )
    return write_page(
        directory / REPORT_NAME,
        title=title,
        intro_html=(
            "Method of Veerman et al., “A tool for GNSS integrity verification "
            "based on statistical extreme value theory” (GIMAT): dependence and declustering, threshold "
            "choice, generalised Pareto tail extrapolated to SI = 1 with bootstrap and profile-likelihood "
            "intervals, GEV on daily maxima, KRS and tail overbounding, and the HMI probability per "
            "service level."
        ),
        body_html=body,
    )


# ---------------------------------------------------------------------------
# one call for the CLI


@dataclass(frozen=True, slots=True)
class EvtRun:
    """What :func:`run_evt` computed and wrote.

    Attributes
    ----------
    analysis : the :class:`TailAnalysis`.
    json_path : the ``evt.json`` written.
    report : the ``evt.html`` written.
    """

    analysis: TailAnalysis
    json_path: Path
    report: Path


def run_evt(
    table: pl.DataFrame,
    directory: str | Path,
    *,
    axis: str = "vertical",
    service: str | None = None,
    threshold: float | str = "auto",
    cluster_gap: float | str = "auto",
    decluster: bool = True,
    n_boot: int = 1000,
    confidence: float = 0.95,
    seed: int | None = 0,
    services: tuple[str, ...] | None = None,
    n_sim: int = 200,
    gev_boot: int = 100,
    diagnostics: bool = True,
    title: str = "EVT tail extrapolation",
) -> EvtRun:
    """Analyse ``table`` and write ``evt.json`` and ``evt.html`` into ``directory`` (created if needed).

    The parameters are those of :func:`~overbound.methods.tail_extrapolation.tail_analysis`
    (``seed`` is its ``rng``).

    Raises
    ------
    ValueError
        From :func:`~overbound.methods.tail_extrapolation.tail_analysis` (bad options, too few
        tail values); nothing is written then.
    """
    analysis = tail_analysis(
        table,
        axis=axis,
        service=service,
        threshold=threshold,
        cluster_gap=cluster_gap,
        decluster=decluster,
        n_boot=n_boot,
        confidence=confidence,
        rng=seed,
        services=services,
        n_sim=n_sim,
        gev_boot=gev_boot,
        diagnostics=diagnostics,
    )
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    json_path = directory / JSON_NAME
    write_evt(analysis, json_path)
    report = write_evt_report(analysis, directory, title=title, table=table)
    return EvtRun(analysis, json_path, report)
