r"""Confidence level in a protection level: the (mu, sigma) uncertainty model of Comby et al. (2003).

Comby et al. 2003, section II.3 and appendix 2. A subset of :math:`n` independent errors (one PL
band) is summarised by its mean :math:`\hat m` and its inflated standard deviation
:math:`\hat\Sigma` (:func:`overbound.stats.overbounding.sigma_inflation`). The true mean
:math:`\mu` and standard deviation :math:`\sigma` of the (Gaussian-overbounded) error are then
treated as random,

.. math::

    \mu \sim N\big(\hat m, \hat\Sigma/\sqrt{n-2}\big) \;\text{(eq. (24))}, \qquad
    \frac{(n-1)\hat\Sigma^2}{\sigma^2} \sim \chi^2_{n-1} \;\text{(eqs. (25)-(29))},

independent (eq. (30)), and the *confidence level* in the subset's PLs is the probability that
they meet the per-sample integrity risk, :math:`CL = P\{g(\mu, \sigma) \le R_n\}` (eqs. (33)-(34)).

Public functions: :func:`exceedance` (eq. (43)), :func:`ideal_pl` (eqs. (8)-(9)),
:func:`confidence_level` (eq. (34), exact one-dimensional form), :func:`pl_at_confidence` (the PL1 /
PL99 of section III.3) and :func:`confidence_level_bruteforce` (eq. (34) integrated in two
dimensions, the reference for tests and benchmarks). ``axis="horizontal"`` is this package's
analogue for the HPL, which the paper leaves open (see :func:`confidence_level`, Notes).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy import integrate, optimize, special, stats

from overbound.stats.sums import dot, vecmat

__all__ = [
    "AXES",
    "confidence_level",
    "confidence_level_bruteforce",
    "exceedance",
    "ideal_pl",
    "pl_at_confidence",
]

#: Axes understood by every function of this module.
AXES = ("vertical", "horizontal")

#: Half-width of the integration range of the mean, in its standard deviations; the Gaussian
#: (vertical) or two-dimensional Gaussian (horizontal) mass beyond it is below 3e-18.
_MEAN_SPAN = 9.0
#: Quadrature weights below this are dropped (their total is below 1e-16).
_WEIGHT_FLOOR = 1e-18
#: Points per panel of the composite Gauss-Legendre rule over the mean.
_PANEL_POINTS = 16
#: Relative step at which the Halley iteration for s*(mu) stops (the error is then ~ its cube).
_STEP_RTOL = 1e-5
_MAXITER = 200
#: PLs are merged into this many groups to find a starting point for the iteration.
_SURROGATE_GROUPS = 64
#: The Halley sums run over blocks of this many distinct PLs: 2 MiB arrays at 64 nodes, where a band
#: of 60 k PLs took 300 MB at once, measured (the sums of the blocks are added in block order).
_PL_BLOCK = 4096
_SQRT_2PI = math.sqrt(2.0 * math.pi)


# ---------------------------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------------------------


def _validate_axis(axis: str) -> str:
    if axis not in AXES:
        raise ValueError(f"axis must be one of {AXES}, got {axis!r}")
    return axis


def _validate_risk(risk: float) -> float:
    risk = float(risk)
    if not 0.0 < risk < 1.0:
        raise ValueError(f"risk must lie in (0, 1), got {risk}")
    return risk


def _validate_model(mean: float, sigma: float, n: int, risk: float) -> tuple[float, float, int, float]:
    mean, sigma = float(mean), float(sigma)
    if not math.isfinite(mean):
        raise ValueError(f"mean must be finite, got {mean}")
    if not (math.isfinite(sigma) and sigma > 0.0):
        raise ValueError(f"sigma must be finite and > 0, got {sigma}")
    if int(n) != n or n < 3:
        raise ValueError(f"n must be an integer >= 3 (the mean model uses n - 2), got {n}")
    risk = _validate_risk(risk)
    if _allowed_risk(int(n), risk) >= 0.5:
        raise ValueError(
            f"R_n = 1 - (1 - risk)^n = {_allowed_risk(int(n), risk):.3g} >= 1/2: the model needs R_n < 1/2"
        )
    return mean, sigma, int(n), risk


def _validate_pl(pl: np.ndarray | float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Sorted distinct PLs and their counts; a scalar means the same PL for all n samples."""
    values = np.asarray(pl, dtype=float)
    if values.ndim == 0:
        values = np.full(n, float(values))
    if values.ndim != 1 or values.size != n:
        raise ValueError(f"pl must be a scalar or hold n = {n} values, got shape {values.shape}")
    if not np.all(np.isfinite(values)) or np.any(values <= 0.0):
        raise ValueError("protection levels must be finite and > 0")
    levels, counts = np.unique(values, return_counts=True)
    return levels, counts.astype(float)


def _validate_nodes(nodes: int) -> int:
    if int(nodes) != nodes or nodes < _PANEL_POINTS or nodes % _PANEL_POINTS:
        raise ValueError(f"nodes must be a positive multiple of {_PANEL_POINTS}, got {nodes}")
    return int(nodes)


# ---------------------------------------------------------------------------------------------
# exceedance and ideal PL
# ---------------------------------------------------------------------------------------------


def _allowed_risk(n: float, risk: float) -> float:
    """R_n = 1 - (1 - risk)^n, eq. (41)."""
    return float(-np.expm1(n * np.log1p(-risk)))


def _exceedance(pl: np.ndarray, r: np.ndarray, sigma: np.ndarray, axis: str) -> np.ndarray:
    """P(|PE| > pl) for |mean| = r >= 0; no validation, broadcasting."""
    if axis == "vertical":
        return special.ndtr((r - pl) / sigma) + special.ndtr((-pl - r) / sigma)
    b2 = (pl / sigma) ** 2
    a2 = (r / sigma) ** 2
    with np.errstate(invalid="ignore"):
        rice = stats.ncx2.sf(b2, 2.0, np.where(a2 > 0.0, a2, 1.0))
    return np.where(a2 > 0.0, rice, np.exp(-0.5 * b2))


def exceedance(
    pl: np.ndarray | float,
    *,
    mean: np.ndarray | float,
    sigma: np.ndarray | float,
    axis: str = "vertical",
) -> np.ndarray:
    r"""Probability that the error exceeds the protection level, :math:`P(|PE| > PL \mid \mu, \sigma)`.

    Comby et al. 2003, eq. (43) (vertical); its Rice analogue for the horizontal.

    Parameters
    ----------
    pl
        Protection levels (>= 0), broadcast against ``mean`` and ``sigma``.
    mean
        Vertical: signed mean :math:`\mu` of the error. Horizontal: length :math:`|\mu|` of the mean
        error vector (its sign is ignored).
    sigma
        Standard deviation (> 0) of the error (per component for the horizontal).
    axis
        ``"vertical"`` or ``"horizontal"``.

    Returns
    -------
    numpy.ndarray
        The exceedance probability, broadcast shape.

    Notes
    -----
    Vertical, for :math:`PE \sim N(\mu, \sigma^2)`:

    .. math:: P = \Phi\Big(\frac{\mu - PL}{\sigma}\Big) + \Phi\Big(\frac{-PL - \mu}{\sigma}\Big),

    both terms by ``scipy.special.ndtr`` of (in the tail) negative arguments, so probabilities down to
    1e-300 keep full relative accuracy (eq. (43)'s :math:`1 - \mathrm{erf}` form would cancel).

    Horizontal, for a 2-D error :math:`N(\boldsymbol\mu, \sigma^2 I)`, :math:`HPE^2/\sigma^2` is
    non-central :math:`\chi^2_2` with non-centrality :math:`|\mu|^2/\sigma^2` (Rice):
    :math:`P = Q_1(|\mu|/\sigma, PL/\sigma)` = ``scipy.stats.ncx2.sf`` (Boost, accurate in the far tail);
    for :math:`\mu = 0` the closed form :math:`\exp(-PL^2/(2\sigma^2))`.

    Examples
    --------
    >>> float(exceedance(5.326723886, mean=0.0, sigma=1.0))  # K_V of DO-229
    1.0000...e-07
    >>> float(exceedance(1.0, mean=0.0, sigma=1.0, axis="horizontal"))  # exp(-1/2)
    0.6065...
    """
    axis = _validate_axis(axis)
    pl_ = np.asarray(pl, dtype=float)
    sigma_ = np.asarray(sigma, dtype=float)
    mean_ = np.asarray(mean, dtype=float)
    if np.any(pl_ < 0.0):
        raise ValueError("protection levels must be >= 0")
    if np.any(~(sigma_ > 0.0)):
        raise ValueError("sigma must be > 0")
    r = np.abs(mean_)
    return _exceedance(pl_, r, sigma_, axis)


def _log_exceedance_vertical(pl: float, r: float, sigma: float) -> float:
    return float(np.logaddexp(special.log_ndtr((r - pl) / sigma), special.log_ndtr((-pl - r) / sigma)))


def _tail_quantiles(risk: float, axis: str) -> tuple[float, float]:
    """(z_lo, z_hi) with |mu| + sigma z_lo <= ideal PL <= |mu| + sigma z_hi.

    Vertical: Phibar((L-r)/s) <= P <= 2 Phibar((L-r)/s). Horizontal: the half-plane bound
    P >= Phibar((L-r)/s) and the disc bound P <= P(s|Z_2| > L - r) = exp(-(L-r)^2/(2 s^2)).
    """
    z_lo = float(-special.ndtri(risk))
    z_hi = float(-special.ndtri(0.5 * risk)) if axis == "vertical" else math.sqrt(-2.0 * math.log(risk))
    return z_lo, z_hi


def ideal_pl(*, mean: float, sigma: float, risk: float = 1e-7, axis: str = "vertical") -> float:
    r"""The ideal protection level: the PL whose exceedance probability equals ``risk``.

    Comby et al. 2003, eqs. (8)-(9) (vertical); the Rice analogue for the horizontal.

    Parameters
    ----------
    mean
        Mean of the error (vertical, signed) or length of the mean error vector (horizontal).
    sigma
        Standard deviation (> 0).
    risk
        Per-sample integrity risk in (0, 1).
    axis
        ``"vertical"`` or ``"horizontal"``.

    Returns
    -------
    float
        :math:`L` with :math:`P(|PE| > L \mid \mu, \sigma) = ` ``risk`` (:func:`exceedance`).

    Notes
    -----
    The exceedance decreases strictly in :math:`L`, and (with :math:`r = |\mu|`)
    :math:`r + \sigma z_\mathrm{lo} \le L \le r + \sigma z_\mathrm{hi}`, where
    :math:`z_\mathrm{lo} = -\Phi^{-1}(\mathrm{risk})` and :math:`z_\mathrm{hi} = -\Phi^{-1}(\mathrm{risk}/2)`
    (vertical: one tail :math:`\le P \le` twice that tail) or :math:`\sqrt{-2\ln \mathrm{risk}}`
    (horizontal: half-plane and disc bounds). ``brentq`` solves
    :math:`\ln P(L) = \ln \mathrm{risk}` in this bracket to ~1e-15 relative. For :math:`\mu = 0` the
    closed forms :math:`\sigma\,(-\Phi^{-1}(\mathrm{risk}/2))` (:math:`K_V = 5.3267` for 1e-7) and
    :math:`\sigma\sqrt{-2\ln \mathrm{risk}}` (5.6777 for 1e-7) are returned.

    Examples
    --------
    >>> round(ideal_pl(mean=0.0, sigma=1.0), 4)
    5.3267
    >>> round(ideal_pl(mean=0.0, sigma=1.0, axis="horizontal"), 4)
    5.6777
    """
    axis = _validate_axis(axis)
    risk = _validate_risk(risk)
    mean, sigma = float(mean), float(sigma)
    if not (math.isfinite(mean) and math.isfinite(sigma) and sigma > 0.0):
        raise ValueError(f"need a finite mean and a finite sigma > 0, got {mean}, {sigma}")
    return _ideal_pl(abs(mean), sigma, risk, axis)


def _ideal_pl(r: float, sigma: float, risk: float, axis: str) -> float:
    z_lo, z_hi = _tail_quantiles(risk, axis)
    if r == 0.0:
        return sigma * z_hi
    log_risk = math.log(risk)
    if axis == "vertical":

        def f(pl: float) -> float:
            return _log_exceedance_vertical(pl, r, sigma) - log_risk
    else:

        def f(pl: float) -> float:
            return float(stats.ncx2.logsf((pl / sigma) ** 2, 2.0, (r / sigma) ** 2)) - log_risk

    lo, hi = r + sigma * z_lo, r + sigma * z_hi
    if f(lo) <= 0.0:
        return lo
    if f(hi) >= 0.0:
        return hi
    return float(optimize.brentq(f, lo, hi, xtol=1e-15 * hi, rtol=4.0 * np.finfo(float).eps, maxiter=200))


# ---------------------------------------------------------------------------------------------
# the one-dimensional confidence level
# ---------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=16)
def _panel_rule(nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Composite Gauss-Legendre rule on [-1, 1]: nodes/16 equal panels of 16 points."""
    panels = nodes // _PANEL_POINTS
    x, w = np.polynomial.legendre.leggauss(_PANEL_POINTS)
    centres = -1.0 + (2.0 * np.arange(panels) + 1.0) / panels
    xs = (centres[:, None] + x / panels).ravel()
    ws = np.tile(w / panels, panels)
    xs.flags.writeable = False
    ws.flags.writeable = False
    return xs, ws


def _rice_pdf(r: np.ndarray, r0: float, tau: float) -> np.ndarray:
    """Density of |mu| for mu ~ N(mu0, tau^2 I_2), |mu0| = r0 (i0e keeps it finite)."""
    return r / tau**2 * np.exp(-0.5 * ((r - r0) / tau) ** 2) * special.i0e(r * r0 / tau**2)


def _mean_rule(
    mean: float, tau: float, nodes: int, axis: str, cutoff: float
) -> tuple[np.ndarray, np.ndarray]:
    """Nodes r = |mu| and weights of the quadrature over the mean's law, restricted to |mu| < cutoff.

    Composite Gauss-Legendre (panels of 16 points) on the support of the integrand: vertical,
    mu in [max(mean - 9 tau, -cutoff), min(mean + 9 tau, cutoff)] against the normal density of
    eq. (24); horizontal, the radius |mu| in [max(0, |mean| - 9 tau), min(|mean| + 9 tau, cutoff)]
    against the Rice density. Weights below 1e-18 are dropped.
    """
    if axis == "vertical":
        a, b = max(mean - _MEAN_SPAN * tau, -cutoff), min(mean + _MEAN_SPAN * tau, cutoff)
    else:
        a, b = max(0.0, abs(mean) - _MEAN_SPAN * tau), min(abs(mean) + _MEAN_SPAN * tau, cutoff)
    if b <= a:
        return np.zeros(0), np.zeros(0)
    x, w = _panel_rule(nodes)
    mu = 0.5 * (a + b) + 0.5 * (b - a) * x
    if axis == "vertical":
        density = np.exp(-0.5 * ((mu - mean) / tau) ** 2) / (tau * _SQRT_2PI)
    else:
        density = _rice_pdf(mu, abs(mean), tau)
    weights = 0.5 * (b - a) * w * density
    keep = weights > _WEIGHT_FLOOR
    return np.abs(mu[keep]), weights[keep]


def _exceedance_dw(
    pl: np.ndarray, r: np.ndarray, w: np.ndarray, axis: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exceedance P(pl; r, 1/w) and its first two derivatives in w = 1/sigma; pl (k, 1), r, w (m,)."""
    if axis == "vertical":
        dm, dp = pl - r, pl + r
        a, b = dm * w, dp * w
        phi_a = np.exp(-0.5 * a * a) / _SQRT_2PI
        phi_b = np.exp(-0.5 * b * b) / _SQRT_2PI
        p = special.ndtr(-a) + special.ndtr(-b)
        d1 = -(dm * phi_a + dp * phi_b)
        d2 = dm * dm * a * phi_a + dp * dp * b * phi_b
        return p, d1, d2
    # Q1(a, b), a = r w, b = pl w: dQ1/dw = pl E [r I1(u) - pl I0(u)] w, E = exp(-(a^2+b^2)/2),
    # u = ab; products E I(u) are formed with exponentially scaled Bessels.
    p = _exceedance(pl, r, 1.0 / w, "horizontal")
    a, b = r * w, pl * w
    u = a * b
    scale = np.exp(-0.5 * (a - b) ** 2)
    e_i0 = scale * special.i0e(u)
    e_i1 = scale * special.i1e(u)
    bracket = r * e_i1 - pl * e_i0
    d1 = b * bracket
    pw2 = pl * w * w
    d2 = pl * (
        bracket * (1.0 - (r * r + pl * pl) * w * w)
        + 2.0 * r * r * pw2 * e_i0
        - 2.0 * r * e_i1
        - 2.0 * r * pl * pw2 * e_i1
    )
    return p, d1, d2


def _compress(levels: np.ndarray, counts: np.ndarray, groups: int) -> tuple[np.ndarray, np.ndarray]:
    """Count-weighted mean PL of ``groups`` consecutive groups of equal total count (a surrogate)."""
    cum = np.cumsum(counts)
    group = np.minimum((groups * (cum - 0.5 * counts) / cum[-1]).astype(int), groups - 1)
    total = np.bincount(group, weights=counts, minlength=groups)
    keep = total > 0
    mean = np.bincount(group, weights=counts * levels, minlength=groups)[keep] / total[keep]
    return mean, total[keep]


def _h_sums(
    levels: np.ndarray, counts: np.ndarray, r: np.ndarray, w: np.ndarray, axis: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """h(w) = sum_i c_i log1p(-P_i) and its first two derivatives in w, per node, summed over blocks of
    :data:`_PL_BLOCK` PLs in order (one block: the plain sums; memory bounded by one block)."""
    h, h1, h2 = (np.zeros(w.shape) for _ in range(3))
    for start in range(0, levels.size, _PL_BLOCK):
        block = slice(start, start + _PL_BLOCK)
        c = counts[block]
        p, d1, d2 = _exceedance_dw(levels[block, None], r, w, axis)
        q = 1.0 / (1.0 - p)
        h += vecmat(c, np.log1p(-p))
        h1 -= vecmat(c, d1 * q)
        h2 -= vecmat(c, (d2 + d1 * d1 * q) * q)
    return h, h1, h2


def _halley(
    levels: np.ndarray,
    counts: np.ndarray,
    r: np.ndarray,
    log_target: float,
    w: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    axis: str,
) -> np.ndarray:
    """Safeguarded Halley iteration on psi(w) = log(-h(w)) - log_target, vectorised over nodes."""
    done = np.zeros(w.shape, dtype=bool)
    for _ in range(_MAXITER):
        h, h1, h2 = _h_sums(levels, counts, r, w, axis)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            psi = np.where(h < 0.0, np.log(-h) - log_target, -np.inf)
            psi1 = h1 / h
            psi2 = h2 / h - psi1 * psi1
            denom = 2.0 * psi1 * psi1 - psi * psi2
            step = np.where(denom > 0.0, -2.0 * psi * psi1 / denom, -psi / psi1)
            w_new = w + step
        # psi > 0: -h too large, sigma too large, the root lies at larger w (psi == 0: w is the root)
        lo = np.where(psi >= 0.0, w, lo)
        hi = np.where(psi <= 0.0, w, hi)
        bad = ~np.isfinite(w_new) | (w_new < lo) | (w_new > hi)
        w_new = np.where(bad, np.sqrt(lo * hi), w_new)
        # Halley converges cubically (relative error e -> ~e^3/4 here): a relative step below 1e-5
        # leaves an error below ~1e-15.
        done |= ~bad & (np.abs(w_new - w) <= _STEP_RTOL * w)
        w = np.where(done, np.where(np.isfinite(w_new), w_new, w), w_new)
        if done.all():
            break
    return w


def _solve_w(levels: np.ndarray, counts: np.ndarray, r: np.ndarray, risk: float, axis: str) -> np.ndarray:
    r"""w* = 1/s*(r) solving sum_i c_i log1p(-P_i(r, 1/w)) = (sum c_i) log1p(-risk), for r < min PL.

    Safeguarded Halley iteration on psi(w) = log(-h(w)) - log(-T), vectorised over the nodes: the
    bracket [z_lo/(max PL - r), z_hi/(min PL - r)] (all P_i >= risk at its left end, all <= risk at
    its right end) shrinks at every evaluation, and a step leaving it is replaced by bisection
    (geometric mean). The start is the root for a surrogate of at most 64 count-weighted group
    means of the PLs (itself started at the right end of the bracket, the single-PL bound of the
    smallest PL), which for PLs of one band is within ~1e-6 of the root, so that the full sum is
    usually evaluated once or twice.
    """
    n = counts.sum()
    log_target = math.log(-n * math.log1p(-risk))
    z_lo, z_hi = _tail_quantiles(risk, axis)
    lo = z_lo / (levels[-1] - r)
    hi = z_hi / (levels[0] - r)
    w = hi.copy()
    if levels.size > _SURROGATE_GROUPS:
        rep, rep_counts = _compress(levels, counts, _SURROGATE_GROUPS)
        w = _halley(rep, rep_counts, r, log_target, w, lo.copy(), hi.copy(), axis)
    return _halley(levels, counts, r, log_target, w, lo, hi, axis)


def _f_sigma(s: np.ndarray, n: int, sigma_hat: float) -> np.ndarray:
    """F_sigma(s) = P(sigma <= s) = chi2_{n-1}.sf((n-1) Sigma^2 / s^2), eq. (28)."""
    with np.errstate(divide="ignore"):
        return special.chdtrc(n - 1, (n - 1) * (sigma_hat / s) ** 2)


def _support_edge(min_pl: float, samples: float, n: int, sigma_hat: float, risk: float) -> float:
    """|mu| beyond which F_sigma(s*(mu)) < 1e-18: the integrand's effective support.

    g >= P(min PL) >= Phibar((min PL - r)/s) (one tail, or the half-plane bound horizontally), so
    g <= R_n needs s* <= (min PL - r)/z(R_n); and F_sigma(s) < 1e-18 for s < s_eps, the 1e-18
    quantile of sigma. Stopping the quadrature there keeps it away from the non-analytic point
    |mu| = min PL, where F_sigma(s*) vanishes like exp(-c/(min PL - |mu|)^2).
    """
    z_rn = -special.ndtri(_allowed_risk(samples, risk))
    s_eps = sigma_hat * math.sqrt((n - 1) / special.chdtri(n - 1, _WEIGHT_FLOOR))
    return float(min_pl - z_rn * s_eps)


def _confidence(
    levels: np.ndarray,
    counts: np.ndarray,
    mean: float,
    nodes: int,
    n: int,
    sigma_hat: float,
    risk: float,
    axis: str,
) -> float:
    tau = sigma_hat / math.sqrt(n - 2)
    edge = _support_edge(float(levels[0]), float(counts.sum()), n, sigma_hat, risk)
    r, weights = _mean_rule(mean, tau, nodes, axis, edge)
    if r.size == 0:
        return 0.0
    w = _solve_w(levels, counts, r, risk, axis)
    f = _f_sigma(1.0 / w, n, sigma_hat)
    return float(np.clip(dot(weights, f), 0.0, 1.0))


def confidence_level(
    pl: np.ndarray | float,
    *,
    mean: float,
    sigma: float,
    n: int,
    risk: float = 1e-7,
    axis: str = "vertical",
    nodes: int = 64,
) -> float:
    r"""Confidence level in a subset's protection levels, :math:`CL = P\{g(\mu, \sigma) \le R_n\}`.

    Comby et al. 2003, appendix 2, eqs. (24)-(46), computed exactly as a one-dimensional integral.

    Parameters
    ----------
    pl
        The subset's own protection levels, ``n`` values (> 0); a scalar stands for ``n`` equal PLs.
    mean
        :math:`\hat m`. Vertical: the signed sample mean of the errors. Horizontal: the length
        :math:`|\hat m| = \mathrm{hypot}(\hat m_E, \hat m_N)` of the signed east/north sample means.
    sigma
        :math:`\hat\Sigma`, the inflated standard deviation
        (:func:`~overbound.stats.overbounding.sigma_inflation`). Horizontal:
        :math:`\max(\hat\Sigma_E, \hat\Sigma_N)`.
    n
        Number of independent samples, >= 3, with :math:`R_n < 1/2`.
    risk
        Integrity risk per independent sample (1e-7, eq. (7)).
    axis
        ``"vertical"`` or ``"horizontal"``.
    nodes
        Quadrature nodes over the mean, a multiple of 16 (composite Gauss-Legendre, 16 per panel).

    Returns
    -------
    float
        CL in [0, 1].

    Raises
    ------
    ValueError
        Invalid inputs (``pl`` not of length ``n``, a PL <= 0, ``sigma`` <= 0, ``n`` < 3, ``risk``
        outside (0, 1) or :math:`R_n \ge 1/2`, unknown axis).

    See Also
    --------
    confidence_level_bruteforce : the same number by two-dimensional integration of eq. (34).
    pl_at_confidence : the constant PL that has a given confidence level.

    Notes
    -----
    **Model.** :math:`P_i(\mu, \sigma) = P(|PE| > PL_i)` (eq. (43), :func:`exceedance`),
    :math:`g = 1 - \prod_i (1 - P_i)` (eq. (44)), :math:`R_n = 1 - (1 - \mathrm{risk})^n` (eq. (41)),
    :math:`f_\mu` of eq. (24), :math:`F_\sigma(s) = \chi^2_{n-1}.\mathrm{sf}((n-1)\hat\Sigma^2/s^2)`
    (eq. (28)), and :math:`CL = \iint_D f_\mu f_\sigma` with :math:`D = \{g \le R_n\}` (eq. (34)).
    The condition is evaluated as :math:`h = \sum_i \log(1 - P_i) \ge n \log(1 - \mathrm{risk})`
    (``log1p``), which keeps full accuracy where :math:`g` and :math:`R_n` are ~1e-5.

    **Why it is one-dimensional.** Write :math:`r = |\mu|` (vertical: :math:`P_i` depends on
    :math:`\mu` only through :math:`|\mu|`, which makes CL symmetric under
    :math:`\hat m \to -\hat m`).

    * If :math:`r < \min PL_i`, every :math:`P_i` increases strictly with :math:`\sigma`. Vertical:
      :math:`\partial P/\partial\sigma = (a\varphi(a) + b\varphi(b))/\sigma` with
      :math:`a = (PL - \mu)/\sigma > 0`, :math:`b = (PL + \mu)/\sigma > 0`. Horizontal:
      :math:`\partial Q_1(r/\sigma, PL/\sigma)/\partial\sigma = b\,e^{-(a^2+b^2)/2}
      [PL\, I_0(ab) - r\, I_1(ab)]/\sigma^2 > 0` since :math:`PL > r` and :math:`I_0 > I_1`. So
      :math:`g` increases from 0 (:math:`\sigma \to 0`) to 1 (:math:`\sigma \to \infty`, every
      :math:`P_i \to 1`) and :math:`g = R_n` has exactly one root :math:`s^*(\mu)`;
      :math:`D = \{\sigma \le s^*(\mu)\}`.
    * If :math:`r \ge \min PL_i`, the smallest PL has :math:`P \ge 1/2` for every :math:`\sigma`
      (vertical: the mean lies beyond it; horizontal: the half-plane beyond the mean already has
      probability 1/2), so :math:`g \ge 1/2 > R_n`: no :math:`\sigma` qualifies (eq. (46), sharpened
      from the largest to the smallest PL). :math:`F_\sigma(s^*) \to 0` continuously as
      :math:`r \uparrow \min PL_i`, so the integrand is smooth at this edge.

    Hence

    .. math::

        CL = \int f_\mu(\mu)\, F_\sigma\big(s^*(\mu)\big)\, d\mu,
        \qquad s^* = 0 \text{ for } |\mu| \ge \min PL_i.

    **Algorithm.**

    1. Quadrature over the mean on the effective support of the integrand (below),
       :math:`\mu \in [\max(\hat m - 9\tau, -e), \min(\hat m + 9\tau, e)]`,
       :math:`\tau = \hat\Sigma/\sqrt{n-2}` (Gaussian mass outside the :math:`\pm 9\tau` span below
       3e-19), by a composite Gauss-Legendre rule of
       ``nodes/16`` equal panels of 16 points against the normal density of eq. (24); weights below
       1e-18 are dropped.
    2. For all nodes at once, solve :math:`\ln(-h) = \ln(-n\ln(1-\mathrm{risk}))` for
       :math:`w = 1/s` by Halley's method, safeguarded by the bracket
       :math:`[z_\mathrm{lo}/(\max PL - r),\, z_\mathrm{hi}/(\min PL - r)]` (every :math:`P_i \ge`
       risk at one end, :math:`\le` risk at the other, see :func:`ideal_pl`) with bisection when a step
       leaves it. Equal PLs are merged with their counts first; the start is the root for at most 64
       count-weighted group means of the PLs (itself started from the single-PL bound of the smallest
       PL). The iteration stops when a Halley step is below 1e-5 relative, which leaves a relative
       error below ~1e-15 (cubic convergence, tested to 1e-12).
    3. :math:`CL = \sum_k w_k F_\sigma(s^*_k)`.

    *Why not Gauss-Hermite over the whole line.* :math:`F_\sigma(s^*(\mu))` vanishes like
    :math:`\exp(-c/(\min PL - |\mu|)^2)` at the edge of the support: smooth but not analytic. When
    that edge lies inside the bulk of the mean's law (few samples, PL a few :math:`\tau` from
    :math:`\hat m`), 64-node Gauss-Hermite is off by up to 2e-7 (n = 5) or 3e-5 (n = 3). The composite
    rule stops at :math:`|\mu| = \min PL - z(R_n)\,s_\epsilon`, beyond which the integrand is below
    1e-18 (:math:`s^* \le (\min PL - |\mu|)/z(R_n)` because :math:`g \ge P(\min PL)`, and
    :math:`F_\sigma(s_\epsilon) = 10^{-18}`), away from that point. For :math:`n \ge 30` both rules
    agree to 1e-15.

    **Horizontal analogue** (the paper leaves the HPL open). The error is modelled as an isotropic
    2-D Gaussian :math:`N(\boldsymbol\mu, \sigma^2 I)`, :math:`P_i = Q_1(|\mu|/\sigma, HPL_i/\sigma)`
    (Rice). Inputs: ``mean`` :math:`= |\hat m|` of the east/north sample means and
    ``sigma`` :math:`= \max(\hat\Sigma_E, \hat\Sigma_N)`. Each component mean is modelled as
    :math:`N(\hat m_c, \hat\Sigma/\sqrt{n-2})` like eq. (24), so :math:`|\mu|` is Rice distributed
    with offset :math:`|\hat m|` and scale :math:`\tau`; the integral runs over the radius with the
    same composite Gauss-Legendre rule on :math:`[\max(0, |\hat m| - 9\tau), \min(|\hat m| + 9\tau,
    \min HPL)]` against the Rice density (:math:`|\mu - \hat m| > 9\tau` has probability
    :math:`e^{-81/2} < 3\times 10^{-18}`). :math:`\sigma` keeps the
    :math:`\chi^2_{n-1}` law of eq. (25) with :math:`\hat\Sigma = \max(\hat\Sigma_E, \hat\Sigma_N)`.

    *How conservative this is, and its limits.* (a) With independent components of standard
    deviations :math:`\sigma_E, \sigma_N \le \sigma` and a zero mean,
    :math:`|(\sigma_E Z_E, \sigma_N Z_N)| \le \sigma |Z|` pointwise, so the isotropic model bounds
    :math:`P(HPE > L)` for every :math:`L`. (b) With a mean offset the isotropic error is the true one
    plus independent zero-mean noise along the smaller axis, so it averages the true exceedance over
    shifted means; by Jensen's inequality this is an upper bound where the exceedance is convex in the
    mean over the range the noise explores, as it is in the far tail (:math:`L - |\mu|` several
    :math:`\sigma`, the regime of a 1e-7 PL; checked numerically in the tests). It is an argument, not
    a proof: it fails e.g. for a mean outside the PL, a region that contributes nothing to CL.
    (c) Strongly unequal components make the model pessimistic (the larger sigma is used for both).
    (d) Correlated east/north errors are not covered: the isotropic bound then needs :math:`\sigma`
    to bound the square root of the covariance's largest eigenvalue, not the larger component.
    (e) Using :math:`n-1` degrees of
    freedom (not the :math:`2(n-1)` of a pooled two-component estimate) does not understate the
    uncertainty of :math:`\sigma`; this is conservative where CL is above about one half (the CLs that
    would vouch for a PL) and errs upwards for very low CLs.

    **Accuracy** (tested). 64 nodes agree with 128 to 1e-10 for :math:`n \ge 10`, to 3e-9 for
    :math:`3 \le n < 10`, to 1e-15 for :math:`n \ge 30`, and with the two-dimensional integration of eq. (34)
    (:func:`confidence_level_bruteforce`) to 1e-6.

    References
    ----------
    .. [1] D. Comby, R. Farnworth, C. Macabiau, "EGNOS vertical protection level assessment",
       ION GPS/GNSS 2003, appendix 2, eqs. (17)-(46).

    Examples
    --------
    >>> round(confidence_level(10.0, mean=0.3, sigma=2.0, n=300), 4)
    0.0288
    >>> round(confidence_level(11.5, mean=0.3, sigma=2.0, n=300, axis="horizontal"), 4)
    0.5464
    """
    axis = _validate_axis(axis)
    mean, sigma, n, risk = _validate_model(mean, sigma, n, risk)
    nodes = _validate_nodes(nodes)
    levels, counts = _validate_pl(pl, n)
    return _confidence(levels, counts, mean, nodes, n, sigma, risk, axis)


def pl_at_confidence(
    level: float,
    *,
    mean: float,
    sigma: float,
    n: int,
    risk: float = 1e-7,
    axis: str = "vertical",
) -> float:
    r"""The constant protection level whose confidence level is ``level`` (PL1, PL99 of section III.3).

    Comby et al. 2003, section III.3 and figure 8: ``pl_at_confidence(0.01, ...)`` is VPL1,
    ``pl_at_confidence(0.99, ...)`` is VPL99.

    Parameters
    ----------
    level
        Confidence level in (0, 1).
    mean, sigma, n, risk, axis
        As for :func:`confidence_level`.

    Returns
    -------
    float
        :math:`L_q` with :math:`CL(L_q) = q` for a subset whose ``n`` PLs all equal :math:`L_q`.

    Notes
    -----
    For a constant PL :math:`L`, :math:`g \le R_n \iff 1 - (1 - P)^n \le 1 - (1 - \mathrm{risk})^n
    \iff P(L; \mu, \sigma) \le \mathrm{risk} \iff L_\mathrm{ideal}(\mu, \sigma) \le L`, since the
    exceedance decreases in :math:`L`. Hence :math:`CL(L) = P(L_\mathrm{ideal}(\mu, \sigma) \le L)`
    (independent of :math:`n` except through the laws of :math:`\mu` and :math:`\sigma`), and
    :math:`L_q` is the :math:`q`-quantile of the ideal PL under the :math:`(\mu, \sigma)` model,
    which is the paper's reading ("the estimated probability that the ideal VPL is below VPL99 is
    equal to 99 %").

    :math:`CL(L)` is computed by the one-dimensional integral of :func:`confidence_level` (64 nodes,
    one PL), and :math:`CL(L) = q` is solved by ``brentq`` to 1e-13 relative in :math:`L`, in a bracket
    grown by factors of 2 from :func:`ideal_pl` at :math:`(\hat m, \hat\Sigma)`.

    Examples
    --------
    >>> pl1 = pl_at_confidence(0.01, mean=0.0, sigma=1.0, n=200)
    >>> pl99 = pl_at_confidence(0.99, mean=0.0, sigma=1.0, n=200)
    >>> round(pl1, 3), round(ideal_pl(mean=0.0, sigma=1.0), 3), round(pl99, 3)
    (4.781, 5.327, 6.037)
    """
    axis = _validate_axis(axis)
    mean, sigma, n, risk = _validate_model(mean, sigma, n, risk)
    level = float(level)
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    one = np.ones(1)

    def cl(pl: float) -> float:
        # constant PL: n log1p(-P) = n log1p(-risk)  <=>  P = risk (one PL with count 1)
        return _confidence(np.array([pl]), one, mean, 64, n, sigma, risk, axis)

    start = _ideal_pl(abs(mean), sigma, risk, axis)
    lo = hi = start
    for _ in range(200):
        if cl(lo) <= level:
            break
        lo *= 0.5
    for _ in range(200):
        if cl(hi) >= level:
            break
        hi *= 2.0
    return float(
        optimize.brentq(
            lambda pl: cl(pl) - level, lo, hi, xtol=1e-13 * lo, rtol=4.0 * np.finfo(float).eps, maxiter=200
        )
    )


# ---------------------------------------------------------------------------------------------
# brute force: eq. (34) in two dimensions
# ---------------------------------------------------------------------------------------------


def confidence_level_bruteforce(
    pl: np.ndarray | float,
    *,
    mean: float,
    sigma: float,
    n: int,
    risk: float = 1e-7,
    axis: str = "vertical",
    grid: int = 256,
    tol: float = 1e-10,
) -> float:
    r"""Confidence level by direct two-dimensional integration of eq. (34), for tests and benchmarks.

    Comby et al. 2003, eq. (34): :math:`CL = \iint_D f_\mu(\mu) f_\sigma(\sigma)\,d\mu\,d\sigma`,
    :math:`D = \{g(\mu, \sigma) \le R_n\}`. Slow; :func:`confidence_level` gives the same number.

    Parameters
    ----------
    pl, mean, sigma, n, risk, axis
        As for :func:`confidence_level`.
    grid
        Points of the :math:`\sigma` grid on which the indicator of :math:`D` is scanned.
    tol
        Absolute and relative tolerance of the outer ``scipy.integrate.quad``.

    Returns
    -------
    float
        CL.

    Notes
    -----
    Independent of the one-dimensional method: it assumes neither the monotonicity of :math:`g`
    in :math:`\sigma` nor the shape of :math:`D`.

    1. Outer integral over the mean with ``scipy.integrate.quad`` (adaptive): vertical over
       :math:`\mu \in \hat m \pm 8\tau` against the normal density of eq. (24); horizontal over
       :math:`|\mu|` against ``scipy.stats.rice``.
    2. Inner integral over :math:`\sigma` of :math:`f_\sigma\,1_D`: the indicator
       :math:`g \le R_n` (as :math:`-\mathrm{expm1}(\sum \mathrm{log1p}(-P_i)) \le R_n`) is scanned on a
       geometric grid spanning the :math:`10^{-15}` and :math:`1 - 10^{-15}` quantiles of
       :math:`\sigma`; every change of the indicator is refined with ``brentq`` in :math:`\sigma`, and
       the density is integrated exactly over each interval of :math:`D` as a difference of
       :math:`F_\sigma` (eq. (28)); a :math:`D` made of several intervals would be handled.
    """
    axis = _validate_axis(axis)
    mean, sigma_hat, n, risk = _validate_model(mean, sigma, n, risk)
    levels, counts = _validate_pl(pl, n)
    r_n = _allowed_risk(n, risk)
    tau = sigma_hat / math.sqrt(n - 2)
    chi_hi = stats.chi2.isf(1e-15, n - 1)
    chi_lo = stats.chi2.ppf(1e-15, n - 1)
    s_grid = sigma_hat * np.sqrt((n - 1) / np.geomspace(chi_hi, chi_lo, grid))
    pl_col = levels[:, None]

    def g(mu: float, s: np.ndarray | float) -> np.ndarray:
        p = _exceedance(pl_col, abs(mu), np.atleast_1d(s)[None, :], axis)
        return -np.expm1(vecmat(counts, np.log1p(-p)))

    def inner(mu: float) -> float:
        inside = g(mu, s_grid) <= r_n
        edges = [0.0] if inside[0] else []
        for j in np.flatnonzero(inside[1:] != inside[:-1]):
            edges.append(
                optimize.brentq(
                    lambda s: float(g(mu, s)[0]) - r_n, s_grid[j], s_grid[j + 1], xtol=1e-14, rtol=1e-14
                )
            )
        if inside[-1]:
            edges.append(math.inf)
        f = _f_sigma(np.asarray(edges, dtype=float), n, sigma_hat) if edges else np.zeros(0)
        f = np.where(np.isinf(edges), 1.0, f) if edges else f
        return float(np.sum(f[1::2] - f[0::2]))

    if axis == "vertical":
        lo, hi = mean - 8.0 * tau, mean + 8.0 * tau

        def integrand(mu: float) -> float:
            return float(np.exp(-0.5 * ((mu - mean) / tau) ** 2) / (tau * _SQRT_2PI)) * inner(mu)

        points = [p for p in (-levels[0], levels[0]) if lo < p < hi]
    else:
        r0 = abs(mean)
        lo, hi = max(0.0, r0 - 8.0 * tau), r0 + 8.0 * tau
        rice = stats.rice(r0 / tau, scale=tau)

        def integrand(mu: float) -> float:
            return float(rice.pdf(mu)) * inner(mu)

        points = [p for p in (levels[0],) if lo < p < hi]
    value, _ = integrate.quad(integrand, lo, hi, points=points or None, epsabs=tol, epsrel=tol, limit=500)
    return float(np.clip(value, 0.0, 1.0))
