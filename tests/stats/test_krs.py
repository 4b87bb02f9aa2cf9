"""KRS core overbounding test and bootstrap tail-overbounding probability (Veerman et al., section 3.5):
the statistic against a direct loop, the sign convention, and seeded Gaussian / t(3) cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from overbound.stats.krs import TAIL_CHECK_PROBABILITY, krs_test, tail_overbound_probability


def test_statistic_against_direct_loop():
    e = np.random.default_rng(0).normal(0.0, 0.9, 60)
    res = krs_test(e, l_min=0.3, l_tail=2.0)
    a = np.abs(e)
    n = a.size
    ts = []
    for L in sorted(a):
        if 0.3 <= L <= 2.0:
            f = sum(x > L for x in a) / n
            if 0 < f < 1:
                ts.append(math.sqrt(n) * (2 * stats.norm.sf(L) - f) / math.sqrt(f * (1 - f)))
    assert res.statistic == pytest.approx(min(ts), rel=1e-12)
    np.testing.assert_allclose(res.t_values, ts, rtol=1e-12)
    assert res.critical == pytest.approx(stats.norm.ppf(0.95), rel=1e-12)
    assert krs_test(e, l_min=0.3, l_tail=2.0, alpha=0.01).critical == pytest.approx(2.3263478740, rel=1e-9)


def test_sign_is_symmetric_in_error_sign():
    e = np.random.default_rng(1).normal(0.0, 0.8, 500)
    assert krs_test(e, l_min=0.5, l_tail=2.0).statistic == krs_test(-e, l_min=0.5, l_tail=2.0).statistic


@pytest.mark.parametrize("seed", range(3))
def test_gaussian_sd08_passes_both(seed):
    e = np.random.default_rng(seed).normal(0.0, 0.8, 50_000)
    assert krs_test(e, l_min=0.5, l_tail=1.5).overbounded
    t = tail_overbound_probability(e, l_tail=1.5, n_boot=300, rng=seed)
    assert t.overbounded and t.probability >= 0.95


@pytest.mark.parametrize("seed", range(3))
def test_gaussian_sd13_fails_both(seed):
    e = np.random.default_rng(seed).normal(0.0, 1.3, 20_000)
    k = krs_test(e, l_min=0.5, l_tail=2.0)
    assert not k.overbounded and k.statistic < -10
    t = tail_overbound_probability(e, l_tail=2.0, n_boot=200, rng=seed)
    assert not t.overbounded and t.probability < 0.05


def test_exactly_bounded_sample_is_not_declared_overbounded():
    # sd 1: the bound is tight, E[2 Phi-bar - F-hat] = 0, so the minimum over L is negative
    fails = sum(
        not krs_test(np.random.default_rng(s).normal(size=5000), l_min=0.5, l_tail=2.5).overbounded
        for s in range(10)
    )
    assert fails == 10


@pytest.mark.parametrize("seed", range(3))
def test_t3_passes_core_fails_tail(seed):
    # 0.5 t(3): P(|L| > l) is below 2 Phi-bar(l) on [0.5, 2] but far above it at l = 5.7 (1e-3 vs 1e-8)
    e = 0.5 * np.random.default_rng(seed).standard_t(3, 20_000)
    l_ = np.array([0.5, 1.0, 2.0, 5.73])
    truth = 2 * stats.t.sf(l_ / 0.5, 3)
    assert np.all(truth[:3] < 2 * stats.norm.sf(l_[:3])) and truth[3] > 1e4 * 2 * stats.norm.sf(5.73)
    assert krs_test(e, l_min=0.5, l_tail=2.0).overbounded
    t = tail_overbound_probability(e, l_tail=2.0, n_boot=200, rng=seed)
    assert not t.overbounded and t.probability < 0.05


def test_default_check_levels_reach_1e8():
    e = np.random.default_rng(0).normal(0.0, 0.8, 5000)
    t = tail_overbound_probability(e, l_tail=1.5, n_boot=20, rng=0)
    assert t.check_levels[0] == 1.5
    assert 2 * stats.norm.sf(t.check_levels[-1]) == pytest.approx(TAIL_CHECK_PROBABILITY, rel=1e-9)
    assert t.check_levels[-1] == pytest.approx(5.7307, abs=1e-3)
    assert t.n == 5000 and t.n_tail == int(np.sum(np.abs(e) > 1.5)) and t.margin.shape == (20,)
    r1 = tail_overbound_probability(e, l_tail=1.5, n_boot=20, rng=0)
    np.testing.assert_array_equal(t.margin, r1.margin)
