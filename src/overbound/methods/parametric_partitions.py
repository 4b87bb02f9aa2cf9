r"""The fits of the parametric analysis from blocks of epochs (station-days), merged exactly.

:func:`~overbound.methods.parametric.parametric_analysis` fits, per axis, the solution epochs of all
stations pooled on one time axis (:func:`~overbound.methods.pooling.pool_epochs`). Here the pooled
series is cut into blocks (a station's GPS day, in pooled order), each reduced to a few sums, and
the fits are finished from the sums added block by block in that order. The pooled table is cut
into the same blocks, so a campaign read a station-day at a time and the table of all its epochs
give the same fits to the last bit. Passes over the blocks:

1. :func:`block_first`: counts, first and last epochs, the time steps, :math:`\sum r`,
   :math:`\sum r^2`, :math:`\sum \ln PL`, the extremes; :func:`axis_plan` merges them: the
   pooled time axis (:func:`~overbound.methods.pooling.pooled_offsets`), the normal ratio's mean,
   the Rayleigh fit, the Weibull's :math:`\max \ln PL` and spread, where each block's epochs
   fall in the subsamples below.
2. :func:`block_second`: :math:`\sum (r - \bar r)^2` (the normal ratio's standard deviation,
   summed as ``np.std`` does), the values of the Weibull fit's start sample (every
   :func:`~overbound.stats.parametric.weibull_start_stride`-th fitted epoch) and the ratio and PL
   series at every ``step``-th slot of the pooled grid (the ACF's subsample,
   ``parametric._acf``). :func:`second_inputs` gathers them.
3. :func:`block_profile`, once per evaluation of the Weibull profile equation
   (:func:`~overbound.stats.parametric.weibull_fit_steps`), and :func:`block_information` at the
   fit (its covariance).

Block sums are added one after the other in pooled order (:func:`add_in_order`): a block
without a fitted epoch adds zeros, which changes no sum.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from overbound.methods.pooling import pooled_offsets
from overbound.stats.dependence import interval_from_steps, step_counts
from overbound.stats.mergeable import BinCounts, merge_counts
from overbound.stats.parametric import (
    WeibullFit,
    squared_deviations,
    weibull_information_sums,
    weibull_profile_sums,
    weibull_start_stride,
)
from overbound.stats.sums import dot

__all__ = [
    "ACF_MAX_SLOTS",
    "AxisPlan",
    "BlockFirst",
    "BlockSecond",
    "FittedBlock",
    "SecondInputs",
    "add_in_order",
    "axis_plan",
    "block_first",
    "block_information",
    "block_profile",
    "block_second",
    "fitted_block",
    "interval_across",
    "second_inputs",
]

#: Longer pooled grids have their ACF computed on every q-th slot (``parametric._acf``).
ACF_MAX_SLOTS = 1 << 21


@dataclass(frozen=True, slots=True)
class FittedBlock:
    """One block's solution epochs of one axis (finite PE, PL > 0), in time order: ``t_us`` all of
    them (their times, µs), ``ratio`` and ``pl`` of those fitted (no alert) and ``t_fit`` their
    times; ``n_alert`` those left out for the alert flag."""

    t_us: np.ndarray
    t_fit: np.ndarray
    ratio: np.ndarray
    pl: np.ndarray
    n_alert: int


def fitted_block(t_us: np.ndarray, pe: np.ndarray, pl: np.ndarray, alert: np.ndarray) -> FittedBlock:
    """The :class:`FittedBlock` of a block's solution epochs (``pe`` signed in the vertical)."""
    keep = ~alert
    pls = pl[keep]
    return FittedBlock(t_us, t_us[keep], pe[keep] / pls, pls, int(t_us.size - pls.size))


@dataclass(frozen=True, slots=True)
class BlockFirst:
    """Pass 1 of one block of one axis (see the module's notes); ``station`` any label equal for
    the blocks of one station; times in µs; sums over the fitted epochs."""

    station: object
    n_solution: int
    n_alert: int
    n_fit: int
    first: int
    last: int
    first_fit: int | None
    last_fit: int | None
    steps: tuple[np.ndarray, np.ndarray]
    ratio_sum: float
    ratio_squares: float
    ratio_min: float
    ratio_max: float
    log_sum: float
    log_min: float
    log_max: float
    pl_min: float
    pl_max: float
    at_or_above: np.ndarray


def block_first(block: FittedBlock, station: object, alert_limits: np.ndarray) -> BlockFirst:
    """Pass 1 of a block (with at least one solution epoch); ``at_or_above``: its fitted PLs at or
    above each of ``alert_limits`` (sorted)."""
    t, r, x = block.t_us, block.ratio, block.pl
    n = x.size
    with np.errstate(divide="ignore"):
        logs = np.log(x)
    return BlockFirst(
        station=station,
        n_solution=int(t.size),
        n_alert=block.n_alert,
        n_fit=int(n),
        first=int(t[0]),
        last=int(t[-1]),
        first_fit=int(block.t_fit[0]) if n else None,
        last_fit=int(block.t_fit[-1]) if n else None,
        steps=step_counts(np.diff(t)),
        ratio_sum=float(r.sum()),
        ratio_squares=dot(r, r),
        ratio_min=float(r.min()) if n else math.inf,
        ratio_max=float(r.max()) if n else -math.inf,
        log_sum=float(logs.sum()),
        log_min=float(logs.min()) if n else math.inf,
        log_max=float(logs.max()) if n else -math.inf,
        pl_min=float(x.min()) if n else math.inf,
        pl_max=float(x.max()) if n else -math.inf,
        at_or_above=np.array([np.count_nonzero(x >= a) for a in alert_limits], dtype=np.int64),
    )


def add_in_order(values) -> float | np.ndarray:
    """The sum of the blocks' partial sums, added one after the other in the order given (the
    rounding of the pooled analysis, whatever the blocks' grouping into tasks)."""
    total = 0.0
    for v in values:
        total = total + v
    return total


@dataclass(frozen=True, slots=True)
class AxisPlan:
    """What pass 2 and the Weibull evaluations need, from the merged pass 1 of all blocks.

    ``n`` fitted epochs (``n_alert`` left out, ``n_solution`` in all, ``n_stations`` stations with
    one); ``mean``: the ratio's mean; ``ymax``, ``spread``: :math:`\\max \\ln PL` and
    :math:`\\max \\ln PL - \\overline{\\ln PL}`; ``stride``: the Weibull start sample's; ``fit_offset``
    per block: its first fitted epoch's position among all; ``shift`` per block: pooled time minus
    time (µs); ``dt``: the pooled interval (µs); ``t0``: pooled time of the first fitted epoch,
    the grid's slot 0; ``size``: slots of the grid; ``step``: the ACF's subsample step;
    ``pl_range``: the fitted PLs' extremes; ``at_or_above``: fitted PLs at or above each alert limit
    of pass 1; ``ratio_squares``: :math:`\\sum r^2`; ``varies``: the
    ratios are not all equal; ``log_varies``: the PLs are not all equal.
    """

    n: int
    n_alert: int
    n_solution: int
    n_stations: int
    mean: float
    ratio_squares: float
    varies: bool
    ymax: float
    spread: float
    log_varies: bool
    stride: int
    fit_offset: tuple[int, ...]
    shift: tuple[int, ...]
    dt: int
    t0: int
    size: int
    step: int
    pl_range: tuple[float, float]
    at_or_above: np.ndarray


def interval_across(parts: Sequence[tuple[object, int, int, tuple[np.ndarray, np.ndarray]]]) -> int | None:
    """The nominal interval (µs) of series cut into parts ``(station, first, last, steps)`` (in
    order; ``steps`` the value counts of the steps inside the part): the steps inside the parts and
    between consecutive parts of a station, by :func:`~overbound.stats.dependence.interval_from_steps`
    (the rule of ``nominal_interval_us`` on the whole series). ``None`` without a step."""
    between = [b[1] - a[2] for a, b in itertools.pairwise(parts) if a[0] == b[0]]
    merged = merge_counts(
        *(BinCounts(*p[3]) for p in parts), BinCounts(*step_counts(np.array(between, dtype=np.int64)))
    )
    return interval_from_steps(merged.bins, merged.counts)


def axis_plan(blocks: list[BlockFirst]) -> AxisPlan:
    """Merge pass 1 of all blocks (in pooled order, those with a solution epoch)."""
    # the pooled series' interval: pooling._interval_us's rule
    dt = interval_across([(b.station, b.first, b.last, b.steps) for b in blocks]) or 1_000_000
    stations: dict[object, list[int]] = {}
    for b in blocks:
        span = stations.setdefault(b.station, [b.first, b.last])
        span[1] = b.last
    offs = pooled_offsets(*(np.array(v, dtype=np.int64) for v in zip(*stations.values(), strict=True)), dt)
    shift_of = {s: int(o) - span[0] for (s, span), o in zip(stations.items(), offs, strict=True)}
    shift = tuple(shift_of[b.station] for b in blocks)
    counts = np.array([b.n_fit for b in blocks], dtype=np.int64)
    n = int(counts.sum())
    fit_offset = tuple(int(c) for c in np.cumsum(counts) - counts)
    fitted = [(b, s) for b, s in zip(blocks, shift, strict=True) if b.n_fit]
    t0 = fitted[0][0].first_fit + fitted[0][1] if fitted else 0
    size = (fitted[-1][0].last_fit + fitted[-1][1] - t0 + dt // 2) // dt + 1 if fitted else 0
    step = max(1, -(-size // ACF_MAX_SLOTS))
    log_sum = add_in_order(b.log_sum for b in blocks)
    ymax = max(b.log_max for b in blocks)
    return AxisPlan(
        n=n,
        n_alert=sum(b.n_alert for b in blocks),
        n_solution=sum(b.n_solution for b in blocks),
        n_stations=len(stations),
        mean=add_in_order(b.ratio_sum for b in blocks) / n if n else math.nan,
        ratio_squares=add_in_order(b.ratio_squares for b in blocks),
        varies=max(b.ratio_max for b in blocks) > min(b.ratio_min for b in blocks),
        ymax=ymax,
        spread=ymax - log_sum / n if n else math.nan,
        log_varies=min(b.log_min for b in blocks) < ymax,
        stride=weibull_start_stride(n),
        fit_offset=fit_offset,
        shift=shift,
        dt=int(dt),
        t0=int(t0),
        size=int(size),
        step=int(step),
        pl_range=(min(b.pl_min for b in blocks), max(b.pl_max for b in blocks)),
        at_or_above=sum(b.at_or_above for b in blocks),
    )


@dataclass(frozen=True, slots=True)
class BlockSecond:
    """Pass 2 of one block: :math:`\\sum (r - \\bar r)^2`, its values of the Weibull start sample
    (``ln PL - ymax``), and its slots of the ACF subsample (index ``k // step``) with the ratio
    series (``r``, or ``r^2`` in the horizontal) and the PL there."""

    squared_deviations: float
    start: np.ndarray
    slot: np.ndarray
    ratio_series: np.ndarray
    pl: np.ndarray


def block_second(block: FittedBlock, plan: AxisPlan, index: int, axis: str) -> BlockSecond:
    """Pass 2 of block ``index`` (its position in pooled order) of ``axis``."""
    r, x = block.ratio, block.pl
    first = (-plan.fit_offset[index]) % plan.stride
    start = np.log(x[first :: plan.stride])
    start -= plan.ymax
    k = block.t_fit + (plan.shift[index] - plan.t0 + plan.dt // 2)
    k //= plan.dt
    on = np.flatnonzero(k % plan.step == 0)
    series = r[on] if axis == "vertical" else np.square(r[on])
    return BlockSecond(squared_deviations(r, plan.mean), start, k[on] // plan.step, series, x[on])


@dataclass(frozen=True, slots=True)
class SecondInputs:
    """Pass 2 merged: :math:`\\sum (r - \\bar r)^2`, the Weibull start sample, and the ACF
    subsamples of the ratio series and of the PL (NaN in empty slots; two epochs in one slot keep
    the larger value, as ``regular_series``)."""

    squared_deviations: float
    start: np.ndarray
    ratio_sub: np.ndarray
    pl_sub: np.ndarray


def second_inputs(parts: list[BlockSecond], plan: AxisPlan) -> SecondInputs:
    """Merge pass 2 of all blocks, given in pooled order."""
    n_sub = (plan.size - 1) // plan.step + 1 if plan.size else 0
    slot = np.concatenate([p.slot for p in parts]) if parts else np.empty(0, dtype=np.int64)
    subs = []
    for name in ("ratio_series", "pl"):
        out = np.full(n_sub, np.nan)
        values = np.concatenate([getattr(p, name) for p in parts]) if parts else np.empty(0)
        if slot.size > 1 and np.any(slot[1:] == slot[:-1]):
            np.fmax.at(out, slot, values)
        else:
            out[slot] = values
        subs.append(out)
    return SecondInputs(
        add_in_order(p.squared_deviations for p in parts),
        np.concatenate([p.start for p in parts]) if parts else np.empty(0),
        *subs,
    )


def block_profile(block: FittedBlock, ymax: float, b: float) -> np.ndarray:
    """The block's :func:`~overbound.stats.parametric.weibull_profile_sums` at ``b``."""
    v = np.log(block.pl)
    v -= ymax
    return weibull_profile_sums(v, b)


def block_information(block: FittedBlock, fit: WeibullFit) -> np.ndarray:
    """The block's :func:`~overbound.stats.parametric.weibull_information_sums` at ``fit``."""
    return weibull_information_sums(np.log(block.pl), fit)
