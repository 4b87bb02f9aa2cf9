r"""Bootstrap confidence intervals for GPD tail fits, GEV block-maxima fits and exceedance probabilities.

Veerman et al. (GIMAT), section 3.7: confidence levels of the misleading-information probability are
obtained by bootstrapping (1000 resamples in GIMAT); section 3.5: :math:`P_{MI95}` is the upper end of
the bootstrap distribution of the extrapolated exceedance probability.

All resamples are fitted at once: the resampled excesses form a ``(n_boot, n)`` array and the
profile-likelihood root of each row is found by a few vectorised Newton steps started from the point
estimate (rows that do not converge fall back to the grid-scan core of :func:`overbound.stats.evt.fit_gpd`).
The GEV resamples of block maxima (section 4) are likewise fitted at once, by a vectorised damped Newton
(:func:`bootstrap_gev`).
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtr, ndtri

from overbound.stats.evt import (
    GEVFit,
    _gev_mle_rows,
    _gpd_mle_rows,
    _gpd_profile,
    _gpd_score,
    _log1prel,
    fit_gev,
    fit_gpd,
    gpd_sf,
)

__all__ = [
    "ExceedanceCI",
    "GEVBootstrap",
    "GPDBootstrap",
    "bca_ci",
    "bootstrap_gev",
    "bootstrap_gpd",
    "jackknife_gpd",
    "p_exceed_ci",
    "percentile_ci",
    "stationary_indices",
]

# Rows per chunk for the Newton iteration: keeps the working arrays in cache (64 x 1e4 doubles = 5 MB).
_CHUNK_ELEMS = 1 << 19
# Newton stops after a step in s = tau * max(y) below this (quadratic convergence: the last step leaves
# an error near the square of the previous one; the score itself is accurate to about 1e-13 in s).
_NEWTON_STOL = 1e-9
_NEWTON_MAXIT = 30
# Below |tau max(y)| < _SMALL the score is taken from the series-stabilised kernel of evt._gpd_score.
_SMALL = 1e-2


def _rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


@dataclass(frozen=True, slots=True)
class GPDBootstrap:
    r"""Result of :func:`bootstrap_gpd`.

    Attributes
    ----------
    xi, sigma : numpy.ndarray
        Shape and scale of the GPD fitted to each resample (length ``n_boot``).
    xi_hat, sigma_hat : float
        Point estimate from the original excesses.
    n : int
        Number of excesses per resample (that of the data).
    method : str
        ``"iid"`` or ``"stationary"``.
    mean_block : float
        Mean block length of the stationary bootstrap (1 for iid).
    n_fallback : int
        Resamples whose Newton iteration did not converge and were refitted by the grid-scan core.
    success : numpy.ndarray
        Per resample: an interior maximum was found (False where the likelihood is unbounded, xi <= -1).
    paired_sums : numpy.ndarray
        ``(n_boot, k)`` sums of the ``paired`` values over each resample (``k = 0`` without them).
    """

    xi: np.ndarray = field(repr=False)
    sigma: np.ndarray = field(repr=False)
    xi_hat: float
    sigma_hat: float
    n: int
    method: str
    mean_block: float
    n_fallback: int
    success: np.ndarray = field(repr=False)
    paired_sums: np.ndarray = field(default_factory=lambda: np.empty((0, 0)), repr=False)

    def xi_ci(self, level: float = 0.95) -> tuple[float, float]:
        """Percentile interval of the shape."""
        return percentile_ci(self.xi, level)


def percentile_ci(values: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    r"""Two-sided percentile bootstrap interval :math:`[q_{(1-level)/2}, q_{(1+level)/2}]`.

    Quantiles by numpy's default (linear interpolation, Hyndman & Fan type 7). NaN values are ignored.

    Examples
    --------
    >>> [round(v, 9) for v in percentile_ci(np.arange(101.0), 0.9)]
    [5.0, 95.0]
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    v = np.asarray(values, dtype=float)
    lo, hi = np.nanquantile(v, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return float(lo), float(hi)


def bca_ci(
    samples: np.ndarray, estimate: float, jackknife: np.ndarray, level: float = 0.95
) -> tuple[float, float]:
    r"""Bias-corrected and accelerated (BCa) bootstrap interval (Efron 1987).

    Parameters
    ----------
    samples
        Bootstrap replicates :math:`\hat\theta^*_b` of the statistic (NaN ignored).
    estimate
        The statistic :math:`\hat\theta` on the data.
    jackknife
        Leave-one-out values :math:`\hat\theta_{(i)}` of the statistic (one per resampled unit).
    level
        Two-sided level.

    Returns
    -------
    tuple of float
        :math:`[q_{\alpha_1}, q_{\alpha_2}]`, sample quantiles of the replicates at

        .. math::

            \alpha_{1,2} = \Phi\Bigl(z_0 + \frac{z_0 + z_{\alpha}}{1 - a (z_0 + z_{\alpha})}\Bigr),
            \quad z_\alpha = \Phi^{-1}\bigl((1 \mp \text{level})/2\bigr),

        with the bias correction :math:`z_0 = \Phi^{-1}(\#\{\hat\theta^*_b < \hat\theta\}/B)` (ties
        counted half) and the acceleration
        :math:`a = \sum d_i^3 / (6 (\sum d_i^2)^{3/2})`, :math:`d_i = \bar\theta_{(\cdot)} - \hat\theta_{(i)}`
        (Efron 1987, eqs. 6.6 and 6.7; Efron & Tibshirani 1993, eq. 14.15).

    Notes
    -----
    With :math:`z_0 = a = 0` this is the percentile interval. :math:`z_0` is clipped to the range a
    bootstrap of ``B`` replicates can resolve (:math:`\Phi^{-1}(1/(2B))`), so that an estimate outside
    all replicates gives the outermost replicate instead of an infinite correction.

    References
    ----------
    .. [1] Efron, B. (1987), "Better bootstrap confidence intervals", JASA 82(397), 171-185.
    .. [2] Efron, B. and Tibshirani, R. J. (1993), An Introduction to the Bootstrap, ch. 14.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> s = rng.normal(0.0, 1.0, 4000)
    >>> lo, hi = bca_ci(s, 0.0, np.linspace(-1.0, 1.0, 50), 0.9)
    >>> bool(abs(lo + 1.645) < 0.1 and abs(hi - 1.645) < 0.1)
    True
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    v = np.asarray(samples, dtype=float)
    v = v[~np.isnan(v)]
    if v.size == 0:
        return math.nan, math.nan
    b = v.size
    frac = (np.count_nonzero(v < estimate) + 0.5 * np.count_nonzero(v == estimate)) / b
    z0 = float(ndtri(min(max(frac, 0.5 / b), 1.0 - 0.5 / b)))
    jk = np.asarray(jackknife, dtype=float)
    jk = jk[np.isfinite(jk)]
    d = jk.mean() - jk if jk.size else jk
    scale = float(np.max(np.abs(d))) if d.size else 0.0
    d = d / scale if scale > 0 else d  # a is scale-free; tiny jackknife values (p ~ 1e-200) underflow d**3
    ss = float(np.sum(d * d))
    a = float(np.sum(d**3)) / (6.0 * ss**1.5) if ss > 0 else 0.0
    z = ndtri(np.array([(1.0 - level) / 2.0, (1.0 + level) / 2.0]))
    w = z0 + z
    alpha = ndtr(z0 + w / np.maximum(1.0 - a * w, 1e-12))
    lo, hi = np.quantile(v, alpha)
    return float(lo), float(hi)


def jackknife_gpd(excesses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Leave-one-out GPD maximum-likelihood fits of ``excesses``: shape and scale per left-out value.

    The ``n`` samples of ``n - 1`` excesses are fitted at once like the bootstrap resamples (vectorised
    Newton from the full-sample estimate, grid-scan core where it fails), so each pair equals
    :func:`~overbound.stats.evt.fit_gpd` of that sample. Used for the BCa acceleration (:func:`bca_ci`).
    """
    y = _validate_bootstrap(excesses, 1, "iid", None)
    n = y.size
    if n < 4:
        raise ValueError(f"need at least 4 excesses for a jackknife, got {n}")
    fit = fit_gpd(y)
    tau0 = fit.xi / fit.sigma if fit.success else 0.0
    # row i holds every excess but the i-th: drop the diagonal of the (n, n) repetition
    keep = ~np.eye(n, dtype=bool)
    loo = np.broadcast_to(y, (n, n))[keep].reshape(n, n - 1)
    xi, sig, _, _ = _fit_chunk(loo, tau0)
    return xi, sig


def stationary_indices(
    n: int, *, n_boot: int, mean_block: float, rng: np.random.Generator | int | None = None
) -> np.ndarray:
    r"""Indices of the stationary bootstrap (Politis & Romano 1994), shape ``(n_boot, n)``.

    Each resample is a concatenation of blocks of the circularly wrapped series; blocks start at a
    uniform position and have geometric lengths of mean ``mean_block`` (a new block starts at each
    position with probability :math:`1/\text{mean\_block}`), so that the resampled series is stationary.
    ``mean_block = 1`` is the iid bootstrap.
    """
    if mean_block < 1.0:
        raise ValueError(f"mean_block must be >= 1, got {mean_block}")
    g = _rng(rng)
    p = 1.0 / mean_block
    new = g.random((n_boot, n)) < p
    new[:, 0] = True
    start = g.integers(0, n, size=(n_boot, n))
    pos = np.arange(n)
    # position of the latest block start at or before each position
    last = np.maximum.accumulate(np.where(new, pos, 0), axis=1)
    rows = np.arange(n_boot)[:, None]
    return (start[rows, last] + (pos - last)) % n


def _score_slope(y: np.ndarray, tau: np.ndarray, ymax: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""Profile score :math:`g(\tau) = 1/\tau - \bar q(1+\xi)/\xi` (per observation) and its slope.

    :math:`\xi = \overline{\log(1+\tau y)}`, :math:`\bar q = \overline{y/(1+\tau y)}`,
    :math:`g' = -1/\tau^2 + \overline{q^2}(1+\xi)/\xi + \bar q^2/\xi^2`. Where :math:`|\tau y_{(n)}| <`
    ``_SMALL`` the score comes from the stabilised kernel and the slope is evaluated at
    :math:`|\tau y_{(n)}| =` ``_SMALL`` (Newton then uses an approximate slope, still convergent).
    """
    small = np.abs(tau) * ymax < _SMALL
    tt = np.where(small, np.where(tau < 0, -_SMALL, _SMALL) / ymax, tau)
    # the same operations as y/(1+w), log1p(w), r*r, written into two buffers (no temporaries: the
    # chunk is 64 x 1e4 doubles and this is the bootstrap's hot loop)
    w = np.multiply(tt[:, None], y)
    buf = np.log1p(w)
    xi = np.mean(buf, axis=1)
    np.add(w, 1.0, out=w)
    r = np.divide(y, w, out=w)
    q = np.mean(r, axis=1)
    q2 = np.mean(np.multiply(r, r, out=buf), axis=1)
    g = 1.0 / tt - q * (1.0 + xi) / xi
    dg = -1.0 / (tt * tt) + q2 * (1.0 + xi) / xi + (q / xi) ** 2
    if np.any(small):
        g = g.copy()
        g[small] = _gpd_score(y[small], tau[small])
    return g, dg


def _newton_rows(y: np.ndarray, tau0: float) -> tuple[np.ndarray, np.ndarray]:
    """Newton iteration on the profile score from ``tau0`` for every row; returns ``(tau, converged)``."""
    b = y.shape[0]
    ymax = np.max(y, axis=1)
    tau = np.full(b, tau0)
    conv = np.zeros(b, dtype=bool)
    active = np.ones(b, dtype=bool)
    for _ in range(_NEWTON_MAXIT):
        ia = np.flatnonzero(active)
        if ia.size == 0:
            break
        # all rows active (the first steps): the rows themselves, not a gathered copy of the chunk
        g, dg = _score_slope(y if ia.size == b else y[ia], tau[ia], ymax[ia])
        ok = dg < 0.0  # concave there: a Newton step moves towards the maximum
        step = np.where(ok, -g / np.where(ok, dg, -1.0), 0.0)
        new = tau[ia] + step
        # stay inside the support 1 + tau y > 0: at most halfway to the boundary -1/max(y)
        lim = -1.0 / ymax[ia]
        new = np.where(new <= lim, 0.5 * (tau[ia] + lim), new)
        tau[ia] = new
        done = ok & (np.abs(step) * ymax[ia] <= _NEWTON_STOL)
        conv[ia[done]] = True
        active[ia[done | ~ok]] = False
    return tau, conv


def _fit_chunk(yc: np.ndarray, tau0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """GPD MLE of each row, Newton from ``tau0``, grid-scan core where Newton fails. (xi, sigma, ok, nfb)."""
    n = yc.shape[1]
    tau, conv = _newton_rows(yc, tau0)
    xi, sig, ll = _gpd_profile(yc, tau[:, None])
    xi, sig, ll = xi[:, 0], sig[:, 0], ll[:, 0] * n
    ymax = np.max(yc, axis=1)
    # a stationary point below the uniform boundary likelihood (xi -> -1) or with xi < -1 is refitted
    conv &= np.isfinite(ll) & (ll >= -n * np.log(ymax)) & (xi >= -1.0)
    ok = np.ones(yc.shape[0], dtype=bool)
    bad = ~conv
    if np.any(bad):
        xb, sb, _, stb = _gpd_mle_rows(yc[bad])
        xi[bad], sig[bad] = xb, sb
        ok[bad] = stb == 0
    return xi, sig, ok, int(bad.sum())


def _validate_bootstrap(
    excesses: np.ndarray, n_boot: int, method: str, times: np.ndarray | None
) -> np.ndarray:
    y = np.asarray(excesses, dtype=float)
    if y.ndim != 1 or y.size < 3:
        raise ValueError(f"need a 1-D array of at least 3 excesses, got shape {y.shape}")
    if not np.all(np.isfinite(y)) or np.min(y) < 0:
        raise ValueError("excesses must be finite and >= 0")
    if n_boot < 1:
        raise ValueError(f"n_boot must be >= 1, got {n_boot}")
    if method not in ("iid", "stationary"):
        raise ValueError(f"method must be 'iid' or 'stationary', got {method!r}")
    if times is not None:
        t = np.asarray(times, dtype=float)
        if t.shape != y.shape:
            raise ValueError(f"times must have the shape of excesses {y.shape}, got {t.shape}")
        y = y[np.argsort(t, kind="stable")]
    return y


def bootstrap_gpd(
    excesses: np.ndarray,
    *,
    n_boot: int = 1000,
    rng: np.random.Generator | int | None = None,
    method: str = "iid",
    mean_block: float | None = None,
    times: np.ndarray | None = None,
    workers: int | None = None,
    paired: np.ndarray | None = None,
) -> GPDBootstrap:
    r"""Bootstrap distribution of the GPD maximum-likelihood estimate.

    Parameters
    ----------
    excesses
        Excesses over the threshold (>= 0), in time order or with ``times``.
    n_boot
        Number of resamples (GIMAT uses 1000, Veerman et al. section 3.7).
    rng
        Seed or generator; the same seed gives the same resamples.
    method
        ``"iid"`` (default) resamples excesses with replacement; ``"stationary"`` is the stationary
        bootstrap of Politis & Romano (1994) for dependent excesses.
    mean_block
        Mean block length (in excesses) of the stationary bootstrap; default :math:`n^{1/3}`.
    times
        Times of the excesses; only their order is used (the stationary bootstrap needs time order).
    paired
        Optional ``(k, n)`` values attached to the excesses (e.g. the size of each cluster); each
        resample also returns their sums over the drawn excesses (``paired_sums``), so that a statistic
        of them is resampled jointly with the fit.
    workers
        Threads over chunks of resamples (default: all cores). Each chunk draws from its own child
        generator (``rng.spawn``), so the numbers do not depend on ``workers``.

    Returns
    -------
    GPDBootstrap

    Notes
    -----
    Declustered cluster maxima (Veerman et al., section 3.2) are nearly independent by construction,
    hence iid is the default; use ``"stationary"`` for all exceedances of a dependent series. The default
    mean block :math:`n^{1/3}` is the optimal rate of Politis & White (2004) without its constant.

    1. Draw the ``(n_boot, n)`` index array (iid uniform, or stationary blocks).
    2. Start each row at the point estimate :math:`\hat\tau = \hat\xi/\hat\sigma` and take Newton steps
       on the profile score in :math:`\tau` (Grimshaw 1993), in chunks of rows, with the step kept
       inside the support :math:`1 + \tau y_{(n)} > 0`.
    3. Rows that do not converge, converge where the profile is not concave, or whose stationary point
       is beaten by the :math:`\xi \to -1` boundary are refitted by the grid-scan core of
       :func:`~overbound.stats.evt.fit_gpd`, so every row equals a single fit (tested to 1e-8).

    References
    ----------
    .. [1] Veerman et al., "A Tool for GNSS Integrity Verification Based on Statistical Extreme Value
       Theory", sections 3.5 and 3.7.
    .. [2] Politis, D. N. and Romano, J. P. (1994), "The stationary bootstrap", JASA 89(428), 1303-1313.
    .. [3] Politis, D. N. and White, H. (2004), "Automatic block-length selection for the dependent
       bootstrap", Econometric Reviews 23(1), 53-70.

    Examples
    --------
    >>> y = np.random.default_rng(0).exponential(1.0, 500)
    >>> bs = bootstrap_gpd(y, n_boot=200, rng=1)
    >>> bs.xi.shape, bs.n_fallback
    ((200,), 0)
    """
    y = _validate_bootstrap(excesses, n_boot, method, times)
    n = y.size
    g = _rng(rng)
    fit = fit_gpd(y)
    if method == "iid":
        mb = 1.0
    else:
        mb = float(mean_block) if mean_block is not None else max(1.0, n ** (1.0 / 3.0))
    tau0 = fit.xi / fit.sigma if fit.success else 0.0
    pv = np.empty((0, n)) if paired is None else np.atleast_2d(np.asarray(paired, dtype=np.float64))
    if pv.shape[1] != n:
        raise ValueError(f"paired must have {n} columns (one per excess), got shape {pv.shape}")
    chunk = max(1, _CHUNK_ELEMS // n)
    sizes = [min(chunk, n_boot - s) for s in range(0, n_boot, chunk)]
    children = g.spawn(len(sizes))  # one stream per chunk: results do not depend on the threads

    def work(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        if method == "iid":
            idx = children[k].integers(0, n, size=(sizes[k], n), dtype=np.int32)
        else:
            idx = stationary_indices(n, n_boot=sizes[k], mean_block=mb, rng=children[k])
        xi, sig, ok, nfb = _fit_chunk(y[idx], tau0)
        sums = np.stack([v[idx].sum(axis=1) for v in pv], axis=1) if pv.size else np.empty((idx.shape[0], 0))
        return xi, sig, ok, nfb, sums

    nw = min(len(sizes), workers if workers is not None else (os.cpu_count() or 1))
    if nw > 1:
        with ThreadPoolExecutor(max_workers=nw) as ex:
            parts = list(ex.map(work, range(len(sizes))))
    else:
        parts = [work(k) for k in range(len(sizes))]
    return GPDBootstrap(
        xi=np.concatenate([p[0] for p in parts]),
        sigma=np.concatenate([p[1] for p in parts]),
        xi_hat=fit.xi,
        sigma_hat=fit.sigma,
        n=n,
        method=method,
        mean_block=mb,
        n_fallback=sum(p[3] for p in parts),
        success=np.concatenate([p[2] for p in parts]),
        paired_sums=np.concatenate([p[4] for p in parts]),
    )


@dataclass(frozen=True, slots=True)
class GEVBootstrap:
    r"""Result of :func:`bootstrap_gev`.

    Attributes
    ----------
    xi, loc, scale : numpy.ndarray
        GEV parameters fitted to each resample (length ``n_boot``; shape :math:`\xi > 0` Fréchet);
        NaN where the fit did not converge.
    loglik : numpy.ndarray
        Maximised log-likelihood of each resample (NaN where not converged).
    converged : numpy.ndarray
        Per resample: the solver converged to an interior maximum (False for degenerate resamples,
        for :math:`\xi \le -1` where the likelihood is unbounded, and at the iteration cap).
    status : numpy.ndarray
        Per resample, the code of :func:`~overbound.stats.evt._gev_mle_rows` (0 converged,
        1 all values equal, 2 no interior maximum / :math:`\xi \le -1`, 3 no convergence).
    n_failed : int
        Number of resamples not converged.
    fit : GEVFit
        The full-sample fit the resample fits started from.
    n : int
        Number of block maxima per resample (that of the data).
    """

    xi: np.ndarray = field(repr=False)
    loc: np.ndarray = field(repr=False)
    scale: np.ndarray = field(repr=False)
    loglik: np.ndarray = field(repr=False)
    converged: np.ndarray = field(repr=False)
    status: np.ndarray = field(repr=False)
    n_failed: int
    fit: GEVFit
    n: int

    def sf(self, x: float) -> np.ndarray:
        r"""GEV survival :math:`P(M > x)` of each resample's fit at ``x`` (NaN where not converged).

        Written as :func:`~overbound.stats.evt.gev_sf` for arrays of parameters: :math:`-\mathrm{expm1}
        (-e^{-t})`, :math:`t = \log(1+\xi z)/\xi`; outside the support 0 above a finite endpoint
        (:math:`\xi < 0`) and 1 below a finite lower end (:math:`\xi > 0`).
        """
        z = (float(x) - self.loc) / self.scale
        w = self.xi * z
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            t = z * _log1prel(w)
            out = -np.expm1(-np.exp(-t))
        out = np.where(w > -1.0, out, np.where(self.xi < 0, 0.0, 1.0))
        return np.where(self.converged, out, np.nan)

    def xi_ci(self, level: float = 0.95) -> tuple[float, float]:
        """Percentile interval of the shape over the converged resamples."""
        return percentile_ci(self.xi, level)


def bootstrap_gev(
    block_maxima: np.ndarray,
    *,
    n_boot: int = 1000,
    rng: np.random.Generator | int | None = None,
    start: GEVFit | None = None,
) -> GEVBootstrap:
    r"""Bootstrap distribution of the GEV maximum-likelihood estimate on block maxima.

    Parameters
    ----------
    block_maxima
        One maximum per block (daily maxima of the safety index in the EVT analysis); at least 3,
        finite, not all equal.
    n_boot
        Number of resamples (GIMAT uses 1000, Veerman et al. section 3.7).
    rng
        Seed or generator; the same seed gives the same resamples and numbers.
    start
        Full-sample fit to start every resample from; :func:`~overbound.stats.evt.fit_gev` of the
        data when ``None``.

    Returns
    -------
    GEVBootstrap

    Notes
    -----
    Veerman et al., section 3.7 (bootstrap confidence of the GEV parameters) and section 4 (GEV on
    daily block maxima). Block maxima of different days are taken as independent, so resampling is iid.

    1. Draw the resamples: row ``k`` is ``block_maxima[idx[k]]`` with
       ``idx = rng.integers(0, n, size=(n_boot, n))`` (drawn in consecutive chunks of rows, which gives
       the same indices).
    2. Fit all rows at once by :func:`~overbound.stats.evt._gev_mle_rows`: damped Newton in
       :math:`(\xi, \mu, \log\sigma)` on the analytic gradient and Hessian of the GEV log-likelihood
       (Coles 2001, eq. 3.7) from the full-sample MLE, with a backtracking line search per row inside
       the support, a gradient step where the Hessian is not negative definite and an iteration cap;
       rows that fail are restarted from their own moment estimates (the starts of ``fit_gev``).
    3. Rows that still do not converge (degenerate resamples, :math:`\xi \le -1`, no interior
       maximum, cap) are flagged in ``converged`` and counted in ``n_failed``; their parameters are NaN.

    A converged row is a local maximum with :math:`\xi > -1`; where
    :func:`~overbound.stats.evt.fit_gev` succeeds it is the same fit (tested to 1e-5). It may also be
    found where ``fit_gev`` wanders to :math:`\xi < -1`, where the likelihood is unbounded.

    References
    ----------
    .. [1] Veerman et al., "A Tool for GNSS Integrity Verification Based on Statistical Extreme Value
       Theory", sections 3.7 and 4.
    .. [2] Coles, S. (2001), "An Introduction to Statistical Modeling of Extreme Values", Springer,
       section 3.3.2.

    Examples
    --------
    >>> x = np.random.default_rng(0).gumbel(0.3, 0.05, 90)
    >>> bs = bootstrap_gev(x, n_boot=200, rng=1)
    >>> bs.xi.shape, bs.n_failed
    ((200,), 0)
    """
    x = np.asarray(block_maxima, dtype=float)
    if x.ndim != 1 or x.size < 3:
        raise ValueError(f"need a 1-D array of at least 3 block maxima, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("block maxima contain NaN or inf")
    if np.ptp(x) == 0:
        raise ValueError("block maxima are all equal")
    if n_boot < 1:
        raise ValueError(f"n_boot must be >= 1, got {n_boot}")
    g = _rng(rng)
    fit = start if start is not None else fit_gev(x)
    n = x.size
    chunk = max(1, _CHUNK_ELEMS // n)
    parts = []
    for s in range(0, n_boot, chunk):
        idx = g.integers(0, n, size=(min(chunk, n_boot - s), n))
        parts.append(_gev_mle_rows(x[idx], (fit.xi, fit.loc, fit.scale)))
    xi, loc, scale, ll, status = (np.concatenate([p[k] for p in parts]) for k in range(5))
    conv = status == 0
    nan = np.where(conv, 1.0, np.nan)
    return GEVBootstrap(
        xi=xi * nan,
        loc=loc * nan,
        scale=scale * nan,
        loglik=ll * nan,
        converged=conv,
        status=status,
        n_failed=int(n_boot - conv.sum()),
        fit=fit,
        n=n,
    )


@dataclass(frozen=True, slots=True)
class ExceedanceCI:
    r"""Result of :func:`p_exceed_ci`.

    Attributes
    ----------
    p : float
        Point estimate :math:`\hat\zeta_u\,\bar G(x - u)` (per sample of the series behind ``n_total``).
    lower, upper : float
        Two-sided percentile interval at ``level``.
    upper_bound : float
        One-sided upper bound: the ``level`` quantile of the resampled probabilities (the paper's
        :math:`P_{MI95}` for ``level = 0.95``).
    level : float
    samples : numpy.ndarray
        Resampled probabilities :math:`\zeta_u^*\,\bar G^*(x - u)`.
    zeta : numpy.ndarray
        Resampled exceedance rates.
    """

    p: float
    lower: float
    upper: float
    upper_bound: float
    level: float
    samples: np.ndarray = field(repr=False)
    zeta: np.ndarray = field(repr=False)


def _stationary_counts(
    positions: np.ndarray, n_total: int, *, n_boot: int, mean_block: float, g: np.random.Generator
) -> np.ndarray:
    """Exceedance counts of stationary-bootstrap resamples of the 0/1 series with ones at ``positions``.

    Each resample is a sequence of circular windows ``[s, s + L)`` (uniform start, geometric length of
    mean ``mean_block``, the last one cut at ``n_total``); its count is a difference of cumulative counts.
    """
    p2 = np.concatenate([positions, positions + n_total])
    k = math.ceil(1.5 * n_total / mean_block) + 20
    rows = max(1, (1 << 22) // k)
    out = np.empty(n_boot, dtype=np.int64)
    for r0 in range(0, n_boot, rows):
        nb = min(rows, n_boot - r0)
        while True:
            lengths = g.geometric(1.0 / mean_block, size=(nb, k))
            ends = np.cumsum(lengths, axis=1)
            if np.all(ends[:, -1] >= n_total):
                break
            k *= 2
        begins = ends - lengths
        lengths = np.clip(np.minimum(ends, n_total) - begins, 0, None)
        starts = g.integers(0, n_total, size=(nb, k))
        cnt = np.searchsorted(p2, starts + lengths) - np.searchsorted(p2, starts)
        out[r0 : r0 + nb] = np.sum(np.where(lengths > 0, cnt, 0), axis=1)
    return out


def p_exceed_ci(
    boot: GPDBootstrap,
    *,
    x_excess: float,
    n_total: int,
    level: float = 0.95,
    rng: np.random.Generator | int | None = None,
    positions: np.ndarray | None = None,
    mean_block: float | None = None,
) -> ExceedanceCI:
    r"""Bootstrap interval and upper bound of an exceedance probability :math:`\zeta_u\,\bar G(x - u)`.

    Parameters
    ----------
    boot
        GPD bootstrap of the ``boot.n`` excesses over the threshold :math:`u`.
    x_excess
        The level as an excess, :math:`x - u` (for :math:`P_{MI}`: :math:`1 - L_{Tail}`).
    n_total
        Number of samples of the series the ``boot.n`` exceedances come from
        (:math:`\hat\zeta_u = n_u / N`).
    level
        Confidence level of the two-sided interval and of the one-sided upper bound.
    rng
        Seed or generator for the resampled rate.
    positions
        Stationary bootstrap only: sample index (0 ... ``n_total`` - 1) of each exceedance.
    mean_block
        Stationary bootstrap only: mean block length in samples of the series (default
        :math:`N^{1/3}`).

    Returns
    -------
    ExceedanceCI

    Notes
    -----
    Veerman et al., section 3.5: :math:`P_{MI} = \zeta_u \bar G_{\hat\gamma,\hat\beta}(1 - L_{Tail})`
    with its bootstrap distribution, :math:`P_{MI95}` its upper 95 % point.

    The rate :math:`\zeta_u` is resampled too, independently of the GPD parameters (the two are
    asymptotically independent: the POT likelihood factorises into a binomial part for
    :math:`\zeta_u` and the GPD part):

    * iid bootstrap: :math:`n_u^* \sim \mathrm{Binomial}(N, n_u/N)`, :math:`\zeta^* = n_u^*/N`;
    * stationary bootstrap: :math:`n_u^*` is the exceedance count of a stationary-bootstrap resample of
      the whole 0/1 exceedance series of length :math:`N` (blocks of geometric length), which carries
      the clustering of exceedances into the variance of the rate.
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if n_total < boot.n:
        raise ValueError(f"n_total ({n_total}) must be >= the number of exceedances ({boot.n})")
    g = _rng(rng)
    b = boot.xi.size
    if boot.method == "iid":
        counts = g.binomial(n_total, boot.n / n_total, size=b)
    else:
        if positions is None:
            raise ValueError("the stationary bootstrap needs the positions of the exceedances")
        pos = np.sort(np.asarray(positions, dtype=np.int64))
        if pos.size != boot.n or pos[0] < 0 or pos[-1] >= n_total:
            raise ValueError("positions must be boot.n sample indices in [0, n_total)")
        mb = float(mean_block) if mean_block is not None else max(1.0, n_total ** (1.0 / 3.0))
        counts = _stationary_counts(pos, n_total, n_boot=b, mean_block=mb, g=g)
    zeta = counts / n_total
    samples = zeta * gpd_sf(x_excess, xi=boot.xi, sigma=boot.sigma)
    p_hat = boot.n / n_total * float(gpd_sf(x_excess, xi=boot.xi_hat, sigma=boot.sigma_hat))
    lo, hi = percentile_ci(samples, level)
    ub = float(np.quantile(samples, level))
    return ExceedanceCI(p=p_hat, lower=lo, upper=hi, upper_bound=ub, level=level, samples=samples, zeta=zeta)
