r"""Misleading-information probability by extreme value theory (Veerman et al., GIMAT).

A campaign almost never shows a misleading-information (MI) event, so the probability that the
safety index :math:`SI = |PE|/PL` exceeds 1 is extrapolated from the tail of its distribution: a
generalised Pareto distribution (GPD) fitted to the cluster maxima above a threshold, times the
exceedance rate, with bootstrap and profile-likelihood confidence intervals; a GEV on daily block
maxima as the second model; the KRS core test and the bootstrap tail-overbounding probability of the
normalised error; and, per service level, the HMI probability of the HMI-filtered data.

Columns needed: ``time``, ``station``, ``vpe`` and ``vpl`` (vertical) or ``hpe`` and ``hpl``
(horizontal). Optional ``alert``.

Validation on the simulator (``validation/evt_coverage.py``, results in ``validation/results/``):
coverage of the P_MI interval and conservativeness of P_MI95 over 200 seeded campaigns.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import polars as pl

from overbound.io.schema import InputError
from overbound.jsontext import dumps
from overbound.methods.pooling import PE_PL, pool_epochs
from overbound.methods.tail_partitions import (
    ACF_MAX_LAG_S,
    DEPENDENCE_QUANTILE,
    SI_LEVELS,
    Block,
    Filter,
    TailData,
    hmi_keep,
    krs_spacing,
    table_tail_data,
)
from overbound.services import K_H_PA, K_V_PA, SERVICES, ServiceLevel, parse_service
from overbound.stats.bootstrap import (
    bca_ci,
    bootstrap_gev,
    bootstrap_gpd,
    jackknife_gpd,
    p_exceed_ci,
    percentile_ci,
)
from overbound.stats.dependence import (
    Clusters,
    cluster_gap,
    cluster_sizes,
    decluster_runs,
    extremal_index,
    one_over_e_time,
    vk_curve,
)
from overbound.stats.evt import GEVFit, GPDFit, fit_gev, fit_gpd, gpd_sf, profile_ci_exceedance
from overbound.stats.krs import KRSResult, TailOverbound, krs_test, tail_overbound_probability
from overbound.stats.threshold import (
    ShapeStability,
    ThresholdChoice,
    mean_excess,
    select_threshold,
    shape_stability,
)

__all__ = [
    "APPROACH_S",
    "DEPENDENCE_QUANTILE",
    "EVT_EXTRA_KEYS",
    "EVT_KEYS",
    "SCHEMA",
    "TOP_CLUSTERS",
    "ClusterSize",
    "Dependence",
    "EpochCounts",
    "GEVResult",
    "ServiceHMI",
    "TailAnalysis",
    "TailFit",
    "analysed_series",
    "evt_dict",
    "per_approach",
    "tail_analysis",
    "tail_analysis_of",
    "tail_filters",
    "write_evt",
]

SCHEMA = "overbound.evt/1"
#: Exposure of one approach (s): the integrity requirement 2e-7 is per approach of 150 s.
APPROACH_S = 150.0
# DEPENDENCE_QUANTILE (the quantile of SI that defines the dependence level u_0 when the threshold is
# chosen automatically) and ACF_MAX_LAG_S (the largest ACF lag) are tail_partitions' (its passes use them)
#: Candidate thresholds: ``N_CANDIDATES`` cluster maxima at :math:`u_0` that leave ``MAX_TAIL`` down to
#: ``MIN_TAIL`` cluster maxima above them (geometric steps), kept below 1.
N_CANDIDATES = 20
MIN_TAIL = 30
MAX_TAIL = 500
#: Clusters above the level at which the cluster size near SI = 1 is measured (:class:`ClusterSize`).
TOP_CLUSTERS = 30
#: Fewest block maxima for the GEV bootstrap (below, its optimiser is unstable and the bound meaningless).
GEV_MIN_BOOT_BLOCKS = 10
#: Lower end of the KRS core range in normalised-error units (small L carry no information).
KRS_L_MIN = 0.5

_K = {"vertical": K_V_PA, "horizontal": K_H_PA}

#: JSON keys of the issue (top level, ``schema`` included).
EVT_KEYS = frozenset(
    {
        "schema",
        "threshold",
        "n_exceedances",
        "cluster_gap_s",
        "n_clusters",
        "extremal_index",
        "gpd",
        "p_mi",
        "p_mi_ci",
        "p_mi_95",
        "p_mi_per_approach",
        "p_mi_per_approach_95",
        "gev",
        "krs",
        "tail_overbound_probability",
        "services",
    }
)
#: Extra top-level keys written besides :data:`EVT_KEYS`.
EVT_EXTRA_KEYS = frozenset(
    {
        "axis",
        "service",
        "confidence",
        "n_boot",
        "seed",
        "decluster",
        "epochs",
        "message",
        "threshold_method",
        "p_mi_profile_ci",
        "p_mi_ci_bootstrap",
        "p_mi_ci_bca",
        "cluster_size",
    }
)


# --------------------------------------------------------------------------------------------------
# results


@dataclass(frozen=True, slots=True)
class EpochCounts:
    """Epochs of the table and what happened to them.

    Attributes
    ----------
    n_rows : rows of the table.
    n_no_solution : rows without a finite error and PL > 0.
    n_alert : solution epochs flagged ``alert`` (excluded).
    n_pl_above_al : solution epochs with PL >= AL of the filtering service (0 without one).
    n_tta : further epochs dropped in the TTA seconds before an alert (0 without a service).
    n_used : epochs analysed.
    n_stations : stations in the analysed epochs.
    interval_s : nominal epoch interval (s).
    """

    n_rows: int
    n_no_solution: int
    n_alert: int
    n_pl_above_al: int
    n_tta: int
    n_used: int
    n_stations: int
    interval_s: float


@dataclass(frozen=True, slots=True)
class Dependence:
    """Dependence of the analysed series (Veerman et al., section 3.2).

    Attributes
    ----------
    acf_lags_s, acf : autocorrelation of the SI series on its regular grid.
    decorrelation_s : first lag where the ACF drops below 1/e (s).
    level : dependence level :math:`u_0` whose exceedances give the V_K curve.
    vk_k_s, vk_v, vk_poisson : the V_K curve, and its expectation for Poisson exceedance times.
    cluster_gap_s : K_T used (read from the curve or given).
    cluster_gap_auto : whether K_T was read from the curve.
    """

    acf_lags_s: np.ndarray = field(repr=False)
    acf: np.ndarray = field(repr=False)
    decorrelation_s: float
    level: float
    vk_k_s: np.ndarray = field(repr=False)
    vk_v: np.ndarray = field(repr=False)
    vk_poisson: np.ndarray = field(repr=False)
    cluster_gap_s: float
    cluster_gap_auto: bool


@dataclass(frozen=True, slots=True)
class ClusterSize:
    r"""Mean cluster size near the target level 1, which turns the cluster rate into a per-epoch probability.

    Attributes
    ----------
    level : the level :math:`v^* = \min(1, \text{the } (m+1)\text{-th largest cluster maximum})`,
        :math:`m` = :data:`TOP_CLUSTERS`, never below the threshold :math:`u`.
    sizes : exceedances of :math:`v^*` in each cluster whose maximum exceeds :math:`v^*`.
    mean : their mean :math:`\hat s = \hat s(v^*)`.
    at_threshold : the mean cluster size at :math:`u`, :math:`n_u / n_c`, for comparison.
    """

    level: float
    sizes: np.ndarray = field(repr=False)
    mean: float
    at_threshold: float

    def bootstrap(self, n_boot: int, rng: np.random.Generator) -> np.ndarray:
        r"""``n_boot`` resampled means: :math:`K^* \sim \mathrm{Poisson}(m)` sizes drawn from ``sizes``."""
        m = self.sizes.size
        k = np.maximum(rng.poisson(m, size=n_boot), 1)
        draws = self.sizes[rng.integers(0, m, size=(n_boot, int(k.max())))]
        draws = np.where(np.arange(draws.shape[1]) < k[:, None], draws, 0)
        return draws.sum(axis=1) / k


def _size_near_one(t_s: np.ndarray, x: np.ndarray, clusters: Clusters, u: float) -> ClusterSize:
    """:class:`ClusterSize` for the clusters (formed at or below ``u``) of the series ``x``."""
    peaks = np.sort(clusters.peak_value)
    v = float(peaks[-TOP_CLUSTERS - 1]) if peaks.size > TOP_CLUSTERS else u
    v = min(max(v, u), 1.0)
    sizes = cluster_sizes(t_s, x, clusters, v)
    if sizes.size == 0:  # no cluster above v (v = 1 with every peak at or below 1): size 1
        sizes = np.ones(1, dtype=np.int64)
    n_c = np.count_nonzero(peaks > u)
    at_u = np.count_nonzero(x > u) / n_c if n_c else math.nan
    return ClusterSize(v, sizes, float(sizes.mean()), float(at_u))


@dataclass(frozen=True, slots=True)
class TailFit:
    r"""The GPD tail extrapolation of one variable to 1 (SI for MI, PE/AL for HMI).

    Attributes
    ----------
    variable : ``"SI"``.
    n_total : epochs of the series :math:`N`.
    threshold : the threshold :math:`u` used.
    threshold_choice : the automatic choice (``None`` when the threshold was given).
    candidates : the threshold grid of the diagnostics.
    mean_excess : mean excess of the GPD sample over each candidate.
    stability : GPD shape and its profile interval per candidate.
    p_vs_threshold : :math:`P(>1)` per epoch estimated at each candidate threshold.
    clusters : runs declustering (gap K_T) of the exceedances of the clustering level.
    cluster_level : the level of ``clusters`` (:math:`u_0 \le u`).
    decluster : GPD fitted to cluster maxima (True) or to all exceedances (False).
    n_exceedances : values above :math:`u` (all epochs).
    n_clusters : clusters whose maximum exceeds :math:`u`.
    extremal_index : Ferro-Segers intervals estimate at :math:`u`.
    gpd : the GPD fit.
    shape_ci : profile-likelihood interval of the shape.
    shape_ci_bootstrap : percentile bootstrap interval of the shape.
    zeta : exceedance rate per epoch :math:`n_u/N`.
    p : :math:`\hat P(>1)` per epoch; ``p_ci`` the union of its bootstrap percentile interval
        (``p_ci_bootstrap``), its BCa interval (``p_ci_bca``, declustered fits only) and its
        profile-likelihood interval (``p_profile_ci``); ``p_95`` the upper end of ``p_ci``.
    cluster_rate : rate per epoch of clusters whose maximum exceeds 1 (MI events).
    cluster_size : mean cluster size near 1 (:class:`ClusterSize`).
    p_approach, p_approach_ci, p_approach_95 : the same per approach (:func:`per_approach`, increasing
        in ``p``: the interval and bound are those of ``p`` mapped through it).
    samples, samples_approach : bootstrap values of ``p`` and ``p_approach``.
    message : plain statement of anything special (finite endpoint, non-regular shape...).
    """

    variable: str
    n_total: int
    threshold: float
    threshold_choice: ThresholdChoice | None
    candidates: np.ndarray = field(repr=False)
    mean_excess: np.ndarray = field(repr=False)
    stability: ShapeStability | None = field(repr=False)
    p_vs_threshold: np.ndarray = field(repr=False)
    clusters: Clusters = field(repr=False)
    cluster_level: float = math.nan
    decluster: bool = True
    n_exceedances: int = 0
    n_clusters: int = 0
    extremal_index: float = math.nan
    gpd: GPDFit | None = None
    shape_ci: tuple[float, float] = (math.nan, math.nan)
    shape_ci_bootstrap: tuple[float, float] = (math.nan, math.nan)
    zeta: float = math.nan
    p: float = math.nan
    p_ci: tuple[float, float] = (math.nan, math.nan)
    p_95: float = math.nan
    p_ci_bootstrap: tuple[float, float] = (math.nan, math.nan)
    p_profile_ci: tuple[float, float] = (math.nan, math.nan)
    p_ci_bca: tuple[float, float] = (math.nan, math.nan)
    cluster_rate: float = math.nan
    cluster_size: ClusterSize | None = None
    p_approach: float = math.nan
    p_approach_ci: tuple[float, float] = (math.nan, math.nan)
    p_approach_95: float = math.nan
    samples: np.ndarray = field(default_factory=lambda: np.empty(0), repr=False)
    samples_approach: np.ndarray = field(default_factory=lambda: np.empty(0), repr=False)
    message: str = ""


@dataclass(frozen=True, slots=True)
class GEVResult:
    r"""GEV on block maxima (Veerman et al., section 4), the second model.

    Attributes
    ----------
    fit : the GEV fit (``None`` with fewer than 3 blocks).
    block_maxima : SI maximum per station and GPS day (blocks with at least half the median count).
    epochs_per_block : median epochs per block :math:`n_b`.
    p_block : :math:`P(\max > 1)` per block.
    p_mi : per epoch, :math:`-\log(1 - p_{block}) / (n_b\,\theta)`.
    p_mi_95 : bootstrap upper bound of ``p_mi``.
    n_boot : resamples used.
    message : what happened.
    """

    fit: GEVFit | None
    block_maxima: np.ndarray = field(repr=False)
    epochs_per_block: float
    p_block: float
    p_mi: float
    p_mi_95: float
    n_boot: int
    message: str


@dataclass(frozen=True, slots=True)
class ServiceHMI:
    r"""HMI probability for one service level (Veerman et al., section 3.6).

    Attributes
    ----------
    service : the level.
    alert_limit : AL of the axis (m).
    counts : epochs after the HMI filtering (PL < AL, TTA before alerts dropped).
    tail : the tail extrapolation of SI to 1 on the filtered epochs (``None`` when it could not be made).
    p_hmi, p_hmi_95 : per epoch, and its bootstrap upper bound.
    exposure_s : the exposure of the requirement (150 s approach, 3600 s NPA).
    p_hmi_exposure, p_hmi_exposure_95 : per exposure (:func:`per_approach` with ``exposure_s``).
    integrity_risk : the requirement.
    meets_requirement : ``p_hmi_exposure_95 <= integrity_risk`` (``None`` if not computed).
    message : what happened.
    """

    service: ServiceLevel
    alert_limit: float
    counts: EpochCounts
    tail: TailFit | None = field(repr=False)
    p_hmi: float
    p_hmi_95: float
    exposure_s: float
    p_hmi_exposure: float
    p_hmi_exposure_95: float
    integrity_risk: float
    meets_requirement: bool | None
    message: str


@dataclass(frozen=True, slots=True)
class TailAnalysis:
    r"""Result of :func:`tail_analysis`: every intermediate of the EVT procedure.

    Attributes
    ----------
    axis : ``vertical`` or ``horizontal``.
    service : name of the HMI-filtering service, or ``None``.
    confidence, n_boot, seed, decluster : the options used.
    counts : :class:`EpochCounts`.
    si_quantiles : SI at the levels ``si_levels``; ``si_max``; ``n_mi`` epochs with SI > 1 observed.
    dependence : :class:`Dependence` (ACF, decorrelation time, V_K curve, cluster gap).
    tail : :class:`TailFit` of the SI: threshold diagnostics, clusters, GPD, P_MI and intervals.
    gev : :class:`GEVResult`.
    krs : KRS core test of :math:`L = |PE|/(PL/K)` (``None`` if not computable).
    tail_overbound : bootstrap tail-overbounding probability (``None`` if not computable).
    services : :class:`ServiceHMI` per service with an alert limit on the axis.
    timings : seconds per step (not written to JSON).
    message : the plain statements of the MI result.
    """

    axis: str
    service: str | None
    confidence: float
    n_boot: int
    seed: int | None
    decluster: bool
    counts: EpochCounts
    si_levels: np.ndarray = field(repr=False)
    si_quantiles: np.ndarray = field(repr=False)
    si_max: float = math.nan
    n_mi: int = 0
    dependence: Dependence | None = None
    tail: TailFit | None = None
    gev: GEVResult | None = None
    krs: KRSResult | None = None
    tail_overbound: TailOverbound | None = None
    services: dict[str, ServiceHMI] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict, compare=False)
    message: str = ""

    @property
    def p_mi(self) -> float:
        """P_MI per epoch."""
        return self.tail.p if self.tail else math.nan


# --------------------------------------------------------------------------------------------------
# helpers


def per_approach(
    p_epoch: np.ndarray | float, cluster_rate: np.ndarray | float, n_epochs: float
) -> np.ndarray:
    r"""Probability of at least one MI epoch in an exposure of ``n_epochs`` epochs.

    Parameters
    ----------
    p_epoch
        Probability that one epoch is MI, :math:`p`.
    cluster_rate
        Rate per epoch of independent MI clusters (events), :math:`r \le p`.
    n_epochs
        Epochs in the exposure :math:`n` (150 s at 1 Hz: 150).

    Returns
    -------
    numpy.ndarray
        :math:`1 - (1 - p)\,e^{-(n-1) r}`.

    Notes
    -----
    The first epoch of the exposure is MI with probability :math:`p`; otherwise an MI event must
    *start* within the :math:`n - 1` further epochs. Assumptions: clusters are the independent units
    (the premise of declustering, Veerman et al. section 3.2), so event starts form a Poisson process
    of rate :math:`r` per epoch, independent of the state at the first epoch; stationarity over the
    exposure. Limits: independent epochs (:math:`r = p`) give :math:`1-(1-p)e^{-(n-1)p} \approx 1 -
    (1-p)^n`; fully persistent errors (:math:`r \to 0`) give :math:`p`. Computed with ``expm1``.

    Examples
    --------
    >>> float(per_approach(1e-6, 0.0, 150))
    1e-06
    """
    p = np.asarray(p_epoch, dtype=float)
    r = np.asarray(cluster_rate, dtype=float)
    return -np.expm1(np.log1p(-p) - (n_epochs - 1.0) * r)


def _rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


def analysed_series(
    table: pl.DataFrame, *, axis: str = "vertical", service: str | ServiceLevel | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Times (s, on the pooled axis of several stations) and SI of the epochs :func:`tail_analysis` analyses.

    Its Notes step 1: solution epochs, alerts excluded, with ``service`` the PL >= AL and TTA filter.
    """
    svc = parse_service(service) if isinstance(service, str) else service
    d = pool_epochs(table, axis)
    al = svc.alert_limit(axis) if svc is not None else None
    block = Block(d.t_us, d.pe, d.pl, d.alert, d.n_rows)
    keep = hmi_keep(block, (al, svc.tta_s if svc is not None else 0.0), None)[0]
    return d.t_us[keep] / 1e6, d.pe[keep] / d.pl[keep]


def _counts(d: TailData, counts: tuple[int, int, int, int]) -> EpochCounts:
    n_alert, n_above, n_tta, n_used = counts
    return EpochCounts(d.n_rows, d.n_no_solution, n_alert, n_above, n_tta, n_used, d.n_stations, d.interval_s)


def _dependence(
    te: np.ndarray, acf: np.ndarray, interval_s: float, level: float, gap: float | str
) -> Dependence:
    """Step 2 from the ACF of the series and the times ``te`` (s) of its exceedances of ``level``."""
    decor = one_over_e_time(acf, interval_s)
    span = max(10.0 * (decor if math.isfinite(decor) else ACF_MAX_LAG_S), 60.0 * interval_s)
    k = np.linspace(0.0, span, 121)
    curve = vk_curve(te, k_values=k)
    if gap == "auto":
        kt = cluster_gap(curve)
        kt = float(kt) if math.isfinite(kt) else float(interval_s)
        auto = True
    else:
        kt, auto = float(gap), False
        if not (math.isfinite(kt) and kt >= 0):
            raise ValueError(f"cluster_gap must be 'auto' or a finite number >= 0, got {gap!r}")
    return Dependence(
        np.arange(acf.size) * interval_s,
        acf,
        decor,
        float(level),
        curve.k,
        curve.v,
        curve.poisson(),
        kt,
        auto,
    )


# --------------------------------------------------------------------------------------------------
# the tail extrapolation of one variable


def _tail_fit(
    t_s: np.ndarray,
    x: np.ndarray,
    *,
    n_total: int,
    level: float,
    positions: np.ndarray,
    variable: str,
    interval_s: float,
    gap_s: float,
    threshold: float | str,
    decluster: bool,
    n_boot: int,
    confidence: float,
    exposure_n: float,
    rng: np.random.Generator,
    n_sim: int,
    diagnostics: bool = True,
) -> TailFit:
    """Steps 3-6 of :func:`tail_analysis` for one series of ``n_total`` epochs, given by its
    exceedances of ``level`` (:math:`u_0`): their times ``t_s`` (sorted), values ``x`` and positions
    in the series. Every statistic of these steps depends on the exceedances of :math:`u_0` and
    the series' length only. ``threshold``: ``"auto"`` or the given one (then ``level``)."""
    g_sel, g_boot, g_rate = rng.spawn(3)
    up = x > level
    t_s, x, positions = t_s[up], x[up], positions[up]
    n = n_total
    auto = threshold == "auto"
    if not auto and not (math.isfinite(level) and level < 1.0):
        raise ValueError(f"threshold must be 'auto' or a number below 1, got {threshold!r}")
    clusters = decluster_runs(t_s, x, threshold=level, run_length=gap_s)
    pool = clusters.peak_value if decluster else x
    # candidate grid: thresholds leaving MAX_TAIL down to MIN_TAIL cluster maxima above, below 1
    peaks = np.sort(clusters.peak_value)
    if peaks.size > MIN_TAIL:
        above_k = np.unique(np.geomspace(min(peaks.size - 1, MAX_TAIL), MIN_TAIL, N_CANDIDATES).round())
        cands = np.unique(peaks[peaks.size - above_k.astype(np.int64) - 1])
        cands = cands[cands < 1.0]
    else:
        cands = np.empty(0)
    choice = None
    msgs: list[str] = []
    if auto:
        if cands.size == 0:
            raise ValueError(
                f"{variable}: too few tail values for an automatic threshold ({pool.size} "
                f"{'cluster maxima' if decluster else 'exceedances'} above the "
                f"{DEPENDENCE_QUANTILE} quantile)"
            )
        choice = select_threshold(pool, candidates=cands, rng=g_sel, n_sim=n_sim)
        if math.isfinite(choice.threshold):
            u = choice.threshold
        else:
            u = float(cands[-1])
            msgs.append(f"every candidate threshold rejected by the GOF test; the highest, {u:.6g}, is used")
    else:
        u = level
    above = pool > u
    sample = pool[above]
    n_exc = int(np.count_nonzero(x > u))
    n_c = int(np.count_nonzero(clusters.peak_value > u))
    if sample.size < 3:
        raise ValueError(f"{variable}: only {sample.size} tail values above the threshold {u:.6g}; need 3")
    # diagnostics over the candidate grid
    if diagnostics and cands.size:
        me = mean_excess(pool, cands)
        stab = shape_stability(pool, cands, level=confidence)
        pvt = np.full(cands.size, np.nan)
        for j, uj in enumerate(cands):  # a loop over ~20 candidate thresholds
            fj = fit_gpd(pool[pool > uj], threshold=uj)
            if decluster:
                sj = _size_near_one(t_s, x, clusters, float(uj)).mean
                pvt[j] = np.count_nonzero(clusters.peak_value > uj) / n * float(fj.sf(1.0)) * sj
            else:
                pvt[j] = np.count_nonzero(x > uj) / n * float(fj.sf(1.0))
    else:
        me, stab, pvt = np.empty(0), None, np.empty(0)
    fit = fit_gpd(sample, threshold=u)
    theta = extremal_index(t_s, x, threshold=u, interval_s=interval_s)
    zeta = n_exc / n
    gbar = float(fit.sf(1.0))
    size = _size_near_one(t_s, x, clusters, u)
    # the rate of the independent units (cluster maxima, or exceedances) whose law the GPD is
    unit_rate = n_c / n if decluster else zeta
    p = unit_rate * gbar * (size.mean if decluster else 1.0)
    rate = p / size.mean
    p_app = float(per_approach(p, rate, exposure_n))
    if not fit.regular:
        msgs.append(f"shape {fit.xi:.3g} < -0.5: non-regular (the MLE asymptotics do not hold)")
    if not fit.success:
        msgs.append(fit.message)
    if fit.xi < 0 and fit.endpoint <= 1.0:
        msgs.append(
            f"the fitted tail has a finite endpoint {fit.endpoint:.6g} below {variable} = 1: "
            f"P = 0 is the estimate (a valid answer, not a failure)"
        )
    try:
        shape_ci = fit.profile_ci(confidence) if fit.success else (math.nan, math.nan)
    except (ValueError, RuntimeError):
        shape_ci = (math.nan, math.nan)
    try:
        factor = unit_rate * (size.mean if decluster else 1.0)
        lo, hi = profile_ci_exceedance(fit, 1.0, level=confidence)
        p_prof = (factor * lo, factor * hi)
    except (ValueError, RuntimeError):
        p_prof = (math.nan, math.nan)
    # bootstrap
    y = sample - u
    g_size, g_rate = g_rate.spawn(2)
    size_star = size.bootstrap(n_boot, g_size)
    if decluster:
        # the clusters are resampled once for both the GPD and the size near 1 (they covary)
        top = clusters.peak_value[above] > size.level
        own = np.zeros(top.size)
        own[top] = cluster_sizes(t_s, x, clusters, size.level)  # level >= u: all of them are above u
        boot = bootstrap_gpd(y, n_boot=n_boot, rng=g_boot, paired=np.vstack([own, top]))
        n_top = boot.paired_sums[:, 1]
        size_star = np.where(n_top > 0, boot.paired_sums[:, 0] / np.maximum(n_top, 1), size.mean)
        k_star = g_rate.poisson(n_c, size=n_boot)
        gb = gpd_sf(1.0 - u, xi=boot.xi, sigma=boot.sigma)
        samples = k_star / n * gb * size_star
        p_bca = bca_ci(samples, p, _jackknife_p(y, u, own, top, n_c, n, size.mean), confidence)
    else:
        idx = positions[x > u]
        mb_exc = max(1.0, n_exc / max(n_c, 1))
        boot = bootstrap_gpd(y, n_boot=n_boot, rng=g_boot, method="stationary", mean_block=mb_exc)
        mb = max(n ** (1.0 / 3.0), 2.0 * gap_s / interval_s, 1.0)
        ci = p_exceed_ci(
            boot, x_excess=1.0 - u, n_total=n, level=confidence, rng=g_rate, positions=idx, mean_block=mb
        )
        samples = ci.samples
        p_bca = (math.nan, math.nan)
    rates = samples / size_star
    samples_app = per_approach(samples, rates, exposure_n)
    p_ci_boot = percentile_ci(samples, confidence)
    p_ci = _union(_union(p_ci_boot, p_bca), p_prof)
    app_ci = per_approach(np.array(p_ci), np.array(p_ci) / size.mean, exposure_n)
    msgs_s = "; ".join(msgs)
    return TailFit(
        variable=variable,
        n_total=n,
        threshold=float(u),
        threshold_choice=choice,
        candidates=cands,
        mean_excess=me,
        stability=stab,
        p_vs_threshold=pvt,
        clusters=dataclasses.replace(clusters, peak_index=positions[clusters.peak_index]),
        cluster_level=level,
        decluster=decluster,
        n_exceedances=n_exc,
        n_clusters=n_c,
        extremal_index=float(theta),
        gpd=fit,
        shape_ci=(float(shape_ci[0]), float(shape_ci[1])),
        shape_ci_bootstrap=percentile_ci(boot.xi, confidence),
        zeta=zeta,
        p=p,
        p_ci=p_ci,
        p_95=p_ci[1],
        p_ci_bootstrap=p_ci_boot,
        p_profile_ci=p_prof,
        p_ci_bca=p_bca,
        cluster_rate=rate,
        cluster_size=size,
        p_approach=p_app,
        p_approach_ci=(float(app_ci[0]), float(app_ci[1])),
        p_approach_95=float(app_ci[1]),
        samples=samples,
        samples_approach=samples_app,
        message=msgs_s,
    )


def _jackknife_p(
    y: np.ndarray, u: float, own: np.ndarray, top: np.ndarray, n_c: int, n: int, size_mean: float
) -> np.ndarray:
    """Leave-one-cluster-out values of P_MI (GPD refit and cluster size near 1), for the BCa acceleration."""
    xi, sig = jackknife_gpd(y)
    n_top = top.sum() - top
    size_j = np.where(n_top > 0, (own.sum() - own) / np.maximum(n_top, 1), size_mean)
    return (n_c - 1) / n * gpd_sf(1.0 - u, xi=xi, sigma=sig) * size_j


def _union(a: tuple[float, float], b: tuple[float, float]) -> tuple[float, float]:
    """The smallest interval holding both (a NaN end of one is ignored)."""
    return float(np.nanmin([a[0], b[0]])), float(np.nanmax([a[1], b[1]]))


def _try_gev(x: np.ndarray) -> GEVFit | None:
    """``fit_gev`` or ``None`` when its optimiser fails (it can raise on degenerate resamples)."""
    try:
        f = fit_gev(x)
    except (ValueError, OverflowError, ZeroDivisionError):
        return None
    return f if f.success else None


def _gev(bm: np.ndarray, size: np.ndarray, theta: float, n_boot: int, confidence: float, rng) -> GEVResult:
    """Step 8 from the maximum ``bm`` and the number of analysed epochs ``size`` of each station-day."""
    nb = float(np.median(size))
    bm = bm[size >= 0.5 * nb]
    th = theta if math.isfinite(theta) and theta > 0 else 1.0
    if bm.size < 3 or np.ptp(bm) == 0:
        return GEVResult(None, bm, nb, math.nan, math.nan, math.nan, 0, f"{bm.size} block maxima: no GEV fit")
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        fit = _try_gev(bm)
    if fit is None:
        return GEVResult(None, bm, nb, math.nan, math.nan, math.nan, 0, "GEV fit failed")

    def per_epoch(pb: np.ndarray | float) -> np.ndarray:
        return -np.log1p(-np.minimum(pb, 1.0 - 1e-16)) / (nb * th)

    pb = float(fit.sf(1.0))
    if bm.size < GEV_MIN_BOOT_BLOCKS or n_boot == 0:
        msg = f"{bm.size} blocks: too few for a bootstrap (no upper bound)" if n_boot else fit.message
        return GEVResult(fit, bm, nb, pb, float(per_epoch(pb)), math.nan, 0, msg)
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        bs = bootstrap_gev(bm, n_boot=n_boot, rng=_rng(rng), start=fit)
    p95 = float(np.nanquantile(per_epoch(bs.sf(1.0)), confidence)) if bs.n_failed < n_boot else math.nan
    msg = fit.message + (
        f"; {bs.n_failed} of {n_boot} resamples without a maximum-likelihood fit, left out"
        if bs.n_failed
        else ""
    )
    return GEVResult(fit, bm, nb, pb, float(per_epoch(pb)), p95, n_boot, msg)


# --------------------------------------------------------------------------------------------------
# entry point


def tail_analysis(
    table: pl.DataFrame,
    *,
    axis: str = "vertical",
    service: str | ServiceLevel | None = None,
    threshold: float | str = "auto",
    cluster_gap: float | str = "auto",
    decluster: bool = True,
    n_boot: int = 1000,
    confidence: float = 0.95,
    rng: np.random.Generator | int | None = 0,
    services: tuple[str, ...] | None = None,
    n_sim: int = 200,
    gev_boot: int | None = None,
    diagnostics: bool = True,
) -> TailAnalysis:
    r"""Misleading-information probability by EVT tail extrapolation (Veerman et al., sections 2-3).

    Parameters
    ----------
    table
        The epoch table (several stations are analysed together, see Notes).
    axis
        ``vertical`` (SI = |VPE|/VPL) or ``horizontal`` (SI = HPE/HPL).
    service
        HMI-oriented filtering (section 3.6) by this service's alert limit and TTA; ``None``: none.
    threshold
        ``"auto"`` (Bader et al. 2018, :func:`~overbound.stats.threshold.select_threshold`) or a value
        of SI below 1.
    cluster_gap
        ``"auto"`` (read from the V_K curve, :func:`~overbound.stats.dependence.cluster_gap`) or K_T (s).
    decluster
        Fit the GPD to cluster maxima (True) or to all exceedances (False).
    n_boot
        Bootstrap resamples (1000, section 3.7).
    confidence
        Level of the intervals; the upper bounds ``*_95`` are the one-sided ``confidence`` quantiles.
    rng
        Seed or generator; the same seed gives the same result.
    services
        Service levels for the HMI results (names or ``NAME:HAL:VAL``); default the filtering
        ``service`` when given, otherwise every built-in level with an alert limit on ``axis``.
    n_sim
        Parametric-bootstrap samples per candidate of the automatic threshold.
    gev_boot
        Bootstrap resamples of the GEV (default ``n_boot``; all fitted at once, :func:`bootstrap_gev`).
    diagnostics
        Compute the per-candidate arrays (mean excess, shape stability, P_MI against threshold) for
        the figures; ``False`` skips them (coverage runs).

    Returns
    -------
    TailAnalysis

    Raises
    ------
    InputError
        A needed column is missing, or no epoch has a solution.
    ValueError
        Bad options; too few tail values for the fit.

    Notes
    -----
    1. **Variable.** :math:`SI = |PE|/PL` per epoch with a solution (finite error, PL > 0), epochs
       flagged ``alert`` excluded. With ``service`` (section 3.6): epochs with PL >= AL are dropped,
       and so are the epochs in the TTA seconds before each alert (an epoch with PL >= AL or flagged
       ``alert``): :math:`0 < t_{alert} - t \le TTA`. The counts are in :class:`EpochCounts`.
       Several stations are placed one after the other on one time axis (a day apart), so that no
       cluster spans two stations; daily blocks are per station and GPS day.
    2. **Dependence** (section 3.2). ACF of SI on its regular grid (NaN in gaps; the estimator of
       :func:`~overbound.stats.dependence.autocorrelation`, computed from the lagged sums of each
       station-day, :mod:`overbound.stats.lagged`, so that a campaign dataset read by partition
       gives the same bits), decorrelation time (first lag below :math:`1/e`); V_K curve of the
       exceedances of the dependence level
       :math:`u_0` (the :data:`DEPENDENCE_QUANTILE` quantile of SI, or the given threshold) on
       :math:`K \in [0, 10\,\tau_{dec}]`; K_T from the curve; runs declustering at :math:`u_0`
       with gap K_T; extremal index by Ferro & Segers at :math:`u`.
    3. **Threshold** (section 3.3). Candidates: :data:`N_CANDIDATES` cluster maxima (at :math:`u_0`)
       that leave from :data:`MAX_TAIL` down to :data:`MIN_TAIL` cluster maxima above them
       (geometric steps), below 1. Mean excess, shape stability (profile intervals) and
       :math:`P_{MI}` per candidate are kept for the figures. ``"auto"`` takes the lowest candidate
       not rejected by Anderson-Darling + ForwardStop (Bader et al. 2018). *Choice:* the grid is set
       by cluster counts, not by quantiles of the data, so that the threshold rises with the length of
       the campaign (:math:`k/n \to 0`, as the GPD limit needs): with a quantile grid the lowest
       candidates stayed at 2-3 sigma of a Gaussian error, whose penultimate shape (about
       :math:`-1/z^2`) the GOF test cannot reject and whose extrapolation to SI = 1 then fell short
       of the truth (validation). Clusters are formed once, at :math:`u_0 \le u`; the clusters at
       :math:`u` are those whose maximum exceeds :math:`u` (with a given threshold, :math:`u_0 = u`).
    4. **Fit.** GPD by maximum likelihood on the cluster maxima above :math:`u` (on all exceedances
       with ``decluster=False``); shape < -0.5 is flagged non-regular; a finite endpoint
       :math:`u - \sigma/\xi \le 1` gives :math:`P_{MI} = 0`, said in ``message``.
    5. **Probability per epoch** (section 3.5). Declustered:

       .. math:: P_{MI} = \underbrace{\frac{n_c}{N}\,\bar G_{\hat\xi,\hat\sigma}(1 - u)}_{r:\
                 \text{MI clusters per epoch}} \cdot \hat s, \qquad \text{all exceedances: }
                 P_{MI} = \zeta_u\,\bar G(1-u),\ \zeta_u = \frac{n_u}{N},

       :math:`n_c` clusters with maximum above :math:`u`, :math:`\hat s` the mean cluster size near
       1 (:class:`ClusterSize`: exceedances of :math:`v^*` per cluster above :math:`v^*`, the
       level with :data:`TOP_CLUSTERS` cluster maxima above, or 1). The identity is exact:
       the expected number of MI epochs is the number of MI clusters times their mean size.
       *Choice* (where the issue's :math:`\zeta_u\,\bar G` with :math:`\bar G` fitted to cluster
       maxima is ambiguous): :math:`\zeta_u = (n_c/N)\,s(u)` uses the cluster size at :math:`u`,
       and clusters shrink with the level where errors are Gaussian-like (asymptotic independence,
       Eastoe & Tawn 2012): on the simulator's AR(1) errors :math:`s(u) = 18` against
       :math:`s(1) = 8.9` (measured on 4e8 epochs), so :math:`\zeta_u\bar G` was 2-3 times the
       truth. :math:`\hat s = s(v^*)` with :math:`u \le v^* \le 1` is between the two, exact when
       the size no longer changes above :math:`v^*`, and conservative when it keeps shrinking.
    6. **Per approach.** :func:`per_approach` with :math:`p = P_{MI}`, the MI cluster rate
       :math:`r = P_{MI}/\hat s` and :math:`n = 150\,\mathrm{s}/\Delta t` epochs.
       *Choice:* the cluster-rate form, not :math:`1-(1-p)^{150/\text{spacing}}`: it needs no
       spacing, and it reduces to the independent case for :math:`r = p`. Assumptions: MI events
       (clusters) independent and stationary over the campaign, as in section 3.2.
    7. **Confidence** (section 3.7). Declustered: the GPD is bootstrapped on the cluster maxima (iid:
       clusters are the independent units), the number of clusters as
       :math:`K^* \sim \mathrm{Poisson}(n_c)`; the same draws of clusters give the GPD refit and the
       size :math:`\hat s^*` (mean size at :math:`v^*` of the drawn clusters above :math:`v^*`), so
       that their covariance enters the interval (a campaign whose clusters reach higher also has
       longer ones near 1: resampling them separately gave 0.86 coverage on 100 simulated 30-day
       campaigns, jointly 0.91); all exceedances: stationary bootstrap of the excesses (mean block = mean
       cluster size) and of the exceedance series (mean block :math:`\max(N^{1/3}, 2K_T/\Delta t)`).
       Profile-likelihood intervals of the shape and of :math:`\bar G(1-u)` (scaled like the
       estimate), and, declustered, the BCa interval (:func:`~overbound.stats.bootstrap.bca_ci`;
       acceleration from the leave-one-cluster-out jackknife of :math:`\hat P_{MI}`, GPD refit and
       :math:`\hat s` together). *Choice:* ``p_ci`` is the union of the percentile, BCa and profile
       intervals and ``p_95`` (:math:`P_{MI95}`) its upper end, the issue's "upper bound" of the
       interval. On 200 simulated 30-day campaigns (``validation/evt_coverage.py``) the percentile
       interval alone covered the truth in 0.92 and the percentile-profile union in 0.93 (misses
       one-sided: the truth above the interval, where the fitted shape is most negative, a bias the
       percentile bootstrap reproduces instead of correcting); the union with BCa, whose
       :math:`z_0` and acceleration move the upper end up exactly there, covered 0.95 with
       :math:`P_{MI95}` at or above the truth in 0.96.
    8. **GEV** (section 4) on daily maxima; per epoch
       :math:`-\log(1 - \bar H(1))/(n_b\theta)` (since :math:`H = F^{n_b\theta}`); bootstrap of
       the block maxima (``gev_boot`` resamples).
    9. **Overbounding** (section 3.5) of :math:`L = |PE|/(PL/K)` down-sampled to samples at least
       the decorrelation time apart (containing the largest): KRS on
       :math:`[0.5, uK]`, :math:`\alpha = 1 - ` ``confidence``; tail-overbounding probability
       with :math:`L_{Tail} = uK`.
    10. **HMI** (section 3.6) per service: the MI analysis (steps 4-7) of SI on the epochs with
        PL < AL, the TTA seconds before each alert (PL >= AL or ``alert``) dropped, with the
        threshold and K_T of the main analysis. Since HMI (PE > AL with PL < AL) implies MI with
        PL < AL, ``p_hmi`` bounds the HMI probability from above, as the paper intends. The exposure
        is the service's (150 s, 3600 s NPA); ``meets_requirement`` compares the upper bound per
        exposure with the service's integrity risk. *Choice:* the threshold is not chosen again per
        service (the filtered SI has the same tail unless the PL filter removes most epochs) - it
        would cost a GOF sequence per service.

    **Reduced input.** Every step reads only what
    :func:`~overbound.methods.tail_partitions.table_tail_data` reduces the table to (counts, SI
    quantiles, ACF, the epochs above :math:`u_0` with their times, daily maxima, the KRS selection),
    gathered station-day by station-day; :func:`tail_analysis_of` runs the steps on it, and a
    campaign dataset gives the same input by partition (:mod:`overbound.campaign_tail`).

    References
    ----------
    .. [1] Veerman et al., "A Tool for GNSS Integrity Verification Based on Statistical Extreme
       Value Theory", sections 2, 3.2-3.7, 4.
    .. [2] Coles, S. (2001), An Introduction to Statistical Modeling of Extreme Values, section 5.3.
    .. [3] Ferro, C. A. T., Segers, J. (2003), JRSS B 65(2), 545-556.
    .. [4] Eastoe, E. F., Tawn, J. A. (2012), Modelling the distribution of the cluster maxima of
       exceedances of subasymptotic thresholds, Biometrika 99(1), 43-55.
    .. [5] Bader, B., Yan, J., Zhang, X. (2018), Automated threshold selection for extreme value
       analysis via ordered goodness-of-fit tests, Annals of Applied Statistics 12(1), 310-329.
    """
    svc = parse_service(service) if isinstance(service, str) else service
    chosen = _chosen_services(svc, services, axis)
    filters = _filters(svc, chosen, axis)
    _check_options(confidence, n_boot, threshold)
    _check_columns(table, axis)
    if not _has_solution(table, axis):
        raise InputError("<epoch table>", "no epoch with a solution")
    level = None if threshold == "auto" else float(threshold)
    data = table_tail_data(table, axis, filters, level)
    return tail_analysis_of(
        data,
        axis=axis,
        service=svc,
        services=services,
        threshold=threshold,
        cluster_gap=cluster_gap,
        decluster=decluster,
        n_boot=n_boot,
        confidence=confidence,
        rng=rng,
        n_sim=n_sim,
        gev_boot=gev_boot,
        diagnostics=diagnostics,
    )


def _check_columns(table: pl.DataFrame, axis: str) -> None:
    """The axis is known and the table has its columns (as :func:`pool_epochs` checks them)."""
    if axis not in PE_PL:
        raise ValueError(f"axis must be 'vertical' or 'horizontal', got {axis!r}")
    missing = [c for c in ("time", "station", *PE_PL[axis]) if c not in table.columns]
    if missing:
        raise InputError("<epoch table>", f"the {axis} analysis needs column(s) {', '.join(missing)}")


def _has_solution(table: pl.DataFrame, axis: str) -> bool:
    pe, pl_ = (pl.col(c) for c in PE_PL[axis])
    ok = pe.is_finite() & pl_.is_finite() & (pl_ > 0)
    return bool(table.select(ok.any()).item()) if table.height else False


def _check_options(confidence: float, n_boot: int, threshold: float | str) -> None:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    if n_boot < 1:
        raise ValueError(f"n_boot must be >= 1, got {n_boot}")
    if threshold != "auto":
        u = float(threshold)
        if not (math.isfinite(u) and u < 1.0):
            raise ValueError(f"threshold must be 'auto' or a number below 1, got {threshold!r}")


def _chosen_services(
    svc: ServiceLevel | None, services: tuple[str, ...] | None, axis: str
) -> tuple[ServiceLevel, ...]:
    """The services of step 10: those given, else the filtering one, else every built-in level
    with an alert limit on ``axis``."""
    if svc is not None and svc.alert_limit(axis) is None:
        raise ValueError(f"service {svc.name} has no {axis} alert limit")
    if services is None:
        return (svc,) if svc is not None else tuple(s for s in SERVICES.values() if s.alert_limit(axis))
    return tuple(parse_service(s) for s in services)


def _filters(svc: ServiceLevel | None, chosen: tuple[ServiceLevel, ...], axis: str) -> tuple[Filter, ...]:
    """The HMI filters of the main series (``svc``'s, or none) and of each service of step 10."""
    main: Filter = (svc.alert_limit(axis), svc.tta_s) if svc is not None else (None, 0.0)
    return (main, *((s.alert_limit(axis), s.tta_s) for s in chosen))


def tail_filters(axis: str, services: tuple[str, ...] | None = None) -> tuple[Filter, ...]:
    """The HMI filters :func:`tail_analysis` reduces its input with (no filtering ``service``):
    for :func:`~overbound.methods.tail_partitions.tail_first` and the passes of a dataset."""
    return _filters(None, _chosen_services(None, services, axis), axis)


def tail_analysis_of(
    data: TailData,
    *,
    axis: str = "vertical",
    service: ServiceLevel | None = None,
    services: tuple[str, ...] | None = None,
    threshold: float | str = "auto",
    cluster_gap: float | str = "auto",
    decluster: bool = True,
    n_boot: int = 1000,
    confidence: float = 0.95,
    rng: np.random.Generator | int | None = 0,
    n_sim: int = 200,
    gev_boot: int | None = None,
    diagnostics: bool = True,
) -> TailAnalysis:
    """:func:`tail_analysis` of its reduced input (:mod:`overbound.methods.tail_partitions`, built
    with the filters of ``service`` and ``services``, :func:`tail_filters` when no ``service``):
    a table's or a campaign dataset's. The options are :func:`tail_analysis`'s."""
    _check_options(confidence, n_boot, threshold)
    chosen = _chosen_services(service, services, axis)
    if len(chosen) != len(data.services):
        raise ValueError(f"the input was reduced for {len(data.services)} services, not {len(chosen)}")
    clock: dict[str, float] = {}
    t0 = time.perf_counter()
    g = _rng(rng)
    seed = rng if isinstance(rng, int) else None
    g_main, g_gev, g_over, g_svc = g.spawn(4)
    n_used = data.counts[3]
    if n_used < 3:
        raise InputError("<epoch table>", f"only {n_used} epochs left to analyse")
    counts = _counts(data, data.counts)
    dt_s = counts.interval_s
    level = data.level
    clock["prepare"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    m = data.main
    dep = _dependence(data.t_s[m], data.acf, dt_s, level, cluster_gap)
    clock["dependence"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    tail = _tail_fit(
        data.t_s[m],
        data.x[m],
        n_total=n_used,
        level=level,
        positions=data.position[m],
        variable="SI",
        interval_s=dt_s,
        gap_s=dep.cluster_gap_s,
        threshold=threshold,
        decluster=decluster,
        n_boot=n_boot,
        confidence=confidence,
        exposure_n=APPROACH_S / dt_s,
        rng=g_main,
        n_sim=n_sim,
        diagnostics=diagnostics,
    )
    clock["tail"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    n_gev = n_boot if gev_boot is None else gev_boot
    gev = _gev(data.block_max, data.block_size, tail.extremal_index, n_gev, confidence, g_gev)
    clock["gev"] = time.perf_counter() - t1
    # overbounding of the normalised error, down-sampled to independent samples
    t1 = time.perf_counter()
    k = _K[axis]
    ell = data.spaced(krs_spacing(data.acf, dt_s)) * k
    l_tail = tail.threshold * k
    krs = None
    if l_tail > KRS_L_MIN:
        krs = krs_test(ell, l_min=KRS_L_MIN, l_tail=l_tail, alpha=1.0 - confidence)
    try:
        over = tail_overbound_probability(
            ell, l_tail=l_tail, n_boot=n_boot, rng=g_over, alpha=1.0 - confidence
        )
    except ValueError:
        over = None
    clock["overbounding"] = time.perf_counter() - t1
    # HMI per service
    t1 = time.perf_counter()
    hmi: dict[str, ServiceHMI] = {}
    for s, gs, series in zip(chosen, g_svc.spawn(len(chosen)), data.services, strict=True):
        hmi[s.name] = _service_hmi(
            data, series, s, axis, tail.threshold, dep.cluster_gap_s, decluster, n_boot, confidence, gs
        )
    clock["services"] = time.perf_counter() - t1
    clock["total"] = time.perf_counter() - t0
    msg = tail.message or "GPD tail extrapolation to SI = 1"
    return TailAnalysis(
        axis=axis,
        service=service.name if service else None,
        confidence=confidence,
        n_boot=n_boot,
        seed=seed,
        decluster=decluster,
        counts=counts,
        si_levels=np.array(SI_LEVELS),
        si_quantiles=data.quantiles,
        si_max=float(data.si_max),
        n_mi=int(data.n_mi),
        dependence=dep,
        tail=tail,
        gev=gev,
        krs=krs,
        tail_overbound=over,
        services=hmi,
        timings=clock,
        message=msg,
    )


def _service_hmi(
    data: TailData,
    series: tuple[np.ndarray, np.ndarray, tuple[int, int, int, int]],
    s: ServiceLevel,
    axis: str,
    threshold: float,
    gap_s: float,
    decluster: bool,
    n_boot: int,
    confidence: float,
    rng: np.random.Generator,
) -> ServiceHMI:
    """Step 10 of :func:`tail_analysis`: the MI extrapolation of the HMI-filtered SI for one
    service, from its filter over the main series' exceedances (``series``: which it keeps, their
    positions among its epochs, its counts)."""
    al = s.alert_limit(axis)
    nan = math.nan
    if al is None:
        raise ValueError(f"service {s.name} has no {axis} alert limit")
    keep, positions, filtered = series
    counts = _counts(data, filtered)
    dt_s = counts.interval_s
    exposure = s.integrity_exposure_s
    if counts.n_used < 3:
        msg = f"only {counts.n_used} epochs with PL < {al:g} m: no estimate"
        return ServiceHMI(s, al, counts, None, nan, nan, exposure, nan, nan, s.integrity_risk, None, msg)
    try:
        tail = _tail_fit(
            data.t_s[keep],
            data.x[keep],
            n_total=counts.n_used,
            level=threshold,
            positions=positions,
            variable="SI",
            interval_s=dt_s,
            gap_s=gap_s,
            threshold=threshold,
            decluster=decluster,
            n_boot=n_boot,
            confidence=confidence,
            exposure_n=exposure / dt_s,
            rng=rng,
            n_sim=0,
            diagnostics=False,
        )
    except ValueError as exc:
        return ServiceHMI(s, al, counts, None, nan, nan, exposure, nan, nan, s.integrity_risk, None, str(exc))
    meets = bool(tail.p_approach_95 <= s.integrity_risk)
    msg = tail.message or f"GPD tail extrapolation of SI to 1 on the epochs with PL < {al:g} m"
    return ServiceHMI(
        s,
        al,
        counts,
        tail,
        tail.p,
        tail.p_95,
        exposure,
        tail.p_approach,
        tail.p_approach_95,
        s.integrity_risk,
        meets,
        msg,
    )


# --------------------------------------------------------------------------------------------------
# JSON


def evt_dict(analysis: TailAnalysis) -> dict:
    """The ``overbound.evt/1`` document: the keys of :data:`EVT_KEYS` plus :data:`EVT_EXTRA_KEYS`."""
    a = analysis
    t = a.tail
    assert t is not None and t.gpd is not None and a.dependence is not None
    gev = a.gev
    gfit = gev.fit if gev else None
    return {
        "schema": SCHEMA,
        "axis": a.axis,
        "service": a.service,
        "confidence": a.confidence,
        "n_boot": a.n_boot,
        "seed": a.seed,
        "decluster": a.decluster,
        "message": a.message,
        "epochs": {
            "rows": a.counts.n_rows,
            "no_solution": a.counts.n_no_solution,
            "alert": a.counts.n_alert,
            "pl_above_al": a.counts.n_pl_above_al,
            "tta": a.counts.n_tta,
            "used": a.counts.n_used,
            "mi_observed": a.n_mi,
        },
        "threshold": t.threshold,
        "threshold_method": t.threshold_choice.method if t.threshold_choice else "given",
        "n_exceedances": t.n_exceedances,
        "cluster_gap_s": a.dependence.cluster_gap_s,
        "n_clusters": t.n_clusters,
        "extremal_index": t.extremal_index,
        "gpd": {
            "shape": t.gpd.xi,
            "scale": t.gpd.sigma,
            "shape_ci": list(t.shape_ci),
            "shape_ci_bootstrap": list(t.shape_ci_bootstrap),
            "regular": t.gpd.regular,
            "endpoint": t.gpd.endpoint,
        },
        "p_mi": t.p,
        "p_mi_ci": list(t.p_ci),
        "p_mi_95": t.p_95,
        "p_mi_profile_ci": list(t.p_profile_ci),
        "p_mi_ci_bootstrap": list(t.p_ci_bootstrap),
        "p_mi_ci_bca": list(t.p_ci_bca),
        "cluster_size": {
            "level": t.cluster_size.level,
            "mean": t.cluster_size.mean,
            "n_clusters": int(t.cluster_size.sizes.size),
            "at_threshold": t.cluster_size.at_threshold,
        }
        if t.cluster_size
        else None,
        "p_mi_per_approach": t.p_approach,
        "p_mi_per_approach_95": t.p_approach_95,
        "gev": {
            "shape": gfit.xi if gfit else None,
            "loc": gfit.loc if gfit else None,
            "scale": gfit.scale if gfit else None,
            "p_mi": gev.p_mi if gev else None,
            "p_mi_95": gev.p_mi_95 if gev else None,
        },
        "krs": {
            "statistic": a.krs.statistic if a.krs else None,
            "critical": a.krs.critical if a.krs else None,
            "overbounded": a.krs.overbounded if a.krs else None,
        },
        "tail_overbound_probability": a.tail_overbound.probability if a.tail_overbound else None,
        "services": {
            name: {
                "p_hmi": h.p_hmi,
                "p_hmi_95": h.p_hmi_95,
                "meets_requirement": h.meets_requirement,
                "alert_limit": h.alert_limit,
                "exposure_s": h.exposure_s,
                "p_hmi_per_exposure": h.p_hmi_exposure,
                "p_hmi_per_exposure_95": h.p_hmi_exposure_95,
                "integrity_risk": h.integrity_risk,
                "n_used": h.counts.n_used,
                "n_dropped_pl": h.counts.n_pl_above_al,
                "n_dropped_tta": h.counts.n_tta,
                "message": h.message,
            }
            for name, h in a.services.items()
        },
    }


def write_evt(analysis: TailAnalysis, path) -> str:
    """Write :func:`evt_dict` as deterministic JSON (:func:`overbound.report.json.dumps`); return the text."""
    from pathlib import Path

    text = dumps(evt_dict(analysis))
    Path(path).write_text(text, encoding="utf-8")
    return text
