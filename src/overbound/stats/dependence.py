r"""Dependence between samples: spacing, autocorrelation, clusters of exceedances, extremal index.

The position errors of an SBAS receiver are correlated over minutes (ionosphere,
slow corrections). Methods that assume independent samples thin the epochs so that
any two samples kept are at least a *spacing* apart: 360 s for EGNOS (Comby et al.
2003, section I.2, eq. (7): one independent sample per approach).

For the tail (Veerman et al., section 3.2) large errors come in clusters: the
autocorrelation and decorrelation time describe the core, the V_K curve gives the
cluster gap K_T, runs declustering keeps the largest value of each cluster, and the
extremal index (Ferro & Segers 2003) measures the mean cluster size.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import polars as pl
import scipy.fft

from overbound.stats.sums import dot

__all__ = [
    "Clusters",
    "RegularSeries",
    "SlotGrid",
    "VKCurve",
    "autocorrelation",
    "cluster_gap",
    "cluster_sizes",
    "decluster_runs",
    "decorrelation_time",
    "extremal_index",
    "extremal_index_runs",
    "interval_from_steps",
    "nominal_interval_us",
    "one_over_e_time",
    "prefix_counts",
    "regular_series",
    "select_spaced",
    "slot_grid",
    "step_counts",
    "vk_curve",
]


def _validate_select_spaced(time_s: np.ndarray, anchor: int, spacing: float) -> tuple[np.ndarray, int]:
    t = np.asarray(time_s)
    if t.ndim != 1:
        raise ValueError(f"time_s must be one-dimensional, got shape {t.shape}")
    if not (np.issubdtype(t.dtype, np.integer) or np.issubdtype(t.dtype, np.floating)):
        raise ValueError(f"time_s must be numeric, got dtype {t.dtype}")
    if t.size == 0:
        raise ValueError("time_s is empty: there is no anchor to select")
    if np.issubdtype(t.dtype, np.floating) and not np.all(np.isfinite(t)):
        raise ValueError("time_s must be finite")
    if t.size > 1 and np.any(t[1:] < t[:-1]):
        raise ValueError("time_s must be sorted in non-decreasing order")
    a = int(anchor)
    if a != anchor or not 0 <= a < t.size:
        raise ValueError(f"anchor must be an index into time_s (0 <= anchor < {t.size}), got {anchor!r}")
    if not (np.isfinite(spacing) and spacing >= 0):
        raise ValueError(f"spacing must be finite and >= 0, got {spacing!r}")
    return t, a


def _chain(step: np.ndarray, start: int, end: int) -> np.ndarray:
    """``start, step[start], step[step[start]], ...`` until the sentinel ``end``, by pointer doubling.

    ``step`` maps every index to another one strictly closer to the sentinel ``end``
    (which maps to itself). Round ``k`` holds the first ``2**k`` chain members and the
    table ``step`` composed ``2**k`` times; the next round applies that table to every member held,
    which doubles the members, and composes the table with itself. Each round is one
    vectorised gather, and there are ``ceil(log2(chain length))`` rounds.
    """
    members = np.array([start], dtype=np.intp)
    jump = step
    while True:
        ahead = jump[members]
        ahead = ahead[ahead != end]
        if ahead.size == 0:  # the 2**k-th successor of the start is past the end: chain complete
            return members
        done = ahead.size < members.size  # the sentinel was reached within this round
        members = np.concatenate([members, ahead])
        if done:
            return members
        jump = jump[jump]


def select_spaced(time_s: np.ndarray, *, anchor: int, spacing: float) -> np.ndarray:
    r"""The largest set of samples at least ``spacing`` apart that contains the sample ``anchor``.

    Parameters
    ----------
    time_s
        Sample times sorted in non-decreasing order (s, or any unit shared with
        ``spacing``; an integer array, e.g. GPS microseconds, with an integer
        ``spacing`` is compared exactly).
    anchor
        Index of the sample that must be kept (Comby et al. 2003 keep the sample with
        the largest absolute error).
    spacing
        Minimum time between any two samples kept; 0 keeps every sample.

    Returns
    -------
    numpy.ndarray
        Sorted indices into ``time_s`` (``intp``): a set of maximum size among the sets
        that contain ``anchor`` and whose pairwise spacings are all ``>= spacing``.

    Raises
    ------
    ValueError
        ``time_s`` empty, not one-dimensional, not finite or not sorted; ``anchor`` not
        an index; ``spacing`` negative or not finite.

    See Also
    --------
    overbound.methods.confidence_level.confidence_analysis : the procedure that uses it.

    Notes
    -----
    **Algorithm.** Greedy from the anchor: forward, the next sample is the *earliest*
    one at least ``spacing`` after the last sample kept; backward, the *latest* one at
    least ``spacing`` before the first kept. Without a Python loop over samples:

    1. ``nxt[i] = searchsorted(t, t[i] + spacing, side="left")``: the earliest sample
       ``>= t[i] + spacing`` (``n`` when there is none, a sentinel that maps to itself);
       ``prv[i] = searchsorted(t, t[i] - spacing, side="right") - 1``: the latest
       sample ``<= t[i] - spacing`` (``-1`` when none).
    2. The forward chain ``a, nxt[a], nxt[nxt[a]], ...`` by pointer doubling (binary
       lifting): holding the first :math:`2^k` members and the table
       :math:`\mathrm{nxt}^{2^k}`, one gather gives the next :math:`2^k` members and one
       more gives :math:`\mathrm{nxt}^{2^{k+1}} = \mathrm{nxt}^{2^k}\circ\mathrm{nxt}^{2^k}`.
       :math:`\lceil\log_2 L\rceil` rounds for a chain of :math:`L` members, each
       :math:`O(n)`. The backward chain likewise with ``prv``.

    **Optimality (exchange argument).** Let :math:`S` be any admissible set containing
    the anchor :math:`a`, and :math:`s_1 < s_2 < \dots < s_m` its members after
    :math:`a` (by time). Let :math:`g_1, g_2, \dots` be the greedy forward chain
    (:math:`g_0 = a`). By induction :math:`g_k` exists and :math:`t(g_k) \le t(s_k)` for
    :math:`k \le m`: :math:`s_1` is at least ``spacing`` after :math:`a`, and
    :math:`g_1` is the earliest such sample, so :math:`t(g_1) \le t(s_1)`; if
    :math:`t(g_k) \le t(s_k)` then :math:`s_{k+1}` is at least ``spacing`` after
    :math:`s_k`, hence after :math:`g_k`, so it is a candidate for :math:`g_{k+1}`,
    which exists and is no later. (Replacing :math:`s_k` by :math:`g_k` — the exchange —
    keeps :math:`S` admissible.) So the greedy forward part has at least :math:`m`
    members; the mirror argument bounds the part before :math:`a`. The two parts do not
    constrain each other: a sample after :math:`a` and one before are at least
    :math:`2\,` ``spacing`` apart. Hence the greedy set is at least as large as
    :math:`S`. Ties in time are allowed (several stations on one time axis): two
    samples at the same time are never both kept when ``spacing > 0``.

    The maximum-size set is not unique in general; this one is the greedy one
    (earliest-next forward, latest-previous backward), which is deterministic.

    References
    ----------
    .. [1] Comby, D., Farnworth, R., Macabiau, C. (2003), "EGNOS vertical protection
       level assessment", ION GPS/GNSS 2003, section II.2 (second level of the data
       selection: samples at least 360 s apart, always containing the largest |VPE|).

    Examples
    --------
    >>> select_spaced(np.array([0.0, 100, 300, 400, 700, 1000]), anchor=2, spacing=360.0)
    array([2, 4])
    >>> select_spaced(np.array([0.0, 100, 300, 400, 700, 1000]), anchor=0, spacing=360.0)
    array([0, 3, 5])
    """
    t, a = _validate_select_spaced(time_s, anchor, spacing)
    n = t.size
    if spacing == 0:
        return np.arange(n, dtype=np.intp)
    if np.issubdtype(t.dtype, np.integer) and float(spacing).is_integer():
        d = np.asarray(int(spacing), dtype=t.dtype)
    else:
        t = t.astype(np.float64, copy=False)
        d = np.float64(spacing)
    # forward: indices 0..n-1, sentinel n (maps to itself)
    nxt = np.empty(n + 1, dtype=np.intp)
    nxt[:n] = np.searchsorted(t, t + d, side="left")
    nxt[n] = n
    # backward, shifted by one so that the sentinel -1 becomes 0: index i is stored at i + 1
    prv = np.empty(n + 1, dtype=np.intp)
    prv[1:] = np.searchsorted(t, t - d, side="right")  # (latest index <= t - d) + 1
    prv[0] = 0
    after = _chain(nxt, a, n)
    before = _chain(prv, a + 1, 0) - 1
    return np.concatenate([before[:0:-1], after])


# --------------------------------------------------------------------------------------------------
# regular time grid
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RegularSeries:
    """A series placed on a regular time grid, NaN in the slots without an epoch.

    Attributes
    ----------
    values : values per grid slot (``float64``), NaN where no epoch fell (gaps) or the
        epoch's value was NaN (no solution).
    start_us : time of slot 0 (the first epoch), GPS microseconds.
    interval_s : grid interval (s).
    slot : grid slot of each input epoch (``intp``).
    n_off_grid : epochs more than a quarter interval off their slot (rounded onto it).
    n_merged : epochs that shared a slot with another one (the larger value is kept).
    """

    values: np.ndarray
    start_us: int
    interval_s: float
    slot: np.ndarray
    n_off_grid: int
    n_merged: int

    @property
    def time_s(self) -> np.ndarray:
        """Slot times in seconds after ``start_us``."""
        return np.arange(self.values.size) * self.interval_s


def nominal_interval_us(time_us: np.ndarray) -> int | None:
    """Nominal sampling interval (integer microseconds) of sorted epoch times; ``None`` without two times.

    The mean of the positive time steps within 25 % of their median: gaps are left out and
    time-tag jitter averages away; the smallest step when no step is that close to the median.
    Computed from the steps' value counts (:func:`step_counts`, :func:`interval_from_steps`), so
    that the interval of a station split into days is that of its whole series.

    >>> nominal_interval_us(np.array([0, 1_030_000, 1_980_000, 3_000_000, 10_000_000]))
    1000000
    """
    return interval_from_steps(*step_counts(np.diff(np.asarray(time_us, dtype=np.int64))))


def step_counts(steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct positive ``steps`` (sorted, int64) and how often each occurs.

    Hash-based (polars ``value_counts``): a year of 1 Hz steps holds a handful of distinct values.
    """
    s = pl.Series("step", np.asarray(steps, dtype=np.int64))
    vc = s.filter(s > 0).value_counts(sort=False).sort("step")
    return vc["step"].to_numpy(), vc["count"].to_numpy().astype(np.int64)


def interval_from_steps(values: np.ndarray, counts: np.ndarray) -> int | None:
    """:func:`nominal_interval_us` from the value counts of the steps (merged by adding counts).

    The median is that of the expanded steps (the mean of the two middle ones when their number
    is even, as polars' and numpy's); the mean of the steps near it is their exact integer sum
    divided by their number, rounded to the nearest microsecond.
    """
    values, counts = np.asarray(values, dtype=np.int64), np.asarray(counts, dtype=np.int64)
    n = int(counts.sum())
    if n == 0:
        return None
    ends = np.cumsum(counts)
    lo, hi = (int(values[np.searchsorted(ends, r, side="right")]) for r in ((n - 1) // 2, n // 2))
    med = (lo + hi) / 2
    near = np.abs(values - med) <= med / 4
    if not near.any():
        return max(int(values[0]), 1)
    total = sum(int(v) * int(c) for v, c in zip(values[near], counts[near], strict=True))
    return max(round(total / int(counts[near].sum())), 1)


def _validate_regular_series(
    time_us: np.ndarray, values: np.ndarray, interval_s: float | None
) -> tuple[np.ndarray, np.ndarray, int]:
    t = np.asarray(time_us)
    v = np.asarray(values, dtype=np.float64)
    if t.ndim != 1 or v.shape != t.shape:
        raise ValueError(
            f"time_us and values must be one-dimensional of equal length, got {t.shape}, {v.shape}"
        )
    if not np.issubdtype(t.dtype, np.integer):
        raise ValueError(f"time_us must be integer microseconds, got dtype {t.dtype}")
    if t.size == 0:
        raise ValueError("time_us is empty")
    if t.size > 1 and np.any(t[1:] < t[:-1]):
        raise ValueError("time_us must be sorted in non-decreasing order")
    if interval_s is not None:
        if not (np.isfinite(interval_s) and interval_s > 0):
            raise ValueError(f"interval_s must be finite and > 0, got {interval_s!r}")
        dt = round(interval_s * 1e6)
    else:
        dt = nominal_interval_us(t)
        if dt is None:
            raise ValueError("cannot estimate the interval: fewer than two distinct epoch times")
    return t.astype(np.int64, copy=False), v, max(int(dt), 1)


def regular_series(
    time_us: np.ndarray, values: np.ndarray, *, interval_s: float | None = None
) -> RegularSeries:
    r"""Place an epoch series with gaps on a regular time grid, NaN in the gaps.

    Parameters
    ----------
    time_us
        Epoch times, GPS microseconds (``int64``, the epoch table's ``time`` column as
        integers), sorted; one station.
    values
        Value per epoch (e.g. the safety index), NaN for epochs without a solution.
    interval_s
        Grid interval; by default :func:`nominal_interval_us`, the rule the continuity
        count of :mod:`overbound.methods.counting` uses too.

    Returns
    -------
    RegularSeries
        ``values`` on the grid, ``start_us``, ``interval_s``, ``slot`` per epoch,
        ``n_off_grid``, ``n_merged``; ``time_s`` property.

    Raises
    ------
    ValueError
        Empty, unsorted or non-integer times; shapes differ; bad ``interval_s``.

    Notes
    -----
    Slot of epoch :math:`i`: :math:`k_i = \lfloor (t_i - t_0)/\Delta + 1/2 \rfloor`
    (nearest slot). Two epochs in one slot (time-tag jitter, duplicates) keep the
    larger value (NaN ignored): for the tail of the safety index the conservative choice.

    Examples
    --------
    >>> s = regular_series(np.array([0, 1_000_000, 3_000_000]), np.array([0.1, 0.2, 0.4]))
    >>> s.values
    array([0.1, 0.2, nan, 0.4])
    """
    t, v, dt = _validate_regular_series(time_us, values, interval_s)
    rel = t - t[0]
    k = (rel + dt // 2) // dt
    off = int(np.count_nonzero(np.abs(rel - k * dt) > dt / 4))
    out = np.full(int(k[-1]) + 1, np.nan)
    merged = 0
    if k.size > 1 and np.any(k[1:] == k[:-1]):
        dup = np.concatenate([[False], k[1:] == k[:-1]])
        merged = int(np.count_nonzero(dup))
        np.fmax.at(out, k, v)
    else:
        out[k] = v
    return RegularSeries(out, int(t[0]), dt / 1e6, k.astype(np.intp), off, merged)


# --------------------------------------------------------------------------------------------------
# autocorrelation
# --------------------------------------------------------------------------------------------------


def _lagged_products(a: np.ndarray, max_lag: int) -> np.ndarray:
    r""":math:`\sum_t a_t a_{t+k}` for ``k = 0 .. max_lag`` by one zero-padded real FFT."""
    size = scipy.fft.next_fast_len(a.size + max_lag, real=True)
    f = scipy.fft.rfft(a.astype(np.float64, copy=False), size)
    return scipy.fft.irfft(f.real**2 + f.imag**2, size)[: max_lag + 1]


def autocorrelation(x: np.ndarray, *, max_lag: int) -> np.ndarray:
    r"""Sample autocorrelation function of a regular series with missing values (NaN), by FFT.

    Parameters
    ----------
    x
        Values on a regular grid (:func:`regular_series`), NaN for gaps and epochs
        without a solution.
    max_lag
        Largest lag (in grid intervals), ``0 <= max_lag < x.size``.

    Returns
    -------
    numpy.ndarray
        :math:`\hat\rho(k)`, ``k = 0 .. max_lag``; ``rho[0] = 1``; NaN at lags with no
        pair of valid samples, and everywhere when fewer than two valid samples or zero
        variance.

    Raises
    ------
    ValueError
        ``x`` not one-dimensional, ``max_lag`` out of range.

    Notes
    -----
    With :math:`w_t = 1` for a valid sample and 0 for NaN, :math:`\bar x` the mean of
    the valid samples and :math:`d_t = w_t (x_t - \bar x)` (deviations zero-filled):

    .. math::

        \hat\rho(k) = \frac{\sum_t d_t d_{t+k} \,/\, \sum_t w_t w_{t+k}}
                           {\sum_t d_t^2 \,/\, \sum_t w_t}

    i.e. the mean lag-:math:`k` product over the pairs that exist, divided by the
    variance. Both sums are correlations computed by FFT
    (one real FFT of length :math:`\ge n + m`, zero padding so no product wraps around,
    ``O(n log n)``); the pair counts are rounded to
    integers. Choice: the *pair-count* normalisation is the unbiased-denominator
    estimator (the usual one for series with missing values); without gaps it is the
    :math:`1/(n-k)` estimator, not the usual :math:`1/n` one, so it is not damped at
    large lags but is noisier there, and it is not guaranteed positive definite.
    The mean is that of all valid samples (not per lag).
    """
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 1:
        raise ValueError(f"x must be one-dimensional, got shape {a.shape}")
    m = int(max_lag)
    if m != max_lag or not 0 <= m < max(a.size, 1):
        raise ValueError(f"max_lag must be an integer in [0, {a.size}), got {max_lag!r}")
    out = np.full(m + 1, np.nan)
    w = np.isfinite(a)
    nv = int(np.count_nonzero(w))
    if nv < 2:
        return out
    d = np.where(w, a - a[w].mean(), 0.0)
    var = dot(d, d) / nv
    if not var > 0:
        return out
    n = a.size
    num = _lagged_products(d, m)
    cnt = np.arange(n, n - m - 1, -1, dtype=np.float64) if nv == n else np.rint(_lagged_products(w, m))
    ok = cnt > 0
    out[ok] = num[ok] / cnt[ok] / var
    out[0] = 1.0
    return out


_DECORRELATION_RULES = ("1/e", "zero", "integral")


def decorrelation_time(
    x: np.ndarray,
    *,
    interval_s: float = 1.0,
    rule: Literal["1/e", "zero", "integral"] = "1/e",
    max_lag: int | None = None,
) -> float:
    r"""Decorrelation time of a regular series (Veerman et al., section 3.2: the core's dependence).

    Parameters
    ----------
    x
        Values on a regular grid, NaN in gaps (:func:`regular_series`).
    interval_s
        Grid interval (s).
    rule
        ``"1/e"`` (default): the first lag at which the autocorrelation drops below
        :math:`1/e`; ``"zero"``: the first lag at which it is :math:`\le 0`;
        ``"integral"``: the integral time scale
        :math:`\Delta\,(1 + 2\sum_{k=1}^{k_0-1}\hat\rho(k))`, summed up to the first
        lag :math:`k_0` with :math:`\hat\rho \le 0`.
    max_lag
        Largest lag examined (grid intervals); default ``x.size - 1``.

    Returns
    -------
    float
        Seconds; ``inf`` when the criterion is not met within ``max_lag``; NaN when the
        autocorrelation is undefined (fewer than two valid samples, constant series).

    Notes
    -----
    For an AR(1) series :math:`\rho(k) = \phi^k` the 1/e time is the first integer lag
    :math:`k > -1/\ln\phi`; the integral scale is :math:`(1+\phi)/(1-\phi)` intervals.
    The 1/e time is the e-folding time of an exponential autocorrelation (a
    first-order Gauss-Markov process, the usual model of SBAS residual errors); the
    zero crossing is longer and noisier; the integral scale is the spacing at which
    the variance of the mean equals that of independent samples.
    """
    if rule not in _DECORRELATION_RULES:
        raise ValueError(f"rule must be one of {_DECORRELATION_RULES}, got {rule!r}")
    a = np.asarray(x, dtype=np.float64)
    m = a.size - 1 if max_lag is None else int(max_lag)
    rho = autocorrelation(a, max_lag=m)
    if not np.isfinite(rho[0]):
        return float("nan")
    if rule == "1/e":
        return one_over_e_time(rho, interval_s)
    hit = np.flatnonzero(rho <= 0)  # NaN lags never count
    if rule == "integral":
        k0 = int(hit[0]) if hit.size else rho.size
        return float(interval_s * (1.0 + 2.0 * np.nansum(rho[1:k0])))
    return float(hit[0] * interval_s) if hit.size else float("inf")


def one_over_e_time(rho: np.ndarray, lag_s: float) -> float:
    """First lag (s) at which an autocorrelation ``rho`` (lags 0, 1, ... of ``lag_s``) drops below 1/e.

    ``inf`` when it never does; NaN lags never count. The rule of :func:`decorrelation_time`
    (``"1/e"``), for an ACF already computed.
    """
    below = np.flatnonzero(np.asarray(rho) < np.exp(-1.0))
    return float(below[0] * lag_s) if below.size else float("inf")


@dataclass(frozen=True, slots=True)
class SlotGrid:
    """Epochs of one station placed on a regular time grid (the continuity count's grid rule)."""

    index: np.ndarray  # grid index of each epoch
    size: int
    interval_s: float
    n_off_grid: int
    gap_prefix: np.ndarray  # gap_prefix[k] = empty grid slots before slot k


def slot_grid(time_us: np.ndarray) -> SlotGrid | None:
    """Nearest slot of each epoch on the grid of :func:`nominal_interval_us`; ``None`` below two epochs.

    ``n_off_grid`` counts epochs more than a quarter interval off their slot; ``gap_prefix[k]`` the
    empty slots before slot ``k``.
    """
    dt = nominal_interval_us(time_us)
    if dt is None:
        return None
    # nearest grid slot, in integers and in place (no float temporaries of the whole series)
    k = time_us - (time_us[0] - dt // 2)
    k //= dt
    resid = k * dt
    np.subtract(time_us, resid, out=resid)
    resid -= time_us[0]
    np.abs(resid, out=resid)
    off = int(np.count_nonzero(resid > dt // 4))
    del resid
    size = int(k[-1]) + 1
    empty = np.ones(size, dtype=bool)
    empty[k] = False
    return SlotGrid(k, size, dt / 1e6, off, prefix_counts(empty))


def prefix_counts(flags: np.ndarray) -> np.ndarray:
    """``out[k]`` = number of set flags before ``k``; int32 while it fits (halves memory)."""
    dtype = np.int32 if flags.size < 2**31 - 1 else np.int64
    out = np.empty(flags.size + 1, dtype=dtype)
    out[0] = 0
    np.cumsum(flags, dtype=dtype, out=out[1:])
    return out


# --------------------------------------------------------------------------------------------------
# V_K curve and cluster gap (Veerman et al., section 3.2)
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class VKCurve:
    """The V_K curve of a set of exceedance times (Veerman et al., section 3.2).

    Attributes
    ----------
    k : time windows K (s), increasing.
    v : V_K, pairs of exceedances at most K apart per exceedance.
    n : number of exceedances N.
    duration_s : time from the first exceedance to the last.
    """

    k: np.ndarray
    v: np.ndarray
    n: int
    duration_s: float

    @property
    def poisson_slope(self) -> float:
        """Slope of E{V_K} at small K for N independent (Poisson) times on ``duration_s``: (N-1)/T."""
        return (self.n - 1) / self.duration_s if self.duration_s > 0 else float("nan")

    def poisson(self, k: np.ndarray | None = None) -> np.ndarray:
        r"""E{V_K} of N independent uniform times on [0, T]: :math:`\frac{N-1}{2}(2u - u^2)`, u = K/T."""
        kk = self.k if k is None else np.asarray(k, dtype=np.float64)
        if not self.duration_s > 0:
            return np.full(kk.shape, np.nan)
        u = np.minimum(kk / self.duration_s, 1.0)
        return 0.5 * (self.n - 1) * (2.0 * u - u * u)


def vk_curve(exceedance_times_s: np.ndarray, *, k_values: np.ndarray) -> VKCurve:
    r"""V_K: the number of pairs of exceedances at most K apart, per exceedance (Veerman et al., section 3.2).

    Parameters
    ----------
    exceedance_times_s
        Times of the threshold exceedances (s), any order; NaN not allowed.
    k_values
        Windows K (s), non-negative; sorted on output.

    Returns
    -------
    VKCurve
        ``k``, ``v``, ``n``, ``duration_s``; ``poisson_slope``, ``poisson(k)``.

    Raises
    ------
    ValueError
        Non-finite times; negative or non-finite K.

    Notes
    -----
    .. math::

        V_K = \frac{\#\{(i, j) : i < j,\ |k_i - k_j| \le K\}}{N}

    For sorted times the number of later exceedances within K of exceedance
    :math:`i` is ``searchsorted(t, t[i] + K, "right") - i - 1``; the sum over
    :math:`i` is one vectorised call per K (a loop over the K values only). For
    independent exceedances (Poisson times) :math:`E\{V_K\} \approx (N-1)K/T`, linear
    in K; clusters add a concave part below the cluster duration
    (:func:`cluster_gap`). With N < 2 the curve is zero.
    """
    t = np.sort(np.asarray(exceedance_times_s, dtype=np.float64).ravel())
    if not np.all(np.isfinite(t)):
        raise ValueError("exceedance_times_s must be finite")
    k = np.sort(np.asarray(k_values, dtype=np.float64).ravel())
    if k.size == 0 or not np.all(np.isfinite(k)) or k[0] < 0:
        raise ValueError("k_values must be non-empty, finite and >= 0")
    n = t.size
    v = np.zeros(k.size)
    if n >= 2:
        base = n * (n + 1) // 2  # sum over i of (i + 1)
        for j, kj in enumerate(k):
            v[j] = (int(np.searchsorted(t, t + kj, side="right").sum()) - base) / n
    return VKCurve(k, v, n, float(t[-1] - t[0]) if n else 0.0)


def cluster_gap(curve: VKCurve, *, fit_from: float = 0.5, rtol: float = 0.05, z: float = 3.0) -> float:
    r"""Cluster gap K_T read from the V_K curve: the smallest K above which V_K is linear in K.

    Parameters
    ----------
    curve
        From :func:`vk_curve`; its largest K should be several cluster durations.
    fit_from
        The reference line is fitted to the points with ``K >= fit_from * max(K)``.
    rtol
        Tolerance relative to the line's intercept (the pairs within clusters per
        exceedance).
    z
        Tolerance in units of the Poisson sampling standard deviation of V at the
        largest K, :math:`\sqrt{V_{K_{max}}/N}`.

    Returns
    -------
    float
        K_T (s): one of ``curve.k``; ``curve.k[0]`` when the curve never falls below
        the line by more than the tolerance (independent exceedances); NaN with fewer
        than two exceedances or fewer than three points in the fitted part.

    Notes
    -----
    Veerman et al. (section 3.2): "the graph should approach a straight line above
    values K_T of K for which independence is obtained". They read K_T by eye; the
    automatic rule here:

    1. Fit :math:`V_K \approx a + bK` by least squares to the upper part
       :math:`K \ge` ``fit_from`` :math:`\cdot K_{max}` (slope free, so that the edge
       effect :math:`-K^2/T^2` at large K does not bias the line).
    2. Deficit :math:`r_K = V_K - a - bK`.
    3. Tolerance :math:`\tau =` ``rtol`` :math:`\cdot |a| +` ``z``
       :math:`\sqrt{V_{K_{max}}/N}`.
    4. :math:`K_T` is the smallest K with :math:`r_K \ge -\tau`: the first K, from
       the left, where the curve has reached the line.

    Clusters of duration D make :math:`V_K - bK` rise up to the plateau :math:`a` (the
    within-cluster pairs per exceedance) at :math:`K = D` and stay there. Choices:

    * The *first* crossing (from the left), not the last departure (from the right):
      :math:`V_K` is a cumulative count, so it wanders around the line like a random
      walk at large K; reading from the right picks up those excursions (and the
      jumps from two clusters close together) as spurious large K_T.
    * The noise term :math:`z\sqrt{V_{K_{max}}/N}` (the standard deviation of V
      for Poisson pair counts) keeps independent exceedances at K_T = 0; it is
      negligible against :math:`a` when there are clusters.
    * The curve joins its plateau tangentially (for exceedances spread evenly over a
      cluster of :math:`m` the deficit near D is about :math:`(D-K)^2/(2m)`), so
      K_T comes out somewhat *below* D: about :math:`(1-\sqrt{\mathrm{rtol}})D` for
      dense clusters, i.e. 0.75-0.8 D with the default ``rtol = 0.05``, nearer D for
      sparse clusters. A smaller ``rtol`` moves it towards D but lets the sampling noise
      of :math:`a` push it beyond D; the tests check the range on simulated clusters.
      Use the result as a starting point and read the figure.
    """
    k, v = curve.k, curve.v
    upper = k >= fit_from * k[-1]
    if curve.n < 2 or np.count_nonzero(upper) < 3:
        return float("nan")
    b, a = np.polyfit(k[upper], v[upper], 1)
    deficit = v - (a + b * k)
    tol = rtol * abs(a) + z * np.sqrt(max(float(v[-1]), 0.0) / curve.n)
    return float(k[np.flatnonzero(deficit >= -tol)[0]]) if np.any(deficit >= -tol) else float(k[-1])


# --------------------------------------------------------------------------------------------------
# runs declustering and extremal index
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Clusters:
    """Clusters of threshold exceedances by runs declustering, one row per cluster.

    Attributes
    ----------
    peak_index : index into the input of each cluster's largest value (the first one on ties).
    peak_time : its time (s).
    peak_value : its value (the cluster maximum).
    size : exceedances in the cluster.
    start, end : times of the first and last exceedance of the cluster (s).
    n_exceedances : exceedances in total (``size.sum()``).
    threshold, run_length : the options used.
    """

    peak_index: np.ndarray
    peak_time: np.ndarray
    peak_value: np.ndarray
    size: np.ndarray
    start: np.ndarray
    end: np.ndarray
    n_exceedances: int
    threshold: float
    run_length: float

    @property
    def n_clusters(self) -> int:
        """Number of clusters."""
        return int(self.peak_index.size)

    @property
    def mean_size(self) -> float:
        """Mean cluster size (NaN without clusters); its inverse is the runs extremal index."""
        return self.n_exceedances / self.n_clusters if self.n_clusters else float("nan")


def _validate_series(
    time_s: np.ndarray, values: np.ndarray, threshold: float
) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(time_s, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if t.ndim != 1 or v.shape != t.shape:
        raise ValueError(
            f"time_s and values must be one-dimensional of equal length, got {t.shape}, {v.shape}"
        )
    if not np.all(np.isfinite(t)):
        raise ValueError("time_s must be finite")
    if t.size > 1 and np.any(t[1:] < t[:-1]):
        raise ValueError("time_s must be sorted in non-decreasing order")
    if not np.isfinite(threshold):
        raise ValueError(f"threshold must be finite, got {threshold!r}")
    return t, v


def decluster_runs(
    time_s: np.ndarray, values: np.ndarray, *, threshold: float, run_length: float
) -> Clusters:
    r"""Runs declustering: exceedances at most ``run_length`` apart form one cluster; keep its maximum.

    Parameters
    ----------
    time_s
        Sample times (s), sorted.
    values
        Samples (e.g. the safety index); NaN never exceeds.
    threshold
        Exceedance means ``value > threshold`` (strict, as R evd and pyextremes).
    run_length
        The cluster gap K_T (s): consecutive exceedances separated by more than this
        start a new cluster (Veerman et al., section 3.2).

    Returns
    -------
    Clusters
        ``peak_index``, ``peak_time``, ``peak_value``, ``size``, ``start``, ``end``,
        ``n_exceedances``, ``threshold``, ``run_length``; ``n_clusters``, ``mean_size``.

    Raises
    ------
    ValueError
        Shapes differ; times not finite or unsorted; threshold not finite; negative
        ``run_length``.

    Notes
    -----
    1. Exceedance indices :math:`i_1 < \dots < i_N`, their times :math:`t_{i_j}`.
    2. A cluster starts at :math:`j = 1` and wherever
       :math:`t_{i_j} - t_{i_{j-1}} >` ``run_length`` (``np.diff``).
    3. Cluster maxima by ``np.maximum.reduceat``; the peak is the first exceedance of
       the cluster equal to its maximum (pandas' ``idxmax``, as pyextremes).

    Equivalences: pyextremes ``get_extremes(method="POT", r=run_length)`` (a new
    cluster when the gap is ``> r``); on a regular grid of interval :math:`\Delta`
    with no gaps, R evd ``clusters(x, u, r)`` (a cluster ends after ``r``
    consecutive non-exceedances) with ``run_length = r`` :math:`\Delta`. A gap in the
    data (NaN, or missing epochs) counts as time below the threshold.

    Examples
    --------
    >>> c = decluster_runs(np.arange(8.0), np.array([0, 2, 3, 0, 0, 5, 0, 4]), threshold=1, run_length=1)
    >>> c.peak_index, c.size
    (array([2, 5, 7]), array([2, 1, 1]))
    """
    t, v = _validate_series(time_s, values, threshold)
    if not (np.isfinite(run_length) and run_length >= 0):
        raise ValueError(f"run_length must be finite and >= 0, got {run_length!r}")
    idx = np.flatnonzero(v > threshold)
    te, ve = t[idx], v[idx]
    if idx.size == 0:
        e = np.empty(0)
        return Clusters(idx, e, e, idx.copy(), e, e, 0, float(threshold), float(run_length))
    starts = np.concatenate([[0], np.flatnonzero(np.diff(te) > run_length) + 1])
    ends = np.concatenate([starts[1:], [idx.size]])
    peak = np.maximum.reduceat(ve, starts)
    size = ends - starts
    hit = np.flatnonzero(ve == np.repeat(peak, size))
    first = hit[np.searchsorted(hit, starts)]
    return Clusters(
        idx[first],
        te[first],
        peak,
        size,
        te[starts],
        te[ends - 1],
        int(idx.size),
        float(threshold),
        float(run_length),
    )


def cluster_sizes(time_s: np.ndarray, values: np.ndarray, clusters: Clusters, level: float) -> np.ndarray:
    r"""Exceedances of ``level`` in each cluster whose maximum exceeds it.

    Parameters
    ----------
    time_s, values
        The series that ``clusters`` was formed on.
    clusters
        Runs declustering at a threshold :math:`u_0 \le` ``level``.
    level
        The level :math:`v`.

    Returns
    -------
    numpy.ndarray
        :math:`s_j(v) = \#\{i \in C_j : x_i > v\}` for the clusters :math:`C_j` with maximum
        :math:`> v`, in time order; their mean is the mean cluster size at :math:`v` (clusters kept
        as formed at :math:`u_0`).

    Examples
    --------
    >>> x = np.array([0, 2, 3, 0, 0, 5, 0, 4.0])
    >>> c = decluster_runs(np.arange(8.0), x, threshold=1, run_length=2)
    >>> cluster_sizes(np.arange(8.0), x, c, 2.5)
    array([1, 2])
    """
    if level < clusters.threshold:
        raise ValueError(f"level {level} is below the clustering threshold {clusters.threshold}")
    t = np.asarray(time_s, dtype=np.float64)
    above = np.asarray(values, dtype=np.float64) > level
    owner = np.searchsorted(clusters.start, t[above], side="right") - 1
    return np.bincount(owner, minlength=clusters.n_clusters)[clusters.peak_value > level]


def extremal_index(
    time_s: np.ndarray, values: np.ndarray, *, threshold: float, interval_s: float = 1.0
) -> float:
    r"""Extremal index by the intervals estimator of Ferro & Segers (2003).

    Parameters
    ----------
    time_s
        Sample times (s) on a regular grid of interval ``interval_s`` (e.g.
        :attr:`RegularSeries.time_s`), sorted; missing epochs and NaN values count as
        non-exceedances.
    values
        Samples; exceedance means ``value > threshold``.
    threshold
        The threshold u.
    interval_s
        Grid interval: the inter-exceedance times are ``rint(diff(t) / interval_s)``.

    Returns
    -------
    float
        :math:`\theta \in (0, 1]`; NaN without exceedances, 1 with one (as R evd ``exi``).

    Notes
    -----
    With :math:`N` exceedances and inter-exceedance times :math:`T_1..T_{N-1}` in
    grid intervals (Ferro & Segers 2003, section 4: the intervals estimator and, when
    some interval exceeds 2, its bias-adjusted form):

    .. math::

        \hat\theta = \min\Bigl(1, \frac{2(\sum T_i)^2}{(N-1)\sum T_i^2}\Bigr)
        \ \text{if}\ \max T_i \le 2, \qquad
        \tilde\theta = \min\Bigl(1, \frac{2(\sum (T_i-1))^2}{(N-1)\sum (T_i-1)(T_i-2)}\Bigr)
        \ \text{otherwise}.

    :math:`\theta` is the inverse of the limiting mean cluster size; it needs no
    cluster gap. This is R evd's ``exi(x, u, r = 0)``.

    References
    ----------
    .. [1] Ferro, C. A. T., Segers, J. (2003), "Inference for clusters of extreme
       values", J. R. Statist. Soc. B 65(2), 545-556.
    """
    t, v = _validate_series(time_s, values, threshold)
    if not (np.isfinite(interval_s) and interval_s > 0):
        raise ValueError(f"interval_s must be finite and > 0, got {interval_s!r}")
    te = t[v > threshold]
    n = te.size
    if n == 0:
        return float("nan")
    if n == 1:
        return 1.0
    gaps = np.rint(np.diff(te) / interval_s)
    if gaps.max() > 2:
        g1 = gaps - 1.0
        den = (n - 1) * dot(g1, gaps - 2.0)
        num = 2.0 * float(g1.sum()) ** 2
    else:
        den = (n - 1) * dot(gaps, gaps)
        num = 2.0 * float(gaps.sum()) ** 2
    return float(min(1.0, num / den)) if den > 0 else 1.0


def extremal_index_runs(
    time_s: np.ndarray, values: np.ndarray, *, threshold: float, run_length: float
) -> float:
    r"""Extremal index by the runs estimator: clusters per exceedance, :math:`N_c/N`.

    The inverse of the mean cluster size of :func:`decluster_runs` (R evd
    ``exi(x, u, r)`` with ``run_length = r * interval``); NaN without exceedances.
    """
    c = decluster_runs(time_s, values, threshold=threshold, run_length=run_length)
    return c.n_clusters / c.n_exceedances if c.n_exceedances else float("nan")
