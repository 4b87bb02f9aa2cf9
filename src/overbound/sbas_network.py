"""Raw data of a network of stations, processed station-day by station-day into a campaign dataset.

A campaign description (TOML) names the stations, their observation files, the navigation and SBAS
message files (patterns with date tokens) and the GPS days. Each station-day is one task on the
campaign runner (:mod:`overbound.campaign`: this process or Dask workers): its observations of the
day go through the DO-229 engine (:func:`overbound.sbas.run.process_inputs` of that station), and
its epoch table is written as the dataset's partition (``station=ID/date=YYYY-MM-DD/part-0.parquet``,
which ``overbound analyze DATASET`` reads), its satellite table in the same layout under
``DATASET.satellites`` beside the dataset (:func:`satellites_root`). The outcome of every
station-day (epochs, solutions, the engine's reasons, every count of what was rejected, or why it
failed) goes into the manifest under ``sbas_network``.

Warm days
---------
A day processed alone starts cold: no fast corrections, masks or ionospheric grid for its first
minutes, an artificial outage at every midnight. Each station-day therefore reads the messages and
navigation files of the previous day too, and keeps the messages from ``warm_s`` (default 1,200 s,
the longest DO-229 time-out being 20 minutes) before its midnight: the engine's state at the first
epoch is then the one a continuous run would have (its corrections depend only on the messages
received before each epoch). ``tests/test_sbas_network.py`` shows a period processed after a
split, warm, equals the same epochs of one continuous run, both tables to the last bit; cold, it
does not. The navigation files of the next day are read too (an ephemeris of 00:00 is broadcast
from about 22:00). Two limits: with several GEOs and no ``geo`` option, a day chooses its GEO at
its first epoch as a receiver switched on then would (the GEO with the latest message), where a
continuous run keeps the GEO it tracks: give ``geo`` for day-exact results; and a campaign of
u-blox logs alone (no ``nav``/``sbas`` patterns) starts each day cold, since only the day's own
logs are read.

Description
-----------
.. code-block:: toml

    start = "2019-01-14"            # first GPS day
    end = "2019-01-15"              # last GPS day (inclusive; default: start)
    nav = ["nav/brdc{doy}0.{yy}n"]  # patterns relative to this file's folder
    sbas = ["ems/{yyyy}/{doy}/h*.ems"]
    mode = "PA"                     # engine options: mode, mask (deg), geo; warm (s)

    [[stations]]
    id = "TLSE"
    obs = ["obs/{id}{doy}0.{yy}o.gz"]
    reference = [43.56, 1.48, 207.0]   # or reference_ecef = [x, y, z]; default: the RINEX header

Tokens: ``{yyyy}``, ``{yy}``, ``{mm}``, ``{dd}``, ``{doy}``, ``{week}`` (GPS week), ``{dow}`` (GPS
day of week, Sunday 0) and ``{id}``; then shell wildcards. A pattern without a date token matches
the same files every day (their messages outside the day and its warm start are left out).
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import glob
import math
import os
import re
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import polars as pl

from overbound.io.geodesy import Reference
from overbound.io.schema import InputError
from overbound.sbas.engine import SbasOptions
from overbound.sbas.run import SbasInputs, SbasRun, process_inputs, read_inputs, run_report

__all__ = [
    "WARM_S",
    "DayOutcome",
    "NetworkCampaign",
    "NetworkStation",
    "expand",
    "period_inputs",
    "process_station_day",
    "read_campaign",
    "run_network",
    "satellites_root",
]

#: Seconds of messages before a day's midnight read first: the longest time-out of the corrections
#: in force (DO-229: 20 min); the messages that stay in force longer (masks, MT 27) are rebroadcast
#: within minutes.
WARM_S = 1200.0
_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
_DAY = dt.timedelta(days=1)
_GPS_EPOCH = dt.date(1980, 1, 6)


@dataclass(frozen=True)
class NetworkStation:
    """A station of the campaign: its id, observation-file patterns and reference (ECEF, m; ``None``:
    the RINEX header position)."""

    id: str
    obs: tuple[str, ...]
    reference: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class NetworkCampaign:
    """A campaign description (:func:`read_campaign`); patterns are relative to ``root``."""

    root: Path
    start: dt.date
    end: dt.date
    stations: tuple[NetworkStation, ...]
    nav: tuple[str, ...] = ()
    sbas: tuple[str, ...] = ()
    options: SbasOptions = field(default_factory=SbasOptions)
    warm_s: float = WARM_S

    @property
    def days(self) -> list[dt.date]:
        return [self.start + dt.timedelta(days=i) for i in range((self.end - self.start).days + 1)]

    def to_dict(self) -> dict:
        return {
            "start": self.start.isoformat(),
            "end": self.end.isoformat(),
            "nav": list(self.nav),
            "sbas": list(self.sbas),
            "options": dataclasses.asdict(self.options),
            "warm_s": self.warm_s,
            "stations": [
                {"id": s.id, "obs": list(s.obs), "reference_ecef": s.reference} for s in self.stations
            ],
        }


def read_campaign(path: str | Path) -> NetworkCampaign:
    """Read a campaign description (see the module notes).

    Raises
    ------
    InputError
        Not TOML, or a key missing or wrong (one line naming the file and the key).
    """
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(str(path), f"cannot read the campaign description: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(str(path), f"not TOML: {exc}") from None
    try:
        start = _date(doc, "start")
        end = _date(doc, "end") if "end" in doc else start
        if end < start:
            raise ValueError(f"end {end} is before start {start}")
        options = SbasOptions(mode=doc.get("mode", "PA"), mask_deg=doc.get("mask", 5.0), geo=doc.get("geo"))
        if options.mode not in ("PA", "NPA"):
            raise ValueError(f"mode {options.mode!r}: PA or NPA")
        if isinstance(options.mask_deg, bool) or not isinstance(options.mask_deg, int | float):
            raise ValueError(f"mask {options.mask_deg!r}: degrees, 0 to 90")
        if not 0 <= options.mask_deg <= 90:
            raise ValueError(f"mask {options.mask_deg!r}: degrees, 0 to 90")
        options = dataclasses.replace(options, mask_deg=float(options.mask_deg))
        if options.geo is not None and (type(options.geo) is not int or not 120 <= options.geo <= 158):
            raise ValueError(f"geo {options.geo!r}: a GEO PRN, an integer 120 to 158")
        warm = float(doc.get("warm", WARM_S))
        if not (math.isfinite(warm) and warm >= 0):
            raise ValueError(f"warm {warm!r}: seconds >= 0")
        listed = doc.get("stations") or []
        if not isinstance(listed, list) or not all(isinstance(x, dict) for x in listed):
            raise ValueError("stations: a list of tables, each [[stations]] with id and obs")
        stations = tuple(_station(i, x) for i, x in enumerate(listed))
        if not stations:
            raise ValueError("no [[stations]]")
        ids = [s.id for s in stations]
        if len(set(ids)) != len(ids):
            raise ValueError(f"station ids repeated: {ids}")
        for pattern in (
            *_patterns(doc, "nav"),
            *_patterns(doc, "sbas"),
            *(p for x in stations for p in x.obs),
        ):
            _fill(pattern, _tokens(start, "ID"))
        return NetworkCampaign(
            path.resolve().parent,
            start,
            end,
            stations,
            _patterns(doc, "nav"),
            _patterns(doc, "sbas"),
            options,
            warm,
        )
    except (KeyError, TypeError, ValueError, InputError) as exc:
        raise InputError(
            str(path), str(exc.reason if isinstance(exc, InputError) else exc).strip("'\"")
        ) from None


def _date(doc: dict, key: str) -> dt.date:
    if key not in doc:
        raise KeyError(f'{key} missing (a GPS day, e.g. {key} = "2019-01-14")')
    value = doc[key]
    if isinstance(value, dt.datetime):  # a GPS day: a time of day would move the day's window
        raise ValueError(f"{key} {value}: a GPS day (YYYY-MM-DD), without a time")
    return value if isinstance(value, dt.date) else dt.date.fromisoformat(str(value))


def _patterns(doc: dict, key: str) -> tuple[str, ...]:
    value = doc.get(key, ())
    value = [value] if isinstance(value, str) else list(value)
    if not all(isinstance(v, str) for v in value):
        raise ValueError(f"{key}: a pattern or a list of patterns")
    return tuple(value)


def _station(i: int, s: dict) -> NetworkStation:
    if "id" not in s:
        raise KeyError(f"stations[{i}].id missing")
    if not isinstance(s["id"], str) or not _ID.fullmatch(s["id"]):
        raise ValueError(
            f"stations[{i}].id {s['id']!r}: letters, digits, '.', '_' or '-' (a partition's folder name)"
        )
    if "reference" in s and "reference_ecef" in s:
        raise ValueError(f"stations[{i}]: reference or reference_ecef, not both")
    ref = None
    if "reference" in s:
        ref = Reference(*(float(v) for v in s["reference"])).to_ecef()
    elif "reference_ecef" in s:
        ref = tuple(float(v) for v in s["reference_ecef"])
        if len(ref) != 3:
            raise ValueError(f"stations[{i}].reference_ecef: three numbers")
    obs = _patterns(s, "obs")
    if not obs:
        raise KeyError(f"stations[{i}].obs missing")
    return NetworkStation(str(s["id"]), obs, ref)


def expand(root: Path, patterns: Sequence[str], day: dt.date, station: str = "") -> list[Path]:
    """The files of ``patterns`` for ``day`` (tokens filled in, then wildcards), sorted, each once."""
    tokens = _tokens(day, station)
    out: dict[Path, None] = {}
    for p in patterns:
        out.update(dict.fromkeys(Path(f) for f in sorted(glob.glob(str(root / _fill(p, tokens))))))
    return list(out)


def _tokens(day: dt.date, station: str) -> dict[str, str]:
    week, dow = divmod((day - _GPS_EPOCH).days, 7)
    return {
        "yyyy": f"{day.year:04d}",
        "yy": f"{day.year % 100:02d}",
        "mm": f"{day.month:02d}",
        "dd": f"{day.day:02d}",
        "doy": f"{day.timetuple().tm_yday:03d}",
        "week": f"{week:04d}",
        "dow": str(dow),
        "id": station,
    }


def _fill(pattern: str, tokens: dict[str, str]) -> str:
    try:
        return pattern.format(**tokens)
    except (KeyError, IndexError, ValueError) as exc:
        raise InputError(
            pattern, f"unknown token {exc} in the pattern (tokens: {', '.join(tokens)})"
        ) from None


def period_inputs(inp: SbasInputs, start_us: int, end_us: int, warm_s: float) -> SbasInputs:
    """``inp`` with its observations in ``[start, end)`` and its messages from ``warm_s`` before
    ``start`` to ``end`` (µs of GPS time): a period processed warm."""
    t = inp.obs["time"].dt.epoch("us").to_numpy() if inp.obs.height else np.empty(0, np.int64)
    keep = (t >= start_us) & (t < end_us)
    ft = inp.frames.time
    frames = inp.frames.take(np.flatnonzero((ft >= start_us - round(warm_s * 1e6)) & (ft < end_us)))
    return dataclasses.replace(
        inp, obs=inp.obs.filter(pl.Series(keep)) if inp.obs.height else inp.obs, frames=frames
    )


@dataclass(frozen=True)
class DayOutcome:
    """What became of a station-day: ``status`` ``written`` (with its counts), ``no observations``
    (no observation file, or none of its epochs in the day) or ``failed`` (``reason``).
    ``solutions``: epochs with a solution of the campaign's mode (PA: finite VPL; NPA: finite HPL);
    ``observation_epochs_outside_day``: epochs of the day's observation files in another day (a
    daily file's closing midnight), left to that day's partition."""

    station: str
    date: str
    status: str
    reason: str = ""
    files: tuple[str, ...] = ()
    epochs: int = 0
    solutions: int = 0
    observation_epochs_outside_day: int = 0
    counts: dict = field(default_factory=dict)
    reference_ecef: tuple[float, float, float] | None = None
    replaced: bool = False

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def process_station_day(
    campaign: NetworkCampaign, station: NetworkStation, day: dt.date, dataset: Path
) -> DayOutcome:
    """One task: the station's epochs of ``day`` (warm, see the module notes) written into the
    dataset, its satellite table into :func:`satellites_root` first; a station-day without
    epochs or that fails removes the partition an earlier run wrote (``replaced``). Every failure
    is the outcome's reason (one line, with the exception's type when it is not ours), never raised."""
    from overbound.io.dataset import partition_path, write_partition

    names: tuple[str, ...] = ()
    here = partition_path(dataset, station.id, day)
    beside = partition_path(satellites_root(dataset), station.id, day)
    existed = here.exists()
    try:
        obs = expand(campaign.root, station.obs, day, station.id)
        names = tuple(_relative(p, campaign.root) for p in obs)
        if not obs:
            return _gone(
                here,
                beside,
                DayOutcome(station.id, day.isoformat(), "no observations", "no observation file"),
            )
        nav = _days_files(
            campaign, campaign.nav, day, station.id, (-1, 0, 1)
        )  # an ephemeris of 00:00 next day
        sbas = _days_files(campaign, campaign.sbas, day, station.id, (-1, 0))
        inp = read_inputs(obs, nav, sbas, station=station.id)
        start = _midnight_us(day)
        warm = period_inputs(inp, start, start + 86_400_000_000, campaign.warm_s)
        outside = inp.obs["time"].n_unique() - warm.obs["time"].n_unique() if inp.obs.height else 0
        if not warm.obs.height:
            why = "no observation epoch in the day"
            outcome = DayOutcome(station.id, day.isoformat(), "no observations", why, names)
            return _gone(here, beside, dataclasses.replace(outcome, observation_epochs_outside_day=outside))
        run = process_inputs(warm, station.reference, campaign.options)
        beside.parent.mkdir(parents=True, exist_ok=True)
        _write_atomic(beside, run.satellites)  # first: the partition, renamed last, says the day is whole
        write_partition(dataset, run.epochs, report=run_report((run,)), extra=run.metadata())
    except Exception as exc:  # a task reports; the other station-days go on
        reason = str(exc).splitlines()[0] if str(exc) else ""
        if not isinstance(exc, InputError | OSError | ValueError):
            reason = f"{type(exc).__name__}: {reason}"
        return _gone(here, beside, DayOutcome(station.id, day.isoformat(), "failed", reason, names))
    solutions = int(run.epochs["vpl" if campaign.options.mode == "PA" else "hpl"].is_finite().sum())
    return DayOutcome(
        station.id, day.isoformat(), "written", "", names, run.epochs.height, solutions, outside,
        _counts(run), run.reference_ecef, existed,
    )  # fmt: skip


def satellites_root(dataset: str | Path) -> Path:
    """Where a network run writes each station-day's satellite table (hive layout as the
    dataset's, ``station=ID/date=YYYY-MM-DD/part-0.parquet``): the folder ``DATASET.satellites``
    beside the dataset, so that the dataset stays one table for polars, pyarrow and DuckDB."""
    root = Path(dataset).resolve()
    return root.with_name(root.name + ".satellites")


def _gone(here: Path, beside: Path, outcome: DayOutcome) -> DayOutcome:
    """The outcome of a station-day without epochs, its earlier partition removed (``replaced``)."""
    existed = here.exists()
    for path in (here, beside):
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
    return dataclasses.replace(outcome, replaced=existed)


def _counts(run: SbasRun) -> dict:
    """The run's counts as JSON: the observation files' rejections and duplicates, the engine's
    reasons; and, apart (``shared_files``), those of the navigation and message files, which every
    station-day reading them repeats."""
    rejected = run.counts.get("rejected", {})
    keep = ("missing_ephemeris_rows", "duplicate_observation_rows", "observation_rows")
    out = {k: run.counts[k] for k in keep if k in run.counts}
    out["rejected"] = {k: v for k, v in rejected.items() if k.startswith("obs:")}
    out["reasons"] = run.counts.get("engine", {}).get("reasons", {})
    out["shared_files"] = {
        "rejected": {k: v for k, v in rejected.items() if not k.startswith("obs:")},
        "bad_crc": run.counts.get("bad_crc", 0),
    }
    return out


def _days_files(
    campaign: NetworkCampaign, patterns: Sequence[str], day: dt.date, station: str, offsets: Sequence[int]
) -> list[Path]:
    """The files of the days ``day + offsets`` (each once, in that order)."""
    out: dict[Path, None] = {}
    for k in offsets:
        out.update(dict.fromkeys(expand(campaign.root, patterns, day + k * _DAY, station)))
    return list(out)


def _midnight_us(day: dt.date) -> int:
    return int(np.datetime64(day.isoformat(), "us").astype(np.int64))


def _relative(p: Path, root: Path) -> str:
    with contextlib.suppress(ValueError):
        return str(p.relative_to(root))
    return str(p)


def _write_atomic(path: Path, table: pl.DataFrame) -> None:
    """Write atomically (temporary file, then rename)."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        table.write_parquet(tmp, compression="zstd", compression_level=1)
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def run_network(
    campaign: NetworkCampaign,
    dataset: str | Path,
    *,
    client=None,
    progress: Callable[[str], None] | None = None,
) -> tuple[DayOutcome, ...]:
    """Every station-day of the campaign into ``dataset`` (created if needed), one task each on
    ``client`` (Dask) or in this process, in (station, day) order; the outcomes go into the
    manifest (``sbas_network``), and each station's reference when given."""
    from overbound.campaign import runner_for
    from overbound.io.dataset import create_dataset, read_manifest, write_manifest
    from overbound.output import locked

    root = create_dataset(Path(dataset).resolve())  # the workers may run elsewhere
    runner = runner_for(client)
    items = [(campaign, s, d, root) for s in campaign.stations for d in campaign.days]
    if progress:
        progress(f"SBAS engine: {len(items)} station-days")
    with locked(root):
        outcomes = tuple(runner.starmap(process_station_day, items))
        manifest = read_manifest(root)
        stations = manifest.setdefault("stations", {})
        for s in campaign.stations:
            entry = stations.setdefault(s.id, {"reference": None})
            used = s.reference or next(
                (o.reference_ecef for o in outcomes if o.station == s.id and o.reference_ecef), None
            )
            if used is not None:
                entry["reference"] = list(_geodetic(used))
        runs = manifest.setdefault("sbas_network", [])
        runs.append({"campaign": campaign.to_dict(), "outcomes": [o.to_dict() for o in outcomes]})
        write_manifest(root, manifest)
    return outcomes


def _geodetic(ecef: tuple[float, float, float]) -> tuple[float, float, float]:
    import pymap3d

    lat, lon, h = pymap3d.ecef2geodetic(*ecef)
    return float(lat), float(lon), float(h)
