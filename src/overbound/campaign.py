"""A campaign dataset analysed partition by partition: on Dask, or in this process.

Each station-day partition of the dataset (:mod:`overbound.io.dataset`) is read alone and
reduced to the partial results of :mod:`overbound.methods.counting_partitions`; the partials
merge in a tree (``split_every`` at a time, in table order) and the merged result is finalized
into the counting KPIs of the whole campaign, equal to those of its pooled table. Memory per
task is one partition plus the partials merged, never the campaign.

Passes 1 and 2 give the counting. With ``evidence=True`` they also give the counted evidence of
the verdicts (:mod:`overbound.methods.evidence`), equal to that of the pooled table: pass 2
reduces each partition to its :class:`~overbound.methods.evidence.EvidencePart` too (it needs the
station's interval, known after pass 1; which errors exceed the station's 95th percentile, not
known before pass 2 ends, is kept as the flags above the percentile's target bins and the values
in them), and pass 3 collects the values of the accuracy bounds (their quantile levels follow
from the effective sizes). A station's evidence holds its 0/1 series packed 8 to a byte (7
series: 4 MB each per station-year at 1 Hz).

Execution
---------
:func:`campaign_client` gives a ``distributed.Client``: on an existing scheduler
(``--scheduler tcp://host:8786``, or ``DASK_SCHEDULER_ADDRESS``), or on a local cluster of
``workers`` processes (one thread each: the work is numpy and polars, which release the GIL but
use their own threads). ``client=None`` runs every task in this process (small datasets, tests).

Cache
-----
Partials are kept beside the data (pickles written by this package, the key first: load only
datasets you trust, as for any pickle): per partition, ``<partition dir>/.overbound/`` holds its
pass 1 (``pass1.pkl``), its pass-2 values (``values.pkl``, with the bins they were collected for),
where pass 2 recounts them its windows (``windows.pkl``), its evidence part (``evidence.pkl``) and
the values of the evidence's bounds (``bounds.pkl``); per station, ``station=ID/.overbound/``
holds the same merged (``pass1.pkl``, ``pass2.pkl`` without the evidence parts, ``bounds.pkl``)
and its drafted evidence (``draft.pkl``: its effective sizes and counted events, a few kB, instead
of its 0/1 series). Each is stored
with a key of what it depends on: the overbound version, the partition files' size and
modification time (partitions are replaced by rename, so a new file has a new time), the
services, the time window, and for pass 2 the part of the plan it read; stored values hold while
their bins cover the new rank bins, evidence parts while their error ranges hold the new
percentile bins. A key that differs means recompute; a cache that cannot be
written (read-only dataset) is skipped. So re-analysing after one day was added reads one file
per unchanged station, the cached partials of the changed one, and the new partition.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import functools
import hashlib
import json
import os
import pickle
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import polars as pl

from overbound import __version__
from overbound._allocator import keep_freed_memory
from overbound.io.dataset import Partition, partition_key, partitions, read_manifest
from overbound.io.open import filter_time
from overbound.io.schema import COLUMNS, REQUIRED, InputError
from overbound.methods.counting import AXES, CountingResult
from overbound.methods.counting_partitions import (
    FirstPass,
    SecondPass,
    SecondPlan,
    bounds_from_second,
    bounds_plan,
    covers,
    daily_availability,
    evidence_draft,
    finalize,
    finish_evidence,
    first_pass,
    merge_first,
    merge_second,
    part_of,
    percentile_range,
    plan_second,
    second_values,
    second_windows,
    station_evidence_inputs,
    station_targets,
    windows_plan,
)
from overbound.methods.evidence import GAP_S, Evidence, EvidencePart
from overbound.services import ServiceLevel

__all__ = [
    "CampaignCounting",
    "PartitionFailure",
    "campaign_client",
    "count_campaign",
    "partitions_in",
    "runner_for",
    "uncached_partitions",
]

#: Columns a partition is read with for the counting.
COUNT_COLUMNS = ("alert",)
COLUMN_TYPES = {c.name: c.dtype for c in COLUMNS}
#: Columns the percentile values of pass 2 need.
VALUE_COLUMNS = ("hpe", "vpe", "hpl", "vpl", "alert")
#: Partials merged per task of the reduction tree.
SPLIT_EVERY = 32
#: Partitions per Dask task (read one after the other, their partials merged): a task of about a
#: second, so that the scheduler's work is a few percent of a core (one task per station-day
#: cost 15 % of the 2 cores of the bench machine).
BATCH = 16
_CACHE_DIR = ".overbound"


@dataclass(frozen=True, slots=True)
class PartitionFailure:
    """A partition that could not be read: left out of the results, counted and named."""

    station: str
    date: str
    reason: str

    @property
    def key(self) -> str:
        """The partition's key, as :attr:`~overbound.io.dataset.Partition.key`."""
        return partition_key(self.station, self.date)


@dataclass(frozen=True)
class CampaignCounting:
    """The counting KPIs of a campaign dataset.

    Attributes
    ----------
    counting : as :func:`~overbound.methods.counting.count_kpis` of the pooled table of the
        partitions read.
    daily : epochs and combined availability per station, GPS day and service
        (:func:`~overbound.methods.counting_partitions.daily_availability`).
    failures : the partitions that could not be read, with the reason.
    n_partitions : partitions in the dataset.
    n_cached : partial results taken from the cache (pass 1, windows and values each count).
    n_computed : partial results computed.
    positions : ``(lat, lon)`` (deg) of the stations whose reference the manifest holds.
    evidence : the counted evidence of the verdicts
        (:func:`~overbound.methods.evidence.counted_evidence` of the pooled table), by partition;
        ``None`` when not asked for.
    """

    counting: CountingResult
    daily: pl.DataFrame
    failures: tuple[PartitionFailure, ...]
    n_partitions: int
    n_cached: int
    n_computed: int
    positions: dict[str, tuple[float, float]] = dataclasses.field(default_factory=dict)
    evidence: Evidence | None = None


# --------------------------------------------------------------------------------------------------
# the cluster


def campaign_client(workers: int | None = None, scheduler: str | None = None):
    """A ``distributed.Client`` on ``scheduler`` (or ``DASK_SCHEDULER_ADDRESS``), else on a local
    cluster of ``workers`` processes (default: the machine's cores)."""
    import dask
    from distributed import Client, LocalCluster

    address = scheduler or os.environ.get("DASK_SCHEDULER_ADDRESS")
    if address:
        return Client(address)
    n = workers or os.cpu_count() or 1
    # Dask sets MALLOC_TRIM_THRESHOLD_ in its workers by default; glibc then stops adapting its
    # mmap threshold, every partition-sized array is mapped and unmapped, and the counting runs
    # at half speed (measured): unset it for our workers.
    # All tasks are sent to the workers at once (worker-saturation inf): with the default queue of
    # about one task per thread, a worker waited for its next task after each (15 % slower).
    # The workers' statistical profiler samples every thread's stack every 10 ms: off, as on a
    # production cluster whose dashboard nobody watches.
    config = {
        "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
        "distributed.scheduler.worker-saturation": float("inf"),
        "distributed.worker.profile.enabled": False,
    }
    with dask.config.set(config):
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            env={"POLARS_MAX_THREADS": "1"},
        )
    return Client(cluster)


# --------------------------------------------------------------------------------------------------
# cached tasks (run on the workers)


def _key(*parts) -> str:
    return hashlib.sha256(json.dumps(parts, default=str).encode()).hexdigest()[:32]


def _file_key(path: Path) -> tuple:
    st = path.stat()
    return (__version__, st.st_size, st.st_mtime_ns)


@functools.cache
def _services_key(services: tuple[ServiceLevel, ...]) -> str:
    return json.dumps([dataclasses.astuple(s) for s in services], default=str)


def _load_cached(path: Path, key: str | None):
    """The value cached at ``path`` under ``key`` (``None`` if absent, unreadable or another key);
    with ``key=None``, the key it was stored under. The key is the file's first pickle: a stale
    entry is told without reading its value."""
    try:
        with path.open("rb") as f:
            stored_key = pickle.load(f)
            if key is None or stored_key != key:
                return stored_key if key is None else None
            return pickle.load(f)
    except (OSError, ValueError, pickle.UnpicklingError, EOFError):
        return None


def _store(path: Path, key: str, value) -> None:
    """Write atomically; a dataset that cannot be written to keeps no cache."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with contextlib.suppress(OSError):
        path.parent.mkdir(exist_ok=True)
        with tmp.open("wb") as f:  # not compressed: mostly float arrays, and read back in one go
            pickle.dump(key, f, protocol=5)
            pickle.dump(value, f, protocol=5)
        os.replace(tmp, path)
    with contextlib.suppress(OSError):
        tmp.unlink(missing_ok=True)


def _read(
    partition: Partition, window: Window = None, only: Sequence[str] | None = None, extra: Sequence[str] = ()
) -> pl.DataFrame:
    """The counting columns of a partition (``only`` those of them), and the optional columns
    ``extra`` it has, its epochs in ``window`` only when it cuts the day. A partition of the
    canonical schema (as ingest and simulate write it) is read as it is; any other goes through
    the Parquet epoch reader."""
    schema = pl.read_parquet_schema(partition.path)
    names = tuple(dict.fromkeys((*REQUIRED, *COUNT_COLUMNS, *extra)))
    wanted = [c for c in names if c in schema and (only is None or c in only or c in extra)]
    if all(c in schema and schema[c] == COLUMN_TYPES[c] for c in wanted):
        table = pl.read_parquet(partition.path, columns=wanted)
    else:
        from overbound.io.table import read_parquet

        table = read_parquet(partition.path, columns=(*COUNT_COLUMNS, *extra))[0]
        table = table.select(c for c in names if c in table.columns and c in wanted)
    return table if window is None else filter_time(table, window)


Window = tuple[dt.datetime | None, dt.datetime | None] | None


def _cut(partition: Partition, window: Window) -> Window:
    """``window`` when it cuts the partition's day, ``None`` when it holds the whole day."""
    if window is None:
        return None
    start, end = window
    day = dt.datetime.combine(partition.date, dt.time())
    cuts = (start is not None and start > day) or (end is not None and end < day + dt.timedelta(days=1))
    return window if cuts else None


def partitions_in(dataset: str | Path, time_range: Window = None) -> list[Partition]:
    """The partitions of ``dataset`` that hold days of ``time_range`` (all without one)."""
    return [p for p in partitions(dataset) if _overlaps(p, time_range)]


def _overlaps(partition: Partition, window: Window) -> bool:
    if window is None:
        return True
    start, end = window
    day = dt.datetime.combine(partition.date, dt.time())
    return (start is None or start < day + dt.timedelta(days=1)) and (end is None or end > day)


def _failure(partition: Partition, exc: Exception) -> PartitionFailure:
    reason = exc.reason if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"
    return PartitionFailure(partition.station, partition.date.isoformat(), str(reason).splitlines()[0])


@dataclass
class _Done:
    """A task's output: the partial (``None`` when the partition failed), its failures, and how
    many partials were cached or computed."""

    partial: object
    failures: tuple[PartitionFailure, ...] = ()
    cached: int = 0
    computed: int = 0


def _pass1_key(partition: Partition, services, bins: int, window: Window) -> str:
    """What a partition's pass 1 depends on (``window`` as :func:`_cut` gives it)."""
    return _key(_file_key(partition.path), _services_key(services), bins, window)


def _first_task(partition: Partition, services, bins: int, use_cache: bool, window: Window) -> _Done:
    keep_freed_memory()  # partition-sized arrays: reuse freed memory (4x faster histograms)
    cache = _partition_cache(partition, "pass1.pkl")
    try:
        key = _pass1_key(partition, services, bins, window)
        if use_cache and (hit := _load_cached(cache, key)) is not None:
            return _Done(hit, cached=1)
        value = first_pass(_read(partition, window), services, histogram_bins=bins, label=partition.key)
    except (InputError, OSError, pl.exceptions.PolarsError, ValueError) as exc:
        return _Done(None, (_failure(partition, exc),))
    if use_cache:
        _store(cache, key, value)
    return _Done(value, computed=1)


def _second_task(
    partition: Partition, plan: SecondPlan, services, use_cache: bool, window: Window, evidence: bool
) -> _Done:
    """Pass 2 of one partition: its values, its windows when the plan asks, and its evidence part
    when ``evidence``; each from the cache when its key (and for values and evidence, the range
    collected) still holds."""
    keep_freed_memory()
    station, label = partition.station, partition.key
    table = None
    cached = computed = 0
    windows, parts = {}, {}
    try:
        fkey = (_file_key(partition.path), window)
        if label in plan.redo:
            wkey = _key(fkey, _services_key(services), windows_plan(plan, station, label))
            hit = _load_cached(_partition_cache(partition, "windows.pkl"), wkey) if use_cache else None
            if hit is None:
                table = _read(partition, window)
                hit = second_windows(table, plan, services, label=label)
                if use_cache:
                    _store(_partition_cache(partition, "windows.pkl"), wkey, hit)
                computed += 1
            else:
                cached += 1
            windows[label] = hit
        if evidence:
            part, hit, table = _evidence_part(partition, plan, services, use_cache, window, table)
            cached, computed = cached + hit, computed + (not hit)
            parts = {station: [part]} if part is not None else {}
        values, hit = _values(partition, plan, use_cache, window, "values.pkl", table)
        cached, computed = cached + hit, computed + (not hit)
    except (InputError, OSError, pl.exceptions.PolarsError, ValueError) as exc:
        return _Done(None, (_failure(partition, exc),))
    return _Done(SecondPass(windows, values, parts), cached=cached, computed=computed)


def _evidence_part(partition: Partition, plan: SecondPlan, services, use_cache: bool, window: Window, table):
    """A partition's evidence part (``None``: no epoch), whether it came from the cache, and the
    table if it was read. A stored part holds while its error ranges hold the station's new
    percentile bins."""
    station = partition.station
    interval_s, ranges = station_evidence_inputs(plan, station)
    key = _key(_file_key(partition.path), window, _services_key(services), interval_s, GAP_S)
    path = _partition_cache(partition, "evidence.pkl")
    stored = _load_cached(path, key) if use_cache else None
    if stored is not None and _parts_hold([p for p in stored if p is not None], plan, station):
        return stored[0], True, table
    if table is None:
        table = _read(partition, window)
    part = None if table.is_empty() else part_of(table, services, (interval_s, ranges), GAP_S)
    if use_cache:
        _store(path, key, [part])
    return part, False, table


def _parts_hold(parts: list[EvidencePart], plan: SecondPlan, station: str) -> bool:
    """Whether evidence parts computed under an earlier plan still tell which errors exceed the
    station's 95th percentile: their ranges hold its new percentile bins."""
    for a in AXES:
        r = percentile_range(plan, station, a)
        if r is not None and not all(p.accuracy[a].lo <= r[0] and r[1] <= p.accuracy[a].hi for p in parts):
            return False
    return True


def _values(
    partition: Partition, plan: SecondPlan, use_cache: bool, window: Window, name: str, table=None
) -> tuple[dict, bool]:
    """A partition's values in the plan's target bins (:func:`second_values`), and whether they
    came from its cache ``name``: stored values hold while their bins cover the plan's rank bins."""
    station = partition.station
    key = _key(_file_key(partition.path), window)
    stored = _load_cached(_partition_cache(partition, name), key) if use_cache else None
    if stored is not None and covers(stored[0], plan, (station, "")):
        return stored[1], True
    if table is None:  # the values need neither times nor station (unless cut by a window)
        table = _read(partition, window, VALUE_COLUMNS if window is None else None)
    values = second_values(table, plan, station=station)
    if use_cache:
        _store(_partition_cache(partition, name), key, (station_targets(plan, station), values))
    return values, False


def _bounds_task(partition: Partition, plan: SecondPlan, use_cache: bool, window: Window) -> _Done:
    """The values the evidence's quantile bounds need (:func:`quantile_plan`) of one partition."""
    keep_freed_memory()
    try:
        values, hit = _values(partition, plan, use_cache, window, "bounds.pkl")
    except (InputError, OSError, pl.exceptions.PolarsError, ValueError) as exc:
        return _Done(None, (_failure(partition, exc),))
    return _Done(SecondPass({}, values), cached=int(hit), computed=int(not hit))


def _by_axis(merge: Callable, *parts: dict) -> dict:
    """Per-axis partials (``{axis: partial}``) merged axis by axis, each axis taken out of ``parts``
    as it is merged: the parts of one axis are freed before the next is merged (the driver's last
    merge of EVT pass 2 of 10 station-years held both axes twice, 0.9 GB, otherwise)."""
    return {a: merge(*(p.pop(a) for p in parts)) for a in list(parts[0])}


def _map_merged(runner, groups, task, merge, progress, stage: str) -> _Done:
    """``task`` over the groups of task arguments (a station's partitions each), each group merged,
    then the groups merged in order; ``progress(stage, done, total)`` counts the tasks."""
    ticks = _ticks(progress, stage, sum(map(len, groups)))
    # merged in the driver: merged on a worker, the 0.5 GB of EVT pass 2 of 10 station-years sat
    # twice on that worker besides its other tasks' memory (peak 4.46 GB against 4.02 GB, measured)
    return _merge_done(merge, *runner.map_reduce(task, groups, merge, ticks))


def _merge_done(merge: Callable, *parts: _Done) -> _Done:
    ok = [p.partial for p in parts if p.partial is not None]
    return _Done(
        merge(*ok) if ok else None,
        tuple(f for p in parts for f in p.failures),
        sum(p.cached for p in parts),
        sum(p.computed for p in parts),
    )


# --------------------------------------------------------------------------------------------------
# the driver


class _Local:
    """Tasks run in this process, one after the other."""

    def map_reduce(self, task, groups, merge, progress) -> list[_Done]:
        """One merged :class:`_Done` per group of task arguments."""
        out = []
        for items in groups:
            done = []
            for item in items:
                done.append(task(*item))
                if progress:
                    progress(1)
            out.append(_merge_done(merge, *done))
        return out

    def share(self, value):
        return value

    def imap(self, fn: Callable, items: list[tuple]) -> Iterator:
        """``fn(*item)`` for each item, in order, each as it is done."""
        return (fn(*item) for item in items)

    def starmap(self, fn: Callable, items: list[tuple]) -> list:
        """``[fn(*item) for item in items]``."""
        return [fn(*item) for item in items]


def _batch(task, merge, items) -> _Done:
    """``task`` on consecutive partitions, one after the other, merged: one Dask task for several
    partitions, so that the scheduler has fewer to place (its share of the cores is taken from the
    workers' on a small machine)."""
    return _merge_done(merge, *(task(*item) for item in items))


class _Dask:
    """Tasks run on a ``distributed.Client``; partials merge on the workers in a tree."""

    def __init__(self, client) -> None:
        self.client = client

    def map_reduce(self, task, groups, merge, progress) -> list[_Done]:
        """One merged :class:`_Done` per group of task arguments. The tasks and the merge trees are
        submitted at once, and only the roots are kept: each partial is released as soon as its
        group is merged, so that the workers hold a few groups of partials, never all of them."""
        import threading

        lock = threading.Lock()

        def ticks(n: int):
            def tick(_future) -> None:  # called in the client's thread as each task ends
                with lock:
                    progress(n)

            return tick

        roots = []
        for items in groups:
            batches = [items[i : i + BATCH] for i in range(0, len(items), BATCH)]
            level = [self.client.submit(_batch, task, merge, b, pure=False) for b in batches]
            if progress:
                for f, b in zip(level, batches, strict=True):
                    f.add_done_callback(ticks(len(b)))
            while len(level) > 1:  # consecutive groups: order kept, ties resolved as in one table
                level = [
                    self.client.submit(_merge_done, merge, *level[i : i + SPLIT_EVERY], pure=False)
                    for i in range(0, len(level), SPLIT_EVERY)
                ]
            roots.append(level[0] if level else None)
        return [r.result() if r is not None else _Done(None) for r in roots]

    def starmap(self, fn: Callable, items: list[tuple]) -> list:
        """``[fn(*item) for item in items]``, one task per item on the workers, in order."""
        return self.client.gather([self.client.submit(fn, *item, pure=False) for item in items])

    def imap(self, fn: Callable, items: list[tuple]) -> Iterator:
        """``fn(*item)`` for each item, one task per item on the workers, submitted at once and
        yielded in order as each is done (the driver works on one while the workers run the
        next); each result is released from the workers once yielded."""
        futures = [self.client.submit(fn, *item, pure=False) for item in items]
        for i in range(len(futures)):
            future, futures[i] = futures[i], None
            yield future.result()

    def share(self, value):
        # one object, under a key of its own: a dict would be scattered value by value under its own
        # keys ("vertical", ...), and two dicts with the same keys would overwrite each other
        return self.client.scatter([value], broadcast=True, hash=False)[0]


def runner_for(client) -> _Local | _Dask:
    """The runner of a campaign's tasks: on ``client`` (a ``distributed.Client``), or in this
    process when it is ``None``."""
    return _Local() if client is None else _Dask(client)


def count_campaign(
    dataset: str | Path,
    services: Sequence[ServiceLevel],
    *,
    client=None,
    cache: bool = True,
    histogram_bins: int = 200,
    time_range: Window = None,
    evidence: bool = False,
    progress: Callable[[str, int, int], None] | None = None,
) -> CampaignCounting:
    """The counting KPIs of every partition of ``dataset``, merged (see the module notes).

    ``client``: a ``distributed.Client`` (:func:`campaign_client`), or ``None`` to run in this
    process. ``time_range``: ``(start, stop)`` GPS times (naive, ``None`` for open), the epochs
    ``start <= time < stop`` only; days outside are not read. ``evidence``: also the counted
    evidence of the verdicts (its parts in pass 2, then one more pass for the values of its
    quantile bounds). ``progress(stage, done, total)`` is called as partitions are done.

    Raises
    ------
    InputError
        Not a dataset, no partition, or no partition could be read.
    """
    parts = partitions_in(dataset, time_range)
    if not parts:
        what = "in the time range" if time_range else "(ingest inputs first)"
        raise InputError(str(dataset), f"the dataset has no partition {what}")
    runner = runner_for(client)
    services = tuple(services)
    run = _Run(runner, dataset, services, runner.share(services), cache, histogram_bins, time_range, progress)
    while True:  # again without a partition that fails after pass 1 (its pass 1 is then cached)
        failed = {f.key for f in run.failures}
        result = run.passes(_by_station([p for p in parts if p.key not in failed]), evidence)
        if result is not None:
            break
    first, counting, found = result
    order = {p.key: i for i, p in enumerate(parts)}
    failures = tuple(sorted(set(run.failures), key=lambda f: order[f.key]))
    positions = {
        name: (float(entry["reference"][0]), float(entry["reference"][1]))
        for name, entry in read_manifest(dataset).get("stations", {}).items()
        if name in counting.stations and isinstance(entry.get("reference"), list)  # not "mean", "truth"
    }
    return CampaignCounting(
        counting,
        daily_availability(first, services),
        failures,
        len(parts),
        run.n_cached,
        run.n_computed,
        positions,
        found,
    )


@dataclass
class _Run:
    """One :func:`count_campaign`: its options, and the failures and cache use of its passes."""

    runner: object
    dataset: str | Path
    services: tuple[ServiceLevel, ...]
    shared_services: object
    cache: bool
    bins: int
    window: Window
    progress: Callable | None
    failures: tuple[PartitionFailure, ...] = ()
    n_cached: int = 0
    n_computed: int = 0

    def _draft(self, second: SecondPass, plan: SecondPlan, counting, drafts: dict[str, str]):
        """The evidence but its bounds: the stations taken whole from the pass-2 cache (no parts)
        from their cached draft, the others drafted from their parts, and their drafts cached."""
        done = {}
        for name, key in drafts.items():
            if name not in second.evidence:
                done[name] = _load_cached(_station_cache(self.dataset, name, "draft.pkl"), key)
                if done[name] is None:
                    raise RuntimeError(f"station {name}: its cached evidence draft went missing in the run")
        draft = evidence_draft(second, plan, counting, self.services, GAP_S, done)
        for name in second.evidence:
            if self.cache and name in drafts:
                value = (draft.stations[name], draft.partials[name])
                _store(_station_cache(self.dataset, name, "draft.pkl"), drafts[name], value)
        return draft

    def done(self, d: _Done) -> bool:
        """Count a pass's outcome; whether no partition failed in it."""
        self.failures += d.failures
        self.n_cached += d.cached
        self.n_computed += d.computed
        return not d.failures

    def passes(self, by_station: dict[str, list[Partition]], evidence: bool):
        """Every pass over the partitions ``by_station``: ``(first, counting, evidence)``, or
        ``None`` when a partition failed after pass 1 (run again without it)."""
        keys = {n: _station_key(ps, self.services, self.bins, self.window) for n, ps in by_station.items()}
        opts = {
            "cache": self.cache,
            "window": self.window,
            "progress": self.progress,
            "dataset": self.dataset,
        }
        one = _pass_one(self.runner, by_station, keys, self.shared_services, self.bins, **opts)
        self.done(one)
        first: FirstPass | None = one.partial
        if first is None or not first.stations:
            why = "; ".join(f"{f.station} {f.date}: {f.reason}" for f in self.failures[:3])
            raise InputError(str(self.dataset), f"no partition could be read ({why})")
        plan = plan_second(first, self.services)
        read = {label for st in first.stations.values() for label in st.labels}  # not failed, not empty
        by_station = {n: [p for p in ps if p.key in read] for n, ps in by_station.items()}
        by_station = {n: ps for n, ps in by_station.items() if ps}
        keys2 = {n: _key(keys[n], _plan_key(plan, first.stations[n].labels, n)) for n in by_station}
        drafts = {n: _draft_key(k, self.services) for n, k in keys2.items()} if evidence else None
        two = _pass_two(self.runner, by_station, keys2, plan, self.shared_services, drafts, **opts)
        if not self.done(two):
            return None
        second: SecondPass = two.partial or SecondPass({}, {})
        counting = finalize(first, second, plan, self.services, histogram_bins=self.bins)
        if not evidence:
            return first, counting, None
        draft = self._draft(second, plan, counting, drafts)
        # pass 3: the values of the evidence's accuracy bounds, whose quantile levels follow from
        # the effective sizes of pass 2's evidence parts
        if (found := bounds_from_second(first, plan, second, draft)) is not None:
            return first, counting, found  # pass 2's values hold the bounds' order statistics
        bounds, levels = bounds_plan(first, draft)
        three = _pass_bounds(self.runner, by_station, keys, bounds, **opts)
        if not self.done(three):
            return None
        return (
            first,
            counting,
            finish_evidence(first, draft, bounds, levels, three.partial or SecondPass({}, {})),
        )


def _pass_one(runner, by_station, keys, svc, bins, *, cache, window, progress, dataset) -> _Done:
    """Pass 1 of every station (:func:`_stations_pass`)."""
    return _stations_pass(
        runner,
        by_station,
        "pass1.pkl",
        keys.__getitem__,
        lambda name, ps: [(p, svc, bins, cache, _cut(p, window)) for p in ps],
        _first_task,
        merge_first,
        cache,
        _ticks(progress, "pass 1", sum(map(len, by_station.values()))),
        dataset,
    )


def _pass_two(runner, by_station, keys, plan, svc, drafts, *, cache, window, progress, dataset) -> _Done:
    """Pass 2 of the partitions read in pass 1, ``keys`` being each station's pass-2 key; with
    ``drafts`` (the key of each station's drafted evidence, :func:`_draft_key`) their evidence
    parts too. A station's cached values hold while they cover the plan's rank bins. Its evidence
    parts are not kept with them: a station is taken from the cache only with its cached draft,
    and otherwise from its partitions, whose parts hold while their error ranges hold its
    percentile bins."""
    shared_plan = runner.share(plan)
    evidence = drafts is not None

    def holds(name: str, stored) -> bool:
        if not covers(stored[0], plan, (name, "")):
            return False
        return not evidence or _cached_key(_station_cache(dataset, name, "draft.pkl")) == drafts[name]

    return _stations_pass(
        runner,
        by_station,
        "pass2.pkl",
        keys.__getitem__,
        lambda name, ps: [(p, shared_plan, svc, cache, _cut(p, window), evidence) for p in ps],
        _second_task,
        merge_second,
        cache,
        _ticks(progress, "pass 2", sum(map(len, by_station.values()))),
        dataset,
        check=holds,
        wrap=lambda name, partial: (station_targets(plan, name), dataclasses.replace(partial, evidence={})),
    )


def _draft_key(pass2_key: str, services) -> str:
    """What a station's drafted evidence depends on: its pass 2 (its data and plan), the services
    and the cluster gap."""
    return _key(pass2_key, _services_key(tuple(services)), GAP_S, "draft")


def _pass_bounds(runner, by_station, keys, plan, *, cache, window, progress, dataset) -> _Done:
    """Pass 3: the values of the evidence's quantile bounds; a station's stored values hold while
    they cover the plan's rank bins."""
    shared_plan = runner.share(plan)
    return _stations_pass(
        runner,
        by_station,
        "bounds.pkl",
        keys.__getitem__,
        lambda name, ps: [(p, shared_plan, cache, _cut(p, window)) for p in ps],
        _bounds_task,
        merge_second,
        cache,
        _ticks(progress, "pass 3", sum(map(len, by_station.values()))),
        dataset,
        check=lambda name, stored: covers(stored[0], plan, (name, "")),
        wrap=lambda name, partial: (station_targets(plan, name), partial),
    )


def uncached_partitions(
    dataset: str | Path,
    services: Sequence[ServiceLevel],
    *,
    histogram_bins: int = 200,
    time_range: Window = None,
) -> int:
    """How many partitions :func:`count_campaign` would read for pass 1 (its partial not cached):
    the work a cluster would be started for. Reads the cache keys only (no partition)."""
    parts = partitions_in(dataset, time_range)
    services = tuple(services)
    n = 0
    for name, ps in _by_station(parts).items():
        whole = _station_key(ps, services, histogram_bins, time_range)
        if _cached_key(_station_cache(dataset, name, "pass1.pkl")) == whole:
            continue
        for p in ps:
            key = _pass1_key(p, services, histogram_bins, _cut(p, time_range))
            n += _cached_key(_partition_cache(p, "pass1.pkl")) != key
    return n


def _cached_key(path: Path) -> str | None:
    """The key a cache file was stored under (``None``: no readable cache)."""
    return _load_cached(path, None)


def _partition_cache(partition: Partition, name: str) -> Path:
    """The cache file ``name`` of a partition's partials."""
    return partition.path.parent / _CACHE_DIR / name


def _station_cache(dataset: str | Path, station: str, name: str) -> Path:
    """The cache file ``name`` of a station's merged partials."""
    return Path(dataset) / f"station={station}" / _CACHE_DIR / name


def _by_station(parts: list[Partition]) -> dict[str, list[Partition]]:
    out: dict[str, list[Partition]] = {}
    for p in parts:
        out.setdefault(p.station, []).append(p)
    return out


def _station_key(parts: list[Partition], services, bins: int, window: Window) -> str:
    """What a station's merged pass 1 depends on: each partition's file key, and the options."""
    files = [(p.key, _file_key(p.path), _cut(p, window)) for p in parts]
    return _key(files, _services_key(services), bins)


def _plan_key(plan: SecondPlan, labels: list[str], station: str) -> str:
    """What a station's pass 2 reads from the plan besides the percentile bins (checked apart)."""
    mine = set(labels)
    return _key(
        plan.grids.get(station),
        plan.slots.get(station),
        sorted(plan.redo & mine),
        sorted(plan.drop_last & mine),
    )


def _stations_pass(
    runner,
    by_station: dict[str, list[Partition]],
    cache_name: str,
    station_key: Callable[[str], str],
    items: Callable[[str, list[Partition]], list[tuple]],
    task: Callable,
    merge: Callable,
    use_cache: bool,
    progress,
    dataset: str | Path,
    check: Callable[[str, object], bool] | None = None,
    wrap: Callable[[str, object], object] | None = None,
) -> _Done:
    """One pass over the stations. A station whose merged partial is in its cache
    (``<dataset>/station=ID/.overbound/<cache_name>``, under ``station_key``) is taken whole;
    the others run ``task`` per partition (each with its own cache), merged per station, and are
    cached when no partition failed. ``wrap(name, partial)`` is what is stored (the partial when
    ``None``) and ``check(name, stored)`` whether a stored one still holds, its partial being its
    last item. The stations' partials are merged in order."""
    hits, todo = {}, {}
    for name, ps in by_station.items():
        hit = (
            _load_cached(_station_cache(dataset, name, cache_name), station_key(name)) if use_cache else None
        )
        if hit is not None and (check is None or check(name, hit)):
            hits[name] = hit if wrap is None else hit[-1]
            if progress:
                progress(len(ps))
        else:
            todo[name] = ps
    results = runner.map_reduce(task, [items(n, ps) for n, ps in todo.items()], merge, progress)
    done = dict(zip(todo, results, strict=True))
    parts, failures, cached, computed = [], [], 0, 0
    for name, ps in by_station.items():
        if name in hits:
            parts.append(hits[name])
            cached += len(ps)
            continue
        d = done[name]
        failures.extend(d.failures)
        cached, computed = cached + d.cached, computed + d.computed
        if d.partial is None:
            continue
        parts.append(d.partial)
        if use_cache and not d.failures:
            value = d.partial if wrap is None else wrap(name, d.partial)
            _store(_station_cache(dataset, name, cache_name), station_key(name), value)
    return _Done(merge(*parts) if parts else None, tuple(failures), cached, computed)


def _ticks(progress, stage: str, total: int) -> Callable[[int], None] | None:
    """A counter calling ``progress(stage, done, total)``."""
    if progress is None:
        return None
    done = [0]

    def step(n: int) -> None:
        done[0] += n
        progress(stage, done[0], total)

    return step
