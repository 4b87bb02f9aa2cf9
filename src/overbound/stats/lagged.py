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


def lagged_sums(x: np.ndarray, max_lag: int, bits: int, before: np.ndarray | None = None) -> LaggedSums:
    """The lagged sums of a block ``x`` (NaN where no valid sample), the pairs reaching into the
    ``before`` slots (the slots just before the block; NaN where none) included.

    Each sum is one zero-padded real-FFT cross-correlation of the left (earlier) and right (later)
    sequences, rounded to ``bits`` fractional bits.
    """
    x = np.asarray(x, dtype=np.float64)
    b = np.empty(0) if before is None else np.asarray(before, dtype=np.float64)
    left = np.concatenate([b, x])
    lw = np.isfinite(left)
    lx = np.where(lw, left, 0.0)
    rw, rx = lw.copy(), lx.copy()
    rw[: b.size] = False
    rx[: b.size] = 0.0
    size = scipy.fft.next_fast_len(left.size + max_lag, real=True)
    fx, fw = (np.conj(scipy.fft.rfft(a, size)) for a in (lx, lw.astype(np.float64)))
    gx, gw = (scipy.fft.rfft(a, size) for a in (rx, rw.astype(np.float64)))

    def corr(fa: np.ndarray, gc: np.ndarray) -> np.ndarray:  # sum_j a[j] c[j + k], k = 0..max_lag
        return scipy.fft.irfft(fa * gc, size)[: max_lag + 1]

    return LaggedSums(
        _fixed(corr(fx, gx), bits),
        _fixed(corr(fx, gw), bits),
        _fixed(corr(fw, gx), bits),
        np.rint(corr(fw, gw)).astype(np.int64),
        int(_fixed(float(np.sum(rx)), bits)),
        int(np.count_nonzero(rw)),
        bits,
    )


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
