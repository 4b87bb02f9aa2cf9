"""The network part of the report of a campaign dataset: daily compliance, the station × day
availability heat map of each service, the partitions left out, and the script that makes the
per-station table sortable.

The heat map shows the combined (H+V) availability of every station-day as its unavailability
``1 - A`` on a log colour scale: the days that miss a 99.9 % or 99 % target stand out, which a
linear scale from 0 to 1 would hide. Days without data are blank.
"""

from __future__ import annotations

import datetime as dt
import functools
import gzip
import json
from importlib import resources

import numpy as np
import polars as pl
from matplotlib.axes import Axes
from matplotlib.collections import PolyCollection
from matplotlib.colors import LogNorm

from overbound.report.figures import new_figure, style
from overbound.report.page import escape, figure_html, section_html
from overbound.services import ServiceLevel

__all__ = [
    "SORTABLE_SCRIPT",
    "land_rings",
    "network_section_html",
    "plot_availability_heatmap",
    "plot_station_map",
]

#: Unavailability below this is drawn with the lightest colour (the scale's floor).
_FLOOR = 1e-5


def plot_availability_heatmap(daily: pl.DataFrame, service: str, *, ax: Axes | None = None) -> Axes:
    """Station × day unavailability ``1 - A`` of ``service`` (a column of ``daily``, see
    :func:`~overbound.methods.counting_partitions.daily_availability`), log colour scale.

    Returns the axes; the image has ``gid`` ``heatmap``.
    """
    stations = daily["station"].unique(maintain_order=True).to_list()
    first, last = daily["date"].min(), daily["date"].max()
    n_days = (last - first).days + 1
    grid = np.full((len(stations), n_days), np.nan)
    row = {s: i for i, s in enumerate(stations)}
    for st, day, a in daily.select("station", "date", service).iter_rows():
        grid[row[st], (day - first).days] = max(1.0 - a, _FLOOR)
    with style():
        if ax is None:
            ax = new_figure(7.5, 1.4 + 0.28 * len(stations)).add_subplot()
        im = ax.imshow(
            grid,
            aspect="auto",
            interpolation="nearest",
            cmap="magma_r",
            norm=LogNorm(vmin=_FLOOR, vmax=1.0),
            extent=(-0.5, n_days - 0.5, len(stations) - 0.5, -0.5),
        )
        im.set_gid("heatmap")
        ax.set_yticks(range(len(stations)), stations)
        ticks = np.unique(np.linspace(0, n_days - 1, min(n_days, 8)).round().astype(int))
        days = [first + dt.timedelta(days=int(d)) for d in ticks]
        ax.set_xticks(ticks, [d.strftime("%m-%d") for d in days])
        years = sorted({first.year, last.year})
        ax.set_xlabel(f"GPS day ({'–'.join(str(y) for y in years)})")
        ax.grid(False)
        ax.set_title(f"{service}: unavailability 1 − A per station-day")
        ax.figure.colorbar(im, ax=ax, label="1 − availability (H+V)")
    return ax


@functools.cache
def land_rings() -> tuple[np.ndarray, ...]:
    """Land outlines, Natural Earth 1:110m (public domain; ``overbound/data/land-110m.json.gz``,
    see its PROVENANCE): one ``(n, 2)`` array of longitude, latitude (deg) per ring."""
    raw = resources.files("overbound.data").joinpath("land-110m.json.gz").read_bytes()
    doc = json.loads(gzip.decompress(raw))
    return tuple(np.asarray(r, dtype=float).reshape(-1, 2) for r in doc["rings"])


def plot_station_map(
    positions: dict[str, tuple[float, float]], availability: dict[str, float], service: str, *, ax=None
) -> Axes:
    """Stations at their ``(lat, lon)`` coloured by ``1 - availability`` of ``service`` (log
    scale, as the heat map), over the land of Natural Earth 1:110m, drawn offline.

    Equirectangular, stretched by ``1/cos`` of the mean latitude; the extent is the stations'
    with 8 degrees of margin (20 degrees at least). The markers have ``gid`` ``stations``.
    """
    lat = np.array([p[0] for p in positions.values()])
    lon = np.array([p[1] for p in positions.values()])
    u = np.array([max(1.0 - availability.get(n, np.nan), _FLOOR) for n in positions])
    half = max(10.0, (np.ptp(lon) + 16.0) / 2, (np.ptp(lat) + 16.0) / 2)
    cx, cy = (lon.max() + lon.min()) / 2, (lat.max() + lat.min()) / 2
    with style():
        if ax is None:
            ax = new_figure(7.0, 5.0).add_subplot()
        land = PolyCollection(land_rings(), facecolor="#e4e7ea", edgecolor="#9aa4ad", linewidth=0.4)
        ax.add_collection(land)
        sc = ax.scatter(
            lon,
            lat,
            c=u,
            cmap="magma_r",
            norm=LogNorm(vmin=_FLOOR, vmax=1.0),
            s=60,
            edgecolors="#1d2733",
            linewidths=0.6,
            zorder=3,
        )
        sc.set_gid("stations")
        for name, x, y in zip(positions, lon, lat, strict=True):
            ax.annotate(name, (x, y), xytext=(4, 4), textcoords="offset points", fontsize=7, zorder=4)
        ax.set_xlim(cx - half, cx + half)
        ax.set_ylim(max(-90.0, cy - half * 0.75), min(90.0, cy + half * 0.75))
        ax.set_aspect(1.0 / max(np.cos(np.radians(cy)), 0.2))
        ax.set_xlabel("longitude (deg)")
        ax.set_ylabel("latitude (deg)")
        ax.set_title(f"{service}: station unavailability 1 − A (H+V)")
        ax.figure.colorbar(sc, ax=ax, label="1 − availability (H+V)", shrink=0.8)
    return ax


def _compliance_rows(network: dict, services: tuple[ServiceLevel, ...]) -> list[str]:
    rows = []
    for s in services:
        c = network["daily_compliance"][s.name]
        share = "n.a." if c["network"] is None else f"{100 * c['network']:.1f}&nbsp;%"
        worst = min(c["stations"].items(), key=lambda kv: kv[1], default=None)
        worst_txt = "–" if worst is None else f"{escape(worst[0])} ({100 * worst[1]:.1f}&nbsp;%)"
        req = "–" if c["required"] is None else f"{100 * c['required']:.10g}&nbsp;%"
        rows.append(
            f"<tr><td>{escape(s.name)}</td><td class='num'>{req}</td>"
            f"<td class='num'>{share}</td><td>{worst_txt}</td></tr>"
        )
    return rows


def network_section_html(
    network: dict,
    daily: pl.DataFrame,
    services: tuple[ServiceLevel, ...],
    positions: dict[str, tuple[float, float]] | None = None,
    availability: dict[str, dict[str, float]] | None = None,
) -> str:
    """The ``<section id="network">``: ``network`` is the summary's ``network`` object;
    ``positions`` the stations' ``(lat, lon)`` known, ``availability[service][station]`` the
    combined availability of each station (for the map)."""
    n_days = daily.height
    parts = [
        f"<p>{network['partitions_analysed']:,} station-days analysed of {network['partitions']:,} in the "
        "dataset, each read alone and merged exactly (counts, continuity across midnight, percentiles). "
        "Daily compliance is the share of station-days whose combined availability meets the service's "
        "requirement.</p>",
        "<table><thead><tr><th>Service</th><th class='num'>Required availability</th>"
        "<th class='num'>Days meeting it</th><th>Worst station</th></tr></thead><tbody>"
        + "".join(_compliance_rows(network, services))
        + "</tbody></table>",
    ]
    if network["unreadable"]:
        items = "".join(
            f"<li>{escape(f['station'])} {escape(f['date'])}: {escape(f['reason'])}</li>"
            for f in network["unreadable"]
        )
        parts.append(
            f'<p class="alarm">{len(network["unreadable"])} station-days could not be read and are left '
            f"out of every figure:</p><ul>{items}</ul>"
        )
    if n_days:
        for s in services:
            ax = plot_availability_heatmap(daily, s.name)
            parts.append(
                figure_html(
                    ax,
                    name=f"heatmap-{s.name}",
                    alt=f"Heat map of the {s.name} unavailability per station and GPS day",
                    caption=f"{s.name}: 1 − combined (H+V) availability per station-day, log scale; "
                    "blank: no data.",
                )
            )
    parts.append(_map_html(positions or {}, availability or {}, services))
    return section_html("network", "Network: stations and days", parts)


def _map_html(positions: dict, availability: dict, services: tuple[ServiceLevel, ...]) -> str:
    """The station map for the first approach service analysed (the first service otherwise)."""
    if not positions:
        return (
            "<p>No station map: the dataset's manifest holds no station positions (ingest with "
            "<code>--reference</code> to record them).</p>"
        )
    service = next((s for s in services if s.val is not None), services[0])
    ax = plot_station_map(positions, availability.get(service.name, {}), service.name)
    return figure_html(
        ax,
        name="station-map",
        alt=f"Map of the stations coloured by their {service.name} unavailability",
        caption=f"Stations coloured by 1 − combined {service.name} availability (log scale). Land: "
        "Natural Earth 1:110m (public domain), embedded.",
    )


#: Click a column head of a ``table.sortable`` to sort by it (numbers as numbers); click again
#: to reverse. Inline, so that the report stays one file.
SORTABLE_SCRIPT = """<script>
document.querySelectorAll('table.sortable thead th').forEach(function (th, col) {
  th.style.cursor = 'pointer';
  th.addEventListener('click', function () {
    var body = th.closest('table').tBodies[0];
    var rows = Array.prototype.slice.call(body.rows);
    var dir = th.dataset.dir === 'asc' ? -1 : 1;
    th.dataset.dir = dir === 1 ? 'asc' : 'desc';
    var key = function (r) {
      var t = r.cells[col].textContent.replace(/[\\s,%m\\u00a0]/g, '');
      var x = parseFloat(t.split('/')[0]);
      return isNaN(x) ? r.cells[col].textContent : x;
    };
    rows.sort(function (a, b) {
      var x = key(a), y = key(b);
      return (x < y ? -1 : x > y ? 1 : 0) * dir;
    });
    rows.forEach(function (r) { body.appendChild(r); });
  });
});
</script>"""
