"""What protection levels alone give, without truth (a flight log, a receiver without a reference).

Without the position errors there is no misleading information to count, no accuracy, no Stanford
diagram and none of the three papers' methods: they all need HPE/VPE. What remains is what the
protection levels say about the *service*: its availability (PL within the alert limit) and continuity
per service level, the PL distributions and time series, per flight (station) and pooled.

Availability and continuity are those of :func:`overbound.methods.counting.count_kpis` (the same
definitions, windows and gaps as with truth): it counts a table whose errors are set to 0 wherever
the PLs are finite, so that an epoch is available when its PLs are within the limits, and only the
PL-based KPIs of its result are reported (:data:`NEEDS_ERRORS` lists the others, and why).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import polars as pl

from overbound.methods.counting import CountingResult, count_kpis
from overbound.services import ServiceLevel

__all__ = ["NEEDS_ERRORS", "NO_TRUTH", "PlDistribution", "PlOnlyAnalysis", "pl_only_analysis"]

#: Why the error-based results are missing.
NO_TRUTH = "no truth: the position errors are unknown (no reference position or trajectory)"
#: The KPIs and methods that need position errors, not computed without them.
NEEDS_ERRORS: tuple[str, ...] = (
    "accuracy (95 % HPE and VPE)",
    "misleading information (MI) and hazardous MI (HMI) counts",
    "Stanford-ESA diagrams and safety index",
    "PL confidence level (Comby, Farnworth & Macabiau 2003)",
    "EVT tail extrapolation (Veerman et al., GIMAT)",
    "parametric analysis (Kannemans 2006)",
    "integrity and PL-bounding verdicts",
)
_QUANTILES = (0.5, 0.95, 0.99)


@dataclass(frozen=True, slots=True)
class PlDistribution:
    """Protection levels of one station (or pooled) over its epochs with a solution.

    ``hpl``, ``vpl``: ``{"p50", "p95", "p99", "max"}`` (m, ``None`` without any PL); ``in_force``:
    the share of the epochs with a logged horizontal alert limit (``hal`` column) whose HPL is within
    it, ``None`` when none is logged; ``modes``: epochs per solution mode as the source names it."""

    n_epochs: int
    n_with_pl: int
    start: str | None
    end: str | None
    hpl: dict[str, float | None]
    vpl: dict[str, float | None]
    in_force: float | None
    n_in_force: int
    modes: dict[str, int]


@dataclass(frozen=True, slots=True)
class PlOnlyAnalysis:
    """The PL-only analysis: ``counting`` (its availability and continuity only are meaningful),
    ``pooled`` and ``by_station`` PL distributions, what was not computed (``needs_errors``) and why."""

    counting: CountingResult
    pooled: PlDistribution
    by_station: dict[str, PlDistribution]
    needs_errors: tuple[str, ...] = NEEDS_ERRORS
    reason: str = NO_TRUTH
    continuity_caution: str | None = None


def pl_only_analysis(table: pl.DataFrame, services: Sequence[ServiceLevel]) -> PlOnlyAnalysis:
    """Availability, continuity and PL distributions of ``table`` (an epoch table whose errors are
    unknown), pooled and per station."""
    solved = pl.col("hpl").is_finite() & pl.col("vpl").is_finite()
    zero = pl.when(solved).then(0.0).otherwise(float("nan"))
    counted = table.with_columns(hpe=zero, vpe=zero).drop("east", "north", strict=False)
    counting = count_kpis(counted, tuple(services))
    stations = table["station"].cast(pl.String).unique().sort().to_list()
    by_station = {s: _distribution(table.filter(pl.col("station").cast(pl.String) == s)) for s in stations}
    return PlOnlyAnalysis(
        counting, _distribution(table), by_station, continuity_caution=_gap_caution(counting)
    )


#: Share of the failing continuity windows held by gaps in the time stamps above which the continuity
#: risk is said to measure the log more than the service.
GAP_DOMINATED = 0.5


def _gap_caution(counting: CountingResult) -> str | None:
    """Why the continuity risks are to be read with care: when at least :data:`GAP_DOMINATED` of the
    windows that fail (all services, both axes combined) hold a missing epoch, the logger's gaps, not
    protection levels above the limits, make most of the risk."""
    fail = gap = 0
    for k in counting.services.values():
        c = k.combined.continuity
        if c is not None and c.risk is not None:
            fail, gap = fail + c.n_fail, gap + c.n_gap_windows
    if not fail or gap < GAP_DOMINATED * fail:
        return None
    return (
        f"Continuity: {gap:,} of the {fail:,} failing windows (all services) hold a gap in the time stamps "
        "(missing seconds, repeated seconds rejected): the continuity risks measure the log's gaps as much "
        "as the service."
    )


def _distribution(t: pl.DataFrame) -> PlDistribution:
    ok = t.filter(pl.col("hpl").is_finite() & pl.col("vpl").is_finite())
    in_force, n_force = None, 0
    if "hal" in t.columns:
        logged = ok.filter(pl.col("hal").is_finite())
        n_force = logged.height
        if n_force:
            in_force = float((logged["hpl"] <= logged["hal"]).mean())
    modes = {}
    if "mode" in t.columns:
        modes = dict(sorted(t.group_by(pl.col("mode").cast(pl.String).fill_null("")).len().iter_rows()))
    return PlDistribution(
        n_epochs=t.height,
        n_with_pl=ok.height,
        start=_iso(t["time"].min()) if t.height else None,
        end=_iso(t["time"].max()) if t.height else None,
        hpl=_quantiles(ok["hpl"].to_numpy()),
        vpl=_quantiles(ok["vpl"].to_numpy()),
        in_force=in_force,
        n_in_force=n_force,
        modes=modes,
    )


def _quantiles(x: np.ndarray) -> dict[str, float | None]:
    """numpy's linear-interpolation quantiles and the maximum (``None`` for no value)."""
    if not x.size:
        return {"p50": None, "p95": None, "p99": None, "max": None}
    q = np.quantile(x, _QUANTILES)
    return {"p50": float(q[0]), "p95": float(q[1]), "p99": float(q[2]), "max": float(x.max())}


def _iso(t) -> str:
    return t.isoformat(timespec="seconds") if t.microsecond == 0 else t.isoformat()
