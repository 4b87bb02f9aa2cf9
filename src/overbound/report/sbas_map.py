"""The files of ``overbound sbas-map``: ``map.parquet``, ``map.json`` and the self-contained ``map.html``.

The availability maps use the classes of the service providers' monthly reports (below 50 %, 50-75,
75-90, 90-95, 95-99, 99-99.5, 99.5-99.9, 99.9 % and above), drawn on the grid cells around each point
over the offline Natural Earth coastlines of the network report.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import polars as pl
from matplotlib.axes import Axes
from matplotlib.collections import PolyCollection
from matplotlib.colors import BoundaryNorm, ListedColormap, LogNorm

from overbound.report.figures import new_figure, style
from overbound.report.network import land_rings
from overbound.report.page import escape, figure_html, row_table, section_html, write_page
from overbound.report.provenance import file_digest, provenance_dict
from overbound.sbas_map import ServiceMap

__all__ = ["AVAILABILITY_CLASSES", "map_dict", "plot_map", "write_map"]

#: Class edges (share of epochs) of the availability maps.
AVAILABILITY_CLASSES = (0.0, 0.5, 0.75, 0.9, 0.95, 0.99, 0.995, 0.999, 1.0 + 1e-12)
_CLASS_COLOURS = ("#7f0000", "#d7301f", "#fc8d59", "#fdcc8a", "#fef0d9", "#c7e9c0", "#74c476", "#006d2c")
SCHEMA = "overbound.sbas-map/1"


def map_dict(smap: ServiceMap, inputs: Sequence[tuple[str, str | Path]]) -> dict:
    """``map.json``: the options, the inputs (``(role, path)``) with their SHA-256 and read reports, the
    epoch span, and per service the share of the grid points at or above 99 % availability."""
    o = smap.options
    g = o.grid
    t = smap.times_us.astype("datetime64[us]").astype("datetime64[s]")  # epochs are whole seconds
    return {
        "schema": SCHEMA,
        "provenance": provenance_dict(),
        "options": {
            "area": {"lon0": g.lon0, "lon1": g.lon1, "lat0": g.lat0, "lat1": g.lat1},
            "step_deg": g.step,
            "height_m": g.height_m,
            "interval_s": o.interval_s,
            "mode": o.engine.mode,
            "mask_deg": o.engine.mask_deg,
            "geo": smap.geo,
            "hourly": o.hourly,
            "continuity_window_s": o.window_s,
            "services": [{"name": s.name, "hal": s.hal, "val": s.val} for s in o.chosen_services()],
        },
        "inputs": [{"role": role, **file_digest(path)} for role, path in inputs],
        "reads": [{"role": role, **r.to_dict()} for role, r in smap.reports],
        "epochs": {"first": str(t[0]), "last": str(t[-1]), "count": int(t.size)},
        "grid_points": int(smap.lat_axis.size * smap.lon_axis.size),
        "services": {
            s.name: {
                "share_of_points_at_least_99": smap.share_above(s.name, 0.99),
                "share_of_points_at_least_99_9": smap.share_above(s.name, 0.999),
            }
            for s in o.chosen_services()
        },
    }


def plot_map(smap: ServiceMap, service: str, column: str, *, ax: Axes | None = None) -> Axes:
    """``column`` of ``service`` (whole span) on the grid cells, over the land outlines; availability
    columns in the report classes, protection levels on a log scale (the edge of the service area
    reaches kilometres), the others on a linear one. Columns that do not depend on the service (the
    ionosphere, the PLs) are titled without it. The mesh has ``gid`` ``map``."""
    t = smap.table.filter((pl.col("service") == service) & pl.col("hour").is_null())
    values = t[column].cast(pl.Float64).fill_null(np.nan).to_numpy().reshape(smap.lat_axis.size, -1)
    step = smap.options.grid.step
    lon_e = np.append(smap.lon_axis - step / 2, smap.lon_axis[-1] + step / 2)
    lat_e = np.append(smap.lat_axis - step / 2, smap.lat_axis[-1] + step / 2)
    classes = column.endswith("availability")
    with style():
        if ax is None:
            ax = new_figure(7.0, 5.0).add_subplot()
        if classes:
            cmap, norm = (
                ListedColormap(_CLASS_COLOURS),
                BoundaryNorm(AVAILABILITY_CLASSES, len(_CLASS_COLOURS)),
            )
            mesh = ax.pcolormesh(lon_e, lat_e, values, cmap=cmap, norm=norm, alpha=0.85)
        elif column.startswith(("hpl", "vpl")) and np.isfinite(values).any():
            norm = LogNorm(vmin=max(np.nanmin(values), 1.0), vmax=max(np.nanmax(values), 2.0))
            mesh = ax.pcolormesh(lon_e, lat_e, values, cmap="viridis", norm=norm, alpha=0.85)
        else:
            mesh = ax.pcolormesh(lon_e, lat_e, values, cmap="viridis", alpha=0.85)
        mesh.set_gid("map")
        ax.add_collection(PolyCollection(land_rings(), facecolor="none", edgecolor="#1d2733", linewidth=0.5))
        ax.set_xlim(lon_e[0], lon_e[-1])
        ax.set_ylim(lat_e[0], lat_e[-1])
        ax.set_aspect(1.0 / max(np.cos(np.radians(np.mean(smap.lat_axis))), 0.2))
        ax.set_xlabel("longitude (deg)")
        ax.set_ylabel("latitude (deg)")
        what = column.replace("_", " ")
        ax.set_title(f"{service}: {what}" if column in ("availability", "continuity_risk") else what)
        bar = ax.figure.colorbar(mesh, ax=ax, shrink=0.8)
        if classes:
            labels = ["0", "50", "75", "90", "95", "99", "99.5", "99.9", "100 %"]
            bar.set_ticks((*AVAILABILITY_CLASSES[:-1], 1.0), labels=labels)
    return ax


def write_map(out_dir: Path, smap: ServiceMap, inputs: Sequence[tuple[str, str | Path]]) -> list[Path]:
    """Write ``map.parquet``, ``map.json`` and ``map.html`` into ``out_dir``; their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    parquet = out_dir / "map.parquet"
    smap.table.write_parquet(parquet, compression="zstd", statistics=False)
    doc = map_dict(smap, inputs)
    js = out_dir / "map.json"
    js.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
    return [parquet, js, _write_html(out_dir / "map.html", smap, doc)]


_COMMON = (
    (
        "iono_availability",
        "Share of epochs at which the ionospheric grid corrects a pierce point at the grid point.",
    ),
    ("hpl_p95", "95th percentile of HPL (m) over the epochs with a solution."),
    ("vpl_p95", "95th percentile of VPL (m) over the epochs with a solution."),
)


def _service_section(smap: ServiceMap, s) -> str:
    limits = f"HPL <= {s.hal:g} m" + (f", VPL <= {s.val:g} m" if s.val is not None else "")
    figs = [
        figure_html(
            plot_map(smap, s.name, "availability"),
            name=f"availability-{s.name}",
            alt=f"{s.name} availability map",
            caption=f"{s.name} availability ({limits}) per grid point.",
        )
    ]
    window = smap.options.window_s
    if smap.table.filter(pl.col("service") == s.name)["continuity_risk"].is_not_null().any():
        figs.append(
            figure_html(
                plot_map(smap, s.name, "continuity_risk"),
                name=f"continuity-{s.name}",
                alt=f"{s.name} continuity risk map",
                caption=f"{s.name} continuity risk ({window:g} s windows).",
            )
        )
        return section_html(f"service-{s.name}", s.name, figs)
    why = f"continuity risk ({window:g} s windows do not fit the {smap.options.interval_s:g} s epochs)"
    return section_html(f"service-{s.name}", s.name, figs, (why,))


def _write_html(path: Path, smap: ServiceMap, doc: dict) -> Path:
    sections = [_service_section(smap, s) for s in smap.options.chosen_services()]
    first = smap.options.chosen_services()[0].name
    common = [
        figure_html(plot_map(smap, first, column), name=column, alt=column.replace("_", " "), caption=caption)
        for column, caption in _COMMON
    ]
    sections.append(section_html("common", "Ionosphere and protection levels", common))
    rows = [
        [
            escape(name),
            f"{100 * v['share_of_points_at_least_99']:.1f} %",
            f"{100 * v['share_of_points_at_least_99_9']:.1f} %",
        ]
        for name, v in doc["services"].items()
    ]
    table = row_table(["service", "points ≥ 99 %", "points ≥ 99.9 %"], rows, "kpi")
    o, e = doc["options"], doc["epochs"]
    intro = escape(
        f"{doc['grid_points']} grid points every {o['step_deg']:g} deg, {e['count']} epochs every "
        f"{o['interval_s']:g} s from {e['first']} to {e['last']} (GPS), {o['mode']}, GEO {o['geo']}, "
        f"mask {o['mask_deg']:g} deg, height {o['height_m']:g} m."
    )
    body = table + "\n" + "\n".join(sections)
    return write_page(path, title="SBAS service-volume map", intro_html=intro, body_html=body)
