"""The EVT tail extrapolation of a campaign dataset, partition by partition.

The three passes of :mod:`overbound.methods.tail_partitions` over the partitions a counting read
(:func:`overbound.campaign.count_campaign`), on the same runner (Dask or this process): memory per
task is a partition and the one before it; the driver holds the reduced input (about 1 % of the
epochs: those above the lower edge of the 0.99 quantile's bin, with times and positions). The
result equals :func:`~overbound.methods.tail_extrapolation.tail_analysis` of the pooled table to
the last bit, since both run the same passes over the same station-days.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import polars as pl

from overbound._allocator import release_freed_memory
from overbound.campaign import (
    Window,
    _by_axis,
    _by_station,
    _cut,
    _Done,
    _failure,
    _file_key,
    _map_merged,
    _read,
    _ticks,
    runner_for,
)
from overbound.io.dataset import Partition
from overbound.io.schema import InputError
from overbound.methods.tail_partitions import (
    Filter,
    TailData,
    TailFirst,
    TailPlan,
    Walk,
    anchor,
    axis_block,
    concat_by_axis,
    krs_spacing,
    merge_tail_first,
    merge_tail_second,
    station_walks,
    tail_data,
    tail_first,
    tail_plan,
    tail_second,
    walk_station,
)

__all__ = ["NO_SOLUTION", "TailInputs", "campaign_tail_data"]

#: The reason of an axis without a solution epoch (as the pooled table's analysis gives it).
NO_SOLUTION = str(InputError("<epoch table>", "no epoch with a solution"))


@dataclass(frozen=True)
class TailInputs:
    """The reduced EVT input of each axis analysed, and why an axis could not be (``failed``)."""

    data: dict[str, TailData]
    failed: dict[str, str]


def _first_task(partition: Partition, filters: dict[str, tuple[Filter, ...]], window: Window) -> _Done:
    try:
        table = _read(partition, window)
        out = {
            a: tail_first(axis_block(table, a), partition.station, partition.key, f)
            for a, f in filters.items()
        }
    except (InputError, OSError, pl.exceptions.PolarsError, ValueError) as exc:
        return _Done(None, (_failure(partition, exc),))
    return _Done(out, computed=1)


#: The last partitions read by pass 2 in this process (path, key, window, table): a task reads its
#: partition and the one before, which the task of the partition before has just read.
_RECENT: list[tuple] = []


def _read_recent(partition: Partition, window: Window) -> pl.DataFrame:
    """:func:`~overbound.campaign._read`, from :data:`_RECENT` when this process has just read it."""
    key = (partition.path, _file_key(partition.path), window)
    for k, table in _RECENT:
        if k == key:
            return table
    table = _read(partition, window)
    _RECENT[:] = [*_RECENT[-1:], (key, table)]
    return table


def _second_task(
    partition: Partition, before: dict[str, Partition | None], plans: dict[str, TailPlan], time_range: Window
) -> _Done:
    """Pass 2 of a partition, with the partition before it of each axis (:attr:`TailPlan.prev`),
    each cut by the campaign's ``time_range`` where it cuts their days."""
    try:
        read = {b.key: _read_recent(b, _cut(b, time_range)) for b in before.values() if b is not None}
        table = _read_recent(partition, _cut(partition, time_range))
        out = {
            a: tail_second(
                axis_block(table, a),
                partition.key,
                p,
                None if before[a] is None else axis_block(read[before[a].key], a),
            )
            for a, p in plans.items()
        }
    except (InputError, OSError, pl.exceptions.PolarsError, ValueError) as exc:
        return _Done(None, (_failure(partition, exc),))
    return _Done(out, computed=1)


def _chain_task(parts: list[Partition], walks: dict[str, Walk], forward: bool, window: Window) -> _Done:
    """One station's part of the KRS selection of each axis of ``walks``, its ``parts`` in walking
    order, each read once for all axes (pass 3)."""

    def blocks():
        for p in parts:
            table = _read(p, _cut(p, window))
            yield p.key, lambda a, table=table: axis_block(table, a)

    try:
        out = walk_station(blocks(), walks, forward)
    except (InputError, OSError, pl.exceptions.PolarsError, ValueError) as exc:
        return _Done(None, (_failure(parts[0], exc),))
    release_freed_memory()  # a station's arrays, walked: not held under the next task's
    return _Done(out, computed=len(parts))


def campaign_tail_data(
    parts: Sequence[Partition],
    filters: dict[str, tuple[Filter, ...]],
    *,
    client=None,
    time_range: Window = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> TailInputs:
    """The reduced EVT input (:class:`~overbound.methods.tail_partitions.TailData`) of each axis of
    ``filters`` (the HMI filters of :func:`~overbound.methods.tail_extrapolation.tail_filters`)
    from ``parts`` (the partitions read by the counting, in dataset order), on ``client`` (Dask)
    or in this process. An axis without a solution epoch, or whose partitions could not be read
    in these passes, is in ``failed`` with the reason."""
    if any(f[0][0] is not None for f in filters.values()):  # pass 1 would need the next day's alerts
        raise ValueError("the main series of a dataset's EVT is not filtered by a service (tail_filters)")
    runner = runner_for(client)
    by_station = _by_station(list(parts))
    first = _map_merged(
        runner,
        [[(p, filters, _cut(p, time_range)) for p in ps] for ps in by_station.values()],
        _first_task,
        functools.partial(_by_axis, merge_tail_first),
        progress,
        "EVT pass 1",
    )
    if first.failures:
        return _failed(filters, first)
    plans, failed = {}, {}
    for a, f in filters.items():
        merged: TailFirst = first.partial[a]
        if not any(b.n_solution for b in merged.blocks):
            failed[a] = NO_SOLUTION
            continue
        try:
            plans[a] = tail_plan(merged, f)
        except InputError as exc:
            failed[a] = str(exc)
    if not plans:
        return TailInputs({}, failed)
    by_key = {p.key: p for p in parts}
    shared = runner.share(plans)
    items = [
        [(p, _before(plans, by_key, p.key), shared, time_range) for p in ps] for ps in by_station.values()
    ]
    second = _map_merged(
        runner, items, _second_task, functools.partial(_by_axis, merge_tail_second), progress, "EVT pass 2"
    )
    if second.failures:
        return _failed(filters, second)
    anchors = {a: anchor(plan.first) for a, plan in plans.items()}
    merged = second.partial
    del second
    # without the KRS selection yet: its spacing comes from the ACF
    data = {a: tail_data(plans[a], merged.pop(a), lambda spacing: np.empty(0)) for a in plans}
    _RECENT.clear()
    spacings = {a: krs_spacing(d.acf, d.interval_s) for a, d in data.items()}
    walks = {a: (plans[a], anchors[a], spacings[a]) for a in plans}
    chosen = _spaced(runner, by_station, walks, time_range, progress)

    def spaced(a: str) -> Callable[[float], np.ndarray]:
        def values(spacing: float) -> np.ndarray:
            if spacing == spacings[a]:
                return chosen[a]
            return _spaced(runner, by_station, {a: (plans[a], anchors[a], spacing)}, time_range, None)[a]

        return values

    return TailInputs({a: dataclasses.replace(d, spaced=spaced(a)) for a, d in data.items()}, failed)


def _before(plans: dict[str, TailPlan], by_key: dict[str, Partition], label: str) -> dict:
    """Per axis, the partition before ``label`` whose last hour pairs with its first, if any."""
    return {a: by_key.get(p.prev.get(label) or "") for a, p in plans.items()}


def _spaced(runner, by_station, walks: dict[str, tuple], window, progress) -> dict[str, np.ndarray]:
    """The KRS selection's SI of each axis (``walks``: axis: ``(plan, anchor, spacing)``): per
    station one task per direction its axes walk (the anchor's station both ways), each reading
    the station's partitions once (pass 3)."""
    station_of = {p.key: p.station for ps in by_station.values() for p in ps}
    anchor_station = {a: station_of[at[0]] for a, (_, at, _) in walks.items()}
    groups = [
        [(ps if forward else ps[::-1], w, forward, window) for forward, w in station]
        for ps, station in zip(
            by_station.values(), station_walks(list(by_station), anchor_station, walks), strict=True
        )
    ]
    done = runner.map_reduce(_chain_task, groups, concat_by_axis, _ticks(progress, "EVT pass 3", len(groups)))
    failures = [f for d in done for f in d.failures]
    if failures:
        f = failures[0]
        raise InputError(f"{f.station} {f.date}", f"unreadable in the EVT pass 3: {f.reason}")
    return concat_by_axis(*(d.partial for d in done if d.partial is not None))


def _failed(filters: dict, done: _Done) -> TailInputs:
    f = done.failures[0]
    why = f"partition {f.station} {f.date} unreadable in the EVT passes: {f.reason}"
    return TailInputs({}, {a: why for a in filters})
