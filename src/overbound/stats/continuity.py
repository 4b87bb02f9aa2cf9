r"""Non-continuity as a function of the alert limit (Kannemans 2006, section 2.1.4).

Kannemans counts, for one alert limit, the sliding windows that start on an available epoch and
lose the service (an unavailable epoch) within the exposure time, then repeats the count "for a
range of vertical alert limits varying from the minimum VPL up to the maximum VPL" (his figure 12)
and fits :math:`\log_{10} P = a + b\,AL` (figure 13: :math:`10^{-2.133 - 0.012\,VAL}`), with a
confidence band that needs a "decorrelation factor" (8 in his case) because consecutive windows
fail together.

:func:`noncontinuity_curve` gives the exact count of
:func:`overbound.methods.counting.continuity_risk` at every alert limit of a grid in one pass
over the data; :func:`pool_curves` sums stations; :func:`fit_loglinear` fits the straight line.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.stats

from overbound.stats.dependence import SlotGrid, slot_grid  # the continuity count's grid rule
from overbound.stats.sums import dot

__all__ = [
    "ContinuityCurve",
    "LogLinearFit",
    "StationGrid",
    "WindowCounter",
    "alert_limit_grid",
    "availability_ranks",
    "clopper_pearson_upper",
    "curve_from_counts",
    "fit_loglinear",
    "noncontinuity_curve",
    "pool_curves",
    "station_grid",
]

#: Default number of evenly spaced alert limits of :func:`alert_limit_grid`.
GRID_POINTS = 400
_CHUNK = 1 << 16  # elements per pass of the array loops: their temporaries stay in cache


@dataclass(frozen=True, slots=True)
class ContinuityCurve:
    r"""Loss-of-continuity counts against the alert limit (arrays read-only, one value per AL).

    Attributes
    ----------
    alert_limit : the alert limits (m), strictly increasing.
    n_windows : windows that start on an epoch with PL < AL and whose slots exist
        (:math:`N_{success} + N_{fail}` of Kannemans).
    n_fail : of those, windows with a slot after the start that is unavailable (PL >= AL, no
        solution, alert) or missing.
    n_events : loss events: runs of failing windows, each counted once (a run goes on across start
        slots that are not windows, see :func:`noncontinuity_curve`).
    risk : ``n_fail / n_windows`` (NaN without windows).
    risk_bound : one-sided Clopper-Pearson upper bound at ``confidence`` of ``n_events``
        independent events out of ``n_windows / decorrelation_factor`` (NaN without windows).
    decorrelation_factor : :math:`D = n_{fail}/n_{events}`, the mean number of failing windows per
        event; the window length in slots when there is no event.
    window_s : exposure time (s).
    confidence : confidence level of ``risk_bound``.
    """

    alert_limit: np.ndarray
    n_windows: np.ndarray
    n_fail: np.ndarray
    n_events: np.ndarray
    risk: np.ndarray
    risk_bound: np.ndarray
    decorrelation_factor: np.ndarray
    window_s: float
    confidence: float


@dataclass(frozen=True, slots=True)
class StationGrid:
    """One station's epochs on the regular time grid of the continuity count (:func:`station_grid`).

    Attributes
    ----------
    n_epochs : epochs placed.
    interval_s : nominal sampling interval (s); ``None`` with fewer than two epoch times.
    n_off_grid : epochs more than a quarter interval off their slot (rounded onto it).
    """

    n_epochs: int
    interval_s: float | None
    n_off_grid: int
    _grid: SlotGrid | None = field(repr=False)


@dataclass(frozen=True, slots=True)
class LogLinearFit:
    r"""Least-squares line :math:`\log_{10} P = a + b\,AL` (Kannemans 2006, section 2.1.4).

    Attributes
    ----------
    a, b : intercept and slope (per metre).
    al_min, al_max : alert-limit range of the points fitted (m).
    n_points : points fitted (those with :math:`P > 0`).
    """

    a: float
    b: float
    al_min: float
    al_max: float
    n_points: int

    def log10_risk(self, alert_limit: float | np.ndarray) -> float | np.ndarray:
        """:math:`a + b\\,AL`."""
        return self.a + self.b * np.asarray(alert_limit, dtype=float)

    def risk(self, alert_limit: float | np.ndarray) -> float | np.ndarray:
        """:math:`10^{a + b\\,AL}`."""
        return 10.0 ** self.log10_risk(alert_limit)


# --------------------------------------------------------------------------------------------------
# validation


def _check_window_confidence(window_s: float, confidence: float) -> None:
    if not (np.isfinite(window_s) and window_s > 0):
        raise ValueError(f"window_s must be finite and > 0, got {window_s!r}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")


def _check_alert_limits(alert_limits: np.ndarray) -> np.ndarray:
    al = np.asarray(alert_limits, dtype=np.float64)
    if al.ndim != 1 or al.size == 0:
        raise ValueError(f"alert_limits must be a non-empty one-dimensional array, got shape {al.shape}")
    if not np.all(np.isfinite(al)):
        raise ValueError("alert_limits must be finite")
    if np.any(np.diff(al) <= 0):
        raise ValueError("alert_limits must be strictly increasing")
    return al


def _check_times(time_us: np.ndarray) -> np.ndarray:
    t = np.asarray(time_us)
    if np.issubdtype(t.dtype, np.datetime64):
        t = t.astype("datetime64[us]").view(np.int64)
    if t.ndim != 1:
        raise ValueError(f"time_us must be one-dimensional, got shape {t.shape}")
    if not np.issubdtype(t.dtype, np.integer):
        raise ValueError(f"time_us must be integer microseconds, got dtype {t.dtype}")
    t = t.astype(np.int64, copy=False)
    if t.size > 1 and np.any(t[1:] < t[:-1]):
        raise ValueError("time_us must be sorted in non-decreasing order (one station)")
    return t


def _check_pl(pl: np.ndarray, n: int, unavailable: np.ndarray | None) -> np.ndarray:
    x = np.asarray(pl, dtype=np.float64)
    if x.shape != (n,):
        raise ValueError(f"pl must have one value per epoch ({n}), got shape {x.shape}")
    lost = np.isnan(x)
    if unavailable is not None:
        u = np.asarray(unavailable, dtype=bool)
        if u.shape != x.shape:
            raise ValueError(f"unavailable must have the shape of pl {x.shape}, got {u.shape}")
        lost |= u
    return np.where(lost, np.inf, x)  # a lost epoch is unavailable at every AL: PL = +inf


# --------------------------------------------------------------------------------------------------
# array helpers


def _rank(al: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``np.searchsorted(al, x, side="right")`` (``#{al <= x}``) as int16/int32, several times faster.

    ``x`` has no NaN. Bucketing: ``x`` falls in one of ``B = 4 len(al)`` equal buckets over
    ``[al[0], al[-1]]``; the rank is the count of grid points below the bucket (a table look-up)
    plus the grid points of that bucket at or below ``x`` (at most ``m`` comparisons, ``m`` the
    most grid points a bucket, widened by a slack far above rounding error, holds).

    >>> _rank(np.array([1.0, 2.0, 2.5, 4.0]), np.array([0.0, 1.0, 2.2, 2.5, 3.9, 4.0, np.inf])).tolist()
    [0, 1, 2, 3, 3, 4, 4]
    """
    n = al.size
    dtype = np.int16 if n < np.iinfo(np.int16).max else np.int32
    if n == 1:
        return (x >= al[0]).astype(dtype)
    b_count = 4 * n
    span = al[-1] - al[0]
    edges = al[0] + span * (np.arange(b_count + 1) / b_count)
    slack = span / b_count * 1e-6
    base = np.searchsorted(al, edges[:-1] - slack, side="right")
    top = np.searchsorted(al, edges[1:] + slack, side="right")
    m = int(np.max(top - base))
    padded = np.concatenate([al, np.full(m, np.nan)])  # no index runs off the end; NaN <= x is False
    out = np.empty(x.size, dtype=dtype)
    scale = b_count / span
    for s in range(0, x.size, _CHUNK):  # chunks: the temporaries stay in cache
        xc = x[s : s + _CHUNK]
        bucket = xc - al[0]
        bucket *= scale
        np.clip(bucket, 0, b_count - 1, out=bucket)  # below/above the grid: first/last bucket
        start = base[bucket.astype(np.intp)]
        oc = out[s : s + _CHUNK]
        oc[:] = start
        for i in range(m):
            oc += padded[start + i] <= xc
    return out


def availability_ranks(alert_limits: np.ndarray, pl: np.ndarray, unavailable: np.ndarray | None = None):
    """Per epoch, the first index of ``alert_limits`` at which it is available (``AL > PL``):
    ``len(alert_limits)`` for a PL that is NaN, unavailable or above the grid; what
    :class:`WindowCounter` is fed."""
    al = _check_alert_limits(alert_limits)
    x = np.asarray(pl, dtype=np.float64)
    return _rank(al, _check_pl(x, x.size, unavailable))


def _sliding_max(x: np.ndarray, w: int) -> np.ndarray:
    """``out[i] = max(x[i:i+w])`` for ``i = 0 .. len(x) - w``, by doubling (log2 w passes).

    >>> _sliding_max(np.array([1, 3, 2, 0, 5, 4]), 3).tolist()
    [3, 3, 5, 5]
    """
    m, p = x, 1  # m[i] = max(x[i:i+p])
    while 2 * p <= w:
        m = np.maximum(m[:-p], m[p:])
        p *= 2
    if p < w:  # [i, i+p) and [i+w-p, i+w) cover [i, i+w) since w - p < p
        m = np.maximum(m[: m.size - (w - p)], m[w - p :])
    return m


class WindowCounter:
    """The window, failure and event counts of :func:`noncontinuity_curve` of one station, its grid
    slots fed in order, a run at a time (a campaign's station-days; see :meth:`feed`).

    ``rank[k]``: first AL index at which slot ``k`` is available (``n_al``: never). The window at
    ``k`` counts for ``j >= lo = rank[k]`` and fails for ``lo <= j < hi`` with ``hi = max(lo,
    peak[k])``, ``peak[k]`` the largest rank of slots ``k+1 .. k+w``; it starts an event for ``j`` in
    ``[max(lo, hi'), hi)``, ``hi'`` of slot ``k - 1`` (slot ``k - 1`` available and its window not
    failing), and at the first available slot. Intervals are added with difference arrays (``+1`` at
    the start, ``-1`` at the end), by chunks. Integer counts: the same whatever the runs fed.
    """

    def __init__(self, n_al: int, w: int, *, counts_nothing: bool = False) -> None:
        self.n_al, self.w = int(n_al), int(w)
        #: The station's windows are not counted (no grid, or an interval longer than the window).
        self.counts_nothing = counts_nothing
        self._dtype = np.int16 if n_al < np.iinfo(np.int16).max else np.int32
        self._pending = np.empty(0, dtype=self._dtype)  # slots not yet a counted window start
        self._last: int | None = None  # grid index of the last slot fed
        self._prev: tuple[int, int] | None = None  # (lo, hi) of the last start counted
        self._min = self.n_al  # lowest rank of the starts counted
        self._diff = np.zeros((3, self.n_al + 1), dtype=np.int64)
        self._first = np.zeros(self.n_al, dtype=np.int64)

    @classmethod
    def for_grid(cls, n_al: int, interval_s: float | None, window_s: float) -> WindowCounter:
        """The counter of a station whose grid has ``interval_s`` (``None``: fewer than two epoch
        times), for windows of ``window_s``: ``round(T/Δ)`` slots (at least one); a counter fed
        nothing (all counts zero, one slot) when there is no grid or its interval is longer than
        the window (``counts_nothing``)."""
        if interval_s is None or interval_s > window_s:
            return cls(n_al, 1, counts_nothing=True)
        return cls(n_al, max(1, round(window_s / interval_s)))

    @property
    def dtype(self) -> np.dtype:
        """The integer type of the ranks."""
        return np.dtype(self._dtype)

    def feed(self, first_slot: int, ranks: np.ndarray, *, last: bool = False) -> None:
        """The ranks of the consecutive slots from ``first_slot`` on. Slots skipped since the last
        feed are missing (never available); a first slot equal to the last slot fed replaces it
        (the later epoch sets a shared slot, as numpy's fancy assignment of one table does).
        ``last``: no slot follows, the last windows are counted.

        A gap longer than a window is kept as ``w`` missing slots: the windows before it fail the
        same, and a window starting on a missing slot counts nothing (memory stays bounded by the
        runs fed, not by the span of the station)."""
        if self.counts_nothing:
            return
        r = np.asarray(ranks, dtype=self._dtype)
        if self._last is None or not self._pending.size:
            buf = r
        elif first_slot == self._last:
            buf = np.concatenate([self._pending[:-1], r])
        elif first_slot > self._last:
            gap = np.full(min(first_slot - self._last - 1, self.w), self.n_al, dtype=self._dtype)
            buf = np.concatenate([self._pending, gap, r])
        else:
            raise ValueError(f"slot {first_slot} fed after slot {self._last}: slots must be fed in order")
        self._last = first_slot + r.size - 1
        self._pending = buf
        self._count(last)

    def _count(self, last: bool) -> None:
        """Count the starts whose window's slots are all final (the last slot fed is not, until
        ``last``: the next run may replace it)."""
        buf, w = self._pending, self.w
        n_starts = buf.size - w - (0 if last else 1)
        if n_starts <= 0:
            return
        peak = _sliding_max(buf[: n_starts + w], w)[1:]
        for s in range(0, n_starts, _CHUNK):
            e = min(s + _CHUNK, n_starts)
            self._add(buf[s:e], peak[s:e])
        self._pending = buf[n_starts:].copy()

    def _add(self, lo: np.ndarray, peak: np.ndarray) -> None:
        n = self.n_al + 1
        hi = np.maximum(lo, peak)
        c_lo = np.bincount(lo, minlength=n)
        self._diff[0] += c_lo
        self._diff[1] += c_lo
        self._diff[1] -= np.bincount(hi, minlength=n)
        if self._prev is not None:  # the window before is the last one counted
            lo_p = np.concatenate([[self._prev[0]], lo])
            hi_p = np.concatenate([[self._prev[1]], hi])
        else:
            lo_p, hi_p = lo, hi
        ev_lo = np.maximum(lo_p[1:], hi_p[:-1])
        self._diff[2] += np.bincount(ev_lo, minlength=n)
        self._diff[2] -= np.bincount(np.maximum(ev_lo, hi_p[1:]), minlength=n)
        self._prev = (int(lo[-1]), int(hi[-1]))
        # the first available start slot f(j) (non-increasing in j) starts an event when it fails
        run = np.minimum.accumulate(lo)
        low = int(run[-1])
        if low < self._min:
            j = np.arange(low, self._min)
            f = np.searchsorted(-run, -j, side="left")  # first k of the chunk with run[k] <= j
            self._first[j] += j < hi[f]
            self._min = low

    def finish(self) -> None:
        """No slot follows: count the last windows."""
        self._count(True)

    def counts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(n_windows, n_fail, n_events)`` per AL index of the starts counted."""
        n_windows, n_fail, n_events = (np.cumsum(d)[: self.n_al] for d in self._diff)
        return n_windows, n_fail, n_events + self._first


def clopper_pearson_upper(k: np.ndarray, n: np.ndarray, confidence: float) -> np.ndarray:
    r"""One-sided Clopper-Pearson upper bound of a binomial proportion, non-integer ``n`` allowed.

    :math:`p_u = B^{-1}(c;\ k+1,\ n-k)` (beta quantile), 1 when :math:`k \ge n`, NaN when
    :math:`n \le 0`.

    >>> float(clopper_pearson_upper(np.array([0]), np.array([100.0]), 0.95)[0])  # 1 - 0.05**(1/100)
    0.0295...
    """
    k = np.asarray(k, dtype=float)
    n = np.asarray(n, dtype=float)
    out = np.full(np.broadcast(k, n).shape, np.nan)
    inner = (n > 0) & (k < n)
    out[(n > 0) & (k >= n)] = 1.0
    out[inner] = scipy.stats.beta.ppf(confidence, (k + 1)[inner], (n - k)[inner])
    return out


def _frozen(x: np.ndarray) -> np.ndarray:
    x.setflags(write=False)
    return x


def curve_from_counts(
    al: np.ndarray,
    n_windows: np.ndarray,
    n_fail: np.ndarray,
    n_events: np.ndarray,
    w: int,
    window_s: float,
    confidence: float,
) -> ContinuityCurve:
    """The :class:`ContinuityCurve` of the counts ``n_windows``, ``n_fail``, ``n_events`` at the alert
    limits ``al`` (e.g. :meth:`WindowCounter.counts`), windows of ``w`` slots: the risk, the
    decorrelation factor and the bound."""
    with np.errstate(invalid="ignore", divide="ignore"):
        risk = np.where(n_windows > 0, n_fail / n_windows, np.nan)
        factor = np.where(n_events > 0, n_fail / np.maximum(n_events, 1), float(w))
    bound = clopper_pearson_upper(n_events, n_windows / factor, confidence)
    arrays = (al.copy(), n_windows, n_fail, n_events, risk, bound, factor)
    return ContinuityCurve(*(_frozen(np.asarray(a)) for a in arrays), float(window_s), float(confidence))


# --------------------------------------------------------------------------------------------------
# the curve


def noncontinuity_curve(
    time_us: np.ndarray | None,
    pl: np.ndarray,
    alert_limits: np.ndarray,
    *,
    window_s: float = 15.0,
    confidence: float = 0.95,
    unavailable: np.ndarray | None = None,
    grid: StationGrid | None = None,
) -> ContinuityCurve:
    r"""Kannemans' non-continuity count at every alert limit of a grid, for one station.

    Parameters
    ----------
    time_us
        Epoch times (GPS microseconds, ``int64``), sorted; one station. Not read when ``grid`` is given.
    pl
        Protection level per epoch; NaN (no solution) is unavailable at every alert limit.
    alert_limits
        Strictly increasing, finite alert limits (m), e.g. :func:`alert_limit_grid`.
    window_s
        Exposure time (s): 15 s for the approach services.
    confidence
        Confidence level of ``risk_bound``.
    unavailable
        Optional per-epoch mask of epochs unavailable at every alert limit (the receiver's alert).
    grid
        :func:`station_grid` ``(time_us)``, to place the station on its grid once for several
        calls (axes, windows); ``time_us`` is then not read again.

    Returns
    -------
    ContinuityCurve

    Raises
    ------
    ValueError
        Shapes differ, unsorted or non-integer times, bad alert limits, window or confidence.

    Notes
    -----
    The epochs are put on the regular grid of :func:`overbound.methods.counting.continuity_risk`
    (same interval and slot rule, the same function); a missing slot is a loss of service.
    With :math:`w = \mathrm{round}(T/\Delta)` slots per window, :math:`v_k` the PL of slot
    :math:`k` (:math:`+\infty` when missing, no solution or alert) and
    :math:`M_k = \max(v_{k+1}, \dots, v_{k+w})`, the window starting at slot :math:`k` counts
    at :math:`AL` iff :math:`v_k < AL` and fails iff :math:`v_k < AL \le M_k`, so for
    :math:`k = 0 \dots K-1` (:math:`K` = slots :math:`- w`: the windows whose slots all exist)

    .. math::

        N(AL) = \#\{k : v_k < AL\}, \qquad N_{fail}(AL) = \#\{k : v_k < AL \le M_k\},

    exactly :func:`~overbound.methods.counting.continuity_risk` ``(time_us, pl < AL)`` at each
    :math:`AL` (tested).

    A loss event is a run of failing windows, windows taken in time order: an event starts at a
    failing window whose preceding window (the last earlier start slot available at that AL)
    does not fail, or that has no preceding window. Choice: slots that start no window (PL >= AL,
    gaps) do not break a run. A flickering PL that goes above and below AL every few epochs is
    one loss of service, not one per flicker; counting a new event after each unavailable slot
    would shrink :math:`D` and narrow the bound exactly where the windows are most dependent.
    When slot :math:`k-1` is unavailable and an earlier window exists, that window contains an
    unavailable slot and fails, so the rule reduces to

    .. math::

        N_{events}(AL) = \#\{k \ge 1 : v_k < AL \le M_k,\ \max(v_{k-1}, M_{k-1}) < AL\}
            + 1[\text{the first window at } AL \text{ fails}]

    (:math:`\max(v_{k-1}, M_{k-1}) < AL`: slot :math:`k-1` is available, its window does not
    fail). On the grid these sets are index intervals (ranks of :math:`v_k` and :math:`M_k` among
    the alert limits; the rank of :math:`M_k` is the sliding maximum of the ranks), counted for
    all alert limits at once with difference arrays, :math:`O(n \log w + n_{AL})`.

    The decorrelation factor :math:`D = N_{fail}/N_{events}` (Kannemans: "a factor 8") turns
    the correlated windows into :math:`N/D` independent trials with :math:`N_{events}` events;
    :math:`D = w` without an event (a lone unavailable slot fails :math:`w` windows). The bound is
    the one-sided Clopper-Pearson upper limit of that binomial proportion.

    Fewer than two epochs or a sampling interval longer than ``window_s``: all counts zero.
    """
    _check_window_confidence(window_s, confidence)
    al = _check_alert_limits(alert_limits)
    if grid is None and time_us is None:
        raise ValueError("noncontinuity_curve needs time_us or its station_grid")
    sg = station_grid(time_us) if grid is None else grid
    v = _check_pl(pl, sg.n_epochs, unavailable)
    n_al = al.size
    zeros = np.zeros(n_al, dtype=np.int64)
    grid = sg._grid
    counter = WindowCounter.for_grid(n_al, None if grid is None else grid.interval_s, window_s)
    w = counter.w
    if counter.counts_nothing or grid.size - w <= 0:
        return curve_from_counts(al, zeros, zeros.copy(), zeros.copy(), w, window_s, confidence)
    rank = np.full(grid.size, n_al, dtype=counter.dtype)
    rank[grid.index] = _rank(al, v)  # AL_j > v  <=>  j >= rank; a missing slot is never available
    # the rank of M_k is the largest rank of its slots (the rank is monotone in v)
    counter.feed(0, rank, last=True)
    n_windows, n_fail, n_events = counter.counts()
    return curve_from_counts(al, n_windows, n_fail, n_events, w, window_s, confidence)


def station_grid(time_us: np.ndarray) -> StationGrid:
    """Place one station's epochs on the continuity count's regular grid (for :func:`noncontinuity_curve`).

    The grid of :func:`overbound.methods.counting.continuity_risk`: nominal interval from the
    spacings (:func:`overbound.stats.dependence.nominal_interval_us`), nearest slot per epoch.

    Raises
    ------
    ValueError
        Times not one-dimensional integer microseconds (or ``datetime64``) sorted in time.
    """
    t = _check_times(time_us)
    g = slot_grid(t) if t.size else None
    return StationGrid(int(t.size), None if g is None else g.interval_s, 0 if g is None else g.n_off_grid, g)


def pool_curves(curves: list[ContinuityCurve] | tuple[ContinuityCurve, ...]) -> ContinuityCurve:
    """Sum the counts of several stations (windows never span two stations) and recompute the rest.

    The pooled decorrelation factor is ``sum(n_fail) / sum(n_events)`` (the window length in slots
    kept from the curves when there is no event: the largest of theirs).

    Raises
    ------
    ValueError
        No curve, or curves with different alert limits, windows or confidence levels.
    """
    if not curves:
        raise ValueError("pool_curves needs at least one curve")
    first = curves[0]
    for c in curves[1:]:
        if not np.array_equal(c.alert_limit, first.alert_limit):
            raise ValueError("cannot pool continuity curves over different alert-limit grids")
        if c.window_s != first.window_s or c.confidence != first.confidence:
            raise ValueError("cannot pool continuity curves with different windows or confidence levels")
    total = [sum(getattr(c, f) for c in curves) for f in ("n_windows", "n_fail", "n_events")]
    w = max(int(np.max(c.decorrelation_factor[c.n_events == 0], initial=1)) for c in curves)
    return curve_from_counts(first.alert_limit, *total, w, first.window_s, first.confidence)


# --------------------------------------------------------------------------------------------------
# grid and fit


def alert_limit_grid(pl: np.ndarray, extra: tuple[float, ...] | list[float] = (), *, n: int = GRID_POINTS):
    """Alert limits over the observed PL range: ``n`` evenly spaced values plus ``extra`` inside it.

    The range is ``[min PL, max PL]`` over the finite values (Kannemans: "from the minimum VPL up
    to the maximum VPL"); values of ``extra`` (the services' alert limits) inside it are added,
    duplicates removed. A constant PL gives one point; no finite PL an empty grid.

    >>> alert_limit_grid(np.array([10.0, 12.0, np.nan, 20.0]), extra=(15.5, 50.0), n=3).tolist()
    [10.0, 15.0, 15.5, 20.0]
    """
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n!r}")
    x = np.asarray(pl, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return np.empty(0)
    lo, hi = float(x.min()), float(x.max())
    grid = np.linspace(lo, hi, n) if hi > lo else np.array([lo])
    e = np.asarray(extra, dtype=np.float64)
    return np.union1d(grid, e[(e >= lo) & (e <= hi)])


def fit_loglinear(alert_limit: np.ndarray, risk: np.ndarray) -> LogLinearFit | None:
    r"""Least-squares fit of :math:`\log_{10} P = a + b\,AL` over the points with :math:`P > 0`.

    Kannemans (2006, section 2.1.4) fits the non-continuity this way (his figure 13,
    :math:`10^{-2.133-0.012\,VAL}`). Points with :math:`P = 0` or NaN are left out (their log is
    not finite). ``None`` with fewer than three such points or a single alert limit among them.

    >>> f = fit_loglinear(np.array([10.0, 20.0, 30.0]), np.array([1e-2, 1e-3, 1e-4]))
    >>> round(f.a, 9), round(f.b, 9), f.n_points
    (-1.0, -0.1, 3)
    """
    x = np.asarray(alert_limit, dtype=np.float64)
    p = np.asarray(risk, dtype=np.float64)
    if x.shape != p.shape:
        raise ValueError(f"alert_limit and risk must have equal shapes, got {x.shape}, {p.shape}")
    ok = np.isfinite(x) & np.isfinite(p) & (p > 0)
    x, y = x[ok], np.log10(p[ok])
    if x.size < 3 or np.ptp(x) == 0:
        return None
    xm = x.mean()
    b = dot(x - xm, y - y.mean()) / dot(x - xm, x - xm)
    return LogLinearFit(float(y.mean() - b * xm), b, float(x.min()), float(x.max()), int(x.size))
