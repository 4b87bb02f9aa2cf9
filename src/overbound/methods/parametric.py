r"""Parametric availability, integrity and continuity (Kannemans 2006, NLR-TP-2006-594, section 2).

Per axis: the ratio PE/PL fitted by a normal (vertical, signed VPE) or a Rayleigh (horizontal)
distribution gives :math:`P_{MI} = P(|PE| > PL)`; a Weibull fit of the PL gives the
unavailability :math:`P(PL \ge AL)`; their product, integrated over the Stanford regions, gives
:math:`P_{HMI}` and the MI probabilities with the PL above and below the AL; the 15 s
loss-of-continuity count over a grid of alert limits gives the non-continuity curve and its
log-linear fit. Bounds at a confidence level use the effective sample size of the correlated
series (decorrelation time from the autocorrelation). The maths is in
:mod:`overbound.stats.parametric` and :mod:`overbound.stats.continuity`; this module prepares the
series, runs the fits per axis and service, and writes ``parametric.json``
(schema ``overbound.parametric/1``).

Columns needed: ``time``, ``station``, ``vpe`` and ``vpl`` (vertical), ``hpe`` and ``hpl``
(horizontal); optional ``alert``. An axis whose columns are missing is reported null with the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import polars as pl

from overbound.io.schema import InputError, as_numpy
from overbound.methods.counting import _station_slices  # the counting's station split, shared on purpose
from overbound.methods.parametric_partitions import (
    ACF_MAX_SLOTS,
    AxisPlan,
    FittedBlock,
    SecondInputs,
    add_in_order,
    axis_plan,
    block_first,
    block_information,
    block_profile,
    block_second,
    fitted_block,
    second_inputs,
)
from overbound.methods.pooling import PE_PL, pool_epochs, unavailable_at_alerts
from overbound.services import ServiceLevel, parse_service, resolve_services
from overbound.stats.continuity import (
    ContinuityCurve,
    LogLinearFit,
    StationGrid,
    alert_limit_grid,
    fit_loglinear,
    noncontinuity_curve,
    pool_curves,
    station_grid,
)
from overbound.stats.dependence import autocorrelation, one_over_e_time
from overbound.stats.parametric import (
    RatioFit,
    WeibullFit,
    effective_sample_size,
    integrity_probabilities,
    log_ratio_exceedance,
    normal_ratio_fit,
    ratio_bound,
    rayleigh_ratio_fit,
    weibull_bound,
    weibull_covariance_from_sums,
    weibull_fit_from_sums,
    weibull_logsf,
)

__all__ = [
    "ACF_MAX_LAG_S",
    "ACF_MAX_SLOTS",
    "AXIS_EXTRA_KEYS",
    "AXIS_KEYS",
    "CONTINUITY_HALF_WIDTH_M",
    "MIN_EPOCHS",
    "SCHEMA",
    "SERVICE_EXTRA_KEYS",
    "SERVICE_KEYS",
    "TOP_EXTRA_KEYS",
    "TOP_KEYS",
    "AxisParametric",
    "ParametricAnalysis",
    "ServiceParametric",
    "analysed_series",
    "parametric_analysis",
    "parametric_dict",
    "write_parametric",
]

SCHEMA = "overbound.parametric/1"
AXES = ("vertical", "horizontal")
#: Fewest fitted epochs for an axis to be analysed.
MIN_EPOCHS = 10
#: Largest ACF lag examined (s): 6 h, or the series when shorter.
ACF_MAX_LAG_S = 6 * 3600.0
#: ACF points kept on the result for the figure (evenly thinned, the 1/e crossings kept).
ACF_FIGURE_POINTS = 2000
#: Half width of the alert-limit window of the local continuity fit (m).
CONTINUITY_HALF_WIDTH_M = 10.0
DECORRELATION_RULE = "1/e"
#: Iterations of the mean-removal bias correction of the ACF (see ``_acf``).
MEAN_BIAS_ITERATIONS = 5

#: JSON keys of the issue: top level, per axis, per service.
TOP_KEYS = frozenset({"schema", "vertical", "horizontal"})
AXIS_KEYS = frozenset(
    {"ratio_fit", "decorrelation_s", "n_effective", "p_mi", "p_mi_bound", "weibull", "services"}
)
SERVICE_KEYS = frozenset(
    {
        "unavailability_fit",
        "unavailability_bound",
        "unavailability_counted",
        "p_hmi",
        "p_hmi_bound",
        "p_mi_pl_above_al",
        "p_mi_pl_below_al",
        "continuity_counted",
        "continuity_fit",
        "continuity_fit_bound",
    }
)
#: Extra keys written besides those of the issue (documented in :func:`parametric_dict`).
TOP_EXTRA_KEYS = frozenset(
    {"confidence", "decorrelation", "decorrelation_rule", "continuity_half_width_m", "epochs", "reasons"}
)
AXIS_EXTRA_KEYS = frozenset(
    {
        "n_epochs",
        "n_alert",
        "n_stations",
        "interval_s",
        "pl_decorrelation_s",
        "pl_n_effective",
        "log10_p_mi",
        "log10_p_mi_bound",
        "ratio_bound_fit",
        "weibull_converged",
        "pl_range",
        "continuity",
        "notes",
    }
)
SERVICE_EXTRA_KEYS = frozenset(
    {
        "alert_limit",
        "continuity_window_s",
        "continuity_fit_source",
        "continuity_local_fit",
        "continuity_local_fit_bound",
        "continuity_n_windows",
        "continuity_n_fail",
        "continuity_n_events",
        "n_available_counted",
        "unavailability_counted_fitted",
        "weibull_bound",
        "log10_unavailability_fit",
        "log10_unavailability_bound",
        "log10_p_hmi",
        "log10_p_hmi_bound",
        "log10_p_mi_pl_above_al",
        "log10_p_mi_pl_below_al",
        "p_mi_pl_above_al_bound",
        "p_mi_pl_below_al_bound",
        "log10_p_mi_pl_above_al_bound",
        "log10_p_mi_pl_below_al_bound",
        "reason",
    }
)

_LN10 = math.log(10.0)


# --------------------------------------------------------------------------------------------------
# results


@dataclass(frozen=True, slots=True)
class ServiceParametric:
    r"""One service on one axis (Kannemans 2006, sections 2.1.2-2.1.4). Probabilities per epoch,
    continuity per ``continuity_window_s``; ``None`` where not computable (see ``reason``).

    Attributes
    ----------
    name, alert_limit : service and its alert limit on this axis (m).
    unavailability_fit : :math:`S(AL) = e^{-a AL^b}` of the Weibull fit.
    unavailability_bound : :math:`S(AL)` at the bound parameters ``weibull_bound``.
    unavailability_counted : counted as :mod:`overbound.methods.counting` does: share of all
        rows of the table that are not available (PL >= AL, no solution, or the ``alert`` flag).
    n_available_counted : rows with PL < AL and no alert.
    unavailability_counted_fitted : share of the fitted epochs (solution, no alert) with PL >= AL,
        the count comparable with ``unavailability_fit``.
    weibull_bound : Weibull parameters of the bound at this AL (they also give the ``*_bound``
        integrals).
    p_hmi, p_mi_pl_above_al, p_mi_pl_below_al : the integrals at the fits; ``*_bound`` at the
        ratio bound and ``weibull_bound``; ``log10_*`` finite where the probability underflows.
    continuity_window_s : exposure time of the service's continuity requirement.
    continuity_counted, continuity_n_windows, continuity_n_fail, continuity_n_events : the count
        at AL, pooled over stations (equal to :func:`overbound.methods.counting.continuity_risk`).
    continuity_fit, continuity_fit_bound : the log-linear fits of the risk and of its
        Clopper-Pearson bound evaluated at AL; ``continuity_fit_source`` says which fits:
        ``"local"`` (alert limits within :data:`CONTINUITY_HALF_WIDTH_M` of AL) or ``"global"``
        (the observed PL range, when the local window holds fewer than 3 points with P > 0).
    continuity_local_fit, continuity_local_fit_bound : the local fits (``None`` when too few points).
    reason : why some values are ``None`` (empty otherwise).
    """

    name: str
    alert_limit: float
    unavailability_fit: float
    log10_unavailability_fit: float
    unavailability_bound: float | None
    log10_unavailability_bound: float | None
    unavailability_counted: float | None
    n_available_counted: int
    unavailability_counted_fitted: float
    weibull_bound: WeibullFit | None
    p_hmi: float
    log10_p_hmi: float
    p_hmi_bound: float | None
    log10_p_hmi_bound: float | None
    p_mi_pl_above_al: float
    log10_p_mi_pl_above_al: float
    p_mi_pl_above_al_bound: float | None
    log10_p_mi_pl_above_al_bound: float | None
    p_mi_pl_below_al: float
    log10_p_mi_pl_below_al: float
    p_mi_pl_below_al_bound: float | None
    log10_p_mi_pl_below_al_bound: float | None
    continuity_window_s: float
    continuity_counted: float | None
    continuity_n_windows: int
    continuity_n_fail: int
    continuity_n_events: int
    continuity_fit: float | None
    continuity_fit_bound: float | None
    continuity_fit_source: str | None
    continuity_local_fit: LogLinearFit | None
    continuity_local_fit_bound: LogLinearFit | None
    reason: str = ""


@dataclass(frozen=True, slots=True)
class AxisParametric:
    r"""The parametric analysis of one axis.

    Attributes
    ----------
    axis : ``vertical`` or ``horizontal``.
    n_epochs : epochs fitted (finite PE, PL > 0, no alert), all stations.
    n_alert, n_no_solution, n_rows, n_stations : epochs flagged ``alert`` (left out of the fits),
        rows without a solution, rows of the table, stations.
    interval_s : nominal sampling interval (s).
    ratio_fit, ratio_bound_fit : the ratio fit and its bound (``None`` with a note when the series
        is too short for its decorrelation time).
    decorrelation_s, pl_decorrelation_s : decorrelation times (s) of the ratio and of the PL
        (``inf`` when the ACF stays above 1/e within the lags examined).
    decorrelation_auto : whether they were read from the ACF (else given).
    n_effective, pl_n_effective : effective sample sizes of the ratio's P_MI bound and of the Weibull
        bound (:func:`parametric_analysis` step 3: :math:`n\Delta/\tau` vertical, :math:`n\Delta/2\tau`
        horizontal and for the PL).
    p_mi, log10_p_mi, p_mi_bound, log10_p_mi_bound : :math:`Q(1)` at the fit and at its bound.
    weibull, weibull_cov : Weibull fit of the PL and covariance of :math:`(\ln a, b)` (``None``
        without the effective sample).
    acf_lags_s, ratio_acf, pl_acf, acf_step : the ACFs of the two series (thinned to about
        :data:`ACF_FIGURE_POINTS` lags, the 1/e crossings kept) and the slot step they were
        computed with (1, or q for long series).
    pl_range : smallest and largest fitted PL (m): the alert-limit range of the continuity fits.
    continuity_curves : pooled non-continuity curve per window (s) used by a service.
    continuity_fits, continuity_fits_bound : per window, the log-linear fit over ``pl_range`` of
        the risk and of its Clopper-Pearson bound.
    services : per service name its :class:`ServiceParametric`; ``None`` for a service without an
        alert limit on this axis (NPA in the vertical).
    notes : why bounds are missing, and other remarks.
    """

    axis: str
    n_epochs: int
    n_alert: int
    n_no_solution: int
    n_rows: int
    n_stations: int
    interval_s: float
    ratio_fit: RatioFit
    ratio_bound_fit: RatioFit | None
    decorrelation_s: float
    pl_decorrelation_s: float
    decorrelation_auto: bool
    n_effective: float
    pl_n_effective: float
    p_mi: float
    log10_p_mi: float
    p_mi_bound: float | None
    log10_p_mi_bound: float | None
    weibull: WeibullFit
    weibull_cov: np.ndarray | None = field(repr=False)
    acf_lags_s: np.ndarray = field(repr=False)
    ratio_acf: np.ndarray = field(repr=False)
    pl_acf: np.ndarray = field(repr=False)
    acf_step: int
    pl_range: tuple[float, float]
    continuity_curves: dict[float, ContinuityCurve] = field(repr=False)
    continuity_fits: dict[float, LogLinearFit | None]
    continuity_fits_bound: dict[float, LogLinearFit | None]
    services: dict[str, ServiceParametric | None]
    notes: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class ParametricAnalysis:
    """Both axes; an axis that could not be analysed is ``None`` with its reason in ``reasons``.

    Attributes
    ----------
    vertical, horizontal : :class:`AxisParametric` or ``None``.
    reasons : axis -> why it is ``None``.
    services : the service levels analysed.
    confidence : confidence level of the bounds.
    decorrelation : ``"auto"`` or the decorrelation time given (s).
    n_rows : rows of the table.
    """

    vertical: AxisParametric | None
    horizontal: AxisParametric | None
    reasons: dict[str, str]
    services: tuple[ServiceLevel, ...]
    confidence: float
    decorrelation: str | float
    n_rows: int

    def axis(self, name: str) -> AxisParametric | None:
        """The result of axis ``name`` (``vertical`` or ``horizontal``)."""
        if name not in AXES:
            raise ValueError(f"axis must be 'vertical' or 'horizontal', got {name!r}")
        return getattr(self, name)


# --------------------------------------------------------------------------------------------------
# options


def _decorrelation(value: str | float) -> str | float:
    if isinstance(value, str) and value.strip().lower() == "auto":
        return "auto"
    try:
        tau = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"decorrelation must be 'auto' or a number of seconds, got {value!r}") from None
    if not (math.isfinite(tau) and tau > 0):
        raise ValueError(f"decorrelation must be 'auto' or finite seconds > 0, got {value!r}")
    return tau


def _services(services) -> tuple[ServiceLevel, ...]:
    if services is None:
        return resolve_services(None)
    if isinstance(services, str | ServiceLevel):
        services = (services,)
    out = tuple(s if isinstance(s, ServiceLevel) else parse_service(s) for s in services)
    names = [s.name for s in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"service(s) given twice: {', '.join(dup)}")
    return out


# --------------------------------------------------------------------------------------------------
# the series


def analysed_series(table: pl.DataFrame, axis: str = "vertical") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pooled times (s), ratios PE/PL and PLs of the epochs :func:`parametric_analysis` fits on ``axis``.

    Solution epochs (finite PE, PL > 0) without the ``alert`` flag; the vertical ratio is signed.
    """
    d = pool_epochs(table, axis, signed=axis == "vertical")
    keep = ~d.alert
    return d.t_us[keep] / 1e6, d.pe[keep] / d.pl[keep], d.pl[keep]


@dataclass(frozen=True, slots=True)
class _ACF:
    lags_s: np.ndarray
    values: np.ndarray
    step: int
    decorrelation_s: float


def _acf(sub: np.ndarray, step: int, interval_s: float) -> _ACF:
    r"""ACF of a regular series (NaN in gaps) read at every ``step``-th slot (``sub``), and its 1/e
    decorrelation time.

    Lags up to :data:`ACF_MAX_LAG_S`. A grid longer than :data:`ACF_MAX_SLOTS` slots is read every
    :math:`q = \lceil n / \text{ACF\_MAX\_SLOTS}\rceil`-th slot (the ``step`` of
    :class:`~overbound.methods.parametric_partitions.AxisPlan`): the estimator at lag :math:`kq` uses
    the pairs of those slots only (unbiased, a little noisier), and the decorrelation time is
    resolved to :math:`q` intervals, rounded up (longer: fewer effective samples, conservative).

    The sample ACF of a series whose mean is estimated is biased low: for a Gauss-Markov series of
    length :math:`T`, :math:`E\hat\rho(k) \approx (\rho(k) - \epsilon)/(1 - \epsilon)` with
    :math:`\epsilon = \mathrm{var}(\bar x)/\sigma^2 \approx 2\tau/T` (Priestley 1981, eq. 5.3.22;
    Marriott & Pope 1954). The returned ACF is corrected, :math:`\hat\rho(1-\epsilon) + \epsilon`,
    with :math:`\tau` and :math:`\epsilon` iterated to agreement (at most
    :data:`MEAN_BIAS_ITERATIONS` times). It matters for short campaigns: on 6.5 h at 1 Hz with
    :math:`\tau` = 300-600 s the uncorrected 1/e time was 10-15 % short and the bounds below their
    nominal share (validation/parametric_coverage.py); on months of data :math:`\epsilon < 10^{-3}`.
    """
    max_lag = int(min(round(ACF_MAX_LAG_S / (interval_s * step)), sub.size - 1))
    rho = autocorrelation(sub, max_lag=max(max_lag, 0))
    if not np.isfinite(rho[0]):
        return _ACF(np.arange(rho.size) * step * interval_s, rho, step, math.nan)
    span_s = np.count_nonzero(np.isfinite(sub)) * step * interval_s
    raw, tau = rho, one_over_e_time(rho, step * interval_s)
    for _ in range(MEAN_BIAS_ITERATIONS):
        # mean-removal bias of the sample ACF: E[rho_hat] ~ (rho - e)/(1 - e), e = var(mean)/var = 2 tau/T
        eps = min(2.0 * tau / span_s, 0.5) if math.isfinite(tau) else 0.5
        rho = raw * (1.0 - eps) + eps
        new = one_over_e_time(rho, step * interval_s)
        if new == tau:
            break
        tau = new
    return _ACF(np.arange(rho.size) * step * interval_s, rho, step, tau)


def _thin_acf(a: _ACF, b: _ACF) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lags and both ACFs thinned to about :data:`ACF_FIGURE_POINTS`, the 1/e crossings kept."""
    n = a.values.size
    every = max(1, -(-n // ACF_FIGURE_POINTS))
    keep = [np.arange(0, n, every), [n - 1]]
    for s in (a, b):
        if math.isfinite(s.decorrelation_s):
            k = round(s.decorrelation_s / (a.lags_s[1] if n > 1 else 1.0))
            keep.append([max(k - 1, 0), min(k, n - 1)])
    idx = np.unique(np.concatenate(keep).astype(np.intp))
    return a.lags_s[idx], a.values[idx], b.values[idx]


def _n_effective(n: int, interval_s: float, tau: float) -> float:
    """:func:`effective_sample_size`; 0 for an infinite time, NaN for an undefined one."""
    if math.isnan(tau):
        return math.nan
    return effective_sample_size(n, interval_s, tau)


# --------------------------------------------------------------------------------------------------
# continuity


@dataclass(frozen=True, slots=True)
class _Rows:
    """All rows of the table per station, each on its grid: the continuity count's input (as
    :mod:`overbound.methods.counting`'s), shared by both axes and every window."""

    stations: list[tuple[np.ndarray | slice, StationGrid]]
    alert: np.ndarray | None


def _rows(table: pl.DataFrame) -> _Rows:
    alert = None
    if "alert" in table.columns and table["alert"].any():
        alert = as_numpy(table["alert"].fill_null(False)).astype(bool)
    time_us = as_numpy(table["time"]).astype(np.int64, copy=False)
    stations = [(idx, station_grid(time_us[idx])) for idx in _station_slices(table).values()]
    return _Rows(stations, alert)


def _continuity(
    rows: _Rows, pls: np.ndarray, grid: np.ndarray, window_s: float, confidence: float
) -> ContinuityCurve:
    """Per-station curves on each station's own grid, pooled; ``pls`` has alerts as +inf (unavailable)."""
    parts = [
        noncontinuity_curve(None, pls[idx], grid, window_s=window_s, confidence=confidence, grid=g)
        for idx, g in rows.stations
    ]
    return pool_curves(parts)


def _in_range(curve: ContinuityCurve, lo: float, hi: float) -> np.ndarray:
    return (curve.alert_limit >= lo) & (curve.alert_limit <= hi)


def _fits(curve: ContinuityCurve, mask: np.ndarray) -> tuple[LogLinearFit | None, LogLinearFit | None]:
    """Log-linear fits of the risk and of its bound over the points of ``mask`` with risk > 0."""
    al = curve.alert_limit[mask]
    risk = curve.risk[mask]
    with np.errstate(invalid="ignore"):
        bound = np.where(risk > 0, curve.risk_bound[mask], np.nan)  # the same points for both
    return fit_loglinear(al, risk), fit_loglinear(al, bound)


# --------------------------------------------------------------------------------------------------
# one axis


def _log10(ln: float) -> float:
    return ln / _LN10


@dataclass(frozen=True, slots=True)
class RowCounts:
    """What one axis' analysis counts over all rows of the table (no solution and alerts
    unavailable): the rows, those available at each service's alert limit, and the
    non-continuity curve of each window (stations pooled)."""

    n_rows: int
    n_available: dict[float, int]
    curves: dict[float, ContinuityCurve]


def service_alert_limits(services: tuple[ServiceLevel, ...], axis: str) -> np.ndarray:
    """The services' alert limits on ``axis`` (sorted, distinct)."""
    return np.unique([al for s in services if (al := s.alert_limit(axis)) is not None]).astype(np.float64)


def continuity_grids(services: tuple[ServiceLevel, ...], axis: str, pl_range: tuple[float, float]) -> dict:
    """Per window used by a service on ``axis``, the alert limits of its curve: 400 over the fitted
    PL range (:func:`~overbound.stats.continuity.alert_limit_grid`) and those services' limits."""
    base = alert_limit_grid(np.array(pl_range))
    windows = sorted({s.continuity_window_s for s in services if s.alert_limit(axis) is not None})
    return {
        w: np.union1d(
            base,
            [a for s in services if s.continuity_window_s == w and (a := s.alert_limit(axis)) is not None],
        )
        for w in windows
    }


def _row_counts(rows: _Rows, table: pl.DataFrame, axis: str, services, pl_range, confidence) -> RowCounts:
    pl_col = as_numpy(table[PE_PL[axis][1]]).astype(np.float64, copy=False)
    if rows.alert is not None:
        pl_col = unavailable_at_alerts(pl_col, rows.alert)
    curves = {
        w: _continuity(rows, pl_col, grid, w, confidence)
        for w, grid in continuity_grids(services, axis, pl_range).items()
    }
    n_available = {
        float(al): int(np.count_nonzero(pl_col < al)) for al in service_alert_limits(services, axis)
    }
    return RowCounts(pl_col.size, n_available, curves)


def _pooled_blocks(d) -> tuple[list[FittedBlock], list[int]]:
    """The pooled epochs cut into blocks (station-days) and each block's station code."""
    cuts = np.flatnonzero(np.diff(d.day)) + 1
    bounds = zip(np.concatenate([[0], cuts]), np.concatenate([cuts, [d.day.size]]), strict=True)
    blocks, stations = [], []
    for a, b in bounds:
        blocks.append(fitted_block(d.t_us[a:b], d.pe[a:b], d.pl[a:b], d.alert[a:b]))
        stations.append(int(d.station[a]))
    return blocks, stations


def check_fittable(plan: AxisPlan, axis: str) -> None:
    """Raise ValueError with the reason when the axis cannot be fitted (the checks, in order, of
    the ratio and Weibull fits on the pooled epochs)."""
    if plan.n < MIN_EPOCHS:
        raise ValueError(f"{plan.n} epochs with a solution and no alert (at least {MIN_EPOCHS} needed)")
    if axis == "vertical" and not plan.varies:
        raise ValueError("r is constant: a normal fit needs a positive standard deviation")
    if axis == "horizontal" and not plan.ratio_squares > 0.0:
        raise ValueError("r is all zero: a Rayleigh fit needs a positive scale")
    if not plan.log_varies:
        raise ValueError("x is constant: the Weibull ML shape is infinite")


def ratio_fit_of(plan: AxisPlan, second: SecondInputs, axis: str) -> RatioFit:
    """The ratio fit of ``axis`` from the merged passes (:func:`check_fittable` passed)."""
    if axis == "vertical":
        return normal_ratio_fit(plan.n, plan.mean, second.squared_deviations, plan.varies)
    return rayleigh_ratio_fit(plan.n, plan.ratio_squares)


@dataclass(frozen=True, slots=True)
class Dependence:
    """The ACFs of the ratio series and of the PL, their decorrelation times and the effective
    sample sizes of the ratio's and of the Weibull's bounds (step 3 of :func:`parametric_analysis`)."""

    ratio_acf: _ACF
    pl_acf: _ACF
    tau_ratio: float
    tau_pl: float
    n_effective: float
    pl_n_effective: float
    auto: bool


def dependence(plan: AxisPlan, second: SecondInputs, axis: str, decorrelation: str | float) -> Dependence:
    """Step 3 of :func:`parametric_analysis` from the merged passes."""
    interval_s = plan.dt / 1e6
    r_acf = _acf(second.ratio_sub, plan.step, interval_s)
    p_acf = _acf(second.pl_sub, plan.step, interval_s)
    auto = decorrelation == "auto"
    tau_r = r_acf.decorrelation_s if auto else float(decorrelation)
    tau_p = p_acf.decorrelation_s if auto else float(decorrelation)
    # the statistics' integral time scales: 2 tau for means of the PL (Weibull scores) and of r^2 for the
    # Rayleigh (whose own 1/e time is half its components'), tau for the normal's variance (step 3)
    n_eff = _n_effective(plan.n, interval_s, tau_r) / (2.0 if axis == "horizontal" else 1.0)
    pl_n_eff = _n_effective(plan.n, interval_s, tau_p) / 2.0
    return Dependence(r_acf, p_acf, tau_r, tau_p, n_eff, pl_n_eff, auto)


def needs_information(dep: Dependence) -> bool:
    """Whether the Weibull bound is computed (its covariance needs the information sums)."""
    return dep.pl_n_effective > 2  # the bound's t quantile has n_e - 2 degrees of freedom


def _axis(
    table: pl.DataFrame,
    rows: _Rows,
    axis: str,
    services: tuple[ServiceLevel, ...],
    decorrelation: str | float,
    confidence: float,
) -> AxisParametric:
    """Raises InputError/ValueError with the reason when the axis cannot be analysed. The pooled
    epochs in blocks (station-days) through the passes of :mod:`overbound.methods.parametric_partitions`."""
    d = pool_epochs(table, axis, signed=axis == "vertical")
    blocks, stations = _pooled_blocks(d)
    als = service_alert_limits(services, axis)
    plan = axis_plan([block_first(b, st, als) for b, st in zip(blocks, stations, strict=True)])
    check_fittable(plan, axis)
    second = second_inputs([block_second(b, plan, i, axis) for i, b in enumerate(blocks)], plan)
    weibull = weibull_fit_from_sums(
        plan.n,
        plan.ymax,
        plan.spread,
        second.start,
        lambda b: add_in_order(block_profile(bl, plan.ymax, b) for bl in blocks),
    )
    dep = dependence(plan, second, axis, decorrelation)
    info = add_in_order(block_information(bl, weibull) for bl in blocks) if needs_information(dep) else None
    counts = _row_counts(rows, table, axis, services, plan.pl_range, confidence)
    return axis_result(axis, plan, second, weibull, dep, info, counts, services, confidence)


def axis_result(
    axis: str,
    plan: AxisPlan,
    second: SecondInputs,
    weibull: WeibullFit,
    dep: Dependence,
    information: np.ndarray | None,
    counts: RowCounts,
    services: tuple[ServiceLevel, ...],
    confidence: float,
) -> AxisParametric:
    """Steps 4-8 of :func:`parametric_analysis` from the merged passes of an axis (the pooled
    table's or a campaign's)."""
    interval_s = plan.dt / 1e6
    ratio_fit = ratio_fit_of(plan, second, axis)
    notes: list[str] = []
    bound_fit = ratio_bound(ratio_fit, dep.n_effective, confidence) if dep.n_effective >= 0 else None
    if bound_fit is None:
        notes.append(_short_note("ratio", dep.n_effective, dep.tau_ratio))
    cov = None
    if information is not None:
        cov = weibull_covariance_from_sums(weibull, information, plan.n, dep.pl_n_effective)
    else:
        notes.append(_short_note("PL", dep.pl_n_effective, dep.tau_pl))
    ln_q1 = float(log_ratio_exceedance(ratio_fit, 1.0))
    ln_q1_b = None if bound_fit is None else float(log_ratio_exceedance(bound_fit, 1.0))
    lags, racf, pacf = _thin_acf(dep.ratio_acf, dep.pl_acf)
    curves = counts.curves
    fits, fits_b = {}, {}
    for w, curve in curves.items():
        fits[w], fits_b[w] = _fits(curve, _in_range(curve, *plan.pl_range))
    als = service_alert_limits(services, axis)
    ctx = _AxisContext(
        plan,
        {float(a): int(c) for a, c in zip(als, plan.at_or_above, strict=True)},
        counts,
        ratio_fit,
        bound_fit,
        weibull,
        cov,
        dep.pl_n_effective,
        confidence,
        fits,
        fits_b,
        interval_s,
    )
    out_services = {s.name: _service(ctx, s, axis) for s in services}
    return AxisParametric(
        axis=axis,
        n_epochs=plan.n,
        n_alert=plan.n_alert,
        n_no_solution=counts.n_rows - plan.n_solution,
        n_rows=counts.n_rows,
        n_stations=plan.n_stations,
        interval_s=interval_s,
        ratio_fit=ratio_fit,
        ratio_bound_fit=bound_fit,
        decorrelation_s=dep.tau_ratio,
        pl_decorrelation_s=dep.tau_pl,
        decorrelation_auto=dep.auto,
        n_effective=dep.n_effective,
        pl_n_effective=dep.pl_n_effective,
        p_mi=math.exp(ln_q1),
        log10_p_mi=_log10(ln_q1),
        p_mi_bound=None if ln_q1_b is None else math.exp(ln_q1_b),
        log10_p_mi_bound=None if ln_q1_b is None else _log10(ln_q1_b),
        weibull=weibull,
        weibull_cov=cov,
        acf_lags_s=lags,
        ratio_acf=racf,
        pl_acf=pacf,
        acf_step=plan.step,
        pl_range=plan.pl_range,
        continuity_curves=curves,
        continuity_fits=fits,
        continuity_fits_bound=fits_b,
        services=out_services,
        notes=tuple(notes),
    )


def _short_note(series: str, n_eff: float, tau: float) -> str:
    if math.isnan(n_eff):
        return f"no {series} bound: its autocorrelation is undefined (constant series)"
    if math.isinf(tau):
        return (
            f"no {series} bound: its autocorrelation stays above 1/e over the "
            f"{ACF_MAX_LAG_S / 3600:g} h of lags examined (or the series)"
        )
    return (
        f"no {series} bound: {n_eff:.3g} effective samples (decorrelation time {tau:g} s) "
        "is too few (more than 2 needed)"
    )


@dataclass(frozen=True, slots=True)
class _AxisContext:
    plan: AxisPlan
    n_unavailable_fitted: dict[float, int]  # fitted PLs at or above each service AL
    counts: RowCounts
    ratio_fit: RatioFit
    bound_fit: RatioFit | None
    weibull: WeibullFit
    cov: np.ndarray | None
    pl_n_effective: float
    confidence: float
    fits: dict[float, LogLinearFit | None]
    fits_b: dict[float, LogLinearFit | None]
    interval_s: float


def _service(ctx: _AxisContext, s: ServiceLevel, axis: str) -> ServiceParametric | None:
    al = s.alert_limit(axis)
    if al is None:
        return None
    reasons = []
    wb = None
    if ctx.cov is None:
        reasons.append("no Weibull bound: too few effective PL samples (see the axis notes)")
    else:
        try:
            wb = weibull_bound(ctx.weibull, ctx.cov, al, ctx.confidence, dof=ctx.pl_n_effective - 2.0)
        except ValueError as exc:
            reasons.append(str(exc))
    if ctx.bound_fit is None:
        reasons.append("no ratio bound: too few effective samples (see the axis notes)")
    nominal = integrity_probabilities(ctx.ratio_fit, ctx.weibull, al)
    bound = None if wb is None or ctx.bound_fit is None else integrity_probabilities(ctx.bound_fit, wb, al)
    ln_s = float(weibull_logsf(ctx.weibull, al))
    ln_sb = None if wb is None else float(weibull_logsf(wb, al))
    n_rows = ctx.counts.n_rows
    n_avail = ctx.counts.n_available[float(al)]
    w = s.continuity_window_s
    curve = ctx.counts.curves[w]
    j = int(np.searchsorted(curve.alert_limit, al))  # al is on the grid
    risk = float(curve.risk[j])
    local = _in_range(curve, al - CONTINUITY_HALF_WIDTH_M, al + CONTINUITY_HALF_WIDTH_M)
    local &= _in_range(curve, *ctx.plan.pl_range)
    lfit, lfit_b = _fits(curve, local)
    source, fit, fit_b = (
        ("local", lfit, lfit_b) if lfit is not None else ("global", ctx.fits[w], ctx.fits_b[w])
    )
    if fit is None:
        source = None
        if int(np.max(curve.n_windows, initial=0)) == 0:
            reasons.append(
                f"no continuity count: no {w:g} s window holds an epoch after its start "
                f"(sampling interval {ctx.interval_s:g} s)"
            )
        else:
            reasons.append("no continuity fit: fewer than 3 alert limits with a non-zero count")

    def bnd(name: str) -> float | None:
        return None if bound is None else getattr(bound, name)

    return ServiceParametric(
        name=s.name,
        alert_limit=al,
        unavailability_fit=math.exp(ln_s),
        log10_unavailability_fit=_log10(ln_s),
        unavailability_bound=None if ln_sb is None else math.exp(ln_sb),
        log10_unavailability_bound=None if ln_sb is None else _log10(ln_sb),
        unavailability_counted=1.0 - n_avail / n_rows if n_rows else None,
        n_available_counted=n_avail,
        unavailability_counted_fitted=ctx.n_unavailable_fitted[float(al)] / ctx.plan.n,
        weibull_bound=wb,
        p_hmi=nominal.p_hmi,
        log10_p_hmi=nominal.log10_p_hmi,
        p_hmi_bound=bnd("p_hmi"),
        log10_p_hmi_bound=bnd("log10_p_hmi"),
        p_mi_pl_above_al=nominal.p_mi_pl_above_al,
        log10_p_mi_pl_above_al=nominal.log10_p_mi_pl_above_al,
        p_mi_pl_above_al_bound=bnd("p_mi_pl_above_al"),
        log10_p_mi_pl_above_al_bound=bnd("log10_p_mi_pl_above_al"),
        p_mi_pl_below_al=nominal.p_mi_pl_below_al,
        log10_p_mi_pl_below_al=nominal.log10_p_mi_pl_below_al,
        p_mi_pl_below_al_bound=bnd("p_mi_pl_below_al"),
        log10_p_mi_pl_below_al_bound=bnd("log10_p_mi_pl_below_al"),
        continuity_window_s=w,
        continuity_counted=risk if math.isfinite(risk) else None,
        continuity_n_windows=int(curve.n_windows[j]),
        continuity_n_fail=int(curve.n_fail[j]),
        continuity_n_events=int(curve.n_events[j]),
        continuity_fit=None if fit is None else float(fit.risk(al)),
        continuity_fit_bound=None if fit_b is None else float(fit_b.risk(al)),
        continuity_fit_source=source,
        continuity_local_fit=lfit,
        continuity_local_fit_bound=lfit_b,
        reason="; ".join(reasons),
    )


# --------------------------------------------------------------------------------------------------
# the analysis


def parametric_analysis(
    table: pl.DataFrame,
    *,
    services: tuple[str | ServiceLevel, ...] | list[str | ServiceLevel] | None = None,
    decorrelation: str | float = "auto",
    confidence: float = 0.95,
) -> ParametricAnalysis:
    r"""Parametric MI, availability, integrity and continuity of both axes (Kannemans 2006, section 2).

    Parameters
    ----------
    table
        The epoch table (several stations are pooled, see Notes).
    services
        Service levels (names, ``NAME:HAL:VAL`` or :class:`~overbound.services.ServiceLevel`);
        default all built-in levels.
    decorrelation
        ``"auto"``: the decorrelation time of each series from its ACF (first lag below
        :math:`1/e`); or seconds, used for both the ratio and the PL.
    confidence
        One-sided confidence level of the bounds (the paper's "95 %", "confidence level of 5 %").

    Returns
    -------
    ParametricAnalysis
        An axis whose columns are missing, with fewer than :data:`MIN_EPOCHS` fitted epochs or whose
        fit fails (constant series) is ``None`` with the reason.

    Raises
    ------
    ValueError
        Bad ``decorrelation``, ``confidence`` or service; a table without ``time``/``station``.

    Notes
    -----
    1. **Epochs.** Per axis, the solution epochs (finite PE, PL > 0) of all stations pooled by
       :func:`~overbound.methods.pooling.pool_epochs` (stations a day apart on one time axis);
       epochs flagged ``alert`` are left out of the fits (a receiver alert is not a PL sample).
       The pooled series is cut into blocks, one per station and GPS day, and every fit is
       finished from the blocks' sums added in pooled order
       (:mod:`~overbound.methods.parametric_partitions`): the path of a campaign dataset
       (:mod:`overbound.campaign_parametric`), which gives the same results to the last bit.
       Choice: against the same sums over one whole array the fits differ in their last digits.
    2. **Ratio** (2.1.1, 2.2.1): :math:`r = VPE/VPL` with the signed VPE, normal fit (mean, sample
       standard deviation); :math:`r = HPE/HPL`, Rayleigh ML fit. :math:`P_{MI} = P(|r| > 1)`.
    3. **Decorrelation.** ACF of the ratio and of the PL on the pooled regular grid (NaN in gaps,
       between stations and at alerts), lags up to :data:`ACF_MAX_LAG_S`; the decorrelation time is
       the first lag with ACF below :math:`1/e` (the e-folding time of a first-order Gauss-Markov
       process; the paper reads 2000 s off its figures 5 and 8). Grids longer than
       :data:`ACF_MAX_SLOTS` slots are read every q-th slot (see ``_acf``). Effective sample size
       :math:`n_e = n\Delta/T` with :math:`T` the integral time scale of the quantity each estimate
       averages, for a first-order Gauss-Markov series of 1/e time :math:`\tau`
       (:func:`~overbound.stats.parametric.effective_sample_size`): normal ratio, :math:`T = \tau`
       for the standard deviation (a mean of squares, ACF :math:`\rho^2`) and :math:`2\tau` for the
       mean (inside :func:`~overbound.stats.parametric.ratio_bound`); Rayleigh ratio: the ACF (and
       ``decorrelation_s``) is that of :math:`r^2 = (HPE/HPL)^2`, the quantity :math:`\hat\sigma^2`
       averages, and :math:`T = 2\tau_{r^2}` (for Gauss-Markov components of 1/e time :math:`\tau_c`
       the ACF of :math:`r^2` is :math:`e^{-2|k|\Delta/\tau_c}`: 1/e time :math:`\tau_c/2`, integral
       scale :math:`\tau_c`; the ACF of :math:`r` itself crosses 1/e near :math:`0.46\tau_c` and gave
       bounds below their nominal share);
       Weibull, :math:`T = 2\tau_{PL}` (the ML estimates are means of the score). *Choice, from
       simulation* (tests/stats/test_parametric.py): with :math:`T = \tau` the 0.95 bounds held in only
       0.84-0.87 (Rayleigh) and 0.87-0.93 (Weibull) of the repetitions; with these scales 0.95-0.99.
       ``inf`` (the ACF never drops below :math:`1/e`) gives :math:`n_e = 0`: no bound, with a note.
    4. **Bounds** at ``confidence``: :func:`~overbound.stats.parametric.ratio_bound` (normal:
       Bonferroni over mean and sigma; Rayleigh: chi-square) and
       :func:`~overbound.stats.parametric.weibull_bound` (Wald ellipse of :math:`(\ln a, b)` at each
       AL, of radius Student's :math:`t_c(n_e - 2)`: on a campaign of few PL decorrelation times the
       normal radius left 9 % of the bounds below the truth, validation/parametric_coverage.py). The ratio
       bounds need :math:`n_e \ge 2` (normal: :math:`> 2`), the Weibull bound :math:`n_e > 2`; the
       figure's pointwise density band keeps the normal quantile (a picture, not a bound).
    5. **Availability** (2.1.2): :math:`S(AL)` of the Weibull ML fit (:math:`PL \ge AL` is
       unavailable), beside the count of :mod:`overbound.methods.counting` (all rows; no solution
       and alerts unavailable) and the count over the fitted epochs.
    6. **Integrity** (2.1.3): :func:`~overbound.stats.parametric.integrity_probabilities` at the
       fits and at the bound parameters (ratio bound, Weibull bound at that AL).
    7. **Continuity** (2.1.4): per station, on its own grid, the count of
       :func:`~overbound.stats.continuity.noncontinuity_curve` over the observed PL range
       (:func:`~overbound.stats.continuity.alert_limit_grid`, 400 points) plus each service's AL, for
       each window used by a service (15 s; NPA 3600 s), with alerts and rows without a solution
       unavailable, then summed over stations. Log-linear fits :math:`\log_{10}P = a + b\,AL` of the
       risk and of its Clopper-Pearson bound over the observed PL range and within
       :data:`CONTINUITY_HALF_WIDTH_M` of each AL (the paper uses +/-10 m for APV-I and +/-5 m for
       the others; +/-10 m for all here).
    8. A service without an alert limit on the axis (NPA in the vertical) is ``None``.
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    tau = _decorrelation(decorrelation)
    svcs = _services(services)
    missing = [c for c in ("time", "station") if c not in table.columns]
    if missing:
        raise InputError("<epoch table>", f"the parametric analysis needs column(s) {', '.join(missing)}")
    rows = _rows(table)
    results: dict[str, AxisParametric | None] = {}
    reasons: dict[str, str] = {}
    for axis in AXES:
        try:
            results[axis] = _axis(table, rows, axis, svcs, tau, float(confidence))
        except (InputError, ValueError) as exc:
            results[axis] = None
            reasons[axis] = _reason(exc)
    return ParametricAnalysis(
        results["vertical"], results["horizontal"], reasons, svcs, float(confidence), tau, table.height
    )


def _reason(exc: Exception) -> str:
    text = str(exc)
    return text.split(": ", 1)[1] if isinstance(exc, InputError) and ": " in text else text


# --------------------------------------------------------------------------------------------------
# JSON


def _fit_dict(f: LogLinearFit | None) -> dict | None:
    if f is None:
        return None
    return {"a": f.a, "b": f.b, "al_min": f.al_min, "al_max": f.al_max, "n_points": f.n_points}


def _ratio_dict(f: RatioFit | None) -> dict | None:
    return None if f is None else {"distribution": f.distribution, "mean": f.mean, "sigma": f.sigma}


def _service_dict(s: ServiceParametric | None) -> dict | None:
    if s is None:
        return None
    out = {k: getattr(s, k) for k in SERVICE_KEYS | SERVICE_EXTRA_KEYS if k not in _SERVICE_OBJECTS}
    out["continuity_local_fit"] = _fit_dict(s.continuity_local_fit)
    out["continuity_local_fit_bound"] = _fit_dict(s.continuity_local_fit_bound)
    out["weibull_bound"] = (
        None if s.weibull_bound is None else {"a": s.weibull_bound.a, "b": s.weibull_bound.b}
    )
    out["reason"] = s.reason or None
    return out


_SERVICE_OBJECTS = frozenset(
    {"continuity_local_fit", "continuity_local_fit_bound", "weibull_bound", "reason"}
)


def _axis_dict(a: AxisParametric) -> dict:
    return {
        "ratio_fit": _ratio_dict(a.ratio_fit),
        "decorrelation_s": a.decorrelation_s,
        "n_effective": a.n_effective,
        "p_mi": a.p_mi,
        "p_mi_bound": a.p_mi_bound,
        "weibull": {"a": a.weibull.a, "b": a.weibull.b},
        "services": {name: _service_dict(s) for name, s in a.services.items()},
        "n_epochs": a.n_epochs,
        "n_alert": a.n_alert,
        "n_stations": a.n_stations,
        "interval_s": a.interval_s,
        "pl_decorrelation_s": a.pl_decorrelation_s,
        "pl_n_effective": a.pl_n_effective,
        "log10_p_mi": a.log10_p_mi,
        "log10_p_mi_bound": a.log10_p_mi_bound,
        "ratio_bound_fit": _ratio_dict(a.ratio_bound_fit),
        "weibull_converged": a.weibull.converged,
        "pl_range": list(a.pl_range),
        "continuity": [
            {
                "window_s": w,
                "n_alert_limits": int(a.continuity_curves[w].alert_limit.size),
                "fit": _fit_dict(a.continuity_fits[w]),
                "fit_bound": _fit_dict(a.continuity_fits_bound[w]),
            }
            for w in sorted(a.continuity_curves)
        ],
        "notes": list(a.notes),
    }


def parametric_dict(analysis: ParametricAnalysis) -> dict:
    r"""The ``overbound.parametric/1`` document.

    Keys of the issue (:data:`TOP_KEYS`, :data:`AXIS_KEYS` per axis, :data:`SERVICE_KEYS` per
    service) and these extras (:data:`TOP_EXTRA_KEYS`, :data:`AXIS_EXTRA_KEYS`,
    :data:`SERVICE_EXTRA_KEYS`):

    * top: ``confidence``; ``decorrelation`` (``"auto"`` or the seconds given);
      ``decorrelation_rule`` (``"1/e"`` or ``"given"``); ``continuity_half_width_m`` (10);
      ``epochs`` (``rows``); ``reasons`` (axis -> why it is null).
    * per axis: ``n_epochs``, ``n_alert``, ``n_stations``, ``interval_s``; ``pl_decorrelation_s`` and
      ``pl_n_effective`` (the PL's, for the Weibull bound; ``decorrelation_s`` and ``n_effective``
      are the ratio's); ``log10_p_mi``, ``log10_p_mi_bound`` (finite where ``p_mi`` underflows to 0);
      ``ratio_bound_fit`` (the parameters ``p_mi_bound`` is computed at); ``weibull_converged``;
      ``pl_range``; ``continuity``: per window the global log-linear fits ``{a, b, al_min, al_max,
      n_points}`` of the risk and of its bound; ``notes``.
    * per service (``null`` when the service has no alert limit on the axis: NPA in the vertical):
      ``alert_limit``; ``continuity_window_s`` (the continuity keys are per that window, 15 s for
      approaches, 3600 s for NPA; every other probability is per epoch); ``continuity_fit_source``
      (``"local"``: the fit within +/-10 m of AL, ``"global"``: over the observed PL range);
      ``continuity_local_fit(_bound)``; ``continuity_n_windows``, ``continuity_n_fail``,
      ``continuity_n_events``; ``n_available_counted``; ``unavailability_counted_fitted`` (over the
      fitted epochs); ``weibull_bound`` ``{a, b}``; ``p_mi_pl_above_al_bound``,
      ``p_mi_pl_below_al_bound``; ``log10_*`` of the fitted and bound probabilities; ``reason``.

    ``unavailability_counted`` is :mod:`overbound.methods.counting`'s (all rows; no solution and
    alerts count as unavailable). Floats have 12 significant digits; NaN and infinities are null.
    """
    a = analysis
    return {
        "schema": SCHEMA,
        "vertical": None if a.vertical is None else _axis_dict(a.vertical),
        "horizontal": None if a.horizontal is None else _axis_dict(a.horizontal),
        "confidence": a.confidence,
        "decorrelation": a.decorrelation,
        "decorrelation_rule": DECORRELATION_RULE if a.decorrelation == "auto" else "given",
        "continuity_half_width_m": CONTINUITY_HALF_WIDTH_M,
        "epochs": {"rows": a.n_rows},
        "reasons": dict(a.reasons),
    }


def write_parametric(analysis: ParametricAnalysis, path: str | Path) -> str:
    """Write :func:`parametric_dict` as deterministic JSON (``report.json.dumps``); return the text."""
    from overbound.jsontext import dumps

    text = dumps(parametric_dict(analysis))
    Path(path).write_text(text, encoding="utf-8")
    return text
