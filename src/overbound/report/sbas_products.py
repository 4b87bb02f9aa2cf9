"""Extra products of an ``overbound sbas`` run, written next to its epoch table.

* ``NAME.subsets.json`` and ``NAME.subsets.png``: the Stanford-ESA all-subsets histogram
  (:func:`overbound.sbas.subsets.all_subsets`; Tossaint et al. 2006, "The Stanford-ESA integrity
  diagram", ION GNSS) for each service level asked for: region counts, subset counts, the worst
  PE/PL ratios and the histograms as sparse cell lists (JSON schema :data:`SUBSETS_SCHEMA`), and
  a horizontal and a vertical Stanford diagram per service in subset units.
* ``NAME.range.parquet``: the range-domain errors against SP3 precise orbits and clocks
  (:func:`overbound.sbas.range_domain.range_errors`, Veerman et al., GIMAT, section 3.4), whose
  ``normalised`` column is the input of the overbounding tests of section 3.5
  (:func:`overbound.stats.krs.krs_test`, :func:`overbound.stats.krs.tail_overbound_probability`).
  Its Parquet provenance (key :data:`overbound.io.table.METADATA_KEY`, read back with
  :func:`overbound.io.table.read_epochs_metadata`) holds the SP3 read report, the SP3 file names
  and coverage counts under ``extra.range``, and the run's provenance under ``extra.sbas``.

Each product is computed first (:func:`subsets_product`, :func:`range_product`), so that a bad
input stops the command before anything is written, then written (:func:`write_subsets`,
:func:`write_range`). Outputs are deterministic: sorted JSON keys, no time stamps, PNG without date
or software metadata.

Alert limits: all services come from one pass over all subsets
(:func:`~overbound.sbas.subsets.all_subsets_by_service`); only the region counts and the histogram
range ``plot_max(AL)`` differ between them, and services with the same limits (e.g. LPV and APV-I)
share one result. A service without a VAL (NPA) has no vertical counts, histogram or diagram.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import polars as pl

from overbound import __version__
from overbound.io.open import Source
from overbound.io.schema import InputError, ReadReport
from overbound.io.sp3 import read_sp3
from overbound.io.table import METADATA_KEY
from overbound.methods.counting import StanfordHistogram
from overbound.sbas.range_domain import range_errors
from overbound.sbas.run import SbasRun
from overbound.sbas.subsets import SubsetHistograms, all_subsets_by_service
from overbound.services import SERVICES, ServiceLevel, resolve_services

__all__ = [
    "SUBSETS_SCHEMA",
    "RangeProduct",
    "SubsetsProduct",
    "default_services",
    "product_path",
    "range_product",
    "subsets_dict",
    "subsets_product",
    "write_range",
    "write_subsets",
]

#: Schema key of ``NAME.subsets.json``.
SUBSETS_SCHEMA = "overbound.sbas-subsets/1"
_AXES = ("horizontal", "vertical")
Progress = Callable[[str], None]


def product_path(path: str | Path, kind: str, suffix: str) -> Path:
    """A product next to an epoch table: ``x.parquet``, ``subsets``, ``.json`` -> ``x.subsets.json``
    (named like :func:`overbound.sbas.run.satellites_path`)."""
    path = Path(path)
    return path.with_name(f"{path.stem}.{kind}{suffix}")


def default_services(mode: str) -> tuple[ServiceLevel, ...]:
    """The service level a mode is flown to: LPV for ``PA``, NPA for ``NPA``."""
    return (SERVICES["LPV"] if mode == "PA" else SERVICES["NPA"],)


# --------------------------------------------------------------------------- all subsets


@dataclass(frozen=True, slots=True)
class SubsetsProduct:
    """All-subsets histograms of a run, per service level (in the order given)."""

    services: tuple[ServiceLevel, ...]
    results: dict[str, SubsetHistograms]
    mode: str
    bins: int
    max_size: int | None


def subsets_product(
    run: SbasRun,
    services: Sequence[str | ServiceLevel] | None = None,
    *,
    bins: int = 200,
    max_size: int | None = None,
    progress: Progress | None = None,
) -> SubsetsProduct:
    """Stanford-ESA all-subsets histograms of a run's used satellites for each service level.

    Parameters
    ----------
    run : the output of :func:`overbound.sbas.run.process`.
    services : names (``LPV``), ``NAME:HAL:VAL`` strings or levels; default :func:`default_services`.
    bins, max_size : as :func:`overbound.sbas.subsets.all_subsets`.
    progress : called with a short description before the (single) pass over the subsets.
    """
    step = progress or (lambda _: None)
    levels = _levels(run.options.mode, services)
    step(f"all-subsets histogram ({', '.join(s.name for s in levels)})")
    results = all_subsets_by_service(
        run.satellites, {s.name: (s.hal, s.val) for s in levels}, mode=run.options.mode, bins=bins,
        max_size=max_size,
    )  # fmt: skip
    return SubsetsProduct(levels, results, run.options.mode, bins, max_size)


def _levels(mode: str, services: Sequence[str | ServiceLevel] | None) -> tuple[ServiceLevel, ...]:
    if not services:
        return default_services(mode)
    if all(isinstance(s, ServiceLevel) for s in services):
        return tuple(services)  # type: ignore[arg-type]
    return resolve_services([s if isinstance(s, str) else s.name for s in services])


def subsets_dict(product: SubsetsProduct, run: SbasRun, *, epochs_name: str = "") -> dict:
    """The ``overbound.sbas-subsets/1`` document (plain JSON types before :func:`report.json.dumps`).

    Keys: ``schema``; ``epochs`` (the epoch table's file name), ``station``, ``mode``,
    ``reference_source``; ``min_size``, ``max_size``, ``bins``; ``n_epochs``, ``n_subsets``,
    ``n_singular``, ``by_size`` (subsets per size), ``worst_ratio`` (largest PE/PL per axis);
    ``services``: per level ``alert_limits`` and per axis (``null`` without an alert limit)
    ``counts`` (Stanford regions, :class:`~overbound.methods.counting.Region` keys) and
    ``histogram``: ``edges`` (m, shared by PE and PL), ``clipped`` and the non-zero cells as
    parallel lists ``pe_bin``, ``pl_bin``, ``count`` (row-major order).
    """
    first = product.results[product.services[0].name]
    services = {}
    for s in product.services:
        r = product.results[s.name]
        limits = {"horizontal": s.hal, "vertical": s.val}
        services[s.name] = {
            "alert_limits": limits,
            **{
                axis: None if limits[axis] is None
                else {"counts": r.counts[axis].to_dict(), "histogram": _sparse(getattr(r, axis))}
                for axis in _AXES
            },
        }  # fmt: skip
    return {
        "schema": SUBSETS_SCHEMA,
        "epochs": epochs_name,
        "station": run.station,
        "mode": product.mode,
        "reference_source": run.reference_source,
        "min_size": 4,
        "max_size": product.max_size,
        "bins": product.bins,
        "n_epochs": first.n_epochs,
        "n_subsets": first.n_subsets,
        "n_singular": first.n_singular,
        "by_size": {str(k): v for k, v in first.by_size.items()},
        "worst_ratio": dict(first.worst_ratio),
        "services": services,
    }


def _sparse(h: StanfordHistogram) -> dict:
    i, j = np.nonzero(h.counts)
    return {
        "edges": h.edges,
        "clipped": h.clipped,
        "pe_bin": i,
        "pl_bin": j,
        "count": h.counts[i, j],
    }


def write_subsets(product: SubsetsProduct, run: SbasRun, path: str | Path) -> tuple[Path, Path]:
    """Write ``NAME.subsets.json`` and ``NAME.subsets.png`` next to the epoch table ``path``."""
    from overbound.jsontext import dumps

    json_path = product_path(path, "subsets", ".json")
    png_path = product_path(path, "subsets", ".png")
    json_path.parent.mkdir(parents=True, exist_ok=True)
    json_path.write_text(dumps(subsets_dict(product, run, epochs_name=Path(path).name)), encoding="utf-8")
    png_path.write_bytes(_subsets_png(product))
    return json_path, png_path


def _subsets_png(product: SubsetsProduct) -> bytes:
    """A row of two Stanford diagrams (horizontal, vertical) per service, in subset units."""
    from overbound.report.figures import plot_stanford
    from overbound.report.style import close_figure, figure_png, new_figure

    n = len(product.services)
    fig = new_figure(10.0, 4.6 * n)
    for row, s in enumerate(product.services):
        r = product.results[s.name]
        y0 = (n - 1 - row) / n
        for col, axis in enumerate(_AXES):
            x0 = col / 2
            # the colour bar takes its room from these axes (plot_stanford with ``ax``)
            ax = fig.add_axes((x0 + 0.12 / 2, y0 + 0.17 / n, 0.78 / 2, 0.72 / n))
            al = s.alert_limit(axis)
            if al is None:
                ax.set_axis_off()
                ax.text(0.5, 0.5, f"{s.name}: no {axis} alert limit", ha="center", va="center")
                continue
            plot_stanford(getattr(r, axis), r.counts[axis], alert_limit=al, service=s.name, ax=ax,
                          unit="subsets")  # fmt: skip
    png = figure_png(fig)
    close_figure(fig)
    return png


# --------------------------------------------------------------------------- range domain


@dataclass(frozen=True, slots=True, eq=False)
class RangeProduct:
    """Range-domain errors of a run against SP3 data, with the SP3 read report and coverage counts."""

    table: pl.DataFrame
    sp3_files: tuple[str, ...]
    sp3_report: ReadReport
    counts: dict


def range_product(
    run: SbasRun, sp3: Source | Sequence[Source], *, progress: Progress | None = None
) -> RangeProduct:
    """Read SP3 files and compute the range-domain errors of a run's used satellites (GIMAT 3.4).

    Parameters
    ----------
    run : the output of :func:`overbound.sbas.run.process` (with its ephemerides, ``run.eph``).
    sp3 : one or several SP3 files (:func:`overbound.io.sp3.read_sp3`).
    progress : called with a short description before each step.

    Returns
    -------
    RangeProduct
        ``table`` is :func:`~overbound.sbas.range_domain.range_errors`; ``counts``: ``used_rows``
        (used satellites over all epochs), ``rows`` (those with SP3 data), ``rows_without_sp3``,
        ``prns_without_sp3``, ``epochs``, ``satellites``, ``sp3_epochs``, ``sp3_satellites``,
        ``sp3_span`` (first and last SP3 epoch, GPST).

    Raises
    ------
    InputError
        Unreadable SP3 files, or SP3 data that cover none of the used satellites' ranges.
    ValueError
        A run without its ephemerides.
    """
    step = progress or (lambda _: None)
    if run.eph is None:
        raise ValueError(
            "the SBAS run does not hold its broadcast ephemerides (SbasRun.eph): rerun process()"
        )
    step("reading SP3 orbits and clocks")
    orbits, report = read_sp3(sp3)
    step("range-domain errors against SP3")
    used = run.satellites.filter(pl.col("used"))
    name = ", ".join(orbits.files)
    if not used.height:
        raise InputError(name, "no satellite was used in an SBAS solution: no range-domain errors")
    table = range_errors(run.satellites, orbits, run.eph, run.reference_ecef)
    t_obs = used["time"].dt.epoch("us").to_numpy()
    if not table.height:
        raise InputError(name, _no_cover(orbits.time, t_obs, orbits.sats, used["prn"].to_numpy()))
    kept = table.select("time", "prn").with_columns(pl.col("prn").cast(used.schema["prn"]))
    missing = used.select("time", "prn").join(kept, on=("time", "prn"), how="anti")
    counts = {
        "used_rows": used.height,
        "rows": table.height,
        "rows_without_sp3": missing.height,
        "prns_without_sp3": sorted({int(p) for p in missing["prn"].to_list()}),
        "epochs": table["time"].n_unique(),
        "satellites": table["prn"].n_unique(),
        "sp3_epochs": len(orbits.time),
        "sp3_satellites": len(orbits.sats),
        "sp3_span": [_iso(orbits.time.min()), _iso(orbits.time.max())],
    }
    return RangeProduct(table, orbits.files, report, counts)


def _iso(t_us) -> str:
    return str(np.datetime64(int(t_us), "us").astype("datetime64[s]")).replace("T", " ")


def _no_cover(t_sp3: np.ndarray, t_obs: np.ndarray, sats: tuple[str, ...], prns: np.ndarray) -> str:
    """Why no used range has SP3 data: no time overlap, or none of the satellites."""
    obs = f"{_iso(t_obs.min())} - {_iso(t_obs.max())} GPST"
    sp3 = f"{_iso(t_sp3.min())} - {_iso(t_sp3.max())} GPST" if t_sp3.size else "no epoch"
    if not t_sp3.size or t_sp3.max() < t_obs.min() or t_sp3.min() > t_obs.max():
        return f"the SP3 orbits ({sp3}) do not cover the observations ({obs})"
    wanted = {f"G{int(p):02d}" for p in prns}
    if not wanted & set(sats):
        return f"the SP3 orbits have none of the used satellites ({', '.join(sorted(wanted))})"
    return f"the SP3 orbits and clocks ({sp3}) cover no used satellite's range over the observations ({obs})"


def write_range(product: RangeProduct, run: SbasRun, path: str | Path) -> Path:
    """Write ``NAME.range.parquet`` next to the epoch table ``path``, with the provenance of
    :func:`overbound.io.table.write_epochs` (same key and layout): the SP3 read report, and under
    ``extra`` the run's provenance (``sbas``) and ``range``: SP3 file names and coverage counts."""
    out = product_path(path, "range", ".parquet")
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {
        "source": product.sp3_report.source,
        "format": "sbas-range-domain",
        "overbound_version": __version__,
        "report": product.sp3_report.to_dict(),
        "extra": {
            **run.metadata(),
            "range": {"sp3_files": list(product.sp3_files), "counts": product.counts},
        },
    }
    product.table.write_parquet(
        out, compression="zstd", metadata={METADATA_KEY: json.dumps(meta, sort_keys=True)}
    )
    return out
