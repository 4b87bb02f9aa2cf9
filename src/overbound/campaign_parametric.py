"""The parametric analysis (Kannemans 2006) of a campaign dataset, partition by partition.

The passes of :mod:`overbound.methods.parametric_partitions` over the partitions a counting read
(:func:`overbound.campaign.count_campaign`), on the same runner (Dask or this process), each
partition a block of the pooled series:

1. one task per partition: each axis' :func:`~overbound.methods.parametric_partitions.block_first`,
   and the rows' counts (rows, rows available at each service's alert limit, the times' first,
   last and steps for the station's continuity grid);
2. one task per station, its partitions in time order: each axis'
   :func:`~overbound.methods.parametric_partitions.block_second`, and the non-continuity counts of
   each window on the station's grid (:class:`~overbound.stats.continuity.WindowCounter`, the
   windows across midnight counted as in one table);
3. one task per partition per evaluation of the Weibull profile equations of both axes together
   (usually two), and one for the information sums at the fits.

Memory per task is a partition (pass 2: one partition and the counters); the driver holds a few
numbers per partition and the ACF subsamples (at most 2^21 slots per series). The result equals
:func:`~overbound.methods.parametric.parametric_analysis` of the pooled table to the last bit:
the same blocks, their sums added in the same order, integer counts.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import polars as pl

from overbound.campaign import (
    Window,
    _by_station,
    _cut,
    _Done,
    _failure,
    _map_merged,
    _read,
    runner_for,
)
from overbound.io.dataset import Partition
from overbound.io.schema import InputError, as_numpy
from overbound.methods.parametric import (
    AXES,
    ParametricAnalysis,
    RowCounts,
    _decorrelation,
    _reason,
    _services,
    axis_result,
    check_fittable,
    continuity_grids,
    dependence,
    needs_information,
    service_alert_limits,
)
from overbound.methods.parametric_partitions import (
    AxisPlan,
    BlockFirst,
    FittedBlock,
    add_in_order,
    axis_plan,
    block_first,
    block_information,
    block_profile,
    block_second,
    fitted_block,
    interval_across,
    second_inputs,
)
from overbound.methods.pooling import alert_flags, axis_columns, solution_rows, unavailable_at_alerts
from overbound.services import ServiceLevel
from overbound.stats.continuity import WindowCounter, availability_ranks, curve_from_counts, pool_curves
from overbound.stats.dependence import step_counts
from overbound.stats.parametric import weibull_fit_steps

__all__ = ["campaign_parametric"]

_ERRORS = (InputError, OSError, pl.exceptions.PolarsError, ValueError)


@dataclass(frozen=True)
class _PartitionRows:
    """Pass 1 of a partition's rows: their number, first and last time and steps (µs), and per axis
    the rows available at each service alert limit (PL < AL, no alert)."""

    n_rows: int
    first: int | None
    last: int | None
    steps: tuple[np.ndarray, np.ndarray]
    n_available: dict[str, np.ndarray]


class _Partition:
    """A partition's columns as the parametric analysis reads them (the pooled table's rules of
    :mod:`overbound.methods.pooling`): times (µs) and alerts of its rows in row order, and per axis
    its solution epochs and the PL of every row with alerts as +inf (the counting's convention)."""

    def __init__(self, partition: Partition, window: Window) -> None:
        self.table = _read(partition, window)
        self.t = as_numpy(self.table["time"]).astype(np.int64, copy=False)
        self.alert = alert_flags(self.table)

    def block(self, axis: str) -> FittedBlock | None:
        """The solution epochs of ``axis`` (``None`` without one)."""
        pe, x = axis_columns(self.table, axis, signed=axis == "vertical")
        order = solution_rows(self.t, np.zeros(self.t.size, dtype=np.int64), pe, x)
        if order.size == 0:
            return None
        return fitted_block(self.t[order], pe[order], x[order], self.alert[order])

    def pl_column(self, axis: str) -> np.ndarray:
        x = axis_columns(self.table, axis)[1]
        return unavailable_at_alerts(x, self.alert)


def _first_task(partition: Partition, window: Window, als: dict[str, np.ndarray]) -> _Done:
    try:
        part = _Partition(partition, window)
        t = part.t
        blocks, n_avail = {}, {}
        for a in AXES:
            b = part.block(a)
            blocks[a] = None if b is None else block_first(b, partition.station, als[a])
            column = part.pl_column(a)
            n_avail[a] = np.array([np.count_nonzero(column < al) for al in als[a]], dtype=np.int64)
        first, last = (int(t.min()), int(t.max())) if t.size else (None, None)
        rows = _PartitionRows(int(t.size), first, last, step_counts(np.diff(t)), n_avail)
    except _ERRORS as exc:
        return _Done(None, (_failure(partition, exc),))
    return _Done([(partition.key, blocks, rows)], computed=1)


def _concat(*parts: list) -> list:
    return [x for p in parts for x in p]


@dataclass(frozen=True)
class _StationPlan:
    """Pass 2's inputs: per axis, the plan and each partition's block index; per station, the
    continuity grid ``(t0, dt)`` (``None`` below two epoch times); per axis and window, the alert
    limits of the curve."""

    plans: dict[str, AxisPlan]
    index: dict[str, dict[str, int]]
    grids: dict[str, tuple[int, int] | None]
    als: dict[str, dict[float, np.ndarray]]


def _second_task(parts: list[Partition], plan: _StationPlan, window: Window) -> _Done:
    """Pass 2 of one station, its partitions in time order."""
    grid = plan.grids[parts[0].station]
    interval_s = None if grid is None else grid[1] / 1e6
    counters = {
        (a, w): WindowCounter.for_grid(al.size, interval_s, w)
        for a, windows in plan.als.items()
        for w, al in windows.items()
    }
    out: dict[str, list] = {a: [] for a in plan.plans}
    try:
        for p in parts:
            part = _Partition(p, _cut(p, window))
            for a, ap in plan.plans.items():
                if (i := plan.index[a].get(p.key)) is not None:
                    out[a].append((i, block_second(part.block(a), ap, i, a)))
            if grid is None or part.t.size == 0:
                continue
            k = (part.t - (grid[0] - grid[1] // 2)) // grid[1]  # slot_grid's nearest slot
            columns = {a: part.pl_column(a) for a in plan.als}
            for (a, w), c in counters.items():
                if not c.counts_nothing:
                    dense = np.full(int(k[-1] - k[0]) + 1, c.n_al, dtype=c.dtype)
                    dense[k - k[0]] = availability_ranks(plan.als[a][w], columns[a])
                    c.feed(int(k[0]), dense)
    except _ERRORS as exc:
        return _Done(None, (_failure(p, exc),))
    for c in counters.values():
        c.finish()
    curves = {key: (*c.counts(), c.w) for key, c in counters.items()}
    return _Done([(out, curves)], computed=len(parts))


def _profile_task(partition: Partition, window: Window, index: dict, fits: dict) -> _Done:
    """Per axis of ``fits`` (axis: ``(ymax, b)`` or a :class:`WeibullFit`), the block's profile sums
    at ``b`` or its information sums at the fit."""
    try:
        part = _Partition(partition, window)
        out = {}
        for a, f in fits.items():
            if (i := index[a].get(partition.key)) is None:
                continue
            b = part.block(a)
            out[a] = [(i, block_profile(b, *f) if isinstance(f, tuple) else block_information(b, f))]
    except _ERRORS as exc:
        return _Done(None, (_failure(partition, exc),))
    return _Done(out, computed=1)


def _merge_axes(*parts: dict) -> dict:
    out: dict[str, list] = {}
    for p in parts:
        for a, items in p.items():
            out.setdefault(a, []).extend(items)
    return out


def campaign_parametric(
    parts: Sequence[Partition],
    *,
    services: tuple[str | ServiceLevel, ...] | list[str | ServiceLevel] | None = None,
    decorrelation: str | float = "auto",
    confidence: float = 0.95,
    client=None,
    time_range: Window = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> ParametricAnalysis:
    """:func:`~overbound.methods.parametric.parametric_analysis` of the pooled table of ``parts``
    (the partitions the counting read: pooled as :func:`~overbound.io.dataset.read_dataset` reads
    them, stations by name, each in time order), on ``client`` (Dask) or in this process.

    Raises
    ------
    ValueError
        Bad ``decorrelation``, ``confidence`` or service, no partition.
    InputError
        A partition could not be read (the analysis of both axes needs all of them).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    tau = _decorrelation(decorrelation)
    svcs = _services(services)
    if not parts:
        raise ValueError("no partition to analyse")
    runner = runner_for(client)
    # the pooled table's order (read_dataset's): stations by name, each in time order
    by_station = _by_station(sorted(parts, key=lambda p: (p.station, p.date)))
    order = [p for ps in by_station.values() for p in ps]
    als = {a: service_alert_limits(svcs, a) for a in AXES}
    groups = [[(p, _cut(p, time_range), als) for p in ps] for ps in by_station.values()]
    first = _map_merged(runner, groups, _first_task, _concat, progress, "parametric pass 1")
    _raise_failed(first)
    by_key = {key: (blocks, rows) for key, blocks, rows in first.partial}
    n_rows = sum(rows.n_rows for _, rows in by_key.values())
    plans, index, failed = {}, {}, {}
    for a in AXES:
        keys = [p.key for p in order if by_key[p.key][0][a] is not None]
        blocks: list[BlockFirst] = [by_key[k][0][a] for k in keys]
        try:
            if not blocks:
                raise InputError("<epoch table>", "no epoch with a solution")
            plan = axis_plan(blocks)
            check_fittable(plan, a)
        except (InputError, ValueError) as exc:
            failed[a] = _reason(exc)
            continue
        plans[a], index[a] = plan, {k: i for i, k in enumerate(keys)}
    results: dict = {a: None for a in AXES}
    if plans:
        fitted = _fit_axes(
            runner,
            by_station,
            order,
            by_key,
            plans,
            index,
            svcs,
            tau,
            confidence,
            time_range,
            progress,
            n_rows,
        )
        for a, r in fitted.items():  # an axis that failed after its fits: its reason
            if isinstance(r, str):
                failed[a] = r
            else:
                results[a] = r
    reasons = {a: failed[a] for a in AXES if a in failed}  # the pooled analysis' order
    return ParametricAnalysis(
        results["vertical"], results["horizontal"], reasons, svcs, float(confidence), tau, n_rows
    )


def _raise_failed(done: _Done) -> None:
    if done.failures:
        f = done.failures[0]
        raise InputError(f"{f.station} {f.date}", f"unreadable in the parametric passes: {f.reason}")


def _station_grids(order: list[Partition], by_key: dict) -> dict[str, tuple[int, int] | None]:
    """Each station's continuity grid: its first epoch and the nominal interval of all its steps,
    partition boundaries included (``slot_grid``'s rule on the station's rows)."""
    grids: dict[str, tuple[int, int] | None] = {}
    for station, ps in _by_station(order).items():
        rows = [by_key[p.key][1] for p in ps if by_key[p.key][1].n_rows]
        dt = interval_across([(station, r.first, r.last, r.steps) for r in rows]) if rows else None
        grids[station] = None if dt is None else (rows[0].first, int(dt))
    return grids


def _fit_axes(
    runner, by_station, order, by_key, plans, index, svcs, tau, confidence, time_range, progress, n_rows
):
    """Passes 2 and 3 of the axes planned, and their results."""
    curve_als = {a: continuity_grids(svcs, a, p.pl_range) for a, p in plans.items()}
    shared = runner.share(_StationPlan(plans, index, _station_grids(order, by_key), curve_als))
    groups = [[(ps, shared, time_range)] for ps in by_station.values()]
    second = _map_merged(runner, groups, _second_task, _concat, progress, "parametric pass 2")
    _raise_failed(second)
    seconds: dict[str, list] = {a: [] for a in plans}
    station_curves: dict[tuple, list] = {}
    for out, counts in second.partial:
        for a, items in out.items():
            seconds[a].extend(items)
        for (a, w), (n_win, n_fail, n_ev, slots) in counts.items():
            curve = curve_from_counts(curve_als[a][w], n_win, n_fail, n_ev, slots, w, confidence)
            station_curves.setdefault((a, w), []).append(curve)
    del second
    merged = {a: second_inputs([b for _, b in sorted(seconds[a], key=_first)], plans[a]) for a in plans}
    deps = {a: dependence(plans[a], merged[a], a, tau) for a in plans}
    fits = _weibull_fits(runner, order, time_range, index, plans, merged, progress)
    need = {a: fits[a] for a in plans if needs_information(deps[a])}
    info = (
        _evaluate(runner, order, time_range, index, need, progress, "parametric information") if need else {}
    )
    out = {}
    for a, plan in plans.items():
        n_avail = sum(by_key[p.key][1].n_available[a] for p in order)
        counts = RowCounts(
            n_rows,
            {float(al): int(n) for al, n in zip(service_alert_limits(svcs, a), n_avail, strict=True)},
            {w: pool_curves(station_curves[a, w]) for w in curve_als[a]},
        )
        try:  # as the pooled analysis: an axis that fails here is null with its reason
            out[a] = axis_result(a, plan, merged[a], fits[a], deps[a], info.get(a), counts, svcs, confidence)
        except (InputError, ValueError) as exc:
            out[a] = _reason(exc)
    return out


def _first(item: tuple) -> int:
    return item[0]


def _weibull_fits(runner, order, time_range, index, plans, merged, progress) -> dict:
    """The Weibull fits of all axes, their profile equations evaluated together: one pass over the
    partitions per evaluation."""
    steps = {a: weibull_fit_steps(p.n, p.ymax, p.spread, merged[a].start) for a, p in plans.items()}
    wanted = {a: next(s) for a, s in steps.items()}
    fits = {}
    evaluation = 0
    while wanted:
        evaluation += 1
        at = {a: (plans[a].ymax, b) for a, b in wanted.items()}
        sums = _evaluate(runner, order, time_range, index, at, progress, f"parametric Weibull {evaluation}")
        for a in list(wanted):
            try:
                wanted[a] = steps[a].send(sums[a])
            except StopIteration as stop:
                fits[a] = stop.value
                del wanted[a]
    return fits


def _evaluate(runner, order, time_range, index, at: dict, progress, stage: str) -> dict[str, np.ndarray]:
    """Per axis of ``at``, the blocks' profile sums at ``(ymax, b)`` or information sums at a fit,
    added in pooled order."""
    shared_index = runner.share({a: index[a] for a in at})
    groups = [[(p, _cut(p, time_range), shared_index, at) for p in ps] for ps in _by_station(order).values()]
    done = _map_merged(runner, groups, _profile_task, _merge_axes, progress, stage)
    _raise_failed(done)
    return {a: add_in_order(v for _, v in sorted(items, key=_first)) for a, items in done.partial.items()}
