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

Stations are taken as independent: their sample sizes and event counts add up. For an SBAS
network this is optimistic for availability (the stations share the broadcast corrections and
much of the geometry); the per-station evidence is kept next to the pooled one for that reason.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import polars as pl

from overbound.io.schema import as_numpy
from overbound.methods.counting import CountingResult, _station_slices
from overbound.services import ServiceLevel
from overbound.stats.dependence import nominal_interval_us
from overbound.stats.proportion import Bounds, clopper_pearson, integrated_autocorrelation

__all__ = [
    "SI_LEVELS",
    "CountedAvailability",
    "CountedContinuity",
    "CountedEvents",
    "CountedQuantile",
    "Evidence",
    "StationEvidence",
    "TailCounts",
    "counted_evidence",
]

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
# the table


@dataclass(frozen=True, slots=True)
class _Arrays:
    """Views of one station's columns (copies only where a value changes: |VPE|, alerted PLs)."""

    t_us: np.ndarray
    pe: dict[str, np.ndarray]
    pl: dict[str, np.ndarray]  # alerted epochs: inf
    alert: np.ndarray | None
    solution: np.ndarray
    interval_s: float | None

    def si(self, axis: str) -> np.ndarray:
        """Safety index PE/PL; NaN without a solution, with PL <= 0 or alerted."""
        pe, pl_ = self.pe[axis], self.pl[axis]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = pe / pl_
        bad = ~(np.isfinite(pe) & (pl_ > 0) & np.isfinite(pl_))
        if self.alert is not None:
            bad |= self.alert
        s[bad] = np.nan
        return s


def _arrays(table: pl.DataFrame, rows) -> _Arrays:
    t_us = as_numpy(table["time"])[rows]
    pe = {"horizontal": as_numpy(table["hpe"])[rows], "vertical": np.abs(as_numpy(table["vpe"])[rows])}
    pls = {"horizontal": as_numpy(table["hpl"])[rows], "vertical": as_numpy(table["vpl"])[rows]}
    alert = None
    if "alert" in table.columns and table["alert"].any():
        alert = as_numpy(table["alert"].fill_null(False))[rows]
        pls = {a: np.where(alert & ~np.isnan(x), np.inf, x) for a, x in pls.items()}
    # as in count_kpis: an alerted epoch (PL infinite) has no solution
    solution = np.isfinite(pe["horizontal"]) & np.isfinite(pls["horizontal"])
    solution &= np.isfinite(pe["vertical"]) & np.isfinite(pls["vertical"])
    step = nominal_interval_us(t_us)
    return _Arrays(t_us, pe, pls, alert, solution, None if step is None else step / 1e6)


def _tail_counts(d: _Arrays, axis: str, gap_s: float) -> TailCounts:
    si = d.si(axis)
    ok = ~np.isnan(si)
    n = int(np.count_nonzero(ok))
    epochs, clusters = [], []
    for level in SI_LEVELS:  # three levels
        above = si > level  # NaN compares False
        epochs.append(int(np.count_nonzero(above)))
        clusters.append(run_clusters(d.t_us[above] / 1e6, gap_s))
    if n:
        mx = float(np.fmax.reduce(si))  # NaN-skipping maximum without nanargmax's copy
        i = int(np.argmax(si == mx))
        tmax = _iso(d.t_us[i] / 1e6)
    else:
        mx, tmax = None, None
    return TailCounts(axis, SI_LEVELS, n, tuple(epochs), tuple(clusters), mx, tmax, gap_s)


def _iso(t_s: float) -> str:
    return str(np.datetime64(round(t_s * 1e6), "us").astype("datetime64[ms]"))


def _events(d: _Arrays, axis: str, al: float, gap_s: float) -> tuple[CountedEvents, CountedEvents]:
    pe, pl_ = d.pe[axis], d.pl[axis]
    avail = (pl_ < al) & d.solution
    exposure = float(np.count_nonzero(avail)) * (d.interval_s or 0.0)
    mi = avail & (pe > pl_)
    hmi = avail & (pe > al)
    return (
        CountedEvents(int(np.count_nonzero(mi)), run_clusters(d.t_us[mi] / 1e6, gap_s), exposure, gap_s),
        CountedEvents(int(np.count_nonzero(hmi)), run_clusters(d.t_us[hmi] / 1e6, gap_s), exposure, gap_s),
    )


def _available(d: _Arrays, s: ServiceLevel) -> np.ndarray:
    ok = d.pl["horizontal"] < s.hal
    if s.val is not None:
        ok &= d.pl["vertical"] < s.val
    return ok


@dataclass
class _Partial:
    """What one station contributes, before the pooled bounds are taken."""

    n: int = 0
    n_eff: float = 0.0
    tau_s: float = 0.0
    assumed: bool = False
    events: int = 0


def _station(
    name: str,
    d: _Arrays,
    counting: CountingResult,
    services: Sequence[ServiceLevel],
    gap_s: float,
    fallback_s: float,
    confidence: float,
) -> tuple[StationEvidence, dict]:
    interval = d.interval_s or 1.0
    t_s = d.t_us / 1e6
    partial: dict = {}
    out: dict[str, ServiceEvidence] = {}
    done: dict[tuple, tuple] = {}  # services with the same limits and window (APV-I, LPV) count once
    for s in services:
        key = (s.hal, s.val, s.continuity_window_s)
        if key not in done:
            avail = _available(d, s)
            n_eff, tau_s, assumed = effective_size(avail, interval, fallback_s)
            events = loss_events(t_s, avail, interval, s.continuity_window_s)
            mi, hmi = {}, {}
            for a in _AXES:
                al = s.alert_limit(a)
                if al is not None:
                    mi[a], hmi[a] = _events(d, a, al, gap_s)
            done[key] = (avail.size, n_eff, tau_s, assumed, events, mi, hmi)
        size, n_eff, tau_s, assumed, events, mi, hmi = done[key]
        partial[s.name] = _Partial(size, n_eff, tau_s, assumed, events)
        k = counting.services[s.name]
        out[s.name] = ServiceEvidence(
            _availability(k.combined.n_available, size, n_eff, tau_s, assumed, confidence),
            _continuity(k.combined.continuity, events, confidence),
            mi,
            hmi,
        )
    acc = {}
    for a in _AXES:
        x = d.pe[a][d.solution]
        q = counting.hpe95 if a == "horizontal" else counting.vpe95  # numpy's percentile of the same x
        n_eff = effective_size(x > q, interval, fallback_s)[0] if x.size else 0.0
        partial[("accuracy", a)] = (x, n_eff)
        acc[a] = quantile_bounds(x, 0.95, n_eff, confidence, q)
    tails = {a: _tail_counts(d, a, gap_s) for a in _AXES}
    ev = StationEvidence(name, int(d.t_us.size), d.interval_s, acc, tails, out)
    return ev, partial


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


def counted_evidence(
    table: pl.DataFrame,
    counting: CountingResult,
    services: Sequence[ServiceLevel],
    *,
    gap_s: float = 360.0,
    fallback_s: float = 3600.0,
    confidence: float = 0.95,
) -> Evidence:
    """The counted evidence of ``table`` for each of ``services`` (see the module notes).

    ``counting`` is :func:`~overbound.methods.counting.count_kpis` of the same table: its available
    epochs and continuity windows are the ones bounded here, so that a verdict can never
    contradict the counted KPI. Bounds are one-sided at ``confidence`` each.
    """
    slices = _station_slices(table) or {"": slice(None)}  # an empty table: one empty station
    stations, partials = {}, {}
    for name, rows in slices.items():
        c = counting.by_station.get(name, counting)
        stations[name], partials[name] = _station(
            name, _arrays(table, rows), c, services, gap_s, fallback_s, confidence
        )
    if len(stations) == 1:
        only = next(iter(stations.values()))
        return Evidence(only, {}, confidence)
    return Evidence(_pool(stations, partials, counting, services, gap_s, confidence), stations, confidence)


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
    acc = {}
    for a in _AXES:
        xs = [partials[n][("accuracy", a)] for n in names]
        x = np.concatenate([v[0] for v in xs])
        q = counting.hpe95 if a == "horizontal" else counting.vpe95
        acc[a] = quantile_bounds(x, 0.95, sum(v[1] for v in xs), c, q)
    tails = {a: _merge_tails([stations[n].tails[a] for n in names], a, gap_s) for a in _AXES}
    intervals = {st.interval_s for st in stations.values()}
    interval = intervals.pop() if len(intervals) == 1 else None
    return StationEvidence("pooled", sum(st.n_epochs for st in stations.values()), interval, acc, tails, out)
