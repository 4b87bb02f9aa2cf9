r"""Counted evidence for the verdicts: the counts of the epoch table with exact bounds that
account for the dependence between epochs, and the safety-index tail counts that the tail
models are checked against.

Everything here is counted, never fitted. The verdict module (:mod:`overbound.verdict`) weighs
it against the requirements and against the models of :mod:`overbound.methods`.

Dependence, stated per quantity
-------------------------------
* **Availability** and **accuracy**: an *effective sample size* :math:`N/\tau`, with
  :math:`\tau` the integrated autocorrelation time of the 0/1 series that is counted
  (available or not; error above the 95th percentile or not), by Geyer's initial positive
  sequence (:func:`overbound.stats.proportion.integrated_autocorrelation`), per station and summed.
  A series that never changes carries no measure of its dependence: one independent sample per
  ``fallback_s`` (3600 s) is assumed then.
* **Continuity**: the *loss events as the trials* (Kannemans 2006, section 2.1.4: the
  "decorrelation factor" is the number of failing windows per event): a loss is an available epoch
  followed by an unavailable or missing one; losses closer than the window join one event.
* **MI and HMI**: *clusters as the events* (runs declustering with gap ``gap_s``, 360 s by
  default, the independence spacing of Comby et al. 2003); their rate per second of available
  time is bounded by the exact Poisson bounds.

By partition
------------
Everything here is computed from :class:`EvidencePart` s, the reduction of a piece of a station's
epochs (:func:`evidence_part`): the 0/1 series packed 8 to a byte (the effective sizes need the
whole series of a station: its integrated autocorrelation, by block means beyond 2**18 values),
the loss, MI, HMI and safety-index events as :class:`Runs` (count, first and last time, and the
gaps wider than the cluster gap, joined across the pieces' boundaries as the events of one
table), and which errors exceed the station's 95th percentile (:class:`ErrorsAbove`, known before
the percentile is). A table is one piece per station; a campaign dataset one per station-day
(:mod:`overbound.methods.counting_partitions`), with the same result to the last bit. The accuracy
bounds, quantiles of the errors at levels that follow from the effective sizes, are taken last
(:class:`EvidenceDraft`): from the table, or by the exact second pass of the partitions.

Stations are taken as independent: their sample sizes and event counts add up. For an SBAS
network this is optimistic for availability (the stations share the broadcast corrections and
much of the geometry); the per-station evidence is kept next to the pooled one for that reason.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
import polars as pl

from overbound.io.schema import InputError
from overbound.methods.counting import (
    CountingResult,
    EpochArrays,
    _station_slices,
    epoch_arrays,
    safety_values,
)
from overbound.services import ServiceLevel
from overbound.stats.dependence import nominal_interval_us
from overbound.stats.proportion import Bounds, clopper_pearson, integrated_autocorrelation

__all__ = [
    "GAP_S",
    "SI_LEVELS",
    "CountedAvailability",
    "CountedContinuity",
    "CountedEvents",
    "CountedQuantile",
    "ErrorsAbove",
    "Evidence",
    "EvidenceDraft",
    "EvidencePart",
    "StationEvidence",
    "TailCounts",
    "counted_evidence",
    "draft_evidence",
    "error_range",
    "evidence_part",
]

#: Runs declustering gap of the MI, HMI and safety-index clusters (s): the independence spacing of
#: Comby et al. 2003.
GAP_S = 360.0
#: Safety-index levels at which the tail models' predictions are checked against the counts.
SI_LEVELS = (0.3, 0.5, 0.7)
_AXES = ("horizontal", "vertical")


@dataclass(frozen=True, slots=True)
class CountedAvailability:
    """Counted availability of one service (both axes), with its bounds.

    ``n_available`` of ``n`` epochs; ``n_effective`` independent samples (``tau_s`` the integrated
    autocorrelation time, ``assumed`` when it could not be measured); ``bounds`` one-sided
    Clopper-Pearson bounds of the proportion with ``n_effective`` trials.
    """

    n: int
    n_available: int
    n_effective: float
    tau_s: float
    assumed: bool
    bounds: Bounds


@dataclass(frozen=True, slots=True)
class CountedContinuity:
    """Counted continuity risk per window: the counting's windows and failures, the loss events
    as the trials, ``bounds`` the Clopper-Pearson bounds of ``n_events`` out of
    ``n_windows / windows_per_event`` trials. ``reason`` when the risk cannot be counted."""

    window_s: float
    n_windows: int
    n_fail: int
    n_events: int
    windows_per_event: float
    bounds: Bounds | None
    reason: str = ""


@dataclass(frozen=True, slots=True)
class CountedQuantile:
    """The 95th percentile of an error with order-statistic bounds from ``n_effective`` samples."""

    q: float
    n: int
    n_effective: float
    estimate: float | None
    lower: float | None
    upper: float | None


@dataclass(frozen=True, slots=True)
class CountedEvents:
    """Epochs and clusters (runs with gap ``gap_s``) of an event, over ``exposure_s`` seconds of
    available time (the time in which the event could happen)."""

    epochs: int
    clusters: int
    exposure_s: float
    gap_s: float


@dataclass(frozen=True, slots=True)
class TailCounts:
    """Counts of the safety index PE/PL of one axis (epochs with a solution, not alerted).

    ``epochs_above[i]`` and ``clusters_above[i]`` count the epochs and the clusters (runs with gap
    ``gap_s``) with SI > ``levels[i]``; ``max_si`` and ``time_of_max`` the largest value.
    """

    axis: str
    levels: tuple[float, ...]
    n_epochs: int
    epochs_above: tuple[int, ...]
    clusters_above: tuple[int, ...]
    max_si: float | None
    time_of_max: str | None
    gap_s: float

    def mean_cluster_size(self, i: int) -> float:
        """Epochs per cluster above ``levels[i]`` (1 where nothing exceeds it)."""
        c = self.clusters_above[i]
        return self.epochs_above[i] / c if c else 1.0


@dataclass(frozen=True, slots=True)
class ServiceEvidence:
    """The counted evidence of one service: availability, continuity, and per axis the MI
    (PE > PL while PL < AL, HMI included) and HMI (PE > AL while PL < AL) events."""

    availability: CountedAvailability
    continuity: CountedContinuity
    mi: dict[str, CountedEvents]
    hmi: dict[str, CountedEvents]


@dataclass(frozen=True, slots=True)
class StationEvidence:
    """The counted evidence of one station, or of the pooled stations."""

    name: str
    n_epochs: int
    interval_s: float | None
    accuracy: dict[str, CountedQuantile]
    tails: dict[str, TailCounts]
    services: dict[str, ServiceEvidence]


@dataclass(frozen=True, slots=True)
class Evidence:
    """Pooled evidence (``pooled``) and, with several stations, the evidence of each."""

    pooled: StationEvidence
    by_station: dict[str, StationEvidence]
    confidence: float


# --------------------------------------------------------------------------------------------------
# pure functions over arrays


def run_clusters(time_s: np.ndarray, gap_s: float) -> int:
    """Number of runs of sorted event times in which consecutive events are at most ``gap_s`` apart."""
    if time_s.size == 0:
        return 0
    return 1 + int(np.count_nonzero(np.diff(time_s) > gap_s))


def effective_size(flags: np.ndarray, interval_s: float, fallback_s: float) -> tuple[float, float, bool]:
    """``(n_effective, tau_s, assumed)`` of a 0/1 series (see the module notes)."""
    n = flags.size
    if n == 0:
        return 0.0, math.nan, True
    k = int(np.count_nonzero(flags))
    if k in (0, n):
        tau = max(1.0, fallback_s / interval_s)
        return max(1.0, n / tau), tau * interval_s, True
    tau = integrated_autocorrelation(flags)
    return n / tau, tau * interval_s, False


def loss_events(time_s: np.ndarray, available: np.ndarray, interval_s: float, window_s: float) -> int:
    """Loss-of-service events: an available epoch followed by an unavailable or missing one
    (the next epoch more than 1.5 intervals later); losses within ``window_s`` of the previous
    one join its event. The last epoch of the data is no loss."""
    if time_s.size < 2:
        return 0
    nxt_ok = available[1:] & (np.diff(time_s) <= 1.5 * interval_s)
    loss = available[:-1] & ~nxt_ok
    return run_clusters(time_s[:-1][loss], window_s)


def quantile_bounds(
    x: np.ndarray, q: float, n_effective: float, confidence: float, estimate: float | None = None
) -> CountedQuantile:
    """The ``q`` quantile of ``x`` (numpy's linear interpolation; ``estimate`` when the caller has it)
    and its order-statistic bounds: the quantiles at the Clopper-Pearson bounds of the level ``q``
    with ``n_effective`` trials."""
    if x.size == 0:
        return CountedQuantile(q, 0, 0.0, None, None, None)
    b = clopper_pearson(q * n_effective, n_effective, confidence)
    if estimate is None:
        lo, est, hi = np.quantile(x, [b.lower, q, b.upper])
    else:
        (lo, hi), est = np.quantile(x, [b.lower, b.upper]), estimate
    return CountedQuantile(q, int(x.size), n_effective, float(est), float(lo), float(hi))


# --------------------------------------------------------------------------------------------------
# partial results: what one piece of a station's epochs (the station, or one of its partitions)
# contributes; pieces of a station join in time order, exactly as the station's table


class Runs(NamedTuple):
    """Sorted event times (µs) reduced for runs declustering: ``n`` events from ``first`` to
    ``last``, ``breaks`` of the consecutive ones more than the gap apart. Consecutive pieces join
    (:meth:`then`) as :func:`run_clusters` of their times together. (A tuple: a station-year's
    evidence holds some 8,000 of them per station, cached and read back.)"""

    n: int
    first: int
    last: int
    breaks: int

    @property
    def clusters(self) -> int:
        return self.breaks + 1 if self.n else 0

    def then(self, later: Runs, gap_s: float) -> Runs:
        """These runs followed by ``later`` (all of whose times come after)."""
        if not later.n or not self.n:
            return later if self.n == 0 else self
        apart = later.first / 1e6 - self.last / 1e6 > gap_s  # as np.diff of the times in seconds
        return Runs(self.n + later.n, self.first, later.last, self.breaks + later.breaks + int(apart))


_NO_RUNS = Runs(0, 0, 0, 0)


def runs(t_us: np.ndarray, gap_s: float) -> Runs:
    """:class:`Runs` of the sorted event times ``t_us``."""
    if t_us.size == 0:
        return _NO_RUNS
    return Runs(int(t_us.size), int(t_us[0]), int(t_us[-1]), run_clusters(t_us / 1e6, gap_s) - 1)


@dataclass(frozen=True, slots=True)
class Flags:
    """A 0/1 series, 8 values per byte (a station-year at 1 Hz: 4 MB)."""

    bits: np.ndarray
    n: int

    @classmethod
    def of(cls, flags: np.ndarray) -> Flags:
        return cls(np.packbits(flags), int(flags.size))

    @staticmethod
    def joined(pieces: Sequence[Flags]) -> np.ndarray:
        """The pieces' series one after the other, as booleans."""
        out = [np.unpackbits(p.bits, count=p.n).view(np.bool_) for p in pieces]
        return np.concatenate(out) if out else np.zeros(0, np.bool_)


@dataclass(frozen=True, slots=True)
class _Loss:
    """One availability mask of a piece: its flags, the losses between its own epochs, and
    whether its first and last epochs are available (a loss may fall on the join)."""

    flags: Flags
    losses: Runs
    first_up: bool
    last_up: bool


@dataclass(frozen=True, slots=True)
class ErrorsAbove:
    """Which errors of a piece (over its epochs with a solution) exceed the station's 95th
    percentile :math:`q`, before :math:`q` is known: ``above`` those at or above ``hi``, and the
    ``index`` and ``value`` of those in ``[lo, hi)``, the range :math:`q` is known to lie in (the
    bins of its order statistics and their neighbours, :func:`error_range`)."""

    above: Flags
    lo: float
    hi: float
    index: np.ndarray
    value: np.ndarray

    @classmethod
    def of(cls, err: np.ndarray, lo: float, hi: float) -> ErrorsAbove:
        near = np.flatnonzero((err >= lo) & (err < hi))
        return cls(Flags.of(err >= hi), lo, hi, near, err[near])

    def holds(self, q: float) -> bool:
        """Whether the flags of ``q`` can be told from these (``lo <= q < hi``)."""
        return self.lo <= q < self.hi


def error_range(q: float | None) -> tuple[float, float]:
    """The range of :class:`ErrorsAbove` when :math:`q` is known: the errors ``> q`` are those
    ``>= nextafter(q)``. No percentile (no error): an empty range at infinity."""
    if q is None:
        return (math.inf, math.inf)
    return (q, float(np.nextafter(q, math.inf)))


@dataclass(frozen=True, slots=True)
class _Tail:
    """The safety index of one axis in a piece: epochs with one, runs above each of
    :data:`SI_LEVELS`, and the largest with its time (the first on a tie)."""

    n: int
    above: tuple[Runs, ...]
    max: tuple[float, int] | None


@dataclass(frozen=True, slots=True)
class EvidencePart:
    """What one piece of a station's epochs (sorted by time) contributes to its evidence
    (:func:`evidence_part`).

    ``loss`` per mask ``(HAL, VAL, window)``; ``events`` per ``(axis, AL)``: MI runs, HMI runs and
    the epochs available on that axis; ``accuracy`` per axis: which errors exceed the station's 95th
    percentile, over the epochs with a solution (:class:`ErrorsAbove`); ``tails`` per axis.
    """

    n: int
    t_first: int
    t_last: int
    loss: dict[tuple, _Loss]
    events: dict[tuple[str, float], tuple[Runs, Runs, int]]
    accuracy: dict[str, ErrorsAbove]
    tails: dict[str, _Tail]


def _mask_key(s: ServiceLevel) -> tuple:
    return (s.hal, s.val, s.continuity_window_s)


def evidence_part(
    x: EpochArrays,
    services: Sequence[ServiceLevel],
    interval_s: float | None,
    q95: Mapping[str, tuple[float, float]],
    gap_s: float = GAP_S,
) -> EvidencePart:
    """The :class:`EvidencePart` of one station's epochs ``x`` (or a piece of them, in time order).

    ``interval_s`` is the station's nominal interval (``None``: unknown); ``q95`` per axis a range
    ``[lo, hi)`` that holds the station's 95th percentile of the error
    (:attr:`CountingResult.hpe95`, ``vpe95``; :func:`error_range` of it when known).
    """
    t_us = x.time_us
    n = int(t_us.size)
    interval = interval_s or 1.0
    next_ok = np.diff(t_us / 1e6) <= 1.5 * interval  # the next epoch is not missing
    loss = {}
    for s in services:
        key = _mask_key(s)
        if key in loss:
            continue
        up = x.pls["horizontal"] < s.hal
        if s.val is not None:
            up &= x.pls["vertical"] < s.val
        lost = up[:-1] & ~(up[1:] & next_ok)
        loss[key] = _Loss(Flags.of(up), runs(t_us[:-1][lost], key[2]), bool(n and up[0]), bool(n and up[-1]))
    events = {}
    for s in services:
        for a in _AXES:
            al = s.alert_limit(a)
            if al is None or (a, al) in events:
                continue
            pe, pl_ = x.pe[a], x.pls[a]
            avail = (pl_ < al) & x.ok
            mi, hmi = avail & (pe > pl_), avail & (pe > al)
            events[(a, al)] = (runs(t_us[mi], gap_s), runs(t_us[hmi], gap_s), int(np.count_nonzero(avail)))
    accuracy = {a: ErrorsAbove.of(x.pe[a][x.ok], *q95[a]) for a in _AXES}
    tails = {a: _tail(t_us, *safety_values(x.pe[a], x.si_pls[a]), gap_s) for a in _AXES}
    first, last = (int(t_us[0]), int(t_us[-1])) if n else (0, 0)
    return EvidencePart(n, first, last, loss, events, accuracy, tails)


def _tail(t_us: np.ndarray, ok: np.ndarray, si: np.ndarray, gap_s: float) -> _Tail:
    t = t_us[ok]
    above = tuple(runs(t[si > level], gap_s) for level in SI_LEVELS)
    if si.size == 0:
        return _Tail(0, above, None)
    i = int(np.argmax(si))
    return _Tail(int(si.size), above, (float(si[i]), int(t[i])))


# --------------------------------------------------------------------------------------------------
# one station from its pieces, then the pooled stations


def _join_losses(parts: Sequence[EvidencePart], key: tuple, interval: float) -> Runs:
    """The loss events of one mask over consecutive pieces: a loss falls on each join where the
    last epoch before it is available and the first after it is not, or is missing."""
    window = key[2]
    out = parts[0].loss[key].losses
    for prev, nxt in itertools.pairwise(parts):
        a, b = prev.loss[key], nxt.loss[key]
        next_ok = b.first_up and nxt.t_first / 1e6 - prev.t_last / 1e6 <= 1.5 * interval
        if a.last_up and not next_ok:
            out = out.then(Runs(1, prev.t_last, prev.t_last, 0), window)
        out = out.then(b.losses, window)
    return out


def _joined_runs(pieces: Sequence[Runs], gap_s: float) -> Runs:
    out = _NO_RUNS
    for r in pieces:
        out = out.then(r, gap_s)
    return out


def _iso(t_s: float) -> str:
    return str(np.datetime64(round(t_s * 1e6), "us").astype("datetime64[ms]"))


def _station_tail(parts: Sequence[EvidencePart], axis: str, gap_s: float) -> TailCounts:
    tails = [p.tails[axis] for p in parts]
    above = [_joined_runs([t.above[i] for t in tails], gap_s) for i in range(len(SI_LEVELS))]
    best = None
    for t in tails:  # the earlier piece on a tie, as argmax of the station's series
        if t.max is not None and (best is None or t.max[0] > best[0]):
            best = t.max
    return TailCounts(
        axis,
        SI_LEVELS,
        sum(t.n for t in tails),
        tuple(r.n for r in above),
        tuple(r.clusters for r in above),
        None if best is None else best[0],
        None if best is None else _iso(best[1] / 1e6),
        gap_s,
    )


def _events_of(parts: Sequence[EvidencePart], key: tuple[str, float], gap_s: float, interval_s: float | None):
    mi = _joined_runs([p.events[key][0] for p in parts], gap_s)
    hmi = _joined_runs([p.events[key][1] for p in parts], gap_s)
    exposure = float(sum(p.events[key][2] for p in parts)) * (interval_s or 0.0)
    return CountedEvents(mi.n, mi.clusters, exposure, gap_s), CountedEvents(
        hmi.n, hmi.clusters, exposure, gap_s
    )


_PENDING = CountedQuantile(0.95, 0, 0.0, None, None, None)


def _station(
    name: str,
    parts: Sequence[EvidencePart],
    interval_s: float | None,
    counting: CountingResult,
    services: Sequence[ServiceLevel],
    gap_s: float,
    fallback_s: float,
    confidence: float,
) -> tuple[StationEvidence, dict]:
    """One station's evidence from its pieces (accuracy bounds pending), and its partial."""
    parts = [p for p in parts if p.n] or list(parts[:1])
    interval = interval_s or 1.0
    partial: dict = {}
    out: dict[str, ServiceEvidence] = {}
    sizes: dict[tuple, tuple] = {}  # services with the same limits and window (APV-I, LPV) count once
    for s in services:
        key = _mask_key(s)
        if key not in sizes:
            flags = Flags.joined([p.loss[key].flags for p in parts])
            n_eff, tau_s, assumed = effective_size(flags, interval, fallback_s)
            events = _join_losses(parts, key, interval).clusters if flags.size > 1 else 0
            sizes[key] = (flags.size, n_eff, tau_s, assumed, events)
        size, n_eff, tau_s, assumed, events = sizes[key]
        partial[s.name] = _Partial(size, n_eff, tau_s, assumed, events)
        mi, hmi = {}, {}
        for a in _AXES:
            al = s.alert_limit(a)
            if al is not None:
                mi[a], hmi[a] = _events_of(parts, (a, al), gap_s, interval_s)
        k = counting.services[s.name]
        out[s.name] = ServiceEvidence(
            _availability(k.combined.n_available, size, n_eff, tau_s, assumed, confidence),
            _continuity(k.combined.continuity, events, confidence),
            mi,
            hmi,
        )
    for a in _AXES:
        flags = _errors_above(parts, a, _q95(counting, a))
        n_eff = effective_size(flags, interval, fallback_s)[0] if flags.size else 0.0
        partial[("accuracy", a)] = (int(flags.size), n_eff)
    tails = {a: _station_tail(parts, a, gap_s) for a in _AXES}
    acc = dict.fromkeys(_AXES, _PENDING)
    return StationEvidence(name, sum(p.n for p in parts), interval_s, acc, tails, out), partial


def _errors_above(parts: Sequence[EvidencePart], axis: str, q: float | None) -> np.ndarray:
    """The station's 0/1 series of its errors above its 95th percentile ``q``."""
    pieces = [p.accuracy[axis] for p in parts]
    flags = Flags.joined([e.above for e in pieces])
    start = 0
    for e in pieces:
        if e.value.size:
            if q is None or not e.holds(q):
                raise ValueError(f"the 95th percentile {q} is outside the range [{e.lo}, {e.hi}) of a part")
            flags[start + e.index[e.value > q]] = True
        start += e.above.n
    return flags


@dataclass
class _Partial:
    """What one station contributes, before the pooled bounds are taken."""

    n: int = 0
    n_eff: float = 0.0
    tau_s: float = 0.0
    assumed: bool = False
    events: int = 0


def _availability(k: int, n: int, n_eff: float, tau_s: float, assumed: bool, c: float) -> CountedAvailability:
    if n == 0:
        return CountedAvailability(0, 0, 0.0, math.nan, True, Bounds(math.nan, 0.0, 1.0, c))
    n_eff = min(max(n_eff, 1.0), float(n))
    b = clopper_pearson(k / n * n_eff, n_eff, c)
    return CountedAvailability(n, k, n_eff, tau_s, assumed, Bounds(k / n, b.lower, b.upper, c))


def _continuity(cont, events: int, c: float) -> CountedContinuity:
    if cont is None:
        return CountedContinuity(math.nan, 0, 0, events, math.nan, None, "not counted")
    if cont.risk is None or cont.n_windows == 0:
        return CountedContinuity(
            cont.window_s, cont.n_windows, cont.n_fail, events, math.nan, None, cont.reason or "no windows"
        )
    per_event = cont.n_fail / events if events and cont.n_fail else cont.window_s / (cont.interval_s or 1.0)
    per_event = max(per_event, 1.0)
    trials = max(cont.n_windows / per_event, 1.0)
    k = min(float(events) if cont.n_fail else 0.0, trials)
    b = clopper_pearson(k, trials, c)
    return CountedContinuity(
        cont.window_s, cont.n_windows, cont.n_fail, events, per_event, Bounds(cont.risk, b.lower, b.upper, c)
    )


def _merge_tails(parts: list[TailCounts], axis: str, gap_s: float) -> TailCounts:
    best = max((p for p in parts if p.max_si is not None), key=lambda p: p.max_si, default=None)
    return TailCounts(
        axis,
        SI_LEVELS,
        sum(p.n_epochs for p in parts),
        tuple(int(x) for x in np.sum([p.epochs_above for p in parts], axis=0)),
        tuple(int(x) for x in np.sum([p.clusters_above for p in parts], axis=0)),
        None if best is None else best.max_si,
        None if best is None else best.time_of_max,
        gap_s,
    )


def _merge_events(parts: list[CountedEvents]) -> CountedEvents:
    return CountedEvents(
        sum(p.epochs for p in parts),
        sum(p.clusters for p in parts),
        sum(p.exposure_s for p in parts),
        parts[0].gap_s,
    )


def _pool(stations: dict, partials: dict, counting: CountingResult, services, gap_s, c) -> StationEvidence:
    names = list(stations)
    out = {}
    for s in services:
        ps = [partials[n][s.name] for n in names]
        k = counting.services[s.name]
        evs = [stations[n].services[s.name] for n in names]
        out[s.name] = ServiceEvidence(
            _availability(
                k.combined.n_available,
                sum(p.n for p in ps),
                sum(p.n_eff for p in ps),
                max(p.tau_s for p in ps),
                any(p.assumed for p in ps),
                c,
            ),
            _continuity(k.combined.continuity, sum(p.events for p in ps), c),
            {a: _merge_events([e.mi[a] for e in evs]) for a in evs[0].mi},
            {a: _merge_events([e.hmi[a] for e in evs]) for a in evs[0].hmi},
        )
    tails = {a: _merge_tails([stations[n].tails[a] for n in names], a, gap_s) for a in _AXES}
    intervals = {st.interval_s for st in stations.values()}
    interval = intervals.pop() if len(intervals) == 1 else None
    acc = dict.fromkeys(_AXES, _PENDING)
    return StationEvidence("pooled", sum(st.n_epochs for st in stations.values()), interval, acc, tails, out)


# --------------------------------------------------------------------------------------------------
# the evidence, in two steps: everything but the accuracy bounds, whose quantile levels follow
# from the effective sizes; then those quantiles, from the table or from another pass over
# the partitions


@dataclass(frozen=True)
class EvidenceDraft:
    """The evidence but for the values of the accuracy bounds (:func:`draft_evidence`).

    ``accuracy`` per ``(scope, axis)`` (scope: a station, or ``""`` for the pooled stations when
    there are several): errors counted, effective size, and the 95th percentile counted.
    ``partials``: what each station adds to the pooled evidence (with its entry of ``stations``,
    all a re-analysis needs of a station whose data did not change: ``draft_evidence(done=)``).
    """

    stations: dict[str, StationEvidence]
    pooled: StationEvidence | None
    accuracy: dict[tuple[str, str], tuple[int, float, float | None]]
    confidence: float
    partials: dict[str, dict] = field(default_factory=dict)

    def levels(self) -> dict[tuple[str, str], tuple[float, float]]:
        """The quantile levels (0-1) of the bounds of each ``(scope, axis)`` with errors: the
        one-sided Clopper-Pearson bounds of the level 0.95 with the effective size as trials."""
        out = {}
        for key, (n, n_eff, _q) in self.accuracy.items():
            if n:
                b = clopper_pearson(0.95 * n_eff, n_eff, self.confidence)
                out[key] = (b.lower, b.upper)
        return out

    def evidence(self, values: Mapping[tuple[str, str], Sequence[float]]) -> Evidence:
        """The evidence, ``values`` being the errors' quantiles at :meth:`levels` of each scope."""

        def done(scope: str, st: StationEvidence) -> StationEvidence:
            acc = {}
            for a in _AXES:
                n, n_eff, q = self.accuracy[(scope, a)]
                lo, hi = values[(scope, a)] if n else (None, None)
                acc[a] = CountedQuantile(
                    0.95, n, n_eff, None if q is None else float(q), _float(lo), _float(hi)
                )
            return replace(st, accuracy=acc)

        stations = {name: done(name, st) for name, st in self.stations.items()}
        if self.pooled is None:
            return Evidence(next(iter(stations.values())), {}, self.confidence)
        return Evidence(done("", self.pooled), stations, self.confidence)


def _float(v) -> float | None:
    return None if v is None else float(v)


def draft_evidence(
    parts: Mapping[str, Sequence[EvidencePart]],
    intervals: Mapping[str, float | None],
    counting: CountingResult,
    services: Sequence[ServiceLevel],
    *,
    gap_s: float = GAP_S,
    fallback_s: float = 3600.0,
    confidence: float = 0.95,
    done: Mapping[str, tuple[StationEvidence, dict]] | None = None,
) -> EvidenceDraft:
    """The :class:`EvidenceDraft` of stations given as their pieces in time order (stations in
    table order, ``parts`` holding all), with their nominal intervals (s). ``done``: stations
    already drafted (their ``stations`` entry and ``partials``, from an earlier draft of the same
    data and options), whose pieces are not needed (empty)."""
    stations, partials, accuracy = {}, {}, {}
    done = done or {}
    for name, ps in parts.items():
        c = counting.by_station.get(name, counting)
        if name in done:
            stations[name], partials[name] = done[name]
        else:
            stations[name], partials[name] = _station(
                name, ps, intervals[name], c, services, gap_s, fallback_s, confidence
            )
        for a in _AXES:
            accuracy[(name, a)] = (*partials[name][("accuracy", a)], _q95(c, a))
    if len(stations) == 1:
        return EvidenceDraft(stations, None, accuracy, confidence, partials)
    for a in _AXES:
        xs = [partials[n][("accuracy", a)] for n in stations]
        accuracy[("", a)] = (sum(v[0] for v in xs), sum(v[1] for v in xs), _q95(counting, a))
    pooled = _pool(stations, partials, counting, services, gap_s, confidence)
    return EvidenceDraft(stations, pooled, accuracy, confidence, partials)


def _q95(counting: CountingResult, axis: str) -> float | None:
    return counting.hpe95 if axis == "horizontal" else counting.vpe95


def counted_evidence(
    table: pl.DataFrame,
    counting: CountingResult,
    services: Sequence[ServiceLevel],
    *,
    gap_s: float = GAP_S,
    fallback_s: float = 3600.0,
    confidence: float = 0.95,
) -> Evidence:
    """The counted evidence of ``table`` for each of ``services`` (see the module notes).

    ``counting`` is :func:`~overbound.methods.counting.count_kpis` of the same table: its available
    epochs and continuity windows are the ones bounded here, so that a verdict can never
    contradict the counted KPI. Bounds are one-sided at ``confidence`` each. A campaign dataset
    gets the same evidence by partition (:func:`evidence_part` per partition, joined per station).
    """
    x = epoch_arrays(table)
    if x.time_us is None:
        raise InputError("<epoch table>", "the counted evidence needs the epochs' times")
    slices = _station_slices(table) or {"": slice(None)}  # an empty table: one empty station
    pieces, intervals, errors = {}, {}, {}
    for name, rows in slices.items():
        xs = x if isinstance(rows, slice) else _take(x, rows)
        step = nominal_interval_us(xs.time_us)
        intervals[name] = None if step is None else step / 1e6
        c = counting.by_station.get(name, counting)
        q95 = {a: error_range(_q95(c, a)) for a in _AXES}
        pieces[name] = [evidence_part(xs, services, intervals[name], q95, gap_s)]
        errors[name] = {a: xs.pe[a][xs.ok] for a in _AXES}
    draft = draft_evidence(
        pieces, intervals, counting, services, gap_s=gap_s, fallback_s=fallback_s, confidence=confidence
    )
    values = {}
    for (scope, a), levels in draft.levels().items():
        err = errors[scope][a] if scope else np.concatenate([e[a] for e in errors.values()])
        values[(scope, a)] = np.quantile(err, list(levels))
    return draft.evidence(values)


def _take(x: EpochArrays, rows: np.ndarray) -> EpochArrays:
    """The epochs ``rows`` of ``x``."""

    def pick(d: dict) -> dict:
        return {a: v[rows] for a, v in d.items()}

    return EpochArrays(pick(x.pe), pick(x.pls), pick(x.si_pls), x.ok[rows], x.time_us[rows])
