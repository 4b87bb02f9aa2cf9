"""Figures of the tail-extrapolation (EVT) analysis, after Veerman et al., sections 3.2-3.5.

Dependence (section 3.2): the autocorrelation of the safety index (:func:`plot_acf`), the
V_K curve with its cluster gap (:func:`plot_vk`) and the declustered exceedances
(:func:`plot_clusters`). Threshold (section 3.3): the mean-excess plot (:func:`plot_mean_excess`,
the paper's figure 2), the shape against the threshold with its confidence band
(:func:`plot_shape_stability`, figure 3) and P_MI against the threshold
(:func:`plot_p_mi_vs_threshold`). Fit and overbounding (section 3.5): the tail of the safety index
with the fitted GPD extrapolated to SI = 1 (:func:`plot_tail_fit`) and the KRS statistic
(:func:`plot_krs`).

Every figure is a pure function of primitive results (:mod:`overbound.stats`) and arrays, with an
optional ``ax``; it draws inside :func:`~overbound.report.figures.style` on a
:func:`~overbound.report.figures.new_figure` when no ``ax`` is given (never through pyplot) and
returns the :class:`~matplotlib.axes.Axes`. The artists carry ``gid`` s (listed per function) so
that tests and reports can find them. Empty or degenerate inputs (no exceedances, a finite GPD
endpoint below SI = 1, a zero probability on a log axis) give a figure with a note, never a
warning or an exception.

References
----------
.. [1] Veerman, H., et al., "GIMAT: a GNSS integrity monitoring and analysis tool based on
   extreme value theory", sections 3.2 (V_K), 3.3 (figures 2 and 3) and 3.5 (KRS, P_MI).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.transforms import blended_transform_factory

from overbound.report.figures import envelope
from overbound.report.style import log_scale, new_figure, style
from overbound.stats.dependence import Clusters, VKCurve
from overbound.stats.evt import GPDFit
from overbound.stats.threshold import ShapeStability

__all__ = [
    "REQUIREMENTS",
    "plot_acf",
    "plot_clusters",
    "plot_krs",
    "plot_mean_excess",
    "plot_p_mi_vs_threshold",
    "plot_shape_stability",
    "plot_tail_fit",
    "plot_vk",
]

#: Integrity requirements drawn on the tail figure (probability of misleading information).
REQUIREMENTS: tuple[float, ...] = (1e-7, 2e-7)
#: Smallest probability any log axis of this module goes down to.
_P_FLOOR = 1e-16
_DATA_COLOUR = "#1f5fa8"
_MODEL_COLOUR = "#d9711c"
_MARK_COLOUR = "#c0201a"
_REF_COLOUR = "#555555"
_REQ_COLOURS = ("#7a1f9e", "#1b7a3a", "#8c564b")


def _new_axes(ax: Axes | None, width: float = 5.0, height: float = 3.2) -> Axes:
    if ax is not None:
        return ax
    fig = new_figure(width, height)
    return fig.add_axes((0.15, 0.17, 0.80, 0.72))


def _note(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", gid="note")


def _finite(x: float | None) -> bool:
    return x is not None and math.isfinite(x)


def _positive(values: Sequence[float] | np.ndarray) -> np.ndarray:
    a = np.asarray(values, dtype=float).ravel()
    return a[np.isfinite(a) & (a > 0)]


def _log_limits(values: Sequence[float] | np.ndarray) -> tuple[float, float]:
    """Limits of a log axis covering the positive finite ``values`` (a decade of margin below)."""
    p = _positive(values)
    if p.size == 0:
        return 1e-9, 1.0
    lo = max(float(p.min()) / 10.0, _P_FLOOR)
    hi = float(p.max()) * 3.0
    if float(p.max()) <= 1.0:
        hi = min(hi, 1.0)
    return lo, max(hi, lo * 100.0)


# ---------------------------------------------------------------------------
# dependence (section 3.2)


def plot_acf(lags_s: np.ndarray, acf: np.ndarray, *, decorrelation_s: float, ax: Axes | None = None) -> Axes:
    """Autocorrelation of the safety index with the 1/e line and the decorrelation time.

    Parameters
    ----------
    lags_s : lags (s).
    acf : autocorrelation at each lag (:func:`~overbound.stats.dependence.autocorrelation`); NaN
        where undefined.
    decorrelation_s : decorrelation time (s) (:func:`~overbound.stats.dependence.decorrelation_time`);
        not drawn when NaN or infinite (then said in the legend).
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists with ``gid`` ``acf``, ``one-over-e`` (at :math:`1/e`), ``zero`` and
        ``decorrelation`` (a vertical line, only when finite); ``note`` when nothing to draw.

    Notes
    -----
    Veerman et al., section 3.2: the autocorrelation handles the dependence of the core. The
    1/e line is that of the default rule of
    :func:`~overbound.stats.dependence.decorrelation_time`.
    """
    lag = np.asarray(lags_s, dtype=float)
    rho = np.asarray(acf, dtype=float)
    with style():
        ax = _new_axes(ax)
        if lag.size == 0 or not np.any(np.isfinite(rho)):
            _note(ax, "autocorrelation undefined")
        else:
            ax.plot(lag, rho, color=_DATA_COLOUR, lw=0.9, gid="acf", label="autocorrelation")
        ax.axhline(0.0, color=_REF_COLOUR, lw=0.6, gid="zero")
        ax.axhline(math.exp(-1.0), color=_MODEL_COLOUR, lw=0.9, ls="--", gid="one-over-e", label="1/e")
        if _finite(decorrelation_s):
            ax.axvline(
                decorrelation_s,
                color=_MARK_COLOUR,
                lw=0.9,
                ls=":",
                gid="decorrelation",
                label=f"decorrelation time {decorrelation_s:g} s",
            )
        else:
            ax.plot([], [], " ", label=f"decorrelation time {decorrelation_s:g} s")
        ax.set_ylim(min(-0.2, float(np.min(_finite_values(rho), initial=0.0)) - 0.05), 1.05)
        ax.set_xlabel("lag (s)")
        ax.set_ylabel("autocorrelation of SI")
        ax.set_title("Autocorrelation")
        ax.legend(loc="upper right")
    return ax


def plot_vk(curve: VKCurve, *, cluster_gap_s: float, fit_from: float = 0.5, ax: Axes | None = None) -> Axes:
    r"""V_K against K with the Poisson line and the fitted upper straight line; K_T marked.

    Parameters
    ----------
    curve : :func:`~overbound.stats.dependence.vk_curve` of the exceedance times.
    cluster_gap_s : the cluster gap K_T (s) (:func:`~overbound.stats.dependence.cluster_gap`);
        not drawn when NaN.
    fit_from : the straight line is fitted to ``K >= fit_from * max(K)``, as in
        :func:`~overbound.stats.dependence.cluster_gap` (same default), so the figure shows
        the line K_T was read against.
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists with ``gid`` ``vk`` (the curve), ``poisson`` (:math:`E\{V_K\}` for independent
        exceedances, ``VKCurve.poisson``), ``upper-fit`` (the least-squares line
        :math:`a + bK` over the upper part, extended to K = 0) and ``cluster-gap``; ``note``
        with fewer than two exceedances.

    Notes
    -----
    Veerman et al., section 3.2: for independent exceedances V_K is linear in K; the graph
    approaches a straight line above K_T. The upper line is not drawn (nor fitted) with
    fewer than three points in the upper part, as in ``cluster_gap``.
    """
    k, v = np.asarray(curve.k, dtype=float), np.asarray(curve.v, dtype=float)
    with style():
        ax = _new_axes(ax)
        if curve.n < 2:
            _note(ax, f"{curve.n} exceedance(s): no pairs")
        ax.plot(k, v, ".-", ms=2.5, color=_DATA_COLOUR, gid="vk", label=f"$V_K$ (N = {curve.n:,})")
        if curve.n >= 2 and curve.duration_s > 0:
            ax.plot(
                k,
                curve.poisson(k),
                color=_REF_COLOUR,
                lw=0.8,
                ls="--",
                gid="poisson",
                label="independent (Poisson)",
            )
        upper = k >= fit_from * k[-1] if k.size else np.zeros(0, dtype=bool)
        if curve.n >= 2 and np.count_nonzero(upper) >= 3:
            b, a = np.polyfit(k[upper], v[upper], 1)
            kk = np.array([0.0, float(k[-1])])
            ax.plot(
                kk,
                a + b * kk,
                color=_MODEL_COLOUR,
                lw=0.9,
                gid="upper-fit",
                label=f"upper line {a:.3g} + {b:.3g} K",
            )
        if _finite(cluster_gap_s):
            ax.axvline(
                cluster_gap_s,
                color=_MARK_COLOUR,
                lw=0.9,
                ls=":",
                gid="cluster-gap",
                label=f"$K_T$ = {cluster_gap_s:g} s",
            )
        ax.set_xlim(left=0)
        ax.set_ylim(bottom=0)
        ax.set_xlabel("K (s)")
        ax.set_ylabel("$V_K$ (pairs per exceedance)")
        ax.set_title("$V_K$ curve")
        ax.legend(loc="lower right")
    return ax


def plot_clusters(
    time_s: np.ndarray,
    si: np.ndarray,
    clusters: Clusters,
    *,
    threshold: float,
    ax: Axes | None = None,
) -> Axes:
    """The safety index around its exceedances, the threshold and each cluster's maximum.

    Parameters
    ----------
    time_s : epoch times (s), sorted.
    si : safety index per epoch (NaN without a solution).
    clusters : :func:`~overbound.stats.dependence.decluster_runs` of ``(time_s, si)``.
    threshold : the tail threshold drawn.
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists with ``gid`` ``si`` (the series' min/max envelope), ``threshold``,
        ``cluster-peaks`` (one marker per cluster at its maximum) and ``note`` when there is
        no exceedance or no epoch.

    Notes
    -----
    The window runs from the first cluster's start to the last cluster's end, widened on each
    side by the larger of the cluster gap and 5 % of that span (the whole series when there is
    no exceedance). The series in the window is drawn as the per-bin minimum and maximum of
    :func:`~overbound.report.figures.envelope` (about one bin per pixel column), so a year at
    1 Hz stays a few thousand points and no exceedance disappears; the peaks are drawn
    exactly. Time on the axis is in hours from the window's start.
    """
    t = np.asarray(time_s, dtype=float)
    x = np.asarray(si, dtype=float)
    with style():
        ax = _new_axes(ax, 8.0, 3.2)
        ax.set_xlabel("time (h)")
        if t.size == 0:
            _note(ax, "no epochs")
            t0 = 0.0
        else:
            if clusters.n_clusters:
                lo, hi = float(clusters.start.min()), float(clusters.end.max())
                pad = max(float(clusters.run_length), 0.05 * (hi - lo), 1.0)
                lo, hi = lo - pad, hi + pad
            else:
                lo, hi = float(t[0]), float(t[-1])
            t0 = max(lo, float(t[0]))
            win = (t >= lo) & (t <= hi)
            tw = np.rint(t[win] * 1e6).astype(np.int64)
            te, ye = envelope(tw, x[win])
            hours = (te.astype(np.int64) / 1e6 - t0) / 3600.0
            ax.plot(hours, ye, color=_DATA_COLOUR, lw=0.6, gid="si", label="SI (min/max per bin)")
            if clusters.n_clusters:
                ax.plot(
                    (clusters.peak_time - t0) / 3600.0,
                    clusters.peak_value,
                    "v",
                    ms=4,
                    color=_MARK_COLOUR,
                    gid="cluster-peaks",
                    label=f"cluster maxima ({clusters.n_clusters:,} of "
                    f"{clusters.n_exceedances:,} exceedances)",
                )
            else:
                _note(ax, f"no exceedance of {threshold:g}")
            ax.set_xlabel(f"time (h) from {t0:.0f} s")
        ax.axhline(
            threshold, color=_MODEL_COLOUR, lw=0.9, ls="--", gid="threshold", label=f"threshold {threshold:g}"
        )
        # head room above the data for the legend, so that no peak is hidden under it
        peak = float(np.max(_finite_values(x), initial=threshold)) if t.size else threshold
        ax.set_ylim(0.0, 1.35 * max(peak, threshold) if max(peak, threshold) > 0 else 1.0)
        ax.set_ylabel("SI")
        ax.set_title("Exceedances and clusters")
        ax.legend(loc="upper right")
    return ax


# ---------------------------------------------------------------------------
# threshold (section 3.3)


def _chosen_line(ax: Axes, chosen: float | None) -> None:
    if _finite(chosen):
        ax.axvline(
            chosen,
            color=_MARK_COLOUR,
            lw=0.9,
            ls=":",
            gid="chosen-threshold",
            label=f"chosen threshold {chosen:g}",
        )


def plot_mean_excess(
    thresholds: np.ndarray, mean_excess: np.ndarray, *, chosen: float | None, ax: Axes | None = None
) -> Axes:
    """Mean-excess plot (Veerman et al., section 3.3, figure 2) with the chosen threshold.

    Parameters
    ----------
    thresholds : candidate thresholds :math:`L_{Tail}`.
    mean_excess : :func:`~overbound.stats.threshold.mean_excess` at each (NaN above the maximum).
    chosen : the threshold retained; not drawn when ``None`` or NaN.
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists with ``gid`` ``mean-excess`` and ``chosen-threshold``; ``note`` when no value
        is finite.

    Notes
    -----
    For a GPD tail the mean excess is linear in the threshold,
    :math:`(\\beta + \\gamma L_{Tail})/(1-\\gamma)`; the threshold is read at the start of the
    linear part.
    """
    u = np.asarray(thresholds, dtype=float)
    me = np.asarray(mean_excess, dtype=float)
    with style():
        ax = _new_axes(ax)
        if not np.any(np.isfinite(me)):
            _note(ax, "no exceedance above any threshold")
        ax.plot(u, me, ".-", ms=2.5, color=_DATA_COLOUR, gid="mean-excess", label="mean excess")
        _chosen_line(ax, chosen)
        ax.set_xlabel("threshold $L_{Tail}$ (SI)")
        ax.set_ylabel("mean excess (SI)")
        ax.set_title("Mean excess")
        ax.legend(loc="upper right")
    return ax


def plot_shape_stability(stability: ShapeStability, *, chosen: float | None, ax: Axes | None = None) -> Axes:
    """GPD shape against the threshold with its confidence band (Veerman et al., section 3.3, figure 3).

    Parameters
    ----------
    stability : :func:`~overbound.stats.threshold.shape_stability`.
    chosen : the threshold retained; not drawn when ``None`` or NaN.
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists with ``gid`` ``xi`` (the estimates), ``xi-band`` (the profile-likelihood
        interval at ``stability.level``), ``xi-nonregular`` (:math:`\\xi = -1/2`, below which the
        MLE is not regular), ``xi-zero`` and ``chosen-threshold``; ``note`` when no shape was
        fitted.

    Notes
    -----
    Infinite ends of the interval (an upper end beyond 50, reported as ``inf`` by
    :meth:`~overbound.stats.evt.GPDFit.profile_ci`) are drawn at the top of the axes: the y
    range is that of the finite estimates and interval ends, widened to include -0.5 and 0.
    """
    u = np.asarray(stability.thresholds, dtype=float)
    xi = np.asarray(stability.xi, dtype=float)
    lo = np.asarray(stability.xi_lower, dtype=float)
    hi = np.asarray(stability.xi_upper, dtype=float)
    finite = np.concatenate([_finite_values(xi), _finite_values(lo), _finite_values(hi), [-0.5, 0.0]])
    ymin, ymax = float(finite.min()), float(finite.max())
    margin = 0.05 * (ymax - ymin) + 0.05
    ymin, ymax = ymin - margin, ymax + margin
    with style():
        ax = _new_axes(ax)
        if not np.any(np.isfinite(xi)):
            _note(ax, "too few exceedances for any shape")
        ax.fill_between(
            u,
            np.clip(lo, ymin, ymax),
            np.clip(hi, ymin, ymax),
            where=np.isfinite(lo) & ~np.isnan(hi),
            color=_DATA_COLOUR,
            alpha=0.2,
            lw=0,
            gid="xi-band",
            label=f"{100 * stability.level:g} % profile interval",
        )
        ax.plot(u, xi, ".-", ms=2.5, color=_DATA_COLOUR, gid="xi", label=r"$\hat\xi$")
        ax.axhline(0.0, color=_REF_COLOUR, lw=0.6, gid="xi-zero")
        ax.axhline(-0.5, color=_REF_COLOUR, lw=0.8, ls="--", gid="xi-nonregular", label=r"$\xi = -1/2$")
        _chosen_line(ax, chosen)
        ax.set_ylim(ymin, ymax)
        ax.set_xlabel("threshold $L_{Tail}$ (SI)")
        ax.set_ylabel(r"shape $\xi$")
        ax.set_title("Shape stability")
        ax.legend(loc="upper right")
    return ax


def _finite_values(a: np.ndarray) -> np.ndarray:
    return a[np.isfinite(a)]


def _zero_markers(ax: Axes, x: np.ndarray, gid: str, label: str) -> None:
    """Markers at the bottom edge of a log axis for probabilities that are exactly zero."""
    if x.size:
        trans = blended_transform_factory(ax.transData, ax.transAxes)
        ax.plot(
            x,
            np.full(x.size, 0.02),
            "v",
            ms=4,
            color=_MARK_COLOUR,
            transform=trans,
            gid=gid,
            label=label,
            clip_on=False,
        )


def plot_p_mi_vs_threshold(
    thresholds: np.ndarray,
    p_mi: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    chosen: float | None,
    ax: Axes | None = None,
) -> Axes:
    """P_MI against the threshold with its interval, on a log axis (Veerman et al., section 3.3).

    Parameters
    ----------
    thresholds : candidate thresholds.
    p_mi, lower, upper : P_MI and its interval per threshold (NaN where not fitted).
    chosen : the threshold retained; not drawn when ``None`` or NaN.
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists with ``gid`` ``p-mi``, ``p-mi-band``, ``p-mi-zero`` (markers at the bottom edge
        where P_MI = 0, i.e. a GPD endpoint below SI = 1) and ``chosen-threshold``; ``note``
        when no probability is positive.

    Notes
    -----
    Zero is not on a log axis: zeros are masked in the line and the band (a lower end of 0
    draws the band down to the bottom of the axes) and shown as markers on the bottom edge.
    The y range covers the positive values only, so no log-of-zero warning can arise.
    """
    u = np.asarray(thresholds, dtype=float)
    p = np.asarray(p_mi, dtype=float)
    lo = np.asarray(lower, dtype=float)
    hi = np.asarray(upper, dtype=float)
    ymin, ymax = _log_limits(np.concatenate([p, lo, hi]))
    with style():
        ax = _new_axes(ax)
        log_scale(ax)
        ax.set_ylim(ymin, ymax)
        if _positive(np.concatenate([p, hi])).size == 0:
            _note(ax, "no positive P_MI")
        band = np.isfinite(hi) & (hi > 0) & np.isfinite(lo)
        ax.fill_between(
            u,
            np.where(lo > 0, np.maximum(lo, ymin), ymin),
            np.where(hi > 0, hi, ymin),
            where=band,
            color=_DATA_COLOUR,
            alpha=0.2,
            lw=0,
            gid="p-mi-band",
            label="confidence interval",
        )
        ax.plot(u, np.where(p > 0, p, np.nan), ".-", ms=2.5, color=_DATA_COLOUR, gid="p-mi", label="$P_{MI}$")
        _zero_markers(ax, u[p == 0], "p-mi-zero", "$P_{MI}$ = 0 (endpoint below SI = 1)")
        _chosen_line(ax, chosen)
        ax.set_xlabel("threshold $L_{Tail}$ (SI)")
        ax.set_ylabel("$P_{MI}$ per epoch")
        ax.set_title("$P_{MI}$ against threshold")
        ax.legend(loc="upper right")
    return ax


# ---------------------------------------------------------------------------
# fit and overbounding (section 3.5)


def _model_grid(fit: GPDFit, top: float) -> np.ndarray:
    """SI values for the model curve: linear to ``top``, refined towards a finite endpoint."""
    x = np.linspace(fit.threshold, top, 400)
    end = fit.endpoint
    if math.isfinite(end) and end < top:
        gap = end - fit.threshold
        near = end - gap * np.geomspace(1.0, 1e-6, 200)
        x = np.unique(np.concatenate([x[x < end], near, [end]]))
    return x


def plot_tail_fit(
    excess_values: np.ndarray,
    *,
    fit: GPDFit | None,
    n_total: int,
    exceedance_rate: float,
    p_mi: float,
    p_mi_ci: tuple[float, float],
    requirements: Sequence[float] = REQUIREMENTS,
    ax: Axes | None = None,
) -> Axes:
    r"""Exceedance probability of the safety index with the fitted GPD extrapolated to SI = 1.

    Parameters
    ----------
    excess_values : the safety-index values the GPD was fitted to (above the threshold, e.g.
        the cluster maxima); values, not excesses.
    fit : the GPD (:func:`~overbound.stats.evt.fit_gpd`); ``None`` when there was nothing to fit.
    n_total : epochs of the series (draws the level :math:`1/N` of one epoch).
    exceedance_rate : :math:`\hat\zeta_u`, the probability per epoch of exceeding the threshold.
    p_mi : :math:`P_{MI} = \hat\zeta_u \bar G(1 - u)` per epoch (0 is a valid value).
    p_mi_ci : its interval ``(lower, upper)``.
    requirements : integrity requirements drawn as horizontal lines (default 1e-7 and 2e-7).
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists with ``gid`` ``empirical``, ``gpd`` (the model), ``endpoint`` (when the GPD has
        a finite endpoint within the plot), ``si-one``, ``p-mi`` (the point) with ``p-mi-interval`` (its bar)
        or ``p-mi-zero`` (a marker on the bottom edge when P_MI = 0),
        ``one-epoch`` and ``requirement-<value>``; ``note`` without exceedances or fit.

    Notes
    -----
    Both curves are unconditional probabilities per epoch, :math:`P(SI > x)`:

    * empirical: the :math:`i`-th largest of the :math:`n` values at
      :math:`\hat\zeta_u\, i/(n+1)` (Weibull plotting positions, so the largest value is not
      put at zero);
    * model: :math:`\hat\zeta_u \bar G_{\hat\xi,\hat\sigma}(x - u)`
      (Veerman et al., section 3.5), from the threshold to
      :math:`\max(1.2, 1.1 \max x)`, so SI = 1 is always inside. A finite endpoint
      :math:`u - \hat\sigma/\hat\xi` is marked and the curve is sampled densely towards it
      (it falls to 0 there, below the axes).

    P_MI = 0 (endpoint below SI = 1) is a valid answer: it is drawn as a marker on the bottom
    edge with the label saying so. The y range covers the positive values shown (data, P_MI
    and its interval, :math:`1/N`, the requirements), a decade below the smallest.
    """
    x = np.sort(np.asarray(excess_values, dtype=float).ravel())[::-1]
    x = x[np.isfinite(x)]
    n = x.size
    zeta = float(exceedance_rate)
    lo_ci, hi_ci = (float(p_mi_ci[0]), float(p_mi_ci[1]))
    emp = zeta * np.arange(1, n + 1) / (n + 1) if n else np.zeros(0)
    top = max(1.2, 1.1 * float(x[0])) if n else 1.2
    usable = fit is not None and math.isfinite(fit.xi) and math.isfinite(fit.sigma) and fit.sigma > 0
    model_x = _model_grid(fit, top) if usable and fit is not None else np.zeros(0)
    model_p = zeta * fit.sf(model_x) if usable and fit is not None else np.zeros(0)
    one_epoch = 1.0 / n_total if n_total > 0 else float("nan")
    shown = np.concatenate(
        [emp, [p_mi, lo_ci, hi_ci, one_epoch, zeta], np.asarray(requirements, dtype=float)]
    )
    ymin, ymax = _log_limits(shown)
    with style():
        ax = _new_axes(ax, 5.4, 3.6)
        log_scale(ax)
        ax.set_ylim(ymin, ymax)
        if n == 0 or not usable:
            _note(ax, "no exceedances: no tail fit" if n == 0 else "no usable GPD fit")
        if n:
            ax.plot(x, emp, ".", ms=3, color=_DATA_COLOUR, gid="empirical", label=f"empirical ({n:,} values)")
        if usable and fit is not None:
            with np.errstate(divide="ignore"):
                shown_p = np.where(model_p > 0, model_p, np.nan)
            ax.plot(
                model_x,
                shown_p,
                color=_MODEL_COLOUR,
                lw=1.0,
                gid="gpd",
                label=rf"GPD $\xi$ = {fit.xi:.3g}, $\sigma$ = {fit.sigma:.3g}, u = {fit.threshold:g}",
            )
            if math.isfinite(fit.endpoint) and fit.endpoint <= top:
                ax.axvline(
                    fit.endpoint,
                    color=_MODEL_COLOUR,
                    lw=0.8,
                    ls=":",
                    gid="endpoint",
                    label=f"GPD endpoint {fit.endpoint:.3g}",
                )
        ax.axvline(1.0, color=_REF_COLOUR, lw=0.8, ls="--", gid="si-one")
        if p_mi > 0 and math.isfinite(p_mi):
            below = p_mi - max(lo_ci, ymin) if math.isfinite(lo_ci) else 0.0
            above = hi_ci - p_mi if math.isfinite(hi_ci) else 0.0
            bar = ax.errorbar(
                [1.0],
                [p_mi],
                yerr=[[max(below, 0.0)], [max(above, 0.0)]],
                fmt="o",
                ms=4,
                color=_MARK_COLOUR,
                capsize=3,
                label=f"$P_{{MI}}$ = {p_mi:.2g} [{lo_ci:.2g}, {hi_ci:.2g}]",
            )
            bar.lines[0].set_gid("p-mi")
            for part in bar.lines[2]:
                part.set_gid("p-mi-interval")
        elif p_mi == 0:
            _zero_markers(
                ax, np.array([1.0]), "p-mi-zero", f"$P_{{MI}}$ = 0 (endpoint below SI = 1), upper {hi_ci:.2g}"
            )
        if math.isfinite(one_epoch):
            ax.axhline(
                one_epoch,
                color=_REF_COLOUR,
                lw=0.6,
                ls="-.",
                gid="one-epoch",
                label=f"one epoch in {n_total:,}",
            )
        for value, colour in zip(requirements, _REQ_COLOURS * len(requirements), strict=False):
            ax.axhline(
                value,
                color=colour,
                lw=0.8,
                ls="--",
                gid=f"requirement-{value:g}",
                label=f"requirement {value:g}",
            )
        ax.set_xlim(min(float(x[-1]) if n else 1.0, fit.threshold if usable and fit else 1.0) - 0.02, top)
        ax.set_xlabel("safety index SI")
        ax.set_ylabel("P(SI > x) per epoch")
        ax.set_title("Tail fit and $P_{MI}$")
        ax.legend(loc="upper right", fontsize=6.5)
    return ax


def plot_krs(levels: np.ndarray, t_values: np.ndarray, *, critical: float, ax: Axes | None = None) -> Axes:
    r"""KRS statistic :math:`T_N(L)` against the normalised error L with the critical value.

    Parameters
    ----------
    levels, t_values : ``KRSResult.levels`` and ``KRSResult.t_values``
        (:func:`~overbound.stats.krs.krs_test`).
    critical : :math:`z_\alpha`; overbounding is accepted when :math:`\min_L T_N(L) \ge z_\alpha`.
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists with ``gid`` ``t-values``, ``critical``, ``minimum`` (a marker at the
        smallest finite :math:`T_N`) and ``note`` when no value is finite.

    Notes
    -----
    Veerman et al., section 3.5:
    :math:`T_N(L) = \sqrt N (2\bar\Phi(L) - \hat F(L)) / \sqrt{\hat F(L)(1-\hat F(L))}`.
    """
    lv = np.asarray(levels, dtype=float)
    tv = np.asarray(t_values, dtype=float)
    ok = np.isfinite(lv) & np.isfinite(tv)
    with style():
        ax = _new_axes(ax)
        if not np.any(ok):
            _note(ax, "no KRS statistic")
        else:
            ax.plot(lv[ok], tv[ok], color=_DATA_COLOUR, lw=0.9, gid="t-values", label="$T_N(L)$")
            i = int(np.argmin(np.where(ok, tv, np.inf)))
            ax.plot(
                [lv[i]],
                [tv[i]],
                "o",
                ms=4,
                color=_MARK_COLOUR,
                gid="minimum",
                label=f"$T_{{KRS}}$ = {tv[i]:.3g} at L = {lv[i]:.3g}",
            )
        ax.axhline(
            critical,
            color=_MODEL_COLOUR,
            lw=0.9,
            ls="--",
            gid="critical",
            label=rf"$z_\alpha$ = {critical:.3g}",
        )
        ax.set_xlabel("normalised error L")
        ax.set_ylabel("$T_N(L)$")
        ax.set_title("KRS overbounding test")
        ax.legend(loc="upper right")
    return ax
