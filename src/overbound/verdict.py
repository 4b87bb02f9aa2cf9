r"""One defensible verdict per service level: the rules that reconcile the counts and the models.

For each service level, pooled and per station, five verdicts — availability, continuity,
accuracy, integrity (HMI), PL bounding (MI) — and an overall one. Each is ``pass``, ``fail`` or
``not demonstrated`` and carries the requirement, the evidence it rests on and one sentence.
Pure functions from the analysis results (:class:`overbound.analysis.Analysis`) to
:class:`Verdict` objects; nothing here reads a file or draws.

The rules, each with its reason
-------------------------------
R1. **Counted evidence first** (availability, continuity, accuracy). The verdict rests on the
    counts with one-sided exact bounds at 95 % (:mod:`overbound.methods.evidence`: effective sample
    size for availability and accuracy, loss events as the trials for continuity): ``pass`` when the
    bound on the safe side meets the requirement, ``fail`` when the bound on the other side misses
    it, ``not demonstrated`` in between. Fits (Kannemans' Weibull, the non-continuity fit) are
    listed as supporting estimates and never vote: a fit is a model of the count, not more evidence.
R2. **An observed HMI is an integrity fail.** No model can outvote an event that happened.
R3. **Counted MI/HMI bound the per-exposure risk from below.** MI events (PE > PL while PL < AL)
    are counted as clusters (runs 360 s apart) per second of available time; the Poisson lower
    bound of that rate times the exposure (150 s; 3600 s for NPA) bounds the per-exposure
    probability from below (each cluster starts within some exposure window). A lower bound above
    the requirement is a ``fail``.
R4. **Tail models vote only when the data do not reject them.** Each model (EVT, parametric)
    predicts how many clusters exceed the safety-index levels 0.3, 0.5, 0.7 and the observed
    maximum; the observed cluster counts are compared with a one-sided Poisson test (the model
    is rejected when it predicts significantly *fewer* exceedances than observed, Bonferroni over
    the levels, family-wise 5 %). Epochs are turned into clusters by the observed mean cluster
    size at each level (the parametric ratio models predict epochs). A model that predicts more
    than observed errs on the safe side and keeps its vote. A rejected model is shown, with its test.
R5. **The EVT shape is floored at 0.** The GPD fitted to a finite campaign often has a negative
    shape, i.e. a finite endpoint below SI = 1 and "P_MI = 0". Position errors have no finite
    upper bound and the Gaussian, the model every PL is built on, lies in the Gumbel domain
    (shape 0; Coles 2001, section 4.2); a negative estimate is a pre-asymptotic effect of the finite
    sample. Where :math:`\hat\xi \le 0` the verdict uses the exponential tail (shape 0) fitted to the
    same cluster maxima: scale = their mean excess, bounded with the exact gamma interval
    (:math:`2\sum y_i/\sigma \sim \chi^2_{2n}`) and the cluster count with the Poisson bounds,
    Bonferroni-combined, so that a verdict never rests on a finite endpoint.
R6. **Per exposure.** Each method's per-epoch figure becomes a per-exposure one by its own stated
    rule: EVT by :func:`overbound.methods.tail_extrapolation.per_approach` (independent Poisson
    clusters, the premise of declustering); the parametric method by the union bound
    :math:`n\,p` (:math:`n` epochs per exposure: valid under any dependence); counts by the cluster
    rate (R3). Both axes share the one integrity risk: the per-axis bounds are added (union bound).
R7. **Pass only when every admissible model passes.** The integrity / PL-bounding verdict is
    ``pass`` when, on every axis, at least one model is admissible and the largest upper bound of
    the admissible models, summed over the axes, meets the requirement, and no evidence votes
    ``fail``. ``fail`` when counted evidence fails (R2, R3), or an admissible model's lower bound
    misses the requirement while none passes. Where admissible evidence points both ways the methods
    disagree beyond their intervals: ``not demonstrated``, and the sentence names them.
R8. **PL confidence level (Comby et al. 2003).** Each rated PL band below the alert limit is
    re-evaluated at the service's per-exposure risk (per independent sample; an approach holds at
    least one epoch, so a per-sample risk above the requirement is a per-approach one): a band whose
    confidence level is below 5 % votes ``fail`` for PL bounding; otherwise the bands support.
    The band model is not a tail model of the whole campaign, so it never votes ``pass``.
R9. **PL bounding demonstrates integrity**: HMI (PE >= AL while PL < AL) implies MI, so a PL-bounding
    ``pass`` is an integrity ``pass``; integrity may also pass on HMI-specific models (parametric
    P_HMI) under R4 and R7.
R10. **Overall** is ``fail`` if any verdict fails, ``pass`` if all pass, else ``not demonstrated``.
    A KPI the service sets no requirement for (accuracy of a user-defined level) passes with that said.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Literal

import numpy as np
from scipy import special

from overbound.methods.evidence import CountedEvents, Evidence, StationEvidence, TailCounts
from overbound.numbers import format_percent, format_probability, log10_or_none
from overbound.services import ServiceLevel
from overbound.stats.proportion import poisson_bounds

if TYPE_CHECKING:
    from overbound.analysis import Analysis
    from overbound.methods.confidence_level import ConfidenceAnalysis
    from overbound.methods.parametric import ParametricAnalysis
    from overbound.methods.tail_extrapolation import TailAnalysis, TailFit

__all__ = [
    "FAIL",
    "KINDS",
    "NOT_DEMONSTRATED",
    "PASS",
    "Adequacy",
    "Assessment",
    "EvidenceItem",
    "ServiceVerdicts",
    "Verdict",
    "accuracy_verdict",
    "assess",
    "availability_verdict",
    "continuity_verdict",
    "overall_verdict",
    "tail_adequacy",
]

PASS, FAIL, NOT_DEMONSTRATED = "pass", "fail", "not demonstrated"
Outcome = Literal["pass", "fail", "not demonstrated"]
KINDS = ("availability", "continuity", "accuracy", "integrity", "pl_bounding")
#: Family-wise level of the adequacy test (R4).
ADEQUACY_ALPHA = 0.05
#: Confidence level below which a PL band votes fail (R8).
BAND_FAIL_BELOW = 0.05
_AXES = ("horizontal", "vertical")


@dataclass(frozen=True, slots=True)
class AdequacyCheck:
    """One level of the adequacy test: observed and predicted clusters above ``level``."""

    level: float
    observed: int
    predicted: float
    p_value: float


@dataclass(frozen=True, slots=True)
class Adequacy:
    """The adequacy test of a tail model (R4): rejected when any check's p-value is below
    ``alpha / len(checks)``."""

    rejected: bool
    alpha: float
    checks: tuple[AdequacyCheck, ...]
    note: str = ""


@dataclass(frozen=True, slots=True)
class EvidenceItem:
    """One piece of evidence under a verdict.

    ``vote`` is what it says on its own (``pass``, ``fail``, ``none`` for supporting figures and
    rejected models); ``estimate``/``lower``/``upper`` the figure and its bounds in the unit of
    ``quantity`` (``log10_*`` keep probabilities below the float range); ``assumption`` the
    dependence or model assumption it rests on.
    """

    method: str
    quantity: str
    estimate: float | None
    lower: float | None
    upper: float | None
    vote: str
    assumption: str = ""
    note: str = ""
    axis: str | None = None
    adequacy: Adequacy | None = None
    log10_estimate: float | None = None
    log10_upper: float | None = None


@dataclass(frozen=True, slots=True)
class Verdict:
    """One verdict: ``verdict`` against ``requirement``, the ``basis`` in a few words, one
    quotable ``sentence`` and the ``evidence`` under it."""

    kind: str
    verdict: Outcome
    requirement: str
    basis: str
    sentence: str
    evidence: tuple[EvidenceItem, ...] = ()


@dataclass(frozen=True, slots=True)
class ServiceVerdicts:
    """The five verdicts of one service and the overall one."""

    service: str
    availability: Verdict
    continuity: Verdict
    accuracy: Verdict
    integrity: Verdict
    pl_bounding: Verdict
    overall: Verdict

    def get(self, kind: str) -> Verdict:
        return getattr(self, kind)


@dataclass(frozen=True, slots=True)
class Assessment:
    """The verdicts of every service, pooled (``services``) and per station (``by_station``, only
    with several stations)."""

    services: dict[str, ServiceVerdicts]
    by_station: dict[str, dict[str, ServiceVerdicts]] = field(default_factory=dict)


# --------------------------------------------------------------------------------------------------
# R1: counted KPIs


def _decide(lower_ok: bool, upper_fails: bool) -> Outcome:
    return PASS if lower_ok else FAIL if upper_fails else NOT_DEMONSTRATED


def availability_verdict(ev, s: ServiceLevel, supporting: Sequence[EvidenceItem] = ()) -> Verdict:
    """R1 on the counted availability (both axes) against ``s.availability``."""
    req = f"availability >= {format_percent(s.availability, 1)} (lower end of the ICAO range)"
    a = ev.availability
    if a.n == 0:
        return Verdict("availability", NOT_DEMONSTRATED, req, "no epochs", "There are no epochs to count.")
    b = a.bounds
    dep = (
        f"one independent sample per {a.tau_s:g} s assumed (availability never changed)"
        if a.assumed
        else f"effective sample size from the integrated autocorrelation time {a.tau_s:.4g} s"
    )
    item = EvidenceItem(
        "counted",
        "availability (both axes)",
        b.estimate,
        b.lower,
        b.upper,
        "pass" if b.lower >= s.availability else "fail" if b.upper < s.availability else "none",
        f"Clopper-Pearson with {a.n_effective:.4g} effective samples of {a.n} epochs; {dep}",
    )
    v = _decide(b.lower >= s.availability, b.upper < s.availability)
    span = f"{format_percent(b.estimate)} ({format_percent(b.lower)} to {format_percent(b.upper)} at 95 %)"
    sentence = {
        PASS: f"Counted availability {span} meets the {format_percent(s.availability, 0)} requirement.",
        FAIL: f"Counted availability {span} is below the {format_percent(s.availability, 0)} requirement.",
        NOT_DEMONSTRATED: f"Counted availability {span} cannot be told apart from the "
        f"{format_percent(s.availability, 0)} requirement with {a.n_effective:.3g} effective samples.",
    }[v]
    return Verdict("availability", v, req, "counted, effective sample size", sentence, (item, *supporting))


def continuity_verdict(ev, s: ServiceLevel, supporting: Sequence[EvidenceItem] = ()) -> Verdict:
    """R1 on the counted continuity risk per window against ``s.continuity_risk``."""
    req = f"continuity risk <= {s.continuity_risk:g} per {s.continuity_window_s:g} s"
    c = ev.continuity
    if c.bounds is None:
        return Verdict(
            "continuity",
            NOT_DEMONSTRATED,
            req,
            "not countable",
            f"Continuity cannot be counted: {c.reason}.",
            tuple(supporting),
        )
    b = c.bounds
    item = EvidenceItem(
        "counted",
        f"loss of continuity per {c.window_s:g} s window",
        b.estimate,
        b.lower,
        b.upper,
        "pass" if b.upper <= s.continuity_risk else "fail" if b.lower > s.continuity_risk else "none",
        f"loss events as the trials: {c.n_events} events, {c.windows_per_event:.3g} failing windows per "
        f"event, {c.n_fail} of {c.n_windows} windows failed (Clopper-Pearson)",
    )
    v = _decide(b.upper <= s.continuity_risk, b.lower > s.continuity_risk)
    span = (
        f"{format_probability(b.estimate)} per {c.window_s:g} s ({c.n_events} loss events; 95 % bounds "
        f"{format_probability(b.lower)} to {format_probability(b.upper)})"
    )
    sentence = {
        PASS: f"Counted continuity risk {span} meets {s.continuity_risk:g}.",
        FAIL: f"Counted continuity risk {span} exceeds {s.continuity_risk:g}.",
        NOT_DEMONSTRATED: f"Counted continuity risk {span}: the campaign is too short to show "
        f"{s.continuity_risk:g} either way.",
    }[v]
    return Verdict("continuity", v, req, "counted, loss events as trials", sentence, (item, *supporting))


def accuracy_verdict(ev: StationEvidence, s: ServiceLevel) -> Verdict:
    """R1 on the 95th percentiles of HPE and |VPE| against the service's accuracy requirements."""
    reqs = {"horizontal": s.accuracy_h95, "vertical": s.accuracy_v95 if s.val is not None else None}
    reqs = {a: r for a, r in reqs.items() if r is not None}
    if not reqs:
        return Verdict(
            "accuracy", PASS, "none", "no requirement", f"No accuracy requirement is set for {s.name}."
        )
    req = ", ".join(f"{'HPE' if a == 'horizontal' else '|VPE|'}95 <= {r:g} m" for a, r in reqs.items())
    items, outcomes = [], []
    for a, r in reqs.items():
        q = ev.accuracy[a]
        if q.estimate is None:
            outcomes.append(NOT_DEMONSTRATED)
            continue
        o = _decide(q.upper <= r, q.lower > r)
        outcomes.append(o)
        items.append(
            EvidenceItem(
                "counted",
                f"{'HPE' if a == 'horizontal' else '|VPE|'} 95th percentile (m)",
                q.estimate,
                q.lower,
                q.upper,
                {PASS: "pass", FAIL: "fail"}.get(o, "none"),
                f"order-statistic bounds with {q.n_effective:.4g} effective samples of {q.n}",
                axis=a,
            )
        )
    v = FAIL if FAIL in outcomes else PASS if all(o == PASS for o in outcomes) else NOT_DEMONSTRATED
    figures = "; ".join(
        f"{'HPE' if i.axis == 'horizontal' else '|VPE|'}95 {i.estimate:.3g} m "
        f"({i.lower:.3g} to {i.upper:.3g})"
        for i in items
    )
    word = {PASS: "meets", FAIL: "misses", NOT_DEMONSTRATED: "is not shown to meet"}[v]
    return Verdict("accuracy", v, req, "counted 95th percentiles", f"{figures} {word} {req}.", tuple(items))


# --------------------------------------------------------------------------------------------------
# R4: adequacy


def tail_adequacy(
    counts: TailCounts,
    *,
    epochs_above=None,
    clusters_above=None,
    lowest_level: float = 0.0,
    alpha: float = ADEQUACY_ALPHA,
) -> Adequacy:
    """The adequacy test of R4 for one model against ``counts``.

    The model gives either ``epochs_above(s)`` (expected epochs with SI > s in the campaign: turned
    into clusters by the observed mean cluster size at that level) or ``clusters_above(s)``
    (expected clusters), for ``s >= lowest_level``. Levels: :data:`overbound.methods.evidence.SI_LEVELS`
    and the observed maximum (one cluster at or above it). The p-value of a level is
    :math:`P(\\mathrm{Poisson}(\\lambda) \\ge k_{obs})`; the model is rejected when one is below
    ``alpha`` divided by the number of levels.
    """
    levels: list[tuple[float, int, float]] = []  # (level, observed clusters, mean cluster size)
    for i, s in enumerate(counts.levels):
        if s >= lowest_level and (counts.max_si is None or s < counts.max_si):
            levels.append((s, counts.clusters_above[i], counts.mean_cluster_size(i)))
    if counts.max_si is not None and counts.max_si >= lowest_level and counts.max_si > 0:
        levels.append((counts.max_si, 1, 1.0))
    checks = []
    for s, k, size in levels:
        if clusters_above is not None:
            lam = float(clusters_above(s))
        else:
            lam = float(epochs_above(s)) / size
        p = 1.0 if k <= 0 else float(special.gammainc(k, lam)) if lam > 0 else 0.0
        checks.append(AdequacyCheck(float(s), int(k), lam, p))
    if not checks:
        return Adequacy(False, alpha, (), "no level to check")
    cut = alpha / len(checks)
    return Adequacy(any(c.p_value < cut for c in checks), alpha, tuple(checks))


def _adequacy_note(a: Adequacy) -> str:
    worst = min(a.checks, key=lambda c: c.p_value)
    return (
        f"predicts {worst.predicted:.3g} clusters above SI {worst.level:.3g} where {worst.observed} "
        f"were observed (p = {format_probability(worst.p_value)}, below {a.alpha:g}/{len(a.checks)})"
    )


# --------------------------------------------------------------------------------------------------
# models of the tail, per exposure


def _evt_item(
    tail: TailFit, axis: str, exposure_n: float, counts: TailCounts, quantity: str
) -> EvidenceItem | None:
    """R5/R6: the EVT per-exposure estimate and bounds, shape floored at 0, with its adequacy."""
    from overbound.methods.tail_extrapolation import per_approach

    gpd = tail.gpd
    if gpd is None:
        return None
    u = float(gpd.threshold)
    peaks = tail.clusters.peak_value
    y = peaks[peaks > u] - u
    n_c = int(y.size)
    if n_c < 2:
        return None
    size = tail.cluster_size.mean if tail.cluster_size is not None else 1.0
    size = size if math.isfinite(size) and size >= 1 else 1.0
    n = float(tail.n_total)
    floored = not gpd.xi > 0
    if floored:
        scale = float(y.mean())
        ch = poisson_bounds(n_c, 0.975)
        s_lo = 2 * y.sum() / (2 * special.gammaincinv(n_c, 0.975))
        s_hi = 2 * y.sum() / (2 * special.gammaincinv(n_c, 0.025))
        log_r = [math.log(k / n) - (1 - u) / s for k, s in ((ch.lower, s_lo), (n_c, scale), (ch.upper, s_hi))]
        rates = [math.exp(x) for x in log_r]
        ps = [r * size for r in rates]
        shape_note = (
            f"GPD shape {gpd.xi:.3g} <= 0 floored at 0 (R5): exponential tail of the {n_c} cluster maxima "
            f"above u = {u:.3g}, scale {scale:.3g} ({s_lo:.3g} to {s_hi:.3g})"
        )

        def clusters_above(s: float) -> float:
            return n_c * math.exp(-(s - u) / scale) * counts.n_epochs / n

        log10_p = (log_r[1] + math.log(size)) / math.log(10)
        log10_hi = (log_r[2] + math.log(size)) / math.log(10)
    else:
        lo, hi = tail.p_ci
        ps = [lo, tail.p, hi]
        rates = [p / size for p in ps]
        xi, sc = float(gpd.xi), float(gpd.sigma)
        shape_note = f"GPD shape {xi:.3g} > 0, scale {sc:.3g}, threshold {u:.3g}, {n_c} cluster maxima"

        def clusters_above(s: float) -> float:
            return n_c * (1 + xi * (s - u) / sc) ** (-1 / xi) * counts.n_epochs / n

        log10_p, log10_hi = log10_or_none(tail.p), log10_or_none(hi)
    pa = [float(per_approach(p, r, exposure_n)) for p, r in zip(ps, rates, strict=True)]
    ad = tail_adequacy(counts, clusters_above=clusters_above, lowest_level=u)
    n_log = math.log10(exposure_n) if exposure_n > 1 else 0.0
    return EvidenceItem(
        "EVT (Veerman et al.)",
        quantity,
        pa[1],
        pa[0],
        pa[2],
        "none",
        f"{shape_note}; mean cluster size near SI = 1: {size:.3g}; per exposure of {exposure_n:g} epochs "
        "with independent Poisson clusters (per_approach)",
        axis=axis,
        adequacy=ad,
        log10_estimate=None if log10_p is None else log10_p + n_log,
        log10_upper=None if log10_hi is None else log10_hi + n_log,
    )


def _ratio_epochs_above(fit, n_epochs: int):
    """Expected epochs with SI > s under the parametric ratio model (normal two-sided or Rayleigh)."""
    from overbound.stats.parametric import log_ratio_exceedance

    def f(s: float) -> float:
        if fit.distribution == "normal":
            lg = np.logaddexp(
                special.log_ndtr((fit.mean - s) / fit.sigma), special.log_ndtr((-s - fit.mean) / fit.sigma)
            )
            return n_epochs * float(np.exp(lg))
        return n_epochs * float(np.exp(log_ratio_exceedance(fit, s)))

    return f


def _parametric_item(
    par_axis, axis: str, exposure_n: float, counts: TailCounts, quantity: str, p, log10_p, pb, log10_pb
) -> EvidenceItem:
    """R6: the parametric per-exposure figure by the union bound, with the ratio model's adequacy."""
    ad = tail_adequacy(counts, epochs_above=_ratio_epochs_above(par_axis.ratio_fit, counts.n_epochs))
    lg, lgb = log10_or_none(p, log10_p), log10_or_none(pb, log10_pb)
    n_log = math.log10(exposure_n)
    up = None if pb is None else min(1.0, exposure_n * pb)
    return EvidenceItem(
        "parametric (Kannemans 2006)",
        quantity,
        min(1.0, exposure_n * p) if p is not None and math.isfinite(p) else None,
        None,
        up,
        "none",
        f"{par_axis.ratio_fit.distribution} ratio model (sigma {par_axis.ratio_fit.sigma:.3g}), "
        f"{par_axis.n_effective:.4g} effective samples; per exposure by the union bound n p, "
        f"n = {exposure_n:g}",
        axis=axis,
        adequacy=ad,
        log10_estimate=None if lg is None else lg + n_log,
        log10_upper=None if lgb is None else lgb + n_log,
    )


# --------------------------------------------------------------------------------------------------
# integrity and PL bounding


def _counted_item(ev: CountedEvents, axis: str, what: str, exposure_s: float) -> EvidenceItem:
    """R3: the per-exposure probability from the counted clusters (Poisson, per second available)."""
    if ev.exposure_s <= 0:
        return EvidenceItem(
            "counted", f"{what} per exposure", None, None, None, "none", "no available time", axis=axis
        )
    b = poisson_bounds(ev.clusters)
    f = exposure_s / ev.exposure_s
    return EvidenceItem(
        "counted",
        f"{what} per exposure",
        min(1.0, ev.clusters * f),
        min(1.0, b.lower * f),
        min(1.0, b.upper * f),
        "none",
        f"{ev.epochs} {what} epochs in {ev.clusters} clusters (runs {ev.gap_s:g} s apart) over "
        f"{ev.exposure_s / 3600:.4g} h of available time; clusters as independent Poisson events",
        axis=axis,
    )


def _rated(cl: ConfidenceAnalysis, al: float) -> list:
    """The rated bands (enough samples, a model) entirely below ``al``, with their samples."""
    return [
        (b, smp)
        for b, smp in zip(cl.bins, cl.samples, strict=True)
        if b.sufficient and b.hi <= al and math.isfinite(b.sigma_inflated)
    ]


def band_confidence(pl, mean: float, sigma: float, n: int, risk: float, axis: str) -> float:
    """R8's confidence level of a band's samples at ``risk`` (NaN where it cannot be computed)."""
    from overbound.stats.confidence import confidence_level

    try:
        return float(confidence_level(pl, mean=mean, sigma=sigma, n=n, risk=risk, axis=axis))
    except ValueError:
        return math.nan


def band_confidence_inputs(confidence, services) -> dict[tuple, tuple]:
    """Every evaluation of R8 the verdicts of ``services`` make, keyed as the verdicts' cache (axis,
    band target, width, risk): the arguments of :func:`band_confidence`. A campaign computes them
    on its workers and hands the values to :func:`assess` (:attr:`Analysis.band_confidences`)."""
    out: dict[tuple, tuple] = {}
    for cl in confidence:
        for s in services:
            al = s.alert_limit(cl.axis)
            for b, smp in _rated(cl, al) if al is not None else ():
                if _own(cl, b, s.integrity_risk) is None:
                    key = (cl.axis, b.target, b.tolerance_used, s.integrity_risk)
                    out.setdefault(key, (smp.pl, b.mean, b.sigma_inflated, b.n, s.integrity_risk, cl.axis))
    return out


def _own(cl: ConfidenceAnalysis, b, risk: float) -> float | None:
    """R8 at the analysis' own risk per sample is the band's confidence level, already computed with
    the same arguments (:func:`~overbound.methods.confidence_level.solve_band`); ``None`` at another
    risk."""
    return b.confidence if risk == cl.risk and math.isfinite(b.confidence) else None


def _band_items(cl: ConfidenceAnalysis, al: float, risk: float, cache: dict) -> list[EvidenceItem]:
    """R8: the rated PL bands below ``al`` re-evaluated at ``risk``; one item per failing band, or
    one supporting item."""
    rated = _rated(cl, al)
    if not rated:
        return []
    out, worst = [], None
    for b, smp in rated:
        key = (cl.axis, b.target, b.tolerance_used, risk)
        if key not in cache:
            own = _own(cl, b, risk)
            cache[key] = (
                own
                if own is not None
                else band_confidence(smp.pl, b.mean, b.sigma_inflated, b.n, risk, cl.axis)
            )
        c = cache[key]
        if math.isfinite(c) and (worst is None or c < worst[1]):
            worst = (b, c)
        if c < BAND_FAIL_BELOW:
            out.append(
                EvidenceItem(
                    "PL confidence level (Comby et al. 2003)",
                    f"confidence that the band {b.lo:g}-{b.hi:g} m meets {risk:g} per sample",
                    c,
                    None,
                    None,
                    "fail",
                    f"{b.n} samples 360 s apart, Gaussian G(m, Sigma) with the inflated sigma "
                    f"{b.sigma_inflated:.3g} m",
                    f"band {b.lo:g}-{b.hi:g} m: confidence {format_probability(c)} < {BAND_FAIL_BELOW:g}",
                    axis=cl.axis,
                )
            )
    if not out and worst is not None:
        b, c = worst
        out.append(
            EvidenceItem(
                "PL confidence level (Comby et al. 2003)",
                f"lowest confidence of {len(rated)} rated bands below {al:g} m at {risk:g} per sample",
                c,
                None,
                None,
                "none",
                "Gaussian band model; supports, never votes pass (R8)",
                f"worst band {b.lo:g}-{b.hi:g} m",
                axis=cl.axis,
            )
        )
    return out


@dataclass(frozen=True, slots=True)
class _Context:
    """What the integrity rules read from the analysis, for one station or the pool."""

    evidence: StationEvidence
    evt: dict[str, TailAnalysis]
    parametric: ParametricAnalysis | None
    confidence: dict[str, ConfidenceAnalysis]
    interval_s: float
    cl_cache: dict
    #: ``(method, axis) -> reason`` of the methods that could not run (``Analysis.method_failures``)
    failed: dict = field(default_factory=dict)


def _tail_models(ctx: _Context, s: ServiceLevel, axis: str, hmi: bool) -> list[EvidenceItem]:
    """The EVT and parametric items of one axis, for MI with PL < AL (``hmi`` False) or HMI."""
    n_exp = max(1.0, s.integrity_exposure_s / ctx.interval_s)
    counts = ctx.evidence.tails[axis]
    items: list[EvidenceItem] = []
    e = ctx.evt.get(axis)
    if e is not None:
        h = e.services.get(s.name)
        own = h is not None and h.tail is not None
        tail = h.tail if own else e.tail
        which = "SI on epochs with PL < AL" if own else "SI on all epochs, an upper bound"
        if tail is not None:
            it = _evt_item(tail, axis, n_exp, counts, f"P(MI, PL < AL) per exposure ({which})")
            if it is not None and hmi:
                # HMI implies MI: the MI tail bounds P(HMI) from above only, so it never votes fail here
                it = replace(it, lower=None, note="an upper bound of P(HMI): HMI implies MI")
            if it is not None:
                items.append(it)
    par = ctx.parametric.axis(axis) if ctx.parametric is not None else None
    sp = par.services.get(s.name) if par is not None else None
    if sp is not None:
        if hmi:
            args = (sp.p_hmi, sp.log10_p_hmi, sp.p_hmi_bound, sp.log10_p_hmi_bound)
            q = "P_HMI per exposure"
        else:
            args = (
                sp.p_mi_pl_below_al,
                sp.log10_p_mi_pl_below_al,
                sp.p_mi_pl_below_al_bound,
                sp.log10_p_mi_pl_below_al_bound,
            )
            q = "P(MI, PL < AL) per exposure"
        items.append(_parametric_item(par, axis, n_exp, counts, q, *args))
    return items


def _not_computed(method: str, axis: str | None, reason: str) -> EvidenceItem:
    """The item of a method that could not run on this input: no figure, and why."""
    return EvidenceItem(method, "not computed", None, None, None, "none", note=reason, axis=axis)


def _model_vote(it: EvidenceItem, share: float) -> EvidenceItem:
    """The item with its vote: ``none`` when rejected (R4) or without an upper bound."""
    if it.adequacy is not None and it.adequacy.rejected:
        return replace(it, vote="none", note="rejected by the data: " + _adequacy_note(it.adequacy))
    if it.upper is None:
        return replace(it, vote="none", note="no upper bound")
    vote = "pass" if it.upper <= share else "fail" if (it.lower is not None and it.lower > share) else "none"
    zero = " (upper bound 0: no tail value reaches SI = 1)" if it.upper == 0 else ""
    return replace(it, vote=vote, note=it.note + zero)


def _tail_verdict(kind: str, ctx: _Context, s: ServiceLevel) -> Verdict:
    """R2, R3, R4, R6, R7, R8 for ``pl_bounding`` or ``integrity``."""
    hmi = kind == "integrity"
    req_p = s.integrity_risk
    req = f"P({'HMI' if hmi else 'MI while PL < AL'}) <= {req_p:g} per {s.integrity_exposure_s:g} s"
    axes = [a for a in _AXES if s.alert_limit(a) is not None]
    what = "HMI" if hmi else "MI"
    sv = ctx.evidence.services[s.name]
    observed = sv.hmi if hmi else sv.mi
    events = sum(observed[a].epochs for a in axes)
    items: list[EvidenceItem] = []
    fails: list[str] = []
    for a in axes:
        it = _counted_item(observed[a], a, what, s.integrity_exposure_s)
        # R2: any observed HMI fails; R3: observed MI fail when their lower bound misses the risk
        over = (hmi and observed[a].epochs > 0) or (it.lower is not None and it.lower > req_p)
        items.append(replace(it, vote="fail" if over else "none"))
        if over:
            fails.append(f"{a} {what} observed ({observed[a].epochs} {what} epochs)")
    not_run = []  # checks that were asked for but could not run: a pass cannot rest on their absence
    if not hmi:
        for a in axes:
            cl = ctx.confidence.get(a)
            if cl is not None:
                for it in _band_items(cl, s.alert_limit(a), req_p, ctx.cl_cache):
                    items.append(it)
                    if it.vote == "fail":
                        fails.append(f"PL {it.note}")
            elif ("confidence", a) in ctx.failed:
                items.append(_not_computed("PL confidence level", a, ctx.failed["confidence", a]))
                not_run.append(f"the PL confidence level of the {a} axis could not be computed")
    if ("parametric", "both") in ctx.failed:
        items.append(_not_computed("parametric", None, ctx.failed["parametric", "both"]))
    uppers, rejected, missing, model_fails = {}, [], [], []
    for a in axes:
        admissible = []
        for it in _tail_models(ctx, s, a, hmi):
            it = _model_vote(it, req_p)
            items.append(it)
            if it.adequacy is not None and it.adequacy.rejected:
                rejected.append(f"{it.method} ({a})")
            elif it.upper is not None:
                admissible.append(it)
                if it.vote == "fail":
                    model_fails.append(f"{it.method} ({a}) lower bound {format_probability(it.lower)}")
        if admissible:
            uppers[a] = max(admissible, key=lambda i: i.upper)
        else:
            missing.append(a)
    total = sum(i.upper for i in uppers.values()) if uppers and not missing else None
    models_pass = total is not None and total <= req_p
    if fails:
        v, basis = FAIL, "counted" if any("observed" in f for f in fails) else "PL confidence level"
        shown = fails[:3] + ([f"{len(fails) - 3} more"] if len(fails) > 3 else [])
        sentence = f"{'; '.join(shown)}: the requirement {req} is not met."
    elif model_fails and not models_pass:
        v, basis = FAIL, "admissible tail models"
        sentence = f"{'; '.join(model_fails)} exceeds {req_p:g} per exposure."
    elif models_pass and not model_fails and not not_run:
        v, basis = PASS, " and ".join(sorted({i.method for i in uppers.values()}))
        dec = ", ".join(
            f"{a} {format_probability(i.upper, i.log10_upper)} ({i.method})" for a, i in uppers.items()
        )
        sentence = (
            f"No {what} observed; the admissible tail models bound P({what}) per exposure by {dec}, "
            f"together within {req_p:g}."
        )
    else:
        basis = "a check could not run" if models_pass and not model_fails else "tail models inconclusive"
        v = NOT_DEMONSTRATED
        why = []
        if model_fails:
            why.append("the admissible models disagree (" + "; ".join(model_fails) + ")")
        if rejected:
            why.append("rejected by the data: " + ", ".join(rejected))
        if missing:
            why.append("no admissible model on the " + " and ".join(missing) + " axis")
        if total is not None and not models_pass:
            why.append(f"the admissible upper bounds add up to {format_probability(total)} > {req_p:g}")
        why += not_run
        pre = f"{events} {what} epochs observed" if events else f"No {what} observed"
        sentence = f"{pre}, but {req} is not demonstrated: " + "; ".join(why or ["no evidence"]) + "."
    return Verdict(kind, v, req, basis, sentence, tuple(items))


def _integrity(ctx: _Context, s: ServiceLevel, bounding: Verdict) -> Verdict:
    """R2 then R9: an observed HMI fails; a PL-bounding pass is an integrity pass."""
    own = _tail_verdict("integrity", ctx, s)
    if own.verdict == FAIL or bounding.verdict != PASS:
        return own
    return Verdict(
        "integrity",
        PASS,
        own.requirement,
        "PL bounding demonstrated (HMI implies MI)",
        "No HMI observed, and PL bounding is demonstrated for this service; HMI (PE >= AL while PL < AL) "
        "implies MI, so the integrity risk is within its bound.",
        own.evidence,
    )


def overall_verdict(vs: Sequence[Verdict]) -> Verdict:
    """R10."""
    outcomes = [v.verdict for v in vs]
    v = FAIL if FAIL in outcomes else PASS if all(o == PASS for o in outcomes) else NOT_DEMONSTRATED
    names = {o: [x.kind.replace("_", " ") for x in vs if x.verdict == o] for o in (FAIL, NOT_DEMONSTRATED)}
    if v == PASS:
        sentence = "Every requirement is demonstrated."
    elif v == FAIL:
        sentence = "Fails on " + ", ".join(names[FAIL]) + "."
    else:
        sentence = "Not demonstrated: " + ", ".join(names[NOT_DEMONSTRATED]) + "."
    return Verdict("overall", v, "all of the above", "rule R10", sentence)


# --------------------------------------------------------------------------------------------------
# supporting fits (R1)


def _parametric_support(par: ParametricAnalysis | None, s: ServiceLevel) -> tuple[list, list]:
    """Kannemans' fitted unavailability and non-continuity of each axis: supporting, no vote."""
    avail, cont = [], []
    if par is None:
        return avail, cont
    for a in _AXES:
        ax = par.axis(a)
        sp = ax.services.get(s.name) if ax is not None else None
        if sp is None:
            continue
        avail.append(
            EvidenceItem(
                "parametric (Kannemans 2006)",
                f"unavailability, {a} (Weibull fit of the PL)",
                sp.unavailability_fit,
                None,
                sp.unavailability_bound,
                "none",
                "Weibull PL model; a fit of the count, shown beside it (R1)",
                axis=a,
            )
        )
        if sp.continuity_fit is not None:
            cont.append(
                EvidenceItem(
                    "parametric (Kannemans 2006)",
                    f"non-continuity fit at the alert limit, {a}",
                    sp.continuity_fit,
                    None,
                    sp.continuity_fit_bound,
                    "none",
                    "log-linear fit of the counted non-continuity against the alert limit (R1)",
                    axis=a,
                )
            )
    return avail, cont


# --------------------------------------------------------------------------------------------------
# the whole assessment


def service_verdicts(ctx: _Context, s: ServiceLevel) -> ServiceVerdicts:
    """The five verdicts and the overall one of service ``s``."""
    ev = ctx.evidence.services[s.name]
    avail_sup, cont_sup = _parametric_support(ctx.parametric, s)
    availability = availability_verdict(ev, s, avail_sup)
    continuity = continuity_verdict(ev, s, cont_sup)
    accuracy = accuracy_verdict(ctx.evidence, s)
    bounding = _tail_verdict("pl_bounding", ctx, s)
    integrity = _integrity(ctx, s, bounding)
    five = (availability, continuity, accuracy, integrity, bounding)
    return ServiceVerdicts(s.name, *five, overall_verdict(five))


def assess(analysis: Analysis, evidence: Evidence | None = None) -> Assessment:
    """The verdicts of every service of ``analysis``, pooled and per station."""
    evidence = evidence if evidence is not None else analysis.evidence
    if evidence is None:
        raise ValueError("the analysis has no counted evidence (run analyze() on a table)")
    evt = {e.axis: e for e in analysis.evt}
    cl = {c.axis: c for c in analysis.confidence}
    failed = {(m, a): why for m, a, why in analysis.method_failures}
    cache: dict = dict(analysis.band_confidences)  # R8's evaluations a campaign made on its workers

    def ctx_of(ev: StationEvidence) -> _Context:
        interval = ev.interval_s or evidence.pooled.interval_s or 1.0
        return _Context(ev, evt, analysis.parametric, cl, interval, cache, failed)

    pooled = {s.name: service_verdicts(ctx_of(evidence.pooled), s) for s in analysis.services}
    by_station = {
        name: {s.name: service_verdicts(ctx_of(ev), s) for s in analysis.services}
        for name, ev in evidence.by_station.items()
    }
    return Assessment(pooled, by_station)
