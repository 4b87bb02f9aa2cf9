r"""The EVT tail extrapolation's input, reduced station-day by station-day and merged exactly.

:func:`~overbound.methods.tail_extrapolation.tail_analysis` needs far less than the pooled epoch
table: the count of the analysed epochs, a few quantiles of the safety index (SI), its
autocorrelation up to an hour, the epochs above the dependence level :math:`u_0` (the 0.99 quantile:
1 % of them) with their times and which services' HMI filters keep them, the daily maxima, and the
SI of the epochs at least the decorrelation time apart around the largest (the KRS input). All of
it is gathered from the *blocks* of the pooled series (its station-days, the partitions of a
campaign dataset) in three passes, and is equal to the last bit whether the blocks come from one
table in memory (:func:`table_tail_data`) or from the partitions of a dataset
(:mod:`overbound.campaign`):

1. :func:`tail_first` per block: counts, the time steps (the sampling interval), the first and
   last times (the stations' places on the pooled axis, :func:`~overbound.methods.pooling.pool_epochs`),
   the SI's bins (:mod:`overbound.stats.mergeable`: exact quantiles), its maximum, the daily
   maximum, the first alert of each HMI filter (the TTA of the block before). :func:`tail_plan`
   merges them into what pass 2 needs.
2. :func:`tail_second` per block, with the block before it (its last hour): the SI values in the
   quantiles' bins, the lagged sums of the SI on its regular grid (:mod:`overbound.stats.lagged`:
   integers, merged exactly in any order), the epochs above the lower edge of the 0.99 quantile's
   bin with their pooled times and positions, and per service its HMI filter over them and its
   counts. :func:`tail_data` finishes: the quantiles, the ACF, the exceedances of :math:`u_0`.
3. The KRS selection (:func:`station_walks`, :func:`walk_station`), once the decorrelation time
   is known: the greedy chain of :func:`~overbound.stats.dependence.select_spaced` walked block by
   block, a station at a time (stations are a day apart on the pooled axis, more than any spacing
   used, so each station's chain starts afresh: forward from its first epoch after the station of the largest
   SI, backward from its last before it, both ways from the largest SI in its own station).

Every partial merges by concatenation in block order or by integer addition; none adds floats.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import polars as pl

from overbound.io.schema import InputError, as_numpy
from overbound.methods.pooling import PE_PL, pooled_offsets
from overbound.stats.dependence import interval_from_steps, one_over_e_time, select_spaced, step_counts
from overbound.stats.lagged import LaggedSums, acf_from_sums, fixed_point_bits, lagged_sums, merge_lagged
from overbound.stats.mergeable import (
    BinCounts,
    bin_counts,
    exact_percentile,
    merge_counts,
    rank_bins,
    value_range,
    values_in_bins,
)

__all__ = [
    "ACF_MAX_LAG_S",
    "DEPENDENCE_QUANTILE",
    "SI_LEVELS",
    "Block",
    "ChainWalk",
    "Filter",
    "TailData",
    "TailFirst",
    "TailPlan",
    "TailSecond",
    "Walk",
    "anchor",
    "axis_block",
    "concat_by_axis",
    "hmi_keep",
    "krs_spacing",
    "merge_tail_first",
    "merge_tail_second",
    "station_walks",
    "table_tail_data",
    "tail_data",
    "tail_first",
    "tail_plan",
    "tail_second",
    "walk_station",
]

#: Quantile of SI whose exceedances give the V_K curve and the clusters (Veerman et al., 3.2).
DEPENDENCE_QUANTILE = 0.99
#: Longest lag of the SI autocorrelation (s).
ACF_MAX_LAG_S = 3600.0
#: The SI quantiles reported.
SI_LEVELS = (0.5, 0.9, 0.99, 0.999, 0.9999)

#: An HMI filter (section 3.6): the alert limit (``None``: none) and the TTA (s). ``(None, 0.0)``
#: keeps every epoch without the ``alert`` flag.
Filter = tuple[float | None, float]
_NEVER = np.iinfo(np.int64).max


@dataclass(frozen=True)
class Block:
    """The solution epochs (finite PE, PL > 0) of one axis of a station-day, in time order.

    ``t`` in µs (GPS time, or already on the pooled axis), ``pe`` the absolute error, ``n_rows``
    the rows of the station-day, solution or not."""

    t: np.ndarray
    pe: np.ndarray
    pl: np.ndarray
    alert: np.ndarray
    n_rows: int


def axis_block(table: pl.DataFrame, axis: str) -> Block:
    """The :class:`Block` of ``axis`` of one station-day of the epoch table."""
    pe_col, pl_col = PE_PL[axis]
    pe = np.abs(as_numpy(table[pe_col]).astype(np.float64, copy=False))
    pls = as_numpy(table[pl_col]).astype(np.float64, copy=False)
    ok = np.isfinite(pe) & np.isfinite(pls) & (pls > 0)
    t = as_numpy(table["time"]).astype(np.int64, copy=False)
    alert = (
        as_numpy(table["alert"].fill_null(False)).astype(bool)
        if "alert" in table.columns
        else np.zeros(t.size, dtype=bool)
    )
    return Block(t[ok], pe[ok], pls[ok], alert[ok], table.height)


def hmi_keep(b: Block, f: Filter, next_alert: int | None) -> tuple[np.ndarray, int, int, int]:
    """The epochs an HMI filter keeps (section 3.6) and its counts ``(n_alert, n_above, n_tta)``:
    not alerted; with an alert limit, PL < AL and not in the TTA before the next alert (PL >= AL
    or the flag), ``next_alert`` being the first one after the block (µs, ``None``: none)."""
    al, tta_s = f
    keep = ~b.alert
    n_alert = int(b.alert.sum())
    if al is None:
        return keep, n_alert, 0, 0
    above = b.pl >= al
    n_above = int(np.count_nonzero(above & ~b.alert))
    alerts = above | b.alert
    keep = keep & ~above
    # the next alert strictly after each epoch: a reversed running minimum, the next block's included
    after = np.append(np.where(alerts, b.t, _NEVER), _NEVER if next_alert is None else next_alert)
    nxt = np.minimum.accumulate(after[::-1])[::-1][1:]
    ahead = np.where(nxt < _NEVER, nxt - b.t, _NEVER)
    tta = keep & (ahead <= round(tta_s * 1e6))
    return keep & ~tta, n_alert, n_above, int(tta.sum())


def _analysed(b: Block, label: str, plan: TailPlan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The block's epochs the main filter keeps: the mask, their pooled times (µs) and SI."""
    shift = plan.shift.get(label, 0)
    nxt = plan.next_alert.get(label, (None,))[0]
    keep, *_ = hmi_keep(b, plan.filters[0], None if nxt is None else nxt - shift)
    return keep, b.t[keep] + shift, b.pe[keep] / b.pl[keep]


def _first_alert(b: Block, f: Filter) -> int | None:
    """The first epoch of the block that the filter's TTA counts back from."""
    al = f[0]
    if al is None:
        return None
    hit = np.flatnonzero((b.pl >= al) | b.alert)
    return int(b.t[hit[0]]) if hit.size else None


# --------------------------------------------------------------------------------------------------
# pass 1


@dataclass(frozen=True)
class BlockFirst:
    """What pass 1 keeps of one block (a few numbers)."""

    station: str
    label: str
    n_rows: int
    n_solution: int
    counts: tuple[int, int, int, int]  # the main filter's n_alert, n_above, n_tta, n_used
    first: int | None  # solution epochs' first and last time
    last: int | None
    kept_first: int | None  # the analysed epochs' first and last time
    kept_last: int | None
    si_max: float
    si_argmax: int  # its position among the block's analysed epochs
    n_mi: int
    alerts: tuple[int | None, ...]  # first alert of each filter (the main one first)


@dataclass(frozen=True)
class TailFirst:
    """Pass 1 of blocks in order: their :class:`BlockFirst`, and the SI bins and time steps merged."""

    blocks: tuple[BlockFirst, ...]
    bins: BinCounts
    steps: BinCounts  # the positive time steps within the blocks (µs) and how often each occurs


def tail_first(
    b: Block, station: str, label: str, filters: Sequence[Filter], next_alert: int | None = None
) -> TailFirst:
    """Pass 1 of one block; ``filters[0]`` the main one, ``next_alert`` its first alert after the
    block (only a main filter with an alert limit needs it)."""
    keep, n_alert, n_above, n_tta = hmi_keep(b, filters[0], next_alert)
    si = b.pe[keep] / b.pl[keep]
    kt = b.t[keep]
    n = int(b.t.size)
    first = BlockFirst(
        station,
        label,
        b.n_rows,
        n,
        (n_alert, n_above, n_tta, int(si.size)),
        int(b.t[0]) if n else None,
        int(b.t[-1]) if n else None,
        int(kt[0]) if kt.size else None,
        int(kt[-1]) if kt.size else None,
        float(si.max()) if si.size else -math.inf,
        int(np.argmax(si)) if si.size else -1,
        int(np.count_nonzero(si > 1.0)),
        tuple(_first_alert(b, f) for f in filters),
    )
    return TailFirst((first,), bin_counts(si), BinCounts(*step_counts(np.diff(b.t))))


def merge_tail_first(*parts: TailFirst) -> TailFirst:
    """Pass-1 partials of consecutive blocks, in order."""
    return TailFirst(
        tuple(b for p in parts for b in p.blocks),
        merge_counts(*(p.bins for p in parts)),
        merge_counts(*(p.steps for p in parts)),
    )


# --------------------------------------------------------------------------------------------------
# the plan of pass 2


@dataclass(frozen=True)
class TailPlan:
    """What pass 2 needs, from the merged pass 1.

    ``shift`` maps a block's times onto the pooled axis (add it); ``origin`` is the pooled time of
    the first analysed epoch (slot 0 of the regular grid); ``prev`` names each block's block of
    the day before when that exists (its last hour pairs with this block's first);
    ``drop_last``: blocks whose last slot is shared with the next block's first (the next block
    holds it); ``next_alert``: per block, each filter's first alert in the next block of its
    station (pooled µs). ``quantiles``: per level, the rank bins and the count below them.
    """

    filters: tuple[Filter, ...]
    dt_us: int
    shift: dict[str, int]
    origin: int
    n_slots: int
    max_lag: int
    bits: int
    n_used: int
    quantiles: dict[float, tuple[np.ndarray, int]]
    exceed_from: float  # exceedances are collected above this (the level's bin edge, or the level)
    level: float | None  # the given threshold, or None: the 0.99 quantile
    prev: dict[str, str | None]
    drop_last: frozenset[str]
    next_alert: dict[str, tuple[int | None, ...]]
    first: TailFirst = field(repr=False)


def _steps(first: TailFirst) -> BinCounts:
    """The time steps of the pooled series: those within blocks and between consecutive blocks
    of a station."""
    extra = [
        b.first - a.last
        for a, b in zip(first.blocks, first.blocks[1:], strict=False)
        if a.station == b.station and a.last is not None and b.first is not None
    ]
    return merge_counts(first.steps, BinCounts(*step_counts(np.array(extra, dtype=np.int64))))


def _stations(blocks: Sequence[BlockFirst]) -> dict[str, list[BlockFirst]]:
    out: dict[str, list[BlockFirst]] = {}
    for b in blocks:
        if b.n_solution:
            out.setdefault(b.station, []).append(b)
    return out


def tail_plan(first: TailFirst, filters: Sequence[Filter], threshold: float | None = None) -> TailPlan:
    """The plan of pass 2 (``threshold``: a given one instead of the 0.99 quantile).

    Raises
    ------
    InputError
        Fewer than 3 analysed epochs.
    """
    blocks = first.blocks
    n_used = sum(b.counts[3] for b in blocks)
    if n_used < 3:
        raise InputError("<epoch table>", f"only {n_used} epochs left to analyse")
    steps = _steps(first)
    dt = interval_from_steps(steps.bins, steps.counts) or 1_000_000
    stations = _stations(blocks)
    offs = pooled_offsets(
        np.array([s[0].first for s in stations.values()], dtype=np.int64),
        np.array([s[-1].last for s in stations.values()], dtype=np.int64),
        dt,
    )
    shift = {b.label: int(o) - s[0].first for o, s in zip(offs, stations.values(), strict=True) for b in s}
    kept = [b for b in blocks if b.counts[3] and b.label in shift]
    origin = kept[0].kept_first + shift[kept[0].label]
    last = kept[-1].kept_last + shift[kept[-1].label]
    n_slots = (last - origin + dt // 2) // dt + 1
    max_lag = int(min(round(ACF_MAX_LAG_S / (dt / 1e6)), n_slots - 1))
    si_max = max(b.si_max for b in kept)
    levels = (*SI_LEVELS, DEPENDENCE_QUANTILE)
    quantiles = {q: rank_bins(first.bins, q, scale=1) for q in levels}
    exceed_from = value_range(quantiles[DEPENDENCE_QUANTILE][0])[0] if threshold is None else threshold

    def slot(t: int, label: str) -> int:
        return (t + shift[label] - origin + dt // 2) // dt

    prev, drop, nxt = {}, set(), {}
    for s in stations.values():
        for a, b in zip([None, *s], s, strict=False):
            # any pair at most max_lag slots apart (slots round to the nearest: one more of slack)
            adjacent = a is not None and (b.first - a.last) < (max_lag + 2) * dt
            prev[b.label] = a.label if adjacent else None
        for a, b in zip(s, [*s[1:], None], strict=True):
            after = (None,) * len(filters) if b is None else b.alerts
            nxt[a.label] = tuple(None if t is None else t + shift[b.label] for t in after)
            if b is not None and a.counts[3] and b.counts[3]:
                if slot(a.kept_last, a.label) == slot(b.kept_first, b.label):
                    drop.add(a.label)
    return TailPlan(
        tuple(filters),
        int(dt),
        shift,
        int(origin),
        int(n_slots),
        max_lag,
        fixed_point_bits(n_used, si_max),
        n_used,
        quantiles,
        float(exceed_from),
        threshold,
        prev,
        frozenset(drop),
        nxt,
        first,
    )


# --------------------------------------------------------------------------------------------------
# pass 2


@dataclass(frozen=True)
class TailSecond:
    """Pass 2 of blocks in order.

    ``values``: SI in the quantiles' bins (one array per level of :attr:`TailPlan.quantiles`);
    ``sums``: lagged sums; ``t``, ``x``: the epochs with SI above :attr:`TailPlan.exceed_from` that
    the main filter or a service's keeps (pooled µs, SI); ``main``: those the main filter keeps,
    ``position`` their index among its analysed epochs; per service filter (``filters[1:]``):
    ``keep`` over them, ``service_position`` among that filter's epochs, and its counts
    ``(n_alert, n_above, n_tta, n_used)``; ``n_used`` the main filter's analysed epochs (the
    offset of the next blocks' positions).

    Positions are kept within their block, as int32 (a station-day has far fewer than 2**31 epochs):
    ``block_candidates`` the epochs of each block, ``offsets`` (one row per block) the block's first
    position in the main series, then in each service's. :meth:`positions` gives them pooled (int64).
    Half the bytes of pooled int64 positions, which were 314 of the 466 MiB of both axes' candidates
    of 10 station-years in the driver (measured).
    """

    values: tuple[np.ndarray, ...]
    sums: LaggedSums | None
    t: np.ndarray
    x: np.ndarray
    main: np.ndarray
    position: np.ndarray
    n_used: int
    keep: tuple[np.ndarray, ...]
    service_position: tuple[np.ndarray, ...]
    service_counts: tuple[tuple[int, int, int, int], ...]
    block_candidates: np.ndarray
    offsets: np.ndarray

    def positions(self, j: int = 0) -> np.ndarray:
        """The pooled positions of the candidates: in the main series (``j = 0``) or in the series of
        service filter ``j`` (1 for ``filters[1]``...)."""
        local = self.position if j == 0 else self.service_position[j - 1]
        return local.astype(np.int64) + np.repeat(self.offsets[:, j], self.block_candidates)


def _grid(t: np.ndarray, si: np.ndarray, plan: TailPlan) -> tuple[int, np.ndarray]:
    """The block's analysed epochs on the regular grid: its first slot and the values of its
    slots (the larger one where two epochs share a slot, as ``regular_series``)."""
    dt = plan.dt_us
    k = (t - plan.origin + dt // 2) // dt
    out = np.full(int(k[-1] - k[0]) + 1, np.nan)
    if k.size > 1 and np.any(k[1:] == k[:-1]):
        np.fmax.at(out, k - k[0], si)
    else:
        out[k - k[0]] = si
    return int(k[0]), out


def tail_second(b: Block, label: str, plan: TailPlan, before: Block | None = None) -> TailSecond:
    """Pass 2 of one block; ``before``: the block of the day before (:attr:`TailPlan.prev`)."""
    shift = plan.shift.get(label, 0)
    nxt = plan.next_alert.get(label, (None,) * len(plan.filters))
    keep, t, si = _analysed(b, label, plan)
    values = tuple(values_in_bins(si, bins) for bins, _ in plan.quantiles.values())
    sums = None
    if si.size:
        k0, grid = _grid(t, si, plan)
        if label in plan.drop_last:
            grid = grid[:-1]
        head = None
        if before is not None and plan.prev.get(label):
            head = _before(before, plan, plan.prev[label], k0, grid)
        sums = lagged_sums(grid, plan.max_lag, plan.bits, head) if grid.size else None
    # the candidates: epochs above the level's bin that the main filter or a service's keeps (a
    # service need not keep a subset of the main filter's epochs)
    si_all = b.pe / b.pl
    any_keep = keep.copy()
    kept = []
    for j, f in enumerate(plan.filters[1:], start=1):
        ks, n_alert, n_above, n_tta = hmi_keep(b, f, None if nxt[j] is None else nxt[j] - shift)
        kept.append((ks, (n_alert, n_above, n_tta, int(ks.sum()))))
        any_keep |= ks
    idx = np.flatnonzero(any_keep & (si_all > plan.exceed_from))
    return TailSecond(
        values,
        sums,
        b.t[idx] + shift,
        si_all[idx],
        keep[idx],
        _local_positions(keep, idx),
        int(si.size),
        tuple(ks[idx] for ks, _ in kept),
        tuple(_local_positions(ks, idx) for ks, _ in kept),
        tuple(c for _, c in kept),
        np.array([idx.size], dtype=np.int64),
        np.zeros((1, 1 + len(kept)), dtype=np.int64),
    )


def _local_positions(keep: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """The index of epochs ``idx`` among the block's epochs ``keep`` keeps (int32: one block)."""
    if keep.size >= 2**31:
        raise ValueError(f"a block of {keep.size} epochs: positions within a block are int32")
    return (np.cumsum(keep, dtype=np.int32) - 1)[idx]


def _before(prev: Block, plan: TailPlan, label: str, k0: int, grid: np.ndarray) -> np.ndarray:
    """The values of the ``max_lag`` slots before slot ``k0`` from the block before; a slot the
    two blocks share is merged into ``grid`` (its first value) with the larger value."""
    _, t, si = _analysed(prev, label, plan)
    head = np.full(plan.max_lag, np.nan)
    if not t.size:
        return head
    dt = plan.dt_us
    k = (t - plan.origin + dt // 2) // dt
    if k[-1] == k0:  # the shared slot (left out of the block before by drop_last)
        grid[0] = np.fmax(grid[0], si[k == k0].max())
    near = (k < k0) & (k >= k0 - plan.max_lag)
    np.fmax.at(head, k[near] - (k0 - plan.max_lag), si[near])
    return head


def merge_tail_second(*parts: TailSecond) -> TailSecond:
    """Pass-2 partials of consecutive blocks, in order (positions offset by the blocks before)."""
    n_services = len(parts[0].keep)
    # each part's series lengths (main, then services'): the offsets of the parts after it
    used = np.array([[p.n_used, *(c[3] for c in p.service_counts)] for p in parts], dtype=np.int64)
    shift = np.cumsum(used, axis=0) - used
    sums = [p.sums for p in parts if p.sums is not None]
    return TailSecond(
        tuple(np.concatenate(v) for v in zip(*(p.values for p in parts), strict=True)),
        merge_lagged(*sums) if sums else None,
        np.concatenate([p.t for p in parts]),
        np.concatenate([p.x for p in parts]),
        np.concatenate([p.main for p in parts]),
        np.concatenate([p.position for p in parts]),
        int(sum(p.n_used for p in parts)),
        tuple(np.concatenate([p.keep[j] for p in parts]) for j in range(n_services)),
        tuple(np.concatenate([p.service_position[j] for p in parts]) for j in range(n_services)),
        tuple(
            tuple(int(sum(p.service_counts[j][i] for p in parts)) for i in range(4))
            for j in range(n_services)
        ),
        np.concatenate([p.block_candidates for p in parts]),
        np.concatenate([p.offsets + d for p, d in zip(parts, shift, strict=True)]),
    )


# --------------------------------------------------------------------------------------------------
# the result


@dataclass(frozen=True)
class TailData:
    """The reduced input of the tail extrapolation of one axis (module notes).

    Attributes
    ----------
    n_rows, n_no_solution, n_stations, interval_s : of the pooled table.
    counts : the main filter's ``(n_alert, n_above, n_tta, n_used)``.
    level : :math:`u_0`, the 0.99 quantile of SI (or the given threshold).
    quantiles : SI at :data:`SI_LEVELS`.
    si_max, n_mi : the largest SI and the number above 1.
    acf : autocorrelation of SI on the regular grid, lags 0 to :data:`ACF_MAX_LAG_S`.
    t_s, x : the epochs with SI above ``level`` that the main filter or a service's keeps (pooled
        s, SI); ``main``: those of the main series, ``position`` their index in it.
    block_max, block_size : the largest SI and the analysed epochs of each station-day.
    services : per service filter, ``(keep over t_s and x, positions in its series, counts)``.
    spaced : ``spaced(spacing)`` gives the SI of the greedy selection at least ``spacing`` s apart
        that contains the largest (:func:`~overbound.stats.dependence.select_spaced`).
    """

    n_rows: int
    n_no_solution: int
    n_stations: int
    interval_s: float
    counts: tuple[int, int, int, int]
    level: float
    quantiles: np.ndarray
    si_max: float
    n_mi: int
    acf: np.ndarray
    t_s: np.ndarray
    x: np.ndarray
    main: np.ndarray
    position: np.ndarray
    block_max: np.ndarray
    block_size: np.ndarray
    services: tuple[tuple[np.ndarray, np.ndarray, tuple[int, int, int, int]], ...]
    spaced: Callable[[float], np.ndarray] = field(repr=False, compare=False)


def tail_data(plan: TailPlan, second: TailSecond, spaced: Callable[[float], np.ndarray]) -> TailData:
    """Pass 1's plan and the merged pass 2 into :class:`TailData`."""
    blocks = plan.first.blocks
    n = plan.n_used
    quant = {
        q: exact_percentile(n, q, below, values, scale=1)
        for (q, (_, below)), values in zip(plan.quantiles.items(), second.values, strict=True)
    }
    level = quant[DEPENDENCE_QUANTILE] if plan.level is None else plan.level
    up = second.x > level
    kept = [b for b in blocks if b.counts[3]]
    return TailData(
        n_rows=sum(b.n_rows for b in blocks),
        n_no_solution=sum(b.n_rows - b.n_solution for b in blocks),
        n_stations=len(_stations(blocks)),
        interval_s=plan.dt_us / 1e6,
        counts=tuple(int(sum(b.counts[i] for b in blocks)) for i in range(4)),
        level=float(level),
        quantiles=np.array([quant[q] for q in SI_LEVELS]),
        si_max=max(b.si_max for b in kept),
        n_mi=sum(b.n_mi for b in blocks),
        acf=_acf(second.sums, plan),
        t_s=second.t[up] / 1e6,
        x=second.x[up],
        main=second.main[up],
        position=second.positions(0)[up],
        block_max=np.array([b.si_max for b in kept]),
        block_size=np.array([b.counts[3] for b in kept], dtype=np.int64),
        services=tuple(
            (k[up], second.positions(j)[up & k], c)
            for j, (k, c) in enumerate(zip(second.keep, second.service_counts, strict=True), start=1)
        ),
        spaced=spaced,
    )


def _acf(sums: LaggedSums | None, plan: TailPlan) -> np.ndarray:
    if sums is None:
        return np.full(plan.max_lag + 1, np.nan)
    return acf_from_sums(sums)


def anchor(first: TailFirst) -> tuple[str, int]:
    """The block and position of the largest SI (the first on ties, in pooled order)."""
    kept = [b for b in first.blocks if b.counts[3]]
    best = max(range(len(kept)), key=lambda i: (kept[i].si_max, -i))
    return kept[best].label, kept[best].si_argmax


# --------------------------------------------------------------------------------------------------
# pass 3: the KRS selection


class ChainWalk:
    """One station's part of the greedy selection, walked block by block (:func:`walk_station`).

    ``at``: the block and position of the largest SI (``("", 0)`` for a station without it). A
    station after the anchor's station is walked forward from its first epoch, one before it
    backward from its last, and the anchor's own station both ways from it (one walk each way):
    stations are a day apart on the pooled axis, more than any spacing, so each station's chain
    starts afresh. Per block the chain continues from the last time kept, with the comparisons of
    ``select_spaced`` (pooled seconds as float64)."""

    def __init__(self, plan: TailPlan, at: tuple[str, int], spacing: float, forward: bool) -> None:
        if spacing >= 86_400.0:
            raise ValueError(f"spacing {spacing} s: the stations' chains would not be apart")
        self.plan, self.at, self.spacing, self.forward = plan, at, float(spacing), forward
        self.last: np.float64 | None = None
        self.started = False
        self.out: list[np.ndarray] = []

    def step(self, label: str, b: Block) -> None:
        """Walk the next block (the blocks in time order forward, in reverse backward)."""
        forward, d = self.forward, np.float64(self.spacing)
        _, t_us, si = _analysed(b, label, self.plan)
        t_s = t_us / 1e6
        if not t_s.size:
            return
        if label == self.at[0]:
            start, self.started = self.at[1], True
        elif self.at[0] and not self.started:
            return  # the anchor's station, before (after) the anchor
        elif self.last is None:
            start = 0 if forward else t_s.size - 1
        elif forward:
            start = int(np.searchsorted(t_s, self.last + d, side="left"))
        else:
            start = int(np.searchsorted(t_s, self.last - d, side="right")) - 1
        if not 0 <= start < t_s.size:
            return
        if forward:
            sel = select_spaced(t_s[start:], anchor=0, spacing=self.spacing) + start
        else:
            sel = select_spaced(t_s[: start + 1], anchor=start, spacing=self.spacing)
        self.last = t_s[sel[-1]] if forward else t_s[sel[0]]
        self.out.append(si[sel])

    def values(self) -> np.ndarray:
        """The SI selected, in time order."""
        out = self.out if self.forward else self.out[::-1]
        return np.concatenate(out) if out else np.empty(0)


#: One axis's KRS walk of a station: the plan, the anchor (block label and position; ``("", 0)``
#: for a station without it), the spacing (s), and whether the walk leaves its first value out (the
#: anchor, when the walk backward from it already holds it).
Walk = tuple[TailPlan, tuple[str, int], float, bool]


def station_walks(
    names: Sequence[str],
    anchor_station: dict[str, str],
    walks: dict[str, tuple[TailPlan, tuple[str, int], float]],
) -> list[list[tuple[bool, dict[str, Walk]]]]:
    """Per station of ``names`` (in pooled order), its walks: ``(forward, {axis: Walk})``, backward
    first. ``walks``: per axis its plan, anchor and spacing; ``anchor_station``: per axis the
    station of its anchor. A station before the anchor's is walked backward, one after it forward,
    the anchor's both ways (:class:`ChainWalk`); the axes that walk a station the same way share
    the walk."""
    rank = {a: list(names).index(anchor_station[a]) for a in walks}
    out = []
    for i in range(len(names)):
        back: dict[str, Walk] = {}
        ahead: dict[str, Walk] = {}
        for a, (plan, at, spacing) in walks.items():
            mine = at if i == rank[a] else ("", 0)
            if i <= rank[a]:
                back[a] = (plan, mine, spacing, False)
            if i >= rank[a]:
                ahead[a] = (plan, mine, spacing, i == rank[a])
        out.append([(False, back)] * bool(back) + [(True, ahead)] * bool(ahead))
    return out


def walk_station(
    blocks: Iterable[tuple[str, Callable[[str], Block]]], walks: dict[str, Walk], forward: bool
) -> dict[str, np.ndarray]:
    """The SI each axis's :class:`ChainWalk` selects over a station's ``blocks`` (each a label and
    the block of an axis, in walking order: each block is got once for all axes)."""
    chains = {a: ChainWalk(plan, at, spacing, forward) for a, (plan, at, spacing, _) in walks.items()}
    for label, block_of in blocks:
        for a, walk in chains.items():
            walk.step(label, block_of(a))
    return {a: w.values()[1:] if walks[a][3] else w.values() for a, w in chains.items()}


def concat_by_axis(*parts: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per axis, the values of the walks in order (an axis absent from a walk adds nothing)."""
    axes = dict.fromkeys(a for p in parts for a in p)
    return {a: np.concatenate([p[a] for p in parts if a in p]) for a in axes}


def krs_spacing(acf: np.ndarray, interval_s: float) -> float:
    """The spacing of the KRS selection: the decorrelation time (first lag of the ACF below 1/e),
    or :data:`ACF_MAX_LAG_S` when it does not drop below within the lags examined."""
    decor = one_over_e_time(acf, interval_s)
    return decor if math.isfinite(decor) else ACF_MAX_LAG_S


# --------------------------------------------------------------------------------------------------
# one table


def _blocks_of(table: pl.DataFrame, axis: str) -> list[tuple[str, str, Block]]:
    """The station-day blocks of a table (stations in the order of their first row, days in
    order), with their station and label."""
    t = as_numpy(table["time"]).astype(np.int64, copy=False)
    frame = pl.DataFrame(
        {"station": table["station"].cast(pl.String), "day": t // 86_400_000_000, "row": np.arange(t.size)}
    )
    order = frame.with_columns(pl.col("row").min().over("station").alias("code"))  # first appearance
    order = order.sort(["code", "day"], maintain_order=True)
    groups = order.group_by(["code", "day"], maintain_order=True).agg(
        pl.col("station").first(), pl.col("row")
    )
    out = []
    for _code, day, name, rows in groups.iter_rows():  # one per station-day
        idx = np.asarray(rows, dtype=np.int64)
        sub = table[idx] if not _contiguous(idx) else table.slice(int(idx[0]), idx.size)
        sub = sub.sort("time") if sub.height > 1 and not sub["time"].is_sorted() else sub
        out.append((name, f"{name}/{day}", axis_block(sub, axis)))
    return out


def _contiguous(idx: np.ndarray) -> bool:
    return bool(idx.size) and int(idx[-1]) - int(idx[0]) + 1 == idx.size


def table_tail_data(
    table: pl.DataFrame, axis: str, filters: Sequence[Filter], threshold: float | None = None
) -> TailData:
    """:class:`TailData` of an epoch table, by the passes of a dataset over its station-days."""
    blocks = _blocks_of(table, axis)
    main = filters[0]
    nexts: list[int | None] = [None] * len(blocks)
    if main[0] is not None:  # the main filter's TTA reaches into the next block of the station
        for i in range(len(blocks) - 1):
            if blocks[i][0] == blocks[i + 1][0]:
                nexts[i] = _first_alert(blocks[i + 1][2], main)
    first = merge_tail_first(
        *(tail_first(b, s, label, filters, n) for (s, label, b), n in zip(blocks, nexts, strict=True))
    )
    plan = tail_plan(first, filters, threshold)
    by_label = {label: b for _, label, b in blocks}
    second = merge_tail_second(
        *(tail_second(b, label, plan, by_label.get(plan.prev.get(label) or "")) for _, label, b in blocks)
    )
    at = anchor(first)
    stations: dict[str, list[tuple[str, Block]]] = {}
    for name, label, b in blocks:
        stations.setdefault(name, []).append((label, b))
    station_of_anchor = next(name for name, label, _ in blocks if label == at[0])

    def spaced(spacing: float) -> np.ndarray:
        groups = station_walks(list(stations), {axis: station_of_anchor}, {axis: (plan, at, spacing)})
        parts = []
        for seq, walks in zip(stations.values(), groups, strict=True):
            for forward, w in walks:
                items = seq if forward else seq[::-1]
                parts.append(walk_station(((label, lambda _a, b=b: b) for label, b in items), w, forward))
        return concat_by_axis(*parts)[axis]

    return tail_data(plan, second, spaced)
