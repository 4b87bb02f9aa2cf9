"""Figures of the report: Stanford diagram, PE/PL time series, safety-index histogram.

Every figure is a function that takes results (or the epoch table) and an optional
``ax``, draws inside :func:`matplotlib.rc_context` with :data:`STYLE` (global rcParams are
never touched) and returns the :class:`~matplotlib.axes.Axes`. Without ``ax`` a new
:class:`matplotlib.figure.Figure` is made directly, not through :mod:`matplotlib.pyplot`,
so no pyplot state is kept and nothing needs a display (PNG output uses Agg).

Columns needed by the table functions: ``time``, ``hpe``, ``vpe``, ``hpl``, ``vpl``.

References
----------
.. [1] Tossaint, M., Samson, J., Toran, F., Ventura-Traveset, J., Sanz, J., Hernandez-Pajares, M.,
   Juan, J. M. (2006), "The Stanford-ESA integrity diagram: focusing on SBAS integrity", ION GNSS 2006.
.. [2] Kannemans, H. (2006), "Integrity, availability and continuity of EGNOS", NLR-TP-2006-594,
   figures 1, 3, 9 and 17 (time series of PE and PL, PE/PL, Stanford plots per service).
"""

from __future__ import annotations

import matplotlib
import numpy as np
import polars as pl
from matplotlib.axes import Axes
from matplotlib.colors import LogNorm
from matplotlib.dates import AutoDateLocator, ConciseDateFormatter
from matplotlib.patches import Polygon
from matplotlib.ticker import FuncFormatter, NullLocator

from overbound.methods.counting import Region, StanfordCounts, StanfordHistogram
from overbound.numbers import format_share
from overbound.report.style import STYLE, close_figure, count_label, figure_png, new_figure, style

__all__ = [
    "AXIS_LABELS",
    "REGION_COLOURS",
    "REGION_LABELS",
    "STYLE",
    "close_figure",
    "envelope",
    "figure_png",
    "new_figure",
    "plot_safety_index",
    "plot_stanford",
    "plot_timeseries",
    "style",
]

#: Axis labels ``(PE, PL)`` per axis.
AXIS_LABELS = {"horizontal": ("HPE (m)", "HPL (m)"), "vertical": ("|VPE| (m)", "VPL (m)")}
#: Region names as the Stanford diagram labels them.
REGION_LABELS = {
    Region.NORMAL: "Normal operation",
    Region.MI: "MI",
    Region.HMI: "HMI",
    Region.UNAVAILABLE: "System unavailable",
    Region.UNAVAILABLE_MI: "Unavailable & MI",
}
#: Light shading of the regions, after the classic Stanford plot.
REGION_COLOURS = {
    Region.NORMAL: "#f1f8ee",
    Region.MI: "#fff1b8",
    Region.HMI: "#f9c5c0",
    Region.UNAVAILABLE: "#e4e4e4",
    Region.UNAVAILABLE_MI: "#fbdcb5",
}
_PE_COLOUR = "#1f5fa8"
_PL_COLOUR = "#d9711c"
_AL_COLOUR = "#c0201a"
_ENVELOPE_BINS = 2000
_SI_BINS = 200


# ---------------------------------------------------------------------------
# Stanford diagram


def _region_polygons(al: float, top: float) -> dict[Region, list[tuple[float, float]]]:
    """Corners of each region on ``[0, top]^2`` (x = PE, y = PL)."""
    a = min(al, top)
    return {
        Region.NORMAL: [(0, 0), (0, a), (a, a)],
        Region.MI: [(0, 0), (a, 0), (a, a)],
        Region.HMI: [(a, 0), (top, 0), (top, a), (a, a)],
        Region.UNAVAILABLE: [(0, a), (a, a), (top, top), (0, top)],
        Region.UNAVAILABLE_MI: [(a, a), (top, a), (top, top)],
    }


def _label_candidates(al: float, top: float) -> dict[Region, list[tuple[float, float]]]:
    """Places for each region's label, inside the region, in order of preference."""
    mid, upper = (al + top) / 2, al + 0.75 * (top - al)
    return {
        Region.NORMAL: [(0.30 * al, 0.74 * al), (0.50 * al, 0.88 * al), (0.28 * al, 0.50 * al)],
        Region.MI: [(0.68 * al, 0.20 * al), (0.80 * al, 0.50 * al)],
        Region.HMI: [(mid, 0.50 * al), (mid, 0.18 * al), (mid, 0.82 * al)],
        Region.UNAVAILABLE: [(0.36 * al, mid), (0.66 * al, upper), (0.36 * al, upper)],
        Region.UNAVAILABLE_MI: [((al + 2 * top) / 3, (2 * al + top) / 3)],
    }


def _label_positions(hist: StanfordHistogram, al: float) -> dict[Region, tuple[float, float]]:
    """For each region, the candidate place whose label box covers the fewest epochs.

    The box is taken as 30 % by 9 % of the plotted range; the first candidate wins ties,
    so the layout is the classic one unless data would be hidden under a label.
    """
    edges = hist.edges
    top = float(edges[-1])
    half_w, half_h = 0.15 * top, 0.045 * top
    # summed-area table: epochs in any block of bins in O(1)
    sat = np.zeros((hist.counts.shape[0] + 1, hist.counts.shape[1] + 1), dtype=np.int64)
    sat[1:, 1:] = hist.counts.cumsum(0).cumsum(1)

    def covered(x: float, y: float) -> int:
        i0, i1 = np.searchsorted(edges, [x - half_w, x + half_w]).clip(0, len(edges) - 1)
        j0, j1 = np.searchsorted(edges, [y - half_h, y + half_h]).clip(0, len(edges) - 1)
        return int(sat[i1, j1] - sat[i0, j1] - sat[i1, j0] + sat[i0, j0])

    return {
        region: min(places, key=lambda p: covered(*p))
        for region, places in _label_candidates(al, top).items()
    }


def plot_stanford(
    hist: StanfordHistogram,
    counts: StanfordCounts,
    *,
    alert_limit: float,
    service: str = "",
    ax: Axes | None = None,
    unit: str = "epochs",
) -> Axes:
    """Stanford(-ESA) integrity diagram: 2-D histogram of (PE, PL) with the regions counted.

    Parameters
    ----------
    hist : the (PE, PL) histogram of one axis (:func:`~overbound.methods.counting.stanford_histogram`).
    counts : epochs per region for ``alert_limit`` (:func:`~overbound.methods.counting.stanford_counts`).
    alert_limit : the service's alert limit on this axis (m).
    service : service name for the title.
    ax : axes to draw on; a new figure (with a colour bar axes) when ``None``.
    unit : what the histogram counts, for the labels: ``"epochs"``, or ``"subsets"`` for the
        all-subsets histogram of :func:`overbound.sbas.subsets.all_subsets`.

    Returns
    -------
    Axes
        The diagram. Artists carry ``gid`` s for inspection: ``alert-limit-pe``,
        ``alert-limit-pl``, ``diagonal``, ``region-<key>`` (the region labels) and
        ``stanford-note``.

    Notes
    -----
    The layout of [1]_: x = position error, y = protection level, both linear from 0
    to ``hist.edges[-1]`` with a square aspect; the bin counts on a logarithmic colour
    scale (empty bins are not coloured); the diagonal PE = PL; the alert limit on both
    axes. The regions and their tie rules are those of
    :class:`~overbound.methods.counting.Region`; each is labelled with its epoch count
    and its share of *all* epochs (including those without a solution). Epochs beyond
    the plotted range are drawn in the border bins; how many is stated under the axes.

    References
    ----------
    .. [1] Tossaint et al. (2006), "The Stanford-ESA integrity diagram", ION GNSS 2006, figure 1.
    """
    top = float(hist.edges[-1])
    pe_label, pl_label = AXIS_LABELS.get(hist.axis, ("PE (m)", "PL (m)"))
    with style():
        if ax is None:
            fig = new_figure(5.0, 4.6)
            ax = fig.add_axes((0.12, 0.17, 0.66, 0.72))
            cax = fig.add_axes((0.82, 0.17, 0.03, 0.72))
        else:
            fig, cax = ax.figure, None
        for region, corners in _region_polygons(alert_limit, top).items():
            ax.add_patch(
                Polygon(corners, closed=True, facecolor=REGION_COLOURS[region], edgecolor="none", zorder=0.1)
            )
        data = np.ma.masked_less(hist.counts.T.astype(float), 1.0)
        cmap = matplotlib.colormaps["turbo"].with_extremes(bad=(1, 1, 1, 0))
        vmax = max(float(hist.counts.max(initial=0)), 10.0)
        image = ax.imshow(
            data,
            origin="lower",
            extent=(0, top, 0, top),
            cmap=cmap,
            norm=LogNorm(vmin=1.0, vmax=vmax),
            interpolation="nearest",
            aspect="equal",
            zorder=2,
        )
        ax.plot([0, top], [0, top], color="black", lw=0.9, zorder=3, gid="diagonal")
        ax.axvline(alert_limit, color="black", lw=0.9, ls="--", zorder=3, gid="alert-limit-pe")
        ax.axhline(alert_limit, color="black", lw=0.9, ls="--", zorder=3, gid="alert-limit-pl")
        ax.set_xlim(0, top)
        ax.set_ylim(0, top)
        ax.set_aspect("equal")
        ax.set_xlabel(pe_label)
        ax.set_ylabel(pl_label)
        ax.set_title(f"{service} {hist.axis}".strip())
        total = counts.total
        positions = _label_positions(hist, alert_limit)
        for region, label in REGION_LABELS.items():
            n = getattr(counts, region.key)
            x, y = positions[region]
            ax.text(
                x,
                y,
                f"{label}\n{n:,} ({format_share(n, total)})",
                ha="center",
                va="center",
                fontsize=7,
                zorder=4,
                gid=f"region-{region.key}",
                color="#b00000" if region is Region.HMI and n else "black",
                bbox={
                    "boxstyle": "round,pad=0.25",
                    "facecolor": "white",
                    "edgecolor": "#999999",
                    "lw": 0.4,
                    "alpha": 0.8,
                },
            )
        ax.annotate(
            f"{total:,} {unit}, AL {alert_limit:g} m: {counts.no_solution:,} without solution (not drawn),\n"
            f"{hist.clipped:,} beyond {top:g} m (drawn on the border)",
            xy=(0.5, 0.0),
            xycoords="axes fraction",
            xytext=(0, -30),
            textcoords="offset points",
            ha="center",
            va="top",
            fontsize=6.5,
            color="#444444",
            gid="stanford-note",
        )
        bar = fig.colorbar(image, cax=cax) if cax is not None else fig.colorbar(image, ax=ax)
        bar.set_label(f"{unit} per bin")
        bar.ax.minorticks_off()
        bar.ax.yaxis.set_major_formatter(FuncFormatter(count_label))
        bar.ax.tick_params(labelsize=7)
    return ax


# ---------------------------------------------------------------------------
# time series


def _time_us(table: pl.DataFrame) -> np.ndarray:
    return table["time"].dt.epoch("us").to_numpy()


def _pe_pl(table: pl.DataFrame, axis: str) -> tuple[np.ndarray, np.ndarray]:
    if axis == "horizontal":
        return table["hpe"].to_numpy(), table["hpl"].to_numpy()
    if axis == "vertical":
        return np.abs(table["vpe"].to_numpy()), table["vpl"].to_numpy()
    raise ValueError(f"axis must be 'horizontal' or 'vertical', got {axis!r}")


def envelope(
    time_us: np.ndarray, values: np.ndarray, *, bins: int = _ENVELOPE_BINS
) -> tuple[np.ndarray, np.ndarray]:
    """Per-time-bin minimum and maximum of ``values``, as one polyline for plotting.

    Parameters
    ----------
    time_us : epoch times (GPS microseconds); any order (several stations may be pooled).
    values : one value per epoch; NaN (no solution) is ignored.
    bins : number of time bins over the span (about one per pixel column).

    Returns
    -------
    (t, y)
        ``t`` in ``datetime64[us]`` and ``y`` with each occupied bin giving two points
        (its minimum then its maximum) at the bin centre, and a NaN break where the data
        have a gap of at least two sampling intervals, so a line through them draws
        the pixels the raw series would, with at most two points per bin plus the breaks.

    Notes
    -----
    Steps, all vectorised:

    1. The sampling interval Δ is the median positive spacing of the first 100 001 epochs;
       the bin width is ``span / bins``, or Δ when that is wider, so that short series
       keep one bin per epoch and are drawn as they are.
    2. Each epoch gets its bin index; epochs are sorted by bin only when they are not
       already in order (several stations).
    3. ``np.fmin.reduceat`` / ``np.fmax.reduceat`` give each bin's extremes, ignoring NaN.
    4. A NaN is put between two occupied bins that have at least 2Δ without epochs between them.

    Examples
    --------
    Ten epochs at 1 Hz in five bins of 1.8 s: each bin holds two epochs.

    >>> t = np.arange(10) * 1_000_000
    >>> x, y = envelope(t, np.arange(10.0), bins=5)
    >>> y.tolist()
    [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
    >>> str(x[0]), str(x[-1])
    ('1970-01-01T00:00:00.900000', '1970-01-01T00:00:08.100000')
    """
    t = np.asarray(time_us, dtype=np.int64)
    v = np.asarray(values, dtype=float)
    if t.size == 0:
        return np.array([], dtype="datetime64[us]"), np.array([], dtype=float)
    t0 = int(t.min())
    span = int(t.max()) - t0
    head = np.diff(t[:100_001])
    step = float(np.median(head[head > 0])) if np.any(head > 0) else 1.0
    coarse = span / bins >= step
    width = span / bins if coarse else max(step, 1.0)
    b = ((t - t0) / width).astype(np.int64)
    if coarse:  # the last epoch, at t0 + span, belongs to the last bin
        b = np.minimum(b, bins - 1)
    if b.size > 1 and np.any(b[1:] < b[:-1]):
        order = np.argsort(b, kind="stable")
        b, v = b[order], v[order]
    starts = np.flatnonzero(np.concatenate(([True], b[1:] != b[:-1])))
    lo = np.fmin.reduceat(v, starts)
    hi = np.fmax.reduceat(v, starts)
    occupied = b[starts]
    centre = t0 + (occupied + 0.5) * width
    # break the line where at least two sampling intervals hold no epoch
    gap = (np.diff(occupied) - 1) * width >= 2 * step
    xs = np.repeat(centre, 2)
    ys = np.column_stack((lo, hi)).ravel()
    if np.any(gap):
        at = 2 * (np.flatnonzero(gap) + 1)
        xs = np.insert(xs, at, centre[np.flatnonzero(gap)] + width)
        ys = np.insert(ys, at, np.nan)
    return xs.astype(np.int64).astype("datetime64[us]"), ys


def plot_timeseries(
    table: pl.DataFrame, *, axis: str, alert_limit: float | None = None, ax: Axes | None = None
) -> Axes:
    """Position error and protection level against GPS time, with the alert limit.

    Parameters
    ----------
    table : the epoch table (``time``, ``hpe``/``hpl`` or ``vpe``/``vpl``).
    axis : ``horizontal`` (HPE, HPL) or ``vertical`` (|VPE|, VPL).
    alert_limit : drawn as a horizontal line when given (m).
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        Lines with ``gid`` ``pe``, ``pl`` and ``alert-limit``.

    Notes
    -----
    As Kannemans (2006) figures 1 and 17. Long series are drawn as the per-bin
    minimum/maximum :func:`envelope` (about one bin per pixel column), which looks the
    same as the raw series and keeps a year at 1 Hz to a few thousand points.
    """
    pe, pl_ = _pe_pl(table, axis)
    t = _time_us(table)
    pe_label, pl_label = (s.removesuffix(" (m)") for s in AXIS_LABELS[axis])
    with style():
        if ax is None:
            fig = new_figure(10.0, 3.2)
            ax = fig.add_axes((0.07, 0.17, 0.91, 0.72))
        if t.size == 0:
            ax.text(0.5, 0.5, "no epochs", transform=ax.transAxes, ha="center", va="center")
        else:
            tp, yp = envelope(t, pl_)
            te, ye = envelope(t, pe)
            ax.plot(tp, yp, color=_PL_COLOUR, lw=0.7, label=pl_label, gid="pl")
            ax.plot(te, ye, color=_PE_COLOUR, lw=0.7, label=pe_label, gid="pe")
            locator = AutoDateLocator()
            ax.xaxis.set_major_locator(locator)
            ax.xaxis.set_major_formatter(ConciseDateFormatter(locator))
        if alert_limit is not None:
            ax.axhline(
                alert_limit,
                color=_AL_COLOUR,
                lw=1.0,
                ls="--",
                label=f"AL {alert_limit:g} m",
                gid="alert-limit",
            )
        ax.set_ylim(bottom=0)
        ax.set_xlabel("GPS time")
        ax.set_ylabel(f"{pe_label}, {pl_label} (m)")
        ax.set_title(f"{pe_label} and {pl_label}")
        if t.size:
            ax.legend(loc="upper right", ncols=3)
    return ax


def plot_safety_index(table: pl.DataFrame, *, axis: str, ax: Axes | None = None) -> Axes:
    """Histogram of the safety index PE/PL (log count) with SI = 1 marked.

    Parameters
    ----------
    table : the epoch table (``hpe``/``hpl`` or ``vpe``/``vpl``).
    axis : ``horizontal`` (HPE/HPL) or ``vertical`` (|VPE|/VPL).
    ax : axes to draw on; a new figure when ``None``.

    Returns
    -------
    Axes
        The histogram (a ``stairs`` artist with ``gid`` ``si-histogram``) and the line
        ``si-one`` at 1.

    Notes
    -----
    Over epochs with a solution and PL > 0, as
    :func:`~overbound.methods.counting.safety_index`. The bins are linear from 0 to
    ``max(1.2, 1.05 * max SI)``; epochs with SI > 1 are misleading information.
    Kannemans (2006) figures 3 and 19 show the same ratio as a time series.
    """
    pe, pl_ = _pe_pl(table, axis)
    ok = np.isfinite(pe) & np.isfinite(pl_) & (pl_ > 0)
    si = pe[ok] / pl_[ok]
    ratio = "HPE/HPL" if axis == "horizontal" else "|VPE|/VPL"
    with style():
        if ax is None:
            fig = new_figure(5.0, 3.2)
            ax = fig.add_axes((0.15, 0.17, 0.81, 0.72))
        top = max(1.2, 1.05 * float(si.max())) if si.size else 1.2
        width = top / _SI_BINS
        counts = np.bincount(np.minimum((si / width).astype(np.int64), _SI_BINS - 1), minlength=_SI_BINS)
        edges = np.linspace(0.0, top, _SI_BINS + 1)
        ax.stairs(counts, edges, fill=True, color=_PE_COLOUR, alpha=0.85, gid="si-histogram")
        n_mi = int(np.count_nonzero(si > 1.0))
        ax.axvline(
            1.0,
            color=_AL_COLOUR,
            lw=1.0,
            ls="--",
            gid="si-one",
            label=f"SI = 1: {n_mi:,} of {si.size:,} epochs above",
        )
        # explicit limits before the log scale: no autoscaling over empty (zero) bins
        ax.set_ylim(0.7, 2.0 * max(int(counts.max(initial=0)), 5))
        ax.set_yscale("log")
        ax.yaxis.set_minor_locator(NullLocator())
        ax.yaxis.set_major_formatter(FuncFormatter(count_label))
        ax.set_xlim(0, top)
        if si.size == 0:
            ax.text(0.5, 0.5, "no epoch with a solution", transform=ax.transAxes, ha="center", va="center")
        ax.set_xlabel(f"safety index {ratio}")
        ax.set_ylabel("epochs per bin")
        ax.set_title(f"Safety index {ratio}")
        ax.legend(loc="upper right")
    return ax
