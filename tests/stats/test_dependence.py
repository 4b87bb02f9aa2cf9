"""select_spaced: the largest anchored set of samples at least `spacing` apart (Comby et al. 2003, II.2)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from overbound.stats.dependence import select_spaced


def _greedy_loop(t: np.ndarray, anchor: int, spacing: float) -> np.ndarray:
    """Reference: the same greedy rule written as a plain loop over the samples."""
    after, last = [], t[anchor]
    for i in range(anchor + 1, t.size):
        if t[i] - last >= spacing:
            after.append(i)
            last = t[i]
    before, first = [], t[anchor]
    for i in range(anchor - 1, -1, -1):
        if first - t[i] >= spacing:
            before.append(i)
            first = t[i]
    return np.array([*before[::-1], anchor, *after], dtype=np.intp)


def _largest_exhaustive(t: np.ndarray, anchor: int, spacing: float) -> int:
    """Reference: the size of the largest admissible set containing the anchor, by trying every subset."""
    others = [i for i in range(t.size) if i != anchor]
    for size in range(len(others), -1, -1):
        for rest in itertools.combinations(others, size):
            chosen = np.sort(np.array([anchor, *rest]))
            if np.all(np.diff(t[chosen]) >= spacing):
                return size + 1
    raise AssertionError("the anchor alone is always admissible")


def _random_times(rng: np.random.Generator, n: int, *, ties: bool) -> np.ndarray:
    if ties:  # several stations on one time axis: integer seconds with repeats
        return np.sort(rng.integers(0, 4 * n, n)).astype(float)
    return np.sort(rng.exponential(100.0, n).cumsum())


def test_doc_examples():
    t = np.array([0.0, 100, 300, 400, 700, 1000])
    assert select_spaced(t, anchor=2, spacing=360.0).tolist() == [2, 4]
    assert select_spaced(t, anchor=0, spacing=360.0).tolist() == [0, 3, 5]
    # backwards from the last sample: latest-previous
    assert select_spaced(t, anchor=5, spacing=360.0).tolist() == [0, 3, 5]
    assert select_spaced(t, anchor=4, spacing=360.0).tolist() == [2, 4]  # 300 - 0 < 360


@pytest.mark.parametrize("ties", [False, True])
def test_matches_loop_reference_and_is_admissible(ties):
    rng = np.random.default_rng(20031)
    for _ in range(300):
        n = int(rng.integers(1, 400))
        t = _random_times(rng, n, ties=ties)
        anchor = int(rng.integers(0, n))
        spacing = float(rng.choice([1.0, 60.0, 360.0, 1000.0]))
        got = select_spaced(t, anchor=anchor, spacing=spacing)
        np.testing.assert_array_equal(got, _greedy_loop(t, anchor, spacing))
        assert anchor in got
        assert np.all(np.diff(got) > 0)  # sorted, no repeats
        assert np.all(np.diff(t[got]) >= spacing)


def test_size_is_maximal_against_exhaustive_search():
    rng = np.random.default_rng(7)
    for _ in range(250):
        n = int(rng.integers(1, 11))
        t = np.sort(rng.integers(0, 30, n)).astype(float)  # dense, with ties: many near-misses
        anchor = int(rng.integers(0, n))
        spacing = float(rng.integers(1, 8))
        assert select_spaced(t, anchor=anchor, spacing=spacing).size == _largest_exhaustive(
            t, anchor, spacing
        )


def test_spacing_boundary_is_inclusive_and_exact_on_integer_microseconds():
    t_us = np.arange(0, 3_600_000_001, 100_000, dtype=np.int64)  # 0.1 s grid over an hour, microseconds
    got = select_spaced(t_us, anchor=0, spacing=360_000_000)
    assert got.size == 11  # 0, 360, ..., 3600 s: exactly 360 s apart is admissible
    np.testing.assert_array_equal(np.diff(t_us[got]), 360_000_000)
    # the same grid in float seconds is not exact (0.1 is not a binary fraction): integers are the safe input
    assert select_spaced(t_us // 100_000, anchor=0, spacing=3600).size == 11


def test_spacing_zero_keeps_everything_and_one_sample():
    t = np.array([0.0, 0.0, 1.0, 5.0])
    np.testing.assert_array_equal(select_spaced(t, anchor=1, spacing=0.0), [0, 1, 2, 3])
    np.testing.assert_array_equal(select_spaced(np.array([42.0]), anchor=0, spacing=360.0), [0])


def test_ties_never_both_kept():
    t = np.array([0.0, 0.0, 360.0, 360.0, 720.0])
    got = select_spaced(t, anchor=3, spacing=360.0)
    np.testing.assert_array_equal(got, [1, 3, 4])  # backwards the latest of the tied samples


def test_long_chain_uses_doubling_correctly():
    # 6 days at 1 Hz, 360 s spacing: 1440 samples, 11 doubling rounds each way from a middle anchor
    t = np.arange(518_400, dtype=np.int64)
    got = select_spaced(t, anchor=250_000, spacing=360)
    assert got.size == 1440
    assert got[0] == 250_000 % 360 and got[-1] == 518_400 - 1 - (518_399 - 250_000) % 360
    assert np.all(np.diff(got) == 360)


@pytest.mark.parametrize(
    ("t", "anchor", "spacing", "match"),
    [
        (np.array([]), 0, 1.0, "empty"),
        (np.array([1.0, 0.0]), 0, 1.0, "sorted"),
        (np.array([[0.0, 1.0]]), 0, 1.0, "one-dimensional"),
        (np.array([0.0, np.nan]), 0, 1.0, "finite"),
        (np.array([0.0, 1.0]), 2, 1.0, "anchor"),
        (np.array([0.0, 1.0]), 0.5, 1.0, "anchor"),
        (np.array([0.0, 1.0]), 0, -1.0, "spacing"),
        (np.array([0.0, 1.0]), 0, np.inf, "spacing"),
    ],
)
def test_validation(t, anchor, spacing, match):
    with pytest.raises(ValueError, match=match):
        select_spaced(t, anchor=anchor, spacing=spacing)
