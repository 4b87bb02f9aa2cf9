"""The ``overbound analyze`` pipeline: read inputs, count KPIs, keep every intermediate."""

from __future__ import annotations

import datetime as dt
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import polars as pl

from overbound._allocator import release_freed_memory
from overbound.campaign import CampaignCounting, count_campaign, partitions_in
from overbound.io.dataset import Partition, is_dataset, read_manifest
from overbound.io.geodesy import MeanPosition, Reference
from overbound.io.open import Source, expand_archives, read, source_name
from overbound.io.schema import InputError, ReadReport, validate_epochs
from overbound.methods.confidence_level import ConfidenceAnalysis, confidence_analysis
from overbound.methods.counting import CountingResult, count_kpis
from overbound.methods.evidence import Evidence, counted_evidence
from overbound.services import SERVICES, ServiceLevel, resolve_services

if TYPE_CHECKING:  # imported when run: they are the slow part of the import
    from overbound.io.truth import Truth
    from overbound.methods.parametric import ParametricAnalysis
    from overbound.methods.protection_levels import PlOnlyAnalysis
    from overbound.methods.tail_extrapolation import TailAnalysis

__all__ = ["Analysis", "Verdict", "analyze", "load_epochs", "verdicts"]


@dataclass(frozen=True, slots=True)
class Analysis:
    """Result of :func:`analyze`.

    Attributes
    ----------
    table : the pooled epoch table of all inputs (sorted by station, then time).
    reports : one :class:`~overbound.io.schema.ReadReport` per input.
    services : the service levels analysed.
    counting : the counting KPIs.
    title : a label for the report (the inputs' names).
    confidence : the PL confidence-level analyses (Comby et al. 2003), one per axis analysed.
    evt : the EVT tail extrapolations (Veerman et al., GIMAT), one per axis analysed.
    evt_failures : ``(axis, reason)`` of each axis whose EVT analysis could not run (e.g. too few
        tail values): no estimate there, and why.
    parametric : the parametric availability, integrity and continuity analysis (Kannemans 2006) of
        both axes, ``None`` when not run (an axis it could not analyse carries its reason).
    method_failures : ``(method, axis, reason)`` of each PL confidence-level axis
        (``"confidence"``) or parametric analysis (``"parametric"``, axis ``"both"``) whose
        numerical steps could not run on this input: the analysis goes on without it, and the
        report and JSON say which stage failed and why.
    evidence : the counted evidence of the verdicts (:func:`~overbound.methods.evidence.counted_evidence`):
        counts with exact bounds that account for the dependence between epochs, and the
        safety-index tail counts the models are checked against. ``None`` for a counting-only
        campaign analysis (no verdicts then).
    network : for a campaign dataset, its analysis by partition
        (:class:`~overbound.campaign.CampaignCounting`: per-day availability, partitions that
        could not be read, cache use); ``counting`` is then its merged result.
    pl_only : for inputs without truth (errors unknown, e.g. a flight log), the protection-level-only
        analysis (:mod:`overbound.methods.protection_levels`); ``counting`` is then its counting,
        whose error-based KPIs are meaningless, and no method nor verdict is run.
    warnings : what the reader must know before trusting the numbers, shown on the report's first
        screen and in ``summary.json``: errors against the mean position (``--reference mean``), an
        error scale implausible for the reference (:func:`input_warnings`).
    truth : with a truth trajectory (``reference`` a :class:`~overbound.io.truth.Truth`, ``--truth``), what
        the errors rest on: :meth:`~overbound.io.truth.Truth.summary` (file, span, samples, gaps,
        interpolation) and its ``statement``, said in the report's header and ``summary.json``: not a
        warning, the basis of every error.
    band_confidences : the confidence levels of the PL bands the verdicts re-evaluate at each
        service's risk (R8 of :mod:`overbound.verdict`), computed ahead on a campaign's workers
        (keys of :func:`~overbound.verdict.band_confidence_inputs`); empty: the verdicts compute them.
    """

    table: pl.DataFrame
    reports: tuple[ReadReport, ...]
    services: tuple[ServiceLevel, ...]
    counting: CountingResult
    title: str
    confidence: tuple[ConfidenceAnalysis, ...] = ()
    evt: tuple[TailAnalysis, ...] = ()
    evt_failures: tuple[tuple[str, str], ...] = ()
    parametric: ParametricAnalysis | None = None
    evidence: Evidence | None = None
    method_failures: tuple[tuple[str, str, str], ...] = ()
    network: CampaignCounting | None = None
    band_confidences: dict = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    pl_only: PlOnlyAnalysis | None = None
    truth: dict | None = None

    @property
    def n_rejected(self) -> int:
        return sum(r.n_rejected for r in self.reports)

    @property
    def n_invalidated(self) -> int:
        return sum(sum(r.invalidated.values()) for r in self.reports)


def load_epochs(
    inputs: Sequence[Source],
    *,
    format: str | None = None,
    reference: Reference | MeanPosition | Truth | None = None,
    station: str | None = None,
    strict: bool = False,
    mapping: Mapping[str, str] | None = None,
    columns: Sequence[str] | None = None,
    time_range: tuple[dt.datetime | None, dt.datetime | None] | None = None,
    progress: Callable[[str], None] | None = None,
) -> tuple[pl.DataFrame, tuple[ReadReport, ...]]:
    """Read and pool several inputs into one epoch table.

    Inputs of the same station must not overlap in time: the pooled table is sorted by
    station and time and checked by :func:`~overbound.io.schema.validate_epochs`, which
    raises on duplicate epochs across files.
    """
    if not inputs:
        raise InputError("<inputs>", "no input files given")
    tables, reports = [], []
    for src in expand_archives(inputs):
        if progress:
            progress(source_name(src))
        t, r = read(
            src,
            format=format,
            reference=reference,
            station=station,
            strict=strict,
            mapping=mapping,
            columns=columns,
            time_range=time_range,
        )
        tables.append(t)
        reports.append(r)
    table = pl.concat(tables, how="diagonal_relaxed") if len(tables) > 1 else tables[0]
    if len(tables) > 1:
        table = table.sort(["station", "time"], maintain_order=True)
    name = ", ".join(source_name(s) for s in inputs) if len(inputs) > 1 else source_name(inputs[0])
    if table.height == 0:
        why = "; ".join(f"{r.source}: {r.rows_read} read, rejected {dict(r.rejected)}" for r in reports)
        raise InputError(name, f"no epoch left to analyse ({why})")
    table = validate_epochs(table, name)
    # One chunk per column: the counting then reads zero-copy numpy views of the table
    # instead of concatenated copies (a Parquet read gives one chunk per row group).
    if any(table[c].n_chunks() > 1 for c in table.columns):
        table = table.rechunk()
    return table, tuple(reports)


def analyze(
    inputs: Sequence[Source] | pl.DataFrame,
    *,
    services: Sequence[str] | Sequence[ServiceLevel] | None = None,
    format: str | None = None,
    reference: Reference | MeanPosition | Truth | None = None,
    station: str | None = None,
    strict: bool = False,
    mapping: Mapping[str, str] | None = None,
    title: str | None = None,
    columns: Sequence[str] | None = (),
    time_range: tuple[dt.datetime | None, dt.datetime | None] | None = None,
    confidence: Sequence[str] | None = (),
    evt: Sequence[str] | None = (),
    evt_n_boot: int = 1000,
    evt_seed: int = 0,
    parametric: bool = False,
    progress: Callable[[str], None] | None = None,
    client=None,
    counting_only: bool = False,
    cache: bool = True,
) -> Analysis:
    """Read ``inputs`` (or take an epoch table) and count the KPIs for each service.

    ``services`` are names, ``NAME:HAL:VAL`` strings or :class:`ServiceLevel`;
    all built-in levels when ``None``. ``mapping`` maps epoch-table names to the
    columns of CSV/Parquet inputs (see :func:`overbound.io.read`). ``columns`` are the optional epoch-table
    columns to keep (default none: the counting needs only the required ones, and a
    year of 1 Hz ``east``/``north`` is half a gigabyte); ``None`` keeps all.
    ``time_range`` keeps the epochs with ``start <= time < stop`` (GPS time).
    ``confidence`` names the axes of the PL confidence-level analysis (Comby et al. 2003,
    :func:`~overbound.methods.confidence_level.confidence_analysis` with its defaults) to
    run: ``()`` none (the default), ``None`` vertical plus horizontal when the table has
    ``east``/``north`` (read them with ``columns``).
    ``evt`` names the axes of the EVT tail extrapolation (Veerman et al.,
    :func:`~overbound.methods.tail_extrapolation.tail_analysis`: automatic threshold and cluster
    gap, ``evt_n_boot`` resamples, seed ``evt_seed``, the HMI of each of ``services`` with an alert
    limit on the axis): ``()`` none (the default), ``None`` vertical plus horizontal when the table
    has horizontal solutions. An axis that cannot be analysed (too few tail values, no solution) is
    listed in ``Analysis.evt_failures`` with the reason instead of failing the analysis. Pass
    ``"alert"`` in ``columns`` so that alerted epochs are excluded.
    ``parametric`` runs the parametric analysis of Kannemans (2006)
    (:func:`~overbound.methods.parametric.parametric_analysis` with its defaults: decorrelation times
    from the ACF, 95 % bounds, ``services``) on both axes; an axis it cannot analyse carries its
    reason in ``Analysis.parametric.reasons``.

    A campaign dataset (one input, a directory of :mod:`overbound.io.dataset`) is counted
    partition by partition (:func:`~overbound.campaign.count_campaign` on ``client``, a
    ``distributed.Client``, or in this process when ``None``; partials cached unless
    ``cache=False``): the same counting and verdicts' evidence as of its pooled table, in memory
    bounded by a partition, and so are the methods (:mod:`overbound.campaign_confidence`,
    :mod:`overbound.campaign_tail`, :mod:`overbound.campaign_parametric`): the pooled table is never
    read. ``counting_only`` skips the evidence (no verdicts) and the methods.
    """
    methods = _Methods(confidence, evt, evt_n_boot, evt_seed, parametric)
    if _is_campaign(inputs, format):
        if any(x is not None for x in (reference, station, mapping)) or strict:
            raise InputError(
                str(inputs[0]),
                "a dataset is read as ingested: give --reference (or --truth), --station, --column and "
                "--strict to 'overbound ingest' instead",
            )
        return _analyze_campaign(
            Path(inputs[0]),
            _levels(services),
            methods,
            title=title,
            columns=columns,
            time_range=time_range,
            client=client,
            cache=cache,
            counting_only=counting_only,
            progress=progress,
        )
    if isinstance(inputs, pl.DataFrame):
        table, reports = validate_epochs(inputs), ()
        label = title or "epoch table"
    else:
        table, reports = load_epochs(
            inputs,
            format=format,
            reference=reference,
            station=station,
            strict=strict,
            mapping=mapping,
            columns=columns,
            time_range=time_range,
            progress=progress,
        )
        label = title or ", ".join(Path(source_name(s)).name for s in inputs)
    levels = _levels(services)
    if reports and not any(r.truth for r in reports):
        return _pl_only(table, reports, levels, label, progress)
    if not all(r.truth for r in reports):
        raise InputError(
            ", ".join(r.source for r in reports if not r.truth),
            "no truth (errors unknown) while other inputs have errors: analyse them separately",
        )
    if progress:
        progress("counting KPIs")
    done = _with_methods(table, reports, levels, count_kpis(table, levels), label, methods, progress)
    return replace(done, warnings=input_warnings(table, reference), truth=truth_basis(reference))


def truth_basis(reference: Reference | MeanPosition | Truth | None) -> dict | None:
    """:attr:`Analysis.truth` of ``reference``: the summary and statement of a truth trajectory, else None."""
    from overbound.io.truth import Truth

    if not isinstance(reference, Truth):
        return None
    return {"statement": reference.statement(), **reference.summary()}


def _pl_only(table, reports, levels, label, progress) -> Analysis:
    """The analysis of inputs without truth: what the protection levels alone give."""
    from overbound.methods.protection_levels import NO_TRUTH, pl_only_analysis

    if progress:
        progress("protection levels without truth")
    result = pl_only_analysis(table, levels)
    note = (
        f"Protection levels only, {NO_TRUTH}. Availability, continuity and the PL distributions are given; "
        "accuracy, MI/HMI, the Stanford diagrams, the three papers' methods and the verdicts need the errors "
        "and are not computed."
    )
    warnings = (note, *((result.continuity_caution,) if result.continuity_caution else ()))
    return Analysis(table, reports, levels, result.counting, label, warnings=warnings, pl_only=result)


#: Median HPE (m) above which the errors are taken to come from a wrong reference position: an SBAS or
#: even a standalone GPS solution is within a few metres of truth (a height in feet, a swapped sign or
#: another station's coordinates give tens to thousands of metres).
IMPLAUSIBLE_MEDIAN_HPE_M = 50.0
#: The same for the median |VPE| (m).
IMPLAUSIBLE_MEDIAN_VPE_M = 50.0


#: What errors against the mean position hide (the warning of ``--reference mean``).
_MEAN_CAVEAT = (
    "not a surveyed position: HPE and VPE show the scatter about that mean, a constant bias of the "
    "receiver is invisible, and the integrity results are optimistic to that extent."
)


def input_warnings(
    table: pl.DataFrame, reference: Reference | MeanPosition | Truth | None
) -> tuple[str, ...]:
    r"""What the report must say first about the errors of ``table``: that they are against the mean
    position (``reference`` :data:`~overbound.io.geodesy.MEAN_POSITION`), and whether their scale is
    implausible (median HPE above :data:`IMPLAUSIBLE_MEDIAN_HPE_M` or median \|VPE\| above
    :data:`IMPLAUSIBLE_MEDIAN_VPE_M` over the epochs with a solution)."""
    out = []
    if isinstance(reference, MeanPosition):
        out.append(
            "Errors are against the mean of the receiver's own positions (of each input file, over the "
            f"whole file), {_MEAN_CAVEAT}"
        )
    # two columns' medians over the solved epochs, without a filtered copy of the whole table
    solved = pl.all_horizontal(pl.col("hpe", "vpe", "hpl", "vpl").is_finite())
    hpe, vpe = table.select(
        pl.col("hpe").filter(solved).median(), pl.col("vpe").abs().filter(solved).median()
    ).row(0)
    if hpe is not None and (hpe > IMPLAUSIBLE_MEDIAN_HPE_M or vpe > IMPLAUSIBLE_MEDIAN_VPE_M):
        from overbound.io.truth import Truth

        if isinstance(reference, Truth):
            check = (
                "Check the truth trajectory (UTC times labelled as GPS time put it 18 s times the speed "
                "off; heights above the geoid, not the ellipsoid; another datum or another run)"
            )
        elif reference is not None:
            check = "Check the reference position (a height in feet, a sign, another station's coordinates)"
        else:
            check = "Check the input's errors (their unit, and the position they were computed against)"
        out.append(
            f"The median HPE is {hpe:.3g} m and the median |VPE| {vpe:.3g} m: implausible for a GNSS "
            f"receiver. {check}; every integrity result below rests on it."
        )
    return tuple(out)


@dataclass(frozen=True, slots=True)
class _Methods:
    """The methods :func:`analyze` was asked to run (its arguments of the same names)."""

    confidence: Sequence[str] | None
    evt: Sequence[str] | None
    evt_n_boot: int
    evt_seed: int
    parametric: bool

    @property
    def none(self) -> bool:
        """No method asked: the counting and its evidence only."""
        return not self.parametric and self.evt is not None and not self.evt and self.confidence == ()


def _with_methods(
    table: pl.DataFrame,
    reports: tuple[ReadReport, ...],
    levels: tuple[ServiceLevel, ...],
    counting: CountingResult,
    label: str,
    methods: _Methods,
    progress: Callable[[str], None] | None,
) -> Analysis:
    """The analysis of ``table`` with its ``counting`` done: the evidence and the methods asked."""
    evidence = counted_evidence(table, counting, levels)
    confidence, evt, parametric = methods.confidence, methods.evt, methods.parametric
    axes = _confidence_axes(table) if confidence is None else tuple(confidence)
    if axes and progress:
        progress("PL confidence level")
    failures: list[tuple[str, str, str]] = []
    cl = tuple(
        c for a in axes if (c := _guarded(failures, "confidence", a, confidence_analysis, table, axis=a))
    )
    evt_axes = _evt_axes(table) if evt is None else tuple(dict.fromkeys(evt))
    done, failed = _run_evt(table, evt_axes, levels, methods.evt_n_boot, methods.evt_seed, progress)
    par = None
    if parametric:
        from overbound.methods.parametric import parametric_analysis

        if progress:
            progress("parametric analysis")
        par = _guarded(failures, "parametric", "both", parametric_analysis, table, services=levels)
    return Analysis(table, reports, levels, counting, label, cl, done, failed, par, evidence, tuple(failures))


def _is_campaign(inputs, format: str | None) -> bool:
    return (
        not isinstance(inputs, pl.DataFrame)
        and len(inputs) == 1
        and format in (None, "dataset")
        and isinstance(inputs[0], str | Path)
        and is_dataset(inputs[0])
    )


def _analyze_campaign(
    dataset: Path,
    levels: tuple[ServiceLevel, ...],
    methods: _Methods,
    *,
    title: str | None,
    columns: Sequence[str] | None,
    time_range: tuple[dt.datetime | None, dt.datetime | None] | None,
    client,
    cache: bool,
    counting_only: bool,
    progress: Callable[[str], None] | None,
) -> Analysis:
    """:func:`analyze` of a campaign dataset (see there): every method by partition."""

    def tick(stage: str, done: int, total: int) -> None:
        if progress:
            progress(f"counting KPIs, {stage}: {done}/{total} station-days")

    network = count_campaign(
        dataset,
        levels,
        client=client,
        cache=cache,
        time_range=time_range,
        evidence=not counting_only,
        progress=tick,
    )
    report = _campaign_report(dataset, network)
    evt_done, cl, failures, par, bands = ((), ()), (), [], None, {}
    if not counting_only:  # the methods by partition read the partitions the counting read
        failed_keys = {f.key for f in network.failures}
        parts = [p for p in partitions_in(dataset, time_range) if p.key not in failed_keys]
        _release(client)  # after each method: its passes' memory would sit under the next one's
        cl, failures = _campaign_confidence(parts, methods, columns, client, time_range, progress)
        bands = _band_confidences(cl, levels, client, progress)
        _release(client)
        evt_done = _campaign_evt(parts, levels, methods, client, time_range, progress)
        _release(client)
        par = _campaign_parametric(parts, levels, methods, client, time_range, progress, failures)
    _release(client)
    warnings, truth = _campaign_basis(read_manifest(dataset))
    return Analysis(
        pl.DataFrame(),
        (report,),
        levels,
        network.counting,
        title or dataset.name,
        warnings=warnings,
        truth=truth,
        confidence=cl,
        evt=evt_done[0],
        evt_failures=evt_done[1],
        parametric=par,
        evidence=network.evidence,
        method_failures=tuple(failures),
        network=network,
        band_confidences=bands,
    )


def _campaign_basis(manifest: dict) -> tuple[tuple[str, ...], dict | None]:
    """What a dataset's errors rest on, from its manifest: a warning for the stations ingested against
    their mean position, and the truth trajectories of those ingested with one."""
    stations = manifest.get("stations", {})
    mean = sorted(name for name, e in stations.items() if e.get("reference") == "mean")
    warnings = (
        (f"Errors of {', '.join(mean)} are against the mean of each input's own positions, {_MEAN_CAVEAT}",)
        if mean else ()
    )  # fmt: skip
    truths = {name: e["truth"] for name, e in sorted(stations.items()) if e.get("truth")}
    if not truths:
        return warnings, None
    said = "; ".join(f"{name}: " + " ".join(t["statement"] for t in ts) for name, ts in truths.items())
    return warnings, {"statement": said, "stations": truths}


def _band_confidences(cl, levels, client, progress) -> dict:
    """R8's evaluations of the verdicts (:func:`~overbound.verdict.band_confidence_inputs`), one task
    per band on the workers: the same numbers the verdicts would compute one after the other."""
    from overbound.campaign import runner_for
    from overbound.verdict import band_confidence, band_confidence_inputs

    inputs = band_confidence_inputs(cl, levels)
    if progress and inputs:
        progress(f"PL confidence level at the services' risks: {len(inputs)} bands")
    runner = runner_for(client)
    return dict(zip(inputs, runner.starmap(band_confidence, list(inputs.values())), strict=True))


def _campaign_parametric(parts, levels, methods: _Methods, client, time_range, progress, failures: list):
    """The parametric analysis of the partitions the counting read (the passes of
    :mod:`overbound.campaign_parametric`), when asked: as of the pooled table."""
    if not methods.parametric:
        return None
    from overbound.campaign_parametric import campaign_parametric

    def tick(stage: str, done: int, total: int) -> None:
        if progress:
            progress(f"{stage}: {done}/{total}")

    return _guarded(
        failures,
        "parametric",
        "both",
        campaign_parametric,
        parts,
        services=levels,
        client=client,
        time_range=time_range,
        progress=tick,
    )


def _campaign_evt(
    parts: list[Partition],
    levels: tuple[ServiceLevel, ...],
    methods: _Methods,
    client,
    time_range,
    progress: Callable[[str], None] | None,
) -> tuple[tuple[TailAnalysis, ...], tuple[tuple[str, str], ...]]:
    """The EVT of each axis asked, from the partitions the counting read (its three passes of
    :mod:`overbound.campaign_tail`): as :func:`_run_evt` of the pooled table."""
    from overbound.campaign_tail import NO_SOLUTION, campaign_tail_data
    from overbound.methods.tail_extrapolation import tail_analysis_of, tail_filters

    asked = ("vertical", "horizontal") if methods.evt is None else tuple(dict.fromkeys(methods.evt))
    if not asked:
        return (), ()
    specs = {a: tuple(_service_spec(s) for s in levels if s.alert_limit(a) is not None) for a in asked}

    def tick(stage: str, done: int, total: int) -> None:
        if progress:
            progress(f"EVT tail extrapolation, {stage}: {done}/{total}")

    inputs = campaign_tail_data(
        parts,
        {a: tail_filters(a, specs[a]) for a in asked},
        client=client,
        time_range=time_range,
        progress=tick,
    )
    done, failed = [], []
    for axis in asked:
        if axis not in inputs.data:
            why = inputs.failed[axis]
            # as _evt_axes: with the axes chosen automatically, a horizontal without a solution is left out
            if not (methods.evt is None and axis == "horizontal" and why == NO_SOLUTION):
                failed.append((axis, why))
            continue
        if progress:
            progress(f"EVT tail extrapolation, {axis}")
        try:
            done.append(
                tail_analysis_of(
                    inputs.data[axis],
                    axis=axis,
                    services=specs[axis],
                    n_boot=methods.evt_n_boot,
                    rng=methods.evt_seed,
                )
            )
        except ValueError as exc:  # InputError too: too few tail values
            failed.append((axis, str(exc)))
    return tuple(done), tuple(failed)


def _campaign_confidence(
    parts: list[Partition],
    methods: _Methods,
    columns: Sequence[str] | None,
    client,
    time_range,
    progress: Callable[[str], None] | None,
) -> tuple[tuple[ConfidenceAnalysis, ...], list[tuple[str, str, str]]]:
    """The PL confidence level of each axis asked, from the partitions the counting read (the
    passes of :mod:`overbound.campaign_confidence`): as of the pooled table read with ``columns``,
    with its failures."""
    from overbound.campaign_confidence import campaign_confidence

    if methods.confidence == ():
        return (), []

    def tick(stage: str, done: int, total: int) -> None:
        if progress:
            progress(f"PL confidence level, {stage}: {done}/{total}")

    run = campaign_confidence(
        parts, methods.confidence, columns=columns, client=client, time_range=time_range, progress=tick
    )
    return run.done, [
        ("confidence", axis, why if isinstance(why, str) else failure_text(why)) for axis, why in run.failed
    ]


def _release(client) -> None:
    """The workers wait now (the driver fits, or writes the report): they give back the memory
    their passes kept for reuse, which would otherwise add to the campaign's peak; and so does
    the driver, whose merges of partials leave freed memory behind (after the counting of 10
    station-years: 1.1 GB resident of which 0.26 GB live, measured)."""
    if client is not None:
        client.run(release_freed_memory)
        release_freed_memory()


def _campaign_report(dataset: Path, network: CampaignCounting) -> ReadReport:
    """The read report of a dataset: its epochs, and the partitions that could not be read."""
    n_stations = len(read_manifest(dataset).get("stations", {})) or len(network.counting.stations)
    n = network.counting.n_total
    failed = [f"{f.station} {f.date}: {f.reason}" for f in network.failures]
    return ReadReport(
        source=str(dataset),
        format="dataset",
        rows_read=n,
        rows_kept=n,
        notes=(
            f"{network.n_partitions} station-days of {n_stations} stations, "
            f"{len(network.failures)} unreadable (left out)"
            + (": " + "; ".join(failed[:20]) if failed else ""),
        ),
    )


#: What a numerical step raises when it cannot run on an input (a root-finder meeting NaN,
#: a singular matrix, an overflow): the method is reported as failed, the analysis goes on.
NUMERICAL_FAILURES = (ValueError, ArithmeticError, RuntimeError, np.linalg.LinAlgError)


_PACKAGE = str(Path(__file__).parent)


def _guarded(failures: list, method: str, axis: str, run: Callable, /, *args, **kwargs):
    """``run(*args, **kwargs)``, or ``None`` with ``(method, axis, reason)`` added to ``failures``."""
    try:
        return run(*args, **kwargs)
    except NUMERICAL_FAILURES as exc:
        failures.append((method, axis, failure_text(exc)))
        return None


def failure_text(exc: BaseException) -> str:
    """``<type> in <module>.<function>: <message>``, the stage being the innermost frame of our
    own code (not scipy's or numpy's)."""
    frames = traceback.extract_tb(exc.__traceback__)
    ours = [f for f in frames if f.filename.startswith(_PACKAGE)]
    where = (ours or frames)[-1] if frames else None
    stage = f" in {Path(where.filename).stem}.{where.name}" if where else ""
    return f"{type(exc).__name__}{stage}: {exc}"


def error_text(exc: BaseException) -> str:
    """Our own messages as they are; one raised inside numpy or scipy (a root-finder meeting NaN)
    as :func:`failure_text`, with the stage of ours that called it, since its text names neither."""
    frames = traceback.extract_tb(exc.__traceback__)
    return str(exc) if frames and frames[-1].filename.startswith(_PACKAGE) else failure_text(exc)


def _confidence_axes(table: pl.DataFrame) -> tuple[str, ...]:
    """Vertical always; horizontal when the table has signed east/north errors."""
    has_en = {"east", "north"} <= set(table.columns) and table["east"].is_not_nan().any()
    return ("vertical", "horizontal") if has_en else ("vertical",)


def _evt_axes(table: pl.DataFrame) -> tuple[str, ...]:
    """Vertical always; horizontal when some epoch has a finite HPE and an HPL > 0."""
    if table.is_empty():
        return ("vertical",)
    hpe, hpl = table["hpe"].to_numpy(), table["hpl"].to_numpy()
    has_h = bool(np.any(np.isfinite(hpe) & np.isfinite(hpl) & (hpl > 0)))
    return ("vertical", "horizontal") if has_h else ("vertical",)


def _service_spec(s: ServiceLevel) -> str:
    """The ``--service`` text of a level: its name when built in, ``NAME:HAL:VAL`` otherwise."""
    if SERVICES.get(s.name) == s:
        return s.name
    return f"{s.name}:{s.hal!r}:{'-' if s.val is None else repr(s.val)}"


def _run_evt(
    table: pl.DataFrame,
    axes: tuple[str, ...],
    levels: tuple[ServiceLevel, ...],
    n_boot: int,
    seed: int,
    progress: Callable[[str], None] | None,
) -> tuple[tuple[TailAnalysis, ...], tuple[tuple[str, str], ...]]:
    """The EVT analysis of each axis; an axis that cannot be analysed gives its reason instead."""
    from overbound.methods.tail_extrapolation import tail_analysis

    done, failed = [], []
    for axis in axes:  # one or two axes
        if progress:
            progress(f"EVT tail extrapolation, {axis}")
        specs = tuple(_service_spec(s) for s in levels if s.alert_limit(axis) is not None)
        try:
            done.append(tail_analysis(table, axis=axis, n_boot=n_boot, rng=seed, services=specs))
        except ValueError as exc:  # InputError too: no solution, too few tail values
            failed.append((axis, str(exc)))
    return tuple(done), tuple(failed)


def _levels(services: Sequence[str] | Sequence[ServiceLevel] | None) -> tuple[ServiceLevel, ...]:
    if services and all(isinstance(s, ServiceLevel) for s in services):
        return tuple(services)  # type: ignore[arg-type]
    return resolve_services([str(s) for s in services] if services else None)


@dataclass(frozen=True, slots=True)
class Verdict:
    """One KPI against its requirement.

    ``passed`` is ``None`` when the value could not be computed (e.g. continuity at
    30 s sampling) or the service states no requirement for it.
    """

    kpi: str
    value: float | int | None
    required: float | int | None
    comparison: str
    passed: bool | None
    note: str = ""


def verdicts(analysis: Analysis, service: ServiceLevel) -> tuple[Verdict, ...]:
    """The service's counting KPIs against its requirements.

    These are the KPI rows of the report. The MI and HMI counts carry no pass: a count can never
    show 2e-7 per approach (an observed HMI is a fail); the verdicts of :mod:`overbound.verdict`
    weigh the counts with the statistical methods.
    """
    c = analysis.counting
    k = c.services[service.name]
    out = [
        _check("availability (combined)", k.combined.availability, service.availability, ">="),
        _check(
            "continuity risk (combined)",
            k.combined.continuity.risk if k.combined.continuity else None,
            service.continuity_risk,
            "<=",
            k.combined.continuity.reason if k.combined.continuity else "",
        ),
        _check("HPE95 (m)", c.hpe95, service.accuracy_h95, "<="),
    ]
    if service.val is not None:
        out.append(_check("|VPE|95 (m)", c.vpe95, service.accuracy_v95, "<="))
    v = k.vertical.stanford
    mi = k.horizontal.stanford.mi + k.horizontal.stanford.hmi + (v.mi + v.hmi if v else 0)
    hmi = k.horizontal.stanford.hmi + (v.hmi if v else 0)
    risk = f"{service.integrity_risk:g} per {service.integrity_exposure_s:g} s"
    out.append(
        Verdict(
            "MI epochs (counted)",
            mi,
            None,
            "<=",
            None,
            f"PE > PL while PL < AL (HMI included); the PL-bounding verdict ({risk}) weighs the count with "
            "the tail models: see the verdicts",
        )
    )
    out.append(
        Verdict(
            "HMI epochs (counted)",
            hmi,
            0,
            "<=",
            False if hmi else None,
            "an observed HMI is an integrity fail"
            if hmi
            else f"none observed; a count alone cannot show {risk}: see the integrity verdict",
        )
    )
    return tuple(out)


def _check(kpi: str, value: float | None, required: float | None, cmp: str, note: str = "") -> Verdict:
    if value is None or required is None:
        return Verdict(
            kpi, value, required, cmp, None, note or ("no requirement" if required is None else "")
        )
    ok = value >= required if cmp == ">=" else value <= required
    return Verdict(kpi, value, required, cmp, bool(ok), note)
