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
being ``parametric.json``.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from overbound import __version__
from overbound.analysis import Analysis, verdicts
from overbound.methods.counting import AXES, AxisKPI, ContinuityResult, CountingResult, ServiceKPI

__all__ = ["SCHEMA", "dumps", "summary_dict", "to_jsonable", "write_summary"]

SCHEMA = "overbound.summary/1"
_DIGITS = 12


def to_jsonable(obj: Any) -> Any:
    """Plain JSON types: dataclasses to dicts, numpy scalars to Python, NaN to None, floats to 12 digits."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [to_jsonable(v) for v in obj.tolist()]
    if isinstance(obj, bool | np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        x = float(obj)
        return float(f"{x:.{_DIGITS}g}") if math.isfinite(x) else None
    return obj


def dumps(doc: dict) -> str:
    """Deterministic JSON text (sorted keys, two-space indent, trailing newline)."""
    return json.dumps(to_jsonable(doc), sort_keys=True, indent=2, allow_nan=False) + "\n"


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


def summary_dict(analysis: Analysis) -> dict:
    """The ``summary.json`` document of an :class:`~overbound.analysis.Analysis`."""
    c = analysis.counting
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
    rejected = sum(r.n_rejected for r in analysis.reports)
    invalidated = sum(sum(r.invalidated.values()) for r in analysis.reports)
    return {
        "schema": SCHEMA,
        "overbound_version": __version__,
        "title": analysis.title,
        "inputs": [r.to_dict() for r in analysis.reports],
        "epochs": {
            "total": c.n_total,
            "with_solution": c.n_with_solution,
            "no_solution": c.n_total - c.n_with_solution,
            "rejected": rejected,
            "invalidated": invalidated,
        },
        "time": {"start": c.start, "end": c.end, "stations": list(c.stations)},
        "accuracy": {"hpe95": c.hpe95, "vpe95": c.vpe95},
        "safety_index": {a: dataclasses.asdict(c.safety[a]) for a in AXES},
        "services": services,
        "stations": {name: _station_dict(sc, analysis.services) for name, sc in c.by_station.items()},
        "confidence": {a.axis: _confidence_brief(a) for a in analysis.confidence},
        "evt": _evt_briefs(analysis),
        "parametric": _parametric_brief(analysis),
    }


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


def write_summary(analysis: Analysis, path: str | Path) -> Path:
    """Write ``summary.json``; return its path."""
    path = Path(path)
    path.write_text(dumps(summary_dict(analysis)), encoding="utf-8")
    return path
