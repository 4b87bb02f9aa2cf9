"""Percentiles of partitioned data equal numpy's on the pooled data, bit for bit (issue 14)."""

from __future__ import annotations

import numpy as np
import pytest

from overbound.stats.mergeable import bin_counts, exact_percentile, merge_counts, rank_bins, values_in_bins


def _two_pass(parts: list[np.ndarray], q: float) -> float:
    counts = merge_counts(*(bin_counts(p) for p in parts))
    bins, below = rank_bins(counts, q)
    values = np.concatenate([values_in_bins(p, bins) for p in parts])
    return exact_percentile(counts.n, q, below, values)


def _data(rng: np.random.Generator, kind: str, n: int) -> np.ndarray:
    if kind == "rayleigh":
        return rng.rayleigh(0.7, n)
    if kind == "signed-heavy":
        return rng.standard_t(2.5, n) * 3.0
    if kind == "ties":
        return np.round(rng.normal(1.0, 0.2, n), 2)  # a few hundred distinct values
    if kind == "constant":
        return np.full(n, 2.5)
    return np.concatenate([rng.normal(0, 1e-6, n // 2), rng.lognormal(3, 2, n - n // 2)])  # "spread"


KINDS = ["rayleigh", "signed-heavy", "ties", "constant", "spread"]


@pytest.mark.parametrize("kind", KINDS)
def test_two_passes_give_numpys_percentile_bit_for_bit(kind: str) -> None:
    rng = np.random.default_rng(KINDS.index(kind))
    for trial in range(40):
        n_parts = int(rng.integers(1, 12))
        parts = [_data(rng, kind, int(rng.integers(1, 3000))) for _ in range(n_parts)]
        pooled = np.concatenate(parts)
        for q in (95, 99, 50, 0, 100, 68.27, 99.9, float(rng.uniform(0, 100))):
            got = _two_pass(parts, q)
            want = float(np.percentile(pooled, q))
            assert got == want and np.signbit(got) == np.signbit(want), (kind, trial, q, got, want)


def test_merging_is_order_free_and_the_second_pass_is_small() -> None:
    rng = np.random.default_rng(7)
    parts = [rng.rayleigh(0.7, 86_400) for _ in range(10)]  # ten station-days at 1 Hz
    a = merge_counts(*(bin_counts(p) for p in parts))
    b = merge_counts(*(bin_counts(p) for p in reversed(parts)))
    assert np.array_equal(a.bins, b.bins) and np.array_equal(a.counts, b.counts) and a.n == 864_000
    bins, _ = rank_bins(a, 95)
    second = sum(values_in_bins(p, bins).size for p in parts)
    assert second < 864_000 / 1000, second  # the exact pass holds a few hundred values, not the campaign


def test_nan_is_refused() -> None:
    with pytest.raises(ValueError, match="NaN"):
        bin_counts(np.array([1.0, np.nan]))


def test_values_in_bins_equals_the_bin_test_of_every_value():
    """The float prefilter of positive bins keeps exactly the values whose bin is asked for: signed
    zeros, subnormals, infinities and the largest float included."""
    from overbound.stats.mergeable import _bins, values_in_bins

    special = np.array(
        [0.0, -0.0, 1e-300, -1e-300, np.inf, -np.inf, 2.0, -2.0, 5e-324, -5e-324, 1.8e308, 3.0]
    )
    rng = np.random.default_rng(5)
    for x in (special, np.concatenate([rng.normal(0, 3, 4000), rng.exponential(2, 4000), special])):
        codes = _bins(x)
        distinct = np.unique(codes)
        pairs = [(i, j) for i in range(distinct.size) for j in range(i, distinct.size)]
        if len(pairs) > 400:  # the random array: 400 ranges of bins drawn
            pairs = [pairs[k] for k in rng.choice(len(pairs), 400, replace=False)]
        for i, j in pairs:
            wanted = distinct[i : j + 1 : max(1, (j - i) // 3)]
            got, ref = np.sort(values_in_bins(x, wanted)), np.sort(x[np.isin(codes, wanted)])
            assert np.array_equal(got, ref) and np.array_equal(np.signbit(got), np.signbit(ref))


def test_exact_quantile_equals_numpy_quantile():
    """``scale=1``: numpy's quantile (no division by 100) from the values of the rank bins."""
    rng = np.random.default_rng(11)
    for n in (1, 2, 7, 1000, 20_001):
        x = np.round(rng.lognormal(0, 2, n), 3)  # ties
        counts = bin_counts(x)
        for q in (0.0, 1e-6, 0.3, 0.9499999, 0.95, 0.9500001, 1.0 - 1e-9, 1.0):
            bins, below = rank_bins(counts, q, scale=1)
            got = exact_percentile(n, q, below, values_in_bins(x, bins), scale=1)
            assert got == np.quantile(x, q), (n, q)


def test_row_percentiles_equal_numpy_nanpercentile_bit_for_bit():
    from overbound.stats.mergeable import row_percentiles

    rng = np.random.default_rng(11)
    x = rng.lognormal(2.0, 1.0, (400, 97))
    x[rng.random(x.shape) < 0.02] = np.nan  # NaN values are no values even where marked valid
    valid = rng.random(x.shape) < rng.random((400, 1))
    valid[:3] = False  # rows without any value
    valid[3, :] = False
    valid[3, 5] = True  # one value
    valid[4, :] = False
    valid[4, [1, 2]] = True  # two
    x[5] = 7.0  # ties
    valid[5] = True
    for q in (0, 50, 95, 99, 99.9, 100):
        got = row_percentiles(x, valid, q)
        for r in range(x.shape[0]):
            vals = x[r][valid[r] & ~np.isnan(x[r])]
            want = np.percentile(vals, q) if vals.size else np.nan
            assert got[r] == want or (np.isnan(got[r]) and np.isnan(want)), (q, r, got[r], want)
