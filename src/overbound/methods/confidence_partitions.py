r"""The PL confidence level (Comby et al. 2003) of a dataset, reduced station-day by station-day.

:func:`~overbound.methods.confidence_level.confidence_analysis` of the pooled epoch table needs,
per target PL, the band's candidates only through: their count, the number of ``spacing`` slots
they occupy (to skip a width that cannot reach ``min_samples``), the largest error (the anchor),
and the greedy chain of :func:`~overbound.stats.dependence.select_spaced` from that anchor. All of
it is gathered from the station-days in three passes, and equals the pooled table's analysis to
the last bit (the same samples, then the same statistics, :func:`samples_bin`):

1. :func:`band_first` per station-day: its rows, its analysed epochs (step 1 of the method),
   their lowest PL (the first target) and their time span, the columns it has.
   :func:`band_plan` merges them: the targets, and the *slices* of the PL axis between every
   band edge :math:`T_k \pm w_j` (as floats, as the pooled analysis computes them: a band is a
   run of slices exactly, with no rounding at its edges).
2. :func:`band_second` per station-day: per slice, the candidates, their largest error with its
   time and pooled row (the anchor: largest error, earliest on ties, as ``argmax`` over the
   merged time axis), and the ``spacing`` slots they occupy (:class:`SlotBits`, a bit per
   slice and slot).
   :func:`band_chains` merges them and, per target, walks the widths as the pooled analysis does
   (step 5): a width whose candidates occupy fewer than ``min_samples`` slots is skipped; a
   width whose candidates occupy at least ``2 (min_samples + 1)`` slots certainly reaches
   ``min_samples`` (each sample of the greedy chain covers at most two slots: see
   :func:`band_chains`); the chain is walked for the widths between, and for the last width.
3. :class:`BandSweep` walks every chain at once across the days, forward from each anchor's day
   to the last, and backward to the first (two tasks), a day of all stations in memory: the
   stations' epochs of a day merged in time order (ties in pooled row order, as a stable sort
   of the pooled table), the next sample of every chain found by one ``searchsorted`` per slice
   of its band. :func:`dataset_confidence` chooses each target's width and computes its bin.

Every partial merges by integer addition, set union (a bitwise or) or an exact comparison; no
float is added.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import polars as pl

from overbound.io.schema import as_numpy
from overbound.methods.confidence_level import (
    _COLUMNS,
    _COMPONENTS,
    ConfidenceAnalysis,
    analysed_columns,
    band_widths,
    check_columns,
    samples_bin,
    solve_band,
    target_count,
    validate_parameters,
    with_solves,
)

__all__ = [
    "BandBlock",
    "BandChains",
    "BandFirst",
    "BandPlan",
    "BandSecond",
    "BandSweep",
    "Chain",
    "ConfidenceParameters",
    "Picks",
    "SlotBits",
    "band_block",
    "band_chains",
    "band_first",
    "band_plan",
    "band_second",
    "concat_blocks",
    "dataset_confidence",
    "day_block",
    "joined_walks",
    "merge_band_first",
    "merge_band_second",
    "merge_picks",
    "merge_slot_bits",
    "table_confidence",
    "take",
    "walk",
]

_INF = np.iinfo(np.int64).max
_DAY_US = 86_400_000_000


@dataclass(frozen=True)
class ConfidenceParameters:
    """The parameters of :func:`~overbound.methods.confidence_level.confidence_analysis` (its defaults)."""

    min_samples: int = 200
    spacing: float = 360.0
    tolerance: float = 0.125
    step: float = 0.25
    max_pl: float = 50.0
    max_tolerance: float = 1.0
    risk: float = 1e-7
    core: float = 0.2

    def check(self, axis: str) -> None:
        """Raise ``ValueError`` as the pooled analysis does; also for ``spacing = 0`` (no chain)."""
        validate_parameters(
            axis,
            self.min_samples,
            self.spacing,
            self.tolerance,
            self.step,
            self.max_pl,
            self.max_tolerance,
            self.risk,
            self.core,
        )
        if self.spacing_us <= 0:
            raise ValueError("a dataset's confidence analysis needs spacing > 0 (the samples are chained)")

    @property
    def spacing_us(self) -> int:
        return round(self.spacing * 1e6)


@dataclass(frozen=True)
class BandBlock:
    """The analysed epochs of one axis of a station-day (or of a day of all stations), in time
    order: times (µs), PL, |error|, the signed errors overbounded, the station (its index among
    the analysis' stations) and the row in the pooled table."""

    t: np.ndarray
    pl: np.ndarray
    error: np.ndarray
    signed: tuple[np.ndarray, ...]
    station: np.ndarray
    row: np.ndarray


def band_block(table: pl.DataFrame, axis: str, station: int, row0: int | np.ndarray) -> BandBlock:
    """The :class:`BandBlock` of ``axis`` of a station-day whose first row is ``row0`` of the pooled
    table (or whose rows are ``row0``); a column the station-day lacks is read as missing values
    (as in the pooled table)."""
    ok, pl_, err, signed = _analysed(table, axis)
    rows = np.flatnonzero(ok)
    return BandBlock(
        _times(table)[rows],
        pl_[rows],
        err[rows],
        tuple(s[rows] for s in signed),
        np.full(rows.size, station, dtype=np.int64),
        rows.astype(np.int64) + row0 if isinstance(row0, int) else np.asarray(row0, dtype=np.int64)[rows],
    )


def _analysed(
    table: pl.DataFrame, axis: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
    """:func:`~overbound.methods.confidence_level.analysed_columns` of a station-day, a column it
    lacks read as missing values (as in the pooled table)."""
    need = [c for c in _COLUMNS[axis] if c not in table.columns]
    if need:
        table = table.with_columns(pl.lit(None, dtype=pl.Float64).alias(c) for c in need)
    return analysed_columns(table, axis)


def _times(table: pl.DataFrame) -> np.ndarray:
    return as_numpy(table["time"]).astype(np.int64, copy=False)


def take(b: BandBlock, index) -> BandBlock:
    """The epochs ``index`` (an index array or a slice) of a block."""
    return BandBlock(
        b.t[index],
        b.pl[index],
        b.error[index],
        tuple(x[index] for x in b.signed),
        b.station[index],
        b.row[index],
    )


def concat_blocks(blocks: Sequence[BandBlock]) -> BandBlock:
    """Blocks concatenated in order."""
    return BandBlock(
        np.concatenate([b.t for b in blocks]),
        np.concatenate([b.pl for b in blocks]),
        np.concatenate([b.error for b in blocks]),
        tuple(np.concatenate(x) for x in zip(*(b.signed for b in blocks), strict=True)),
        np.concatenate([b.station for b in blocks]),
        np.concatenate([b.row for b in blocks]),
    )


def day_block(blocks: Sequence[BandBlock]) -> BandBlock:
    """The blocks of one day merged in time order, ties in pooled row order (a stable sort of the
    pooled table by time)."""
    b = concat_blocks(blocks)
    if np.all(b.row[1:] > b.row[:-1]):  # blocks in pooled row order (a dataset): sorted runs, merged
        return take(b, np.argsort(b.t, kind="stable"))
    return take(b, np.lexsort((b.row, b.t)))


# --- pass 1 --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BandFirst:
    """Pass 1 of one axis, merged over station-days in pooled order: each one's key, station and
    rows; the analysed epochs, their lowest PL and time span; the columns seen; whether a signed
    east error is present (the pooled analysis' default axes)."""

    keys: tuple[str, ...]
    stations: tuple[str, ...]
    n_rows: tuple[int, ...]
    n: int
    pl_min: float
    t_min: int
    t_max: int
    columns: frozenset[str]
    has_east: bool


def band_first(table: pl.DataFrame, axis: str, key: str, station: str) -> BandFirst:
    """Pass 1 of one station-day."""
    ok, pl_, _, _ = _analysed(table, axis)
    n = int(np.count_nonzero(ok))
    t = _times(table)[ok]
    east = "east" in table.columns and bool(table["east"].is_not_nan().any())
    return BandFirst(
        (key,),
        (station,),
        (table.height,),
        n,
        float(pl_[ok].min()) if n else math.inf,
        int(t.min()) if n else _INF,
        int(t.max()) if n else -_INF,
        frozenset(table.columns),
        east,
    )


def merge_band_first(*parts: BandFirst) -> BandFirst:
    """Pass-1 partials of consecutive station-days merged, in their order."""
    return BandFirst(
        sum((p.keys for p in parts), ()),
        sum((p.stations for p in parts), ()),
        sum((p.n_rows for p in parts), ()),
        sum(p.n for p in parts),
        min(p.pl_min for p in parts),
        min(p.t_min for p in parts),
        max(p.t_max for p in parts),
        frozenset().union(*(p.columns for p in parts)),
        any(p.has_east for p in parts),
    )


@dataclass(frozen=True)
class BandPlan:
    """What passes 2 and 3 need: the targets, the band edges and slices, the slot range, and per
    station-day its first pooled row and its station's index.

    ``lo[k, j]``, ``hi[k, j]``: the band of target ``k`` at width ``j`` is slices ``lo <= s < hi``;
    slice ``s`` holds the PLs ``edges[s] <= PL < edges[s + 1]``."""

    axis: str
    parameters: ConfidenceParameters
    stations: tuple[str, ...]
    n_epochs: int
    pl_min: float
    targets: np.ndarray
    widths: np.ndarray
    edges: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    slot0: int
    n_slots: int
    row0: dict[str, int]
    station_index: dict[str, int]

    @property
    def n_slices(self) -> int:
        return max(self.edges.size - 1, 0)

    def slice_of(self, pl_: np.ndarray) -> np.ndarray:
        """The slice of each PL; ``-1`` outside every band."""
        s = np.searchsorted(self.edges, pl_, side="right") - 1
        return np.where(s < self.n_slices, s, -1)


def band_plan(first: BandFirst, axis: str, parameters: ConfidenceParameters) -> BandPlan:
    """The plan of passes 2 and 3 from the merged pass 1.

    Raises the pooled analysis' errors: a column the axis needs is in no station-day
    (:class:`~overbound.io.schema.InputError`), a parameter out of range (``ValueError``)."""
    parameters.check(axis)
    check_columns(first.columns, axis)
    p = parameters
    # the station names of the pooled table in order of first appearance (stations with rows)
    stations = tuple(dict.fromkeys(s for s, n in zip(first.stations, first.n_rows, strict=True) if n))
    pl_min = first.pl_min if first.n else math.nan
    targets = np.array([pl_min + k * p.step for k in range(target_count(pl_min, p.max_pl, p.step))])
    widths = band_widths(p.tolerance, p.max_tolerance)
    lo_f = np.array([[t - w for w in widths] for t in targets.tolist()]).reshape(targets.size, widths.size)
    hi_f = np.array([[t + w for w in widths] for t in targets.tolist()]).reshape(targets.size, widths.size)
    edges = np.unique(np.concatenate([lo_f.ravel(), hi_f.ravel()]))
    s = p.spacing_us
    slot0 = first.t_min // s if first.n else 0
    n_slots = first.t_max // s - slot0 + 1 if first.n else 0
    row0 = dict(zip(first.keys, np.cumsum((0, *first.n_rows[:-1])).tolist(), strict=True))
    return BandPlan(
        axis,
        p,
        stations,
        first.n,
        pl_min,
        targets,
        widths,
        edges,
        np.searchsorted(edges, lo_f),
        np.searchsorted(edges, hi_f),
        int(slot0),
        int(n_slots),
        row0,
        {name: i for i, name in enumerate(stations)},
    )


# --- pass 2 --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BandSecond:
    """Pass 2 merged: per slice the candidates (``count``) and the anchor candidate (largest
    ``error``, then earliest ``t``, then lowest ``row``; ``error = -inf`` for an empty slice); the
    occupied (slice, slot) pairs (``slots``)."""

    count: np.ndarray
    error: np.ndarray
    t: np.ndarray
    row: np.ndarray
    slots: SlotBits


@dataclass(frozen=True)
class SlotBits:
    """The (slice, slot) pairs occupied by candidates, as bits: row ``s`` of ``bits`` (packed, 8
    slots a byte) holds slots ``lo, lo + 1, ...`` (counted from the plan's ``slot0``; ``lo`` a
    multiple of 8) of slice ``s``. A station-day spans 240 slots of 360 s (12 kB for 400 slices);
    a campaign at most the plan's ``n_slots`` (a station-year of 1 Hz data and its 12 M pairs:
    4.3 MB, where the pairs as sorted int64 codes took 100 MB and a sort at every merge)."""

    lo: int
    bits: np.ndarray

    @classmethod
    def of(cls, s: np.ndarray, slot: np.ndarray, n_slices: int) -> SlotBits:
        """The pairs ``(s[i], slot[i])``."""
        if s.size == 0:
            return cls(0, np.zeros((n_slices, 0), dtype=np.uint8))
        lo = int(slot.min()) // 8 * 8
        seen = np.zeros((n_slices, int(slot.max()) - lo + 1), dtype=bool)
        seen[s, slot - lo] = True
        return cls(lo, np.packbits(seen, axis=1))

    @property
    def hi(self) -> int:
        """The slot after the last one held (a multiple of 8)."""
        return self.lo + 8 * self.bits.shape[1]

    def dense(self, n_slots: int) -> np.ndarray:
        """The pairs as booleans ``[slice, slot]`` over slots ``0 .. n_slots - 1``."""
        out = np.zeros((self.bits.shape[0], n_slots), dtype=bool)
        if self.bits.shape[1]:
            rows = np.unpackbits(self.bits, axis=1).view(np.bool_)
            width = min(rows.shape[1], n_slots - self.lo)
            out[:, self.lo : self.lo + width] = rows[:, :width]
        return out


def merge_slot_bits(*parts: SlotBits) -> SlotBits:
    """The pairs of all ``parts`` (their union: a bitwise or, in any order)."""
    held = [p for p in parts if p.bits.shape[1]]
    if not held:
        return parts[0]
    lo, hi = min(p.lo for p in held), max(p.hi for p in held)
    bits = np.zeros((held[0].bits.shape[0], (hi - lo) // 8), dtype=np.uint8)
    for p in held:
        bits[:, (p.lo - lo) // 8 : (p.hi - lo) // 8] |= p.bits
    return SlotBits(lo, bits)


def band_second(b: BandBlock, plan: BandPlan) -> BandSecond:
    """Pass 2 of one station-day's block."""
    n = plan.n_slices
    s = plan.slice_of(b.pl)
    keep = s >= 0
    s, t, err, row = s[keep], b.t[keep], b.error[keep], b.row[keep]
    count = np.bincount(s, minlength=n).astype(np.int64)
    best_err = np.full(n, -np.inf)
    best_t = np.full(n, _INF, dtype=np.int64)
    best_row = np.full(n, _INF, dtype=np.int64)
    if s.size:
        first = _first_largest(s, err, t, row)
        best_err[s[first]], best_t[s[first]], best_row[s[first]] = err[first], t[first], row[first]
    slots = SlotBits.of(s, t // plan.parameters.spacing_us - plan.slot0, n)
    return BandSecond(count, best_err, best_t, best_row, slots)


def _first_largest(s: np.ndarray, err: np.ndarray, t: np.ndarray, row: np.ndarray) -> np.ndarray:
    """Per slice present in ``s``, the index of its largest ``err``, the earliest ``(t, row)`` on ties."""
    by_slice = np.argsort(s, kind="stable")
    ss, e = s[by_slice], err[by_slice]
    start = np.flatnonzero(np.r_[True, ss[1:] != ss[:-1]])
    size = np.diff(np.r_[start, ss.size])
    top = np.flatnonzero(e == np.repeat(np.maximum.reduceat(e, start), size))
    cand = by_slice[top]  # the epochs at their slice's largest error
    group = np.searchsorted(start, top, side="right") - 1
    order = np.lexsort((row[cand], t[cand], group))  # few: the ties only
    g = group[order]
    return cand[order][np.r_[True, g[1:] != g[:-1]]]


def merge_band_second(*parts: BandSecond) -> BandSecond:
    """Pass-2 partials merged (in any order: the anchor is chosen by a total order)."""
    count, error, t, row = parts[0].count, parts[0].error, parts[0].t, parts[0].row
    for p in parts[1:]:  # a few hundred slices each
        better = (p.error > error) | ((p.error == error) & ((p.t < t) | ((p.t == t) & (p.row < row))))
        count = count + p.count
        error, t, row = (
            np.where(better, p.error, error),
            np.where(better, p.t, t),
            np.where(better, p.row, row),
        )
    return BandSecond(count, error, t, row, merge_slot_bits(*(p.slots for p in parts)))


@dataclass(frozen=True)
class Chain:
    """The greedy chain of one band: target ``k`` at width ``j`` (slices ``lo <= s < hi``),
    from its anchor (time, pooled row)."""

    k: int
    j: int
    lo: int
    hi: int
    t: int
    row: int


@dataclass(frozen=True)
class BandChains:
    """Per target and width the candidates; the chains to walk."""

    n_candidates: np.ndarray
    chains: tuple[Chain, ...]


def band_chains(plan: BandPlan, second: BandSecond) -> BandChains:
    """The chains to walk (step 5 of the pooled analysis, without the selection).

    The widths of a target are tried in order, as :func:`confidence_analysis` does: one whose
    candidates occupy fewer than ``min_samples`` slots of ``spacing`` is skipped (except the last);
    the others need the chain, until one occupies at least ``2 (min_samples + 1)`` slots: that
    one reaches ``min_samples`` whatever the chain. Proof: the greedy chain forward from the anchor
    :math:`a = g_0 < g_1 < \\dots < g_L` leaves no candidate in :math:`[g_i + S, g_{i+1})`, so the
    candidates from :math:`g_i` to :math:`g_{i+1}` (and after :math:`g_L`) lie within :math:`S` of
    :math:`g_i`: in its slot or the next; likewise backward (:math:`h_1 > \\dots > h_M`, and before
    :math:`a`). So the candidates occupy at most :math:`2(L + 1) + 2(M + 1) = 2(n + 1)` slots,
    :math:`n = L + 1 + M` the samples, and ``slots >= 2 (min_samples + 1)`` gives
    ``n >= min_samples``."""
    p = plan.parameters
    n_t, n_w = plan.lo.shape
    cum = np.concatenate([[0], np.cumsum(second.count)])
    n_cand = cum[plan.hi] - cum[plan.lo]
    occupied = second.slots.dense(plan.n_slots)
    seen = np.zeros(plan.n_slots, dtype=bool)
    chains: list[Chain] = []
    for k in range(n_t):  # ~200 targets; the slices of a target's widths are marked incrementally
        seen[:] = False
        count, a, b = 0, plan.lo[k, 0], plan.lo[k, 0]
        for j in range(n_w):
            lo, hi = int(plan.lo[k, j]), int(plan.hi[k, j])
            for s in (*range(lo, a), *range(b, hi)):
                count += int(np.count_nonzero(occupied[s] & ~seen))
                seen |= occupied[s]
            a, b = lo, hi
            last = j == n_w - 1
            if count < p.min_samples and not last:
                continue
            if n_cand[k, j]:
                anchor = _anchor(second, lo, hi)
                chains.append(Chain(k, j, lo, hi, int(second.t[anchor]), int(second.row[anchor])))
            if count >= 2 * (p.min_samples + 1):
                break
    return BandChains(n_cand, tuple(chains))


def _anchor(second: BandSecond, lo: int, hi: int) -> int:
    """The slice holding the band's anchor: largest error, earliest, lowest row."""
    s = np.arange(lo, hi)
    order = np.lexsort((second.row[s], second.t[s], -second.error[s]))
    return int(s[order[0]])


# --- pass 3 --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Picks:
    """Samples of the chains, with the chain (index into :attr:`BandChains.chains`) of each."""

    chain: np.ndarray
    samples: BandBlock


class BandSweep:
    """The chains walked one way across the days (:meth:`day`, days in walking order), all at once.

    Forward, a chain starts at its anchor (a sample) and the next sample is the earliest candidate
    at least ``spacing`` after the last (the lowest pooled row on ties); backward, it starts
    ``spacing`` before its anchor (the anchor itself is the forward walk's) and the next sample is
    the latest candidate at least ``spacing`` before (the highest row on ties): the chain of
    :func:`~overbound.stats.dependence.select_spaced` on the merged time axis. A chain's state is
    one time, carried from day to day."""

    def __init__(self, plan: BandPlan, chains: Sequence[Chain], forward: bool) -> None:
        self.plan, self.forward = plan, forward
        self.lo = np.array([c.lo for c in chains], dtype=np.int64)
        self.hi = np.array([c.hi for c in chains], dtype=np.int64)
        self.anchor_t = np.array([c.t for c in chains], dtype=np.int64)
        self.anchor_row = np.array([c.row for c in chains], dtype=np.int64)
        self.theta = np.zeros(len(chains), dtype=np.int64)
        self.started = np.zeros(len(chains), dtype=bool)
        self._picks: list[Picks] = []

    def day(self, b: BandBlock) -> None:
        """Walk every started chain through one day's merged block (:func:`day_block`)."""
        if b.t.size == 0:
            return
        spacing = self.plan.parameters.spacing_us
        n = b.t.size
        s = self.plan.slice_of(b.pl)
        pos = np.flatnonzero(s >= 0)
        by_slice = np.argsort(
            s[pos].astype(np.int16 if self.plan.n_slices < 2**15 else np.int64), kind="stable"
        )
        keys = s[pos][by_slice] * n + pos[by_slice]  # by slice, then by position in the day (a radix sort)
        chain, at = [], []
        new = np.flatnonzero(~self.started & (self.anchor_t >= b.t[0]) & (self.anchor_t <= b.t[-1]))
        lo = np.searchsorted(b.t, self.anchor_t[new], side="left")
        hi = np.searchsorted(b.t, self.anchor_t[new], side="right")
        for c, a, z in zip(new.tolist(), lo.tolist(), hi.tolist(), strict=True):  # once per chain
            i = a + np.flatnonzero(b.row[a:z] == self.anchor_row[c])  # among the epochs at its time
            if i.size:
                self.started[c] = True
                self.theta[c] = self.anchor_t[c] + (spacing if self.forward else -spacing)
                if self.forward:
                    chain.append(np.array([c]))
                    at.append(i[:1])
        active = np.flatnonzero(self.started)
        while active.size:
            found, best = self._next(active, b.t, keys, n)
            active, best = active[found], best[found]
            chain.append(active)
            at.append(best)
            self.theta[active] = b.t[best] + (spacing if self.forward else -spacing)
        if chain:
            c, i = np.concatenate(chain), np.concatenate(at)
            self._picks.append(Picks(c, take(b, i)))

    def _next(self, active: np.ndarray, t: np.ndarray, keys: np.ndarray, n: int):
        """Per active chain: whether it has a next sample today, and its position in the day."""
        size = self.hi[active] - self.lo[active]
        owner = np.repeat(np.arange(active.size), size)
        first = np.concatenate([[0], np.cumsum(size)[:-1]])
        sl = self.lo[active][owner] + (np.arange(owner.size) - first[owner])
        base = sl * n
        if self.forward:
            p = np.searchsorted(t, self.theta[active], side="left")
            i = np.searchsorted(keys, base + p[owner], side="left")
            hit = keys[np.minimum(i, keys.size - 1)] if keys.size else np.full(i.size, _INF)
            cand = np.where((i < keys.size) & (hit < base + n), hit - base, _INF)
            best = np.minimum.reduceat(cand, first) if cand.size else cand
            return best < _INF, best
        p = np.searchsorted(t, self.theta[active], side="right") - 1
        i = np.searchsorted(keys, base + p[owner], side="right") - 1
        hit = keys[np.maximum(i, 0)] if keys.size else np.full(i.size, -1)
        cand = np.where((i >= 0) & (hit >= base), hit - base, -1)
        best = np.maximum.reduceat(cand, first) if cand.size else cand
        return best >= 0, best

    def pieces(self) -> tuple[Picks, ...]:
        """The samples found, in walking order (by day, then by step), a piece per day with some:
        joined once, by :func:`joined_walks` (a copy fewer of the campaign's samples)."""
        return tuple(self._picks)


def _no_picks(n_signed: int) -> Picks:
    e, f = np.empty(0, dtype=np.int64), np.empty(0)
    return Picks(e, BandBlock(e, f, f, tuple(f for _ in range(n_signed)), e, e))


def merge_picks(*parts: Picks) -> Picks:
    """Picks concatenated in order."""
    return Picks(np.concatenate([p.chain for p in parts]), concat_blocks([p.samples for p in parts]))


def joined_walks(backward: Sequence[Picks], forward: Sequence[Picks], axis: str) -> Picks:
    """The pieces of both walks of ``axis`` (:meth:`BandSweep.pieces`) as one :class:`Picks`, each
    chain's samples in time order: the backward walk reversed, then the forward (one copy, from
    views)."""
    r = slice(None, None, -1)
    parts = [Picks(p.chain[r], take(p.samples, r)) for p in backward[::-1]] + list(forward)
    return merge_picks(*parts) if parts else _no_picks(len(_COMPONENTS[axis]))


# --- finish --------------------------------------------------------------------------------------


def dataset_confidence(
    plan: BandPlan, chains: BandChains, both: Picks, starmap: Callable | None = None
) -> ConfidenceAnalysis:
    """The :class:`ConfidenceAnalysis` from the walked chains (``both`` walks,
    :func:`joined_walks`): per target the first width walked whose chain reaches ``min_samples``,
    else the last (step 5); its samples in time order, its statistics (step 6).
    ``starmap(fn, items)`` (a campaign runner's): the rated bands' solves (:func:`solve_band`, most
    of step 6's time) through it, the same numbers as in this process."""
    p = plan.parameters
    order = np.argsort(both.chain, kind="stable")  # each chain's samples in time order
    bounds = np.searchsorted(both.chain[order], np.arange(len(chains.chains) + 1))
    walked: dict[tuple[int, int], np.ndarray] = {}
    for i, c in enumerate(chains.chains):
        walked[c.k, c.j] = order[bounds[i] : bounds[i + 1]]
    bins, samples, requests = [], [], []
    last = plan.widths.size - 1
    for k, target in enumerate(plan.targets.tolist()):
        j = next(
            (j for j in range(last + 1) if (k, j) in walked and walked[k, j].size >= p.min_samples),
            last,
        )
        idx = walked.get((k, j), np.empty(0, dtype=np.intp))
        chosen = take(both.samples, idx)
        bin_, band, request = samples_bin(
            chosen.t,
            chosen.row,
            chosen.station,
            chosen.pl,
            chosen.error,
            chosen.signed,
            axis=plan.axis,
            target=target,
            width=float(plan.widths[j]),
            n_candidates=int(chains.n_candidates[k, j]),
            min_samples=p.min_samples,
            risk=p.risk,
            core=p.core,
            deferred=True,
        )
        bins.append(bin_)
        samples.append(band)
        requests.append(request)
    rated = [i for i, r in enumerate(requests) if r is not None]
    solved = (starmap or _starmap)(solve_band, [(requests[i],) for i in rated])
    for i, s in zip(rated, solved, strict=True):
        bins[i] = with_solves(bins[i], s)
    return ConfidenceAnalysis(
        axis=plan.axis,
        risk=float(p.risk),
        min_samples=int(p.min_samples),
        spacing=float(p.spacing),
        tolerance=float(p.tolerance),
        step=float(p.step),
        max_pl=float(p.max_pl),
        max_tolerance=float(p.max_tolerance),
        core=float(p.core),
        stations=plan.stations,
        n_epochs=plan.n_epochs,
        pl_min=plan.pl_min,
        bins=tuple(bins),
        samples=tuple(samples),
    )


def _starmap(fn: Callable, items: list[tuple]) -> list:
    return [fn(*item) for item in items]


def walk(plan: BandPlan, chains: BandChains, days: Iterable[BandBlock], forward: bool) -> tuple[Picks, ...]:
    """One direction's :class:`BandSweep` over ``days`` (merged day blocks, in walking order)."""
    sweep = BandSweep(plan, chains.chains, forward)
    for b in days:
        sweep.day(b)
    return sweep.pieces()


def table_confidence(
    table: pl.DataFrame,
    axis: str = "vertical",
    parameters: ConfidenceParameters | None = None,
    starmap: Callable | None = None,
) -> ConfidenceAnalysis:
    """:func:`~overbound.methods.confidence_level.confidence_analysis` of an epoch table (all
    stations, ``parameters`` or its defaults) by the passes of a dataset over its station-days
    (stations in order of first appearance, days in order): equal to it to the last bit.
    ``starmap``: as :func:`dataset_confidence`."""
    parameters = parameters or ConfidenceParameters()
    parameters.check(axis)
    stations = table["station"].cast(pl.String)
    day = as_numpy(table["time"]).astype(np.int64) // _DAY_US
    blocks = []  # (station, day, key, rows)
    for name in stations.unique(maintain_order=True).to_list():
        rows = np.flatnonzero(as_numpy(stations == name))
        days = day[rows]
        for d in np.unique(days).tolist():
            blocks.append((name, d, f"{name}/{d}", rows[days == d]))
    if not blocks:
        raise ValueError("the epoch table is empty")
    first = merge_band_first(*(band_first(table[r], axis, key, name) for name, _, key, r in blocks))
    plan = band_plan(first, axis, parameters)
    parts = [band_block(table[r], axis, plan.station_index.get(name, -1), r) for name, _, _, r in blocks]
    chains = band_chains(plan, merge_band_second(*(band_second(b, plan) for b in parts)))
    by_day: dict[int, list[BandBlock]] = {}
    for (_, d, _, _), b in zip(blocks, parts, strict=True):
        by_day.setdefault(d, []).append(b)
    days = [day_block(by_day[d]) for d in sorted(by_day)]
    both = joined_walks(walk(plan, chains, days[::-1], False), walk(plan, chains, days, True), axis)
    return dataset_confidence(plan, chains, both, starmap)
