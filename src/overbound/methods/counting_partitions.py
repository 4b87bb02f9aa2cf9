"""The counting KPIs of an epoch table split into partitions (station-days), merged exactly.

:func:`~overbound.methods.counting.count_kpis` needs the whole table in memory. A campaign of
many station-years is instead read one partition at a time (one station, one GPS day), each
reduced to a small partial result; the partials merge, and the merged result is finalized into
the same :class:`~overbound.methods.counting.CountingResult`, equal to ``count_kpis`` of the
pooled table: counts identical, probabilities and percentiles to the last bit. Two passes:

1. :func:`first_pass` per partition: epoch and region counts, available epochs per mask, the
   Stanford histograms, the safety-index maximum with its epoch, the time steps' value counts,
   the first and last epoch, the bin counts of the percentile variables
   (:mod:`overbound.stats.mergeable`) and the per-day counts. Partials merge by
   :func:`merge_first` (associative; order kept, so ties resolve as in one table).
   Pass 1 also counts the continuity windows that lie inside the partition, and keeps the grid
   slots at its two ends, on the grid of its own first epoch and interval (a :class:`Guess`).
2. :func:`plan_second` finds, from the merged first pass, each station's time grid (the
   nominal interval of all its steps, day boundaries included, and its first epoch: the grid
   of :func:`~overbound.stats.dependence.slot_grid` on the whole station) and the bins holding
   each percentile's order statistics. :func:`second_pass` per partition takes the values in
   those bins, and counts the windows again only where the partition's guess does not hold (its
   grid differs from its station's, or it shares a slot with the next partition);
   :func:`merge_second` gathers them.
3. :func:`finalize` counts the windows that cross partition boundaries from the kept end
   slots (a window that crosses midnight is counted once, with the slots of the next day and
   any gap between), and computes the exact percentiles.

Choices
-------
- Two epochs of one station may fall in the same grid slot on either side of a partition
  boundary (time-tag jitter at midnight). In one table the later one sets the slot's state
  (numpy's fancy assignment, last write wins); here the earlier partition is told by the plan
  to leave that slot to the next (``drop_last``), which gives the same slot states. Its epochs
  still count in ``n_off_grid``.
- Percentile variables: HPE and |VPE| over epochs with a solution (HPE95, |VPE|95), and the
  safety index of each axis (its :data:`~overbound.methods.counting.SAFETY_PERCENTILES`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import polars as pl

from overbound.methods.counting import (
    AXES,
    SAFETY_PERCENTILES,
    CountingResult,
    SafetyIndex,
    StanfordCounts,
    StanfordHistogram,
    _counts,
    _iso,
    availability_mask,
    continuity_keys,
    continuity_result,
    epoch_arrays,
    histogram_keys,
    no_grid_continuity,
    safety_values,
    service_kpi,
    stanford_histogram,
    sum_continuity,
    window_slots,
)
from overbound.methods.evidence import (
    GAP_S,
    Evidence,
    EvidenceDraft,
    EvidencePart,
    draft_evidence,
    evidence_part,
)
from overbound.services import ServiceLevel
from overbound.stats.dependence import interval_from_steps, prefix_counts, step_counts
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
    "FirstPass",
    "PartitionWindows",
    "SecondPass",
    "SecondPlan",
    "count_partitioned",
    "daily_availability",
    "finalize",
    "first_pass",
    "merge_first",
    "merge_second",
    "plan_second",
    "second_pass",
    "second_values",
    "second_windows",
    "station_targets",
]

#: The percentile variable of each axis's error (the evidence's accuracy bounds).
ERROR_VARIABLE = {"horizontal": "hpe", "vertical": "vpe"}
#: The percentile variables and their percentiles.
PERCENTILES: dict[str, tuple[float, ...]] = {
    "hpe": (95.0,),
    "vpe": (95.0,),
    "si_horizontal": SAFETY_PERCENTILES,
    "si_vertical": SAFETY_PERCENTILES,
}
_DAY_US = 86_400_000_000


# --------------------------------------------------------------------------------------------------
# pass 1


@dataclass
class Edge:
    """The grid slots at the two ends of one partition: ``a``/``b`` its first and last slot;
    ``head``/``tail`` the slots ``[a, a+W)`` and ``(b-W, b]`` (clipped to the partition): whether
    each holds an epoch (``present``, ``W`` the most slots of any window) and whether that epoch is
    available, per mask key (``up``, ``W`` the most slots of that key's windows)."""

    a: int
    b: int
    head_present: np.ndarray
    tail_present: np.ndarray
    head_up: dict[tuple, np.ndarray]
    tail_up: dict[tuple, np.ndarray]

    def shifted(self, m: int) -> Edge:
        """The same slots numbered ``m`` further (another origin of the same grid)."""
        return Edge(self.a + m, self.b + m, self.head_present, self.tail_present, self.head_up, self.tail_up)


@dataclass
class PartitionWindows:
    """The continuity windows of one partition: off-grid epochs, the windows that lie inside it
    (``[n, n_fail, n_gap]`` per ``(key, window)``), and its :class:`Edge` (``None``: no slot)."""

    n_off_grid: int
    windows: dict[tuple, np.ndarray]
    edge: Edge | None


@dataclass
class Guess:
    """A partition's windows counted in pass 1 on the grid of its own first epoch ``t0`` and
    nominal interval ``dt`` (µs). When the station's grid has the same interval and a phase
    that differs by whole intervals (regular data), they are the station's windows, the slots
    renumbered; otherwise pass 2 counts them again."""

    t0: int
    dt: int
    windows: PartitionWindows


@dataclass
class StationFirst:
    """Pass-1 partial of one station over one or more of its partitions (in time order).

    ``spans``: first and last epoch (µs) of each partition, ``labels`` the caller's names of
    them (unique), ``guesses`` their continuity windows counted on their own grid
    (:class:`Guess`); ``steps``: value counts of the time steps inside partitions;
    ``n_available`` and ``regions`` per :func:`continuity_keys` key (regions as the six
    :class:`StanfordCounts` fields); ``si_max`` per axis ``(value, time)``; ``bins`` per
    percentile variable; ``days``: per GPS day number, epochs and available epochs per
    combined key.
    """

    spans: list[tuple[int, int]]
    labels: list[str]
    guesses: list[Guess | None]
    steps: tuple[np.ndarray, np.ndarray]
    n_total: int
    n_ok: int
    n_available: dict[tuple, int]
    regions: dict[tuple, np.ndarray]
    si_n: dict[str, int]
    si_max: dict[str, tuple[float, int] | None]
    bins: dict[str, BinCounts]
    days: dict[int, np.ndarray]


@dataclass
class FirstPass:
    """Pass-1 partial of a set of partitions: per station, plus the network's histograms
    (sparse flat bin indices and counts, and the clipped count, per histogram key)."""

    stations: dict[str, StationFirst]
    histograms: dict[tuple[str, float], tuple[np.ndarray, np.ndarray, int]] = field(default_factory=dict)


def _percentile_values(x, safety: dict[str, tuple[np.ndarray, np.ndarray]]) -> dict[str, np.ndarray]:
    """The values of each percentile variable (as :func:`count_kpis` and :func:`safety_index`);
    ``safety`` is :func:`~overbound.methods.counting.safety_values` of each axis."""
    out = {"hpe": x.pe["horizontal"][x.ok], "vpe": x.pe["vertical"][x.ok]}
    for axis in AXES:
        out[f"si_{axis}"] = safety[axis][1]
    return out


def _safety(x) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    return {axis: safety_values(x.pe[axis], x.si_pls[axis]) for axis in AXES}


def _station_of(table: pl.DataFrame) -> str:
    """The station of a partition table (one station: checked on the first and last rows, the
    table being sorted by station)."""
    st = table["station"]
    first, last = st[0], st[-1]
    if first != last:
        raise ValueError(f"a partition holds one station, got {first!r} and {last!r}")
    return str(first)


def first_pass(
    table: pl.DataFrame, services: Sequence[ServiceLevel], *, histogram_bins: int = 200, label: str = ""
) -> FirstPass:
    """Pass 1 on one partition: a table of one station, sorted by time (empty: no station);
    ``label`` names the partition in :attr:`StationFirst.labels`."""
    if table.is_empty():
        return FirstPass({}, {})
    x = epoch_arrays(table)
    keys = continuity_keys(services)
    masks = {k: availability_mask(x.pls, k) for k in keys}
    no_sol = {a: np.isnan(x.pe[a]) | np.isnan(x.pls[a]) for a in AXES}
    above = {a: x.pe[a] > x.pls[a] for a in AXES}
    regions = {
        k: np.array(dataclasses.astuple(_counts(x.pe[k[0]], x.pls[k[0]], k[1], no_sol[k[0]], above[k[0]])))
        for k in keys
        if k[0] != "combined"
    }
    safety = _safety(x)
    values = _percentile_values(x, safety)
    t = x.time_us
    day = t // _DAY_US
    d0 = int(day[0])
    combined = [k for k in keys if k[0] == "combined"]
    if day[-1] == d0:  # the usual partition: one GPS day
        days = {d0: np.array([t.size] + [np.count_nonzero(masks[k]) for k in combined], dtype=np.int64)}
    else:
        per_day = np.stack(
            [np.bincount(day - d0)]
            + [np.bincount(day - d0, weights=masks[k]).astype(np.int64) for k in combined]
        )
        days = {d0 + i: per_day[:, i].astype(np.int64) for i in np.flatnonzero(per_day[0])}
    steps = step_counts(np.diff(t))
    dt = interval_from_steps(*steps)
    guess = None if dt is None else Guess(int(t[0]), dt, _windows(x, int(t[0]), dt, services, False))
    station = StationFirst(
        spans=[(int(t[0]), int(t[-1]))],
        labels=[label],
        guesses=[guess],
        steps=steps,
        n_total=table.height,
        n_ok=int(np.count_nonzero(x.ok)),
        n_available={k: int(np.count_nonzero(m)) for k, m in masks.items()},
        regions=regions,
        si_n={a: int(values[f"si_{a}"].size) for a in AXES},
        si_max={a: _si_max(t, *safety[a]) for a in AXES},
        bins={v: bin_counts(values[v]) for v in PERCENTILES},
        days=days,
    )
    hist = {}
    for key in histogram_keys(services, histogram_bins):
        h = stanford_histogram(
            x.pe[key[0]], x.pls[key[0]], axis=key[0], max_value=key[1], bins=histogram_bins
        )
        flat = h.counts.ravel()
        nz = np.flatnonzero(flat)
        hist[key] = (nz, flat[nz].astype(np.int64), h.clipped)
    return FirstPass({_station_of(table): station}, hist)


def _si_max(time_us: np.ndarray, ok: np.ndarray, si: np.ndarray) -> tuple[float, int] | None:
    """The largest safety index ``si`` of the epochs ``ok`` (the first on a tie) and its epoch."""
    if si.size == 0:
        return None
    i = int(np.argmax(si))
    return float(si[i]), int(time_us[np.flatnonzero(ok)[i]])


def _add_dicts(a: dict, b: dict) -> dict:
    out = dict(a)
    for k, v in b.items():
        out[k] = out[k] + v if k in out else v
    return out


def _later_max(a: tuple[float, int] | None, b: tuple[float, int] | None) -> tuple[float, int] | None:
    """The maximum of ``a`` (earlier in table order) and ``b``; ``a`` on a tie, as ``argmax``."""
    if a is None or (b is not None and b[0] > a[0]):
        return b
    return a


def merge_first(*parts: FirstPass) -> FirstPass:
    """The pass-1 partial of ``parts`` together, given in table order (station, then time)."""
    by_station: dict[str, list[StationFirst]] = {}
    for p in parts:
        for name, st in p.stations.items():
            by_station.setdefault(name, []).append(st)
    stations = {name: _merge_stations(sts) for name, sts in by_station.items()}
    hist: dict = {}
    for key in dict.fromkeys(k for p in parts for k in p.histograms):
        hs = [p.histograms[key] for p in parts if key in p.histograms]
        merged = merge_counts(*(BinCounts(idx, counts) for idx, counts, _ in hs))
        hist[key] = (merged.bins, merged.counts, sum(h[2] for h in hs))
    return FirstPass(stations, hist)


def _merge_stations(sts: list[StationFirst]) -> StationFirst:
    """One station's partials in time order, merged at once (one aggregation per count table)."""
    if len(sts) == 1:
        return sts[0]
    steps = merge_counts(*(BinCounts(*s.steps) for s in sts))
    best: dict[str, tuple[float, int] | None] = dict.fromkeys(AXES)
    for s in sts:
        best = {ax: _later_max(best[ax], s.si_max[ax]) for ax in AXES}
    return StationFirst(
        spans=[x for s in sts for x in s.spans],
        labels=[x for s in sts for x in s.labels],
        guesses=[x for s in sts for x in s.guesses],
        steps=(steps.bins, steps.counts),
        n_total=sum(s.n_total for s in sts),
        n_ok=sum(s.n_ok for s in sts),
        n_available=_sum_dicts(s.n_available for s in sts),
        regions=_sum_dicts(s.regions for s in sts),
        si_n=_sum_dicts(s.si_n for s in sts),
        si_max=best,
        bins={v: merge_counts(*(s.bins[v] for s in sts)) for v in PERCENTILES},
        days=_sum_dicts(s.days for s in sts),
    )


# --------------------------------------------------------------------------------------------------
# pass 2


@dataclass(frozen=True)
class SecondPlan:
    """What pass 2 needs from pass 1.

    ``grids``: per station, its first epoch and nominal interval (µs), ``None`` below two
    epochs; ``slots``: per station, the most grid slots a window holds; ``drop_last``: the
    labels of the partitions whose last slot is shared with the next; ``redo``: the labels of
    the partitions whose windows pass 2 counts (their pass-1 guess does not hold);
    ``targets``: the bins of each ``(scope, variable)`` percentile collected in pass 2 (scope: a
    station, or ``""`` for the network when it holds several), and ``below`` per percentile its
    own rank bins with the number of values below them.
    """

    grids: dict[str, tuple[int, int] | None]
    slots: dict[str, int]
    drop_last: frozenset[str]
    redo: frozenset[str]
    targets: dict[tuple[str, str], np.ndarray]
    below: dict[tuple[str, str, float], tuple[np.ndarray, int]]


def _ranks(
    counts: BinCounts, qs: Iterable[float], scale: float = 100.0
) -> dict[float, tuple[np.ndarray, int]]:
    """Per percentile ``q`` (``scale=1``: quantile) of ``qs``, the bins of its order statistics
    and the values below them (:func:`~overbound.stats.mergeable.rank_bins`)."""
    return {q: rank_bins(counts, q, scale=scale) for q in qs}


def _scopes(first: FirstPass) -> dict[str, dict[str, BinCounts]]:
    scopes = {name: st.bins for name, st in first.stations.items()}
    if len(scopes) > 1:
        scopes[""] = {v: merge_counts(*(st.bins[v] for st in first.stations.values())) for v in PERCENTILES}
    return scopes


def _max_slots(services: Sequence[ServiceLevel], dt: int) -> int:
    windows = [w for ws in continuity_keys(services).values() for w in ws]
    return max((window_slots(w, dt / 1e6) for w in windows), default=1)


def plan_second(first: FirstPass, services: Sequence[ServiceLevel]) -> SecondPlan:
    """The grids and percentile bins of pass 2, from the merged pass 1 of all partitions."""
    grids, slots, drop, redo = {}, {}, set(), set()
    for name, st in first.stations.items():
        spans = st.spans
        between = np.array([b[0] - a[1] for a, b in itertools.pairwise(spans)], dtype=np.int64)
        steps = merge_counts(BinCounts(*st.steps), BinCounts(*step_counts(between)))
        dt = interval_from_steps(steps.bins, steps.counts)
        t0 = spans[0][0]
        grids[name] = None if dt is None else (t0, dt)
        if dt is None:
            continue
        slots[name] = _max_slots(services, dt)
        for (a, b), label in zip(itertools.pairwise(spans), st.labels, strict=False):
            if _slot(a[1], t0, dt) == _slot(b[0], t0, dt):
                drop.add(label)
        for label, g in zip(st.labels, st.guesses, strict=True):
            if label in drop or g is None or g.dt != dt or (g.t0 - t0) % dt:
                redo.add(label)
    targets, below = {}, {}
    for scope, bins in _scopes(first).items():
        for var, qs in PERCENTILES.items():
            if bins[var].n == 0:
                continue
            ranks = _ranks(bins[var], qs)
            below.update({(scope, var, q): r for q, r in ranks.items()})
            margin = ERROR_MARGIN_BINS if var in ERROR_VARIABLE.values() else MARGIN_BINS
            targets[(scope, var)] = _widened(
                bins[var].bins, np.concatenate([r[0] for r in ranks.values()]), margin
            )
    return SecondPlan(grids, slots, frozenset(drop), frozenset(redo), targets, below)


#: Neighbouring bins (of those holding values) that pass 2 also collects on each side of a rank
#: bin: a re-analysis after a day was added finds its rank bins among them and can reuse it.
MARGIN_BINS = 4
#: The same for the errors' 95th percentiles: wider, so that the values collected also hold the
#: order statistics of the evidence's accuracy bounds (the quantiles at the Clopper-Pearson levels
#: around 0.95), and the pass that would collect them is not needed (:func:`bounds_from_second`):
#: 16 bins of 1/256 octave are 4.4 % of the value on each side, about 2 % of a partition's errors.
ERROR_MARGIN_BINS = 16


def _widened(present: np.ndarray, rank: np.ndarray, margin: int = MARGIN_BINS) -> np.ndarray:
    """``rank`` bins and ``margin`` of the ``present`` bins on each side of them."""
    i = np.searchsorted(present, rank)
    near = (i[:, None] + np.arange(-margin, margin + 1)).ravel()
    return np.unique(present[np.clip(near, 0, present.size - 1)])


def covers(collected: dict, plan: SecondPlan, scopes: Iterable[str]) -> bool:
    """Whether values ``collected`` by :func:`second_values` (against an earlier plan: their
    bins per ``(scope, variable)``) hold every value ``plan`` needs for ``scopes``."""
    have: dict = {}
    for (scope, var, _q), (rank, _below) in plan.below.items():
        if scope not in scopes:
            continue
        if (scope, var) not in have:
            have[(scope, var)] = set(collected.get((scope, var), np.empty(0, np.uint64)).tolist())
        if not have[(scope, var)].issuperset(rank.tolist()):
            return False
    return True


def quantile_plan(first: FirstPass, levels: Mapping[tuple[str, str], Sequence[float]]) -> SecondPlan:
    """A plan whose :func:`second_values` collect what the quantiles ``levels`` (0-1, as
    ``numpy.quantile``) of each ``(scope, variable)`` need (the bounds of the verdicts' evidence:
    levels known only once the counting is done)."""
    scopes = _scopes(first)
    targets, below = {}, {}
    for (scope, var), qs in levels.items():
        ranks = _ranks(scopes[scope][var], qs, scale=1)
        below.update({(scope, var, q): r for q, r in ranks.items()})
        targets[(scope, var)] = _widened(
            scopes[scope][var].bins, np.concatenate([r[0] for r in ranks.values()])
        )
    return SecondPlan({}, {}, frozenset(), frozenset(), targets, below)


def exact_quantiles(
    first: FirstPass, plan: SecondPlan, values: SecondPass, levels: Mapping[tuple[str, str], Sequence[float]]
) -> dict[tuple[str, str], list[float]]:
    """``numpy.quantile`` of the pooled values of each ``(scope, variable)`` at its ``levels``,
    from the values collected for :func:`quantile_plan`."""
    scopes, memo = _scopes(first), {}
    out = {}
    for (scope, var), qs in levels.items():
        n = scopes[scope][var].n
        out[(scope, var)] = [_percentile(plan, values, memo, n, scope, var, q, scale=1) for q in qs]
    return out


def _slot(t: np.ndarray | int, t0: int, dt: int):
    """The nearest grid slot (as :func:`~overbound.stats.dependence.slot_grid`)."""
    return (t - (t0 - dt // 2)) // dt


@dataclass
class SecondPass:
    """Pass-2 partial of a set of partitions: the windows of the partitions of ``plan.redo``
    by label, the values in the percentile bins, and when asked the evidence parts per station
    in time order (:func:`part_of`)."""

    windows: dict[str, PartitionWindows]
    values: dict[tuple[str, str], list[np.ndarray]]
    evidence: dict[str, list[EvidencePart]] = field(default_factory=dict)


def second_pass(
    table: pl.DataFrame,
    plan: SecondPlan,
    services: Sequence[ServiceLevel],
    *,
    label: str = "",
    evidence: bool = False,
    gap_s: float = GAP_S,
) -> SecondPass:
    """Pass 2 on one partition (the same table and label as its :func:`first_pass`): its values
    (:func:`second_values`), its windows when its label is in ``plan.redo``, and with ``evidence``
    its evidence part (:func:`part_of`)."""
    if table.is_empty():
        return SecondPass({}, {})
    windows = {label: second_windows(table, plan, services, label=label)} if label in plan.redo else {}
    parts = {}
    if evidence:
        name = _station_of(table)
        parts = {name: [part_of(table, services, station_evidence_inputs(plan, name), gap_s)]}
    return SecondPass(windows, second_values(table, plan), parts)


def second_values(
    table: pl.DataFrame, plan: SecondPlan, *, station: str | None = None
) -> dict[tuple[str, str], list[np.ndarray]]:
    """The partition's values in the percentile target bins of its station and of the network.
    With ``station`` given, the table needs only the error and PL columns (and ``alert``)."""
    name = station if station is not None else _station_of(table)
    x = epoch_arrays(table)
    values = _percentile_values(x, _safety(x))
    return {
        (scope, var): [values_in_bins(values[var], bins)]
        for (scope, var), bins in station_targets(plan, name).items()
    }


def station_targets(plan: SecondPlan, station: str) -> dict[tuple[str, str], np.ndarray]:
    """The target bins :func:`second_values` collects for a partition of ``station``: its
    station's and the network's."""
    return {k: b for k, b in plan.targets.items() if k[0] in (station, "")}


def windows_plan(plan: SecondPlan, station: str, label: str) -> tuple:
    """What :func:`second_windows` of a partition reads from the plan (its cache key): the
    station's grid and window slots, and whether it leaves its last slot to the next partition."""
    return (plan.grids.get(station), plan.slots.get(station), label in plan.drop_last)


def second_windows(
    table: pl.DataFrame, plan: SecondPlan, services: Sequence[ServiceLevel], *, label: str = ""
) -> PartitionWindows:
    """The windows of one partition on its station's grid."""
    grid = plan.grids[_station_of(table)]
    if grid is None:
        return PartitionWindows(0, {}, None)
    return _windows(epoch_arrays(table), *grid, services, label in plan.drop_last)


def _windows(x, t0: int, dt: int, services: Sequence[ServiceLevel], drop_last: bool) -> PartitionWindows:
    """Windows inside the partition and its end slots, on the grid ``(t0, dt)``; with
    ``drop_last`` its last slot is left to the next partition."""
    t = x.time_us
    k = _slot(t, t0, dt)
    off = int(np.count_nonzero(np.abs(t - k * dt - t0) > dt // 4))
    keys = continuity_keys(services)
    masks = {key: availability_mask(x.pls, key) for key in keys}
    if drop_last:  # the next partition sets the shared slot
        keep = k != k[-1]
        k = k[keep]
        masks = {key: m[keep] for key, m in masks.items()}
    if k.size == 0:
        return PartitionWindows(off, {}, None)
    a, b = int(k[0]), int(k[-1])
    size = b - a + 1
    # one epoch in every slot (the usual day: no gap, no two epochs in one slot): slots are rows
    full = size == k.size and bool(np.all(k[1:] != k[:-1]))
    present = np.ones(size, dtype=bool)
    if not full:
        present[:] = False
        present[k - a] = True
    empty_prefix = None if full else prefix_counts(~present)
    w_max = min(_max_slots(services, dt), size)
    windows, head_up, tail_up = {}, {}, {}
    for key, ws in keys.items():
        if full:
            up = masks[key]
        else:
            up = np.zeros(size, dtype=bool)
            up[k - a] = masks[key]
        lost_prefix = prefix_counts(~up)
        for window in ws:
            w = window_slots(window, dt / 1e6)
            m = max(size - w, 0)  # windows starting at 0..m-1 end inside the partition
            starts = up[:m]
            fail = lost_prefix[w + 1 : w + 1 + m] != lost_prefix[1 : 1 + m]
            n_gap = 0
            if empty_prefix is not None:
                gap = empty_prefix[w + 1 : w + 1 + m] != empty_prefix[1 : 1 + m]
                n_gap = np.count_nonzero(starts & gap)
            windows[(key, window)] = np.array(
                [np.count_nonzero(starts), np.count_nonzero(starts & fail), n_gap], dtype=np.int64
            )
        w_key = min(max(window_slots(window, dt / 1e6) for window in ws), size)  # this key's windows
        head_up[key], tail_up[key] = up[:w_key].copy(), up[size - w_key :].copy()
    edge = Edge(a, b, present[:w_max].copy(), present[size - w_max :].copy(), head_up, tail_up)
    return PartitionWindows(off, windows, edge)


def merge_second(*parts: SecondPass) -> SecondPass:
    """The pass-2 partial of ``parts`` together, given in table order."""
    windows: dict = {}
    values: dict = {}
    evidence: dict = {}
    for p in parts:
        windows.update(p.windows)
        for key, arrays in p.values.items():
            values[key] = values.get(key, []) + arrays
        for name, pieces in p.evidence.items():
            evidence[name] = evidence.get(name, []) + pieces
    # one array per key: a station-year's cache then holds a few arrays, not thousands
    values = {key: [np.concatenate(arrays)] if len(arrays) > 1 else arrays for key, arrays in values.items()}
    return SecondPass(windows, values, evidence)


# --------------------------------------------------------------------------------------------------
# finalize


def _boundary_windows(edges: list[Edge], key: tuple, w: int) -> tuple[int, int, int, int]:
    """``(n, n_fail, n_gap, n_truncated)`` of the windows starting in the last ``w`` slots of each
    partition, from the end slots of it and of the partitions that follow (gaps between: empty).

    All partitions at once: row ``i`` holds the slots ``b_i - w + 1 .. b_i + w`` (its last ``w``
    and the ``w`` after), filled from its tail and the next partition's head; the few rows that
    reach a third partition (the next one shorter than the window) are filled one by one."""
    m = len(edges)
    a = np.array([e.a for e in edges], dtype=np.int64)
    b = np.array([e.b for e in edges], dtype=np.int64)
    lo = b - w + 1  # each row's first slot
    o = a[1:] - lo[:-1]  # where the next partition's head starts in each row
    near = np.flatnonzero(o < 2 * w)
    nxt = [edges[i + 1] for i in near]
    present = _strips(m, w, [e.tail_present for e in edges], [e.head_present for e in nxt], near, o)
    up = _strips(m, w, [e.tail_up[key] for e in edges], [e.head_up[key] for e in nxt], near, o)
    far = np.flatnonzero(a[2:] <= b[:-2] + w)  # rows whose strip reaches the partition after next
    for i in far:
        for f in edges[i + 2 :]:
            if f.a > b[i] + w:
                break
            _put(present[i], int(lo[i]), int(b[i] + w), f.a, f.head_present)
            _put(up[i], int(lo[i]), int(b[i] + w), f.a, f.head_up[key])
    slot = lo[:, None] + np.arange(w)  # the start slots: the row's first w
    start = up[:, :w] & (slot >= a[:, None])
    counted = start & (slot + w <= b[-1])
    lost = np.zeros((m, 2 * w + 1), dtype=np.int32)
    empty = np.zeros((m, 2 * w + 1), dtype=np.int32)
    np.cumsum(~up, axis=1, out=lost[:, 1:])
    np.cumsum(~present, axis=1, out=empty[:, 1:])
    fail = lost[:, w + 1 :] != lost[:, 1 : w + 1]  # a slot lost among the w after the start
    gap = empty[:, w + 1 :] != empty[:, 1 : w + 1]
    n = int(np.count_nonzero(counted))
    n_trunc = int(np.count_nonzero(start)) - n
    return n, int(np.count_nonzero(counted & fail)), int(np.count_nonzero(counted & gap)), n_trunc


def _strips(m: int, w: int, tails: list, heads: list, near: np.ndarray, o: np.ndarray) -> np.ndarray:
    """The ``(m, 2w)`` strips of :func:`_boundary_windows`: row ``i`` ends its first half with the
    last slots of ``tails[i]`` and holds ``heads[k]`` (the head of partition ``near[k] + 1``) from
    column ``o[near[k]]``. Pieces of the same column and length are copied together, one block
    each (the usual campaign: two blocks; a numpy op per row cost 1.5 s a campaign)."""
    strip = np.zeros((m, 2 * w), dtype=bool)
    t = [x[-w:] for x in tails]
    h = [x[: 2 * w - int(o[i])] for x, i in zip(heads, near, strict=True)]
    pieces = t + h
    rows = np.concatenate([np.arange(m), near])
    lens = np.fromiter((x.size for x in pieces), dtype=np.int64, count=len(pieces))
    first = np.concatenate([w - lens[:m], o[near]])  # each piece's first column
    group = first * (2 * w + 1) + lens
    for g in np.unique(group[lens > 0]):
        sel = np.flatnonzero(group == g)
        c, n = int(first[sel[0]]), int(lens[sel[0]])
        strip[rows[sel], c : c + n] = np.stack([pieces[k] for k in sel])
    return strip


def _put(strip: np.ndarray, lo: int, hi: int, start: int, src: np.ndarray) -> None:
    """Copy end slots starting at slot ``start`` into the strip of slots ``[lo, hi]``."""
    i0, i1 = max(start, lo), min(start + src.size - 1, hi)
    if i1 >= i0:
        strip[i0 - lo : i1 - lo + 1] = src[i0 - start : i1 - start + 1]


@dataclass
class _StationWindows:
    n_off_grid: int
    windows: dict[tuple, np.ndarray]
    edges: list[Edge]


def _station_windows(st: StationFirst, second: SecondPass, plan: SecondPlan, name: str) -> _StationWindows:
    """A station's partition windows in time order: pass 2's where it counted them, else the
    pass-1 guess with its slots renumbered onto the station's grid."""
    grid = plan.grids[name]
    parts = []
    for label, g in zip(st.labels, st.guesses, strict=True):
        if label in second.windows:
            parts.append(second.windows[label])
        elif grid is not None and g is not None:
            m = (g.t0 - grid[0]) // grid[1]
            w = g.windows
            parts.append(PartitionWindows(w.n_off_grid, w.windows, w.edge.shifted(m) if w.edge else None))
    return _StationWindows(
        sum(p.n_off_grid for p in parts),
        _sum_dicts(p.windows for p in parts),
        [p.edge for p in parts if p.edge is not None],
    )


def _station_continuity(sw: _StationWindows, grid, key: tuple, window_s: float):
    interval_s = None if grid is None else grid[1] / 1e6
    if none := no_grid_continuity(interval_s, sw.n_off_grid, window_s):
        return none
    if not sw.edges:
        return continuity_result(0, 0, 0, 0, window_s, interval_s, sw.n_off_grid)
    inside = sw.windows.get((key, window_s), np.zeros(3, dtype=np.int64))
    w = window_slots(window_s, interval_s)
    bn, bf, bg, bt = _boundary_windows(sw.edges, key, w)
    n, n_fail, n_gap = (int(v) for v in inside)
    short = sw.edges[-1].b - sw.edges[0].a + 1 <= w  # the station's slots hold no whole window
    return continuity_result(
        n + bn, n_fail + bf, n_gap + bg, bt, window_s, interval_s, sw.n_off_grid, short=short
    )


def _percentile(
    plan: SecondPlan,
    second: SecondPass,
    memo: dict,
    n: int,
    scope: str,
    var: str,
    q: float,
    scale: float = 100.0,
) -> float:
    bins, below = plan.below[(scope, var, q)]
    if (scope, var) not in memo:
        memo[(scope, var)] = np.concatenate(second.values.get((scope, var), [np.empty(0)]))
    return exact_percentile(n, q, below, values_in_bins(memo[(scope, var)], bins), scale=scale)


def _result(
    names: list[str],
    first: FirstPass,
    second: SecondPass,
    plan: SecondPlan,
    services: Sequence[ServiceLevel],
    scope: str,
    histograms: dict,
    by_station: dict,
    memo: dict,
) -> CountingResult:
    """The result of stations ``names``; ``memo`` keeps each station's continuity counts and
    the gathered percentile values between the calls of one :func:`finalize`."""
    sts = [first.stations[n] for n in names]
    n_total = sum(s.n_total for s in sts)
    n_ok = sum(s.n_ok for s in sts)
    n_available = _sum_dicts(s.n_available for s in sts)
    regions = _sum_dicts(s.regions for s in sts)
    counts = {k: StanfordCounts(*(int(c) for c in v)) for k, v in regions.items()}

    def station(n: str, key: tuple, window_s: float):
        if ("windows", n) not in memo:
            memo[("windows", n)] = _station_windows(first.stations[n], second, plan, n)
        if (n, key, window_s) not in memo:
            memo[(n, key, window_s)] = _station_continuity(memo[("windows", n)], plan.grids[n], key, window_s)
        return memo[(n, key, window_s)]

    def continuity(key, window_s):
        return sum_continuity([station(n, key, window_s) for n in names], window_s)

    safety = {}
    for axis in AXES:
        n_si = sum(s.si_n[axis] for s in sts)
        var = f"si_{axis}"
        keys = [f"p{p:g}" for p in SAFETY_PERCENTILES]
        if n_si == 0:
            safety[axis] = SafetyIndex(0, None, None, dict.fromkeys(keys))
            continue
        best = None
        for s in sts:
            best = _later_max(best, s.si_max[axis])
        pct = {
            k: _percentile(plan, second, memo, n_si, scope, var, q)
            for k, q in zip(keys, SAFETY_PERCENTILES, strict=True)
        }
        safety[axis] = SafetyIndex(n_si, best[0], _iso(best[1]), pct)
    starts = [s.spans[0][0] for s in sts]
    ends = [s.spans[-1][1] for s in sts]
    return CountingResult(
        n_total=n_total,
        n_with_solution=n_ok,
        stations=tuple(names),
        start=_iso(min(starts)) if starts else None,
        end=_iso(max(ends)) if ends else None,
        hpe95=_percentile(plan, second, memo, n_ok, scope, "hpe", 95.0) if n_ok else None,
        vpe95=_percentile(plan, second, memo, n_ok, scope, "vpe", 95.0) if n_ok else None,
        safety=safety,
        services={s.name: service_kpi(s, n_total, n_available, counts, continuity) for s in services},
        histograms=histograms,
        by_station=by_station,
    )


def _sum_dicts(dicts: Iterable[dict]) -> dict:
    out: dict = {}
    for d in dicts:
        out = _add_dicts(out, d)
    return out


def finalize(
    first: FirstPass,
    second: SecondPass,
    plan: SecondPlan,
    services: Sequence[ServiceLevel],
    *,
    histogram_bins: int = 200,
) -> CountingResult:
    """The :class:`CountingResult` of all partitions, as :func:`count_kpis` of their pooled table."""
    names = list(first.stations)
    hist = {}
    for key in histogram_keys(services, histogram_bins):
        idx, counts, clipped = first.histograms[key]
        dense = np.zeros(histogram_bins * histogram_bins, dtype=np.int64)
        dense[idx] = counts
        counts2d = dense.reshape(histogram_bins, histogram_bins)
        edges = np.linspace(0.0, key[1], histogram_bins + 1)
        hist[key] = StanfordHistogram(key[0], edges, np.ascontiguousarray(counts2d), int(clipped))
    memo: dict = {}
    if len(names) <= 1:
        return _result(names, first, second, plan, services, names[0] if names else "", hist, {}, memo)
    by_station = {n: _result([n], first, second, plan, services, n, {}, {}, memo) for n in names}
    return _result(names, first, second, plan, services, "", hist, by_station, memo)


def daily_availability(first: FirstPass, services: Sequence[ServiceLevel]) -> pl.DataFrame:
    """Epochs and combined availability per station and GPS day: the daily-compliance table.

    Columns ``station``, ``date``, ``n_epochs``, then ``<service>`` (0–1) per service.
    """
    combined = [k for k in continuity_keys(services) if k[0] == "combined"]
    rows = {"station": [], "date": [], "n_epochs": []}
    cols = {s.name: [] for s in services}
    for name, st in first.stations.items():
        for day in sorted(st.days):
            c = st.days[day]
            rows["station"].append(name)
            rows["date"].append(day)
            rows["n_epochs"].append(int(c[0]))
            for s in services:
                cols[s.name].append(int(c[1 + combined.index(("combined", s.hal, s.val))]) / int(c[0]))
    df = pl.DataFrame(rows, schema={"station": pl.String, "date": pl.Int32, "n_epochs": pl.Int64})
    df = df.with_columns(pl.col("date").cast(pl.Date))  # days since 1970-01-01 (GPS time scale)
    return df.with_columns(pl.Series(name, v, dtype=pl.Float64) for name, v in cols.items())


def count_partitioned(
    partitions: Sequence[Callable[[], pl.DataFrame]],
    services: Sequence[ServiceLevel],
    *,
    histogram_bins: int = 200,
) -> tuple[CountingResult, FirstPass]:
    """Both passes in this process over ``partitions`` (loaders of one partition table each, in
    table order: station, then time); the counting result and the merged pass 1."""
    first = merge_first(
        *(
            first_pass(load(), services, histogram_bins=histogram_bins, label=str(i))
            for i, load in enumerate(partitions)
        )
    )
    plan = plan_second(first, services)
    second = merge_second(
        *(second_pass(load(), plan, services, label=str(i)) for i, load in enumerate(partitions))
    )
    return finalize(first, second, plan, services, histogram_bins=histogram_bins), first


# --------------------------------------------------------------------------------------------------
# the counted evidence of the verdicts: its parts in pass 2, then pass 3 (the values of its
# quantile bounds), the same as :func:`~overbound.methods.evidence.counted_evidence` of the table


def station_evidence_inputs(plan: SecondPlan, station: str) -> tuple:
    """``(interval_s, ((axis, (lo, hi)), ...))``: the station's nominal interval and per axis the
    range of values its 95th percentile of the error lies in, that of its pass-2 target bins (the
    bins of the order statistics and their neighbours, contiguous among the station's bins)."""
    ranges = []
    for a in AXES:
        bins = plan.targets.get((station, ERROR_VARIABLE[a]))
        ranges.append((a, (math.inf, math.inf) if bins is None else value_range(bins)))
    grid = plan.grids.get(station)
    return None if grid is None else grid[1] / 1e6, tuple(ranges)


def percentile_range(plan: SecondPlan, station: str, axis: str) -> tuple[float, float] | None:
    """The range of values the station's 95th percentile of the ``axis`` error lies in: that of
    the bins of its order statistics (``None``: no error)."""
    below = plan.below.get((station, ERROR_VARIABLE[axis], 95.0))
    return None if below is None else value_range(below[0])


def part_of(
    table: pl.DataFrame, services: Sequence[ServiceLevel], station: tuple, gap_s: float
) -> EvidencePart:
    """Pass 2's evidence part of one partition (``station`` from :func:`station_evidence_inputs`)."""
    interval_s, q95 = station
    return evidence_part(epoch_arrays(table), services, interval_s, dict(q95), gap_s)


def bounds_plan(first: FirstPass, draft: EvidenceDraft) -> tuple[SecondPlan, dict]:
    """The plan of pass 3 (:func:`quantile_plan`) and the quantile levels it collects."""
    levels = _bound_levels(draft)
    return quantile_plan(first, levels), levels


def _bound_levels(draft: EvidenceDraft) -> dict[tuple[str, str], tuple[float, float]]:
    """The quantile levels of the accuracy bounds per ``(scope, percentile variable)``."""
    return {(scope, ERROR_VARIABLE[a]): lv for (scope, a), lv in draft.levels().items()}


def bounds_from_second(first: FirstPass, plan: SecondPlan, second: SecondPass, draft: EvidenceDraft):
    """The evidence from pass 2 alone when its values hold the bins of every order statistic of
    the accuracy bounds (long campaigns: the bounds are close to the 95th percentile); ``None``
    when some are outside them (pass 3 collects them then)."""
    levels = _bound_levels(draft)
    scopes = _scopes(first)
    below = {}
    for (scope, var), qs in levels.items():
        have = set(plan.targets.get((scope, var), np.empty(0, np.uint64)).tolist())
        ranks = _ranks(scopes[scope][var], qs, scale=1)
        if not all(have.issuperset(rank.tolist()) for rank, _ in ranks.values()):
            return None
        below.update({(scope, var, q): r for q, r in ranks.items()})
    bounds = SecondPlan({}, {}, frozenset(), frozenset(), plan.targets, below)
    return finish_evidence(first, draft, bounds, levels, second)


def finish_evidence(
    first: FirstPass, draft: EvidenceDraft, plan: SecondPlan, levels: dict, values: SecondPass
):
    """The evidence, from the values pass 3 collected for :func:`bounds_plan`."""
    found = exact_quantiles(first, plan, values, levels)
    return draft.evidence({(scope, a): found[(scope, ERROR_VARIABLE[a])] for scope, a in draft.levels()})


def evidence_draft(
    second: SecondPass,
    plan: SecondPlan,
    counting: CountingResult,
    services,
    gap_s: float = GAP_S,
    done: Mapping[str, tuple] | None = None,
) -> EvidenceDraft:
    """The evidence but its accuracy bounds, from the evidence parts of pass 2 (and the stations
    ``done`` already, see :func:`~overbound.methods.evidence.draft_evidence`), stations in the
    counting's order."""
    done = done or {}
    names = [n for n in counting.stations if n in second.evidence or n in done] or list(second.evidence)
    parts = {n: second.evidence.get(n, []) for n in names}
    intervals = {n: station_evidence_inputs(plan, n)[0] for n in names}
    return draft_evidence(parts, intervals, counting, services, gap_s=gap_s, done=done)


def evidence_partitioned(
    partitions: Sequence[Callable[[], pl.DataFrame]],
    services: Sequence[ServiceLevel],
    first: FirstPass,
    counting: CountingResult,
    *,
    gap_s: float = GAP_S,
) -> Evidence:
    """:func:`~overbound.methods.evidence.counted_evidence` of the pooled table, from the same
    ``partitions`` as :func:`count_partitioned` (its merged pass 1 and result), in this process:
    pass 2 with the evidence parts, then pass 3 for the values of the accuracy bounds."""
    plan = plan_second(first, services)
    second = merge_second(
        *(
            second_pass(load(), plan, services, label=str(i), evidence=True, gap_s=gap_s)
            for i, load in enumerate(partitions)
        )
    )
    draft = evidence_draft(second, plan, counting, services, gap_s)
    if (found := bounds_from_second(first, plan, second, draft)) is not None:
        return found
    bounds, levels = bounds_plan(first, draft)
    values = [second_values(t, bounds) for load in partitions if not (t := load()).is_empty()]
    return finish_evidence(first, draft, bounds, levels, merge_second(*(SecondPass({}, v) for v in values)))
