r"""The autocorrelation of a long regular series from the lagged sums of its blocks, merged exactly.

A campaign's series (years at 1 Hz) is too long for one FFT and is read a station-day at a time.
Each *block* (a run of consecutive grid slots) gives, for the lags :math:`k = 0..m`, the raw sums
over the pairs :math:`(t - k, t)` whose later slot :math:`t` is in the block and whose earlier slot
is in the block or in the :math:`m` slots before it (``before``), with :math:`w_t = 1` for a valid
sample and 0 for NaN, :math:`x_t` zero-filled:

.. math::

    S_{xx}(k) = \sum x_{t-k} x_t, \quad S_{xw}(k) = \sum x_{t-k} w_t, \quad
    S_{wx}(k) = \sum w_{t-k} x_t, \quad S_{ww}(k) = \sum w_{t-k} w_t,

plus :math:`S_x = \sum x_t`, :math:`S_w = \sum w_t`. Every pair of the series is counted once,
in the block of its later slot. The sums of the series are the sums of its blocks, and with
:math:`\bar x = S_x / S_w` the autocorrelation is that of
:func:`~overbound.stats.dependence.autocorrelation` (pair-count normalisation, mean of all valid
samples), its numerator expanded:

.. math::

    \sum_t d_{t-k} d_t = S_{xx}(k) - \bar x\,(S_{xw}(k) + S_{wx}(k)) + \bar x^2 S_{ww}(k),
    \qquad \hat\rho(k) = \frac{\sum d_{t-k} d_t / S_{ww}(k)}{\sum d_t^2 / S_w}.

**Exact merge.** Floating-point sums depend on the order they are added in, and the partials of
a campaign merge in a tree whose shape depends on the execution. So each block's float sums are
rounded once to a fixed-point integer of ``bits`` fractional bits (:func:`fixed_point_bits`: as
many as the campaign's largest possible sum leaves in an int64), and blocks add as integers,
exactly, in any order. The same blocks give the same bits, whether they come from one table or
from the partitions of a dataset. The expansion loses :math:`\log_{10}(\overline{x^2}/s^2)`
digits to cancellation (under one for a safety index, about 1.5 for a PL of mean 15 m and
standard deviation 3 m); the fixed point keeps :math:`2^{-62}` of the largest possible sum.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.fft

__all__ = ["LaggedSums", "acf_from_sums", "fixed_point_bits", "lagged_sums", "merge_lagged"]


@dataclass(frozen=True)
class LaggedSums:
    """Fixed-point lagged sums of one or more blocks (see the module notes).

    ``xx``, ``xw``, ``wx`` and ``sx`` are integers of ``bits`` fractional bits; ``ww`` and ``sw``
    are exact pair and sample counts."""

    xx: np.ndarray
    xw: np.ndarray
    wx: np.ndarray
    ww: np.ndarray
    sx: int
    sw: int
    bits: int


def fixed_point_bits(n_samples: int, max_abs: float) -> int:
    """Fractional bits so that any sum of at most ``n_samples`` products of values of magnitude at
    most ``max_abs`` (and of the values themselves) fits in an int64 with a bit to spare."""
    bound = max(n_samples, 1) * max(max_abs * max_abs, max_abs, 1e-300)
    return 61 - math.ceil(math.log2(bound))


def _fixed(x: np.ndarray | float, bits: int) -> np.ndarray:
    return np.rint(np.ldexp(np.asarray(x, dtype=np.float64), bits)).astype(np.int64)


#: Largest number of (run of missing samples, lag) pairs for which the sums with a missing sample are
#: formed from the runs (:func:`lagged_sums`); above, three more FFT correlations are cheaper.
RUNS_LIMIT = 2_000_000


def lagged_sums(x: np.ndarray, max_lag: int, bits: int, before: np.ndarray | None = None) -> LaggedSums:
    """The lagged sums of a block ``x`` (NaN where no valid sample), the pairs reaching into the
    ``before`` slots (the slots just before the block; NaN where none) included.

    :math:`S_{xx}` is a zero-padded real-FFT cross-correlation of the left (earlier) and right
    (later) sequences. The three sums with a weight are the same sums over all pairs (prefix sums
    and pair counts) minus those with a missing sample, formed from the runs of missing samples
    when they are few (the usual gaps and alerts: :data:`RUNS_LIMIT`), else three more FFT
    correlations. Each sum is rounded to ``bits`` fractional bits; the route depends on the
    block alone, so that the same block always gives the same bits.
    """
    x = np.asarray(x, dtype=np.float64)
    nb = 0 if before is None else np.asarray(before).size
    left = x if before is None else np.concatenate([np.asarray(before, dtype=np.float64), x])
    if x.size == 0:  # no right slot: no pair
        zero = np.zeros(max_lag + 1, dtype=np.int64)
        return LaggedSums(zero, zero.copy(), zero.copy(), zero.copy(), 0, 0, bits)
    lw = np.isfinite(left)
    lx = np.where(lw, left, 0.0)
    rx = lx.copy()
    rx[:nb] = 0.0
    size = scipy.fft.next_fast_len(left.size + max_lag, real=True)
    fx = np.conj(scipy.fft.rfft(lx, size))

    def corr(fa: np.ndarray, c: np.ndarray) -> np.ndarray:  # sum_j a[j] c[j + k], k = 0..max_lag
        return scipy.fft.irfft(fa * scipy.fft.rfft(c, size), size)[: max_lag + 1]

    runs = _runs(~lw)
    if runs.shape[0] * (max_lag + 1) <= RUNS_LIMIT:
        xw, wx, ww = _weighted_by_runs(lx, rx, runs, nb, max_lag)
    else:
        rw = lw.astype(np.float64)
        rw[:nb] = 0.0
        fw = np.conj(scipy.fft.rfft(lw.astype(np.float64), size))
        xw, wx, ww = corr(fx, rw), corr(fw, rx), np.rint(corr(fw, rw)).astype(np.int64)
    return LaggedSums(
        _fixed(corr(fx, rx), bits),
        _fixed(xw, bits),
        _fixed(wx, bits),
        ww,
        int(_fixed(float(np.sum(rx)), bits)),
        int(np.count_nonzero(lw[nb:])),
        bits,
    )


def _runs(flags: np.ndarray) -> np.ndarray:
    """``[start, stop)`` of each run of true ``flags``, one row per run."""
    d = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    return np.column_stack([np.flatnonzero(d == 1), np.flatnonzero(d == -1)])


def _weighted_by_runs(
    lx: np.ndarray, rx: np.ndarray, runs: np.ndarray, nb: int, m: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r""":math:`S_{xw}, S_{wx}, S_{ww}` of :func:`lagged_sums` from the pairs of all slots minus those
    with a missing sample, ``runs`` being the ``[start, stop)`` of the runs of missing slots of
    ``before + x`` (``nb`` slots before).

    Lag :math:`k` pairs the left slot :math:`u - k` with the right slot :math:`u` for
    :math:`\max(nb, k) \le u < L`; with zero-filled values, prefix sums give every sum over a
    range of slots: :math:`S_{xw}(k) = \sum_u x_{u-k} - \sum_{u 	ext{ missing}} x_{u-k}`,
    :math:`S_{wx}(k) = \sum_u x_u - \sum_{j 	ext{ missing}} x_{j+k}`, and :math:`S_{ww}(k)` is
    the pairs less those with a missing right slot, less those with a missing left slot, plus
    those with both (the overlap of a run shifted by :math:`k` with another run).
    """
    n = lx.size
    k = np.arange(m + 1)
    lo = np.minimum(np.maximum(nb, k), n)  # first right slot of lag k (n: no pair at that lag)
    cl = np.concatenate([[0.0], np.cumsum(lx)])
    cr = np.concatenate([[0.0], np.cumsum(rx)])
    a0, a1 = runs[:, :1], runs[:, 1:]  # missing left slots j (columns: lags)
    b0, b1 = np.maximum(a0, nb), np.maximum(a1, nb)  # missing right slots u >= nb
    # sum of x[u - k] over the missing right slots u (u - k >= 0), and of x[j + k] over the missing j
    miss_xw = (cl[np.maximum(b1 - k, 0)] - cl[np.maximum(b0 - k, 0)]).sum(axis=0)
    miss_wx = (cr[np.minimum(a1 + k, n)] - cr[np.minimum(a0 + k, n)]).sum(axis=0)
    xw = cl[np.maximum(n - k, 0)] - cl[np.maximum(lo - k, 0)] - miss_xw
    wx = cr[n] - cr[lo] - miss_wx
    pairs = n - lo
    right = np.clip(b1 - np.maximum(b0, k), 0, None).sum(axis=0)  # missing u >= max(nb, k)
    left_ = np.clip(np.minimum(a1, n - k) - np.maximum(a0, lo - k), 0, None).sum(axis=0)
    # both: j in run A, u = j + k in run B: the overlap of [A0 + k, A1 + k) with [B0, B1)
    # (only the pairs of runs that some lag 0..m brings together)
    ia, ib = np.nonzero((b1[None, :, 0] > a0[:, :1]) & (b0[None, :, 0] < a1[:, :1] + m + 1))
    both = np.zeros(m + 1, dtype=np.int64)
    if ia.size:
        lo_ab = np.maximum(a0[ia] + k, b0[ib])
        hi_ab = np.minimum(a1[ia] + k, b1[ib])
        both = np.clip(hi_ab - lo_ab, 0, None).sum(axis=0)
    return xw, wx, (pairs - right - left_ + both).astype(np.int64)


def merge_lagged(*parts: LaggedSums) -> LaggedSums:
    """The sums of several blocks (integers: exact, in any order)."""
    first = parts[0]
    if any(p.bits != first.bits or p.xx.size != first.xx.size for p in parts):
        raise ValueError("lagged sums of different lags or fixed points cannot be merged")
    return LaggedSums(
        np.sum([p.xx for p in parts], axis=0),
        np.sum([p.xw for p in parts], axis=0),
        np.sum([p.wx for p in parts], axis=0),
        np.sum([p.ww for p in parts], axis=0),
        sum(p.sx for p in parts),
        sum(p.sw for p in parts),
        first.bits,
    )


def acf_from_sums(s: LaggedSums) -> np.ndarray:
    r""":math:`\hat\rho(k)` from merged sums (module notes); NaN at lags without a pair, and
    everywhere with fewer than two valid samples or no variance, as
    :func:`~overbound.stats.dependence.autocorrelation`."""
    out = np.full(s.xx.size, np.nan)
    if s.sw < 2:
        return out
    scale = math.ldexp(1.0, -s.bits)
    mean = s.sx * scale / s.sw
    xx, xw, wx = (a.astype(np.float64) * scale for a in (s.xx, s.xw, s.wx))
    ww = s.ww.astype(np.float64)
    num = xx - mean * (xw + wx) + mean * mean * ww
    var = num[0] / s.sw
    if not var > 0:
        return out
    ok = ww > 0
    out[ok] = num[ok] / ww[ok] / var
    out[0] = 1.0
    return out
