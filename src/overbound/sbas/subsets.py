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

Vectorisation: the per-satellite terms w g g^T (16 numbers) and w g y (4) are laid out per epoch
slot; for the epochs with n used satellites the 0/1 matrix M (subsets x n) of all subsets turns
every subset's normal matrix and right-hand side into one matrix product M @ terms; the 4 x 4
systems are then inverted together by an elementwise Cholesky factorisation. The only Python loops
are over the satellite count n and over chunks of epochs (bounded memory).

Subset rule and cap: all subsets of ``min_size`` (4) to ``max_size`` satellites; ``max_size=None``
takes them all (sum_{k>=4} C(n, k) per epoch: 848 for 10 satellites, 3797 for 12, 16 278 for 14).
``max_size`` is gLAB's ``-filter:stfdesa:maxsat`` (largest subset computed, default all). A
singular subset (a Cholesky pivot of N_S below 1e-12 times its diagonal element) is counted and left
out, as gLAB does (it counts failures of its Cholesky inversion).

Binning: that of :func:`overbound.methods.counting.stanford_histogram` (square bins from 0 to
``plot_max(AL)``, values beyond the last edge in the border bin and counted in ``clipped``), so that
:func:`overbound.report.figures.plot_stanford` draws the result. gLAB's own grid (0.1 m pixels to
50 m, with an MI-preserving shift of quantised points) is not reproduced.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import polars as pl

from overbound.methods.counting import StanfordCounts, StanfordHistogram, plot_max, stanford_counts
from overbound.methods.counting import stanford_histogram as _histogram
from overbound.sbas.solution import K_H_NPA, K_H_PA, K_V_PA

__all__ = ["SubsetHistograms", "all_subsets", "subset_count", "subset_masks", "subset_solutions"]

#: Relative Cholesky pivot under which a subset's normal matrix is singular.
SINGULAR = 1e-12
#: Subset-satellite rows per chunk (bounds the (epochs, subsets, 16) working arrays to ~100 MB).
CHUNK_ROWS = 1 << 20
_SCHEMA = {"time": pl.Int64, "subset": pl.Int64, "prns": pl.String, "size": pl.Int64,
           "hpe": pl.Float64, "vpe": pl.Float64, "hpl": pl.Float64, "vpl": pl.Float64}  # fmt: skip
_FIELDS = tuple(f.name for f in dataclasses.fields(StanfordCounts))


@dataclass(frozen=True, slots=True)
class SubsetHistograms:
    """All-subsets Stanford histograms and counts.

    Attributes
    ----------
    horizontal, vertical : (|PE|, PL) histograms of every subset solution.
    counts : Stanford region counts per axis (``"horizontal"``, ``"vertical"``) for the alert limits given.
    alert_limits : the alert limits of ``counts`` and of the plotted range.
    n_epochs : epochs with at least ``min_size`` used satellites.
    n_subsets : subset solutions computed (in the histograms).
    n_singular : subsets left out for a singular normal matrix.
    by_size : subsets computed per subset size.
    worst_ratio : largest PE / PL per axis (gLAB's HWIR / VWIR).
    """

    horizontal: StanfordHistogram
    vertical: StanfordHistogram
    counts: dict[str, StanfordCounts]
    alert_limits: dict[str, float]
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
    rows = [c for k in range(top, min_size - 1, -1) for c in itertools.combinations(range(n), k)]
    out = np.zeros((len(rows), n))
    for i, c in enumerate(rows):
        out[i, list(c)] = 1.0
    return out


def all_subsets(
    satellites: pl.DataFrame,
    *,
    mode: str = "PA",
    horizontal_al: float = 40.0,
    vertical_al: float = 50.0,
    bins: int = 200,
    min_size: int = 4,
    max_size: int | None = None,
) -> SubsetHistograms:
    """Stanford-ESA histograms of all satellite subsets of every epoch.

    Parameters
    ----------
    satellites : the per-satellite table of :func:`overbound.sbas.engine.run_sbas` (columns ``time``,
        ``used``, ``elevation``, ``azimuth`` in degrees, ``sigma``, ``prefit``).
    mode : ``"PA"`` (K_H 6.0) or ``"NPA"`` (6.18); K_V is 5.33.
    horizontal_al, vertical_al : alert limits of the region counts; the histograms span
        ``plot_max(AL)`` (default APV-I, 40 m and 50 m).
    bins : bins per axis.
    min_size, max_size : subset sizes computed (``max_size`` None: all; see the module notes).
    """
    als = {"horizontal": float(horizontal_al), "vertical": float(vertical_al)}
    acc = _Accumulator(als, bins)
    n_epochs = 0
    by_size: dict[int, int] = {}
    for chunk in _solutions(satellites, mode, min_size, max_size):
        n_epochs += chunk.new_epochs
        for k, c in zip(*np.unique(chunk.masks.sum(axis=1).astype(int), return_counts=True), strict=True):
            by_size[int(k)] = by_size.get(int(k), 0) + int(c) * chunk.time.size
        acc.add(chunk.hpe.ravel(), chunk.vpe.ravel(), chunk.hpl.ravel(), chunk.vpl.ravel())
    return SubsetHistograms(
        horizontal=acc.histogram("horizontal"),
        vertical=acc.histogram("vertical"),
        counts=acc.counts,
        alert_limits=als,
        n_epochs=n_epochs,
        n_subsets=acc.n,
        n_singular=acc.singular,
        by_size=dict(sorted(by_size.items())),
        worst_ratio=acc.worst,
    )


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
        step = max(1, CHUNK_ROWS // (masks.shape[0] * n))
        for start in range(0, ep.size, step):
            e = ep[start : start + step]
            # one GEMM (subsets, n) @ (n, epochs * 20) rather than a batched matmul per epoch
            flat = terms[e, :n].transpose(1, 0, 2).reshape(n, -1)
            summed = (masks @ flat).reshape(masks.shape[0], e.size, 20).transpose(1, 0, 2)
            hpe, vpe, hpl, vpl = _solve(np.ascontiguousarray(summed), k_h)
            yield _Chunk(times[e], prn[e, :n], masks, e.size, hpe, vpe, hpl, vpl)


def _epoch_terms(used: pl.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Epoch times, PRNs per slot, the 20 terms (w g g^T flattened, then w g y) of each used satellite
    per (epoch, slot), and the number of used satellites per epoch."""
    t = used["time"].to_physical().to_numpy()
    times, epoch, counts = np.unique(t, return_inverse=True, return_counts=True)
    order = np.argsort(epoch, kind="stable")
    epoch = epoch[order]
    slot = np.arange(epoch.size) - np.concatenate([[0], np.cumsum(counts)[:-1]])[epoch]
    e = np.deg2rad(used["elevation"].to_numpy()[order])
    a = np.deg2rad(used["azimuth"].to_numpy()[order])
    g = np.stack([-np.cos(e) * np.sin(a), -np.cos(e) * np.cos(a), -np.sin(e), np.ones(e.size)], axis=-1)
    w = 1.0 / used["sigma"].to_numpy()[order] ** 2
    y = used["prefit"].to_numpy()[order]
    terms = np.zeros((counts.size, max(int(counts.max(initial=0)), 1), 20))
    terms[epoch, slot, :16] = (w[:, None, None] * g[:, :, None] * g[:, None, :]).reshape(-1, 16)
    terms[epoch, slot, 16:] = (w * y)[:, None] * g
    prn = np.zeros(terms.shape[:2], np.int64)
    prn[epoch, slot] = used["prn"].to_numpy()[order]
    return times, prn, terms, counts


def _solve(summed: np.ndarray, k_h: float) -> tuple[np.ndarray, ...]:
    """Horizontal error, signed vertical error, HPL, VPL of each (epoch, subset) from its summed terms;
    NaN for singular subsets."""
    normal = summed[..., :16].reshape(*summed.shape[:-1], 4, 4)
    cov, singular = _spd_inverse(normal)
    x = np.einsum("...ij,...j->...i", cov, summed[..., 16:])
    de, dn, den, du = cov[..., 0, 0], cov[..., 1, 1], cov[..., 0, 1], cov[..., 2, 2]
    d_major = np.sqrt((de + dn) / 2 + np.sqrt(((de - dn) / 2) ** 2 + den**2))
    nan = np.where(singular, np.nan, 1.0)
    hpe, vpe = np.hypot(x[..., 0], x[..., 1]), x[..., 2]
    return hpe * nan, vpe * nan, k_h * d_major * nan, K_V_PA * np.sqrt(du) * nan


def _spd_inverse(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of a stack (..., m, m) of symmetric positive (semi-)definite matrices by an
    elementwise Cholesky factorisation (a = L L^T, a^-1 = L^-T L^-1) on contiguous per-element
    arrays: a few dozen array operations instead of one LAPACK call per 4 x 4 matrix (several
    times faster than ``numpy.linalg.inv``). A pivot below ``SINGULAR`` times its diagonal element
    (a column dependent on the previous ones) marks the matrix singular; its result is meaningless."""
    m = a.shape[-1]
    e = [[np.ascontiguousarray(a[..., i, j]) for j in range(m)] for i in range(m)]
    low: list[list[np.ndarray]] = [[np.zeros(0)] * m for _ in range(m)]
    singular = np.zeros(a.shape[:-2], bool)
    for j in range(m):
        zero = np.zeros(a.shape[:-2])
        d = e[j][j] - sum((low[j][k] ** 2 for k in range(j)), zero)
        bad = ~(d > SINGULAR * e[j][j])
        singular |= bad
        low[j][j] = np.sqrt(np.where(bad, 1.0, d))
        for i in range(j + 1, m):
            low[i][j] = (e[i][j] - sum((low[i][k] * low[j][k] for k in range(j)), zero)) / low[j][j]
    inv: list[list[np.ndarray | None]] = [[None] * m for _ in range(m)]  # L^-1 by forward substitution
    for j in range(m):
        inv[j][j] = 1.0 / low[j][j]
        for i in range(j + 1, m):
            inv[i][j] = -sum(low[i][k] * inv[k][j] for k in range(j, i)) / low[i][i]
    out = np.empty(a.shape)
    for i in range(m):
        for j in range(i, m):  # (L^-T L^-1)_ij = sum_k inv[k][i] inv[k][j], k >= max(i, j)
            out[..., i, j] = out[..., j, i] = sum(inv[k][i] * inv[k][j] for k in range(j, m))
    return out, singular


class _Accumulator:
    """Histograms and region counts summed over chunks, with the binning of ``stanford_histogram``."""

    def __init__(self, als: dict[str, float], bins: int) -> None:
        self.als = als
        self.bins = bins
        self.hist = {a: np.zeros((bins, bins), np.int64) for a in als}
        self.clipped = dict.fromkeys(als, 0)
        self.counts = {a: StanfordCounts(0, 0, 0, 0, 0, 0) for a in als}
        self.worst = dict.fromkeys(als, 0.0)
        self.n = 0
        self.singular = 0

    def add(self, pe_h: np.ndarray, pe_v: np.ndarray, hpl: np.ndarray, vpl: np.ndarray) -> None:
        bad = np.isnan(hpl)
        self.singular += int(bad.sum())
        self.n += int((~bad).sum())
        for axis, pe, pl_ in (("horizontal", pe_h[~bad], hpl[~bad]), ("vertical", pe_v[~bad], vpl[~bad])):
            h = _histogram(pe, pl_, axis=axis, max_value=plot_max(self.als[axis]), bins=self.bins)
            self.hist[axis] += h.counts
            self.clipped[axis] += h.clipped
            c = stanford_counts(np.abs(pe), pl_, self.als[axis])
            self.counts[axis] = StanfordCounts(*(getattr(self.counts[axis], f) + getattr(c, f)
                                                 for f in _FIELDS))  # fmt: skip
            if pe.size:
                self.worst[axis] = max(self.worst[axis], float(np.max(np.abs(pe) / pl_)))

    def histogram(self, axis: str) -> StanfordHistogram:
        edges = np.linspace(0.0, plot_max(self.als[axis]), self.bins + 1)
        return StanfordHistogram(axis, edges, self.hist[axis], self.clipped[axis])
