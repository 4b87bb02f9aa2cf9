r"""Threshold selection for the GPD tail model: mean excess, shape stability and an automatic choice.

Veerman et al. (GIMAT), section 3.3 chooses the tail threshold :math:`L_{Tail}` by eye from the
mean-excess plot and the stability of the fitted shape, and notes that no satisfactory automatic
selection was available. :func:`select_threshold` implements the published automatic procedure of
Bader, Yan & Zhang (2018): Anderson-Darling goodness-of-fit tests of the GPD at increasing candidate
thresholds, combined by the ForwardStop rule (false-discovery-rate control for ordered hypotheses,
G'Sell et al. 2016).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from overbound.stats.bootstrap import _fit_chunk, _rng
from overbound.stats.evt import _gpd_cumhaz, fit_gpd, gpd_isf

__all__ = [
    "ShapeStability",
    "ThresholdChoice",
    "anderson_darling_gpd",
    "forward_stop",
    "mean_excess",
    "select_threshold",
    "shape_stability",
]

#: Default candidate thresholds: these empirical quantile levels of the data (Bader et al. 2018 use a
#: sequence of sample quantiles), kept while at least ``_MIN_EXCEEDANCES`` values exceed them.
DEFAULT_CANDIDATE_LEVELS = np.linspace(0.0, 0.95, 20)
_MIN_EXCEEDANCES = 30


def _values(values: np.ndarray) -> np.ndarray:
    x = np.asarray(values, dtype=float)
    if x.ndim != 1 or x.size < 3:
        raise ValueError(f"need a 1-D array of at least 3 values, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("values contain NaN or inf")
    return x


def mean_excess(values: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    r"""Empirical mean excess :math:`\overline{ME}(u) = \frac1k\sum_{x_i > u}(x_i - u)` per threshold.

    Veerman et al., section 3.3. For a GPD tail it is linear in :math:`u`,
    :math:`(\sigma_u + \xi u)/(1-\xi)`; ``nan`` where no value exceeds :math:`u`.

    Examples
    --------
    >>> mean_excess(np.array([1.0, 2.0, 3.0, 4.0]), np.array([0.0, 2.5, 4.0]))
    array([2.5, 1. , nan])
    """
    x = np.sort(_values(values))
    u = np.asarray(thresholds, dtype=float)
    cs = np.concatenate([[0.0], np.cumsum(x[::-1])])  # sums of the k largest
    k = x.size - np.searchsorted(x, u, side="right")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(k > 0, cs[k] / k - u, np.nan)


@dataclass(frozen=True, slots=True)
class ShapeStability:
    """Result of :func:`shape_stability`: per threshold, the shape, its profile interval and the count."""

    thresholds: np.ndarray
    xi: np.ndarray
    xi_lower: np.ndarray
    xi_upper: np.ndarray
    n_exceedances: np.ndarray
    level: float


def shape_stability(values: np.ndarray, thresholds: np.ndarray, *, level: float = 0.95) -> ShapeStability:
    r"""GPD shape and its profile-likelihood interval at each threshold (Veerman et al., section 3.3).

    Thresholds with fewer than 3 exceedances give ``nan``. Once the threshold is high enough for the
    GPD to hold, the shape is stable up to noise.
    """
    x = _values(values)
    u = np.asarray(thresholds, dtype=float)
    out = np.full((3, u.size), np.nan)
    cnt = np.zeros(u.size, dtype=int)
    for j, uj in enumerate(u):  # a loop over a handful of thresholds
        exc = x[x > uj]
        cnt[j] = exc.size
        if exc.size < 3:
            continue
        f = fit_gpd(exc, threshold=uj)
        lo, hi = f.profile_ci(level)
        out[:, j] = f.xi, lo, hi
    return ShapeStability(u, out[0], out[1], out[2], cnt, level)


def _ad_rows(ys: np.ndarray, xi: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Anderson-Darling statistic per row of sorted excesses ``ys`` (B, n) against GPD(xi, sigma) rows."""
    n = ys.shape[1]
    h = _gpd_cumhaz(ys, xi[:, None], sigma[:, None])  # -log sf
    with np.errstate(divide="ignore"):
        log_f = np.log(-np.expm1(-h))  # log cdf
    log_s = -h
    i = np.arange(1, n + 1)
    return -n - np.sum((2 * i - 1) * (log_f + log_s[:, ::-1]), axis=1) / n


def anderson_darling_gpd(excesses: np.ndarray, *, xi: float, sigma: float) -> float:
    r"""Anderson-Darling statistic of excesses against the GPD(:math:`\xi, \sigma`).

    .. math:: A^2 = -n - \frac1n\sum_{i=1}^n (2i-1)\left[\log z_{(i)} + \log(1 - z_{(n+1-i)})\right],
              \quad z = G(y),

    with :math:`\log(1-z)` taken from the survival function (accurate in the tail).
    """
    ys = np.sort(np.asarray(excesses, dtype=float))[None, :]
    return float(_ad_rows(ys, np.array([xi]), np.array([sigma]))[0])


def _ad_pvalue(y: np.ndarray, n_sim: int, g: np.random.Generator) -> tuple[float, float]:
    """AD statistic of the GPD ML fit to ``y`` and its parametric-bootstrap p-value."""
    fit = fit_gpd(y)
    stat = anderson_darling_gpd(y, xi=fit.xi, sigma=fit.sigma)
    sim = gpd_isf(g.random((n_sim, y.size)), xi=fit.xi, sigma=fit.sigma)
    xs, ss, _, _ = _fit_chunk(sim, fit.xi / fit.sigma if fit.success else 0.0)
    sims = _ad_rows(np.sort(sim, axis=1), xs, ss)
    p = (1.0 + np.sum(sims >= stat)) / (n_sim + 1.0)
    return stat, float(p)


def forward_stop(p_values: np.ndarray, *, alpha: float = 0.05) -> int:
    r"""ForwardStop rule (G'Sell et al. 2016): the number :math:`\hat k` of rejected leading hypotheses.

    .. math:: \hat k = \max\left\{k : -\frac1k\sum_{i=1}^k \log(1 - p_i) \le \alpha\right\},

    0 when no :math:`k` qualifies.

    Examples
    --------
    >>> forward_stop(np.array([0.001, 0.01, 0.5, 0.9]), alpha=0.05)
    2
    """
    p = np.asarray(p_values, dtype=float)
    with np.errstate(divide="ignore"):
        stat = np.cumsum(-np.log1p(-p)) / np.arange(1, p.size + 1)
    ok = np.flatnonzero(stat <= alpha)
    return int(ok[-1] + 1) if ok.size else 0


@dataclass(frozen=True, slots=True)
class ThresholdChoice:
    r"""Result of :func:`select_threshold`.

    Attributes
    ----------
    threshold : float
        Chosen threshold :math:`u_{\hat k + 1}` (``nan`` when every candidate is rejected).
    n_exceedances : int
        Values above it.
    p_values, statistics, candidates : numpy.ndarray
        AD p-value and statistic per candidate threshold (increasing).
    method : str
    goodness_of_fit : float
        AD p-value at the chosen threshold.
    message : str
    """

    threshold: float
    n_exceedances: int
    p_values: np.ndarray = field(repr=False)
    statistics: np.ndarray = field(repr=False)
    candidates: np.ndarray = field(repr=False)
    method: str
    goodness_of_fit: float
    message: str


def select_threshold(
    values: np.ndarray,
    *,
    candidates: np.ndarray | None = None,
    alpha: float = 0.05,
    n_sim: int = 200,
    rng: np.random.Generator | int | None = None,
) -> ThresholdChoice:
    r"""Automatic GPD threshold by sequential Anderson-Darling tests with ForwardStop.

    Parameters
    ----------
    values
        The variable (e.g. declustered safety indices); the tail is modelled above the threshold.
    candidates
        Increasing candidate thresholds; default the empirical quantiles at
        :data:`DEFAULT_CANDIDATE_LEVELS` with at least 30 exceedances.
    alpha
        ForwardStop level (false discovery rate among the rejected thresholds).
    n_sim
        Parametric-bootstrap samples per candidate for the AD p-value.
    rng
        Seed or generator of the parametric bootstrap.

    Returns
    -------
    ThresholdChoice

    Notes
    -----
    Bader, Yan & Zhang (2018), section 2:

    1. For each candidate :math:`u_1 < \dots < u_m`, fit the GPD by maximum likelihood to the excesses
       and compute the Anderson-Darling statistic :math:`A^2_i` (:func:`anderson_darling_gpd`).
    2. p-value :math:`p_i` by parametric bootstrap: ``n_sim`` GPD samples of the same size from the
       fitted parameters, each refitted (all at once), :math:`p_i = (1 + \#\{A^{2*} \ge A^2_i\})/(n_{sim}+1)`.
       Bader et al. use the asymptotic table of Choulakian & Stephens (2001) interpolated in the
       shape; that table is not reproduced here (we could not check its values against the source),
       so the exact-size parametric bootstrap is used instead, which is valid for every shape and
       sample size (slower, and the p-value is resolved to :math:`1/(n_{sim}+1)`).
    3. ForwardStop (:func:`forward_stop`): :math:`\hat k = \max\{k: -\frac1k\sum_{i\le k}\log(1-p_i)
       \le \alpha\}`; the threshold is :math:`u_{\hat k+1}`, the lowest one not rejected as a block.

    The choice can be overridden by passing a fixed threshold to the fit; Veerman et al., section 3.3,
    note that no automatic selection was available to GIMAT.

    References
    ----------
    .. [1] Bader, B., Yan, J. and Zhang, X. (2018), "Automated threshold selection for extreme value
       analysis via ordered goodness-of-fit tests with adjustment for false discovery rate", Annals of
       Applied Statistics 12(1), 310-329.
    .. [2] G'Sell, M. G., Wager, S., Chouldechova, A. and Tibshirani, R. (2016), "Sequential selection
       procedures and false discovery rate control", JRSS B 78(2), 423-444.
    .. [3] Choulakian, V. and Stephens, M. A. (2001), "Goodness-of-fit tests for the generalized
       Pareto distribution", Technometrics 43(4), 478-484.
    .. [4] Veerman et al., "A Tool for GNSS Integrity Verification Based on Statistical Extreme Value
       Theory", section 3.3.
    """
    x = _values(values)
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
    g = _rng(rng)
    if candidates is None:
        u = np.unique(np.quantile(x, DEFAULT_CANDIDATE_LEVELS))
        u = u[np.array([np.sum(x > v) for v in u]) >= _MIN_EXCEEDANCES]
    else:
        u = np.asarray(candidates, dtype=float)
        if u.ndim != 1 or u.size == 0 or np.any(np.diff(u) <= 0):
            raise ValueError("candidates must be a non-empty increasing 1-D array")
    if u.size == 0:
        raise ValueError(f"no candidate threshold has {_MIN_EXCEEDANCES} exceedances")
    stats_ = np.full(u.size, np.nan)
    pv = np.full(u.size, np.nan)
    for j, uj in enumerate(u):  # one test per candidate threshold
        exc = x[x > uj] - uj
        if exc.size < 3:
            raise ValueError(f"candidate {uj} has fewer than 3 exceedances")
        stats_[j], pv[j] = _ad_pvalue(exc, n_sim, g)
    k = forward_stop(pv, alpha=alpha)
    method = "Anderson-Darling + ForwardStop (Bader, Yan & Zhang 2018), parametric-bootstrap p-values"
    if k >= u.size:
        return ThresholdChoice(
            math.nan, 0, pv, stats_, u, method, math.nan, "every candidate threshold rejected by ForwardStop"
        )
    thr = float(u[k])
    msg = f"{k} lower candidate(s) rejected; GPD not rejected at threshold {thr:.6g} (AD p = {pv[k]:.3g})"
    return ThresholdChoice(thr, int(np.sum(x > thr)), pv, stats_, u, method, float(pv[k]), msg)
