"""``summary.json`` and ``report.html`` of a protection-level-only analysis (inputs without truth).

The document says first that the errors are unknown and lists what needs them
(:data:`overbound.methods.protection_levels.NEEDS_ERRORS`); then, per service, the availability and
continuity the PLs give, pooled and per flight (station); per flight the epochs, the span in GPS time
and UTC, the PL percentiles and the share within the alert limit the receiver logged; the PL time
series of every flight and the pooled PL distributions.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import polars as pl

from overbound import __version__
from overbound.io.gpstime import utc_iso
from overbound.methods.counting import CountingResult
from overbound.methods.protection_levels import PlDistribution
from overbound.report.json import _continuity, _input_dict
from overbound.report.page import escape, figure_html, row_table, section_html, write_page
from overbound.report.style import new_figure

__all__ = ["SCHEMA", "pl_only_dict", "write_pl_only_report"]

#: Schema name of a PL-only ``summary.json``.
SCHEMA = "overbound.pl-summary/1"
_AXES = ("horizontal", "vertical", "combined")


def _distribution(d: PlDistribution) -> dict:
    return {
        "epochs": d.n_epochs,
        "with_pl": d.n_with_pl,
        "time": {
            "start_gpst": d.start,
            "end_gpst": d.end,
            "start_utc": utc_iso(d.start),
            "end_utc": utc_iso(d.end),
        },
        "hpl": d.hpl,
        "vpl": d.vpl,
        "within_logged_hal": d.in_force,
        "epochs_with_logged_hal": d.n_in_force,
        "modes": d.modes,
    }


def _services(c: CountingResult, services) -> dict:
    out = {}
    for s in services:
        k = c.services[s.name]
        axes = {"horizontal": k.horizontal, "vertical": k.vertical, "combined": k.combined}
        out[s.name] = {
            "hal": s.hal,
            "val": s.val,
            "availability": {n: a.availability for n, a in axes.items()},
            "continuity": {n: _continuity(a.continuity) for n, a in axes.items()},
        }
    return out


def pl_only_dict(analysis, provenance: dict | None = None) -> dict:
    """The ``summary.json`` document of a PL-only :class:`~overbound.analysis.Analysis`."""
    p = analysis.pl_only
    return {
        "schema": SCHEMA,
        "overbound_version": __version__,
        "title": analysis.title,
        "warnings": list(analysis.warnings),
        "not_computed": {"reason": p.reason, "needs_errors": list(p.needs_errors)},
        "inputs": [_input_dict(r) for r in analysis.reports],
        "provenance": provenance or {"overbound_version": __version__},
        "epochs": {
            "total": p.pooled.n_epochs,
            "with_pl": p.pooled.n_with_pl,
            "no_solution": p.pooled.n_epochs - p.pooled.n_with_pl,
            "rejected": analysis.n_rejected,
            "invalidated": analysis.n_invalidated,
        },
        "pooled": _distribution(p.pooled),
        "services": _services(p.counting, analysis.services),
        "stations": {
            name: {
                **_distribution(d),
                "services": _services(p.counting.by_station[name], analysis.services)
                if name in p.counting.by_station
                else _services(p.counting, analysis.services),
            }
            for name, d in p.by_station.items()
        },
    }


def _share(x: float | None) -> str:
    return "n.a." if x is None or not np.isfinite(x) else f"{100 * x:.2f} %"


def _m(x: float | None) -> str:
    return "n.a." if x is None else f"{x:.1f} m"


def _flights_table(doc: dict) -> str:
    rows = []
    for name, st in doc["stations"].items():
        t = st["time"]
        rows.append(
            [
                escape(name),
                f"{st['epochs']:,}",
                f"{st['with_pl']:,}",
                escape(f"{t['start_gpst']} – {t['end_gpst']}"),
                escape(f"{t['start_utc']} – {t['end_utc']}"),
                *(_m(st[a][q]) for a in ("hpl", "vpl") for q in ("p50", "p95", "max")),
                _share(st["within_logged_hal"]),
            ]
        )
    head = ["flight", "epochs", "with PL", "span (GPS time)", "span (UTC)", "HPL 50 %", "HPL 95 %", "HPL max",
            "VPL 50 %", "VPL 95 %", "VPL max", "HPL ≤ logged HAL"]  # fmt: skip
    return row_table(head, rows, "kpi")


def _service_table(doc: dict) -> str:
    rows = []
    for name, s in doc["services"].items():
        val = "-" if s["val"] is None else f"{s['val']:g}"
        risk = s["continuity"]["combined"]
        window = (
            "n.a."
            if risk is None or risk["risk"] is None
            else f"{risk['risk']:.3g} per {risk['window_s']:g} s ({risk['n_gap_windows']:,} of "
            f"{risk['n_fail']:,} failing windows with a gap)"
        )
        rows.append(
            [escape(name), f"{s['hal']:g}/{val}", *(_share(s["availability"][a]) for a in _AXES), window]
        )
    head = ["service", "HAL/VAL (m)", "avail. H", "avail. V", "avail. H+V", "continuity risk H+V"]
    return row_table(head, rows, "kpi")


def _flight_availability(doc: dict) -> str:
    """Flights x services: the availability H+V of each."""
    names = list(doc["services"])
    rows = [
        [escape(st), *(_share(v["services"][s]["availability"]["combined"]) for s in names)]
        for st, v in doc["stations"].items()
    ]
    return row_table(["flight", *(escape(s) for s in names)], rows, "kpi")


def _time_series(table: pl.DataFrame, station: str, services) -> str:
    t = table.filter(pl.col("station").cast(pl.String) == station).sort("time")
    fig = new_figure(9.0, 3.2)
    ax = fig.add_subplot()
    x = t["time"].to_numpy()
    ax.plot(x, t["hpl"].to_numpy(), lw=0.8, label="HPL")
    ax.plot(x, t["vpl"].to_numpy(), lw=0.8, label="VPL")
    # the approach limits (under 100 m): the en-route and terminal ones would flatten the curves
    hals = sorted({s.hal for s in services if s.hal < 100})
    vals = sorted({s.val for s in services if s.val is not None and s.val < 100})
    for v in hals:
        ax.axhline(v, ls="--", lw=0.7, color="grey")
    for v in vals:
        ax.axhline(v, ls=":", lw=0.7, color="grey")
    ax.set_ylabel("protection level (m)")
    ax.set_xlabel("GPS time")
    ax.set_yscale("log")
    ax.legend(loc="upper right", fontsize=7)
    ax.set_title(station, fontsize=9)
    fig.autofmt_xdate()
    return figure_html(
        ax,
        name=f"pl-series-{station}",
        alt=f"HPL and VPL of {station} against time",
        caption=f"{station}: HPL and VPL (log scale); dashed: HAL {_list(hals)} m, dotted: VAL "
        f"{_list(vals)} m (the services' limits under 100 m).",
    )


def _list(values) -> str:
    return ", ".join(f"{v:g}" for v in values) or "none"


def _distributions(table: pl.DataFrame) -> str:
    fig = new_figure(6.0, 3.6)
    ax = fig.add_subplot()
    for axis in ("hpl", "vpl"):
        x = np.sort(table[axis].to_numpy()[np.isfinite(table[axis].to_numpy())])
        if x.size:
            ax.step(x, 1.0 - np.arange(x.size) / x.size, where="post", label=axis.upper())
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("protection level (m)")
    ax.set_ylabel("share of epochs ≥ PL")
    ax.legend(fontsize=7)
    caption = "HPL and VPL of all flights: the share of epochs whose PL is at least the abscissa."
    return figure_html(
        ax, name="pl-distribution", alt="Complementary distribution of HPL and VPL", caption=caption
    )


def write_pl_only_report(analysis, path: str | Path, doc: dict) -> Path:
    """Write the self-contained ``report.html`` of a PL-only analysis; return its path."""
    warnings = "".join(f'<p class="warning" role="alert">{escape(w)}</p>' for w in analysis.warnings)
    missing = "".join(f"<li>{escape(m)}</li>" for m in doc["not_computed"]["needs_errors"])
    e = doc["epochs"]
    n_flights = len(doc["stations"])
    intro = escape(
        f"{e['total']:,} epochs of {n_flights} flight(s), {e['with_pl']:,} with protection levels; "
        f"{e['rejected']:,} rows rejected, {e['invalidated']:,} invalidated (see the inputs). All times GPS "
        "time, spans also in UTC."
    )
    no_truth = [warnings, f"<p>Not computed ({escape(doc['not_computed']['reason'])}):</p><ul>{missing}</ul>"]
    rows = [
        [
            escape(Path(r["source"]).name),
            f"{r['rows_read']:,}",
            f"{r['rows_kept']:,}",
            escape(", ".join(f"{k} {v}" for k, v in r["rejected"].items()) or "0"),
            escape("; ".join(r["notes"])),
        ]
        for r in doc["inputs"]
    ]
    inputs = row_table(["input", "read", "kept", "rejected", "notes"], rows, "kpi")
    series = [_time_series(analysis.table, name, analysis.services) for name in doc["stations"]]
    body = "\n".join(
        [
            section_html("no-truth", "Without truth", no_truth),
            section_html(
                "services",
                "Availability and continuity per service",
                [_service_table(doc), "<h3>Availability H+V per flight</h3>", _flight_availability(doc)],
            ),
            section_html("flights", "Flights", [_flights_table(doc)]),
            section_html("time-series", "Protection levels against time", series),
            section_html("distribution", "Protection-level distributions", [_distributions(analysis.table)]),
            section_html("inputs", "Inputs", [inputs]),
        ]
    )
    return write_page(path, title=f"{analysis.title} — protection levels", intro_html=intro, body_html=body)
