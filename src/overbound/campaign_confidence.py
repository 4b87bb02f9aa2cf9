"""The PL confidence level of a campaign dataset, partition by partition.

The three passes of :mod:`overbound.methods.confidence_partitions` over the partitions a counting
read (:func:`overbound.campaign.count_campaign`), on the same runner (Dask or this process): passes 1
and 2 one task per partition; pass 3 two tasks, the chains walked forward and backward across the
days, each holding one day of all stations. The result equals
:func:`~overbound.methods.confidence_level.confidence_analysis` of the pooled table to the last bit.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import polars as pl

from overbound._allocator import release_freed_memory
from overbound.campaign import (
    Window,
    _by_axis,
    _by_station,
    _cut,
    _Done,
    _failure,
    _map_merged,
    _read,
    _ticks,
    runner_for,
)
from overbound.io.dataset import Partition
from overbound.io.schema import REQUIRED, InputError
from overbound.methods.confidence_level import ConfidenceAnalysis, analysed_names
from overbound.methods.confidence_partitions import (
    BandChains,
    BandPlan,
    BandSweep,
    ConfidenceParameters,
    band_block,
    band_chains,
    band_first,
    band_plan,
    band_second,
    dataset_confidence,
    day_block,
    joined_walks,
    merge_band_first,
    merge_band_second,
)

__all__ = ["ConfidenceRun", "campaign_confidence"]

#: The optional columns the method reads (the pooled table's analysis reads those the table has).
EXTRA = ("east", "north", "alert")
_ERRORS = (InputError, OSError, pl.exceptions.PolarsError, ValueError)


@dataclass(frozen=True)
class ConfidenceRun:
    """The analyses of the axes done, and ``(axis, reason)`` of each axis that could not be: the
    exception the pooled table's analysis would raise, or why a partition could not be read."""

    done: tuple[ConfidenceAnalysis, ...]
    failed: tuple[tuple[str, str | Exception], ...]


def _first_task(partition: Partition, axes: tuple[str, ...], window: Window, extra: tuple[str, ...]) -> _Done:
    try:
        table = _read(partition, window, REQUIRED, extra)
        out = {a: band_first(table, a, partition.key, partition.station) for a in axes}
    except _ERRORS as exc:
        return _Done(None, (_failure(partition, exc),))
    return _Done(out, computed=1)


def _block(partition: Partition, table: pl.DataFrame, plan: BandPlan):
    return band_block(
        table, plan.axis, plan.station_index.get(partition.station, -1), plan.row0[partition.key]
    )


def _second_task(
    partition: Partition, plans: dict[str, BandPlan], window: Window, extra: tuple[str, ...]
) -> _Done:
    try:
        table = _read(partition, window, REQUIRED, extra)
        out = {a: band_second(_block(partition, table, p), p) for a, p in plans.items()}
    except _ERRORS as exc:
        return _Done(None, (_failure(partition, exc),))
    return _Done(out, computed=1)


def _walk_task(
    days: list[list[Partition]],
    plans: dict[str, BandPlan],
    chains: dict[str, BandChains],
    axis: str,
    forward: bool,
    window: Window,
    extra: tuple[str, ...],
) -> _Done:
    """Pass 3 of ``axis`` one way: ``days`` (the partitions of each day) in walking order, each day
    read once (the axis' columns only), one day in memory."""
    plan = plans[axis]
    sweep = BandSweep(plan, chains[axis].chains, forward)
    only, extra = _axis_columns(axis, extra)
    for parts in days:
        blocks = []
        for p in parts:
            try:
                blocks.append(_block(p, _read(p, _cut(p, window), only, extra), plan))
            except _ERRORS as exc:  # the partition named, not its day's first
                return _Done(None, (_failure(p, exc),))
        sweep.day(day_block(blocks))
    release_freed_memory()  # the days' arrays: the worker's next walk or pass need not find it held
    return _Done(sweep.pieces(), computed=sum(map(len, days)))


def _axis_columns(axis: str, extra: tuple[str, ...]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The columns of ``axis`` (``REQUIRED`` ones, then those of ``extra``) a walk reads: the time,
    the station, the error and PL, the signed components and the alerts."""
    error, pl_, *components = analysed_names(axis)
    return ("time", "station", error, pl_), tuple(c for c in extra if c in (*components, "alert"))


def _ways(days: list) -> tuple[tuple[bool, list], ...]:
    """The days of the backward walk (last first), then of the forward."""
    return (False, days[::-1]), (True, days)


def campaign_confidence(
    parts: Sequence[Partition],
    axes: Sequence[str] | None,
    *,
    parameters: ConfidenceParameters | None = None,
    columns: Sequence[str] | None = None,
    client=None,
    time_range: Window = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> ConfidenceRun:
    """The PL confidence level of each of ``axes`` (``None``: vertical, and horizontal when the
    partitions have signed east errors, as the pooled table's default) from ``parts`` (the
    partitions the counting read, in dataset order), on ``client`` (Dask) or in this process.
    ``columns``: the optional columns of :data:`EXTRA` read (``None``: all), as the pooled table's
    analysis sees those the table was read with. An axis asked twice is analysed once."""
    parameters = parameters or ConfidenceParameters()
    runner = runner_for(client)
    if not parts:
        raise ValueError("no partition to analyse")
    by_station = _by_station(list(parts))
    extra = EXTRA if columns is None else tuple(c for c in EXTRA if c in columns)
    failed: list[tuple[str, str | Exception]] = []
    tried = ("vertical", "horizontal") if axes is None else tuple(dict.fromkeys(axes))
    for a in tried:  # the axis name and the parameters first, as the pooled analysis checks them
        try:
            parameters.check(a)
        except ValueError as exc:
            failed.append((a, exc))
    tried = tuple(a for a in tried if a not in dict(failed))
    if not tried:
        return ConfidenceRun((), tuple(failed))
    merge = functools.partial(_by_axis, merge_band_first)
    groups = [[(p, tried, _cut(p, time_range), extra) for p in ps] for ps in by_station.values()]
    first = _map_merged(runner, groups, _first_task, merge, progress, "confidence pass 1")
    if first.failures:
        return _failed(tried, first)
    if axes is None:
        h = first.partial["horizontal"]
        tried = ("vertical", "horizontal") if h.has_east and {"east", "north"} <= h.columns else ("vertical",)
    plans = {}
    for a in tried:
        try:
            plans[a] = band_plan(first.partial[a], a, parameters)
        except ValueError as exc:  # InputError too: a column missing
            failed.append((a, exc))
    if not plans:
        return ConfidenceRun((), tuple(failed))
    shared = runner.share(plans)
    merge = functools.partial(_by_axis, merge_band_second)
    groups = [[(p, shared, _cut(p, time_range), extra) for p in ps] for ps in by_station.values()]
    second = _map_merged(runner, groups, _second_task, merge, progress, "confidence pass 2")
    if second.failures:
        return _failed(tried, second)
    chains = {a: band_chains(plans[a], second.partial[a]) for a in plans}
    del second
    by_day: dict = {}
    for p in parts:
        by_day.setdefault(p.date, []).append(p)
    days = [by_day[d] for d in sorted(by_day)]
    shared_chains = runner.share(chains)
    # a task per axis and way (4 on 2 workers: half the samples each, an axis' joined by the driver
    # while the workers walk the next)
    walks = [(w, shared, shared_chains, a, fw, time_range, extra) for a in plans for fw, w in _ways(days)]
    tick = _ticks(progress, "confidence pass 3", len(walks))
    done: dict[str, list] = {a: [] for a in plans}
    out, failures = [], []
    for (_, _, _, a, _, _, _), d in zip(walks, runner.imap(_walk_task, walks), strict=True):
        if tick:
            tick(1)
        failures += d.failures
        done[a].append(d.partial)
        if len(done[a]) == 2 and not failures:  # the axis' backward and forward walks
            both = joined_walks(*done.pop(a), a)
            out.append(dataset_confidence(plans[a], chains[a], both, runner.starmap))
            del both
    if failures:
        return _failed(tried, _Done(None, tuple(failures)))
    return ConfidenceRun(tuple(out), tuple(failed))


def _failed(axes: Sequence[str], done: _Done) -> ConfidenceRun:
    f = done.failures[0]
    why = f"partition {f.station} {f.date} unreadable in the confidence passes: {f.reason}"
    return ConfidenceRun((), tuple((a, why) for a in axes))
