"""The campaign dataset: the epoch table of many stations and days, partitioned by station and GPS day.

Layout (hive partitioning, readable by polars, pyarrow, Dask and DuckDB as one table)::

    DATASET/
      dataset.json                                   the manifest
      station=<ID>/date=<YYYY-MM-DD>/part-0.parquet  one station-day of the epoch table

A partition holds the canonical columns of :mod:`overbound.io.schema` (``station`` included,
so a file read alone is still a whole epoch table), sorted by time, written by
:func:`~overbound.io.table.write_epochs` (an encoding per column, :data:`PARTITION_COMPRESSION`;
provenance of the input that gave it).
The day is the GPS day of the epochs (GPS time, like the table).

The manifest (``overbound.dataset/1``) holds the overbound version, the stations with their
reference positions when an input was read against one, and the read report of every
ingested input with the partitions it wrote, so that kept + rejected = read stays auditable
after the inputs are gone.

Every file is written through a temporary name and renamed into place, under the
dataset's lock (:func:`overbound.output.locked`): a reader sees each partition and the
manifest whole, old or new.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import json
import os
import re
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import polars as pl

from overbound import __version__
from overbound.io.geodesy import MeanPosition, Reference
from overbound.io.schema import InputError, ReadReport, validate_epochs

if TYPE_CHECKING:
    from overbound.io.truth import Truth

__all__ = [
    "MANIFEST",
    "SCHEMA",
    "IngestResult",
    "Partition",
    "create_dataset",
    "ingest",
    "is_dataset",
    "partition_key",
    "partition_path",
    "partitions",
    "read_dataset",
    "read_manifest",
    "write_manifest",
    "write_partition",
]

#: The partitions' Parquet layout: an encoding per column (:data:`~overbound.io.table.PER_COLUMN`):
#: the times delta-packed, the errors and PLs plain and uncompressed, the few-valued columns in
#: dictionaries. A campaign reads every partition many times, so decoding speed counts, and so
#: does the size, as whether the dataset stays in the page cache decides the speed too: LZ4 decodes
#: 2.3 times as fast as zstd, but its files are 15 % larger, and the 10 station-years of
#: ``bench/bench_campaign.py`` (18.7 GiB in zstd, 21.5 GB in LZ4) no longer fitted beside the
#: workers (counting 85 s zstd, 199 s LZ4, measured). This layout decodes 3.3 times as fast as
#: zstd (a station-day's times, errors and PLs: 1.96 ms against 6.56 ms) at 2 % more bytes.
PARTITION_COMPRESSION = "per-column"  # io.table.PER_COLUMN (io.table's imports reach this module)
#: Why an input without truth is not written as an epoch table (ingest, convert).
NO_TRUTH_TABLE = (
    "no truth (errors unknown): an epoch table holds errors, so it is analysed directly "
    "('overbound analyze FILE...'), not ingested or converted"
)
#: The manifest's file name inside a dataset.
MANIFEST = "dataset.json"
#: The manifest's schema name.
SCHEMA = "overbound.dataset/1"
_PARTITION = re.compile(r"station=(?P<station>[^/]+)/date=(?P<date>\d{4}-\d{2}-\d{2})/part-0\.parquet")


@dataclass(frozen=True, slots=True)
class Partition:
    """One station-day of a dataset: its station, GPS day, and file."""

    station: str
    date: dt.date
    path: Path

    @property
    def key(self) -> str:
        """``station=ID/date=YYYY-MM-DD`` (the partition's directory, relative to the dataset)."""
        return partition_key(self.station, self.date.isoformat())


def partition_key(station: str, date: str) -> str:
    """The key (directory) of the partition of ``station`` on GPS day ``date`` (ISO 8601)."""
    return f"station={station}/date={date}"


@dataclass(frozen=True)
class IngestResult:
    """What :func:`ingest` did.

    Attributes
    ----------
    written : the partitions written, in order (station, day).
    replaced : the keys of those that replaced an existing partition.
    reports : the read report of each input.
    rows : epochs written per partition key.
    """

    written: tuple[Partition, ...]
    replaced: tuple[str, ...]
    reports: tuple[ReadReport, ...]
    rows: Mapping[str, int] = field(default_factory=dict)


def is_dataset(path: str | Path) -> bool:
    """Whether ``path`` is a dataset directory (it holds :data:`MANIFEST`)."""
    p = Path(path)
    return p.is_dir() and (p / MANIFEST).is_file()


def create_dataset(path: str | Path) -> Path:
    """Create an empty dataset at ``path`` (a new or empty directory); return its path.

    Raises
    ------
    InputError
        ``path`` is a file, or a non-empty directory that is not a dataset.
    """
    p = Path(path)
    if is_dataset(p):
        return p
    if p.exists() and (not p.is_dir() or any(p.iterdir())):
        raise InputError(
            str(p), "exists and is not an overbound dataset (no dataset.json); give a new directory"
        )
    p.mkdir(parents=True, exist_ok=True)
    write_manifest(p, {"schema": SCHEMA, "overbound_version": __version__, "stations": {}, "inputs": []})
    return p


def read_manifest(path: str | Path) -> dict:
    """The manifest of the dataset at ``path``.

    Raises
    ------
    InputError
        No manifest, or one that is not the JSON of :data:`SCHEMA`.
    """
    p = Path(path) / MANIFEST
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(str(path), "not an overbound dataset (no dataset.json)") from None
    except (OSError, ValueError) as exc:
        raise InputError(str(p), f"unreadable dataset manifest ({exc})") from None
    if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
        raise InputError(str(p), f"not a {SCHEMA} manifest")
    return doc


def partitions(path: str | Path) -> list[Partition]:
    """The partitions of the dataset at ``path``, sorted by station then day.

    Raises
    ------
    InputError
        ``path`` is not a dataset.
    """
    root = Path(path)
    read_manifest(root)
    out = []
    for f in root.glob("station=*/date=*/part-0.parquet"):
        m = _PARTITION.fullmatch(f.relative_to(root).as_posix())
        if m:
            out.append(Partition(m["station"], dt.date.fromisoformat(m["date"]), f))
    return sorted(out, key=lambda p: (p.station, p.date))


def ingest(
    dataset: str | Path,
    sources: Sequence,
    *,
    reference: Reference | MeanPosition | Truth | None = None,
    read: Callable | None = None,
    **read_options,
) -> IngestResult:
    """Add inputs of any supported format to a dataset, split by station and GPS day.

    Parameters
    ----------
    dataset : the dataset directory (created when new).
    sources : input files (any format :func:`overbound.io.open.read` reads).
    reference : true antenna position, for formats that carry positions; recorded in the
        manifest for the stations of the input.
    read : the reader (default :func:`overbound.io.open.read`; a parameter for tests).
    **read_options : further options of :func:`overbound.io.open.read` (``format``,
        ``station``, ``strict``, ``mapping``, ``time_range``).

    Returns
    -------
    IngestResult : the partitions written and replaced, and the read reports.

    Notes
    -----
    Every input is read before anything is written, so an input that cannot be read leaves
    the dataset as it was. A station-day already in the dataset is replaced by the new
    epochs of that station and day (the result lists it); two inputs of one call that
    cover the same station-day are one table, checked like the inputs of
    ``overbound analyze`` (a time repeated across them is an error).
    """
    from overbound.io.open import read as read_any
    from overbound.output import locked

    root = create_dataset(dataset)
    reader = read or read_any
    tables, reports = [], []
    for src in sources:
        t, r = reader(src, reference=reference, **read_options)
        if not r.truth:  # NaN errors would read back as no-solution epochs: the PLs would be lost
            raise InputError(r.source, NO_TRUTH_TABLE)
        tables.append(t)
        reports.append(r)
    if not tables:
        raise InputError(str(root), "no input to ingest")
    table = pl.concat(tables, how="diagonal_relaxed").sort(["station", "time"], maintain_order=True)
    table = validate_epochs(table, ", ".join(r.source for r in reports))
    days = table.with_columns(pl.col("time").dt.date().alias("_date"))
    written, replaced, rows = [], [], {}
    with locked(root):
        manifest = read_manifest(root)
        for (station, day), part in days.group_by(["station", "_date"], maintain_order=True):
            existed = partition_path(root, str(station), day).exists()
            # the input's report as provenance when there is one input (several: see the manifest)
            p = write_partition(root, part.drop("_date"), report=reports[0] if len(reports) == 1 else None)
            if existed:
                replaced.append(p.key)
            written.append(p)
            rows[p.key] = part.height
        _record(manifest, reports, written, reference, table)
        write_manifest(root, manifest)
    return IngestResult(tuple(written), tuple(replaced), tuple(reports), rows)


def partition_path(root: str | Path, station: str, day: dt.date) -> Path:
    """The file of a station-day in the dataset at ``root``."""
    return Path(root) / f"station={station}" / f"date={day.isoformat()}" / "part-0.parquet"


def write_partition(
    root: str | Path, table: pl.DataFrame, *, report: ReadReport | None = None, extra: dict | None = None
) -> Partition:
    """Write one station-day (``table`` holds one station and one GPS day) atomically.

    The file is :func:`~overbound.io.table.write_epochs` of ``table`` (with ``report`` and
    ``extra`` as its provenance), written under a temporary name in the partition's directory
    and renamed over the old one. The caller holds the dataset's lock.

    Raises
    ------
    ValueError
        ``table`` is empty or spans several stations or days.
    """
    from overbound.io.table import write_epochs

    stations = table["station"].unique()
    days = table["time"].dt.date().unique()
    if table.height == 0 or len(stations) != 1 or len(days) != 1:
        raise ValueError(f"a partition is one station-day; got {len(stations)} stations, {len(days)} days")
    p = Partition(str(stations[0]), days[0], partition_path(root, str(stations[0]), days[0]))
    p.path.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.path.with_name(f".part-0.tmp-{os.getpid()}.parquet")
    try:
        write_epochs(table, tmp, report=report, extra_metadata=extra, compression=PARTITION_COMPRESSION)
        os.replace(tmp, p.path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
    return p


def _record(
    manifest: dict, reports, written, reference: Reference | MeanPosition | Truth | None, table: pl.DataFrame
) -> None:
    from overbound.io.truth import Truth  # when run: io.truth imports this module (via io.open)

    stations = manifest.setdefault("stations", {})
    for name in table["station"].unique().sort().to_list():
        entry = stations.setdefault(name, {"reference": None})
        if isinstance(reference, Reference):
            entry["reference"] = [reference.lat_deg, reference.lon_deg, reference.height_m]
        elif isinstance(reference, MeanPosition):  # each input's own mean, in its notes
            entry["reference"] = "mean"
        elif isinstance(reference, Truth):
            entry["reference"] = "truth"
            entry.setdefault("truth", []).append({"statement": reference.statement(), **reference.summary()})
    manifest.setdefault("inputs", []).append(
        {
            "reports": [r.to_dict() for r in reports],
            "partitions": [p.key for p in written],
            "overbound_version": __version__,
        }
    )
    manifest["overbound_version"] = __version__


def write_manifest(root: Path, doc: dict) -> None:
    """Write the manifest ``doc`` atomically (the caller holds the dataset's lock)."""
    tmp = root / f".{MANIFEST}.tmp-{os.getpid()}"
    tmp.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp, root / MANIFEST)


def read_dataset(
    path: str | Path, *, columns: Sequence[str] | None = None, skip: Collection[str] = ()
) -> tuple[pl.DataFrame, ReadReport]:
    """The whole epoch table of a dataset, and a report of what was read.

    The partitions are read in (station, day) order and concatenated: the same table as
    the one of its inputs read together. ``columns`` is that of
    :func:`~overbound.io.table.read_parquet` (the other columns are not even read);
    :func:`overbound.io.open.read` applies its column and time-window options on top, as for
    any input. ``skip`` holds partition keys (``station=ID/date=YYYY-MM-DD``) left out, e.g.
    those a campaign analysis could not read.

    Raises
    ------
    InputError
        Not a dataset, no partition, or a partition that cannot be read (named).
    """
    from overbound.io.table import read_parquet

    root = Path(path)
    parts = [p for p in partitions(root) if p.key not in skip]
    if not parts:
        raise InputError(str(root), "the dataset has no partition (ingest inputs first)")
    table = pl.concat([read_parquet(p.path, columns=columns)[0] for p in parts], how="diagonal_relaxed")
    stations = sorted({p.station for p in parts})
    report = ReadReport(
        source=str(root),
        format="dataset",
        rows_read=table.height,
        rows_kept=table.height,
        notes=(
            f"{len(parts)} station-days of {len(stations)} stations ({', '.join(stations[:10])}"
            f"{', ...' if len(stations) > 10 else ''}); the read reports of its inputs are in {MANIFEST}",
        ),
    )
    return table, report
