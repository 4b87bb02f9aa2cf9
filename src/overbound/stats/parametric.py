r"""Parametric MI, availability and integrity statistics (Kannemans 2006, NLR-TP-2006-594, section 2).

Kannemans replaces the plain counts of a Stanford plot, which give zero MI probability on any
campaign of realistic length, by two fitted distributions and their product:

* **Ratio fits** (sections 2.1.1 and 2.2.1): the ratio :math:`r = PE/PL` is normal in the vertical
  (signed VPE) and Rayleigh in the horizontal; the MI probability is :math:`P(|r| > 1)`
  (:func:`fit_normal_ratio`, :func:`fit_rayleigh_ratio`, :func:`ratio_exceedance`), with a one-sided
  bound from the effective sample size of the correlated series (:func:`effective_sample_size`,
  :func:`ratio_bound`).
* **Weibull** (section 2.1.2): the PL has the density :math:`a b x^{b-1} e^{-a x^b}`; the ML fit
  (:func:`fit_weibull`) gives the unavailability :math:`S(AL) = e^{-a\,AL^b}`, and the delta method with
  the decorrelated sample gives its bound (:func:`weibull_covariance`, :func:`weibull_bound`) and the
  band of the histogram figure (:func:`weibull_pdf_band`, the paper's figure 7).
* **Integrals** (section 2.1.3): with PL and :math:`r` independent, the joint density of
  :math:`(PL, |PE|)` is :math:`p_{PL}(x)\,p_r(y/x)/x` (:func:`pe_pl_density`, the contour figures 11),
  and :func:`integrity_probabilities` integrates it over the Stanford regions (P_HMI, P_MI with
  :math:`PL \gtrless AL`).

Probabilities are per epoch. Every probability is computed in log space and returned with its
:math:`\log_{10}`, which stays finite when the probability underflows (a ratio sigma of 0.02 gives
:math:`P_{MI} \approx 10^{-545}`).

The continuity curve of section 2.1.4 is in :mod:`overbound.stats.continuity`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy import special, stats

from overbound.stats.sums import dot

__all__ = [
    "IntegrityProbabilities",
    "RatioFit",
    "WeibullFit",
    "effective_sample_size",
    "fit_normal_ratio",
    "fit_rayleigh_ratio",
    "fit_weibull",
    "integrity_probabilities",
    "log_ratio_exceedance",
    "normal_ratio_fit",
    "pe_pl_density",
    "ratio_bound",
    "ratio_exceedance",
    "ratio_pdf",
    "ratio_plot_positions",
    "rayleigh_ratio_fit",
    "squared_deviations",
    "weibull_bound",
    "weibull_covariance",
    "weibull_covariance_from_sums",
    "weibull_fit_from_sums",
    "weibull_fit_steps",
    "weibull_information_sums",
    "weibull_logpdf",
    "weibull_logsf",
    "weibull_pdf",
    "weibull_pdf_band",
    "weibull_plot_positions",
    "weibull_profile_sums",
    "weibull_sf",
    "weibull_start_stride",
]

_LN10 = math.log(10.0)
_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
#: Profile-equation evaluations allowed per stage of :func:`fit_weibull`.
_WEIBULL_MAXITER = 100
#: :func:`fit_weibull` stops when the step in b is below this fraction of b (the last step is a Halley
#: step, whose error is of the order of its cube).
_WEIBULL_STEP_RTOL = 1e-8
#: Above this many values :func:`fit_weibull` first solves on a regular subsample of about half its size.
_WEIBULL_SUBSAMPLE = 1 << 17
#: Gauss-Legendre rules of the integrals: 16 points per panel, checked against 8 (nodes, weights on [-1, 1]).
_GL_FINE = np.polynomial.legendre.leggauss(16)
_GL_COARSE = np.polynomial.legendre.leggauss(8)
#: Initial panels of the integrals: geometric edges from this (times 1/A on the PL -> 0 side) to 1/2, in
#: steps of at most this ratio.
_PANEL_START = 1e-15
_PANEL_RATIO = 2.7
#: A panel is split while the 16- and 8-point rules differ by more than this fraction of the integral ...
_PANEL_RTOL = 1e-11
#: ... for at most this many rounds, with at most this many panels split per round.
_PANEL_ROUNDS = 60
_PANEL_MAX_SPLIT = 2048
#: Default number of points returned by the probability-plot helpers.
_PLOT_POINTS = 4000


# ---------------------------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------------------------


def _sample(x: np.ndarray, name: str, min_size: int) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {a.shape}")
    if a.size < min_size:
        raise ValueError(f"{name} needs at least {min_size} values, got {a.size}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} must be finite")
    return a


def _points(x: np.ndarray | float, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if np.isnan(a).any():
        raise ValueError(f"{name} must not contain NaN")
    return a


def _confidence(confidence: float) -> float:
    c = float(confidence)
    if not 0.0 < c < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")
    return c


def _alert_limit(alert_limit: float) -> float:
    al = float(alert_limit)
    if not (math.isfinite(al) and al > 0.0):
        raise ValueError(f"alert_limit must be finite and > 0, got {alert_limit!r}")
    return al


# ---------------------------------------------------------------------------------------------
# ratio fits (sections 2.1.1, 2.2.1)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RatioFit:
    r"""Fitted distribution of the ratio :math:`r = PE/PL` (Kannemans 2006, sections 2.1.1 and 2.2.1).

    Attributes
    ----------
    distribution : ``"normal"`` (signed VPE/VPL) or ``"rayleigh"`` (HPE/HPL).
    mean : normal: the mean :math:`m`; Rayleigh: the fitted distribution's mean
        :math:`\sigma\sqrt{\pi/2}` (reported, not a parameter).
    sigma : normal: the standard deviation; Rayleigh: the scale :math:`\sigma` (the paper's
        "Rayleigh standard deviation", 0.065 in section 2.2.1).
    n : number of ratios fitted.
    """

    distribution: Literal["normal", "rayleigh"]
    mean: float
    sigma: float
    n: int


def fit_normal_ratio(r: np.ndarray) -> RatioFit:
    r"""Normal fit of the signed ratio VPE/VPL (Kannemans 2006, section 2.1.1, figure 4).

    Parameters
    ----------
    r
        Ratios VPE/VPL with the signed VPE (positive above the truth).

    Returns
    -------
    RatioFit
        ``mean`` the sample mean, ``sigma`` the sample standard deviation (``ddof=1``).

    Raises
    ------
    ValueError
        Not one-dimensional, fewer than two values, not finite, or constant.
    """
    a = _sample(r, "r", 2)
    m = float(a.sum()) / a.size
    return normal_ratio_fit(a.size, m, squared_deviations(a, m), float(a.max()) > float(a.min()))


def squared_deviations(r: np.ndarray, mean: float) -> float:
    r""":math:`\sum_i (r_i - \bar r)^2`, as ``np.std`` sums them (a block's share of the normal fit)."""
    d = r - mean
    return float(np.multiply(d, d, out=d).sum())


def normal_ratio_fit(n: int, mean: float, sum_squared_deviations: float, varies: bool) -> RatioFit:
    r"""The normal fit of :func:`fit_normal_ratio` from its sums, which add over blocks of the ratios:
    ``n`` ratios, their ``mean`` (their sum over ``n``), :math:`\sum (r_i - \bar r)^2` (see
    :func:`squared_deviations`) and whether they are not all equal (``varies``); the standard
    deviation is :math:`\sqrt{\sum (r_i - \bar r)^2 / (n - 1)}` (``ddof=1``).

    Raises
    ------
    ValueError
        Fewer than two ratios, or all equal.
    """
    if n < 2:
        raise ValueError(f"r needs at least 2 values, got {n}")
    if not varies:
        raise ValueError("r is constant: a normal fit needs a positive standard deviation")
    return RatioFit("normal", mean, math.sqrt(sum_squared_deviations / (n - 1)), int(n))


def fit_rayleigh_ratio(r: np.ndarray) -> RatioFit:
    r"""Maximum-likelihood Rayleigh fit of HPE/HPL (Kannemans 2006, section 2.2.1).

    Parameters
    ----------
    r
        Ratios HPE/HPL, ``>= 0``.

    Returns
    -------
    RatioFit
        ``sigma`` with :math:`\hat\sigma^2 = \sum r_i^2 / (2n)` (the ML estimate) and ``mean`` the
        fitted distribution's mean :math:`\hat\sigma\sqrt{\pi/2}`.

    Raises
    ------
    ValueError
        Not one-dimensional, empty, not finite, negative values, or all zero.
    """
    a = _sample(r, "r", 1)
    if (a < 0.0).any():
        raise ValueError("r must be >= 0 for a Rayleigh fit (HPE/HPL)")
    return rayleigh_ratio_fit(a.size, dot(a, a))


def rayleigh_ratio_fit(n: int, sum_squares: float) -> RatioFit:
    r"""The Rayleigh fit of :func:`fit_rayleigh_ratio` from ``n`` ratios and :math:`\sum r_i^2`
    (a sum that adds over blocks of the ratios).

    Raises
    ------
    ValueError
        No ratio, or all zero.
    """
    if n < 1:
        raise ValueError("r needs at least 1 values, got 0")
    s = math.sqrt(sum_squares / (2.0 * n))
    if not s > 0.0:
        raise ValueError("r is all zero: a Rayleigh fit needs a positive scale")
    return RatioFit("rayleigh", s * math.sqrt(math.pi / 2.0), s, int(n))


def _log_q(fit: RatioFit, t: np.ndarray) -> np.ndarray:
    """``ln P(|r| > t)`` for ``t >= 0`` (no validation)."""
    m, s = fit.mean, fit.sigma
    if fit.distribution == "normal":
        return np.logaddexp(special.log_ndtr((m - t) / s), special.log_ndtr((-t - m) / s))
    return -0.5 * np.square(t / s)


def log_ratio_exceedance(fit: RatioFit, t: np.ndarray | float) -> np.ndarray:
    r"""Natural log of :math:`Q(t) = P(|r| > t)`, :math:`t \ge 0` (Kannemans 2006, sections 2.1.1, 2.2.1).

    :math:`Q(1)` is the MI probability (:math:`|PE| > PL`); :math:`Q(AL/PL)` enters the integrals of
    section 2.1.3.

    Parameters
    ----------
    fit
        Ratio fit.
    t
        Thresholds, ``>= 0`` (``inf`` allowed); any shape.

    Returns
    -------
    numpy.ndarray
        Normal (two-sided: :math:`|VPE| > t\,VPL` on either side is MI):
        :math:`\ln[\bar\Phi((t-m)/\sigma) + \Phi((-t-m)/\sigma)]` by ``log_ndtr`` and ``logaddexp``;
        Rayleigh: :math:`-t^2/(2\sigma^2)`. Never underflows (finite down to about
        :math:`-10^{308}`).

    Raises
    ------
    ValueError
        ``t`` negative or NaN.

    Examples
    --------
    The paper's normal fit (sigma 0.059, mean 0): :math:`P_{MI} = 2\bar\Phi(1/0.059)`.

    >>> fit = RatioFit("normal", 0.0, 0.059, 100)
    >>> round(float(log_ratio_exceedance(fit, 1.0)) / math.log(10), 2)
    -63.71
    """
    a = _points(t, "t")
    if (a < 0.0).any():
        raise ValueError("t must be >= 0 (Q(t) = P(|r| > t))")
    return _log_q(fit, a)


def ratio_exceedance(fit: RatioFit, t: np.ndarray | float) -> np.ndarray:
    """:math:`Q(t) = P(|r| > t)`: ``exp`` of :func:`log_ratio_exceedance` (may underflow to 0)."""
    return np.exp(log_ratio_exceedance(fit, t))


def _log_ratio_pdf(fit: RatioFit, y: np.ndarray) -> np.ndarray:
    m, s = fit.mean, fit.sigma
    with np.errstate(divide="ignore", invalid="ignore"):
        if fit.distribution == "normal":  # folded normal: density of |r|
            out = np.logaddexp(-0.5 * np.square((y - m) / s), -0.5 * np.square((y + m) / s))
            out = out - math.log(s) - _LOG_SQRT_2PI
        else:
            out = np.log(y) - 2.0 * math.log(s) - 0.5 * np.square(y / s)
    return np.where(y >= 0.0, out, -np.inf)


def ratio_pdf(fit: RatioFit, y: np.ndarray | float) -> np.ndarray:
    r"""Density of :math:`|r|` (normal: folded normal) or of :math:`r` (Rayleigh), for the contour figure.

    Parameters
    ----------
    fit
        Ratio fit.
    y
        Ratio values; the density is 0 for ``y < 0``.

    Returns
    -------
    numpy.ndarray
        Normal: :math:`[\varphi((y-m)/\sigma) + \varphi((y+m)/\sigma)]/\sigma`; Rayleigh:
        :math:`(y/\sigma^2)\,e^{-y^2/(2\sigma^2)}`. Its survival function is :func:`ratio_exceedance`.

    Raises
    ------
    ValueError
        ``y`` contains NaN.
    """
    return np.exp(_log_ratio_pdf(fit, _points(y, "y")))


def effective_sample_size(n: int, interval_s: float, decorrelation_s: float) -> float:
    r"""Number of independent samples equivalent to a correlated series: :math:`n\,\Delta/\tau`.

    Kannemans 2006, section 2.1.1 ("a decorrelation time of 2000 seconds"): the classical interval
    is "far too optimistic" for correlated samples.

    Parameters
    ----------
    n
        Number of samples.
    interval_s
        Sampling interval :math:`\Delta` (s).
    decorrelation_s
        Decorrelation time :math:`\tau` (s), e.g. the 1/e time of the autocorrelation
        (:func:`overbound.stats.dependence.decorrelation_time`); ``inf`` gives 0.

    Returns
    -------
    float
        :math:`\min(n,\; n\Delta/\tau)` (a decorrelation time below the interval means independent
        samples).

    Raises
    ------
    ValueError
        ``n`` negative, ``interval_s`` not finite and > 0, ``decorrelation_s`` not > 0 (or NaN).

    Notes
    -----
    For a first-order Gauss-Markov (AR(1)) series :math:`\rho(k) = \phi^k` with 1/e time
    :math:`\tau = -\Delta/\ln\phi`, the sample variance has
    :math:`\mathrm{var}(s^2) = (2\sigma^4/n)(1+\phi^2)/(1-\phi^2) \approx 2\sigma^4 \tau/(n\Delta)`:
    :math:`n\Delta/\tau` is the effective size of the **variance** estimator (the :math:`\chi^2`
    degrees of freedom). The sample **mean** has
    :math:`\mathrm{var}(\bar r) = (\sigma^2/n)(1+\phi)/(1-\phi) \approx \sigma^2\,2\tau/(n\Delta)`:
    half that size. :func:`ratio_bound` uses both.

    **Which series' decorrelation time.** For the normal ratio the 1/e time of the ratio's own ACF is
    :math:`\tau`. For the Rayleigh ratio :math:`r = \sqrt{x^2 + y^2}` of two AR(1) components of 1/e
    time :math:`\tau`, :math:`\hat\sigma^2` is a mean of :math:`r^2`, whose ACF is :math:`\phi^{2k}`
    (integral scale :math:`\tau`), but the ACF of :math:`r` itself decays about as :math:`\phi^{2k}`
    too, so its 1/e time is about :math:`\tau/2` and :math:`n_e` from it is twice too large: in
    simulation (N = 20000 at 1 s, :math:`\tau` = 100 s) the 0.95 bound then held in 0.84-0.87 of the
    repetitions instead of 0.95. Likewise the Weibull ML estimates are means of the score: with
    :math:`n_e = n\Delta/\tau` of the PL the 0.95 unavailability bound held in 0.87 (S = 0.2), 0.905
    (S = 0.025), 0.93 (S = 1e-3) of Gaussian-copula AR(1) repetitions, and with :math:`n_e/2` in 0.95-0.99
    (tests/stats/test_parametric.py).
    """
    n_ = int(n)
    if n_ != n or n_ < 0:
        raise ValueError(f"n must be a non-negative integer, got {n!r}")
    dt = float(interval_s)
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError(f"interval_s must be finite and > 0, got {interval_s!r}")
    tau = float(decorrelation_s)
    if not tau > 0.0:
        raise ValueError(f"decorrelation_s must be > 0, got {decorrelation_s!r}")
    return float(min(n_, n_ * dt / tau))


def ratio_bound(fit: RatioFit, n_effective: float, confidence: float) -> RatioFit | None:
    r"""One-sided conservative bound of a ratio fit at a confidence (Kannemans 2006, section 2.1.1).

    The bound fit is the parameter point at which :math:`P_{MI} = Q(1)` is evaluated for
    ``p_mi_bound``.

    Parameters
    ----------
    fit
        Ratio fit.
    n_effective
        Effective sample size :math:`n_e` of the ratio series (:func:`effective_sample_size`).
    confidence
        Confidence :math:`c` (e.g. 0.95, the paper's "confidence level of 5%").

    Returns
    -------
    RatioFit or None
        The bound fit (same ``n``), or None when the series is too short for its decorrelation
        time: :math:`n_e < 2`, and for the normal fit also :math:`n_e = 2` exactly, where the
        :math:`t` quantile's :math:`n_e/2 - 1` degrees of freedom vanish.

    Raises
    ------
    ValueError
        ``n_effective`` negative or NaN, ``confidence`` outside (0, 1).

    Notes
    -----
    **Normal.** Bonferroni over the two parameters, each at :math:`c' = (1+c)/2`:

    .. math::

        \sigma_b = s\sqrt{\frac{n_e - 1}{\chi^2_{1-c'}(n_e - 1)}}, \qquad
        m_b = m + \operatorname{sign}(m)\, t_{c'}(n_e/2 - 1)\, \frac{s}{\sqrt{n_e/2}}

    (:math:`\operatorname{sign}(0) = +1`; non-integer degrees of freedom are fine): :math:`n_e` is the
    effective size of the variance estimator and :math:`n_e/2` that of the mean (see
    :func:`effective_sample_size`). :math:`Q(1)` grows with :math:`|m|` and with :math:`\sigma`, so
    :math:`P(Q_b(1) \ge Q(1)) \ge c` (joint coverage of the two one-sided bounds).

    **Rayleigh.** :math:`2n\hat\sigma^2/\sigma^2 \sim \chi^2(2n)` for independent samples, so
    :math:`\sigma_b^2 = 2 n_e \hat\sigma^2 / \chi^2_{1-c}(2 n_e)`; ``mean`` is
    :math:`\sigma_b\sqrt{\pi/2}`.

    The paper's own bounds (:math:`2.3\times10^{-33}` vertical, :math:`2.4\times10^{-32}` horizontal)
    do not follow from any consistent :math:`n_e` with its stated decorrelation time (2000 s) and
    duration (6.5 h); they are not reproduced.
    """
    c = _confidence(confidence)
    ne = float(n_effective)
    if not ne >= 0.0:
        raise ValueError(f"n_effective must be >= 0, got {n_effective!r}")
    if ne < 2.0:
        return None
    if fit.distribution == "rayleigh":
        s_b = fit.sigma * math.sqrt(2.0 * ne / float(stats.chi2.ppf(1.0 - c, 2.0 * ne)))
        return RatioFit("rayleigh", s_b * math.sqrt(math.pi / 2.0), s_b, fit.n)
    if ne <= 2.0:
        return None
    cp = 0.5 * (1.0 + c)
    s_b = fit.sigma * math.sqrt((ne - 1.0) / float(stats.chi2.ppf(1.0 - cp, ne - 1.0)))
    half = 0.5 * ne
    shift = float(stats.t.ppf(cp, half - 1.0)) * fit.sigma / math.sqrt(half)
    m_b = fit.mean + math.copysign(shift, 1.0 if fit.mean >= 0.0 else -1.0)
    return RatioFit("normal", m_b, s_b, fit.n)


def ratio_plot_positions(
    fit: RatioFit, r: np.ndarray, *, max_points: int = _PLOT_POINTS
) -> tuple[np.ndarray, np.ndarray]:
    r"""Coordinates of the normal (Rayleigh) probability plot of the ratio (Kannemans 2006, figure 4).

    Parameters
    ----------
    fit
        The fit whose distribution gives the plot (its parameters are not used).
    r
        The ratios fitted (signed for the normal fit, ``>= 0`` for the Rayleigh fit).
    max_points
        Points returned at most (thinned as :func:`weibull_plot_positions`).

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        The sorted ratios :math:`r_{(i)}` and the standard quantiles of their Bernard median ranks
        :math:`F_i = (i - 0.3)/(n + 0.4)`: :math:`\Phi^{-1}(F_i)` (normal) or
        :math:`\sqrt{-2\ln(1-F_i)}` (Rayleigh). The fit is the straight line
        :math:`r = m + \sigma q` (normal) or :math:`r = \sigma q` (Rayleigh).

    Raises
    ------
    ValueError
        ``r`` empty, not finite, or negative for a Rayleigh fit.
    """
    a = _sample(r, "r", 1)
    if fit.distribution == "rayleigh" and (a < 0.0).any():
        raise ValueError("r must be >= 0 for a Rayleigh probability plot")
    ranks, f = _plot_ranks(a.size, max_points)
    q = special.ndtri(f) if fit.distribution == "normal" else np.sqrt(-2.0 * np.log1p(-f))
    return np.sort(a)[ranks], q


# ---------------------------------------------------------------------------------------------
# Weibull (section 2.1.2)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class WeibullFit:
    r"""Weibull distribution :math:`p(x) = a b x^{b-1} e^{-a x^b}` of the PL (Kannemans 2006, section 2.1.2).

    Attributes
    ----------
    a : the paper's :math:`a` (:math:`a = \lambda^{-b}` for the scale :math:`\lambda` of
        ``scipy.stats.weibull_min``).
    b : shape (``weibull_min``'s ``c``).
    n : number of values fitted.
    converged : the profile equation was solved to the tolerance.
    iterations : profile-equation evaluations (on the subsample and on all values).
    """

    a: float
    b: float
    n: int
    converged: bool
    iterations: int


def weibull_profile_sums(v: np.ndarray, b: float) -> np.ndarray:
    r"""The sums of the profile equation of :func:`fit_weibull` over values ``v = ln x - max ln x``
    (``<= 0``) at the shape ``b``: :math:`\sum w_i v_i^k`, ``k = 0 .. 3``, ``w = e^{b v} <= 1``. They
    add over blocks of the values (a campaign's station-days)."""
    buf = np.multiply(v, b)
    np.exp(buf, out=buf)
    s0 = float(buf.sum())
    buf *= v
    s1 = float(buf.sum())
    s2 = dot(buf, v)
    buf *= v
    return np.array([s0, s1, s2, dot(buf, v)])


def _drive(steps: Generator, sums: Callable[[float], np.ndarray]):
    """Run a generator that yields the shapes ``b`` it needs :func:`weibull_profile_sums` at."""
    try:
        b = next(steps)
        while True:
            b = steps.send(sums(b))
    except StopIteration as stop:
        return stop.value


def _solve_profile(
    sums: Callable[[float], np.ndarray], n: int, spread: float, b: float
) -> tuple[float, float, int, bool]:
    """:func:`_profile_root` with the sums of ``sums(b)``."""
    return _drive(_profile_root(n, spread, b), sums)


def _profile_root(
    n: int, spread: float, b: float
) -> Generator[float, np.ndarray, tuple[float, float, int, bool]]:
    r"""Root of :math:`h(b) = 1/b - E_b[u]` by Halley steps safeguarded by Newton and bisection.

    Yields each ``b`` it needs the :func:`weibull_profile_sums` of the ``n`` values ``v = ln x - max
    ln x`` at, and is sent them; ``spread = max ln x - mean ln x`` (so :math:`u = v + ` ``spread``).
    Returns ``(b, ln mean(exp(b v)) at that b, evaluations, converged)``; see :func:`fit_weibull`.
    """
    lo, hi = 1.0 / spread, math.inf  # h(1/max u) = max u - E[u] > 0: a lower bracket
    log_mean = math.nan
    for it in range(1, _WEIBULL_MAXITER + 1):
        s0, s1, s2, s3 = (float(x) for x in (yield b))
        m1, m2, m3 = s1 / s0, s2 / s0, s3 / s0
        var = max(m2 - m1 * m1, 0.0)
        h = 1.0 / b - spread - m1
        if h == 0.0:
            return b, math.log(s0 / n), it, True
        if h > 0.0:
            lo = max(lo, b)
        else:
            hi = min(hi, b)
        h1 = -1.0 / b**2 - var  # < 0: h strictly decreasing, unique root
        h2 = 2.0 / b**3 - (m3 - 3.0 * m1 * m2 + 2.0 * m1**3)
        den = 2.0 * h1 * h1 - h * h2
        new = b - 2.0 * h * h1 / den if den > 0.0 else math.nan  # Halley
        if not lo < new < hi:
            new = b - h / h1  # Newton
        if not lo < new < hi:
            new = math.sqrt(lo * hi) if math.isfinite(hi) else 2.0 * b  # bisection (geometric)
        step = new - b
        # ln mean(e^{b v}) at the new b, second-order Taylor from this evaluation (the last step is tiny)
        log_mean = math.log(s0 / n) + m1 * step + 0.5 * var * step * step
        if abs(step) <= _WEIBULL_STEP_RTOL * b:
            return new, log_mean, it, True
        b = new
    return b, log_mean, _WEIBULL_MAXITER, False


def weibull_start_stride(n: int) -> int:
    """Every how many values (in their order) :func:`fit_weibull` takes the sample it starts from:
    all of them up to 131072 values, else a regular subsample of about 65536."""
    return 1 if n <= _WEIBULL_SUBSAMPLE else n // (_WEIBULL_SUBSAMPLE // 2)


def _weibull_start(sample: np.ndarray, n: int, spread: float) -> tuple[float, int]:
    r"""Start of the profile iteration, and the evaluations spent on it: :math:`\pi/(\sqrt6\,s_u)`, exact
    for Weibull data, refined to the root of the regular subsample (:func:`weibull_start_stride`) of
    ``n`` values ``v`` above 131072 of them. ``sample``: those values of ``v``. Choice: a constant
    subsample of values that vary starts from :math:`\pi/(\sqrt6\,\mathrm{spread})` (any start > 0
    converges; the standard deviation of all the values would need them all at once)."""
    if n > _WEIBULL_SUBSAMPLE:
        sub = np.ascontiguousarray(sample)
        top = float(sub.max())
        if not float(sub.min()) < top:  # np.std of a constant array need not be 0
            return math.pi / (math.sqrt(6.0) * spread), 0
        b0 = math.pi / (math.sqrt(6.0) * float(np.std(sub)))
        shifted = sub - top
        b, _, it, _ = _solve_profile(
            functools.partial(weibull_profile_sums, shifted), sub.size, top - float(sub.mean()), b0
        )
        return b, it
    return math.pi / (math.sqrt(6.0) * float(np.std(sample))), 0


def weibull_fit_from_sums(
    n: int, ymax: float, spread: float, sample: np.ndarray, sums: Callable[[float], np.ndarray]
) -> WeibullFit:
    r"""The ML fit of :func:`fit_weibull` from what adds over blocks of the values, for a campaign
    read a station-day at a time: ``n`` values with :math:`\max \ln x` ``ymax`` and
    ``spread`` :math:`= \max \ln x - \overline{\ln x}` (> 0), the start ``sample`` (the values ``v =
    ln x - ymax`` at every :func:`weibull_start_stride`-th position) and ``sums(b)``, the
    :func:`weibull_profile_sums` of all ``v`` added over the blocks. Equal to :func:`fit_weibull`
    of the values to the last bit when the blocks' sums are added in the same order."""
    return _drive(weibull_fit_steps(n, ymax, spread, sample), sums)


def weibull_fit_steps(
    n: int, ymax: float, spread: float, sample: np.ndarray
) -> Generator[float, np.ndarray, WeibullFit]:
    """:func:`weibull_fit_from_sums` as a generator: it yields each shape ``b`` it needs the
    :func:`weibull_profile_sums` of all values at, is sent them, and returns the fit (so that a
    campaign evaluates the fits of both axes in one pass over its station-days)."""
    b, iterations = _weibull_start(sample, n, spread)
    b, log_mean, it, converged = yield from _profile_root(n, spread, b)
    log_a = -(b * ymax + log_mean)
    return WeibullFit(math.exp(log_a), b, int(n), converged, iterations + it)


def fit_weibull(x: np.ndarray) -> WeibullFit:
    r"""Maximum-likelihood Weibull fit :math:`p(x) = a b x^{b-1} e^{-a x^b}` (Kannemans 2006, section 2.1.2).

    Parameters
    ----------
    x
        Protection levels, ``> 0``.

    Returns
    -------
    WeibullFit
        ML estimates (the same as ``scipy.stats.weibull_min.fit(x, floc=0)`` with ``c = b`` and
        ``scale = a**(-1/b)``, solved to near machine precision).

    Raises
    ------
    ValueError
        Not one-dimensional, fewer than two values, not finite or not ``> 0``, or all equal
        (the ML shape is then infinite).

    Notes
    -----
    With :math:`u_i = \ln x_i - \overline{\ln x}`, the likelihood equations reduce to the profile
    equation in :math:`b`,

    .. math::

        h(b) = \frac1b - \frac{\sum_i u_i e^{b u_i}}{\sum_i e^{b u_i}} = 0, \qquad
        a = \frac{n}{\sum_i x_i^b},

    (the :math:`\overline{\ln x}` of :math:`1/b + \overline{\ln x} - \sum x^b \ln x / \sum x^b`
    cancels). :math:`h'(b) = -1/b^2 - \mathrm{var}_b(u) < 0`, with :math:`h \to +\infty` as
    :math:`b \to 0` and :math:`h \to -\max u < 0` as :math:`b \to \infty`: one root. It is found by
    Halley steps (the weighted mean, variance and third central moment of :math:`u` give
    :math:`h, h', h''`), falling back to Newton and then to bisection of the bracket, with the weights
    :math:`e^{b(u - \max u)} \le 1` (no overflow). The start is :math:`b_0 = \pi/(\sqrt6\,s_u)`, exact
    for Weibull data (:math:`\mathrm{sd}(\ln x) = \pi/(b\sqrt6)`). Above 131072 values the root is
    first found on a regular subsample (every k-th value, about 65536), so that all values are
    visited only by the last evaluations, usually two (one ``exp``, two products and three sums each):
    about 0.4 s for :math:`8\times10^6` values.
    """
    a_ = _sample(x, "x", 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.log(a_)
        total = float(v.sum())
    if not math.isfinite(total):
        raise ValueError("x must be finite and > 0 for a Weibull fit")
    ybar, ymax = total / v.size, float(v.max())
    v -= ymax
    spread = ymax - ybar
    if not float(v.min()) < 0.0:
        raise ValueError("x is constant: the Weibull ML shape is infinite")
    sample = v[:: weibull_start_stride(v.size)]
    return weibull_fit_from_sums(v.size, ymax, spread, sample, functools.partial(weibull_profile_sums, v))


def _log_ax_b(fit: WeibullFit, x: np.ndarray) -> np.ndarray:
    r""":math:`\ln(a x^b)`, ``-inf`` at ``x <= 0``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(x > 0.0, math.log(fit.a) + fit.b * np.log(np.maximum(x, 0.0)), -np.inf)


def weibull_logsf(fit: WeibullFit, x: np.ndarray | float) -> np.ndarray:
    r"""Log survival :math:`\ln S(x) = -a x^b` (0 for :math:`x \le 0`); Kannemans 2006, section 2.1.2.

    :math:`S(AL)` is the unavailability (:math:`PL \ge AL` is unavailable, the convention of
    :mod:`overbound.methods.counting`). Raises ``ValueError`` on NaN.
    """
    return -np.exp(_log_ax_b(fit, _points(x, "x")))


def weibull_sf(fit: WeibullFit, x: np.ndarray | float) -> np.ndarray:
    r"""Survival :math:`S(x) = e^{-a x^b}`: ``exp`` of :func:`weibull_logsf`."""
    return np.exp(weibull_logsf(fit, x))


def weibull_logpdf(fit: WeibullFit, x: np.ndarray | float) -> np.ndarray:
    r"""Log density :math:`\ln a + \ln b + (b-1)\ln x - a x^b` (Kannemans 2006, section 2.1.2).

    ``-inf`` for :math:`x < 0`; at :math:`x = 0`: ``+inf`` (:math:`b < 1`), :math:`\ln a` (:math:`b = 1`)
    or ``-inf`` (:math:`b > 1`). Raises ``ValueError`` on NaN.
    """
    a = _points(x, "x")
    xp = np.maximum(a, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = math.log(fit.a) + math.log(fit.b) + special.xlogy(fit.b - 1.0, xp) - np.exp(_log_ax_b(fit, xp))
    return np.where(a >= 0.0, out, -np.inf)


def weibull_pdf(fit: WeibullFit, x: np.ndarray | float) -> np.ndarray:
    r"""Density :math:`a b x^{b-1} e^{-a x^b}`: ``exp`` of :func:`weibull_logpdf`."""
    return np.exp(weibull_logpdf(fit, x))


def weibull_covariance(fit: WeibullFit, x: np.ndarray, n_effective: float) -> np.ndarray:
    r"""Covariance of the ML estimates :math:`(\ln a, b)` from a decorrelated sample (Kannemans 2006, 2.1.2).

    Parameters
    ----------
    fit
        The ML fit of ``x`` (:func:`fit_weibull`).
    x
        The values fitted (``> 0``).
    n_effective
        Effective sample size of the PL series (its own decorrelation time, the paper's figure 8).

    Returns
    -------
    numpy.ndarray
        :math:`2\times2`, :math:`J^{-1}/n_e` with the observed information per sample

        .. math::

            J = \frac1n\sum_i \begin{pmatrix} a x_i^b & a x_i^b \ln x_i \\
                a x_i^b \ln x_i & 1/b^2 + a x_i^b \ln^2 x_i \end{pmatrix}

        (minus the mean Hessian of :math:`\ln a + \ln b + (b-1)\ln x - a x^b` in :math:`(\ln a, b)`).

    Raises
    ------
    ValueError
        ``x`` not finite or not ``> 0``, ``n_effective`` not finite and ``> 0``.
    """
    ne = float(n_effective)
    if not (math.isfinite(ne) and ne > 0.0):
        raise ValueError(f"n_effective must be finite and > 0, got {n_effective!r}")
    a_ = _sample(x, "x", 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        y = np.log(a_)
    if not math.isfinite(float(y.sum())):
        raise ValueError("x must be finite and > 0")
    return weibull_covariance_from_sums(fit, weibull_information_sums(y, fit), a_.size, ne)


def weibull_information_sums(y: np.ndarray, fit: WeibullFit) -> np.ndarray:
    r""":math:`\sum z_i`, :math:`\sum z_i y_i`, :math:`\sum z_i y_i^2` with :math:`y = \ln x`,
    :math:`z = a x^b`: the sums of the observed information of :func:`weibull_covariance`, which add
    over blocks of the values."""
    z = np.multiply(y, fit.b)
    z += math.log(fit.a)
    np.exp(z, out=z)  # a x^b
    s0 = float(z.sum())
    s1 = dot(z, y)
    z *= y
    return np.array([s0, s1, dot(z, y)])


def weibull_covariance_from_sums(fit: WeibullFit, sums: np.ndarray, n: int, n_effective: float) -> np.ndarray:
    """:func:`weibull_covariance` from the :func:`weibull_information_sums` of its ``n`` values."""
    ne = float(n_effective)
    if not (math.isfinite(ne) and ne > 0.0):
        raise ValueError(f"n_effective must be finite and > 0, got {n_effective!r}")
    s0, s1, s2 = (float(x) for x in sums)
    j11, j12 = s0 / n, s1 / n
    j22 = 1.0 / fit.b**2 + s2 / n
    return np.linalg.inv(np.array([[j11, j12], [j12, j22]])) / ne


def weibull_bound(
    fit: WeibullFit, cov: np.ndarray, alert_limit: float, confidence: float, *, dof: float | None = None
) -> WeibullFit:
    r"""Weibull parameters of the one-sided unavailability bound at an alert limit (Kannemans 2006, 2.1.2).

    Parameters
    ----------
    fit
        ML fit.
    cov
        Covariance of :math:`(\ln a, b)` (:func:`weibull_covariance`).
    alert_limit
        AL (same unit as the PL).
    confidence
        One-sided confidence :math:`c` (the paper's 95 %).
    dof
        Degrees of freedom of a Student :math:`t` quantile used in place of the normal one; ``None``:
        the normal (the paper's Wald bound). :func:`overbound.methods.parametric.parametric_analysis`
        passes :math:`n_e - 2`: the covariance is itself estimated from :math:`n_e` effective samples
        with two parameters, and on a campaign of few decorrelation times the normal quantile left the
        unavailability bound below the truth in 5.5-9 % of campaigns (validation/parametric_coverage.py,
        1800 s PL decorrelation over 6.5 h; 2-6 % with the t quantile) — the same small-sample
        reasoning as :func:`ratio_bound`'s :math:`t` and :math:`\chi^2` quantiles.

    Returns
    -------
    WeibullFit
        The point :math:`\theta_b` of the Wald ellipse of :math:`\theta = (\ln a, b)` where the
        linearised :math:`\ln S(AL)` is largest,

        .. math::

            \theta_b = \theta + z_c \frac{C g}{\sqrt{g^\top C g}}, \qquad
            g = \frac{\partial \ln S(AL)}{\partial \theta} = -a\,AL^b\,(1, \ln AL),

        :math:`z_c = \Phi^{-1}(c)` (or :math:`t_c(\nu)` with ``dof`` :math:`\nu`), so
        :math:`\ln S(AL;\theta_b) \approx \ln S(AL) + z_c\,\mathrm{sd}`.
        ``unavailability_bound = weibull_sf(bound, AL)``; the same parameters feed
        :func:`integrity_probabilities` at that AL. ``n``, ``converged``, ``iterations`` are the fit's.

    Raises
    ------
    ValueError
        Bad ``cov``, ``alert_limit``, ``confidence`` or ``dof``; or the bound point has :math:`b \le 0`
        or an :math:`a` that underflows or overflows (the effective sample is too small for this
        confidence: the linearisation is meaningless).
    """
    al = _alert_limit(alert_limit)
    if dof is None:
        zc = float(special.ndtri(_confidence(confidence)))
    elif math.isfinite(dof) and dof > 0.0:
        zc = float(stats.t.ppf(_confidence(confidence), dof))
    else:
        raise ValueError(f"dof must be finite and > 0, got {dof!r}")
    c = np.asarray(cov, dtype=np.float64)
    if c.shape != (2, 2) or not np.isfinite(c).all():
        raise ValueError(f"cov must be a finite 2x2 matrix, got shape {c.shape}")
    v = np.array([1.0, math.log(al)])  # g = -a AL^b v, and the direction only depends on v
    cv = c @ v
    var = float(v @ cv)
    if not var > 0.0:
        return fit
    d = -zc * cv / math.sqrt(var)
    b_b = fit.b + float(d[1])
    if not b_b > 0.0:
        raise ValueError(f"Weibull bound at confidence {confidence} has b <= 0: too few effective samples")
    ln_a_b = math.log(fit.a) + float(d[0])
    if not -745.0 < ln_a_b < 709.0:  # exp would underflow to 0 or overflow
        raise ValueError(
            f"Weibull bound at confidence {confidence} has a = exp({ln_a_b:.4g}), outside floating point: "
            "too few effective samples"
        )
    return WeibullFit(math.exp(ln_a_b), b_b, fit.n, fit.converged, fit.iterations)


def weibull_pdf_band(
    fit: WeibullFit, cov: np.ndarray, x: np.ndarray | float, confidence: float
) -> tuple[np.ndarray, np.ndarray]:
    r"""Pointwise two-sided band of the Weibull density (Kannemans 2006, figure 7, "confidence interval").

    Parameters
    ----------
    fit, cov
        ML fit and covariance of :math:`(\ln a, b)`.
    x
        Points (e.g. histogram bin centres).
    confidence
        Two-sided confidence :math:`c`.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        ``lo, hi`` = :math:`p(x)\,e^{\mp z\,\mathrm{sd}(x)}`, :math:`z = \Phi^{-1}((1+c)/2)`, with the
        delta-method :math:`\mathrm{sd}^2 = g^\top C g` of the log density,
        :math:`g = (1 - a x^b,\; 1/b + \ln x\,(1 - a x^b))`. At :math:`x \le 0` both equal the density.
    """
    a = _points(x, "x")
    z = float(special.ndtri(0.5 * (1.0 + _confidence(confidence))))
    c = np.asarray(cov, dtype=np.float64)
    if c.shape != (2, 2):
        raise ValueError(f"cov must be a 2x2 matrix, got shape {c.shape}")
    logp = weibull_logpdf(fit, a)
    pos = a > 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        lx = np.log(np.where(pos, a, 1.0))
        g0 = 1.0 - np.exp(_log_ax_b(fit, np.where(pos, a, 1.0)))
        g1 = 1.0 / fit.b + lx * g0
        sd = np.sqrt(np.maximum(c[0, 0] * g0 * g0 + 2.0 * c[0, 1] * g0 * g1 + c[1, 1] * g1 * g1, 0.0))
    half = np.where(pos, z * sd, 0.0)
    return np.exp(logp - half), np.exp(logp + half)


def _plot_ranks(n: int, max_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Thinned 0-based ranks (see :func:`weibull_plot_positions`) and their Bernard median ranks."""
    m = int(max_points)
    if m != max_points or m < 16:
        raise ValueError(f"max_points must be an integer >= 16, got {max_points!r}")
    if n <= m:
        ranks = np.arange(n, dtype=np.intp)
    else:
        q = m // 8
        pct = n // 100  # rank of the 1st percentile
        low = np.arange(min(q, pct), dtype=np.intp)
        if pct > q:
            low = np.concatenate([low, np.rint(np.geomspace(q, pct, q)).astype(np.intp)])
        mid = np.rint(np.linspace(pct, n - 1 - pct, m // 2)).astype(np.intp)
        ranks = np.unique(np.concatenate([low, mid, n - 1 - low]))
    return ranks, (ranks + 0.7) / (n + 0.4)


def weibull_plot_positions(x: np.ndarray, *, max_points: int = _PLOT_POINTS) -> tuple[np.ndarray, np.ndarray]:
    r"""Coordinates of the Weibull probability plot (Kannemans 2006, figure 6), thinned for large samples.

    Parameters
    ----------
    x
        Values ``> 0`` (PL).
    max_points
        Points returned at most (default 4000).

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        :math:`\ln x_{(i)}` and :math:`\ln(-\ln(1 - F_i))` with the Bernard median ranks
        :math:`F_i = (i - 0.3)/(n + 0.4)`, :math:`i = 1..n`, for a subset of the order statistics. A
        Weibull sample lies on the line :math:`\ln a + b \ln x`.

    Notes
    -----
    **Thinning** (so that a figure of :math:`8\times10^6` epochs stays light): with :math:`m` =
    ``max_points`` and at most :math:`n` points, the ranks kept are, on each side, all of the
    :math:`m/8` most extreme ones; from there to the 1st (99th) percentile :math:`m/8` ranks
    log-spaced in the distance to the end (so the tail looks as dense as the data in the plot's
    coordinates, where the ranks of the tail spread logarithmically); and :math:`m/2` ranks evenly
    spaced between the 1st and 99th percentiles. Below :math:`100\,m/8` values every point beyond the
    percentiles is kept; with :math:`n \le m`, every point. The sort is ``numpy.sort`` (about 0.2 s for
    :math:`8\times10^6` values).
    """
    a = _sample(x, "x", 1)
    if not float(a.min()) > 0.0:
        raise ValueError("x must be > 0 for a Weibull probability plot")
    ranks, f = _plot_ranks(a.size, max_points)
    return np.log(np.sort(a)[ranks]), np.log(-np.log1p(-f))


# ---------------------------------------------------------------------------------------------
# integrals (section 2.1.3)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class IntegrityProbabilities:
    r"""Per-epoch probabilities of one service at one alert limit (Kannemans 2006, section 2.1.3, figure 11).

    Attributes
    ----------
    p_mi : :math:`Q(1) = P(|PE| > PL)` (the ratio fit alone).
    p_hmi : :math:`P(PL < AL,\ |PE| > AL)`.
    p_mi_pl_above_al : :math:`P(PL \ge AL,\ |PE| > PL) = S(AL)\,Q(1)`.
    p_mi_pl_below_al : :math:`P(PL < AL,\ PL < |PE| \le AL)`.
    unavailability : :math:`S(AL) = P(PL \ge AL)`.
    log10_* : :math:`\log_{10}` of each (finite when the probability underflows to 0).

    ``p_mi = p_hmi + p_mi_pl_above_al + p_mi_pl_below_al``.
    """

    p_mi: float
    p_hmi: float
    p_mi_pl_above_al: float
    p_mi_pl_below_al: float
    unavailability: float
    log10_p_mi: float
    log10_p_hmi: float
    log10_p_mi_pl_above_al: float
    log10_p_mi_pl_below_al: float
    log10_unavailability: float


def _initial_panels(big_a: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Initial panels ``(lo, hi, side)``; ``side`` False: in :math:`\epsilon`, True: in :math:`\delta`."""

    def edges(start: float) -> np.ndarray:
        k = math.ceil(math.log(0.5 / start) / math.log(_PANEL_RATIO)) + 1
        return np.concatenate(([0.0], np.geomspace(start, 0.5, k)))

    e = edges(_PANEL_START)
    d = edges(max(_PANEL_START / max(big_a, 1.0), 1e-300))  # e^{-A delta} decays on the scale 1/A
    lo = np.concatenate([e[:-1], d[:-1]])
    hi = np.concatenate([e[1:], d[1:]])
    side = np.concatenate([np.zeros(e.size - 1, bool), np.ones(d.size - 1, bool)])
    return lo, hi, side


def _panel_log_integrals(lo, hi, side, log_integrand, rule) -> np.ndarray:
    """``ln`` of the Gauss-Legendre rule on each panel, with ``log_integrand(delta, ln delta)``."""
    xi, wi = rule
    t = lo[:, None] + (hi - lo)[:, None] * (xi + 1.0) / 2.0
    s = side[:, None]
    # each side's nodes are exact in its own variable: epsilon near PL = AL, delta near PL = 0
    delta = np.where(s, t, 1.0 - t)
    with np.errstate(divide="ignore"):
        logd = np.where(s, np.log(t), np.log1p(-t))
    logw = np.log((hi - lo)[:, None] * wi / 2.0)
    return special.logsumexp(logw + log_integrand(delta, logd), axis=1)


def _log_integral(big_a: float, log_integrand) -> float:
    r""":math:`\ln \int_0^1 e^{-A\delta}\, g\, d\epsilon` by the adaptive composite rule of
    :func:`integrity_probabilities` (``log_integrand`` includes :math:`-A\delta`)."""
    lo, hi, side = _initial_panels(big_a)
    done: list[np.ndarray] = []
    log_tol = math.log(_PANEL_RTOL)
    for _ in range(_PANEL_ROUNDS):
        fine = _panel_log_integrals(lo, hi, side, log_integrand, _GL_FINE)
        coarse = _panel_log_integrals(lo, hi, side, log_integrand, _GL_COARSE)
        total = float(special.logsumexp(np.concatenate([*done, fine])))
        with np.errstate(invalid="ignore", divide="ignore"):
            log_err = fine + np.log(np.abs(np.expm1(coarse - fine)))
        split = log_err > total + log_tol  # False for NaN / -inf (panels where both rules give 0)
        split[np.flatnonzero(split)[_PANEL_MAX_SPLIT:]] = False
        done.append(fine[~split])
        if not split.any():
            break
        lo, hi, side = lo[split], hi[split], side[split]
        mid = np.where(lo > 0.0, np.sqrt(lo * hi), hi * 1e-3)  # geometric halves; [0, h] -> [0, h/1000]
        lo, hi, side = np.concatenate([lo, mid]), np.concatenate([mid, hi]), np.concatenate([side, side])
    else:
        done.append(fine[split])  # rounds exhausted: keep the last estimates
    return float(special.logsumexp(np.concatenate(done)))


def integrity_probabilities(
    ratio: RatioFit, weibull: WeibullFit, alert_limit: float
) -> IntegrityProbabilities:
    r"""P_HMI, P_MI above and below the AL and the unavailability (Kannemans 2006, section 2.1.3).

    Parameters
    ----------
    ratio
        Ratio fit (or its bound, :func:`ratio_bound`).
    weibull
        PL fit (or its bound at this AL, :func:`weibull_bound`).
    alert_limit
        AL, same unit as the PL.

    Returns
    -------
    IntegrityProbabilities

    Raises
    ------
    ValueError
        ``alert_limit`` not finite and ``> 0``, or :math:`A = a\,AL^b > e^{700}` (unavailability below
        :math:`10^{-10^{303}}`).

    Notes
    -----
    Model: PL :math:`\sim` Weibull, :math:`r = PE/PL` independent of PL, :math:`Q(t) = P(|r| > t)`
    (the paper's three equations of section 2.1.3):

    .. math::

        P_{HMI} = \int_0^{AL} p_{PL}(x)\, Q(AL/x)\, dx, \quad
        P_{MI(PL>AL)} = S(AL)\,Q(1), \quad
        P_{MI(PL<AL)} = \int_0^{AL} p_{PL}(x)\,[Q(1) - Q(AL/x)]\, dx = F(AL)\,Q(1) - P_{HMI}.

    The last is integrated directly, with :math:`Q(1)\,(-\mathrm{expm1}(\ln Q(AL/x) - \ln Q(1)))`, so
    nothing cancels. **Numerics.** With :math:`A = a\,AL^b` and :math:`z = a x^b = A(1-\epsilon)`,
    :math:`p_{PL}(x)\,dx = e^{-z}dz` and :math:`AL/x = (1-\epsilon)^{-1/b}`:

    .. math::

        \int_0^{AL} p_{PL}(x)\, g(x)\, dx = A \int_0^1 e^{-A(1-\epsilon)}\,
            g\big(AL\,(1-\epsilon)^{1/b}\big)\, d\epsilon,

    which has no singularity at :math:`x = 0` for any :math:`b`. The :math:`P_{HMI}` integrand is
    concentrated within about :math:`b\sigma^2` of :math:`\epsilon = 0` (PL just below AL) while AL is
    within the PL distribution; :math:`e^{-A(1-\epsilon)}` concentrates it near :math:`\epsilon = 1`
    (:math:`\delta = 1 - \epsilon \sim 1/A`) when AL is far beyond it, and in between the two factors
    can make a narrow interior peak (e.g. NPA, HAL 556 m over HPLs of 10-20 m). So: composite 16-point
    Gauss-Legendre panels, initially geometric (ratio 2.7) from :math:`10^{-15}` to 1/2 in
    :math:`\epsilon` and from :math:`10^{-15}/\max(1, A)` to 1/2 in :math:`\delta` (each side's nodes
    exact in its own variable), then every panel whose 16- and 8-point values differ by more than
    :math:`10^{-11}` of the integral is split at its geometric midpoint, round after round (vectorised
    over panels; about 2 ms per call, 5 ms for NPA). All sums in log space (``logsumexp``). Relative error
    below :math:`10^{-9}` against ``scipy.integrate`` and against a 40-point rule with tolerance
    :math:`10^{-15}` over 300 random parameter sets (ratio sigma 0.003-0.5, Weibull shape 0.2-16, AL
    from 0.02 to 300 times the PL scale); where :math:`|\ln P|` is huge the error is that of the log
    itself (:math:`10^{-16}|\ln P|`).
    """
    al = _alert_limit(alert_limit)
    log_a = math.log(weibull.a) + weibull.b * math.log(al)  # ln A, never underflows
    if log_a > 700.0:
        raise ValueError(f"a * alert_limit**b = e^{log_a:.0f}: the alert limit is absurdly far beyond the PL")
    big_a = math.exp(log_a)
    logq1 = float(_log_q(ratio, np.float64(1.0)))

    def log_q_at(logd: np.ndarray) -> np.ndarray:
        with np.errstate(over="ignore"):
            return _log_q(ratio, np.exp(-logd / weibull.b))  # Q(AL/x), AL/x = delta^(-1/b) >= 1

    def hmi(delta: np.ndarray, logd: np.ndarray) -> np.ndarray:
        return -big_a * delta + log_q_at(logd)

    def below(delta: np.ndarray, logd: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore"):  # ln(1 - Q(AL/x)/Q(1)), no cancellation
            return -big_a * delta + np.log(-np.expm1(np.minimum(log_q_at(logd) - logq1, 0.0)))

    log_hmi = log_a + _log_integral(big_a, hmi)
    log_below = log_a + logq1 + _log_integral(big_a, below)
    logs = (logq1, log_hmi, -big_a + logq1, log_below, -big_a)
    return IntegrityProbabilities(*(math.exp(v) for v in logs), *(v / _LN10 for v in logs))


def pe_pl_density(
    ratio: RatioFit, weibull: WeibullFit, pl: np.ndarray | float, pe: np.ndarray | float
) -> np.ndarray:
    r"""Joint density of (PL, PE) of the contour figures (Kannemans 2006, figures 10 and 11).

    Parameters
    ----------
    ratio, weibull
        The two fits.
    pl
        PL values (broadcast against ``pe``).
    pe
        :math:`|VPE|` for a normal ratio fit (folded), HPE for a Rayleigh one.

    Returns
    -------
    numpy.ndarray
        :math:`f(x, y) = p_{PL}(x)\,p_r(y/x)/x` (PL and the ratio independent, section 2.1.3); 0 where
        ``pl <= 0`` or ``pe < 0``. Integrating it over the Stanford regions gives
        :func:`integrity_probabilities`.
    """
    x, y = np.broadcast_arrays(_points(pl, "pl"), _points(pe, "pe"))
    pos = x > 0.0
    xs = np.where(pos, x, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_f = weibull_logpdf(weibull, xs) + _log_ratio_pdf(ratio, y / xs) - np.log(xs)
    return np.where(pos, np.exp(log_f), 0.0)
