r"""Extreme value distribution fits: the GPD on threshold excesses and the GEV on block maxima.

Veerman et al. (GIMAT), section 2: the tail of the safety index SI = |PE|/PL is modelled by a
generalised Pareto distribution (GPD) fitted to the excesses over a threshold :math:`L_{Tail}`
(section 3.3), and by a generalised extreme value distribution (GEV) on block maxima as the second
model (section 4). The misleading-information probability of section 3.5 is the exceedance rate
times the GPD survival function at SI = 1 (built on :meth:`GPDFit.sf`).

Sign convention (that of the paper and of R's evd): the shape :math:`\xi` (the paper's
:math:`\gamma` for the GPD and :math:`K` for the GEV) is positive for heavy tails, zero for the
exponential/Gumbel limit and negative for a finite upper endpoint. scipy's ``genpareto`` uses
``c == xi``, but scipy's ``genextreme`` uses ``c == -xi``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, special, stats

from overbound.stats.sums import matvec

__all__ = [
    "GEVFit",
    "GPDFit",
    "fit_gev",
    "fit_gpd",
    "gev_cdf",
    "gev_logpdf",
    "gev_sf",
    "gpd_isf",
    "gpd_logpdf",
    "gpd_sf",
    "profile_ci_exceedance",
]

#: Shapes below this are non-regular: the MLE is not asymptotically normal (Smith 1985).
NONREGULAR_SHAPE = -0.5

# Grid of s = tau * max(x) over which the GPD profile likelihood is scanned before refinement:
# dense in log(1 + s) towards the lower end s -> -1 (strongly negative shapes, endpoint near the
# sample maximum), geometric for s > 0 (heavy tails).
_S_GRID = np.concatenate(
    [
        -1.0 + np.logspace(-10, -0.1, 14),
        -np.logspace(-0.6, -3, 4),
        [0.0],
        np.logspace(-3, 7, 14),
    ]
)


_SCAN_SIZE = 256


def _log1prel(w: np.ndarray) -> np.ndarray:
    """``log1p(w) / w``, equal to 1 at ``w == 0`` (relative accuracy kept for tiny ``w``)."""
    w = np.asarray(w, dtype=float)
    out = np.empty_like(w)
    with np.errstate(invalid="ignore", divide="ignore"):
        np.log1p(w, out=out)
        np.divide(out, w, out=out, where=w != 0.0)
    out[w == 0.0] = 1.0
    return out


def _psi(y: np.ndarray) -> np.ndarray:
    """``(y/(1+y) - log1p(y)) / y**2``, -1/2 at 0 (series for ``|y| < 1e-2`` against cancellation)."""
    y = np.asarray(y, dtype=float)
    small = np.abs(y) < 1e-2
    ys = np.where(small, y, 0.0)
    series = np.zeros_like(ys)
    for k in range(8, -1, -1):  # sum_k (-1)^(k+1) (k+1)/(k+2) y^k, Horner
        series = series * ys + (-1.0) ** (k + 1) * (k + 1) / (k + 2)
    yl = np.where(small, 1.0, y)
    with np.errstate(invalid="ignore", divide="ignore"):
        direct = (yl / (1.0 + yl) - np.log1p(yl)) / (yl * yl)
    return np.where(small, series, direct)


def _chi(w: np.ndarray) -> np.ndarray:
    """``(2 log1p(w) - 2w/(1+w) - w**2/(1+w)**2) / w**3``, 2/3 at 0 (series for ``|w| < 1e-2``).

    With ``t = log1p(xi z)/xi`` it gives :math:`\\partial^2 t/\\partial\\xi^2 = z^3\\chi(\\xi z)`, the
    companion of :func:`_psi` (:math:`\\partial t/\\partial\\xi = z^2\\psi(\\xi z)`).
    """
    w = np.asarray(w, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = w / (1.0 + w)
        out = (2.0 * np.log1p(w) - 2.0 * r - r * r) / (w * w * w)
    small = np.flatnonzero(np.abs(w) < 1e-2)
    if small.size:
        ws = w.flat[small]
        series = np.zeros_like(ws)
        for j in range(10, -1, -1):  # sum_j (-1)^j (j+1)(j+2)/(j+3) w^j, Horner
            series = series * ws + (-1.0) ** j * (j + 1) * (j + 2) / (j + 3)
        out.flat[small] = series
    return out


# --------------------------------------------------------------------------------------------------
# GPD: distribution functions


def gpd_sf(x: np.ndarray | float, *, xi: float, sigma: float) -> np.ndarray:
    r"""Survival function of the GPD of excesses, :math:`P(Y > y)`.

    Parameters
    ----------
    x
        Excesses over the threshold (``y = value - threshold``); ``y <= 0`` gives 1.
    xi
        Shape (:math:`\xi > 0` heavy tail; scipy ``genpareto`` ``c == xi``).
    sigma
        Scale, > 0.

    Returns
    -------
    numpy.ndarray
        :math:`(1 + \xi y/\sigma)^{-1/\xi}`, exactly 0 at and beyond the endpoint
        :math:`-\sigma/\xi` when :math:`\xi < 0`.

    Notes
    -----
    Veerman et al., section 2, GPD cdf (with :math:`\mu = 0`):

    .. math:: \bar G(y) = \exp\left(-\frac{y}{\sigma}\,\frac{\log(1 + \xi y/\sigma)}{\xi y/\sigma}\right),

    where :math:`\log(1+w)/w` is evaluated with ``log1p`` and equals 1 at :math:`w = 0`, so that
    :math:`\xi \to 0` gives :math:`e^{-y/\sigma}` continuously (no switch at a cut-off).

    Examples
    --------
    >>> float(gpd_sf(1.0, xi=0.0, sigma=1.0)) == math.exp(-1.0)
    True
    >>> float(gpd_sf(3.0, xi=-0.5, sigma=1.0))
    0.0
    """
    return np.exp(-_gpd_cumhaz(np.asarray(x, dtype=float), xi, sigma))


def _gpd_cumhaz(y: np.ndarray, xi: float, sigma: float) -> np.ndarray:
    """-log sf: ``log1p(xi y/sigma)/xi`` (inf beyond a finite endpoint, 0 for y <= 0)."""
    z = np.maximum(y, 0.0) / sigma
    w = xi * z
    with np.errstate(invalid="ignore", divide="ignore"):
        h = z * _log1prel(w)
    return np.where(w <= -1.0, np.inf, h)


def gpd_logpdf(x: np.ndarray | float, *, xi: float, sigma: float) -> np.ndarray:
    r"""Log density of the GPD of excesses: :math:`-\log\sigma - (1+\xi)\,\log(1+\xi y/\sigma)/\xi`.

    ``-inf`` outside the support :math:`0 \le y` (and :math:`y < -\sigma/\xi` for :math:`\xi < 0`).
    """
    y = np.asarray(x, dtype=float)
    z = y / sigma
    w = xi * z
    with np.errstate(invalid="ignore", divide="ignore"):
        out = -math.log(sigma) - (1.0 + xi) * z * _log1prel(w)
    inside = (y >= 0.0) & (w > -1.0)
    if xi == -1.0:  # uniform on (0, sigma)
        out = np.full_like(z, -math.log(sigma))
    return np.where(inside, out, -np.inf)


def gpd_isf(p: np.ndarray | float, *, xi: float, sigma: float) -> np.ndarray:
    r"""Inverse survival function of the GPD of excesses: :math:`\sigma\,(p^{-\xi} - 1)/\xi`.

    Computed as :math:`\sigma\,\ell\,\mathrm{exprel}(\xi \ell)` with :math:`\ell = -\log p`, exact for
    :math:`\xi \to 0` (:math:`-\sigma \log p`).
    """
    ell = -np.log(np.asarray(p, dtype=float))
    return sigma * ell * special.exprel(xi * ell)


# --------------------------------------------------------------------------------------------------
# GPD: maximum likelihood through the profile in tau = xi / sigma (Grimshaw 1993)


def _gpd_profile(y: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Profile quantities at ``tau`` for the rows of ``y`` (shape (B, n); tau shape (B, G)).

    Returns ``xi(tau) = mean log1p(tau y)``, ``sigma(tau) = xi/tau`` (exact at tau = 0) and the
    profile log-likelihood per observation ``-(log sigma + xi + 1)``.
    """
    w = tau[:, :, None] * y[:, None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = _log1prel(w)
        sig = np.mean(y[:, None, :] * rel, axis=2)
        xi = tau * sig
        ll = -(np.log(sig) + xi + 1.0)
    ll = np.where(np.isfinite(ll) & (np.min(w, axis=2) > -1.0), ll, -np.inf)
    return xi, sig, ll


def _gpd_score(y: np.ndarray, tau: np.ndarray) -> np.ndarray:
    r"""Derivative of the profile log-likelihood per observation in tau, rows of ``y`` (B, n), tau (B,).

    :math:`-[(\bar q - \sigma(\tau))/(\tau\sigma(\tau)) + \bar q]`
    with :math:`\bar q = \overline{y/(1+\tau y)}`;
    for :math:`|\tau y_{(n)}| < 10^{-2}` the difference quotient is the series-stabilised
    :math:`\overline{y^2\psi(\tau y)}`, exact at tau = 0.
    """
    w = tau[:, None] * y
    sig = np.mean(y * _log1prel(w), axis=1)
    q = np.mean(y / (1.0 + w), axis=1)
    small = np.abs(tau) * np.max(y, axis=1) < 1e-2
    out = np.empty_like(tau)
    big = ~small
    if np.any(big):
        out[big] = -((q[big] - sig[big]) / (tau[big] * sig[big]) + q[big])
    if np.any(small):
        m = np.mean(y[small] ** 2 * _psi(w[small]), axis=1)
        out[small] = -(m / sig[small] + q[small])
    return out


def _gpd_scan(y: np.ndarray, tau_grid: np.ndarray) -> tuple[np.ndarray, ...]:
    """Best grid point of the profile (xi >= -1 only) and its neighbours as a bracket, per row."""
    xi_g, _, ll_g = _gpd_profile(y, tau_grid)
    ll_g = np.where(xi_g >= -1.0, ll_g, -np.inf)
    k = np.argmax(ll_g, axis=1)
    first_ok = np.argmax(np.isfinite(ll_g), axis=1)
    rows = np.arange(y.shape[0])
    lo = tau_grid[rows, np.maximum(k - 1, first_ok)]
    hi = tau_grid[rows, np.minimum(k + 1, _S_GRID.size - 1)]
    return k, first_ok, lo, hi


def _gpd_mle_rows(y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """GPD MLE for each row of excesses ``y`` (B, n) at once.

    Returns ``(xi, sigma, loglik, status)`` with status 0 = interior maximum, 1 = the profile rises
    towards xi = -1 (likelihood unbounded), 2 = the maximum lies beyond the grid (xi very large).

    Steps:
    1. scan the profile log-likelihood on the grid ``tau = s / max(y)`` (``_S_GRID``), keeping only
       points with ``xi(tau) >= -1`` (for xi < -1 the likelihood is unbounded and no MLE exists);
    2. take the best grid point and bracket the stationary point between its neighbours;
    3. refine the root of the profile score by a vectorised Illinois (modified regula falsi) iteration.
    """
    b, n = y.shape
    ymax = np.max(y, axis=1)
    rows = np.arange(b)
    tau_grid = _S_GRID[None, :] / ymax[:, None]
    # The scan only brackets the maximum: it runs on a strided subsample that keeps the maximum
    # (cheap), and is redone on the full rows wherever the bracket does not hold.
    step = max(1, n // _SCAN_SIZE)
    sub = np.concatenate([y[:, ::step], ymax[:, None]], axis=1) if step > 1 else y
    k, first_ok, lo, hi = _gpd_scan(sub, tau_grid)
    flo = _gpd_score(y, lo)
    fhi = _gpd_score(y, hi)
    # Walk the bracket along the grid by the sign of the full-data score where the subsample was off.
    ilo = np.maximum(k - 1, first_ok)
    ihi = np.minimum(k + 1, _S_GRID.size - 1)
    for _ in range(_S_GRID.size):
        left = (flo <= 0.0) & (ilo > first_ok)
        right = (fhi >= 0.0) & (ihi < _S_GRID.size - 1) & ~left
        if not (np.any(left) or np.any(right)):
            break
        ihi[left], hi[left], fhi[left] = ilo[left], lo[left], flo[left]
        ilo[left] -= 1
        lo[left] = tau_grid[rows[left], ilo[left]]
        flo[left] = _gpd_score(y[left], lo[left])
        ilo[right], lo[right], flo[right] = ihi[right], hi[right], fhi[right]
        ihi[right] += 1
        hi[right] = tau_grid[rows[right], ihi[right]]
        fhi[right] = _gpd_score(y[right], hi[right])
    k = np.where((ihi - ilo) == 2, ilo + 1, np.where(flo <= 0.0, ilo, ihi))
    edge = (k <= first_ok) | (k >= _S_GRID.size - 1)
    redo = ~((flo > 0.0) & (fhi < 0.0)) | edge
    if step > 1 and np.any(redo):
        k[redo], first_ok[redo], lo[redo], hi[redo] = _gpd_scan(y[redo], tau_grid[redo])
        flo[redo] = _gpd_score(y[redo], lo[redo])
        fhi[redo] = _gpd_score(y[redo], hi[redo])
    status = np.zeros(b, dtype=int)
    status[k == first_ok] = 1
    status[k == _S_GRID.size - 1] = 2
    active = (status == 0) & (flo > 0.0) & (fhi < 0.0)
    side = np.zeros(b, dtype=int)
    for _ in range(200):
        if not np.any(active):
            break
        ia = np.flatnonzero(active)
        a, c, fa, fc = lo[ia], hi[ia], flo[ia], fhi[ia]
        t = (a * fc - c * fa) / (fc - fa)
        bad = ~((t > a) & (t < c))
        t = np.where(bad, 0.5 * (a + c), t)
        ft = _gpd_score(y[ia], t)
        left = ft > 0.0
        lo[ia] = np.where(left, t, a)
        flo[ia] = np.where(left, ft, fa)
        hi[ia] = np.where(left, c, t)
        fhi[ia] = np.where(left, fc, ft)
        # Illinois: halve the retained end's value when the same end is kept twice running.
        s_new = np.where(left, 1, -1)
        same = s_new == side[ia]
        fhi[ia] = np.where(same & left, 0.5 * fhi[ia], fhi[ia])
        flo[ia] = np.where(same & ~left, 0.5 * flo[ia], flo[ia])
        side[ia] = s_new
        width = hi[ia] - lo[ia]
        done = (ft == 0.0) | (width <= 1e-11 * np.maximum(np.abs(t), 1e-300) + 1e-300)
        lo[ia] = np.where(ft == 0.0, t, lo[ia])
        hi[ia] = np.where(ft == 0.0, t, hi[ia])
        active[ia[done]] = False
    with np.errstate(invalid="ignore", divide="ignore"):
        sec = (lo * fhi - hi * flo) / (fhi - flo)  # final secant point inside the (tiny) bracket
    tau_hat = np.where((sec >= lo) & (sec <= hi), sec, np.where(np.abs(flo) <= np.abs(fhi), lo, hi))
    tau_hat = np.where(status == 0, tau_hat, tau_grid[rows, k])
    xi, sig, ll = _gpd_profile(y, tau_hat[:, None])
    xi, sig, ll = xi[:, 0], sig[:, 0], ll[:, 0] * n
    # At xi = -1 the best fit is uniform on (0, max y) with log-likelihood -n log(max y); if that beats
    # the interior stationary point the likelihood rises towards (and beyond) xi = -1.
    status[(status == 0) & ~(ll >= -n * np.log(ymax))] = 1
    unbounded = status == 1
    xi = np.where(unbounded, -1.0, xi)
    sig = np.where(unbounded, ymax, sig)
    ll = np.where(unbounded, -n * np.log(ymax), ll)
    return xi, sig, ll, status


@dataclass(frozen=True, slots=True)
class GPDFit:
    r"""Result of :func:`fit_gpd`.

    Attributes
    ----------
    xi : float
        Shape :math:`\hat\xi` (:math:`>0` heavy tail; scipy ``genpareto`` ``c``).
    sigma : float
        Scale :math:`\hat\sigma`.
    threshold : float
        Threshold :math:`u`; the model is :math:`P(X > x \mid X > u) = \bar G(x - u)`.
    n : int
        Number of exceedances.
    loglik : float
        Maximised log-likelihood of the excesses.
    success : bool
        Whether a regular interior maximum was found (False for :math:`\xi \le -1`, where the
        likelihood is unbounded, or for a shape beyond the search grid).
    message : str
        What happened.
    regular : bool
        :math:`\hat\xi > -1/2`: the usual asymptotics of the MLE hold (Smith 1985).
    excesses : numpy.ndarray
        The excesses :math:`x - u` (kept for the profile likelihood).
    """

    xi: float
    sigma: float
    threshold: float
    n: int
    loglik: float
    success: bool
    message: str
    regular: bool
    excesses: np.ndarray = field(repr=False, compare=False)

    @property
    def endpoint(self) -> float:
        r"""Upper endpoint :math:`u - \sigma/\xi` for :math:`\xi < 0`, ``inf`` otherwise."""
        return self.threshold - self.sigma / self.xi if self.xi < 0 else math.inf

    def sf(self, x: np.ndarray | float) -> np.ndarray:
        """Conditional survival :math:`P(X > x \\mid X > u)`; 1 below the threshold, 0 beyond the endpoint."""
        return gpd_sf(np.asarray(x, dtype=float) - self.threshold, xi=self.xi, sigma=self.sigma)

    def isf(self, p: np.ndarray | float) -> np.ndarray:
        """Level exceeded with conditional probability ``p`` above the threshold (inverse of :meth:`sf`)."""
        return self.threshold + gpd_isf(p, xi=self.xi, sigma=self.sigma)

    def profile_loglik(self, xi: float) -> float:
        """Profile log-likelihood :math:`\\max_\\sigma \\ell(\\xi, \\sigma)` at a given shape."""
        return _gpd_profile_xi(self.excesses, xi)

    def profile_ci(self, level: float = 0.95, param: str = "xi") -> tuple[float, float]:
        r"""Profile-likelihood confidence interval for the shape.

        The set :math:`\{\xi: 2(\hat\ell - \ell_p(\xi)) \le \chi^2_{1}(\text{level})\}`, its ends found
        by Brent's root finder on the profile. A lower end that would lie below :math:`\xi = -1`
        (likelihood unbounded there) is reported as -1; an upper end beyond 50 as ``inf``.
        """
        if param != "xi":
            raise ValueError(f"param must be 'xi', got {param!r}")
        if not 0.0 < level < 1.0:
            raise ValueError(f"level must be in (0, 1), got {level}")
        cut = self.loglik - 0.5 * float(stats.chi2.isf(1.0 - level, 1))

        def f(x: float) -> float:
            return _gpd_profile_xi(self.excesses, x) - cut

        ends = []
        for direction, limit in ((-1.0, -1.0 + 1e-9), (1.0, 50.0)):
            step = 0.05 + 2.0 / math.sqrt(self.n)
            inner = self.xi
            end = None
            while True:
                outer = self.xi + direction * step
                if (outer - limit) * direction >= 0:
                    outer = limit
                if f(outer) < 0:
                    end = optimize.brentq(f, min(inner, outer), max(inner, outer), xtol=1e-10)
                    break
                if outer == limit:
                    break
                inner, step = outer, 2.0 * step
            ends.append(end if end is not None else (-1.0 if direction < 0 else math.inf))
        return (float(ends[0]), float(ends[1]))


def _gpd_profile_xi(y: np.ndarray, xi: float) -> float:
    r"""Profile log-likelihood at fixed :math:`\xi > -1`: the MLE :math:`\tau = \xi/\sigma` solves
    :math:`\overline{1/(1+\tau y)} = 1/(1+\xi)` (a decreasing function of :math:`\tau`: unique root)."""
    n = y.size
    if xi <= -1.0:
        return math.inf
    if xi == 0.0:
        s = float(np.mean(y))
        return -n * (math.log(s) + 1.0)
    ymax = float(np.max(y))
    target = 1.0 / (1.0 + xi)

    def g(t: float) -> float:
        return float(np.mean(1.0 / (1.0 + t * y))) - target

    if xi > 0:
        lo, hi = 0.0, 1.0 / ymax
        while g(hi) > 0:
            lo, hi = hi, 4.0 * hi
    else:
        lo, hi = -1.0 / ymax, 0.0
        frac = 0.5
        while g(-frac / ymax) < 0:
            frac = 0.5 * (1.0 + frac)
            if frac >= 1.0 - 1e-15:
                break
        lo = -frac / ymax
    tau = optimize.brentq(g, lo, hi, xtol=1e-300, rtol=1e-15)
    sigma = xi / tau if tau != 0 else float(np.mean(y))
    return float(np.sum(gpd_logpdf(y, xi=xi, sigma=sigma)))


def _validate_fit_gpd(exceedances: np.ndarray, threshold: float) -> np.ndarray:
    x = np.asarray(exceedances, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"exceedances must be one-dimensional, got shape {x.shape}")
    if x.size < 3:
        raise ValueError(f"need at least 3 exceedances, got {x.size}")
    if not np.all(np.isfinite(x)):
        raise ValueError("exceedances contain NaN or inf")
    y = x - float(threshold)
    if np.min(y) < 0:
        raise ValueError(f"exceedances must be >= threshold {threshold}, min is {np.min(x)}")
    if np.max(y) <= 0:
        raise ValueError("all exceedances equal the threshold")
    return y


def fit_gpd(exceedances: np.ndarray, *, threshold: float = 0.0) -> GPDFit:
    r"""Fit a generalised Pareto distribution to threshold exceedances by maximum likelihood.

    Parameters
    ----------
    exceedances
        Values above the threshold (all ``>= threshold``); with the default ``threshold=0`` these
        may be the excesses themselves.
    threshold
        The threshold :math:`u` (the paper's :math:`L_{Tail}`).

    Returns
    -------
    GPDFit
        ``xi``, ``sigma``, ``threshold``, ``n``, ``loglik``, ``success``, ``message``, ``regular``;
        methods ``sf``, ``isf``, ``endpoint``, ``profile_ci``.

    Raises
    ------
    ValueError
        Fewer than 3 values, non-finite values, values below the threshold.

    Notes
    -----
    Veerman et al., section 2 (GPD cdf) and section 3.5 (:math:`P_{MI}` from the fitted survival).
    Shape convention: :math:`\xi > 0` heavy tail (scipy ``genpareto`` ``c == xi``).

    With :math:`\tau = \xi/\sigma` (Grimshaw 1993) the log-likelihood of excesses :math:`y_i`,
    maximised over :math:`\xi` for fixed :math:`\tau`, is attained at
    :math:`\xi(\tau) = \frac1n\sum\log(1+\tau y_i)` and gives the profile

    .. math:: \ell^*(\tau) = -n\left[\log\frac{\xi(\tau)}{\tau} + \xi(\tau) + 1\right],

    a function of one variable on :math:`\tau > -1/y_{(n)}`; :math:`\tau = 0` is the exponential
    (:math:`\xi/\tau \to \bar y`, evaluated exactly with ``log1p(w)/w``).

    1. :math:`\ell^*` is scanned on a fixed grid of :math:`s = \tau\,y_{(n)}` (dense towards
       :math:`s \to -1`, geometric for :math:`s > 0`), keeping :math:`\xi(\tau) \ge -1`.
    2. The root of :math:`d\ell^*/d\tau` next to the best grid point is refined by the Illinois
       method (the derivative is written with a series-stabilised kernel, exact at :math:`\tau = 0`).
    3. If the best point is at :math:`\xi = -1` the likelihood increases without bound towards the
       endpoint :math:`y_{(n)}` (it is unbounded for every sample when :math:`\xi < -1`): the result
       has ``success=False``, :math:`\xi = -1`, :math:`\sigma = y_{(n)}`.

    ``regular`` is :math:`\hat\xi > -1/2`. The core works on a 2-D array of samples (rows), so a
    bootstrap can fit all resamples at once.

    References
    ----------
    .. [1] Veerman et al., "A Tool for GNSS Integrity Verification Based on Statistical Extreme
       Value Theory", sections 2 and 3.5.
    .. [2] Grimshaw, S. D. (1993), "Computing maximum likelihood estimates for the generalized
       Pareto distribution", Technometrics 35(2), 185-191.
    .. [3] Smith, R. L. (1985), "Maximum likelihood estimation in a class of nonregular cases",
       Biometrika 72(1), 67-90.

    Examples
    --------
    >>> y = np.random.default_rng(1).exponential(2.0, 2000)
    >>> fit = fit_gpd(y)
    >>> bool(fit.success), round(fit.sigma, 1), abs(fit.xi) < 0.1
    (True, 2.0, True)
    """
    y = _validate_fit_gpd(exceedances, threshold)
    xi, sig, ll, status = _gpd_mle_rows(y[None, :])
    xi_, sig_, ll_, st = float(xi[0]), float(sig[0]), float(ll[0]), int(status[0])
    if st == 1:
        success, message = False, "likelihood unbounded: the profile rises towards shape <= -1"
    elif st == 2:
        success, message = False, "shape beyond the search range (extremely heavy tail)"
    elif not (np.isfinite(ll_) and np.isfinite(xi_) and sig_ > 0):
        success, message = False, "converged but log-likelihood not finite"
    else:
        success, message = True, "interior maximum of the profile likelihood"
        if xi_ <= NONREGULAR_SHAPE:
            message += "; shape < -0.5: non-regular (MLE asymptotics do not hold)"
    return GPDFit(
        xi=xi_,
        sigma=sig_,
        threshold=float(threshold),
        n=int(y.size),
        loglik=ll_,
        success=success,
        message=message,
        regular=bool(xi_ > NONREGULAR_SHAPE),
        excesses=y,
    )


# --------------------------------------------------------------------------------------------------
# GEV


def _gev_t(x: np.ndarray, xi: float, loc: float, scale: float) -> np.ndarray:
    """``t = log1p(xi z)/xi`` with ``z = (x-loc)/scale`` (``z`` at xi = 0); NaN outside the support."""
    z = (np.asarray(x, dtype=float) - loc) / scale
    w = xi * z
    with np.errstate(invalid="ignore", divide="ignore"):
        t = z * _log1prel(w)
    return np.where(w > -1.0, t, np.nan)


def gev_cdf(x: np.ndarray | float, *, xi: float, loc: float, scale: float) -> np.ndarray:
    r"""GEV cdf :math:`\exp[-(1+\xi z)^{-1/\xi}]` (Veerman et al., section 2), Gumbel at :math:`\xi=0`.

    Shape convention :math:`\xi > 0` Fréchet (heavy); scipy ``genextreme`` ``c == -xi``.
    """
    t = _gev_t(x, xi, loc, scale)
    below = 1.0 if xi < 0 else 0.0  # outside the support: above the endpoint (xi<0) or below (xi>0)
    return np.where(np.isnan(t), below, np.exp(-np.exp(-t)))


def gev_sf(x: np.ndarray | float, *, xi: float, loc: float, scale: float) -> np.ndarray:
    """GEV survival :math:`-\\mathrm{expm1}(-e^{-t})`, accurate far in the upper tail."""
    t = _gev_t(x, xi, loc, scale)
    outside = 0.0 if xi < 0 else 1.0
    return np.where(np.isnan(t), outside, -np.expm1(-np.exp(-t)))


def gev_logpdf(x: np.ndarray | float, *, xi: float, loc: float, scale: float) -> np.ndarray:
    """GEV log density :math:`-\\log s - (1+\\xi) t - e^{-t}`; ``-inf`` outside the support."""
    t = _gev_t(x, xi, loc, scale)
    with np.errstate(over="ignore"):
        out = -math.log(scale) - (1.0 + xi) * t - np.exp(-t)
    return np.where(np.isnan(t), -np.inf, out)


@dataclass(frozen=True, slots=True)
class GEVFit:
    r"""Result of :func:`fit_gev`.

    Attributes
    ----------
    xi, loc, scale : float
        Shape (:math:`>0` Fréchet; scipy ``genextreme`` ``c == -xi``), location and scale.
    n : int
        Number of block maxima.
    loglik : float
        Maximised log-likelihood.
    success : bool
        Whether the optimiser converged to a finite maximum.
    message : str
        What happened.
    """

    xi: float
    loc: float
    scale: float
    n: int
    loglik: float
    success: bool
    message: str

    def cdf(self, x: np.ndarray | float) -> np.ndarray:
        return gev_cdf(x, xi=self.xi, loc=self.loc, scale=self.scale)

    def sf(self, x: np.ndarray | float) -> np.ndarray:
        return gev_sf(x, xi=self.xi, loc=self.loc, scale=self.scale)

    def isf(self, p: np.ndarray | float) -> np.ndarray:
        r"""Level with survival ``p``: :math:`\mu + s\,y\,\mathrm{exprel}(\xi y)`.

        Here :math:`y = -\log(-\log(1-p))`, computed with ``log1p`` so that tiny ``p`` keeps its
        accuracy; exact in the Gumbel limit.
        """
        y = -np.log(-np.log1p(-np.asarray(p, dtype=float)))
        return self.loc + self.scale * y * special.exprel(self.xi * y)


def _gev_pwm_start(x: np.ndarray) -> tuple[float, float, float]:
    """Probability-weighted-moment estimate (Hosking, Wallis & Wood 1985), Gumbel when degenerate."""
    xs = np.sort(x)
    n = xs.size
    j = np.arange(n)
    b0 = xs.mean()
    b1 = np.sum(j * xs) / (n * (n - 1))
    b2 = np.sum(j * (j - 1) * xs) / (n * (n - 1) * (n - 2))
    c = (2 * b1 - b0) / (3 * b2 - b0) - math.log(2) / math.log(3)
    k = 7.8590 * c + 2.9554 * c * c  # Hosking's k = -xi
    if abs(k) < 1e-6 or not np.isfinite(k) or k <= -1.0:
        scale = math.sqrt(6.0) * float(np.std(x)) / math.pi
        return 0.0, float(b0 - 0.5772156649015329 * scale), scale
    g = math.gamma(1 + k)
    scale = (2 * b1 - b0) * k / (g * (1 - 2.0**-k))
    loc = b0 + scale * (g - 1) / k
    return float(-k), float(loc), float(scale)


def fit_gev(block_maxima: np.ndarray) -> GEVFit:
    r"""Fit a generalised extreme value distribution to block maxima by maximum likelihood.

    Parameters
    ----------
    block_maxima
        One maximum per block (daily by default in the EVT analysis).

    Returns
    -------
    GEVFit
        ``xi``, ``loc``, ``scale``, ``n``, ``loglik``, ``success``, ``message``; methods ``cdf``,
        ``sf``, ``isf``.

    Notes
    -----
    Veerman et al., section 2, GEV cdf :math:`H(e) = \exp[-(1 + \xi (e-\mu)/\sigma)^{-1/\xi}]`
    (the paper's :math:`K` is :math:`\xi`; scipy ``genextreme`` ``c == -xi``).

    1. Start from the probability-weighted-moment estimate (Gumbel moments if degenerate).
    2. Minimise the negative log-likelihood in :math:`(\xi, \mu, \log\sigma)` by Nelder-Mead with
       tight tolerances, then polish with BFGS, keeping the better point.
    3. The Gumbel limit is continuous: :math:`t = \log(1+\xi z)/\xi` is evaluated as
       :math:`z\,\log1p(\xi z)/(\xi z)`, exact at :math:`\xi = 0`.
    """
    x = np.asarray(block_maxima, dtype=float)
    if x.ndim != 1 or x.size < 3:
        raise ValueError(f"need a 1-D array of at least 3 block maxima, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("block maxima contain NaN or inf")
    n = x.size
    sd = float(np.std(x))
    if sd == 0:
        raise ValueError("block maxima are all equal")

    def nll(p: np.ndarray) -> float:
        # An optimiser step can take log-scale to +-hundreds: exp() then under- or overflows.
        if not -700.0 < p[2] < 700.0 or not np.all(np.isfinite(p)):
            return 1e300
        v = -float(np.sum(gev_logpdf(x, xi=p[0], loc=p[1], scale=math.exp(p[2]))))
        return v if np.isfinite(v) else 1e300

    xi0, loc0, scale0 = _gev_pwm_start(x)
    starts = [np.array([xi0, loc0, math.log(scale0)])]
    gs = math.sqrt(6.0) * sd / math.pi
    starts.append(np.array([0.0, float(np.mean(x)) - 0.5772156649015329 * gs, math.log(gs)]))
    best = None
    for p0 in starts:
        r = optimize.minimize(
            nll, p0, method="Nelder-Mead", options={"xatol": 1e-9, "fatol": 1e-11, "maxiter": 5000}
        )
        r2 = optimize.minimize(nll, r.x, method="BFGS", options={"gtol": 1e-10})
        cand = r2 if r2.fun <= r.fun else r
        if best is None or cand.fun < best.fun:
            best = cand
    assert best is not None
    xi, loc, scale = float(best.x[0]), float(best.x[1]), math.exp(float(best.x[2]))
    ll = -float(best.fun)
    success = bool(np.isfinite(ll) and ll > -1e299)
    message = "maximum likelihood (Nelder-Mead then BFGS)" if success else "log-likelihood not finite"
    if success and xi <= -1.0:
        success, message = False, "shape <= -1: likelihood unbounded"
    return GEVFit(xi=xi, loc=loc, scale=scale, n=n, loglik=ll, success=success, message=message)


# --------------------------------------------------------------------------------------------------
# GEV: maximum likelihood for many samples at once (the bootstrap's solver)

# Damped Newton of _gev_mle_rows, in the coordinates of the data standardised by the start point:
# stop once a Newton step is below _GEV_XTOL in every coordinate (xi, mu / scale0, log sigma); the step
# is then taken, leaving an error near its square.
_GEV_XTOL = 1e-8
_GEV_MAXIT = 60
_GEV_MAXHALF = 40  # backtracking halvings per iteration
_GEV_ARMIJO = 1e-4
_GEV_MAXSTEP = 1.0  # longest step in any coordinate (standardised units)
_EULER_GAMMA = 0.5772156649015329


def _rowdot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row sums of ``a * b`` without the temporary product."""
    return np.einsum("ij,ij->i", a, b)


def _gev_loglik_rows(x: np.ndarray, th: np.ndarray) -> np.ndarray:
    """GEV log-likelihood of each row of ``x`` (B, n) at its row of ``th`` = (xi, mu, log sigma), or -inf."""
    xi, mu, lam = th[:, 0:1], th[:, 1:2], th[:, 2:3]
    z = (x - mu) * np.exp(-lam)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        t = z * _log1prel(xi * z)
        # off the support log1p gives NaN (or -inf at the boundary), so the sum is not finite there
        ll = -x.shape[1] * th[:, 2] - np.sum((1.0 + xi) * t + np.exp(-t), axis=1)
    return np.where(np.isfinite(ll), ll, -np.inf)


def _psi_chi(w: np.ndarray, r: np.ndarray, log1p_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_psi` and :func:`_chi` of ``w`` from ``r = w/(1+w)`` and ``log1p(w)`` already at hand."""
    with np.errstate(invalid="ignore", divide="ignore"):
        iw2 = 1.0 / (w * w)
        psi = (r - log1p_w) * iw2
        chi = (2.0 * (log1p_w - r) - r * r) * iw2 / w
    small = np.flatnonzero(np.abs(w) < 1e-2)
    if small.size:
        ws = w.flat[small]
        psi.flat[small] = _psi(ws)
        chi.flat[small] = _chi(ws)
    return psi, chi


def _gev_derivs_rows(x: np.ndarray, th: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Log-likelihood, gradient (B, 3) and Hessian (B, 3, 3) in :math:`(\xi, \mu, \lambda = \log\sigma)`.

    Per observation :math:`\ell = -\lambda - (1+\xi)t - e^{-t}` with :math:`t = \log(1+\xi z)/\xi`,
    :math:`z = (x-\mu)e^{-\lambda}`, so with :math:`A = e^{-t} - 1 - \xi`

    .. math:: \partial_i \ell = -\delta_{i\lambda} - \delta_{i\xi} t + A\,t_i, \qquad
              \partial_{ij}\ell = -e^{-t} t_i t_j - \delta_{i\xi} t_j - \delta_{j\xi} t_i + A\,t_{ij},

    where, with :math:`u = 1 + \xi z`: :math:`t_\xi = z^2\psi(\xi z)`, :math:`t_\mu = -1/(\sigma u)`,
    :math:`t_\lambda = -z/u`, :math:`t_{\xi\xi} = z^3\chi(\xi z)`, :math:`t_{\xi\mu} = z/(\sigma u^2)`,
    :math:`t_{\xi\lambda} = z^2/u^2`, :math:`t_{\mu\mu} = -\xi/(\sigma u)^2`,
    :math:`t_{\mu\lambda} = 1/(\sigma u^2)`, :math:`t_{\lambda\lambda} = z/u^2`. The kernels
    :func:`_psi` and :func:`_chi` are series-stabilised at :math:`\xi z \to 0`, so the Gumbel limit
    :math:`\xi = 0` is an ordinary point. Rows off the support get ``-inf`` (derivatives meaningless).
    """
    n = x.shape[1]
    xi, mu = th[:, 0:1], th[:, 1:2]
    isig = np.exp(-th[:, 2])
    z = (x - mu) * isig[:, None]
    w = xi * z
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        iu = 1.0 / (1.0 + w)
        lw = np.log1p(w)
        t = np.divide(z * lw, w, out=z.copy(), where=w != 0.0)  # z log1p(w)/w, = z at w = 0
        e = np.exp(-t)
        a = e - 1.0 - xi
        psi, chi = _psi_chi(w, w * iu, lw)
        v = z * iu  # -t_lambda
        tx = z * z * psi  # t_xi
        ex, av, ev = e * tx, a * v, e * v
        s_t, s_tx, s_iu, s_v = (np.sum(q, axis=1) for q in (t, tx, iu, v))
        ll = -n * th[:, 2] - np.sum((1.0 + xi) * t + e, axis=1)
        g = np.stack([_rowdot(a, tx) - s_t, -isig * _rowdot(a, iu), -_rowdot(a, v) - n], axis=1)
        h = np.empty((x.shape[0], 3, 3))
        h[:, 0, 0] = _rowdot(a, z * z * z * chi) - _rowdot(ex, tx) - 2.0 * s_tx
        h[:, 0, 1] = h[:, 1, 0] = isig * (_rowdot(ex, iu) + _rowdot(av, iu) + s_iu)
        h[:, 0, 2] = h[:, 2, 0] = _rowdot(ex, v) + _rowdot(av, v) + s_v
        h[:, 1, 1] = -isig * isig * (_rowdot(e + a * xi, iu * iu))
        h[:, 1, 2] = h[:, 2, 1] = isig * (_rowdot(a, iu * iu) - _rowdot(ev, iu))
        h[:, 2, 2] = _rowdot(av, iu) - _rowdot(ev, v)
    return np.where(np.isfinite(ll), ll, -np.inf), g, h


def _newton_dir(g: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Newton step ``-h^{-1} g`` per row by an explicit 3x3 Cholesky of ``-h``; ``ok`` where ``-h`` is PD."""
    a = -h
    with np.errstate(invalid="ignore", divide="ignore"):
        l00 = np.sqrt(a[:, 0, 0])
        l10, l20 = a[:, 1, 0] / l00, a[:, 2, 0] / l00
        r11 = a[:, 1, 1] - l10 * l10
        l11 = np.sqrt(r11)
        l21 = (a[:, 2, 1] - l20 * l10) / l11
        r22 = a[:, 2, 2] - l20 * l20 - l21 * l21
        l22 = np.sqrt(r22)
        y0 = g[:, 0] / l00  # solve L y = g, then L^T d = y
        y1 = (g[:, 1] - l10 * y0) / l11
        y2 = (g[:, 2] - l20 * y0 - l21 * y1) / l22
        d2 = y2 / l22
        d1 = (y1 - l21 * d2) / l11
        d0 = (y0 - l10 * d1 - l20 * d2) / l00
    d = np.stack([d0, d1, d2], axis=1)
    ok = (a[:, 0, 0] > 0) & (r11 > 0) & (r22 > 0) & np.all(np.isfinite(d), axis=1)
    return d, ok


def _gev_gumbel_start(y: np.ndarray) -> np.ndarray:
    """Gumbel moment estimate (xi, mu, log sigma) of each row: its support is the whole line."""
    sd = math.sqrt(6.0) / math.pi * np.std(y, axis=1)
    return np.stack([np.zeros(sd.size), np.mean(y, axis=1) - _EULER_GAMMA * sd, np.log(sd)], axis=1)


def _gev_pwm_start_rows(y: np.ndarray) -> np.ndarray:
    """Probability-weighted-moment estimate of each row as in :func:`_gev_pwm_start`, (xi, mu, log sigma)."""
    ys = np.sort(y, axis=1)
    n = y.shape[1]
    j = np.arange(n)
    b0 = ys.mean(axis=1)
    b1 = matvec(ys, j.astype(float)) / (n * (n - 1))
    b2 = matvec(ys, (j * (j - 1)).astype(float)) / (n * (n - 1) * (n - 2))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        c = (2 * b1 - b0) / (3 * b2 - b0) - math.log(2) / math.log(3)
        k = 7.8590 * c + 2.9554 * c * c  # Hosking's k = -xi
        g = special.gamma(1 + k)
        scale = (2 * b1 - b0) * k / (g * (1 - 2.0**-k))
        loc = b0 + scale * (g - 1) / k
        th = np.stack([-k, loc, np.log(scale)], axis=1)
    ok = (np.abs(k) >= 1e-6) & (k > -1.0) & np.all(np.isfinite(th), axis=1)
    return np.where(ok[:, None], th, _gev_gumbel_start(y))


def _ascent_dir(g: np.ndarray, h: np.ndarray, n: int) -> np.ndarray:
    """Gradient step where the Hessian is not negative definite: the maximiser of the quadratic model
    along ``g`` where it curves down along ``g`` (Cauchy step), else ``g / n``."""
    curv = -np.einsum("bi,bij,bj->b", g, h, g)
    with np.errstate(invalid="ignore", divide="ignore"):
        step = np.where(curv > 0.0, np.sum(g * g, axis=1) / curv, 1.0 / n)
    return g * step[:, None]


def _gev_newton(y: np.ndarray, th: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Damped Newton of :func:`_gev_mle_rows` on the rows of ``y`` from ``th``; ``(th, ll, status)``.

    Status 0 converged, 2 crossed xi <= -1, 3 iteration cap or failed line search. Rows whose start is
    off the support start from their Gumbel moments.
    """
    b, n = y.shape
    th = th.copy()
    ll = _gev_loglik_rows(y, th)
    off = ~np.isfinite(ll)
    if np.any(off):
        th[off] = _gev_gumbel_start(y[off])
    status = np.full(b, 3)
    active = np.arange(b)
    ll, grad, hess = _gev_derivs_rows(y, th)
    for _ in range(_GEV_MAXIT):
        if active.size == 0:
            break
        d, nd = _newton_dir(grad[active], hess[active])
        done = nd & (np.max(np.abs(d), axis=1) <= _GEV_XTOL)
        th[active[done]] += d[done]
        status[active[done]] = 0
        active, d, nd = active[~done], d[~done], nd[~done]
        d = np.where(nd[:, None], d, _ascent_dir(grad[active], hess[active], n))
        d *= np.minimum(1.0, _GEV_MAXSTEP / np.max(np.abs(d), axis=1))[:, None]
        moved = _line_search(y, th, ll, active, d, np.sum(d * grad[active], axis=1))
        active = active[moved]
        crossed = th[active, 0] <= -1.0
        status[active[crossed]] = 2
        active = active[~crossed]
        if active.size:
            ll[active], grad[active], hess[active] = _gev_derivs_rows(y[active], th[active])
    conv = status == 0
    ll[conv] = _gev_loglik_rows(y[conv], th[conv])
    status[conv & ~np.isfinite(ll)] = 3
    return th, ll, status


def _gev_mle_rows(
    x: np.ndarray, start: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    r"""GEV maximum-likelihood fit of each row of ``x`` (B, n) at once, by damped Newton.

    Parameters
    ----------
    x
        Samples of block maxima, one per row (n >= 3).
    start
        ``(xi, loc, scale)`` to start every row from (in the bootstrap: the full-sample MLE).

    Returns
    -------
    tuple of numpy.ndarray
        ``(xi, loc, scale, loglik, status)``; status 0 = converged to a local maximum, 1 = degenerate
        row (all values equal), 2 = no interior maximum found: the likelihood rose across
        :math:`\xi = -1` (it is unbounded for :math:`\xi < -1`) or stayed below its limit at
        :math:`\xi = -1`, 3 = no convergence (iteration cap or failed line search). Parameters and
        log-likelihood are those of the last iterate; they are an MLE only where status is 0.

    Notes
    -----
    Maximises the GEV log-likelihood (Coles 2001, eq. 3.7; Veerman et al., section 2)

    .. math:: \ell(\xi, \mu, \sigma) = -n\log\sigma - (1 + 1/\xi)\sum_i \log(1 + \xi z_i)
              - \sum_i (1 + \xi z_i)^{-1/\xi}, \qquad z_i = (x_i - \mu)/\sigma,

    subject to :math:`1 + \xi z_i > 0` for every value of the row, written with
    :math:`t_i = \log(1+\xi z_i)/\xi` (``log1p``, exact at :math:`\xi = 0`: the Gumbel limit
    :math:`-n\log\sigma - \sum z_i - \sum e^{-z_i}` is reached smoothly, as in :func:`fit_gev`).

    1. Standardise the rows by the start's location and scale, so the parameters
       :math:`(\xi, \mu, \lambda = \log\sigma)` are all of order one; rows whose values are not all
       inside the start's support start from their Gumbel moment estimate instead.
    2. Per row: the analytic gradient and Hessian (:func:`_gev_derivs_rows`); a Newton step where the
       Hessian is negative definite (3x3 Cholesky), else a step along the gradient :math:`g` (to the
       maximum of the quadratic model along :math:`g` if it curves down there, else :math:`g/n`);
       each step is capped at 1 in every coordinate.
    3. Backtracking line search per row (halving, Armijo condition, with a rounding allowance):
       points off the support have log-likelihood :math:`-\infty` and are rejected.
    4. Converged when the Hessian is negative definite and the Newton step is below ``_GEV_XTOL`` in
       every coordinate (that last step is taken). Rows whose iterate crosses :math:`\xi \le -1`
       stop there; the rest stop at ``_GEV_MAXIT`` iterations.
    5. Rows that did not converge are restarted from their own probability-weighted-moment estimate,
       then from their Gumbel moments (the two starts of :func:`fit_gev`). Those still failing get
       status 2 if their likelihood is below its limit at :math:`\xi = -1` (the reversed
       exponential :math:`\sigma^{-1}e^{-(b - x)/\sigma}`, :math:`b = x_{(n)}`,
       :math:`\sigma = \overline{b - x}`: log-likelihood :math:`-n\log\sigma - n`), else 3.

    A converged row is a local maximum with :math:`\xi > -1`; as in :func:`fit_gev` it is kept even
    where the :math:`\xi = -1` limit is higher (unlike :func:`fit_gpd`).

    References
    ----------
    .. [1] Coles, S. (2001), "An Introduction to Statistical Modeling of Extreme Values", Springer,
       section 3.3.2, eq. (3.7).
    .. [2] Nocedal, J. and Wright, S. J. (2006), "Numerical Optimization", 2nd ed., Springer,
       sections 3.1 (backtracking) and 3.4 (Newton with Hessian modification).
    """
    x = np.asarray(x, dtype=float)
    b, n = x.shape
    xi0, loc0, scale0 = (float(v) for v in start)
    if not (math.isfinite(xi0) and xi0 > -1.0 and math.isfinite(loc0) and scale0 > 0):
        scale0 = math.sqrt(6.0) / math.pi * float(np.std(x)) or 1.0  # Gumbel moments of all rows
        xi0, loc0 = 0.0, float(np.mean(x)) - _EULER_GAMMA * scale0
    y = (x - loc0) / scale0
    th = np.tile([xi0, 0.0, 0.0], (b, 1))
    ll = np.full(b, -np.inf)
    status = np.ones(b, dtype=int)
    rows = np.flatnonzero(np.ptp(y, axis=1) > 0.0)
    for k, make_start in enumerate((None, _gev_pwm_start_rows, _gev_gumbel_start)):
        if rows.size == 0:
            break
        th0 = th[rows] if make_start is None else make_start(y[rows])
        th_r, ll_r, st_r = _gev_newton(y[rows], th0)
        keep = (st_r == 0) | (k == 0)  # a restart replaces a failed row only where it converges
        th[rows[keep]], ll[rows[keep]], status[rows[keep]] = th_r[keep], ll_r[keep], st_r[keep]
        rows = rows[status[rows] != 0]
    if rows.size:
        ll[rows] = _gev_loglik_rows(y[rows], th[rows])
        ymax = np.max(y[rows], axis=1, keepdims=True)
        with np.errstate(divide="ignore"):
            ll_edge = -n * np.log(np.mean(ymax - y[rows], axis=1)) - n
        status[rows] = np.where((th[rows, 0] <= -1.0) | ~(ll[rows] >= ll_edge), 2, 3)
    scale = scale0 * np.exp(th[:, 2])
    return th[:, 0], loc0 + scale0 * th[:, 1], scale, ll - n * math.log(scale0), status


def _line_search(
    y: np.ndarray, th: np.ndarray, ll: np.ndarray, rows: np.ndarray, d: np.ndarray, slope: np.ndarray
) -> np.ndarray:
    """Backtracking along ``d`` for ``rows``; updates ``th`` and ``ll`` in place, returns which rows moved.

    Accepts the first step :math:`\\alpha \\in \\{1, 1/2, \\ldots\\}` with
    :math:`\\ell(\\theta + \\alpha d) \\ge \\ell(\\theta) + c\\,\\alpha\\,g^\\top d - \\epsilon`, where
    :math:`\\epsilon` allows for rounding in the sum of ``n`` terms (a step this small is only taken
    next to the maximum, where the Newton decrement sits at rounding level).
    """
    moved = np.zeros(rows.size, dtype=bool)
    alpha = np.ones(rows.size)
    pending = np.arange(rows.size)
    for _ in range(_GEV_MAXHALF):
        if pending.size == 0:
            break
        r = rows[pending]
        trial = th[r] + alpha[pending, None] * d[pending]
        ll_t = _gev_loglik_rows(y[r], trial)
        slack = 1e-13 * (y.shape[1] + np.abs(ll[r]))
        ok = np.isfinite(ll_t) & (ll_t >= ll[r] + _GEV_ARMIJO * alpha[pending] * slope[pending] - slack)
        th[r[ok]], ll[r[ok]] = trial[ok], ll_t[ok]
        moved[pending[ok]] = True
        pending = pending[~ok]
        alpha[pending] *= 0.5
    return moved


# --------------------------------------------------------------------------------------------------
# Profile likelihood of an exceedance probability

_XI_GRID = np.concatenate([np.linspace(-1.0 + 1e-6, 1.0, 161), np.linspace(1.05, 4.0, 40)])


def _loglik_at_p(y: np.ndarray, d: float, logp: float, xi: np.ndarray) -> np.ndarray:
    r"""GPD log-likelihood of ``y`` at shapes ``xi`` with the scale tied to :math:`\bar G(d) = p`.

    :math:`\sigma_p(\xi) = d / (\ell\,\mathrm{exprel}(\xi\ell))`, :math:`\ell = -\log p`; ``logp = -inf``
    (p = 0) is the boundary endpoint :math:`= d`, :math:`\sigma = -\xi d` (only for :math:`\xi < 0`).
    """
    xi = np.atleast_1d(np.asarray(xi, dtype=float))
    if np.isneginf(logp):
        sig = np.where(xi < 0, -xi * d, np.nan)
    else:
        ell = -logp
        with np.errstate(over="ignore", divide="ignore"):
            sig = d / (ell * special.exprel(xi * ell))
    with np.errstate(invalid="ignore", divide="ignore"):
        z = y[None, :] / sig[:, None]
    w = xi[:, None] * z
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        ll = -y.size * np.log(sig) - (1.0 + xi) * np.sum(z * _log1prel(w), axis=1)
        inside = np.all(w > -1.0, axis=1) & (sig > 0)
    return np.where(inside & np.isfinite(ll), ll, -np.inf)


def _profile_at_p(y: np.ndarray, d: float, logp: float) -> float:
    """:math:`\\max_\\xi` of :func:`_loglik_at_p`: grid scan, then bounded Brent around the best point."""
    ll = _loglik_at_p(y, d, logp, _XI_GRID)
    k = int(np.argmax(ll))
    if not np.isfinite(ll[k]):
        return -math.inf
    lo = _XI_GRID[max(k - 1, 0)]
    hi = _XI_GRID[min(k + 1, _XI_GRID.size - 1)]
    r = optimize.minimize_scalar(
        lambda t: -float(_loglik_at_p(y, d, logp, np.array([t]))[0]),
        bounds=(lo, hi),
        method="bounded",
        options={"xatol": 1e-10},
    )
    return max(float(ll[k]), -float(r.fun))


def profile_ci_exceedance(fit: GPDFit, x: float, *, level: float = 0.95) -> tuple[float, float]:
    r"""Profile-likelihood interval for the conditional exceedance probability :math:`p = \bar G(x - u)`.

    Parameters
    ----------
    fit
        GPD fit (its excesses are used).
    x
        Level above the threshold (for :math:`P_{MI}`: SI = 1).
    level
        Confidence level (:math:`\chi^2_1` cut).

    Returns
    -------
    tuple of float
        ``(lower, upper)`` for :math:`P(X > x \mid X > u)`; multiply by :math:`\zeta_u` for the
        unconditional probability.

    Notes
    -----
    Reparametrise the GPD by :math:`(\xi, p)` with :math:`p = \bar G(d)`, :math:`d = x - u`: for a
    fixed :math:`p` the scale is tied to the shape,

    .. math:: \sigma_p(\xi) = \frac{\xi d}{p^{-\xi} - 1} = \frac{d}{\ell\,\mathrm{exprel}(\xi \ell)},
              \qquad \ell = -\log p,

    and the profile :math:`\ell_p(p) = \max_\xi \ell(\xi, \sigma_p(\xi))` gives the interval
    :math:`\{p: 2(\hat\ell - \ell_p(p)) \le \chi^2_1(\text{level})\}` (Coles 2001, section 4.3.3, for
    return levels; here for the probability). The ends are found by Brent's method in :math:`\log p`.

    Finite endpoint: :math:`p = 0` is admissible (the level lies at or beyond the endpoint
    :math:`u - \sigma/\xi`, :math:`\xi < 0`); its profile is the maximum over the boundary
    "endpoint = :math:`x`", :math:`\sigma = -\xi d`, which requires :math:`x \ge \max` of the data. If it
    is within the cut, the lower end is reported as exactly 0. When :math:`\hat p = 0` the profile
    jumps at 0 (every :math:`p > 0` forces the endpoint beyond :math:`x`): the result is
    ``(0, upper)`` with ``upper`` the largest :math:`p > 0` inside the cut, or ``(0, 0)`` if none is.
    Shapes are searched on :math:`(-1, 4]`.
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    y = fit.excesses
    d = float(x) - fit.threshold
    if d <= 0:
        raise ValueError(f"x must lie above the threshold {fit.threshold}, got {x}")
    cut = fit.loglik - 0.5 * float(stats.chi2.isf(1.0 - level, 1))
    p_hat = float(fit.sf(x))

    def f(lp: float) -> float:
        return _profile_at_p(y, d, lp) - cut

    # p = 0 set {endpoint <= x}: the MLE itself when p_hat = 0, else its boundary endpoint = x
    if p_hat == 0.0:
        at_zero = fit.loglik
    else:
        at_zero = _profile_at_p(y, d, -math.inf) if d >= float(np.max(y)) else -math.inf
    if p_hat == 0.0:
        # The profile jumps at p = 0 (p > 0 forces the endpoint beyond x): scan p > 0 on a grid of
        # log p and report the hull [0, upper] of {0} and the p > 0 part of the set (empty: upper 0).
        grid = -np.geomspace(700.0, 1e-3, 80)
        ok = np.flatnonzero([f(float(v)) >= 0 for v in grid])
        if ok.size == 0:
            return 0.0, 0.0
        j = int(ok[-1])
        if j == grid.size - 1:
            return 0.0, 1.0
        return 0.0, math.exp(optimize.brentq(f, float(grid[j]), float(grid[j + 1]), xtol=1e-10))
    # upper end: from log p_hat up towards log p = 0 (p = 1 has no likelihood)
    start = math.log(p_hat)
    hi_lp = start
    while True:
        hi_lp = min(hi_lp + 1.0, 0.5 * hi_lp) if hi_lp < -2.0 else 0.5 * hi_lp
        if f(hi_lp) < 0:
            upper = math.exp(optimize.brentq(f, start, hi_lp, xtol=1e-10))
            break
        if hi_lp > -1e-12:
            upper = 1.0
            break
    if at_zero >= cut:
        return 0.0, upper
    lo_lp, step = math.log(p_hat), 1.0
    while True:
        cand = lo_lp - step
        if f(cand) < 0:
            return math.exp(optimize.brentq(f, cand, lo_lp, xtol=1e-10)), upper
        if cand < -740.0:
            return 0.0, upper
        lo_lp, step = cand, 2.0 * step
