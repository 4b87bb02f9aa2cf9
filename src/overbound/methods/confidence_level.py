r"""Confidence level in the protection level, per PL band (Comby et al. 2003).

For each *target* protection level the procedure takes the epochs whose PL lies within
a tolerance of the target, thins them to independent samples, bounds their error
distribution by a Gaussian (cdf overbounding, sigma inflation), and computes the
probability that the PLs of the band are bounds of the error at the integrity risk:
the *confidence level* (CL). A band whose CL is below 1 % is *suspect*: its PL does
not bound its errors (the ENAC 15-16 m VPL case of the paper).

Columns needed: ``time``, ``station``, ``vpe`` and ``vpl`` (vertical); ``hpe``,
``hpl``, ``east`` and ``north`` (horizontal). Optional ``alert``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection
from dataclasses import dataclass

import numpy as np
import polars as pl

from overbound.io.schema import InputError, as_numpy
from overbound.jsontext import IsoTimes
from overbound.stats.confidence import confidence_level, ideal_pl, pl_at_confidence
from overbound.stats.dependence import select_spaced
from overbound.stats.overbounding import SigmaInflation, sigma_inflation

__all__ = [
    "AXES",
    "MIN_COMPUTABLE",
    "SUSPECT_BELOW",
    "BandSamples",
    "BandSolve",
    "ConfidenceAnalysis",
    "ConfidenceBin",
    "analysed_columns",
    "analysed_names",
    "band_widths",
    "check_columns",
    "confidence_analysis",
    "samples_bin",
    "solve_band",
    "target_count",
    "validate_parameters",
    "with_solves",
]

AXES = ("vertical", "horizontal")
#: A bin is *suspect* when its confidence level is below this (Comby et al. 2003, section III.3).
SUSPECT_BELOW = 0.01
#: Fewest samples for which a bin's error statistics are computed (the law of the mean in
#: Comby et al. (2003) eq. (24) needs ``n > 2``).
MIN_COMPUTABLE = 3
_COLUMNS = {"vertical": ("vpe", "vpl"), "horizontal": ("hpe", "hpl", "east", "north")}
_COMPONENTS = {"vertical": ("vpe",), "horizontal": ("east", "north")}
_EPS = 1e-9  # float slack when comparing band widths built by repeated addition


@dataclass(frozen=True, slots=True)
class ConfidenceBin:
    r"""One target PL of :func:`confidence_analysis` (one row of the paper's figure 6).

    Fields go to JSON as they are; a NaN (statistic not computed) is written ``null``.

    Attributes
    ----------
    target : the target PL (m).
    lo, hi : the PL band actually used, ``lo <= PL < hi`` (m): ``target -/+ tolerance_used``.
    n : selected samples (at least ``spacing`` apart, containing the largest error).
    mean : estimated error mean :math:`\hat m` (m); horizontal: the norm of the east and north means.
    sigma : estimated error standard deviation :math:`\hat\sigma` (m); horizontal: the larger component's.
    sigma_inflated : the overbounding standard deviation :math:`\hat\Sigma` (m); horizontal: the
        larger of the east and north ones.
    confidence : the confidence level (eq. 34); NaN for an insufficient bin (``n < min_samples``).
    pl_ideal : the PL that :math:`G(\hat m, \hat\Sigma)` exceeds with probability ``risk`` (eq. 9) (m).
    pl_1, pl_99 : the PL (constant over the band's samples) whose confidence level would be
        1 % and 99 % (section III.3, figure 8) (m); NaN for an insufficient bin.
    (``mean``, ``sigma``, ``sigma_inflated`` and ``pl_ideal`` are NaN when ``n < MIN_COMPUTABLE``
    or the errors are all equal.)
    max_abs_error : largest |error| among the samples (|VPE| or HPE) (m); the largest in the band.
    max_ratio : largest |error| / PL among the samples.
    epochs : the samples' GPS times, ISO 8601 (millisecond precision), sorted; an
        :class:`~overbound.jsontext.IsoTimes` (integers, formatted when read or written).
    sufficient : ``n >= min_samples``.
    tolerance_used : the half-width of the band used (m), after widening.
    n_candidates : epochs with a solution in the band, before the spacing.
    suspect : ``confidence < SUSPECT_BELOW`` (1 %).
    """

    target: float
    lo: float
    hi: float
    n: int
    mean: float
    sigma: float
    sigma_inflated: float
    confidence: float
    pl_ideal: float
    pl_1: float
    pl_99: float
    max_abs_error: float
    max_ratio: float
    epochs: IsoTimes
    sufficient: bool
    tolerance_used: float
    n_candidates: int
    suspect: bool

    @classmethod
    def from_dict(cls, d: dict) -> ConfidenceBin:
        """The bin from its JSON form (``null`` back to NaN); inverse of ``asdict`` up to float rounding."""
        kw = {}
        for name in cls.__dataclass_fields__:
            v = d[name]
            if name == "epochs":
                v = IsoTimes.parse(v)
            elif name in ("n", "n_candidates"):
                v = int(v)
            elif name in ("sufficient", "suspect"):
                v = bool(v)
            else:
                v = math.nan if v is None else float(v)
            kw[name] = v
        return cls(**kw)


@dataclass(frozen=True, slots=True, eq=False)
class BandSamples:
    """The samples behind one :class:`ConfidenceBin` (not written to JSON).

    Attributes
    ----------
    rows : row indices of the samples in the analysed table, in time order.
    time_us : their GPS times (microseconds since 1970-01-01, GPS time scale).
    station : their station, as indices into :attr:`ConfidenceAnalysis.stations`.
    pl : their protection levels (m).
    error : their error magnitude, |VPE| or HPE (m).
    components : names of the signed error components overbounded: ``("vpe",)`` or
        ``("east", "north")``.
    signed : the signed errors of each component (m), in the order of ``components``.
    inflations : the :class:`~overbound.stats.overbounding.SigmaInflation` of each component
        (empty when ``n < MIN_COMPUTABLE``).
    """

    rows: np.ndarray
    time_us: np.ndarray
    station: np.ndarray
    pl: np.ndarray
    error: np.ndarray
    components: tuple[str, ...]
    signed: tuple[np.ndarray, ...]
    inflations: tuple[SigmaInflation, ...]

    @property
    def binding(self) -> int:
        """Index of the component with the largest inflated sigma (the one the CL uses); 0 if none."""
        if not self.inflations:
            return 0
        return int(np.argmax([s.sigma_inflated for s in self.inflations]))


@dataclass(frozen=True, slots=True)
class ConfidenceAnalysis:
    """Result of :func:`confidence_analysis`: the parameters, every bin and its samples.

    Attributes
    ----------
    axis : ``vertical`` or ``horizontal``.
    risk : integrity risk per independent sample (eq. 7).
    min_samples, spacing, tolerance, step, max_pl, max_tolerance, core : the parameters used.
    stations : station names of the analysed epochs (table order of first appearance).
    n_epochs : epochs analysed (with a solution, not flagged ``alert``).
    pl_min : lowest PL among them, the first target (m); NaN without epochs.
    bins : one :class:`ConfidenceBin` per target, in increasing target order.
    samples : the :class:`BandSamples` of each bin (parallel to ``bins``).
    """

    axis: str
    risk: float
    min_samples: int
    spacing: float
    tolerance: float
    step: float
    max_pl: float
    max_tolerance: float
    core: float
    stations: tuple[str, ...]
    n_epochs: int
    pl_min: float
    bins: tuple[ConfidenceBin, ...]
    samples: tuple[BandSamples, ...]

    def parameters(self) -> dict[str, float | int]:
        """The procedure's parameters by name."""
        return {
            "min_samples": self.min_samples,
            "spacing": self.spacing,
            "tolerance": self.tolerance,
            "step": self.step,
            "max_pl": self.max_pl,
            "max_tolerance": self.max_tolerance,
            "core": self.core,
        }

    @property
    def suspect(self) -> tuple[int, ...]:
        """Indices of the suspect bins (confidence level below 1 %)."""
        return tuple(i for i, b in enumerate(self.bins) if b.suspect)

    @property
    def worst(self) -> int | None:
        """Index of the bin with the lowest confidence level (first on ties); ``None`` if none has one."""
        cl = np.array([b.confidence for b in self.bins], dtype=float)
        if not np.any(np.isfinite(cl)):
            return None
        return int(np.nanargmin(cl))


@dataclass(frozen=True, slots=True)
class _Data:
    """The analysed epochs, in time order, and their order by PL."""

    rows: np.ndarray
    time_us: np.ndarray
    station: np.ndarray
    pl: np.ndarray
    error: np.ndarray
    signed: tuple[np.ndarray, ...]
    by_pl: np.ndarray  # positions sorted by PL
    pl_sorted: np.ndarray


def confidence_analysis(
    table: pl.DataFrame,
    *,
    axis: str = "vertical",
    min_samples: int = 200,
    spacing: float = 360.0,
    tolerance: float = 0.125,
    step: float = 0.25,
    max_pl: float = 50.0,
    max_tolerance: float = 1.0,
    risk: float = 1e-7,
    core: float = 0.2,
    station: str | None = None,
) -> ConfidenceAnalysis:
    r"""Confidence level in the protection level for each target PL (Comby et al. 2003).

    Parameters
    ----------
    table
        The epoch table.
    axis
        ``vertical`` (VPE, VPL; the paper) or ``horizontal`` (east and north errors, HPL).
    min_samples
        Samples a band must reach (200: appendix 1), widening the band if needed.
    spacing
        Minimum time between two samples of a band (s): 360 s, the correlation time of
        EGNOS errors (section I.2).
    tolerance
        Half-width of the PL band around each target (m); 0.125 m (section II.2).
    step
        Spacing of the targets (m).
    max_pl
        Last target (m): 50 m, the largest vertical alert limit (section II.2, footnote 3).
    max_tolerance
        Largest half-width a band may be widened to (m); must be ``>= tolerance``.
    risk
        Integrity risk per independent sample (eq. 7).
    core
        Share of the error distribution around the mean left out of the cdf overbounding
        (0.2: eqs. 15-16).
    station
        Analyse this station only; by default all stations together (see Notes).

    Returns
    -------
    ConfidenceAnalysis
        The parameters, one :class:`ConfidenceBin` per target (statistics, band used,
        flags, sample epochs) and the :class:`BandSamples` of each.

    Raises
    ------
    InputError
        A needed column is missing; for ``horizontal``, the table has no signed
        ``east``/``north`` errors.
    ValueError
        A parameter is out of range, or ``station`` is not in the table.

    See Also
    --------
    overbound.stats.dependence.select_spaced : the sample selection.
    overbound.stats.overbounding.sigma_inflation : the cdf overbounding (eqs. 10-16).
    overbound.stats.confidence.confidence_level : the confidence level (eqs. 17-46).

    Notes
    -----
    Steps (sections II.2 and III.1):

    1. Epochs with a solution (finite error and PL > 0, and finite east/north for the
       horizontal) and not flagged ``alert`` are kept, in time order (several stations
       merged); NaN epochs are ignored, and so is a zero PL (it bounds nothing; the
       model needs PL > 0). The epochs are sorted by PL once: every band's candidates
       are then a ``searchsorted`` slice, and the loop runs over bands, never over epochs.
    2. Targets :math:`T_k = \mathrm{PL_{min}} + k\,\mathrm{step}` from the lowest PL
       up to ``max_pl`` inclusive, as the paper starts "at the lowest value of the VPL
       in the file".
    3. For each target the band :math:`T - w \le \mathrm{PL} < T + w`, :math:`w` =
       ``tolerance``. Half-open, so that with ``step = 2 tolerance`` the un-widened
       bands partition the PL axis and no epoch falls in two of them.
    4. Among the band's epochs, the sample with the largest |error| (|VPE|, or HPE;
       the earliest on ties) is the anchor, and
       :func:`~overbound.stats.dependence.select_spaced` keeps the largest set of
       epochs at least ``spacing`` apart that contains it (section II.2, second level).
    5. If fewer than ``min_samples`` are kept, the band is widened by ``tolerance`` at a
       time, :math:`w = 2\,\mathrm{tolerance}, 3\,\mathrm{tolerance}, \dots` up to
       ``max_tolerance``, and steps 3-4 are redone (third level); the first width that
       reaches ``min_samples`` is used, else the widest (the bin is then flagged
       ``sufficient = False``). A new anchor is taken each time, as the largest error of
       the wider band may be another epoch.
    6. Per bin: ``sigma_inflation`` of the signed errors gives :math:`\hat m, \hat\sigma,
       \hat\Sigma` (eqs. 10-16) and the ideal PL (eq. 9); for a sufficient bin, the
       confidence level with the samples' own PLs (eqs. 34, 41, 44) and the PLs of 1 %
       and 99 % confidence (section III.3). Horizontal: east and north are
       overbounded separately, :math:`\hat m` = hypot of their means and
       :math:`\hat\Sigma` the larger inflated sigma (the conservative circular model).

    **Choices where the paper is open.**

    * *Cap on widening*, ``max_tolerance = 1 m``: the procedure assumes one error
      distribution per band. The PL is proportional to the error sigma the system
      claims, so a band :math:`T \pm w` mixes claimed sigmas within :math:`\pm w/T`;
      1 m keeps that within :math:`\pm 10\,\%` from 10 m up (the bulk of SBAS VPLs)
      while letting a 6-day 1 Hz campaign fill the bands of its common PLs (at 360 s a
      6-day campaign has only 1440 independent slots, so a band needs 14 % of them).
      A wider band would also dilute a local anomaly: the ENAC 15-16 m tail is a quarter
      of a 4 m band. The price: bands of rare PLs stay insufficient (on simulated 6-day
      campaigns, bands from about 10 to 17 m reach 200 samples; on one seed in ten the
      15-16 m bands themselves stop at 150-195 and the anomaly shows in the neighbouring
      bands that overlap it). The paper grows the band without a cap; its "if possible
      within a 0.25 m interval" is the un-widened band.
    * *Insufficient bins* (``n < min_samples`` at the cap) are kept and flagged
      (``sufficient = False``) with their samples, band, counts and descriptive
      statistics (:math:`\hat m, \hat\sigma, \hat\Sigma`, ideal PL, largest error and
      ratio, from ``MIN_COMPUTABLE`` = 3 samples), but their confidence level, PL1 and
      PL99 are NaN (``null`` in JSON), so they are never ``suspect``. The paper fixes 200
      samples "in order for the analysis to make statistical sense" (section II.2,
      appendix 1: below 200 a single tail sample inflates :math:`\hat\Sigma` strongly). On
      simulated campaigns whose PL bounds the error well, CLs computed from 8-15 samples at
      rare PLs fall below 1 % (the inflation of a handful of samples plus the wide
      :math:`\chi^2_{n-1}` law of :math:`\sigma`): they would be false alarms. An empty band
      has NaN statistics. Lower ``min_samples`` to get CLs from fewer samples.
    * *Several stations.* The selection runs on the merged time axis of all stations: two
      samples of a band are at least ``spacing`` apart whichever station they come from.
      Errors of different stations at the same time are *not* independent: they share the
      broadcast SBAS corrections (satellite clock and orbit corrections, the ionospheric
      grid), whose errors dominate the position error and decorrelate over the same
      ~360 s. Pooling per-station selections would count those correlated samples as
      independent, raise ``n`` and overstate the confidence. Several stations still help:
      a band visited at different times by different stations fills faster. Stations
      known to be independent (different SBAS, or far apart) can be analysed one at a
      time with ``station=``.

    References
    ----------
    .. [1] Comby, D., Farnworth, R., Macabiau, C. (2003), "EGNOS vertical protection level
       assessment", ION GPS/GNSS 2003, pp. 2783-2794: sections II.2 (data selection),
       II.3 (eq. 9, eqs. 10-16), III (the ENAC results, figures 6-10), appendices 1-2.

    Examples
    --------
    Two simulated days whose errors are tripled where the VPL is in [15, 16) m (the ENAC case):

    >>> from overbound.simulate import SimulationConfig, simulate
    >>> sim = simulate(SimulationConfig(days=2, seed=1, tail_fraction=0.0, anomalies=("band:15:16:3",)))
    >>> a = confidence_analysis(sim.table, min_samples=60, max_pl=25.0)
    >>> suspect = [a.bins[i].target for i in a.suspect]
    >>> round(min(suspect), 2), round(max(suspect), 2)
    (14.71, 16.71)
    >>> worst = a.bins[a.worst]
    >>> worst.sufficient, worst.confidence < 0.01, worst.pl_1 > worst.hi
    (True, True, True)
    """
    validate_parameters(axis, min_samples, spacing, tolerance, step, max_pl, max_tolerance, risk, core)
    data, stations = _prepare(table, axis, station)
    spacing_us = round(spacing * 1e6)
    widths = band_widths(tolerance, max_tolerance)
    bins: list[ConfidenceBin] = []
    samples: list[BandSamples] = []
    pl_min = float(data.pl_sorted[0]) if data.pl_sorted.size else math.nan
    # a loop over ~200 bands; everything inside is vectorised
    for k in range(target_count(pl_min, max_pl, step)):
        target = pl_min + k * step
        chosen, width, n_cand = _select_band(data, target, widths, spacing_us, min_samples)
        bin_, band = _band_statistics(
            data, chosen, axis, target, width, n_cand, min_samples, risk=risk, core=core
        )
        bins.append(bin_)
        samples.append(band)
    return ConfidenceAnalysis(
        axis=axis,
        risk=float(risk),
        min_samples=int(min_samples),
        spacing=float(spacing),
        tolerance=float(tolerance),
        step=float(step),
        max_pl=float(max_pl),
        max_tolerance=float(max_tolerance),
        core=float(core),
        stations=stations,
        n_epochs=int(data.rows.size),
        pl_min=pl_min,
        bins=tuple(bins),
        samples=tuple(samples),
    )


def validate_parameters(
    axis: str,
    min_samples: int,
    spacing: float,
    tolerance: float,
    step: float,
    max_pl: float,
    max_tolerance: float,
    risk: float,
    core: float,
) -> None:
    if axis not in AXES:
        raise ValueError(f"axis must be 'vertical' or 'horizontal', got {axis!r}")
    if int(min_samples) != min_samples or min_samples < 1:
        raise ValueError(f"min_samples must be a positive integer, got {min_samples!r}")
    checks = {
        "spacing": (spacing, spacing >= 0),
        "tolerance": (tolerance, tolerance > 0),
        "step": (step, step > 0),
        "max_pl": (max_pl, max_pl > 0),
        "max_tolerance": (max_tolerance, max_tolerance >= tolerance - _EPS),
        "risk": (risk, 0 < risk < 1),
        "core": (core, 0 < core < 1),
    }
    for name, (value, ok) in checks.items():
        if not (math.isfinite(value) and ok):
            rule = {
                "spacing": ">= 0",
                "tolerance": "> 0",
                "step": "> 0",
                "max_pl": "> 0",
                "max_tolerance": f">= tolerance ({tolerance!r})",
                "risk": "in (0, 1)",
                "core": "in (0, 1)",
            }[name]
            raise ValueError(f"{name} must be finite and {rule}, got {value!r}")


def check_columns(columns: Collection[str], axis: str) -> None:
    """Raise the :class:`InputError` of an epoch table whose ``columns`` lack one ``axis`` needs."""
    need = ("time", "station", *_COLUMNS[axis])
    missing = [c for c in need if c not in columns]
    if missing:
        if axis == "horizontal" and set(missing) & {"east", "north"}:
            raise InputError(
                "<epoch table>",
                "the horizontal confidence analysis needs the signed east and north errors "
                f"(columns east, north) to overbound each component; missing {', '.join(missing)}. "
                "HPE alone has lost their signs and means; use a reader that keeps them or add the columns",
            )
        raise InputError(
            "<epoch table>", f"the {axis} confidence analysis needs column(s) {', '.join(missing)}"
        )


def analysed_names(axis: str) -> tuple[str, ...]:
    """The columns the analysis of ``axis`` reads besides the time, station and alerts: the error,
    the PL, then the signed errors it overbounds when they are not the error itself."""
    return _COLUMNS[axis]


def analysed_columns(
    table: pl.DataFrame, axis: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
    """``(ok, pl, |error|, signed)`` of the rows of ``table``: ``ok`` marks the analysed epochs
    (step 1 of :func:`confidence_analysis`), the arrays are those of every row."""
    error_col, pl_col, *components = _COLUMNS[axis]
    pl_ = as_numpy(table[pl_col]).astype(np.float64, copy=False)
    err = np.abs(as_numpy(table[error_col]).astype(np.float64, copy=False))
    signed = tuple(as_numpy(table[c]).astype(np.float64, copy=False) for c in components or [error_col])
    ok = np.isfinite(pl_) & (pl_ > 0) & np.isfinite(err)
    for s in signed:
        ok &= np.isfinite(s)
    if "alert" in table.columns and table["alert"].any():
        ok &= ~as_numpy(table["alert"].fill_null(False))
    return ok, pl_, err, signed


def band_widths(tolerance: float, max_tolerance: float) -> np.ndarray:
    """The half-widths tried for a band (step 5): ``tolerance`` times 1, 2, ... up to ``max_tolerance``."""
    return tolerance * np.arange(1, math.floor(max_tolerance / tolerance + _EPS) + 1)


def target_count(pl_min: float, max_pl: float, step: float) -> int:
    """Number of targets ``pl_min + k step`` up to ``max_pl`` inclusive (step 2); 0 without epochs."""
    return max(math.floor((max_pl - pl_min) / step + _EPS) + 1, 0) if math.isfinite(pl_min) else 0


def _prepare(table: pl.DataFrame, axis: str, station: str | None) -> tuple[_Data, tuple[str, ...]]:
    """Arrays of the analysed epochs in time order, and the station names."""
    check_columns(table.columns, axis)
    st = table["station"].cast(pl.Categorical())
    uniq = st.unique(maintain_order=True)
    names = tuple(uniq.cast(pl.String).to_list())
    phys = as_numpy(uniq.to_physical()).astype(np.int64)
    codes = as_numpy(st.to_physical()).astype(np.int64)
    sorter = np.argsort(phys)
    code = sorter[np.searchsorted(phys, codes, sorter=sorter)] if codes.size else codes
    ok, pl_, err, signed = analysed_columns(table, axis)
    if station is not None:
        if station not in names:
            raise ValueError(f"station {station!r} is not in the table (stations: {', '.join(names)})")
        ok &= code == names.index(station)
    rows = np.flatnonzero(ok)
    time_us = as_numpy(table["time"])[rows]
    if time_us.size > 1 and np.any(time_us[1:] < time_us[:-1]):  # several stations: merge their time axes
        order = np.argsort(time_us, kind="stable")
        rows, time_us = rows[order], time_us[order]
    pls = pl_[rows]
    by_pl = np.argsort(pls, kind="stable")
    data = _Data(
        rows=rows,
        time_us=time_us,
        station=code[rows],
        pl=pls,
        error=err[rows],
        signed=tuple(s[rows] for s in signed),
        by_pl=by_pl,
        pl_sorted=pls[by_pl],
    )
    return data, names


def _select_band(
    data: _Data, target: float, widths: np.ndarray, spacing_us: int, min_samples: int
) -> tuple[np.ndarray, float, int]:
    """Positions (time order) of the samples of the band around ``target``, the half-width used, candidates.

    Widening only adds two thin PL slices to the band, so the candidates of the wider band
    are the previous ones merged with the new slices (timsort merges two sorted runs in
    linear time). A width is skipped without selecting when the candidates occupy fewer
    than ``min_samples`` time slots of ``spacing`` (no two samples at least ``spacing``
    apart share a slot, so that bounds the selection).
    """
    cand = np.empty(0, dtype=np.intp)
    i0 = i1 = int(np.searchsorted(data.pl_sorted, target, side="left"))
    for i, w in enumerate(widths):  # a handful of widenings
        last = i == widths.size - 1
        j0, j1 = (int(j) for j in np.searchsorted(data.pl_sorted, [target - w, target + w], side="left"))
        new = np.concatenate([data.by_pl[j0:i0], data.by_pl[i1:j1]])
        if new.size:
            cand = np.sort(np.concatenate([cand, np.sort(new, kind="stable")]), kind="stable")
        i0, i1 = j0, j1
        if not last and _slots(data.time_us[cand], spacing_us) < min_samples:
            continue  # cannot reach min_samples: no need to select
        if cand.size == 0:
            return cand, float(w), 0
        anchor = int(np.argmax(data.error[cand]))
        chosen = cand[select_spaced(data.time_us[cand], anchor=anchor, spacing=spacing_us)]
        if chosen.size >= min_samples or last:
            return chosen, float(w), int(cand.size)
    raise AssertionError("unreachable: the last width always returns")  # pragma: no cover


def _slots(time_us: np.ndarray, spacing_us: int) -> int:
    """Distinct time slots ``floor(t / spacing)`` of sorted times: an upper bound of any spaced selection."""
    if spacing_us == 0 or time_us.size == 0:
        return int(time_us.size)
    slot = time_us // spacing_us
    return int(np.count_nonzero(slot[1:] != slot[:-1])) + 1


def samples_bin(
    time_us: np.ndarray,
    rows: np.ndarray,
    station: np.ndarray,
    pl: np.ndarray,
    error: np.ndarray,
    signed: tuple[np.ndarray, ...],
    *,
    axis: str,
    target: float,
    width: float,
    n_candidates: int,
    min_samples: int,
    risk: float,
    core: float,
    deferred: bool = False,
):
    """The bin of a band and its samples (step 6) from the samples selected (in time order);
    ``deferred`` as :func:`_band_statistics`."""
    empty = np.empty(0)
    data = _Data(rows, time_us, station, pl, error, signed, empty.astype(np.intp), empty)
    chosen = np.arange(rows.size)
    return _band_statistics(
        data, chosen, axis, target, width, n_candidates, min_samples, risk=risk, core=core, deferred=deferred
    )


def _band_statistics(
    data: _Data,
    chosen: np.ndarray,
    axis: str,
    target: float,
    width: float,
    n_cand: int,
    min_samples: int,
    *,
    risk: float,
    core: float,
    deferred: bool = False,
) -> tuple[ConfidenceBin, BandSamples] | tuple[ConfidenceBin, BandSamples, BandSolve | None]:
    """Step 6 of a band: its statistics from the samples ``chosen``. ``deferred``: without its three
    solves (confidence level, PL1, PL99), returned as a :class:`BandSolve` (``None`` when the band
    has none) for :func:`solve_band` elsewhere (a campaign's workers) and :func:`with_solves`."""
    n = int(chosen.size)
    pls = data.pl[chosen]
    error = data.error[chosen]
    signed = tuple(s[chosen] for s in data.signed)
    nan = math.nan
    mean = sigma = sigma_inflated = confidence = pl_ideal = pl_1 = pl_99 = nan
    inflations: tuple[SigmaInflation, ...] = ()
    request = None
    if n >= MIN_COMPUTABLE and all(np.ptp(s) > 0 for s in signed):
        inflations = tuple(sigma_inflation(s, core=core) for s in signed)
        mean = float(np.hypot(*[f.mean for f in inflations])) if axis == "horizontal" else inflations[0].mean
        sigma = max(f.sigma for f in inflations)
        sigma_inflated = max(f.sigma_inflated for f in inflations)
        pl_ideal = float(ideal_pl(mean=mean, sigma=sigma_inflated, risk=risk, axis=axis))
        if n >= min_samples:
            request = BandSolve(pls, n, mean, sigma_inflated, risk, axis)
            if not deferred:
                confidence, pl_1, pl_99 = solve_band(request)
                request = None
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = error / pls
    bin_ = ConfidenceBin(
        target=float(target),
        lo=float(target - width),
        hi=float(target + width),
        n=n,
        mean=float(mean),
        sigma=float(sigma),
        sigma_inflated=float(sigma_inflated),
        confidence=confidence,
        pl_ideal=pl_ideal,
        pl_1=pl_1,
        pl_99=pl_99,
        max_abs_error=float(error.max()) if n else nan,
        max_ratio=float(ratio.max()) if n else nan,
        epochs=IsoTimes(data.time_us[chosen]),
        sufficient=n >= min_samples,
        tolerance_used=float(width),
        n_candidates=n_cand,
        suspect=bool(confidence < SUSPECT_BELOW),
    )
    band = BandSamples(
        rows=data.rows[chosen],
        time_us=data.time_us[chosen],
        station=data.station[chosen],
        pl=pls,
        error=error,
        components=_COMPONENTS[axis],
        signed=signed,
        inflations=inflations,
    )
    return (bin_, band, request) if deferred else (bin_, band)


@dataclass(frozen=True)
class BandSolve:
    """The inputs of a rated band's three solves (:func:`solve_band`): its samples' PLs, their
    number, and the error model (mean, inflated sigma) at the risk per sample."""

    pls: np.ndarray
    n: int
    mean: float
    sigma: float
    risk: float
    axis: str


def solve_band(s: BandSolve) -> tuple[float, float, float]:
    """The confidence level of the band's PLs (eq. 34), and PL1 and PL99 (section III.3)."""
    model = {"mean": s.mean, "sigma": s.sigma, "risk": s.risk, "axis": s.axis, "n": s.n}
    return (
        float(confidence_level(s.pls, **model)),
        float(pl_at_confidence(0.01, **model)),
        float(pl_at_confidence(0.99, **model)),
    )


def with_solves(bin_: ConfidenceBin, solved: tuple[float, float, float]) -> ConfidenceBin:
    """A deferred bin with its :func:`solve_band` results."""
    confidence, pl_1, pl_99 = solved
    return dataclasses.replace(
        bin_, confidence=confidence, pl_1=pl_1, pl_99=pl_99, suspect=bool(confidence < SUSPECT_BELOW)
    )
