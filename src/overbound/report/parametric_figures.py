r"""Figures of the parametric analysis, after Kannemans (2006), NLR-TP-2006-594, section 2.

Time series (figures 1, 3, 17, 19): the ratio PE/PL against time (:func:`plot_ratio_timeseries`;
PE with PL is :func:`overbound.report.figures.plot_timeseries`). Fits: the normal (vertical) or
Rayleigh (horizontal) probability plot of the ratio with the fitted line (:func:`plot_ratio_probability`,
figure 4), the Weibull probability plot of the PL (:func:`plot_weibull_probability`, figure 6), the
autocorrelation of the ratio and of the PL with each decorrelation time (:func:`plot_acf_pair`,
figures 5 and 8), the PL histogram with the Weibull density and its band (:func:`plot_pl_histogram`,
figures 7 and 20). Integrity (figures 11 and 22): the joint density of (|PE|, PL) as contours relative
to its maximum with the Stanford lines and the probability of each region (:func:`plot_pe_pl_contours`).
Continuity (figures 12-16 and 23): the counted non-continuity against the alert limit with the
log-linear fits and their bounds (:func:`plot_noncontinuity`).

Every figure is a function of arrays and of the results of :mod:`overbound.stats.parametric` and
:mod:`overbound.stats.continuity`, with an optional ``ax``; it draws inside
:func:`~overbound.report.figures.style` on a :func:`~overbound.report.figures.new_figure` when no
``ax`` is given (never through pyplot) and returns the :class:`~matplotlib.axes.Axes`. Artists carry
``gid`` s (listed per function). Long series are thinned (min/max envelopes, thinned order
statistics, histograms), so months of 1 Hz data stay a few thousand points per figure.

Probabilities in the figures are written by :func:`format_probability`, from their
:math:`\log_{10}` when they are below :math:`10^{-300}` (``1.2e-412``), never as 0.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from matplotlib.axes import Axes
from matplotlib.dates import AutoDateLocator, ConciseDateFormatter
from matplotlib.ticker import FixedFormatter, FixedLocator, NullLocator
from matplotlib.transforms import blended_transform_factory
from scipy import special

from overbound.numbers import TINY, format_probability, mantissa_exponent
from overbound.report.figures import envelope
from overbound.report.style import log_scale, new_figure, style
from overbound.stats.continuity import ContinuityCurve, LogLinearFit
from overbound.stats.parametric import (
    RatioFit,
    WeibullFit,
    pe_pl_density,
    ratio_plot_positions,
    weibull_pdf,
    weibull_pdf_band,
    weibull_plot_positions,
)

__all__ = [
    "CONTOUR_LEVELS",
    "TINY",
    "LocalFit",
    "RegionLabels",
    "format_probability",
    "mantissa_exponent",
    "mark_alert_limits",
    "plot_acf_pair",
    "plot_noncontinuity",
    "plot_pe_pl_contours",
    "plot_pl_histogram",
    "plot_ratio_probability",
    "plot_ratio_timeseries",
    "plot_weibull_probability",
]

#: Contour levels of :func:`plot_pe_pl_contours`, relative to the maximum density (Kannemans, figure 11).
CONTOUR_LEVELS: tuple[float, ...] = (1e-10, 1e-5, 1e-3, 0.01, 0.1, 0.5, 1.0)
_DATA_COLOUR = "#1f5fa8"
_MODEL_COLOUR = "#d9711c"
_MARK_COLOUR = "#c0201a"
_REF_COLOUR = "#555555"
_BOUND_COLOUR = "#7a1f9e"
_SERVICE_COLOURS = ("#1b7a3a", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f")
_RATIO = {"vertical": "VPE/VPL", "horizontal": "HPE/HPL"}
_PL = {"vertical": "VPL", "horizontal": "HPL"}
#: The ratio series whose ACF sets the MI bound (methods.parametric step 3: r^2 for the Rayleigh).
_ACF_RATIO = {"vertical": "VPE/VPL", "horizontal": "(HPE/HPL)²"}
_PE = {"vertical": "|VPE|", "horizontal": "HPE"}
#: Cumulative probabilities labelled on the probability-plot axes.
_PROB_TICKS = (1e-4, 1e-3, 0.01, 0.05, 0.2, 0.5, 0.8, 0.95, 0.99, 0.999, 0.9999, 0.99999, 0.999999)
_CONTOUR_POINTS = 301
_HIST_BINS = 120


# ---------------------------------------------------------------------------
# probabilities as text


# ---------------------------------------------------------------------------
# helpers


def _new_axes(ax: Axes | None, width: float = 5.0, height: float = 3.4, left: float = 0.14) -> Axes:
    if ax is not None:
        return ax
    fig = new_figure(width, height)
    return fig.add_axes((left, 0.16, 0.96 - left, 0.73))


def _note(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", gid="note")


def _finite(x: float | None) -> bool:
    return x is not None and math.isfinite(x)


def mark_alert_limits(
    ax: Axes, alert_limits: Mapping[str, float], *, vertical: bool, lo: float, hi: float
) -> None:
    """One dotted line (``gid`` ``alert-limit-<AL>``) per distinct alert limit in ``[lo, hi]``, labelled
    with its services; vertical lines (an x axis of PL) or horizontal ones."""
    groups: dict[float, list[str]] = {}
    for name, al in alert_limits.items():
        groups.setdefault(float(al), []).append(name)
    for i, (al, names) in enumerate(sorted(groups.items())):
        if not lo <= al <= hi:
            continue
        colour = _SERVICE_COLOURS[i % len(_SERVICE_COLOURS)]
        label = f"AL {al:g} m ({', '.join(names)})"
        line = ax.axvline if vertical else ax.axhline
        line(al, color=colour, lw=0.9, ls=":", gid=f"alert-limit-{al:g}", label=label)


# ---------------------------------------------------------------------------
# time series (figures 3 and 19)


def plot_ratio_timeseries(
    time_us: np.ndarray, ratio: np.ndarray, *, axis: str, ax: Axes | None = None
) -> Axes:
    """The ratio PE/PL against GPS time as its min/max envelope (Kannemans 2006, figures 3 and 19).

    Parameters
    ----------
    time_us : epoch times (GPS microseconds); several stations may overlap.
    ratio : VPE/VPL with the signed VPE (vertical) or HPE/HPL (horizontal) per epoch.
    axis : ``vertical`` or ``horizontal`` (labels).
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists with ``gid`` ``ratio`` (the per-bin minimum and maximum of
        :func:`~overbound.report.figures.envelope`, about one bin per pixel column) and ``zero``;
        ``note`` without epochs. MI is :math:`|r| > 1`, usually far above the plotted range, so the
        lines :math:`\\pm 1` are drawn only when the data come within a factor of two of them.
    """
    t = np.asarray(time_us, dtype=np.int64)
    r = np.asarray(ratio, dtype=float)
    name = _RATIO.get(axis, "PE/PL")
    with style():
        ax = _new_axes(ax, 10.0, 3.0)
        if t.size == 0:
            _note(ax, "no epochs")
        else:
            te, ye = envelope(t, r)
            ax.plot(te, ye, color=_DATA_COLOUR, lw=0.6, gid="ratio", label=f"{name} (min/max per bin)")
            locator = AutoDateLocator()
            ax.xaxis.set_major_locator(locator)
            ax.xaxis.set_major_formatter(ConciseDateFormatter(locator))
            top = float(np.nanmax(np.abs(r))) if np.any(np.isfinite(r)) else 0.0
            if top >= 0.5:
                for y in (1.0, -1.0) if axis == "vertical" else (1.0,):
                    ax.axhline(y, color=_MARK_COLOUR, lw=0.9, ls="--", gid=f"mi-{y:+g}")
        ax.axhline(0.0, color=_REF_COLOUR, lw=0.6, gid="zero")
        ax.set_xlabel("GPS time")
        ax.set_ylabel(name)
        ax.set_title(f"Ratio {name}")
        if t.size:
            ax.legend(loc="upper right")
    return ax


# ---------------------------------------------------------------------------
# probability plots (figures 4 and 6)


def _probability_axis(ax: Axes, transform, *, x: bool = False) -> None:
    """Label a quantile axis with the cumulative probabilities it stands for (``transform``: F -> q)."""
    lo, hi = ax.get_xlim() if x else ax.get_ylim()
    ticks: list[tuple[float, float]] = []
    for p in _PROB_TICKS:  # in order; a tick too close to the previous one is left out
        q = float(transform(p))
        if lo <= q <= hi and (not ticks or q - ticks[-1][0] >= 0.06 * (hi - lo)):
            ticks.append((q, p))
    target = ax.xaxis if x else ax.yaxis
    target.set_major_locator(FixedLocator([q for q, _ in ticks]))
    target.set_major_formatter(FixedFormatter([f"{p:g}" for _, p in ticks]))
    target.set_minor_locator(NullLocator())


def plot_ratio_probability(
    ratio: np.ndarray,
    fit: RatioFit,
    *,
    axis: str,
    bound: RatioFit | None = None,
    p_mi: tuple[float, float] | None = None,
    ax: Axes | None = None,
) -> Axes:
    r"""Normal (vertical) or Rayleigh (horizontal) probability plot of the ratio (Kannemans 2006, figure 4).

    Parameters
    ----------
    ratio : the ratios fitted (signed VPE/VPL; HPE/HPL).
    fit : their :class:`~overbound.stats.parametric.RatioFit`; its distribution sets the plot.
    axis : ``vertical`` or ``horizontal`` (labels).
    bound : the bound fit (drawn dashed) when there is one.
    p_mi : ``(P_MI, log10 P_MI)`` of the fit, for the legend.
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        x = the sorted ratios, y = the standard quantile of their median rank (Bernard), labelled
        with the cumulative probability: :math:`\Phi^{-1}(F)` (normal) or :math:`\sqrt{-2\ln(1-F)}`
        (Rayleigh); data of the fitted law lie on the straight line :math:`r = m + \sigma q`
        (:math:`r = \sigma q`). Artists ``ratio-data`` (thinned by
        :func:`~overbound.stats.parametric.ratio_plot_positions`), ``ratio-fit``, ``ratio-bound``.
    """
    r, q = ratio_plot_positions(fit, np.asarray(ratio, dtype=float))
    normal = fit.distribution == "normal"
    name = _RATIO.get(axis, "PE/PL")
    law = "normal" if normal else "Rayleigh"
    with style():
        ax = _new_axes(ax, left=0.18)
        ax.plot(r, q, ".", ms=2.0, color=_DATA_COLOUR, gid="ratio-data", label=f"{name} ({fit.n:,} epochs)")
        qq = np.linspace(float(q.min()), float(q.max()), 50)
        mi = f", P_MI {format_probability(*p_mi)}" if p_mi is not None else ""
        if normal:
            label = f"normal m = {fit.mean:.3g}, σ = {fit.sigma:.3g}{mi}"
        else:
            label = f"Rayleigh σ = {fit.sigma:.3g}{mi}"
        ax.plot(
            fit.mean * normal + fit.sigma * qq, qq, color=_MODEL_COLOUR, lw=1.0, gid="ratio-fit", label=label
        )
        if bound is not None:
            ax.plot(
                bound.mean * normal + bound.sigma * qq,
                qq,
                color=_BOUND_COLOUR,
                lw=0.9,
                ls="--",
                gid="ratio-bound",
                label=f"bound σ = {bound.sigma:.3g}" + (f", m = {bound.mean:.3g}" if normal else ""),
            )
        ax.set_ylim(float(q.min()) - 0.2, float(q.max()) + 0.2)
        if normal:
            _probability_axis(ax, special.ndtri)
        else:
            _probability_axis(ax, lambda p: math.sqrt(-2.0 * math.log1p(-p)))
        ax.set_xlabel(name)
        ax.set_ylabel("cumulative probability")
        ax.set_title(f"{law.capitalize()} probability plot of {name}")
        ax.legend(loc="lower right")
    return ax


def plot_weibull_probability(
    pl: np.ndarray,
    fit: WeibullFit,
    *,
    axis: str,
    alert_limits: Mapping[str, float] | None = None,
    ax: Axes | None = None,
) -> Axes:
    r"""Weibull probability plot of the protection level (Kannemans 2006, figure 6).

    Parameters
    ----------
    pl : the PLs fitted (> 0).
    fit : their :class:`~overbound.stats.parametric.WeibullFit`.
    axis : ``vertical`` or ``horizontal`` (labels).
    alert_limits : service name -> alert limit, drawn as vertical lines when in range.
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        x = PL on a log axis, y = :math:`\ln(-\ln(1-F))` of the median ranks labelled with
        :math:`F`; a Weibull sample lies on :math:`\ln a + b \ln x`. Artists ``pl-data`` (thinned by
        :func:`~overbound.stats.parametric.weibull_plot_positions`), ``weibull-fit`` and
        ``alert-limit-<AL>``.
    """
    lx, y = weibull_plot_positions(np.asarray(pl, dtype=float))
    name = _PL.get(axis, "PL")
    with style():
        ax = _new_axes(ax, left=0.18)
        log_scale(ax, "x")
        ax.plot(
            np.exp(lx), y, ".", ms=2.0, color=_DATA_COLOUR, gid="pl-data", label=f"{name} ({fit.n:,} epochs)"
        )
        xs = np.geomspace(float(np.exp(lx.min())), float(np.exp(lx.max())) * 1.5, 60)
        ax.plot(
            xs,
            math.log(fit.a) + fit.b * np.log(xs),
            color=_MODEL_COLOUR,
            lw=1.0,
            gid="weibull-fit",
            label=f"Weibull a = {fit.a:.3g}, b = {fit.b:.3g}",
        )
        ax.set_ylim(float(y.min()) - 0.3, float(y.max()) + 0.6)
        ax.set_xlim(float(xs[0]) / 1.1, float(xs[-1]))
        mark_alert_limits(ax, alert_limits or {}, vertical=True, lo=float(xs[0]), hi=float(xs[-1]))
        _probability_axis(ax, lambda p: math.log(-math.log1p(-p)))
        ax.set_xlabel(f"{name} (m)")
        ax.set_ylabel("cumulative probability")
        ax.set_title(f"Weibull probability plot of {name}")
        ax.legend(loc="lower right", fontsize=6.5)
    return ax


# ---------------------------------------------------------------------------
# autocorrelation (figures 5 and 8)


def plot_acf_pair(
    lags_s: np.ndarray,
    ratio_acf: np.ndarray,
    pl_acf: np.ndarray,
    *,
    axis: str,
    ratio_decorrelation_s: float,
    pl_decorrelation_s: float,
    ax: Axes | None = None,
) -> Axes:
    """Autocorrelation of the ratio and of the PL with each decorrelation time (Kannemans 2006, figures 5, 8).

    Parameters
    ----------
    lags_s : lags (s).
    ratio_acf, pl_acf : the autocorrelations at those lags (NaN where undefined).
    axis : ``vertical`` or ``horizontal`` (labels).
    ratio_decorrelation_s, pl_decorrelation_s : the decorrelation times (s) used for the bounds
        (read where the ACF falls below 1/e, or given); a vertical line each when finite.
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists ``ratio-acf``, ``pl-acf``, ``one-over-e``, ``zero``, ``ratio-decorrelation`` and
        ``pl-decorrelation``; ``note`` when no value is finite. Lags in hours beyond 2 h.
    """
    lag = np.asarray(lags_s, dtype=float)
    hours = lag.size > 0 and float(lag.max()) > 7200.0
    unit, k = ("h", 3600.0) if hours else ("s", 1.0)
    rname, pname = _ACF_RATIO.get(axis, "PE/PL"), _PL.get(axis, "PL")
    with style():
        ax = _new_axes(ax)
        values = []
        for acf, gid, label, colour in (
            (ratio_acf, "ratio-acf", rname, _DATA_COLOUR),
            (pl_acf, "pl-acf", pname, _MODEL_COLOUR),
        ):
            rho = np.asarray(acf, dtype=float)
            values.append(rho[np.isfinite(rho)])
            ax.plot(lag / k, rho, color=colour, lw=0.9, gid=gid, label=f"ACF of {label}")
        if not any(v.size for v in values):
            _note(ax, "autocorrelation undefined")
        ax.axhline(0.0, color=_REF_COLOUR, lw=0.6, gid="zero")
        ax.axhline(math.exp(-1.0), color=_REF_COLOUR, lw=0.8, ls="--", gid="one-over-e", label="1/e")
        for tau, gid, label, colour in (
            (ratio_decorrelation_s, "ratio-decorrelation", rname, _DATA_COLOUR),
            (pl_decorrelation_s, "pl-decorrelation", pname, _MODEL_COLOUR),
        ):
            text = f"τ {label} = {tau:g} s"
            if _finite(tau):
                ax.axvline(tau / k, color=colour, lw=0.9, ls=":", gid=gid, label=text)
            else:
                ax.plot([], [], " ", label=f"{text} (not reached)")
        low = min((float(v.min()) for v in values if v.size), default=0.0)
        ax.set_ylim(min(-0.2, low - 0.05), 1.05)
        taus = [t for t in (ratio_decorrelation_s, pl_decorrelation_s) if _finite(t)]
        if lag.size and len(taus) == 2:  # zoom on the decay: ten times the longer time
            ax.set_xlim(0, min(float(lag.max()), max(10.0 * max(taus), 60.0)) / k)
        else:
            ax.set_xlim(left=0)
        ax.set_xlabel(f"lag ({unit})")
        ax.set_ylabel("autocorrelation")
        ax.set_title("Autocorrelation and decorrelation times")
        ax.legend(loc="upper right")
    return ax


# ---------------------------------------------------------------------------
# PL histogram (figures 7 and 20)


def plot_pl_histogram(
    pl: np.ndarray,
    fit: WeibullFit,
    *,
    axis: str,
    cov: np.ndarray | None = None,
    confidence: float = 0.95,
    alert_limits: Mapping[str, float] | None = None,
    ax: Axes | None = None,
) -> Axes:
    r"""Histogram of the PL (density) with the Weibull density and its band (Kannemans 2006, figure 7).

    Parameters
    ----------
    pl : the PLs fitted.
    fit : their Weibull fit.
    axis : ``vertical`` or ``horizontal`` (labels).
    cov : covariance of :math:`(\ln a, b)` from the decorrelated sample; the pointwise two-sided
        band at ``confidence`` (:func:`~overbound.stats.parametric.weibull_pdf_band`) is drawn when given.
    confidence : level of the band.
    alert_limits : service name -> alert limit, drawn when inside the plotted range.
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Artists ``pl-histogram`` (120 bins from 0 to the largest PL, density), ``weibull-pdf``,
        ``weibull-band`` (when ``cov``) and ``alert-limit-<AL>``.
    """
    x = np.asarray(pl, dtype=float)
    name = _PL.get(axis, "PL")
    top = float(x.max()) * 1.02 if x.size else 1.0
    with style():
        ax = _new_axes(ax)
        counts, edges = np.histogram(x, bins=_HIST_BINS, range=(0.0, top))
        dens = counts / (max(x.size, 1) * np.diff(edges))
        ax.stairs(
            dens,
            edges,
            fill=True,
            color=_DATA_COLOUR,
            alpha=0.45,
            gid="pl-histogram",
            label=f"{name} ({x.size:,} epochs)",
        )
        xs = np.linspace(top / 2000.0, top, 600)
        if cov is not None:
            lo, hi = weibull_pdf_band(fit, cov, xs, confidence)
            ax.fill_between(
                xs,
                lo,
                hi,
                color=_MODEL_COLOUR,
                alpha=0.3,
                lw=0,
                gid="weibull-band",
                label=f"{100 * confidence:g} % band (decorrelated sample)",
            )
        ax.plot(
            xs,
            weibull_pdf(fit, xs),
            color=_MODEL_COLOUR,
            lw=1.0,
            gid="weibull-pdf",
            label=f"Weibull a = {fit.a:.3g}, b = {fit.b:.3g}",
        )
        mark_alert_limits(ax, alert_limits or {}, vertical=True, lo=0.0, hi=top)
        ax.set_xlim(0.0, top)
        ax.set_ylim(bottom=0.0)
        ax.set_xlabel(f"{name} (m)")
        ax.set_ylabel("probability density (1/m)")
        ax.set_title(f"Histogram of {name} and Weibull fit")
        ax.legend(loc="upper right", fontsize=6.5)
    return ax


# ---------------------------------------------------------------------------
# contours (figures 11 and 22)


@dataclass(frozen=True, slots=True)
class RegionLabels:
    """The probabilities written in the regions of :func:`plot_pe_pl_contours`, as text.

    Each is ``"nominal [bound]"`` (e.g. from :func:`format_probability`); the Stanford regions of the
    (|PE|, PL) plane at the alert limit: ``unavailability`` (PL >= AL), ``mi_pl_above_al``
    (PL >= AL, |PE| > PL), ``mi_pl_below_al`` (PL < AL, PL < |PE| <= AL), ``hmi`` (PL < AL,
    |PE| > AL).
    """

    unavailability: str
    mi_pl_above_al: str
    mi_pl_below_al: str
    hmi: str


def _contour_grid(ratio: RatioFit, weibull: WeibullFit, top: float) -> tuple[np.ndarray, np.ndarray]:
    """PE and PL grids on [0, top]: even, plus as many points where the density is (PL and ratio tails)."""
    ln_tail = math.log(1e12)
    pl_hi = (ln_tail / weibull.a) ** (1.0 / weibull.b) * 1.2  # S(pl_hi) < 1e-12
    t_hi = abs(ratio.mean) * (ratio.distribution == "normal") + ratio.sigma * math.sqrt(2.0 * ln_tail + 4.0)
    pl_grid = np.union1d(
        np.linspace(0.0, top, _CONTOUR_POINTS), np.linspace(0.0, min(top, pl_hi), _CONTOUR_POINTS)
    )
    pe_hi = min(top, t_hi * min(top, pl_hi))
    pe_grid = np.union1d(np.linspace(0.0, top, _CONTOUR_POINTS), np.linspace(0.0, pe_hi, _CONTOUR_POINTS))
    return pe_grid, pl_grid


def plot_pe_pl_contours(
    ratio: RatioFit,
    weibull: WeibullFit,
    *,
    alert_limit: float,
    axis: str,
    labels: RegionLabels,
    title: str = "",
    ax: Axes | None = None,
) -> Axes:
    r"""Joint density of (|PE|, PL) as contours with the Stanford lines and region probabilities.

    Kannemans 2006, figures 11 and 22: the density :math:`p_{PL}(x)\,p_r(y/x)/x`
    (:func:`~overbound.stats.parametric.pe_pl_density`; PL Weibull, the ratio normal folded to
    :math:`|VPE|` or Rayleigh, independent) drawn as contours at :data:`CONTOUR_LEVELS` of its
    maximum (the level 1 is the maximum itself, marked by a point), with the lines PE = PL,
    PL = AL and PE = AL, and the probability of each region written in it with its bound in
    brackets.

    Parameters
    ----------
    ratio, weibull : the fits.
    alert_limit : AL (m).
    axis : ``vertical`` or ``horizontal`` (labels).
    labels : the texts of the regions (:class:`RegionLabels`).
    title : title (e.g. the services with this AL).
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        x = |PE|, y = PL (the Stanford diagram's layout), both from 0 to 1.5 AL rounded up to 10 m.
        Artists ``contours`` (``QuadContourSet`` lines carry it), ``max``, ``diagonal``,
        ``alert-limit-pe``, ``alert-limit-pl``, ``region-unavailability``, ``region-mi-above``,
        ``region-mi-below``, ``region-hmi``.

    Notes
    -----
    The density is evaluated on a grid that is even over the plot and refined (301 more points per
    axis) over the part of the plane where it is above about :math:`10^{-12}` of the PL and ratio
    tails, so that the narrow wedge of a small ratio sigma is resolved even when AL is large
    (NPA). Contours are drawn on :math:`\log_{10}` of the relative density.
    """
    al = float(alert_limit)
    top = max(10.0, math.ceil(1.5 * al / 10.0) * 10.0)
    pe_grid, pl_grid = _contour_grid(ratio, weibull, top)
    with np.errstate(divide="ignore"):
        dens = pe_pl_density(ratio, weibull, pl_grid[:, None], pe_grid[None, :])
        peak = float(dens.max())
        rel = np.log10(dens / peak) if peak > 0 else np.full(dens.shape, -np.inf)
    rel = np.where(np.isfinite(rel), rel, -400.0)
    levels = [math.log10(v) for v in CONTOUR_LEVELS if v < 1.0]
    pe_name, pl_name = _PE.get(axis, "|PE|"), _PL.get(axis, "PL")
    with style():
        if ax is None:
            fig = new_figure(6.6, 4.8)
            ax = fig.add_axes((0.09, 0.11, 0.62, 0.80))
        if peak > 0:
            cs = ax.contour(pe_grid, pl_grid, rel, levels=levels, cmap="viridis", linewidths=0.8, zorder=2)
            cs.set_gid("contours")
            for art, lv in zip(cs.legend_elements()[0], levels, strict=True):
                ax.plot([], [], color=art.get_color(), lw=0.8, label=f"{10**lv:g} of the maximum")
            i, j = np.unravel_index(int(np.argmax(dens)), dens.shape)
            ax.plot(
                [pe_grid[j]],
                [pl_grid[i]],
                "+",
                ms=7,
                color="black",
                gid="max",
                zorder=3,
                label="maximum density (1)",
            )
        else:
            _note(ax, "density underflows")
        ax.plot([0, top], [0, top], color="black", lw=0.9, gid="diagonal", label=f"{pe_name} = {pl_name}")
        ax.axhline(al, color=_MARK_COLOUR, lw=0.9, ls="--", gid="alert-limit-pl")
        ax.axvline(al, color=_MARK_COLOUR, lw=0.9, ls="--", gid="alert-limit-pe", label=f"AL {al:g} m")
        box = {
            "boxstyle": "round,pad=0.25",
            "facecolor": "white",
            "edgecolor": "#999999",
            "lw": 0.4,
            "alpha": 0.85,
        }
        mid = (al + top) / 2.0
        y_unav = al + 0.6 * (top - al)
        for x, y, key, text in (
            (
                0.75 * y_unav,
                y_unav,
                "region-unavailability",
                f"unavailability\n{labels.unavailability}",
            ),
            (
                (al + 2 * top) / 3.0 + 0.05 * (top - al),
                (2 * al + top) / 3.0 - 0.05 * (top - al),
                "region-mi-above",
                f"P_MI (PL ≥ AL)\n{labels.mi_pl_above_al}",
            ),
            (0.72 * al, 0.3 * al, "region-mi-below", f"P_MI (PL < AL)\n{labels.mi_pl_below_al}"),
            (mid, 0.5 * al, "region-hmi", f"P_HMI\n{labels.hmi}"),
        ):
            ax.text(x, y, text, ha="center", va="center", fontsize=6.5, zorder=4, gid=key, bbox=box)
        ax.set_xlim(0, top)
        ax.set_ylim(0, top)
        ax.set_aspect("equal")
        ax.set_xlabel(f"{pe_name} (m)")
        ax.set_ylabel(f"{pl_name} (m)")
        ax.set_title(title or f"{axis} AL {al:g} m")
        ax.legend(loc="upper left", bbox_to_anchor=(1.03, 1.0), fontsize=6.5, borderaxespad=0.0)
    return ax


# ---------------------------------------------------------------------------
# continuity (figures 12-16 and 23)


@dataclass(frozen=True, slots=True)
class LocalFit:
    """A service's local log-linear fits for :func:`plot_noncontinuity`.

    Attributes
    ----------
    name : service(s) (label).
    alert_limit : its AL (m).
    fit, fit_bound : the fits of the risk and of its bound (``None`` when not fitted).
    requirement : the continuity requirement per window (drawn as a horizontal line).
    """

    name: str
    alert_limit: float
    fit: LogLinearFit | None
    fit_bound: LogLinearFit | None
    requirement: float | None = None


def _line(ax: Axes, f: LogLinearFit, **kw) -> None:
    x = np.linspace(f.al_min, f.al_max, 50)
    ax.plot(x, f.risk(x), **kw)


def plot_noncontinuity(
    curve: ContinuityCurve,
    *,
    axis: str,
    fit: LogLinearFit | None,
    fit_bound: LogLinearFit | None,
    local: Sequence[LocalFit] = (),
    ax: Axes | None = None,
) -> Axes:
    r"""Non-continuity against the alert limit with the log-linear fits and bounds (Kannemans 2006, 2.1.4).

    Parameters
    ----------
    curve : the counted curve (:func:`~overbound.stats.continuity.noncontinuity_curve`, pooled).
    axis : ``vertical`` or ``horizontal`` (labels).
    fit, fit_bound : the fits :math:`\log_{10} P = a + b\,AL` of the risk and of its one-sided
        Clopper-Pearson bound over the whole range (figure 13).
    local : the local fits of the services (figures 14-16) with their ALs and requirements.
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Log y. Artists ``risk`` (the counted points), ``risk-bound`` (their bounds), ``risk-zero``
        (markers on the bottom edge where nothing failed), ``fit``, ``fit-bound``,
        ``local-fit-<AL>``, ``local-fit-bound-<AL>``, ``service-<AL>`` (the fit's value at AL),
        ``alert-limit-<AL>`` and ``requirement-<value>``.
    """
    al = np.asarray(curve.alert_limit, dtype=float)
    risk = np.asarray(curve.risk, dtype=float)
    bound = np.asarray(curve.risk_bound, dtype=float)
    pos = np.isfinite(risk) & (risk > 0)
    shown = [risk[pos], bound[np.isfinite(bound) & (bound > 0)]]
    shown += [np.array([s.requirement]) for s in local if _finite(s.requirement)]
    allv = np.concatenate(shown) if shown else np.zeros(0)
    allv = allv[allv > 0]
    lo = max(float(allv.min()) / 10.0, 1e-16) if allv.size else 1e-9
    hi = min(1.5, float(allv.max()) * 3.0) if allv.size else 1.0
    with style():
        if ax is None:
            fig = new_figure(8.0, 3.8)
            ax = fig.add_axes((0.09, 0.14, 0.56, 0.76))
        log_scale(ax)
        ax.set_ylim(lo, max(hi, lo * 100.0))
        if not np.any(pos):
            _note(ax, "no loss of continuity at any alert limit")
        ax.plot(
            al[pos],
            risk[pos],
            ".",
            ms=2.5,
            color=_DATA_COLOUR,
            gid="risk",
            label=f"counted ({curve.window_s:g} s windows)",
        )
        okb = np.isfinite(bound) & (bound > 0)
        ax.plot(
            al[okb],
            bound[okb],
            ".",
            ms=1.5,
            color=_BOUND_COLOUR,
            alpha=0.5,
            gid="risk-bound",
            label=f"one-sided {100 * curve.confidence:g} % bound",
        )
        zero = np.isfinite(risk) & (risk == 0)
        if np.any(zero):
            trans = blended_transform_factory(ax.transData, ax.transAxes)
            ax.plot(
                al[zero],
                np.full(int(zero.sum()), 0.02),
                "|",
                ms=4,
                color=_REF_COLOUR,
                transform=trans,
                gid="risk-zero",
                label="no loss counted",
                clip_on=False,
            )
        if fit is not None:
            _line(
                ax,
                fit,
                color=_MODEL_COLOUR,
                lw=1.1,
                gid="fit",
                label=f"fit log10 P = {fit.a:.3f} {'−' if fit.b < 0 else '+'} {abs(fit.b):.4f} AL",
            )
        if fit_bound is not None:
            _line(
                ax, fit_bound, color=_MODEL_COLOUR, lw=0.9, ls="--", gid="fit-bound", label="fit of the bound"
            )
        reqs: set[float] = set()
        for i, s in enumerate(local):
            colour = _SERVICE_COLOURS[i % len(_SERVICE_COLOURS)]
            tag = f"{s.alert_limit:g}"
            ax.axvline(s.alert_limit, color=colour, lw=0.8, ls=":", gid=f"alert-limit-{tag}")
            if s.fit is not None:
                _line(
                    ax,
                    s.fit,
                    color=colour,
                    lw=2.0,
                    alpha=0.8,
                    gid=f"local-fit-{tag}",
                    label=f"{s.name}: local fit at AL {tag} m",
                )
                ax.plot(
                    [s.alert_limit],
                    [float(s.fit.risk(s.alert_limit))],
                    "o",
                    ms=4,
                    color=colour,
                    gid=f"service-{tag}",
                )
            if s.fit_bound is not None:
                _line(ax, s.fit_bound, color=colour, lw=1.2, ls="--", gid=f"local-fit-bound-{tag}")
            if _finite(s.requirement) and s.requirement not in reqs:
                reqs.add(float(s.requirement))
                ax.axhline(
                    s.requirement,
                    color=_MARK_COLOUR,
                    lw=0.8,
                    ls="-.",
                    gid=f"requirement-{s.requirement:g}",
                    label=f"requirement {s.requirement:g} per {curve.window_s:g} s",
                )
        if al.size:
            ax.set_xlim(float(al.min()), float(al.max()))
        ax.set_xlabel(f"alert limit (m), {_PL.get(axis, 'PL')}")
        ax.set_ylabel(f"non-continuity per {curve.window_s:g} s")
        ax.set_title(f"Non-continuity against the alert limit ({curve.window_s:g} s)")
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=6.5, borderaxespad=0.0)
    return ax
