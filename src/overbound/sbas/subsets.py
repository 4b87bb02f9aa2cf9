"""Stanford-ESA all-subsets histogram: errors and protection levels of every satellite subset.

For each epoch, every subset of at least four of the satellites the SBAS solution used is solved
again with the same weights, and its (PE, PL) pair is added to a Stanford histogram (Tossaint et
al. 2006, "The Stanford-ESA integrity diagram", ION GNSS; issue 6 item 5). Sub-geometries are
weaker than the full one, so the histogram probes the protection level over many more geometries
than the data hold. gLAB does the same (``-filter:stfdesa``).

Per subset S (DO-229D J.1, as :mod:`overbound.sbas.solution`): with g_i the east-north-up geometry
row [-cos E sin A, -cos E cos A, -sin E, 1] and w_i = 1 / sigma_i^2 of the full solution,
N_S = sum_{i in S} w_i g_i g_i^T, x_S = N_S^-1 sum_{i in S} w_i g_i y_i (y_i the pre-fit residual
at the reference, so x_S[:3] is the position error), HPL = K_H d_major, VPL = K_V d_U.

Vectorisation: the per-satellite terms w g g^T (its 10 distinct numbers) and w g y (4) are laid out
per epoch slot; for the epochs with n used satellites the 0/1 matrix M (subsets x n) of all subsets
turns every subset's normal matrix and right-hand side into one matrix product terms @ M^T; the
4 x 4 systems are then solved together by an elementwise Cholesky factorisation, which forms only
the position block of N_S^-1 (see :func:`_solve`). The only Python loops are over the satellite
count n and over chunks of epochs (bounded memory).

Subset rule and cap: all subsets of ``min_size`` (4) to ``max_size`` satellites; ``max_size=None``
takes them all (sum_{k>=4} C(n, k) per epoch: 848 for 10 satellites, 3797 for 12, 16 278 for 14).
``max_size`` is gLAB's ``-filter:stfdesa:maxsat`` (largest subset computed, default all). A
singular subset (a Cholesky pivot of N_S below 1e-12 times its diagonal element) is counted and left
out, as gLAB does (it counts failures of its Cholesky inversion).

Binning: that of :func:`overbound.methods.counting.stanford_histogram` (square bins from 0 to
``plot_max(AL)``, values beyond the last edge in the border bin and counted in ``clipped``), so that
:func:`overbound.report.figures.plot_stanford` draws the result. gLAB's own grid (0.1 m pixels to
50 m, with an MI-preserving shift of quantised points) is not reproduced.

Several alert limits (:func:`all_subsets_by_service`): the subset solutions do not depend on the
alert limits, so one pass serves all services. The histogram range does (1.5 AL: 60 m for a HAL of
40 m, 840 m for NPA's 556 m); a range common to all services would make the approach diagrams
useless (4.2 m bins for 200 bins to 840 m), so each distinct range of an axis keeps its histogram,
filled from the same solutions (a bincount per chunk, cheap next to the solve).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field

import numpy as np
import polars as pl

from overbound.methods.counting import StanfordCounts, StanfordHistogram, plot_max, stanford_counts
from overbound.methods.counting import stanford_histogram as _histogram
from overbound.sbas.solution import K_H_NPA, K_H_PA, K_V_PA

__all__ = [
    "SubsetHistograms",
    "all_subsets",
    "all_subsets_by_service",
    "subset_count",
    "subset_masks",
    "subset_solutions",
]

#: Relative Cholesky pivot under which a subset's normal matrix is singular.
SINGULAR = 1e-12
#: Upper triangle (i <= j) of the normal matrix in the unknowns (clock, E, N, U), then the 4 right-hand sides.
_PAIRS = tuple((i, j) for i in range(4) for j in range(i, 4))
_N_TERMS = len(_PAIRS) + 4
_AXES = ("horizontal", "vertical")
#: Subset-satellite rows per chunk (bounds the (14, epochs, subsets) sums to ~30 MB).
CHUNK_ROWS = 1 << 20
_SCHEMA = {"time": pl.Int64, "subset": pl.Int64, "prns": pl.String, "size": pl.Int64,
           "hpe": pl.Float64, "vpe": pl.Float64, "hpl": pl.Float64, "vpl": pl.Float64}  # fmt: skip
_FIELDS = tuple(f.name for f in dataclasses.fields(StanfordCounts))


@dataclass(frozen=True, slots=True)
class SubsetHistograms:
    """All-subsets Stanford histograms and counts.

    Attributes
    ----------
    horizontal, vertical : (|PE|, PL) histograms of every subset solution on ``[0, plot_max(AL)]``;
        ``vertical`` None without a vertical alert limit.
    counts : Stanford region counts per axis (``"horizontal"``, ``"vertical"``) for the alert limits given
        (no ``"vertical"`` without a vertical alert limit).
    alert_limits : the alert limits of ``counts`` and of the plotted range (``"vertical"`` may be None).
    n_epochs : epochs with at least ``min_size`` used satellites.
    n_subsets : subset solutions computed (in the histograms).
    n_singular : subsets left out for a singular normal matrix.
    by_size : subsets computed per subset size.
    worst_ratio : largest PE / PL per axis (gLAB's HWIR / VWIR).
    """

    horizontal: StanfordHistogram
    vertical: StanfordHistogram | None
    counts: dict[str, StanfordCounts]
    alert_limits: dict[str, float | None]
    n_epochs: int
    n_subsets: int
    n_singular: int
    by_size: dict[int, int] = field(default_factory=dict)
    worst_ratio: dict[str, float] = field(default_factory=dict)


def subset_count(n: int, min_size: int = 4, max_size: int | None = None) -> int:
    """Number of subsets of ``n`` satellites with ``min_size`` to ``max_size`` members."""
    top = n if max_size is None else min(n, max_size)
    return sum(math.comb(n, k) for k in range(min_size, top + 1))


def subset_masks(n: int, min_size: int = 4, max_size: int | None = None) -> np.ndarray:
    """0/1 matrix (subsets, n): the full set first, then by decreasing size, lexicographic within a size."""
    top = n if max_size is None else min(n, max_size)
    parts = [np.zeros((0, n))]
    for k in range(top, min_size - 1, -1):
        cols = itertools.chain.from_iterable(itertools.combinations(range(n), k))
        idx = np.fromiter(cols, np.intp, math.comb(n, k) * k).reshape(math.comb(n, k), k)
        part = np.zeros((idx.shape[0], n))
        np.put_along_axis(part, idx, 1.0, axis=1)
        parts.append(part)
    return np.concatenate(parts)


def all_subsets(
    satellites: pl.DataFrame,
    *,
    mode: str = "PA",
    horizontal_al: float = 40.0,
    vertical_al: float | None = 50.0,
    bins: int = 200,
    min_size: int = 4,
    max_size: int | None = None,
) -> SubsetHistograms:
    """Stanford-ESA histograms of all satellite subsets of every epoch, for one pair of alert limits.

    Parameters
    ----------
    satellites : the per-satellite table of :func:`overbound.sbas.engine.run_sbas` (columns ``time``,
        ``used``, ``elevation``, ``azimuth`` in degrees, ``sigma``, ``prefit``).
    mode : ``"PA"`` (K_H 6.0) or ``"NPA"`` (6.18); K_V is 5.33.
    horizontal_al, vertical_al : alert limits of the region counts; the histograms span
        ``plot_max(AL)`` (default APV-I, 40 m and 50 m). ``vertical_al`` None: no vertical
        histogram or counts.
    bins : bins per axis.
    min_size, max_size : subset sizes computed (``max_size`` None: all; see the module notes).
    """
    return all_subsets_by_service(
        satellites, {"": (horizontal_al, vertical_al)}, mode=mode, bins=bins, min_size=min_size,
        max_size=max_size,
    )[""]  # fmt: skip


def all_subsets_by_service(
    satellites: pl.DataFrame,
    alert_limits: Mapping[str, tuple[float, float | None]],
    *,
    mode: str = "PA",
    bins: int = 200,
    min_size: int = 4,
    max_size: int | None = None,
) -> dict[str, SubsetHistograms]:
    """All-subsets histograms for several pairs of alert limits in one pass over the subsets.

    The subsets are solved once; each chunk of solutions is binned once per distinct plot range
    ``plot_max(AL)`` of an axis and counted once per distinct alert limit, so the result of each
    name equals :func:`all_subsets` with its limits (tested).

    Parameters
    ----------
    satellites, mode, bins, min_size, max_size : as :func:`all_subsets`.
    alert_limits : name (e.g. a service) -> (HAL, VAL) in metres; VAL None: no vertical histogram
        or counts (NPA).

    Returns
    -------
    dict
        Name -> :class:`SubsetHistograms`, in the order of ``alert_limits``; names with equal limits
        share one object.
    """
    limits = _check_limits(alert_limits)
    acc = _Accumulator(limits.values(), bins)
    n_epochs = 0
    by_size: dict[int, int] = {}
    for chunk in _solutions(satellites, mode, min_size, max_size):
        n_epochs += chunk.new_epochs
        for k, c in zip(*np.unique(chunk.masks.sum(axis=1).astype(int), return_counts=True), strict=True):
            by_size[int(k)] = by_size.get(int(k), 0) + int(c) * chunk.time.size
        acc.add(chunk.hpe.ravel(), chunk.vpe.ravel(), chunk.hpl.ravel(), chunk.vpl.ravel())
    shared: dict[tuple[float, float | None], SubsetHistograms] = {}
    for pair in limits.values():
        if pair not in shared:
            als = dict(zip(_AXES, pair, strict=True))
            shared[pair] = SubsetHistograms(
                horizontal=acc.histogram("horizontal", pair[0]),
                vertical=None if pair[1] is None else acc.histogram("vertical", pair[1]),
                counts={a: acc.counts[a, al] for a, al in als.items() if al is not None},
                alert_limits=als,
                n_epochs=n_epochs,
                n_subsets=acc.n,
                n_singular=acc.singular,
                by_size=dict(sorted(by_size.items())),
                worst_ratio=dict(acc.worst),
            )
    return {name: shared[pair] for name, pair in limits.items()}


def _check_limits(
    alert_limits: Mapping[str, tuple[float, float | None]],
) -> dict[str, tuple[float, float | None]]:
    """The limits as floats; a clear error for none, a malformed pair or a non-positive limit."""
    if not alert_limits:
        raise ValueError("no alert limits given: expected name -> (HAL, VAL or None)")
    out = {}
    for name, pair in alert_limits.items():
        try:
            hal, val = pair
            hal, val = float(hal), None if val is None else float(val)
        except (TypeError, ValueError):
            raise ValueError(f"alert limits {name!r}: {pair!r} is not a (HAL, VAL or None) pair") from None
        if not all(math.isfinite(x) and x > 0 for x in (hal, val) if x is not None):
            raise ValueError(f"alert limits {name!r}: {pair!r}: expected positive finite metres")
        out[name] = (hal, val)
    return out


def subset_solutions(
    satellites: pl.DataFrame, *, mode: str = "PA", min_size: int = 4, max_size: int | None = None
) -> pl.DataFrame:
    """Every subset solution as a table, for inspection of few epochs (it grows as the subset count).

    Columns ``time``, ``subset`` (index in :func:`subset_masks` of the epoch's used satellites, 0 = all),
    ``prns`` (the subset's PRNs), ``size``, ``hpe``, ``vpe`` (signed), ``hpl``, ``vpl`` (NaN: singular).
    """
    parts = []
    for c in _solutions(satellites, mode, min_size, max_size):
        e, s = c.hpe.shape
        prns = [" ".join(str(p) for p in c.prn[i][c.masks[j] > 0]) for i in range(e) for j in range(s)]
        parts.append(pl.DataFrame({
            "time": np.repeat(c.time, s), "subset": np.tile(np.arange(s), e), "prns": prns,
            "size": np.tile(c.masks.sum(axis=1).astype(np.int64), e),
            "hpe": c.hpe.ravel(), "vpe": c.vpe.ravel(), "hpl": c.hpl.ravel(), "vpl": c.vpl.ravel(),
        }))  # fmt: skip
    if not parts:
        return pl.DataFrame(schema=_SCHEMA).with_columns(pl.col("time").cast(satellites.schema["time"]))
    out = pl.concat(parts).sort("time", "subset")
    return out.with_columns(pl.col("time").cast(satellites.schema["time"]))


@dataclass(frozen=True, slots=True)
class _Chunk:
    """Subset solutions of epochs with the same number of used satellites: arrays (epochs, subsets)."""

    time: np.ndarray
    prn: np.ndarray
    masks: np.ndarray
    new_epochs: int
    hpe: np.ndarray
    vpe: np.ndarray
    hpl: np.ndarray
    vpl: np.ndarray


def _solutions(satellites: pl.DataFrame, mode: str, min_size: int, max_size: int | None) -> Iterator[_Chunk]:
    """Subset solutions by satellite count and chunks of epochs (the vectorised core)."""
    if mode not in ("PA", "NPA"):
        raise ValueError(f"mode {mode!r}: expected PA or NPA")
    if min_size < 4:
        raise ValueError(f"min_size {min_size}: a subset needs at least 4 satellites (4 unknowns)")
    if max_size is not None and max_size < min_size:
        raise ValueError(f"max_size {max_size} is below min_size {min_size}")
    missing = {"time", "prn", "used", "elevation", "azimuth", "sigma", "prefit"} - set(satellites.columns)
    if missing:
        raise ValueError(f"per-satellite table lacks {sorted(missing)} (expected run_sbas's satellites)")
    k_h = K_H_PA if mode == "PA" else K_H_NPA
    times, prn, terms, counts = _epoch_terms(satellites.filter(pl.col("used")))
    for n in np.unique(counts).tolist():
        if n < min_size:
            continue
        ep = np.flatnonzero(counts == n)
        masks = subset_masks(n, min_size, max_size)
        masks_t = np.ascontiguousarray(masks.T)
        step = max(1, CHUNK_ROWS // (masks.shape[0] * n))
        for start in range(0, ep.size, step):
            e = ep[start : start + step]
            # one GEMM (terms * epochs, n) @ (n, subsets): each term comes out as a contiguous
            # (epochs, subsets) block, the layout of the elementwise solve
            summed = (terms[:, e, :n].reshape(-1, n) @ masks_t).reshape(_N_TERMS, e.size, masks.shape[0])
            hpe, vpe, hpl, vpl = _solve(summed, k_h)
            yield _Chunk(times[e], prn[e, :n], masks, e.size, hpe, vpe, hpl, vpl)


def _epoch_terms(used: pl.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Epoch times, PRNs per slot, the terms (:data:`_PAIRS` of w h h^T, then w h y) of each used
    satellite as an array (terms, epoch, slot), and the number of used satellites per epoch.

    h = [1, g_E, g_N, g_U]: the clock first, so that the position covariance is the inverse of the
    trailing block of the Cholesky factor (see :func:`_solve`)."""
    t = used["time"].to_physical().to_numpy()
    times, epoch, counts = np.unique(t, return_inverse=True, return_counts=True)
    order = np.argsort(epoch, kind="stable")
    epoch = epoch[order]
    slot = np.arange(epoch.size) - np.concatenate([[0], np.cumsum(counts)[:-1]])[epoch]
    e = np.deg2rad(used["elevation"].to_numpy()[order])
    a = np.deg2rad(used["azimuth"].to_numpy()[order])
    h = np.stack([np.ones(e.size), -np.cos(e) * np.sin(a), -np.cos(e) * np.cos(a), -np.sin(e)])
    w = 1.0 / used["sigma"].to_numpy()[order] ** 2
    y = used["prefit"].to_numpy()[order]
    terms = np.zeros((_N_TERMS, counts.size, max(int(counts.max(initial=0)), 1)))
    for k, (i, j) in enumerate(_PAIRS):
        terms[k, epoch, slot] = w * h[i] * h[j]
    terms[len(_PAIRS) :, epoch, slot] = w * y * h
    prn = np.zeros(terms.shape[1:], np.int64)
    prn[epoch, slot] = used["prn"].to_numpy()[order]
    return times, prn, terms, counts


def _solve(summed: np.ndarray, k_h: float) -> tuple[np.ndarray, ...]:
    """Horizontal error, signed vertical error, HPL, VPL of each (epoch, subset) from its summed terms
    (terms, epochs, subsets); NaN for singular subsets.

    Elementwise Cholesky factorisation N = L L^T on contiguous per-element arrays: a few dozen array
    operations instead of one LAPACK call per 4 x 4 system. Only the position block of N^-1 is needed
    (DO-229D J.1: d_E^2, d_N^2, d_EN, d_U^2); with the unknowns ordered (clock, E, N, U) and L^-1
    lower triangular, that block is T^T T with T the inverse of the trailing 3 x 3 block of L, and
    x = N^-1 b is two triangular substitutions, so neither the full inverse nor x's clock is formed.
    A pivot below ``SINGULAR`` times its diagonal element (a column dependent on the previous ones)
    marks the subset singular."""
    a = {p: summed[k] for k, p in enumerate(_PAIRS)}
    b = summed[len(_PAIRS) :]
    low: dict[tuple[int, int], np.ndarray] = {}
    r: list[np.ndarray] = []  # 1 / L_jj
    singular = np.zeros(summed.shape[1:], bool)
    for j in range(4):
        d = _minus_products(a[j, j], [(low[j, k], low[j, k]) for k in range(j)])
        bad = ~(d > SINGULAR * a[j, j])
        singular |= bad
        np.putmask(d, bad, 1.0)
        r.append(np.reciprocal(np.sqrt(d, out=d), out=d))
        for i in range(j + 1, 4):
            low[i, j] = _minus_products(a[j, i], [(low[i, k], low[j, k]) for k in range(j)])
            low[i, j] *= r[j]
    t: dict[tuple[int, int], np.ndarray] = {}  # T = (trailing block of L)^-1, forward substitution
    for j in range(1, 4):
        t[j, j] = r[j]
        for i in range(j + 1, 4):
            t[i, j] = _sum_products([(low[i, k], t[k, j]) for k in range(j, i)])
            t[i, j] *= r[i]
            np.negative(t[i, j], out=t[i, j])
    z: list[np.ndarray] = []  # L z = b
    for i in range(4):
        z.append(_minus_products(b[i], [(low[i, k], z[k]) for k in range(i)]))
        z[i] *= r[i]
    x: dict[int, np.ndarray] = {}  # L^T x = z, position only
    for i in (3, 2, 1):
        x[i] = _minus_products(z[i], [(low[k, i], x[k]) for k in range(i + 1, 4)])
        x[i] *= r[i]
    de = _sum_products([(t[k, 1], t[k, 1]) for k in (1, 2, 3)])  # (T^T T)_ij = sum_k T_ki T_kj
    dn = _sum_products([(t[k, 2], t[k, 2]) for k in (2, 3)])
    den = _sum_products([(t[k, 1], t[k, 2]) for k in (2, 3)])
    d_major = np.sqrt((de + dn) / 2 + np.sqrt(((de - dn) / 2) ** 2 + den**2))
    nan = np.where(singular, np.nan, 1.0)
    hpe = np.hypot(x[1], x[2])
    return hpe * nan, x[3] * nan, k_h * d_major * nan, K_V_PA * t[3, 3] * nan


def _minus_products(base: np.ndarray, pairs: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """base - sum of u * v over ``pairs``, as a new array, with one temporary."""
    if not pairs:
        return np.array(base, copy=True)
    tmp = np.empty(pairs[0][0].shape)
    out = np.subtract(base, np.multiply(*pairs[0], out=tmp))
    for u, v in pairs[1:]:
        out -= np.multiply(u, v, out=tmp)
    return out


def _sum_products(pairs: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Sum of u * v over (non-empty) ``pairs``, as a new array, with one temporary."""
    out = np.multiply(*pairs[0])
    tmp = np.empty(out.shape)
    for u, v in pairs[1:]:
        out += np.multiply(u, v, out=tmp)
    return out


class _Accumulator:
    """Histograms and region counts summed over chunks, with the binning of ``stanford_histogram``:
    one histogram per axis and plot range ``plot_max(AL)``, region counts per axis and alert limit,
    for all the (HAL, VAL) pairs at once."""

    def __init__(self, pairs: Iterable[tuple[float, float | None]], bins: int) -> None:
        self.bins = bins
        pairs = list(pairs)
        self.als = {a: sorted({p[i] for p in pairs if p[i] is not None}) for i, a in enumerate(_AXES)}
        self.tops = {a: sorted({plot_max(al) for al in als}) for a, als in self.als.items()}
        self.hist = {(a, top): np.zeros((bins, bins), np.int64) for a in _AXES for top in self.tops[a]}
        self.clipped = dict.fromkeys(self.hist, 0)
        self.counts = {(a, al): StanfordCounts(0, 0, 0, 0, 0, 0) for a in _AXES for al in self.als[a]}
        self.worst = dict.fromkeys(_AXES, 0.0)
        self.n = 0
        self.singular = 0

    def add(self, pe_h: np.ndarray, pe_v: np.ndarray, hpl: np.ndarray, vpl: np.ndarray) -> None:
        bad = np.isnan(hpl)
        n_bad = int(np.count_nonzero(bad))
        self.singular += n_bad
        self.n += hpl.size - n_bad
        if n_bad:
            ok = ~bad
            pe_h, pe_v, hpl, vpl = pe_h[ok], pe_v[ok], hpl[ok], vpl[ok]
        for axis, pe, pl_ in (("horizontal", pe_h, hpl), ("vertical", pe_v, vpl)):
            pe = np.abs(pe)
            for top in self.tops[axis]:
                h = _histogram(pe, pl_, axis=axis, max_value=top, bins=self.bins)
                self.hist[axis, top] += h.counts
                self.clipped[axis, top] += h.clipped
            for al in self.als[axis]:
                c = stanford_counts(pe, pl_, al)
                old = self.counts[axis, al]
                self.counts[axis, al] = StanfordCounts(*(getattr(old, f) + getattr(c, f) for f in _FIELDS))
            if pe.size:
                self.worst[axis] = max(self.worst[axis], float(np.max(pe / pl_)))

    def histogram(self, axis: str, al: float) -> StanfordHistogram:
        top = plot_max(al)
        edges = np.linspace(0.0, top, self.bins + 1)
        return StanfordHistogram(axis, edges, self.hist[axis, top].copy(), self.clipped[axis, top])
