"""``overbound sbas-map``: service-volume maps from SBAS messages and GPS navigation data alone.

Reads the files once, cuts the epochs into chunks of time and runs each chunk (all grid points,
:func:`overbound.sbas.maps.point_epochs`) as one task on the campaign runner (this process or Dask
workers, :func:`overbound.campaign.runner_for`), then summarises the points' epochs into the map table
(:func:`overbound.sbas.maps.summarise`). The numbers do not depend on the chunking or the workers:
every (epoch, point) is computed by the engine from the whole message history.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import polars as pl

from overbound.campaign import runner_for
from overbound.io.open import Source
from overbound.io.schema import InputError, ReadReport
from overbound.methods.counting import continuity_risks
from overbound.sbas.engine import SbasOptions
from overbound.sbas.maps import (
    EGNOS_AREA,
    GEO_MIN_ELEVATION_DEG,
    MapGrid,
    geo_elevation,
    grid_points,
    map_times,
    point_epochs,
)
from overbound.sbas.messages import SbasMessages, decode
from overbound.sbas.run import read_stations
from overbound.services import ServiceLevel, resolve_services
from overbound.stats.mergeable import row_percentiles

__all__ = ["MapOptions", "ServiceMap", "compute_map", "default_services", "summarise"]

_US = 1_000_000
#: Epochs per task: a day at 60 s is 24 tasks, each about one hour.
_EPOCHS_PER_TASK = 60


def default_services(mode: str) -> tuple[ServiceLevel, ...]:
    """PA: the services with a vertical limit (APV-I, APV-II, LPV, LPV-200, CAT-I); NPA: NPA."""
    if mode == "NPA":
        return resolve_services(["NPA"])
    return tuple(s for s in resolve_services(None) if s.val is not None)


@dataclass(frozen=True)
class MapOptions:
    """What to map: the grid, the epochs (``interval_s`` from ``start_us`` to before ``end_us``, GPS
    us; None: from the start of the messages' GPS day to the last message + 1 s), the services, the
    engine options (mode, mask, GEO), hourly rows, and the continuity window (15 s; 15 min with
    ``maritime``)."""

    grid: MapGrid = field(default_factory=lambda: MapGrid(*EGNOS_AREA, step=1.0))
    interval_s: float = 60.0
    start_us: int | None = None
    end_us: int | None = None
    services: tuple[ServiceLevel, ...] = ()
    engine: SbasOptions = field(default_factory=SbasOptions)
    hourly: bool = False
    maritime: bool = False

    @property
    def window_s(self) -> float:
        return 900.0 if self.maritime else 15.0

    def chosen_services(self) -> tuple[ServiceLevel, ...]:
        return self.services or default_services(self.engine.mode)


@dataclass(frozen=True, eq=False)
class ServiceMap:
    """A computed map: ``table`` (:func:`overbound.sbas.maps.summarise`), the epochs, the grid's axes,
    the options, and the read reports of the inputs."""

    table: pl.DataFrame
    times_us: np.ndarray
    lat_axis: np.ndarray
    lon_axis: np.ndarray
    options: MapOptions
    reports: tuple[tuple[str, ReadReport], ...]
    geo: int

    def share_above(self, service: str, level: float = 0.99) -> float:
        """Share of the grid points whose availability of ``service`` over the whole span is >= ``level``."""
        t = self.table.filter((pl.col("service") == service) & pl.col("hour").is_null())
        return float((t["availability"] >= level).mean()) if t.height else float("nan")


def _messages(frames, geo: int | None) -> tuple[SbasMessages, int]:
    msgs = decode(frames)
    geos = sorted(set(msgs.log["geo"].unique().to_list()))
    if not geos:
        raise InputError("--sbas", "no SBAS message in the files")
    if geo is None and len(geos) > 1:
        raise InputError("--sbas", f"messages of several GEOs ({geos}): choose one with --geo")
    chosen = geo if geo is not None else geos[0]
    if chosen not in geos:
        raise InputError("--sbas", f"no messages of GEO {chosen} (present: {geos})")
    return msgs, chosen


def compute_map(
    nav: Source | Sequence[Source],
    sbas: Source | Sequence[Source],
    options: MapOptions,
    *,
    client=None,
    progress: Callable[[str], None] | None = None,
) -> ServiceMap:
    """Read the navigation and message files, compute every (epoch, grid point) on the runner of
    ``client`` (None: this process) and summarise them (see the module notes)."""
    step = progress or (lambda _: None)
    step("reading the navigation and message files")
    inp = read_stations((), nav, sbas)[0]
    if not inp.eph.height:
        raise InputError("--nav", "no GPS ephemeris in the navigation files")
    msgs, geo = _messages(inp.frames, options.engine.geo)
    engine = dataclasses.replace(options.engine, geo=geo)
    times = map_times(msgs, options.interval_s, options.start_us, options.end_us, geo)
    if not times.size:
        raise InputError("--start/--end", "no epoch between the start and the end")
    lat, lon, ecef = grid_points(options.grid)
    runner = runner_for(client)
    shared = [runner.share(v) for v in (ecef, inp.eph, msgs)]
    chunks = [times[a : a + _EPOCHS_PER_TASK] for a in range(0, times.size, _EPOCHS_PER_TASK)]
    step(f"{lat.size} grid points x {times.size} epochs in {len(chunks)} tasks")
    parts = runner.starmap(_task, [(c, *shared, engine, inp.klobuchar, (lat, lon)) for c in chunks])
    epochs = pl.concat(parts)
    step("summarising")
    # without a GEO position (no MT 17 or MT 9) every point is taken to see it
    visible = ~(geo_elevation(msgs, geo, lat, lon, options.grid.height_m) < GEO_MIN_ELEVATION_DEG)
    table = summarise(epochs, lat, lon, options.chosen_services(), hourly=options.hourly,
                      window_s=options.window_s, geo_visible=visible)  # fmt: skip
    lat_axis, lon_axis = options.grid.axes()
    return ServiceMap(table, times, lat_axis, lon_axis, options, tuple(inp.reports), geo)


def _task(times, ecef, eph, msgs, engine, klobuchar, latlon) -> pl.DataFrame:
    return point_epochs(times, ecef, eph, msgs, engine, klobuchar=klobuchar, latlon=latlon)


def summarise(
    epochs: pl.DataFrame,
    lat: np.ndarray,
    lon: np.ndarray,
    services: Sequence[ServiceLevel],
    *,
    hourly: bool = False,
    window_s: float = 15.0,
    geo_visible: np.ndarray | None = None,
) -> pl.DataFrame:
    """The map table: one row per grid point and service (and hour when ``hourly``), see the module notes.

    ``geo_visible``: per point, whether it sees the GEO (:data:`GEO_MIN_ELEVATION_DEG`); a point that
    does not has neither the service nor the ionospheric correction at any epoch.

    ``epochs``: :func:`point_epochs` (every time with every point). Columns ``lat``, ``lon``, ``service``,
    ``hour`` (null for the whole span, else the hour since the first epoch's midnight), ``n_epochs``,
    ``n_available``, ``availability``, ``continuity_risk``, ``hpl_p95``, ``vpl_p95``, ``hpl_p99``,
    ``vpl_p99``, ``iono_availability``.
    """
    n_p = lat.size
    times = epochs["time"].dt.epoch("us").to_numpy()[::n_p]
    shape = (times.size, n_p)
    hpl = epochs["hpl"].to_numpy().reshape(shape).T
    vpl = epochs["vpl"].to_numpy().reshape(shape).T
    iono = epochs["iono_ok"].to_numpy().reshape(shape).T
    if geo_visible is not None:  # no message reaches a point below the GEO's horizon mask
        hidden = ~np.asarray(geo_visible, bool)
        hpl, vpl, iono = hpl.copy(), vpl.copy(), iono.copy()
        hpl[hidden], vpl[hidden], iono[hidden] = np.nan, np.nan, False
    spans: list[tuple[int | None, np.ndarray]] = [(None, np.arange(times.size))]
    if hourly:
        hour = (times - times[0] // (86_400 * _US) * (86_400 * _US)) // (3600 * _US)
        spans += [(int(h), np.flatnonzero(hour == h)) for h in np.unique(hour)]
    parts = []
    for hour_value, cols in spans:
        parts.append(_span_rows(times[cols], hpl[:, cols], vpl[:, cols], iono[:, cols], lat, lon, services,
                                hour_value, window_s))  # fmt: skip
    return pl.concat(parts)


def _span_rows(times, hpl, vpl, iono, lat, lon, services, hour, window_s) -> pl.DataFrame:
    n_p, n_t = hpl.shape
    with np.errstate(invalid="ignore"):
        solved = np.isfinite(hpl) & np.isfinite(vpl)
        pct = {f"{name}_p{q}": _percentile(x, solved, q) for name, x in (("hpl", hpl), ("vpl", vpl))
               for q in (95, 99)}  # fmt: skip
    rows = []
    for s in services:
        with np.errstate(invalid="ignore"):
            ok = solved & (hpl <= s.hal) & ((vpl <= s.val) if s.val is not None else True)
        risk = [r.risk for r in continuity_risks(times, ok, window_s=window_s)]
        rows.append(pl.DataFrame({
            "lat": lat, "lon": lon, "service": [s.name] * n_p,
            "hour": pl.Series([hour] * n_p, dtype=pl.Int32),
            "n_epochs": np.full(n_p, n_t, np.int64), "n_available": ok.sum(axis=1).astype(np.int64),
            "availability": ok.mean(axis=1) if n_t else np.full(n_p, np.nan),
            "continuity_risk": pl.Series(risk, dtype=pl.Float64),
            **{k: pct[k] for k in ("hpl_p95", "vpl_p95", "hpl_p99", "vpl_p99")},
            "iono_availability": iono.mean(axis=1) if n_t else np.full(n_p, np.nan),
        }))  # fmt: skip
    return pl.concat(rows)


def _percentile(x: np.ndarray, solved: np.ndarray, q: float) -> pl.Series:
    """Per row, numpy's linear-interpolation percentile of the solved epochs' values (null without any)."""
    return pl.Series(row_percentiles(x, solved, q)).fill_nan(None)
