r"""Gaussian cdf overbounding of an error sample: the inflated sigma of Comby et al. (2003).

Comby et al. 2003, section II.3 "Second step", eqs. (10)-(16): the sample standard deviation
:math:`\hat\sigma` of a subset of position errors is inflated to the smallest
:math:`\hat\Sigma \ge \hat\sigma` for which the Gaussian :math:`G(\hat m, \hat\Sigma)` bounds the
empirical distribution in both tails, outside a central share (20 %) that is left out so that
errors close to the mean cause no inflation. :math:`\hat m` and :math:`\hat\Sigma` are the inputs
of the confidence-level model of :mod:`overbound.stats.confidence`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

__all__ = ["SigmaInflation", "sigma_inflation"]


@dataclass(frozen=True, slots=True)
class SigmaInflation:
    """Result of :func:`sigma_inflation`.

    Attributes
    ----------
    n : int
        Number of samples.
    mean : float
        Sample mean :math:`\\hat m`, the centre of the overbounding Gaussian.
    sigma : float
        Sample standard deviation :math:`\\hat\\sigma` (``ddof=1``).
    sigma_inflated : float
        Inflated standard deviation :math:`\\hat\\Sigma \\ge \\hat\\sigma`.
    core : float
        Central probability share left out of the overbounding (0.2 in the paper).
    binding : str
        Which constraint set :math:`\\hat\\Sigma`: ``"sample"`` (no inflation needed, :math:`\\hat\\Sigma =
        \\hat\\sigma`), ``"left"`` or ``"right"`` (the tail whose order statistic set it).
    binding_error : float or None
        The error value (order statistic) that set :math:`\\hat\\Sigma`; ``None`` for ``"sample"``.
    """

    n: int
    mean: float
    sigma: float
    sigma_inflated: float
    core: float
    binding: str
    binding_error: float | None

    @property
    def inflation(self) -> float:
        """Inflation factor :math:`\\hat\\Sigma / \\hat\\sigma \\ge 1`."""
        return self.sigma_inflated / self.sigma

    @property
    def core_limits(self) -> tuple[float, float]:
        """Limits :math:`\\hat m \\mp c\\,\\hat\\Sigma` of the left-out core (eqs. (15)-(16)).

        The tail regions are the open half-lines below the first and above the second value.
        """
        c = _core_quantile(self.core)
        return (self.mean - c * self.sigma_inflated, self.mean + c * self.sigma_inflated)

    def cdf(self, x: np.ndarray | float) -> np.ndarray:
        """Cdf of the overbounding Gaussian :math:`G(\\hat m, \\hat\\Sigma)` (eq. (13))."""
        return special.ndtr((np.asarray(x, dtype=float) - self.mean) / self.sigma_inflated)

    def sf(self, x: np.ndarray | float) -> np.ndarray:
        """Survival function of :math:`G(\\hat m, \\hat\\Sigma)` (eq. (14)), accurate in the far tail."""
        return special.ndtr((self.mean - np.asarray(x, dtype=float)) / self.sigma_inflated)


def _core_quantile(core: float) -> float:
    """c = -Phi^{-1}(0.5 - core/2): the core is [m - c Sigma, m + c Sigma]."""
    return float(special.ndtri(0.5 + 0.5 * core))


def _validate_sigma_inflation(errors: np.ndarray, core: float) -> tuple[np.ndarray, float]:
    x = np.asarray(errors, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"errors must be one-dimensional, got shape {x.shape}")
    if x.size < 2:
        raise ValueError(f"need at least 2 errors, got {x.size}")
    if not np.all(np.isfinite(x)):
        raise ValueError("errors contain NaN or infinite values")
    if not 0.0 < core < 1.0:
        raise ValueError(f"core must lie in (0, 1), got {core}")
    if x.min() == x.max():
        raise ValueError("all errors are equal: no spread to overbound")
    return np.sort(x), float(core)


def sigma_inflation(errors: np.ndarray, *, core: float = 0.2) -> SigmaInflation:
    r"""Smallest inflated sigma whose Gaussian overbounds both tails of the sample.

    Comby et al. 2003, eqs. (10)-(16).

    Parameters
    ----------
    errors
        One-dimensional sample of signed errors (e.g. the VPE of one PL band), at least two values,
        finite, not all equal.
    core
        Central share of the overbounding Gaussian left out of the bounding, in (0, 1). The paper's
        "40 %" limits of eqs. (15)-(16) are ``core=0.2``.

    Returns
    -------
    SigmaInflation
        ``n``, ``mean`` (:math:`\hat m`), ``sigma`` (:math:`\hat\sigma`, ``ddof=1``),
        ``sigma_inflated`` (:math:`\hat\Sigma`), ``core``, ``binding``, ``binding_error``; properties
        ``inflation`` and ``core_limits``, methods ``cdf`` and ``sf`` of :math:`G(\hat m, \hat\Sigma)`.

    Raises
    ------
    ValueError
        Fewer than two errors, non-finite values, all errors equal, or ``core`` outside (0, 1).

    Notes
    -----
    **Definition.** With :math:`F_n(L) = \#\{x_j \le L\}/n` (right-continuous empirical cdf),
    :math:`S_n(L) = \#\{x_j \ge L\}/n` and :math:`c = -\Phi^{-1}(1/2 - \mathrm{core}/2)`
    (:math:`c = 0.2533` for ``core=0.2``), :math:`\hat\Sigma` is the smallest
    :math:`\Sigma \ge \hat\sigma` such that

    .. math::

        \Phi\Big(\frac{L_1 - \hat m}{\Sigma}\Big) \ge F_n(L_1) \quad \forall L_1 < \hat m - c\Sigma,
        \qquad
        \bar\Phi\Big(\frac{L_2 - \hat m}{\Sigma}\Big) \ge S_n(L_2) \quad \forall L_2 > \hat m + c\Sigma,

    i.e. eq. (11) on both tails, with the tail limits of eqs. (15)-(16),
    :math:`E_\mathrm{left}(L_1) < 40\,\%` and :math:`E_\mathrm{right}(L_2) < 40\,\%`, computed with
    :math:`\Sigma` itself.

    **Choices where the paper is silent.**

    1. *Open tail regions.* The limits of eqs. (15)-(16) are excluded. With closed regions the set of
       admissible :math:`\Sigma` is open whenever a point with more than 40 % of the sample on its side
       binds (it must leave the region, :math:`\Sigma > d/c`), and the infimum is not attained; with
       open regions every constraint is a closed half-line and the minimum exists.
    2. *Right tail uses* :math:`S_n(L) = P_n(X \ge L)`, the mirror image of :math:`F_n` under
       :math:`x \to -x`, so the procedure is exactly symmetric (left and right swap). The paper's
       :math:`1 - \mathrm{cdf}_\mathrm{VPE}(L) = P_n(X > L)` gives the same :math:`\hat\Sigma`: on an
       open region the supremum of the step :math:`P_n(X > L)` over :math:`L < x_{(k)}` tends to
       :math:`S_n(x_{(k)})` while :math:`\bar\Phi` is continuous.
    3. *Centre* :math:`\hat m` is the sample mean (not re-fitted), as in the paper's implementation
       :math:`G(\hat m, \hat\Sigma)`.

    **Closed form.** Between order statistics :math:`F_n` is flat and :math:`\Phi` increasing, so the
    left condition needs checking only at the order statistics. For a sample point
    :math:`x_{(i)} = \hat m - d` with :math:`d > 0` and :math:`F = F_n(x_{(i)})` (ties counted with
    ``searchsorted(side="right")``):

    * if :math:`F \le 1/2 - \mathrm{core}/2`, the point is admissible for every
      :math:`\Sigma \ge d / (-\Phi^{-1}(F))` (this bound is :math:`\le d/c`, where it leaves the region);
    * otherwise it can never be bounded inside the region and must lie in the core,
      :math:`\Sigma \ge d/c`.

    Both cases are :math:`\Sigma \ge b_i = d / \max(c, -\Phi^{-1}(F))`. The right tail mirrors this with
    :math:`d = x_{(k)} - \hat m` and :math:`S = S_n(x_{(k)})` (``searchsorted(side="left")``). Points
    on the other side of :math:`\hat m` put no constraint. Hence

    .. math:: \hat\Sigma = \max\big(\hat\sigma, \max_i b_i\big),

    exact (no grid search), :math:`O(n \log n)` for the sort. ``binding`` names the tail of the
    largest bound (``"left"`` on an exact tie).

    Properties: location and scale equivariant, symmetric under :math:`x \to -x` (left and right
    swap); :math:`\hat\Sigma \ge \hat\sigma` by construction.

    References
    ----------
    .. [1] D. Comby, R. Farnworth, C. Macabiau, "EGNOS vertical protection level assessment",
       ION GPS/GNSS 2003, eqs. (10)-(16) and appendix 1.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.array([-1.2, -0.4, 0.0, 0.3, 0.5, 0.8, 1.1, 6.0])
    >>> r = sigma_inflation(x)
    >>> r.binding, r.binding_error
    ('right', 6.0)
    >>> round(r.sigma, 4), round(r.sigma_inflated, 4)
    (2.1873, 4.4443)
    """
    xs, core = _validate_sigma_inflation(errors, core)
    n = xs.size
    mean = float(np.mean(xs))
    sigma = float(np.std(xs, ddof=1))
    c = _core_quantile(core)

    with np.errstate(divide="ignore"):
        # Left tail: share of samples <= x_(i); right tail: share of samples >= x_(k).
        share_left = np.searchsorted(xs, xs, side="right") / n
        share_right = (n - np.searchsorted(xs, xs, side="left")) / n
        z_left = np.maximum(c, -special.ndtri(share_left))
        z_right = np.maximum(c, -special.ndtri(share_right))
    d_left = mean - xs
    d_right = xs - mean
    bound_left = np.where(d_left > 0.0, d_left / z_left, 0.0)
    bound_right = np.where(d_right > 0.0, d_right / z_right, 0.0)

    i_left = int(np.argmax(bound_left))
    i_right = int(np.argmax(bound_right))
    b_left = float(bound_left[i_left])
    b_right = float(bound_right[i_right])
    if sigma >= max(b_left, b_right):
        return SigmaInflation(n, mean, sigma, sigma, core, "sample", None)
    if b_left >= b_right:
        return SigmaInflation(n, mean, sigma, b_left, core, "left", float(xs[i_left]))
    return SigmaInflation(n, mean, sigma, b_right, core, "right", float(xs[i_right]))
