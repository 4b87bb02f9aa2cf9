"""``summary.json``: the counting KPIs as a stable, byte-reproducible document.

Keys are sorted and floats are written with 12 significant digits, so that the same
inputs give the same bytes on every run. NaN and infinities become ``null``.
Schema ``overbound.summary/1``; keys listed in the foundation issue are stable,
others may be added. ``stations`` holds the same KPIs per station when the input has
several stations (empty otherwise); ``confidence`` the PL confidence level of each axis
analysed in brief (bins rated, the suspect bands with a confidence below 1 %, the worst band);
``evt`` the EVT tail extrapolation of each axis analysed in brief (P_MI, its upper bound, the upper
bound per approach, each service's verdict and the message; ``null`` numbers and the reason as
message when the axis could not be analysed); the full documents are ``evt-<axis>.json``;
``parametric`` the parametric analysis (Kannemans 2006) in brief
(:func:`overbound.report.parametric.parametric_brief`; ``{}`` when not run), the full document
being ``parametric.json``. ``verdicts`` holds, per service, the five verdicts and the overall one of
:mod:`overbound.verdict` (``verdicts_by_station`` the same per station when there are several);
``provenance`` the overbound version, the command line, the options and each input's base name, size
and SHA-256; ``network`` (a campaign dataset only, :func:`network_dict`) the partitions analysed and
left out, every station-day's availability and the daily compliance. No absolute path is written
anywhere, nor anything that depends on the cache or the workers.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import polars as pl

from overbound import __version__
from overbound.analysis import Analysis, verdicts
from overbound.jsontext import dumps, to_jsonable
from overbound.methods.counting import AXES, AxisKPI, ContinuityResult, CountingResult, ServiceKPI
from overbound.report.provenance import base_names, file_digest, provenance_dict
from overbound.verdict import KINDS, Assessment, ServiceVerdicts, assess

__all__ = [
    "SCHEMA",
    "base_names",
    "dumps",
    "file_digest",
    "provenance_dict",
    "summary_dict",
    "to_jsonable",
    "verdicts_dict",
    "write_summary",
]

SCHEMA = "overbound.summary/1"


def _continuity(c: ContinuityResult | None) -> dict | None:
    if c is None:
        return None
    return {
        "risk": c.risk,
        "n_windows": c.n_windows,
        "n_fail": c.n_fail,
        "n_gap_windows": c.n_gap_windows,
        "n_truncated": c.n_truncated,
        "window_s": c.window_s,
        "interval_s": c.interval_s,
        "n_off_grid": c.n_off_grid,
        "reason": c.reason or None,
    }


def _axes(kpi: dict[str, AxisKPI], field: str) -> dict:
    return {name: getattr(a, field) for name, a in kpi.items()}


def _service_kpis(k: ServiceKPI) -> dict:
    """Availability, continuity risk and Stanford counts of one service (pooled or per station)."""
    axes = {"horizontal": k.horizontal, "vertical": k.vertical, "combined": k.combined}
    return {
        "availability": _axes(axes, "availability"),
        "continuity_risk": {n: (a.continuity.risk if a.continuity else None) for n, a in axes.items()},
        "stanford": {a: (axes[a].stanford.to_dict() if axes[a].stanford else None) for a in AXES},
    }


def _station_dict(c: CountingResult, services) -> dict:
    """The per-station part of the summary: counts, accuracy and each service's KPIs."""
    return {
        "epochs": {"total": c.n_total, "with_solution": c.n_with_solution},
        "time": {"start": c.start, "end": c.end},
        "accuracy": {"hpe95": c.hpe95, "vpe95": c.vpe95},
        "services": {s.name: _service_kpis(c.services[s.name]) for s in services},
    }


def verdicts_dict(services: dict[str, ServiceVerdicts]) -> dict:
    """``{SERVICE: {availability, continuity, accuracy, integrity, pl_bounding, overall}}``, each
    ``{verdict, requirement, basis, sentence, evidence: [...]}`` (:mod:`overbound.verdict`)."""
    return {name: {k: to_jsonable(sv.get(k)) for k in (*KINDS, "overall")} for name, sv in services.items()}


def summary_dict(
    analysis: Analysis, *, assessment: Assessment | None = None, provenance: dict | None = None
) -> dict:
    """The ``summary.json`` document of an :class:`~overbound.analysis.Analysis`.

    ``verdicts`` (and ``verdicts_by_station`` with several stations) are :func:`overbound.verdict.assess`
    of the analysis (computed when ``assessment`` is ``None``); ``provenance`` is
    :func:`provenance_dict` (version only when ``None``). No absolute path is written: inputs appear by
    their base names, so the same data in another folder give the same bytes.
    """
    c = analysis.counting
    if assessment is None and analysis.evidence is not None:
        assessment = assess(analysis)
    services = {}
    for s in analysis.services:
        k = c.services[s.name]
        axes = {"horizontal": k.horizontal, "vertical": k.vertical, "combined": k.combined}
        services[s.name] = {
            "hal": s.hal,
            "val": s.val,
            **_service_kpis(k),
            "n_available": _axes(axes, "n_available"),
            "continuity": {n: _continuity(a.continuity) for n, a in axes.items()},
            "requirements": {
                "integrity_risk": s.integrity_risk,
                "integrity_exposure_s": s.integrity_exposure_s,
                "tta_s": s.tta_s,
                "continuity_risk": s.continuity_risk,
                "continuity_window_s": s.continuity_window_s,
                "availability": s.availability,
                "availability_max": s.availability_max,
                "accuracy_h95": s.accuracy_h95,
                "accuracy_v95": s.accuracy_v95,
                "source": s.source,
            },
            "verdicts": [dataclasses.asdict(v) for v in verdicts(analysis, s)],
        }
    return {
        "schema": SCHEMA,
        "overbound_version": __version__,
        "title": analysis.title,
        **({"warnings": list(analysis.warnings)} if analysis.warnings else {}),
        **({"truth_trajectory": analysis.truth} if analysis.truth else {}),
        "inputs": [_input_dict(r) for r in analysis.reports],
        "verdicts": verdicts_dict(assessment.services) if assessment else {},
        "verdicts_by_station": (
            {st: verdicts_dict(per) for st, per in assessment.by_station.items()} if assessment else {}
        ),
        "provenance": provenance if provenance is not None else provenance_dict(),
        "epochs": {
            "total": c.n_total,
            "with_solution": c.n_with_solution,
            "no_solution": c.n_total - c.n_with_solution,
            "rejected": analysis.n_rejected,
            "invalidated": analysis.n_invalidated,
        },
        "time": {"start": c.start, "end": c.end, "stations": list(c.stations)},
        "accuracy": {"hpe95": c.hpe95, "vpe95": c.vpe95},
        "safety_index": {a: dataclasses.asdict(c.safety[a]) for a in AXES},
        "services": services,
        "stations": {name: _station_dict(sc, analysis.services) for name, sc in c.by_station.items()},
        "confidence": {a.axis: _confidence_brief(a) for a in analysis.confidence}
        | {
            axis: {"failed": reason}
            for method, axis, reason in analysis.method_failures
            if method == "confidence"
        },
        "evt": _evt_briefs(analysis),
        "parametric": _parametric_brief(analysis),
        "method_failures": [
            {"method": method, "axis": axis, "reason": reason}
            for method, axis, reason in analysis.method_failures
        ],
        **({"network": network_dict(analysis)} if analysis.network is not None else {}),
    }


def network_dict(analysis: Analysis) -> dict:
    """The ``network`` object of a campaign dataset: partitions analysed and left out, and the
    availability of every station-day with the daily compliance per service (the share of
    station-days whose availability meets the service's requirement), per station and pooled."""
    net = analysis.network
    daily = net.daily
    names = [s.name for s in analysis.services]
    compliance = {}
    for s in analysis.services:
        if s.availability is None or daily.is_empty():
            compliance[s.name] = {"required": s.availability, "network": None, "stations": {}}
            continue
        met = daily.with_columns((daily[s.name] >= s.availability).alias("_met"))
        per = met.group_by("station", maintain_order=True).agg(pl.col("_met").mean())
        compliance[s.name] = {
            "required": s.availability,
            "network": float(met["_met"].mean()),
            "stations": dict(zip(per["station"].to_list(), per["_met"].to_list(), strict=True)),
        }
    return {
        "partitions": net.n_partitions,
        "partitions_analysed": net.n_partitions - len(net.failures),
        "unreadable": [dataclasses.asdict(f) for f in net.failures],
        "daily_compliance": compliance,
        "days": {
            station: [
                {
                    "date": r["date"].isoformat(),
                    "epochs": r["n_epochs"],
                    "availability": {n: r[n] for n in names},
                }
                for r in rows.iter_rows(named=True)
            ]
            for (station,), rows in daily.group_by("station", maintain_order=True)
        },
    }


def _input_dict(report) -> dict:
    """A read report with its source reduced to base names."""
    d = report.to_dict()
    d["source"] = base_names(d.get("source", ""))
    return d


def _parametric_brief(analysis: Analysis) -> dict:
    """The parametric analysis in a few numbers per axis; ``{}`` when it was not run."""
    if analysis.parametric is None:
        return {}
    from overbound.report.parametric import parametric_brief  # lazy: it draws with matplotlib

    return parametric_brief(analysis.parametric)


def _confidence_brief(a) -> dict:
    """The PL confidence level in a few numbers; the bins are in ``confidence-<axis>.json``."""
    worst = None if a.worst is None else a.bins[a.worst]
    return {
        "n_bins": len(a.bins),
        "n_bins_rated": sum(b.sufficient for b in a.bins),
        "suspect_targets": [a.bins[i].target for i in a.suspect],
        "worst": None if worst is None else {"target": worst.target, "confidence": worst.confidence},
    }


def _evt_briefs(analysis: Analysis) -> dict:
    """Per axis, the EVT result in a few numbers; the rest is in ``evt-<axis>.json``."""
    out: dict = {}
    for a in analysis.evt:
        t = a.tail
        out[a.axis] = {
            "p_mi": t.p if t else None,
            "p_mi_95": t.p_95 if t else None,
            "p_mi_per_approach_95": t.p_approach_95 if t else None,
            "services": {name: {"meets_requirement": h.meets_requirement} for name, h in a.services.items()},
            "message": a.message,
        }
    for axis, reason in analysis.evt_failures:
        out[axis] = {
            "p_mi": None,
            "p_mi_95": None,
            "p_mi_per_approach_95": None,
            "services": {},
            "message": f"no estimate: {reason}",
        }
    return out


def write_summary(
    analysis: Analysis,
    path: str | Path,
    *,
    assessment: Assessment | None = None,
    provenance: dict | None = None,
) -> Path:
    """Write ``summary.json``; return its path."""
    path = Path(path)
    doc = summary_dict(analysis, assessment=assessment, provenance=provenance)
    path.write_text(dumps(doc), encoding="utf-8")
    return path
