"""Counting KPIs: availability, continuity, accuracy, safety index and Stanford regions.

These are the plain counts every SBAS performance report starts from, computed per
service level and per axis (horizontal, vertical, combined) over the epoch table.
They make no distributional assumption; the statistical methods (PL confidence
level, tail extrapolation, parametric fits) build on them.

Columns needed: ``time``, ``station``, ``hpe``, ``vpe``, ``hpl``, ``vpl``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np
import polars as pl

from overbound.io.schema import as_numpy
from overbound.services import ServiceLevel
from overbound.stats.dependence import SlotGrid, slot_grid

__all__ = [
    "AXES",
    "SAFETY_PERCENTILES",
    "AxisKPI",
    "ContinuityResult",
    "CountingResult",
    "Region",
    "SafetyIndex",
    "ServiceKPI",
    "StanfordCounts",
    "StanfordHistogram",
    "continuity_risk",
    "continuity_risks",
    "count_kpis",
    "plot_max",
    "safety_index",
    "safety_values",
    "stanford_counts",
    "stanford_histogram",
    "stanford_regions",
]

AXES = ("horizontal", "vertical")
#: Percentiles of PE/PL reported by :func:`safety_index`.
SAFETY_PERCENTILES: tuple[float, ...] = (50.0, 95.0, 99.0, 99.9, 99.99, 99.999)


class Region(enum.IntEnum):
    """Disjoint Stanford-diagram regions of one epoch (per axis and alert limit).

    The boundaries follow the Stanford/ESA convention (Tossaint et al. 2006,
    "The Stanford-ESA integrity diagram", ION GNSS), with protection level PL,
    position error PE (absolute for the vertical) and alert limit AL:

    * ``PL >= AL``: ``UNAVAILABLE_MI`` when ``PE > PL``, else ``UNAVAILABLE``;
    * ``PL < AL``: ``HMI`` when ``PE > AL``, else ``MI`` when ``PE > PL``, else ``NORMAL``;
    * ``NO_SOLUTION`` when PE or PL is NaN.

    Ties: ``PE == PL`` is bounded (normal), ``PL == AL`` is unavailable,
    ``PE == AL`` is not hazardous.
    """

    NORMAL = 0
    MI = 1
    HMI = 2
    UNAVAILABLE = 3
    UNAVAILABLE_MI = 4
    NO_SOLUTION = 5

    @property
    def key(self) -> str:
        return self.name.lower()

    @classmethod
    def parse(cls, text: str) -> Region:
        """``Region.parse("hmi") is Region.HMI``; the inverse of :attr:`key`."""
        try:
            return cls[text.upper()]
        except KeyError:
            raise ValueError(
                f"unknown Stanford region {text!r}; known: {', '.join(r.key for r in cls)}"
            ) from None


@dataclass(frozen=True, slots=True)
class StanfordCounts:
    """Epoch counts per :class:`Region`."""

    normal: int
    mi: int
    hmi: int
    unavailable: int
    unavailable_mi: int
    no_solution: int

    @property
    def total(self) -> int:
        return self.normal + self.mi + self.hmi + self.unavailable + self.unavailable_mi + self.no_solution

    def to_dict(self) -> dict[str, int]:
        return {r.key: getattr(self, r.key) for r in Region}


@dataclass(frozen=True, slots=True)
class StanfordHistogram:
    """2-D histogram of (PE, PL) for a Stanford diagram.

    Attributes
    ----------
    axis : ``horizontal`` or ``vertical``.
    edges : common bin edges of PE and PL (m), from 0 to the plotted maximum.
    counts : ``counts[i, j]`` epochs with PE in bin ``i`` and PL in bin ``j``.
    clipped : epochs beyond the last edge on either axis; as the field draws it, they
        are counted in the last bin (on the border of the diagram).
    """

    axis: str
    edges: np.ndarray
    counts: np.ndarray
    clipped: int


@dataclass(frozen=True, slots=True)
class ContinuityResult:
    """Loss-of-continuity count over sliding windows (Kannemans 2006, section 2.1.4).

    Attributes
    ----------
    risk : ``n_fail / n_windows``, or ``None`` with ``reason`` when it cannot be counted.
    n_windows : windows that start on an available epoch and end inside the data.
    n_fail : of those, windows with at least one unavailable or missing epoch after the start.
    n_gap_windows : windows touched by at least one missing epoch (a gap) after the start.
    n_truncated : available start epochs whose window runs past the end of the data (not counted).
    window_s : exposure time (s).
    interval_s : nominal sampling interval found (s; see :func:`continuity_risk`).
    n_off_grid : epochs more than a quarter interval off the regular time grid (rounded onto it).
    reason : why ``risk`` is ``None`` (empty otherwise).
    """

    risk: float | None
    n_windows: int
    n_fail: int
    n_gap_windows: int
    n_truncated: int
    window_s: float
    interval_s: float | None
    n_off_grid: int = 0
    reason: str = ""


@dataclass(frozen=True, slots=True)
class SafetyIndex:
    """Safety index PE/PL over epochs with a solution and PL > 0."""

    n: int
    max: float | None
    time_of_max: str | None
    percentiles: dict[str, float | None]


@dataclass(frozen=True, slots=True)
class AxisKPI:
    """KPIs of one service on one axis (``horizontal``, ``vertical`` or ``combined``)."""

    axis: str
    alert_limit: float | None
    availability: float | None
    n_available: int
    continuity: ContinuityResult | None
    stanford: StanfordCounts | None


@dataclass(frozen=True, slots=True)
class ServiceKPI:
    """Counting KPIs of one service level."""

    service: ServiceLevel
    horizontal: AxisKPI
    vertical: AxisKPI
    combined: AxisKPI

    def axis(self, name: str) -> AxisKPI:
        return getattr(self, name)


@dataclass(frozen=True, slots=True)
class CountingResult:
    """Everything :func:`count_kpis` counted.

    Attributes
    ----------
    n_total : epochs in the table (with or without a solution).
    n_with_solution : epochs with finite HPE, VPE, HPL and VPL.
    stations : station names, in table order of first appearance.
    start, end : first and last epoch (ISO 8601, GPS time).
    hpe95, vpe95 : 95th percentiles of HPE and |VPE| over epochs with a solution (m).
    safety : :class:`SafetyIndex` per axis.
    services : :class:`ServiceKPI` per service name.
    histograms : :class:`StanfordHistogram` per ``(axis, plot maximum)``.
    by_station : the same counts for each station alone when the table holds several
        (without histograms); empty for a single station, where they equal the pooled ones.
    """

    n_total: int
    n_with_solution: int
    stations: tuple[str, ...]
    start: str | None
    end: str | None
    hpe95: float | None
    vpe95: float | None
    safety: dict[str, SafetyIndex]
    services: dict[str, ServiceKPI]
    histograms: dict[tuple[str, float], StanfordHistogram]
    by_station: dict[str, CountingResult] = field(default_factory=dict)

    def histogram(self, axis: str, alert_limit: float) -> StanfordHistogram:
        """The histogram drawn for ``axis`` and a service with ``alert_limit``."""
        return self.histograms[(axis, plot_max(alert_limit))]


# ---------------------------------------------------------------------------
# pure array functions


def stanford_regions(pe: np.ndarray, pl_: np.ndarray, alert_limit: float) -> np.ndarray:
    """Region code (:class:`Region`) of each epoch; ``pe`` is the absolute error.

    >>> stanford_regions(np.array([1.0, 5.0, 45.0, 5.0, 60.0, np.nan]),
    ...                  np.array([5.0, 4.0, 30.0, 40.0, 50.0, 10.0]), 40.0).tolist()
    [0, 1, 2, 3, 4, 5]
    """
    pe = np.asarray(pe, dtype=float)
    pl_ = np.asarray(pl_, dtype=float)
    out = np.full(pe.shape, Region.NORMAL, dtype=np.int8)
    above_pl = pe > pl_
    avail = pl_ < alert_limit
    out[avail & above_pl] = Region.MI
    out[avail & (pe > alert_limit)] = Region.HMI
    out[~avail] = Region.UNAVAILABLE
    out[~avail & above_pl] = Region.UNAVAILABLE_MI
    out[np.isnan(pe) | np.isnan(pl_)] = Region.NO_SOLUTION
    return out


def stanford_counts(pe: np.ndarray, pl_: np.ndarray, alert_limit: float) -> StanfordCounts:
    """Epoch counts per Stanford region (see :class:`Region` for the boundaries).

    Equal to ``np.bincount(stanford_regions(...))`` (tested), computed from boolean
    masks without the per-epoch code array.
    """
    pe, pl_ = np.asarray(pe, dtype=float), np.asarray(pl_, dtype=float)
    return _counts(pe, pl_, alert_limit, np.isnan(pe) | np.isnan(pl_), pe > pl_)


def _counts(
    pe: np.ndarray, pl_: np.ndarray, al: float, no_solution: np.ndarray, above: np.ndarray
) -> StanfordCounts:
    """Region counts given the AL-independent masks (shared by every service of an axis)."""
    avail = pl_ < al
    avail &= ~no_solution
    n_avail = int(np.count_nonzero(avail))
    n_mi_all = int(np.count_nonzero(avail & above))
    n_hmi = int(np.count_nonzero(avail & (pe > al)))  # PE > AL > PL: a subset of ``above``
    n_nosol = int(np.count_nonzero(no_solution))
    n_unavail = pe.size - n_avail - n_nosol
    n_unavail_mi = int(np.count_nonzero(above)) - n_mi_all  # NaN compares False: above excludes no-solution
    return StanfordCounts(
        normal=n_avail - n_mi_all,
        mi=n_mi_all - n_hmi,
        hmi=n_hmi,
        unavailable=n_unavail - n_unavail_mi,
        unavailable_mi=n_unavail_mi,
        no_solution=n_nosol,
    )


def plot_max(alert_limit: float) -> float:
    """Upper edge of the Stanford diagram's axes for an alert limit: 1.5 AL, rounded up to 10 m."""
    return float(np.ceil(1.5 * alert_limit / 10.0) * 10.0)


def stanford_histogram(
    pe: np.ndarray, pl_: np.ndarray, *, axis: str, max_value: float, bins: int = 200
) -> StanfordHistogram:
    """2-D (|PE|, PL) histogram on ``[0, max_value]`` with ``bins`` square bins.

    Epochs beyond ``max_value`` go to the last bin and are counted in ``clipped``;
    no-solution epochs are left out. One ``np.bincount`` over a flat index, no
    ``histogram2d``; no-solution epochs go to an extra row and column that is cut off.
    """
    pe = np.abs(np.asarray(pe, dtype=float))
    pl_ = np.asarray(pl_, dtype=float)
    nan = np.isnan(pe) | np.isnan(pl_)
    stride = bins + 1  # index ``bins`` is the discard row/column
    scale = bins / max_value
    tmp = np.empty(pe.shape, dtype=float)
    flat = _bin_index(pe, scale, bins, nan, tmp)
    flat *= stride
    flat += _bin_index(pl_, scale, bins, nan, tmp)
    counts = np.bincount(flat, minlength=stride * stride).reshape(stride, stride)[:bins, :bins]
    clipped = int(np.count_nonzero((pe >= max_value) | (pl_ >= max_value)))
    return StanfordHistogram(
        axis, np.linspace(0.0, max_value, bins + 1), np.ascontiguousarray(counts), clipped
    )


def _bin_index(x: np.ndarray, scale: float, bins: int, nan: np.ndarray, tmp: np.ndarray) -> np.ndarray:
    """floor(x * scale) clipped to the last bin; ``bins`` where ``nan``; in place in ``tmp``."""
    np.multiply(x, scale, out=tmp)
    np.minimum(tmp, bins - 1, out=tmp)
    np.putmask(tmp, nan, bins)
    return tmp.astype(np.intp)


def safety_index(pe: np.ndarray, pl_: np.ndarray, time_us: np.ndarray | None = None) -> SafetyIndex:
    """Maximum and percentiles of PE/PL over epochs with a solution and PL > 0.

    Percentiles use linear interpolation between order statistics (Hyndman & Fan
    type 7, numpy's default).
    """
    ok, si = safety_values(pe, pl_)
    keys = [f"p{p:g}" for p in SAFETY_PERCENTILES]
    if si.size == 0:
        return SafetyIndex(0, None, None, dict.fromkeys(keys))
    imax = int(np.argmax(si))
    si_max = float(si[imax])
    when = None if time_us is None else _iso(int(np.asarray(time_us)[_nth_true(ok, imax)]))
    q = np.percentile(si, SAFETY_PERCENTILES, overwrite_input=True)  # si is our own copy
    return SafetyIndex(int(si.size), si_max, when, {k: float(v) for k, v in zip(keys, q, strict=True)})


def safety_values(pe: np.ndarray, pl_: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The epochs with a solution and PL > 0 (a mask) and their safety index ``|PE|/PL`` (a new
    array), in table order."""
    ok = np.isfinite(pe) & np.isfinite(pl_) & (pl_ > 0)
    si = pe[ok]
    np.abs(si, out=si)
    si /= pl_[ok]
    return ok, si


def _nth_true(mask: np.ndarray, n: int, block: int = 1 << 20) -> int:
    """Index of the ``n``-th (0-based) True of ``mask``, by blocks: no index array of the whole mask.

    >>> _nth_true(np.array([False, True, False, True, True]), 1, block=2)
    3
    """
    starts = np.arange(0, mask.size, block)
    before = np.concatenate(([0], np.cumsum(np.add.reduceat(mask, starts, dtype=np.int64))))
    b = int(np.searchsorted(before, n, side="right")) - 1
    return int(starts[b] + np.flatnonzero(mask[starts[b] : starts[b] + block])[n - before[b]])


def _iso(us: int) -> str:
    return np.datetime64(us, "us").astype("datetime64[ms]").astype(str)


# ---------------------------------------------------------------------------
# continuity


def continuity_risk(time_us: np.ndarray, available: np.ndarray, *, window_s: float) -> ContinuityResult:
    """Loss-of-continuity share of sliding windows, counted in time (Kannemans 2006, 2.1.4).

    One station; ``time_us`` strictly increasing GPS microseconds; ``available`` per epoch.

    Notes
    -----
    Kannemans' count, with windows measured in time rather than rows:

    .. math::

        N_{success} = \\#\\{t : A(t) \\wedge A(s)\\ \\forall s \\in (t, t+T]\\},\\quad
        N_{fail} = \\#\\{t : A(t) \\wedge \\exists s \\in (t, t+T] : \\neg A(s)\\},\\quad
        P = N_{fail} / (N_{success} + N_{fail})

    with exposure ``T = window_s``. Steps:

    1. The nominal interval Δ is the mean of the epoch spacings within 25 % of the median
       spacing (gaps left out, jitter averaged); each epoch is put on the grid
       ``k = round((t - t_0)/Δ)``; epochs more than Δ/4 off it are counted in ``n_off_grid``.
    2. A window starts at every available epoch and holds the ``round(T/Δ)`` grid slots
       after it. A slot with no epoch (a gap) counts as loss of service, as does an
       unavailable epoch.
    3. Windows that would run past the last epoch are not counted (``n_truncated``).
    4. When Δ > T no window holds a sample, and ``risk`` is ``None`` with the reason.
    """
    return _continuity_on_grid(slot_grid(np.asarray(time_us, dtype=np.int64)), available, window_s)


def continuity_risks(
    time_us: np.ndarray, available: np.ndarray, *, window_s: float
) -> list[ContinuityResult]:
    """:func:`continuity_risk` of many series sampled at the same epochs (the points of a service-volume
    map): one row of ``available`` (series, epochs) per series, the grid placed once. Each result equals
    :func:`continuity_risk` of its row alone."""
    grid = slot_grid(np.asarray(time_us, dtype=np.int64))
    available = np.atleast_2d(np.asarray(available, dtype=bool))
    # blocks of rows: the prefix counts are (rows, slots) int32, 350 MB for 1000 points of a day at 1 Hz
    block = max(1, 2**26 // max(grid.size if grid else 1, 1))
    return [r for a in range(0, available.shape[0], block)
            for r in _continuity_rows(grid, available[a : a + block], window_s)]  # fmt: skip


def _continuity_on_grid(grid: SlotGrid | None, available: np.ndarray, window_s: float) -> ContinuityResult:
    return _continuity_rows(grid, np.asarray(available, dtype=bool)[None, :], window_s)[0]


def _continuity_rows(grid: SlotGrid | None, available: np.ndarray, window_s: float) -> list[ContinuityResult]:
    """The window counts of :func:`continuity_risk` for each row of ``available`` on one grid."""
    rows = available.shape[0]
    if grid is None:
        return [no_grid_continuity(None, 0, window_s)] * rows
    if none := no_grid_continuity(grid.interval_s, grid.n_off_grid, window_s):
        return [none] * rows
    w = window_slots(window_s, grid.interval_s)
    up = np.zeros((rows, grid.size), dtype=bool)  # slot holds an available epoch
    up[:, grid.index] = available
    # lost[r, k] = lost slots (gaps or unavailable) of row r before slot k: int32 while it fits
    lost = np.zeros((rows, grid.size + 1), dtype=np.int32 if grid.size < 2**31 - 1 else np.int64)
    np.cumsum(~up, axis=1, dtype=lost.dtype, out=lost[:, 1:])
    # Windows start at slots 0..K-1 (their w following slots exist); events in slots
    # (k, k+w] = prefix[k+w+1] - prefix[k+1], taken as contiguous slices, not gathers.
    k_max = max(grid.size - w, 0)
    starts = up[:, :k_max]
    n_fail = np.count_nonzero(starts & (lost[:, w + 1 : w + 1 + k_max] != lost[:, 1 : 1 + k_max]), axis=1)
    del lost
    gp = grid.gap_prefix
    n_gap = np.count_nonzero(starts & (gp[w + 1 : w + 1 + k_max] != gp[1 : 1 + k_max]), axis=1)
    n = np.count_nonzero(starts, axis=1)
    n_truncated = np.count_nonzero(up[:, k_max:], axis=1)
    short = k_max == 0  # no window fits in the data at all
    return [continuity_result(int(n[r]), int(n_fail[r]), int(n_gap[r]), int(n_truncated[r]), window_s,
                              grid.interval_s, grid.n_off_grid, short=short)
            for r in range(rows)]  # fmt: skip


def continuity_result(
    n: int,
    n_fail: int,
    n_gap: int,
    n_truncated: int,
    window_s: float,
    interval_s: float,
    n_off_grid: int,
    *,
    short: bool = False,
) -> ContinuityResult:
    """The :class:`ContinuityResult` of one station's window counts (whole or merged from days)."""
    return ContinuityResult(
        n_fail / n if n else None,
        n,
        n_fail,
        n_gap,
        n_truncated,
        window_s,
        interval_s,
        n_off_grid,
        "" if n else _no_window(short, window_s),
    )


def _no_window(short: bool, window_s: float) -> str:
    """Why no window was counted: none fits in the data (``short``), or none starts on an available epoch."""
    if short:
        return f"the data are shorter than the {window_s:g} s window: every window runs past their end"
    return "no window starts on an available epoch"


def no_grid_continuity(interval_s: float | None, n_off_grid: int, window_s: float) -> ContinuityResult | None:
    """The result when no window can be counted (no grid, or an interval longer than the
    window), else ``None``."""
    if interval_s is None:
        return ContinuityResult(None, 0, 0, 0, 0, window_s, None, 0, "fewer than two epochs")
    if interval_s > window_s:
        reason = f"sampling interval {interval_s:g} s exceeds the {window_s:g} s exposure time"
        return ContinuityResult(None, 0, 0, 0, 0, window_s, interval_s, n_off_grid, reason)
    return None


def window_slots(window_s: float, interval_s: float) -> int:
    """Grid slots after a window's start that the window holds: ``round(T/Δ)``, at least one."""
    return max(1, round(window_s / interval_s))


def sum_continuity(parts: list[ContinuityResult], window_s: float) -> ContinuityResult:
    """Pool per-station counts: windows never span two stations."""
    if len(parts) == 1:
        return parts[0]
    n = sum(p.n_windows for p in parts)
    n_fail = sum(p.n_fail for p in parts)
    intervals = sorted({p.interval_s for p in parts if p.interval_s is not None})
    reason = "" if n else "; ".join(sorted({p.reason for p in parts if p.reason}))
    return ContinuityResult(
        n_fail / n if n else None,
        n,
        n_fail,
        sum(p.n_gap_windows for p in parts),
        sum(p.n_truncated for p in parts),
        window_s,
        intervals[0] if len(intervals) == 1 else None,
        sum(p.n_off_grid for p in parts),
        reason,
    )


# ---------------------------------------------------------------------------
# the whole table


def count_kpis(
    table: pl.DataFrame,
    services: tuple[ServiceLevel, ...] | list[ServiceLevel],
    *,
    histogram_bins: int = 200,
    by_station: bool = True,
) -> CountingResult:
    """All counting KPIs of ``table`` for each service.

    Columns needed: ``time``, ``station``, ``hpe``, ``vpe``, ``hpl``, ``vpl``.

    Returns
    -------
    CountingResult
        Pooled over all stations, and per station in ``by_station`` (unless
        ``by_station=False``). Availability per service and axis (share of *all* epochs with PL < AL;
        combined = both axes), continuity risk per service window (per station,
        pooled), Stanford counts and histograms, accuracy (HPE95, |VPE|95 over
        epochs with a solution) and the safety index PE/PL.

    Notes
    -----
    A service without a vertical alert limit (NPA) has null vertical KPIs and its
    combined KPIs equal the horizontal ones.

    An epoch whose optional ``alert`` column is true (the receiver flagged the solution
    as not to be used) is unavailable for every service: its PLs count as infinite, so
    it lands in the ``unavailable`` region, and it is left out of the safety index.
    """
    x = epoch_arrays(table)
    pe, pls, ok, time_us = x.pe, x.pls, x.ok, x.time_us
    stations = _station_slices(table)
    counter = _Counter(pe, pls, [(idx, slot_grid(time_us[idx])) for idx in stations.values()])
    out_services = {s.name: counter.service(s) for s in services}
    hist = {
        key: stanford_histogram(pe[key[0]], pls[key[0]], axis=key[0], max_value=key[1], bins=histogram_bins)
        for key in histogram_keys(services, histogram_bins)
    }
    return CountingResult(
        n_total=table.height,
        n_with_solution=int(np.count_nonzero(ok)),
        stations=tuple(stations),
        start=_iso(int(time_us.min())) if time_us.size else None,
        end=_iso(int(time_us.max())) if time_us.size else None,
        hpe95=_percentile95(pe["horizontal"][ok]),
        vpe95=_percentile95(pe["vertical"][ok]),
        safety={axis: safety_index(pe[axis], x.si_pls[axis], time_us) for axis in AXES},
        services=out_services,
        histograms=hist,
        by_station=_by_station(table, services) if by_station and len(stations) > 1 else {},
    )


@dataclass(frozen=True, slots=True)
class EpochArrays:
    """The arrays the counting reads from an epoch table.

    ``pe``: HPE and |VPE| per axis; ``pls``: HPL and VPL, +inf where the receiver alerted (so
    the epoch is unavailable for every service); ``si_pls``: the PLs of the safety index, NaN
    where alerted (left out); ``ok``: epochs with finite HPE, VPE, HPL and VPL; ``time_us``:
    ``None`` when the table was read without its times.
    """

    pe: dict[str, np.ndarray]
    pls: dict[str, np.ndarray]
    si_pls: dict[str, np.ndarray]
    ok: np.ndarray
    time_us: np.ndarray | None


def epoch_arrays(table: pl.DataFrame) -> EpochArrays:
    """:class:`EpochArrays` of ``table`` (zero-copy views where the columns allow)."""
    hpe = as_numpy(table["hpe"])
    vpe = as_numpy(table["vpe"])
    vpe = np.abs(vpe, out=vpe) if vpe.flags.writeable else np.abs(vpe)  # in place when already a copy
    hpl = as_numpy(table["hpl"])
    vpl = as_numpy(table["vpl"])
    si_pls = {"horizontal": hpl, "vertical": vpl}
    alert = _alerts(table)
    if alert is not None:
        si_pls = {a: np.where(alert, np.nan, x) for a, x in si_pls.items()}
        hpl, vpl = (np.where(alert & ~np.isnan(x), np.inf, x) for x in (hpl, vpl))
    ok = np.isfinite(hpe) & np.isfinite(vpe) & np.isfinite(hpl) & np.isfinite(vpl)
    pe = {"horizontal": hpe, "vertical": vpe}
    pls = {"horizontal": hpl, "vertical": vpl}
    return EpochArrays(pe, pls, si_pls, ok, as_numpy(table["time"]) if "time" in table.columns else None)


def histogram_keys(services, bins: int) -> list[tuple[str, float]]:
    """The ``(axis, plot maximum)`` of each Stanford histogram drawn for ``services``, in order."""
    keys = [
        (axis, plot_max(al)) for s in services for axis in AXES if (al := s.alert_limit(axis)) is not None
    ]
    return list(dict.fromkeys(keys)) if bins else []


def continuity_keys(services) -> dict[tuple, list[float]]:
    """Each availability mask whose continuity is counted, with its windows (s), in order.

    ``(axis, AL)`` for an axis, ``("combined", HAL, VAL)`` for both: services sharing alert
    limits and window (APV-I and LPV) share one count.
    """
    out: dict[tuple, list[float]] = {}
    for s in services:
        keys = [(axis, al) for axis in AXES if (al := s.alert_limit(axis)) is not None]
        for key in (*keys, ("combined", s.hal, s.val)):
            windows = out.setdefault(key, [])
            if s.continuity_window_s not in windows:
                windows.append(s.continuity_window_s)
    return out


def availability_mask(pls: dict[str, np.ndarray], key: tuple) -> np.ndarray:
    """Epochs available under a :func:`continuity_keys` key (PL < AL, on both axes when combined)."""
    if key[0] != "combined":
        return pls[key[0]] < key[1]
    _, hal, val = key
    h = pls["horizontal"] < hal
    return h & (pls["vertical"] < val) if val is not None else h


def service_kpi(
    s: ServiceLevel,
    n_total: int,
    n_available: dict[tuple, int],
    counts: dict[tuple, StanfordCounts],
    continuity,
) -> ServiceKPI:
    """The :class:`ServiceKPI` of ``s`` from counts per :func:`continuity_keys` key;
    ``continuity(key, window_s)`` gives the continuity of a mask."""
    axes: dict[str, AxisKPI] = {}
    for axis in AXES:
        al = s.alert_limit(axis)
        if al is None:
            axes[axis] = AxisKPI(axis, None, None, 0, None, None)
            continue
        k = n_available[(axis, al)]
        cont = continuity((axis, al), s.continuity_window_s)
        axes[axis] = AxisKPI(axis, al, k / n_total if n_total else None, k, cont, counts[(axis, al)])
    key = ("combined", s.hal, s.val)
    k = n_available[key]
    cont = continuity(key, s.continuity_window_s)
    combined = AxisKPI("combined", None, k / n_total if n_total else None, k, cont, None)
    return ServiceKPI(s, axes["horizontal"], axes["vertical"], combined)


def _by_station(table: pl.DataFrame, services: tuple[ServiceLevel, ...] | list[ServiceLevel]) -> dict:
    st = pl.col("station").cast(pl.String)
    names = table["station"].cast(pl.String).unique(maintain_order=True).to_list()
    return {
        name: count_kpis(table.filter(st == name), services, histogram_bins=0, by_station=False)
        for name in names
    }


def _alerts(table: pl.DataFrame) -> np.ndarray | None:
    """The ``alert`` flags when the table has any set, else ``None``."""
    if "alert" not in table.columns or not table["alert"].any():
        return None
    return as_numpy(table["alert"].fill_null(False))


def _percentile95(x: np.ndarray) -> float | None:
    return float(np.percentile(x, 95)) if x.size else None


def _station_slices(table: pl.DataFrame) -> dict[str, np.ndarray | slice]:
    """Row indices of each station (a slice when the table holds one station)."""
    st = table["station"].cast(pl.Categorical())
    uniq = st.unique(maintain_order=True)
    names = uniq.cast(pl.String).to_list()
    if len(names) <= 1:
        return {name: slice(None) for name in names}
    codes = as_numpy(st.to_physical())  # compare codes, not millions of strings
    return {name: np.flatnonzero(codes == code) for name, code in zip(names, uniq.to_physical(), strict=True)}


@dataclass
class _Counter:
    """Per-table state shared by the services: arrays, station grids, and continuity
    results cached by alert limits and window (APV-I and LPV share theirs)."""

    pe: dict[str, np.ndarray]
    pls: dict[str, np.ndarray]
    grids: list[tuple[np.ndarray | slice, SlotGrid | None]]

    def __post_init__(self) -> None:
        self._cache: dict[tuple, ContinuityResult] = {}
        self._masks: dict[tuple, np.ndarray] = {}
        # AL-independent masks of each axis, shared by all services
        self._no_solution = {a: np.isnan(self.pe[a]) | np.isnan(self.pls[a]) for a in AXES}
        self._above = {a: self.pe[a] > self.pls[a] for a in AXES}

    def mask(self, key: tuple) -> np.ndarray:
        if key not in self._masks:
            self._masks[key] = availability_mask(self.pls, key)
        return self._masks[key]

    def continuity(self, key: tuple, window_s: float) -> ContinuityResult:
        if (key, window_s) not in self._cache:
            avail = self.mask(key)
            parts = [_continuity_on_grid(g, avail[idx], window_s) for idx, g in self.grids]
            self._cache[(key, window_s)] = (
                sum_continuity(parts, window_s)
                if parts
                else ContinuityResult(None, 0, 0, 0, 0, window_s, None, 0, "no epochs")
            )
        return self._cache[(key, window_s)]

    def service(self, s: ServiceLevel) -> ServiceKPI:
        keys = [(a, al) for a in AXES if (al := s.alert_limit(a)) is not None]
        keys.append(("combined", s.hal, s.val))
        n_avail = {k: int(np.count_nonzero(self.mask(k))) for k in keys}
        counts = {
            (a, al): _counts(self.pe[a], self.pls[a], al, self._no_solution[a], self._above[a])
            for a, al in keys[:-1]
        }
        return service_kpi(s, self.pe["horizontal"].size, n_avail, counts, self.continuity)
