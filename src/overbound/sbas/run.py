"""Files in, epoch table out: the ``overbound sbas`` pipeline around :func:`~overbound.sbas.engine.run_sbas`.

:func:`process` reads the observation, navigation and SBAS message files (each recognised by its
content: RINEX 2/3 observations, plain, gzip or Hatanaka; RINEX 2/3 GPS navigation; EMS, RINEX-B or
RTKLIB ``.sbs`` SBAS messages; u-blox UBX raw logs, binary or hex-wrapped, which may carry all three;
other receivers' raw logs through RTKLIB ``convbin``, which writes RINEX and ``.sbs``), checks that
they fit together (ephemerides and messages over the observation span), chooses the reference
position and the GEO, runs the engine and gathers every count of what was rejected on the way.
:func:`write_run` writes the epoch table (:func:`overbound.io.table.write_epochs`, so ``overbound
analyze`` reads it) and the per-satellite table next to it (``NAME.sats.parquet``).

Several receivers
-----------------
:func:`process_stations` processes the observation files station by station, never merged
(:func:`read_stations`, :func:`station_names`): files are one station when their RINEX marker
names agree and their header positions are within :data:`SAME_STATION_M`; the navigation and
SBAS message files serve every station. Each station's run equals :func:`process` of its files
alone; :func:`write_runs` writes them as one epoch table. Records of one time and satellite in two
files of one station are the only duplicates (dropped and counted).

Reference position
------------------
The engine linearises about the reference and reports errors against it. It is, in order: the
position given (geodetic or ECEF); the RINEX header ``APPROX POSITION XYZ``; or, with
``reference="mean"``, the mean of the engine's own solutions: a first run about a plain
single-frequency position (least squares on broadcast orbits and clocks, no atmosphere, median
over up to 60 epochs) gives east/north/up offsets whose mean over the epochs with a solution
moves the reference; the engine runs again about the moved point (twice, so the linearisation
point is within millimetres of the mean). Errors are then scatter about the mean, the only
choice when no surveyed position exists (the u-blox EGNOS hour).

GEO
---
With messages of one GEO, that one. With several and no ``geo``, each epoch takes the GEO a
single-channel SBAS receiver would be tracking: it stays with its GEO while that GEO's last
CRC-valid message is at most :data:`GEO_SWITCH_S` old, and otherwise switches to the GEO with
the most recent message. Each GEO's epochs go through the engine with that GEO's messages only
(its start-up after a switch is the engine's: mask, fast corrections and grid must be received
again). The ``geo`` column of both tables says which GEO served each epoch.
"""

from __future__ import annotations

import io
import math
import re
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import polars as pl
import pymap3d

from overbound.io._rinex import US, load_bytes
from overbound.io.ems import read_ems
from overbound.io.geodesy import Reference
from overbound.io.open import Source, source_name
from overbound.io.rinex_b import read_rinex_b
from overbound.io.rinex_nav import (
    SPEED_OF_LIGHT,
    GpsEphemerides,
    broadcast_state,
    read_rinex_nav,
    rotate_earth,
    select_ephemeris,
)
from overbound.io.rinex_obs import read_rinex_obs
from overbound.io.rtklib_sbs import SBS_LINE, read_rtklib_sbs
from overbound.io.sbas_frames import SbasFrames
from overbound.io.schema import InputError, ReadReport
from overbound.io.table import write_epochs
from overbound.io.ubx_raw import is_ubx, read_ubx_raw
from overbound.sbas.engine import SbasOptions, SbasResult, run_sbas
from overbound.sbas.messages import decode

__all__ = [
    "GEO_SWITCH_S",
    "SAME_STATION_M",
    "SbasInputs",
    "SbasRun",
    "process",
    "process_inputs",
    "process_stations",
    "read_inputs",
    "read_stations",
    "run_report",
    "satellites_path",
    "station_names",
    "write_run",
    "write_runs",
]

#: A tracked GEO is left when its last message is older than this (s).
GEO_SWITCH_S = 12.0
_EMS_LINE = re.compile(rb"^\s*\d{3} \d\d \d\d \d\d \d\d \d\d \d\d [ \d]?\d [0-9A-Fa-f]{64}\s*$")
_SBS_LINE = re.compile(SBS_LINE.encode())
_KINDS = {
    "obs": ("rinex-obs", "ubx"),
    "nav": ("rinex-nav", "ubx"),
    "sbas": ("ems", "rinex-b", "rtklib-sbs", "ubx"),
}
#: Said with an unknown format: the route for the raw logs of other receivers (docs/your-data.md).
_CONVERT = (
    " (other receivers' raw logs, e.g. Hemisphere, NovAtel, Septentrio: convert them with RTKLIB's "
    "convbin to RINEX and an .sbs message log)"
)
_KIND_TEXT = {
    "rinex-obs": "a RINEX observation file",
    "rinex-nav": "a RINEX navigation file",
    "ems": "an EMS SBAS message file",
    "rinex-b": "a RINEX-B SBAS message file",
    "rtklib-sbs": "an RTKLIB .sbs SBAS message log",
    "ubx": "a u-blox UBX log",
}
_OPTION = {"obs": "--obs", "nav": "--nav", "sbas": "--sbas"}
_ACCEPTS = {
    "obs": "RINEX 2/3 observations (plain, gzip, Hatanaka) or a u-blox UBX raw log",
    "nav": "RINEX 2/3 GPS navigation or a u-blox UBX raw log",
    "sbas": "EMS, RINEX-B or RTKLIB .sbs SBAS message files or a u-blox UBX raw log",
}
Progress = Callable[[str], None]


@dataclass(frozen=True, slots=True, eq=False)
class SbasInputs:
    """Everything read from the files, before the engine."""

    obs: pl.DataFrame
    eph: pl.DataFrame
    frames: SbasFrames
    header_position: tuple[float, float, float] | None
    station: str
    reports: tuple[tuple[str, ReadReport], ...]  # (role, report)
    duplicate_observations: int = 0  # records of a (time, satellite) already read, dropped
    #: GPS broadcast ionospheric coefficients (alpha, beta) of the first RINEX navigation file's header.
    klobuchar: tuple[tuple[float, ...], tuple[float, ...]] | None = None


@dataclass(frozen=True, slots=True, eq=False)
class SbasRun:
    """The engine's output for a set of files, with the reference used and every count."""

    epochs: pl.DataFrame
    satellites: pl.DataFrame
    reference_ecef: tuple[float, float, float]
    reference_source: str
    station: str
    options: SbasOptions
    reports: tuple[tuple[str, ReadReport], ...]
    counts: dict[str, object] = field(default_factory=dict)
    #: The broadcast ephemerides the engine used (range-domain products need their TGD); None if not kept.
    eph: pl.DataFrame | None = None

    def metadata(self) -> dict:
        """JSON-ready provenance: inputs, rejections, options, reference, engine counts."""
        lat, lon, h = (float(v) for v in pymap3d.ecef2geodetic(*self.reference_ecef))
        return {
            "sbas": {
                "reference_ecef": [round(v, 4) for v in self.reference_ecef],
                "reference_llh": [round(lat, 9), round(lon, 9), round(h, 4)],
                "reference_source": self.reference_source,
                "options": asdict(self.options),  # every engine option, so none is lost from the record
                "inputs": [{"role": role, **r.to_dict()} for role, r in self.reports],
                "counts": self.counts,
            }
        }


def process(
    obs: Source | Sequence[Source],
    nav: Source | Sequence[Source] = (),
    sbas: Source | Sequence[Source] = (),
    *,
    reference: Reference | tuple[float, float, float] | str | None = None,
    station: str | None = None,
    options: SbasOptions | None = None,
    progress: Progress | None = None,
) -> SbasRun:
    """Read the files and run the DO-229 engine on them.

    Parameters
    ----------
    obs : observation files (RINEX 2/3, gzip, Hatanaka) or u-blox UBX raw logs.
    nav : GPS navigation files; may be empty when a UBX log in ``obs`` carries ephemerides.
    sbas : EMS, RINEX-B or RTKLIB ``.sbs`` files; may be empty when a UBX log in ``obs`` carries SBAS
        frames.
    reference : a :class:`Reference`, an ECEF triple, ``"mean"`` (see the module notes) or None
        (the RINEX header position).
    station : name for the ``station`` column (default: the RINEX marker name or the file stem).
    options : engine options (mode, mask, GEO...).
    progress : called with a short description before each step.

    Raises
    ------
    InputError
        Unreadable or unknown files, no pseudoranges, no ephemeris covering the observations, no
        SBAS message over them, no reference position.
    """
    inp = read_inputs(obs, nav, sbas, station=station, progress=progress)
    return process_inputs(inp, reference, options or SbasOptions(), progress or (lambda _: None))


def process_stations(
    obs: Source | Sequence[Source],
    nav: Source | Sequence[Source] = (),
    sbas: Source | Sequence[Source] = (),
    *,
    reference: Reference | tuple[float, float, float] | str | None = None,
    stations: str | Sequence[str] | None = None,
    options: SbasOptions | None = None,
    progress: Progress | None = None,
) -> tuple[SbasRun, ...]:
    """:func:`process` of each station of the observation files (:func:`read_stations`), in the
    order of their names: each run equals :func:`process` of that station's files alone with the
    same navigation and message files (without navigation files, the ephemerides of all u-blox
    logs serve every station).

    ``reference``: ``None`` (each station's RINEX header position) or ``"mean"`` (each its own
    mean); a position names one antenna, so with several stations it is refused.

    Raises
    ------
    ValueError
        A position given for several stations; station names not one per file.
    InputError
        As :func:`process`, for any station (named in the message).
    """
    step = progress or (lambda _: None)
    found = read_stations(obs, nav, sbas, stations=stations, progress=step)
    if len(found) > 1 and reference is not None and not (isinstance(reference, str) and reference == "mean"):
        names = ", ".join(i.station for i in found)
        raise ValueError(
            f"one reference position for {len(found)} stations ({names}): each takes its RINEX header "
            "position, or give reference 'mean', or process the stations one at a time"
        )
    opt = options or SbasOptions()
    runs = []
    for inp in found:
        where = f"{inp.station}: " if len(found) > 1 else ""
        runs.append(process_inputs(inp, reference, opt, lambda what, where=where: step(where + what)))
    return tuple(runs)


def process_inputs(inp: SbasInputs, reference, opt: SbasOptions, step: Progress = lambda _: None) -> SbasRun:
    """:func:`process` of inputs already read (one station's, :func:`read_inputs`): the checks, the
    reference (as in :func:`process`) and the engine runs."""
    counts = _check(inp)
    msgs = decode(inp.frames)
    counts["messages"] = msgs.counts
    if isinstance(reference, str) and reference != "mean":
        raise ValueError(f"reference {reference!r}: expected a position, 'mean' or None")
    if reference is None:
        if inp.header_position is None:
            raise InputError(
                inp.station, "no reference position: the observations have no RINEX header position; "
                "give --reference LAT,LON,H, --reference-ecef X,Y,Z or --reference mean",
            )  # fmt: skip
        ref, source = inp.header_position, "rinex header"
    elif isinstance(reference, Reference):
        ref, source = reference.to_ecef(), "given"
    elif isinstance(reference, str):
        step("initial position")
        ref, source = inp.header_position or _spp(inp.obs, inp.eph, inp.station), "mean"
    else:
        ref, source = tuple(float(v) for v in reference), "given"
    geo_of_epoch = _geo_schedule(inp.obs, inp.frames, opt.geo)
    passes = 3 if source == "mean" else 1
    for k in range(passes):
        step(f"SBAS engine (mean position, pass {k + 1} of {passes})" if passes > 1 else "SBAS engine")
        result = _run(inp, msgs, ref, opt, geo_of_epoch)
        if source == "mean" and k < passes - 1:
            ref = _shift(ref, result.epochs)
    counts["engine"] = result.counts
    return SbasRun(
        epochs=result.epochs, satellites=result.satellites, reference_ecef=tuple(float(v) for v in ref),
        reference_source=source, station=inp.station, options=opt, reports=inp.reports, counts=counts,
        eph=inp.eph,
    )  # fmt: skip


def _read_role(files, role: str, from_ubx, readers: dict, from_others, reports: list) -> list:
    """What the files of one role (``nav``, ``sbas``) give: each u-blox log read alone (``from_ubx`` picks
    its part), the other files of one kind read together by ``readers[kind]`` (kinds in order of first
    appearance; ``from_others`` picks the part of its result); every read report is appended to
    ``reports``."""
    out, others = [], {}
    for name, kind, data in _load(files, role):
        if kind == "ubx":
            raw, rep = read_ubx_raw(_stream(data, name))
            out.append(from_ubx(raw))
            reports.append((role, rep))
        else:
            others.setdefault(kind, []).append(_stream(data, name))
    for kind, streams in others.items():
        result, rep = readers[kind](streams)
        out.append(from_others(result))
        reports.append((role, rep))
    return out


#: Header positions of two observation files farther apart than this (m) are two receivers.
SAME_STATION_M = 100.0


@dataclass(frozen=True, slots=True, eq=False)
class _ObsFile:
    """One observation file as read: its table, report, identity (RINEX marker name and header
    position; neither for a u-blox log) and, for a u-blox log, its ephemerides and SBAS frames."""

    name: str
    table: pl.DataFrame
    report: ReadReport
    marker: str = ""
    position: tuple[float, float, float] | None = None
    eph: pl.DataFrame | None = None
    frames: SbasFrames | None = None


def _read_observations(obs: Source | Sequence[Source]) -> list[_ObsFile]:
    files = []
    for name, kind, data in _load(obs, "obs"):
        if kind == "ubx":
            raw, rep = read_ubx_raw(_stream(data, name))
            files.append(_ObsFile(name, raw.obs, rep, eph=raw.eph, frames=raw.frames))
        else:
            # the engine uses the L1 C/A code only (no SNR mask, no carrier smoothing: plain DO-229)
            o, rep = read_rinex_obs(_stream(data, name), codes=("C1C",))
            table = o.table.select(c for c in o.table.columns if not c.endswith(("_lli", "_ssi")))
            files.append(_ObsFile(name, table, rep, o.header.marker_name.strip(), o.header.approx_position))
    return files


def _stem(name: str) -> str:
    return Path(name).name.split(".")[0]


def station_names(files: Sequence[tuple[str, str, tuple[float, float, float] | None]]) -> list[str]:
    """The station of each observation file ``(name, marker, header position)``, in order.

    Files are one station when their RINEX marker names are equal and their header positions are
    within :data:`SAME_STATION_M`: several files of a day of one receiver. A position of (0, 0, 0)
    (a converter's placeholder) counts as none. Files with a position are grouped first; a file
    with a marker but no position then joins the first station of its marker; a file with neither
    (a u-blox log) joins the only station when there is one, else all such files are one station.
    So the grouping does not depend on the order of files of different kinds. A station is named
    by its marker, else by its first file's name up to the first dot; a name already taken gets
    ``-<file>`` and then a number (``MARKER-file``, ``MARKER-file-2``).
    """
    items = [(name, marker, _position(position)) for name, marker, position in files]
    groups: list[list] = []  # [marker, position, label]
    label_of: dict[int, int] = {}

    def new_group(i: int) -> int:
        name, marker, position = items[i]
        taken = {g[2] for g in groups}
        label = marker or _stem(name)
        if label in taken:
            label = f"{label}-{_stem(name)}" if marker else label
        base, k = label, 1
        while label in taken:
            k += 1
            label = f"{base}-{k}"
        groups.append([marker, position, label])
        return len(groups) - 1

    order = sorted(range(len(items)), key=lambda i: (items[i][2] is None, not items[i][1]))
    anonymous = []
    for i in order:
        _, marker, position = items[i]
        if position is None and not marker:
            anonymous.append(i)
            continue
        found = next(
            (
                k
                for k, g in enumerate(groups)
                if g[0] == marker and (position is None or _near(g[1], position))
            ),
            None,
        )
        label_of[i] = new_group(i) if found is None else found
    if anonymous:
        only = len(groups) == 1
        k = 0 if only else new_group(anonymous[0])
        label_of.update(dict.fromkeys(anonymous, k))
    return [groups[label_of[i]][2] for i in range(len(items))]


def _position(p: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
    return None if p is None or math.hypot(*p) < 1.0 else p


def _near(a: tuple[float, float, float] | None, b: tuple[float, float, float]) -> bool:
    return a is None or math.dist(a, b) <= SAME_STATION_M


def _file_stations(files: list[_ObsFile], stations: str | Sequence[str] | None) -> list[str]:
    """Each file's station: ``stations`` (one name for all, or one per file), else :func:`station_names`."""
    if stations is None:
        return station_names([(f.name, f.marker, f.position) for f in files])
    if isinstance(stations, str):
        return [stations] * len(files)
    if len(stations) == 1:
        return [stations[0]] * len(files)
    if len(stations) != len(files):
        raise ValueError(
            f"{len(stations)} station names for {len(files)} observation files: give one name for "
            "all, or one per file in the order of the files"
        )
    return list(stations)


def read_stations(
    obs: Source | Sequence[Source],
    nav: Source | Sequence[Source] = (),
    sbas: Source | Sequence[Source] = (),
    *,
    stations: str | Sequence[str] | None = None,
    progress: Progress | None = None,
) -> tuple[SbasInputs, ...]:
    """Read all input files: one :class:`SbasInputs` per station of the observation files, in the
    order of their station names (see :func:`station_names`; ``stations``: one name for all
    files, or one per file). The navigation and SBAS message files are read once and serve every
    station; without them, the ephemerides of all u-blox logs serve every station (broadcast
    ephemerides are the same for all), and each station takes the SBAS frames its own logs hold.
    Observation records of one time and satellite in two files of one station are counted as
    duplicates, the first read kept; files of two stations are never merged."""
    step = progress or (lambda _: None)
    step("reading observations")
    files = _read_observations(obs)
    names = _file_stations(files, stations)
    if not files:  # no observation: one station without any, which the checks refuse
        files, names = [_ObsFile("obs", pl.DataFrame(), ReadReport("obs", "none", 0, 0))], ["obs"]
    reports: list[tuple[str, ReadReport]] = []
    step("reading ephemerides")
    ephs = [f.eph for f in files if f.eph is not None] if not nav else []
    navs = _read_role(nav, "nav", lambda raw: raw.eph, {"rinex-nav": read_rinex_nav}, lambda n: n, reports)
    headers = [n.header for n in navs if isinstance(n, GpsEphemerides)]
    ephs += [n.table if isinstance(n, GpsEphemerides) else n for n in navs]
    klob = next(((h.ion_alpha, h.ion_beta) for h in headers if h.ion_alpha and h.ion_beta), None)
    eph = pl.concat(ephs, how="diagonal_relaxed") if ephs else pl.DataFrame()
    if eph.height:
        eph = eph.unique(("prn", "toc", "iode", "iodc"), keep="first", maintain_order=True)
    step("reading SBAS messages")
    sbas_readers = {"ems": read_ems, "rinex-b": read_rinex_b, "rtklib-sbs": read_rtklib_sbs}
    shared = SbasFrames.concat(
        _read_role(sbas, "sbas", lambda raw: raw.frames, sbas_readers, lambda f: f, reports)
    )  # once, for every station
    out = []
    for station in sorted(set(names)):
        mine = [f for f, n in zip(files, names, strict=True) if n == station]
        obs_table, n_dup = _merge_observations([f.table for f in mine])
        frames = shared if sbas else SbasFrames.concat([f.frames for f in mine if f.frames is not None])
        position = next((f.position for f in mine if f.position is not None), None)
        own = tuple(("obs", f.report) for f in mine) + tuple(reports)
        out.append(SbasInputs(obs_table, eph, frames, position, station, own, n_dup, klob))
    return tuple(out)


def read_inputs(
    obs: Source | Sequence[Source],
    nav: Source | Sequence[Source] = (),
    sbas: Source | Sequence[Source] = (),
    *,
    station: str | None = None,
    progress: Progress | None = None,
) -> SbasInputs:
    """Read and merge all input files of one station (see :func:`process`).

    Raises
    ------
    InputError
        The observation files hold several stations and ``station`` does not name them as one
        (:func:`read_stations` reads them apart).
    """
    found = read_stations(obs, nav, sbas, stations=station, progress=progress)
    if len(found) > 1:
        names = ", ".join(i.station for i in found)
        raise InputError(
            _names(obs)[0], f"the observation files hold {len(found)} stations ({names}): process them "
            "apart (read_stations, process_stations) or name them as one station",
        )  # fmt: skip
    return found[0]


def _merge_observations(tables: list[pl.DataFrame]) -> tuple[pl.DataFrame, int]:
    """The observation tables as one, in (time, system, PRN) order, and how many duplicate records
    (same time and satellite, e.g. overlapping files) were dropped, the first one read being kept."""
    table = pl.concat(tables, how="diagonal_relaxed") if tables else pl.DataFrame()
    if not table.height:
        return table, 0
    t = table["time"].dt.epoch("us").to_numpy()
    system = table["system"].cast(pl.String).cast(pl.Categorical).to_physical().to_numpy()
    code = system.astype(np.int64) * 1024 + table["prn"].to_numpy().astype(np.int64)
    order = np.lexsort((code, t))  # stable: among duplicates the first read comes first
    t, code = t[order], code[order]
    dup = np.zeros(order.size, bool)
    dup[1:] = (t[1:] == t[:-1]) & (code[1:] == code[:-1])
    if (order[1:] > order[:-1]).all() and not dup.any():
        return table, 0  # already in order (one file): no copy
    return table[order[~dup]], int(dup.sum())


def satellites_path(path: str | Path) -> Path:
    """The per-satellite table next to an epoch table: ``x.parquet`` -> ``x.sats.parquet``."""
    path = Path(path)
    return path.with_name(f"{path.stem}.sats{path.suffix}")


def run_report(runs: Sequence[SbasRun]) -> ReadReport:
    """The read report of the epoch table of ``runs``: observation rows read, epochs kept, every
    rejection and bad CRC summed, each station's reference."""
    rejected: Counter = Counter()
    for run in runs:
        rejected.update(run.counts.get("rejected", {}))
    bad_crc = sum(run.counts.get("bad_crc", 0) for run in runs)
    return ReadReport(
        source=", ".join(dict.fromkeys(r.source for run in runs for _, r in run.reports)),
        format="sbas-engine",
        rows_read=sum(r.rows_read for run in runs for role, r in run.reports if role == "obs"),
        rows_kept=sum(run.epochs.height for run in runs),
        rejected=dict(sorted(rejected.items())),
        invalidated={"bad_crc": bad_crc} if bad_crc else {},
        notes=tuple(
            (f"{run.station} " if len(runs) > 1 else "")
            + f"reference ({run.reference_source}): {run.reference_ecef}"
            for run in runs
        ),
    )


def write_run(run: SbasRun, path: str | Path) -> tuple[Path, Path]:
    """Write the epoch table (with the run's provenance) and the per-satellite table next to it."""
    return write_runs((run,), path)


def write_runs(runs: Sequence[SbasRun], path: str | Path) -> tuple[Path, Path]:
    """Write the epoch tables of the runs (one per station, :func:`process_stations`) as one, with
    their provenance, and their per-satellite tables next to it. Of one run, the tables as they
    are, its provenance under ``sbas``; of several, the tables one after the other (the satellite
    table then with a ``station`` column after ``time``), the provenance of each station under
    ``sbas_stations``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    report = run_report(runs)
    if len(runs) == 1:
        epochs, sats, meta = runs[0].epochs, runs[0].satellites, runs[0].metadata()
    else:
        epochs = pl.concat([run.epochs for run in runs], how="vertical_relaxed")
        sats = pl.concat(
            [
                run.satellites.insert_column(1, pl.Series("station", [run.station] * run.satellites.height))
                for run in runs
            ]
        ).with_columns(pl.col("station").cast(pl.Categorical))
        meta = {"sbas_stations": {run.station: run.metadata()["sbas"] for run in runs}}
    write_epochs(epochs, path, report=report, extra_metadata=meta)
    sats_path = satellites_path(path)
    if path.suffix.lower() == ".csv":
        sats.write_csv(sats_path)
    else:
        # zstd level 1: 5 % larger than the default level 3 and a third faster to write (0.32 s against
        # 0.47 s for a day at 1 Hz, 849,360 rows, 85 MB), which is a tenth of the whole command
        sats.write_parquet(sats_path, compression="zstd", compression_level=1)
    return path, sats_path


# --------------------------------------------------------------------------- reading


def _names(sources: Source | Sequence[Source]) -> list[str]:
    return [source_name(s) for s in _items(sources)]


def _items(sources: Source | Sequence[Source]) -> list[Source]:
    if isinstance(sources, Sequence) and not isinstance(sources, str | bytes):
        return list(sources)
    return [sources]  # type: ignore[list-item]


def _stream(data: bytes, name: str) -> io.BytesIO:
    s = io.BytesIO(data)
    s.name = name
    return s


def _load(sources: Source | Sequence[Source], role: str):
    """(name, kind, decompressed bytes) of each file of a role; a file of the wrong kind is refused."""
    for src in _items(sources):
        name = source_name(src)
        data = load_bytes(src)
        kind = _kind(data, role)
        if kind not in _KINDS[role]:
            what = _KIND_TEXT.get(kind)
            raise InputError(
                name, f"{what} given as {_OPTION[role]}; {_OPTION[role]} takes {_ACCEPTS[role]}" if what
                else f"unknown format for {_OPTION[role]}: expected {_ACCEPTS[role]}{_CONVERT}",
            )  # fmt: skip
        yield name, kind, data


def _kind(data: bytes, role: str) -> str:
    """Content-based format of one (decompressed) file."""
    if is_ubx(data[:64]):
        return "ubx"
    first = data[:200].split(b"\n", 1)[0].rstrip(b"\r")
    if first[60:].strip() == b"RINEX VERSION / TYPE":
        kinds = {b"O": "rinex-obs", b"N": "rinex-nav", b"G": "rinex-nav", b"H": "rinex-nav", b"B": "rinex-b"}
        return kinds.get(first[20:21], "rinex-other")
    if not data.strip():
        return "ems" if role == "sbas" else "empty"  # an hour without messages is an empty EMS file
    line = data.lstrip().split(b"\n", 1)[0]
    if _SBS_LINE.match(line):
        return "rtklib-sbs"  # RTKLIB's "week tow prn type : hex" (its first field has 4 digits, EMS's 3)
    if _EMS_LINE.match(line) or re.match(rb"^\s*\d{3} \d\d \d\d \d\d ", line):
        return "ems"  # the EMS reader counts or explains malformed lines
    return "unknown"


# --------------------------------------------------------------------------- checks


def _span(t_us: np.ndarray) -> str:
    a, b = (
        str(np.datetime64(int(v), "us").astype("datetime64[s]")).replace("T", " ")
        for v in (t_us.min(), t_us.max())
    )
    return f"{a} - {b} GPST"


def _check(inp: SbasInputs) -> dict:
    """Refuse inputs that cannot give one solution; count what is missing or rejected."""
    src = inp.station
    gps = inp.obs.filter(pl.col("system") == "G") if inp.obs.height else inp.obs
    if not gps.height or "C1C" not in gps.columns or gps["C1C"].is_nan().all():
        raise InputError(src, "no GPS L1 C/A pseudoranges (C1C / RINEX 2 C1) in the observations")
    t_obs = gps["time"].dt.epoch("us").to_numpy()
    if not inp.eph.height:
        raise InputError(
            src, "no GPS broadcast ephemerides: give --nav with a RINEX navigation file "
            "(or a u-blox log with AID-EPH or GPS subframes)",
        )  # fmt: skip
    covered = _ephemeris_coverage(gps, inp.eph)
    if not covered.any():
        t_eph = inp.eph["toe_time"].dt.epoch("us").to_numpy()
        raise InputError(
            src, f"no broadcast ephemeris covers the observations ({_span(t_obs)}); ephemerides "
            f"have toe {_span(t_eph)}",
        )  # fmt: skip
    fr = inp.frames
    if len(fr) == 0 or not fr.crc_ok.any():
        raise InputError(
            src, "no SBAS messages" + (" with a valid CRC" if len(fr) else "")
            + ": give --sbas with EMS, RINEX-B or RTKLIB .sbs files (or a u-blox log with SBAS "
            "RXM-SFRB(X) frames)",
        )  # fmt: skip
    t_msg = fr.time[fr.crc_ok]
    if t_msg.min() > t_obs.max() or t_msg.max() < t_obs.min():
        raise InputError(
            src, f"the SBAS messages ({_span(t_msg)}) do not overlap the observations ({_span(t_obs)})"
        )
    rejected: Counter = Counter()
    for role, r in inp.reports:
        for k, v in r.rejected.items():
            rejected[f"{role}:{k}"] += v
    missing = gps.filter(~pl.Series(covered))
    return {
        "rejected": dict(sorted(rejected.items())),
        "bad_crc": int((~fr.crc_ok).sum()),
        "missing_ephemeris_rows": missing.height,
        "missing_ephemeris_prns": sorted(set(missing["prn"].to_list())),
        "observation_rows": gps.height,
        "duplicate_observation_rows": inp.duplicate_observations,
        "observation_epochs": int(np.unique(t_obs).size),
    }


def _ephemeris_coverage(gps: pl.DataFrame, eph: pl.DataFrame) -> np.ndarray:
    """Whether some record of the PRN (any health) has a fit interval covering each row's time."""
    e = eph.select(
        pl.col("prn").cast(pl.Int64), t=pl.col("toe_time").dt.epoch("us"),
        half=(pl.when(pl.col("fit_interval") > 1).then(pl.col("fit_interval")).otherwise(4.0) * 1800 * US),
    ).sort("t")  # fmt: skip
    q = (
        gps.select(pl.col("prn").cast(pl.Int64), t=pl.col("time").dt.epoch("us"))
        .with_row_index("i")
        .sort("t")
    )
    j = q.join_asof(
        e.rename({"t": "toe"}),
        left_on="t",
        right_on="toe",
        by="prn",
        strategy="nearest",
        check_sortedness=False,
    )  # both sorted by time: sorted within each PRN too
    ok = ((j["t"] - j["toe"]).abs() <= j["half"]).fill_null(False).to_numpy()
    out = np.zeros(gps.height, bool)
    out[j["i"].to_numpy()] = ok
    return out


# --------------------------------------------------------------------------- engine runs


def _geo_schedule(obs: pl.DataFrame, frames: SbasFrames, geo: int | None) -> pl.DataFrame:
    """GEO per observation epoch (see the module notes): columns ``time``, ``geo``."""
    epochs = np.unique(obs.filter(pl.col("system") == "G")["time"].dt.epoch("us").to_numpy())
    ok = frames.crc_ok
    geos = sorted(set(frames.prn[ok].tolist()))
    if geo is not None or len(geos) == 1:
        g = geo if geo is not None else geos[0]
        if g not in geos:
            raise InputError("--geo", f"no messages of GEO {g} (present: {geos})")
        chosen = np.full(epochs.size, g, np.int64)
    else:
        age = np.empty((len(geos), epochs.size))
        for k, g in enumerate(geos):
            tags = frames.time[ok & (frames.prn == g)]
            i = np.searchsorted(tags, epochs, side="right") - 1
            age[k] = np.where(i >= 0, (epochs - tags[np.maximum(i, 0)]) / US, np.inf)
        best = np.argmin(age, axis=0)
        chosen_k = np.empty(epochs.size, np.int64)
        cur = int(best[0])
        for e in range(epochs.size):  # a receiver tracks one GEO until it loses it
            if age[cur, e] > GEO_SWITCH_S and age[best[e], e] < age[cur, e]:
                cur = int(best[e])
            chosen_k[e] = cur
        chosen = np.asarray(geos)[chosen_k]
    return pl.DataFrame(
        {"time": pl.Series(epochs).cast(pl.Datetime("us")), "geo": pl.Series(chosen, dtype=pl.Int16)}
    )


def _run(inp: SbasInputs, msgs, ref, opt: SbasOptions, schedule: pl.DataFrame) -> SbasResult:
    """One engine run per GEO over its epochs; tables concatenated in time order."""
    parts = []
    for g in schedule["geo"].unique().sort().to_list():
        times = schedule.filter(pl.col("geo") == g)["time"]
        obs = inp.obs.filter(pl.col("time").is_in(times.implode()))
        o = replace(opt, geo=int(g))  # every other option as given (relativity was once dropped here)
        r = run_sbas(obs, inp.eph, msgs, ref, station=inp.station, options=o, klobuchar=inp.klobuchar)
        geo_col = pl.lit(g, pl.Int16).alias("geo")
        parts.append((r.epochs.with_columns(geo_col), r.satellites.with_columns(geo_col), r.counts))
    if len(parts) == 1:
        e, s, c = parts[0]
        return SbasResult(epochs=e, satellites=s, counts=c)
    reasons: Counter = Counter()
    for _, _, c in parts:
        reasons.update(c["reasons"])
    counts = {"epochs": sum(p[2]["epochs"] for p in parts), "rows": sum(p[2]["rows"] for p in parts),
              "reasons": dict(sorted(reasons.items()))}  # fmt: skip
    if "klobuchar" in parts[0][2]:  # NPA: rows on the broadcast model, or why none
        klob = [p[2]["klobuchar"] for p in parts]
        counts["klobuchar"] = sum(klob) if all(isinstance(k, int) for k in klob) else klob[0]
    return SbasResult(
        epochs=pl.concat([p[0] for p in parts]).sort("time"),
        satellites=pl.concat([p[1] for p in parts]).sort("time", "prn"),
        counts=counts,
    )


def _shift(ref, epochs: pl.DataFrame) -> tuple[float, float, float]:
    """The reference moved by the mean east/north/up error of the epochs with a solution."""
    sol = epochs.filter(pl.col("vpl").is_finite())
    if not sol.height:
        raise InputError("--reference mean", "no epoch has an SBAS solution: no mean position")
    lat, lon, h = pymap3d.ecef2geodetic(*ref)
    x, y, z = pymap3d.enu2ecef(sol["east"].mean(), sol["north"].mean(), sol["vpe"].mean(), lat, lon, h)
    return float(x), float(y), float(z)


def _spp(obs: pl.DataFrame, eph: pl.DataFrame, name: str, n_epochs: int = 60) -> tuple[float, float, float]:
    """Median of plain single-frequency least-squares positions (no atmosphere) over a few epochs.

    Only the start point of the mean-position iteration: any error of tens of metres is removed
    by the engine's passes.
    """
    gps = obs.filter((pl.col("system") == "G") & pl.col("C1C").is_finite())
    epochs = np.unique(gps["time"].dt.epoch("us").to_numpy())
    pick = epochs[np.linspace(0, epochs.size - 1, min(n_epochs, epochs.size)).astype(int)]
    sols = []
    for t in pick.tolist():
        rows = gps.filter(pl.col("time").dt.epoch("us") == t)
        prn = rows["prn"].to_numpy().astype(np.int64)
        pr = rows["C1C"].to_numpy()
        r = select_ephemeris(eph, prn, np.full(prn.size, t))
        ok = r >= 0
        if ok.sum() < 5:
            continue
        st = broadcast_state(eph, r[ok], np.full(ok.sum(), t), -pr[ok] / SPEED_OF_LIGHT)
        y0 = pr[ok] + SPEED_OF_LIGHT * (st.clock - st.tgd)
        x = np.zeros(4)
        for _ in range(10):
            sat = rotate_earth(st.position, np.linalg.norm(st.position - x[:3], axis=1) / SPEED_OF_LIGHT)
            rho = np.linalg.norm(sat - x[:3], axis=1)
            g = np.column_stack([(x[:3] - sat) / rho[:, None], np.ones(rho.size)])
            dx = np.linalg.lstsq(g, y0 - rho - x[3], rcond=None)[0]
            x += dx
            if np.linalg.norm(dx[:3]) < 1e-3:
                break
        if 6.2e6 < np.linalg.norm(x[:3]) < 6.5e6:
            sols.append(x[:3])
    if not sols:
        raise InputError(name, "no epoch with 5 satellites and ephemerides: cannot find a starting position")
    m = np.median(np.asarray(sols), axis=0)
    return float(m[0]), float(m[1]), float(m[2])
