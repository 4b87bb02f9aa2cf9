"""Percentiles of data split into partitions, equal to numpy's on the pooled data to the last bit.

A campaign of many station-days cannot be pooled in memory, yet its accuracy figures (HPE95,
|VPE|95) must be the linear-interpolation percentile of all its epochs, as ``np.percentile``
gives it on one table. Two passes over the partitions do it exactly:

1. :func:`bin_counts` per partition: how many values fall in each *bin* of an
   order-preserving code of the float64 bits (the top :data:`BITS` bits: sign, exponent and
   8 bits of mantissa, so a bin spans 1/256 of an octave: a day of errors spanning a few
   octaves fills a thousand or two bins); the counts merge by addition
   (:func:`merge_counts`).
2. :func:`rank_bins` finds, from the merged counts, the bins holding the two order statistics
   the percentile interpolates between; :func:`values_in_bins` takes, per partition, the few
   values in those bins; :func:`exact_percentile` sorts them and interpolates as numpy does.

The interpolation repeats numpy's ``linear`` method (Hyndman & Fan type 7): virtual index
``(n - 1) * (q / 100)``, its floor ``k`` and fraction ``g``, and numpy's ``_lerp``, which
computes ``b - (b - a)(1 - g)`` when ``g >= 0.5`` and ``a + (b - a) g`` otherwise
(numpy 2.x, ``numpy/lib/_function_base_impl.py``). The tests compare with ``np.percentile``
bit for bit on random and tied data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "BITS",
    "BinCounts",
    "bin_counts",
    "exact_percentile",
    "merge_counts",
    "rank_bins",
    "values_in_bins",
]

#: Bits of the order-preserving code kept as the bin: 1 sign + 11 exponent + 8 mantissa. Fewer
#: bits: smaller partial results (a day at 1 Hz: ~1.5k bins per variable instead of ~20k at 12
#: mantissa bits, measured), more values in the second pass (still a few hundred per partition).
BITS = 20
_SHIFT = np.uint64(64 - BITS)


@dataclass(frozen=True)
class BinCounts:
    """Sparse counts of values per bin: sorted ``bins`` (uint64 float-bit bins, or any integer
    keys) and their ``counts`` (int64)."""

    bins: np.ndarray
    counts: np.ndarray

    @property
    def n(self) -> int:
        """The number of values counted."""
        return int(self.counts.sum())


def _bins(x: np.ndarray) -> np.ndarray:
    """The bin of each value: the top bits of its float64 bits, flipped so that order is kept."""
    u = np.ascontiguousarray(x, dtype=np.float64).view(np.uint64)
    negative = (u >> np.uint64(63)).astype(bool)
    key = np.where(negative, ~u, u | np.uint64(1 << 63))
    return key >> _SHIFT


def bin_counts(x: np.ndarray) -> BinCounts:
    """Pass 1 on one partition: its values counted per bin.

    Raises
    ------
    ValueError
        A value is NaN (the percentile of data with NaN is NaN: filter first).
    """
    x = np.asarray(x, dtype=np.float64)
    if np.isnan(x).any():
        raise ValueError("NaN values: pass the finite values only")
    return _counted(_bins(x), None)


def _counted(bins: np.ndarray, counts: np.ndarray | None) -> BinCounts:
    """Distinct ``bins`` (sorted, of the dtype given) with their summed ``counts`` (1 each when
    ``None``). Any integer keys count this way: float bins here, time steps and flat histogram
    indices in :mod:`overbound.methods.counting_partitions`.

    A dense ``bincount`` over the span of the bins when it is narrow (the usual case: a
    partition's errors span a few octaves, a few tens of thousands of bins), else a sort.
    """
    if bins.size == 0:
        return BinCounts(np.empty(0, bins.dtype), np.empty(0, np.int64))
    lo = bins.min()
    if int(bins.max() - lo) < _DENSE_SPAN:
        dense = np.bincount((bins - lo).astype(np.intp), weights=counts)  # float64: exact below 2**53
        nz = np.flatnonzero(dense)
        return BinCounts(nz.astype(bins.dtype) + lo, dense[nz].astype(np.int64))
    uniq, inverse = np.unique(bins, return_inverse=True)
    total = np.bincount(inverse, weights=counts, minlength=uniq.size)
    return BinCounts(uniq, total.astype(np.int64))


#: Widest span of bins counted densely (4 M bins, 32 MB of float64 counts).
_DENSE_SPAN = 1 << 22


def merge_counts(*parts: BinCounts) -> BinCounts:
    """The counts of the partitions together (associative and commutative)."""
    if not parts:
        return BinCounts(np.empty(0, np.uint64), np.empty(0, np.int64))
    if len(parts) == 1:
        return parts[0]
    return _counted(np.concatenate([p.bins for p in parts]), np.concatenate([p.counts for p in parts]))


def _virtual_index(n: int, q: float, scale: float = 100.0) -> tuple[int, float]:
    """numpy's linear virtual index ``(n - 1) * (q / scale)``: its floor (clipped) and fraction
    (``scale`` 100 for ``percentile``, 1 for ``quantile``, which does not divide)."""
    v = (n - 1) * (q if scale == 1 else np.true_divide(q, scale))
    k = int(np.clip(np.floor(v), 0, n - 1))
    return k, float(v - np.floor(v))


def rank_bins(counts: BinCounts, q: float, *, scale: float = 100.0) -> tuple[np.ndarray, int]:
    """The bins holding the order statistics ``k`` and ``k + 1`` of the percentile ``q``
    (``scale=1``: the quantile ``q``), and the number of values in the bins below the first of
    them."""
    n = counts.n
    if n == 0:
        raise ValueError("no values")
    k, _ = _virtual_index(n, q, scale)
    ranks = [k, min(k + 1, n - 1)]
    ends = np.cumsum(counts.counts)
    which = np.searchsorted(ends, np.array(ranks), side="right")
    first = int(which[0])
    below = int(ends[first - 1]) if first else 0
    return counts.bins[first : int(which[1]) + 1], below


def values_in_bins(x: np.ndarray, bins: np.ndarray) -> np.ndarray:
    """Pass 2 on one partition: its values that fall in ``bins`` (sorted)."""
    x = np.asarray(x, dtype=np.float64)
    if bins.size == 0:
        return x[:0]
    # positive finite bins (errors, safety indices): first the few values between the first and
    # the last bin by two float comparisons, then their bins; otherwise the bins of all
    lo, hi = value_range(bins)
    if lo > 0 and np.isfinite(hi):
        x = x[(x >= lo) & (x < hi)]
    codes = _bins(x)
    i = np.searchsorted(bins, codes)  # bins are sorted (as rank_bins gives them)
    np.minimum(i, bins.size - 1, out=i)
    return x[bins[i] == codes]


def value_range(bins: np.ndarray) -> tuple[float, float]:
    """``[lo, hi)``: from the smallest float64 of the first of ``bins`` (sorted) to that of the bin
    after the last; every value of those bins lies in it (positive bins only: the order of the
    bins is the values' order there)."""
    return _bin_start(int(bins[0])), _bin_start(int(bins[-1]) + 1)


def _bin_start(code: int) -> float:
    """The smallest float64 of bin ``code`` (the inverse of :func:`_bins` on the bin's lowest
    key); NaN where that key is no number, +inf past the last bin. Used for positive bins only."""
    if code >= 1 << BITS:
        return float("inf")
    key = np.uint64(code) << _SHIFT
    u = key ^ np.uint64(1 << 63) if key >> np.uint64(63) else ~key
    return float(np.array([u], dtype=np.uint64).view(np.float64)[0])


def row_percentiles(x: np.ndarray, valid: np.ndarray, q: float) -> np.ndarray:
    """Per row of ``x``, numpy's ``nanpercentile`` of the row's ``valid`` values (NaN where a row has
    none), to the last bit, without numpy's per-row loop (``apply_along_axis``).

    numpy's linear method: virtual index ``v = (n - 1) * (q / 100)``, the order statistics
    ``a = s[floor(v)]`` and ``b = s[min(floor(v) + 1, n - 1)]`` of the row's ``n`` valid values, and
    its ``_lerp``: ``a + (b - a) g``, or ``b - (b - a)(1 - g)`` when ``g = v - floor(v) >= 0.5``.
    """
    valid = valid & ~np.isnan(x)  # a NaN is no value, as nanpercentile has it
    s = np.sort(np.where(valid, x, np.nan), axis=1)  # NaN sorts last: the valid values lead each row
    n = np.count_nonzero(valid, axis=1)
    v = (np.maximum(n, 1) - 1) * np.true_divide(q, 100.0)
    k = np.floor(v)
    g = v - k
    lo = np.clip(k.astype(np.int64), 0, np.maximum(n - 1, 0))
    hi = np.minimum(lo + 1, np.maximum(n - 1, 0))
    a = np.take_along_axis(s, lo[:, None], axis=1)[:, 0]
    b = np.take_along_axis(s, hi[:, None], axis=1)[:, 0]
    out = _lerp(a, b, g)
    out[n == 0] = np.nan
    return out


def _lerp(a, b, g):
    """numpy's ``_lerp`` of its quantiles: ``a + (b - a) g``, or ``b - (b - a)(1 - g)`` when ``g >= 0.5``
    (the same bits as ``np.percentile``)."""
    d = b - a
    return np.where(g >= 0.5, b - d * (1.0 - g), a + d * g)


def exact_percentile(n: int, q: float, below: int, values: np.ndarray, *, scale: float = 100.0) -> float:
    """numpy's ``percentile(pooled, q)`` (``scale=1``: ``quantile(pooled, q)``) from the values of
    the rank bins of all partitions.

    Parameters
    ----------
    n : the number of values pooled.
    q : the percentile, 0 to 100.
    below : the number of values in the bins below the rank bins (:func:`rank_bins`).
    values : every value in the rank bins, from all partitions (:func:`values_in_bins`).
    """
    k, g = _virtual_index(n, q, scale)
    s = np.sort(np.asarray(values, dtype=np.float64))
    a = s[k - below]
    b = s[min(k + 1, n - 1) - below]
    return float(_lerp(a, b, g))
